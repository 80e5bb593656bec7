//! The scene of a 3D simulation: the keys of a 2D scene ([`crate::scene::Scene`]) with three-component
//! vectors (`grid.domain`, `gravity`, positions, velocities), 3D walls (boxes, planes, spheres,
//! cylinders; [`crate::geometry3`]), 3D bodies (boxes, spheres, cylinders) and rigid bodies (boxes,
//! spheres, cylinders, meshes), and how a `Simulation<3>` is built from it.

use crate::contact::{Contacts, Contacts3, Hinge};
use crate::geometry::{Region, Side};
use crate::geometry3::{Solid, Wall3, Walls3};
use crate::grid::GridLayout;
use crate::material::{ConstitutiveModel, Material};
use crate::math::{wide, Matrix, Precision, Real, Vector};
use crate::mesh::TriangleMesh;
use crate::motion::{Motion3, WallPose};
use crate::particles::Particles;
use crate::rigid::RigidBody;
use crate::scene::{
    default_side, friction, inside, one, time_step, AugmentedSpec, MemoryEstimate, OutputSpec, RigidSurfaceSpec,
    SceneError, Seeding, SideSpec, TimeSpec, MAX_GRID_NODES, MAX_SEED_CANDIDATES,
};
use crate::simulation::{Model, Simulation};
use crate::treatment::augmented::AugmentedGrid;
use crate::treatment::naive::NaiveBoundary;
use crate::treatment::{Boundary, Method};
use crate::wall::{WallCondition, WallContact};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

type P3 = Vector<3>;

/// The most points the walls of a 3D scene may be sampled with (about 200 bytes each).
const MAX_BOUNDARY_POINTS: Real = 5e7;

/// The background grid of a 3D scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "Grid3")]
pub struct Grid3Spec {
    /// Size of the domain box [0, Lx] × [0, Ly] × [0, Lz], always a wall.
    #[schemars(extend("unit" = "m"), transform = crate::scene::items_positive)]
    pub domain: [Real; 3],
    /// Cells along x: h = Lx / resolution; Ly and Lz must be whole numbers of cells.
    #[schemars(range(min = 2, max = 4096), extend("unit" = "cells"))]
    pub resolution: usize,
}

/// A 3D wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Wall3Spec {
    /// A box turned by `angle` about `axis`, material `inside` it (a container, the default) or
    /// `outside` it (an obstacle).
    #[schemars(title = "BoxWall")]
    Box {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Edge lengths along the box's own axes.
        #[schemars(extend("unit" = "m"), transform = crate::scene::items_positive)]
        size: [Real; 3],
        /// Axis the box is turned about (any length but zero).
        #[serde(default = "z_axis")]
        #[schemars(extend("unit" = "1", "unbounded" = true))]
        axis: [Real; 3],
        /// Angle the box is turned by about `axis`, counter-clockwise seen from its tip.
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        angle: Real,
        /// Where the material is: `inside` the box (a container) or `outside` (an obstacle).
        #[serde(default = "inside")]
        side: SideSpec,
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
        /// How the wall moves (default: it stays).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        motion: Option<Motion3>,
    },
    /// A plane through `point`, the material on the side `normal` points to (a floor's normal points up).
    #[schemars(title = "PlaneWall")]
    Plane {
        /// A point of the plane.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        point: [Real; 3],
        /// Normal pointing into the material (any length but zero).
        #[schemars(extend("unit" = "1", "unbounded" = true))]
        normal: [Real; 3],
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
    },
    /// A sphere, material `outside` it (an obstacle, the default) or `inside` it (a container).
    #[schemars(title = "SphereWall")]
    Sphere {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
        /// Where the material is: `outside` the sphere (an obstacle) or `inside` (a container).
        #[serde(default = "default_side")]
        side: SideSpec,
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
        /// How the wall moves (default: it stays).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        motion: Option<Motion3>,
    },
    /// A capped cylinder, material `outside` it (an obstacle, the default) or `inside` it (a container).
    #[schemars(title = "CylinderWall")]
    Cylinder {
        /// Centre of its axis.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Direction of its axis (any length but zero).
        #[schemars(extend("unit" = "1", "unbounded" = true))]
        axis: [Real; 3],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
        /// Length along the axis.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        length: Real,
        /// Where the material is: `outside` the cylinder (an obstacle) or `inside` (a container).
        #[serde(default = "default_side")]
        side: SideSpec,
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
        /// How the wall moves (default: it stays).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        motion: Option<Motion3>,
    },
    /// A closed triangle mesh, material `outside` it (an obstacle, the default) or `inside` it (a
    /// container).
    #[schemars(title = "MeshWall")]
    Mesh {
        #[serde(flatten)]
        mesh: MeshSource,
        /// A thin wall of this thickness instead of a solid: the points within thickness/2 of the
        /// triangles, which may then be open and oriented either way (material all around it; at least
        /// about 3 cells keeps the material on one side out of the MLS systems of the other).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        thickness: Option<Real>,
        /// Where the material is: `outside` the mesh (an obstacle) or `inside` (a container).
        #[serde(default = "default_side")]
        side: SideSpec,
        /// This wall's condition (default: the scene's `wall_condition`).
        #[serde(default)]
        condition: Option<WallCondition>,
        /// Coulomb friction coefficient μ of a `separate` wall (default: the scene's `wall_friction`).
        #[serde(default, with = "friction::optional")]
        #[schemars(schema_with = "friction::optional_schema")]
        friction: Option<Real>,
        /// How the wall moves (default: it stays).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        motion: Option<Motion3>,
    },
}

