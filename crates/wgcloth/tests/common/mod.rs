//! Helpers shared by the integration tests.
#![allow(dead_code)]

use glam::{Mat3, Vec3};

/// Central finite-difference Jacobian of f: R³ → R³ at x.
pub fn fd_jacobian(x: Vec3, step: f32, f: impl Fn(Vec3) -> Vec3) -> Mat3 {
    let col = |k: usize| {
        let mut e = Vec3::ZERO;
        e[k] = step;
        (f(x + e) - f(x - e)) / (2.0 * step)
    };
    Mat3::from_cols(col(0), col(1), col(2))
}

pub fn frobenius(m: Mat3) -> f32 {
    m.to_cols_array().iter().map(|e| e * e).sum::<f32>().sqrt()
}

/// Asserts |a − b| ≤ rel |b| + abs (Frobenius), naming the case.
pub fn assert_close(a: Mat3, b: Mat3, rel: f32, abs: f32, what: &str) {
    let err = frobenius(a - b);
    assert!(
        err <= rel * frobenius(b) + abs,
        "{what}: error {err:.3e} vs |J| {:.3e}\n got {a:?}\n want {b:?}",
        frobenius(b)
    );
}

/// A small deterministic generator (xorshift), so tests need no crate.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_f32(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next_f32()
    }

    pub fn vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

/// The headless adapter: a missing one fails the test, unless
/// `WGCLOTH_NO_GPU_TESTS=1` opts out, when the GPU half of a test is
/// skipped with a notice.
pub fn gpu_context() -> Option<wgcloth::gpu::GpuContext> {
    match wgcloth::gpu::GpuContext::headless() {
        Ok(ctx) => Some(ctx),
        Err(e) if !std::env::var("WGCLOTH_NO_GPU_TESTS").is_ok_and(|v| v == "1") => {
            panic!("the GPU tests need an adapter (WGCLOTH_NO_GPU_TESTS=1 skips them): {e}")
        }
        Err(e) => {
            eprintln!("skipping GPU test: {e}");
            None
        }
    }
}

/// The thesis sphere scene on an N×N cloth with `model`.
pub fn sphere(grid: u32, model: wgcloth::config::ModelKind) -> wgcloth::Scene {
    let mut c = wgcloth::Config {
        model,
        ..Default::default()
    };
    c.cloth.grid = [grid, grid];
    wgcloth::Scene::new(&c).unwrap()
}

/// The thesis scene with the sphere crossing the cloth's plane at `speed`
/// m/s instead of its sinusoid, from 0.35 m behind the cloth to 0.75 m in
/// front of it, and the steps that takes. One solve a step, so the body
/// goes deeper than the contact band and the push-out has work to do.
pub fn crossing_config(speed: f32, grid: u32) -> (wgcloth::Config, u64) {
    use wgcloth::config::MotionKind;
    let mut c = wgcloth::Config::default();
    c.cloth.grid = [grid, grid];
    c.solver.substeps = 1;
    c.rigid.position = [0.0, -0.15, -0.35];
    c.rigid.motion.kind = MotionKind::Linear;
    c.rigid.motion.velocity = [0.0, 0.0, speed];
    let steps = (1.1 / speed / c.solver.dt).ceil() as u64;
    (c, steps)
}

/// How deep the deepest of `x` is inside `body` placed at time `t`, m.
pub fn deepest_inside(body: &wgcloth::scene::RigidBody, t: f64, x: &[Vec3]) -> f32 {
    let mut frame = wgcloth::cpu::rigid::RigidFrame::default();
    wgcloth::cpu::rigid::transform(body, t as f32, &mut frame);
    x.iter()
        .map(|&p| wgcloth::cpu::measure::penetration_depth(body, &frame, p))
        .fold(0.0, f32::max)
}

/// Points whose inside test's ray ([`wgcloth::cpu::measure::INSIDE_RAY`])
/// passes exactly through a vertex or an edge's midpoint of `body`'s mesh,
/// before, inside and past the body: each vertex and midpoint moved along
/// the ray by each of eight offsets.
pub fn on_rays_through_vertices_and_edges(body: &wgcloth::scene::RigidBody) -> Vec<Vec3> {
    let vertices = &body.mesh.vertices;
    let midpoints = body.mesh.triangles.iter().flat_map(|t| {
        (0..3).map(|k| 0.5 * (vertices[t[k] as usize] + vertices[t[(k + 1) % 3] as usize]))
    });
    let ray = wgcloth::cpu::measure::INSIDE_RAY;
    vertices
        .iter()
        .copied()
        .chain(midpoints)
        .flat_map(|through| {
            [-1.0, -0.37, -0.11, -0.02, 0.02, 0.11, 0.37, 1.0].map(|s| through + s * ray)
        })
        .collect()
}

/// Whether body-space `p` is inside the convex mesh of `body`, or `None`
/// within `margin` of a face's plane, where the answer is the rounding's.
pub fn inside_convex(body: &wgcloth::scene::RigidBody, p: Vec3, margin: f32) -> Option<bool> {
    let mut inside = true;
    for (t, tri) in body.mesh.triangles.iter().enumerate() {
        let distance = body.face_normals[t].dot(p - body.mesh.vertices[tri[0] as usize]);
        if distance.abs() < margin {
            return None;
        }
        inside &= distance < 0.0;
    }
    Some(inside)
}
