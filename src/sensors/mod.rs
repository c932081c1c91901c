//! Thermocouple drivers, resistive sensors on an ADC, and the sensor
//! vocabulary the filter and observer use.
//!
//! The thermal maths of this crate never names a HAL trait. Hardware lives
//! here, at the edge: the drivers take an `embedded_hal::spi::SpiDevice`
//! (embedded-hal 1.0), and everything they hand inwards is a plain
//! [`SensorResult`]: either a [`Reading`] in degC or a [`SensorFault`].
//!
//! | chip | module | interface | sensor data (resolution) | cold junction |
//! |---|---|---|---|---|
//! | MAX31855 | [`max31855`] | one 32-bit read-only frame | 14 bit, 0.25 degC | 12 bit, 0.0625 degC |
//! | MAX31856 | [`max31856`] | register file | 19 bit, 0.0078125 degC | 14 bit, 0.015625 degC |
//! | MAX31865 | [`max31865`] | register file | RTD ratio, 15 bit (PT100 on 430 ohm: 0.034 K at 0 degC) | none (RTD) |
//!
//! The modules offer a pure `decode` that needs no bus (for tests, and for
//! users who move the bytes by DMA) and a driver that does the SPI traffic.
//!
//! Resistive sensors read by the MCU's own ADC through a divider need no
//! driver: [`resistive`] converts a count (the user's ADC, any width 1 ..= 24
//! bit) into a [`SensorResult`]. Its arithmetic error against the reference
//! equation in f64, over every 12-bit count from -40 to 150 degC; the
//! quantisation of one count is larger (0.02 .. 0.9 K at 12 bits, see
//! [`resistive`]). The sensor's own tolerance (an NTC's R25 and beta class,
//! an RTD's class A/B, a KTY's R25/R100 selection) comes on top of every
//! row:
//!
//! | kind | module | reference equation | conversion error |
//! |---|---|---|---|
//! | NTC, beta | [`resistive`] | 1/T = 1/T0 + ln(R/R0)/beta | 3.7e-5 K |
//! | NTC, Steinhart-Hart | [`resistive`] | 1/T = a + b ln R + c (ln R)^3 | 6.2e-5 K |
//! | NTC, R-T table | [`resistive`] | piecewise beta between points | 4.6e-5 K (plus the table's own interpolation error: 8.7e-3 K for 5 K steps) |
//! | PT100 / PT1000 | [`resistive`] | Callendar-Van Dusen, IEC 60751 | 4.1e-5 K (1.5e-4 K over -200 .. 850 degC) |
//! | KTY83-110/120/150, KTY84-130/150 (silicon PTC), any PTC R-T table | [`resistive`] | the datasheet's R-T table, linear between rows | 1.8e-5 K (plus the table's own interpolation error: 0.12 K at its off-grid rows) |
//! | winding resistance (a source's own `V/I`, DC injection) | [`crate::observer::network::resistance`] | T = (R - r0) / s, the winding's measured `R(T)` | the resistance's relative noise times `R(T) / s`: 2.5 K at 20 degC, 3.3 K at 100 degC per reading for copper at 1 %; through the filter, 0.69 K worst (RMSE 0.19 K) on `drive-3node` over an hour at one reading a second |
//!
//! A resistive sensor has no cold junction: its [`Reading::cold_junction_c`]
//! is `None` ([`Reading::new`]).
//!
//! # How a fault reaches the filter
//!
//! A reading is trusted only if every check along the way passed:
//!
//! 1. The chip's own fault flags (open thermocouple, shorts, range) and the
//!    frame's format checks become [`SensorFault`]s in `decode`; a bus error
//!    becomes [`Error::Bus`] in the driver and [`SensorFault::Bus`] once it is
//!    reduced to a [`SensorResult`] (via `From<Error<E>> for SensorFault`).
//! 2. [`check`] then applies the software plausibility checks of a
//!    [`PlausibilityCheck`]: finite, inside the physical range, no impossible
//!    rate of change, not stuck while the estimate moves.
//! 3. The Kalman filter gates what is left by its innovation and reports
//!    [`SensorFault::Rejected`] for what it refuses.
//!
//! A faulted sample is *no measurement*: the filter skips its update step for
//! that sensor and keeps predicting from the model, so the estimate degrades
//! gracefully (its covariance grows) instead of being dragged by a broken
//! wire. The fault itself is never swallowed: it is returned to the caller
//! (and through the observer to thermal protection), because a thermocouple
//! that stays faulted means the coil is running on the model alone.

