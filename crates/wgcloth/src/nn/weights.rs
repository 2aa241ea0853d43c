//! The weights file, `weights/*.safetensors` (DESIGN "The networks"):
//! f32 tensors `layer{i}.weight` (out × in) and `layer{i}.bias` (out),
//! `input_min`, `input_max` (one per input), `output_mean`, `output_std`
//! (one per output); metadata `format` = `wgcloth-mlp/1`, `model`, `activation`,
//! `negative_slope`, `inputs`, `outputs`, plus the training recipe and
//! figures. The network maps u = (x − min)/(max − min) to standardised
//! outputs y, g = y ⊙ std + mean. Reading validates everything and names
//! what is wrong; [`WeightsFile::folded`] bakes both scalings into the
//! first and last layers.

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;
use std::path::Path;

use safetensors::{Dtype, SafeTensors, tensor::TensorView};

use crate::error::{Error, Result};
use crate::nn::mlp::{Layer, Mlp};

/// The `format` metadata of every weights file this crate reads and writes.
pub const FORMAT: &str = "wgcloth-mlp/1";

/// A network shipped in `weights/`, compiled in so that the network models
/// and the benchmarks work from any directory.
#[derive(Clone, Copy, Debug)]
pub struct Shipped {
    /// The file's path in the repository.
    pub path: &'static str,
    /// The file's content.
    pub bytes: &'static [u8],
}

impl Shipped {
    /// Parses and validates the compiled-in file.
    pub fn read(self) -> Result<WeightsFile> {
        WeightsFile::parse(self.bytes, Path::new(self.path))
    }
}

macro_rules! shipped {
    ($file:literal) => {
        Shipped {
            path: concat!("crates/wgcloth/weights/", $file),
            bytes: include_bytes!(concat!("../../weights/", $file)),
        }
    };
}

/// The thesis-size friction network (thesis 2.7).
pub const FRICTION_THESIS: Shipped = shipped!("friction_mlp.safetensors");
/// The distilled friction network, in the contact frame: 30× fewer
/// multiply-adds than the thesis network, and more accurate.
pub const FRICTION_SMALL: Shipped = shipped!("friction_mlp_small.safetensors");
/// The naive network (thesis 2.4).
pub const NAIVE: Shipped = shipped!("naive_mlp.safetensors");
/// Every shipped network.
pub const SHIPPED: [Shipped; 3] = [FRICTION_THESIS, FRICTION_SMALL, NAIVE];

/// The friction network's inputs (c = n d̃, v_rel, coefficients) and outputs (g = f / s).
pub const FRICTION_INPUTS: [&str; 10] =
    ["cx", "cy", "cz", "vx", "vy", "vz", "kn", "kd", "kt", "mu"];
/// The friction network's outputs: g = f / s, world frame.
pub const FRICTION_OUTPUTS: [&str; 3] = ["gx", "gy", "gz"];
/// The friction network in the contact frame: depth |c|, approach speed
/// v_rel·ĉ, signed sliding speed ±|ṫ|, coefficients (see
/// `cpu::contact::ContactFrame`).
pub const FRICTION_CONTACT_INPUTS: [&str; 7] =
    ["depth", "approach", "slide", "kn", "kd", "kt", "mu"];
/// The contact-frame network's outputs, the logits of its output's form
/// (`cpu::contact::cone`): y_n, with g_n = L softplus(y_n), and w, with
/// stick stiffness k_t e^w. Files from before issue 65 named them "gn, gt"
/// and are refused.
pub const FRICTION_CONTACT_OUTPUTS: [&str; 2] = ["load", "stick"];
/// The naive network's inputs (thesis 2.4): b's x, corner c and the point p
/// in the local frame with corner a at the origin, b on +x and the normal
/// on +z, so cz = 0 (`cpu::contact::LocalFrame`).
pub const NAIVE_INPUTS: [&str; 7] = ["bx", "cx", "cy", "cz", "px", "py", "pz"];
/// The naive network's outputs: f / c in the local frame.
pub const NAIVE_OUTPUTS: [&str; 3] = ["fx", "fy", "fz"];

