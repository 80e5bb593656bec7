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
//! The contact surfaces:
//! - a body: its drawn solid (a disk, a convex polygon, or the convex pieces of a concave one);
//! - a container polygon and the domain box: closed polylines (hollow: bodies stay inside);
//! - an obstacle polygon: a solid as a body is;
//! - a circle: a disk, or around material a ring of segments at most a cell long;
//! - a stroke: capsules along its centreline.
//!
//! Friction and restitution are the bodies' (`contact_friction`, `restitution`). A wall's own are 0, and
//! each contact takes the larger of its two sides' values.

// `Real` is f64 here, f32 in augmpm-core-f32; rapier works in f64 in either.
#![allow(clippy::useless_conversion, clippy::unnecessary_cast)]

use rapier2d_f64::na::{Isometry2, Point2, Vector2};
use rapier2d_f64::prelude as rp;

use crate::geometry::{Point, Region, Side, WallShape, Walls2};
use crate::math::{Real, PI};
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

/// How a rigid body meets others: friction and restitution of its contacts, and the point, fixed in the
/// scene, that it turns about if it is hinged (m).
#[derive(Clone, Debug, PartialEq)]
pub struct Contact {
    pub friction: Real,
    pub restitution: Real,
    pub hinge: Option<Point>,
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
                if let Some(hinge) = contact.hinge {
                    let joint = rp::RevoluteJointBuilder::new()
                        .local_anchor1(Point2::from(vector(&hinge)))
                        .local_anchor2(Point2::from(vector(&(hinge - body.centre))));
                    joints.insert(ground, handle, joint, true);
                }
                handle
            })
            .collect();
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
                WallPose::planar(
                    t + dt,
                    [x.x as Real - body.centre.x, x.y as Real - body.centre.y],
                    start + turned as Real,
                    [v.x as Real, v.y as Real],
                    moved.angvel() as Real,
                )
            })
            .collect()
    }
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
                let segments: Vec<[u32; 2]> = (0..n as u32).map(|i| [i, (i + 1) % n as u32]).collect();
                rp::SharedShape::convex_decomposition(&points, &segments)
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
