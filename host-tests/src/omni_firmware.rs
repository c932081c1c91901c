//! `replay --model omnimagnet`: the Omnimagnet replayed through the
//! observer the firmware flashes for it, the `OmniObserver` of
//! [`codegen::omnimagnet_observer`](crate::codegen::omnimagnet_observer)
//! (`examples/observer_m4.rs`, `codegen --device omnimagnet`), not a
//! `NetworkObserver` over the linearised network: its 5 ms model step on
//! the ticks' mean `I^2`, its protection cycle, its thermocouple checks,
//! its own derating rule and critical temperatures.
//!
//! The thermocouples fitted are the ones the replay fuses (`--measure`
//! onto the nodes the Omnimagnet has thermocouples on); with none, the
//! flashed set of six, which then never reads (what an MCU with its
//! thermocouples unplugged computes: silence puts the protection on the
//! unfused model's bound). A set that needs the firmware's model refresh
//! (a solenoid left with one thermocouple) is refused: the replay does not
//! run the background re-linearisation.

use std::time::Instant;

use anyhow::{bail, Result};
use coil_thermal::observer::omnimagnet::{needs_model_refresh, NoWarmUp, ALARM_NODES};
use coil_thermal::observer::{
    OmniInputs, OmniObserver, OmniObserverState, OmniSettings, SensorStatus, TimedReading,
};
use coil_thermal::omnimagnet::{Omnimagnet, NODES, SOLENOIDS, THERMOCOUPLES, THERMOCOUPLE_NODES};
use coil_thermal::Reading;

use crate::codegen::{omnimagnet_settings, OMNIMAGNET_AMBIENT_C};
use crate::library_observer::{EventKindAt, FusionStats, Protected};
use crate::observer::{Estimator, Measurement, TickClock, TimeHistogram};
use crate::sim::PlantInfo;

/// The loop tick of the flashed Omnimagnet observer \[us\]
/// (`OmniSettings::loop_period_us` of `codegen --device omnimagnet`).
pub const TICK_US: u32 = 1000;

/// What a replay may change of the flashed observer's settings (each
/// printed as an override: not what the MCU runs).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct OmniOverrides {
    /// Thermocouple noise \[K\] (`--measurement-noise-k`).
    pub sensor_sigma_k: Option<f64>,
    /// Every node's process noise \[K^2/s\] (`--process-noise-k2-per-s`).
    pub node_noise_k2_per_s: Option<f64>,
    /// The heat-input bias noise \[W^2/s\] (`--bias-noise-w2-per-s`).
    pub bias_noise_w2_per_s: Option<f64>,
}

/// The settings of the flashed observer with the thermocouples
/// `fitted` and `overrides`.
pub fn settings(fitted: [bool; THERMOCOUPLES], overrides: &OmniOverrides) -> OmniSettings {
    let defaults = omnimagnet_settings();
    let mut filter = defaults.filter;
    filter.sensors = fitted;
    if let Some(s) = overrides.sensor_sigma_k {
        filter.thermocouple_sigma_k = s;
    }
    if let Some(q) = overrides.node_noise_k2_per_s {
        filter.node_noise_k2_per_s = [q; NODES];
    }
    if let Some(q) = overrides.bias_noise_w2_per_s {
        filter.bias_noise_w2_per_s = q;
    }
    OmniSettings { filter, ..defaults }
}

/// The flashed Omnimagnet observer replayed tick by tick (see the module
/// docs).
pub struct OmniFirmwareEstimator {
    info: PlantInfo,
    observer: OmniObserver,
    settings: OmniSettings,
    state: Box<OmniObserverState<NoWarmUp>>,
    /// The thermocouple slot of each fused sensor, in `--measure` order.
    slots: Vec<usize>,
    currents_a: [f32; SOLENOIDS],
    ambient_c: f32,
    pending: [Option<f32>; THERMOCOUPLES],
    now_us: u32,
    /// The start temperatures, until the first row's ambient arrives.
    start_c: Option<[f32; NODES]>,
    clock: TickClock,
    temps: Vec<f64>,
    tick_ns: TimeHistogram,
    protected: Protected,
    events: Vec<EventKindAt>,
    stats: Vec<FusionStats>,
    awaiting: bool,
}

