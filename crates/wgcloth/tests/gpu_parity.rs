//! The GPU stages against their CPU twins on lavapipe (or any adapter).
//! Without an adapter these tests fail unless WGCLOTH_NO_GPU_TESTS=1 opts out.

mod common;

use std::sync::Arc;

use common::sphere;
use glam::{Mat3, Vec3};
use wgcloth::config::{ModelKind, Preconditioner, SceneKind, Smoother};
use wgcloth::cpu::{CpuSim, PERTURBATION};
use wgcloth::gpu::{CgBudget, GpuContext, GpuSim, Kernels, SolvedSteps, context};
use wgcloth::math::{Sym3, closest_on_triangle};
use wgcloth::sensitivity::{Reference, Sensitivity};
use wgcloth::{Config, Scene};

fn gpu() -> Option<(GpuContext, Arc<Kernels>)> {
    let ctx = common::gpu_context()?;
    let kernels = Arc::new(Kernels::new(&ctx.device).expect("kernels build"));
    Some((ctx, kernels))
}

fn max_dev(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f32::max)
}

fn max_norm(a: &[Vec3]) -> f32 {
    a.iter().map(|p| p.length()).fold(0.0, f32::max)
}

/// What a GPU run may differ from the CPU's by: `exact` (positions, m, and
/// the contact totals' relative difference) where the adapter computes as
/// the CPU does; elsewhere also up to four times what two faithful CPU
/// runs of `steps` steps differ from the CPU's by (`wgcloth validate`'s
/// rule, [`Sensitivity`]): one from a start nudged by a few ulps, one
/// whose solves stop elsewhere within their tolerance. At 1e-3 two such
/// solves ended the substeps' run 1.2 cm apart where the nudge moved it
/// 0.36 mm, and the H200 1.7 cm.
fn allowed_drift(
    ctx: &GpuContext,
    (scene, steps): (&Scene, usize),
    (cpu, cpu_contacts): (&CpuSim, usize),
    exact: (f32, f64),
) -> (f32, f64) {
    if context::computes_as_the_cpu(&ctx.adapter) {
        return exact;
    }
    let reference = Reference {
        x: &cpu.state.x,
        contacts: cpu_contacts as u64,
    };
    let s = Sensitivity::measure(scene, steps as u64, reference, || {});
    eprintln!("faithful CPU runs: {s:?}");
    let spread = s.faithful(&ctx.adapter);
    (
        exact.0.max(4.0 * spread.drift),
        exact.1.max(4.0 * spread.contacts),
    )
}

fn full(blocks: &[Sym3]) -> Vec<Mat3> {
    blocks.iter().map(|m| m.to_mat3()).collect()
}

fn mat_dev(a: &[Mat3], b: &[Mat3]) -> (f32, f32) {
    let fro = |m: Mat3| m.to_cols_array().iter().map(|e| e * e).sum::<f32>().sqrt();
    let dev = a
        .iter()
        .zip(b)
        .map(|(p, q)| fro(*p - *q))
        .fold(0.0, f32::max);
    (dev, a.iter().map(|m| fro(*m)).fold(0.0, f32::max))
}

fn hang(grid: u32) -> Scene {
    hang_solved(grid, MULTIGRID, 100, 1e-3)
}

/// Multigrid with the default smoother.
const MULTIGRID: (Preconditioner, Smoother) = (Preconditioner::Multigrid, Smoother::Patches);

/// Each preconditioner, multigrid with each smoother.
const PRECONDITIONERS: [(Preconditioner, Smoother); 3] = [
    (Preconditioner::Jacobi, Smoother::Patches),
    (Preconditioner::Multigrid, Smoother::Patches),
    (Preconditioner::Multigrid, Smoother::BlockJacobi),
];

fn hang_solved(
    grid: u32,
    (preconditioner, smoother): (Preconditioner, Smoother),
    iters: u32,
    tol: f32,
) -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    (c.solver.preconditioner, c.solver.smoother) = (preconditioner, smoother);
    (c.solver.cg_iters, c.solver.cg_tol) = (iters, tol);
    Scene::new(&c).unwrap()
}

/// A CPU simulator advanced `steps` steps, so springs are stretched and moving.
fn cpu_after(scene: &Scene, steps: usize) -> CpuSim {
    let mut cpu = CpuSim::new(scene.clone());
    for _ in 0..steps {
        cpu.step();
    }
    cpu
}

/// Stage "assemble", springs included: the system from the same state.
#[test]
fn assembly_matches_the_cpu_on_the_same_state() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = hang(12);
    let mut cpu = cpu_after(&scene, 7);
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&cpu.state.x, &cpu.state.v, cpu.state.step as u32);
    let start = cpu.state.clone();
    gpu.step();
    cpu.step();

    let (gd, go, gb) = gpu.read_system().unwrap();
    let (a, b) = cpu.system();
    let (dev, norm) = mat_dev(&full(&gd), &full(&a.diag));
    assert!(dev <= 1e-5 * norm, "A diagonal {dev} vs {norm}");
    let (dev, norm) = mat_dev(&full(&go), &full(&a.off));
    assert!(dev <= 1e-5 * norm, "A off-diagonal {dev} vs {norm}");
    // b = m v + h f sums spring forces that nearly cancel gravity's: an
    // ulp of a spring's length is a large part of it.
    let allowed = 1e-5 * max_norm(b)
        + if context::computes_as_the_cpu(&ctx.adapter) {
            0.0
        } else {
            let mut nudged = CpuSim::new(scene.clone());
            nudged.state = start;
            nudged.state.nudge(PERTURBATION);
            nudged.step();
            4.0 * max_dev(nudged.system().1, b)
        };
    assert!(
        max_dev(&gb, b) <= allowed,
        "b {} vs {} (allowed {allowed})",
        max_dev(&gb, b),
        max_norm(b)
    );
}

