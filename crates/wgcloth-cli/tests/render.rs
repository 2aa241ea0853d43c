//! Frames on lavapipe (or any adapter), checked on their pixels against
//! the geometry they draw, not against stored images. Without an adapter
//! these tests fail unless WGCLOTH_NO_GPU_TESTS=1 opts out.

#[path = "../../wgcloth/tests/common/mod.rs"]
mod common;

use common::gpu_context as gpu;
use std::sync::Arc;

use glam::{Mat4, Vec3};
use wgcloth::config::SceneKind;
use wgcloth::cpu::CpuSim;
use wgcloth::gpu::{GpuContext, GpuSim, Kernels};
use wgcloth::render::{Camera, Frame, HostScene, Renderer, Source, Style, lines};
use wgcloth::{Config, Scene};
use wgcloth_cli::frames::obj::write_obj;
use wgcloth_cli::frames::output::{Exports, FrameWriter, GIF_NAME, frame_name};
use wgcloth_cli::frames::raster;
use wgcloth_cli::frames::usd::USD_NAME;

const SIZE: u32 = 256;

fn scene(kind: SceneKind) -> Scene {
    let mut c = Config {
        scene: kind,
        ..Default::default()
    };
    c.cloth.grid = [16, 16];
    Scene::new(&c).unwrap()
}

fn camera(scene: &Scene) -> Camera {
    Camera::framing(scene, scene.config.rigid.motion.period)
}

/// Pixel coordinates of world point p.
fn project(view_proj: Mat4, p: Vec3) -> (f32, f32) {
    let clip = view_proj * p.extend(1.0);
    let ndc = clip.truncate() / clip.w;
    (
        (0.5 * ndc.x + 0.5) * SIZE as f32,
        (0.5 - 0.5 * ndc.y) * SIZE as f32,
    )
}

fn at(frame: &Frame, (x, y): (f32, f32)) -> [u8; 4] {
    frame.pixel(x as u32, y as u32)
}

// The cloth is reddish, the body bluish, forces pure green, the clear white.
fn is_cloth([r, g, b, _]: [u8; 4]) -> bool {
    r as i32 > g as i32 + 30 && r as i32 > b as i32 + 30
}
fn is_body([r, _, b, _]: [u8; 4]) -> bool {
    b as i32 > r as i32 + 30
}
fn is_green([r, g, b, _]: [u8; 4]) -> bool {
    g > 180 && r < 100 && b < 100
}
fn is_white(p: [u8; 4]) -> bool {
    p[..3].iter().all(|c| *c > 245)
}

fn render_cpu(ctx: &GpuContext, sim: &CpuSim, camera: &Camera, style: Style) -> Frame {
    let host = HostScene::new(&ctx.device, &sim.scene);
    host.upload_sim(&ctx.queue, sim, sim.scene.metres_per_force());
    let renderer = Renderer::new(&ctx.device, SIZE, SIZE).unwrap();
    renderer
        .render(&ctx.device, &ctx.queue, &host.source(), camera, style)
        .unwrap()
}

/// The cloth at rest is a flat square: every point of it projects onto
/// cloth (or the body, which is in front of it from the camera), points
/// just beyond its edges onto background, and the body's centre onto body.
#[test]
fn the_cloth_covers_its_projection_and_the_body_shows_in_front() {
    let Some(ctx) = gpu() else { return };
    let scene = scene(SceneKind::Sphere);
    let camera = camera(&scene);
    let sim = CpuSim::new(scene);
    let frame = render_cpu(&ctx, &sim, &camera, Style::default());
    let view_proj = camera.view_proj(1.0);
    let cloth = &sim.scene.cloth;
    let corner = |i: u32, j: u32| cloth.rest_positions[(j * cloth.nx + i) as usize];
    let (a, b, c) = (
        corner(0, 0),
        corner(cloth.nx - 1, 0),
        corner(0, cloth.ny - 1),
    );
    let point = |u: f32, v: f32| a + u * (b - a) + v * (c - a);
    let (mut inside, mut covered, mut outside, mut clear) = (0, 0, 0, 0);
    for k in 0..=20 {
        for l in 0..=20 {
            let (u, v) = (0.05 + 0.9 * k as f32 / 20.0, 0.05 + 0.9 * l as f32 / 20.0);
            let p = at(&frame, project(view_proj, point(u, v)));
            inside += 1;
            covered += (is_cloth(p) || is_body(p)) as u32;
        }
        // Just beyond each edge.
        let t = k as f32 / 20.0;
        for (u, v) in [(-0.08, t), (1.08, t), (t, -0.08), (t, 1.08)] {
            let p = at(&frame, project(view_proj, point(u, v)));
            outside += 1;
            clear += (is_white(p) || is_body(p)) as u32;
        }
    }
    assert_eq!(covered, inside, "cloth pixels inside its projection");
    assert_eq!(clear, outside, "background just outside the cloth");
    let body = sim.scene.rigid.as_ref().unwrap();
    let centre = body.translation(0.0);
    let middle = at(&frame, project(view_proj, centre));
    assert!(is_body(middle), "the body's centre: {middle:?}");
    // Both colours are lit, not flat: some shading variation on the body.
    let (x, y) = project(view_proj, centre);
    let shades: std::collections::BTreeSet<u8> = (-10..=10)
        .map(|d| frame.pixel(x as u32, (y + d as f32) as u32)[2])
        .collect();
    assert!(shades.len() > 3, "the body is shaded: {shades:?}");
}

