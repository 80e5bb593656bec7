//! Checkpoints: a simulation's [`State`](augmpm_core::State) as a dict of numpy arrays (one per
//! per-particle field of `State::fields`, float64 or uint32, shape (N, ...)) and scalars (one per
//! `State::scalars`), and back. The field table of the core drives both directions, for any D and
//! either precision. The walls' part of the state: `wall_impulse` (float64, (walls + 1, D): each wall's
//! impulse on the material so far, the domain box last), `wall_angular_impulse` (float64, (walls + 1, 3):
//! its moment about the origin; in 2D only z) and `wall_pose` (float64, (k, 8) in 2D, (k, 14)
//! in 3D: per wall posed from outside, its index and `WallPose::names`); a checkpoint without them
//! (written before they were kept) has no impulse counted and no posed wall. `body_kick` (float64,
//! (rigid bodies, D + 3)): per rigid body, the velocity change (m/s) and angular velocity change (rad/s;
//! 3 components, in 2D only z) the material sees it take ahead in the next step (`State::body_kicks`); a
//! checkpoint without it predicts none. `f` of a scene whose materials keep no deformation gradient (fluids
//! only: the engine then holds none) is every particle's identity, and restoring one checks that it is.
//! A particle's material is its body's (one material a body), so a checkpoint has no `material` array; an
//! older checkpoint's is not read.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::errors::scene_error;

/// The checkpoint's arrays, from the core's field table (2D): name, dtype, shape after the particle
/// axis, unit and doc line of each.
#[pyfunction]
pub fn state_fields(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let items = augmpm_core::State::<2>::fields()
        .map(|f| {
            let d = PyDict::new(py);
            d.set_item("name", f.name)?;
            let dtype = if f.kind == augmpm_core::particles::FieldKind::Index { "uint32" } else { "float64" };
            d.set_item("dtype", dtype)?;
            d.set_item("shape", f.kind.shape(2))?;
            d.set_item("unit", f.unit)?;
            d.set_item("doc", f.doc)?;
            d.set_item("optional", f.optional)?;
            Ok(d)
        })
        .collect::<PyResult<Vec<_>>>()?;
    PyList::new(py, items)
}

