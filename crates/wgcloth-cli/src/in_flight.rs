//! The GPU run loop's steps in flight: each step is submitted with a copy
//! of its statistics and timestamps into a reused staging buffer, mapped
//! asynchronously, so the host waits only when [`DEPTH`] steps are already
//! in flight (for the oldest) and never creates a buffer per step. Each
//! step's starting positions, velocities and statistics are kept on the
//! GPU in a ring one deeper than the steps in flight, so a step found cut
//! short or diverging a few steps late still has the state before it: to
//! solve it again ([`InFlight::rewind`]) or to name what failed.

use std::collections::VecDeque;
use std::time::Instant;

use wgcloth::cpu::State;
use wgcloth::error::{Error, Result};
use wgcloth::gpu::context::WATCHDOG;
use wgcloth::gpu::layout::StepState;
use wgcloth::gpu::readback::{Mapped, Staging};
use wgcloth::gpu::{GpuContext, GpuSim};

/// Steps submitted and not yet read.
pub const DEPTH: usize = 3;

/// Where the timestamps start in a staging buffer (after the statistics).
const TICKS_AT: u64 = 256;

struct Slot {
    staging: Staging,
    x: wgpu::Buffer,
    v: wgpu::Buffer,
    /// The loads the cloth's contacts carried into the step.
    loads: wgpu::Buffer,
    /// The statistics before the step (its clock among them).
    stats: wgpu::Buffer,
}

impl Slot {
    /// Its copy of `GpuSim::step_start`, in the same order.
    fn kept(&self) -> [&wgpu::Buffer; 4] {
        [&self.x, &self.v, &self.loads, &self.stats]
    }
}

struct Pending {
    step: u64,
    budget: u32,
    dispatches: u32,
    record_ms: f64,
    slot: usize,
    submission: wgpu::SubmissionIndex,
}

/// A step read back: its statistics, its passes' times, and the slot that
/// holds the state it started from ([`InFlight::start_of`]).
pub struct Finished {
    /// The step's index from 0.
    pub step: u64,
    /// The PCG iterations the step recorded.
    pub budget: u32,
    /// The compute dispatches the step recorded.
    pub dispatches: u32,
    /// The host's time to record the step (`GpuSim::encode_step`), ms.
    pub record_ms: f64,
    /// The clock and statistics right after the step.
    pub state: StepState,
    /// Each pass's time, empty without timestamp queries.
    pub stage_ms: Vec<(&'static str, f64)>,
    slot: usize,
}

/// The ring of steps in flight and their kept start states.
pub struct InFlight {
    slots: Vec<Slot>,
    pending: VecDeque<Pending>,
}

impl InFlight {
    /// Staging and kept-state buffers for `sim`'s steps, [`DEPTH`] + 1 of each.
    pub fn new(device: &wgpu::Device, sim: &GpuSim) -> InFlight {
        let ticks = sim.timestamps().map_or(0, |t| t.size());
        let vectors = sim.positions().size();
        let buffer = |label, size, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        let kept = wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC;
        let slots = (0..=DEPTH)
            .map(|_| Slot {
                staging: Staging::new(device, "step statistics", TICKS_AT + ticks),
                x: buffer("kept positions", vectors, kept),
                v: buffer("kept velocities", vectors, kept),
                loads: buffer("kept loads", sim.loads().size(), kept),
                stats: buffer("kept statistics", sim.statistics().size(), kept),
            })
            .collect();
        InFlight {
            slots,
            pending: VecDeque::new(),
        }
    }

    /// Whether no step is in flight.
    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }

