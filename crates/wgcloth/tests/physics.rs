//! Physical outcomes of whole runs on the CPU reference path.

mod common;

use glam::{Quat, Vec3};
use wgcloth::config::{ModelKind, MotionKind, Pins, Rotation, SceneKind, Shape};
use wgcloth::cpu::CpuSim;
use wgcloth::{Config, Scene};

fn hang_config(grid: u32) -> Config {
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    c
}

#[test]
fn hanging_cloth_comes_to_rest_with_exact_pins_and_never_gains_energy() {
    let mut sim = CpuSim::new(Scene::new(&hang_config(12)).unwrap());
    let cloth = sim.scene.cloth.clone();
    let pinned: Vec<usize> = (0..cloth.vertex_count())
        .filter(|&i| cloth.pinned[i])
        .collect();
    assert_eq!(pinned, vec![0, 11]);
    let mut energy = sim.energy().total();
    let mut worst_gain = 0.0f64;
    for _ in 0..800 {
        sim.step();
        for &i in &pinned {
            assert_eq!(
                sim.state.x[i], cloth.rest_positions[i],
                "pinned vertex {i} moved"
            );
        }
        let e = sim.energy().total();
        worst_gain = worst_gain.max(e - energy);
        energy = e;
    }
    let ke = sim.energy().kinetic;
    eprintln!("worst step energy gain {worst_gain:.3e} J, final kinetic {ke:.3e} J");
    // Backward Euler only dissipates: no step may create energy beyond f32 noise.
    assert!(worst_gain < 1e-6, "a step gained {worst_gain:.3e} J");
    assert!(
        ke < 1e-7,
        "still moving after 8 s: kinetic energy {ke:.3e} J"
    );
}

#[test]
fn thesis_scene_keeps_cloth_out_of_the_sphere_for_a_full_period() {
    for model in [ModelKind::Friction, ModelKind::Naive] {
        let mut c = Config {
            model,
            ..Default::default()
        };
        c.cloth.grid = [32, 32];
        let period = c.rigid.motion.period;
        let steps = (period / c.solver.dt).round() as u64;
        let mut sim = CpuSim::new(Scene::new(&c).unwrap());
        let (mut deepest, mut contacts) = (0.0f32, 0usize);
        for k in 0..steps {
            let s = sim.step();
            assert!(sim.is_finite(), "{model:?}: state not finite at step {k}");
            deepest = deepest.max(s.max_penetration);
            contacts += s.contacts;
        }
        eprintln!("{model:?}: deepest {deepest:.4} m, {contacts} contacts over {steps} steps");
        assert!(
            contacts > 1000,
            "{model:?}: the sphere must actually hit the cloth"
        );
        assert!(
            deepest < 0.01,
            "{model:?}: a vertex went {deepest} m inside the sphere"
        );
    }
}

/// A 0.2 m cloth patch lying on a plane tilted by `tilt` about z, with
/// Coulomb coefficient μ = 0.5; returns the simulator.
fn patch_on_incline(tilt: f32) -> CpuSim {
    let mut c = Config {
        scene: SceneKind::Sphere,
        model: ModelKind::Friction,
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
    let k = &mut c.contact;
    (k.force_scale, k.kn, k.kd, k.kt, k.mu) = (1.0, 1000.0, 2.0, 1000.0, 0.5);
    // The cloth's plane (local x–y) laid flat, then tilted with the plane,
    // its vertices just inside the contact band.
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
    c.solver.cg_iters = 200;
    CpuSim::new(Scene::new(&c).unwrap())
}

fn mean(v: &[Vec3]) -> Vec3 {
    v.iter().copied().sum::<Vec3>() / v.len() as f32
}

#[test]
fn coulomb_friction_holds_below_the_friction_angle() {
    let tilt = 0.8 * 0.5f32.atan();
    let mut sim = patch_on_incline(tilt);
    let normal = Quat::from_rotation_z(tilt) * Vec3::Y;
    let start = mean(&sim.state.x);
    for _ in 0..200 {
        sim.step();
    }
    let moved = mean(&sim.state.x) - start;
    let drift = (moved - moved.dot(normal) * normal).length();
    eprintln!("drift over 2 s at {:.1}°: {drift:.2e} m", tilt.to_degrees());
    assert!(
        drift < 1e-3,
        "the patch slid {drift} m below the friction angle"
    );
}

#[test]
fn coulomb_friction_lets_the_patch_slide_above_the_friction_angle() {
    let (mu, g) = (0.5f32, 9.81f32);
    let tilt = 1.3 * mu.atan();
    let mut sim = patch_on_incline(tilt);
    let downhill = -(Quat::from_rotation_z(tilt) * Vec3::X);
    let mut speed = Vec::new();
    for _ in 0..200 {
        sim.step();
        speed.push(mean(&sim.state.v).dot(downhill));
    }
    // Acceleration over the second second, once sliding is established. The
    // lagged friction linearisation over-brakes by about h·a/|v| (≈ 1–2 %).
    let measured = (speed[199] - speed[99]) / 1.0;
    let expected = g * (tilt.sin() - mu * tilt.cos());
    eprintln!(
        "acceleration at {:.1}°: {measured:.4} m/s², expected {expected:.4}",
        tilt.to_degrees()
    );
    assert!(
        (measured - expected).abs() < 0.03 * expected,
        "{measured} vs {expected}"
    );
}

#[test]
fn a_sphere_crossing_the_cloth_at_10_m_per_s_leaves_no_vertex_inside() {
    let (c, steps) = common::crossing_config(10.0, 24);
    let scene = Scene::new(&c).unwrap();
    let body = scene.rigid.clone().unwrap();
    let mut sim = CpuSim::new(scene);
    let (mut deepest_solved, mut carried) = (0.0f32, 0.0f32);
    for k in 0..steps {
        let s = sim.step();
        assert!(sim.is_finite(), "state not finite at step {k}");
        deepest_solved = deepest_solved.max(s.max_penetration);
        let inside = common::deepest_inside(&body, sim.state.time, &sim.state.x);
        assert!(inside < 1e-5, "step {k}: a vertex ends {inside} m inside");
        carried = carried.max(sim.state.x.iter().map(|x| x.z).fold(f32::MIN, f32::max));
    }
    eprintln!(
        "{steps} steps: deepest after the solve {deepest_solved:.4} m; cloth carried to z = {carried:.3} m"
    );
    // The sphere met the cloth: the solve alone left vertices deeper than
    // the contact band, and the cloth went with the body, not through it.
    assert!(deepest_solved > c.contact.max_depth);
    assert!(carried > 0.3, "the cloth stayed behind: the body tunnelled");
}
