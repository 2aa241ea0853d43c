//! The configs in `scenes/` load, build and step: what a user runs with
//! `wgcloth run --config scenes/NAME.toml`.

use std::path::Path;

use wgcloth::config::Config;
use wgcloth::cpu::CpuSim;
use wgcloth::intersections::intersecting_pairs;
use wgcloth::scene::Scene;

#[test]
fn every_scene_config_loads_starts_untangled_and_steps_finite() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&dir).expect("scenes/") {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let config = Config::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let scene = Scene::new(&config).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(
            scene.rigid.is_some(),
            "{}: a body folds the cloth",
            path.display()
        );
        let triangles = &scene.cloth.triangles;
        assert!(intersecting_pairs(&scene.cloth.rest_positions, triangles).is_empty());
        let mut sim = CpuSim::new(scene);
        for _ in 0..20 {
            sim.step();
        }
        assert!(
            sim.state.x.iter().all(|p| p.is_finite()),
            "{}",
            path.display()
        );
        names.push(path.file_stem().unwrap().to_string_lossy().into_owned());
    }
    names.sort();
    assert_eq!(names, ["drape", "pleat"]);
}
