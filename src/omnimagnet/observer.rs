//! The Omnimagnet thermal observer: the 16-node linearised model in a Kalman
//! filter ([`crate::filter`]) with the six embedded thermocouples, predicting
//! every control tick and correcting whenever samples arrive.
//!
//! # State, inputs, measurements
//!
//! | | size | content |
//! |---|---|---|
//! | state `x` | 19 | the 16 element temperatures as deviations from the operating point \[K\], then one heat-input bias per solenoid \[W\] |
//! | input `u` | 5 | Joule power of each solenoid \[W\], ambient \[degC\], 1 (the constant term) |
//! | readings | 6 | the thermocouples, two per solenoid ([`THERMOCOUPLE_NODES`]) \[degC\] |
//!
//! **Powers, not the paper's `U = I^2`.** The input is `p = R(T) I^2` with
//! `R(T)` (Eq. A3) evaluated every tick at the *estimated* solenoid
//! temperature. The paper's `U = I^2` form freezes `R` at the operating point,
//! so between re-linearisations (5 K apart by default) the Joule power would
//! be wrong by up to `alpha0 * 5 K` = 2 %, and by 20 % over a 50 K rise
//! without re-linearisation. Using the estimate (not a measurement) keeps the
//! input defined on every tick, also when all thermocouples are missing.
//!
//! **Deviation coordinates.** The filter works on `T - T_op` (the
//! linearisation's operating point) and the thermocouples are shifted the same
//! way. The temperatures then stay within a few kelvin of zero, so `f32`
//! keeps about five more bits of each 1 ms increment (a 1 ms step changes a
//! solenoid by about 1e-4 K; `f32` resolves 8e-6 K near 100 degC but 5e-7 K
//! near 5 K). The shift enters the constant input column:
//! `T_op + dx' = Ad (T_op + dx) + ...` gives `dx' = Ad dx + ... + (Ad - I) T_op`.
//!
//! **Heat-input bias (state augmentation).** The filter's model is not the
//! device: capacities, conductances, `h` and `R0` are uncertain (the paper's
//! fitted factors alone move temperatures by tens of kelvin). A constant error
//! in a solenoid's heat balance (its `R0`, or the conductances around it)
//! would leave a steady offset between the model and that solenoid's
//! thermocouples, which a filter with white process noise only partly
//! removes and spreads into the unmeasured neighbours. Each solenoid
//! therefore has a bias `b_m` \[W\] added to its Joule power, a random walk
//! (`b' = b + w_b`), so `F = [Ad, Bd_p; 0, I]` and the bias column is the
//! power column. Three biases are observable from the three solenoid
//! temperatures (see [`ObserverConfig::observability`]); more parameter
//! states (a loss-factor per element, an `h` scale) are not: at a steady
//! state the thermocouples give three numbers.
//!
//! # Process noise
//!
//! `Q = diag(q_T dt, q_b dt)`: each element's temperature diffuses at
//! [`ObserverSettings::node_noise_k2_per_s`] (model error in its heat
//! balance, white), each bias at [`ObserverSettings::bias_noise_w2_per_s`]
//! (slow drift of the heat-balance error as the device heats). The
//! first-order form `Q_c dt` is exact to `O(dt^2)`; at 1 ms it is exact for
//! every practical purpose.
//!
//! # What the thermocouples cannot see
//!
//! No sensor sits on an unmeasured element and none of them has a heat
//! source, so at a steady state its temperature is fixed by the conductance
//! ratios of the unmeasured sub-network and the three solenoid temperatures.
//! An error in those ratios (an outer-shell `h`, the cover-to-paper contact)
//! is invisible to every estimator that uses these sensors: the tests compute
//! this bound per element ("oracle": the nominal model's unmeasured
//! elements integrated from the true start, driven by the *true* solenoid
//! temperatures) and show the filter reaches it. Under independent +-20 %
//! errors of every parameter, in the tests' 1 h runs the bound reaches
//! 1.05 K (the core, all three at 3.8 A), and it is larger at the steady
//! state of that preset, because these errors grow with the temperature
//! rise; with +-5 % errors every element stays within 0.5 K. See the
//! README for the measured figures. The reported variance
//! ([`OmnimagnetObserver::variances_k2`]) does *not* cover these errors
//! (they are not white noise; the NEES on the perturbed model is about 8800
//! for 16 states at +-20 %): a protection margin for the unmeasured
//! elements, the cover insulation above all, must come from the parameter
//! uncertainty, e.g. this bound.
//!
//! # Gain modes
//!
//! * [`GainMode::SteadyState`] (default): [`MeanModel::predict`] every
//!   tick (the mean predict of `F`'s structure, 16 x 16 + 16 x 5
//!   multiply-adds) and [`update_steady`] per correction,
//!   with the gain solved at build time for one correction every
//!   `period = correction_period_s / dt` predicts (the thermocouples' 2 Hz).
//!   A correction with a sensor missing, rejected, faulted or disabled uses
//!   the optimal update of that subset from the stored steady prior
//!   (`O(N P + P^3)` from the stored `M H^T` and `S`, see [`crate::filter`]).
//! * [`GainMode::TimeVarying`]: full covariance, [`predict`] every tick and
//!   the sequential Joseph [`update`]. Exact for irregular sample times, for
//!   a model that just changed and during the start transient.
//!
//! # Following the re-linearisation
//!
//! [`OmnimagnetObserver::follow`] polls a [`Relinearizer`] (one slice per
//! call). When it swaps in a new model, [`OmnimagnetObserver::install_linearization`]
//! replaces `F` and `G` and re-bases the estimate on the new operating point
//! in the same call (`O(N^2)` plus one `O(N^3 / 6)` Cholesky of `Q` in the
//! filter's validation). The steady-state gain is *not* re-solved there: it
//! is kept (a gain for a model a few kelvin away is suboptimal, not unstable;
//! the tests measure the effect) and marked stale
//! ([`OmnimagnetObserver::gain_is_stale`]). The new gain is solved by
//! [`ObserverConfig::solve_gain`], a `&self` call that can run on a copy of
//! the configuration in a background task (bounded: at most `2 log2(period)`
//! compositions and 64 doublings; 1.1 ms on the host in f64), and
//! installed in `O(1)` by [`OmnimagnetObserver::install_gain`]. The time-
//! varying mode needs nothing: its covariance follows the new `F`.
//!
//! # Faults and the gate
//!
//! A reading that is `None` or NaN means "predict only" for that sensor; a
//! [`SensorFault`] from the driver is not fused and is reported as
//! [`ThermocoupleVerdict::Faulted`]. Every other reading is gated
//! (chi-square, 1 dof, [`ObserverSettings::gate_threshold`]) against the
//! prior; a sensor rejected [`ObserverSettings::suspect_after`] times in a
//! row is reported suspect. The default of 2 at 2 Hz flags a failure within
//! 1 s of its onset (the first bad sample arrives within 0.5 s, the second
//! 0.5 s later); 3, the filter's default, could take 1.5 s.
//!
//! # Costs and memory
//!
//! | call | work (N = 19, P = 6) |
//! |---|---|
//! | [`OmnimagnetObserver::predict`], steady | 3 `R(T)`, 336 multiply-adds ([`MeanModel::predict`]) |
//! | [`OmnimagnetObserver::predict`], time-varying | about 8.8 k multiply-adds (bias rows of `F` are unit rows) |
//! | [`OmnimagnetObserver::correct`], steady, all six fused | 6 gate tests, 228 multiply-adds |
//! | [`OmnimagnetObserver::correct`], steady, a subset | 6 gate tests, about 300 multiply-adds |
//! | [`OmnimagnetObserver::correct`], time-varying | about 12 k multiply-adds |
//!
//! Measured on the host: see the README's "Omnimagnet observer" section
//! (steady predict 0.04-0.07 us, time-varying predict 1.3-2 us, in f32).
//! [`ObserverConfig`] holds `F`, `G`, `H^T`, `Q`, the steady gain and the
//! [`MeanModel`] (at most 10 KiB in f32, checked by a test);
//! [`ObserverState`] the estimate and its covariance (at most 2 KiB in
//! f32).
//!
//! [`predict_mean`]: crate::filter::predict_mean
//! [`predict`]: crate::filter::predict
//! [`update`]: crate::filter::update
//! [`update_steady`]: crate::filter::update_steady

