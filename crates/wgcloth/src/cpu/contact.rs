//! Stage "contact": the collision models, the force each contact exerts and
//! its Jacobian blocks. Mirrors wgsl/contact.wgsl.
//!
//! Every model is a function of the network's inputs, the collision vector
//! c = n d̃ (d̃ < 0) and the relative velocity v_rel, and returns the force on
//! the penetrating point with its Jacobians ∂f/∂c and ∂f/∂v_rel. The chain
//! rule into the system is the same for all of them (with n held fixed
//! during the step, ∂c/∂x_k = β_k n nᵀ):
//!   K_c = (∂f/∂c) n nᵀ,  D_c = ∂f/∂v_rel,
//! each then made symmetric negative semidefinite so A stays SPD.

use glam::{Mat3, Vec3};
use rayon::prelude::*;

pub use crate::config::Coefficients;
use crate::config::{ContactConfig, ModelKind};
use crate::cpu::collide::{Contact, Geometry};
use crate::math::{outer, project_nsd, symmetric_part};
use crate::nn::Mlp;
use crate::nn::mlp::LANES;
use crate::nn::weights::{NetKind, Network};
use std::sync::Arc;

/// A force and its Jacobians with respect to c and v_rel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ForceJacobian {
    /// Force on the penetrating point (g, before the scale s, for the
    /// friction models' unscaled functions).
    pub force: Vec3,
    /// ∂force/∂c, with c the collision vector.
    pub d_c: Mat3,
    /// ∂force/∂v_rel.
    pub d_v: Mat3,
}

impl ForceJacobian {
    const ZERO: ForceJacobian = ForceJacobian {
        force: Vec3::ZERO,
        d_c: Mat3::ZERO,
        d_v: Mat3::ZERO,
    };

    fn scaled(self, s: f32) -> ForceJacobian {
        ForceJacobian {
            force: self.force * s,
            d_c: self.d_c * s,
            d_v: self.d_v * s,
        }
    }
}

/// Naive penalty force (thesis eq. 6): f = −c_n d̃ n, which with c = n d̃ is
/// simply −c_n c; the velocity plays no part.
pub fn naive(c: Vec3, stiffness: f32) -> ForceJacobian {
    ForceJacobian {
        force: -stiffness * c,
        d_c: Mat3::from_diagonal(Vec3::splat(-stiffness)),
        d_v: Mat3::ZERO,
    }
}

/// Eq. 8's normal force F_c = max(0, −k_n d̃ + k_d ḋ) at c (|c| = −d̃) and
/// relative velocity v: what friction's bound μ F_c is taken of; 0 on
/// the surface.
pub fn normal_force(c: Vec3, v: Vec3, k: &Coefficients) -> f32 {
    let r = c.length();
    if r == 0.0 {
        return 0.0;
    }
    (k.kn * r + k.kd * v.dot(c / r)).max(0.0)
}

/// The friction model of thesis eqs. 8–9 (after Xu et al.), unscaled: g
/// with f = s g. From c: |c| = −d̃, n = −c/|c|. With ḋ = −(v_rel·n) the
/// approach speed and ṫ = v_rel − (v_rel·n) n the tangential velocity,
///   F_c = max(0, −k_n d̃ + k_d ḋ)                        (eq. 8, no pulling)
///   g   = F_c n − min(k_t |ṫ|, μ F_c) ṫ/|ṫ|             (eq. 9)
/// Stick: k_t|ṫ| ≤ μF_c, friction −k_t ṫ (ṫ = 0 lands here: no friction).
/// Slip: Coulomb friction −μ F_c t̂. Jacobians are exact in each branch,
/// including the turning of n with c.
pub fn friction(c: Vec3, v: Vec3, k: &Coefficients) -> ForceJacobian {
    let f_c = normal_force(c, v, k);
    if f_c == 0.0 {
        // On the surface (d̃ = 0), or separating faster than the spring
        // pushes.
        return ForceJacobian::ZERO;
    }
    let r = c.length();
    let c_hat = c / r;
    let n = -c_hat;
    let p = Mat3::IDENTITY - outer(c_hat, c_hat); // projector onto the tangent plane
    let approach = v.dot(c_hat); // ḋ = −v·n
    // ∂F_c/∂c = k_n ĉᵀ + k_d vᵀP / r; ∂F_c/∂v = k_d ĉᵀ (rows, stored as vectors).
    let dfc_dc = k.kn * c_hat + k.kd * (p * v) / r;
    let dfc_dv = k.kd * c_hat;
    // Normal part F_c n = −F_c ĉ.
    let mut force = f_c * n;
    let mut d_c = -outer(c_hat, dfc_dc) - (f_c / r) * p;
    let mut d_v = -outer(c_hat, dfc_dv);
    // ṫ = P v; ∂ṫ/∂v = P; ∂ṫ/∂c = −((ĉ·v) P + ĉ (P v)ᵀ) / r.
    let t_dot = p * v;
    let dt_dc = -(approach * p + outer(c_hat, p * v)) / r;
    let speed = t_dot.length();
    if k.kt * speed <= k.mu * f_c {
        force -= k.kt * t_dot;
        d_c -= k.kt * dt_dc;
        d_v -= k.kt * p;
    } else {
        let t_hat = t_dot / speed;
        let turn = (Mat3::IDENTITY - outer(t_hat, t_hat)) * (1.0 / speed); // ∂t̂/∂ṫ
        force -= k.mu * f_c * t_hat;
        d_c -= k.mu * (outer(t_hat, dfc_dc) + f_c * turn * dt_dc);
        d_v -= k.mu * (outer(t_hat, dfc_dv) + f_c * turn * p);
    }
    ForceJacobian { force, d_c, d_v }
}

