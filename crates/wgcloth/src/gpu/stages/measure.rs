//! Stage "measure" (wgsl/measure.wgsl; CPU twin cpu/measure.rs): the
//! deepest any cloth vertex is inside the body, folded into the run's, and
//! the push-out of every vertex inside onto the surface.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct Measure {
    measure: Bound,
}

impl Measure {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Measure {
        let buffers = [
            ("x", &b.x),
            ("v", &b.v),
            ("body_vertices", &b.body_vertices),
            ("body_face_normals", &b.body_face_normals),
            ("bvh_nodes", &b.bvh_nodes),
            ("frame", &b.frame),
            ("state", &b.state),
        ];
        Measure {
            measure: kernels
                .kernel(Entry::Measure)
                .bind_parts(device, &buffers, &[&b.topology]),
        }
    }
}

impl Record for Measure {
    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        self.measure.dispatch(pass, p.n_vertices, WORKGROUP);
    }
}
