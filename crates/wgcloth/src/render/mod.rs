//! Headless frames of a scene (thesis Figures 1–2): the cloth and the
//! rigid body with two-sided Phong shading, an optional wireframe, and the
//! contact forces as green segments (wgsl/render.wgsl). The pipelines read
//! the simulator's own GPU buffers ([`Source::gpu`]); the CPU path uploads
//! its state into buffers of the same layout ([`HostScene`]).

pub mod camera;
pub mod lines;
pub mod shade;

use glam::{Mat4, Vec3};
use wgpu::util::DeviceExt;

use crate::cpu::CpuSim;
#[cfg(not(target_arch = "wasm32"))]
use crate::error::{Error, Result};
use crate::gpu::GpuSim;
use crate::gpu::buffers::vec4s;
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::context::read_buffer;
use crate::scene::Scene;

pub use camera::Camera;

/// wgsl/render.wgsl with the shading constants in front of it.
fn shader() -> String {
    shade::prelude() + include_str!("../../wgsl/render.wgsl")
}
#[cfg(not(target_arch = "wasm32"))]
// The offscreen frames' format ([`Renderer`], native only).
const COLOR: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
const DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// The frame size unless asked otherwise.
pub const DEFAULT_SIZE: u32 = 512;

/// What a frame shows besides the shaded surfaces.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Style {
    /// Draw the edges of the cloth's triangles.
    pub wireframe: bool,
    /// Draw each contact's force as a segment from the penetrating point.
    pub forces: bool,
}

/// A rendered frame, RGBA8 (sRGB), rows top to bottom.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// 4 bytes per pixel, width × height pixels.
    pub rgba: Vec<u8>,
}

impl Frame {
    /// The RGBA of pixel (x, y), y counted down from the top row.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = 4 * (y * self.width + x) as usize;
        [
            self.rgba[i],
            self.rgba[i + 1],
            self.rgba[i + 2],
            self.rgba[i + 3],
        ]
    }
}

/// The buffers a frame is drawn from, in the simulator's layout: cloth
/// positions (vec4) and triangles (u32 ×3), the placed body's vertices and
/// triangles, and force segments (vec4 pairs).
pub struct Source<'a> {
    /// Cloth positions, one vec4 per vertex.
    pub positions: &'a wgpu::Buffer,
    /// Cloth triangles, three u32 vertex indices each.
    pub triangles: &'a wgpu::Buffer,
    /// Number of cloth triangles drawn.
    pub triangle_count: u32,
    /// The cloth grid's vertices per row and per column (vertex (r, c) is
    /// `r * nx + c`): the shader's vertex normals come from a vertex's
    /// grid neighbours.
    pub grid: [u32; 2],
    /// The body's vertices placed in the world, one vec4 each.
    pub body_vertices: &'a wgpu::Buffer,
    /// The body's triangles, three u32 each; a binding, as they may be a
    /// section of a larger buffer.
    pub body_triangles: wgpu::BufferBinding<'a>,
    /// Number of body triangles drawn (0 without a body).
    pub body_triangle_count: u32,
    /// Force segments, two vec4 per contact slot (w = 0: no contact).
    pub lines: &'a wgpu::Buffer,
    /// Number of contact slots: one per cloth vertex, one per body vertex.
    pub line_count: u32,
}

