//! What a run reports: the `--report` JSON of docs/DESIGN.md, the
//! one-screen summary, and the series they are summarised from.

use std::collections::BTreeMap;

use serde::Serialize;

use wgcloth::config::{Config, ModelKind, Preconditioner, SceneKind, Smoother};
use wgcloth::cpu::{State, StepStats};
use wgcloth::error::{Error, Result};
use wgcloth::gpu::mlp::NetworkKernel;
use wgcloth::health::Divergence;
use wgcloth::scene::Scene;
use wgcloth::stage::SelfContactStages;

#[derive(Clone, Debug, Serialize)]
pub struct Report {
    pub backend: String,
    pub adapter: String,
    pub model: ModelKind,
    /// A network model's weights file, layer widths, multiply-adds per
    /// evaluation, and on the GPU the kernel that runs it.
    pub network: Option<String>,
    pub scene: SceneKind,
    pub grid: [u32; 2],
    pub steps: u64,
    pub dt: f32,
    /// Backward Euler solves per step (`Scene::substeps`).
    pub substeps: u32,
    /// Median wall time of a step, ms.
    pub ms_per_step: f64,
    /// Mean wall time of a step, ms: the time to a converged step with the
    /// slow steps counted, which the median hides (a multigrid solve's
    /// hardest steps take several times its median iterations).
    pub ms_per_step_mean: f64,
    /// Median time of each stage per step, ms (GPU: timestamp queries,
    /// absent where the adapter has none).
    pub stage_ms: BTreeMap<String, f64>,
    /// Compute dispatches a step records, the median over the timed steps
    /// (GPU only, and none if no step was timed; the iteration budget
    /// varies them from step to step).
    pub dispatches_per_step: Option<u32>,
    /// The host's time to record a step (`GpuSim::encode_step`, CPU side),
    /// ms, the median over the timed steps (GPU only).
    pub record_ms_per_step: Option<f64>,
    /// GPU memory of the scene's state, bytes (`GpuSim::state_bytes`; GPU
    /// only), and per cloth vertex.
    pub gpu_state_bytes: Option<u64>,
    pub gpu_bytes_per_vertex: Option<f64>,
    /// GPU arrays bound in parts because they pass a binding's limit, with
    /// the bindings each takes (`GpuSim::split_arrays`).
    pub gpu_split_arrays: Vec<(String, usize)>,
    /// Whether the solver's workgroup sums ran through subgroup operations
    /// (`Kernels::subgroups`; GPU only).
    pub gpu_subgroup_sums: Option<bool>,
    /// How the solver's vectors lay in GPU memory, `packed` or `vec4`
    /// (`Kernels::vectors`; GPU only).
    pub gpu_vectors: Option<String>,
    /// Whether each solve ran whole, PCG and its V-cycle in one dispatch
    /// (`GpuSim::solved_whole`, `solver.whole_solve_nodes`; GPU only).
    pub gpu_solved_whole: Option<bool>,
    /// The process's peak resident memory, bytes (Linux `VmHWM`; absent
    /// elsewhere): on the CPU path the simulation's memory plus the
    /// program's own.
    pub peak_resident_bytes: Option<u64>,
    /// Deepest any cloth vertex got inside the rigid surface, m (≥ 0).
    pub max_penetration: f32,
    pub finite: bool,
    /// The step that diverged, the vertex it started at and why
    /// (`health::diagnose`); the run stopped there.
    pub divergence: Option<Divergence>,
    /// The state before the diverging step.
    #[serde(skip)]
    pub last_good: Option<State>,
    /// A GPU fault the run survived by finishing on the CPU (`auto`); the
    /// statistics then cover the CPU's steps.
    pub device_fault: Option<DeviceFault>,
    /// The PCG preconditioner (with multigrid, its smoother), and the
    /// iterations per step.
    pub preconditioner: Preconditioner,
    pub smoother: Option<Smoother>,
    pub cg_iterations_mean: f64,
    /// The most iterations one step's solve took.
    pub cg_iterations_max: u32,
    /// The worst and the median of the steps' end-of-solve relative
    /// residuals, and how many steps ended above [`RESIDUAL_GOAL`].
    pub cg_residual_max: f32,
    pub cg_residual_median: f32,
    pub cg_steps_above_goal: u64,
    /// GPU steps the run loop solved again from their start because its
    /// iteration budget had cut them short of `solver.cg_tol`
    /// (`GpuSim::set_cg_budget`, `CgBudget::cut`; always 0 on the CPU).
    pub cg_steps_resolved: u64,
    pub cg_breakdowns: u64,
    pub contacts_mean: f64,
    /// Total energy (kinetic + gravitational + elastic) at the end, J.
    pub energy_final: f64,
    /// What stage "separate" did (`[self_contact]` on).
    pub self_contact: Option<SelfContactReport>,
}

