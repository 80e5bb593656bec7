//! augmpm-core: an MLS-MPM engine whose walls are right.
//!
//! Layers, bottom up (each module imports only from those below it): [`math`]
//! (dimension-generic types) and [`parallel`] (thread thresholds, disjoint
//! writes); [`kernel`] (B-spline weights, MLS shape functions), [`grid`],
//! [`particles`], [`material`] (constitutive models) and [`wall`] (wall
//! conditions, boundary points); [`geometry`] (the walls' shapes); the wall
//! treatments [`boundary`] (naive) and [`augmented`], with [`wall_fit`] (its
//! fit at walls) and [`schedule`] (the particles' order); [`transfer`] (the
//! stages of a step); [`solver`] (model, state, step); [`scene`] (building a
//! simulation from a scene description).

// Index loops over the dimension `D` read like the formulas they implement.
#![allow(clippy::needless_range_loop)]

pub mod augmented;
pub mod boundary;
pub mod geometry;
pub mod grid;
pub mod kernel;
pub mod material;
pub mod math;
pub mod parallel;
pub mod particles;
pub mod scene;
pub mod schedule;
pub mod schema;
pub mod solver;
pub mod transfer;
pub mod wall;
pub mod wall_fit;

pub use boundary::Method;
pub use scene::{MemoryEstimate, Scene, SceneError};
pub use solver::{MemoryUse, Metrics, Model, Simulation, StageTimes, State, StepError};
pub use wall::WallCondition;