/// A collision model with its coefficients, as selected for a run.
#[derive(Clone, Debug, PartialEq)]
pub enum Model {
    /// The naive penalty force f = −c_n d̃ n (thesis eq. 6); see [`naive`].
    Naive {
        /// c_n, N/m.
        stiffness: f32,
    },
    /// The analytic friction model of thesis eqs. 8–9, f = s g; see
    /// [`friction`].
    Friction {
        /// s, the force scale.
        scale: f32,
        /// k_n, k_d, k_t, μ.
        coefficients: Coefficients,
    },
    /// g from the network (thesis 2.7), read in the contact's frame
    /// ([`ContactFrame`]) whichever frame it was trained in; ∂g/∂c and ∂g/∂v_rel from its input
    /// Jacobian, by reverse mode through the layers.
    FrictionNet {
        /// The friction network; its kind picks world or contact frame.
        net: Arc<Network>,
        /// s, the force scale: f = s g.
        scale: f32,
        /// k_n, k_d, k_t, μ, fed to the network as inputs.
        coefficients: Coefficients,
    },
    /// f / c from the small network of thesis 2.4 in the contact's local
    /// frame, ∂/∂p from its input Jacobian.
    NaiveNet {
        /// The naive network (7 inputs, [`LocalFrame::inputs`]).
        net: Arc<Network>,
        /// c_n, N/m: the network predicts f / c_n.
        stiffness: f32,
    },
}

/// The naive network's local frame (thesis 2.4): the triangle's first
/// corner a at the origin and b on +x. The thesis leaves the roll about x
/// free; fixing it so the triangle lies in the xy-plane with its normal
/// (the contact normal) along +z makes cz always 0 and pz = d̃, so the naive
/// force is exactly linear in the frame, as the thesis found its data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalFrame {
    /// World → frame: rows e1 (along b − a), e2, e3 (the normal).
    pub rotation: Mat3,
    /// bx, cx, cy, cz, px, py, pz: the network's inputs.
    pub inputs: [f32; 7],
}

/// The local frame of a contact's geometry; None for a degenerate triangle.
pub fn local_frame(g: &Geometry) -> Option<LocalFrame> {
    let [a, b, c] = g.triangle;
    let e1 = (b - a).normalize_or_zero();
    let e3 = (b - a).cross(c - a).normalize_or_zero();
    if e1 == Vec3::ZERO || e3 == Vec3::ZERO {
        return None;
    }
    let rotation = Mat3::from_cols(e1, e3.cross(e1), e3).transpose();
    let [b, c, p] = [b, c, g.point].map(|q| rotation * (q - a));
    Some(LocalFrame {
        rotation,
        inputs: [b.x, c.x, c.y, 0.0, p.x, p.y, p.z],
    })
}

