//! Per-element alarms: warning, latched shutdown and predictive, debounced and
//! with hysteresis.
//!
//! # Levels
//!
//! Each element's *alarm limit* is the derated limit of its critical
//! temperature at the measured ambient (see [`derating`](super::derating)):
//!
//! | alarm | raised when (debounced) | cleared when (debounced) |
//! |---|---|---|
//! | warning | `T > limit - warning_margin_k` | `T < limit - warning_margin_k - hysteresis_k` |
//! | shutdown | `T > limit` | only by [`AlarmState::reset`], allowed once `T < limit - hysteresis_k` |
//! | predictive | `time_to_limit_s < horizon_s` | `time_to_limit_s > horizon_s + horizon_hysteresis_s`, or `None` |
//!
//! The levels are recomputed every tick from the ambient passed in, so they
//! follow a measured ambient as the HPPA report recommends.
//!
//! # Debouncing: an up/down counter
//!
//! Each alarm has one saturating counter. While the alarm is off, a sample
//! beyond the raise level counts up and any other sample counts down (not
//! below zero); the alarm rises when the counter reaches `debounce_ticks`.
//! Clearing works the same way with the clear level. So:
//!
//! * a clean crossing is raised after exactly `debounce_ticks` samples;
//! * once *every* sample is beyond the level, the alarm rises within at most
//!   `debounce_ticks` ticks whatever came before (the counter is never
//!   negative, so earlier noise can only shorten the wait);
//! * when noise puts a fraction `p > 1/2` of the samples beyond the level,
//!   the counter drifts up by `2p - 1` per tick and the alarm rises after
//!   about `debounce_ticks / (2p - 1)` ticks. A counter that a single
//!   contrary sample resets to zero would need `debounce_ticks` samples in a
//!   row, which at `p = 0.8` and 50 ticks happens about once in 70 000: noise
//!   riding on a real crossing would delay it almost indefinitely.
//!
//! Against toggling, the hysteresis band does the work: noise of peak
//! amplitude below `hysteresis_k / 2` around a level can raise the alarm at
//! most once and never clear it.
//!
//! # Invalid samples
//!
//! A non-finite temperature (NaN, an infinity: a broken sensor or a diverged
//! estimate) sets the element's [`sensor_invalid`](ElementAlarm::sensor_invalid)
//! flag and raises a [`SensorInvalid`](EventKind::SensorInvalid) event. It is
//! treated as *unknown*, which is never evidence for a clear:
//!
//! * for the warning it counts as "above": a sensor that stays invalid raises
//!   the warning after `debounce_ticks`, and an active warning never clears;
//! * for the shutdown it neither counts up nor clears a latch: a glitch must
//!   not shut a machine down, and the current limiter (which gives an invalid
//!   element its floor current) is what keeps an unobserved coil safe;
//! * [`AlarmState::reset`] is refused while any element is invalid.
//!
//! A NaN predicted time counts as "below the horizon" for the same reason.
//! A non-finite ambient is replaced by the last valid one (initially
//! `nominal_ambient_c`), flagged, and blocks a reset.
//!
//! # Cost
//!
//! [`AlarmState::tick`] is O(N) with a fixed amount of work per element, never
//! allocates and never panics; the fixed-point path (`Q32`) has no division.

use core::fmt;
use core::ops::Range;

use nalgebra::Const;

use super::derating::{derated_limit_c, DeratingRule};
use super::events::{AlarmEvent, EventKind, EventQueue};
use crate::error::{check, BuildError};
use crate::scalar::Scalar;
use crate::sizes::{Element, Length};

/// Where one sample lies relative to an alarm's raise and clear levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Observation {
    /// Beyond the raise level: evidence for raising.
    Above,
    /// Inside the hysteresis band: evidence for neither.
    Band,
    /// Beyond the clear level: evidence for clearing.
    Below,
    /// Not known: holds an inactive alarm, counts against clearing.
    Unknown,
}

/// What one update did to an alarm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Transition {
    None,
    Raised,
    Cleared,
}

/// One debounced alarm: its state and its up/down counter.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Debounced {
    active: bool,
    count: u16,
}

impl Debounced {
    /// `true` while the alarm is raised.
    pub fn is_active(&self) -> bool {
        self.active
    }

    /// The up/down counter, in ticks: towards raising while off, towards
    /// clearing (or, for a latched alarm, towards "settled for a reset") while
    /// on.
    pub fn count(&self) -> u16 {
        self.count
    }

    /// `true` when [`Self::update`] with `observation` would change
    /// nothing: no evidence and a counter already at zero (or an inactive
    /// alarm facing an unknown sample).
    #[inline]
    fn is_settled(&self, observation: Observation) -> bool {
        match (self.active, observation) {
            (false, Observation::Unknown) => true,
            (false, obs) => self.count == 0 && obs != Observation::Above,
            (true, obs) => self.count == 0 && obs != Observation::Below,
        }
    }

    fn update(
        &mut self,
        observation: Observation,
        debounce_ticks: u16,
        latched: bool,
    ) -> Transition {
        let evidence = match (self.active, observation) {
            (false, Observation::Unknown) => return Transition::None,
            (false, obs) => obs == Observation::Above,
            (true, obs) => obs == Observation::Below,
        };
        self.count = if evidence {
            self.count.saturating_add(1)
        } else {
            self.count.saturating_sub(1)
        };
        if self.count < debounce_ticks {
            return Transition::None;
        }
        if !self.active {
            self.active = true;
            self.count = 0;
            Transition::Raised
        } else if latched {
            // Settled: hold the count at the threshold so that one later
            // contrary sample costs exactly one tick.
            self.count = debounce_ticks;
            Transition::None
        } else {
            self.active = false;
            self.count = 0;
            Transition::Cleared
        }
    }
}

/// The alarm configuration for `N` elements (`Const<N>`: arrays; `Dyn`:
/// vectors, see [`crate::sizes`]), in scalar `S`.
///
/// Built once by [`AlarmBuilder::build`], then only read; share it between
/// devices of the same kind.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmConfig<S: Element, N: Length> {
    pub(crate) critical_c: N::Array<S>,
    pub(crate) product: S,
    pub(crate) warning_margin_k: S,
    pub(crate) hysteresis_k: S,
    pub(crate) debounce_ticks: u16,
    pub(crate) horizon_s: S,
    pub(crate) horizon_clear_s: S,
    pub(crate) nominal_ambient_c: S,
}

#[cfg(feature = "defmt")]
impl<S: Element + defmt::Format, const N: usize> defmt::Format for AlarmConfig<S, Const<N>> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "AlarmConfig {{ critical_c: {}, product: {}, warning_margin_k: {}, hysteresis_k: {}, debounce_ticks: {}, horizon_s: {}, horizon_clear_s: {}, nominal_ambient_c: {} }}",
            self.critical_c,
            self.product,
            self.warning_margin_k,
            self.hysteresis_k,
            self.debounce_ticks,
            self.horizon_s,
            self.horizon_clear_s,
            self.nominal_ambient_c
        )
    }
}

impl<S: Scalar, N: Length> AlarmConfig<S, N> {
    /// The alarm limit \[degC\] (the shutdown level) of every element at
    /// ambient `ambient_c` \[degC\]; what the current limiter tapers towards.
    pub fn alarm_limits_c(&self, ambient_c: S) -> N::Array<S> {
        N::mapped(&self.critical_c, |&critical_c| {
            derated_limit_c(critical_c, ambient_c, self.product)
        })
    }