impl OmniFirmwareEstimator {
    /// The flashed observer for the plant `info` (the Omnimagnet's model:
    /// its 16 nodes, three solenoid currents, the ambient), with
    /// thermocouples on `fused_nodes` (none: the flashed six, never read).
    ///
    /// # Errors
    /// Another model, a fused node without a thermocouple, a set that
    /// needs a model refresh, or a refusal of the library's builder.
    pub fn new(info: PlantInfo, fused_nodes: &[usize], overrides: &OmniOverrides) -> Result<Self> {
        if info.nodes.len() != NODES || info.inputs.len() != SOLENOIDS {
            bail!(
                "the flashed Omnimagnet observer has {NODES} nodes and {SOLENOIDS} currents; model `{}` has {} and {}",
                info.name,
                info.nodes.len(),
                info.inputs.len()
            );
        }
        let mut slots = Vec::with_capacity(fused_nodes.len());
        for &node in fused_nodes {
            // Two thermocouples per solenoid: the first free slot on the node.
            let Some(j) =
                (0..THERMOCOUPLES).find(|j| THERMOCOUPLE_NODES[*j] == node && !slots.contains(j))
            else {
                bail!(
                    "--measure onto `{}`: the flashed Omnimagnet observer has two thermocouples on each of {} and none elsewhere",
                    info.nodes[node],
                    [0, 2, 4]
                        .map(|j| info.nodes[THERMOCOUPLE_NODES[j]].as_str())
                        .join(", ")
                );
            };
            slots.push(j);
        }
        let fitted: [bool; THERMOCOUPLES] = if slots.is_empty() {
            [true; THERMOCOUPLES]
        } else {
            core::array::from_fn(|j| slots.contains(&j))
        };
        if let Some(solenoid) = needs_model_refresh(&fitted) {
            bail!(
                "these thermocouples leave solenoid {} with at most one: its firmware needs a model refresh (codegen --device omnimagnet --model-refresh-s), \
                 which a replay does not run; fuse both thermocouples of every solenoid",
                solenoid + 1
            );
        }
        let settings = settings(fitted, overrides);
        let observer = OmniObserver::new(
            &Omnimagnet::PAPER,
            &[OMNIMAGNET_AMBIENT_C; NODES],
            OMNIMAGNET_AMBIENT_C,
            &settings,
        )
        .map_err(|e| anyhow::anyhow!("the flashed Omnimagnet observer: {e}"))?;
        let ambient = OMNIMAGNET_AMBIENT_C as f32;
        let state = Box::new(observer.state(&[ambient; NODES], ambient));
        let stats = fused_nodes
            .iter()
            .map(|&node| FusionStats::new(node))
            .collect();
        Ok(Self {
            info,
            observer,
            settings,
            state,
            slots,
            currents_a: [0.0; SOLENOIDS],
            ambient_c: ambient,
            pending: [None; THERMOCOUPLES],
            now_us: 0,
            start_c: None,
            clock: TickClock::default(),
            temps: vec![OMNIMAGNET_AMBIENT_C; NODES],
            tick_ns: TimeHistogram::default(),
            protected: Protected::for_sizes(NODES, SOLENOIDS),
            events: Vec::new(),
            stats,
            awaiting: false,
        })
    }

    /// The settings the observer was built with.
    pub fn settings(&self) -> &OmniSettings {
        &self.settings
    }

    /// What each fused sensor's readings came to, in `--measure` order.
    pub fn stats(&self) -> &[FusionStats] {
        &self.stats
    }

    /// The published outputs into `temps` and `protected`.
    fn publish(&mut self) {
        let o = self.state.outputs();
        let limits_c = self.observer.alarm().alarm_limits_c(self.ambient_c);
        for (i, (t, u)) in o.temps_c.iter().zip(&o.upper_c).enumerate() {
            self.temps[i] = f64::from(*t);
            self.protected.upper_c[i] = f64::from(*u);
        }
        for (k, &node) in ALARM_NODES.iter().enumerate() {
            self.protected.alarm_limit_c[node] = limits_c.get(k).copied().map(f64::from);
            self.protected.time_to_limit_s[node] = o.time_to_limit_s[k].map(f64::from);
        }
        for (l, limit) in self.protected.source_limit_a.iter_mut().zip(&o.limits) {
            *l = f64::from(limit.current_a);
        }
        self.protected.warning = o.alarm.warning;
        self.protected.shutdown = o.alarm.shutdown;
        self.protected.predictive = o.alarm.predictive;
    }

