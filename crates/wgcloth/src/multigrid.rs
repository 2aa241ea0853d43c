//! The grid hierarchy of the multigrid preconditioner, shared by the CPU
//! twin (`cpu::multigrid`) and the kernels (wgsl/multigrid.wgsl).
//!
//! The cloth is a regular grid, so its coarse levels are too: level l + 1
//! keeps every second node of level l along each axis (⌈n / 2⌉ of n), and a
//! node between two kept ones takes half of each (bilinear interpolation
//! P). Each coarse operator is the Galerkin product Pᵀ A P, whose blocks are
//! weighted sums of symmetric blocks and so symmetric themselves: the
//! springs reach two nodes (bend springs), and so does every coarse level's
//! 5 × 5 stencil. Since A_ij = A_ji and each block is symmetric, a node
//! stores only the upper half of its stencil ([`STORED_STENCIL`] blocks)
//! and reads the lower half from its neighbours ([`stored_at`]): half the
//! memory, and a coarse operator that is exactly symmetric in f32.

/// Blocks in a coarse node's stencil: offsets −2..=2 along each axis.
pub const STENCIL: u32 = 25;
/// Blocks a coarse node stores: the centre and the offsets after it in
/// [`stencil_slot`]'s order (dy > 0, or dy = 0 and dx > 0).
pub const STORED_STENCIL: u32 = STENCIL / 2 + 1;
/// Stop coarsening once a level has at most this many nodes; the coarsest
/// is then solved by [`COARSE_SWEEPS`] Jacobi sweeps in one workgroup.
pub const COARSEST_NODES: u32 = 16;
/// Damped block-Jacobi sweeps on the coarsest level.
pub const COARSE_SWEEPS: u32 = 12;
/// The most levels a hierarchy has (a 2²⁶-particle cloth needs 23).
pub const MAX_LEVELS: u32 = 24;
/// The most nodes of a level the GPU's V-cycle takes in its tail, one
/// dispatch of one workgroup for all the levels from there down. Each
/// dispatch costs a barrier that drains the device (6–8 µs on an H200,
/// work or not); below this size one workgroup does a level's work in
/// less. A CPU adapter (lavapipe) runs a workgroup on one thread, so it
/// stops sooner: a 1024-node tail made the H200's PCG 4–6 % faster and
/// lavapipe's 19 % slower at 64² (BENCHMARKS.md "Hardware GPU").
pub fn tail_nodes(cpu_adapter: bool) -> u32 {
    match cpu_adapter {
        true => 256,
        false => 1024,
    }
}

/// The first level of the tail: the first coarse level of at most `most`
/// nodes ([`tail_nodes`]; the coarsest has at most [`COARSEST_NODES`]).
pub fn tail_from(nodes: &[u32], most: u32) -> usize {
    (1..nodes.len())
        .find(|&l| nodes[l] <= most)
        .unwrap_or(nodes.len() - 1)
}

/// ω of the damped block-Jacobi smoother ω D⁻¹, where the row allows it.
pub const SMOOTH_WEIGHT: f32 = 1.0;
/// How close a row's ω may come to its bound 2 / (1 + s) (see [`row_weight`]).
pub const SMOOTH_MARGIN: f32 = 0.95;

/// The damping ω_i of a row whose off-diagonal blocks scaled by its
/// diagonal block's inverse have norms summing to `spread`
/// (s_i = Σ_j |D_i⁻¹ A_ij|). By Gershgorin's theorem every eigenvalue of
/// the smoothed operator diag(ω_i D_i⁻¹) A lies below max_i ω_i (1 + s_i) < 2,
/// so every sweep converges and the V-cycle is positive definite, whatever
/// the contacts put in A (a face contact's β_k β_l blocks can take a row's
/// D⁻¹A past 2, where a fixed ω would make the V-cycle indefinite).
pub fn row_weight(spread: f32) -> f32 {
    SMOOTH_WEIGHT.min(2.0 * SMOOTH_MARGIN / (1.0 + spread))
}

/// Nodes of a smoothing patch (the patch smoother, `Smoother::Patches`):
/// 2 × 2, local node k at (k % 2, k / 2) from the patch's first.
pub const PATCH: u32 = 4;
/// Unknowns of a patch.
pub const PATCH_UNKNOWNS: usize = 3 * PATCH as usize;
/// Packed symmetric blocks (6 floats each) that hold a patch's inverse, a
/// symmetric 12 × 12 of 78 floats: its four diagonal 3 × 3 blocks, then
/// the six above them ([`upper_block`]), 9 floats each, column-major.
pub const PATCH_BLOCKS: u32 = 13;
/// Colours of the patches (see [`colour_grid`]).
pub const PATCH_COLOURS: usize = 4;
/// `patches_at` of a level smoothed by block Jacobi (the coarsest always).
pub const NO_PATCHES: u32 = u32::MAX;

/// A patch's matrix or inverse, row-major.
pub type PatchMatrix = [[f32; PATCH_UNKNOWNS]; PATCH_UNKNOWNS];

