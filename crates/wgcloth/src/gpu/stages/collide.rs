//! Stage "collide" (wgsl/collide.wgsl; CPU twin cpu/collide.rs): the
//! two-level tile hierarchy over the cloth refitted, then the proximity
//! tests in both directions (thesis 2.3).

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

/// Cells along the cloth's longer side from which the face–vertex search
/// takes a workgroup per rigid vertex (wgsl/collide.wgsl, part (b)): a
/// rigid vertex then has hundreds of triangles within reach. On a coarser
/// cloth one invocation per rigid vertex is faster on lavapipe (measured
/// from 16² to 256²). On an H200 the whole collide stage took 0.45 ms at
/// 64² with it; the workgroup search was not measured below 256² there.
pub const FACE_VERTEX_TILED_FROM: u32 = 128;

pub(crate) struct Collide {
    tiles: Bound,
    supertiles: Bound,
    vertex_face: Bound,
    face_vertex: Bound,
    face_vertex_serial: Bound,
    order: Bound,
    /// The most workgroups one dispatch may have: `face_vertex` runs one
    /// per rigid vertex, each taking every this-many-th beyond.
    max_groups: u32,
    triangle_contacts: wgpu::Buffer,
}

impl Collide {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Collide {
        let buffers = [
            ("x", &b.x),
            ("body_vertices", &b.body_vertices),
            ("body_face_normals", &b.body_face_normals),
            ("bvh_nodes", &b.bvh_nodes),
            ("rigid", &b.rigid),
            ("frame", &b.frame),
            ("bounds", &b.bounds),
            ("contacts", &b.contacts),
            ("triangle_contacts", &b.triangle_contacts),
            ("state", &b.state),
        ];
        let bind = |entry| {
            kernels
                .kernel(entry)
                .bind_parts(device, &buffers, &[&b.topology])
        };
        Collide {
            tiles: bind(Entry::CollideTiles),
            supertiles: bind(Entry::CollideSupertiles),
            vertex_face: bind(Entry::CollideVertexFace),
            face_vertex: bind(Entry::CollideFaceVertex),
            face_vertex_serial: bind(Entry::CollideFaceVertexSerial),
            order: bind(Entry::CollideOrder),
            max_groups: device.limits().max_compute_workgroups_per_dimension,
            triangle_contacts: b.triangle_contacts.clone(),
        }
    }
}

impl Record for Collide {
    /// Before the pass: face–vertex contacts link into their triangle's
    /// list, as found and in order, so every list starts empty (zero heads).
    /// Cleared whole, the rigid vertices' next entries too (linking writes
    /// each before it is read): one clear for every world of a batch
    /// (`gpu::worlds`), whose regions each start with their heads.
    fn clear(&self, encoder: &mut wgpu::CommandEncoder, _p: &Params) {
        encoder.clear_buffer(&self.triangle_contacts, 0, None);
    }

    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        self.tiles.dispatch(pass, p.tiles_x * p.tiles_y, WORKGROUP);
        let supertiles = p.supertiles_x * p.supertiles_y;
        self.supertiles.dispatch(pass, supertiles, WORKGROUP);
        self.vertex_face.dispatch(pass, p.n_vertices, WORKGROUP);
        if p.cells_x.max(p.cells_y) >= FACE_VERTEX_TILED_FROM {
            self.face_vertex.set(pass);
            pass.dispatch_workgroups(p.n_rigid_vertices.min(self.max_groups));
        } else {
            self.face_vertex_serial
                .dispatch(pass, p.n_rigid_vertices, WORKGROUP);
        }
        self.order.dispatch(pass, p.n_rigid_vertices, WORKGROUP);
    }
}
