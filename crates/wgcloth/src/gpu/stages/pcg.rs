//! Stage "pcg" (wgsl/pcg.wgsl; CPU twin cpu/pcg.rs): Jacobi-preconditioned
//! CG on A v' = b with pinned rows filtered, its scalars and convergence
//! test on the GPU.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;

/// The kernels bound with the scalars one way round: reading scalars
/// `[k]`, writing `[1 - k]`.
struct Side {
    init: Bound,
    init_scalars: Bound,
    spmv: Bound,
    update: Bound,
    direction: Bound,
    finish: Bound,
}

pub(crate) struct Pcg {
    /// The scalars ping-pong between two buffers, one iteration each way.
    sides: [Side; 2],
}

impl Pcg {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Pcg {
        let side = |k: usize| {
            let buffers = [
                ("matrix", &b.matrix),
                ("topology", &b.topology),
                ("b", &b.b),
                ("x", &b.v),
                ("r", &b.r),
                ("z", &b.z),
                ("p", &b.p),
                ("q", &b.q),
                ("inv_diag", &b.inv_diag),
                ("partials", &b.partials),
                ("scalars_in", &b.scalars[k]),
                ("scalars_out", &b.scalars[1 - k]),
                ("state", &b.state),
            ];
            let bind = |entry| kernels.kernel(entry).bind(device, &buffers);
            Side {
                init: bind(Entry::PcgInit),
                init_scalars: bind(Entry::PcgInitScalars),
                spmv: bind(Entry::PcgSpmv),
                update: bind(Entry::PcgUpdate),
                direction: bind(Entry::PcgDirection),
                finish: bind(Entry::PcgFinish),
            }
        };
        Pcg {
            sides: [side(0), side(1)],
        }
    }

    /// `cg_max_iters` iterations of three dispatches each; converged
    /// kernels return at once.
    pub(crate) fn encode(&self, pass: &mut wgpu::ComputePass, p: &Params) -> u32 {
        let n = p.n_vertices;
        self.sides[0].init.dispatch(pass, n, WORKGROUP);
        // Writes scalars[0], which iteration 0 reads.
        self.sides[1].init_scalars.dispatch(pass, 1, 1);
        let iters = p.cg_max_iters as usize;
        for it in 0..iters {
            let side = &self.sides[it % 2];
            side.spmv.dispatch(pass, n, WORKGROUP);
            side.update.dispatch(pass, n, WORKGROUP);
            side.direction.dispatch(pass, n, WORKGROUP);
        }
        // The last iteration wrote scalars[iters % 2].
        self.sides[iters % 2].finish.dispatch(pass, 1, 1);
        3 + 3 * iters as u32
    }
}
