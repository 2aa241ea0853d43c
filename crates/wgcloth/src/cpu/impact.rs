//! What stage "separate" does to the near pairs that would close below the
//! floor (twin of wgsl/impact.wgsl): it changes their vertices' steps by
//! impulses, equal and opposite within each pair, so the cloth's momentum
//! is kept (to the fixed point's 2^-32 m), and friction is bounded by
//! Coulomb's law. Nothing is reset: a vertex no failing pair touches keeps
//! its step, and one that is pushed keeps what the push did not change.
//!
//! 1. **Impulse rounds.** A failing pair's two sides (the vertex and the
//!    triangle, or the two edges) are pushed apart along the slab it fails
//!    needing the least push, the free vertices of each side moving as
//!    one, just far enough that the pair passes, and friction takes at
//!    most μ times that push off their relative tangential step. The two
//!    sides' shares keep momentum: equal masses, so a vertex moves three
//!    times as far as the triangle it meets. A vertex the failsafe may not
//!    move (pinned, or pushed out of the body with no plane to keep it
//!    out by) stays, and so does one the body has stopped where the push
//!    would bring it nearer the body (the body wins: the layer behind is
//!    pushed instead); the other side's free vertices take their share.
//!    Each pair's change is divided by the most
//!    failing pairs at any of its vertices (a Jacobi sweep that does not
//!    overshoot a vertex between pairs), and the changes are summed in
//!    fixed point, whose sums do not depend on the order pairs are met
//!    in (the GPU adds them with integer atomics).
//! 2. **Impact zones** (Bridson, Fedkiw & Anderson 2002), for what the
//!    rounds leave: the vertices of each pair still failing join one zone
//!    (labels lowered to the least of the pair's, then each label to its
//!    label's label), and each zone moves as one: with a vertex it may not
//!    move, by that one's step; with one the body stopped, with the body
//!    (as far from it as it started); else by its mean step, which keeps
//!    its momentum. No pair within a zone closes at all.

use glam::Vec3;

use crate::config::SelfContactConfig;
use crate::cpu::collide::Contact;
use crate::cpu::separate::NearPair;

/// Impulse rounds a detection of near pairs runs before impact zones.
pub const IMPULSE_ROUNDS: u32 = 8;
/// Rounds of impact zones a detection runs after its impulse rounds.
pub const ZONE_ROUNDS: u32 = 16;

/// Fixed-point units a metre: steps are summed as integers of 2^-32 m.
pub const UNITS: f32 = 4_294_967_296.0;
/// The largest |step| fixed point holds, m (a step beyond is a run that
/// has already diverged).
pub const LARGEST: f32 = 1_073_741_824.0;

/// `x` m in fixed point: |x| (at most [`LARGEST`]) times 2^32, truncated,
/// with x's sign; 0 where x is not finite. The GPU builds the same integer
/// as two words: whole metres, then the fraction, each exact in f32.
pub fn to_fixed(x: f32) -> i64 {
    if !x.is_finite() {
        return 0;
    }
    let w = x.abs().min(LARGEST) * UNITS;
    let high = (w / UNITS).trunc();
    let low = w - high * UNITS;
    let q = ((high as i64) << 32) + low as i64;
    if x < 0.0 { -q } else { q }
}

/// A fixed-point sum back in metres: its magnitude's high word times 2^32
/// plus its low word, in f32 (the GPU's operations, rounding alike), times
/// 2^-32, with its sign (so that a small negative sum is as exact as a
/// positive one).
pub fn from_fixed(q: i64) -> f32 {
    let m = q.unsigned_abs();
    let high = (m >> 32) as u32 as f32;
    let low = m as u32 as f32;
    let x = (high * UNITS + low) / UNITS;
    if q < 0 { -x } else { x }
}

/// Each component of `v` in fixed point.
fn fixed3(v: Vec3) -> [i64; 3] {
    v.to_array().map(to_fixed)
}

/// A sum of fixed-point vectors back in metres.
fn vec3_of(q: [i64; 3]) -> Vec3 {
    Vec3::from_array(q.map(from_fixed))
}

/// Where a vertex in contact with the body at the step's start may go:
/// not nearer its surface, which moves by `surface_step`, than the floor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyGap {
    /// The surface's outward unit normal.
    pub normal: Vec3,
    /// The vertex's signed distance above the surface at the start, m.
    pub gap: f32,
    /// How far the surface moves in the step, m.
    pub surface_step: Vec3,
}

