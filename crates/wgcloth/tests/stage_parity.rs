//! Each GPU stage against its CPU twin on the same state, on lavapipe (or
//! any adapter). Without an adapter these tests fail unless
//! WGCLOTH_NO_GPU_TESTS=1 opts out.

mod common;
#[path = "common/parity.rs"]
mod parity;
#[path = "common/scenes.rs"]
mod scene_files;

use std::sync::Arc;

use common::sphere;
use glam::Vec3;
use parity::{
    cpu_after, full, gpu, gpu_solves, hang, hang_solved, mat_dev, max_dev, max_norm, random_mlp,
    solved_whole,
};
use scene_files::edge_on_pleat;
use wgcloth::bvh::Bvh;
use wgcloth::config::{ModelKind, Preconditioner, Smoother};
use wgcloth::cpu::impact;
use wgcloth::cpu::pcg::{self, PcgScratch, SolveSettings};
use wgcloth::cpu::{CpuSim, PERTURBATION, State, StepStats, integrate, self_contact, separate};
use wgcloth::gpu::context::computes_as_the_cpu;
use wgcloth::gpu::layout::{StepState, VectorLayout};
use wgcloth::gpu::{GpuContext, GpuSim, Kernels, SolvedSteps, context};
use wgcloth::intersections::intersecting_pairs;
use wgcloth::math::closest_on_triangle;
use wgcloth::stage::Stage;
use wgcloth::{Config, Scene};

