//! Run configuration: the thesis scene by default, overridden by a TOML
//! file and then by command-line flags, and validated field by field so a
//! bad value is reported by its dotted name before anything runs.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::nn::weights::{self, NetKind, Shipped, WeightsFile};

/// The scene a run simulates (`scene`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SceneKind {
    /// Cloth pinned at its top corners, a rigid body moving through it.
    Sphere,
    /// The cloth alone, hanging under gravity.
    Hang,
}

/// The PCG preconditioner (`solver.preconditioner`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Preconditioner {
    /// A geometric multigrid V-cycle on the cloth's grid: iterations to a
    /// tolerance grow slowly with the grid (docs/DESIGN.md "The solve").
    #[default]
    Multigrid,
    /// The diagonal of A (the thesis's).
    Jacobi,
}

impl Preconditioner {
    /// Every preconditioner.
    pub const ALL: [Preconditioner; 2] = [Preconditioner::Multigrid, Preconditioner::Jacobi];

    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Preconditioner::Multigrid => "multigrid",
            Preconditioner::Jacobi => "jacobi",
        }
    }
}

/// How the multigrid preconditioner smooths each level but the coarsest
/// (`solver.smoother`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Smoother {
    /// Block Gauss-Seidel over 2 × 2-node patches, each solved exactly, in
    /// four colours: forward before the coarse correction, backward after
    /// (docs/DESIGN.md "The solve").
    #[default]
    Patches,
    /// Damped block Jacobi, one 3 × 3 block per node.
    BlockJacobi,
}

impl Smoother {
    /// Every smoother.
    pub const ALL: [Smoother; 2] = [Smoother::Patches, Smoother::BlockJacobi];

    /// The name used in configs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Smoother::Patches => "patches",
            Smoother::BlockJacobi => "block-jacobi",
        }
    }
}

/// The collision model (`model`; DESIGN "Collision models").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ModelKind {
    /// Penalty force f = −c d̃ n (thesis eq. 6).
    Naive,
    /// Contact and Coulomb friction force (thesis eqs. 8–9).
    Friction,
    /// The friction force predicted by the trained network (thesis 2.6–2.7),
    /// its input Jacobian as the contact stiffness.
    FrictionNet,
    /// The naive force predicted by the small network of thesis 2.4 from
    /// the contact's triangle and point in a local frame.
    NaiveNet,
}

impl SceneKind {
    /// Every scene, as the command line offers them.
    pub const ALL: [SceneKind; 2] = [SceneKind::Sphere, SceneKind::Hang];

    /// The name on the command line and in config files.
    pub fn name(self) -> &'static str {
        match self {
            SceneKind::Sphere => "sphere",
            SceneKind::Hang => "hang",
        }
    }
}

impl ModelKind {
    /// Every collision model, as the command line offers them.
    pub const ALL: [ModelKind; 4] = [
        ModelKind::Naive,
        ModelKind::Friction,
        ModelKind::FrictionNet,
        ModelKind::NaiveNet,
    ];

    /// Whether the model evaluates a network.
    pub fn is_network(self) -> bool {
        self.default_weights().is_some()
    }

    /// The name on the command line and in config files.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Naive => "naive",
            ModelKind::Friction => "friction",
            ModelKind::FrictionNet => "friction-net",
            ModelKind::NaiveNet => "naive-net",
        }
    }

    /// For a network model, the analytic model whose force it learned.
    pub fn analytic(self) -> Option<ModelKind> {
        match self {
            ModelKind::FrictionNet => Some(ModelKind::Friction),
            ModelKind::NaiveNet => Some(ModelKind::Naive),
            ModelKind::Naive | ModelKind::Friction => None,
        }
    }

    /// The shipped weights a network model reads unless told otherwise.
    pub fn default_weights(self) -> Option<&'static str> {
        self.shipped_weights().map(|s| s.path)
    }

    /// The shipped network a network model reads unless told otherwise.
    pub fn shipped_weights(self) -> Option<Shipped> {
        match self {
            ModelKind::FrictionNet => Some(weights::FRICTION_SMALL),
            ModelKind::NaiveNet => Some(weights::NAIVE),
            ModelKind::Naive | ModelKind::Friction => None,
        }
    }
}

