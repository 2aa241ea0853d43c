//! Stage "self_contact": the cloth pushing against itself (issue 23), as
//! forces in the implicit solve. Twin of wgsl/self_contact.wgsl.
//!
//! At the step's start, each vertex–triangle pair whose vertex projects
//! inside the triangle, and each edge–edge pair whose closest points lie
//! inside both edges, closer than the thickness ε and sharing no vertex, is
//! a contact: the first side (the vertex, or the first edge's point) is the
//! penetrating point, the other the surface, n points from the surface to
//! it and d̃ = distance − ε < 0. As for a face–vertex contact with the body
//! (DESIGN "collision detection" (b)), the four vertices carry weights β
//! with the force on vertex k β_k f, ∂d̃/∂x_k = β_k nᵀ and
//! v_rel = Σ β_k v_k: (1, −w0, −w1, −w2) with w the barycentrics, or
//! (1 − s, s, −(1 − t), −t) at edge parameters s, t. The force is eqs. 8–9
//! with the `[contact]` coefficients (the analytic model whichever model the
//! body uses: the networks learnt cloth against a rigid body), made safe for
//! PCG by `contact::response`, each pair's coefficients held to the
//! cloth's mass ([`Band::coefficients`]). A pair adds β_k β_l B at (k, l) with
//! B = −(h D_c + h² K_c), positive semidefinite, so A stays SPD: the
//! diagonal blocks go into A's diagonal (the preconditioners see them), the
//! others into [`Couplings`], which the SpMV applies by gathering over each
//! vertex's pairs.
//!
//! Pairs that are close in the flat cloth are not contacts: a pair counts
//! only when its two sides lie at least 2ε apart in the cloth's rest grid,
//! so a fine grid's neighbouring rows do not push each other apart in the
//! plane. A vertex takes part in at most [`PAIRS_PER_VERTEX`] pairs (the
//! GPU's list); the pairs of a vertex in more are dropped and counted.
//! (Edge–edge pairs are most of them: two layers resting within ε have
//! about four for each vertex–triangle pair.)

use glam::{Mat3, Vec2, Vec3};
use rayon::prelude::*;

use crate::bvh::{Aabb, Bvh};
use crate::cpu::collide::{Tolerances, point_triangle};
use crate::cpu::contact::{Coefficients, friction, normal_force, response};
use crate::cpu::separate::{self, Candidate, EDGE_PAIR, candidates};
use crate::math::{Sym3, closest_between_segments, closest_on_triangle, segment_parameters};
use crate::parallel::GRAIN;
use crate::scene::Cloth;

/// The most pairs a vertex takes part in (the GPU's list per vertex, or
/// fewer where one binding would not hold the lists: `Params::cloth_per_vertex`).
/// Two layers resting within ε of each other put a vertex in about 16,
/// four fifths of them edge–edge.
pub const PAIRS_PER_VERTEX: u32 = 64;

/// A cloth–cloth contact at the step's start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    /// The vertex then the triangle's three, or one edge's two then the
    /// other's.
    pub vertices: [u32; 4],
    /// Edge–edge (else vertex–triangle).
    pub edges: bool,
    /// β_k of each of `vertices`: the penetrating point minus the nearest
    /// point of the surface is Σ β_k x_k ([`Pair::gap`]).
    pub beta: [f32; 4],
}

impl Pair {
    /// The order pairs are kept in on both paths: vertex–triangle first,
    /// then by vertex (the GPU's key, `EDGE_PAIR` on the first).
    pub fn key(&self) -> [u32; 4] {
        let [a, b, c, d] = self.vertices;
        [a | if self.edges { EDGE_PAIR } else { 0 }, b, c, d]
    }

    /// Σ β_k y_k: at velocities, v_rel; at positions, the gap from the
    /// surface to the penetrating point, |gap| its distance and gap/|gap|
    /// its normal n.
    pub fn gap(&self, y: &[Vec3]) -> Vec3 {
        (0..4).fold(Vec3::ZERO, |acc, k| {
            acc + self.beta[k] * y[self.vertices[k] as usize]
        })
    }

    /// The pair's friction bound scale: its vertices' ([`bound_scales`])
    /// weighted by β².
    pub fn bound_scale(&self, scales: &[f32]) -> f32 {
        let (scaled, weight) = (self.vertices.iter().zip(self.beta))
            .fold((0.0, 0.0), |(s, w), (&i, b)| {
                (s + b * b * scales[i as usize], w + b * b)
            });
        scaled / weight
    }

