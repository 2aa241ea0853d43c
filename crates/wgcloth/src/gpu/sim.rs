//! One scene's state on the GPU (buffers and bind groups) and the recorded
//! step. This is the embedding API: create it from the app's own device and
//! queue, record steps into the app's command encoder, and draw
//! [`GpuSim::positions`] with [`GpuSim::indices`] directly.

use std::collections::BTreeMap;
use std::sync::Arc;

use bytemuck::Pod;
use glam::Vec3;
use wgpu::util::DeviceExt;

use crate::config::ModelKind;
use crate::error::{Error, Result};
use crate::gpu::constants::{MAX_TRIANGLE_CONTACTS, TILE, WORKGROUP, model};
use crate::gpu::context::read_buffer;
use crate::gpu::kernels::Kernels;
use crate::gpu::layout::{
    self, BvhNode, Contact, Params, Response, RigidFrame, Scalars, Sections, SpringTerm, StepState,
    Sym3,
};
use crate::gpu::mlp::{BatchBuffers, BatchShape, GpuMlp, NetworkKernel, output_bytes};
use crate::nn::weights::NetKind;
use crate::render::metres_per_force;
use crate::scene::{Motion, Scene};
use crate::stage::Stage;

/// A contact slot and its response, as read back.
pub type ContactSlot = (Contact, Response);

/// The scene's buffers. Related arrays share one buffer (slots of both
/// contact directions, A's diagonal and off-diagonal blocks, the placed
/// body's vertices and normals, all static connectivity in `topology`), so
/// no kernel binds more than WebGPU's default 8 storage buffers.
struct Buffers {
    params: wgpu::Buffer,
    x: wgpu::Buffer,
    v: wgpu::Buffer,
    /// Positions and velocities as `record_checkpoint` last copied them.
    x_kept: wgpu::Buffer,
    v_kept: wgpu::Buffer,
    rest: wgpu::Buffer,
    topology: wgpu::Buffer,
    sections: Sections,
    rest_lengths: wgpu::Buffer,
    spring_terms: wgpu::Buffer,
    /// Vertex–face slots (one per cloth vertex), then face–vertex ones
    /// (one per rigid vertex).
    contacts: wgpu::Buffer,
    responses: wgpu::Buffer,
    /// Per cloth triangle its face–vertex contact count, then the lists.
    triangle_contacts: wgpu::Buffer,
    /// A's diagonal blocks, then its off-diagonal ones.
    matrix: wgpu::Buffer,
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
    body_face_normals: wgpu::Buffer,
    bvh_nodes: wgpu::Buffer,
    /// The placed body: its vertices, then their normals.
    rigid: wgpu::Buffer,
    frame: wgpu::Buffer,
    /// Tile bounds, then super-tile bounds.
    bounds: wgpu::Buffer,
    /// The network batch's size, then its contact slots.
    net_batch: wgpu::Buffer,
    net_inputs: wgpu::Buffer,
    net_outputs: wgpu::Buffer,
    /// The renderer's force segments (stage "lines") and their scale.
    lines: wgpu::Buffer,
    line_scale: wgpu::Buffer,
}

/// Every entry point the step records, bound to this scene's buffers.
struct Dispatches {
    kernels: Arc<Kernels>,
    groups: BTreeMap<(&'static str, &'static str), wgpu::BindGroup>,
    /// pcg bind groups with the scalars ping-ponged: [0] reads scalars 0
    /// and writes 1, [1] the reverse.
    pcg: [BTreeMap<&'static str, wgpu::BindGroup>; 2],
}

/// Timestamp queries around each pass, where the adapter has them.
struct Timer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f32,
}