use nalgebra::{Const, RealField, SMatrix, SVector};

use super::data::{NODES, SOLENOIDS};
use super::linearize::Linearization;
use super::relinearize::{RelinearizePoll, Relinearizer};
use super::{measurement_matrix, Omnimagnet, THERMOCOUPLES, THERMOCOUPLE_NODES};
use crate::error::{check, BuildError};
use crate::filter::{
    self, InputStatus, KalmanConfig, KalmanState, Observability, SensorVerdict, SteadyEstimate,
    SteadyStateGain, CHI2_1DOF_999,
};
use crate::input::InputLimits;
use crate::protect::resistance_sensor::MeanTemperatureReading;
use crate::sensors::SensorFault;

/// Filter states: 16 element temperatures and 3 heat-input biases.
pub const STATES: usize = NODES + SOLENOIDS;
/// Filter inputs: 3 Joule powers \[W\], the ambient \[degC\] and 1.
pub const INPUTS: usize = SOLENOIDS + 2;

/// Relative distance of every time-varying variance from the steady-state
/// posterior below which the warm-up switches to the steady-state gain.
pub const STEADY_SWITCH_TOLERANCE: f64 = 1.0;

/// The filter configuration type the observer uses.
pub type ObserverKalman<T> = KalmanConfig<T, Const<STATES>, Const<INPUTS>, Const<THERMOCOUPLES>>;
/// The steady-state solution type the observer uses.
pub type ObserverGain<T> = SteadyStateGain<T, Const<STATES>, Const<THERMOCOUPLES>>;

/// The steady-state predict's model: the temperature rows of `F` and `G`
/// in deviation coordinates, and their origin (the operating point).
///
/// `F = [[Phi, Gamma], [0, I]]` and the biases enter like the Joule powers
/// (`Gamma` is `G`'s power columns), so the mean predict
/// `x' = F x + G u` is, for the temperatures, `Phi x_T + G (u + [b, 0, 0])`
/// and the biases stay: 16 x 16 + 16 x 5 multiply-adds instead of the
/// 19 x 19 + 19 x 5 of the general product, with the same result.
///
/// Small and `Copy` (1.4 KiB in `f32`), so a model re-linearised in a
/// background task can be handed to the control loop (for example through
/// a [`Mailbox`](crate::observer::Mailbox)) and installed in `O(N)`.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanModel<T: RealField + Copy> {
    /// `Ad - I` (dimensionless), formed in `f64`: the step is written as an
    /// increment so that its rounding can be carried (see [`Self::predict`]).
    pub(crate) phi_minus_i: SMatrix<T, NODES, NODES>,
    /// Columns: per solenoid `Bd_p` \[K/J\], `Gd` (dimensionless), then the
    /// constant term with the origin shift \[K\].
    pub(crate) g: SMatrix<T, NODES, INPUTS>,
    /// The operating point \[degC\].
    pub(crate) origin_c: SVector<T, NODES>,
    /// Step \[s\].
    pub(crate) dt_s: f64,
}

impl<T: RealField + Copy> MeanModel<T> {
    /// The model of `lin` (its step, its operating point as the origin).
    pub fn new(lin: &Linearization) -> Self {
        Self {
            phi_minus_i: (lin.discrete.ad - SMatrix::<f64, NODES, NODES>::identity()).cast(),
            g: deviation_inputs(lin).cast(),
            origin_c: SVector::from_fn(|i, _| cast(lin.op_temps_c[i])),
            dt_s: lin.discrete.dt_s,
        }
    }

    /// The operating point \[degC\]: temperatures are `origin_c + x`.
    pub fn origin_c(&self) -> &SVector<T, NODES> {
        &self.origin_c
    }

