//! Stage "pcg" (wgsl/pcg.wgsl; CPU twin cpu/pcg.rs): preconditioned CG on
//! A v' = b with pinned rows filtered, its scalars and convergence test on
//! the GPU, preconditioned by any `Precondition` (Jacobi, or the
//! multigrid V-cycle of `stages::multigrid`). An iteration is two
//! dispatches with Jacobi, and the V-cycle's besides with multigrid; each
//! iteration's are sized by the GPU (`next`
//! to one workgroup, which carries the scalars, after convergence), so the
//! iterations recorded after convergence do almost no work. Where the
//! preconditioner runs the whole solve in one dispatch
//! ([`Precondition::whole`]), a solve is `init`, `init_scalars`, that
//! dispatch, `correct` and `finish`, whatever its iterations.

use crate::gpu::buffers::{Buffers, multigrid_grids, solved_whole};
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::ScalarsAndSizes;
use crate::gpu::pass::Pass;
use crate::gpu::stages::multigrid::Multigrid;
use crate::gpu::stages::precondition::{Jacobi, Precondition};
use crate::gpu::stages::{Record, Recording};
use crate::scene::Scene;

/// The kernels bound with the ping-pong buffers one way round: scalars
/// `[k]` and direction `[k]` as this iteration's (`spmv` writes the first
/// direction there), scalars and direction `[1 - k]` as the next one's.
struct Side {
    init: Bound,
    init_scalars: Bound,
    spmv: Bound,
    update: Bound,
    advance: Bound,
    next: Bound,
    conclude: Bound,
    finish: Bound,
    /// With cloth–cloth contacts: x into this side's direction, for the
    /// couplings' part of r = S (b − A x) after `init`, and of q = S A p
    /// after `spmv` or `next` (this side's direction and scalars, which
    /// they just wrote).
    couple_start: Bound,
    couple_init: Bound,
    couple: Bound,
}

pub(crate) struct Pcg {
    /// The scalars and the direction ping-pong between two buffers each.
    sides: [Side; 2],
    /// The scalars, which hold each iteration's dispatch sizes.
    scalars: [wgpu::Buffer; 2],
    /// x += e after a whole solve.
    correct: Bound,
    preconditioner: Box<dyn Precondition>,
}

impl Pcg {
    pub(crate) fn new(kernels: &Kernels, device: &wgpu::Device, b: &Buffers, scene: &Scene) -> Pcg {
        let side = |k: usize| {
            let buffers = [
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
                ("scalars_spare", &b.scalars[k]),
                ("state", &b.state),
                ("cloth_lists", &b.cloth_lists),
                ("cloth_pairs", &b.cloth_pairs),
            ];
            let bind = |entry| {
                kernels
                    .kernel(entry)
                    .bind_parts(device, &buffers, &[&b.topology, &b.matrix])
            };
            Side {
                init: bind(Entry::PcgInit),
                init_scalars: bind(Entry::PcgInitScalars),
                spmv: bind(Entry::PcgSpmv),
                update: bind(Entry::PcgUpdate),
                advance: bind(Entry::PcgAdvance),
                next: bind(Entry::PcgNext),
                conclude: bind(Entry::PcgConclude),
                finish: bind(Entry::PcgFinish),
                couple_start: bind(Entry::PcgCoupleStart),
                couple_init: bind(Entry::PcgCoupleInit),
                couple: bind(Entry::PcgCouple),
            }
        };
        Pcg {
            sides: [side(0), side(1)],
            scalars: b.scalars.clone(),
            correct: kernels
                .kernel(Entry::PcgCorrect)
                .bind(device, &[("x", &b.v), ("zq", &b.zq)]),
            // Multigrid's levels, or none where Jacobi preconditions.
            preconditioner: match Multigrid::new(
                kernels,
                device,
                b,
                &multigrid_grids(scene),
                solved_whole(scene),
            ) {
                Some(multigrid) => Box::new(multigrid),
                None => Box::new(Jacobi),
            },
        }
    }
}

impl Record for Pcg {
    /// `r.cg_iterations` iterations (at most `cg_max_iters`); once
    /// converged, `next` and `conclude` carry the scalars and the rest dispatch no workgroups. Iteration
    /// `it` reads side `it % 2`: `next` ends iteration `it − 1` (side
    /// `(it − 1) % 2`) and starts `it`.
    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let p = r.params;
        let n = p.n_vertices;
        let iters = r.cg_iterations.min(p.cg_max_iters) as usize;
        let pc = &self.preconditioner;
        pc.encode_setup(pass);
        if let Some(solve) = pc.whole() {
            // `init_scalars` (side 1) leaves scalars[0], which `solve`
            // carries to the end and `finish` (side 0) reads.
            self.sides[0].init.dispatch(pass, n, WORKGROUP);
            self.sides[1].init_scalars.dispatch(pass, 1, 1);
            solve.dispatch(pass, 1, 1);
            self.correct.dispatch(pass, n, WORKGROUP);
            self.sides[0].finish.dispatch(pass, 1, 1);
            return;
        }
        let coupled = p.cloth_thickness > 0.0;
        self.sides[0].init.dispatch(pass, n, WORKGROUP);
        if coupled {
            self.sides[0].couple_start.dispatch(pass, n, WORKGROUP);
            self.sides[0].couple_init.dispatch(pass, n, WORKGROUP);
        }
        pc.encode_apply(pass, None);
        // Writes scalars[0], which iteration 0 reads, and the dispatch sizes
        // into scalars[1] too.
        self.sides[1].init_scalars.dispatch(pass, 1, 1);
        // Iteration `it`'s x, r and z, sized by the scalars it reads.
        let update = |pass: &mut Pass, it: usize| {
            let (side, args) = (&self.sides[it % 2], &self.scalars[it % 2]);
            let at = ScalarsAndSizes::groups_offset(0);
            match pc.fused() {
                true => side.update.dispatch_indirect(pass, args, at),
                false => {
                    side.advance.dispatch_indirect(pass, args, at);
                    pc.encode_apply(pass, Some(args));
                }
            }
        };
        if iters > 0 {
            self.sides[0].spmv.dispatch(pass, n, WORKGROUP);
            if coupled {
                self.sides[0].couple.dispatch(pass, n, WORKGROUP);
            }
            update(pass, 0);
            for it in 1..iters {
                let prev = (it - 1) % 2;
                let args = (&self.scalars[prev], ScalarsAndSizes::next_groups_offset());
                self.sides[prev]
                    .next
                    .dispatch_indirect(pass, args.0, args.1);
                if coupled {
                    self.sides[1 - prev]
                        .couple
                        .dispatch_indirect(pass, args.0, args.1);
                }
                update(pass, it);
            }
            self.sides[(iters - 1) % 2].conclude.dispatch(pass, 1, 1);
        }
        // The last iteration wrote scalars[iters % 2].
        self.sides[iters % 2].finish.dispatch(pass, 1, 1);
    }
}
