//! The stable augmented transfer (`augmented.transfer = "stable"`): P2G with the normalised
//! B-spline weights ŵ = w/Σw is the transpose of the G2P fit, so a round trip cannot add energy,
//! keeps every mass positive and conserves momentum; the fit meets the wall condition at the wall.
//! Derivation: docs/stable_transfer.md.

use augmpm_core::geometry::{Point, Polygon, Region, WallDistance, WallShape, Walls2};
use augmpm_core::grid::{GridLayout, GridState};
use augmpm_core::material::{Material, WeaklyCompressibleFluid};
use augmpm_core::math::{Dim, Real};
use augmpm_core::particles::Particles;
use augmpm_core::step::packing::Packing;
use augmpm_core::step::schedule::{Binning, Schedule};
use augmpm_core::step::transfer::{g2p, grid_velocity, p2g, Transfer, VolumeRatio};
use augmpm_core::treatment::augmented::{AugmentedGrid, AugmentedTransfer, WallParticles};
use augmpm_core::wall::WallCondition;
use nalgebra::{Matrix2, Vector2};
use proptest::prelude::*;

const H: Real = 1.0 / 32.0;

/// A container in the unit box whose floor rises at `angle` (rad) to the grid from (0.05, y0).
fn tilted_container(angle: Real, y0: Real) -> (Walls2, Point, Point) {
    let y1 = y0 + 0.9 * angle.tan();
    let poly =
        Polygon::new(vec![Point::new(0.05, y0), Point::new(0.95, y1), Point::new(0.95, 0.95), Point::new(0.05, 0.95)]);
    let along = Point::new(angle.cos(), angle.sin());
    (Walls2::new(vec![WallShape::Polygon(poly)], Point::new(1.0, 1.0)), Point::new(0.05, y0), along)
}

/// A stress-free material: the transfers alone move momentum.
fn dust() -> Vec<Material> {
    vec![Material::Fluid(WeaklyCompressibleFluid::dust(1.0))]
}

/// Particles within `depth` (m) above the floor of the container, between 0.3 and 0.7 of its
/// length, with velocities and affine matrices from `seed`.
fn particles_near_floor(origin: Point, along: Point, n: usize, depth: Real, seed: u64) -> Particles<2> {
    let normal_in = Point::new(-along.y, along.x);
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(1);
    let mut rnd = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as Real / (1u64 << 53) as Real
    };
    let mut ps = Particles::<2>::default();
    for _ in 0..n {
        let x = origin + along * (0.27 + 0.4 * rnd()) + normal_in * (depth * rnd());
        let v = Vector2::new(rnd() - 0.5, rnd() - 0.5);
        ps.push(x, v, 0.5 + rnd(), 1.0, 0);
        let last = ps.len() - 1;
        ps.c[last] = Matrix2::new(rnd() - 0.5, rnd() - 0.5, rnd() - 0.5, rnd() - 0.5) * 8.0;
    }
    ps
}

struct Setup {
    layout: GridLayout<2>,
    walls: Walls2,
    grid: AugmentedGrid<2>,
    schedule: Schedule<2>,
    table: WallParticles<2>,
}

fn setup(walls: Walls2, condition: WallCondition, ps: &Particles<2>, transfer: AugmentedTransfer) -> Setup {
    let layout = GridLayout::new(H, [32, 32]);
    let grid = AugmentedGrid::new(&layout, &walls, H, vec![condition.into(); walls.walls.len() + 1], 0.25 * H)
        .with_transfer(transfer);
    let mut schedule = Schedule::new(&layout);
    schedule.sort(&layout, &ps.x, &mut Binning::default()).unwrap();
    let mut table = WallParticles::default();
    let ill = table.update::<Dim<2>>(&grid, &layout, &ps.x).unwrap();
    assert_eq!(ill, 0, "the particles lie inside the region: no MLS system is degenerate");
    Setup { layout, walls, grid, schedule, table }
}

