//! The force each wall receives from the material (from the impulses the wall conditions apply), and
//! walls posed from outside between steps (`Simulation::set_wall_pose`).

use augmpm_core::motion::WallPose;
use augmpm_core::scene3::Scene3;
use augmpm_core::{Method, Scene, Simulation};

/// Water in a box tilted `angle` (rad) to the grid, slip walls, at rest under gravity.
fn tank(angle: f64, walls_json: Option<&str>) -> Scene {
    let (s, c) = angle.sin_cos();
    let (cx, cy, half) = (0.5, 0.45, 0.3);
    let corner = |u: f64, v: f64| format!("[{:.6}, {:.6}]", cx + c * u - s * v, cy + s * u + c * v);
    let polygon = format!(
        r#"{{"type": "polygon", "vertices": [{}, {}, {}, {}]}}"#,
        corner(-half, -half),
        corner(half, -half),
        corner(half, half),
        corner(-half, half)
    );
    let json = format!(
        r#"{{
        "gravity": [0.0, -9.81],
        "grid": {{"domain": [1.0, 1.0], "resolution": 40}},
        "time": {{"cfl": 0.5, "steps": 1, "output_interval": 1}},
        "wall_condition": "slip",
        "walls": [{}],
        "bodies": [{{"shape": "circle", "center": [0.5, 0.33], "radius": 0.13,
                    "material": {{"type": "fluid", "density": 1000.0, "stiffness": 2e4, "viscosity": 2.0}}}}]
    }}"#,
        walls_json.unwrap_or(&polygon)
    );
    Scene::from_json(&json).expect("scene parses")
}

/// The impulse (N·s/m) of wall 0 and the domain box, summed, at the current state.
fn total_impulse(sim: &Simulation<2>) -> [f64; 2] {
    sim.wall_impulse().iter().fold([0.0, 0.0], |a, i| [a[0] + i.x, a[1] + i.y])
}

/// Momentum balance: the material's momentum changes by what gravity and the walls give it, so over
/// 0.2 s the walls' impulses close the balance to 1e-3 of gravity's (to round-off for the naive walls,
/// whose transfers are each other's transpose); and water settled in a tilted tank (3 s, slip walls)
/// is held up by its walls: their mean upward force is its weight M g within 1%.
#[test]
fn walls_hold_up_the_weight_of_water_at_rest() {
    for method in [Method::Naive, Method::Augmented] {
        let (mut sim, _) = tank(0.35, None).build(method).unwrap();
        let dt = sim.model.dt;
        sim.advance((3.0 / dt) as u64).unwrap();
        let (before, t0, p0) = (total_impulse(&sim), sim.time(), sim.particles().momentum());
        sim.advance((0.2 / dt) as u64).unwrap();
        let (after, t1, p1) = (total_impulse(&sim), sim.time(), sim.particles().momentum());
        let weight = sim.particles().mass.iter().sum::<f64>() * 9.81;
        let gravity = weight * (t1 - t0);
        let tolerance = if method == Method::Naive { 1e-9 } else { 1e-3 };
        for k in 0..2 {
            let residual = (p1[k] - p0[k]) - (after[k] - before[k]) + if k == 1 { gravity } else { 0.0 };
            assert!(residual.abs() < tolerance * gravity, "{method:?}: axis {k} misses {residual} N·s/m");
        }
        let up = (after[1] - before[1]) / (t1 - t0);
        assert!((up - weight).abs() < 0.01 * weight, "{method:?}: up {up} N/m vs weight {weight} N/m");
        // The box never touched the water.
        let box_impulse = sim.wall_impulse()[1];
        assert!(box_impulse.norm() == 0.0, "{method:?}: the domain box gave {box_impulse}");
    }
}