/// The cloth vertices held at their initial positions (`cloth.pins`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pins {
    /// The two corners of the top row (the thesis scene).
    TopCorners,
    /// The whole top row.
    TopEdge,
    /// No vertex: the cloth falls freely.
    None,
}

/// The rigid body's mesh (`rigid.shape`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// An icosphere of `rigid.radius`, `rigid.subdivisions` times subdivided.
    Sphere,
    /// A box of `rigid.half_extents`, `rigid.subdivisions` segments per edge.
    Box,
    /// A square of `rigid.plane_size` in the body's x–z plane, normal +y.
    Plane,
    /// The OBJ file `rigid.mesh`, scaled by `rigid.scale`.
    Obj,
}

/// How the rigid body moves (`rigid.motion.kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MotionKind {
    /// It stays at `rigid.position`.
    Static,
    /// Constant velocity `rigid.motion.velocity`.
    Linear,
    /// Back and forth along `rigid.motion.axis` (the thesis scene).
    Sinusoid,
}

/// A rotation by `degrees` about `axis` (`cloth.rotation`, `rigid.rotation`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Rotation {
    /// Rotation axis: any non-zero vector, normalised when used.
    pub axis: [f32; 3],
    /// Angle about `axis`, in degrees.
    pub degrees: f32,
}

impl Default for Rotation {
    fn default() -> Self {
        Rotation {
            axis: [0.0, 1.0, 0.0],
            degrees: 0.0,
        }
    }
}

/// The cloth (`[cloth]`): its grid, material and placement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClothConfig {
    /// Particles along the cloth's width and height.
    pub grid: [u32; 2],
    /// Width and height in m.
    pub size: [f32; 2],
    /// Total mass in kg.
    pub mass: f32,
    /// Spring stiffness E in N/m (thesis eq. 4).
    pub stiffness: f32,
    /// Rayleigh damping D = −α M + β K: α in 1/s.
    pub damping_mass: f32,
    /// β in s.
    pub damping_stiffness: f32,
    /// `cloth.pins`: which vertices keep their initial positions.
    pub pins: Pins,
    /// World position of the cloth's centre.
    pub center: [f32; 3],
    /// Orientation of the cloth, which lies in its local x–y plane.
    pub rotation: Rotation,
}

impl Default for ClothConfig {
    fn default() -> Self {
        ClothConfig {
            grid: [32, 32],
            size: [1.0, 1.0],
            mass: 0.2,
            stiffness: 5000.0,
            damping_mass: 0.01,
            damping_stiffness: 5e-4,
            pins: Pins::TopCorners,
            center: [0.0, 0.0, 0.0],
            rotation: Rotation::default(),
        }
    }
}

/// The rigid body's prescribed translation (`[rigid.motion]`); each field
/// applies only to the motion its comment names.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MotionConfig {
    /// `rigid.motion.kind`: static, linear or sinusoid.
    pub kind: MotionKind,
    /// Sinusoid: direction of travel.
    pub axis: [f32; 3],
    /// Sinusoid: m.
    pub amplitude: f32,
    /// Sinusoid: s.
    pub period: f32,
    /// Sinusoid: phase in degrees.
    pub phase_deg: f32,
    /// Linear: m/s.
    pub velocity: [f32; 3],
}

impl Default for MotionConfig {
    fn default() -> Self {
        // With the default position: starts behind the cloth (z = −0.35),
        // pushes it forward to z = +0.15 and returns within one 2 s period;
        // peak speed 0.79 m/s.
        MotionConfig {
            kind: MotionKind::Sinusoid,
            axis: [0.0, 0.0, 1.0],
            amplitude: 0.25,
            period: 2.0,
            phase_deg: -90.0,
            velocity: [0.0, 0.0, 0.0],
        }
    }
}

