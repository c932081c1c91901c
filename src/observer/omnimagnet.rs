//! One observer per Omnimagnet: a thin adapter that composes the library's
//! pieces behind the same tick API as [`super::grid`].
//!
//! * model: [`Omnimagnet::linearize`] at one operating point, in `f32`;
//! * filter: steady-state Kalman ([`predict_mean`] every model step,
//!   [`update_steady`] when thermocouple readings arrive);
//! * protection: alarms on the wire and cover insulation of each solenoid
//!   (nodes 7 .. 12, [`ALARM_NODES`]), the current limiter on the three
//!   solenoid currents, and the sliced modal time-to-limit predictor.
//!
//! # Protection cycle
//!
//! A 1 ms step changes a solenoid by about 1e-4 K, so the protection need
//! not follow every step: it runs once every
//! [`OmniSettings::protect_period_steps`] model steps (default 16 ms), one
//! stage per tick so that no tick carries more than one: a predictor slice
//! (one horizon), then the alarm, then the limiter. Between cycles the
//! outputs stand, except the times to limit, which are aged every tick. The
//! slice is put off by one tick when that tick also corrects or catches up
//! (never twice in a row), so a correction tick does not carry the most
//! expensive stage. The limits lag the model by at most a cycle and three
//! ticks (20 ms at the defaults, against time constants of seconds), and the
//! alarm's debounce and event stamps count cycles, not ticks.
//!
//! The predictor is built for one slice per cycle (`tick_s` = the cycle)
//! and is fed the largest current of each solenoid since its last slice, so
//! its conservative bound still covers currents that vary within a cycle.
//! Each slice ages its answers by one cycle; the real time it lags behind
//! (a put-off slice, a catch-up, dropped time) is counted and subtracted
//! from the published times to limit, so they stay never later than the
//! model's.
//!
//! It does not re-linearise: a full Omnimagnet observer with re-linearisation
//! lives in `omnimagnet::observer`, and this adapter is meant to be replaced
//! by it; only the tick API here is meant to last.
//!
//! # Readings
//!
//! Each thermocouple reading arrives on its own, as a [`TimedReading`]: the
//! driver's [`SensorResult`] and the time it was sampled on the same
//! microsecond clock as [`OmniInputs::now_us`]. A fault is not fused and is
//! reported as [`SensorStatus::Fault`]; a reading older than
//! `max_reading_age_us` is not fused and reported [`SensorStatus::TooOld`]; a
//! reading the innovation gate refuses is [`SensorStatus::Rejected`]. A late
//! reading younger than the limit is fused as if it were taken now: the
//! thermal time constants are seconds, a few milliseconds of age are within
//! the thermocouple's noise. The steady-state gain assumes a correction every
//! `reading_period_steps`; irregular arrivals make it slightly suboptimal, not
//! unstable (the gain is that of a stable filter, see [`crate::filter`]).
//!
//! # Limits per solenoid
//!
//! Solenoid `m` is limited by whichever of its wire (node `7 + 2m`) or cover
//! insulation (node `8 + 2m`) has less headroom to its alarm limit; the
//! limiter sees that headroom below the cover's limit.

use nalgebra::{SMatrix, SVector};

use super::clock::{ClockState, StepClock};
use super::grid::EVENT_CAPACITY;
use super::snapshot::{self, Fingerprint, RestorePolicy, SnapshotError, SnapshotMeta};
use crate::error::BuildError;
use crate::filter::{
    predict_mean, update_steady, KalmanConfig, SensorVerdict, SteadyEstimate, SteadyStateGain,
};
use crate::input::{InputFlags, InputLimits, ScalarLimits};
use crate::omnimagnet::{
    measurement_matrix, Omnimagnet, COVER_INSULATION_LIMIT_C, NODES, SOLENOIDS, THERMOCOUPLES,
    THERMOCOUPLE_NODES, WIRE_INSULATION_LIMIT_C,
};
use crate::protect::alarm::{AlarmBuilder, AlarmConfig, AlarmState, AlarmStatus};
use crate::protect::derating::DeratingRule;
use crate::protect::events::EventQueue;
use crate::protect::limiter::{CoilLimit, LimiterConfig};
use crate::protect::predict::{LimitPredictor, Operating, PredictorBuilder, PredictorState};
use crate::sensors::{SensorFault, SensorResult};

