//! Stage "pcg": the preconditioned conjugate gradient solve of thesis
//! eq. 1 (its matrix: `cpu::assemble::BlockMatrix`), with pinned vertices removed by
//! filtering (Baraff & Witkin's modified PCG). The preconditioner is any
//! [`Precondition`] (`cpu::precondition`): the thesis's [`Jacobi`] or a
//! multigrid V-cycle (`cpu::multigrid`), as `solver.preconditioner` names
//! it. Mirrors wgsl/pcg.wgsl.

use glam::Vec3;
use rayon::prelude::*;

pub use crate::config::{Preconditioner, Smoother};
pub use crate::cpu::assemble::BlockMatrix;
use crate::cpu::multigrid::Multigrid;
use crate::cpu::precondition::jacobi_z;
pub use crate::cpu::precondition::{Jacobi, Precondition};
use crate::parallel::GRAIN;
use crate::scene::Cloth;

/// How a PCG solve ended.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PcgOutcome {
    /// CG iterations run.
    pub iterations: u32,
    /// |S r| / |S b| at exit: the relative residual of the free rows, the
    /// same measure whichever preconditioner ran.
    pub relative_residual: f32,
    /// PᵀAp ≤ 0, a non-finite scalar, or rᵀz ≤ 0 above the tolerance (a preconditioner that is not positive definite) stopped the iteration.
    pub breakdown: bool,
}

/// When a solve stops, and how it is preconditioned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveSettings {
    /// The most iterations.
    pub max_iters: u32,
    /// Stop once |S r| ≤ `tol` |S b| (0: run every iteration).
    pub tol: f32,
    /// The preconditioner P.
    pub preconditioner: Preconditioner,
    /// Multigrid's smoother.
    pub smoother: Smoother,
}

/// Where `solver.preconditioner` names a preconditioner: a new one is an
/// arm here and an implementation of [`Precondition`].
impl dyn Precondition {
    /// The preconditioner `settings` ask for, for `cloth`.
    pub fn of(cloth: &Cloth, settings: &SolveSettings) -> Box<dyn Precondition> {
        match settings.preconditioner {
            Preconditioner::Multigrid => Box::new(Multigrid::new(cloth, settings.smoother)),
            Preconditioner::Jacobi => Box::new(Jacobi::default()),
        }
    }
}

/// Work vectors and the preconditioner, kept between steps.
#[derive(Debug, Default)]
pub struct PcgScratch {
    r: Vec<Vec3>,
    z: Vec<Vec3>,
    p: Vec<Vec3>,
    q: Vec<Vec3>,
    preconditioner: Option<Box<dyn Precondition>>,
}

/// Solves A x = b for the free vertices of `cloth`; `x` holds the initial
/// guess on entry, and pinned entries keep their value (the prescribed
/// velocity). Stops after `max_iters` or once the relative residual is at
/// most `tol`.
///
/// Each iteration is fused passes, as on the GPU: q = S A p with pᵀq; the
/// x and r updates with rᵀr and, for Jacobi, z = P⁻¹ r with rᵀz
/// (multigrid's z is a V-cycle); and the p update. The GPU's `next` forms
/// the new p where the product reads it; here that recomputation cost
/// more than the pass it saves (`wgcloth bench --iterations`). Dot
/// products sum in f64 so a 10⁶-term sum keeps the digits the convergence
/// test reads.
pub fn solve(
    a: &BlockMatrix,
    cloth: &Cloth,
    b: &[Vec3],
    x: &mut [Vec3],
    settings: SolveSettings,
    s: &mut PcgScratch,
) -> PcgOutcome {
    // On a worker thread, a pass shorter than its grain (a small coarse
    // level's) runs in place; from another thread each one would be sent to
    // the pool and waited for.
    rayon::scope(|_| {
        let (adj, pinned) = (&cloth.adjacency, &cloth.pinned[..]);
        let n = b.len();
        let PcgScratch {
            r,
            z,
            p,
            q,
            preconditioner,
        } = s;
        for v in [&mut *r, &mut *z, &mut *p, &mut *q] {
            v.resize(n, Vec3::ZERO);
        }
        // One built for another cloth or other settings is rebuilt.
        let (kind, smoother) = (settings.preconditioner, settings.smoother);
        if !(preconditioner.as_ref()).is_some_and(|pc| pc.fits(cloth, kind, smoother)) {
            *preconditioner = None;
        }
        let pc = preconditioner.get_or_insert_with(|| <dyn Precondition>::of(cloth, &settings));
        pc.setup(a, cloth);
        let fused = pc.diagonal().is_some();
        let bb = b
            .par_iter()
            .with_min_len(GRAIN)
            .enumerate()
            .filter(|&(i, _)| !pinned[i])
            .map(|(_, bi)| bi.length_squared() as f64)
            .sum::<f64>();
        // r = S (b − A x), z = P⁻¹ r, p = z.
        a.multiply(adj, x, q);
        let mut rr = r
            .par_iter_mut()
            .with_min_len(GRAIN)
            .enumerate()
            .map(|(i, r)| {
                *r = if pinned[i] { Vec3::ZERO } else { b[i] - q[i] };
                r.length_squared() as f64
            })
            .sum::<f64>();
        let mut delta = pc.apply(a, cloth, r, z);
        p.copy_from_slice(z);

        let mut out = PcgOutcome::default();
        let threshold = (settings.tol as f64).powi(2) * bb;
        while out.iterations < settings.max_iters && rr > threshold && delta > 0.0 {
            let pq = a.multiply_filtered_dot(adj, pinned, p, q);
            if !(pq > 0.0 && pq.is_finite()) {
                out.breakdown = true;
                break;
            }
            let alpha = (delta / pq) as f32;
            // x += α p and r −= α q with rᵀr; a diagonal P's z = P⁻¹ r and
            // rᵀz in the same pass.
            let diagonal = pc.diagonal();
            let (rr_new, rz) = x
                .par_iter_mut()
                .with_min_len(GRAIN)
                .zip(r.par_iter_mut())
                .zip(z.par_iter_mut())
                .enumerate()
                .map(|(i, ((x, r), z))| {
                    *x += alpha * p[i];
                    *r -= alpha * q[i];
                    let rz = diagonal.map_or(0.0, |d| jacobi_z(*r, d[i], z));
                    (r.length_squared() as f64, rz)
                })
                .reduce(|| (0.0, 0.0), |(a, b), (c, d)| (a + c, b + d));
            rr = rr_new;
            let delta_new = match fused {
                true => rz,
                false => pc.apply(a, cloth, r, z),
            };
            let beta = (delta_new / delta) as f32;
            p.par_iter_mut()
                .with_min_len(GRAIN)
                .zip(&*z)
                .for_each(|(p, z)| *p = *z + beta * *p);
            delta = delta_new;
            out.iterations += 1;
        }
        // A preconditioner that is not positive definite (rᵀz ≤ 0 with the
        // residual above the goal) ends the solve as a breakdown, never as
        // convergence.
        out.breakdown |= !(delta.is_finite() && rr.is_finite()) || (rr > threshold && delta <= 0.0);
        out.relative_residual = if bb > 0.0 {
            (rr.max(0.0) / bb).sqrt() as f32
        } else {
            0.0
        };
        out
    })
}
