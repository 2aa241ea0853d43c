//! The `wgcloth` binary on bad input: every case must exit with code 2,
//! say what is wrong in one `error:` line naming the bad field or file,
//! and never panic. Tiny valid runs check the happy path, the `--report`
//! JSON and how a GPU run's solver sums (`--no-subgroups`) and lays out
//! its vectors (`--vectors`). Every run is
//! `--grid 4 --steps 2` so the file is fast.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use wgcloth::gpu::layout::VectorLayout;

/// Flags that keep a run tiny if validation ever lets it through.
const TINY: &[&str] = &["--grid", "4", "--steps", "2"];

fn wgcloth(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgcloth"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("failed to start the wgcloth binary")
}

/// `run --backend cpu --grid 4 --steps 2` followed by `extra` (whose own
/// `--grid` replaces the tiny one: clap rejects a repeated flag).
fn run_tiny(extra: &[&str]) -> Output {
    let mut args = vec!["run", "--backend", "cpu"];
    if extra.contains(&"--grid") {
        args.extend_from_slice(&["--steps", "2"]);
    } else {
        args.extend_from_slice(TINY);
    }
    args.extend_from_slice(extra);
    wgcloth(&args)
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Stderr lines that matter: not empty, not the environment's
/// `XDG_RUNTIME_DIR` complaint.
fn stderr_lines(out: &Output) -> Vec<String> {
    stderr(out)
        .trim()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.contains("XDG_RUNTIME_DIR is invalid"))
        .map(String::from)
        .collect()
}

fn describe(case: &str, out: &Output) -> String {
    format!(
        "case `{case}`: exit {:?}\n--- stderr ---\n{}\n--- stdout ---\n{}",
        out.status.code(),
        stderr(out),
        String::from_utf8_lossy(&out.stdout)
    )
}

fn assert_exit_2_no_panic(case: &str, out: &Output) {
    assert!(
        !stderr(out).contains("panicked"),
        "panicked\n{}",
        describe(case, out)
    );
    assert_eq!(
        out.status.code(),
        Some(2),
        "expected exit code 2\n{}",
        describe(case, out)
    );
}

/// One of our own errors: exit 2, no panic, exactly one `error:` line
/// that contains every string of `all_of` and at least one of `any_of`
/// (when `any_of` is not empty). Returns the line.
fn expect_error(case: &str, out: &Output, all_of: &[&str], any_of: &[&str]) -> String {
    assert_exit_2_no_panic(case, out);
    let lines = stderr_lines(out);
    assert_eq!(
        lines.len(),
        1,
        "expected exactly one stderr line\n{}",
        describe(case, out)
    );
    let line = &lines[0];
    assert!(
        line.starts_with("error:"),
        "the line should start with `error:`\n{}",
        describe(case, out)
    );
    for s in all_of {
        assert!(
            line.contains(s),
            "the error should name `{s}`\n{}",
            describe(case, out)
        );
    }
    assert!(
        any_of.is_empty() || any_of.iter().any(|s| line.contains(s)),
        "the error should name one of {any_of:?}\n{}",
        describe(case, out)
    );
    line.clone()
}

/// A bad flag value that clap accepts but validation must reject: the
/// error names the dotted config field or the flag.
fn expect_field_error(extra: &[&str], field: &str, flag: &str) {
    let case = extra.join(" ");
    let out = run_tiny(extra);
    expect_error(&case, &out, &[], &[field, flag]);
}

/// A clap usage error: exit 2, no panic, and the first line names `what`.
fn expect_clap_error(case: &str, out: &Output, what: &str) {
    assert_exit_2_no_panic(case, out);
    let lines = stderr_lines(out);
    let first = lines.first().map(String::as_str).unwrap_or("");
    assert!(
        first.starts_with("error:") && first.contains(what),
        "the first stderr line should be an `error:` naming `{what}`\n{}",
        describe(case, out)
    );
}

/// A fresh directory for one test's files.
struct TempDir(PathBuf);

impl TempDir {
    fn new(test: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!(
            "wgcloth-cli-bad-input-{}-{test}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create temp dir");
        TempDir(dir)
    }

