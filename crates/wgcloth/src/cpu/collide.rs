//! Stage "collide": contact detection in both directions (thesis 2.2–2.3).
//! Mirrors wgsl/collide.wgsl, which finds the same contacts by other broad
//! phases.
//!
//! (a) vertex–face: each cloth vertex x against the rigid triangles its
//!     body-space cell lists ([`BodyGrid`]; the GPU walks the body's BVH).
//! (b) face–vertex: each rigid vertex p against the cloth triangles near it
//!     in the cloth's BVH, refitted every step (the GPU walks tiles).
//! The proximity test is the same: the projection onto the triangle's plane
//! falls inside it and the signed distance d = (x − a)·n lies in
//! (−max_depth, ε); of several candidates the one with the smallest
//! |d̃| = ε − d wins (ties: the lower triangle index, so the result does not
//! depend on traversal order).

use glam::Vec3;
use rayon::prelude::*;

use crate::bvh::{Aabb, Bvh};
use crate::cpu::body_grid::BodyGrid;
use crate::cpu::rigid::RigidFrame;
use crate::math::{Barycentric, barycentric, inside_triangle};
use crate::parallel::GRAIN;
use crate::scene::{Cloth, RigidBody};

/// One contact, in the form every model and the assembly share.
///
/// The cloth vertices carry coefficients β such that
/// - the force on cloth vertex k is β_k f, where f acts on the penetrating point;
/// - the penetration depth moves as ∂d̃/∂x_k = β_k nᵀ;
/// - the relative velocity is v_rel = Σ β_k v_k + u.
///
/// (a) one vertex i, β = 1, u = −(rigid surface velocity);
/// (b) a cloth triangle, β = −w (its barycentric weights), u = the rigid
///     vertex's velocity. Then blocks enter the system as β_k β_l K_c, which
///     is the thesis's w_k w_l K_c.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// The cloth vertices the contact acts on: (a) vertex i, repeated;
    /// (b) the cloth triangle's three. The first
    /// [`vertex_count`](Contact::vertex_count) are used.
    pub vertices: [u32; 3],
    /// β_k of each of `vertices` ((a): [1, 0, 0]; (b): −w).
    pub beta: [f32; 3],
    /// The cloth triangle of a face–vertex contact.
    pub cloth_triangle: Option<u32>,
    /// Rigid triangle (vertex–face) or rigid vertex (face–vertex).
    pub rigid_feature: u32,
    /// Unit normal of the surface, pointing to the side the penetrating
    /// point should be pushed towards.
    pub normal: Vec3,
    /// Signed distance d of the penetrating point above the surface.
    pub distance: f32,
    /// d̃ = d − ε < 0.
    pub depth: f32,
    /// u, the part of v_rel not due to the cloth's velocities (m/s).
    pub velocity_offset: Vec3,
}

/// A contact as the naive network of thesis 2.4 sees it: the surface
/// triangle, wound so its normal is the contact normal, and the penetrating
/// point, moved by the thickness ε against the normal so that its height
/// above the triangle's plane is d̃ = d − ε.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    /// The surface triangle's corners (a, b, c), world space, wound so
    /// (b − a) × (c − a) points along the contact normal.
    pub triangle: [Vec3; 3],
    /// The penetrating point, moved by ε against the normal, world space.
    pub point: Vec3,
}

impl Contact {
    /// The thesis's collision vector c = n d̃ (network input).
    pub fn collision_vector(&self) -> Vec3 {
        self.normal * self.depth
    }

    /// The contact's triangle and point at cloth positions `x` and the
    /// rigid body placed by `frame`.
    pub fn geometry(
        &self,
        cloth: &Cloth,
        body: &RigidBody,
        frame: &RigidFrame,
        x: &[Vec3],
    ) -> Geometry {
        let rigid = |i: u32| frame.vertices[i as usize];
        let ([a, b, c], point) = match self.cloth_triangle {
            None => (
                body.mesh.triangles[self.rigid_feature as usize].map(rigid),
                x[self.vertices[0] as usize],
            ),
            Some(t) => (
                cloth.triangles[t as usize].map(|i| x[i as usize]),
                rigid(self.rigid_feature),
            ),
        };
        let triangle = match (b - a).cross(c - a).dot(self.normal) < 0.0 {
            true => [a, c, b],
            false => [a, b, c],
        };
        Geometry {
            triangle,
            point: point - (self.distance - self.depth) * self.normal,
        }
    }

