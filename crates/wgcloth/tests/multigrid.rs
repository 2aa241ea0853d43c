//! The multigrid preconditioner: its coarse operators are the Galerkin
//! products Pᵀ A P of dense matrices built independently, the V-cycle is a
//! symmetric positive definite operator (what CG needs of a
//! preconditioner), and the iterations to a tolerance stay nearly flat as
//! the grid grows where Jacobi's grow with its side.

mod common;

use common::Rng;
use glam::{Mat3, Vec3};
use wgcloth::config::{Preconditioner, SceneKind, Smoother};
use wgcloth::cpu::CpuSim;
use wgcloth::cpu::multigrid::Multigrid;
use wgcloth::cpu::pcg::BlockMatrix;
use wgcloth::math::Sym3;
use wgcloth::multigrid::{Level, weight};
use wgcloth::scene::Cloth;
use wgcloth::{Config, Scene};

/// A random symmetric positive definite system in the cloth's sparsity.
fn random_system(cloth: &Cloth, rng: &mut Rng) -> BlockMatrix {
    let mut a = BlockMatrix::new(cloth.vertex_count(), cloth.springs.len());
    let mut sym = |scale: f32| {
        let m = Mat3::from_cols(
            rng.vec3(-1.0, 1.0),
            rng.vec3(-1.0, 1.0),
            rng.vec3(-1.0, 1.0),
        );
        (0.5 * scale) * Sym3::from_mat3(m + m.transpose())
    };
    for o in &mut a.off {
        *o = sym(1.0);
    }
    for d in &mut a.diag {
        *d = sym(1.0) + Sym3::from_diagonal(Vec3::splat(40.0));
    }
    a
}

/// P[i][I]: the interpolation weight of coarse node I at fine node i,
/// zero at a filtered (pinned) fine node.
fn interpolation(fine: Level, coarse: Level, filtered: &dyn Fn(usize) -> bool) -> Vec<Vec<f32>> {
    (0..fine.nodes())
        .map(|i| {
            let (c, r) = ((i % fine.nx as usize) as u32, (i / fine.nx as usize) as u32);
            (0..coarse.nodes())
                .map(|k| {
                    let (cc, rc) = (
                        (k % coarse.nx as usize) as u32,
                        (k / coarse.nx as usize) as u32,
                    );
                    if filtered(i) {
                        0.0
                    } else {
                        weight(c, cc, coarse.nx) * weight(r, rc, coarse.ny)
                    }
                })
                .collect()
        })
        .collect()
}

/// Checks the stencils of `coarse` against Σ_ij P_iI A_ij P_jJ over the
/// dense fine blocks `fine_block(i, j)`, and that nothing lies outside the
/// 5 × 5 stencil.
fn check_galerkin(
    fine: Level,
    coarse: Level,
    fine_block: &dyn Fn(usize, usize) -> Sym3,
    filtered: &dyn Fn(usize) -> bool,
    coarse_block: &dyn Fn(usize, usize) -> Sym3,
) {
    let p = interpolation(fine, coarse, filtered);
    let blocks: Vec<Vec<Mat3>> = (0..fine.nodes())
        .map(|i| {
            (0..fine.nodes())
                .map(|j| fine_block(i, j).to_mat3())
                .collect()
        })
        .collect();
    for big_i in 0..coarse.nodes() {
        for big_j in 0..coarse.nodes() {
            let mut expected = Mat3::ZERO;
            for (i, row) in blocks.iter().enumerate() {
                for (j, block) in row.iter().enumerate() {
                    expected += (p[i][big_i] * p[j][big_j]) * *block;
                }
            }
            let got = coarse_block(big_i, big_j).to_mat3();
            let scale = expected
                .abs()
                .to_cols_array()
                .iter()
                .fold(1.0f32, |m, v| m.max(*v));
            let diff = (got - expected).abs().to_cols_array();
            let worst = diff.iter().fold(0.0f32, |m, v| m.max(*v));
            assert!(
                worst <= 1e-5 * scale,
                "coarse ({big_i}, {big_j}): stencil {got:?}, Pᵀ A P {expected:?}"
            );
        }
    }
}

