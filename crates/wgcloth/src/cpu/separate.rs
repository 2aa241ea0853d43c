//! Stage "separate": how far each cloth vertex may move in a step without
//! the cloth passing through itself (issue 23), a conservative bound in the
//! manner of Offset Geometric Contact (Chen et al. 2025). Mirrors
//! wgsl/separate.wgsl; cpu/integrate.rs keeps each step within it.
//!
//! The first contact between two moving triangles is a vertex reaching a
//! triangle or an edge reaching an edge. Take every such pair that shares
//! no vertex and lies within `radius`, at separation s. A point of a
//! primitive moves at most as far as the farthest of its vertices, so if
//! every vertex of both moves less than s / 2 the pair cannot meet. Each
//! vertex is therefore allowed `gamma` (< 1/2) times the least separation
//! of the pairs it belongs to, and `gamma · radius` where it belongs to
//! none. A state with no intersecting pair keeps none when every vertex
//! stays within its bound. The radius a step looks within, its reach, is
//! `self_contact.radius` or, when some vertex's solved step h v' is longer
//! than that allows, as far as the longest step needs ([`reach`]): a
//! vertex far from the rest of the cloth is never held back.
//!
//! The broad phase is the cloth's BVH (refitted by the caller): each vertex
//! looks for triangles within the radius, each edge for triangles whose
//! box its own, grown by the radius, overlaps, and takes their edges.
//! A vertex's least separation is an atomic minimum over the bits of a
//! non-negative f32 (which order as the floats do), so the result does not
//! depend on the order pairs are met in, as on the GPU.

