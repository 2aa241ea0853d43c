//! Stage "rigid" (wgsl/rigid.wgsl; CPU twin cpu/rigid.rs): places the body
//! at the end of the step.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct Rigid {
    place: Bound,
}

impl Rigid {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Rigid {
        let buffers = [
            ("body_vertices", &b.body_vertices),
            ("body_normals", &b.body_normals),
            ("rigid", &b.rigid),
            ("frame", &b.frame),
            ("state", &b.state),
        ];
        Rigid {
            place: kernels.kernel(Entry::Rigid).bind(device, &buffers),
        }
    }
}

impl Record for Rigid {
    /// Returns the dispatches recorded.
    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        // At least one invocation: it also writes the frame.
        self.place
            .dispatch(pass, p.n_rigid_vertices.max(1), WORKGROUP);
    }
}
