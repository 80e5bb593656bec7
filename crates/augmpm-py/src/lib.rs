//! Python bindings of augmpm-core, the module `augmpm._core`.
//!
//! The Python package validates scene files and hands the resolved scene to
//! [`PySimulation`] as JSON; arrays come back as numpy arrays.

mod errors;
mod grid;
mod scene;

use augmpm_core::Method;
use numpy::{PyArray1, PyArray2, PyArray3, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use errors::{guard, scene_error, simulation_error};

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
    /// Set when a Rust panic interrupted a call: the state can no longer be trusted.
    broken: Option<String>,
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
        return Err(scene_error("points", &format!("must have shape (M, 2), got {:?}", a.shape())));
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

/// A float64 array of the saved state with the given trailing shape, flattened.
fn state_array(state: &Bound<'_, PyDict>, key: &str, n: usize, tail: &[usize]) -> PyResult<Vec<f64>> {
    array_of::<f64>(state, key, n, tail, "float64")
}

/// A uint32 array of the saved state of shape (n,).
fn state_indices(state: &Bound<'_, PyDict>, key: &str, n: usize) -> PyResult<Vec<u32>> {
    array_of::<u32>(state, key, n, &[], "uint32")
}

fn array_of<T: numpy::Element + Copy>(
    state: &Bound<'_, PyDict>,
    key: &str,
    n: usize,
    tail: &[usize],
    dtype: &str,
) -> PyResult<Vec<T>> {
    let bad = |reason: String| scene_error(&format!("state.{key}"), &reason);
    let item = state.get_item(key)?.ok_or_else(|| bad("missing".to_string()))?;
    let array: PyReadonlyArrayDyn<'_, T> = item.extract().map_err(|_| bad(format!("must be a {dtype} numpy array")))?;
    let shape: Vec<usize> = std::iter::once(n).chain(tail.iter().copied()).collect();
    if array.shape() != shape.as_slice() {
        return Err(bad(format!("must have shape {shape:?}, got {:?}", array.shape())));
    }
    Ok(array.as_array().iter().copied().collect())
}

/// A scalar of the saved state.
fn state_scalar<'py, T: FromPyObject<'py>>(state: &Bound<'py, PyDict>, key: &str) -> PyResult<T> {
    let bad = |reason: &str| scene_error(&format!("state.{key}"), reason);
    state.get_item(key)?.ok_or_else(|| bad("missing"))?.extract().map_err(|_| bad("has the wrong type"))
}

impl PySimulation {
    fn build(scene_json: &str, method: &str, threads: usize, memory_limit: Option<u64>) -> PyResult<Self> {
        parse_method(method)?;
        let value: serde_json::Value =
            serde_json::from_str(scene_json).map_err(|e| scene_error("scene", &format!("not valid JSON: {e}")))?;
        let bad = |e: augmpm_core::SceneError| scene_error(&e.key, &e.reason);
        let bad32 = |e: augmpm_core_f32::SceneError| scene_error(&e.key, &e.reason);
        let (engine, warnings) = match value.get("precision").and_then(|p| p.as_str()).unwrap_or("f64") {
            "f32" => {
                let scene = augmpm_core_f32::Scene::from_json(scene_json).map_err(bad32)?;
                if let Some(limit) = memory_limit {
                    scene.memory_estimate().and_then(|m| m.check(limit)).map_err(bad32)?;
                }
                let method =
                    if method == "naive" { augmpm_core_f32::Method::Naive } else { augmpm_core_f32::Method::Augmented };
                let (sim, warnings) = scene.build(method).map_err(bad32)?;
                (Engine::F32(sim), warnings)
            }
            _ => {
                let scene = augmpm_core::Scene::from_json(scene_json).map_err(bad)?;
                if let Some(limit) = memory_limit {
                    scene.memory_estimate().and_then(|m| m.check(limit)).map_err(bad)?;
                }
                let (sim, warnings) = scene.build(parse_method(method)?).map_err(bad)?;
                (Engine::F64(sim), warnings)
            }
        };
        let mut this = Self { engine, warnings, broken: None };
        with_sim!(&mut this.engine, s, core => s.set_threads(threads)).map_err(|e| scene_error("threads", &e))?;
        Ok(this)
    }

    /// Refuses to touch an engine that a panic interrupted.
    fn usable(&self) -> PyResult<()> {
        match &self.broken {
            None => Ok(()),
            Some(why) => Err(errors::Error::new_err(format!(
                "this simulation is unusable after an internal error ({why}); build a new one"
            ))),
        }
    }

    /// Runs `f` on the engine as [`guard`] does; a panic also marks the simulation unusable.
    fn guarded<T>(&mut self, f: impl FnOnce(&mut Engine) -> PyResult<T>) -> PyResult<T> {
        self.usable()?;
        let engine = &mut self.engine;
        errors::catch_panic(|| f(engine)).unwrap_or_else(|message| {
            self.broken = Some(message.clone());
            Err(errors::internal_error(&message))
        })
    }
}

#[pymethods]
impl PySimulation {
    #[new]
    #[pyo3(signature = (scene_json, method, threads=0, memory_limit=None))]
    fn new(scene_json: &str, method: &str, threads: usize, memory_limit: Option<u64>) -> PyResult<Self> {
        guard(|| Self::build(scene_json, method, threads, memory_limit))
    }

    /// The state of the run, for a checkpoint: a dict of scalars and numpy arrays (float64 reals
    /// in either precision, exact) that [`PySimulation::restore`] takes back.
    fn checkpoint<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        self.guarded(|engine| {
            with_sim!(engine, s, core => {
                let st = s.state();
                let p = &st.particles;
                let n = p.x.len();
                let matrices = |m: &[core::math::Matrix<2>]| -> PyResult<Bound<'py, PyArray3<f64>>> {
                    let flat: Vec<f64> =
                        m.iter().flat_map(|a| [wide(a[(0, 0)]), wide(a[(0, 1)]), wide(a[(1, 0)]), wide(a[(1, 1)])]).collect();
                    PyArray1::from_vec(py, flat).reshape([n, 2, 2])
                };
                d.set_item("step", st.step)?;
                d.set_item("time", wide(st.time))?;
                d.set_item("ill_conditioned", st.ill_conditioned)?;
                d.set_item("low_mass_nodes", st.low_mass_nodes)?;
                d.set_item("held_at_wall", st.held_at_wall)?;
                d.set_item("max_cfl", wide(st.max_cfl))?;
                d.set_item("drift", wide(st.drift))?;
                d.set_item("x", vectors_to_array(py, &p.x)?)?;
                d.set_item("v", vectors_to_array(py, &p.v)?)?;
                d.set_item("c", matrices(&p.c)?)?;
                d.set_item("f", matrices(&p.f)?)?;
                d.set_item("jp", scalars_to_array(py, &p.jp))?;
                d.set_item("mass", scalars_to_array(py, &p.mass))?;
                d.set_item("vol0", scalars_to_array(py, &p.vol0))?;
                d.set_item("body", PyArray1::from_slice(py, &p.body))?;
                d.set_item("material", PyArray1::from_slice(py, &p.material))?;
                d.set_item("density", scalars_to_array(py, &st.density))?;
                d.set_item("bins", PyArray1::from_slice(py, &st.bins))?;
                Ok(())
            })
        })?;
        Ok(d)
    }

    /// Continues from a state returned by [`PySimulation::checkpoint`] of a simulation of the same
    /// scene and method; the steps that follow are bitwise identical to the saved run's. A state
    /// that does not fit raises SceneError naming the entry, and leaves the simulation as it was.
    fn restore(&mut self, state: &Bound<'_, PyDict>) -> PyResult<()> {
        let count = state
            .get_item("x")?
            .ok_or_else(|| scene_error("state.x", "missing"))?
            .extract::<PyReadonlyArrayDyn<'_, f64>>()
            .map_err(|_| scene_error("state.x", "must be a float64 numpy array"))?
            .shape()
            .first()
            .copied()
            .unwrap_or(0);
        let x = state_array(state, "x", count, &[2])?;
        let v = state_array(state, "v", count, &[2])?;
        let c = state_array(state, "c", count, &[2, 2])?;
        let f = state_array(state, "f", count, &[2, 2])?;
        let jp = state_array(state, "jp", count, &[])?;
        let mass = state_array(state, "mass", count, &[])?;
        let vol0 = state_array(state, "vol0", count, &[])?;
        let density = state_array(state, "density", count, &[])?;
        let body = state_indices(state, "body", count)?;
        let material = state_indices(state, "material", count)?;
        let bins = state_indices(state, "bins", count)?;
        let step: u64 = state_scalar(state, "step")?;
        let time: f64 = state_scalar(state, "time")?;
        let counters: [u64; 3] = [
            state_scalar(state, "ill_conditioned")?,
            state_scalar(state, "low_mass_nodes")?,
            state_scalar(state, "held_at_wall")?,
        ];
        let max_cfl: f64 = state_scalar(state, "max_cfl")?;
        let drift: f64 = state_scalar(state, "drift")?;
        self.guarded(|engine| {
            with_sim!(engine, s, core => {
                type R = core::math::Real;
                let vec2 = |a: &[f64]| -> Vec<core::math::Vector<2>> {
                    a.chunks_exact(2).map(|v| core::math::Vector::<2>::new(v[0] as R, v[1] as R)).collect()
                };
                let mat2 = |a: &[f64]| -> Vec<core::math::Matrix<2>> {
                    a.chunks_exact(4)
                        .map(|m| core::math::Matrix::<2>::new(m[0] as R, m[1] as R, m[2] as R, m[3] as R))
                        .collect()
                };
                let reals = |a: &[f64]| -> Vec<R> { a.iter().map(|&v| v as R).collect() };
                let particles = core::particles::Particles {
                    x: vec2(&x),
                    v: vec2(&v),
                    c: mat2(&c),
                    f: mat2(&f),
                    jp: reals(&jp),
                    mass: reals(&mass),
                    vol0: reals(&vol0),
                    body,
                    material,
                };
                let state = core::State {
                    step,
                    time: time as R,
                    ill_conditioned: counters[0],
                    low_mass_nodes: counters[1],
                    held_at_wall: counters[2],
                    max_cfl: max_cfl as R,
                    particles,
                    density: reals(&density),
                    bins,
                    drift: drift as R,
                };
                s.restore(state).map_err(|e| scene_error("state", &e))
            })
        })
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
        let (particles, scratch, grid) = guard(|| {
            Ok(with_sim!(&self.engine, s, core => {
                let m = s.memory_use();
                (m.particles, m.particle_scratch, m.grid)
            }))
        })?;
        let d = PyDict::new(py);
        d.set_item("particles", particles)?;
        d.set_item("particle_scratch", scratch)?;
        d.set_item("grid", grid)?;
        Ok(d)
    }

    /// Wall-clock seconds spent so far in each stage of the step: sort, density, boundary, p2g, grid, g2p.
    fn stage_times<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = guard(|| {
            Ok(with_sim!(&self.engine, s, core => {
                let t = s.stage_times();
                [t.sort, t.density, t.boundary, t.p2g, t.grid, t.g2p]
            }))
        })?;
        let d = PyDict::new(py);
        for (k, v) in ["sort", "density", "boundary", "p2g", "grid", "g2p"].into_iter().zip(t) {
            d.set_item(k, v)?;
        }
        Ok(d)
    }

    /// Takes `n` steps (the GIL is released meanwhile). Raises SimulationError on failure;
    /// the state is then that of the failing step.
    fn step(&mut self, py: Python<'_>, n: u64) -> PyResult<()> {
        self.guarded(|engine| {
            with_sim!(engine, s, core => {
                let earlier = s.failure().is_some();
                py.allow_threads(|| s.advance(n)).map_err(|e| {
                    let again = if earlier { " (it failed earlier; restore a checkpoint or build a new simulation)" } else { "" };
                    simulation_error(format!("{e}{again}"), e.location())
                })
            })
        })
    }

    /// Particle positions (m), shape (N, 2).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| with_sim!(&self.engine, s, core => vectors_to_array(py, &s.particles.x)))
    }

    /// Particle velocities (m/s), shape (N, 2).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| with_sim!(&self.engine, s, core => vectors_to_array(py, &s.particles.v)))
    }

    /// Index of each particle's body, shape (N,).
    #[getter]
    fn body<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<i32>>> {
        guard(|| {
            Ok(with_sim!(&self.engine, s, core => PyArray1::from_iter(py, s.particles.body.iter().map(|&b| b as i32))))
        })
    }

    /// Particle masses (kg/m in 2D), shape (N,).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(|| Ok(with_sim!(&self.engine, s, core => scalars_to_array(py, &s.particles.mass))))
    }

    /// Fluid density of each particle in the last step (kg/m²), shape (N,): ρ0/J or gathered from the grid.
    #[getter]
    fn densities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(|| Ok(with_sim!(&self.engine, s, core => scalars_to_array(py, s.grid_density()))))
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
    fn stable_dt(&self) -> PyResult<f64> {
        guard(|| Ok(with_sim!(&self.engine, s, core => wide(s.model.stable_dt()))))
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
        guard(|| {
            let d: Vec<f64> = with_sim!(&self.engine, s, core => {
                let region = s.model.region.as_ref();
                points.iter().map(|x| wide(region.distance(&x.cast::<core::math::Real>()).distance)).collect()
            });
            Ok(PyArray1::from_vec(py, d))
        })
    }

    /// Boundary grid points of the augmented grid, shape (B, 2); empty for the naive method.
    #[getter]
    fn boundary_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| {
            with_sim!(&self.engine, s, core => {
                let xs: Vec<_> = match &s.model.boundary {
                    core::solver::Boundary::Augmented(g) => g.points.iter().map(|p| p.x).collect(),
                    core::solver::Boundary::Naive(_) => Vec::new(),
                };
                vectors_to_array(py, &xs)
            })
        })
    }

    /// Step, time, kinetic energy, particles outside the walls, the deepest penetration (cell widths),
    /// and the augmented grid's counts of ill-conditioned particle-steps and low-mass node-steps.
    fn metrics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let m = guard(|| {
            Ok(with_sim!(&self.engine, s, core => {
                let m = s.metrics();
                (m.step, wide(m.time), wide(m.kinetic_energy), m.n_outside, wide(m.max_penetration),
                 m.ill_conditioned, m.low_mass_nodes, m.held_at_wall, wide(m.max_cfl))
            }))
        })?;
        {
            let (step, time, kinetic_energy, n_outside, max_penetration, ill, low, held, cfl) = m;
            d.set_item("step", step)?;
            d.set_item("time", time)?;
            d.set_item("kinetic_energy", kinetic_energy)?;
            d.set_item("n_outside", n_outside)?;
            d.set_item("max_penetration", max_penetration)?;
            d.set_item("ill_conditioned", ill)?;
            d.set_item("low_mass_nodes", low)?;
            d.set_item("held_at_wall", held)?;
            d.set_item("max_cfl", cfl)?;
        }
        Ok(d)
    }
}

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
    m.add_class::<PySimulation>()?;
    m.add_class::<grid::PyGrid>()?;
    errors::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
