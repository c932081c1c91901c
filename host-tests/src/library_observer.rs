//! Replay through the library's observer: a model file run by
//! [`NetworkObserver`] at fixed ticks (1 ms by default), each tick timed.
//!
//! # Sizes
//! `NetworkObserver<N, B, M, X, P>` has its sizes in types; a model file has
//! them at run time. The model's network is copied into `Network<C, 2, C>`
//! for the smallest `C` of [`OBSERVER_CLASSES`] that holds its nodes and
//! sources (as `limits` pads it: padding nodes decay to boundary 0 and touch
//! no real node, padding sources sit at zero current), and the observer is
//! `NetworkObserver<C, 2, C, 2C, 1>`. Its build solves the steady Kalman
//! gain of `2C` states in `f64` on the stack, so it runs on a thread with a
//! large stack and the result is boxed. Few classes keep the compile time
//! down: a 2-node coil runs as 8 nodes, the HPPA grid's 84 coils as 96.
//!
//! # Open loop and fused thermocouples
//! The observer has [`SENSOR_SLOTS`] thermocouple slots. Without fused
//! sensors none gets a reading: the estimate is the library's model step,
//! the exact zero-order hold of the network with `R(T)` at the estimate,
//! run in `f32` on deviations with the rounding carried. With `--measure`
//! each column is a thermocouple of its node: a row's reading is handed to
//! the tick right after the row (as a driver's sample taken then), and the
//! library's steady-state correction fuses it with the gain solved for the
//! trace's row spacing; unused slots sit on a padding node (the class then
//! needs one node more than the model), decoupled from the real nodes.
//!
//! # Heat-input biases: the firmware's filter
//! The fused observer is the firmware's: each of the model's sources
//! carries a heat-input bias state, at the model file's `[observer]`
//! `bias_noise_w2_per_s` and `max_cooling_bias_fraction` (the library's
//! defaults, 1e-3 W^2/s and 0, when the file has no table or the table not
//! the key), as `coil-thermal codegen` builds the firmware from the same
//! file; `replay --bias-noise-w2-per-s` overrides the file's noise. The
//! sensor noise and the correction period stay the replay's
//! (`--measurement-noise-k`, the trace's row spacing): given the file's,
//! the replay is the generated observer within `f32` rounding (test
//! `replay_firmware_filter`: `drive-3node` over its bench hour, at most
//! 8e-6 K apart). The padding sources carry no current and their biases no
//! sensor can see (an unobservable random walk has no steady gain), so
//! they are left out of the bias states
//! ([`NetworkObserverBuilder::bias_sources`]: their bias is exactly 0), as
//! the fault campaign does ([`crate::faults`]). A sensor therefore corrects
//! the model's heat as well as its temperatures: a housing thermocouple
//! warms an unmeasured coil whose plant runs 40 % hotter than the model
//! (coil MSE 1.09 K^2, against 5.46 with the biases frozen and 31.9 open
//! loop; test `kalman_replay`).
//!
//! When the sensors cannot see every source's bias (e.g. three sources and
//! one sensor; the HUST models, copper and speed losses, with one sensor),
//! the gain solve does not converge and the replay refuses, naming the
//! fixes. `[observer] bias_sources` names the sources whose bias is
//! estimated (the others' stay exactly 0, as the padding's), as the
//! firmware generated from the file does: one sensor, one heat. Or the
//! firmware freezes every bias (`[observer] bias_noise_w2_per_s = 0`;
//! `replay --bias-noise-w2-per-s 0` replays so without editing the file:
//! temperatures corrected, no heat input estimated). A heat the model
//! lacks is also what `--disturbance` estimates, with the library's
//! time-varying filter ([`crate::kalman`]). Open loop (no sensor) there is
//! nothing to fuse and no bias.
//!
//! # Currents above 100 A
//! The observer holds a current beyond its plausibility limit (the
//! library's `InputLimits::default()`, 100 A, fixed for the observer) at
//! that limit. Recorded motor currents reach 400 A (the HUST motor), so the
//! host feeds every current divided by [`CURRENT_SCALE`] into windings
//! whose resistance is `CURRENT_SCALE^2` times the model's: the same power,
//! exactly (both factors are powers of two), for currents up to 1600 A.
//!
//! # Speed-dependent sources
//! A model file's speed factors and speed losses
//! ([`Model::effective_currents`]) are folded into effective currents on
//! the host before each tick: a speed loss is a 1 ohm source carrying
//! `sqrt(P)`, a speed factor scales its source's current by `sqrt(factor)`.
//! The observer sees an ordinary network with currents.

