//! Iterations to 1e-3 of the default scene's systems under multigrid cycles
//! the product does not run, against the shipped V-cycle: a research probe
//! for the hard steps (BENCHMARKS.md "The hardest steps").
//!
//! Every `EVERY`-th step of the 200, the CPU path's system A v = b is solved
//! again by PCG from the step's own initial guess (the last velocity) with
//! each cycle below. The cycles are built from explicit sparse matrices in
//! f64: Galerkin coarse operators Pᵀ A P on the grid hierarchy of
//! `wgcloth::multigrid` (bilinear P, pinned vertices filtered), the
//! coarsest level (at most 16 nodes) solved exactly. A coarse node carries
//! its translation, or its translation and a linearised rotation θ (a node
//! at x below it moves by Σ w (t + θ × (x − x_C)), smoothed aggregation's
//! rigid modes). The smoothers:
//! - `jacobi`: damped block Jacobi per node, as shipped (ω from
//!   `multigrid::row_weight`);
//! - `patches`: block Gauss-Seidel over 2 × 2-node patches, each solved
//!   exactly, the patches in four colours (patch column and row parity:
//!   patches of a colour share no spring, so a colour's could run in
//!   parallel); forward before the coarse correction, backward after, so
//!   the cycle stays symmetric positive definite without damping.
//!
//! `cargo run --release --example cycle_probe -- GRID EVERY [STIFFNESS]`
//! prints, per sampled step, the shipped solve's iterations and each
//! cycle's, then their means and most.

use std::collections::HashMap;

use glam::{Mat3, Vec3};
use wgcloth::cpu::CpuSim;
use wgcloth::cpu::pcg::BlockMatrix;
use wgcloth::multigrid::{COARSEST_NODES, parents, row_weight};
use wgcloth::scene::Cloth;
use wgcloth::{Config, Error, Scene};

/// Rows of (column, value).
type Sparse = Vec<Vec<(usize, f64)>>;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Smoother {
    Jacobi,
    /// Patches on the finest this many levels, block Jacobi below.
    Patches(usize),
}

/// One cycle to compare: unknowns per coarse node (3 or 6), the smoother,
/// and whether the first coarse level is solved exactly (two grids).
#[derive(Clone, Copy, Debug)]
struct Cycle {
    name: &'static str,
    coarse_dof: usize,
    smoother: Smoother,
    two_grid: bool,
}

const fn probe(name: &'static str, coarse_dof: usize, smoother: Smoother, two_grid: bool) -> Cycle {
    Cycle {
        name,
        coarse_dof,
        smoother,
        two_grid,
    }
}

const ALL: usize = usize::MAX;

const CYCLES: [Cycle; 8] = [
    probe("two grids, translations", 3, Smoother::Jacobi, true),
    probe("two grids, rotations", 6, Smoother::Jacobi, true),
    probe("V, block Jacobi, translations", 3, Smoother::Jacobi, false),
    probe("V, block Jacobi, rotations", 6, Smoother::Jacobi, false),
    probe("V, patches, translations", 3, Smoother::Patches(ALL), false),
    probe("V, patches, rotations", 6, Smoother::Patches(ALL), false),
    probe(
        "V, patches on the cloth only",
        3,
        Smoother::Patches(1),
        false,
    ),
    probe(
        "V, patches on the top two levels",
        3,
        Smoother::Patches(2),
        false,
    ),
];

fn multiply(a: &Sparse, x: &[f64]) -> Vec<f64> {
    a.iter()
        .map(|row| row.iter().map(|&(j, v)| v * x[j]).sum())
        .collect()
}

fn multiply_transposed(a: &Sparse, x: &[f64], columns: usize) -> Vec<f64> {
    let mut y = vec![0.0; columns];
    for (row, &xi) in a.iter().zip(x) {
        for &(j, v) in row {
            y[j] += v * xi;
        }
    }
    y
}

fn minus(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(a, b)| a - b).collect()
}

