//! What the observers' parts share: the protection as plain tables, the
//! `const` checks and copies that assemble it, and the writer that prints
//! parts as Rust.
//!
//! Each observer kept in flash ([`OmniParts`](super::omnimagnet::OmniParts),
//! [`GridParts`](super::grid::GridParts),
//! [`NetworkParts`](super::network::NetworkParts)) is read into plain
//! tables by its `parts()`, written as a Rust expression by its
//! `write_rust` (through [`Fields`] and [`Literal`] here, so every
//! generated file spells values the same way: floats as the shortest text
//! that reads back to the same bits) and assembled again by a `const fn`
//! (`from_parts`, the network's `from_assembled_parts`), which copies and
//! checks but computes nothing (see the Omnimagnet's parts).
//!
//! The filtered observers (the network's, the Omnimagnet's) share the
//! filter's, the steady-state gain's and the time-to-limit predictor's
//! tables ([`KalmanTables`], [`GainTables`], [`PredictorTables`]): each
//! with its reading (`of`), its `const` check, its `const` copy into the
//! configuration and its writer, here once.
//!
//! The alarm and the limiter are generic over the scalar: their tables
//! ([`AlarmTables`], [`LimiterTables`]) and the upper bound's rows are
//! copied into their configurations by `const fn`s that only move `Copy`
//! values, so one assembly serves every scalar.

use core::fmt::{self, Write};

use super::clock::StepClock;
use super::consistency::{Band, BiasBound, StuckTest};
pub use crate::discretize::StepTables;
use crate::error::BuildError;
use crate::filter::{GatePolicy, KalmanConfig};
use crate::protect::alarm::AlarmConfig;
use crate::protect::limiter::LimiterConfig;
use crate::protect::margin::{ElementBound, UpperBound};
use crate::protect::predict::{LimitPredictor, Winding};
use crate::scalar::Scalar;
use nalgebra::Const;

/// Horizons of the time-to-limit predictor (both filtered observers').
pub const PREDICTOR_POINTS: usize = 32;

/// The steady-state Kalman gain and covariances (see
/// [`SteadyStateGain`](crate::filter::SteadyStateGain)), `X = N + M` states, `P` sensors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GainTables<const X: usize, const P: usize> {
    /// Model steps between corrections the gain was solved for.
    pub period: u32,
    /// `K` (X x P): \[K/K\] on temperatures, \[W/K\] on biases.
    pub gain: [[f32; P]; X],
    /// Prior covariance `M` (X x X) \[K^2, K W, W^2\].
    pub prior: [[f32; X]; X],
    /// Posterior covariance (X x X).
    pub posterior: [[f32; X]; X],
    /// `S_jj` per sensor \[K^2\].
    pub innovation_var: [f32; P],
    /// `M H^T` (X x P).
    pub prior_ht: [[f32; P]; X],
    /// `S = H M H^T + R` (P x P) \[K^2\].
    pub innovation_cov: [[f32; P]; P],
}

impl<const X: usize, const P: usize> GainTables<X, P> {
    /// The tables of a solved gain (the Omnimagnet's and the network's
    /// `parts()`), row-major.
    pub(crate) fn of(gain: &crate::filter::SteadyStateGain<f32, Const<X>, Const<P>>) -> Self {
        Self {
            period: gain.period,
            gain: rows(&gain.gain),
            prior: rows(&gain.prior),
            posterior: rows(&gain.posterior),
            innovation_var: gain.innovation_var.into(),
            prior_ht: rows(&gain.prior_ht),
            innovation_cov: rows(&gain.innovation_cov),
        }
    }

    /// The gain these tables hold (a `const fn` that only moves values,
    /// for a configuration in flash).
    pub(crate) const fn gain(&self) -> crate::filter::SteadyStateGain<f32, Const<X>, Const<P>> {
        crate::filter::SteadyStateGain {
            period: self.period,
            gain: matrix(&self.gain),
            prior: matrix(&self.prior),
            posterior: matrix(&self.posterior),
            innovation_var: vector(&self.innovation_var),
            prior_ht: matrix(&self.prior_ht),
            innovation_cov: matrix(&self.innovation_cov),
        }
    }

    /// Every entry finite.
    pub(crate) const fn is_finite(&self) -> bool {
        finite_rows(&self.gain)
            && finite_rows(&self.prior)
            && finite_rows(&self.posterior)
            && finite(&self.innovation_var)
            && finite_rows(&self.prior_ht)
            && finite_rows(&self.innovation_cov)
    }
}

