//! Contact data for training the friction network (thesis 2.4, 2.6):
//! recorded contacts (c = n d̃ and v_rel from simulation runs over many
//! sphere starts, paths and speeds) mixed with uniform samples of the
//! declared input domain, each with freshly drawn coefficients (the
//! thesis's second approach), targets from the analytic force g.
//!
//! File format (`wgcloth-contacts/1`): a safetensors file with f32 tensors
//! `inputs` [N, 10] (cx cy cz vx vy vz kn kd kt mu) and `targets` [N, 3]
//! (gx gy gz), metadata `format`, `seed`, `recorded`, `uniform`.

use std::collections::HashMap;
use std::path::Path;

use glam::Vec3;
use safetensors::{Dtype, SafeTensors, tensor::TensorView};

use crate::config::{Config, ModelKind, MotionKind};
use crate::cpu::CpuSim;
use crate::cpu::contact::{Coefficients, friction};
use crate::error::{Error, Result};
use crate::scene::Scene;

pub const FORMAT: &str = "wgcloth-contacts/1";

/// The declared input domain (DESIGN "The networks").
pub const MAX_DEPTH: f32 = 0.05;
pub const MAX_SPEED: f32 = 2.0;
pub const KN: (f32, f32) = (10.0, 1000.0);
pub const KD: (f32, f32) = (0.0, 10.0);
pub const KT: (f32, f32) = (1.0, 1000.0);
pub const MU: (f32, f32) = (0.0, 1.0);

/// Input bounds of the domain, in input order: the min-max scaler.
pub fn domain_bounds() -> ([f32; 10], [f32; 10]) {
    let (c, v) = (MAX_DEPTH, MAX_SPEED);
    (
        [-c, -c, -c, -v, -v, -v, KN.0, KD.0, KT.0, MU.0],
        [c, c, c, v, v, v, KN.1, KD.1, KT.1, MU.1],
    )
}

/// A small seeded generator (splitmix64), so data is reproducible.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    pub fn range(&mut self, (lo, hi): (f32, f32)) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// Uniform in the ball of radius r.
    pub fn in_ball(&mut self, r: f32) -> Vec3 {
        loop {
            let p = Vec3::new(self.unit(), self.unit(), self.unit()) * 2.0 - 1.0;
            if p.length_squared() <= 1.0 {
                return p * r;
            }
        }
    }
}

#[derive(Clone, Debug, Default, PartialEq)]
pub struct Dataset {
    pub inputs: Vec<[f32; 10]>,
    pub targets: Vec<[f32; 3]>,
}

/// One sample: the inputs and the analytic target g.
pub fn sample(c: Vec3, v: Vec3, k: &Coefficients) -> ([f32; 10], [f32; 3]) {
    let g = friction(c, v, k).force;
    (
        [c.x, c.y, c.z, v.x, v.y, v.z, k.kn, k.kd, k.kt, k.mu],
        g.to_array(),
    )
}

pub fn random_coefficients(rng: &mut Rng) -> Coefficients {
    Coefficients {
        kn: rng.range(KN),
        kd: rng.range(KD),
        kt: rng.range(KT),
        mu: rng.range(MU),
    }
}

/// A uniform sample of the declared domain: c in the ball of radius 0.05
/// (turned so d̃ ≤ 0 is automatic: c = n d̃ takes any direction), v_rel in
/// the ball of radius 2, coefficients uniform.
pub fn uniform_sample(rng: &mut Rng) -> ([f32; 10], [f32; 3]) {
    let c = rng.in_ball(MAX_DEPTH);
    let v = rng.in_ball(MAX_SPEED);
    sample(c, v, &random_coefficients(rng))
}

/// Contacts (c, v_rel) recorded from `runs` thesis-scene runs whose sphere
/// start, path direction, amplitude and period are drawn at random.
pub fn record_contacts(
    runs: u32,
    grid: u32,
    rng: &mut Rng,
    mut progress: impl FnMut(u32),
) -> Result<Vec<(Vec3, Vec3)>> {
    let mut out = Vec::new();
    for run in 0..runs {
        let mut config = Config {
            model: ModelKind::Friction,
            ..Default::default()
        };
        config.cloth.grid = [grid, grid];
        let r = &mut config.rigid;
        r.radius = rng.range((0.12, 0.28));
        r.position = [rng.range((-0.2, 0.2)), rng.range((-0.3, 0.1)), -0.1];
        let m = &mut r.motion;
        m.kind = MotionKind::Sinusoid;
        m.axis = [rng.range((-0.3, 0.3)), rng.range((-0.3, 0.3)), 1.0];
        m.amplitude = rng.range((0.2, 0.35));
        m.period = rng.range((1.2, 3.0));
        let k = &mut config.contact;
        (k.kn, k.kd, k.kt, k.mu) = (
            rng.range((300.0, 1000.0)),
            rng.range((0.5, 4.0)),
            rng.range((20.0, 400.0)),
            rng.range((0.1, 0.9)),
        );
        let steps = (m.period / config.solver.dt).round() as u64;
        let mut sim = CpuSim::new(Scene::new(&config)?);
        for _ in 0..steps {
            sim.step();
            for c in sim.contacts() {
                let (cv, v) = (c.collision_vector(), c.relative_velocity(&sim.state.v));
                if cv.length() <= MAX_DEPTH && v.length() <= MAX_SPEED {
                    out.push((cv, v));
                }
            }
        }
        progress(run + 1);
    }
    Ok(out)
}