impl<'a> Source<'a> {
    /// A GPU simulator's own buffers; call `GpuSim::record_force_lines`
    /// after a step for current force segments.
    pub fn gpu(sim: &'a GpuSim, scene: &Scene) -> Source<'a> {
        let (body_vertices, body_triangles) = sim.body();
        Source {
            positions: sim.positions(),
            triangles: sim.indices(),
            triangle_count: scene.cloth.triangles.len() as u32,
            grid: [scene.cloth.nx, scene.cloth.ny],
            body_vertices,
            body_triangles,
            body_triangle_count: body_triangle_count(scene),
            lines: sim.force_lines(),
            line_count: slot_count(scene),
        }
    }
}

fn body_triangle_count(scene: &Scene) -> u32 {
    scene
        .rigid
        .as_ref()
        .map_or(0, |b| b.mesh.triangles.len() as u32)
}

/// Contact slots: one per cloth vertex, one per body vertex.
fn slot_count(scene: &Scene) -> u32 {
    (scene.cloth.vertex_count() + scene.rigid.as_ref().map_or(0, |b| b.mesh.vertices.len())) as u32
}

/// GPU copies of a CPU simulator's state for drawing, updated per frame.
pub struct HostScene {
    positions: wgpu::Buffer,
    triangles: wgpu::Buffer,
    body_vertices: wgpu::Buffer,
    body_triangles: wgpu::Buffer,
    lines: wgpu::Buffer,
    triangle_count: u32,
    grid: [u32; 2],
    body_triangle_count: u32,
    line_count: u32,
}

impl HostScene {
    /// Buffers sized for `scene`, holding the cloth at rest and no force
    /// segments until the first upload.
    pub fn new(device: &wgpu::Device, scene: &Scene) -> HostScene {
        let buffer = |label: &str, contents: &[u8]| {
            // Bindings need at least one element.
            let mut bytes = contents.to_vec();
            bytes.resize(bytes.len().max(16), 0);
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &bytes,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
        };
        let flat = |t: &[[u32; 3]]| t.iter().flatten().copied().collect::<Vec<u32>>();
        let (body_vertices, body_triangles) = match &scene.rigid {
            Some(b) => (vec4s(&b.mesh.vertices, 1.0), flat(&b.mesh.triangles)),
            None => (vec![], vec![]),
        };
        let slots = slot_count(scene) as usize;
        HostScene {
            positions: buffer(
                "cloth positions",
                bytemuck::cast_slice(&vec4s(&scene.cloth.rest_positions, 1.0)),
            ),
            triangles: buffer(
                "cloth triangles",
                bytemuck::cast_slice(&flat(&scene.cloth.triangles)),
            ),
            body_vertices: buffer("body vertices", bytemuck::cast_slice(&body_vertices)),
            body_triangles: buffer("body triangles", bytemuck::cast_slice(&body_triangles)),
            lines: buffer("force lines", &vec![0u8; 32 * slots]),
            triangle_count: scene.cloth.triangles.len() as u32,
            grid: [scene.cloth.nx, scene.cloth.ny],
            body_triangle_count: body_triangle_count(scene),
            line_count: slot_count(scene),
        }
    }

    /// Uploads cloth positions `x` at `time` (the body placed for that
    /// time) and force segments (none: the buffer keeps its last ones).
    pub fn upload(
        &self,
        queue: &wgpu::Queue,
        scene: &Scene,
        (x, time): (&[Vec3], f32),
        lines: &[[f32; 4]],
    ) {
        let write = |buffer: &wgpu::Buffer, data: &[[f32; 4]]| {
            queue.write_buffer(buffer, 0, bytemuck::cast_slice(data));
        };
        write(&self.positions, &vec4s(x, 1.0));
        if let Some(body) = &scene.rigid {
            write(
                &self.body_vertices,
                &vec4s(&body.placed_vertices(time), 1.0),
            );
        }
        write(&self.lines, lines);
    }

    /// Uploads a CPU simulator's state and its last step's force segments
    /// (`metres_per_force` long per unit of force).
    pub fn upload_sim(&self, queue: &wgpu::Queue, sim: &CpuSim, metres_per_force: f32) {
        let state = (&sim.state.x[..], sim.state.time as f32);
        self.upload(
            queue,
            &sim.scene,
            state,
            &lines::force_lines(sim, metres_per_force),
        );
    }