/// Stage "assemble", springs included: the system from the same state.
#[test]
fn assembly_matches_the_cpu_on_the_same_state() {
    let Some((ctx, kernels)) = gpu() else { return };
    let scene = hang(12);
    let mut cpu = cpu_after(&scene, 7);
    let gpu = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    gpu.upload_state(&cpu.state);
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
        gpu.upload_state(&cpu.state);
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
    gpu.upload_state(&cpu.state);
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
    gpu.upload_state(&cpu.state);
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
    gpu.upload_state(&State::at(x.clone(), v.clone(), 0, scene.config.solver.dt));
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
    for (solve, whole) in gpu_solves() {
        // 441 vertices: in the chain the second workgroup of each dispatch
        // partial; whole, the last lanes' strides one vertex short.
        let scene = solved_whole(hang_solved(21, solve, 300, 1e-4), whole);
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
            "{solve:?} (whole {whole}): iterations {} with subgroups, {} without; positions differ by {:.2e} m",
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
        gpu.upload_state(&State::at(x.clone(), v.clone(), clock as u64, h));
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

/// Stage "separate" on the GPU finds the near pairs and least separations
/// the CPU does and changes the same steps, to the bit, on a cloth pushed
/// into pleats (the pleat scene after 1.2 s, a step of 3 and of 15 times
/// its velocities taken from the state uploaded to both, after 1.25 s one
/// of twice them, and after 1.5 s one of 10 times, so that many pairs
/// fail: impulses alone, then zones, the box stopping steps, pairs that
/// overflow the GPU's list, so that its passes walk the cloth again, and
/// at 1.25 s the last resort).
#[test]
fn the_gpu_finds_and_changes_what_the_cpu_does_on_a_pleated_cloth() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let scene = Scene::new(&edge_on_pleat()).unwrap();
    let mut cpu = CpuSim::new(scene.clone());
    let gpu = GpuSim::new(&ctx.device, &ctx.queue, &scene).unwrap();
    let capacity = separate::NEAR_PAIRS_PER_VERTEX as usize * scene.cloth.vertex_count();
    let (mut overflowed, mut zones, mut last_resort, mut box_stops) = (false, false, false, false);
    // 1.2 s in, then 1.25 s and 1.5 s in, where the box pushes the pile.
    for (at, factor) in [(120, 3.0), (120, 15.0), (125, 2.0), (150, 10.0)] {
        while cpu.state.step < at {
            cpu.step();
        }
        let start = &cpu.state.x;
        let v: Vec<_> = cpu.state.v.iter().map(|v| factor * *v).collect();
        let h = scene.config.solver.dt;
        let (mut x, mut solved) = (start.clone(), v.clone());
        integrate::integrate(&scene.cloth, h, &mut x, &mut solved);
        let triangles = &scene.cloth.triangles;
        let d: Vec<_> = x.iter().zip(start).map(|(x, s)| *x - *s).collect();
        let mut bvh = Bvh::build(&separate::swept_boxes(start, &x, triangles));
        let edges = separate::triangle_edges(triangles);
        let keep = &scene.config.self_contact;
        let (pairs, want) = separate::near_pairs(start, &d, triangles, &edges, &bvh, keep);
        // Where the box bounds the steps: the contacts found from the start.
        let mut probe = CpuSim::new(scene.clone());
        probe.state = cpu.state.clone();
        for stage in [Stage::Rigid, Stage::Collide] {
            probe.run_stage(stage, &mut StepStats::default());
        }
        let body = impact::body_gaps(probe.contacts(), &scene.cloth.pinned, h);
        let within = separate::Within {
            triangles,
            edges: &edges,
            keep,
            mu: scene.config.contact.mu,
            fixed: &scene.cloth.pinned,
            body: &body,
            h,
        };
        let done = within.keep_apart(start, &mut x, &mut solved, &mut bvh);

        let before = gpu.read_state().unwrap();
        gpu.upload_state(&State::at(start.to_vec(), v.clone(), cpu.state.step, h));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        for stage in [
            Stage::Rigid,
            Stage::Collide,
            Stage::Integrate,
            Stage::Separate,
        ] {
            gpu.record_stage(&mut encoder, stage);
        }
        ctx.queue.submit([encoder.finish()]);
        let (_, gpu_pairs) = gpu.read_separations().unwrap();
        let after = gpu.read_state().unwrap();
        let gpu_x = gpu.read_positions().unwrap();
        let gpu_v = gpu.read_velocities().unwrap();
        let total = |f: fn(&StepState) -> u32| (f(&after) - f(&before)) as usize;
        let pushed = total(|s| s.self_pushed_total);
        let zoned = total(|s| s.self_zoned_total);
        let stopped = total(|s| s.self_stopped_total);
        let held = total(|s| s.self_held_total);
        let detections = total(|s| s.self_detections_total) as u32;

        let apart = |a: &[glam::Vec3], b: &[glam::Vec3]| {
            (a.iter().zip(b))
                .map(|(a, b)| (*a - *b).length())
                .fold(0.0f32, f32::max)
        };
        let near = want.iter().filter(|s| s.is_finite()).count();
        eprintln!(
            "x{factor}: {near} of {} vertices in {} near pairs at first (GPU, last detection: {gpu_pairs}); \
             pushed {} (GPU {pushed}), zoned {} (GPU {zoned}), stopped by the box {} (GPU {stopped}), \
             held {} (GPU {held}), {} detections (GPU {detections}); \
             positions {:.2e} m, velocities {:.2e} m/s apart",
            start.len(),
            pairs.len(),
            done.pushed,
            done.zoned,
            done.stopped,
            done.held,
            done.detections,
            apart(&gpu_x, &x),
            apart(&gpu_v, &solved),
        );
        assert!(done.pushed > 0, "x{factor}: impulses");
        zones |= done.zoned > 0;
        if computes_as_the_cpu(&ctx.adapter) {
            assert_eq!(
                (pushed, zoned, stopped, held, detections),
                (
                    done.pushed,
                    done.zoned,
                    done.stopped,
                    done.held,
                    done.detections
                ),
                "x{factor}"
            );
            assert_eq!(apart(&gpu_x, &x), 0.0, "x{factor}: positions");
            assert_eq!(apart(&gpu_v, &solved), 0.0, "x{factor}: velocities");
        } else {
            // A GPU that fuses multiply-adds tests some pair an ulp
            // otherwise, and where zones form, that moves whole zones: it
            // must only keep the cloth whole, and, where pairs are few,
            // end within rounding of the CPU.
            assert!(
                intersecting_pairs(&gpu_x, triangles).is_empty(),
                "x{factor}"
            );
            if factor < 5.0 {
                assert!(apart(&gpu_x, &x) <= 1e-6, "x{factor}: positions");
            }
        }
        overflowed |= pairs.len() > capacity;
        last_resort |= done.held > 0;
        box_stops |= done.stopped > 0;
    }
    assert!(overflowed, "one case overflows the list");
    assert!(zones, "one case forms impact zones");
    assert!(last_resort, "one case reaches the last resort");
    assert!(box_stops, "the box stops a changed step");
}

/// Stage "self_contact" on the GPU finds the cloth–cloth contacts the CPU
/// does and adds the same terms to A and b, and the GPU's solve, with the
/// contacts' blocks outside the springs' pattern, gives the CPU's
/// velocities: the pleat scene's cloth with its top quarter folded down
/// onto it, 3 mm above (within the 5 mm thickness), turned a little and
/// sliding, uploaded to both, and one step's stages up to the solve
/// recorded on both. Without those blocks the CPU's solve lands far from
/// both (so the comparison can tell). Folded in half, the cloth has more
/// contacts than the GPU's list holds: it counts the ones left out.
#[test]
fn the_gpu_pushes_the_cloth_against_itself_as_the_cpu_does() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let mut config = edge_on_pleat();
    (config.solver.cg_tol, config.solver.cg_iters) = (1e-6, 400);
    let scene = Scene::new(&config).unwrap();
    let (_, gpu, stats) = folded(&ctx, &scene, 2);
    let capacity = 4 * scene.cloth.vertex_count();
    assert!(stats.self_contacts > capacity && stats.self_contacts_dropped == 0);
    let dropped = gpu.read_state().unwrap().cloth_contacts_dropped as usize;
    assert_eq!(
        dropped,
        stats.self_contacts - capacity,
        "counted on the GPU"
    );

    let (mut cpu, gpu, mut stats) = folded(&ctx, &scene, 4);

    let (pairs, terms) = cpu.self_contacts();
    let got = gpu.read_cloth_contacts().unwrap();
    let edge_pairs = pairs.iter().filter(|p| p.edges).count();
    eprintln!(
        "{} cloth–cloth contacts ({edge_pairs} edge–edge), GPU {}",
        pairs.len(),
        got.len()
    );
    assert!(edge_pairs >= 20 && pairs.len() - edge_pairs >= 20);
    let keys: Vec<[u32; 4]> = pairs.iter().map(self_contact::Pair::key).collect();
    assert_eq!(got.iter().map(|p| p.key).collect::<Vec<_>>(), keys);
    let biggest = |m: glam::Mat3| m.to_cols_array().iter().fold(0.0f32, |a, b| a.max(b.abs()));
    let block_scale = terms.iter().map(|t| biggest(t.block)).fold(0.0, f32::max);
    let rhs_scale = terms.iter().map(|t| t.rhs.length()).fold(0.0, f32::max);
    for ((p, t), g) in pairs.iter().zip(terms).zip(&got) {
        let beta = glam::Vec4::from_array(p.beta) - glam::Vec4::from_array(g.beta);
        assert!(beta.abs().max_element() <= 1e-4, "{p:?}");
        assert!(
            biggest(g.block.to_mat3() - t.block) <= 1e-4 * block_scale,
            "{p:?}"
        );
        assert!(
            (glam::Vec3::from_array(g.rhs) - t.rhs).length() <= 1e-4 * rhs_scale,
            "{p:?}"
        );
    }
    let (gpu_diag, _, gpu_b) = gpu.read_system().unwrap();
    let (matrix, b) = cpu.system();
    for i in 0..b.len() {
        let d = matrix.diag[i].to_mat3();
        assert!(
            biggest(gpu_diag[i].to_mat3() - d) <= 1e-5 * biggest(d),
            "vertex {i}"
        );
        assert!(
            (gpu_b[i] - b[i]).length() <= 1e-5 * (1.0 + b[i].length()),
            "vertex {i}"
        );
    }

    let start_v = cpu.state.v.clone();
    let mut uncoupled = matrix.clone();
    uncoupled.couplings = Default::default();
    let mut without = start_v.clone();
    let settings = SolveSettings {
        max_iters: config.solver.cg_iters,
        tol: config.solver.cg_tol,
        preconditioner: config.solver.preconditioner,
        smoother: config.solver.smoother,
    };
    let b = b.to_vec();
    pcg::solve(
        &uncoupled,
        &scene.cloth,
        &b,
        &mut without,
        settings,
        &mut PcgScratch::default(),
    );
    cpu.run_stage(Stage::Pcg, &mut stats);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    gpu.record_stage(&mut encoder, Stage::Pcg);
    ctx.queue.submit([encoder.finish()]);
    let gpu_v = gpu.read_velocities().unwrap();
    let apart = |a: &[glam::Vec3], b: &[glam::Vec3]| {
        a.iter()
            .zip(b)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0f32, f32::max)
    };
    let (deviation, coupling) = (apart(&gpu_v, &cpu.state.v), apart(&without, &cpu.state.v));
    eprintln!(
        "velocities: GPU {deviation:.2e} m/s from the CPU; without the couplings {coupling:.2e} m/s"
    );
    assert!(stats.pcg.relative_residual <= 1e-6 && !stats.pcg.breakdown);
    assert!(
        deviation <= 0.02 * coupling,
        "GPU {deviation}, couplings {coupling}"
    );
}