    fn file(&self, name: &str, contents: &str) -> PathBuf {
        let path = self.0.join(name);
        std::fs::write(&path, contents).expect("write temp file");
        path
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn s(p: &Path) -> &str {
    p.to_str().expect("temp path is UTF-8")
}

/// A closed tetrahedron with outward winding.
const TETRAHEDRON: &str = "\
v 0 0 0
v 0.2 0 0
v 0 0.2 0
v 0 0 0.2
f 1 3 2
f 1 2 4
f 1 4 3
f 2 3 4
";

// ---------------------------------------------------------------- flags

#[test]
fn grid_1_is_rejected() {
    expect_field_error(&["--grid", "1"], "cloth.grid", "--grid");
}

#[test]
fn grid_0_is_rejected() {
    expect_field_error(&["--grid", "0"], "cloth.grid", "--grid");
}

#[test]
fn dt_0_is_rejected() {
    expect_field_error(&["--dt", "0"], "solver.dt", "--dt");
}

#[test]
fn dt_negative_is_rejected() {
    // One token, so the value certainly reaches validation.
    expect_field_error(&["--dt=-0.01"], "solver.dt", "--dt");
}

#[test]
fn dt_negative_as_separate_token_is_rejected_by_name() {
    // `--dt -0.01` is how a user writes it: the negative number must be
    // taken as the flag's value (and rejected as `solver.dt`), not read as
    // an unknown short flag `-0`.
    expect_field_error(&["--dt", "-0.01"], "solver.dt", "--dt");
}

#[test]
fn dt_nan_is_rejected() {
    expect_field_error(&["--dt", "nan"], "solver.dt", "--dt");
}

#[test]
fn dt_inf_is_rejected() {
    expect_field_error(&["--dt", "inf"], "solver.dt", "--dt");
}

#[test]
fn max_speed_0_is_rejected() {
    expect_field_error(&["--max-speed", "0"], "solver.max_speed", "--max-speed");
}

#[test]
fn weights_for_an_analytic_model_are_rejected_not_ignored() {
    let case = "--model friction --weights ../wgcloth/weights/naive_mlp.safetensors";
    let out = run_tiny(&[
        "--model",
        "friction",
        "--weights",
        "../wgcloth/weights/naive_mlp.safetensors",
    ]);
    expect_error(case, &out, &["contact.weights", "friction"], &[]);
}

#[test]
fn cg_iters_0_is_rejected() {
    expect_field_error(&["--cg-iters", "0"], "solver.cg_iters", "--cg-iters");
}

#[test]
fn cg_tol_negative_is_rejected() {
    expect_field_error(&["--cg-tol=-1"], "solver.cg_tol", "--cg-tol");
}

#[test]
fn cg_tol_negative_as_separate_token_is_rejected_by_name() {
    expect_field_error(&["--cg-tol", "-1"], "solver.cg_tol", "--cg-tol");
}

#[test]
fn steps_not_a_number_is_a_usage_error() {
    let out = wgcloth(&["run", "--grid", "4", "--steps", "not-a-number"]);
    expect_clap_error("--steps not-a-number", &out, "--steps");
}

#[test]
fn unknown_model_is_a_usage_error() {
    let out = run_tiny(&["--model", "bogus"]);
    expect_clap_error("--model bogus", &out, "--model");
}

#[test]
fn unknown_vector_layout_is_a_usage_error_naming_the_layouts() {
    let out = run_tiny(&["--vectors", "vec3"]);
    expect_clap_error("--vectors vec3", &out, "--vectors");
    assert!(stderr(&out).contains("packed, vec4"), "{}", stderr(&out));
}

#[test]
fn unknown_backend_is_a_usage_error() {
    let out = wgcloth(&["run", "--grid", "4", "--steps", "2", "--backend", "bogus"]);
    expect_clap_error("--backend bogus", &out, "--backend");
}

#[test]
fn unknown_scene_is_a_usage_error() {
    let out = run_tiny(&["--scene", "bogus"]);
    expect_clap_error("--scene bogus", &out, "--scene");
}

#[test]
fn unknown_subcommand_is_a_usage_error() {
    let out = wgcloth(&["simulate", "--grid", "4"]);
    expect_clap_error("simulate", &out, "simulate");
}

fn wgcloth_env(args: &[&str], key: &str, value: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgcloth"))
        .args(args)
        .env(key, value)
        .output()
        .expect("failed to run the wgcloth binary")
}

#[test]
fn backend_gpu_without_a_matching_adapter_is_one_clear_error() {
    let args = ["run", "--grid", "4", "--steps", "2", "--backend", "gpu"];
    let out = wgcloth_env(&args, "WGPU_ADAPTER_NAME", "no-such-adapter");
    expect_error(
        "--backend gpu, no adapter",
        &out,
        &["WGPU_ADAPTER_NAME", "no-such-adapter"],
        &[],
    );
}

#[test]
fn backend_auto_without_an_adapter_falls_back_to_the_cpu_with_a_notice() {
    let args = ["run", "--grid", "4", "--steps", "2", "--backend", "auto"];
    let out = wgcloth_env(&args, "WGPU_ADAPTER_NAME", "no-such-adapter");
    assert!(out.status.success(), "{}", describe("auto fallback", &out));
    let err = stderr(&out);
    assert!(err.contains("notice") && err.contains("CPU"), "{err}");
    assert!(String::from_utf8_lossy(&out.stdout).contains("backend      cpu"));
}

/// The GPU solver's flags on a CPU run change nothing, and say so.
#[test]
fn gpu_solver_flags_on_a_cpu_run_get_a_notice() {
    let out = run_tiny(&["--vectors", "vec4", "--no-subgroups"]);
    assert!(
        out.status.success(),
        "{}",
        describe("cpu run, gpu flags", &out)
    );
    let err = stderr(&out);
    for flag in ["--no-subgroups", "--vectors"] {
        assert!(
            err.contains(&format!(
                "notice: {flag} sets up the GPU solver; this run is on the CPU"
            )),
            "{err}"
        );
    }
    let plain = stderr(&run_tiny(&[]));
    assert!(!plain.contains("GPU solver"), "{plain}");
}

#[test]
fn validate_with_a_zero_tolerance_is_rejected() {
    let out = wgcloth(&[
        "validate",
        "--grid",
        "4",
        "--steps",
        "2",
        "--tolerance",
        "0",
    ]);
    expect_error("--tolerance 0", &out, &["--tolerance"], &[]);
}

// ----------------------------------------------------------------- TOML

#[test]
fn missing_config_file() {
    let dir = TempDir::new("missing_config");
    let path = dir.path("does-not-exist.toml");
    let out = run_tiny(&["--config", s(&path)]);
    expect_error("missing --config", &out, &[s(&path)], &[]);
}

#[test]
fn toml_syntax_error() {
    let dir = TempDir::new("toml_syntax");
    let path = dir.file("config.toml", "[cloth\nmass = 1.0\n");
    let out = run_tiny(&["--config", s(&path)]);
    expect_error("TOML syntax error", &out, &[s(&path)], &[]);
}

#[test]
fn toml_unknown_field() {
    let dir = TempDir::new("toml_unknown_field");
    let path = dir.file("config.toml", "[cloth]\nmas = 1.0\n");
    let out = run_tiny(&["--config", s(&path)]);
    // `mas` is on line 2 (the line number must not be off by one when the
    // offending key starts its line).
    expect_error(
        "TOML unknown field",
        &out,
        &[s(&path), "`mas`", "line 2"],
        &[],
    );
}

#[test]
fn toml_wrong_type() {
    let dir = TempDir::new("toml_wrong_type");
    let path = dir.file("config.toml", "[cloth]\nmass = \"heavy\"\n");
    let out = run_tiny(&["--config", s(&path)]);
    // toml's message names the type, not the key; the line locates it.
    expect_error("TOML wrong type", &out, &[s(&path), "line 2"], &[]);
}

#[test]
fn toml_negative_mass() {
    let dir = TempDir::new("toml_negative_mass");
    let path = dir.file("config.toml", "[cloth]\nmass = -1.0\n");
    let out = run_tiny(&["--config", s(&path)]);
    expect_error("cloth.mass = -1", &out, &["cloth.mass"], &[]);
}

#[test]
fn toml_zero_stiffness() {
    let dir = TempDir::new("toml_zero_stiffness");
    let path = dir.file("config.toml", "[cloth]\nstiffness = 0.0\n");
    let out = run_tiny(&["--config", s(&path)]);
    expect_error("cloth.stiffness = 0", &out, &["cloth.stiffness"], &[]);
}

#[test]
fn toml_negative_kn_with_friction() {
    let dir = TempDir::new("toml_negative_kn");
    let path = dir.file("config.toml", "[contact]\nkn = -1.0\n");
    let out = run_tiny(&["--model", "friction", "--config", s(&path)]);
    expect_error("contact.kn = -1, friction", &out, &["contact.kn"], &[]);
}

#[test]
fn toml_zero_naive_stiffness_with_naive() {
    let dir = TempDir::new("toml_zero_naive_stiffness");
    let path = dir.file("config.toml", "[contact]\nnaive_stiffness = 0.0\n");
    let out = run_tiny(&["--model", "naive", "--config", s(&path)]);
    expect_error(
        "contact.naive_stiffness = 0, naive",
        &out,
        &["contact.naive_stiffness"],
        &[],
    );
}

#[test]
fn toml_zero_dt() {
    let dir = TempDir::new("toml_zero_dt");
    let path = dir.file("config.toml", "[solver]\ndt = 0.0\n");
    let out = run_tiny(&["--config", s(&path)]);
    expect_error("solver.dt = 0", &out, &["solver.dt"], &[]);
}

// ------------------------------------------------------------------ OBJ

#[test]
fn missing_mesh_file() {
    let dir = TempDir::new("missing_mesh");
    let path = dir.path("does-not-exist.obj");
    let out = run_tiny(&["--scene", "sphere", "--mesh", s(&path)]);
    expect_error("missing --mesh", &out, &[s(&path)], &[]);
}

#[test]
fn obj_non_finite_vertex() {
    let dir = TempDir::new("obj_nan");
    let path = dir.file(
        "mesh.obj",
        "v nan 0 0\nv 0.2 0 0\nv 0 0.2 0\nv 0 0 0.2\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    );
    let out = run_tiny(&["--scene", "sphere", "--mesh", s(&path)]);
    expect_error("OBJ vertex nan", &out, &[s(&path)], &[]);
}

#[test]
fn obj_face_index_out_of_range() {
    let dir = TempDir::new("obj_out_of_range");
    let path = dir.file("mesh.obj", "v 0 0 0\nv 0.2 0 0\nv 0 0.2 0\nf 1 2 7\n");
    let out = run_tiny(&["--scene", "sphere", "--mesh", s(&path)]);
    expect_error("OBJ face index 7 of 3", &out, &[s(&path)], &[]);
}

/// Indices tobj would turn into wrapped `usize` arithmetic (a panic in
/// debug builds; found by fuzzing) are refused by line.
#[test]
fn obj_indices_out_of_range_name_the_line() {
    let dir = TempDir::new("obj_indices");
    let head = "v 0 0 0\nv 0.2 0 0\nv 0 0.2 0\nvt 0 0\nvn 0 0 1\n";
    for face in [
        "f 0 1 2",
        "f -4 -1 -2",
        "f 1/-2 2/1 3/1",
        "f 1//1 2//2 3//1",
        "f 1 2 99999999999",
    ] {
        let path = dir.file("mesh.obj", &format!("{head}{face}\n"));
        let out = run_tiny(&["--scene", "sphere", "--mesh", s(&path)]);
        expect_error(face, &out, &[s(&path), "line 6", "out of range"], &[]);
    }
}

#[test]
fn obj_without_faces() {
    let dir = TempDir::new("obj_no_faces");
    let path = dir.file("mesh.obj", "v 0 0 0\nv 0.2 0 0\nv 0 0.2 0\n");
    let out = run_tiny(&["--scene", "sphere", "--mesh", s(&path)]);
    expect_error("OBJ with no faces", &out, &[s(&path)], &[]);
}

#[test]
fn mesh_with_hang_scene() {
    let dir = TempDir::new("mesh_hang");
    let path = dir.file("mesh.obj", TETRAHEDRON);
    let out = run_tiny(&["--scene", "hang", "--mesh", s(&path)]);
    expect_error("--mesh with --scene hang", &out, &["--mesh"], &[]);
}

// ------------------------------------------------------------- positive

#[test]
fn tiny_run_writes_report_json() {
    let dir = TempDir::new("report");
    let report = dir.path("report.json");
    let out = run_tiny(&["--scene", "sphere", "--report", s(&report)]);
    assert!(
        !stderr(&out).contains("panicked"),
        "{}",
        describe("report", &out)
    );
    assert_eq!(out.status.code(), Some(0), "{}", describe("report", &out));
    let text = std::fs::read_to_string(&report).expect("report file written");
    let json: serde_json::Value = serde_json::from_str(&text)
        .unwrap_or_else(|e| panic!("report is not valid JSON ({e}):\n{text}"));
    let obj = json.as_object().expect("report is a JSON object");
    for key in [
        "backend",
        "adapter",
        "model",
        "scene",
        "grid",
        "steps",
        "ms_per_step",
        "ms_per_step_mean",
        "max_penetration",
        "finite",
        "cg_iterations_mean",
        "cg_residual_max",
        "cg_residual_median",
        "cg_steps_above_goal",
        "contacts_mean",
    ] {
        assert!(obj.contains_key(key), "report lacks `{key}`:\n{text}");
    }
    assert_eq!(json["grid"], serde_json::json!([4, 4]), "{text}");
    assert_eq!(json["steps"], serde_json::json!(2), "{text}");
    assert_eq!(json["finite"], serde_json::json!(true), "{text}");
}

/// `wgcloth run --backend gpu FLAGS --report` in `dir` (report `k`),
/// which must succeed: its report and its standard output.
fn gpu_run(dir: &TempDir, k: usize, flags: &[&str]) -> (serde_json::Value, String) {
    let report = dir.path(&format!("report_{k}.json"));
    let mut args = vec!["run", "--backend", "gpu", "--report", s(&report)];
    args.extend(flags);
    let out = wgcloth(&args);
    assert_eq!(out.status.code(), Some(0), "{}", describe("gpu run", &out));
    let json = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    (json, String::from_utf8_lossy(&out.stdout).into_owned())
}

/// A GPU run says how its solver sums (the backend line, the report's
/// `gpu_subgroup_sums`): through subgroups where the adapter has them,
/// through workgroup memory with `--no-subgroups`; and how it lays out its
/// vectors (`gpu_vectors`): as suits the adapter, or as `--vectors` says.
#[test]
fn gpu_runs_say_how_the_solver_sums_and_lays_out_its_vectors() {
    let adapter = match wgcloth::gpu::GpuContext::pick_adapter() {
        Ok(adapter) => adapter,
        Err(e) if !std::env::var("WGCLOTH_NO_GPU_TESTS").is_ok_and(|v| v == "1") => {
            panic!("the GPU tests need an adapter (WGCLOTH_NO_GPU_TESTS=1 skips them): {e}")
        }
        Err(e) => return eprintln!("skipping GPU test: {e}"),
    };
    let has = adapter.features().contains(wgpu::Features::SUBGROUP);
    let own = VectorLayout::for_adapter(adapter.get_info().device_type).name();
    let dir = TempDir::new("subgroups");
    let cases: [(&[&str], bool, &str); 4] = [
        (&[], has, own),
        (&["--no-subgroups"], false, own),
        (&["--vectors", "packed"], has, "packed"),
        (&["--vectors", "vec4"], has, "vec4"),
    ];
    for (k, (flags, sums, vectors)) in cases.into_iter().enumerate() {
        let (json, stdout) = gpu_run(&dir, k, &[TINY, flags].concat());
        assert_eq!(
            json["gpu_subgroup_sums"],
            serde_json::json!(sums),
            "{flags:?}"
        );
        assert_eq!(json["gpu_vectors"], serde_json::json!(vectors), "{flags:?}");
        let how = match sums {
            true => "solver sums through subgroups",
            false => "solver sums through workgroup memory",
        };
        assert!(
            stdout.contains(&format!("{how}, vectors {vectors}")),
            "{flags:?}: {stdout}"
        );
    }
}

/// A GPU run says whether its solves ran whole in one dispatch
/// (`gpu_solved_whole`, the pcg line): by default on a small cloth, not
/// with `--whole-solve-nodes 0`, whose chain records more dispatches a
/// step; and how long the host took to record a step.
#[test]
fn gpu_runs_say_whether_the_solve_ran_whole() {
    if let Err(e) = wgcloth::gpu::GpuContext::pick_adapter() {
        if std::env::var("WGCLOTH_NO_GPU_TESTS").is_ok_and(|v| v == "1") {
            return eprintln!("skipping GPU test: {e}");
        }
        panic!("the GPU tests need an adapter (WGCLOTH_NO_GPU_TESTS=1 skips them): {e}");
    }
    let dir = TempDir::new("whole");
    let mut dispatches = Vec::new();
    // Multigrid has coarse levels from 8².
    let small = ["--grid", "8", "--steps", "3"];
    for (k, (flags, whole)) in [(&[][..], true), (&["--whole-solve-nodes", "0"][..], false)]
        .into_iter()
        .enumerate()
    {
        let (json, stdout) = gpu_run(&dir, k, &[&small[..], flags].concat());
        assert_eq!(
            json["gpu_solved_whole"],
            serde_json::json!(whole),
            "{flags:?}"
        );
        assert_eq!(
            stdout.contains("each solve whole in one dispatch"),
            whole,
            "{flags:?}: {stdout}"
        );
        assert!(json["record_ms_per_step"].as_f64().unwrap() > 0.0, "{json}");
        dispatches.push(json["dispatches_per_step"].as_u64().unwrap());
    }
    assert!(
        dispatches[0] < dispatches[1],
        "whole and chain: {dispatches:?}"
    );
}

#[test]
fn tiny_run_with_config_and_mesh_succeeds() {
    let dir = TempDir::new("config_and_mesh");
    let mesh = dir.file("tet.obj", TETRAHEDRON);
    let config = dir.file(
        "config.toml",
        "model = \"naive\"\n[cloth]\nmass = 0.3\n[solver]\ndt = 0.005\n",
    );
    // The default backend (auto) may print a notice; only the outcome matters.
    let out = wgcloth(&[
        "run",
        "--grid",
        "4",
        "--steps",
        "2",
        "--config",
        s(&config),
        "--mesh",
        s(&mesh),
    ]);
    assert!(
        !stderr(&out).contains("panicked"),
        "{}",
        describe("config and mesh", &out)
    );
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        describe("config and mesh", &out)
    );
}

#[test]
fn scene_beyond_the_adapters_buffer_limits_is_one_clear_error() {
    // A 1300² cloth's topology is about 488 MB: more than three of
    // lavapipe's 128 MiB bindings, even bound in parts (1024² runs). Skipped
    // where no adapter exists (the GPU tests enforce one in CI).
    let out = wgcloth(&[
        "run",
        "--backend",
        "gpu",
        "--scene",
        "hang",
        "--grid",
        "1300",
        "--steps",
        "1",
    ]);
    let err = stderr(&out);
    if err.contains("no GPU adapter") {
        return;
    }
    let line = expect_error("--grid 1300 on the GPU", &out, &["--grid"], &[]);
    assert!(
        line.contains("topology") && line.contains("in at most 3 bindings"),
        "{line}"
    );
}

#[test]
fn friction_net_with_a_missing_weights_file_names_it() {
    let out = run_tiny(&[
        "--model",
        "friction-net",
        "--weights",
        "no/such/net.safetensors",
    ]);
    expect_error("missing --weights", &out, &["no/such/net.safetensors"], &[]);
}

#[test]
fn friction_net_with_a_corrupt_weights_file_names_it() {
    let dir = TempDir::new("corrupt_weights");
    let path = dir.path("net.safetensors");
    std::fs::write(&path, b"not a network").unwrap();
    let out = run_tiny(&["--model", "friction-net", "--weights", s(&path)]);
    expect_error("corrupt --weights", &out, &[s(&path), "safetensors"], &[]);
}

#[test]
fn bench_with_an_unwritable_report_fails_before_measuring() {
    let dir = TempDir::new("bench_report");
    let report = dir.path("missing/bench.json");
    let out = wgcloth(&["bench", "--quick", "--report", s(&report)]);
    expect_error(
        "bench --report in a missing folder",
        &out,
        &[s(&report)],
        &[],
    );
}

#[test]
fn network_models_run_from_any_directory_on_their_built_in_weights() {
    let dir = TempDir::new("built_in_weights");
    use wgcloth::config::ModelKind;
    for model in [ModelKind::FrictionNet, ModelKind::NaiveNet] {
        let file = format!("{} (built in)", model.default_weights().unwrap());
        let model = model.name();
        let out = Command::new(env!("CARGO_BIN_EXE_wgcloth"))
            .args(["run", "--backend", "cpu", "--model", model])
            .args(TINY)
            .current_dir(&dir.0)
            .env("RUST_LOG", "warn")
            .output()
            .expect("failed to start the wgcloth binary");
        assert!(out.status.success(), "{}", describe(model, &out));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains(&file), "{model}: {text}");
    }
}

#[test]
fn a_network_model_with_the_other_kind_of_network_names_both() {
    let shipped = |name: &str| format!("{}/../wgcloth/weights/{name}", env!("CARGO_MANIFEST_DIR"));
    let friction = shipped("friction_mlp.safetensors");
    let out = run_tiny(&["--model", "naive-net", "--weights", &friction]);
    expect_error(
        "naive-net with friction weights",
        &out,
        &[&friction, "naive-net", "friction network"],
        &[],
    );
    let naive = shipped("naive_mlp.safetensors");
    let out = run_tiny(&["--model", "friction-net", "--weights", &naive]);
    expect_error(
        "friction-net with naive weights",
        &out,
        &[&naive, "friction-net", "naive network"],
        &[],
    );
}

#[test]
fn eval_net_with_data_of_the_other_network_names_both() {
    let dir = TempDir::new("eval_mismatch");
    let data = dir.path("naive.st");
    let out = wgcloth(&[
        "gen-data",
        "--model",
        "naive",
        "--out",
        s(&data),
        "--recorded",
        "0",
        "--uniform",
        "50",
    ]);
    assert!(out.status.success(), "{}", describe("gen-data", &out));
    let friction = format!(
        "{}/../wgcloth/weights/friction_mlp.safetensors",
        env!("CARGO_MANIFEST_DIR")
    );
    let out = wgcloth(&["eval-net", &friction, "--data", s(&data), "--samples", "10"]);
    expect_error(
        "eval-net mismatch",
        &out,
        &[s(&data), "naive data", "friction network"],
        &[],
    );
}

#[test]
fn out_naming_a_file_is_one_clear_error_and_the_file_is_kept() {
    let dir = TempDir::new("out_file");
    let path = dir.file("notes.txt", "mine");
    let out = run_tiny(&["--out", s(&path)]);
    expect_error("--out naming a file", &out, &[s(&path), "is a file"], &[]);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "mine");
}

