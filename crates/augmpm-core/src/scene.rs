//! Scene description (the resolved form of a scene file) and how a 2D
//! simulation is built from it: validation, walls, particle seeding.

use crate::contact::{Contact, Contacts, Contacts2, Hinge};
use crate::geometry::{Circle, Point, Polygon, Region, Side, Stroke, SurfaceMotion, WallShape, Walls2};
use crate::grid::GridLayout;
use crate::material::Material;
use crate::math::{Precision, Real};
use crate::motion::{Motion, WallPose};
use crate::particles::Particles;
use crate::rigid::RigidBody;
use crate::simulation::{Model, Simulation};
use crate::treatment::augmented::{AugmentedGrid, AugmentedTransfer};
use crate::treatment::naive::NaiveBoundary;
use crate::treatment::{Boundary, Method};
use crate::wall::{WallCondition, WallContact};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A scene that cannot be built: the key (dotted path) and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{key}: {reason}")]
pub struct SceneError {
    pub key: String,
    pub reason: String,
}

impl SceneError {
    pub fn new(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self { key: key.into(), reason: reason.into() }
    }
}

// Every scene key is declared here once, with its doc line, default, range and unit: the JSON Schema
// that `parameters::scene_schema` exports from these types is what Rust and Python validate against
// and what the README's scene reference is generated from. Conventions: `unit` on every number
// ("1" when dimensionless, "h" for cell widths), bounds as JSON Schema keywords, or `unbounded` for
// a number that may be any finite value.

/// The background grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Size of the domain box [0, Lx] × [0, Ly], always a wall.
    #[schemars(extend("unit" = "m"), transform = items_positive)]
    pub domain: [Real; 2],
    /// Cells along x: h = Lx / resolution; Ly must be a whole number of cells.
    #[schemars(range(min = 2, max = 65536), extend("unit" = "cells"))]
    pub resolution: usize,
    /// Correct the fluid density gathered next to walls for the part of the kernel that lies in the
    /// wall (for `density_estimate = "grid"`; off by default, as in the paper).
    #[serde(default)]
    pub density_wall_correction: bool,
}

/// Time stepping: exactly one of `dt` and `cfl`, exactly one of `steps` and `end`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TimeSpec {
    /// Time step.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "s"))]
    pub dt: Option<Real>,
    /// Time step as a fraction of the materials' stable step (one cell per step at the wave speed, and
    /// the viscous limit).
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "maximum" = 1.0, "unit" = "1"))]
    pub cfl: Option<Real>,
    /// Steps to run.
    #[serde(default)]
    #[schemars(extend("maximum" = 9_223_372_036_854_775_807u64, "unit" = "steps"))]
    pub steps: Option<u64>,
    /// End time: the run takes ⌈end / dt⌉ steps.
    #[serde(default)]
    #[schemars(extend("minimum" = 0.0, "unit" = "s"))]
    pub end: Option<Real>,
    /// Steps between output frames.
    #[schemars(extend("minimum" = 1, "maximum" = 9_223_372_036_854_775_807u64, "unit" = "steps"))]
    pub output_interval: u64,
}

/// A wall; the domain box is always one more.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum WallSpec {
    /// A closed polygon, counter-clockwise, material `inside` it (a container, the default) or `outside` it
    /// (an obstacle).
    #[schemars(title = "PolygonWall")]
    Polygon {
        /// Corners, counter-clockwise; the first may be repeated at the end.
        #[schemars(length(min = 3), extend("unit" = "m", "unbounded" = true))]
        vertices: Vec<[Real; 2]>,
        /// Where the material is: `inside` the polygon (a container) or `outside` (an obstacle).
        #[serde(default = "inside")]
        side: SideSpec,
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
        /// Velocity of the wall's surface; only its part along the wall acts (it turns with a moving wall).
        #[serde(default)]
        #[schemars(extend("unit" = "m/s", "unbounded" = true))]
        velocity: [Real; 2],
        /// Speed of the surface counter-clockwise along the polygon (a belt loop).
        #[serde(default)]
        #[schemars(extend("unit" = "m/s", "unbounded" = true))]
        tangential_speed: Real,
        /// How the wall moves as a rigid body (default: it stays where the scene draws it).
        #[serde(default)]
        motion: Option<Motion>,
    },
    /// A circle, material `outside` it (an obstacle, the default) or `inside` it (a container).
    #[schemars(title = "CircleWall")]
    Circle {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 2],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
        /// Where the material is: `outside` the circle (an obstacle) or `inside` (a container).
        #[serde(default = "default_side")]
        side: SideSpec,
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
        /// Velocity of the wall's surface; only its part along the wall acts (it turns with a moving wall).
        #[serde(default)]
        #[schemars(extend("unit" = "m/s", "unbounded" = true))]
        velocity: [Real; 2],
        /// Speed of the surface counter-clockwise around the centre (a spinning cylinder).
        #[serde(default)]
        #[schemars(extend("unit" = "m/s", "unbounded" = true))]
        tangential_speed: Real,
        /// How the wall moves as a rigid body (default: it stays where the scene draws it).
        #[serde(default)]
        motion: Option<Motion>,
    },
    /// An open polyline drawn `thickness` wide (round ends and joints), material all around it: a plate,
    /// a ramp, a paddle.
    #[schemars(title = "PolylineWall")]
    Polyline {
        /// Points of the centreline, in order; consecutive points distinct.
        #[schemars(length(min = 2), extend("unit" = "m", "unbounded" = true))]
        vertices: Vec<[Real; 2]>,
        /// Width of the wall (at least about 3 cells keeps material on one side from the grid points of
        /// the other).
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        thickness: Real,
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
        /// How the wall moves as a rigid body (default: it stays where the scene draws it).
        #[serde(default)]
        motion: Option<Motion>,
    },
}

impl WallSpec {
    /// The wall's own condition, if it names one.
    pub fn condition(&self) -> Option<WallCondition> {
        match self {
            WallSpec::Polygon { condition, .. }
            | WallSpec::Circle { condition, .. }
            | WallSpec::Polyline { condition, .. } => *condition,
        }
    }

    /// The wall's own friction coefficient, if it names one.
    pub fn friction(&self) -> Option<Real> {
        match self {
            WallSpec::Polygon { friction, .. }
            | WallSpec::Circle { friction, .. }
            | WallSpec::Polyline { friction, .. } => *friction,
        }
    }

    /// How the wall moves, if it does.
    pub fn motion(&self) -> Option<&Motion> {
        match self {
            WallSpec::Polygon { motion, .. } | WallSpec::Circle { motion, .. } | WallSpec::Polyline { motion, .. } => {
                motion.as_ref()
            }
        }
    }
}

/// Which side of a wall the material is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum SideSpec {
    /// Around the wall: an obstacle.
    Outside,
    /// In the wall: a container.
    Inside,
}

pub(crate) fn default_side() -> SideSpec {
    SideSpec::Outside
}

pub(crate) fn inside() -> SideSpec {
    SideSpec::Inside
}

