//! `wgcloth.Simulator` and `wgcloth.run`: one world or a batch, on the
//! backend the CLI would pick, with the CLI's notices.

use numpy::ndarray::Array3;
use numpy::{IntoPyArray, PyArray3};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyList;
use pythonize::pythonize;
use wgcloth::GpuSim;
use wgcloth_cli::run::{self as cli, Backend, Batch, Observers, Steps};

use crate::error;
use crate::scene::Scene;

/// `scenes` (one `Scene` or a sequence of them) as the worlds of a batch:
/// `worlds` copies of one scene, or the sequence, whose length `worlds`
/// must then match; and whether a batch was asked for (`worlds`, or a
/// sequence), rather than one scene.
fn worlds_of(
    scenes: &Bound<'_, PyAny>,
    worlds: Option<usize>,
) -> PyResult<(Vec<wgcloth::Scene>, bool)> {
    let one = scenes.cast::<Scene>().ok();
    let batch = worlds.is_some() || one.is_none();
    let given: Vec<wgcloth::Scene> = match one {
        Some(one) => vec![one.get().scene.clone(); worlds.unwrap_or(1)],
        None => {
            let list: Vec<Bound<'_, Scene>> = scenes.extract().map_err(|_| {
                pyo3::exceptions::PyTypeError::new_err("scene: a Scene, or a sequence of Scenes")
            })?;
            if let Some(n) = worlds.filter(|&n| n != list.len()) {
                return Err(PyValueError::new_err(format!(
                    "worlds is {n} but {} scenes were given; give one or make them agree",
                    list.len()
                )));
            }
            list.iter().map(|s| s.get().scene.clone()).collect()
        }
    };
    if given.is_empty() || worlds == Some(0) {
        return Err(PyValueError::new_err("worlds: at least 1"));
    }
    let n = given[0].cloth.vertex_count();
    if let Some(k) = given.iter().position(|s| s.cloth.vertex_count() != n) {
        return Err(PyValueError::new_err(format!(
            "world {k} has {} cloth vertices and world 0 {n}: the worlds of a simulator share a grid",
            given[k].cloth.vertex_count()
        )));
    }
    Ok((given, batch))
}

fn backend_of(name: &str) -> PyResult<Backend> {
    match name {
        "auto" => Ok(Backend::Auto),
        "gpu" => Ok(Backend::Gpu),
        "cpu" => Ok(Backend::Cpu),
        other => Err(PyValueError::new_err(format!(
            "backend: \"auto\", \"gpu\" or \"cpu\", not {other:?}"
        ))),
    }
}

/// Writes a notice to Python's `sys.stderr`, where a notebook shows it.
fn tell(py: Python<'_>, line: &str) -> PyResult<()> {
    py.import("sys")?
        .getattr("stderr")?
        .call_method1("write", (format!("{line}\n"),))?;
    Ok(())
}

/// The backend a run chooses (`auto`: a hardware GPU, else the CPU), and
/// the batch of `scenes` on it, with the CLI's notices, told to Python's
/// `sys.stderr` and returned: `gpu` refuses a batch the GPU does not run
/// (before a device is opened), `auto` runs it on the CPU.
fn batch(
    py: Python<'_>,
    backend: Backend,
    scenes: Vec<wgcloth::Scene>,
) -> PyResult<(Batch, Vec<String>)> {
    if backend == Backend::Gpu && scenes.len() > 1 {
        GpuSim::batchable(&scenes[0]).map_err(error)?;
    }
    let (chosen, notice) = py
        .detach(|| cli::choose_backend(backend, wgcloth::gpu::OPTIONAL_FEATURES))
        .map_err(error)?;
    let mut notices: Vec<String> = notice.into_iter().collect();
    let batch = py
        .detach(|| cli::batch_on(&chosen, scenes, &[], |n| notices.push(n)))
        .map_err(error)?;
    for n in &notices {
        tell(py, n)?;
    }
    Ok((batch, notices))
}

/// N worlds of a scene stepped together (one world by default), on the
/// best adapter or the CPU path (`backend` "auto", "gpu" or "cpu").
/// `positions` and `velocities` are numpy arrays of shape (worlds,
/// vertices, 3); `report()` is the `wgcloth run --worlds` report as a dict.
#[pyclass(module = "wgcloth")]
pub struct Simulator {
    batch: Batch,
    notices: Vec<String>,
}

#[pymethods]
impl Simulator {
    #[new]
    #[pyo3(signature = (scene, worlds = None, backend = "auto"))]
    fn new(
        py: Python<'_>,
        scene: &Bound<'_, PyAny>,
        worlds: Option<usize>,
        backend: &str,
    ) -> PyResult<Simulator> {
        let (scenes, _) = worlds_of(scene, worlds)?;
        let (batch, notices) = batch(py, backend_of(backend)?, scenes)?;
        Ok(Simulator { batch, notices })
    }

