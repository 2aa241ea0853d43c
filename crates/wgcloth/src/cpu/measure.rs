//! Stage "measure": how deep the cloth got inside the rigid body after the
//! step (a ray-parity inside test, then the distance to the nearest face
//! plane containing the projection; no depth limit), the run's deepest.
//! CPU twin of wgsl/measure.wgsl.

use glam::Vec3;
use rayon::prelude::*;

use crate::cpu::GRAIN;
use crate::cpu::collide::{Tolerances, point_triangle};
use crate::cpu::rigid::RigidFrame;
use crate::scene::RigidBody;

/// Whether the ray o + t d (t > 0) crosses triangle (a, b, c) (Möller–Trumbore).
fn ray_crosses(o: Vec3, d: Vec3, [a, b, c]: [Vec3; 3]) -> bool {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return false;
    }
    let s = (o - a) / det;
    let u = s.dot(p);
    let q = s.cross(e1);
    let v = d.dot(q);
    u >= 0.0 && v >= 0.0 && u + v <= 1.0 && e2.dot(q) > 0.0
}

/// Whether body-space point p lies inside the closed rigid mesh: a ray in a
/// direction no mesh we generate is aligned with crosses it an odd number
/// of times.
pub fn inside_body(body: &RigidBody, p: Vec3) -> bool {
    let dir = Vec3::new(1.0, 0.754_877_7, 0.569_840_3).normalize();
    let mut crossings = 0u32;
    body.bvh.query_ray(p, dir, |t| {
        let tri = body.mesh.triangles[t as usize].map(|i| body.mesh.vertices[i as usize]);
        crossings += ray_crosses(p, dir, tri) as u32;
    });
    crossings % 2 == 1
}

/// How deep cloth point `x` is inside the rigid body (0 when outside): the
/// distance to the nearest face plane whose triangle contains its
/// projection, exact for convex bodies. Unlike contact detection it has no
/// depth limit, so a vertex that tunnelled deep still counts.
pub fn penetration_depth(body: &RigidBody, frame: &RigidFrame, x: Vec3) -> f32 {
    let p = frame.to_body(x);
    let root = body.bvh.nodes[0].bounds;
    if !root.near(p, 0.0) || !inside_body(body, p) {
        return 0.0;
    }
    let reach = (root.max - root.min).length();
    let unlimited = Tolerances {
        thickness: 0.0,
        max_depth: reach,
    };
    let mut depth = f32::INFINITY;
    body.bvh.query(p, reach, |t| {
        let tri = body.mesh.triangles[t as usize].map(|i| body.mesh.vertices[i as usize]);
        if let Some((d, _)) = point_triangle(p, tri, body.face_normals[t as usize], unlimited) {
            depth = depth.min(-d);
        }
    });
    if depth.is_finite() {
        return depth;
    }
    // Inside, but in a concave corner no face projection covers: the
    // nearest mesh vertex bounds the depth.
    body.mesh
        .vertices
        .iter()
        .map(|v| (*v - p).length())
        .fold(f32::INFINITY, f32::min)
}

/// The deepest any cloth vertex is inside the rigid body, m.
pub fn max_penetration(body: &RigidBody, frame: &RigidFrame, x: &[Vec3]) -> f32 {
    x.par_iter()
        .with_min_len(GRAIN)
        .map(|&xi| penetration_depth(body, frame, xi))
        .reduce(|| 0.0, f32::max)
}