#[test]
fn coarse_operators_are_galerkin_products_with_pins_filtered() {
    let mut rng = Rng(5);
    let cloth = Cloth::grid(9, 9, 1.0, 1.0, &[0, 8, 40], |u, v| Vec3::new(u, -v, 0.0));
    let a = random_system(&cloth, &mut rng);
    let mut mg = Multigrid::new(&cloth, Smoother::default());
    mg.setup(&a, &cloth);
    let levels = mg.levels().to_vec();
    assert_eq!(levels.len(), 3, "9×9 → 5×5 → 3×3");

    // Level 1 from the cloth's blocks, pinned vertices filtered out.
    let fine_block = |i: usize, j: usize| {
        if i == j {
            return a.diag[i];
        }
        let adj = &cloth.adjacency;
        adj.range(i)
            .find(|&k| adj.other[k] as usize == j)
            .map_or(Sym3::ZERO, |k| a.off[adj.spring[k] as usize])
    };
    let pinned = |i: usize| cloth.pinned[i];
    let mg = &mg;
    let level = |l: usize| move |i: usize, j: usize| mg.coarse_block(l, i, j);
    check_galerkin(levels[0], levels[1], &fine_block, &pinned, &level(1));

    // Level 2 from level 1's stencils.
    check_galerkin(levels[1], levels[2], &level(1), &|_| false, &level(2));
}

/// uᵀ M⁻¹ v = vᵀ M⁻¹ u and uᵀ M⁻¹ u > 0 for `b` and random u, v, all
/// free of the pins, with each smoother.
fn check_spd(a: &BlockMatrix, cloth: &Cloth, b: &[Vec3], rng: &mut Rng) {
    for smoother in Smoother::ALL {
        check_spd_with(a, cloth, b, rng, smoother);
    }
}

fn check_spd_with(a: &BlockMatrix, cloth: &Cloth, b: &[Vec3], rng: &mut Rng, smoother: Smoother) {
    let mut mg = Multigrid::new(cloth, smoother);
    mg.setup(a, cloth);
    let n = cloth.vertex_count();
    let free = |i: usize, v: Vec3| if cloth.pinned[i] { Vec3::ZERO } else { v };
    let mut vectors: Vec<Vec<Vec3>> = vec![(0..n).map(|i| free(i, b[i])).collect()];
    for _ in 0..4 {
        vectors.push((0..n).map(|i| free(i, rng.vec3(-1.0, 1.0))).collect());
    }
    let dot =
        |x: &[Vec3], y: &[Vec3]| -> f64 { x.iter().zip(y).map(|(x, y)| x.dot(*y) as f64).sum() };
    let norm = |x: &[Vec3]| dot(x, x).sqrt();
    let applied: Vec<Vec<Vec3>> = vectors
        .iter()
        .map(|u| {
            let mut z = vec![Vec3::ZERO; n];
            mg.apply(a, cloth, u, &mut z);
            z
        })
        .collect();
    for (k, (u, mu)) in vectors.iter().zip(&applied).enumerate() {
        assert!(
            dot(u, mu) > 0.0,
            "{smoother:?}, vector {k}: uᵀM⁻¹u = {}",
            dot(u, mu)
        );
        for (i, z) in mu.iter().enumerate() {
            if cloth.pinned[i] {
                assert_eq!(*z, Vec3::ZERO, "pinned vertex {i} preconditioned");
            }
        }
        let (v, mv) = (
            &vectors[(k + 1) % vectors.len()],
            &applied[(k + 1) % vectors.len()],
        );
        let (uv, vu) = (dot(u, mv), dot(v, mu));
        assert!(
            (uv - vu).abs() <= 1e-4 * norm(u) * norm(mv),
            "{smoother:?}: uᵀM⁻¹v = {uv}, vᵀM⁻¹u = {vu}"
        );
    }
}

#[test]
fn the_v_cycle_is_symmetric_positive_definite() {
    let mut rng = Rng(11);
    let cloth = Cloth::grid(12, 7, 1.0, 1.0, &[0, 11], |u, v| Vec3::new(u, -v, 0.0));
    let b: Vec<Vec3> = (0..cloth.vertex_count())
        .map(|_| rng.vec3(-1.0, 1.0))
        .collect();
    check_spd(&random_system(&cloth, &mut rng), &cloth, &b, &mut rng);

    // Real steps' systems as the sphere meets the cloth: a face contact's
    // β_k β_l blocks take some rows' D⁻¹A past 2, which a fixed smoother
    // weight would turn into an indefinite V-cycle.
    let mut c = Config::default();
    c.cloth.grid = [16, 16];
    let mut sim = CpuSim::new(Scene::new(&c).unwrap());
    let mut checked = 0;
    for _ in 0..100 {
        if sim.step().contacts > 0 {
            let (a, b) = sim.system();
            check_spd(a, &sim.scene.cloth, b, &mut rng);
            checked += 1;
        }
    }
    assert!(
        checked > 30,
        "the sphere should touch the cloth ({checked} steps)"
    );
}

/// Mean and most PCG iterations per step to |S r| ≤ 1e-3 |S b| over a
/// hanging cloth's first steps.
fn iterations(grid: u32, preconditioner: Preconditioner) -> (f64, u32) {
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.solver.preconditioner = preconditioner;
    iterations_of(c, grid, 15)
}