    /// The step \[s\].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// `Ad - I` (dimensionless) and the Joule-power columns of `G`
    /// \[K/W\] (for the steady response to a heat bias).
    pub(crate) fn power_response(
        &self,
    ) -> (SMatrix<T, NODES, NODES>, SMatrix<T, NODES, SOLENOIDS>) {
        (
            self.phi_minus_i,
            self.g.fixed_columns::<SOLENOIDS>(0).into_owned(),
        )
    }

    /// Every entry is finite.
    pub fn is_finite(&self) -> bool {
        let finite = |m: &[T]| m.iter().all(|v| v.is_finite());
        finite(self.phi_minus_i.as_slice())
            && finite(self.g.as_slice())
            && finite(self.origin_c.as_slice())
    }

    /// One mean-only predict of the observer state `x` (deviations \[K\],
    /// biases \[W\]) with the input `u` (powers \[W\], ambient \[degC\], 1),
    /// as an increment `(Ad - I) x + G (u + [b, 0, 0])` added to `x` with
    /// the rounding carried in `residual_k` \[K\] (one per node, kept in the
    /// state; zero to start). In `f32` a 1 ms step changes a node by about
    /// 1e-5 K, close to what a deviation of tens of kelvin resolves: without
    /// the carry most of every increment is rounded away and the estimate
    /// drifts over hours (see the network observer's "f32 without drift").
    /// A non-finite `u` drops the input term, as [`filter::predict_mean`].
    pub fn predict(
        &self,
        x: &mut SVector<T, STATES>,
        u: &SVector<T, INPUTS>,
        residual_k: &mut [T; NODES],
    ) {
        // One pass over the columns of `[Phi - I, G]` with the 16 sums in
        // registers: the order of nalgebra's `gemv` (column by column), so
        // the same result to the bit, without its copies.
        let state: &[T; STATES] = &x.data.0[0];
        let mut v: [T; INPUTS] = u.data.0[0];
        for (vm, bias) in v.iter_mut().zip(&state[NODES..]) {
            *vm += *bias;
        }
        let mut increment = [T::zero(); NODES];
        for (column, xj) in self.phi_minus_i.data.0.iter().zip(state) {
            for (inc, m) in increment.iter_mut().zip(column) {
                *inc += *m * *xj;
            }
        }
        if v.iter().all(|e| e.is_finite()) {
            for (column, vk) in self.g.data.0.iter().zip(&v) {
                for (inc, m) in increment.iter_mut().zip(column) {
                    *inc += *m * *vk;
                }
            }
        }
        for ((xi, inc), residual) in x.iter_mut().zip(&increment).zip(residual_k.iter_mut()) {
            // Fast2Sum, as `network::compensated_add` (for any float `T`).
            let corrected = *inc + *residual;
            let sum = *xi + corrected;
            *residual = corrected - (sum - *xi);
            *xi = sum;
        }
    }

    /// Moves the deviations in `x` from this model's origin to `to`'s, so
    /// that the temperatures `origin + x` are unchanged (biases untouched).
    pub fn rebase(&self, x: &mut SVector<T, STATES>, to: &Self) {
        for i in 0..NODES {
            x[i] += self.origin_c[i] - to.origin_c[i];
        }
    }
}

/// `G` of the deviation coordinates, in f64: the ZOH input matrix with the
/// shift of the origin in the constant column,
/// `T_op + dx' = Ad (T_op + dx) + ...` so `dx' = Ad dx + ... + (Ad - I) T_op`.
fn deviation_inputs(lin: &Linearization) -> SMatrix<f64, NODES, INPUTS> {
    let d = &lin.discrete;
    let op = SVector::<f64, NODES>::from_column_slice(&lin.op_temps_c);
    let mut g = d.input_matrix::<INPUTS>();
    let shift = d.ad * op - op;
    for i in 0..NODES {
        g[(i, INPUTS - 1)] += shift[i];
    }
    g
}

/// Which Kalman gain the corrections use (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GainMode {
    /// Constant gain solved for one correction every `period` predicts;
    /// mean-only predict. The cheapest per tick.
    SteadyState,
    /// Full covariance propagated every tick (time-varying Kalman filter).
    TimeVarying,
}

/// Build-time settings of the observer, in SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObserverSettings {
    /// Which thermocouples are fitted and used (order of
    /// [`THERMOCOUPLE_NODES`]); at least one.
    pub sensors: [bool; THERMOCOUPLES],
    /// Thermocouple noise standard deviation \[K\] (the paper's calibrated
    /// uncertainty: 0.1 degC).
    pub thermocouple_sigma_k: f64,
    /// Growth rate of each element's temperature variance from model error
    /// \[K^2/s\] (node order).
    pub node_noise_k2_per_s: [f64; NODES],
    /// Growth rate of each heat-input bias variance \[W^2/s\].
    pub bias_noise_w2_per_s: f64,
    /// Initial standard deviation of the error *common* to all elements
    /// \[K\] (fully correlated part of the initial covariance).
    pub initial_common_sigma_k: f64,
    /// Initial standard deviation of each element's own error \[K\]
    /// (independent part).
    pub initial_sigma_k: f64,
    /// Initial standard deviation of every heat-input bias \[W\].
    pub initial_bias_sigma_w: f64,
    /// Time between thermocouple samples \[s\]: the steady-state gain is
    /// solved for one correction every `round(correction_period_s / dt)`
    /// predicts.
    pub correction_period_s: f64,
    /// Gate threshold on `nu^2 / S` (chi-square, 1 dof; `+inf` disables).
    pub gate_threshold: f64,
    /// Consecutive rejections before a sensor is reported suspect (0: never).
    pub suspect_after: u16,
    /// Consecutive all-rejected corrections before the covariance is
    /// inflated (0: never); see [`crate::filter`], "Recovery".
    pub recover_after: u16,
    /// Gain mode after the warm-up.
    pub mode: GainMode,
    /// Least number of corrections run with the time-varying filter before
    /// switching to `mode` (0: start in `mode`); the switch waits further
    /// until the covariance has converged ([`STEADY_SWITCH_TOLERANCE`]).
    /// The start covariance is not the steady-state one, and only the
    /// time-varying filter uses it.
    pub warmup_corrections: u32,
}

