//! `wgcloth validate`: whole GPU runs against the CPU on lavapipe (or any
//! adapter). Without an adapter these tests fail unless
//! WGCLOTH_NO_GPU_TESTS=1 opts out.

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use common::sphere;
use wgcloth::config::ModelKind;

/// The network models over 100 steps of the thesis scene pass `wgcloth
/// validate`: the GPU stays within the scene's own sensitivity of the CPU
/// (a network's kinks amplify rounding as contact does).
#[test]
fn thesis_scene_with_either_network_validates_against_the_cpu() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    for model in [ModelKind::FrictionNet, ModelKind::NaiveNet] {
        let v =
            wgcloth_cli::run::validate(&ctx, sphere(16, model), 100, |_, _, _| {}, || {}).unwrap();
        let spread = v.sensitivity.faithful(&ctx.adapter);
        eprintln!(
            "{model:?}: deviation {:.3e} m, faithful runs {:.3e} m, contacts {} vs {}",
            v.max_deviation, spread.drift, v.gpu_contacts, v.cpu_contacts
        );
        assert!(v.cpu_contacts > 500, "the sphere must hit the cloth");
        assert!(
            v.max_deviation <= 1e-4 + 4.0 * spread.drift,
            "{model:?}: {} m apart, faithful runs {} m",
            v.max_deviation,
            spread.drift
        );
        let ratio = v.gpu_contacts as f64 / v.cpu_contacts as f64;
        assert!((ratio - 1.0).abs() < 0.05, "{model:?}: contacts {ratio}");
    }
}