    /// The alarm limit \[degC\] of element `element` at `ambient_c` \[degC\],
    /// or `None` if there is no such element.
    pub fn alarm_limit_c(&self, element: usize, ambient_c: S) -> Option<S> {
        self.critical_c
            .as_ref()
            .get(element)
            .map(|&critical_c| derated_limit_c(critical_c, ambient_c, self.product))
    }

    /// The critical temperatures \[degC\], one per element.
    pub fn critical_c(&self) -> &N::Array<S> {
        &self.critical_c
    }

    /// How far below the alarm limit the warning rises \[K\].
    pub fn warning_margin_k(&self) -> S {
        self.warning_margin_k
    }

    /// The hysteresis \[K\] below a level that a clear (or a reset) needs.
    pub fn hysteresis_k(&self) -> S {
        self.hysteresis_k
    }

    /// Ticks of evidence needed to raise or clear an alarm.
    pub fn debounce_ticks(&self) -> u16 {
        self.debounce_ticks
    }

    /// Feeds every parameter (critical temperatures, the derating
    /// product, margins, debounce, horizons, nominal ambient) to a
    /// snapshot fingerprint.
    #[must_use]
    pub fn fingerprint(&self, fp: crate::observer::Fingerprint) -> crate::observer::Fingerprint {
        self.critical_c
            .as_ref()
            .iter()
            .fold(fp, |fp, c| fp.f64(c.to_f64()))
            .f64s(&[
                self.product.to_f64(),
                self.warning_margin_k.to_f64(),
                self.hysteresis_k.to_f64(),
                self.horizon_s.to_f64(),
                self.horizon_clear_s.to_f64(),
                self.nominal_ambient_c.to_f64(),
            ])
            .u32(u32::from(self.debounce_ticks))
    }
}

/// Builds an [`AlarmConfig`]; every parameter has a documented default.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmBuilder<N: Length> {
    critical_c: N::Array<f64>,
    product: f64,
    warning_margin_k: f64,
    hysteresis_k: f64,
    debounce_ticks: u16,
    horizon_s: f64,
    horizon_hysteresis_s: f64,
    nominal_ambient_c: f64,
}

impl<const N: usize> AlarmBuilder<Const<N>> {
    /// Starts a configuration from a derating rule and each element's
    /// critical temperature \[degC\] (the lowest of its materials).
    ///
    /// Defaults: `warning_margin_k` 5 K, `hysteresis_k` 2 K,
    /// `debounce_ticks` 10 (10 ms at a 1 ms tick), `horizon_s` 60 s,
    /// `horizon_hysteresis_s` 10 s, `nominal_ambient_c` 20 degC (the
    /// calibration ambient of both reference devices).
    pub fn new(rule: &DeratingRule, critical_c: [f64; N]) -> Self {
        Self::of(rule, critical_c)
    }
}

impl<N: Length> AlarmBuilder<N> {
    /// [`AlarmBuilder::new`] for elements of any [`Length`] (a `Vec` of
    /// critical temperatures for `Dyn`, a model's size read at run time).
    pub fn of(rule: &DeratingRule, critical_c: N::Array<f64>) -> Self {
        Self {
            critical_c,
            product: rule.product(),
            warning_margin_k: 5.0,
            hysteresis_k: 2.0,
            debounce_ticks: 10,
            horizon_s: 60.0,
            horizon_hysteresis_s: 10.0,
            nominal_ambient_c: 20.0,
        }
    }

    /// How far below the alarm limit the warning rises \[K\], finite and >= 0.
    pub fn warning_margin_k(mut self, margin_k: f64) -> Self {
        self.warning_margin_k = margin_k;
        self
    }

    /// How far below a level the temperature must fall to clear its alarm
    /// (or allow a reset) \[K\], finite and >= 0.
    pub fn hysteresis_k(mut self, hysteresis_k: f64) -> Self {
        self.hysteresis_k = hysteresis_k;
        self
    }

    /// Net ticks of evidence needed to raise or clear an alarm, >= 1 (see the
    /// module docs for the up/down counter).
    pub fn debounce_ticks(mut self, ticks: u16) -> Self {
        self.debounce_ticks = ticks;
        self
    }

    /// The predictive alarm rises when the predicted time to the alarm limit
    /// is below this \[s\], finite and >= 0.
    pub fn horizon_s(mut self, horizon_s: f64) -> Self {
        self.horizon_s = horizon_s;
        self
    }

    /// The predictive alarm clears when the predicted time exceeds
    /// `horizon_s` plus this \[s\], finite and >= 0.
    pub fn horizon_hysteresis_s(mut self, hysteresis_s: f64) -> Self {
        self.horizon_hysteresis_s = hysteresis_s;
        self
    }

    /// The ambient \[degC\] assumed until the first finite ambient arrives.
    pub fn nominal_ambient_c(mut self, ambient_c: f64) -> Self {
        self.nominal_ambient_c = ambient_c;
        self
    }

    /// Validates and converts to scalar `S`.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the first parameter that is not
    /// finite or out of its range (`critical_c` for any element).
    pub fn build<S: Scalar>(&self) -> Result<AlarmConfig<S, N>, BuildError> {
        let non_negative = |x: f64| x.is_finite() && x >= 0.0;
        check(
            self.critical_c.as_ref().iter().all(|c| c.is_finite()),
            "critical_c",
        )?;
        check(non_negative(self.warning_margin_k), "warning_margin_k")?;
        check(non_negative(self.hysteresis_k), "hysteresis_k")?;
        check(self.debounce_ticks >= 1, "debounce_ticks")?;
        check(non_negative(self.horizon_s), "horizon_s")?;
        check(
            non_negative(self.horizon_hysteresis_s),
            "horizon_hysteresis_s",
        )?;
        check(self.nominal_ambient_c.is_finite(), "nominal_ambient_c")?;
        Ok(AlarmConfig {
            critical_c: N::mapped(&self.critical_c, |&c| S::from_f64(c)),
            product: S::from_f64(self.product),
            warning_margin_k: S::from_f64(self.warning_margin_k),
            hysteresis_k: S::from_f64(self.hysteresis_k),
            debounce_ticks: self.debounce_ticks,
            horizon_s: S::from_f64(self.horizon_s),
            horizon_clear_s: S::from_f64(self.horizon_s + self.horizon_hysteresis_s),
            nominal_ambient_c: S::from_f64(self.nominal_ambient_c),
        })
    }
}

/// The alarm state of one element.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ElementAlarm {
    warning: Debounced,
    shutdown: Debounced,
    predictive: Debounced,
    sensor_invalid: bool,
    below_reset: bool,
}

impl ElementAlarm {
    /// The warning is raised.
    pub fn warning(&self) -> bool {
        self.warning.active
    }

    /// The shutdown is latched.
    pub fn shutdown(&self) -> bool {
        self.shutdown.active
    }

    /// The predictive alarm is raised.
    pub fn predictive(&self) -> bool {
        self.predictive.active
    }

    /// The last temperature was not finite.
    pub fn sensor_invalid(&self) -> bool {
        self.sensor_invalid
    }

