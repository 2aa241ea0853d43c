//! A batch of worlds on the CPU (`cpu::worlds`, issue 67): each world ends
//! bit for bit where its scene ends run alone, and no world reads another's
//! state.

use wgcloth::config::ModelKind;
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::cpu::{CpuSim, PERTURBATION};
use wgcloth::{Config, Scene};

const STEPS: usize = 30;

/// The thesis scene at 16² with world `k`'s friction and sphere path:
/// worlds that would end differently if they were mixed up.
fn world(k: usize) -> Scene {
    let mut c = Config {
        model: ModelKind::Friction,
        ..Default::default()
    };
    c.cloth.grid = [16, 16];
    c.contact.mu = 0.2 + 0.2 * k as f32;
    c.contact.kt = 50.0 + 100.0 * k as f32;
    c.rigid.motion.amplitude = 0.2 + 0.04 * k as f32;
    Scene::new(&c).unwrap()
}

fn batch(worlds: usize) -> CpuWorlds {
    CpuWorlds::new((0..worlds).map(world).collect())
}

#[test]
fn each_world_of_a_batch_ends_bit_for_bit_where_it_ends_alone() {
    let mut together = batch(4);
    for _ in 0..STEPS {
        together.step();
    }
    for (k, w) in together.worlds().iter().enumerate() {
        let mut alone = CpuSim::new(world(k));
        for _ in 0..STEPS {
            alone.step();
        }
        assert!(w.state.x == alone.state.x, "world {k}: positions");
        assert!(w.state.v == alone.state.v, "world {k}: velocities");
        assert_eq!(w.state.step, STEPS as u64);
    }
    let (a, b) = (&together.worlds()[0].state.x, &together.worlds()[1].state.x);
    assert!(a != b, "the worlds' parameters reach them");
}

#[test]
fn a_world_disturbed_or_left_out_changes_no_other() {
    let (mut calm, mut shaken) = (batch(4), batch(4));
    shaken.worlds_mut()[1].state.nudge(1e3 * PERTURBATION);
    for step in 0..STEPS {
        calm.step();
        // World 2 sits out the second half.
        let stats = shaken.step_where(|k| k != 2 || step < STEPS / 2);
        assert_eq!(stats[2].is_some(), step < STEPS / 2);
    }
    let (calm, shaken) = (calm.worlds(), shaken.worlds());
    for k in [0, 3] {
        assert!(calm[k].state.x == shaken[k].state.x, "world {k} moved");
        assert!(calm[k].state.v == shaken[k].state.v, "world {k} moved");
    }
    assert!(calm[1].state.x != shaken[1].state.x, "the disturbed world");
    assert_eq!(shaken[2].state.step, (STEPS / 2) as u64);
}