/// The rigid body of the `sphere` scene (`[rigid]`); the `hang` scene
/// ignores it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RigidConfig {
    /// `rigid.shape`: sphere, box, plane or obj.
    pub shape: Shape,
    /// Sphere: m.
    pub radius: f32,
    /// Sphere: icosahedron subdivisions; box and plane: segments per edge.
    pub subdivisions: u32,
    /// Box: m.
    pub half_extents: [f32; 3],
    /// Plane: width and depth in m (normal +y in body space).
    pub plane_size: [f32; 2],
    /// Obj: the mesh file.
    pub mesh: Option<PathBuf>,
    /// Obj: uniform scale applied to the file's coordinates.
    pub scale: f32,
    /// World position of the body origin at t = 0 (before the motion).
    pub position: [f32; 3],
    /// `rigid.rotation`: the body's fixed orientation (the motion only
    /// translates it).
    pub rotation: Rotation,
    /// `rigid.motion`: how the body's origin moves over time.
    pub motion: MotionConfig,
}

impl Default for RigidConfig {
    fn default() -> Self {
        RigidConfig {
            shape: Shape::Sphere,
            radius: 0.2,
            subdivisions: 3,
            half_extents: [0.2, 0.2, 0.2],
            plane_size: [2.0, 2.0],
            mesh: None,
            scale: 1.0,
            position: [0.0, -0.15, -0.1],
            rotation: Rotation::default(),
            motion: MotionConfig::default(),
        }
    }
}

/// Contact detection and the collision models' coefficients (`[contact]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactConfig {
    /// ε: contact starts this far outside a surface (thesis 2.3 "force field"), m.
    pub thickness: f32,
    /// Points deeper than this below a surface are not its contacts, m.
    /// The default keeps |c| = |d̃| ≤ 0.05, the network's declared domain;
    /// deeper matches are mostly false (a rigid vertex against cloth
    /// draped further round the body).
    pub max_depth: f32,
    /// c of the naive model (thesis eq. 6), N/m.
    pub naive_stiffness: f32,
    /// s of the friction model (thesis eqs. 8–9).
    pub force_scale: f32,
    /// Contact stiffness k_n.
    pub kn: f32,
    /// Contact damping k_d.
    pub kd: f32,
    /// Friction stiffness k_t.
    pub kt: f32,
    /// Coulomb coefficient μ.
    pub mu: f32,
    /// The network of a network model (a `wgcloth-mlp/1` file); by default
    /// the model's shipped one under `weights/`.
    pub weights: Option<PathBuf>,
}

/// Friction-model coefficients, in the network's input order: the
/// `[contact]` ones as the friction models (`cpu::contact`) take them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coefficients {
    /// Contact stiffness k_n (eq. 8).
    pub kn: f32,
    /// Contact damping k_d on the approach speed ḋ (eq. 8).
    pub kd: f32,
    /// Friction stiffness k_t on the tangential velocity ṫ (eq. 9).
    pub kt: f32,
    /// Coulomb coefficient μ (eq. 9).
    pub mu: f32,
}

impl ContactConfig {
    /// k_n, k_d, k_t and μ, as the friction models take them.
    pub fn coefficients(&self) -> Coefficients {
        Coefficients {
            kn: self.kn,
            kd: self.kd,
            kt: self.kt,
            mu: self.mu,
        }
    }
}

impl Default for ContactConfig {
    fn default() -> Self {
        ContactConfig {
            thickness: 0.025,
            max_depth: 0.025,
            naive_stiffness: 1000.0,
            force_scale: 1.0,
            kn: 1000.0,
            kd: 1.0,
            kt: 100.0,
            mu: 0.5,
            weights: None,
        }
    }
}

/// The cloth against itself (`[self_contact]`, issue 23): each step is held
/// back where the cloth would otherwise pass through itself
/// (cpu/separate.rs), so no two triangles cross.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SelfContactConfig {
    /// Whether the step keeps the cloth from passing through itself.
    pub enabled: bool,
    /// The share of its gap a held vertex may close in a step (< 1/2); a
    /// pair's two sides may close twice that between them.
    pub gamma: f32,
    /// The gap no pair closes below, m (far above the spacing of f32
    /// positions, whose rounding would otherwise cross a vanishing gap).
    pub floor: f32,
    /// The gap below which the cloth pushes against itself with the
    /// `[contact]` coefficients' eqs. 8–9 force and friction, in the
    /// implicit solve (cpu/self_contact.rs), m; above `floor`. 0 leaves
    /// only the guarantee.
    pub thickness: f32,
    /// The most a vertex's cloth–cloth contacts add to its diagonal block
    /// of A, in multiples of its mass: each contact's h² k_n, h k_d and
    /// h k_t are held to this times m over the most contacts at any of its
    /// vertices. Higher holds a layer resting on another harder (below the
    /// friction angle it creeps, about as μ g h / mass_ratio: 0.2 mm/s at
    /// 1000 in `tests/coulomb.rs`, 2 mm/s at 100) and takes PCG more
    /// iterations (the drape at 64²: 95.8 a step at 1000, 54.6 at 100).
    pub mass_ratio: f32,
}

