//! Small 3-D helpers shared by every stage: outer products, barycentric
//! coordinates, and the projection that keeps contact blocks symmetric
//! negative semidefinite so the implicit system stays SPD (DESIGN "physics").

use std::ops::{Add, AddAssign, Mul};

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Vec3, Vec3A};

/// A symmetric 3 × 3 block as six floats, xx, yy, zz, xy, xz, yz: every
/// block of the implicit system on both paths (the GPU's buffers hold it as
/// `PackedSym3`, wgsl/common.wgsl), two thirds of a `Mat3`'s bytes. Its
/// arithmetic does what `Mat3`'s does to the same entries, so a product
/// with a vector rounds as the full matrix's does.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Sym3(pub [f32; 6]);

impl Sym3 {
    /// The zero block.
    pub const ZERO: Sym3 = Sym3([0.0; 6]);

    /// diag(d).
    pub fn from_diagonal(d: Vec3) -> Sym3 {
        Sym3([d.x, d.y, d.z, 0.0, 0.0, 0.0])
    }

    /// a aᵀ, the products of `outer(a, a)`.
    pub fn outer(a: Vec3) -> Sym3 {
        Sym3([
            a.x * a.x,
            a.y * a.y,
            a.z * a.z,
            a.x * a.y,
            a.x * a.z,
            a.y * a.z,
        ])
    }

    /// The symmetric part (M + Mᵀ) / 2 of `m`, which is `m` to the bit where
    /// `m` is symmetric.
    pub fn from_mat3(m: Mat3) -> Sym3 {
        let s = symmetric_part(m);
        Sym3([
            s.x_axis.x, s.y_axis.y, s.z_axis.z, s.y_axis.x, s.z_axis.x, s.z_axis.y,
        ])
    }

    /// Its columns (which are its rows).
    #[inline(always)]
    pub fn columns(self) -> [Vec3; 3] {
        let [xx, yy, zz, xy, xz, yz] = self.0;
        [
            Vec3::new(xx, xy, xz),
            Vec3::new(xy, yy, yz),
            Vec3::new(xz, yz, zz),
        ]
    }

    /// (xx, yy, zz).
    pub fn diagonal(self) -> Vec3 {
        Vec3::new(self.0[0], self.0[1], self.0[2])
    }

    /// The full matrix.
    pub fn to_mat3(self) -> Mat3 {
        let [x, y, z] = self.columns();
        Mat3::from_cols(x, y, z)
    }

    /// Whether every entry is finite.
    pub fn is_finite(self) -> bool {
        self.0.iter().all(|e| e.is_finite())
    }
}

impl Mul<Vec3> for Sym3 {
    type Output = Vec3;
    /// Column by column, as `Mat3 * Vec3`.
    #[inline(always)]
    fn mul(self, v: Vec3) -> Vec3 {
        let [x, y, z] = self.columns();
        x * v.x + y * v.y + z * v.z
    }
}

impl Mul<Sym3> for f32 {
    type Output = Sym3;
    #[inline(always)]
    fn mul(self, m: Sym3) -> Sym3 {
        let [a, b, c, d, e, f] = m.0;
        Sym3([self * a, self * b, self * c, self * d, self * e, self * f])
    }
}

impl Add for Sym3 {
    type Output = Sym3;
    #[inline(always)]
    fn add(self, o: Sym3) -> Sym3 {
        let ([a, b, c, d, e, f], [p, q, r, s, t, u]) = (self.0, o.0);
        Sym3([a + p, b + q, c + r, d + s, e + t, f + u])
    }
}

impl AddAssign for Sym3 {
    #[inline(always)]
    fn add_assign(&mut self, o: Sym3) {
        *self = *self + o;
    }
}

/// Σ_k A_k x_k, a block row times a vector, with each column's products
/// summed apart: one dependent add per block in each of three chains,
/// where `acc += A_k * x_k` makes three in one (5–10 % off the CPU's
/// multigrid iteration at 1024²). The V-cycle's rows use
/// it. CG's own product keeps one chain: there it gained nothing, and its
/// rounding moved Jacobi's iterations to 1e-4 past the GPU parity test's
/// bound.
#[derive(Clone, Copy, Default)]
pub struct RowSum {
    x: Vec3A,
    y: Vec3A,
    z: Vec3A,
}