    /// The contact normal n and d̃ = distance − ε at positions `x` (d̃ at
    /// most 0, so rounding at the band's edge never pulls; no normal and
    /// d̃ = 0, so no force, where the gap rounds to nothing).
    pub fn normal_depth(&self, x: &[Vec3], thickness: f32) -> (Vec3, f32) {
        let gap = self.gap(x);
        let distance = gap.length();
        match distance > 0.0 {
            true => (gap / distance, (distance - thickness).min(0.0)),
            false => (Vec3::ZERO, 0.0),
        }
    }
}

/// The flat grid the cloth is cut from: vertex i at (column dx, row dy, 0).
/// The rest distance of a pair is measured here, on both paths.
pub fn rest_grid(cloth: &Cloth) -> Vec<Vec3> {
    let spacing = grid_spacing(cloth);
    (0..cloth.vertex_count() as u32)
        .map(|i| rest_point(i, cloth.nx, spacing))
        .collect()
}

/// The grid's spacing along a row and down a column, m.
pub fn grid_spacing(cloth: &Cloth) -> Vec2 {
    let at = |i: u32| cloth.rest_positions[i as usize];
    Vec2::new((at(1) - at(0)).length(), (at(cloth.nx) - at(0)).length())
}

/// Vertex i of a grid `nx` wide in the flat rest grid.
pub fn rest_point(i: u32, nx: u32, spacing: Vec2) -> Vec3 {
    Vec3::new(
        (i % nx) as f32 * spacing.x,
        (i / nx) as f32 * spacing.y,
        0.0,
    )
}

/// The barycentrics of `p`'s projection on triangle `tri` when it falls
/// inside and `p` lies within `thickness` of the triangle's plane, off it.
pub fn vertex_triangle(p: Vec3, tri: [Vec3; 3], thickness: f32) -> Option<Vec3> {
    let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero();
    if n == Vec3::ZERO {
        return None;
    }
    let both_sides = Tolerances {
        thickness,
        max_depth: thickness,
    };
    let (d, w) = point_triangle(p, tri, n, both_sides)?;
    (d != 0.0).then_some(w)
}

/// The parameters (s, t) of the closest points of edges `e` and `f` when
/// both lie inside their edges, less than `thickness` and more than 0
/// apart.
pub fn edge_edge(e: [Vec3; 2], f: [Vec3; 2], thickness: f32) -> Option<(f32, f32)> {
    let (s, t) = segment_parameters(e[0], e[1], f[0], f[1]);
    let inside = |u: f32| u > 0.0 && u < 1.0;
    if !(inside(s) && inside(t)) {
        return None;
    }
    let gap = (e[0] + (e[1] - e[0]) * s) - (f[0] + (f[1] - f[0]) * t);
    let distance = gap.length();
    (distance > 0.0 && distance < thickness).then_some((s, t))
}

/// The cloth a step finds contacts on.
pub struct Sheet<'a> {
    /// The cloth's triangles.
    triangles: &'a [[u32; 3]],
    /// Their edges (`separate::triangle_edges`).
    edges: &'a [[u32; 2]],
    /// Each vertex in the flat rest grid ([`rest_grid`]).
    rest: &'a [Vec3],
    /// ε, m.
    thickness: f32,
    /// Whether the grid's neighbours lie within 2ε at rest, which a
    /// triangle's edges tell. Else no vertex is near another at rest, and
    /// no pair is asked whether it is ([`Sheet::vertices_near_at_rest`]).
    neighbours_near: bool,
}

