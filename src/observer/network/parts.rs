//! The observer as data: everything [`NetworkObserverBuilder::build`]
//! solves, in plain arrays, so that a model can be solved once on a host
//! and shipped in flash.
//!
//! Building a [`NetworkObserver`] has two halves:
//!
//! 1. **solve** ([`NetworkObserverBuilder::parts`]): the matrix exponential
//!    of the network's zero-order hold, the Riccati equation of the
//!    steady-state gain, the eigen-decomposition of the time-to-limit
//!    predictor and the default incidence, in `f64`. Tens of KiB of stack
//!    and milliseconds to seconds of a Cortex-M;
//! 2. **assemble** ([`NetworkObserver::from_parts`]): validation, the
//!    filter's configuration, the alarm, limiter and upper bound (a square
//!    root per node), and the snapshot fingerprint, in `f64`. No
//!    exponential, no Riccati, no eigenvalue: a few hundred bytes of stack
//!    and `O((N + M)^2)` copies.
//!
//! [`NetworkObserverBuilder::build`] is exactly `from_parts(&parts()?)`, so
//! an observer assembled from parts written out by
//! [`NetworkParts::write_rust`] (what `coil-thermal codegen` does) and
//! compiled into a firmware image is the observer the builder makes, to the
//! bit: same tables, same fingerprint, same outputs.
//!
//! `parts()` runs the assembly too and keeps what it derives
//! ([`NetworkParts::assembled`], an [`AssembledTables`]), so a firmware
//! need not: [`NetworkObserver::from_assembled_parts`] is a `const fn` that
//! checks the tables' structure and copies them, and a `static` initialised
//! with it (what a generated module's `OBSERVER` is) is assembled by the
//! compiler. The image then holds no assembly and no `f64` routine (on a
//! Cortex-M0, 23 620 B of a 57 596 B image; `docs/cost.md`).
//! [`NetworkObserver::from_parts`] refuses parts whose assembled tables are
//! not its own derivation, so both ways give the same observer.
//!
//! Matrices are stored row by row (`[row][column]`), as they read in a
//! generated file. The filter's configuration, the sensor checks, the gain
//! and the predictor are the Omnimagnet's tables too
//! ([`KalmanTables`](crate::observer::KalmanTables),
//! [`ChecksTables`](crate::observer::ChecksTables), [`GainTables`],
//! [`PredictorTables`]): each read, checked, copied and written in one
//! place; the model's step and the shadow's block are one type
//! ([`StepTables`](crate::observer::StepTables)).

use core::fmt::{self, Write};

use nalgebra::{Const, SVector};

use super::assemble::{layout_of, Solved, StepMatrices};
use super::bias::nominal_powers_w;
use super::resistance::Conversion;
use super::resistance::{check_kinds, SensorKind};
use super::solve::{check_offset, elements_per_stage, two_tick_corrections, GainSpec, Solution};
use super::{
    default_incidence, Model, NetworkObserver, NetworkObserverBuilder, NetworkSettings, NO_LIMIT_C,
    PREDICTOR_POINTS,
};
use crate::discretize::fixed::{ConstFixedStep, FixedStep};
use crate::error::{check, BuildError};
use crate::input::ScalarLimits;
use crate::network::{DeviationResistance, NetworkDescription, ScalarResistance};
use crate::observer::consistency::Shadow;
use crate::observer::tables::{
    below, bound_rows, finite, finite_rows, invalid, matrix, rows, vector, write_alarm,
    write_checks, write_clock, write_gain, write_kalman, write_limiter, write_predictor,
    write_step, AlarmTables, ChecksTables, ClockTables, Fields, KalmanTables, LimiterTables,
    Literal, StepTables,
};
pub use crate::observer::tables::{GainTables, PredictorTables};
use crate::observer::SensorChecks;
use crate::protect::margin::UncertaintyMargin;
use crate::protect::predict::LimitPredictor;
use crate::sizes::ConstSizes;

impl<const N: usize, const B: usize, const M: usize> StepTables<N, B, M> {
    fn of(model: &Model<N, B, M>) -> Self {
        Self {
            phi_minus_i: rows(&model.phi_minus_i),
            bd_power: rows(&model.bd_power),
            gd_boundary: rows(&model.gd_boundary),
            constant_k: model.constant_k.into(),
        }
    }
}

/// The discretised network (see [`StepTables`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelTables<const N: usize, const B: usize, const M: usize> {
    /// `Ad`, the one-step transition (dimensionless); the filter's `F`.
    pub ad: [[f32; N]; N],
    /// The model's step.
    pub step: StepTables<N, B, M>,
    /// The node each current heats.
    pub source_node: [usize; M],
    /// Each source's `R(T)`.
    pub resistance: [ScalarResistance<f32>; M],
}

/// The shadow model's block step (see "Sensors against the physics" in
/// [`super`]): the exact zero-order hold of one correction period, in the
/// same deviation coordinates as [`ModelTables`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadowTables<const N: usize, const B: usize, const M: usize> {
    /// Model steps per block (the correction period).
    pub block_steps: u32,
    /// The block's step.
    pub step: StepTables<N, B, M>,
}

impl<const N: usize, const B: usize, const M: usize> ModelTables<N, B, M> {
    const fn is_finite(&self) -> bool {
        let mut k = 0;
        while k < M {
            let r = &self.resistance[k];
            if !(r.r_at_0c_ohm.is_finite() && r.slope_ohm_per_k.is_finite()) {
                return false;
            }
            k += 1;
        }
        finite_rows(&self.ad) && self.step.is_finite()
    }
}

/// A [`NetworkObserver`] as data: the builder's inputs that the tick reads
/// directly, and the tables it solved. See the module docs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetworkParts<
    const N: usize,
    const B: usize,
    const M: usize,
    const X: usize,
    const P: usize,