impl Default for SelfContactConfig {
    fn default() -> Self {
        SelfContactConfig {
            enabled: false,
            gamma: 0.45,
            floor: 1e-3,
            thickness: 5e-3,
            mass_ratio: 1000.0,
        }
    }
}

/// The most the rigid body and the cloth may close in one substep, in
/// multiples of the cloth's shortest spring rest length: the one linear
/// solve of a step flings vertices the body sweeps past faster than this,
/// and stretches a cloth that falls onto the body as fast (BENCHMARKS.md,
/// "Substeps that keep the body within half a spacing").
pub const MAX_BODY_TRAVEL: f32 = 0.5;

/// `solver.whole_solve_nodes` by default: cloths up to 64 × 64 vertices,
/// whose solve one workgroup runs faster than a chain of dispatches an
/// iteration on lavapipe (BENCHMARKS.md "The short step").
pub const WHOLE_SOLVE_NODES: u32 = 64 * 64;

/// The most substeps one step may take (`solver.substeps`).
pub const MAX_SUBSTEPS: u32 = 64;

/// Time stepping and the linear solve (`[solver]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverConfig {
    /// Time step h in s.
    pub dt: f32,
    /// Backward Euler steps of h / n that make one step of h: 0 (the
    /// default) takes the fewest that keep how far the rigid body and the
    /// cloth close in one (the body's top speed, and an unpinned cloth's
    /// fall onto it) within [`MAX_BODY_TRAVEL`] of the cloth's spacing
    /// (`Scene::substeps`); at most [`MAX_SUBSTEPS`].
    pub substeps: u32,
    /// `solver.steps`: number of time steps a run takes.
    pub steps: u64,
    /// Maximum PCG iterations (thesis: 25).
    pub cg_iters: u32,
    /// Relative residual |S r| / |S b| at which PCG stops (thesis: 1e-6);
    /// 0 runs every iteration.
    pub cg_tol: f32,
    /// The PCG preconditioner (thesis: Jacobi).
    pub preconditioner: Preconditioner,
    /// The multigrid preconditioner's smoother.
    pub smoother: Smoother,
    /// On the GPU, a multigrid solve of a cloth of at most this many
    /// vertices runs whole in one workgroup, one dispatch a solve, rather
    /// than a chain of dispatches per iteration (the same algorithm, its
    /// sums in another order; without self-contact forces, whose couplings
    /// take it past WebGPU's bindings); 0 never. The CPU is unaffected.
    pub whole_solve_nodes: u32,
    /// m/s².
    pub gravity: [f32; 3],
    /// m/s: a vertex faster than this stops the run as diverging (the
    /// sphere moves at about 1 m/s).
    pub max_speed: f32,
}

impl Default for SolverConfig {
    fn default() -> Self {
        SolverConfig {
            dt: 0.01,
            substeps: 0,
            steps: 200,
            cg_iters: 200,
            cg_tol: 1e-3,
            preconditioner: Preconditioner::Multigrid,
            smoother: Smoother::Patches,
            whole_solve_nodes: WHOLE_SOLVE_NODES,
            gravity: [0.0, -9.81, 0.0],
            max_speed: 100.0,
        }
    }
}

/// Where a TOML configuration went wrong: its line, the dotted key, what.
#[cfg(feature = "toml")]
struct TomlError {
    line: Option<usize>,
    key: Option<String>,
    message: String,
}

