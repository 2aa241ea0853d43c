//! Running a scene for a number of steps and summarising it: the `--report`
//! JSON of DESIGN.md and the one-screen summary.

use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

use crate::config::{ModelKind, SceneKind};
use crate::cpu::{CpuSim, STAGES};
use crate::error::{Error, Result};
use crate::scene::Scene;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    Gpu,
    Cpu,
    /// The GPU when an adapter exists, else the CPU (with a notice).
    Auto,
}

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub backend: String,
    pub adapter: String,
    pub model: ModelKind,
    pub scene: SceneKind,
    pub grid: [u32; 2],
    pub steps: u64,
    pub dt: f32,
    /// Median wall time of a step, ms.
    pub ms_per_step: f64,
    /// Median time of each stage per step, ms.
    pub stage_ms: BTreeMap<String, f64>,
    /// Deepest any cloth vertex got inside the rigid surface, m (≥ 0).
    pub max_penetration: f32,
    pub finite: bool,
    pub cg_iterations_mean: f64,
    pub cg_residual_max: f32,
    pub cg_breakdowns: u64,
    pub contacts_mean: f64,
    /// Total energy (kinetic + gravitational + elastic) at the end, J.
    pub energy_final: f64,
}

pub fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let m = values.len() / 2;
    if values.len() % 2 == 1 {
        values[m]
    } else {
        0.5 * (values[m - 1] + values[m])
    }
}

/// Which backend actually runs, and the notice to print when `auto` had
/// to fall back.
pub fn resolve_backend(requested: Backend) -> Result<(Backend, Option<String>)> {
    match requested {
        Backend::Cpu => Ok((Backend::Cpu, None)),
        Backend::Auto => Ok((
            Backend::Cpu,
            Some("notice: no GPU backend in this build; running the CPU reference path".into()),
        )),
        Backend::Gpu => Err(Error::Unsupported(
            "--backend gpu: the GPU backend is not part of this build yet; use --backend cpu"
                .into(),
        )),
    }
}

/// Runs the scene on the CPU for `steps` steps, calling `progress` after
/// each. Stops at the first non-finite state with [`Error::Diverged`].
pub fn run_cpu(scene: Scene, steps: u64, mut progress: impl FnMut(u64)) -> (Report, Result<()>) {
    let config = scene.config.clone();
    let mut sim = CpuSim::new(scene);
    let mut wall = Vec::with_capacity(steps as usize);
    let mut stage: Vec<Vec<f64>> = vec![Vec::with_capacity(steps as usize); STAGES.len()];
    let (mut cg_iters, mut contacts, mut breakdowns) = (0u64, 0u64, 0u64);
    let (mut cg_residual_max, mut max_penetration) = (0.0f32, 0.0f32);
    let mut outcome = Ok(());
    for k in 0..steps {
        let start = Instant::now();
        let s = sim.step();
        wall.push(start.elapsed().as_secs_f64() * 1e3);
        for (times, secs) in stage.iter_mut().zip(s.stage_seconds) {
            times.push(secs * 1e3);
        }
        cg_iters += s.pcg.iterations as u64;
        contacts += s.contacts as u64;
        breakdowns += s.pcg.breakdown as u64;
        cg_residual_max = cg_residual_max.max(s.pcg.relative_residual);
        max_penetration = max_penetration.max(s.max_penetration);
        progress(k + 1);
        if !sim.is_finite() {
            outcome = Err(Error::Diverged {
                step: k + 1,
                reason: "positions or velocities are no longer finite".into(),
            });
            break;
        }
    }
    let done = sim.state.step.max(1) as f64;
    let report = Report {
        backend: "cpu".into(),
        adapter: format!(
            "CPU reference path ({} threads)",
            rayon::current_num_threads()
        ),
        model: config.model,
        scene: config.scene,
        grid: config.cloth.grid,
        steps: sim.state.step,
        dt: config.solver.dt,
        ms_per_step: median(&mut wall),
        stage_ms: STAGES
            .iter()
            .zip(&mut stage)
            .map(|(name, t)| (name.to_string(), median(t)))
            .collect(),
        max_penetration,
        finite: sim.is_finite(),
        cg_iterations_mean: cg_iters as f64 / done,
        cg_residual_max,
        cg_breakdowns: breakdowns,
        contacts_mean: contacts as f64 / done,
        energy_final: sim.energy().total(),
    };
    (report, outcome)
}

impl Report {
    /// The one-screen summary.
    pub fn summary(&self) -> String {
        let stages: Vec<String> = self
            .stage_ms
            .iter()
            .map(|(k, v)| format!("{k} {v:.3}"))
            .collect();
        format!(
            "wgcloth run: scene {:?}, model {:?}, grid {}x{}, {} steps of {} s\n\
             backend      {} — {}\n\
             ms/step      {:.3} (median)\n\
             stages (ms)  {}\n\
             pcg          {:.1} iterations/step, worst relative residual {:.2e}, {} breakdowns\n\
             contacts     {:.1} per step\n\
             penetration  {:.4} m deepest (thickness not counted)\n\
             state        {} (final energy {:.4} J)",
            self.scene,
            self.model,
            self.grid[0],
            self.grid[1],
            self.steps,
            self.dt,
            self.backend,
            self.adapter,
            self.ms_per_step,
            stages.join(", "),
            self.cg_iterations_mean,
            self.cg_residual_max,
            self.cg_breakdowns,
            self.contacts_mean,
            self.max_penetration,
            if self.finite { "finite" } else { "NOT FINITE" },
            self.energy_final,
        )
    }
}