#[test]
fn out_under_a_file_is_one_clear_error() {
    let dir = TempDir::new("out_under_file");
    let file = dir.file("blocker", "x");
    let target = file.join("frames");
    let out = run_tiny(&["--out", s(&target)]);
    expect_error("--out under a file", &out, &["blocker"], &[]);
}

#[test]
fn frames_already_there_need_force() {
    let dir = TempDir::new("out_exists");
    let frame = dir.file("frame_0000.png", "not a png of ours");
    let out = run_tiny(&["--out", s(&dir.0)]);
    expect_error(
        "frames already in --out",
        &out,
        &["frame_0000.png", "--force"],
        &[],
    );
    assert_eq!(
        std::fs::read_to_string(&frame).unwrap(),
        "not a png of ours"
    );
}

#[test]
fn every_0_is_rejected() {
    let dir = TempDir::new("every_0");
    let out = run_tiny(&["--out", s(&dir.path("frames")), "--every", "0"]);
    expect_error("--every 0", &out, &["--every"], &[]);
}

#[test]
fn frame_sizes_the_adapter_cannot_render_are_rejected_and_write_nothing() {
    let dir = TempDir::new("frame_size");
    let frames = dir.path("frames");
    for size in ["0", "100000"] {
        let out = run_tiny(&["--out", s(&frames), "--size", size]);
        expect_error(&format!("--size {size}"), &out, &["--size"], &[]);
        assert!(
            !frames.exists(),
            "--size {size} created the frame directory"
        );
    }
}

