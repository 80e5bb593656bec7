//! Rigid bodies that the material pushes and that push it back (two-way coupling; the direction the paper's
//! conclusion names). A body is a wall posed by the engine itself: the wall conditions give the material an
//! impulse at the body's surface each step (`WallImpulses`), the body takes the opposite impulse and its
//! moment, gravity acts on it, and its new velocity moves it as a moving wall in the next step. Its state
//! is the wall's pose (`WallPose`: the position and turn of its centre of mass, which is its pivot, and
//! their rates), so checkpoints carry it with the walls' poses.
//!
//! Each step is symplectic Euler: the velocities take the step's impulses,
//! `v' = v + (−J)/m + g dt`, `ω' = ω + I⁻¹(−L_c)` with `L_c = L − c × J` the moment about the centre of mass
//! `c` of the impulse `J` the body gave the material (`L` about the origin), then the pose moves on at the
//! new velocities, `c' = c + v' dt`. So the body gains exactly the momentum and (in 2D) the angular momentum
//! about the origin that the material lost at its wall (`c' × m v' = c × m v'`). The material saw the wall
//! move at the old velocities during the step, plus the change that gravity, contacts and joints gave
//! them over the step before (`State::body_kicks`); the rest of the difference is followed as any wall
//! move is. What a body meets besides the material (other bodies, the scene's walls, its hinge) is
//! resolved in [`crate::contact`], which then moves it instead of [`drift`].

use crate::math::{Matrix, Real, Vector};
use crate::motion::WallPose;
use crate::wall::moment;

/// A rigid body's constants.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidBody<const D: usize> {
    /// Its wall's index in the region (after the scene's walls).
    pub wall: usize,
    /// Mass (kg, per metre of depth in 2D).
    pub mass: Real,
    /// Inertia about the centre of mass in the frame the scene draws the body in (kg·m², per metre in 2D:
    /// only the zz entry).
    pub inertia: Matrix<3>,
    /// Its centre of mass where the scene draws it (m): the pivot of its wall's pose.
    pub centre: Vector<D>,
}

impl<const D: usize> RigidBody<D> {
    /// The body in `pose` at `t` (s), still there, with its velocities after a step `dt` (s) in which its
    /// wall gave the material the impulse `linear` (N·s) with moment `angular` (N·m·s, about the origin),
    /// under `gravity` (m/s²).
    pub fn kick(
        &self,
        pose: &WallPose<D>,
        t: Real,
        dt: Real,
        gravity: &Vector<D>,
        linear: &Vector<D>,
        angular: &Vector<3>,
    ) -> WallPose<D> {
        let c = self.centre + pose.offset(t);
        let v = Vector::<D>::from(pose.velocity) - linear / self.mass + gravity * dt;
        let spin = -(angular - moment(&c, linear));
        let w = Vector::<3>::from(pose.angular_velocity);
        let w = if D == 2 {
            [0.0, 0.0, w.z + spin.z / self.inertia[(2, 2)]]
        } else {
            // The inertia turned as the body is at `t` (the gyroscopic term is left out of the step).
            let r = pose.rotation(t).into_inner();
            let world = r * self.inertia * r.transpose();
            (w + world.try_inverse().map_or(Vector::<3>::zeros(), |inv| inv * spin)).into()
        };
        WallPose {
            time: t,
            position: pose.offset(t).into(),
            angle: pose.turn(t),
            velocity: v.into(),
            angular_velocity: w,
        }
    }
}

/// The pose after `dt` (s) of a body in `pose` moving freely at its velocities.
pub fn drift<const D: usize>(pose: &WallPose<D>, dt: Real) -> WallPose<D> {
    let t = pose.time + dt;
    WallPose { time: t, position: pose.offset(t).into(), angle: pose.turn(t), ..*pose }
}

