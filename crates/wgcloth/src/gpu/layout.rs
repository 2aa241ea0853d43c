//! Host mirrors of the WGSL structs in `wgsl/common.wgsl` (same field
//! order, sizes and alignment; a test checks the sizes), and the packed
//! topology buffer.

use bytemuck::{Pod, Zeroable};

use crate::gpu::constants::NO_TRIANGLE;
use crate::multigrid::MAX_LEVELS;
use crate::scene::Scene;

/// A symmetric 3×3 block as buffers hold it (`PackedSym3` in
/// wgsl/common.wgsl), the CPU's type.
pub use crate::math::Sym3;

/// How the solver's vectors (b, r, z, q, the directions, P⁻¹ and the
/// multigrid levels': `gpu::shaders::SOLVER_VECTORS`) lie in memory. The
/// velocities, which PCG solves for, stay a `vec4` each: they are also the
/// vertex buffer's neighbours and every stage reads them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VectorLayout {
    /// Three packed `f32` a vertex: a quarter fewer bytes to move, for a
    /// hardware GPU, where bytes bound an iteration.
    Packed,
    /// One `vec4<f32>` a vertex: one load instead of three, for a CPU
    /// adapter, which pays per load and lane rather than per byte
    /// (lavapipe's solve took up to a fifth longer packed; BENCHMARKS.md).
    Vec4,
}

impl VectorLayout {
    /// Both layouts.
    pub const ALL: [VectorLayout; 2] = [VectorLayout::Packed, VectorLayout::Vec4];

    /// The layout of that [`VectorLayout::name`].
    pub fn named(name: &str) -> Option<VectorLayout> {
        Self::ALL.into_iter().find(|l| l.name() == name)
    }

    /// The layout for an adapter of type `device_type`.
    pub fn for_adapter(device_type: wgpu::DeviceType) -> VectorLayout {
        match device_type {
            wgpu::DeviceType::Cpu => VectorLayout::Vec4,
            _ => VectorLayout::Packed,
        }
    }

    /// Its name in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            VectorLayout::Packed => "packed",
            VectorLayout::Vec4 => "vec4",
        }
    }

    /// Bytes of one vertex's entry.
    pub const fn bytes(self) -> u64 {
        match self {
            VectorLayout::Packed => 12,
            VectorLayout::Vec4 => 16,
        }
    }
}

