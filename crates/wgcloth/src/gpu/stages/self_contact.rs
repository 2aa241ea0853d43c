//! Stage "self_contact" (wgsl/self_contact.wgsl; CPU twin
//! cpu/self_contact.rs): the cloth's contacts with itself, their eqs. 8–9
//! forces and blocks added to A and b (issue 23). The blocks outside the
//! springs' pattern are applied in the solve (`pcg::couple`).

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::{WORKGROUP, cloth_header};
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct SelfContact {
    cells: Bound,
    /// The tile hierarchy refitted to the cells (separate's tiles, then
    /// collide's super-tiles over them).
    tiles: Bound,
    supertiles: Bound,
    walks: Bound,
    link: Bound,
    sort: Bound,
    respond: Bound,
    gather: Bound,
    lists: wgpu::Buffer,
}

impl SelfContact {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> SelfContact {
        let buffers = [
            ("x", &b.x),
            ("v", &b.v),
            ("bounds", &b.bounds),
            ("cloth_lists", &b.cloth_lists),
            ("cloth_pairs", &b.cloth_pairs),
            ("b", &b.b),
            ("state", &b.state),
            ("cloth_loads", &b.cloth_loads),
        ];
        let bind = |entry| {
            kernels
                .kernel(entry)
                .bind_parts(device, &buffers, &[&b.topology, &b.matrix])
        };
        SelfContact {
            cells: bind(Entry::SelfContactCells),
            tiles: bind(Entry::SeparateTiles),
            supertiles: bind(Entry::CollideSupertiles),
            walks: bind(Entry::SelfContactWalks),
            link: bind(Entry::SelfContactLink),
            sort: bind(Entry::SelfContactSort),
            respond: bind(Entry::SelfContactRespond),
            gather: bind(Entry::SelfContactGather),
            lists: b.cloth_lists.clone(),
        }
    }
}

impl Record for SelfContact {
    /// Before the pass: the header and each vertex's counts start at 0.
    fn clear(&self, encoder: &mut wgpu::CommandEncoder, p: &Params) {
        let words = cloth_header::WORDS as u64 + 2 * p.n_vertices as u64;
        encoder.clear_buffer(&self.lists, 0, Some(4 * words));
    }

    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        let n = p.n_vertices;
        self.cells.dispatch(pass, p.cells_x * p.cells_y, WORKGROUP);
        self.tiles.dispatch(pass, p.tiles_x * p.tiles_y, WORKGROUP);
        let supertiles = p.supertiles_x * p.supertiles_y;
        self.supertiles.dispatch(pass, supertiles, WORKGROUP);
        self.walks.dispatch(pass, n, WORKGROUP);
        self.link.dispatch(pass, p.cloth_capacity, WORKGROUP);
        self.sort.dispatch(pass, n, WORKGROUP);
        self.respond.dispatch(pass, p.cloth_capacity, WORKGROUP);
        self.gather.dispatch(pass, n, WORKGROUP);
    }
}
