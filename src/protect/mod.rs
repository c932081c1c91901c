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
//! * [`limiter`]: per-coil current limits that taper towards the alarm limit,
//!   and weights that favour cooler coils.
//! * [`margin`]: the protective upper bound the limiter, the alarm and the
//!   time to limit act on (the estimate plus `k sigma` of a filter and a
//!   model-uncertainty margin), so that protection errs hot when the model
//!   is wrong.
//!
//! A tick of a protected loop, after the model's update:
//!
//! ```
//! use coil_thermal::protect::{alarm::AlarmBuilder, derating::*, events::EventQueue};
//! use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
//!
//! let rule = DeratingRule::hppa();
//! let alarm = AlarmBuilder::new(&rule, [HPPA_CRITICAL_C; 4]).build::<f32>()?;
//! let limiter = LimiterConfig::<f32, _>::new([3.0; 4], 10.0, 0.0)?;
//! let mut state = coil_thermal::protect::alarm::AlarmState::new(&alarm);
//! let mut events = EventQueue::<32>::new();
//! let mut limits = [CoilLimit::default(); 4];
//!
//! let (temps_c, ambient_c) = ([40.0, 58.0, 66.0, 30.0], 20.0);
//! let status = state.tick(&alarm, &temps_c, ambient_c, &[None; 4], &mut events);
//! limiter.apply(&temps_c, &alarm.alarm_limits_c(state.ambient_c()), ambient_c, &mut limits);
//! assert!(!status.shutdown); // debounced: one hot tick is not enough
//! assert_eq!(limits[2].current_a, 0.0); // but the current is cut at once
//! assert!(limits[3].weight > limits[0].weight);
//! # Ok::<(), coil_thermal::BuildError>(())
//! ```
//!
//! Model-dependent protection needs the network the temperatures came from:
//!
//! * [`predict`]: every element's time to its alarm limit at the present
//!   currents (never later than the truth), sliced to a few microseconds per
//!   tick, for the predictive alarm.
//! * [`safe_current`]: the largest common scale on the currents, or the
//!   largest current of one coil, that keeps every element below its limit
//!   over a horizon (seconds, for ever, or at a duty cycle).
//! * [`runaway`]: per coil, the current above which no steady state exists,
//!   and the one above which the steady hot spot passes its limit.
//! * [`resistance_sensor`]: the winding's mean temperature from its voltage
//!   and current, as a virtual sensor with its own variance, and a drift
//!   check for a coil that heats more than modelled.
//! * [`study`]: the Omnimagnet paper's maximum safe time and current for
//!   each combination of powered coils, with `R(T)` exact.

pub mod alarm;
pub mod derating;
pub mod events;
pub mod limiter;
pub mod margin;
mod modal;
pub mod predict;
pub mod resistance_sensor;
pub mod runaway;
pub mod safe_current;
pub mod study;
