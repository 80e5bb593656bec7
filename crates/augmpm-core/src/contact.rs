//! What the rigid bodies meet besides the material: each other, the scene's walls and their hinges (an
//! axle, a hinged flap). Resolved over each step by rapier, dimforge's rigid-body engine.
//!
//! The order within a step:
//! - The material's impulse and gravity have already changed the bodies' velocities ([`RigidBody::kick`]).
//! - Rapier takes the bodies where they are at the step's start, with those velocities. The scene's walls
//!   are fixed bodies, or kinematic ones moving over the step as the region places them.
//! - It solves the contacts and joints over the step and moves the bodies to its end.
//!
//! Rapier's world is built afresh each step from augmpm's state (the bodies' wall poses). Nothing else
//! needs to be kept, so a resumed run is bitwise the same. No contact impulse is carried from one step to
//! the next (no warm start); at MPM's steps (~1e-4 s) the solver's own iterations suffice. Rapier runs on
//! one thread, so its result does not depend on the thread count.
//!
//! The contact surfaces in 2D (`Contacts2`, rapier2d):
//! - a body: its drawn solid (a disk, a convex polygon, or the exact convex pieces of a concave one);
//! - a container polygon and the domain box: closed polylines (hollow: bodies stay inside);
//! - an obstacle polygon: a solid as a body is;
//! - a circle: a disk, or around material a ring of segments at most a cell long;
//! - a stroke: capsules along its centreline.
//!
//! In 3D (`Contacts3`, rapier3d):
//! - a body: its drawn solid (a box, a ball, a capped cylinder; a mesh as the convex pieces of its
//!   approximate V-HACD decomposition, since two triangle meshes meet unreliably);
//! - an obstacle wall: its solid (a mesh as its triangles);
//! - a container (a box, sphere, cylinder or mesh the material is inside) and a thin mesh wall: its
//!   surface as triangles (hollow; a thin wall with its half thickness as contact skin);
//! - a plane: the half-space past it; the domain box: its six faces' half-spaces.
//!
//! Friction and restitution are the bodies' (`contact_friction`, `restitution`). A wall's own are 0, and
//! each contact takes the larger of its two sides' values.

// `Real` is f64 here, f32 in augmpm-core-f32; rapier works in f64 in either.
#![allow(clippy::useless_conversion, clippy::unnecessary_cast)]

use rapier2d_f64::na::{Isometry2, Point2, Vector2};
use rapier2d_f64::prelude as rp;
use rapier3d_f64::na::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rapier3d_f64::prelude as rp3;

use crate::geometry::{Point, Region, Side, WallShape, Walls2};
use crate::geometry3::{Solid, Wall3, Walls3};
use crate::math::{Matrix, Real, Vector, PI};
use crate::motion::WallPose;
use crate::rigid::RigidBody;

/// What the rigid bodies meet besides the material, resolved over one step.
pub trait Contacts<const D: usize>: Send + Sync {
    /// The bodies' poses at `t + dt` (s), from `kicked`: each body's pose at `t` with its velocities
    /// after the step's impulses and gravity, in the order of `bodies`. The scene's walls are where
    /// `region` places them over the step.
    fn drift(
        &self,
        t: Real,
        dt: Real,
        bodies: &[RigidBody<D>],
        kicked: &[WallPose<D>],
        region: &dyn Region<D>,
    ) -> Vec<WallPose<D>>;
}

/// A hinge: the point fixed in the scene that a body turns about (m; z unused in 2D) and the unit axis
/// it turns about there (z in 2D).
pub type Hinge = ([Real; 3], [Real; 3]);

/// How a rigid body meets others: friction and restitution of its contacts, and its hinge if it has one:
/// fixed in the scene, or in the body `hinge_to` (an index among the bodies) where the scene draws it.
#[derive(Clone, Debug, PartialEq)]
pub struct Contact {
    pub friction: Real,
    pub restitution: Real,
    pub hinge: Option<Hinge>,
    pub hinge_to: Option<usize>,
}

