//! Walls that move as rigid bodies: a wall's motion (`walls[i].motion` in scenes) gives its pose at any
//! time, a displacement of the wall from where the scene draws it and a rotation about a pivot. The
//! velocity of a wall point over a step is its displacement over the step divided by the step, so that
//! material moving with the wall ends the step where the wall does.

use crate::math::{Real, Vector};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

type Point = Vector<2>;

/// How a wall moves; the scene's drawing of the wall is its pose at time 0.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Motion {
    /// At a constant velocity and angular velocity (about the pivot, which moves with the wall).
    #[schemars(title = "ConstantMotion")]
    Constant {
        /// Velocity of the pivot.
        #[serde(default)]
        #[schemars(extend("unit" = "m/s", "unbounded" = true))]
        velocity: [Real; 2],
        /// Angular velocity, counter-clockwise.
        #[serde(default)]
        #[schemars(extend("unit" = "rad/s", "unbounded" = true))]
        angular_velocity: Real,
        /// The point the wall turns about, where the scene draws it (default: the wall's centre).
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        pivot: Option<[Real; 2]>,
    },
    /// Back and forth: displaced by `amplitude · (sin(2π f t + φ) − sin φ)` and turned by
    /// `angular_amplitude · (sin(2π f t + φ) − sin φ)` about the pivot.
    #[schemars(title = "OscillationMotion")]
    Oscillation {
        /// Largest displacement of the pivot along each axis.
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        amplitude: [Real; 2],
        /// Largest rotation about the pivot, counter-clockwise.
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        angular_amplitude: Real,
        /// Frequency f.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "Hz"))]
        frequency: Real,
        /// Phase φ at time 0.
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        phase: Real,
        /// The point the wall turns about, where the scene draws it (default: the wall's centre).
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        pivot: Option<[Real; 2]>,
    },
    /// Along a path through keyframes, linearly between them; held at the first before it and at the
    /// last after it.
    #[schemars(title = "KeyframeMotion")]
    Keyframes {
        /// Times of the keyframes, increasing.
        #[schemars(length(min = 1), extend("unit" = "s", "unbounded" = true))]
        times: Vec<Real>,
        /// Displacement of the pivot at each keyframe from where the scene draws it.
        #[schemars(length(min = 1), extend("unit" = "m", "unbounded" = true))]
        positions: Vec<[Real; 2]>,
        /// Rotation about the pivot at each keyframe, counter-clockwise (default: none).
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        angles: Option<Vec<Real>>,
        /// The point the wall turns about, where the scene draws it (default: the wall's centre).
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        pivot: Option<[Real; 2]>,
    },
}

/// Where a moving wall is: displaced by `offset` and turned by `angle` (rad, counter-clockwise)
/// about `pivot` (m, where the scene draws it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub pivot: Point,
    pub offset: Point,
    pub angle: Real,
}

impl Pose {
    /// The pose of a still wall.
    pub fn still(pivot: Point) -> Self {
        Self { pivot, offset: Point::zeros(), angle: 0.0 }
    }

    /// Where the point `p` of the scene's drawing is in this pose.
    pub fn place(&self, p: &Point) -> Point {
        let (s, c) = self.angle.sin_cos();
        let r = p - self.pivot;
        self.pivot + self.offset + Point::new(c * r.x - s * r.y, s * r.x + c * r.y)
    }

    /// Where the point `x` (in this pose) is in the scene's drawing.
    pub fn unplace(&self, x: &Point) -> Point {
        let (s, c) = self.angle.sin_cos();
        let r = x - self.pivot - self.offset;
        self.pivot + Point::new(c * r.x + s * r.y, -s * r.x + c * r.y)
    }

    /// A direction (a normal) of the drawing turned into this pose.
    pub fn turn(&self, n: &Point) -> Point {
        let (s, c) = self.angle.sin_cos();
        Point::new(c * n.x - s * n.y, s * n.x + c * n.y)
    }
}

