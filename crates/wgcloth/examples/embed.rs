// An app embeds wgcloth: its own device with WebGPU's default limits, the
// thesis scene stepped in its own encoder, the cloth drawn by its own
// render pass straight from the simulator's buffers, and the positions and
// the solver's statistics read back without waiting. Run:
// cargo run --release -p wgcloth --example embed
use wgcloth::gpu::{CgBudget, GpuSim, Readback, layout::StepState};
use wgcloth::{Config, Scene};

const SHADER: &str = "
@vertex fn vs(@location(0) p: vec4<f32>) -> @builtin(position) vec4<f32> {
    return vec4<f32>(1.4 * p.z, 1.4 * p.y + 0.1, 0.5 + 0.4 * p.x, 1.0);
}
@fragment fn fs() -> @location(0) vec4<f32> { return vec4<f32>(0.9, 0.35, 0.25, 1.0); }";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default()))?;
    // DeviceDescriptor::default() asks for wgpu::Limits::default().
    let (device, queue) = pollster::block_on(adapter.request_device(&Default::default()))?;

    let scene = Scene::new(&Config::default())?;
    let sim = GpuSim::new(&device, &queue, &scene)?;
    let mut readback = Readback::new(&device, sim.positions().size(), 2);
    // A step records as many PCG iterations as recent steps needed, not the
    // whole cap: each empty one still costs its dispatches. (A cloth of up
    // to 64² solves whole in one dispatch, and its budget stays the cap.)
    let mut statistics = Readback::new(&device, sim.statistics().size(), 2);
    let mut budget = CgBudget::for_solver(&scene.config.solver);

    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("cloth"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let format = wgpu::TextureFormat::Rgba8Unorm;
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("cloth"),
        layout: None,
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[Some(wgpu::VertexBufferLayout {
                array_stride: 16, // one vec4<f32> per cloth vertex
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &wgpu::vertex_attr_array![0 => Float32x4],
            })],
        },
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[Some(format.into())],
        }),
        primitive: Default::default(),
        depth_stencil: None,
        multisample: Default::default(),
        multiview_mask: None,
        cache: None,
    });
    let target = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("frame"),
        size: wgpu::Extent3d {
            width: 256,
            height: 256,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        view_formats: &[],
    });
    let view = target.create_view(&Default::default());

    let mut lowest = None;
    for _frame in 0..50 {
        let mut encoder = device.create_command_encoder(&Default::default());
        sim.encode_step(&mut encoder); // records the step: no wait, no readback
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::WHITE),
                    store: wgpu::StoreOp::Store,
                },
            })],
            ..Default::default()
        });
        pass.set_pipeline(&pipeline);
        pass.set_vertex_buffer(0, sim.positions().slice(..));
        pass.set_index_buffer(sim.indices().slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..sim.index_count(), 0, 0..1);
        drop(pass);
        readback.encode_copy(&mut encoder, sim.positions());
        statistics.encode_copy(&mut encoder, sim.statistics());
        queue.submit([encoder.finish()]);
        readback.submitted();
        statistics.submitted();
        device.poll(wgpu::PollType::Poll)?; // runs finished map_async callbacks
        if let Some(x) = readback.try_take::<[f32; 4]>() {
            lowest = x.iter().map(|p| p[1]).reduce(f32::min);
        }
        if let Some(s) = statistics.try_take::<StepState>() {
            // A step or two old, so the budget it ran under is taken as the
            // current one: a step may be counted against a budget it did
            // not run under, cut or not.
            budget.observe(s[0].last_iterations, sim.cg_budget(), s[0].last_residual);
            sim.set_cg_budget(budget.next());
        }
    }
    println!(
        "50 steps on {}; lowest cloth point read back: {lowest:?} m; PCG iterations recorded a step: {} of {}",
        adapter.get_info().name,
        sim.cg_budget(),
        scene.config.solver.cg_iters
    );
    Ok(())
}
