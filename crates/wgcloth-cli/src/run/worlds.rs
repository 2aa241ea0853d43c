//! A batch of worlds (`run --worlds N`, `--sweep FILE`; issue 67): every
//! world steps together, the CPU path spreading them over its threads
//! (`wgcloth::cpu::worlds`), the GPU in one step's dispatches
//! (`GpuSim::with_worlds`). A world that diverges stops there on the CPU;
//! on the GPU its region steps on unread. The rest go on either way.
//! What it reports: one line a world and one for the batch.

use std::time::Instant;

use serde::Serialize;

use super::Chosen;
use super::report::{RESIDUAL_GOAL, Tally, median, peak_resident_bytes};
use glam::Vec3;
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::cpu::{self, integrate};
use wgcloth::error::{Error, Result};
use wgcloth::gpu::layout::StepState;
use wgcloth::gpu::{GpuContext, GpuSim, context::describe};
use wgcloth::health::{self, Divergence, FailedStep};
use wgcloth::scene::Scene;
use wgcloth::stage::SelfContactStages;

/// One world's run.
#[derive(Clone, Debug, Default, Serialize)]
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

/// A batch of worlds that steps when asked and tallies each world as it
/// goes: what `run --worlds` loops over, and what the Python package's
/// `Simulator` holds.
pub struct Batch {
    on: On,
    /// What each world's sweep set, for its report line.
    set: Vec<String>,
    /// Batch steps taken.
    steps: u64,
    /// Per world: the steps it took, up to one that diverged.
    taken: Vec<u64>,
    diverged: Vec<Option<Divergence>>,
    /// Each batch step's wall time, ms, and their sum, s.
    wall_ms: Vec<f64>,
    seconds: f64,
}

enum On {
    Cpu {
        batch: CpuWorlds,
        stages: Vec<SelfContactStages>,
        tallies: Vec<Tally>,
    },
    Gpu {
        ctx: Box<GpuContext>,
        sim: Box<GpuSim>,
        scenes: Vec<Scene>,
        /// The last step's statistics of every world.
        last: Vec<StepState>,
        /// Per world: iterations, and the most a step took.
        iterations: Vec<(u64, u32)>,
        /// Per world: the worst residual, and the steps above the goal.
        residuals: Vec<(f32, u64)>,
    },
}

impl Batch {
    /// `scenes` on the CPU path, each world described by what its sweep
    /// `set` (none where empty).
    pub fn cpu(scenes: Vec<Scene>, set: &[String]) -> Batch {
        let stages = (scenes.iter())
            .map(|s| SelfContactStages::of(&s.config.self_contact))
            .collect();
        let n = scenes.len();
        Batch::on(
            On::Cpu {
                batch: CpuWorlds::new(scenes),
                stages,
                tallies: (0..n).map(|_| Tally::default()).collect(),
            },
            n,
            set,
        )
    }