#[test]
fn unknown_export_format_is_a_usage_error() {
    let out = run_tiny(&["--out", "frames", "--export", "fbx"]);
    expect_clap_error("--export fbx", &out, "fbx");
}

#[test]
fn an_export_without_a_frame_directory_is_refused() {
    for format in ["obj", "usd", "obj,usd"] {
        let out = run_tiny(&["--export", format]);
        expect_error(
            &format!("--export {format}"),
            &out,
            &["--export", "--out"],
            &[],
        );
    }
}

// ------------------------------------------------- every config field

/// Each field of the configuration with a value its check refuses, in
/// the scene and model the check applies to; the error names the field.
const BAD_FIELDS: &[(&str, &str)] = &[
    ("[cloth]\ngrid = [1, 4]", "cloth.grid"),
    ("[cloth]\ngrid = [10000, 10000]", "cloth.grid"),
    ("[cloth]\nsize = [1.0, 0.0]", "cloth.size"),
    ("[cloth]\nmass = 0.0", "cloth.mass"),
    ("[cloth]\nstiffness = inf", "cloth.stiffness"),
    ("[cloth]\ndamping_mass = -0.1", "cloth.damping_mass"),
    (
        "[cloth]\ndamping_stiffness = nan",
        "cloth.damping_stiffness",
    ),
    ("[cloth]\ncenter = [0.0, inf, 0.0]", "cloth.center"),
    (
        "[cloth.rotation]\naxis = [0.0, 0.0, 0.0]\ndegrees = 30.0",
        "cloth.rotation",
    ),
    ("[cloth.rotation]\ndegrees = nan", "cloth.rotation"),
    ("[rigid]\nradius = 0.0", "rigid.radius"),
    ("[rigid]\nsubdivisions = 8", "rigid.subdivisions"),
    (
        "[rigid]\nshape = \"box\"\nhalf_extents = [0.1, -0.1, 0.1]",
        "rigid.half_extents",
    ),
    (
        "[rigid]\nshape = \"box\"\nsubdivisions = 0",
        "rigid.subdivisions",
    ),
    (
        "[rigid]\nshape = \"plane\"\nplane_size = [0.0, 1.0]",
        "rigid.plane_size",
    ),
    ("[rigid]\nshape = \"obj\"", "rigid.mesh"),
    (
        "[rigid]\nshape = \"obj\"\nmesh = \"body.obj\"\nscale = 0.0",
        "rigid.scale",
    ),
    ("[rigid]\nposition = [nan, 0.0, 0.0]", "rigid.position"),
    (
        "[rigid.rotation]\naxis = [0.0, 0.0, 0.0]\ndegrees = 10.0",
        "rigid.rotation",
    ),
    (
        "[rigid.motion]\nkind = \"linear\"\nvelocity = [0.0, 0.0, inf]",
        "rigid.motion.velocity",
    ),
    (
        "[rigid.motion]\naxis = [0.0, 0.0, 0.0]",
        "rigid.motion.axis",
    ),
    ("[rigid.motion]\namplitude = nan", "rigid.motion.amplitude"),
    ("[rigid.motion]\nperiod = 0.0", "rigid.motion.period"),
    ("[rigid.motion]\nphase_deg = inf", "rigid.motion.phase_deg"),
    ("[contact]\nthickness = 0.0", "contact.thickness"),
    ("[contact]\nmax_depth = -0.01", "contact.max_depth"),
    (
        "model = \"naive-net\"\n[contact]\nnaive_stiffness = nan",
        "contact.naive_stiffness",
    ),
    ("[contact]\nforce_scale = 0.0", "contact.force_scale"),
    ("[contact]\nkn = 0.0", "contact.kn"),
    ("[contact]\nkd = -1.0", "contact.kd"),
    ("model = \"friction\"\n[contact]\nkt = 0.0", "contact.kt"),
    ("[contact]\nmu = -0.5", "contact.mu"),
    (
        "model = \"naive\"\n[contact]\nweights = \"../wgcloth/weights/naive_mlp.safetensors\"",
        "contact.weights",
    ),
    ("[solver]\ndt = inf", "solver.dt"),
    ("[solver]\ncg_iters = 0", "solver.cg_iters"),
    ("[solver]\ncg_tol = -1e-6", "solver.cg_tol"),
    ("[solver]\ngravity = [0.0, nan, 0.0]", "solver.gravity"),
    ("[solver]\nmax_speed = 0.0", "solver.max_speed"),
    ("[solver]\nsteps = -1", "solver.steps"),
    ("scene = \"cube\"", "`scene`"),
    ("model = \"learned\"", "`model`"),
    ("[cloth]\npins = \"middle\"", "cloth.pins"),
    ("[rigid.motion]\nkind = \"orbit\"", "rigid.motion.kind"),
    ("[cloth]\ngrid = [-1, 4]", "cloth.grid"),
    ("[self_contact]\ngamma = 0.5", "self_contact.gamma"),
    ("[self_contact]\nfloor = 0.0", "self_contact.floor"),
    ("[self_contact]\nthickness = 1e-4", "self_contact.thickness"),
    (
        "[self_contact]\nmass_ratio = 0.0",
        "self_contact.mass_ratio",
    ),
];

