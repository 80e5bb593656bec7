//! Python bindings of augmpm-core, the module `augmpm._core`, one module per concern: scenes
//! (`scene`: the schema and its checks), simulations (`simulation`), checkpoints (`checkpoint`: the
//! state as numpy arrays, from the core's field table), the grid of a scene's walls (`grid`),
//! numpy conversions (`convert`) and the exception tree (`errors`).
//!
//! The Python package validates scene files and hands the resolved scene to `Simulation` as JSON;
//! arrays come back as numpy float64 arrays.

mod checkpoint;
mod convert;
mod errors;
mod grid;
mod scene;
mod simulation;

use pyo3::prelude::*;

use errors::{guard, scene_error};

/// Panics on `threads` rayon worker threads with `message`: the test of the panic guard.
#[pyfunction]
fn _panic(message: String, threads: usize) -> PyResult<()> {
    guard(|| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| scene_error("threads", &e.to_string()))?;
        pool.install(|| {
            use rayon::prelude::*;
            (0..threads.max(1) * 4).into_par_iter().for_each(|i| {
                if i % 2 == 1 {
                    panic!("{message}");
                }
            })
        });
        Ok(())
    })
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::install_panic_hook();
    m.add_function(wrap_pyfunction!(_panic, m)?)?;
    m.add_function(wrap_pyfunction!(scene::scene_schema, m)?)?;
    m.add_function(wrap_pyfunction!(scene::check_scene, m)?)?;
    m.add_function(wrap_pyfunction!(scene::scene3_schema, m)?)?;
    m.add_function(wrap_pyfunction!(checkpoint::state_fields, m)?)?;
    m.add_class::<simulation::PySimulation>()?;
    m.add_class::<grid::PyGrid>()?;
    errors::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