    /// `scenes` on the GPU of `ctx`: a batch stepped in one step's
    /// dispatches (`GpuSim::with_worlds`), or one scene of any kind alone,
    /// each solve to the whole PCG cap.
    pub fn gpu(ctx: &GpuContext, scenes: Vec<Scene>, set: &[String]) -> Result<Batch> {
        let kernels = ctx.kernels()?;
        let sim = Box::new(match scenes.len() {
            1 => GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scenes[0])?,
            _ => GpuSim::with_worlds(&kernels, &ctx.device, &ctx.queue, &scenes)?,
        });
        let n = scenes.len();
        let last = sim.read_world_states()?;
        ctx.fault()?;
        Ok(Batch::on(
            On::Gpu {
                ctx: Box::new(ctx.clone()),
                sim,
                scenes,
                last,
                iterations: vec![(0, 0); n],
                residuals: vec![(0.0, 0); n],
            },
            n,
            set,
        ))
    }

    fn on(on: On, n: usize, set: &[String]) -> Batch {
        Batch {
            on,
            set: (0..n)
                .map(|w| set.get(w).cloned().unwrap_or_default())
                .collect(),
            steps: 0,
            taken: vec![0; n],
            diverged: vec![None; n],
            wall_ms: Vec::new(),
            seconds: 0.0,
        }
    }

    /// Worlds in the batch.
    pub fn worlds(&self) -> usize {
        self.taken.len()
    }

    /// The batch's scenes, world after world.
    pub fn scenes(&self) -> Vec<&Scene> {
        match &self.on {
            On::Cpu { batch, .. } => batch.worlds().iter().map(|s| &s.scene).collect(),
            On::Gpu { scenes, .. } => scenes.iter().collect(),
        }
    }

    /// "cpu" or "gpu": where the batch steps.
    pub fn backend(&self) -> &'static str {
        match &self.on {
            On::Cpu { .. } => "cpu",
            On::Gpu { .. } => "gpu",
        }
    }

    /// The adapter the batch steps on, or the CPU path and its threads.
    pub fn adapter(&self) -> String {
        match &self.on {
            On::Cpu { .. } => format!(
                "CPU reference path ({} threads)",
                rayon::current_num_threads()
            ),
            On::Gpu { ctx, .. } => describe(&ctx.adapter),
        }
    }

    /// Batch steps taken so far.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Steps the batch one step. A world that diverges stops there on the
    /// CPU; on the GPU its region steps on unread. The rest go on.
    pub fn step(&mut self) -> Result<()> {
        let k = self.steps;
        let start = Instant::now();
        let (taken, diverged) = (&mut self.taken, &mut self.diverged);
        match &mut self.on {
            On::Cpu {
                batch,
                stages,
                tallies,
            } => {
                let stats = batch.step_where(|w| diverged[w].is_none());
                self.wall_ms.push(start.elapsed().as_secs_f64() * 1e3);
                for (w, s) in stats.iter().enumerate() {
                    let Some(s) = s else { continue };
                    taken[w] = k + 1;
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
            }
            On::Gpu {
                ctx,
                sim,
                scenes,
                last,
                iterations,
                residuals,
            } => {
                sim.step();
                let states = sim.read_world_states()?;
                ctx.fault()?;
                self.wall_ms.push(start.elapsed().as_secs_f64() * 1e3);
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
                        let (x, v, _) = sim.read_world(w as u32)?;
                        let (diag, _, b) = sim.read_world_system(w as u32)?;
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
                *last = states;
            }
        }
        self.seconds += start.elapsed().as_secs_f64();
        self.steps += 1;
        Ok(())
    }

    /// Every world's positions and velocities, world after world.
    pub fn state(&self) -> Result<(Vec<Vec3>, Vec<Vec3>)> {
        match &self.on {
            On::Cpu { batch, .. } => Ok((
                batch
                    .worlds()
                    .iter()
                    .flat_map(|s| s.state.x.clone())
                    .collect(),
                batch
                    .worlds()
                    .iter()
                    .flat_map(|s| s.state.v.clone())
                    .collect(),
            )),
            On::Gpu { sim, .. } => sim.read_worlds(),
        }
    }

    /// The batch so far: one report a world, and the batch's timings.
    pub fn report(&self) -> Result<BatchReport> {
        let worlds = match &self.on {
            On::Cpu {
                batch,
                stages,
                tallies,
            } => (batch.worlds().iter().zip(tallies).enumerate())
                .map(|(w, (sim, t))| {
                    let done = self.taken[w].max(1) as f64;
                    WorldReport {
                        cg_iterations_mean: t.cg_iters as f64 / done,
                        cg_iterations_max: t.residuals.most_iterations,
                        cg_residual_max: t.residuals.max,
                        cg_steps_above_goal: t.residuals.above_goal,
                        max_penetration: t.max_penetration,
                        contacts_mean: t.contacts as f64 / done,
                        energy_final: sim.energy().total(),
                        finite: sim.is_finite(),
                        failsafe_share: (stages[w].separate).then(|| {
                            t.self_contact(done, sim.scene.cloth.vertex_count())
                                .failsafe_share
                        }),
                        ..self.world_report(w)
                    }
                })
                .collect(),
            On::Gpu {
                sim,
                scenes,
                last,
                iterations,
                residuals,
                ..
            } => {
                let (x, v) = sim.read_worlds()?;
                let n = scenes[0].cloth.vertex_count().max(1);
                (scenes.iter().zip(x.chunks(n).zip(v.chunks(n))))
                    .enumerate()
                    .map(|(w, (scene, (x, v)))| {
                        let done = self.taken[w].max(1) as f64;
                        let state = &last[w];
                        WorldReport {
                            cg_iterations_mean: iterations[w].0 as f64 / done,
                            cg_iterations_max: iterations[w].1,
                            cg_residual_max: residuals[w].0,
                            cg_steps_above_goal: residuals[w].1,
                            max_penetration: f32::from_bits(state.max_penetration_bits),
                            contacts_mean: state.contacts_total as f64 / state.steps.max(1) as f64,
                            energy_final: cpu::energy(scene, x, v).total(),
                            finite: x.iter().chain(v).all(|p| p.is_finite()),
                            failsafe_share: None,
                            ..self.world_report(w)
                        }
                    })
                    .collect()
            }
        };
        let world_steps: u64 = self.taken.iter().sum();
        Ok(BatchReport {
            backend: self.backend().into(),
            adapter: self.adapter(),
            steps: self.steps,
            ms_per_step: median(&mut self.wall_ms.clone()),
            world_steps_per_second: world_steps as f64 / self.seconds.max(1e-9),
            peak_resident_bytes: peak_resident_bytes(),
            worlds,
        })
    }

    /// World `w`'s report with what both backends know of it.
    fn world_report(&self, w: usize) -> WorldReport {
        WorldReport {
            world: w,
            set: self.set[w].clone(),
            steps: self.taken[w],
            divergence: self.diverged[w].clone(),
            ..WorldReport::default()
        }
    }
}

/// The batch of `scenes` on `chosen`: on its GPU where the batch runs there
/// (two or more worlds in one `GpuSim::with_worlds`, one world alone).
/// Under `auto` (`cpu_fallback`) a batch the GPU does not run (a scene it
/// does not batch yet, worlds that differ in what a batch shares, or more
/// than the device holds) runs on the CPU, and `notice` is told why; with
/// `--backend gpu` that is the error.
pub fn batch_on(
    chosen: &Chosen,
    scenes: Vec<Scene>,
    set: &[String],
    mut notice: impl FnMut(String),
) -> Result<Batch> {
    let Chosen::Gpu { ctx, cpu_fallback } = chosen else {
        return Ok(Batch::cpu(scenes, set));
    };
    let tried = match scenes.len() > 1 {
        true => GpuSim::batchable(&scenes[0]).and_then(|()| Batch::gpu(ctx, scenes.clone(), set)),
        false => Batch::gpu(ctx, scenes.clone(), set),
    };
    match tried {
        Err(e @ (Error::Config { .. } | Error::Limit { .. })) if *cpu_fallback => {
            notice(format!(
                "notice: {e}; running the batch on the CPU reference path"
            ));
            Ok(Batch::cpu(scenes, set))
        }
        tried => tried,
    }
}

/// Runs `batch` for `steps` steps; `progress` is told the batch steps done.
pub fn run_batch(
    mut batch: Batch,
    steps: u64,
    mut progress: impl FnMut(u64),
) -> Result<BatchReport> {
    for k in 0..steps {
        batch.step()?;
        progress(k + 1);
    }
    batch.report()
}
