//! What the fuzz targets (fuzz/fuzz_targets) demand of each loader on
//! arbitrary bytes; tests/fuzz_regressions.rs replays the seed corpus and
//! every input the fuzzer ever crashed through the same checks.

use std::path::Path;

use glam::{Quat, Vec3};
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::CpuSim;
use wgcloth::nn::weights::WeightsFile;
use wgcloth::scene::{Motion, RigidBody, TriMesh};
use wgcloth::{Config, Scene};

/// The weights loader: a file it accepts gives a network whose folded
/// layers are finite, and running that network does not panic.
pub fn weights(data: &[u8]) {
    let Ok(file) = WeightsFile::parse(data, Path::new("fuzz.safetensors")) else {
        return;
    };
    let net = file.network();
    for (k, layer) in net.mlp.layers.iter().enumerate() {
        assert!(
            layer
                .weight
                .iter()
                .chain(&layer.bias)
                .all(|w| w.is_finite()),
            "accepted weights fold into a non-finite layer {k}"
        );
    }
    let middle: Vec<f32> = file
        .input_min
        .iter()
        .zip(&file.input_max)
        .map(|(lo, hi)| 0.5 * lo + 0.5 * hi)
        .collect();
    let _ = net.mlp.forward_jacobian(&middle, 0..middle.len());
}

/// The OBJ loader: a mesh it accepts becomes the rigid body of a small
/// sphere scene, which runs two CPU steps: the body's BVH, both collision
/// directions and the contact forces take any accepted mesh.
pub fn obj(data: &[u8]) {
    let Ok(mesh) = TriMesh::parse_obj(data, Path::new("fuzz.obj")) else {
        return;
    };
    let mut config = Config {
        scene: SceneKind::Sphere,
        model: ModelKind::Friction,
        ..Default::default()
    };
    config.cloth.grid = [6, 6];
    let mut scene = Scene::new(&config).expect("the default scene builds");
    let motion = Motion::Linear {
        velocity: Vec3::new(0.0, 0.0, 1.0),
    };
    scene.rigid = Some(RigidBody::new(mesh, Quat::IDENTITY, Vec3::ZERO, motion));
    let mut sim = CpuSim::new(scene);
    sim.step();
    sim.step();
}

/// The config parser: a small scene that validates also builds and steps
/// on the CPU, since validation is the only gate before a run.
pub fn config(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(config) = Config::from_toml(text, Path::new("fuzz.toml")) else {
        return;
    };
    if config.validate().is_err() {
        return;
    }
    // Files are the other targets' business; big grids and bodies (a
    // sphere of subdivision 7 has 327 680 triangles) only cost time.
    let [nx, ny] = config.cloth.grid;
    let small = nx * ny <= 100 && config.rigid.subdivisions <= 4;
    if config.rigid.mesh.is_some() || config.contact.weights.is_some() || !small {
        return;
    }
    let Ok(scene) = Scene::new(&config) else {
        return;
    };
    let mut sim = CpuSim::new(scene);
    sim.step();
    sim.step();
}
