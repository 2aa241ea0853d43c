//! Stage "pcg"'s preconditioners (GPU twin: `gpu::stages::precondition`):
//! what the solve asks of one, and the thesis's Jacobi. The multigrid
//! V-cycle is `cpu::multigrid`.

use glam::Vec3;
use rayon::prelude::*;

use crate::config::{Preconditioner, Smoother};
use crate::cpu::assemble::BlockMatrix;
use crate::parallel::GRAIN;
use crate::scene::Cloth;

/// A preconditioner P ≈ A of `cpu::pcg::solve`: set up from A once a
/// solve, then z = P⁻¹ r once an iteration, zero on pinned rows (the
/// filter S). `<dyn Precondition>::of` in `cpu::pcg` builds the one
/// `solver.preconditioner` names.
pub trait Precondition: std::fmt::Debug + Send + Sync {
    /// Whether it was built for `cloth` as `kind` with `smoother`; else the
    /// solve builds another.
    fn fits(&self, cloth: &Cloth, kind: Preconditioner, smoother: Smoother) -> bool;
    /// P from this step's A.
    fn setup(&mut self, a: &BlockMatrix, cloth: &Cloth);
    /// z = P⁻¹ r, returning rᵀz; `r` is zero on pinned rows.
    fn apply(&mut self, a: &BlockMatrix, cloth: &Cloth, r: &[Vec3], z: &mut [Vec3]) -> f64;
    /// P⁻¹ when P is a diagonal: the solve then forms z in the pass that
    /// updates x and r, and never calls [`apply`](Self::apply) after it.
    fn diagonal(&self) -> Option<&[Vec3]> {
        None
    }
}

/// The thesis's preconditioner: A's diagonal.
#[derive(Clone, Debug, Default)]
pub struct Jacobi {
    /// P⁻¹'s diagonal, zero on pinned rows, which is the filter S.
    inv_diag: Vec<Vec3>,
}

impl Precondition for Jacobi {
    fn fits(&self, _: &Cloth, kind: Preconditioner, _: Smoother) -> bool {
        kind == Preconditioner::Jacobi
    }

    fn setup(&mut self, a: &BlockMatrix, cloth: &Cloth) {
        let pinned = &cloth.pinned;
        self.inv_diag.resize(a.diag.len(), Vec3::ZERO);
        self.inv_diag
            .par_iter_mut()
            .with_min_len(GRAIN)
            .enumerate()
            .for_each(|(i, m)| {
                *m = match pinned[i] {
                    true => Vec3::ZERO,
                    false => a.diag[i].diagonal().recip(),
                };
            });
    }

    fn apply(&mut self, _: &BlockMatrix, _: &Cloth, r: &[Vec3], z: &mut [Vec3]) -> f64 {
        z.par_iter_mut()
            .with_min_len(GRAIN)
            .zip(r)
            .zip(&self.inv_diag)
            .map(|((z, r), m)| jacobi_z(*r, *m, z))
            .sum()
    }

    fn diagonal(&self) -> Option<&[Vec3]> {
        Some(&self.inv_diag)
    }
}

/// Jacobi's z = P⁻¹ r at one vertex (`inv_diag` is P⁻¹'s diagonal),
/// returning its rᵀz.
#[inline]
pub(crate) fn jacobi_z(r: Vec3, inv_diag: Vec3, z: &mut Vec3) -> f64 {
    *z = r * inv_diag;
    r.dot(*z) as f64
}
