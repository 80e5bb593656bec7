//! The stages of a step and their order: [`schedule`] (the particles binned by block, the
//! colouring that lets P2G scatter without atomics) and [`transfer`] (density, P2G, grid update,
//! G2P: functions over slices).

pub mod schedule;
pub mod transfer;