impl RowSum {
    /// Adds `block` × `v`.
    #[inline(always)]
    pub fn add(&mut self, block: Sym3, v: Vec3) {
        let [x, y, z] = block.columns();
        self.x += Vec3A::from(x) * v.x;
        self.y += Vec3A::from(y) * v.y;
        self.z += Vec3A::from(z) * v.z;
    }

    /// The sum.
    #[inline(always)]
    pub fn total(self) -> Vec3 {
        (self.x + self.y + self.z).into()
    }
}

/// a bᵀ.
pub fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// (M + Mᵀ) / 2.
pub fn symmetric_part(m: Mat3) -> Mat3 {
    (m + m.transpose()) * 0.5
}

/// Barycentric coordinates (u, v, w) of the projection of `p` onto the plane
/// of triangle (a, b, c), so that proj = u a + v b + w c. `None` for a
/// degenerate triangle.
#[inline]
pub fn barycentric(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<Vec3> {
    Some(Barycentric::new(a, b, c)?.weights(p))
}

/// What [`barycentric`] computes from a triangle's corners alone, kept to
/// weigh many points against one triangle: the same operations in the same
/// order, so the weights are the same to the bit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Barycentric {
    /// Corner a.
    pub a: Vec3,
    e0: Vec3,
    e1: Vec3,
    d00: f32,
    d01: f32,
    d11: f32,
    denom: f32,
}

impl Barycentric {
    /// Triangle (a, b, c)'s; `None` when it is degenerate.
    #[inline]
    pub fn new(a: Vec3, b: Vec3, c: Vec3) -> Option<Barycentric> {
        let e0 = b - a;
        let e1 = c - a;
        let d00 = e0.dot(e0);
        let d01 = e0.dot(e1);
        let d11 = e1.dot(e1);
        let denom = d00 * d11 - d01 * d01;
        (denom > f32::EPSILON * d00 * d11).then_some(Barycentric {
            a,
            e0,
            e1,
            d00,
            d01,
            d11,
            denom,
        })
    }

    /// The barycentric coordinates of `p`'s projection (see [`barycentric`]).
    #[inline]
    pub fn weights(&self, p: Vec3) -> Vec3 {
        let ep = p - self.a;
        let d20 = ep.dot(self.e0);
        let d21 = ep.dot(self.e1);
        let v = (self.d11 * d20 - self.d01 * d21) / self.denom;
        let w = (self.d00 * d21 - self.d01 * d20) / self.denom;
        Vec3::new(1.0 - v - w, v, w)
    }
}

/// True when all barycentric coordinates lie in [0, 1] (thesis 2.3).
pub fn inside_triangle(bary: Vec3) -> bool {
    bary.min_element() >= 0.0 && bary.max_element() <= 1.0
}

/// The point of triangle (a, b, c) nearest to `p`, by the Voronoi region
/// `p` lies in (Ericson, Real-Time Collision Detection, 5.1.5). Mirrored by
/// `closest_on_triangle` in wgsl/common.wgsl.
pub fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac) = (b - a, c - a);
    let (d1, d2) = (ab.dot(p - a), ac.dot(p - a));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let (d3, d4) = (ab.dot(p - b), ac.dot(p - b));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let (d5, d6) = (ab.dot(p - c), ac.dot(p - c));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let inv = 1.0 / (va + vb + vc);
    a + ab * (vb * inv) + ac * (vc * inv)
}

/// The closest points of segments (p1, q1) and (p2, q2), one on each
/// (Ericson, Real-Time Collision Detection, 5.1.9); a degenerate segment is
/// its point.
pub fn closest_between_segments(p1: Vec3, q1: Vec3, p2: Vec3, q2: Vec3) -> (Vec3, Vec3) {
    let (s, t) = segment_parameters(p1, q1, p2, q2);
    (p1 + (q1 - p1) * s, p2 + (q2 - p2) * t)
}

