//! Host mirrors of the WGSL structs in `wgsl/common.wgsl` (same field
//! order, sizes and alignment; a test checks the sizes), and the packed
//! topology buffer.

use bytemuck::{Pod, Zeroable};

use crate::gpu::constants::NO_TRIANGLE;
use crate::scene::Scene;

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct Params {
    pub n_vertices: u32,
    pub n_springs: u32,
    pub n_triangles: u32,
    pub n_rigid_vertices: u32,
    pub n_rigid_triangles: u32,
    pub model: u32,
    pub has_rigid: u32,
    pub cg_max_iters: u32,
    pub dt: f32,
    pub vertex_mass: f32,
    pub stiffness: f32,
    pub cg_tol: f32,
    pub damping_mass: f32,
    pub damping_stiffness: f32,
    pub thickness: f32,
    pub max_depth: f32,
    pub gravity: [f32; 3],
    pub naive_stiffness: f32,
    pub force_scale: f32,
    pub kn: f32,
    pub kd: f32,
    pub kt: f32,
    pub mu: f32,
    pub motion_kind: u32,
    pub motion_period: f32,
    pub motion_phase: f32,
    pub rigid_position: [f32; 3],
    pub motion_amplitude: f32,
    pub rigid_rotation: [f32; 4],
    pub motion_vector: [f32; 3],
    pub cells_x: u32,
    pub cells_y: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub supertiles_x: u32,
    pub supertiles_y: u32,
    /// Network inputs per row, rows per batch entry (1 + Jacobian
    /// columns) and outputs per row.
    pub net_width: u32,
    pub net_rows: u32,
    pub net_outputs: u32,
    /// `solver.max_speed`: a faster vertex raises `StepState::health`.
    pub max_speed: f32,
    /// Where each section of the topology buffer starts ([`Sections`]).
    pub springs_at: u32,
    pub adjacency_at: u32,
    pub pinned_at: u32,
    pub vertex_triangles_at: u32,
    pub spring_triangles_at: u32,
    pub body_triangles_at: u32,
    pub bvh_order_at: u32,
}

/// Clock and run statistics kept on the GPU.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct StepState {
    pub time: f32,
    pub steps: u32,
    pub cg_iterations_total: u32,
    pub cg_breakdowns: u32,
    pub cg_residual_max: f32,
    pub contacts_total: u32,
    pub contacts_last: u32,
    pub max_penetration_bits: u32,
    pub last_iterations: u32,
    pub last_residual: f32,
    /// `health::NOT_FINITE | health::TOO_FAST`, raised by the integrate
    /// pass and kept until the state is replaced.
    pub health: u32,
    pub pad: u32,
}

/// Mirrors `SpringTerm` in wgsl/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SpringTerm {
    pub force: [f32; 4],
    pub block: Sym3,
}

/// Symmetric 3×3 block: (xx, yy, zz, xy), (xz, yz, 0, 0).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Sym3 {
    pub a: [f32; 4],
    pub b: [f32; 4],
}

impl Sym3 {
    pub fn to_mat3(self) -> glam::Mat3 {
        let [xx, yy, zz, xy] = self.a;
        let [xz, yz, _, _] = self.b;
        glam::Mat3::from_cols_array(&[xx, xy, xz, xy, yy, yz, xz, yz, zz])
    }
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Contact {
    /// `triangle` is the cloth triangle of a face–vertex contact and the
    /// rigid triangle of a vertex–face one.
    pub normal: [f32; 3],
    pub depth: f32,
    pub beta: [f32; 3],
    pub distance: f32,
    pub offset: [f32; 3],
    pub valid: u32,
    pub vertices: [u32; 3],
    pub triangle: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Response {
    pub force: [f32; 3],
    pub normal_stiffness: f32,
    pub damping: Sym3,
}

/// Mirrors `RigidFrame` in wgsl/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RigidFrame {
    pub rotation: [f32; 4],
    pub translation: [f32; 3],
    pub pad0: f32,
    pub velocity: [f32; 3],
    pub pad1: f32,
}

/// Mirrors `BvhNode` in wgsl/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BvhNode {
    pub lo: [f32; 3],
    pub first: u32,
    pub hi: [f32; 3],
    pub count: u32,
}

/// PCG scalars (mirrors `Scalars` in wgsl/pcg.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct Scalars {
    pub delta: f32,
    pub delta0: f32,
    pub threshold: f32,
    pub iterations: u32,
    pub done: u32,
    pub breakdown: u32,
    pub pad: [u32; 2],
}

/// The static connectivity of the cloth and the body as one `u32` buffer
/// (wgsl/topology.wgsl reads it): the cloth triangles first, so the same
/// buffer is the app's index buffer, then each section at a start aligned
/// to 256 bytes, so a section can also be bound on its own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sections {
    pub springs: u32,
    pub adjacency: u32,
    pub pinned: u32,
    pub vertex_triangles: u32,
    pub spring_triangles: u32,
    pub body_triangles: u32,
    pub bvh_order: u32,
}

/// The topology buffer's contents and where its sections start.
pub fn topology(scene: &Scene) -> (Vec<u32>, Sections) {
    let cloth = &scene.cloth;
    let n = cloth.vertex_count();
    // Vertex → 3 t + corner and spring → (triangle, edge) × 2: where the
    // assembly finds the face–vertex contacts.
    let mut per_vertex: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut spring_triangles = vec![[NO_TRIANGLE; 4]; cloth.springs.len()];
    for (ti, (tri, edges)) in cloth
        .triangles
        .iter()
        .zip(&cloth.triangle_springs)
        .enumerate()
    {
        for corner in 0..3 {
            per_vertex[tri[corner] as usize].push(3 * ti as u32 + corner as u32);
            let slot = &mut spring_triangles[edges[corner] as usize];
            let side = if slot[0] == NO_TRIANGLE { 0 } else { 2 };
            slot[side] = ti as u32;
            slot[side + 1] = corner as u32;
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
        springs: section(&mut cloth.springs.iter().flatten().copied()),
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
    (data, sections)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_match_the_wgsl_layout() {
        assert_eq!(size_of::<Params>(), 224);
        assert_eq!(size_of::<SpringTerm>(), 48);
        assert_eq!(size_of::<StepState>(), 48);
        assert_eq!(size_of::<Sym3>(), 32);
        assert_eq!(size_of::<Contact>(), 64);
        assert_eq!(size_of::<Response>(), 48);
        assert_eq!(size_of::<Scalars>(), 32);
        assert_eq!(size_of::<RigidFrame>(), 48);
        assert_eq!(size_of::<BvhNode>(), 32);
        assert_eq!(std::mem::offset_of!(Params, gravity), 64);
        assert_eq!(std::mem::offset_of!(Params, rigid_position), 112);
        assert_eq!(std::mem::offset_of!(Params, rigid_rotation), 128);
        assert_eq!(std::mem::offset_of!(Params, motion_vector), 144);
    }
}