/// Particle p's grid points with its normalised transfer weights ŵ (the reweighted B-spline
/// weights over Σw) and offsets x_i − x_p.
fn points_of(s: &Setup, ps: &Particles<2>, p: usize) -> Vec<(usize, Real, Point)> {
    let mut pts = Vec::new();
    match s.table.entry(p) {
        Some(e) => s.grid.for_each_near(&s.layout, &ps.x[p], e.near, |i, w, d| pts.push((i, e.tilt.weight(w, &d), d))),
        None => s.grid.for_each_point(&s.layout, &ps.x[p], p, |i, w, d| pts.push((i, w, d))).map(|_| ()).unwrap(),
    }
    let total: Real = pts.iter().map(|p| p.1).sum();
    pts.iter().map(|&(i, w, d)| (i, w / total, d)).collect()
}

/// Particle p's affine velocity over its grid points (`WallEntry::affine_velocity`: next to a wall, its
/// kept affine state with the rotation rate that carries its spin over its own points).
fn affine(s: &Setup, ps: &Particles<2>, p: usize) -> Matrix2<Real> {
    s.table.entry(p).map_or(ps.c[p], |e| e.affine_velocity::<Dim<2>>(&ps.c[p], H))
}

/// The transfers' energy norm: E = ½ Σ_p m_p Σ_i ŵ_ip |v_p + C_p (x_i − x_p)|², C_p the particle's
/// affine velocity over its points.
fn energy(s: &Setup, ps: &Particles<2>) -> Real {
    (0..ps.len())
        .map(|p| {
            let c = affine(s, ps, p);
            let u = |d: &Point| ps.v[p] + c * d;
            0.5 * ps.mass[p] * points_of(s, ps, p).iter().map(|(_, w, d)| w * u(d).norm_squared()).sum::<Real>()
        })
        .sum()
}

/// Linear and angular momentum of the particles' affine velocities at their grid points:
/// P = Σ_p m_p Σ_i ŵ_ip u_p(x_i), L = Σ_p m_p Σ_i ŵ_ip x_i × u_p(x_i).
fn momenta(s: &Setup, ps: &Particles<2>) -> (Point, Real) {
    let (mut lin, mut ang) = (Point::zeros(), 0.0);
    for p in 0..ps.len() {
        let c = affine(s, ps, p);
        for (_, w, d) in points_of(s, ps, p) {
            let u = ps.v[p] + c * d;
            lin += u * (w * ps.mass[p]);
            ang += (ps.x[p] + d).perp(&u) * w * ps.mass[p];
        }
    }
    (lin, ang)
}

/// A region with the container's distance but no wall faces: the fit has no wall terms.
struct NoFeet<'a>(&'a Walls2);

impl Region<2> for NoFeet<'_> {
    fn distance(&self, x: &Point) -> WallDistance<2> {
        self.0.distance(x)
    }
}

/// A zero grid state on the setup's nodes and boundary points (with the B-spline mass where its transfer reads it).
/// G2P of dust (no stress, no density sums) from the node velocities `velocity` over a step `dt` (s).
fn g2p_dust(
    t: &Transfer<'_, 2>,
    region: &dyn Region<2>,
    velocity: &[Point],
    ps: &mut Particles<2>,
    dt: Real,
) -> augmpm_core::step::transfer::G2pOutcome {
    g2p(t, region, &dust(), velocity, &VolumeRatio::default(), &Packing::default(), ps, dt, &mut Vec::new())
}

fn empty_grid(s: &Setup) -> GridState<2> {
    GridState::new(s.layout.num_nodes() + s.grid.points.len(), s.grid.transfer == AugmentedTransfer::Paper)
}

/// One P2G → grid update → (wall conditions) → G2P round trip with dt = 0 (positions fixed).
fn round_trip(s: &Setup, ps: &mut Particles<2>, walls_act: bool) -> GridState<2> {
    let t = Transfer { layout: &s.layout, schedule: &s.schedule, augmented: Some((&s.grid, &s.table)) };
    let mut state = empty_grid(s);
    let mut density = vec![0.0; ps.len()];
    p2g(&t, &dust(), ps, None, &mut density, 1e-3, &mut state, &mut VolumeRatio::default(), &mut Packing::default());
    let after_p2g = state.clone();
    grid_velocity(&t, &mut state, &Point::zeros(), 1e-3);
    if walls_act {
        s.grid.apply(&state.mass, &mut state.momentum, &mut augmpm_core::wall::WallImpulses::zeros(s.grid.walls.len()));
        g2p_dust(&t, &s.walls, &state.momentum, ps, 0.0);
    } else {
        g2p_dust(&t, &NoFeet(&s.walls), &state.momentum, ps, 0.0);
    }
    after_p2g
}

