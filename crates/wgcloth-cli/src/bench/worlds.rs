//! Batched worlds against as many separate simulators (issue 67):
//! world-steps a second of N worlds of the default run (every solve to
//! 1e-3), stepped as one batch and one simulator after another, side by
//! side in one run, each from the same state: one world run through the
//! untimed steps, so that the body presses the cloth: a batch of
//! `CpuWorlds` on the CPU, one `GpuSim::with_worlds` on the GPU.

use std::time::Instant;

use serde::Serialize;

use super::{BenchOptions, HEADLINE, UNTIMED_STEPS, median};
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::cpu::{CpuSim, State};
use wgcloth::error::{Error, Result};
use wgcloth::gpu::worlds::MAX_WORLDS;
use wgcloth::gpu::{GpuContext, GpuSim, Kernels};
use wgcloth::scene::Scene;

/// One batch size on one backend.
#[derive(Clone, Debug, Serialize)]
pub struct WorldsRow {
    pub backend: String,
    pub worlds: usize,
    pub grid: u32,
    /// Steps timed, each of every world.
    pub steps: u64,
    /// World-steps a second stepped as one batch.
    pub batched: f64,
    /// World-steps a second stepped as separate simulators, one after
    /// another.
    pub separate: f64,
    /// `batched` over `separate`.
    pub ratio: f64,
    /// Dispatches a batch step records (GPU), and of them the network
    /// batch's: the rest are one world's, whatever the worlds; the network
    /// takes a chunk's more for each chunk the worlds' contacts fill.
    pub dispatches: Option<(u32, u32)>,
    /// The host's time to record a batch step (GPU), median, ms.
    pub record_ms: Option<f64>,
}

/// The rows' scene at `grid`, and its state after the untimed steps on
/// the CPU.
fn warm_scene(grid: u32, opts: &BenchOptions) -> Result<(Scene, State)> {
    let scene = HEADLINE.scene(grid, opts.substeps)?;
    let mut warm = CpuSim::new(scene.clone());
    for _ in 0..UNTIMED_STEPS {
        warm.step();
    }
    Ok((scene, warm.state))
}

/// The row of `worlds` worlds at `grid`, `steps` timed, at `batched` and
/// `separate` world-steps a second, told to `progress` too.
fn row(
    backend: &str,
    (worlds, grid, steps): (usize, u32, u64),
    (batched, separate): (f64, f64),
    (dispatches, record_ms): (Option<(u32, u32)>, Option<f64>),
    progress: &mut impl FnMut(&str),
) -> WorldsRow {
    progress(&format!(
        "  {batched:.1} world-steps/s batched, {separate:.1} separate"
    ));
    WorldsRow {
        backend: backend.into(),
        worlds,
        grid,
        steps,
        batched,
        separate,
        ratio: batched / separate,
        dispatches,
        record_ms,
    }
}

/// The CPU's rows, one for each of `opts.worlds`.
pub fn rows(opts: &BenchOptions, progress: &mut impl FnMut(&str)) -> Result<Vec<WorldsRow>> {
    if opts.worlds.is_empty() {
        return Ok(Vec::new());
    }
    let grid = opts.period_grid;
    let (scene, warm) = warm_scene(grid, opts)?;
    let steps = opts.worlds_steps;
    let from_warm = |sims: &mut [CpuSim]| sims.iter_mut().for_each(|s| s.state = warm.clone());
    let mut rows = Vec::new();
    for &n in &opts.worlds {
        progress(&format!("worlds cpu {n} × {grid}²"));
        let mut separate: Vec<CpuSim> = (0..n).map(|_| CpuSim::new(scene.clone())).collect();
        from_warm(&mut separate);
        let start = Instant::now();
        for _ in 0..steps {
            separate.iter_mut().for_each(|s| _ = s.step());
        }
        let separate = (n as u64 * steps) as f64 / start.elapsed().as_secs_f64();
        let mut batch = CpuWorlds::new(vec![scene.clone(); n]);
        from_warm(batch.worlds_mut());
        let start = Instant::now();
        for _ in 0..steps {
            batch.step();
        }
        let batched = (n as u64 * steps) as f64 / start.elapsed().as_secs_f64();
        let timed = (batched, separate);
        rows.push(row("cpu", (n, grid, steps), timed, (None, None), progress));
    }
    Ok(rows)
}

/// The GPU's rows on `ctx`, one for each of `opts.worlds` a batch holds
/// ([`MAX_WORLDS`]): the separate simulators each record and submit their
/// step in turn, the batch its one step; each side waits for the device
/// once, at the end.
pub fn gpu_rows(
    opts: &BenchOptions,
    ctx: &GpuContext,
    progress: &mut impl FnMut(&str),
) -> Result<Vec<WorldsRow>> {
    let grid = opts.period_grid;
    let (scene, warm) = warm_scene(grid, opts)?;
    let kernels = Kernels::new(&ctx.device)?;
    let steps = opts.worlds_steps;
    let mut rows = Vec::new();
    for &n in &opts.worlds {
        if n > MAX_WORLDS as usize {
            progress(&format!(
                "worlds gpu {n}: a batch holds at most {MAX_WORLDS}"
            ));
            continue;
        }
        progress(&format!("worlds gpu {n} × {grid}²"));
        let scenes = vec![scene.clone(); n];
        let batch = match GpuSim::with_worlds(&kernels, &ctx.device, &ctx.queue, &scenes) {
            Err(e @ Error::Limit { .. }) => {
                progress(&format!("  no row: {e}"));
                continue;
            }
            batch => batch?,
        };
        let separate = (0..n)
            .map(|_| GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene))
            .collect::<Result<Vec<_>>>()?;
        separate.iter().for_each(|s| s.upload_state(&warm));
        ctx.finish()?;
        let start = Instant::now();
        for _ in 0..steps {
            separate.iter().for_each(|s| _ = s.step());
        }
        ctx.finish()?;
        let separate = (n as u64 * steps) as f64 / start.elapsed().as_secs_f64();
        batch.upload_state(&warm);
        ctx.finish()?;
        let start = Instant::now();
        // Each step recorded and submitted as `step` does, its recording timed.
        let (mut dispatches, mut record_ms) = (0, Vec::new());
        for _ in 0..steps {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            let recording = Instant::now();
            dispatches = dispatches.max(batch.encode_step(&mut encoder));
            record_ms.push(recording.elapsed().as_secs_f64() * 1e3);
            ctx.queue.submit([encoder.finish()]);
        }
        ctx.finish()?;
        let batched = (n as u64 * steps) as f64 / start.elapsed().as_secs_f64();
        let timed = (batched, separate);
        let recorded = (
            Some((dispatches, batch.network_dispatches())),
            Some(median(&mut record_ms)),
        );
        rows.push(row("gpu", (n, grid, steps), timed, recorded, progress));
    }
    Ok(rows)
}
