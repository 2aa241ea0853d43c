//! Coulomb's law on an incline, for the analytic friction model and the
//! shipped friction network, on the CPU and the GPU, at the default contact
//! and solver settings: a cloth patch holds below the friction angle and
//! slides at g (sin θ − μ cos θ) above it.

mod common;

use glam::{Quat, Vec3};
use wgcloth::config::{ModelKind, MotionKind, Pins, Rotation, SceneKind, Shape};
use wgcloth::cpu::CpuSim;
use wgcloth::gpu::{GpuSim, Kernels};
use wgcloth::{Config, Scene};

const MODELS: [ModelKind; 2] = [ModelKind::Friction, ModelKind::FrictionNet];
const G: f32 = 9.81;
/// The steps each run takes (2 s); the second half is measured, once the
/// patch has settled into the contact band.
const STEPS: usize = 200;

/// A free 0.2 m cloth patch lying on a static plane tilted by `tilt` about
/// z, its vertices just inside the contact band; every contact and solver
/// setting is the default (μ = 0.5).
fn patch_on_incline(tilt: f32, model: ModelKind) -> Scene {
    let mut c = Config {
        scene: SceneKind::Sphere,
        model,
        ..Default::default()
    };
    let r = &mut c.rigid;
    r.shape = Shape::Plane;
    r.plane_size = [20.0, 20.0];
    r.subdivisions = 1;
    r.position = [0.0; 3];
    r.rotation = Rotation {
        axis: [0.0, 0.0, 1.0],
        degrees: tilt.to_degrees(),
    };
    r.motion.kind = MotionKind::Static;
    // The cloth's plane (local x–y) laid flat, then tilted with the plane.
    let q = Quat::from_rotation_z(tilt) * Quat::from_rotation_x(-std::f32::consts::FRAC_PI_2);
    let (axis, angle) = q.to_axis_angle();
    let cl = &mut c.cloth;
    cl.rotation = Rotation {
        axis: axis.to_array(),
        degrees: angle.to_degrees(),
    };
    cl.center =
        (Quat::from_rotation_z(tilt) * Vec3::new(0.0, c.contact.thickness - 1e-4, 0.0)).to_array();
    (cl.grid, cl.size, cl.mass, cl.pins) = ([6, 6], [0.2, 0.2], 0.036, Pins::None);
    cl.damping_mass = 0.0; // no air drag: only Coulomb's law acts along the slope
    Scene::new(&c).unwrap()
}

fn mean(v: &[Vec3]) -> Vec3 {
    v.iter().copied().sum::<Vec3>() / v.len() as f32
}

/// The patch's mean position and velocity after STEPS / 2 and STEPS steps.
type Halves = [(Vec3, Vec3); 2];

fn on_cpu(scene: &Scene) -> Halves {
    let mut sim = CpuSim::new(scene.clone());
    [0, 1].map(|_| {
        for _ in 0..STEPS / 2 {
            sim.step();
        }
        (mean(&sim.state.x), mean(&sim.state.v))
    })
}

fn on_gpu(ctx: &wgcloth::gpu::GpuContext, kernels: &Kernels, scene: &Scene) -> Halves {
    let sim = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, scene).unwrap();
    [0, 1].map(|_| {
        for _ in 0..STEPS / 2 {
            sim.step();
        }
        (
            mean(&sim.read_positions().unwrap()),
            mean(&sim.read_velocities().unwrap()),
        )
    })
}

/// Each model on the CPU, then (where there is an adapter) on the GPU.
fn each_run(tilt: f32, check: impl Fn(&str, ModelKind, Halves)) {
    for model in MODELS {
        check("CPU", model, on_cpu(&patch_on_incline(tilt, model)));
    }
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let kernels = Kernels::new(&ctx.device).expect("kernels build");
    for model in MODELS {
        check(
            "GPU",
            model,
            on_gpu(&ctx, &kernels, &patch_on_incline(tilt, model)),
        );
    }
}

#[test]
fn friction_holds_the_patch_below_the_friction_angle() {
    let tilt = 0.8 * 0.5f32.atan();
    let normal = Quat::from_rotation_z(tilt) * Vec3::Y;
    each_run(tilt, |path, model, [(x1, _), (x2, _)]| {
        let moved = x2 - x1;
        let drift = (moved - moved.dot(normal) * normal).length();
        eprintln!(
            "{path} {model:?}: drift over the second second at {:.1}°: {drift:.2e} m",
            tilt.to_degrees()
        );
        assert!(
            drift < 3e-3,
            "{path} {model:?}: the patch slid {drift} m in 1 s below the friction angle"
        );
    });
}

#[test]
fn friction_lets_the_patch_slide_at_coulombs_acceleration_above_the_friction_angle() {
    let mu = 0.5f32;
    let tilt = 1.3 * mu.atan();
    let downhill = -(Quat::from_rotation_z(tilt) * Vec3::X);
    let expected = G * (tilt.sin() - mu * tilt.cos());
    each_run(tilt, |path, model, [(_, v1), (_, v2)]| {
        let seconds = (STEPS / 2) as f32 * Config::default().solver.dt;
        let measured = (v2 - v1).dot(downhill) / seconds;
        eprintln!(
            "{path} {model:?}: acceleration at {:.1}°: {measured:.4} m/s², Coulomb {expected:.4}",
            tilt.to_degrees()
        );
        // The lagged friction linearisation over-brakes by about h·a/|v|
        // (2–3 % here); the issue asked for 20 %.
        assert!(
            (measured - expected).abs() < 0.05 * expected,
            "{path} {model:?}: {measured} m/s² vs {expected}"
        );
    });
}
