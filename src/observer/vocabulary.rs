//! The words every observer speaks: a timed sensor sample, what became of
//! it, the checks a reading must pass against the physics, what a tick of
//! a filtered observer produces, and the capacity of the alarm event queue.
//! No device owns them (the grid, the Omnimagnet and the network observers,
//! the consistency screen and the protection cycle all use them).

use super::clock::TickSteps;
use crate::error::{check, BuildError};
use crate::input::InputFlags;
use crate::protect::alarm::AlarmStatus;
use crate::protect::limiter::{hold_shutdown, CoilLimit};
use crate::sensors::{SensorFault, SensorResult};
use crate::sizes::Length;
use nalgebra::Const;

/// Capacity of each observer's alarm event queue.
pub const EVENT_CAPACITY: usize = 16;

/// One sensor sample and when it was taken.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimedReading {
    /// The driver's result.
    pub result: SensorResult,
    /// Sample time on the tick's microsecond clock \[us\] (wrapping).
    pub sampled_at_us: u32,
}

impl TimedReading {
    /// The reading \[degC\] if it can be fused at `now_us` \[us\]: not a
    /// fault, not older than `max_age_us` \[us\], finite; otherwise what
    /// to report. Shared by the observers' corrections.
    pub(crate) fn sample_c(&self, now_us: u32, max_age_us: u32) -> Result<f32, SensorStatus> {
        match self.result {
            Err(fault) => Err(SensorStatus::Fault(fault)),
            Ok(r) => {
                let age_us = now_us.wrapping_sub(self.sampled_at_us);
                if age_us > max_age_us {
                    Err(SensorStatus::TooOld { age_us })
                } else if !r.temp_c.is_finite() {
                    Err(SensorStatus::Fault(SensorFault::NotFinite))
                } else {
                    Ok(r.temp_c)
                }
            }
        }
    }
}

#[cfg(test)]
impl TimedReading {
    /// The readings `temps_c` \[degC\] of every sensor, healthy, sampled at
    /// `now_us` \[us\] (the tests' thermocouples).
    pub(crate) fn all_at<const P: usize>(temps_c: [f32; P], now_us: u32) -> [Option<Self>; P] {
        temps_c.map(|temp_c| {
            Some(Self {
                result: Ok(crate::sensors::Reading::new(temp_c)),
                sampled_at_us: now_us,
            })
        })
    }
}

/// What happened to one sensor's sample this tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorStatus {
    /// No reading arrived.
    #[default]
    NoReading,
    /// Fused, with its normalised innovation squared (dimensionless).
    Fused {
        /// `nu^2 / S`.
        nis: f32,
    },
    /// Refused by the innovation gate.
    Rejected {
        /// `nu^2 / S`.
        nis: f32,
    },
    /// The sensor reported a fault; not fused.
    Fault(SensorFault),
    /// Older than `max_reading_age_us`; not fused.
    TooOld {
        /// Its age \[us\].
        age_us: u32,
    },
    /// Colder than the physics allows: below the band of the observer's
    /// unfused shadow model (see the network observer's "Sensors against
    /// the physics"); not fused.
    ColderThanPhysics {
        /// How far below the band's lower edge \[K\].
        below_k: f32,
    },
    /// Silent: no reading (not even a fault) for more than two correction
    /// periods; a dropout (a cable, a driver, a bus).
    Silent {
        /// Since the last reading \[ms\].
        for_ms: u32,
    },
    /// Stuck: the reading has not moved while the shadow model at its node
    /// moved by more than the stuck threshold within the stuck window, or
    /// by more than the threshold plus the band's share of the rise since
    /// the reading last changed; not fused until it moves.
    Stuck {
        /// How far the shadow moved since the reading last changed or
        /// within the window, the larger \[K\].
        model_moved_k: f32,
    },
}

/// The checks every filtered observer (the Omnimagnet's, the network's)
/// holds its sensors to against the unfused shadow model, and the bound on
/// what its sensors leave uncertain (see the network observer's "Sensors
/// against the physics"). One set of settings, read by both builders.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorChecks {
    /// Fixed part of the band a reading must keep to below the unfused
    /// shadow model \[K\] (`f64::INFINITY` turns the test off). Default 3.
    pub consistency_offset_k: f64,
    /// Share of the shadow model's rise above the ambient in that band
    /// (dimensionless, finite, `>= 0`): the model's uncertainty. Default
    /// 0.25.
    pub consistency_fraction: f64,
    /// How far the shadow model at a sensor's node must move while its
    /// reading stays the same for the sensor to count as stuck \[K\]
    /// (`f64::INFINITY` turns the test off). Default 1.0.
    pub stuck_threshold_k: f64,
    /// How far a reading may move and still count as unchanged for the
    /// stuck test \[K\] (finite, `>= 0`; 0: to the bit). Default 0. Set
    /// it to about one converter code plus twice the reading noise (0.3 K
    /// for a MAX31855 with 0.1 K of noise) so that a detached
    /// thermocouple jittering around the room's temperature is told
    /// stuck (see docs/protection.md, "Thermocouples as they read").
    pub stuck_tolerance_k: f64,
    /// Largest steady-state standard deviation \[K\] an element with a
    /// limit may have: a sensor set that leaves one less certain is refused
    /// at build ([`BuildError::Unobservable`]; one thermocouple on the
    /// Omnimagnet's solenoid 1 alone leaves solenoids 2 and 3 at 22-24 K).
    /// Default 5 (`f64::INFINITY`: no check).
    pub max_element_sigma_k: f64,
}