fn condition(k: u8) -> WallCondition {
    [WallCondition::Sticky, WallCondition::Slip, WallCondition::Separate][k as usize % 3]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// A round trip through the grid, still walls acting under any condition, never increases the
    /// energy norm E = ½ Σ_p m_p Σ_i ŵ_ip |u_p(x_i)|² (relative 1e-12: round-off of a few thousand
    /// terms); every grid point that received mass has a positive one.
    #[test]
    fn round_trip_never_adds_energy(angle in 0.0f64..45.0, seed in 0u64..1_000_000, k in 0u8..3) {
        let (walls, origin, along) = tilted_container(angle.to_radians(), 0.12);
        let mut ps = particles_near_floor(origin, along, 200, 2.5 * H, seed);
        let s = setup(walls, condition(k), &ps, AugmentedTransfer::Stable);
        let before = energy(&s, &ps);
        let grid = round_trip(&s, &mut ps, true);
        prop_assert!(grid.mass.iter().all(|&m| m >= 0.0));
        prop_assert!(grid.mass.iter().zip(&grid.momentum).all(|(&m, q)| m > 0.0 || q.norm() == 0.0));
        let after = energy(&s, &ps);
        prop_assert!(after <= before * (1.0 + 1e-12), "energy {} -> {}", before, after);
    }

    /// With the boundary points left free (no wall condition, no wall term in the fit), P2G → G2P
    /// conserves mass, linear momentum P and angular momentum L of the affine velocities at the grid
    /// points (relative 1e-12).
    #[test]
    fn free_round_trip_conserves_momentum(angle in 0.0f64..45.0, seed in 0u64..1_000_000) {
        let (walls, origin, along) = tilted_container(angle.to_radians(), 0.12);
        let mut ps = particles_near_floor(origin, along, 200, 2.5 * H, seed);
        let s = setup(walls, WallCondition::Sticky, &ps, AugmentedTransfer::Stable);
        let mass: Real = ps.mass.iter().sum();
        let (p0, l0) = momenta(&s, &ps);
        let grid = round_trip(&s, &mut ps, false);
        let grid_mass: Real = grid.mass.iter().sum();
        prop_assert!((grid_mass - mass).abs() <= 1e-12 * mass);
        let grid_p = grid.momentum.iter().fold(Point::zeros(), |a, q| a + q);
        let position = |i: usize| if i < s.layout.num_nodes() {
            s.layout.position(i)
        } else {
            s.grid.points[i - s.layout.num_nodes()].x
        };
        let grid_l: Real = grid.momentum.iter().enumerate().map(|(i, q)| position(i).perp(q)).sum();
        let (p1, l1) = momenta(&s, &ps);
        let scale = mass * (p0.norm() + 1.0);
        prop_assert!((grid_p - p0).norm() <= 1e-12 * scale, "P2G: {} vs {}", grid_p, p0);
        prop_assert!((p1 - p0).norm() <= 1e-12 * scale, "round trip: {} vs {}", p1, p0);
        prop_assert!((grid_l - l0).abs() <= 1e-12 * scale, "P2G: {} vs {}", grid_l, l0);
        prop_assert!((l1 - l0).abs() <= 1e-12 * scale, "round trip: {} vs {}", l1, l0);
    }

    /// An affine velocity field that satisfies the wall condition (sticky: zero on the floor; slip:
    /// tangent to it) is reproduced exactly by G2P, value and gradient, up to the floor.
    #[test]
    fn affine_fields_that_meet_the_wall_are_exact(
        angle in 0.0f64..45.0,
        seed in 0u64..1_000_000,
        slip in any::<bool>(),
        coef in (-2.0f64..2.0, -2.0f64..2.0, -2.0f64..2.0, -2.0f64..2.0),
    ) {
        let (walls, origin, along) = tilted_container(angle.to_radians(), 0.12);
        let normal_in = Point::new(-along.y, along.x);
        let mut ps = particles_near_floor(origin, along, 100, 2.5 * H, seed);
        let cond = if slip { WallCondition::Slip } else { WallCondition::Sticky };
        let s = setup(walls, cond, &ps, AugmentedTransfer::Stable);
        // u = U t + γ (t·r) t + (n·r) c, r = x − origin: zero normal part on the floor; sticky drops
        // the first two terms, which slide along it.
        let (u, gamma) = if slip { (coef.0, coef.1) } else { (0.0, 0.0) };
        let c = Point::new(coef.2, coef.3);
        let gradient = along * along.transpose() * gamma + c * normal_in.transpose();
        let field = |x: &Point| along * u + gradient * (x - origin);
        let mut velocity: Vec<Point> = (0..s.layout.num_nodes()).map(|i| field(&s.layout.position(i))).collect();
        velocity.extend(s.grid.points.iter().map(|b| field(&b.x)));
        let t = Transfer { layout: &s.layout, schedule: &s.schedule, augmented: Some((&s.grid, &s.table)) };
        g2p_dust(&t, &s.walls, &velocity, &mut ps, 0.0);
        for p in 0..ps.len() {
            prop_assert!((ps.v[p] - field(&ps.x[p])).norm() <= 1e-10, "v {} vs {}", ps.v[p], field(&ps.x[p]));
            prop_assert!((affine(&s, &ps, p) - gradient).norm() <= 1e-8, "C {} vs {}", affine(&s, &ps, p), gradient);
        }
    }
}