/// Geometry of a body.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "shape", rename_all = "lowercase")]
pub enum BodyShape {
    /// A polygon in a local frame, placed at `center + scale · vertex`; counter-clockwise.
    #[schemars(title = "PolygonBody")]
    Polygon {
        /// Corners in the local frame, counter-clockwise.
        #[schemars(length(min = 3), extend("unit" = "m", "unbounded" = true))]
        vertices: Vec<[Real; 2]>,
        /// Scale of the local frame.
        #[serde(default = "one")]
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "1"))]
        scale: Real,
        /// Where the local frame's origin goes.
        #[serde(default)]
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 2],
    },
    /// An axis-aligned box.
    #[schemars(title = "BoxBody")]
    Box {
        /// Lower-left corner.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        min: [Real; 2],
        /// Upper-right corner, above and right of `min`.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        max: [Real; 2],
    },
    /// A disk.
    #[schemars(title = "CircleBody")]
    Circle {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 2],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
    },
}

pub(crate) fn one() -> Real {
    1.0
}

/// Jittered-grid seeding: one random point per square of side `spacing`, or `per_cell` points per
/// grid cell on average (spacing h/√per_cell); 4 per cell when neither is given.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Seeding {
    /// Side of the squares that get one particle each.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
    pub spacing: Option<Real>,
    /// Particles per grid cell, on average.
    #[serde(default)]
    #[schemars(range(min = 1, max = 1024), extend("unit" = "1"))]
    pub per_cell: Option<u32>,
}

/// A body of material: a shape, its material, its initial velocity and how it is seeded.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct BodySpec {
    #[serde(flatten)]
    pub shape: BodyShape,
    /// The body's material, chosen by `type`.
    pub material: Material,
    /// Initial velocity.
    #[serde(default)]
    #[schemars(extend("unit" = "m/s", "unbounded" = true))]
    pub velocity: [Real; 2],
    /// How particles are placed in the body.
    #[serde(default)]
    pub seeding: Seeding,
    /// Seed only the part of the body inside the material region (clipped by the walls: a body poured
    /// around an obstacle) instead of refusing a body that reaches past a wall.
    #[serde(default)]
    pub fill: bool,
}

/// The shape of a rigid body: a solid polygon or disk (the material stays outside it).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "shape", rename_all = "lowercase")]
pub enum RigidShape {
    /// A simple polygon.
    #[schemars(title = "PolygonRigidBody")]
    Polygon {
        /// Corners, counter-clockwise; the first may be repeated at the end.
        #[schemars(length(min = 3), extend("unit" = "m", "unbounded" = true))]
        vertices: Vec<[Real; 2]>,
    },
    /// A disk.
    #[schemars(title = "CircleRigidBody")]
    Circle {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 2],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
    },
}

/// A rigid body that the material pushes and that pushes it back: a solid shape of uniform density whose
/// surface is a moving wall; gravity and the impulse of its wall conditions move it. It meets the other
/// bodies and the scene's walls in contacts (rapier), and may turn about a hinge.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RigidBodySpec {
    #[serde(flatten)]
    pub shape: RigidShape,
    /// Density (kg/m², per metre of depth); give it or `mass`.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg/m²"))]
    pub density: Option<Real>,
    /// Mass (kg per metre of depth); give it or `density`.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg/m"))]
    pub mass: Option<Real>,
    /// Initial velocity of its centre of mass.
    #[serde(default)]
    #[schemars(extend("unit" = "m/s", "unbounded" = true))]
    pub velocity: [Real; 2],
    /// Initial angular velocity, counter-clockwise.
    #[serde(default)]
    #[schemars(extend("unit" = "rad/s", "unbounded" = true))]
    pub angular_velocity: Real,
    #[serde(flatten)]
    pub surface: RigidSurfaceSpec,
    /// A point fixed in the scene that the body turns about: an axle, a hinge. Its centre then moves as
    /// its `angular_velocity` turns it about the hinge (leave `velocity` out). With `hinge_to`, the point
    /// is fixed in that body instead, and `velocity` is the body's own.
    #[serde(default)]
    #[schemars(extend("unit" = "m", "unbounded" = true))]
    pub hinge: Option<[Real; 2]>,
    /// The body (its index in `rigid_bodies`) that this body's `hinge` point is fixed in, where the scene
    /// draws it: a wheel on a cart's axle, the links of a chain. The two do not meet in contacts. This body
    /// starts with the `velocity` and `angular_velocity` it is given: give them so that the hinge point
    /// moves alike in both bodies, or the joint evens them out in the first step.
    #[serde(default)]
    #[schemars(extend("unit" = "1"))]
    pub hinge_to: Option<usize>,
}

/// A rigid body's surface (2D and 3D): how the material meets it, as a wall, and how the other bodies and
/// the walls meet it (rapier's contacts).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RigidSurfaceSpec {
    /// Its surface's condition (default: the scene's `wall_condition`).
    #[serde(default)]
    pub condition: Option<WallCondition>,
    /// Coulomb friction coefficient μ of a `separate` surface (default: the scene's `wall_friction`).
    #[serde(default, with = "friction::optional")]
    #[schemars(schema_with = "friction::optional_schema")]
    pub friction: Option<Real>,
    /// Coulomb friction coefficient of its contacts with other bodies and the walls; a contact takes the
    /// larger of its two sides' (a wall's is 0).
    #[serde(default = "default_contact_friction")]
    #[schemars(extend("minimum" = 0.0, "unit" = "1"))]
    pub contact_friction: Real,
    /// Restitution of its contacts with other bodies and the walls: 0 stops them, 1 bounces elastically;
    /// a contact takes the larger of its two sides'.
    #[serde(default)]
    #[schemars(extend("minimum" = 0.0, "maximum" = 1.0, "unit" = "1"))]
    pub restitution: Real,
}

fn default_contact_friction() -> Real {
    0.5
}

impl RigidSurfaceSpec {
    /// Its condition, the scene's `default` unless it names one; friction on a surface that is not
    /// separate is refused, naming `key`'s `friction`.
    pub(crate) fn condition(&self, key: &str, default: WallCondition) -> Result<WallCondition, SceneError> {
        let condition = self.condition.unwrap_or(default);
        if self.friction.is_some_and(|mu| mu > 0.0) && condition != WallCondition::Separate {
            return Err(SceneError::new(
                format!("{key}.friction"),
                format!("friction acts on separate surfaces; this body's is {condition:?}").to_lowercase(),
            ));
        }
        Ok(condition)
    }

    /// How the body meets other bodies and the walls, turning about `hinge` if it has one, in the scene or
    /// in the body `hinge_to`.
    pub(crate) fn contact(&self, hinge: Option<Hinge>, hinge_to: Option<usize>) -> Contact {
        Contact { friction: self.contact_friction, restitution: self.restitution, hinge, hinge_to }
    }
}

