//! Stage "separate": each cloth vertex's step, from where it started to
//! where the solve and the push-out left it, changed where the cloth would
//! otherwise pass through itself (issue 23). Twin of wgsl/separate.wgsl.
//! The pairs are found and tested as in Offset Geometric Contact (Chen et
//! al. 2025), on their relative motion, so that a cloth moving as one is
//! never touched; what a failing pair does is `impact`'s: impulses that
//! keep momentum and obey Coulomb, then impact zones.
//!
//! Two moving triangles first touch as a vertex reaching a triangle or an
//! edge reaching an edge. A pair sharing no vertex can come within `floor`
//! of each other in the step only if the boxes swept by its two primitives
//! (start and end of each vertex), grown by `floor`, overlap: those are the
//! near pairs ([`near_pairs`]), each with its separation s at the start.
//! Every point of a primitive moves by a convex sum of its vertices'
//! displacements, so a pair whose displacements differ by at most
//! 2 gamma (s − floor) from one side to the other, across a slab between
//! them, ends the step above floor + (1 − 2 gamma)(s − floor)
//! ([`NearPair::passes`]). The floor is needed: without it a gap closing
//! geometrically reaches the spacing of f32 positions, whose rounding then
//! crosses it.
//!
//! A step ([`Within::keep_apart`]) finds the near pairs of its steps, and
//! while any fails, changes the steps ([`impact`](crate::cpu::impact)) and
//! finds them again, since a changed step sweeps a box of its own: up to
//! [`DETECTIONS`] times. Where the last still finds one failing, the last
//! resort holds the vertices of near pairs to `gamma (s_v − floor)` along
//! their steps ([`hold`]): held steps shrink their swept boxes, so it needs
//! no other detection. It is counted, and the scenes never reach it.
//!
//! The broad phase is the cloth's BVH refitted to the swept boxes. A
//! vertex's least separation is the least over its pairs, which the GPU
//! takes as an atomic minimum over the bits of non-negative f32s.

use glam::Vec3;
use rayon::prelude::*;

use crate::bvh::{Aabb, Bvh};
use crate::config::SelfContactConfig;
use crate::cpu::impact::{BodyGap, Impact};
use crate::math::{closest_between_segments, closest_on_triangle};
use crate::parallel::GRAIN;

/// Every edge of `triangles` once, by vertex (lower index first), sorted.
pub fn triangle_edges(triangles: &[[u32; 3]]) -> Vec<[u32; 2]> {
    let mut edges: Vec<[u32; 2]> = triangles.iter().flat_map(|&t| edges_of(t)).collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// Detections of near pairs a step runs: each but the last followed by
/// `impact`'s rounds where a pair fails, the last by the last resort.
pub const DETECTIONS: u32 = 4;
/// Rounds of the relative test ([`hold`]) before the last resort holds
/// every vertex in a near pair to its bound.
pub const ROUNDS: u32 = 8;
/// Near pairs the GPU's list holds per cloth vertex (wgsl/separate.wgsl);
/// past that the step falls back as when the rounds do not settle.
pub const NEAR_PAIRS_PER_VERTEX: u32 = 8;
/// Marks an edge–edge pair in the GPU's list: a bit of its first vertex
/// index, which never reaches it (a cloth has at most 2^26 vertices).
pub const EDGE_PAIR: u32 = 1 << 31;

/// A slab two primitives lie on either side of at the step's start: every
/// point of the first is at least `width` further along `normal` than
/// every point of the second.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Slab {
    /// Unit normal, from the second primitive's side to the first's; zero
    /// where there is none (the primitives touch, or are degenerate).
    pub normal: Vec3,
    /// Its width, m.
    pub width: f32,
}

impl Slab {
    /// The slab normal to `towards` (from the second primitive to the
    /// first) that holds a first-side point `a` and a second-side point `b`
    /// on its faces: the primitives lie in planes normal to it, or `a`
    /// and `b` are their nearest points.
    fn between(towards: Vec3, a: Vec3, b: Vec3) -> Slab {
        let normal = towards.normalize_or_zero();
        let width = normal.dot(a - b);
        match width < 0.0 {
            true => Slab {
                normal: -normal,
                width: -width,
            },
            false => Slab { normal, width },
        }
    }