#[test]
fn hanging_cloth_runs_like_the_cpu_for_60_steps() {
    let Some((ctx, kernels)) = gpu() else { return };
    // A fixed iteration count on both sides (tolerance 0): the thesis's 25
    // Jacobi iterations, and 5 multigrid V-cycles, about what 1e-3 takes.
    for solve in PRECONDITIONERS {
        let (preconditioner, smoother) = solve;
        // Multigrid at 33²: on lavapipe its second level (17², past
        // `tail_nodes`) has its own dispatches, as the cloth's.
        let (grid, iters) = match preconditioner {
            Preconditioner::Jacobi => (16, 25),
            Preconditioner::Multigrid => (33, 5),
        };
        let scene = hang_solved(grid, solve, iters, 0.0);
        let cpu = cpu_after(&scene, 60);
        let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        for _ in 0..60 {
            gpu.step();
        }
        let x = gpu.read_positions().unwrap();
        let dev = max_dev(&x, &cpu.state.x);
        let state = gpu.read_state().unwrap();
        eprintln!(
            "{preconditioner:?} ({smoother:?}), 60 steps: largest position deviation {dev:.3e} m; GPU state {state:?}"
        );
        assert_eq!(state.steps, 60);
        assert_eq!(state.cg_iterations_total, 60 * iters);
        assert_eq!(state.clock, 60);
        assert!(
            dev < 1e-4,
            "{preconditioner:?} ({smoother:?}): GPU and CPU drifted {dev} m apart"
        );
        for (i, p) in scene.cloth.pinned.iter().enumerate() {
            if *p {
                assert_eq!(x[i], scene.cloth.rest_positions[i]);
            }
        }
    }
}

/// Steps at which the default sphere is pushing into the cloth.
const IN_CONTACT: usize = 70;

#[test]
fn contacts_responses_and_system_match_the_cpu_on_the_same_state() {
    let Some((ctx, kernels)) = gpu() else { return };
    // friction-net twice: its default network works in the contact frame,
    // the thesis-size one in the world frame.
    let models = [
        (ModelKind::Friction, None),
        (ModelKind::Naive, None),
        (ModelKind::FrictionNet, None),
        (
            ModelKind::FrictionNet,
            Some("weights/friction_mlp.safetensors"),
        ),
        (ModelKind::NaiveNet, None),
    ];
    for (model, weights) in models {
        let mut scene = sphere(20, model);
        if let Some(path) = weights {
            scene.config.contact.weights = Some(path.into());
            scene = Scene::new(&scene.config).unwrap();
        }
        let mut cpu = cpu_after(&scene, IN_CONTACT);
        let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        gpu.upload_state(&cpu.state.x, &cpu.state.v, cpu.state.step as u32);
        let speed = max_norm(&cpu.state.v);
        gpu.step();
        cpu.step();

        let (vf, fv) = gpu.read_contacts().unwrap();
        let gpu_vf: Vec<_> = vf.iter().filter(|(c, _)| c.valid != 0).collect();
        let gpu_fv: Vec<_> = fv.iter().filter(|(c, _)| c.valid != 0).collect();
        let cpu_vf: Vec<_> = cpu
            .contacts()
            .iter()
            .filter(|c| c.cloth_triangle.is_none())
            .collect();
        let cpu_fv: Vec<_> = cpu
            .contacts()
            .iter()
            .filter(|c| c.cloth_triangle.is_some())
            .collect();
        assert!(
            cpu_vf.len() > 10 && cpu_fv.len() > 10,
            "{model:?}: the state must be in contact"
        );
        assert_eq!(
            gpu_vf.len(),
            cpu_vf.len(),
            "{model:?}: vertex–face contact count"
        );
        assert_eq!(
            gpu_fv.len(),
            cpu_fv.len(),
            "{model:?}: face–vertex contact count"
        );
        let responses = cpu.responses();
        let mut kinks = 0;
        let mut kink_dev = 0.0f32;
        let mut force_dev = 0.0f32;
        let mut force_max = 0.0f32;
        for (k, c) in cpu.contacts().iter().enumerate() {
            let (g, r) = match c.cloth_triangle {
                None => vf[c.vertices[0] as usize],
                Some(t) => {
                    let g = fv[c.rigid_feature as usize];
                    assert_eq!(
                        g.0.triangle, t,
                        "{model:?}: rigid vertex {} hit another triangle",
                        c.rigid_feature
                    );
                    g
                }
            };
            assert!(
                (g.distance - c.distance).abs() < 1e-5,
                "{model:?}: distance {} vs {}",
                g.distance,
                c.distance
            );
            force_dev = force_dev.max((Vec3::from(r.force) - responses[k].force).length());
            force_max = force_max.max(responses[k].force.length());
            let (dev, norm) = mat_dev(&[r.damping.to_mat3()], &[responses[k].damping]);
            if dev > 1e-3 * norm + 1e-4 {
                // A network is piecewise linear: where a unit's input is
                // within rounding of 0 the two sides may take different
                // pieces and the Jacobian jumps by that unit's share.
                kinks += 1;
                kink_dev += dev;
                assert!(
                    model.is_network() && dev <= 2e-2 * norm,
                    "{model:?}: contact damping {dev} vs {norm}"
                );
            }
        }
        assert!(
            force_dev <= 1e-4 * force_max,
            "{model:?}: contact forces {force_dev} vs {force_max}"
        );
        assert!(
            kinks * 50 <= cpu.contacts().len(),
            "{model:?}: {kinks} of {} contacts differ",
            cpu.contacts().len()
        );

        let (gd, go, gb) = gpu.read_system().unwrap();
        let (a, b) = cpu.system();
        // A kink's damping enters blocks scaled by h β_k β_l ≤ 1.
        let (dev, norm) = mat_dev(&full(&gd), &full(&a.diag));
        assert!(
            dev <= 1e-4 * norm + kink_dev,
            "{model:?}: A diagonal {dev} vs {norm}"
        );
        let (dev, norm) = mat_dev(&full(&go), &full(&a.off));
        assert!(
            dev <= 1e-4 * norm + kink_dev,
            "{model:?}: A off-diagonal {dev} vs {norm}"
        );
        // ... and b as h D v_rel, with |v_rel| ≤ |v| + the sphere's ≤ 1 m/s.
        let h = scene.config.solver.dt;
        assert!(
            max_dev(&gb, b) <= 1e-4 * max_norm(b) + kink_dev * h * (speed + 1.0),
            "{model:?}: b {} vs {}",
            max_dev(&gb, b),
            max_norm(b)
        );
    }
}

