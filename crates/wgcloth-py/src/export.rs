//! `wgcloth.write_usd`: frames a Python run kept, as the USD file `wgcloth
//! run --export usd` writes.

use std::path::PathBuf;

use numpy::{AllowTypeChange, PyArrayLike3, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use wgcloth_cli::frames::usd::UsdRecording;

use crate::error;
use crate::scene::Scene;

/// Writes `positions` (frames × the scene's vertices × 3, cast to float32), the
/// cloth at each of `steps`, and the body placed at each step's time, as
/// one USD file: meshes /World/cloth and /World/body with time-sampled
/// points, time codes the steps, `timeCodesPerSecond` 1 / h. An existing
/// file is replaced only with `force`.
#[pyfunction]
#[pyo3(signature = (path, scene, positions, steps, force = false))]
pub fn write_usd(
    path: PathBuf,
    scene: &Scene,
    positions: PyArrayLike3<'_, f32, AllowTypeChange>,
    steps: Vec<u64>,
    force: bool,
) -> PyResult<()> {
    let vertices = scene.scene.cloth.vertex_count();
    let wanted = [steps.len(), vertices, 3];
    if positions.shape() != wanted {
        return Err(PyValueError::new_err(format!(
            "positions: shape {wanted:?} (a frame a step, the scene's vertices, xyz), not {:?}",
            positions.shape()
        )));
    }
    if steps.is_empty() || steps.windows(2).any(|w| w[0] >= w[1]) {
        return Err(PyValueError::new_err(format!(
            "steps: one or more, each after the last, not {steps:?}"
        )));
    }
    if path.exists() && !force {
        return Err(error(wgcloth::Error::file(
            &path,
            "already exists; pass force=True to replace it",
        )));
    }
    let flat = positions.as_array();
    let mut usd = UsdRecording::default();
    for (k, &step) in steps.iter().enumerate() {
        let frame = flat.index_axis(numpy::ndarray::Axis(0), k);
        let x: Vec<glam::Vec3> = (frame.rows().into_iter())
            .map(|p| glam::Vec3::new(p[0], p[1], p[2]))
            .collect();
        usd.push(&scene.scene, step, &x);
    }
    usd.write(&path, &scene.scene).map_err(error)
}