/// The contacts of a 2D scene's rigid bodies, through rapier.
pub struct Contacts2 {
    /// The scene's walls and the domain box: each one's index among the region's walls, its surface in
    /// the frame of its pivot, and the pivot (m, where the scene draws it).
    walls: Vec<(usize, rp::SharedShape, Vector2<f64>)>,
    /// Each body's surface in the frame of its centre of mass as drawn, and how it meets others.
    bodies: Vec<(rp::SharedShape, Contact)>,
    /// The grid spacing (m): rapier's length unit.
    h: f64,
}

impl Contacts2 {
    /// The contacts of `bodies` (whose walls are the last of `region`'s) in `region`, on a grid of
    /// spacing `h` (m).
    pub fn new(region: &Walls2, bodies: &[RigidBody<2>], contacts: Vec<Contact>, h: Real) -> Self {
        let first_body = bodies.iter().map(|b| b.wall).min().unwrap_or(region.walls.len());
        let mut walls: Vec<_> = (0..first_body)
            .map(|w| {
                let pivot = region.pivot(w);
                (w, surface(region.drawn(w), &pivot, h), vector(&pivot))
            })
            .collect();
        let domain_box = WallShape::Polygon(region.domain_box().clone());
        walls.push((region.box_index(), surface(&domain_box, &Point::zeros(), h), Vector2::zeros()));
        let bodies =
            bodies.iter().zip(contacts).map(|(b, c)| (surface(region.drawn(b.wall), &b.centre, h), c)).collect();
        Self { walls, bodies, h: h as f64 }
    }
}

impl Contacts<2> for Contacts2 {
    fn drift(
        &self,
        t: Real,
        dt: Real,
        bodies: &[RigidBody<2>],
        kicked: &[WallPose<2>],
        region: &dyn Region<2>,
    ) -> Vec<WallPose<2>> {
        let mut set = rp::RigidBodySet::new();
        let mut colliders = rp::ColliderSet::new();
        let mut joints = rp::ImpulseJointSet::new();
        // A wall's friction and restitution are 0, so that each contact takes its body's.
        let collider = |shape: &rp::SharedShape, friction: Real, restitution: Real| {
            rp::ColliderBuilder::new(shape.clone())
                .density(0.0)
                .friction(friction as f64)
                .restitution(restitution as f64)
                .friction_combine_rule(rp::CoefficientCombineRule::Max)
                .restitution_combine_rule(rp::CoefficientCombineRule::Max)
        };
        for (wall, shape, pivot) in &self.walls {
            let handle = match region.placement(*wall) {
                Some(p) => {
                    let at = |k: usize| isometry(&(p.pivot + p.offset[k]), p.turn[k][2]);
                    let handle = set.insert(rp::RigidBodyBuilder::kinematic_position_based().position(at(0)));
                    set[handle].set_next_kinematic_position(at(1));
                    handle
                }
                None => set.insert(rp::RigidBodyBuilder::fixed().translation(*pivot)),
            };
            colliders.insert_with_parent(collider(shape, 0.0, 0.0), handle, &mut set);
        }
        let ground = set.insert(rp::RigidBodyBuilder::fixed());
        let handles: Vec<_> = bodies
            .iter()
            .zip(kicked)
            .zip(&self.bodies)
            .map(|((body, pose), (shape, contact))| {
                let centre = body.centre + pose.offset(t);
                let mass = rp::MassProperties::new(Point2::origin(), body.mass as f64, body.inertia[(2, 2)] as f64);
                let builder = rp::RigidBodyBuilder::dynamic()
                    .position(isometry(&centre, pose.turn(t)[2]))
                    .linvel(Vector2::new(pose.velocity[0] as f64, pose.velocity[1] as f64))
                    .angvel(pose.angular_velocity[2] as f64)
                    .additional_mass_properties(mass)
                    .can_sleep(false);
                let handle = set.insert(builder);
                colliders.insert_with_parent(collider(shape, contact.friction, contact.restitution), handle, &mut set);
                handle
            })
            .collect();
        // Each hinge joins its body's frame (its drawing's, about its centre) to the scene or to the body it
        // is hinged to, at the point where the scene draws it; two hinged bodies do not meet in contacts.
        for (k, (body, (_, contact))) in bodies.iter().zip(&self.bodies).enumerate() {
            if let Some((at, _)) = contact.hinge {
                let hinge = Point::new(at[0], at[1]);
                let (parent, origin) = match contact.hinge_to {
                    Some(j) => (handles[j], bodies[j].centre),
                    None => (ground, Point::zeros()),
                };
                let joint = rp::RevoluteJointBuilder::new()
                    .local_anchor1(Point2::from(vector(&(hinge - origin))))
                    .local_anchor2(Point2::from(vector(&(hinge - body.centre))))
                    .contacts_enabled(contact.hinge_to.is_none());
                joints.insert(parent, handles[k], joint, true);
            }
        }
        let params = rp::IntegrationParameters { dt: dt as f64, length_unit: self.h, ..Default::default() };
        rp::PhysicsPipeline::new().step(
            &Vector2::zeros(),
            &params,
            &mut rp::IslandManager::new(),
            &mut rp::DefaultBroadPhase::new(),
            &mut rp::NarrowPhase::new(),
            &mut set,
            &mut colliders,
            &mut joints,
            &mut rp::MultibodyJointSet::new(),
            &mut rp::CCDSolver::new(),
            &(),
            &(),
        );
        bodies
            .iter()
            .zip(kicked)
            .zip(handles)
            .map(|((body, pose), handle)| {
                let moved = &set[handle];
                let start = pose.turn(t)[2];
                // The turn over the step, added to the angle so that it is not wrapped to (−π, π].
                let turned = (rapier2d_f64::na::UnitComplex::new(start as f64).inverse() * moved.rotation()).angle();
                let (x, v) = (moved.translation(), moved.linvel());
                // The offset from the drawing in f64 first, so that f32 keeps a slow body's small steps.
                let offset = x - vector(&body.centre);
                WallPose::planar(
                    t + dt,
                    [offset.x as Real, offset.y as Real],
                    start + turned as Real,
                    [v.x as Real, v.y as Real],
                    moved.angvel() as Real,
                )
            })
            .collect()
    }
}