/// A coarse cloth against a fine body: the default sphere subdivided five
/// times (10,242 vertices) under an 8 × 8 cloth, where up to 171
/// face–vertex contacts share a cloth triangle. On the same state the GPU
/// assembles the CPU's system (each vertex had summed only some of its
/// triangles' contacts, its b 2.5 N·s off, and the solve broke down at step
/// 48), and a run of 60 steps solves every step and, where the adapter
/// computes as the CPU, ends where the CPU's does.
#[test]
fn a_coarse_cloth_against_a_fine_body_assembles_and_runs_as_the_cpu() {
    let Some((ctx, kernels)) = gpu() else { return };
    let mut config = sphere(8, ModelKind::Friction).config;
    config.rigid.subdivisions = 5;
    let scene = Scene::new(&config).unwrap();
    let mut cpu = cpu_after(&scene, 35);
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&cpu.state.x, &cpu.state.v, cpu.state.step as u32);
    gpu.step();
    cpu.step();
    let mut per_triangle = std::collections::HashMap::new();
    for c in cpu.contacts() {
        *per_triangle.entry(c.cloth_triangle).or_insert(0) += 1;
    }
    let crowded = per_triangle.values().max().copied().unwrap_or(0);
    let (gd, _, gb) = gpu.read_system().unwrap();
    let (a, b) = cpu.system();
    let (dev, norm) = mat_dev(&full(&gd), &full(&a.diag));
    eprintln!(
        "{crowded} contacts on a triangle at most; b {:.2e} of {:.2e}, A's diagonal {dev:.2e} of {norm:.2e} apart",
        max_dev(&gb, b),
        max_norm(b)
    );
    assert!(crowded > 100, "{crowded} contacts on a triangle at most");
    assert!(max_dev(&gb, b) <= 1e-4 * max_norm(b));
    assert!(dev <= 1e-4 * norm);

    let mut cpu = CpuSim::new(scene.clone());
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    for _ in 0..60 {
        cpu.step();
        gpu.step();
    }
    let state = gpu.read_state().unwrap();
    let apart = max_dev(&gpu.read_positions().unwrap(), &cpu.state.x);
    eprintln!(
        "60 steps: {} breakdowns, positions {apart:.2e} m apart",
        state.cg_breakdowns
    );
    assert_eq!(state.cg_breakdowns, 0);
    // Elsewhere contact grows an ulp's difference (what a faithful run may
    // differ by), so only the solve is held there.
    if context::computes_as_the_cpu(&ctx.adapter) {
        assert!(apart <= 1e-5, "{apart} m apart");
    }
}

/// Face–vertex contacts on a cloth of several super-tiles (130²: 3 × 3 of
/// them), where each rigid vertex's workgroup searches one super-tile a
/// round: every rigid vertex hits the triangle the CPU's search finds, at
/// the same depth.
#[test]
fn face_vertex_contacts_match_the_cpu_across_super_tiles() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = sphere(130, ModelKind::Friction);
    let mut cpu = cpu_after(&scene, IN_CONTACT);
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&cpu.state.x, &cpu.state.v, cpu.state.step as u32);
    gpu.step();
    cpu.step();
    let (_, fv) = gpu.read_contacts().unwrap();
    let on_cpu: Vec<_> = cpu
        .contacts()
        .iter()
        .filter_map(|c| {
            c.cloth_triangle
                .map(|t| (c.rigid_feature as usize, t, c.distance))
        })
        .collect();
    assert!(on_cpu.len() > 10, "the state must be in contact");
    assert_eq!(
        fv.iter().filter(|(c, _)| c.valid != 0).count(),
        on_cpu.len()
    );
    for (k, t, distance) in on_cpu {
        let g = fv[k].0;
        assert_eq!((g.valid, g.triangle), (1, t), "rigid vertex {k}");
        assert!(
            (g.distance - distance).abs() < 1e-5,
            "rigid vertex {k}: {} vs {distance}",
            g.distance
        );
    }
}

#[test]
fn thesis_scene_runs_like_the_cpu_with_both_models() {
    let Some((ctx, kernels)) = gpu() else { return };
    for model in [ModelKind::Friction, ModelKind::Naive] {
        let scene = sphere(16, model);
        let steps = 100;
        let mut cpu = CpuSim::new(scene.clone());
        let mut cpu_contacts = 0;
        let mut cpu_deepest = 0.0f32;
        for _ in 0..steps {
            let s = cpu.step();
            cpu_contacts += s.contacts;
            cpu_deepest = cpu_deepest.max(s.max_penetration);
        }
        let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        let mut solved = SolvedSteps::for_scene(&gpu, &scene);
        for _ in 0..steps {
            solved.step(&gpu).unwrap();
        }
        let x = gpu.read_positions().unwrap();
        let state = gpu.read_state().unwrap();
        let dev = max_dev(&x, &cpu.state.x);
        let deepest = f32::from_bits(state.max_penetration_bits);
        eprintln!(
            "{model:?}, {steps} steps: position deviation {dev:.3e} m; contacts {} vs {cpu_contacts}; deepest {deepest:.4} vs {cpu_deepest:.4}",
            state.contacts_total
        );
        assert!(cpu_contacts > 500, "the sphere must hit the cloth");
        let (allowed, contacts_allowed) =
            allowed_drift(&ctx, (&scene, steps), (&cpu, cpu_contacts), (1e-3, 0.02));
        assert!(
            dev < allowed,
            "{model:?}: GPU and CPU drifted {dev} m apart (allowed {allowed})"
        );
        let ratio = state.contacts_total as f64 / cpu_contacts as f64;
        assert!(
            (ratio - 1.0).abs() < contacts_allowed,
            "{model:?}: contact totals {} vs {cpu_contacts}",
            state.contacts_total
        );
        // Before any push-out: on both paths the contact forces alone keep
        // every vertex out of the sphere.
        assert_eq!(
            (deepest, cpu_deepest),
            (0.0, 0.0),
            "{model:?}: deepest inside after the solve (GPU, CPU)"
        );
    }
}

