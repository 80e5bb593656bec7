//! What a wall asks of the material against it: its condition (sticky, slip, separate), applied to a
//! velocity at one, two or three normals (a face, an edge or corner in 2D, a corner in 3D), and the
//! points sampled along it that join the augmented grid.

use crate::math::{Real, Vector};
use schemars::JsonSchema;

/// The outward unit normals (into the wall) at a point of a wall: three, repeated where fewer faces
/// meet (`[n, n, n]` on a face, `[n0, n1, n1]` at a 2D corner or a 3D edge).
pub type Normals<const D: usize> = [Vector<D>; 3];
use serde::{Deserialize, Serialize};

/// What a wall does to the velocity of the material against it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum WallCondition {
    /// No-slip: the velocity equals the wall's.
    #[default]
    Sticky,
    /// Full-slip: the normal component (relative to the wall) is removed.
    Slip,
    /// Only a normal component into the wall is removed; the material may leave it.
    Separate,
}

impl WallCondition {
    /// Applies the condition to velocity `v` at a wall of outward normal `n`
    /// (unit, into the wall) whose surface moves at `wall_v`.
    #[inline]
    pub fn apply<const D: usize>(self, v: Vector<D>, n: &Vector<D>, wall_v: &Vector<D>) -> Vector<D> {
        self.apply_at(v, &[*n, *n, *n], wall_v)
    }

    /// Applies the condition at a point with one, two or three outward unit normals (a corner).
    ///
    /// The wall's geometry stays still, so only the tangential part of `wall_v` counts.
    /// Relative to it, sticky leaves nothing; slip removes the components along all the
    /// normals at once (projection on the complement of their span), so a corner of any
    /// angles is satisfied exactly; separate takes the closest velocity that does not move
    /// into any face (the projection on the cone `u·n_k ≤ 0`).
    #[inline]
    pub fn apply_at<const D: usize>(self, v: Vector<D>, normals: &Normals<D>, wall_v: &Vector<D>) -> Vector<D> {
        self.apply_relative(v, normals, &tangential(*wall_v, normals))
    }

    /// Applies the condition relative to a wall moving at `wall_v`, its normal part included (a wall
    /// that moves as a rigid body).
    #[inline]
    pub fn apply_relative<const D: usize>(self, v: Vector<D>, normals: &Normals<D>, wall_v: &Vector<D>) -> Vector<D> {
        let [n0, n1, n2] = normals;
        let tangential = |u: Vector<D>| tangential(u, normals);
        let wall_t = *wall_v;
        let rel = v - wall_t;
        let out = match self {
            WallCondition::Sticky => Vector::<D>::zeros(),
            WallCondition::Slip => tangential(rel),
            WallCondition::Separate if n2 != n1 => {
                // Three faces: the nearest feasible projection on the complement of the span of each
                // subset of the normals (the projection on the cone is one of them; all three: always).
                let feasible = |u: &Vector<D>, tolerance: Real| normals.iter().all(|n| u.dot(n) <= tolerance);
                if feasible(&rel, 0.0) {
                    rel
                } else {
                    let tolerance = (1e-12 as Real).max(16.0 * Real::EPSILON) * rel.norm();
                    let subsets = [[n0, n0, n0], [n1, n1, n1], [n2, n2, n2], [n0, n1, n1], [n0, n2, n2], [n1, n2, n2]];
                    subsets
                        .iter()
                        .map(|&[a, b, c]| tangential_to(rel, &[*a, *b, *c]))
                        .filter(|u| feasible(u, tolerance))
                        .fold(tangential(rel), |best, u| if (u - rel).norm() < (best - rel).norm() { u } else { best })
                }
            }
            WallCondition::Separate => {
                let feasible = |u: &Vector<D>| u.dot(n0) <= 0.0 && u.dot(n1) <= 0.0;
                if feasible(&rel) {
                    rel
                } else {
                    // Candidates: the projection on either face, and the edge (always feasible).
                    let tolerance = (1e-12 as Real).max(16.0 * Real::EPSILON) * rel.norm();
                    let faces = [rel - n0 * rel.dot(n0), rel - n1 * rel.dot(n1)];
                    let edge = tangential(rel);
                    faces
                        .into_iter()
                        .filter(|u| u.dot(n0) <= tolerance && u.dot(n1) <= tolerance)
                        .fold(edge, |best, u| if (u - rel).norm() < (best - rel).norm() { u } else { best })
                }
            }
        };
        out + wall_t
    }
}

