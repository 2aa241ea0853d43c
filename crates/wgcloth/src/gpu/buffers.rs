//! One scene's state on the GPU, apart from the kernels (as in
//! wgsparkl): the run's constants (`params_for`), every buffer's size as
//! a pure function of the scene (`Sizes`, as vello's `RenderConfig`),
//! the check of those sizes against the device's limits, and the buffers.

use glam::Vec3;
use wgpu::util::DeviceExt;

use crate::config::{ModelKind, Preconditioner, Smoother};
use crate::cpu::{self_contact, separate};
use crate::error::{Error, Result};
use crate::gpu::constants::{
    TILE, WORKGROUP, cloth_header, model, motion, self_header, separations,
};
use crate::gpu::layout::{
    BvhNode, ClothPair, Contact, Grid, Hop, Params, Response, RigidFrame, ScalarsAndSizes,
    Sections, StepState, Sym3, VectorLayout, WorldParams,
};
use crate::gpu::shaders::PARTS;
use crate::gpu::worlds::MAX_WORLDS;
use crate::multigrid::{self, NO_PATCHES, PATCH_BLOCKS, PATCH_COLOURS, STORED_STENCIL};
use crate::nn::weights::NetKind;
use crate::scene::{Motion, Scene};
use crate::stage::SelfContactStages;

/// Workgroups covering `n` invocations.
/// The least common multiple of `a` and `b`.
fn lcm(a: u64, b: u64) -> u64 {
    let gcd = |mut a: u64, mut b: u64| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    a / gcd(a, b) * b
}

pub(crate) fn groups(n: u32) -> u32 {
    n.div_ceil(WORKGROUP)
}

pub(crate) fn vec4s(points: &[Vec3], w: f32) -> Vec<[f32; 4]> {
    points.iter().map(|p| p.extend(w).to_array()).collect()
}

/// The scene's buffers. Related arrays share one buffer (slots of both
/// contact directions, A's diagonal and off-diagonal blocks, the placed
/// body's vertices and normals, all static connectivity in `topology`), so
/// no kernel binds more than WebGPU's default 8 storage buffers.
pub(crate) struct Buffers {
    /// Bytes of all the storage buffers below (the two small uniforms and
    /// the network's weights not counted).
    pub(crate) storage_bytes: u64,
    pub(crate) params: wgpu::Buffer,
    pub(crate) x: wgpu::Buffer,
    pub(crate) v: wgpu::Buffer,
    pub(crate) rest: wgpu::Buffer,
    pub(crate) topology: Parts,
    pub(crate) sections: Sections,
    /// Vertex–face slots (one per cloth vertex), then face–vertex ones
    /// (one per rigid vertex).
    pub(crate) contacts: wgpu::Buffer,
    pub(crate) responses: wgpu::Buffer,
    /// Per cloth triangle the head of its face–vertex contact list, then
    /// per rigid vertex the next entry of its list (wgsl/collide.wgsl).
    pub(crate) triangle_contacts: wgpu::Buffer,
    /// A's diagonal blocks, then its off-diagonal ones.
    pub(crate) matrix: Parts,
    /// How b, r, zq, p, P⁻¹ and the multigrid vectors lie in memory.
    pub(crate) vector_layout: VectorLayout,
    pub(crate) b: wgpu::Buffer,
    pub(crate) r: wgpu::Buffer,
    /// PCG: z = P⁻¹ r, then q = S A p.
    pub(crate) zq: wgpu::Buffer,
    /// PCG: the search direction, ping-ponged between iterations.
    pub(crate) p: [wgpu::Buffer; 2],
    pub(crate) inv_diag: wgpu::Buffer,
    pub(crate) partials: wgpu::Buffer,
    /// PCG's scalars, ping-ponged; they also hold the next iteration's
    /// indirect dispatch sizes.
    pub(crate) scalars: [wgpu::Buffer; 2],
    /// Multigrid: the smoother blocks of the levels block Jacobi smooths
    /// (with patches, the coarsest alone), then every coarse level's
    /// stencils, then the patch smoother's inverses (one element when
    /// Jacobi preconditions).
    pub(crate) operators: Parts,
    /// Multigrid: every coarse level's right-hand side and correction.
    pub(crate) vectors: wgpu::Buffer,
    /// Multigrid: per level, its `Hop`, what its dispatches work between:
    /// one per patch colour where the patch smoother smooths it (colour
    /// 0's but for the sweeps), else colour 0's alone.
    pub(crate) hops: Vec<Vec<wgpu::Buffer>>,
    /// Multigrid: the same hops in one array, for the coarse levels' tail.
    pub(crate) hop_list: wgpu::Buffer,
    pub(crate) state: wgpu::Buffer,
    pub(crate) body_vertices: wgpu::Buffer,
    pub(crate) body_normals: wgpu::Buffer,
    pub(crate) body_face_normals: wgpu::Buffer,
    pub(crate) bvh_nodes: wgpu::Buffer,
    /// The placed body: its vertices, then their normals.
    pub(crate) rigid: wgpu::Buffer,
    pub(crate) frame: wgpu::Buffer,
    /// Tile bounds, then super-tile bounds (then, with self-contact, each
    /// cell's swept box: stage "separate").
    pub(crate) bounds: wgpu::Buffer,
    /// Stage "separate": per vertex its least separation's bits, then its
    /// flags, then the header (`constants::self_header`).
    pub(crate) separations: wgpu::Buffer,
    /// Stage "separate": its rounds' indirect dispatches.
    pub(crate) self_dispatches: wgpu::Buffer,
    /// Stage "separate": the near pairs, four words each.
    pub(crate) self_pairs: wgpu::Buffer,
    /// Stage "self_contact": its header, each vertex's contact count and
    /// list (`gpu::constants::cloth_header`).
    pub(crate) cloth_lists: wgpu::Buffer,
    /// Stage "self_contact": the cloth–cloth contacts.
    pub(crate) cloth_pairs: wgpu::Buffer,
    /// Stage "load": per vertex, the normal load its cloth–cloth contacts
    /// carried in the last solve, and this step's friction bound scale.
    pub(crate) cloth_loads: wgpu::Buffer,
    /// Where the step started (self-contact only).
    pub(crate) x_start: wgpu::Buffer,
    /// The network batch's size, then its contact slots.
    pub(crate) net_batch: wgpu::Buffer,
    pub(crate) net_inputs: wgpu::Buffer,
    pub(crate) net_outputs: wgpu::Buffer,
    /// The renderer's force segments (stage "lines") and their scale.
    pub(crate) lines: wgpu::Buffer,
    pub(crate) line_scale: wgpu::Buffer,
    /// Worlds the per-world buffers hold, one region each.
    pub(crate) worlds: u32,
    /// One world's region of each per-world buffer, in bytes.
    pub(crate) region: Sizes,
    /// A batch's own parameters (`gpu::worlds`); `None` for one scene.
    pub(crate) batch: Option<WorldBuffers>,
}

