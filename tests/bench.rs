//! `wgcloth bench` on a tiny table: every backend × model gets a row with
//! the steps it was asked to time, the period ratios divide the right
//! rows, and the network throughput is consistent with the work each
//! kernel does. Speed itself is never asserted.

use wgcloth::bench::{BenchOptions, VARIANTS, bench};
use wgcloth::config::ModelKind;
use wgcloth::nn::weights::SHIPPED;
use wgcloth::run::Steps;

fn tiny() -> BenchOptions {
    BenchOptions {
        quick: true,
        grids: vec![6],
        steps: Steps {
            untimed: 2,
            total: 5,
        },
        period_grid: 6,
        period_steps: 3,
        batch_sizes: vec![7, 40],
        repeats: 2,
    }
}

#[test]
fn a_tiny_bench_has_every_row_and_consistent_figures() {
    let opts = tiny();
    let report = bench(&opts, |_| {}).expect("bench runs");
    let gpu = !report.gpu.starts_with("no GPU rows");
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        assert!(gpu, "CI needs a GPU adapter: {}", report.gpu);
    }
    let backends: &[&str] = if gpu { &["cpu", "gpu"] } else { &["cpu"] };

    assert_eq!(report.rows.len(), backends.len() * VARIANTS.len());
    for (step, (backend, v)) in report.rows.iter().zip(
        backends
            .iter()
            .flat_map(|b| VARIANTS.iter().map(move |v| (*b, *v))),
    ) {
        let (row, model) = (&step.report, v.model);
        let what = format!("{backend} {}", v.label());
        assert_eq!(step.label, v.label());
        assert_eq!(
            (row.backend.as_str(), row.model),
            (backend, model),
            "{what}"
        );
        assert_eq!(row.grid, [6, 6], "{what}");
        assert_eq!(row.steps, opts.steps.total, "{what}");
        assert!(row.finite, "{what}");
        assert!(
            row.ms_per_step > 0.0 && row.ms_per_step.is_finite(),
            "{what}"
        );
        assert_eq!(row.network.is_some(), model.is_network(), "{what}");
        if backend == "cpu" {
            // CPU stage timers cover the step's stages.
            assert!(
                row.stage_ms.contains_key("pcg"),
                "{what}: {:?}",
                row.stage_ms
            );
        }
    }

    assert_eq!(report.periods.len(), backends.len() * VARIANTS.len());
    for p in &report.periods {
        assert!(p.seconds > 0.0, "{p:?}");
        let analytic = match p.model {
            ModelKind::FrictionNet => Some(ModelKind::Friction),
            ModelKind::NaiveNet => Some(ModelKind::Naive),
            _ => None,
        };
        match (analytic, p.ratio_to_analytic) {
            (None, None) => {}
            (Some(a), Some(ratio)) => {
                let base = report
                    .periods
                    .iter()
                    .find(|q| q.backend == p.backend && q.model == a)
                    .expect("the analytic row");
                assert!(
                    (ratio - p.seconds / base.seconds).abs() < 1e-9 * ratio,
                    "{p:?}"
                );
            }
            other => panic!("{p:?}: ratio {other:?}"),
        }
    }

    for shipped in SHIPPED {
        let net = shipped.read().expect("shipped network").network();
        // The forward pass and one reverse pass per output, per evaluation.
        let reverse =
            2 * net.mlp.multiply_adds() * (1 + net.mlp.outputs()) * net.kind.evaluations();
        for &n in &opts.batch_sizes {
            let rows: Vec<_> = report
                .networks
                .iter()
                .filter(|r| r.network == shipped.path && r.contacts == n)
                .collect();
            assert_eq!(rows.len(), backends.len(), "{} × {n}", shipped.path);
            for r in rows {
                if r.backend == "cpu" {
                    assert_eq!(r.flop_per_contact, reverse);
                }
                assert!(r.flop_per_contact >= reverse, "{r:?}");
                let gflops = n as f64 / (r.ms * 1e-3) * r.flop_per_contact as f64 * 1e-9;
                assert!((r.gflop_per_s - gflops).abs() <= 1e-9 * gflops, "{r:?}");
            }
        }
    }

    let table = report.table();
    for v in VARIANTS {
        assert!(table.contains(&v.label()), "{table}");
    }
}
