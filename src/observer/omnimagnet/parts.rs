//! The Omnimagnet observer as data, for a configuration in flash.
//!
//! [`OmniObserver::new`] linearises the nonlinear model, solves the
//! steady-state gain (Riccati), decomposes the network for the predictor
//! and builds the protection: tens of KiB of stack in `f64`, and a
//! 16 KiB configuration that, built on the target, lives in RAM. Nothing
//! of it depends on the device's run: it can be solved once on a host.
//!
//! * [`OmniObserver::parts`] (host, or anywhere `new` runs) reads every
//!   table of a built observer into an [`OmniParts`]: plain row-major
//!   arrays of the `f32` values the tick reads, the integers and the
//!   settings, nothing computed again;
//! * [`OmniParts::write_rust`] writes them as a Rust expression (what
//!   `coil-thermal codegen --device omnimagnet` puts in
//!   `examples/generated/omnimagnet.rs`); floats as the shortest text that
//!   reads back to the same bits;
//! * [`OmniObserver::from_parts`] is a `const fn`: it checks the tables
//!   (finite where the tick needs it, indices in range) and copies them
//!   into the configuration's types, transposing each matrix into
//!   nalgebra's column-major storage
//!   ([`SMatrix::from_array_storage`]). So
//!   `static OMNI: OmniObserver = match OmniObserver::from_parts(&PARTS) { .. }`
//!   is evaluated by the compiler: the configuration is in `.rodata`
//!   (flash), never built on the target, and a bad table is a compile
//!   error naming it.
//!
//! Why copies and no arithmetic: `from_parts` must give the observer `new`
//! gives, to the bit, and any value computed again (`1 / taper_k`, a
//! square root, an `f64` cast) could round differently from the path that
//! made it. The snapshot fingerprint is carried too: its hash is not a
//! `const fn`, and the host round trip (`host-tests/tests/omnimagnet_codegen.rs`)
//! checks that the generated configuration is `new`'s, fingerprint
//! included, and runs both side by side.
//!
//! The tick takes `&self`, so it runs on `&'static OmniObserver` in flash
//! and only the [`OmniObserverState`](super::OmniObserverState) is in RAM.

use core::fmt::{self, Write};

use super::{check_refresh, OmniObserver, ALARM_NODES, PREDICTOR_POINTS};
use crate::error::BuildError;
use crate::filter::{GatePolicy, KalmanConfig};
use crate::input::ScalarLimits;
use crate::observer::consistency::{Band, BiasBound, RefreshWatchdog, StuckTest};
use crate::observer::tables::{
    below, bound_rows, finite, finite_rows, invalid, upper_bound, write_alarm, write_clock,
    write_limiter, AlarmTables, ClockTables, Fields, LimiterTables, Literal,
};
use crate::observer::tables::{matrix, rows, vector, GainTables, PredictorTables};
use crate::omnimagnet::observer::{
    GainMode, MeanModel, ObserverConfig, ObserverSettings, INPUTS, STATES,
};
use crate::omnimagnet::{NODES, SOLENOIDS, THERMOCOUPLES};

const ALARMS: usize = ALARM_NODES.len();

/// The linear model of one step (see [`MeanModel`]), rows first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanModelTables {
    /// `Ad - I` (dimensionless).
    pub phi_minus_i: [[f32; NODES]; NODES],
    /// Per solenoid `Bd_p` \[K/J\], `Gd` (dimensionless), the constant term
    /// \[K\].
    pub g: [[f32; INPUTS]; NODES],
    /// The operating point \[degC\].
    pub origin_c: [f32; NODES],
    /// Step \[s\].
    pub dt_s: f64,
}

