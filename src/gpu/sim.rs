//! One scene's state on the GPU (buffers and bind groups) and the recorded
//! step. This is the embedding API: create it from the app's own device and
//! queue, record steps into the app's command encoder, and draw
//! [`GpuSim::positions`] with [`GpuSim::indices`] directly.

use std::sync::Arc;

use bytemuck::Pod;
use glam::Vec3;
use wgpu::util::DeviceExt;

use crate::config::ModelKind;
use crate::error::{Error, Result};
use crate::gpu::context::read_buffer;
use crate::gpu::kernels::Kernels;
use crate::gpu::layout::{
    BvhNode, Contact, Params, Response, RigidFrame, Scalars, StepState, Sym3,
};
use crate::gpu::mlp::{BatchBuffers, BatchShape, GpuMlp, NetworkKernel, output_bytes};
use crate::nn::weights::NetKind;
use crate::render::metres_per_force;
use crate::scene::{Motion, Scene};
use crate::stage::Stage;

const WORKGROUP: u32 = 256;

/// `MAX_TRIANGLE_CONTACTS` in wgsl/common.wgsl.
const MAX_TRIANGLE_CONTACTS: usize = 8;

/// Cloth grid cells per tile edge, and tiles per super-tile edge
/// (`TILE` in wgsl/collide.wgsl).
const TILE: u32 = 8;

/// A contact slot and its response, as read back.
pub type ContactSlot = (Contact, Response);

struct Buffers {
    params: wgpu::Buffer,
    x: wgpu::Buffer,
    v: wgpu::Buffer,
    /// Positions and velocities as `record_checkpoint` last copied them.
    x_kept: wgpu::Buffer,
    v_kept: wgpu::Buffer,
    rest: wgpu::Buffer,
    pinned: wgpu::Buffer,
    springs: wgpu::Buffer,
    rest_lengths: wgpu::Buffer,
    adj_offsets: wgpu::Buffer,
    adj_spring: wgpu::Buffer,
    adj_other: wgpu::Buffer,
    triangles: wgpu::Buffer,
    vertex_triangle_offsets: wgpu::Buffer,
    vertex_triangles: wgpu::Buffer,
    spring_triangles: wgpu::Buffer,
    spring_force: wgpu::Buffer,
    spring_block: wgpu::Buffer,
    vf_contacts: wgpu::Buffer,
    vf_responses: wgpu::Buffer,
    fv_contacts: wgpu::Buffer,
    fv_responses: wgpu::Buffer,
    triangle_contact_count: wgpu::Buffer,
    triangle_contacts: wgpu::Buffer,
    a_diag: wgpu::Buffer,
    a_off: wgpu::Buffer,
    b: wgpu::Buffer,
    r: wgpu::Buffer,
    z: wgpu::Buffer,
    p: wgpu::Buffer,
    q: wgpu::Buffer,
    inv_diag: wgpu::Buffer,
    partials: wgpu::Buffer,
    scalars: [wgpu::Buffer; 2],
    state: wgpu::Buffer,
    body_vertices: wgpu::Buffer,
    body_normals: wgpu::Buffer,
    body_triangles: wgpu::Buffer,
    body_face_normals: wgpu::Buffer,
    bvh_nodes: wgpu::Buffer,
    bvh_order: wgpu::Buffer,
    rigid_vertices: wgpu::Buffer,
    rigid_normals: wgpu::Buffer,
    frame: wgpu::Buffer,
    tile_bounds: wgpu::Buffer,
    supertile_bounds: wgpu::Buffer,
    net_count: wgpu::Buffer,
    net_list: wgpu::Buffer,
    net_inputs: wgpu::Buffer,
    net_outputs: wgpu::Buffer,
    /// The renderer's force segments (stage "lines") and their scale.
    lines: wgpu::Buffer,
    line_scale: wgpu::Buffer,
}

struct BindGroups {
    rigid: wgpu::BindGroup,
    collide: wgpu::BindGroup,
    contact: wgpu::BindGroup,
    measure: wgpu::BindGroup,
    springs: wgpu::BindGroup,
    assemble: wgpu::BindGroup,
    /// [0]: scalars in = 0, out = 1; [1]: the reverse.
    pcg: [wgpu::BindGroup; 2],
    integrate: wgpu::BindGroup,
    lines: wgpu::BindGroup,
}

/// Timestamp queries around each pass, where the adapter has them.
struct Timer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f32,
}

pub struct GpuSim {
    kernels: Arc<Kernels>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    params: Params,
    buffers: Buffers,
    groups: BindGroups,
    timer: Option<Timer>,
    /// The network of a network model.
    network: Option<GpuMlp>,
}

