//! Running a scene for a number of steps on a backend and summarising it:
//! the `--report` JSON of docs/DESIGN.md and the one-screen summary.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::frames::Recording;
use crate::in_flight::InFlight;
use crate::monitor::Monitor;
use wgcloth::config::{Config, ModelKind, Preconditioner, SceneKind, Smoother};
use wgcloth::cpu::{self, CpuSim, State, integrate};
use wgcloth::error::{Error, Result};
use wgcloth::gpu::layout::StepState;
use wgcloth::gpu::mlp::NetworkKernel;
use wgcloth::gpu::{CgBudget, GpuContext, GpuSim, SolvedSteps, context::describe};
use wgcloth::health::{self, Divergence, FailedStep};
use wgcloth::scene::Scene;
use wgcloth::sensitivity::{Reference, Sensitivity, largest_distance};
use wgcloth::stage::{SelfContactStages, Stage};

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Backend {
    Gpu,
    Cpu,
    /// The GPU when an adapter exists, else the CPU (with a notice).
    Auto,
}

/// The backend a run uses.
pub enum Chosen {
    Cpu,
    /// With `cpu_fallback` (what `auto` picks), a device fault moves the
    /// run to the CPU, from the last state copied to the host, with a
    /// notice; without it the fault ends the run with an error.
    Gpu {
        ctx: Box<GpuContext>,
        cpu_fallback: bool,
    },
}

impl Chosen {
    /// The GPU, a fault ending the run.
    pub fn gpu(ctx: GpuContext) -> Chosen {
        Chosen::Gpu {
            ctx: Box::new(ctx),
            cpu_fallback: false,
        }
    }

    pub fn context(&self) -> Option<&GpuContext> {
        match self {
            Chosen::Gpu { ctx, .. } => Some(ctx),
            Chosen::Cpu => None,
        }
    }
}

/// Resolves `auto`, and says why when it falls back to the CPU (no
/// adapter, or only a software one). A GPU device gets what its adapter
/// has of the `optional` features (`wgcloth::gpu::OPTIONAL_FEATURES`).
pub fn choose_backend(
    requested: Backend,
    optional: wgpu::Features,
) -> Result<(Chosen, Option<String>)> {
    match requested {
        Backend::Cpu => Ok((Chosen::Cpu, None)),
        Backend::Gpu => Ok((Chosen::gpu(GpuContext::headless_with(optional)?), None)),
        Backend::Auto => Ok(match GpuContext::headless_with(optional) {
            // A software rasteriser (lavapipe) runs the kernels on the same
            // CPU cores, several times slower than the reference path.
            Ok(ctx) if ctx.adapter.device_type == wgpu::DeviceType::Cpu => (
                Chosen::Cpu,
                Some(format!(
                    "notice: the only GPU adapter is a software one ({}); running on the faster CPU reference path (--backend gpu forces it)",
                    describe(&ctx.adapter)
                )),
            ),
            Ok(ctx) => (
                Chosen::Gpu {
                    ctx: Box::new(ctx),
                    cpu_fallback: true,
                },
                None,
            ),
            Err(e) => (
                Chosen::Cpu,
                Some(format!(
                    "notice: {e}\nnotice: running on the CPU reference path"
                )),
            ),
        }),
    }
}

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

/// Each step's end-of-solve relative residual: a bounded sample for the
/// Multigrid's smoother, when multigrid preconditions.
pub fn smoother_of(config: &Config) -> Option<Smoother> {
    (config.solver.preconditioner == Preconditioner::Multigrid).then_some(config.solver.smoother)
}

/// A preconditioner's name, with multigrid's smoother: "multigrid (patches)".
pub fn solver_name(preconditioner: Preconditioner, smoother: Option<Smoother>) -> String {
    match smoother {
        Some(smoother) => format!("{} ({})", preconditioner.name(), smoother.name()),
        None => preconditioner.name().to_string(),
    }
}

/// median, the worst, and the steps above [`RESIDUAL_GOAL`].
#[derive(Default)]
struct Residuals {
    sample: Series,
    max: f32,
    above_goal: u64,
    most_iterations: u32,
}