pub mod max31855;
pub mod max31856;
pub mod max31865;
pub mod resistive;

use core::fmt;

use crate::error::BuildError;

/// One sensor sample: a temperature, and for a thermocouple the
/// temperature of its cold junction.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reading {
    /// The sensed temperature \[degC\]: a thermocouple's hot junction
    /// (cold-junction compensated), a thermistor's or an RTD's element, a
    /// winding's mean from its resistance.
    pub temp_c: f32,
    /// A thermocouple's cold-junction temperature \[degC\]: the
    /// converter's die, where the thermocouple wires end (the MAX31855 and
    /// MAX31856 drivers fill it). `None` for a sensor without one.
    pub cold_junction_c: Option<f32>,
}

impl Reading {
    /// A reading of `temp_c` \[degC\] from a sensor without a cold
    /// junction (a thermistor, an RTD, a winding's resistance, a
    /// simulation).
    pub const fn new(temp_c: f32) -> Self {
        Self {
            temp_c,
            cold_junction_c: None,
        }
    }
}

/// What one sensor sample produced: a reading, or why there is none.
pub type SensorResult = Result<Reading, SensorFault>;

/// Why a sensor sample is not a usable measurement.
///
/// The first three come from the converter's own fault detection; the others
/// from the drivers' format checks, the plausibility checker ([`check`]) or
/// the filter. Whatever the cause, the filter treats the sample as no
/// measurement (see the [module documentation](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SensorFault {
    /// The sensor is open: a broken or unplugged wire (a thermocouple
    /// converter's flag; a resistive divider's rail count).
    OpenCircuit,
    /// The sensor is shorted to ground (converter flag or rail count).
    ShortToGnd,
    /// The sensor is shorted to the supply, or (MAX31856) its inputs are
    /// outside the supply rails (converter flag or rail count).
    ShortToVcc,
    /// The temperature is outside the sensor's physical or configured range:
    /// reported by the MAX31856's range and threshold flags, and by
    /// [`check`].
    OutOfRange,
    /// The reading (or its time step) is NaN or infinite.
    NotFinite,
    /// The reading has not changed for too long while the estimate moved: a
    /// frozen converter, a stale DMA buffer, a bus that reads constant bits.
    Stuck,
    /// The reading changed faster than the coil physically can.
    Jump,
    /// The filter's innovation gate refused the reading: it disagrees with the
    /// model by more than the gate allows.
    Rejected,
    /// The SPI transfer failed. The bus error itself is in the driver's
    /// [`Error::Bus`].
    Bus,
    /// The converter's answer breaks its own format (reserved bits set, a
    /// fault flag without a cause, a configuration that does not read back):
    /// a wiring, power or bus-integrity problem rather than a thermocouple
    /// fault.
    InvalidData,
}

impl fmt::Display for SensorFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::OpenCircuit => "sensor open circuit",
            Self::ShortToGnd => "sensor shorted to ground",
            Self::ShortToVcc => "sensor shorted to supply",
            Self::OutOfRange => "temperature outside the sensor's range",
            Self::NotFinite => "reading is not finite",
            Self::Stuck => "reading stuck while the estimate moves",
            Self::Jump => "reading changed faster than physically possible",
            Self::Rejected => "reading rejected by the filter's innovation gate",
            Self::Bus => "SPI bus error",
            Self::InvalidData => "converter data violates its format",
        })
    }
}

impl core::error::Error for SensorFault {}

/// A driver error: either the bus failed, or the bus worked and the sensor
/// reported (or was found to have) a fault.
///
/// `E` is the SPI device's error type. Reduce to a [`SensorFault`] with
/// `SensorFault::from(error)` (or [`Error::fault`]) where the bus error's
/// detail is not needed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// The SPI transfer failed.
    Bus(E),
    /// The transfer worked; the sample is not a measurement.
    Sensor(SensorFault),
}