impl ObserverSettings {
    /// The defaults: all six thermocouples at 0.1 degC and 2 Hz, the gate at
    /// [`CHI2_1DOF_999`], suspect after 2 rejections, and the process noise
    /// tuned on the perturbed-model tests (see the README).
    pub const DEFAULT: Self = Self {
        sensors: [true; THERMOCOUPLES],
        thermocouple_sigma_k: 0.1,
        node_noise_k2_per_s: [1e-4; NODES],
        bias_noise_w2_per_s: 1e-3,
        initial_common_sigma_k: 10.0,
        initial_sigma_k: 1.0,
        initial_bias_sigma_w: 5.0,
        correction_period_s: 0.5,
        gate_threshold: CHI2_1DOF_999,
        suspect_after: 2,
        recover_after: 5,
        mode: GainMode::SteadyState,
        warmup_corrections: 120,
    };

    /// The defaults with another sensor subset.
    pub const fn with_sensors(sensors: [bool; THERMOCOUPLES]) -> Self {
        let mut s = Self::DEFAULT;
        s.sensors = sensors;
        s
    }
}

impl Default for ObserverSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What a correction did with one thermocouple.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ThermocoupleVerdict {
    /// Not in the configured sensor subset.
    Disabled,
    /// No sample, or a NaN/infinite one: predict only.
    Missing,
    /// The driver reported a fault: not fused.
    Faulted(SensorFault),
    /// Passed the gate and fused (`nis`: normalised innovation squared).
    Fused {
        /// `nu^2 / S` (dimensionless).
        nis: f32,
    },
    /// Failed the gate and not fused.
    Rejected {
        /// `nu^2 / S` (dimensionless; infinite if it overflowed).
        nis: f32,
    },
}

/// The outcome of one correction.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CorrectionReport {
    /// One verdict per thermocouple.
    pub verdicts: [ThermocoupleVerdict; THERMOCOUPLES],
    /// Thermocouples rejected `suspect_after` times in a row by the gate
    /// (open, shorted, jumped or stuck without a fault bit).
    pub suspect: [bool; THERMOCOUPLES],
    /// The covariance was inflated because every reading was rejected for
    /// `recover_after` corrections.
    pub recovered: bool,
}

impl CorrectionReport {
    /// Number of fused readings.
    pub fn fused(&self) -> usize {
        self.verdicts
            .iter()
            .filter(|v| matches!(v, ThermocoupleVerdict::Fused { .. }))
            .count()
    }

    /// A thermocouple that is suspect or reported a driver fault in this
    /// correction: its readings are not being used.
    pub fn flagged(&self, sensor: usize) -> bool {
        self.suspect.get(sensor).copied().unwrap_or(false)
            || matches!(
                self.verdicts.get(sensor),
                Some(ThermocoupleVerdict::Faulted(_))
            )
    }
}

/// The model, filter and gain of one observer: built and validated once,
/// replaced only by [`OmnimagnetObserver::install_linearization`] and
/// [`OmnimagnetObserver::install_gain`].
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, PartialEq)]
pub struct ObserverConfig<T: RealField + Copy> {
    pub(crate) settings: ObserverSettings,
    pub(crate) kalman: ObserverKalman<T>,
    pub(crate) gain: ObserverGain<T>,
    /// The steady-state predict's model, whose origin is the operating point
    /// of the linearisation.
    pub(crate) model: MeanModel<T>,
    /// `R(T) = r_at_0c + slope T` of each solenoid \[ohm, ohm/K\].
    pub(crate) resistance: [(T, T); SOLENOIDS],
    pub(crate) solenoid_nodes: [usize; SOLENOIDS],
    pub(crate) period: u32,
    pub(crate) dt_s: f64,
    pub(crate) gain_stale: bool,
}

/// Per-device state: the estimate, its covariance (time-varying mode) and
/// the gate memory.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObserverState<T: RealField + Copy> {
    /// The filter state (deviations from the operating point \[K\], biases
    /// \[W\]), its covariance and the gate counters.
    pub filter: KalmanState<T, Const<STATES>, Const<THERMOCOUPLES>>,
    /// Gain mode in use.
    pub mode: GainMode,
    /// The last finite input `u` (held when a tick's inputs are not finite).
    pub last_input: SVector<T, INPUTS>,
    /// Corrections so far (saturating).
    pub corrections: u32,
    /// A virtual reading ([`OmnimagnetObserver::correct_winding`]) has been
    /// fused: the observer stays time-varying.
    pub virtual_readings: bool,
    /// What each node's deviation could not hold in the steady-state
    /// predict \[K\] (see [`MeanModel::predict`]).
    pub residual_k: [T; NODES],
}

/// The Omnimagnet observer: configuration and state of one device.
#[derive(Debug, Clone, PartialEq)]
pub struct OmnimagnetObserver<T: RealField + Copy> {
    config: ObserverConfig<T>,
    state: ObserverState<T>,
}

fn cast<T: RealField + Copy>(v: f64) -> T {
    nalgebra::convert(v)
}

impl ObserverSettings {
    fn validate(&self) -> Result<(), BuildError> {
        let pos = |v: f64| v.is_finite() && v > 0.0;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        check(self.sensors.iter().any(|s| *s), "sensors")?;
        check(pos(self.thermocouple_sigma_k), "thermocouple_sigma_k")?;
        check(
            self.node_noise_k2_per_s.iter().all(|v| nonneg(*v)),
            "node_noise_k2_per_s",
        )?;
        check(nonneg(self.bias_noise_w2_per_s), "bias_noise_w2_per_s")?;
        check(
            nonneg(self.initial_common_sigma_k),
            "initial_common_sigma_k",
        )?;
        check(pos(self.initial_sigma_k), "initial_sigma_k")?;
        check(nonneg(self.initial_bias_sigma_w), "initial_bias_sigma_w")?;
        check(pos(self.correction_period_s), "correction_period_s")?;
        Ok(())
    }
}