/// A wall posed from outside with a velocity moves as the same constant motion from the scene: the
/// same particles within 1e-9 m after 0.1 s (the two paths differ by rounding).
#[test]
fn a_posed_wall_moves_like_a_scene_motion() {
    let box_json = |motion: &str| {
        format!(r#"{{"type": "polygon", "vertices": [[0.2, 0.15], [0.8, 0.15], [0.8, 0.75], [0.2, 0.75]]{motion}}}"#)
    };
    let scripted = tank(0.0, Some(&box_json(""))).build(Method::Augmented).unwrap().0;
    let moving = box_json(r#", "motion": {"type": "constant", "velocity": [0.1, 0.05], "angular_velocity": 0.2}"#);
    let (reference, _) = tank(0.0, Some(&moving)).build(Method::Augmented).unwrap();
    let mut sim = scripted;
    // The scene's dt accounts for the scene motion; the posed run must take the same step.
    sim.model.dt = reference.model.dt;
    let pose = WallPose::planar(0.0, [0.0, 0.0], 0.0, [0.1, 0.05], 0.2);
    sim.set_wall_pose(0, pose).unwrap();
    moves_alike(sim, reference);
}

/// Advances both 0.1 s: the same particles within 1e-9 m, none outside the walls.
fn moves_alike<const D: usize>(mut sim: Simulation<D>, mut reference: Simulation<D>)
where
    augmpm_core::math::Dim<D>: augmpm_core::math::DimOps<D>,
{
    let steps = (0.1 / reference.model.dt) as u64;
    sim.advance(steps).unwrap();
    reference.advance(steps).unwrap();
    let gap = sim.particles().x.iter().zip(&reference.particles().x).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    assert!(gap < 1e-9, "{gap} m");
    assert_eq!(sim.metrics().n_outside, 0);
}

/// A posed wall is part of the state: a simulation restored from a state taken after `set_wall_pose`
/// continues bitwise identically, and one restored from a state before it puts the wall back.
#[test]
fn posed_walls_are_part_of_the_state() {
    let (mut sim, _) = tank(0.2, None).build(Method::Augmented).unwrap();
    sim.advance(20).unwrap();
    let before = sim.state();
    let pose = WallPose::planar(0.0, [0.001, 0.0], 0.002, [0.05, 0.0], 0.1);
    sim.set_wall_pose(0, pose).unwrap();
    sim.advance(5).unwrap();
    let saved = sim.state();
    sim.advance(30).unwrap();
    let (mut resumed, _) = tank(0.2, None).build(Method::Augmented).unwrap();
    resumed.restore(saved).unwrap();
    resumed.advance(30).unwrap();
    assert_eq!(resumed.state(), sim.state());
    // Back to before the pose: the wall is where the scene draws it again.
    let (mut fresh, _) = tank(0.2, None).build(Method::Augmented).unwrap();
    fresh.advance(20).unwrap();
    sim.restore(before).unwrap();
    sim.advance(10).unwrap();
    fresh.advance(10).unwrap();
    assert_eq!(fresh.state(), sim.state());
}

/// Bad poses are refused, naming the argument, and change nothing: a wall that does not exist, a jump
/// of more than a cell, a velocity of more than a cell per step, a non-finite number.
#[test]
fn bad_poses_are_refused() {
    let (mut sim, _) = tank(0.0, None).build(Method::Augmented).unwrap();
    let still = WallPose::planar(0.0, [0.0, 0.0], 0.0, [0.0, 0.0], 0.0);
    let state = sim.state();
    assert_eq!(sim.set_wall_pose(1, still).unwrap_err().0, "wall");
    assert_eq!(sim.set_wall_pose(0, WallPose { position: [0.1, 0.0], ..still }).unwrap_err().0, "position");
    assert_eq!(sim.set_wall_pose(0, WallPose { velocity: [1e3, 0.0], ..still }).unwrap_err().0, "velocity");
    assert_eq!(sim.set_wall_pose(0, WallPose { angle: [0.0, 0.0, f64::NAN], ..still }).unwrap_err().0, "angle");
    assert_eq!(sim.set_wall_pose(0, WallPose { angle: [0.1, 0.0, 0.0], ..still }).unwrap_err().0, "angle");
    assert_eq!(sim.state(), state);
}

/// Water in a 3D box tank turned about (1, 0.2, 0.6), slip walls; `wall` is the tank (JSON) or the
/// tank drawn as a box at the domain's centre.
fn tank3(wall: Option<&str>) -> Scene3 {
    let tank =
        r#"{"type": "box", "center": [0.5, 0.5, 0.5], "size": [0.6, 0.6, 0.6], "axis": [1.0, 0.2, 0.6], "angle": 0.3"#;
    let json = format!(
        r#"{{
        "gravity": [0.0, -9.81, 0.0],
        "grid": {{"domain": [1.0, 1.0, 1.0], "resolution": 16}},
        "time": {{"cfl": 0.5, "steps": 1, "output_interval": 1}},
        "wall_condition": "slip",
        "walls": [{}, {{"type": "plane", "point": [0.5, 0.05, 0.5], "normal": [0.0, 1.0, 0.0]}}],
        "bodies": [{{"shape": "sphere", "center": [0.5, 0.45, 0.5], "radius": 0.15,
                    "material": {{"type": "fluid", "density": 1000.0, "stiffness": 2e4, "viscosity": 2.0}}}}]
    }}"#,
        wall.map_or(format!("{tank}}}"), |w| format!("{tank}, {w}}}"))
    );
    Scene3::from_json(&json).expect("scene parses")
}

/// In 3D, a wall posed from outside with a velocity and a rotation vector moves as the same constant
/// motion from the scene: the same particles within 1e-9 m after 0.1 s.
#[test]
fn a_posed_3d_wall_moves_like_a_scene_motion() {
    let motion =
        r#""motion": {"type": "constant", "velocity": [0.1, 0.05, -0.03], "angular_velocity": [0.1, -0.2, 0.15]}"#;
    let (reference, _) = tank3(Some(motion)).build(Method::Augmented).unwrap();
    let (mut sim, _) = tank3(None).build(Method::Augmented).unwrap();
    sim.model.dt = reference.model.dt;
    let pose = WallPose {
        time: 0.0,
        position: [0.0; 3],
        angle: [0.0; 3],
        velocity: [0.1, 0.05, -0.03],
        angular_velocity: [0.1, -0.2, 0.15],
    };
    sim.set_wall_pose(0, pose).unwrap();
    moves_alike(sim, reference);
}

