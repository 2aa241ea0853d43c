//! Divergence: what every step must leave, and when one does not, the
//! vertex where it started. A step fails when a position or velocity is not
//! finite, when a vertex moves faster than `solver.max_speed` (a state
//! exploding before it overflows), or when PCG breaks down (pᵀAp ≤ 0 or a
//! non-finite scalar: A is not positive definite). Both paths raise the
//! first two as flags at the end of the integrate stage (`cpu::integrate::
//! health`, wgsl/integrate.wgsl) and count breakdowns in the pcg stage; the
//! diagnosis runs here for both, on the failing step only, from the state
//! and the system that step left.

use glam::Vec3;
use serde::Serialize;

use crate::math::Sym3;

/// A position or velocity is not finite.
pub const NOT_FINITE: u32 = 1;
/// A vertex is faster than `solver.max_speed`.
pub const TOO_FAST: u32 = 2;

/// Why a run stopped.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Divergence {
    /// The failing step (the state after step − 1 is the last good one).
    pub step: u64,
    /// The vertex where the failure starts.
    pub vertex: u32,
    /// Why, in one line.
    pub reason: String,
}

/// What a failed step left behind.
pub struct FailedStep<'a> {
    /// The failing step, numbered as in [`Divergence::step`].
    pub step: u64,
    /// The integrate stage's flags.
    pub flags: u32,
    /// Whether PCG broke down (pᵀAp ≤ 0 or a non-finite scalar).
    pub breakdown: bool,
    /// A's diagonal blocks and b, as the step assembled them.
    pub diag: &'a [Sym3],
    /// The right-hand side b of A v' = b, one entry per vertex.
    pub b: &'a [Vec3],
    /// The state after the step.
    pub x: &'a [Vec3],
    /// Velocities after the step, m/s.
    pub v: &'a [Vec3],
    /// `solver.max_speed`, m/s, the speed beyond which a step fails.
    pub max_speed: f32,
}

/// Whether a step with these flags and PCG outcome failed.
pub fn failed(flags: u32, breakdown: bool) -> bool {
    flags != 0 || breakdown
}

fn positive_definite(m: &Sym3) -> bool {
    let m = m.to_mat3();
    let minor = m.x_axis.x * m.y_axis.y - m.y_axis.x * m.x_axis.y;
    m.x_axis.x > 0.0 && minor > 0.0 && m.determinant() > 0.0
}

/// The vertex the failure starts at, and why, most specific cause first:
/// a row of the system that is not finite (a force or stiffness at that
/// vertex overflowed; the solve then spreads it to every vertex), a
/// diagonal block that is not positive definite (PCG's breakdown), a state
/// that is not finite, the fastest vertex.
pub fn diagnose(f: &FailedStep) -> Divergence {
    let first = |bad: &dyn Fn(usize) -> bool| (0..f.x.len()).find(|&i| bad(i));
    let fastest = (0..f.v.len())
        .max_by(|&i, &j| f.v[i].length().total_cmp(&f.v[j].length()))
        .unwrap_or(0);
    let at = |i: usize| format!("at ({:.3}, {:.3}, {:.3}) m", f.x[i].x, f.x[i].y, f.x[i].z);
    let (vertex, reason) = if let Some(i) =
        first(&|i| !f.b[i].is_finite() || !f.diag[i].is_finite())
    {
        (
            i,
            "its row of the backward Euler system is not finite (a contact or spring force or stiffness there overflowed)".to_string(),
        )
    } else if f.breakdown {
        match first(&|i| !positive_definite(&f.diag[i])) {
            Some(i) => (
                i,
                "PCG broke down: A's diagonal block there is not positive definite (a negative contact or spring stiffness)".to_string(),
            ),
            None => (
                fastest,
                format!(
                    "PCG broke down (pᵀAp ≤ 0); the fastest vertex moves at {:.3e} m/s {}",
                    f.v[fastest].length(),
                    at(fastest)
                ),
            ),
        }
    } else if let Some(i) = first(&|i| !f.x[i].is_finite() || !f.v[i].is_finite()) {
        (i, "its position or velocity is not finite".to_string())
    } else {
        (
            fastest,
            format!(
                "it moves at {:.3e} m/s {}, beyond solver.max_speed = {} m/s (the state is exploding)",
                f.v[fastest].length(),
                at(fastest),
                f.max_speed
            ),
        )
    };
    Divergence {
        step: f.step,
        vertex: vertex as u32,
        reason,
    }
}