/// Refuses the `hinge_to` of `rigid_bodies[k]` (`hinged_to`: every body's `hinge_to`) that names no other
/// body, names a body hinged back to this one (one hinge joins two bodies; longer loops are linkages and
/// stay allowed) or comes without its hinge point (`hinge`); `key` is the body's.
pub(crate) fn check_hinge_to(key: &str, k: usize, hinged_to: &[Option<usize>], hinge: bool) -> Result<(), SceneError> {
    let Some(to) = hinged_to[k] else { return Ok(()) };
    let key = format!("{key}.hinge_to");
    let n = hinged_to.len();
    if to >= n {
        let bodies = if n == 1 { "1 rigid body".to_string() } else { format!("{n} rigid bodies") };
        return Err(SceneError::new(key, format!("names rigid_bodies[{to}]; the scene has {bodies}")));
    }
    if to == k {
        return Err(SceneError::new(key, "a body cannot be hinged to itself"));
    }
    if hinged_to[to] == Some(k) {
        return Err(SceneError::new(
            key,
            format!("rigid_bodies[{to}] is hinged to this body already; one hinge joins two bodies"),
        ));
    }
    if !hinge {
        return Err(SceneError::new(key, "give the point the two bodies turn about with hinge"));
    }
    Ok(())
}

impl RigidBodySpec {
    /// The initial velocity (m/s) of its centre of mass at `centre` (m): about its hinge if that is fixed
    /// in the scene, else `velocity`.
    fn initial_velocity(&self, centre: &Point) -> [Real; 2] {
        match (self.hinge, self.hinge_to) {
            (Some(hinge), None) => {
                let r = centre - point(&hinge);
                [-self.angular_velocity * r.y, self.angular_velocity * r.x]
            }
            _ => self.velocity,
        }
    }

    /// Its wall as drawn, its mass (kg/m), polar inertia about its centre of mass (kg·m²/m) and its centre
    /// of mass (m); an error names `key` for a polygon that is not simple and counter-clockwise, or
    /// neither or both of `density` and `mass`.
    fn solid(&self, key: &str) -> Result<(WallShape, Real, Real, Point), SceneError> {
        let (shape, area, polar, centre) = match &self.shape {
            RigidShape::Polygon { vertices } => {
                let poly = checked_polygon(&format!("{key}.vertices"), vertices.iter().map(point).collect())?;
                let (area, centre, polar) = crate::rigid::polygon_moments(&poly.vertices);
                (WallShape::Obstacle(poly), area, polar, centre)
            }
            RigidShape::Circle { center, radius } => {
                let area = crate::math::PI * radius * radius;
                let circle = Circle { center: point(center), radius: *radius };
                (WallShape::Circle(circle, Side::Outside), area, 0.5 * area * radius * radius, point(center))
            }
        };
        let density = match (self.density, self.mass) {
            (Some(rho), None) => rho,
            (None, Some(m)) => m / area,
            _ => return Err(SceneError::new(key, "give exactly one of density and mass")),
        };
        Ok((shape, density * area, density * polar, centre))
    }
}

/// A scene: the grid, time stepping, walls and bodies, and how walls act on the grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Name of the scene, shown in progress bars and reports.
    #[serde(default)]
    pub name: String,
    /// Seed of the particle jitter; the same seed gives the same particles.
    #[serde(default)]
    #[schemars(extend("maximum" = 18_446_744_073_709_551_615u64, "unit" = "1"))]
    pub seed: u64,
    /// Gravity.
    #[serde(default = "default_gravity")]
    #[schemars(extend("unit" = "m/s²", "unbounded" = true))]
    pub gravity: [Real; 2],
    /// The background grid.
    pub grid: GridSpec,
    /// Time stepping.
    pub time: TimeSpec,
    /// How walls act on the grid; `Simulation(scene, method)` and `--method` override it.
    #[serde(default)]
    pub method: Method,
    /// Condition of every wall (and the domain box) unless a wall names its own.
    #[serde(default)]
    pub wall_condition: WallCondition,
    /// Coulomb friction coefficient μ of every `separate` wall (and the domain box, if separate) unless
    /// a wall names its own: the tangential velocity against the wall shrinks by μ times the normal
    /// velocity the wall stops; "inf" holds the material where it presses (it may still lift off).
    #[serde(default, with = "friction")]
    #[schemars(schema_with = "friction::schema")]
    pub wall_friction: Real,
    /// The walls besides the domain box: polygons and circles, containers or obstacles.
    #[serde(default)]
    pub walls: Vec<WallSpec>,
    /// The bodies of material: a run needs at least one; the walls of a scene without bodies can be
    /// studied on their own (`augmpm._core.Grid`).
    #[serde(default)]
    pub bodies: Vec<BodySpec>,
    /// Rigid bodies the material pushes and that push it back; their walls follow the scene's walls
    /// (wall `len(walls) + k` is `rigid_bodies[k]`).
    #[serde(default)]
    pub rigid_bodies: Vec<RigidBodySpec>,
    /// Settings of the augmented grid (`method = "augmented"`).
    #[serde(default)]
    pub augmented: AugmentedSpec,
    /// Floating-point precision of the engine: the same code in double or single precision.
    #[serde(default)]
    pub precision: Precision,
    /// What a run writes besides positions, velocities and bodies.
    #[serde(default)]
    pub output: OutputSpec,
}

/// What a run writes of each frame besides the particles' positions, velocities and bodies.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Per-particle fields written into each frame's npz and VTK files.
    #[serde(default)]
    pub fields: Vec<OutputField>,
    /// Also write each frame's particles as a PLY point cloud (`ply/frame_00000.ply`), for Blender and
    /// Houdini, with the fields above as vertex properties.
    #[serde(default)]
    pub ply: bool,
}

/// A per-particle field a run can write into its frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum OutputField {
    /// The density ρ0 / J (kg/m², kg/m³ in 3D).
    #[serde(rename = "density")]
    Density,
    /// The pressure −tr σ / D (N/m, Pa in 3D).
    #[serde(rename = "pressure")]
    Pressure,
    /// The volume ratio J = V/V⁰ (fluids ρ0/ρ; solids det F · J_p).
    #[serde(rename = "J")]
    J,
    /// The Cauchy stress σ, D×D (N/m, Pa in 3D).
    #[serde(rename = "stress")]
    Stress,
    /// The plastic volume ratio J_p (snow; sand: its loose volume, ≥ 1; 1 for the other materials).
    #[serde(rename = "plastic")]
    Plastic,
}

/// Settings of the augmented grid (`method = "augmented"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AugmentedSpec {
    /// Exclusion distance δ: regular nodes closer than δ·h to a wall (or outside the material) are
    /// dropped from the interpolation (Fig. 3 of the paper; its δ = h/4).
    #[serde(default = "default_delta")]
    #[schemars(extend("minimum" = 0.0, "exclusiveMaximum" = 1.5, "unit" = "h"))]
    pub delta: Real,
    /// Largest spacing of the boundary points along a wall.
    #[serde(default = "default_spacing")]
    #[schemars(extend("exclusiveMinimum" = 0.05, "maximum" = 1.0, "unit" = "h"))]
    pub spacing: Real,
    /// How particles and the augmented grid exchange mass and momentum.
    #[serde(default)]
    pub transfer: AugmentedTransfer,
}

