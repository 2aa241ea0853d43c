//! How far each cloth vertex may move in a step without the cloth passing
//! through itself (issue 23): a conservative bound in the manner of Offset
//! Geometric Contact (Chen et al. 2025).
//!
//! The first contact between two moving triangles is a vertex reaching a
//! triangle or an edge reaching an edge. Take every such pair that shares
//! no vertex and lies within `radius`, at separation s. A point of a
//! primitive moves at most as far as the farthest of its vertices, so if
//! every vertex of both moves less than s / 2 the pair cannot meet. Each
//! vertex is therefore allowed `gamma` (< 1/2) times the least separation
//! of the pairs it belongs to, and `gamma · radius` where it belongs to
//! none. A state with no intersecting pair keeps none when every vertex
//! stays within its bound.

use glam::Vec3;

use rayon::prelude::*;

use crate::grid::{Aabb, Cells, overlapping_pairs};
use crate::math::{closest_between_segments, closest_on_triangle};

/// The cloth's primitives a bound looks at.
pub struct Primitives<'a> {
    /// Triangles, by vertex.
    pub triangles: &'a [[u32; 3]],
    /// Edges of those triangles, each once, by vertex.
    pub edges: &'a [[u32; 2]],
}

/// Every edge of `triangles` once, by vertex (lower index first), sorted.
pub fn triangle_edges(triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = triangles
        .iter()
        .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// One vertex–triangle or edge–edge pair within the search radius: its
/// four vertices and their separation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearPair {
    /// The vertex then the triangle's three, or one edge's two then the other's.
    pub vertices: [u32; 4],
    /// Distance between the two primitives.
    pub separation: f32,
}

/// Vertex–triangle and edge–edge pairs that share no vertex and lie within
/// `radius` of each other.
pub fn near_pairs(x: &[Vec3], p: &Primitives, radius: f32) -> Vec<NearPair> {
    let at = |i: u32| x[i as usize];
    // Vertex–triangle: each vertex looks in the one cell it lies in, where
    // every triangle whose box grown by the radius holds it is listed.
    let grown: Vec<Aabb> = p
        .triangles
        .iter()
        .map(|t| Aabb::around(t.map(at), radius))
        .collect();
    let mut pairs: Vec<NearPair> = match Cells::new(&grown) {
        None => Vec::new(),
        Some(cells) => (0..x.len() as u32)
            .into_par_iter()
            .flat_map_iter(|v| {
                let (cells, grown) = (&cells, &grown);
                cells.at(at(v)).filter_map(move |t| {
                    let b = &grown[t as usize];
                    let tri = p.triangles[t as usize];
                    if tri.contains(&v) || !(b.lo.cmple(at(v)).all() && at(v).cmple(b.hi).all()) {
                        return None;
                    }
                    let c = closest_on_triangle(at(v), at(tri[0]), at(tri[1]), at(tri[2]));
                    Some(NearPair {
                        vertices: [v, tri[0], tri[1], tri[2]],
                        separation: (at(v) - c).length(),
                    })
                })
            })
            .filter(|pair| pair.separation < radius)
            .collect(),
    };
    // Edge–edge: boxes grown by half the radius overlap for edges within it.
    let boxes: Vec<Aabb> = p
        .edges
        .iter()
        .map(|e| Aabb::around(e.map(at), 0.5 * radius))
        .collect();
    let apart = |a: u32, b: u32| {
        let (e, f) = (p.edges[a as usize], p.edges[b as usize]);
        !e.iter().any(|v| f.contains(v))
    };
    pairs.extend(
        overlapping_pairs(&boxes, apart)
            .into_iter()
            .map(|[a, b]| {
                let (e, f) = (p.edges[a as usize], p.edges[b as usize]);
                let (c, d) = closest_between_segments(at(e[0]), at(e[1]), at(f[0]), at(f[1]));
                NearPair {
                    vertices: [e[0], e[1], f[0], f[1]],
                    separation: (c - d).length(),
                }
            })
            .filter(|pair| pair.separation < radius),
    );
    pairs
}

/// What a bound keeps and how far it looks.
#[derive(Clone, Copy, Debug)]
pub struct Keep {
    /// Pairs farther apart than this are not looked at, m.
    pub radius: f32,
    /// The share of a pair's gap each of its vertices may close in a step
    /// (below 1/2).
    pub gamma: f32,
    /// The gap no pair closes below, m. In exact arithmetic the bound alone
    /// never lets a pair meet, but a gap closing geometrically toward zero
    /// reaches the spacing of f32 positions, whose rounding then crosses
    /// it; a floor far above that spacing keeps the guarantee.
    pub floor: f32,
}

/// Each vertex's displacement bound for the step from `x`: `gamma` times
/// what the least separation of the near pairs it belongs to (or the
/// radius) exceeds the floor by. A pair at separation s then ends the step
/// above floor + (1 − 2 gamma)(s − floor).
pub fn displacement_bounds(x: &[Vec3], p: &Primitives, keep: Keep) -> Vec<f32> {
    let mut least = vec![keep.radius; x.len()];
    for pair in near_pairs(x, p, keep.radius) {
        for v in pair.vertices {
            least[v as usize] = least[v as usize].min(pair.separation);
        }
    }
    least
        .iter()
        .map(|s| keep.gamma * (s - keep.floor).max(0.0))
        .collect()
}