    /// How many of `vertices` and `beta` the contact uses: 1 for
    /// vertex–face, 3 for face–vertex.
    pub fn vertex_count(&self) -> usize {
        if self.cloth_triangle.is_some() { 3 } else { 1 }
    }

    /// v_rel = Σ β_k v_k + u at cloth velocities `v`.
    pub fn relative_velocity(&self, v: &[Vec3]) -> Vec3 {
        (0..self.vertex_count()).fold(self.velocity_offset, |acc, k| {
            acc + self.beta[k] * v[self.vertices[k] as usize]
        })
    }
}

/// The bounds of the proximity test, from the contact configuration.
#[derive(Clone, Copy, Debug)]
pub struct Tolerances {
    /// ε, m: contact starts when d < ε.
    pub thickness: f32,
    /// How far below a surface, m, a point is still in contact: d > −max_depth.
    pub max_depth: f32,
}

impl Tolerances {
    /// How far from a triangle's box a point can be and still be a candidate.
    pub fn reach(&self) -> f32 {
        self.thickness.max(self.max_depth)
    }

    /// Whether signed distance `d` lies in the contact band (−max_depth, ε).
    #[inline]
    pub fn in_band(&self, d: f32) -> bool {
        d > -self.max_depth && d < self.thickness
    }
}

/// The narrow-phase test: `Some((d, barycentrics))` when `p` is in contact
/// with triangle (a, b, c) of unit normal n.
#[inline]
pub fn point_triangle(p: Vec3, tri: [Vec3; 3], n: Vec3, tol: Tolerances) -> Option<(f32, Vec3)> {
    let d = (p - tri[0]).dot(n);
    if !tol.in_band(d) {
        return None;
    }
    let w = barycentric(p, tri[0], tri[1], tri[2])?;
    inside_triangle(w).then_some((d, w))
}

/// A triangle that does not move (the rigid body's, in body space) as the
/// narrow phase weighs points against it: what [`point_triangle`] computes
/// from its corners alone, made once.
#[derive(Clone, Copy, Debug)]
pub struct Face {
    /// Its barycentric frame.
    pub frame: Barycentric,
    /// Its unit normal.
    pub normal: Vec3,
}

impl Face {
    /// [`point_triangle`] of `p` against this face, the same to the bit.
    #[inline]
    pub fn touch(&self, p: Vec3, tol: Tolerances) -> Option<(f32, Vec3)> {
        let d = (p - self.frame.a).dot(self.normal);
        if !tol.in_band(d) {
            return None;
        }
        let w = self.frame.weights(p);
        inside_triangle(w).then_some((d, w))
    }
}

/// The candidate that wins (larger d, then lower index).
#[derive(Clone, Copy, Debug)]
pub struct Best {
    /// Index of the triangle (rigid or cloth, whichever the query searched).
    pub triangle: u32,
    /// Signed distance d of the point above the triangle's plane, m.
    pub distance: f32,
    /// Barycentric weights of the point's projection onto the triangle.
    pub weights: Vec3,
    /// The triangle's unit normal (in the space the query ran in).
    pub normal: Vec3,
}

impl Best {
    /// Runs the narrow phase of `p` against triangle `t` (unit normal `n`)
    /// and keeps it in `best` if it wins.
    pub fn consider(
        best: &mut Option<Best>,
        t: u32,
        p: Vec3,
        tri: [Vec3; 3],
        n: Vec3,
        tol: Tolerances,
    ) {
        if let Some((distance, weights)) = point_triangle(p, tri, n, tol) {
            Best::keep(
                best,
                Best {
                    triangle: t,
                    distance,
                    weights,
                    normal: n,
                },
            );
        }
    }

    /// Stores `cand` in `best` if it wins over what `best` holds.
    pub fn keep(best: &mut Option<Best>, cand: Best) {
        let better = match best {
            None => true,
            Some(b) => {
                cand.distance > b.distance
                    || (cand.distance == b.distance && cand.triangle < b.triangle)
            }
        };
        if better {
            *best = Some(cand);
        }
    }
}