/// A [`KalmanConfig`] as data but for its input matrix `G` (the
/// network's is a placeholder column, the Omnimagnet's its own table):
/// `X` states, `P` sensors, rows first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KalmanTables<const X: usize, const P: usize> {
    /// The filter's `F` (dimensionless; \[K/J\] or \[K/W\] in the bias
    /// columns).
    pub f: [[f32; X]; X],
    /// `H^T` (X x P, dimensionless).
    pub ht: [[f32; P]; X],
    /// The filter's process noise `Q` per model step \[K^2, K W, W^2\].
    pub q: [[f32; X]; X],
    /// Each sensor's noise variance `R` \[K^2\].
    pub r: [f32; P],
    /// The innovation gate's threshold on `nu^2 / S` (chi-square, 1 dof;
    /// `+inf`: no gate).
    pub gate_threshold: f32,
    /// Consecutive rejections that make a sensor suspect.
    pub suspect_after: u16,
    /// Consecutive all-rejected corrections before the recovery widening.
    pub recover_after: u16,
    /// The recovery widening's variances \[K^2, W^2\].
    pub recovery_variance: [f32; X],
    /// The first of the trailing random-walk states (unit rows of `F`).
    pub walk_from: usize,
}

impl<const X: usize, const P: usize> KalmanTables<X, P> {
    /// All zero (a placeholder before a derivation fills it).
    pub(crate) const ZERO: Self = Self {
        f: [[0.0; X]; X],
        ht: [[0.0; P]; X],
        q: [[0.0; X]; X],
        r: [0.0; P],
        gate_threshold: 0.0,
        suspect_after: 0,
        recover_after: 0,
        recovery_variance: [0.0; X],
        walk_from: 0,
    };

    /// The tables of `k` (its `G` left out).
    pub(crate) fn of<const U: usize>(k: &KalmanConfig<f32, Const<X>, Const<U>, Const<P>>) -> Self {
        Self {
            f: rows(&k.f),
            ht: rows(&k.ht),
            q: rows(&k.q),
            r: k.r.into(),
            gate_threshold: k.gate.threshold,
            suspect_after: k.gate.suspect_after,
            recover_after: k.gate.recover_after,
            recovery_variance: k.recovery_variance.into(),
            walk_from: k.walk_from,
        }
    }

    /// The configuration of these tables with the input matrix `g`,
    /// copied (no checks: [`Self::is_valid`] is the callers').
    pub(crate) const fn config<const U: usize>(
        &self,
        g: nalgebra::SMatrix<f32, X, U>,
    ) -> KalmanConfig<f32, Const<X>, Const<U>, Const<P>> {
        KalmanConfig {
            f: matrix(&self.f),
            g,
            ht: matrix(&self.ht),
            q: matrix(&self.q),
            r: vector(&self.r),
            gate: GatePolicy {
                threshold: self.gate_threshold,
                suspect_after: self.suspect_after,
                recover_after: self.recover_after,
            },
            recovery_variance: vector(&self.recovery_variance),
            walk_from: self.walk_from,
            reads: crate::filter::reads_of_rows(&self.ht),
        }
    }

    /// Every entry finite (the gate's threshold may be `+inf`: no gate)
    /// and `walk_from` within the state.
    pub(crate) const fn is_valid(&self) -> bool {
        finite_rows(&self.f)
            && finite_rows(&self.ht)
            && finite_rows(&self.q)
            && finite(&self.r)
            && !self.gate_threshold.is_nan()
            && finite(&self.recovery_variance)
            && self.walk_from <= X
    }
}

/// The sensor checks' configuration as data (see
/// [`SensorChecks`](super::SensorChecks)): the consistency band, its image
/// on the `M` heat-input biases, the stuck test and silence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChecksTables<const M: usize> {
    /// The consistency band's fixed part \[K\] and its share of the rise
    /// (dimensionless).
    pub band: [f32; 2],
    /// The band's image on each heat-input bias \[W\] (`+inf`: unbounded).
    pub bias_offset_w: [f32; M],
    /// The bias bound's share of the Joule power (dimensionless).
    pub bias_fraction: f32,
    /// The stuck test's threshold \[K\].
    pub stuck_threshold_k: f32,
    /// The stuck test's tolerance for an unchanged reading \[K\].
    pub stuck_tolerance_k: f32,
    /// The stuck test's window (readings).
    pub stuck_window: u32,
    /// No reading for this long makes a sensor silent \[us\].
    pub silent_after_us: u32,
}

impl<const M: usize> ChecksTables<M> {
    /// All zero (a placeholder before a derivation fills it).
    pub(crate) const ZERO: Self = Self {
        band: [0.0; 2],
        bias_offset_w: [0.0; M],
        bias_fraction: 0.0,
        stuck_threshold_k: 0.0,
        stuck_tolerance_k: 0.0,
        stuck_window: 0,
        silent_after_us: 0,
    };

