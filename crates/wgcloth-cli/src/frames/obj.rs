//! `wgcloth run --out DIR --export obj`: each frame's geometry as a
//! Wavefront OBJ file (`frame_NNNN.obj`) with two objects, `cloth` and
//! `body`, in world coordinates (metres, y up), which Blender imports as a
//! sequence.

use std::fmt::Write as _;
use std::path::Path;

use glam::Vec3;

use wgcloth::error::{Error, Result};
use wgcloth::scene::Scene;

/// The OBJ file of frame `k`.
pub fn obj_name(k: usize) -> String {
    format!("frame_{k:04}.obj")
}

/// The OBJ text of the cloth at `x` and the body placed at `time`.
pub fn obj_text(scene: &Scene, x: &[Vec3], time: f32) -> String {
    let mut out = String::from("# wgcloth frame\n");
    let mut object = |name: &str, vertices: &[Vec3], triangles: &[[u32; 3]], base: usize| {
        let _ = writeln!(out, "o {name}");
        for v in vertices {
            let _ = writeln!(out, "v {} {} {}", v.x, v.y, v.z);
        }
        // OBJ indices count from 1 across the whole file.
        for t in triangles {
            let [a, b, c] = t.map(|i| base + i as usize + 1);
            let _ = writeln!(out, "f {a} {b} {c}");
        }
    };
    object("cloth", x, &scene.cloth.triangles, 0);
    if let Some(body) = &scene.rigid {
        let placed = body.placed_vertices(time);
        object("body", &placed, &body.mesh.triangles, x.len());
    }
    out
}

pub fn write_obj(path: &Path, scene: &Scene, x: &[Vec3], time: f32) -> Result<()> {
    std::fs::write(path, obj_text(scene, x, time)).map_err(|e| Error::io(path, e))
}
