//! Host-side (std) tooling for `coil-thermal`: independent reference solvers,
//! trace generators and replay helpers used by the tests and benchmarks.

pub mod grid_reference;
pub mod traces;