/// The triangles (vertex indices) of a simple counter-clockwise polygon, by ear clipping: corner after
/// corner, cut off one that turns left and whose triangle holds no other vertex. A polygon that rounding
/// leaves without such a corner keeps the triangles found so far.
fn ear_clip(points: &[Point2<f64>]) -> Vec<[u32; 3]> {
    let cross = |a: &Point2<f64>, b: &Point2<f64>, c: &Point2<f64>| (b - a).perp(&(c - a));
    let mut left: Vec<usize> = (0..points.len()).collect();
    let mut triangles = Vec::with_capacity(points.len().saturating_sub(2));
    while left.len() >= 3 {
        let n = left.len();
        let corner = |k: usize| [left[(k + n - 1) % n], left[k], left[(k + 1) % n]];
        let ear = (0..n).find(|&k| {
            let [i, j, l] = corner(k);
            let (a, b, c) = (&points[i], &points[j], &points[l]);
            cross(a, b, c) > 0.0
                && left.iter().filter(|&&m| m != i && m != j && m != l).all(|&m| {
                    let p = &points[m];
                    cross(a, b, p) < 0.0 || cross(b, c, p) < 0.0 || cross(c, a, p) < 0.0
                })
        });
        let Some(k) = ear else { break };
        triangles.push(corner(k).map(|i| i as u32));
        left.remove(k);
    }
    triangles
}

fn vector(p: &Point) -> Vector2<f64> {
    Vector2::new(p.x as f64, p.y as f64)
}

fn isometry(x: &Point, angle: Real) -> Isometry2<f64> {
    Isometry2::new(vector(x), angle as f64)
}

