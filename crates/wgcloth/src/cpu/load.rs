//! Stage "load": the normal force each vertex's cloth–cloth contacts
//! carried in the step's solve, which bounds the next step's friction
//! (`self_contact::bound_scales`). Twin of wgsl/load.wgsl.
//!
//! A pair's force over the step is its linearisation at the solved
//! velocities v': h f' = h (f − D_c v_rel) − B Σ β_k v'_k, the pair's
//! right-hand side less its block times v'_rel (`self_contact::respond`).
//! Vertex i carries |β_i| n·f' of it, n the pair's normal at the step's
//! start (the positions have not moved yet).

use glam::Vec3;

use crate::cpu::self_contact::{Pair, PairTerm};

/// Per vertex, into `loads`, the normal force its `pairs` (in key order,
/// with their `terms`) carried at the solved velocities `v` over a step
/// of `h` from positions `x`: Σ |β_i| n·f', at least 0.
pub fn carry(
    pairs: &[Pair],
    terms: &[PairTerm],
    (x, v): (&[Vec3], &[Vec3]),
    h: f32,
    loads: &mut [f32],
) {
    loads.fill(0.0);
    for (p, t) in pairs.iter().zip(terms) {
        let (n, _) = p.normal_depth(x, 0.0);
        let pushed = n.dot(t.rhs - t.block * p.gap(v)) / h;
        for (&i, b) in p.vertices.iter().zip(p.beta) {
            loads[i as usize] += b.abs() * pushed;
        }
    }
    loads.iter_mut().for_each(|l| *l = l.max(0.0));
}
