//! Stage "load" (wgsl/load.wgsl; CPU twin cpu/load.rs): the normal force
//! each vertex's cloth–cloth contacts carried in the solve, which bounds
//! the next step's friction.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct Load {
    carry: Bound,
}

impl Load {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Load {
        let buffers = [
            ("x", &b.x),
            ("v", &b.v),
            ("cloth_lists", &b.cloth_lists),
            ("cloth_pairs", &b.cloth_pairs),
            ("cloth_loads", &b.cloth_loads),
        ];
        Load {
            carry: kernels.kernel(Entry::Load).bind(device, &buffers),
        }
    }
}

impl Record for Load {
    fn encode(&self, pass: &mut Pass, r: &Recording) {
        self.carry.dispatch(pass, r.params.n_vertices, WORKGROUP);
    }
}