/// f / c and its Jacobians from a naive network. The network's ∂f/∂p,
/// turned back to the world, stands in for ∂f/∂c: with n held fixed c moves
/// with p only along n, and the chain rule keeps (∂f/∂c) n nᵀ, which for
/// the exact naive force is −I n nᵀ = (−n nᵀ) n nᵀ either way.
pub fn naive_net(net: &Mlp, g: &Geometry) -> ForceJacobian {
    let Some(frame) = local_frame(g) else {
        return ForceJacobian::ZERO;
    };
    let (f, j) = net.forward_jacobian(&frame.inputs, NetKind::Naive.wrt());
    naive_net_output(&frame, &f, &j)
}

/// The naive network's output f and Jacobian j in `frame`, back in the
/// world.
fn naive_net_output(frame: &LocalFrame, f: &[f32], j: &[f32]) -> ForceJacobian {
    let back = frame.rotation.transpose();
    // j is row-major [3 outputs × 3 tangents (px, py, pz)].
    let d_p = Mat3::from_cols(
        Vec3::new(j[0], j[3], j[6]),
        Vec3::new(j[1], j[4], j[7]),
        Vec3::new(j[2], j[5], j[8]),
    );
    ForceJacobian {
        force: back * Vec3::new(f[0], f[1], f[2]),
        d_c: back * d_p * frame.rotation,
        d_v: Mat3::ZERO,
    }
}

/// Below this slide speed (m/s) ṫ has no direction: friction is taken as
/// zero and g_t / s as its limit ∂g_t/∂s.
pub const SLIDE_AT_REST: f32 = 1e-6;

/// A contact in its own frame, where both friction networks are evaluated.
/// Eqs. 8–9 give g = g_n n + g_t t̂ with n = −ĉ and t̂ = ṫ/|ṫ|, where g_n
/// and g_t depend only on the depth r = |c|, the approach speed
/// a = v_rel·ĉ (ḋ), the slide speed s = |ṫ| and the coefficients. The
/// contact-frame network learns two scalars from which [`cone`] forms g_n
/// and g_t, and the directions are exact. The world-frame network (thesis
/// 2.7) is evaluated at the same contact turned to the frame's directions
/// and its g read along n and t̂: the thesis used its g as it came, which
/// holds no cone, has friction where nothing slides, and fails Coulomb's
/// law (issue 21). Its g_t is the odd part in s,
///   g_t = (y_t(s) − y_t(−s)) / 2,
/// so friction vanishes with ṫ as it must and g_t / s stays finite (the
/// Jacobian's (g_t / s)(I − t̂t̂ᵀ) ∂ṫ term cannot blow up at rest), and its
/// g_n the even part: it saw few samples at zero slide (a uniform ball of
/// v_rel has slide density ∝ s) and its y_n(0) errs 2× more. The
/// contact-frame network's normal output is read at slide 0 (eq. 8 does
/// not depend on the slide) and its rate output as the even part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactFrame {
    c_hat: Vec3,
    /// t̂; zero below `SLIDE_AT_REST`.
    t_hat: Vec3,
    t_dot: Vec3,
    depth: f32,
    approach: f32,
    slide: f32,
}

impl ContactFrame {
    /// The frame at collision vector c and relative velocity v; None at
    /// c = 0, which has no normal (and no force).
    pub fn new(c: Vec3, v: Vec3) -> Option<ContactFrame> {
        let depth = c.length();
        if depth == 0.0 {
            return None;
        }
        let c_hat = c / depth;
        let approach = v.dot(c_hat);
        let t_dot = v - approach * c_hat;
        let slide = t_dot.length();
        Some(ContactFrame {
            c_hat,
            t_hat: if slide > SLIDE_AT_REST {
                t_dot / slide
            } else {
                Vec3::ZERO
            },
            t_dot,
            depth,
            approach,
            slide,
        })
    }

    /// The slides of the rows a friction network of `kind` is evaluated at.
    fn slides(&self, kind: NetKind) -> impl Iterator<Item = f32> {
        [self.slide, -self.slide, 0.0]
            .into_iter()
            .take(kind.evaluations())
    }

    /// A friction network's input rows, at +slide, at −slide and (the
    /// contact-frame network) at 0: (depth, approach, slide, k_n, k_d, k_t,
    /// μ) for the contact-frame network; for the world-frame one (c, v_rel,
    /// k_n, k_d, k_t, μ) with c = depth ĉ and v_rel = approach ĉ + slide t̂,
    /// the same contact turned to the frame's directions.
    pub fn inputs(&self, kind: NetKind, k: &Coefficients) -> Vec<f32> {
        let (mut rows, mut still) = (Vec::new(), Vec::new());
        self.push_inputs(kind, k, &mut rows, &mut still);
        rows.extend(still);
        rows
    }