/// What stage "separate" did over a run (cpu/separate.rs).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SelfContactReport {
    /// The most near pairs one detection found.
    pub pairs_max: u64,
    /// Vertex steps the failsafe changed, summed over the run.
    pub changed_total: u64,
    /// `changed_total` over the run's vertex steps: the failsafe's share.
    pub failsafe_share: f64,
    /// Vertex steps impulses changed.
    pub pushed_total: u64,
    /// Vertex steps moved in impact zones.
    pub zoned_total: u64,
    /// Vertex steps whose change the body stopped.
    pub stopped_total: u64,
    /// Vertex steps the last resort held.
    pub held_total: u64,
    /// Steps that reached the last resort: pairs still failing at their
    /// last detection.
    pub last_resort_steps: u64,
    /// GPU: steps whose near pairs overflowed the list (their rounds walked
    /// the cloth again: slower, the same result); 0 on the CPU.
    pub overflow_steps: u64,
    /// The most cloth–cloth contacts one step pushed apart (stage
    /// "self_contact"; 0 with no thickness).
    pub contacts_max: u64,
    /// Cloth–cloth contacts left out, summed over the run: at vertices in
    /// more than `self_contact::PAIRS_PER_VERTEX`, or (GPU) past the
    /// contact list's capacity.
    pub contacts_dropped: u64,
}

/// The relative residual every step's solve should reach (issue 20); the
/// report counts the steps that end above it.
pub const RESIDUAL_GOAL: f32 = 1e-3;

/// Multigrid's smoother, when multigrid preconditions.
pub(super) fn smoother_of(config: &Config) -> Option<Smoother> {
    (config.solver.preconditioner == Preconditioner::Multigrid).then_some(config.solver.smoother)
}

/// A preconditioner's name, with multigrid's smoother: "multigrid (patches)".
pub fn solver_name(preconditioner: Preconditioner, smoother: Option<Smoother>) -> String {
    match smoother {
        Some(smoother) => format!("{} ({})", preconditioner.name(), smoother.name()),
        None => preconditioner.name().to_string(),
    }
}

/// What a CPU run's steps add up to, step by step.
#[derive(Default)]
pub(super) struct Tally {
    pub(super) cg_iters: u64,
    pub(super) contacts: u64,
    pub(super) breakdowns: u64,
    pub(super) residuals: Residuals,
    pub(super) max_penetration: f32,
    pub(super) separated: SelfContactReport,
}

impl Tally {
    /// Adds a step's statistics; `self_contact`: which of its stages ran.
    pub(super) fn push(&mut self, s: &StepStats, self_contact: SelfContactStages) {
        self.cg_iters += s.pcg.iterations as u64;
        self.contacts += s.contacts as u64;
        self.breakdowns += s.pcg.breakdown as u64;
        self.residuals
            .push(s.pcg.relative_residual, s.pcg.iterations);
        self.max_penetration = self.max_penetration.max(s.max_penetration);
        let (sep, t) = (&s.separation, &mut self.separated);
        t.pairs_max = t.pairs_max.max(sep.pairs as u64);
        t.changed_total += sep.changed as u64;
        t.pushed_total += sep.pushed as u64;
        t.zoned_total += sep.zoned as u64;
        t.stopped_total += sep.stopped as u64;
        t.held_total += sep.held as u64;
        t.last_resort_steps += u64::from(self_contact.separate && !sep.settled);
        t.contacts_max = t.contacts_max.max(s.self_contacts as u64);
        t.contacts_dropped += s.self_contacts_dropped as u64;
    }

    /// What stage "separate" did over `steps` steps of `vertices`, with
    /// self-contact on.
    pub(super) fn self_contact(&self, steps: f64, vertices: usize) -> SelfContactReport {
        SelfContactReport {
            failsafe_share: self.separated.changed_total as f64 / (steps * vertices as f64),
            ..self.separated.clone()
        }
    }
}

/// Each step's end-of-solve relative residual: a bounded sample for the
/// median, the worst, and the steps above [`RESIDUAL_GOAL`].
#[derive(Default)]
pub(super) struct Residuals {
    pub(super) sample: Series,
    pub(super) max: f32,
    pub(super) above_goal: u64,
    pub(super) most_iterations: u32,
}

impl Residuals {
    pub(super) fn push(&mut self, residual: f32, iterations: u32) {
        self.most_iterations = self.most_iterations.max(iterations);
        self.sample.push(residual as f64);
        self.max = self.max.max(residual);
        // A NaN residual counts as above.
        self.above_goal += u64::from(residual > RESIDUAL_GOAL || residual.is_nan());
    }

