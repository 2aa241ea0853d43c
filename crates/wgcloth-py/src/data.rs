//! Contact data for training a network in Python, and the weights files
//! a trained network comes back as (DESIGN "The networks").

use std::collections::BTreeMap;
use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{
    AllowTypeChange, IntoPyArray, PyArrayLike1, PyArrayLike2, PyArrayMethods, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use wgcloth::nn::Layer;
use wgcloth::nn::weights::{NetKind, WeightsFile};
use wgcloth_learn::dataset::{Counts, generate};

use crate::error;

fn kind_of(model: &str, kinds: &[NetKind]) -> PyResult<NetKind> {
    kinds
        .iter()
        .copied()
        .find(|k| k.name() == model)
        .ok_or_else(|| {
            let names: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
            PyValueError::new_err(format!("model: one of {names:?}, not {model:?}"))
        })
}

/// The samples `wgcloth gen-data` writes, as numpy arrays: a dict of
/// `inputs` (float32, samples × the network's inputs), `targets` (float32,
/// samples × 3), `input_names`, `target_names` and `model`. Deterministic
/// for a seed; the same seed and counts give the command's file.
#[pyfunction]
#[pyo3(signature = (model = "friction", recorded = 200_000, uniform = 800_000, resting = 0, seed = 1))]
pub fn gen_data<'py>(
    py: Python<'py>,
    model: &str,
    recorded: usize,
    uniform: usize,
    resting: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let kind = kind_of(model, &NetKind::DATA)?;
    let counts = Counts {
        recorded,
        uniform,
        resting,
    };
    let data = py
        .detach(|| generate(kind, counts, seed, |_, _| {}))
        .map_err(error)?;
    let width = kind.inputs().len();
    let inputs =
        Array2::from_shape_vec((data.len(), width), data.inputs).expect("a row of inputs a sample");
    let targets = Array2::from_shape_vec(
        (data.targets.len(), 3),
        data.targets.into_iter().flatten().collect(),
    )
    .expect("three targets a sample");
    let out = PyDict::new(py);
    out.set_item("inputs", inputs.into_pyarray(py))?;
    out.set_item("targets", targets.into_pyarray(py))?;
    out.set_item("input_names", kind.inputs().to_vec())?;
    out.set_item("target_names", kind.data().outputs().to_vec())?;
    out.set_item("model", kind.name())?;
    Ok(out)
}

/// A `wgcloth-mlp/1` weights file as a dict: `model`, `layers` (a list of
/// (weight, bias), weight of shape outputs × inputs), `input_min`,
/// `input_max`, `output_mean`, `output_std`, `negative_slope` and `notes`.
/// The file is checked as the simulator checks it.
#[pyfunction]
pub fn read_weights<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let file = WeightsFile::read(&path).map_err(error)?;
    let out = PyDict::new(py);
    out.set_item("model", file.kind.name())?;
    let layers = (file.layers.into_iter())
        .map(|l| {
            let w = Array2::from_shape_vec((l.outputs, l.inputs), l.weight)
                .expect("outputs × inputs weights");
            (w.into_pyarray(py), l.bias.into_pyarray(py))
        })
        .collect::<Vec<_>>();
    out.set_item("layers", layers)?;
    out.set_item("input_min", file.input_min.into_pyarray(py))?;
    out.set_item("input_max", file.input_max.into_pyarray(py))?;
    out.set_item("output_mean", file.output_mean.into_pyarray(py))?;
    out.set_item("output_std", file.output_std.into_pyarray(py))?;
    out.set_item("negative_slope", file.negative_slope)?;
    out.set_item("notes", file.notes)?;
    Ok(out)
}

/// Writes a network trained anywhere (PyTorch, JAX, numpy) as a
/// `wgcloth-mlp/1` weights file that a scene's `contact.weights` names.
/// `layers` are (weight, bias) pairs of arrays (any float type, or
/// nested lists), weight of shape outputs × inputs,
/// LeakyReLU (`negative_slope`) after each but the last; the network maps
/// inputs scaled to [0, 1] by `input_min` and `input_max` to outputs
/// standardised by `output_mean` and `output_std`. The file is checked as
/// the simulator reads it before it is written; an existing file is
/// replaced only with `force`.
#[pyfunction]
#[pyo3(signature = (path, model, layers, input_min, input_max, output_mean, output_std,
                    negative_slope = wgcloth_learn::train::NEGATIVE_SLOPE, notes = None, force = false))]
#[allow(clippy::too_many_arguments)]
pub fn write_weights(
    path: PathBuf,
    model: &str,
    layers: Vec<(
        PyArrayLike2<'_, f32, AllowTypeChange>,
        PyArrayLike1<'_, f32, AllowTypeChange>,
    )>,
    input_min: Vec<f32>,
    input_max: Vec<f32>,
    output_mean: Vec<f32>,
    output_std: Vec<f32>,
    negative_slope: f32,
    notes: Option<BTreeMap<String, String>>,
    force: bool,
) -> PyResult<()> {
    let kind = kind_of(
        model,
        &[NetKind::Friction, NetKind::Naive, NetKind::FrictionContact],
    )?;
    let layers = (layers.iter().enumerate())
        .map(|(i, (w, b))| {
            let [outputs, inputs] = [w.shape()[0], w.shape()[1]];
            if b.len() != outputs {
                return Err(PyValueError::new_err(format!(
                    "layers[{i}]: a bias of {} values for a weight of {outputs} rows",
                    b.len()
                )));
            }
            Ok(Layer {
                inputs,
                outputs,
                weight: w.as_array().iter().copied().collect(),
                bias: b.to_vec()?,
            })
        })
        .collect::<PyResult<Vec<Layer>>>()?;
    let file = WeightsFile {
        kind,
        layers,
        negative_slope,
        input_min,
        input_max,
        output_mean,
        output_std,
        notes: notes.unwrap_or_default(),
    };
    // Parsed back first: a file the simulator would refuse is never written.
    WeightsFile::parse(&file.to_bytes(), &path).map_err(error)?;
    file.write(&path, force).map_err(error)
}
