//! Rigid bodies meeting each other, the scene's walls and their hinges (through rapier), with no material
//! in their way: the material of these scenes is a small elastic lump held by sticky walls far from the
//! bodies.

use augmpm_core::{Method, Scene, Simulation};

const G: f64 = 9.81;
/// The floor's tilt (rad): tan θ = 0.203.
const TILT: f64 = 0.2;

/// A tank on a 32-cell grid of the unit square whose floor falls by `TILT` to the right, from (0.05, 0.5);
/// an elastic lump stuck to the floor's high end; the `rigid` bodies (JSON), under `gravity`.
fn tank(rigid: &str, gravity: f64) -> Simulation<2> {
    let floor = |x: f64| 0.5 - (x - 0.05) * TILT.tan();
    let json = format!(
        r#"{{
        "gravity": [0.0, {gravity}],
        "grid": {{"domain": [1.0, 1.0], "resolution": 32}},
        "time": {{"cfl": 0.5, "end": 1.0, "output_interval": 1}},
        "wall_condition": "sticky",
        "walls": [{{"type": "polygon", "vertices": [[0.05, 0.5], [0.95, {}], [0.95, 0.95], [0.05, 0.95]]}}],
        "bodies": [{{"shape": "circle", "center": [0.12, {}], "radius": 0.03,
                    "material": {{"type": "elastic", "density": 1000.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3}}}}],
        "rigid_bodies": [{rigid}]
    }}"#,
        floor(0.95),
        floor(0.12) + 0.035,
    );
    let scene = Scene::from_json(&json).expect("scene parses");
    scene.build(Method::Augmented).expect("scene builds").0
}

/// The corners (JSON) of a square of side `side` (m) standing on the tilted floor, its base centred at
/// `x` (m) and lifted `gap` (m) off it.
fn square_on_floor(x: f64, side: f64, gap: f64) -> String {
    let floor = 0.5 - (x - 0.05) * TILT.tan();
    let (along, up) = ([TILT.cos(), -TILT.sin()], [TILT.sin(), TILT.cos()]);
    let corner = |u: f64, v: f64| {
        let (cx, cy) = (x + up[0] * (v + gap) + along[0] * u, floor + up[1] * (v + gap) + along[1] * u);
        format!("[{cx:.9}, {cy:.9}]")
    };
    let h = 0.5 * side;
    format!("[{}, {}, {}, {}]", corner(-h, 0.0), corner(h, 0.0), corner(h, side), corner(-h, side))
}

/// Runs `sim` to time `t` (s), calling `each` after every step.
fn run_to(sim: &mut Simulation<2>, t: f64, mut each: impl FnMut(&Simulation<2>)) {
    while sim.time() < t {
        sim.step().expect("step");
        each(sim);
    }
}

/// A block on an incline of angle θ slides down at a = g (sin θ − μ cos θ) when μ < tan θ, and stays when
/// μ > tan θ. On θ = 0.2 rad, to the step that passes 0.3 s (0.3003 s): without friction it travels
/// ½ g sin θ t² = 87.9 mm (within 2%:
/// the contact's softness and the step), never sinking into the floor by more than 2% of a cell (rapier
/// leaves 0.1% of its length unit, here a cell, uncorrected, and its contacts are springs); with μ = 0.5
/// it creeps less than 1 mm.
#[test]
fn a_block_slides_down_an_incline_as_its_friction_allows() {
    let h = 1.0 / 32.0;
    for (mu, factor, tolerance) in [(0.0, 1.0, 0.02 * 0.0877), (0.5, 0.0, 1e-3)] {
        let rigid = format!(
            r#"{{"shape": "polygon", "vertices": {}, "density": 500.0, "contact_friction": {mu}}}"#,
            square_on_floor(0.5, 0.1, 0.0)
        );
        let mut sim = tank(&rigid, -G);
        let start = sim.rigid_bodies()[0].0;
        let normal = nalgebra::Vector2::new(TILT.sin(), TILT.cos());
        let mut deepest: f64 = 0.0;
        run_to(&mut sim, 0.3, |sim| {
            // The centre's height above the floor, less half the side.
            let c = sim.rigid_bodies()[0].0;
            deepest = deepest.max(-((c - start).dot(&normal)));
        });
        // To the step that passes 0.3 s.
        let expected = factor * 0.5 * G * TILT.sin() * sim.time() * sim.time();
        let moved = sim.rigid_bodies()[0].0 - start;
        let along = moved.dot(&nalgebra::Vector2::new(TILT.cos(), -TILT.sin()));
        assert!((along - expected).abs() < tolerance, "μ = {mu}: slid {along:.5} m, expected {expected:.5} m");
        assert!(deepest < 0.02 * h, "μ = {mu}: sank {:.4} cells into the floor", deepest / h);
    }
}

