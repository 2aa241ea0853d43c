//! Criterion benchmarks of the learned models, CPU and GPU side by side:
//!
//! - `network/<net>/<backend>/<contacts>`: the network and its input
//!   Jacobian over a batch of contacts (throughput in contacts/s; the
//!   floating-point work per contact, as each kernel does it, is printed
//!   first, so GFLOP/s is contacts/s × that). Sizes run from 1k to 1M contacts while a batch
//!   stays under a work budget (smaller on a software adapter).
//! - `step64/<backend>/<model>`: one step of the thesis sphere scene at
//!   64² from the same in-contact state, analytic models against their
//!   networks.
//! - `period/<backend>/<model>`: the thesis's headline measure, the wall
//!   time to simulate one sphere period (2 s, 200 steps) at 32².
//!
//! `cargo bench --bench network`

mod common;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::CpuSim;
use wgcloth::gpu::GpuSim;
use wgcloth::gpu::mlp::{BatchShape, NetworkBatch};
use wgcloth::nn::weights::{self, Network};
use wgcloth_cli::bench::{PERIOD_STEPS, UNTIMED_STEPS, VARIANTS};
use wgcloth_learn::domain::{Rng, uniform_inputs};

const SIZES: [usize; 6] = [1_000, 4_000, 16_000, 64_000, 256_000, 1_000_000];

/// The shipped networks by file stem.
fn networks() -> Vec<(&'static str, Network)> {
    weights::SHIPPED
        .iter()
        .map(|shipped| {
            let name = shipped.path.rsplit('/').next().unwrap_or(shipped.path);
            (
                name.trim_end_matches(".safetensors"),
                shipped.read().expect("shipped weights").network(),
            )
        })
        .collect()
}

fn network(c: &mut Criterion) {
    let gpu = common::gpu();
    let software = gpu
        .as_ref()
        .is_some_and(|(ctx, _)| ctx.adapter.device_type == wgpu::DeviceType::Cpu);
    for (name, network) in networks() {
        let (net, wrt) = (&network.mlp, network.kind.wrt());
        // A contact is one row of the network per evaluation, each timed
        // with its whole Jacobian.
        let evaluations = network.kind.evaluations();
        let flop = 2 * net.jacobian_multiply_adds() * evaluations;
        eprintln!("network {name}: {flop} floating-point operations per contact on the CPU");
        let mut rng = Rng::new(5);
        let inputs: Vec<f32> = (0..SIZES[SIZES.len() - 1])
            .flat_map(|_| uniform_inputs(network.kind, &mut rng))
            .collect();
        let width = net.inputs() * evaluations;
        let mut group = c.benchmark_group(format!("network/{name}"));
        group.sample_size(10);
        // Work per batch: 4 GFLOP on the CPU or a software adapter, 2 TFLOP
        // on a real GPU.
        let cpu_budget = 4e9;
        let gpu_budget = if software { 4e9 } else { 2e12 };
        for n in SIZES {
            let work = (n * flop) as f64;
            group.throughput(Throughput::Elements(n as u64));
            let batch = &inputs[..n * width];
            if work <= cpu_budget {
                group.bench_function(BenchmarkId::new("cpu", n), |b| {
                    b.iter(|| net.forward_jacobian_parallel(batch, wrt.clone()))
                });
            }
            if let Some((ctx, kernels)) = gpu.as_ref().filter(|_| work <= gpu_budget) {
                let on_gpu = NetworkBatch::new(
                    kernels,
                    &ctx.device,
                    net,
                    wrt.clone(),
                    BatchShape::new(n * evaluations),
                )
                .expect("fits the adapter");
                if n == SIZES[0] {
                    eprintln!(
                        "network {name}: {} floating-point operations per contact on the GPU ({} kernel)",
                        2 * on_gpu.network().multiply_adds_per_contact() * evaluations,
                        on_gpu.network().kernel().name()
                    );
                }
                on_gpu.upload(&ctx.queue, batch).expect("batch fits");
                group.bench_function(BenchmarkId::new("gpu", n), |b| {
                    b.iter(|| {
                        on_gpu.run(&ctx.device, &ctx.queue);
                        ctx.finish().expect("device healthy");
                    })
                });
            }
        }
        group.finish();
    }
}

fn step64(c: &mut Criterion) {
    let gpu = common::gpu();
    let mut warm = CpuSim::new(common::scene(SceneKind::Sphere, ModelKind::Friction, 64));
    for _ in 0..UNTIMED_STEPS {
        warm.step();
    }
    let start = warm.state.clone();
    for backend in ["cpu", "gpu"] {
        let mut group = c.benchmark_group(format!("step64/{backend}"));
        group.sample_size(10);
        for v in VARIANTS {
            let scene = v.scene(64, 0).expect("valid benchmark scene");
            if backend == "cpu" {
                let mut sim = CpuSim::new(scene);
                group.bench_function(v.label(), |b| {
                    b.iter(|| {
                        sim.state.clone_from(&start);
                        sim.step()
                    })
                });
            } else if let Some((ctx, kernels)) = &gpu {
                let sim = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, &scene)
                    .expect("fits the adapter");
                group.bench_function(v.label(), |b| {
                    b.iter(|| {
                        sim.upload_state(&start);
                        sim.step();
                        ctx.finish().expect("device healthy");
                    })
                });
            }
        }
        group.finish();
    }
}

fn period(c: &mut Criterion) {
    let gpu = common::gpu();
    for backend in ["cpu", "gpu"] {
        let mut group = c.benchmark_group(format!("period/{backend}"));
        group.sample_size(10);
        for v in VARIANTS {
            let scene = v.scene(32, 0).expect("valid benchmark scene");
            if backend == "cpu" {
                group.bench_function(v.label(), |b| {
                    b.iter(|| {
                        let mut sim = CpuSim::new(scene.clone());
                        for _ in 0..PERIOD_STEPS {
                            sim.step();
                        }
                    })
                });
            } else if let Some((ctx, kernels)) = &gpu {
                group.bench_function(v.label(), |b| {
                    b.iter(|| {
                        let sim = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, &scene)
                            .expect("fits the adapter");
                        for _ in 0..PERIOD_STEPS {
                            sim.step();
                        }
                        ctx.finish().expect("device healthy");
                    })
                });
            }
        }
        group.finish();
    }
}

criterion_group!(benches, network, step64, period);
criterion_main!(benches);
