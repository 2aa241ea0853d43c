//! The main command on a machine with no Vulkan driver
//! (`VK_ICD_FILENAMES=/dev/null`): it runs on the CPU with a notice, draws
//! its frames with the CPU rasteriser, and writes the OBJ frames of
//! `--export obj`.

use std::path::PathBuf;
use std::process::Command;

fn run_without_a_driver(dir: &PathBuf, extra: &[&str]) -> String {
    let _ = std::fs::remove_dir_all(dir);
    let out = Command::new(env!("CARGO_BIN_EXE_wgcloth"))
        .args([
            "run", "--grid", "8", "--steps", "8", "--every", "4", "--size", "96", "--out",
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
fn without_an_adapter_the_frames_are_drawn_on_the_cpu() {
    let dir = scratch("frames");
    let stderr = run_without_a_driver(&dir, &[]);
    assert!(
        stderr.contains("drawing them with the CPU rasteriser"),
        "{stderr}"
    );
    // Steps 0, 4 and 8: the cloth (reddish) and the body (bluish) on white.
    for k in 0..3 {
        let path = dir.join(format!("frame_{k:04}.png"));
        let frame = image::open(&path)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .to_rgb8();
        assert_eq!(frame.dimensions(), (96, 96));
        let count = |f: fn(&image::Rgb<u8>) -> bool| frame.pixels().filter(|p| f(p)).count();
        let cloth = count(|p| p[0] as i32 > p[2] as i32 + 30);
        let body = count(|p| p[2] as i32 > p[0] as i32 + 30);
        let white = count(|p| p.0 == [255; 3]);
        assert!(
            cloth > 500 && body > 50 && white > 2000,
            "{}: {cloth} cloth, {body} body, {white} white pixels",
            path.display()
        );
    }
    let gif = std::fs::File::open(dir.join("animation.gif")).unwrap();
    let frames = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(gif)).unwrap();
    assert_eq!(image::AnimationDecoder::into_frames(frames).count(), 3);
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
    std::fs::remove_dir_all(&dir).unwrap();
}