/// `to_dict` and `from_dict` for the state of one core crate (the f64 or the f32 engine).
macro_rules! state_conversions {
    ($name:ident, $core:ident) => {
        pub mod $name {
            use super::*;
            use crate::convert::{array_of, rows_of};
            use numpy::{PyArray1, PyArrayMethods};
            use $core::particles::{Column, ColumnMut};
            use $core::simulation::Scalar;
            use $core::State;

            /// The state as a dict: arrays by field name, then the scalars.
            pub fn to_dict<'py, const D: usize>(py: Python<'py>, mut state: State<D>) -> PyResult<Bound<'py, PyDict>> {
                let d = PyDict::new(py);
                let n = state.particles.len();
                for (field, column) in State::<D>::fields().zip(state.columns()) {
                    let mut shape = vec![n];
                    shape.extend(field.kind.shape(D));
                    // An optional column the model does not keep reads as every particle at rest (F = I); any
                    // other column has one entry per particle.
                    let reals = if field.optional { column.to_f64_rows(n) } else { column.to_f64() };
                    match (&column, reals) {
                        (Column::Index(a), _) => d.set_item(field.name, PyArray1::from_slice(py, a))?,
                        (_, Some(data)) => d.set_item(field.name, PyArray1::from_vec(py, data).reshape(shape)?)?,
                        (_, None) => unreachable!("only index columns have no reals"),
                    }
                }
                for (name, scalar) in state.scalars() {
                    match scalar {
                        Scalar::Count(v) => d.set_item(name, *v)?,
                        Scalar::Real(v) => d.set_item(name, crate::convert::wide(*v))?,
                    }
                }
                d.set_item("wall_impulse", crate::convert::vectors_to_array(py, &state.wall_impulse)?)?;
                d.set_item("wall_angular_impulse", crate::convert::vectors_to_array(py, &state.wall_angular_impulse)?)?;
                let poses: Vec<f64> = state
                    .wall_poses
                    .iter()
                    .flat_map(|(w, p)| {
                        std::iter::once(*w as f64).chain(p.to_row().into_iter().map(crate::convert::wide))
                    })
                    .collect();
                let columns = 1 + $core::motion::WallPose::<D>::names().len();
                d.set_item("wall_pose", PyArray1::from_vec(py, poses).reshape([state.wall_poses.len(), columns])?)?;
                let kicks: Vec<f64> = state
                    .body_kicks
                    .iter()
                    .flat_map(|(v, w)| v.iter().chain(w.iter()).map(|&a| crate::convert::wide(a)))
                    .collect();
                d.set_item("body_kick", PyArray1::from_vec(py, kicks).reshape([state.body_kicks.len(), D + 3])?)?;
                Ok(d)
            }

            /// The state a dict from [`to_dict`] holds; a missing entry, a wrong dtype or shape raises
            /// SceneError naming it (`state.v`).
            pub fn from_dict<const D: usize>(dict: &Bound<'_, PyDict>) -> PyResult<State<D>> {
                let n = rows_of::<f64>(dict, "x", "float64")?;
                let mut state = State::<D>::new(Default::default());
                for (field, mut column) in State::<D>::fields().zip(state.columns_mut()) {
                    let tail = field.kind.shape(D);
                    match &mut column {
                        ColumnMut::Index(_) => {
                            column.set_indices(&array_of::<u32>(dict, field.name, n, &tail, "uint32")?)
                        }
                        _ => column.set_f64(&array_of::<f64>(dict, field.name, n, &tail, "float64")?),
                    }
                }
                for (name, scalar) in state.scalars() {
                    let bad = |reason: &str| scene_error(&format!("state.{name}"), reason);
                    let item = dict.get_item(name)?.ok_or_else(|| bad("missing"))?;
                    match scalar {
                        Scalar::Count(v) => *v = item.extract().map_err(|_| bad("must be a non-negative integer"))?,
                        Scalar::Real(v) => {
                            *v = item.extract::<f64>().map_err(|_| bad("must be a number"))? as $core::math::Real
                        }
                    }
                }
                if dict.contains("wall_impulse")? {
                    let rows = rows_of::<f64>(dict, "wall_impulse", "float64")?;
                    let flat = array_of::<f64>(dict, "wall_impulse", rows, &[D], "float64")?;
                    state.wall_impulse = flat
                        .chunks(D)
                        .map(|c| $core::math::Vector::<D>::from_fn(|k, _| c[k] as $core::math::Real))
                        .collect();
                }
                if dict.contains("wall_angular_impulse")? {
                    let rows = rows_of::<f64>(dict, "wall_angular_impulse", "float64")?;
                    let flat = array_of::<f64>(dict, "wall_angular_impulse", rows, &[3], "float64")?;
                    state.wall_angular_impulse = flat
                        .chunks(3)
                        .map(|c| $core::math::Vector::<3>::from_fn(|k, _| c[k] as $core::math::Real))
                        .collect();
                }
                if dict.contains("body_kick")? {
                    let rows = rows_of::<f64>(dict, "body_kick", "float64")?;
                    let flat = array_of::<f64>(dict, "body_kick", rows, &[D + 3], "float64")?;
                    state.body_kicks = flat
                        .chunks(D + 3)
                        .map(|c| {
                            (
                                $core::math::Vector::<D>::from_fn(|k, _| c[k] as $core::math::Real),
                                $core::math::Vector::<3>::from_fn(|k, _| c[D + k] as $core::math::Real),
                            )
                        })
                        .collect();
                }
                if dict.contains("wall_pose")? {
                    let rows = rows_of::<f64>(dict, "wall_pose", "float64")?;
                    let columns = 1 + $core::motion::WallPose::<D>::names().len();
                    // No posed wall: an empty array of any width (3D checkpoints before 3D poses wrote (0, 8)).
                    let flat = if rows == 0 {
                        Vec::new()
                    } else {
                        array_of::<f64>(dict, "wall_pose", rows, &[columns], "float64")?
                    };
                    for row in flat.chunks(columns) {
                        let wall = row[0];
                        if !(wall >= 0.0 && wall.fract() == 0.0 && wall < u32::MAX as f64) {
                            return Err(scene_error("state.wall_pose", &format!("{wall} is not a wall index")));
                        }
                        let numbers: Vec<$core::math::Real> =
                            row[1..].iter().map(|&a| a as $core::math::Real).collect();
                        state.wall_poses.push((wall as usize, $core::motion::WallPose::from_row(&numbers)));
                    }
                }
                Ok(state)
            }
        }
    };
}

state_conversions!(double, augmpm_core);
state_conversions!(single, augmpm_core_f32);
