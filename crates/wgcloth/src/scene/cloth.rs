//! The cloth: an nx × ny particle grid, its triangles, and its springs
//! (thesis 2.2): structural (±1 row/col), shear (both diagonals) and bend
//! (±2 row/col). Topology is fixed for the whole run; it is what the
//! stages gather over.

use glam::Vec3;

/// Vertex → incident springs, as CSR (offsets into `spring` and `other`),
/// sorted by the neighbour's index. Stages gather over it instead of
/// scattering, which is also how the GPU twins accumulate.
#[derive(Clone, Debug, Default)]
pub struct Adjacency {
    /// Vertex i's entries are `offsets[i]..offsets[i + 1]`; one more than
    /// the vertex count.
    pub offsets: Vec<u32>,
    /// Each entry's spring, an index into [`Cloth::springs`].
    pub spring: Vec<u32>,
    /// Each entry's other vertex, ascending within a vertex's entries.
    pub other: Vec<u32>,
}

impl Adjacency {
    /// The entries of vertex `i`.
    pub fn range(&self, i: usize) -> std::ops::Range<usize> {
        self.offsets[i] as usize..self.offsets[i + 1] as usize
    }
}

/// The three spring families of thesis 2.2.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpringKind {
    /// To the next vertex along a row or a column.
    Structural,
    /// To a diagonal neighbour.
    Shear,
    /// To the vertex two along a row or a column (resists bending).
    Bend,
}

/// The cloth's rest state and fixed topology (see the module docs).
#[derive(Clone, Debug)]
pub struct Cloth {
    /// Particles per row (along the width).
    pub nx: u32,
    /// Particles per column (along the height), row 0 on top.
    pub ny: u32,
    /// Initial positions; pinned vertices stay at theirs.
    pub rest_positions: Vec<Vec3>,
    /// Vertex indices, two triangles per grid cell, the cell diagonals
    /// alternating like a checkerboard.
    pub triangles: Vec<[u32; 3]>,
    /// The two vertices [i, j] of each spring.
    pub springs: Vec<[u32; 2]>,
    /// Each spring's family, parallel to `springs`.
    pub spring_kinds: Vec<SpringKind>,
    /// Each spring's rest length L in m: its length in `rest_positions`.
    pub rest_lengths: Vec<f32>,
    /// Vertex → incident springs, what the stages gather over.
    pub adjacency: Adjacency,
    /// For each triangle, the springs along its edges (t0 t1), (t1 t2), (t2 t0):
    /// where the cross blocks of a face contact land.
    pub triangle_springs: Vec<[u32; 3]>,
    /// Per vertex, whether it is pinned at its rest position.
    pub pinned: Vec<bool>,
    /// m_i in kg: the total mass shared equally by the vertices.
    pub vertex_mass: f32,
    /// E of thesis eq. 4 (N/m), the same for every spring.
    pub stiffness: f32,
}