/// Each cloth vertex's gap to the body from the step's vertex–face
/// `contacts` found where it started (none for a pinned vertex), h the
/// step.
pub fn body_gaps(contacts: &[Contact], pinned: &[bool], h: f32) -> Vec<Option<BodyGap>> {
    let mut body = vec![None; pinned.len()];
    for c in contacts.iter().filter(|c| c.cloth_triangle.is_none()) {
        let i = c.vertices[0] as usize;
        body[i] = (!pinned[i]).then_some(BodyGap {
            normal: c.normal,
            gap: c.distance,
            surface_step: -c.velocity_offset * h,
        });
    }
    body
}

/// How the failsafe treats the cloth: the pair test's gamma and floor, the
/// friction coefficient, the vertices it may not move and where the body
/// bounds them.
pub struct Impact<'a> {
    /// Gamma and floor.
    pub keep: &'a SelfContactConfig,
    /// μ, the `[contact]` one.
    pub mu: f32,
    /// Per vertex: pinned, or pushed out of the body with no contact at the
    /// step's start to keep it out by: the failsafe does not move it.
    pub fixed: &'a [bool],
    /// Per vertex: stopped against the body ([`Impact::clip`]), which it
    /// may leave but not come nearer.
    pub stopped: Vec<bool>,
    /// Per vertex, its gap to the body where it was in contact with it at
    /// the step's start (never for a pinned one).
    pub body: &'a [Option<BodyGap>],
}

/// A failing pair's push ([`Impact::push`]): its free first-side vertices
/// each move by `first` times `change`, its free second-side ones by
/// −`second` times it, and the others not at all. With free vertices on
/// both sides the factors are the other side's free count, so the two
/// sides' momenta are equal and opposite.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Push {
    /// The change, m: t along the slab's normal, less up to μ t of the
    /// relative tangential step.
    pub change: Vec3,
    /// The first side's factor.
    pub first: u32,
    /// The second side's factor.
    pub second: u32,
    /// Which of the pair's four vertices the push moves.
    pub free: [bool; 4],
}

