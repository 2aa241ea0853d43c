//! A scene: the cloth and the optional rigid body built from a validated
//! [`Config`]. Immutable during a run; the per-step state lives with the
//! backend that steps it.

pub mod cloth;
pub mod mesh;
pub mod rigid;

use glam::{Quat, Vec3};

use crate::config::{
    Config, MAX_BODY_TRAVEL, MAX_SUBSTEPS, MotionKind, Pins, Rotation, SceneKind, Shape,
};
use crate::error::{Error, Result};
use crate::nn::weights::Network;
pub use cloth::Cloth;
pub use mesh::TriMesh;
pub use rigid::{Motion, RigidBody};
use std::sync::Arc;

/// What a run simulates, built once from a config (see the module docs).
#[derive(Clone, Debug)]
pub struct Scene {
    /// The validated configuration it was built from.
    pub config: Config,
    /// The cloth.
    pub cloth: Cloth,
    /// The rigid body; `None` in the `hang` scene.
    pub rigid: Option<RigidBody>,
    /// The collision network, folded to physical units, for network models.
    pub network: Option<Arc<Network>>,
    /// Backward Euler steps of [`Scene::substep_dt`] per step of
    /// `solver.dt` ([`substeps`]).
    pub substeps: u32,
}

fn quat(r: &Rotation) -> Quat {
    Quat::from_axis_angle(Vec3::from_array(r.axis).normalize(), r.degrees.to_radians())
}

impl Scene {
    /// Metres of drawn force segment per unit of contact force: 5 cm on a
    /// 32×32 cloth, and in proportion to the vertex count, as each
    /// vertex's share of the contact force falls with it.
    pub fn metres_per_force(&self) -> f32 {
        0.05 * self.cloth.vertex_count() as f32 / 1024.0
    }

    /// Validates `config` and builds its cloth, its rigid body (reading an
    /// OBJ mesh if it names one) and the network of a network model.
    pub fn new(config: &Config) -> Result<Scene> {
        config.validate()?;
        let c = &config.cloth;
        let [nx, ny] = c.grid;
        let pinned: Vec<u32> = match c.pins {
            Pins::TopCorners => vec![0, nx - 1],
            Pins::TopEdge => (0..nx).collect(),
            Pins::None => vec![],
        };
        let (rot, center, [w, h]) = (quat(&c.rotation), Vec3::from_array(c.center), c.size);
        let cloth = Cloth::grid(nx, ny, c.mass, c.stiffness, &pinned, |u, v| {
            center + rot * Vec3::new((u - 0.5) * w, (0.5 - v) * h, 0.0)
        });

        let rigid = match config.scene {
            SceneKind::Hang => None,
            SceneKind::Sphere => {
                let r = &config.rigid;
                let mesh = match r.shape {
                    Shape::Sphere => TriMesh::icosphere(r.radius, r.subdivisions),
                    Shape::Box => TriMesh::cuboid(Vec3::from_array(r.half_extents), r.subdivisions),
                    Shape::Plane => TriMesh::plane(r.plane_size, r.subdivisions),
                    Shape::Obj => {
                        let path = r.mesh.as_ref().ok_or_else(|| {
                            Error::config("rigid.mesh", "shape `obj` needs a mesh file")
                        })?;
                        TriMesh::load_obj(path)?.scaled(r.scale)
                    }
                };
                let m = &r.motion;
                let motion = match m.kind {
                    MotionKind::Static => Motion::Static,
                    MotionKind::Linear => Motion::Linear {
                        velocity: Vec3::from_array(m.velocity),
                    },
                    MotionKind::Sinusoid => Motion::Sinusoid {
                        axis: Vec3::from_array(m.axis).normalize(),
                        amplitude: m.amplitude,
                        period: m.period,
                        phase: m.phase_deg.to_radians(),
                    },
                };
                Some(RigidBody::new(
                    mesh,
                    quat(&r.rotation),
                    Vec3::from_array(r.position),
                    motion,
                ))
            }
        };
        let network = config.read_weights()?.map(|file| Arc::new(file.network()));
        let substeps = substeps(config, &cloth, rigid.as_ref())?;
        Ok(Scene {
            config: config.clone(),
            cloth,
            rigid,
            network,
            substeps,
        })
    }

    /// The time step each backward Euler solve takes, s: `solver.dt` over
    /// [`Scene::substeps`].
    pub fn substep_dt(&self) -> f32 {
        self.config.solver.dt / self.substeps as f32
    }
}

/// The substeps of one step: `solver.substeps`, or where that is 0 the
/// fewest that keep how far the body and the cloth close in one within
/// [`MAX_BODY_TRAVEL`] times the cloth's shortest rest length. A step is
/// one linear solve, linearised where it starts (thesis eq. 1): a body
/// that sweeps past a vertex by about the cloth's spacing in one flings it
/// out of the cloth, and a cloth that falls onto the body as fast is
/// stretched as far (BENCHMARKS.md, "Substeps that keep the body within
/// half a spacing", "A falling cloth closes on the body too"). They close
/// at most at the body's top speed plus [`fall_speed`]. An error where
/// that would take more than [`MAX_SUBSTEPS`].
pub fn substeps(config: &Config, cloth: &Cloth, rigid: Option<&RigidBody>) -> Result<u32> {
    let fixed = config.solver.substeps;
    if fixed > 0 {
        return Ok(fixed);
    }
    let gravity = Vec3::from_array(config.solver.gravity);
    let closing = rigid.map_or(0.0, |body| {
        body.motion.top_speed() + fall_speed(cloth, body, gravity)
    });
    let travel = closing * config.solver.dt;
    let spacing = cloth
        .rest_lengths
        .iter()
        .copied()
        .fold(f32::INFINITY, f32::min);
    let needed = (travel / (MAX_BODY_TRAVEL * spacing)).ceil().max(1.0);
    if needed > MAX_SUBSTEPS as f32 {
        return Err(Error::config(
            "solver.substeps",
            format!(
                "the body and the cloth close by up to {:.1} mm a step against a cloth spacing of {:.2} mm, which needs {needed} substeps, more than {MAX_SUBSTEPS}; lower solver.dt",
                1e3 * travel,
                1e3 * spacing
            ),
        ));
    }
    Ok(needed as u32)
}

