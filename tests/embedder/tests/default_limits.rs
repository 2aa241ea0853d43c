//! What an app does with wgcloth, from outside the library: a device with
//! WebGPU's default limits and an error handler of its own, the default
//! thesis scene (`friction-net`), 50 steps recorded into its own encoders,
//! the positions read back without blocking. Runs on lavapipe in CI; a
//! missing adapter fails it.

use std::sync::{Arc, Mutex};

use glam::Vec3;
use wgcloth::config::ModelKind;
use wgcloth::gpu::{GpuSim, Readback};
use wgcloth::{Config, Scene};

#[test]
fn the_thesis_scene_steps_on_a_device_with_webgpu_default_limits() {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))
        .expect("a GPU adapter (lavapipe: apt-get install mesa-vulkan-drivers)");
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: wgpu::Limits::default(),
        ..Default::default()
    }))
    .expect("a device with the default limits");
    // Most apps install their own handler; every error must reach it.
    let errors = Arc::new(Mutex::new(Vec::<String>::new()));
    let seen = errors.clone();
    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        seen.lock().unwrap().push(e.to_string())
    }));

    let config = Config::default();
    assert_eq!(config.model, ModelKind::FrictionNet);
    let scene = Scene::new(&config).unwrap();
    let sim = GpuSim::new(&device, &queue, &scene).expect("the scene fits the default limits");
    let mut readback = Readback::new(&device, sim.positions().size(), 2);
    const STEPS: usize = 50;
    for step in 0..STEPS {
        let mut encoder = device.create_command_encoder(&Default::default());
        sim.encode_step(&mut encoder);
        if step + 1 == STEPS {
            assert!(readback.encode_copy(&mut encoder, sim.positions()));
        }
        queue.submit([encoder.finish()]);
    }
    readback.submitted();
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("the device finishes");
    let x: Vec<[f32; 4]> = readback
        .try_take()
        .expect("the copy is mapped once the device is idle");
    assert!(
        errors.lock().unwrap().is_empty(),
        "wgpu errors: {:?}",
        errors.lock().unwrap()
    );

    let x: Vec<Vec3> = x[..scene.cloth.vertex_count()]
        .iter()
        .map(|p| Vec3::from_slice(&p[..3]))
        .collect();
    assert!(x.iter().all(|p| p.is_finite()), "positions not finite");
    let moved = x
        .iter()
        .zip(&scene.cloth.rest_positions)
        .map(|(p, r)| (*p - *r).length())
        .fold(0.0, f32::max);
    assert!(moved > 0.01, "the cloth did not move ({moved} m)");
    // Out of the sphere: no vertex more than 1 cm inside it.
    let body = scene.rigid.as_ref().unwrap();
    let time = STEPS as f32 * config.solver.dt;
    let center = body.translation(time);
    let deepest = x
        .iter()
        .map(|p| config.rigid.radius - (*p - center).length())
        .fold(f32::MIN, f32::max);
    assert!(deepest < 0.01, "a vertex is {deepest} m inside the sphere");
    let near = x
        .iter()
        .filter(|p| (**p - center).length() < config.rigid.radius + 0.05)
        .count();
    assert!(
        near > 0,
        "the sphere never reached the cloth by step {STEPS}"
    );
}

/// A device below what a scene needs gets an error naming the limit, the
/// scene's need and the device's value, not a panic and not a validation
/// error in the app's handler.
#[test]
fn a_device_too_small_for_the_scene_gets_an_error_naming_the_limit() {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))
        .expect("a GPU adapter (lavapipe: apt-get install mesa-vulkan-drivers)");
    let small = 1 << 16;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: wgpu::Limits {
            max_storage_buffer_binding_size: small,
            ..Default::default()
        },
        ..Default::default()
    }))
    .expect("a device with a 64 KiB storage binding limit");
    let errors = Arc::new(Mutex::new(Vec::<String>::new()));
    let seen = errors.clone();
    device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
        seen.lock().unwrap().push(e.to_string())
    }));
    let mut config = Config::default();
    config.cloth.grid = [64, 64];
    let scene = Scene::new(&config).unwrap();
    let Err(e) = GpuSim::new(&device, &queue, &scene) else {
        panic!("a 64² scene cannot fit 64 KiB bindings");
    };
    let message = e.to_string();
    assert!(
        message.contains("max_storage_buffer_binding_size") && message.contains(&small.to_string()),
        "{message}"
    );
    assert!(
        errors.lock().unwrap().is_empty(),
        "{:?}",
        errors.lock().unwrap()
    );
}