    /// [`inputs`](ContactFrame::inputs) appended, the rows at ±slide to
    /// `moving` and the row at slide 0 to `still`: a block's rows are
    /// gathered without a vector per contact, and the still rows, of which
    /// only g_n is read, can be carried back for g_n alone.
    pub fn push_inputs(
        &self,
        kind: NetKind,
        k: &Coefficients,
        moving: &mut Vec<f32>,
        still: &mut Vec<f32>,
    ) {
        let (r, a) = (self.depth, self.approach);
        for (row, s) in self.slides(kind).enumerate() {
            let rows = if row < kind.moving_rows() {
                &mut *moving
            } else {
                &mut *still
            };
            match kind {
                NetKind::FrictionContact => rows.extend_from_slice(&[r, a, s]),
                _ => {
                    let v = a * self.c_hat + s * self.t_hat;
                    rows.extend_from_slice(&(r * self.c_hat).to_array());
                    rows.extend_from_slice(&v.to_array());
                }
            }
            rows.extend_from_slice(&[k.kn, k.kd, k.kt, k.mu]);
        }
    }

    /// A friction network's outputs y and input Jacobians j at the rows of
    /// [`inputs`](ContactFrame::inputs), read in this frame (as the
    /// contact-frame network's: (g_n, g_t) a row, and row-major [2 × (depth,
    /// approach, slide)]) and held to the friction cone.
    pub fn network_force(
        &self,
        kind: NetKind,
        y: &[f32],
        j: &[f32],
        k: &Coefficients,
    ) -> ForceJacobian {
        let still = (kind == NetKind::FrictionContact).then(|| (y[4], &j[12..15]));
        self.moving_force(kind, y, j, still, k)
    }

    /// [`network_force`](ContactFrame::network_force) from the rows at
    /// ±slide, with the still row's g_n and ∂g_n/∂(depth, approach, slide)
    /// given apart (the contact-frame network's; None for the world-frame
    /// one's, which has no still row).
    fn moving_force(
        &self,
        kind: NetKind,
        y: &[f32],
        j: &[f32],
        still: Option<(f32, &[f32])>,
        k: &Coefficients,
    ) -> ForceJacobian {
        match kind {
            NetKind::FrictionContact => self.force(y, j, still, k),
            _ => {
                let (y, j) = self.read_world_rows(y, j);
                self.force(&y, &j, None, k)
            }
        }
    }

    /// The world-frame network's g (3 a row) and ∂g/∂(c, v_rel) (row-major
    /// [3 × 6] a row) in the frame: g_n = −ĉ·g and g_t = t̂·g, with the
    /// derivatives along the frame's directions, ∂/∂depth = J_c ĉ,
    /// ∂/∂approach = J_v ĉ and ∂/∂slide = J_v t̂. At rest t̂ is undefined;
    /// ∂g_t/∂slide, the tangential stiffness that holds a resting contact,
    /// is then the mean over the tangent plane, (tr J_v − ĉ·J_v ĉ) / 2.
    fn read_world_rows(&self, g: &[f32], j: &[f32]) -> ([f32; 4], [f32; 12]) {
        let (c_hat, t_hat) = (self.c_hat, self.t_hat);
        let (mut y, mut frame_j) = ([0.0; 4], [0.0; 12]);
        for row in 0..2 {
            let (g, j) = (Vec3::from_slice(&g[3 * row..]), &j[18 * row..]);
            let column = |t: usize| Vec3::new(j[t], j[6 + t], j[12 + t]);
            let j_c = Mat3::from_cols(column(0), column(1), column(2));
            let j_v = Mat3::from_cols(column(3), column(4), column(5));
            let along = [j_c * c_hat, j_v * c_hat, j_v * t_hat];
            y[2 * row..2 * row + 2].copy_from_slice(&[-c_hat.dot(g), t_hat.dot(g)]);
            let out = &mut frame_j[6 * row..6 * row + 6];
            for (d, a) in along.iter().enumerate() {
                out[d] = -c_hat.dot(*a);
                out[3 + d] = t_hat.dot(*a);
            }
            if t_hat == Vec3::ZERO {
                out[5] =
                    0.5 * (j_v.x_axis.x + j_v.y_axis.y + j_v.z_axis.z - c_hat.dot(j_v * c_hat));
            }
        }
        (y, frame_j)
    }