impl<T: RealField + Copy> ObserverConfig<T> {
    /// Builds the filter for `lin` (any step; 1 ms for the control loop) and
    /// solves the steady-state gain.
    pub fn new(
        model: &Omnimagnet,
        lin: &Linearization,
        settings: &ObserverSettings,
    ) -> Result<Self, BuildError> {
        settings.validate()?;
        let dt_s = lin.discrete.dt_s;
        let ratio = settings.correction_period_s / dt_s;
        check(
            ratio.is_finite() && (0.5..=f64::from(u32::MAX)).contains(&ratio),
            "correction_period_s",
        )?;
        let period = (libm::round(ratio) as u32).max(1);
        let mut resistance = [(T::zero(), T::zero()); SOLENOIDS];
        let mut solenoid_nodes = [0; SOLENOIDS];
        for ((r, node), s) in resistance
            .iter_mut()
            .zip(solenoid_nodes.iter_mut())
            .zip(&model.geometry().solenoids)
        {
            let res = s.resistance();
            *r = (cast(res.r_at_0c_ohm), cast(res.slope_ohm_per_k));
            *node = s.node;
        }
        let kalman = Self::build_kalman(lin, settings)?;
        let gain = SteadyStateGain::solve(&kalman, period)?;
        Ok(Self {
            settings: *settings,
            kalman,
            gain,
            model: MeanModel::new(lin),
            resistance,
            solenoid_nodes,
            period,
            dt_s,
            gain_stale: false,
        })
    }

    /// `F`, `G`, `H`, `Q`, `R` of the augmented model (f64, then cast).
    fn build_kalman(
        lin: &Linearization,
        settings: &ObserverSettings,
    ) -> Result<ObserverKalman<T>, BuildError> {
        let d = &lin.discrete;
        let mut f = SMatrix::<f64, STATES, STATES>::identity();
        f.fixed_view_mut::<NODES, NODES>(0, 0).copy_from(&d.ad);
        // The bias adds to the Joule power, so it enters like the power.
        f.fixed_view_mut::<NODES, SOLENOIDS>(0, NODES)
            .copy_from(&d.bd_power);
        let mut g = SMatrix::<f64, STATES, INPUTS>::zeros();
        g.fixed_view_mut::<NODES, INPUTS>(0, 0)
            .copy_from(&deviation_inputs(lin));
        let mut h = SMatrix::<f64, THERMOCOUPLES, STATES>::zeros();
        let h16 = measurement_matrix();
        for (row, on) in settings.sensors.iter().enumerate() {
            // A disabled sensor has a zero row: the Riccati solution then
            // carries none of its information and its gain column is zero.
            if *on {
                h.fixed_view_mut::<1, NODES>(row, 0)
                    .copy_from(&h16.fixed_view::<1, NODES>(row, 0));
            }
        }
        let dt = d.dt_s;
        let mut q = SMatrix::<f64, STATES, STATES>::zeros();
        for (i, v) in settings.node_noise_k2_per_s.iter().enumerate() {
            q[(i, i)] = v * dt;
        }
        for m in 0..SOLENOIDS {
            q[(NODES + m, NODES + m)] = settings.bias_noise_w2_per_s * dt;
        }
        let r = SVector::<f64, THERMOCOUPLES>::repeat(
            settings.thermocouple_sigma_k * settings.thermocouple_sigma_k,
        );
        // Recovery widens by the start uncertainty: the estimate may be as
        // far off as it was at power-up.
        let mut recovery = SVector::<T, STATES>::repeat(cast(
            settings.initial_common_sigma_k * settings.initial_common_sigma_k
                + settings.initial_sigma_k * settings.initial_sigma_k,
        ));
        for m in 0..SOLENOIDS {
            recovery[NODES + m] =
                cast(settings.initial_bias_sigma_w * settings.initial_bias_sigma_w);
        }
        KalmanConfig::new(f.cast(), g.cast(), h.cast(), q.cast(), r.cast())?
            .with_gate(cast(settings.gate_threshold))?
            .with_suspect_after(settings.suspect_after)
            .with_recovery(settings.recover_after, recovery)
    }

    /// Solves the steady-state gain for the current model: bounded (at most
    /// `2 log2(period)` compositions and 64 doublings of 19 x 19 matrices),
    /// but far beyond a 1 ms tick; run it in a background task on a copy of
    /// the configuration and hand the result to
    /// [`OmnimagnetObserver::install_gain`].
    pub fn solve_gain(&self) -> Result<ObserverGain<T>, BuildError> {
        SteadyStateGain::solve(&self.kalman, self.period)
    }

    /// The filter configuration (`F`, `G`, `H`, `Q`, `R`, gate).
    pub fn kalman(&self) -> &ObserverKalman<T> {
        &self.kalman
    }

    /// The steady-state solution in use.
    pub fn gain(&self) -> &ObserverGain<T> {
        &self.gain
    }

    /// The settings it was built with.
    pub fn settings(&self) -> &ObserverSettings {
        &self.settings
    }

    /// Predicts per correction the steady-state gain assumes.
    pub fn period(&self) -> u32 {
        self.period
    }

    /// The predict step \[s\].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The operating point \[degC\] the deviations are taken from.
    pub fn origin_c(&self) -> &SVector<T, NODES> {
        &self.model.origin_c
    }

    /// The node of each solenoid's winding.
    pub fn solenoid_nodes(&self) -> &[usize; SOLENOIDS] {
        &self.solenoid_nodes
    }

    /// The steady-state predict's model (the build-time linearisation, or
    /// the last one installed).
    pub fn model(&self) -> &MeanModel<T> {
        &self.model
    }

