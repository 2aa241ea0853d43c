//! Setup shared by the criterion benches.

use std::sync::Arc;

use wgcloth::Scene;
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::gpu::{GpuContext, Kernels};

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

/// A benchmark scene: `wgcloth_cli::bench::scene`, the thesis's solver.
pub fn scene(kind: SceneKind, model: ModelKind, grid: u32) -> Scene {
    wgcloth_cli::bench::scene(kind, model, grid).expect("valid benchmark scene")
}
