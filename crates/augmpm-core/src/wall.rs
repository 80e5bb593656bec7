//! What a wall asks of the material against it: its condition (sticky, slip, separate), applied to a
//! velocity at one or two normals, and the points sampled along it that join the augmented grid.

use crate::math::{Real, Vector};
use schemars::JsonSchema;
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
        self.apply_at(v, &[*n, *n], wall_v)
    }

    /// Applies the condition at a point with one or two outward unit normals (a corner).
    ///
    /// The wall's geometry stays still, so only the tangential part of `wall_v` counts.
    /// Relative to it, sticky leaves nothing; slip removes the components along both
    /// normals at once (projection on the complement of their span), so a corner of any
    /// angle is satisfied exactly; separate takes the closest velocity that does not move
    /// into either face (the projection on the cone `u·n0 ≤ 0, u·n1 ≤ 0`).
    #[inline]
    pub fn apply_at<const D: usize>(self, v: Vector<D>, normals: &[Vector<D>; 2], wall_v: &Vector<D>) -> Vector<D> {
        let [n0, n1] = normals;
        // Orthonormal basis {e0, e1} of span{n0, n1}. Two equal normals (no corner) leave a
        // residue of the rounding (~1e-7 in f32): only a residue above it is a second direction.
        let r = n1 - n0 * n1.dot(n0);
        let e1 = (r.norm() > (1e-9 as Real).max(16.0 * Real::EPSILON)).then(|| r.normalize());
        let tangential = |u: Vector<D>| {
            let u = u - n0 * u.dot(n0);
            e1.map_or(u, |e1| u - e1 * u.dot(&e1))
        };
        let wall_t = tangential(*wall_v);
        let rel = v - wall_t;
        let out = match self {
            WallCondition::Sticky => Vector::<D>::zeros(),
            WallCondition::Slip => tangential(rel),
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

/// A point sampled on a wall, carrying the wall's outward normal(s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundaryPoint<const D: usize> {
    /// Position (m).
    pub x: Vector<D>,
    /// Outward unit normals (into the wall); two at a corner, else `normals[1] == normals[0]`.
    pub normals: [Vector<D>; 2],
    /// Index of the wall it was sampled on.
    pub wall: usize,
    /// Velocity of the wall surface there (m/s); only its tangential part acts.
    pub velocity: Vector<D>,
}

impl<const D: usize> BoundaryPoint<D> {
    /// A point of a still wall.
    pub fn new(x: Vector<D>, n0: Vector<D>, n1: Vector<D>, wall: usize) -> Self {
        Self { x, normals: [n0, n1], wall, velocity: Vector::<D>::zeros() }
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
        let out = WallCondition::Slip.apply_at(v, &[n0, n1], &still);
        assert!(out.dot(&n0).abs() < 1e-15 && out.dot(&n1).abs() < 1e-15);
        let sequential = {
            let u = v - n0 * v.dot(&n0);
            u - n1 * u.dot(&n1)
        };
        assert!(sequential.dot(&n0).abs() > 0.1);
        // 3D: two faces meeting along the z axis; the velocity along the edge survives.
        let (m0, m1) = (nalgebra::Vector3::new(0.0, -1.0, 0.0), nalgebra::Vector3::new(a.sin(), -a.cos(), 0.0));
        let v3 = nalgebra::Vector3::new(0.7, -1.3, 2.5);
        let out3 = WallCondition::Slip.apply_at(v3, &[m0, m1], &nalgebra::Vector3::zeros());
        assert!(out3.dot(&m0).abs() < 1e-15 && out3.dot(&m1).abs() < 1e-15);
        assert!((out3.z - 2.5).abs() < 1e-15);
        // A velocity tangent to a straight wall passes unchanged.
        let tangent = Vector2::new(2.0, 0.0);
        assert_eq!(WallCondition::Slip.apply_at(tangent, &[n0, n0], &still), tangent);
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
        let out = WallCondition::Separate.apply_at(v, &[n0, n1], &still);
        assert!((out - Vector2::new(0.5, 0.0)).norm() < 1e-15, "{out}");
        let into_both = Vector2::new(-0.5, -1.0);
        let out = WallCondition::Separate.apply_at(into_both, &[n0, n1], &still);
        assert!(out.dot(&n0) <= 1e-15 && out.dot(&n1) <= 1e-15);
        assert!(out.norm() < 1e-15, "{out}");
        let away = Vector2::new(0.3, 1.0);
        assert_eq!(WallCondition::Separate.apply_at(away, &[n0, n1], &still), away);
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
}