/// Network rows per contact of the contact-frame network
/// (`NetKind::FrictionContact`): at +slide, at −slide and at slide 0.
pub const CONTACT_FRAME_ROWS: u32 = 3;
/// Network rows per contact of the world-frame friction network
/// (`NetKind::Friction`), read in the contact frame: at +slide and −slide.
pub const WORLD_FRAME_ROWS: u32 = 2;

/// What a network computes: a weights file's `model` metadata.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetKind {
    /// The friction force g of thesis 2.6–2.7 from world-frame c, v_rel
    /// and the coefficients (model `friction`).
    Friction,
    /// The naive force of thesis 2.4 from a triangle and a point in the
    /// local frame (model `naive`).
    Naive,
    /// The friction model in the contact frame (model `friction-contact`):
    /// rotation invariant by construction, so a small network learns only
    /// the scalar law of eqs. 8–9. Trained on friction data.
    FrictionContact,
}

impl NetKind {
    /// The kinds `gen-data` records data for: the contact-frame network
    /// trains on friction data.
    pub const DATA: [NetKind; 2] = [NetKind::Friction, NetKind::Naive];

    /// The `model` metadata value.
    pub fn name(self) -> &'static str {
        match self {
            NetKind::Friction => "friction",
            NetKind::Naive => "naive",
            NetKind::FrictionContact => "friction-contact",
        }
    }

    /// The inputs the simulator takes the network's Jacobian along: c and
    /// v_rel (friction), depth, approach and slide (friction-contact), the
    /// point p (naive).
    pub fn wrt(self) -> Range<usize> {
        match self {
            NetKind::Friction => 0..6,
            NetKind::Naive => 4..7,
            NetKind::FrictionContact => 0..3,
        }
    }

    /// Network evaluations per contact: a friction network (either frame)
    /// runs at +slide and −slide, the symmetry that makes its friction odd
    /// in ṫ; the contact-frame network also at slide 0 for the normal
    /// force, which eq. 8 makes independent of the slide
    /// (`cpu::contact::ContactFrame`).
    pub fn evaluations(self) -> usize {
        match self {
            NetKind::Naive => 1,
            NetKind::Friction => WORLD_FRAME_ROWS as usize,
            NetKind::FrictionContact => CONTACT_FRAME_ROWS as usize,
        }
    }

    /// Of the [`evaluations`](NetKind::evaluations), those of which only
    /// the first output (g_n) and its gradient are read: the
    /// contact-frame network's row at slide 0. They come last.
    pub fn still_rows(self) -> usize {
        match self {
            NetKind::FrictionContact => 1,
            NetKind::Naive | NetKind::Friction => 0,
        }
    }

    /// The evaluations whose every output and gradient is read: all but
    /// the [`still_rows`](NetKind::still_rows), and first.
    pub fn moving_rows(self) -> usize {
        self.evaluations() - self.still_rows()
    }

    /// The kind of data (and of `gen-data`) a network of this kind learns from.
    pub fn data(self) -> NetKind {
        match self {
            NetKind::FrictionContact => NetKind::Friction,
            kind => kind,
        }
    }

    /// The input names, in order, as in the `inputs` metadata.
    pub fn inputs(self) -> &'static [&'static str] {
        match self {
            NetKind::Friction => &FRICTION_INPUTS,
            NetKind::Naive => &NAIVE_INPUTS,
            NetKind::FrictionContact => &FRICTION_CONTACT_INPUTS,
        }
    }

    /// The output names, in order, as in the `outputs` metadata.
    pub fn outputs(self) -> &'static [&'static str] {
        match self {
            NetKind::Friction => &FRICTION_OUTPUTS,
            NetKind::Naive => &NAIVE_OUTPUTS,
            NetKind::FrictionContact => &FRICTION_CONTACT_OUTPUTS,
        }
    }
}

