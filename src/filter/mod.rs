//! Discrete Kalman filter for the thermal models (placeholder docs).

mod gate;
mod kalman;
pub mod observability;
mod riccati;

pub use gate::{GateCounters, GatePolicy, SensorVerdict, UpdateReport, CHI2_1DOF_999};
pub use kalman::{predict, predict_mean, update, InputStatus, KalmanConfig, KalmanState};
pub use observability::{observability, Observability};
pub use riccati::{k_step_model, update_steady, SteadyEstimate, SteadyStateGain};

#[cfg(test)]
mod testutil;