/// A pose set from outside between steps (`Simulation::set_wall_pose`): at `time` (s) the wall's pivot
/// is displaced by `position` (m) from where the scene draws it and the wall is turned by `angle`; from
/// then on it moves at `velocity` (m/s) and turns at `angular_velocity` until set again.
///
/// Turns are rotation vectors (rad, rad/s): about their direction by their length. A 2D wall turns in
/// its plane, about z: its angle (counter-clockwise) is `angle[2]`, and the other components are zero
/// ([`WallPose::planar`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallPose<const D: usize> {
    pub time: Real,
    pub position: [Real; D],
    pub angle: [Real; 3],
    pub velocity: [Real; D],
    pub angular_velocity: [Real; 3],
}

impl<const D: usize> WallPose<D> {
    /// The names of its numbers in the order of a checkpoint row (after the wall's index): in 2D
    /// `angle` and `angular_velocity` are the turns about z.
    pub fn names() -> &'static [&'static str] {
        if D == 2 {
            &["time", "position_x", "position_y", "angle", "velocity_x", "velocity_y", "angular_velocity"]
        } else {
            &[
                "time",
                "position_x",
                "position_y",
                "position_z",
                "angle_x",
                "angle_y",
                "angle_z",
                "velocity_x",
                "velocity_y",
                "velocity_z",
                "angular_velocity_x",
                "angular_velocity_y",
                "angular_velocity_z",
            ]
        }
    }

    /// Its numbers, in the order of [`WallPose::names`].
    pub fn to_row(&self) -> Vec<Real> {
        let turns = |a: &[Real; 3]| if D == 2 { a[2..].to_vec() } else { a.to_vec() };
        let mut row = vec![self.time];
        row.extend_from_slice(&self.position);
        row.extend(turns(&self.angle));
        row.extend_from_slice(&self.velocity);
        row.extend(turns(&self.angular_velocity));
        row
    }

    /// The pose of a row of [`WallPose::to_row`] (as many numbers as [`WallPose::names`]).
    pub fn from_row(r: &[Real]) -> Self {
        assert_eq!(r.len(), Self::names().len(), "a wall pose row has one number per name");
        let k = if D == 2 { 1 } else { 3 };
        let turn = |a: &[Real]| if D == 2 { [0.0, 0.0, a[0]] } else { [a[0], a[1], a[2]] };
        Self {
            time: r[0],
            position: std::array::from_fn(|i| r[1 + i]),
            angle: turn(&r[1 + D..]),
            velocity: std::array::from_fn(|i| r[1 + D + k + i]),
            angular_velocity: turn(&r[1 + 2 * D + k..]),
        }
    }

    /// The largest speed (m/s) of a point at most `reach` (m) from the pivot.
    pub fn top_speed(&self, reach: Real) -> Real {
        let norm = |a: &[Real]| a.iter().map(|c| c * c).sum::<Real>().sqrt();
        norm(&self.velocity) + norm(&self.angular_velocity) * reach
    }

    /// The displacement (m) of the pivot at time `t` (s).
    pub fn offset(&self, t: Real) -> Vector<D> {
        Vector::<D>::from_fn(|i, _| self.position[i] + self.velocity[i] * (t - self.time))
    }

    /// The turn at time `t` (s): `angle`, then `angular_velocity` × (t − `time`).
    pub fn rotation(&self, t: Real) -> nalgebra::Rotation3<Real> {
        nalgebra::Rotation3::new(P3::from(self.angular_velocity) * (t - self.time))
            * nalgebra::Rotation3::new(P3::from(self.angle))
    }

    /// The turn at time `t` (s) as a rotation vector (rad; in 2D the angle about z, summed exactly).
    pub fn turn(&self, t: Real) -> [Real; 3] {
        if D == 2 {
            [0.0, 0.0, self.angle[2] + self.angular_velocity[2] * (t - self.time)]
        } else {
            self.rotation(t).scaled_axis().into()
        }
    }
}

impl WallPose<2> {
    /// A 2D pose: turned by `angle` (rad, counter-clockwise), turning at `angular_velocity` (rad/s).
    pub fn planar(time: Real, position: [Real; 2], angle: Real, velocity: [Real; 2], angular_velocity: Real) -> Self {
        Self { time, position, angle: [0.0, 0.0, angle], velocity, angular_velocity: [0.0, 0.0, angular_velocity] }
    }

    /// The pose at time `t` (s) of a wall turning about `pivot`.
    pub fn pose(&self, t: Real, pivot: Point) -> Pose {
        Pose { pivot, offset: self.offset(t), angle: self.turn(t)[2] }
    }
}

