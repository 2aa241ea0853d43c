//! The kinematic rigid body: a triangle mesh in body space, its broad-phase
//! hierarchy (built once), and the prescribed translation it follows.

use glam::{Quat, Vec3};

use crate::bvh::{Bvh, triangle_boxes};
use crate::scene::mesh::TriMesh;

/// Prescribed translation of the body's origin; the orientation is fixed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Motion {
    Static,
    /// Constant velocity.
    Linear {
        velocity: Vec3,
    },
    /// `amplitude · sin(2π t / period + phase)` along the unit `axis`
    /// (the thesis scene: along world z through the cloth).
    Sinusoid {
        axis: Vec3,
        amplitude: f32,
        period: f32,
        phase: f32,
    },
}

impl Motion {
    pub fn displacement(&self, t: f32) -> Vec3 {
        match *self {
            Motion::Static => Vec3::ZERO,
            Motion::Linear { velocity } => velocity * t,
            Motion::Sinusoid {
                axis,
                amplitude,
                period,
                phase,
            } => axis * amplitude * (std::f32::consts::TAU * t / period + phase).sin(),
        }
    }

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
                axis * amplitude * w * (w * t + phase).cos()
            }
        }
    }
}

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
    pub rotation: Quat,
    /// Position of the body origin at t = 0, before the motion.
    pub position: Vec3,
    pub motion: Motion,
}

impl RigidBody {
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