/// Pᵀ A P.
fn galerkin(a: &Sparse, p: &Sparse, columns: usize) -> Sparse {
    let ap: Vec<HashMap<usize, f64>> = a
        .iter()
        .map(|row| {
            let mut sum = HashMap::new();
            for &(j, v) in row {
                for &(k, w) in &p[j] {
                    *sum.entry(k).or_insert(0.0) += v * w;
                }
            }
            sum
        })
        .collect();
    let mut out: Vec<HashMap<usize, f64>> = vec![HashMap::new(); columns];
    for (row, ap_row) in p.iter().zip(&ap) {
        for &(k, w) in row {
            for (&l, &v) in ap_row {
                *out[k].entry(l).or_insert(0.0) += w * v;
            }
        }
    }
    out.into_iter()
        .map(|sum| {
            let mut row: Vec<(usize, f64)> = sum.into_iter().collect();
            row.sort_by_key(|e| e.0);
            row
        })
        .collect()
}

/// A symmetric positive definite matrix's Cholesky factor, dense, row-major.
struct Cholesky {
    n: usize,
    l: Vec<f64>,
}

impl Cholesky {
    fn of(dense: Vec<f64>, n: usize) -> Cholesky {
        let mut l = dense;
        // A whisker on the diagonal for the unknowns no spring reaches (a
        // rotation about a node's only child).
        let trace: f64 = (0..n).map(|k| l[k * n + k]).sum();
        for k in 0..n {
            l[k * n + k] += 1e-9 * trace / n as f64;
        }
        for j in 0..n {
            let d = (l[j * n + j] - (0..j).map(|k| l[j * n + k].powi(2)).sum::<f64>())
                .max(f64::MIN_POSITIVE)
                .sqrt();
            l[j * n + j] = d;
            for i in j + 1..n {
                let s = l[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
                l[i * n + j] = s / d;
            }
        }
        Cholesky { n, l }
    }

    fn solve(&self, b: &[f64]) -> Vec<f64> {
        let (n, l) = (self.n, &self.l);
        let mut y = b.to_vec();
        for i in 0..n {
            y[i] = (y[i] - (0..i).map(|k| l[i * n + k] * y[k]).sum::<f64>()) / l[i * n + i];
        }
        for i in (0..n).rev() {
            y[i] = (y[i] - (i + 1..n).map(|k| l[k * n + i] * y[k]).sum::<f64>()) / l[i * n + i];
        }
        y
    }

    /// The inverse, dense.
    fn inverse(&self) -> Vec<f64> {
        let n = self.n;
        let mut out = vec![0.0; n * n];
        for c in 0..n {
            let mut e = vec![0.0; n];
            e[c] = 1.0;
            for (r, v) in self.solve(&e).into_iter().enumerate() {
                out[r * n + c] = v;
            }
        }
        out
    }
}

/// A's entries among `unknowns`, dense.
fn restricted(a: &Sparse, unknowns: &[usize]) -> Vec<f64> {
    let k = unknowns.len();
    let mut out = vec![0.0; k * k];
    for (li, &gi) in unknowns.iter().enumerate() {
        for &(j, v) in &a[gi] {
            if let Some(lj) = unknowns.iter().position(|&g| g == j) {
                out[li * k + lj] = v;
            }
        }
    }
    out
}

/// A patch of nodes and the inverse of A among its unknowns.
struct Patch {
    unknowns: Vec<usize>,
    inverse: Vec<f64>,
}

struct Level {
    a: Sparse,
    /// Per node, ω D⁻¹ (block Jacobi); empty with patches.
    jacobi: Vec<Vec<f64>>,
    /// The patches in colour order; empty with block Jacobi.
    patches: Vec<Patch>,
    dof: usize,
    /// Interpolation from the next level; None on the coarsest.
    p: Option<Sparse>,
    exact: Option<Cholesky>,
}

fn frobenius(m: &[f64]) -> f64 {
    m.iter().map(|e| e * e).sum::<f64>().sqrt()
}

/// Per node, ω D⁻¹ with ω from the row's spread, as the product's smoother.
fn block_jacobi(a: &Sparse, dof: usize) -> Vec<Vec<f64>> {
    (0..a.len() / dof)
        .map(|node| {
            let unknowns: Vec<usize> = (node * dof..(node + 1) * dof).collect();
            let inverse = Cholesky::of(restricted(a, &unknowns), dof).inverse();
            let mut blocks: HashMap<usize, Vec<f64>> = HashMap::new();
            for r in 0..dof {
                for &(j, v) in &a[node * dof + r] {
                    if j / dof != node {
                        blocks.entry(j / dof).or_insert(vec![0.0; dof * dof])[r * dof + j % dof] =
                            v;
                    }
                }
            }
            let spread: f64 = blocks
                .values()
                .map(|b| {
                    let scaled: Vec<f64> = (0..dof * dof)
                        .map(|rc| {
                            (0..dof)
                                .map(|k| inverse[rc / dof * dof + k] * b[k * dof + rc % dof])
                                .sum()
                        })
                        .collect();
                    frobenius(&scaled)
                })
                .sum();
            let w = row_weight(spread as f32) as f64;
            inverse.iter().map(|v| v * w).collect()
        })
        .collect()
}

/// The 2 × 2-node patches of an `nx × ny` level, in colour order.
fn patches(a: &Sparse, nx: usize, ny: usize, dof: usize) -> Vec<Patch> {
    let (px, py) = (nx.div_ceil(2), ny.div_ceil(2));
    let mut out: Vec<(usize, Patch)> = Vec::new();
    for pr in 0..py {
        for pc in 0..px {
            let mut unknowns = Vec::new();
            for y in 2 * pr..(2 * pr + 2).min(ny) {
                for x in 2 * pc..(2 * pc + 2).min(nx) {
                    unknowns.extend((y * nx + x) * dof..(y * nx + x + 1) * dof);
                }
            }
            let inverse = Cholesky::of(restricted(a, &unknowns), unknowns.len()).inverse();
            out.push(((pr % 2) * 2 + pc % 2, Patch { unknowns, inverse }));
        }
    }
    out.sort_by_key(|e| e.0);
    out.into_iter().map(|e| e.1).collect()
}

fn skew(v: Vec3) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(0.0, v.z, -v.y),
        Vec3::new(-v.z, 0.0, v.x),
        Vec3::new(v.y, -v.x, 0.0),
    )
}