    /// One tick of [`TICK_US`] with the held inputs and the pending
    /// readings, as a driver delivers them: sampled now.
    fn tick(&mut self) {
        self.now_us = self.now_us.wrapping_add(TICK_US);
        let now_us = self.now_us;
        let readings = core::array::from_fn(|j| {
            self.pending[j].take().map(|temp_c| TimedReading {
                result: Ok(Reading::new(temp_c)),
                sampled_at_us: now_us,
            })
        });
        let inputs = OmniInputs {
            currents_a: self.currents_a,
            ambient_c: self.ambient_c,
            readings,
            now_us,
            elapsed_us: TICK_US,
        };
        let start = Instant::now();
        std::hint::black_box(self.observer.tick(&mut self.state, &inputs));
        self.tick_ns.record(start.elapsed().as_nanos());
        let upper = self.state.outputs().upper_c;
        let limits_c = self.observer.alarm().alarm_limits_c(self.ambient_c);
        let margin_k = self.observer.alarm().warning_margin_k();
        while let Some(e) = self.state.events.pop() {
            let node = e.element.and_then(|k| ALARM_NODES.get(k).copied());
            let mut at = EventKindAt::of(
                &e,
                self.clock.done_s(),
                node.map(|n| upper[n]),
                e.element.and_then(|k| limits_c.get(k).copied()),
                margin_k,
            );
            at.node = node;
            self.events.push(at);
        }
        if self.awaiting {
            self.awaiting = false;
            let sensors = self.state.outputs().sensors;
            for (s, &j) in self.stats.iter_mut().zip(&self.slots) {
                match sensors[j] {
                    SensorStatus::Fused { .. } => s.fused += 1,
                    SensorStatus::Rejected { .. } => s.rejected += 1,
                    SensorStatus::Stuck { .. } => s.stuck += 1,
                    SensorStatus::ColderThanPhysics { .. } => s.colder_than_physics += 1,
                    _ => {}
                }
            }
        }
    }
}

impl Estimator for OmniFirmwareEstimator {
    fn info(&self) -> &PlantInfo {
        &self.info
    }

    /// The state is made at the first row, when its ambient is known.
    fn reset(&mut self, temps_c: &[f64]) {
        let start: [f32; NODES] = core::array::from_fn(|i| {
            temps_c.get(i).copied().unwrap_or(OMNIMAGNET_AMBIENT_C) as f32
        });
        self.temps = start.iter().map(|t| f64::from(*t)).collect();
        self.start_c = Some(start);
        self.pending = [None; THERMOCOUPLES];
        self.now_us = 0;
        self.clock = TickClock::default();
        self.events.clear();
        *self.state = self.observer.state(&start, self.ambient_c);
        self.publish();
    }

    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], _signals: &[f64]) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        for (held, a) in self.currents_a.iter_mut().zip(currents_a) {
            *held = *a as f32;
        }
        self.ambient_c = boundary_c.first().copied().unwrap_or(OMNIMAGNET_AMBIENT_C) as f32;
        if let Some(start) = self.start_c.take() {
            *self.state = self.observer.state(&start, self.ambient_c);
        }
        self.clock.ask(dt_s);
        while self.clock.next_tick(TICK_US) {
            self.tick();
        }
        self.publish();
    }

    /// Hands the row's readings to the next tick (the estimate recorded at
    /// this row is the prior, as for the network observer).
    fn update(&mut self, measured: &[Measurement]) {
        for (m, &j) in measured.iter().zip(&self.slots) {
            // A missing reading (an empty or NaN cell) is no reading.
            if m.node == THERMOCOUPLE_NODES[j] && m.value_c.is_finite() {
                self.pending[j] = Some(m.value_c as f32);
                self.awaiting = true;
            }
        }
    }

    fn estimate_c(&self) -> &[f64] {
        &self.temps
    }

    fn kind(&self) -> &'static str {
        "omni-observer"
    }

    fn take_tick_times_ns(&mut self) -> Option<TimeHistogram> {
        Some(std::mem::take(&mut self.tick_ns))
    }

    fn firmware(&mut self, out: &mut Protected, events: &mut Vec<EventKindAt>) -> bool {
        out.clone_from(&self.protected);
        events.append(&mut self.events);
        true
    }
}