    /// The last temperature was valid and below the reset threshold
    /// (`limit - hysteresis_k`) \[degC\].
    pub fn below_reset(&self) -> bool {
        self.below_reset
    }

    /// The warning's debouncer.
    pub fn warning_debounce(&self) -> Debounced {
        self.warning
    }

    /// The shutdown's debouncer (while latched, its count says how settled
    /// the element is below the reset threshold).
    pub fn shutdown_debounce(&self) -> Debounced {
        self.shutdown
    }

    /// The predictive alarm's debouncer.
    pub fn predictive_debounce(&self) -> Debounced {
        self.predictive
    }
}

impl ElementAlarm {
    /// The full update of one element whose alarms may move, out of line:
    /// most elements are settled, and keeping this out of the element loop
    /// leaves the loop its registers. `observations` are those of the
    /// warning, the shutdown and the predictive alarm.
    #[cold]
    #[inline(never)]
    fn update<const CAP: usize>(
        &mut self,
        index: usize,
        valid: bool,
        observations: [Observation; 3],
        debounce: u16,
        tick: u64,
        events: &mut EventQueue<CAP>,
    ) {
        let mut push = |kind: EventKind| {
            // A full queue counts the drop itself; the state stays the truth.
            let _ = events.push(AlarmEvent {
                tick,
                element: Some(index),
                kind,
            });
        };
        if valid == self.sensor_invalid {
            push(sensor_event(valid));
        }
        self.sensor_invalid = !valid;
        let [warning_obs, shutdown_obs, time_obs] = observations;
        let changes = [
            (
                self.warning.update(warning_obs, debounce, false),
                EventKind::WarningRaised,
                EventKind::WarningCleared,
            ),
            (
                self.shutdown.update(shutdown_obs, debounce, true),
                EventKind::ShutdownLatched,
                // Never produced: the shutdown is latched.
                EventKind::Reset,
            ),
            (
                self.predictive.update(time_obs, debounce, false),
                EventKind::PredictiveRaised,
                EventKind::PredictiveCleared,
            ),
        ];
        for (transition, raised, cleared) in changes {
            match transition {
                Transition::Raised => push(raised),
                Transition::Cleared => push(cleared),
                Transition::None => {}
            }
        }
    }
}

/// A summary of all elements after a tick: `true` if any element has it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AlarmStatus {
    /// Some element's warning is raised.
    pub warning: bool,
    /// Some element's shutdown is latched: the caller must cut the current.
    pub shutdown: bool,
    /// Some element's predictive alarm is raised.
    pub predictive: bool,
    /// Some element's temperature was not finite this tick.
    pub sensor_invalid: bool,
    /// The ambient was not finite this tick; the last valid one was used.
    pub ambient_invalid: bool,
    /// The event queue has dropped events since its last acknowledgement.
    pub events_dropped: bool,
}

impl AlarmStatus {
    /// Both statuses in one: each flag set if it is set in either (for the
    /// parts of [`AlarmState::tick_part`]).
    #[must_use]
    pub fn union(self, other: Self) -> Self {
        Self {
            warning: self.warning || other.warning,
            shutdown: self.shutdown || other.shutdown,
            predictive: self.predictive || other.predictive,
            sensor_invalid: self.sensor_invalid || other.sensor_invalid,
            ambient_invalid: self.ambient_invalid || other.ambient_invalid,
            events_dropped: self.events_dropped || other.events_dropped,
        }
    }
}

/// Why [`AlarmState::reset`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ResetError {
    /// The element's last temperature was not below its reset threshold.
    TooHot {
        /// Element index.
        element: usize,
    },
    /// The element is below its reset threshold but has not been for
    /// `debounce_ticks` (net) ticks yet.
    NotSettled {
        /// Element index.
        element: usize,
    },
    /// The element's last temperature was not finite.
    SensorInvalid {
        /// Element index.
        element: usize,
    },
    /// The last ambient was not finite, so the thresholds are uncertain.
    AmbientInvalid,
}

impl fmt::Display for ResetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooHot { element } => {
                write!(f, "element {element} is not below its reset threshold")
            }
            Self::NotSettled { element } => write!(
                f,
                "element {element} has not stayed below its reset threshold long enough"
            ),
            Self::SensorInvalid { element } => {
                write!(f, "element {element} has no valid temperature")
            }
            Self::AmbientInvalid => write!(f, "the ambient temperature is not valid"),
        }
    }
}

impl core::error::Error for ResetError {}

/// The alarm state of `N` elements: small, per device, what a snapshot saves.
#[derive(Debug, Clone, PartialEq)]
pub struct AlarmState<S: Element, N: Length> {
    elements: N::Array<ElementAlarm>,
    ambient_c: S,
    ambient_invalid: bool,
    tick: u64,
}

#[cfg(feature = "defmt")]
impl<S: Element + defmt::Format, const N: usize> defmt::Format for AlarmState<S, Const<N>> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "AlarmState {{ elements: {}, ambient_c: {}, ambient_invalid: {}, tick: {} }}",
            self.elements,
            self.ambient_c,
            self.ambient_invalid,
            self.tick
        )
    }
}

/// Where a tick's alarm limits come from: derated from the critical
/// temperatures at the tick's ambient ([`Derate`]), or given (a slice of
/// them, derated already \[degC\]).
trait Levels<S: Scalar, N: Length>: Copy {
    /// The temperatures \[degC\] the limits are taken from.
    fn of<'a>(self, config: &'a AlarmConfig<S, N>) -> &'a [S]
    where
        Self: 'a;
    /// The limit \[degC\] from `level_c` \[degC\] at `ambient_c` \[degC\].
    fn limit_c(level_c: S, ambient_c: S, product: S) -> S;
}

/// Each limit derated from its critical temperature.
#[derive(Clone, Copy)]
struct Derate;

impl<S: Scalar, N: Length> Levels<S, N> for Derate {
    #[inline(always)]
    fn of<'a>(self, config: &'a AlarmConfig<S, N>) -> &'a [S]
    where
        Self: 'a,
    {
        config.critical_c.as_ref()
    }
    #[inline(always)]
    fn limit_c(critical_c: S, ambient_c: S, product: S) -> S {
        derated_limit_c(critical_c, ambient_c, product)
    }
}

impl<S: Scalar, N: Length> Levels<S, N> for &N::Array<S> {
    #[inline(always)]
    fn of<'a>(self, _: &'a AlarmConfig<S, N>) -> &'a [S]
    where
        Self: 'a,
    {
        self.as_ref()
    }
    #[inline(always)]
    fn limit_c(limit_c: S, _: S, _: S) -> S {
        limit_c
    }
}

impl<S: Scalar, N: Length> AlarmState<S, N> {
    /// All alarms off, ambient at the configuration's nominal ambient.
    pub fn new(config: &AlarmConfig<S, N>) -> Self {
        Self {
            elements: N::filled_like(&config.critical_c, ElementAlarm::default()),
            ambient_c: config.nominal_ambient_c,
            ambient_invalid: false,
            tick: 0,
        }
    }

