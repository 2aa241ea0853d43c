//! Stage "measure": how deep the cloth got inside the rigid body after the
//! solve (a ray-parity inside test, then the distance to the nearest point
//! of the surface; no depth limit), the run's deepest, and the push-out
//! that moves every vertex found inside back out of the body. CPU twin of
//! wgsl/measure.wgsl.

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::cpu::rigid::RigidFrame;
use crate::math::closest_on_triangle;
use crate::parallel::GRAIN;
use crate::scene::RigidBody;

/// The direction of the inside test's ray, +x: the hierarchy's boxes are
/// then tested by exact comparisons, and the triangles are projected onto
/// the yz plane without rounding.
pub const INSIDE_RAY: Vec3 = Vec3::X;

/// Edge u → v of a triangle projected along the ray, the ray at the
/// origin: its edge function u × v, and whether the origin lies to its
/// left, an exact zero decided as if the ray were moved by (ε, ε²). Two
/// triangles sharing the edge take opposite sides of it, so a ray through
/// an edge or a vertex crosses one triangle there, never two or none.
/// Möller–Trumbore, whose rounding differs between the two, misjudged
/// 13 % of such rays in the test of this, and a 256² run had pushed two
/// vertices 28 and 32 mm outside the sphere onto it. The function is
/// evaluated from the lower endpoint, so that both triangles round alike.
/// None for an edge along the ray.
fn projected_edge(u: Vec2, v: Vec2) -> Option<(f32, bool)> {
    let swapped = (v.x, v.y) < (u.x, u.y);
    let (lo, hi) = if swapped { (v, u) } else { (u, v) };
    if lo == hi {
        return None;
    }
    let e = lo.x * hi.y - lo.y * hi.x;
    // Moved by δ, the function is e + (hi − lo) × δ.
    let w = hi - lo;
    let left = match (e != 0.0, w.y != 0.0) {
        (true, _) => e > 0.0,
        (false, true) => w.y < 0.0,
        (false, false) => w.x > 0.0,
    };
    Some(if swapped { (-e, !left) } else { (e, left) })
}

/// Whether the ray from `p` along [`INSIDE_RAY`] crosses triangle `tri`:
/// the origin on the same side of its three projected edges, and the
/// crossing, whose barycentric weights are the edge functions, ahead of p.
fn ray_crosses(p: Vec3, tri: [Vec3; 3]) -> bool {
    let [a, b, c] = tri.map(|v| v - p);
    let yz = |v: Vec3| Vec2::new(v.y, v.z);
    let edges = (
        projected_edge(yz(b), yz(c)),
        projected_edge(yz(c), yz(a)),
        projected_edge(yz(a), yz(b)),
    );
    let (Some((ea, left)), Some((eb, b_left)), Some((ec, c_left))) = edges else {
        return false;
    };
    let ahead = ea * a.x + eb * b.x + ec * c.x;
    // All left, the edge functions sum to a positive area; all right, negative.
    b_left == left && c_left == left && ahead != 0.0 && (ahead > 0.0) == left
}

/// Whether body-space point p lies inside the closed rigid mesh: its ray
/// crosses the surface an odd number of times.
pub fn inside_body(body: &RigidBody, p: Vec3) -> bool {
    let mut crossings = 0u32;
    body.bvh.query_x_ray(p, |t| {
        let tri = body.mesh.triangles[t as usize].map(|i| body.mesh.vertices[i as usize]);
        crossings += ray_crosses(p, tri) as u32;
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
/// vertex from staying inside, or a fast body from tunnelling. Each vertex
/// it moves is marked in `moved`, which stage `separate` then does not
/// move: the body wins. Returns how deep the deepest vertex (pinned ones
/// too) was before it moved, m.
pub fn push_out(
    body: &RigidBody,
    frame: &RigidFrame,
    thickness: f32,
    pinned: &[bool],
    (x, v): (&mut [Vec3], &mut [Vec3]),
    moved: &mut [bool],
) -> f32 {
    x.par_iter_mut()
        .with_min_len(GRAIN)
        .zip(v.par_iter_mut())
        .zip(moved.par_iter_mut())
        .zip(pinned)
        .map(|(((xi, vi), moved), &pinned)| {
            let Some(out) = way_out(body, frame.to_body(*xi)) else {
                return 0.0;
            };
            if !pinned {
                let n = frame.rotation * out.normal;
                *xi = frame.rotation * out.surface + frame.translation + thickness * n;
                *vi += (frame.velocity.dot(n) - vi.dot(n)).max(0.0) * n;
                *moved = true;
            }
            out.depth
        })
        .reduce(|| 0.0, f32::max)
}