/// Declares [`WorldParams`] from one list of [`Params`] fields, each
/// with its WGSL type: the struct, its WGSL declaration and the copies
/// between the two.
macro_rules! world_params {
    ($($field:ident: $ty:ty => $wgsl:literal,)*) => {
        #[repr(C)]
        #[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
        /// The [`Params`] fields each world of a batch has its own of
        /// (`gpu::worlds`): its contact model's coefficients, the cloth's
        /// material, the body's motion and the solver's tolerance. The
        /// rest (sizes, the model's kind, substeps) the worlds share. Laid
        /// out as WGSL lays out the struct `gpu::worlds` declares.
        pub struct WorldParams {
            $(#[doc = concat!("[`Params::", stringify!($field), "`].")] pub $field: $ty,)*
        }

        impl WorldParams {
            /// Each field's name and WGSL type, in order.
            pub const FIELDS: &[(&str, &str)] = &[$((stringify!($field), $wgsl)),*];

            /// The fields of `params` that are a world's own.
            pub fn of(params: &Params) -> WorldParams {
                WorldParams { $($field: params.$field,)* }
            }

            /// `params` with these fields set to zero: what worlds of one
            /// batch must share.
            pub fn shared(params: &Params) -> Params {
                Params { $($field: Zeroable::zeroed(),)* ..*params }
            }
        }
    };
}

// Scalars first, then each three-vector with a scalar in its fourth lane
// (WGSL's vec3 alignment), so the Rust and WGSL layouts agree: 128 bytes.
world_params! {
    vertex_mass: f32 => "f32",
    stiffness: f32 => "f32",
    cg_tol: f32 => "f32",
    damping_mass: f32 => "f32",
    damping_stiffness: f32 => "f32",
    naive_stiffness: f32 => "f32",
    force_scale: f32 => "f32",
    kn: f32 => "f32",
    kd: f32 => "f32",
    kt: f32 => "f32",
    mu: f32 => "f32",
    motion_kind: u32 => "u32",
    motion_period: f32 => "f32",
    motion_phase: f32 => "f32",
    motion_amplitude: f32 => "f32",
    max_speed: f32 => "f32",
    gravity: [f32; 3] => "vec3<f32>",
    thickness: f32 => "f32",
    rigid_position: [f32; 3] => "vec3<f32>",
    max_depth: f32 => "f32",
    motion_vector: [f32; 3] => "vec3<f32>",
    dt: f32 => "f32",
    rigid_rotation: [f32; 4] => "vec4<f32>",
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
/// The run's constants, as every scene stage reads them (mirrors `Params`
/// in wgsl/common.wgsl, a uniform in group 0); built by `buffers::params_for`.
pub struct Params {
    /// Cloth vertices.
    pub n_vertices: u32,
    /// Cloth springs.
    pub n_springs: u32,
    /// Cloth triangles.
    pub n_triangles: u32,
    /// The rigid body's vertices (0 without a body).
    pub n_rigid_vertices: u32,
    /// The rigid body's triangles (0 without a body).
    pub n_rigid_triangles: u32,
    /// The contact model the kernels evaluate ([`model`](crate::gpu::constants::model)).
    pub model: u32,
    /// 1 when the scene has a rigid body, else 0.
    pub has_rigid: u32,
    /// Most PCG iterations per step (`solver.cg_iters`); the pass records
    /// them all, and converged ones return at once.
    pub cg_max_iters: u32,
    /// Time step of one substep in s (`Scene::substep_dt`).
    pub dt: f32,
    /// Mass of each cloth vertex in kg.
    pub vertex_mass: f32,
    /// Spring stiffness E in N/m (thesis eq. 4), the same for every spring.
    pub stiffness: f32,
    /// Relative residual at which PCG stops (`solver.cg_tol`).
    pub cg_tol: f32,
    /// Rayleigh damping α (mass term) in 1/s.
    pub damping_mass: f32,
    /// Rayleigh damping β (stiffness term) in s.
    pub damping_stiffness: f32,
    /// Contact thickness ε in m: contact starts this far outside a surface.
    pub thickness: f32,
    /// Points deeper than this below a surface, in m, are not its contacts.
    pub max_depth: f32,
    /// Gravitational acceleration in m/s².
    pub gravity: [f32; 3],
    /// c of the naive model (thesis eq. 6), N/m.
    pub naive_stiffness: f32,
    /// s of the friction model (thesis eqs. 8–9).
    pub force_scale: f32,
    /// Contact stiffness k_n.
    pub kn: f32,
    /// Contact damping k_d.
    pub kd: f32,
    /// Friction stiffness k_t.
    pub kt: f32,
    /// Coulomb coefficient μ.
    pub mu: f32,
    /// The body's motion: 0 static, 1 linear, 2 sinusoid (wgsl/rigid.wgsl).
    pub motion_kind: u32,
    /// Sinusoid: period in s.
    pub motion_period: f32,
    /// Sinusoid: phase in radians.
    pub motion_phase: f32,
    /// World position of the body's origin at t = 0 (before the motion), m.
    pub rigid_position: [f32; 3],
    /// Sinusoid: amplitude in m.
    pub motion_amplitude: f32,
    /// The body's fixed orientation, a unit quaternion (x, y, z, w).
    pub rigid_rotation: [f32; 4],
    /// Linear: the velocity in m/s; sinusoid: the unit axis of travel.
    pub motion_vector: [f32; 3],
    /// Cloth grid cells along a row (`nx − 1`).
    pub cells_x: u32,
    /// Cloth grid cells along a column (`ny − 1`).
    pub cells_y: u32,
    /// Tiles of `TILE × TILE` cells along x (the face–vertex broad phase).
    pub tiles_x: u32,
    /// Tiles along y.
    pub tiles_y: u32,
    /// Super-tiles of `TILE × TILE` tiles along x.
    pub supertiles_x: u32,
    /// Super-tiles along y.
    pub supertiles_y: u32,
    /// Network inputs per batch entry (0 without a network).
    pub net_width: u32,
    /// Rows per batch entry: 1 + the Jacobian columns (0 without a network).
    pub net_rows: u32,
    /// Network outputs per row (0 without a network).
    pub net_outputs: u32,
    /// `solver.max_speed`: a faster vertex raises `StepState::health`.
    pub max_speed: f32,
    /// Where each section of the topology buffer starts, in `u32`s
    /// ([`Sections`]): here [`Sections::springs`].
    pub springs_at: u32,
    /// Start of [`Sections::adjacency`].
    pub adjacency_at: u32,
    /// Start of [`Sections::pinned`].
    pub pinned_at: u32,
    /// Start of [`Sections::vertex_triangles`].
    pub vertex_triangles_at: u32,
    /// Start of [`Sections::spring_triangles`].
    pub spring_triangles_at: u32,
    /// Start of [`Sections::body_triangles`].
    pub body_triangles_at: u32,
    /// Start of [`Sections::bvh_order`].
    pub bvh_order_at: u32,
    /// Where the topology's parts 1 and 2 start, in elements, when it is
    /// bound in parts (`gpu::shaders::SPLIT_ARRAYS`); else unused.
    pub topology_splits: [u32; 2],
    /// The same for the system matrix.
    pub matrix_splits: [u32; 2],
    /// The same for the multigrid operators.
    pub operators_splits: [u32; 2],
    /// 1 when the step keeps the cloth from passing through itself
    /// (`self_contact.enabled`), else 0.
    pub self_contact: u32,
    /// `self_contact.gamma`.
    pub self_gamma: f32,
    /// `self_contact.floor`, m.
    pub self_floor: f32,
    /// Near pairs the list holds (stage "separate"):
    /// `separate::NEAR_PAIRS_PER_VERTEX` per vertex, or what one binding
    /// holds (`gpu::buffers::fit_pair_list`).
    pub self_capacity: u32,
    /// `self_contact.thickness` when self-contact is on, else 0: stage
    /// "self_contact" runs when above 0.
    pub cloth_thickness: f32,
    /// Cloth–cloth contacts the list holds (stage "self_contact"): four
    /// per vertex (a cloth folded flat onto itself has about that many), or
    /// what one binding holds.
    pub cloth_capacity: u32,
    /// The flat rest grid's spacing along a row and down a column, m
    /// (`cpu::self_contact::grid_spacing`).
    pub rest_spacing: [f32; 2],
    /// Entries of each vertex's contact list (stage "self_contact"):
    /// `cpu::self_contact::PAIRS_PER_VERTEX`, or what one binding holds.
    pub cloth_per_vertex: u32,
    /// `self_contact.mass_ratio` times the vertex mass, kg
    /// (`cpu::self_contact::Band::limit`).
    pub cloth_limit: f32,
    /// Steps of [`Params::dt`] per step of `solver.dt` (`Scene::substeps`).
    pub substeps: u32,
    /// The uniform's size is a multiple of 16 bytes.
    pub pad: [u32; 3],
}

/// Clock and run statistics kept on the GPU. A step of `solver.dt` is
/// [`Params::substeps`] solves; its sums and maxima run over them.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct StepState {
    /// Substeps of h ([`Params::dt`]) since t = 0 on the body's clock: the
    /// simulated time is clock × h, formed as `f32(clock) * h` where a
    /// kernel needs it (one rounding, so no drift; an `f32` sum of h was
    /// 0.66 s off by step 100k).
    pub clock: u32,
    /// Steps taken.
    pub steps: u32,
    /// PCG iterations summed over every substep.
    pub cg_iterations_total: u32,
    /// Steps any of whose PCG solves broke down (pᵀAp ≤ 0, a non-finite
    /// scalar, or rᵀz ≤ 0 above the tolerance: a preconditioner that is not
    /// positive definite).
    pub cg_breakdowns: u32,
    /// The largest relative residual |S r| / |S b| any step's PCG ended at.
    pub cg_residual_max: f32,
    /// Contacts summed over every substep (stage "measure" adds `contacts_last`).
    pub contacts_total: u32,
    /// Contacts the last substep found (stage "collide" counts them).
    pub contacts_last: u32,
    /// The deepest the cloth has been inside the body after a solve (before
    /// the push-out moved it onto the surface), in m, as the bit pattern of a non-negative `f32` (so the kernels can take an atomic max).
    pub max_penetration_bits: u32,
    /// PCG iterations of the last step: the most of its substeps'.
    pub last_iterations: u32,
    /// Relative residual |S r| / |S b| the last step's PCG ended at: the
    /// worst of its substeps'.
    pub last_residual: f32,
    /// `health::NOT_FINITE | health::TOO_FAST`, raised by the integrate
    /// pass and kept until the state is replaced.
    pub health: u32,
    /// Self-contact: the most near pairs one detection found (stage
    /// "separate").
    pub self_pairs_max: u32,
    /// Self-contact: steps in which a substep's last detection still found
    /// pairs failing, so that the last resort held vertices.
    pub self_fallbacks: u32,
    /// Self-contact: vertex steps the last resort held, summed over every
    /// step.
    pub self_held_total: u32,
    /// Self-contact: steps in which a detection's near pairs overflowed
    /// the list (its passes walked the cloth again instead: slower, the
    /// same result).
    pub self_overflows: u32,
    /// Self-contact: vertex steps the failsafe changed (impulses, zones or
    /// the last resort), summed over every step.
    pub self_changed_total: u32,
    /// Self-contact: vertex steps impulses changed, summed over every step.
    pub self_pushed_total: u32,
    /// Self-contact: vertex steps moved in impact zones, summed.
    pub self_zoned_total: u32,
    /// Self-contact: vertex steps the body stopped in the failsafe, summed.
    pub self_stopped_total: u32,
    /// Self-contact: detections of near pairs, summed over every substep.
    pub self_detections_total: u32,
    /// Self-contact: the most cloth–cloth contacts one step applied (stage
    /// "self_contact").
    pub cloth_contacts_max: u32,
    /// Self-contact: cloth–cloth contacts left out, summed over every
    /// step (past the list's capacity, or at a vertex in more than
    /// `cpu::self_contact::PAIRS_PER_VERTEX`).
    pub cloth_contacts_dropped: u32,
    /// Which of the three step counts above this step has added to already
    /// (bits of `STEP_*` in wgsl/common.wgsl), so that each counts a step
    /// once whatever its substeps do; cleared by its first solve.
    pub step_flags: u32,
}

/// A cloth–cloth contact and what it adds to the system (mirrors
/// `ClothPair` in wgsl/common.wgsl and `cpu::self_contact::{Pair,
/// PairTerm}`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ClothPair {
    /// `cpu::self_contact::Pair::key`: the vertices, `EDGE_PAIR` on the
    /// first of an edge–edge pair.
    pub key: [u32; 4],
    /// β per vertex.
    pub beta: [f32; 4],
    /// h (f − D_c v_rel).
    pub rhs: [f32; 3],
    /// 1 when applied; 0 when dropped at a crowded vertex.
    pub applied: u32,
    /// B = −(h D_c + h² K_c).
    pub block: Sym3,
    /// Eq. 8's normal force F_c at the step's start (N), which the
    /// friction bound's scale is taken of (`self_contact::bound_scales`).
    pub pushes: f32,
    /// Pads the struct to a multiple of 16 bytes.
    pub pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
/// A contact slot (mirrors `Contact` in wgsl/common.wgsl and
/// `cpu::collide::Contact`): the force on cloth vertex k is β_k f and
/// v_rel = Σ β_k v_k + offset.
pub struct Contact {
    /// Unit normal of the surface, pointing to the side the penetrating
    /// point should be pushed towards.
    pub normal: [f32; 3],
    /// d̃ = d − ε in m, negative in contact.
    pub depth: f32,
    /// β per cloth vertex: (1, 0, 0) vertex–face, minus the barycentric
    /// weights face–vertex.
    pub beta: [f32; 3],
    /// Signed distance d of the penetrating point above the surface, in m.
    pub distance: f32,
    /// u in v_rel: minus the rigid surface's velocity (vertex–face) or the
    /// rigid vertex's velocity (face–vertex), m/s.
    pub offset: [f32; 3],
    /// Nonzero when the slot holds a contact this step.
    pub valid: u32,
    /// The cloth vertices β weighs (vertex–face: the one vertex, three times).
    pub vertices: [u32; 3],
    /// The cloth triangle of a face–vertex contact and the rigid triangle
    /// of a vertex–face one.
    pub triangle: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
/// What a contact adds to the system (mirrors `Response` in
/// wgsl/common.wgsl and `cpu::contact::Response`).
pub struct Response {
    /// Force on the penetrating point in N (cloth vertex k receives β_k f).
    pub force: [f32; 3],
    /// k with K_c = k n nᵀ, the contact stiffness block.
    pub normal_stiffness: f32,
    /// The contact damping block D_c.
    pub damping: Sym3,
    /// Padding to the WGSL size.
    pub pad: [f32; 2],
}

/// Mirrors `RigidFrame` in wgsl/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RigidFrame {
    /// The body's orientation, a unit quaternion (x, y, z, w).
    pub rotation: [f32; 4],
    /// World position of the body's origin at the end of the step, m.
    pub translation: [f32; 3],
    /// Padding to the WGSL layout.
    pub pad0: f32,
    /// The body's velocity at the end of the step, m/s.
    pub velocity: [f32; 3],
    /// Padding to the WGSL layout.
    pub pad1: f32,
}

/// Mirrors `BvhNode` in wgsl/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BvhNode {
    /// Lower corner of the box, in body space.
    pub lo: [f32; 3],
    /// Leaf: first index into the BVH's primitive order; internal: the
    /// left child (the right is `first + 1`).
    pub first: u32,
    /// Upper corner of the box, in body space.
    pub hi: [f32; 3],
    /// Primitives of a leaf; 0 for an internal node.
    pub count: u32,
}

