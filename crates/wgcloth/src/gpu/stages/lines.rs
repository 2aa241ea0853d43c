//! Stage "lines" (wgsl/lines.wgsl; CPU twin render/lines.rs): each
//! contact's force as a segment, for drawing; not part of a step.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;
use crate::gpu::pass::Pass;

pub(crate) struct Lines {
    force_lines: Bound,
}

impl Lines {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Lines {
        let buffers = [
            ("x", &b.x),
            ("rigid", &b.rigid),
            ("contacts", &b.contacts),
            ("responses", &b.responses),
            ("line_scale", &b.line_scale),
            ("lines", &b.lines),
        ];
        Lines {
            force_lines: kernels.kernel(Entry::Lines).bind(device, &buffers),
        }
    }

    pub(crate) fn encode(&self, pass: &mut Pass, p: &Params) {
        let slots = p.n_vertices + p.n_rigid_vertices;
        self.force_lines.dispatch(pass, slots, WORKGROUP);
    }
}
