//! The CPU's broad phase for vertex–face contacts (stage collide (a)): a
//! uniform grid over the rigid body's space, built once, each cell listing
//! the triangles a point in it can touch.
//!
//! A point p touches triangle t only inside t's prism: p = q + d n with q
//! in the triangle and |d| < reach (thesis 2.3's proximity test). A cell
//! lists t when its box meets the prism's bounding box and the slab
//! |n·(p − a)| ≤ reach around t's plane; a point's candidates are then its
//! cell's list, one lookup, where the body's BVH (which the GPU walks,
//! wgsl/collide.wgsl) costs a walk of some thirty nodes per cloth vertex
//! near the body and tests every triangle of each leaf it reaches. The
//! narrow phase decides and ties go to the lower triangle, so both find
//! the same contacts.

use glam::{IVec3, UVec3, Vec3};

use crate::bvh::Aabb;
use crate::cpu::collide::Face;
use crate::math::Barycentric;
use crate::scene::RigidBody;

/// The most cells a grid may have: 8 MiB of offsets. A body whose
/// prisms would need more gets larger cells, and longer lists.
const MAX_CELLS: u64 = 1 << 21;

/// Cells per reach: quarter-reach cells keep a sphere's lists near four
/// triangles; half-reach ones listed six and were slower, eighth-reach ones
/// three and were no faster.
const CELLS_PER_REACH: f32 = 4.0;

/// Each prism and slab is widened by this share of a cell, so that no
/// rounding of the narrow phase can find a contact the grid did not list.
const MARGIN: f32 = 1.0 / 1024.0;

/// See the module docs.
#[derive(Clone, Debug)]
pub struct BodyGrid {
    /// Body-space corner of cell (0, 0, 0).
    origin: Vec3,
    /// 1 / the cell's side, 1/m.
    inverse_cell: f32,
    /// Cells along x, y and z.
    dims: [u32; 3],
    /// Cell c's triangles are `triangles[offsets[c]..offsets[c + 1]]`.
    offsets: Vec<u32>,
    triangles: Vec<u32>,
    /// Each triangle as the narrow phase reads it; `None` for a degenerate
    /// one, which no point touches and no cell lists.
    faces: Vec<Option<Face>>,
    /// The reach the lists hold for.
    reach: f32,
}

