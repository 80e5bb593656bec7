//! augmpm-core: an MLS-MPM engine whose walls are right.
//!
//! Layers, bottom up: [`math`] (dimension-generic types), [`kernel`]
//! (B-spline weights, MLS shape functions), [`grid`], [`particles`],
//! [`material`] (constitutive models), [`geometry`] and [`boundary`] (walls),
//! [`augmented`] and [`wall_fit`] (the augmented grid and its wall fit),
//! [`transfer`] (the stages of a step), [`solver`] (model, state, step) and
//! [`scene`] (building a simulation from a scene description).

// Index loops over the dimension `D` read like the formulas they implement.
#![allow(clippy::needless_range_loop)]

pub mod augmented;
pub mod boundary;
pub mod geometry;
pub mod grid;
pub mod kernel;
pub mod material;
pub mod math;
pub mod particles;
pub mod scene;
pub mod schedule;
pub mod solver;
pub mod transfer;
pub mod wall_fit;

pub use boundary::{Method, WallCondition};
pub use scene::{MemoryEstimate, Scene, SceneError};
pub use solver::{MemoryUse, Metrics, Model, Simulation, StageTimes, State, StepError};
