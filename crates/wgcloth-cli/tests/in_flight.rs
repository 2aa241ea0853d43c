//! The GPU run loop keeps up to `in_flight::DEPTH` steps in flight, reads
//! each step's statistics asynchronously and records only as many PCG
//! iterations as recent steps needed: it must still count every step once,
//! in order, and end where a plain loop that waits for every step ends.
//! Lavapipe in CI; without an adapter these tests fail under CI=true and
//! skip elsewhere.

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use wgcloth::config::SceneKind;
use wgcloth::cpu;
use wgcloth::gpu::GpuSim;
use wgcloth::{Config, Scene};
use wgcloth_cli::in_flight::DEPTH;
use wgcloth_cli::run::{self, Chosen, Steps};

#[test]
fn steps_in_flight_count_every_step_and_end_where_a_plain_loop_does() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.cloth.grid = [16, 16];
    let scene = Scene::new(&c).unwrap();
    // Not a multiple of the ring's depth, so the last steps drain it part full.
    let steps = 10 * DEPTH as u64 + 1;
    let chosen = Chosen::gpu(ctx);
    let report = run::run(
        &chosen,
        scene.clone(),
        Steps::all(steps),
        Default::default(),
    )
    .expect("runs");
    assert_eq!(report.steps, steps, "{}", report.summary());
    assert_eq!(report.cg_steps_above_goal, 0, "{}", report.summary());
    assert_eq!(report.cg_steps_cut, 0, "{}", report.summary());

    // The same steps, each waited for and read before the next.
    let ctx = chosen.context().expect("a GPU");
    let sim = GpuSim::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let (mut iterations, mut most) = (0u64, 0u32);
    for _ in 0..steps {
        sim.step();
        let state = sim.read_state().unwrap();
        iterations += state.last_iterations as u64;
        most = most.max(state.last_iterations);
    }
    let (x, v) = (
        sim.read_positions().unwrap(),
        sim.read_velocities().unwrap(),
    );
    assert_eq!(report.cg_iterations_max, most, "{}", report.summary());
    assert_eq!(
        report.cg_iterations_mean,
        iterations as f64 / steps as f64,
        "{}",
        report.summary()
    );
    // Recording fewer iterations than the cap changes nothing a
    // converged solve computes: the same state, bit for bit.
    assert_eq!(
        report.energy_final,
        cpu::energy(&scene, &x, &v).total(),
        "{}",
        report.summary()
    );
}
