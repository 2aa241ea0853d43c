//! The wgcloth Python package's native module, `wgcloth._native`: scenes
//! from TOML files, dicts or keyword arguments ([`scene`]), simulators of
//! one or many worlds on the best adapter or the CPU path whose state is
//! numpy arrays ([`simulator`]), and contact data and weights files for
//! training a network in Python ([`data`]), and runs as USD files
//! ([`export`]). What wgcloth refuses raises `wgcloth.WgclothError`
//! with the library's message; a wrong Python argument, `TypeError` or
//! `ValueError`.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

mod data;
mod export;
mod scene;
mod simulator;

create_exception!(
    wgcloth,
    WgclothError,
    PyException,
    "An error from wgcloth: a bad configuration, file or argument, a scene the device cannot hold, a device fault."
);

/// The library's error as a Python exception with its message.
fn error(e: wgcloth::Error) -> PyErr {
    WgclothError::new_err(e.to_string())
}

#[pymodule]
#[pyo3(name = "_native")]
fn native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("WgclothError", m.py().get_type::<WgclothError>())?;
    m.add_class::<scene::Scene>()?;
    m.add_class::<simulator::Simulator>()?;
    m.add_function(wrap_pyfunction!(simulator::run, m)?)?;
    m.add_function(wrap_pyfunction!(data::gen_data, m)?)?;
    m.add_function(wrap_pyfunction!(data::read_weights, m)?)?;
    m.add_function(wrap_pyfunction!(data::write_weights, m)?)?;
    m.add_function(wrap_pyfunction!(export::write_usd, m)?)?;
    m.add("NEGATIVE_SLOPE", wgcloth_learn::train::NEGATIVE_SLOPE)?;
    Ok(())
}