/// The steady-state filter (see [`ObserverConfig`]), rows first.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterTables {
    /// The settings it was solved with.
    pub settings: ObserverSettings,
    /// `F` (dimensionless; \[K/W\] in the bias columns).
    pub f: [[f32; STATES]; STATES],
    /// `G`: \[K/J\], dimensionless and \[K\] columns (see [`MeanModel`]).
    pub g: [[f32; INPUTS]; STATES],
    /// `H^T` (dimensionless).
    pub ht: [[f32; THERMOCOUPLES]; STATES],
    /// Process noise `Q` \[K^2, W^2\].
    pub q: [[f32; STATES]; STATES],
    /// Measurement noise variances \[K^2\].
    pub r: [f32; THERMOCOUPLES],
    /// The gate's threshold on `nu^2 / S` (dimensionless; `+inf`: off).
    pub gate_threshold: f32,
    /// Consecutive rejections before a sensor is suspect.
    pub suspect_after: u16,
    /// Consecutive all-rejected corrections before the recovery.
    pub recover_after: u16,
    /// Variances added on recovery \[K^2, W^2\].
    pub recovery_variance: [f32; STATES],
    /// First state whose row of `F` is a unit row.
    pub walk_from: usize,
    /// The steady-state gain and covariances.
    pub gain: GainTables<STATES, THERMOCOUPLES>,
    /// The build-time model of the predict.
    pub model: MeanModelTables,
    /// Each solenoid's `R(0 degC)` \[ohm\] and `dR/dT` \[ohm/K\].
    pub resistance: [[f32; 2]; SOLENOIDS],
    /// The node of each solenoid's winding.
    pub solenoid_nodes: [usize; SOLENOIDS],
    /// Model steps per correction the gain was solved for.
    pub period: u32,
    /// Model step \[s\].
    pub dt_s: f64,
    /// The gain was solved for another model.
    pub gain_stale: bool,
}

/// The alarm, the limiter and the upper bound (see
/// [`crate::protect`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProtectionTables {
    /// The alarm of each [`ALARM_NODES`] element.
    pub alarm: AlarmTables<f32, ALARMS>,
    /// The limiter of each solenoid's current.
    pub limiter: LimiterTables<f32, SOLENOIDS>,
    /// Each node's upper bound: the share of its rise `f`
    /// (dimensionless), `f / (1 + f)` and its offset \[K\].
    pub bound: [[f32; 3]; NODES],
    /// The time-to-limit predictor (one boundary, the ambient).
    pub predictor: PredictorTables<NODES, 1, SOLENOIDS>,
}

/// An [`OmniObserver`] as data (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OmniParts {
    /// The Kalman filter.
    pub filter: FilterTables,
    /// The protection.
    pub protection: ProtectionTables,
    /// The unfused shadow model (one correction period per step).
    pub shadow: MeanModelTables,
    /// The step clock.
    pub clock: ClockTables,
    /// Largest plausible current \[A\].
    pub max_current_a: f32,
    /// Lowest plausible ambient \[degC\].
    pub min_temp_c: f32,
    /// Highest plausible ambient \[degC\].
    pub max_temp_c: f32,
    /// Oldest reading fused \[us\].
    pub max_reading_age_us: u32,
    /// A protection cycle \[us\].
    pub protect_period_us: u32,
    /// The cycles' phase \[us\].
    pub protect_phase_us: u32,
    /// The control loop's tick \[us\] (a tick stepping longer is busy).
    pub loop_period_us: u32,
    /// One predictor slice \[us\]: the protection cycle over the slices
    /// per cycle.
    pub predictor_slice_us: u32,
    /// Elements the predictor evaluates per slice (`u32::MAX`: all).
    pub predictor_elements_per_tick: u32,
    /// Model steps per shadow step.
    pub shadow_block_steps: u32,
    /// The consistency band's fixed part \[K\] and share of the rise.
    pub band: [f32; 2],
    /// The band on the heat-input biases \[W\] (`+inf`: unbounded).
    pub bias_offset_w: [f32; SOLENOIDS],
    /// The bias bound's share of the Joule power (dimensionless).
    pub bias_fraction: f32,
    /// The stuck test's threshold \[K\].
    pub stuck_threshold_k: f32,
    /// The stuck test's tolerance for an unchanged reading \[K\].
    pub stuck_tolerance_k: f32,
    /// The stuck test's window (readings).
    pub stuck_window: u32,
    /// No reading for this long makes a thermocouple silent \[us\].
    pub silent_after_us: u32,
    /// The snapshot fingerprint of this configuration.
    pub fingerprint: u32,
    /// The fingerprint of the nonlinear model it was built from.
    pub plant_fingerprint: u32,
    /// Model steps without an `install_model` after which the declared
    /// model refresh is stale (`u32::MAX`: none declared; see
    /// [`OmniSettings::model_refresh_s`](super::OmniSettings::model_refresh_s)).
    pub model_stale_after_steps: u32,
}

