//! A `no_std`, allocation-free thermal observer for electromagnetic
//! actuators, linked into a motion controller's 1 ms control loop: every tick
//! it takes the coil currents \[A\] (and, when they arrive, thermocouple
//! readings and the ambient \[degC\]) and keeps an estimate of every part of
//! the device, with derated alarms, a latched shutdown, each element's time to
//! its limit \[s\] and a current limit per coil \[A\].
//!
//! # A tour
//!
//! * Describe a device as a [`Network`] of heat capacities \[J/K\],
//!   conductances \[W/K\], boundaries and `R(T)` Joule sources, or let the host
//!   tool read a TOML model file and generate the observer's tables
//!   (`coil-thermal codegen`).
//! * Run it behind the tick API: [`observer::NetworkObserver`] for any network,
//!   [`observer::GridObserver`] for the HPPA coil grid, [`observer::OmniObserver`]
//!   for the Omnimagnet ([`docs::observer`]).
//! * Protection ([`protect`]): derated alarms, a latched shutdown, time to limit
//!   and a current limiter acting on an upper bound of the estimate
//!   ([`docs::prediction_and_margin`], [`docs::protection`]).
//! * Every scalar type through one [`Scalar`] trait: `f32`, `f64`, or [`Q32`]
//!   fixed point for cores without an FPU ([`docs::firmware`], [`docs::cost`]);
//!   on such a core, `f32` routines written for Thumb-1 ([`soft_float`],
//!   opted in with [`soft_float_routines!`]).
//!
//! The lowest layer in a few lines: a coil on a housing, stepped at 1 ms in
//! `f32` and held against the exact steady state.
//!
//! ```rust
//! use coil_thermal::{ExplicitStepper, InputLimits, Network, NetworkState, Resistance};
//!
//! // A coil (node 0) on a housing (node 1) cooled to the ambient (boundary 0).
//! let network: Network<2, 1, 1> = Network::new([68.7, 400.0])? // J/K
//!     .connect(0, 1, 0.35)? // W/K
//!     .connect_boundary(1, 0, 1.5)?
//!     .joule_source(0, 0, Resistance::HPPA_COIL)?; // R(T) = 0.026 T + 5.166 ohm
//!
//! // The 1 ms hot-path stepper, in f32 (refused if 1 ms were unstable).
//! let stepper = ExplicitStepper::<f32, 2, 1, 1>::new(&network, 1e-3, InputLimits::default())?;
//! let mut state = NetworkState::<f32, 2, 1, 1>::uniform(20.0);
//! for _ in 0..10_000 {
//!     // currents [A], boundary temperatures [degC]; NaN inputs are held and flagged
//!     let flags = stepper.step(&mut state, &[1.0], &[20.0]);
//!     assert!(flags.is_clean());
//! }
//! assert!(state.temps_c[0] > 20.0);
//!
//! // The exact steady state, with the resistance rising as the coil heats.
//! let steady = network.steady_state(&[1.0], &[20.0])?;
//! assert!(steady[0] > state.temps_c[0] as f64);
//! # Ok::<(), coil_thermal::BuildError>(())
//! ```
//!
//! The repository's README is the front page (model your own device, wire it
//! into a 1 ms loop, the host tool in five commands); the guides below are its
//! longer chapters, and the model file format is `host-tests/MODEL_FORMAT.md`
//! in the repository.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// Index loops mirror the matrix algebra they implement (K_ij, G_ib).
#![allow(clippy::needless_range_loop)]
// Runtime-sized networks on a host (`RunTimeStepper`); never on an MCU.
#[cfg(feature = "alloc")]
extern crate alloc;

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
pub mod sizes;
pub mod soft_float;
pub mod solenoid;

/// The linear algebra crate this one is built on, re-exported so that a
/// user needs no `nalgebra` dependency of their own (and no matching
/// version or features: a plain `nalgebra` dependency turns on `std` and
/// breaks thumb builds). Write `coil_thermal::nalgebra::SVector`.
pub use nalgebra;

/// The guides behind the README, one page per topic; their Rust examples
/// are compiled and run as doctests.
#[cfg(any(doc, doctest))]
pub mod docs {
    /// The models against the papers' measurements.
    #[doc = include_str!("../docs/validation.md")]
    pub mod validation {}
    /// Restart, the latch, input and sensor faults.
    #[doc = include_str!("../docs/protection.md")]
    pub mod protection {}
    /// Time to limit, safe current and the upper bound under model error.
    #[doc = include_str!("../docs/prediction_and_margin.md")]
    pub mod prediction_and_margin {}
    /// Into the controller: the tick API, sharing and warm restarts.
    #[doc = include_str!("../docs/observer.md")]
    pub mod observer {}
    /// The HPPA coil grid.
    #[doc = include_str!("../docs/grid.md")]
    pub mod grid {}
    /// The Omnimagnet model and observer.
    #[doc = include_str!("../docs/omnimagnet.md")]
    pub mod omnimagnet {}
    /// Cost on target (instructions, flash, RAM) and on the host.
    #[doc = include_str!("../docs/cost.md")]
    pub mod cost {}
    /// The QEMU firmware examples and fixed point.
    #[doc = include_str!("../docs/firmware.md")]
    pub mod firmware {}
    /// The host tool `coil-thermal`.
    #[doc = include_str!("../docs/host-tool.md")]
    pub mod host_tool {}
    /// The `--json` output of the host tool's subcommands.
    #[doc = include_str!("../docs/json.md")]
    pub mod json {}
    /// Real data: the HUST motor.
    #[doc = include_str!("../docs/hust.md")]
    pub mod hust {}
}

/// The README's Rust examples, compiled and run as doctests (the README is
/// the repository's front page, written for a reader on the repository).
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

pub use error::BuildError;
pub use grid::{CoilGrid, GridConfig, GridParams, GridState, Stencil};
pub use input::{DriveFlags, InputFlags, InputLimits, VoltageDrive};
pub use network::{Drive, ExplicitStepper, Network, NetworkState, Resistance};
pub use network::{MotorBuilder, MotorDatasheet};
pub use scalar::{Scalar, Q32};
pub use sensors::{Reading, SensorFault, SensorResult};
pub use solenoid::SolenoidParams;
