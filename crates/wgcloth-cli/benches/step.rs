//! Criterion benchmark of one step, CPU and GPU side by side in one run:
//! the hanging cloth and the thesis sphere scene (friction model) at 32²,
//! 64² and 128², 25 PCG iterations, tolerance 0 (the thesis's solver).
//! The GPU is whatever adapter the headless constructor picks (lavapipe
//! here); it is skipped with a notice where there is none.
//!
//! `cargo bench --bench step`

mod common;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::CpuSim;
use wgcloth::gpu::GpuSim;

/// Steps run before timing, so the sphere is pushing the cloth.
fn warm_steps(scene: SceneKind) -> usize {
    if scene == SceneKind::Sphere { 80 } else { 5 }
}

fn step(c: &mut Criterion) {
    let gpu = common::gpu();
    for kind in [SceneKind::Hang, SceneKind::Sphere] {
        let mut group = c.benchmark_group(format!("step/{kind:?}").to_lowercase());
        group.sample_size(10);
        for grid in [32u32, 64, 128] {
            let s = common::scene(kind, ModelKind::Friction, grid);
            let mut cpu = CpuSim::new(s.clone());
            for _ in 0..warm_steps(kind) {
                cpu.step();
            }
            group.bench_function(BenchmarkId::new("cpu", grid), |b| b.iter(|| cpu.step()));
            if let Some((ctx, kernels)) = &gpu {
                let sim = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, &s)
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
