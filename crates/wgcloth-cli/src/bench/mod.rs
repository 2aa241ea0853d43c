//! `wgcloth bench` (DESIGN "Command line"): one row per backend × model ×
//! solve × grid with the median ms/step after a warm-up, the per-stage
//! medians, contacts and CG iterations. The headline is the converged step
//! (every solve to a relative residual of 1e-3, multigrid against Jacobi,
//! with the iterations each took); the thesis's fixed 25 Jacobi iterations
//! stay for comparison. Then the networks' throughput over batches of
//! contacts, and the thesis's headline measure, seconds per sphere period
//! with the analytic force against each network on the same backend.
//! [`traffic`] sets each PCG iteration against its memory-traffic floor
//! and every other stage against its floor of memory or arithmetic;
//! [`plot`] draws the figure.

pub mod plot;
pub mod traffic;
pub mod worlds;

use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;

use crate::run::{self, Chosen, RESIDUAL_GOAL, Report, Steps, median};
use wgcloth::config::{Config, ModelKind, Preconditioner, SceneKind, Smoother};
use wgcloth::cpu::CpuSim;
use wgcloth::cpu::pcg::{self, PcgScratch, SolveSettings};
use wgcloth::error::{Error, Result};
use wgcloth::gpu::mlp::{BatchShape, NetworkBatch};
use wgcloth::gpu::{GpuContext, context::describe};
use wgcloth::multigrid;
use wgcloth::nn::weights::{self, Shipped};
use wgcloth::scene::Scene;
use wgcloth::stage::Stage;
use wgcloth_learn::domain::{Rng, uniform_inputs};

/// How a row's steps are solved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solve {
    /// The thesis's: one solve a step (`--substeps 1`) of 25 Jacobi-PCG
    /// iterations at tolerance 0, the same solver work for every model.
    Thesis,
    /// Every solve to |S r| ≤ [`RESIDUAL_GOAL`] |S b| with this
    /// preconditioner, and as many solves a step as the scene takes
    /// (`Scene::substeps`).
    Converged(Preconditioner),
}

impl Solve {
    /// The most iterations a converged solve may take: far above what
    /// multigrid needs, and above the most Jacobi took at 256² (3149).
    pub fn cap(self) -> u32 {
        match self {
            Solve::Thesis => 25,
            Solve::Converged(Preconditioner::Multigrid) => 100,
            Solve::Converged(Preconditioner::Jacobi) => 5000,
        }
    }
}

/// A model, for a network model the shipped network it runs instead of its
/// default one, and how its steps are solved.
#[derive(Clone, Copy, Debug)]
pub struct Variant {
    pub model: ModelKind,
    pub network: Option<Shipped>,
    /// How its steps are solved.
    pub solve: Solve,
    /// Whether the cloth is kept from passing through itself (stage
    /// "separate").
    pub self_contact: bool,
}

impl Variant {
    const fn of(model: ModelKind) -> Variant {
        Variant {
            model,
            network: None,
            solve: Solve::Thesis,
            self_contact: false,
        }
    }

    const fn converged(model: ModelKind, preconditioner: Preconditioner) -> Variant {
        Variant {
            model,
            network: None,
            solve: Solve::Converged(preconditioner),
            self_contact: false,
        }
    }

    /// The model's name, the network's file stem when not the default, and
    /// the preconditioner of a converged solve.
    pub fn label(&self) -> String {
        let model = match self.network {
            None => self.model.name().into(),
            Some(net) => {
                let stem = net.path.rsplit('/').next().unwrap_or(net.path);
                format!(
                    "{} ({})",
                    self.model.name(),
                    stem.trim_end_matches(".safetensors")
                )
            }
        };
        let solved = match self.solve {
            Solve::Thesis => model,
            Solve::Converged(p) => format!("{model}, 1e-3 {}", p.name()),
        };
        match self.self_contact {
            true => format!("{solved}, self-contact"),
            false => solved,
        }
    }

    /// The sphere scene at N×N with this variant's network and solve, a
    /// converged solve's steps taking `substeps` solves (0: the scene's).
    pub fn scene(&self, grid: u32, substeps: u32) -> Result<Scene> {
        let mut c = config(SceneKind::Sphere, self.model, grid);
        if let Solve::Converged(p) = self.solve {
            let solver = &mut c.solver;
            solver.preconditioner = p;
            (solver.cg_iters, solver.cg_tol) = (self.solve.cap(), RESIDUAL_GOAL);
            solver.substeps = substeps;
        }
        c.self_contact.enabled = self.self_contact;
        let mut scene = Scene::new(&c)?;
        if let Some(net) = self.network {
            scene.network = Some(Arc::new(net.read()?.network()));
            // Names the network in the report.
            scene.config.contact.weights = Some(net.path.into());
        }
        Ok(scene)
    }
}

/// The default run: friction-net, every step solved with multigrid.
pub const HEADLINE: Variant = Variant::converged(ModelKind::FrictionNet, Preconditioner::Multigrid);

/// The default run with the cloth kept from passing through itself.
pub const SELF_CONTACT: Variant = Variant {
    self_contact: true,
    ..HEADLINE
};

/// Every model with its default network and the friction model with the
/// thesis-size network too, solved as the thesis did; then the default
/// model and the analytic one solved to the goal with multigrid, and the
/// default model with Jacobi; last the default run with the cloth kept
/// from passing through itself.
pub const VARIANTS: [Variant; ModelKind::ALL.len() + 5] = {
    let rest = [
        Variant {
            model: ModelKind::FrictionNet,
            network: Some(weights::FRICTION_THESIS),
            solve: Solve::Thesis,
            self_contact: false,
        },
        HEADLINE,
        Variant::converged(ModelKind::Friction, Preconditioner::Multigrid),
        Variant::converged(ModelKind::FrictionNet, Preconditioner::Jacobi),
        SELF_CONTACT,
    ];
    let models = ModelKind::ALL.len();
    let mut all = [HEADLINE; ModelKind::ALL.len() + 5];
    let mut k = 0;
    while k < all.len() {
        all[k] = match k < models {
            true => Variant::of(ModelKind::ALL[k]),
            false => rest[k - models],
        };
        k += 1;
    }
    all
};

/// Steps before the timed ones: the sphere reaches the cloth and pushes it
/// (about 0.8 s into the default motion).
pub const UNTIMED_STEPS: u64 = 80;

/// One sphere period of the default motion (2 s at h = 0.01 s).
pub const PERIOD_STEPS: u64 = 200;

