//! A run on the CPU reference path.

use std::time::Instant;

use super::report::{Report, Tally, Timings, describe_network, peak_resident_bytes, smoother_of};
use super::{Observers, Steps, keep};
use wgcloth::cpu::{self, CpuSim, integrate};
use wgcloth::error::Result;
use wgcloth::health::{self, FailedStep};
use wgcloth::stage::{SelfContactStages, Stage};

/// Steps `sim` from where its state is to `steps.total`.
pub(super) fn run_cpu(mut sim: CpuSim, steps: Steps, obs: &mut Observers) -> Result<Report> {
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
    let mut tally = Tally::default();
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
        tally.push(&s, self_contact);
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
        record_ms_per_step: None,
        gpu_state_bytes: None,
        gpu_bytes_per_vertex: None,
        gpu_split_arrays: Vec::new(),
        gpu_subgroup_sums: None,
        gpu_vectors: None,
        gpu_solved_whole: None,
        peak_resident_bytes: peak_resident_bytes(),
        max_penetration: tally.max_penetration,
        finite: sim.is_finite(),
        last_good: divergence.is_some().then_some(last_good),
        divergence,
        device_fault: None,
        preconditioner: config.solver.preconditioner,
        smoother: smoother_of(&config),
        cg_iterations_mean: tally.cg_iters as f64 / done,
        cg_iterations_max: tally.residuals.most_iterations,
        cg_residual_max: tally.residuals.max,
        cg_residual_median: tally.residuals.median(),
        cg_steps_above_goal: tally.residuals.above_goal,
        cg_steps_resolved: 0,
        cg_breakdowns: tally.breakdowns,
        contacts_mean: tally.contacts as f64 / done,
        energy_final: sim.energy().total(),
        self_contact: (self_contact.separate)
            .then(|| tally.self_contact(done, sim.scene.cloth.vertex_count())),
    })
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