use std::time::Instant;

use anyhow::{anyhow, bail, Result};
use coil_thermal::observer::network::{
    NetworkInputs, NetworkObserver, NetworkObserverBuilder, NetworkObserverState, NetworkSettings,
};
use coil_thermal::observer::{SensorStatus, TimedReading};
use coil_thermal::Reading;

use crate::codegen::ObserverSpec;
use crate::dynamic_network::DynNetwork;
use crate::kalman::FusionStats;
use crate::limits::{class_of, on_big_stack, padded_with, Padding};
use crate::model_file::Model;
use crate::observer::{Estimator, Measurement};
use crate::sim::{plant_info, PlantInfo};

/// The padded sizes `C` (nodes and sources) of the observer.
pub const OBSERVER_CLASSES: [usize; 4] = [8, 16, 32, 96];

/// Currents enter the observer divided by this, resistances multiplied by
/// its square (see the module docs).
pub const CURRENT_SCALE: f64 = 16.0;

/// The default tick \[us\] (the controller's 1 ms loop).
pub const DEFAULT_TICK_US: u32 = 1000;

/// Thermocouple slots of the padded observer: at most this many fused
/// sensors (unused slots sit on a padding node and never read).
pub const SENSOR_SLOTS: usize = 4;

/// How the observer fuses the `--measure` sensors.
#[derive(Debug, Clone, PartialEq)]
pub struct Fusion {
    /// Node of each fused sensor, in the order of the readings.
    pub sensor_nodes: Vec<usize>,
    /// Standard deviation of every thermocouple \[K\].
    pub sensor_sigma_k: f64,
    /// Growth rate of each node's temperature variance \[K^2/s\].
    pub node_noise_k2_per_s: f64,
    /// Time between readings the steady gain is solved for \[s\] (the
    /// trace's row spacing).
    pub correction_period_s: f64,
    /// The heat-input biases of the model's sources.
    pub biases: BiasSettings,
}

/// Where a replay's bias noise comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BiasNoiseFrom {
    /// `replay --bias-noise-w2-per-s`.
    Flag,
    /// The model file's `[observer] bias_noise_w2_per_s`.
    ModelFile,
    /// The library's default (`NetworkSettings::DEFAULT`), as `codegen`
    /// builds a file without the key.
    Default,
}

impl BiasNoiseFrom {
    /// Stable name (`--json`'s `bias_noise_from`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Flag => "flag",
            Self::ModelFile => "model-file",
            Self::Default => "default",
        }
    }
}

/// The heat-input bias settings of the fused observer (see the module
/// docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BiasSettings {
    /// Growth rate of each model source's bias variance \[W^2/s\] (0
    /// freezes every bias at zero).
    pub bias_noise_w2_per_s: f64,
    /// Largest heat the sensors may take away, as a share of each source's
    /// Joule power (dimensionless).
    pub max_cooling_bias_fraction: f64,
    /// Where `bias_noise_w2_per_s` comes from.
    pub from: BiasNoiseFrom,
}

