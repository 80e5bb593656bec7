//! Python bindings of augmpm-core, the module `augmpm._core`.
//!
//! The Python package validates scene files and hands the resolved scene to
//! [`PySimulation`] as JSON; arrays come back as numpy arrays.

mod errors;
mod grid;

use augmpm_core::Method;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use errors::{scene_error, simulation_error};

/// The engine of a simulation, in the scene's precision: the same core sources compiled with
/// `Real = f64` (`augmpm-core`) or `Real = f32` (`augmpm-core-f32`).
enum Engine {
    F64(augmpm_core::Simulation<2>),
    F32(augmpm_core_f32::Simulation<2>),
}

/// Runs `$body` on the simulation of either precision, with `$core` naming its crate.
macro_rules! with_sim {
    ($engine:expr, $s:ident, $core:ident => $body:expr) => {
        match $engine {
            Engine::F64($s) => {
                #[allow(unused_imports)]
                use augmpm_core as $core;
                $body
            }
            Engine::F32($s) => {
                #[allow(unused_imports)]
                use augmpm_core_f32 as $core;
                $body
            }
        }
    };
}

/// A 2D simulation built from a resolved scene (JSON) with a boundary method.
#[pyclass(name = "Simulation", module = "augmpm._core")]
struct PySimulation {
    engine: Engine,
    warnings: Vec<String>,
}

/// A value of either precision as f64 (generic, so the f64 case is no conversion at all).
fn wide<R: Into<f64>>(x: R) -> f64 {
    x.into()
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

/// An (N, 2) float64 array of vectors of either precision.
pub(crate) fn vectors_to_array<'py, R: nalgebra::Scalar + Copy + Into<f64>>(
    py: Python<'py>,
    v: &[nalgebra::Vector2<R>],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = v.iter().flat_map(|x| [wide(x[0]), wide(x[1])]).collect();
    PyArray1::from_vec(py, flat).reshape([v.len(), 2])
}

/// An (N,) float64 array of scalars of either precision.
fn scalars_to_array<'py, R: Copy + Into<f64>>(py: Python<'py>, v: &[R]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_iter(py, v.iter().map(|&x| wide(x)))
}

#[pymethods]
impl PySimulation {
    #[new]
    #[pyo3(signature = (scene_json, method, threads=0))]
    fn new(scene_json: &str, method: &str, threads: usize) -> PyResult<Self> {
        parse_method(method)?;
        let value: serde_json::Value =
            serde_json::from_str(scene_json).map_err(|e| scene_error("scene", &format!("not valid JSON: {e}")))?;
        let bad = |e: augmpm_core::SceneError| scene_error(&e.key, &e.reason);
        let bad32 = |e: augmpm_core_f32::SceneError| scene_error(&e.key, &e.reason);
        let (engine, warnings) = match value.get("precision").and_then(|p| p.as_str()).unwrap_or("f64") {
            "f32" => {
                let scene = augmpm_core_f32::Scene::from_json(scene_json).map_err(bad32)?;
                let method =
                    if method == "naive" { augmpm_core_f32::Method::Naive } else { augmpm_core_f32::Method::Augmented };
                let (sim, mut warnings) = scene.build(method).map_err(bad32)?;
                if method == augmpm_core_f32::Method::Augmented {
                    warnings.push(
                        "precision f32 with the augmented method is not yet robust: in the benchmark dam break a \
                         particle leaves the grid after ~250 steps (f64 runs it through); prefer f64"
                            .to_string(),
                    );
                }
                (Engine::F32(sim), warnings)
            }
            _ => {
                let scene = augmpm_core::Scene::from_json(scene_json).map_err(bad)?;
                let (sim, warnings) = scene.build(parse_method(method)?).map_err(bad)?;
                (Engine::F64(sim), warnings)
            }
        };
        let mut this = Self { engine, warnings };
        with_sim!(&mut this.engine, s, core => s.set_threads(threads)).map_err(|e| scene_error("threads", &e))?;
        Ok(this)
    }

