//! Contact data for training the networks (thesis 2.4, 2.6): contacts
//! recorded from simulation runs over many sphere starts, paths and speeds,
//! mixed with uniform samples of the declared input domain, targets from
//! the analytic force. Friction samples draw fresh coefficients each (the
//! thesis's second approach); naive samples are local-frame geometry.
//!
//! File format (`wgcloth-contacts/1`): a safetensors file with f32 tensors
//! `inputs` [N, 10] (cx cy cz vx vy vz kn kd kt mu) or [N, 7] (bx cx cy cz
//! px py pz) and `targets` [N, 3], metadata `format`, `model` (`friction`,
//! the default, or `naive`), `seed`, `recorded`, `uniform`, `resting`.

use std::collections::HashMap;
use std::path::Path;

use safetensors::{Dtype, SafeTensors, tensor::TensorView};

use crate::domain::{
    MAX_DEPTH, MAX_SPEED, Rng, Sample, bounds, friction_sample, naive_sample, random_coefficients,
    resting_sample, uniform_sample,
};
use wgcloth::config::{Config, ModelKind, MotionKind};
use wgcloth::cpu::CpuSim;
use wgcloth::cpu::contact::local_frame;
use wgcloth::cpu::worlds::CpuWorlds;
use wgcloth::error::{Error, Result};
use wgcloth::nn::weights::{self, NetKind};
use wgcloth::scene::Scene;

pub const FORMAT: &str = "wgcloth-contacts/1";

/// Randomised runs `gen-data` steps together as one batch of worlds.
const RUNS_A_BATCH: usize = 8;

#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    pub kind: NetKind,
    /// Row-major [len × kind's input count].
    pub inputs: Vec<f32>,
    pub targets: Vec<[f32; 3]>,
}

/// What a recorded contact contributes before coefficients are drawn:
/// friction (c, v_rel), or the naive network's local-frame inputs.
fn recorded_inputs(kind: NetKind, sim: &CpuSim) -> Vec<Vec<f32>> {
    let (Some(body), Some(frame)) = (&sim.scene.rigid, sim.rigid_frame()) else {
        return Vec::new();
    };
    let (x, v) = (&sim.state.x, &sim.state.v);
    let (lo, hi) = bounds(kind);
    let in_domain = |s: &[f32]| {
        s.iter()
            .zip(lo.iter().zip(&hi))
            .all(|(x, (l, h))| l <= x && x <= h)
    };
    sim.contacts()
        .iter()
        .filter_map(|c| match kind {
            NetKind::Friction | NetKind::FrictionContact => {
                let (cv, vr) = (c.collision_vector(), c.relative_velocity(v));
                (cv.length() <= MAX_DEPTH && vr.length() <= MAX_SPEED)
                    .then(|| [cv.to_array(), vr.to_array()].concat())
            }
            NetKind::Naive => local_frame(&c.geometry(&sim.scene.cloth, body, frame, x))
                .map(|f| f.inputs.to_vec())
                .filter(|s| in_domain(s)),
        })
        .collect()
}