/// The part of `u` orthogonal to all `normals` (the projection on the complement of their span).
#[inline]
fn tangential<const D: usize>(u: Vector<D>, normals: &Normals<D>) -> Vector<D> {
    tangential_to(u, normals)
}

/// [`tangential`], by Gram–Schmidt: an orthonormal basis of the normals' span, each normal's residue
/// after the earlier ones counting only above the rounding (two equal normals leave ~1e-7 in f32).
/// A third normal equal to the second (a face, a 2D corner, a 3D edge) is skipped.
#[inline]
fn tangential_to<const D: usize>(u: Vector<D>, [n0, n1, n2]: &Normals<D>) -> Vector<D> {
    let floor = (1e-9 as Real).max(16.0 * Real::EPSILON);
    let r = n1 - n0 * n1.dot(n0);
    let u = u - n0 * u.dot(n0);
    let (u, e1) = if r.norm() > floor {
        let e1 = r.normalize();
        (u - e1 * u.dot(&e1), Some(e1))
    } else {
        (u, None)
    };
    if n2 == n1 {
        return u;
    }
    let mut r2 = n2 - n0 * n2.dot(n0);
    if let Some(e1) = e1 {
        r2 -= e1 * r2.dot(&e1);
    }
    if r2.norm() > floor {
        let e2 = r2.normalize();
        u - e2 * u.dot(&e2)
    } else {
        u
    }
}

/// The part of a slide of `speed` (m/s) along a wall that Coulomb friction `mu` keeps where the wall
/// stopped a velocity `pressed` (m/s) into it: it shrinks by `mu · pressed`, and stops where it would
/// reverse (always, for an infinite `mu`).
#[inline]
pub fn coulomb_kept(mu: Real, pressed: Real, speed: Real) -> Real {
    if mu.is_infinite() || speed <= mu * pressed {
        0.0
    } else {
        1.0 - mu * pressed / speed
    }
}

/// How a wall acts on the material against it: its condition and, on a `separate` wall, its Coulomb
/// friction coefficient μ (0: frictionless; infinite: no sliding while in contact, lift-off still free).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WallContact {
    pub condition: WallCondition,
    /// μ ≥ 0, used on `separate` walls only.
    pub friction: Real,
    /// Whether the wall moves as a rigid body: its velocity then counts in full, normal part included
    /// (a still wall's geometry stays, so only the tangential part of its surface velocity does).
    pub moving: bool,
}

impl From<WallCondition> for WallContact {
    fn from(condition: WallCondition) -> Self {
        Self { condition, friction: 0.0, moving: false }
    }
}

impl WallContact {
    /// The contact at a wall of outward normal `n` (unit, into the wall) moving at `wall_v`.
    #[inline]
    pub fn apply<const D: usize>(self, v: Vector<D>, n: &Vector<D>, wall_v: &Vector<D>) -> Vector<D> {
        self.apply_at(v, &[*n, *n, *n], wall_v)
    }