#[cfg(feature = "toml")]
impl TomlError {
    /// What `e` says, with its line in `text` where it was parsed from one.
    fn of(mut e: toml::de::Error, text: Option<&str>) -> TomlError {
        let line = (e.span().zip(text)).map(|(s, t)| t[..s.start].matches('\n').count() + 1);
        // Without the input, the error's display names the dotted key.
        e.set_input(None);
        let shown = e.to_string();
        let key = (shown.lines())
            .find_map(|l| l.strip_prefix("in `")?.strip_suffix('`'))
            .map(str::to_string);
        TomlError {
            line,
            key,
            message: e.message().trim().to_string(),
        }
    }
}

/// A run's whole configuration; the defaults are the thesis scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// `scene`: which scene to build.
    pub scene: SceneKind,
    /// `model`: the collision model.
    pub model: ModelKind,
    /// `[cloth]`: the cloth.
    pub cloth: ClothConfig,
    /// `[rigid]`: the rigid body (the `sphere` scene only).
    pub rigid: RigidConfig,
    /// `[contact]`: contact detection and force coefficients.
    pub contact: ContactConfig,
    /// `[solver]`: time step, step count and PCG.
    pub solver: SolverConfig,
    /// `[self_contact]`: the cloth against itself.
    pub self_contact: SelfContactConfig,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            scene: SceneKind::Sphere,
            model: ModelKind::FrictionNet,
            cloth: ClothConfig::default(),
            rigid: RigidConfig::default(),
            contact: ContactConfig::default(),
            solver: SolverConfig::default(),
            self_contact: SelfContactConfig::default(),
        }
    }
}

impl Config {
    /// The weights file a network model reads: `contact.weights`, else the
    /// model's shipped file (built in). None for the analytic models.
    pub fn weights_path(&self) -> Option<PathBuf> {
        let shipped = self.model.default_weights()?;
        Some(
            self.contact
                .weights
                .clone()
                .unwrap_or_else(|| shipped.into()),
        )
    }

    /// The network model's weights: `contact.weights` read from disk, else
    /// the built-in copy of the shipped file. None for the analytic models;
    /// an error for a network of the other model.
    pub fn read_weights(&self) -> Result<Option<WeightsFile>> {
        let Some(shipped) = self.model.shipped_weights() else {
            return Ok(None);
        };
        let (file, path) = match &self.contact.weights {
            Some(path) => (WeightsFile::read(path)?, path.as_path()),
            None => (shipped.read()?, Path::new(shipped.path)),
        };
        let wanted = match self.model {
            ModelKind::NaiveNet => NetKind::Naive,
            _ => NetKind::Friction,
        };
        if file.kind.data() != wanted {
            return Err(Error::file(
                path,
                format!(
                    "is a {} network; model {} needs a {} one",
                    file.kind.name(),
                    self.model.name(),
                    wanted.name()
                ),
            ));
        }
        Ok(Some(file))
    }

    /// Parses a TOML document; unknown or mistyped fields are errors naming
    /// the file and line. Needs the crate's `toml` feature.
    #[cfg(feature = "toml")]
    pub fn from_toml(text: &str, path: &Path) -> Result<Config> {
        Self::parse_toml(text).map_err(|e| {
            let line = e.line.map(|l| format!("line {l}: ")).unwrap_or_default();
            let key = e.key.map(|k| format!("`{k}`: ")).unwrap_or_default();
            Error::file(path, format!("{line}{key}{}", e.message))
        })
    }

    /// This configuration with `overrides` set over it: a TOML table laid
    /// out as a configuration file is (`contact.mu = 0.3`), whose tables
    /// merge into this one's. A key that names no field, or a value of the
    /// wrong type, is an error naming the key. Needs the crate's `toml`
    /// feature.
    #[cfg(feature = "toml")]
    pub fn with_overrides(&self, overrides: &toml::Table) -> Result<Config> {
        fn merge(into: &mut toml::Table, from: &toml::Table) {
            for (key, value) in from {
                match (into.get_mut(key), value) {
                    (Some(toml::Value::Table(t)), toml::Value::Table(f)) => merge(t, f),
                    _ => {
                        into.insert(key.clone(), value.clone());
                    }
                }
            }
        }
        let unwritable = |e: &dyn std::fmt::Display| Error::config("configuration", e.to_string());
        let mut table = toml::Table::try_from(self).map_err(|e| unwritable(&e))?;
        merge(&mut table, overrides);
        Config::deserialize(toml::Value::Table(table)).map_err(|e| {
            let e = TomlError::of(e, None);
            Error::config(e.key.as_deref().unwrap_or("configuration"), e.message)
        })
    }