/// A network ready to run: its kind and its layers in physical units.
#[derive(Clone, Debug, PartialEq)]
pub struct Network {
    /// What it computes.
    pub kind: NetKind,
    /// The layers, in physical units.
    pub mlp: Mlp,
}

impl Network {
    /// Multiply-adds of one contact's forward evaluation(s).
    pub fn multiply_adds(&self) -> usize {
        self.mlp.multiply_adds() * self.kind.evaluations()
    }

    /// Multiply-adds of one contact's forces and Jacobians in reverse mode:
    /// a forward pass per evaluation, and a reverse pass per output read,
    /// which at a still row is g_n alone.
    pub fn jacobian_multiply_adds(&self) -> usize {
        let (rows, still) = (self.kind.evaluations(), self.kind.still_rows());
        let passes = rows + self.kind.moving_rows() * self.mlp.outputs() + still;
        self.mlp.multiply_adds() * passes
    }
}

/// A network as stored: layers acting on scaled data, and the scalers.
#[derive(Clone, Debug, PartialEq)]
pub struct WeightsFile {
    /// What it computes (`model`).
    pub kind: NetKind,
    /// The layers, mapping min-max scaled inputs to standardised outputs
    /// (`layer{i}.weight`, `layer{i}.bias`).
    pub layers: Vec<Layer>,
    /// LeakyReLU's slope for negative pre-activations (`negative_slope`).
    pub negative_slope: f32,
    /// Per input, the value scaled to 0 (`input_min`).
    pub input_min: Vec<f32>,
    /// Per input, the value scaled to 1 (`input_max`).
    pub input_max: Vec<f32>,
    /// Per output, the mean added back: g = y ⊙ std + mean (`output_mean`).
    pub output_mean: Vec<f32>,
    /// Per output, the standard deviation y is multiplied by (`output_std`).
    pub output_std: Vec<f32>,
    /// Everything else in the metadata: training recipe and figures.
    pub notes: BTreeMap<String, String>,
}

/// A tensor's values, checked to be finite f32 of the given shape.
pub fn floats(view: &TensorView, name: &str, shape: &[usize], path: &Path) -> Result<Vec<f32>> {
    if view.dtype() != Dtype::F32 {
        return Err(Error::file(
            path,
            format!("tensor `{name}` is {:?}, expected F32", view.dtype()),
        ));
    }
    if view.shape() != shape {
        return Err(Error::file(
            path,
            format!(
                "tensor `{name}` has shape {:?}, expected {shape:?}",
                view.shape()
            ),
        ));
    }
    let values: Vec<f32> = view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::file(
            path,
            format!("tensor `{name}` has a non-finite value at index {k}"),
        ));
    }
    Ok(values)
}