impl Residuals {
    fn push(&mut self, residual: f32, iterations: u32) {
        self.most_iterations = self.most_iterations.max(iterations);
        self.sample.push(residual as f64);
        self.max = self.max.max(residual);
        // A NaN residual counts as above.
        self.above_goal += u64::from(residual > RESIDUAL_GOAL || residual.is_nan());
    }

    fn median(&mut self) -> f32 {
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
struct Timings {
    wall_ms: Series,
    stage_ms: BTreeMap<String, Series>,
}

/// The most values a [`Series`] holds.
const SERIES_CAP: usize = 8192;

/// A series of step times in bounded memory, so a soak of any length
/// stays flat: up to [`SERIES_CAP`] steps every value is kept; beyond, every
/// other one is dropped and then only every `stride`-th step kept, an
/// evenly spaced sample of the whole run.
#[derive(Default)]
struct Series {
    values: Vec<f64>,
    stride: u64,
    seen: u64,
    /// The sum of every value pushed, kept or not.
    total: f64,
}

impl Series {
    fn push(&mut self, value: f64) {
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
    fn push(&mut self, wall_ms: f64, stages: impl IntoIterator<Item = (&'static str, f64)>) {
        self.wall_ms.push(wall_ms);
        for (name, ms) in stages {
            self.stage_ms.entry(name.to_string()).or_default().push(ms);
        }
    }

    /// The wall time's median and mean, and each stage's median.
    fn summary(mut self) -> (f64, f64, BTreeMap<String, f64>) {
        let stages = self
            .stage_ms
            .iter_mut()
            .map(|(k, v)| (k.clone(), median(&mut v.values)))
            .collect();
        let mean = self.wall_ms.mean();
        (median(&mut self.wall_ms.values), mean, stages)
    }
}

/// How many steps a run takes, and how many of the first are left out of
/// the timings (pipelines warming up, the body not yet in contact).
#[derive(Clone, Copy, Debug)]
pub struct Steps {
    pub total: u64,
    pub untimed: u64,
    /// PCG iterations the first GPU step records, instead of the whole
    /// cap: with too few, the run loop solves it again at once (what
    /// `tests/in_flight.rs` needs of it).
    pub first_budget: Option<u32>,
}

impl Steps {
    pub fn all(total: u64) -> Steps {
        Steps {
            total,
            untimed: 0,
            first_budget: None,
        }
    }
}

/// What a run feeds as it goes; every part is optional.
#[derive(Default)]
pub struct Observers<'a, 'r> {
    /// Told the number of steps done after each step.
    pub progress: Option<&'a mut dyn FnMut(u64)>,
    /// Told, in one line, of a GPU fault the run survives on the CPU.
    pub notice: Option<&'a mut dyn FnMut(&str)>,
    /// Frames of the initial state and of every `--every` steps.
    pub recording: Option<&'a mut Recording<'r>>,
    /// Samples every K steps (`run --monitor`).
    pub monitor: Option<&'a mut Monitor>,
}

impl Observers<'_, '_> {
    fn progress(&mut self, done: u64) {
        if let Some(p) = self.progress.as_mut() {
            p(done)
        }
    }

    fn notice(&mut self, line: &str) {
        if let Some(n) = self.notice.as_mut() {
            n(line)
        }
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

/// How often a GPU run that may fall back copies its state to the host:
/// often enough to lose little on a fault, rarely enough to cost nothing.
const CHECKPOINT_INTERVAL: Duration = Duration::from_secs(2);

/// The host's copy of a GPU run's state, where the CPU resumes after a
/// device fault.
struct Checkpoint {
    state: State,
    reached: u64,
    taken: Instant,
}

/// Runs `scene` for `steps.total` steps on `chosen`.
pub fn run(chosen: &Chosen, scene: Scene, steps: Steps, mut obs: Observers) -> Result<Report> {
    let (ctx, cpu_fallback) = match chosen {
        Chosen::Cpu => return run_cpu(CpuSim::new(scene), steps, &mut obs),
        Chosen::Gpu { ctx, cpu_fallback } => (ctx, *cpu_fallback),
    };
    if !cpu_fallback {
        return run_gpu(ctx, &scene, steps, &mut obs, None);
    }
    let mut checkpoint = Checkpoint {
        state: State::initial(&scene),
        reached: 0,
        taken: Instant::now(),
    };
    let error = match run_gpu(ctx, &scene, steps, &mut obs, Some(&mut checkpoint)) {
        Err(Error::Gpu(what)) => what,
        // A scene beyond the device's limits still runs on the CPU.
        Err(e @ Error::Limit { .. }) => e.to_string(),
        done => return done,
    };
    let resumed_from = checkpoint.state.step;
    // Frames need the device that failed.
    let frames = match obs.recording.take() {
        Some(_) => format!("; frames stop at step {}", checkpoint.reached),
        None => String::new(),
    };
    obs.notice(&format!(
        "notice: the GPU failed after {} steps ({error}); continuing on the CPU reference path from step {resumed_from}{frames}",
        checkpoint.reached
    ));
    // Built only now: the CPU path's system matrix is large.
    let mut sim = CpuSim::new(scene);
    sim.state = checkpoint.state;
    let mut report = run_cpu(sim, steps, &mut obs)?;
    report.device_fault = Some(DeviceFault {
        error,
        failed_at: checkpoint.reached + 1,
        resumed_from,
    });
    Ok(report)
}

/// Steps `sim` from where its state is to `steps.total`.
fn run_cpu(mut sim: CpuSim, steps: Steps, obs: &mut Observers) -> Result<Report> {
    let config = sim.scene.config.clone();
    let has_body = sim.scene.rigid.is_some();
    let self_contact = SelfContactStages::of(&config.self_contact);
    let first = sim.state.step;
    if first == 0 {
        if let Some(r) = obs.recording.as_deref_mut() {
            r.cpu(0, &sim)?;
        }
        if let Some(m) = obs.monitor.as_deref_mut() {
            m.record(0, &sim.scene, &sim.state.x, &sim.state.v, None)?;
        }
    }
    let mut timings = Timings::default();
    let (mut cg_iters, mut contacts, mut breakdowns) = (0u64, 0u64, 0u64);
    let mut residuals = Residuals::default();
    let mut max_penetration = 0.0f32;
    let mut separated = SelfContactReport::default();
    let mut divergence = None;
    let mut last_good = sim.state.clone();
    let max_speed = config.solver.max_speed;
    for k in first..steps.total {
        keep(&mut last_good, &sim.state);
        let start = Instant::now();
        let s = sim.step();
        let wall = start.elapsed().as_secs_f64() * 1e3;
        if k >= steps.untimed {
            timings.push(
                wall,
                Stage::ALL
                    .iter()
                    .filter(|stage| stage.runs(has_body, self_contact))
                    .map(|stage| (stage.name(), s.stage_seconds[stage.index()] * 1e3)),
            );
        }
        cg_iters += s.pcg.iterations as u64;
        contacts += s.contacts as u64;
        breakdowns += s.pcg.breakdown as u64;
        residuals.push(s.pcg.relative_residual, s.pcg.iterations);
        max_penetration = max_penetration.max(s.max_penetration);
        let sep = &s.separation;
        separated.pairs_max = separated.pairs_max.max(sep.pairs as u64);
        separated.changed_total += sep.changed as u64;
        separated.pushed_total += sep.pushed as u64;
        separated.zoned_total += sep.zoned as u64;
        separated.stopped_total += sep.stopped as u64;
        separated.held_total += sep.held as u64;
        separated.last_resort_steps += u64::from(self_contact.separate && !sep.settled);
        separated.contacts_max = separated.contacts_max.max(s.self_contacts as u64);
        separated.contacts_dropped += s.self_contacts_dropped as u64;
        let flags = integrate::health(&sim.state.x, &sim.state.v, max_speed);
        if health::failed(flags, s.pcg.breakdown) {
            keep(&mut sim.state, &last_good);
            let (flags, breakdown) = cpu_failing_solve(&mut sim, max_speed);
            let (matrix, b) = sim.system();
            divergence = Some(health::diagnose(&FailedStep {
                step: k + 1,
                flags,
                breakdown,
                diag: &matrix.diag,
                b,
                x: &sim.state.x,
                v: &sim.state.v,
                max_speed,
            }));
            break;
        }
        if let Some(r) = obs.recording.as_deref_mut() {
            r.cpu(k + 1, &sim)?;
        }
        if let Some(m) = obs.monitor.as_deref_mut().filter(|m| m.due(k + 1)) {
            m.record(k + 1, &sim.scene, &sim.state.x, &sim.state.v, None)?;
        }
        obs.progress(k + 1);
    }
    let done = (sim.state.step - first).max(1) as f64;
    let (ms_per_step, ms_per_step_mean, stage_ms) = timings.summary();
    Ok(Report {
        backend: "cpu".into(),
        adapter: format!(
            "CPU reference path ({} threads)",
            rayon::current_num_threads()
        ),
        model: config.model,
        network: describe_network(&sim.scene, None),
        scene: config.scene,
        grid: config.cloth.grid,
        steps: sim.state.step,
        dt: config.solver.dt,
        substeps: sim.scene.substeps,
        ms_per_step,
        ms_per_step_mean,
        stage_ms,
        dispatches_per_step: None,
        gpu_state_bytes: None,
        gpu_bytes_per_vertex: None,
        gpu_split_arrays: Vec::new(),
        gpu_subgroup_sums: None,
        gpu_vectors: None,
        peak_resident_bytes: peak_resident_bytes(),
        max_penetration,
        finite: sim.is_finite(),
        last_good: divergence.is_some().then_some(last_good),
        divergence,
        device_fault: None,
        preconditioner: config.solver.preconditioner,
        smoother: smoother_of(&config),
        cg_iterations_mean: cg_iters as f64 / done,
        cg_iterations_max: residuals.most_iterations,
        cg_residual_max: residuals.max,
        cg_residual_median: residuals.median(),
        cg_steps_above_goal: residuals.above_goal,
        cg_steps_resolved: 0,
        cg_breakdowns: breakdowns,
        contacts_mean: contacts as f64 / done,
        energy_final: sim.energy().total(),
        self_contact: self_contact.separate.then_some(SelfContactReport {
            failsafe_share: separated.changed_total as f64
                / (done * sim.scene.cloth.vertex_count() as f64),
            ..separated
        }),
    })
}

/// "FILE: KIND 10-256-…-3, N multiply-adds per contact[, KERNEL kernel]"
/// for a network model.
fn describe_network(scene: &Scene, kernel: Option<NetworkKernel>) -> Option<String> {
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

/// Runs `scene` on the GPU with up to [`in_flight::DEPTH`] steps in
/// flight, each step's statistics read asynchronously; the host waits for
/// a step only when the ring is full, or to draw, monitor or checkpoint
/// it. With a `checkpoint` the state is copied to it every
/// [`CHECKPOINT_INTERVAL`] for the CPU to resume from.
fn run_gpu(
    ctx: &GpuContext,
    scene: &Scene,
    steps: Steps,
    obs: &mut Observers,
    mut checkpoint: Option<&mut Checkpoint>,
) -> Result<Report> {
    let kernels = ctx.kernels()?;
    let sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, scene)?;
    ctx.finish()?;
    if let Some(r) = obs.recording.as_deref_mut() {
        r.gpu(0, &sim, scene)?;
    }
    if let Some(m) = obs.monitor.as_deref_mut() {
        let (x, v) = (sim.read_positions()?, sim.read_velocities()?);
        m.record(0, scene, &x, &v, Some(&ctx.device))?;
    }
    // The checkpoint holds the initial state; its interval counts from the
    // first step, not from building the kernels (seconds on lavapipe).
    if let Some(c) = checkpoint.as_deref_mut() {
        c.taken = Instant::now();
    }
    let config = &scene.config;
    let dt = config.solver.dt as f64;
    let mut timings = Timings::default();
    let (mut divergence, mut last_good) = (None, None);
    let mut residuals = Residuals::default();
    let mut budget = CgBudget::for_solver(&config.solver);
    let mut flight = InFlight::new(&ctx.device, &sim);
    let (mut last, mut breakdowns, mut submitted) = (StepState::default(), 0, 0);
    let (mut cg_iterations, mut contacts, mut resolved) = (0u64, 0u64, 0u64);
    let mut dispatches = Series::default();
    // Iterations the next step records instead of the budget's: the whole
    // cap for a step solved again, or the first step's (`first_budget`).
    let mut forced = steps.first_budget;
    let mut since = Instant::now();
    while divergence.is_none() && (submitted < steps.total || !flight.is_empty()) {
        let mut finished = Vec::new();
        // Whether the host needs the state after the step just submitted.
        let mut synced = false;
        if submitted < steps.total {
            sim.set_cg_budget(forced.take().unwrap_or_else(|| budget.next()));
            finished.extend(flight.submit(ctx, &sim, submitted)?);
            submitted += 1;
            synced = obs.recording.as_ref().is_some_and(|r| r.due(submitted))
                || obs.monitor.as_ref().is_some_and(|m| m.due(submitted))
                || checkpoint
                    .as_ref()
                    .is_some_and(|c| c.taken.elapsed() >= CHECKPOINT_INTERVAL);
        }
        // Until a step is read back the budget is the whole cap: wait for
        // the first, so the steps behind it record what it took, not the cap.
        let wait = synced || submitted == steps.total || !budget.informed();
        while let Some(f) = flight.next(ctx, &sim, wait)? {
            finished.push(f);
        }
        let mut rewound = false;
        for f in finished {
            let state = f.state;
            if budget.cut(state.last_iterations, f.budget, state.last_residual) {
                // Solve the step again from its start with the whole
                // cap, dropping the steps recorded after it. Its time
                // runs on, so it includes what was thrown away.
                flight.rewind(ctx, &sim, &f)?;
                forced = Some(budget.cap());
                (submitted, resolved, rewound) = (f.step, resolved + 1, true);
                break;
            }
            // With the ring full the host waits for each step in turn, so
            // the time between completions is the step's.
            let now = Instant::now();
            if f.step >= steps.untimed {
                timings.push(
                    (now - since).as_secs_f64() * 1e3,
                    f.stage_ms.iter().copied(),
                );
                dispatches.push(f.dispatches as f64);
            }
            since = now;
            // The step's iterations and contacts, summed over its
            // substeps as on the CPU; `last_iterations` is their most, what
            // the budget of each solve follows.
            let iterations = state
                .cg_iterations_total
                .wrapping_sub(last.cg_iterations_total);
            residuals.push(state.last_residual, iterations);
            budget.observe(state.last_iterations, f.budget, state.last_residual);
            cg_iterations += iterations as u64;
            contacts += state.contacts_total.wrapping_sub(last.contacts_total) as u64;
            let breakdown = state.cg_breakdowns > breakdowns;
            (breakdowns, last) = (state.cg_breakdowns, state);
            if health::failed(state.health, breakdown) {
                // Run the step again from the state it started from, to
                // name what failed in its own system.
                while flight.next(ctx, &sim, true)?.is_some() {}
                let (x0, v0) = flight.start_of(&sim, &f)?;
                sim.upload_state(&x0, &v0, f.step as u32);
                sim.set_cg_budget(f.budget);
                let (flags, breakdown) = gpu_failing_solve(ctx, &sim, scene.substeps)?;
                let (diag, _, b) = sim.read_system()?;
                let (x, v) = (sim.read_positions()?, sim.read_velocities()?);
                divergence = Some(health::diagnose(&FailedStep {
                    step: f.step + 1,
                    flags,
                    breakdown,
                    diag: &diag,
                    b: &b,
                    x: &x,
                    v: &v,
                    max_speed: config.solver.max_speed,
                }));
                last_good = Some(State {
                    x: x0,
                    v: v0,
                    time: f.step as f64 * dt,
                    step: f.step,
                });
                break;
            }
            if let Some(c) = checkpoint.as_deref_mut() {
                c.reached = f.step + 1;
            }
            obs.progress(f.step + 1);
        }
        // After a rewind the step a due frame, sample or checkpoint was
        // for comes again.
        if !synced || divergence.is_some() || rewound {
            continue;
        }
        if let Some(r) = obs.recording.as_deref_mut() {
            r.gpu(submitted, &sim, scene)?;
        }
        if let Some(m) = obs.monitor.as_deref_mut().filter(|m| m.due(submitted)) {
            let (x, v) = (sim.read_positions()?, sim.read_velocities()?);
            m.record(submitted, scene, &x, &v, Some(&ctx.device))?;
        }
        if let Some(c) = checkpoint.as_deref_mut()
            && c.taken.elapsed() >= CHECKPOINT_INTERVAL
        {
            let (x, v) = (sim.read_positions()?, sim.read_velocities()?);
            c.state = State {
                x,
                v,
                time: submitted as f64 * dt,
                step: submitted,
            };
            c.taken = Instant::now();
        }
        // The next step's time starts after the host's own work.
        since = Instant::now();
    }
    ctx.finish()?;
    let (x, v) = (sim.read_positions()?, sim.read_velocities()?);
    let finite = x.iter().chain(&v).all(|p| p.is_finite());
    let done = last.steps.max(1) as f64;
    let (ms_per_step, ms_per_step_mean, stage_ms) = timings.summary();
    Ok(Report {
        backend: "gpu".into(),
        adapter: describe(&ctx.adapter),
        model: config.model,
        network: describe_network(scene, sim.network_kernel()),
        scene: config.scene,
        grid: config.cloth.grid,
        steps: last.steps as u64,
        dt: config.solver.dt,
        substeps: scene.substeps,
        ms_per_step,
        ms_per_step_mean,
        stage_ms,
        dispatches_per_step: (!dispatches.values.is_empty())
            .then(|| median(&mut dispatches.values).round() as u32),
        gpu_state_bytes: Some(sim.state_bytes()),
        gpu_bytes_per_vertex: Some(sim.state_bytes() as f64 / scene.cloth.vertex_count() as f64),
        gpu_split_arrays: sim
            .split_arrays()
            .into_iter()
            .map(|(name, parts)| (name.to_string(), parts))
            .collect(),
        gpu_subgroup_sums: Some(kernels.subgroups()),
        gpu_vectors: Some(sim.vector_layout().name().to_string()),
        peak_resident_bytes: peak_resident_bytes(),
        max_penetration: f32::from_bits(last.max_penetration_bits),
        finite,
        divergence,
        last_good,
        device_fault: None,
        preconditioner: config.solver.preconditioner,
        smoother: smoother_of(config),
        cg_iterations_mean: cg_iterations as f64 / done,
        cg_iterations_max: residuals.most_iterations,
        cg_residual_max: last.cg_residual_max,
        cg_residual_median: residuals.median(),
        cg_steps_above_goal: residuals.above_goal,
        cg_steps_resolved: resolved,
        cg_breakdowns: last.cg_breakdowns as u64,
        contacts_mean: contacts as f64 / done,
        energy_final: cpu::energy(scene, &x, &v).total(),
        self_contact: config.self_contact.enabled.then_some(SelfContactReport {
            pairs_max: last.self_pairs_max as u64,
            changed_total: last.self_changed_total as u64,
            failsafe_share: last.self_changed_total as f64
                / (done * scene.cloth.vertex_count() as f64),
            pushed_total: last.self_pushed_total as u64,
            zoned_total: last.self_zoned_total as u64,
            stopped_total: last.self_stopped_total as u64,
            held_total: last.self_held_total as u64,
            last_resort_steps: last.self_fallbacks as u64,
            overflow_steps: last.self_overflows as u64,
            contacts_max: last.cloth_contacts_max as u64,
            contacts_dropped: last.cloth_contacts_dropped as u64,
        }),
    })
}

/// GPU against CPU on the same scene: the largest position deviation (m)
/// after `steps` steps, and the contact totals of each. The GPU waits for
/// each step, and records the PCG iterations a run loop would
/// ([`SolvedSteps`]): each step ends where one recording the whole cap
/// ends. `each_step` sees both after every step (its number from 1);
/// `progress` is called before each step of every run: the GPU's and the
/// CPU's together, then the two of [`Sensitivity::measure`].
///
/// A faithful GPU does not end where the CPU does: rounding grows in
/// contact, and each solve stops elsewhere within its tolerance.
/// `sensitivity` measures how far two faithful CPU runs end apart;
/// [`Sensitivity::faithful`] says what the adapter's run may differ by.
pub struct Validation {
    pub max_deviation: f32,
    pub sensitivity: Sensitivity,
    pub cpu_contacts: u64,
    pub gpu_contacts: u64,
    pub adapter: String,
}

pub fn validate(
    ctx: &GpuContext,
    scene: Scene,
    steps: u64,
    mut each_step: impl FnMut(u64, &GpuSim, &CpuSim),
    mut progress: impl FnMut(),
) -> Result<Validation> {
    let kernels = ctx.kernels()?;
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene)?;
    let mut solved = SolvedSteps::for_scene(&gpu, &scene);
    let mut cpu = CpuSim::new(scene.clone());
    let mut cpu_contacts = 0;
    for k in 0..steps {
        progress();
        solved.step(&gpu)?;
        cpu_contacts += cpu.step().contacts as u64;
        each_step(k + 1, &gpu, &cpu);
    }
    ctx.finish()?;
    let x = gpu.read_positions()?;
    let reference = Reference {
        x: &cpu.state.x,
        contacts: cpu_contacts,
    };
    Ok(Validation {
        max_deviation: largest_distance(&x, &cpu.state.x),
        sensitivity: Sensitivity::measure(&scene, steps, reference, progress),
        cpu_contacts,
        gpu_contacts: gpu.read_state()?.contacts_total as u64,
        adapter: describe(&ctx.adapter),
    })
}

/// The process's peak resident memory so far (Linux's `VmHWM`), bytes.
fn peak_resident_bytes() -> Option<u64> {
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
        format!(
            "wgcloth run: scene {:?}, model {}, grid {}x{}, {} steps of {} s{}\n\
             backend      {} — {}{}{}\n\
             {}\
             ms/step      {:.3} (median{dispatches}), {:.3} (mean)\n\
             {memory}\
             stages (ms)  {}\n\
             pcg          {} preconditioner, {:.1} iterations/step (most {}), relative residual median {:.2e}, worst {:.2e}, {} steps above {RESIDUAL_GOAL:.0e}, {} solved again after the iteration budget cut them, {} breakdowns\n\
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

/// Runs the step that failed again from where it started, solve by solve
/// (`Scene::substeps`), up to the first solve that fails: its health flags
/// and breakdown. Its system is then the one the failure entered, which
/// `health::diagnose` reads; after later solves it has spread. The step
/// counts as taken.
pub fn cpu_failing_solve(sim: &mut CpuSim, max_speed: f32) -> (u32, bool) {
    let mut failure = (0, false);
    for _ in 0..sim.scene.substeps {
        let mut s = cpu::StepStats::default();
        for stage in Stage::ALL {
            sim.run_stage(stage, &mut s);
        }
        sim.state.time += sim.scene.substep_dt() as f64;
        failure = (
            integrate::health(&sim.state.x, &sim.state.v, max_speed),
            s.pcg.breakdown,
        );
        if health::failed(failure.0, failure.1) {
            break;
        }
    }
    sim.state.step += 1;
    failure
}

/// [`cpu_failing_solve`] on the GPU, `sim` holding the step's start.
pub fn gpu_failing_solve(ctx: &GpuContext, sim: &GpuSim, substeps: u32) -> Result<(u32, bool)> {
    let breakdowns = sim.read_state()?.cg_breakdowns;
    let mut failure = (0, false);
    for _ in 0..substeps {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        for stage in Stage::ALL {
            sim.record_stage(&mut encoder, stage);
        }
        ctx.queue.submit([encoder.finish()]);
        ctx.finish()?;
        let state = sim.read_state()?;
        failure = (state.health, state.cg_breakdowns > breakdowns);
        if health::failed(failure.0, failure.1) {
            break;
        }
    }
    Ok(failure)
}

/// Copies `from` into `to` without allocating.
fn keep(to: &mut State, from: &State) {
    to.x.copy_from_slice(&from.x);
    to.v.copy_from_slice(&from.v);
    (to.time, to.step) = (from.time, from.step);
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
