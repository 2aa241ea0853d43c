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
use crate::gpu::kernels::Kernels;
use crate::gpu::layout::{Contact, Params, Response, Scalars, StepState, Sym3};
use crate::scene::Scene;

const WORKGROUP: u32 = 256;

/// Timed passes, in recording order (`stage_ms` uses these names).
pub const PASSES: [&str; 4] = ["springs", "assemble", "pcg", "integrate"];

struct Buffers {
    params: wgpu::Buffer,
    x: wgpu::Buffer,
    v: wgpu::Buffer,
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
}

struct BindGroups {
    springs: wgpu::BindGroup,
    assemble: wgpu::BindGroup,
    /// [0]: scalars in = 0, out = 1; [1]: the reverse.
    pcg: [wgpu::BindGroup; 2],
    integrate: wgpu::BindGroup,
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
}

fn groups(n: u32) -> u32 {
    n.div_ceil(WORKGROUP)
}

fn vec4s(points: &[Vec3], w: f32) -> Vec<[f32; 4]> {
    points.iter().map(|p| p.extend(w).to_array()).collect()
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
        let cfg = &scene.config;
        let n = cloth.vertex_count();
        let s = cloth.springs.len();
        let t = cloth.triangles.len();
        check_limits(device, n, s, t)?;

        let params = Params {
            n_vertices: n as u32,
            n_springs: s as u32,
            n_triangles: t as u32,
            model: match cfg.model {
                ModelKind::Naive => 0,
                ModelKind::Friction => 1,
            },
            has_rigid: 0,
            cg_max_iters: cfg.solver.cg_iters,
            dt: cfg.solver.dt,
            vertex_mass: cloth.vertex_mass,
            stiffness: cloth.stiffness,
            cg_tol: cfg.solver.cg_tol,
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
            ..Default::default()
        };

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

        let storage = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
            })
        };
        let zeroed = |label: &str, bytes: usize| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(16) as u64,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let vec4 = size_of::<[f32; 4]>();
        let pinned: Vec<u32> = cloth.pinned.iter().map(|&p| p as u32).collect();
        let flat_triangles: Vec<u32> = cloth.triangles.iter().flatten().copied().collect();
        let partial_count = groups(n as u32) as usize;
        let buffers = Buffers {
            params: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            }),
            x: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("positions"),
                contents: bytemuck::cast_slice(&vec4s(&cloth.rest_positions, 1.0)),
                usage: wgpu::BufferUsages::VERTEX
                    | wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
            }),
            v: zeroed("velocities", n * vec4),
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
            triangles: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("triangles"),
                contents: bytemuck::cast_slice(&flat_triangles),
                usage: wgpu::BufferUsages::INDEX
                    | wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC,
            }),
            vertex_triangle_offsets: storage(
                "vertex triangle offsets",
                bytemuck::cast_slice(&vertex_triangle_offsets),
            ),
            vertex_triangles: storage("vertex triangles", bytemuck::cast_slice(&vertex_triangles)),
            spring_triangles: storage("spring triangles", bytemuck::cast_slice(&spring_triangles)),
            spring_force: zeroed("spring forces", s * vec4),
            spring_block: zeroed("spring blocks", s * size_of::<Sym3>()),
            vf_contacts: zeroed("vertex-face contacts", size_of::<Contact>()),
            vf_responses: zeroed("vertex-face responses", size_of::<Response>()),
            fv_contacts: zeroed("face-vertex contacts", size_of::<Contact>()),
            fv_responses: zeroed("face-vertex responses", size_of::<Response>()),
            triangle_contact_count: zeroed("triangle contact counts", 4),
            triangle_contacts: zeroed("triangle contacts", 4),
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
        };
        // Contact buffers stay 1-element dummies until the rigid-body stages
        // run; `has_rigid = 0` keeps the gathers off them.
        let bf = &buffers;
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
        let groups = BindGroups {
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
        };
        let timer = device
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY)
            .then(|| Timer {
                queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("stage timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * PASSES.len() as u32,
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamps"),
                    size: (16 * PASSES.len()) as u64,
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
        })
    }

    /// Cloth positions, one `vec4<f32>` (w = 1) per vertex: a vertex buffer.
    pub fn positions(&self) -> &wgpu::Buffer {
        &self.buffers.x
    }

    /// Cloth triangles as `u32` indices into [`Self::positions`].
    pub fn indices(&self) -> &wgpu::Buffer {
        &self.buffers.triangles
    }

    pub fn index_count(&self) -> u32 {
        3 * self.params.n_triangles
    }

    fn pass<'e>(&self, encoder: &'e mut wgpu::CommandEncoder, k: usize) -> wgpu::ComputePass<'e> {
        encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(PASSES[k]),
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
        stage: &str,
        entry: &str,
        group: &wgpu::BindGroup,
        threads: u32,
    ) {
        pass.set_pipeline(self.kernels.pipeline(stage, entry));
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(groups(threads), 1, 1);
    }

    /// Records one backward Euler step into `encoder`; nothing is read back.
    pub fn record_step(&self, encoder: &mut wgpu::CommandEncoder) {
        let (n, s) = (self.params.n_vertices, self.params.n_springs);
        let g = &self.groups;
        {
            let mut pass = self.pass(encoder, 0);
            self.dispatch(&mut pass, "springs", "main", &g.springs, s);
        }
        {
            let mut pass = self.pass(encoder, 1);
            self.dispatch(&mut pass, "assemble", "vertex", &g.assemble, n);
            self.dispatch(&mut pass, "assemble", "spring", &g.assemble, s);
        }
        {
            let mut pass = self.pass(encoder, 2);
            self.dispatch(&mut pass, "pcg", "init", &g.pcg[0], n);
            // Writes scalars[0], which iteration 0 reads.
            self.dispatch(&mut pass, "pcg", "init_scalars", &g.pcg[1], 1);
            let iters = self.params.cg_max_iters as usize;
            for it in 0..iters {
                let group = &g.pcg[it % 2];
                self.dispatch(&mut pass, "pcg", "spmv", group, n);
                self.dispatch(&mut pass, "pcg", "update", group, n);
                self.dispatch(&mut pass, "pcg", "direction", group, n);
            }
            // The last iteration wrote scalars[iters % 2].
            pass.set_pipeline(self.kernels.pipeline("pcg", "finish"));
            pass.set_bind_group(0, &g.pcg[iters % 2], &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        {
            let mut pass = self.pass(encoder, 3);
            self.dispatch(&mut pass, "integrate", "main", &g.integrate, n);
        }
        if let Some(t) = &self.timer {
            encoder.resolve_query_set(&t.queries, 0..2 * PASSES.len() as u32, &t.resolve, 0);
        }
    }

    /// Replaces the cloth state (e.g. with a CPU state, to compare a stage).
    pub fn upload_state(&self, x: &[Vec3], v: &[Vec3], time: f32) {
        self.queue
            .write_buffer(&self.buffers.x, 0, bytemuck::cast_slice(&vec4s(x, 1.0)));
        self.queue
            .write_buffer(&self.buffers.v, 0, bytemuck::cast_slice(&vec4s(v, 0.0)));
        self.queue
            .write_buffer(&self.buffers.state, 0, bytemuck::bytes_of(&time));
    }

    /// Records and submits one step.
    pub fn step(&self) {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.record_step(&mut encoder);
        self.queue.submit([encoder.finish()]);
    }

    /// Copies `buffer` back to the host (blocks until the GPU is done).
    fn read<T: Pod>(&self, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
        let size = buffer.size();
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::Gpu(format!("waiting for the device failed: {e}")))?;
        rx.recv()
            .map_err(|_| Error::Gpu("readback never completed".into()))?
            .map_err(|e| Error::Gpu(format!("readback failed: {e}")))?;
        let view = staging
            .get_mapped_range(..)
            .map_err(|e| Error::Gpu(format!("readback failed: {e}")))?;
        Ok(bytemuck::cast_slice(&view).to_vec())
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
            PASSES
                .iter()
                .enumerate()
                .map(|(k, name)| {
                    let dt = ticks[2 * k + 1].saturating_sub(ticks[2 * k]);
                    (*name, dt as f64 * t.period_ns as f64 * 1e-6)
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