/// What a batch of worlds adds to group 0 (`gpu::worlds`).
pub(crate) struct WorldBuffers {
    /// Each world's [`WorldParams`], `WORLDS_PER_BINDING` to a binding
    /// (`gpu::worlds`), `MAX_WORLDS` in all.
    pub(crate) params: wgpu::Buffer,
    /// Each per-world global's region, in its elements.
    pub(crate) strides: wgpu::Buffer,
}

/// A batch of worlds, as [`Buffers::new`] lays it out: each world's own
/// parameters and the size of each per-world global's region.
pub(crate) struct Batch<'a> {
    pub(crate) params: &'a [WorldParams],
    pub(crate) strides: &'a [u32],
}

/// An array the kernels may bind in parts (`gpu::shaders::SPLIT_ARRAYS`):
/// one buffer, bound as up to [`PARTS`] windows, part k under the WGSL name
/// `name_k` (part 0: `name`).
pub(crate) struct Parts {
    pub(crate) buffer: wgpu::Buffer,
    pub(crate) name: &'static str,
    /// Part k's bytes are `bounds[k]..bounds[k + 1]`; an empty part is
    /// never read, and is bound to the buffer's first bytes.
    bounds: [u64; PARTS + 1],
}

impl Parts {
    /// The window bound as the WGSL variable `name`, if it is one of these parts.
    pub(crate) fn binding(&self, name: &str) -> Option<wgpu::BufferBinding<'_>> {
        let k = match name.strip_prefix(self.name)? {
            "" => 0,
            part => part.strip_prefix('_')?.parse().ok()?,
        };
        let (start, end) = (*self.bounds.get(k)?, *self.bounds.get(k + 1)?);
        let (offset, size) = match end > start {
            true => (start, end - start),
            false => (0, self.buffer.size().min(256)),
        };
        Some(wgpu::BufferBinding {
            buffer: &self.buffer,
            offset,
            size: std::num::NonZeroU64::new(size),
        })
    }

    /// The bindings the array takes.
    pub(crate) fn count(&self) -> usize {
        1 + self.bounds[1..].windows(2).filter(|w| w[0] < w[1]).count()
    }
}

/// Where an array of `count` elements of `size` bytes is cut to bind it in
/// at most [`PARTS`] windows of at most `bindable` bytes, each starting at a
/// multiple of `align` bytes: the element indices where parts 1 and 2
/// start (`count` for a part not needed); `None` if it does not fit.
pub(crate) fn cuts(count: u64, size: u64, bindable: u64, align: u64) -> Option<[u64; 2]> {
    if count * size <= bindable {
        return Some([count; 2]);
    }
    // Elements per part: a multiple of the elements in lcm(size, align) bytes.
    let gcd = |mut a: u64, mut b: u64| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    let step = align / gcd(size, align);
    let per = bindable / size / step * step;
    (per > 0 && count <= PARTS as u64 * per).then(|| [per, (2 * per).min(count)])
}