/// Two equal disks meeting head-on with no gravity keep their total momentum to round-off; without
/// restitution they leave together at half the first one's speed (within 1%), with restitution 1 they
/// swap velocities (within 5%: rapier's restitution is not exact at a single contact step).
#[test]
fn colliding_bodies_keep_their_momentum() {
    for (e, after) in [(0.0, [0.5, 0.5]), (1.0, [0.0, 1.0])] {
        let disk = |x: f64, v: f64| {
            format!(
                r#"{{"shape": "circle", "center": [{x}, 0.75], "radius": 0.05, "density": 500.0,
                     "velocity": [{v}, 0.0], "restitution": {e}}}"#
            )
        };
        let mut sim = tank(&format!("{}, {}", disk(0.3, 1.0), disk(0.6, 0.0)), 0.0);
        let momentum = |sim: &Simulation<2>| sim.rigid_bodies().iter().map(|b| b.2).sum::<nalgebra::Vector2<f64>>();
        let p0 = momentum(&sim);
        let mut drift: f64 = 0.0;
        run_to(&mut sim, 0.25, |sim| drift = drift.max((momentum(sim) - p0).norm()));
        assert!(drift < 1e-12, "e = {e}: momentum changed by {drift:e} N·s/m per kg/m²");
        let v: Vec<f64> = sim.rigid_bodies().iter().map(|b| b.2.x).collect();
        let tolerance = if e == 0.0 { 0.01 } else { 0.05 };
        assert!((v[0] - after[0]).abs() < tolerance && (v[1] - after[1]).abs() < tolerance, "e = {e}: {v:?}");
    }
}

/// A body hinged at a point d from its centre of mass swings as a physical pendulum,
/// T = 2π √(I_h / (m g d)) with I_h = I_c + m d² (plus θ₀²/16 of it at amplitude θ₀ = 0.1 rad): the period
/// within 1%, and its centre stays d from the hinge within 1e-5 d (the joint is solved each step).
#[test]
fn a_hinged_body_swings_as_a_pendulum() {
    let (hinge, d, r, theta) = ([0.5, 0.85], 0.15, 0.04, 0.1_f64);
    let centre = [hinge[0] + d * theta.sin(), hinge[1] - d * theta.cos()];
    let rigid = format!(
        r#"{{"shape": "circle", "center": [{}, {}], "radius": {r}, "density": 500.0, "hinge": [{}, {}]}}"#,
        centre[0], centre[1], hinge[0], hinge[1]
    );
    let mut sim = tank(&rigid, -G);
    let (m, ic) = (500.0 * std::f64::consts::PI * r * r, 0.5 * 500.0 * std::f64::consts::PI * r.powi(4));
    let period = 2.0 * std::f64::consts::PI * ((ic + m * d * d) / (m * G * d)).sqrt() * (1.0 + theta * theta / 16.0);
    // The swing's turning points are where the angular velocity changes sign: the second is a period on.
    let (mut turns, mut last, mut worst): (Vec<f64>, f64, f64) = (Vec::new(), 0.0, 0.0);
    run_to(&mut sim, 1.2 * period, |sim| {
        let (c, _, _, w) = sim.rigid_bodies()[0];
        worst = worst.max(((c - nalgebra::Vector2::new(hinge[0], hinge[1])).norm() - d).abs());
        if last != 0.0 && w[2] * last < 0.0 {
            turns.push(sim.time());
        }
        last = w[2];
    });
    assert!(turns.len() >= 2, "turning points at {turns:?}");
    let measured = turns[1];
    assert!((measured / period - 1.0).abs() < 0.01, "period {measured:.4} s, expected {period:.4} s");
    assert!(worst < 1e-5 * d, "the centre strayed {worst:e} m from d = {d} m");
}