/// A PCG scalars buffer (mirrors `ScalarsAndSizes` in wgsl/pcg.wgsl): the
/// scalars every kernel reads (WGSL `Scalars`, up to `next_groups`), then
/// the dispatch sizes of the next iteration's update and V-cycle.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ScalarsAndSizes {
    /// δ = rᵀz of the current iterate.
    pub delta: f32,
    /// |S b|².
    pub bb: f32,
    /// PCG has converged once rᵀr ≤ this: `cg_tol`² |S b|².
    pub threshold: f32,
    /// Iterations run so far.
    pub iterations: u32,
    /// Nonzero once converged or broken down: later kernels return at once.
    pub done: u32,
    /// Nonzero when PCG broke down (pᵀAp ≤ 0, a non-finite scalar, or rᵀz ≤ 0 above the tolerance (a preconditioner that is not positive definite)).
    pub breakdown: u32,
    /// rᵀr of the current iterate.
    pub rr: f32,
    /// Padding to the WGSL layout.
    pub pad: u32,
    /// `next`'s indirect dispatch, `[workgroups, 1, 1]`: the cloth's while
    /// the solve goes on, one workgroup (which carries the scalars) once done.
    pub next_groups: [u32; 3],
    /// The next iteration's indirect dispatch, `[workgroups, 1, 1]` per
    /// multigrid level (level 0: the cloth); zero workgroups once done.
    pub groups: [u32; 3 * MAX_LEVELS as usize],
    /// The same for a patch sweep of each level: four threads per patch
    /// of a colour ([`colour_grid`](crate::multigrid::colour_grid)).
    pub patch_groups: [u32; 3 * MAX_LEVELS as usize],
}