/// The parameters (s, t) in [0, 1] of the closest points p1 + s (q1 − p1)
/// and p2 + t (q2 − p2) of two segments. Mirrored by
/// `segment_parameters` in wgsl/common.wgsl.
pub fn segment_parameters(p1: Vec3, q1: Vec3, p2: Vec3, q2: Vec3) -> (f32, f32) {
    let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
    let (a, e, f) = (d1.dot(d1), d2.dot(d2), d2.dot(r));
    let tiny = f32::EPSILON * (a + e).max(f32::MIN_POSITIVE);
    if a <= tiny && e <= tiny {
        (0.0, 0.0)
    } else if a <= tiny {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(r);
        if e <= tiny {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s = if denom > tiny * a.max(e) {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    }
}

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations:
/// returns the eigenvalues and the matrix whose columns are the eigenvectors.
/// Jacobi is branch-light and fixed-cost, which is why the GPU twin uses it too.
pub fn symmetric_eigen(m: Mat3) -> (Vec3, Mat3) {
    let mut a = m.to_cols_array_2d(); // a[col][row]; symmetric, so either reads.
    let mut v = [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _sweep in 0..8 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if off <= 1e-14 * diag || off == 0.0 {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = a[p][q];
            if apq == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // A ← Jᵀ A J: first columns p, q, then rows p, q.
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in &mut v {
                let vp = row[p];
                let vq = row[q];
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let values = Vec3::new(a[0][0], a[1][1], a[2][2]);
    // v[row][col] holds eigenvector `col` in its column.
    let vectors = Mat3::from_cols(
        Vec3::new(v[0][0], v[1][0], v[2][0]),
        Vec3::new(v[0][1], v[1][1], v[2][1]),
        Vec3::new(v[0][2], v[1][2], v[2][2]),
    );
    (values, vectors)
}

/// Whether symmetric `m` is negative semidefinite: every principal minor of
/// −m is nonnegative (for semidefiniteness the leading ones alone do not
/// suffice).
pub fn is_nsd(m: Mat3) -> bool {
    let n = -m;
    let (a, b, c) = (n.x_axis.x, n.y_axis.y, n.z_axis.z);
    let (ab, ac, bc) = (n.y_axis.x, n.z_axis.x, n.z_axis.y);
    a >= 0.0
        && b >= 0.0
        && c >= 0.0
        && a * b >= ab * ab
        && a * c >= ac * ac
        && b * c >= bc * bc
        && n.determinant() >= 0.0
}

/// The nearest symmetric negative semidefinite matrix (Frobenius norm):
/// symmetric part, then positive eigenvalues clamped to zero. Every contact
/// block passes through here before it enters K or D.
pub fn project_nsd(m: Mat3) -> Mat3 {
    let m = symmetric_part(m);
    // Nearly every contact's damping block is NSD already (all but 70 of
    // 107,786 in 66 steps of the sphere scene at 128²): it is its own
    // projection, without the eigen-decomposition.
    if is_nsd(m) {
        return m;
    }
    let (values, q) = symmetric_eigen(m);
    let clamped = values.min(Vec3::ZERO);
    // Exactly symmetric, not just to rounding: one block serves both
    // (i, j) and (j, i) of the system matrix.
    symmetric_part(q * Mat3::from_diagonal(clamped) * q.transpose())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sym(seed: u32) -> Mat3 {
        // A deterministic, irregular symmetric matrix.
        let f = |k: u32| ((seed * 7919 + k * 104_729) % 2003) as f32 / 1001.0 - 1.0;
        let m = Mat3::from_cols(
            Vec3::new(f(1), f(2), f(3)),
            Vec3::new(f(4), f(5), f(6)),
            Vec3::new(f(7), f(8), f(9)),
        );
        symmetric_part(m)
    }

    #[test]
    fn closest_points_of_segments_are_no_farther_than_any_sampled_pair() {
        for seed in 0..200u32 {
            let f = |k: u32| ((seed * 7919 + k * 104_729) % 2003) as f32 / 1001.0 - 1.0;
            let v = |k: u32| Vec3::new(f(k), f(k + 1), f(k + 2));
            // Every tenth pair parallel, every seventh a point.
            let (p1, mut q1, p2) = (v(1), v(4), v(7));
            let q2 = if seed % 10 == 0 {
                p2 + (q1 - p1) * 0.7
            } else {
                v(10)
            };
            if seed % 7 == 0 {
                q1 = p1;
            }
            let (c1, c2) = closest_between_segments(p1, q1, p2, q2);
            let on = |c: Vec3, p: Vec3, q: Vec3| {
                let t = (c - p).dot(q - p) / (q - p).length_squared().max(1e-30);
                (p + (q - p) * t.clamp(0.0, 1.0) - c).length() < 1e-5
            };
            assert!(on(c1, p1, q1) && on(c2, p2, q2), "seed {seed}");
            let best = (c1 - c2).length();
            for i in 0..=40 {
                for j in 0..=40 {
                    let (s, t) = (i as f32 / 40.0, j as f32 / 40.0);
                    let d = (p1 + (q1 - p1) * s - p2 - (q2 - p2) * t).length();
                    assert!(best <= d + 1e-5, "seed {seed}: {best} > {d}");
                }
            }
        }
    }

    #[test]
    fn eigen_reconstructs_and_is_orthonormal() {
        for seed in 0..200 {
            let m = sym(seed);
            let (l, q) = symmetric_eigen(m);
            let back = q * Mat3::from_diagonal(l) * q.transpose();
            assert!((back - m).abs().to_cols_array().iter().all(|e| *e < 1e-5));
            let qtq = q.transpose() * q - Mat3::IDENTITY;
            assert!(qtq.abs().to_cols_array().iter().all(|e| *e < 1e-5));
        }
    }

    #[test]
    fn nsd_projection_is_nsd_and_idempotent() {
        for seed in 0..200 {
            let p = project_nsd(sym(seed));
            let (l, _) = symmetric_eigen(p);
            assert!(l.max_element() < 1e-5, "{l:?}");
            let pp = project_nsd(p);
            assert!((pp - p).abs().to_cols_array().iter().all(|e| *e < 1e-5));
        }
        // An already-NSD matrix is unchanged.
        let n = Vec3::new(0.3, -0.4, 0.5).normalize();
        let k = outer(n, n) * -7.0;
        assert!(
            (project_nsd(k) - k)
                .abs()
                .to_cols_array()
                .iter()
                .all(|e| *e < 1e-5)
        );
    }

    #[test]
    fn nsd_test_agrees_with_the_eigenvalues() {
        let (mut nsd, mut not) = (0, 0);
        for seed in 0..400 {
            // Shifted so that both kinds are common.
            let m = sym(seed) - Mat3::IDENTITY * (seed % 4) as f32 * 0.5;
            let (l, _) = symmetric_eigen(m);
            let top = l.max_element();
            if top.abs() < 1e-4 {
                continue; // too close to call in f32
            }
            assert_eq!(is_nsd(m), top < 0.0, "seed {seed}: eigenvalues {l:?}");
            if top < 0.0 { nsd += 1 } else { not += 1 }
        }
        assert!(nsd > 50 && not > 50, "{nsd} NSD, {not} not");
    }

    #[test]
    fn barycentric_inside_and_outside() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let w = barycentric(Vec3::new(0.25, 0.25, 3.0), a, b, c).unwrap();
        assert!((w - Vec3::new(0.5, 0.25, 0.25)).length() < 1e-6);
        assert!(inside_triangle(w));
        let w = barycentric(Vec3::new(1.0, 1.0, 0.0), a, b, c).unwrap();
        assert!(!inside_triangle(w));
        assert!(barycentric(Vec3::ZERO, a, a, a).is_none());
    }
}
