#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod error;
pub mod scalar;
pub mod sensors;

pub use error::BuildError;
pub use scalar::{Scalar, Q32};
pub use sensors::{Reading, SensorFault, SensorResult};