    /// Submits step `step` (its state kept first, its statistics copied
    /// after it); when [`DEPTH`] steps are already in flight, first waits
    /// for the oldest and returns it.
    pub fn submit(
        &mut self,
        ctx: &GpuContext,
        sim: &GpuSim,
        step: u64,
    ) -> Result<Option<Finished>> {
        let oldest = match self.pending.len() >= DEPTH {
            true => self.next(ctx, sim, true)?,
            false => None,
        };
        let k = step as usize % self.slots.len();
        let slot = &self.slots[k];
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        let (stats, staging) = (sim.statistics(), slot.staging.buffer());
        for (from, to) in sim.step_start().into_iter().zip(slot.kept()) {
            encoder.copy_buffer_to_buffer(from, 0, to, 0, from.size());
        }
        let recording = Instant::now();
        let dispatches = sim.encode_step(&mut encoder);
        let record_ms = recording.elapsed().as_secs_f64() * 1e3;
        encoder.copy_buffer_to_buffer(stats, 0, staging, 0, stats.size());
        if let Some(t) = sim.timestamps() {
            encoder.copy_buffer_to_buffer(t, 0, staging, TICKS_AT, t.size());
        }
        slot.staging.copying();
        let submission = ctx.queue.submit([encoder.finish()]);
        slot.staging.map();
        self.pending.push_back(Pending {
            step,
            budget: sim.cg_budget(),
            dispatches,
            record_ms,
            slot: k,
            submission,
        });
        Ok(oldest)
    }

    /// The oldest step in flight once it is read: waiting for it when
    /// `wait`, else only if it has already finished.
    pub fn next(&mut self, ctx: &GpuContext, sim: &GpuSim, wait: bool) -> Result<Option<Finished>> {
        let Some(oldest) = self.pending.front() else {
            return Ok(None);
        };
        let poll = match wait {
            true => wgpu::PollType::Wait {
                submission_index: Some(oldest.submission.clone()),
                timeout: Some(WATCHDOG),
            },
            false => wgpu::PollType::Poll,
        };
        ctx.device.poll(poll).map_err(|e| {
            Error::Gpu(format!(
                "waiting for step {} failed (hung or lost device): {e}",
                oldest.step + 1
            ))
        })?;
        ctx.fault()?;
        let slot = &self.slots[oldest.slot];
        let failed = |what: &str| {
            Err(Error::Gpu(format!(
                "step {}'s statistics {what}",
                oldest.step + 1
            )))
        };
        match slot.staging.mapped() {
            Mapped::Ready => {}
            Mapped::Failed => return failed("could not be read"),
            Mapped::Pending if wait => return failed("never arrived"),
            Mapped::Pending => return Ok(None),
        }
        let oldest = self.pending.pop_front().expect("checked above");
        let bytes: Vec<u8> = slot.staging.take(0).unwrap_or_default();
        if bytes.len() < size_of::<StepState>() {
            return Err(Error::Gpu(format!(
                "reading step {}'s statistics",
                oldest.step + 1
            )));
        }
        let state: StepState = bytemuck::pod_read_unaligned(&bytes[..size_of::<StepState>()]);
        let ticks: Vec<u64> =
            bytemuck::pod_collect_to_vec(&bytes[(TICKS_AT as usize).min(bytes.len())..]);
        Ok(Some(Finished {
            step: oldest.step,
            budget: oldest.budget,
            dispatches: oldest.dispatches,
            record_ms: oldest.record_ms,
            state,
            stage_ms: match ticks.is_empty() {
                true => Vec::new(),
                false => sim.stage_ms(&ticks),
            },
            slot: oldest.slot,
        }))
    }

    /// Puts `sim` back where `finished`'s step started (positions,
    /// velocities, clock and run statistics), after waiting for the steps
    /// in flight behind it and dropping them (read, not counted): they
    /// followed a state that is being replaced.
    pub fn rewind(&mut self, ctx: &GpuContext, sim: &GpuSim, finished: &Finished) -> Result<()> {
        while self.next(ctx, sim, true)?.is_some() {}
        let slot = &self.slots[finished.slot];
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        for (from, to) in slot.kept().into_iter().zip(sim.step_start()) {
            encoder.copy_buffer_to_buffer(from, 0, to, 0, from.size());
        }
        ctx.queue.submit([encoder.finish()]);
        Ok(())
    }

    /// The state `finished`'s step started from, `dt` a step.
    pub fn start_of(&self, sim: &GpuSim, finished: &Finished, dt: f32) -> Result<State> {
        let slot = &self.slots[finished.slot];
        Ok(State {
            x: sim.read_vec3(&slot.x)?,
            v: sim.read_vec3(&slot.v)?,
            time: finished.step as f64 * dt as f64,
            step: finished.step,
            loads: sim.read_loads(&slot.loads)?,
        })
    }
}
