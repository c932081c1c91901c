//! Replay through the library's observer: a model file run by
//! [`RunTimeObserver`] (the MCU's network observer at the model's own size)
//! at fixed ticks (1 ms by default), each tick timed.
//!
//! # Sizes
//! The observer is the library's [`RunTimeObserver`]: the MCU's network
//! observer (the same tick, correction, protection and assembly) over
//! sizes read from the model file, built by
//! [`RunTimeObserver::build_at_run_time`] from the firmware's network of
//! the file ([`Model::firmware_network`]) at its own number of nodes,
//! boundaries, sources and sensors, with no cap below what memory allows
//! (test `the_library_observer_runs_a_300_node_motor_at_its_own_size`).
//!
//! # Open loop and fused thermocouples
//! The observer has one sensor per fused thermocouple; open loop one on
//! node 0 that never reads (a filter has a sensor). Without fused sensors
//! the estimate is the library's model step, the exact zero-order hold of
//! the network with `R(T)` at the estimate, run in `f32` on deviations
//! with the rounding carried. With `--measure` each column is a
//! thermocouple of its node: a row's reading is handed to the tick right
//! after the row (as a driver's sample taken then), and the library's
//! steady-state correction fuses it with the gain solved for the
//! firmware's correction period (`[observer] correction_period_s`).
//!
//! # The firmware's observer
//! The observer is built from a [`FirmwareConfig`] (see
//! [`crate::firmware`]): the model file's `[observer]` table over
//! `codegen`'s defaults, so the sensor noise, the correction period, the
//! heat-input biases (`bias_noise_w2_per_s`, `max_cooling_bias_fraction`,
//! `bias_sources`), the critical temperatures, the derating, the hardware
//! and plausible current limits are the ones `coil-thermal codegen`
//! flashes; `replay`'s flags that change one of them are named in its
//! output as overrides. Its protection (each node's upper bound, derated
//! alarm limit and time to limit, each source's current limit, the alarm's
//! events) is read after every tick ([`ObserverEstimator::protected`],
//! [`ObserverEstimator::take_events`]). Test `replay_is_the_firmware`: the
//! estimates, the upper bounds, the alarm limits, the input limits and the
//! events of `drive-3node` over its bench hour at 1.6 times its currents
//! are the generated module's to the bit (all 19 events on its ticks;
//! each cell of the trace is rounded once to `f32`, as the MCU receives
//! it). Without sensors the heat-input biases are off. A sensor corrects
//! the model's heat as well as its temperatures: a housing thermocouple
//! warms an unmeasured coil whose plant runs 40 % hotter than the model
//! (coil MSE 1.09 K^2, against 5.46 with the biases frozen and 31.9 open
//! loop; test `fused_replay`).
//!
//! When the sensors cannot see every source's bias (e.g. three sources and
//! one sensor; the HUST models, copper and speed losses, with one sensor),
//! a bias per source has no steady gain, and the builder's default
//! ([`BiasMode::Auto`](coil_thermal::observer::network::BiasMode)) gives
//! the sources one heat bias shared in proportion to their Joule power, as
//! the firmware generated from the file does: one sensor, one heat. Only
//! where even that does not converge does the replay refuse, with the
//! words `codegen` and `faults` use. `[observer] bias_sources` names the
//! sources whose bias is estimated (the others' stay exactly 0). Or the
//! firmware freezes every bias (`[observer] bias_noise_w2_per_s = 0`;
//! `replay --bias-noise-w2-per-s 0` replays so without editing the file:
//! temperatures corrected, no heat input estimated). Open loop (no sensor)
//! there is nothing to fuse and no bias.
//!
//! # Voltage-driven sources
//! A `[[source]]` driven by a PWM duty or a voltage (`drive = "pwm"` or
//! `"voltage"`) ticks through the library's `tick_voltage`, as the
//! generated module does: each row's duty and supply become a
//! `VoltageDrive` ([`FirmwareInputs::drive`], as the module's
//! `source_drives`), the winding draws `sqrt(D) V / R(T_est)` at the
//! estimate, and the library's rules flag, clamp or hold
//! a bad duty or supply (counted per rule: [`DriveFlagTicks`]). Its limit
//! is published in the input's own unit (a duty, or a voltage) from the
//! library's `drive_limit` ([`Protected::drive_limit`]). Test
//! `replay_voltage_firmware`: the 24 V valve over two hours with a dead
//! supply channel and a duty above 1 is the generated module's, within
//! 5e-7 K and 5e-7 of duty, the drive rules on the same ticks.
//!
//! # Currents above 100 A
//! The observer holds a current beyond its plausibility limit
//! (`[observer] max_current_a`, the firmware's) at that limit. Recorded
//! motor currents reach 400 A (the HUST motor): the open-loop estimator of
//! [`ObserverEstimator::new`] (no firmware) takes currents up to
//! [`OPEN_LOOP_MAX_CURRENT_A`].
//!
//! # Speed-dependent sources
//! A model file's power scales, speed factors and losses enter as the
//! generated module's `source_currents_a` computes them, in the same `f32`
//! operations ([`FirmwareInputs`]), on the same network
//! ([`Model::firmware_network`]: each power scale folded into its
//! resistance): a speed factor multiplies its source's current by the
//! `f32` root of `1 + a1 f + a2 f^2`, a speed or `[[loss]]` loss is a 1 ohm
//! source carrying `sqrt(P)`. The observer sees an ordinary network with
//! currents, and its estimates are the module's to the bit (test
//! `replay_firmware_filter`).