#[test]
fn every_config_field_rejects_a_bad_value_by_name() {
    let dir = TempDir::new("every_field");
    for (k, (toml, field)) in BAD_FIELDS.iter().enumerate() {
        let path = dir.file(&format!("c{k}.toml"), toml);
        // The grid cases need the file's grid, not the tiny one.
        let out = match field.starts_with("cloth.grid") {
            true => wgcloth(&[
                "run",
                "--backend",
                "cpu",
                "--steps",
                "2",
                "--config",
                s(&path),
            ]),
            false => run_tiny(&["--config", s(&path)]),
        };
        expect_error(&format!("{toml:?}"), &out, &[field], &[]);
    }
}

// ------------------------------------------- monitor, data and training

#[test]
fn monitor_every_0_is_rejected_and_writes_nothing() {
    let dir = TempDir::new("monitor_every_0");
    let csv = dir.path("m.csv");
    let out = run_tiny(&["--monitor", s(&csv), "--monitor-every", "0"]);
    expect_error("--monitor-every 0", &out, &["--monitor-every"], &[]);
    assert!(
        !csv.exists(),
        "no monitor file for a run that never started"
    );
}

#[test]
fn monitor_in_a_missing_directory_names_the_path() {
    let dir = TempDir::new("monitor_missing_dir");
    let csv = dir.path("nowhere/m.csv");
    let out = run_tiny(&["--monitor", s(&csv)]);
    expect_error("--monitor nowhere/m.csv", &out, &[s(&csv)], &[]);
}