    /// The filter input of one step into `u`: the Joule power
    /// `R(T) I^2` \[W\] of each solenoid at its estimated temperature
    /// (`x` in deviations from `model`'s origin), the ambient \[degC\] and
    /// the constant 1. Returns `false` and leaves `u` (the last finite
    /// input) as it was when a current or the ambient is not finite.
    pub fn joule_input(
        &self,
        model: &MeanModel<T>,
        x: &SVector<T, STATES>,
        currents_a: &[T; SOLENOIDS],
        ambient_c: T,
        u: &mut SVector<T, INPUTS>,
    ) -> bool {
        if !(ambient_c.is_finite() && currents_a.iter().all(|i| i.is_finite())) {
            return false;
        }
        self.joule_input_by(model, x, currents_a, ambient_c, u, |r_ohm, current| {
            r_ohm * current * current
        });
        true
    }

    /// [`Self::joule_input`] for a step over which the currents varied:
    /// the Joule power `R(T) <I^2>` \[W\] of each solenoid from its mean
    /// square current over the step `mean_sq_a2` \[A^2\] (the exact mean
    /// power of the step for the resistance at the estimate, where the
    /// held current of one tick would sample the heating). Returns `false`
    /// and leaves `u` as it was when a mean square or the ambient is not
    /// finite.
    pub fn joule_input_mean_sq(
        &self,
        model: &MeanModel<T>,
        x: &SVector<T, STATES>,
        mean_sq_a2: &[T; SOLENOIDS],
        ambient_c: T,
        u: &mut SVector<T, INPUTS>,
    ) -> bool {
        if !(ambient_c.is_finite() && mean_sq_a2.iter().all(|i| i.is_finite())) {
            return false;
        }
        self.joule_input_by(model, x, mean_sq_a2, ambient_c, u, |r_ohm, i2| r_ohm * i2);
        true
    }

    /// The input `u` with each solenoid's power `power(R(T), per_solenoid)`.
    #[inline(always)]
    fn joule_input_by(
        &self,
        model: &MeanModel<T>,
        x: &SVector<T, STATES>,
        per_solenoid: &[T; SOLENOIDS],
        ambient_c: T,
        u: &mut SVector<T, INPUTS>,
        power: impl Fn(T, T) -> T,
    ) {
        let solenoids = per_solenoid
            .iter()
            .zip(&self.resistance)
            .zip(&self.solenoid_nodes);
        for (power_w, ((current, (r0, slope)), node)) in u.iter_mut().zip(solenoids) {
            // `get` keeps the tick free of a panic path: a node index outside
            // the model (a malformed geometry table) reads as 0 degC.
            let origin = model.origin_c.get(*node).copied().unwrap_or(T::zero());
            let deviation = x.get(*node).copied().unwrap_or(T::zero());
            // Floored at zero, NaN included (as `max`, without its call).
            let r_ohm = *r0 + *slope * (origin + deviation);
            let r_ohm = if r_ohm > T::zero() { r_ohm } else { T::zero() };
            *power_w = power(r_ohm, *current);
        }
        u[SOLENOIDS] = ambient_c;
        u[INPUTS - 1] = T::one();
    }

    /// The readings of the configured sensors as deviations from `model`'s
    /// origin (`None` for a disabled sensor, a missing reading or a fault).
    pub fn deviations(
        &self,
        model: &MeanModel<T>,
        samples_c: &[Option<Result<T, SensorFault>>; THERMOCOUPLES],
    ) -> [Option<T>; THERMOCOUPLES] {
        let mut z = [None; THERMOCOUPLES];
        for (j, (zj, s)) in z.iter_mut().zip(samples_c).enumerate() {
            if let (true, Some(Ok(v))) = (self.settings.sensors[j], s) {
                *zj = Some(*v - model.origin_c[THERMOCOUPLE_NODES[j]]);
            }
        }
        z
    }

    /// Per-element (and per-bias) observability of the augmented model from
    /// the thermocouples in `sensors` (`tol` as in
    /// [`filter::observability()`]).
    pub fn observability(
        &self,
        sensors: &[bool; THERMOCOUPLES],
        tol: T,
    ) -> Observability<T, STATES> {
        let h = SMatrix::<T, THERMOCOUPLES, STATES>::from_fn(|r, c| {
            if c == THERMOCOUPLE_NODES[r] {
                T::one()
            } else {
                T::zero()
            }
        });
        filter::observability(self.kalman.f(), &h, sensors, tol)
    }
}

/// Per-element observability of the 16-node model `lin` from the
/// thermocouples in `sensors` (no bias states), in f64.
pub fn element_observability(
    lin: &Linearization,
    sensors: &[bool; THERMOCOUPLES],
) -> Observability<f64, NODES> {
    filter::observability(&lin.discrete.ad, &measurement_matrix(), sensors, 1e-9)
}