/// Filter inputs per step: the three `I^2` \[A^2\], the ambient \[degC\] and 1
/// (the constant term).
pub const INPUTS: usize = SOLENOIDS + 2;
/// Elements with an alarm: wire and cover insulation of each solenoid.
pub const ALARM_NODES: [usize; 6] = [7, 8, 9, 10, 11, 12];
/// Horizons of the time-to-limit predictor.
pub const PREDICTOR_POINTS: usize = 32;
/// A limit no Omnimagnet node without a critical temperature reaches
/// \[degC\], for the predictor (which needs a finite limit for every node).
const NO_LIMIT_C: f32 = 1000.0;

/// Build settings, each with a default.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OmniSettings {
    /// Model step \[us\]. Default 1000.
    pub step_us: u32,
    /// Catch-up bound, model steps per tick. Default 4.
    pub max_steps_per_tick: u32,
    /// Process noise variance per step and node \[K^2\]. Default `1e-6`.
    pub process_var_k2: f64,
    /// Thermocouple noise variance \[K^2\]. Default `0.0625` (0.25 K).
    pub reading_var_k2: f64,
    /// Model steps between corrections the steady gain is solved for.
    /// Default 500 (2 Hz readings at 1 ms).
    pub reading_period_steps: u32,
    /// Oldest reading still fused \[us\]. Default 100 000.
    pub max_reading_age_us: u32,
    /// Hardware current limit of each solenoid \[A\]. Default 8.
    pub hardware_limit_a: f64,
    /// Width of the limiter's taper band \[K\]. Default 10.
    pub taper_k: f64,
    /// Model steps per protection cycle (see the module docs), at least
    /// `4 max_steps_per_tick`: a cycle takes at most four ticks (a put-off
    /// slice and three stages), so it always ends before the next is due
    /// and the predictor's lag stays bounded. Default 16.
    pub protect_period_steps: u32,
}

impl Default for OmniSettings {
    fn default() -> Self {
        Self {
            step_us: 1000,
            max_steps_per_tick: 4,
            process_var_k2: 1e-6,
            reading_var_k2: 0.0625,
            reading_period_steps: 500,
            max_reading_age_us: 100_000,
            hardware_limit_a: 8.0,
            taper_k: 10.0,
            protect_period_steps: 16,
        }
    }
}

/// One thermocouple sample and when it was taken.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimedReading {
    /// The driver's result.
    pub result: SensorResult,
    /// Sample time on the tick's microsecond clock \[us\] (wrapping).
    pub sampled_at_us: u32,
}

/// What happened to one thermocouple this tick.
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
}

/// The inputs of one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OmniInputs {
    /// Solenoid currents \[A\]; NaN holds the last valid one.
    pub currents_a: [f32; SOLENOIDS],
    /// Ambient temperature \[degC\].
    pub ambient_c: f32,
    /// Fresh readings, one slot per thermocouple ([`THERMOCOUPLE_NODES`]).
    pub readings: [Option<TimedReading>; THERMOCOUPLES],
    /// Now, on the readings' microsecond clock \[us\] (wrapping).
    pub now_us: u32,
    /// Measured time since the previous tick \[us\].
    pub elapsed_us: u32,
}

/// What one tick produced (`Copy`, for [`Shared`](super::Shared)).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OmniOutputs {
    /// Node temperature estimates \[degC\] (see
    /// [`NODE_NAMES`](crate::omnimagnet::NODE_NAMES)).
    pub temps_c: [f32; NODES],
    /// Current limit per solenoid.
    pub limits: [CoilLimit<f32>; SOLENOIDS],
    /// Time to the alarm limit of each [`ALARM_NODES`] element \[s\]
    /// (`None`: never).
    pub time_to_limit_s: [Option<f32>; ALARM_NODES.len()],
    /// The alarm summary.
    pub alarm: AlarmStatus,
    /// What happened to each thermocouple's reading.
    pub sensors: [SensorStatus; THERMOCOUPLES],
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

/// The configuration of one Omnimagnet device.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone)]
pub struct OmniObserver {
    kalman: KalmanConfig<f32, NODES, INPUTS, THERMOCOUPLES>,
    gain: SteadyStateGain<f32, NODES, THERMOCOUPLES>,
    alarm: AlarmConfig<f32, 6>,
    limiter: LimiterConfig<f32, SOLENOIDS>,
    predictor: LimitPredictor<f32, NODES, 1, SOLENOIDS, PREDICTOR_POINTS>,
    clock: StepClock,
    limits: ScalarLimits<f32>,
    max_reading_age_us: u32,
    /// Model step \[us\].
    step_us: u32,
    /// Length of a protection cycle \[us\]: `protect_period_steps` steps.
    protect_period_us: u32,
    fingerprint: u32,
}

