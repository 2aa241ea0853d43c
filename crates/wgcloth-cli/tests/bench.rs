//! `wgcloth bench` on a tiny table: every backend × model × grid gets a
//! row with the steps it was asked to time and every stage's time, the
//! growth exponents, traffic floors and period ratios divide the right
//! rows, the network throughput is consistent with the work each kernel
//! does, and the plot draws every series and stage. Speed itself is never
//! asserted.

use wgcloth::config::{ModelKind, Preconditioner, Smoother};
use wgcloth::nn::weights::SHIPPED;
use wgcloth::stage::{SelfContactStages, Stage};
use wgcloth_cli::bench::plot::{figure, stage_color, variant_color};
use wgcloth_cli::bench::{Backends, BenchOptions, Solve, VARIANTS, bench};
use wgcloth_cli::run::Steps;

fn tiny() -> BenchOptions {
    BenchOptions {
        quick: true,
        grids: vec![6, 10],
        hardware_gpu_grids: Vec::new(),
        steps: Steps {
            untimed: 2,
            total: 5,
            first_budget: None,
        },
        period_grid: 6,
        period_steps: 3,
        batch_sizes: vec![7, 40],
        repeats: 2,
        iteration_grids: vec![16],
        backends: Backends::Both,
        // The converged rows' solves a step (the scene's own is 1 here).
        substeps: 2,
        worlds: vec![1, 3],
        worlds_steps: 2,
    }
}

/// [`tiny`] on one grid, one repeat, one batch.
fn one_grid() -> BenchOptions {
    BenchOptions {
        grids: vec![6],
        period_steps: 2,
        batch_sizes: vec![7],
        repeats: 1,
        ..tiny()
    }
}

/// `--gpu-only`: the GPU's rows and nothing of the CPU's, or an error
/// where there is no adapter.
#[test]
fn a_gpu_only_bench_has_no_cpu_row() {
    let opts = one_grid().gpu_only();
    let report = match bench(&opts, |_| {}) {
        Ok(report) => report,
        Err(e) if !std::env::var("WGCLOTH_NO_GPU_TESTS").is_ok_and(|v| v == "1") => {
            panic!("the GPU tests need an adapter (WGCLOTH_NO_GPU_TESTS=1 skips them): {e}")
        }
        Err(e) => {
            assert!(e.to_string().contains("adapter"), "{e}");
            return;
        }
    };
    assert_eq!(report.rows.len(), VARIANTS.len());
    assert!(report.rows.iter().all(|r| r.report.backend == "gpu"));
    assert!(report.periods.iter().all(|p| p.backend == "gpu") && !report.periods.is_empty());
    assert!(report.networks.iter().all(|n| n.backend == "gpu"));
    assert!(report.iterations.is_empty());
    // The GPU's batched-worlds rows: one per batch size, each recording
    // the dispatches of one world's step, whatever its worlds, besides the
    // network batch's chunks.
    let worlds: Vec<usize> = report.worlds.iter().map(|w| w.worlds).collect();
    assert_eq!(worlds, opts.worlds);
    assert!(report.worlds.iter().all(|w| w.backend == "gpu"));
    let besides: Vec<Option<u32>> = (report.worlds.iter())
        .map(|w| w.dispatches.map(|(d, net)| d - net))
        .collect();
    assert!(besides[0].is_some_and(|d| d > 0), "{besides:?}");
    assert!(besides.iter().all(|d| *d == besides[0]), "{besides:?}");
}

