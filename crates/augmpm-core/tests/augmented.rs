//! The augmented grid reproduces linear fields exactly up to and along the walls,
//! which the naive grid (wall nodes holding the wall value) cannot.

use augmpm_core::geometry::{Point, Polygon, Region, WallShape, Walls2};
use augmpm_core::grid::GridLayout;
use augmpm_core::kernel::{MlsKind, Stencil};
use augmpm_core::math::Dim;
use augmpm_core::treatment::augmented::AugmentedGrid;
use augmpm_core::wall::WallCondition;
use proptest::prelude::*;

/// A container in the unit box whose floor rises at `angle` (rad) to the grid from (0.05, y0).
fn tilted_container(angle: f64, y0: f64) -> Walls2 {
    let y1 = y0 + 0.9 * angle.tan();
    let poly =
        Polygon::new(vec![Point::new(0.05, y0), Point::new(0.95, y1), Point::new(0.95, 0.95), Point::new(0.05, 0.95)]);
    Walls2::new(vec![WallShape::Polygon(poly)], Point::new(1.0, 1.0))
}

fn augmented(walls: &Walls2, layout: &GridLayout<2>, delta_cells: f64) -> AugmentedGrid<2> {
    AugmentedGrid::new(
        layout,
        walls,
        layout.h,
        vec![WallCondition::Sticky.into(); walls.walls.len() + 1],
        delta_cells * layout.h,
    )
}

/// Values of `f` at every grid point (nodes, then boundary points); NaN on excluded nodes, so
/// that a node wrongly taken into the interpolation poisons the result.
fn sample(grid: &AugmentedGrid<2>, layout: &GridLayout<2>, f: impl Fn(&Point) -> f64) -> Vec<f64> {
    (0..layout.num_nodes())
        .map(|i| if grid.included[i] { f(&layout.position(i)) } else { f64::NAN })
        .chain(grid.points.iter().map(|p| f(&p.x)))
        .collect()
}

/// The paper's container with δ = h/4 keeps 3,781 of the 6,561 nodes (shared/spec/paper-scenes.md).
#[test]
fn exclusion_matches_the_authors_count() {
    let poly = Polygon::new(vec![
        Point::new(0.047, 0.5),
        Point::new(0.953, 0.047),
        Point::new(0.953, 0.953),
        Point::new(0.047, 0.953),
    ]);
    let walls = Walls2::new(vec![WallShape::Polygon(poly)], Point::new(1.0, 1.0));
    let layout = GridLayout::new(1.0 / 80.0, [80, 80]);
    let grid = augmented(&walls, &layout, 0.25);
    assert_eq!(grid.included.iter().filter(|&&i| i).count(), 3781);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// For any wall angle and any point of the material region (on the wall, next to it, in a
    /// corner), the augmented MLS reconstruction of a linear field is exact to 1e-10 relative.
    #[test]
    fn augmented_reproduces_linear_fields(
        angle_deg in 0.0f64..40.0,
        y0 in 0.05f64..0.2,
        u in (0.0f64..1.0, 0.0f64..1.0),
        coef in (-3.0f64..3.0, -3.0f64..3.0, -3.0f64..3.0),
    ) {
        let walls = tilted_container(angle_deg.to_radians(), y0);
        let layout = GridLayout::new(1.0 / 32.0, [32, 32]);
        let grid = augmented(&walls, &layout, 0.25);
        let field = |x: &Point| coef.0 + coef.1 * x.x + coef.2 * x.y;
        let values = sample(&grid, &layout, field);
        // A point of the region: map u into the box and pull it inside the walls.
        let mut x = Point::new(0.05 + 0.9 * u.0, 0.05 + 0.9 * u.1);
        let d = walls.distance(&x);
        if d.distance > 0.0 {
            x -= d.normal * d.distance;
        }
        let (value, grad, kind) = grid.interpolate::<Dim<2>>(&layout, &x, &values).unwrap();
        prop_assert!(kind == MlsKind::General || kind == MlsKind::Regular);
        let scale = coef.0.abs() + coef.1.abs() + coef.2.abs() + 1e-3;
        prop_assert!((value - field(&x)).abs() <= 1e-10 * scale, "value {} vs {}", value, field(&x));
        prop_assert!((grad - Point::new(coef.1, coef.2)).norm() <= 1e-8 * scale, "gradient {}", grad);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// The per-cell index and the closed-form table find exactly the boundary points that a
    /// brute-force scan of all of them finds in the particle's B-spline support.
    #[test]
    fn index_finds_exactly_the_points_in_reach(
        angle_deg in 0.0f64..40.0,
        u in (0.0f64..1.0, 0.0f64..1.0),
    ) {
        let walls = tilted_container(angle_deg.to_radians(), 0.12);
        let layout = GridLayout::new(1.0 / 32.0, [32, 32]);
        let grid = augmented(&walls, &layout, 0.25);
        let x = Point::new(0.02 + 0.96 * u.0, 0.02 + 0.96 * u.1);
        let mut found = Vec::new();
        grid.for_each_point(&layout, &x, 0, |i, _, _| {
            if i >= layout.num_nodes() {
                found.push(i - layout.num_nodes());
            }
        })
        .unwrap();
        found.sort_unstable();
        let brute: Vec<usize> = (0..grid.points.len())
            .filter(|&b| augmpm_core::kernel::weight(&(grid.points[b].x - x), 1.0 / layout.h) > 0.0)
            .collect();
        prop_assert_eq!(found, brute);
    }
}

/// A particle pushed past the wall is counted as ill-conditioned in the run's metrics and the run
/// goes on (no panic, finite state).
#[test]
fn ill_conditioned_particles_are_counted_in_a_run() {
    let json = r#"{"gravity": [0.0, -9.81], "grid": {"domain": [1.0, 1.0], "resolution": 32},
        "time": {"dt": 1e-4, "steps": 10, "output_interval": 10},
        "walls": [{"type": "polygon", "vertices": [[0.05, 0.3], [0.95, 0.3], [0.95, 0.95], [0.05, 0.95]]}],
        "bodies": [{"shape": "box", "min": [0.3, 0.4], "max": [0.6, 0.6],
                    "material": {"type": "elastic", "density": 1000.0, "youngs_modulus": 1e5, "poisson_ratio": 0.3}}]}"#;
    let scene = augmpm_core::Scene::from_json(json).unwrap();
    let (mut sim, _) = scene.build(augmpm_core::Method::Augmented).unwrap();
    let h = sim.model.layout.h;
    sim.state.particles.x[0] = Point::new(0.5, 0.3 - 1.2 * h); // sees only the floor's boundary points
    sim.state.particles.x[1] = Point::new(0.5, 0.1); // deep in the wall: sees nothing
    sim.step().unwrap();
    let m = sim.metrics();
    assert_eq!(m.ill_conditioned, 2);
    assert_eq!(m.n_outside, 2);
    // Neither moves deeper: the sticky floor's points hold the first, the second has no points.
    assert!(sim.state.particles.v[0].y >= -1e-12 && sim.state.particles.v[1].y >= -1e-12);
    assert!(sim.state.particles.v.iter().all(|v| v.iter().all(|c| c.is_finite())));
}