/// Mean and most PCG iterations per step to |S r| ≤ 1e-3 |S b| over
/// `steps` steps of `c` on a `grid`² cloth.
fn iterations_of(mut c: Config, grid: u32, steps: u32) -> (f64, u32) {
    c.cloth.grid = [grid, grid];
    c.solver.cg_iters = 5000;
    c.solver.cg_tol = 1e-3;
    let mut sim = CpuSim::new(Scene::new(&c).unwrap());
    let (mut total, mut most) = (0, 0);
    for _ in 0..steps {
        let out = sim.step().pcg;
        assert!(!out.breakdown && out.relative_residual <= 1e-3, "{out:?}");
        total += out.iterations;
        most = most.max(out.iterations);
    }
    (total as f64 / steps as f64, most)
}

#[test]
fn multigrid_iterations_stay_nearly_flat_as_the_grid_grows() {
    let mg: Vec<(f64, u32)> = [16, 32, 64]
        .map(|n| iterations(n, Preconditioner::Multigrid))
        .to_vec();
    let jacobi: Vec<(f64, u32)> = [16, 64]
        .map(|n| iterations(n, Preconditioner::Jacobi))
        .to_vec();
    eprintln!("multigrid 16², 32², 64²: {mg:?}; Jacobi 16², 64²: {jacobi:?}");
    // Four times the side: Jacobi's iterations grow with it, multigrid's
    // by at most a few.
    assert!(jacobi[1].0 >= 2.0 * jacobi[0].0, "Jacobi {jacobi:?}");
    assert!(mg[2].0 <= 1.5 * mg[0].0 + 2.0, "multigrid {mg:?}");
    assert!(mg[2].1 <= mg[0].1 + 8, "multigrid {mg:?}");
    assert!(
        mg[2].0 * 4.0 <= jacobi[1].0,
        "multigrid {mg:?}, Jacobi {jacobi:?}"
    );
}

/// The steps after the sphere leaves the cloth, which swings stiff against
/// its mass, are the hard ones (docs/DESIGN.md "The hardest steps"): the
/// patch smoother, which solves each 2 × 2 patch's springs together, takes
/// well under half block Jacobi's iterations over them.
#[test]
fn the_patch_smoother_takes_under_half_block_jacobis_iterations() {
    let run = |smoother| {
        let mut c = Config::default();
        c.solver.smoother = smoother;
        iterations_of(c, 24, 160)
    };
    let (patches, jacobi) = (run(Smoother::Patches), run(Smoother::BlockJacobi));
    eprintln!("24², 160 steps: patches {patches:?}, block Jacobi {jacobi:?}");
    assert!(patches.0 < 0.5 * jacobi.0, "{patches:?} against {jacobi:?}");
    assert!(patches.1 < jacobi.1 / 2, "{patches:?} against {jacobi:?}");
}

/// The CPU's patch sweeps cut the rows into a band per thread, each of
/// which also solves the next band's first row for its own last
/// (src/cpu/multigrid.rs, `patch_sweep`): any number of threads gives the
/// V-cycle of one, bit for bit, on a grid of several bands a level, odd
/// rows and pins.
#[test]
fn the_patch_v_cycle_is_the_same_on_any_number_of_threads() {
    let mut rng = Rng(5);
    let cloth = Cloth::grid(150, 131, 1.0, 1.0, &[0, 149], |u, v| Vec3::new(u, -v, 0.0));
    let a = random_system(&cloth, &mut rng);
    let r: Vec<Vec3> = (0..cloth.vertex_count())
        .map(|i| match cloth.pinned[i] {
            true => Vec3::ZERO,
            false => rng.vec3(-1.0, 1.0),
        })
        .collect();
    let v_cycle = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut mg = Multigrid::new(&cloth, Smoother::Patches);
            mg.setup(&a, &cloth);
            let mut z = vec![Vec3::ZERO; cloth.vertex_count()];
            mg.apply(&a, &cloth, &r, &mut z);
            z.iter()
                .flat_map(|z| z.to_array().map(f32::to_bits))
                .collect::<Vec<u32>>()
        })
    };
    let one = v_cycle(1);
    assert!(one.iter().any(|&bits| f32::from_bits(bits) != 0.0));
    for threads in [2, 3, 8] {
        let z = v_cycle(threads);
        let differ = z.iter().zip(&one).filter(|(x, y)| x != y).count();
        assert_eq!(
            differ,
            0,
            "{threads} threads: {differ} of {} floats differ",
            z.len()
        );
    }
}