impl WallPose<3> {
    /// The pose at time `t` (s) of a wall turning about `pivot`: turned by `angle`, then by
    /// `angular_velocity` × (t − `time`).
    pub fn pose3(&self, t: Real, pivot: P3) -> Pose3 {
        Pose3 { pivot, offset: self.offset(t), rotation: self.rotation(t).into_inner() }
    }
}

/// The factor `sin(2π f t + φ) − sin φ` of an oscillation's displacement and turn at time `t` (s).
fn swing(t: Real, frequency: Real, phase: Real) -> Real {
    (2.0 * crate::math::PI * frequency * t + phase).sin() - phase.sin()
}

/// Where time `t` (s) falls among increasing keyframe `times`: at keyframe `k` with weight 0 (before the
/// first, after the last, or on one), or `u` of the way from keyframe `k` to `k + 1`.
fn keyframe(times: &[Real], t: Real) -> (usize, Real) {
    let last = times.len() - 1;
    if t <= times[0] {
        (0, 0.0)
    } else if t >= times[last] {
        (last, 0.0)
    } else {
        let k = times.partition_point(|&tk| tk <= t) - 1;
        (k, (t - times[k]) / (times[k + 1] - times[k]))
    }
}

/// The largest speed of a path through keyframes: `step(k)` is the distance from keyframe `k − 1` to `k`.
fn keyframe_speed(times: &[Real], step: impl Fn(usize) -> Real) -> Real {
    (1..times.len()).map(|k| step(k) / (times[k] - times[k - 1])).fold(0.0, Real::max)
}

/// Checks what the schema cannot: keyframes in increasing time, one position (and rotation) each.
fn check_keyframes(
    times: &[Real],
    positions: usize,
    turns: Option<(&'static str, usize)>,
) -> Result<(), (&'static str, String)> {
    if positions != times.len() {
        return Err(("positions", format!("{positions} positions for {} times", times.len())));
    }
    if let Some((key, n)) = turns.filter(|&(_, n)| n != times.len()) {
        return Err((key, format!("{n} {key} for {} times", times.len())));
    }
    if let Some(k) = (1..times.len()).find(|&k| times[k] <= times[k - 1]) {
        return Err(("times", format!("times must increase: {} follows {}", times[k], times[k - 1])));
    }
    Ok(())
}

impl Motion {
    /// The pivot, if the scene gives one.
    pub fn pivot(&self) -> Option<[Real; 2]> {
        match self {
            Motion::Constant { pivot, .. } | Motion::Oscillation { pivot, .. } | Motion::Keyframes { pivot, .. } => {
                *pivot
            }
        }
    }

    /// The pose at time `t` (s) of a wall whose centre is `centre` (the pivot unless one is given).
    pub fn pose(&self, t: Real, centre: Point) -> Pose {
        let pivot = self.pivot().map_or(centre, |p| Point::new(p[0], p[1]));
        let (offset, angle) = match self {
            Motion::Constant { velocity, angular_velocity, .. } => {
                (Point::new(velocity[0], velocity[1]) * t, angular_velocity * t)
            }
            Motion::Oscillation { amplitude, angular_amplitude, frequency, phase, .. } => {
                let s = swing(t, *frequency, *phase);
                (Point::new(amplitude[0], amplitude[1]) * s, angular_amplitude * s)
            }
            Motion::Keyframes { times, positions, angles, .. } => {
                let angle_at = |k: usize| angles.as_ref().map_or(0.0, |a| a[k]);
                let at = |k: usize| (Point::new(positions[k][0], positions[k][1]), angle_at(k));
                let (k, u) = keyframe(times, t);
                if u == 0.0 {
                    at(k)
                } else {
                    let ((p0, a0), (p1, a1)) = (at(k), at(k + 1));
                    (p0 + (p1 - p0) * u, a0 + (a1 - a0) * u)
                }
            }
        };
        Pose { pivot, offset, angle }
    }

    /// The largest speed (m/s) of a point at most `reach` (m) from the pivot: a bound the time step
    /// must keep below a cell per step.
    pub fn top_speed(&self, reach: Real) -> Real {
        match self {
            Motion::Constant { velocity, angular_velocity, .. } => {
                Point::new(velocity[0], velocity[1]).norm() + angular_velocity.abs() * reach
            }
            Motion::Oscillation { amplitude, angular_amplitude, frequency, .. } => {
                2.0 * crate::math::PI
                    * frequency
                    * (Point::new(amplitude[0], amplitude[1]).norm() + angular_amplitude.abs() * reach)
            }
            Motion::Keyframes { times, positions, angles, .. } => keyframe_speed(times, |k| {
                let dp = Point::new(positions[k][0] - positions[k - 1][0], positions[k][1] - positions[k - 1][1]);
                let da = angles.as_ref().map_or(0.0, |a| a[k] - a[k - 1]);
                dp.norm() + da.abs() * reach
            }),
        }
    }

    /// Checks what the schema cannot: keyframes in increasing time, one position (and angle) each.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        match self {
            Motion::Keyframes { times, positions, angles, .. } => {
                check_keyframes(times, positions.len(), angles.as_ref().map(|a| ("angles", a.len())))
            }
            _ => Ok(()),
        }
    }
}