use std::time::Instant;

use anyhow::{anyhow, bail, Result};
use coil_thermal::observer::network::{
    NetworkInputsOf, NetworkSettings, RunTimeBiasMode, RunTimeObserver, RunTimeObserverState,
    RunTimeSpec, SensorKind,
};
use coil_thermal::observer::{SensorStatus, TimedReading};
use coil_thermal::{DriveFlags, Reading, SensorFault, VoltageDrive};

use crate::codegen::FirmwareInputs;
use crate::dynamic_network::DynNetwork;
use crate::firmware::FirmwareConfig;
use crate::model_file::Model;
use crate::observer::{Estimator, Measurement, TickClock};
use crate::sim::{plant_info, PlantInfo};
use nalgebra::Dyn;

/// The plausibility limit of [`ObserverEstimator::new`]'s currents \[A\]:
/// recorded motor currents reach 400 A (the HUST motor), beyond the
/// library's default limit (100 A) for a firmware.
pub const OPEN_LOOP_MAX_CURRENT_A: f64 = 1600.0;

/// An alarm event of the observer: the element (a node of the model, or
/// `None`) and what happened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventKindAt {
    /// The node, `None` for the ambient, a reset or the clock.
    pub node: Option<usize>,
    /// What happened.
    pub kind: coil_thermal::protect::events::EventKind,
    /// Time since the replay's start \[s\] (the end of the tick).
    pub since_start_s: f64,
    /// The node's upper bound at that tick \[degC\].
    pub upper_c: Option<f64>,
    /// The level it was compared with at that tick \[degC\]: the warning
    /// level for a warning, the derated alarm limit otherwise.
    pub limit_c: Option<f64>,
}

impl EventKindAt {
    /// A library event at `since_start_s` \[s\], with its node's upper bound
    /// `upper_c` and derated alarm limit `alarm_limit_c` \[degC\] (`None`
    /// without a node); a warning is reported against the warning level,
    /// `warning_margin_k` \[K\] below the limit.
    pub fn of(
        event: &coil_thermal::protect::events::AlarmEvent,
        since_start_s: f64,
        upper_c: Option<f32>,
        alarm_limit_c: Option<f32>,
        warning_margin_k: f32,
    ) -> Self {
        use coil_thermal::protect::events::EventKind;
        let below_k = match event.kind {
            EventKind::WarningRaised | EventKind::WarningCleared => warning_margin_k,
            _ => 0.0,
        };
        Self {
            node: event.element,
            kind: event.kind,
            since_start_s,
            upper_c: upper_c.map(f64::from),
            limit_c: alarm_limit_c.map(|l| f64::from(l - below_k)),
        }
    }
}

/// What the firmware's protection acts on, after a tick: per node of the
/// model and per source of its network.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Protected {
    /// Each node's protective upper bound \[degC\].
    pub upper_c: Vec<f64>,
    /// Each node's derated alarm limit at the present ambient \[degC\]
    /// (`None`: no critical temperature, not limited).
    pub alarm_limit_c: Vec<Option<f64>>,
    /// Each source's current limit \[A\] (its effective current: a speed
    /// factor's `sqrt` included).
    pub source_limit_a: Vec<f64>,
    /// Each voltage-driven source's limit in its input's own unit, from
    /// the library's `drive_limit` on the row's supply: the duty of a
    /// `pwm` input, the voltage \[V\] of a linear `voltage` input, as the
    /// generated module's `input_drive_limits` (`None`: a current-driven
    /// source, limited by `source_limit_a`).
    pub drive_limit: Vec<Option<f64>>,
    /// Each limited node's time to its alarm limit \[s\] (`None`: never,
    /// or not limited).
    pub time_to_limit_s: Vec<Option<f64>>,
    /// Some warning is raised.
    pub warning: bool,
    /// The shutdown is latched.
    pub shutdown: bool,
    /// Some predictive alarm is raised.
    pub predictive: bool,
}

