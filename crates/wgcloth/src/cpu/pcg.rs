//! Stage "pcg": the system matrix and the Jacobi-preconditioned conjugate
//! gradient solve of thesis eq. 1, with pinned vertices removed by
//! filtering (Baraff & Witkin's modified PCG). Mirrors wgsl/pcg.wgsl.

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use crate::cpu::GRAIN;
use crate::scene::cloth::Adjacency;

/// A = M − hD − h²K in the cloth's sparsity: one diagonal block per vertex
/// and one symmetric off-diagonal block per spring, A_ij = A_ji = `off[s]`
/// (every other coupling — the face contacts — lies on a spring's pair).
#[derive(Clone, Debug, Default)]
pub struct BlockMatrix {
    /// A_ii, one block per vertex.
    pub diag: Vec<Mat3>,
    /// A_ij = A_ji, one block per spring (i, j), in spring order.
    pub off: Vec<Mat3>,
}

impl BlockMatrix {
    /// The zero matrix of a cloth with `vertices` vertices and `springs`
    /// springs.
    pub fn new(vertices: usize, springs: usize) -> BlockMatrix {
        BlockMatrix {
            diag: vec![Mat3::ZERO; vertices],
            off: vec![Mat3::ZERO; springs],
        }
    }

    /// Row i of A x, gathered over the vertex's springs.
    fn row(&self, adj: &Adjacency, x: &[Vec3], i: usize) -> Vec3 {
        let mut acc = self.diag[i] * x[i];
        for k in adj.range(i) {
            acc += self.off[adj.spring[k] as usize] * x[adj.other[k] as usize];
        }
        acc
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
    /// √(rᵀP⁻¹r / bᵀP⁻¹b) at exit: the preconditioned relative residual.
    pub relative_residual: f32,
    /// pᵀAp ≤ 0 or a non-finite scalar stopped the iteration.
    pub breakdown: bool,
}

/// Work vectors, kept between steps.
#[derive(Clone, Debug, Default)]
pub struct PcgScratch {
    r: Vec<Vec3>,
    z: Vec<Vec3>,
    p: Vec<Vec3>,
    q: Vec<Vec3>,
    inv_diag: Vec<Vec3>,
}

/// Solves A x = b for the free vertices; `x` holds the initial guess on
/// entry, and pinned entries keep their value (the prescribed velocity).
/// Stops after `max_iters` or when the preconditioned residual falls below
/// `tol` relative to b's (tol = 0: run every iteration).
///
/// Each iteration is three fused passes, as on the GPU: q = S A p with
/// pᵀq; the x, r, z updates with rᵀz; and the p update. Dot products sum in
/// f64 so a 10⁶-term sum keeps the digits the convergence test reads.
#[allow(clippy::too_many_arguments)]
pub fn solve(
    a: &BlockMatrix,
    adj: &Adjacency,
    pinned: &[bool],
    b: &[Vec3],
    x: &mut [Vec3],
    max_iters: u32,
    tol: f32,
    s: &mut PcgScratch,
) -> PcgOutcome {
    let n = b.len();
    for v in [&mut s.r, &mut s.z, &mut s.p, &mut s.q, &mut s.inv_diag] {
        v.resize(n, Vec3::ZERO);
    }
    // Jacobi preconditioner; zero on pinned rows, which is the filter S.
    s.inv_diag
        .par_iter_mut()
        .with_min_len(GRAIN)
        .enumerate()
        .for_each(|(i, m)| {
            let d = a.diag[i];
            *m = if pinned[i] {
                Vec3::ZERO
            } else {
                Vec3::new(d.x_axis.x, d.y_axis.y, d.z_axis.z).recip()
            };
        });
    let delta0 = b
        .par_iter()
        .with_min_len(GRAIN)
        .zip(&s.inv_diag)
        .map(|(bi, m)| (*bi * *m).dot(*bi) as f64)
        .sum::<f64>();
    // r = S (b − A x), p = P⁻¹ r.
    a.multiply(adj, x, &mut s.q);
    let mut delta =
        s.r.par_iter_mut()
            .with_min_len(GRAIN)
            .zip(s.p.par_iter_mut())
            .enumerate()
            .map(|(i, (r, p))| {
                *r = if pinned[i] { Vec3::ZERO } else { b[i] - s.q[i] };
                *p = *r * s.inv_diag[i];
                r.dot(*p) as f64
            })
            .sum::<f64>();

    let mut out = PcgOutcome::default();
    let threshold = (tol as f64).powi(2) * delta0;
    while out.iterations < max_iters && delta > threshold && delta > 0.0 {
        let pq = a.multiply_filtered_dot(adj, pinned, &s.p, &mut s.q);
        if !(pq > 0.0 && pq.is_finite()) {
            out.breakdown = true;
            break;
        }
        let alpha = (delta / pq) as f32;
        let delta_new = x
            .par_iter_mut()
            .with_min_len(GRAIN)
            .zip(s.r.par_iter_mut())
            .zip(s.z.par_iter_mut())
            .enumerate()
            .map(|(i, ((x, r), z))| {
                *x += alpha * s.p[i];
                *r -= alpha * s.q[i];
                *z = *r * s.inv_diag[i];
                r.dot(*z) as f64
            })
            .sum::<f64>();
        let beta = (delta_new / delta) as f32;
        s.p.par_iter_mut()
            .with_min_len(GRAIN)
            .zip(&s.z)
            .for_each(|(p, z)| *p = *z + beta * *p);
        delta = delta_new;
        out.iterations += 1;
    }
    out.breakdown |= !delta.is_finite();
    out.relative_residual = if delta0 > 0.0 {
        (delta.max(0.0) / delta0).sqrt() as f32
    } else {
        0.0
    };
    out
}