/// In contact, every contact's segment starts at a green pixel, and green
/// appears only when forces are drawn.
#[test]
fn force_segments_are_green_where_contacts_are() {
    let Some(ctx) = gpu() else { return };
    let scene = scene(SceneKind::Sphere);
    let camera = camera(&scene);
    let mut sim = CpuSim::new(scene);
    for _ in 0..70 {
        sim.step();
    }
    assert!(sim.contacts().len() > 10, "the sphere must be in contact");
    let with = render_cpu(
        &ctx,
        &sim,
        &camera,
        Style {
            forces: true,
            wireframe: false,
        },
    );
    let without = render_cpu(&ctx, &sim, &camera, Style::default());
    let view_proj = camera.view_proj(1.0);
    let near_green = |(x, y): (f32, f32)| {
        (-2..=2).any(|dx: i32| {
            (-2..=2).any(|dy: i32| {
                let (px, py) = (x as i32 + dx, y as i32 + dy);
                (0..SIZE as i32).contains(&px)
                    && (0..SIZE as i32).contains(&py)
                    && is_green(with.pixel(px as u32, py as u32))
            })
        })
    };
    let segments = lines::force_lines(&sim, sim.scene.metres_per_force());
    let in_use: Vec<[Vec3; 2]> = segments
        .chunks_exact(2)
        .filter(|pair| pair[0][3] != 0.0)
        .map(|pair| [0, 1].map(|k| Vec3::from_slice(&pair[k][..3])))
        .collect();
    assert_eq!(in_use.len(), sim.contacts().len());
    // A segment shorter than 2 pixels on screen (a contact without force,
    // or one along the line of sight) may rasterise to nothing.
    let on_screen = |[a, b]: [Vec3; 2]| {
        let ((ax, ay), (bx, by)) = (project(view_proj, a), project(view_proj, b));
        (ax - bx).hypot(ay - by) >= 2.0
    };
    let starts: Vec<Vec3> = in_use
        .iter()
        .filter(|s| on_screen(**s))
        .map(|s| s[0])
        .collect();
    assert!(
        starts.len() > 10,
        "only {} segments to look for",
        starts.len()
    );
    let marked = starts
        .iter()
        .filter(|p| near_green(project(view_proj, **p)))
        .count();
    assert_eq!(marked, starts.len(), "contacts with a green segment");
    // The sphere stays in sight as it pushes the cloth.
    let centre = sim.rigid_frame().unwrap().translation;
    let middle = at(&without, project(view_proj, centre));
    assert!(is_body(middle), "the body's centre in contact: {middle:?}");
    let green = |f: &Frame| {
        f.rgba
            .chunks_exact(4)
            .filter(|p| is_green([p[0], p[1], p[2], p[3]]))
            .count()
    };
    assert!(green(&with) >= starts.len());
    assert_eq!(green(&without), 0);
}

/// A GPU run's frame, drawn from the simulator's own buffers, matches the
/// CPU run's frame of the same step (the two runs agree to rounding before
/// contact), with a body and without one (whose empty triangle list must
/// still bind).
#[test]
fn gpu_frames_draw_from_the_simulators_buffers_like_the_cpu() {
    let Some(ctx) = gpu() else { return };
    for kind in [SceneKind::Sphere, SceneKind::Hang] {
        gpu_frame_matches_the_cpu(&ctx, scene(kind));
    }
}

