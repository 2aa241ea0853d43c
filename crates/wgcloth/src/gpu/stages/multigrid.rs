//! Stage "pcg"'s multigrid preconditioner (wgsl/multigrid.wgsl; CPU twin
//! cpu/multigrid.rs): the coarse operators (and the patch smoother's
//! inverses) rebuilt once a step, then one V-cycle per PCG iteration, each
//! dispatch bound to its pair of levels down to the tail: the levels of at
//! most [`tail_nodes`] nodes, in one dispatch of one workgroup. A small
//! cloth's solve runs whole instead, PCG and V-cycle in one workgroup
//! (`solve`, where `gpu::buffers::solved_whole`).

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels, LevelKind, Levels};
use crate::gpu::layout::{Grid, ScalarsAndSizes};
use crate::gpu::pass::Pass;
use crate::gpu::stages::precondition::Precondition;
use crate::multigrid::{
    NO_PATCHES, PATCH_COLOURS, patch_grid, patch_threads, tail_from, tail_nodes,
};

/// The patch smoother's kernels, per level above the tail.
struct Patches {
    /// Per level but the coarsest: its patches' inverses.
    inverses: Vec<Bound>,
    /// Per level above the tail and colour: the forward sweep, down.
    down: Vec<[Bound; PATCH_COLOURS]>,
    /// The same, backward, up.
    up: Vec<[Bound; PATCH_COLOURS]>,
}

pub(crate) struct Multigrid {
    /// The levels, the cloth first.
    grids: Vec<Grid>,
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
    /// Per level l above the tail: level l's correction (z on the cloth);
    /// with patches, the cloth's rᵀz alone.
    up: Vec<Bound>,
    /// With the patch smoother.
    patches: Option<Patches>,
    /// The whole solve, where the scene's is ([`Precondition::whole`]).
    solve: Option<Bound>,
}

impl Multigrid {
    /// `None` when the scene is preconditioned by Jacobi (no levels).
    pub(crate) fn new(
        kernels: &Kernels,
        device: &wgpu::Device,
        b: &Buffers,
        grids: &[Grid],
        whole: bool,
    ) -> Option<Multigrid> {
        let last = grids.len().checked_sub(1).filter(|&l| l > 0)?;
        let buffers = |l: usize, colour: usize| {
            [
                ("bound_hop", &b.hops[l][colour]),
                ("hop_list", &b.hop_list),
                ("vectors", &b.vectors),
                ("r", &b.r),
                ("zq", &b.zq),
                ("partials", &b.partials),
                // `solve` reads the scalars `init_scalars` leaves first.
                ("scalars", &b.scalars[0]),
            ]
        };
        let parted = [&b.topology, &b.matrix, &b.operators];
        // Every level above the coarsest is smoothed alike.
        let patched = grids[0].patches_at != NO_PATCHES;
        let bind_as = |entry, l: usize, colour: usize, levels| {
            let kind = LevelKind {
                levels,
                patches: patched,
            };
            kernels
                .kernel(entry)
                .bind_level(device, &buffers(l, colour), &parted, Some(kind))
        };
        // Each kernel bound to hop l works on level l, fixed in its pipeline.
        let bind = |entry, l: usize, colour: usize| {
            let levels = if l == 0 {
                Levels::Cloth
            } else {
                Levels::Coarse
            };
            bind_as(entry, l, colour, levels)
        };
        let nodes: Vec<u32> = grids.iter().map(|g| g.nodes() as u32).collect();
        let cpu_adapter = device.adapter_info().device_type == wgpu::DeviceType::Cpu;
        let tail = tail_from(&nodes, tail_nodes(cpu_adapter));
        let hops = |entry, end| (0..end).map(|l| bind(entry, l, 0)).collect();
        let colours = |entry, end| {
            (0..end)
                .map(|l| std::array::from_fn(|c| bind(entry, l, c)))
                .collect()
        };
        let patches = patched.then(|| Patches {
            inverses: hops(Entry::MultigridPatches, last),
            down: colours(Entry::MultigridPatchDown, tail),
            up: colours(Entry::MultigridPatchUp, tail),
        });
        // With patches only the cloth's `up` runs (its rᵀz).
        let ups = if patches.is_some() { 1 } else { tail };
        Some(Multigrid {
            galerkin: hops(Entry::MultigridGalerkin, last),
            residual: hops(Entry::MultigridResidual, tail),
            down: hops(Entry::MultigridDown, tail),
            // The tail walks the coarse levels from its first.
            tail: bind_as(Entry::MultigridTail, tail, 0, Levels::Coarse),
            guess: hops(Entry::MultigridGuessUp, tail),
            up: hops(Entry::MultigridUp, ups),
            patches,
            // Its V-cycle starts at the cloth.
            solve: whole.then(|| bind_as(Entry::MultigridSolve, 0, 0, Levels::Any)),
            grids: grids.to_vec(),
        })
    }
}

impl Precondition for Multigrid {
    /// Every coarse level's operator from this step's A, finest first, then
    /// every level's patch inverses.
    fn encode_setup(&self, pass: &mut Pass) {
        for (l, galerkin) in self.galerkin.iter().enumerate() {
            galerkin.dispatch(pass, self.grids[l + 1].nodes() as u32, WORKGROUP);
        }
        if let Some(p) = &self.patches {
            for (l, inverses) in p.inverses.iter().enumerate() {
                let (px, py) = patch_grid(self.grids[l].shape());
                inverses.dispatch(pass, px * py, WORKGROUP);
            }
        }
    }

    fn whole(&self) -> Option<&Bound> {
        self.solve.as_ref()
    }

    /// One V-cycle on the PCG residual, leaving z and partial rᵀz: sized
    /// on the host, or from `scalars`' per-level sizes (zero once the solve
    /// is over).
    fn encode_apply(&self, pass: &mut Pass, scalars: Option<&wgpu::Buffer>) {
        // A kernel over level l's nodes, or over its patch sweep's threads.
        let dispatch = |pass: &mut Pass, kernel: &Bound, level: usize, sweep: bool| match scalars {
            Some(args) => {
                let offset = match sweep {
                    true => ScalarsAndSizes::patch_groups_offset(level),
                    false => ScalarsAndSizes::groups_offset(level),
                };
                kernel.dispatch_indirect(pass, args, offset);
            }
            None => {
                let shape = self.grids[level].shape();
                let threads = match sweep {
                    true => patch_threads(shape),
                    false => shape.nodes() as u32,
                };
                kernel.dispatch(pass, threads, WORKGROUP);
            }
        };
        let above = self.down.len();
        for l in 0..above {
            if let Some(p) = &self.patches {
                for sweep in &p.down[l] {
                    dispatch(pass, sweep, l, true);
                }
            }
            dispatch(pass, &self.residual[l], l, false);
            dispatch(pass, &self.down[l], l + 1, false);
        }
        // One workgroup while the solve goes on: the coarsest level's size.
        dispatch(pass, &self.tail, self.grids.len() - 1, false);
        for l in (0..above).rev() {
            dispatch(pass, &self.guess[l], l, false);
            if let Some(p) = &self.patches {
                for sweep in p.up[l].iter().rev() {
                    dispatch(pass, sweep, l, true);
                }
            }
            if let Some(up) = self.up.get(l) {
                dispatch(pass, up, l, false);
            }
        }
    }
}
