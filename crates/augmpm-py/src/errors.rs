//! The exception tree: `Error`, with `SceneError` (bad input) and
//! `SimulationError` (a run that failed) under it.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(_core, Error, PyException, "Base class of every augmpm error.");
create_exception!(_core, SceneError, Error, "A scene or argument is invalid; `key` names what is wrong.");
create_exception!(_core, SimulationError, Error, "A run failed; `step` and `particle` say where.");

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("Error", py.get_type::<Error>())?;
    m.add("SceneError", py.get_type::<SceneError>())?;
    m.add("SimulationError", py.get_type::<SimulationError>())?;
    Ok(())
}

/// `SceneError("key: reason")` with attributes `key` and `reason`.
pub fn scene_error(key: &str, reason: &str) -> PyErr {
    Python::with_gil(|py| {
        let err = SceneError::new_err(format!("{key}: {reason}"));
        let value = err.value(py);
        let _ = value.setattr("key", key);
        let _ = value.setattr("reason", reason);
        err
    })
}

/// `SimulationError(message)` with attributes `step` and `particle`, from either precision's error.
pub fn simulation_error(e: impl std::fmt::Display, (step, particle): (u64, usize)) -> PyErr {
    Python::with_gil(|py| {
        let err = SimulationError::new_err(e.to_string());
        let value = err.value(py);
        let _ = value.setattr("step", step);
        let _ = value.setattr("particle", particle);
        err
    })
}