fn groups(n: u32) -> u32 {
    n.div_ceil(WORKGROUP)
}

fn vec4s(points: &[Vec3], w: f32) -> Vec<[f32; 4]> {
    points.iter().map(|p| p.extend(w).to_array()).collect()
}

/// The run's constants, as the kernels read them.
fn params_for(scene: &Scene) -> Params {
    let cloth = &scene.cloth;
    let cfg = &scene.config;
    let (cells_x, cells_y) = (cloth.nx - 1, cloth.ny - 1);
    let (tiles_x, tiles_y) = (cells_x.div_ceil(TILE), cells_y.div_ceil(TILE));
    let mut p = Params {
        n_vertices: cloth.vertex_count() as u32,
        n_springs: cloth.springs.len() as u32,
        n_triangles: cloth.triangles.len() as u32,
        // MODEL_* in wgsl/common.wgsl.
        model: match cfg.model {
            ModelKind::Naive => 0,
            ModelKind::Friction => 1,
            ModelKind::FrictionNet => match scene.network.as_ref().map(|n| n.kind) {
                Some(NetKind::FrictionContact) => 4,
                _ => 2,
            },
            ModelKind::NaiveNet => 3,
        },
        net_width: scene.network.as_ref().map_or(0, |n| n.mlp.inputs() as u32),
        net_rows: scene
            .network
            .as_ref()
            .map_or(0, |n| 1 + n.kind.wrt().len() as u32),
        net_outputs: scene.network.as_ref().map_or(0, |n| n.mlp.outputs() as u32),
        cg_max_iters: cfg.solver.cg_iters,
        dt: cfg.solver.dt,
        vertex_mass: cloth.vertex_mass,
        stiffness: cloth.stiffness,
        cg_tol: cfg.solver.cg_tol,
        max_speed: cfg.solver.max_speed,
        damping_mass: cfg.cloth.damping_mass,
        damping_stiffness: cfg.cloth.damping_stiffness,
        thickness: cfg.contact.thickness,
        max_depth: cfg.contact.max_depth,
        gravity: cfg.solver.gravity,
        naive_stiffness: cfg.contact.naive_stiffness,
        force_scale: cfg.contact.force_scale,
        kn: cfg.contact.kn,
        kd: cfg.contact.kd,
        kt: cfg.contact.kt,
        mu: cfg.contact.mu,
        cells_x,
        cells_y,
        tiles_x,
        tiles_y,
        supertiles_x: tiles_x.div_ceil(TILE),
        supertiles_y: tiles_y.div_ceil(TILE),
        ..Default::default()
    };
    if let Some(body) = &scene.rigid {
        p.has_rigid = 1;
        p.n_rigid_vertices = body.mesh.vertices.len() as u32;
        p.n_rigid_triangles = body.mesh.triangles.len() as u32;
        p.rigid_position = body.position.to_array();
        p.rigid_rotation = body.rotation.to_array();
        (p.motion_kind, p.motion_vector) = match body.motion {
            Motion::Static => (0, [0.0; 3]),
            Motion::Linear { velocity } => (1, velocity.to_array()),
            Motion::Sinusoid {
                axis,
                amplitude,
                period,
                phase,
            } => {
                (p.motion_amplitude, p.motion_period, p.motion_phase) = (amplitude, period, phase);
                (2, axis.to_array())
            }
        };
    }
    p
}

