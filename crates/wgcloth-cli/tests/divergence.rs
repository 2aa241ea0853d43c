//! Divergence is caught at the step it happens, on both paths: a vertex
//! past `solver.max_speed` names the fastest vertex, a non-finite value
//! names the vertex whose row it entered the system at (not the vertex 0
//! the solve spreads it to), the run stops there with the state before it
//! kept, and the CLI reports it in one line, in its report and as an OBJ.
//! Without an adapter the GPU halves fail unless WGCLOTH_NO_GPU_TESTS=1 opts out.

mod cli;

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use common::gpu_context as gpu;

use glam::Vec3;
use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::cpu::{CpuSim, State};
use wgcloth::gpu::{GpuSim, Kernels};
use wgcloth::health::{self, FailedStep, NOT_FINITE, TOO_FAST};
use wgcloth::math::Sym3;
use wgcloth::{Config, Scene};
use wgcloth_cli::run::{self, Chosen, Steps};

/// The hanging cloth at 8² (in the x-y plane, pinned at its top corners)
/// under gravity along −z: its free edge falls out of the plane at about
/// g h ≈ 0.098 m/s more each step, a step of `substeps` solves (0: the
/// scene's own, 1).
fn falling(max_speed: f32, substeps: u32) -> Scene {
    let mut c = Config {
        scene: SceneKind::Hang,
        model: ModelKind::Friction,
        ..Default::default()
    };
    c.cloth.grid = [8, 8];
    c.solver.max_speed = max_speed;
    c.solver.substeps = substeps;
    c.solver.gravity = [0.0, 0.0, -9.81];
    Scene::new(&c).expect("valid scene")
}

fn fastest(v: &[Vec3]) -> (u32, f32) {
    let (i, s) = v
        .iter()
        .map(|v| v.length())
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .expect("vertices");
    (i as u32, s)
}

/// What a plain CPU run sees at the first step whose fastest vertex
/// exceeds `max_speed`.
struct TooFast {
    step: u64,
    vertex: u32,
    /// Positions before the step, velocities after it.
    before: Vec<Vec3>,
    v: Vec<Vec3>,
}

fn first_too_fast(scene: &Scene, max_speed: f32) -> TooFast {
    let mut sim = CpuSim::new(scene.clone());
    for step in 1..100 {
        let before = sim.state.x.clone();
        sim.step();
        let (vertex, speed) = fastest(&sim.state.v);
        if speed > max_speed {
            let v = sim.state.v.clone();
            return TooFast {
                step,
                vertex,
                before,
                v,
            };
        }
    }
    panic!("the cloth never got faster than {max_speed} m/s");
}

#[test]
fn a_run_past_max_speed_stops_at_that_step_naming_the_fastest_vertex() {
    // The third step crosses 0.25 m/s with a margin no rounding closes.
    let max_speed = 0.25;
    let scene = falling(max_speed, 0);
    let TooFast {
        step,
        vertex,
        before,
        v,
    } = first_too_fast(&scene, max_speed);
    assert!(step > 1, "the first step should be good");
    let mut backends = vec![Chosen::Cpu];
    if let Some(ctx) = gpu() {
        backends.push(Chosen::gpu(ctx));
    }
    for backend in &backends {
        let report =
            run::run(backend, scene.clone(), Steps::all(50), Default::default()).expect("runs");
        let what = &report.backend;
        let d = report.divergence.as_ref().expect("diverged");
        assert_eq!(d.step, step, "{what}: {d:?}");
        if what == "cpu" {
            assert_eq!(d.vertex, vertex, "{what}: {d:?}");
        } else {
            // Free-falling vertices tie up to rounding: the GPU may name
            // another as fast as the CPU's fastest.
            let speed = |i: u32| v[i as usize].length();
            assert!(
                (speed(d.vertex) - speed(vertex)).abs() < 1e-4 * speed(vertex),
                "{what}: {d:?}"
            );
        }
        assert!(d.reason.contains("max_speed"), "{what}: {}", d.reason);
        assert_eq!(report.steps, step, "{what}: the run stops at the step");
        let good = report.last_good.as_ref().expect("the last good state");
        assert_eq!(good.step, step - 1, "{what}");
        let off = good
            .x
            .iter()
            .zip(&before)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0f32, f32::max);
        assert!(off < 1e-5, "{what}: last good state {off} m off");
        assert!(run::check_diverged(&report).is_err());
    }
}

