//! The declared input domains of the two networks (DESIGN "The networks"),
//! their analytic targets, and uniform samples of each: what the training
//! data covers and what `eval-net` scores on.

use glam::Vec3;

use wgcloth::cpu::contact::{Coefficients, ContactFrame, friction, naive};
use wgcloth::nn::weights::NetKind;

/// Friction network: |c| ≤ 0.05 m, |v_rel| ≤ 2 m/s, coefficient ranges.
pub const MAX_DEPTH: f32 = 0.05;
pub const MAX_SPEED: f32 = 2.0;
pub const KN: (f32, f32) = (10.0, 1000.0);
pub const KD: (f32, f32) = (0.0, 10.0);
pub const KT: (f32, f32) = (1.0, 1000.0);
pub const MU: (f32, f32) = (0.0, 1.0);

/// The resting regime (issue 65), where cloth lies on a surface: depth
/// 0.1–5 mm, slide up to 5 cm/s, approach within ±1 cm/s. Forces there are
/// millinewtons to a few newtons, far below the domain's tens, so a
/// network that is good domain-wide can still be wrong here.
pub const RESTING_DEPTH: (f32, f32) = (1e-4, 5e-3);
pub const RESTING_SLIDE: f32 = 0.05;
pub const RESTING_APPROACH: f32 = 0.01;

/// Naive network, in its local frame (`cpu::contact::local_frame`):
/// triangles with corners within 0.15 m of a, points over them at most
/// 0.05 m deep.
pub const NAIVE_REACH: f32 = 0.15;

/// Input bounds in input order: the min-max scaler. The naive frame's cz
/// is always 0; its nominal range only keeps the scaler well defined.
pub fn bounds(kind: NetKind) -> (Vec<f32>, Vec<f32>) {
    match kind {
        NetKind::Friction => {
            let (c, v) = (MAX_DEPTH, MAX_SPEED);
            (
                vec![-c, -c, -c, -v, -v, -v, KN.0, KD.0, KT.0, MU.0],
                vec![c, c, c, v, v, v, KN.1, KD.1, KT.1, MU.1],
            )
        }
        // depth, approach, slide (either sign: the network also runs at −s).
        NetKind::FrictionContact => (
            vec![0.0, -MAX_SPEED, -MAX_SPEED, KN.0, KD.0, KT.0, MU.0],
            vec![MAX_DEPTH, MAX_SPEED, MAX_SPEED, KN.1, KD.1, KT.1, MU.1],
        ),
        NetKind::Naive => {
            let r = NAIVE_REACH;
            (
                vec![0.0, -r, 0.0, -r, -r, -r, -MAX_DEPTH],
                vec![r, r, r, r, r, r, 0.0],
            )
        }
    }
}

/// A small seeded generator (splitmix64), so data is reproducible.
#[derive(Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn range(&mut self, (lo, hi): (f32, f32)) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform in the ball of radius r.
    pub fn in_ball(&mut self, r: f32) -> Vec3 {
        loop {
            let p = Vec3::new(self.unit(), self.unit(), self.unit()) * 2.0 - 1.0;
            if p.length_squared() <= 1.0 {
                return p * r;
            }
        }
    }
}

/// One sample: inputs and the analytic target.
pub type Sample = (Vec<f32>, [f32; 3]);

/// A friction sample: the inputs and the analytic g (thesis eqs. 8–9).
pub fn friction_sample(c: Vec3, v: Vec3, k: &Coefficients) -> Sample {
    let g = friction(c, v, k).force;
    (
        vec![c.x, c.y, c.z, v.x, v.y, v.z, k.kn, k.kd, k.kt, k.mu],
        g.to_array(),
    )
}

/// A naive sample from local-frame inputs: the frame's normal is +z and
/// pz = d̃, so the target f / c is the naive force of c = (0, 0, pz)
/// (thesis eq. 6).
pub fn naive_sample(inputs: [f32; 7]) -> Sample {
    let f = naive(Vec3::new(0.0, 0.0, inputs[6]), 1.0).force;
    (inputs.to_vec(), f.to_array())
}