/// The contact surface of a wall or body drawn as `shape`, in the frame of `origin` (m); circles as rings
/// of segments at most `h` (m) long.
fn surface(shape: &WallShape, origin: &Point, h: Real) -> rp::SharedShape {
    let local = |p: &Point| Point2::from(vector(&(p - origin)));
    let closed = |points: Vec<Point2<f64>>| {
        let n = points.len() as u32;
        rp::SharedShape::polyline(points, Some((0..n).map(|i| [i, (i + 1) % n]).collect()))
    };
    match shape {
        WallShape::Polygon(p) => closed(p.vertices.iter().map(local).collect()),
        WallShape::Obstacle(p) => {
            let points: Vec<_> = p.vertices.iter().map(local).collect();
            let n = points.len();
            // Counter-clockwise and convex: every corner turns left (or goes straight on).
            let convex = (0..n).all(|i| {
                let (a, b, c) = (points[i], points[(i + 1) % n], points[(i + 2) % n]);
                (b - a).perp(&(c - b)) >= 0.0
            });
            let solid = if convex { rp::SharedShape::convex_polyline(points.clone()) } else { None };
            solid.unwrap_or_else(|| {
                // Concave: the convex pieces of its triangulation (Hertel–Mehlhorn), which cover it exactly.
                let parts: Vec<_> = rapier2d_f64::parry::transformation::hertel_mehlhorn(&points, &ear_clip(&points))
                    .into_iter()
                    .filter_map(rp::SharedShape::convex_polyline)
                    .map(|part| (Isometry2::identity(), part))
                    .collect();
                if parts.is_empty() {
                    closed(points)
                } else {
                    rp::SharedShape::compound(parts)
                }
            })
        }
        WallShape::Circle(c, Side::Outside) => {
            let (ball, at) = (rp::SharedShape::ball(c.radius as f64), vector(&(c.center - origin)));
            if at == Vector2::zeros() {
                ball
            } else {
                rp::SharedShape::compound(vec![(Isometry2::translation(at.x, at.y), ball)])
            }
        }
        WallShape::Circle(c, Side::Inside) => {
            let n = ((2.0 * PI * c.radius / h).ceil() as usize).max(16);
            closed(
                (0..n)
                    .map(|k| {
                        let a = 2.0 * PI * k as Real / n as Real;
                        local(&(c.center + Point::new(a.cos(), a.sin()) * c.radius))
                    })
                    .collect(),
            )
        }
        WallShape::Stroke(s) => rp::SharedShape::compound(
            s.vertices
                .windows(2)
                .map(|ab| {
                    (Isometry2::identity(), rp::SharedShape::capsule(local(&ab[0]), local(&ab[1]), s.half as f64))
                })
                .collect(),
        ),
    }
}

/// The contacts of a 3D scene's rigid bodies, through rapier.
pub struct Contacts3 {
    /// The scene's walls: each one's index among the region's walls, its surface placed relative to its
    /// pivot (the shape and where it sits in the pivot's frame), and the pivot (m, where the scene draws it).
    walls: Vec<(usize, Surface3, Vector3<f64>)>,
    /// The domain box's far corner (m).
    extent: Vector3<f64>,
    /// Each body's surface placed relative to its centre of mass as drawn, its mass properties in the frame
    /// it is drawn in, and how it meets others.
    bodies: Vec<(Surface3, rp3::MassProperties, Contact)>,
    /// The grid spacing (m): rapier's length unit.
    h: f64,
}

impl Contacts3 {
    /// The contacts of `bodies` (whose walls are the last of `region`'s) in `region`, on a grid of
    /// spacing `h` (m).
    pub fn new(region: &Walls3, bodies: &[RigidBody<3>], contacts: Vec<Contact>, h: Real) -> Self {
        let first_body = bodies.iter().map(|b| b.wall).min().unwrap_or(region.walls.len());
        let walls = (0..first_body)
            .map(|w| {
                let pivot = region.pivot(w);
                (w, surface3(&region.walls[w], &pivot, h, false), pivot.map(|c| c as f64))
            })
            .collect();
        let bodies = bodies
            .iter()
            .zip(contacts)
            .map(|(b, c)| {
                let inertia = b.inertia.map(|c| c as f64);
                let mass = rp3::MassProperties::with_inertia_matrix(Point3::origin(), b.mass as f64, inertia);
                (surface3(&region.walls[b.wall], &b.centre, h, true), mass, c)
            })
            .collect();
        Self { walls, extent: region.extent().map(|c| c as f64), bodies, h: h as f64 }
    }
}