/// A NaN velocity enters the system at its vertex's row. A step of two
/// solves spreads it everywhere by the second, so the run loop solves the
/// failing step again solve by solve (`run::cpu_failing_solve`,
/// `run::gpu_failing_solve`) and the diagnosis reads the first's system.
#[test]
fn a_non_finite_velocity_is_named_at_its_vertex_on_both_paths() {
    let scene = falling(100.0, 2);
    let bad = 37usize;
    let mut cpu = CpuSim::new(scene.clone());
    cpu.step();
    let (x0, mut v0) = (cpu.state.x.clone(), cpu.state.v.clone());
    v0[bad] = Vec3::new(f32::NAN, 0.0, 0.0);
    cpu.state.v = v0.clone();
    assert!(cpu.step().pcg.breakdown);
    cpu.state.x = x0.clone();
    cpu.state.v = v0.clone();
    let (flags, breakdown) = run::cpu_failing_solve(&mut cpu, 100.0);
    assert_eq!(flags & NOT_FINITE, NOT_FINITE);
    let (matrix, b) = cpu.system();
    let d = health::diagnose(&FailedStep {
        step: 2,
        flags,
        breakdown,
        diag: &matrix.diag,
        b,
        x: &cpu.state.x,
        v: &cpu.state.v,
        max_speed: 100.0,
    });
    assert_eq!(d.vertex, bad as u32, "{d:?}");
    assert!(d.reason.contains("system"), "{}", d.reason);

    let Some(ctx) = gpu() else { return };
    let kernels = std::sync::Arc::new(Kernels::new(&ctx.device).expect("kernels"));
    let sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).expect("fits");
    let start = State::at(x0.clone(), v0.clone(), 1, scene.config.solver.dt);
    sim.upload_state(&start);
    sim.step();
    ctx.finish().expect("device healthy");
    let state = sim.read_state().expect("state");
    assert_eq!(state.health & NOT_FINITE, NOT_FINITE, "{state:?}");
    // Both solves broke down; counted as the CPU counts: one step.
    assert_eq!(state.cg_breakdowns, 1, "{state:?}");
    sim.upload_state(&start);
    let (flags, breakdown) = run::gpu_failing_solve(&ctx, &sim, scene.substeps).expect("runs");
    let (diag, _, b) = sim.read_system().expect("system");
    let (x, v) = (
        sim.read_positions().unwrap(),
        sim.read_velocities().unwrap(),
    );
    let gpu_d = health::diagnose(&FailedStep {
        step: 2,
        flags,
        breakdown,
        diag: &diag,
        b: &b,
        x: &x,
        v: &v,
        max_speed: 100.0,
    });
    assert_eq!(gpu_d.vertex, bad as u32, "{gpu_d:?}");
    // Replacing the state clears the flag.
    let still = vec![Vec3::ZERO; x0.len()];
    sim.upload_state(&State::at(x0.clone(), still, 0, scene.config.solver.dt));
    ctx.finish().expect("device healthy");
    assert_eq!(sim.read_state().unwrap().health, 0);
}

#[test]
fn the_gpu_raises_the_same_flags_as_the_cpu() {
    let Some(ctx) = gpu() else { return };
    let scene = falling(0.05, 0);
    let kernels = std::sync::Arc::new(Kernels::new(&ctx.device).expect("kernels"));
    let sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).expect("fits");
    let mut cpu = CpuSim::new(scene);
    for step in 1..=4 {
        sim.step();
        cpu.step();
        ctx.finish().expect("device healthy");
        let gpu_flags = sim.read_state().unwrap().health;
        let cpu_flags = wgcloth::cpu::integrate::health(&cpu.state.x, &cpu.state.v, 0.05);
        // Sticky on the GPU: compare while the CPU's are rising.
        assert_eq!(gpu_flags & TOO_FAST, cpu_flags & TOO_FAST, "step {step}");
        if cpu_flags != 0 {
            return;
        }
    }
    panic!("the cloth never got faster than 0.05 m/s");
}

#[test]
fn a_breakdown_names_the_vertex_whose_block_is_not_positive_definite() {
    let n = 9;
    let mut diag = vec![Sym3::from_diagonal(Vec3::ONE); n];
    diag[5] = Sym3::from_diagonal(Vec3::new(1.0, -2.0, 1.0));
    let zeros = vec![Vec3::ZERO; n];
    let d = health::diagnose(&FailedStep {
        step: 3,
        flags: 0,
        breakdown: true,
        diag: &diag,
        b: &zeros,
        x: &zeros,
        v: &zeros,
        max_speed: 1.0,
    });
    assert_eq!((d.step, d.vertex), (3, 5), "{d:?}");
    assert!(d.reason.contains("positive definite"), "{}", d.reason);
}

#[test]
fn the_cli_reports_a_divergence_in_one_line_and_keeps_the_last_good_state() {
    let dir = std::env::temp_dir().join(format!("wgcloth-diverge-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (report, obj) = (dir.join("r.json"), dir.join("good.obj"));
    let config = dir.join("fall.toml");
    std::fs::write(&config, "[solver]\ngravity = [0.0, 0.0, -9.81]\n").unwrap();
    let out = cli::friction_run("hang", "cpu")
        .args(["--grid", "8", "--steps", "50", "--max-speed", "0.25"])
        .arg("--config")
        .arg(&config)
        .arg("--report")
        .arg(&report)
        .arg("--last-good")
        .arg(&obj)
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    let TooFast { step, vertex, .. } = first_too_fast(&falling(0.25, 0), 0.25);
    assert!(
        lines[0].contains(&format!("diverged at step {step}, vertex {vertex}")),
        "{stderr}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).expect("report")).unwrap();
    assert_eq!(json["divergence"]["step"], step);
    assert_eq!(json["divergence"]["vertex"], vertex);
    let (models, _) = tobj::load_obj(&obj, &tobj::LoadOptions::default()).expect("OBJ");
    let cloth = models.iter().find(|m| m.name == "cloth").expect("cloth");
    assert_eq!(cloth.mesh.positions.len(), 3 * 64);
    std::fs::remove_dir_all(&dir).ok();
}