    pub(super) fn median(&mut self) -> f32 {
        median(&mut self.sample.values) as f32
    }
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

/// Per-step wall and stage times, summarised as medians (and the wall
/// time's mean).
#[derive(Default)]
pub(super) struct Timings {
    wall_ms: Series,
    stage_ms: BTreeMap<String, Series>,
}

/// The most values a [`Series`] holds.
pub(super) const SERIES_CAP: usize = 8192;

/// A series of step times in bounded memory, so a soak of any length
/// stays flat: up to [`SERIES_CAP`] steps every value is kept; beyond, every
/// other one is dropped and then only every `stride`-th step kept, an
/// evenly spaced sample of the whole run.
#[derive(Default)]
pub(super) struct Series {
    pub(super) values: Vec<f64>,
    stride: u64,
    seen: u64,
    /// The sum of every value pushed, kept or not.
    total: f64,
}

impl Series {
    pub(super) fn push(&mut self, value: f64) {
        self.stride = self.stride.max(1);
        if self.seen.is_multiple_of(self.stride) {
            self.values.push(value);
            if self.values.len() == SERIES_CAP {
                let kept: Vec<f64> = self.values.iter().copied().step_by(2).collect();
                self.values = kept;
                self.stride *= 2;
            }
        }
        self.seen += 1;
        self.total += value;
    }