    #[cfg(feature = "toml")]
    fn parse_toml(text: &str) -> std::result::Result<Config, TomlError> {
        toml::from_str(text).map_err(|e| TomlError::of(e, Some(text)))
    }

    /// [`Config::from_toml`] on a file. Needs the crate's `toml` feature.
    #[cfg(feature = "toml")]
    pub fn load(path: &Path) -> Result<Config> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Config::from_toml(&text, path)
    }

    /// Checks every field; the first bad one is reported by its dotted name.
    pub fn validate(&self) -> Result<()> {
        let c = &self.cloth;
        if c.grid.iter().any(|&n| n < 2) {
            return Err(Error::config(
                "cloth.grid",
                format!("needs at least 2 particles per side, got {:?}", c.grid),
            ));
        }
        if (c.grid[0] as u64) * (c.grid[1] as u64) > (1 << 26) {
            return Err(Error::config(
                "cloth.grid",
                format!("{:?} is more than 2^26 particles", c.grid),
            ));
        }
        positive("cloth.size", &c.size)?;
        positive("cloth.mass", &[c.mass])?;
        positive("cloth.stiffness", &[c.stiffness])?;
        non_negative("cloth.damping_mass", &[c.damping_mass])?;
        non_negative("cloth.damping_stiffness", &[c.damping_stiffness])?;
        finite("cloth.center", &c.center)?;
        rotation("cloth.rotation", &c.rotation)?;

        if self.scene == SceneKind::Sphere {
            let r = &self.rigid;
            match r.shape {
                Shape::Sphere => {
                    positive("rigid.radius", &[r.radius])?;
                    if r.subdivisions > 7 {
                        return Err(Error::config(
                            "rigid.subdivisions",
                            format!("at most 7 for a sphere, got {}", r.subdivisions),
                        ));
                    }
                }
                Shape::Box => positive("rigid.half_extents", &r.half_extents)?,
                Shape::Plane => positive("rigid.plane_size", &r.plane_size)?,
                Shape::Obj => {
                    if r.mesh.is_none() {
                        return Err(Error::config("rigid.mesh", "shape `obj` needs a mesh file"));
                    }
                    positive("rigid.scale", &[r.scale])?;
                }
            }
            if matches!(r.shape, Shape::Box | Shape::Plane) && !(1..=1024).contains(&r.subdivisions)
            {
                return Err(Error::config(
                    "rigid.subdivisions",
                    format!(
                        "segments per edge must be in 1..=1024, got {}",
                        r.subdivisions
                    ),
                ));
            }
            finite("rigid.position", &r.position)?;
            rotation("rigid.rotation", &r.rotation)?;
            let m = &r.motion;
            match m.kind {
                MotionKind::Static => {}
                MotionKind::Linear => finite("rigid.motion.velocity", &m.velocity)?,
                MotionKind::Sinusoid => {
                    direction("rigid.motion.axis", &m.axis)?;
                    finite("rigid.motion.amplitude", &[m.amplitude])?;
                    positive("rigid.motion.period", &[m.period])?;
                    finite("rigid.motion.phase_deg", &[m.phase_deg])?;
                }
            }
        }

        let k = &self.contact;
        positive("contact.thickness", &[k.thickness])?;
        positive("contact.max_depth", &[k.max_depth])?;
        match self.model {
            ModelKind::Naive | ModelKind::NaiveNet => {
                positive("contact.naive_stiffness", &[k.naive_stiffness])?
            }
            ModelKind::Friction | ModelKind::FrictionNet => {
                positive("contact.force_scale", &[k.force_scale])?;
                positive("contact.kn", &[k.kn])?;
                non_negative("contact.kd", &[k.kd])?;
                positive("contact.kt", &[k.kt])?;
                non_negative("contact.mu", &[k.mu])?;
            }
        }

        let s = &self.solver;
        positive("solver.dt", &[s.dt])?;
        if s.substeps > MAX_SUBSTEPS {
            return Err(Error::config(
                "solver.substeps",
                format!(
                    "must be at most {MAX_SUBSTEPS} (0 picks them), got {}",
                    s.substeps
                ),
            ));
        }
        if s.cg_iters == 0 {
            return Err(Error::config("solver.cg_iters", "must be at least 1"));
        }
        non_negative("solver.cg_tol", &[s.cg_tol])?;
        finite("solver.gravity", &s.gravity)?;
        positive("solver.max_speed", &[s.max_speed])?;
        let sc = &self.self_contact;
        positive("self_contact.floor", &[sc.floor])?;
        non_negative("self_contact.thickness", &[sc.thickness])?;
        positive("self_contact.mass_ratio", &[sc.mass_ratio])?;
        if sc.thickness > 0.0 && sc.thickness <= sc.floor {
            return Err(Error::config(
                "self_contact.thickness",
                format!(
                    "must exceed self_contact.floor ({} m) or be 0 (no forces), got {}",
                    sc.floor, sc.thickness
                ),
            ));
        }
        if !(sc.gamma > 0.0 && sc.gamma < 0.5) {
            return Err(Error::config(
                "self_contact.gamma",
                format!("must lie in (0, 0.5), got {}", sc.gamma),
            ));
        }
        if let (Some(path), false) = (&self.contact.weights, self.model.is_network()) {
            return Err(Error::config(
                "contact.weights",
                format!(
                    "model `{}` uses no network, so {} would be ignored; use friction-net or naive-net",
                    self.model.name(),
                    path.display()
                ),
            ));
        }
        Ok(())
    }
}

