//! The report's per-step solve residuals, on the CPU and the GPU
//! (lavapipe in CI): a solve run to a tight tolerance leaves no step above
//! the 1e-3 goal, and one cut to two iterations leaves steps above it.

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::{Config, Scene};
use wgcloth_cli::run::{self, Chosen, RESIDUAL_GOAL, Steps};

fn hanging(cg_iters: u32, cg_tol: f32) -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        model: ModelKind::Friction,
        ..Default::default()
    };
    c.cloth.grid = [8, 8];
    c.solver.cg_iters = cg_iters;
    c.solver.cg_tol = cg_tol;
    Scene::new(&c).unwrap()
}

#[test]
fn converged_steps_report_none_above_the_goal_and_cut_ones_do() {
    let mut backends = vec![Chosen::Cpu];
    backends.extend(common::gpu_context().map(Chosen::gpu));
    for chosen in &backends {
        let converged = run::run(
            chosen,
            hanging(300, 1e-5),
            Steps::all(20),
            Default::default(),
        )
        .expect("runs");
        assert_eq!(converged.cg_steps_above_goal, 0, "{}", converged.summary());
        assert!(
            converged.cg_residual_median <= 1e-5,
            "{}",
            converged.summary()
        );
        assert!(converged.cg_residual_max <= 1e-5, "{}", converged.summary());

        let cut =
            run::run(chosen, hanging(2, 0.0), Steps::all(20), Default::default()).expect("runs");
        assert!(cut.cg_steps_above_goal > 0, "{}", cut.summary());
        assert!(cut.cg_steps_above_goal <= 20);
        assert!(cut.cg_residual_median > RESIDUAL_GOAL, "{}", cut.summary());
        assert!(cut.cg_residual_max >= cut.cg_residual_median);
    }
}
