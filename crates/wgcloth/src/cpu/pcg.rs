//! Stage "pcg": the system matrix and the preconditioned conjugate
//! gradient solve of thesis eq. 1, with pinned vertices removed by
//! filtering (Baraff & Witkin's modified PCG). The preconditioner is the
//! thesis's Jacobi or a multigrid V-cycle (`cpu::multigrid`). Mirrors
//! wgsl/pcg.wgsl.

use glam::Vec3;
use rayon::prelude::*;

pub use crate::config::{Preconditioner, Smoother};
use crate::cpu::multigrid::Multigrid;
use crate::cpu::self_contact::Couplings;
use crate::math::Sym3;
use crate::multigrid::Level;
use crate::parallel::GRAIN;
use crate::scene::Cloth;
use crate::scene::cloth::Adjacency;

/// A = M − hD − h²K in the cloth's sparsity: one diagonal block per vertex
/// and one symmetric off-diagonal block per spring, A_ij = A_ji = `off[s]`
/// (the face contacts' couplings lie on a spring's pair), and the
/// cloth–cloth contacts' couplings, which do not.
#[derive(Clone, Debug, Default)]
pub struct BlockMatrix {
    /// A_ii, one block per vertex.
    pub diag: Vec<Sym3>,
    /// A_ij = A_ji, one block per spring (i, j), in spring order.
    pub off: Vec<Sym3>,
    /// The cloth–cloth contacts' off-diagonal blocks (none without
    /// self-contact forces); the preconditioners see only their diagonal.
    pub couplings: Couplings,
}

impl BlockMatrix {
    /// The zero matrix of a cloth with `vertices` vertices and `springs`
    /// springs.
    pub fn new(vertices: usize, springs: usize) -> BlockMatrix {
        BlockMatrix {
            diag: vec![Sym3::ZERO; vertices],
            off: vec![Sym3::ZERO; springs],
            couplings: Couplings::default(),
        }
    }

    /// Row i of A x, gathered over the vertex's springs.
    fn row(&self, adj: &Adjacency, x: &[Vec3], i: usize) -> Vec3 {
        let mut acc = self.diag[i] * x[i];
        for k in adj.range(i) {
            acc += self.off[adj.spring[k] as usize] * x[adj.other[k] as usize];
        }
        acc + self.couplings.row(i, x)
    }

    /// y = A x.
    pub fn multiply(&self, adj: &Adjacency, x: &[Vec3], y: &mut [Vec3]) {
        y.par_iter_mut()
            .with_min_len(GRAIN)
            .enumerate()
            .for_each(|(i, yi)| *yi = self.row(adj, x, i));
    }

    /// y = S A x with pinned rows zeroed, returning xᵀy (one pass).
    pub fn multiply_filtered_dot(
        &self,
        adj: &Adjacency,
        pinned: &[bool],
        x: &[Vec3],
        y: &mut [Vec3],
    ) -> f64 {
        y.par_iter_mut()
            .with_min_len(GRAIN)
            .enumerate()
            .map(|(i, yi)| {
                *yi = if pinned[i] {
                    Vec3::ZERO
                } else {
                    self.row(adj, x, i)
                };
                yi.dot(x[i]) as f64
            })
            .sum()
    }
}

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

