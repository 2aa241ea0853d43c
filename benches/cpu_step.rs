//! Criterion benchmark of the CPU reference step: the hanging cloth at
//! 64², 128² and 256² (25 PCG iterations, tolerance 0, as the thesis) and
//! the thesis sphere scene with the friction model at 64² and 128².
//!
//! `cargo bench --bench cpu_step`

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::CpuSim;
use wgcloth::{Config, Scene};

fn sim(scene: SceneKind, grid: u32) -> CpuSim {
    let mut c = Config {
        scene,
        model: ModelKind::Friction,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    c.solver.cg_iters = 25;
    c.solver.cg_tol = 0.0;
    let mut sim = CpuSim::new(Scene::new(&c).expect("valid benchmark scene"));
    // Start where the sphere is pushing the cloth, so contacts are live.
    let warm = if scene == SceneKind::Sphere { 80 } else { 5 };
    for _ in 0..warm {
        sim.step();
    }
    sim
}

fn step(c: &mut Criterion) {
    let mut group = c.benchmark_group("cpu_step");
    group.sample_size(10);
    for (scene, grids) in [
        (SceneKind::Hang, &[64u32, 128, 256][..]),
        (SceneKind::Sphere, &[64, 128][..]),
    ] {
        for &grid in grids {
            let mut s = sim(scene, grid);
            let name = format!("{scene:?}").to_lowercase();
            group.bench_function(BenchmarkId::new(name, grid), |b| b.iter(|| s.step()));
        }
    }
    group.finish();
}

criterion_group!(benches, step);
criterion_main!(benches);