impl MeanModelTables {
    fn of(model: &MeanModel<f32>) -> Self {
        Self {
            phi_minus_i: rows(&model.phi_minus_i),
            g: rows(&model.g),
            origin_c: model.origin_c.into(),
            dt_s: model.dt_s,
        }
    }

    const fn is_finite(&self) -> bool {
        finite_rows(&self.phi_minus_i)
            && finite_rows(&self.g)
            && finite(&self.origin_c)
            && self.dt_s.is_finite()
            && self.dt_s > 0.0
    }

    const fn model(&self) -> MeanModel<f32> {
        MeanModel {
            phi_minus_i: matrix(&self.phi_minus_i),
            g: matrix(&self.g),
            origin_c: vector(&self.origin_c),
            dt_s: self.dt_s,
        }
    }
}

impl GainTables<STATES, THERMOCOUPLES> {
    const fn is_finite(&self) -> bool {
        finite_rows(&self.gain)
            && finite_rows(&self.prior)
            && finite_rows(&self.posterior)
            && finite(&self.innovation_var)
            && finite_rows(&self.prior_ht)
            && finite_rows(&self.innovation_cov)
    }
}

impl PredictorTables<NODES, 1, SOLENOIDS> {
    const fn is_valid(&self) -> bool {
        below(&self.winding_node, NODES)
            && self.points_per_tick >= 1
            && self.points_per_tick <= PREDICTOR_POINTS + 1
            && finite(&self.grid_s)
            && finite_rows(&self.decay)
            && finite(&self.lambda_per_s)
            && finite_rows(&self.v)
            && finite_rows(&self.v_inv)
            && finite_rows(&self.gain_power)
            && finite_rows(&self.mode_gain_power)
            && finite_rows(&self.gain_boundary)
            && finite_rows(&self.mode_gain_boundary)
            && finite(&self.offset_c)
            && finite(&self.mode_offset)
            && finite(&self.winding_r_at_0c_ohm)
            && finite(&self.winding_slope_ohm_per_k)
            && self.tick_s.is_finite()
            && self.tick_s > 0.0
            && self.slowest_time_constant_s.is_finite()
    }
}

impl OmniObserver {
    /// Every table of this configuration as data (see the module docs):
    /// `from_parts(&self.parts())` is this observer, to the bit.
    pub fn parts(&self) -> OmniParts {
        let c = &self.filter;
        let k = &c.kalman;
        let gain = &c.gain;
        let (a, l, p) = (&self.alarm, &self.limiter, &self.predictor);
        OmniParts {
            filter: FilterTables {
                settings: c.settings,
                f: rows(&k.f),
                g: rows(&k.g),
                ht: rows(&k.ht),
                q: rows(&k.q),
                r: k.r.into(),
                gate_threshold: k.gate.threshold,
                suspect_after: k.gate.suspect_after,
                recover_after: k.gate.recover_after,
                recovery_variance: k.recovery_variance.into(),
                walk_from: k.walk_from,
                gain: GainTables::of(gain),
                model: MeanModelTables::of(&c.model),
                resistance: c.resistance.map(|(r0, slope)| [r0, slope]),
                solenoid_nodes: c.solenoid_nodes,
                period: c.period,
                dt_s: c.dt_s,
                gain_stale: c.gain_stale,
            },
            protection: ProtectionTables {
                alarm: AlarmTables::of(a),
                limiter: LimiterTables::of(l),
                bound: bound_rows(&self.bound),
                predictor: PredictorTables::of(p),
            },
            shadow: MeanModelTables::of(&self.shadow),
            clock: ClockTables::of(&self.clock),
            max_current_a: self.limits.max_current_a,
            min_temp_c: self.limits.min_temp_c,
            max_temp_c: self.limits.max_temp_c,
            max_reading_age_us: self.max_reading_age_us,
            protect_period_us: self.protect_period_us,
            protect_phase_us: self.protect_phase_us,
            loop_period_us: self.loop_period_us,
            predictor_slice_us: self.predictor_slice_us,
            predictor_elements_per_tick: u32::try_from(self.predictor.elements_per_tick)
                .unwrap_or(u32::MAX),
            shadow_block_steps: self.shadow_block_steps,
            band: [self.band.offset_k, self.band.fraction],
            bias_offset_w: self.bias_bound.offset_w,
            bias_fraction: self.bias_bound.fraction,
            stuck_threshold_k: self.stuck_test.threshold_k,
            stuck_tolerance_k: self.stuck_test.tolerance_k,
            stuck_window: self.stuck_test.window,
            silent_after_us: self.silent_after_us,
            fingerprint: self.fingerprint,
            plant_fingerprint: self.plant_fingerprint,
            model_stale_after_steps: self.refresh.bound_steps(),
        }
    }