impl<'a> Sheet<'a> {
    /// The sheet of `triangles`, with their `edges`, cut from the `rest`
    /// grid, its contacts within `thickness`.
    pub fn new(
        triangles: &'a [[u32; 3]],
        edges: &'a [[u32; 2]],
        rest: &'a [Vec3],
        thickness: f32,
    ) -> Sheet<'a> {
        let mut sheet = Sheet {
            triangles,
            edges,
            rest,
            thickness,
            neighbours_near: false,
        };
        sheet.neighbours_near = (triangles.first()).is_some_and(|&t| {
            separate::edges_of(t)
                .iter()
                .any(|&[i, j]| sheet.near_at_rest(i, j))
        });
        sheet
    }

    /// Whether the two sides of a pair lie at least 2ε apart at rest.
    fn apart_at_rest(&self, vertices: [u32; 4], edges: bool) -> bool {
        let r = |i: u32| self.rest[i as usize];
        let [a, b, c, d] = vertices;
        let gap = match edges {
            false => r(a) - closest_on_triangle(r(a), r(b), r(c), r(d)),
            true => {
                let (p, q) = closest_between_segments(r(a), r(b), r(c), r(d));
                p - q
            }
        };
        gap.length() >= 2.0 * self.thickness
    }

    /// Whether a vertex of the pair's first side lies within 2ε of one of
    /// its second side's at rest, and so the pair is not
    /// [apart](Self::apart_at_rest): a few products that refuse, before any
    /// geometry, the pairs of neighbours that a fine flat cloth meets
    /// within ε (at 256² their exact tests took three fifths of its step).
    #[inline(always)]
    fn vertices_near_at_rest(&self, vertices: [u32; 4], edges: bool) -> bool {
        let [a, b, c, d] = vertices;
        let first: &[u32] = if edges { &[a, b] } else { &[a] };
        let second: &[u32] = if edges { &[c, d] } else { &[b, c, d] };
        (first.iter()).any(|&i| second.iter().any(|&j| self.refused(i, j)))
    }

    /// Whether every pair with vertex i on one side and j on the other is
    /// refused before any geometry: the two lie within 2ε of each other at
    /// rest (asked only where the grid's neighbours do, else no two do).
    #[inline(always)]
    fn refused(&self, i: u32, j: u32) -> bool {
        self.neighbours_near && self.near_at_rest(i, j)
    }

    /// Whether vertices i and j lie within 2ε of each other at rest.
    #[inline(always)]
    fn near_at_rest(&self, i: u32, j: u32) -> bool {
        let reach = 2.0 * self.thickness;
        self.rest[i as usize].distance_squared(self.rest[j as usize]) < reach * reach
    }

    /// The vertex–triangle contact of vertex `v` and triangle `t`.
    pub fn vertex_pair(&self, x: &[Vec3], v: u32, t: u32) -> Option<Pair> {
        let tri = self.triangles[t as usize];
        let vertices = [v, tri[0], tri[1], tri[2]];
        if tri.contains(&v) || self.vertices_near_at_rest(vertices, false) {
            return None;
        }
        let at = |i: u32| x[i as usize];
        let w = vertex_triangle(at(v), tri.map(at), self.thickness)?;
        self.apart_at_rest(vertices, false).then_some(Pair {
            vertices,
            edges: false,
            beta: [1.0, -w.x, -w.y, -w.z],
        })
    }

    /// The edge–edge contact of edges `e` and `f` (each `[low, high]`).
    pub fn edge_pair(&self, x: &[Vec3], e: [u32; 2], f: [u32; 2]) -> Option<Pair> {
        let vertices = [e[0], e[1], f[0], f[1]];
        if e.iter().any(|v| f.contains(v)) || self.vertices_near_at_rest(vertices, true) {
            return None;
        }
        let at = |i: u32| x[i as usize];
        let (s, t) = edge_edge(e.map(at), f.map(at), self.thickness)?;
        self.apart_at_rest(vertices, true).then_some(Pair {
            vertices,
            edges: true,
            beta: [1.0 - s, s, t - 1.0, -t],
        })
    }

    /// Every contact at positions `x`, each once, sorted by
    /// [`Pair::key`], but those at vertices in more than `per_vertex`
    /// ([`PAIRS_PER_VERTEX`]); `bvh` holds the triangles' boxes at `x`.
    pub fn find(&self, x: &[Vec3], bvh: &Bvh, per_vertex: u32) -> Found {
        // The boxes of primitives at x; a pair is tested only where the
        // first's, grown by ε, overlaps the second's (as the GPU does).
        let boxed =
            |vertices: &[u32]| (vertices.iter()).fold(Aabb::EMPTY, |b, &i| b.grow(x[i as usize]));
        let reach = |vertices: &[u32]| boxed(vertices).grown(self.thickness);
        let mut pairs: Vec<Pair> = (0..x.len() as u32)
            .into_par_iter()
            .with_min_len(GRAIN)
            .flat_map_iter(|v| {
                let mut found = Vec::new();
                let walked = (self.triangles, self.edges);
                let refused = |i, j| self.refused(i, j);
                candidates(v, walked, bvh, (reach, boxed), refused, |pair| match pair {
                    Candidate::Vertex(t) => found.extend(self.vertex_pair(x, v, t)),
                    Candidate::Edges(e, f) => found.extend(self.edge_pair(x, e, f)),
                });
                found
            })
            .collect();
        // An edge–edge pair is met from both triangles along its upper edge.
        pairs.par_sort_unstable_by_key(Pair::key);
        pairs.dedup_by_key(|p| p.key());
        let mut count = vec![0u32; x.len()];
        for p in &pairs {
            for &v in &p.vertices {
                count[v as usize] += 1;
            }
        }
        let before = pairs.len();
        pairs.retain(|p| p.vertices.iter().all(|&v| count[v as usize] <= per_vertex));
        Found {
            dropped: before - pairs.len(),
            pairs,
            counts: count,
        }
    }
}

/// The contacts a step finds ([`Sheet::find`]).
#[derive(Clone, Debug, Default)]
pub struct Found {
    /// The contacts kept, sorted by [`Pair::key`].
    pub pairs: Vec<Pair>,
    /// How many were dropped at crowded vertices.
    pub dropped: usize,
    /// Per vertex, the contacts found at it (those dropped too).
    pub counts: Vec<u32>,
}

