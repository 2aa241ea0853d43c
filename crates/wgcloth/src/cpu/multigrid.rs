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

use glam::{Mat3, Vec3, Vec4};
use rayon::prelude::*;

use crate::config::Preconditioner;
use crate::config::Smoother;
use crate::cpu::assemble::BlockMatrix;
use crate::cpu::precondition::Precondition;
use crate::math::{RowSum, Sym3};
use crate::multigrid::{
    COARSE_SWEEPS, Level, PATCH, PATCH_COLOURS, PATCH_UNKNOWNS, PatchMatrix, STENCIL,
    STORED_STENCIL, levels, node_colour, parents, patch_grid, patch_inverse, row_weight,
    stencil_slot, stored_at, weight,
};
use crate::parallel::GRAIN;
use crate::scene::Cloth;

/// The hierarchy's operators and work vectors, kept between steps.
#[derive(Clone, Debug)]
pub struct Multigrid {
    levels: Vec<Level>,
    /// Per coarse level (index l − 1): [`STORED_STENCIL`] blocks per node,
    /// the upper half of its stencil (`multigrid::stored_at`).
    stencils: Vec<Vec<Sym3>>,
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
    /// Per cloth node, the first of the springs it starts, and the spring
    /// count last: `Cloth::grid` lists each node's springs together, so
    /// those of a run of nodes are one run of A's blocks, which the
    /// cloth's read-ahead asks for at once.
    spring_starts: Vec<u32>,
}

impl Precondition for Multigrid {
    fn fits(&self, cloth: &Cloth, kind: Preconditioner, smoother: Smoother) -> bool {
        kind == Preconditioner::Multigrid
            && self.levels[0] == Level::of(cloth)
            && self.smoother == smoother
    }

    fn setup(&mut self, a: &BlockMatrix, cloth: &Cloth) {
        Multigrid::setup(self, a, cloth);
    }

    fn apply(&mut self, a: &BlockMatrix, cloth: &Cloth, r: &[Vec3], z: &mut [Vec3]) -> f64 {
        Multigrid::apply(self, a, cloth, r, z)
    }
}