    pub(crate) fn of(
        band: &Band,
        bias_bound: &BiasBound<Const<M>>,
        stuck_test: &StuckTest,
        silent_after_us: u32,
    ) -> Self {
        Self {
            band: [band.offset_k, band.fraction],
            bias_offset_w: bias_bound.offset_w,
            bias_fraction: bias_bound.fraction,
            stuck_threshold_k: stuck_test.threshold_k,
            stuck_tolerance_k: stuck_test.tolerance_k,
            stuck_window: stuck_test.window,
            silent_after_us,
        }
    }

    pub(crate) const fn band(&self) -> Band {
        Band {
            offset_k: self.band[0],
            fraction: self.band[1],
        }
    }

    pub(crate) const fn bias_bound(&self) -> BiasBound<Const<M>> {
        BiasBound {
            offset_w: self.bias_offset_w,
            fraction: self.bias_fraction,
        }
    }

    pub(crate) const fn stuck_test(&self) -> StuckTest {
        StuckTest {
            threshold_k: self.stuck_threshold_k,
            window: self.stuck_window,
            tolerance_k: self.stuck_tolerance_k,
        }
    }

    /// The band finite, no NaN bias bound (an unbounded bias is `+inf`; a
    /// NaN would silently drop the bound), no NaN threshold (`+inf`: no
    /// stuck test) and a finite, non-negative tolerance.
    pub(crate) const fn is_valid(&self) -> bool {
        let mut m = 0;
        while m < M {
            if self.bias_offset_w[m].is_nan() {
                return false;
            }
            m += 1;
        }
        finite(&self.band)
            && self.bias_fraction.is_finite()
            && !self.stuck_threshold_k.is_nan()
            && self.stuck_tolerance_k.is_finite()
            && self.stuck_tolerance_k >= 0.0
    }
}

/// Its checks live with the other tables' (the struct is
/// [`crate::discretize::StepTables`]: the discretisation's, which its
/// integer step reads without importing the observer).
impl<const N: usize, const B: usize, const M: usize> StepTables<N, B, M> {
    /// Every entry finite.
    pub(crate) const fn is_finite(&self) -> bool {
        finite_rows(&self.phi_minus_i)
            && finite_rows(&self.bd_power)
            && finite_rows(&self.gd_boundary)
            && finite(&self.constant_k)
    }
}

/// Rows (the tables' layout) to nalgebra's column-major storage, in a
/// `const fn`.
pub(crate) const fn matrix<const R: usize, const C: usize>(
    rows: &[[f32; C]; R],
) -> nalgebra::SMatrix<f32, R, C> {
    let mut columns = [[0.0f32; R]; C];
    let mut i = 0;
    while i < R {
        let mut j = 0;
        while j < C {
            columns[j][i] = rows[i][j];
            j += 1;
        }
        i += 1;
    }
    nalgebra::SMatrix::from_array_storage(nalgebra::ArrayStorage(columns))
}

/// A column vector of `values`, in a `const fn`.
pub(crate) const fn vector<const R: usize>(values: &[f32; R]) -> nalgebra::SMatrix<f32, R, 1> {
    nalgebra::SMatrix::from_array_storage(nalgebra::ArrayStorage([*values]))
}

/// A matrix as its rows (the tables' layout).
pub(crate) fn rows<const R: usize, const C: usize>(
    m: &nalgebra::SMatrix<f32, R, C>,
) -> [[f32; C]; R] {
    core::array::from_fn(|i| core::array::from_fn(|j| m[(i, j)]))
}

/// The time-to-limit predictor's modal tables (see
/// [`crate::protect::predict`]), [`PREDICTOR_POINTS`] horizons.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PredictorTables<const N: usize, const B: usize, const M: usize> {
    /// Horizons \[s\].
    pub grid_s: [f32; PREDICTOR_POINTS],
    /// `exp(lambda_j t_k)`, row `k` for horizon `k`.
    pub decay: [[f32; N]; PREDICTOR_POINTS],
    /// Mode rates `lambda_j` \[1/s\] (negative).
    pub lambda_per_s: [f32; N],
    /// Mode shapes `V` (columns).
    pub v: [[f32; N]; N],
    /// `V^-1`.
    pub v_inv: [[f32; N]; N],
    /// Steady rise per watt of each source \[K/W\].
    pub gain_power: [[f32; M]; N],
    /// Steady temperature per degree of each boundary (dimensionless).
    pub gain_boundary: [[f32; B]; N],
    /// Steady rise from the fixed powers \[K\].
    pub offset_c: [f32; N],
    /// The node of each winding.
    pub winding_node: [usize; M],
    /// Each winding's resistance extrapolated to 0 degC \[ohm\].
    pub winding_r_at_0c_ohm: [f32; M],
    /// Each winding's `dR/dT` \[ohm/K\].
    pub winding_slope_ohm_per_k: [f32; M],
    /// Time between two predictor slices \[s\].
    pub tick_s: f32,
    /// Horizons evaluated per slice.
    pub points_per_tick: usize,
    /// The network's slowest time constant \[s\].
    pub slowest_time_constant_s: f64,
}

