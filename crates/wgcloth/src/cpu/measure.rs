//! Stage "measure": how deep the cloth got inside the rigid body after the
//! solve (a ray-parity inside test, then the distance to the nearest point
//! of the surface; no depth limit), the run's deepest, and the push-out
//! that moves every vertex found inside back out of the body. CPU twin of
//! wgsl/measure.wgsl.

use glam::Vec3;
use rayon::prelude::*;

use crate::cpu::GRAIN;
use crate::cpu::rigid::RigidFrame;
use crate::math::closest_on_triangle;
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

/// Where a point inside the body leaves it (body space): the nearest
/// point of its surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WayOut {
    /// Distance to the surface, m.
    pub depth: f32,
    /// The nearest surface point.
    pub surface: Vec3,
    /// The outward unit normal of the triangle it lies on.
    pub normal: Vec3,
}

/// Where body-space point `p` leaves the body, when it is inside: the
/// closest point over all its triangles (of equally close ones, the lower
/// triangle index, as on the GPU). `None` outside. Unlike contact detection
/// it has no depth limit, so a vertex that tunnelled deep still counts.
pub fn way_out(body: &RigidBody, p: Vec3) -> Option<WayOut> {
    let root = body.bvh.nodes[0].bounds;
    if !root.near(p, 0.0) || !inside_body(body, p) {
        return None;
    }
    let reach = (root.max - root.min).length();
    let mut best: Option<(f32, u32, Vec3)> = None;
    body.bvh.query(p, reach, |t| {
        let [a, b, c] = body.mesh.triangles[t as usize].map(|i| body.mesh.vertices[i as usize]);
        let q = closest_on_triangle(p, a, b, c);
        let d2 = (q - p).length_squared();
        if best.is_none_or(|(e2, u, _)| (d2, t) < (e2, u)) {
            best = Some((d2, t, q));
        }
    });
    best.map(|(d2, t, surface)| WayOut {
        depth: d2.sqrt(),
        surface,
        normal: body.face_normals[t as usize],
    })
}

/// How deep cloth point `x` is inside the rigid body placed by `frame`
/// (0 when outside); see [`way_out`].
pub fn penetration_depth(body: &RigidBody, frame: &RigidFrame, x: Vec3) -> f32 {
    way_out(body, frame.to_body(x)).map_or(0.0, |w| w.depth)
}

/// The push-out: every free cloth vertex the solve left inside the body
/// moves to the nearest point of the surface ([`way_out`]) and on along
/// that triangle's normal by the contact thickness ε, where the contact
/// force starts (on the surface itself it would start the next step with
/// the full penalty ε k_n), and loses the velocity with which it moves
/// into the body relative to the surface (an inelastic impact). Contacts
/// only see points within `max_depth` of a face, so this is what keeps a
/// vertex from staying inside, or a fast body from tunnelling. Returns how
/// deep the deepest vertex (pinned ones too) was before it moved, m.
pub fn push_out(
    body: &RigidBody,
    frame: &RigidFrame,
    thickness: f32,
    pinned: &[bool],
    x: &mut [Vec3],
    v: &mut [Vec3],
) -> f32 {
    x.par_iter_mut()
        .with_min_len(GRAIN)
        .zip(v.par_iter_mut())
        .zip(pinned)
        .map(|((xi, vi), &pinned)| {
            let Some(out) = way_out(body, frame.to_body(*xi)) else {
                return 0.0;
            };
            if !pinned {
                let n = frame.rotation * out.normal;
                *xi = frame.rotation * out.surface + frame.translation + thickness * n;
                *vi += (frame.velocity.dot(n) - vi.dot(n)).max(0.0) * n;
            }
            out.depth
        })
        .reduce(|| 0.0, f32::max)
}
