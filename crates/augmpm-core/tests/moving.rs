//! Walls that move as rigid bodies: material inside a moving container goes with it and stays inside.

use augmpm_core::{Method, Scene, Simulation};

/// Water in a square container (tilted 20° to the grid) that `motion` moves.
fn container(motion: &str, steps: u64) -> Scene {
    let json = format!(
        r#"{{
        "gravity": [0.0, -9.81],
        "grid": {{"domain": [1.0, 1.0], "resolution": 48}},
        "time": {{"cfl": 0.4, "steps": {steps}, "output_interval": 50}},
        "wall_condition": "slip",
        "walls": [{{"type": "polygon",
                   "vertices": [[0.35, 0.2], [0.7064, 0.3297], [0.5767, 0.6861], [0.2203, 0.5564]],
                   "motion": {motion}}}],
        "bodies": [{{"shape": "circle", "center": [0.46, 0.42], "radius": 0.08,
                    "material": {{"type": "fluid", "density": 1000.0, "stiffness": 5e4, "viscosity": 0.1}}}}]
    }}"#
    );
    Scene::from_json(&json).expect("scene parses")
}

/// Runs `steps` steps, returning the most particles outside the walls at any of them and the mean
/// velocity (m/s) at the end.
fn run(sim: &mut Simulation<2>, steps: u64) -> (usize, [f64; 2]) {
    let mut most = 0;
    for _ in 0..steps {
        sim.advance(1).unwrap();
        most = most.max(sim.metrics().n_outside);
    }
    let p = sim.particles();
    let mass: f64 = p.mass.iter().sum();
    let v = p.momentum() / mass;
    (most, [v.x, v.y])
}

/// Galilean invariance: water given the velocity of a container carried at 0.3 m/s (to the upper right,
/// at 30°) falls and settles in it as in the same container standing still. After 0.3 s its mean
/// velocity relative to the container matches the still run's within 0.01 m/s (3% of the speed), no
/// particle is ever outside (augmented), and the walls are where the motion puts them.
#[test]
fn water_in_a_moving_container_behaves_as_in_a_still_one() {
    let carried = [0.2598, 0.15];
    let mut moving = container(r#"{"type": "constant", "velocity": [0.2598, 0.15]}"#, 0);
    moving.bodies[0].velocity = carried;
    let (mut sim, _) = moving.build(Method::Augmented).unwrap();
    let steps = (0.3 / sim.model.dt).round() as u64;
    let (outside, v) = run(&mut sim, steps);
    let still = container(r#"{"type": "constant"}"#, 0);
    let (mut reference, _) = still.build(Method::Augmented).unwrap();
    let (_, v0) = run(&mut reference, steps);
    assert_eq!(outside, 0);
    let relative = [v[0] - carried[0], v[1] - carried[1]];
    assert!((relative[0] - v0[0]).hypot(relative[1] - v0[1]) < 0.01, "{relative:?} vs still {v0:?}");
    // The walls went along: the first corner is now 0.3 s · 0.3 m/s up-right of where the scene drew it.
    let t = sim.time();
    let corner = nalgebra::Vector2::new(0.35 + carried[0] * t, 0.2 + carried[1] * t);
    assert!(sim.model.region.distance(&corner).distance.abs() < 1e-9);
}

/// A container that turns a quarter turn in a second (about its centre) and one shaken sideways at
/// 2 Hz by ±2 cm keep every particle inside (augmented), and checkpoints taken between steps resume
/// bitwise: the pose of the walls follows from the time.
#[test]
fn water_stays_in_a_turning_and_in_a_shaken_container() {
    for motion in [
        r#"{"type": "constant", "angular_velocity": 1.5708}"#,
        r#"{"type": "oscillation", "amplitude": [0.02, 0.0], "frequency": 2.0}"#,
    ] {
        let scene = container(motion, 0);
        let (mut sim, _) = scene.build(Method::Augmented).unwrap();
        let (outside, _) = run(&mut sim, 300);
        assert_eq!(outside, 0, "{motion}");
        let saved = sim.state();
        let (more, _) = run(&mut sim, 200);
        assert_eq!(more, 0, "{motion}");
        let (mut resumed, _) = scene.build(Method::Augmented).unwrap();
        resumed.restore(saved).unwrap();
        run(&mut resumed, 200);
        assert!(resumed.state() == sim.state(), "{motion}: resumed run differs");
    }
}

/// A wall that would move more than a cell in a step of `time.dt` is refused naming it; with
/// `time.cfl` the step shrinks so that it moves at most `cfl` cells.
#[test]
fn a_wall_may_move_at_most_a_cell_per_step() {
    let fast = r#"{"type": "constant", "velocity": [30.0, 0.0]}"#;
    let mut scene = container(fast, 0);
    scene.time.cfl = None;
    scene.time.dt = Some(1e-3);
    let err = scene.build(Method::Naive).err().unwrap();
    assert_eq!(err.key, "walls[0].motion");
    assert!(err.reason.contains("cells in a step"), "{}", err.reason);
    let (sim, _) = container(fast, 0).build(Method::Naive).unwrap();
    let h = 1.0 / 48.0;
    assert!(30.0 * sim.model.dt <= 0.4 * h * (1.0 + 1e-12), "dt = {}", sim.model.dt);
}
