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
    Scene::new(&patch_config(tilt, model)).unwrap()
}

fn patch_config(tilt: f32, model: ModelKind) -> Config {
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
    c
}

fn mean(v: &[Vec3]) -> Vec3 {
    v.iter().copied().sum::<Vec3>() / v.len() as f32
}

/// The patch's mean position and velocity after each step.
type Trace = Vec<(Vec3, Vec3)>;

fn on_cpu(scene: &Scene) -> Trace {
    let mut sim = CpuSim::new(scene.clone());
    (0..STEPS)
        .map(|_| {
            sim.step();
            (mean(&sim.state.x), mean(&sim.state.v))
        })
        .collect()
}

fn on_gpu(ctx: &wgcloth::gpu::GpuContext, kernels: &Kernels, scene: &Scene) -> Trace {
    let sim = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, scene).unwrap();
    (0..STEPS)
        .map(|_| {
            sim.step();
            (
                mean(&sim.read_positions().unwrap()),
                mean(&sim.read_velocities().unwrap()),
            )
        })
        .collect()
}

/// Each model's scene on the CPU, then (where there is an adapter) on the GPU.
fn each_run(scene: impl Fn(ModelKind) -> Scene, check: impl Fn(&str, ModelKind, Trace)) {
    for model in MODELS {
        check("CPU", model, on_cpu(&scene(model)));
    }
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let kernels = Kernels::new(&ctx.device).expect("kernels build");
    for model in MODELS {
        check("GPU", model, on_gpu(&ctx, &kernels, &scene(model)));
    }
}

#[test]
fn friction_holds_the_patch_below_the_friction_angle() {
    let tilt = 0.8 * 0.5f32.atan();
    let normal = Quat::from_rotation_z(tilt) * Vec3::Y;
    each_run(
        |m| patch_on_incline(tilt, m),
        |path, model, trace| {
            let moved = trace[STEPS - 1].0 - trace[STEPS / 2 - 1].0;
            let drift = (moved - moved.dot(normal) * normal).length();
            eprintln!(
                "{path} {model:?}: drift over the second second at {:.1}°: {drift:.2e} m",
                tilt.to_degrees()
            );
            assert!(
                drift < 3e-3,
                "{path} {model:?}: the patch slid {drift} m in 1 s below the friction angle"
            );
        },
    );
}

#[test]
fn friction_lets_the_patch_slide_at_coulombs_acceleration_above_the_friction_angle() {
    let mu = 0.5f32;
    let tilt = 1.3 * mu.atan();
    let downhill = -(Quat::from_rotation_z(tilt) * Vec3::X);
    let expected = G * (tilt.sin() - mu * tilt.cos());
    each_run(
        |m| patch_on_incline(tilt, m),
        |path, model, trace| {
            let seconds = (STEPS / 2) as f32 * Config::default().solver.dt;
            let measured = (trace[STEPS - 1].1 - trace[STEPS / 2 - 1].1).dot(downhill) / seconds;
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
        },
    );
}

#[test]
fn a_moving_plane_drags_the_patch_at_coulombs_acceleration_until_it_sticks() {
    let (mu, speed) = (0.5f32, 3.0f32);
    let dt = Config::default().solver.dt;
    let scene = |model| {
        let mut c = patch_config(0.0, model);
        c.rigid.motion.kind = MotionKind::Linear;
        c.rigid.motion.velocity = [speed, 0.0, 0.0];
        Scene::new(&c).unwrap()
    };
    each_run(scene, |path, model, trace| {
        let v: Vec<f32> = trace.iter().map(|(_, v)| v.x).collect();
        // Slip: from 20 % to 80 % of the plane's speed, friction is μ m g.
        let at = |f: f32| v.iter().position(|&u| u >= f * speed);
        let (Some(a), Some(b)) = (at(0.2), at(0.8)) else {
            panic!("{path} {model:?}: the patch never reached the plane's speed: {v:?}");
        };
        let measured = (v[b] - v[a]) / ((b - a) as f32 * dt);
        let last = v[STEPS - 1];
        eprintln!(
            "{path} {model:?}: slip acceleration {measured:.3} m/s² (μ g {:.3}), final speed {last:.4} m/s",
            mu * G
        );
        assert!(
            (measured - mu * G).abs() < 0.2 * mu * G,
            "{path} {model:?}: dragged at {measured} m/s², Coulomb {}",
            mu * G
        );
        assert!(
            (last - speed).abs() < 0.01 * speed,
            "{path} {model:?}: the patch ends at {last} m/s on a plane at {speed}"
        );
    });
}