    /// How far the sides may come nearer across it: 2 gamma (width − floor).
    pub fn allowance(&self, keep: &SelfContactConfig) -> f32 {
        2.0 * keep.gamma * (self.width - keep.floor).max(0.0)
    }
}

/// One vertex–triangle or edge–edge pair whose swept boxes come near.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearPair {
    /// The vertex then the triangle's three, or one edge's two then the
    /// other's.
    pub vertices: [u32; 4],
    /// Edge–edge (else vertex–triangle).
    pub edges: bool,
    /// Distance between the two primitives at the step's start, m.
    pub separation: f32,
    /// The slabs between them at the start: along the line between their
    /// nearest points (as wide as the separation), and normal to the
    /// triangle or to both edges (the planes they lie in; zero normal
    /// where degenerate).
    pub slabs: [Slab; 2],
}

impl NearPair {
    /// The pair of `vertices` as it stands at positions `start`.
    pub fn at(vertices: [u32; 4], edges: bool, start: &[Vec3]) -> NearPair {
        let at = |k: u32| start[k as usize];
        let [a, b, c, d] = vertices.map(at);
        let (nearest, plane) = match edges {
            false => {
                let q = closest_on_triangle(a, b, c, d);
                ((a, q), Slab::between((c - b).cross(d - b), a, b))
            }
            true => (
                closest_between_segments(a, b, c, d),
                Slab::between((b - a).cross(d - c), a, c),
            ),
        };
        let separation = (nearest.0 - nearest.1).length();
        NearPair {
            vertices,
            edges,
            separation,
            slabs: [
                Slab::between(nearest.0 - nearest.1, nearest.0, nearest.1),
                plane,
            ],
        }
    }

    /// The vertices of each primitive.
    pub fn sides(&self) -> (&[u32], &[u32]) {
        self.vertices.split_at(if self.edges { 2 } else { 1 })
    }

    /// Whether the primitives touch at the start: no slab between them.
    pub fn touching(&self) -> bool {
        self.slabs[0].normal == Vec3::ZERO
    }

    /// The slabs a test may use: the nearest points' (as wide as the
    /// separation), and the planes' where wider than the floor (a plane
    /// slab as thin as two coplanar edges' says nothing of how near they
    /// come within it).
    pub fn usable(&self, keep: &SelfContactConfig) -> impl Iterator<Item = &Slab> {
        let [nearest, plane] = &self.slabs;
        let plane = (plane.normal != Vec3::ZERO && plane.width > keep.floor).then_some(plane);
        std::iter::once(nearest).chain(plane)
    }

    /// Whether displacements `moved` keep the pair above the floor. Each
    /// point of a primitive moves by a convex sum of its vertices'
    /// displacements, so across a slab of width w the gap stays above
    /// w − the most n·(d_b − d_a) over a vertex a of the first side and b
    /// of the second: the pair passes when that is at most the slab's
    /// allowance for either slab (a slide along a slab brings nothing
    /// nearer). Touching, it passes when no displacement of one side
    /// differs from one of the other's by more than 2 gamma (s − floor).
    pub fn passes(&self, moved: impl Fn(u32) -> Vec3, keep: &SelfContactConfig) -> bool {
        let (p, q) = self.sides();
        let most = |f: &dyn Fn(u32, u32) -> f32| {
            (p.iter().flat_map(|&a| q.iter().map(move |&b| (a, b))))
                .fold(0.0, |m, (a, b)| f32::max(m, f(a, b)))
        };
        if self.touching() {
            let widest = most(&|a, b| (moved(a) - moved(b)).length());
            return widest <= 2.0 * keep.gamma * (self.separation - keep.floor).max(0.0);
        }
        self.usable(keep)
            .any(|s| most(&|a, b| s.normal.dot(moved(b) - moved(a))) <= s.allowance(keep))
    }

