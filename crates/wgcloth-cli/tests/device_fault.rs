//! Device faults end a GPU run with an error instead of a hang or a panic,
//! and a run that `auto` put on the GPU finishes on the CPU instead, with
//! a notice. The faults are real: the device is destroyed mid-run, or a
//! command buffer that fails validation is submitted to its queue.
//! Without an adapter these fail unless WGCLOTH_NO_GPU_TESTS=1 opts out.

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use std::sync::mpsc;
use std::time::Duration;

use wgcloth::config::{ModelKind, SceneKind};
use wgcloth::gpu::GpuContext;
use wgcloth::{Config, Error, Scene};
use wgcloth_cli::in_flight;
use wgcloth_cli::run::{self, Chosen, Observers, Report, Steps};

const STEPS: u64 = 30;
const FAULT_AT: u64 = 8;

/// The thesis scene at 8², the body in contact within the run.
fn scene() -> Scene {
    let mut c = Config {
        scene: SceneKind::Sphere,
        model: ModelKind::FrictionNet,
        ..Default::default()
    };
    c.cloth.grid = [8, 8];
    Scene::new(&c).expect("valid scene")
}

#[derive(Clone, Copy, Debug)]
enum Fault {
    /// `Device::destroy`: the device is lost.
    Lose,
    /// A copy of 3 bytes (copies need multiples of 4) fails validation
    /// and with it the submission.
    BadSubmission,
}

fn inject(ctx: &GpuContext, fault: Fault) {
    match fault {
        Fault::Lose => ctx.device.destroy(),
        Fault::BadSubmission => {
            let buffer = |usage| {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("fault"),
                    size: 16,
                    usage,
                    mapped_at_creation: false,
                })
            };
            let (from, to) = (
                buffer(wgpu::BufferUsages::COPY_SRC),
                buffer(wgpu::BufferUsages::COPY_DST),
            );
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&from, 0, &to, 0, 3);
            ctx.queue.submit([encoder.finish()]);
        }
    }
}

/// Runs the scene on `ctx` with the fault injected after step FAULT_AT,
/// on a thread so a hang fails the test instead of stalling the suite.
/// Returns the result and the notices.
fn run_with_fault(
    ctx: GpuContext,
    cpu_fallback: bool,
    fault: Fault,
) -> (wgcloth::Result<Report>, Vec<String>) {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let faulty = ctx.clone();
        let chosen = Chosen::Gpu {
            ctx: Box::new(ctx),
            cpu_fallback,
        };
        let mut notices = Vec::new();
        let result = run::run(
            &chosen,
            scene(),
            Steps::all(STEPS),
            Observers {
                progress: Some(&mut |done| {
                    if done == FAULT_AT {
                        inject(&faulty, fault)
                    }
                }),
                notice: Some(&mut |line| notices.push(line.to_string())),
                ..Default::default()
            },
        );
        let _ = tx.send((result, notices));
    });
    // A step here takes milliseconds; the watchdog is 120 s. Reaching this
    // means the fault was waited on, not detected.
    rx.recv_timeout(Duration::from_secs(60))
        .unwrap_or_else(|_| panic!("{fault:?}: the run hung instead of failing"))
}

fn gpu_error(result: wgcloth::Result<Report>, fault: Fault) -> String {
    match result {
        Err(Error::Gpu(what)) => what,
        Err(e) => panic!("{fault:?}: expected a GPU error, got: {e}"),
        Ok(r) => panic!("{fault:?}: the run finished ({} steps)", r.steps),
    }
}

#[test]
fn a_lost_device_ends_a_gpu_run_with_an_error() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let (result, notices) = run_with_fault(ctx, false, Fault::Lose);
    let what = gpu_error(result, Fault::Lose);
    assert!(
        what.contains("lost"),
        "the error says the device was lost: {what}"
    );
    assert!(notices.is_empty(), "no fallback without auto: {notices:?}");
}

#[test]
fn a_failed_submission_ends_a_gpu_run_with_an_error() {
    let Some(ctx) = common::gpu_context() else {
        return;
    };
    let (result, _) = run_with_fault(ctx, false, Fault::BadSubmission);
    let what = gpu_error(result, Fault::BadSubmission);
    assert!(
        what.starts_with("Validation Error: ") && what.contains("Copy size 3"),
        "one line naming the failed command: {what}"
    );
}

/// `auto` finishes on the CPU from the last checkpoint. The steps before
/// the fault take less than the checkpoint interval (which counts from
/// the first step, not from building the kernels), so that is the initial
/// state and the result is exactly a CPU run's.
#[test]
fn auto_finishes_on_the_cpu_after_a_device_fault() {
    let cpu =
        run::run(&Chosen::Cpu, scene(), Steps::all(STEPS), Default::default()).expect("CPU run");
    for fault in [Fault::Lose, Fault::BadSubmission] {
        let Some(ctx) = common::gpu_context() else {
            return;
        };
        let (result, notices) = run_with_fault(ctx, true, fault);
        let report = result.unwrap_or_else(|e| panic!("{fault:?}: auto failed: {e}"));
        let device_fault = report
            .device_fault
            .as_ref()
            .unwrap_or_else(|| panic!("{fault:?}: the report records the fault"));
        // The fault is injected when step FAULT_AT has been read; steps
        // submitted before it (up to the ring's depth) may still finish
        // and be read, and a CI run once read step FAULT_AT + 1 with it.
        assert!(
            (FAULT_AT + 1..=FAULT_AT + 1 + in_flight::DEPTH as u64)
                .contains(&device_fault.failed_at),
            "{fault:?}: failed at {}",
            device_fault.failed_at
        );
        assert_eq!(device_fault.resumed_from, 0, "{fault:?}");
        assert_eq!(notices.len(), 1, "{fault:?}: one notice: {notices:?}");
        assert!(
            notices[0].contains("continuing on the CPU reference path from step 0"),
            "{fault:?}: {}",
            notices[0]
        );
        assert_eq!(report.backend, "cpu");
        assert_eq!(report.steps, STEPS);
        assert_eq!(
            report.energy_final.to_bits(),
            cpu.energy_final.to_bits(),
            "{fault:?}: the CPU finished the same run"
        );
        assert!(report.summary().contains("GPU fault"), "{fault:?}");
    }
}