/// What `wgcloth bench` measures.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub quick: bool,
    pub grids: Vec<u32>,
    /// Further grids run on a hardware GPU only (a software adapter and
    /// the CPU would take hours over them).
    pub hardware_gpu_grids: Vec<u32>,
    /// Steps before the timed ones, and timed steps per row.
    pub steps: Steps,
    /// Grid of the sphere-period rows (the thesis's: 32²), and its steps.
    pub period_grid: u32,
    pub period_steps: u64,
    /// Contacts per network batch.
    pub batch_sizes: Vec<usize>,
    /// Timed repeats of each batch and period.
    pub repeats: usize,
    /// Grids of the CPU solver-iteration rows.
    pub iteration_grids: Vec<u32>,
    /// The backends whose rows it measures.
    pub backends: Backends,
    /// Solves a step of the converged rows (`solver.substeps`; 0: the
    /// scene's own, `Scene::substeps`). The thesis's rows take one.
    pub substeps: u32,
    /// Worlds of the batched-worlds rows (the default run at
    /// `period_grid`), and the steps each row times.
    pub worlds: Vec<usize>,
    pub worlds_steps: u64,
}

/// Which backends a bench measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backends {
    /// The CPU, and the GPU where an adapter exists.
    Both,
    /// The CPU's rows alone, no adapter opened: a machine without a GPU,
    /// or one where a software adapter's rows would take most of the time.
    Cpu,
    /// The GPU's rows alone: no CPU step, period, network or
    /// solver-iteration row (a hardware GPU's run, where the CPU's rows
    /// would take most of the time and are measured elsewhere); an error
    /// where there is no adapter.
    Gpu,
}

impl BenchOptions {
    /// Every grid from 32² to 256², batches of 1k to 1M contacts.
    pub fn full() -> BenchOptions {
        BenchOptions {
            quick: false,
            grids: vec![32, 64, 128, 256],
            hardware_gpu_grids: vec![512, 1024],
            steps: Steps {
                untimed: UNTIMED_STEPS,
                total: UNTIMED_STEPS + 40,
                first_budget: None,
            },
            period_grid: 32,
            period_steps: PERIOD_STEPS,
            batch_sizes: vec![1_000, 4_000, 16_000, 64_000, 256_000, 1_000_000],
            repeats: 3,
            iteration_grids: vec![128, 256, 512],
            backends: Backends::Both,
            substeps: 0,
            worlds: vec![1, 16, 64, 256, 1024],
            worlds_steps: 5,
        }
    }

    /// These options' GPU rows alone.
    pub fn gpu_only(self) -> BenchOptions {
        BenchOptions {
            backends: Backends::Gpu,
            iteration_grids: Vec::new(),
            ..self
        }
    }

    /// These options' CPU rows alone.
    pub fn cpu_only(self) -> BenchOptions {
        BenchOptions {
            backends: Backends::Cpu,
            ..self
        }
    }

    /// Two grids, fewer steps and batches: a few minutes on lavapipe.
    pub fn quick() -> BenchOptions {
        BenchOptions {
            quick: true,
            grids: vec![32, 64],
            hardware_gpu_grids: Vec::new(),
            steps: Steps {
                untimed: UNTIMED_STEPS,
                total: UNTIMED_STEPS + 20,
                first_budget: None,
            },
            batch_sizes: vec![1_000, 16_000],
            repeats: 1,
            iteration_grids: vec![128],
            worlds: vec![1, 16, 64],
            worlds_steps: 3,
            ..BenchOptions::full()
        }
    }
}

impl BenchOptions {
    /// The CPU solver-iteration rows alone, 128² to 1024² (a minute or
    /// two): no step, period or network rows.
    pub fn iterations() -> BenchOptions {
        BenchOptions {
            grids: Vec::new(),
            hardware_gpu_grids: Vec::new(),
            period_steps: 0,
            batch_sizes: Vec::new(),
            iteration_grids: vec![128, 256, 512, 1024],
            worlds: Vec::new(),
            ..BenchOptions::full()
        }
    }

    /// The batched-worlds rows alone (`bench --worlds`), 1 to 1,024 worlds
    /// on the CPU and on the GPU where there is one: no step, period,
    /// network or solver-iteration rows.
    pub fn worlds() -> BenchOptions {
        BenchOptions {
            grids: Vec::new(),
            hardware_gpu_grids: Vec::new(),
            period_steps: 0,
            batch_sizes: Vec::new(),
            iteration_grids: Vec::new(),
            ..BenchOptions::full()
        }
    }
}

/// A benchmark scene: N×N cloth and the thesis's step and solver, one
/// solve of 25 Jacobi-PCG iterations at tolerance 0, so every model does
/// the same solver work.
pub fn scene(kind: SceneKind, model: ModelKind, grid: u32) -> Result<Scene> {
    Scene::new(&config(kind, model, grid))
}