impl<const N: usize, const B: usize, const M: usize> PredictorTables<N, B, M> {
    /// The tables of `predictor`, the inverse of [`Self::predictor`] (the
    /// per-tick element budget is a setting, not a table).
    pub(crate) fn of(predictor: &LimitPredictor<f32, N, B, M, PREDICTOR_POINTS>) -> Self {
        Self {
            grid_s: predictor.grid_s,
            decay: predictor.decay,
            lambda_per_s: predictor.lambda_per_s,
            v: predictor.v,
            v_inv: predictor.v_inv,
            gain_power: predictor.gain_power,
            gain_boundary: predictor.gain_boundary,
            offset_c: predictor.offset_c,
            winding_node: predictor.windings.map(|w| w.node),
            winding_r_at_0c_ohm: predictor.windings.map(|w| w.r_at_0c_ohm),
            winding_slope_ohm_per_k: predictor.windings.map(|w| w.slope_ohm_per_k),
            tick_s: predictor.tick_s,
            points_per_tick: predictor.points_per_tick,
            slowest_time_constant_s: predictor.slowest_time_constant_s,
        }
    }

    /// The predictor of these tables, evaluating `elements_per_tick`
    /// elements per tick (`usize::MAX`: all). Copies, no arithmetic and no
    /// checks (the callers check): a `const fn`, so the Omnimagnet's
    /// configuration can be assembled by the compiler.
    pub(crate) const fn predictor(
        &self,
        elements_per_tick: usize,
    ) -> LimitPredictor<f32, N, B, M, PREDICTOR_POINTS> {
        let mut windings = [Winding {
            node: 0,
            r_at_0c_ohm: 0.0,
            slope_ohm_per_k: 0.0,
        }; M];
        let mut m = 0;
        while m < M {
            windings[m] = Winding {
                node: self.winding_node[m],
                r_at_0c_ohm: self.winding_r_at_0c_ohm[m],
                slope_ohm_per_k: self.winding_slope_ohm_per_k[m],
            };
            m += 1;
        }
        LimitPredictor {
            grid_s: self.grid_s,
            decay: self.decay,
            lambda_per_s: self.lambda_per_s,
            v: self.v,
            v_inv: self.v_inv,
            gain_power: self.gain_power,
            gain_boundary: self.gain_boundary,
            offset_c: self.offset_c,
            windings,
            sizes: crate::sizes::ConstSizes,
            tick_s: self.tick_s,
            points_per_tick: self.points_per_tick,
            slowest_time_constant_s: self.slowest_time_constant_s,
            elements_per_tick,
        }
    }
}

impl<const N: usize, const B: usize, const M: usize> PredictorTables<N, B, M> {
    /// The indices in range, a slice of one to all horizons (and one
    /// more: the steady state), every entry finite and a positive slice
    /// time.
    pub(crate) const fn is_valid(&self) -> bool {
        below(&self.winding_node, N)
            && self.points_per_tick >= 1
            && self.points_per_tick <= PREDICTOR_POINTS + 1
            && finite(&self.grid_s)
            && finite_rows(&self.decay)
            && finite(&self.lambda_per_s)
            && finite_rows(&self.v)
            && finite_rows(&self.v_inv)
            && finite_rows(&self.gain_power)
            && finite_rows(&self.gain_boundary)
            && finite(&self.offset_c)
            && finite(&self.winding_r_at_0c_ohm)
            && finite(&self.winding_slope_ohm_per_k)
            && self.tick_s.is_finite()
            && self.tick_s > 0.0
            && self.slowest_time_constant_s.is_finite()
    }
}