fn gpu_frame_matches_the_cpu(ctx: &GpuContext, scene: Scene) {
    let camera = camera(&scene);
    let kernels = Arc::new(Kernels::new(&ctx.device).unwrap());
    let gpu_sim = GpuSim::with_kernels(&kernels, &ctx.device, &ctx.queue, &scene).unwrap();
    let mut cpu_sim = CpuSim::new(scene.clone());
    for _ in 0..20 {
        gpu_sim.step();
        cpu_sim.step();
    }
    let style = Style {
        wireframe: true,
        forces: true,
    };
    let renderer = Renderer::new(&ctx.device, SIZE, SIZE).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    gpu_sim.record_force_lines(&mut encoder);
    ctx.queue.submit([encoder.finish()]);
    let from_gpu = renderer
        .render(
            &ctx.device,
            &ctx.queue,
            &Source::gpu(&gpu_sim, &scene),
            &camera,
            style,
        )
        .unwrap();
    ctx.finish()
        .expect("no device error drawing from the GPU's buffers");
    let from_cpu = render_cpu(ctx, &cpu_sim, &camera, style);
    let differing = from_gpu
        .rgba
        .chunks_exact(4)
        .zip(from_cpu.rgba.chunks_exact(4))
        .filter(|(a, b)| a.iter().zip(*b).any(|(x, y)| x.abs_diff(*y) > 8))
        .count();
    let drawn = from_cpu.rgba.chunks_exact(4).filter(|p| p[0] < 245).count();
    assert!(drawn > 1000, "the frame shows the scene");
    assert!(
        differing * 100 <= drawn,
        "{differing} of {drawn} drawn pixels differ"
    );
}

/// The frame of `steps` steps of the 16² sphere scene in `style`, drawn
/// by the GPU's renderer (lavapipe here) and by the CPU rasteriser (what
/// draws frames with no adapter), as RGBA pixels.
type Pixels = Vec<[u8; 4]>;
fn both_renderers(ctx: &GpuContext, steps: u32, style: Style) -> (Pixels, Pixels) {
    let scene = scene(SceneKind::Sphere);
    let camera = camera(&scene);
    let mut sim = CpuSim::new(scene.clone());
    for _ in 0..steps {
        sim.step();
    }
    assert!(!sim.contacts().is_empty(), "the body is in contact");
    let body = scene.rigid.as_ref().unwrap();
    let placed = body.placed_vertices(sim.state.time as f32);
    let lines = lines::force_lines(&sim, scene.metres_per_force());
    let geometry = raster::Geometry {
        cloth: &sim.state.x,
        grid: [scene.cloth.nx, scene.cloth.ny],
        triangles: &scene.cloth.triangles,
        body: &placed,
        body_triangles: &body.mesh.triangles,
        lines: &lines,
    };
    let pixels = |f: Frame| {
        (f.rgba.chunks_exact(4))
            .map(|p| [p[0], p[1], p[2], p[3]])
            .collect()
    };
    (
        pixels(render_cpu(ctx, &sim, &camera, style)),
        pixels(raster::render(&geometry, &camera, style, [SIZE; 2])),
    )
}

/// The surfaces of a cloth folded around the body, where the camera sees
/// it: the same silhouette (pixels that are not background) to within a
/// few edge pixels, and the same shading where both draw (the cloth shaded
/// flat instead of by its vertex normals differs by 2.1 levels on average).
#[test]
fn the_cpu_rasteriser_shades_the_frame_the_gpu_draws() {
    let Some(ctx) = gpu() else { return };
    let (gpu_frame, cpu_frame) = both_renderers(&ctx, 100, Style::default());
    let background = |p: &[u8; 4]| *p == [255, 255, 255, 255];
    let (mut either, mut one, mut both, mut shading) = (0, 0, 0, 0u64);
    for (g, c) in gpu_frame.iter().zip(&cpu_frame) {
        match (background(g), background(c)) {
            (true, true) => {}
            (false, false) => {
                either += 1;
                both += 1;
                shading += (0..3).map(|k| g[k].abs_diff(c[k]) as u64).max().unwrap();
            }
            _ => (either, one) = (either + 1, one + 1),
        }
    }
    let body = cpu_frame.iter().filter(|p| is_body(**p)).count();
    let cloth = cpu_frame.iter().filter(|p| is_cloth(**p)).count();
    assert!(
        body > 1000 && cloth > 5000,
        "{body} body and {cloth} cloth pixels"
    );
    assert!(
        one * 200 <= either,
        "{one} of {either} pixels are drawn by one renderer only"
    );
    let mean = shading as f64 / both as f64;
    assert!(
        mean < 1.0,
        "the colours both draw differ by {mean:.2} levels on average"
    );
}

/// The forces, drawn over everything: green within a pixel wherever the
/// GPU draws green (a segment's pixels may step differently).
#[test]
fn the_cpu_rasteriser_draws_the_forces_the_gpu_draws() {
    let Some(ctx) = gpu() else { return };
    let forces = Style {
        wireframe: false,
        forces: true,
    };
    let (gpu_frame, cpu_frame) = both_renderers(&ctx, 40, forces);
    let n = SIZE as usize;
    let green = |x: usize, y: usize| {
        (y.saturating_sub(1)..(y + 2).min(n))
            .any(|j| (x.saturating_sub(1)..(x + 2).min(n)).any(|i| is_green(cpu_frame[j * n + i])))
    };
    let drawn: Vec<usize> = (0..n * n).filter(|&i| is_green(gpu_frame[i])).collect();
    let shared = drawn.iter().filter(|&&i| green(i % n, i / n)).count();
    assert!(
        drawn.len() > 100,
        "the GPU draws forces ({} pixels)",
        drawn.len()
    );
    assert!(
        shared * 100 >= drawn.len() * 95,
        "{shared} of the GPU's {} force pixels have green within a pixel on the CPU",
        drawn.len()
    );
}