/// A closed triangle mesh and its placement: scaled about its origin, turned by `angle` about `axis`,
/// its origin moved to `position`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "MeshSource")]
pub struct MeshSource {
    /// A mesh file (OBJ, STL or PLY; a relative path from the scene file's folder), read by the Python
    /// package into `vertices` and `triangles`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// Vertices of the mesh in its own frame (or read from `file`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    #[schemars(extend("unit" = "m", "unbounded" = true))]
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as three indices into `vertices`, counter-clockwise seen from outside; the mesh must
    /// be closed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    #[schemars(extend("unit" = "1", "unbounded" = true))]
    pub triangles: Vec<[usize; 3]>,
    /// Scale of the mesh's frame.
    #[serde(default = "one")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "1"))]
    pub scale: Real,
    /// Where the mesh's origin is placed.
    #[serde(default)]
    #[schemars(extend("unit" = "m", "unbounded" = true))]
    pub position: [Real; 3],
    /// Axis the mesh is turned about (any length but zero).
    #[serde(default = "z_axis")]
    #[schemars(extend("unit" = "1", "unbounded" = true))]
    pub axis: [Real; 3],
    /// Angle the mesh is turned by about `axis`, counter-clockwise seen from its tip.
    #[serde(default)]
    #[schemars(extend("unit" = "rad", "unbounded" = true))]
    pub angle: Real,
    /// Edges whose faces' normals differ by more than this are creases (their boundary points carry
    /// both faces' normals); 0.5236 rad is 30°.
    #[serde(default = "crease_angle")]
    #[schemars(extend("exclusiveMinimum" = 0.0, "maximum" = std::f64::consts::PI, "unit" = "rad"))]
    pub crease_angle: Real,
}

impl MeshSource {
    /// An error naming `key` unless the mesh has vertices and triangles.
    fn require(&self, key: &str) -> Result<(), SceneError> {
        if !self.vertices.is_empty() && !self.triangles.is_empty() {
            return Ok(());
        }
        Err(match &self.file {
            Some(_) => SceneError::new(
                format!("{key}.file"),
                "mesh files are read by the Python package (augmpm); the engine takes vertices and triangles",
            ),
            None => SceneError::new(key, "give a mesh file, or vertices and triangles"),
        })
    }

    /// The vertices placed in the scene (m).
    fn placed(&self) -> Vec<[f64; 3]> {
        let axis = nalgebra::Vector3::from_iterator(self.axis.iter().map(|&c| wide(c)));
        let turn = if axis.norm() > 0.0 {
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), wide(self.angle))
        } else {
            nalgebra::Rotation3::identity()
        };
        let position = nalgebra::Vector3::from_iterator(self.position.iter().map(|&c| wide(c)));
        let scale = wide(self.scale);
        self.vertices.iter().map(|v| (turn * (nalgebra::Vector3::from(*v) * scale) + position).into()).collect()
    }

    /// The checked mesh, placed; an error names `key`'s entry.
    fn build(&self, key: &str) -> Result<std::sync::Arc<TriangleMesh>, SceneError> {
        self.require(key)?;
        TriangleMesh::new(&self.placed(), &self.triangles, wide(self.crease_angle))
            .map(std::sync::Arc::new)
            .map_err(|e| SceneError::new(format!("{key}.{}", e.key), e.reason))
    }

    /// The placed mesh as the middle surface of a thin wall: open or closed, oriented either way.
    fn build_open(&self, key: &str) -> Result<std::sync::Arc<TriangleMesh>, SceneError> {
        self.require(key)?;
        TriangleMesh::open(&self.placed(), &self.triangles)
            .map(std::sync::Arc::new)
            .map_err(|e| SceneError::new(format!("{key}.{}", e.key), e.reason))
    }

    /// The centre and the radius (m) of a ball around the placed mesh.
    fn bounds(&self) -> (P3, Real) {
        let placed = self.placed();
        let lo = placed.iter().fold([f64::INFINITY; 3], |m, v| std::array::from_fn(|k| m[k].min(v[k])));
        let hi = placed.iter().fold([f64::NEG_INFINITY; 3], |m, v| std::array::from_fn(|k| m[k].max(v[k])));
        let (lo, hi) = (P3::from_fn(|k, _| lo[k] as Real), P3::from_fn(|k, _| hi[k] as Real));
        ((lo + hi) * 0.5, (hi - lo).norm() * 0.5)
    }

    /// Surface area (m²) of the placed mesh.
    fn area(&self) -> Real {
        let v = |i: usize| nalgebra::Vector3::from(self.vertices.get(i).copied().unwrap_or_default());
        let area: f64 =
            self.triangles.iter().map(|t| 0.5 * (v(t[1]) - v(t[0])).cross(&(v(t[2]) - v(t[0]))).norm()).sum();
        area as Real * self.scale * self.scale
    }
}

fn crease_angle() -> Real {
    crate::math::PI / 6.0
}

fn z_axis() -> [Real; 3] {
    [0.0, 0.0, 1.0]
}

impl Wall3Spec {
    /// The centre and the radius (m) of a ball around the wall's solid (none for a plane, sampled only
    /// where it crosses the domain).
    fn bounds(&self) -> Option<(P3, Real)> {
        match self {
            Wall3Spec::Box { center, size, .. } => Some((p3(center), p3(size).norm() * 0.5)),
            Wall3Spec::Sphere { center, radius, .. } => Some((p3(center), *radius)),
            Wall3Spec::Cylinder { center, radius, length, .. } => Some((p3(center), radius.hypot(0.5 * length))),
            Wall3Spec::Mesh { mesh, .. } if !mesh.vertices.is_empty() => Some(mesh.bounds()),
            Wall3Spec::Plane { .. } | Wall3Spec::Mesh { .. } => None,
        }
    }

    /// Area (m²) of the wall's surface (a plane: at most the largest cross-section of the domain box,
    /// bounded by the sum of its faces' areas over two).
    fn area(&self, domain: &[Real; 3]) -> Real {
        let pi = crate::math::PI;
        match self {
            Wall3Spec::Box { size, .. } => 2.0 * (size[0] * size[1] + size[1] * size[2] + size[2] * size[0]),
            Wall3Spec::Sphere { radius, .. } => 4.0 * pi * radius * radius,
            Wall3Spec::Cylinder { radius, length, .. } => 2.0 * pi * radius * (length + radius),
            Wall3Spec::Plane { .. } => domain[0] * domain[1] + domain[1] * domain[2] + domain[2] * domain[0],
            Wall3Spec::Mesh { mesh, thickness: Some(_), .. } => 2.0 * mesh.area(),
            Wall3Spec::Mesh { mesh, .. } => mesh.area(),
        }
    }

    /// How the wall moves, if it does.
    fn motion(&self) -> Option<&Motion3> {
        match self {
            Wall3Spec::Box { motion, .. }
            | Wall3Spec::Sphere { motion, .. }
            | Wall3Spec::Cylinder { motion, .. }
            | Wall3Spec::Mesh { motion, .. } => motion.as_ref(),
            Wall3Spec::Plane { .. } => None,
        }
    }