fn default_gravity() -> [Real; 2] {
    [0.0, -9.81]
}

fn default_spacing() -> Real {
    1.0
}

fn default_delta() -> Real {
    0.25
}

impl Default for AugmentedSpec {
    fn default() -> Self {
        Self { delta: default_delta(), spacing: default_spacing(), transfer: AugmentedTransfer::default() }
    }
}

/// A friction coefficient in scene files: a number ≥ 0, or "inf" (JSON has no infinity; TOML's `inf`
/// reaches the engine as "inf").
pub(crate) mod friction {
    use super::Real;
    use serde::{Deserialize, Deserializer, Serializer};

    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Given {
        Number(Real),
        Text(String),
    }

    fn parse<E: serde::de::Error>(given: Given) -> Result<Real, E> {
        match given {
            Given::Number(x) => Ok(x),
            Given::Text(t) if t.eq_ignore_ascii_case("inf") => Ok(Real::INFINITY),
            Given::Text(t) => Err(E::custom(format!("expected a number >= 0 or \"inf\", got {t:?}"))),
        }
    }

    #[allow(clippy::unnecessary_cast)] // `Real` is f64 here, f32 in augmpm-core-f32
    pub fn serialize<S: Serializer>(mu: &Real, s: S) -> Result<S::Ok, S::Error> {
        if mu.is_infinite() && *mu > 0.0 {
            s.serialize_str("inf")
        } else {
            s.serialize_f64(*mu as f64)
        }
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Real, D::Error> {
        parse(Given::deserialize(d)?)
    }

    pub fn schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "anyOf": [{"type": "number", "minimum": 0.0}, {"type": "string", "const": "inf"}],
            "default": 0.0,
            "unit": "1"
        })
    }

    pub mod optional {
        use super::*;

        pub fn serialize<S: Serializer>(mu: &Option<Real>, s: S) -> Result<S::Ok, S::Error> {
            match mu {
                Some(mu) => super::serialize(mu, s),
                None => s.serialize_none(),
            }
        }

        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Real>, D::Error> {
            Option::<Given>::deserialize(d)?.map(parse).transpose()
        }

        pub fn optional_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
            schemars::json_schema!({
                "anyOf": [{"type": "number", "minimum": 0.0}, {"type": "string", "const": "inf"}, {"type": "null"}],
                "unit": "1"
            })
        }
    }
    pub use optional::optional_schema;
}

/// Bounds every item of a vector to be positive (a transform of its schema).
pub(crate) fn items_positive(schema: &mut schemars::Schema) {
    if let Some(items) = schema.get_mut("items").and_then(|i| i.as_object_mut()) {
        items.insert("exclusiveMinimum".into(), 0.0.into());
    }
}

/// Largest grid accepted (nodes, ghosts included): 16.7 M nodes, about 1 GB of node state.
pub(crate) const MAX_GRID_NODES: u64 = 1 << 24;
/// Bytes per grid node, at most: mass, B-spline mass (the paper's augmented transfer only), momentum (2D), the
/// density's node sums (the grid density's mass, or the smoothed J's volume and volume·J), flags and blocks.
/// Where the B-spline mass is not kept, its place stands for what else a node may hold: with moving walls the
/// naive treatment's record of the nodes inside (an f64 and a flag, 9 B).
const GRID_BYTES_PER_NODE: u64 = 7 * std::mem::size_of::<Real>() as u64;
/// Largest number of jittered candidate points per body: 20 M particles need about 4 GB.
pub(crate) const MAX_SEED_CANDIDATES: u64 = 20_000_000;

/// Bytes per particle of a running simulation: its state (the per-particle fields of
/// [`crate::simulation::State::fields`]), the schedule's order (one index) and, while seeding, the candidate
/// positions and the growth of the arrays (four reals).
fn particle_bytes() -> u64 {
    (crate::simulation::State::<2>::bytes_per_particle() + std::mem::size_of::<u32>() + 4 * std::mem::size_of::<Real>())
        as u64
}

/// What a scene will need in memory, estimated without allocating it.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryEstimate {
    /// Bytes, particles and grid together.
    pub bytes: u64,
    /// Particles the bodies will be seeded with (from their areas).
    pub particles: u64,
    /// Grid nodes, ghosts included.
    pub nodes: u64,
    /// The scene key that drives the estimate: `grid.resolution` or the largest body's seeding.
    pub key: String,
}

impl MemoryEstimate {
    /// Fails, naming the key that drives the estimate, when it exceeds `available` bytes.
    pub fn check(&self, available: u64) -> Result<(), SceneError> {
        if self.bytes <= available {
            return Ok(());
        }
        Err(SceneError::new(
            &self.key,
            format!(
                "the simulation would need about {} ({} particles, {} grid nodes) but only {} of memory \
                 are available; lower grid.resolution or the seeding density",
                byte_size(self.bytes),
                self.particles,
                self.nodes,
                byte_size(available)
            ),
        ))
    }
}

/// `bytes` in the largest binary unit that keeps it at 1 or more, to one decimal: "97.7 KiB", "1.5 MiB".
fn byte_size(bytes: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} B")
    } else {
        format!("{value:.1} {}", units[unit])
    }
}

fn point(p: &[Real; 2]) -> Point {
    Point::new(p[0], p[1])
}

fn finite(key: &str, values: &[Real]) -> Result<(), SceneError> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(v) => Err(SceneError::new(key, format!("must be finite, got {v}"))),
        None => Ok(()),
    }
}

/// Checks a wall or body polygon: ≥ 3 finite vertices, each visited once, counter-clockwise, simple.
/// A polygon closed by repeating its first vertex at the end is accepted without the repeat.
fn checked_polygon(key: &str, mut vertices: Vec<Point>) -> Result<Polygon, SceneError> {
    if vertices.len() > 3 && vertices.first() == vertices.last() {
        vertices.pop();
    }
    if vertices.len() < 3 {
        return Err(SceneError::new(key, format!("a polygon needs at least 3 vertices, got {}", vertices.len())));
    }
    for v in &vertices {
        finite(key, v.as_slice())?;
    }
    for (i, a) in vertices.iter().enumerate() {
        if let Some(j) = vertices[i + 1..].iter().position(|b| b == a) {
            let j = i + 1 + j;
            return Err(SceneError::new(
                key,
                format!(
                    "vertices {i} and {j} are the same point ({}, {}): a polygon visits each vertex once",
                    a.x, a.y
                ),
            ));
        }
    }
    let poly = Polygon::new(vertices);
    if let Some((i, j)) = poly.self_intersection() {
        return Err(SceneError::new(key, format!("polygon is self-intersecting (edges {i} and {j} cross)")));
    }
    let area = poly.signed_area();
    if area < 0.0 {
        return Err(SceneError::new(key, "polygon is clockwise; list its vertices counter-clockwise"));
    }
    if area == 0.0 {
        return Err(SceneError::new(key, "polygon has zero area"));
    }
    Ok(poly)
}