impl BodyGrid {
    /// The grid of `body`'s triangles for points within `reach` of a face.
    pub fn new(body: &RigidBody, reach: f32) -> BodyGrid {
        let corners = |t: &[u32; 3]| t.map(|i| body.mesh.vertices[i as usize]);
        let faces: Vec<Option<Face>> = (body.mesh.triangles.iter().zip(&body.face_normals))
            .map(|(t, &normal)| {
                let [a, b, c] = corners(t);
                Some(Face {
                    frame: Barycentric::new(a, b, c)?,
                    normal,
                })
            })
            .collect();
        let prisms: Vec<Aabb> = (body.mesh.triangles.iter().zip(&body.face_normals))
            .map(|(t, &n)| {
                let r = n * reach;
                Aabb::of_points(&corners(t).map(|c| [c - r, c + r]).concat())
            })
            .collect();
        let finite = |b: &Aabb| b.min.is_finite() && b.max.is_finite();
        let bounds = prisms
            .iter()
            .filter(|b| finite(b))
            .fold(Aabb::EMPTY, |a, b| a.union(*b));
        if bounds == Aabb::EMPTY {
            return BodyGrid {
                origin: Vec3::ZERO,
                inverse_cell: 0.0,
                dims: [0; 3],
                offsets: vec![0],
                triangles: Vec::new(),
                faces,
                reach,
            };
        }
        let extent = bounds.max - bounds.min;
        // Cells of side `side` over the bounds widened by the margin.
        let count = |side: f32| {
            ((extent + 2.0 * MARGIN * side) / side)
                .ceil()
                .max(Vec3::ONE)
                .as_uvec3()
        };
        let cells = |side: f32| count(side).as_u64vec3().element_product();
        let mut side = (reach / CELLS_PER_REACH)
            .max(extent.max_element() * 1e-6)
            .max(1e-9);
        if cells(side) > MAX_CELLS {
            side *= (cells(side) as f32 / MAX_CELLS as f32).cbrt();
            while cells(side) > MAX_CELLS {
                side *= 1.01;
            }
        }
        let dims = count(side).to_array();
        let margin = side * MARGIN;
        let origin = bounds.min - margin;
        let last = count(side).as_ivec3() - 1;
        let cell_of = |p: Vec3| {
            ((p - origin) / side)
                .floor()
                .as_ivec3()
                .clamp(IVec3::ZERO, last)
        };
        // Each triangle's cells, in x-fastest order; `visit(cell)` for
        // each one the triangle's prism and slab meet.
        let covered = |t: usize, visit: &mut dyn FnMut(usize)| {
            let prism = prisms[t].grown(margin);
            let Some(Face { frame, normal: n }) = faces[t] else {
                return;
            };
            if !finite(&prism) {
                return;
            }
            let a = frame.a;
            // The slab |n·(p − a)| ≤ reach meets a cell of centre c when
            // |n·(c − a)| ≤ reach + the cell's half-extent along n.
            let half = 0.5 * side;
            let slab = reach + half * n.abs().element_sum() + margin;
            let (lo, hi) = (cell_of(prism.min), cell_of(prism.max));
            for z in lo.z..=hi.z {
                for y in lo.y..=hi.y {
                    for x in lo.x..=hi.x {
                        let c = IVec3::new(x, y, z);
                        let centre = origin + (c.as_vec3() + 0.5) * side;
                        if n.dot(centre - a).abs() <= slab {
                            let [x, y, z] = c.as_uvec3().to_array().map(|v| v as usize);
                            visit(x + dims[0] as usize * (y + dims[1] as usize * z));
                        }
                    }
                }
            }
        };
        // Counted, then filled (compressed rows).
        let total = dims.iter().map(|&d| d as usize).product::<usize>();
        let mut offsets = vec![0u32; total + 1];
        for t in 0..prisms.len() {
            covered(t, &mut |c| offsets[c + 1] += 1);
        }
        for c in 0..total {
            offsets[c + 1] += offsets[c];
        }
        let mut next = offsets[..total].to_vec();
        let mut triangles = vec![0u32; offsets[total] as usize];
        for t in 0..prisms.len() {
            covered(t, &mut |c| {
                triangles[next[c] as usize] = t as u32;
                next[c] += 1;
            });
        }
        BodyGrid {
            origin,
            inverse_cell: 1.0 / side,
            dims,
            offsets,
            triangles,
            faces,
            reach,
        }
    }

    /// Triangle t as the narrow phase reads it; `None` when it is
    /// degenerate (no cell lists it).
    #[inline]
    pub fn face(&self, t: u32) -> Option<&Face> {
        self.faces[t as usize].as_ref()
    }

    /// The reach the lists were built for: a query within a larger one
    /// could miss a triangle.
    pub fn reach(&self) -> f32 {
        self.reach
    }

