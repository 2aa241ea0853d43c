//! The springs of stage "assemble": force and stiffness block of every
//! spring (thesis 2.2, eqs. 4–5). Mirrors wgsl/springs.wgsl; the CPU keeps
//! one term per spring for the assembly to gather, where the GPU computes
//! each where it is gathered.

use glam::Vec3;
use rayon::prelude::*;

use crate::math::Sym3;
use crate::parallel::GRAIN;
use crate::scene::Cloth;

/// Force on the spring's first vertex i (the second gets the opposite) and
/// the block K_s = ∂f_i/∂x_j, so K_ii −= K_s and K_ij += K_s (eq. 5).
///
/// With Δx = x_j − x_i, l = |Δx|, d = Δx / l:
/// f_i = E (l − L) d and K_s = E [ (L/l) d dᵀ + (1 − L/l) I ] (eq. 4,
/// rewritten with the unit direction). Under compression (l < L) the
/// matrix keeps 1 − L/l at 0 so K stays negative semidefinite and the
/// implicit system positive definite; the force is never clamped.
pub fn spring(xi: Vec3, xj: Vec3, rest: f32, stiffness: f32) -> (Vec3, Sym3) {
    let dx = xj - xi;
    let l = dx.length();
    if l <= f32::MIN_POSITIVE {
        // Coincident endpoints: no direction, hence no force; the block
        // stays isotropic so the system is still well posed.
        return (Vec3::ZERO, Sym3::ZERO);
    }
    let d = dx / l;
    let ratio = rest / l;
    let force = stiffness * (l - rest) * d;
    let block = stiffness
        * (ratio * Sym3::outer(d) + Sym3::from_diagonal(Vec3::splat((1.0 - ratio).max(0.0))));
    (force, block)
}

/// Evaluates every spring at positions `x`.
pub fn evaluate(cloth: &Cloth, x: &[Vec3], forces: &mut [Vec3], blocks: &mut [Sym3]) {
    forces
        .par_iter_mut()
        .with_min_len(GRAIN)
        .zip(blocks.par_iter_mut())
        .zip(cloth.springs.par_iter().zip(&cloth.rest_lengths))
        .for_each(|((f, k), (&[i, j], &rest))| {
            (*f, *k) = spring(x[i as usize], x[j as usize], rest, cloth.stiffness);
        });
}

/// The largest stretch (l − L) / L over all springs at positions `x`: how
/// far the most-stretched spring is beyond its rest length, as a share of
/// it (0 when none is). A step that flings a vertex shows here
/// (BENCHMARKS.md "One linear solve a step from 128² up"). Shortening is
/// not counted: a fold shortens the bending springs across it, by up to
/// all of their length where it lies flat.
pub fn max_strain(cloth: &Cloth, x: &[Vec3]) -> f32 {
    cloth
        .springs
        .par_iter()
        .with_min_len(GRAIN)
        .zip(&cloth.rest_lengths)
        .map(|(&[i, j], &rest)| ((x[j as usize] - x[i as usize]).length() - rest) / rest)
        .reduce(|| 0.0, f32::max)
}

/// Elastic potential ½ E (l − L)² summed over all springs.
pub fn potential_energy(cloth: &Cloth, x: &[Vec3]) -> f64 {
    cloth
        .springs
        .par_iter()
        .zip(&cloth.rest_lengths)
        .map(|(&[i, j], &rest)| {
            let l = (x[j as usize] - x[i as usize]).length() as f64;
            0.5 * cloth.stiffness as f64 * (l - rest as f64).powi(2)
        })
        .sum()
}