impl Scene {
    /// Parses the JSON form of a resolved scene.
    /// Checked against [`Scene::schema`] first, so that an error names the key (`bodies[0].radius`),
    /// then by [`Scene::validate`].
    pub fn from_json(text: &str) -> Result<Self, SceneError> {
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| SceneError::new("scene", format!("not valid JSON: {e}")))?;
        crate::schema::check(Self::schema(), &value).map_err(|e| SceneError::new(e.key, e.reason))?;
        let scene: Self = serde_json::from_value(value).map_err(|e| SceneError::new("scene", e.to_string()))?;
        scene.validate()?;
        Ok(scene)
    }

    /// The JSON Schema of scenes, derived from these types: every key with its doc line (`description`),
    /// default, range (JSON Schema bounds, or `unbounded`) and `unit`. The Python package builds its
    /// scene models from it and the README's scene reference is generated from it.
    pub fn schema() -> &'static serde_json::Value {
        static SCHEMA: std::sync::OnceLock<serde_json::Value> = std::sync::OnceLock::new();
        SCHEMA.get_or_init(|| serde_json::to_value(schemars::schema_for!(Scene)).expect("the schema is JSON"))
    }

    /// Checks everything that needs no geometry: each key against [`Scene::schema`] (types, ranges,
    /// finite numbers, unknown keys), then the rules that tie keys together (one of `time.dt` and
    /// `time.cfl`, a whole number of cells, ...). [`Scene::build`] calls it first.
    pub fn validate(&self) -> Result<(), SceneError> {
        // A scene built in code may hold a NaN or an infinity, which JSON writes as null: the schema
        // refuses it where a number is required, and here where a number is optional (null: not given).
        let t = &self.time;
        let mut optional: Vec<(String, Option<Real>)> =
            vec![("time.dt".into(), t.dt), ("time.cfl".into(), t.cfl), ("time.end".into(), t.end)];
        optional.extend(
            self.bodies
                .iter()
                .enumerate()
                .map(|(b, body)| (format!("bodies[{b}].seeding.spacing"), body.seeding.spacing)),
        );
        if let Some((key, v)) = optional.into_iter().find_map(|(k, v)| v.filter(|v| !v.is_finite()).map(|v| (k, v))) {
            return Err(SceneError::new(key, format!("must be a finite number, got {v}")));
        }
        let frictions = self.walls.iter().enumerate().map(|(i, w)| (format!("walls[{i}].friction"), w.friction()));
        let frictions = frictions.chain(std::iter::once(("wall_friction".to_string(), Some(self.wall_friction))));
        if let Some((key, mu)) =
            frictions.into_iter().find_map(|(k, mu)| mu.filter(|mu| mu.is_nan() || *mu < 0.0).map(|mu| (k, mu)))
        {
            return Err(SceneError::new(key, format!("must be a number >= 0 or \"inf\", got {mu}")));
        }
        let value = serde_json::to_value(self).map_err(|e| SceneError::new("scene", e.to_string()))?;
        crate::schema::check(Self::schema(), &value).map_err(|e| SceneError::new(e.key, e.reason))?;
        self.layout_unchecked()?;
        let t = &self.time;
        if t.steps.is_some() == t.end.is_some() {
            return Err(SceneError::new("time", "give exactly one of steps and end"));
        }
        match (t.dt, t.cfl) {
            (Some(_), Some(_)) | (None, None) => return Err(SceneError::new("time", "give exactly one of dt and cfl")),
            _ => {}
        }
        // Friction acts on separate walls only: a wall that names its own must be one, and a scene
        // friction needs one to act on.
        let conditions: Vec<WallCondition> =
            self.walls.iter().map(|w| w.condition().unwrap_or(self.wall_condition)).collect();
        for (i, (wall, condition)) in self.walls.iter().zip(&conditions).enumerate() {
            if wall.friction().is_some_and(|mu| mu > 0.0) && *condition != WallCondition::Separate {
                return Err(SceneError::new(
                    format!("walls[{i}].friction"),
                    format!("friction acts on separate walls; this wall is {condition:?}").to_lowercase(),
                ));
            }
        }
        for (i, wall) in self.walls.iter().enumerate() {
            if let Some(motion) = wall.motion() {
                motion.validate().map_err(|(k, reason)| SceneError::new(format!("walls[{i}].motion.{k}"), reason))?;
                if self.grid.density_wall_correction {
                    return Err(SceneError::new(
                        "grid.density_wall_correction",
                        format!("not available with moving walls (walls[{i}] moves)"),
                    ));
                }
            }
        }
        let hinged_to: Vec<_> = self.rigid_bodies.iter().map(|b| b.hinge_to).collect();
        for (k, body) in self.rigid_bodies.iter().enumerate() {
            body.surface.condition(&format!("rigid_bodies[{k}]"), self.wall_condition)?;
            if self.grid.density_wall_correction {
                return Err(SceneError::new(
                    "grid.density_wall_correction",
                    format!("not available with moving walls (rigid_bodies[{k}] moves)"),
                ));
            }
            check_hinge_to(&format!("rigid_bodies[{k}]"), k, &hinged_to, body.hinge.is_some())?;
            if body.hinge.is_some() && body.hinge_to.is_none() && body.velocity != [0.0; 2] {
                return Err(SceneError::new(
                    format!("rigid_bodies[{k}].velocity"),
                    "a hinged body's centre moves as its angular_velocity turns it about the hinge; leave velocity out",
                ));
            }
        }
        let separate = self.wall_condition == WallCondition::Separate
            || conditions.contains(&WallCondition::Separate)
            || self.rigid_bodies.iter().any(|b| b.surface.condition == Some(WallCondition::Separate));
        if self.wall_friction > 0.0 && !separate {
            return Err(SceneError::new(
                "wall_friction",
                "friction acts on separate walls, and no wall (nor the domain box) is separate",
            ));
        }
        for (b, body) in self.bodies.iter().enumerate() {
            let key = format!("bodies[{b}]");
            if body.seeding.spacing.is_some() && body.seeding.per_cell.is_some() {
                return Err(SceneError::new(format!("{key}.seeding"), "give spacing or per_cell, not both"));
            }
            if let BodyShape::Box { min, max } = &body.shape {
                if max[0] <= min[0] || max[1] <= min[1] {
                    return Err(SceneError::new(format!("{key}.max"), "must exceed min along both axes"));
                }
            }
            body.material.validate().map_err(|(k, reason)| SceneError::new(format!("{key}.material.{k}"), reason))?;
        }
        Ok(())
    }

    /// How a wall of `condition` acts: its own friction, else the scene's (on separate walls).
    fn contact(&self, condition: WallCondition, friction: Option<Real>, moving: bool) -> WallContact {
        let friction = match condition {
            WallCondition::Separate => friction.unwrap_or(self.wall_friction),
            _ => 0.0,
        };
        WallContact { condition, friction, moving }
    }

    /// Cell width h (m).
    pub fn cell_size(&self) -> Real {
        self.grid.domain[0] / self.grid.resolution as Real
    }

    /// The grid of a scene whose keys are in range (`validate`).
    fn layout_unchecked(&self) -> Result<GridLayout<2>, SceneError> {
        let g = &self.grid;
        let h = self.cell_size();
        let ny = g.domain[1] / h;
        if !ny.is_finite() {
            // h underflows to 0 for a subnormal width.
            return Err(SceneError::new(
                "grid.domain",
                format!("height {} is not a finite number of cells of width {h}", g.domain[1]),
            ));
        }
        if (ny - ny.round()).abs() > 1e-9 * ny.max(1.0) || ny.round() < 2.0 {
            return Err(SceneError::new(
                "grid.domain",
                format!("height {} is not a whole number (≥ 2) of cells of width {h}", g.domain[1]),
            ));
        }
        // In floating point first: a huge height must not wrap an integer cast.
        let nodes_f = (g.resolution as Real + 5.0) * (ny.round() + 5.0);
        if nodes_f > MAX_GRID_NODES as Real {
            return Err(SceneError::new(
                "grid.resolution",
                format!(
                    "the grid would have {nodes_f:.3e} nodes (about {:.3e} MB); at most {MAX_GRID_NODES} are allowed",
                    nodes_f * GRID_BYTES_PER_NODE as Real / 1e6
                ),
            ));
        }
        Ok(GridLayout::new(h, [g.resolution, ny.round() as usize]))
    }

    /// The walls (with their surfaces' motion) and each wall's condition, the domain box last.
    fn walls(&self, extent: Point) -> Result<(Walls2, Vec<WallContact>), SceneError> {
        let mut shapes = Vec::new();
        let mut conditions = Vec::new();
        let mut motions = Vec::new();
        for (i, w) in self.walls.iter().enumerate() {
            let key = format!("walls[{i}]");
            // Walls are sampled (augmented grid) and classified against the grid: keep them
            // within one domain size of the box.
            let near_box = |p: &Point| (0..2).all(|k| p[k] >= -extent[k] && p[k] <= 2.0 * extent[k]);
            let far = || SceneError::new(&key, "wall lies far outside the domain box (more than one domain size away)");
            let (shape, condition, velocity) = match w {
                WallSpec::Polygon { vertices, side, condition, velocity, tangential_speed, .. } => {
                    let poly = checked_polygon(&format!("{key}.vertices"), vertices.iter().map(point).collect())?;
                    if !poly.vertices.iter().all(near_box) {
                        return Err(far());
                    }
                    match side {
                        SideSpec::Inside => (WallShape::Polygon(poly), condition, (velocity, *tangential_speed, None)),
                        // The surface runs counter-clockwise around the polygon seen from outside too: its
                        // normal into the wall points the other way.
                        SideSpec::Outside => {
                            (WallShape::Obstacle(poly), condition, (velocity, -*tangential_speed, None))
                        }
                    }
                }
                WallSpec::Circle { center, radius, side, condition, velocity, tangential_speed, .. } => {
                    let r = Point::repeat(*radius);
                    if !(near_box(&(point(center) - r)) && near_box(&(point(center) + r))) {
                        return Err(far());
                    }
                    let side = match side {
                        SideSpec::Outside => Side::Outside,
                        SideSpec::Inside => Side::Inside,
                    };
                    let circle = Circle { center: point(center), radius: *radius };
                    (WallShape::Circle(circle, side), condition, (velocity, *tangential_speed, Some(point(center))))
                }
                WallSpec::Polyline { vertices, thickness, condition, .. } => {
                    let vertices: Vec<Point> = vertices.iter().map(point).collect();
                    let r = Point::repeat(*thickness);
                    if !vertices.iter().all(|v| near_box(&(v - r)) && near_box(&(v + r))) {
                        return Err(far());
                    }
                    if let Some(k) = (1..vertices.len()).find(|&k| vertices[k] == vertices[k - 1]) {
                        return Err(SceneError::new(
                            format!("{key}.vertices"),
                            format!("points {} and {k} coincide (a segment of zero length)", k - 1),
                        ));
                    }
                    let stroke = Stroke { vertices, half: 0.5 * thickness };
                    (WallShape::Stroke(stroke), condition, (&[0.0; 2], 0.0, None))
                }
            };
            let (velocity, speed, center) = velocity;
            shapes.push(shape);
            conditions.push(self.contact(condition.unwrap_or(self.wall_condition), w.friction(), w.motion().is_some()));
            motions.push(SurfaceMotion { velocity: point(velocity), tangential_speed: speed, center });
        }
        let mut moves: Vec<Option<Motion>> = self.walls.iter().map(|w| w.motion().cloned()).collect();
        // The rigid bodies: solids moving at their initial velocities about their centres of mass until
        // the engine poses them.
        for (k, body) in self.rigid_bodies.iter().enumerate() {
            let key = format!("rigid_bodies[{k}]");
            let (shape, _, _, centre) = body.solid(&key)?;
            shapes.push(shape);
            conditions.push(self.contact(
                body.surface.condition.unwrap_or(self.wall_condition),
                body.surface.friction,
                true,
            ));
            motions.push(SurfaceMotion { velocity: Point::zeros(), tangential_speed: 0.0, center: None });
            moves.push(Some(Motion::Constant {
                velocity: body.initial_velocity(&centre),
                angular_velocity: body.angular_velocity,
                pivot: Some([centre.x, centre.y]),
            }));
        }
        // The domain box, always a wall, still.
        conditions.push(self.contact(self.wall_condition, None, false));
        Ok((Walls2::new(shapes, extent).with_motions(motions).with_moves(moves), conditions))
    }

    /// The time step (s) of a validated scene, and a warning when `time.dt` exceeds the stable bound
    /// ([`time_step`]).
    fn dt(
        &self,
        model_stable_dt: Real,
        fastest: Option<(usize, Real)>,
        h: Real,
    ) -> Result<(Real, Option<String>), SceneError> {
        time_step(&self.time, model_stable_dt, fastest, h).map_err(|e| {
            // A rigid body's wall follows the scene's: name the body.
            match fastest.filter(|&(wall, _)| wall >= self.walls.len() && e.key == format!("walls[{wall}].motion")) {
                Some((wall, _)) => {
                    SceneError::new(format!("rigid_bodies[{}].velocity", wall - self.walls.len()), e.reason)
                }
                None => e,
            }
        })
    }

    /// The grid, the material region and the walls' boundary handling, without bodies.
    pub fn build_walls(&self, method: Method) -> Result<(GridLayout<2>, Walls2, Boundary<2>), SceneError> {
        self.validate()?;
        let layout = self.layout_unchecked()?;
        let h = layout.h;
        let extent = Point::new(layout.extent()[0], layout.extent()[1]);
        let (region, conditions) = self.walls(extent)?;
        let boundary = match method {
            Method::Naive => Boundary::Naive(NaiveBoundary::new(&layout, &region, conditions)),
            Method::Augmented => {
                if self.augmented.transfer == AugmentedTransfer::Paper && region.moves() {
                    return Err(SceneError::new(
                        "augmented.transfer",
                        "\"paper\" holds particles against still walls only; moving walls need \"stable\"",
                    ));
                }
                let (delta, spacing) = (self.augmented.delta, self.augmented.spacing);
                Boundary::Augmented(
                    AugmentedGrid::new(&layout, &region, spacing * h, conditions, delta * h)
                        .with_transfer(self.augmented.transfer),
                )
            }
        };
        Ok((layout, region, boundary))
    }

    /// Estimates the memory the simulation of this scene will take, without building it. Bodies
    /// whose shape or seeding is invalid count no particles (building reports them).
    pub fn memory_estimate(&self) -> Result<MemoryEstimate, SceneError> {
        self.validate()?;
        let layout = self.layout_unchecked()?;
        let nodes = layout.num_nodes() as u64;
        let h = layout.h;
        let domain_area = self.grid.domain[0] * self.grid.domain[1];
        let mut particles = 0.0 as Real;
        let mut largest = (0.0 as Real, None);
        for (b, body) in self.bodies.iter().enumerate() {
            let Ok(spacing) = seeding_spacing("", body, h) else { continue };
            let area = match &body.shape {
                BodyShape::Box { min, max } => (max[0] - min[0]) * (max[1] - min[1]),
                BodyShape::Circle { radius, .. } => crate::math::PI * radius * radius,
                BodyShape::Polygon { vertices, scale, .. } => {
                    let n = vertices.len();
                    let twice: Real = (0..n)
                        .map(|i| {
                            let (a, b) = (vertices[i], vertices[(i + 1) % n]);
                            a[0] * b[1] - b[0] * a[1]
                        })
                        .sum();
                    0.5 * twice.abs() * scale * scale
                }
            };
            // At most the domain's area: a body reaching outside it is refused when built, not here.
            let count = area.min(domain_area) / (spacing * spacing);
            if count.is_finite() && count > 0.0 {
                particles += count;
                if count > largest.0 {
                    largest = (count, Some(b));
                }
            }
        }
        // In floating point, saturating: a tiny seeding spacing must not wrap the byte count.
        let particle_bytes = particles * particle_bytes() as Real;
        let grid_bytes = nodes as Real * GRID_BYTES_PER_NODE as Real;
        let key = match largest.1 {
            Some(b) if particle_bytes > grid_bytes => format!("bodies[{b}].seeding"),
            _ => "grid.resolution".to_string(),
        };
        let saturate = |v: Real| if v >= u64::MAX as Real { u64::MAX } else { v as u64 };
        let (bytes, particles) = (saturate(particle_bytes + grid_bytes), saturate(particles));
        Ok(MemoryEstimate { bytes, particles, nodes, key })
    }

    /// Validates the scene and builds the simulation. Returns warnings beside it.
    pub fn build(&self, method: Method) -> Result<(Simulation<2>, Vec<String>), SceneError> {
        if self.precision != Precision::NATIVE {
            return Err(SceneError::new(
                "precision",
                format!("this engine runs {:?} scenes, not {:?}", Precision::NATIVE, self.precision),
            ));
        }
        let (layout, region, boundary) = self.build_walls(method)?;
        let h = layout.h;
        if self.bodies.is_empty() {
            return Err(SceneError::new("bodies", "a scene needs at least one body"));
        }
        let mut materials = Vec::new();
        let mut particles = Particles::<2>::default();
        for (b, body) in self.bodies.iter().enumerate() {
            let key = format!("bodies[{b}]");
            materials.push(body.material.clone());
            let first = particles.len();
            let mut seeded = Particles::<2>::default();
            seed_body(&key, body, b, self.seed, h, &mut seeded)?;
            let outside = |p: usize| region.distance(&seeded.x[p]).distance > 0.0;
            if body.fill && (0..seeded.len()).all(outside) {
                return Err(SceneError::new(key, "body lies outside the walls: nothing is left to fill"));
            }
            for p in (0..seeded.len()).filter(|&p| !(body.fill && outside(p))) {
                particles.push(seeded.x[p], seeded.v[p], seeded.mass[p], seeded.vol0[p], seeded.body[p]);
            }
            let energy: f64 = (first..particles.len())
                .map(|p| crate::particles::energy_root(particles.mass[p], &particles.v[p]).powi(2))
                .sum();
            if !energy.is_finite() {
                return Err(SceneError::new(
                    format!("{key}.velocity"),
                    "the body's kinetic energy is beyond the floating-point range (velocity or density too large)",
                ));
            }
            let outside = (first..particles.len()).filter(|&p| region.distance(&particles.x[p]).distance > 0.0).count();
            if outside > 0 {
                return Err(SceneError::new(
                    key,
                    if outside == particles.len() - first {
                        format!("body lies outside the walls (all {outside} particles)")
                    } else {
                        format!(
                            "body lies partly outside the walls ({outside} of {} particles)",
                            particles.len() - first
                        )
                    },
                ));
            }
        }
        let wall_fraction = (self.grid.density_wall_correction
            && materials.iter().any(crate::material::ConstitutiveModel::<2>::needs_grid_density))
        .then(|| crate::step::transfer::wall_fractions(&layout, &region));
        let fastest = region.fastest();
        let (mut bodies, mut contacts) = (Vec::new(), Vec::new());
        for (k, spec) in self.rigid_bodies.iter().enumerate() {
            let (_, mass, polar, centre) = spec.solid(&format!("rigid_bodies[{k}]"))?;
            let mut inertia = crate::math::Matrix::<3>::zeros();
            inertia[(2, 2)] = polar;
            bodies.push(RigidBody { wall: self.walls.len() + k, mass, inertia, centre });
            let hinge = spec.hinge.map(|[x, y]| ([x, y, 0.0], [0.0, 0.0, 1.0]));
            contacts.push(spec.surface.contact(hinge, spec.hinge_to));
        }
        let contacts: Option<Box<dyn Contacts<2>>> =
            (!bodies.is_empty()).then(|| Box::new(Contacts2::new(&region, &bodies, contacts, h)) as _);
        let mut model = Model {
            layout,
            materials,
            gravity: point(&self.gravity),
            region: Box::new(region),
            boundary,
            wall_fraction,
            dt: 0.0,
            bodies,
            contacts,
        };
        let (dt, warning) = self.dt(model.stable_dt(), fastest, h)?;
        model.dt = dt;
        let mut warnings: Vec<String> = warning.into_iter().collect();
        warnings.extend(unused_material_keys(self.bodies.iter().map(|b| &b.material)));
        if self.grid.density_wall_correction && model.wall_fraction.is_none() {
            warnings.push(
                "grid.density_wall_correction has no effect: no fluid gathers its density from the grid \
                 (it applies to density_estimate = \"grid\")"
                    .to_string(),
            );
        }
        let mut sim = Simulation::new(model, particles);
        // Each rigid body's wall is posed by the engine from the start, at its initial velocities.
        for (body, spec) in sim.model.bodies.iter().zip(&self.rigid_bodies) {
            let pose =
                WallPose::planar(0.0, [0.0, 0.0], 0.0, spec.initial_velocity(&body.centre), spec.angular_velocity);
            sim.state.wall_poses.push((body.wall, pose));
        }
        Ok((sim, warnings))
    }
}

