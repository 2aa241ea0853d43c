//! A batch of worlds on the CPU (`cpu::worlds`) and on the GPU
//! (`gpu::worlds`, issue 67): each world ends bit for bit where its scene
//! ends run alone, and no world reads another's state.

mod common;

use wgcloth::config::ModelKind;
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::cpu::{CpuSim, PERTURBATION, State};
use wgcloth::gpu::worlds::MAX_WORLDS;
use wgcloth::gpu::{GpuSim, Kernels};
use wgcloth::{Config, Scene};

const STEPS: usize = 30;

/// The thesis scene at 16² with world `k`'s friction and sphere path:
/// worlds that would end differently if they were mixed up.
fn world(k: usize) -> Scene {
    world_of(ModelKind::Friction, k)
}

/// [`world`] with `model`.
fn world_of(model: ModelKind, k: usize) -> Scene {
    let mut c = Config {
        model,
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

/// A GPU batch of `worlds` worlds of `model`, each at rest.
fn gpu_batch(
    ctx: &wgcloth::gpu::GpuContext,
    kernels: &Kernels,
    model: ModelKind,
    worlds: usize,
) -> GpuSim {
    let scenes: Vec<Scene> = (0..worlds).map(|k| world_of(model, k)).collect();
    GpuSim::with_worlds(kernels, &ctx.device, &ctx.queue, &scenes).expect("the batch fits")
}

/// The analytic model, and the network's, whose one batch serves every
/// world's contacts.
#[test]
fn each_world_of_a_gpu_batch_ends_bit_for_bit_where_it_ends_alone() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let kernels = Kernels::new(&ctx.device).unwrap();
    for model in [ModelKind::Friction, ModelKind::FrictionNet] {
        gpu_batch_ends_where_each_world_ends_alone(&ctx, &kernels, model);
    }
}

fn gpu_batch_ends_where_each_world_ends_alone(
    ctx: &wgcloth::gpu::GpuContext,
    kernels: &Kernels,
    model: ModelKind,
) {
    let together = gpu_batch(ctx, kernels, model, 4);
    let dispatches: Vec<u32> = (0..STEPS).map(|_| together.step()).collect();
    let name = model.name();
    let (mut ends, mut touched) = (Vec::new(), 0);
    for k in 0..4 {
        let scene = world_of(model, k);
        let alone = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        let alone_dispatches: Vec<u32> = (0..STEPS).map(|_| alone.step()).collect();
        // But for the network's chunks, a batch records one world's dispatches.
        let besides = |d: &[u32], sim: &GpuSim| -> Vec<u32> {
            d.iter().map(|d| d - sim.network_dispatches()).collect()
        };
        assert_eq!(
            besides(&dispatches, &together),
            besides(&alone_dispatches, &alone),
            "{name}: a batch records one world's dispatches"
        );
        let (x, v, state) = together.read_world(k as u32).unwrap();
        assert!(
            x == alone.read_positions().unwrap(),
            "{name}, world {k}: positions"
        );
        assert!(
            v == alone.read_velocities().unwrap(),
            "{name}, world {k}: velocities"
        );
        let alone_state = alone.read_state().unwrap();
        assert_eq!(state.steps, alone_state.steps, "{name}, world {k}: steps");
        let iterations = (state.cg_iterations_total, alone_state.cg_iterations_total);
        assert_eq!(iterations.0, iterations.1, "{name}, world {k}: iterations");
        let contacts = (state.contacts_total, alone_state.contacts_total);
        assert_eq!(contacts.0, contacts.1, "{name}, world {k}: contacts");
        touched += usize::from(contacts.0 > 0);
        ends.push(x);
    }
    assert!(touched > 0, "{name}: the sphere reaches some world's cloth");
    assert!(
        ends[0] != ends[1],
        "{name}: the worlds' parameters reach them"
    );
}

#[test]
fn a_world_of_a_gpu_batch_disturbed_changes_no_other() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let kernels = Kernels::new(&ctx.device).unwrap();
    // The network's: every world's contacts share its batch.
    let model = ModelKind::FrictionNet;
    let batch = || gpu_batch(&ctx, &kernels, model, 4);
    let (calm, shaken) = (batch(), batch());
    let mut nudged = State::initial(&world_of(model, 1));
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
    let moved = calm.read_world(1).unwrap().0 != shaken.read_world(1).unwrap().0;
    assert!(moved, "the disturbed world");
}

/// Worlds that cannot share a batch get one error naming what, before any
/// buffer is made: none, more than a batch holds, a world whose grid
/// differs, and a scene the batch does not run (self-contact).
#[test]
fn a_gpu_batch_refuses_worlds_it_cannot_hold_with_an_error_naming_why() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let kernels = Kernels::new(&ctx.device).unwrap();
    let refused =
        |scenes: &[Scene]| match GpuSim::with_worlds(&kernels, &ctx.device, &ctx.queue, scenes) {
            Ok(_) => panic!("a batch of {} worlds was made", scenes.len()),
            Err(e) => e.to_string(),
        };
    assert!(refused(&[]).contains("at least one world"));
    let many = vec![world(0); MAX_WORLDS as usize + 1];
    assert!(refused(&many).contains(&MAX_WORLDS.to_string()));
    let mut coarser = Config::default();
    coarser.cloth.grid = [8, 8];
    let mixed = [world(0), Scene::new(&coarser).unwrap()];
    let message = refused(&mixed);
    assert!(
        message.contains("world 1") && message.contains("grid"),
        "{message}"
    );
    let mut folding = Config::default();
    folding.cloth.grid = [16, 16];
    folding.self_contact.enabled = true;
    let message = refused(&[Scene::new(&folding).unwrap()]);
    assert!(message.contains("self-contact"), "{message}");
}

/// Past the first 512 worlds, whose parameters the first uniform binding
/// holds, each world still reads its own: worlds under different gravity,
/// so that each step tells them apart.
#[test]
fn a_world_past_the_first_binding_of_parameters_keeps_its_own() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let under = |k: usize| {
        let mut c = Config::default();
        c.cloth.grid = [8, 8];
        c.model = ModelKind::Friction;
        c.solver.gravity[1] *= 1.0 + 0.1 * k as f32;
        Scene::new(&c).unwrap()
    };
    let kernels = Kernels::new(&ctx.device).unwrap();
    let scenes: Vec<Scene> = (0..514).map(|k| under(k % 3)).collect();
    let batch = GpuSim::with_worlds(&kernels, &ctx.device, &ctx.queue, &scenes).unwrap();
    for _ in 0..3 {
        batch.step();
    }
    for k in [0, 511, 512, 513] {
        let alone = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scenes[k]).unwrap();
        for _ in 0..3 {
            alone.step();
        }
        let (x, v, _) = batch.read_world(k as u32).unwrap();
        assert!(x == alone.read_positions().unwrap(), "world {k}: positions");
        assert!(
            v == alone.read_velocities().unwrap(),
            "world {k}: velocities"
        );
    }
    let (a, b) = (
        batch.read_world(512).unwrap().0,
        batch.read_world(513).unwrap().0,
    );
    assert!(a != b, "gravity tells the worlds apart");
}