    /// The observer of `parts`, typically written by
    /// `coil-thermal codegen --device omnimagnet`: a `const fn`, so a
    /// `static` initialised with it is evaluated by the compiler and lands
    /// in flash. Copies the tables (no arithmetic: see the module docs).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the first inconsistent part:
    /// a non-finite table entry (`filter`, `filter.gain`, `filter.model`,
    /// `protection`, `protection.predictor`, `shadow`), an index out of
    /// range (`filter.solenoid_nodes`, `filter.walk_from`,
    /// `predictor`), a clock the tick cannot run (`clock.step_us`,
    /// `clock.max_steps_per_tick`, `clock.frozen_flag_ticks`,
    /// `clock.frozen_loss_ticks`), a protection period below four
    /// catch-ups of the clock or a phase beyond it
    /// (`protect_period_us`, `protect_phase_us`), a zero shadow block
    /// (`shadow_block_steps`), a NaN bias bound (`bias_offset_w`) or
    /// input limit (`limits`), or a time-varying filter (`filter.settings`);
    /// [`BuildError::ModelRefreshRequired`] for a sensor set that needs a
    /// model refresh the parts do not declare, as [`OmniObserver::new`].
    pub const fn from_parts(parts: &OmniParts) -> Result<Self, BuildError> {
        let f = &parts.filter;
        if !matches!(f.settings.mode, GainMode::SteadyState) || f.settings.warmup_corrections != 0 {
            return Err(invalid("filter.settings"));
        }
        if !(finite_rows(&f.f)
            && finite_rows(&f.g)
            && finite_rows(&f.ht)
            && finite_rows(&f.q)
            && finite(&f.r)
            && !f.gate_threshold.is_nan()
            && finite(&f.recovery_variance)
            && finite_rows(&f.resistance)
            && f.dt_s.is_finite()
            && f.dt_s > 0.0)
        {
            return Err(invalid("filter"));
        }
        if !below(&f.solenoid_nodes, NODES) {
            return Err(invalid("filter.solenoid_nodes"));
        }
        if f.walk_from > STATES {
            return Err(invalid("filter.walk_from"));
        }
        if !f.gain.is_finite() {
            return Err(invalid("filter.gain"));
        }
        if !f.model.is_finite() {
            return Err(invalid("filter.model"));
        }
        if !parts.shadow.is_finite() || !finite(&parts.band) {
            return Err(invalid("shadow"));
        }
        // An unbounded bias is `+inf`; NaN would silently drop the bound.
        let mut m = 0;
        while m < SOLENOIDS {
            if parts.bias_offset_w[m].is_nan() {
                return Err(invalid("bias_offset_w"));
            }
            m += 1;
        }
        if !(parts.bias_fraction.is_finite()
            && !parts.stuck_threshold_k.is_nan()
            && parts.stuck_tolerance_k.is_finite()
            && parts.stuck_tolerance_k >= 0.0
            && parts.max_current_a.is_finite()
            && parts.min_temp_c.is_finite()
            && parts.max_temp_c.is_finite())
        {
            return Err(invalid("limits"));
        }
        let p = &parts.protection;
        if !(p.alarm.is_finite() && p.limiter.is_finite() && finite_rows(&p.bound)) {
            return Err(invalid("protection"));
        }
        if !p.predictor.is_valid() {
            return Err(invalid("protection.predictor"));
        }
        let clock = match parts.clock.clock() {
            Ok(clock) => clock,
            Err(e) => return Err(e),
        };
        if parts.predictor_slice_us == 0
            || !parts
                .protect_period_us
                .is_multiple_of(parts.predictor_slice_us)
        {
            return Err(invalid("predictor_slice_us"));
        }
        // As `new`: a cycle takes at most a put-off slice, the slices, the
        // alarm and the limiter, each up to `max_steps_per_tick` steps late.
        let slices = (parts.protect_period_us / parts.predictor_slice_us) as u64;
        let least_period_us =
            clock.step_us as u64 * clock.max_steps_per_tick as u64 * (2 * slices + 2);
        if (parts.protect_period_us as u64) < least_period_us {
            return Err(invalid("protect_period_us"));
        }
        if parts.loop_period_us == 0 {
            return Err(invalid("loop_period_us"));
        }
        if parts.predictor_elements_per_tick == 0 {
            return Err(invalid("predictor_elements_per_tick"));
        }
        if parts.protect_phase_us >= parts.protect_period_us {
            return Err(invalid("protect_phase_us"));
        }
        if parts.shadow_block_steps == 0 {
            return Err(invalid("shadow_block_steps"));
        }
        if let Err(e) = check_refresh(
            &f.settings.sensors,
            parts.model_stale_after_steps,
            parts.clock.step_us,
        ) {
            return Err(e);
        }

        let g = &f.gain;
        let t = &p.predictor;
        let mut resistance = [(0.0, 0.0); SOLENOIDS];
        let mut m = 0;
        while m < SOLENOIDS {
            resistance[m] = (f.resistance[m][0], f.resistance[m][1]);
            m += 1;
        }
        Ok(Self {
            filter: ObserverConfig {
                settings: f.settings,
                kalman: KalmanConfig {
                    f: matrix(&f.f),
                    g: matrix(&f.g),
                    ht: matrix(&f.ht),
                    q: matrix(&f.q),
                    r: vector(&f.r),
                    gate: GatePolicy {
                        threshold: f.gate_threshold,
                        suspect_after: f.suspect_after,
                        recover_after: f.recover_after,
                    },
                    recovery_variance: vector(&f.recovery_variance),
                    walk_from: f.walk_from,
                },
                gain: g.gain(),
                model: f.model.model(),
                resistance,
                solenoid_nodes: f.solenoid_nodes,
                period: f.period,
                dt_s: f.dt_s,
                gain_stale: f.gain_stale,
            },
            alarm: p.alarm.config(),
            limiter: p.limiter.config(),
            // `u32::MAX` stands for "all" (`new`'s `usize::MAX`).
            predictor: t.predictor(if parts.predictor_elements_per_tick == u32::MAX {
                usize::MAX
            } else {
                parts.predictor_elements_per_tick as usize
            }),
            bound: upper_bound(&p.bound),
            clock,
            limits: ScalarLimits {
                max_current_a: parts.max_current_a,
                min_temp_c: parts.min_temp_c,
                max_temp_c: parts.max_temp_c,
            },
            max_reading_age_us: parts.max_reading_age_us,
            step_us: parts.clock.step_us,
            protect_period_us: parts.protect_period_us,
            protect_phase_us: parts.protect_phase_us,
            loop_period_us: parts.loop_period_us,
            held_slices_per_tick: OmniObserver::held_slices_per_tick(
                parts.clock.step_us,
                parts.loop_period_us,
                parts.shadow_block_steps,
                parts.protect_period_us,
                parts.protect_period_us / parts.predictor_slice_us,
            ),
            predictor_slice_us: parts.predictor_slice_us,
            fingerprint: parts.fingerprint,
            plant_fingerprint: parts.plant_fingerprint,
            shadow: parts.shadow.model(),
            shadow_block_steps: parts.shadow_block_steps,
            band: Band {
                offset_k: parts.band[0],
                fraction: parts.band[1],
            },
            bias_bound: BiasBound {
                offset_w: parts.bias_offset_w,
                fraction: parts.bias_fraction,
            },
            stuck_test: StuckTest {
                threshold_k: parts.stuck_threshold_k,
                window: parts.stuck_window,
                tolerance_k: parts.stuck_tolerance_k,
            },
            silent_after_us: parts.silent_after_us,
            refresh: RefreshWatchdog::from_steps(parts.model_stale_after_steps),
        })
    }
}