    /// (g_n, g_t) of a force g: what the network learns.
    pub fn targets(&self, g: Vec3) -> [f32; 2] {
        [-g.dot(self.c_hat), g.dot(self.t_hat)]
    }

    /// g and its Jacobians from a friction network's rows at +slide and
    /// −slide, y (two outputs a row) and their derivatives j (row-major
    /// [2 × (depth, approach, slide)] a row), and for the contact-frame
    /// network its still row's first output with that output's derivatives
    /// ([`cone`]); the world-frame network's (g_n, g_t) are the even and
    /// odd parts of its rows, held to eq. 8's "no pulling" and to Coulomb's
    /// law ([`coulomb`]).
    fn force(
        &self,
        y: &[f32],
        j: &[f32],
        still: Option<(f32, &[f32])>,
        k: &Coefficients,
    ) -> ForceJacobian {
        let (y0, y1) = (&y[..2], &y[2..4]);
        let (j0, j1) = (&j[..6], &j[6..12]);
        // Even and odd parts in the slide: the mirror row's slide is −s, so
        // its slide derivatives enter with the other sign.
        let even = |o: usize| {
            (
                0.5 * (y0[o] + y1[o]),
                0.5 * Vec3::new(
                    j0[3 * o] + j1[3 * o],
                    j0[3 * o + 1] + j1[3 * o + 1],
                    j0[3 * o + 2] - j1[3 * o + 2],
                ),
            )
        };
        let ((g_n, d_gn), (g_t, d_gt)) = match still {
            Some((y_n, d)) => cone(
                (y_n, Vec3::new(d[0], d[1], 0.0)),
                even(1),
                (self.depth, self.approach, self.slide),
                k,
            ),
            None => {
                let odd = (
                    0.5 * (y0[1] - y1[1]),
                    0.5 * Vec3::new(j0[3] - j1[3], j0[4] - j1[4], j0[5] + j1[5]),
                );
                coulomb(even(0), odd, k.mu)
            }
        };
        let (c_hat, t_hat, r, a) = (self.c_hat, self.t_hat, self.depth, self.approach);
        let p = Mat3::IDENTITY - outer(c_hat, c_hat);
        // Gradients of a function of (r, a, s): ∂r/∂c = ĉ; ∂a/∂c = ṫ/r,
        // ∂a/∂v = ĉ; ∂s/∂c = −a t̂/r, ∂s/∂v = t̂.
        let grad_c = |d: Vec3| d.x * c_hat + (d.y / r) * self.t_dot - (d.z * a / r) * t_hat;
        let grad_v = |d: Vec3| d.y * c_hat + d.z * t_hat;
        let n = -c_hat;
        // g_t ∂t̂ = (g_t / s)(I − t̂t̂ᵀ) ∂ṫ, with ∂ṫ/∂v = P and
        // ∂ṫ/∂c = −(a P + ĉ ṫᵀ) / r.
        let ratio = if t_hat == Vec3::ZERO {
            d_gt.z
        } else {
            g_t / self.slide
        };
        let turn = ratio * (Mat3::IDENTITY - outer(t_hat, t_hat));
        let dt_dc = -(a * p + outer(c_hat, self.t_dot)) / r;
        ForceJacobian {
            force: g_n * n + g_t * t_hat,
            d_c: outer(n, grad_c(d_gn)) - (g_n / r) * p + outer(t_hat, grad_c(d_gt)) + turn * dt_dc,
            d_v: outer(n, grad_v(d_gn)) + outer(t_hat, grad_v(d_gt)) + turn * p,
        }
    }
}

