#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
#![deny(missing_docs)]

pub mod error;
pub mod filter;
pub mod scalar;

pub use error::BuildError;
pub use scalar::{Scalar, Q32};
