//! Replays the fuzz seed corpus (fuzz/seeds) and every input the fuzzer
//! crashed on (fuzz/regressions, kept after the fix) through the checks
//! the fuzz targets make, so a fixed loader bug stays fixed without a
//! nightly toolchain.

// What the fuzz targets check (fuzz/), with the loaders they feed.
#[path = "common/loaders.rs"]
mod loaders;

fn replay(target: &str, check: fn(&[u8])) {
    let mut count = 0;
    for dir in ["seeds", "regressions"] {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fuzz")
            .join(dir)
            .join(target);
        // A target the fuzzer never crashed has no regressions folder.
        if !dir.exists() {
            continue;
        }
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.expect("directory entry").path();
            let data = std::fs::read(&path).expect("readable input");
            eprintln!("{target}: {}", path.display());
            check(&data);
            count += 1;
        }
    }
    assert!(count > 0, "no inputs for {target}");
}

#[test]
fn weights_inputs() {
    replay("weights", loaders::weights);
}

#[test]
fn obj_inputs() {
    replay("obj", loaders::obj);
}

#[test]
fn config_inputs() {
    replay("config", loaders::config);
}
