//! `wgcloth run --worlds N` and `--sweep FILE` (issue 67): each world of a
//! batch ends where the same configuration run alone ends, whichever
//! sweep format set its values.

mod cli;

use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `wgcloth run` with `args` on `backend`; its `--report` JSON.
fn report(dir: &Path, backend: &str, name: &str, args: &[&str]) -> serde_json::Value {
    let path = dir.join(format!("{name}.json"));
    let out = cli::friction_run("sphere", backend)
        .args(["--grid", "8", "--steps", "25", "--report"])
        .arg(&path)
        .args(args)
        .output()
        .expect("the wgcloth binary starts");
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(&path).expect("report written"))
        .expect("report is JSON")
}

/// The sweeps in `sweeps/` name their worlds' values as the configuration
/// has them: what a user runs with `wgcloth run --sweep sweeps/NAME`.
#[test]
fn every_shipped_sweep_loads() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../sweeps");
    let mut files = 0;
    for entry in std::fs::read_dir(&dir).expect("sweeps/") {
        let path = entry.unwrap().path();
        let worlds = wgcloth_cli::sweep::read(&path, &wgcloth::Config::default())
            .unwrap_or_else(|e| panic!("{e}"));
        assert!(worlds.len() > 1, "{}", path.display());
        files += 1;
    }
    assert!(files > 0);
}

/// A fresh directory for test `name`'s files.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("wgcloth-worlds-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    dir
}

#[test]
fn each_world_of_a_sweep_ends_where_its_configuration_ends_alone() {
    sweep_ends_where_each_configuration_ends_alone("cpu");
}

/// The same on the GPU (lavapipe in CI), its batch in one step's dispatches.
#[test]
fn each_world_of_a_gpu_sweep_ends_where_its_configuration_ends_alone() {
    if std::env::var("WGCLOTH_NO_GPU_TESTS").is_ok_and(|v| v == "1") {
        eprintln!("skipping GPU test: WGCLOTH_NO_GPU_TESTS=1");
        return;
    }
    sweep_ends_where_each_configuration_ends_alone("gpu");
}

fn sweep_ends_where_each_configuration_ends_alone(backend: &str) {
    let dir = temp_dir(&format!("sweep-{backend}"));
    // μ, the springs' stiffness and the sphere's amplitude per world.
    let worlds = [(0.2, 3000.0, 0.25), (0.8, 5000.0, 0.3), (0.5, 8000.0, 0.2)];
    let mut csv = String::from("contact.mu,cloth.stiffness,rigid.motion.amplitude\n");
    let mut toml = String::new();
    for (mu, e, a) in worlds {
        csv += &format!("{mu},{e},{a}\n");
        toml += &format!(
            "[[world]]\ncontact.mu = {mu}\ncloth.stiffness = {e}\nrigid.motion.amplitude = {a}\n"
        );
    }
    let csv_path = dir.join("sweep.csv");
    let toml_path = dir.join("sweep.toml");
    std::fs::write(&csv_path, csv).unwrap();
    std::fs::write(&toml_path, toml).unwrap();
    let from_csv = report(
        &dir,
        backend,
        "csv",
        &["--sweep", csv_path.to_str().unwrap()],
    );
    let from_toml = report(
        &dir,
        backend,
        "toml",
        &["--sweep", toml_path.to_str().unwrap()],
    );
    assert_eq!(from_csv["backend"], backend);
    assert_eq!(
        from_csv["worlds"], from_toml["worlds"],
        "CSV and TOML sweeps"
    );
    let batch = from_csv["worlds"].as_array().expect("worlds");
    assert_eq!(batch.len(), worlds.len());
    for (k, (mu, e, a)) in worlds.into_iter().enumerate() {
        let config = dir.join(format!("world{k}.toml"));
        std::fs::write(
            &config,
            format!(
                "[contact]\nmu = {mu}\n[cloth]\nstiffness = {e}\n[rigid.motion]\namplitude = {a}\n"
            ),
        )
        .unwrap();
        let alone = report(
            &dir,
            backend,
            &format!("alone{k}"),
            &["--config", config.to_str().unwrap()],
        );
        let world = &batch[k];
        assert_eq!(world["steps"], 25);
        for key in [
            "energy_final",
            "cg_iterations_mean",
            "max_penetration",
            "contacts_mean",
        ] {
            assert_eq!(world[key], alone[key], "world {k}: {key}");
        }
    }
    // The worlds differ: the sweep reached them.
    assert_ne!(batch[0]["energy_final"], batch[1]["energy_final"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A world that diverges stops and is named, the run exits with code 2,
/// and the others run to the end, their report written.
#[test]
fn a_diverging_world_stops_alone_and_is_named() {
    let dir = temp_dir("diverging");
    let sweep = dir.join("sweep.csv");
    // Faster than 1 mm/s: the cloth's first step of falling.
    std::fs::write(&sweep, "solver.max_speed\n100\n0.001\n").unwrap();
    let report = dir.join("r.json");
    let out = Command::new(env!("CARGO_BIN_EXE_wgcloth"))
        .args([
            "run",
            "--backend",
            "cpu",
            "--grid",
            "8",
            "--steps",
            "10",
            "--sweep",
        ])
        .arg(&sweep)
        .arg("--report")
        .arg(&report)
        .output()
        .expect("the wgcloth binary starts");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("world 1") && stderr.contains("step 1"),
        "{stderr}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let worlds = r["worlds"].as_array().unwrap();
    assert_eq!(worlds[0]["steps"], 10);
    assert!(worlds[0]["divergence"].is_null());
    assert_eq!(worlds[1]["steps"], 1);
    assert_eq!(worlds[1]["divergence"]["step"], 1);
    let _ = std::fs::remove_dir_all(&dir);
}