impl Cloth {
    /// A grid whose vertex (row r, column c) is `r * nx + c`, row 0 on top;
    /// `place` maps grid coordinates (u, v) ∈ \[0, 1\]², v = 0 on top, to world.
    pub fn grid(
        nx: u32,
        ny: u32,
        total_mass: f32,
        stiffness: f32,
        pinned: &[u32],
        place: impl Fn(f32, f32) -> Vec3,
    ) -> Cloth {
        let id = |c: u32, r: u32| r * nx + c;
        let n = (nx * ny) as usize;
        let rest_positions: Vec<Vec3> = (0..ny)
            .flat_map(|r| (0..nx).map(move |c| (c, r)))
            .map(|(c, r)| place(c as f32 / (nx - 1) as f32, r as f32 / (ny - 1) as f32))
            .collect();

        let mut springs = Vec::new();
        let mut spring_kinds = Vec::new();
        for r in 0..ny {
            for c in 0..nx {
                let mut add = |dc: i32, dr: i32, kind| {
                    let (c2, r2) = (c as i32 + dc, r as i32 + dr);
                    if (0..nx as i32).contains(&c2) && (0..ny as i32).contains(&r2) {
                        springs.push([id(c, r), id(c2 as u32, r2 as u32)]);
                        spring_kinds.push(kind);
                    }
                };
                add(1, 0, SpringKind::Structural);
                add(0, 1, SpringKind::Structural);
                add(1, 1, SpringKind::Shear);
                add(-1, 1, SpringKind::Shear);
                add(2, 0, SpringKind::Bend);
                add(0, 2, SpringKind::Bend);
            }
        }
        let rest_lengths = springs
            .iter()
            .map(|&[i, j]| (rest_positions[j as usize] - rest_positions[i as usize]).length())
            .collect();

        let mut incident: Vec<Vec<(u32, u32)>> = vec![Vec::new(); n];
        for (s, &[i, j]) in springs.iter().enumerate() {
            incident[i as usize].push((j, s as u32));
            incident[j as usize].push((i, s as u32));
        }
        let mut adjacency = Adjacency {
            offsets: vec![0],
            ..Default::default()
        };
        for mut list in incident {
            list.sort_unstable();
            for (other, s) in list {
                adjacency.other.push(other);
                adjacency.spring.push(s);
            }
            adjacency.offsets.push(adjacency.other.len() as u32);
        }

        // Two triangles per cell, the diagonal alternating like a
        // checkerboard so the drape has no preferred shear direction.
        let mut triangles = Vec::new();
        for r in 0..ny - 1 {
            for c in 0..nx - 1 {
                let (a, b, cc, d) = (id(c, r), id(c + 1, r), id(c, r + 1), id(c + 1, r + 1));
                if (r + c).is_multiple_of(2) {
                    triangles.push([a, cc, b]);
                    triangles.push([b, cc, d]);
                } else {
                    triangles.push([a, d, b]);
                    triangles.push([a, cc, d]);
                }
            }
        }
        let spring_between = |i: u32, j: u32| -> u32 {
            let range = adjacency.range(i as usize);
            let k = adjacency.other[range.clone()]
                .binary_search(&j)
                .expect("every triangle edge is a structural or shear spring");
            adjacency.spring[range.start + k]
        };
        let triangle_springs = triangles
            .iter()
            .map(|&[a, b, c]| {
                [
                    spring_between(a, b),
                    spring_between(b, c),
                    spring_between(c, a),
                ]
            })
            .collect();

        let mut pin_flags = vec![false; n];
        for &p in pinned {
            pin_flags[p as usize] = true;
        }
        Cloth {
            nx,
            ny,
            rest_positions,
            triangles,
            springs,
            spring_kinds,
            rest_lengths,
            adjacency,
            triangle_springs,
            pinned: pin_flags,
            vertex_mass: total_mass / n as f32,
            stiffness,
        }
    }

    /// The number of particles, nx · ny.
    pub fn vertex_count(&self) -> usize {
        self.rest_positions.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spring_counts_and_symmetric_adjacency() {
        let (nx, ny) = (5u32, 4u32);
        let cloth = Cloth::grid(nx, ny, 1.0, 10.0, &[], |u, v| Vec3::new(u, -v, 0.0));
        let count = |k| cloth.spring_kinds.iter().filter(|&&s| s == k).count() as u32;
        assert_eq!(count(SpringKind::Structural), (nx - 1) * ny + nx * (ny - 1));
        assert_eq!(count(SpringKind::Shear), 2 * (nx - 1) * (ny - 1));
        assert_eq!(count(SpringKind::Bend), (nx - 2) * ny + nx * (ny - 2));
        assert_eq!(cloth.triangles.len() as u32, 2 * (nx - 1) * (ny - 1));
        for i in 0..cloth.vertex_count() {
            for k in cloth.adjacency.range(i) {
                let [a, b] = cloth.springs[cloth.adjacency.spring[k] as usize];
                let j = cloth.adjacency.other[k];
                assert!((a, b) == (i as u32, j) || (a, b) == (j, i as u32));
            }
        }
        for (t, s) in cloth.triangles.iter().zip(&cloth.triangle_springs) {
            for e in 0..3 {
                let [a, b] = cloth.springs[s[e] as usize];
                let (p, q) = (t[e], t[(e + 1) % 3]);
                assert!((a, b) == (p, q) || (a, b) == (q, p));
            }
        }
    }
}