    /// The wall's own condition and friction coefficient, if it names them.
    fn contact_keys(&self) -> (Option<WallCondition>, Option<Real>) {
        match self {
            Wall3Spec::Box { condition, friction, .. }
            | Wall3Spec::Plane { condition, friction, .. }
            | Wall3Spec::Sphere { condition, friction, .. }
            | Wall3Spec::Cylinder { condition, friction, .. }
            | Wall3Spec::Mesh { condition, friction, .. } => (*condition, *friction),
        }
    }
}

/// Geometry of a 3D body.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "shape", rename_all = "lowercase")]
pub enum Body3Shape {
    /// An axis-aligned box.
    #[schemars(title = "BoxBody3")]
    Box {
        /// Lowest corner.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        min: [Real; 3],
        /// Highest corner, beyond `min` along every axis.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        max: [Real; 3],
    },
    /// A ball.
    #[schemars(title = "SphereBody")]
    Sphere {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
    },
    /// A capped cylinder.
    #[schemars(title = "CylinderBody")]
    Cylinder {
        /// Centre of its axis.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Direction of its axis (any length but zero).
        #[schemars(extend("unit" = "1", "unbounded" = true))]
        axis: [Real; 3],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
        /// Length along the axis.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        length: Real,
    },
    /// A closed triangle mesh.
    #[schemars(title = "MeshBody")]
    Mesh {
        #[serde(flatten)]
        mesh: MeshSource,
    },
}

/// A body of material in 3D: a shape, its material, its initial velocity and how it is seeded (8
/// particles per cell when the seeding names neither `spacing` nor `per_cell`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "Body3")]
pub struct Body3Spec {
    #[serde(flatten)]
    pub shape: Body3Shape,
    /// The body's material, chosen by `type`.
    pub material: Material,
    /// Initial velocity.
    #[serde(default)]
    #[schemars(extend("unit" = "m/s", "unbounded" = true))]
    pub velocity: [Real; 3],
    /// How particles are placed in the body (cubes of side `spacing`, or `per_cell` per cell).
    #[serde(default)]
    pub seeding: Seeding,
    /// Seed only the part of the body inside the material region instead of refusing a body that
    /// reaches past a wall.
    #[serde(default)]
    pub fill: bool,
}

/// The shape of a 3D rigid body: a solid box, ball, capped cylinder or closed mesh (the material stays
/// outside it).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(tag = "shape", rename_all = "lowercase")]
pub enum Rigid3Shape {
    /// A box turned by `angle` about `axis`.
    #[schemars(title = "BoxRigidBody3")]
    Box {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Edge lengths along the box's own axes.
        #[schemars(extend("unit" = "m"), transform = crate::scene::items_positive)]
        size: [Real; 3],
        /// Axis the box is turned about (any length but zero).
        #[serde(default = "z_axis")]
        #[schemars(extend("unit" = "1", "unbounded" = true))]
        axis: [Real; 3],
        /// Angle the box is turned by about `axis`, counter-clockwise seen from its tip.
        #[serde(default)]
        #[schemars(extend("unit" = "rad", "unbounded" = true))]
        angle: Real,
    },
    /// A ball.
    #[schemars(title = "SphereRigidBody")]
    Sphere {
        /// Centre.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
    },
    /// A capped cylinder.
    #[schemars(title = "CylinderRigidBody")]
    Cylinder {
        /// Centre of its axis.
        #[schemars(extend("unit" = "m", "unbounded" = true))]
        center: [Real; 3],
        /// Direction of its axis (any length but zero).
        #[schemars(extend("unit" = "1", "unbounded" = true))]
        axis: [Real; 3],
        /// Radius.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        radius: Real,
        /// Length along the axis.
        #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "m"))]
        length: Real,
    },
    /// A closed triangle mesh.
    #[schemars(title = "MeshRigidBody")]
    Mesh {
        #[serde(flatten)]
        mesh: MeshSource,
    },
}

/// A rigid body that the material pushes and that pushes it back (3D): a solid of uniform density whose
/// surface is a moving wall; gravity and the impulse of its wall conditions move it. It meets the other
/// bodies and the scene's walls in contacts (rapier).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[schemars(title = "RigidBody3")]
pub struct RigidBody3Spec {
    #[serde(flatten)]
    pub shape: Rigid3Shape,
    /// Density; give it or `mass`.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg/m³"))]
    pub density: Option<Real>,
    /// Mass; give it or `density`.
    #[serde(default)]
    #[schemars(extend("exclusiveMinimum" = 0.0, "unit" = "kg"))]
    pub mass: Option<Real>,
    /// Initial velocity of its centre of mass.
    #[serde(default)]
    #[schemars(extend("unit" = "m/s", "unbounded" = true))]
    pub velocity: [Real; 3],
    /// Initial angular velocity: about its direction, at its length.
    #[serde(default)]
    #[schemars(extend("unit" = "rad/s", "unbounded" = true))]
    pub angular_velocity: [Real; 3],
    #[serde(flatten)]
    pub surface: RigidSurfaceSpec,
    /// A point fixed in the scene that the body turns about, with `hinge_axis`: an axle, a hinge. Its
    /// centre then moves as its `angular_velocity` (along the axis) turns it about the hinge (leave
    /// `velocity` out). With `hinge_to`, the point and axis are fixed in that body instead, and `velocity`
    /// and `angular_velocity` are the body's own.
    #[serde(default)]
    #[schemars(extend("unit" = "m", "unbounded" = true))]
    pub hinge: Option<[Real; 3]>,
    /// The direction of the hinge's axis (any length but zero); give it with `hinge`.
    #[serde(default)]
    #[schemars(extend("unit" = "1", "unbounded" = true))]
    pub hinge_axis: Option<[Real; 3]>,
    /// The body (its index in `rigid_bodies`) that this body's `hinge` point and `hinge_axis` are fixed in,
    /// where the scene draws them: a wheel on a cart's axle, the links of a chain. The two do not meet in
    /// contacts. This body starts with the `velocity` and `angular_velocity` it is given: give them so that
    /// the hinge point moves alike in both bodies, or the joint evens them out in the first step.
    #[serde(default)]
    #[schemars(extend("unit" = "1"))]
    pub hinge_to: Option<usize>,
}