/// An [`AlarmConfig`] as data: the scalar values it holds, nothing
/// computed again.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlarmTables<S, const N: usize> {
    /// Critical temperature of each element \[degC\].
    pub critical_c: [S; N],
    /// The derating rule's product (dimensionless).
    pub derating_product: S,
    /// Warning margin below the alarm limit \[K\].
    pub warning_margin_k: S,
    /// Hysteresis of the alarm's clear \[K\].
    pub hysteresis_k: S,
    /// Alarm debounce (protection cycles).
    pub debounce_ticks: u16,
    /// Predictive alarm horizon \[s\].
    pub horizon_s: S,
    /// The horizon at which the predictive alarm clears \[s\].
    pub horizon_clear_s: S,
    /// The ambient the derating is taken at when none is measured \[degC\].
    pub nominal_ambient_c: S,
}

impl<S: Scalar, const N: usize> AlarmTables<S, N> {
    pub(crate) fn of(a: &AlarmConfig<S, Const<N>>) -> Self {
        Self {
            critical_c: a.critical_c,
            derating_product: a.product,
            warning_margin_k: a.warning_margin_k,
            hysteresis_k: a.hysteresis_k,
            debounce_ticks: a.debounce_ticks,
            horizon_s: a.horizon_s,
            horizon_clear_s: a.horizon_clear_s,
            nominal_ambient_c: a.nominal_ambient_c,
        }
    }

    /// The configuration, copied field by field.
    pub(crate) const fn config(&self) -> AlarmConfig<S, Const<N>> {
        AlarmConfig {
            critical_c: self.critical_c,
            product: self.derating_product,
            warning_margin_k: self.warning_margin_k,
            hysteresis_k: self.hysteresis_k,
            debounce_ticks: self.debounce_ticks,
            horizon_s: self.horizon_s,
            horizon_clear_s: self.horizon_clear_s,
            nominal_ambient_c: self.nominal_ambient_c,
        }
    }
}

impl<const N: usize> AlarmTables<f32, N> {
    /// Every value finite.
    pub(crate) const fn is_finite(&self) -> bool {
        finite(&self.critical_c)
            && finite(&[
                self.derating_product,
                self.warning_margin_k,
                self.hysteresis_k,
                self.horizon_s,
                self.horizon_clear_s,
                self.nominal_ambient_c,
            ])
    }
}

/// A [`LimiterConfig`] as data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimiterTables<S, const N: usize> {
    /// Each current's hardware limit \[A\].
    pub hardware_limit_a: [S; N],
    /// The taper band below the alarm limit \[K\].
    pub taper_k: S,
    /// `1 / taper_k` \[1/K\] (as the limiter holds it).
    pub taper_per_k: S,
    /// The floor of every limit \[A\].
    pub floor_a: S,
}

impl<S: Scalar, const N: usize> LimiterTables<S, N> {
    pub(crate) fn of(l: &LimiterConfig<S, Const<N>>) -> Self {
        Self {
            hardware_limit_a: l.hardware_limit_a,
            taper_k: l.taper_k,
            taper_per_k: l.taper_per_k,
            floor_a: l.floor_a,
        }
    }

    /// The configuration, copied field by field.
    pub(crate) const fn config(&self) -> LimiterConfig<S, Const<N>> {
        LimiterConfig {
            hardware_limit_a: self.hardware_limit_a,
            taper_k: self.taper_k,
            taper_per_k: self.taper_per_k,
            floor_a: self.floor_a,
        }
    }
}

impl<const N: usize> LimiterTables<f32, N> {
    /// Every value finite.
    pub(crate) const fn is_finite(&self) -> bool {
        finite(&self.hardware_limit_a) && finite(&[self.taper_k, self.taper_per_k, self.floor_a])
    }
}

/// A [`StepClock`] as data.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClockTables {
    /// Model step \[us\].
    pub step_us: u32,
    /// Catch-up bound (model steps per tick).
    pub max_steps_per_tick: u32,
    /// Ticks without elapsed time before the clock is flagged frozen.
    pub frozen_flag_ticks: u32,
    /// Ticks without elapsed time before the model is taken as lost.
    pub frozen_loss_ticks: u32,
}

impl ClockTables {
    pub(crate) fn of(c: &StepClock) -> Self {
        Self {
            step_us: c.step_us,
            max_steps_per_tick: c.max_steps_per_tick,
            frozen_flag_ticks: c.frozen_flag_ticks,
            frozen_loss_ticks: c.frozen_loss_ticks,
        }
    }