/// What one pair adds to the system: B = −(h D_c + h² K_c) and
/// h (f − D_c v_rel), each vertex k taking β_k of the second and
/// β_k β_l B at (k, l).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PairTerm {
    /// B, symmetric positive semidefinite.
    pub block: Mat3,
    /// h (f − D_c v_rel).
    pub rhs: Vec3,
    /// f, the force on the penetrating side.
    pub force: Vec3,
}

/// How a step's pairs are evaluated: eqs. 8–9 with `coefficients` over a
/// band of `thickness`, at time step `h`, each vertex's pairs together
/// adding at most about `limit` to its diagonal.
#[derive(Clone, Copy, Debug)]
pub struct Band {
    /// k_n, k_d, k_t, μ (the `[contact]` ones).
    pub coefficients: Coefficients,
    /// ε, m.
    pub thickness: f32,
    /// h, s.
    pub h: f32,
    /// `self_contact.mass_ratio` times the vertex mass, kg.
    pub limit: f32,
    /// A vertex's mass, kg.
    pub vertex_mass: f32,
}

impl Band {
    /// The coefficients of a pair whose most crowded vertex is in `most`
    /// pairs: h² k_n, h k_d and h k_t each at most `limit / most`, so the
    /// blocks a vertex's pairs add to A stay within a few times its mass
    /// and PCG converges at any grid (the `[contact]` coefficients are
    /// per contact, and a fine grid's vertex weighs a thousandth of
    /// h k_t). Coulomb's bound μ f_c holds whatever k_t; a lower k_t lets
    /// a resting layer creep at up to μ f_c / k_t.
    pub fn coefficients(&self, most: u32) -> Coefficients {
        let (k, h) = (&self.coefficients, self.h);
        let share = self.limit / most.max(1) as f32;
        Coefficients {
            kn: k.kn.min(share / (h * h)),
            kd: k.kd.min(share / h),
            kt: k.kt.min(share / h),
            mu: k.mu,
        }
    }

    /// The mass pair `p` moves along its slide, over h (kg/s), for the
    /// friction floor of `contact::response`: 1 / (h Σ β_k² n_k / m), each
    /// vertex's mass m shared among the n_k pairs found at it (`counts`),
    /// so that its pairs together never stop it past rest. A pinned vertex
    /// counts as free, which only raises the floor.
    pub fn inertia(&self, p: &Pair, counts: &[u32]) -> f32 {
        let spread: f32 = (p.vertices.iter().zip(p.beta))
            .map(|(&i, b)| b * b * counts[i as usize] as f32)
            .sum();
        self.vertex_mass / (self.h * spread)
    }
}

/// The eqs. 8–9 force of each pair at positions `x` and velocities `v`
/// and its terms of the system, made safe for PCG by `contact::response`;
/// `counts` are the pairs found at each vertex ([`Found::counts`]),
/// `carried` the normal load each vertex's pairs carried in the last
/// step's solve (stage "load"), which sets the friction's bound
/// ([`bound_scales`]).
pub fn respond(
    pairs: &[Pair],
    counts: &[u32],
    carried: &[f32],
    x: &[Vec3],
    v: &[Vec3],
    band: &Band,
) -> Vec<PairTerm> {
    let h = band.h;
    let at_start = |p: &Pair| {
        let (n, depth) = p.normal_depth(x, band.thickness);
        let most = p.vertices.iter().map(|&i| counts[i as usize]).max();
        (n, n * depth, p.gap(v), band.coefficients(most.unwrap_or(1)))
    };
    let pushes: Vec<f32> = (pairs.par_iter().with_min_len(GRAIN))
        .map(|p| {
            let (_, c, v_rel, k) = at_start(p);
            normal_force(c, v_rel, &k)
        })
        .collect();
    let scales = bound_scales(pairs, &pushes, carried);
    pairs
        .par_iter()
        .with_min_len(GRAIN)
        .map(|p| {
            let (n, c, v_rel, mut k) = at_start(p);
            k.mu *= p.bound_scale(&scales);
            let r = response(&friction(c, v_rel, &k), n, v_rel, band.inertia(p, counts));
            PairTerm {
                block: -(h * r.damping + h * h * r.stiffness),
                rhs: h * (r.force - r.damping * v_rel),
                force: r.force,
            }
        })
        .collect()
}