    /// One tick: compares every element's temperature `temps_c` \[degC\] with
    /// its levels at ambient `ambient_c` \[degC\], and the predicted times to
    /// the alarm limit `time_to_limit_s` \[s\] (`None`: never) with the
    /// horizon; pushes one event per change into `events`.
    ///
    /// O(N), allocation-free, panic-free. See the module docs for invalid
    /// inputs.
    pub fn tick<const CAP: usize>(
        &mut self,
        config: &AlarmConfig<S, N>,
        temps_c: &N::Array<S>,
        ambient_c: S,
        time_to_limit_s: &N::Array<Option<S>>,
        events: &mut EventQueue<CAP>,
    ) -> AlarmStatus {
        let all = 0..temps_c.as_ref().len();
        self.tick_part(config, temps_c, ambient_c, time_to_limit_s, events, all)
    }

    /// [`Self::tick`] for the elements in `elements` only, for a caller that
    /// spreads one tick over several control ticks to bound the work of each:
    /// the part that starts at element 0 counts the tick and takes
    /// `ambient_c`; the other parts use that tick and ambient (their
    /// `ambient_c` is ignored). Each element must be in exactly one part per
    /// tick. The status covers the part's elements and the ambient; combine
    /// the parts' with [`AlarmStatus::union`]. A range beyond `N` is cut to it.
    pub fn tick_part<const CAP: usize>(
        &mut self,
        config: &AlarmConfig<S, N>,
        temps_c: &N::Array<S>,
        ambient_c: S,
        time_to_limit_s: &N::Array<Option<S>>,
        events: &mut EventQueue<CAP>,
        elements: Range<usize>,
    ) -> AlarmStatus {
        self.judge(
            config,
            temps_c,
            ambient_c,
            time_to_limit_s,
            events,
            elements,
            Derate,
        )
    }

    /// The ambient \[degC\] the limits of a tick at `ambient_c` \[degC\]
    /// are derated at: `ambient_c`, or the last valid one if it is not
    /// finite (see the module docs).
    pub(crate) fn derating_ambient_c(&self, ambient_c: S) -> S {
        if ambient_c.is_finite() {
            ambient_c
        } else {
            self.ambient_c
        }
    }

    /// [`Self::tick`] with every element's alarm limit \[degC\] given, if
    /// `limits_c` is `Some`: then it must be [`AlarmConfig::alarm_limits_c`]
    /// at [`Self::derating_ambient_c`] of `ambient_c` (for an observer
    /// that keeps them per ambient, which moves far less often than its
    /// alarm runs: each is a derating, soft-float routines on a core
    /// without an FPU). The same tick, to the bit.
    #[inline(always)]
    pub(crate) fn tick_at_limits<const CAP: usize>(
        &mut self,
        config: &AlarmConfig<S, N>,
        temps_c: &N::Array<S>,
        ambient_c: S,
        limits_c: Option<&N::Array<S>>,
        time_to_limit_s: &N::Array<Option<S>>,
        events: &mut EventQueue<CAP>,
    ) -> AlarmStatus {
        match limits_c {
            Some(limits_c) => self.judge(
                config,
                temps_c,
                ambient_c,
                time_to_limit_s,
                events,
                0..temps_c.as_ref().len(),
                limits_c,
            ),
            None => self.tick(config, temps_c, ambient_c, time_to_limit_s, events),
        }
    }

    /// [`Self::tick_part`] with the alarm limits of `levels`.
    ///
    /// On a core with an FPU a hint to inline, as `tick_part` had before
    /// it shared this body (forced, the Omnimagnet's warm-up ticks on the
    /// M4F took 8 instructions more on average; out of line, the network
    /// observer's 7); out of line elsewhere (inlined into
    /// `tick_at_limits`, the 2-node Cortex-M0 footprint took 240 B more).
    #[cfg_attr(target_abi = "eabihf", inline)]
    #[cfg_attr(not(target_abi = "eabihf"), inline(never))]
    #[allow(clippy::too_many_arguments)]
    fn judge<L: Levels<S, N>, const CAP: usize>(
        &mut self,
        config: &AlarmConfig<S, N>,
        temps_c: &N::Array<S>,
        ambient_c: S,
        time_to_limit_s: &N::Array<Option<S>>,
        events: &mut EventQueue<CAP>,
        elements: Range<usize>,
        levels: L,
    ) -> AlarmStatus {
        let first = elements.start;
        if first == 0 {
            self.tick = self.tick.wrapping_add(1);
        }
        let tick = self.tick;
        if first == 0 {
            let ambient_valid = ambient_c.is_finite();
            if ambient_valid {
                self.ambient_c = ambient_c;
            }
            if ambient_valid == self.ambient_invalid {
                // A full queue counts the drop itself; the state stays the truth.
                let _ = events.push(AlarmEvent {
                    tick,
                    element: None,
                    kind: sensor_event(ambient_valid),
                });
            }
            self.ambient_invalid = !ambient_valid;
        }

        let debounce = config.debounce_ticks;
        let mut status = AlarmStatus {
            ambient_invalid: self.ambient_invalid,
            ..AlarmStatus::default()
        };
        let (mut warning, mut shutdown, mut predictive, mut sensor_invalid) =
            (false, false, false, false);
        let n = temps_c.as_ref().len();
        let elements = first.min(n)..elements.end.min(n);
        let (Some(alarms), Some(temps_c), Some(levels_c), Some(time_to_limit_s)) = (
            self.elements.as_mut().get_mut(elements.clone()),
            temps_c.as_ref().get(elements.clone()),
            levels.of(config).get(elements.clone()),
            time_to_limit_s.as_ref().get(elements),
        ) else {
            return status;
        };
        let inputs = temps_c
            .iter()
            .zip(levels_c.iter())
            .zip(time_to_limit_s.iter());
        for (offset, (element, ((&temp_c, &level_c), &time_s))) in
            alarms.iter_mut().zip(inputs).enumerate()
        {
            let index = first + offset;
            let limit_c = L::limit_c(level_c, self.ambient_c, config.product);
            let warning_c = limit_c - config.warning_margin_k;
            let valid = temp_c.is_finite();
            let time_obs = observe_time(time_s, config);
            let hysteresis_k = config.hysteresis_k;
            // A valid sample below `limit - hysteresis` is below the limit
            // too (the hysteresis is not negative): `Below` for the shutdown.
            let below_reset = valid && temp_c < limit_c - hysteresis_k;
            element.below_reset = below_reset;
            // The usual element, in plain comparisons: a valid sample as
            // before, every counter at zero and no evidence for any alarm
            // (see `Debounced::is_settled`). The full update would change
            // nothing; anything else (including a NaN level) takes it.
            let (w, s, p) = (&element.warning, &element.shutdown, &element.predictive);
            let settled = valid
                && !element.sensor_invalid
                && w.count == 0
                && s.count == 0
                && if w.active {
                    temp_c >= warning_c - hysteresis_k
                } else {
                    temp_c <= warning_c
                }
                && if s.active {
                    !below_reset
                } else {
                    temp_c <= limit_c
                }
                && p.is_settled(time_obs);
            if !settled {
                let (warning_obs, shutdown_obs) = if valid {
                    (
                        observe(temp_c, warning_c, hysteresis_k),
                        observe(temp_c, limit_c, hysteresis_k),
                    )
                } else {
                    (Observation::Above, Observation::Unknown)
                };
                let observations = [warning_obs, shutdown_obs, time_obs];
                element.update(index, valid, observations, debounce, tick, events);
            }
            // Locals, not `status` fields: kept in registers across the loop.
            warning |= element.warning.active;
            shutdown |= element.shutdown.active;
            predictive |= element.predictive.active;
            sensor_invalid |= element.sensor_invalid;
        }
        status.warning = warning;
        status.shutdown = shutdown;
        status.predictive = predictive;
        status.sensor_invalid = sensor_invalid;
        status.events_dropped = events.overflowed();
        status
    }

