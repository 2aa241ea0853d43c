//! Coulomb's law on an incline, for the analytic friction model, the
//! default friction network and the thesis-size one in the same output
//! form, on the CPU and the GPU, at the default contact and solver
//! settings: a cloth patch holds below the friction angle and slides at
//! g (sin θ − μ cos θ) above it.

mod common;

use glam::{Quat, Vec3};
use wgcloth::config::{ModelKind, MotionKind, Pins, Rotation, SceneKind, Shape};
use wgcloth::cpu::CpuSim;
use wgcloth::cpu::contact::{Coefficients, friction, response};
use wgcloth::gpu::{GpuSim, Kernels, SolvedSteps};
use wgcloth::{Config, Scene};

/// A friction model as these tests run it: a kind, and for a network the
/// weights file (crate-relative) when not the default one.
#[derive(Clone, Copy)]
struct Model {
    kind: ModelKind,
    weights: Option<&'static str>,
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        match self.weights {
            None => write!(f, "{}", self.kind.name()),
            Some(w) => write!(f, "{} ({w})", self.kind.name()),
        }
    }
}

const MODELS: [Model; 3] = [
    Model {
        kind: ModelKind::Friction,
        weights: None,
    },
    Model {
        kind: ModelKind::FrictionNet,
        weights: None,
    },
    // The thesis's hidden layers (256, 256, 128 ×5) in the contact frame's
    // output form (crates/wgcloth/weights/README.md).
    Model {
        kind: ModelKind::FrictionNet,
        weights: Some("weights/friction_mlp_thesis_cone.safetensors"),
    },
];
const G: f32 = 9.81;
/// The steps each run takes (2 s); the second half is measured, once the
/// patch has settled into the contact band.
const STEPS: usize = 200;

/// A free 0.2 m cloth patch lying on a static plane tilted by `tilt` about
/// z, its vertices just inside the contact band; every contact and solver
/// setting is the default (μ = 0.5).
fn patch_on_incline(tilt: f32, model: Model) -> Scene {
    Scene::new(&patch_config(tilt, model)).unwrap()
}

fn patch_config(tilt: f32, model: Model) -> Config {
    let mut c = Config {
        scene: SceneKind::Sphere,
        model: model.kind,
        ..Default::default()
    };
    c.contact.weights = model
        .weights
        .map(|w| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(w));
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
    let mut solved = SolvedSteps::for_scene(&sim, scene);
    (0..STEPS)
        .map(|_| {
            solved.step(&sim).unwrap();
            (
                mean(&sim.read_positions().unwrap()),
                mean(&sim.read_velocities().unwrap()),
            )
        })
        .collect()
}

/// Each model's scene on the CPU, then (where there is an adapter) on the GPU.
fn each_run(scene: impl Fn(Model) -> Scene, check: impl Fn(&str, Model, Trace)) {
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

/// The cloth on itself (issue 23): a flap of a limp cloth laid on the rest
/// of it, which is pinned flat (a cloth table), just inside the
/// self-contact band, under gravity tilted by `tilt` along the table's
/// rows. Rows 0–3 are the flap, face down over rows 8–11; rows 4–7 are
/// pinned in a column 1 m above the flap's top row, so the cloth that
/// joins the flap to the rest hangs clear of the table (folded straight
/// back, that strip lay across the table's edges at a slant and pushed the
/// flap uphill), every spring at rest where the scene starts. The
/// cloth–cloth contacts carry eqs. 8–9 with the `[contact]` coefficients
/// (μ = 0.5).
fn flap_on_cloth(tilt: f32) -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        model: ModelKind::Friction,
        ..Default::default()
    };
    let cl = &mut c.cloth;
    (cl.grid, cl.size, cl.mass, cl.pins) = ([12, 24], [0.33, 0.9], 0.3, Pins::None);
    // Limp, so the column's springs barely pull on the flap.
    (cl.stiffness, cl.damping_mass) = (1e-3, 0.0);
    cl.rotation = Rotation {
        axis: [1.0, 0.0, 0.0],
        degrees: -90.0,
    };
    c.self_contact.enabled = true;
    let (nx, flap) = (12, 4);
    let rest = Scene::new(&c).unwrap().cloth.rest_positions;
    // Down the table's rows.
    let away = (rest[nx] - rest[0]).normalize();
    c.solver.gravity = (G * tilt.sin() * away - G * tilt.cos() * Vec3::Y).to_array();
    let mut scene = Scene::new(&c).unwrap();
    // Over the inside of the table's triangles, not its vertices.
    let shift = 0.3 * (rest[1] - rest[0]) + 0.4 * (rest[nx] - rest[0]);
    let up = Vec3::Y * (c.self_contact.thickness - 1e-5);
    let cloth = &mut scene.cloth;
    for (i, x) in cloth.rest_positions.iter_mut().enumerate() {
        let (r, col) = (i / nx, i % nx);
        if r < flap {
            *x = rest[(3 * flap - 1 - r) * nx + col] + shift + up;
        }
    }
    for i in flap * nx..2 * flap * nx {
        let (r, col) = (i / nx, i % nx);
        let above = Vec3::Y * (1.0 + 0.05 * (r - flap) as f32);
        cloth.rest_positions[i] = cloth.rest_positions[(flap - 1) * nx + col] + above;
    }
    let x = &cloth.rest_positions;
    for (l, &[i, j]) in cloth.rest_lengths.iter_mut().zip(&cloth.springs) {
        *l = x[i as usize].distance(x[j as usize]);
    }
    for (i, pinned) in cloth.pinned.iter_mut().enumerate() {
        *pinned = i / nx >= flap;
    }
    scene
}

