//! A batch of worlds (`run --worlds N`, `--sweep FILE`; issue 67): every
//! world steps together, the CPU path spreading them over its threads
//! (`wgcloth::cpu::worlds`). A world that diverges stops there and the
//! rest go on. What it reports: one line a world and one for the batch.

use std::time::Instant;

use serde::Serialize;

use super::report::{Tally, median, peak_resident_bytes};
use wgcloth::cpu::integrate;
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::error::Result;
use wgcloth::health::{self, Divergence, FailedStep};
use wgcloth::scene::Scene;
use wgcloth::stage::SelfContactStages;

/// One world's run.
#[derive(Clone, Debug, Serialize)]
pub struct WorldReport {
    /// Its place in the batch, from 0.
    pub world: usize,
    /// What its sweep set (`run --sweep`), as dotted `key = value` pairs.
    pub set: String,
    /// Steps it took: all of them, or up to the one that diverged.
    pub steps: u64,
    pub finite: bool,
    /// Where it diverged and stopped (`health::diagnose`, on the failing
    /// step's last solve).
    pub divergence: Option<Divergence>,
    pub cg_iterations_mean: f64,
    pub cg_iterations_max: u32,
    pub cg_residual_max: f32,
    pub cg_steps_above_goal: u64,
    /// Deepest any cloth vertex got inside the rigid surface, m.
    pub max_penetration: f32,
    pub contacts_mean: f64,
    /// Total energy at the end, J.
    pub energy_final: f64,
    /// Stage "separate"'s share of vertex steps (`[self_contact]` on).
    pub failsafe_share: Option<f64>,
}

/// A batch run: the worlds and what they took together.
#[derive(Clone, Debug, Serialize)]
pub struct BatchReport {
    pub backend: String,
    pub adapter: String,
    /// Steps each world was asked for.
    pub steps: u64,
    /// Median wall time of a step of the whole batch, ms.
    pub ms_per_step: f64,
    /// World-steps a second over the run's wall time.
    pub world_steps_per_second: f64,
    pub peak_resident_bytes: Option<u64>,
    pub worlds: Vec<WorldReport>,
}

impl BatchReport {
    /// One line a world, then the batch's.
    pub fn summary(&self) -> String {
        let mut out = String::new();
        for w in &self.worlds {
            let state = match &w.divergence {
                Some(d) => format!(
                    "diverged at step {}, vertex {}: {}",
                    d.step, d.vertex, d.reason
                ),
                None if w.finite => "finite".to_string(),
                None => "NOT FINITE".to_string(),
            };
            let set = match w.set.is_empty() {
                true => String::new(),
                false => format!(" ({})", w.set),
            };
            out += &format!(
                "world {:>3}{set}: {} steps, PCG {:.1} iterations (most {}, worst residual {:.1e}), \
                 deepest {:.2} mm, {:.1} contacts, energy {:.4} J, {state}\n",
                w.world,
                w.steps,
                w.cg_iterations_mean,
                w.cg_iterations_max,
                w.cg_residual_max,
                w.max_penetration * 1e3,
                w.contacts_mean,
                w.energy_final,
            );
        }
        out += &format!(
            "batch: {} worlds × {} steps on {}: {:.1} ms a batch step (median), {:.1} world-steps/s",
            self.worlds.len(),
            self.steps,
            self.adapter,
            self.ms_per_step,
            self.world_steps_per_second
        );
        out
    }
}

/// Runs `scenes` as one batch for `steps` steps on the CPU path, each
/// world described by what its sweep `set` (none where empty);
/// `progress` is told the batch steps done.
pub fn run_worlds(
    scenes: Vec<Scene>,
    set: &[String],
    steps: u64,
    mut progress: impl FnMut(u64),
) -> Result<BatchReport> {
    let stages: Vec<SelfContactStages> = (scenes.iter())
        .map(|s| SelfContactStages::of(&s.config.self_contact))
        .collect();
    let mut batch = CpuWorlds::new(scenes);
    let n = batch.worlds().len();
    let mut tallies: Vec<Tally> = (0..n).map(|_| Tally::default()).collect();
    let mut diverged: Vec<Option<Divergence>> = vec![None; n];
    let mut wall_ms = Vec::new();
    let started = Instant::now();
    for k in 0..steps {
        let start = Instant::now();
        let stats = batch.step_where(|w| diverged[w].is_none());
        wall_ms.push(start.elapsed().as_secs_f64() * 1e3);
        for (w, s) in stats.iter().enumerate() {
            let Some(s) = s else { continue };
            tallies[w].push(s, stages[w]);
            let sim = &batch.worlds()[w];
            let max_speed = sim.scene.config.solver.max_speed;
            let flags = integrate::health(&sim.state.x, &sim.state.v, max_speed);
            if health::failed(flags, s.pcg.breakdown) {
                let (matrix, b) = sim.system();
                diverged[w] = Some(health::diagnose(&FailedStep {
                    step: k + 1,
                    flags,
                    breakdown: s.pcg.breakdown,
                    diag: &matrix.diag,
                    b,
                    x: &sim.state.x,
                    v: &sim.state.v,
                    max_speed,
                }));
            }
        }
        progress(k + 1);
    }
    let seconds = started.elapsed().as_secs_f64();
    let worlds = (batch.worlds().iter().zip(tallies).zip(&diverged))
        .enumerate()
        .map(|(world, ((sim, t), divergence))| {
            let done = sim.state.step.max(1) as f64;
            WorldReport {
                world,
                set: set.get(world).cloned().unwrap_or_default(),
                steps: sim.state.step,
                finite: sim.is_finite(),
                divergence: divergence.clone(),
                cg_iterations_mean: t.cg_iters as f64 / done,
                cg_iterations_max: t.residuals.most_iterations,
                cg_residual_max: t.residuals.max,
                cg_steps_above_goal: t.residuals.above_goal,
                max_penetration: t.max_penetration,
                contacts_mean: t.contacts as f64 / done,
                energy_final: sim.energy().total(),
                failsafe_share: (stages[world].separate).then(|| {
                    t.self_contact(done, sim.scene.cloth.vertex_count())
                        .failsafe_share
                }),
            }
        })
        .collect::<Vec<_>>();
    let world_steps: u64 = worlds.iter().map(|w| w.steps).sum();
    Ok(BatchReport {
        backend: "cpu".into(),
        adapter: format!(
            "CPU reference path ({} threads)",
            rayon::current_num_threads()
        ),
        steps,
        ms_per_step: median(&mut wall_ms),
        world_steps_per_second: world_steps as f64 / seconds.max(1e-9),
        peak_resident_bytes: peak_resident_bytes(),
        worlds,
    })
}