> {
    /// The settings the tables were solved with.
    pub settings: NetworkSettings,
    /// The node thermocouple `j` measures.
    pub sensor_nodes: [usize; P],
    /// Each node's critical temperature \[degC\] (`None`: no limit).
    pub critical_c: [Option<f64>; N],
    /// The derating rule's product (dimensionless, in `(0, 1]`).
    pub derating_product: f64,
    /// Each current's hardware limit \[A\].
    pub hardware_limit_a: [f64; M],
    /// `incidence[i][m]`: current `m` heats element `i`.
    pub incidence: [[bool; M]; N],
    /// The discretised network.
    pub model: ModelTables<N, B, M>,
    /// The steady-state gain.
    pub gain: GainTables<X, P>,
    /// The time-to-limit predictor.
    pub predictor: PredictorTables<N, B, M>,
    /// The shadow model.
    pub shadow: ShadowTables<N, B, M>,
    /// What [`NetworkObserver::from_parts`] derives from everything above
    /// (the filter's configuration, the protection, the fingerprint, ...),
    /// solved on the host, so that [`NetworkObserver::from_assembled_parts`]
    /// (a `const fn`) only copies it.
    pub assembled: AssembledTables<N, M, X, P>,
}

/// What [`NetworkObserver::from_parts`] derives from a [`NetworkParts`]'
/// settings and tables, in `f32` as the observer holds it: solved on the
/// host by [`NetworkObserverBuilder::parts`] (which runs the derivation
/// and keeps its result), checked against the derivation by
/// [`NetworkObserver::from_parts`] (`assembled` when it differs), and
/// copied by [`NetworkObserver::from_assembled_parts`], which computes
/// nothing. Matrices row by row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AssembledTables<const N: usize, const M: usize, const X: usize, const P: usize> {
    /// The filter's configuration (its `G` is a placeholder column the
    /// tick never reads: the input enters the mean predict only).
    pub kalman: KalmanTables<X, P>,
    /// The alarm.
    pub alarm: AlarmTables<f32, N>,
    /// The limiter (per-element taper factors).
    pub limiter: LimiterTables<f32, N>,
    /// Each element's upper bound as a row: the share of its rise, `f / (1
    /// + f)` and its offset \[K\].
    pub bound: [[f32; 3]; N],
    /// The bound's `k` (of `k sigma`).
    pub k_sigma: f32,
    /// The steady `sigma` in each node's bound \[K\].
    pub bound_sigma_k: [f32; N],
    /// The sensor checks.
    pub checks: ChecksTables<M>,
    /// The input rules: the largest current \[A\], the lowest and the
    /// highest boundary temperature \[degC\].
    pub limits: [f32; 3],
    /// The origin of the deviation coordinates \[degC\].
    pub origin_c: f32,
    /// Each current's hardware limit \[A\].
    pub hardware_limit_a: [f32; M],
    /// `max_cooling_bias_fraction`.
    pub cooling_bias_fraction: f32,
    /// The biases' decay per model step (0: random walks).
    pub bias_decay_per_step: f32,
    /// The boundary offset's decay per model step.
    pub offset_decay_per_step: f32,
    /// A bias or the offset decays.
    pub decays: bool,
    /// The sources sharing one heat bias.
    pub shared_bias: [bool; M],
    /// Each shared source's nominal Joule power \[W\] (0 for the others).
    pub nominal_power_w: [f32; M],
    /// Each resistance sensor's conversion (`None`: a thermocouple), as
    /// `R(0 degC)` \[ohm\], `dR/dT` \[ohm/K\], the minimum current \[A\],
    /// the lowest and the highest reading \[degC\].
    pub resistance_sensors: [Option<[f32; 5]>; P],
    /// How far below the shadow each sensor's screens take its node \[K\].
    pub noise_allowance_k: [f32; P],
    /// The model's clock.
    pub clock: ClockTables,
    /// The protection cycle's period \[us\].
    pub protect_period_us: u32,
    /// The snapshot fingerprint.
    pub fingerprint: u32,
}

impl<const N: usize, const M: usize, const X: usize, const P: usize> AssembledTables<N, M, X, P> {
    /// All zero: the tables before the derivation fills them (never an
    /// observer's: [`NetworkObserver::from_parts`] refuses them).
    const UNSOLVED: Self = Self {
        kalman: KalmanTables::ZERO,
        alarm: AlarmTables {
            critical_c: [0.0; N],
            derating_product: 0.0,
            warning_margin_k: 0.0,
            hysteresis_k: 0.0,
            debounce_ticks: 0,
            horizon_s: 0.0,
            horizon_clear_s: 0.0,
            nominal_ambient_c: 0.0,
        },
        limiter: LimiterTables {
            hardware_limit_a: [0.0; N],
            taper_k: 0.0,
            taper_per_k: 0.0,
            floor_a: 0.0,
        },
        bound: [[0.0; 3]; N],
        k_sigma: 0.0,
        bound_sigma_k: [0.0; N],
        checks: ChecksTables::ZERO,
        limits: [0.0; 3],
        origin_c: 0.0,
        hardware_limit_a: [0.0; M],
        cooling_bias_fraction: 0.0,
        bias_decay_per_step: 0.0,
        offset_decay_per_step: 0.0,
        decays: false,
        shared_bias: [false; M],
        nominal_power_w: [0.0; M],
        resistance_sensors: [None; P],
        noise_allowance_k: [0.0; P],
        clock: ClockTables {
            step_us: 0,
            max_steps_per_tick: 0,
            frozen_flag_ticks: 0,
            frozen_loss_ticks: 0,
        },
        protect_period_us: 0,
        fingerprint: 0,
    };

    /// Every `f32` finite (the gate's threshold may be `+inf`: no gate;
    /// an unbounded bias is `+inf`) and the indices in range.
    const fn is_valid(&self) -> bool {
        let mut j = 0;
        while j < P {
            if let Some(row) = &self.resistance_sensors[j] {
                if !finite(row) {
                    return false;
                }
            }
            j += 1;
        }
        self.kalman.is_valid()
            && self.alarm.is_finite()
            && self.limiter.is_finite()
            && finite_rows(&self.bound)
            && finite(&self.bound_sigma_k)
            && self.checks.is_valid()
            && finite(&[
                self.k_sigma,
                self.origin_c,
                self.cooling_bias_fraction,
                self.bias_decay_per_step,
                self.offset_decay_per_step,
            ])
            && finite(&self.limits)
            && finite(&self.hardware_limit_a)
            && finite(&self.nominal_power_w)
            && finite(&self.noise_allowance_k)
    }
}