/// The solver's vectors packed (three floats a vertex, a hardware GPU's
/// layout) and a `vec4` each (a CPU adapter's) give the same steps to the
/// bit, cloth–cloth couplings in the solve, with either preconditioner
/// and either smoother: the pleat scene folded as below, 3 steps.
#[test]
fn both_vector_layouts_step_bit_for_bit() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let layouts =
        VectorLayout::ALL.map(|layout| Kernels::with_vectors(&ctx.device, layout).unwrap());
    for (preconditioner, smoother) in [
        (Preconditioner::Multigrid, Smoother::Patches),
        (Preconditioner::Multigrid, Smoother::BlockJacobi),
        (Preconditioner::Jacobi, Smoother::Patches),
    ] {
        let mut config = edge_on_pleat();
        (config.solver.preconditioner, config.solver.smoother) = (preconditioner, smoother);
        let scene = Scene::new(&config).unwrap();
        let start = folded_state(&scene, 4);
        let runs = layouts.each_ref().map(|kernels| {
            let gpu = GpuSim::with_kernels(kernels, &ctx.device, &ctx.queue, &scene).unwrap();
            gpu.upload_state(&start.state);
            for _ in 0..3 {
                gpu.step();
            }
            let contacts = gpu.read_cloth_contacts().unwrap().len();
            (
                gpu.read_positions().unwrap(),
                gpu.read_state().unwrap(),
                contacts,
            )
        });
        let [(x, state, contacts), (x_vec4, state_vec4, _)] = &runs;
        let what = format!("{preconditioner:?}, {smoother:?}");
        assert!(*contacts > 0, "{what}: no cloth–cloth contacts to couple");
        assert!(state.cg_iterations_total > 3 && x.iter().all(|p| p.is_finite()));
        assert_eq!(
            state.cg_iterations_total, state_vec4.cg_iterations_total,
            "{what}"
        );
        assert_eq!(x, x_vec4, "{what}: the layouts' positions differ");
    }
}