#[test]
fn gen_data_with_no_samples_is_rejected_and_writes_nothing() {
    let dir = TempDir::new("gen_data_empty");
    let data = dir.path("d.safetensors");
    let out = wgcloth(&[
        "gen-data",
        "--out",
        s(&data),
        "--recorded",
        "0",
        "--uniform",
        "0",
    ]);
    expect_error("gen-data with no samples", &out, &["--recorded"], &[]);
    assert!(!data.exists());
}

#[test]
fn eval_net_with_0_samples_is_rejected() {
    let out = wgcloth(&[
        "eval-net",
        "../wgcloth/weights/naive_mlp.safetensors",
        "--samples",
        "0",
    ]);
    expect_error("eval-net --samples 0", &out, &["--samples"], &[]);
}

#[test]
fn train_flags_out_of_range_are_rejected_by_name_and_write_nothing() {
    let dir = TempDir::new("train_flags");
    let data = dir.path("d.safetensors");
    let made = wgcloth(&[
        "gen-data",
        "--out",
        s(&data),
        "--recorded",
        "0",
        "--uniform",
        "64",
    ]);
    assert!(made.status.success(), "{}", describe("gen-data", &made));
    let weights = dir.path("w.safetensors");
    for (flag, value) in [
        ("--epochs", "0"),
        ("--batch", "0"),
        ("--hidden", "8,0"),
        ("--lr", "nan"),
        ("--lr", "-1"),
        ("--lr", "0"),
    ] {
        let out = wgcloth(&[
            "train",
            "--data",
            s(&data),
            "--out",
            s(&weights),
            flag,
            value,
        ]);
        expect_error(&format!("train {flag} {value}"), &out, &[flag], &[]);
        assert!(!weights.exists(), "train {flag} {value} wrote weights");
    }
}

