//! The main command on a machine with no Vulkan driver
//! (`VK_ICD_FILENAMES=/dev/null`): it runs on the CPU with a notice, draws
//! no frames and so writes no image file (never an empty GIF), and still
//! writes the OBJ frames of `--export obj`.

use std::path::PathBuf;
use std::process::Command;

fn run_without_a_driver(dir: &PathBuf, extra: &[&str]) -> String {
    let _ = std::fs::remove_dir_all(dir);
    let out = Command::new(env!("CARGO_BIN_EXE_wgcloth"))
        .args([
            "run", "--grid", "8", "--steps", "8", "--every", "4", "--out",
        ])
        .arg(dir)
        .args(extra)
        .env("VK_ICD_FILENAMES", "/dev/null")
        .env("VK_DRIVER_FILES", "/dev/null")
        .output()
        .expect("wgcloth runs");
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "exit {:?}: {stderr}", out.status);
    assert!(stderr.contains("notice: no GPU adapter"), "{stderr}");
    stderr
}

fn scratch(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("wgcloth-no-adapter-{name}-{}", std::process::id()))
}

#[test]
fn without_an_adapter_no_image_file_is_written() {
    let dir = scratch("frames");
    let stderr = run_without_a_driver(&dir, &[]);
    assert!(stderr.contains("no image file is written"), "{stderr}");
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert!(files.is_empty(), "left {files:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn without_an_adapter_obj_frames_are_still_written() {
    let dir = scratch("obj");
    run_without_a_driver(&dir, &["--export", "obj"]);
    // Steps 0, 4 and 8.
    for k in 0..3 {
        let path = dir.join(format!("frame_{k:04}.obj"));
        let (models, _) = tobj::load_obj(&path, &tobj::LoadOptions::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let names: Vec<&str> = models.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["cloth", "body"], "{}", path.display());
        assert_eq!(models[0].mesh.positions.len(), 3 * 64);
    }
    assert!(!dir.join("animation.gif").exists());
    assert!(!dir.join("frame_0000.png").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