    /// The buffers to draw a frame from.
    pub fn source(&self) -> Source<'_> {
        Source {
            positions: &self.positions,
            triangles: &self.triangles,
            triangle_count: self.triangle_count,
            grid: self.grid,
            body_vertices: &self.body_vertices,
            body_triangles: self.body_triangles.as_entire_buffer_binding(),
            body_triangle_count: self.body_triangle_count,
            lines: &self.lines,
            line_count: self.line_count,
        }
    }
}

/// Mirrors `Camera` in wgsl/render.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct CameraUniform {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    light: [f32; 4],
    grid: [u32; 4],
}

/// The render pipelines for one colour format, to draw into any target
/// of it (an offscreen [`Renderer`], or a window's surface).
pub struct Pipelines {
    layout: wgpu::BindGroupLayout,
    cloth: wgpu::RenderPipeline,
    body: wgpu::RenderPipeline,
    wire: wgpu::RenderPipeline,
    force: wgpu::RenderPipeline,
    camera: wgpu::Buffer,
}

/// A depth buffer for a width × height target.
pub fn depth_target(device: &wgpu::Device, width: u32, height: u32) -> wgpu::TextureView {
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
    texture(device, "depth", (width, height), DEPTH, usage)
        .create_view(&wgpu::TextureViewDescriptor::default())
}

fn texture(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

impl Pipelines {
    /// Compiles the pipelines for targets of colour `format`.
    pub fn new(device: &wgpu::Device, format: wgpu::TextureFormat) -> Pipelines {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("render"),
            source: wgpu::ShaderSource::Wgsl(shader().into()),
        });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let storage = wgpu::BufferBindingType::Storage { read_only: true };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("render"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform),
                entry(1, storage),
                entry(2, storage),
                entry(3, storage),
                entry(4, storage),
                entry(5, storage),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |(vs, fs): (&str, &str), topology, bias, depth_compare| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(fs),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(vs),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    // Two-sided: the cloth is seen from both sides.
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH,
                    depth_write_enabled: Some(depth_compare == wgpu::CompareFunction::LessEqual),
                    depth_compare: Some(depth_compare),
                    stencil: Default::default(),
                    bias,
                }),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets: &[Some(format.into())],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        // Surfaces are pushed back a little so lines on them win the depth
        // test (lines may not carry a bias themselves).
        let behind = wgpu::DepthBiasState {
            constant: 2,
            slope_scale: 1.0,
            clamp: 0.0,
        };
        let (tested, always) = (
            wgpu::CompareFunction::LessEqual,
            wgpu::CompareFunction::Always,
        );
        let (triangles, segments) = (
            wgpu::PrimitiveTopology::TriangleList,
            wgpu::PrimitiveTopology::LineList,
        );
        Pipelines {
            cloth: pipeline(("vs_cloth", "fs_cloth"), triangles, behind, tested),
            body: pipeline(("vs_body", "fs_body"), triangles, behind, tested),
            wire: pipeline(("vs_wire", "fs_wire"), segments, Default::default(), tested),
            // Forces are drawn over everything: a cloth vertex's force often
            // points behind the cloth as seen from the body's side.
            force: pipeline(
                ("vs_line", "fs_force"),
                segments,
                Default::default(),
                always,
            ),
            layout,
            camera: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("camera"),
                size: size_of::<CameraUniform>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }

    /// Records a frame of `source` as seen by `camera` into a target
    /// (colour view, depth view, width / height), cleared to white first.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        (view, depth, aspect): (&wgpu::TextureView, &wgpu::TextureView, f32),
        source: &Source,
        camera: &Camera,
        style: Style,
    ) {
        let view_proj: Mat4 = camera.view_proj(aspect);
        let uniform = CameraUniform {
            view_proj: view_proj.to_cols_array_2d(),
            eye: camera.eye.extend(1.0).to_array(),
            light: camera.light.extend(0.0).to_array(),
            grid: [source.grid[0], source.grid[1], 0, 0],
        };
        queue.write_buffer(&self.camera, 0, bytemuck::bytes_of(&uniform));
        fn bind(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render"),
            layout: &self.layout,
            entries: &[
                bind(0, &self.camera),
                bind(1, source.positions),
                bind(2, source.triangles),
                bind(3, source.body_vertices),
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::Buffer(source.body_triangles.clone()),
                },
                bind(5, source.lines),
            ],
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("frame"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: shade::BACKGROUND.x as f64,
                        g: shade::BACKGROUND.y as f64,
                        b: shade::BACKGROUND.z as f64,
                        a: 1.0,
                    }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            ..Default::default()
        });
        pass.set_bind_group(0, &group, &[]);
        let mut draw = |pipeline, vertices: u32| {
            pass.set_pipeline(pipeline);
            pass.draw(0..vertices, 0..1);
        };
        draw(&self.cloth, 3 * source.triangle_count);
        draw(&self.body, 3 * source.body_triangle_count);
        if style.wireframe {
            draw(&self.wire, 6 * source.triangle_count);
        }
        if style.forces {
            draw(&self.force, 2 * source.line_count);
        }
    }
}