/// `--cpu-only`: the CPU's rows (steps, periods, networks, solver
/// iterations, the CPU's floors) and nothing of the GPU's, with or without
/// an adapter.
#[test]
fn a_cpu_only_bench_has_no_gpu_row() {
    let opts = one_grid().cpu_only();
    let report = bench(&opts, |_| {}).unwrap();
    assert_eq!(report.rows.len(), VARIANTS.len());
    assert!(report.rows.iter().all(|r| r.report.backend == "cpu"));
    assert!(report.periods.iter().all(|p| p.backend == "cpu") && !report.periods.is_empty());
    assert!(report.networks.iter().all(|n| n.backend == "cpu") && !report.networks.is_empty());
    assert!(!report.iterations.is_empty());
    // A row for each batch size asked, each timed in both ways.
    let worlds: Vec<usize> = report.worlds.iter().map(|w| w.worlds).collect();
    assert_eq!(worlds, opts.worlds);
    for w in &report.worlds {
        assert!(w.batched > 0.0 && w.separate > 0.0, "{w:?}");
        assert!(
            (w.ratio - w.batched / w.separate).abs() < 1e-9 * w.ratio,
            "{w:?}"
        );
    }
    assert!(report.bandwidth.iter().all(|b| b.backend == "cpu"));
    assert!(report.stage_traffic.iter().all(|t| t.backend == "cpu"));
    assert!(report.gpu.contains("CPU rows alone"), "{}", report.gpu);
}