impl<'a, const N: usize, const B: usize, const M: usize, const P: usize>
    NetworkObserverBuilder<'a, N, B, M, P>
{
    /// The solve half of [`Self::build`] (see the module docs): validates
    /// everything and solves every table, in `f64`, for
    /// [`NetworkObserver::from_parts`] now or, written out by
    /// [`NetworkParts::write_rust`], in a firmware image later.
    ///
    /// # Errors
    /// As [`Self::build`].
    pub fn parts<const X: usize>(&self) -> Result<NetworkParts<N, B, M, X, P>, BuildError> {
        let () = NetworkObserver::<N, B, M, X, P>::SIZES;
        let s = &self.settings;
        let network = self.network;
        network.check_sources()?;
        check_offset(s, (N, B, M), X)?;
        check(self.sensor_nodes.iter().all(|n| *n < N), "sensor_nodes")?;
        check(!self.bad_sensor, "resistance_sensor")?;
        check(s.ambient_boundary < B, "ambient_boundary")?;
        check(
            self.critical_c
                .iter()
                .all(|c| c.is_none_or(|c| c.is_finite() && c < NO_LIMIT_C)),
            "critical_c",
        )?;
        check(
            self.hardware_limit_a
                .iter()
                .all(|a| a.is_finite() && *a > 0.0),
            "hardware_limit_a",
        )?;
        let incidence = match self.incidence {
            Some(incidence) => incidence,
            None => default_incidence(network, s.incidence_fraction)?,
        };
        // Before the solve: a resistance sensor on no winding of its own
        // is refused at once (`check_sources` found every source).
        let source_node: [usize; M] = core::array::from_fn(|m| {
            NetworkDescription::joule_source_of(network, m).map_or(usize::MAX, |source| source.node)
        });
        check_kinds(&self.sensor_kinds, &self.sensor_nodes, &source_node)?;
        let Solution {
            timing,
            model,
            gain,
            predictor,
            block,
        } = self.gain_spec().solve(network, Const::<X>)?;
        let mut parts = NetworkParts {
            settings: *s,
            sensor_nodes: self.sensor_nodes,
            critical_c: self.critical_c,
            derating_product: self.rule.product(),
            hardware_limit_a: self.hardware_limit_a,
            incidence,
            model: ModelTables {
                ad: rows(&model.ad.cast()),
                step: StepTables::of(&model),
                source_node: model.source_node,
                resistance: model.resistance,
            },
            gain: GainTables::of(&gain),
            predictor: PredictorTables::of(&predictor),
            shadow: ShadowTables {
                block_steps: timing.correction_period,
                step: StepTables::of(&block),
            },
            assembled: AssembledTables::UNSOLVED,
        };
        // The assembly's derivations, once, here on the host: what
        // `from_parts` checks the tables against and
        // `from_assembled_parts` copies.
        parts.assembled = NetworkObserver::derive(&parts, &self.sensor_kinds)?.assembled_tables();
        Ok(parts)
    }
}

impl<const N: usize, const B: usize, const M: usize, const P: usize>
    NetworkObserverBuilder<'_, N, B, M, P>
{
    /// What the gain solve reads of this builder.
    fn gain_spec(&self) -> GainSpec<'_, ConstSizes<N, B, M>, Const<P>> {
        GainSpec {
            settings: &self.settings,
            sensor_nodes: &self.sensor_nodes,
            kinds: &self.sensor_kinds,
            critical_c: &self.critical_c,
            hardware_limit_a: &self.hardware_limit_a,
            bias_sources: &self.bias_sources,
            bias_mode: self.bias_mode.as_ref(),
        }
    }
}

impl<const N: usize, const B: usize, const M: usize, const X: usize, const P: usize>
    NetworkObserver<N, B, M, X, P>
{
    /// The sizes an observer takes, checked where the solve or an
    /// assembly names it: a compile error, never a run-time one.
    const SIZES: () = {
        assert!(
            X == N + M || X == N + M + 1,
            "X must be N + M (temperatures and biases), or N + M + 1 with a boundary offset"
        );
        assert!(B >= 1, "a network needs a boundary (the ambient)");
        assert!(M >= 1 && P >= 1, "at least one current and one sensor");
    };

    /// The assemble half of [`NetworkObserverBuilder::build`] (see the
    /// module docs): an observer from solved tables, typically a `const`
    /// written by `coil-thermal codegen`. Computes no exponential, no
    /// Riccati solution and no eigenvalue.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming what is inconsistent: a
    /// setting (as [`NetworkObserverBuilder::build`]), an index out of
    /// range (`sensor_nodes`, `source_node`, `winding_node`,
    /// `points_per_tick`), a non-finite table entry (`model`, `gain`,
    /// `predictor`), a gain solved for another correction period
    /// (`gain.period`), the limits (`critical_c`, `derating_product`,
    /// `hardware_limit_a`), or assembled tables that are not what it
    /// derives (`assembled`).
    pub fn from_parts(parts: &NetworkParts<N, B, M, X, P>) -> Result<Self, BuildError> {
        Self::from_parts_with_sensors(parts, &SensorKind::thermocouples())
    }

    /// [`Self::from_parts`] for tables solved with sensors of other kinds
    /// (see [`super::resistance`]): `kinds[j]` is what sensor `j` is, as
    /// [`NetworkObserverBuilder::kinds`] gave it to the solve.
    ///
    /// # Errors
    /// Those of [`Self::from_parts`]; [`BuildError::InvalidParameter`]
    /// naming a resistance sensor's field, `resistance_sensor` for one
    /// that does not read its source's node, and `sensor_kinds` for
    /// tables whose innovation variances were solved with other sensor
    /// noises than these kinds' (a resistance sensor's tables assembled
    /// as thermocouples', or the reverse).
    pub fn from_parts_with_sensors(
        parts: &NetworkParts<N, B, M, X, P>,
        kinds: &[SensorKind; P],
    ) -> Result<Self, BuildError> {
        let observer = Self::derive(parts, kinds)?;
        check(parts.assembled == observer.assembled_tables(), "assembled")?;
        Ok(observer)
    }

    /// [`Self::from_parts_with_sensors`] but for the check of
    /// [`NetworkParts::assembled`]: validates and derives everything in
    /// `f64` (what [`NetworkObserverBuilder::parts`] runs on the host to
    /// solve the assembled tables).
    fn derive(
        parts: &NetworkParts<N, B, M, X, P>,
        kinds: &[SensorKind; P],
    ) -> Result<Self, BuildError> {
        let () = Self::SIZES;
        let s = &parts.settings;
        let (m, sh) = (&parts.model, &parts.shadow);
        // The tables' own checks: the predictor's indices before it is
        // read, then everything the assembly checks for every size.
        let predictor = predictor_from(&parts.predictor, elements_per_stage(s))?;
        let steps = |t: &StepTables<N, B, M>| StepMatrices {
            phi_minus_i: matrix(&t.phi_minus_i),
            bd_power: matrix(&t.bd_power),
            gd_boundary: matrix(&t.gd_boundary),
            constant_k: SVector::from(t.constant_k),
        };
        let integer = integer_step(s, &m.step).map(|step| {
            #[cfg(feature = "integer-step")]
            let block = integer_block(s, &sh.step);
            #[cfg(not(feature = "integer-step"))]
            let block = None;
            (step, block)
        });
        Self::assemble(
            s,
            Solved {
                sizes: ConstSizes,
                sensor_nodes: parts.sensor_nodes,
                kinds: *kinds,
                critical_c: parts.critical_c,
                derating_product: parts.derating_product,
                hardware_limit_a: parts.hardware_limit_a,
                incidence: parts.incidence,
                ad: matrix(&m.ad),
                step: steps(&m.step),
                source_node: m.source_node,
                resistance: m.resistance,
                gain: parts.gain.gain(),
                predictor,
                block: (steps(&sh.step), sh.block_steps),
                integer,
            },
        )
    }
}