impl WeightsFile {
    /// Reads and validates the weights file at `path`.
    pub fn read(path: &Path) -> Result<WeightsFile> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        WeightsFile::parse(&bytes, path)
    }

    /// Validates a weights file's bytes; `path` only names it in errors.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<WeightsFile> {
        let (_, header) = SafeTensors::read_metadata(bytes)
            .map_err(|e| Error::file(path, format!("not a safetensors file: {e}")))?;
        let tensors = SafeTensors::deserialize(bytes)
            .map_err(|e| Error::file(path, format!("not a safetensors file: {e}")))?;
        let meta = header.metadata().clone().unwrap_or_default();
        let field = |key: &str| -> Result<&str> {
            meta.get(key)
                .map(String::as_str)
                .ok_or_else(|| Error::file(path, format!("metadata has no `{key}`")))
        };
        if field("format")? != FORMAT {
            return Err(Error::file(
                path,
                format!("format is {:?}, expected {FORMAT:?}", field("format")?),
            ));
        }
        let kind = match field("model")? {
            "friction" => NetKind::Friction,
            "naive" => NetKind::Naive,
            "friction-contact" => NetKind::FrictionContact,
            other => {
                return Err(Error::file(
                    path,
                    format!(
                        "model {other:?} is not \"friction\", \"friction-contact\" or \"naive\""
                    ),
                ));
            }
        };
        if field("activation")? != "leaky_relu" {
            return Err(Error::file(
                path,
                format!(
                    "activation {:?} is not \"leaky_relu\"",
                    field("activation")?
                ),
            ));
        }
        let negative_slope: f32 = field("negative_slope")?
            .parse()
            .ok()
            .filter(|s: &f32| s.is_finite() && *s >= 0.0)
            .ok_or_else(|| Error::file(path, "negative_slope is not a finite number ≥ 0"))?;
        for (key, expected) in [("inputs", kind.inputs()), ("outputs", kind.outputs())] {
            let got: Vec<&str> = field(key)?.split(',').map(str::trim).collect();
            if got != expected {
                return Err(Error::file(
                    path,
                    format!(
                        "{key} are {got:?}, a {} network needs {expected:?}",
                        kind.name()
                    ),
                ));
            }
        }

        let views: HashMap<String, TensorView> = tensors.tensors().into_iter().collect();
        let get = |name: &str| {
            views
                .get(name)
                .ok_or_else(|| Error::file(path, format!("tensor `{name}` is missing")))
        };
        let mut layers = Vec::new();
        let mut width = kind.inputs().len();
        while views.contains_key(&format!("layer{}.weight", layers.len())) {
            let i = layers.len();
            let w = get(&format!("layer{i}.weight"))?;
            let outputs = *w.shape().first().unwrap_or(&0);
            if w.shape().len() != 2 || w.shape()[1] != width || outputs == 0 {
                return Err(Error::file(
                    path,
                    format!(
                        "layer{i}.weight has shape {:?}; after {width} values it must be [n, {width}]",
                        w.shape()
                    ),
                ));
            }
            layers.push(Layer {
                inputs: width,
                outputs,
                weight: floats(w, &format!("layer{i}.weight"), &[outputs, width], path)?,
                bias: floats(
                    get(&format!("layer{i}.bias"))?,
                    &format!("layer{i}.bias"),
                    &[outputs],
                    path,
                )?,
            });
            width = outputs;
        }
        if layers.is_empty() {
            return Err(Error::file(path, "tensor `layer0.weight` is missing"));
        }
        if width != kind.outputs().len() {
            return Err(Error::file(
                path,
                format!(
                    "the last layer has {width} outputs, expected {}",
                    kind.outputs().len()
                ),
            ));
        }
        let known = 2 * layers.len() + 4;
        if views.len() != known {
            let mut extra: Vec<&String> = views
                .keys()
                .filter(|k| {
                    !k.starts_with("layer")
                        && !["input_min", "input_max", "output_mean", "output_std"]
                            .contains(&k.as_str())
                })
                .collect();
            extra.sort();
            return Err(Error::file(
                path,
                format!(
                    "unexpected tensors {extra:?} (layers must be numbered from 0 without gaps)"
                ),
            ));
        }
        let n_in = kind.inputs().len();
        let n_out = kind.outputs().len();
        let input_min = floats(get("input_min")?, "input_min", &[n_in], path)?;
        let input_max = floats(get("input_max")?, "input_max", &[n_in], path)?;
        let output_mean = floats(get("output_mean")?, "output_mean", &[n_out], path)?;
        let output_std = floats(get("output_std")?, "output_std", &[n_out], path)?;
        if let Some(k) = (0..n_in).find(|&k| input_max[k] <= input_min[k]) {
            return Err(Error::file(
                path,
                format!("input `{}` has max ≤ min", kind.inputs()[k]),
            ));
        }
        if let Some(k) = (0..n_out).find(|&k| output_std[k] <= 0.0) {
            return Err(Error::file(
                path,
                format!("output `{}` has std ≤ 0", kind.outputs()[k]),
            ));
        }
        let standard = [
            "format",
            "model",
            "activation",
            "negative_slope",
            "inputs",
            "outputs",
        ];
        let notes = meta
            .into_iter()
            .filter(|(k, _)| !standard.contains(&k.as_str()))
            .collect();
        let file = WeightsFile {
            kind,
            layers,
            negative_slope,
            input_min,
            input_max,
            output_mean,
            output_std,
            notes,
        };
        // Finite tensors can still overflow f32 once the scalers are folded
        // in (a weight of 1e38 over an input range of 0.05): the network
        // would compute non-finite forces.
        if let Some(k) = file
            .folded()
            .layers
            .iter()
            .position(|l| !l.weight.iter().chain(&l.bias).all(|w| w.is_finite()))
        {
            return Err(Error::file(
                path,
                format!(
                    "layer {k} overflows f32 once the scalers (input range, output std) are folded into it"
                ),
            ));
        }
        Ok(file)
    }

    /// The file as safetensors bytes: every tensor, the standard metadata
    /// and `notes`.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut meta: HashMap<String, String> = self.notes.clone().into_iter().collect();
        for (k, v) in [
            ("format", FORMAT.to_string()),
            ("model", self.kind.name().to_string()),
            ("activation", "leaky_relu".to_string()),
            ("negative_slope", self.negative_slope.to_string()),
            ("inputs", self.kind.inputs().join(",")),
            ("outputs", self.kind.outputs().join(",")),
        ] {
            meta.insert(k.to_string(), v);
        }
        let mut data: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
        let bytes = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
        for (i, l) in self.layers.iter().enumerate() {
            data.push((
                format!("layer{i}.weight"),
                vec![l.outputs, l.inputs],
                bytes(&l.weight),
            ));
            data.push((format!("layer{i}.bias"), vec![l.outputs], bytes(&l.bias)));
        }
        data.push((
            "input_min".into(),
            vec![self.input_min.len()],
            bytes(&self.input_min),
        ));
        data.push((
            "input_max".into(),
            vec![self.input_max.len()],
            bytes(&self.input_max),
        ));
        data.push((
            "output_mean".into(),
            vec![self.output_mean.len()],
            bytes(&self.output_mean),
        ));
        data.push((
            "output_std".into(),
            vec![self.output_std.len()],
            bytes(&self.output_std),
        ));
        let views: Vec<(String, TensorView)> = data
            .iter()
            .map(|(n, shape, b)| {
                (
                    n.clone(),
                    TensorView::new(Dtype::F32, shape.clone(), b).expect("consistent shapes"),
                )
            })
            .collect();
        // Collected into the map type of safetensors' build (std or hashbrown).
        safetensors::serialize(views, Some(meta.into_iter().collect()))
            .expect("small, consistent tensors serialise")
    }

    /// Writes the file; an existing file is only replaced with `force`.
    pub fn write(&self, path: &Path, force: bool) -> Result<()> {
        if path.exists() && !force {
            return Err(Error::file(
                path,
                "already exists; pass --force to replace it",
            ));
        }
        std::fs::write(path, self.to_bytes()).map_err(|e| Error::io(path, e))
    }

    /// The network with its kind, in physical units (`folded`).
    pub fn network(&self) -> Network {
        Network {
            kind: self.kind,
            mlp: self.folded(),
        }
    }

    /// The network in physical units: u = (x − min) / (max − min) folded
    /// into the first layer, g = y ⊙ std + mean into the last.
    pub fn folded(&self) -> Mlp {
        let mut layers = self.layers.clone();
        let first = &mut layers[0];
        for o in 0..first.outputs {
            for i in 0..first.inputs {
                let w = &mut first.weight[o * first.inputs + i];
                let range = self.input_max[i] - self.input_min[i];
                first.bias[o] -= *w * self.input_min[i] / range;
                *w /= range;
            }
        }
        let last = layers.last_mut().expect("at least one layer");
        for o in 0..last.outputs {
            for w in &mut last.weight[o * last.inputs..(o + 1) * last.inputs] {
                *w *= self.output_std[o];
            }
            last.bias[o] = last.bias[o] * self.output_std[o] + self.output_mean[o];
        }
        Mlp {
            layers,
            negative_slope: self.negative_slope,
        }
    }
}
