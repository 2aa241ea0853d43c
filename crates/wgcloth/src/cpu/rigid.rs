//! Stage "rigid": places the kinematic body at time t. Mirrors wgsl/rigid.wgsl.

use glam::{Quat, Vec3};
use rayon::prelude::*;

use crate::parallel::GRAIN;
use crate::scene::RigidBody;

/// The rigid body in world space at one instant.
#[derive(Clone, Debug, Default)]
pub struct RigidFrame {
    /// Body → world rotation (the body's fixed orientation).
    pub rotation: Quat,
    /// World position of the body origin, m.
    pub translation: Vec3,
    /// Velocity of every point of the body (it only translates).
    pub velocity: Vec3,
    /// The mesh's vertices in world space.
    pub vertices: Vec<Vec3>,
    /// The mesh's unit outward vertex normals in world space.
    pub vertex_normals: Vec<Vec3>,
}

impl RigidFrame {
    /// World → body space.
    #[inline]
    pub fn to_body(&self, p: Vec3) -> Vec3 {
        self.rotation.inverse() * (p - self.translation)
    }
}

/// Places `body` at time `t` (s): fills `frame` with its rotation,
/// translation, velocity, and world-space vertices and vertex normals.
pub fn transform(body: &RigidBody, t: f32, frame: &mut RigidFrame) {
    frame.rotation = body.rotation;
    frame.translation = body.translation(t);
    frame.velocity = body.motion.velocity(t);
    let (r, tr) = (frame.rotation, frame.translation);
    frame.vertices.resize(body.mesh.vertices.len(), Vec3::ZERO);
    frame
        .vertex_normals
        .resize(body.mesh.vertices.len(), Vec3::ZERO);
    frame
        .vertices
        .par_iter_mut()
        .with_min_len(GRAIN)
        .zip(frame.vertex_normals.par_iter_mut())
        .zip(body.mesh.vertices.par_iter().zip(&body.vertex_normals))
        .for_each(|((x, n), (xb, nb))| {
            *x = r * *xb + tr;
            *n = r * *nb;
        });
}
