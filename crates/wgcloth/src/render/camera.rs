//! A camera that frames the scene: the cloth at rest and the rigid body
//! wherever its motion takes it during the run, seen obliquely from the
//! side the body approaches (as in thesis Figures 1–2).

use glam::camera::rh::{proj::directx, view::look_at_mat4};
use glam::{Mat4, Vec3};

use crate::scene::Scene;

/// A perspective camera looking from `eye` at `target`, y up, with one
/// directional light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Where the camera is, world, m.
    pub eye: Vec3,
    /// The point it looks at, world, m.
    pub target: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Direction towards the light.
    pub light: Vec3,
}

/// From the target towards the eye: on the side the body comes from (−z),
/// a little to the side and above, so the body is seen pushing into the
/// cloth.
const VIEW: Vec3 = Vec3::new(0.55, 0.35, -1.0);

/// Towards the light: above, and on the camera's side of the cloth, so
/// that the side the camera sees is lit and its folds shade.
const LIGHT: Vec3 = Vec3::new(-0.3, 0.8, -0.6);

impl Camera {
    /// Frames everything the scene occupies over `duration` seconds.
    pub fn framing(scene: &Scene, duration: f32) -> Camera {
        let cloth = &scene.cloth;
        let mut points = cloth.rest_positions.clone();
        // A cloth pinned nowhere falls: as far as its own width below its
        // start, draped over the body or hanging from it.
        if !cloth.pinned.iter().any(|&p| p) {
            let (lo, hi) = extent(&points);
            let fall = (hi - lo).max_element()
                * Vec3::from_array(scene.config.solver.gravity).normalize_or_zero();
            points.extend(cloth.rest_positions.iter().map(|&p| p + fall));
        }
        if let Some(body) = &scene.rigid {
            for k in 0..=16 {
                points.extend(body.placed_vertices(duration * k as f32 / 16.0));
            }
        }
        let (lo, hi) = extent(&points);
        let target = 0.5 * (lo + hi);
        let radius = (0.5 * (hi - lo).length()).max(1e-3);
        let fov_y = 40f32.to_radians();
        let distance = 1.05 * radius / (0.5 * fov_y).sin();
        Camera {
            eye: target + distance * VIEW.normalize(),
            target,
            fov_y,
            light: LIGHT.normalize(),
        }
    }

    /// World → clip space for a target of this aspect ratio (width / height).
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        let distance = (self.eye - self.target).length();
        // Narrow the view for a tall target so the scene still fits.
        let fov_y = if aspect < 1.0 {
            2.0 * ((0.5 * self.fov_y).tan() / aspect).atan()
        } else {
            self.fov_y
        };
        // wgpu's clip space: depth in [0, 1], y up (glam's "directx").
        directx::perspective(fov_y, aspect, 0.01 * distance, 10.0 * distance)
            * look_at_mat4(self.eye, self.target, Vec3::Y)
    }
}

/// The least and greatest corners of `points`' box.
fn extent(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}