/// [`scene`]'s configuration.
fn config(kind: SceneKind, model: ModelKind, grid: u32) -> Config {
    let mut c = Config {
        scene: kind,
        model,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    c.solver.substeps = 1;
    c.solver.cg_iters = Solve::Thesis.cap();
    c.solver.cg_tol = 0.0;
    c.solver.preconditioner = Preconditioner::Jacobi;
    c
}

/// The network and its input Jacobian over one batch of contacts.
#[derive(Clone, Debug, Serialize)]
pub struct NetworkRow {
    pub network: &'static str,
    pub backend: String,
    /// `reverse` on the CPU; the GPU kernel's name.
    pub kernel: String,
    pub contacts: usize,
    /// Floating-point operations per contact as the kernel does them.
    pub flop_per_contact: usize,
    /// Median over the repeats.
    pub ms: f64,
    pub contacts_per_s: f64,
    pub gflop_per_s: f64,
}

/// One step row: the run's report under the variant's label.
#[derive(Clone, Debug, Serialize)]
pub struct StepRow {
    pub label: String,
    /// Whether every step was solved to the goal (else the thesis's 25
    /// Jacobi iterations).
    pub converged: bool,
    /// Cloth vertices (grid²), springs and triangles, and the body's vertices.
    pub particles: usize,
    pub springs: usize,
    pub triangles: usize,
    pub body_vertices: usize,
    /// Σ stage_ms / ms_per_step: how much of the step the stages account
    /// for (on the GPU the rest is submission and waiting).
    pub stage_coverage: f64,
    /// A contact's network multiply-adds with the Jacobian in reverse mode
    /// (0 for an analytic model).
    pub network_multiply_adds: usize,
    #[serde(flatten)]
    pub report: Report,
}

impl StepRow {
    /// The step at which the run stopped as diverging (its state exploding,
    /// e.g. the thesis's 25 iterations at 1024²): it has no step time to
    /// compare, and the table says so rather than print one.
    pub fn diverged_at(&self) -> Option<u64> {
        self.report.divergence.as_ref().map(|d| d.step)
    }
}

/// Wall time of one sphere period (at 32² unless told otherwise), from a
/// fresh simulator.
#[derive(Clone, Debug, Serialize)]
pub struct PeriodRow {
    pub backend: String,
    pub label: String,
    pub model: ModelKind,
    pub seconds: f64,
    /// Against the analytic model the network learned (friction for
    /// friction-net, naive for naive-net), same backend, same run.
    pub ratio_to_analytic: Option<f64>,
}

/// A step's growth with the particle count: ms ∝ particles^exponent
/// between two grids (≤ 1: no faster than linear).
#[derive(Clone, Debug, Serialize)]
pub struct ScalingRow {
    pub backend: String,
    pub label: String,
    pub from_grid: u32,
    pub to_grid: u32,
    pub exponent: f64,
}

/// One PCG iteration of the friction rows against its memory-traffic
/// floor on the same backend.
#[derive(Clone, Debug, Serialize)]
pub struct TrafficRow {
    pub backend: String,
    pub grid: u32,
    /// [`traffic::Layout::iteration_bytes`] for this backend's layout.
    pub bytes_per_iteration: u64,
    /// Those bytes at the measured copy bandwidth.
    pub floor_ms: f64,
    /// The pcg stage's median time over its iterations (the stage's
    /// setup pass included).
    pub measured_ms: f64,
    pub times_floor: f64,
}

/// One CPU solver iteration of each preconditioner on the hanging cloth's
/// system after one step, timed apart from the solve's setup, against its
/// memory-traffic floor.
#[derive(Clone, Debug, Serialize)]
pub struct IterationRow {
    pub grid: u32,
    pub preconditioner: Preconditioner,
    /// Multigrid's smoother.
    pub smoother: Option<Smoother>,
    /// [`traffic::Layout::iteration_bytes`] or
    /// [`traffic::Layout::multigrid_iteration_bytes`] for the CPU layout.
    pub bytes_per_iteration: u64,
    /// Those bytes at the measured copy bandwidth.
    pub floor_ms: f64,
    /// The median over pairs of solves run back to back of (time of 2k
    /// iterations − time of k) / k.
    pub measured_ms: f64,
    pub times_floor: f64,
    /// The rest of a k-iteration solve: the setup (multigrid's Galerkin
    /// operators and smoothers; Jacobi's inverse diagonal) and r₀.
    pub setup_ms: f64,
}

/// A converged row's solve: the iterations its steps took to the goal,
/// against the same model's row with the thesis's 25 Jacobi iterations.
#[derive(Clone, Debug, Serialize)]
pub struct ConvergedRow {
    pub backend: String,
    pub label: String,
    pub grid: u32,
    pub preconditioner: Preconditioner,
    /// Solves a step (`Scene::substeps`).
    pub substeps: u32,
    /// The row's median ms/step.
    pub ms_per_step: f64,
    /// PCG iterations per step (summed over its solves), mean and most.
    pub iterations_mean: f64,
    pub iterations_max: u32,
    /// The worst relative residual a step ended at, and the steps that
    /// ended above the goal (a solve the iteration cap cut short).
    pub residual_max: f32,
    pub steps_above_goal: u64,
    /// Steps the run loop solved again because its budget had cut them
    /// (`Report::cg_steps_resolved`): the budget follows steps read back a
    /// few steps late, so a sudden jump in iterations (the sphere reaching
    /// the cloth) can outrun it.
    pub steps_resolved: u64,
    /// This row's ms/step over the thesis-solve row's (same backend, model
    /// and grid; not solved to any tolerance), where neither diverged.
    pub times_thesis_step: Option<f64>,
    /// The step at which this row's run diverged ([`StepRow::diverged_at`]).
    pub diverged_at: Option<u64>,
}

/// One stage of the default model's thesis-solve rows against its floor
/// on the same backend: the time its bytes take at the copy bandwidth or
/// its multiply-adds at the arithmetic rate, whichever is longer.
#[derive(Clone, Debug, Serialize)]
pub struct StageTrafficRow {
    pub backend: String,
    pub grid: u32,
    pub stage: &'static str,
    /// [`traffic::Layout::stage_bytes`] for this backend's layout.
    pub bytes: u64,
    /// [`traffic::stage_multiply_adds`].
    pub multiply_adds: f64,
    /// The bytes at the measured copy bandwidth.
    pub memory_floor_ms: f64,
    /// The multiply-adds at the measured arithmetic rate.
    pub arithmetic_floor_ms: f64,
    /// The larger of the two, and which it is ("memory" or "arithmetic").
    pub floor_ms: f64,
    pub bound: &'static str,
    /// The stage's median time in the row.
    pub measured_ms: f64,
    pub times_floor: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub quick: bool,
    pub period_grid: u32,
    pub period_steps: u64,
    pub cpu: String,
    /// The GPU adapter, or why there are no GPU rows.
    pub gpu: String,
    pub rows: Vec<StepRow>,
    pub converged: Vec<ConvergedRow>,
    pub scaling: Vec<ScalingRow>,
    pub bandwidth: Vec<traffic::Bandwidth>,
    pub arithmetic: Vec<traffic::Arithmetic>,
    pub cg_traffic: Vec<TrafficRow>,
    pub iterations: Vec<IterationRow>,
    pub stage_traffic: Vec<StageTrafficRow>,
    pub networks: Vec<NetworkRow>,
    pub periods: Vec<PeriodRow>,
    /// Batched worlds against separate simulators (CPU).
    pub worlds: Vec<worlds::WorldsRow>,
}

/// The backends of `which`: the CPU's unless GPU rows alone, the GPU's
/// where an adapter exists unless CPU rows alone; the adapter, or why there
/// is none. GPU rows alone with no adapter is an error.
fn backends(which: Backends) -> Result<(Vec<Chosen>, String)> {
    if which == Backends::Cpu {
        return Ok((vec![Chosen::Cpu], "no GPU rows: CPU rows alone".into()));
    }
    match GpuContext::headless() {
        Ok(ctx) => {
            let note = describe(&ctx.adapter);
            let cpu = (which == Backends::Both).then_some(Chosen::Cpu);
            Ok((cpu.into_iter().chain([Chosen::gpu(ctx)]).collect(), note))
        }
        Err(e) if which == Backends::Gpu => Err(e),
        Err(e) => Ok((vec![Chosen::Cpu], format!("no GPU rows: {e}"))),
    }
}

/// One step row: `v` on `backend` at `grid`².
fn step_row(backend: &Chosen, v: Variant, grid: u32, opts: &BenchOptions) -> Result<StepRow> {
    let scene = v.scene(grid, opts.substeps)?;
    let (particles, springs) = (scene.cloth.vertex_count(), scene.cloth.springs.len());
    let triangles = scene.cloth.triangles.len();
    let body_vertices = scene.rigid.as_ref().map_or(0, |b| b.mesh.vertices.len());
    let network_multiply_adds = scene
        .network
        .as_ref()
        .map_or(0, |n| n.jacobian_multiply_adds());
    let report = run::run(backend, scene, opts.steps, Default::default())?;
    // A run that diverged before its timed steps has no step time.
    let stage_coverage = match report.ms_per_step > 0.0 {
        true => report.stage_ms.values().sum::<f64>() / report.ms_per_step,
        false => 0.0,
    };
    Ok(StepRow {
        label: v.label(),
        converged: v.solve != Solve::Thesis,
        particles,
        springs,
        triangles,
        body_vertices,
        stage_coverage,
        network_multiply_adds,
        report,
    })
}

/// Runs the whole table; `progress` hears what is being measured.
pub fn bench(opts: &BenchOptions, mut progress: impl FnMut(&str)) -> Result<BenchReport> {
    let (chosen, gpu_note) = backends(opts.backends)?;
    let mut rows = Vec::new();
    for backend in &chosen {
        for grid in grids(opts, backend) {
            for v in VARIANTS {
                progress(&format!("step {} {} {grid}²", name(backend), v.label()));
                let row = step_row(backend, v, grid, opts)?;
                let r = &row.report;
                progress(&match &r.divergence {
                    Some(d) => format!("  diverged at step {}: {}", d.step, d.reason),
                    None => format!(
                        "  {:.3} ms/step (median), {:.3} (mean), {:.1} iterations a step, worst residual {:.1e}",
                        r.ms_per_step, r.ms_per_step_mean, r.cg_iterations_mean, r.cg_residual_max
                    ),
                });
                rows.push(row);
            }
        }
    }
    progress("copy bandwidth and arithmetic rate");
    let mut bandwidth = vec![traffic::cpu_bandwidth()];
    let mut arithmetic = vec![traffic::cpu_arithmetic()];
    for backend in &chosen {
        if let Some(ctx) = backend.context() {
            bandwidth.push(traffic::gpu_bandwidth(ctx)?);
            arithmetic.push(traffic::gpu_arithmetic(ctx)?);
        }
    }
    let mut periods = Vec::new();
    for backend in chosen.iter().filter(|_| opts.period_steps > 0) {
        let mut seconds = Vec::new();
        for v in VARIANTS.into_iter().filter(|v| v.solve == Solve::Thesis) {
            progress(&format!("period {} {}", name(backend), v.label()));
            let scene = v.scene(opts.period_grid, opts.substeps)?;
            let steps = Steps::all(opts.period_steps);
            let mut runs = (0..opts.repeats)
                .map(|_| {
                    let start = Instant::now();
                    run::run(backend, scene.clone(), steps, Default::default())?;
                    Ok(start.elapsed().as_secs_f64())
                })
                .collect::<Result<Vec<f64>>>()?;
            seconds.push((v, median(&mut runs)));
        }
        let of = |m: ModelKind| seconds.iter().find(|(v, _)| v.model == m).map(|(_, s)| *s);
        for &(v, s) in &seconds {
            let analytic = v.model.analytic().and_then(of);
            periods.push(PeriodRow {
                backend: name(backend).into(),
                label: v.label(),
                model: v.model,
                seconds: s,
                ratio_to_analytic: analytic.map(|a| s / a),
            });
        }
    }
    let gpu = chosen.iter().find_map(Chosen::context);
    let networks = network_rows(opts, gpu, &mut progress)?;
    let iterations = solver_iterations(opts, &bandwidth[0], &mut progress)?;
    let mut worlds = match opts.backends {
        Backends::Gpu => Vec::new(),
        _ => worlds::rows(opts, &mut progress)?,
    };
    if let Some(ctx) = gpu {
        worlds.extend(worlds::gpu_rows(opts, ctx, &mut progress)?);
    }
    Ok(BenchReport {
        quick: opts.quick,
        period_grid: opts.period_grid,
        period_steps: opts.period_steps,
        cpu: format!(
            "CPU reference path ({} threads)",
            rayon::current_num_threads()
        ),
        gpu: gpu_note,
        converged: converged(&rows),
        scaling: scaling(&rows),
        cg_traffic: cg_traffic(&rows, &bandwidth),
        iterations,
        stage_traffic: stage_traffic(&rows, &bandwidth, &arithmetic),
        bandwidth,
        arithmetic,
        rows,
        networks,
        periods,
        worlds,
    })
}

/// The converged rows' solves, each against its thesis-solve twin.
fn converged(rows: &[StepRow]) -> Vec<ConvergedRow> {
    rows.iter()
        .filter(|r| r.converged)
        .map(|r| {
            let (report, grid) = (&r.report, r.report.grid[0]);
            let thesis = rows.iter().find(|t| {
                !t.converged
                    && t.label == report.model.name()
                    && t.report.backend == report.backend
                    && t.report.grid[0] == grid
                    && t.diverged_at().is_none()
            });
            ConvergedRow {
                backend: report.backend.clone(),
                label: r.label.clone(),
                grid,
                preconditioner: report.preconditioner,
                substeps: report.substeps,
                ms_per_step: report.ms_per_step,
                iterations_mean: report.cg_iterations_mean,
                iterations_max: report.cg_iterations_max,
                residual_max: report.cg_residual_max,
                steps_above_goal: report.cg_steps_above_goal,
                steps_resolved: report.cg_steps_resolved,
                times_thesis_step: thesis
                    .filter(|_| r.diverged_at().is_none())
                    .map(|t| report.ms_per_step / t.report.ms_per_step),
                diverged_at: r.diverged_at(),
            }
        })
        .collect()
}

/// The grids a backend runs: the hardware-GPU ones only on a hardware GPU.
fn grids(opts: &BenchOptions, backend: &Chosen) -> Vec<u32> {
    let hardware = backend
        .context()
        .is_some_and(|ctx| ctx.adapter.device_type != wgpu::DeviceType::Cpu);
    let mut grids = opts.grids.clone();
    if hardware {
        grids.extend(&opts.hardware_gpu_grids);
    }
    grids
}

/// Each backend × variant's growth from its smallest grid of at least 64²
/// (the smallest of all when only the largest is) to its largest.
fn scaling(rows: &[StepRow]) -> Vec<ScalingRow> {
    let mut out = Vec::new();
    let mut series: Vec<(&str, &str)> = Vec::new();
    for r in rows {
        let key = (r.report.backend.as_str(), r.label.as_str());
        if !series.contains(&key) {
            series.push(key);
        }
    }
    for (backend, label) in series {
        let of: Vec<&StepRow> = rows
            .iter()
            .filter(|r| r.report.backend == backend && r.label == label)
            .filter(|r| r.diverged_at().is_none())
            .collect();
        let Some(to) = of.iter().max_by_key(|r| r.particles) else {
            continue;
        };
        let smallest = |at_least: u32| {
            of.iter()
                .filter(|r| r.report.grid[0] >= at_least && r.particles < to.particles)
                .min_by_key(|r| r.particles)
        };
        if let Some(from) = smallest(64).or_else(|| smallest(0)) {
            let (a, b) = (from, to);
            out.push(ScalingRow {
                backend: backend.into(),
                label: label.into(),
                from_grid: a.report.grid[0],
                to_grid: b.report.grid[0],
                exponent: (b.report.ms_per_step / a.report.ms_per_step).ln()
                    / (b.particles as f64 / a.particles as f64).ln(),
            });
        }
    }
    out
}

/// The friction rows' PCG iterations against the floor of their backend.
fn cg_traffic(rows: &[StepRow], bandwidth: &[traffic::Bandwidth]) -> Vec<TrafficRow> {
    rows.iter()
        .filter(|r| r.label == ModelKind::Friction.name() && r.diverged_at().is_none())
        .filter_map(|r| {
            let backend = r.report.backend.as_str();
            let gb_per_s = bandwidth.iter().find(|b| b.backend == backend)?.gb_per_s;
            let layout = traffic::of(&r.report);
            let pcg_ms = r.report.stage_ms.get(Stage::Pcg.name())?;
            let iterations = r.report.cg_iterations_mean;
            let bytes = layout.iteration_bytes(r.particles as u64, r.springs as u64);
            let floor_ms = bytes as f64 / (gb_per_s * 1e9) * 1e3;
            let measured_ms = pcg_ms / iterations;
            (iterations > 0.0).then(|| TrafficRow {
                backend: backend.into(),
                grid: r.report.grid[0],
                bytes_per_iteration: bytes,
                floor_ms,
                measured_ms,
                times_floor: measured_ms / floor_ms,
            })
        })
        .collect()
}

/// Timed pairs of solves in the iteration rows: their differences are
/// noisier than a whole step's time, so they need more repeats.
const REPEATS_PER_SOLVE: usize = 9;

/// Iterations per timed solve of each preconditioner (and twice as many):
/// enough to dwarf the timer, few enough that neither reaches round-off.
fn timed_iterations(preconditioner: Preconditioner) -> u32 {
    match preconditioner {
        Preconditioner::Multigrid => 8,
        Preconditioner::Jacobi => 40,
    }
}

/// The CPU's solver iteration per preconditioner at each iteration grid:
/// the hanging cloth's system after one step, solved at tolerance 0 for k
/// and for 2k iterations; the difference is k iterations without the setup.
fn solver_iterations(
    opts: &BenchOptions,
    bandwidth: &traffic::Bandwidth,
    progress: &mut impl FnMut(&str),
) -> Result<Vec<IterationRow>> {
    let mut out = Vec::new();
    for &grid in &opts.iteration_grids {
        let mut sim = CpuSim::new(scene(SceneKind::Hang, ModelKind::Friction, grid)?);
        sim.step();
        let (a, b) = sim.system();
        let (a, b, cloth) = (a.clone(), b.to_vec(), &sim.scene.cloth);
        let springs = cloth.springs.len() as u64;
        let solvers = Smoother::ALL
            .map(|s| (Preconditioner::Multigrid, Some(s)))
            .into_iter()
            .chain([(Preconditioner::Jacobi, None)]);
        for (preconditioner, smoother) in solvers {
            let name = run::solver_name(preconditioner, smoother);
            progress(&format!("solver iteration cpu {name} {grid}²"));
            let mut scratch = PcgScratch::default();
            let k = timed_iterations(preconditioner);
            let mut solve_ms = |iterations: u32| {
                let settings = SolveSettings {
                    max_iters: iterations,
                    tol: 0.0,
                    preconditioner,
                    smoother: smoother.unwrap_or_default(),
                };
                let mut x = sim.state.v.clone();
                let start = Instant::now();
                let outcome = pcg::solve(&a, cloth, &b, &mut x, settings, &mut scratch);
                let ms = start.elapsed().as_secs_f64() * 1e3;
                match outcome.iterations == iterations {
                    true => Ok(ms),
                    false => Err(Error::Unsupported(format!(
                        "bench: the {grid}² solve stopped after {} of {iterations} iterations",
                        outcome.iterations
                    ))),
                }
            };
            // k and 2k iterations back to back, in alternating order, so
            // the machine's drift falls mostly on both of a pair: the
            // medians of the pairs' differences. Medians of the two series
            // apart had given a negative setup on this VM.
            solve_ms(k)?;
            let (mut per_iteration, mut setups) = (Vec::new(), Vec::new());
            for repeat in 0..REPEATS_PER_SOLVE {
                let (once, twice) = match repeat % 2 {
                    0 => (solve_ms(k)?, solve_ms(2 * k)?),
                    _ => {
                        let twice = solve_ms(2 * k)?;
                        (solve_ms(k)?, twice)
                    }
                };
                per_iteration.push((twice - once) / k as f64);
                setups.push(2.0 * once - twice);
            }
            let measured_ms = median(&mut per_iteration);
            let bytes = match preconditioner {
                Preconditioner::Multigrid => traffic::CPU.multigrid_iteration_bytes(
                    &multigrid::levels(cloth.nx, cloth.ny),
                    springs,
                    smoother.unwrap_or_default(),
                ),
                Preconditioner::Jacobi => {
                    traffic::CPU.iteration_bytes(cloth.vertex_count() as u64, springs)
                }
            };
            let floor_ms = bytes as f64 / (bandwidth.gb_per_s * 1e9) * 1e3;
            out.push(IterationRow {
                grid,
                preconditioner,
                smoother,
                bytes_per_iteration: bytes,
                floor_ms,
                measured_ms,
                times_floor: measured_ms / floor_ms,
                setup_ms: median(&mut setups),
            });
        }
    }
    Ok(out)
}

/// Every stage but pcg (and but contact in a row without contacts) of the
/// friction-net rows (thesis solve) against the floors of their backend.
fn stage_traffic(
    rows: &[StepRow],
    bandwidth: &[traffic::Bandwidth],
    arithmetic: &[traffic::Arithmetic],
) -> Vec<StageTrafficRow> {
    let mut out = Vec::new();
    for r in rows
        .iter()
        .filter(|r| !r.converged && r.label == ModelKind::FrictionNet.name())
        .filter(|r| r.diverged_at().is_none())
    {
        let backend = r.report.backend.as_str();
        let (Some(b), Some(a)) = (
            bandwidth.iter().find(|b| b.backend == backend),
            arithmetic.iter().find(|a| a.backend == backend),
        ) else {
            continue;
        };
        let layout = traffic::of(&r.report);
        let extent = traffic::Extent {
            vertices: r.particles as u64,
            springs: r.springs as u64,
            triangles: r.triangles as u64,
            body_vertices: r.body_vertices as u64,
            contacts: r.report.contacts_mean,
            network_multiply_adds: r.network_multiply_adds as u64,
        };
        for stage in Stage::ALL {
            let (Some(bytes), Some(&measured_ms)) = (
                layout.stage_bytes(stage, &extent),
                r.report.stage_ms.get(stage.name()),
            ) else {
                continue;
            };
            // A stage with nothing to move (contact, before any contact).
            if bytes == 0 {
                continue;
            }
            let multiply_adds = traffic::stage_multiply_adds(stage, &extent);
            let memory_floor_ms = bytes as f64 / (b.gb_per_s * 1e9) * 1e3;
            let arithmetic_floor_ms = multiply_adds / (a.g_multiply_adds_per_s * 1e9) * 1e3;
            let (floor_ms, bound) = if arithmetic_floor_ms > memory_floor_ms {
                (arithmetic_floor_ms, "arithmetic")
            } else {
                (memory_floor_ms, "memory")
            };
            out.push(StageTrafficRow {
                backend: backend.into(),
                grid: r.report.grid[0],
                stage: stage.name(),
                bytes,
                multiply_adds,
                memory_floor_ms,
                arithmetic_floor_ms,
                floor_ms,
                bound,
                measured_ms,
                times_floor: measured_ms / floor_ms,
            });
        }
    }
    out
}

fn name(backend: &Chosen) -> &'static str {
    match backend {
        Chosen::Cpu => "cpu",
        Chosen::Gpu { .. } => "gpu",
    }
}

