//! The embedding API: one scene simulated on the app's own device. Create
//! it from the app's device and queue, record steps into the app's command
//! encoder ([`GpuSim::encode_step`]), and draw [`GpuSim::positions`] with
//! [`GpuSim::indices`] directly. It ties the scene's buffers
//! (`gpu::buffers`) to the stages that record the step (`gpu::stages`).

use std::sync::atomic::{AtomicU32, Ordering};

#[cfg(not(target_arch = "wasm32"))]
use bytemuck::Pod;
#[cfg(not(target_arch = "wasm32"))]
use glam::Vec3;

use crate::cpu::State;
use crate::error::{Error, Result};
use crate::gpu::buffers::{
    Batch, Buffers, Sizes, batchable, check_limits, fit_pair_list, params_for, solved_whole, vec4s,
};
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::context::{read_buffer, read_range};
use crate::gpu::kernels::Kernels;
use crate::gpu::layout::{self, Contact, Params, Response, Sections, StepState, WorldParams};
use crate::gpu::mlp::{BatchBuffers, BatchShape, GpuMlp, NetworkKernel, output_bytes};
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Recording, Stages};
use crate::gpu::worlds::{MAX_WORLDS, WORLD_PARAMS_BINDINGS};
use crate::scene::Scene;
use crate::stage::{SelfContactStages, Stage};

/// A contact slot and its response, as read back.
pub type ContactSlot = (Contact, Response);

/// What [`GpuSim::build`] lays out: the topology, the buffers' sizes (all
/// of them, and one world's region) and a batch's own parameters.
struct Laid<'a> {
    topology: (Vec<u32>, Sections),
    sizes: (Sizes, Sizes),
    batch: Option<Batch<'a>>,
}

/// Timestamp queries around each pass, where the adapter has them.
struct Timer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f32,
}

/// One scene's buffers and bound stages on the app's device: records or
/// runs steps and reads their results back.
pub struct GpuSim {
    device: wgpu::Device,
    queue: wgpu::Queue,
    params: Params,
    buffers: Buffers,
    stages: Stages,
    timer: Option<Timer>,
    /// PCG iterations a step records ([`GpuSim::set_cg_budget`]).
    cg_budget: AtomicU32,
    /// Whether each solve runs whole in one dispatch (`solver.whole_solve_nodes`).
    solved_whole: bool,
}