impl<E> Error<E> {
    /// The sensor-level view of this error: [`SensorFault::Bus`] for a bus
    /// error, the fault itself otherwise.
    pub fn fault(&self) -> SensorFault {
        match self {
            Self::Bus(_) => SensorFault::Bus,
            Self::Sensor(fault) => *fault,
        }
    }
}

impl<E> From<Error<E>> for SensorFault {
    fn from(error: Error<E>) -> Self {
        error.fault()
    }
}

impl<E> From<SensorFault> for Error<E> {
    fn from(fault: SensorFault) -> Self {
        Self::Sensor(fault)
    }
}

impl<E: fmt::Debug> fmt::Display for Error<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bus(error) => write!(f, "SPI bus error: {error:?}"),
            Self::Sensor(fault) => fmt::Display::fmt(fault, f),
        }
    }
}

impl<E: fmt::Debug> core::error::Error for Error<E> {}

/// Limits for the software plausibility checks of one sensor (see [`check`]).
///
/// Built with [`PlausibilityCheck::new`] and the `with_*` methods, which
/// validate every limit, so [`check`] never meets a NaN limit that would make
/// a comparison silently pass. All builders are `const fn`, so a limit set can
/// be a `const` or `static`.
///
/// ```
/// use coil_thermal::sensors::PlausibilityCheck;
///
/// // Class H winding: -40 .. 220 degC, at most 50 K/s, and the reading may
/// // not stay within 0.5 K for 3000 samples while the estimate moves > 0.5 K.
/// let limits = PlausibilityCheck::new(-40.0, 220.0)
///     .and_then(|c| c.with_max_rate(50.0))
///     .and_then(|c| c.with_stuck_detection(3000, 0.5));
/// assert!(limits.is_ok());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlausibilityCheck {
    min_c: f32,
    max_c: f32,
    max_rate_k_per_s: Option<f32>,
    stuck_samples: u32,
    stuck_tolerance_k: f32,
}

impl PlausibilityCheck {
    /// Range check only: readings outside `min_c ..= max_c` \[degC\] are
    /// [`SensorFault::OutOfRange`]; rate and stuck checks are off.
    ///
    /// Set the range to what the sensor can physically see in this machine
    /// (the winding's insulation class, the ambient minimum), not to the
    /// converter's full scale: a reading beyond it is a broken sensor.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if a limit is not finite or
    /// `min_c >= max_c`.
    pub const fn new(min_c: f32, max_c: f32) -> Result<Self, BuildError> {
        if !min_c.is_finite() {
            return Err(BuildError::InvalidParameter { name: "min_c" });
        }
        if !max_c.is_finite() || max_c <= min_c {
            return Err(BuildError::InvalidParameter { name: "max_c" });
        }
        Ok(Self {
            min_c,
            max_c,
            max_rate_k_per_s: None,
            stuck_samples: 0,
            stuck_tolerance_k: 0.0,
        })
    }

    /// Also reject readings that moved faster than `max_rate_k_per_s` \[K/s\]
    /// since the last accepted reading ([`SensorFault::Jump`]).
    ///
    /// Use the fastest heating the coil can do (peak power over the heat
    /// capacity of what the thermocouple touches) with a margin for noise.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if the rate is not finite or not
    /// strictly positive.
    pub const fn with_max_rate(self, max_rate_k_per_s: f32) -> Result<Self, BuildError> {
        if !max_rate_k_per_s.is_finite() || max_rate_k_per_s <= 0.0 {
            return Err(BuildError::InvalidParameter {
                name: "max_rate_k_per_s",
            });
        }
        Ok(Self {
            max_rate_k_per_s: Some(max_rate_k_per_s),
            ..self
        })
    }

    /// Also report [`SensorFault::Stuck`] when `samples` consecutive readings
    /// stayed within `tolerance_k` \[K\] of the first of them while the
    /// estimate moved by more than `tolerance_k` over the same samples.
    ///
    /// `samples` counts calls to [`check`], not conversions: a MAX31855 read
    /// every 1 ms repeats each conversion for about 100 samples, so `samples`
    /// must span many conversion periods. `samples == 0` turns the check off.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if `tolerance_k` is not finite or is
    /// negative.
    pub const fn with_stuck_detection(
        self,
        samples: u32,
        tolerance_k: f32,
    ) -> Result<Self, BuildError> {
        if !tolerance_k.is_finite() || tolerance_k < 0.0 {
            return Err(BuildError::InvalidParameter {
                name: "tolerance_k",
            });
        }
        Ok(Self {
            stuck_samples: samples,
            stuck_tolerance_k: tolerance_k,
            ..self
        })
    }

