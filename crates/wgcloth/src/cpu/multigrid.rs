//! The multigrid preconditioner of stage "pcg": one symmetric V(1,1)-cycle
//! on the grid hierarchy of [`crate::multigrid`], each level but the
//! coarsest smoothed by the patch smoother (four-colour block Gauss-Seidel
//! over 2 × 2-node patches, forward down and backward up) or damped block
//! Jacobi ([`Smoother`]), Galerkin coarse operators rebuilt every step, the
//! coarsest level solved by a fixed number of block-Jacobi sweeps. A fixed
//! symmetric positive definite linear operator, so CG stays CG. Mirrors
//! wgsl/multigrid.wgsl kernel by kernel.
//!
//! Pinned vertices are filtered as in the fine solve: the interpolation
//! P̃ = S P never reaches them, so every level solves for free motion only.

use std::mem::take;
use std::ops::Range;

use glam::{Mat3, Vec3};
use rayon::prelude::*;

use crate::config::Smoother;
use crate::cpu::GRAIN;
use crate::cpu::pcg::BlockMatrix;
use crate::math::RowSum;
use crate::multigrid::{
    COARSE_SWEEPS, Level, PATCH, PATCH_COLOURS, PATCH_UNKNOWNS, PatchMatrix, STENCIL,
    STORED_STENCIL, levels, node_colour, parents, patch_grid, patch_inverse, row_weight,
    stencil_slot, stored_at, weight,
};
use crate::scene::Cloth;

/// The hierarchy's operators and work vectors, kept between steps.
#[derive(Clone, Debug)]
pub struct Multigrid {
    levels: Vec<Level>,
    /// Per coarse level (index l − 1): [`STORED_STENCIL`] blocks per node,
    /// the upper half of its stencil (`multigrid::stored_at`).
    stencils: Vec<Vec<Mat3>>,
    /// Per level: ω D⁻¹, zero where D is singular (a pinned node, or a coarse
    /// node whose fine nodes are all pinned); empty on the levels the patch
    /// smoother smooths (all but the coarsest), which need none.
    smoothers: Vec<Vec<Mat3>>,
    /// Per coarse level: its right-hand side (the restricted residual).
    rhs: Vec<Vec<Vec3>>,
    /// Per coarse level: its correction after the up-leg's smoothing.
    correction: Vec<Vec<Vec3>>,
    /// Per level but the coarsest: its pre-smoothing (ω D⁻¹ r, or the
    /// forward patch sweeps'), and room for its residual on the way down
    /// and its guess on the way up.
    pre: Vec<Vec<Vec3>>,
    work: Vec<Vec<Vec3>>,
    /// Per level but the coarsest, with the patch smoother: each 2 × 2
    /// patch's inverse, patch (pc, pr) at pr · px + pc.
    patch_inverses: Vec<Vec<PatchMatrix>>,
    /// Per level but the coarsest, with the patch smoother: each node's
    /// patch colour ([`node_colour`]).
    colours: Vec<Vec<u8>>,
    smoother: Smoother,
}

/// Which way a patch sweep goes.
enum Sweep<'a> {
    /// Colours 0 to 3 from zero, each patch's residual from the colours
    /// before it (the rest are still zero, whatever z holds there) and its
    /// nodes set. The function is called with z and, in order, the grid
    /// rows whose nodes and neighbours within two rows are all set.
    Forward(&'a mut dyn FnMut(&[Vec3], Range<usize>)),
    /// Colours 3 to 0 from the guess in z, each node corrected.
    Backward,
}

/// The nodes of patch (pc, pr) of `level`, by local index; None past the
/// grid's edge.
fn patch_nodes(level: Level, (pc, pr): (usize, usize)) -> [Option<Node>; PATCH as usize] {
    std::array::from_fn(|k| {
        let (c, r) = ((2 * pc + k % 2) as u32, (2 * pr + k / 2) as u32);
        (c < level.nx && r < level.ny).then_some((
            r as usize * level.nx as usize + c as usize,
            c,
            r,
        ))
    })
}

/// ω_i D⁻¹ of a row with diagonal block `d` and off-diagonal blocks `off`
/// ([`row_weight`]), or zero if D is not invertible.
fn smoother(d: Mat3, off: impl Iterator<Item = Mat3>) -> Mat3 {
    let det = d.determinant();
    if !(det.is_finite() && det.abs() > f32::MIN_POSITIVE) {
        return Mat3::ZERO;
    }
    let inverse = d.inverse();
    let spread = off.map(|block| frobenius(inverse * block)).sum();
    row_weight(spread) * inverse
}