    /// Whether the pair could fail however its vertices are held: a held
    /// step is the full one scaled by a factor in [0, 1]. Across a slab,
    /// β n·d_b − α n·d_a is largest at max(0, n·d_b) + max(0, −n·d_a);
    /// touching, |α a − β b| is largest at a corner, the longest step or
    /// the widest difference of full steps.
    pub fn could_fail(&self, d: &[Vec3], keep: &SelfContactConfig) -> bool {
        let step = |v: u32| d[v as usize];
        if self.touching() {
            let longest = (self.vertices.iter()).fold(0.0f32, |m, &v| m.max(step(v).length()));
            return longest > 0.0 || !self.passes(step, keep);
        }
        let (p, q) = self.sides();
        let most = |side: &[u32], n: Vec3| side.iter().fold(0.0f32, |m, &v| m.max(n.dot(step(v))));
        self.usable(keep)
            .all(|s| most(q, s.normal) + most(p, -s.normal) > s.allowance(keep))
    }
}

/// The box swept by `vertices` from `start` to `end`.
pub fn swept(start: &[Vec3], end: &[Vec3], vertices: &[u32]) -> Aabb {
    vertices.iter().fold(Aabb::EMPTY, |b, &v| {
        b.grow(start[v as usize]).grow(end[v as usize])
    })
}

/// Where steps `d` from `start` end, as both paths compute them.
pub fn ends(start: &[Vec3], d: &[Vec3]) -> Vec<Vec3> {
    start.iter().zip(d).map(|(s, d)| *s + *d).collect()
}

/// Each triangle's swept box, what the BVH is refitted to.
pub fn swept_boxes(start: &[Vec3], end: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Aabb> {
    triangles.iter().map(|t| swept(start, end, t)).collect()
}

/// The near pairs: those sharing no vertex whose swept boxes, the first
/// grown by the floor, overlap and that [could fail](NearPair::could_fail)
/// (vertex–triangle, then edge–edge, each once), and each vertex's least
/// separation at the start over them (+∞ in none), for steps `d` from
/// `start`. Pairs that cannot fail need no bound, so they are left out of
/// both. `bvh` holds the [`swept_boxes`] to [`ends`].
pub fn near_pairs(
    start: &[Vec3],
    d: &[Vec3],
    triangles: &[[u32; 3]],
    edges: &[[u32; 2]],
    bvh: &Bvh,
    keep: &SelfContactConfig,
) -> (Vec<NearPair>, Vec<f32>) {
    let floor = keep.floor;
    let end = ends(start, d);
    let end = &end;
    let grown = |vertices: &[u32]| swept(start, end, vertices).grown(floor);
    let found: Vec<(Vec<NearPair>, Vec<NearPair>)> = (0..start.len() as u32)
        .into_par_iter()
        .with_min_len(GRAIN)
        .map(|v| {
            let (mut vertex, mut edge) = (Vec::new(), Vec::new());
            let boxed = |vertices: &[u32]| swept(start, end, vertices);
            candidates(
                v,
                (triangles, edges),
                bvh,
                (grown, boxed),
                |_, _| false,
                |pair| match pair {
                    Candidate::Vertex(t) => {
                        let tri = triangles[t as usize];
                        vertex.push(NearPair::at([v, tri[0], tri[1], tri[2]], false, start));
                    }
                    Candidate::Edges(e, f) => {
                        edge.push(NearPair::at([e[0], e[1], f[0], f[1]], true, start));
                    }
                },
            );
            let could_fail = |pair: &NearPair| pair.could_fail(d, keep);
            vertex.retain(could_fail);
            edge.retain(could_fail);
            (vertex, edge)
        })
        .collect();
    let (vertex, edge): (Vec<_>, Vec<_>) = found.into_iter().unzip();
    let mut pairs: Vec<NearPair> = vertex.into_iter().chain(edge).flatten().collect();
    // An edge–edge pair is met from both triangles along its upper edge.
    let first_edge_pair = pairs.partition_point(|p| !p.edges);
    pairs[first_edge_pair..].par_sort_unstable_by_key(|p| p.vertices);
    pairs.dedup_by_key(|p| (p.vertices, p.edges));
    let mut least = vec![f32::INFINITY; start.len()];
    for pair in &pairs {
        for &v in &pair.vertices {
            least[v as usize] = least[v as usize].min(pair.separation);
        }
    }
    (pairs, least)
}

/// A pair [`candidates`] names.
#[derive(Clone, Copy)]
pub enum Candidate {
    /// The walk's vertex and triangle t.
    Vertex(u32),
    /// One of the vertex's edges and a triangle's edge after it.
    Edges([u32; 2], [u32; 2]),
}

/// The pairs sharing no vertex whose first primitive is vertex `v` or an
/// edge it starts (its lower vertex; `edges` sorted) and whose boxes
/// overlap, the first's
/// `reach`, the second's `boxed` (an edge–edge pair perhaps twice, from
/// both triangles along its second edge), in one walk of `bvh` (which holds
/// the triangles' `boxed`) for the union of the first's: a walk for the
/// vertex and one for each of its edges cost more than their tests.
///
/// No pair is named with a vertex i on one side and j on the other where
/// `refused(i, j)`, which is asked before the pair's boxes are, and the
/// triangles it makes [`passed_over`] are passed over whole.
pub fn candidates(
    v: u32,
    (triangles, edges): (&[[u32; 3]], &[[u32; 2]]),
    bvh: &Bvh,
    (reach, boxed): (impl Fn(&[u32]) -> Aabb, impl Fn(&[u32]) -> Aabb),
    refused: impl Fn(u32, u32) -> bool,
    mut visit: impl FnMut(Candidate),
) {
    let own = &edges[edges.partition_point(|e| e[0] < v)..edges.partition_point(|e| e[0] <= v)];
    let vertex = reach(&[v]);
    let own_reach: Vec<Aabb> = own.iter().map(|e| reach(e)).collect();
    let query = own_reach.iter().fold(vertex, |q, b| q.union(*b));
    bvh.query_box(query, |t| {
        let tri = triangles[t as usize];
        let refused_with_v = tri.map(|j| refused(v, j));
        if passed_over(refused_with_v) {
            return;
        }
        let tri_box = boxed(&tri);
        if !tri.contains(&v) && refused_with_v == [false; 3] && vertex.overlaps(&tri_box) {
            visit(Candidate::Vertex(t));
        }
        for (&e, e_reach) in own.iter().zip(&own_reach) {
            if e_reach.overlaps(&tri_box) {
                for (f, ends) in edges_of(tri).into_iter().zip(TRIANGLE_EDGES) {
                    let apart = !e.iter().any(|v| f.contains(v));
                    // e is [v, w], and v's answers are in hand.
                    let kept = || {
                        !ends.iter().any(|&k| refused_with_v[k])
                            && !f.iter().any(|&j| refused(e[1], j))
                    };
                    if f > e && apart && kept() && e_reach.overlaps(&boxed(&f)) {
                        visit(Candidate::Edges(e, f));
                    }
                }
            }
        }
    });
}

/// Whether [`candidates`] passes over a triangle whose vertices are, in
/// turn, refused or not with the walk's vertex v: two of them are. Every
/// pair the walk names holds v on its first side and, on its second, the
/// triangle or one of its edges, each of which holds one of any two of its
/// vertices.
pub fn passed_over(refused_with_v: [bool; 3]) -> bool {
    refused_with_v.iter().filter(|&&r| r).count() >= 2
}

/// A triangle's edges by the places of their ends in it, as [`edges_of`]
/// lists them.
const TRIANGLE_EDGES: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];