impl Contacts<3> for Contacts3 {
    fn drift(
        &self,
        t: Real,
        dt: Real,
        bodies: &[RigidBody<3>],
        kicked: &[WallPose<3>],
        region: &dyn Region<3>,
    ) -> Vec<WallPose<3>> {
        let mut set = rp3::RigidBodySet::new();
        let mut colliders = rp3::ColliderSet::new();
        // A wall's friction and restitution are 0, so that each contact takes its body's.
        let collider = |surface: &Surface3, friction: Real, restitution: Real| {
            rp3::ColliderBuilder::new(surface.shape.clone())
                .position(surface.at)
                .contact_skin(surface.skin)
                .density(0.0)
                .friction(friction as f64)
                .restitution(restitution as f64)
                .friction_combine_rule(rp3::CoefficientCombineRule::Max)
                .restitution_combine_rule(rp3::CoefficientCombineRule::Max)
        };
        let turned = |turn: &[Real; 3]| UnitQuaternion::from_scaled_axis(Vector3::from(*turn).map(|c| c as f64));
        for (wall, surface, pivot) in &self.walls {
            let handle = match region.placement(*wall) {
                Some(p) => {
                    let place = |k: usize| {
                        let x = (p.pivot + p.offset[k]).map(|c| c as f64);
                        Isometry3::from_parts(Translation3::from(x), turned(&p.turn[k]))
                    };
                    let handle = set.insert(rp3::RigidBodyBuilder::kinematic_position_based().position(place(0)));
                    set[handle].set_next_kinematic_position(place(1));
                    handle
                }
                None => set.insert(rp3::RigidBodyBuilder::fixed().translation(*pivot)),
            };
            colliders.insert_with_parent(collider(surface, 0.0, 0.0), handle, &mut set);
        }
        // The domain box: the half-spaces past its six faces.
        let ground = set.insert(rp3::RigidBodyBuilder::fixed());
        for k in 0..3 {
            for (corner, outward) in [(0.0, -1.0), (self.extent[k], 1.0)] {
                let mut normal = Vector3::zeros();
                normal[k] = -outward;
                let mut x = Vector3::zeros();
                x[k] = corner;
                let face = Surface3 {
                    shape: rp3::SharedShape::halfspace(nalgebra::Unit::new_normalize(normal)),
                    at: Isometry3::translation(x.x, x.y, x.z),
                    skin: 0.0,
                };
                colliders.insert_with_parent(collider(&face, 0.0, 0.0), ground, &mut set);
            }
        }
        let mut joints = rp3::ImpulseJointSet::new();
        let handles: Vec<_> = bodies
            .iter()
            .zip(kicked)
            .zip(&self.bodies)
            .map(|((body, pose), (surface, mass, contact))| {
                let centre = (body.centre + pose.offset(t)).map(|c| c as f64);
                let builder = rp3::RigidBodyBuilder::dynamic()
                    .position(Isometry3::from_parts(Translation3::from(centre), turned(&pose.turn(t))))
                    .linvel(Vector3::from(pose.velocity).map(|c| c as f64))
                    .angvel(Vector3::from(pose.angular_velocity).map(|c| c as f64))
                    .additional_mass_properties(*mass)
                    .can_sleep(false);
                let handle = set.insert(builder);
                colliders.insert_with_parent(
                    collider(surface, contact.friction, contact.restitution),
                    handle,
                    &mut set,
                );
                handle
            })
            .collect();
        // As in 2D. A body's frame is its drawing's, so the axis and the anchors keep their drawn values.
        for (k, (body, (_, _, contact))) in bodies.iter().zip(&self.bodies).enumerate() {
            if let Some((point, axis)) = contact.hinge {
                let (point, axis) = (Vector3::from(point).map(|c| c as f64), Vector3::from(axis).map(|c| c as f64));
                let (parent, origin) = match contact.hinge_to {
                    Some(j) => (handles[j], wide3(&bodies[j].centre)),
                    None => (ground, Vector3::zeros()),
                };
                let joint = rp3::RevoluteJointBuilder::new(nalgebra::Unit::new_normalize(axis))
                    .local_anchor1(Point3::from(point - origin))
                    .local_anchor2(Point3::from(point - wide3(&body.centre)))
                    .contacts_enabled(contact.hinge_to.is_none());
                joints.insert(parent, handles[k], joint, true);
            }
        }
        let params = rp3::IntegrationParameters { dt: dt as f64, length_unit: self.h, ..Default::default() };
        rp3::PhysicsPipeline::new().step(
            &Vector3::zeros(),
            &params,
            &mut rp3::IslandManager::new(),
            &mut rp3::DefaultBroadPhase::new(),
            &mut rp3::NarrowPhase::new(),
            &mut set,
            &mut colliders,
            &mut joints,
            &mut rp3::MultibodyJointSet::new(),
            &mut rp3::CCDSolver::new(),
            &(),
            &(),
        );
        bodies
            .iter()
            .zip(handles)
            .map(|(body, handle)| {
                let moved = &set[handle];
                let (x, v, w) = (moved.translation(), moved.linvel(), moved.angvel());
                let turn = moved.rotation().scaled_axis();
                WallPose {
                    time: t + dt,
                    // The offset from the drawing in f64 first, so that f32 keeps a slow body's small steps.
                    position: std::array::from_fn(|k| (x[k] - body.centre[k] as f64) as Real),
                    angle: std::array::from_fn(|k| turn[k] as Real),
                    velocity: std::array::from_fn(|k| v[k] as Real),
                    angular_velocity: std::array::from_fn(|k| w[k] as Real),
                }
            })
            .collect()
    }
}