/// One linearised step of sliding friction (`contact::response`) on a
/// point of mass m, friction alone acting along the slide:
/// m (s' − s) = h (f·t̂ + t̂ᵀ D_c t̂ (s' − s)). A slide whose momentum m s
/// exceeds the friction's impulse μ F_c h loses exactly that impulse;
/// a slower one comes to rest at the step's end, not past it.
#[test]
fn one_linearised_step_of_friction_takes_coulombs_impulse_off_a_slide_and_never_reverses_it() {
    let k = Coefficients {
        kn: 1000.0,
        kd: 0.0,
        kt: 100.0,
        mu: 0.5,
    };
    let (n, depth, h, m) = (Vec3::Y, 2e-3, 0.01, 0.1);
    let t_hat = Vec3::X;
    let impulse = k.mu * k.kn * depth * h; // 0.01 N s: stops 0.1 m/s
    for s in [0.02, 0.05, 0.09, 0.11, 0.2, 1.0] {
        let v_rel = s * t_hat;
        let r = response(&friction(-depth * n, v_rel, &k), n, v_rel, m / h);
        let s_end = s + h * r.force.dot(t_hat) / (m - h * t_hat.dot(r.damping * t_hat));
        let coulomb = (s - impulse / m).max(0.0);
        assert!(
            (s_end - coulomb).abs() < 1e-5,
            "at {s} m/s the step ends at {s_end} m/s; Coulomb's law: {coulomb}"
        );
    }
}

/// The flap's mean position and velocity after each of `steps` steps,
/// and the normal force its contacts carried in each step's solve (the
/// sum of its vertices' `State::loads`), on the CPU and (where there is an
/// adapter) the GPU.
fn flap_runs(scene: &Scene, steps: usize) -> Vec<(&'static str, Trace, Vec<f32>)> {
    let flap = 4 * scene.cloth.nx as usize;
    let carried = |loads: &[f32]| loads[..flap].iter().sum::<f32>();
    let mut cpu = CpuSim::new(scene.clone());
    let (mut trace, mut loads) = (Trace::new(), Vec::new());
    for _ in 0..steps {
        cpu.step();
        trace.push((mean(&cpu.state.x[..flap]), mean(&cpu.state.v[..flap])));
        loads.push(carried(&cpu.state.loads));
    }
    let mut runs = vec![("CPU", trace, loads)];
    if let Some(ctx) = common::gpu_context() {
        let gpu = GpuSim::new(&ctx.device, &ctx.queue, scene).unwrap();
        let mut solved = SolvedSteps::for_scene(&gpu, scene);
        let (mut trace, mut loads) = (Trace::new(), Vec::new());
        for _ in 0..steps {
            solved.step(&gpu).unwrap();
            let (x, v) = (
                gpu.read_positions().unwrap(),
                gpu.read_velocities().unwrap(),
            );
            trace.push((mean(&x[..flap]), mean(&v[..flap])));
            loads.push(carried(&gpu.read_loads(gpu.loads()).unwrap()));
        }
        runs.push(("GPU", trace, loads));
    }
    runs
}

#[test]
fn a_flap_of_cloth_holds_on_the_cloth_below_the_friction_angle_and_slides_at_coulombs_rate_above() {
    let mu = 0.5f32;
    let dt = Config::default().solver.dt;
    for (tilt, slides) in [(0.8 * mu.atan(), false), (1.3 * mu.atan(), true)] {
        let scene = flap_on_cloth(tilt);
        let table = scene.cloth.rest_positions.last().unwrap().y;
        let g = Vec3::from_array(scene.config.solver.gravity);
        let downhill = (g - g.dot(Vec3::Y) * Vec3::Y).normalize_or_zero();
        let expected = G * (tilt.sin() - mu * tilt.cos());
        // Below the angle 1 s is watched, from 0.3 s in; above it 0.3 s.
        let steps = if slides { 60 } else { 130 };
        // The flap's weight against the table.
        let weight = 4.0 * scene.cloth.nx as f32 * scene.cloth.vertex_mass * G * tilt.cos();
        for (path, trace, loads) in flap_runs(&scene, steps) {
            let (from, to) = (trace[29], trace[steps - 1]);
            // The solve's normal force holds the flap up, step by step
            // (stage "load"; the friction's bound is taken of it).
            let carried = loads[29..].iter().sum::<f32>() / (steps - 29) as f32;
            assert!(
                (carried / weight - 1.0).abs() < 0.01,
                "{path}: the contacts carried {carried} N of the flap's {weight} N"
            );
            let measured = (to.1 - from.1).dot(downhill) / ((steps - 30) as f32 * dt);
            let drift = (to.0 - from.0).dot(downhill);
            eprintln!(
                "{path} at {:.1}°: flap drift {drift:.2e} m and acceleration {measured:.3} m/s² \
                 over {:.1} s (Coulomb {:.3}), {:.2e} m above the table",
                tilt.to_degrees(),
                (steps - 30) as f32 * dt,
                expected.max(0.0),
                to.0.y - table
            );
            assert!(
                to.0.is_finite() && to.0.y > table,
                "{path}: the flap fell through"
            );
            match slides {
                false => assert!(
                    drift.abs() < 1e-3,
                    "{path}: slid {drift} m in 1 s below the angle"
                ),
                // It slides at Coulomb's rate, never faster: the friction's
                // bound is μ times the normal force of the last solve,
                // however the flap's contacts begin and end (DESIGN "The
                // cloth against itself").
                true => assert!(
                    measured > 0.95 * expected && measured < 1.02 * expected,
                    "{path}: {measured} m/s² vs Coulomb {expected}"
                ),
            }
        }
    }
}