/// The patches of `level`, per axis: patch (pc, pr) holds nodes
/// 2 pc..2 pc + 2 × 2 pr..2 pr + 2 within the grid.
pub fn patch_grid(level: Level) -> (u32, u32) {
    (level.nx.div_ceil(2), level.ny.div_ceil(2))
}

/// The patches of one colour, at most, per axis. Colour c = cx + 2 cy holds
/// patches (cx + 2 i, cy + 2 j): no two share a spring (a spring reaches
/// two nodes, and such patches are four apart), so each colour's are solved
/// side by side.
pub fn colour_grid(level: Level) -> (u32, u32) {
    let (px, py) = patch_grid(level);
    (px.div_ceil(2), py.div_ceil(2))
}

/// The patch colour of node (c, r) (see [`colour_grid`]).
pub fn node_colour(c: u32, r: u32) -> u32 {
    (c / 2) % 2 + 2 * ((r / 2) % 2)
}

/// Threads of a patch sweep of `level`: four per patch of a colour.
pub fn patch_threads(level: Level) -> u32 {
    let (cx, cy) = colour_grid(level);
    PATCH * cx * cy
}

/// Index among a patch's six blocks above the diagonal of block (k, b),
/// k < b: (0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3).
pub fn upper_block(k: u32, b: u32) -> u32 {
    3 * k - k * k.saturating_sub(1) / 2 + b - k - 1
}

/// The inverse of a symmetric positive definite patch matrix (its lower
/// half read), by Cholesky M = L Lᵀ and M⁻¹ = L⁻ᵀ L⁻¹, so it is exactly
/// symmetric; None if M is not positive definite. In f32, the same sums in
/// the same order as `patch_factor` and `inverse_float` in
/// wgsl/multigrid.wgsl.
pub fn patch_inverse(m: &PatchMatrix) -> Option<PatchMatrix> {
    const N: usize = PATCH_UNKNOWNS;
    // L below its diagonal; on it 1 / L_jj, which is all either product
    // needs of it: twelve divisions instead of 144.
    let mut l = [[0f32; N]; N];
    for j in 0..N {
        let mut d = m[j][j];
        for v in &l[j][..j] {
            d -= v * v;
        }
        if !(d > 0.0 && d.is_finite()) {
            return None;
        }
        l[j][j] = 1.0 / d.sqrt();
        for i in j + 1..N {
            let mut s = m[i][j];
            for (a, b) in l[i][..j].iter().zip(&l[j][..j]) {
                s -= a * b;
            }
            l[i][j] = s * l[j][j];
        }
    }
    // W = L⁻¹, lower, a row at a time from the rows above it. The zeros
    // above W's diagonal come first in each sum and add nothing, so these
    // are the WGSL's column-at-a-time sums, in its order, vectorised.
    let mut w = [[0f32; N]; N];
    for i in 0..N {
        let mut s = [0f32; N];
        for k in 0..i {
            let a = l[i][k];
            for (s, b) in s.iter_mut().zip(&w[k]) {
                *s += a * b;
            }
        }
        for c in 0..i {
            w[i][c] = -s[c] * l[i][i];
        }
        w[i][i] = l[i][i];
    }
    // M⁻¹ = Wᵀ W, a rank-one update per row of W: again the same sums (k
    // ascending), and (i, j) and (j, i) the same products.
    let mut out = [[0f32; N]; N];
    for row in &w {
        for (out, &a) in out.iter_mut().zip(row) {
            for (o, b) in out.iter_mut().zip(row) {
                *o += a * b;
            }
        }
    }
    Some(out)
}

/// One level's grid: `nx × ny` nodes, node (c, r) at index r · nx + c.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Level {
    /// Nodes per row.
    pub nx: u32,
    /// Nodes per column.
    pub ny: u32,
}

impl Level {
    /// nx · ny.
    pub fn nodes(self) -> usize {
        self.nx as usize * self.ny as usize
    }

    /// The cloth's own grid, level 0.
    pub fn of(cloth: &crate::scene::Cloth) -> Level {
        Level {
            nx: cloth.nx,
            ny: cloth.ny,
        }
    }

    /// The next coarser level.
    pub fn coarser(self) -> Level {
        Level {
            nx: self.nx.div_ceil(2),
            ny: self.ny.div_ceil(2),
        }
    }
}

/// The levels of an `nx × ny` cloth, finest (the cloth) first: at least
/// one coarse level, the last with at most [`COARSEST_NODES`] nodes.
pub fn levels(nx: u32, ny: u32) -> Vec<Level> {
    let mut out = vec![Level { nx, ny }];
    let mut last = out[0];
    while out.len() == 1 || last.nodes() > COARSEST_NODES as usize {
        last = last.coarser();
        out.push(last);
    }
    out
}