type P3 = Vector<3>;

/// How a 3D wall moves; the scene's drawing of the wall is its pose at time 0. A turn is a rotation
/// vector: its direction the axis (right-handed), its length the angle (rad).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Motion3 {
    /// At a constant velocity and angular velocity (about the pivot, which moves with the wall).
    #[schemars(title = "ConstantMotion3")]
    Constant {
        /// Velocity of the pivot.
        #[serde(default)]
        #[schemars(extend("unit" = "m/s", "unbounded" = true))]
        velocity: [Real; 3],
        /// Angular velocity: about its direction, at its length.
        #[serde(default)]
        #[schemars(extend("unit" = "rad/s", "unbounded" = true))]
        angular_velocity: [Real; 3],
        /// The point the wall turns about, where the scene draws it (default: the wall's centre).
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        pivot: Option<[Real; 3]>,
    },
    /// Back and forth: displaced by `amplitude · (sin(2π f t + φ) − sin φ)` and turned by the rotation
    /// vector `angular_amplitude · (sin(2π f t + φ) − sin φ)` about the pivot.
    #[schemars(title = "OscillationMotion3")]
    Oscillation {
        /// Largest displacement of the pivot along each axis.
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        amplitude: [Real; 3],
        /// Largest turn about the pivot, as a rotation vector.
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        angular_amplitude: [Real; 3],
        /// Frequency f.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "Hz"))]
        frequency: Real,
        /// Phase φ at time 0.
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        phase: Real,
        /// The point the wall turns about, where the scene draws it (default: the wall's centre).
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        pivot: Option<[Real; 3]>,
    },
    /// Along a path through keyframes, linearly between them (the rotation vectors too); held at the
    /// first before it and at the last after it.
    #[schemars(title = "KeyframeMotion3")]
    Keyframes {
        /// Times of the keyframes, increasing.
        #[schemars(length(min = 1), extend("unit" = "s", "unbounded" = true))]
        times: Vec<Real>,
        /// Displacement of the pivot at each keyframe from where the scene draws it.
        #[schemars(length(min = 1), extend("unit" = "m", "unbounded" = true))]
        positions: Vec<[Real; 3]>,
        /// Turn about the pivot at each keyframe, as a rotation vector (default: none).
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        rotations: Option<Vec<[Real; 3]>>,
        /// The point the wall turns about, where the scene draws it (default: the wall's centre).
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        pivot: Option<[Real; 3]>,
    },
}

/// Where a moving 3D wall is: displaced by `offset` and turned by `rotation` about `pivot` (m, where the
/// scene draws it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose3 {
    pub pivot: P3,
    pub offset: P3,
    pub rotation: crate::math::Matrix<3>,
}

impl Pose3 {
    /// The pose of a still wall.
    pub fn still(pivot: P3) -> Self {
        Self { pivot, offset: P3::zeros(), rotation: crate::math::Matrix::<3>::identity() }
    }

    /// The pose displaced by `offset` and turned by the rotation vector `turn` about `pivot`.
    fn new(pivot: P3, offset: P3, turn: P3) -> Self {
        Self { pivot, offset, rotation: nalgebra::Rotation3::new(turn).into_inner() }
    }