/// A 3D tank on a 16-cell grid of the unit cube: a plane floor through (0.5, 0.3, 0.5) tilted by `TILT`
/// about z (falling towards +x), an elastic lump stuck to its high end (sticky walls), the `rigid` bodies.
fn tank3(rigid: &str) -> augmpm_core::Simulation<3> {
    let n = [TILT.sin(), TILT.cos(), 0.0];
    let on_floor = |x: f64, lift: f64| [x + lift * n[0], 0.3 - (x - 0.5) * TILT.tan() + lift * n[1], 0.5];
    let lump = on_floor(0.15, 0.09);
    let json = format!(
        r#"{{
        "gravity": [0.0, {}, 0.0],
        "grid": {{"domain": [1.0, 1.0, 1.0], "resolution": 16}},
        "time": {{"cfl": 0.5, "end": 1.0, "output_interval": 1}},
        "wall_condition": "sticky",
        "walls": [{{"type": "plane", "point": [0.5, 0.3, 0.5], "normal": [{}, {}, 0.0]}}],
        "bodies": [{{"shape": "sphere", "center": [{}, {}, {}], "radius": 0.08,
                    "material": {{"type": "elastic", "density": 1000.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3}}}}],
        "rigid_bodies": [{rigid}]
    }}"#,
        -G, n[0], n[1], lump[0], lump[1], lump[2]
    );
    augmpm_core::scene3::Scene3::from_json(&json).expect("scene parses").build(Method::Augmented).expect("builds").0
}

/// A ball on an incline of angle θ slides at g sin θ without friction and rolls at 5/7 g sin θ with it
/// (its moment of inertia 2/5 m r²; μ = 0.5 holds it to rolling above tan θ · 2/7 = 0.058). Over 0.3 s
/// on θ = 0.2 rad, to the step that passes it (0.3017 s), it travels 88.7 mm and 63.3 mm (within 2%),
/// turning as it rolls (ω r = v within 2%),
/// and never sinks into the plane by more than 2% of a cell.
#[test]
fn a_ball_slides_or_rolls_down_a_3d_incline() {
    let (r, h) = (0.1, 1.0 / 16.0);
    let n = nalgebra::Vector3::new(TILT.sin(), TILT.cos(), 0.0);
    let down = nalgebra::Vector3::new(TILT.cos(), -TILT.sin(), 0.0);
    let centre = nalgebra::Vector3::new(0.5, 0.3, 0.5) + n * r;
    for (mu, factor) in [(0.0, 1.0), (0.5, 5.0 / 7.0)] {
        let rigid = format!(
            r#"{{"shape": "sphere", "center": [{}, {}, {}], "radius": {r}, "density": 800.0, "contact_friction": {mu}}}"#,
            centre.x, centre.y, centre.z
        );
        let mut sim = tank3(&rigid);
        let mut deepest: f64 = 0.0;
        while sim.time() < 0.3 {
            sim.step().expect("step");
            let c = sim.rigid_bodies()[0].0;
            deepest = deepest.max(-(c - centre).dot(&n));
        }
        let (c, _, v, w) = sim.rigid_bodies()[0];
        let expected = 0.5 * factor * G * TILT.sin() * sim.time() * sim.time();
        let along = (c - centre).dot(&down);
        assert!((along / expected - 1.0).abs() < 0.02, "μ = {mu}: {along:.5} m, expected {expected:.5} m");
        assert!(deepest < 0.02 * h, "μ = {mu}: sank {:.4} cells", deepest / h);
        let spin = nalgebra::Vector3::from(w).norm() * r;
        if mu > 0.0 {
            assert!((spin / v.norm() - 1.0).abs() < 0.02, "rolling: ω r = {spin:.4}, v = {:.4}", v.norm());
        } else {
            assert!(spin < 1e-9, "a frictionless ball does not turn: ω r = {spin:e}");
        }
    }
}

