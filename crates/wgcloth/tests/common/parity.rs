//! Helpers of the GPU-against-CPU tests (stage_parity.rs, gpu_runs.rs,
//! embedding.rs): the adapter with its kernels, deviations, the hanging
//! cloth and random networks.
#![allow(dead_code)]

use std::sync::Arc;

use glam::{Mat3, Vec3};
use wgcloth::config::{Preconditioner, SceneKind, Smoother};
use wgcloth::cpu::CpuSim;
use wgcloth::gpu::{GpuContext, Kernels};
use wgcloth::math::Sym3;
use wgcloth::{Config, Scene};

pub fn gpu() -> Option<(GpuContext, Arc<Kernels>)> {
    let ctx = crate::common::gpu_context()?;
    let kernels = Arc::new(Kernels::new(&ctx.device).expect("kernels build"));
    Some((ctx, kernels))
}

pub fn max_dev(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f32::max)
}

pub fn max_norm(a: &[Vec3]) -> f32 {
    a.iter().map(|p| p.length()).fold(0.0, f32::max)
}

pub fn full(blocks: &[Sym3]) -> Vec<Mat3> {
    blocks.iter().map(|m| m.to_mat3()).collect()
}

pub fn mat_dev(a: &[Mat3], b: &[Mat3]) -> (f32, f32) {
    let fro = |m: Mat3| m.to_cols_array().iter().map(|e| e * e).sum::<f32>().sqrt();
    let dev = a
        .iter()
        .zip(b)
        .map(|(p, q)| fro(*p - *q))
        .fold(0.0, f32::max);
    (dev, a.iter().map(|m| fro(*m)).fold(0.0, f32::max))
}

pub fn hang(grid: u32) -> Scene {
    hang_solved(grid, MULTIGRID, 100, 1e-3)
}

/// Multigrid with the default smoother.
pub const MULTIGRID: (Preconditioner, Smoother) = (Preconditioner::Multigrid, Smoother::Patches);

/// Each preconditioner, multigrid with each smoother.
pub const PRECONDITIONERS: [(Preconditioner, Smoother); 3] = [
    (Preconditioner::Jacobi, Smoother::Patches),
    (Preconditioner::Multigrid, Smoother::Patches),
    (Preconditioner::Multigrid, Smoother::BlockJacobi),
];

pub fn hang_solved(
    grid: u32,
    (preconditioner, smoother): (Preconditioner, Smoother),
    iters: u32,
    tol: f32,
) -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    (c.solver.preconditioner, c.solver.smoother) = (preconditioner, smoother);
    (c.solver.cg_iters, c.solver.cg_tol) = (iters, tol);
    Scene::new(&c).unwrap()
}

/// Each of [`PRECONDITIONERS`] with each way the GPU runs its solve: as a
/// chain of dispatches (false), and with multigrid also whole in one
/// workgroup (true, `solver.whole_solve_nodes`).
pub fn gpu_solves() -> impl Iterator<Item = ((Preconditioner, Smoother), bool)> {
    PRECONDITIONERS.into_iter().flat_map(|solve| {
        let ways: &[bool] = match solve.0 {
            Preconditioner::Jacobi => &[false],
            Preconditioner::Multigrid => &[false, true],
        };
        ways.iter().map(move |&whole| (solve, whole))
    })
}

/// `scene` with its GPU solve run whole, or as a chain of dispatches.
pub fn solved_whole(mut scene: Scene, whole: bool) -> Scene {
    scene.config.solver.whole_solve_nodes = if whole { u32::MAX } else { 0 };
    scene
}

/// A CPU simulator advanced `steps` steps, so springs are stretched and moving.
pub fn cpu_after(scene: &Scene, steps: usize) -> CpuSim {
    let mut cpu = CpuSim::new(scene.clone());
    for _ in 0..steps {
        cpu.step();
    }
    cpu
}

/// A random network with the given layer sizes (deterministic).
pub fn random_mlp(sizes: &[usize], seed: u64) -> wgcloth::nn::Mlp {
    let mut s = seed;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    wgcloth::nn::Mlp {
        layers: sizes
            .windows(2)
            .map(|w| wgcloth::nn::Layer {
                inputs: w[0],
                outputs: w[1],
                weight: (0..w[0] * w[1])
                    .map(|_| next() * 1.5 / (w[0] as f32).sqrt())
                    .collect(),
                bias: (0..w[1]).map(|_| 0.1 * next()).collect(),
            })
            .collect(),
        negative_slope: 0.01,
    }
}