/// The run's constants, as the kernels read them.
pub(crate) fn params_for(scene: &Scene, sections: &Sections) -> Params {
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
        dt: scene.substep_dt(),
        substeps: scene.substeps,
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
        self_contact: cfg.self_contact.enabled as u32,
        self_gamma: cfg.self_contact.gamma,
        self_floor: cfg.self_contact.floor,
        self_capacity: match cfg.self_contact.enabled {
            true => separate::NEAR_PAIRS_PER_VERTEX * cloth.vertex_count() as u32,
            false => 0,
        },
        rest_spacing: self_contact::grid_spacing(cloth).to_array(),
        ..Default::default()
    };
    if SelfContactStages::of(&cfg.self_contact).forces {
        p.cloth_thickness = cfg.self_contact.thickness;
        p.cloth_capacity = 4 * cloth.vertex_count() as u32;
        p.cloth_per_vertex = self_contact::PAIRS_PER_VERTEX;
        p.cloth_limit = cfg.self_contact.mass_ratio * cloth.vertex_mass;
    }
    if let Some(body) = &scene.rigid {
        p.has_rigid = 1;
        p.n_rigid_vertices = body.mesh.vertices.len() as u32;
        p.n_rigid_triangles = body.mesh.triangles.len() as u32;
        p.rigid_position = body.position.to_array();
        p.rigid_rotation = body.rotation.to_array();
        (p.motion_kind, p.motion_vector) = match body.motion {
            Motion::Static => (motion::STATIC, [0.0; 3]),
            Motion::Linear { velocity } => (motion::LINEAR, velocity.to_array()),
            Motion::Sinusoid {
                axis,
                amplitude,
                period,
                phase,
            } => {
                (p.motion_amplitude, p.motion_period, p.motion_phase) = (amplitude, period, phase);
                (motion::SINUSOID, axis.to_array())
            }
        };
    }
    p
}

/// The multigrid levels as the kernels see them, the cloth first, with
/// their offsets into the operators and vectors buffers; empty when the
/// scene is preconditioned by Jacobi.
pub(crate) fn multigrid_grids(scene: &Scene) -> Vec<Grid> {
    multigrid_layout(scene).0
}

/// Whether each solve runs whole in one workgroup (`multigrid::solve`):
/// a multigrid solve with coarse levels, no cloth–cloth couplings, and at
/// most `solver.whole_solve_nodes` vertices.
pub(crate) fn solved_whole(scene: &Scene) -> bool {
    multigrid_grids(scene).len() > 1
        && !SelfContactStages::of(&scene.config.self_contact).forces
        && scene.cloth.vertex_count() as u64 <= scene.config.solver.whole_solve_nodes as u64
}

/// Whether a batch of worlds of `scene` runs on the GPU (`gpu::worlds`),
/// or why not: so far the only indirect dispatches its kernels record are
/// the network's (over every world's contacts at once), so each step must
/// be solved whole and without self-contact.
pub(crate) fn batchable(scene: &Scene) -> Result<()> {
    let refuse = |why: &str| {
        Err(Error::config(
            "worlds",
            format!("a GPU batch of worlds {why}"),
        ))
    };
    if SelfContactStages::of(&scene.config.self_contact).separate {
        return refuse("runs without self-contact so far (self_contact.enabled = false)");
    }
    if !solved_whole(scene) {
        return refuse(&format!(
            "solves each world whole in one dispatch: it needs the multigrid preconditioner \
             and at most solver.whole_solve_nodes = {} vertices (the cloth has {})",
            scene.config.solver.whole_solve_nodes,
            scene.cloth.vertex_count()
        ));
    }
    Ok(())
}

/// [`multigrid_grids`], and the operators' elements (blocks) they use: up to
/// the last patch inverse, or the last stencil block; 1 with no levels.
fn multigrid_layout(scene: &Scene) -> (Vec<Grid>, u64) {
    if scene.config.solver.preconditioner != Preconditioner::Multigrid {
        return (vec![], 1);
    }
    let levels = multigrid::levels(scene.cloth.nx, scene.cloth.ny);
    let last = levels.len() - 1;
    // Each level has smoother blocks (block Jacobi, and the coarsest level
    // always) or patch inverses, never both.
    let patched = |k: usize| scene.config.solver.smoother == Smoother::Patches && k < last;
    let nodes = |k: usize| levels[k].nodes() as u32;
    let smoother_total: u32 = (0..=last).filter(|&k| !patched(k)).map(nodes).sum();
    let coarse_total: u32 = (1..=last).map(nodes).sum();
    // Operators: the smoother blocks, every coarse level's stencils, then
    // the patches' inverses.
    let (mut smoothers, mut stencils, mut vectors) = (0, smoother_total, 0);
    let mut patches = smoother_total + coarse_total * STORED_STENCIL;
    // The work vector after every coarse level's two.
    let work_at = 2 * coarse_total;
    let grids = levels
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let n = nodes(k);
            let coarse = k > 0;
            let g = Grid {
                level: k as u32,
                nx: l.nx,
                ny: l.ny,
                smoothers_at: if patched(k) { 0 } else { smoothers },
                stencil_at: if coarse { stencils } else { 0 },
                rhs_at: if coarse { vectors } else { 0 },
                correction_at: if coarse { vectors + n } else { 0 },
                work_at,
                patches_at: if patched(k) { patches } else { NO_PATCHES },
            };
            if coarse {
                stencils += n * STORED_STENCIL;
                vectors += 2 * n;
            }
            if patched(k) {
                let (px, py) = multigrid::patch_grid(*l);
                patches += px * py * PATCH_BLOCKS;
            } else {
                smoothers += n;
            }
            g
        })
        .collect();
    (grids, patches.into())
}