#[test]
fn a_frame_size_beyond_the_adapter_is_one_clear_error() {
    let Some(ctx) = gpu() else { return };
    let most = ctx.device.limits().max_texture_dimension_2d;
    for (w, h) in [(0, 64), (most + 1, 64)] {
        let err = Renderer::new(&ctx.device, w, h).err().unwrap().to_string();
        assert!(
            err.contains("--size") && err.contains(&most.to_string()),
            "{err}"
        );
    }
}

/// `--out` refuses a file in the way and, without `--force`, frames
/// already there; it creates a missing directory.
#[test]
fn the_frame_directory_is_checked_before_writing() {
    let root = std::env::temp_dir().join(format!("wgcloth-frames-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    std::fs::create_dir_all(&root).unwrap();
    let file = root.join("a-file");
    std::fs::write(&file, "keep me").unwrap();
    let (none, both) = (
        Exports::default(),
        Exports {
            obj: true,
            usd: true,
        },
    );
    let err = FrameWriter::create(&file, 3, (40, none), false)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("a-file") && err.contains("is a file"), "{err}");
    assert_eq!(std::fs::read_to_string(&file).unwrap(), "keep me");

    let dir = root.join("new/frames");
    let mut writer = FrameWriter::create(&dir, 3, (40, both), false).unwrap();
    let frame = Frame {
        width: 2,
        height: 2,
        rgba: vec![255; 16],
    };
    writer.write(&frame).unwrap();
    writer.finish(&scene(SceneKind::Hang)).unwrap();
    assert!(dir.join(frame_name(0)).is_file());
    // The run's USD file, written at the end, is refused as a frame is.
    std::fs::remove_file(dir.join(frame_name(0))).unwrap();
    std::fs::remove_file(dir.join(GIF_NAME)).unwrap();
    let err = FrameWriter::create(&dir, 3, (40, both), false)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains(USD_NAME) && err.contains("--force"), "{err}");
    writer = FrameWriter::create(&dir, 3, (40, both), true).unwrap();
    writer.write(&frame).unwrap();
    writer.finish(&scene(SceneKind::Hang)).unwrap();
    let err = FrameWriter::create(&dir, 3, (40, both), false)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("frame_0000.png") && err.contains("--force"),
        "{err}"
    );
    FrameWriter::create(&dir, 3, (40, both), true).unwrap();
    std::fs::remove_dir_all(&root).unwrap();
}

/// `--export obj`: a frame's file loads back (with tobj, as Blender's
/// importer reads it) as the simulated cloth and the placed body.
#[test]
fn obj_frames_load_back_as_the_simulated_geometry() {
    let scene = scene(SceneKind::Sphere);
    let mut sim = CpuSim::new(scene);
    for _ in 0..30 {
        sim.step();
    }
    let time = sim.state.time as f32;
    let path = std::env::temp_dir().join(format!("wgcloth-obj-{}.obj", std::process::id()));
    write_obj(&path, &sim.scene, &sim.state.x, time).unwrap();
    let (models, _) = tobj::load_obj(&path, &tobj::LoadOptions::default()).unwrap();
    std::fs::remove_file(&path).unwrap();
    let names: Vec<&str> = models.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["cloth", "body"]);
    let points = |m: &tobj::Model| -> Vec<Vec3> {
        m.mesh
            .positions
            .chunks_exact(3)
            .map(Vec3::from_slice)
            .collect()
    };
    // tobj numbers each object's vertices in the order its faces use them,
    // so compare corner by corner.
    let corners = |m: &tobj::Model| -> Vec<Vec3> {
        let p = points(m);
        m.mesh.indices.iter().map(|&i| p[i as usize]).collect()
    };
    let cloth: Vec<Vec3> = sim
        .scene
        .cloth
        .triangles
        .iter()
        .flatten()
        .map(|&i| sim.state.x[i as usize])
        .collect();
    assert_eq!(corners(&models[0]), cloth);
    let frame = sim.rigid_frame().unwrap();
    let body = sim.scene.rigid.as_ref().unwrap();
    let placed: Vec<Vec3> = body
        .mesh
        .triangles
        .iter()
        .flatten()
        .map(|&i| frame.vertices[i as usize])
        .collect();
    let worst = corners(&models[1])
        .iter()
        .zip(&placed)
        .map(|(a, b)| (*a - *b).length())
        .fold(0.0f32, f32::max);
    assert_eq!(corners(&models[1]).len(), placed.len());
    assert!(worst < 1e-5, "body vertices {worst} m from the simulator's");
}