impl Impact<'_> {
    /// Whether vertex `v` may move along `direction`: not fixed, and not
    /// stopped against the body where that brings it nearer.
    fn free(&self, v: u32, direction: Vec3) -> bool {
        let v = v as usize;
        let into = |g: &BodyGap| g.normal.dot(direction) < 0.0;
        let held_by_body = self.stopped[v] && self.body[v].as_ref().is_some_and(into);
        !(self.fixed[v] || held_by_body)
    }

    /// The push that makes a failing pair pass, or `None` where it passes
    /// or no push can (it touches, with no slab, or a slab's failing
    /// vertex pair holds no free vertex): a zone must take it.
    ///
    /// Across a slab of normal n, the first side's free vertices (those
    /// that may move along n) move by `first` t n and the second's (along
    /// −n) by −`second` t n, so a vertex pair (a, b) of the two sides
    /// closes by w_a first + w_b second times t less (w: 1 free, 0 not).
    /// Across each usable slab, t is the least that brings every vertex
    /// pair's approach n·(d_b − d_a) to 63/64 of the slab's allowance (so
    /// rounding does not leave it failing by an ulp); the slab needing the
    /// least t is taken. Friction then takes up to μ t off the relative
    /// tangential step of the two sides' mean steps, no more than stops it
    /// (Coulomb, with the push's momentum as the normal impulse).
    pub fn push(&self, pair: &NearPair, d: &[Vec3]) -> Option<Push> {
        if pair.touching() {
            return None;
        }
        let step = |v: u32| d[v as usize];
        let (p, q) = pair.sides();
        let mut best: Option<(f32, Vec3, Push)> = None;
        for slab in pair.usable(self.keep) {
            let n = slab.normal;
            let free: [bool; 4] = std::array::from_fn(|k| {
                let direction = if k < p.len() { n } else { -n };
                self.free(pair.vertices[k], direction)
            });
            let (free_p, free_q) = free.split_at(p.len());
            let count = |side: &[bool]| side.iter().filter(|&&f| f).count() as u32;
            let (first, second) = match (count(free_p), count(free_q)) {
                (0, 0) => (0, 0),
                (0, _) => (0, 1),
                (_, 0) => (1, 0),
                (free_p, free_q) => (free_q, free_p),
            };
            let allowance = slab.allowance(self.keep);
            let aim = allowance - allowance / 64.0;
            let (mut most, mut t, mut pushable) = (0.0f32, 0.0f32, true);
            for (j, &a) in p.iter().enumerate() {
                for (k, &b) in q.iter().enumerate() {
                    let approach = n.dot(step(b) - step(a));
                    most = most.max(approach);
                    if approach > aim {
                        let rate = (free_p[j] as u32 * first + free_q[k] as u32 * second) as f32;
                        pushable &= rate > 0.0;
                        t = t.max((approach - aim) / rate);
                    }
                }
            }
            if most <= allowance {
                return None;
            }
            if pushable && best.as_ref().is_none_or(|(least, ..)| t < *least) {
                let push = Push {
                    change: Vec3::ZERO,
                    first,
                    second,
                    free,
                };
                best = Some((t, n, push));
            }
        }
        let (t, n, push) = best?;
        let mean = |side: &[u32]| {
            let sum = side.iter().fold(Vec3::ZERO, |s, &v| s + step(v));
            sum / side.len() as f32
        };
        let relative = mean(p) - mean(q);
        let tangential = relative - n * n.dot(relative);
        let slide = tangential.length();
        // How fast the relative mean step changes with the change.
        let (free_p, free_q) = push.free.split_at(p.len());
        let moving = |side: &[bool]| side.iter().filter(|&&f| f).count() as u32;
        let rate = (moving(free_p) * push.first) as f32 / p.len() as f32
            + (moving(free_q) * push.second) as f32 / q.len() as f32;
        let friction = match slide > 0.0 {
            true => tangential * ((slide / rate).min(self.mu * t) / slide),
            false => Vec3::ZERO,
        };
        Some(Push {
            change: n * t - friction,
            ..push
        })
    }

    /// The body wins: each vertex whose step `d` brings it nearer the
    /// body's surface than the floor, across the plane it had contact with
    /// at the start (or was pushed out to), moves out along its normal to
    /// the floor, and is stopped from then on: no push moves it nearer,
    /// and its zone moves with the body. The body takes the momentum.
    pub fn clip(&mut self, i: usize, d: &mut Vec3) {
        let Some(g) = self.body[i] else {
            return;
        };
        let along = g.normal.dot(*d - g.surface_step);
        let least = self.keep.floor - g.gap;
        if along < least {
            *d += g.normal * (least - along);
            self.stopped[i] = true;
        }
    }

    /// Whether the pair passes with steps `d` ([`NearPair::passes`]).
    fn passes(&self, pair: &NearPair, d: &[Vec3]) -> bool {
        pair.passes(|v| d[v as usize], self.keep)
    }

    /// The fixed-point change of each of a pair's four vertices by its
    /// push divided among `shared` pairs: the change's integers b, times
    /// the first side's factor for a free first-side vertex and minus the
    /// second's for a free second-side one, so that with free vertices on
    /// both sides their sum is zero to the unit.
    pub fn shares(&self, pair: &NearPair, push: Push, shared: u32) -> [[i64; 3]; 4] {
        let base = fixed3(push.change / shared as f32);
        let split = pair.sides().0.len();
        std::array::from_fn(|k| {
            let factor = match (push.free[k], k < split) {
                (false, _) => 0,
                (true, true) => push.first as i64,
                (true, false) => -(push.second as i64),
            };
            base.map(|b| factor * b)
        })
    }

    /// Up to [`IMPULSE_ROUNDS`] rounds over `pairs`, each changing `d` by
    /// every failing pair's [`shares`](Impact::shares) of its
    /// [`push`](Impact::push) divided among the most failing pairs at any
    /// of its vertices, summed in fixed point; `moved` marks each vertex a
    /// round changed. Stops at the first round in which no pair fails.
    pub fn impulse_rounds(&mut self, pairs: &[NearPair], d: &mut [Vec3], moved: &mut [bool]) {
        let n = d.len();
        let mut counts = vec![0u32; n];
        let mut sums = vec![[0i64; 3]; n];
        for _ in 0..IMPULSE_ROUNDS {
            let failing: Vec<&NearPair> = pairs.iter().filter(|p| !self.passes(p, d)).collect();
            if failing.is_empty() {
                return;
            }
            for pair in &failing {
                for &v in &pair.vertices {
                    counts[v as usize] += 1;
                }
            }
            for pair in &failing {
                let Some(push) = self.push(pair, d) else {
                    continue;
                };
                let most = pair.vertices.iter().map(|&v| counts[v as usize]).max();
                let shares = self.shares(pair, push, most.unwrap_or(1));
                for (&v, share) in pair.vertices.iter().zip(shares) {
                    let sum = &mut sums[v as usize];
                    for k in 0..3 {
                        sum[k] += share[k];
                    }
                }
            }
            for i in 0..n {
                if sums[i] != [0; 3] {
                    d[i] += vec3_of(sums[i]);
                    moved[i] = true;
                    self.clip(i, &mut d[i]);
                }
                sums[i] = [0; 3];
                counts[i] = 0;
            }
        }
    }

    /// Up to [`ZONE_ROUNDS`] rounds of impact zones over `pairs`. `label`
    /// (each vertex's own index at the step's start) names each vertex's
    /// zone and `zoned` marks the vertices in one; both carry over between
    /// the step's detections, so a zone only grows. Each round: every pair
    /// that fails lowers its vertices' labels to the least of theirs as
    /// they stood (`next`), then each label becomes its label's next; then
    /// every zoned vertex that is not fixed takes its zone's step: that
    /// of its lowest fixed vertex; else, where it holds a vertex stopped
    /// against the body, the body's step there (the zone moves with the
    /// body, as far from it as it started); else its mean step, which
    /// keeps its momentum. A step is kept out of the body ([`Impact::clip`]).
    pub fn zone_rounds(
        &mut self,
        pairs: &[NearPair],
        d: &mut [Vec3],
        label: &mut [u32],
        zoned: &mut [bool],
    ) {
        let n = d.len();
        let mut next = vec![0u32; n];
        // Per zone, at its label: the fixed-point sum of its unfixed
        // vertices' steps and their count, and its lowest fixed and
        // stopped vertices.
        let mut sums = vec![([0i64; 3], 0u32); n];
        let (mut pin, mut body) = (vec![u32::MAX; n], vec![u32::MAX; n]);
        for _ in 0..ZONE_ROUNDS {
            let failing: Vec<&NearPair> = pairs.iter().filter(|p| !self.passes(p, d)).collect();
            if failing.is_empty() {
                return;
            }
            next.copy_from_slice(label);
            for pair in &failing {
                let least = pair.vertices.iter().map(|&v| label[v as usize]).min();
                let least = least.expect("a pair has four vertices");
                for &v in &pair.vertices {
                    next[v as usize] = next[v as usize].min(least);
                    zoned[v as usize] = true;
                }
            }
            for i in 0..n {
                label[i] = next[next[i] as usize];
            }
            for i in (0..n).filter(|&i| zoned[i]) {
                let z = label[i] as usize;
                if self.fixed[i] {
                    pin[z] = pin[z].min(i as u32);
                    continue;
                }
                if self.stopped[i] {
                    body[z] = body[z].min(i as u32);
                }
                let (sum, count) = &mut sums[z];
                for (s, q) in sum.iter_mut().zip(fixed3(d[i])) {
                    *s += q;
                }
                *count += 1;
            }
            for i in 0..n {
                if !zoned[i] || self.fixed[i] {
                    continue;
                }
                let z = label[i] as usize;
                let mut step = match (pin[z], body[z]) {
                    (u32::MAX, u32::MAX) => vec3_of(sums[z].0) / sums[z].1 as f32,
                    (u32::MAX, b) => {
                        let gap = self.body[b as usize].expect("a stopped vertex has a gap");
                        gap.surface_step
                    }
                    (a, _) => d[a as usize],
                };
                self.clip(i, &mut step);
                d[i] = step;
            }
            pin.fill(u32::MAX);
            body.fill(u32::MAX);
            sums.fill(([0; 3], 0));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default gamma (0.45) and floor (1 mm).
    const KEEP: &SelfContactConfig = &SelfContactConfig {
        enabled: true,
        gamma: 0.45,
        floor: 1e-3,
        thickness: 5e-3,
        mass_ratio: 100.0,
    };

    /// The failsafe over a lone pair's four vertices, `fixed` of them it
    /// may not move, μ = 0.5, no body.
    fn lone(fixed: &'static [bool; 4]) -> Impact<'static> {
        Impact {
            keep: KEEP,
            mu: 0.5,
            fixed,
            stopped: vec![false; 4],
            body: &[None; 4],
        }
    }

    /// A vertex 4 mm above the middle of a triangle in z = 0, stepping
    /// down by `down` and sideways by `slide`, the triangle still.
    fn falling_vertex(down: f32, slide: f32) -> (NearPair, Vec<Vec3>) {
        let start = [
            Vec3::new(0.3, 0.3, 0.004),
            Vec3::ZERO,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let pair = NearPair::at([0, 1, 2, 3], false, &start);
        let d = vec![
            Vec3::new(slide, 0.0, -down),
            Vec3::ZERO,
            Vec3::ZERO,
            Vec3::ZERO,
        ];
        (pair, d)
    }

    /// The steps after one round of `pair` alone.
    fn pushed(impact: &Impact, pair: &NearPair, d: &[Vec3]) -> Vec<Vec3> {
        let push = impact.push(pair, d).expect("the pair fails");
        let shares = impact.shares(pair, push, 1);
        (0..4).map(|k| d[k] + vec3_of(shares[k])).collect()
    }

    /// One push makes a lone pair pass, its sides' momenta cancel to the
    /// fixed point's unit, the vertex moves three times as far as the
    /// triangle, and friction takes at most μ times the push off the slide
    /// (Coulomb), stopping a slow one.
    #[test]
    fn a_push_passes_keeps_momentum_and_obeys_coulomb() {
        let impact = lone(&[false; 4]);
        for slide in [0.0, 1e-3, 0.05] {
            let (pair, d) = falling_vertex(0.01, slide);
            assert!(!pair.passes(|v| d[v as usize], KEEP));
            let push = impact.push(&pair, &d).unwrap();
            let shares = impact.shares(&pair, push, 1);
            let total = shares
                .iter()
                .fold([0i64; 3], |t, s| std::array::from_fn(|k| t[k] + s[k]));
            assert_eq!(total, [0; 3], "slide {slide}: momentum");
            let after = pushed(&impact, &pair, &d);
            assert!(
                pair.passes(|v| after[v as usize], KEEP),
                "slide {slide}: passes"
            );
            let (vertex, triangle) = (after[0] - d[0], after[1] - d[1]);
            assert!(
                (vertex + 3.0 * triangle).length() < 1e-8,
                "slide {slide}: shares"
            );
            // The change of the sides' relative mean step: along z the
            // push, along x friction against the slide.
            let relative = |d: &[Vec3]| d[0] - (d[1] + d[2] + d[3]) / 3.0;
            let change = relative(&after) - relative(&d);
            let (normal, friction) = (change.z, -change.x);
            assert!(normal > 0.0 && friction >= 0.0, "{change}");
            assert!(
                friction <= 0.5 * normal * (1.0 + 1e-5),
                "slide {slide}: Coulomb"
            );
            let left = relative(&after).x;
            match slide {
                0.0 => assert_eq!(friction, 0.0),
                // Stopped: the slide is under μ times the push.
                s if s < 0.5 * normal => assert!(left.abs() < 1e-8, "{left}"),
                // Slowed by μ times the push.
                _ => assert!((friction - 0.5 * normal).abs() < 1e-6 * normal, "{change}"),
            }
        }
    }

    /// A triangle vertex the failsafe may not move stays, and the vertex
    /// takes the whole push; with both sides fixed, nothing can push.
    #[test]
    fn a_vertex_that_may_not_move_stays() {
        let impact = lone(&[false, true, false, false]);
        let (pair, d) = falling_vertex(0.01, 0.0);
        let after = pushed(&impact, &pair, &d);
        assert_eq!(after[1], Vec3::ZERO);
        assert!(pair.passes(|v| after[v as usize], KEEP));
        let stuck = lone(&[true; 4]);
        assert_eq!(stuck.push(&pair, &d), None);
    }

    /// Impact zones: two pairs that no push may fix, each with a vertex
    /// the failsafe may not move on both sides, are merged, and the free
    /// vertices take their zone's anchor's step; a free zone takes its
    /// mean, which keeps its momentum.
    #[test]
    fn zones_move_as_one() {
        let (pair, d) = falling_vertex(0.01, 0.02);
        let mut impact = lone(&[false; 4]);
        let (mut steps, mut label, mut zoned) = (d.clone(), vec![0, 1, 2, 3], vec![false; 4]);
        impact.zone_rounds(&[pair], &mut steps, &mut label, &mut zoned);
        assert_eq!(zoned, [true; 4]);
        assert_eq!(label, [0; 4]);
        let mean = d.iter().sum::<Vec3>() / 4.0;
        assert!(
            steps.iter().all(|s| (*s - mean).length() < 1e-9),
            "{steps:?}"
        );
        assert!(pair.passes(|v| steps[v as usize], KEEP));
        let mut impact = lone(&[false, false, true, false]);
        let (mut steps, mut label, mut zoned) = (d.clone(), vec![0, 1, 2, 3], vec![false; 4]);
        impact.zone_rounds(&[pair], &mut steps, &mut label, &mut zoned);
        assert!(steps.iter().all(|s| *s == d[2]), "{steps:?}");
    }

    /// A vertex gap 2 mm above a body face of normal `normal` whose
    /// surface steps by `surface_step`.
    fn gap(normal: Vec3, surface_step: Vec3) -> Option<BodyGap> {
        Some(BodyGap {
            normal,
            gap: 2e-3,
            surface_step,
        })
    }

    /// The body wins and the layer it stops pushes the one behind: a
    /// triangle lying on the body, stopped against it, takes none of a
    /// falling vertex's push (the vertex takes it all and passes), where a
    /// free triangle would be pushed into the body; stopped against a body
    /// on the vertex's side instead, it is pushed away from it as if free.
    #[test]
    fn a_layer_stopped_against_the_body_pushes_the_layer_behind() {
        let (pair, d) = falling_vertex(0.01, 0.0);
        let below = [
            None,
            gap(Vec3::Z, Vec3::ZERO),
            gap(Vec3::Z, Vec3::ZERO),
            gap(Vec3::Z, Vec3::ZERO),
        ];
        let mut impact = Impact {
            body: &below,
            ..lone(&[false; 4])
        };
        let free = pushed(&impact, &pair, &d);
        assert!(free[1].z < 0.0, "a free triangle is pushed down: {free:?}");
        impact.stopped = vec![false, true, true, true];
        let after = pushed(&impact, &pair, &d);
        assert!(after[1..].iter().all(|s| *s == Vec3::ZERO), "{after:?}");
        assert!(pair.passes(|v| after[v as usize], KEEP));
        assert!(after[0].z > free[0].z, "the vertex takes the whole push");
        let above = [
            None,
            gap(-Vec3::Z, Vec3::ZERO),
            gap(-Vec3::Z, Vec3::ZERO),
            gap(-Vec3::Z, Vec3::ZERO),
        ];
        let impact = Impact {
            body: &above,
            stopped: vec![false, true, true, true],
            ..lone(&[false; 4])
        };
        assert_eq!(pushed(&impact, &pair, &d), free);
    }

    /// A zone holding a vertex the body stopped moves with the body's
    /// surface, as far from it as it started, not by its mean step.
    #[test]
    fn a_zone_the_body_stopped_moves_with_the_body() {
        let (pair, d) = falling_vertex(0.01, 0.02);
        let surface = Vec3::new(0.0, 0.0, 3e-3);
        let body = [None, None, gap(Vec3::Z, surface), None];
        let mut impact = Impact {
            body: &body,
            stopped: vec![false, false, true, false],
            ..lone(&[false; 4])
        };
        let (mut steps, mut label, mut zoned) = (d.clone(), vec![0, 1, 2, 3], vec![false; 4]);
        impact.zone_rounds(&[pair], &mut steps, &mut label, &mut zoned);
        assert!(steps.iter().all(|s| *s == surface), "{steps:?}");
    }

    #[test]
    fn fixed_point_round_trips_and_sums_exactly() {
        for x in [0.0f32, 1e-9, -3.5e-4, 0.0123, -0.75, 2.5, -1234.5] {
            let back = from_fixed(to_fixed(x));
            // Truncated to 2^-32 m, then rounded once to f32.
            assert!(
                (back - x).abs() <= 2.5e-10 + x.abs() * 1.2e-7,
                "{x} -> {back}"
            );
        }
        assert_eq!(to_fixed(f32::NAN), 0);
        assert_eq!(to_fixed(-1.0), -(1i64 << 32));
        // Opposite values cancel to the unit, in any order.
        let a = to_fixed(0.3);
        let b = to_fixed(-0.1);
        assert_eq!(a + b + to_fixed(-0.3) + to_fixed(0.1), 0);
    }
}