/// A triangle's edges, each lower vertex first.
pub fn edges_of(t: [u32; 3]) -> [[u32; 2]; 3] {
    TRIANGLE_EDGES.map(|[a, b]| [t[a].min(t[b]), t[a].max(t[b])])
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

/// Which vertices a step must hold to their bounds so that no near pair
/// closes below the floor, or `None` when [`ROUNDS`] rounds do not settle
/// it (then every vertex in a near pair is held).
///
/// A pair at separation s whose vertices move by `d'` cannot close below
/// floor + (1 − 2 gamma)(s − floor) when every displacement of a vertex of
/// one primitive differs from every one of the other's by at most
/// 2 gamma (s − floor): each point of a primitive moves by a convex sum of
/// its vertices' displacements. Vertices moving together (a falling cloth)
/// so pass whatever their speed. Each round holds, besides those already
/// held, the four vertices of every pair that fails with the displacements
/// of the round before; held vertices move at most gamma (s − floor), so a
/// pair with all four held always passes, and the rounds only grow the set.
pub fn hold(
    pairs: &[NearPair],
    d: &[Vec3],
    bounds: &[f32],
    keep: &SelfContactConfig,
) -> Option<Vec<bool>> {
    let mut held = vec![false; d.len()];
    for _ in 0..ROUNDS {
        let moved = |v: u32| match held[v as usize] {
            true => within(d[v as usize], bounds[v as usize]),
            false => d[v as usize],
        };
        let failing: Vec<&NearPair> = pairs
            .iter()
            .filter(|pair| !pair.passes(moved, keep))
            .collect();
        let mut changed = false;
        for pair in failing {
            for &v in &pair.vertices {
                changed |= !std::mem::replace(&mut held[v as usize], true);
            }
        }
        if !changed {
            return Some(held);
        }
    }
    None
}

/// What a step's self-contact did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Separation {
    /// Near pairs found, the most of a detection (an edge–edge pair perhaps
    /// twice).
    pub pairs: usize,
    /// Vertices whose step the failsafe changed, in any of the ways below.
    pub changed: usize,
    /// Vertices whose step impulses changed.
    pub pushed: usize,
    /// Vertices moved in impact zones.
    pub zoned: usize,
    /// Vertices whose changed step the body stopped ([`Impact::clip`]).
    pub stopped: usize,
    /// Vertices the last resort held to their bounds.
    pub held: usize,
    /// Detections of near pairs run.
    pub detections: u32,
    /// False when the last resort ran.
    pub settled: bool,
}