impl Rigid3Shape {
    /// Area (m²) of the body's surface.
    fn area(&self) -> Real {
        let pi = crate::math::PI;
        match self {
            Rigid3Shape::Box { size, .. } => 2.0 * (size[0] * size[1] + size[1] * size[2] + size[2] * size[0]),
            Rigid3Shape::Sphere { radius, .. } => 4.0 * pi * radius * radius,
            Rigid3Shape::Cylinder { radius, length, .. } => 2.0 * pi * radius * (length + radius),
            Rigid3Shape::Mesh { mesh } => mesh.area(),
        }
    }
}

impl RigidBody3Spec {
    /// The initial velocity (m/s) of its centre of mass at `centre` (m): about its hinge if that is fixed
    /// in the scene, else `velocity`.
    fn initial_velocity(&self, centre: &P3) -> [Real; 3] {
        match (self.hinge, self.hinge_to) {
            (Some(hinge), None) => p3(&self.angular_velocity).cross(&(centre - p3(&hinge))).into(),
            _ => self.velocity,
        }
    }

    /// Its hinge and the hinge's unit axis, if it has one; an error names the key that is missing, bad
    /// or at odds with the hinge.
    fn hinge(&self, key: &str) -> Result<Option<Hinge>, SceneError> {
        match (self.hinge, self.hinge_axis) {
            (None, None) => Ok(None),
            (Some(_), None) => Err(SceneError::new(format!("{key}.hinge_axis"), "a hinge needs its axis")),
            (None, Some(_)) => Err(SceneError::new(format!("{key}.hinge"), "hinge_axis is given without a hinge")),
            (Some(point), Some(axis)) => {
                let axis = direction(&format!("{key}.hinge_axis"), &axis)?;
                if self.hinge_to.is_some() {
                    return Ok(Some((point, axis.into())));
                }
                if self.velocity != [0.0; 3] {
                    return Err(SceneError::new(
                        format!("{key}.velocity"),
                        "a hinged body's centre moves as its angular_velocity turns it about the hinge; leave \
                         velocity out",
                    ));
                }
                let w = p3(&self.angular_velocity);
                if (w - axis * w.dot(&axis)).norm() > 1e-9 * w.norm().max(1.0) {
                    return Err(SceneError::new(
                        format!("{key}.angular_velocity"),
                        "a hinged body turns about the hinge's axis only",
                    ));
                }
                Ok(Some((point, axis.into())))
            }
        }
    }

    /// Its solid as drawn, its mass (kg), inertia about its centre of mass in the frame the scene draws it
    /// in (kg·m²) and its centre of mass (m); an error names `key` for a bad direction or mesh, or
    /// neither or both of `density` and `mass`.
    fn solid(&self, key: &str) -> Result<(Solid, Real, Matrix<3>, P3), SceneError> {
        let pi = crate::math::PI;
        let outer = |a: &P3| a * a.transpose();
        // The solid, its volume (m³), the inertia of unit density about its centre (m⁵) and that centre.
        let (solid, volume, inertia, centre) = match &self.shape {
            Rigid3Shape::Box { center, size, axis, angle } => {
                let axis = nalgebra::Unit::new_normalize(direction(&format!("{key}.axis"), axis)?);
                let axes: Matrix<3> = nalgebra::Rotation3::from_axis_angle(&axis, *angle).into_inner();
                let half = p3(size) * 0.5;
                let volume = 8.0 * half.x * half.y * half.z;
                let (x, y, z) = (half.x * half.x, half.y * half.y, half.z * half.z);
                let own = Matrix::<3>::from_diagonal(&P3::new(y + z, x + z, x + y)) * (volume / 3.0);
                (Solid::Box { centre: p3(center), half, axes }, volume, axes * own * axes.transpose(), p3(center))
            }
            Rigid3Shape::Sphere { center, radius } => {
                let volume = 4.0 / 3.0 * pi * radius.powi(3);
                let inertia = Matrix::<3>::identity() * (0.4 * volume * radius * radius);
                (Solid::Sphere { centre: p3(center), radius: *radius }, volume, inertia, p3(center))
            }
            Rigid3Shape::Cylinder { center, axis, radius, length } => {
                let a = direction(&format!("{key}.axis"), axis)?;
                let volume = pi * radius * radius * length;
                let (along, across) = (0.5 * radius * radius, (3.0 * radius * radius + length * length) / 12.0);
                let inertia = (outer(&a) * along + (Matrix::<3>::identity() - outer(&a)) * across) * volume;
                let solid = Solid::Cylinder { centre: p3(center), axis: a, radius: *radius, half_length: 0.5 * length };
                (solid, volume, inertia, p3(center))
            }
            Rigid3Shape::Mesh { mesh } => {
                direction(&format!("{key}.axis"), &mesh.axis)?;
                let built = mesh.build(key)?;
                let (vertices, triangles) = built.triangles();
                let points: Vec<_> = vertices.iter().map(|v| nalgebra::Point3::from(*v)).collect();
                let props = parry3d_f64::mass_properties::MassProperties::from_trimesh(1.0, &points, triangles);
                let centre = props.local_com.coords.map(|c| c as Real);
                let inertia = props.reconstruct_inertia_matrix().map(|c| c as Real);
                (Solid::Mesh(built), props.mass() as Real, inertia, centre)
            }
        };
        let density = match (self.density, self.mass) {
            (Some(rho), None) => rho,
            (None, Some(m)) => m / volume,
            _ => return Err(SceneError::new(key, "give exactly one of density and mass")),
        };
        Ok((solid, density * volume, inertia * density, centre))
    }
}

/// A 3D scene: the grid, time stepping, walls and bodies, and how walls act on the grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
#[schemars(title = "Scene3")]
pub struct Scene3 {
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
    pub gravity: [Real; 3],
    /// The background grid.
    pub grid: Grid3Spec,
    /// Time stepping.
    pub time: TimeSpec,
    /// How walls act on the grid.
    #[serde(default)]
    pub method: Method,
    /// Condition of every wall (and the domain box) unless a wall names its own.
    #[serde(default)]
    pub wall_condition: WallCondition,
    /// Coulomb friction coefficient μ of every `separate` wall unless a wall names its own.
    #[serde(default, with = "friction")]
    #[schemars(schema_with = "friction::schema")]
    pub wall_friction: Real,
    /// The walls besides the domain box: boxes, planes, spheres and cylinders.
    #[serde(default)]
    pub walls: Vec<Wall3Spec>,
    /// The bodies of material: a run needs at least one.
    #[serde(default)]
    pub bodies: Vec<Body3Spec>,
    /// Rigid bodies the material pushes and that push it back; their walls follow the scene's walls
    /// (wall `len(walls) + k` is `rigid_bodies[k]`).
    #[serde(default)]
    pub rigid_bodies: Vec<RigidBody3Spec>,
    /// Settings of the augmented grid (`method = "augmented"`).
    #[serde(default)]
    pub augmented: AugmentedSpec,
    /// Floating-point precision of the engine.
    #[serde(default)]
    pub precision: Precision,
    /// What a run writes besides positions, velocities and bodies.
    #[serde(default)]
    pub output: OutputSpec,
}