    /// The clock, copied: what [`StepClock::new`] and
    /// [`StepClock::with_frozen_limits`] refuse is refused here too, named
    /// `clock.step_us`, `clock.max_steps_per_tick`,
    /// `clock.frozen_flag_ticks` or `clock.frozen_loss_ticks`.
    pub(crate) const fn clock(&self) -> Result<StepClock, BuildError> {
        let name = if self.step_us == 0 {
            "clock.step_us"
        } else if self.max_steps_per_tick == 0 {
            "clock.max_steps_per_tick"
        } else if self.frozen_flag_ticks == 0 {
            "clock.frozen_flag_ticks"
        } else if self.frozen_loss_ticks < self.frozen_flag_ticks {
            "clock.frozen_loss_ticks"
        } else {
            return Ok(StepClock {
                step_us: self.step_us,
                max_steps_per_tick: self.max_steps_per_tick,
                frozen_flag_ticks: self.frozen_flag_ticks,
                frozen_loss_ticks: self.frozen_loss_ticks,
            });
        };
        Err(invalid(name))
    }
}

/// Each element's upper bound as a row: the share of its rise `f`
/// (dimensionless), `f / (1 + f)` and its offset \[K\].
pub(crate) fn bound_rows<S: Scalar, const N: usize>(
    bound: &UpperBound<S, Const<N>>,
) -> [[S; 3]; N] {
    bound
        .elements
        .map(|e| [e.rise_fraction, e.limit_fraction, e.offset_k])
}

/// The upper bound of [`bound_rows`]' rows, copied.
pub(crate) const fn upper_bound<S: Scalar, const N: usize>(
    rows: &[[S; 3]; N],
) -> UpperBound<S, Const<N>> {
    let mut elements = [ElementBound::<S>::ZERO; N];
    let mut i = 0;
    while i < N {
        elements[i] = ElementBound {
            rise_fraction: rows[i][0],
            limit_fraction: rows[i][1],
            offset_k: rows[i][2],
        };
        i += 1;
    }
    UpperBound { elements }
}

pub(crate) const fn finite(values: &[f32]) -> bool {
    let mut k = 0;
    while k < values.len() {
        if !values[k].is_finite() {
            return false;
        }
        k += 1;
    }
    true
}

pub(crate) const fn finite_rows<const C: usize>(rows: &[[f32; C]]) -> bool {
    finite(rows.as_flattened())
}

pub(crate) const fn below(indices: &[usize], n: usize) -> bool {
    let mut k = 0;
    while k < indices.len() {
        if indices[k] >= n {
            return false;
        }
        k += 1;
    }
    true
}

pub(crate) const fn invalid(name: &'static str) -> BuildError {
    BuildError::InvalidParameter { name }
}

/// A value written as Rust source that reads back to the same bits.
pub(crate) trait Literal {
    fn write(&self, out: &mut dyn Write) -> fmt::Result;
}

macro_rules! float_literal {
    ($t:ident) => {
        impl Literal for $t {
            fn write(&self, out: &mut dyn Write) -> fmt::Result {
                // `{:?}` is the shortest text that reads back to the same
                // bits; it spells the non-finite values in no Rust syntax.
                if self.is_nan() {
                    write!(out, "{}::NAN", stringify!($t))
                } else if self.is_infinite() {
                    let sign = if *self > 0.0 { "" } else { "NEG_" };
                    write!(out, "{}::{sign}INFINITY", stringify!($t))
                } else {
                    write!(out, "{self:?}")
                }
            }
        }
    };
}
float_literal!(f32);
float_literal!(f64);

macro_rules! debug_literal {
    ($($t:ty),*) => {$(
        impl Literal for $t {
            fn write(&self, out: &mut dyn Write) -> fmt::Result {
                write!(out, "{self:?}")
            }
        }
    )*};
}
debug_literal!(u8, u16, u32, usize, bool);

impl Literal for crate::scalar::Q32 {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        write!(out, "coil_thermal::Q32::from_bits({})", self.to_bits())
    }
}

impl<T: Literal> Literal for Option<T> {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        match self {
            Some(v) => {
                out.write_str("Some(")?;
                v.write(out)?;
                out.write_char(')')
            }
            None => out.write_str("None"),
        }
    }
}

impl<T: Literal, const N: usize> Literal for [T; N] {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        out.write_char('[')?;
        for (k, v) in self.iter().enumerate() {
            if k > 0 {
                out.write_str(", ")?;
            }
            v.write(out)?;
        }
        out.write_char(']')
    }
}

/// Writes a struct expression: `path {`, one `name: value,` per line,
/// `}`; a table (an array of rows) one row per line.
pub(crate) struct Fields<'a> {
    out: &'a mut dyn Write,
    indent: usize,
}

impl<'a> Fields<'a> {
    /// `path` is `module::Type`, written after `coil_thermal::`.
    pub(crate) fn open(
        out: &'a mut dyn Write,
        path: &str,
        indent: usize,
    ) -> Result<Self, fmt::Error> {
        writeln!(out, "coil_thermal::{path} {{")?;
        Ok(Self { out, indent })
    }

