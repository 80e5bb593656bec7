//! `augmpm._core.Simulation`: a 2D or 3D simulation built from a resolved scene (JSON; 3D when
//! `grid.domain` has three components), in the scene's precision; steps, arrays of the particles,
//! metrics, checkpoints.

use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::checkpoint;
use crate::convert::{parse_method, rows_like, scalars_to_array, vectors_to_array, wide};
use crate::errors::{self, guard, scene_error, simulation_error};

/// The engine of a simulation, in the scene's precision and dimension: the same core sources compiled
/// with `Real = f64` (`augmpm-core`) or `Real = f32` (`augmpm-core-f32`), for D = 2 or 3.
enum Engine {
    F64(augmpm_core::Simulation<2>),
    F32(augmpm_core_f32::Simulation<2>),
    F64D3(augmpm_core::Simulation<3>),
    F32D3(augmpm_core_f32::Simulation<3>),
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
            Engine::F64D3($s) => {
                #[allow(unused_imports)]
                use augmpm_core as $core;
                $body
            }
            Engine::F32D3($s) => {
                #[allow(unused_imports)]
                use augmpm_core_f32 as $core;
                $body
            }
        }
    };
}

/// Whether a scene (JSON value) is 3D: its `grid.domain` has three components.
pub fn is_3d(value: &serde_json::Value) -> bool {
    value.pointer("/grid/domain").and_then(|d| d.as_array()).is_some_and(|d| d.len() == 3)
}

/// A 2D simulation built from a resolved scene (JSON) with a boundary method.
#[pyclass(name = "Simulation", module = "augmpm._core")]
pub struct PySimulation {
    engine: Engine,
    warnings: Vec<String>,
    /// Set when a Rust panic interrupted a call: the state can no longer be trusted.
    broken: Option<String>,
}

impl PySimulation {
    fn build(scene_json: &str, method: &str, threads: usize, memory_limit: Option<u64>) -> PyResult<Self> {
        parse_method(method)?;
        let value: serde_json::Value =
            serde_json::from_str(scene_json).map_err(|e| scene_error("scene", &format!("not valid JSON: {e}")))?;
        let bad = |e: augmpm_core::SceneError| scene_error(&e.key, &e.reason);
        let bad32 = |e: augmpm_core_f32::SceneError| scene_error(&e.key, &e.reason);
        let f32 = value.get("precision").and_then(|p| p.as_str()) == Some("f32");
        let (engine, warnings) = match (f32, is_3d(&value)) {
            (false, true) => {
                let scene = augmpm_core::scene3::Scene3::from_json(scene_json).map_err(bad)?;
                if let Some(limit) = memory_limit {
                    scene.memory_estimate().and_then(|m| m.check(limit)).map_err(bad)?;
                }
                let (sim, warnings) = scene.build(parse_method(method)?).map_err(bad)?;
                (Engine::F64D3(sim), warnings)
            }
            (true, true) => {
                let scene = augmpm_core_f32::scene3::Scene3::from_json(scene_json).map_err(bad32)?;
                if let Some(limit) = memory_limit {
                    scene.memory_estimate().and_then(|m| m.check(limit)).map_err(bad32)?;
                }
                let method =
                    if method == "naive" { augmpm_core_f32::Method::Naive } else { augmpm_core_f32::Method::Augmented };
                let (sim, warnings) = scene.build(method).map_err(bad32)?;
                (Engine::F32D3(sim), warnings)
            }
            (true, false) => {
                let scene = augmpm_core_f32::Scene::from_json(scene_json).map_err(bad32)?;
                if let Some(limit) = memory_limit {
                    scene.memory_estimate().and_then(|m| m.check(limit)).map_err(bad32)?;
                }
                let method =
                    if method == "naive" { augmpm_core_f32::Method::Naive } else { augmpm_core_f32::Method::Augmented };
                let (sim, warnings) = scene.build(method).map_err(bad32)?;
                (Engine::F32(sim), warnings)
            }
            (false, false) => {
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

    /// The state of the run, for a checkpoint: a dict of numpy arrays (one per field of
    /// `state_fields()`; float64 reals in either precision, exact) and scalars, which
    /// [`PySimulation::restore`] takes back.
    fn checkpoint<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        self.guarded(|engine| match engine {
            Engine::F64(s) => checkpoint::double::to_dict(py, s.state()),
            Engine::F32(s) => checkpoint::single::to_dict(py, s.state()),
            Engine::F64D3(s) => checkpoint::double::to_dict(py, s.state()),
            Engine::F32D3(s) => checkpoint::single::to_dict(py, s.state()),
        })
    }

    /// Continues from a state returned by [`PySimulation::checkpoint`] of a simulation of the same
    /// scene and method; the steps that follow are bitwise identical to the saved run's. A state
    /// that does not fit raises SceneError naming the entry, and leaves the simulation as it was.
    fn restore(&mut self, state: &Bound<'_, PyDict>) -> PyResult<()> {
        self.guarded(|engine| {
            match engine {
                Engine::F64(s) => s.restore(checkpoint::double::from_dict(state)?),
                Engine::F32(s) => s.restore(checkpoint::single::from_dict(state)?),
                Engine::F64D3(s) => s.restore(checkpoint::double::from_dict(state)?),
                Engine::F32D3(s) => s.restore(checkpoint::single::from_dict(state)?),
            }
            .map_err(|e| scene_error("state", &e))
        })
    }

    /// Floating-point precision of the engine: "f32" or "f64".
    #[getter]
    fn precision(&self) -> &'static str {
        match self.engine {
            Engine::F64(_) | Engine::F64D3(_) => "f64",
            Engine::F32(_) | Engine::F32D3(_) => "f32",
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

    /// Particle positions (m), shape (N, D).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| with_sim!(&self.engine, s, core => vectors_to_array(py, &s.particles().x)))
    }

    /// Particle velocities (m/s), shape (N, D).
    #[getter]
    fn velocities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| with_sim!(&self.engine, s, core => vectors_to_array(py, &s.particles().v)))
    }

