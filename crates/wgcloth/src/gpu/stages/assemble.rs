//! Stage "assemble" (wgsl/assemble.wgsl with wgsl/springs.wgsl; CPU twins
//! cpu/springs.rs and cpu/assemble.rs): the springs (thesis eqs. 4–5) and
//! the linearised backward Euler system (eqs. 1–3), gathered per vertex
//! (diagonal blocks and b) and per spring (off-diagonal blocks).

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct Assemble {
    vertex: Bound,
    spring: Bound,
}

impl Assemble {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Assemble {
        let buffers = [
            ("v", &b.v),
            ("x", &b.x),
            ("contacts", &b.contacts),
            ("responses", &b.responses),
            ("triangle_contacts", &b.triangle_contacts),
            ("b", &b.b),
        ];
        let bind = |entry| {
            kernels
                .kernel(entry)
                .bind_parts(device, &buffers, &[&b.topology, &b.matrix])
        };
        Assemble {
            vertex: bind(Entry::AssembleVertex),
            spring: bind(Entry::AssembleSpring),
        }
    }
}

impl Record for Assemble {
    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        self.vertex.dispatch(pass, p.n_vertices, WORKGROUP);
        self.spring.dispatch(pass, p.n_springs, WORKGROUP);
    }
}
