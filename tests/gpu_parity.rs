//! The GPU stages against their CPU twins on lavapipe (or any adapter).
//! Without an adapter these tests fail under CI=true and skip elsewhere.

use std::sync::Arc;

use glam::{Mat3, Vec3};
use wgcloth::config::SceneKind;
use wgcloth::cpu::{CpuSim, springs};
use wgcloth::gpu::{GpuContext, GpuSim, Kernels};
use wgcloth::{Config, Scene};

fn gpu() -> Option<(GpuContext, Arc<Kernels>)> {
    match GpuContext::headless() {
        Ok(ctx) => {
            let kernels = Arc::new(Kernels::new(&ctx.device).expect("kernels build"));
            Some((ctx, kernels))
        }
        Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => {
            panic!("CI needs a GPU adapter: {e}")
        }
        Err(e) => {
            eprintln!("skipping GPU test: {e}");
            None
        }
    }
}

fn max_dev(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f32::max)
}

fn max_norm(a: &[Vec3]) -> f32 {
    a.iter().map(|p| p.length()).fold(0.0, f32::max)
}

fn mat_dev(a: &[Mat3], b: &[Mat3]) -> (f32, f32) {
    let fro = |m: Mat3| m.to_cols_array().iter().map(|e| e * e).sum::<f32>().sqrt();
    let dev = a
        .iter()
        .zip(b)
        .map(|(p, q)| fro(*p - *q))
        .fold(0.0, f32::max);
    (dev, a.iter().map(|m| fro(*m)).fold(0.0, f32::max))
}

fn hang(grid: u32) -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    Scene::new(&c).unwrap()
}

/// A CPU simulator advanced `steps` steps, so springs are stretched and moving.
fn cpu_after(scene: &Scene, steps: usize) -> CpuSim {
    let mut cpu = CpuSim::new(scene.clone());
    for _ in 0..steps {
        cpu.step();
    }
    cpu
}

#[test]
fn springs_and_assembly_match_the_cpu_on_the_same_state() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = hang(12);
    let mut cpu = cpu_after(&scene, 7);
    let gpu = GpuSim::new(kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&cpu.state.x, &cpu.state.v, cpu.state.time as f32);
    gpu.step();
    cpu.step();

    let (gf, gk) = gpu.read_springs().unwrap();
    let mut cf = vec![Vec3::ZERO; scene.cloth.springs.len()];
    let mut ck = vec![Mat3::ZERO; scene.cloth.springs.len()];
    // The CPU's state before its step: recompute from the uploaded one.
    let before = cpu_after(&scene, 7);
    springs::evaluate(&scene.cloth, &before.state.x, &mut cf, &mut ck);
    let gk: Vec<Mat3> = gk.iter().map(|m| m.to_mat3()).collect();
    assert!(
        max_dev(&gf, &cf) <= 1e-4 * max_norm(&cf),
        "spring forces {} vs {}",
        max_dev(&gf, &cf),
        max_norm(&cf)
    );
    let (dev, norm) = mat_dev(&gk, &ck);
    assert!(dev <= 1e-5 * norm, "spring blocks {dev} vs {norm}");

    let (gd, go, gb) = gpu.read_system().unwrap();
    let (a, b) = cpu.system();
    let (dev, norm) = mat_dev(&gd.iter().map(|m| m.to_mat3()).collect::<Vec<_>>(), &a.diag);
    assert!(dev <= 1e-5 * norm, "A diagonal {dev} vs {norm}");
    let (dev, norm) = mat_dev(&go.iter().map(|m| m.to_mat3()).collect::<Vec<_>>(), &a.off);
    assert!(dev <= 1e-5 * norm, "A off-diagonal {dev} vs {norm}");
    assert!(
        max_dev(&gb, b) <= 1e-5 * max_norm(b),
        "b {} vs {}",
        max_dev(&gb, b),
        max_norm(b)
    );
}

#[test]
fn hanging_cloth_runs_like_the_cpu_for_60_steps() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = hang(16);
    let cpu = cpu_after(&scene, 60);
    let gpu = GpuSim::new(kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    for _ in 0..60 {
        gpu.step();
    }
    let x = gpu.read_positions().unwrap();
    let dev = max_dev(&x, &cpu.state.x);
    let state = gpu.read_state().unwrap();
    eprintln!("60 steps: largest position deviation {dev:.3e} m; GPU state {state:?}");
    assert_eq!(state.steps, 60);
    assert_eq!(state.cg_iterations_total, 60 * 25);
    assert!((state.time - 0.6).abs() < 1e-5);
    assert!(dev < 1e-4, "GPU and CPU drifted {dev} m apart");
    for (i, p) in scene.cloth.pinned.iter().enumerate() {
        if *p {
            assert_eq!(x[i], scene.cloth.rest_positions[i]);
        }
    }
}