/// The interpolation from the level below an `nx × ny` one (nodes at
/// `at`, `fine_dof` unknowns each) to it with `coarse_dof` unknowns a
/// node, and the coarse level's grid and node positions.
fn interpolation(
    (nx, ny): (u32, u32),
    at: &[Vec3],
    pinned: Option<&[bool]>,
    fine_dof: usize,
    coarse_dof: usize,
) -> (Sparse, (u32, u32), Vec<Vec3>) {
    let (cx, cy) = (nx.div_ceil(2), ny.div_ceil(2));
    let coarse_at: Vec<Vec3> = (0..cy)
        .flat_map(|r| (0..cx).map(move |c| (c, r)))
        .map(|(c, r)| at[(2 * r * nx + 2 * c) as usize])
        .collect();
    let mut p: Sparse = vec![Vec::new(); (nx * ny) as usize * fine_dof];
    for i in 0..(nx * ny) as usize {
        if pinned.is_some_and(|p| p[i]) {
            continue;
        }
        let (c, r) = (i as u32 % nx, i as u32 / nx);
        for (pr, wr) in parents(r, cy) {
            for (pc, wc) in parents(c, cx) {
                let w = (wr * wc) as f64;
                if w == 0.0 {
                    continue;
                }
                let node = (pr * cx + pc) as usize;
                for t in 0..3 {
                    p[i * fine_dof + t].push((node * coarse_dof + t, w));
                }
                if coarse_dof == 6 {
                    // t += θ × (x − x_C) = [−(x − x_C)]× θ; a fine rotation
                    // is its parents' weighted.
                    let m = skew(coarse_at[node] - at[i]);
                    for t in 0..3 {
                        for q in 0..3 {
                            p[i * fine_dof + t].push((node * 6 + 3 + q, w * m.col(q)[t] as f64));
                        }
                    }
                    if fine_dof == 6 {
                        for q in 0..3 {
                            p[i * 6 + 3 + q].push((node * 6 + 3 + q, w));
                        }
                    }
                }
            }
        }
    }
    (p, (cx, cy), coarse_at)
}