    /// Lowest plausible reading \[degC\].
    pub const fn min_c(&self) -> f32 {
        self.min_c
    }

    /// Highest plausible reading \[degC\].
    pub const fn max_c(&self) -> f32 {
        self.max_c
    }

    /// Fastest plausible change \[K/s\], `None` if the rate check is off.
    pub const fn max_rate_k_per_s(&self) -> Option<f32> {
        self.max_rate_k_per_s
    }

    /// Samples before a motionless reading is [`SensorFault::Stuck`], 0 if
    /// the stuck check is off.
    pub const fn stuck_samples(&self) -> u32 {
        self.stuck_samples
    }

    /// Band \[K\] within which readings count as identical, and the estimate
    /// movement \[K\] that makes identical readings suspicious.
    pub const fn stuck_tolerance_k(&self) -> f32 {
        self.stuck_tolerance_k
    }
}

/// Time since the last accepted reading saturates here \[s\] (about 11.6
/// days), so an unplugged sensor never drives it to infinity.
const MAX_ELAPSED_S: f32 = 1.0e6;
/// The accumulated estimate movement saturates here \[K\], far beyond any
/// tolerance, so it can never overflow to infinity.
const MAX_DRIFT_K: f32 = 1.0e6;

/// The memory of [`check`] for one sensor: a few words, updated in O(1).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlausibilityState {
    last_accepted_c: Option<f32>,
    since_accepted_s: f32,
    run_reference_c: f32,
    run_samples: u32,
    run_estimate_drift_k: f32,
}

impl PlausibilityState {
    /// A state with no history: the first reading is only range-checked.
    pub const fn new() -> Self {
        Self {
            last_accepted_c: None,
            since_accepted_s: 0.0,
            run_reference_c: 0.0,
            run_samples: 0,
            run_estimate_drift_k: 0.0,
        }
    }

    /// Forget all history, as after replacing the sensor.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// The last reading [`check`] accepted \[degC\], if any.
    pub const fn last_accepted_c(&self) -> Option<f32> {
        self.last_accepted_c
    }

    /// Consecutive samples (including the latest) within the stuck tolerance
    /// of each other's first.
    pub const fn unchanged_samples(&self) -> u32 {
        self.run_samples
    }
}

impl Default for PlausibilityState {
    fn default() -> Self {
        Self::new()
    }
}