/// The time step (s) of validated time settings, and a warning when `time.dt` exceeds the stable bound
/// `model_stable_dt` (s) of the materials.
/// With moving walls, `fastest` (the fastest wall and its top speed, m/s) may move at most one cell
/// `h` (m) per step: `time.cfl` takes the step that keeps it there, a `time.dt` beyond is refused.
pub(crate) fn time_step(
    time: &TimeSpec,
    model_stable_dt: Real,
    fastest: Option<(usize, Real)>,
    h: Real,
) -> Result<(Real, Option<String>), SceneError> {
    match (time.dt, time.cfl) {
        (Some(dt), _) => {
            if let Some((wall, speed)) = fastest.filter(|(_, speed)| speed * dt > h) {
                return Err(SceneError::new(
                    format!("walls[{wall}].motion"),
                    format!(
                        "moves up to {speed:.4e} m/s, {:.3} cells in a step of time.dt = {dt:e} s (at most one \
                         cell per step); lower time.dt or give time.cfl",
                        speed * dt / h
                    ),
                ));
            }
            let warning = (dt > model_stable_dt).then(|| {
                format!(
                    "time.dt = {dt:e} s exceeds the stable bound {model_stable_dt:e} s of the materials \
                     (one cell per step at the wave speed, or the viscous limit); the run may blow up"
                )
            });
            Ok((dt, warning))
        }
        (None, cfl) => {
            let walls_dt = fastest.map_or(Real::INFINITY, |(_, speed)| h / speed);
            let dt = cfl.unwrap_or(1.0) * model_stable_dt.min(walls_dt);
            if !(dt.is_finite() && dt > 0.0) {
                return Err(SceneError::new(
                    "time.cfl",
                    format!("the materials' stable step is {model_stable_dt:e} s; give time.dt instead"),
                ));
            }
            Ok((dt, None))
        }
    }
}