/// A step of substeps (`Scene::substeps`): the GPU records them in one
/// step, its clock counting them and its step count and budget the steps,
/// and ends where the CPU's substeps do.
#[test]
fn a_step_of_substeps_runs_like_the_cpu() {
    let Some((ctx, kernels)) = gpu() else { return };
    let mut c = Config {
        model: ModelKind::Naive,
        ..Default::default()
    };
    c.cloth.grid = [16, 16];
    // 63 mm a step at most, against a spacing of 67 mm.
    c.rigid.motion.period /= 8.0;
    let scene = Scene::new(&c).unwrap();
    assert_eq!(scene.substeps, 2);
    let steps = 16;
    let mut cpu = CpuSim::new(scene.clone());
    let (mut cpu_contacts, mut cpu_iterations) = (0, 0);
    for _ in 0..steps {
        let s = cpu.step();
        cpu_contacts += s.contacts;
        cpu_iterations += s.pcg.iterations;
    }
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    let mut solved = SolvedSteps::for_scene(&gpu, &scene);
    for _ in 0..steps {
        solved.step(&gpu).unwrap();
    }
    let state = gpu.read_state().unwrap();
    let dev = max_dev(&gpu.read_positions().unwrap(), &cpu.state.x);
    eprintln!(
        "{steps} steps: deviation {dev:.3e} m; contacts {} vs {cpu_contacts}; iterations {} vs {cpu_iterations}",
        state.contacts_total, state.cg_iterations_total
    );
    assert_eq!((state.steps, state.clock), (steps, 2 * steps));
    assert_eq!(cpu.state.step, steps as u64);
    assert!(cpu_contacts > 100, "the sphere must hit the cloth");
    let (allowed, contacts_allowed) = allowed_drift(
        &ctx,
        (&scene, steps as usize),
        (&cpu, cpu_contacts),
        (1e-3, 0.02),
    );
    assert!(
        dev < allowed,
        "GPU and CPU drifted {dev} m apart (allowed {allowed})"
    );
    let ratio = state.contacts_total as f64 / cpu_contacts as f64;
    assert!((ratio - 1.0).abs() < contacts_allowed, "contacts {ratio}");
    assert!(state.last_residual <= c.solver.cg_tol);
}

#[test]
fn vertices_deep_inside_are_measured_and_pushed_out_as_on_the_cpu() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = sphere(16, ModelKind::Friction);
    let mut cpu = cpu_after(&scene, IN_CONTACT);
    let center = {
        let body = scene.rigid.as_ref().unwrap();
        body.translation((cpu.state.time + scene.config.solver.dt as f64) as f32)
    };
    // Ten vertices 5 cm inside the sphere (radius 0.2): deeper than the
    // contact band, so no force pushes them out during the step.
    for (k, i) in (0..scene.cloth.vertex_count())
        .step_by(23)
        .take(10)
        .enumerate()
    {
        let dir = (cpu.state.x[i] - center).normalize_or(Vec3::Z);
        cpu.state.x[i] = center + dir * (0.15 - 0.002 * k as f32);
        cpu.state.v[i] = Vec3::ZERO;
    }
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&cpu.state.x, &cpu.state.v, cpu.state.step as u32);
    gpu.step();
    let stats = cpu.step();
    let deepest = f32::from_bits(gpu.read_state().unwrap().max_penetration_bits);
    let x = gpu.read_positions().unwrap();
    let body = scene.rigid.as_ref().unwrap();
    let (left_gpu, left_cpu) = (
        common::deepest_inside(body, cpu.state.time, &x),
        common::deepest_inside(body, cpu.state.time, &cpu.state.x),
    );
    eprintln!(
        "deepest after the solve: GPU {deepest:.5} m, CPU {:.5} m; after the push-out {left_gpu:.1e} and {left_cpu:.1e} m; positions {:.1e} m apart",
        stats.max_penetration,
        max_dev(&x, &cpu.state.x)
    );
    // Springs pull them partly out within the step; still beyond the band.
    let band = scene.config.contact.max_depth;
    assert!(
        stats.max_penetration > band,
        "the test must put vertices deeper than the contact band"
    );
    assert!((deepest - stats.max_penetration).abs() < 1e-4);
    assert!(left_gpu < 1e-5 && left_cpu < 1e-5, "a vertex stayed inside");
    assert!(max_dev(&x, &cpu.state.x) < 1e-4);
}

/// The GPU's inside test judges the rays that pass exactly through a mesh
/// vertex or edge as the CPU's does (whose own test checks it against the
/// convex body's planes): cloth vertices put on such rays, before, inside
/// and past a static sphere at the origin, are found inside and pushed
/// out by stage `measure` alone on both paths alike.
#[test]
fn rays_through_mesh_vertices_and_edges_find_the_same_vertices_inside_on_the_gpu() {
    use wgcloth::config::MotionKind;
    use wgcloth::cpu::measure;
    use wgcloth::cpu::rigid::{RigidFrame, transform};
    use wgcloth::stage::Stage;
    let Some((ctx, kernels)) = gpu() else { return };
    let mut c = Config::default();
    c.cloth.grid = [128, 128];
    c.rigid.position = [0.0; 3];
    c.rigid.motion.kind = MotionKind::Static;
    let scene = Scene::new(&c).unwrap();
    let body = scene.rigid.as_ref().unwrap();
    let n = scene.cloth.vertex_count();
    // Those clear of the surface, where rounding decides.
    let mut points = common::on_rays_through_vertices_and_edges(body);
    points.retain(|&p| common::inside_convex(body, p, 1e-4).is_some());
    assert!(
        points.len() >= n,
        "{} points for {n} vertices",
        points.len()
    );
    // An even sample: about one point in two.
    let x: Vec<Vec3> = (0..n).map(|i| points[i * points.len() / n]).collect();
    let v = vec![Vec3::new(0.0, 0.0, -1.0); n];
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&x, &v, 0);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    gpu.record_stage(&mut encoder, Stage::Rigid);
    gpu.record_stage(&mut encoder, Stage::Measure);
    ctx.queue.submit([encoder.finish()]);
    let (gpu_x, gpu_v) = (
        gpu.read_positions().unwrap(),
        gpu.read_velocities().unwrap(),
    );
    let mut frame = RigidFrame::default();
    transform(body, c.solver.dt, &mut frame);
    let (mut cpu_x, mut cpu_v) = (x.clone(), v.clone());
    let thickness = c.contact.thickness;
    let mut moved = vec![false; n];
    measure::push_out(
        body,
        &frame,
        thickness,
        &scene.cloth.pinned,
        (&mut cpu_x, &mut cpu_v),
        &mut moved,
    );
    let pushed = (0..n).filter(|&i| cpu_x[i] != x[i]).count();
    assert_eq!(
        pushed,
        moved.iter().filter(|&&m| m).count(),
        "marked as moved"
    );
    let otherwise: Vec<Vec3> = (0..n)
        .filter(|&i| (gpu_x[i] != x[i]) != (cpu_x[i] != x[i]))
        .map(|i| x[i])
        .collect();
    eprintln!("{pushed} of {n} vertices pushed out");
    assert!(pushed > n / 8 && pushed < n - n / 8, "{pushed} pushed out");
    assert!(
        otherwise.is_empty(),
        "the GPU judged {} vertices otherwise, e.g. at {:?}",
        otherwise.len(),
        &otherwise[..otherwise.len().min(4)]
    );
    let apart: Vec<usize> = (0..n)
        .filter(|&i| {
            (gpu_x[i] - cpu_x[i]).length() >= 1e-5 || (gpu_v[i] - cpu_v[i]).length() >= 1e-5
        })
        .collect();
    eprintln!(
        "positions differ by {:.3e} m at most, velocities by {:.3e} m/s; {} vertices by 1e-5 or more",
        max_dev(&gpu_x, &cpu_x),
        max_dev(&gpu_v, &cpu_v),
        apart.len()
    );
    if context::computes_as_the_cpu(&ctx.adapter) {
        assert!(apart.is_empty());
    }
    // Elsewhere each vertex pushed otherwise has two triangles as near as
    // rounding tells (the nearest surface point on their shared edge or
    // corner): which one's normal it leaves along is the rounding's.
    for i in apart {
        let mut d2: Vec<f32> = body
            .mesh
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|k| body.mesh.vertices[k as usize]);
                (closest_on_triangle(x[i], a, b, c) - x[i]).length_squared()
            })
            .collect();
        d2.sort_by(f32::total_cmp);
        let gap = d2[1].sqrt() - d2[0].sqrt();
        eprintln!(
            "  vertex at {:?}: depth {:.4e} m, next triangle {gap:.2e} m further",
            x[i],
            d2[0].sqrt()
        );
        assert!(
            gap < 1e-6,
            "vertex at {:?}: the GPU's push-out differs with no tie ({gap} m)",
            x[i]
        );
    }
}

