//! Stage "integrate": x' = x + h v' (backward Euler position update);
//! pinned vertices return to their prescribed positions with zero velocity.
//! Mirrors wgsl/integrate.wgsl.

use glam::Vec3;
use rayon::prelude::*;

use crate::health::{NOT_FINITE, TOO_FAST};
use crate::parallel::GRAIN;
use crate::scene::Cloth;

/// x' = x + h v' for every free vertex, with h = `dt` and v' the solved
/// velocities in `v`; pinned vertices go back to their rest positions with
/// zero velocity.
pub fn integrate(cloth: &Cloth, dt: f32, x: &mut [Vec3], v: &mut [Vec3]) {
    x.par_iter_mut()
        .with_min_len(GRAIN)
        .zip(v.par_iter_mut())
        .enumerate()
        .for_each(|(i, (x, v))| {
            if cloth.pinned[i] {
                *x = cloth.rest_positions[i];
                *v = Vec3::ZERO;
            } else {
                *x += dt * *v;
            }
        });
}

/// The flags a vertex raises after the step: [`NOT_FINITE`], else
/// [`TOO_FAST`] beyond `max_speed` (m/s).
pub fn vertex_health(x: Vec3, v: Vec3, max_speed: f32) -> u32 {
    if !x.is_finite() || !v.is_finite() {
        NOT_FINITE
    } else if v.length_squared() > max_speed * max_speed {
        TOO_FAST
    } else {
        0
    }
}

/// Every vertex's flags, or'ed (wgsl/integrate.wgsl raises the same).
pub fn health(x: &[Vec3], v: &[Vec3], max_speed: f32) -> u32 {
    x.par_iter()
        .with_min_len(GRAIN)
        .zip(v)
        .map(|(x, v)| vertex_health(*x, *v, max_speed))
        .reduce(|| 0, |a, b| a | b)
}
