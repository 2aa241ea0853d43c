//! The GPU run loop keeps up to `in_flight::DEPTH` steps in flight, reads
//! each step's statistics asynchronously and records only as many PCG
//! iterations as recent steps needed: it must still count every step once,
//! in order, and end where a plain loop that waits for every step ends,
//! also when it solves again a step that its budget cut.
//! Lavapipe in CI; without an adapter these tests fail unless
//! WGCLOTH_NO_GPU_TESTS=1 opts out.

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use wgcloth::config::SceneKind;
use wgcloth::cpu;
use wgcloth::gpu::GpuSim;
use wgcloth::{Config, Scene};
use wgcloth_cli::in_flight::{DEPTH, InFlight};
use wgcloth_cli::run::{self, Chosen, Steps};

/// The hanging cloth at 16², the default solve.
fn hanging() -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.cloth.grid = [16, 16];
    // The solve as a chain of dispatches, whose iterations a budget cuts.
    c.solver.whole_solve_nodes = 0;
    Scene::new(&c).unwrap()
}

#[test]
fn steps_in_flight_count_every_step_and_end_where_a_plain_loop_does() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let scene = hanging();
    // Not a multiple of the ring's depth, so the last steps drain it part full.
    let steps = 10 * DEPTH as u64 + 1;

    // The same steps, each waited for and read before the next.
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
    drop(sim);

    let chosen = Chosen::gpu(ctx);
    // The second run's first step records 2 iterations, too few: the run
    // loop must solve it again, after the steps behind it were recorded.
    for first_budget in [None, Some(2)] {
        let run_steps = Steps {
            first_budget,
            ..Steps::all(steps)
        };
        let report = run::run(&chosen, scene.clone(), run_steps, Default::default()).expect("runs");
        let summary = report.summary();
        assert_eq!(report.steps, steps, "{summary}");
        assert_eq!(report.cg_steps_above_goal, 0, "{summary}");
        // The default budget follows these steps, never short of them.
        match first_budget {
            Some(_) => assert!(report.cg_steps_resolved >= 1, "{summary}"),
            None => assert_eq!(report.cg_steps_resolved, 0, "{summary}"),
        }
        assert_eq!(report.cg_iterations_max, most, "{summary}");
        assert_eq!(
            report.cg_iterations_mean,
            iterations as f64 / steps as f64,
            "{summary}"
        );
        // Recording fewer iterations than the cap, or a step twice,
        // changes nothing a converged solve computes: the same state, bit
        // for bit.
        assert_eq!(
            report.energy_final,
            cpu::energy(&scene, &x, &v).total(),
            "{summary}"
        );
    }
}

/// The run loop's rewind: a step its budget cut short of the tolerance is
/// solved again from its kept start (`InFlight::rewind`), the steps
/// recorded after it dropped. The run then ends where a plain loop ends,
/// the state and every run statistic (clock, steps, iterations, worst
/// residual) bit for bit, as if the cut step had never been recorded.
#[test]
fn a_cut_step_solved_again_ends_where_a_plain_loop_does() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let scene = hanging();
    let (steps, cut) = (3 * DEPTH as u64, 2);

    let sim = GpuSim::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let cap = sim.cg_budget();
    let mut flight = InFlight::new(&ctx.device, &sim);
    let (mut step, mut rewound) = (0, false);
    while step < steps {
        let again = step == cut && rewound;
        sim.set_cg_budget(if step == cut && !again { 2 } else { cap });
        let done = flight.submit(&ctx, &sim, step).unwrap();
        step += 1;
        if let Some(f) = done.filter(|f| f.step == cut && !rewound) {
            assert_eq!(f.budget, 2);
            assert_eq!(f.state.last_iterations, 2, "{:?}", f.state);
            assert!(
                f.state.last_residual > scene.config.solver.cg_tol,
                "{:?}",
                f.state
            );
            flight.rewind(&ctx, &sim, &f).unwrap();
            (step, rewound) = (cut, true);
        }
    }
    while flight.next(&ctx, &sim, true).unwrap().is_some() {}
    assert!(
        rewound,
        "the cut step was read while later ones were in flight"
    );

    let plain = GpuSim::new(&ctx.device, &ctx.queue, &scene).unwrap();
    for _ in 0..steps {
        plain.step();
    }
    let state = sim.read_state().unwrap();
    assert_eq!(state.steps as u64, steps, "{state:?}");
    assert!(
        state.cg_residual_max <= scene.config.solver.cg_tol,
        "{state:?}"
    );
    assert_eq!(
        bytemuck::bytes_of(&state),
        bytemuck::bytes_of(&plain.read_state().unwrap()),
        "{state:?}"
    );
    assert_eq!(
        sim.read_positions().unwrap(),
        plain.read_positions().unwrap()
    );
    assert_eq!(
        sim.read_velocities().unwrap(),
        plain.read_velocities().unwrap()
    );
}