/// A thesis-scene run whose sphere start, path direction, amplitude,
/// period and coefficients are drawn from `rng` (with the naive model for
/// naive data, as the thesis recorded) on an N×N cloth: its configuration
/// and its steps, one sphere period.
pub fn random_run(kind: NetKind, grid: u32, rng: &mut Rng) -> (Config, u64) {
    let mut config = Config {
        model: match kind {
            NetKind::Friction | NetKind::FrictionContact => ModelKind::Friction,
            NetKind::Naive => ModelKind::Naive,
        },
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
    (config, steps)
}

/// The contacts of each of `runs` (configurations and steps), recorded
/// after every step, the runs stepped as one batch of worlds
/// (`cpu::worlds`).
pub fn record_contacts(kind: NetKind, runs: &[(Config, u64)]) -> Result<Vec<Vec<Vec<f32>>>> {
    let scenes = (runs.iter())
        .map(|(config, _)| Scene::new(config))
        .collect::<Result<Vec<_>>>()?;
    let mut batch = CpuWorlds::new(scenes);
    let mut out = vec![Vec::new(); runs.len()];
    let longest = runs.iter().map(|(_, steps)| *steps).max().unwrap_or(0);
    for step in 0..longest {
        let stepped = batch.step_where(|k| step < runs[k].1);
        for ((records, sim), s) in out.iter_mut().zip(batch.worlds()).zip(&stepped) {
            if s.is_some() {
                records.extend(recorded_inputs(kind, sim));
            }
        }
    }
    Ok(out)
}

impl Dataset {
    pub fn new(kind: NetKind) -> Dataset {
        Dataset {
            kind,
            inputs: Vec::new(),
            targets: Vec::new(),
        }
    }

    /// Inputs per sample.
    pub fn width(&self) -> usize {
        self.kind.inputs().len()
    }

    pub fn len(&self) -> usize {
        self.targets.len()
    }

    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    /// The inputs of sample i.
    pub fn input(&self, i: usize) -> &[f32] {
        &self.inputs[i * self.width()..(i + 1) * self.width()]
    }

    pub fn push(&mut self, (x, y): Sample) {
        debug_assert_eq!(x.len(), self.width());
        self.inputs.extend(x);
        self.targets.push(y);
    }

    /// Swaps samples i and j.
    fn swap(&mut self, i: usize, j: usize) {
        let w = self.width();
        for k in 0..w {
            self.inputs.swap(i * w + k, j * w + k);
        }
        self.targets.swap(i, j);
    }

    pub fn to_bytes(&self, meta: HashMap<String, String>) -> Vec<u8> {
        let x: Vec<u8> = self.inputs.iter().flat_map(|v| v.to_le_bytes()).collect();
        let y: Vec<u8> = self
            .targets
            .iter()
            .flatten()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let mut meta = meta;
        meta.insert("format".into(), FORMAT.into());
        meta.insert("model".into(), self.kind.name().into());
        let views = [
            (
                "inputs",
                TensorView::new(Dtype::F32, vec![self.len(), self.width()], &x)
                    .expect("consistent"),
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
        let meta = |key: &str| header.metadata().as_ref().and_then(|m| m.get(key)).cloned();
        if meta("format").as_deref() != Some(FORMAT) {
            return Err(Error::file(path, format!("not a {FORMAT} file")));
        }
        let kind = match meta("model").as_deref() {
            None | Some("friction") => NetKind::Friction,
            Some("naive") => NetKind::Naive,
            Some(other) => {
                return Err(Error::file(
                    path,
                    format!("model {other:?} is neither \"friction\" nor \"naive\""),
                ));
            }
        };
        let width = kind.inputs().len();
        let st = SafeTensors::deserialize(&bytes)
            .map_err(|e| Error::file(path, format!("not a contact data file: {e}")))?;
        // Any number of rows, each `width` wide.
        let floats = |name: &str, width: usize| -> Result<Vec<f32>> {
            let v = st
                .tensor(name)
                .map_err(|_| Error::file(path, format!("tensor `{name}` is missing")))?;
            let rows = v.shape().first().copied().unwrap_or(0);
            weights::floats(&v, name, &[rows, width], path)
        };
        let x = floats("inputs", width)?;
        let y = floats("targets", 3)?;
        if x.len() / width != y.len() / 3 {
            return Err(Error::file(
                path,
                format!("{} inputs but {} targets", x.len() / width, y.len() / 3),
            ));
        }
        if x.is_empty() {
            return Err(Error::file(path, "holds no samples"));
        }
        Ok(Dataset {
            kind,
            inputs: x,
            targets: y
                .chunks_exact(3)
                .map(|c| c.try_into().expect("3 wide"))
                .collect(),
        })
    }
}

/// How many samples of each source `gen-data` draws.
#[derive(Clone, Copy, Debug, Default)]
pub struct Counts {
    /// Contacts recorded from randomised sphere runs.
    pub recorded: usize,
    /// Uniform samples of the declared domain.
    pub uniform: usize,
    /// Samples of the resting regime (friction data only).
    pub resting: usize,
}

/// gen-data: recorded contacts from simulation, uniform domain samples and
/// (friction) resting-regime samples of a network's inputs, shuffled;
/// deterministic for a seed.
pub fn generate(
    kind: NetKind,
    Counts {
        recorded,
        uniform,
        resting,
    }: Counts,
    seed: u64,
    mut progress: impl FnMut(&str, f32),
) -> Result<Dataset> {
    if recorded + uniform + resting == 0 {
        return Err(Error::config(
            "--recorded",
            "with --uniform 0 and --resting 0 there would be no samples; ask for some",
        ));
    }
    if kind == NetKind::Naive && resting > 0 {
        return Err(Error::config(
            "--resting",
            "is for friction data; the naive network has no resting regime",
        ));
    }
    let mut rng = Rng::new(seed);
    let mut data = Dataset::new(kind);
    let mut contacts = Vec::new();
    let mut run = 0;
    'runs: while contacts.len() < recorded {
        // Runs drawn as one after another draws them, stepped as a batch;
        // the draws of runs left over are given back, so the data do not
        // depend on the batch's size.
        let draws: Vec<(Rng, (Config, u64))> = (0..RUNS_A_BATCH)
            .map(|_| {
                let run = random_run(kind, 16, &mut rng);
                (rng.clone(), run)
            })
            .collect();
        let runs: Vec<(Config, u64)> = draws.iter().map(|(_, r)| r.clone()).collect();
        for (records, (after, _)) in record_contacts(kind, &runs)?.into_iter().zip(draws) {
            contacts.extend(records);
            run += 1;
            progress(
                "simulating",
                (contacts.len() as f32 / recorded as f32).min(1.0),
            );
            if contacts.len() >= recorded {
                rng = after;
                break 'runs;
            }
            if run > 1000 {
                return Err(Error::config(
                    "--recorded",
                    "the runs produced too few contacts",
                ));
            }
        }
    }
    // Draw `recorded` of them without replacement (partial Fisher–Yates).
    for k in 0..recorded {
        let j = k + (rng.next_u64() % (contacts.len() - k) as u64) as usize;
        contacts.swap(k, j);
        let x = &contacts[k];
        data.push(match kind {
            NetKind::Friction | NetKind::FrictionContact => {
                let (c, v) = (
                    glam::Vec3::from_slice(&x[..3]),
                    glam::Vec3::from_slice(&x[3..]),
                );
                friction_sample(c, v, &random_coefficients(&mut rng))
            }
            NetKind::Naive => naive_sample(x[..].try_into().expect("7 local-frame inputs")),
        });
    }
    for _ in 0..uniform {
        data.push(uniform_sample(kind, &mut rng));
    }
    for _ in 0..resting {
        let k = random_coefficients(&mut rng);
        data.push(resting_sample(&mut rng, &k));
    }
    progress("sampling", 1.0);
    for k in (1..data.len()).rev() {
        let j = (rng.next_u64() % (k as u64 + 1)) as usize;
        data.swap(k, j);
    }
    Ok(data)
}
