//! The kinematic rigid body: a triangle mesh in body space, its broad-phase
//! hierarchy (built once), and the prescribed translation it follows.

use glam::{Quat, Vec3};

use crate::bvh::{Bvh, triangle_boxes};
use crate::scene::mesh::TriMesh;

/// Prescribed translation of the body's origin; the orientation is fixed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    /// The body does not move.
    Static,
    /// Constant velocity.
    Linear {
        /// World velocity in m/s.
        velocity: Vec3,
    },
    /// `amplitude · sin(2π t / period + phase)` along the unit `axis`
    /// (the thesis scene: along world z through the cloth).
    Sinusoid {
        /// Unit direction of travel, world frame.
        axis: Vec3,
        /// Peak displacement in m.
        amplitude: f32,
        /// Period in s.
        period: f32,
        /// Phase at t = 0, radians.
        phase: f32,
    },
}

/// 2π t / period + phase with the whole periods taken out first: at t =
/// 1000 s the angle would otherwise be thousands of radians, where an f32
/// carries little of it and WGSL does not promise `sin`'s accuracy (it
/// does on [−π, π]). Mirrored in wgsl/rigid.wgsl.
fn angle(t: f32, period: f32, phase: f32) -> f32 {
    let cycles = t / period;
    std::f32::consts::TAU * (cycles - cycles.floor()) + phase
}

impl Motion {
    /// The body origin's offset from [`RigidBody::position`] at time `t` (s),
    /// m.
    pub fn displacement(&self, t: f32) -> Vec3 {
        match *self {
            Motion::Static => Vec3::ZERO,
            Motion::Linear { velocity } => velocity * t,
            Motion::Sinusoid {
                axis,
                amplitude,
                period,
                phase,
            } => axis * amplitude * angle(t, period, phase).sin(),
        }
    }

    /// The most [`Motion::velocity`]'s length reaches, m/s.
    pub fn top_speed(&self) -> f32 {
        match *self {
            Motion::Static => 0.0,
            Motion::Linear { velocity } => velocity.length(),
            Motion::Sinusoid {
                amplitude, period, ..
            } => amplitude.abs() * std::f32::consts::TAU / period,
        }
    }

    /// How far beyond [`RigidBody::position`] along unit `direction` the
    /// motion carries the body that [`fall_speed`](crate::scene::fall_speed)
    /// must count, m: a sinusoid's swing along it; none for a body at rest,
    /// nor for a linear motion, which a falling cloth meets at most at its
    /// speed plus the fall to where it starts.
    pub fn deepest(&self, direction: Vec3) -> f32 {
        match *self {
            Motion::Sinusoid {
                axis, amplitude, ..
            } => (amplitude * axis.dot(direction)).abs(),
            Motion::Static | Motion::Linear { .. } => 0.0,
        }
    }

    /// The body's velocity at time `t` (s), m/s: the derivative of
    /// [`Motion::displacement`].
    pub fn velocity(&self, t: f32) -> Vec3 {
        match *self {
            Motion::Static => Vec3::ZERO,
            Motion::Linear { velocity } => velocity,
            Motion::Sinusoid {
                axis,
                amplitude,
                period,
                phase,
            } => {
                let w = std::f32::consts::TAU / period;
                axis * amplitude * w * angle(t, period, phase).cos()
            }
        }
    }
}

/// The kinematic rigid body: its mesh and what is derived from it, in body
/// space, and how it is placed in the world over time.
#[derive(Clone, Debug)]
pub struct RigidBody {
    /// Body-space mesh.
    pub mesh: TriMesh,
    /// Body-space unit outward face normals.
    pub face_normals: Vec<Vec3>,
    /// Body-space unit outward vertex normals.
    pub vertex_normals: Vec<Vec3>,
    /// Hierarchy over the body-space triangles.
    pub bvh: Bvh,
    /// Body → world rotation, fixed for the run.
    pub rotation: Quat,
    /// Position of the body origin at t = 0, before the motion.
    pub position: Vec3,
    /// The prescribed translation of the body origin.
    pub motion: Motion,
}

impl RigidBody {
    /// A body placed by `rotation` and `position`, with its normals and
    /// hierarchy computed from `mesh`.
    pub fn new(mesh: TriMesh, rotation: Quat, position: Vec3, motion: Motion) -> RigidBody {
        let bvh = Bvh::build(&triangle_boxes(&mesh.vertices, &mesh.triangles));
        RigidBody {
            face_normals: mesh.face_normals(),
            vertex_normals: mesh.vertex_normals(),
            bvh,
            mesh,
            rotation,
            position,
            motion,
        }
    }

    /// World translation of the body origin at time t.
    pub fn translation(&self, t: f32) -> Vec3 {
        self.position + self.motion.displacement(t)
    }

    /// The mesh's vertices in the world at time t.
    pub fn placed_vertices(&self, t: f32) -> Vec<Vec3> {
        let at = self.translation(t);
        self.mesh
            .vertices
            .iter()
            .map(|v| self.rotation * *v + at)
            .collect()
    }
}