fn frobenius(m: Mat3) -> f32 {
    m.to_cols_array().iter().map(|e| e * e).sum::<f32>().sqrt()
}

/// Asks the cache for `items` ahead of their use: a hint, which changes no
/// result, where the CPU has one (x86-64) and nothing elsewhere.
#[inline(always)]
fn prefetch<T>(items: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let bytes = std::mem::size_of_val(items);
        let start = items.as_ptr().cast::<i8>();
        // Every 64-byte line from the first byte to the last.
        for offset in (0..bytes).step_by(64).chain(bytes.checked_sub(1)) {
            // SAFETY: the address is inside `items`, and a prefetch never
            // faults or writes.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(start.add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = items;
}

/// Grid coordinates of node `i` of `level`.
fn coords(level: Level, i: usize) -> (u32, u32) {
    (
        (i % level.nx as usize) as u32,
        (i / level.nx as usize) as u32,
    )
}

/// A node of a level: its index and its grid coordinates (c, r).
type Node = (usize, u32, u32);

/// Sets `out[i] = f(node i)` for every node of `level`, a grid row at a
/// time, so no node's coordinates are divided out of its index.
fn for_each_node<T: Send>(level: Level, out: &mut [T], f: impl Fn(Node) -> T + Sync) {
    for_each_node_in(level, 0..level.ny as usize, out, f);
}

/// [`for_each_node`] over the grid rows `rows` alone, `out` the whole level.
fn for_each_node_in<T: Send>(
    level: Level,
    rows: Range<usize>,
    out: &mut [T],
    f: impl Fn(Node) -> T + Sync,
) {
    let nx = level.nx as usize;
    out[rows.start * nx..rows.end * nx]
        .par_chunks_mut(nx)
        .with_min_len(GRAIN.div_ceil(nx))
        .enumerate()
        .for_each(|(k, row)| {
            let r = rows.start + k;
            for (c, o) in row.iter_mut().enumerate() {
                *o = f((r * nx + c, c as u32, r as u32));
            }
        });
}

impl Multigrid {
    /// The hierarchy of `cloth`'s grid, operators zero until [`setup`](Self::setup).
    pub fn new(cloth: &Cloth, smoother: Smoother) -> Multigrid {
        let levels = levels(cloth.nx, cloth.ny);
        let coarse = || levels[1..].iter().map(|l| vec![Vec3::ZERO; l.nodes()]);
        let upper = || {
            levels[..levels.len() - 1]
                .iter()
                .map(|l| vec![Vec3::ZERO; l.nodes()])
        };
        Multigrid {
            stencils: levels[1..]
                .iter()
                .map(|l| vec![Mat3::ZERO; l.nodes() * STORED_STENCIL as usize])
                .collect(),
            smoothers: vec![Vec::new(); levels.len()],
            rhs: coarse().collect(),
            correction: coarse().collect(),
            pre: upper().collect(),
            work: upper().collect(),
            patch_inverses: Vec::new(),
            colours: match smoother {
                Smoother::Patches => levels[..levels.len() - 1]
                    .iter()
                    .map(|&level| {
                        (0..level.nodes())
                            .map(|i| {
                                let (c, r) = coords(level, i);
                                node_colour(c, r) as u8
                            })
                            .collect()
                    })
                    .collect(),
                Smoother::BlockJacobi => Vec::new(),
            },
            smoother,
            levels,
        }
    }

    /// How it smooths.
    pub fn smoother(&self) -> Smoother {
        self.smoother
    }

    /// The grid levels, the cloth first.
    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// Block (i, j) of coarse level `l`'s operator (`l` ≥ 1), zero where j
    /// is outside i's stencil.
    pub fn coarse_block(&self, l: usize, i: usize, j: usize) -> Mat3 {
        let level = self.levels[l];
        let ((ci, ri), (cj, rj)) = (coords(level, i), coords(level, j));
        let (dx, dy) = (cj as i32 - ci as i32, rj as i32 - ri as i32);
        if dx.abs() > 2 || dy.abs() > 2 {
            return Mat3::ZERO;
        }
        self.stored_block(l, i, j, dx, dy)
    }

    /// Block (i, j) of coarse level `l`, j at (dx, dy) from i, from where
    /// the upper half of the stencils keeps it.
    fn stored_block(&self, l: usize, i: usize, j: usize, dx: i32, dy: i32) -> Mat3 {
        let (at_neighbour, slot) = stored_at(dx, dy);
        let node = if at_neighbour { j } else { i };
        self.stencils[l - 1][node * STORED_STENCIL as usize + slot]
    }

    /// Calls `f(j, A_ij)` for every block of row `i` (at `(c, r)`) of level
    /// `l`'s operator.
    fn row_entries(
        &self,
        a: &BlockMatrix,
        cloth: &Cloth,
        l: usize,
        (i, c, r): Node,
        mut f: impl FnMut(usize, Mat3),
    ) {
        if l == 0 {
            f(i, a.diag[i]);
            let adj = &cloth.adjacency;
            for k in adj.range(i) {
                f(adj.other[k] as usize, a.off[adj.spring[k] as usize]);
            }
            return;
        }
        let level = self.levels[l];
        for dy in -2..=2i32 {
            for dx in -2..=2i32 {
                let (cj, rj) = (c as i32 + dx, r as i32 + dy);
                if (0..level.nx as i32).contains(&cj) && (0..level.ny as i32).contains(&rj) {
                    let j = rj as usize * level.nx as usize + cj as usize;
                    f(j, self.stored_block(l, i, j, dx, dy));
                }
            }
        }
    }

    /// Row `node` of level `l`'s operator times the vector `x(j)`.
    fn row(
        &self,
        a: &BlockMatrix,
        cloth: &Cloth,
        l: usize,
        node: Node,
        x: impl Fn(usize) -> Vec3,
    ) -> Vec3 {
        self.row_where(a, cloth, l, node, |_| true, x)
    }

    /// Row `node` of level `l`'s operator times `x(j)` over the j that `keep`.
    fn row_where(
        &self,
        a: &BlockMatrix,
        cloth: &Cloth,
        l: usize,
        node: Node,
        keep: impl Fn(usize) -> bool,
        x: impl Fn(usize) -> Vec3,
    ) -> Vec3 {
        let mut acc = RowSum::default();
        self.row_entries(a, cloth, l, node, |j, block| {
            if keep(j) {
                acc.add(block, x(j))
            }
        });
        acc.total()
    }

    /// The weight of fine node `i` at `(c, r)` (level `l`) in coarse node
    /// `(cc, rc)`, zero at a pinned vertex (P̃ = S P).
    fn fine_weight(&self, cloth: &Cloth, l: usize, (i, c, r): Node, coarse: (u32, u32)) -> f32 {
        if l == 0 && cloth.pinned[i] {
            return 0.0;
        }
        let next = self.levels[l + 1];
        weight(c, coarse.0, next.nx) * weight(r, coarse.1, next.ny)
    }

    /// The fine nodes coarse node `(cc, rc)` gathers from: up to 3 × 3.
    fn children(fine: Level, (cc, rc): (u32, u32)) -> impl Iterator<Item = Node> {
        let span = |k: u32, n: u32| (2 * k).saturating_sub(1)..(2 * k + 2).min(n);
        span(rc, fine.ny).flat_map(move |r| {
            span(cc, fine.nx).map(move |c| (r as usize * fine.nx as usize + c as usize, c, r))
        })
    }

    /// Σ over coarse parents (level `l` + 1) of fine node `(i, c, r)`,
    /// weighted.
    fn interpolate(&self, cloth: &Cloth, l: usize, (i, c, r): Node, coarse: &[Vec3]) -> Vec3 {
        if l == 0 && cloth.pinned[i] {
            return Vec3::ZERO;
        }
        let next = self.levels[l + 1];
        let mut acc = Vec3::ZERO;
        for (pr, wr) in parents(r, next.ny) {
            for (pc, wc) in parents(c, next.nx) {
                acc += (wr * wc) * coarse[pr as usize * next.nx as usize + pc as usize];
            }
        }
        acc
    }

    /// Each patch's inverse of level `l`'s operator among its unknowns
    /// (pinned vertices' and missing nodes' unknowns held at zero).
    fn patch_inverses_of(&self, a: &BlockMatrix, cloth: &Cloth, l: usize) -> Vec<PatchMatrix> {
        let level = self.levels[l];
        let (px, py) = patch_grid(level);
        let (px, py) = (px as usize, py as usize);
        let diagonal = |i: usize| match l {
            0 => a.diag[i],
            _ => self.stored_block(l, i, i, 0, 0),
        };
        // Past the grid, a pinned vertex, or a coarse node of pinned
        // vertices alone (a zero row).
        let held = |node: Option<Node>| match node {
            None => true,
            Some((i, ..)) => (l == 0 && cloth.pinned[i]) || diagonal(i) == Mat3::ZERO,
        };
        // Block (i, j) of the operator, j in i's patch.
        let block = |(i, c, r): Node, (j, cj, rj): Node| match l {
            0 if i == j => a.diag[i],
            0 => {
                let adj = &cloth.adjacency;
                let k = adj.range(i).find(|&k| adj.other[k] as usize == j);
                k.map_or(Mat3::ZERO, |k| a.off[adj.spring[k] as usize])
            }
            _ => self.stored_block(l, i, j, cj as i32 - c as i32, rj as i32 - r as i32),
        };
        (0..px * py)
            .into_par_iter()
            .map(|p| {
                let nodes = patch_nodes(level, (p % px, p / px)).map(|n| n.filter(|_| !held(n)));
                let mut m = [[0f32; PATCH_UNKNOWNS]; PATCH_UNKNOWNS];
                for (k, &node) in nodes.iter().enumerate() {
                    let Some(node) = node else {
                        for t in 0..3 {
                            m[3 * k + t][3 * k + t] = 1.0;
                        }
                        continue;
                    };
                    for (b, &other) in nodes.iter().enumerate() {
                        let Some(other) = other else { continue };
                        let columns = block(node, other).to_cols_array_2d();
                        for (c, column) in columns.iter().enumerate() {
                            for (r, &e) in column.iter().enumerate() {
                                m[3 * k + r][3 * b + c] = e;
                            }
                        }
                    }
                }
                // Not positive definite only if A is not: leave the patch alone.
                patch_inverse(&m).unwrap_or([[0.0; PATCH_UNKNOWNS]; PATCH_UNKNOWNS])
            })
            .collect()
    }

    /// One block Gauss-Seidel pass over level `l`'s patches on `z` for
    /// A z = `rhs` (kernels `patch_down`, `patch_up`), the way `sweep` says.
    /// Patches of a colour share no spring (those within two nodes are of
    /// other colours), so each colour's are solved from the same z.
    fn patch_sweep(
        &self,
        a: &BlockMatrix,
        cloth: &Cloth,
        l: usize,
        rhs: &[Vec3],
        z: &mut [Vec3],
        mut sweep: Sweep,
    ) {
        let forward = matches!(sweep, Sweep::Forward(_));
        let level = self.levels[l];
        let (px, py) = patch_grid(level);
        let (px, py) = (px as usize, py as usize);
        let (inverses, colours) = (&self.patch_inverses[l], &self.colours[l]);
        // Each colour in turn over the whole grid would stream the level's
        // operator four times. The same sums, a few patch rows at a time:
        // the colour at place q in the order runs q rows behind the first,
        // so a patch's neighbours of earlier colours are done and those of
        // later ones not yet begun.
        let order: [u8; PATCH_COLOURS] = match forward {
            true => [0, 1, 2, 3],
            false => [3, 2, 1, 0],
        };
        const ROWS: usize = 32;
        // Finished rows are handed on in batches of at least this many
        // nodes: on a small level each hand-over costs more than the cache
        // saves (a 128² cloth's solve took about 5 % longer with one a window).
        const FINISHED_NODES: usize = 16384;
        // Node (c, r)'s residual among the colours a sweep reads.
        let residual = |z: &[Vec3], colour: u8, (c, r): (usize, usize)| {
            let i = r * level.nx as usize + c;
            // A pinned vertex stays at zero (P̃ = S P).
            if l == 0 && cloth.pinned[i] {
                return Vec3::ZERO;
            }
            let node = (i, c as u32, r as u32);
            rhs[i]
                - match forward {
                    // Colour 0 has no colour before it.
                    true if colour == 0 => Vec3::ZERO,
                    true => self.row_where(a, cloth, l, node, |j| colours[j] < colour, |j| z[j]),
                    false => self.row(a, cloth, l, node, |j| z[j]),
                }
        };
        // d = M⁻¹ res, a column at a time (M⁻¹ is symmetric, so its rows
        // are its columns): twelve sums side by side.
        let solve = |(pc, pr): (usize, usize), d: &mut [Vec3; PATCH as usize]| {
            let res: [f32; PATCH_UNKNOWNS] = std::array::from_fn(|u| d[u / 3][u % 3]);
            let mut out = [0f32; PATCH_UNKNOWNS];
            for (column, &r) in inverses[pr * px + pc].iter().zip(&res) {
                for (o, m) in out.iter_mut().zip(column) {
                    *o += m * r;
                }
            }
            *d = std::array::from_fn(|k| Vec3::from_slice(&out[3 * k..3 * k + 3]));
        };
        // A coarse level's forward sweep is the V-cycle's first read of its
        // stencils since the last one, and the finer levels' passes between
        // have evicted them: each patch asks for its colour's next patch in
        // its column while it is computed (BENCHMARKS.md, "Reading ahead").
        let read_ahead = forward && l > 0;
        // A colour's patches of one window, solved a patch row to a task
        // from the same z, then set.
        let mut solved = vec![[Vec3::ZERO; PATCH as usize]; ROWS.div_ceil(2) * px.div_ceil(2)];
        let mut done = 0;
        for start in (0..py + order.len()).step_by(ROWS) {
            for (q, &colour) in order.iter().enumerate() {
                let (cx, cy) = (colour as usize % 2, colour as usize / 2);
                let rows = start.saturating_sub(q)..(start + ROWS).saturating_sub(q).min(py);
                // The colour's patch rows among them, two apart, and its
                // patches in each.
                let first = rows.start + usize::from(rows.start % 2 != cy);
                let per_row = (px - cx).div_ceil(2);
                if first >= rows.end || per_row == 0 {
                    continue;
                }
                let solved = &mut solved[..(rows.end - first).div_ceil(2) * per_row];
                let z_now: &[Vec3] = z;
                solved
                    .par_chunks_mut(per_row)
                    .with_min_len((GRAIN / (16 * PATCH as usize)).div_ceil(per_row))
                    .enumerate()
                    .for_each(|(k, row)| {
                        let pr = first + 2 * k;
                        // The residuals a grid row at a time, in memory order.
                        for (half, r) in [(0, 2 * pr), (2, 2 * pr + 1)] {
                            for (m, d) in row.iter_mut().enumerate() {
                                if read_ahead {
                                    self.read_ahead(l, (cx + 2 * m, pr + 2), half);
                                }
                                for side in 0..2 {
                                    let c = 4 * m + 2 * cx + side;
                                    let inside = c < level.nx as usize && r < level.ny as usize;
                                    d[half + side] = match inside {
                                        true => residual(z_now, colour, (c, r)),
                                        false => Vec3::ZERO,
                                    };
                                }
                            }
                        }
                        for (m, d) in row.iter_mut().enumerate() {
                            solve((cx + 2 * m, pr), d);
                        }
                    });
                for (k, row) in solved.chunks(per_row).enumerate() {
                    for (m, d) in row.iter().enumerate() {
                        let nodes = patch_nodes(level, (cx + 2 * m, first + 2 * k));
                        for (node, d) in nodes.iter().zip(d) {
                            if let Some((i, ..)) = *node {
                                z[i] = if forward { *d } else { z[i] + *d };
                            }
                        }
                    }
                }
            }
            // Every colour has set the patch rows before the last colour's
            // end; a grid row is finished once those within two of it are.
            let set = (start + ROWS).saturating_sub(order.len() - 1).min(py);
            let rows = match set == py {
                true => level.ny as usize,
                false => (2 * set).saturating_sub(2),
            };
            if let Sweep::Forward(finished) = &mut sweep
                && rows > done
                && (set == py || (rows - done) * level.nx as usize >= FINISHED_NODES)
            {
                finished(z, done..rows);
                done = rows;
            }
        }
    }

    /// Prefetches the stencil rows of patch `(pc, pr)` of coarse level `l`
    /// in its grid row `half` (0 or 2, as the sweep's residuals), and with
    /// the first its inverse. Past the grid's edge, nothing.
    fn read_ahead(&self, l: usize, (pc, pr): (usize, usize), half: usize) {
        let level = self.levels[l];
        let (px, py) = patch_grid(level);
        let (r, nx) = (2 * pr + half / 2, level.nx as usize);
        if pr >= py as usize || r >= level.ny as usize || 2 * pc >= nx {
            return;
        }
        let first = r * nx + 2 * pc;
        let last = (first + 1).min(r * nx + nx - 1);
        let w = STORED_STENCIL as usize;
        prefetch(&self.stencils[l - 1][first * w..(last + 1) * w]);
        if half == 0 {
            prefetch(std::slice::from_ref(
                &self.patch_inverses[l][pr * px as usize + pc],
            ));
        }
    }

    /// Rebuilds every level's smoother and coarse operator from this step's
    /// A (kernel `galerkin`).
    pub fn setup(&mut self, a: &BlockMatrix, cloth: &Cloth) {
        // The patch smoother needs no cloth smoother: a pass over A saved.
        if self.smoother == Smoother::BlockJacobi {
            let fine: Vec<Mat3> = (0..cloth.vertex_count())
                .into_par_iter()
                .with_min_len(GRAIN)
                .map(|i| {
                    if cloth.pinned[i] {
                        return Mat3::ZERO;
                    }
                    let adj = &cloth.adjacency;
                    smoother(
                        a.diag[i],
                        adj.range(i).map(|k| a.off[adj.spring[k] as usize]),
                    )
                })
                .collect();
            self.smoothers[0] = fine;
        }
        let last = self.levels.len() - 1;
        let centre = stencil_slot(0, 0);
        for l in 0..last {
            let (from, to) = (self.levels[l], self.levels[l + 1]);
            // Block Jacobi's smoother needs the whole row; a patch-smoothed
            // level (all but the coarsest) only the half that is kept.
            let whole_rows = l + 1 == last || self.smoother == Smoother::BlockJacobi;
            let mut stencil = std::mem::take(&mut self.stencils[l]);
            let mut smoothers = std::mem::take(&mut self.smoothers[l + 1]);
            let rows = stencil
                .par_chunks_mut(STORED_STENCIL as usize)
                .with_min_len(GRAIN / STENCIL as usize)
                .enumerate()
                .filter_map(|(coarse, stored)| {
                    let (cc, rc) = coords(to, coarse);
                    let mut out = [Mat3::ZERO; STENCIL as usize];
                    for node in Self::children(from, (cc, rc)) {
                        let wi = self.fine_weight(cloth, l, node, (cc, rc));
                        if wi == 0.0 {
                            continue;
                        }
                        self.row_entries(a, cloth, l, node, |j, block| {
                            if l == 0 && cloth.pinned[j] {
                                return;
                            }
                            let (c, r) = coords(from, j);
                            for (pr, wr) in parents(r, to.ny) {
                                for (pc, wc) in parents(c, to.nx) {
                                    let w = wi * wr * wc;
                                    let (dx, dy) = (pc as i32 - cc as i32, pr as i32 - rc as i32);
                                    let slot = stencil_slot(dx, dy);
                                    if w != 0.0 && (whole_rows || slot >= centre) {
                                        out[slot] += w * block;
                                    }
                                }
                            }
                        });
                    }
                    stored.copy_from_slice(&out[centre..]);
                    // The whole row gives the smoother; the upper half is kept.
                    whole_rows.then(|| {
                        let off = out.iter().enumerate().filter(|&(k, _)| k != centre);
                        smoother(out[centre], off.map(|(_, block)| *block))
                    })
                });
            smoothers.clear();
            smoothers.par_extend(rows);
            (self.stencils[l], self.smoothers[l + 1]) = (stencil, smoothers);
        }
        self.patch_inverses = match self.smoother {
            Smoother::Patches => (0..self.levels.len() - 1)
                .map(|l| self.patch_inverses_of(a, cloth, l))
                .collect(),
            Smoother::BlockJacobi => Vec::new(),
        };
    }

    /// z = M⁻¹ r, one V-cycle, returning rᵀz. `r` is zero on pinned rows
    /// and so is z. The same operator as the kernels, which with block
    /// Jacobi recompute what this keeps (each level's pre-smoothing) where
    /// they read it, and with patches keep the smoothed vector in place.
    pub fn apply(&mut self, a: &BlockMatrix, cloth: &Cloth, r: &[Vec3], z: &mut [Vec3]) -> f64 {
        let last = self.levels.len() - 1;
        // Down: pre-smooth a = ω D⁻¹ r, then restrict the residual r − A a
        // (kernel `down`).
        for l in 0..last {
            let (mut pre, mut residual) = (take(&mut self.pre[l]), take(&mut self.work[l]));
            let mut out = take(&mut self.rhs[l]);
            let fine_rhs: &[Vec3] = if l == 0 { r } else { &self.rhs[l - 1] };
            let smooth = &self.smoothers[l];
            let (from, to) = (self.levels[l], self.levels[l + 1]);
            match self.smoother {
                // Each patch was solved for the colours before it, the
                // later ones zero: the later colours' part is what is left
                // (none at the last colour's), computed for each grid row
                // once the sweep has set the rows within its reach, while
                // their blocks are still in cache.
                Smoother::Patches => {
                    let colours = &self.colours[l];
                    let mut finished = |pre: &[Vec3], rows| {
                        for_each_node_in(from, rows, &mut residual, |node| {
                            if colours[node.0] as usize == PATCH_COLOURS - 1 {
                                return Vec3::ZERO;
                            }
                            let later = |j: usize| colours[j] > colours[node.0];
                            -self.row_where(a, cloth, l, node, later, |j| pre[j])
                        })
                    };
                    let sweep = Sweep::Forward(&mut finished);
                    self.patch_sweep(a, cloth, l, fine_rhs, &mut pre, sweep);
                }
                Smoother::BlockJacobi => {
                    pre.par_iter_mut()
                        .with_min_len(GRAIN)
                        .enumerate()
                        .for_each(|(i, a_i)| *a_i = smooth[i] * fine_rhs[i]);
                    for_each_node(from, &mut residual, |node| {
                        fine_rhs[node.0] - self.row(a, cloth, l, node, |j| pre[j])
                    });
                }
            }
            for_each_node(to, &mut out, |(_, cc, rc)| {
                Self::children(from, (cc, rc))
                    .map(|node| self.fine_weight(cloth, l, node, (cc, rc)) * residual[node.0])
                    .sum()
            });
            (self.pre[l], self.work[l], self.rhs[l]) = (pre, residual, out);
        }
        // The coarsest level: damped Jacobi sweeps from zero (`coarse`).
        let coarse_rhs = &self.rhs[last - 1];
        let smooth = &self.smoothers[last];
        let mut e: Vec<Vec3> = (0..coarse_rhs.len())
            .map(|i| smooth[i] * coarse_rhs[i])
            .collect();
        let level = self.levels[last];
        for _ in 1..COARSE_SWEEPS {
            e = (0..e.len())
                .map(|i| {
                    let (c, r) = coords(level, i);
                    let row = self.row(a, cloth, last, (i, c, r), |j| e[j]);
                    e[i] + smooth[i] * (coarse_rhs[i] - row)
                })
                .collect();
        }
        self.correction[last - 1] = e;
        // Up: the guess is the pre-smoothing plus the interpolated coarse
        // correction, then one more sweep (kernel `up`).
        for l in (0..last).rev() {
            let mut guess = take(&mut self.work[l]);
            let mut out = match l {
                0 => Vec::new(),
                _ => take(&mut self.correction[l - 1]),
            };
            let fine_rhs: &[Vec3] = if l == 0 { r } else { &self.rhs[l - 1] };
            let (smooth, coarse, pre) = (&self.smoothers[l], &self.correction[l], &self.pre[l]);
            let level = self.levels[l];
            for_each_node(level, &mut guess, |node| {
                pre[node.0] + self.interpolate(cloth, l, node, coarse)
            });
            let target: &mut [Vec3] = match l {
                0 => z,
                _ => &mut out,
            };
            match self.smoother {
                Smoother::Patches => {
                    self.patch_sweep(a, cloth, l, fine_rhs, &mut guess, Sweep::Backward);
                    target.copy_from_slice(&guess);
                }
                Smoother::BlockJacobi => for_each_node(level, target, |node: Node| {
                    let i = node.0;
                    guess[i] + smooth[i] * (fine_rhs[i] - self.row(a, cloth, l, node, |j| guess[j]))
                }),
            }
            if l > 0 {
                self.correction[l - 1] = out;
            }
            self.work[l] = guess;
        }
        r.par_iter()
            .with_min_len(GRAIN)
            .zip(z.par_iter())
            .map(|(r, z)| r.dot(*z) as f64)
            .sum()
    }
}
