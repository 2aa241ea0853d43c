//! Whole runs on the GPU against the CPU's: scenes stepped on both paths,
//! the solve's stopping, arrays bound in parts. Without an adapter these
//! tests fail unless WGCLOTH_NO_GPU_TESTS=1 opts out.

mod common;
#[path = "common/parity.rs"]
mod parity;

use common::sphere;
use parity::{
    MULTIGRID, PRECONDITIONERS, cpu_after, full, gpu, gpu_solves, hang_solved, mat_dev, max_dev,
    max_norm, solved_whole,
};
use wgcloth::config::{ModelKind, Preconditioner};
use wgcloth::cpu::CpuSim;
use wgcloth::gpu::{CgBudget, GpuContext, GpuSim, Kernels, SolvedSteps, context};
use wgcloth::sensitivity::{Reference, Sensitivity};
use wgcloth::{Config, Scene};

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

/// Each preconditioner over 60 steps, multigrid's solve both as a chain of
/// dispatches and run whole in one workgroup (`solver.whole_solve_nodes`).
#[test]
fn hanging_cloth_runs_like_the_cpu_for_60_steps() {
    let Some((ctx, kernels)) = gpu() else { return };
    // A fixed iteration count on both sides (tolerance 0): the thesis's 25
    // Jacobi iterations, and 5 multigrid V-cycles, about what 1e-3 takes.
    for (solve, whole) in gpu_solves() {
        let (preconditioner, smoother) = solve;
        // Multigrid at 33²: on lavapipe its second level (17², past
        // `tail_nodes`) has its own dispatches in the chain, as the cloth's.
        let (grid, iters) = match preconditioner {
            Preconditioner::Jacobi => (16, 25),
            Preconditioner::Multigrid => (33, 5),
        };
        let scene = solved_whole(hang_solved(grid, solve, iters, 0.0), whole);
        let cpu = cpu_after(&scene, 60);
        let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        assert_eq!(gpu.solved_whole(), whole);
        for _ in 0..60 {
            gpu.step();
        }
        let x = gpu.read_positions().unwrap();
        let dev = max_dev(&x, &cpu.state.x);
        let state = gpu.read_state().unwrap();
        let how = format!("{preconditioner:?} ({smoother:?}, whole {whole})");
        eprintln!("{how}, 60 steps: largest position deviation {dev:.3e} m; GPU state {state:?}");
        assert_eq!(state.steps, 60);
        assert_eq!(state.cg_iterations_total, 60 * iters);
        assert_eq!(state.clock, 60);
        assert!(dev < 1e-4, "{how}: GPU and CPU drifted {dev} m apart");
        for (i, p) in scene.cloth.pinned.iter().enumerate() {
            if *p {
                assert_eq!(x[i], scene.cloth.rest_positions[i]);
            }
        }
    }
}

/// Issue 67's short step: the thesis scene at 32² and 64², its solves run
/// whole, records at most 100 dispatches a step, the same whatever the
/// iteration budget; the chain of dispatches records more the more
/// iterations it is given.
#[test]
fn a_step_solved_whole_records_at_most_100_dispatches_whatever_its_iterations() {
    let Some((ctx, kernels)) = gpu() else { return };
    let recorded = |sim: &GpuSim, budget: u32| {
        sim.set_cg_budget(budget);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        sim.encode_step(&mut encoder)
    };
    for grid in [32, 64] {
        let mut scene = sphere(grid, ModelKind::FrictionNet);
        let whole = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        assert!(
            whole.solved_whole(),
            "{grid}²: the default solve is not whole"
        );
        let (few, many) = (recorded(&whole, 1), recorded(&whole, 200));
        eprintln!("{grid}²: {few} dispatches a step solved whole");
        assert_eq!(
            few, many,
            "{grid}²: the whole solve's dispatches follow the budget"
        );
        assert!(few <= 100, "{grid}²: {few} dispatches a step");
        scene.config.solver.whole_solve_nodes = 0;
        let chain = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        let (few, many) = (recorded(&chain, 1), recorded(&chain, 40));
        eprintln!("{grid}²: {few} to {many} dispatches a step as a chain");
        assert!(
            many > few + 39,
            "{grid}²: the chain's dispatches do not grow"
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
    gpu.upload_state(&cpu.state);
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

#[test]
fn thesis_scene_runs_like_the_cpu_with_both_models() {
    let Some((ctx, kernels)) = gpu() else { return };
    // Friction's solves run whole in one workgroup, the naive model's as
    // a chain of dispatches.
    for (model, whole) in [(ModelKind::Friction, true), (ModelKind::Naive, false)] {
        let scene = solved_whole(sphere(16, model), whole);
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
            "{model:?} (whole {whole}), {steps} steps: position deviation {dev:.3e} m; contacts {} vs {cpu_contacts}; deepest {deepest:.4} vs {cpu_deepest:.4}",
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
fn converged_pcg_stops_early_on_the_gpu_as_on_the_cpu() {
    let Some((ctx, kernels)) = gpu() else { return };
    for (solve, whole) in gpu_solves() {
        let (preconditioner, smoother) = solve;
        // An odd side: the last node of each axis is a coarse node itself.
        let scene = solved_whole(hang_solved(21, solve, 300, 1e-4), whole);
        let mut cpu = CpuSim::new(scene.clone());
        let mut cpu_iters = 0;
        let mut cpu_worst = 0.0f32;
        for _ in 0..20 {
            let out = cpu.step().pcg;
            cpu_iters += out.iterations;
            cpu_worst = cpu_worst.max(out.relative_residual);
        }
        let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
        assert_eq!(gpu.solved_whole(), whole);
        let mut solved = SolvedSteps::for_scene(&gpu, &scene);
        for _ in 0..20 {
            solved.step(&gpu).unwrap();
        }
        let state = gpu.read_state().unwrap();
        let gpu_iters = state.cg_iterations_total;
        eprintln!(
            "{preconditioner:?} ({smoother:?}, whole {whole}): PCG iterations over 20 steps: GPU {gpu_iters}, CPU {cpu_iters} \
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
            "{preconditioner:?} ({smoother:?}, whole {whole}): GPU {gpu_iters}, CPU {cpu_iters}"
        );
    }
}

/// A device whose bindings hold 96 bytes per vertex of a 32² hanging
/// cloth gets the topology (about 260 bytes per vertex), the matrix (160)
/// and the multigrid operators (205, with the patch inverses) bound in parts, as lavapipe gets them
/// at 1024² under its 128 MiB; the steps are bit for bit those of one
/// binding each. A cloth too large even for three parts is one clear error.
#[test]
fn arrays_past_the_binding_limit_are_bound_in_parts_and_step_bit_for_bit() {
    let Some((ctx, kernels)) = gpu() else { return };
    // The chain of dispatches: the solve of any cloth large enough to split.
    let scene = solved_whole(hang_solved(32, MULTIGRID, 40, 1e-3), false);
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