impl<const N: usize, const B: usize, const M: usize, const X: usize, const P: usize>
    NetworkObserver<N, B, M, X, P>
{
    /// What this observer derived from its parts, as tables (see
    /// [`AssembledTables`]).
    fn assembled_tables(&self) -> AssembledTables<N, M, X, P> {
        let sh = &self.shadow;
        AssembledTables {
            kalman: KalmanTables::of(&self.kalman),
            alarm: AlarmTables::of(&self.alarm),
            limiter: LimiterTables::of(&self.limiter),
            bound: bound_rows(&self.bound),
            k_sigma: self.k_sigma,
            bound_sigma_k: self.bound_sigma_k,
            checks: ChecksTables::of(
                &sh.band,
                &sh.bias_bound,
                &self.stuck_test,
                self.silent_after_us,
            ),
            limits: [
                self.limits.max_current_a,
                self.limits.min_temp_c,
                self.limits.max_temp_c,
            ],
            origin_c: self.origin_c,
            hardware_limit_a: self.hardware_limit_a,
            cooling_bias_fraction: self.cooling_bias_fraction,
            bias_decay_per_step: self.bias_decay_per_step,
            offset_decay_per_step: self.offset_decay_per_step,
            decays: self.decays,
            shared_bias: self.shared_bias,
            nominal_power_w: self.nominal_power_w,
            resistance_sensors: self.resistance_sensors.map(|c| c.map(|c| c.row())),
            noise_allowance_k: self.noise_allowance_k,
            clock: ClockTables::of(&self.clock),
            protect_period_us: self.protect_period_us,
            fingerprint: self.fingerprint,
        }
    }

    /// The observer of `parts` as [`Self::from_parts`] assembles it, copied
    /// from [`NetworkParts::assembled`] and the tables: a `const fn` that
    /// computes nothing, so a `static` initialised with it (what
    /// `coil-thermal codegen` writes) is assembled by the compiler and the
    /// firmware holds neither the assembly's code nor its `f64` routines.
    /// The settings were validated on the host when the tables were solved
    /// ([`NetworkObserverBuilder::parts`] runs the assembly), and
    /// [`Self::from_parts`] of the same parts is this observer, to the bit,
    /// or refuses them.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the first inconsistent part:
    /// an index out of range (`sensor_nodes`, `source_node`,
    /// `ambient_boundary`, `boundary_offset`, `predictor`), a non-finite
    /// table entry (`model`, `gain`, `predictor`, `shadow`, `assembled`), a
    /// gain or shadow solved for another correction period
    /// (`gain.period`, `shadow.block_steps`), or a clock the tick cannot
    /// run (`clock.step_us`, `clock.max_steps_per_tick`,
    /// `clock.frozen_flag_ticks`, `clock.frozen_loss_ticks`).
    pub const fn from_assembled_parts(
        parts: &NetworkParts<N, B, M, X, P>,
    ) -> Result<Self, BuildError> {
        let () = Self::SIZES;
        let s = &parts.settings;
        let (m, g, t, sh, a) = (
            &parts.model,
            &parts.gain,
            &parts.predictor,
            &parts.shadow,
            &parts.assembled,
        );
        if !below(&parts.sensor_nodes, N) {
            return Err(invalid("sensor_nodes"));
        }
        if !below(&m.source_node, N) {
            return Err(invalid("source_node"));
        }
        if s.ambient_boundary >= B {
            return Err(invalid("ambient_boundary"));
        }
        let offset_ok = match s.boundary_offset {
            Some(b) => b < B && X == N + M + 1,
            None => X == N + M,
        };
        if !offset_ok {
            return Err(invalid("boundary_offset"));
        }
        if !m.is_finite() {
            return Err(invalid("model"));
        }
        if g.period != sh.block_steps || g.period == 0 {
            return Err(invalid("gain.period"));
        }
        if !g.is_finite() {
            return Err(invalid("gain"));
        }
        if !t.is_valid() {
            return Err(invalid("predictor"));
        }
        if !sh.step.is_finite() {
            return Err(invalid("shadow"));
        }
        if !a.is_valid() {
            return Err(invalid("assembled"));
        }
        let clock = match a.clock.clock() {
            Ok(clock) => clock,
            Err(e) => return Err(e),
        };
        let integer_step = match integer_step(s, &m.step) {
            Ok(step) => step,
            Err(e) => return Err(e),
        };
        if let Err(e) = two_tick_corrections(s) {
            return Err(e);
        }
        // Refused above without the feature, so always `None` here then.
        #[cfg(not(feature = "integer-step"))]
        let _ = integer_step;
        if clock.step_us != s.step_us || a.protect_period_us == 0 {
            return Err(invalid("assembled"));
        }
        let mut resistance_sensors = [None; P];
        let mut j = 0;
        while j < P {
            if let Some(row) = &a.resistance_sensors[j] {
                resistance_sensors[j] = Some(Conversion::of_row(row));
            }
            j += 1;
        }
        Ok(Self {
            phi_minus_i: matrix(&m.step.phi_minus_i),
            bd_power: matrix(&m.step.bd_power),
            gd_boundary: matrix(&m.step.gd_boundary),
            constant_k: vector(&m.step.constant_k),
            origin_c: a.origin_c,
            source_node: m.source_node,
            resistance: about_origin(&m.resistance, a.origin_c),
            kalman: a.kalman.config(nalgebra::SMatrix::from_array_storage(
                nalgebra::ArrayStorage([[0.0; X]; 1]),
            )),
            gain: g.gain(),
            sensor_nodes: parts.sensor_nodes,
            resistance_sensors,
            noise_allowance_k: a.noise_allowance_k,
            limited: limited_of(&parts.critical_c),
            incidence: parts.incidence,
            hardware_limit_a: a.hardware_limit_a,
            alarm: a.alarm.config(),
            limiter: a.limiter.config(),
            predictor: t.predictor(elements_per_stage(s)),
            bound: crate::observer::tables::upper_bound(&a.bound),
            k_sigma: a.k_sigma,
            bound_sigma_k: a.bound_sigma_k,
            shadow: Shadow {
                phi_minus_i: matrix(&sh.step.phi_minus_i),
                bd_power: matrix(&sh.step.bd_power),
                gd_boundary: matrix(&sh.step.gd_boundary),
                constant_k: vector(&sh.step.constant_k),
                block_steps: sh.block_steps,
                waits_for_light_tick: s.step_us > s.loop_tick_us(),
                #[cfg(feature = "integer-step")]
                integer_block: integer_block(s, &sh.step),
                band: a.checks.band(),
                bias_bound: a.checks.bias_bound(),
            },
            warmup_corrections: s.warmup_corrections,
            cooling_bias_fraction: a.cooling_bias_fraction,
            bias_decay_per_step: a.bias_decay_per_step,
            offset_boundary: s.boundary_offset,
            decays: a.decays,
            #[cfg(not(target_abi = "eabihf"))]
            correction_in_two_ticks: s.correction_in_two_ticks,
            offset_decay_per_step: a.offset_decay_per_step,
            shared_bias: a.shared_bias,
            nominal_power_w: a.nominal_power_w,
            stuck_test: a.checks.stuck_test(),
            silent_after_us: a.checks.silent_after_us,
            clock,
            limits: ScalarLimits {
                max_current_a: a.limits[0],
                min_temp_c: a.limits[1],
                max_temp_c: a.limits[2],
            },
            ambient_boundary: s.ambient_boundary,
            max_reading_age_us: s.max_reading_age_us,
            step_us: s.step_us,
            loop_period_us: s.loop_tick_us(),
            protect_period_us: a.protect_period_us,
            fingerprint: a.fingerprint,
            #[cfg(feature = "integer-step")]
            integer_step,
        })
    }
}