/// A 3D vector in f64.
fn wide3(v: &Vector<3>) -> Vector3<f64> {
    v.map(|c| c as f64)
}

/// A rotation of f64 from a matrix of `Real` (orthonormal columns).
fn rotation(axes: &Matrix<3>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(axes.map(|c| c as f64)))
}

/// A 3D contact surface: a shape, where it sits in its body's frame, and the skin (m) its contacts keep
/// around it (a thin wall's half thickness).
struct Surface3 {
    shape: rp3::SharedShape,
    at: Isometry3<f64>,
    skin: f64,
}

/// The contact surface of a 3D wall or body drawn as `wall`, placed relative to `origin` (m); the surfaces
/// of containers as triangles, spheres and cylinders with at least one triangle per cell `h` (m) around.
/// A mesh that moves freely (a rigid body, `dynamic`) is the convex pieces of its approximate convex
/// decomposition (parry's V-HACD): rapier's contacts between two triangle meshes are not reliable.
fn surface3(wall: &Wall3, origin: &Vector<3>, h: Real, dynamic: bool) -> Surface3 {
    if let (true, Solid::Mesh(m)) = (dynamic, &wall.solid) {
        let (vertices, triangles) = m.triangles();
        let shift = -wide3(origin);
        let points: Vec<_> = vertices.iter().map(|v| Point3::from(v + shift)).collect();
        use rapier3d_f64::parry::transformation::vhacd::{VHACDParameters, VHACD};
        let pieces = VHACD::decompose(&VHACDParameters::default(), &points, triangles, true);
        let parts: Vec<_> = (pieces.compute_exact_convex_hulls(&points, triangles).into_iter())
            .filter_map(|(vertices, indices)| rp3::SharedShape::convex_mesh(vertices, &indices))
            .map(|part| (Isometry3::identity(), part))
            .collect();
        // No piece (a mesh too thin for V-HACD's voxels): its convex hull, or its triangles.
        let shape = if parts.is_empty() {
            rp3::SharedShape::convex_hull(&points).unwrap_or_else(|| {
                rp3::SharedShape::trimesh(points.clone(), triangles.to_vec()).expect("a closed mesh")
            })
        } else {
            rp3::SharedShape::compound(parts)
        };
        return Surface3 { shape, at: Isometry3::identity(), skin: 0.0 };
    }
    let (shape, at) = solid_surface(wall, origin, h);
    let skin = if let Solid::Shell { half, .. } = &wall.solid { *half as f64 } else { 0.0 };
    Surface3 { shape, at, skin }
}

