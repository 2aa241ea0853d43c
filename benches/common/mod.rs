//! Setup shared by the criterion benches.

use std::sync::Arc;

use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::gpu::{GpuContext, Kernels};
use wgcloth::{Config, Scene};

/// The headless adapter with its kernels, or None (with a notice) where
/// there is none: the GPU benches are then skipped.
pub fn gpu() -> Option<(GpuContext, Arc<Kernels>)> {
    match GpuContext::headless() {
        Ok(ctx) => {
            let kernels = Arc::new(Kernels::new(&ctx.device).expect("kernels"));
            eprintln!("GPU: {}", wgcloth::gpu::context::describe(&ctx.adapter));
            Some((ctx, kernels))
        }
        Err(e) => {
            eprintln!("no GPU benchmarks: {e}");
            None
        }
    }
}

/// A benchmark scene: N×N cloth, 25 PCG iterations at tolerance 0 (the
/// thesis's solver).
pub fn scene(kind: SceneKind, model: ModelKind, grid: u32) -> Scene {
    let mut c = Config {
        scene: kind,
        model,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    c.solver.cg_iters = 25;
    c.solver.cg_tol = 0.0;
    Scene::new(&c).expect("valid benchmark scene")
}
