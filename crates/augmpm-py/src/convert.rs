//! Conversions between the engine's values and numpy arrays, for any dimension D and either
//! precision: arrays reaching Python are float64 (exact for f32 too), those coming in are checked
//! for their dtype and shape, naming the key.

use augmpm_core::Method;
use nalgebra::SVector;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::scene_error;

/// A value of either precision as f64 (generic, so the f64 case is no conversion at all).
pub fn wide<R: Into<f64>>(x: R) -> f64 {
    x.into()
}

/// Parses a boundary method name.
pub fn parse_method(method: &str) -> PyResult<Method> {
    match method {
        "naive" => Ok(Method::Naive),
        "augmented" => Ok(Method::Augmented),
        other => Err(scene_error("method", &format!("unknown method {other:?}; expected \"naive\" or \"augmented\""))),
    }
}

/// Points of an (M, D) array.
pub fn rows<const D: usize>(a: &PyReadonlyArray2<'_, f64>) -> PyResult<Vec<SVector<f64, D>>> {
    let a = a.as_array();
    if a.ncols() != D {
        return Err(scene_error("points", &format!("must have shape (M, {D}), got {:?}", a.shape())));
    }
    Ok(a.rows().into_iter().map(|r| SVector::<f64, D>::from_fn(|i, _| r[i])).collect())
}

/// As [`rows`], with D that of `_like` (vectors of a simulation of either precision).
pub fn rows_like<T: nalgebra::Scalar, const D: usize>(
    _like: &[SVector<T, D>],
    a: &PyReadonlyArray2<'_, f64>,
) -> PyResult<Vec<SVector<f64, D>>> {
    rows::<D>(a)
}

/// An (N, D) float64 array of vectors of either precision.
pub fn vectors_to_array<'py, R: nalgebra::Scalar + Copy + Into<f64>, const D: usize>(
    py: Python<'py>,
    v: &[SVector<R, D>],
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = v.iter().flat_map(|x| x.iter().map(|&c| wide(c)).collect::<Vec<_>>()).collect();
    PyArray1::from_vec(py, flat).reshape([v.len(), D])
}

/// An (N,) float64 array of scalars of either precision.
pub fn scalars_to_array<'py, R: Copy + Into<f64>>(py: Python<'py>, v: &[R]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_iter(py, v.iter().map(|&x| wide(x)))
}

/// The array `key` of `dict`, of dtype `T` (`dtype` names it) and shape `[n] + tail`, flattened.
pub fn array_of<T: numpy::Element + Copy>(
    dict: &Bound<'_, PyDict>,
    key: &str,
    n: usize,
    tail: &[usize],
    dtype: &str,
) -> PyResult<Vec<T>> {
    let bad = |reason: String| scene_error(&format!("state.{key}"), &reason);
    let item = dict.get_item(key)?.ok_or_else(|| bad("missing".to_string()))?;
    let array: PyReadonlyArrayDyn<'_, T> = item.extract().map_err(|_| bad(format!("must be a {dtype} numpy array")))?;
    let shape: Vec<usize> = std::iter::once(n).chain(tail.iter().copied()).collect();
    if array.shape() != shape.as_slice() {
        return Err(bad(format!("must have shape {shape:?}, got {:?}", array.shape())));
    }
    Ok(array.as_array().iter().copied().collect())
}

/// The length of the first axis of the array `key` of `dict`, of dtype `T`.
pub fn rows_of<T: numpy::Element>(dict: &Bound<'_, PyDict>, key: &str, dtype: &str) -> PyResult<usize> {
    let bad = |reason: &str| scene_error(&format!("state.{key}"), reason);
    let item = dict.get_item(key)?.ok_or_else(|| bad("missing"))?;
    let array: PyReadonlyArrayDyn<'_, T> =
        item.extract().map_err(|_| bad(&format!("must be a {dtype} numpy array")))?;
    Ok(array.shape().first().copied().unwrap_or(0))
}
