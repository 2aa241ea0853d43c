//! `wgcloth.Scene`: a validated configuration and the scene built from it.

use std::path::PathBuf;

use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use pythonize::{depythonize, pythonize};
use wgcloth::Config;

use crate::error;

/// A scene: the thesis scene by default, or a TOML file's or a dict's,
/// with keyword arguments set over it the way a configuration file lays
/// them out (`model="friction"`, `contact={"mu": 0.4}`); a dict's keys
/// may be dotted (`{"contact.mu": 0.4}`), as a sweep file's are. Every
/// value is checked when the scene is made.
#[pyclass(frozen, module = "wgcloth")]
pub struct Scene {
    pub(crate) config: Config,
    pub(crate) scene: wgcloth::Scene,
}

#[pymethods]
impl Scene {
    #[new]
    #[pyo3(signature = (source = None, /, **overrides))]
    fn new(
        source: Option<&Bound<'_, PyAny>>,
        overrides: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Scene> {
        let base = match source {
            None => Config::default(),
            Some(s) if s.is_instance_of::<PyDict>() => with(Config::default(), s)?,
            Some(s) => {
                let path: PathBuf = s.extract().map_err(|_| {
                    pyo3::exceptions::PyTypeError::new_err(
                        "a Scene is made from a TOML file's path or a dict of its values",
                    )
                })?;
                Config::load(&path).map_err(error)?
            }
        };
        let config = match overrides {
            Some(o) => with(base, o.as_any())?,
            None => base,
        };
        Scene::of(config)
    }

    /// This scene with `overrides` set over it, as keyword arguments or
    /// one dict (dotted keys allowed).
    #[pyo3(signature = (values = None, /, **overrides))]
    fn replace(
        &self,
        values: Option<&Bound<'_, PyDict>>,
        overrides: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Scene> {
        let mut config = self.config.clone();
        for o in values.into_iter().chain(overrides) {
            config = with(config, o.as_any())?;
        }
        Scene::of(config)
    }

    /// The whole configuration as a dict, laid out as its TOML file is.
    #[getter]
    fn config<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(pythonize(py, &self.config)?)
    }

    /// The configuration as a TOML document, for the `wgcloth` command
    /// (`wgcloth run --config FILE`).
    fn to_toml(&self) -> PyResult<String> {
        toml::to_string(&self.config)
            .map_err(|e| crate::WgclothError::new_err(format!("the configuration as TOML: {e}")))
    }

    /// Cloth vertices.
    #[getter]
    fn vertices(&self) -> usize {
        self.scene.cloth.vertex_count()
    }

    /// The cloth's triangles, shape (triangles, 3), vertex indices.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        let t = &self.scene.cloth.triangles;
        let flat: Vec<u32> = t.iter().flatten().copied().collect();
        Array2::from_shape_vec((t.len(), 3), flat)
            .expect("three indices a triangle")
            .into_pyarray(py)
    }

    /// Pickled as its configuration, so that a scene travels to another
    /// process (a Ray task, multiprocessing) and is built again there.
    fn __reduce__<'py>(
        slf: &Bound<'py, Self>,
    ) -> PyResult<(Bound<'py, PyAny>, (Bound<'py, PyAny>,))> {
        let py = slf.py();
        let config = pythonize(py, &slf.get().config)?;
        Ok((py.get_type::<Scene>().into_any(), (config,)))
    }

    fn __repr__(&self) -> String {
        let c = &self.config;
        format!(
            "Scene(scene={:?}, model={:?}, grid={:?}, steps={})",
            c.scene.name(),
            c.model.name(),
            c.cloth.grid,
            c.solver.steps
        )
    }
}

impl Scene {
    fn of(config: Config) -> PyResult<Scene> {
        let scene = wgcloth::Scene::new(&config).map_err(error)?;
        Ok(Scene { config, scene })
    }
}

/// `value` without the None values of its dicts (TOML has no null: a
/// None leaves a field as it is, as in a configuration's own dict, where
/// an unset path is None).
fn without_none<'py>(value: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
    let Ok(dict) = value.cast::<PyDict>() else {
        return Ok(value.clone());
    };
    let kept = PyDict::new(value.py());
    for (k, v) in dict.iter().filter(|(_, v)| !v.is_none()) {
        kept.set_item(k, without_none(&v)?)?;
    }
    Ok(kept.into_any())
}

/// `config` with a dict's values set over it, one key at a time so that a
/// dotted key and a table of the same section merge.
fn with(mut config: Config, values: &Bound<'_, PyAny>) -> PyResult<Config> {
    let values = without_none(values)?;
    let dict = values.cast::<PyDict>()?;
    for (key, value) in dict.iter() {
        let key: String = key.cast::<PyString>()?.to_str()?.to_string();
        let value: toml::Value = depythonize(&value).map_err(|e| {
            crate::WgclothError::new_err(format!("`{key}`: not a configuration value: {e}"))
        })?;
        let path: Vec<String> = key.split('.').map(str::to_string).collect();
        let mut table = toml::Table::new();
        wgcloth_cli::sweep::set(&mut table, &path, value);
        config = config.with_overrides(&table).map_err(error)?;
    }
    Ok(config)
}