    /// The mean of every value pushed (0 before the first).
    fn mean(&self) -> f64 {
        self.total / self.seen.max(1) as f64
    }
}

impl Timings {
    pub(super) fn push(
        &mut self,
        wall_ms: f64,
        stages: impl IntoIterator<Item = (&'static str, f64)>,
    ) {
        self.wall_ms.push(wall_ms);
        for (name, ms) in stages {
            self.stage_ms.entry(name.to_string()).or_default().push(ms);
        }
    }

    /// The wall time's median and mean, and each stage's median.
    pub(super) fn summary(mut self) -> (f64, f64, BTreeMap<String, f64>) {
        let stages = self
            .stage_ms
            .iter_mut()
            .map(|(k, v)| (k.clone(), median(&mut v.values)))
            .collect();
        let mean = self.wall_ms.mean();
        (median(&mut self.wall_ms.values), mean, stages)
    }
}

/// A GPU fault that `--backend auto` survived by finishing on the CPU.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceFault {
    pub error: String,
    /// The step the GPU had reached when it failed.
    pub failed_at: u64,
    /// The checkpoint the CPU resumed from (≤ `failed_at`).
    pub resumed_from: u64,
}

/// "FILE: KIND 10-256-…-3, N multiply-adds per contact[, KERNEL kernel]"
/// for a network model.
pub(super) fn describe_network(scene: &Scene, kernel: Option<NetworkKernel>) -> Option<String> {
    let (net, path) = (scene.network.as_ref()?, scene.config.weights_path()?);
    let built_in = match scene.config.contact.weights {
        None => " (built in)",
        Some(_) => "",
    };
    let mut widths = vec![net.mlp.inputs().to_string()];
    widths.extend(net.mlp.layers.iter().map(|l| l.outputs.to_string()));
    let kernel = kernel
        .map(|k| format!(", {} kernel", k.name()))
        .unwrap_or_default();
    Some(format!(
        "{}{built_in}: {} {}, {} multiply-adds per contact{kernel}",
        path.display(),
        net.kind.name(),
        widths.join("-"),
        net.multiply_adds()
    ))
}

/// The process's peak resident memory so far (Linux's `VmHWM`), bytes.
pub(super) fn peak_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

impl Report {
    /// The one-screen summary.
    pub fn summary(&self) -> String {
        let stages: Vec<String> = self
            .stage_ms
            .iter()
            .map(|(k, v)| format!("{k} {v:.3}"))
            .collect();
        let dispatches = self
            .dispatches_per_step
            .map(|d| format!(", {d} dispatches/step"))
            .unwrap_or_default()
            + &self
                .record_ms_per_step
                .map(|ms| format!(", recorded in {ms:.3} ms"))
                .unwrap_or_default();
        let memory = match (self.gpu_state_bytes, self.gpu_bytes_per_vertex) {
            (Some(bytes), Some(per_vertex)) => {
                let split: Vec<String> = self
                    .gpu_split_arrays
                    .iter()
                    .map(|(name, parts)| format!(", {name} in {parts} bindings"))
                    .collect();
                format!(
                    "gpu memory   {:.2} MiB of state, {per_vertex:.0} bytes per vertex{}\n",
                    bytes as f64 / (1 << 20) as f64,
                    split.concat()
                )
            }
            _ => String::new(),
        };
        let vertices = (self.grid[0] as u64 * self.grid[1] as u64) as f64;
        let memory = memory
            + &self
                .peak_resident_bytes
                .map(|bytes| {
                    format!(
                        "memory       {:.1} MiB peak resident (the whole process), {:.0} bytes per vertex\n",
                        bytes as f64 / (1 << 20) as f64,
                        bytes as f64 / vertices
                    )
                })
                .unwrap_or_default();
        let whole = match self.gpu_solved_whole {
            Some(true) => ", each solve whole in one dispatch",
            _ => "",
        };
        format!(
            "wgcloth run: scene {:?}, model {}, grid {}x{}, {} steps of {} s{}\n\
             backend      {} — {}{}{}\n\
             {}\
             ms/step      {:.3} (median{dispatches}), {:.3} (mean)\n\
             {memory}\
             stages (ms)  {}\n\
             pcg          {} preconditioner{whole}, {:.1} iterations/step (most {}), relative residual median {:.2e}, worst {:.2e}, {} steps above {RESIDUAL_GOAL:.0e}, {} solved again after the iteration budget cut them, {} breakdowns\n\
             contacts     {:.1} per step\n\
             penetration  {:.4} m deepest (thickness not counted)\n\
             state        {} (final energy {:.4} J)",
            self.scene,
            self.model.name(),
            self.grid[0],
            self.grid[1],
            self.steps,
            self.dt,
            match self.substeps {
                1 => String::new(),
                n => format!(", each {n} solves of {:.3} ms", 1e3 * self.dt / n as f32),
            },
            self.backend,
            self.adapter,
            match self.gpu_subgroup_sums {
                Some(true) => ", solver sums through subgroups",
                Some(false) => ", solver sums through workgroup memory",
                None => "",
            },
            self.gpu_vectors
                .as_ref()
                .map(|v| format!(", vectors {v}"))
                .unwrap_or_default(),
            self.network
                .as_ref()
                .map(|n| format!("network      {n}\n"))
                .unwrap_or_default(),
            self.ms_per_step,
            self.ms_per_step_mean,
            if stages.is_empty() {
                "(no timestamp queries on this adapter)".into()
            } else {
                stages.join(", ")
            },
            solver_name(self.preconditioner, self.smoother),
            self.cg_iterations_mean,
            self.cg_iterations_max,
            self.cg_residual_median,
            self.cg_residual_max,
            self.cg_steps_above_goal,
            self.cg_steps_resolved,
            self.cg_breakdowns,
            self.contacts_mean,
            self.max_penetration,
            if self.finite { "finite" } else { "NOT FINITE" },
            self.energy_final,
        ) + &self
            .self_contact
            .as_ref()
            .map(|c| {
                format!(
                    "\nself-contact {} near pairs at most in a detection, {} overflowed the GPU's pair list; {} cloth–cloth contacts at most in a step, {} dropped\nfailsafe     {} vertex steps changed ({:.3} % of all): {} by impulses, {} in impact zones, {} stopped by the body, {} held by the last resort in {} steps",
                    c.pairs_max, c.overflow_steps, c.contacts_max, c.contacts_dropped,
                    c.changed_total, 100.0 * c.failsafe_share, c.pushed_total, c.zoned_total, c.stopped_total, c.held_total, c.last_resort_steps
                )
            })
            .unwrap_or_default()
            + &self
            .device_fault
            .as_ref()
            .map(|f| {
                format!(
                    "\nGPU fault    at step {} ({}); finished on the CPU from step {}",
                    f.failed_at, f.error, f.resumed_from
                )
            })
            .unwrap_or_default()
            + &self
                .divergence
                .as_ref()
                .map(|d| {
                    format!(
                        "\ndiverged     at step {}, vertex {}: {}",
                        d.step, d.vertex, d.reason
                    )
                })
                .unwrap_or_default()
    }
}

/// Fails a run that diverged.
pub fn check_diverged(report: &Report) -> Result<()> {
    match &report.divergence {
        Some(d) => Err(Error::Diverged {
            step: d.step,
            vertex: d.vertex,
            reason: d.reason.clone(),
        }),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Past the cap a series keeps an evenly spaced sample of every step,
    /// in bounded memory, with the median of the whole.
    #[test]
    fn a_long_series_keeps_an_even_sample() {
        let mut series = Series::default();
        let n = 5 * SERIES_CAP as u64 + 123;
        for k in 0..n {
            series.push(k as f64);
        }
        assert!(series.values.len() < SERIES_CAP);
        assert_eq!(series.stride, 8);
        for (i, v) in series.values.iter().enumerate() {
            assert_eq!(*v, (i as u64 * series.stride) as f64);
        }
        let all_median = (n - 1) as f64 / 2.0;
        let sampled = median(&mut series.values);
        assert!(
            (sampled - all_median).abs() <= series.stride as f64,
            "{sampled} vs {all_median}"
        );
    }
}