impl BiasSettings {
    /// The firmware's: the model file's `[observer]` table (`spec`), each
    /// key missing at the library's default, as `codegen` builds them;
    /// `bias_noise_w2_per_s` (the replay's flag) overrides the file's.
    pub fn firmware(spec: Option<&ObserverSpec>, bias_noise_w2_per_s: Option<f64>) -> Self {
        let defaults = NetworkSettings::DEFAULT;
        let file = spec.and_then(|s| s.bias_noise_w2_per_s);
        let (noise, from) = match (bias_noise_w2_per_s, file) {
            (Some(v), _) => (v, BiasNoiseFrom::Flag),
            (None, Some(v)) => (v, BiasNoiseFrom::ModelFile),
            (None, None) => (defaults.bias_noise_w2_per_s, BiasNoiseFrom::Default),
        };
        Self {
            bias_noise_w2_per_s: noise,
            max_cooling_bias_fraction: spec
                .and_then(|s| s.max_cooling_bias_fraction)
                .unwrap_or(defaults.max_cooling_bias_fraction),
            from,
        }
    }
}

/// The size-independent face of a padded observer with its state.
trait PaddedObserver: Send {
    /// A fresh state at `temps_c` (real nodes) and `boundary_c`.
    fn reset(&mut self, temps_c: &[f64], boundary_c: &[f64]);
    /// Sets the held inputs of the following ticks.
    fn inputs(&mut self, currents_a: &[f64], boundary_c: &[f64]);
    /// Readings (one per fused sensor, `None`: none) for the next tick.
    fn readings(&mut self, z: &[Option<f64>]);
    /// What the last tick did with each fused sensor's reading.
    fn statuses(&self, out: &mut [SensorStatus]);
    /// One library tick of `elapsed_us`; returns its host time \[ns\].
    fn tick(&mut self, elapsed_us: u32) -> u64;
    /// The real nodes' estimates \[degC\] into `out`.
    fn temps_c(&self, out: &mut [f64]);
}

struct Sized<const C: usize, const X: usize> {
    observer: NetworkObserver<C, 2, C, X, SENSOR_SLOTS>,
    state: NetworkObserverState<C, 2, C, X, SENSOR_SLOTS>,
    inputs: NetworkInputs<2, C, SENSOR_SLOTS>,
    /// Readings waiting for the next tick.
    pending: [Option<f32>; SENSOR_SLOTS],
}

impl<const C: usize, const X: usize> Sized<C, X> {
    fn build(
        net: &DynNetwork,
        settings: NetworkSettings,
        sensor_nodes: &[usize],
        biased: &[bool],
        name: &str,
    ) -> Result<Box<dyn PaddedObserver>> {
        let padding = Padding {
            link_to_boundary: true,
            resistance_scale: CURRENT_SCALE * CURRENT_SCALE,
        };
        let network = padded_with::<C>(net, padding)?;
        // Unused slots on the first padding node (decoupled from the real
        // nodes, so the real sensors' gain is the one they would have
        // alone), or on node 0 when no sensor is fused (never read).
        let spare = if sensor_nodes.is_empty() {
            0
        } else {
            net.nodes()
        };
        let mut slots = [spare; SENSOR_SLOTS];
        slots[..sensor_nodes.len()].copy_from_slice(sensor_nodes);
        let bias_sources: [bool; C] =
            core::array::from_fn(|m| biased.get(m).copied().unwrap_or(false));
        let observer = NetworkObserverBuilder::new(&network, slots)
            // No element limits the currents here: the replay's alarm
            // watches the estimate (see `observer::LibraryAlarm`).
            .incidence([[false; C]; C])
            .settings(settings)
            .bias_sources(bias_sources)
            .build::<X>()
            .map_err(|e| match e {
                coil_thermal::BuildError::NotConverged { .. }
                    if settings.bias_noise_w2_per_s > 0.0 => anyhow!(
                    "the library observer of model `{name}` with its heat-bias states ({} W^2/s) does not build: {e} \
                     (the sensors cannot see every source's bias: name the sources whose heat they can see in `[observer] bias_sources`, \
                     or freeze the biases with `[observer] bias_noise_w2_per_s = 0` (replay: --bias-noise-w2-per-s 0), or estimate the missing heat with --disturbance)",
                    settings.bias_noise_w2_per_s
                ),
                e => anyhow!("the library observer: {e}"),
            })?;
        let origin = settings.origin_c as f32;
        let state = observer.state(&[origin; C], &[origin; 2]);
        Ok(Box::new(Self {
            observer,
            state,
            inputs: NetworkInputs {
                currents_a: [0.0; C],
                boundary_c: [origin; 2],
                readings: [None; SENSOR_SLOTS],
                now_us: 0,
                elapsed_us: 0,
            },
            pending: [None; SENSOR_SLOTS],
        }))
    }
}

