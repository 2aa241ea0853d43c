//! Does the cloth pass through itself? Every pair of cloth triangles that
//! share no vertex and intersect: the check a self-collision stage must
//! keep at zero (issue 23), run on a state the host holds.
//!
//! Two triangles that are not coplanar intersect exactly when an edge of
//! one crosses the other: each end of the segment they share lies on an
//! edge of one of them. An edge pq crosses triangle abc when p and q lie
//! strictly on opposite sides of its plane and the line pq passes through
//! the closed triangle. Every side is the sign of an orientation
//! determinant computed in f64 from the f32 positions, where its rounding
//! is many orders below f32's spacing at cloth scales, so a pair is
//! misjudged only within about 1e-12 m of touching. Touching pairs (an
//! edge end on the other's plane) and coplanar overlaps do not count.
//!
//! The broad phase is a uniform grid over the triangles' bounding boxes
//! (`grid.rs`).

use glam::{DVec3, Vec3};

use crate::grid::{Aabb, overlapping_pairs};

/// Intersecting pairs of triangles that share no vertex, each as
/// [lower index, higher index], in increasing order.
pub fn intersecting_pairs(x: &[Vec3], triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let corners = |t: u32| triangles[t as usize].map(|i| x[i as usize]);
    let boxes: Vec<Aabb> = (0..triangles.len() as u32)
        .map(|t| Aabb::around(corners(t), 0.0))
        .collect();
    overlapping_pairs(&boxes, |a, b| {
        let (ta, tb) = (triangles[a as usize], triangles[b as usize]);
        !ta.iter().any(|v| tb.contains(v)) && intersect(corners(a), corners(b))
    })
}

/// Whether triangles p and q, assumed to share no vertex, intersect.
pub fn intersect(p: [Vec3; 3], q: [Vec3; 3]) -> bool {
    let (p, q) = (p.map(|v| v.as_dvec3()), q.map(|v| v.as_dvec3()));
    let edges = |t: [DVec3; 3]| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])];
    edges(p).iter().any(|&e| crosses(e, q)) || edges(q).iter().any(|&e| crosses(e, p))
}

/// Whether segment (s, e) crosses triangle t: its ends strictly on either
/// side of t's plane and the line through them inside the closed triangle.
fn crosses((s, e): (DVec3, DVec3), t: [DVec3; 3]) -> bool {
    let (ds, de) = (orient(t[0], t[1], t[2], s), orient(t[0], t[1], t[2], e));
    if ds * de >= 0.0 {
        return false;
    }
    let sides = [
        orient(s, e, t[0], t[1]),
        orient(s, e, t[1], t[2]),
        orient(s, e, t[2], t[0]),
    ];
    sides.iter().all(|&v| v >= 0.0) || sides.iter().all(|&v| v <= 0.0)
}

/// Six times the signed volume of the tetrahedron (a, b, c, d).
fn orient(a: DVec3, b: DVec3, c: DVec3, d: DVec3) -> f64 {
    (b - a).dot((c - a).cross(d - a))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [Vec3; 3] {
        [a.into(), b.into(), c.into()]
    }

    #[test]
    fn a_triangle_pierced_through_its_middle_intersects_and_one_beside_it_does_not() {
        let flat = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let through = tri([0.2, 0.2, -0.5], [0.2, 0.2, 0.5], [0.3, 0.25, 0.5]);
        assert!(intersect(flat, through) && intersect(through, flat));
        let beside = tri([0.8, 0.8, -0.5], [0.8, 0.8, 0.5], [0.9, 0.85, 0.5]);
        assert!(!intersect(flat, beside));
        let above = tri([0.2, 0.2, 0.01], [0.2, 0.2, 0.5], [0.3, 0.25, 0.5]);
        assert!(!intersect(flat, above));
    }

    #[test]
    fn two_triangles_crossing_edge_through_edge_intersect() {
        // Neither has a vertex inside the other: only edges cross, the
        // case a vertex-only test misses.
        let a = tri([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
        let b = tri([0.0, 0.5, -1.0], [0.0, 0.5, 1.0], [0.0, -1.0, 0.0]);
        assert!(intersect(a, b) && intersect(b, a));
    }

    /// A sheet of `n`×`n` vertices at height z(col), two triangles a cell.
    fn sheet(n: u32, z: impl Fn(u32) -> f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let x = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32 * 0.1, (i / n) as f32 * 0.1, z(i % n)))
            .collect();
        let mut t = Vec::new();
        for r in 0..n - 1 {
            for c in 0..n - 1 {
                let v = r * n + c;
                t.push([v, v + 1, v + n]);
                t.push([v + 1, v + n + 1, v + n]);
            }
        }
        (x, t)
    }

    #[test]
    fn a_smooth_sheet_has_none_and_a_sheet_through_another_has_one_row_of_pairs() {
        let (x, t) = sheet(12, |c| (c as f32 * 0.7).sin() * 0.05);
        assert!(intersecting_pairs(&x, &t).is_empty());
        // A second sheet turned upright through the first along x = 0.55:
        // every pair found crosses that line, and each is found once.
        let (mut x2, mut t2) = (x.clone(), t.clone());
        let offset = x.len() as u32;
        let (up, up_t) = sheet(12, |_| 0.0);
        x2.extend(up.iter().map(|p| Vec3::new(0.55, p.x, p.y - 0.5)));
        t2.extend(up_t.iter().map(|t| t.map(|v| v + offset)));
        let pairs = intersecting_pairs(&x2, &t2);
        assert!(!pairs.is_empty());
        let brute: Vec<[u32; 2]> = (0..t2.len() as u32)
            .flat_map(|a| (a + 1..t2.len() as u32).map(move |b| [a, b]))
            .filter(|&[a, b]| {
                let (ta, tb) = (t2[a as usize], t2[b as usize]);
                !ta.iter().any(|v| tb.contains(v))
                    && intersect(ta.map(|i| x2[i as usize]), tb.map(|i| x2[i as usize]))
            })
            .collect();
        assert_eq!(pairs, brute, "the grid finds what testing every pair finds");
        for [a, b] in pairs {
            assert!((a as usize) < t.len() && (b as usize) >= t.len());
        }
    }
}