/// Per vertex, what its pairs' friction bounds μ F_c are scaled by: the
/// normal load it carried in the last step's solve over the load its
/// pairs push with at this step's start (Σ |β| F_c of `pushes`, in key
/// order), 1 where either is 0 (a first touch). The bound is the normal
/// force of the solve, lagged a step, as IPC lags its contact forces:
/// taken at the step's start alone, it jumps by a whole pair's share when
/// a vertex gains or loses one at the same depth, and since a vertex
/// between n and n + 1 pairs gains 1/n and loses 1/(n + 1) of its load,
/// a sliding layer's friction averages several percent above μ times its
/// weight (DESIGN "The cloth against itself").
pub fn bound_scales(pairs: &[Pair], pushes: &[f32], carried: &[f32]) -> Vec<f32> {
    let mut pushed = vec![0.0f32; carried.len()];
    for (p, f) in pairs.iter().zip(pushes) {
        for (&i, b) in p.vertices.iter().zip(p.beta) {
            pushed[i as usize] += b.abs() * f;
        }
    }
    (pushed.iter().zip(carried))
        .map(|(&start, &solved)| match start > 0.0 && solved > 0.0 {
            true => solved / start,
            false => 1.0,
        })
        .collect()
}

/// The off-diagonal blocks of the pairs, β_k β_l B at (k, l ≠ k), which
/// fall outside the springs' pattern: applied by gathering over each
/// vertex's pairs, in key order (as the GPU's sorted lists).
#[derive(Clone, Debug, Default)]
pub struct Couplings {
    pairs: Vec<Pair>,
    blocks: Vec<Mat3>,
    /// Per vertex, where its entries start (n + 1; empty with no pairs).
    starts: Vec<u32>,
    /// 4 · pair + slot of the vertex in the pair.
    entries: Vec<u32>,
}

impl Couplings {
    /// The couplings of `pairs` with their terms, on a cloth of `n`
    /// vertices.
    pub fn new(n: usize, pairs: &[Pair], terms: &[PairTerm]) -> Couplings {
        if pairs.is_empty() {
            return Couplings::default();
        }
        let mut starts = vec![0u32; n + 1];
        for p in pairs {
            for &v in &p.vertices {
                starts[v as usize + 1] += 1;
            }
        }
        for i in 0..n {
            starts[i + 1] += starts[i];
        }
        let mut fill = starts.clone();
        let mut entries = vec![0u32; starts[n] as usize];
        for (index, p) in pairs.iter().enumerate() {
            for (slot, &v) in p.vertices.iter().enumerate() {
                entries[fill[v as usize] as usize] = 4 * index as u32 + slot as u32;
                fill[v as usize] += 1;
            }
        }
        Couplings {
            pairs: pairs.to_vec(),
            blocks: terms.iter().map(|t| t.block).collect(),
            starts,
            entries,
        }
    }

    /// Each pair with its block B: what A holds off the springs' pattern,
    /// β_k β_l B at (k, l ≠ k).
    pub fn blocks(&self) -> impl Iterator<Item = (&Pair, &Mat3)> {
        self.pairs.iter().zip(&self.blocks)
    }

    /// Row i of the couplings times `x`: Σ over vertex i's pairs of
    /// β_k B Σ_{l ≠ k} β_l x_l.
    pub fn row(&self, i: usize, x: &[Vec3]) -> Vec3 {
        if self.starts.is_empty() {
            return Vec3::ZERO;
        }
        let entries = &self.entries[self.starts[i] as usize..self.starts[i + 1] as usize];
        entries.iter().fold(Vec3::ZERO, |acc, &e| {
            let (index, slot) = ((e / 4) as usize, (e % 4) as usize);
            let p = &self.pairs[index];
            let others = (0..4)
                .filter(|&l| l != slot)
                .fold(Vec3::ZERO, |s, l| s + p.beta[l] * x[p.vertices[l] as usize]);
            acc + p.beta[slot] * (self.blocks[index] * others)
        })
    }
}