impl Literal for GainMode {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        write!(
            out,
            "coil_thermal::omnimagnet::observer::GainMode::{self:?}"
        )
    }
}

fn write_model(out: &mut Fields<'_>, name: &str, m: &MeanModelTables) -> fmt::Result {
    let MeanModelTables {
        phi_minus_i,
        g,
        origin_c,
        dt_s,
    } = m;
    let mut w = out.nested(name, "observer::omnimagnet::MeanModelTables")?;
    w.table("phi_minus_i", phi_minus_i)?;
    w.table("g", g)?;
    w.field("origin_c", origin_c)?;
    w.field("dt_s", dt_s)?;
    w.close(false)
}

impl OmniParts {
    /// Writes these parts as a Rust expression of type [`OmniParts`] that
    /// names every type by its full path (`coil_thermal::`), for a
    /// `const` in a generated module. Reading it back gives these parts to
    /// the bit.
    ///
    /// # Errors
    /// Those of `out`.
    pub fn write_rust(&self, out: &mut dyn Write) -> fmt::Result {
        // Destructured whole, so that a field added to the parts (or to
        // the filter's settings) is a compile error here, not a field
        // silently left out of the generated file.
        let Self {
            filter,
            protection,
            shadow,
            clock,
            max_current_a,
            min_temp_c,
            max_temp_c,
            max_reading_age_us,
            protect_period_us,
            protect_phase_us,
            loop_period_us,
            predictor_slice_us,
            predictor_elements_per_tick,
            shadow_block_steps,
            band,
            bias_offset_w,
            bias_fraction,
            stuck_threshold_k,
            stuck_tolerance_k,
            stuck_window,
            silent_after_us,
            fingerprint,
            plant_fingerprint,
            model_stale_after_steps,
        } = self;
        let mut w = Fields::open(out, "observer::omnimagnet::OmniParts", 0)?;
        write_filter(&mut w, filter)?;
        write_protection(&mut w, protection)?;
        write_model(&mut w, "shadow", shadow)?;
        write_clock(&mut w, clock)?;
        w.field("max_current_a", max_current_a)?;
        w.field("min_temp_c", min_temp_c)?;
        w.field("max_temp_c", max_temp_c)?;
        w.field("max_reading_age_us", max_reading_age_us)?;
        w.field("protect_period_us", protect_period_us)?;
        w.field("protect_phase_us", protect_phase_us)?;
        w.field("loop_period_us", loop_period_us)?;
        w.field("predictor_slice_us", predictor_slice_us)?;
        w.field("predictor_elements_per_tick", predictor_elements_per_tick)?;
        w.field("shadow_block_steps", shadow_block_steps)?;
        w.field("band", band)?;
        w.field("bias_offset_w", bias_offset_w)?;
        w.field("bias_fraction", bias_fraction)?;
        w.field("stuck_threshold_k", stuck_threshold_k)?;
        w.field("stuck_tolerance_k", stuck_tolerance_k)?;
        w.field("stuck_window", stuck_window)?;
        w.field("silent_after_us", silent_after_us)?;
        w.field("fingerprint", fingerprint)?;
        w.field("plant_fingerprint", plant_fingerprint)?;
        w.field("model_stale_after_steps", model_stale_after_steps)?;
        w.close(true)
    }
}