/// Each level's `Hop`: it and the next coarser one (colour 0).
pub(crate) fn hops(grids: &[Grid]) -> Vec<Hop> {
    (0..grids.len())
        .map(|l| Hop {
            fine: grids[l],
            coarse: grids.get(l + 1).copied().unwrap_or_default(),
            colour: 0,
        })
        .collect()
}

/// Bytes of one near pair in stage "separate"'s list: four vertices.
const PAIR_BYTES: usize = 16;

/// Shortens stage "separate"'s pair list to what one binding holds, where
/// `separate::NEAR_PAIRS_PER_VERTEX` per vertex would not fit: a step
/// whose pairs overflow the list walks the cloth again for its rounds (the
/// same result, slower), so a large cloth still runs within a device's
/// limits.
pub(crate) fn fit_pair_list(limits: &wgpu::Limits, params: &mut Params) {
    let bindable = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let most = bindable / PAIR_BYTES as u64;
    params.self_capacity = params.self_capacity.min(most.min(u32::MAX as u64) as u32);
    // Stage "self_contact": four contacts per vertex and
    // self_contact::PAIRS_PER_VERTEX entries in each vertex's list, or what
    // one binding holds.
    if params.cloth_thickness > 0.0 {
        let n = params.n_vertices as u64;
        let most = bindable / size_of::<ClothPair>() as u64;
        params.cloth_capacity = params.cloth_capacity.min(most.min(u32::MAX as u64) as u32);
        let words = bindable / 4 - cloth_header::WORDS as u64 - cloth_header::COUNTS as u64 * n;
        params.cloth_per_vertex = params.cloth_per_vertex.min((words / n) as u32);
    }
}

/// Every buffer's size in bytes that depends on the scene, a pure function
/// of it (as vello's `RenderConfig`): the limits check and the allocation
/// read the same numbers.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Sizes {
    /// One `vec4<f32>` per cloth vertex: x and v.
    pub(crate) per_vertex: u64,
    /// One entry per cloth vertex of a solver vector
    /// (`gpu::shaders::SOLVER_VECTORS`, as `VectorLayout` lays it out): b,
    /// r, each p, P⁻¹.
    pub(crate) solver_vector: u64,
    /// z and q together; and p and the correction e where the solve runs
    /// whole ([`solved_whole`]).
    pub(crate) zq: u64,
    pub(crate) topology: u64,
    pub(crate) contacts: u64,
    pub(crate) responses: u64,
    pub(crate) triangle_contacts: u64,
    pub(crate) matrix: u64,
    pub(crate) partials: u64,
    pub(crate) operators: u64,
    pub(crate) vectors: u64,
    pub(crate) rigid: u64,
    pub(crate) bounds: u64,
    pub(crate) separations: u64,
    pub(crate) self_pairs: u64,
    pub(crate) cloth_lists: u64,
    pub(crate) cloth_pairs: u64,
    pub(crate) cloth_loads: u64,
    pub(crate) x_start: u64,
    pub(crate) net_batch: u64,
    pub(crate) net_inputs: u64,
    pub(crate) net_outputs: u64,
    pub(crate) lines: u64,
    pub(crate) frame: u64,
    pub(crate) state: u64,
    /// Each of PCG's two scalars buffers.
    pub(crate) scalars: u64,
    pub(crate) self_dispatches: u64,
}