/// The world-frame network's (g_n, g_t), each with its gradient in
/// (depth, approach, slide), put inside the friction cone: g_n ≥ 0 (eq. 8
/// never pulls) and |g_t| ≤ μ g_n (eq. 9's Coulomb bound), with the clamped
/// value's own gradient. Its outputs are free scalars with absolute errors
/// of 0.1–1 N, against millinewton forces at resting contact; inside the
/// cone the network decides, at its edge Coulomb does. Mirrored in
/// `contact_net_force` (wgsl/contact.wgsl).
pub fn coulomb(normal: (f32, Vec3), tangent: (f32, Vec3), mu: f32) -> ((f32, Vec3), (f32, Vec3)) {
    if normal.0 <= 0.0 {
        return ((0.0, Vec3::ZERO), (0.0, Vec3::ZERO));
    }
    let cap = mu * normal.0;
    let tangent = if tangent.0 > cap {
        (cap, mu * normal.1)
    } else if tangent.0 < -cap {
        (-cap, -mu * normal.1)
    } else {
        tangent
    };
    (normal, tangent)
}

/// The log of the largest stick stiffness factor [`cone`] takes from the
/// network (e^20 ≈ 5·10⁸): a trained network stays far below it; it only
/// keeps e^w finite, so a slide of 0 never meets an infinite rate.
pub const STICK_LOG_MAX: f32 = 20.0;

/// ln(1 + e^y), written so it neither overflows nor differs from the
/// kernels' (wgsl/contact.wgsl has no log1p).
fn softplus(y: f32) -> f32 {
    y.max(0.0) + (1.0 + (-y.abs()).exp()).ln()
}

/// L = k_n r + k_d max(a, 0), the load eq. 8 gives a contact at depth r
/// approaching at a when nothing separates: the scale of [`cone`]'s g_n,
/// and what training divides the targets by.
pub fn cone_load(r: f32, a: f32, k: &Coefficients) -> f32 {
    k.kn * r + k.kd * a.max(0.0)
}

/// The contact-frame network's two outputs read in the form of eqs. 8–9's
/// friction cone (issue 65): the output's form, not a clamp, keeps the
/// force a push with friction against the slide and within Coulomb's
/// bound, and carries the law's scales, so the network learns only
/// dimensionless factors and its error shrinks with the load:
///   g_n = L softplus(y_n),  L = k_n r + k_d max(a, 0)     (eq. 8's load when nothing separates)
///   g_t = −min(k_t e^w s, μ g_n)                            (eq. 9, stick then slip)
/// with y_n the still row's first output and w the even part of the moving
/// rows' second (so ∂w/∂s = 0 at rest). The network learns how separating
/// lowers the load (softplus(y_n) = 1 + k_d a / (k_n r) there, 1 when
/// approaching) and the stick stiffness's factor on k_t (1 for eqs. 8–9).
/// g_n > 0 for every input, and g_t ≤ 0 ≤ s: friction never points along
/// the slide. Each output comes with its gradient in (depth r, approach a,
/// slide s); `normal` and `rate` are (y_n, ∂y_n) and (w, ∂w). Mirrored by
/// `cone` in wgsl/contact.wgsl.
pub fn cone(
    normal: (f32, Vec3),
    rate: (f32, Vec3),
    (r, a, s): (f32, f32, f32),
    k: &Coefficients,
) -> ((f32, Vec3), (f32, Vec3)) {
    let (y_n, d_yn) = normal;
    let load = cone_load(r, a, k);
    let d_load = Vec3::new(k.kn, if a > 0.0 { k.kd } else { 0.0 }, 0.0);
    let share = softplus(y_n);
    let g_n = load * share;
    let d_gn = share * d_load + (load / (1.0 + (-y_n).exp())) * d_yn;
    let (w, d_w) = if rate.0 > STICK_LOG_MAX {
        (STICK_LOG_MAX, Vec3::ZERO)
    } else {
        rate
    };
    let stick = k.kt * w.exp();
    let cap = k.mu * g_n;
    let friction = if stick * s <= cap {
        (-stick * s, -stick * (Vec3::Z + s * d_w))
    } else {
        (-cap, -k.mu * d_gn)
    };
    ((g_n, d_gn), friction)
}

/// g and its Jacobians from a friction network of `kind` (world or
/// contact frame), evaluated in the contact's frame ([`ContactFrame`]).
pub fn friction_net(net: &Mlp, kind: NetKind, c: Vec3, v: Vec3, k: &Coefficients) -> ForceJacobian {
    let Some(frame) = ContactFrame::new(c, v) else {
        return ForceJacobian::ZERO;
    };
    let (y, j) = net.forward_jacobian(&frame.inputs(kind, k), kind.wrt());
    frame.network_force(kind, &y, &j, k)
}

