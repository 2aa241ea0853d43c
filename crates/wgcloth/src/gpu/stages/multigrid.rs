//! Stage "pcg"'s multigrid preconditioner (wgsl/multigrid.wgsl; CPU twin
//! cpu/multigrid.rs): the coarse operators rebuilt once a step, then one
//! V-cycle per PCG iteration, each dispatch bound to its pair of levels down
//! to the tail: the levels of at most [`tail_nodes`] nodes, in one dispatch
//! of one workgroup.

use crate::gpu::buffers::{Buffers, groups};
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::{Grid, Scalars};
use crate::multigrid::{tail_from, tail_nodes};

pub(crate) struct Multigrid {
    /// Nodes per level, the cloth first.
    nodes: Vec<u32>,
    /// Per level l < L: level l + 1's operator and smoother.
    galerkin: Vec<Bound>,
    /// Per level l above the tail: level l's residual after pre-smoothing.
    residual: Vec<Bound>,
    /// Per level l above the tail: level l + 1's right-hand side.
    down: Vec<Bound>,
    /// The levels from the tail's first down and back up.
    tail: Bound,
    /// Per level l above the tail: level l's guess.
    guess: Vec<Bound>,
    /// Per level l above the tail: level l's correction (z on the cloth).
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
                    ("bound_hop", &b.hops[l]),
                    ("hop_list", &b.hop_list),
                    ("vectors", &b.vectors),
                    ("r", &b.r),
                    ("zq", &b.zq),
                    ("partials", &b.partials),
                ],
                &[&b.topology, &b.matrix, &b.operators],
            )
        };
        let nodes: Vec<u32> = grids.iter().map(|g| g.nx * g.ny).collect();
        let cpu_adapter = device.adapter_info().device_type == wgpu::DeviceType::Cpu;
        let tail = tail_from(&nodes, tail_nodes(cpu_adapter));
        let hops = |entry, end| (0..end).map(|l| bind(entry, l)).collect();
        Some(Multigrid {
            galerkin: hops(Entry::MgGalerkin, last),
            residual: hops(Entry::MgResidual, tail),
            down: hops(Entry::MgDown, tail),
            tail: bind(Entry::MgTail, tail),
            guess: hops(Entry::MgGuess, tail),
            up: hops(Entry::MgUp, tail),
            nodes,
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
        let above = self.down.len();
        for l in 0..above {
            dispatch(pass, &self.residual[l], l);
            dispatch(pass, &self.down[l], l + 1);
        }
        // One workgroup while the solve goes on: the coarsest level's size.
        dispatch(pass, &self.tail, self.nodes.len() - 1);
        for l in (0..above).rev() {
            dispatch(pass, &self.guess[l], l);
            dispatch(pass, &self.up[l], l);
        }
        4 * above as u32 + 1
    }
}