/// The fastest an unpinned cloth, falling from rest, can meet the body,
/// m/s: √(2 |g| Δh) by its energy, Δh from its highest vertex down to the
/// lowest point the body reaches. A body moving away as it falls is met
/// slower than its speed plus that, so the start is the lowest a linear
/// motion needs. A cloth on pins hangs from them where it starts: 0.
pub fn fall_speed(cloth: &Cloth, body: &RigidBody, gravity: Vec3) -> f32 {
    let g = gravity.length();
    if g == 0.0 || cloth.pinned.contains(&true) {
        return 0.0;
    }
    let down = gravity / g;
    let height = |p: Vec3| -p.dot(down);
    let highest = (cloth.rest_positions.iter()).fold(f32::NEG_INFINITY, |h, &p| h.max(height(p)));
    let lowest = (body.mesh.vertices.iter()).fold(f32::INFINITY, |h, &v| {
        h.min(height(body.rotation * v + body.position))
    }) - body.motion.deepest(down);
    (2.0 * g * (highest - lowest).max(0.0)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The substeps a scene takes, or the error's text.
    fn substeps_of(grid: u32, edit: impl Fn(&mut Config)) -> std::result::Result<u32, String> {
        let mut c = Config::default();
        c.cloth.grid = [grid, grid];
        edit(&mut c);
        Scene::new(&c)
            .map(|s| s.substeps)
            .map_err(|e| e.to_string())
    }

    /// The thesis sphere moves 7.85 mm a step at most (0.25 m at 2π / 2 s
    /// over 0.01 s): within half the spacing of a 64² cloth (7.94 mm), and
    /// 1.99 and 4.01 halves of the 128² and 256² spacings. No body or a
    /// body at rest takes one solve a step; `solver.substeps` sets them;
    /// a body too fast for `MAX_SUBSTEPS` is an error naming the field.
    #[test]
    fn substeps_keep_the_body_within_half_a_spacing() {
        let default = |_: &mut Config| {};
        assert_eq!(substeps_of(32, default), Ok(1));
        assert_eq!(substeps_of(64, default), Ok(1));
        assert_eq!(substeps_of(128, default), Ok(2));
        assert_eq!(substeps_of(256, default), Ok(5));
        assert_eq!(substeps_of(256, |c| c.scene = SceneKind::Hang), Ok(1));
        assert_eq!(
            substeps_of(256, |c| c.rigid.motion.kind = MotionKind::Static),
            Ok(1)
        );
        assert_eq!(substeps_of(256, |c| c.solver.substeps = 3), Ok(3));
        // Half the step, half the travel.
        assert_eq!(substeps_of(256, |c| c.solver.dt = 0.005), Ok(3));
        // A cloth on pins hangs from them: the thesis cloth's pins alone
        // keep its 256² step at 5.
        let fallen = |c: &mut Config| c.cloth.pins = Pins::None;
        assert!(substeps_of(256, fallen).unwrap() > 5);
        let fast = substeps_of(64, |c| c.rigid.motion.period = 0.01).unwrap_err();
        assert!(
            fast.contains("solver.substeps") && fast.contains("lower solver.dt"),
            "{fast}"
        );
    }

    /// An unpinned cloth falls onto the body at √(2 g Δh), Δh from its top
    /// down to the body's lowest point (the thesis cloth's top 0.5 m up, its
    /// sphere of 0.2 m at 0.15 m down: Δh = 0.85 m), to a vertical swing's
    /// bottom too (0.25 m lower); on its pins or without gravity it does
    /// not fall.
    #[test]
    fn fall_speed_is_a_fall_from_the_cloths_top_to_the_bodys_lowest_point() {
        let fall = |edit: &dyn Fn(&mut Config)| {
            let mut c = Config::default();
            c.cloth.pins = Pins::None;
            c.rigid.motion.kind = MotionKind::Static;
            edit(&mut c);
            let scene = Scene::new(&c).unwrap();
            let g = Vec3::from_array(c.solver.gravity);
            fall_speed(&scene.cloth, scene.rigid.as_ref().unwrap(), g)
        };
        let energy = |h: f32| (2.0 * 9.81 * h).sqrt();
        // The icosphere's lowest vertex lies within 1 mm of its pole.
        let speed = fall(&|_| {});
        assert!((energy(0.849)..=energy(0.85)).contains(&speed), "{speed}");
        let swing = fall(&|c| {
            c.rigid.motion.kind = MotionKind::Sinusoid;
            c.rigid.motion.axis = [0.0, 1.0, 0.0];
        });
        assert!((energy(1.099)..=energy(1.1)).contains(&swing), "{swing}");
        assert_eq!(fall(&|c| c.cloth.pins = Pins::TopCorners), 0.0);
        assert_eq!(fall(&|c| c.solver.gravity = [0.0; 3]), 0.0);
    }
}