impl Model {
    /// The model of a run; `network` is the scene's (network models only).
    pub fn new(kind: ModelKind, c: &ContactConfig, network: Option<&Arc<Network>>) -> Model {
        let coefficients = c.coefficients();
        let loaded = || {
            network
                .expect("Scene::new loads the network of a network model")
                .clone()
        };
        match kind {
            ModelKind::Naive => Model::Naive {
                stiffness: c.naive_stiffness,
            },
            ModelKind::Friction => Model::Friction {
                scale: c.force_scale,
                coefficients,
            },
            ModelKind::FrictionNet => Model::FrictionNet {
                net: loaded(),
                scale: c.force_scale,
                coefficients,
            },
            ModelKind::NaiveNet => Model::NaiveNet {
                net: loaded(),
                stiffness: c.naive_stiffness,
            },
        }
    }

    /// Force on the penetrating point and its Jacobians, in force units, at
    /// collision vector c and relative velocity v_rel; `geometry` is asked
    /// for only by the models that read the triangle and point.
    pub fn evaluate(&self, c: Vec3, v_rel: Vec3, geometry: impl Fn() -> Geometry) -> ForceJacobian {
        self.evaluate_block(&[(c, v_rel)], |_| geometry())[0]
    }

    /// `evaluate` for a block of contacts, each as (c, v_rel); a network
    /// model runs its network over the whole block at once. `geometry`
    /// gives the triangle and point of the block's i-th contact.
    fn evaluate_block(
        &self,
        contacts: &[(Vec3, Vec3)],
        geometry: impl Fn(usize) -> Geometry,
    ) -> Vec<ForceJacobian> {
        match self {
            Model::Naive { stiffness } => contacts
                .iter()
                .map(|(c, _)| naive(*c, *stiffness))
                .collect(),
            Model::Friction {
                scale,
                coefficients,
            } => contacts
                .iter()
                .map(|(c, v)| friction(*c, *v, coefficients).scaled(*scale))
                .collect(),
            Model::FrictionNet {
                net,
                scale,
                coefficients,
            } => {
                let frames: Vec<Option<ContactFrame>> = contacts
                    .iter()
                    .map(|(c, v)| ContactFrame::new(*c, *v))
                    .collect();
                let (kind, mlp) = (net.kind, &net.mlp);
                let moving_rows = kind.moving_rows();
                let mut moving = Vec::with_capacity(frames.len() * moving_rows * mlp.inputs());
                let mut still = Vec::with_capacity(frames.len() * kind.still_rows() * mlp.inputs());
                for frame in frames.iter().flatten() {
                    frame.push_inputs(kind, coefficients, &mut moving, &mut still);
                }
                let (y, j) = mlp.forward_jacobian_batch(&moving, kind.wrt());
                // Only g_n is read at slide 0: one reverse pass, not one per
                // output.
                let (y0, j0) = mlp.forward_jacobian_rows(&still, kind.wrt(), 0..1);
                // Per contact: `moving_rows` rows of outputs and of
                // Jacobians, and (the contact-frame network) g_n's value and
                // gradient.
                let (outs, t) = (mlp.outputs(), kind.wrt().len());
                each_framed(&frames, |f, i| {
                    let g_n =
                        (kind.still_rows() > 0).then(|| (y0[outs * i], &j0[t * i..t * (i + 1)]));
                    let (y, j) = (
                        &y[moving_rows * outs * i..],
                        &j[moving_rows * outs * t * i..],
                    );
                    f.moving_force(kind, y, j, g_n, coefficients).scaled(*scale)
                })
            }
            Model::NaiveNet { net, stiffness } => {
                let frames: Vec<Option<LocalFrame>> = (0..contacts.len())
                    .map(|i| local_frame(&geometry(i)))
                    .collect();
                let inputs: Vec<f32> = frames.iter().flatten().flat_map(|f| f.inputs).collect();
                let (f, j) = net.mlp.forward_jacobian_batch(&inputs, net.kind.wrt());
                each_framed(&frames, |frame, i| {
                    naive_net_output(frame, &f[3 * i..], &j[9 * i..]).scaled(*stiffness)
                })
            }
        }
    }
}