/// Moves each vertex of `to` back along its step from `from` to within its
/// bound; returns how many were moved.
pub fn clamp_displacements(from: &[Vec3], to: &mut [Vec3], bounds: &[f32]) -> usize {
    let mut clamped = 0;
    for ((a, b), &limit) in from.iter().zip(to.iter_mut()).zip(bounds) {
        let step = *b - *a;
        let length = step.length();
        if length > limit {
            *b = *a + step * (limit / length);
            clamped += 1;
        }
    }
    clamped
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::intersections::intersecting_pairs;

    /// Two n×n sheets 1 cm apart, one above the other.
    fn two_sheets(n: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut x = Vec::new();
        let mut t = Vec::new();
        for layer in 0..2u32 {
            let base = layer * n * n;
            for i in 0..n * n {
                let (c, r) = ((i % n) as f32, (i / n) as f32);
                x.push(Vec3::new(c * 0.05, r * 0.05, layer as f32 * 0.01));
            }
            for r in 0..n - 1 {
                for c in 0..n - 1 {
                    let v = base + r * n + c;
                    t.push([v, v + 1, v + n]);
                    t.push([v + 1, v + n + 1, v + n]);
                }
            }
        }
        (x, t)
    }

    /// Deterministic pseudo-random unit-ish vectors.
    fn jitter(seed: &mut u64) -> Vec3 {
        let mut next = || {
            *seed ^= *seed << 13;
            *seed ^= *seed >> 7;
            *seed ^= *seed << 17;
            (*seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        Vec3::new(next(), next(), next())
    }

    #[test]
    fn near_pairs_are_every_pair_within_the_radius_and_no_other() {
        let (x, t) = two_sheets(5);
        let edges = triangle_edges(&t);
        let p = Primitives {
            triangles: &t,
            edges: &edges,
        };
        let radius = 0.03;
        let found = near_pairs(&x, &p, radius);
        // Brute force over every vertex–triangle and edge–edge pair.
        let mut brute = Vec::new();
        for (v, &xv) in x.iter().enumerate() {
            for tri in &t {
                if tri.contains(&(v as u32)) {
                    continue;
                }
                let c = closest_on_triangle(
                    xv,
                    x[tri[0] as usize],
                    x[tri[1] as usize],
                    x[tri[2] as usize],
                );
                if (xv - c).length() < radius {
                    brute.push([v as u32, tri[0], tri[1], tri[2]]);
                }
            }
        }
        for (i, e) in edges.iter().enumerate() {
            for f in &edges[i + 1..] {
                if e.iter().any(|v| f.contains(v)) {
                    continue;
                }
                let at = |k: u32| x[k as usize];
                let (c, d) = closest_between_segments(at(e[0]), at(e[1]), at(f[0]), at(f[1]));
                if (c - d).length() < radius {
                    brute.push([e[0], e[1], f[0], f[1]]);
                }
            }
        }
        let mut got: Vec<[u32; 4]> = found.iter().map(|p| p.vertices).collect();
        got.sort_unstable();
        brute.sort_unstable();
        assert_eq!(got, brute);
        assert!(
            found.iter().any(|p| p.separation < 0.0101),
            "the layers 1 cm apart"
        );
    }

    #[test]
    fn steps_within_the_bounds_never_cross_and_steps_past_them_do() {
        let (x0, t) = two_sheets(6);
        let edges = triangle_edges(&t);
        let p = Primitives {
            triangles: &t,
            edges: &edges,
        };
        let keep = Keep {
            radius: 0.05,
            gamma: 0.45,
            floor: 1e-4,
        };
        let run = |scale: f32| {
            let mut x = x0.clone();
            let mut seed = 7u64;
            let mut worst = 0;
            let mut closest = f32::INFINITY;
            for _ in 0..60 {
                let bounds = displacement_bounds(&x, &p, keep);
                // The lower layer pushed up into the upper, both jittered
                // (pushed at once, two layers could swap whole, leaving no
                // pair crossed after the step).
                let mut next: Vec<Vec3> = x
                    .iter()
                    .enumerate()
                    .map(|(i, &v)| {
                        let toward = if i < 36 { Vec3::Z } else { Vec3::ZERO };
                        v + (toward + 0.5 * jitter(&mut seed)).normalize() * scale * bounds[i]
                    })
                    .collect();
                clamp_displacements(
                    &x,
                    &mut next,
                    &bounds.iter().map(|b| b * scale).collect::<Vec<_>>(),
                );
                x = next;
                worst = worst.max(intersecting_pairs(&x, &t).len());
                let gaps = near_pairs(&x, &p, keep.radius).into_iter();
                closest = gaps.map(|q| q.separation).fold(closest, f32::min);
            }
            (worst, closest)
        };
        let (crossed, closest) = run(1.0);
        assert_eq!(crossed, 0, "within the bounds");
        // The layers close in to the floor and stop there (to the rounding
        // of a separation computed in f32).
        assert!(
            closest >= 0.999 * keep.floor && closest < 2.0 * keep.floor,
            "{closest}"
        );
        assert!(
            run(2.5).0 > 0,
            "past them the layers cross, so the test can fail"
        );
    }
}