    /// Where the point `p` of the scene's drawing is in this pose.
    pub fn place(&self, p: &P3) -> P3 {
        self.pivot + self.offset + self.rotation * (p - self.pivot)
    }

    /// Where the point `x` (in this pose) is in the scene's drawing.
    pub fn unplace(&self, x: &P3) -> P3 {
        self.pivot + self.rotation.transpose() * (x - self.pivot - self.offset)
    }

    /// A direction (a normal) of the drawing turned into this pose.
    pub fn turn(&self, n: &P3) -> P3 {
        self.rotation * n
    }

    /// A bound on how far (m) a point at most `reach` (m) from the pivot moves from this pose to `other`
    /// (with the same pivot): the pivot's move plus ‖R₂ − R₁‖ `reach` (the Frobenius norm bounds the
    /// turn's effect on any point at `reach`, without the rounding of an angle near zero).
    pub fn distance_to(&self, other: &Pose3, reach: Real) -> Real {
        (other.offset - self.offset).norm() + (other.rotation - self.rotation).norm() * reach
    }
}

impl Motion3 {
    /// The pivot, if the scene gives one.
    pub fn pivot(&self) -> Option<[Real; 3]> {
        match self {
            Motion3::Constant { pivot, .. } | Motion3::Oscillation { pivot, .. } | Motion3::Keyframes { pivot, .. } => {
                *pivot
            }
        }
    }

    /// The pose at time `t` (s) of a wall whose centre is `centre` (the pivot unless one is given).
    pub fn pose(&self, t: Real, centre: P3) -> Pose3 {
        let pivot = self.pivot().map_or(centre, P3::from);
        let (offset, turn) = match self {
            Motion3::Constant { velocity, angular_velocity, .. } => {
                (P3::from(*velocity) * t, P3::from(*angular_velocity) * t)
            }
            Motion3::Oscillation { amplitude, angular_amplitude, frequency, phase, .. } => {
                let s = swing(t, *frequency, *phase);
                (P3::from(*amplitude) * s, P3::from(*angular_amplitude) * s)
            }
            Motion3::Keyframes { times, positions, rotations, .. } => {
                let at =
                    |k: usize| (P3::from(positions[k]), rotations.as_ref().map_or(P3::zeros(), |r| P3::from(r[k])));
                let (k, u) = keyframe(times, t);
                if u == 0.0 {
                    at(k)
                } else {
                    let ((p0, r0), (p1, r1)) = (at(k), at(k + 1));
                    (p0 + (p1 - p0) * u, r0 + (r1 - r0) * u)
                }
            }
        };
        Pose3::new(pivot, offset, turn)
    }

    /// The largest speed (m/s) of a point at most `reach` (m) from the pivot: a bound the time step must
    /// keep below a cell per step.
    pub fn top_speed(&self, reach: Real) -> Real {
        match self {
            Motion3::Constant { velocity, angular_velocity, .. } => {
                P3::from(*velocity).norm() + P3::from(*angular_velocity).norm() * reach
            }
            Motion3::Oscillation { amplitude, angular_amplitude, frequency, .. } => {
                2.0 * crate::math::PI
                    * frequency
                    * (P3::from(*amplitude).norm() + P3::from(*angular_amplitude).norm() * reach)
            }
            // Between keyframes the rotation vector moves linearly; the angle turned is at most its change.
            Motion3::Keyframes { times, positions, rotations, .. } => keyframe_speed(times, |k| {
                let dp = P3::from(positions[k]) - P3::from(positions[k - 1]);
                let dr = rotations.as_ref().map_or(0.0, |r| (P3::from(r[k]) - P3::from(r[k - 1])).norm());
                dp.norm() + dr * reach
            }),
        }
    }