#[test]
fn steps_recorded_into_one_app_encoder_equal_separate_submissions() {
    let Some((ctx, kernels)) = gpu() else { return };
    // A cap of 40 iterations, more than these steps take: a fifth of the
    // default's dispatches to record.
    let mut config = sphere(12, ModelKind::Friction).config;
    config.solver.cg_iters = 40;
    let scene = Scene::new(&config).unwrap();
    let separate = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    for _ in 0..50 {
        separate.step();
    }
    // An embedding app: its own encoder, many steps, one submission; the
    // clock and the rigid body's motion live on the GPU.
    let embedded = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let dispatches: u32 = (0..50).map(|_| embedded.encode_step(&mut encoder)).sum();
    ctx.queue.submit([encoder.finish()]);
    ctx.finish().unwrap();
    // 11 outside the solve; PCG's init, init_scalars, spmv, conclude and
    // finish; per iteration `next` (but the first) and `advance`; the
    // multigrid setup (per coarse level L its operator, and per level but
    // the coarsest its patch inverses) and a V-cycle (11 T + 2: four
    // forward patch sweeps, a residual and a restriction down, a guess and
    // four backward sweeps up, per level above the tail's first T; the
    // tail; the cloth's rᵀz) at the start and in every iteration.
    let levels = wgcloth::multigrid::levels(12, 12);
    let nodes: Vec<u32> = levels.iter().map(|l| l.nodes() as u32).collect();
    let (iters, coarse) = (scene.config.solver.cg_iters, levels.len() as u32 - 1);
    let cpu_adapter = ctx.adapter.device_type == wgpu::DeviceType::Cpu;
    let most = wgcloth::multigrid::tail_nodes(cpu_adapter);
    let cycle = 11 * wgcloth::multigrid::tail_from(&nodes, most) as u32 + 2;
    let pcg = 5 + (iters - 1) + iters * (1 + cycle) + 2 * coarse + cycle;
    assert_eq!(dispatches, 50 * (11 + pcg), "dispatches per step");
    assert_eq!(
        embedded.read_positions().unwrap(),
        separate.read_positions().unwrap()
    );
    assert_eq!(embedded.read_state().unwrap().steps, 50);
    assert!(
        embedded
            .positions()
            .usage()
            .contains(wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE)
    );
    assert!(
        embedded
            .indices()
            .usage()
            .contains(wgpu::BufferUsages::INDEX)
    );
    assert_eq!(
        embedded.index_count() as usize,
        3 * scene.cloth.triangles.len()
    );
}

#[test]
fn a_lost_device_is_an_error_not_a_panic_or_a_hang() {
    let Some((ctx, kernels)) = gpu() else { return };
    let sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &hang(8)).unwrap();
    sim.step();
    ctx.finish().unwrap();
    ctx.device.destroy();
    sim.step();
    let err = ctx
        .finish()
        .expect_err("a destroyed device must report an error");
    eprintln!("{err}");
    assert!(err.to_string().starts_with("GPU:"), "{err}");
}

#[test]
fn converged_pcg_stops_early_on_the_gpu_as_on_the_cpu() {
    let Some((ctx, kernels)) = gpu() else { return };
    for solve in PRECONDITIONERS {
        let (preconditioner, smoother) = solve;
        // An odd side: the last node of each axis is a coarse node itself.
        let scene = hang_solved(21, solve, 300, 1e-4);
        let mut cpu = CpuSim::new(scene.clone());
        let mut cpu_iters = 0;
        let mut cpu_worst = 0.0f32;
        for _ in 0..20 {
            let out = cpu.step().pcg;
            cpu_iters += out.iterations;
            cpu_worst = cpu_worst.max(out.relative_residual);
        }
        let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        let mut solved = SolvedSteps::for_scene(&gpu, &scene);
        for _ in 0..20 {
            solved.step(&gpu).unwrap();
        }
        let state = gpu.read_state().unwrap();
        let gpu_iters = state.cg_iterations_total;
        eprintln!(
            "{preconditioner:?} ({smoother:?}): PCG iterations over 20 steps: GPU {gpu_iters}, CPU {cpu_iters} \
             (cap 6000); worst residual GPU {:.2e}, CPU {cpu_worst:.2e}",
            state.cg_residual_max
        );
        assert!(
            cpu_iters < 20 * 150,
            "the CPU solve should converge well before the cap"
        );
        assert!(state.cg_residual_max <= 1e-4 && cpu_worst <= 1e-4);
        assert_eq!(state.cg_breakdowns, 0);
        // f32 sums on the GPU, f64 on the CPU: the stopping iteration may differ slightly.
        assert!(
            (gpu_iters as f64 - cpu_iters as f64).abs() <= 0.05 * cpu_iters as f64 + 20.0,
            "{preconditioner:?} ({smoother:?}): GPU {gpu_iters}, CPU {cpu_iters}"
        );
    }
}