/// A particle gives the grid the angular momentum it took from it, across a move: with the boundary points
/// left free, P2G → G2P → advection over 1 ms (the particles' second moments change as they move along and
/// away from the floor) → P2G gives the grid the angular momentum the first grid held, within 1e-12
/// relative. It is the particles' own, Σ m (x × v + h²/4 axial(c)) with the affine state c they keep. The
/// particles lie 0.15 h to 2.5 h inside the floor, where their weights are centred; kept as the fitted
/// gradient instead, the grids' angular momenta differ by far more (the test fails).
#[test]
fn particles_keep_their_spin_across_a_move() {
    for (angle, seed) in [(0.0, 1), (17.0, 2), (38.0, 3)] {
        let (walls, origin, along) = tilted_container(Real::to_radians(angle), 0.12);
        let normal_in = Point::new(-along.y, along.x);
        let mut ps = particles_near_floor(origin, along, 200, 2.35 * H, seed);
        ps.x.iter_mut().for_each(|x| *x += normal_in * (0.15 * H));
        let grid_l = |s: &Setup, ps: &Particles<2>| {
            let t = Transfer { layout: &s.layout, schedule: &s.schedule, augmented: Some((&s.grid, &s.table)) };
            let mut state = empty_grid(s);
            p2g(
                &t,
                &dust(),
                ps,
                None,
                &mut vec![0.0; ps.len()],
                1e-3,
                &mut state,
                &mut VolumeRatio::default(),
                &mut Packing::default(),
            );
            let position = |i: usize| {
                if i < s.layout.num_nodes() {
                    s.layout.position(i)
                } else {
                    s.grid.points[i - s.layout.num_nodes()].x
                }
            };
            let l: Real = state.momentum.iter().enumerate().map(|(i, q)| position(i).perp(q)).sum();
            (l, state)
        };
        let own = |ps: &Particles<2>| -> Real {
            (0..ps.len())
                .map(|p| ps.mass[p] * (ps.x[p].perp(&ps.v[p]) + H * H / 4.0 * (ps.c[p][(1, 0)] - ps.c[p][(0, 1)])))
                .sum()
        };
        let s = setup(walls.clone(), WallCondition::Sticky, &ps, AugmentedTransfer::Stable);
        let (l0, mut state) = grid_l(&s, &ps);
        let scale = ps.mass.iter().sum::<Real>();
        assert!((l0 - own(&ps)).abs() <= 1e-12 * scale, "{angle}°: P2G {l0} vs the particles' {}", own(&ps));
        grid_velocity(
            &Transfer { layout: &s.layout, schedule: &s.schedule, augmented: Some((&s.grid, &s.table)) },
            &mut state,
            &Point::zeros(),
            1e-3,
        );
        let t = Transfer { layout: &s.layout, schedule: &s.schedule, augmented: Some((&s.grid, &s.table)) };
        g2p_dust(&t, &NoFeet(&s.walls), &state.momentum, &mut ps, 1e-3);
        assert!((own(&ps) - l0).abs() <= 1e-12 * scale, "{angle}°: G2P and the move {} vs {l0}", own(&ps));
        let moved = setup(walls, WallCondition::Sticky, &ps, AugmentedTransfer::Stable);
        let (l1, _) = grid_l(&moved, &ps);
        assert!((l1 - l0).abs() <= 1e-12 * scale, "{angle}°: the next P2G {l1} vs {l0}");
    }
}

