//! Stage "separate" (wgsl/separate.wgsl and wgsl/impact.wgsl; CPU twins
//! cpu/separate.rs and cpu/impact.rs): each cloth vertex's step changed
//! where the cloth would otherwise pass through itself (issue 23).

use crate::cpu::impact::{IMPULSE_ROUNDS, ZONE_ROUNDS};
use crate::cpu::separate::{DETECTIONS, ROUNDS};
use crate::gpu::buffers::Buffers;
use crate::gpu::constants::{WORKGROUP, self_header, separations};
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct Separate {
    start: Bound,
    /// A detection: the steps it is for, the tile hierarchy refitted to what the steps sweep
    /// (the tiles, then collide's super-tiles over them), and the walks.
    sweep: Bound,
    prepare: Bound,
    tiles: Bound,
    supertiles: Bound,
    walks: Bound,
    plan_walked: Bound,
    /// A pass over the pairs: over the list, and over the walks again
    /// where the list overflowed (one of the two is empty).
    test: [Bound; 2],
    plan_tested: Bound,
    push: [Bound; 2],
    apply: Bound,
    plan_phase: Bound,
    hook: [Bound; 2],
    jump: Bound,
    spread: Bound,
    clear: Bound,
    plan_detect: Bound,
    plan_last: Bound,
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
            ("contacts", &b.contacts),
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
            start: bind(Entry::SeparateStart),
            sweep: bind(Entry::SeparateSweep),
            prepare: bind(Entry::SeparatePrepare),
            tiles: bind(Entry::SeparateTiles),
            supertiles: bind(Entry::CollideSupertiles),
            walks: bind(Entry::SeparateWalks),
            plan_walked: bind(Entry::SeparatePlanWalked),
            test: [
                bind(Entry::SeparateTestPairs),
                bind(Entry::SeparateTestWalks),
            ],
            plan_tested: bind(Entry::SeparatePlanTested),
            push: [
                bind(Entry::SeparatePushPairs),
                bind(Entry::SeparatePushWalks),
            ],
            apply: bind(Entry::SeparateApply),
            plan_phase: bind(Entry::SeparatePlanPhase),
            hook: [
                bind(Entry::SeparateHookPairs),
                bind(Entry::SeparateHookWalks),
            ],
            jump: bind(Entry::SeparateJump),
            spread: bind(Entry::SeparateSpread),
            clear: bind(Entry::SeparateClear),
            plan_detect: bind(Entry::SeparatePlanDetect),
            plan_last: bind(Entry::SeparatePlanLast),
            round: bind(Entry::SeparateRound),
            recheck: bind(Entry::SeparateRecheck),
            settle: bind(Entry::SeparateSettle),
            plan: bind(Entry::SeparatePlan),
            finish: bind(Entry::SeparateFinish),
            separations: b.separations.clone(),
            dispatches: b.self_dispatches.clone(),
        }
    }
}

impl Record for Separate {
    /// Before the pass: the header's words start at 0.
    fn clear(&self, encoder: &mut wgpu::CommandEncoder, p: &Params) {
        let at = 4 * (separations::WORDS * p.n_vertices) as u64;
        encoder.clear_buffer(&self.separations, at, Some(4 * self_header::WORDS as u64));
    }

    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        let n = p.n_vertices;
        let direct = |pass: &mut Pass, kernel: &Bound, invocations, group| {
            kernel.dispatch(pass, invocations, group);
        };
        // Every other dispatch is sized by the `plan_*` kernel before it:
        // empty once the step has settled.
        let indirect = |pass: &mut Pass, kernel: &Bound, word: u32| {
            kernel.dispatch_indirect(pass, &self.dispatches, 4 * word as u64);
        };
        let pairs = |pass: &mut Pass, kernels: &[Bound; 2]| {
            indirect(pass, &kernels[0], self_header::LIST_ARGS);
            indirect(pass, &kernels[1], self_header::RETEST_ARGS);
        };
        direct(pass, &self.start, n, WORKGROUP);
        direct(pass, &self.plan_detect, 1, 1);
        for detection in 0..DETECTIONS {
            indirect(pass, &self.sweep, self_header::WALKS_ARGS);
            indirect(pass, &self.prepare, self_header::PREPARE_ARGS);
            indirect(pass, &self.tiles, self_header::TILES_ARGS);
            indirect(pass, &self.supertiles, self_header::SUPERTILES_ARGS);
            indirect(pass, &self.walks, self_header::WALKS_ARGS);
            direct(pass, &self.plan_walked, 1, 1);
            if detection + 1 == DETECTIONS {
                pairs(pass, &self.test);
                direct(pass, &self.plan_last, 1, 1);
                for _ in 0..ROUNDS {
                    indirect(pass, &self.round, self_header::ROUND_ARGS);
                    indirect(pass, &self.recheck, self_header::RECHECK_ARGS);
                    indirect(pass, &self.settle, self_header::SETTLE_ARGS);
                    direct(pass, &self.plan, 1, 1);
                }
                break;
            }
            for _ in 0..IMPULSE_ROUNDS {
                pairs(pass, &self.test);
                direct(pass, &self.plan_tested, 1, 1);
                pairs(pass, &self.push);
                indirect(pass, &self.apply, self_header::VERTEX_ARGS);
            }
            direct(pass, &self.plan_phase, 1, 1);
            for _ in 0..ZONE_ROUNDS {
                pairs(pass, &self.hook);
                direct(pass, &self.plan_tested, 1, 1);
                for kernel in [&self.jump, &self.spread, &self.clear] {
                    indirect(pass, kernel, self_header::VERTEX_ARGS);
                }
            }
            direct(pass, &self.plan_detect, 1, 1);
        }
        direct(pass, &self.finish, n, WORKGROUP);
    }
}