/// The solver's workgroup sums through subgroup operations (the headless
/// device asks for them, and lavapipe has them) against the same sums
/// through workgroup memory alone, on a device opened without them: the
/// same solves but for f32 rounding, with each preconditioner.
#[test]
fn subgroup_sums_solve_as_workgroup_memory_sums_do() {
    let Some((ctx, kernels)) = gpu() else { return };
    let adapter = GpuContext::pick_adapter().unwrap();
    let has = adapter.features().contains(wgpu::Features::SUBGROUP);
    assert_eq!(kernels.subgroups(), has);
    if !has {
        assert!(
            !std::env::var("CI").is_ok_and(|v| v == "true"),
            "CI's lavapipe offers subgroup operations: this test must run them"
        );
        eprintln!(
            "skipping: {} has no subgroup operations",
            adapter.get_info().name
        );
        return;
    }
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .unwrap();
    let plain = Kernels::new(&device).unwrap();
    assert!(!plain.subgroups());
    for solve in PRECONDITIONERS {
        // 441 vertices: the second workgroup of each dispatch partial.
        let scene = hang_solved(21, solve, 300, 1e-4);
        let with = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        let without = GpuSim::with_kernels(&plain, &device, &queue, &scene).unwrap();
        let mut solved = [&with, &without].map(|sim| SolvedSteps::for_scene(sim, &scene));
        for _ in 0..20 {
            solved[0].step(&with).unwrap();
            solved[1].step(&without).unwrap();
        }
        let (a, b) = (with.read_state().unwrap(), without.read_state().unwrap());
        let (pa, pb) = (
            with.read_positions().unwrap(),
            without.read_positions().unwrap(),
        );
        eprintln!(
            "{solve:?}: iterations {} with subgroups, {} without; positions differ by {:.2e} m",
            a.cg_iterations_total,
            b.cg_iterations_total,
            max_dev(&pa, &pb)
        );
        assert!(a.cg_residual_max <= 1e-4 && b.cg_residual_max <= 1e-4);
        assert_eq!((a.cg_breakdowns, b.cg_breakdowns), (0, 0));
        // Rounding moves a step's stop by an iteration or so either way,
        // and on a hardware GPU a few more (an H200: 1,393 against 1,346
        // for Jacobi's 20 steps).
        let (ia, ib) = (a.cg_iterations_total as f64, b.cg_iterations_total as f64);
        assert!(
            ia > 20.0 && (ia - ib).abs() <= 0.05 * ib + 20.0,
            "{solve:?}: {ia} against {ib}"
        );
        assert!(max_dev(&pa, &pb) <= 1e-5, "{solve:?}");
    }
}

/// A random network with the given layer sizes (deterministic).
fn random_mlp(sizes: &[usize], seed: u64) -> wgcloth::nn::Mlp {
    let mut s = seed;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    wgcloth::nn::Mlp {
        layers: sizes
            .windows(2)
            .map(|w| wgcloth::nn::Layer {
                inputs: w[0],
                outputs: w[1],
                weight: (0..w[0] * w[1])
                    .map(|_| next() * 1.5 / (w[0] as f32).sqrt())
                    .collect(),
                bias: (0..w[1]).map(|_| 0.1 * next()).collect(),
            })
            .collect(),
        negative_slope: 0.01,
    }
}

/// Runs `net` on the GPU over `inputs` (one row per contact) and returns
/// the outputs, [contact × (1 + |wrt|) × outputs].
fn gpu_batch(
    ctx: &GpuContext,
    kernels: &Arc<Kernels>,
    net: &wgcloth::nn::Mlp,
    wrt: std::ops::Range<usize>,
    inputs: &[Vec<f32>],
    shape: wgcloth::gpu::mlp::BatchShape,
) -> wgcloth::Result<Vec<f32>> {
    let batch = wgcloth::gpu::mlp::NetworkBatch::new(kernels, &ctx.device, net, wrt, shape)?;
    let flat: Vec<f32> = inputs.iter().flatten().copied().collect();
    batch.upload(&ctx.queue, &flat)?;
    batch.run(&ctx.device, &ctx.queue);
    batch.read_outputs(&ctx.device, &ctx.queue)
}

