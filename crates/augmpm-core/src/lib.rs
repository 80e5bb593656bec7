//! augmpm-core: an MLS-MPM engine whose walls are right.
//!
//! Layers, bottom up (each module imports only from those below it): [`math`]
//! (dimension-generic types) and [`parallel`] (thread thresholds, disjoint
//! writes); [`kernel`] (B-spline weights, MLS shape functions), [`grid`],
//! [`particles`] (the per-particle field table), [`material`] (constitutive
//! models) and [`wall`] (wall conditions, boundary points); [`mesh`] (closed
//! triangle meshes), [`geometry`] and [`geometry3`] (the walls' shapes); [`contact`] (what rigid bodies meet besides the material, through rapier); [`treatment`] (the wall treatments behind one trait: naive,
//! augmented); [`step`] (the particles' schedule, the stages of a step);
//! [`simulation`] (model, state, the step in order); [`schema`] and [`scene`]
//! (scene parameters, declared once, and building a simulation from a scene).

// Index loops over the dimension `D` read like the formulas they implement.
#![allow(clippy::needless_range_loop)]

pub mod contact;
pub mod geometry;
pub mod geometry3;
pub mod grid;
pub mod kernel;
pub mod material;
pub mod math;
pub mod mesh;
pub mod motion;
pub mod parallel;
pub mod particles;
pub mod rigid;
pub mod scene;
pub mod scene3;
pub mod schema;
pub mod simulation;
pub mod step;
pub mod treatment;
pub mod wall;

pub use scene::{MemoryEstimate, Scene, SceneError};
pub use simulation::{MemoryUse, Metrics, Model, Simulation, StageTimes, State, StepError};
pub use treatment::{Boundary, Method, WallTreatment};
pub use wall::WallCondition;
