//! Running a scene for a number of steps on a backend: the choice of
//! backend, what a run feeds as it goes, and the GPU's fall back to the
//! CPU. The loops are `on_cpu` and `on_gpu`; what a run reports and its
//! one-screen summary, `report`; GPU against CPU, `validate`.

use std::time::{Duration, Instant};

use crate::frames::Recording;
use crate::monitor::Monitor;
use wgcloth::cpu::{CpuSim, State};
use wgcloth::error::{Error, Result};
use wgcloth::gpu::{GpuContext, context::describe};
use wgcloth::scene::Scene;

mod on_cpu;
mod on_gpu;
mod report;
mod validate;
mod worlds;

pub use on_cpu::cpu_failing_solve;
use on_cpu::run_cpu;
pub use on_gpu::gpu_failing_solve;
use on_gpu::run_gpu;
pub use report::{
    DeviceFault, RESIDUAL_GOAL, Report, SelfContactReport, check_diverged, median, solver_name,
};
pub use validate::{Validation, validate};
pub use worlds::{Batch, BatchReport, WorldReport, batch_on, run_batch};

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

/// Copies `from` into `to` without allocating.
fn keep(to: &mut State, from: &State) {
    to.x.copy_from_slice(&from.x);
    to.v.copy_from_slice(&from.v);
    to.loads.copy_from_slice(&from.loads);
    (to.time, to.step) = (from.time, from.step);
}