/// Where a grid's neighbours lie within 2ε at rest (here the thickness is
/// 0.53 spacings), the walks name no pair one of whose vertices is near
/// one of the other side's at rest (`separate::candidates`;
/// `refused_corners` in wgsl/self_contact.wgsl), and each pair tests its
/// vertices' rest distances before any geometry
/// (`Sheet::vertices_near_at_rest`): the GPU still finds what the CPU
/// does, contact for contact, on the folded pleat scene.
#[test]
fn both_paths_find_the_same_contacts_where_neighbours_are_near_at_rest() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let (scene, _) = pleat_with_thickness(0.53);
    let (cpu, gpu, stats) = folded(&ctx, &scene, 4);
    assert_eq!(stats.self_contacts_dropped, 0);
    let (pairs, _) = cpu.self_contacts();
    let edge_pairs = pairs.iter().filter(|p| p.edges).count();
    assert!(
        edge_pairs >= 20 && pairs.len() - edge_pairs >= 20,
        "{}",
        pairs.len()
    );
    let keys: Vec<[u32; 4]> = pairs.iter().map(self_contact::Pair::key).collect();
    let got = gpu.read_cloth_contacts().unwrap();
    assert_eq!(got.iter().map(|p| p.key).collect::<Vec<_>>(), keys);
}