/// A ball hinged on an axis in no coordinate plane but square to gravity, (1, 0, 1)/√2, d from its
/// centre, swings as a physical pendulum: T = 2π √((2/5 m r² + m d²) / (m g d)) (plus θ₀²/16 of it at
/// θ₀ = 0.1 rad) within 1%, its centre d from the hinge within 1e-5 d.
#[test]
fn a_ball_on_a_3d_hinge_swings_as_a_pendulum() {
    let (hinge, d, r, theta) = (nalgebra::Vector3::new(0.5, 0.85, 0.5), 0.2, 0.05, 0.1_f64);
    let axis = nalgebra::Vector3::new(1.0, 0.0, 1.0).normalize();
    // Swung by θ₀ about the axis from straight below the hinge.
    let arm = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), theta)
        * nalgebra::Vector3::new(0.0, -d, 0.0);
    let c = hinge + arm;
    let rigid = format!(
        r#"{{"shape": "sphere", "center": [{}, {}, {}], "radius": {r}, "density": 800.0,
             "hinge": [{}, {}, {}], "hinge_axis": [1.0, 0.0, 1.0]}}"#,
        c.x, c.y, c.z, hinge.x, hinge.y, hinge.z
    );
    let mut sim = tank3(&rigid);
    let period = 2.0 * std::f64::consts::PI * ((0.4 * r * r + d * d) / (G * d)).sqrt() * (1.0 + theta * theta / 16.0);
    let (mut turns, mut last, mut worst): (Vec<f64>, f64, f64) = (Vec::new(), 0.0, 0.0);
    while sim.time() < 1.2 * period {
        sim.step().expect("step");
        let (c, _, _, w) = sim.rigid_bodies()[0];
        worst = worst.max(((c - hinge).norm() - d).abs());
        let spin = nalgebra::Vector3::from(w).dot(&axis);
        if last != 0.0 && spin * last < 0.0 {
            turns.push(sim.time());
        }
        last = spin;
    }
    assert!(turns.len() >= 2, "turning points at {turns:?}");
    assert!((turns[1] / period - 1.0).abs() < 0.01, "period {:.4} s, expected {period:.4} s", turns[1]);
    assert!(worst < 1e-5 * d, "the centre strayed {worst:e} m from d = {d} m");
}

/// Two bodies hinged to each other (`hinge_to`) and falling freely: the joint's forces are internal, so
/// their total momentum gains exactly M g t (to 1e-12 of it: round-off in rapier's equal and opposite
/// impulses); an ideal hinge does no work, so the motion about their common centre of mass keeps its
/// kinetic energy (within 1%: rapier's joint stabilisation takes 0.05%); and the hinge point of each stays
/// on the other's (within 1e-6 m, 3e-5 of a cell). The disk overlaps the square's corner: hinged bodies do
/// not meet in contacts, which would push them apart (and break the energy bound).
#[test]
fn two_hinged_bodies_fall_together_turning_about_their_hinge() {
    let (hinge, disk, r, w) = ([0.5, 0.8], [0.52, 0.78], 0.04, 6.0);
    // The disk turns about the hinge while the square is still: the hinge's two points move together.
    let v = [-w * (disk[1] - hinge[1]), w * (disk[0] - hinge[0])];
    let rigid = format!(
        r#"{{"shape": "polygon", "vertices": [[0.4, 0.8], [0.5, 0.8], [0.5, 0.9], [0.4, 0.9]], "density": 500.0}},
           {{"shape": "circle", "center": [{}, {}], "radius": {r}, "density": 800.0, "velocity": [{}, {}],
             "angular_velocity": {w}, "hinge": [{}, {}], "hinge_to": 0}}"#,
        disk[0], disk[1], v[0], v[1], hinge[0], hinge[1]
    );
    let mut sim = tank(&rigid, -G);
    let masses = [500.0 * 0.01, 800.0 * std::f64::consts::PI * r * r];
    let inertia = [masses[0] * 0.02 / 12.0, 0.5 * masses[1] * r * r];
    let drawn = [nalgebra::Vector2::new(0.45, 0.85), nalgebra::Vector2::new(disk[0], disk[1])];
    let total = masses[0] + masses[1];
    let state = |sim: &Simulation<2>| {
        let b = sim.rigid_bodies();
        let p: nalgebra::Vector2<f64> = (0..2).map(|k| b[k].2 * masses[k]).sum();
        let kinetic: f64 =
            (0..2).map(|k| 0.5 * (masses[k] * b[k].2.norm_squared() + inertia[k] * b[k].3[2].powi(2))).sum();
        // The hinge where each body carries it now.
        let at = |k: usize| {
            nalgebra::Rotation2::new(b[k].1[2]) * (nalgebra::Vector2::new(hinge[0], hinge[1]) - drawn[k]) + b[k].0
        };
        (p, kinetic - 0.5 * p.norm_squared() / total, (at(0) - at(1)).norm())
    };
    let (p0, relative0, _) = state(&sim);
    let (mut gap, mut energy): (f64, [f64; 2]) = (0.0, [relative0, relative0]);
    run_to(&mut sim, 0.15, |sim| {
        let (_, relative, apart) = state(sim);
        gap = gap.max(apart);
        energy = [energy[0].min(relative), energy[1].max(relative)];
    });
    let (p, _, _) = state(&sim);
    let gained = total * G * sim.time();
    let error = (p - p0 - nalgebra::Vector2::new(0.0, -gained)).norm();
    assert!(error < 1e-12 * gained, "momentum off M g t = {gained:e} N·s/m by {error:e}");
    assert!(
        energy[0] > 0.99 * relative0 && energy[1] < 1.01 * relative0,
        "kinetic energy about the centre of mass within {energy:?} J/m of {relative0:e} J/m"
    );
    assert!(gap < 1e-6, "the two hinge points came {gap:e} m apart");
}