use std::sync::atomic::{AtomicU32, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use crate::bvh::{Aabb, Bvh};
use crate::config::SelfContactConfig;
use crate::cpu::GRAIN;
use crate::math::{closest_between_segments, closest_on_triangle};

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

/// Each vertex's least separation from the cloth primitives it could
/// reach (vertex–triangle and edge–edge pairs sharing no vertex), capped at
/// `radius`. `bvh` holds the boxes of `triangles` at `x`.
pub fn least_separations(
    x: &[Vec3],
    triangles: &[[u32; 3]],
    edges: &[[u32; 2]],
    bvh: &Bvh,
    radius: f32,
) -> Vec<f32> {
    let least: Vec<AtomicU32> = (0..x.len())
        .map(|_| AtomicU32::new(radius.to_bits()))
        .collect();
    let note = |vertices: &[u32], s: f32| {
        if s < radius {
            for &v in vertices {
                least[v as usize].fetch_min(s.to_bits(), Ordering::Relaxed);
            }
        }
    };
    let at = |i: u32| x[i as usize];
    (0..x.len() as u32)
        .into_par_iter()
        .with_min_len(GRAIN)
        .for_each(|v| {
            bvh.query(at(v), radius, |t| {
                let tri = triangles[t as usize];
                if !tri.contains(&v) {
                    let c = closest_on_triangle(at(v), at(tri[0]), at(tri[1]), at(tri[2]));
                    note(&[v, tri[0], tri[1], tri[2]], (at(v) - c).length());
                }
            })
        });
    edges.par_iter().with_min_len(GRAIN).for_each(|&e| {
        let grown = Aabb::of_points(&e.map(at));
        let grown = Aabb {
            min: grown.min - radius,
            max: grown.max + radius,
        };
        bvh.query_box(grown, |t| {
            let tri = triangles[t as usize];
            for f in [[tri[0], tri[1]], [tri[1], tri[2]], [tri[2], tri[0]]] {
                let f = [f[0].min(f[1]), f[0].max(f[1])];
                // Each pair from its lower edge (and perhaps twice, from
                // both triangles of the other: a minimum minds not).
                if f > e && !e.iter().any(|v| f.contains(v)) {
                    let (c, d) = closest_between_segments(at(e[0]), at(e[1]), at(f[0]), at(f[1]));
                    note(&[e[0], e[1], f[0], f[1]], (c - d).length());
                }
            }
        })
    });
    least
        .into_iter()
        .map(|s| f32::from_bits(s.into_inner()))
        .collect()
}

/// How far a step looks for pairs: `self_contact.radius`, or far enough
/// that a vertex with no pair within it may take the step's longest
/// stride `max_step` (m), `floor + max_step / gamma`.
pub fn reach(max_step: f32, keep: &SelfContactConfig) -> f32 {
    keep.radius.max(keep.floor + max_step / keep.gamma)
}

/// A vertex's displacement bound from its least separation s:
/// `gamma · (s − floor)`. A pair at separation s then ends the step above
/// floor + (1 − 2 gamma)(s − floor).
pub fn displacement_bound(least_separation: f32, keep: &SelfContactConfig) -> f32 {
    keep.gamma * (least_separation - keep.floor).max(0.0)
}

/// `step` shortened along its direction to at most `bound`.
pub fn within(step: Vec3, bound: f32) -> Vec3 {
    let length = step.length();
    if length > bound {
        step * (bound / length)
    } else {
        step
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::triangle_boxes;
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

    /// Each vertex's least separation by testing every pair.
    fn brute_force(x: &[Vec3], t: &[[u32; 3]], edges: &[[u32; 2]], radius: f32) -> Vec<f32> {
        let mut least = vec![radius; x.len()];
        let mut note = |vertices: [u32; 4], s: f32| {
            if s < radius {
                for v in vertices {
                    least[v as usize] = least[v as usize].min(s);
                }
            }
        };
        let at = |k: u32| x[k as usize];
        for v in 0..x.len() as u32 {
            for tri in t.iter().filter(|tri| !tri.contains(&v)) {
                let c = closest_on_triangle(at(v), at(tri[0]), at(tri[1]), at(tri[2]));
                note([v, tri[0], tri[1], tri[2]], (at(v) - c).length());
            }
        }
        for (i, e) in edges.iter().enumerate() {
            for f in edges[i + 1..]
                .iter()
                .filter(|f| !e.iter().any(|v| f.contains(v)))
            {
                let (c, d) = closest_between_segments(at(e[0]), at(e[1]), at(f[0]), at(f[1]));
                note([e[0], e[1], f[0], f[1]], (c - d).length());
            }
        }
        least
    }

    fn separations(x: &[Vec3], t: &[[u32; 3]], edges: &[[u32; 2]], radius: f32) -> Vec<f32> {
        let bvh = Bvh::build(&triangle_boxes(x, t));
        least_separations(x, t, edges, &bvh, radius)
    }

    #[test]
    fn least_separations_are_those_of_testing_every_pair() {
        let (mut x, t) = two_sheets(5);
        let edges = triangle_edges(&t);
        // Crumpled, so vertex–triangle and edge–edge gaps of every kind occur.
        let mut seed = 3u64;
        for p in &mut x {
            *p += 0.008 * jitter(&mut seed);
        }
        let radius = 0.006;
        let found = separations(&x, &t, &edges, radius);
        assert_eq!(found, brute_force(&x, &t, &edges, radius));
        assert!(
            found.iter().any(|&s| s < 0.001) && found.contains(&radius),
            "some vertices near the other layer, some out of reach: {found:?}"
        );
    }

    #[test]
    fn steps_within_the_bounds_never_cross_and_steps_past_them_do() {
        let (x0, t) = two_sheets(6);
        let edges = triangle_edges(&t);
        let keep = SelfContactConfig {
            enabled: true,
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
                let least = separations(&x, &t, &edges, keep.radius);
                // The lower layer pushed up into the upper, both jittered
                // (pushed at once, two layers could swap whole, leaving no
                // pair crossed after the step).
                for (i, p) in x.iter_mut().enumerate() {
                    let toward = if i < 36 { Vec3::Z } else { Vec3::ZERO };
                    let bound = scale * displacement_bound(least[i], &keep);
                    *p += (toward + 0.5 * jitter(&mut seed)).normalize() * bound;
                }
                worst = worst.max(intersecting_pairs(&x, &t).len());
                let gaps = separations(&x, &t, &edges, keep.radius);
                closest = gaps.into_iter().fold(closest, f32::min);
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