/// Distance (m) between seeded particles of a body on cells of width `h` (default: 4 per cell).
fn seeding_spacing(key: &str, body: &BodySpec, h: Real) -> Result<Real, SceneError> {
    match (body.seeding.spacing, body.seeding.per_cell) {
        (Some(s), None) if s.is_finite() && s > 0.0 => Ok(s),
        (None, Some(n)) if n > 0 => Ok(h / (n as Real).sqrt()),
        (None, None) => Ok(h / 2.0),
        _ => Err(SceneError::new(format!("{key}.seeding"), "give one positive spacing or per_cell")),
    }
}

/// Seeds one body on a jittered grid aligned with the domain origin.
fn seed_body(
    key: &str,
    body: &BodySpec,
    index: usize,
    seed: u64,
    h: Real,
    out: &mut Particles<2>,
) -> Result<(), SceneError> {
    let spacing = seeding_spacing(key, body, h)?;
    // Area (m²), bounding box and inside test of the body.
    type ShapeInfo = (Real, Point, Point, Box<dyn Fn(&Point) -> bool>);
    let (area, lo, hi, inside): ShapeInfo = match &body.shape {
        BodyShape::Polygon { vertices, scale, center } => {
            let c = point(center);
            let poly =
                checked_polygon(&format!("{key}.vertices"), vertices.iter().map(|v| c + point(v) * *scale).collect())?;
            let lo = poly.vertices.iter().fold(Point::repeat(Real::INFINITY), |a, v| a.inf(v));
            let hi = poly.vertices.iter().fold(Point::repeat(Real::NEG_INFINITY), |a, v| a.sup(v));
            (poly.signed_area(), lo, hi, Box::new(move |p| poly.contains(p)))
        }
        BodyShape::Box { min, max } => {
            let (lo, hi) = (point(min), point(max));
            let area = (hi.x - lo.x) * (hi.y - lo.y);
            (area, lo, hi, Box::new(move |p| p.x >= lo.x && p.x < hi.x && p.y >= lo.y && p.y < hi.y))
        }
        BodyShape::Circle { center, radius } => {
            let circle = Circle { center: point(center), radius: *radius };
            let r = Point::repeat(*radius);
            let area = crate::math::PI * radius * radius;
            (area, circle.center - r, circle.center + r, Box::new(move |p| circle.contains(p)))
        }
    };
    // In floating point first: a tiny spacing must not wrap an integer cast.
    let cells_f = ((hi - lo) / spacing).map(|c| c.ceil() + 1.0);
    if cells_f.x * cells_f.y > MAX_SEED_CANDIDATES as Real {
        return Err(SceneError::new(
            format!("{key}.seeding"),
            format!(
                "would try about {:.3e} points (at most {MAX_SEED_CANDIDATES}, about 200 bytes each); raise the spacing",
                cells_f.x * cells_f.y
            ),
        ));
    }
    let cells = cells_f.map(|c| c as u64);
    // One stream per body, so adding a body does not reshuffle the others.
    let mut rng = Pcg64::seed_from_u64(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let first = (lo / spacing).map(|c| c.floor() as i64);
    let mut positions = Vec::new();
    for j in 0..cells.y as i64 {
        for i in 0..cells.x as i64 {
            let corner = Point::new((first.x + i) as Real, (first.y + j) as Real) * spacing;
            // Drawn in f64 in either precision, so that f32 and f64 scenes seed the same particles.
            let jitter = Point::new(rng.gen::<f64>() as Real, rng.gen::<f64>() as Real);
            let p = corner + jitter * spacing;
            if inside(&p) {
                positions.push(p);
            }
        }
    }
    if positions.is_empty() {
        return Err(SceneError::new(
            format!("{key}.seeding"),
            format!("no particle was seeded (the body is smaller than the seeding spacing {spacing} m)"),
        ));
    }
    let n = positions.len() as Real;
    let density = crate::material::ConstitutiveModel::<2>::density(&body.material);
    let (mass, vol0) = (area * density / n, area / n);
    let v = point(&body.velocity);
    for p in positions {
        out.push(p, v, mass, vol0, index as u32);
    }
    Ok(())
}

/// Warnings for the material keys of the bodies that have no effect (`bodies[i].material.…`), in order.
pub(crate) fn unused_material_keys<'a>(materials: impl Iterator<Item = &'a Material>) -> Vec<String> {
    materials
        .enumerate()
        .filter_map(|(i, m)| match m {
            Material::Fluid(f) => f.unused_keys(&format!("bodies[{i}].material")),
            _ => None,
        })
        .collect()
}