// ---------------------------------------------------------------- worlds

#[test]
fn a_sweep_key_that_names_no_field_is_named_with_its_world() {
    let dir = TempDir::new("sweep-key");
    let sweep = dir.file("sweep.csv", "contact.mu,contact.mux\n0.3,1\n0.5,2\n");
    let out = run_tiny(&["--sweep", s(&sweep)]);
    expect_error("sweep key", &out, &["sweep.csv", "world 1", "mux"], &[]);
}

#[test]
fn a_sweep_value_of_the_wrong_type_is_named() {
    let dir = TempDir::new("sweep-type");
    let sweep = dir.file("sweep.toml", "[[world]]\ncontact.mu = \"high\"\n");
    let out = run_tiny(&["--sweep", s(&sweep)]);
    expect_error("sweep type", &out, &["sweep.toml", "contact.mu"], &[]);
}

#[test]
fn a_sweep_of_no_world_or_another_format_is_rejected() {
    let dir = TempDir::new("sweep-empty");
    let empty = dir.file("empty.csv", "contact.mu\n");
    expect_error(
        "empty",
        &run_tiny(&["--sweep", s(&empty)]),
        &["empty.csv", "no world"],
        &[],
    );
    let text = dir.file("sweep.txt", "contact.mu\n0.3\n");
    let out = run_tiny(&["--sweep", s(&text)]);
    expect_error("format", &out, &["sweep.txt", ".toml", ".csv"], &[]);
    let stray = dir.file("stray.toml", "[contact]\nmu = 0.3\n");
    let out = run_tiny(&["--sweep", s(&stray)]);
    expect_error(
        "stray table",
        &out,
        &["stray.toml", "`contact`", "[[world]]"],
        &[],
    );
}

