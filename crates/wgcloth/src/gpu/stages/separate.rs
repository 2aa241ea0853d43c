//! Stage "separate" (wgsl/separate.wgsl; CPU twin cpu/separate.rs): each
//! cloth vertex's least separation from the cloth it could reach, which
//! bounds its step in the integrate pass (issue 23).

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;

pub(crate) struct Separate {
    /// Collide's refit of the tile hierarchy, for scenes without a body
    /// (where collide does not run).
    tiles: Bound,
    supertiles: Bound,
    prepare: Bound,
    vertices: Bound,
    edges: Bound,
    separations: wgpu::Buffer,
}

impl Separate {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Separate {
        let buffers = [
            ("x", &b.x),
            ("v", &b.v),
            ("bounds", &b.bounds),
            ("separations", &b.separations),
        ];
        let bind = |entry| {
            kernels
                .kernel(entry)
                .bind_parts(device, &buffers, &[&b.topology])
        };
        Separate {
            tiles: bind(Entry::CollideTiles),
            supertiles: bind(Entry::CollideSupertiles),
            prepare: bind(Entry::SeparatePrepare),
            vertices: bind(Entry::SeparateVertices),
            edges: bind(Entry::SeparateEdges),
            separations: b.separations.clone(),
        }
    }

    /// Before the pass: the longest stride, an atomic maximum, starts at 0.
    pub(crate) fn clear(&self, encoder: &mut wgpu::CommandEncoder, p: &Params) {
        encoder.clear_buffer(&self.separations, 4 * p.n_vertices as u64, Some(4));
    }

    pub(crate) fn encode(&self, pass: &mut wgpu::ComputePass, p: &Params) -> u32 {
        let refit = p.has_rigid == 0;
        if refit {
            self.tiles.dispatch(pass, p.tiles_x * p.tiles_y, WORKGROUP);
            let supertiles = p.supertiles_x * p.supertiles_y;
            self.supertiles.dispatch(pass, supertiles, WORKGROUP);
        }
        self.prepare.dispatch(pass, p.n_vertices, WORKGROUP);
        self.vertices.dispatch(pass, p.n_vertices, WORKGROUP);
        self.edges.dispatch(pass, p.n_springs, WORKGROUP);
        3 + 2 * refit as u32
    }
}
