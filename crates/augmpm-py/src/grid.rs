//! `augmpm._core.Grid`: the background grid of a scene's walls, for MLS
//! reconstruction of given fields (the paper's Fig. 4 interpolation test).

use augmpm_core::geometry::Region;
use augmpm_core::grid::GridLayout;
use augmpm_core::math::Dim;
use augmpm_core::Scene;
use augmpm_core::{Boundary, WallTreatment};
use nalgebra::Vector2;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::convert::{parse_method, rows, vectors_to_array};
use crate::errors::{guard, scene_error};

/// Reconstructed values (M,) and gradients (M, 2).
type ValuesAndGradients<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// Grid nodes, boundary points and MLS reconstruction for one boundary method.
#[pyclass(name = "Grid", module = "augmpm._core")]
pub struct PyGrid {
    layout: GridLayout<2>,
    region: augmpm_core::geometry::Walls2,
    boundary: Boundary<2>,
}

#[pymethods]
impl PyGrid {
    #[new]
    fn new(scene_json: &str, method: &str) -> PyResult<Self> {
        guard(|| {
            let method = parse_method(method)?;
            let scene = Scene::from_json(scene_json).map_err(|e| scene_error(&e.key, &e.reason))?;
            let (layout, region, boundary) = scene.build_walls(method).map_err(|e| scene_error(&e.key, &e.reason))?;
            Ok(Self { layout, region, boundary })
        })
    }

    /// Positions (m) of the regular nodes, ghosts included, shape (N, 2).
    #[getter]
    fn nodes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| {
            let xs: Vec<Vector2<f64>> = (0..self.layout.num_nodes()).map(|i| self.layout.position(i)).collect();
            vectors_to_array(py, &xs)
        })
    }

    /// Whether each regular node takes part in the interpolation, shape (N,).
    #[getter]
    fn included<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        PyArray1::from_iter(py, (0..self.layout.num_nodes()).map(|i| self.boundary.includes(i)))
    }

    /// Boundary points (m), shape (B, 2); empty for the naive method.
    #[getter]
    fn boundary_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let xs: Vec<Vector2<f64>> = self.boundary.boundary_points().iter().map(|p| p.x).collect();
        vectors_to_array(py, &xs)
    }

    /// Signed distance (m) of points (M, 2) to the walls, positive outside the material.
    fn wall_distance<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let pts = rows::<2>(&points)?;
        guard(|| Ok(PyArray1::from_vec(py, pts.iter().map(|x| self.region.distance(x).distance).collect())))
    }

    /// MLS reconstruction at `query` (M, 2) of a field given at the grid points: `values`
    /// holds one value per node followed by one per boundary point. Returns the values (M,)
    /// and gradients (M, 2); NaN where the query's stencil leaves the grid.
    fn interpolate<'py>(
        &self,
        py: Python<'py>,
        values: PyReadonlyArray1<'py, f64>,
        query: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<ValuesAndGradients<'py>> {
        guard(|| self.interpolate_guarded(py, values, query))
    }
}

impl PyGrid {
    fn interpolate_guarded<'py>(
        &self,
        py: Python<'py>,
        values: PyReadonlyArray1<'py, f64>,
        query: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<ValuesAndGradients<'py>> {
        let values = values.as_slice().map_err(|_| scene_error("values", "must be a contiguous float64 array"))?;
        let expected = self.boundary.num_points(&self.layout);
        if values.len() != expected {
            return Err(scene_error(
                "values",
                &format!("must hold one entry per node and boundary point ({expected}), got {}", values.len()),
            ));
        }
        let pts = rows::<2>(&query)?;
        let nan = (f64::NAN, Vector2::repeat(f64::NAN));
        let out: Vec<(f64, Vector2<f64>)> = pts
            .iter()
            .map(|x| {
                self.boundary
                    .interpolate::<Dim<2>>(&self.layout, x, values)
                    .map(|(u, grad, _)| (u, grad))
                    .unwrap_or(nan)
            })
            .collect();
        let u = PyArray1::from_iter(py, out.iter().map(|o| o.0));
        let grads: Vec<Vector2<f64>> = out.iter().map(|o| o.1).collect();
        Ok((u, vectors_to_array(py, &grads)?))
    }
}
