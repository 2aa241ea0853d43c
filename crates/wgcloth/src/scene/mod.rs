//! A scene: the cloth and the optional rigid body built from a validated
//! [`Config`]. Immutable during a run; the per-step state lives with the
//! backend that steps it.

pub mod cloth;
pub mod mesh;
pub mod rigid;

use glam::{Quat, Vec3};

use crate::config::{Config, MotionKind, Pins, Rotation, SceneKind, Shape};
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
        Ok(Scene {
            config: config.clone(),
            cloth,
            rigid,
            network,
        })
    }
}