/// No-slip: a Couette-like velocity u = U_wall + s·(distance from the wall) interpolates to exactly
/// the wall velocity at wall points, while the naive grid (wall nodes set to U_wall) is off by O(h).
#[test]
fn no_slip_wall_velocity_is_exact_and_naive_is_not() {
    let angle = 20f64.to_radians();
    let walls = tilted_container(angle, 0.1);
    let layout = GridLayout::new(1.0 / 40.0, [40, 40]);
    let grid = augmented(&walls, &layout, 0.25);
    let floor = (Point::new(0.05, 0.1), Point::new(angle.cos(), angle.sin()));
    let (u_wall, shear) = (1.5, 40.0);
    // Distance above the (infinite) floor line; exact linear field away from the other walls.
    let height = |x: &Point| (x - floor.0).perp(&floor.1).abs();
    let field = |x: &Point| u_wall + shear * height(x);
    let values = sample(&grid, &layout, field);
    let naive: Vec<f64> = (0..layout.num_nodes())
        .map(|i| {
            let x = layout.position(i);
            if walls.distance(&x).distance >= 0.0 {
                u_wall
            } else {
                field(&x)
            }
        })
        .collect();
    let mut naive_worst: f64 = 0.0;
    for k in 0..20 {
        let x = floor.0 + floor.1 * (0.3 + 0.02 * k as f64);
        let (u, _, _) = grid.interpolate::<Dim<2>>(&layout, &x, &values).unwrap();
        assert!((u - u_wall).abs() < 1e-12 * u_wall, "augmented {u} at the wall");
        let s = Stencil::new(&x, 1.0 / layout.h);
        let origin = layout.stencil_origin(&s.base).unwrap();
        let mut un = 0.0;
        s.for_each(layout.h, |o, w, _| un += w * naive[origin + layout.offset(&o)]);
        naive_worst = naive_worst.max((un - u_wall).abs());
    }
    // The naive stencil mixes wall-side nodes (U_wall) with interior ones: O(shear·h) off.
    assert!(naive_worst > 0.05 * shear * layout.h, "naive worst {naive_worst}");
}

/// A point deep inside a wall sees no grid point (isolated); one just past the wall sees only the
/// boundary points on a line (regularized). Neither panics; both are reported.
#[test]
fn degenerate_particles_are_detected() {
    let walls = tilted_container(0.0, 0.3);
    let layout = GridLayout::new(1.0 / 32.0, [32, 32]);
    let grid = augmented(&walls, &layout, 0.25);
    let (_, kind, _) = grid.particle_inverse::<Dim<2>>(&layout, &Point::new(0.5, 0.1), 0).unwrap();
    assert_eq!(kind, MlsKind::Isolated);
    let (minv, kind, _) = grid.particle_inverse::<Dim<2>>(&layout, &Point::new(0.5, 0.3 - 1.2 * layout.h), 0).unwrap();
    assert_eq!(kind, MlsKind::Regularized);
    assert!(minv.gamma.iter().chain(minv.beta.iter()).all(|v| v.is_finite()));
}