/// A 3D posed wall is part of the state (a restored state continues bitwise identically, one from before
/// the pose puts the wall back), and bad 3D poses are refused naming the argument: a plane, a jump of
/// more than a cell, a non-finite turn.
#[test]
fn posed_3d_walls_are_part_of_the_state_and_bad_ones_are_refused() {
    let (mut sim, _) = tank3(None).build(Method::Augmented).unwrap();
    sim.advance(10).unwrap();
    let before = sim.state();
    let still = WallPose::<3> {
        time: 0.0,
        position: [0.0; 3],
        angle: [0.0; 3],
        velocity: [0.0; 3],
        angular_velocity: [0.0; 3],
    };
    assert_eq!(sim.set_wall_pose(1, still).unwrap_err().0, "wall");
    assert_eq!(sim.set_wall_pose(2, still).unwrap_err().0, "wall");
    assert_eq!(sim.set_wall_pose(0, WallPose { position: [0.0, 0.1, 0.0], ..still }).unwrap_err().0, "position");
    assert_eq!(sim.set_wall_pose(0, WallPose { angle: [0.0, 0.2, 0.0], ..still }).unwrap_err().0, "position");
    assert_eq!(
        sim.set_wall_pose(0, WallPose { angular_velocity: [0.0, f64::NAN, 0.0], ..still }).unwrap_err().0,
        "angular_velocity"
    );
    assert_eq!(sim.state(), before);
    let pose = WallPose {
        position: [0.002, 0.0, 0.001],
        angle: [0.0, 0.004, 0.0],
        velocity: [0.05, 0.0, 0.0],
        angular_velocity: [0.0, 0.1, 0.05],
        ..still
    };
    sim.set_wall_pose(0, pose).unwrap();
    sim.advance(5).unwrap();
    let saved = sim.state();
    sim.advance(20).unwrap();
    let (mut resumed, _) = tank3(None).build(Method::Augmented).unwrap();
    resumed.restore(saved).unwrap();
    resumed.advance(20).unwrap();
    assert_eq!(resumed.state(), sim.state());
    let (mut fresh, _) = tank3(None).build(Method::Augmented).unwrap();
    fresh.advance(10).unwrap();
    sim.restore(before).unwrap();
    sim.advance(10).unwrap();
    fresh.advance(10).unwrap();
    assert_eq!(fresh.state(), sim.state());
}

/// 3D momentum balance: with no gravity, a fluid ball thrown at an obstacle (a box turned about (1, 1, 0),
/// an axis-aligned box, a sphere) changes its momentum by exactly what the walls gave it, for both methods:
/// to round-off (1e-12 of the impulse). Near a box's edges and corners a particle sees more boundary
/// points than the step's table remembers (12); its weights are centred all the same, or its P2G and G2P
/// would not be each other's transpose (3–4% of the impulse went missing before they were).
#[test]
fn walls_account_for_the_momentum_the_material_loses_in_3d() {
    let obstacles = [
        r#"{"type": "box", "side": "outside", "center": [0.6, 0.5, 0.5], "size": [0.15, 0.2, 0.15], "axis": [1, 1, 0], "angle": 0.4}"#,
        r#"{"type": "box", "side": "outside", "center": [0.6, 0.5, 0.5], "size": [0.15, 0.2, 0.15]}"#,
        r#"{"type": "sphere", "center": [0.6, 0.5, 0.5], "radius": 0.1}"#,
    ];
    for obstacle in obstacles {
        let json = format!(
            r#"{{"grid": {{"domain": [1, 1, 1], "resolution": 16}}, "gravity": [0, 0, 0], "wall_condition": "slip",
            "time": {{"cfl": 0.4, "steps": 100, "output_interval": 100}},
            "walls": [{obstacle}],
            "bodies": [{{"shape": "sphere", "center": [0.3, 0.5, 0.5], "radius": 0.12, "velocity": [1.0, 0.2, 0.1],
                        "material": {{"type": "fluid", "density": 1000.0, "stiffness": 3e4, "viscosity": 1.0}}}}]}}"#
        );
        for method in [Method::Naive, Method::Augmented] {
            let (mut sim, _) = Scene3::from_json(&json).unwrap().build(method).unwrap();
            let p0 = sim.particles().momentum();
            sim.advance(100).unwrap();
            let impulse: nalgebra::Vector3<f64> = sim.wall_impulse().iter().sum();
            let residual = (sim.particles().momentum() - p0 - impulse).norm();
            assert!(impulse.norm() > 0.5, "{method:?}: the ball reached the obstacle ({impulse})");
            assert!(residual < 1e-12 * impulse.norm(), "{method:?} {obstacle}: {residual:e} N·s missing");
        }
    }
}