fn hierarchy(a: &BlockMatrix, cloth: &Cloth, x: &[Vec3], cycle: Cycle) -> Vec<Level> {
    let n = cloth.vertex_count();
    let adj = &cloth.adjacency;
    // The cloth's A with pinned rows and columns filtered (identity rows).
    let mut fine: Sparse = vec![Vec::new(); 3 * n];
    for i in 0..n {
        if cloth.pinned[i] {
            for t in 0..3 {
                fine[3 * i + t].push((3 * i + t, 1.0));
            }
            continue;
        }
        let blocks = std::iter::once((i, a.diag[i])).chain(
            adj.range(i)
                .map(|k| (adj.other[k] as usize, a.off[adj.spring[k] as usize])),
        );
        for (j, block) in blocks.filter(|&(j, _)| !cloth.pinned[j]) {
            for r in 0..3 {
                for c in 0..3 {
                    fine[3 * i + r].push((3 * j + c, block.columns()[c][r] as f64));
                }
            }
        }
    }
    let (mut grid, mut at, mut dof, mut op) = ((cloth.nx, cloth.ny), x.to_vec(), 3, fine);
    let mut levels = Vec::new();
    loop {
        let coarsest = grid.0 * grid.1 <= COARSEST_NODES || (cycle.two_grid && !levels.is_empty());
        if coarsest {
            let m = op.len();
            let exact = Some(Cholesky::of(
                restricted(&op, &(0..m).collect::<Vec<_>>()),
                m,
            ));
            levels.push(Level {
                a: op,
                jacobi: Vec::new(),
                patches: Vec::new(),
                dof,
                p: None,
                exact,
            });
            return levels;
        }
        let pinned = levels.is_empty().then_some(&cloth.pinned[..]);
        let (p, coarse_grid, coarse_at) = interpolation(grid, &at, pinned, dof, cycle.coarse_dof);
        let coarse = galerkin(
            &op,
            &p,
            (coarse_grid.0 * coarse_grid.1) as usize * cycle.coarse_dof,
        );
        let (jacobi, patches) = match cycle.smoother {
            Smoother::Patches(top) if levels.len() < top => (
                Vec::new(),
                patches(&op, grid.0 as usize, grid.1 as usize, dof),
            ),
            _ => (block_jacobi(&op, dof), Vec::new()),
        };
        levels.push(Level {
            a: op,
            jacobi,
            patches,
            dof,
            p: Some(p),
            exact: None,
        });
        (grid, at, dof, op) = (coarse_grid, coarse_at, cycle.coarse_dof, coarse);
    }
}

/// One smoothing pass on `z` for A z = r: block Jacobi, or the patches
/// forward (`reverse` false) or backward.
fn smooth(level: &Level, r: &[f64], z: &mut [f64], reverse: bool) {
    if level.patches.is_empty() {
        let res = minus(r, &multiply(&level.a, z));
        let dof = level.dof;
        for (node, block) in level.jacobi.iter().enumerate() {
            for i in 0..dof {
                z[node * dof + i] += (0..dof)
                    .map(|j| block[i * dof + j] * res[node * dof + j])
                    .sum::<f64>();
            }
        }
        return;
    }
    let mut order: Vec<&Patch> = level.patches.iter().collect();
    if reverse {
        order.reverse();
    }
    for patch in order {
        let k = patch.unknowns.len();
        let res: Vec<f64> = patch
            .unknowns
            .iter()
            .map(|&g| r[g] - level.a[g].iter().map(|&(j, v)| v * z[j]).sum::<f64>())
            .collect();
        for (li, &g) in patch.unknowns.iter().enumerate() {
            z[g] += (0..k)
                .map(|lj| patch.inverse[li * k + lj] * res[lj])
                .sum::<f64>();
        }
    }
}

/// z ≈ A⁻¹ r by one symmetric V(1,1)-cycle from level `l`.
fn cycle(levels: &[Level], l: usize, r: &[f64]) -> Vec<f64> {
    let level = &levels[l];
    let (Some(p), None) = (&level.p, &level.exact) else {
        return level
            .exact
            .as_ref()
            .expect("the coarsest is solved exactly")
            .solve(r);
    };
    let mut z = vec![0.0; r.len()];
    smooth(level, r, &mut z, false);
    let residual = minus(r, &multiply(&level.a, &z));
    let coarse = multiply_transposed(p, &residual, levels[l + 1].a.len());
    let correction = multiply(p, &cycle(levels, l + 1, &coarse));
    z.iter_mut().zip(correction).for_each(|(z, c)| *z += c);
    smooth(level, r, &mut z, true);
    z
}