impl ScalarsAndSizes {
    /// Byte offset of `next`'s indirect dispatch arguments.
    pub fn next_groups_offset() -> u64 {
        std::mem::offset_of!(ScalarsAndSizes, next_groups) as u64
    }

    /// Byte offset of level `l`'s indirect dispatch arguments.
    pub fn groups_offset(l: usize) -> u64 {
        (std::mem::offset_of!(ScalarsAndSizes, groups) + 12 * l) as u64
    }

    /// Byte offset of level `l`'s patch sweeps' indirect dispatch arguments.
    pub fn patch_groups_offset(l: usize) -> u64 {
        (std::mem::offset_of!(ScalarsAndSizes, patch_groups) + 12 * l) as u64
    }
}

/// One multigrid level as the kernels see it (mirrors `Grid` in
/// wgsl/multigrid.wgsl): its grid and where its data lives.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Grid {
    /// 0 for the cloth.
    pub level: u32,
    /// Nodes per row.
    pub nx: u32,
    /// Nodes per column.
    pub ny: u32,
    /// First of its ω D⁻¹ blocks in the operators buffer; 0, and none
    /// kept, on a level the patch smoother smooths.
    pub smoothers_at: u32,
    /// First of its stencil blocks in the operators buffer (coarse levels).
    pub stencil_at: u32,
    /// First of its right-hand side's entries (three packed `f32` a node)
    /// in the vectors buffer.
    pub rhs_at: u32,
    /// First of its correction's entries in the vectors buffer.
    pub correction_at: u32,
    /// First entry of the work vector in the vectors buffer: the level's
    /// residual on the way down, its guess on the way up (one region, as
    /// large as the cloth, shared by every level).
    pub work_at: u32,
    /// First of its patches' inverses in the operators buffer,
    /// [`PATCH_BLOCKS`](crate::multigrid::PATCH_BLOCKS) blocks each, when
    /// the patch smoother smooths it; else
    /// [`NO_PATCHES`](crate::multigrid::NO_PATCHES).
    pub patches_at: u32,
}