fn default_gravity() -> [Real; 3] {
    [0.0, -9.81, 0.0]
}

fn p3(v: &[Real; 3]) -> P3 {
    P3::new(v[0], v[1], v[2])
}

/// `v` normalised, or an error naming `key` when it has no length.
fn direction(key: &str, v: &[Real; 3]) -> Result<P3, SceneError> {
    let d = p3(v);
    let n = d.norm();
    if n > 0.0 && n.is_finite() {
        Ok(d / n)
    } else {
        Err(SceneError::new(key, "must be a direction (a vector of non-zero, finite length)"))
    }
}

impl Scene3 {
    /// Parses the JSON form of a resolved 3D scene: checked against [`Scene3::schema`] first (an error
    /// names the key), then by [`Scene3::validate`].
    pub fn from_json(text: &str) -> Result<Self, SceneError> {
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|e| SceneError::new("scene", format!("not valid JSON: {e}")))?;
        crate::schema::check(Self::schema(), &value).map_err(|e| SceneError::new(e.key, e.reason))?;
        let scene: Self = serde_json::from_value(value).map_err(|e| SceneError::new("scene", e.to_string()))?;
        scene.validate()?;
        Ok(scene)
    }

    /// The JSON Schema of 3D scenes, derived from these types.
    pub fn schema() -> &'static serde_json::Value {
        static SCHEMA: std::sync::OnceLock<serde_json::Value> = std::sync::OnceLock::new();
        SCHEMA.get_or_init(|| serde_json::to_value(schemars::schema_for!(Scene3)).expect("the schema is JSON"))
    }

    /// Cell width h (m).
    pub fn cell_size(&self) -> Real {
        self.grid.domain[0] / self.grid.resolution as Real
    }

    /// Checks each key against [`Scene3::schema`], then the rules between keys: one of `time.dt` and
    /// `time.cfl`, one of `time.steps` and `time.end`, whole numbers of cells, directions of non-zero
    /// length, friction on separate walls only, boxes with `max` beyond `min`, the materials' rules.
    pub fn validate(&self) -> Result<(), SceneError> {
        let t = &self.time;
        let optional = [("time.dt", t.dt), ("time.cfl", t.cfl), ("time.end", t.end)];
        if let Some((key, v)) = optional.into_iter().find_map(|(k, v)| v.filter(|v| !v.is_finite()).map(|v| (k, v))) {
            return Err(SceneError::new(key, format!("must be a finite number, got {v}")));
        }
        let value = serde_json::to_value(self).map_err(|e| SceneError::new("scene", e.to_string()))?;
        crate::schema::check(Self::schema(), &value).map_err(|e| SceneError::new(e.key, e.reason))?;
        self.layout()?;
        if t.steps.is_some() == t.end.is_some() {
            return Err(SceneError::new("time", "give exactly one of steps and end"));
        }
        if t.dt.is_some() == t.cfl.is_some() {
            return Err(SceneError::new("time", "give exactly one of dt and cfl"));
        }
        let mut separate = self.wall_condition == WallCondition::Separate;
        for (i, wall) in self.walls.iter().enumerate() {
            let key = format!("walls[{i}]");
            match wall {
                Wall3Spec::Box { axis, .. } | Wall3Spec::Cylinder { axis, .. } => {
                    direction(&format!("{key}.axis"), axis)?;
                }
                Wall3Spec::Plane { normal, .. } => {
                    direction(&format!("{key}.normal"), normal)?;
                }
                Wall3Spec::Mesh { mesh, .. } => {
                    direction(&format!("{key}.axis"), &mesh.axis)?;
                }
                Wall3Spec::Sphere { .. } => {}
            }
            if let Some(motion) = wall.motion() {
                motion.validate().map_err(|(k, reason)| SceneError::new(format!("{key}.motion.{k}"), reason))?;
            }
            let (condition, friction) = wall.contact_keys();
            let condition = condition.unwrap_or(self.wall_condition);
            if friction.is_some_and(|mu| mu > 0.0) && condition != WallCondition::Separate {
                return Err(SceneError::new(
                    format!("{key}.friction"),
                    format!("friction acts on separate walls; this wall is {condition:?}").to_lowercase(),
                ));
            }
            separate |= condition == WallCondition::Separate;
        }
        let hinged_to: Vec<_> = self.rigid_bodies.iter().map(|b| b.hinge_to).collect();
        for (k, body) in self.rigid_bodies.iter().enumerate() {
            let key = format!("rigid_bodies[{k}]");
            body.solid(&key)?;
            body.hinge(&key)?;
            crate::scene::check_hinge_to(&key, k, &hinged_to, body.hinge.is_some())?;
            separate |= body.surface.condition(&key, self.wall_condition)? == WallCondition::Separate;
        }
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
            match &body.shape {
                Body3Shape::Box { min, max } if (0..3).any(|k| max[k] <= min[k]) => {
                    return Err(SceneError::new(format!("{key}.max"), "must exceed min along every axis"));
                }
                Body3Shape::Cylinder { axis, .. } | Body3Shape::Mesh { mesh: MeshSource { axis, .. } } => {
                    direction(&format!("{key}.axis"), axis)?;
                }
                _ => {}
            }
            body.material.validate().map_err(|(k, reason)| SceneError::new(format!("{key}.material.{k}"), reason))?;
        }
        Ok(())
    }

    /// The grid: nodes at i·h, whole numbers of cells along y and z, at most [`MAX_GRID_NODES`] nodes.
    pub fn layout(&self) -> Result<GridLayout<3>, SceneError> {
        let g = &self.grid;
        let h = self.cell_size();
        let mut cells = [g.resolution; 3];
        for (k, axis) in [(1, "height"), (2, "depth")] {
            let n = g.domain[k] / h;
            if !n.is_finite() || (n - n.round()).abs() > 1e-9 * n.max(1.0) || n.round() < 2.0 {
                return Err(SceneError::new(
                    "grid.domain",
                    format!("{axis} {} is not a whole number (≥ 2) of cells of width {h}", g.domain[k]),
                ));
            }
            cells[k] = n.round() as usize;
        }
        let nodes: Real = cells.iter().map(|&c| c as Real + 5.0).product();
        if nodes > MAX_GRID_NODES as Real {
            return Err(SceneError::new(
                "grid.resolution",
                format!("the grid would have {nodes:.3e} nodes; at most {MAX_GRID_NODES} are allowed"),
            ));
        }
        Ok(GridLayout::new(h, cells))
    }

    /// The walls as a material region and each wall's contact, the domain box last.
    fn walls(&self) -> Result<(Walls3, Vec<WallContact>), SceneError> {
        let side = |s: &SideSpec| if *s == SideSpec::Inside { Side::Inside } else { Side::Outside };
        let mut walls = Vec::new();
        let mut contacts = Vec::new();
        let extent = P3::from_fn(|k, _| self.grid.domain[k]);
        for (i, w) in self.walls.iter().enumerate() {
            let key = format!("walls[{i}]");
            // Walls are sampled (augmented grid) and classified against the grid: keep them within one
            // domain size of the box, as in 2D.
            if let Some((centre, reach)) = w.bounds() {
                if (0..3).any(|k| centre[k] - reach < -extent[k] || centre[k] + reach > 2.0 * extent[k]) {
                    return Err(SceneError::new(
                        &key,
                        "wall lies far outside the domain box (more than one domain size away)",
                    ));
                }
            }
            let wall = match w {
                Wall3Spec::Box { center, size, axis, angle, side: s, .. } => {
                    let axis = nalgebra::Unit::new_normalize(direction(&format!("{key}.axis"), axis)?);
                    let axes: Matrix<3> = nalgebra::Rotation3::from_axis_angle(&axis, *angle).into_inner();
                    Wall3 { solid: Solid::Box { centre: p3(center), half: p3(size) * 0.5, axes }, side: side(s) }
                }
                Wall3Spec::Plane { point, normal, .. } => {
                    // The half-space's normal points out of the material.
                    let normal = -direction(&format!("{key}.normal"), normal)?;
                    Wall3 { solid: Solid::HalfSpace { point: p3(point), normal }, side: Side::Inside }
                }
                Wall3Spec::Sphere { center, radius, side: s, .. } => {
                    Wall3 { solid: Solid::Sphere { centre: p3(center), radius: *radius }, side: side(s) }
                }
                Wall3Spec::Cylinder { center, axis, radius, length, side: s, .. } => {
                    let axis = direction(&format!("{key}.axis"), axis)?;
                    let solid =
                        Solid::Cylinder { centre: p3(center), axis, radius: *radius, half_length: 0.5 * length };
                    Wall3 { solid, side: side(s) }
                }
                Wall3Spec::Mesh { mesh, thickness: Some(thickness), side: s, .. } => {
                    if *s == SideSpec::Inside {
                        return Err(SceneError::new(
                            format!("{key}.side"),
                            "a thin wall (thickness) has material all around it; leave side out",
                        ));
                    }
                    let solid = Solid::Shell { mesh: mesh.build_open(&key)?, half: 0.5 * thickness };
                    Wall3 { solid, side: Side::Outside }
                }
                Wall3Spec::Mesh { mesh, side: s, .. } => Wall3 { solid: Solid::Mesh(mesh.build(&key)?), side: side(s) },
            };
            walls.push(wall);
            let (condition, friction) = w.contact_keys();
            let contact = self.contact(condition.unwrap_or(self.wall_condition), friction);
            contacts.push(WallContact { moving: w.motion().is_some(), ..contact });
        }
        let mut moves: Vec<Option<Motion3>> = self.walls.iter().map(|w| w.motion().cloned()).collect();
        // The rigid bodies: solids moving at their initial velocities about their centres of mass until
        // the engine poses them.
        for (k, body) in self.rigid_bodies.iter().enumerate() {
            let (solid, _, _, centre) = body.solid(&format!("rigid_bodies[{k}]"))?;
            walls.push(Wall3 { solid, side: Side::Outside });
            let contact = self.contact(body.surface.condition.unwrap_or(self.wall_condition), body.surface.friction);
            contacts.push(WallContact { moving: true, ..contact });
            moves.push(Some(Motion3::Constant {
                velocity: body.initial_velocity(&centre),
                angular_velocity: body.angular_velocity,
                pivot: Some(centre.into()),
            }));
        }
        contacts.push(self.contact(self.wall_condition, None));
        let region = Walls3::new(walls, extent)
            .with_moves(moves)
            .map_err(|i| SceneError::new(format!("walls[{i}].motion"), "a plane cannot move; give a box instead"))?;
        Ok((region, contacts))
    }

    /// How a wall of `condition` acts: its own friction, else the scene's (on separate walls).
    fn contact(&self, condition: WallCondition, friction: Option<Real>) -> WallContact {
        let friction = if condition == WallCondition::Separate { friction.unwrap_or(self.wall_friction) } else { 0.0 };
        WallContact { condition, friction, moving: false }
    }

    /// Estimates the memory the simulation of this scene will take, without building it: particles from
    /// the bodies' volumes and seeding, the grid from its nodes.
    pub fn memory_estimate(&self) -> Result<MemoryEstimate, SceneError> {
        self.validate()?;
        // A wall far outside the domain is refused as such, not for the points it would take.
        self.walls()?;
        let layout = self.layout()?;
        let nodes = layout.num_nodes() as u64;
        let h = layout.h;
        let mut particles = 0.0 as Real;
        let mut largest = (0.0 as Real, None);
        for (b, body) in self.bodies.iter().enumerate() {
            let volume = match &body.shape {
                Body3Shape::Box { min, max } => (p3(max) - p3(min)).product(),
                Body3Shape::Sphere { radius, .. } => 4.0 / 3.0 * crate::math::PI * radius.powi(3),
                Body3Shape::Cylinder { radius, length, .. } => crate::math::PI * radius * radius * length,
                Body3Shape::Mesh { mesh } => mesh.build(&format!("bodies[{b}]"))?.volume() as Real,
            };
            let domain: Real = self.grid.domain.iter().product();
            let count = volume.min(domain) / seeding_spacing(body, h).powi(3);
            particles += count;
            if count > largest.0 {
                largest = (count, Some(b));
            }
        }
        // Per particle: the state and its scratch (as in 2D, for D = 3); per node: mass, spline mass,
        // momentum (3), flags and the schedule's share.
        let per_particle = (crate::simulation::State::<3>::bytes_per_particle()
            + std::mem::size_of::<u32>()
            + 4 * std::mem::size_of::<Real>()) as Real;
        let (particle_bytes, grid_bytes) =
            (particles * per_particle, nodes as Real * 9.0 * std::mem::size_of::<Real>() as Real);
        // The boundary points: each with its normals, velocity, grid values and index entry.
        let point_bytes =
            self.boundary_points() * (std::mem::size_of::<crate::wall::BoundaryPoint<3>>() + 6 * 8) as Real;
        let key = match largest.1 {
            Some(b) if particle_bytes > grid_bytes.max(point_bytes) => format!("bodies[{b}].seeding"),
            _ if point_bytes > grid_bytes => "augmented.spacing".to_string(),
            _ => "grid.resolution".to_string(),
        };
        let grid_bytes = grid_bytes + point_bytes;
        let saturate = |v: Real| if v >= u64::MAX as Real { u64::MAX } else { v as u64 };
        Ok(MemoryEstimate { bytes: saturate(particle_bytes + grid_bytes), particles: saturate(particles), nodes, key })
    }

    /// About how many points sample the walls' surfaces (the domain box's included) at the augmented
    /// grid's spacing: area over spacing², plus a row along every edge.
    fn boundary_points(&self) -> Real {
        let spacing = self.augmented.spacing * self.cell_size();
        let d = &self.grid.domain;
        let box_area = 2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0]);
        let area: Real = box_area
            + self.walls.iter().map(|w| w.area(d)).sum::<Real>()
            + self.rigid_bodies.iter().map(|b| b.shape.area()).sum::<Real>();
        area / (spacing * spacing) * 1.5
    }

    /// The grid, the walls and their treatment by `method`, without the bodies (the interpolation test's
    /// grid).
    pub fn build_walls(&self, method: Method) -> Result<(GridLayout<3>, Walls3, Boundary<3>), SceneError> {
        self.validate()?;
        let layout = self.layout()?;
        let h = layout.h;
        let (region, contacts) = self.walls()?;
        let points = self.boundary_points();
        if points.is_nan() || points > MAX_BOUNDARY_POINTS {
            return Err(SceneError::new(
                "augmented.spacing",
                format!("the walls would be sampled with about {points:.3e} points (at most {MAX_BOUNDARY_POINTS:e}); raise the spacing or lower grid.resolution"),
            ));
        }
        if method == Method::Augmented {
            // A mesh is sampled from candidates a quarter spacing apart along its triangles' longest edges.
            let spacing = wide(self.augmented.spacing * h);
            for (i, wall) in region.walls.iter().enumerate() {
                let candidates = match &wall.solid {
                    Solid::Mesh(mesh) => mesh.sample_candidates(spacing, None),
                    Solid::Shell { mesh, half } => mesh.sample_candidates(spacing, Some(wide(*half))),
                    _ => 0.0,
                };
                if candidates.is_nan() || candidates > wide(MAX_BOUNDARY_POINTS) {
                    let n = self.walls.len();
                    return Err(SceneError::new(
                        if i < n { format!("walls[{i}]") } else { format!("rigid_bodies[{}]", i - n) },
                        format!("sampling this mesh at the augmented grid's spacing would try about {candidates:.3e} points (at most {MAX_BOUNDARY_POINTS:e}); split its long triangles, or raise augmented.spacing"),
                    ));
                }
            }
        }
        let boundary = match method {
            Method::Naive => Boundary::Naive(NaiveBoundary::new(&layout, &region, contacts)),
            Method::Augmented => {
                let (delta, spacing) = (self.augmented.delta, self.augmented.spacing);
                Boundary::Augmented(
                    AugmentedGrid::new(&layout, &region, spacing * h, contacts, delta * h)
                        .with_transfer(self.augmented.transfer),
                )
            }
        };
        Ok((layout, region, boundary))
    }

    /// Validates the scene and builds the simulation; returns warnings beside it.
    pub fn build(&self, method: Method) -> Result<(Simulation<3>, Vec<String>), SceneError> {
        if self.precision != Precision::NATIVE {
            return Err(SceneError::new(
                "precision",
                format!("this engine runs {:?} scenes, not {:?}", Precision::NATIVE, self.precision),
            ));
        }
        self.validate()?;
        if self.bodies.is_empty() {
            return Err(SceneError::new("bodies", "a scene needs at least one body"));
        }
        let (layout, region, boundary) = self.build_walls(method)?;
        let h = layout.h;
        let fastest = region.fastest();
        let mut particles = Particles::<3>::default();
        for (b, body) in self.bodies.iter().enumerate() {
            let key = format!("bodies[{b}]");
            let first = particles.len();
            seed_body(&key, body, b, self.seed, h, &region, &mut particles)?;
            let outside = (first..particles.len()).filter(|&p| region.distance(&particles.x[p]).distance > 0.0).count();
            if outside > 0 {
                return Err(SceneError::new(
                    key,
                    format!(
                        "body lies partly or wholly outside the walls ({outside} of {} particles)",
                        particles.len() - first
                    ),
                ));
            }
        }
        let materials: Vec<Material> = self.bodies.iter().map(|b| b.material.clone()).collect();
        let (mut bodies, mut contacts) = (Vec::new(), Vec::new());
        for (k, spec) in self.rigid_bodies.iter().enumerate() {
            let (_, mass, inertia, centre) = spec.solid(&format!("rigid_bodies[{k}]"))?;
            bodies.push(RigidBody { wall: self.walls.len() + k, mass, inertia, centre });
            let hinge = spec.hinge(&format!("rigid_bodies[{k}]"))?;
            contacts.push(spec.surface.contact(hinge, spec.hinge_to));
        }
        let contacts: Option<Box<dyn Contacts<3>>> =
            (!bodies.is_empty()).then(|| Box::new(Contacts3::new(&region, &bodies, contacts, h)) as _);
        let mut model = Model {
            layout,
            materials,
            gravity: p3(&self.gravity),
            region: Box::new(region),
            boundary,
            wall_fraction: None,
            dt: 0.0,
            bodies,
            contacts,
        };
        let (dt, warning) = time_step(&self.time, model.stable_dt(), fastest, h).map_err(|e| {
            // A rigid body's wall follows the scene's: name the body.
            match fastest.filter(|&(wall, _)| wall >= self.walls.len() && e.key == format!("walls[{wall}].motion")) {
                Some((wall, _)) => {
                    SceneError::new(format!("rigid_bodies[{}].velocity", wall - self.walls.len()), e.reason)
                }
                None => e,
            }
        })?;
        model.dt = dt;
        let mut sim = Simulation::new(model, particles);
        // Each rigid body's wall is posed by the engine from the start, at its initial velocities.
        for (body, spec) in sim.model.bodies.iter().zip(&self.rigid_bodies) {
            let pose = WallPose {
                time: 0.0,
                position: [0.0; 3],
                angle: [0.0; 3],
                velocity: spec.initial_velocity(&body.centre),
                angular_velocity: spec.angular_velocity,
            };
            sim.state.wall_poses.push((body.wall, pose));
        }
        let mut warnings: Vec<String> = warning.into_iter().collect();
        warnings.extend(crate::scene::unused_material_keys(self.bodies.iter().map(|b| &b.material)));
        Ok((sim, warnings))
    }
}