/// Check one reading `temp_c` \[degC\] against `limits`, returning it if it
/// is plausible.
///
/// * `dt_s` \[s\]: time since the previous call for this sensor (the control
///   period when called every tick). A time step rather than an absolute time
///   because an `f32` clock in seconds loses millisecond resolution after a
///   few hours. Negative steps count as zero.
/// * `estimate_change_k` \[K\]: how far the filter's estimate of the measured
///   temperature moved since the previous call. Only the stuck check uses it;
///   a non-finite value counts as no movement.
///
/// The checks, in order; the first that fails is returned:
///
/// 1. [`SensorFault::NotFinite`]: `temp_c` or `dt_s` is NaN or infinite. The
///    state is left exactly as it was, so a NaN never poisons later checks.
/// 2. [`SensorFault::OutOfRange`]: `temp_c` is outside
///    `min_c ..= max_c`.
/// 3. [`SensorFault::Jump`] (if a rate is set): `|temp_c - last accepted|`
///    exceeds `max_rate * (time since that accepted reading)`. Rejected
///    samples do not move the reference, so after a genuine step (a sensor
///    reconnected) the allowance grows with time until the reading is
///    accepted again, instead of locking out forever.
/// 4. [`SensorFault::Stuck`] (if `samples > 0`): the last `samples` readings
///    stayed within `tolerance_k` of the first of them and the estimate's net
///    movement over those samples exceeds `tolerance_k`. It keeps firing until
///    the reading moves out of the band.
///
/// Every finite reading, accepted or not, feeds the stuck tracker; only
/// accepted readings become the reference for the rate check. Never panics;
/// O(1); no allocation.
pub fn check(
    limits: &PlausibilityCheck,
    state: &mut PlausibilityState,
    temp_c: f32,
    dt_s: f32,
    estimate_change_k: f32,
) -> Result<f32, SensorFault> {
    if !temp_c.is_finite() || !dt_s.is_finite() {
        return Err(SensorFault::NotFinite);
    }

    let dt_s = dt_s.max(0.0);
    state.since_accepted_s = (state.since_accepted_s + dt_s).min(MAX_ELAPSED_S);

    let estimate_change_k = if estimate_change_k.is_finite() {
        estimate_change_k
    } else {
        0.0
    };
    let continues_run =
        state.run_samples > 0 && (temp_c - state.run_reference_c).abs() <= limits.stuck_tolerance_k;
    if continues_run {
        state.run_samples = state.run_samples.saturating_add(1);
        state.run_estimate_drift_k =
            (state.run_estimate_drift_k + estimate_change_k).clamp(-MAX_DRIFT_K, MAX_DRIFT_K);
    } else {
        // The estimate's move since the previous sample happened before this
        // run started, so the new run's drift starts at zero.
        state.run_reference_c = temp_c;
        state.run_samples = 1;
        state.run_estimate_drift_k = 0.0;
    }

    if temp_c < limits.min_c || temp_c > limits.max_c {
        return Err(SensorFault::OutOfRange);
    }

    if let (Some(max_rate), Some(last_c)) = (limits.max_rate_k_per_s, state.last_accepted_c) {
        if (temp_c - last_c).abs() > max_rate * state.since_accepted_s {
            return Err(SensorFault::Jump);
        }
    }

    if limits.stuck_samples > 0
        && state.run_samples >= limits.stuck_samples
        && state.run_estimate_drift_k.abs() > limits.stuck_tolerance_k
    {
        return Err(SensorFault::Stuck);
    }

    state.last_accepted_c = Some(temp_c);
    state.since_accepted_s = 0.0;
    Ok(temp_c)
}

