//! Triangle meshes for the rigid body: generated icosphere, box and plane,
//! or an OBJ file. Triangles wind counter-clockwise seen from outside, so
//! (b − a) × (c − a) is the outward normal.

use std::collections::HashMap;
use std::path::Path;

use glam::Vec3;

use crate::error::{Error, Result};

/// An indexed triangle mesh, wound counter-clockwise seen from outside.
#[derive(Clone, Debug, Default)]
pub struct TriMesh {
    /// Vertex positions in m.
    pub vertices: Vec<Vec3>,
    /// Each triangle's three vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Unit face normals (zero for a degenerate face).
    pub fn face_normals(&self) -> Vec<Vec3> {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| self.vertices[i as usize]);
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect()
    }

    /// Area-weighted vertex normals: the outward direction of each rigid
    /// vertex, used to orient the two-sided cloth against it.
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut n = vec![Vec3::ZERO; self.vertices.len()];
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize]);
            let area_normal = (b - a).cross(c - a);
            for &i in t {
                n[i as usize] += area_normal;
            }
        }
        n.into_iter().map(Vec3::normalize_or_zero).collect()
    }

    /// The mesh scaled by `s` about the origin.
    pub fn scaled(mut self, s: f32) -> TriMesh {
        for v in &mut self.vertices {
            *v *= s;
        }
        self
    }

    /// Geodesic sphere: an icosahedron subdivided `subdivisions` times.
    pub fn icosphere(radius: f32, subdivisions: u32) -> TriMesh {
        let t = (1.0 + 5f32.sqrt()) / 2.0;
        let mut vertices: Vec<Vec3> = [
            (-1.0, t, 0.0),
            (1.0, t, 0.0),
            (-1.0, -t, 0.0),
            (1.0, -t, 0.0),
            (0.0, -1.0, t),
            (0.0, 1.0, t),
            (0.0, -1.0, -t),
            (0.0, 1.0, -t),
            (t, 0.0, -1.0),
            (t, 0.0, 1.0),
            (-t, 0.0, -1.0),
            (-t, 0.0, 1.0),
        ]
        .iter()
        .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
        .collect();
        let mut triangles: Vec<[u32; 3]> = vec![
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ];
        for _ in 0..subdivisions {
            let mut midpoint: HashMap<(u32, u32), u32> = HashMap::new();
            let mut mid = |a: u32, b: u32, vertices: &mut Vec<Vec3>| {
                *midpoint.entry((a.min(b), a.max(b))).or_insert_with(|| {
                    let m = (vertices[a as usize] + vertices[b as usize]).normalize();
                    vertices.push(m);
                    vertices.len() as u32 - 1
                })
            };
            let mut next = Vec::with_capacity(triangles.len() * 4);
            for [a, b, c] in triangles {
                let ab = mid(a, b, &mut vertices);
                let bc = mid(b, c, &mut vertices);
                let ca = mid(c, a, &mut vertices);
                next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
            }
            triangles = next;
        }
        TriMesh {
            vertices,
            triangles,
        }
        .scaled(radius)
    }

    /// Axis-aligned box centred at the origin, each face a `segments`²
    /// grid of quads so rigid vertices are spread over its surface.
    pub fn cuboid(half_extents: Vec3, segments: u32) -> TriMesh {
        let s = segments.max(1);
        let mut mesh = TriMesh::default();
        let mut index: HashMap<[i64; 3], u32> = HashMap::new();
        // Each face: its normal axis and sign; u × v = outward normal.
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let mut n = Vec3::ZERO;
                n[axis] = sign;
                let mut u = Vec3::ZERO;
                u[(axis + 1) % 3] = 1.0;
                let v = n.cross(u);
                let mut id = |i: u32, j: u32, mesh: &mut TriMesh| {
                    let a = 2.0 * i as f32 / s as f32 - 1.0;
                    let b = 2.0 * j as f32 / s as f32 - 1.0;
                    let unit = n + u * a + v * b; // on the [-1, 1]³ cube
                    let key = (unit * s as f32).round().as_i64vec3().to_array();
                    *index.entry(key).or_insert_with(|| {
                        mesh.vertices.push(unit * half_extents);
                        mesh.vertices.len() as u32 - 1
                    })
                };
                for i in 0..s {
                    for j in 0..s {
                        let p00 = id(i, j, &mut mesh);
                        let p10 = id(i + 1, j, &mut mesh);
                        let p01 = id(i, j + 1, &mut mesh);
                        let p11 = id(i + 1, j + 1, &mut mesh);
                        mesh.triangles.push([p00, p10, p11]);
                        mesh.triangles.push([p00, p11, p01]);
                    }
                }
            }
        }
        mesh
    }

    /// A square in the body's x–z plane with normal +y, `segments`² quads.
    pub fn plane(size: [f32; 2], segments: u32) -> TriMesh {
        let s = segments.max(1);
        let mut mesh = TriMesh::default();
        for j in 0..=s {
            for i in 0..=s {
                let x = (i as f32 / s as f32 - 0.5) * size[0];
                let z = (j as f32 / s as f32 - 0.5) * size[1];
                mesh.vertices.push(Vec3::new(x, 0.0, z));
            }
        }
        let id = |i: u32, j: u32| j * (s + 1) + i;
        for j in 0..s {
            for i in 0..s {
                // Counter-clockwise seen from +y.
                mesh.triangles
                    .push([id(i, j), id(i, j + 1), id(i + 1, j + 1)]);
                mesh.triangles
                    .push([id(i, j), id(i + 1, j + 1), id(i + 1, j)]);
            }
        }
        mesh
    }

    /// Loads every object of an OBJ file into one mesh (polygons fanned into
    /// triangles), rejecting non-finite vertices, indices out of range and
    /// meshes with no usable triangle.
    /// Needs the crate's `obj` feature; without it this says so.
    pub fn load_obj(path: &Path) -> Result<TriMesh> {
        #[cfg(not(feature = "obj"))]
        return Err(Error::file(
            path,
            "is an OBJ mesh, and this build of the wgcloth library reads none (feature `obj`)",
        ));
        #[cfg(feature = "obj")]
        {
            let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
            TriMesh::parse_obj(&bytes, path)
        }
    }

    /// [`TriMesh::load_obj`] on the file's bytes; `path` only names it in
    /// errors. Materials are not read: the body is drawn in one colour.
    #[cfg(feature = "obj")]
    pub fn parse_obj(bytes: &[u8], path: &Path) -> Result<TriMesh> {
        check_obj_indices(bytes).map_err(|reason| Error::file(path, reason))?;
        let options = tobj::LoadOptions {
            triangulate: true,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        let (models, _materials) =
            tobj::load_obj_buf(&mut &bytes[..], &options, |_| Ok(Default::default()))
                .map_err(|e| Error::file(path, format!("not a readable OBJ mesh: {e}")))?;
        let mut mesh = TriMesh::default();
        for model in &models {
            let m = &model.mesh;
            let base = mesh.vertices.len() as u32;
            for (k, p) in m.positions.chunks_exact(3).enumerate() {
                let v = Vec3::new(p[0], p[1], p[2]);
                if !v.is_finite() {
                    return Err(Error::file(
                        path,
                        format!(
                            "vertex {} of object `{}` is not finite: {v}",
                            k + 1,
                            model.name
                        ),
                    ));
                }
                mesh.vertices.push(v);
            }
            let count = (m.positions.len() / 3) as u32;
            for tri in m.indices.chunks_exact(3) {
                if let Some(bad) = tri.iter().find(|&&i| i >= count) {
                    return Err(Error::file(
                        path,
                        format!(
                            "a face of object `{}` refers to vertex {} but the object has {count}",
                            model.name,
                            bad + 1
                        ),
                    ));
                }
                mesh.triangles
                    .push([tri[0] + base, tri[1] + base, tri[2] + base]);
            }
        }
        let normals = mesh.face_normals();
        let before = mesh.triangles.len();
        let mut k = 0;
        mesh.triangles.retain(|_| {
            k += 1;
            normals[k - 1] != Vec3::ZERO
        });
        if mesh.triangles.is_empty() {
            return Err(Error::file(
                path,
                format!("no usable triangle ({before} faces, all degenerate or none)"),
            ));
        }
        Ok(mesh)
    }
}

