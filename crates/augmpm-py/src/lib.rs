//! Python bindings of augmpm-core, the module `augmpm._core`.
//!
//! The Python package validates scene files and hands the resolved scene to
//! [`PySimulation`] as JSON; arrays come back as numpy arrays.

mod errors;
mod grid;

use augmpm_core::solver::Boundary;
use augmpm_core::{Method, Scene, Simulation};
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use errors::{scene_error, simulation_error};

/// A 2D simulation built from a resolved scene (JSON) with a boundary method.
#[pyclass(name = "Simulation", module = "augmpm._core")]
struct PySimulation {
    sim: Simulation<2>,
    warnings: Vec<String>,
}

/// Parses a boundary method name.
pub(crate) fn parse_method(method: &str) -> PyResult<Method> {
    match method {
        "naive" => Ok(Method::Naive),
        "augmented" => Ok(Method::Augmented),
        other => Err(scene_error("method", &format!("unknown method {other:?}; expected \"naive\" or \"augmented\""))),
    }
}

/// Points of an (M, 2) array.
pub(crate) fn rows(a: &numpy::PyReadonlyArray2<'_, f64>) -> PyResult<Vec<nalgebra::Vector2<f64>>> {
    let a = a.as_array();
    if a.ncols() != 2 {
        return Err(pyo3::exceptions::PyValueError::new_err(format!(
            "points must have shape (M, 2), got {:?}",
            a.shape()
        )));
    }
    Ok(a.rows().into_iter().map(|r| nalgebra::Vector2::new(r[0], r[1])).collect())
}

pub(crate) fn vectors_to_array<'py>(
    py: Python<'py>,
    v: &[nalgebra::Vector2<f64>],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = v.iter().flat_map(|x| [x[0], x[1]]).collect();
    PyArray1::from_vec(py, flat).reshape([v.len(), 2])
}

#[pymethods]
impl PySimulation {
    #[new]
    #[pyo3(signature = (scene_json, method, threads=0))]
    fn new(scene_json: &str, method: &str, threads: usize) -> PyResult<Self> {
        let method = parse_method(method)?;
        let scene = Scene::from_json(scene_json).map_err(|e| scene_error(&e.key, &e.reason))?;
        let (mut sim, warnings) = scene.build(method).map_err(|e| scene_error(&e.key, &e.reason))?;
        sim.set_threads(threads).map_err(|e| scene_error("threads", &e))?;
        Ok(Self { sim, warnings })
    }

    /// Number of threads the steps run on.
    #[getter]
    fn threads(&self) -> usize {
        self.sim.threads()
    }

    /// Heap bytes of the particle state, the per-particle scratch and the grid.
    fn memory_use<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = self.sim.memory_use();
        let d = PyDict::new(py);
        d.set_item("particles", m.particles)?;
        d.set_item("particle_scratch", m.particle_scratch)?;
        d.set_item("grid", m.grid)?;
        Ok(d)
    }

    /// Wall-clock seconds spent so far in each stage of the step: sort, density, boundary, p2g, grid, g2p.
    fn stage_times<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = self.sim.stage_times();
        let d = PyDict::new(py);
        for (k, v) in [
            ("sort", t.sort),
            ("density", t.density),
            ("boundary", t.boundary),
            ("p2g", t.p2g),
            ("grid", t.grid),
            ("g2p", t.g2p),
        ] {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// Takes `n` steps (the GIL is released meanwhile). Raises SimulationError on failure;
    /// the state is then that of the failing step.
    fn step(&mut self, py: Python<'_>, n: u64) -> PyResult<()> {
        let sim = &mut self.sim;
        py.allow_threads(|| sim.advance(n)).map_err(simulation_error)
    }

    /// Particle positions (m), shape (N, 2).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        vectors_to_array(py, &self.sim.particles.x)
    }

    /// Particle velocities (m/s), shape (N, 2).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        vectors_to_array(py, &self.sim.particles.v)
    }

    /// Index of each particle's body, shape (N,).
    #[getter]
    fn body<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        PyArray1::from_iter(py, self.sim.particles.body.iter().map(|&b| b as i32))
    }

    /// Particle masses (kg/m in 2D), shape (N,).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.sim.particles.mass)
    }

    /// Fluid density of each particle gathered from the regular grid in the last step (kg/m²), shape (N,).
    #[getter]
    fn densities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.sim.grid_density())
    }

    #[getter]
    fn num_particles(&self) -> usize {
        self.sim.particles.len()
    }

    /// Time (s).
    #[getter]
    fn time(&self) -> f64 {
        self.sim.time
    }

    /// Steps taken so far.
    #[getter]
    fn steps_done(&self) -> u64 {
        self.sim.step
    }

    /// Time step (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.sim.model.dt
    }

    /// The materials' stable time step (s) on this grid.
    #[getter]
    fn stable_dt(&self) -> f64 {
        self.sim.model.stable_dt()
    }

    /// Grid cell width h (m).
    #[getter]
    fn cell_size(&self) -> f64 {
        self.sim.model.layout.h
    }

    /// Warnings raised while building the simulation (e.g. dt above the stable bound).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// Signed distance (m) of points (M, 2) to the walls, positive outside the material region.
    fn wall_distance<'py>(
        &self,
        py: Python<'py>,
        points: numpy::PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let region = self.sim.model.region.as_ref();
        Ok(PyArray1::from_vec(py, rows(&points)?.iter().map(|x| region.distance(x).distance).collect()))
    }

    /// Boundary grid points of the augmented grid, shape (B, 2); empty for the naive method.
    #[getter]
    fn boundary_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let xs: Vec<nalgebra::Vector2<f64>> = match &self.sim.model.boundary {
            Boundary::Augmented(g) => g.points.iter().map(|p| p.x).collect(),
            Boundary::Naive(_) => Vec::new(),
        };
        vectors_to_array(py, &xs)
    }

    /// Step, time, kinetic energy, particles outside the walls, the deepest penetration (cell widths),
    /// and the augmented grid's counts of ill-conditioned particle-steps and low-mass node-steps.
    fn metrics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = self.sim.metrics();
        let d = PyDict::new(py);
        d.set_item("step", m.step)?;
        d.set_item("time", m.time)?;
        d.set_item("kinetic_energy", m.kinetic_energy)?;
        d.set_item("n_outside", m.n_outside)?;
        d.set_item("max_penetration", m.max_penetration)?;
        d.set_item("ill_conditioned", m.ill_conditioned)?;
        d.set_item("low_mass_nodes", m.low_mass_nodes)?;
        d.set_item("held_at_wall", m.held_at_wall)?;
        Ok(d)
    }
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySimulation>()?;
    m.add_class::<grid::PyGrid>()?;
    errors::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