/// The coarse nodes fine coordinate `c` interpolates from along one axis,
/// with their weights (`n_coarse` nodes on the coarse axis): the coarse node
/// itself for an even `c`, else its two neighbours half each (the one to
/// its left alone at an even-length axis's end). The second weight is 0
/// when there is one parent.
pub fn parents(c: u32, n_coarse: u32) -> [(u32, f32); 2] {
    let left = c / 2;
    if c.is_multiple_of(2) {
        [(left, 1.0), (left, 0.0)]
    } else if left + 1 < n_coarse {
        [(left, 0.5), (left + 1, 0.5)]
    } else {
        [(left, 1.0), (left, 0.0)]
    }
}

/// The weight of coarse node `coarse` at fine coordinate `c` (0 if it is
/// not one of its parents).
pub fn weight(c: u32, coarse: u32, n_coarse: u32) -> f32 {
    parents(c, n_coarse)
        .iter()
        .filter(|&&(p, _)| p == coarse)
        .map(|&(_, w)| w)
        .sum()
}

/// Index into a stencil of the offset (dx, dy), each in −2..=2.
pub fn stencil_slot(dx: i32, dy: i32) -> usize {
    ((dy + 2) * 5 + dx + 2) as usize
}

/// Where the block of offset (dx, dy) from a node is stored: at the node
/// itself (`false`) or at its neighbour at (dx, dy) (`true`), and the slot
/// among that node's [`STORED_STENCIL`].
pub fn stored_at(dx: i32, dy: i32) -> (bool, usize) {
    let centre = STENCIL as usize / 2;
    let slot = stencil_slot(dx, dy);
    match slot >= centre {
        true => (false, slot - centre),
        false => (true, centre - slot),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_halve_to_the_coarsest() {
        let l = levels(32, 32);
        let sides: Vec<u32> = l.iter().map(|l| l.nx).collect();
        assert_eq!(sides, [32, 16, 8, 4]);
        assert_eq!(levels(2, 2).len(), 2);
        let odd = levels(33, 5);
        assert_eq!(odd[1], Level { nx: 17, ny: 3 });
        assert!(odd.last().unwrap().nodes() <= COARSEST_NODES as usize);
        let tall = levels(2, 1 << 25);
        assert!(tall.len() <= MAX_LEVELS as usize, "{}", tall.len());
    }

    #[test]
    fn each_offset_is_stored_once_and_its_opposite_at_the_neighbour() {
        let mut seen = [0; STORED_STENCIL as usize];
        for dy in -2..=2 {
            for dx in -2..=2 {
                let (neighbour, slot) = stored_at(dx, dy);
                let centre = (dx, dy) == (0, 0);
                assert_eq!(stored_at(-dx, -dy), (!neighbour && !centre, slot));
                if !neighbour {
                    seen[slot] += 1;
                }
            }
        }
        assert_eq!(seen, [1; STORED_STENCIL as usize]);
    }

    #[test]
    fn a_patch_inverse_times_its_matrix_is_the_identity() {
        // A stiff SPD matrix, as a patch's: a mass on the diagonal and
        // springs 10⁴ times stiffer coupling the unknowns.
        let n = PATCH_UNKNOWNS;
        let mut m = [[0f32; PATCH_UNKNOWNS]; PATCH_UNKNOWNS];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, e) in row.iter_mut().enumerate() {
                let spring = ((i * 7 + j * 7) % 5) as f32 - 2.0;
                *e = 1e4 * spring / (1.0 + i.abs_diff(j) as f32);
            }
        }
        // Mᵀ M + I: symmetric positive definite.
        let mut spd = [[0f32; PATCH_UNKNOWNS]; PATCH_UNKNOWNS];
        for i in 0..n {
            for j in 0..n {
                spd[i][j] = (0..n).map(|k| m[k][i] * m[k][j]).sum::<f32>() * 1e-4
                    + if i == j { 1.0 } else { 0.0 };
            }
        }
        let inverse = patch_inverse(&spd).expect("positive definite");
        for (i, row) in inverse.iter().enumerate() {
            for j in 0..n {
                assert_eq!(row[j], inverse[j][i], "symmetric");
                let e: f64 = (0..n).map(|k| row[k] as f64 * spd[k][j] as f64).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((e - want).abs() < 1e-2, "({i}, {j}): {e}");
            }
        }
        let mut indefinite = spd;
        indefinite[5][5] = -1.0;
        assert!(patch_inverse(&indefinite).is_none());
    }

    #[test]
    fn upper_blocks_are_numbered_row_by_row() {
        let pairs: Vec<(u32, u32)> = (0..4u32)
            .flat_map(|k| (k + 1..4).map(move |b| (k, b)))
            .collect();
        for (m, &(k, b)) in pairs.iter().enumerate() {
            assert_eq!(upper_block(k, b), m as u32);
        }
    }

    #[test]
    fn interpolation_is_a_partition_of_unity() {
        for n_fine in [2u32, 5, 8, 33] {
            let n_coarse = n_fine.div_ceil(2);
            for c in 0..n_fine {
                let total: f32 = (0..n_coarse).map(|k| weight(c, k, n_coarse)).sum();
                assert_eq!(total, 1.0, "fine {c} of {n_fine}");
            }
        }
    }
}