impl Grid {
    /// Its nodes.
    pub fn nodes(&self) -> usize {
        self.shape().nodes()
    }

    /// Its grid's shape.
    pub fn shape(&self) -> crate::multigrid::Level {
        crate::multigrid::Level {
            nx: self.nx,
            ny: self.ny,
        }
    }
}

/// A pair of adjacent levels, what one multigrid dispatch works between
/// (mirrors `Hop` in wgsl/multigrid.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct Hop {
    /// The finer level.
    pub fine: Grid,
    /// The next coarser one (unused when `fine` is the coarsest).
    pub coarse: Grid,
    /// The colour of patches a patch sweep of `fine` solves.
    pub colour: u32,
}

/// The static connectivity of the cloth and the body as one `u32` buffer
/// (wgsl/topology.wgsl reads it): the cloth triangles first, so the same
/// buffer is the app's index buffer, then each section at a start aligned
/// to 256 bytes, so a section can also be bound on its own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sections {
    /// Start of the springs (two vertices and the rest length's bits each),
    /// in `u32`s.
    pub springs: u32,
    /// Start of the adjacency: offsets per vertex, then (spring, other vertex) pairs.
    pub adjacency: u32,
    /// Start of the pinned flags, one per vertex (nonzero: pinned).
    pub pinned: u32,
    /// Start of each vertex's triangles: offsets per vertex, then 3 t + corner.
    pub vertex_triangles: u32,
    /// Start of the triangles along each spring: 3 t + edge, twice per
    /// spring, `NO_TRIANGLE` where there is none.
    pub spring_triangles: u32,
    /// Start of the rigid body's triangles (three vertices each).
    pub body_triangles: u32,
    /// Start of the body BVH's primitive order.
    pub bvh_order: u32,
}

