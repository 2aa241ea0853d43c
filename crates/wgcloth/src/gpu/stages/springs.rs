//! Stage "springs" (wgsl/springs.wgsl; CPU twin cpu/springs.rs): each
//! spring's force and stiffness block (thesis eqs. 4–5).

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;

pub(crate) struct Springs {
    springs: Bound,
}

impl Springs {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Springs {
        let buffers = [
            ("x", &b.x),
            ("topology", &b.topology),
            ("rest_lengths", &b.rest_lengths),
            ("spring_terms", &b.spring_terms),
        ];
        Springs {
            springs: kernels.kernel(Entry::Springs).bind(device, &buffers),
        }
    }

    pub(crate) fn encode(&self, pass: &mut wgpu::ComputePass, p: &Params) -> u32 {
        self.springs.dispatch(pass, p.n_springs, WORKGROUP);
        1
    }
}