/// The integer model step the settings ask for (see "The model step in
/// integer arithmetic" in [`super`]), if any; refused without the
/// `integer-step` feature (whose absence keeps its code out of an `f32`
/// firmware) or for tables it cannot hold.
const fn integer_step<const N: usize, const B: usize, const M: usize>(
    s: &NetworkSettings,
    step: &StepTables<N, B, M>,
) -> Result<Option<ConstFixedStep<N, B, M>>, BuildError> {
    if !s.integer_model_step {
        return Ok(None);
    }
    if cfg!(not(feature = "integer-step")) {
        return Err(invalid(
            "integer_model_step (enable coil-thermal's integer-step feature)",
        ));
    }
    match FixedStep::of(step) {
        Some(step) => Ok(Some(step)),
        None => Err(invalid("model")),
    }
}

/// The shadow's block step in integer arithmetic when the model steps in
/// it; `None` (the block steps in `f32`, as accurate) where the block's
/// tables do not fit the integer step's scales: a longer step's
/// conductances are larger, and the shadow is no reason to refuse a model.
#[cfg(feature = "integer-step")]
const fn integer_block<const N: usize, const B: usize, const M: usize>(
    s: &NetworkSettings,
    block: &StepTables<N, B, M>,
) -> Option<ConstFixedStep<N, B, M>> {
    if s.integer_model_step {
        FixedStep::of(block)
    } else {
        None
    }
}

/// Which elements have a limit (`Some` critical temperature).
/// Each winding's line `resistance` taken about the observer's origin
/// `origin_c` \[degC\] (see [`DeviationResistance`]).
const fn about_origin<const M: usize>(
    resistance: &[ScalarResistance<f32>; M],
    origin_c: f32,
) -> [DeviationResistance; M] {
    let mut out = [DeviationResistance {
        r_at_origin_ohm: 0.0,
        slope_ohm_per_k: 0.0,
    }; M];
    let mut m = 0;
    while m < M {
        out[m] = DeviationResistance::about(&resistance[m], origin_c);
        m += 1;
    }
    out
}

const fn limited_of<const N: usize>(critical_c: &[Option<f64>; N]) -> [bool; N] {
    let mut limited = [false; N];
    let mut i = 0;
    while i < N {
        limited[i] = critical_c[i].is_some();
        i += 1;
    }
    limited
}