impl Protected {
    /// Nothing published yet, for `nodes` nodes and `sources` sources.
    pub fn for_sizes(nodes: usize, sources: usize) -> Self {
        Self {
            upper_c: vec![0.0; nodes],
            alarm_limit_c: vec![None; nodes],
            source_limit_a: vec![0.0; sources],
            drive_limit: vec![None; sources],
            time_to_limit_s: vec![None; nodes],
            ..Self::default()
        }
    }
}

/// The firmware's network of `model` ([`Model::firmware_network`]) and
/// the spec of its observer as `codegen` builds it from `config` (the
/// critical temperatures, the hardware limit, the derating, the heat
/// biases the file names and their layout), with `settings`, on the
/// sensors `sensor_nodes` of `sensor_kinds`: what the replay and the fault
/// campaign build the library's [`RunTimeObserver`] from. A model without
/// a source gets one that never carries current, on node 0 (the library's
/// observer takes at least one current; no bias: [`Model::carries_bias`]
/// is false for it).
///
/// # Errors
/// A model without a boundary (the library's observer needs one, the
/// ambient).
pub(crate) fn firmware_observer_spec(
    model: &Model,
    config: &FirmwareConfig,
    settings: NetworkSettings,
    sensor_nodes: Vec<usize>,
    sensor_kinds: Vec<SensorKind>,
) -> Result<(DynNetwork, RunTimeSpec)> {
    let mut net = model.firmware_network();
    if net.sources().is_empty() {
        net.joule_source(0, coil_thermal::Resistance::constant(1.0))
            .map_err(|e| anyhow!("model `{}`: {e}", model.name))?;
    }
    if net.boundaries() == 0 {
        bail!(
            "model `{}` has no boundary: the library observer needs one (the ambient)",
            model.name
        );
    }
    let sources = net.sources().len();
    let spec = RunTimeSpec {
        sensor_nodes,
        sensor_kinds,
        critical_c: config.critical_c.clone(),
        incidence: None,
        hardware_limit_a: vec![config.hardware_limit_a; sources],
        rule: config.rule(),
        settings,
        // The model's sources carry their biases (those `[observer]
        // bias_sources` names, when given).
        bias_sources: (0..sources).map(|m| model.carries_bias(m)).collect(),
        bias_mode: if config.shared_bias {
            RunTimeBiasMode::Shared(vec![true; sources])
        } else {
            RunTimeBiasMode::Auto
        },
    };
    Ok((net, spec))
}

/// The library's observer of a model at its own size, with its state and
/// the inputs it holds between ticks.
struct AtModelSize {
    observer: RunTimeObserver,
    state: RunTimeObserverState,
    inputs: NetworkInputsOf<Dyn, Dyn, Dyn>,
    /// Each source's voltage drive; all `None` for a current-driven model.
    drives: Vec<Option<VoltageDrive>>,
    /// The drive rules that fired since [`AtModelSize::take_drive_flags`].
    drive_flags: DriveFlags,
    /// Readings waiting for the next tick.
    pending: Vec<Option<Result<f32, SensorFault>>>,
    /// The boundary the alarm takes as the ambient.
    ambient_boundary: usize,
}

impl AtModelSize {
    /// The observer of `network` built from `spec`, at the settings' origin
    /// with the warm-up (`name`: the model's, for the refusal's words).
    fn build(network: &DynNetwork, spec: &RunTimeSpec, name: &str) -> Result<Self> {
        let settings = spec.settings;
        let observer = RunTimeObserver::build_at_run_time(network, spec).map_err(|e| {
            // The same words as `codegen` and `faults` (one fix for one
            // refusal).
            match crate::codegen::build_hint::observer_build_hint(&e, settings.bias_noise_w2_per_s)
            {
                Some(hint) => anyhow!(
                    "the observer of model `{name}` does not build: {e}; {hint} \
                     (replay: --bias-noise-w2-per-s 0 freezes the biases without editing the file)"
                ),
                None => anyhow!("the observer of model `{name}` does not build: {e}"),
            }
        })?;
        let origin = settings.origin_c as f32;
        let (n, b, m) = (
            network.nodes(),
            network.boundaries(),
            network.sources().len(),
        );
        let p = spec.sensor_nodes.len();
        let state = observer.with_warm_up(observer.state(&vec![origin; n], &vec![origin; b]));
        Ok(Self {
            observer,
            state,
            inputs: NetworkInputsOf {
                currents_a: vec![0.0; m],
                boundary_c: vec![origin; b],
                readings: vec![None; p],
                now_us: 0,
                elapsed_us: 0,
            },
            pending: vec![None; p],
            drives: vec![None; m],
            drive_flags: DriveFlags::NONE,
            ambient_boundary: settings.ambient_boundary,
        })
    }