/// Floating-point work per batch at most: the CPU and a software adapter
/// get a few seconds' worth, a real GPU far more.
const CPU_BUDGET: f64 = 4e9;
const GPU_BUDGET: f64 = 2e12;

fn network_rows(
    opts: &BenchOptions,
    gpu: Option<&GpuContext>,
    progress: &mut impl FnMut(&str),
) -> Result<Vec<NetworkRow>> {
    let kernels = match gpu {
        Some(ctx) => Some(ctx.kernels()?),
        None => None,
    };
    let mut rows = Vec::new();
    let largest = opts.batch_sizes.iter().copied().max().unwrap_or(0);
    for shipped in weights::SHIPPED {
        let network = shipped.read()?.network();
        let (net, kind, wrt) = (&network.mlp, network.kind, network.kind.wrt());
        let mut rng = Rng::new(5);
        let inputs: Vec<f32> = (0..largest)
            .flat_map(|_| uniform_inputs(kind, &mut rng))
            .collect();
        // A contact is one row of the network per evaluation, each timed
        // with its whole Jacobian.
        let evaluations = kind.evaluations();
        let flop = 2 * net.jacobian_multiply_adds() * evaluations;
        for &n in &opts.batch_sizes {
            let rows_n = n * evaluations;
            let batch = &inputs[..rows_n * net.inputs()];
            if opts.backends != Backends::Gpu && (n * flop) as f64 <= CPU_BUDGET {
                progress(&format!("network {} cpu {n}", shipped.path));
                let ms = timed(opts.repeats, || {
                    net.forward_jacobian_parallel(batch, wrt.clone());
                    Ok(())
                })?;
                rows.push(network_row(shipped, "cpu", "reverse", n, flop, ms));
            }
            let (Some(ctx), Some(kernels)) = (gpu, &kernels) else {
                continue;
            };
            let software = ctx.adapter.device_type == wgpu::DeviceType::Cpu;
            let budget = if software { CPU_BUDGET } else { GPU_BUDGET };
            // Every kernel does at least the reverse-mode work: skip a batch
            // over budget before allocating it.
            if (n * flop) as f64 > budget {
                continue;
            }
            let on_gpu = NetworkBatch::new(
                kernels,
                &ctx.device,
                net,
                wrt.clone(),
                BatchShape::new(rows_n),
            )?;
            let flop = 2 * on_gpu.network().multiply_adds_per_contact() * evaluations;
            if (n * flop) as f64 > budget {
                continue;
            }
            progress(&format!("network {} gpu {n}", shipped.path));
            on_gpu.upload(&ctx.queue, batch)?;
            let ms = timed(opts.repeats, || {
                on_gpu.run(&ctx.device, &ctx.queue);
                ctx.finish()
            })?;
            let kernel = on_gpu.network().kernel().name();
            rows.push(network_row(shipped, "gpu", kernel, n, flop, ms));
        }
    }
    Ok(rows)
}