pub struct GpuSim {
    device: wgpu::Device,
    queue: wgpu::Queue,
    params: Params,
    buffers: Buffers,
    dispatches: Dispatches,
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
fn params_for(scene: &Scene, sections: &Sections) -> Params {
    let cloth = &scene.cloth;
    let cfg = &scene.config;
    let (cells_x, cells_y) = (cloth.nx - 1, cloth.ny - 1);
    let (tiles_x, tiles_y) = (cells_x.div_ceil(TILE), cells_y.div_ceil(TILE));
    let mut p = Params {
        n_vertices: cloth.vertex_count() as u32,
        n_springs: cloth.springs.len() as u32,
        n_triangles: cloth.triangles.len() as u32,
        model: match cfg.model {
            ModelKind::Naive => model::NAIVE,
            ModelKind::Friction => model::FRICTION,
            ModelKind::FrictionNet => match scene.network.as_ref().map(|n| n.kind) {
                Some(NetKind::FrictionContact) => model::FRICTION_CONTACT_NET,
                _ => model::FRICTION_NET,
            },
            ModelKind::NaiveNet => model::NAIVE_NET,
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
        springs_at: sections.springs,
        adjacency_at: sections.adjacency,
        pinned_at: sections.pinned,
        vertex_triangles_at: sections.vertex_triangles,
        spring_triangles_at: sections.spring_triangles,
        body_triangles_at: sections.body_triangles,
        bvh_order_at: sections.bvh_order,
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

/// Every buffer's size in bytes, a pure function of the scene (as vello's
/// `RenderConfig`): the limits check and the allocation read the same.
struct Sizes {
    vertices: u64,
    springs: usize,
    slots: usize,
    batch: usize,
}

impl Sizes {
    fn of(scene: &Scene) -> Sizes {
        let cloth = &scene.cloth;
        let r = scene.rigid.as_ref().map_or(0, |b| b.mesh.vertices.len());
        let slots = cloth.vertex_count() + r;
        Sizes {
            vertices: cloth.vertex_count() as u64,
            springs: cloth.springs.len(),
            slots,
            // A network batch holds every contact slot, at most.
            batch: scene
                .network
                .as_ref()
                .map_or(0, |net| slots * net.kind.evaluations()),
        }
    }

    /// The largest buffers a kernel binds whole, by name.
    fn bound(&self, params: &Params, topology_words: usize) -> [(&'static str, u64); 8] {
        let n = self.vertices;
        let batch = self.batch as u64;
        [
            ("topology", 4 * topology_words as u64),
            (
                "spring terms",
                (self.springs * size_of::<SpringTerm>()) as u64,
            ),
            (
                "system matrix",
                (n + self.springs as u64) * size_of::<Sym3>() as u64,
            ),
            ("contacts", (self.slots * size_of::<Contact>()) as u64),
            ("responses", (self.slots * size_of::<Response>()) as u64),
            ("network inputs", batch * params.net_width as u64 * 4),
            (
                "network outputs",
                batch * (params.net_rows * params.net_outputs) as u64 * 4,
            ),
            ("positions", n * 16),
        ]
    }
}

impl Buffers {
    fn new(
        device: &wgpu::Device,
        scene: &Scene,
        params: &Params,
        (topology, sections): (Vec<u32>, Sections),
    ) -> Buffers {
        let cloth = &scene.cloth;
        let (n, s, t) = (
            cloth.vertex_count(),
            cloth.springs.len(),
            cloth.triangles.len(),
        );
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
        let partial_count = groups(n as u32) as usize;
        let tiles = (params.tiles_x * params.tiles_y) as usize;
        let supertiles = (params.supertiles_x * params.supertiles_y) as usize;
        let sizes = Sizes::of(scene);

        let body = scene.rigid.as_ref();
        let r = body.map_or(0, |b| b.mesh.vertices.len());
        let body_vertices = body.map_or(vec![], |b| vec4s(&b.mesh.vertices, 1.0));
        let body_normals = body.map_or(vec![], |b| vec4s(&b.vertex_normals, 0.0));
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
        let batch = sizes.batch;
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
            topology: init(
                "topology",
                bytemuck::cast_slice(&topology),
                wgpu::BufferUsages::INDEX,
            ),
            sections,
            rest_lengths: storage("rest lengths", bytemuck::cast_slice(&cloth.rest_lengths)),
            spring_terms: zeroed("spring terms", s * size_of::<SpringTerm>()),
            contacts: zeroed("contacts", sizes.slots * size_of::<Contact>()),
            responses: zeroed("responses", sizes.slots * size_of::<Response>()),
            triangle_contacts: zeroed(
                "triangle contacts",
                t * (1 + MAX_TRIANGLE_CONTACTS as usize) * 4,
            ),
            matrix: zeroed("system matrix", (n + s) * size_of::<Sym3>()),
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
            body_face_normals: storage(
                "body face normals",
                bytemuck::cast_slice(&body_face_normals),
            ),
            bvh_nodes: storage("body BVH nodes", bytemuck::cast_slice(&bvh_nodes)),
            rigid: init(
                "placed body",
                &vec![0u8; 2 * r * vec4],
                wgpu::BufferUsages::VERTEX,
            ),
            frame: zeroed("rigid frame", size_of::<RigidFrame>()),
            bounds: zeroed("tile bounds", (tiles + supertiles) * 2 * vec4),
            net_batch: zeroed("network batch", (1 + batch) * 4),
            net_inputs: zeroed("network inputs", batch * params.net_width as usize * 4),
            net_outputs: zeroed(
                "network outputs",
                batch * (params.net_rows * params.net_outputs) as usize * 4,
            ),
            lines: zeroed("force lines", 2 * sizes.slots * vec4),
            line_scale: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("force line scale"),
                contents: bytemuck::cast_slice(&[metres_per_force(scene), 0.0, 0.0, 0.0]),
                usage: wgpu::BufferUsages::UNIFORM,
            }),
        }
    }

    /// Each stage's buffers by WGSL variable name; every kernel of the
    /// stage takes the ones it uses.
    fn of_stage(&self, stage: &str) -> Vec<(&'static str, &wgpu::Buffer)> {
        match stage {
            "rigid" => vec![
                ("params", &self.params),
                ("body_vertices", &self.body_vertices),
                ("body_normals", &self.body_normals),
                ("rigid", &self.rigid),
                ("frame", &self.frame),
                ("state", &self.state),
            ],
            "collide" => vec![
                ("params", &self.params),
                ("x", &self.x),
                ("topology", &self.topology),
                ("body_vertices", &self.body_vertices),
                ("body_face_normals", &self.body_face_normals),
                ("bvh_nodes", &self.bvh_nodes),
                ("rigid", &self.rigid),
                ("frame", &self.frame),
                ("bounds", &self.bounds),
                ("contacts", &self.contacts),
                ("triangle_contacts", &self.triangle_contacts),
                ("state", &self.state),
            ],
            "contact" => vec![
                ("params", &self.params),
                ("v", &self.v),
                ("contacts", &self.contacts),
                ("responses", &self.responses),
                ("x", &self.x),
                ("topology", &self.topology),
                ("rigid", &self.rigid),
                ("net_batch", &self.net_batch),
                ("net_inputs", &self.net_inputs),
                ("net_outputs", &self.net_outputs),
            ],
            "measure" => vec![
                ("params", &self.params),
                ("x", &self.x),
                ("topology", &self.topology),
                ("body_vertices", &self.body_vertices),
                ("body_face_normals", &self.body_face_normals),
                ("bvh_nodes", &self.bvh_nodes),
                ("frame", &self.frame),
                ("state", &self.state),
            ],
            "springs" => vec![
                ("params", &self.params),
                ("x", &self.x),
                ("topology", &self.topology),
                ("rest_lengths", &self.rest_lengths),
                ("spring_terms", &self.spring_terms),
            ],
            "assemble" => vec![
                ("params", &self.params),
                ("v", &self.v),
                ("topology", &self.topology),
                ("spring_terms", &self.spring_terms),
                ("contacts", &self.contacts),
                ("responses", &self.responses),
                ("triangle_contacts", &self.triangle_contacts),
                ("matrix", &self.matrix),
                ("b", &self.b),
            ],
            "integrate" => vec![
                ("params", &self.params),
                ("x", &self.x),
                ("v", &self.v),
                ("rest_positions", &self.rest),
                ("topology", &self.topology),
                ("state", &self.state),
            ],
            "lines" => vec![
                ("params", &self.params),
                ("x", &self.x),
                ("rigid", &self.rigid),
                ("contacts", &self.contacts),
                ("responses", &self.responses),
                ("line_scale", &self.line_scale),
                ("lines", &self.lines),
            ],
            _ => unreachable!("stage {stage} binds per iteration"),
        }
    }

    /// The pcg stage's buffers, reading scalars `[k]` and writing `[1 - k]`.
    fn of_pcg(&self, k: usize) -> Vec<(&'static str, &wgpu::Buffer)> {
        vec![
            ("params", &self.params),
            ("matrix", &self.matrix),
            ("topology", &self.topology),
            ("b", &self.b),
            ("x", &self.v),
            ("r", &self.r),
            ("z", &self.z),
            ("p", &self.p),
            ("q", &self.q),
            ("inv_diag", &self.inv_diag),
            ("partials", &self.partials),
            ("scalars_in", &self.scalars[k]),
            ("scalars_out", &self.scalars[1 - k]),
            ("state", &self.state),
        ]
    }
}

/// The entry points each stage records.
const ENTRIES: [(&str, &[&str]); 8] = [
    ("rigid", &["main"]),
    (
        "collide",
        &["tiles", "supertiles", "vertex_face", "face_vertex"],
    ),
    (
        "contact",
        &[
            "vertex_face",
            "face_vertex",
            "reset_batch",
            "gather",
            "respond_batch",
        ],
    ),
    ("springs", &["main"]),
    ("assemble", &["vertex", "spring"]),
    ("integrate", &["main"]),
    ("measure", &["main"]),
    ("lines", &["force_lines"]),
];

const PCG_ENTRIES: [&str; 6] = [
    "init",
    "init_scalars",
    "spmv",
    "update",
    "direction",
    "finish",
];

impl Dispatches {
    fn new(kernels: Arc<Kernels>, device: &wgpu::Device, buffers: &Buffers) -> Dispatches {
        let mut groups = BTreeMap::new();
        for (stage, entries) in ENTRIES {
            let named = buffers.of_stage(stage);
            for &entry in entries {
                let group = kernels.kernel(stage, entry).bind(device, &named);
                groups.insert((stage, entry), group);
            }
        }
        let pcg = [0, 1].map(|k| {
            let named = buffers.of_pcg(k);
            PCG_ENTRIES
                .iter()
                .map(|&entry| (entry, kernels.kernel("pcg", entry).bind(device, &named)))
                .collect()
        });
        Dispatches {
            kernels,
            groups,
            pcg,
        }
    }

    /// Records `stage::entry` over `threads` invocations.
    fn run(&self, pass: &mut wgpu::ComputePass, entry: (&'static str, &'static str), threads: u32) {
        self.bind(pass, entry, 0);
        pass.dispatch_workgroups(groups(threads), 1, 1);
    }

    /// Sets `stage::entry`'s pipeline and bind group (pcg: the one whose
    /// scalars ping-pong to `pcg_side`).
    fn bind(
        &self,
        pass: &mut wgpu::ComputePass,
        (stage, entry): (&'static str, &'static str),
        pcg_side: usize,
    ) {
        pass.set_pipeline(&self.kernels.kernel(stage, entry).pipeline);
        let group = match stage {
            "pcg" => &self.pcg[pcg_side][entry],
            _ => &self.groups[&(stage, entry)],
        };
        pass.set_bind_group(0, group, &[]);
    }
}

impl GpuSim {
    /// Compiles the kernels for `device` and uploads `scene` onto it: the
    /// one call an app needs. Fails with an error naming the limit when the
    /// device cannot run the scene. To run several scenes on one device,
    /// build [`Kernels`] once and use [`GpuSim::with_kernels`].
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, scene: &Scene) -> Result<GpuSim> {
        Self::with_kernels(Arc::new(Kernels::new(device)?), device, queue, scene)
    }

    /// Uploads `scene` onto the app's device with kernels already built for
    /// it. Fails with a clear error when the scene exceeds the device's
    /// limits.
    pub fn with_kernels(
        kernels: Arc<Kernels>,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
    ) -> Result<GpuSim> {
        let (topology, sections) = layout::topology(scene);
        let params = params_for(scene, &sections);
        check_limits(&device.limits(), scene, &params, topology.len())?;
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let sim = Self::create(kernels, device, queue, scene, params, (topology, sections));
        captured(oom, "allocating the scene's buffers")?;
        captured(scope, "creating the scene's GPU state")?;
        sim
    }

    /// Builds everything once the scene is known to fit (errors the device
    /// reports come back through the caller's error scopes).
    fn create(
        kernels: Arc<Kernels>,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        params: Params,
        topology: (Vec<u32>, Sections),
    ) -> Result<GpuSim> {
        let buffers = Buffers::new(device, scene, &params, topology);
        let dispatches = Dispatches::new(kernels.clone(), device, &buffers);
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
                        count: &buffers.net_batch,
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
            device: device.clone(),
            queue: queue.clone(),
            params,
            buffers,
            dispatches,
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
        let slots = p.n_vertices + p.n_rigid_vertices;
        self.dispatches
            .run(&mut pass, ("lines", "force_lines"), slots);
    }

    /// Force segments, two vec4s per contact slot (w = 0: no contact):
    /// vertex–face slots, then face–vertex ones.
    pub fn force_lines(&self) -> &wgpu::Buffer {
        &self.buffers.lines
    }

    /// The rigid body's vertices placed at the current time (the first
    /// `vec4` per vertex of the buffer; their normals follow), and its
    /// triangles (three `u32` indices each).
    pub fn body(&self) -> (&wgpu::Buffer, wgpu::BufferBinding<'_>) {
        let triangles = 3 * self.params.n_rigid_triangles as u64;
        let triangles = wgpu::BufferBinding {
            buffer: &self.buffers.topology,
            offset: 4 * self.buffers.sections.body_triangles as u64,
            size: std::num::NonZeroU64::new(4 * triangles.max(1)),
        };
        (&self.buffers.rigid, triangles)
    }

    /// Cloth positions, one `vec4<f32>` (w = 1) per vertex: a vertex buffer.
    pub fn positions(&self) -> &wgpu::Buffer {
        &self.buffers.x
    }

    /// Cloth triangles as `u32` indices into [`Self::positions`]: an index
    /// buffer whose first [`Self::index_count`] indices are the cloth's
    /// (the simulator's other connectivity follows them).
    pub fn indices(&self) -> &wgpu::Buffer {
        &self.buffers.topology
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

    /// The passes a step records: the rigid-body ones only with a body.
    fn active_passes(&self) -> impl Iterator<Item = Stage> + '_ {
        Stage::ALL
            .into_iter()
            .filter(move |stage| self.params.has_rigid != 0 || !stage.needs_body())
    }

    /// Records one backward Euler step into `encoder`; nothing is read
    /// back. Returns the number of dispatches recorded.
    pub fn encode_step(&self, encoder: &mut wgpu::CommandEncoder) -> u32 {
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
        let d = &self.dispatches;
        let mut count = 0;
        if stage == Stage::Collide {
            // Face–vertex contacts append to their triangle's list: zero
            // the per-triangle counts.
            let counts = 4 * p.n_triangles as u64;
            encoder.clear_buffer(&self.buffers.triangle_contacts, 0, Some(counts));
        }
        let mut pass = self.pass(encoder, stage);
        // `side`: which way the pcg scalars ping-pong (0 elsewhere).
        let mut run = |pass: &mut wgpu::ComputePass, entry, side: usize, threads: u32| {
            d.bind(pass, entry, side);
            pass.dispatch_workgroups(groups(threads), 1, 1);
            count += 1;
        };
        match stage {
            Stage::Rigid => run(&mut pass, ("rigid", "main"), 0, r.max(1)),
            Stage::Collide => {
                run(&mut pass, ("collide", "tiles"), 0, p.tiles_x * p.tiles_y);
                let supertiles = p.supertiles_x * p.supertiles_y;
                run(&mut pass, ("collide", "supertiles"), 0, supertiles);
                run(&mut pass, ("collide", "vertex_face"), 0, n);
                run(&mut pass, ("collide", "face_vertex"), 0, r);
            }
            Stage::Contact => match &self.network {
                None => {
                    run(&mut pass, ("contact", "vertex_face"), 0, n);
                    run(&mut pass, ("contact", "face_vertex"), 0, r);
                }
                Some(net) => {
                    run(&mut pass, ("contact", "reset_batch"), 0, 1);
                    run(&mut pass, ("contact", "gather"), 0, n + r);
                    let recorded = net.record(&mut pass);
                    let (args, offset) = net.per_contact_dispatch();
                    d.bind(&mut pass, ("contact", "respond_batch"), 0);
                    pass.dispatch_workgroups_indirect(args, offset);
                    count += recorded + 1;
                }
            },
            Stage::Springs => run(&mut pass, ("springs", "main"), 0, s),
            Stage::Assemble => {
                run(&mut pass, ("assemble", "vertex"), 0, n);
                run(&mut pass, ("assemble", "spring"), 0, s);
            }
            Stage::Pcg => {
                run(&mut pass, ("pcg", "init"), 0, n);
                // Writes scalars[0], which iteration 0 reads.
                run(&mut pass, ("pcg", "init_scalars"), 1, 1);
                let iters = p.cg_max_iters as usize;
                for it in 0..iters {
                    for entry in ["spmv", "update", "direction"] {
                        run(&mut pass, ("pcg", entry), it % 2, n);
                    }
                }
                // The last iteration wrote scalars[iters % 2].
                run(&mut pass, ("pcg", "finish"), iters % 2, 1);
            }
            Stage::Integrate => run(&mut pass, ("integrate", "main"), 0, n),
            Stage::Measure => run(&mut pass, ("measure", "main"), 0, n),
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
        let count = self.encode_step(&mut encoder);
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
        let mut diagonal: Vec<Sym3> = self.read(&self.buffers.matrix)?;
        let n = self.params.n_vertices as usize;
        let mut off = diagonal.split_off(n);
        off.truncate(self.params.n_springs as usize);
        Ok((diagonal, off, b))
    }

    /// The last step's contact slots and responses: vertex–face (one per
    /// cloth vertex), then face–vertex (one per rigid vertex); `valid`
    /// marks the slots in use.
    pub fn read_contacts(&self) -> Result<(Vec<ContactSlot>, Vec<ContactSlot>)> {
        let contacts: Vec<Contact> = self.read(&self.buffers.contacts)?;
        let responses: Vec<Response> = self.read(&self.buffers.responses)?;
        let (n, r) = (
            self.params.n_vertices as usize,
            self.params.n_rigid_vertices as usize,
        );
        let mut slots = contacts.into_iter().zip(responses);
        let vertex_face = slots.by_ref().take(n).collect();
        Ok((vertex_face, slots.take(r).collect()))
    }

    /// Spring forces and blocks of the last step.
    pub fn read_springs(&self) -> Result<(Vec<Vec3>, Vec<Sym3>)> {
        let terms: Vec<SpringTerm> = self.read(&self.buffers.spring_terms)?;
        Ok(terms
            .iter()
            .take(self.params.n_springs as usize)
            .map(|t| (Vec3::from_slice(&t.force[..3]), t.block))
            .unzip())
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

/// Refuses a scene the device cannot run, naming the limit, what the
/// scene needs and what the device has, before anything is created.
fn check_limits(
    limits: &wgpu::Limits,
    scene: &Scene,
    params: &Params,
    topology: usize,
) -> Result<()> {
    let bindable = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    for (what, bytes) in Sizes::of(scene).bound(params, topology) {
        if bytes > bindable {
            let limit = if bytes > limits.max_buffer_size {
                "max_buffer_size"
            } else {
                "max_storage_buffer_binding_size"
            };
            return Err(Error::Gpu(format!(
                "the scene's {what} need a {bytes}-byte buffer; the device's {limit} is {bindable} bytes (use a smaller --grid)"
            )));
        }
    }
    let most = (params.n_vertices.max(params.n_springs) as u64)
        .max((params.n_vertices + params.n_rigid_vertices) as u64);
    let dispatchable = limits.max_compute_workgroups_per_dimension as u64 * WORKGROUP as u64;
    if most > dispatchable {
        return Err(Error::Gpu(format!(
            "the scene needs {} workgroups in one dispatch; the device's max_compute_workgroups_per_dimension is {} (use a smaller --grid)",
            most.div_ceil(WORKGROUP as u64),
            limits.max_compute_workgroups_per_dimension
        )));
    }
    Ok(())
}

/// The first error `scope` captured, as one line saying what was being done.
fn captured(scope: wgpu::ErrorScopeGuard, doing: &str) -> Result<()> {
    match pollster::block_on(scope.pop()) {
        None => Ok(()),
        Some(e) => Err(Error::Gpu(format!(
            "{doing}: {}",
            crate::gpu::context::one_line(&e.to_string())
        ))),
    }
}
