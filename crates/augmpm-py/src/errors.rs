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
pub fn simulation_error(e: impl std::fmt::Display, (step, particle): (u64, Option<usize>)) -> PyErr {
    Python::with_gil(|py| {
        let err = SimulationError::new_err(e.to_string());
        let value = err.value(py);
        let _ = value.setattr("step", step);
        let _ = value.setattr("particle", particle);
        err
    })
}

/// Where and why the last panic of this process happened, recorded by [`install_panic_hook`].
static LAST_PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// Replaces Rust's panic message on stderr: the panic is recorded and reported by [`guard`] as a
/// Python exception instead (on any thread: a worker's panic reaches the caller through rayon).
pub fn install_panic_hook() {
    std::panic::set_hook(Box::new(|info| {
        let message = match (info.payload().downcast_ref::<&str>(), info.payload().downcast_ref::<String>()) {
            (Some(s), _) => s.to_string(),
            (_, Some(s)) => s.clone(),
            _ => "unknown panic".to_string(),
        };
        let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
        if let Ok(mut last) = LAST_PANIC.lock() {
            *last = Some(format!("{message}{at}"));
        }
    }));
}

/// Runs `f`; a Rust panic comes back as `Err` with its message (and where it happened).
pub fn catch_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        let recorded = LAST_PANIC.lock().ok().and_then(|mut last| last.take());
        recorded.unwrap_or_else(|| match payload.downcast_ref::<String>() {
            Some(s) => s.clone(),
            None => payload.downcast_ref::<&str>().map_or("unknown panic".to_string(), |s| s.to_string()),
        })
    })
}

/// `augmpm.Error` for a panic: a bug, reported with its message.
pub fn internal_error(message: &str) -> PyErr {
    Error::new_err(format!("internal error (a bug in augmpm; please report it): {message}"))
}

/// Runs `f`, turning a Rust panic into `augmpm.Error` with the panic's message: no panic crosses
/// into Python. Every entry point of the bindings goes through it.
pub fn guard<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    catch_panic(f).unwrap_or_else(|message| Err(internal_error(&message)))
}