    /// A fresh state at `temps_c` and `boundary_c` \[degC\], with the
    /// warm-up.
    fn reset(&mut self, temps_c: &[f64], boundary_c: &[f64]) {
        self.inputs(&[], boundary_c);
        let temps: Vec<f32> = temps_c.iter().map(|t| *t as f32).collect();
        self.state = self
            .observer
            .with_warm_up(self.observer.state(&temps, &self.inputs.boundary_c));
        self.inputs.now_us = 0;
    }

    /// Sets the held inputs of the following ticks (currents \[A\] missing
    /// at the end are zero, boundaries \[degC\] missing take the first's).
    fn inputs(&mut self, currents_a: &[f64], boundary_c: &[f64]) {
        self.inputs.currents_a.fill(0.0);
        for (i, v) in self.inputs.currents_a.iter_mut().zip(currents_a) {
            *i = *v as f32;
        }
        let fill = boundary_c.first().map_or(20.0, |b| *b as f32);
        self.inputs.boundary_c.fill(fill);
        for (b, v) in self.inputs.boundary_c.iter_mut().zip(boundary_c) {
            *b = *v as f32;
        }
    }

    /// Readings (one per fused sensor, `None`: none; a fault the sensor
    /// reported instead of a value) for the next tick.
    fn readings(&mut self, z: &[Option<Result<f64, SensorFault>>]) {
        self.pending.fill(None);
        for (p, v) in self.pending.iter_mut().zip(z) {
            *p = match v {
                Some(Ok(v)) if v.is_finite() => Some(Ok(*v as f32)),
                Some(Err(fault)) => Some(Err(*fault)),
                _ => None,
            };
        }
    }

    /// Holds each source's voltage drive `(duty, supply_v)` in the model's
    /// units (see `Model::voltage_drive`; `None`: its current is the
    /// input's): the ticks run `tick_voltage` while one is `Some`.
    fn drives(&mut self, drives: &[Option<(f64, f64)>]) {
        self.drives.fill(None);
        for (slot, d) in self.drives.iter_mut().zip(drives) {
            *slot = d.map(|(duty, supply_v)| VoltageDrive::pwm(duty as f32, supply_v as f32));
        }
    }

    /// The drive rules that fired since the last call.
    fn take_drive_flags(&mut self) -> DriveFlags {
        core::mem::take(&mut self.drive_flags)
    }

    /// Each held voltage drive's limit after the last tick, `(duty,
    /// effective voltage [V])` from the library's `drive_limit` on the
    /// held supply (`None` for a current-driven source).
    fn drive_limits(&self, out: &mut [Option<(f64, f64)>]) {
        for ((m, l), d) in out.iter_mut().enumerate().zip(&self.drives) {
            *l = d.map(|d| {
                let limit = self.observer.drive_limit(&self.state, m, d.supply_v);
                (f64::from(limit.duty), f64::from(limit.voltage_v))
            });
        }
    }

    /// What the last tick did with each fused sensor's reading.
    fn statuses(&self, out: &mut [SensorStatus]) {
        for (o, s) in out.iter_mut().zip(&self.state.outputs().sensors) {
            *o = *s;
        }
    }

    /// One library tick of `elapsed_us`; returns its host time \[ns\].
    fn tick(&mut self, elapsed_us: u32) -> u64 {
        self.inputs.now_us = self.inputs.now_us.wrapping_add(elapsed_us);
        self.inputs.elapsed_us = elapsed_us;
        // A thermocouple sample taken now, as a driver would deliver it
        // (the cold junction does not enter the fusion).
        let now_us = self.inputs.now_us;
        for (slot, z) in self.inputs.readings.iter_mut().zip(&mut self.pending) {
            *slot = z.take().map(|result| TimedReading {
                result: result.map(Reading::new),
                sampled_at_us: now_us,
            });
        }
        let start = Instant::now();
        if self.drives.iter().any(Option::is_some) {
            let (_, flags) = std::hint::black_box(self.observer.tick_voltage(
                &mut self.state,
                &self.inputs,
                &self.drives,
            ));
            let ns = start.elapsed().as_nanos() as u64;
            self.drive_flags |= flags;
            ns
        } else {
            std::hint::black_box(self.observer.tick(&mut self.state, &self.inputs));
            start.elapsed().as_nanos() as u64
        }
    }

    /// The nodes' estimates \[degC\] into `out`.
    fn temps_c(&self, out: &mut [f64]) {
        let temps = self.observer.temps_c(&self.state);
        for (o, t) in out.iter_mut().zip(temps) {
            *o = f64::from(t);
        }
    }

