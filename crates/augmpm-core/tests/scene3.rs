//! 3D scenes: the keys of a 2D scene with three-component vectors and 3D walls and bodies, built into a
//! `Simulation<3>`; bad input is refused naming the key.

use augmpm_core::scene3::Scene3;
use augmpm_core::Method;

/// Water in a box container turned 0.4 rad about (1, 2, 0.5) (no face in a coordinate plane), with a
/// sphere obstacle above its floor; `extra` adds top-level keys.
fn tank(body: &str, walls_extra: &str) -> String {
    format!(
        r#"{{
        "name": "tank3",
        "gravity": [0.0, -9.81, 0.0],
        "grid": {{"domain": [1.0, 1.0, 1.0], "resolution": 16}},
        "time": {{"cfl": 0.4, "end": 0.3, "output_interval": 10}},
        "wall_condition": "slip",
        "walls": [
            {{"type": "box", "center": [0.5, 0.45, 0.5], "size": [0.6, 0.5, 0.6], "axis": [1.0, 2.0, 0.5], "angle": 0.4}},
            {{"type": "sphere", "center": [0.5, 0.3, 0.5], "radius": 0.08}}{walls_extra}
        ],
        "bodies": [{body}]
    }}"#
    )
}

const WATER: &str = r#"{"shape": "box", "min": [0.38, 0.45, 0.38], "max": [0.62, 0.62, 0.62],
    "material": {"type": "fluid", "density": 1000.0, "stiffness": 1e4, "viscosity": 1.0}}"#;

/// A 3D scene from JSON builds and runs with both methods: the water falls onto the sphere and the
/// tilted floor, and with the augmented grid no particle is past a wall at any of 30 checks over 0.3 s.
/// Its particles are seeded 8 per cell (2 per cell width along each axis) with the body's mass.
#[test]
fn a_3d_scene_builds_and_keeps_its_water_inside() {
    let scene = Scene3::from_json(&tank(WATER, "")).unwrap();
    for method in [Method::Naive, Method::Augmented] {
        let (mut sim, warnings) = scene.build(method).unwrap();
        assert!(warnings.is_empty());
        let p = sim.particles();
        let mass: f64 = p.mass.iter().sum();
        assert!((mass - 1000.0 * 0.24 * 0.17 * 0.24).abs() < 1e-9 * mass, "{mass} kg");
        let per_cell = p.len() as f64 / (0.24 * 0.17 * 0.24 * 16f64.powi(3));
        assert!((per_cell - 8.0).abs() < 0.5, "{per_cell} per cell");
        let steps = (0.01 / sim.model.dt).ceil() as u64;
        let mut most = 0;
        for _ in 0..30 {
            sim.advance(steps).unwrap();
            most = most.max(sim.metrics().n_outside);
        }
        if method == Method::Augmented {
            assert_eq!(most, 0);
        }
        assert!(sim.time() > 0.29);
    }
}

/// A plane, a cylinder and bodies of each shape build; a body reaching past a wall is refused unless it
/// is `fill`ed, and then only its part inside the walls is seeded, each particle with the mass and volume
/// of its own part of the body (the seeded mass is the density times the volume inside the walls, within
/// the sampling's error).
#[test]
fn every_wall_and_body_shape_builds() {
    let plane = r#", {"type": "plane", "point": [0.5, 0.25, 0.5], "normal": [0.1, 1.0, 0.0]},
        {"type": "cylinder", "center": [0.5, 0.5, 0.5], "axis": [0.0, 1.0, 0.0], "radius": 0.45, "length": 0.9, "side": "inside"}"#;
    let fluid = r#""material": {"type": "fluid", "density": 1000.0, "stiffness": 1e4, "viscosity": 1.0}"#;
    let bodies = format!(
        r#"{{"shape": "sphere", "center": [0.4, 0.55, 0.4], "radius": 0.06, {fluid}}},
           {{"shape": "cylinder", "center": [0.6, 0.55, 0.6], "axis": [1.0, 0.0, 0.0], "radius": 0.04, "length": 0.1, {fluid}}}"#
    );
    let (sim, _) = Scene3::from_json(&tank(&bodies, plane)).unwrap().build(Method::Augmented).unwrap();
    assert_eq!(sim.metrics().n_outside, 0);
    let overlapping = format!(r#"{{"shape": "sphere", "center": [0.5, 0.3, 0.5], "radius": 0.12, {fluid}}}"#);
    let Err(e) = Scene3::from_json(&tank(&overlapping, "")).unwrap().build(Method::Naive) else {
        panic!("a body past the sphere must be refused");
    };
    assert_eq!(e.key, "bodies[0]");
    let filled = overlapping.replace("\"radius\": 0.12,", "\"radius\": 0.12, \"fill\": true,");
    let (sim, _) = Scene3::from_json(&tank(&filled, "")).unwrap().build(Method::Naive).unwrap();
    assert_eq!(sim.metrics().n_outside, 0);
    let p = sim.particles();
    assert!(p.len() > 100);
    // The sphere of radius 0.12 less the obstacle sphere of radius 0.08 it holds (both about (0.5, 0.3, 0.5));
    // the container cuts off nothing of it.
    let inside = 4.0 / 3.0 * std::f64::consts::PI * (0.12f64.powi(3) - 0.08f64.powi(3));
    let mass: f64 = p.mass.iter().sum();
    let volume: f64 = p.vol0.iter().sum();
    // One particle a cube of h/2 (1/32 m): the part seeded differs from the exact volume by the cubes its
    // surfaces cut, a few per cent at this size (the particles per cell, 8, within 5%).
    assert!((mass / (1000.0 * inside) - 1.0).abs() < 0.05, "{mass} kg for {inside} m³");
    assert!((volume / inside - 1.0).abs() < 0.05, "{volume} m³ for {inside} m³");
}

/// Bad 3D scenes are refused naming the key: a 2D domain, a 2D wall type, a turning axis of zero
/// length, a height that is not a whole number of cells, a box body inside out, a friction on a slip
/// wall.
#[test]
fn bad_3d_scenes_are_refused_naming_the_key() {
    let cases = [
        (tank(WATER, "").replace("[1.0, 1.0, 1.0]", "[1.0, 1.0]"), "grid.domain"),
        (tank(WATER, r#", {"type": "polygon", "vertices": [[0, 0], [1, 0], [1, 1]]}"#), "walls[2]"),
        (tank(WATER, "").replace("\"axis\": [1.0, 2.0, 0.5]", "\"axis\": [0.0, 0.0, 0.0]"), "walls[0].axis"),
        (tank(WATER, "").replace("[1.0, 1.0, 1.0]", "[1.0, 1.03, 1.0]"), "grid.domain"),
        (tank(&WATER.replace("[0.62, 0.62, 0.62]", "[0.62, 0.40, 0.62]"), ""), "bodies[0].max"),
        (
            tank(WATER, r#", {"type": "sphere", "center": [0.5, 0.8, 0.5], "radius": 0.05, "friction": 0.3}"#),
            "walls[2].friction",
        ),
    ];
    for (json, key) in cases {
        let e = Scene3::from_json(&json).unwrap_err();
        assert!(e.key.starts_with(key), "{key}: got {e}");
    }
}