    /// The condition at a point with one, two or three outward unit normals ([`WallCondition::apply_at`]),
    /// then Coulomb friction: where the condition removed a velocity Δ into the wall (relative to
    /// it), the tangential relative velocity shrinks by μ|Δ|, stopping where it would reverse (the
    /// usual MPM update, Bardenhagen et al. 2000). Material moving off the wall is left as it is.
    #[inline]
    pub fn apply_at<const D: usize>(self, v: Vector<D>, normals: &Normals<D>, wall_v: &Vector<D>) -> Vector<D> {
        let reference = if self.moving { *wall_v } else { tangential(*wall_v, normals) };
        let out = self.condition.apply_relative(v, normals, &reference);
        if self.friction == 0.0 || self.condition != WallCondition::Separate {
            return out;
        }
        // `out − v` is what the condition removed: the normal velocity into the wall (relative to
        // it: `out` and `v` carry the same wall velocity, only its tangential part, `wall_t`).
        let pressed = (out - v).norm();
        if pressed == 0.0 {
            return out;
        }
        let wall_t = reference;
        let slide = out - wall_t;
        wall_t + slide * coulomb_kept(self.friction, pressed, slide.norm())
    }
}

/// The moment about the origin, `x × p` (3 components; in 2D only z), of `p` given at `x`.
#[inline]
pub fn moment<const D: usize>(x: &Vector<D>, p: &Vector<D>) -> Vector<3> {
    let pad = |v: &Vector<D>| Vector::<3>::from_fn(|k, _| if k < D { v[k] } else { 0.0 });
    pad(x).cross(&pad(p))
}

/// What the walls gave the material in one step, per wall (the domain box last): the impulse `Σ Δp`
/// (N·s, per metre in 2D) and its moment about the origin `Σ x × Δp` (N·m·s), over the grid points
/// (and, with the stable transfer's wall fit, the particles) where it was given.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WallImpulses<const D: usize> {
    pub linear: Vec<Vector<D>>,
    pub angular: Vec<Vector<3>>,
}

impl<const D: usize> WallImpulses<D> {
    /// Nothing given yet, for `walls` walls (the domain box counted).
    pub fn zeros(walls: usize) -> Self {
        Self { linear: vec![Vector::<D>::zeros(); walls], angular: vec![Vector::<3>::zeros(); walls] }
    }

    /// Wall `wall` gave `dp` at `x`.
    #[inline]
    pub fn add(&mut self, wall: usize, x: &Vector<D>, dp: Vector<D>) {
        self.linear[wall] += dp;
        self.angular[wall] += moment(x, &dp);
    }

    /// Wall `wall` gave `dp` with moment `moment` about the origin.
    #[inline]
    pub fn add_with_moment(&mut self, wall: usize, dp: Vector<D>, moment: Vector<3>) {
        self.linear[wall] += dp;
        self.angular[wall] += moment;
    }

    /// Back to nothing given, keeping the number of walls.
    pub fn clear(&mut self) {
        self.linear.fill(Vector::<D>::zeros());
        self.angular.fill(Vector::<3>::zeros());
    }
}

/// A point sampled on a wall, carrying the wall's outward normal(s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundaryPoint<const D: usize> {
    /// Position (m).
    pub x: Vector<D>,
    /// Outward unit normals (into the wall): repeated where fewer faces meet ([`Normals`]).
    pub normals: Normals<D>,
    /// Index of the wall it was sampled on.
    pub wall: usize,
    /// Velocity of the wall surface there (m/s): of a still wall only its tangential part acts, of a
    /// moving one ([`WallContact::moving`]) all of it.
    pub velocity: Vector<D>,
}

impl<const D: usize> BoundaryPoint<D> {
    /// A point of a still wall on a face (`n0 == n1`) or where two faces meet.
    pub fn new(x: Vector<D>, n0: Vector<D>, n1: Vector<D>, wall: usize) -> Self {
        Self::with_normals(x, [n0, n1, n1], wall)
    }