/// Which way a patch sweep goes.
enum Sweep<'a> {
    /// Colours 0 to 3 from zero, each patch's residual from the colours
    /// before it and its nodes set; and what is left of each node's
    /// residual, the colours after its own, into the slice, computed for
    /// each grid row once the rows within its reach are set, while their
    /// blocks are still in cache.
    Forward(&'a mut [Vec3]),
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
fn smoother(d: Sym3, off: impl Iterator<Item = Sym3>) -> Mat3 {
    let d = d.to_mat3();
    let det = d.determinant();
    if !(det.is_finite() && det.abs() > f32::MIN_POSITIVE) {
        return Mat3::ZERO;
    }
    let inverse = d.inverse();
    let spread = off.map(|block| frobenius(inverse * block.to_mat3())).sum();
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
    let nx = level.nx as usize;
    out.par_chunks_mut(nx)
        .with_min_len(GRAIN.div_ceil(nx))
        .enumerate()
        .for_each(|(r, row)| {
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
                .map(|l| vec![Sym3::ZERO; l.nodes() * STORED_STENCIL as usize])
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
            spring_starts: {
                let mut starts = vec![0u32; cloth.vertex_count() + 1];
                for &[i, _] in &cloth.springs {
                    starts[i as usize + 1] += 1;
                }
                for i in 0..cloth.vertex_count() {
                    starts[i + 1] += starts[i];
                }
                starts
            },
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
    pub fn coarse_block(&self, l: usize, i: usize, j: usize) -> Sym3 {
        let level = self.levels[l];
        let ((ci, ri), (cj, rj)) = (coords(level, i), coords(level, j));
        let (dx, dy) = (cj as i32 - ci as i32, rj as i32 - ri as i32);
        if dx.abs() > 2 || dy.abs() > 2 {
            return Sym3::ZERO;
        }
        self.stored_block(l, i, j, dx, dy)
    }

    /// Block (i, j) of coarse level `l`, j at (dx, dy) from i, from where
    /// the upper half of the stencils keeps it.
    fn stored_block(&self, l: usize, i: usize, j: usize, dx: i32, dy: i32) -> Sym3 {
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
        mut f: impl FnMut(usize, Sym3),
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
            Some((i, ..)) => (l == 0 && cloth.pinned[i]) || diagonal(i) == Sym3::ZERO,
        };
        // Block (i, j) of the operator, j in i's patch.
        let block = |(i, c, r): Node, (j, cj, rj): Node| match l {
            0 if i == j => a.diag[i],
            0 => {
                let adj = &cloth.adjacency;
                let k = adj.range(i).find(|&k| adj.other[k] as usize == j);
                k.map_or(Sym3::ZERO, |k| a.off[adj.spring[k] as usize])
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
                        let columns = block(node, other).columns();
                        for (c, column) in columns.iter().enumerate() {
                            for (r, &e) in column.to_array().iter().enumerate() {
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
    /// other colours), so each colour's are solved from the same z, in any
    /// order.
    ///
    /// A patch row holds two colours and reaches only the rows beside it,
    /// so the sweep takes a patch row at a time, both its colours, the
    /// rows in an order the colours allow ([`Pass::rows`]). Each patch is
    /// solved from the same z as when each colour took its turn over the
    /// grid, but a row's blocks are read while the row before them is still
    /// in cache, where each colour read two nodes of four in half the rows.
    ///
    /// The rows are cut into bands, a band to a task, each on a copy of its
    /// rows and those beside it as they stand before the sweep. A band
    /// begins at a row of the sweep's first two colours, which reads
    /// nothing above it that the sweep has set. Its last row needs the next
    /// band's first, which reads only rows as they stand before the sweep
    /// (its own, and backward the rows beside it): the band solves that row
    /// too, in its copy, from the same values as the next band. So no band
    /// waits for another; only the residual of each band's first row, which
    /// reaches the row above, is computed after the bands.
    fn patch_sweep(
        &self,
        a: &BlockMatrix,
        cloth: &Cloth,
        l: usize,
        rhs: &[Vec3],
        z: &mut [Vec3],
        mut sweep: Sweep,
    ) {
        let level = self.levels[l];
        let (nx, ny) = (level.nx as usize, level.ny as usize);
        let (px, py) = patch_grid(level);
        let (px, py) = (px as usize, py as usize);
        let pass = Pass {
            multigrid: self,
            a,
            cloth,
            l,
            level,
            px,
            py,
            rhs,
            forward: matches!(sweep, Sweep::Forward(_)),
        };
        // Where patch row pr's nodes begin.
        let at = |pr: usize| (2 * pr).min(ny) * nx;
        let starts = band_starts(pass);
        let ends = starts[1..].iter().copied().chain([py]);
        let bands: Vec<Range<usize>> = starts.iter().zip(ends).map(|(&s, e)| s..e).collect();
        let mut residual = match &mut sweep {
            Sweep::Forward(residual) => Some(&mut **residual),
            Sweep::Backward => None,
        };
        let band_residual = parts(
            residual.as_deref_mut(),
            bands.iter().map(|band| at(band.end) - at(band.start)),
        );
        let before: &[Vec3] = z;
        let solved: Vec<BandZ> = bands
            .par_iter()
            .zip(band_residual)
            .map(|(band, mut residual)| {
                // The band's rows, the row above and the two below as they
                // stand before the sweep.
                let copied = band.start.saturating_sub(1)..(band.end + 2).min(py);
                let first = at(copied.start);
                let mut z = BandZ {
                    first,
                    z: before[first..at(copied.end)].to_vec(),
                };
                // Its rows and the next band's first, which its last needs.
                let rows = band.start..(band.end + 1).min(py);
                // Its residual rows: those whose reach is set here.
                let reach = match band.start {
                    0 => 0,
                    s => 2 * s + 2,
                }..match band.end < py {
                    true => 2 * band.end,
                    false => ny,
                };
                let mut done = reach.start;
                pass.rows(&mut z, rows, |z, set| {
                    let Some(residual) = &mut residual else {
                        return;
                    };
                    let end = match set == py {
                        true => ny,
                        false => 2 * set - 2,
                    };
                    let end = end.min(reach.end);
                    if end > done {
                        let out = &mut residual[(done - 2 * band.start) * nx..];
                        pass.residual_rows(|j| z.get(j), done..end, out);
                        done = end;
                    }
                });
                z
            })
            .collect();
        for (band, solved) in bands.iter().zip(&solved) {
            let own = at(band.start) - solved.first..at(band.end) - solved.first;
            z[at(band.start)..at(band.end)].copy_from_slice(&solved.z[own]);
        }
        // The residual rows of each band's first row, which reach the row
        // above, set in the band before.
        if let Some(residual) = residual {
            for band in &bands[1..] {
                let rows = 2 * band.start..(2 * band.start + 2).min(ny);
                pass.residual_rows(|j| z[j], rows.clone(), &mut residual[rows.start * nx..]);
            }
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
                    let mut out = [Sym3::ZERO; STENCIL as usize];
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
                Smoother::Patches => {
                    let sweep = Sweep::Forward(&mut residual);
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

/// What a patch sweep of one level reads, and which way it goes.
#[derive(Clone, Copy)]
struct Pass<'a> {
    multigrid: &'a Multigrid,
    a: &'a BlockMatrix,
    cloth: &'a Cloth,
    l: usize,
    /// Level `l`, and its patches per row and column ([`patch_grid`]).
    level: Level,
    px: usize,
    py: usize,
    rhs: &'a [Vec3],
    forward: bool,
}

impl Pass<'_> {
    /// The parity of the patch rows a sweep takes first, and within a row
    /// of the patch columns: even forward (colours 0 and 1 before 2 and 3,
    /// 0 before 1), odd backward (3 and 2 before 1 and 0, 3 before 2).
    fn first(self) -> usize {
        usize::from(!self.forward)
    }

    /// Solves patch rows `rows` in an order the colours allow: each row of
    /// the sweep's first two colours, then the row before it, both of whose
    /// neighbours are now set; a last row of the other two at the end, the
    /// row after it set by then or past the grid. Calls `set(z, k)` each
    /// time rows `rows.start..k` are all set.
    fn rows(self, z: &mut BandZ, rows: Range<usize>, mut set: impl FnMut(&BandZ, usize)) {
        let first = self.first();
        let mut residuals = Vec::new();
        for pr in rows.clone().filter(|pr| pr % 2 == first) {
            let before = (pr > rows.start).then(|| pr - 1);
            let next = before.unwrap_or(pr + 2);
            self.patch_row(z, (pr, next), &mut residuals);
            if let Some(before) = before {
                self.patch_row(z, (before, pr + 2), &mut residuals);
            }
            set(z, pr + 1);
        }
        let last = rows.end.checked_sub(1);
        if let Some(pr) = last.filter(|&pr| pr >= rows.start && pr % 2 != first) {
            self.patch_row(z, (pr, rows.end), &mut residuals);
            set(z, rows.end);
        }
    }

    /// Solves patch row `pr`: its first colour's patches, their residuals
    /// a grid row at a time into `residuals`, then its second colour's;
    /// meanwhile reads ahead for row `next`, the one solved after it.
    fn patch_row(
        self,
        z: &mut BandZ,
        (pr, next): (usize, usize),
        residuals: &mut Vec<[Vec3; PATCH as usize]>,
    ) {
        let (nx, ny, px) = (self.level.nx as usize, self.level.ny as usize, self.px);
        let first = self.first();
        for cx in [first, 1 - first] {
            let colour = (cx + 2 * (pr % 2)) as u8;
            residuals.clear();
            residuals.resize((px - cx).div_ceil(2), [Vec3::ZERO; PATCH as usize]);
            for (half, r) in [(0, 2 * pr), (2, 2 * pr + 1)] {
                if r >= ny {
                    continue;
                }
                for (m, d) in residuals.iter_mut().enumerate() {
                    if cx == first && half == 0 {
                        self.read_ahead((2 * m, next));
                    }
                    for side in 0..2 {
                        let c = 4 * m + 2 * cx + side;
                        if c < nx {
                            let node = (r * nx + c, c as u32, r as u32);
                            d[half + side] = self.residual(z, colour, node);
                        }
                    }
                }
            }
            for (m, residual) in residuals.iter().enumerate() {
                self.patch(z, (cx + 2 * m, pr), residual);
            }
        }
    }

    /// Solves patch `(pc, pr)` from its residual: d = M⁻¹ res, z = d
    /// forward and z + d backward.
    fn patch(self, z: &mut BandZ, (pc, pr): (usize, usize), residual: &[Vec3; PATCH as usize]) {
        let nodes = patch_nodes(self.level, (pc, pr));
        // M⁻¹ is symmetric, so its rows are its columns: twelve sums side
        // by side, four to a register (the compiler, left to itself, split
        // them into pairs and gathered the rest).
        let inverse = &self.multigrid.patch_inverses[self.l][pr * self.px + pc];
        let res: [f32; PATCH_UNKNOWNS] = std::array::from_fn(|u| residual[u / 3][u % 3]);
        let mut d = [Vec4::ZERO; PATCH_UNKNOWNS / 4];
        for (column, &r) in inverse.iter().zip(&res) {
            for (o, m) in d.iter_mut().zip(column.chunks_exact(4)) {
                *o += Vec4::from_slice(m) * r;
            }
        }
        let d: [f32; PATCH_UNKNOWNS] = std::array::from_fn(|u| d[u / 4][u % 4]);
        for (k, node) in nodes.iter().enumerate() {
            if let Some((i, ..)) = *node {
                let d = Vec3::from_slice(&d[3 * k..3 * k + 3]);
                z.set(i, if self.forward { d } else { z.get(i) + d });
            }
        }
    }

    /// Asks the cache for what solving patches `pc` and `pc + 1` of patch
    /// row `pr` reads first from memory: their inverses, and their nodes'
    /// stencil rows on a coarse level or, on a large cloth, their diagonal
    /// blocks, adjacency and the blocks of the springs they start. A hint,
    /// which changes no result. The rows of a sweep follow each other two
    /// and three rows apart, which the hardware's prefetcher does not
    /// follow, and a coarse level's forward sweep is the V-cycle's first
    /// read of its stencils since the finer levels' passes evicted them.
    // Out of line: inlined into the row loop, the 512² solve took 2 % to
    // 5 % longer.
    #[inline(never)]
    fn read_ahead(self, (pc, pr): (usize, usize)) {
        let (multigrid, l, level) = (self.multigrid, self.l, self.level);
        let (nx, ny, px) = (level.nx as usize, level.ny as usize, self.px);
        if pr >= self.py || pc >= px {
            return;
        }
        prefetch(&multigrid.patch_inverses[l][pr * px + pc..pr * px + (pc + 2).min(px)]);
        for r in (2 * pr..2 * pr + 2).filter(|&r| r < ny) {
            let nodes = r * nx + 2 * pc..r * nx + (2 * pc + 4).min(nx);
            match l {
                0 if level.nodes() >= CLOTH_READ_AHEAD => {
                    let (a, adj) = (self.a, &self.cloth.adjacency);
                    prefetch(&a.diag[nodes.clone()]);
                    let entries =
                        adj.offsets[nodes.start] as usize..adj.offsets[nodes.end] as usize;
                    prefetch(&adj.other[entries.clone()]);
                    prefetch(&adj.spring[entries]);
                    let starts = &multigrid.spring_starts;
                    prefetch(&a.off[starts[nodes.start] as usize..starts[nodes.end] as usize]);
                }
                0 => {}
                _ => {
                    let w = STORED_STENCIL as usize;
                    prefetch(&multigrid.stencils[l - 1][nodes.start * w..nodes.end * w]);
                }
            }
        }
    }

    /// Node `(i, c, r)`'s residual among the colours the sweep reads: all
    /// backward, those before `colour` forward (the rest are still zero,
    /// whatever z holds there).
    fn residual(self, z: &BandZ, colour: u8, node: Node) -> Vec3 {
        let (multigrid, l) = (self.multigrid, self.l);
        // A pinned vertex stays at zero (P̃ = S P).
        if l == 0 && self.cloth.pinned[node.0] {
            return Vec3::ZERO;
        }
        let colours = &multigrid.colours[l];
        let (a, cloth) = (self.a, self.cloth);
        self.rhs[node.0]
            - match self.forward {
                // Colour 0 has no colour before it.
                true if colour == 0 => Vec3::ZERO,
                true => {
                    multigrid.row_where(a, cloth, l, node, |j| colours[j] < colour, |j| z.get(j))
                }
                false => multigrid.row(a, cloth, l, node, |j| z.get(j)),
            }
    }

    /// What a forward sweep leaves of each node's residual at grid rows
    /// `rows`: minus its row over the colours after its own (none after
    /// the last), into `out`, which begins at the first row's first node.
    fn residual_rows(self, z: impl Fn(usize) -> Vec3, rows: Range<usize>, out: &mut [Vec3]) {
        let (multigrid, l) = (self.multigrid, self.l);
        let nx = self.level.nx as usize;
        let colours = &multigrid.colours[l];
        let rows_first = rows.start * nx;
        for r in rows {
            for c in 0..nx {
                let i = r * nx + c;
                out[i - rows_first] = match colours[i] as usize {
                    colour if colour == PATCH_COLOURS - 1 => Vec3::ZERO,
                    _ => -multigrid.row_where(
                        self.a,
                        self.cloth,
                        l,
                        (i, c as u32, r as u32),
                        |j| colours[j] > colours[i],
                        &z,
                    ),
                };
            }
        }
    }
}

/// A band's copy of z in a patch sweep, from node `first` on.
struct BandZ {
    first: usize,
    z: Vec<Vec3>,
}

impl BandZ {
    #[inline(always)]
    fn get(&self, j: usize) -> Vec3 {
        self.z[j - self.first]
    }

    #[inline(always)]
    fn set(&mut self, i: usize, value: Vec3) {
        self.z[i - self.first] = value;
    }
}

/// The fewest nodes of a cloth whose sweeps read ahead its own blocks
/// ([`Pass::read_ahead`]). At 128² (16,384 nodes, whose operator and
/// inverses stay in a 32 MiB cache) it made the solve 3 % slower, even
/// with the springs found as one run (15 % when it walked each node's
/// adjacency for them).
const CLOTH_READ_AHEAD: usize = 1 << 15;

/// The fewest patch rows a sweep's band holds, so that the row a band
/// solves again for the one before it stays a small share of its work.
const MIN_BAND: usize = 8;

/// The first patch row of each band of `pass`'s sweep, a band to a
/// thread but none under [`MIN_BAND`] rows or [`GRAIN`] nodes; each but
/// the first starts at a row of the sweep's first two colours
/// ([`Pass::first`]).
fn band_starts(pass: Pass) -> Vec<usize> {
    let rows = MIN_BAND.max(GRAIN.div_ceil(2 * pass.level.nx as usize));
    let bands = rayon::current_num_threads().min(pass.py / rows).max(1);
    (0..bands)
        .map(|k| {
            let start = k * pass.py / bands;
            start + usize::from(k > 0 && start % 2 != pass.first())
        })
        .collect()
}

/// `v` cut into consecutive parts of `lengths`, or a None for each where
/// there is no `v`.
fn parts<T>(
    mut v: Option<&mut [T]>,
    lengths: impl Iterator<Item = usize>,
) -> Vec<Option<&mut [T]>> {
    lengths
        .map(|length| {
            let (part, rest) = v.take()?.split_at_mut(length);
            v = Some(rest);
            Some(part)
        })
        .collect()
}