/// The topology buffer's contents and where its sections start.
pub fn topology(scene: &Scene) -> (Vec<u32>, Sections) {
    let cloth = &scene.cloth;
    let n = cloth.vertex_count();
    // Vertex → 3 t + corner and spring → 3 t + edge, twice: where the
    // assembly finds the face–vertex contacts.
    let mut per_vertex: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut spring_triangles = vec![[NO_TRIANGLE; 2]; cloth.springs.len()];
    for (ti, (tri, edges)) in cloth
        .triangles
        .iter()
        .zip(&cloth.triangle_springs)
        .enumerate()
    {
        for corner in 0..3 {
            per_vertex[tri[corner] as usize].push(3 * ti as u32 + corner as u32);
            let slot = &mut spring_triangles[edges[corner] as usize];
            let side = if slot[0] == NO_TRIANGLE { 0 } else { 1 };
            slot[side] = 3 * ti as u32 + corner as u32;
        }
    }
    let mut vertex_triangles = vec![0u32];
    let mut list = Vec::new();
    for triangles in per_vertex {
        list.extend(triangles);
        vertex_triangles.push(list.len() as u32);
    }
    vertex_triangles.extend(list);
    let adj = &cloth.adjacency;
    let adjacency = adj.offsets.iter().copied().chain(
        adj.spring
            .iter()
            .zip(&adj.other)
            .flat_map(|(&s, &o)| [s, o]),
    );
    let body = scene.rigid.as_ref();

    let mut data: Vec<u32> = cloth.triangles.iter().flatten().copied().collect();
    let mut section = |items: &mut dyn Iterator<Item = u32>| {
        data.resize(data.len().next_multiple_of(64), 0);
        let at = data.len() as u32;
        data.extend(items);
        at
    };
    let sections = Sections {
        springs: section(
            &mut cloth
                .springs
                .iter()
                .zip(&cloth.rest_lengths)
                .flat_map(|(&[i, j], rest)| [i, j, rest.to_bits()]),
        ),
        adjacency: section(&mut adjacency.into_iter()),
        pinned: section(&mut cloth.pinned.iter().map(|&p| p as u32)),
        vertex_triangles: section(&mut vertex_triangles.into_iter()),
        spring_triangles: section(&mut spring_triangles.into_iter().flatten()),
        body_triangles: section(
            &mut body
                .into_iter()
                .flat_map(|b| b.mesh.triangles.iter().flatten().copied()),
        ),
        bvh_order: section(&mut body.into_iter().flat_map(|b| b.bvh.order.iter().copied())),
    };
    // One word past the last section, so an empty one (no body) still
    // binds within the buffer.
    data.push(0);
    (data, sections)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The size naga gives the WGSL struct `name` in `stage`'s source.
    fn wgsl_size(stage: &str, name: &str) -> usize {
        let source = crate::gpu::shaders::source(
            stage,
            crate::gpu::shaders::Variant {
                mlp_threads: 8,
                split: true,
                subgroups: false,
                vectors: VectorLayout::Packed,
            },
        );
        let module = naga::front::wgsl::parse_str(&source).expect("the stage parses");
        let (_, ty) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no struct {name} in {stage}"));
        ty.inner.size(module.to_ctx()) as usize
    }

    #[test]
    fn sizes_match_the_wgsl_layout() {
        for (stage, name, size) in [
            ("assemble", "Params", size_of::<Params>()),
            ("assemble", "StepState", size_of::<StepState>()),
            ("assemble", "PackedSym3", size_of::<Sym3>()),
            ("assemble", "Contact", size_of::<Contact>()),
            ("assemble", "Response", size_of::<Response>()),
            ("pcg", "ScalarsAndSizes", size_of::<ScalarsAndSizes>()),
            ("multigrid", "Hop", size_of::<Hop>()),
            ("assemble", "RigidFrame", size_of::<RigidFrame>()),
            ("assemble", "BvhNode", size_of::<BvhNode>()),
            ("assemble", "ClothPair", size_of::<ClothPair>()),
        ] {
            assert_eq!(wgsl_size(stage, name), size, "{name}");
        }
        // The packed blocks are 6 floats, without padding.
        assert_eq!(size_of::<Sym3>(), 24);
        assert_eq!(std::mem::offset_of!(Params, gravity), 64);
        assert_eq!(std::mem::offset_of!(Params, rigid_position), 112);
        assert_eq!(std::mem::offset_of!(Params, rigid_rotation), 128);
        assert_eq!(std::mem::offset_of!(Params, motion_vector), 144);
    }
}
