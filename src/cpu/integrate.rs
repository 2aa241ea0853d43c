//! Stage "integrate": x' = x + h v' (backward Euler position update);
//! pinned vertices return to their prescribed positions with zero velocity.
//! Mirrors wgsl/integrate.wgsl.

use glam::Vec3;
use rayon::prelude::*;

use crate::cpu::GRAIN;
use crate::scene::Cloth;

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