    /// Checks what the schema cannot: keyframes in increasing time, one position (and rotation) each.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        match self {
            Motion3::Keyframes { times, positions, rotations, .. } => {
                check_keyframes(times, positions.len(), rotations.as_ref().map(|r| ("rotations", r.len())))
            }
            _ => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pose places a drawn point and takes it back; turning a quarter about the pivot (1, 0) takes
    /// (2, 0) to (1, 1).
    #[test]
    fn a_pose_places_and_unplaces_points() {
        let pose = Pose { pivot: Point::new(1.0, 0.0), offset: Point::new(0.5, 0.0), angle: crate::math::PI / 2.0 };
        let p = Point::new(2.0, 0.0);
        assert!((pose.place(&p) - Point::new(1.5, 1.0)).norm() < 1e-15);
        assert!((pose.unplace(&pose.place(&p)) - p).norm() < 1e-15);
        assert!((pose.turn(&Point::new(1.0, 0.0)) - Point::new(0.0, 1.0)).norm() < 1e-15);
    }

    /// Keyframes are followed linearly between them and held outside them; an oscillation starts
    /// where the scene draws the wall.
    #[test]
    fn keyframes_and_oscillations_follow_their_paths() {
        let path = Motion::Keyframes {
            times: vec![0.0, 1.0, 3.0],
            positions: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]],
            angles: Some(vec![0.0, 0.0, 1.0]),
            pivot: None,
        };
        assert!(path.validate().is_ok());
        let c = Point::new(0.5, 0.5);
        let at = |t| path.pose(t, c);
        assert!((at(0.5).offset - Point::new(0.5, 0.0)).norm() < 1e-15);
        assert!((at(2.0).offset - Point::new(1.0, 1.0)).norm() < 1e-15 && (at(2.0).angle - 0.5).abs() < 1e-15);
        assert_eq!(at(5.0).offset, Point::new(1.0, 2.0));
        assert_eq!(at(-1.0).offset, Point::zeros());
        // 1 m in the first second, then √(0 + 4) m + 1 rad · 2 m in two seconds.
        assert!((path.top_speed(2.0) - 2.0).abs() < 1e-12);
        let shake = Motion::Oscillation {
            amplitude: [0.1, 0.0],
            angular_amplitude: 0.0,
            frequency: 2.0,
            phase: 0.3,
            pivot: None,
        };
        assert_eq!(shake.pose(0.0, c).offset, Point::zeros());
        assert!((shake.pose(0.5, c).offset.x).abs() < 1e-12, "a whole period later it is back");
        let bad = Motion::Keyframes { times: vec![0.0, 0.0], positions: vec![[0.0; 2]; 2], angles: None, pivot: None };
        assert_eq!(bad.validate().unwrap_err().0, "times");
    }

    /// A 3D pose places a drawn point and takes it back; a quarter turn about z through the pivot (1, 0, 0)
    /// takes (2, 0, 0) to (1, 1, 0); a constant motion turns at its angular velocity, and the bound on a
    /// point's move is the pivot's move plus angle times reach.
    #[test]
    fn a_3d_pose_places_unplaces_and_turns() {
        let half_pi = crate::math::PI / 2.0;
        let pose = Pose3::new(P3::new(1.0, 0.0, 0.0), P3::new(0.5, 0.0, 0.0), P3::new(0.0, 0.0, half_pi));
        let x = pose.place(&P3::new(2.0, 0.0, 0.0));
        assert!((x - P3::new(1.5, 1.0, 0.0)).norm() < 1e-14);
        assert!((pose.unplace(&x) - P3::new(2.0, 0.0, 0.0)).norm() < 1e-14);
        let spin = Motion3::Constant { velocity: [0.0, 0.0, 1.0], angular_velocity: [0.0, 2.0, 0.0], pivot: None };
        let (a, b) = (spin.pose(0.1, P3::zeros()), spin.pose(0.3, P3::zeros()));
        // Turned by 0.4 rad about y: ‖R₂ − R₁‖ = 2√2 sin(0.2), at least the chord 2 sin(0.2) of a point at 1.
        let chord = 2.0 * (0.2 as Real).sin();
        assert!((a.distance_to(&b, 1.5) - (0.2 + 2.0_f64.sqrt() * chord * 1.5)).abs() < 1e-12);
        assert!((spin.top_speed(1.5) - (1.0 + 2.0 * 1.5)).abs() < 1e-12);
        let bad = Motion3::Keyframes { times: vec![0.0, 1.0], positions: vec![[0.0; 3]], rotations: None, pivot: None };
        assert_eq!(bad.validate().unwrap_err().0, "positions");
    }
}