/// The cloth a step keeps from passing through itself, and how.
pub struct Within<'a> {
    /// The cloth's triangles.
    pub triangles: &'a [[u32; 3]],
    /// Their edges ([`triangle_edges`]).
    pub edges: &'a [[u32; 2]],
    /// Gamma and floor.
    pub keep: &'a SelfContactConfig,
    /// μ, the `[contact]` one.
    pub mu: f32,
    /// Per vertex: pinned, or pushed out of the body with no contact at
    /// the step's start.
    pub fixed: &'a [bool],
    /// Per vertex, its gap to the body where it had contact with it at the
    /// step's start ([`BodyGap`]).
    pub body: &'a [Option<BodyGap>],
    /// The time step, s.
    pub h: f32,
}

impl Within<'_> {
    /// The step from `start` to `x`, changed where the cloth would
    /// otherwise pass through itself: up to [`DETECTIONS`] detections of
    /// the near pairs (`bvh` refitted to their swept boxes), each where a
    /// pair fails but the last followed by `impact`'s impulse and zone
    /// rounds; where the last finds a pair failing, the last resort
    /// ([`hold`]), which holds the vertices the failsafe may not move too:
    /// without them its pairs could cross. The impulses' and zones' steps
    /// are kept out of the body ([`Impact::clip`]). A changed
    /// vertex ends at its start plus its step, and its velocity changes by
    /// its step's change over h.
    pub fn keep_apart(
        &self,
        start: &[Vec3],
        x: &mut [Vec3],
        v: &mut [Vec3],
        bvh: &mut Bvh,
    ) -> Separation {
        let keep = self.keep;
        let n = x.len();
        let solved: Vec<Vec3> = x.iter().zip(start).map(|(x, s)| *x - *s).collect();
        let mut d = solved.clone();
        let mut impact = Impact {
            keep,
            mu: self.mu,
            fixed: self.fixed,
            stopped: vec![false; n],
            body: self.body,
        };
        let mut label: Vec<u32> = (0..n as u32).collect();
        let (mut zoned, mut pushed) = (vec![false; n], vec![false; n]);
        let mut done = Separation {
            settled: true,
            ..Separation::default()
        };
        for detection in 0..DETECTIONS {
            let swept = swept_boxes(start, &ends(start, &d), self.triangles);
            bvh.refit(|t| swept[t as usize]);
            let (pairs, least) = near_pairs(start, &d, self.triangles, self.edges, bvh, keep);
            done.detections += 1;
            done.pairs = done.pairs.max(pairs.len());
            if pairs.iter().all(|p| p.passes(|v| d[v as usize], keep)) {
                break;
            }
            if detection + 1 == DETECTIONS {
                let bounds: Vec<f32> = least.iter().map(|&s| displacement_bound(s, keep)).collect();
                let rounds = hold(&pairs, &d, &bounds, keep);
                let held = rounds.unwrap_or_else(|| least.iter().map(|s| s.is_finite()).collect());
                for i in 0..n {
                    if held[i] && d[i].length() > bounds[i] {
                        d[i] = within(d[i], bounds[i]);
                        done.held += 1;
                    }
                }
                done.settled = false;
                break;
            }
            impact.impulse_rounds(&pairs, &mut d, &mut pushed);
            impact.zone_rounds(&pairs, &mut d, &mut label, &mut zoned);
        }
        for i in (0..n).filter(|&i| d[i] != solved[i]) {
            x[i] = start[i] + d[i];
            v[i] += (d[i] - solved[i]) / self.h;
            done.changed += 1;
        }
        done.stopped = impact.stopped.iter().filter(|&&s| s).count();
        done.pushed = pushed.iter().filter(|&&p| p).count();
        done.zoned = zoned.iter().filter(|&&z| z).count();
        done
    }
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

    /// The least distance between two primitives sharing no vertex.
    fn closest_gap(x: &[Vec3], t: &[[u32; 3]], edges: &[[u32; 2]]) -> f32 {
        // Every box swept a metre along each axis: every pair overlaps and
        // could fail.
        let far: Vec<Vec3> = x.iter().map(|&p| p + Vec3::ONE).collect();
        let (_, least) = brute_force(x, &far, t, edges, &KEEP);
        least.into_iter().fold(f32::INFINITY, f32::min)
    }

    /// The near pairs (each once, sorted) and least separations by
    /// testing every pair.
    fn brute_force(
        start: &[Vec3],
        end: &[Vec3],
        t: &[[u32; 3]],
        edges: &[[u32; 2]],
        keep: &SelfContactConfig,
    ) -> (Vec<([u32; 4], bool)>, Vec<f32>) {
        let floor = keep.floor;
        let d: Vec<Vec3> = end.iter().zip(start).map(|(e, s)| *e - *s).collect();
        let mut least = vec![f32::INFINITY; start.len()];
        let mut pairs = Vec::new();
        let grown = |v: &[u32]| swept(start, end, v).grown(floor);
        let mut note = |vertices: [u32; 4], edges: bool| {
            let pair = NearPair::at(vertices, edges, start);
            if !pair.could_fail(&d, keep) {
                return;
            }
            let s = pair.separation;
            pairs.push((vertices, edges));
            for v in vertices {
                least[v as usize] = least[v as usize].min(s);
            }
        };
        for v in 0..start.len() as u32 {
            for tri in t.iter().filter(|tri| !tri.contains(&v)) {
                if grown(&[v]).overlaps(&swept(start, end, tri)) {
                    note([v, tri[0], tri[1], tri[2]], false);
                }
            }
        }
        for (i, e) in edges.iter().enumerate() {
            for f in edges[i + 1..]
                .iter()
                .filter(|f| !e.iter().any(|v| f.contains(v)))
            {
                if grown(e).overlaps(&swept(start, end, f)) {
                    note([e[0], e[1], f[0], f[1]], true);
                }
            }
        }
        pairs.sort_unstable();
        (pairs, least)
    }

    fn near(
        start: &[Vec3],
        end: &[Vec3],
        t: &[[u32; 3]],
        edges: &[[u32; 2]],
        keep: &SelfContactConfig,
    ) -> (Vec<NearPair>, Vec<f32>) {
        let bvh = Bvh::build(&swept_boxes(start, end, t));
        let d: Vec<Vec3> = end.iter().zip(start).map(|(e, s)| *e - *s).collect();
        near_pairs(start, &d, t, edges, &bvh, keep)
    }

    const KEEP: SelfContactConfig = SelfContactConfig {
        enabled: true,
        gamma: 0.45,
        floor: 1e-3,
        thickness: 5e-3,
        mass_ratio: 100.0,
    };

    #[test]
    fn near_pairs_are_those_of_testing_every_pair() {
        let (mut start, t) = two_sheets(5);
        let edges = triangle_edges(&t);
        // Crumpled and moving, so pairs of every kind are near.
        let mut seed = 3u64;
        for p in &mut start {
            *p += 0.004 * jitter(&mut seed);
        }
        let end: Vec<Vec3> = start
            .iter()
            .map(|&p| p + 0.01 * jitter(&mut seed))
            .collect();
        let (pairs, least) = near(&start, &end, &t, &edges, &KEEP);
        let mut found: Vec<([u32; 4], bool)> =
            pairs.iter().map(|p| (p.vertices, p.edges)).collect();
        found.sort_unstable();
        found.dedup();
        let (want, want_least) = brute_force(&start, &end, &t, &edges, &KEEP);
        assert_eq!(found, want);
        assert_eq!(least, want_least);
        assert!(pairs.iter().any(|p| p.edges) && pairs.iter().any(|p| !p.edges));
        // Flat layers 1 cm apart moving together by 2 cm along their plane:
        // the boxes of a vertex and the far triangle of a cell around it
        // overlap, but no pair could fail.
        let (flat, _) = two_sheets(5);
        let moved: Vec<Vec3> = flat
            .iter()
            .map(|&p| p + Vec3::new(0.02, 0.0, 0.0))
            .collect();
        let (pairs, least) = near(&flat, &moved, &t, &edges, &KEEP);
        assert!(pairs.is_empty() && least.iter().all(|s| s.is_infinite()));
    }

    /// The lower of two sheets 1 cm apart pushed up into the upper, 4 mm a
    /// step with jitter: held as `hold` says, it never crosses and stops at
    /// the floor; let go, it crosses.
    #[test]
    fn held_steps_never_cross_and_free_ones_do() {
        let (x0, t) = two_sheets(6);
        let edges = triangle_edges(&t);
        let keep = SelfContactConfig {
            enabled: true,
            gamma: 0.45,
            floor: 1e-4,
            thickness: 0.0,
            mass_ratio: 100.0,
        };
        let run = |held: bool| {
            let mut x = x0.clone();
            let mut seed = 7u64;
            let (mut worst, mut closest, mut fallbacks) = (0, f32::INFINITY, 0);
            for _ in 0..40 {
                let d: Vec<Vec3> = (0..x.len())
                    .map(|i| {
                        let toward = if i < 36 { 0.004 * Vec3::Z } else { Vec3::ZERO };
                        toward + 0.002 * jitter(&mut seed)
                    })
                    .collect();
                let end: Vec<Vec3> = x.iter().zip(&d).map(|(x, d)| *x + *d).collect();
                let (pairs, least) = near(&x, &end, &t, &edges, &keep);
                let bounds: Vec<f32> = least
                    .iter()
                    .map(|&s| displacement_bound(s, &keep))
                    .collect();
                let hold_set = hold(&pairs, &d, &bounds, &keep).unwrap_or_else(|| {
                    fallbacks += 1;
                    least.iter().map(|s| s.is_finite()).collect()
                });
                for i in 0..x.len() {
                    x[i] += match held && hold_set[i] {
                        true => within(d[i], bounds[i]),
                        false => d[i],
                    };
                }
                worst = worst.max(intersecting_pairs(&x, &t).len());
                closest = closest.min(closest_gap(&x, &t, &edges));
            }
            (worst, closest, fallbacks)
        };
        let (crossed, closest, fallbacks) = run(true);
        eprintln!("held: closest {closest}, {fallbacks} fallbacks");
        assert_eq!(crossed, 0, "held");
        // The layers close in to the floor and stop there (to the rounding
        // of a separation computed in f32).
        assert!(
            closest >= 0.999 * keep.floor && closest < 3.0 * keep.floor,
            "{closest}"
        );
        assert!(
            run(false).0 > 0,
            "let go, the layers cross, so the test can fail"
        );
    }

    /// Two sheets 1 cm apart moving together by 5 cm (five times their
    /// gap), across each other's path: nothing is held.
    #[test]
    fn vertices_moving_together_are_not_held_however_far() {
        let (start, t) = two_sheets(5);
        let edges = triangle_edges(&t);
        let keep = SelfContactConfig {
            enabled: true,
            ..Default::default()
        };
        let d = vec![Vec3::new(0.03, 0.0, 0.04); start.len()];
        let end: Vec<Vec3> = start.iter().map(|&p| p + d[0]).collect();
        let (pairs, least) = near(&start, &end, &t, &edges, &keep);
        assert!(
            pairs.len() > 50,
            "the layers are near: {} pairs",
            pairs.len()
        );
        let bounds: Vec<f32> = least
            .iter()
            .map(|&s| displacement_bound(s, &keep))
            .collect();
        assert!(bounds.iter().all(|&b| b < 0.05));
        assert_eq!(
            hold(&pairs, &d, &bounds, &keep),
            Some(vec![false; start.len()])
        );
    }
}
