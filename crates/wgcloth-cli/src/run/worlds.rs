//! A batch of worlds (`run --worlds N`, `--sweep FILE`; issue 67): every
//! world steps together, the CPU path spreading them over its threads
//! (`wgcloth::cpu::worlds`), the GPU in one step's dispatches
//! (`GpuSim::with_worlds`). A world that diverges stops there on the CPU;
//! on the GPU its region steps on unread. The rest go on either way.
//! What it reports: one line a world and one for the batch.

use std::time::Instant;

use serde::Serialize;

use super::report::{RESIDUAL_GOAL, Tally, median, peak_resident_bytes};
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::cpu::{self, integrate};
use wgcloth::error::Result;
use wgcloth::gpu::{GpuContext, GpuSim, Kernels, context::describe};
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

/// [`run_worlds`] on the GPU: the batch records each step once for every
/// world, and reads back every world's statistics after it (one copy).
pub fn run_worlds_gpu(
    ctx: &GpuContext,
    scenes: Vec<Scene>,
    set: &[String],
    steps: u64,
    mut progress: impl FnMut(u64),
) -> Result<BatchReport> {
    let kernels = Kernels::new(&ctx.device)?;
    let batch = GpuSim::with_worlds(&kernels, &ctx.device, &ctx.queue, &scenes)?;
    let n = scenes.len();
    // Per world: iterations, most iterations, worst residual, steps above
    // the goal, contacts, deepest penetration.
    let mut iterations = vec![(0u64, 0u32); n];
    let mut residuals = vec![(0f32, 0u64); n];
    let mut taken = vec![0u64; n];
    let mut diverged: Vec<Option<Divergence>> = vec![None; n];
    let mut last = batch.read_world_states()?;
    let mut wall_ms = Vec::new();
    let started = Instant::now();
    for k in 0..steps {
        let start = Instant::now();
        batch.step();
        let states = batch.read_world_states()?;
        wall_ms.push(start.elapsed().as_secs_f64() * 1e3);
        for (w, s) in states.iter().enumerate() {
            if diverged[w].is_some() {
                continue;
            }
            taken[w] = k + 1;
            iterations[w].0 += s.last_iterations as u64;
            iterations[w].1 = iterations[w].1.max(s.last_iterations);
            let r = s.last_residual;
            residuals[w].0 = residuals[w].0.max(r);
            residuals[w].1 += u64::from(r > RESIDUAL_GOAL || r.is_nan());
            let breakdown = s.cg_breakdowns > last[w].cg_breakdowns;
            if health::failed(s.health, breakdown) {
                let (x, v, _) = batch.read_world(w as u32)?;
                let (diag, _, b) = batch.read_world_system(w as u32)?;
                diverged[w] = Some(health::diagnose(&FailedStep {
                    step: k + 1,
                    flags: s.health,
                    breakdown,
                    diag: &diag,
                    b: &b,
                    x: &x,
                    v: &v,
                    max_speed: scenes[w].config.solver.max_speed,
                }));
            }
        }
        last = states;
        progress(k + 1);
    }
    ctx.finish()?;
    let seconds = started.elapsed().as_secs_f64();
    let mut worlds = Vec::with_capacity(n);
    for (w, scene) in scenes.iter().enumerate() {
        let (x, v, state) = batch.read_world(w as u32)?;
        let done = taken[w].max(1) as f64;
        worlds.push(WorldReport {
            world: w,
            set: set.get(w).cloned().unwrap_or_default(),
            steps: taken[w],
            finite: x.iter().chain(&v).all(|p| p.is_finite()),
            divergence: diverged[w].clone(),
            cg_iterations_mean: iterations[w].0 as f64 / done,
            cg_iterations_max: iterations[w].1,
            cg_residual_max: residuals[w].0,
            cg_steps_above_goal: residuals[w].1,
            max_penetration: f32::from_bits(state.max_penetration_bits),
            contacts_mean: state.contacts_total as f64 / state.steps.max(1) as f64,
            energy_final: cpu::energy(scene, &x, &v).total(),
            failsafe_share: None,
        });
    }
    let world_steps: u64 = taken.iter().sum();
    Ok(BatchReport {
        backend: "gpu".into(),
        adapter: describe(&ctx.adapter),
        steps,
        ms_per_step: median(&mut wall_ms),
        world_steps_per_second: world_steps as f64 / seconds.max(1e-9),
        peak_resident_bytes: peak_resident_bytes(),
        worlds,
    })
}