fn finite(field: &str, values: &[f32]) -> Result<()> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(v) => Err(Error::config(field, format!("must be finite, got {v}"))),
        None => Ok(()),
    }
}

fn positive(field: &str, values: &[f32]) -> Result<()> {
    finite(field, values)?;
    match values.iter().find(|&&v| v <= 0.0) {
        Some(v) => Err(Error::config(field, format!("must be > 0, got {v}"))),
        None => Ok(()),
    }
}

fn non_negative(field: &str, values: &[f32]) -> Result<()> {
    finite(field, values)?;
    match values.iter().find(|&&v| v < 0.0) {
        Some(v) => Err(Error::config(field, format!("must be ≥ 0, got {v}"))),
        None => Ok(()),
    }
}

fn direction(field: &str, v: &[f32; 3]) -> Result<()> {
    finite(field, v)?;
    if glam::Vec3::from_array(*v).length() < 1e-6 {
        return Err(Error::config(field, "must be a non-zero vector"));
    }
    Ok(())
}

fn rotation(field: &str, r: &Rotation) -> Result<()> {
    direction(&format!("{field}.axis"), &r.axis)?;
    finite(&format!("{field}.degrees"), &[r.degrees])
}

// The tests read TOML, which the library parses only with its `toml` feature.
#[cfg(all(test, feature = "toml"))]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_round_trip_through_toml() {
        let c = Config::default();
        c.validate().unwrap();
        let text = toml::to_string(&c).unwrap();
        assert_eq!(Config::from_toml(&text, Path::new("x.toml")).unwrap(), c);
    }

    #[test]
    fn partial_toml_keeps_defaults() {
        let c = Config::from_toml("[cloth]\nmass = 0.5\n", Path::new("x.toml")).unwrap();
        assert_eq!(c.cloth.mass, 0.5);
        assert_eq!(c.cloth.grid, ClothConfig::default().grid);
    }

    #[test]
    fn errors_name_the_field() {
        let e = Config::from_toml("[cloth]\nmas = 0.5\n", Path::new("x.toml")).unwrap_err();
        assert!(
            e.to_string().contains("mas") && e.to_string().contains("line 2"),
            "{e}"
        );
        let mut c = Config::default();
        c.solver.dt = f32::NAN;
        assert!(c.validate().unwrap_err().to_string().contains("solver.dt"));
        let mut c = Config::default();
        c.solver.substeps = MAX_SUBSTEPS + 1;
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("solver.substeps")
        );
        let mut c = Config::default();
        c.rigid.motion.period = 0.0;
        assert!(
            c.validate()
                .unwrap_err()
                .to_string()
                .contains("rigid.motion.period")
        );
    }
}