    /// What the protection published at the last tick.
    fn protection(&self, out: &mut Protected) {
        let o = self.state.outputs();
        let ambient_c = self.ambient_c();
        let alarm = self.observer.alarm();
        for (u, t) in out.upper_c.iter_mut().zip(&o.upper_c) {
            *u = f64::from(*t);
        }
        for (i, l) in out.alarm_limit_c.iter_mut().enumerate() {
            *l = alarm.alarm_limit_c(i, ambient_c).map(f64::from);
        }
        for (l, limit) in out.source_limit_a.iter_mut().zip(&o.limits) {
            *l = f64::from(limit.current_a);
        }
        for (t, s) in out.time_to_limit_s.iter_mut().zip(&o.time_to_limit_s) {
            *t = s.map(f64::from);
        }
        out.warning = o.alarm.warning;
        out.shutdown = o.alarm.shutdown;
        out.predictive = o.alarm.predictive;
    }

    /// The ambient the alarm derates against \[degC\].
    fn ambient_c(&self) -> f32 {
        self.inputs
            .boundary_c
            .get(self.ambient_boundary)
            .copied()
            .unwrap_or(f32::NAN)
    }

    /// The estimate of `node` \[degC\] at which its protective upper bound
    /// reaches `limit_c` \[degC\], its reference at `reference_c` \[degC\]
    /// (the library's `ElementBound::mean_limit_c`).
    fn mean_limit_c(&self, node: usize, limit_c: f64, reference_c: f64) -> f64 {
        self.observer
            .upper_bound()
            .element(node)
            .map_or(limit_c, |e| {
                f64::from(e.mean_limit_c(limit_c as f32, reference_c as f32))
            })
    }

    /// Moves the alarm events of the last tick into `out`.
    fn drain_events(&mut self, out: &mut Vec<EventKindAt>) {
        let ambient_c = self.ambient_c();
        let alarm = self.observer.alarm();
        while let Some(e) = self.state.events.pop() {
            let upper = &self.state.outputs().upper_c;
            out.push(EventKindAt::of(
                &e,
                0.0,
                e.element.and_then(|i| upper.get(i).copied()),
                e.element.and_then(|i| alarm.alarm_limit_c(i, ambient_c)),
                alarm.warning_margin_k(),
            ));
        }
    }
}

/// Fusion statistics of one sensor over a replay, as the observer's
/// sensor statuses count them.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FusionStats {
    /// Node index.
    pub node: usize,
    /// Readings fused.
    pub fused: usize,
    /// Readings rejected by the gate.
    pub rejected: usize,
    /// Readings judged stuck against the physics (the observer's shadow
    /// model).
    pub stuck: usize,
    /// Readings refused as colder than the physics (the observer's shadow
    /// model).
    pub colder_than_physics: usize,
}

impl FusionStats {
    /// Nothing counted yet for the sensor on `node`.
    pub fn new(node: usize) -> Self {
        Self {
            node,
            fused: 0,
            rejected: 0,
            stuck: 0,
            colder_than_physics: 0,
        }
    }
}

/// A model file replayed by the library's [`RunTimeObserver`] at fixed
/// ticks: the firmware's observer of the file (see the module docs).
pub struct ObserverEstimator {
    model: Model,
    info: PlantInfo,
    observer: AtModelSize,
    tick_us: u32,
    /// The trace time asked for and the ticks done since the reset.
    clock: TickClock,
    temps: Vec<f64>,
    /// The module's `source_currents_a` and `source_drives` (see
    /// [`FirmwareInputs`]).
    firmware_inputs: FirmwareInputs,
    /// The row's inputs and signals, each rounded once to `f32` as the
    /// MCU receives them, and the observer's currents from them.
    input_f32: Vec<f32>,
    signal_f32: Vec<f32>,
    currents_f32: Vec<f32>,
    currents: Vec<f64>,
    tick_ns: crate::observer::TimeHistogram,
    sensors: Vec<usize>,
    /// Readings handed over, not yet seen by a tick.
    awaiting: bool,
    statuses: Vec<SensorStatus>,
    stats: Vec<FusionStats>,
    /// The settings the observer was built with.
    config: FirmwareConfig,
    /// The protection's outputs after the last tick.
    protected: Protected,
    /// Alarm events since the last [`Self::take_events`].
    events: Vec<EventKindAt>,
    /// Each source's voltage drive `(duty, supply_v)` of the present row
    /// (see [`FirmwareInputs::drive`]).
    drives: Vec<Option<(f64, f64)>>,
    /// Each voltage drive's `(duty, effective voltage)` limit.
    drive_limits: Vec<Option<(f64, f64)>>,
    /// Ticks on which each drive rule fired.
    drive_flag_ticks: DriveFlagTicks,
}

