//! A run on the GPU: steps in flight, statistics read asynchronously,
//! checkpoints for the CPU to resume from.

use std::time::Instant;

use super::report::{
    Report, Residuals, SelfContactReport, Series, Timings, describe_network, median,
    peak_resident_bytes, smoother_of,
};
use super::{CHECKPOINT_INTERVAL, Checkpoint, Observers, Steps};
use crate::in_flight::InFlight;
use wgcloth::cpu::{self, State};
use wgcloth::error::Result;
use wgcloth::gpu::layout::StepState;
use wgcloth::gpu::{CgBudget, GpuContext, GpuSim, context::describe};
use wgcloth::health::{self, FailedStep};
use wgcloth::scene::Scene;
use wgcloth::stage::Stage;

/// Runs `scene` on the GPU with up to [`in_flight::DEPTH`] steps in
/// flight, each step's statistics read asynchronously; the host waits for
/// a step only when the ring is full, or to draw, monitor or checkpoint
/// it. With a `checkpoint` the state is copied to it every
/// [`CHECKPOINT_INTERVAL`] for the CPU to resume from.
pub(super) fn run_gpu(
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
    let (mut dispatches, mut record_ms) = (Series::default(), Series::default());
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
                record_ms.push(f.record_ms);
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
                let start = flight.start_of(&sim, &f, config.solver.dt)?;
                sim.upload_state(&start);
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
                last_good = Some(start);
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
            c.state = State {
                x: sim.read_positions()?,
                v: sim.read_velocities()?,
                time: submitted as f64 * dt,
                step: submitted,
                loads: sim.read_loads(sim.loads())?,
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
        record_ms_per_step: (!record_ms.values.is_empty()).then(|| median(&mut record_ms.values)),
        gpu_state_bytes: Some(sim.state_bytes()),
        gpu_bytes_per_vertex: Some(sim.state_bytes() as f64 / scene.cloth.vertex_count() as f64),
        gpu_split_arrays: sim
            .split_arrays()
            .into_iter()
            .map(|(name, parts)| (name.to_string(), parts))
            .collect(),
        gpu_subgroup_sums: Some(kernels.subgroups()),
        gpu_vectors: Some(sim.vector_layout().name().to_string()),
        gpu_solved_whole: Some(sim.solved_whole()),
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
