//! What keeps the cloth out of itself conserves momentum, on both paths:
//! a cloth folded in half, with no gravity, pins or body, whose layers are
//! driven into each other far faster than the forces can stop them.

mod common;

use glam::{DVec3, Vec3};
use wgcloth::config::{Pins, SceneKind};
use wgcloth::cpu::{CpuSim, State};
use wgcloth::gpu::GpuSim;
use wgcloth::intersections::intersecting_pairs;
use wgcloth::{Config, Scene};

/// A soft 16² cloth alone, weightless, free and undamped but for its
/// springs, kept from passing through itself, its solve run to 1e-7: what
/// the solve leaves of b is momentum lost, and b holds the contacts' h f,
/// about 8 times the momentum (at 1e-6 the residual alone came to 1.1e-5
/// of Σ m|v| with `self_contact.mass_ratio` at 1000).
fn weightless() -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.cloth.grid = [16, 16];
    c.cloth.pins = Pins::None;
    // Soft, as the folding scenes: the crease, at 3 mm where the rest
    // spacing is 67 mm, pushes little.
    c.cloth.stiffness = 50.0;
    c.cloth.damping_mass = 0.0;
    c.solver.gravity = [0.0; 3];
    (c.solver.cg_tol, c.solver.cg_iters) = (1e-7, 400);
    c.self_contact.enabled = true;
    Scene::new(&c).unwrap()
}

/// Its upper half folded down onto its lower, 3 mm in front of it (within
/// the forces' 5 mm), the layers closing at 1.2 m/s (12 mm a step, four
/// times the gap) while the whole cloth drifts sideways at 0.2 m/s.
fn folded(scene: &Scene) -> State {
    let mut state = State::initial(scene);
    let (nx, ny) = (scene.cloth.nx as usize, scene.cloth.ny as usize);
    let rest = &scene.cloth.rest_positions;
    for (i, (x, v)) in state.x.iter_mut().zip(&mut state.v).enumerate() {
        let (r, c) = (i / nx, i % nx);
        let upper = r >= ny / 2;
        if upper {
            *x = rest[(ny - 1 - r) * nx + c] + Vec3::new(0.0, 0.0, 0.003);
        }
        *v = Vec3::new(0.2, 0.0, if upper { -0.6 } else { 0.6 });
    }
    state
}

fn momentum(scene: &Scene, v: &[Vec3]) -> DVec3 {
    let m = scene.cloth.vertex_mass as f64;
    v.iter().map(|v| m * v.as_dvec3()).sum()
}

/// Σ m |v|: the scale the momentum's change is held to.
fn momentum_scale(scene: &Scene, v: &[Vec3]) -> f64 {
    let m = scene.cloth.vertex_mass as f64;
    v.iter().map(|v| m * v.as_dvec3().length()).sum()
}

const STEPS: usize = 15;

#[test]
fn a_folded_cloth_driven_into_itself_keeps_its_momentum_on_the_cpu() {
    let scene = weightless();
    let start = folded(&scene);
    let (p0, scale) = (momentum(&scene, &start.v), momentum_scale(&scene, &start.v));
    let mut sim = CpuSim::new(scene.clone());
    sim.state = start;
    let (mut changed, mut worst) = (0, 0.0f64);
    for step in 1..=STEPS {
        let stats = sim.step();
        changed += stats.separation.changed;
        let drift = (momentum(&scene, &sim.state.v) - p0).length() / scale;
        worst = worst.max(drift);
        let crossing = intersecting_pairs(&sim.state.x, &scene.cloth.triangles).len();
        assert_eq!(crossing, 0, "step {step}: the layers cross");
    }
    eprintln!(
        "CPU: {changed} vertex steps changed by the failsafe; momentum {worst:.2e} of Σ m|v| off"
    );
    assert!(changed > 0, "the failsafe acts");
    assert!(worst <= 1e-5, "momentum {worst:.2e} of Σ m|v| off");
}

#[test]
fn a_folded_cloth_driven_into_itself_keeps_its_momentum_on_the_gpu() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let scene = weightless();
    let start = folded(&scene);
    let (p0, scale) = (momentum(&scene, &start.v), momentum_scale(&scene, &start.v));
    let gpu = GpuSim::new(&ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&start);
    let mut worst = 0.0f64;
    for step in 1..=STEPS {
        gpu.step();
        let v = gpu.read_velocities().unwrap();
        let drift = (momentum(&scene, &v) - p0).length() / scale;
        worst = worst.max(drift);
        let x = gpu.read_positions().unwrap();
        let crossing = intersecting_pairs(&x, &scene.cloth.triangles).len();
        assert_eq!(crossing, 0, "step {step}: the layers cross");
    }
    let changed = gpu.read_state().unwrap().self_changed_total;
    eprintln!(
        "GPU: {changed} vertex steps changed by the failsafe; momentum {worst:.2e} of Σ m|v| off"
    );
    assert!(changed > 0, "the failsafe acts");
    assert!(worst <= 1e-5, "momentum {worst:.2e} of Σ m|v| off");
}

/// A state set without its loads (`State::loads` empty) carries none: it
/// steps as one whose loads are all 0, on both paths.
#[test]
fn a_state_without_loads_steps_as_one_that_carried_none() {
    let scene = weightless();
    let mut bare = folded(&scene);
    bare.loads.clear();
    let zeros = folded(&scene);
    let mut runs = [CpuSim::new(scene.clone()), CpuSim::new(scene.clone())];
    (runs[0].state, runs[1].state) = (bare.clone(), zeros.clone());
    for _ in 0..3 {
        runs.iter_mut().for_each(|s| _ = s.step());
    }
    assert!(runs[0].state.x == runs[1].state.x && runs[0].state.loads == runs[1].state.loads);
    assert!(
        runs[0].state.loads.iter().any(|&l| l > 0.0),
        "the contacts carry load"
    );
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let gpu = GpuSim::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let mut ends = Vec::new();
    for start in [&bare, &zeros] {
        gpu.upload_state(start);
        for _ in 0..3 {
            gpu.step();
        }
        ends.push((
            gpu.read_positions().unwrap(),
            gpu.read_loads(gpu.loads()).unwrap(),
        ));
    }
    assert!(
        ends[0] == ends[1],
        "the GPU from a bare state and from zero loads"
    );
}