    fn pad(&mut self, extra: usize) -> fmt::Result {
        write!(self.out, "{:1$}", "", 4 * (self.indent + extra))
    }

    pub(crate) fn field(&mut self, name: &str, value: &dyn Literal) -> fmt::Result {
        self.pad(1)?;
        write!(self.out, "{name}: ")?;
        value.write(self.out)?;
        self.out.write_str(",\n")
    }

    pub(crate) fn table<T: Literal>(&mut self, name: &str, rows: &[T]) -> fmt::Result {
        self.rows(name, "[", rows, "]")
    }

    /// A table that may be absent: `None` or `Some([..])`, one row per line.
    pub(crate) fn optional_table<T: Literal>(
        &mut self,
        name: &str,
        rows: Option<&[T]>,
    ) -> fmt::Result {
        match rows {
            Some(rows) => self.rows(name, "Some([", rows, "])"),
            None => {
                self.pad(1)?;
                writeln!(self.out, "{name}: None,")
            }
        }
    }

    fn rows<T: Literal>(&mut self, name: &str, open: &str, rows: &[T], close: &str) -> fmt::Result {
        self.pad(1)?;
        writeln!(self.out, "{name}: {open}")?;
        for row in rows {
            self.pad(2)?;
            row.write(self.out)?;
            self.out.write_str(",\n")?;
        }
        self.pad(1)?;
        writeln!(self.out, "{close},")
    }

    /// A nested struct expression as the value of `name`.
    pub(crate) fn nested(&mut self, name: &str, path: &str) -> Result<Fields<'_>, fmt::Error> {
        self.pad(1)?;
        write!(self.out, "{name}: ")?;
        Fields::open(&mut *self.out, path, self.indent + 1)
    }

    pub(crate) fn close(mut self, last: bool) -> fmt::Result {
        self.pad(0)?;
        self.out.write_str(if last { "}" } else { "},\n" })
    }
}

/// Writes `a` as the field `name`, an [`AlarmTables`] expression.
pub(crate) fn write_alarm<S: Literal, const N: usize>(
    out: &mut Fields<'_>,
    name: &str,
    a: &AlarmTables<S, N>,
) -> fmt::Result {
    // Destructured whole: a field added to the tables is a compile error
    // here, not a field silently left out of the generated file.
    let AlarmTables {
        critical_c,
        derating_product,
        warning_margin_k,
        hysteresis_k,
        debounce_ticks,
        horizon_s,
        horizon_clear_s,
        nominal_ambient_c,
    } = a;
    let mut w = out.nested(name, "observer::AlarmTables")?;
    w.field("critical_c", critical_c)?;
    w.field("derating_product", derating_product)?;
    w.field("warning_margin_k", warning_margin_k)?;
    w.field("hysteresis_k", hysteresis_k)?;
    w.field("debounce_ticks", debounce_ticks)?;
    w.field("horizon_s", horizon_s)?;
    w.field("horizon_clear_s", horizon_clear_s)?;
    w.field("nominal_ambient_c", nominal_ambient_c)?;
    w.close(false)
}

/// Writes `l` as the field `name`, a [`LimiterTables`] expression.
pub(crate) fn write_limiter<S: Literal, const N: usize>(
    out: &mut Fields<'_>,
    name: &str,
    l: &LimiterTables<S, N>,
) -> fmt::Result {
    let LimiterTables {
        hardware_limit_a,
        taper_k,
        taper_per_k,
        floor_a,
    } = l;
    let mut w = out.nested(name, "observer::LimiterTables")?;
    w.field("hardware_limit_a", hardware_limit_a)?;
    w.field("taper_k", taper_k)?;
    w.field("taper_per_k", taper_per_k)?;
    w.field("floor_a", floor_a)?;
    w.close(false)
}

/// Writes `c` as the field `clock`, a [`ClockTables`] expression.
pub(crate) fn write_clock(out: &mut Fields<'_>, c: &ClockTables) -> fmt::Result {
    let ClockTables {
        step_us,
        max_steps_per_tick,
        frozen_flag_ticks,
        frozen_loss_ticks,
    } = c;
    let mut w = out.nested("clock", "observer::ClockTables")?;
    w.field("step_us", step_us)?;
    w.field("max_steps_per_tick", max_steps_per_tick)?;
    w.field("frozen_flag_ticks", frozen_flag_ticks)?;
    w.field("frozen_loss_ticks", frozen_loss_ticks)?;
    w.close(false)
}