impl<const C: usize, const X: usize> PaddedObserver for Sized<C, X> {
    fn reset(&mut self, temps_c: &[f64], boundary_c: &[f64]) {
        self.inputs(&[], boundary_c);
        // Padding nodes start at boundary 0, their equilibrium.
        let mut temps = [self.inputs.boundary_c[0]; C];
        for (t, v) in temps.iter_mut().zip(temps_c) {
            *t = *v as f32;
        }
        self.state = self.observer.state(&temps, &self.inputs.boundary_c);
        self.inputs.now_us = 0;
    }

    fn inputs(&mut self, currents_a: &[f64], boundary_c: &[f64]) {
        self.inputs.currents_a = [0.0; C];
        for (i, v) in self.inputs.currents_a.iter_mut().zip(currents_a) {
            *i = (*v / CURRENT_SCALE) as f32;
        }
        // A padding boundary has no links: boundary 0's value serves.
        let fill = boundary_c.first().map_or(20.0, |b| *b as f32);
        self.inputs.boundary_c = [fill; 2];
        for (b, v) in self.inputs.boundary_c.iter_mut().zip(boundary_c) {
            *b = *v as f32;
        }
    }

    fn readings(&mut self, z: &[Option<f64>]) {
        self.pending = [None; SENSOR_SLOTS];
        for (p, v) in self.pending.iter_mut().zip(z) {
            *p = v.filter(|v| v.is_finite()).map(|v| v as f32);
        }
    }

    fn statuses(&self, out: &mut [SensorStatus]) {
        out.copy_from_slice(&self.state.outputs().sensors[..out.len()]);
    }

    fn tick(&mut self, elapsed_us: u32) -> u64 {
        self.inputs.now_us = self.inputs.now_us.wrapping_add(elapsed_us);
        self.inputs.elapsed_us = elapsed_us;
        // A thermocouple sample taken now, as a driver would deliver it
        // (the cold junction does not enter the fusion).
        let now_us = self.inputs.now_us;
        for (slot, z) in self.inputs.readings.iter_mut().zip(&mut self.pending) {
            *slot = z.take().map(|temp_c| TimedReading {
                result: Ok(Reading {
                    temp_c,
                    cold_junction_c: 25.0,
                }),
                sampled_at_us: now_us,
            });
        }
        let start = Instant::now();
        std::hint::black_box(self.observer.tick(&mut self.state, &self.inputs));
        start.elapsed().as_nanos() as u64
    }

    fn temps_c(&self, out: &mut [f64]) {
        let temps = self.observer.temps_c(&self.state);
        for (o, t) in out.iter_mut().zip(temps) {
            *o = f64::from(t);
        }
    }
}

/// A model file replayed open loop by the library's [`NetworkObserver`] at
/// fixed ticks (see the module docs).
pub struct ObserverEstimator {
    model: Model,
    info: PlantInfo,
    observer: Box<dyn PaddedObserver>,
    tick_us: u32,
    /// Time simulated so far since the reset \[us\].
    done_us: u64,
    /// Time asked for so far since the reset \[us\].
    asked_s: f64,
    temps: Vec<f64>,
    effective: Vec<f64>,
    tick_ns: crate::observer::TimeHistogram,
    size_class: usize,
    sensors: Vec<usize>,
    /// Readings handed over, not yet seen by a tick.
    awaiting: bool,
    statuses: Vec<SensorStatus>,
    stats: Vec<FusionStats>,
    /// The fused observer's bias settings (`None` open loop).
    biases: Option<BiasSettings>,
}