impl SensorChecks {
    /// The defaults (see each field).
    pub const DEFAULT: Self = Self {
        consistency_offset_k: 3.0,
        consistency_fraction: 0.25,
        stuck_threshold_k: 1.0,
        stuck_tolerance_k: 0.0,
        max_element_sigma_k: 5.0,
    };

    /// Refuses a setting out of its range, naming it.
    pub(crate) fn validate(&self) -> Result<(), BuildError> {
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        check(
            !self.consistency_offset_k.is_nan() && self.consistency_offset_k >= 0.0,
            "consistency_offset_k",
        )?;
        check(nonneg(self.consistency_fraction), "consistency_fraction")?;
        check(
            !self.stuck_threshold_k.is_nan() && self.stuck_threshold_k >= 0.0,
            "stuck_threshold_k",
        )?;
        check(nonneg(self.stuck_tolerance_k), "stuck_tolerance_k")?;
        check(
            !self.max_element_sigma_k.is_nan() && self.max_element_sigma_k > 0.0,
            "max_element_sigma_k",
        )
    }

    /// Refuses an element with a limit (`limited`) whose steady standard
    /// deviation `sigma_k` \[K\] exceeds [`Self::max_element_sigma_k`].
    pub(crate) fn observable(
        &self,
        node: usize,
        limited: bool,
        sigma_k: f64,
    ) -> Result<(), BuildError> {
        if limited && sigma_k > self.max_element_sigma_k {
            Err(BuildError::Unobservable {
                node,
                sigma_k: sigma_k as f32,
            })
        } else {
            Ok(())
        }
    }
}

impl Default for SensorChecks {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What one tick of a filtered observer produced: the Omnimagnet's
/// ([`OmniOutputs`](super::OmniOutputs)) and the network's
/// ([`NetworkOutputs`](super::NetworkOutputs)), for `N` nodes, `M`
/// currents, `A` elements with a time to limit and `P` sensors, each a
/// dimension (`Const<N>` on an MCU, where the outputs are `Copy`, for
/// [`Shared`](super::Shared); [`ConstOutputs`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FilteredOutputs<N: Length, M: Length, A: Length, P: Length> {
    /// Node temperature estimates \[degC\]: the filter's mean.
    pub temps_c: N::Array<f32>,
    /// Each node's protective upper bound \[degC\], what the limiter and
    /// the alarm act on: the estimate plus `k_sigma` steady-state standard
    /// deviations and, on the unmeasured nodes, the model-uncertainty
    /// margin (see [`crate::protect::margin`]). Taken with the protection
    /// cycle (by its alarm and limiter stages), so it lags `temps_c` by up
    /// to a cycle, as the limits do.
    pub upper_c: N::Array<f32>,
    /// Current limit per input.
    pub limits: M::Array<CoilLimit<f32>>,
    /// Time until each limited element's upper bound reaches its alarm
    /// limit \[s\] (`None`: never, or no limit).
    pub time_to_limit_s: A::Array<Option<f32>>,
    /// The alarm summary.
    pub alarm: AlarmStatus,
    /// What happened to each sensor's reading.
    pub sensors: P::Array<SensorStatus>,
    /// A correction ran this tick.
    pub corrected: bool,
    /// Input rules that fired this tick.
    pub flags: InputFlags,
    /// Model steps taken this tick.
    pub steps: u32,
    /// Time dropped by the catch-up limit \[us\].
    pub dropped_us: u32,
    /// Ticks since the state was made.
    pub tick: u32,
}

/// The outputs of an MCU's observer: every size known when the firmware is
/// compiled.
pub type ConstOutputs<const N: usize, const M: usize, const A: usize, const P: usize> =
    FilteredOutputs<Const<N>, Const<M>, Const<A>, Const<P>>;

/// Copied where every vector is (arrays: an MCU's).
impl<N: Length, M: Length, A: Length, P: Length> Copy for FilteredOutputs<N, M, A, P>
where
    N::Array<f32>: Copy,
    M::Array<CoilLimit<f32>>: Copy,
    A::Array<Option<f32>>: Copy,
    P::Array<SensorStatus>: Copy,
{
}

#[cfg(feature = "defmt")]
impl<const N: usize, const M: usize, const A: usize, const P: usize> defmt::Format
    for ConstOutputs<N, M, A, P>
{
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "FilteredOutputs {{ temps_c: {}, upper_c: {}, limits: {}, time_to_limit_s: {}, \
             alarm: {}, sensors: {}, corrected: {}, flags: {}, steps: {}, dropped_us: {}, \
             tick: {} }}",
            self.temps_c,
            self.upper_c,
            self.limits,
            self.time_to_limit_s,
            self.alarm,
            self.sensors,
            self.corrected,
            self.flags,
            self.steps,
            self.dropped_us,
            self.tick
        )
    }
}

impl<N: Length, M: Length, A: Length, P: Length> FilteredOutputs<N, M, A, P> {
    /// Ends a tick: its input flags, its model steps and dropped time
    /// (`steps`), every current limit held at zero while the shutdown is
    /// latched (until the deliberate clear), and the tick counted.
    #[inline(always)]
    pub(crate) fn finish_tick(&mut self, flags: InputFlags, steps: &TickSteps) {
        self.flags = flags;
        self.steps = steps.steps;
        self.dropped_us = steps.dropped_us;
        if self.alarm.shutdown {
            hold_shutdown(self.limits.as_mut());
        }
        self.tick = self.tick.wrapping_add(1);
    }
}
