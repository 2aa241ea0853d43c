//! Running a scene for a number of steps on a backend and summarising it:
//! the `--report` JSON of DESIGN.md and the one-screen summary.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use crate::config::{ModelKind, SceneKind};
use crate::cpu::{self, CpuSim, State, integrate};
use crate::error::{Error, Result};
use crate::gpu::mlp::NetworkKernel;
use crate::gpu::{GpuContext, GpuSim, Kernels, context::describe};
use crate::health::{self, Divergence, FailedStep};
use crate::render::Recording;
use crate::scene::Scene;
use crate::stage::Stage;

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
    Gpu(Box<GpuContext>),
}

/// Resolves `auto`, and says why when it falls back to the CPU (no
/// adapter, or only a software one).
pub fn choose_backend(requested: Backend) -> Result<(Chosen, Option<String>)> {
    match requested {
        Backend::Cpu => Ok((Chosen::Cpu, None)),
        Backend::Gpu => Ok((Chosen::Gpu(Box::new(GpuContext::headless()?)), None)),
        Backend::Auto => Ok(match GpuContext::headless() {
            // A software rasteriser (lavapipe) runs the kernels on the same
            // CPU cores, several times slower than the reference path.
            Ok(ctx) if ctx.adapter.device_type == wgpu::DeviceType::Cpu => (
                Chosen::Cpu,
                Some(format!(
                    "notice: the only GPU adapter is a software one ({}); running on the faster CPU reference path (--backend gpu forces it)",
                    describe(&ctx.adapter)
                )),
            ),
            Ok(ctx) => (Chosen::Gpu(Box::new(ctx)), None),
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
    /// Median wall time of a step, ms.
    pub ms_per_step: f64,
    /// Median time of each stage per step, ms (GPU: timestamp queries,
    /// absent where the adapter has none).
    pub stage_ms: BTreeMap<String, f64>,
    /// Compute dispatches one step records (GPU only).
    pub dispatches_per_step: Option<u32>,
    /// Deepest any cloth vertex got inside the rigid surface, m (≥ 0).
    pub max_penetration: f32,
    pub finite: bool,
    /// The step that diverged, the vertex it started at and why
    /// (`health::diagnose`); the run stopped there.
    pub divergence: Option<Divergence>,
    /// The state before the diverging step.
    #[serde(skip)]
    pub last_good: Option<State>,
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

/// Per-step wall and stage times, summarised as medians.
#[derive(Default)]
struct Timings {
    wall_ms: Vec<f64>,
    stage_ms: BTreeMap<String, Vec<f64>>,
}

impl Timings {
    fn push(&mut self, wall_ms: f64, stages: impl IntoIterator<Item = (&'static str, f64)>) {
        self.wall_ms.push(wall_ms);
        for (name, ms) in stages {
            self.stage_ms.entry(name.to_string()).or_default().push(ms);
        }
    }

    fn medians(mut self) -> (f64, BTreeMap<String, f64>) {
        let stages = self
            .stage_ms
            .iter_mut()
            .map(|(k, v)| (k.clone(), median(v)))
            .collect();
        (median(&mut self.wall_ms), stages)
    }
}

/// How many steps a run takes, and how many of the first are left out of
/// the timings (pipelines warming up, the body not yet in contact).
#[derive(Clone, Copy, Debug)]
pub struct Steps {
    pub total: u64,
    pub untimed: u64,
}

impl Steps {
    pub fn all(total: u64) -> Steps {
        Steps { total, untimed: 0 }
    }
}

/// Runs `steps.total` steps, calling `progress` after each.
/// Runs `scene`, rendering frames into `recording` when given (of the
/// initial state and after every `--every` steps).
pub fn run(
    chosen: &Chosen,
    scene: Scene,
    steps: Steps,
    progress: impl FnMut(u64),
    recording: Option<&mut Recording>,
) -> Result<Report> {
    match chosen {
        Chosen::Cpu => run_cpu(scene, steps, progress, recording),
        Chosen::Gpu(ctx) => run_gpu(ctx, scene, steps, progress, recording),
    }
}

fn run_cpu(
    scene: Scene,
    steps: Steps,
    mut progress: impl FnMut(u64),
    mut recording: Option<&mut Recording>,
) -> Result<Report> {
    let config = scene.config.clone();
    let has_body = scene.rigid.is_some();
    let mut sim = CpuSim::new(scene);
    if let Some(r) = recording.as_deref_mut() {
        r.cpu(0, &sim)?;
    }
    let mut timings = Timings::default();
    let (mut cg_iters, mut contacts, mut breakdowns) = (0u64, 0u64, 0u64);
    let (mut cg_residual_max, mut max_penetration) = (0.0f32, 0.0f32);
    let mut divergence = None;
    let mut last_good = sim.state.clone();
    let max_speed = config.solver.max_speed;
    for k in 0..steps.total {
        keep(&mut last_good, &sim.state);
        let start = Instant::now();
        let s = sim.step();
        let wall = start.elapsed().as_secs_f64() * 1e3;
        if k >= steps.untimed {
            timings.push(
                wall,
                Stage::ALL
                    .iter()
                    .filter(|stage| has_body || !stage.needs_body())
                    .map(|stage| (stage.name(), s.stage_seconds[stage.index()] * 1e3)),
            );
        }
        cg_iters += s.pcg.iterations as u64;
        contacts += s.contacts as u64;
        breakdowns += s.pcg.breakdown as u64;
        cg_residual_max = cg_residual_max.max(s.pcg.relative_residual);
        max_penetration = max_penetration.max(s.max_penetration);
        let flags = integrate::health(&sim.state.x, &sim.state.v, max_speed);
        if health::failed(flags, s.pcg.breakdown) {
            let (matrix, b) = sim.system();
            divergence = Some(health::diagnose(&FailedStep {
                step: k + 1,
                flags,
                breakdown: s.pcg.breakdown,
                diag: &matrix.diag,
                b,
                x: &sim.state.x,
                v: &sim.state.v,
                max_speed,
            }));
            break;
        }
        if let Some(r) = recording.as_deref_mut() {
            r.cpu(k + 1, &sim)?;
        }
        progress(k + 1);
    }
    let done = sim.state.step.max(1) as f64;
    let (ms_per_step, stage_ms) = timings.medians();
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
        ms_per_step,
        stage_ms,
        dispatches_per_step: None,
        max_penetration,
        finite: sim.is_finite(),
        last_good: divergence.is_some().then_some(last_good),
        divergence,
        cg_iterations_mean: cg_iters as f64 / done,
        cg_residual_max,
        cg_breakdowns: breakdowns,
        contacts_mean: contacts as f64 / done,
        energy_final: sim.energy().total(),
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

fn run_gpu(
    ctx: &GpuContext,
    scene: Scene,
    steps: Steps,
    mut progress: impl FnMut(u64),
    mut recording: Option<&mut Recording>,
) -> Result<Report> {
    let kernels = Arc::new(Kernels::new(&ctx.device)?);
    let sim = GpuSim::new(kernels, &ctx.device, &ctx.queue, &scene)?;
    if let Some(r) = recording.as_deref_mut() {
        r.gpu(0, &sim, &scene)?;
    }
    let mut timings = Timings::default();
    let mut dispatches = 0;
    let (mut divergence, mut last_good) = (None, None);
    let mut breakdowns = 0;
    for k in 0..steps.total {
        let start = Instant::now();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        sim.record_checkpoint(&mut encoder);
        dispatches = sim.record_step(&mut encoder);
        ctx.queue.submit([encoder.finish()]);
        ctx.finish()?;
        let wall = start.elapsed().as_secs_f64() * 1e3;
        let stages = sim.read_stage_ms()?.unwrap_or_default();
        if k >= steps.untimed {
            timings.push(wall, stages);
        }
        let state = sim.read_state()?;
        let breakdown = state.cg_breakdowns > breakdowns;
        breakdowns = state.cg_breakdowns;
        if health::failed(state.health, breakdown) {
            let (diag, _, b) = sim.read_system()?;
            let diag: Vec<glam::Mat3> = diag.iter().map(|d| d.to_mat3()).collect();
            let (x, v) = (sim.read_positions()?, sim.read_velocities()?);
            divergence = Some(health::diagnose(&FailedStep {
                step: k + 1,
                flags: state.health,
                breakdown,
                diag: &diag,
                b: &b,
                x: &x,
                v: &v,
                max_speed: scene.config.solver.max_speed,
            }));
            let (x, v) = sim.read_kept()?;
            last_good = Some(State {
                x,
                v,
                time: k as f64 * scene.config.solver.dt as f64,
                step: k,
            });
            break;
        }
        if let Some(r) = recording.as_deref_mut() {
            r.gpu(k + 1, &sim, &scene)?;
        }
        progress(k + 1);
    }
    let state = sim.read_state()?;
    let (x, v) = (sim.read_positions()?, sim.read_velocities()?);
    let finite = x.iter().chain(&v).all(|p| p.is_finite());
    let done = state.steps.max(1) as f64;
    let (ms_per_step, stage_ms) = timings.medians();
    let config = &scene.config;
    Ok(Report {
        backend: "gpu".into(),
        adapter: describe(&ctx.adapter),
        model: config.model,
        network: describe_network(&scene, sim.network_kernel()),
        scene: config.scene,
        grid: config.cloth.grid,
        steps: state.steps as u64,
        dt: config.solver.dt,
        ms_per_step,
        stage_ms,
        dispatches_per_step: Some(dispatches),
        max_penetration: f32::from_bits(state.max_penetration_bits),
        finite,
        divergence,
        last_good,
        cg_iterations_mean: state.cg_iterations_total as f64 / done,
        cg_residual_max: state.cg_residual_max,
        cg_breakdowns: state.cg_breakdowns as u64,
        contacts_mean: state.contacts_total as f64 / done,
        energy_final: cpu::energy(&scene, &x, &v).total(),
    })
}

/// GPU against CPU on the same scene: the largest position deviation (m)
/// after `steps` steps, and the contact totals of each.
///
/// Contact makes the dynamics discontinuous (a vertex entering the band
/// gets k_d ḋ at once; friction switches between stick and slip), so
/// rounding-level differences grow. `sensitivity` measures how much: the
/// deviation between the CPU run and a CPU run whose free vertices start
/// `PERTURBATION` m away. A GPU as faithful as f32 allows deviates by
/// about that much.
pub struct Validation {
    pub max_deviation: f32,
    pub sensitivity: f32,
    pub cpu_contacts: u64,
    pub gpu_contacts: u64,
    pub adapter: String,
}

/// Initial offset of the sensitivity run, m: a few f32 ulps at 1 m.
pub const PERTURBATION: f32 = 1e-7;

fn max_deviation(a: &[glam::Vec3], b: &[glam::Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length())
        .fold(
            0.0f32,
            |m, d| if d.is_nan() { f32::INFINITY } else { m.max(d) },
        )
}

pub fn validate(
    ctx: &GpuContext,
    scene: Scene,
    steps: u64,
    mut progress: impl FnMut(u64),
) -> Result<Validation> {
    let kernels = Arc::new(Kernels::new(&ctx.device)?);
    let gpu = GpuSim::new(kernels, &ctx.device, &ctx.queue, &scene)?;
    let mut cpu = CpuSim::new(scene.clone());
    let mut nudged = CpuSim::new(scene);
    for (i, x) in nudged.state.x.iter_mut().enumerate() {
        // A fixed, irregular direction per vertex.
        let phase = i as f32 * 2.399_963;
        *x += PERTURBATION
            * glam::Vec3::new(phase.cos(), phase.sin(), (0.5 * phase).cos()).normalize();
    }
    let mut cpu_contacts = 0;
    for k in 0..steps {
        gpu.step();
        cpu_contacts += cpu.step().contacts as u64;
        nudged.step();
        progress(k + 1);
    }
    ctx.finish()?;
    let x = gpu.read_positions()?;
    Ok(Validation {
        max_deviation: max_deviation(&x, &cpu.state.x),
        sensitivity: max_deviation(&nudged.state.x, &cpu.state.x),
        cpu_contacts,
        gpu_contacts: gpu.read_state()?.contacts_total as u64,
        adapter: describe(&ctx.adapter),
    })
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
        format!(
            "wgcloth run: scene {:?}, model {}, grid {}x{}, {} steps of {} s\n\
             backend      {} — {}\n\
             {}\
             ms/step      {:.3} (median{dispatches})\n\
             stages (ms)  {}\n\
             pcg          {:.1} iterations/step, worst relative residual {:.2e}, {} breakdowns\n\
             contacts     {:.1} per step\n\
             penetration  {:.4} m deepest (thickness not counted)\n\
             state        {} (final energy {:.4} J)",
            self.scene,
            self.model.name(),
            self.grid[0],
            self.grid[1],
            self.steps,
            self.dt,
            self.backend,
            self.adapter,
            self.network
                .as_ref()
                .map(|n| format!("network      {n}\n"))
                .unwrap_or_default(),
            self.ms_per_step,
            if stages.is_empty() {
                "(no timestamp queries on this adapter)".into()
            } else {
                stages.join(", ")
            },
            self.cg_iterations_mean,
            self.cg_residual_max,
            self.cg_breakdowns,
            self.contacts_mean,
            self.max_penetration,
            if self.finite { "finite" } else { "NOT FINITE" },
            self.energy_final,
        ) + &self
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

/// Copies `from` into `to` without allocating.
fn keep(to: &mut State, from: &State) {
    to.x.copy_from_slice(&from.x);
    to.v.copy_from_slice(&from.v);
    (to.time, to.step) = (from.time, from.step);
}