fn solid_surface(wall: &Wall3, origin: &Vector<3>, h: Real) -> (rp3::SharedShape, Isometry3<f64>) {
    let at = |centre: &Vector<3>, r: UnitQuaternion<f64>| {
        Isometry3::from_parts(Translation3::from(wide3(&(centre - origin))), r)
    };
    let around = |radius: Real| ((2.0 * PI * radius / h).ceil() as u32).max(16);
    let mesh = |(vertices, triangles): (Vec<Point3<f64>>, Vec<[u32; 3]>), place: Isometry3<f64>| {
        let placed = vertices.iter().map(|p| place * p).collect();
        (rp3::SharedShape::trimesh(placed, triangles).expect("a closed surface"), Isometry3::identity())
    };
    let inside = wall.side == Side::Inside;
    match &wall.solid {
        // The material is inside the half-space; bodies stay out of the rest.
        Solid::HalfSpace { point, normal } => (
            rp3::SharedShape::halfspace(nalgebra::Unit::new_normalize(-wide3(normal))),
            at(point, UnitQuaternion::identity()),
        ),
        Solid::Box { centre, half, axes } => {
            let cuboid = rapier3d_f64::parry::shape::Cuboid::new(wide3(half));
            if inside {
                mesh(cuboid.to_trimesh(), at(centre, rotation(axes)))
            } else {
                (rp3::SharedShape::new(cuboid), at(centre, rotation(axes)))
            }
        }
        Solid::Sphere { centre, radius } => {
            let ball = rapier3d_f64::parry::shape::Ball::new(*radius as f64);
            if inside {
                let n = around(*radius);
                mesh(ball.to_trimesh(n / 2, n), at(centre, UnitQuaternion::identity()))
            } else {
                (rp3::SharedShape::new(ball), at(centre, UnitQuaternion::identity()))
            }
        }
        Solid::Cylinder { centre, axis, radius, half_length } => {
            // parry's cylinder runs along its y axis.
            let r = UnitQuaternion::rotation_between(&Vector3::y(), &wide3(axis))
                .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
            let cylinder = rapier3d_f64::parry::shape::Cylinder::new(*half_length as f64, *radius as f64);
            if inside {
                mesh(cylinder.to_trimesh(around(*radius)), at(centre, r))
            } else {
                (rp3::SharedShape::new(cylinder), at(centre, r))
            }
        }
        Solid::Mesh(m) | Solid::Shell { mesh: m, .. } => {
            // A thin wall's triangles are its mid-surface; its half thickness is the contact skin.
            let (vertices, triangles) = m.triangles();
            let shift = -wide3(origin);
            let points = vertices.iter().map(|v| Point3::from(v + shift)).collect();
            (rp3::SharedShape::trimesh(points, triangles.to_vec()).expect("a closed mesh"), Isometry3::identity())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ear clipping cuts a simple counter-clockwise polygon into n − 2 triangles, all counter-clockwise,
    /// whose areas sum to the polygon's: an L, and the water wheel's 30 corners (six paddles on a hub,
    /// `scenes/rigid/water_wheel.toml`), whose gaps between paddles a convex hull would fill.
    #[test]
    fn ear_clipping_covers_concave_polygons_exactly() {
        let wheel: Vec<Point2<f64>> = (0..6)
            .flat_map(|k| {
                let a = std::f64::consts::PI / 3.0 * k as f64;
                let (u, v) = (Vector2::new(a.cos(), a.sin()), Vector2::new(-a.sin(), a.cos()));
                let hub = (0.06f64 * 0.06 - 0.018 * 0.018).sqrt();
                let mid = a + std::f64::consts::PI / 6.0;
                [
                    u * hub - v * 0.018,
                    u * 0.17 - v * 0.018,
                    u * 0.17 + v * 0.018,
                    u * hub + v * 0.018,
                    Vector2::new(mid.cos(), mid.sin()) * 0.06,
                ]
            })
            .map(Point2::from)
            .collect();
        let l =
            [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0)].map(|(x, y)| Point2::new(x, y));
        for polygon in [l.to_vec(), wheel] {
            let n = polygon.len();
            let area = 0.5 * (0..n).map(|i| polygon[i].coords.perp(&polygon[(i + 1) % n].coords)).sum::<f64>();
            let triangles = ear_clip(&polygon);
            assert_eq!(triangles.len(), n - 2);
            let twice: Vec<f64> = triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| polygon[i as usize]);
                    (b - a).perp(&(c - a))
                })
                .collect();
            assert!(twice.iter().all(|&t| t > 0.0), "every triangle counter-clockwise");
            assert!((0.5 * twice.iter().sum::<f64>() - area).abs() < 1e-12 * area);
        }
    }
}