fn predictor_from<const N: usize, const B: usize, const M: usize>(
    t: &PredictorTables<N, B, M>,
    elements_per_stage: usize,
) -> Result<LimitPredictor<f32, N, B, M, PREDICTOR_POINTS>, BuildError> {
    check(t.winding_node.iter().all(|n| *n < N), "winding_node")?;
    check(
        (1..=PREDICTOR_POINTS + 1).contains(&t.points_per_tick),
        "points_per_tick",
    )?;
    // The indices by their own names; `is_valid` checks them again with
    // every entry.
    check(t.is_valid(), "predictor")?;
    Ok(t.predictor(elements_per_stage))
}

impl<const N: usize, const B: usize, const M: usize, const X: usize, const P: usize>
    NetworkParts<N, B, M, X, P>
{
    /// The sources whose heat-input biases these tables share (see
    /// [`BiasMode`](super::BiasMode); all `false`: a bias per source), as
    /// [`NetworkObserver::from_parts`] reads them.
    pub fn shared_bias_sources(&self) -> [bool; M] {
        let nominal_w = nominal_powers_w::<Const<M>>(
            &self.hardware_limit_a,
            &self.model.resistance,
            self.settings.origin_c,
        );
        layout_of(&self.settings, &self.gain.gain(), N, Const::<M>, &nominal_w).shared_mask()
    }

    /// Writes these parts as a Rust expression of type `NetworkParts<N, B,
    /// M, X, P>` that names every type by its full path (`coil_thermal::`),
    /// for a `const` in a generated module. Reading it back gives these
    /// parts to the bit (floats are written by `{:?}`, which round-trips).
    ///
    /// # Errors
    /// Those of `out`.
    pub fn write_rust(&self, out: &mut dyn Write) -> fmt::Result {
        // Destructured whole, so that a field added to the parts is a
        // compile error here, not a field silently left out of the
        // generated file.
        let Self {
            settings,
            sensor_nodes,
            critical_c,
            derating_product,
            hardware_limit_a,
            incidence,
            model,
            gain,
            predictor,
            shadow,
            assembled,
        } = self;
        let mut w = Fields::open(out, "observer::network::NetworkParts", 0)?;
        write_settings(&mut w, settings)?;
        w.field("sensor_nodes", sensor_nodes)?;
        w.field("critical_c", critical_c)?;
        w.field("derating_product", derating_product)?;
        w.field("hardware_limit_a", hardware_limit_a)?;
        w.table("incidence", incidence)?;
        write_model(&mut w, model)?;
        write_gain(&mut w, gain)?;
        write_predictor(&mut w, predictor)?;
        write_shadow(&mut w, shadow)?;
        write_assembled(&mut w, assembled)?;
        w.close(true)
    }
}

impl Literal for ScalarResistance<f32> {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        out.write_str("coil_thermal::network::ScalarResistance { r_at_0c_ohm: ")?;
        self.r_at_0c_ohm.write(out)?;
        out.write_str(", slope_ohm_per_k: ")?;
        self.slope_ohm_per_k.write(out)?;
        out.write_str(" }")
    }
}

fn write_settings(out: &mut Fields<'_>, s: &NetworkSettings) -> fmt::Result {
    let NetworkSettings {
        step_us,
        loop_period_us,
        max_steps_per_tick,
        sensor_sigma_k,
        node_noise_k2_per_s,
        bias_noise_w2_per_s,
        bias_tau_s,
        boundary_offset,
        boundary_offset_std_k,
        boundary_offset_tau_s,
        recovery_sigma_k,
        recovery_bias_sigma_w,
        correction_period_s,
        gate_threshold,
        suspect_after,
        recover_after,
        max_reading_age_us,
        taper_k,
        protect_period_steps,
        k_sigma,
        unmeasured_margin:
            UncertaintyMargin {
                rise_fraction,
                offset_k,
            },
        incidence_fraction,
        origin_c,
        ambient_boundary,
        frozen_flag_ticks,
        warmup_corrections,
        max_current_a,
        checks:
            SensorChecks {
                consistency_offset_k,
                consistency_fraction,
                stuck_threshold_k,
                stuck_tolerance_k,
                max_element_sigma_k,
            },
        max_cooling_bias_fraction,
        frozen_loss_ticks,
        integer_model_step,
        predictor_elements_per_stage,
        correction_in_two_ticks,
    } = s;
    let mut w = out.nested("settings", "observer::network::NetworkSettings")?;
    w.field("step_us", step_us)?;
    w.field("loop_period_us", loop_period_us)?;
    w.field("max_steps_per_tick", max_steps_per_tick)?;
    w.field("sensor_sigma_k", sensor_sigma_k)?;
    w.field("node_noise_k2_per_s", node_noise_k2_per_s)?;
    w.field("bias_noise_w2_per_s", bias_noise_w2_per_s)?;
    w.field("recovery_sigma_k", recovery_sigma_k)?;
    w.field("recovery_bias_sigma_w", recovery_bias_sigma_w)?;
    w.field("correction_period_s", correction_period_s)?;
    w.field("gate_threshold", gate_threshold)?;
    w.field("suspect_after", suspect_after)?;
    w.field("recover_after", recover_after)?;
    w.field("max_reading_age_us", max_reading_age_us)?;
    w.field("taper_k", taper_k)?;
    w.field("protect_period_steps", protect_period_steps)?;
    w.field("k_sigma", k_sigma)?;
    let mut m = w.nested("unmeasured_margin", "protect::margin::UncertaintyMargin")?;
    m.field("rise_fraction", rise_fraction)?;
    m.field("offset_k", offset_k)?;
    m.close(false)?;
    w.field("incidence_fraction", incidence_fraction)?;
    w.field("origin_c", origin_c)?;
    w.field("ambient_boundary", ambient_boundary)?;
    w.field("warmup_corrections", warmup_corrections)?;
    w.field("max_current_a", max_current_a)?;
    let mut c = w.nested("checks", "observer::SensorChecks")?;
    c.field("consistency_offset_k", consistency_offset_k)?;
    c.field("consistency_fraction", consistency_fraction)?;
    c.field("stuck_threshold_k", stuck_threshold_k)?;
    c.field("stuck_tolerance_k", stuck_tolerance_k)?;
    c.field("max_element_sigma_k", max_element_sigma_k)?;
    c.close(false)?;
    w.field("bias_tau_s", bias_tau_s)?;
    w.field("boundary_offset", boundary_offset)?;
    w.field("boundary_offset_std_k", boundary_offset_std_k)?;
    w.field("boundary_offset_tau_s", boundary_offset_tau_s)?;
    w.field("max_cooling_bias_fraction", max_cooling_bias_fraction)?;
    w.field("frozen_flag_ticks", frozen_flag_ticks)?;
    w.field("frozen_loss_ticks", frozen_loss_ticks)?;
    w.field("integer_model_step", integer_model_step)?;
    w.field("predictor_elements_per_stage", predictor_elements_per_stage)?;
    w.field("correction_in_two_ticks", correction_in_two_ticks)?;
    w.close(false)
}