impl<T: RealField + Copy> OmnimagnetObserver<T> {
    /// Builds the observer for `lin` with the estimate starting at
    /// `initial_temps_c` \[degC\] and zero heat-input biases.
    pub fn new(
        model: &Omnimagnet,
        lin: &Linearization,
        settings: &ObserverSettings,
        initial_temps_c: &[f64; NODES],
        ambient_c: f64,
    ) -> Result<Self, BuildError> {
        check(
            initial_temps_c.iter().all(|t| t.is_finite()),
            "initial_temps_c",
        )?;
        check(ambient_c.is_finite(), "ambient_c")?;
        let config = ObserverConfig::new(model, lin, settings)?;
        let mut x = SVector::<T, STATES>::zeros();
        for i in 0..NODES {
            x[i] = cast::<T>(initial_temps_c[i]) - config.model.origin_c[i];
        }
        let mut p0 = SMatrix::<T, STATES, STATES>::zeros();
        let common: T = cast(settings.initial_common_sigma_k * settings.initial_common_sigma_k);
        for i in 0..NODES {
            for j in 0..NODES {
                p0[(i, j)] = common;
            }
            p0[(i, i)] += cast(settings.initial_sigma_k * settings.initial_sigma_k);
        }
        for i in NODES..STATES {
            p0[(i, i)] = cast(settings.initial_bias_sigma_w * settings.initial_bias_sigma_w);
        }
        let mode = if settings.warmup_corrections > 0 {
            GainMode::TimeVarying
        } else {
            settings.mode
        };
        let mut last_input = SVector::<T, INPUTS>::zeros();
        last_input[SOLENOIDS] = cast(ambient_c);
        last_input[INPUTS - 1] = T::one();
        Ok(Self {
            state: ObserverState {
                filter: KalmanState::new(x, p0),
                mode,
                last_input,
                corrections: 0,
                virtual_readings: false,
                residual_k: [T::zero(); NODES],
            },
            config,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &ObserverConfig<T> {
        &self.config
    }

    /// The per-device state.
    pub fn state(&self) -> &ObserverState<T> {
        &self.state
    }

    /// Gain mode in use.
    pub fn mode(&self) -> GainMode {
        self.state.mode
    }

    /// Switches the gain mode. Entering the time-varying mode starts the
    /// covariance at the steady-state prior (the covariance the steady filter
    /// implicitly had).
    pub fn set_mode(&mut self, mode: GainMode) {
        if mode == GainMode::TimeVarying && self.state.mode == GainMode::SteadyState {
            self.state.filter.cov = *self.config.gain.prior();
        }
        self.state.mode = mode;
    }

    /// Estimated temperature of every element \[degC\], node order.
    pub fn temperatures_c(&self) -> [T; NODES] {
        core::array::from_fn(|i| self.config.model.origin_c[i] + self.state.filter.x[i])
    }

    /// Estimated heat-input bias of each solenoid \[W\] (what the model
    /// misses in its heat balance).
    pub fn heat_bias_w(&self) -> [T; SOLENOIDS] {
        core::array::from_fn(|m| self.state.filter.x[NODES + m])
    }

    /// Variance of every element's estimate \[K^2\]: the propagated
    /// covariance in time-varying mode, the steady-state prior (the value
    /// just before a correction, the largest) in steady-state mode.
    pub fn variances_k2(&self) -> [T; NODES] {
        let cov = match self.state.mode {
            GainMode::TimeVarying => &self.state.filter.cov,
            GainMode::SteadyState => self.config.gain.prior(),
        };
        core::array::from_fn(|i| cov[(i, i)])
    }

    /// The time-varying posterior has reached the steady-state one: every
    /// variance within [`STEADY_SWITCH_TOLERANCE`] of it (relative). Until
    /// then the steady gain would under-weight the readings for the states
    /// still uncertain and the estimate's error would exceed what the
    /// steady covariance claims. A factor of 2, not closer: the core and the
    /// inside air converge with the core's 2.5 h time constant (about
    /// 8 min to reach a factor 2, hours to 10 %), and the steady gain on
    /// them is small either way.
    fn covariance_converged(&self) -> bool {
        let post = self.config.gain.posterior();
        let cov = &self.state.filter.cov;
        let tol: T = cast(STEADY_SWITCH_TOLERANCE);
        (0..STATES).all(|i| (cov[(i, i)] - post[(i, i)]).abs() <= tol * post[(i, i)])
    }

    /// `true` after a model swap until a new gain is installed.
    pub fn gain_is_stale(&self) -> bool {
        self.config.gain_stale
    }

    /// One tick: solenoid currents \[A\] and ambient \[degC\] held over the
    /// step. The Joule power uses `R(T)` at the estimated solenoid
    /// temperatures. The input rules of [`crate::input`] at
    /// [`InputLimits::default`] apply: a current beyond +-100 A is clamped
    /// to it and used (reported as [`InputStatus::Clamped`]: a huge finite
    /// current, whose `R I^2` would overflow, heats as the clamp, never
    /// less); a non-finite current, or an ambient that is not finite or
    /// outside -60 .. 400 degC, leaves the last input in use (the powers
    /// and ambient of the last valid step, reported as
    /// [`InputStatus::Dropped`]).
    pub fn predict(&mut self, currents_a: &[T; SOLENOIDS], ambient_c: T) -> InputStatus {
        let config = &self.config;
        let state = &mut self.state;
        let limits = InputLimits::default();
        let max_a: T = cast(limits.max_current_a);
        let ambient_ok =
            ambient_c >= cast(limits.min_temp_c) && ambient_c <= cast(limits.max_temp_c);
        let mut clamped = false;
        let currents = currents_a.map(|i| {
            if i.is_finite() && i.abs() > max_a {
                clamped = true;
                if i > T::zero() {
                    max_a
                } else {
                    -max_a
                }
            } else {
                i
            }
        });
        // A NaN ambient fails `ambient_ok` as well.
        let finite = ambient_ok
            && config.joule_input(
                &config.model,
                &state.filter.x,
                &currents,
                ambient_c,
                &mut state.last_input,
            );
        match state.mode {
            GainMode::SteadyState => config.model.predict(
                &mut state.filter.x,
                &state.last_input,
                &mut state.residual_k,
            ),
            GainMode::TimeVarying => {
                filter::predict(&config.kalman, &mut state.filter, &state.last_input);
            }
        }
        if !finite {
            InputStatus::Dropped
        } else if clamped {
            InputStatus::Clamped
        } else {
            InputStatus::Used
        }
    }

    /// A correction with the readings that arrived \[degC\]: `None` (or NaN)
    /// means no sample from that thermocouple.
    pub fn correct(&mut self, readings_c: &[Option<T>; THERMOCOUPLES]) -> CorrectionReport {
        let samples = readings_c.map(|r| r.map(Ok));
        self.correct_samples(&samples)
    }

    /// A correction with the driver's results: a [`SensorFault`] is not
    /// fused and is reported as [`ThermocoupleVerdict::Faulted`].
    pub fn correct_samples(
        &mut self,
        samples_c: &[Option<Result<T, SensorFault>>; THERMOCOUPLES],
    ) -> CorrectionReport {
        let sensors = self.config.settings.sensors;
        let z = self.config.deviations(&self.config.model, samples_c);
        let report = match self.state.mode {
            GainMode::SteadyState => {
                let f = &mut self.state.filter;
                let mut est = SteadyEstimate {
                    x: f.x,
                    gate: f.gate,
                };
                let rep =
                    filter::update_steady(&self.config.kalman, &self.config.gain, &mut est, &z);
                f.x = est.x;
                f.gate = est.gate;
                rep
            }
            GainMode::TimeVarying => {
                filter::update(&self.config.kalman, &mut self.state.filter, &z)
            }
        };
        self.state.corrections = self.state.corrections.saturating_add(1);
        if self.state.mode == GainMode::TimeVarying
            && self.config.settings.mode == GainMode::SteadyState
            && !self.state.virtual_readings
            && self.state.corrections >= self.config.settings.warmup_corrections
            && self.covariance_converged()
        {
            self.state.mode = GainMode::SteadyState;
        }
        let mut out = CorrectionReport {
            verdicts: [ThermocoupleVerdict::Missing; THERMOCOUPLES],
            suspect: [false; THERMOCOUPLES],
            recovered: report.recovered,
        };
        for j in 0..THERMOCOUPLES {
            out.verdicts[j] = match (sensors[j], samples_c[j], report.verdicts[j]) {
                (false, _, _) => ThermocoupleVerdict::Disabled,
                (true, Some(Err(fault)), _) => ThermocoupleVerdict::Faulted(fault),
                (true, _, SensorVerdict::Missing) => ThermocoupleVerdict::Missing,
                (true, _, SensorVerdict::Fused { nis }) => ThermocoupleVerdict::Fused { nis },
                (true, _, SensorVerdict::Rejected { nis }) => ThermocoupleVerdict::Rejected { nis },
            };
            out.suspect[j] = sensors[j] && report.suspect[j];
        }
        out
    }

    /// Fuses solenoid `solenoid`'s mean winding temperature from its
    /// resistance (a [`MeanTemperatureReading`] from
    /// [`ResistanceSensor::read`](crate::protect::resistance_sensor::ResistanceSensor::read),
    /// built on that solenoid's `R(T)`) like a thermocouple on the solenoid,
    /// with the reading's own variance: a virtual sensor
    /// ([`crate::filter::virtual_sensor`]). Gated like the thermocouples;
    /// call it after [`Self::predict`] on a tick whose current gave a
    /// reading. A solenoid index out of range or a non-finite reading is
    /// [`SensorVerdict::Missing`] and changes nothing. It does not count as
    /// a thermocouple correction.
    ///
    /// The reading is outside the steady-state gain's design, so the first
    /// one switches the observer to the time-varying filter (covariance
    /// started at the steady prior, [`Self::set_mode`]) and it stays there
    /// ([`ObserverState::virtual_readings`]): the per-tick cost becomes the
    /// time-varying predict's.
    ///
    /// With thermocouples on some solenoids only, this makes the others'
    /// heat-input biases observable (see the README's observability table).
    pub fn correct_winding(
        &mut self,
        solenoid: usize,
        reading: &MeanTemperatureReading,
    ) -> SensorVerdict {
        let Some(&node) = self.config.solenoid_nodes.get(solenoid) else {
            return SensorVerdict::Missing;
        };
        let Some(&origin) = self.config.model.origin_c.get(node) else {
            return SensorVerdict::Missing;
        };
        let mut h = SVector::<T, STATES>::zeros();
        if let Some(hn) = h.get_mut(node) {
            *hn = T::one();
        }
        let z = cast::<T>(f64::from(reading.temp_c)) - origin;
        let r = cast::<T>(f64::from(reading.variance_k2));
        if !(z.is_finite() && r.is_finite() && r > T::zero()) {
            return SensorVerdict::Missing;
        }
        self.set_mode(GainMode::TimeVarying);
        self.state.virtual_readings = true;
        filter::update_virtual(&self.config.kalman, &mut self.state.filter, &h, z, r)
    }

    /// Replaces `F` and `G` by those of `lin` (same step) and re-bases the
    /// estimate on its operating point; the covariance is unchanged (a shift
    /// of origin). The steady-state gain is kept and marked stale (see the
    /// module docs). On error nothing changes.
    pub fn install_linearization(&mut self, lin: &Linearization) -> Result<(), BuildError> {
        if lin.discrete.dt_s != self.config.dt_s {
            return Err(BuildError::InvalidTimeStep);
        }
        let kalman = ObserverConfig::<T>::build_kalman(lin, &self.config.settings)?;
        let model = MeanModel::new(lin);
        self.config.model.rebase(&mut self.state.filter.x, &model);
        self.config.model = model;
        self.config.kalman = kalman;
        self.config.gain_stale = true;
        Ok(())
    }

    /// Installs a steady-state gain solved for the current model (from
    /// [`ObserverConfig::solve_gain`]). `O(1)`.
    pub fn install_gain(&mut self, gain: ObserverGain<T>) -> Result<(), BuildError> {
        if gain.period() != self.config.period {
            return Err(BuildError::InvalidParameter { name: "gain" });
        }
        self.config.gain = gain;
        self.config.gain_stale = false;
        Ok(())
    }

    /// One slice of `relinearizer` at the current estimate (call it from a
    /// loop slower than the tick, or once per tick: each call is one
    /// bounded slice); on [`RelinearizePoll::Swapped`] the new model is
    /// installed. `relinearizer` must produce this observer's step.
    pub fn follow(&mut self, relinearizer: &mut Relinearizer, ambient_c: f64) -> RelinearizePoll {
        let temps = self.temperatures_c();
        let temps_f64: [f64; NODES] =
            core::array::from_fn(|i| nalgebra::convert_unchecked(temps[i]));
        let poll = relinearizer.poll(&temps_f64, ambient_c);
        if poll == RelinearizePoll::Swapped {
            if let Err(e) = self.install_linearization(relinearizer.active()) {
                return RelinearizePoll::Failed(e);
            }
        }
        poll
    }
}

#[cfg(test)]
#[path = "observer_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "observer_physics_tests.rs"]
mod observer_physics_tests;