impl Sizes {
    pub(crate) fn of(
        scene: &Scene,
        params: &Params,
        topology_words: usize,
        vectors: VectorLayout,
    ) -> Sizes {
        let p = params;
        let (n, s, t) = (
            p.n_vertices as u64,
            p.n_springs as u64,
            p.n_triangles as u64,
        );
        let slots = n + p.n_rigid_vertices as u64;
        // A network batch holds every contact slot, at most.
        let batch = scene
            .network
            .as_ref()
            .map_or(0, |net| slots * net.kind.evaluations() as u64);
        let tiles = (p.tiles_x * p.tiles_y + p.supertiles_x * p.supertiles_y) as u64;
        // Vertices self-contact keeps arrays for (none without it).
        let self_n = if p.self_contact != 0 { n } else { 0 };
        let self_cells = if p.self_contact != 0 {
            (p.cells_x * p.cells_y) as u64
        } else {
            0
        };
        let size = |n: u64, of: usize| n * of as u64;
        let (grids, operators) = multigrid_layout(scene);
        let multigrid_entries = match grids.last() {
            Some(last) => last.work_at as u64 + grids[0].nodes() as u64,
            None => 1,
        };
        Sizes {
            per_vertex: size(n, 16),
            solver_vector: n * vectors.bytes(),
            zq: if solved_whole(scene) { 4 } else { 2 } * n * vectors.bytes(),
            topology: size(topology_words as u64, 4),
            contacts: size(slots, size_of::<Contact>()),
            responses: size(slots, size_of::<Response>()),
            triangle_contacts: size(2 * (t + p.n_rigid_vertices as u64), 4),
            matrix: size(n + s, size_of::<Sym3>()),
            partials: size(5 * groups(n as u32) as u64, 4),
            operators: size(operators, size_of::<Sym3>()),
            vectors: multigrid_entries * vectors.bytes(),
            rigid: size(2 * p.n_rigid_vertices as u64, 16),
            // With self-contact, each cell's swept box after them.
            bounds: size(tiles + self_cells, 32),
            separations: size(
                self_n * separations::WORDS as u64 + self_header::WORDS as u64,
                4,
            ),
            self_pairs: size(p.self_capacity as u64, PAIR_BYTES),
            cloth_lists: match p.cloth_thickness > 0.0 {
                true => {
                    let per_vertex = (cloth_header::COUNTS + p.cloth_per_vertex) as u64;
                    size(cloth_header::WORDS as u64 + n * per_vertex, 4)
                }
                false => 0,
            },
            cloth_pairs: size(p.cloth_capacity as u64, size_of::<ClothPair>()),
            cloth_loads: match p.cloth_thickness > 0.0 {
                true => size(n, 8),
                false => 0,
            },
            x_start: size(self_n, 16),
            net_batch: size(1 + batch, 4),
            net_inputs: size(batch * p.net_width as u64, 4),
            net_outputs: size(batch * (p.net_rows * p.net_outputs) as u64, 4),
            lines: size(2 * slots, 16),
            frame: size_of::<RigidFrame>() as u64,
            state: size_of::<StepState>() as u64,
            scalars: size_of::<ScalarsAndSizes>() as u64,
            self_dispatches: 4 * self_header::DISPATCH_WORDS as u64,
        }
    }

    /// Each buffer a world of a batch has a region of: its bytes here, and
    /// the WGSL names it is bound under (`gpu::worlds::PER_WORLD`).
    fn per_world(&mut self) -> [(&mut u64, &'static [&'static str]); 26] {
        [
            (&mut self.per_vertex, &["x", "v"]),
            (
                &mut self.solver_vector,
                &["b", "r", "p", "p_next", "inv_diag"],
            ),
            (&mut self.zq, &["zq"]),
            (&mut self.contacts, &["contacts"]),
            (&mut self.responses, &["responses"]),
            (&mut self.triangle_contacts, &["triangle_contacts"]),
            (&mut self.matrix, &["matrix"]),
            (&mut self.partials, &["partials"]),
            (&mut self.operators, &["operators"]),
            (&mut self.vectors, &["vectors"]),
            (&mut self.rigid, &["rigid"]),
            (&mut self.bounds, &["bounds"]),
            (&mut self.separations, &["separations"]),
            (&mut self.self_pairs, &["pairs"]),
            (&mut self.cloth_lists, &["cloth_lists"]),
            (&mut self.cloth_pairs, &["cloth_pairs"]),
            (&mut self.cloth_loads, &["cloth_loads"]),
            (&mut self.x_start, &["x_start"]),
            (&mut self.net_batch, &["net_batch"]),
            (&mut self.net_inputs, &["net_inputs"]),
            (&mut self.net_outputs, &["net_outputs"]),
            (&mut self.lines, &["lines"]),
            (&mut self.frame, &["frame"]),
            (&mut self.state, &["state"]),
            (
                &mut self.scalars,
                &["scalars", "scalars_in", "scalars_next", "scalars_spare"],
            ),
            (&mut self.self_dispatches, &["dispatches"]),
        ]
    }

    /// The sizes of a batch of `worlds` worlds of this scene: each
    /// per-world buffer `worlds` regions, each a whole number of the
    /// elements of every name it is bound under (`element_bytes`,
    /// `gpu::worlds::element_bytes`); and each name's region in elements,
    /// in `gpu::worlds::PER_WORLD` order (its `world_strides`).
    pub(crate) fn for_worlds(
        &self,
        worlds: u32,
        element_bytes: &std::collections::BTreeMap<String, u32>,
    ) -> (Sizes, Vec<u32>) {
        let mut sizes = self.clone();
        let mut strides = vec![0; 4 * crate::gpu::worlds::STRIDE_VECTORS];
        for (bytes, names) in sizes.per_world() {
            let elements: Vec<(usize, u64)> = (names.iter())
                .filter_map(|n| {
                    Some((crate::gpu::worlds::slot(n)?, *element_bytes.get(*n)? as u64))
                })
                .collect();
            let unit = elements.iter().fold(1, |unit, &(_, e)| lcm(unit, e));
            let region = bytes.div_ceil(unit) * unit;
            for (slot, element) in elements {
                strides[slot] = (region / element) as u32;
            }
            *bytes = region * worlds as u64;
        }
        (sizes, strides)
    }

    /// Each buffer a kernel binds whole, by what it holds.
    pub(crate) fn whole(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("per-vertex vectors", self.per_vertex),
            ("solver vectors", self.solver_vector),
            ("PCG z and q", self.zq),
            ("contacts", self.contacts),
            ("responses", self.responses),
            ("triangle contact lists", self.triangle_contacts),
            ("partial sums", self.partials),
            ("multigrid vectors", self.vectors),
            ("placed body", self.rigid),
            ("tile bounds", self.bounds),
            ("least separations", self.separations),
            ("self-contact pairs", self.self_pairs),
            ("cloth-cloth contact lists", self.cloth_lists),
            ("cloth-cloth contacts", self.cloth_pairs),
            ("cloth-cloth loads", self.cloth_loads),
            ("step start", self.x_start),
            ("network batch", self.net_batch),
            ("network inputs", self.net_inputs),
            ("network outputs", self.net_outputs),
            ("force lines", self.lines),
        ]
    }

    /// The arrays that may be bound in parts, in `SPLIT_ARRAYS` order: what
    /// each holds, its bytes and its element's bytes.
    pub(crate) fn parted(&self) -> [(&'static str, u64, u64); 3] {
        let block = size_of::<Sym3>() as u64;
        [
            ("topology", self.topology, 4),
            ("system matrix", self.matrix, block),
            ("multigrid operators", self.operators, block),
        ]
    }
}