/// Adds each pair's diagonal blocks β_k² B to A's diagonal and β_k times
/// its right-hand side to b.
pub fn add_to_system(pairs: &[Pair], terms: &[PairTerm], diag: &mut [Sym3], b: &mut [Vec3]) {
    for (p, t) in pairs.iter().zip(terms) {
        let block = Sym3::from_mat3(t.block);
        for (&v, &beta) in p.vertices.iter().zip(&p.beta) {
            diag[v as usize] += beta * beta * block;
            b[v as usize] += beta * t.rhs;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::triangle_boxes;
    use crate::cpu::separate::triangle_edges;

    const THICKNESS: f32 = 5e-3;
    const K: Coefficients = Coefficients {
        kn: 1000.0,
        kd: 1.0,
        kt: 100.0,
        mu: 0.5,
    };
    const BAND: Band = Band {
        coefficients: K,
        thickness: THICKNESS,
        h: 0.01,
        limit: f32::INFINITY,
        vertex_mass: 1e-3,
    };

    /// A 3×3-vertex sheet and, `gap` above it, a second one turned by
    /// `turn` radians about z and shifted, so that vertices of each lie
    /// over the other's faces and edges cross; rest points far apart.
    fn two_layers(gap: f32, turn: f32) -> (Vec<Vec3>, Vec<[u32; 3]>, Vec<Vec3>) {
        let (mut x, mut t, mut rest) = (Vec::new(), Vec::new(), Vec::new());
        let rotation = Mat3::from_rotation_z(turn);
        for layer in 0..2u32 {
            for i in 0..9u32 {
                let p = Vec3::new((i % 3) as f32 * 0.1, (i / 3) as f32 * 0.1, 0.0);
                x.push(match layer {
                    0 => p,
                    _ => rotation * p + Vec3::new(0.03, 0.02, gap),
                });
                rest.push(p + Vec3::new(layer as f32 * 10.0, 0.0, 0.0));
            }
            for r in 0..2 {
                for c in 0..2 {
                    let v = 9 * layer + 3 * r + c;
                    t.push([v, v + 1, v + 3]);
                    t.push([v + 1, v + 4, v + 3]);
                }
            }
        }
        (x, t, rest)
    }

    fn find_all(x: &[Vec3], t: &[[u32; 3]], rest: &[Vec3]) -> Found {
        let edges = triangle_edges(t);
        let sheet = Sheet::new(t, &edges, rest, THICKNESS);
        let found = sheet.find(x, &Bvh::build(&triangle_boxes(x, t)), PAIRS_PER_VERTEX);
        assert_eq!(found.dropped, 0);
        found
    }

    fn find(x: &[Vec3], t: &[[u32; 3]], rest: &[Vec3]) -> Vec<Pair> {
        find_all(x, t, rest).pairs
    }

    /// Velocities along `along`, of a different size at each vertex.
    fn swirl(n: usize, along: Vec3) -> Vec<Vec3> {
        (0..n).map(|i| along * (i as f32 * 0.37).sin()).collect()
    }

    /// No load carried from a last step.
    fn unloaded(x: &[Vec3]) -> Vec<f32> {
        vec![0.0; x.len()]
    }

    /// Counts of one pair at each vertex: the coefficients as configured.
    fn alone(x: &[Vec3]) -> Vec<u32> {
        vec![1; x.len()]
    }

    /// The contacts are those of testing every pair, both kinds present.
    #[test]
    fn found_pairs_are_those_of_testing_every_pair() {
        let (x, t, rest) = two_layers(3e-3, 0.4);
        let edges = triangle_edges(&t);
        let sheet = Sheet::new(&t, &edges, &rest, THICKNESS);
        let (sheet, x) = (&sheet, &x);
        let mut every: Vec<Pair> = (0..x.len() as u32)
            .flat_map(|v| (0..t.len() as u32).filter_map(move |f| sheet.vertex_pair(x, v, f)))
            .collect();
        for (i, &e) in edges.iter().enumerate() {
            every.extend(
                edges[i + 1..]
                    .iter()
                    .filter_map(|&f| sheet.edge_pair(x, e, f)),
            );
        }
        every.sort_by_key(Pair::key);
        let found = find(x, &t, &rest);
        assert_eq!(found, every);
        assert!(found.iter().any(|p| p.edges) && found.iter().any(|p| !p.edges));
        // Nothing within one layer: those pairs are close at rest.
        let layer = |v: u32| v / 9;
        assert!(
            found
                .iter()
                .all(|p| layer(p.vertices[0]) != layer(p.vertices[3]))
        );
    }

    /// A fine sheet folded over itself, where 2ε spans three spacings: the
    /// contacts are those whose nearest points lie 2ε apart at rest, found
    /// here by testing every pair with no shortcut. The walk passes over
    /// the triangles two of whose vertices are near its vertex at rest,
    /// and the pairs test their vertices' rest distances first; neither
    /// may lose a contact.
    #[test]
    fn the_rest_shortcuts_keep_every_contact_of_a_fold() {
        let (nx, ny, spacing) = (14u32, 6u32, 3e-3f32);
        let hinge = (nx - 1) as f32 * spacing / 2.0;
        let mut x = Vec::new();
        let mut rest = Vec::new();
        for i in 0..nx * ny {
            let p = Vec3::new((i % nx) as f32 * spacing, (i / nx) as f32 * spacing, 0.0);
            rest.push(p);
            // The far half turned over the near one, a little aside, 3 mm up.
            x.push(match p.x > hinge {
                true => Vec3::new(2.0 * hinge - p.x + 1e-3, p.y + 1.3e-3, 3e-3),
                false => p,
            });
        }
        let t: Vec<[u32; 3]> = (0..ny - 1)
            .flat_map(|r| (0..nx - 1).map(move |c| r * nx + c))
            .flat_map(|v| [[v, v + 1, v + nx], [v + 1, v + nx + 1, v + nx]])
            .collect();
        let r = |i: u32| rest[i as usize];
        let apart = |gap: Vec3| gap.length() >= 2.0 * THICKNESS;
        let at = |i: u32| x[i as usize];
        let mut every = Vec::new();
        for v in 0..x.len() as u32 {
            for tri in t.iter().filter(|tri| !tri.contains(&v)) {
                let [a, b, c] = tri.map(r);
                let w = vertex_triangle(at(v), tri.map(at), THICKNESS);
                if let Some(w) = w.filter(|_| apart(r(v) - closest_on_triangle(r(v), a, b, c))) {
                    every.push(Pair {
                        vertices: [v, tri[0], tri[1], tri[2]],
                        edges: false,
                        beta: [1.0, -w.x, -w.y, -w.z],
                    });
                }
            }
        }
        let edges = triangle_edges(&t);
        for (k, &e) in edges.iter().enumerate() {
            for &f in edges[k + 1..]
                .iter()
                .filter(|f| !e.iter().any(|v| f.contains(v)))
            {
                let (p, q) = closest_between_segments(r(e[0]), r(e[1]), r(f[0]), r(f[1]));
                let st = edge_edge(e.map(at), f.map(at), THICKNESS);
                if let Some((s, t)) = st.filter(|_| apart(p - q)) {
                    every.push(Pair {
                        vertices: [e[0], e[1], f[0], f[1]],
                        edges: true,
                        beta: [1.0 - s, s, t - 1.0, -t],
                    });
                }
            }
        }
        every.sort_by_key(Pair::key);
        let found = find(&x, &t, &rest);
        assert_eq!(found, every);
        // Where the walk passes over a triangle, no pair of its vertex and
        // the vertex's edges with it is apart at rest.
        let sheet = Sheet::new(&t, &edges, &rest, THICKNESS);
        let mut passed_over = 0;
        for (v, &tri) in (0..x.len() as u32).flat_map(|v| t.iter().map(move |tri| (v, tri))) {
            if !separate::passed_over(tri.map(|j| sheet.refused(v, j))) {
                continue;
            }
            passed_over += 1;
            let [a, b, c] = tri.map(r);
            assert!(!apart(r(v) - closest_on_triangle(r(v), a, b, c)));
            for e in edges.iter().filter(|e| e[0] == v) {
                for f in separate::edges_of(tri) {
                    let (p, q) = closest_between_segments(r(e[0]), r(e[1]), r(f[0]), r(f[1]));
                    assert!(!apart(p - q), "{e:?} {f:?}");
                }
            }
        }
        assert!(passed_over > 0);
        // Both kinds, and vertex–triangle pairs within ε that the rule
        // refuses, neighbours at the fold.
        let vertex_pairs = found.iter().filter(|p| !p.edges).count();
        assert!(vertex_pairs > 0 && vertex_pairs < found.len());
        let close = (0..x.len() as u32)
            .flat_map(|v| t.iter().map(move |&tri| (v, tri)))
            .filter(|(v, tri)| !tri.contains(v))
            .filter(|&(v, tri)| vertex_triangle(at(v), tri.map(at), THICKNESS).is_some())
            .count();
        assert!(close > vertex_pairs, "{close} close, {vertex_pairs} kept");
    }

    /// ∂d̃/∂x_l = β_l nᵀ: moving vertex l by δ along n changes the distance
    /// by β_l δ, so the penalty's normal stiffness at (k, l) is the finite
    /// difference of vertex k's normal force, −k_n β_k β_l.
    #[test]
    fn pair_stiffness_is_the_finite_difference_of_the_normal_force() {
        let (x, t, rest) = two_layers(2.5e-3, 0.4);
        let still = vec![Vec3::ZERO; x.len()];
        // No damping, so the block at rest is −h² K_c alone.
        let band = Band {
            coefficients: Coefficients { kd: 0.0, ..K },
            ..BAND
        };
        let pairs = find(&x, &t, &rest);
        assert!(pairs.len() > 4);
        let delta = 1e-5;
        for p in &pairs {
            let (normal, _) = p.normal_depth(&x, THICKNESS);
            for l in 0..4 {
                let force_along = |sign: f32| {
                    let mut moved = x.clone();
                    moved[p.vertices[l] as usize] += sign * delta * normal;
                    let again = find(&moved, &t, &rest);
                    let q = again
                        .iter()
                        .find(|q| q.key() == p.key())
                        .expect("pair kept");
                    respond(
                        &[*q],
                        &alone(&moved),
                        &unloaded(&moved),
                        &moved,
                        &still,
                        &band,
                    )[0]
                    .force
                    .dot(normal)
                };
                let slope = (force_along(1.0) - force_along(-1.0)) / (2.0 * delta);
                let term = respond(&[*p], &alone(&x), &unloaded(&x), &x, &still, &band)[0];
                // B = −h² K_c at rest; nᵀ K_c n = −k_n.
                let k_nn = -normal.dot(term.block * normal) / (0.01 * 0.01);
                for k in 0..4 {
                    let expected = p.beta[k] * slope;
                    let assembled = p.beta[k] * p.beta[l] * k_nn;
                    assert!(
                        (assembled - expected).abs() <= 2e-2 * K.kn,
                        "{p:?} k {k} l {l}: {assembled} vs finite difference {expected}"
                    );
                }
                assert!((slope - p.beta[l] * -K.kn).abs() <= 2e-2 * K.kn, "{slope}");
            }
        }
    }

    /// The couplings and the diagonal blocks make the pairs' quadratic
    /// form Σ (Σ_k β_k x_k)ᵀ B (Σ_l β_l x_l) ≥ 0, exactly the full 4×4
    /// blocks' action.
    #[test]
    fn couplings_apply_the_full_pair_blocks() {
        let (x, t, rest) = two_layers(2e-3, 0.4);
        let v = swirl(x.len(), Vec3::new(0.3, -0.1, 0.05));
        let pairs = find(&x, &t, &rest);
        let terms = respond(&pairs, &alone(&x), &unloaded(&x), &x, &v, &BAND);
        let n = x.len();
        let couplings = Couplings::new(n, &pairs, &terms);
        let mut diag = vec![Sym3::ZERO; n];
        add_to_system(&pairs, &terms, &mut diag, &mut vec![Vec3::ZERO; n]);
        let probe: Vec<Vec3> = (0..n)
            .map(|i| Vec3::new((i as f32).cos(), (2.0 * i as f32).sin(), 0.5))
            .collect();
        for i in 0..n {
            let applied = diag[i] * probe[i] + couplings.row(i, &probe);
            let full = pairs.iter().zip(&terms).fold(Vec3::ZERO, |acc, (p, t)| {
                let sum = (0..4).fold(Vec3::ZERO, |s, l| {
                    s + p.beta[l] * probe[p.vertices[l] as usize]
                });
                let mine = (0..4)
                    .filter(|&k| p.vertices[k] as usize == i)
                    .map(|k| p.beta[k])
                    .sum::<f32>();
                acc + mine * (t.block * sum)
            });
            assert!(
                (applied - full).length() <= 1e-5 * (1.0 + full.length()),
                "{i}"
            );
        }
        let form: f32 = (0..n)
            .map(|i| probe[i].dot(diag[i] * probe[i] + couplings.row(i, &probe)))
            .sum();
        assert!(form > 0.0);
    }

    /// With a limit, the blocks a vertex's pairs add to A stay within
    /// twice it (h k_d + h² k_n along the normal, h k_t across), wherever
    /// the vertex is crowded; the friction still keeps to Coulomb's cone.
    #[test]
    fn a_vertex_s_pairs_add_at_most_twice_the_limit_and_keep_to_coulomb() {
        let (x, t, rest) = two_layers(1.5e-3, 0.4);
        let v = swirl(x.len(), Vec3::new(0.02, -0.01, 0.0));
        let found = find_all(&x, &t, &rest);
        let limit = 1e-4;
        let band = Band { limit, ..BAND };
        let terms = respond(&found.pairs, &found.counts, &unloaded(&x), &x, &v, &band);
        let raw = respond(&found.pairs, &found.counts, &unloaded(&x), &x, &v, &BAND);
        // The largest eigenvalue of a symmetric positive semidefinite block.
        let largest = |b: Mat3| {
            let y = (0..64).fold(Vec3::new(0.6, 0.7, 0.4), |y, _| (b * y).normalize_or_zero());
            y.dot(b * y)
        };
        let mut added = vec![0.0f32; x.len()];
        for ((p, term), unlimited) in found.pairs.iter().zip(&terms).zip(&raw) {
            for (&i, beta) in p.vertices.iter().zip(p.beta) {
                added[i as usize] += beta * beta * largest(term.block);
            }
            // Unlimited, the blocks are a hundred times the limit.
            assert!(largest(unlimited.block) > 100.0 * limit);
            let (n, _) = p.normal_depth(&x, THICKNESS);
            let normal = term.force.dot(n);
            let across = (term.force - normal * n).length();
            assert!(
                normal >= 0.0 && across <= K.mu * normal * (1.0 + 1e-5),
                "{p:?}"
            );
        }
        let most = added.iter().fold(0.0f32, |a, &b| a.max(b));
        assert!(
            most > 0.5 * limit && most <= 2.0 * limit * (1.0 + 1e-5),
            "{most}"
        );
    }
}