fn network_row(
    shipped: Shipped,
    backend: &str,
    kernel: &str,
    contacts: usize,
    flop_per_contact: usize,
    ms: f64,
) -> NetworkRow {
    let contacts_per_s = contacts as f64 / (ms * 1e-3);
    NetworkRow {
        network: shipped.path,
        backend: backend.into(),
        kernel: kernel.into(),
        contacts,
        flop_per_contact,
        ms,
        contacts_per_s,
        gflop_per_s: contacts_per_s * flop_per_contact as f64 * 1e-9,
    }
}

/// Median wall time of `repeats` calls after one untimed call, ms.
fn timed(repeats: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    f()?;
    let mut ms = Vec::with_capacity(repeats);
    for _ in 0..repeats {
        let start = Instant::now();
        f()?;
        ms.push(start.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(&mut ms))
}

/// How a column's cells line up in the terminal (Markdown aligns them too).
#[derive(Clone, Copy)]
enum Align {
    Left,
    Right,
}

/// One table of the bench's output: its title, column heads and cells,
/// rendered for the terminal or as Markdown from the same cells.
struct Table {
    title: String,
    columns: Vec<(&'static str, Align)>,
    rows: Vec<Vec<String>>,
}

impl Table {
    /// A table of `rows`, each made into cells by `cells`; none where there
    /// are no rows.
    fn of<T>(
        title: String,
        columns: &[(&'static str, Align)],
        rows: &[T],
        cells: impl Fn(&T) -> Vec<String>,
    ) -> Option<Table> {
        (!rows.is_empty()).then(|| Table {
            title,
            columns: columns.to_vec(),
            rows: rows.iter().map(cells).collect(),
        })
    }

    /// Padded columns two spaces apart, under the title.
    fn text(&self) -> String {
        let width = |k: usize| {
            (self.rows.iter().map(|r| r[k].chars().count()))
                .chain([self.columns[k].0.chars().count()])
                .max()
                .unwrap_or(0)
        };
        let widths: Vec<usize> = (0..self.columns.len()).map(width).collect();
        let line = |cells: Vec<&str>| {
            let padded: Vec<String> = (cells.iter().zip(&self.columns).zip(&widths))
                .map(|((cell, (_, align)), &w)| match align {
                    Align::Left => format!("{cell:<w$}"),
                    Align::Right => format!("{cell:>w$}"),
                })
                .collect();
            padded.join("  ").trim_end().to_string() + "\n"
        };
        let mut out = format!("\n{}\n", self.title);
        out += &line(self.columns.iter().map(|c| c.0).collect());
        for row in &self.rows {
            out += &line(row.iter().map(String::as_str).collect());
        }
        out
    }

    /// A Markdown table under the title in bold.
    fn markdown(&self) -> String {
        let line = |cells: Vec<&str>| format!("| {} |\n", cells.join(" | "));
        let mut out = format!("\n**{}**\n\n", self.title);
        out += &line(self.columns.iter().map(|c| c.0).collect());
        out += &line(
            (self.columns.iter())
                .map(|(_, align)| match align {
                    Align::Left => "---",
                    Align::Right => "---:",
                })
                .collect(),
        );
        for row in &self.rows {
            out += &line(row.iter().map(String::as_str).collect());
        }
        out
    }
}

/// A step time, or the step its run diverged at.
fn ms_cell(ms: f64, diverged_at: Option<u64>, digits: usize) -> String {
    match diverged_at {
        Some(step) => format!("div@{step}"),
        None => format!("{ms:.digits$}"),
    }
}

impl BenchReport {
    /// The terminal tables (those a run measured).
    pub fn table(&self) -> String {
        let mut out = format!("cpu: {}\ngpu: {}\n", self.cpu, self.gpu);
        for t in self.tables() {
            out += &t.text();
        }
        out
    }

    /// The same tables in Markdown (`bench --markdown`), for BENCHMARKS.md.
    pub fn markdown(&self) -> String {
        let mut out = format!("CPU: {}; GPU: {}.\n", self.cpu, self.gpu);
        for t in self.tables() {
            out += &t.markdown();
        }
        out
    }

    fn tables(&self) -> Vec<Table> {
        use Align::{Left, Right};
        let stages: Vec<&'static str> = Stage::ALL
            .iter()
            .map(|s| s.name())
            .filter(|s| self.rows.iter().any(|r| r.report.stage_ms.contains_key(*s)))
            .collect();
        let mut step_columns = vec![
            ("backend", Left),
            ("model", Left),
            ("grid", Right),
            ("ms/step", Right),
            ("contacts", Right),
            ("cg", Right),
            ("staged", Right),
        ];
        step_columns.extend(stages.iter().map(|&s| (s, Right)));
        let ratio = |r: Option<f64>| r.map(|r| format!("{r:.2}")).unwrap_or_default();
        [
            Table::of(
                "ms/step (median), contacts and CG iterations (means), each stage's median ms".into(),
                &step_columns,
                &self.rows,
                |row| {
                    let r = &row.report;
                    let mut cells = vec![
                        r.backend.clone(),
                        row.label.clone(),
                        r.grid[0].to_string(),
                        ms_cell(r.ms_per_step, row.diverged_at(), 3),
                        format!("{:.1}", r.contacts_mean),
                        format!("{:.1}", r.cg_iterations_mean),
                        format!("{:.0}%", 100.0 * row.stage_coverage),
                    ];
                    cells.extend(stages.iter().map(|s| {
                        (r.stage_ms.get(*s)).map_or("-".into(), |ms| format!("{ms:.3}"))
                    }));
                    cells
                },
            ),
            Table::of(
                format!("converged step: every solve to |S r| ≤ {RESIDUAL_GOAL:.0e} |S b|"),
                &[
                    ("backend", Left),
                    ("model", Left),
                    ("grid", Right),
                    ("solves", Right),
                    ("ms/step", Right),
                    ("iters", Right),
                    ("most", Right),
                    ("worst", Right),
                    ("above", Right),
                    ("again", Right),
                    ("× thesis", Right),
                ],
                &self.converged,
                |c| {
                    vec![
                        c.backend.clone(),
                        c.label.clone(),
                        c.grid.to_string(),
                        c.substeps.to_string(),
                        ms_cell(c.ms_per_step, c.diverged_at, 3),
                        format!("{:.1}", c.iterations_mean),
                        c.iterations_max.to_string(),
                        format!("{:.2e}", c.residual_max),
                        c.steps_above_goal.to_string(),
                        c.steps_resolved.to_string(),
                        ratio(c.times_thesis_step),
                    ]
                },
            ),
            Table::of(
                "step growth, ms/step ∝ particles^exponent".into(),
                &[
                    ("backend", Left),
                    ("model", Left),
                    ("grids", Right),
                    ("exponent", Right),
                ],
                &self.scaling,
                |g| {
                    vec![
                        g.backend.clone(),
                        g.label.clone(),
                        format!("{}² → {}²", g.from_grid, g.to_grid),
                        format!("{:.2}", g.exponent),
                    ]
                },
            ),
            Table::of(
                "copy bandwidth".into(),
                &[("backend", Left), ("GB/s", Right), ("method", Left)],
                &self.bandwidth,
                |b| vec![b.backend.clone(), format!("{:.1}", b.gb_per_s), b.method.clone()],
            ),
            Table::of(
                "multiply-add rate".into(),
                &[("backend", Left), ("G/s", Right), ("method", Left)],
                &self.arithmetic,
                |a| {
                    vec![
                        a.backend.clone(),
                        format!("{:.1}", a.g_multiply_adds_per_s),
                        a.method.clone(),
                    ]
                },
            ),
            Table::of(
                "PCG iteration against its memory-traffic floor (friction rows)".into(),
                &[
                    ("backend", Left),
                    ("grid", Right),
                    ("MB/iter", Right),
                    ("floor ms", Right),
                    ("measured ms", Right),
                    ("× floor", Right),
                ],
                &self.cg_traffic,
                |t| {
                    vec![
                        t.backend.clone(),
                        t.grid.to_string(),
                        format!("{:.2}", t.bytes_per_iteration as f64 * 1e-6),
                        format!("{:.4}", t.floor_ms),
                        format!("{:.4}", t.measured_ms),
                        format!("{:.1}", t.times_floor),
                    ]
                },
            ),
            Table::of(
                "CPU solver iteration against its memory-traffic floor (hanging cloth, after one step)"
                    .into(),
                &[
                    ("preconditioner", Left),
                    ("grid", Right),
                    ("MB/iter", Right),
                    ("floor ms", Right),
                    ("measured ms", Right),
                    ("× floor", Right),
                    ("setup ms", Right),
                ],
                &self.iterations,
                |t| {
                    vec![
                        run::solver_name(t.preconditioner, t.smoother),
                        t.grid.to_string(),
                        format!("{:.2}", t.bytes_per_iteration as f64 * 1e-6),
                        format!("{:.4}", t.floor_ms),
                        format!("{:.4}", t.measured_ms),
                        format!("{:.2}", t.times_floor),
                        format!("{:.3}", t.setup_ms),
                    ]
                },
            ),
            Table::of(
                "each other stage against its floor, memory or arithmetic (friction-net rows)".into(),
                &[
                    ("backend", Left),
                    ("grid", Right),
                    ("stage", Right),
                    ("MB", Right),
                    ("M madds", Right),
                    ("floor ms", Right),
                    ("bound", Right),
                    ("measured ms", Right),
                    ("× floor", Right),
                ],
                &self.stage_traffic,
                |t| {
                    vec![
                        t.backend.clone(),
                        t.grid.to_string(),
                        t.stage.to_string(),
                        format!("{:.3}", t.bytes as f64 * 1e-6),
                        format!("{:.2}", t.multiply_adds * 1e-6),
                        format!("{:.4}", t.floor_ms),
                        t.bound.to_string(),
                        format!("{:.4}", t.measured_ms),
                        format!("{:.1}", t.times_floor),
                    ]
                },
            ),
            Table::of(
                format!(
                    "sphere period ({} steps at {}², fresh simulator)",
                    self.period_steps, self.period_grid
                ),
                &[
                    ("backend", Left),
                    ("model", Left),
                    ("seconds", Right),
                    ("× analytic", Right),
                ],
                &self.periods,
                |p| {
                    vec![
                        p.backend.clone(),
                        p.label.clone(),
                        format!("{:.3}", p.seconds),
                        ratio(p.ratio_to_analytic),
                    ]
                },
            ),
            Table::of(
                "network and input Jacobian over a batch".into(),
                &[
                    ("network", Left),
                    ("backend", Left),
                    ("kernel", Left),
                    ("contacts", Right),
                    ("ms", Right),
                    ("contacts/s", Right),
                    ("GFLOP/s", Right),
                ],
                &self.networks,
                |n| {
                    vec![
                        n.network.to_string(),
                        n.backend.clone(),
                        n.kernel.to_string(),
                        n.contacts.to_string(),
                        format!("{:.3}", n.ms),
                        format!("{:.0}", n.contacts_per_s),
                        format!("{:.2}", n.gflop_per_s),
                    ]
                },
            ),
            Table::of(
                "batched worlds against separate simulators (default run, every solve to 1e-3)"
                    .into(),
                &[
                    ("backend", Left),
                    ("worlds", Right),
                    ("grid", Right),
                    ("steps", Right),
                    ("batched world-steps/s", Right),
                    ("separate world-steps/s", Right),
                    ("× separate", Right),
                    ("dispatches a batch step (network's)", Right),
                    ("ms to record a batch step", Right),
                ],
                &self.worlds,
                |w| {
                    vec![
                        w.backend.clone(),
                        w.worlds.to_string(),
                        w.grid.to_string(),
                        w.steps.to_string(),
                        format!("{:.1}", w.batched),
                        format!("{:.1}", w.separate),
                        format!("{:.2}", w.ratio),
                        w.dispatches
                            .map_or("—".into(), |(d, net)| format!("{d} ({net})")),
                        w.record_ms.map_or("—".into(), |ms| format!("{ms:.3}")),
                    ]
                },
            ),
        ]
        .into_iter()
        .flatten()
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgcloth::health::Divergence;

    /// A diverged row has no step time: the table names the step it
    /// diverged at, and the growth, iteration-traffic and thesis ratios
    /// leave it out rather than divide by its zero.
    #[test]
    fn a_diverged_row_is_named_and_left_out() {
        let opts = BenchOptions {
            steps: Steps {
                untimed: 1,
                total: 3,
                first_budget: None,
            },
            ..BenchOptions::quick()
        };
        let model = ModelKind::Friction;
        let thesis = Variant::of(model);
        let solved = Variant::converged(model, Preconditioner::Multigrid);
        let mut rows = Vec::new();
        for grid in [6, 10, 14] {
            for v in [thesis, solved] {
                rows.push(step_row(&Chosen::Cpu, v, grid, &opts).expect("a tiny CPU run"));
            }
        }
        let kept =
            |rows: &[StepRow]| (scaling(rows), cg_traffic(rows, &[traffic::cpu_bandwidth()]));
        let (growth, traffic) = kept(&rows);
        assert!(
            growth.iter().all(|g| g.to_grid == 14) && growth.len() == 2,
            "{growth:?}"
        );
        assert_eq!(traffic.len(), 3);
        // The largest thesis row diverges at step 2 before any timed step.
        let last = rows
            .iter_mut()
            .rfind(|r| !r.converged)
            .expect("a thesis row");
        last.report.divergence = Some(Divergence {
            step: 2,
            vertex: 0,
            reason: "planted".into(),
        });
        last.report.ms_per_step = 0.0;
        let (growth, traffic) = kept(&rows);
        let thesis_growth = growth
            .iter()
            .find(|g| g.label == thesis.label())
            .expect("a thesis series");
        assert_eq!(thesis_growth.to_grid, 10, "the diverged 14² row left out");
        assert!(thesis_growth.exponent.is_finite());
        assert_eq!(traffic.len(), 2, "{traffic:?}");
        let solves = converged(&rows);
        let at_14 = solves.iter().find(|c| c.grid == 14).expect("the 14² solve");
        assert_eq!(at_14.times_thesis_step, None, "no ratio to a diverged row");
        assert!(
            solves
                .iter()
                .filter(|c| c.grid < 14)
                .all(|c| c.times_thesis_step.is_some())
        );
        let report = BenchReport {
            quick: true,
            period_grid: 6,
            period_steps: 0,
            cpu: String::new(),
            gpu: String::new(),
            converged: solves,
            scaling: growth,
            cg_traffic: traffic,
            iterations: Vec::new(),
            stage_traffic: Vec::new(),
            bandwidth: Vec::new(),
            arithmetic: Vec::new(),
            rows,
            networks: Vec::new(),
            periods: Vec::new(),
            worlds: Vec::new(),
        };
        let table = report.table();
        assert!(table.contains("div@2"), "{table}");
        assert!(!table.contains("inf") && !table.contains("NaN"), "{table}");
    }
}