#[test]
fn worlds_that_disagree_with_the_sweep_or_number_none_are_rejected() {
    let dir = TempDir::new("worlds-count");
    let sweep = dir.file("sweep.csv", "contact.mu\n0.3\n0.5\n");
    let out = run_tiny(&["--worlds", "3", "--sweep", s(&sweep)]);
    expect_error("3 vs 2", &out, &["--worlds", "3", "2"], &[]);
    expect_error("none", &run_tiny(&["--worlds", "0"]), &["--worlds"], &[]);
}

#[test]
fn worlds_refuse_the_flags_of_a_single_world_and_a_scene_the_gpu_batch_lacks() {
    let dir = TempDir::new("worlds-flags");
    let frames = dir.path("frames");
    let out = run_tiny(&["--worlds", "2", "--out", s(&frames)]);
    expect_error("--out", &out, &["--out", "one world"], &[]);
    assert!(!frames.exists(), "nothing is written");
    // The GPU batch runs without self-contact so far.
    let folding = dir.file("folding.toml", "[self_contact]\nenabled = true\n");
    let mut args = vec![
        "run",
        "--backend",
        "gpu",
        "--worlds",
        "2",
        "--config",
        s(&folding),
    ];
    args.extend_from_slice(TINY);
    expect_error("gpu", &wgcloth(&args), &["worlds", "self-contact"], &[]);
}