/// `force(frame, i)` for each contact with a frame, i counting only those
/// (the network's rows); no force for a contact without one.
fn each_framed<F>(
    frames: &[Option<F>],
    force: impl Fn(&F, usize) -> ForceJacobian,
) -> Vec<ForceJacobian> {
    let mut next = 0;
    frames
        .iter()
        .map(|frame| match frame {
            None => ForceJacobian::ZERO,
            Some(frame) => {
                next += 1;
                force(frame, next - 1)
            }
        })
        .collect()
}

/// What one contact adds to the implicit system.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Response {
    /// Force on the penetrating point (cloth vertex k receives β_k f).
    pub force: Vec3,
    /// K_c, symmetric negative semidefinite.
    pub stiffness: Mat3,
    /// D_c, symmetric negative semidefinite.
    pub damping: Mat3,
}

/// The chain rule into the system, K_c = (∂f/∂c) n nᵀ and D_c = ∂f/∂v_rel,
/// made safe for PCG in three moves:
///
/// 1. Normal–tangential cross terms are dropped: each block keeps its
///    n-n part and its tangent-plane part. Sliding friction grows with the
///    normal load (a t̂ nᵀ term); symmetrised, that term would turn
///    tangential acceleration into a normal kick and make sliding cloth
///    bounce off the surface. K_c thus keeps min(0, nᵀ(∂f/∂c)n) n nᵀ.
/// 2. Coulomb friction has a constant magnitude while sliding, so its
///    Jacobian along the sliding direction t̂ is zero and a linearised step
///    would apply μF_c explicitly, reversing the sliding within the step
///    (a 0.2 g vertex under 3.5 N gains 175 m/s in 10 ms). D_c is floored
///    along t̂ at η = −(f·t̂)/|ṫ| − `inertia`: with `inertia` the mass the
///    contact moves over h, the least damping with which friction alone
///    brings the slide to rest at the step's end and not past it. A slide
///    carrying more momentum than the friction's impulse gets no floor and
///    keeps μF_c; the whole secant (`inertia` 0, lagged friction as in
///    IPC) scales it by |ṫ'|/|ṫ| and holds back a slide that speeds up.
///    In the stick branch the floor is already met.
/// 3. What remains is projected to the nearest symmetric NSD matrix.
pub fn response(fj: &ForceJacobian, normal: Vec3, v_rel: Vec3, inertia: f32) -> Response {
    let nn = outer(normal, normal);
    let tangent_plane = Mat3::IDENTITY - nn;
    let normal_stiffness = normal.dot(fj.d_c * normal).min(0.0);
    let mut damping =
        normal.dot(fj.d_v * normal) * nn + tangent_plane * symmetric_part(fj.d_v) * tangent_plane;
    let t_dot = tangent_plane * v_rel;
    let speed = t_dot.length();
    if speed > 0.0 {
        let t_hat = t_dot / speed;
        let floor = -fj.force.dot(t_hat) / speed - inertia;
        let deficit = floor + t_hat.dot(damping * t_hat);
        if deficit > 0.0 {
            damping -= deficit * outer(t_hat, t_hat);
        }
    }
    Response {
        force: fj.force,
        stiffness: normal_stiffness * nn,
        damping: project_nsd(damping),
    }
}

/// Evaluates the model for every contact at velocities `v`, in blocks of
/// the network's batch width (`nn::mlp::LANES`); `geometry` gives a
/// contact's triangle and point. Each contact's sliding friction keeps the
/// whole secant floor (`response`'s `inertia` 0): a cloth vertex's share
/// of its contacts with the body is not counted.
pub fn respond(
    model: &Model,
    contacts: &[Contact],
    v: &[Vec3],
    geometry: impl Fn(&Contact) -> Geometry + Sync,
    out: &mut Vec<Response>,
) {
    out.clear();
    out.resize(contacts.len(), Response::default());
    out.par_chunks_mut(LANES)
        .zip(contacts.par_chunks(LANES))
        .for_each(|(out, contacts)| {
            let block: Vec<(Vec3, Vec3)> = contacts
                .iter()
                .map(|c| (c.collision_vector(), c.relative_velocity(v)))
                .collect();
            let forces = model.evaluate_block(&block, |i| geometry(&contacts[i]));
            for (((r, c), fj), (_, v_rel)) in out.iter_mut().zip(contacts).zip(&forces).zip(&block)
            {
                *r = response(fj, c.normal, *v_rel, 0.0);
            }
        });
}