fn write_model<const N: usize, const B: usize, const M: usize>(
    out: &mut Fields<'_>,
    m: &ModelTables<N, B, M>,
) -> fmt::Result {
    let ModelTables {
        ad,
        step,
        source_node,
        resistance,
    } = m;
    let mut w = out.nested("model", "observer::network::ModelTables")?;
    w.table("ad", ad)?;
    write_step(&mut w, step)?;
    w.field("source_node", source_node)?;
    w.field("resistance", resistance)?;
    w.close(false)
}

fn write_shadow<const N: usize, const B: usize, const M: usize>(
    out: &mut Fields<'_>,
    sh: &ShadowTables<N, B, M>,
) -> fmt::Result {
    let ShadowTables { block_steps, step } = sh;
    let mut w = out.nested("shadow", "observer::network::ShadowTables")?;
    w.field("block_steps", block_steps)?;
    write_step(&mut w, step)?;
    w.close(false)
}

/// Writes `a` as the field `assembled`, an [`AssembledTables`] expression.
fn write_assembled<const N: usize, const M: usize, const X: usize, const P: usize>(
    out: &mut Fields<'_>,
    a: &AssembledTables<N, M, X, P>,
) -> fmt::Result {
    // Destructured whole: a field added to the tables is a compile error
    // here, not a field silently left out of the generated file.
    let AssembledTables {
        kalman,
        alarm,
        limiter,
        bound,
        k_sigma,
        bound_sigma_k,
        checks,
        limits,
        origin_c,
        hardware_limit_a,
        cooling_bias_fraction,
        bias_decay_per_step,
        offset_decay_per_step,
        decays,
        shared_bias,
        nominal_power_w,
        resistance_sensors,
        noise_allowance_k,
        clock,
        protect_period_us,
        fingerprint,
    } = a;
    let mut w = out.nested("assembled", "observer::network::AssembledTables")?;
    write_kalman(&mut w, "kalman", kalman)?;
    write_alarm(&mut w, "alarm", alarm)?;
    write_limiter(&mut w, "limiter", limiter)?;
    w.table("bound", bound)?;
    w.field("k_sigma", k_sigma)?;
    w.field("bound_sigma_k", bound_sigma_k)?;
    write_checks(&mut w, checks)?;
    w.field("limits", limits)?;
    w.field("origin_c", origin_c)?;
    w.field("hardware_limit_a", hardware_limit_a)?;
    w.field("cooling_bias_fraction", cooling_bias_fraction)?;
    w.field("bias_decay_per_step", bias_decay_per_step)?;
    w.field("offset_decay_per_step", offset_decay_per_step)?;
    w.field("decays", decays)?;
    w.field("shared_bias", shared_bias)?;
    w.field("nominal_power_w", nominal_power_w)?;
    w.field("resistance_sensors", resistance_sensors)?;
    w.field("noise_allowance_k", noise_allowance_k)?;
    write_clock(&mut w, clock)?;
    w.field("protect_period_us", protect_period_us)?;
    w.field("fingerprint", fingerprint)?;
    w.close(false)
}

#[cfg(test)]
mod tests {
    use super::super::{NetworkInputs, NetworkSettings};
    use super::*;
    use crate::network::{Network, Resistance};
    use crate::observer::TimedReading;
    use crate::Reading;

    type Parts = NetworkParts<3, 1, 1, 4, 1>;