/// How many ticks each of the library's drive rules fired on (see
/// `coil_thermal::DriveFlags`): a voltage-driven model's bad duties and
/// supplies are counted, never dropped without a word.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct DriveFlagTicks {
    /// A duty was NaN, infinite or negative: the last valid current held.
    pub duty_invalid: u64,
    /// A duty above 1 was taken as 1.
    pub duty_clamped: u64,
    /// A supply was NaN, infinite, zero or negative: the last valid
    /// current held, the duty limit zero.
    pub supply_invalid: u64,
    /// `R(T)` at the estimate was not positive: the last valid current
    /// held.
    pub resistance_invalid: u64,
}

impl DriveFlagTicks {
    fn count(&mut self, flags: DriveFlags) {
        for (n, flag) in [
            (&mut self.duty_invalid, DriveFlags::DUTY_INVALID),
            (&mut self.duty_clamped, DriveFlags::DUTY_CLAMPED),
            (&mut self.supply_invalid, DriveFlags::SUPPLY_INVALID),
            (&mut self.resistance_invalid, DriveFlags::RESISTANCE_INVALID),
        ] {
            *n += u64::from(flags.contains(flag));
        }
    }

    /// `true` when no rule fired.
    pub fn is_clean(&self) -> bool {
        *self == Self::default()
    }
}

impl ObserverEstimator {
    /// The library observer of `model` with ticks of `tick_us` \[us\] (one
    /// model step each), open loop, with the library's defaults.
    ///
    /// # Errors
    /// No boundary, a tick of 0, or a network the library refuses.
    pub fn new(model: Model, tick_us: u32) -> Result<Self> {
        let mut config = FirmwareConfig::of(&model, None)?;
        config.settings.step_us = tick_us;
        config.settings.loop_period_us = tick_us;
        // Not a firmware's: currents as a motor's 400 A need.
        config.settings.max_current_a = OPEN_LOOP_MAX_CURRENT_A;
        Self::firmware(model, tick_us, &config, &[])
    }

    /// The firmware observer `config` (see [`crate::firmware`]) of `model`
    /// ticked every `tick_us` \[us\], fusing a thermocouple on each node
    /// of `fused_nodes` (the readings handed to [`Estimator::update`], in
    /// that order; none: open loop, and no heat-input bias).
    ///
    /// # Errors
    /// As [`Self::new`]; settings the library refuses (a sensor noise or
    /// correction period that is not finite and positive, a negative
    /// noise).
    pub fn firmware(
        model: Model,
        tick_us: u32,
        config: &FirmwareConfig,
        fused_nodes: &[usize],
    ) -> Result<Self> {
        if tick_us == 0 {
            bail!("--tick-us must be at least 1");
        }
        model.require_fixed_network("the library's network observer")?;
        let sensors = fused_nodes.to_vec();
        let info = plant_info(&model);
        let mut settings = config.settings;
        if sensors.is_empty() {
            // Open loop: no sensor, no bias (see the module docs), no
            // boundary offset.
            settings.bias_noise_w2_per_s = 0.0;
            settings.boundary_offset = None;
        } else {
            let positive = |v: f64| v.is_finite() && v > 0.0;
            if !positive(settings.sensor_sigma_k) {
                bail!(
                    "the sensor noise must be finite and > 0 K, got {}",
                    settings.sensor_sigma_k
                );
            }
            if !(settings.node_noise_k2_per_s.is_finite() && settings.node_noise_k2_per_s >= 0.0) {
                bail!(
                    "the process noise must be finite and >= 0 K^2/s, got {}",
                    settings.node_noise_k2_per_s
                );
            }
            if !positive(settings.correction_period_s) {
                bail!(
                    "the correction period must be finite and > 0 s, got {}",
                    settings.correction_period_s
                );
            }
            if !(settings.bias_noise_w2_per_s.is_finite() && settings.bias_noise_w2_per_s >= 0.0) {
                bail!(
                    "the bias noise must be finite and >= 0 W^2/s, got {}",
                    settings.bias_noise_w2_per_s
                );
            }
            if !(settings.max_cooling_bias_fraction.is_finite()
                && settings.max_cooling_bias_fraction >= 0.0)
            {
                bail!(
                    "max_cooling_bias_fraction must be finite and >= 0, got {}",
                    settings.max_cooling_bias_fraction
                );
            }
            settings.correction_period_s =
                settings.correction_period_s.max(f64::from(tick_us) * 1e-6);
            // A reading is handed to the tick right after its row.
            // (kept at the firmware's: a reading is handed over with its own tick's time)
        }
        // The file's sensor kinds apply to its own sensors; a replay that
        // fuses other nodes (an override it lists) fuses temperatures. Open
        // loop one thermocouple on node 0 that never reads: the filter has
        // a sensor, as the firmware generated from the file has.
        let (sensor_nodes, sensor_kinds) = if sensors.is_empty() {
            (vec![0], vec![SensorKind::Thermocouple])
        } else if sensors == config.sensor_nodes {
            (sensors.clone(), config.sensor_kinds.clone())
        } else if config.has_resistance_sensor() {
            bail!(
                "--measure: the model file's sensors include a winding's resistance, fused with its own noise; measure exactly the file's sensors, in its order ({} column(s)), or none",
                config.sensor_nodes.len()
            );
        } else {
            (
                sensors.clone(),
                vec![SensorKind::Thermocouple; sensors.len()],
            )
        };
        let (net, spec) =
            firmware_observer_spec(&model, config, settings, sensor_nodes, sensor_kinds)?;
        let observer = AtModelSize::build(&net, &spec, &model.name)?;
        let n = model.nodes.len();
        let m = model.network.sources().len();
        let firmware_inputs = FirmwareInputs::new(&model);
        Ok(Self {
            model,
            info,
            observer,
            tick_us,
            clock: TickClock::default(),
            temps: vec![0.0; n],
            firmware_inputs,
            input_f32: Vec::new(),
            signal_f32: Vec::new(),
            currents_f32: Vec::new(),
            currents: Vec::new(),
            tick_ns: crate::observer::TimeHistogram::default(),
            statuses: vec![SensorStatus::NoReading; sensors.len()],
            stats: sensors.iter().map(|&node| FusionStats::new(node)).collect(),
            sensors,
            awaiting: false,
            config: FirmwareConfig {
                settings,
                ..config.clone()
            },
            protected: Protected::for_sizes(n, m),
            events: Vec::new(),
            drives: vec![None; m],
            drive_limits: vec![None; m],
            drive_flag_ticks: DriveFlagTicks::default(),
        })
    }