/// Grid data that violate the wall (a uniform flow of 1 m/s straight into the floor) give a
/// particle at distance d from the floor a normal velocity O(d): each tenfold step closer divides
/// it by about ten (at least by 5), for sticky and slip walls.
#[test]
fn normal_velocity_vanishes_linearly_at_the_wall() {
    for cond in [WallCondition::Sticky, WallCondition::Slip] {
        let (walls, origin, along) = tilted_container(20f64.to_radians(), 0.12);
        let normal_in = Point::new(-along.y, along.x);
        let distances = [0.3, 0.03, 0.003, 0.0003];
        let mut ps = Particles::<2>::default();
        for (k, d) in distances.iter().enumerate() {
            ps.push(origin + along * (0.3 + 0.1 * k as Real) + normal_in * (d * H), Point::zeros(), 1.0, 1.0, 0);
        }
        let s = setup(walls, cond, &ps, AugmentedTransfer::Stable);
        let velocity = vec![-normal_in; s.layout.num_nodes() + s.grid.points.len()];
        let t = Transfer { layout: &s.layout, schedule: &s.schedule, augmented: Some((&s.grid, &s.table)) };
        g2p_dust(&t, &s.walls, &velocity, &mut ps, 0.0);
        let normal: Vec<Real> = ps.v.iter().map(|v| v.dot(&normal_in).abs()).collect();
        for k in 1..distances.len() {
            assert!(normal[k] <= normal[k - 1] / 5.0, "{cond:?}: |v·n| at d = {:?} h: {normal:?}", distances);
        }
        assert!(normal[3] < 1e-3, "{cond:?}: {normal:?}");
    }
}

/// The J-bar average keeps the total volume Σ V⁰J next to walls too: particles in the wall table scatter
/// and gather J over the regular stencil like the others (relative 1e-12: sums of a few thousand O(1)
/// terms), and a uniform J comes back unchanged (1e-14).
#[test]
fn volume_ratio_average_keeps_the_volume_next_to_walls() {
    use augmpm_core::material::DensityEstimate;
    let (walls, origin, along) = tilted_container(20f64.to_radians(), 0.12);
    let mut ps = particles_near_floor(origin, along, 300, 4.0 * H, 3);
    let s = setup(walls, WallCondition::Slip, &ps, AugmentedTransfer::Stable);
    assert!(s.table.len() > 50, "{} particles see the wall", s.table.len());
    let t = Transfer { layout: &s.layout, schedule: &s.schedule, augmented: Some((&s.grid, &s.table)) };
    let fluid = vec![Material::Fluid(WeaklyCompressibleFluid {
        density_estimate: DensityEstimate::Deformation,
        relaxation_time: None,
        ..WeaklyCompressibleFluid::dust(1.0)
    })];
    for uniform in [true, false] {
        for p in 0..ps.len() {
            ps.vol0[p] = 0.5 + 0.001 * (p % 997) as Real;
            ps.jp[p] = if uniform { 1.1 } else { 0.9 + 0.2 * ((p * 37) % 101) as Real / 101.0 };
        }
        let volume: Real = ps.vol0.iter().zip(&ps.jp).map(|(v, j)| v * j).sum();
        let mut state = empty_grid(&s);
        let mut ratio = VolumeRatio::new(s.layout.num_nodes());
        p2g(&t, &fluid, &ps, None, &mut vec![0.0; ps.len()], 1e-3, &mut state, &mut ratio, &mut Packing::default());
        grid_velocity(&t, &mut state, &Point::zeros(), 1e-3);
        ratio.finish(&s.layout, &s.schedule);
        g2p(&t, &NoFeet(&s.walls), &fluid, &state.momentum, &ratio, &Packing::default(), &mut ps, 0.0, &mut Vec::new());
        let after: Real = ps.vol0.iter().zip(&ps.jp).map(|(v, j)| v * j).sum();
        assert!((after - volume).abs() < 1e-12 * volume, "total volume {after} vs {volume}");
        if uniform {
            assert!(ps.jp.iter().all(|&j| (j - 1.1).abs() < 1e-14), "a uniform J changed");
        }
    }
}