    /// A point of a still wall with the given normals (three faces meet at a 3D corner).
    pub fn with_normals(x: Vector<D>, normals: Normals<D>, wall: usize) -> Self {
        Self { x, normals, wall, velocity: Vector::<D>::zeros() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// Full slip at a 60° corner leaves no component along either normal (the authors'
    /// one-after-the-other projection leaves one); in 3D it keeps the motion along the edge.
    #[test]
    fn slip_satisfies_both_normals_at_a_corner() {
        let n0 = Vector2::new(0.0, -1.0);
        let a = 60f64.to_radians();
        let n1 = Vector2::new(a.sin(), -a.cos());
        let v = Vector2::new(0.7, -1.3);
        let still = Vector2::zeros();
        let out = WallCondition::Slip.apply_at(v, &[n0, n1, n1], &still);
        assert!(out.dot(&n0).abs() < 1e-15 && out.dot(&n1).abs() < 1e-15);
        let sequential = {
            let u = v - n0 * v.dot(&n0);
            u - n1 * u.dot(&n1)
        };
        assert!(sequential.dot(&n0).abs() > 0.1);
        // 3D: two faces meeting along the z axis; the velocity along the edge survives.
        let (m0, m1) = (nalgebra::Vector3::new(0.0, -1.0, 0.0), nalgebra::Vector3::new(a.sin(), -a.cos(), 0.0));
        let v3 = nalgebra::Vector3::new(0.7, -1.3, 2.5);
        let out3 = WallCondition::Slip.apply_at(v3, &[m0, m1, m1], &nalgebra::Vector3::zeros());
        assert!(out3.dot(&m0).abs() < 1e-15 && out3.dot(&m1).abs() < 1e-15);
        assert!((out3.z - 2.5).abs() < 1e-15);
        // A velocity tangent to a straight wall passes unchanged.
        let tangent = Vector2::new(2.0, 0.0);
        assert_eq!(WallCondition::Slip.apply_at(tangent, &[n0, n0, n0], &still), tangent);
    }

    /// Separate at a 120° (obtuse) corner: leaving along one face is allowed when that
    /// projection no longer moves into the other face; only then is the corner a stop.
    #[test]
    fn separate_projects_on_the_corner_cone() {
        let n0 = Vector2::new(0.0, -1.0);
        let a = 30f64.to_radians(); // second face tilted 30°: a 150° interior angle
        let n1 = Vector2::new(-a.sin(), -a.cos());
        let still = Vector2::zeros();
        let v = Vector2::new(0.5, -1.0);
        let out = WallCondition::Separate.apply_at(v, &[n0, n1, n1], &still);
        assert!((out - Vector2::new(0.5, 0.0)).norm() < 1e-15, "{out}");
        let into_both = Vector2::new(-0.5, -1.0);
        let out = WallCondition::Separate.apply_at(into_both, &[n0, n1, n1], &still);
        assert!(out.dot(&n0) <= 1e-15 && out.dot(&n1) <= 1e-15);
        assert!(out.norm() < 1e-15, "{out}");
        let away = Vector2::new(0.3, 1.0);
        assert_eq!(WallCondition::Separate.apply_at(away, &[n0, n1, n1], &still), away);
    }

    /// At a 3D corner where three faces meet at angles other than 90° (the floor and two walls leaning
    /// 20° and 30°), slip leaves no velocity at all (three independent normals span space), and separate
    /// projects on the cone: a velocity into the floor alone slides along the floor's edge with the
    /// nearer wall, one leaving the corner passes unchanged, and the result never moves into a face.
    #[test]
    fn three_faces_at_a_3d_corner() {
        use nalgebra::Vector3;
        let (a, b) = (20f64.to_radians(), 30f64.to_radians());
        let normals =
            [Vector3::new(0.0, -1.0, 0.0), Vector3::new(-a.cos(), a.sin(), 0.0), Vector3::new(0.0, b.sin(), -b.cos())];
        let still = Vector3::zeros();
        let v = Vector3::new(-0.4, -1.0, -0.3);
        assert!(WallCondition::Slip.apply_at(v, &normals, &still).norm() < 1e-14);
        for v in [v, Vector3::new(0.5, -1.0, 0.7), Vector3::new(-0.2, 0.1, -2.0), Vector3::new(-3.0, -0.5, 0.1)] {
            let out = WallCondition::Separate.apply_at(v, &normals, &still);
            assert!(normals.iter().all(|n| out.dot(n) <= 1e-14), "{v} → {out}");
            // The projection on a convex cone: v − out is normal to it at out (out·(v − out) = 0).
            assert!(out.dot(&(v - out)).abs() < 1e-12, "{v} → {out}");
        }
        let away = Vector3::new(0.6, 0.2, 0.6);
        assert_eq!(WallCondition::Separate.apply_at(away, &normals, &still), away);
    }

    /// The wall's geometry is still: a wall velocity with a normal part only moves the material
    /// along the wall.
    #[test]
    fn wall_velocity_counts_only_tangentially() {
        let n = Vector2::new(0.0, -1.0);
        let wall = Vector2::new(1.0, 2.0);
        assert_eq!(WallCondition::Sticky.apply(Vector2::new(3.0, 3.0), &n, &wall), Vector2::new(1.0, 0.0));
        assert_eq!(WallCondition::Slip.apply(Vector2::new(3.0, 3.0), &n, &wall), Vector2::new(3.0, 0.0));
    }

    #[test]
    fn conditions_project_velocity() {
        let n = Vector2::new(0.0, -1.0);
        let still = Vector2::zeros();
        let into = Vector2::new(2.0, -3.0);
        let away = Vector2::new(2.0, 3.0);
        assert_eq!(WallCondition::Sticky.apply(into, &n, &still), still);
        assert_eq!(WallCondition::Slip.apply(into, &n, &still), Vector2::new(2.0, 0.0));
        assert_eq!(WallCondition::Slip.apply(away, &n, &still), Vector2::new(2.0, 0.0));
        assert_eq!(WallCondition::Separate.apply(into, &n, &still), Vector2::new(2.0, 0.0));
        assert_eq!(WallCondition::Separate.apply(away, &n, &still), away);
        let belt = Vector2::new(1.5, 0.0);
        assert_eq!(WallCondition::Sticky.apply(into, &n, &belt), belt);
        assert_eq!(WallCondition::Slip.apply(into, &n, &belt), Vector2::new(2.0, 0.0));
    }

    /// Coulomb friction on a separate floor (normal −y): pressing down at 1 m/s with a slide of
    /// 2 m/s, μ = 0.5 leaves 2 − 0.5·1 = 1.5 m/s; μ = 3 stops the slide (it would reverse); infinite μ
    /// stops it too; moving off the floor leaves the velocity as it is; μ = 0 is the plain condition.
    #[test]
    fn coulomb_friction_shrinks_the_slide_by_mu_times_the_stopped_normal_velocity() {
        let n = Vector2::new(0.0, -1.0);
        let still = Vector2::zeros();
        let contact = |mu: Real| WallContact { condition: WallCondition::Separate, friction: mu, moving: false };
        let pressing = Vector2::new(2.0, -1.0);
        assert!((contact(0.5).apply(pressing, &n, &still) - Vector2::new(1.5, 0.0)).norm() < 1e-15);
        assert_eq!(contact(3.0).apply(pressing, &n, &still), Vector2::zeros());
        assert_eq!(contact(Real::INFINITY).apply(pressing, &n, &still), Vector2::zeros());
        let lifting = Vector2::new(2.0, 0.5);
        assert_eq!(contact(Real::INFINITY).apply(lifting, &n, &still), lifting);
        assert_eq!(contact(0.0).apply(pressing, &n, &still), WallCondition::Separate.apply(pressing, &n, &still));
        // Relative to a belt moving at 1 m/s: the slide is 1 m/s, μ = 0.5 leaves 0.5 m/s of it.
        let belt = Vector2::new(1.0, 0.0);
        assert!((contact(0.5).apply(pressing, &n, &belt) - Vector2::new(1.5, 0.0)).norm() < 1e-15);
        // Friction acts on separate walls only.
        let slip = WallContact { condition: WallCondition::Slip, friction: 0.5, moving: false };
        assert_eq!(slip.apply(pressing, &n, &still), Vector2::new(2.0, 0.0));
    }
}