#[test]
fn network_kernels_match_the_cpu_network_and_its_jacobian() {
    let Some((ctx, kernels)) = gpu() else { return };
    // Layer sizes that do and do not divide the tiles; batches smaller and
    // larger than a tile, in one chunk and in several.
    // Three outputs (the world-frame networks) and two (the contact frame's).
    let cases: [(&[usize], std::ops::Range<usize>, usize, usize); 9] = [
        (&[10, 256, 256, 128, 128, 3], 0..6, 300, usize::MAX),
        (&[10, 128, 128, 64, 3], 0..6, 300, usize::MAX),
        (&[10, 64, 64, 48, 3], 0..6, 300, usize::MAX),
        (&[7, 48, 48, 2], 0..3, 300, usize::MAX),
        (&[7, 33, 2], 0..3, 70, 20),
        (&[7, 16, 16, 16, 16, 16, 3], 4..7, 130, usize::MAX),
        (&[10, 37, 70, 5, 3], 0..6, 1, usize::MAX),
        (&[10, 65, 3], 0..6, 200, 47),
        (&[3, 1, 3], 0..3, 64, 10),
    ];
    for (k, (sizes, wrt, n, max_chunk)) in cases.into_iter().enumerate() {
        let net = random_mlp(sizes, 7 + k as u64);
        let mut s = 99 + k as u64;
        let inputs: Vec<Vec<f32>> = (0..n)
            .map(|_| {
                (0..sizes[0])
                    .map(|_| {
                        s = s
                            .wrapping_mul(6364136223846793005)
                            .wrapping_add(1442695040888963407);
                        (s >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
                    })
                    .collect()
            })
            .collect();
        use wgcloth::gpu::mlp::{BatchShape, NetworkKernel};
        for kernel in [NetworkKernel::Tiled, NetworkKernel::PerContact] {
            let shape = BatchShape {
                capacity: n,
                max_chunk,
                kernel,
            };
            let what = format!("{kernel:?} {sizes:?}");
            match gpu_batch(&ctx, &kernels, &net, wrt.clone(), &inputs, shape) {
                Ok(got) => check_batch(&net, &wrt, &inputs, &got, &what),
                // Too much work per invocation for lavapipe's loop limit.
                Err(e) => assert!(
                    kernel == NetworkKernel::PerContact
                        && kernels.software()
                        && e.to_string().contains("loop iterations"),
                    "{what}: {e}"
                ),
            }
        }
    }
}

/// GPU batch outputs against the CPU network and its Jacobian.
fn check_batch(
    net: &wgcloth::nn::Mlp,
    wrt: &std::ops::Range<usize>,
    inputs: &[Vec<f32>],
    got: &[f32],
    what: &str,
) {
    let (rows, outputs) = (1 + wrt.len(), net.outputs());
    assert_eq!(
        got.len(),
        inputs.len() * rows * outputs,
        "{what}: output size"
    );
    let (mut worst, mut scale) = (0.0f32, 0.0f32);
    for (c, x) in inputs.iter().enumerate() {
        let (y, j) = net.forward_jacobian(x, wrt.clone());
        for o in 0..outputs {
            worst = worst.max((got[outputs * c * rows + o] - y[o]).abs());
            scale = scale.max(y[o].abs());
            for t in 0..wrt.len() {
                let gpu_d = got[outputs * (c * rows + 1 + t) + o];
                worst = worst.max((gpu_d - j[o * wrt.len() + t]).abs());
                scale = scale.max(j[o * wrt.len() + t].abs());
            }
        }
    }
    eprintln!(
        "{what}, {} contacts: largest difference {worst:.2e} of {scale:.2e}",
        inputs.len()
    );
    assert!(worst <= 1e-4 * scale, "{what}: {worst} vs {scale}");
}

#[test]
fn a_network_beyond_the_adapters_limits_is_one_clear_error() {
    let Some((ctx, _)) = gpu() else { return };
    drop(ctx);
    // A device that binds at most 1 MiB per storage buffer.
    let adapter = GpuContext::pick_adapter().unwrap();
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 1 << 20,
        ..adapter.limits()
    };
    let (device, _queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: limits,
        ..Default::default()
    }))
    .unwrap();
    let kernels = Arc::new(Kernels::new(&device).unwrap());
    let buffer = |size| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        })
    };
    let (inputs, count, outputs) = (buffer(64), buffer(64), buffer(1 << 12));
    let io = || wgcloth::gpu::mlp::BatchBuffers {
        inputs: &inputs,
        count: &count,
        outputs: &outputs,
    };
    // 10 × 30000 weights: 1.2 MB.
    let wide = random_mlp(&[10, 30000, 3], 1);
    let shape = wgcloth::gpu::mlp::BatchShape {
        kernel: wgcloth::gpu::mlp::NetworkKernel::Tiled,
        ..wgcloth::gpu::mlp::BatchShape::new(4)
    };
    let err = wgcloth::gpu::GpuMlp::new(&kernels, &device, &wide, 0..6, shape, io())
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("weights") && err.contains("bytes"), "{err}");
    // Weights that fit (0.5 MB), activations of one contact that do not:
    // 7 rows × 40000 floats = 1.1 MB.
    let one_wide = random_mlp(&[6, 1, 40000, 1, 3], 2);
    let err = wgcloth::gpu::GpuMlp::new(&kernels, &device, &one_wide, 0..6, shape, io())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        err.contains("activations") && err.contains("bytes"),
        "{err}"
    );
}

/// A device whose bindings hold 96 bytes per vertex of a 32² hanging
/// cloth gets the topology (about 260 bytes per vertex), the matrix (160)
/// and the multigrid operators (205, with the patch inverses) bound in parts, as lavapipe gets them
/// at 1024² under its 128 MiB; the steps are bit for bit those of one
/// binding each. A cloth too large even for three parts is one clear error.
#[test]
fn arrays_past_the_binding_limit_are_bound_in_parts_and_step_bit_for_bit() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = hang_solved(32, MULTIGRID, 40, 1e-3);
    let whole = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    assert!(
        whole.split_arrays().is_empty(),
        "{:?}",
        whole.split_arrays()
    );

    let adapter = GpuContext::pick_adapter().unwrap();
    let limits = wgpu::Limits {
        max_storage_buffer_binding_size: 96 * 32 * 32,
        ..adapter.limits()
    };
    // The same features as `ctx`'s device, so the same sums.
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_features: ctx.device.features(),
        required_limits: limits,
        ..Default::default()
    }))
    .unwrap();
    let narrow = Kernels::new(&device).unwrap();
    assert_eq!(narrow.subgroups(), kernels.subgroups());
    assert!(
        narrow.splittable(),
        "lavapipe binds 32 storage buffers per stage"
    );
    let parted = GpuSim::with_kernels(&narrow, &device, &queue, &scene).unwrap();
    assert_eq!(
        parted.split_arrays(),
        [("topology", 3), ("matrix", 2), ("operators", 3)]
    );
    for _ in 0..30 {
        whole.step();
        parted.step();
    }
    let (a, b) = (
        whole.read_positions().unwrap(),
        parted.read_positions().unwrap(),
    );
    let (sa, sb) = (whole.read_state().unwrap(), parted.read_state().unwrap());
    assert!(sa.cg_iterations_total > 30, "the solves ran: {sa:?}");
    assert_eq!(sa.cg_iterations_total, sb.cg_iterations_total);
    assert!(a.iter().all(|p| p.is_finite()));
    assert_eq!(a, b, "positions differ once arrays are bound in parts");

    let err = GpuSim::with_kernels(
        &narrow,
        &device,
        &queue,
        &hang_solved(48, MULTIGRID, 40, 1e-3),
    )
    .err()
    .expect("a 48² topology does not fit three 96 KiB bindings")
    .to_string();
    assert!(
        err.contains("topology") && err.contains("max_storage_buffer_binding_size"),
        "{err}"
    );
}

/// The scene's GPU state holds at least the step's per-vertex vectors
/// (x, v and their checkpoint copies, rest: 5 `vec4`s; b, r, z and q, both
/// directions, P⁻¹: 7 packed vec3s) and grows with the cloth, not faster.
#[test]
fn state_bytes_count_the_per_vertex_vectors_and_grow_with_the_cloth() {
    let Some((ctx, kernels)) = gpu() else { return };
    let bytes = |grid: u32| {
        let scene = sphere(grid, ModelKind::Friction);
        let sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        let n = scene.cloth.vertex_count() as u64;
        assert!(
            sim.state_bytes() >= (5 * 16 + 7 * 12) * n,
            "{grid}²: {}",
            sim.state_bytes()
        );
        sim.state_bytes() as f64
    };
    let growth = bytes(64) / bytes(32);
    assert!((3.0..=4.5).contains(&growth), "64² / 32²: {growth}");
}

