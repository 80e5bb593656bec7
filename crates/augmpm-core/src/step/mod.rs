//! The stages of a step and their order: [`schedule`] (the particles binned by block, the
//! colouring that lets P2G scatter without atomics) and [`transfer`] (density, P2G, grid update,
//! G2P: functions over slices), with [`rows_sse`], 3D G2P's row sums in SSE2 registers.

pub mod rows_sse;
pub mod schedule;
pub mod transfer;
