//! Embedding wgcloth in a wgpu program: the app owns the device, records
//! simulation steps and its own render pass into one command encoder, and
//! draws the cloth straight from the simulator's position and index
//! buffers (no copy through the CPU). Headless: the last frame is saved.
//!
//! `cargo run --release --example embed -- [FRAMES] [OUT.png]`

use std::sync::Arc;

use wgcloth::gpu::{GpuSim, Kernels};
use wgcloth::{Config, Scene};

const SIZE: u32 = 512;
const STEPS_PER_FRAME: u32 = 2;

// Orthographic side view; shade by depth so the drape reads.
const SHADER: &str = r#"
@vertex
fn vs(@location(0) p: vec4<f32>) -> @builtin(position) vec4<f32> {
    // Look along −x: screen x = z, screen y = y.
    return vec4<f32>(p.z * 1.4, p.y * 1.4 + 0.1, 0.5 + 0.4 * p.x, 1.0);
}

@fragment
fn fs(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let shade = 1.2 - frag.z;
    return vec4<f32>(0.9 * shade, 0.35 * shade, 0.25 * shade, 1.0);
}
"#;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let frames: u32 = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(45);
    let out = args.get(2).cloned().unwrap_or_else(|| "embed.png".into());

    // The app's own device and queue.
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))?;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: adapter.limits(),
        ..Default::default()
    }))?;
    println!("adapter: {}", adapter.get_info().name);

    // The simulator: kernels once per device, state once per scene.
    let kernels = Arc::new(Kernels::new(&device)?);
    let sim = GpuSim::new(kernels, &device, &queue, &Scene::new(&Config::default())?)?;

    let target = device.create_texture(&wgpu::TextureDescriptor {
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        ..target_descriptor()
    });
    let depth = device.create_texture(&wgpu::TextureDescriptor {
        format: wgpu::TextureFormat::Depth32Float,
        ..target_descriptor()
    });
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("cloth"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("cloth"),
        layout: None,
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: 16,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x4],
            })],
        },
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::TextureFormat::Rgba8Unorm.into())],
        }),
        primitive: Default::default(),
        depth_stencil: Some(wgpu::DepthStencilState {
            format: wgpu::TextureFormat::Depth32Float,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        multiview_mask: None,
        cache: None,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("frame readback"),
        size: (SIZE * SIZE * 4) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });

    for frame in 0..frames {
        let mut encoder = device.create_command_encoder(&Default::default());
        for _ in 0..STEPS_PER_FRAME {
            sim.record_step(&mut encoder);
        }
        {
            let view = target.create_view(&Default::default());
            let depth_view = depth.create_view(&Default::default());
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("cloth"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: 0.95,
                            g: 0.95,
                            b: 0.93,
                            a: 1.0,
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            pass.set_pipeline(&pipeline);
            // The simulator's own buffers, drawn directly.
            pass.set_vertex_buffer(0, sim.positions().slice(..));
            pass.set_index_buffer(sim.indices().slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..sim.index_count(), 0, 0..1);
        }
        if frame + 1 == frames {
            encoder.copy_texture_to_buffer(
                target.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &readback,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(SIZE * 4),
                        rows_per_image: None,
                    },
                },
                target_descriptor().size,
            );
        }
        queue.submit([encoder.finish()]);
    }
    readback.map_async(wgpu::MapMode::Read, .., |r| r.expect("frame readback"));
    device.poll(wgpu::PollType::wait_indefinitely())?;
    let pixels = readback.get_mapped_range(..)?.to_vec();
    image::RgbaImage::from_raw(SIZE, SIZE, pixels)
        .ok_or("frame size")?
        .save(&out)?;
    println!(
        "{out}: the cloth after {} steps, drawn from the simulator's buffers",
        frames * STEPS_PER_FRAME
    );
    Ok(())
}

fn target_descriptor() -> wgpu::TextureDescriptor<'static> {
    wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d {
            width: SIZE,
            height: SIZE,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8Unorm,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    }
}