/// Writes `k` as the field `name`, a [`KalmanTables`] expression.
pub(crate) fn write_kalman<const X: usize, const P: usize>(
    out: &mut Fields<'_>,
    name: &str,
    k: &KalmanTables<X, P>,
) -> fmt::Result {
    let KalmanTables {
        f,
        ht,
        q,
        r,
        gate_threshold,
        suspect_after,
        recover_after,
        recovery_variance,
        walk_from,
    } = k;
    let mut w = out.nested(name, "observer::KalmanTables")?;
    w.table("f", f)?;
    w.table("ht", ht)?;
    w.table("q", q)?;
    w.field("r", r)?;
    w.field("gate_threshold", gate_threshold)?;
    w.field("suspect_after", suspect_after)?;
    w.field("recover_after", recover_after)?;
    w.field("recovery_variance", recovery_variance)?;
    w.field("walk_from", walk_from)?;
    w.close(false)
}

/// Writes `g` as the field `gain`, a [`GainTables`] expression.
pub(crate) fn write_gain<const X: usize, const P: usize>(
    out: &mut Fields<'_>,
    g: &GainTables<X, P>,
) -> fmt::Result {
    let GainTables {
        period,
        gain,
        prior,
        posterior,
        innovation_var,
        prior_ht,
        innovation_cov,
    } = g;
    let mut w = out.nested("gain", "observer::network::GainTables")?;
    w.field("period", period)?;
    w.table("gain", gain)?;
    w.table("prior", prior)?;
    w.table("posterior", posterior)?;
    w.field("innovation_var", innovation_var)?;
    w.table("prior_ht", prior_ht)?;
    w.table("innovation_cov", innovation_cov)?;
    w.close(false)
}

/// Writes `t` as the field `predictor`, a [`PredictorTables`] expression.
pub(crate) fn write_predictor<const N: usize, const B: usize, const M: usize>(
    out: &mut Fields<'_>,
    t: &PredictorTables<N, B, M>,
) -> fmt::Result {
    let PredictorTables {
        grid_s,
        decay,
        lambda_per_s,
        v,
        v_inv,
        gain_power,
        gain_boundary,
        offset_c,
        winding_node,
        winding_r_at_0c_ohm,
        winding_slope_ohm_per_k,
        tick_s,
        points_per_tick,
        slowest_time_constant_s,
    } = t;
    let mut w = out.nested("predictor", "observer::network::PredictorTables")?;
    w.field("grid_s", grid_s)?;
    w.table("decay", decay)?;
    w.field("lambda_per_s", lambda_per_s)?;
    w.table("v", v)?;
    w.table("v_inv", v_inv)?;
    w.table("gain_power", gain_power)?;
    w.table("gain_boundary", gain_boundary)?;
    w.field("offset_c", offset_c)?;
    w.field("winding_node", winding_node)?;
    w.field("winding_r_at_0c_ohm", winding_r_at_0c_ohm)?;
    w.field("winding_slope_ohm_per_k", winding_slope_ohm_per_k)?;
    w.field("tick_s", tick_s)?;
    w.field("points_per_tick", points_per_tick)?;
    w.field("slowest_time_constant_s", slowest_time_constant_s)?;
    w.close(false)
}

/// Writes `c` as the field `checks`, a [`ChecksTables`] expression.
pub(crate) fn write_checks<const M: usize>(
    out: &mut Fields<'_>,
    c: &ChecksTables<M>,
) -> fmt::Result {
    let ChecksTables {
        band,
        bias_offset_w,
        bias_fraction,
        stuck_threshold_k,
        stuck_tolerance_k,
        stuck_window,
        silent_after_us,
    } = c;
    let mut w = out.nested("checks", "observer::ChecksTables")?;
    w.field("band", band)?;
    w.field("bias_offset_w", bias_offset_w)?;
    w.field("bias_fraction", bias_fraction)?;
    w.field("stuck_threshold_k", stuck_threshold_k)?;
    w.field("stuck_tolerance_k", stuck_tolerance_k)?;
    w.field("stuck_window", stuck_window)?;
    w.field("silent_after_us", silent_after_us)?;
    w.close(false)
}

/// Writes `s` as the field `step`, a [`StepTables`] expression.
pub(crate) fn write_step<const N: usize, const B: usize, const M: usize>(
    out: &mut Fields<'_>,
    s: &StepTables<N, B, M>,
) -> fmt::Result {
    let StepTables {
        phi_minus_i,
        bd_power,
        gd_boundary,
        constant_k,
    } = s;
    let mut w = out.nested("step", "observer::StepTables")?;
    w.table("phi_minus_i", phi_minus_i)?;
    w.table("bd_power", bd_power)?;
    w.table("gd_boundary", gd_boundary)?;
    w.field("constant_k", constant_k)?;
    w.close(false)
}