/// Test doubles shared by the driver tests.
#[cfg(test)]
pub(crate) mod test_support {
    use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};

    /// An SPI device whose every transaction fails, because the mock cannot
    /// inject bus errors.
    pub(crate) struct FailingSpi;

    impl ErrorType for FailingSpi {
        type Error = ErrorKind;
    }

    impl SpiDevice for FailingSpi {
        fn transaction(&mut self, _: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
            Err(ErrorKind::Other)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f32 = 0.001;

    fn range_only() -> PlausibilityCheck {
        PlausibilityCheck::new(-40.0, 200.0).unwrap()
    }

    fn full() -> PlausibilityCheck {
        PlausibilityCheck::new(-40.0, 200.0)
            .and_then(|c| c.with_max_rate(100.0))
            .and_then(|c| c.with_stuck_detection(5, 0.5))
            .unwrap()
    }

    #[test]
    fn errors_display_and_reduce_to_faults() {
        use embedded_hal::spi::ErrorKind;
        assert_eq!(SensorFault::OpenCircuit.to_string(), "sensor open circuit");
        let bus: Error<ErrorKind> = Error::Bus(ErrorKind::ModeFault);
        assert_eq!(bus.to_string(), "SPI bus error: ModeFault");
        assert_eq!(SensorFault::from(bus), SensorFault::Bus);
        let sensor: Error<ErrorKind> = SensorFault::Stuck.into();
        assert_eq!(sensor, Error::Sensor(SensorFault::Stuck));
        assert_eq!(sensor.to_string(), SensorFault::Stuck.to_string());
        let _: &dyn core::error::Error = &sensor;
    }

    #[test]
    fn builders_reject_invalid_limits() {
        let invalid = |r: Result<PlausibilityCheck, BuildError>, name| {
            assert_eq!(r, Err(BuildError::InvalidParameter { name }));
        };
        invalid(PlausibilityCheck::new(f32::NAN, 1.0), "min_c");
        invalid(PlausibilityCheck::new(0.0, f32::INFINITY), "max_c");
        invalid(PlausibilityCheck::new(5.0, 5.0), "max_c");
        invalid(PlausibilityCheck::new(6.0, 5.0), "max_c");
        invalid(range_only().with_max_rate(0.0), "max_rate_k_per_s");
        invalid(range_only().with_max_rate(-1.0), "max_rate_k_per_s");
        invalid(range_only().with_max_rate(f32::NAN), "max_rate_k_per_s");
        invalid(range_only().with_stuck_detection(3, -0.1), "tolerance_k");
        invalid(
            range_only().with_stuck_detection(3, f32::NAN),
            "tolerance_k",
        );
        let c = full();
        assert_eq!((c.min_c(), c.max_c()), (-40.0, 200.0));
        assert_eq!(c.max_rate_k_per_s(), Some(100.0));
        assert_eq!((c.stuck_samples(), c.stuck_tolerance_k()), (5, 0.5));
    }

    #[test]
    fn builders_work_in_const_context() {
        const LIMITS: Result<PlausibilityCheck, BuildError> = PlausibilityCheck::new(0.0, 1.0);
        assert!(LIMITS.is_ok());
    }

    #[test]
    fn non_finite_input_is_reported_and_leaves_state_untouched() {
        let limits = full();
        let mut state = PlausibilityState::new();
        assert_eq!(check(&limits, &mut state, 20.0, DT, 0.0), Ok(20.0));
        let before = state;
        for (temp, dt) in [
            (f32::NAN, DT),
            (f32::INFINITY, DT),
            (f32::NEG_INFINITY, DT),
            (20.0, f32::NAN),
            (20.0, f32::INFINITY),
        ] {
            assert_eq!(
                check(&limits, &mut state, temp, dt, 1.0),
                Err(SensorFault::NotFinite)
            );
            assert_eq!(state, before);
        }
        assert_eq!(check(&limits, &mut state, 20.05, DT, 0.0), Ok(20.05));
    }

    #[test]
    fn range_limits_are_inclusive() {
        let limits = range_only();
        let mut state = PlausibilityState::new();
        assert_eq!(check(&limits, &mut state, -40.0, DT, 0.0), Ok(-40.0));
        assert_eq!(check(&limits, &mut state, 200.0, DT, 0.0), Ok(200.0));
        assert_eq!(
            check(&limits, &mut state, 200.25, DT, 0.0),
            Err(SensorFault::OutOfRange)
        );
        assert_eq!(
            check(&limits, &mut state, -40.25, DT, 0.0),
            Err(SensorFault::OutOfRange)
        );
        // Without a rate limit any in-range step is fine.
        assert_eq!(check(&limits, &mut state, -40.0, DT, 0.0), Ok(-40.0));
    }

    #[test]
    fn jump_is_measured_from_the_last_accepted_reading() {
        // 100 K/s: 0.1 K per 1 ms sample.
        let limits = full();
        let mut state = PlausibilityState::new();
        assert_eq!(check(&limits, &mut state, 20.0, DT, 0.0), Ok(20.0));
        assert_eq!(check(&limits, &mut state, 20.09, DT, 0.0), Ok(20.09));
        assert_eq!(
            check(&limits, &mut state, 25.0, DT, 0.0),
            Err(SensorFault::Jump)
        );
        assert_eq!(state.last_accepted_c(), Some(20.09));
        // The rejected sample did not move the reference, and the allowance
        // grew: 0.2 K over two samples is fine.
        assert_eq!(check(&limits, &mut state, 20.28, DT, 0.0), Ok(20.28));
    }

    #[test]
    fn a_genuine_step_is_accepted_once_enough_time_has_passed() {
        let limits = full();
        let mut state = PlausibilityState::new();
        assert_eq!(check(&limits, &mut state, 20.0, DT, 0.0), Ok(20.0));
        // A 10 K step needs 0.1 s at 100 K/s: 100 samples.
        let mut accepted_at = None;
        for i in 1..=200 {
            if check(&limits, &mut state, 30.0 + (i % 2) as f32 * 0.1, DT, 0.0).is_ok() {
                accepted_at = Some(i);
                break;
            }
        }
        // f32 accumulation of the 1 ms steps may land one sample either side.
        assert!(matches!(accepted_at, Some(99..=101)), "{accepted_at:?}");
    }

    #[test]
    fn negative_time_step_counts_as_zero() {
        let limits = full();
        let mut state = PlausibilityState::new();
        assert_eq!(check(&limits, &mut state, 20.0, DT, 0.0), Ok(20.0));
        assert_eq!(
            check(&limits, &mut state, 20.01, -1.0, 0.0),
            Err(SensorFault::Jump)
        );
        assert_eq!(check(&limits, &mut state, 20.0, -1.0, 0.0), Ok(20.0));
    }

    #[test]
    fn stuck_needs_both_a_frozen_reading_and_a_moving_estimate() {
        let limits = full(); // 5 samples, 0.5 K
        let mut state = PlausibilityState::new();
        // Frozen reading, frozen estimate: a steady coil, fine for ever.
        for _ in 0..20 {
            assert_eq!(check(&limits, &mut state, 50.0, DT, 0.0), Ok(50.0));
        }
        state.reset();
        // Frozen reading while the estimate climbs 0.2 K per sample: the run's
        // drift passes 0.5 K at its 4th sample, the count of 5 at its 5th.
        let results: [_; 6] = core::array::from_fn(|_| check(&limits, &mut state, 50.0, DT, 0.2));
        assert_eq!(results[..4], [Ok(50.0); 4]);
        assert_eq!(results[4..], [Err(SensorFault::Stuck); 2]);
        // Readings inside the tolerance band stay stuck.
        assert_eq!(
            check(&limits, &mut state, 50.25, DT, 0.2),
            Err(SensorFault::Stuck)
        );
        // Leaving the band ends the run (10 ms later, so the 0.6 K move is
        // within the rate limit).
        assert_eq!(check(&limits, &mut state, 50.6, 0.01, 0.2), Ok(50.6));
        assert_eq!(state.unchanged_samples(), 1);
    }

    #[test]
    fn stuck_uses_net_estimate_movement() {
        let limits = full();
        let mut state = PlausibilityState::new();
        // An estimate that dithers by ±0.4 K has no net movement.
        for i in 0..50 {
            let change = if i % 2 == 0 { 0.4 } else { -0.4 };
            assert_eq!(check(&limits, &mut state, 50.0, DT, change), Ok(50.0));
        }
        // Non-finite estimate changes count as no movement.
        for _ in 0..50 {
            assert_eq!(check(&limits, &mut state, 50.0, DT, f32::NAN), Ok(50.0));
        }
    }

    #[test]
    fn stuck_detection_off_when_samples_is_zero() {
        let limits = range_only().with_stuck_detection(0, 0.5).unwrap();
        let mut state = PlausibilityState::new();
        for _ in 0..100 {
            assert_eq!(check(&limits, &mut state, 50.0, DT, 1.0), Ok(50.0));
        }
    }

    proptest! {
        #[test]
        fn check_never_panics_and_returns_its_input(
            samples in proptest::collection::vec(
                (any::<f32>(), any::<f32>(), any::<f32>()), 1..64),
            min in -1.0e3f32..0.0,
            span in 1.0e-3f32..1.0e3,
            rate in 1.0e-3f32..1.0e4,
            count in 0u32..8,
            tolerance in 0.0f32..10.0,
        ) {
            let limits = PlausibilityCheck::new(min, min + span)
                .and_then(|c| c.with_max_rate(rate))
                .and_then(|c| c.with_stuck_detection(count, tolerance))
                .unwrap();
            let mut state = PlausibilityState::new();
            for (temp, dt, change) in samples {
                let before = state;
                match check(&limits, &mut state, temp, dt, change) {
                    Ok(accepted) => {
                        prop_assert_eq!(accepted, temp);
                        prop_assert!(accepted >= limits.min_c() && accepted <= limits.max_c());
                    }
                    Err(SensorFault::NotFinite) => {
                        prop_assert!(!temp.is_finite() || !dt.is_finite());
                        prop_assert_eq!(state, before);
                    }
                    Err(_) => prop_assert!(temp.is_finite()),
                }
                prop_assert!(state.since_accepted_s.is_finite());
                prop_assert!(state.run_estimate_drift_k.is_finite());
                prop_assert!(state.run_reference_c.is_finite());
            }
        }
    }
}
