//! Physical outcomes of whole runs on the CPU reference path.

mod common;

use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::CpuSim;
use wgcloth::cpu::springs::max_strain;
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
        eprintln!("{model:?}: deepest {deepest:e} m, {contacts} contacts over {steps} steps");
        assert!(
            contacts > 1000,
            "{model:?}: the sphere must actually hit the cloth"
        );
        // Before any push-out: the contact forces alone keep every vertex
        // out of the sphere, which moves up to 8 mm a step.
        assert_eq!(
            deepest, 0.0,
            "{model:?}: the solve left a vertex {deepest} m inside the sphere"
        );
    }
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

/// A body that sweeps past the cloth by more than half its spacing in one
/// step flings the vertices it meets: a step is one linear solve,
/// linearised where it starts. The substeps a scene takes by default
/// (`Scene::substeps`) keep the cloth whole and out of the body.
#[test]
fn substeps_keep_a_fast_body_from_flinging_the_cloth() {
    let run = |substeps: u32| {
        let mut c = Config {
            model: ModelKind::Naive,
            ..Default::default()
        };
        c.cloth.grid = [32, 32];
        // Eight times the thesis sphere's speed: 63 mm a step at most,
        // against a spacing of 32 mm.
        c.rigid.motion.period /= 8.0;
        c.solver.substeps = substeps;
        let scene = Scene::new(&c).unwrap();
        let n = scene.substeps;
        let mut sim = CpuSim::new(scene);
        let (mut strain, mut deepest) = (0.0f32, 0.0f32);
        for _ in 0..12 {
            let s = sim.step();
            assert!(sim.is_finite());
            strain = strain.max(max_strain(&sim.scene.cloth, &sim.state.x));
            deepest = deepest.max(s.max_penetration);
        }
        (n, strain, deepest)
    };
    let (n, strain, deepest) = run(0);
    let (_, strain_one, deepest_one) = run(1);
    eprintln!(
        "{n} substeps: strain {strain:.3}, deepest {deepest:.4} m; one: strain {strain_one:.3}, deepest {deepest_one:.4} m"
    );
    assert_eq!(n, 4, "63 mm at most half of 32 mm a substep");
    assert!(strain < 0.15, "a spring strained {strain}");
    assert!(deepest < 2e-3, "a vertex went {deepest} m inside");
    // What the substeps cure: without them the same run flings vertices.
    assert!(strain_one > 1.0 && deepest_one > 0.01);
}