    /// Index of each particle's body, shape (N,).
    #[getter]
    fn body<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<i32>>> {
        guard(|| {
            Ok(
                with_sim!(&self.engine, s, core => PyArray1::from_iter(py, s.particles().body.iter().map(|&b| b as i32))),
            )
        })
    }

    /// Particle masses (kg/m in 2D), shape (N,).
    #[getter]
    fn masses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(|| Ok(with_sim!(&self.engine, s, core => scalars_to_array(py, &s.particles().mass))))
    }

    /// Fluid density of each particle in the last step (kg/m²), shape (N,): ρ0/J or gathered from the grid.
    #[getter]
    fn densities<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(|| Ok(with_sim!(&self.engine, s, core => scalars_to_array(py, s.grid_density()))))
    }

    /// Per-particle fields of the current state, for output: `stress`, each particle's Cauchy stress (N/m
    /// in 2D, Pa in 3D), shape (N, D, D); `J`, its volume ratio V/V⁰ (fluids ρ0/ρ, solids det F · J_p),
    /// and `plastic`, its plastic volume ratio J_p (snow; sand: its loose volume, ≥ 1; 1 for the other materials), shape (N,).
    fn particle_fields<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let dim = self.dim();
        guard(|| {
            let d = PyDict::new(py);
            with_sim!(&self.engine, s, core => {
                let fields = s.particle_fields();
                let n = fields.stress.len();
                // Row-major D×D per particle.
                let flat: Vec<f64> = fields
                    .stress
                    .iter()
                    .flat_map(|m| (0..m.nrows()).flat_map(move |i| (0..m.ncols()).map(move |j| wide(m[(i, j)]))))
                    .collect();
                let stress = PyArray1::from_vec(py, flat).reshape([n, dim, dim])?;
                d.set_item("stress", stress)?;
                d.set_item("J", scalars_to_array(py, &fields.volume_ratio))?;
                d.set_item("plastic", scalars_to_array(py, &fields.plastic))?;
            });
            Ok(d)
        })
    }

    #[getter]
    fn num_particles(&self) -> usize {
        with_sim!(&self.engine, s, core => s.particles().len())
    }

    /// Time (s).
    #[getter]
    fn time(&self) -> f64 {
        with_sim!(&self.engine, s, core => wide(s.time()))
    }

    /// Steps taken so far.
    #[getter]
    fn steps_done(&self) -> u64 {
        with_sim!(&self.engine, s, core => s.steps_done())
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

    /// Space dimension of the simulation: 2 or 3.
    #[getter]
    fn dim(&self) -> usize {
        match self.engine {
            Engine::F64(_) | Engine::F32(_) => 2,
            Engine::F64D3(_) | Engine::F32D3(_) => 3,
        }
    }

    /// Signed distance (m) of points (M, D) to the walls, positive outside the material region.
    fn wall_distance<'py>(
        &self,
        py: Python<'py>,
        points: numpy::PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(|| {
            let d: Vec<f64> = with_sim!(&self.engine, s, core => {
                let region = s.model.region.as_ref();
                rows_like(&s.particles().x, &points)?
                    .iter()
                    .map(|x| wide(region.distance(&x.cast::<core::math::Real>()).distance))
                    .collect()
            });
            Ok(PyArray1::from_vec(py, d))
        })
    }

    /// Boundary grid points of the augmented grid, shape (B, D); empty for the naive method.
    #[getter]
    fn boundary_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| {
            with_sim!(&self.engine, s, core => {
                use core::WallTreatment;
                let xs: Vec<_> = s.model.boundary.boundary_points().iter().map(|p| p.x).collect();
                vectors_to_array(py, &xs)
            })
        })
    }

    /// Points on the walls where they are now (the domain box's included), at most `spacing` (m) apart,
    /// shape (P, D): what a 3D frame draws of the walls, for either method.
    fn wall_points<'py>(&self, py: Python<'py>, spacing: f64) -> PyResult<Bound<'py, PyArray2<f64>>> {
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err(scene_error("spacing", &format!("must be a positive number, got {spacing}")));
        }
        guard(|| {
            with_sim!(&self.engine, s, core => {
                let spacing = (spacing as core::math::Real).max(s.model.layout.h * 0.25);
                let xs: Vec<_> = s.model.region.boundary_points(spacing).iter().map(|p| p.x).collect();
                vectors_to_array(py, &xs)
            })
        })
    }

    /// Each scene wall where it is now (moving walls follow their motion), as an (M, 2) array of the
    /// vertices of its closed outline (a circle as 64 points), and whether it moves.
    fn wall_outlines<'py>(&self, py: Python<'py>) -> PyResult<Vec<(Bound<'py, PyArray2<f64>>, bool)>> {
        guard(|| {
            with_sim!(&self.engine, s, core => {
                let region = s.model.region.as_ref();
                region
                    .outlines()
                    .iter()
                    .enumerate()
                    .map(|(i, outline)| Ok((vectors_to_array(py, outline)?, region.is_moving(i))))
                    .collect()
            })
        })
    }

    /// Sets scene wall `wall` where it is now: its pivot displaced by `position` (m, D numbers) from where
    /// the scene draws it, turned by `angle` (rad: one number in 2D, counter-clockwise; a rotation vector
    /// in 3D), moving from now on at `velocity` (m/s) and `angular_velocity` (rad/s, as `angle`) until set
    /// again. Raises SceneError naming the argument (a wall that does not exist or cannot move, a jump or
    /// a step of more than one cell, a non-finite number, a wrong count of numbers).
    fn set_wall_pose(
        &mut self,
        wall: usize,
        position: Vec<f64>,
        angle: Vec<f64>,
        velocity: Vec<f64>,
        angular_velocity: Vec<f64>,
    ) -> PyResult<()> {
        let dim = self.dim();
        let turns = if dim == 2 { 1 } else { 3 };
        for (key, numbers, count) in [
            ("position", &position, dim),
            ("angle", &angle, turns),
            ("velocity", &velocity, dim),
            ("angular_velocity", &angular_velocity, turns),
        ] {
            if numbers.len() != count {
                return Err(scene_error(key, &format!("must have {count} numbers in {dim}D, got {}", numbers.len())));
            }
        }
        let row: Vec<f64> = [&[0.0][..], &position, &angle, &velocity, &angular_velocity].concat();
        self.guarded(|engine| {
            with_sim!(engine, s, core => {
                let row: Vec<core::math::Real> = row.iter().map(|&a| a as core::math::Real).collect();
                s.set_wall_pose(wall, core::motion::WallPose::from_row(&row))
                    .map_err(|(key, reason)| scene_error(key, &reason))
            })
        })
    }

    /// The impulse (N·s per metre of depth in 2D, N·s in 3D) each scene wall has given the material since
    /// the start, shape (walls + 1, D), the domain box last; the force a wall receives is minus its rate.
    #[getter]
    fn wall_impulse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| with_sim!(&self.engine, s, core => vectors_to_array(py, s.wall_impulse())))
    }

    /// Each rigid body's state now, one row per body: in 2D `x, y, angle, vx, vy, angular_velocity` (its
    /// centre of mass (m), its turn from where the scene draws it (rad, counter-clockwise) and their rates);
    /// in 3D `x, y, z`, the turn as a rotation vector, the velocity and the angular velocity (12 columns).
    #[getter]
    fn rigid_bodies<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let dim = self.dim();
        guard(|| {
            with_sim!(&self.engine, s, core => {
                let rows = s.rigid_bodies();
                let turns = if dim == 2 { 2..3 } else { 0..3 };
                let mut flat = Vec::new();
                for (x, angle, v, w) in &rows {
                    flat.extend(x.iter().map(|&a| crate::convert::wide(a)));
                    flat.extend(angle[turns.clone()].iter().map(|&a| crate::convert::wide(a)));
                    flat.extend(v.iter().map(|&a| crate::convert::wide(a)));
                    flat.extend(w[turns.clone()].iter().map(|&a| crate::convert::wide(a)));
                }
                let columns = 2 * dim + 2 * turns.len();
                Ok(PyArray1::from_vec(py, flat).reshape([rows.len(), columns])?)
            })
        })
    }

    /// The moment about the origin of the impulse each scene wall has given the material since the start
    /// (N·m·s per metre of depth in 2D, N·m·s in 3D), shape (walls + 1,) in 2D (about z) and (walls + 1, 3)
    /// in 3D, the domain box last; the torque a wall receives is minus its rate.
    #[getter]
    fn wall_angular_impulse<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        guard(|| {
            with_sim!(&self.engine, s, core => {
                let rows = s.wall_angular_impulse();
                if self.dim() == 2 {
                    let z: Vec<f64> = rows.iter().map(|a| crate::convert::wide(a[2])).collect();
                    Ok(PyArray1::from_vec(py, z).into_any())
                } else {
                    vectors_to_array(py, rows).map(|a| a.into_any())
                }
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
