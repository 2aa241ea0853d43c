//! Stage "pcg"'s multigrid preconditioner (wgsl/multigrid.wgsl; CPU twin
//! cpu/multigrid.rs): the coarse operators rebuilt once a step, then one
//! V-cycle per PCG iteration, each dispatch bound to its pair of levels.

use crate::gpu::buffers::{Buffers, groups};
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::{Grid, Scalars};

pub(crate) struct Multigrid {
    /// Nodes per level, the cloth first.
    nodes: Vec<u32>,
    /// Per level l < L: level l + 1's operator and smoother.
    galerkin: Vec<Bound>,
    /// Per level l < L: level l's residual after pre-smoothing.
    residual: Vec<Bound>,
    /// Per level l < L: level l + 1's right-hand side.
    down: Vec<Bound>,
    /// The coarsest level's sweeps.
    coarse: Bound,
    /// Per level l < L: level l's guess.
    guess: Vec<Bound>,
    /// Per level l < L: level l's correction (z on the cloth).
    up: Vec<Bound>,
}

impl Multigrid {
    /// `None` when the scene is preconditioned by Jacobi (no levels).
    pub(crate) fn new(
        kernels: &Kernels,
        device: &wgpu::Device,
        b: &Buffers,
        grids: &[Grid],
    ) -> Option<Multigrid> {
        let last = grids.len().checked_sub(1).filter(|&l| l > 0)?;
        let bind = |entry, l: usize| {
            kernels.kernel(entry).bind_parts(
                device,
                &[
                    ("hop", &b.hops[l]),
                    ("vectors", &b.vectors),
                    ("r", &b.r),
                    ("zq", &b.zq),
                    ("partials", &b.partials),
                ],
                &[&b.topology, &b.matrix, &b.operators],
            )
        };
        let hops = |entry| (0..last).map(|l| bind(entry, l)).collect();
        Some(Multigrid {
            nodes: grids.iter().map(|g| g.nx * g.ny).collect(),
            galerkin: hops(Entry::MgGalerkin),
            residual: hops(Entry::MgResidual),
            down: hops(Entry::MgDown),
            coarse: bind(Entry::MgCoarse, last),
            guess: hops(Entry::MgGuess),
            up: hops(Entry::MgUp),
        })
    }

    /// Every coarse level's operator from this step's A, finest first.
    pub(crate) fn encode_setup(&self, pass: &mut wgpu::ComputePass) -> u32 {
        for (l, galerkin) in self.galerkin.iter().enumerate() {
            galerkin.dispatch(pass, self.nodes[l + 1], WORKGROUP);
        }
        self.galerkin.len() as u32
    }

    /// One V-cycle on the PCG residual, leaving z and partial rᵀz: sized
    /// on the host, or from `scalars`' per-level sizes (zero once the solve
    /// is over).
    pub(crate) fn encode_cycle(
        &self,
        pass: &mut wgpu::ComputePass,
        scalars: Option<&wgpu::Buffer>,
    ) -> u32 {
        let dispatch = |pass: &mut wgpu::ComputePass, kernel: &Bound, level: usize| match scalars {
            Some(args) => kernel.dispatch_indirect(pass, args, Scalars::groups_offset(level)),
            None => {
                kernel.set(pass);
                pass.dispatch_workgroups(groups(self.nodes[level]), 1, 1);
            }
        };
        let levels = self.down.len();
        for l in 0..levels {
            dispatch(pass, &self.residual[l], l);
            dispatch(pass, &self.down[l], l + 1);
        }
        dispatch(pass, &self.coarse, levels);
        for l in (0..levels).rev() {
            dispatch(pass, &self.guess[l], l);
            dispatch(pass, &self.up[l], l);
        }
        4 * levels as u32 + 1
    }
}