impl Buffers {
    fn new(device: &wgpu::Device, scene: &Scene, params: &Params) -> Buffers {
        let cloth = &scene.cloth;
        let (n, s, t) = (
            cloth.vertex_count(),
            cloth.springs.len(),
            cloth.triangles.len(),
        );
        // Vertex → (triangle, corner) and spring → (triangle, edge): where
        // the gathers find the face–vertex contacts.
        let mut per_vertex: Vec<Vec<u32>> = vec![Vec::new(); n];
        let mut spring_triangles = vec![[u32::MAX; 4]; s];
        for (ti, (tri, edges)) in cloth
            .triangles
            .iter()
            .zip(&cloth.triangle_springs)
            .enumerate()
        {
            for corner in 0..3 {
                per_vertex[tri[corner] as usize].push(3 * ti as u32 + corner as u32);
                let slot = &mut spring_triangles[edges[corner] as usize];
                let side = if slot[0] == u32::MAX { 0 } else { 2 };
                slot[side] = ti as u32;
                slot[side + 1] = corner as u32;
            }
        }
        let mut vertex_triangle_offsets = vec![0u32];
        let mut vertex_triangles = Vec::new();
        for list in per_vertex {
            vertex_triangles.extend(list);
            vertex_triangle_offsets.push(vertex_triangles.len() as u32);
        }

        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let init = |label: &str, contents: &[u8], extra: wgpu::BufferUsages| {
            // Empty arrays (no rigid body) still need a bindable buffer of
            // at least one element of the largest struct (Contact, 64 B).
            let padded;
            let contents = if contents.is_empty() {
                padded = [0u8; 64];
                &padded[..]
            } else {
                contents
            };
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: usage | extra,
            })
        };
        let storage =
            |label: &str, contents: &[u8]| init(label, contents, wgpu::BufferUsages::empty());
        let zeroed = |label: &str, bytes: usize| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(64) as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        let vec4 = size_of::<[f32; 4]>();
        let pinned: Vec<u32> = cloth.pinned.iter().map(|&p| p as u32).collect();
        let flat_triangles: Vec<u32> = cloth.triangles.iter().flatten().copied().collect();
        let partial_count = groups(n as u32) as usize;
        let tiles = (params.tiles_x * params.tiles_y) as usize;
        let supertiles = (params.supertiles_x * params.supertiles_y) as usize;

        let body = scene.rigid.as_ref();
        let r = body.map_or(0, |b| b.mesh.vertices.len());
        let body_vertices = body.map_or(vec![], |b| vec4s(&b.mesh.vertices, 1.0));
        let body_normals = body.map_or(vec![], |b| vec4s(&b.vertex_normals, 0.0));
        let body_triangles: Vec<u32> = body.map_or(vec![], |b| {
            b.mesh.triangles.iter().flatten().copied().collect()
        });
        let body_face_normals = body.map_or(vec![], |b| vec4s(&b.face_normals, 0.0));
        let bvh_nodes: Vec<BvhNode> = body.map_or(vec![], |b| {
            b.bvh
                .nodes
                .iter()
                .map(|n| BvhNode {
                    lo: n.bounds.min.to_array(),
                    first: n.first,
                    hi: n.bounds.max.to_array(),
                    count: n.count,
                })
                .collect()
        });
        let bvh_order = body.map_or(vec![], |b| b.bvh.order.clone());
        // A network batch holds every contact slot, at most.
        let batch = scene
            .network
            .as_ref()
            .map_or(0, |net| (n + r) * net.kind.evaluations());
        Buffers {
            params: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("params"),
                contents: bytemuck::bytes_of(params),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            }),
            x: init(
                "positions",
                bytemuck::cast_slice(&vec4s(&cloth.rest_positions, 1.0)),
                wgpu::BufferUsages::VERTEX,
            ),
            v: zeroed("velocities", n * vec4),
            x_kept: zeroed("kept positions", n * vec4),
            v_kept: zeroed("kept velocities", n * vec4),
            rest: storage(
                "rest positions",
                bytemuck::cast_slice(&vec4s(&cloth.rest_positions, 1.0)),
            ),
            pinned: storage("pinned", bytemuck::cast_slice(&pinned)),
            springs: storage("springs", bytemuck::cast_slice(&cloth.springs)),
            rest_lengths: storage("rest lengths", bytemuck::cast_slice(&cloth.rest_lengths)),
            adj_offsets: storage(
                "adjacency offsets",
                bytemuck::cast_slice(&cloth.adjacency.offsets),
            ),
            adj_spring: storage(
                "adjacency springs",
                bytemuck::cast_slice(&cloth.adjacency.spring),
            ),
            adj_other: storage(
                "adjacency vertices",
                bytemuck::cast_slice(&cloth.adjacency.other),
            ),
            triangles: init(
                "triangles",
                bytemuck::cast_slice(&flat_triangles),
                wgpu::BufferUsages::INDEX,
            ),
            vertex_triangle_offsets: storage(
                "vertex triangle offsets",
                bytemuck::cast_slice(&vertex_triangle_offsets),
            ),
            vertex_triangles: storage("vertex triangles", bytemuck::cast_slice(&vertex_triangles)),
            spring_triangles: storage("spring triangles", bytemuck::cast_slice(&spring_triangles)),
            spring_force: zeroed("spring forces", s * vec4),
            spring_block: zeroed("spring blocks", s * size_of::<Sym3>()),
            vf_contacts: zeroed("vertex-face contacts", n * size_of::<Contact>()),
            vf_responses: zeroed("vertex-face responses", n * size_of::<Response>()),
            fv_contacts: zeroed("face-vertex contacts", r * size_of::<Contact>()),
            fv_responses: zeroed("face-vertex responses", r * size_of::<Response>()),
            triangle_contact_count: zeroed("triangle contact counts", t * 4),
            triangle_contacts: zeroed("triangle contacts", t * MAX_TRIANGLE_CONTACTS * 4),
            a_diag: zeroed("A diagonal", n * size_of::<Sym3>()),
            a_off: zeroed("A off-diagonal", s * size_of::<Sym3>()),
            b: zeroed("b", n * vec4),
            r: zeroed("r", n * vec4),
            z: zeroed("z", n * vec4),
            p: zeroed("p", n * vec4),
            q: zeroed("q", n * vec4),
            inv_diag: zeroed("inverse diagonal", n * vec4),
            partials: zeroed("partial sums", 3 * partial_count * 4),
            scalars: [
                zeroed("pcg scalars 0", size_of::<Scalars>()),
                zeroed("pcg scalars 1", size_of::<Scalars>()),
            ],
            state: zeroed("step state", size_of::<StepState>()),
            body_vertices: storage("body vertices", bytemuck::cast_slice(&body_vertices)),
            body_normals: storage("body vertex normals", bytemuck::cast_slice(&body_normals)),
            body_triangles: storage("body triangles", bytemuck::cast_slice(&body_triangles)),
            body_face_normals: storage(
                "body face normals",
                bytemuck::cast_slice(&body_face_normals),
            ),
            bvh_nodes: storage("body BVH nodes", bytemuck::cast_slice(&bvh_nodes)),
            bvh_order: storage("body BVH order", bytemuck::cast_slice(&bvh_order)),
            rigid_vertices: zeroed("rigid vertices", r * vec4),
            rigid_normals: zeroed("rigid normals", r * vec4),
            frame: zeroed("rigid frame", size_of::<RigidFrame>()),
            tile_bounds: zeroed("tile bounds", tiles * 2 * vec4),
            supertile_bounds: zeroed("super-tile bounds", supertiles * 2 * vec4),
            net_count: zeroed("network batch size", 4),
            net_list: zeroed("network batch contacts", batch * 4),
            net_inputs: zeroed("network inputs", batch * params.net_width as usize * 4),
            net_outputs: zeroed(
                "network outputs",
                batch * (params.net_rows * params.net_outputs) as usize * 4,
            ),
            lines: zeroed("force lines", 2 * (n + r) * vec4),
            line_scale: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("force line scale"),
                contents: bytemuck::cast_slice(&[metres_per_force(scene), 0.0, 0.0, 0.0]),
                usage: wgpu::BufferUsages::UNIFORM,
            }),
        }
    }
}