/// The per-device state.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone)]
pub struct OmniObserverState {
    /// The filter's estimate and gate memory.
    pub estimate: SteadyEstimate<f32, NODES, THERMOCOUPLES>,
    /// The alarm's state.
    pub alarm: AlarmState<f32, 6>,
    /// The predictor's sweep.
    pub predictor: PredictorState<f32, NODES, SOLENOIDS>,
    /// The time not yet simulated.
    pub clock: ClockState,
    /// Alarm events not yet drained.
    pub events: EventQueue<EVENT_CAPACITY>,
    held_currents_a: [f32; SOLENOIDS],
    held_ambient_c: f32,
    /// Largest held current magnitude of each solenoid since the last
    /// predictor slice \[A\].
    peak_currents_a: [f32; SOLENOIDS],
    /// Real time minus the predictor's own ageing \[us\]: how much older its
    /// answers are than it assumes.
    predictor_lag_us: u32,
    /// Next protection stage: 0 none, 1 predictor slice, 2 alarm, 3 limiter.
    stage: u8,
    /// The predictor slice was put off on the previous tick.
    slice_put_off: bool,
    outputs: OmniOutputs,
}

impl OmniObserverState {
    /// The outputs of the last tick.
    pub fn outputs(&self) -> &OmniOutputs {
        &self.outputs
    }
}

impl OmniObserver {
    /// Linearises `model` at `op_temps_c` and `ambient_c` \[degC\], builds the
    /// filter (solving the steady gain: ~20 KiB of stack in `f32`), the
    /// predictor and the protection.
    ///
    /// # Errors
    /// Those of the linearisation, the filter, the gain solver, the
    /// predictor, the alarm, the limiter and the clock, naming the parameter.
    pub fn new(
        model: &Omnimagnet,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        settings: &OmniSettings,
    ) -> Result<Self, BuildError> {
        let clock = StepClock::new(settings.step_us, settings.max_steps_per_tick)?;
        let dt_s = clock.step_s();
        let period = settings.protect_period_steps;
        let protect_period_us = period.checked_mul(settings.step_us);
        let Some(protect_period_us) =
            protect_period_us.filter(|_| period >= 4 * settings.max_steps_per_tick)
        else {
            return Err(BuildError::InvalidParameter {
                name: "protect_period_steps",
            });
        };
        let (kalman, gain, fingerprint) =
            Self::filter(model, op_temps_c, ambient_c, dt_s, settings)?;
        let rule = DeratingRule::omnimagnet();
        let (w, c) = (WIRE_INSULATION_LIMIT_C, COVER_INSULATION_LIMIT_C);
        let alarm = AlarmBuilder::new(&rule, [w, c, w, c, w, c]).build::<f32>()?;
        let limiter = LimiterConfig::new(
            [settings.hardware_limit_a; SOLENOIDS],
            settings.taper_k,
            0.0,
        )?;
        let predictor = Self::predictor(model, op_temps_c, ambient_c, dt_s * f64::from(period))?;
        Ok(Self {
            kalman,
            gain,
            alarm,
            limiter,
            predictor,
            clock,
            limits: InputLimits::default().to_scalar(),
            max_reading_age_us: settings.max_reading_age_us,
            step_us: settings.step_us,
            protect_period_us,
            fingerprint,
        })
    }

    // The build steps run in frames of their own (`inline(never)`): on an
    // MCU their matrix temporaries would otherwise add up in one frame.
    #[inline(never)]
    fn predictor(
        model: &Omnimagnet,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        cycle_s: f64,
    ) -> Result<LimitPredictor<f32, NODES, 1, SOLENOIDS, PREDICTOR_POINTS>, BuildError> {
        PredictorBuilder::new()
            .tick_s(cycle_s)
            .build(&model.network(op_temps_c, ambient_c)?)
    }

