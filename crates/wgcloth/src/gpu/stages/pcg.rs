//! Stage "pcg" (wgsl/pcg.wgsl; CPU twin cpu/pcg.rs): Jacobi-preconditioned
//! CG on A v' = b with pinned rows filtered, its scalars and convergence
//! test on the GPU, two dispatches per iteration.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;

/// The kernels bound with the ping-pong buffers one way round: scalars
/// `[k]` and direction `[k]` as this iteration's (`spmv` writes the first
/// direction there), scalars and direction `[1 - k]` as the next one's.
struct Side {
    init: Bound,
    init_scalars: Bound,
    spmv: Bound,
    update: Bound,
    next: Bound,
    conclude: Bound,
    finish: Bound,
}

pub(crate) struct Pcg {
    /// The scalars and the direction ping-pong between two buffers each.
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
                ("zq", &b.zq),
                ("p", &b.p[k]),
                ("p_next", &b.p[1 - k]),
                ("inv_diag", &b.inv_diag),
                ("partials", &b.partials),
                ("scalars_in", &b.scalars[k]),
                ("scalars_next", &b.scalars[1 - k]),
                ("state", &b.state),
            ];
            let bind = |entry| kernels.kernel(entry).bind(device, &buffers);
            Side {
                init: bind(Entry::PcgInit),
                init_scalars: bind(Entry::PcgInitScalars),
                spmv: bind(Entry::PcgSpmv),
                update: bind(Entry::PcgUpdate),
                next: bind(Entry::PcgNext),
                conclude: bind(Entry::PcgConclude),
                finish: bind(Entry::PcgFinish),
            }
        };
        Pcg {
            sides: [side(0), side(1)],
        }
    }

    /// `cg_max_iters` iterations; converged kernels return at once.
    /// Iteration `it` reads side `it % 2`: `next` ends iteration `it − 1`
    /// (side `(it − 1) % 2`) and starts `it`.
    pub(crate) fn encode(&self, pass: &mut wgpu::ComputePass, p: &Params) -> u32 {
        let n = p.n_vertices;
        let iters = p.cg_max_iters as usize;
        self.sides[0].init.dispatch(pass, n, WORKGROUP);
        // Writes scalars[0], which iteration 0 reads.
        self.sides[1].init_scalars.dispatch(pass, 1, 1);
        if iters > 0 {
            self.sides[0].spmv.dispatch(pass, n, WORKGROUP);
            self.sides[0].update.dispatch(pass, n, WORKGROUP);
            for it in 1..iters {
                self.sides[(it - 1) % 2].next.dispatch(pass, n, WORKGROUP);
                self.sides[it % 2].update.dispatch(pass, n, WORKGROUP);
            }
            self.sides[(iters - 1) % 2].conclude.dispatch(pass, 1, 1);
        }
        // The last iteration wrote scalars[iters % 2].
        self.sides[iters % 2].finish.dispatch(pass, 1, 1);
        match iters {
            0 => 3,
            _ => 4 + 2 * iters as u32,
        }
    }
}
