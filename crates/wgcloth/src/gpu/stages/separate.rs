//! Stage "separate" (wgsl/separate.wgsl; CPU twin cpu/separate.rs): each
//! cloth vertex's step held back where the cloth would otherwise pass
//! through itself (issue 23).

use crate::cpu::separate::ROUNDS;
use crate::gpu::buffers::Buffers;
use crate::gpu::constants::{WORKGROUP, self_header};
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;

pub(crate) struct Separate {
    /// The tile hierarchy refitted to what the step sweeps (the tiles, then
    /// collide's super-tiles over them).
    tiles: Bound,
    supertiles: Bound,
    prepare: Bound,
    walks: Bound,
    round: Bound,
    recheck: Bound,
    settle: Bound,
    plan: Bound,
    finish: Bound,
    separations: wgpu::Buffer,
    dispatches: wgpu::Buffer,
}

impl Separate {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers) -> Separate {
        let buffers = [
            ("x_start", &b.x_start),
            ("x", &b.x),
            ("v", &b.v),
            ("bounds", &b.bounds),
            ("separations", &b.separations),
            ("pairs", &b.self_pairs),
            ("state", &b.state),
            ("dispatches", &b.self_dispatches),
        ];
        let bind = |entry| {
            kernels
                .kernel(entry)
                .bind_parts(device, &buffers, &[&b.topology])
        };
        Separate {
            tiles: bind(Entry::SeparateTiles),
            supertiles: bind(Entry::CollideSupertiles),
            prepare: bind(Entry::SeparatePrepare),
            walks: bind(Entry::SeparateWalks),
            round: bind(Entry::SeparateRound),
            recheck: bind(Entry::SeparateRecheck),
            settle: bind(Entry::SeparateSettle),
            plan: bind(Entry::SeparatePlan),
            finish: bind(Entry::SeparateFinish),
            separations: b.separations.clone(),
            dispatches: b.self_dispatches.clone(),
        }
    }

    /// Before the pass: the header's counters start at 0.
    pub(crate) fn clear(&self, encoder: &mut wgpu::CommandEncoder, p: &Params) {
        let at = 8 * p.n_vertices as u64;
        encoder.clear_buffer(&self.separations, at, Some(4 * self_header::WORDS as u64));
    }

    pub(crate) fn encode(&self, pass: &mut wgpu::ComputePass, p: &Params) -> u32 {
        let n = p.n_vertices;
        self.prepare.dispatch(pass, n, WORKGROUP);
        self.tiles.dispatch(pass, p.tiles_x * p.tiles_y, WORKGROUP);
        let supertiles = p.supertiles_x * p.supertiles_y;
        self.supertiles.dispatch(pass, supertiles, WORKGROUP);
        self.walks.dispatch(pass, n, WORKGROUP);
        let args = |word: u32| 4 * word as u64;
        self.plan.dispatch(pass, 1, 1);
        // Each round's dispatches are sized by `plan`: nothing once settled,
        // the walks again in place of the list when it overflowed.
        for _ in 0..ROUNDS {
            for (kernel, at) in [
                (&self.round, self_header::ROUND_ARGS),
                (&self.recheck, self_header::RECHECK_ARGS),
                (&self.settle, self_header::SETTLE_ARGS),
            ] {
                kernel.dispatch_indirect(pass, &self.dispatches, args(at));
            }
            self.plan.dispatch(pass, 1, 1);
        }
        self.finish.dispatch(pass, n, WORKGROUP);
        6 + 4 * ROUNDS
    }
}
