//! Whole-step physics checks of the naive MLS-MPM engine on small scenes.

use augmpm_core::{Method, Scene, Simulation};

fn build(json: &str) -> Simulation<2> {
    let scene = Scene::from_json(json).expect("scene parses");
    scene.build(Method::Naive).expect("scene builds").0
}

fn centre_of_mass(sim: &Simulation<2>) -> nalgebra::Vector2<f64> {
    let p = &sim.state.particles;
    let m: f64 = p.mass.iter().sum();
    p.x.iter().zip(&p.mass).fold(nalgebra::Vector2::zeros(), |a, (x, mi)| a + x * *mi) / m
}

/// Free fall: an unstressed block far from every wall falls as y0 − g t²/2
/// (to the first-order error g·t·dt/2 of symplectic Euler, and exactly as its
/// discrete sum y0 − g dt² n(n+1)/2).
#[test]
fn free_fall_matches_g_t2_over_2() {
    let mut sim = build(
        r#"{"gravity": [0.0, -9.81], "grid": {"domain": [1.0, 1.0], "resolution": 32},
            "time": {"dt": 1e-3, "steps": 200, "output_interval": 10},
            "bodies": [{"shape": "box", "min": [0.4, 0.7], "max": [0.6, 0.9],
                        "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3}}]}"#,
    );
    let y0 = centre_of_mass(&sim).y;
    let n = 200u64;
    sim.advance(n).unwrap();
    let (g, dt, t) = (9.81, 1e-3, sim.time());
    let y = centre_of_mass(&sim).y;
    let discrete = y0 - g * dt * dt * (n * (n + 1)) as f64 / 2.0;
    assert!((y - discrete).abs() < 1e-10, "y = {y}, discrete = {discrete}");
    assert!((y - (y0 - g * t * t / 2.0)).abs() <= g * t * dt / 2.0 + 1e-10);
    // Uniform motion leaves the block undeformed.
    assert!(sim.state.particles.f.iter().all(|f| (f - nalgebra::Matrix2::identity()).norm() < 1e-10));
}

/// An elastic block on a sticky floor stays at rest: its static sag under its own
/// weight is ρ g H²/(2E) = 0.02 mm (0.001 h), so the centre of mass must stay within
/// 0.02 h of where it started and no particle may move faster than 1 cm/s.
#[test]
fn elastic_block_rests_on_floor() {
    let mut sim = build(
        r#"{"gravity": [0.0, -9.81], "grid": {"domain": [1.0, 1.0], "resolution": 32},
            "time": {"dt": 2e-4, "steps": 2000, "output_interval": 100},
            "bodies": [{"shape": "box", "min": [0.3, 0.0], "max": [0.7, 0.2],
                        "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e7, "poisson_ratio": 0.3}}]}"#,
    );
    let h = sim.model.layout.h;
    let c0 = centre_of_mass(&sim);
    sim.advance(2000).unwrap();
    let drift = (centre_of_mass(&sim) - c0).norm();
    let vmax = sim.state.particles.v.iter().map(|v| v.norm()).fold(0.0, f64::max);
    assert!(drift < 0.02 * h, "centre of mass moved {} h", drift / h);
    assert!(vmax < 1e-2, "max speed {vmax} m/s");
    assert_eq!(sim.metrics().n_outside, 0);
}

/// The same scene and seed give bitwise identical states.
#[test]
fn runs_are_reproducible() {
    let json = r#"{"seed": 3, "gravity": [0.0, -9.81], "grid": {"domain": [1.0, 1.0], "resolution": 32},
        "time": {"cfl": 0.3, "steps": 100, "output_interval": 10},
        "walls": [{"type": "polygon", "vertices": [[0.05, 0.3], [0.95, 0.05], [0.95, 0.95], [0.05, 0.95]]}],
        "bodies": [{"shape": "circle", "center": [0.5, 0.6], "radius": 0.15,
                    "material": {"type": "fluid", "density": 1000.0, "stiffness": 1e4, "viscosity": 1.0}}]}"#;
    let (mut a, mut b) = (build(json), build(json));
    a.advance(100).unwrap();
    b.advance(100).unwrap();
    assert_eq!(a.state.particles.x, b.state.particles.x);
    assert_eq!(a.state.particles.v, b.state.particles.v);
}