/// The same in 3D: a ball hinged on an axis (0, 0, 1) to a box's corner edge, falling freely while it
/// turns about the hinge, overlapping the box's edge: the total momentum gains M g t (to 1e-12 of it), the
/// kinetic energy about the centre of mass holds within 1%, and the hinge point of each body stays on the
/// other's within 1e-6 m.
#[test]
fn two_hinged_3d_bodies_fall_together_turning_about_their_hinge() {
    let (hinge, ball, r, w) =
        (nalgebra::Vector3::new(0.55, 0.8, 0.5), nalgebra::Vector3::new(0.57, 0.78, 0.5), 0.04_f64, 6.0);
    let spin = nalgebra::Vector3::new(0.0, 0.0, w);
    let v = spin.cross(&(ball - hinge));
    let rigid = format!(
        r#"{{"shape": "box", "center": [0.5, 0.85, 0.5], "size": [0.1, 0.1, 0.1], "density": 500.0}},
           {{"shape": "sphere", "center": [{}, {}, {}], "radius": {r}, "density": 800.0, "velocity": [{}, {}, {}],
             "angular_velocity": [0.0, 0.0, {w}], "hinge": [{}, {}, {}], "hinge_axis": [0.0, 0.0, 1.0],
             "hinge_to": 0}}"#,
        ball.x, ball.y, ball.z, v.x, v.y, v.z, hinge.x, hinge.y, hinge.z
    );
    let mut sim = tank3(&rigid);
    let masses = [500.0 * 1e-3, 800.0 * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3)];
    let inertia = [masses[0] * 0.02 / 12.0, 0.4 * masses[1] * r * r];
    let drawn = [nalgebra::Vector3::new(0.5, 0.85, 0.5), ball];
    let total = masses[0] + masses[1];
    let state = |sim: &augmpm_core::Simulation<3>| {
        let b = sim.rigid_bodies();
        let p: nalgebra::Vector3<f64> = (0..2).map(|k| b[k].2 * masses[k]).sum();
        let kinetic: f64 = (0..2)
            .map(|k| {
                0.5 * (masses[k] * b[k].2.norm_squared() + inertia[k] * nalgebra::Vector3::from(b[k].3).norm_squared())
            })
            .sum();
        let at = |k: usize| nalgebra::Rotation3::new(nalgebra::Vector3::from(b[k].1)) * (hinge - drawn[k]) + b[k].0;
        (p, kinetic - 0.5 * p.norm_squared() / total, (at(0) - at(1)).norm())
    };
    let (p0, relative0, _) = state(&sim);
    let (mut gap, mut energy): (f64, [f64; 2]) = (0.0, [relative0, relative0]);
    while sim.time() < 0.15 {
        sim.step().expect("step");
        let (_, relative, apart) = state(&sim);
        gap = gap.max(apart);
        energy = [energy[0].min(relative), energy[1].max(relative)];
    }
    let (p, _, _) = state(&sim);
    let gained = total * G * sim.time();
    let error = (p - p0 - nalgebra::Vector3::new(0.0, -gained, 0.0)).norm();
    assert!(error < 1e-12 * gained, "momentum off M g t = {gained:e} N·s/m by {error:e}");
    assert!(
        energy[0] > 0.99 * relative0 && energy[1] < 1.01 * relative0,
        "kinetic energy about the centre of mass within {energy:?} J of {relative0:e} J"
    );
    assert!(gap < 1e-6, "the two hinge points came {gap:e} m apart");
}