pub fn random_coefficients(rng: &mut Rng) -> Coefficients {
    Coefficients {
        kn: rng.range(KN),
        kd: rng.range(KD),
        kt: rng.range(KT),
        mu: rng.range(MU),
    }
}

/// The rows a network of `kind` evaluates for one uniform sample: the
/// sample's inputs, or for a friction network its contact frame's rows.
pub fn uniform_inputs(kind: NetKind, rng: &mut Rng) -> Vec<f32> {
    let (x, _) = uniform_sample(kind, rng);
    if kind == NetKind::Naive {
        return x;
    }
    let (c, v) = (Vec3::from_slice(&x[..3]), Vec3::from_slice(&x[3..6]));
    let k = Coefficients {
        kn: x[6],
        kd: x[7],
        kt: x[8],
        mu: x[9],
    };
    // c = 0 has no frame; any depth-zero row stands in for it.
    ContactFrame::new(c, v).map_or_else(
        || {
            let width = kind.inputs().len();
            let zeros = vec![0.0; width - 4];
            [&zeros[..], &x[6..]].concat().repeat(kind.evaluations())
        },
        |f| f.inputs(kind, &k),
    )
}

/// A friction sample of the resting regime with coefficients `k`: depth,
/// slide speed and approach speed uniform in their ranges, ĉ uniform on
/// the sphere and the slide along a uniform direction of its tangent plane.
pub fn resting_sample(rng: &mut Rng, k: &Coefficients) -> Sample {
    let c_hat = loop {
        let p = rng.in_ball(1.0);
        if p.length_squared() > 1e-4 {
            break p.normalize();
        }
    };
    let t_hat = loop {
        let p = rng.in_ball(1.0).reject_from(c_hat);
        if p.length_squared() > 1e-4 {
            break p.normalize();
        }
    };
    let depth = rng.range(RESTING_DEPTH);
    let v = rng.range((-RESTING_APPROACH, RESTING_APPROACH)) * c_hat
        + rng.range((0.0, RESTING_SLIDE)) * t_hat;
    friction_sample(depth * c_hat, v, k)
}

/// A uniform sample of a network's declared domain (in the world frame for
/// both friction networks).
/// Friction: c in the ball of radius 0.05 (c = n d̃ takes any direction, so
/// d̃ ≤ 0 is automatic), v_rel in the ball of radius 2, coefficients
/// uniform. Naive: b on +x, c in the upper half of the xy-plane, the point
/// over the triangle (uniform barycentric weights, a little beyond its
/// edges as detection allows) and up to 0.05 m below its plane.
pub fn uniform_sample(kind: NetKind, rng: &mut Rng) -> Sample {
    match kind {
        NetKind::Friction | NetKind::FrictionContact => {
            let c = rng.in_ball(MAX_DEPTH);
            let v = rng.in_ball(MAX_SPEED);
            friction_sample(c, v, &random_coefficients(rng))
        }
        NetKind::Naive => {
            let r = NAIVE_REACH;
            let b = Vec3::new(rng.range((0.005, r)), 0.0, 0.0);
            let c = Vec3::new(rng.range((-r, r)), rng.range((0.005, r)), 0.0);
            let (mut u, mut w) = (rng.unit(), rng.unit());
            if u + w > 1.0 {
                (u, w) = (1.0 - u, 1.0 - w);
            }
            let over = (u * b + w * c + 0.05 * Vec3::new(rng.unit(), rng.unit(), 0.0) - 0.025)
                .clamp(Vec3::splat(-r), Vec3::splat(r));
            let pz = -MAX_DEPTH * rng.unit();
            naive_sample([b.x, c.x, c.y, 0.0, over.x, over.y, pz])
        }
    }
}
