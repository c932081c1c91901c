#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// Index loops mirror the matrix algebra they implement (K_ij, G_ib).
#![allow(clippy::needless_range_loop)]

pub mod discretize;
pub mod error;
pub mod filter;
pub mod grid;
pub mod input;
pub mod network;
pub mod observer;
pub mod omnimagnet;
pub mod protect;
pub mod scalar;
pub mod sensors;
pub mod solenoid;

/// The linear algebra crate this one is built on, re-exported so that a
/// user needs no `nalgebra` dependency of their own (and no matching
/// version or features: a plain `nalgebra` dependency turns on `std` and
/// breaks thumb builds). Write `coil_thermal::nalgebra::SVector`.
pub use nalgebra;

pub use error::BuildError;
pub use grid::{CoilGrid, GridConfig, GridParams, GridState, Stencil};
pub use input::{InputFlags, InputLimits};
pub use network::{ExplicitStepper, Network, NetworkState, Resistance};
pub use network::{MotorBuilder, MotorDatasheet};
pub use scalar::{Scalar, Q32};
pub use sensors::{Reading, SensorFault, SensorResult};
pub use solenoid::SolenoidParams;