fn write_filter(out: &mut Fields<'_>, f: &FilterTables) -> fmt::Result {
    let FilterTables {
        settings,
        f,
        g,
        ht,
        q,
        r,
        gate_threshold,
        suspect_after,
        recover_after,
        recovery_variance,
        walk_from,
        gain,
        model,
        resistance,
        solenoid_nodes,
        period,
        dt_s,
        gain_stale,
    } = f;
    let mut w = out.nested("filter", "observer::omnimagnet::FilterTables")?;
    write_settings(&mut w, settings)?;
    w.table("f", f)?;
    w.table("g", g)?;
    w.table("ht", ht)?;
    w.table("q", q)?;
    w.field("r", r)?;
    w.field("gate_threshold", gate_threshold)?;
    w.field("suspect_after", suspect_after)?;
    w.field("recover_after", recover_after)?;
    w.field("recovery_variance", recovery_variance)?;
    w.field("walk_from", walk_from)?;
    write_gain(&mut w, gain)?;
    write_model(&mut w, "model", model)?;
    w.field("resistance", resistance)?;
    w.field("solenoid_nodes", solenoid_nodes)?;
    w.field("period", period)?;
    w.field("dt_s", dt_s)?;
    w.field("gain_stale", gain_stale)?;
    w.close(false)
}