impl BindGroups {
    fn new(kernels: &Kernels, device: &wgpu::Device, bf: &Buffers) -> BindGroups {
        let pcg_group = |[sin, sout]: [&wgpu::Buffer; 2]| {
            kernels.bind(
                device,
                "pcg",
                &[
                    ("params", &bf.params),
                    ("a_diag", &bf.a_diag),
                    ("a_off", &bf.a_off),
                    ("adj_offsets", &bf.adj_offsets),
                    ("adj_spring", &bf.adj_spring),
                    ("adj_other", &bf.adj_other),
                    ("pinned", &bf.pinned),
                    ("b", &bf.b),
                    ("x", &bf.v),
                    ("r", &bf.r),
                    ("z", &bf.z),
                    ("p", &bf.p),
                    ("q", &bf.q),
                    ("inv_diag", &bf.inv_diag),
                    ("partials", &bf.partials),
                    ("scalars_in", sin),
                    ("scalars_out", sout),
                    ("state", &bf.state),
                ],
            )
        };
        BindGroups {
            rigid: kernels.bind(
                device,
                "rigid",
                &[
                    ("params", &bf.params),
                    ("body_vertices", &bf.body_vertices),
                    ("body_normals", &bf.body_normals),
                    ("rigid_vertices", &bf.rigid_vertices),
                    ("rigid_normals", &bf.rigid_normals),
                    ("frame", &bf.frame),
                    ("state", &bf.state),
                ],
            ),
            collide: kernels.bind(
                device,
                "collide",
                &[
                    ("params", &bf.params),
                    ("x", &bf.x),
                    ("triangles", &bf.triangles),
                    ("body_vertices", &bf.body_vertices),
                    ("body_triangles", &bf.body_triangles),
                    ("body_face_normals", &bf.body_face_normals),
                    ("bvh_nodes", &bf.bvh_nodes),
                    ("bvh_order", &bf.bvh_order),
                    ("rigid_vertices", &bf.rigid_vertices),
                    ("rigid_normals", &bf.rigid_normals),
                    ("frame", &bf.frame),
                    ("tile_bounds", &bf.tile_bounds),
                    ("supertile_bounds", &bf.supertile_bounds),
                    ("vf_contacts", &bf.vf_contacts),
                    ("fv_contacts", &bf.fv_contacts),
                    ("triangle_contact_count", &bf.triangle_contact_count),
                    ("triangle_contacts", &bf.triangle_contacts),
                    ("state", &bf.state),
                ],
            ),
            contact: kernels.bind(
                device,
                "contact",
                &[
                    ("params", &bf.params),
                    ("v", &bf.v),
                    ("vf_contacts", &bf.vf_contacts),
                    ("fv_contacts", &bf.fv_contacts),
                    ("vf_responses", &bf.vf_responses),
                    ("fv_responses", &bf.fv_responses),
                    ("x", &bf.x),
                    ("triangles", &bf.triangles),
                    ("rigid_vertices", &bf.rigid_vertices),
                    ("body_triangles", &bf.body_triangles),
                    ("net_count", &bf.net_count),
                    ("net_list", &bf.net_list),
                    ("net_inputs", &bf.net_inputs),
                    ("net_outputs", &bf.net_outputs),
                ],
            ),
            measure: kernels.bind(
                device,
                "measure",
                &[
                    ("params", &bf.params),
                    ("x", &bf.x),
                    ("body_vertices", &bf.body_vertices),
                    ("body_triangles", &bf.body_triangles),
                    ("body_face_normals", &bf.body_face_normals),
                    ("bvh_nodes", &bf.bvh_nodes),
                    ("bvh_order", &bf.bvh_order),
                    ("frame", &bf.frame),
                    ("state", &bf.state),
                ],
            ),
            springs: kernels.bind(
                device,
                "springs",
                &[
                    ("params", &bf.params),
                    ("x", &bf.x),
                    ("springs", &bf.springs),
                    ("rest_lengths", &bf.rest_lengths),
                    ("spring_force", &bf.spring_force),
                    ("spring_block", &bf.spring_block),
                ],
            ),
            assemble: kernels.bind(
                device,
                "assemble",
                &[
                    ("params", &bf.params),
                    ("v", &bf.v),
                    ("springs", &bf.springs),
                    ("spring_force", &bf.spring_force),
                    ("spring_block", &bf.spring_block),
                    ("adj_offsets", &bf.adj_offsets),
                    ("adj_spring", &bf.adj_spring),
                    ("vertex_triangle_offsets", &bf.vertex_triangle_offsets),
                    ("vertex_triangles", &bf.vertex_triangles),
                    ("spring_triangles", &bf.spring_triangles),
                    ("vf_contacts", &bf.vf_contacts),
                    ("vf_responses", &bf.vf_responses),
                    ("fv_contacts", &bf.fv_contacts),
                    ("fv_responses", &bf.fv_responses),
                    ("triangle_contact_count", &bf.triangle_contact_count),
                    ("triangle_contacts", &bf.triangle_contacts),
                    ("a_diag", &bf.a_diag),
                    ("a_off", &bf.a_off),
                    ("b", &bf.b),
                ],
            ),
            pcg: [
                pcg_group([&bf.scalars[0], &bf.scalars[1]]),
                pcg_group([&bf.scalars[1], &bf.scalars[0]]),
            ],
            integrate: kernels.bind(
                device,
                "integrate",
                &[
                    ("params", &bf.params),
                    ("x", &bf.x),
                    ("v", &bf.v),
                    ("rest_positions", &bf.rest),
                    ("pinned", &bf.pinned),
                    ("state", &bf.state),
                ],
            ),
            lines: kernels.bind(
                device,
                "lines",
                &[
                    ("params", &bf.params),
                    ("x", &bf.x),
                    ("rigid_vertices", &bf.rigid_vertices),
                    ("vf_contacts", &bf.vf_contacts),
                    ("fv_contacts", &bf.fv_contacts),
                    ("vf_responses", &bf.vf_responses),
                    ("fv_responses", &bf.fv_responses),
                    ("line_scale", &bf.line_scale),
                    ("lines", &bf.lines),
                ],
            ),
        }
    }
}

