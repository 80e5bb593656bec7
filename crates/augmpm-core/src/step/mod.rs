//! The stages of a step and their order: [`schedule`] (the particles binned by block, the
//! colouring that lets P2G scatter without atomics) and [`transfer`] (density, P2G, grid update,
//! G2P: functions over slices), with [`packing`], the particles' packing on the grid that the `packing` fluids
//! relax their J toward, [`rows_sse`], 3D G2P's row sums in SSE2 registers, and [`tile`], 3D
//! P2G's scatter into a tile of the grid per block.

pub mod packing;
pub mod rows_sse;
pub mod schedule;
pub mod tile;
pub mod transfer;