impl ObserverEstimator {
    /// Builds the observer of `model` with ticks of `tick_us` \[us\], open
    /// loop (on a large stack: the gain is solved there).
    ///
    /// # Errors
    /// No boundary, more than 2, more nodes or sources than the largest
    /// class, a tick of 0, or a network the library refuses.
    pub fn new(model: Model, tick_us: u32) -> Result<Self> {
        Self::with_fusion(model, tick_us, None)
    }

    /// [`Self::new`] fusing thermocouples: each `--measure` column is a
    /// reading of its node, handed to the tick that follows its row.
    ///
    /// # Errors
    /// As [`Self::new`]; more than [`SENSOR_SLOTS`] sensors; a noise or
    /// period that is not finite and positive; a model that fills its size
    /// class (the unused sensor slots need a padding node).
    pub fn with_fusion(model: Model, tick_us: u32, fusion: Option<Fusion>) -> Result<Self> {
        if tick_us == 0 {
            bail!("--tick-us must be at least 1");
        }
        model.require_fixed_network("the library's network observer")?;
        let sensors = fusion
            .as_ref()
            .map_or(Vec::new(), |f| f.sensor_nodes.clone());
        if sensors.len() > SENSOR_SLOTS {
            bail!(
                "--measure: the library observer fuses at most {SENSOR_SLOTS} sensors, got {}",
                sensors.len()
            );
        }
        let info = plant_info(&model);
        let net = model.network.clone();
        if net.boundaries() == 0 {
            bail!(
                "model `{}` has no boundary: the library observer needs one (the ambient)",
                model.name
            );
        }
        // Fused sensors leave their unused slots on a padding node, so the
        // class must hold one more node.
        let mut need = net.clone();
        if !sensors.is_empty() {
            need = DynNetwork::new(vec![1.0; net.nodes() + 1], net.boundaries())?;
            for s in net.sources() {
                need.joule_source(s.node, s.resistance)?;
            }
        }
        let class = class_of(&need, &OBSERVER_CLASSES, "the library observer")?;
        let ambient = info
            .boundaries
            .iter()
            .position(|b| b.name == "ambient")
            .unwrap_or(0);
        let mut settings = NetworkSettings {
            step_us: tick_us,
            // Open loop: no sensor, no bias (see the module docs).
            bias_noise_w2_per_s: 0.0,
            ambient_boundary: ambient,
            ..NetworkSettings::DEFAULT
        };
        if let Some(f) = &fusion {
            let positive = |v: f64| v.is_finite() && v > 0.0;
            if !positive(f.sensor_sigma_k) {
                bail!(
                    "--measurement-noise-k must be finite and > 0, got {}",
                    f.sensor_sigma_k
                );
            }
            if !(f.node_noise_k2_per_s.is_finite() && f.node_noise_k2_per_s >= 0.0) {
                bail!(
                    "--process-noise-k2-per-s must be finite and >= 0, got {}",
                    f.node_noise_k2_per_s
                );
            }
            if !positive(f.correction_period_s) {
                bail!("the trace's row spacing must be > 0 s to fuse readings");
            }
            let b = &f.biases;
            if !(b.bias_noise_w2_per_s.is_finite() && b.bias_noise_w2_per_s >= 0.0) {
                bail!(
                    "the bias noise must be finite and >= 0 W^2/s, got {} ({})",
                    b.bias_noise_w2_per_s,
                    match b.from {
                        BiasNoiseFrom::Flag => "--bias-noise-w2-per-s",
                        _ => "the model file's [observer] bias_noise_w2_per_s",
                    }
                );
            }
            if !(b.max_cooling_bias_fraction.is_finite() && b.max_cooling_bias_fraction >= 0.0) {
                bail!(
                    "the model file's [observer] max_cooling_bias_fraction must be finite and >= 0, got {}",
                    b.max_cooling_bias_fraction
                );
            }
            settings.bias_noise_w2_per_s = b.bias_noise_w2_per_s;
            settings.max_cooling_bias_fraction = b.max_cooling_bias_fraction;
            settings.sensor_sigma_k = f.sensor_sigma_k;
            settings.node_noise_k2_per_s = f.node_noise_k2_per_s;
            settings.correction_period_s = f.correction_period_s.max(f64::from(tick_us) * 1e-6);
            // A reading is handed to the tick right after its row.
            settings.max_reading_age_us = u32::MAX;
        }
        let slots = sensors.clone();
        let name = model.name.clone();
        // The model's sources carry their biases (those `[observer]
        // bias_sources` names, when given), the padding's do not (see the
        // module docs).
        let biased: Vec<bool> = (0..class).map(|m| model.carries_bias(m)).collect();
        let observer = on_big_stack("the library observer", move || match class {
            8 => Sized::<8, 16>::build(&net, settings, &slots, &biased, &name),
            16 => Sized::<16, 32>::build(&net, settings, &slots, &biased, &name),
            32 => Sized::<32, 64>::build(&net, settings, &slots, &biased, &name),
            _ => Sized::<96, 192>::build(&net, settings, &slots, &biased, &name),
        })?;
        let n = model.nodes.len();
        Ok(Self {
            model,
            info,
            observer,
            tick_us,
            done_us: 0,
            asked_s: 0.0,
            temps: vec![0.0; n],
            effective: Vec::new(),
            tick_ns: crate::observer::TimeHistogram::default(),
            size_class: class,
            statuses: vec![SensorStatus::NoReading; sensors.len()],
            stats: sensors
                .iter()
                .map(|&node| FusionStats {
                    node,
                    fused: 0,
                    rejected: 0,
                    stuck: 0,
                    colder_than_physics: 0,
                    rejected_at_s: Vec::new(),
                })
                .collect(),
            sensors,
            awaiting: false,
            biases: fusion.map(|f| f.biases),
        })
    }