impl GpuSim {
    /// Uploads `scene` onto the app's device. Fails with a clear error when
    /// the scene exceeds the device's limits.
    pub fn new(
        kernels: Arc<Kernels>,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
    ) -> Result<GpuSim> {
        let cloth = &scene.cloth;
        check_limits(
            device,
            cloth.vertex_count(),
            cloth.springs.len(),
            cloth.triangles.len(),
        )?;
        let params = params_for(scene);
        let buffers = Buffers::new(device, scene, &params);
        let groups = BindGroups::new(&kernels, device, &buffers);
        let network = match &scene.network {
            Some(net) if params.has_rigid != 0 => {
                let slots = (params.n_vertices + params.n_rigid_vertices) as usize;
                let (capacity, wrt) = (slots * net.kind.evaluations(), net.kind.wrt());
                debug_assert!(buffers.net_outputs.size() >= output_bytes(&net.mlp, capacity, &wrt));
                Some(GpuMlp::new(
                    kernels.clone(),
                    device,
                    &net.mlp,
                    wrt,
                    BatchShape::new(capacity),
                    BatchBuffers {
                        inputs: &buffers.net_inputs,
                        count: &buffers.net_count,
                        outputs: &buffers.net_outputs,
                    },
                )?)
            }
            _ => None,
        };
        let timer = device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
            .then(|| Timer {
                queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("stage timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * Stage::ALL.len() as u32,
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamps"),
                    size: (16 * Stage::ALL.len()) as u64,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                period_ns: queue.get_timestamp_period(),
            });
        Ok(GpuSim {
            kernels,
            device: device.clone(),
            queue: queue.clone(),
            params,
            buffers,
            groups,
            timer,
            network,
        })
    }

    /// Records stage "lines": the last step's contact forces as segments
    /// in [`GpuSim::force_lines`], `render::metres_per_force` long per unit
    /// of force.
    pub fn record_force_lines(&self, encoder: &mut wgpu::CommandEncoder) {
        let p = &self.params;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("lines"),
            timestamp_writes: None,
        });
        let mut count = 0;
        let slots = p.n_vertices + p.n_rigid_vertices;
        self.dispatch(
            &mut pass,
            ("lines", "force_lines"),
            &self.groups.lines,
            slots,
            &mut count,
        );
    }

    /// Force segments, two vec4s per contact slot (w = 0: no contact):
    /// vertex–face slots, then face–vertex ones.
    pub fn force_lines(&self) -> &wgpu::Buffer {
        &self.buffers.lines
    }

    /// The rigid body's vertices placed at the current time (vec4 each) and
    /// its triangles (three u32 each).
    pub fn body(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.buffers.rigid_vertices, &self.buffers.body_triangles)
    }

    /// Cloth positions, one `vec4<f32>` (w = 1) per vertex: a vertex buffer.
    pub fn positions(&self) -> &wgpu::Buffer {
        &self.buffers.x
    }

    /// Cloth triangles as `u32` indices into [`Self::positions`].
    pub fn indices(&self) -> &wgpu::Buffer {
        &self.buffers.triangles
    }

    /// The kernel running a network model's network.
    pub fn network_kernel(&self) -> Option<NetworkKernel> {
        self.network.as_ref().map(GpuMlp::kernel)
    }

    pub fn index_count(&self) -> u32 {
        3 * self.params.n_triangles
    }

    fn pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        stage: Stage,
    ) -> wgpu::ComputePass<'e> {
        let k = stage.index();
        encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(stage.name()),
            timestamp_writes: self
                .timer
                .as_ref()
                .map(|t| wgpu::ComputePassTimestampWrites {
                    query_set: &t.queries,
                    beginning_of_pass_write_index: Some(2 * k as u32),
                    end_of_pass_write_index: Some(2 * k as u32 + 1),
                }),
        })
    }

    fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass,
        (stage, entry): (&str, &str),
        group: &wgpu::BindGroup,
        threads: u32,
        count: &mut u32,
    ) {
        pass.set_pipeline(self.kernels.pipeline(stage, entry));
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(groups(threads), 1, 1);
        *count += 1;
    }

    /// The passes a step records: the rigid-body ones only with a body.
    fn active_passes(&self) -> impl Iterator<Item = Stage> + '_ {
        Stage::ALL
            .into_iter()
            .filter(move |stage| self.params.has_rigid != 0 || !stage.needs_body())
    }

    /// Records one backward Euler step into `encoder`; nothing is read
    /// back. Returns the number of dispatches recorded.
    pub fn record_step(&self, encoder: &mut wgpu::CommandEncoder) -> u32 {
        let count = self
            .active_passes()
            .map(|stage| self.record_stage(encoder, stage))
            .sum();
        if let Some(t) = &self.timer {
            let queries = 2 * Stage::ALL.len() as u32;
            encoder.resolve_query_set(&t.queries, 0..queries, &t.resolve, 0);
        }
        count
    }

    /// Records one stage's pass on what the earlier passes left (the
    /// per-stage benches time them one by one); a rigid-body stage records
    /// nothing without a body. Returns the number of dispatches recorded.
    pub fn record_stage(&self, encoder: &mut wgpu::CommandEncoder, stage: Stage) -> u32 {
        let p = &self.params;
        if p.has_rigid == 0 && stage.needs_body() {
            return 0;
        }
        let (n, s, r) = (p.n_vertices, p.n_springs, p.n_rigid_vertices);
        let g = &self.groups;
        let mut count = 0;
        if stage == Stage::Collide {
            // Face–vertex contacts append to their triangle's list.
            encoder.clear_buffer(&self.buffers.triangle_contact_count, 0, None);
        }
        let mut pass = self.pass(encoder, stage);
        let mut run = |entry: (&str, &str), group: &wgpu::BindGroup, threads: u32| {
            self.dispatch(&mut pass, entry, group, threads, &mut count)
        };
        match stage {
            Stage::Rigid => run(("rigid", "main"), &g.rigid, r.max(1)),
            Stage::Collide => {
                run(("collide", "tiles"), &g.collide, p.tiles_x * p.tiles_y);
                run(
                    ("collide", "supertiles"),
                    &g.collide,
                    p.supertiles_x * p.supertiles_y,
                );
                run(("collide", "vertex_face"), &g.collide, n);
                run(("collide", "face_vertex"), &g.collide, r);
            }
            Stage::Contact => match &self.network {
                None => {
                    run(("contact", "vertex_face"), &g.contact, n);
                    run(("contact", "face_vertex"), &g.contact, r);
                }
                Some(net) => {
                    run(("contact", "reset_batch"), &g.contact, 1);
                    run(("contact", "gather"), &g.contact, n + r);
                    count += net.record(&mut pass);
                    let (args, offset) = net.per_contact_dispatch();
                    pass.set_pipeline(self.kernels.pipeline("contact", "respond_batch"));
                    pass.set_bind_group(0, &g.contact, &[]);
                    pass.dispatch_workgroups_indirect(args, offset);
                    count += 1;
                }
            },
            Stage::Springs => run(("springs", "main"), &g.springs, s),
            Stage::Assemble => {
                run(("assemble", "vertex"), &g.assemble, n);
                run(("assemble", "spring"), &g.assemble, s);
            }
            Stage::Pcg => {
                run(("pcg", "init"), &g.pcg[0], n);
                // Writes scalars[0], which iteration 0 reads.
                run(("pcg", "init_scalars"), &g.pcg[1], 1);
                let iters = p.cg_max_iters as usize;
                for it in 0..iters {
                    let group = &g.pcg[it % 2];
                    run(("pcg", "spmv"), group, n);
                    run(("pcg", "update"), group, n);
                    run(("pcg", "direction"), group, n);
                }
                // The last iteration wrote scalars[iters % 2].
                run(("pcg", "finish"), &g.pcg[iters % 2], 1);
            }
            Stage::Integrate => run(("integrate", "main"), &g.integrate, n),
            Stage::Measure => run(("measure", "main"), &g.measure, n),
        }
        count
    }

    /// Replaces the cloth state (e.g. with a CPU state, to compare a stage).
    pub fn upload_state(&self, x: &[Vec3], v: &[Vec3], time: f32) {
        self.queue
            .write_buffer(&self.buffers.x, 0, bytemuck::cast_slice(&vec4s(x, 1.0)));
        self.queue
            .write_buffer(&self.buffers.v, 0, bytemuck::cast_slice(&vec4s(v, 0.0)));
        self.queue
            .write_buffer(&self.buffers.state, 0, bytemuck::bytes_of(&time));
        // A new state starts healthy.
        let health = std::mem::offset_of!(StepState, health) as u64;
        self.queue
            .write_buffer(&self.buffers.state, health, bytemuck::bytes_of(&0u32));
    }

    /// Records a copy of the positions and velocities: the last good state
    /// to return to when the next step diverges ([`GpuSim::read_kept`]).
    pub fn record_checkpoint(&self, encoder: &mut wgpu::CommandEncoder) {
        let b = &self.buffers;
        encoder.copy_buffer_to_buffer(&b.x, 0, &b.x_kept, 0, b.x.size());
        encoder.copy_buffer_to_buffer(&b.v, 0, &b.v_kept, 0, b.v.size());
    }

    /// The positions and velocities of the last checkpoint.
    pub fn read_kept(&self) -> Result<(Vec<Vec3>, Vec<Vec3>)> {
        Ok((
            self.read_vec3(&self.buffers.x_kept)?,
            self.read_vec3(&self.buffers.v_kept)?,
        ))
    }

    /// Records and submits one step; returns its dispatch count.
    pub fn step(&self) -> u32 {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let count = self.record_step(&mut encoder);
        self.queue.submit([encoder.finish()]);
        count
    }

    fn read<T: Pod>(&self, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
        read_buffer(&self.device, &self.queue, buffer)
    }

    fn read_vec3(&self, buffer: &wgpu::Buffer) -> Result<Vec<Vec3>> {
        let raw: Vec<[f32; 4]> = self.read(buffer)?;
        Ok(raw[..self.params.n_vertices as usize]
            .iter()
            .map(|p| Vec3::from_slice(&p[..3]))
            .collect())
    }

    pub fn read_positions(&self) -> Result<Vec<Vec3>> {
        self.read_vec3(&self.buffers.x)
    }

    pub fn read_velocities(&self) -> Result<Vec<Vec3>> {
        self.read_vec3(&self.buffers.v)
    }

    pub fn read_state(&self) -> Result<StepState> {
        Ok(self.read::<StepState>(&self.buffers.state)?[0])
    }

    /// The assembled system of the last step: A's diagonal and per-spring
    /// blocks, and b.
    pub fn read_system(&self) -> Result<(Vec<Sym3>, Vec<Sym3>, Vec<Vec3>)> {
        let b = self.read_vec3(&self.buffers.b)?;
        Ok((
            self.read(&self.buffers.a_diag)?,
            self.read(&self.buffers.a_off)?,
            b,
        ))
    }

    /// The last step's contact slots and responses: vertex–face (one per
    /// cloth vertex), then face–vertex (one per rigid vertex); `valid`
    /// marks the slots in use.
    pub fn read_contacts(&self) -> Result<(Vec<ContactSlot>, Vec<ContactSlot>)> {
        let b = &self.buffers;
        let zip = |c: Vec<Contact>, r: Vec<Response>, len: u32| -> Vec<ContactSlot> {
            c.into_iter().zip(r).take(len as usize).collect()
        };
        Ok((
            zip(
                self.read(&b.vf_contacts)?,
                self.read(&b.vf_responses)?,
                self.params.n_vertices,
            ),
            zip(
                self.read(&b.fv_contacts)?,
                self.read(&b.fv_responses)?,
                self.params.n_rigid_vertices,
            ),
        ))
    }

    /// Spring forces and blocks of the last step.
    pub fn read_springs(&self) -> Result<(Vec<Vec3>, Vec<Sym3>)> {
        let f: Vec<[f32; 4]> = self.read(&self.buffers.spring_force)?;
        let f = f.iter().map(|p| Vec3::from_slice(&p[..3])).collect();
        Ok((f, self.read(&self.buffers.spring_block)?))
    }

    /// Milliseconds of each pass of the last recorded step, when the
    /// adapter has timestamp queries.
    pub fn read_stage_ms(&self) -> Result<Option<Vec<(&'static str, f64)>>> {
        let Some(t) = &self.timer else {
            return Ok(None);
        };
        let ticks: Vec<u64> = self.read(&t.resolve)?;
        Ok(Some(
            self.active_passes()
                .map(|stage| {
                    let k = stage.index();
                    let dt = ticks[2 * k + 1].saturating_sub(ticks[2 * k]);
                    (stage.name(), dt as f64 * t.period_ns as f64 * 1e-6)
                })
                .collect(),
        ))
    }
}

/// Refuses scenes whose buffers or dispatches exceed the device's limits.
fn check_limits(device: &wgpu::Device, n: usize, s: usize, t: usize) -> Result<()> {
    let limits = device.limits();
    let biggest = [
        ("spring blocks", s * size_of::<Sym3>()),
        ("A off-diagonal", s * size_of::<Sym3>()),
        ("A diagonal", n * size_of::<Sym3>()),
        ("triangle indices", t * 12),
    ];
    for (what, bytes) in biggest {
        let bindable = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if bytes as u64 > bindable {
            return Err(Error::Gpu(format!(
                "the scene's {what} need {bytes} bytes, more than this adapter binds ({bindable} bytes); use a smaller --grid"
            )));
        }
    }
    let most = n.max(s) as u64;
    let dispatchable = limits.max_compute_workgroups_per_dimension as u64 * WORKGROUP as u64;
    if most > dispatchable {
        return Err(Error::Gpu(format!(
            "the scene has {most} springs or vertices, more than one dispatch covers here ({dispatchable}); use a smaller --grid"
        )));
    }
    Ok(())
}
