//! `augmpm._core.Grid`: the background grid of a scene's walls, for MLS
//! reconstruction of given fields (the paper's Fig. 4 interpolation test), in 2D or 3D.

use augmpm_core::geometry::Region;
use augmpm_core::grid::GridLayout;
use augmpm_core::math::{Dim, DimOps};
use augmpm_core::scene3::Scene3;
use augmpm_core::{Boundary, Method, Scene, WallTreatment};
use nalgebra::SVector;
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;

use crate::convert::{parse_method, rows, vectors_to_array};
use crate::errors::{guard, scene_error};
use crate::simulation::is_3d;

/// Reconstructed values (M,) and gradients (M, D).
type ValuesAndGradients<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// The grid, walls and boundary treatment of one dimension.
struct Walled<const D: usize> {
    layout: GridLayout<D>,
    region: Box<dyn Region<D>>,
    boundary: Boundary<D>,
}

impl<const D: usize> Walled<D>
where
    Dim<D>: DimOps<D>,
{
    fn nodes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let xs: Vec<SVector<f64, D>> = (0..self.layout.num_nodes()).map(|i| self.layout.position(i)).collect();
        vectors_to_array(py, &xs)
    }

    fn included<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        PyArray1::from_iter(py, (0..self.layout.num_nodes()).map(|i| self.boundary.includes(i)))
    }

    fn boundary_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let xs: Vec<SVector<f64, D>> = self.boundary.boundary_points().iter().map(|p| p.x).collect();
        vectors_to_array(py, &xs)
    }

    fn wall_distance<'py>(
        &self,
        py: Python<'py>,
        points: &PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let pts = rows::<D>(points)?;
        Ok(PyArray1::from_vec(py, pts.iter().map(|x| self.region.distance(x).distance).collect()))
    }

    fn interpolate<'py>(
        &self,
        py: Python<'py>,
        values: &PyReadonlyArray1<'py, f64>,
        query: &PyReadonlyArray2<'py, f64>,
    ) -> PyResult<ValuesAndGradients<'py>> {
        let values = values.as_slice().map_err(|_| scene_error("values", "must be a contiguous float64 array"))?;
        let expected = self.boundary.num_points(&self.layout);
        if values.len() != expected {
            return Err(scene_error(
                "values",
                &format!("must hold one entry per node and boundary point ({expected}), got {}", values.len()),
            ));
        }
        let pts = rows::<D>(query)?;
        let nan = (f64::NAN, SVector::<f64, D>::repeat(f64::NAN));
        let out: Vec<(f64, SVector<f64, D>)> = pts
            .iter()
            .map(|x| {
                self.boundary
                    .interpolate::<Dim<D>>(&self.layout, x, values)
                    .map(|(u, grad, _)| (u, grad))
                    .unwrap_or(nan)
            })
            .collect();
        let u = PyArray1::from_iter(py, out.iter().map(|o| o.0));
        let grads: Vec<SVector<f64, D>> = out.iter().map(|o| o.1).collect();
        Ok((u, vectors_to_array(py, &grads)?))
    }
}

enum Inner {
    D2(Walled<2>),
    D3(Walled<3>),
}

/// Grid nodes, boundary points and MLS reconstruction for one boundary method; 3D where the scene's
/// `grid.domain` has three components (arrays (N, 3) then).
#[pyclass(name = "Grid", module = "augmpm._core")]
pub struct PyGrid {
    inner: Inner,
}

macro_rules! each {
    ($self:expr, $g:ident => $body:expr) => {
        match &$self.inner {
            Inner::D2($g) => $body,
            Inner::D3($g) => $body,
        }
    };
}

fn build(scene_json: &str, method: Method) -> PyResult<Inner> {
    let value: serde_json::Value =
        serde_json::from_str(scene_json).map_err(|e| scene_error("scene", &format!("not valid JSON: {e}")))?;
    if is_3d(&value) {
        let scene = Scene3::from_json(scene_json).map_err(|e| scene_error(&e.key, &e.reason))?;
        let (layout, region, boundary) = scene.build_walls(method).map_err(|e| scene_error(&e.key, &e.reason))?;
        Ok(Inner::D3(Walled { layout, region: Box::new(region), boundary }))
    } else {
        let scene = Scene::from_json(scene_json).map_err(|e| scene_error(&e.key, &e.reason))?;
        let (layout, region, boundary) = scene.build_walls(method).map_err(|e| scene_error(&e.key, &e.reason))?;
        Ok(Inner::D2(Walled { layout, region: Box::new(region), boundary }))
    }
}

#[pymethods]
impl PyGrid {
    #[new]
    fn new(scene_json: &str, method: &str) -> PyResult<Self> {
        guard(|| Ok(Self { inner: build(scene_json, parse_method(method)?)? }))
    }

    /// 2 or 3.
    #[getter]
    fn dim(&self) -> usize {
        match self.inner {
            Inner::D2(_) => 2,
            Inner::D3(_) => 3,
        }
    }

    /// Positions (m) of the regular nodes, ghosts included, shape (N, D).
    #[getter]
    fn nodes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        guard(|| each!(self, g => g.nodes(py)))
    }

    /// Whether each regular node takes part in the interpolation, shape (N,).
    #[getter]
    fn included<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<bool>> {
        each!(self, g => g.included(py))
    }

    /// Boundary points (m), shape (B, D); empty for the naive method.
    #[getter]
    fn boundary_points<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        each!(self, g => g.boundary_points(py))
    }

    /// Signed distance (m) of points (M, D) to the walls, positive outside the material.
    fn wall_distance<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        guard(|| each!(self, g => g.wall_distance(py, &points)))
    }

    /// MLS reconstruction at `query` (M, D) of a field given at the grid points: `values`
    /// holds one value per node followed by one per boundary point. Returns the values (M,)
    /// and gradients (M, D); NaN where the query's stencil leaves the grid.
    fn interpolate<'py>(
        &self,
        py: Python<'py>,
        values: PyReadonlyArray1<'py, f64>,
        query: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<ValuesAndGradients<'py>> {
        guard(|| each!(self, g => g.interpolate(py, &values, &query)))
    }
}
