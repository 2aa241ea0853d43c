//! The library in an app's device: steps recorded into the app's encoder,
//! a lost device, limits an adapter lacks, the state's bytes, kernels
//! compiled once. Without an adapter these tests fail unless
//! WGCLOTH_NO_GPU_TESTS=1 opts out.

mod common;
#[path = "common/parity.rs"]
mod parity;

use std::sync::Arc;

use common::sphere;
use parity::{gpu, hang, random_mlp};
use wgcloth::Scene;
use wgcloth::config::ModelKind;
use wgcloth::gpu::{GpuContext, GpuSim, Kernels};

#[test]
fn steps_recorded_into_one_app_encoder_equal_separate_submissions() {
    let Some((ctx, kernels)) = gpu() else { return };
    // A cap of 40 iterations, more than these steps take: a fifth of the
    // default's dispatches for the chain to record.
    let mut config = sphere(12, ModelKind::Friction).config;
    config.solver.cg_iters = 40;
    // The solve run whole in one workgroup (the default at this size) and
    // as a chain of dispatches.
    for whole in [true, false] {
        config.solver.whole_solve_nodes = if whole { u32::MAX } else { 0 };
        embedded_steps(&ctx, &kernels, &Scene::new(&config).unwrap(), whole);
    }
}

fn embedded_steps(ctx: &GpuContext, kernels: &Arc<Kernels>, scene: &Scene, whole: bool) {
    let separate = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, scene).unwrap();
    for _ in 0..50 {
        separate.step();
    }
    // An embedding app: its own encoder, many steps, one submission; the
    // clock and the rigid body's motion live on the GPU.
    let embedded = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, scene).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let dispatches: u32 = (0..50).map(|_| embedded.encode_step(&mut encoder)).sum();
    ctx.queue.submit([encoder.finish()]);
    ctx.finish().unwrap();
    // 11 outside the solve, and the multigrid setup (per coarse level L
    // its operator, and per level but the coarsest its patch inverses).
    // Whole: PCG's init, init_scalars, the solve, correct and finish. As a
    // chain: PCG's init, init_scalars, spmv, conclude and finish; per
    // iteration `next` (but the first) and `advance`; a V-cycle (11 T + 2:
    // four forward patch sweeps, a residual and a restriction down, a guess
    // and four backward sweeps up, per level above the tail's first T; the
    // tail; the cloth's rᵀz) at the start and in every iteration.
    let levels = wgcloth::multigrid::levels(12, 12);
    let nodes: Vec<u32> = levels.iter().map(|l| l.nodes() as u32).collect();
    let (iters, coarse) = (scene.config.solver.cg_iters, levels.len() as u32 - 1);
    let cpu_adapter = ctx.adapter.device_type == wgpu::DeviceType::Cpu;
    let most = wgcloth::multigrid::tail_nodes(cpu_adapter);
    let cycle = 11 * wgcloth::multigrid::tail_from(&nodes, most) as u32 + 2;
    let pcg = match whole {
        true => 5 + 2 * coarse,
        false => 5 + (iters - 1) + iters * (1 + cycle) + 2 * coarse + cycle,
    };
    assert_eq!(
        dispatches,
        50 * (11 + pcg),
        "dispatches per step (whole {whole})"
    );
    assert_eq!(
        embedded.read_positions().unwrap(),
        separate.read_positions().unwrap()
    );
    assert_eq!(embedded.read_state().unwrap().steps, 50);
    assert!(
        embedded
            .positions()
            .usage()
            .contains(wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE)
    );
    assert!(
        embedded
            .indices()
            .usage()
            .contains(wgpu::BufferUsages::INDEX)
    );
    assert_eq!(
        embedded.index_count() as usize,
        3 * scene.cloth.triangles.len()
    );
}

#[test]
fn a_lost_device_is_an_error_not_a_panic_or_a_hang() {
    let Some((ctx, kernels)) = gpu() else { return };
    let sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &hang(8)).unwrap();
    sim.step();
    ctx.finish().unwrap();
    ctx.device.destroy();
    sim.step();
    let err = ctx
        .finish()
        .expect_err("a destroyed device must report an error");
    eprintln!("{err}");
    assert!(err.to_string().starts_with("GPU:"), "{err}");
}

#[test]
fn a_network_beyond_the_adapters_limits_is_one_clear_error() {
    let Some((ctx, _)) = gpu() else { return };
    drop(ctx);
    // A device that binds at most 1 MiB per storage buffer.
    let adapter = GpuContext::pick_adapter().unwrap();
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 1 << 20,
        ..adapter.limits()
    };
    let (device, _queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: limits,
        ..Default::default()
    }))
    .unwrap();
    let kernels = Arc::new(Kernels::new(&device).unwrap());
    let buffer = |size| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        })
    };
    let (inputs, count, outputs) = (buffer(64), buffer(64), buffer(1 << 12));
    let io = || wgcloth::gpu::mlp::BatchBuffers {
        inputs: &inputs,
        count: &count,
        outputs: &outputs,
    };
    // 10 × 30000 weights: 1.2 MB.
    let wide = random_mlp(&[10, 30000, 3], 1);
    let shape = wgcloth::gpu::mlp::BatchShape {
        kernel: wgcloth::gpu::mlp::NetworkKernel::Tiled,
        ..wgcloth::gpu::mlp::BatchShape::new(4)
    };
    let err = wgcloth::gpu::GpuMlp::new(&kernels, &device, &wide, 0..6, shape, io())
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("weights") && err.contains("bytes"), "{err}");
    // Weights that fit (0.5 MB), activations of one contact that do not:
    // 7 rows × 40000 floats = 1.1 MB.
    let one_wide = random_mlp(&[6, 1, 40000, 1, 3], 2);
    let err = wgcloth::gpu::GpuMlp::new(&kernels, &device, &one_wide, 0..6, shape, io())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        err.contains("activations") && err.contains("bytes"),
        "{err}"
    );
}

/// The scene's GPU state holds at least the step's per-vertex vectors
/// (x, v and their checkpoint copies, rest: 5 `vec4`s; b, r, z and q, both
/// directions, P⁻¹: 7 packed vec3s) and grows with the cloth, not faster.
#[test]
fn state_bytes_count_the_per_vertex_vectors_and_grow_with_the_cloth() {
    let Some((ctx, kernels)) = gpu() else { return };
    let bytes = |grid: u32| {
        let scene = sphere(grid, ModelKind::Friction);
        let sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        let n = scene.cloth.vertex_count() as u64;
        assert!(
            sim.state_bytes() >= (5 * 16 + 7 * 12) * n,
            "{grid}²: {}",
            sim.state_bytes()
        );
        sim.state_bytes() as f64
    };
    let growth = bytes(64) / bytes(32);
    assert!((3.0..=4.5).contains(&growth), "64² / 32²: {growth}");
}

/// A context compiles its kernels once: later calls, and its clones made
/// before or after, get the same ones.
#[test]
fn a_context_compiles_its_kernels_once() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let before = ctx.clone();
    let first = ctx.kernels().unwrap();
    assert!(Arc::ptr_eq(&first, &ctx.kernels().unwrap()));
    assert!(Arc::ptr_eq(&first, &before.kernels().unwrap()));
    assert!(Arc::ptr_eq(&first, &ctx.clone().kernels().unwrap()));
}