/// The side (m) of the cubes that get one particle each: the seeding's `spacing`, or h/∛per_cell
/// (default h/2: 8 per cell).
fn seeding_spacing(body: &Body3Spec, h: Real) -> Real {
    match (body.seeding.spacing, body.seeding.per_cell) {
        (Some(s), None) => s,
        (None, Some(n)) => h / (n as Real).cbrt(),
        _ => h / 2.0,
    }
}

/// Seeds one body on a jittered grid of cubes aligned with the domain origin (one random point per
/// cube of side `spacing`; default h/2, 8 per cell); with `fill`, only the points inside `region`.
fn seed_body(
    key: &str,
    body: &Body3Spec,
    index: usize,
    seed: u64,
    h: Real,
    region: &Walls3,
    out: &mut Particles<3>,
) -> Result<(), SceneError> {
    let spacing = seeding_spacing(body, h);
    let (solid, volume) = match &body.shape {
        Body3Shape::Box { min, max } => {
            let (lo, hi) = (p3(min), p3(max));
            let solid = Solid::Box { centre: (lo + hi) * 0.5, half: (hi - lo) * 0.5, axes: Matrix::<3>::identity() };
            (solid, (hi - lo).product())
        }
        Body3Shape::Sphere { center, radius } => {
            (Solid::Sphere { centre: p3(center), radius: *radius }, 4.0 / 3.0 * crate::math::PI * radius.powi(3))
        }
        Body3Shape::Cylinder { center, axis, radius, length } => {
            let axis = direction(&format!("{key}.axis"), axis)?;
            let solid = Solid::Cylinder { centre: p3(center), axis, radius: *radius, half_length: 0.5 * length };
            (solid, crate::math::PI * radius * radius * length)
        }
        Body3Shape::Mesh { mesh } => {
            let mesh = mesh.build(key)?;
            let volume = mesh.volume() as Real;
            (Solid::Mesh(mesh), volume)
        }
    };
    // The bounding box of the solid: its distance along each axis from far away.
    let reach = |dir: P3| {
        let far = 1e3 * (1.0 + volume.cbrt());
        let probe = solid.centre();
        probe + dir * (far - solid.signed_distance(&(probe + dir * far)).0)
    };
    let (lo, hi) = match &solid {
        Solid::Mesh(mesh) => {
            let (lo, hi) = mesh.bounds();
            (P3::from_fn(|k, _| lo[k] as Real), P3::from_fn(|k, _| hi[k] as Real))
        }
        _ => (P3::from_fn(|k, _| reach(-P3::ith(k, 1.0))[k]), P3::from_fn(|k, _| reach(P3::ith(k, 1.0))[k])),
    };
    let cells_f = ((hi - lo) / spacing).map(|c| c.ceil() + 1.0);
    // A NaN (a body too large for floating point) is refused too.
    if cells_f.product().is_nan() || cells_f.product() > MAX_SEED_CANDIDATES as Real {
        return Err(SceneError::new(
            format!("{key}.seeding"),
            format!(
                "would try about {:.3e} points (at most {MAX_SEED_CANDIDATES}); raise the spacing",
                cells_f.product()
            ),
        ));
    }
    let cells = cells_f.map(|c| c as i64);
    // One stream per body, so adding a body does not reshuffle the others.
    let mut rng = Pcg64::seed_from_u64(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let first = (lo / spacing).map(|c| c.floor() as i64);
    let mut positions = Vec::new();
    // The points in the body's shape share its volume, those the walls cut off (`fill`) included.
    let mut in_shape = 0usize;
    for l in 0..cells.z {
        for j in 0..cells.y {
            for i in 0..cells.x {
                let corner = P3::new((first.x + i) as Real, (first.y + j) as Real, (first.z + l) as Real) * spacing;
                // Drawn in f64 in either precision, so that f32 and f64 scenes seed the same particles.
                let jitter = P3::new(rng.gen::<f64>() as Real, rng.gen::<f64>() as Real, rng.gen::<f64>() as Real);
                let p = corner + jitter * spacing;
                if solid.signed_distance(&p).0 < 0.0 {
                    in_shape += 1;
                    if !(body.fill && region.distance(&p).distance > 0.0) {
                        positions.push(p);
                    }
                }
            }
        }
    }
    if positions.is_empty() {
        return Err(SceneError::new(
            format!("{key}.seeding"),
            format!("no particle was seeded (the body is smaller than the seeding spacing {spacing} m, or outside the walls)"),
        ));
    }
    let n = in_shape as Real;
    let density = ConstitutiveModel::<3>::density(&body.material);
    let (mass, vol0) = (volume * density / n, volume / n);
    let v = p3(&body.velocity);
    for p in positions {
        out.push(p, v, mass, vol0, index as u32);
    }
    Ok(())
}