fn write_settings(out: &mut Fields<'_>, s: &ObserverSettings) -> fmt::Result {
    let ObserverSettings {
        sensors,
        thermocouple_sigma_k,
        node_noise_k2_per_s,
        bias_noise_w2_per_s,
        initial_common_sigma_k,
        initial_sigma_k,
        initial_bias_sigma_w,
        correction_period_s,
        gate_threshold,
        suspect_after,
        recover_after,
        mode,
        warmup_corrections,
    } = s;
    let mut w = out.nested("settings", "omnimagnet::observer::ObserverSettings")?;
    w.field("sensors", sensors)?;
    w.field("thermocouple_sigma_k", thermocouple_sigma_k)?;
    w.field("node_noise_k2_per_s", node_noise_k2_per_s)?;
    w.field("bias_noise_w2_per_s", bias_noise_w2_per_s)?;
    w.field("initial_common_sigma_k", initial_common_sigma_k)?;
    w.field("initial_sigma_k", initial_sigma_k)?;
    w.field("initial_bias_sigma_w", initial_bias_sigma_w)?;
    w.field("correction_period_s", correction_period_s)?;
    w.field("gate_threshold", gate_threshold)?;
    w.field("suspect_after", suspect_after)?;
    w.field("recover_after", recover_after)?;
    w.field("mode", mode)?;
    w.field("warmup_corrections", warmup_corrections)?;
    w.close(false)
}

fn write_gain(out: &mut Fields<'_>, g: &GainTables<STATES, THERMOCOUPLES>) -> fmt::Result {
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

fn write_protection(out: &mut Fields<'_>, p: &ProtectionTables) -> fmt::Result {
    let ProtectionTables {
        alarm,
        limiter,
        bound,
        predictor,
    } = p;
    let mut w = out.nested("protection", "observer::omnimagnet::ProtectionTables")?;
    write_alarm(&mut w, "alarm", alarm)?;
    write_limiter(&mut w, "limiter", limiter)?;
    w.table("bound", bound)?;
    write_predictor(&mut w, predictor)?;
    w.close(false)
}

fn write_predictor(out: &mut Fields<'_>, t: &PredictorTables<NODES, 1, SOLENOIDS>) -> fmt::Result {
    let PredictorTables {
        grid_s,
        decay,
        lambda_per_s,
        v,
        v_inv,
        gain_power,
        mode_gain_power,
        gain_boundary,
        mode_gain_boundary,
        offset_c,
        mode_offset,
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
    w.table("mode_gain_power", mode_gain_power)?;
    w.table("gain_boundary", gain_boundary)?;
    w.table("mode_gain_boundary", mode_gain_boundary)?;
    w.field("offset_c", offset_c)?;
    w.field("mode_offset", mode_offset)?;
    w.field("winding_node", winding_node)?;
    w.field("winding_r_at_0c_ohm", winding_r_at_0c_ohm)?;
    w.field("winding_slope_ohm_per_k", winding_slope_ohm_per_k)?;
    w.field("tick_s", tick_s)?;
    w.field("points_per_tick", points_per_tick)?;
    w.field("slowest_time_constant_s", slowest_time_constant_s)?;
    w.close(false)
}