/// PCG iterations to |S r| ≤ 1e-3 |S b| from `x0`, or None on a breakdown
/// (or where left out).
fn iterations(
    a: &BlockMatrix,
    cloth: &Cloth,
    b: &[Vec3],
    x0: &[Vec3],
    levels: &[Level],
) -> Option<u32> {
    let free: Vec<f64> = cloth
        .pinned
        .iter()
        .map(|&p| if p { 0.0 } else { 1.0 })
        .collect();
    let flat = |v: &[Vec3]| -> Vec<f64> {
        v.iter()
            .zip(&free)
            .flat_map(|(v, f)| [v.x as f64 * f, v.y as f64 * f, v.z as f64 * f])
            .collect()
    };
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(a, b)| a * b).sum::<f64>();
    let a_times = |v: &[f64]| multiply(&levels[0].a, v);
    let mut ax0 = vec![Vec3::ZERO; x0.len()];
    a.multiply(&cloth.adjacency, x0, &mut ax0);
    let mut r = minus(&flat(b), &flat(&ax0));
    let b = flat(b);
    let mut z = cycle(levels, 0, &r);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    for k in 0..5000 {
        if dot(&r, &r) <= 1e-6 * dot(&b, &b) {
            return Some(k);
        }
        let q = a_times(&p);
        let pq = dot(&p, &q);
        if rz <= 0.0 || pq <= 0.0 {
            return None;
        }
        let alpha = rz / pq;
        r.iter_mut().zip(&q).for_each(|(r, q)| *r -= alpha * q);
        z = cycle(levels, 0, &r);
        let next = dot(&r, &z);
        p.iter_mut()
            .zip(&z)
            .for_each(|(p, z)| *p = z + next / rz * *p);
        rz = next;
    }
    None
}

fn main() -> wgcloth::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let number = |k: usize, what: &str| -> wgcloth::Result<f64> {
        args.get(k)
            .and_then(|a| a.parse().ok())
            .ok_or_else(|| Error::config(what, "usage: cycle_probe GRID EVERY [STIFFNESS]"))
    };
    let (grid, every) = (number(0, "GRID")? as u32, number(1, "EVERY")? as u64);
    let mut config = Config::default();
    config.cloth.grid = [grid, grid];
    if args.len() > 2 {
        config.cloth.stiffness = number(2, "STIFFNESS")? as f32;
    }
    let mut sim = CpuSim::new(Scene::new(&config)?);
    let mut seen: Vec<Vec<Option<u32>>> = Vec::new();
    for step in 0..config.solver.steps {
        let (x0, v0) = (sim.state.x.clone(), sim.state.v.clone());
        let shipped = sim.step().pcg.iterations;
        if step % every.max(1) != 0 {
            continue;
        }
        let cloth = &sim.scene.cloth;
        let (a, b) = sim.system();
        let mut row = vec![Some(shipped)];
        for c in CYCLES {
            // A two-grid cycle's dense coarse factor is cubic in its
            // unknowns: left out past 32².
            let skip = c.two_grid && grid > 32;
            row.push(match skip {
                true => None,
                false => iterations(a, cloth, b, &v0, &hierarchy(a, cloth, &x0, c)),
            });
        }
        let show: Vec<String> = row
            .iter()
            .map(|k| k.map_or("–".into(), |k| k.to_string()))
            .collect();
        println!("step {step:3}: {}", show.join(" "));
        seen.push(row);
    }
    let names = std::iter::once("shipped V-cycle").chain(CYCLES.iter().map(|c| c.name));
    for (k, name) in names.enumerate() {
        let counts: Vec<u32> = seen.iter().filter_map(|row| row[k]).collect();
        let mean = counts.iter().sum::<u32>() as f64 / counts.len().max(1) as f64;
        let most = counts.iter().max().copied().unwrap_or(0);
        let missing = seen.len() - counts.len();
        println!("{name:32} mean {mean:5.1}  most {most:3}  breakdowns or left out {missing}");
    }
    Ok(())
}
