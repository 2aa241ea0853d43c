//! Renders one frame of the thesis scene to a PNG with a tiny software
//! rasteriser (z-buffer, two-sided Lambert shading): the README picture.
//! The real renderer (wgpu, Phong, wireframe, force vectors) is a later issue.
//!
//! `cargo run --release --example snapshot -- [STEPS] [OUT.png]`

use glam::{Mat4, Vec3, Vec4Swizzles};
use image::{Rgb, RgbImage};
use wgcloth::cpu::CpuSim;
use wgcloth::{Config, Scene};

const SIZE: u32 = 512;

struct Canvas {
    image: RgbImage,
    depth: Vec<f32>,
    view_proj: Mat4,
    light: Vec3,
}

impl Canvas {
    fn to_screen(&self, p: Vec3) -> Vec3 {
        let c = self.view_proj * p.extend(1.0);
        let ndc = c.xyz() / c.w;
        Vec3::new(
            (ndc.x + 1.0) * 0.5 * SIZE as f32,
            (1.0 - ndc.y) * 0.5 * SIZE as f32,
            ndc.z,
        )
    }

    fn triangle(&mut self, world: [Vec3; 3], color: Vec3) {
        let normal = (world[1] - world[0])
            .cross(world[2] - world[0])
            .normalize_or_zero();
        let shade = 0.25 + 0.75 * normal.dot(self.light).abs(); // two-sided
        let rgb = (color * shade * 255.0).min(Vec3::splat(255.0));
        let [a, b, c] = world.map(|p| self.to_screen(p));
        let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
        if area.abs() < 1e-9 {
            return;
        }
        let lo = a.min(b).min(c).max(Vec3::ZERO);
        let hi = a.max(b).max(c).min(Vec3::splat(SIZE as f32 - 1.0));
        for y in lo.y as u32..=hi.y as u32 {
            for x in lo.x as u32..=hi.x as u32 {
                let p = (x as f32 + 0.5, y as f32 + 0.5);
                let w0 = ((c.x - b.x) * (p.1 - b.y) - (c.y - b.y) * (p.0 - b.x)) / area;
                let w1 = ((a.x - c.x) * (p.1 - c.y) - (a.y - c.y) * (p.0 - c.x)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * a.z + w1 * b.z + w2 * c.z;
                let k = (y * SIZE + x) as usize;
                if z < self.depth[k] {
                    self.depth[k] = z;
                    self.image
                        .put_pixel(x, y, Rgb([rgb.x as u8, rgb.y as u8, rgb.z as u8]));
                }
            }
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let steps: u64 = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(90);
    let out = args
        .get(2)
        .cloned()
        .unwrap_or_else(|| "docs/thesis_scene.png".into());
    let mut config = Config {
        model: wgcloth::config::ModelKind::Friction,
        ..Config::default()
    };
    config.cloth.grid = [48, 48];
    let mut sim = CpuSim::new(Scene::new(&config)?);
    for _ in 0..steps {
        sim.step();
    }
    let eye = Vec3::new(1.6, 0.35, -1.2);
    let view = glam::camera::rh::view::look_at_mat4(eye, Vec3::new(0.0, -0.1, 0.0), Vec3::Y);
    let proj = glam::camera::rh::proj::directx::perspective(40f32.to_radians(), 1.0, 0.1, 10.0);
    let mut canvas = Canvas {
        image: RgbImage::from_pixel(SIZE, SIZE, Rgb([240, 240, 236])),
        depth: vec![f32::INFINITY; (SIZE * SIZE) as usize],
        view_proj: proj * view,
        light: Vec3::new(0.4, 0.8, 0.6).normalize(),
    };
    if let Some(frame) = sim.rigid_frame() {
        let body = sim.scene.rigid.as_ref().expect("frame implies a body");
        for t in &body.mesh.triangles {
            canvas.triangle(
                t.map(|i| frame.vertices[i as usize]),
                Vec3::new(0.55, 0.57, 0.62),
            );
        }
    }
    let nx = sim.scene.cloth.nx;
    for (k, t) in sim.scene.cloth.triangles.iter().enumerate() {
        // A checkerboard of 4×4-cell squares shows how the cloth stretches.
        let cell = (k / 2) as u32;
        let checker = ((cell % (nx - 1)) / 4 + (cell / (nx - 1)) / 4).is_multiple_of(2);
        let color = if checker {
            Vec3::new(0.85, 0.3, 0.25)
        } else {
            Vec3::new(0.95, 0.8, 0.45)
        };
        canvas.triangle(t.map(|i| sim.state.x[i as usize]), color);
    }
    canvas.image.save(&out)?;
    println!(
        "{out}: thesis scene after {steps} steps (t = {:.2} s)",
        sim.state.time
    );
    Ok(())
}