    /// Per-sensor fusion counts so far.
    pub fn stats(&self) -> &[FusionStats] {
        &self.stats
    }

    /// The heat-input bias settings the fused observer runs (`None` open
    /// loop: no sensor, no bias).
    pub fn biases(&self) -> Option<BiasSettings> {
        self.biases
    }

    /// The padded size the observer runs at.
    pub fn size_class(&self) -> usize {
        self.size_class
    }

    /// The tick \[us\].
    pub fn tick_us(&self) -> u32 {
        self.tick_us
    }

    /// Holds these inputs (per model input \[A\], boundary \[degC\],
    /// signal) for [`Self::tick_once`].
    pub fn hold_inputs(&mut self, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        self.model
            .effective_currents(currents_a, signals, &mut self.effective);
        self.observer.inputs(&self.effective, boundary_c);
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
        // until then the padding sits at the mean start temperature.
        let mean = temps_c.iter().sum::<f64>() / temps_c.len().max(1) as f64;
        self.observer.reset(temps_c, &[mean, mean]);
        self.temps.copy_from_slice(temps_c);
        self.done_us = 0;
        self.asked_s = 0.0;
    }

    /// Ticks of `tick_us` until the simulated time reaches the trace's
    /// (a remainder shorter than a tick carries to the next row).
    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        self.model
            .effective_currents(currents_a, signals, &mut self.effective);
        self.observer.inputs(&self.effective, boundary_c);
        self.asked_s += dt_s;
        let target_us = (self.asked_s * 1e6).round() as u64;
        let tick = u64::from(self.tick_us);
        while self.done_us + tick <= target_us {
            let ns = self.observer.tick(self.tick_us);
            self.tick_ns.record(ns);
            self.done_us += tick;
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
    }

    /// Hands the row's readings to the next tick (the estimate recorded at
    /// this row is the prior; the correction shows from the next row on).
    fn update(&mut self, measured: &[Measurement]) {
        if self.sensors.is_empty() {
            return;
        }
        let z: Vec<Option<f64>> = self
            .sensors
            .iter()
            .enumerate()
            .map(|(j, node)| {
                measured
                    .get(j)
                    .filter(|m| m.node == *node)
                    .map(|m| m.value_c)
                    // A missing reading (an empty or NaN cell) is no reading.
                    .filter(|v| !v.is_nan())
            })
            .collect();
        self.awaiting = z.iter().any(|v| v.is_some_and(f64::is_finite));
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
}