#[test]
fn a_tiny_bench_has_every_row_and_consistent_figures() {
    let opts = tiny();
    let report = bench(&opts, |_| {}).expect("bench runs");
    let gpu = !report.gpu.starts_with("no GPU rows");
    if !std::env::var("WGCLOTH_NO_GPU_TESTS").is_ok_and(|v| v == "1") {
        assert!(
            gpu,
            "the GPU tests need an adapter (WGCLOTH_NO_GPU_TESTS=1 skips them): {}",
            report.gpu
        );
    }
    let backends: &[&str] = if gpu { &["cpu", "gpu"] } else { &["cpu"] };

    let grids = &opts.grids;
    assert_eq!(
        report.rows.len(),
        backends.len() * grids.len() * VARIANTS.len()
    );
    let expected = backends.iter().flat_map(|b| {
        grids
            .iter()
            .flat_map(move |g| VARIANTS.iter().map(move |v| (*b, *g, *v)))
    });
    for (step, (backend, grid, v)) in report.rows.iter().zip(expected) {
        let (row, model) = (&step.report, v.model);
        let what = format!("{backend} {}", v.label());
        assert_eq!(step.label, v.label());
        assert_eq!(
            (row.backend.as_str(), row.model),
            (backend, model),
            "{what}"
        );
        assert_eq!(row.grid, [grid, grid], "{what}");
        assert_eq!(step.particles, (grid * grid) as usize, "{what}");
        assert_eq!(row.steps, opts.steps.total, "{what}");
        assert!(row.finite, "{what}");
        assert!(
            row.ms_per_step > 0.0 && row.ms_per_step.is_finite(),
            "{what}"
        );
        assert_eq!(row.network.is_some(), model.is_network(), "{what}");
        // Every stage is timed: CPU timers, GPU timestamp queries (which
        // lavapipe has; an adapter without them reports none).
        if backend == "cpu" || !row.stage_ms.is_empty() {
            let keys: Vec<&str> = row.stage_ms.keys().map(|k| k.as_str()).collect();
            // The default thickness turns the forces on with self-contact.
            let stages = SelfContactStages {
                separate: v.self_contact,
                forces: v.self_contact,
            };
            let mut want: Vec<&str> = Stage::ALL
                .iter()
                .filter(|s| s.runs(true, stages))
                .map(|s| s.name())
                .collect();
            want.sort();
            assert_eq!(keys, want, "{what}");
        }
        let staged: f64 = row.stage_ms.values().sum();
        assert!(
            (step.stage_coverage - staged / row.ms_per_step).abs() < 1e-9,
            "{what}"
        );
    }

    assert_eq!(report.scaling.len(), backends.len() * VARIANTS.len());
    for g in &report.scaling {
        let ms = |grid: u32| {
            report
                .rows
                .iter()
                .find(|r| {
                    r.report.backend == g.backend && r.label == g.label && r.report.grid[0] == grid
                })
                .expect("the row")
                .report
                .ms_per_step
        };
        assert_eq!((g.from_grid, g.to_grid), (6, 10), "{g:?}");
        let exponent = (ms(10) / ms(6)).ln() / (100.0f64 / 36.0).ln();
        assert!((g.exponent - exponent).abs() < 1e-9, "{g:?}");
    }

    assert_eq!(report.bandwidth.len(), backends.len());
    assert!(report.bandwidth.iter().all(|b| b.gb_per_s > 0.0));
    assert_eq!(report.arithmetic.len(), backends.len());
    assert!(
        report
            .arithmetic
            .iter()
            .all(|a| a.g_multiply_adds_per_s > 0.0)
    );
    assert_eq!(report.cg_traffic.len(), backends.len() * grids.len());
    for t in &report.cg_traffic {
        let row = report
            .rows
            .iter()
            .find(|r| {
                r.report.backend == t.backend && r.report.grid[0] == t.grid && r.label == "friction"
            })
            .expect("the friction row");
        let per_iteration = row.report.stage_ms["pcg"] / row.report.cg_iterations_mean;
        assert!((t.measured_ms - per_iteration).abs() < 1e-9, "{t:?}");
        // At least every vector of the 13 a vertex's iteration touches.
        assert!(
            t.bytes_per_iteration >= 13 * 12 * row.particles as u64,
            "{t:?}"
        );
        assert!(
            (t.times_floor - t.measured_ms / t.floor_ms).abs() < 1e-9,
            "{t:?}"
        );
    }

    // Each preconditioner's CPU iteration (multigrid with each smoother),
    // its floor counting at least A once and every vector it touches;
    // multigrid's more (A three times, and the coarse levels).
    let floors: Vec<_> = report
        .iterations
        .iter()
        .map(|t| (t.grid, t.preconditioner, t.smoother))
        .collect();
    assert_eq!(
        floors,
        [
            (16, Preconditioner::Multigrid, Some(Smoother::Patches)),
            (16, Preconditioner::Multigrid, Some(Smoother::BlockJacobi)),
            (16, Preconditioner::Jacobi, None)
        ]
    );
    for t in &report.iterations {
        assert!(t.measured_ms.is_finite() && t.setup_ms.is_finite(), "{t:?}");
        assert!(t.bytes_per_iteration >= 13 * 12 * 256, "{t:?}");
        assert!(
            (t.times_floor - t.measured_ms / t.floor_ms).abs() < 1e-9 * t.times_floor.abs(),
            "{t:?}"
        );
    }
    let jacobi = &report.iterations[2];
    for multigrid in &report.iterations[..2] {
        assert!(
            multigrid.bytes_per_iteration > 3 * jacobi.bytes_per_iteration,
            "{multigrid:?} {jacobi:?}"
        );
    }

    // Every converged row reached the goal at every step (the run loop
    // solves again the steps its budget cut), and is set against its
    // model's thesis-solve row.
    let converged = VARIANTS.iter().filter(|v| v.solve != Solve::Thesis).count();
    assert!(converged >= 2);
    assert_eq!(
        report.converged.len(),
        backends.len() * grids.len() * converged
    );
    for c in &report.converged {
        assert_eq!(c.steps_above_goal, 0, "{c:?}");
        assert!(c.steps_resolved == 0 || c.backend == "gpu", "{c:?}");
        assert!(c.residual_max <= 1e-3 && c.iterations_mean >= 1.0, "{c:?}");
        assert!(c.iterations_max as f64 >= c.iterations_mean, "{c:?}");
        let row = report
            .rows
            .iter()
            .find(|r| {
                r.label == c.label && r.report.backend == c.backend && r.report.grid[0] == c.grid
            })
            .expect("the converged row");
        assert_eq!(row.report.preconditioner, c.preconditioner, "{c:?}");
        assert_eq!((c.substeps, row.report.substeps), (2, 2), "{c:?}");
        let thesis = report
            .rows
            .iter()
            .find(|r| {
                !r.converged
                    && r.label == row.report.model.name()
                    && r.report.backend == c.backend
                    && r.report.grid[0] == c.grid
            })
            .expect("the thesis-solve row");
        assert_eq!(thesis.report.substeps, 1, "the thesis's step is one solve");
        let ratio = row.report.ms_per_step / thesis.report.ms_per_step;
        assert!((c.times_thesis_step.unwrap() - ratio).abs() < 1e-9, "{c:?}");
    }

    // Each friction-net thesis row's stages against their floors: every
    // stage that sweeps the cloth or the body, and contact where there were
    // contacts.
    for backend in backends {
        for &grid in grids {
            let of: Vec<&str> = report
                .stage_traffic
                .iter()
                .filter(|t| t.backend == *backend && t.grid == grid)
                .map(|t| t.stage)
                .collect();
            for stage in ["rigid", "collide", "assemble", "integrate", "measure"] {
                assert!(of.contains(&stage), "{backend} {grid}²: {of:?}");
            }
            assert!(!of.contains(&"pcg"), "{of:?}");
        }
    }
    for t in &report.stage_traffic {
        let row = report
            .rows
            .iter()
            .find(|r| {
                !r.converged
                    && r.label == "friction-net"
                    && r.report.backend == t.backend
                    && r.report.grid[0] == t.grid
            })
            .expect("the friction-net row");
        assert_eq!(t.measured_ms, row.report.stage_ms[t.stage], "{t:?}");
        // The stages that sweep the cloth move at least one vector per vertex.
        if ["collide", "assemble", "integrate", "measure"].contains(&t.stage) {
            assert!(t.bytes >= 12 * row.particles as u64, "{t:?}");
        }
        assert!(t.bytes > 0 && t.floor_ms > 0.0, "{t:?}");
        // Only the contact stage runs the network: its contacts times the
        // row's multiply-adds per contact, and the floor is the longer one.
        let expected = if t.stage == "contact" {
            row.report.contacts_mean * row.network_multiply_adds as f64
        } else {
            0.0
        };
        assert!(row.network_multiply_adds > 0, "friction-net runs a network");
        assert_eq!(t.multiply_adds, expected, "{t:?}");
        assert_eq!(
            t.floor_ms,
            t.memory_floor_ms.max(t.arithmetic_floor_ms),
            "{t:?}"
        );
        assert_eq!(
            t.bound == "arithmetic",
            t.arithmetic_floor_ms > t.memory_floor_ms,
            "{t:?}"
        );
        assert!(
            (t.times_floor - t.measured_ms / t.floor_ms).abs() < 1e-9 * t.times_floor,
            "{t:?}"
        );
    }

    let thesis_variants = VARIANTS.iter().filter(|v| v.solve == Solve::Thesis).count();
    assert_eq!(report.periods.len(), backends.len() * thesis_variants);
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
    // The Markdown tables hold the same rows, each as wide as its head.
    let markdown = report.markdown();
    for block in markdown.split("\n\n").filter(|b| b.starts_with('|')) {
        let widths: Vec<usize> = block.lines().map(|l| l.matches(" | ").count()).collect();
        assert!(widths.iter().all(|&w| w == widths[0]), "{block}");
    }
    for v in VARIANTS {
        assert!(
            markdown.contains(&format!("| {} |", v.label())),
            "{markdown}"
        );
    }
    assert_eq!(
        markdown
            .lines()
            .filter(|l| l.starts_with("| cpu |"))
            .count(),
        table.lines().filter(|l| l.starts_with("cpu ")).count(),
        "{markdown}\n{table}"
    );

    // Every series of the log-log panel and every stage of the breakdown
    // is drawn from the rows: taking a series' rows, or a stage's times,
    // out of the report takes pixels of its colour off the figure (the
    // legend keeps its own).
    let pixels = |report: &wgcloth_cli::bench::BenchReport, color| {
        let canvas = figure(report).expect("a figure");
        let (w, h) = (canvas.width() as u32, canvas.height() as u32);
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| canvas.pixel(x, y) == color)
            .count()
    };
    for (k, v) in VARIANTS.iter().enumerate() {
        let color = variant_color(k);
        let mut without = report.clone();
        without.rows.retain(|r| r.label != v.label());
        assert!(
            pixels(&without, color) < pixels(&report, color),
            "{} not drawn",
            v.label()
        );
    }
    for (k, stage) in Stage::ALL.iter().enumerate() {
        let color = stage_color(k);
        let mut without = report.clone();
        for r in &mut without.rows {
            r.report.stage_ms.remove(stage.name());
        }
        assert!(
            pixels(&without, color) < pixels(&report, color),
            "{} not drawn",
            stage.name()
        );
    }
}