    /// Steps every world `n` times (the GIL released while it runs).
    #[pyo3(signature = (n = 1))]
    fn step(&mut self, py: Python<'_>, n: u64) -> PyResult<()> {
        for _ in 0..n {
            let batch = &mut self.batch;
            py.detach(|| batch.step()).map_err(error)?;
            py.check_signals()?;
        }
        Ok(())
    }

    /// Every world's cloth positions, m: float32, shape (worlds, vertices, 3).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f32>>> {
        Ok(self.array(py, self.batch.state().map_err(error)?.0))
    }

    /// Every world's cloth velocities, m/s: float32, shape (worlds, vertices, 3).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f32>>> {
        Ok(self.array(py, self.batch.state().map_err(error)?.1))
    }

    /// The run so far as a dict: the backend and adapter, the median ms a
    /// batch step, and one entry a world (`worlds`) with its PCG
    /// iterations and residuals, contacts, deepest penetration, final
    /// energy and any divergence.
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        Ok(pythonize(py, &self.batch.report().map_err(error)?)?)
    }

    /// Worlds stepped together.
    #[getter]
    fn worlds(&self) -> usize {
        self.batch.worlds()
    }

    /// Cloth vertices of each world.
    #[getter]
    fn vertices(&self) -> usize {
        self.batch.scenes()[0].cloth.vertex_count()
    }

    /// Steps taken.
    #[getter]
    fn steps(&self) -> u64 {
        self.batch.steps()
    }

    /// "gpu" or "cpu": where the worlds step.
    #[getter]
    fn backend(&self) -> String {
        self.batch.backend().to_string()
    }

    /// The adapter, or the CPU path and its threads.
    #[getter]
    fn adapter(&self) -> String {
        self.batch.adapter()
    }

    /// The notices printed when the backend was chosen (why `auto` runs on
    /// the CPU, say).
    #[getter]
    fn notices<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, &self.notices)
    }

    fn __repr__(&self) -> String {
        format!(
            "Simulator(worlds={}, vertices={}, backend={:?}, steps={})",
            self.worlds(),
            self.vertices(),
            self.batch.backend(),
            self.batch.steps()
        )
    }
}

impl Simulator {
    fn array<'py>(&self, py: Python<'py>, v: Vec<glam::Vec3>) -> Bound<'py, PyArray3<f32>> {
        let flat: Vec<f32> = v.iter().flat_map(|p| p.to_array()).collect();
        Array3::from_shape_vec((self.worlds(), self.vertices(), 3), flat)
            .expect("every world's vertices")
            .into_pyarray(py)
    }
}

/// Runs `scene` for its `solver.steps` (or `steps`) steps as the `wgcloth
/// run` command does, and returns its report as a dict: one scene with the
/// command's stepping (steps in flight on the GPU, a fault falling back to
/// the CPU under "auto") and its report, or, given `worlds` or a sequence
/// of scenes, a batch and `run --worlds`'s report (`worlds`: one entry a
/// world).
#[pyfunction]
#[pyo3(signature = (scene, steps = None, worlds = None, backend = "auto"))]
pub fn run<'py>(
    py: Python<'py>,
    scene: &Bound<'py, PyAny>,
    steps: Option<u64>,
    worlds: Option<usize>,
    backend: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let backend = backend_of(backend)?;
    let (scenes, batched) = worlds_of(scene, worlds)?;
    let steps = steps.unwrap_or(scenes[0].config.solver.steps);
    if batched {
        let (batch, _) = crate::simulator::batch(py, backend, scenes)?;
        let report = py
            .detach(|| cli::run_batch(batch, steps, |_| {}))
            .map_err(error)?;
        return Ok(pythonize(py, &report)?);
    }
    let (chosen, notice) = py
        .detach(|| cli::choose_backend(backend, wgcloth::gpu::OPTIONAL_FEATURES))
        .map_err(error)?;
    let scene = scenes.into_iter().next().expect("one scene");
    let mut notices: Vec<String> = notice.into_iter().collect();
    let report = py
        .detach(|| {
            let mut notice = |line: &str| notices.push(line.to_string());
            let obs = Observers {
                notice: Some(&mut notice),
                ..Observers::default()
            };
            cli::run(&chosen, scene, Steps::all(steps), obs)
        })
        .map_err(error)?;
    for n in &notices {
        tell(py, n)?;
    }
    Ok(pythonize(py, &report)?)
}