    /// Floating-point precision of the engine: "f32" or "f64".
    #[getter]
    fn precision(&self) -> &'static str {
        match self.engine {
            Engine::F64(_) => "f64",
            Engine::F32(_) => "f32",
        }
    }

    /// Number of threads the steps run on.
    #[getter]
    fn threads(&self) -> usize {
        with_sim!(&self.engine, s, core => s.threads())
    }

    /// Heap bytes of the particle state, the per-particle scratch and the grid.
    fn memory_use<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (particles, scratch, grid) = with_sim!(&self.engine, s, core => {
            let m = s.memory_use();
            (m.particles, m.particle_scratch, m.grid)
        });
        let d = PyDict::new(py);
        d.set_item("particles", particles)?;
        d.set_item("particle_scratch", scratch)?;
        d.set_item("grid", grid)?;
        Ok(d)
    }

    /// Wall-clock seconds spent so far in each stage of the step: sort, density, boundary, p2g, grid, g2p.
    fn stage_times<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = with_sim!(&self.engine, s, core => {
            let t = s.stage_times();
            [t.sort, t.density, t.boundary, t.p2g, t.grid, t.g2p]
        });
        let d = PyDict::new(py);
        for (k, v) in ["sort", "density", "boundary", "p2g", "grid", "g2p"].into_iter().zip(t) {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// Takes `n` steps (the GIL is released meanwhile). Raises SimulationError on failure;
    /// the state is then that of the failing step.
    fn step(&mut self, py: Python<'_>, n: u64) -> PyResult<()> {
        let engine = &mut self.engine;
        with_sim!(engine, s, core => py.allow_threads(|| s.advance(n)).map_err(|e| simulation_error(&e, e.location())))
    }

    /// Particle positions (m), shape (N, 2).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        with_sim!(&self.engine, s, core => vectors_to_array(py, &s.particles.x))
    }

    /// Particle velocities (m/s), shape (N, 2).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        with_sim!(&self.engine, s, core => vectors_to_array(py, &s.particles.v))
    }

    /// Index of each particle's body, shape (N,).
    #[getter]
    fn body<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        with_sim!(&self.engine, s, core => PyArray1::from_iter(py, s.particles.body.iter().map(|&b| b as i32)))
    }

    /// Particle masses (kg/m in 2D), shape (N,).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        with_sim!(&self.engine, s, core => scalars_to_array(py, &s.particles.mass))
    }

    /// Fluid density of each particle gathered from the regular grid in the last step (kg/m²), shape (N,).
    #[getter]
    fn densities<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        with_sim!(&self.engine, s, core => scalars_to_array(py, s.grid_density()))
    }

    #[getter]
    fn num_particles(&self) -> usize {
        with_sim!(&self.engine, s, core => s.particles.len())
    }

    /// Time (s).
    #[getter]
    fn time(&self) -> f64 {
        with_sim!(&self.engine, s, core => wide(s.time))
    }

    /// Steps taken so far.
    #[getter]
    fn steps_done(&self) -> u64 {
        with_sim!(&self.engine, s, core => s.step)
    }

    /// Time step (s).
    #[getter]
    fn dt(&self) -> f64 {
        with_sim!(&self.engine, s, core => wide(s.model.dt))
    }

    /// The materials' stable time step (s) on this grid.
    #[getter]
    fn stable_dt(&self) -> f64 {
        with_sim!(&self.engine, s, core => wide(s.model.stable_dt()))
    }

    /// Grid cell width h (m).
    #[getter]
    fn cell_size(&self) -> f64 {
        with_sim!(&self.engine, s, core => wide(s.model.layout.h))
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
        let points = rows(&points)?;
        let d: Vec<f64> = with_sim!(&self.engine, s, core => {
            let region = s.model.region.as_ref();
            points.iter().map(|x| wide(region.distance(&x.cast::<core::math::Real>()).distance)).collect()
        });
        Ok(PyArray1::from_vec(py, d))
    }

    /// Boundary grid points of the augmented grid, shape (B, 2); empty for the naive method.
    #[getter]
    fn boundary_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        with_sim!(&self.engine, s, core => {
            let xs: Vec<_> = match &s.model.boundary {
                core::solver::Boundary::Augmented(g) => g.points.iter().map(|p| p.x).collect(),
                core::solver::Boundary::Naive(_) => Vec::new(),
            };
            vectors_to_array(py, &xs)
        })
    }

    /// Step, time, kinetic energy, particles outside the walls, the deepest penetration (cell widths),
    /// and the augmented grid's counts of ill-conditioned particle-steps and low-mass node-steps.
    fn metrics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        with_sim!(&self.engine, s, core => {
            let m = s.metrics();
            d.set_item("step", m.step)?;
            d.set_item("time", wide(m.time))?;
            d.set_item("kinetic_energy", wide(m.kinetic_energy))?;
            d.set_item("n_outside", m.n_outside)?;
            d.set_item("max_penetration", wide(m.max_penetration))?;
            d.set_item("ill_conditioned", m.ill_conditioned)?;
            d.set_item("low_mass_nodes", m.low_mass_nodes)?;
            d.set_item("held_at_wall", m.held_at_wall)?;
        });
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