impl GpuSim {
    /// Compiles the kernels for `device` and uploads `scene` onto it: the
    /// one call an app needs. It waits on the device's error scopes, which
    /// resolve at once on native backends. Fails with an error naming the
    /// limit when the device cannot run the scene. To run several scenes
    /// on one device, build [`Kernels`] once and use
    /// [`GpuSim::with_kernels`]. In a browser, where nothing may block,
    /// await [`GpuSim::create`] instead.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, scene: &Scene) -> Result<GpuSim> {
        pollster::block_on(Self::create(device, queue, scene))
    }

    /// Uploads `scene` onto the app's device with kernels already built for
    /// it. Fails with a clear error when the scene exceeds the device's
    /// limits. In a browser, await [`GpuSim::create_with_kernels`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn with_kernels(
        kernels: &Kernels,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
    ) -> Result<GpuSim> {
        pollster::block_on(Self::create_with_kernels(kernels, device, queue, scene))
    }

    /// [`GpuSim::new`] as a future: on the web the device's error scopes
    /// resolve only once the event loop runs.
    pub async fn create(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
    ) -> Result<GpuSim> {
        let kernels = Kernels::create(device).await?;
        Self::create_with_kernels(&kernels, device, queue, scene).await
    }

    /// [`GpuSim::with_kernels`] as a future.
    pub async fn create_with_kernels(
        kernels: &Kernels,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
    ) -> Result<GpuSim> {
        let (topology, sections) = layout::topology(scene);
        let mut params = params_for(scene, &sections);
        fit_pair_list(&device.limits(), &mut params);
        let sizes = Sizes::of(scene, &params, topology.len(), kernels.vectors());
        let kernels =
            match check_limits(&device.limits(), &sizes, &mut params, kernels.splittable())? {
                false => kernels,
                true => kernels.in_parts(device).await?,
            };
        let laid = Laid {
            topology: (topology, sections),
            sizes: (sizes.clone(), sizes),
            batch: None,
        };
        Self::built(kernels, (device, queue), scene, params, laid, "the scene's").await
    }

    /// [`GpuSim::build`] within error scopes, which `what` the errors
    /// they catch name.
    async fn built(
        kernels: &Kernels,
        (device, queue): (&wgpu::Device, &wgpu::Queue),
        scene: &Scene,
        params: Params,
        laid: Laid<'_>,
        what: &str,
    ) -> Result<GpuSim> {
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let sim = Self::build(kernels, device, queue, scene, params, laid);
        captured(oom, &format!("allocating {what} buffers")).await?;
        captured(scope, &format!("creating {what} GPU state")).await?;
        sim
    }

    /// A batch of worlds, one per scene, stepped together: each kernel
    /// covers every world, so a step records the dispatches of one
    /// (`gpu::worlds`). World k ends each step where `scenes[k]` alone
    /// would. The worlds share their cloth's grid, their body's mesh, the
    /// contact model's kind and everything else that sizes a buffer or a
    /// dispatch; each has its own [`WorldParams`] (coefficients, material,
    /// the body's motion, tolerance) and state; the network runs once over
    /// every world's contacts. So far a batch runs the scenes whose step a
    /// single dispatch solves ([`GpuSim::solved_whole`]) and no
    /// self-contact; any other gets an error saying which.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn with_worlds(
        kernels: &Kernels,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scenes: &[Scene],
    ) -> Result<GpuSim> {
        pollster::block_on(Self::create_worlds(kernels, device, queue, scenes))
    }

    /// Whether [`GpuSim::with_worlds`] runs worlds of `scene`, or an error
    /// saying why not.
    pub fn batchable(scene: &Scene) -> Result<()> {
        batchable(scene)
    }

    /// [`GpuSim::with_worlds`] as a future.
    pub async fn create_worlds(
        kernels: &Kernels,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scenes: &[Scene],
    ) -> Result<GpuSim> {
        let Some(scene) = scenes.first() else {
            return Err(Error::config("worlds", "a batch needs at least one world"));
        };
        if scenes.len() > MAX_WORLDS as usize {
            return Err(Error::config(
                "worlds",
                format!(
                    "{} worlds, but a batch holds at most {MAX_WORLDS} (each world's \
                     parameters take {} B of {WORLD_PARAMS_BINDINGS} uniform bindings \
                     of 64 KiB); run the rest in another batch",
                    scenes.len(),
                    size_of::<WorldParams>()
                ),
            ));
        }
        let (topology, sections) = layout::topology(scene);
        let mut params = params_for(scene, &sections);
        fit_pair_list(&device.limits(), &mut params);
        batchable(scene)?;
        let shared = WorldParams::shared(&params);
        let mut each = vec![WorldParams::of(&params)];
        for (k, world) in scenes.iter().enumerate().skip(1) {
            let (its_topology, its_sections) = layout::topology(world);
            let mut its = params_for(world, &its_sections);
            fit_pair_list(&device.limits(), &mut its);
            let same_body = (world.rigid.as_ref().map(|b| &b.mesh.vertices))
                == (scene.rigid.as_ref().map(|b| &b.mesh.vertices));
            if its_topology != topology
                || world.cloth.rest_positions != scene.cloth.rest_positions
                || !same_body
                || world.network != scene.network
                || bytemuck::bytes_of(&WorldParams::shared(&its)) != bytemuck::bytes_of(&shared)
            {
                return Err(Error::config(
                    "worlds",
                    format!(
                        "world {k} differs from world 0 in what a batch shares (the cloth's \
                         grid, the body's mesh, the contact model or its network, the \
                         solver's sizes or substeps); run it in a batch of its own"
                    ),
                ));
            }
            each.push(WorldParams::of(&its));
        }
        let kernels = kernels.for_worlds(device).await?;
        let elements = crate::gpu::worlds::element_bytes(kernels.variant()).map_err(Error::Gpu)?;
        let sizes = Sizes::of(scene, &params, topology.len(), kernels.vectors());
        let (region, _) = sizes.for_worlds(1, &elements);
        let (batched, strides) = sizes.for_worlds(scenes.len() as u32, &elements);
        // A batch binds each array whole: its worlds must fit one binding.
        check_limits(&device.limits(), &batched, &mut params, false).map_err(|e| match e {
            Error::Limit {
                what,
                limit,
                needed,
                device,
            } => Error::Limit {
                what: format!("{what} of {} worlds", scenes.len()),
                limit,
                needed,
                device,
            },
            e => e,
        })?;
        let laid = Laid {
            topology: (topology, sections),
            sizes: (batched, region),
            batch: Some(Batch {
                params: &each,
                strides: &strides,
            }),
        };
        Self::built(kernels, (device, queue), scene, params, laid, "the worlds'").await
    }

    /// Builds everything once the scene is known to fit (errors the device
    /// reports come back through the caller's error scopes).
    fn build(
        kernels: &Kernels,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        params: Params,
        laid: Laid,
    ) -> Result<GpuSim> {
        let Laid {
            topology,
            sizes,
            batch,
        } = laid;
        let buffers = Buffers::new(
            device,
            scene,
            &params,
            topology,
            kernels.vectors(),
            sizes,
            batch,
        );
        let network = match &scene.network {
            Some(net) if params.has_rigid != 0 => {
                // One batch for every world's contacts (`gpu::worlds`).
                let slots = (params.n_vertices + params.n_rigid_vertices) as usize
                    * buffers.worlds as usize;
                let (capacity, wrt) = (slots * net.kind.evaluations(), net.kind.wrt());
                debug_assert!(buffers.net_outputs.size() >= output_bytes(&net.mlp, capacity, &wrt));
                Some(GpuMlp::new(
                    kernels,
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
                    count: 2 * query_passes(&params),
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamps"),
                    size: 16 * query_passes(&params) as u64,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                period_ns: queue.get_timestamp_period(),
            });
        Ok(GpuSim {
            device: device.clone(),
            queue: queue.clone(),
            stages: Stages::new(kernels, device, &buffers, scene, network),
            cg_budget: AtomicU32::new(params.cg_max_iters),
            solved_whole: solved_whole(scene),
            params,
            buffers,
            timer,
        })
    }

    /// Records stage "lines": the last step's contact forces as segments
    /// in [`GpuSim::force_lines`], `Scene::metres_per_force` long per unit
    /// of force.
    pub fn record_force_lines(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = Pass::new(encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("lines"),
            timestamp_writes: None,
        }));
        self.stages.begin(&mut pass);
        self.stages.lines.encode(&mut pass, &self.params);
    }

    /// Force segments, two vec4s per contact slot (w = 0: no contact):
    /// vertex–face slots, then face–vertex ones.
    pub fn force_lines(&self) -> &wgpu::Buffer {
        &self.buffers.lines
    }

    /// The rigid body's vertices placed at the current time (a `vec4` per
    /// vertex; all their normals follow all the vertices in the buffer),
    /// and its triangles (three `u32` indices each; one zero word without
    /// a body).
    pub fn body(&self) -> (&wgpu::Buffer, wgpu::BufferBinding<'_>) {
        let triangles = 3 * self.params.n_rigid_triangles as u64;
        let triangles = wgpu::BufferBinding {
            buffer: &self.buffers.topology.buffer,
            offset: 4 * self.buffers.sections.body_triangles as u64,
            size: std::num::NonZeroU64::new(4 * triangles.max(1)),
        };
        (&self.buffers.rigid, triangles)
    }

    /// GPU memory the scene's state takes, in bytes: every storage buffer
    /// of the step (a network's weights and activations not counted).
    pub fn state_bytes(&self) -> u64 {
        self.buffers.storage_bytes
    }

    /// The arrays bound in more than one part, because they pass the
    /// device's per-binding limit, with the bindings each takes (see
    /// [`Kernels::splittable`]); empty when every array fits one binding.
    pub fn split_arrays(&self) -> Vec<(&'static str, usize)> {
        let b = &self.buffers;
        [&b.topology, &b.matrix, &b.operators]
            .into_iter()
            .filter(|p| p.count() > 1)
            .map(|p| (p.name, p.count()))
            .collect()
    }

    /// How the solver's vectors lie in this scene's buffers (its kernels'
    /// [`Kernels::vectors`]).
    pub fn vector_layout(&self) -> layout::VectorLayout {
        self.buffers.vector_layout
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The device the scene lives on.
    pub(crate) fn device(&self) -> &wgpu::Device {
        &self.device
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The queue its steps are submitted to.
    pub(crate) fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// Cloth positions, one `vec4<f32>` (w = 1) per vertex: a vertex buffer.
    pub fn positions(&self) -> &wgpu::Buffer {
        &self.buffers.x
    }

    /// Cloth velocities, one `vec4<f32>` (w = 0) per vertex.
    pub fn velocities(&self) -> &wgpu::Buffer {
        &self.buffers.v
    }

    /// The clock and run statistics ([`StepState`]), for an app to copy
    /// into its own staging buffers after each step.
    pub fn statistics(&self) -> &wgpu::Buffer {
        &self.buffers.state
    }

    /// What a step starts from: [`Self::positions`], [`Self::velocities`],
    /// [`Self::loads`] and [`Self::statistics`] (with the clock). Copied
    /// back, they make the next step repeat one, as the run loop's rewind
    /// and [`SolvedSteps`](crate::gpu::budget::SolvedSteps) do.
    pub fn step_start(&self) -> [&wgpu::Buffer; 4] {
        [
            self.positions(),
            self.velocities(),
            self.loads(),
            self.statistics(),
        ]
    }

    /// Per vertex, two `f32`: the normal force its cloth–cloth contacts
    /// carried in the last step's solve (`cpu::State::loads`), then the
    /// friction bound scale the step took from it.
    pub fn loads(&self) -> &wgpu::Buffer {
        &self.buffers.cloth_loads
    }

    /// Where each recorded step leaves its passes' timestamps (two `u64`
    /// ticks per [`Stage::ALL`] entry and substep; [`Self::stage_ms`]
    /// reads them), when the adapter has timestamp queries.
    pub fn timestamps(&self) -> Option<&wgpu::Buffer> {
        self.timer.as_ref().map(|t| &t.resolve)
    }

    /// Milliseconds of each pass from a copy of [`Self::timestamps`],
    /// summed over the step's substeps.
    pub fn stage_ms(&self, ticks: &[u64]) -> Vec<(&'static str, f64)> {
        let period = self.timer.as_ref().map_or(1.0, |t| t.period_ns) as f64;
        self.active_passes()
            .map(|stage| {
                let ticks: u64 = (0..self.params.substeps)
                    .map(|sub| {
                        let q = 2 * query_pass(stage, sub) as usize;
                        ticks[q + 1].saturating_sub(ticks[q])
                    })
                    .sum();
                (stage.name(), ticks as f64 * period * 1e-6)
            })
            .collect()
    }

    /// The PCG iterations each step records (`solver.cg_iters` unless
    /// [`Self::set_cg_budget`] set fewer). Converged
    /// iterations dispatch no work, but each recorded one still costs its
    /// dispatches' overhead, which is large on software adapters: an app
    /// that knows roughly how many iterations its steps take can record
    /// fewer. A step that runs out before the tolerance reports it
    /// ([`StepState::last_residual`] above `solver.cg_tol`).
    pub fn cg_budget(&self) -> u32 {
        self.cg_budget.load(Ordering::Relaxed)
    }

    /// Records at most `iterations` PCG iterations (at least 1, at most
    /// `solver.cg_iters`) in the steps encoded from now on ([`Self::cg_budget`]);
    /// where each solve runs whole ([`Self::solved_whole`]) the budget stays
    /// the cap.
    pub fn set_cg_budget(&self, iterations: u32) {
        let cap = self.params.cg_max_iters.max(1);
        let budget = match self.solved_whole {
            true => cap,
            false => iterations.clamp(1, cap),
        };
        self.cg_budget.store(budget, Ordering::Relaxed);
    }

    /// Whether each solve runs whole, PCG and its V-cycle in one dispatch
    /// of one workgroup (`solver.whole_solve_nodes`), so that a step
    /// records the same dispatches whatever its iterations.
    pub fn solved_whole(&self) -> bool {
        self.solved_whole
    }

    /// Cloth triangles as `u32` indices into [`Self::positions`]: an index
    /// buffer whose first [`Self::index_count`] indices are the cloth's
    /// (the simulator's other connectivity follows them).
    pub fn indices(&self) -> &wgpu::Buffer {
        &self.buffers.topology.buffer
    }

    /// The kernel running a network model's network.
    pub fn network_kernel(&self) -> Option<NetworkKernel> {
        self.stages.contact.network_kernel()
    }

    /// Dispatches a step's network batch records (0 without a network): a
    /// batch of worlds' one batch takes a chunk's more for each chunk its
    /// worlds' contacts fill (`GpuMlp`); the rest of a step records one
    /// world's dispatches, whatever the worlds.
    pub fn network_dispatches(&self) -> u32 {
        self.stages.contact.network_dispatches() * self.params.substeps
    }

    /// The cloth's indices at the start of [`Self::indices`]: three per triangle.
    pub fn index_count(&self) -> u32 {
        3 * self.params.n_triangles
    }

    fn pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        stage: Stage,
        substep: u32,
    ) -> Pass<'e> {
        let k = query_pass(stage, substep);
        Pass::for_worlds(
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(stage.name()),
                timestamp_writes: self
                    .timer
                    .as_ref()
                    .map(|t| wgpu::ComputePassTimestampWrites {
                        query_set: &t.queries,
                        beginning_of_pass_write_index: Some(2 * k),
                        end_of_pass_write_index: Some(2 * k + 1),
                    }),
            }),
            self.buffers.worlds,
        )
    }

    /// Which self-contact stages the scene runs.
    fn self_contact_stages(&self) -> SelfContactStages {
        SelfContactStages {
            separate: self.params.self_contact != 0,
            forces: self.params.cloth_thickness > 0.0,
        }
    }

    /// The passes a step records: the rigid-body ones only with a body.
    fn active_passes(&self) -> impl Iterator<Item = Stage> + '_ {
        Stage::ALL
            .into_iter()
            .filter(move |stage| stage.runs(self.params.has_rigid != 0, self.self_contact_stages()))
    }

    /// Records one step of `solver.dt` into `encoder`: `Scene::substeps`
    /// backward Euler steps of `Scene::substep_dt`; nothing is read back.
    /// Returns the number of dispatches recorded.
    pub fn encode_step(&self, encoder: &mut wgpu::CommandEncoder) -> u32 {
        let count = (0..self.params.substeps)
            .flat_map(|sub| self.active_passes().map(move |stage| (sub, stage)))
            .map(|(sub, stage)| self.record_substage(encoder, stage, sub))
            .sum();
        if let Some(t) = &self.timer {
            let queries = 2 * query_passes(&self.params);
            encoder.resolve_query_set(&t.queries, 0..queries, &t.resolve, 0);
        }
        count
    }

    /// Records one stage's pass on what the earlier passes left (the
    /// per-stage benches time them one by one); a rigid-body stage records
    /// nothing without a body. Returns the number of dispatches recorded.
    pub fn record_stage(&self, encoder: &mut wgpu::CommandEncoder, stage: Stage) -> u32 {
        self.record_substage(encoder, stage, 0)
    }

    /// [`Self::record_stage`], its pass timed in `substep`'s queries.
    fn record_substage(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        stage: Stage,
        substep: u32,
    ) -> u32 {
        let p = &self.params;
        if !stage.runs(p.has_rigid != 0, self.self_contact_stages()) {
            return 0;
        }
        let record = self.stages.of(stage);
        record.clear(encoder, p);
        let mut pass = self.pass(encoder, stage, substep);
        self.stages.begin(&mut pass);
        let recording = Recording {
            params: p,
            group0: &self.stages.params,
            cg_iterations: self.cg_budget.load(Ordering::Relaxed),
        };
        record.encode(&mut pass, &recording);
        pass.dispatches()
    }

    /// Replaces the cloth state of every world with `state` (e.g. a CPU
    /// state, to compare a stage): positions, velocities, the loads its
    /// cloth–cloth contacts carried (none where `state.loads` is empty),
    /// and the clock at `state.step` steps of `solver.dt`.
    pub fn upload_state(&self, state: &State) {
        for k in 0..self.buffers.worlds {
            self.upload_world_state(k, state);
        }
    }

    /// [`Self::upload_state`] for world `k` of a batch alone.
    pub fn upload_world_state(&self, k: u32, state: &State) {
        let (x, v) = (&state.x, &state.v);
        let (b, region) = (&self.buffers, &self.buffers.region);
        let at = |bytes: u64| k as u64 * bytes;
        let write = |buffer, at, data: &[u8]| self.queue.write_buffer(buffer, at, data);
        write(
            &b.x,
            at(region.per_vertex),
            bytemuck::cast_slice(&vec4s(x, 1.0)),
        );
        write(
            &b.v,
            at(region.per_vertex),
            bytemuck::cast_slice(&vec4s(v, 0.0)),
        );
        if self.params.cloth_thickness > 0.0 {
            let loads: Vec<[f32; 2]> = (0..x.len())
                .map(|i| [state.loads.get(i).copied().unwrap_or(0.0), 1.0])
                .collect();
            write(
                &b.cloth_loads,
                at(region.cloth_loads),
                bytemuck::cast_slice(&loads),
            );
        }
        let clock = state.step as u32 * self.params.substeps;
        write(&b.state, at(region.state), bytemuck::bytes_of(&clock));
        // A new state starts healthy.
        let health = std::mem::offset_of!(StepState, health) as u64;
        write(
            &b.state,
            at(region.state) + health,
            bytemuck::bytes_of(&0u32),
        );
    }

    /// Worlds this simulator steps: 1 for a scene, else a batch's.
    pub fn worlds(&self) -> u32 {
        self.buffers.worlds
    }

    /// Where world `k`'s positions lie in [`Self::positions`], in bytes:
    /// one `vec4<f32>` per cloth vertex, to draw it with [`Self::indices`].
    pub fn world_positions(&self, k: u32) -> std::ops::Range<u64> {
        let at = k as u64 * self.buffers.region.per_vertex;
        at..at + 16 * self.params.n_vertices as u64
    }

    /// Records and submits one step; returns its dispatch count.
    pub fn step(&self) -> u32 {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let count = self.encode_step(&mut encoder);
        self.queue.submit([encoder.finish()]);
        count
    }

    #[cfg(not(target_arch = "wasm32"))]
    fn read<T: Pod>(&self, buffer: &wgpu::Buffer) -> Result<Vec<T>> {
        read_buffer(&self.device, &self.queue, buffer)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// A buffer of one `vec4<f32>` per vertex (positions, velocities or a
    /// copy of either), read back (blocks until the GPU is done).
    pub fn read_vec3(&self, buffer: &wgpu::Buffer) -> Result<Vec<Vec3>> {
        let raw: Vec<[f32; 4]> = self.read(buffer)?;
        Ok(raw[..self.params.n_vertices as usize]
            .iter()
            .map(|p| Vec3::from_slice(&p[..3]))
            .collect())
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// Cloth positions (world 0's in a batch), read back (blocks until the
    /// GPU is done).
    pub fn read_positions(&self) -> Result<Vec<Vec3>> {
        self.read_vec3(&self.buffers.x)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// World `k`'s positions and velocities, and its clock and statistics,
    /// read back alone (blocks until the GPU is done).
    pub fn read_world(&self, k: u32) -> Result<(Vec<Vec3>, Vec<Vec3>, StepState)> {
        let (device, queue, region) = (&self.device, &self.queue, &self.buffers.region);
        let vectors = |buffer| -> Result<Vec<Vec3>> {
            let raw: Vec<[f32; 4]> = read_range(device, queue, buffer, self.world_positions(k))?;
            Ok(raw.iter().map(|p| Vec3::from_slice(&p[..3])).collect())
        };
        let at = k as u64 * region.state;
        let bytes: Vec<u8> = read_range(device, queue, &self.buffers.state, at..at + region.state)?;
        let state = bytemuck::pod_read_unaligned(&bytes[..size_of::<StepState>()]);
        Ok((vectors(&self.buffers.x)?, vectors(&self.buffers.v)?, state))
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// Every world's positions and velocities, world after world, read
    /// back in one copy of each buffer (blocks until the GPU is done).
    pub fn read_worlds(&self) -> Result<(Vec<Vec3>, Vec<Vec3>)> {
        let n = self.params.n_vertices as usize;
        let stride = (self.buffers.region.per_vertex / 16) as usize;
        let worlds = self.buffers.worlds as usize;
        let all = |buffer| -> Result<Vec<Vec3>> {
            let raw: Vec<[f32; 4]> = self.read(buffer)?;
            Ok((0..worlds)
                .flat_map(|k| &raw[k * stride..][..n])
                .map(|p| Vec3::from_slice(&p[..3]))
                .collect())
        };
        Ok((all(&self.buffers.x)?, all(&self.buffers.v)?))
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// Cloth velocities, read back (blocks until the GPU is done).
    pub fn read_velocities(&self) -> Result<Vec<Vec3>> {
        self.read_vec3(&self.buffers.v)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The loads of [`Self::loads`] or a copy of it (`cpu::State::loads`;
    /// zeros without self-contact forces), read back (blocks until the GPU
    /// is done).
    pub fn read_loads(&self, buffer: &wgpu::Buffer) -> Result<Vec<f32>> {
        let n = self.params.n_vertices as usize;
        if self.params.cloth_thickness <= 0.0 {
            return Ok(vec![0.0; n]);
        }
        let raw: Vec<[f32; 2]> = self.read(buffer)?;
        Ok(raw[..n].iter().map(|l| l[0]).collect())
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The clock and run statistics, read back (blocks until the GPU is done).
    pub fn read_state(&self) -> Result<StepState> {
        Ok(self.read::<StepState>(&self.buffers.state)?[0])
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// What the last step's stage "separate" found (self-contact only; the
    /// twin of `cpu::separate::near_pairs`): each vertex's least
    /// separation (+∞ in no near pair) and the number of near pairs.
    pub fn read_separations(&self) -> Result<(Vec<f32>, u32)> {
        use crate::gpu::constants::{self_header, separations};
        let words: Vec<u32> = self.read(&self.buffers.separations)?;
        let n = self.params.n_vertices as usize;
        let at = separations::LEAST as usize * n;
        let least = words[at..at + n].iter().map(|&b| f32::from_bits(b));
        let header = separations::WORDS as usize * n;
        Ok((
            least.collect(),
            words[header + self_header::PAIR_COUNT as usize],
        ))
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The last step's cloth–cloth contacts that were applied (stage
    /// "self_contact"; the twin of `cpu::self_contact::Sheet::find`),
    /// sorted by key as the CPU keeps them.
    pub fn read_cloth_contacts(&self) -> Result<Vec<layout::ClothPair>> {
        use crate::gpu::constants::cloth_header;
        let header: Vec<u32> = self.read(&self.buffers.cloth_lists)?;
        let found = header[cloth_header::COUNT as usize].min(self.params.cloth_capacity);
        let mut pairs: Vec<layout::ClothPair> = self.read(&self.buffers.cloth_pairs)?;
        pairs.truncate(found as usize);
        pairs.retain(|p| p.applied != 0);
        pairs.sort_by_key(|p| p.key);
        Ok(pairs)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The assembled system of the last step: A's diagonal and per-spring
    /// blocks, and b.
    pub fn read_system(&self) -> Result<(Vec<layout::Sym3>, Vec<layout::Sym3>, Vec<Vec3>)> {
        self.read_world_system(0)
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// [`Self::read_system`] of world `k` of a batch.
    pub fn read_world_system(
        &self,
        k: u32,
    ) -> Result<(Vec<layout::Sym3>, Vec<layout::Sym3>, Vec<Vec3>)> {
        let (n, region) = (self.params.n_vertices as usize, &self.buffers.region);
        let floats: Vec<f32> = self.read(&self.buffers.b)?;
        let b = floats[(k as u64 * region.solver_vector / 4) as usize..]
            .chunks(self.vector_layout().bytes() as usize / 4)
            .take(n)
            .map(Vec3::from_slice)
            .collect();
        let blocks: Vec<layout::Sym3> = self.read(&self.buffers.matrix.buffer)?;
        let at = (k as u64 * region.matrix / size_of::<layout::Sym3>() as u64) as usize;
        let diagonal = blocks[at..at + n].to_vec();
        let off = blocks[at + n..at + n + self.params.n_springs as usize].to_vec();
        Ok((diagonal, off, b))
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// Every world's clock and statistics, read back in one copy (blocks
    /// until the GPU is done).
    pub fn read_world_states(&self) -> Result<Vec<StepState>> {
        let bytes: Vec<u8> = self.read(&self.buffers.state)?;
        let region = self.buffers.region.state as usize;
        Ok((0..self.buffers.worlds as usize)
            .map(|k| bytemuck::pod_read_unaligned(&bytes[k * region..][..size_of::<StepState>()]))
            .collect())
    }

    #[cfg(not(target_arch = "wasm32"))]
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

    #[cfg(not(target_arch = "wasm32"))]
    /// Milliseconds of each pass of the last recorded step, when the
    /// adapter has timestamp queries.
    pub fn read_stage_ms(&self) -> Result<Option<Vec<(&'static str, f64)>>> {
        let Some(t) = &self.timer else {
            return Ok(None);
        };
        let ticks: Vec<u64> = self.read(&t.resolve)?;
        Ok(Some(self.stage_ms(&ticks)))
    }
}

/// Passes a step's timestamps cover: each stage in each substep.
fn query_passes(params: &Params) -> u32 {
    Stage::ALL.len() as u32 * params.substeps
}

/// The timestamp pair of `stage` in `substep`.
fn query_pass(stage: Stage, substep: u32) -> u32 {
    substep * Stage::ALL.len() as u32 + stage.index() as u32
}

/// The first error `scope` captured, as one line saying what was being done.
async fn captured(scope: wgpu::ErrorScopeGuard, doing: &str) -> Result<()> {
    match scope.pop().await {
        None => Ok(()),
        Some(e) => Err(Error::Gpu(format!(
            "{doing}: {}",
            crate::gpu::context::one_line(&e.to_string())
        ))),
    }
}