    /// Clears the latched shutdown, if every element's last temperature was
    /// valid and below its reset threshold (`limit - hysteresis_k`), every
    /// latched element has stayed there for `debounce_ticks` net ticks, and
    /// the ambient is valid. Pushes a [`Reset`](EventKind::Reset) event.
    ///
    /// With no shutdown latched this does nothing and succeeds.
    ///
    /// # Errors
    /// Why not, naming the first element that blocks it.
    pub fn reset<const CAP: usize>(
        &mut self,
        config: &AlarmConfig<S, N>,
        events: &mut EventQueue<CAP>,
    ) -> Result<(), ResetError> {
        if !self.shutdown_latched() {
            return Ok(());
        }
        if self.ambient_invalid {
            return Err(ResetError::AmbientInvalid);
        }
        for (element, alarm) in self.elements.as_ref().iter().enumerate() {
            if alarm.sensor_invalid {
                return Err(ResetError::SensorInvalid { element });
            }
            if !alarm.below_reset {
                return Err(ResetError::TooHot { element });
            }
            if alarm.shutdown.active && alarm.shutdown.count < config.debounce_ticks {
                return Err(ResetError::NotSettled { element });
            }
        }
        for alarm in self.elements.as_mut() {
            alarm.shutdown = Debounced::default();
        }
        let _ = events.push(AlarmEvent {
            tick: self.tick,
            element: None,
            kind: EventKind::Reset,
        });
        Ok(())
    }

    /// Latches the shutdown of every element, without an event: for a warm
    /// restart from a snapshot that recorded a latched shutdown, because a
    /// reset of the MCU must not be a way around the latch. [`Self::reset`]
    /// clears it under its usual conditions.
    pub fn latch_shutdown(&mut self) {
        for element in self.elements.as_mut() {
            element.shutdown = Debounced {
                active: true,
                count: 0,
            };
        }
    }

    /// Latches the shutdown of every element for a fault outside the
    /// elements (e.g. [`EventKind::ClockFrozen`]: the model is lost) and,
    /// if it was not latched yet, pushes a `kind` event with no element.
    /// [`Self::reset`] clears it under its usual conditions. Bounded,
    /// panic-free: for the tick.
    pub fn latch_shutdown_for<const CAP: usize>(
        &mut self,
        kind: EventKind,
        events: &mut EventQueue<CAP>,
    ) {
        if self.shutdown_latched() {
            return;
        }
        self.latch_shutdown();
        let _ = events.push(AlarmEvent {
            tick: self.tick,
            element: None,
            kind,
        });
    }

    /// `true` while any element's shutdown is latched.
    #[inline]
    pub fn shutdown_latched(&self) -> bool {
        self.elements.as_ref().iter().any(|e| e.shutdown.active)
    }

    /// Every element's alarm state.
    pub fn elements(&self) -> &N::Array<ElementAlarm> {
        &self.elements
    }

    /// The ambient \[degC\] used by the last tick: the last finite one
    /// passed in (or the nominal ambient before any).
    pub fn ambient_c(&self) -> S {
        self.ambient_c
    }

    /// Ticks since construction.
    pub fn tick_count(&self) -> u64 {
        self.tick
    }
}

fn sensor_event(valid: bool) -> EventKind {
    if valid {
        EventKind::SensorValid
    } else {
        EventKind::SensorInvalid
    }
}

/// A finite temperature against a raise level and its hysteresis.
#[inline]
fn observe<S: Scalar>(temp_c: S, level_c: S, hysteresis_k: S) -> Observation {
    if temp_c > level_c {
        Observation::Above
    } else if temp_c < level_c - hysteresis_k {
        Observation::Below
    } else {
        Observation::Band
    }
}