    /// The settings the observer runs with (the open loop's bias noise
    /// at 0; the correction period at least one tick).
    pub fn config(&self) -> &FirmwareConfig {
        &self.config
    }

    /// What the protection published after the last tick.
    pub fn protected(&self) -> &Protected {
        &self.protected
    }

    /// The alarm events since the last call, with their times since the
    /// reset.
    pub fn take_events(&mut self) -> Vec<EventKindAt> {
        std::mem::take(&mut self.events)
    }

    /// Each node's estimate \[degC\] at which the protective upper bound
    /// reaches its limit in `limits_c` \[degC\] (`None`: unlimited), with
    /// `boundary_c` \[degC\] the boundaries: the limits a prediction of the
    /// mean is given so that it answers for the bound the firmware's
    /// limiter, alarm and time to limit act on (see
    /// `coil_thermal::protect::margin`).
    pub fn mean_limits_c(&self, limits_c: &[Option<f64>], boundary_c: &[f64]) -> Vec<Option<f64>> {
        let reference_c = boundary_c
            .get(self.config.settings.ambient_boundary)
            .copied()
            .unwrap_or(f64::NAN);
        limits_c
            .iter()
            .enumerate()
            .map(|(i, l)| l.map(|l| self.observer.mean_limit_c(i, l, reference_c)))
            .collect()
    }

    /// Per-sensor fusion counts so far.
    pub fn stats(&self) -> &[FusionStats] {
        &self.stats
    }

    /// The model's nodes, the observer's size.
    pub fn nodes(&self) -> usize {
        self.temps.len()
    }

    /// The tick \[us\].
    pub fn tick_us(&self) -> u32 {
        self.tick_us
    }

    /// Holds these inputs (per model input \[A\], boundary \[degC\],
    /// signal) for [`Self::tick_once`].
    pub fn hold_inputs(&mut self, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        let to_f32 = |from: &[f64], to: &mut Vec<f32>| {
            to.clear();
            to.extend(from.iter().map(|v| *v as f32));
        };
        to_f32(currents_a, &mut self.input_f32);
        to_f32(signals, &mut self.signal_f32);
        self.currents_f32.resize(self.firmware_inputs.len(), 0.0);
        self.firmware_inputs
            .currents_a(&self.input_f32, &self.signal_f32, &mut self.currents_f32);
        self.currents.clear();
        self.currents
            .extend(self.currents_f32.iter().map(|&i| f64::from(i)));
        self.observer.inputs(&self.currents, boundary_c);
        // A voltage-driven winding's current is the library's
        // (`tick_voltage`: `sqrt(D) V / R(T_est)`), as on the MCU.
        if self.model.has_voltage_drives() {
            for (m, d) in self.drives.iter_mut().enumerate() {
                *d = self
                    .firmware_inputs
                    .drive(m, &self.input_f32, &self.signal_f32)
                    .map(|d| (f64::from(d.duty), f64::from(d.supply_v)));
            }
            self.observer.drives(&self.drives);
        }
    }

    /// Ticks on which each drive rule fired since the reset (all zero for
    /// a current-driven model).
    pub fn drive_flag_ticks(&self) -> DriveFlagTicks {
        self.drive_flag_ticks
    }