/// Repeated round trips with the particles held still amplify the transfer's dominant mode (power
/// iteration, the energy rescaled after each trip): even that mode loses energy in a trip, and no
/// grid point ever gets a negative mass.
#[test]
fn dominant_mode_does_not_gain_energy() {
    for cond in [WallCondition::Sticky, WallCondition::Slip, WallCondition::Separate] {
        let (walls, origin, along) = tilted_container(20f64.to_radians(), 0.12);
        let mut ps = particles_near_floor(origin, along, 800, 3.0 * H, 3);
        let s = setup(walls, cond, &ps, AugmentedTransfer::Stable);
        let mut worst: Real = 0.0;
        for _ in 0..200 {
            let before = energy(&s, &ps);
            let grid = round_trip(&s, &mut ps, true);
            assert!(grid.mass.iter().all(|&m| m >= 0.0));
            let after = energy(&s, &ps);
            worst = worst.max(after / before);
            let k = (before / after).sqrt();
            ps.v.iter_mut().for_each(|v| *v *= k);
            ps.c.iter_mut().for_each(|c| *c *= k);
        }
        assert!(worst <= 1.0 + 1e-12, "{cond:?}: a trip multiplied the energy by {worst}");
    }
}

/// The reweighted transfer weights are positive and their first moment Σ ŵ (x_i − x_p) vanishes
/// (≤ 1e-12 h) for a particle at least 0.1 h inside the floor, at any angle: the particle's own
/// position is the centre of its grid points, so what the grid receives is its momentum m v_p and
/// angular momentum x_p × m v_p plus the affine part, as on a whole stencil. Closer to the wall the
/// limits on the tilt (|η| h ≤ 4, a spread of at least 0.04 h²) leave a first moment below 0.2 h
/// (0.15 h measured at 0.02 h).
#[test]
fn transfer_weights_are_centred_on_the_particle() {
    for angle in [0.0, 7.0, 20.0, 33.0, 45.0] {
        let (walls, origin, along) = tilted_container(Real::to_radians(angle), 0.12);
        let normal_in = Point::new(-along.y, along.x);
        let mut ps = Particles::<2>::default();
        let depths = [0.02, 0.05, 0.1, 0.3, 0.7, 1.2, 2.0];
        for (k, d) in depths.iter().enumerate() {
            for j in 0..10 {
                let x = origin + along * (0.2 + 0.05 * k as Real + 0.0037 * j as Real) + normal_in * (d * H);
                ps.push(x, Point::zeros(), 1.0, 1.0, 0);
            }
        }
        let s = setup(walls, WallCondition::Slip, &ps, AugmentedTransfer::Stable);
        for p in 0..ps.len() {
            let pts = points_of(&s, &ps, p);
            assert!(pts.iter().all(|&(_, w, _)| w >= 0.0));
            let first = pts.iter().fold(Point::zeros(), |a, &(_, w, d)| a + d * w);
            let bound = if depths[p / 10] >= 0.1 { 1e-12 } else { 0.2 };
            assert!(
                first.norm() <= bound * H,
                "{angle}°, {} h deep: first moment {} h",
                depths[p / 10],
                first.norm() / H
            );
        }
    }
}