impl Buffers {
    /// The buffers of `scene`, or of a batch of its worlds (`batch`), at
    /// `sizes` (`Sizes::for_worlds` for a batch, whose worlds each start
    /// at the scene's rest).
    pub(crate) fn new(
        device: &wgpu::Device,
        scene: &Scene,
        params: &Params,
        (topology, sections): (Vec<u32>, Sections),
        vectors: VectorLayout,
        (sizes, region): (Sizes, Sizes),
        batch: Option<Batch>,
    ) -> Buffers {
        let worlds = batch.as_ref().map_or(1, |b| b.params.len());
        let cloth = &scene.cloth;
        let level_hops = hops(&multigrid_grids(scene));
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        // Bytes of the storage buffers, for the memory a scene takes.
        let allocated = std::cell::Cell::new(0u64);
        let counted = |buffer: wgpu::Buffer| {
            allocated.set(allocated.get() + buffer.size());
            buffer
        };
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
            counted(
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents,
                    usage: usage | extra,
                }),
            )
        };
        let storage =
            |label: &str, contents: &[u8]| init(label, contents, wgpu::BufferUsages::empty());
        let zeroed = |label: &str, bytes: u64| {
            counted(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(64),
                usage,
                mapped_at_creation: false,
            }))
        };
        // `bytes` cut at `cuts` (elements of `size` bytes; at the end where
        // a part is not needed).
        let parts = |name, buffer: wgpu::Buffer, bytes: u64, cuts: [u32; 2], size: usize| {
            let at = |k: u32| (k as u64 * size as u64).min(bytes);
            Parts {
                name,
                bounds: [0, at(cuts[0]), at(cuts[1]), bytes],
                buffer,
            }
        };
        // Arrays of symmetric blocks, zeroed, bound in parts where cut.
        let blocks = |name, label, bytes, cuts| {
            parts(name, zeroed(label, bytes), bytes, cuts, size_of::<Sym3>())
        };

        let body = scene.rigid.as_ref();
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
        Buffers {
            params: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("params"),
                contents: bytemuck::bytes_of(params),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            }),
            x: init(
                "positions",
                bytemuck::cast_slice(&vec4s(&cloth.rest_positions, 1.0).repeat(worlds)),
                wgpu::BufferUsages::VERTEX,
            ),
            v: zeroed("velocities", sizes.per_vertex),
            rest: storage(
                "rest positions",
                bytemuck::cast_slice(&vec4s(&cloth.rest_positions, 1.0)),
            ),
            topology: parts(
                "topology",
                init(
                    "topology",
                    bytemuck::cast_slice(&topology),
                    wgpu::BufferUsages::INDEX,
                ),
                sizes.topology,
                params.topology_splits,
                4,
            ),
            sections,
            contacts: zeroed("contacts", sizes.contacts),
            responses: zeroed("responses", sizes.responses),
            triangle_contacts: zeroed("triangle contacts", sizes.triangle_contacts),
            matrix: blocks(
                "matrix",
                "system matrix",
                sizes.matrix,
                params.matrix_splits,
            ),
            vector_layout: vectors,
            b: zeroed("b", sizes.solver_vector),
            r: zeroed("r", sizes.solver_vector),
            zq: zeroed("z and q", sizes.zq),
            p: [
                zeroed("p 0", sizes.solver_vector),
                zeroed("p 1", sizes.solver_vector),
            ],
            inv_diag: zeroed("inverse diagonal", sizes.solver_vector),
            partials: zeroed("partial sums", sizes.partials),
            scalars: [0, 1].map(|k| {
                counted(device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(&format!("pcg scalars {k}")),
                    size: sizes.scalars,
                    usage: usage | wgpu::BufferUsages::INDIRECT,
                    mapped_at_creation: false,
                }))
            }),
            operators: blocks(
                "operators",
                "multigrid operators",
                sizes.operators,
                params.operators_splits,
            ),
            vectors: zeroed("multigrid vectors", sizes.vectors),
            hops: level_hops
                .iter()
                .map(|&hop| {
                    let colours = match hop.fine.patches_at {
                        NO_PATCHES => 1,
                        _ => PATCH_COLOURS as u32,
                    };
                    (0..colours)
                        .map(|colour| {
                            let hop = Hop { colour, ..hop };
                            storage("multigrid hop", bytemuck::bytes_of(&hop))
                        })
                        .collect()
                })
                .collect(),
            hop_list: storage("multigrid hops", bytemuck::cast_slice(&level_hops)),
            state: zeroed("step state", sizes.state),
            body_vertices: storage("body vertices", bytemuck::cast_slice(&body_vertices)),
            body_normals: storage("body vertex normals", bytemuck::cast_slice(&body_normals)),
            body_face_normals: storage(
                "body face normals",
                bytemuck::cast_slice(&body_face_normals),
            ),
            bvh_nodes: storage("body BVH nodes", bytemuck::cast_slice(&bvh_nodes)),
            rigid: init(
                "placed body",
                &vec![0u8; sizes.rigid as usize],
                wgpu::BufferUsages::VERTEX,
            ),
            frame: zeroed("rigid frame", sizes.frame),
            bounds: zeroed("tile bounds", sizes.bounds),
            separations: zeroed("least separations", sizes.separations),
            self_dispatches: counted(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("self-contact dispatches"),
                size: sizes.self_dispatches,
                usage: usage | wgpu::BufferUsages::INDIRECT,
                mapped_at_creation: false,
            })),
            self_pairs: zeroed("self-contact pairs", sizes.self_pairs),
            cloth_lists: zeroed("cloth-cloth contact lists", sizes.cloth_lists),
            cloth_pairs: zeroed("cloth-cloth contacts", sizes.cloth_pairs),
            cloth_loads: zeroed("cloth-cloth loads", sizes.cloth_loads),
            x_start: zeroed("step start", sizes.x_start),
            net_batch: zeroed("network batch", sizes.net_batch),
            net_inputs: zeroed("network inputs", sizes.net_inputs),
            net_outputs: zeroed("network outputs", sizes.net_outputs),
            lines: zeroed("force lines", sizes.lines),
            line_scale: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("force line scale"),
                contents: bytemuck::cast_slice(&[scene.metres_per_force(), 0.0, 0.0, 0.0]),
                usage: wgpu::BufferUsages::UNIFORM,
            }),
            batch: batch.map(|b| {
                let uniform = |label, contents: &[u8]| {
                    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some(label),
                        contents,
                        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    })
                };
                let mut each = b.params.to_vec();
                each.resize(MAX_WORLDS as usize, WorldParams::default());
                WorldBuffers {
                    params: uniform("world params", bytemuck::cast_slice(&each)),
                    strides: uniform("world strides", bytemuck::cast_slice(b.strides)),
                }
            }),
            worlds: worlds as u32,
            region,
            // Last: every buffer above is counted.
            storage_bytes: allocated.get(),
        }
    }
}

