//! `run --monitor`: a CSV row of the start and of every K steps, with the
//! state's energy as the CPU computes it, the process's resident memory
//! and, on the GPU, the allocator's bytes; GPU and CPU samples agree.
//! Without an adapter the GPU half fails unless WGCLOTH_NO_GPU_TESTS=1 opts out.

mod cli;

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::CpuSim;
use wgcloth::{Config, Scene};
use wgcloth_cli::monitor::Monitor;
use wgcloth_cli::run::{self, Chosen, Observers, Steps};

fn hang(grid: u32) -> Config {
    let mut c = Config {
        scene: SceneKind::Hang,
        model: ModelKind::Friction,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    c
}

#[test]
fn the_cli_writes_a_row_every_k_steps() {
    let dir = std::env::temp_dir().join(format!("wgcloth-monitor-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("m.csv");
    let out = cli::friction_run("hang", "cpu")
        .args([
            "--grid",
            "6",
            "--steps",
            "30",
            "--monitor-every",
            "10",
            "--monitor",
        ])
        .arg(&csv)
        .output()
        .expect("wgcloth runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("monitor      4 samples"), "{stdout}");

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    let steps: Vec<&str> = rows.iter().map(|r| r[column("step")]).collect();
    assert_eq!(steps, ["0", "10", "20", "30"]);
    // The cloth starts at its rest lengths, then hangs under its weight.
    let strain = |row: &Vec<&str>| row[column("max_strain")].parse::<f32>().unwrap();
    assert_eq!(strain(&rows[0]), 0.0);
    assert!(strain(&rows[3]) > 1e-4, "{}", strain(&rows[3]));

    // The first row is the rest state's energy.
    let rest = CpuSim::new(Scene::new(&hang(6)).unwrap()).energy().total();
    let first: f64 = rows[0][column("energy_j")].parse().unwrap();
    assert!(
        (first - rest).abs() <= 1e-9 * rest.abs().max(1.0),
        "{first} vs {rest}"
    );
    for row in &rows {
        assert_eq!(row[column("backend")], "cpu");
        assert_eq!(row[column("finite")], "true");
        assert_eq!(row[column("self_intersections")], "0", "a hanging cloth");
        let strain: f32 = row[column("max_strain")].parse().unwrap();
        // Hanging under its weight a 6² cloth stretches, but not by a tenth.
        assert!((0.0..0.1).contains(&strain), "strain {strain}");
        let rss: u64 = row[column("rss_bytes")].parse().expect("resident memory");
        assert!(rss > 1 << 20, "a process holds more than 1 MiB: {rss}");
        assert_eq!(
            row[column("gpu_allocated_bytes")],
            "",
            "no GPU on the CPU path"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn gpu_samples_match_the_cpu_and_count_device_memory() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("wgcloth-monitor-gpu-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = Scene::new(&hang(8)).unwrap();
    let mut samples = Vec::new();
    for (name, chosen) in [("cpu", Chosen::Cpu), ("gpu", Chosen::gpu(ctx))] {
        let mut monitor = Monitor::create(&dir.join(format!("{name}.csv")), 5).unwrap();
        run::run(
            &chosen,
            scene.clone(),
            Steps::all(20),
            Observers {
                monitor: Some(&mut monitor),
                ..Default::default()
            },
        )
        .expect("runs");
        samples.push(monitor.samples);
    }
    let (cpu, gpu) = (&samples[0], &samples[1]);
    assert_eq!(gpu.len(), 5, "steps 0, 5, 10, 15, 20");
    for (c, g) in cpu.iter().zip(gpu) {
        assert_eq!((c.step, c.backend, g.backend), (g.step, "cpu", "gpu"));
        assert!(
            (c.energy - g.energy).abs() <= 1e-3 * c.energy.abs().max(1e-3),
            "step {}: energy {} on the CPU, {} on the GPU",
            c.step,
            c.energy,
            g.energy
        );
        assert!(
            (c.max_strain - g.max_strain).abs() <= 0.02 * c.max_strain + 1e-5,
            "step {}: strain {} on the CPU, {} on the GPU",
            c.step,
            c.max_strain,
            g.max_strain
        );
        let allocated = g.gpu_allocated_bytes.expect("the allocator reports");
        // x, v and the system alone take 13 vectors of 16 B per vertex.
        assert!(allocated >= 13 * 16 * 64, "{allocated} B allocated");
        assert!(g.gpu_reserved_bytes.unwrap() >= allocated);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