#[test]
fn a_sphere_crossing_at_10_m_per_s_leaves_no_vertex_inside_on_the_gpu() {
    let Some((ctx, kernels)) = gpu() else { return };
    let (c, steps) = common::crossing_config(10.0, 16);
    let scene = Scene::new(&c).unwrap();
    let body = scene.rigid.clone().unwrap();
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    let mut cpu = CpuSim::new(scene);
    for k in 1..=steps {
        gpu.step();
        cpu.step();
        let x = gpu.read_positions().unwrap();
        let inside = common::deepest_inside(&body, cpu.state.time, &x);
        assert!(inside < 1e-5, "step {k}: a vertex ends {inside} m inside");
        let dev = max_dev(&x, &cpu.state.x);
        assert!(dev < 1e-3, "step {k}: GPU and CPU {dev} m apart");
    }
    let deepest = f32::from_bits(gpu.read_state().unwrap().max_penetration_bits);
    eprintln!("{steps} steps: deepest after the solve {deepest:.4} m");
    assert!(
        deepest > c.contact.max_depth,
        "the sphere must reach past the band"
    );
}

#[test]
fn the_body_is_placed_from_the_step_count_as_on_the_cpu_far_into_a_run() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = sphere(4, ModelKind::Friction);
    let body = scene.rigid.as_ref().unwrap();
    let h = scene.config.solver.dt;
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    let x = scene.cloth.rest_positions.clone();
    let v = vec![Vec3::ZERO; x.len()];
    // Step 100 000 (1000 s), where an f32 sum of h was 0.66 s off, and a
    // step a quarter period later, where the sphere moves fastest.
    for clock in [100_000u32, 100_050] {
        gpu.upload_state(&x, &v, clock);
        gpu.step();
        let placed = gpu.read_vec3(gpu.body().0).unwrap();
        let t = ((clock + 1) as f64 * h as f64) as f32;
        let mut frame = wgcloth::cpu::rigid::RigidFrame::default();
        wgcloth::cpu::rigid::transform(body, t, &mut frame);
        let dev = max_dev(&placed, &frame.vertices[..placed.len()]);
        eprintln!("step {clock}: body {dev:.1e} m from the CPU's at t = {t} s");
        assert!(
            dev < 1e-5,
            "step {clock}: the GPU placed the body {dev} m off"
        );
    }
}

#[test]
fn a_coarse_cloth_keeps_every_face_vertex_contact_and_repeats_bit_for_bit() {
    let Some((ctx, kernels)) = gpu() else { return };
    for model in [ModelKind::Friction, ModelKind::FrictionNet] {
        // 0.2 m cells against a sphere of 642 vertices: many rigid vertices
        // fall on one cloth triangle at once.
        let scene = sphere(6, model);
        let steps = 100;
        let run = |count: bool| {
            let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
            let mut solved = SolvedSteps::for_scene(&gpu, &scene);
            let mut most = 0;
            for _ in 0..steps {
                solved.step(&gpu).unwrap();
                if count {
                    let (_, face_vertex) = gpu.read_contacts().unwrap();
                    let mut per_triangle = vec![0; scene.cloth.triangles.len()];
                    for (c, _) in face_vertex.iter().filter(|(c, _)| c.valid != 0) {
                        per_triangle[c.triangle as usize] += 1;
                    }
                    most = most.max(per_triangle.into_iter().max().unwrap_or(0));
                }
            }
            (gpu.read_positions().unwrap(), most)
        };
        let ((first, most), (second, _)) = (run(true), run(false));
        let cpu = cpu_after(&scene, steps);
        let dev = max_dev(&first, &cpu.state.x);
        eprintln!(
            "{model:?}: at most {most} face–vertex contacts on one triangle; GPU–CPU {dev:.2e} m"
        );
        assert!(
            most > 8,
            "the scene must put more than 8 contacts on a triangle"
        );
        let bits = |x: &[Vec3]| {
            x.iter()
                .flat_map(|p| p.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        assert!(
            bits(&first) == bits(&second),
            "{model:?}: two runs of the same scene differ"
        );
        assert!(dev < 1e-3, "{model:?}: GPU and CPU drifted {dev} m apart");
    }
}

/// `SolvedSteps` records the iterations its budget gives and solves a step
/// the budget cut again from its start with the whole cap: every step, and
/// the run's statistics, end bit for bit where steps recording the cap end.
#[test]
fn solved_steps_end_where_steps_recording_the_cap_end() {
    let Some((ctx, kernels)) = gpu() else { return };
    // Jacobi's steps take tens of iterations to 1e-5, the budget's first 17.
    let scene = hang_solved(12, PRECONDITIONERS[0], 300, 1e-5);
    let capped = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    let budgeted = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    let mut budget = CgBudget::new(300, 1e-5);
    // A budget that has seen only one-iteration steps cuts the first ones.
    for _ in 0..CgBudget::WINDOW {
        budget.observe(1, 300, 0.0);
    }
    let mut solved = SolvedSteps::new(&budgeted, budget);
    let bits = |sim: &GpuSim| {
        let (x, v) = (
            sim.read_positions().unwrap(),
            sim.read_velocities().unwrap(),
        );
        let state = sim.read_state().unwrap();
        let words: Vec<u32> = x
            .iter()
            .chain(&v)
            .flat_map(|p| p.to_array().map(f32::to_bits))
            .collect();
        (words, bytemuck::bytes_of(&state).to_vec())
    };
    let mut most = 0;
    for step in 1..=12 {
        capped.step();
        let state = solved.step(&budgeted).unwrap();
        most = most.max(state.last_iterations);
        assert!(
            bits(&capped) == bits(&budgeted),
            "step {step}: the budgeted run left the capped one"
        );
    }
    eprintln!(
        "{} of 12 steps solved again, at most {most} iterations, the last budget {}",
        solved.resolved(),
        budgeted.cg_budget()
    );
    assert!(
        solved.resolved() > 0,
        "no step was cut: the repeat went untested"
    );
    assert!(
        budgeted.cg_budget() < 200,
        "the budget never fell below the cap"
    );
}

/// A context compiles its kernels once: later calls, and its clones made
/// before or after, get the same ones.
#[test]
fn a_context_compiles_its_kernels_once() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let before = ctx.clone();
    let first = ctx.kernels().unwrap();
    assert!(Arc::ptr_eq(&first, &ctx.kernels().unwrap()));
    assert!(Arc::ptr_eq(&first, &before.kernels().unwrap()));
    assert!(Arc::ptr_eq(&first, &ctx.clone().kernels().unwrap()));
}
