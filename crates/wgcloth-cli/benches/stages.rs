//! Criterion benchmark of each stage of the step on its own, CPU and GPU
//! side by side: `stages/<stage>/<backend>/<grid>`, the thesis sphere scene
//! with the default network model (friction-net) at 32², 64² and 128², from
//! an in-contact state (80 steps in). A stage runs on what the earlier
//! stages of the last step left, so re-running it repeats the same work.
//! A GPU sample is one submission of the stage's pass and the wait for it,
//! so on a fast GPU the submission's fixed cost dominates the small
//! stages; `wgcloth bench` reads the passes' own timestamps instead.
//!
//! `cargo bench --bench stages`

mod common;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::{CpuSim, StepStats};
use wgcloth::gpu::GpuSim;
use wgcloth::stage::Stage;
use wgcloth_cli::bench::UNTIMED_STEPS;

fn stages(c: &mut Criterion) {
    let gpu = common::gpu();
    for grid in [32u32, 64, 128] {
        let scene = common::scene(SceneKind::Sphere, ModelKind::FrictionNet, grid);
        let mut cpu = CpuSim::new(scene.clone());
        for _ in 0..UNTIMED_STEPS {
            cpu.step();
        }
        let on_gpu = gpu.as_ref().map(|(ctx, kernels)| {
            let sim = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, &scene)
                .expect("fits the adapter");
            for _ in 0..UNTIMED_STEPS {
                sim.step();
            }
            ctx.finish().expect("device healthy");
            (ctx, sim)
        });
        // Integrate moves the cloth each time it runs; only measure, which
        // reads it, comes after.
        for stage in Stage::ALL {
            let mut group = c.benchmark_group(format!("stages/{}", stage.name()));
            group.sample_size(10);
            let mut stats = StepStats::default();
            group.bench_function(BenchmarkId::new("cpu", grid), |b| {
                b.iter(|| cpu.run_stage(stage, &mut stats))
            });
            if let Some((ctx, sim)) = &on_gpu {
                group.bench_function(BenchmarkId::new("gpu", grid), |b| {
                    b.iter(|| {
                        let mut encoder = ctx.device.create_command_encoder(&Default::default());
                        sim.record_stage(&mut encoder, stage);
                        ctx.queue.submit([encoder.finish()]);
                        ctx.finish().expect("device healthy");
                    })
                });
            }
            group.finish();
        }
    }
}

criterion_group!(benches, stages);
criterion_main!(benches);
