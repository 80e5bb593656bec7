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
/// is displaced by `position` (m) from where the scene draws it and the wall is turned by `angle`
/// (rad, counter-clockwise); from then on it moves at `velocity` (m/s) and `angular_velocity`
/// (rad/s) until set again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallPose {
    pub time: Real,
    pub position: [Real; 2],
    pub angle: Real,
    pub velocity: [Real; 2],
    pub angular_velocity: Real,
}

impl WallPose {
    /// Its numbers in the order of a checkpoint row (after the wall's index).
    pub const NAMES: [&'static str; 7] =
        ["time", "position_x", "position_y", "angle", "velocity_x", "velocity_y", "angular_velocity"];

    /// The pose at time `t` (s) of a wall turning about `pivot`.
    pub fn pose(&self, t: Real, pivot: Point) -> Pose {
        let s = t - self.time;
        let offset = Point::new(self.position[0] + self.velocity[0] * s, self.position[1] + self.velocity[1] * s);
        Pose { pivot, offset, angle: self.angle + self.angular_velocity * s }
    }

    /// The largest speed (m/s) of a point at most `reach` (m) from the pivot.
    pub fn top_speed(&self, reach: Real) -> Real {
        Point::new(self.velocity[0], self.velocity[1]).norm() + self.angular_velocity.abs() * reach
    }

    /// Its numbers, in the order of [`WallPose::NAMES`].
    pub fn to_row(&self) -> [Real; 7] {
        let [px, py] = self.position;
        let [vx, vy] = self.velocity;
        [self.time, px, py, self.angle, vx, vy, self.angular_velocity]
    }

    /// The pose of a row of [`WallPose::to_row`].
    pub fn from_row(r: [Real; 7]) -> Self {
        Self { time: r[0], position: [r[1], r[2]], angle: r[3], velocity: [r[4], r[5]], angular_velocity: r[6] }
    }
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
                let s = (2.0 * crate::math::PI * frequency * t + phase).sin() - phase.sin();
                (Point::new(amplitude[0], amplitude[1]) * s, angular_amplitude * s)
            }
            Motion::Keyframes { times, positions, angles, .. } => {
                let angle_at = |k: usize| angles.as_ref().map_or(0.0, |a| a[k]);
                let at = |k: usize| (Point::new(positions[k][0], positions[k][1]), angle_at(k));
                let last = times.len() - 1;
                if t <= times[0] {
                    at(0)
                } else if t >= times[last] {
                    at(last)
                } else {
                    let k = times.partition_point(|&tk| tk <= t) - 1;
                    let u = (t - times[k]) / (times[k + 1] - times[k]);
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
            Motion::Keyframes { times, positions, angles, .. } => (1..times.len())
                .map(|k| {
                    let dp = Point::new(positions[k][0] - positions[k - 1][0], positions[k][1] - positions[k - 1][1]);
                    let da = angles.as_ref().map_or(0.0, |a| a[k] - a[k - 1]);
                    (dp.norm() + da.abs() * reach) / (times[k] - times[k - 1])
                })
                .fold(0.0, Real::max),
        }
    }

    /// Checks what the schema cannot: keyframes in increasing time, one position (and angle) each.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if let Motion::Keyframes { times, positions, angles, .. } = self {
            if positions.len() != times.len() {
                return Err(("positions", format!("{} positions for {} times", positions.len(), times.len())));
            }
            if let Some(a) = angles {
                if a.len() != times.len() {
                    return Err(("angles", format!("{} angles for {} times", a.len(), times.len())));
                }
            }
            if let Some(k) = (1..times.len()).find(|&k| times[k] <= times[k - 1]) {
                return Err(("times", format!("times must increase: {} follows {}", times[k], times[k - 1])));
            }
        }
        Ok(())
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
}