/// Rejects element indices that tobj 4 turns into out-of-range `usize`
/// arithmetic (which overflows, a panic in debug builds): 0, a relative
/// index reaching before the first element of its kind, or an absolute
/// one past the last. Found by fuzzing (fuzz/regressions/obj).
#[cfg(feature = "obj")]
fn check_obj_indices(bytes: &[u8]) -> std::result::Result<(), String> {
    let text = String::from_utf8_lossy(bytes);
    const KINDS: [(&str, &str); 3] = [
        ("v", "vertex"),
        ("vt", "texture coordinate"),
        ("vn", "normal"),
    ];
    let count = |kind: &str| {
        text.lines()
            .filter(|l| l.split_whitespace().next() == Some(kind))
            .count() as i64
    };
    let totals = KINDS.map(|(kind, _)| count(kind));
    let mut seen = [0i64; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let Some(first) = words.next() else { continue };
        if let Some(k) = KINDS.iter().position(|(kind, _)| *kind == first) {
            seen[k] += 1;
            continue;
        }
        if !matches!(first, "f" | "l" | "p") {
            continue;
        }
        for word in words {
            for (k, part) in word.split('/').enumerate().take(3) {
                // What does not parse is tobj's to reject.
                let Ok(index) = part.parse::<i64>() else {
                    continue;
                };
                let name = KINDS[k].1;
                if index == 0 || index < -seen[k] || index > totals[k] {
                    return Err(format!(
                        "line {}: {name} index {index} is out of range ({} defined before it, {} in all)",
                        n + 1,
                        seen[k],
                        totals[k]
                    ));
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signed_volume(m: &TriMesh) -> f32 {
        m.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.vertices[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// A closed mesh with outward winding has positive signed volume and
    /// every edge shared by exactly two faces.
    fn check_closed_outward(m: &TriMesh) {
        let vol = signed_volume(m);
        assert!(vol > 0.0, "volume {vol}");
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a, b)).or_default() += 1;
                assert!(edges[&(a, b)] == 1, "edge used twice in one direction");
            }
        }
        for &(a, b) in edges.keys() {
            assert!(edges.contains_key(&(b, a)), "open edge {a}-{b}");
        }
    }

    #[test]
    fn icosphere_is_closed_and_round() {
        let m = TriMesh::icosphere(0.3, 2);
        assert_eq!(m.triangles.len(), 20 * 16);
        check_closed_outward(&m);
        assert!(m.vertices.iter().all(|v| (v.length() - 0.3).abs() < 1e-6));
        let vol = signed_volume(&m);
        let exact = 4.0 / 3.0 * std::f32::consts::PI * 0.027;
        assert!((vol - exact).abs() < 0.05 * exact);
    }

    #[test]
    fn cuboid_is_closed_with_welded_edges() {
        let m = TriMesh::cuboid(Vec3::new(0.1, 0.2, 0.3), 3);
        check_closed_outward(&m);
        assert_eq!(m.vertices.len(), 6 * 9 + 2); // 6s² + 2 for a closed grid cube
        let n = m.face_normals();
        assert!(n.iter().all(|n| (n.length() - 1.0).abs() < 1e-6));
    }

    #[test]
    fn plane_faces_up() {
        let m = TriMesh::plane([2.0, 2.0], 2);
        assert!(
            m.face_normals()
                .iter()
                .all(|n| (*n - Vec3::Y).length() < 1e-6)
        );
    }
}