#[cfg(not(target_arch = "wasm32"))]
/// The render pipelines with an offscreen RGBA8 (sRGB) target of one size,
/// read back frame by frame.
pub struct Renderer {
    pipelines: Pipelines,
    color: wgpu::Texture,
    depth: wgpu::TextureView,
    width: u32,
    height: u32,
}

#[cfg(not(target_arch = "wasm32"))]
impl Renderer {
    /// Pipelines and a width × height target; a size the adapter cannot
    /// hold is an error naming the limit.
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Result<Renderer> {
        let most = device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > most || height > most {
            return Err(Error::config(
                "--size",
                format!(
                    "{width}×{height} is not a frame this adapter renders (1 to {most} per side)"
                ),
            ));
        }
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        Ok(Renderer {
            pipelines: Pipelines::new(device, COLOR),
            color: texture(device, "frame", (width, height), COLOR, usage),
            depth: depth_target(device, width, height),
            width,
            height,
        })
    }

    /// Draws `source` as seen by `camera` and reads the frame back (native
    /// only: it blocks; a browser draws with [`Pipelines::record`]).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn render(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        source: &Source,
        camera: &Camera,
        style: Style,
    ) -> Result<Frame> {
        let view = self
            .color
            .create_view(&wgpu::TextureViewDescriptor::default());
        let mut encoder = device.create_command_encoder(&Default::default());
        let aspect = self.width as f32 / self.height as f32;
        let target = (&view, &self.depth, aspect);
        self.pipelines
            .record(device, queue, &mut encoder, target, source, camera, style);
        // Rows padded to the copy alignment, then unpadded on the host.
        let row = 4 * self.width;
        let padded = row.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame readback"),
            size: (padded * self.height) as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            self.color.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(self.height),
                },
            },
            self.color.size(),
        );
        queue.submit([encoder.finish()]);
        let bytes: Vec<u8> = read_buffer(device, queue, &readback)?;
        let rgba = bytes
            .chunks_exact(padded as usize)
            .take(self.height as usize)
            .flat_map(|r| &r[..row as usize])
            .copied()
            .collect();
        Ok(Frame {
            width: self.width,
            height: self.height,
            rgba,
        })
    }
}

/// The largest frame side any adapter is asked for (common GPUs' and
/// lavapipe's 2D texture limit).
pub const MAX_FRAME_SIZE: u32 = 16384;

#[cfg(test)]
mod tests {
    use super::shader;

    #[test]
    fn the_render_shader_validates_with_naga() {
        let module = naga::front::wgsl::parse_str(&shader()).expect("render.wgsl parses");
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&module)
        .expect("render.wgsl validates");
        let names: Vec<&str> = module
            .entry_points
            .iter()
            .map(|e| e.name.as_str())
            .collect();
        for wanted in [
            "vs_cloth", "vs_body", "vs_wire", "vs_line", "fs_cloth", "fs_body",
        ] {
            assert!(names.contains(&wanted), "{wanted} in {names:?}");
        }
    }
}
