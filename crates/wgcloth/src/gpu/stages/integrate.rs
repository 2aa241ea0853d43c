//! Stage "integrate" (wgsl/integrate.wgsl; CPU twin cpu/integrate.rs):
//! x' = x + h v', the clock, and the health flags.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct Integrate {
    integrate: Bound,
}

impl Integrate {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Integrate {
        let buffers = [
            ("x", &b.x),
            ("v", &b.v),
            ("rest_positions", &b.rest),
            ("state", &b.state),
            ("x_start", &b.x_start),
        ];
        Integrate {
            integrate: kernels.kernel(Entry::Integrate).bind_parts(
                device,
                &buffers,
                &[&b.topology],
            ),
        }
    }
}

impl Record for Integrate {
    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        self.integrate.dispatch(pass, p.n_vertices, WORKGROUP);
    }
}
