//! The `wgcloth` binary as the CLI tests start it.

use std::process::Command;

/// `wgcloth run` on `backend` with the analytic friction model on
/// `scene`: the start the runs of several tests share; each adds its own
/// flags.
pub fn friction_run(scene: &str, backend: &str) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_wgcloth"));
    command.args([
        "run",
        "--backend",
        backend,
        "--scene",
        scene,
        "--model",
        "friction",
    ]);
    command
}