/// Work vectors and the multigrid hierarchy, kept between steps.
#[derive(Clone, Debug, Default)]
pub struct PcgScratch {
    r: Vec<Vec3>,
    z: Vec<Vec3>,
    p: Vec<Vec3>,
    q: Vec<Vec3>,
    inv_diag: Vec<Vec3>,
    multigrid: Option<Multigrid>,
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
        for v in [&mut s.r, &mut s.z, &mut s.p, &mut s.q, &mut s.inv_diag] {
            v.resize(n, Vec3::ZERO);
        }
        match settings.preconditioner {
            Preconditioner::Multigrid => {
                // A hierarchy built for another cloth or smoother is rebuilt.
                let fits = |mg: &Multigrid| {
                    mg.levels()[0] == Level::of(cloth) && mg.smoother() == settings.smoother
                };
                if !s.multigrid.as_ref().is_some_and(fits) {
                    s.multigrid = Some(Multigrid::new(cloth, settings.smoother));
                }
                if let Some(mg) = &mut s.multigrid {
                    mg.setup(a, cloth);
                }
            }
            // The diagonal; zero on pinned rows, which is the filter S.
            Preconditioner::Jacobi => s
                .inv_diag
                .par_iter_mut()
                .with_min_len(GRAIN)
                .enumerate()
                .for_each(|(i, m)| {
                    *m = if pinned[i] {
                        Vec3::ZERO
                    } else {
                        a.diag[i].diagonal().recip()
                    };
                }),
        }
        let bb = b
            .par_iter()
            .with_min_len(GRAIN)
            .enumerate()
            .filter(|&(i, _)| !pinned[i])
            .map(|(_, bi)| bi.length_squared() as f64)
            .sum::<f64>();
        // r = S (b − A x), z = P⁻¹ r, p = z.
        a.multiply(adj, x, &mut s.q);
        let mut rr =
            s.r.par_iter_mut()
                .with_min_len(GRAIN)
                .enumerate()
                .map(|(i, r)| {
                    *r = if pinned[i] { Vec3::ZERO } else { b[i] - s.q[i] };
                    r.length_squared() as f64
                })
                .sum::<f64>();
        let mut delta = precondition(a, cloth, settings.preconditioner, s);
        s.p.copy_from_slice(&s.z);
        let jacobi = settings.preconditioner == Preconditioner::Jacobi;

        let mut out = PcgOutcome::default();
        let threshold = (settings.tol as f64).powi(2) * bb;
        while out.iterations < settings.max_iters && rr > threshold && delta > 0.0 {
            let pq = a.multiply_filtered_dot(adj, pinned, &s.p, &mut s.q);
            if !(pq > 0.0 && pq.is_finite()) {
                out.breakdown = true;
                break;
            }
            let alpha = (delta / pq) as f32;
            // x += α p and r −= α q with rᵀr; Jacobi's z = P⁻¹ r and rᵀz
            // in the same pass.
            let (rr_new, rz) = x
                .par_iter_mut()
                .with_min_len(GRAIN)
                .zip(s.r.par_iter_mut())
                .zip(s.z.par_iter_mut())
                .enumerate()
                .map(|(i, ((x, r), z))| {
                    *x += alpha * s.p[i];
                    *r -= alpha * s.q[i];
                    let rz = match jacobi {
                        true => jacobi_z(*r, s.inv_diag[i], z),
                        false => 0.0,
                    };
                    (r.length_squared() as f64, rz)
                })
                .reduce(|| (0.0, 0.0), |(a, b), (c, d)| (a + c, b + d));
            rr = rr_new;
            let delta_new = match jacobi {
                true => rz,
                false => precondition(a, cloth, settings.preconditioner, s),
            };
            let beta = (delta_new / delta) as f32;
            s.p.par_iter_mut()
                .with_min_len(GRAIN)
                .zip(&s.z)
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

/// z = P⁻¹ r, returning rᵀz.
fn precondition(
    a: &BlockMatrix,
    cloth: &Cloth,
    preconditioner: Preconditioner,
    s: &mut PcgScratch,
) -> f64 {
    match (preconditioner, &mut s.multigrid) {
        (Preconditioner::Multigrid, Some(mg)) => mg.apply(a, cloth, &s.r, &mut s.z),
        _ => {
            s.z.par_iter_mut()
                .with_min_len(GRAIN)
                .zip(&s.r)
                .zip(&s.inv_diag)
                .map(|((z, r), m)| jacobi_z(*r, *m, z))
                .sum()
        }
    }
}

/// Jacobi's z = P⁻¹ r at one vertex (`inv_diag` is P⁻¹'s diagonal),
/// returning its rᵀz.
#[inline]
fn jacobi_z(r: Vec3, inv_diag: Vec3, z: &mut Vec3) -> f64 {
    *z = r * inv_diag;
    r.dot(*z) as f64
}
