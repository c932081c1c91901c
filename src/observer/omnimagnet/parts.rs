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
//! The filter's configuration, the sensor checks, the gain, the predictor
//! and the protection are tables the network observer's parts share
//! (`observer::tables`: each read, checked, copied and written once); the
//! linear model of a step ([`MeanModelTables`], its inputs in one `G`) and
//! the rest of the configuration are the Omnimagnet's own.
//!
//! The tick takes `&self`, so it runs on `&'static OmniObserver` in flash
//! and only the [`OmniObserverState`](super::OmniObserverState) is in RAM.

use core::fmt::{self, Write};

use super::{check_refresh, OmniObserver, ALARM_NODES};
use crate::error::BuildError;
use crate::input::ScalarLimits;
use crate::observer::consistency::RefreshWatchdog;
use crate::observer::tables::{
    below, bound_rows, finite, finite_rows, invalid, upper_bound, write_alarm, write_checks,
    write_clock, write_gain, write_kalman, write_limiter, write_predictor, AlarmTables,
    ChecksTables, ClockTables, Fields, KalmanTables, LimiterTables, Literal,
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
    /// The filter's configuration but for `G`.
    pub kalman: KalmanTables<STATES, THERMOCOUPLES>,
    /// `G`: \[K/J\], dimensionless and \[K\] columns (see [`MeanModel`]).
    pub g: [[f32; INPUTS]; STATES],
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
    /// The sensor checks.
    pub checks: ChecksTables<SOLENOIDS>,
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
                kalman: KalmanTables::of(k),
                g: rows(&k.g),
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
            checks: ChecksTables::of(
                &self.band,
                &self.bias_bound,
                &self.stuck_test,
                self.silent_after_us,
            ),
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
    /// a non-finite table entry (`filter`, `filter.kalman`, `filter.gain`,
    /// `filter.model`, `protection`, `protection.predictor`, `shadow`), an
    /// index out of range (`filter.solenoid_nodes`, `filter.kalman`'s
    /// `walk_from`, `protection.predictor`), a clock the tick cannot run
    /// (`clock.step_us`, `clock.max_steps_per_tick`,
    /// `clock.frozen_flag_ticks`, `clock.frozen_loss_ticks`), a protection
    /// period below four catch-ups of the clock or a phase beyond it
    /// (`protect_period_us`, `protect_phase_us`), a zero shadow block
    /// (`shadow_block_steps`), sensor checks with a non-finite band, a NaN
    /// bias bound or stuck threshold or a negative tolerance (`checks`), a
    /// non-finite input limit (`limits`), or a time-varying filter
    /// (`filter.settings`);
    /// [`BuildError::ModelRefreshRequired`] for a sensor set that needs a
    /// model refresh the parts do not declare, as [`OmniObserver::new`].
    pub const fn from_parts(parts: &OmniParts) -> Result<Self, BuildError> {
        let f = &parts.filter;
        if !matches!(f.settings.mode, GainMode::SteadyState) || f.settings.warmup_corrections != 0 {
            return Err(invalid("filter.settings"));
        }
        if !f.kalman.is_valid() {
            return Err(invalid("filter.kalman"));
        }
        if !(finite_rows(&f.g) && finite_rows(&f.resistance) && f.dt_s.is_finite() && f.dt_s > 0.0)
        {
            return Err(invalid("filter"));
        }
        if !below(&f.solenoid_nodes, NODES) {
            return Err(invalid("filter.solenoid_nodes"));
        }
        if !f.gain.is_finite() {
            return Err(invalid("filter.gain"));
        }
        if !f.model.is_finite() {
            return Err(invalid("filter.model"));
        }
        if !parts.shadow.is_finite() {
            return Err(invalid("shadow"));
        }
        if !parts.checks.is_valid() {
            return Err(invalid("checks"));
        }
        if !(parts.max_current_a.is_finite()
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
                kalman: f.kalman.config(matrix(&f.g)),
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
            band: parts.checks.band(),
            bias_bound: parts.checks.bias_bound(),
            stuck_test: parts.checks.stuck_test(),
            silent_after_us: parts.checks.silent_after_us,
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
            checks,
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
        write_checks(&mut w, checks)?;
        w.field("fingerprint", fingerprint)?;
        w.field("plant_fingerprint", plant_fingerprint)?;
        w.field("model_stale_after_steps", model_stale_after_steps)?;
        w.close(true)
    }
}

fn write_filter(out: &mut Fields<'_>, f: &FilterTables) -> fmt::Result {
    let FilterTables {
        settings,
        kalman,
        g,
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
    write_kalman(&mut w, "kalman", kalman)?;
    w.table("g", g)?;
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
