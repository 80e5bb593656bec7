//! Scenes: the schema every scene key is declared in, and the checks that need no geometry.

use pyo3::prelude::*;

use crate::errors::{guard, scene_error};

/// The JSON Schema of scene files (JSON text): each key's type, doc line (`description`), default,
/// range and `unit`. The Python package builds its scene models from it.
#[pyfunction]
pub fn scene_schema() -> String {
    augmpm_core::Scene::schema().to_string()
}

/// Checks a resolved scene (JSON) as the engine does before building it: every key against the
/// schema, then the rules between keys (one of `time.dt` and `time.cfl`, whole cells, ...); raises
/// `SceneError` naming the key.
#[pyfunction]
pub fn check_scene(scene_json: &str) -> PyResult<()> {
    guard(|| {
        let value: serde_json::Value =
            serde_json::from_str(scene_json).map_err(|e| scene_error("scene", &format!("not valid JSON: {e}")))?;
        let checked = if crate::simulation::is_3d(&value) {
            augmpm_core::scene3::Scene3::from_json(scene_json).map(drop)
        } else {
            augmpm_core::Scene::from_json(scene_json).map(drop)
        };
        checked.map_err(|e| scene_error(&e.key, &e.reason))
    })
}

/// The JSON Schema of 3D scene files (JSON text): the keys of `scene_schema()` with three-component
/// vectors, and the 3D walls and bodies.
#[pyfunction]
pub fn scene3_schema() -> String {
    augmpm_core::scene3::Scene3::schema().to_string()
}