    /// The protection after a tick, each voltage drive's limit in its
    /// input's unit: a `pwm` input's duty, a linear input's voltage (the
    /// effective voltage over the source's power scale), as the generated
    /// module's `input_drive_limits`.
    fn publish_protection(&mut self) {
        self.observer.protection(&mut self.protected);
        if !self.model.has_voltage_drives() {
            return;
        }
        self.observer.drive_limits(&mut self.drive_limits);
        for (m, (out, limit)) in self
            .protected
            .drive_limit
            .iter_mut()
            .zip(&self.drive_limits)
            .enumerate()
        {
            if !self.model.is_voltage_driven(m) {
                continue;
            }
            // Before the first row's drive (the reset) the supply is not
            // known: no limit yet (NaN), never a current in a duty's place.
            // Both are `f32`s widened, so narrowing them back is exact.
            *out = Some(limit.map_or(f64::NAN, |(duty, voltage_v)| {
                self.firmware_inputs
                    .drive_limit(m, duty as f32, voltage_v as f32)
                    .map_or(f64::NAN, f64::from)
            }));
        }
    }

    /// One library tick of `tick_us` with the held inputs, not recorded;
    /// returns its host time \[ns\] (for `bench`).
    pub fn tick_once(&mut self) -> u64 {
        self.observer.tick(self.tick_us)
    }
}

impl Estimator for ObserverEstimator {
    fn info(&self) -> &PlantInfo {
        &self.info
    }

    fn reset(&mut self, temps_c: &[f64]) {
        // The boundaries of the first row arrive with the first predict;
        // until then they sit at the mean start temperature.
        let mean = temps_c.iter().sum::<f64>() / temps_c.len().max(1) as f64;
        self.observer.reset(temps_c, &[mean]);
        self.drive_flag_ticks = DriveFlagTicks::default();
        self.publish_protection();
        self.events.clear();
        self.temps.copy_from_slice(temps_c);
        self.clock = TickClock::default();
    }

    /// Ticks of `tick_us` until the simulated time reaches the trace's
    /// (a remainder shorter than a tick carries to the next row).
    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        self.hold_inputs(currents_a, boundary_c, signals);
        self.clock.ask(dt_s);
        while self.clock.next_tick(self.tick_us) {
            let ns = self.observer.tick(self.tick_us);
            self.tick_ns.record(ns);
            let flags = self.observer.take_drive_flags();
            self.drive_flag_ticks.count(flags);
            let first = self.events.len();
            self.observer.drain_events(&mut self.events);
            for e in &mut self.events[first..] {
                e.since_start_s = self.clock.done_s();
            }
            if self.awaiting {
                self.awaiting = false;
                self.observer.statuses(&mut self.statuses);
                for (s, status) in self.stats.iter_mut().zip(&self.statuses) {
                    match status {
                        SensorStatus::Fused { .. } => s.fused += 1,
                        SensorStatus::Rejected { .. } => s.rejected += 1,
                        SensorStatus::Stuck { .. } => s.stuck += 1,
                        SensorStatus::ColderThanPhysics { .. } => s.colder_than_physics += 1,
                        _ => {}
                    }
                }
            }
        }
        self.observer.temps_c(&mut self.temps);
        self.publish_protection();
    }

    /// Hands the row's readings to the next tick (the estimate recorded at
    /// this row is the prior; the correction shows from the next row on).
    fn update(&mut self, measured: &[Measurement]) {
        if self.sensors.is_empty() {
            return;
        }
        let z: Vec<Option<Result<f64, SensorFault>>> = self
            .sensors
            .iter()
            .enumerate()
            .map(|(j, node)| {
                let m = measured.get(j).filter(|m| m.node == *node)?;
                match m.fault {
                    // A fault is handed over as the MCU hands it.
                    Some(fault) => Some(Err(fault)),
                    // A missing reading (an empty or NaN cell) is no reading.
                    None => (!m.value_c.is_nan()).then_some(Ok(m.value_c)),
                }
            })
            .collect();
        self.awaiting = z.iter().any(|v| matches!(v, Some(Ok(v)) if v.is_finite()));
        self.observer.readings(&z);
    }

    fn estimate_c(&self) -> &[f64] {
        &self.temps
    }

    fn kind(&self) -> &'static str {
        "network-observer"
    }

    fn take_tick_times_ns(&mut self) -> Option<crate::observer::TimeHistogram> {
        Some(std::mem::take(&mut self.tick_ns))
    }

    fn firmware(&mut self, out: &mut Protected, events: &mut Vec<EventKindAt>) -> bool {
        out.clone_from(&self.protected);
        events.append(&mut self.events);
        true
    }
}