    fn network() -> Network<3, 1, 1> {
        Network::new([60.0, 400.0, 900.0])
            .and_then(|n| n.connect(0, 1, 0.8))
            .and_then(|n| n.connect(1, 2, 2.0))
            .and_then(|n| n.connect_boundary(2, 0, 1.2))
            .and_then(|n| n.joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0)))
            .expect("a valid network")
    }

    fn parts() -> Parts {
        NetworkObserverBuilder::new(&network(), [1])
            .critical_c([Some(155.0), Some(80.0), None])
            .parts()
            .expect("solvable")
    }

    #[test]
    fn an_observer_from_parts_ticks_as_the_built_one() {
        let net = network();
        let built: NetworkObserver<3, 1, 1, 4, 1> = NetworkObserverBuilder::new(&net, [1])
            .critical_c([Some(155.0), Some(80.0), None])
            .build()
            .expect("builds");
        // A copy of the parts, as a generated `const` would hold them.
        let copied = parts();
        let assembled = NetworkObserver::from_parts(&copied).expect("assembles");
        assert_eq!(built.fingerprint(), assembled.fingerprint());
        // The compiler's assembly (a `static` of a generated module: the
        // same `const fn`) copies the same observer: every field to the bit (`{:?}` of a float
        // reads back to its bits and tells -0.0 from 0.0).
        let copied_here = NetworkObserver::from_assembled_parts(&copied).expect("assembles");
        assert_eq!(format!("{built:?}"), format!("{copied_here:?}"));
        assert_eq!(format!("{built:?}"), format!("{assembled:?}"));
        let mut a = built.state(&[20.0; 3], &[20.0]);
        let mut b = assembled.state(&[20.0; 3], &[20.0]);
        for tick in 0..20_000u32 {
            let now_us = tick * 1000;
            let reading = (tick % 500 == 0).then_some(TimedReading {
                result: Ok(Reading::new(20.0 + tick as f32 * 1e-3)),
                sampled_at_us: now_us,
            });
            let inputs = NetworkInputs {
                currents_a: [if tick < 10_000 { 6.0 } else { 12.0 }],
                boundary_c: [20.0],
                readings: [reading],
                now_us,
                elapsed_us: 1000,
            };
            assert_eq!(built.tick(&mut a, &inputs), assembled.tick(&mut b, &inputs));
        }
        // The run did something worth comparing: heated and corrected.
        assert!(a.outputs().temps_c[0] > 25.0, "{:?}", a.outputs().temps_c);
    }

    /// The name `assemble` refuses `p` by.
    fn refusal(
        assemble: fn(&Parts) -> Result<NetworkObserver<3, 1, 1, 4, 1>, BuildError>,
        p: &Parts,
    ) -> &'static str {
        match assemble(p) {
            Err(BuildError::InvalidParameter { name }) => name,
            other => panic!(
                "expected a refusal, got {:?}",
                other.map(|o| o.fingerprint())
            ),
        }
    }

    /// What both assemblies refuse by the same name: an index out of
    /// range, a non-finite table, a gain solved for another period.
    fn refuses_the_shared_inconsistencies(
        assemble: fn(&Parts) -> Result<NetworkObserver<3, 1, 1, 4, 1>, BuildError>,
    ) {
        let name = |p: &Parts| refusal(assemble, p);
        let mut p = parts();
        p.sensor_nodes = [3];
        assert_eq!(name(&p), "sensor_nodes");
        let mut p = parts();
        p.model.source_node = [7];
        assert_eq!(name(&p), "source_node");
        let mut p = parts();
        p.model.ad[1][2] = f32::NAN;
        assert_eq!(name(&p), "model");
        let mut p = parts();
        p.gain.prior[3][3] = f32::INFINITY;
        assert_eq!(name(&p), "gain");
        let mut p = parts();
        p.gain.period += 1;
        assert_eq!(name(&p), "gain.period");
    }

    #[test]
    fn inconsistent_parts_are_refused_by_name() {
        refuses_the_shared_inconsistencies(NetworkObserver::from_parts);
        let name = |p: &Parts| refusal(NetworkObserver::from_parts, p);
        let mut p = parts();
        p.predictor.points_per_tick = 0;
        assert_eq!(name(&p), "points_per_tick");
        let mut p = parts();
        p.predictor.winding_node = [3];
        assert_eq!(name(&p), "winding_node");
        let mut p = parts();
        p.predictor.decay[4][0] = f32::NAN;
        assert_eq!(name(&p), "predictor");
        let mut p = parts();
        p.derating_product = 1.5;
        assert_eq!(name(&p), "derating_product");
        let mut p = parts();
        p.hardware_limit_a = [0.0];
        assert_eq!(name(&p), "hardware_limit_a");
        let mut p = parts();
        p.settings.step_us = 0;
        assert!(NetworkObserver::from_parts(&p).is_err());
        // Assembled tables that are not the derivation's.
        let mut p = parts();
        p.assembled.fingerprint ^= 1;
        assert_eq!(name(&p), "assembled");
        let mut p = parts();
        p.assembled.kalman.q[0][0] *= 2.0;
        assert_eq!(name(&p), "assembled");
    }

    #[test]
    fn the_compilers_assembly_refuses_inconsistent_parts_by_name() {
        refuses_the_shared_inconsistencies(NetworkObserver::from_assembled_parts);
        let name = |p: &Parts| refusal(NetworkObserver::from_assembled_parts, p);
        let mut p = parts();
        p.predictor.winding_node = [3];
        assert_eq!(name(&p), "predictor");
        let mut p = parts();
        p.shadow.step.constant_k[0] = f32::NAN;
        assert_eq!(name(&p), "shadow");
        let mut p = parts();
        p.assembled.kalman.f[0][1] = f32::NAN;
        assert_eq!(name(&p), "assembled");
        let mut p = parts();
        p.assembled.clock.step_us = 0;
        assert_eq!(name(&p), "clock.step_us");
        assert!(NetworkObserver::from_assembled_parts(&parts()).is_ok());
    }

    #[test]
    fn a_drive_sets_its_own_current_limit() {
        let net = network();
        let build = |max_current_a: f64| {
            NetworkObserverBuilder::new(&net, [1])
                .critical_c([Some(155.0), Some(80.0), None])
                .settings(NetworkSettings {
                    max_current_a,
                    ..NetworkSettings::DEFAULT
                })
                .build::<4>()
        };
        let tick = |observer: &NetworkObserver<3, 1, 1, 4, 1>| {
            let mut state = observer.state(&[20.0; 3], &[20.0]);
            let inputs = NetworkInputs {
                currents_a: [400.0],
                boundary_c: [20.0],
                readings: [None],
                now_us: 1000,
                elapsed_us: 1000,
            };
            observer.tick(&mut state, &inputs).flags
        };
        // 400 A: clamped (and flagged) at the default 100 A, taken at 500 A.
        let default = build(100.0).expect("builds");
        assert!(tick(&default).contains(crate::InputFlags::CURRENT_CLAMPED));
        let drive = build(500.0).expect("builds");
        assert!(tick(&drive).is_clean());
        assert!(matches!(
            build(f64::NAN),
            Err(BuildError::InvalidParameter {
                name: "max_current_a"
            })
        ));
    }

    #[test]
    fn written_rust_names_every_table() {
        struct Text {
            buf: [u8; 32 * 1024],
            len: usize,
        }
        impl Write for Text {
            fn write_str(&mut self, s: &str) -> fmt::Result {
                let end = self.len + s.len();
                self.buf
                    .get_mut(self.len..end)
                    .ok_or(fmt::Error)?
                    .copy_from_slice(s.as_bytes());
                self.len = end;
                Ok(())
            }
        }
        let mut text = Text {
            buf: [0; 32 * 1024],
            len: 0,
        };
        parts().write_rust(&mut text).expect("fits");
        let text = core::str::from_utf8(&text.buf[..text.len]).expect("utf-8");
        for field in [
            "critical_c: [Some(155.0), Some(80.0), None]",
            "sensor_nodes: [1]",
            "phi_minus_i:",
            "innovation_cov:",
            "gain_boundary:",
            "slowest_time_constant_s:",
        ] {
            assert!(text.contains(field), "{field} missing");
        }
        assert!(!text.contains("NaN") && !text.contains("inf"));
    }
}