/// The rigid triangle closest to cloth vertex `x`, of those `grid` lists
/// near it in body space.
pub fn best_rigid_triangle(
    grid: &BodyGrid,
    frame: &RigidFrame,
    x: Vec3,
    tol: Tolerances,
) -> Option<Best> {
    let p = frame.to_body(x);
    let mut best = None;
    for &t in grid.candidates(p) {
        let Some(face) = grid.face(t) else { continue };
        if let Some((distance, weights)) = face.touch(p, tol) {
            let normal = face.normal;
            Best::keep(
                &mut best,
                Best {
                    triangle: t,
                    distance,
                    weights,
                    normal,
                },
            );
        }
    }
    best
}

/// The unit normal of cloth triangle t turned to face away from the rigid
/// vertex's outward normal: the cloth is two-sided, and a rigid vertex
/// pushes it along its own outward direction.
pub fn cloth_normal(cloth: &Cloth, x: &[Vec3], t: u32, rigid_normal: Vec3) -> Vec3 {
    let [a, b, c] = cloth.triangles[t as usize].map(|i| x[i as usize]);
    let n = (b - a).cross(c - a).normalize_or_zero();
    if n.dot(rigid_normal) > 0.0 { -n } else { n }
}

/// The cloth triangle closest to rigid vertex `p` (cloth BVH query).
pub fn best_cloth_triangle(
    cloth: &Cloth,
    cloth_bvh: &Bvh,
    x: &[Vec3],
    p: Vec3,
    rigid_normal: Vec3,
    tol: Tolerances,
) -> Option<Best> {
    let mut best = None;
    cloth_bvh.query(p, tol.reach(), |t| {
        let tri = cloth.triangles[t as usize].map(|i| x[i as usize]);
        let n = cloth_normal(cloth, x, t, rigid_normal);
        if n != Vec3::ZERO {
            Best::consider(&mut best, t, p, tri, n, tol);
        }
    });
    best
}

/// (a) vertex–face contacts, one per cloth vertex at most, in vertex order.
/// `grid` is the body's, built for a reach of at least `tol`'s.
pub fn vertex_face(
    grid: &BodyGrid,
    frame: &RigidFrame,
    x: &[Vec3],
    tol: Tolerances,
) -> Vec<Contact> {
    assert!(
        grid.reach() >= tol.reach(),
        "a body grid for reach {} queried within {}",
        grid.reach(),
        tol.reach()
    );
    x.par_iter()
        .with_min_len(GRAIN / 8)
        .enumerate()
        .filter_map(|(i, &xi)| {
            let b = best_rigid_triangle(grid, frame, xi, tol)?;
            let i = i as u32;
            Some(Contact {
                vertices: [i, i, i],
                beta: [1.0, 0.0, 0.0],
                cloth_triangle: None,
                rigid_feature: b.triangle,
                normal: frame.rotation * b.normal,
                distance: b.distance,
                depth: b.distance - tol.thickness,
                velocity_offset: -frame.velocity,
            })
        })
        .collect()
}

/// (b) face–vertex contacts, one per rigid vertex at most, in vertex order.
pub fn face_vertex(
    cloth: &Cloth,
    cloth_bvh: &Bvh,
    x: &[Vec3],
    frame: &RigidFrame,
    tol: Tolerances,
) -> Vec<Contact> {
    frame
        .vertices
        .par_iter()
        .with_min_len(GRAIN / 8)
        .zip(&frame.vertex_normals)
        .enumerate()
        .filter_map(|(k, (&p, &np))| {
            let b = best_cloth_triangle(cloth, cloth_bvh, x, p, np, tol)?;
            let tri = cloth.triangles[b.triangle as usize];
            Some(Contact {
                vertices: tri,
                beta: (-b.weights).to_array(),
                cloth_triangle: Some(b.triangle),
                rigid_feature: k as u32,
                normal: b.normal,
                distance: b.distance,
                depth: b.distance - tol.thickness,
                velocity_offset: frame.velocity,
            })
        })
        .collect()
}

/// Broad phase for (b): the cloth hierarchy refitted to positions `x`.
pub fn refit_cloth(cloth: &Cloth, bvh: &mut Bvh, x: &[Vec3]) {
    bvh.refit(|t| Aabb::of_points(&cloth.triangles[t as usize].map(|i| x[i as usize])));
}