/// Area (m²), centroid (m) and polar moment of area about the centroid (m⁴) of a simple polygon given
/// counter-clockwise (the shoelace sums).
pub fn polygon_moments(vertices: &[Vector<2>]) -> (Real, Vector<2>, Real) {
    let n = vertices.len();
    let (mut area2, mut first, mut second) = (0.0, Vector::<2>::zeros(), 0.0);
    for i in 0..n {
        let (a, b) = (vertices[i], vertices[(i + 1) % n]);
        let cross = a.x * b.y - b.x * a.y;
        area2 += cross;
        first += (a + b) * cross;
        second += cross * (a.dot(&a) + a.dot(&b) + b.dot(&b));
    }
    let area = 0.5 * area2;
    let centroid = first / (3.0 * area2);
    // About the origin Σ cross (a·a + a·b + b·b) / 12; about the centroid by the parallel axis theorem.
    (area, centroid, second / 12.0 - area * centroid.norm_squared())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square's area is 1, its centroid its middle and its polar moment 1/6; an L of two squares
    /// has the centroid and moment the parallel axis theorem gives.
    #[test]
    fn polygon_moments_are_those_of_the_shapes() {
        let square = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)].map(|(x, y)| Vector::<2>::new(x + 2.0, y - 1.0));
        let (a, c, j) = polygon_moments(&square);
        assert!((a - 1.0).abs() < 1e-14 && (c - Vector::<2>::new(2.5, -0.5)).norm() < 1e-14);
        assert!((j - 1.0 / 6.0).abs() < 1e-13);
        let l = [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0)]
            .map(|(x, y)| Vector::<2>::new(x, y));
        let (a, c, j) = polygon_moments(&l);
        // Squares centred at (0.5, 0.5), (1.5, 0.5), (0.5, 1.5): centroid (5/6, 5/6).
        let centroid = Vector::<2>::new(5.0, 5.0) / 6.0;
        let expected: Real = [(0.5, 0.5), (1.5, 0.5), (0.5, 1.5)]
            .iter()
            .map(|&(x, y)| 1.0 / 6.0 + (Vector::<2>::new(x, y) - centroid).norm_squared())
            .sum();
        assert!((a - 3.0).abs() < 1e-14 && (c - centroid).norm() < 1e-14 && (j - expected).abs() < 1e-13);
    }

    /// A free body under gravity alone falls as g t²/2 and keeps turning at its angular velocity; an
    /// impulse J given to the material at a point r from the centre of mass changes its velocity by −J/m
    /// and its spin by −(r × J)/I.
    #[test]
    fn a_body_takes_gravity_and_the_opposite_of_the_impulses() {
        let centre = Vector::<2>::new(0.3, 0.4);
        let body = RigidBody::<2> { wall: 0, mass: 2.0, inertia: Matrix::<3>::from_diagonal_element(0.5), centre };
        let g = Vector::<2>::new(0.0, -9.81);
        let mut pose = WallPose::planar(0.0, [0.0, 0.0], 0.0, [0.0, 0.0], 1.5);
        let dt = 1e-3;
        for k in 0..1000 {
            pose = drift(&body.kick(&pose, k as Real * dt, dt, &g, &Vector::<2>::zeros(), &Vector::<3>::zeros()), dt);
        }
        // Symplectic Euler: y = −g dt² n(n+1)/2 after n steps.
        assert!((pose.position[1] + 9.81 * dt * dt * 1000.0 * 1001.0 / 2.0).abs() < 1e-12);
        assert!((pose.velocity[1] + 9.81).abs() < 1e-12 && (pose.angle[2] - 1.5).abs() < 1e-12);
        let (j, r) = (Vector::<2>::new(0.2, -0.1), Vector::<2>::new(0.1, 0.3));
        let still = WallPose::planar(1.0, [0.0, 0.0], 0.0, [0.0, 0.0], 0.0);
        let next = drift(&body.kick(&still, 1.0, dt, &Vector::<2>::zeros(), &j, &moment(&(centre + r), &j)), dt);
        assert!((Vector::<2>::from(next.velocity) + j / 2.0).norm() < 1e-15);
        assert!((next.angular_velocity[2] + (r.x * j.y - r.y * j.x) / 0.5).abs() < 1e-15);
    }
}
