//! Batched worlds against as many separate simulators (issue 67):
//! world-steps a second of N worlds of the default run (friction-net,
//! every solve to 1e-3), stepped as one batch and one simulator after
//! another, side by side in one run, each from the same state: one world
//! run through the untimed steps, so that the body presses the cloth.

use std::time::Instant;

use serde::Serialize;

use super::{BenchOptions, HEADLINE, UNTIMED_STEPS};
use wgcloth::cpu::CpuSim;
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::error::Result;

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
}

/// The CPU's rows, one for each of `opts.worlds`.
pub fn rows(opts: &BenchOptions, progress: &mut impl FnMut(&str)) -> Result<Vec<WorldsRow>> {
    if opts.worlds.is_empty() {
        return Ok(Vec::new());
    }
    let grid = opts.period_grid;
    let scene = HEADLINE.scene(grid, opts.substeps)?;
    let mut warm = CpuSim::new(scene.clone());
    for _ in 0..UNTIMED_STEPS {
        warm.step();
    }
    let steps = opts.worlds_steps;
    let from_warm =
        |sims: &mut [CpuSim]| sims.iter_mut().for_each(|s| s.state = warm.state.clone());
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
        progress(&format!(
            "  {batched:.1} world-steps/s batched, {separate:.1} separate"
        ));
        rows.push(WorldsRow {
            backend: "cpu".into(),
            worlds: n,
            grid,
            steps,
            batched,
            separate,
            ratio: batched / separate,
        });
    }
    Ok(rows)
}