impl Dataset {
    pub fn len(&self) -> usize {
        self.inputs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.inputs.is_empty()
    }

    pub fn push(&mut self, (x, y): ([f32; 10], [f32; 3])) {
        self.inputs.push(x);
        self.targets.push(y);
    }

    pub fn to_bytes(&self, meta: HashMap<String, String>) -> Vec<u8> {
        let x: Vec<u8> = self
            .inputs
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let y: Vec<u8> = self
            .targets
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let mut meta = meta;
        meta.insert("format".into(), FORMAT.into());
        let views = [
            (
                "inputs",
                TensorView::new(Dtype::F32, vec![self.len(), 10], &x).expect("consistent"),
            ),
            (
                "targets",
                TensorView::new(Dtype::F32, vec![self.len(), 3], &y).expect("consistent"),
            ),
        ];
        safetensors::serialize(views, Some(meta)).expect("serialisable")
    }

    pub fn write(&self, path: &Path, meta: HashMap<String, String>, force: bool) -> Result<()> {
        if path.exists() && !force {
            return Err(Error::file(
                path,
                "already exists; pass --force to replace it",
            ));
        }
        std::fs::write(path, self.to_bytes(meta)).map_err(|e| Error::io(path, e))
    }

    /// Reads a data file, refusing anything but a non-empty, well-formed one.
    pub fn read(path: &Path) -> Result<Dataset> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let (_, header) = SafeTensors::read_metadata(&bytes)
            .map_err(|e| Error::file(path, format!("not a contact data file: {e}")))?;
        if header
            .metadata()
            .as_ref()
            .and_then(|m| m.get("format"))
            .map(String::as_str)
            != Some(FORMAT)
        {
            return Err(Error::file(path, format!("not a {FORMAT} file")));
        }
        let st = SafeTensors::deserialize(&bytes)
            .map_err(|e| Error::file(path, format!("not a contact data file: {e}")))?;
        let floats = |name: &str, width: usize| -> Result<Vec<f32>> {
            let v = st
                .tensor(name)
                .map_err(|_| Error::file(path, format!("tensor `{name}` is missing")))?;
            if v.dtype() != Dtype::F32 || v.shape().len() != 2 || v.shape()[1] != width {
                return Err(Error::file(
                    path,
                    format!(
                        "tensor `{name}` must be F32 [N, {width}], is {:?} {:?}",
                        v.dtype(),
                        v.shape()
                    ),
                ));
            }
            let out: Vec<f32> = v
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            match out.iter().position(|x| !x.is_finite()) {
                Some(k) => Err(Error::file(
                    path,
                    format!("tensor `{name}` has a non-finite value at index {k}"),
                )),
                None => Ok(out),
            }
        };
        let x = floats("inputs", 10)?;
        let y = floats("targets", 3)?;
        if x.len() / 10 != y.len() / 3 {
            return Err(Error::file(
                path,
                format!("{} inputs but {} targets", x.len() / 10, y.len() / 3),
            ));
        }
        if x.is_empty() {
            return Err(Error::file(path, "holds no samples"));
        }
        Ok(Dataset {
            inputs: x
                .chunks_exact(10)
                .map(|c| c.try_into().expect("10 wide"))
                .collect(),
            targets: y
                .chunks_exact(3)
                .map(|c| c.try_into().expect("3 wide"))
                .collect(),
        })
    }
}

/// gen-data: `recorded` contacts from simulation (each with fresh random
/// coefficients) plus `uniform` domain samples, shuffled; deterministic
/// for a seed.
pub fn generate(
    recorded: usize,
    uniform: usize,
    seed: u64,
    mut progress: impl FnMut(&str, f32),
) -> Result<Dataset> {
    let mut rng = Rng::new(seed);
    let mut data = Dataset::default();
    let mut contacts = Vec::new();
    let mut run = 0;
    while contacts.len() < recorded {
        contacts.extend(record_contacts(1, 16, &mut rng, |_| {})?);
        run += 1;
        progress(
            "simulating",
            (contacts.len() as f32 / recorded as f32).min(1.0),
        );
        if run > 1000 {
            return Err(Error::config(
                "--recorded",
                "the runs produced too few contacts",
            ));
        }
    }
    // Draw `recorded` of them without replacement (partial Fisher–Yates).
    for k in 0..recorded {
        let j = k + (rng.next_u64() % (contacts.len() - k) as u64) as usize;
        contacts.swap(k, j);
        let (c, v) = contacts[k];
        data.push(sample(c, v, &random_coefficients(&mut rng)));
    }
    for _ in 0..uniform {
        data.push(uniform_sample(&mut rng));
    }
    progress("sampling", 1.0);
    for k in (1..data.len()).rev() {
        let j = (rng.next_u64() % (k as u64 + 1)) as usize;
        data.inputs.swap(k, j);
        data.targets.swap(k, j);
    }
    Ok(data)
}