/// A predicted time against the horizon: sooner is "above".
#[inline]
fn observe_time<S: Scalar, N: Length>(
    time_s: Option<S>,
    config: &AlarmConfig<S, N>,
) -> Observation {
    match time_s {
        None => Observation::Below,
        // NaN compares unordered: unknown, so it counts towards raising.
        Some(t) if t.partial_cmp(&config.horizon_s).is_none() => Observation::Above,
        Some(t) if t < config.horizon_s => Observation::Above,
        Some(t) if t > config.horizon_clear_s => Observation::Below,
        Some(_) => Observation::Band,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protect::derating::HPPA_CRITICAL_C;
    use crate::scalar::Q32;
    use proptest::prelude::*;

    /// xorshift64*: deterministic noise without a dependency.
    struct Rng(u64);
    impl Rng {
        fn next_u64(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
        }
        /// Uniform in [-1, 1).
        fn symmetric(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
    }

    // HPPA rule, 100 degC, 20 degC ambient: limit 65.36, warning 60.36,
    // warning clear 58.36, reset threshold 63.36.
    const LIMIT: f64 = 65.36;
    const WARNING: f64 = 60.36;
    const HYST: f64 = 2.0;

    fn config<S: Scalar, const N: usize>(debounce: u16) -> AlarmConfig<S, Const<N>> {
        AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; N])
            .warning_margin_k(5.0)
            .hysteresis_k(HYST)
            .debounce_ticks(debounce)
            .horizon_s(30.0)
            .horizon_hysteresis_s(5.0)
            .build()
            .unwrap()
    }

    /// Runs one tick with one element, no prediction, 20 degC ambient.
    fn step<S: Scalar, const Q: usize>(
        state: &mut AlarmState<S, Const<1>>,
        cfg: &AlarmConfig<S, Const<1>>,
        temp_c: f64,
        events: &mut EventQueue<Q>,
    ) -> AlarmStatus {
        state.tick(
            cfg,
            &[S::from_f64(temp_c)],
            S::from_f64(20.0),
            &[None],
            events,
        )
    }

    /// `tick_at_limits` with the limits derated at `derating_ambient_c` is
    /// `tick` to the bit: the same statuses, events and state over
    /// temperatures crossing every level and an ambient that moves, goes
    /// NaN and infinite (the last valid one derates then) and comes back.
    #[test]
    fn the_tick_at_given_limits_is_the_tick() {
        let cfg = config::<f32, 3>(2);
        let (mut plain, mut given) = (AlarmState::new(&cfg), AlarmState::new(&cfg));
        let (mut plain_events, mut given_events) =
            (EventQueue::<64>::new(), EventQueue::<64>::new());
        let mut rng = Rng(7);
        let ambients = [
            20.0,
            20.0,
            35.0,
            f32::NAN,
            f32::NAN,
            -5.0,
            f32::INFINITY,
            20.0,
        ];
        let mut derated_at_last_valid = 0;
        for k in 0..4_000 {
            let ambient_c = ambients[(k / 50) % ambients.len()];
            let temps_c: [f32; 3] =
                core::array::from_fn(|_| (LIMIT + 12.0 * rng.symmetric()) as f32);
            let time_s = [
                None,
                Some(10.0 + 40.0 * rng.symmetric() as f32),
                Some(f32::NAN),
            ];
            let derating_c = given.derating_ambient_c(ambient_c);
            derated_at_last_valid += usize::from(derating_c.to_bits() != ambient_c.to_bits());
            let limits_c = cfg.alarm_limits_c(derating_c);
            let a = plain.tick(&cfg, &temps_c, ambient_c, &time_s, &mut plain_events);
            let b = given.tick_at_limits(
                &cfg,
                &temps_c,
                ambient_c,
                Some(&limits_c),
                &time_s,
                &mut given_events,
            );
            assert_eq!(a, b, "tick {k}");
            assert_eq!(plain, given, "tick {k}");
            while let Some(e) = plain_events.pop() {
                assert_eq!(Some(e), given_events.pop(), "tick {k}");
            }
            assert!(given_events.is_empty());
        }
        // The NaN and infinite ambients (3 of every 8 runs of 50 ticks)
        // were derated at the last valid one.
        assert_eq!(derated_at_last_valid, 1_500);
    }

    fn count(events: &mut EventQueue<4096>, kind: EventKind) -> usize {
        let mut n = 0;
        while let Some(e) = events.pop() {
            n += usize::from(e.kind == kind);
        }
        n
    }

    fn debounce_delays_raise_exactly<S: Scalar>() {
        for debounce in [1u16, 2, 7, 50] {
            let cfg = config::<S, 1>(debounce);
            let mut state = AlarmState::new(&cfg);
            let mut events = EventQueue::<8>::new();
            for _ in 0..100 {
                step(&mut state, &cfg, WARNING - 0.01, &mut events);
            }
            assert!(events.is_empty());
            for k in 1..=debounce {
                let status = step(&mut state, &cfg, WARNING + 0.01, &mut events);
                assert_eq!(status.warning, k == debounce, "{debounce} {k}");
            }
            let event = events.pop().unwrap();
            assert_eq!(event.kind, EventKind::WarningRaised);
            assert_eq!(event.tick, 100 + u64::from(debounce));
            assert_eq!(event.element, Some(0));
            // Same count for the clear, which needs the hysteresis too.
            for _ in 0..100 {
                step(&mut state, &cfg, WARNING - HYST + 0.01, &mut events);
            }
            assert!(state.elements()[0].warning());
            for k in 1..=debounce {
                let status = step(&mut state, &cfg, WARNING - HYST - 0.01, &mut events);
                assert_eq!(status.warning, k != debounce);
            }
            assert_eq!(events.pop().unwrap().kind, EventKind::WarningCleared);
        }
    }

    #[test]
    fn a_tick_in_parts_is_the_whole_tick() {
        // Noisy temperatures through every level, a NaN now and then, times
        // around the horizon and an ambient that fails once: the state, the
        // events and the combined status must be those of whole ticks.
        let cfg = config::<f32, 6>(3);
        let mut rng = Rng(0x1234_5678);
        let (mut whole, mut parts) = (AlarmState::new(&cfg), AlarmState::new(&cfg));
        let (mut events_whole, mut events_parts) =
            (EventQueue::<64>::new(), EventQueue::<64>::new());
        for k in 0..400 {
            let temps: [f32; 6] = core::array::from_fn(|i| {
                let t = 55.0
                    + 12.0 * ((k as f32 + 9.0 * i as f32) * 0.05).sin()
                    + rng.symmetric() as f32;
                if (k + i) % 61 == 0 {
                    f32::NAN
                } else {
                    t
                }
            });
            let times: [Option<f32>; 6] = core::array::from_fn(|i| match (k + 2 * i) % 7 {
                0 => None,
                1 => Some(f32::NAN),
                x => Some(x as f32 * 15.0),
            });
            let ambient = if k == 100 { f32::NAN } else { 20.0 };
            let a = whole.tick(&cfg, &temps, ambient, &times, &mut events_whole);
            let b = parts
                .tick_part(&cfg, &temps, ambient, &times, &mut events_parts, 0..2)
                .union(parts.tick_part(&cfg, &temps, f32::NAN, &times, &mut events_parts, 2..5))
                .union(parts.tick_part(&cfg, &temps, f32::NAN, &times, &mut events_parts, 5..9));
            assert_eq!(a, b, "tick {k}");
            assert_eq!(whole, parts, "tick {k}");
            while let Some(e) = events_whole.pop() {
                assert_eq!(Some(e), events_parts.pop(), "tick {k}");
            }
            assert!(events_parts.is_empty());
        }
    }

    #[test]
    fn debounce_delays_raise_exactly_f32_f64_q32() {
        debounce_delays_raise_exactly::<f32>();
        debounce_delays_raise_exactly::<f64>();
        debounce_delays_raise_exactly::<Q32>();
    }

    #[test]
    fn noise_below_half_hysteresis_cannot_toggle() {
        // Noise of peak 0.45 * hysteresis on a signal that sits exactly on
        // the warning level: at most one raise, never a clear.
        let cfg = config::<f64, 1>(10);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<4096>::new();
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for _ in 0..100_000 {
            step(
                &mut state,
                &cfg,
                WARNING + 0.45 * HYST * rng.symmetric(),
                &mut events,
            );
        }
        assert!(state.elements()[0].warning());
        assert!(!events.overflowed());
        let mut raised = 0;
        let mut cleared = 0;
        while let Some(e) = events.pop() {
            raised += usize::from(e.kind == EventKind::WarningRaised);
            cleared += usize::from(e.kind == EventKind::WarningCleared);
        }
        assert_eq!((raised, cleared), (1, 0));
    }

    #[test]
    fn toggles_only_on_real_crossings_of_the_band() {
        // A slow sine from WARNING - 3 HYST to WARNING + 3 HYST with noise of
        // peak 0.45 HYST: the true signal crosses the whole band 20 times up
        // and 20 times down, and the alarm toggles exactly that often.
        let cfg = config::<f32, 1>(20);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<4096>::new();
        let mut rng = Rng(42);
        let period = 5_000.0;
        for t in 0..100_000 {
            let phase = core::f64::consts::TAU * f64::from(t) / period;
            let temp = WARNING - 3.0 * HYST * phase.cos() + 0.45 * HYST * rng.symmetric();
            step(&mut state, &cfg, temp, &mut events);
        }
        let mut raised = 0;
        let mut cleared = 0;
        while let Some(e) = events.pop() {
            raised += usize::from(e.kind == EventKind::WarningRaised);
            cleared += usize::from(e.kind == EventKind::WarningCleared);
        }
        assert_eq!((raised, cleared), (20, 20));
    }

    #[test]
    fn noise_does_not_defer_a_real_crossing() {
        // 80 % of the samples above the level: the up/down counter raises
        // after about debounce / (2 * 0.8 - 1) = 83 ticks. A counter reset
        // by every contrary sample (the reference below) would need 50 in a
        // row, probability 0.8^50 = 1.4e-5 per try.
        let debounce = 50;
        let cfg = config::<f64, 1>(debounce);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<8>::new();
        let mut rng = Rng(7);
        let mut consecutive = 0u16;
        let mut naive_raised = false;
        let mut raised_at = None;
        for t in 1..=300 {
            // Uniform noise of peak A around WARNING + 0.6 A: P(above) = 0.8.
            let temp = WARNING + 0.6 + rng.symmetric();
            consecutive = if temp > WARNING { consecutive + 1 } else { 0 };
            naive_raised |= consecutive >= debounce;
            if step(&mut state, &cfg, temp, &mut events).warning && raised_at.is_none() {
                raised_at = Some(t);
            }
        }
        let raised_at = raised_at.expect("noise deferred the raise");
        assert!((50..=200).contains(&raised_at), "{raised_at}");
        assert!(!naive_raised, "the reference should have been deferred");
    }

    #[test]
    fn steady_crossing_raises_within_debounce_whatever_came_before() {
        let debounce = 25;
        let cfg = config::<f64, 1>(debounce);
        for seed in 1..50 {
            let mut state = AlarmState::new(&cfg);
            let mut events = EventQueue::<8>::new();
            let mut rng = Rng(seed);
            let history = 1 + rng.next_u64() % 500;
            for _ in 0..history {
                // Noise entirely around the level, never a clean run.
                let temp = WARNING + 0.5 * rng.symmetric();
                if step(&mut state, &cfg, temp, &mut events).warning {
                    break;
                }
            }
            if state.elements()[0].warning() {
                continue;
            }
            let mut ticks = 0;
            while !step(&mut state, &cfg, WARNING + 0.1, &mut events).warning {
                ticks += 1;
                assert!(ticks < debounce, "seed {seed}");
            }
        }
    }

    #[test]
    fn shutdown_latches_and_reset_needs_cool_settled_elements() {
        let cfg = config::<f64, 2>(5);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<64>::new();
        fn run(
            state: &mut AlarmState<f64, Const<2>>,
            cfg: &AlarmConfig<f64, Const<2>>,
            events: &mut EventQueue<64>,
            temps: [f64; 2],
            ticks: usize,
        ) -> AlarmStatus {
            let mut status = AlarmStatus::default();
            for _ in 0..ticks {
                status = state.tick(cfg, &temps, 20.0, &[None; 2], events);
            }
            status
        }
        // Element 1 goes over the limit for 4 ticks: not yet.
        assert!(!run(&mut state, &cfg, &mut events, [30.0, LIMIT + 0.5], 4).shutdown);
        assert!(run(&mut state, &cfg, &mut events, [30.0, LIMIT + 0.5], 1).shutdown);
        // Cooling below the limit but inside the hysteresis: still latched,
        // and a reset is refused.
        assert!(
            run(
                &mut state,
                &cfg,
                &mut events,
                [30.0, LIMIT - HYST + 0.1],
                100
            )
            .shutdown
        );
        assert_eq!(
            state.reset(&cfg, &mut events),
            Err(ResetError::TooHot { element: 1 })
        );
        // Below the reset threshold for 4 ticks: not settled yet.
        assert!(run(&mut state, &cfg, &mut events, [30.0, LIMIT - HYST - 0.1], 4).shutdown);
        assert_eq!(
            state.reset(&cfg, &mut events),
            Err(ResetError::NotSettled { element: 1 })
        );
        // The other element being hot blocks it too.
        run(
            &mut state,
            &cfg,
            &mut events,
            [LIMIT - 1.0, LIMIT - HYST - 0.1],
            1,
        );
        assert_eq!(
            state.reset(&cfg, &mut events),
            Err(ResetError::TooHot { element: 0 })
        );
        // Cold and long enough, even far below ambient: still latched until
        // the reset.
        assert!(run(&mut state, &cfg, &mut events, [30.0, 0.0], 1000).shutdown);
        assert!(state.shutdown_latched());
        assert_eq!(state.reset(&cfg, &mut events), Ok(()));
        assert!(!state.shutdown_latched());
        let mut kinds = [0usize; 2];
        let mut reset_event = None;
        while let Some(e) = events.pop() {
            kinds[0] += usize::from(e.kind == EventKind::ShutdownLatched && e.element == Some(1));
            if e.kind == EventKind::Reset {
                reset_event = Some(e);
            }
            kinds[1] += usize::from(e.kind == EventKind::ShutdownLatched);
        }
        assert_eq!(kinds, [1, 1]);
        assert_eq!(reset_event.unwrap().element, None);
        assert_eq!(reset_event.unwrap().tick, state.tick_count());
        // Nothing latched: a reset is a no-op success without an event.
        assert_eq!(state.reset(&cfg, &mut events), Ok(()));
        assert!(events.is_empty());
    }

    #[test]
    fn invalid_temperatures_never_clear_and_never_panic() {
        let cfg = config::<f32, 1>(3);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<4096>::new();
        // Raise the warning and latch the shutdown.
        for _ in 0..3 {
            step(&mut state, &cfg, LIMIT + 1.0, &mut events);
        }
        assert!(state.elements()[0].warning() && state.shutdown_latched());
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for _ in 0..1000 {
                let status = step(&mut state, &cfg, bad, &mut events);
                assert!(status.sensor_invalid && status.warning && status.shutdown);
            }
            assert_eq!(
                state.reset(&cfg, &mut events),
                Err(ResetError::SensorInvalid { element: 0 })
            );
        }
        assert!(state.elements()[0].sensor_invalid());
        // One valid cool sample flags the sensor valid but clears nothing.
        step(&mut state, &cfg, 30.0, &mut events);
        assert!(!state.elements()[0].sensor_invalid());
        assert!(state.elements()[0].warning());
        // One SensorInvalid for the whole invalid run, not one per tick.
        assert_eq!(count(&mut events, EventKind::SensorInvalid), 1);
    }

    #[test]
    fn persistent_invalid_sensor_raises_warning_but_not_shutdown() {
        let cfg = config::<f64, 1>(4);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<4096>::new();
        for k in 1..=4 {
            let status = step(&mut state, &cfg, f64::NAN, &mut events);
            assert_eq!(status.warning, k == 4);
        }
        for _ in 0..1000 {
            assert!(!step(&mut state, &cfg, f64::NAN, &mut events).shutdown);
        }
        let first = events.pop().unwrap();
        assert_eq!((first.kind, first.tick), (EventKind::SensorInvalid, 1));
        assert_eq!(events.pop().unwrap().kind, EventKind::WarningRaised);
        assert!(events.is_empty(), "one event per change, not per tick");
    }

    #[test]
    fn nan_does_not_reset_progress_towards_a_shutdown() {
        // Interleaved NaNs neither count nor cancel: 5 hot samples latch.
        let cfg = config::<f64, 1>(5);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<64>::new();
        for k in 1..=5 {
            assert!(!step(&mut state, &cfg, f64::NAN, &mut events).shutdown);
            let status = step(&mut state, &cfg, LIMIT + 1.0, &mut events);
            assert_eq!(status.shutdown, k == 5);
        }
    }

    #[test]
    fn levels_follow_the_ambient_and_invalid_ambient_holds() {
        let cfg = config::<f64, 1>(1);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<64>::new();
        // At 30 degC ambient the limit is 30 + 70 * 0.567 = 69.69, warning 64.69.
        let hot = [63.0];
        assert!(!state.tick(&cfg, &hot, 30.0, &[None], &mut events).warning);
        assert!((cfg.alarm_limits_c(30.0)[0] - 69.69).abs() < 1e-9);
        assert_eq!(cfg.alarm_limit_c(1, 30.0), None);
        // A NaN ambient keeps 30 degC, not 20 (where 63 would warn) and not
        // the critical temperature.
        let status = state.tick(&cfg, &hot, f64::NAN, &[None], &mut events);
        assert!(status.ambient_invalid && !status.warning);
        assert_eq!(state.ambient_c(), 30.0);
        // Back to 20 degC: 63 > 60.36 warns.
        let status = state.tick(&cfg, &hot, 20.0, &[None], &mut events);
        assert!(status.warning && !status.ambient_invalid);
        let kinds = [
            events.pop().unwrap().kind,
            events.pop().unwrap().kind,
            events.pop().unwrap().kind,
        ];
        assert_eq!(
            kinds,
            [
                EventKind::SensorInvalid,
                EventKind::SensorValid,
                EventKind::WarningRaised
            ]
        );
    }

    #[test]
    fn invalid_ambient_blocks_reset() {
        let cfg = config::<f64, 1>(1);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<64>::new();
        state.tick(&cfg, &[LIMIT + 1.0], 20.0, &[None], &mut events);
        state.tick(&cfg, &[30.0], f64::NAN, &[None], &mut events);
        assert_eq!(
            state.reset(&cfg, &mut events),
            Err(ResetError::AmbientInvalid)
        );
        state.tick(&cfg, &[30.0], 20.0, &[None], &mut events);
        assert_eq!(state.reset(&cfg, &mut events), Ok(()));
    }

    fn predictive_alarm<S: Scalar>() {
        // Horizon 30 s, clears above 35 s, debounce 3.
        let cfg = config::<S, 2>(3);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<64>::new();
        let temps = [S::from_f64(30.0); 2];
        let ambient = S::from_f64(20.0);
        let mut run = |state: &mut AlarmState<S, Const<2>>, times: [Option<f64>; 2], n: usize| {
            let times = times.map(|t| t.map(S::from_f64));
            let mut status = AlarmStatus::default();
            for _ in 0..n {
                status = state.tick(&cfg, &temps, ambient, &times, &mut events);
            }
            status
        };
        assert!(!run(&mut state, [Some(29.0), None], 2).predictive);
        assert!(run(&mut state, [Some(29.0), None], 1).predictive);
        assert!(state.elements()[0].predictive() && !state.elements()[1].predictive());
        // Inside the time hysteresis: holds.
        assert!(run(&mut state, [Some(33.0), Some(1e9)], 100).predictive);
        // "Never": clears after the debounce.
        assert!(run(&mut state, [None, None], 2).predictive);
        assert!(!run(&mut state, [None, None], 1).predictive);
        // Already past the limit (negative time) raises.
        assert!(run(&mut state, [None, Some(-1.0)], 3).predictive);
        assert!(state.elements()[1].predictive());
        // The temperature alarms were never touched.
        assert!(!state.elements()[0].warning() && !state.shutdown_latched());
    }

    #[test]
    fn predictive_alarm_f32_f64_q32() {
        predictive_alarm::<f32>();
        predictive_alarm::<f64>();
        predictive_alarm::<Q32>();
    }

    #[test]
    fn nan_prediction_counts_towards_raising() {
        let cfg = config::<f32, 1>(2);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<8>::new();
        let temps = [30.0];
        assert!(
            !state
                .tick(&cfg, &temps, 20.0, &[Some(f32::NAN)], &mut events)
                .predictive
        );
        assert!(
            state
                .tick(&cfg, &temps, 20.0, &[Some(f32::NAN)], &mut events)
                .predictive
        );
        for _ in 0..100 {
            assert!(
                state
                    .tick(&cfg, &temps, 20.0, &[Some(f32::NAN)], &mut events)
                    .predictive
            );
        }
        // +inf is "never".
        state.tick(&cfg, &temps, 20.0, &[Some(f32::INFINITY)], &mut events);
        assert!(
            !state
                .tick(&cfg, &temps, 20.0, &[Some(f32::INFINITY)], &mut events)
                .predictive
        );
    }

    #[test]
    fn event_overflow_loses_nothing_silently() {
        // 30 warning cycles, each exactly one raise and one clear, into a
        // queue of 8 that is never drained: 8 delivered + 52 counted = 60.
        let cfg = config::<f64, 1>(1);
        let mut state = AlarmState::new(&cfg);
        let mut events = EventQueue::<8>::new();
        let cycles = 30;
        let mut last = AlarmStatus::default();
        for _ in 0..cycles {
            step(&mut state, &cfg, WARNING + 1.0, &mut events);
            last = step(&mut state, &cfg, WARNING - HYST - 1.0, &mut events);
        }
        assert!(last.events_dropped);
        let mut delivered = 0;
        let mut expected_kind = EventKind::WarningRaised;
        while let Some(e) = events.pop() {
            assert_eq!(e.kind, expected_kind, "the oldest events survive in order");
            expected_kind = if expected_kind == EventKind::WarningRaised {
                EventKind::WarningCleared
            } else {
                EventKind::WarningRaised
            };
            delivered += 1;
        }
        assert_eq!(delivered, 8);
        assert_eq!(delivered + events.dropped(), 2 * cycles);
    }

    #[test]
    fn builder_rejects_bad_parameters() {
        let rule = DeratingRule::hppa();
        let base = AlarmBuilder::new(&rule, [100.0; 3]);
        let err = |b: AlarmBuilder<Const<3>>| b.build::<f64>().unwrap_err();
        let name = |name| BuildError::InvalidParameter { name };
        assert_eq!(
            err(AlarmBuilder::new(&rule, [100.0, f64::NAN, 100.0])),
            name("critical_c")
        );
        assert_eq!(
            err(base.clone().warning_margin_k(-1.0)),
            name("warning_margin_k")
        );
        assert_eq!(
            err(base.clone().hysteresis_k(f64::INFINITY)),
            name("hysteresis_k")
        );
        assert_eq!(err(base.clone().debounce_ticks(0)), name("debounce_ticks"));
        assert_eq!(err(base.clone().horizon_s(f64::NAN)), name("horizon_s"));
        assert_eq!(
            err(base.clone().horizon_hysteresis_s(-0.5)),
            name("horizon_hysteresis_s")
        );
        assert_eq!(
            err(base.clone().nominal_ambient_c(f64::NAN)),
            name("nominal_ambient_c")
        );
        assert!(base.build::<Q32>().is_ok());
    }

    proptest! {
        /// Noise of any peak below half the hysteresis on a constant signal
        /// anywhere around the band, any debounce, any seed: the samples
        /// cannot reach both sides of the band, so at most one raise and no
        /// clear.
        #[test]
        fn hysteresis_holds_under_any_small_noise(
            seed in 1u64..u64::MAX,
            peak_fraction in 0.0f64..0.5,
            centre_c in (WARNING - HYST - 2.0)..(WARNING + 2.0),
            debounce in 1u16..40,
        ) {
            let cfg = config::<f64, 1>(debounce);
            let mut state = AlarmState::new(&cfg);
            let mut events = EventQueue::<4096>::new();
            let mut rng = Rng(seed);
            for _ in 0..2000 {
                let temp = centre_c + peak_fraction * HYST * rng.symmetric();
                step(&mut state, &cfg, temp, &mut events);
            }
            let (mut raised, mut cleared) = (0, 0);
            while let Some(e) = events.pop() {
                raised += usize::from(e.kind == EventKind::WarningRaised);
                cleared += usize::from(e.kind == EventKind::WarningCleared);
            }
            prop_assert!(raised <= 1);
            prop_assert_eq!(cleared, 0);
        }
    }
}