    #[inline(never)]
    #[allow(clippy::type_complexity)]
    fn filter(
        model: &Omnimagnet,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        dt_s: f64,
        settings: &OmniSettings,
    ) -> Result<
        (
            KalmanConfig<f32, NODES, INPUTS, THERMOCOUPLES>,
            SteadyStateGain<f32, NODES, THERMOCOUPLES>,
            u32,
        ),
        BuildError,
    > {
        let lin = model.linearize(op_temps_c, ambient_c, dt_s)?;
        let d = &lin.discrete;
        let mut g = SMatrix::<f64, NODES, INPUTS>::zeros();
        for i in 0..NODES {
            for m in 0..SOLENOIDS {
                g[(i, m)] = lin.bd_current_squared[(i, m)];
            }
            g[(i, SOLENOIDS)] = d.gd_boundary[(i, 0)];
            g[(i, SOLENOIDS + 1)] = d.dd[i];
        }
        let positive = |v: f64, name| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(BuildError::InvalidParameter { name })
            }
        };
        let q = positive(settings.process_var_k2, "process_var_k2")?;
        let r = positive(settings.reading_var_k2, "reading_var_k2")?;
        let kalman = KalmanConfig::new(
            d.ad.cast::<f32>(),
            g.cast::<f32>(),
            measurement_matrix().cast::<f32>(),
            SMatrix::<f32, NODES, NODES>::identity() * q as f32,
            SVector::<f32, THERMOCOUPLES>::repeat(r as f32),
        )?;
        let gain = SteadyStateGain::solve(&kalman, settings.reading_period_steps)?;
        let mut fingerprint = Fingerprint::new()
            .u32(settings.step_us)
            .f64s(d.ad.as_slice())
            .f64s(g.as_slice())
            .f64(q)
            .f64(r)
            .u32(settings.reading_period_steps);
        fingerprint = fingerprint
            .f64s(&[settings.hardware_limit_a, settings.taper_k])
            .u32(settings.protect_period_steps);
        Ok((kalman, gain, fingerprint.finish()))
    }

    /// The configuration fingerprint that snapshots carry.
    pub fn fingerprint(&self) -> u32 {
        self.fingerprint
    }

    /// The filter configuration.
    pub fn kalman(&self) -> &KalmanConfig<f32, NODES, INPUTS, THERMOCOUPLES> {
        &self.kalman
    }

    /// A state with every node at `temps_c` \[degC\] and the ambient at
    /// `ambient_c` \[degC\], no current, no alarm.
    pub fn state(&self, temps_c: &[f32; NODES], ambient_c: f32) -> OmniObserverState {
        let x = SVector::from_column_slice(temps_c);
        let op = self.operating(temps_c, &[0.0; SOLENOIDS], ambient_c);
        let mut state = OmniObserverState {
            estimate: SteadyEstimate::new(x),
            alarm: AlarmState::new(&self.alarm),
            predictor: PredictorState::new(&self.predictor, &op),
            clock: ClockState::default(),
            events: EventQueue::new(),
            held_currents_a: [0.0; SOLENOIDS],
            held_ambient_c: ambient_c,
            peak_currents_a: [0.0; SOLENOIDS],
            predictor_lag_us: 0,
            // The first ticks run a whole cycle: outputs valid from the start.
            stage: 1,
            slice_put_off: false,
            outputs: OmniOutputs {
                temps_c: *temps_c,
                limits: [CoilLimit::default(); SOLENOIDS],
                time_to_limit_s: [None; ALARM_NODES.len()],
                alarm: AlarmStatus::default(),
                sensors: [SensorStatus::NoReading; THERMOCOUPLES],
                corrected: false,
                flags: InputFlags::NONE,
                steps: 0,
                dropped_us: 0,
                tick: 0,
            },
        };
        // Limits valid from the first tick: without this the first ticks
        // (until the cycle reaches the limiter) would clamp every command to
        // the default zero-current limit.
        self.limit(&mut state.outputs, ambient_c);
        state
    }

    fn operating(
        &self,
        temps_c: &[f32; NODES],
        currents_a: &[f32; SOLENOIDS],
        ambient_c: f32,
    ) -> Operating<f32, NODES, 1, SOLENOIDS> {
        let alarm_limits = self.alarm.alarm_limits_c(ambient_c);
        let mut limits_c = [NO_LIMIT_C; NODES];
        for (node, limit) in ALARM_NODES.iter().zip(alarm_limits) {
            if let Some(slot) = limits_c.get_mut(*node) {
                *slot = limit;
            }
        }
        Operating {
            temps_c: *temps_c,
            currents_a: *currents_a,
            boundary_c: [ambient_c],
            limits_c,
        }
    }

    /// One controller tick: model steps from the elapsed time (each a filter
    /// predict), a correction if readings arrived, then at most one stage of
    /// the protection cycle (see the module docs). Bounded
    /// (`max_steps_per_tick` steps, one correction, one stage),
    /// allocation-free, panic-free.
    pub fn tick<'s>(
        &self,
        state: &'s mut OmniObserverState,
        inputs: &OmniInputs,
    ) -> &'s OmniOutputs {
        let steps = self.clock.advance(&mut state.clock, inputs.elapsed_us);
        let mut flags = steps.flags;
        flags |= self
            .limits
            .accept_currents(&inputs.currents_a, &mut state.held_currents_a);
        flags |= self
            .limits
            .accept_temperature(inputs.ambient_c, &mut state.held_ambient_c);
        let [i1, i2, i3] = state.held_currents_a;
        let u =
            SVector::<f32, INPUTS>::from([i1 * i1, i2 * i2, i3 * i3, state.held_ambient_c, 1.0]);
        for _ in 0..steps.steps {
            predict_mean(&self.kalman, &mut state.estimate.x, &u);
        }
        if steps.steps > 0 {
            for (peak, i) in state.peak_currents_a.iter_mut().zip(state.held_currents_a) {
                *peak = peak.max(i.abs());
            }
        }
        state.predictor_lag_us = state
            .predictor_lag_us
            .saturating_add(steps.steps.saturating_mul(self.step_us))
            .saturating_add(steps.dropped_us);
        let corrected = self.correct(state, inputs);
        let out = &mut state.outputs;
        out.corrected = corrected;
        out.temps_c.copy_from_slice(state.estimate.x.as_slice());

        if state.stage == 0 && state.predictor_lag_us >= self.protect_period_us {
            state.stage = 1;
        }
        let busy = corrected || steps.steps > 1;
        match state.stage {
            1 if busy && !state.slice_put_off => state.slice_put_off = true,
            1 => {
                state.slice_put_off = false;
                let op = self.operating(
                    &state.outputs.temps_c,
                    &state.peak_currents_a,
                    state.held_ambient_c,
                );
                state.predictor.tick(&self.predictor, &op);
                state.predictor_lag_us = state
                    .predictor_lag_us
                    .saturating_sub(self.protect_period_us);
                state.peak_currents_a = state.held_currents_a.map(f32::abs);
                state.stage = 2;
            }
            2 => {
                self.age_time_to_limit(state);
                let out = &mut state.outputs;
                let temps = alarm_temps(&out.temps_c);
                out.alarm = state.alarm.tick(
                    &self.alarm,
                    &temps,
                    state.held_ambient_c,
                    &out.time_to_limit_s,
                    &mut state.events,
                );
                state.stage = 3;
            }
            3 => {
                self.limit(&mut state.outputs, state.held_ambient_c);
                state.stage = 0;
            }
            _ => state.stage = 0,
        }
        self.age_time_to_limit(state);
        let out = &mut state.outputs;
        out.flags = flags;
        out.steps = steps.steps;
        out.dropped_us = steps.dropped_us;
        out.tick = out.tick.wrapping_add(1);
        &state.outputs
    }

    /// The predictor's answers for the [`ALARM_NODES`], made older by the
    /// time it lags behind (never later than its own answer).
    fn age_time_to_limit(&self, state: &mut OmniObserverState) {
        let lag_s = state.predictor_lag_us as f32 * 1e-6;
        let ttl = state.predictor.time_to_limit_s();
        for (time, node) in state.outputs.time_to_limit_s.iter_mut().zip(ALARM_NODES) {
            *time = ttl.get(node).copied().flatten().map(|t| {
                let left = t - lag_s;
                // NaN ("unknown") passes through.
                if left < 0.0 {
                    0.0
                } else {
                    left
                }
            });
        }
    }

    /// The limiter on the three solenoids at the present estimate.
    fn limit(&self, out: &mut OmniOutputs, ambient_c: f32) {
        let temps = alarm_temps(&out.temps_c);
        let limits_c = self.alarm.alarm_limits_c(ambient_c);
        let mut solenoid_c = [f32::NAN; SOLENOIDS];
        let mut solenoid_limit_c = [f32::NAN; SOLENOIDS];
        for (m, (t, l)) in solenoid_c
            .iter_mut()
            .zip(solenoid_limit_c.iter_mut())
            .enumerate()
        {
            let (Some(wire), Some(cover), Some(lw), Some(lc)) = (
                temps.get(2 * m),
                temps.get(2 * m + 1),
                limits_c.get(2 * m),
                limits_c.get(2 * m + 1),
            ) else {
                continue;
            };
            let (hw, hc) = (lw - wire, lc - cover);
            // NaN must reach the limiter (which then gives the floor), so no
            // `min`, which would let it lose.
            let headroom = if hw.is_finite() && hc.is_finite() {
                hw.min(hc)
            } else {
                f32::NAN
            };
            *t = lc - headroom;
            *l = *lc;
        }
        self.limiter
            .apply(&solenoid_c, &solenoid_limit_c, ambient_c, &mut out.limits);
    }

    /// Sorts the readings and runs one steady-state correction if any is
    /// usable; returns whether it ran.
    fn correct(&self, state: &mut OmniObserverState, inputs: &OmniInputs) -> bool {
        let mut z = [None; THERMOCOUPLES];
        let statuses = &mut state.outputs.sensors;
        for ((zj, status), reading) in z.iter_mut().zip(statuses.iter_mut()).zip(&inputs.readings) {
            *status = match reading {
                None => SensorStatus::NoReading,
                Some(TimedReading {
                    result: Err(fault), ..
                }) => SensorStatus::Fault(*fault),
                Some(TimedReading {
                    result: Ok(r),
                    sampled_at_us,
                }) => {
                    let age_us = inputs.now_us.wrapping_sub(*sampled_at_us);
                    if age_us > self.max_reading_age_us {
                        SensorStatus::TooOld { age_us }
                    } else if !r.temp_c.is_finite() {
                        SensorStatus::Fault(SensorFault::NotFinite)
                    } else {
                        *zj = Some(r.temp_c);
                        SensorStatus::NoReading
                    }
                }
            };
        }
        if z.iter().all(Option::is_none) {
            return false;
        }
        let report = update_steady(&self.kalman, &self.gain, &mut state.estimate, &z);
        for ((status, verdict), zj) in statuses.iter_mut().zip(report.verdicts).zip(z) {
            if zj.is_some() {
                *status = match verdict {
                    SensorVerdict::Fused { nis } => SensorStatus::Fused { nis },
                    SensorVerdict::Rejected { nis } => SensorStatus::Rejected { nis },
                    SensorVerdict::Missing => SensorStatus::NoReading,
                };
            }
        }
        true
    }

    /// Writes a snapshot of the node estimates and the latched shutdown,
    /// stamped `now_s` \[s\]; returns its length (`snapshot_len(16)` bytes).
    pub fn save(
        &self,
        state: &OmniObserverState,
        now_s: u32,
        out: &mut [u8],
    ) -> Result<usize, SnapshotError> {
        let mut temps_c = [0.0f32; NODES];
        temps_c.copy_from_slice(state.estimate.x.as_slice());
        let meta = SnapshotMeta {
            fingerprint: self.fingerprint,
            saved_at_s: now_s,
            shutdown_latched: state.alarm.shutdown_latched(),
        };
        snapshot::save(&temps_c, &meta, out)
    }

    /// Restores a state saved by [`Self::save`] with this configuration at
    /// most `max_age_s` \[s\] before `now_s` \[s\]. A latched shutdown stays
    /// latched.
    ///
    /// # Errors
    /// Why the snapshot was refused; start from
    /// [`Self::conservative_state`] then.
    pub fn restore(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
    ) -> Result<OmniObserverState, SnapshotError> {
        let policy = RestorePolicy {
            fingerprint: self.fingerprint,
            now_s,
            max_age_s,
        };
        let (temps_c, meta) = snapshot::restore::<NODES>(bytes, &policy)?;
        let mut state = self.state(&temps_c, ambient_c);
        if meta.shutdown_latched {
            state.alarm.latch_shutdown();
        }
        Ok(state)
    }

    /// The documented start when no snapshot can be trusted
    /// ([`snapshot::conservative_start`]): measured nodes at their readings
    /// \[degC\], every other node no cooler than the hottest reading or the
    /// ambient `ambient_c` \[degC\].
    pub fn conservative_state(
        &self,
        readings_c: &[Option<f32>; THERMOCOUPLES],
        ambient_c: f32,
    ) -> OmniObserverState {
        let temps = snapshot::conservative_start::<NODES, THERMOCOUPLES>(
            readings_c,
            &THERMOCOUPLE_NODES,
            ambient_c,
        );
        self.state(&temps, ambient_c)
    }
}

/// The estimates of the [`ALARM_NODES`] \[degC\].
fn alarm_temps(temps_c: &[f32; NODES]) -> [f32; ALARM_NODES.len()] {
    ALARM_NODES.map(|node| temps_c.get(node).copied().unwrap_or(f32::NAN))
}