/// A cell with a corner within 2ε of the walk's vertex at rest, on the
/// diagonal its triangles share, may still hold a contact with it: its
/// left edge, 2ε apart at rest, carried under one of the vertex's edges.
/// The walks refuse only pairs the rule refuses (`separate::candidates`
/// and `passed_over`; wgsl/walk.wgsl `cell_pairs` with
/// wgsl/self_contact.wgsl `refused_corners`), so both paths find it.
#[test]
fn the_walks_keep_a_contact_with_a_cell_that_has_a_corner_near_at_rest() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    // 2ε = 1.5 spacings: the rest neighbours within it are those 1 and √2
    // spacings away.
    let (scene, spacing) = pleat_with_thickness(0.75);
    let nx = scene.cloth.nx;
    let mut cpu = CpuSim::new(scene.clone());
    let x = &mut cpu.state.x;
    let (right, up) = (x[1] - x[0], x[nx as usize] - x[0]);
    let below = right.cross(up).normalize() * (-0.3 * spacing);
    // Cell (cx, cy), its diagonal from (cx + 1, cy) to (cx, cy + 1), and
    // vertex a √2 spacings from its corner (cx + 1, cy) alone; the vertex's
    // edge up and the cell's left edge are 2 spacings apart.
    let (cx, cy) = (10, 4);
    assert_eq!((cx + cy) % 2, 0);
    let a = (cy - 1) * nx + cx + 2;
    let e = [a, a + nx];
    let f = [cy * nx + cx, (cy + 1) * nx + cx];
    let middle = (x[e[0] as usize] + x[e[1] as usize]) / 2.0;
    x[f[0] as usize] = middle - 0.5 * right + below;
    x[f[1] as usize] = middle + 0.5 * right + below;
    let (cpu, gpu, stats) = staged(&ctx, &scene, cpu);
    assert_eq!(stats.self_contacts_dropped, 0);
    let (pairs, _) = cpu.self_contacts();
    let keys: Vec<[u32; 4]> = pairs.iter().map(self_contact::Pair::key).collect();
    let pair = [e[0], e[1], f[0], f[1]];
    assert!(
        pairs.iter().any(|p| p.vertices == pair),
        "{pair:?} in {keys:?}"
    );
    let got = gpu.read_cloth_contacts().unwrap();
    assert_eq!(got.iter().map(|p| p.key).collect::<Vec<_>>(), keys);
}

/// The pleat scene with its self-contact thickness `spacings` of its
/// grid's spacing, and the spacing.
fn pleat_with_thickness(spacings: f32) -> (Scene, f32) {
    let mut config = edge_on_pleat();
    let spacing = config.cloth.size[0] / (config.cloth.grid[0] - 1) as f32;
    config.self_contact.thickness = spacings * spacing;
    (Scene::new(&config).unwrap(), spacing)
}

/// `scene`'s CPU state with the cloth's top 1/`part` folded down onto the
/// rest, 3 mm above it, turned and shifted a little and sliding.
fn folded_state(scene: &Scene, part: usize) -> CpuSim {
    let mut cpu = CpuSim::new(scene.clone());
    let (nx, ny) = (scene.cloth.nx as usize, scene.cloth.ny as usize);
    let rest = &scene.cloth.rest_positions;
    let turn = glam::Mat3::from_rotation_z(0.15);
    for (i, x) in cpu.state.x.iter_mut().enumerate() {
        let (r, c) = (i / nx, i % nx);
        if r < ny / part {
            let below = rest[(2 * (ny / part) - 1 - r) * nx + c];
            *x = turn * below + glam::Vec3::new(0.004, 0.0, 0.003);
        }
    }
    for (i, v) in cpu.state.v.iter_mut().enumerate() {
        let t = i as f32;
        *v = glam::Vec3::new(
            0.3 * (0.7 * t).sin(),
            0.2 * (1.3 * t).cos(),
            0.05 * (2.1 * t).sin(),
        );
    }
    cpu
}

/// [`folded_state`] uploaded to both paths, and a step's stages up to the
/// solve run on both.
fn folded(
    ctx: &wgcloth::gpu::GpuContext,
    scene: &Scene,
    part: usize,
) -> (CpuSim, GpuSim, StepStats) {
    staged(ctx, scene, folded_state(scene, part))
}

fn staged(
    ctx: &wgcloth::gpu::GpuContext,
    scene: &Scene,
    mut cpu: CpuSim,
) -> (CpuSim, GpuSim, StepStats) {
    let gpu = GpuSim::new(&ctx.device, &ctx.queue, scene).unwrap();
    gpu.upload_state(&cpu.state);
    let mut stats = StepStats::default();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    for stage in [
        Stage::Rigid,
        Stage::Collide,
        Stage::Contact,
        Stage::Assemble,
        Stage::SelfContact,
    ] {
        cpu.run_stage(stage, &mut stats);
        gpu.record_stage(&mut encoder, stage);
    }
    ctx.queue.submit([encoder.finish()]);
    (cpu, gpu, stats)
}
