//! Thermal protection on plain arrays of element temperatures `[S; N]`.
//!
//! Nothing here knows which model produced the temperatures: the same code
//! protects the HPPA coil grid, the Omnimagnet filter's estimate or any
//! network, in `f32`, `f64` or fixed point ([`Q32`](crate::scalar::Q32)).
//!
//! * [`derating`]: where the alarm limit sits below a material's critical
//!   temperature (the HPPA report's factors), and the critical temperatures.
//! * [`alarm`]: per-element warning, latched shutdown and predictive alarms,
//!   debounced and with hysteresis; configuration in [`alarm::AlarmConfig`],
//!   state in [`alarm::AlarmState`].
//! * [`events`]: the fixed-capacity queue through which the alarm reports
//!   every change.

pub mod alarm;
pub mod derating;
pub mod events;