/// Refuses a scene the device cannot run, naming the limit, what the
/// scene needs and what the device has, before anything is created. Where
/// the kernels bind the largest arrays in parts (`split`), sets where each
/// is cut (`Params::*_splits`); else each must fit one binding. Returns
/// whether any is cut, and so needs `Kernels::in_parts`.
pub(crate) fn check_limits(
    limits: &wgpu::Limits,
    sizes: &Sizes,
    params: &mut Params,
    split: bool,
) -> Result<bool> {
    let bindable = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    let (mut cut, mut parted) = (Vec::new(), false);
    for (what, bytes, size) in sizes.parted() {
        let count = bytes / size;
        let whole = Some([count; 2]);
        let parts = match split && bytes <= limits.max_buffer_size {
            true => cuts(
                count,
                size,
                bindable,
                limits.min_storage_buffer_offset_alignment as u64,
            ),
            false => whole.filter(|_| bytes <= bindable),
        };
        let Some(parts) = parts else {
            let (limit, value) = if bytes > limits.max_buffer_size {
                ("max_buffer_size", limits.max_buffer_size)
            } else {
                (
                    "max_storage_buffer_binding_size",
                    limits.max_storage_buffer_binding_size,
                )
            };
            let needed = match split {
                true => format!("a {bytes}-byte buffer in at most {PARTS} bindings"),
                false => format!(
                    "a {bytes}-byte buffer (a device with {} storage buffers per shader stage binds it in parts)",
                    crate::gpu::kernels::SPLIT_STORAGE_BUFFERS
                ),
            };
            return Err(Error::Limit {
                what: what.into(),
                limit,
                needed,
                device: format!("{value} bytes"),
            });
        };
        parted |= parts[0] < count;
        cut.push(parts.map(|k| k as u32));
    }
    (
        params.topology_splits,
        params.matrix_splits,
        params.operators_splits,
    ) = (cut[0], cut[1], cut[2]);
    for (what, bytes) in sizes.whole() {
        if bytes > bindable {
            let (limit, value) = if bytes > limits.max_buffer_size {
                ("max_buffer_size", limits.max_buffer_size)
            } else {
                (
                    "max_storage_buffer_binding_size",
                    limits.max_storage_buffer_binding_size,
                )
            };
            return Err(Error::Limit {
                what: what.into(),
                limit,
                needed: format!("a {bytes}-byte buffer"),
                device: format!("{value} bytes"),
            });
        }
    }
    let most = (params.n_vertices.max(params.n_springs) as u64)
        .max((params.n_vertices + params.n_rigid_vertices) as u64);
    let dispatchable = limits.max_compute_workgroups_per_dimension as u64 * WORKGROUP as u64;
    if most > dispatchable {
        return Err(Error::Limit {
            what: "vertices or springs".into(),
            limit: "max_compute_workgroups_per_dimension",
            needed: format!(
                "{} workgroups in one dispatch",
                most.div_ceil(WORKGROUP as u64)
            ),
            device: limits.max_compute_workgroups_per_dimension.to_string(),
        });
    }
    Ok(parted)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1100 × 1024 cloth with self-contact fits a device whose bindings
    /// hold 128 MiB (lavapipe's and WebGPU's default) and whose buffers may
    /// be larger (lavapipe's): its pair list (8 per vertex would be 144 MB)
    /// is cut to one binding, its cloth–cloth contact lists shortened, and
    /// the largest arrays are bound in parts.
    #[test]
    fn a_large_cloth_with_self_contact_fits_a_128_mib_binding() {
        let mut config = crate::Config {
            scene: crate::config::SceneKind::Hang,
            ..Default::default()
        };
        config.cloth.grid = [1100, 1024];
        config.self_contact.enabled = true;
        let scene = Scene::new(&config).unwrap();
        let (topology, sections) = crate::gpu::layout::topology(&scene);
        let mut params = params_for(&scene, &sections);
        let limits = wgpu::Limits {
            max_buffer_size: 1 << 32,
            ..Default::default()
        };
        let wanted = params.self_capacity as u64 * PAIR_BYTES as u64;
        assert!(wanted > limits.max_storage_buffer_binding_size);
        fit_pair_list(&limits, &mut params);
        let sizes = Sizes::of(&scene, &params, topology.len(), VectorLayout::Packed);
        assert!(sizes.self_pairs <= limits.max_storage_buffer_binding_size);
        assert!(sizes.self_pairs + PAIR_BYTES as u64 > limits.max_storage_buffer_binding_size);
        assert!(sizes.cloth_lists <= limits.max_storage_buffer_binding_size);
        assert!(sizes.cloth_pairs <= limits.max_storage_buffer_binding_size);
        assert!(
            params.cloth_per_vertex > 16
                && params.cloth_per_vertex < self_contact::PAIRS_PER_VERTEX
        );
        check_limits(&limits, &sizes, &mut params, true).unwrap();
    }

    #[test]
    fn arrays_are_cut_at_aligned_elements_into_at_most_three_parts() {
        // Fits one binding: no cut.
        assert_eq!(cuts(100, 24, 2400, 256), Some([100, 100]));
        // 24-byte blocks, 256-byte alignment: parts of a multiple of 32
        // blocks (768 bytes), as many as a 10,000-byte binding holds (416).
        assert_eq!(cuts(500, 24, 10_000, 256), Some([416, 500]));
        assert_eq!(cuts(1000, 24, 10_000, 256), Some([416, 832]));
        for (count, size) in [(500u64, 24u64), (1000, 24), (7000, 4)] {
            let [a, b] = cuts(count, size, 10_000, 256).unwrap();
            // An empty part is never read (it binds the first bytes).
            for (start, end) in [(0, a), (a, b), (b, count)]
                .into_iter()
                .filter(|(s, e)| s < e)
            {
                assert_eq!(start * size % 256, 0, "{count} × {size}: part at {start}");
                assert!(
                    (end - start) * size <= 10_000,
                    "{count} × {size}: part {start}..{end}"
                );
            }
        }
        // More than three parts' worth, or not one aligned step: refused.
        assert_eq!(cuts(1248, 24, 10_000, 256), Some([416, 832]));
        assert_eq!(cuts(1249, 24, 10_000, 256), None);
        assert_eq!(cuts(100, 24, 700, 256), None);
    }
}
