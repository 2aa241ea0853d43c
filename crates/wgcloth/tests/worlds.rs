//! A batch of worlds on the CPU (`cpu::worlds`) and on the GPU
//! (`gpu::worlds`, issue 67): each world ends bit for bit where its scene
//! ends run alone, and no world reads another's state.

mod common;

use wgcloth::config::ModelKind;
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::cpu::{CpuSim, PERTURBATION, State};
use wgcloth::gpu::{GpuSim, Kernels};
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

/// A GPU batch of `worlds` worlds, each at rest, and its kernels' device.
fn gpu_batch(ctx: &wgcloth::gpu::GpuContext, kernels: &Kernels, worlds: usize) -> GpuSim {
    let scenes: Vec<Scene> = (0..worlds).map(world).collect();
    GpuSim::with_worlds(kernels, &ctx.device, &ctx.queue, &scenes).expect("the batch fits")
}

#[test]
fn each_world_of_a_gpu_batch_ends_bit_for_bit_where_it_ends_alone() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let kernels = Kernels::new(&ctx.device).unwrap();
    let together = gpu_batch(&ctx, &kernels, 4);
    let dispatches: Vec<u32> = (0..STEPS).map(|_| together.step()).collect();
    let mut ends = Vec::new();
    for k in 0..4 {
        let alone = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &world(k)).unwrap();
        let alone_dispatches: Vec<u32> = (0..STEPS).map(|_| alone.step()).collect();
        assert_eq!(
            dispatches, alone_dispatches,
            "a batch records one world's dispatches"
        );
        let (x, v, state) = together.read_world(k as u32).unwrap();
        assert!(x == alone.read_positions().unwrap(), "world {k}: positions");
        assert!(
            v == alone.read_velocities().unwrap(),
            "world {k}: velocities"
        );
        let alone_state = alone.read_state().unwrap();
        assert_eq!(state.steps, alone_state.steps, "world {k}: steps");
        assert_eq!(
            state.cg_iterations_total, alone_state.cg_iterations_total,
            "world {k}"
        );
        assert_eq!(
            state.contacts_total, alone_state.contacts_total,
            "world {k}"
        );
        ends.push(x);
    }
    assert!(ends[0] != ends[1], "the worlds' parameters reach them");
}

#[test]
fn a_world_of_a_gpu_batch_disturbed_changes_no_other() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let kernels = Kernels::new(&ctx.device).unwrap();
    let (calm, shaken) = (gpu_batch(&ctx, &kernels, 4), gpu_batch(&ctx, &kernels, 4));
    let mut nudged = State::initial(&world(1));
    nudged.nudge(1e3 * PERTURBATION);
    shaken.upload_world_state(1, &nudged);
    for _ in 0..STEPS {
        calm.step();
        shaken.step();
    }
    for k in [0, 2, 3] {
        let (a, b) = (calm.read_world(k).unwrap(), shaken.read_world(k).unwrap());
        assert!(a.0 == b.0 && a.1 == b.1, "world {k} moved");
    }
    assert!(
        calm.read_world(1).unwrap().0 != shaken.read_world(1).unwrap().0,
        "the disturbed world"
    );
}
