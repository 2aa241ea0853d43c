//! Criterion benchmark of one step, CPU and GPU side by side in one run:
//! the hanging cloth and the thesis sphere scene (friction model) at 32²,
//! 64² and 128², 25 PCG iterations, tolerance 0 (the thesis's solver).
//! The GPU is whatever adapter the headless constructor picks (lavapipe
//! here); it is skipped with a notice where there is none.
//!
//! `cargo bench --bench step`

use std::sync::Arc;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::CpuSim;
use wgcloth::gpu::{GpuContext, GpuSim, Kernels};
use wgcloth::{Config, Scene};

/// Steps run before timing, so the sphere is pushing the cloth.
fn warm_steps(scene: SceneKind) -> usize {
    if scene == SceneKind::Sphere { 80 } else { 5 }
}

fn scene(kind: SceneKind, grid: u32) -> Scene {
    let mut c = Config {
        scene: kind,
        model: ModelKind::Friction,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    c.solver.cg_iters = 25;
    c.solver.cg_tol = 0.0;
    Scene::new(&c).expect("valid benchmark scene")
}

fn step(c: &mut Criterion) {
    let gpu = match GpuContext::headless() {
        Ok(ctx) => {
            let kernels = Arc::new(Kernels::new(&ctx.device).expect("kernels"));
            eprintln!("GPU: {}", wgcloth::gpu::context::describe(&ctx.adapter));
            Some((ctx, kernels))
        }
        Err(e) => {
            eprintln!("no GPU benchmarks: {e}");
            None
        }
    };
    for kind in [SceneKind::Hang, SceneKind::Sphere] {
        let mut group = c.benchmark_group(format!("step/{kind:?}").to_lowercase());
        group.sample_size(10);
        for grid in [32u32, 64, 128] {
            let s = scene(kind, grid);
            let mut cpu = CpuSim::new(s.clone());
            for _ in 0..warm_steps(kind) {
                cpu.step();
            }
            group.bench_function(BenchmarkId::new("cpu", grid), |b| b.iter(|| cpu.step()));
            if let Some((ctx, kernels)) = &gpu {
                let sim = GpuSim::new(kernels.clone(), &ctx.device, &ctx.queue, &s)
                    .expect("fits the adapter");
                for _ in 0..warm_steps(kind) {
                    sim.step();
                }
                ctx.finish().expect("device healthy");
                group.bench_function(BenchmarkId::new("gpu", grid), |b| {
                    b.iter(|| {
                        sim.step();
                        ctx.finish().expect("device healthy");
                    })
                });
            }
        }
        group.finish();
    }
}

criterion_group!(benches, step);
criterion_main!(benches);