    /// Every triangle body-space point `p` can touch within the reach, in
    /// increasing order (others may be among them); none outside the grid.
    #[inline]
    pub fn candidates(&self, p: Vec3) -> &[u32] {
        let c = (p - self.origin) * self.inverse_cell;
        let dims = UVec3::from_array(self.dims).as_vec3();
        // Written so that NaN falls outside. Inside, truncation is the
        // floor, without the library call x86-64's baseline makes of it.
        if !(c.cmpge(Vec3::ZERO).all() && c.cmplt(dims).all()) {
            return &[];
        }
        let [x, y, z] = c.as_uvec3().to_array().map(|v| v as usize);
        let cell = x + self.dims[0] as usize * (y + self.dims[1] as usize * z);
        &self.triangles[self.offsets[cell] as usize..self.offsets[cell + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use glam::Quat;

    use super::*;
    use crate::cpu::collide::{Tolerances, point_triangle};
    use crate::scene::{Motion, TriMesh};

    /// Every triangle a point touches, by testing them all.
    fn touched(body: &RigidBody, p: Vec3, tol: Tolerances) -> Vec<u32> {
        (0..body.mesh.triangles.len() as u32)
            .filter(|&t| {
                let tri = body.mesh.triangles[t as usize].map(|i| body.mesh.vertices[i as usize]);
                point_triangle(p, tri, body.face_normals[t as usize], tol).is_some()
            })
            .collect()
    }

    /// Lists every triangle each of a lattice of points over the body's
    /// box, and of points on and off each face, touches, in increasing
    /// order; returns how many points touch one.
    fn check(body: &RigidBody, tol: Tolerances, cells_at_most: u64) -> usize {
        let grid = BodyGrid::new(body, tol.reach());
        let cells = grid.dims.iter().map(|&d| d as u64).product::<u64>();
        assert!((1..=cells_at_most).contains(&cells), "{cells} cells");
        let bounds = Aabb::of_points(&body.mesh.vertices).grown(2.0 * tol.reach());
        let steps = 23;
        // Off the lattice by irrational shares, so points fall anywhere in a cell.
        let lattice = (0..steps * steps * steps).map(|k| {
            let f = Vec3::new(
                (k % steps) as f32,
                (k / steps % steps) as f32,
                (k / steps / steps) as f32,
            );
            let u = (f + Vec3::new(0.414, 0.577, 0.732)) / steps as f32;
            bounds.min + u * (bounds.max - bounds.min)
        });
        let faces = (body.mesh.triangles.iter().zip(&body.face_normals)).flat_map(|(t, &n)| {
            let [a, b, c] = t.map(|i| body.mesh.vertices[i as usize]);
            let weights = [[1.0, 1.0, 1.0], [0.98, 0.01, 0.01], [0.01, 0.49, 0.5]];
            weights.into_iter().flat_map(move |[u, v, w]| {
                let q = (u * a + v * b + w * c) / (u + v + w);
                [-0.99 * tol.max_depth, 0.0, 0.99 * tol.thickness].map(|d| q + d * n)
            })
        });
        let mut touching = 0;
        for p in lattice.chain(faces) {
            let listed = grid.candidates(p);
            assert!(listed.windows(2).all(|w| w[0] < w[1]), "unsorted at {p}");
            let want = touched(body, p, tol);
            for t in &want {
                assert!(listed.contains(t), "{p} touches {t}, not listed");
            }
            touching += !want.is_empty() as usize;
        }
        touching
    }

    #[test]
    fn a_cell_lists_every_triangle_its_points_touch() {
        let tol = Tolerances {
            thickness: 0.02,
            max_depth: 0.05,
        };
        let turn = Quat::IDENTITY;
        let bodies = [
            TriMesh::icosphere(0.2, 2),
            TriMesh::cuboid(Vec3::new(0.3, 0.05, 0.1), 3),
            TriMesh::plane([0.8, 0.5], 4),
        ];
        for mesh in bodies {
            let body = RigidBody::new(mesh, turn, Vec3::ZERO, Motion::Static);
            let touching = check(&body, tol, MAX_CELLS);
            let faces = body.mesh.triangles.len();
            // The lattice's points touch faces too, not only those set on them.
            assert!(
                touching > 9 * faces + 200,
                "{touching} points touch a face of {faces}"
            );
        }
    }

    #[test]
    fn a_grid_past_its_cell_budget_grows_its_cells_and_still_lists_them_all() {
        // Half-millimetre cells over a metre would be 10^10.
        let tol = Tolerances {
            thickness: 1e-3,
            max_depth: 1e-3,
        };
        let body = RigidBody::new(
            TriMesh::cuboid(Vec3::splat(0.5), 2),
            Quat::IDENTITY,
            Vec3::ZERO,
            Motion::Static,
        );
        let faces = body.mesh.triangles.len();
        assert!(check(&body, tol, MAX_CELLS) >= 9 * faces);
    }

    #[test]
    fn points_outside_the_grid_or_not_numbers_have_no_candidates() {
        let body = RigidBody::new(
            TriMesh::icosphere(0.2, 1),
            Quat::IDENTITY,
            Vec3::ZERO,
            Motion::Static,
        );
        let grid = BodyGrid::new(&body, 0.01);
        for p in [
            Vec3::splat(1.0),
            Vec3::splat(-1.0),
            Vec3::NAN,
            Vec3::INFINITY,
        ] {
            assert!(grid.candidates(p).is_empty(), "{p}");
        }
        assert!(!grid.candidates(Vec3::new(0.0, 0.0, 0.2)).is_empty());
    }
}
