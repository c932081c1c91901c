//! Replay: an estimator and a protection stage run over a recorded trace.
//!
//! Per trace row: *update* with the row's measurements, *check* the
//! estimate, *predict* to the next row with the row's inputs. The
//! estimators are the firmware's observers, which raise their own alarms
//! (the library's `NetworkObserver` ticking at 1 ms,
//! [`crate::library_observer`], and the devices' in [`crate::grid_firmware`]
//! and [`crate::omni_firmware`]), and a model run open loop at the trace's
//! rows, watched by the host's [`LibraryAlarm`]: the library's
//! `coil_thermal::protect::alarm` with its derated limits, debounced
//! warning, latched shutdown and event queue.
//!
//! # At the model's own size
//!
//! A model file has its node count at run time: the watched nodes (those
//! with a critical temperature) are the elements of the library's alarm
//! at run-time size (`AlarmConfig<f64, Dyn>`, its vectors the model's
//! `Vec`s), with no padding and no cap. One tick runs in parts of
//! [`ALARM_PART`] elements (`AlarmState::tick_part`), the event queue
//! drained after each, so a queue of a fixed capacity never drops an
//! event however many elements cross at once.

use std::time::Instant;

use anyhow::{anyhow, bail, Result};
use coil_thermal::nalgebra::Dyn;
use coil_thermal::protect::alarm::{AlarmBuilder, AlarmConfig, AlarmState, AlarmStatus};
use coil_thermal::protect::derating::DeratingRule;
use coil_thermal::protect::events::{AlarmEvent as LibEvent, EventKind, EventQueue};
use serde::Serialize;

use crate::limits::TimeToLimit;

use crate::sim::{InputRow, PlantInfo, RowSource};

/// A measured temperature for one node at one row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Node index.
    pub node: usize,
    /// Measured value \[degC\] (`NaN`: none).
    pub value_c: f64,
    /// The fault the sensor reported instead of a value (a conversion's:
    /// see [`crate::raw_sensors`]).
    pub fault: Option<coil_thermal::SensorFault>,
}

/// A state estimator over a plant.
pub trait Estimator {
    /// The plant's names.
    fn info(&self) -> &PlantInfo;
    /// Sets the estimate \[degC\].
    fn reset(&mut self, temps_c: &[f64]);
    /// Time update over `dt_s` with inputs held (see [`crate::sim::Plant::step`]).
    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]);
    /// Measurement update (fused sensors only).
    fn update(&mut self, measured: &[Measurement]);
    /// Current estimate \[degC\].
    fn estimate_c(&self) -> &[f64];
    /// Short description for reports (e.g. `open-loop`).
    fn kind(&self) -> &'static str;
    /// The host times of the library ticks since the last call \[ns\],
    /// for an estimator that runs the library's observer tick by tick;
    /// `None` for one that steps once per trace row.
    fn take_tick_times_ns(&mut self) -> Option<TimeHistogram> {
        None
    }
    /// For an estimator that runs the firmware's observer: its
    /// protection's outputs after the last tick into `out`, and its alarm
    /// events since the last call into `events`; returns `false` (and
    /// writes nothing) for one that has no protection of its own (the
    /// replay's [`Protection`] then watches the estimate).
    fn firmware(
        &mut self,
        _out: &mut crate::library_observer::Protected,
        _events: &mut Vec<crate::library_observer::EventKindAt>,
    ) -> bool {
        false
    }
}

/// One event of the library's alarm, with its time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlarmEvent {
    /// Time of the row whose estimate caused it \[s\].
    pub time_s: f64,
    /// Node name; `None` for the ambient sensor and for a reset.
    pub node: Option<String>,
    /// `warning`, `shutdown`, `predictive`, `sensor` or `reset`.
    pub level: &'static str,
    /// `raised`, `cleared`, `latched` (shutdown), `invalid` or `valid`
    /// (sensor), `reset`.
    pub kind: &'static str,
    /// The node's estimated temperature at that row \[degC\] (`None` without
    /// a node).
    pub temp_c: Option<f64>,
    /// The level it was compared with at that row's ambient \[degC\]: the
    /// warning level for a warning, the derated alarm limit otherwise.
    pub limit_c: Option<f64>,
}

/// A protection stage: looks at each estimate, reports alarm events.
pub trait Protection {
    /// Checks the estimate `estimate_c` \[degC\] of the row at `time_s` \[s\]
    /// with that row's inputs (held from now on): `currents_a` per model
    /// input \[A\], `boundary_c` per boundary \[degC\] and `signals`; pushes
    /// what changed to `events`.
    fn check(
        &mut self,
        time_s: f64,
        estimate_c: &[f64],
        currents_a: &[f64],
        boundary_c: &[f64],
        signals: &[f64],
        events: &mut Vec<AlarmEvent>,
    );
}

/// The settings of [`LibraryAlarm`]: the library's
/// [`AlarmBuilder`] parameters, per node, plus where the ambient comes from.
#[derive(Debug, Clone)]
pub struct AlarmSettings {
    /// The derating rule of the alarm limits.
    pub rule: DeratingRule,
    /// Critical temperature of each node \[degC\]; nodes with `None` are not
    /// watched.
    pub critical_c: Vec<Option<f64>>,
    /// The warning rises this far below the alarm limit \[K\].
    pub warning_margin_k: f64,
    /// How far below a level a clear (or a reset) needs \[K\].
    pub hysteresis_k: f64,
    /// Rows of evidence to raise or clear an alarm (the alarm's tick is one
    /// replay row).
    pub debounce_rows: u16,
    /// Predictive alarm horizon \[s\]: the predictive alarm rises when a
    /// node's time to limit falls below it (only with
    /// [`LibraryAlarm::with_time_to_limit`]).
    pub horizon_s: f64,
    /// The boundary whose temperature is the measured ambient of the
    /// derating rule; `None`: `nominal_ambient_c` throughout.
    pub ambient_boundary: Option<usize>,
    /// The ambient before the first valid one, or throughout \[degC\].
    pub nominal_ambient_c: f64,
}

/// Elements of the alarm ticked between two drains of its event queue.
pub const ALARM_PART: usize = 96;

/// Every event one part of a tick can push: four per element (sensor,
/// warning, shutdown, predictive) and the ambient's.
const EVENT_CAPACITY: usize = 4 * ALARM_PART + 1;

/// The library's alarm ([`AlarmState`]) over the watched nodes, at the
/// model's own size.
struct RunTimeAlarm {
    config: AlarmConfig<f64, Dyn>,
    state: AlarmState<f64, Dyn>,
    events: EventQueue<EVENT_CAPACITY>,
}

impl RunTimeAlarm {
    fn build(s: &AlarmSettings, critical_c: &[f64]) -> Result<Self> {
        let config = AlarmBuilder::<Dyn>::of(&s.rule, critical_c.to_vec())
            .warning_margin_k(s.warning_margin_k)
            .hysteresis_k(s.hysteresis_k)
            .debounce_ticks(s.debounce_rows)
            .horizon_s(s.horizon_s)
            .nominal_ambient_c(s.nominal_ambient_c)
            .build::<f64>()
            .map_err(|e| anyhow!("alarm: {e}"))?;
        Ok(Self {
            state: AlarmState::new(&config),
            config,
            events: EventQueue::new(),
        })
    }

    /// One alarm tick over every element, in parts of [`ALARM_PART`];
    /// every event goes to `sink` in queue order.
    fn tick(
        &mut self,
        temps_c: &Vec<f64>,
        ambient_c: f64,
        time_to_limit_s: &Vec<Option<f64>>,
        sink: &mut dyn FnMut(LibEvent),
    ) -> AlarmStatus {
        let mut status = AlarmStatus::default();
        // At least one part: the first counts the tick and judges the
        // ambient, with or without elements.
        for start in (0..temps_c.len().max(1)).step_by(ALARM_PART) {
            let part = self.state.tick_part(
                &self.config,
                temps_c,
                ambient_c,
                time_to_limit_s,
                &mut self.events,
                start..start + ALARM_PART,
            );
            while let Some(event) = self.events.pop() {
                sink(event);
            }
            status = status.union(part);
        }
        status
    }

    /// The alarm limit of element `e` at the ambient of the last tick
    /// \[degC\].
    fn limit_c(&self, e: usize) -> Option<f64> {
        self.config.alarm_limit_c(e, self.state.ambient_c())
    }

    /// The warning margin \[K\].
    fn warning_margin_k(&self) -> f64 {
        self.config.warning_margin_k()
    }
}

/// The library's derated, debounced, latched alarm as a replay
/// [`Protection`]: one element per node with a critical temperature, limits
/// derated at the measured ambient every row.
pub struct LibraryAlarm {
    /// Plant node of each element.
    nodes: Vec<usize>,
    names: Vec<String>,
    ambient_boundary: Option<usize>,
    nominal_ambient_c: f64,
    alarm: RunTimeAlarm,
    temps_c: Vec<f64>,
    time_to_limit_s: Vec<Option<f64>>,
    /// This row's library events, drained from the queue.
    pending: Vec<LibEvent>,
    shutdown: bool,
    prediction: Option<Prediction>,
}

/// The time to limit feeding the predictive alarm, and its record.
struct Prediction {
    predictor: TimeToLimit,
    horizon_s: f64,
    /// Each node's alarm limit of this row (`None`: not watched) \[degC\].
    limits_c: Vec<Option<f64>>,
    summary: TimeToLimitSummary,
    sweep_ns: TimeHistogram,
}

/// What the time-to-limit prediction saw over a replay.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct TimeToLimitSummary {
    /// The predictive alarm's horizon \[s\].
    pub horizon_s: f64,
    /// The shortest predicted time to limit of any watched node \[s\]
    /// (`None`: every node was "never" on every row).
    pub min_s: Option<f64>,
    /// The node that had it.
    pub min_node: Option<String>,
    /// The row time at which it was predicted \[s\].
    pub min_at_time_s: Option<f64>,
    /// The first row at which any node's time to limit was below the
    /// horizon \[s\] (the predictive alarm rises `--debounce-rows` later).
    pub first_below_horizon_time_s: Option<f64>,
    /// Rows whose prediction was unknown (`NaN`: an input was not finite).
    pub unknown_rows: usize,
    /// Host time of one full prediction sweep \[ns\]: median and maximum
    /// (the library's 1 ms tick runs it in slices; not in the step time).
    pub sweep_p50_ns: f64,
    /// ... maximum.
    pub sweep_max_ns: f64,
}

impl LibraryAlarm {
    /// Builds the alarm for `info`'s nodes with a critical temperature in
    /// `settings` (in node order), at their number (any).
    ///
    /// # Errors
    /// A boundary index out of range, or a parameter the library's builder
    /// refuses.
    pub fn new(info: &PlantInfo, settings: &AlarmSettings) -> Result<Self> {
        if settings.critical_c.len() != info.nodes.len() {
            bail!(
                "alarm: {} critical temperatures for {} nodes",
                settings.critical_c.len(),
                info.nodes.len()
            );
        }
        if let Some(b) = settings
            .ambient_boundary
            .filter(|b| *b >= info.boundaries.len())
        {
            bail!(
                "alarm: boundary {b} does not exist in model `{}`",
                info.name
            );
        }
        let (nodes, critical_c): (Vec<usize>, Vec<f64>) = settings
            .critical_c
            .iter()
            .enumerate()
            .filter_map(|(i, c)| c.map(|c| (i, c)))
            .unzip();
        let n = nodes.len();
        let alarm = RunTimeAlarm::build(settings, &critical_c)?;
        Ok(Self {
            names: nodes.iter().map(|i| info.nodes[*i].clone()).collect(),
            nodes,
            ambient_boundary: settings.ambient_boundary,
            nominal_ambient_c: settings.nominal_ambient_c,
            alarm,
            temps_c: vec![0.0; n],
            time_to_limit_s: vec![None; n],
            pending: Vec::new(),
            shutdown: false,
            prediction: None,
        })
    }

    /// Feeds the predictive alarm: every row, each watched node's time to
    /// its alarm limit (the library's derated limit at the alarm's
    /// ambient) is predicted by `predictor` with that row's inputs held,
    /// and the alarm compares it with `horizon_s` \[s\].
    ///
    /// # Errors
    /// `predictor`'s model has other nodes, inputs, boundaries or signals
    /// than the replayed plant `info`, or `horizon_s` is not finite and
    /// positive.
    pub fn with_time_to_limit(
        mut self,
        info: &PlantInfo,
        predictor: TimeToLimit,
        horizon_s: f64,
    ) -> Result<Self> {
        if !(horizon_s.is_finite() && horizon_s > 0.0) {
            bail!("time to limit: the horizon must be finite and > 0 s, got {horizon_s}");
        }
        let model = predictor.model();
        let names = |v: &mut dyn Iterator<Item = String>| v.collect::<Vec<_>>();
        let same = model.nodes == info.nodes
            && names(&mut model.inputs.iter().map(|i| i.name.clone()))
                == names(&mut info.inputs.iter().map(|i| i.name.clone()))
            && names(&mut model.boundaries.iter().map(|b| b.name.clone()))
                == names(&mut info.boundaries.iter().map(|b| b.name.clone()))
            && model.signals == info.signals;
        if !same {
            bail!(
                "time to limit: model `{}` does not have the nodes, inputs, boundaries and signals of the replayed `{}`",
                model.name,
                info.name
            );
        }
        self.prediction = Some(Prediction {
            predictor,
            horizon_s,
            limits_c: vec![None; info.nodes.len()],
            summary: TimeToLimitSummary {
                horizon_s,
                ..Default::default()
            },
            sweep_ns: TimeHistogram::default(),
        });
        Ok(self)
    }

    /// What the time-to-limit prediction saw so far (`None` without
    /// [`Self::with_time_to_limit`]).
    pub fn time_to_limit(&self) -> Option<TimeToLimitSummary> {
        self.prediction.as_ref().map(|p| {
            let mut summary = p.summary.clone();
            let ns = &p.sweep_ns;
            summary.sweep_p50_ns = ns.nth(ns.count() / 2).map_or(0.0, |v| v as f64);
            summary.sweep_max_ns = ns.max().map_or(0.0, |v| v as f64);
            summary
        })
    }

    /// Each node's time to limit at this row, into `self.time_to_limit_s`
    /// (per watched node; all `None` without a predictor).
    fn predict(
        &mut self,
        time_s: f64,
        estimate_c: &[f64],
        currents_a: &[f64],
        boundary_c: &[f64],
        signals: &[f64],
    ) {
        let Some(p) = self.prediction.as_mut() else {
            self.time_to_limit_s.fill(None);
            return;
        };
        for (e, &node) in self.nodes.iter().enumerate() {
            p.limits_c[node] = self.alarm.limit_c(e);
        }
        let start = Instant::now();
        let ttl = p
            .predictor
            .predict(estimate_c, currents_a, boundary_c, signals, &p.limits_c);
        p.sweep_ns.record(start.elapsed().as_nanos());
        let s = &mut p.summary;
        let mut unknown = false;
        for ((out, &node), name) in self
            .time_to_limit_s
            .iter_mut()
            .zip(&self.nodes)
            .zip(&self.names)
        {
            *out = ttl[node];
            match ttl[node] {
                Some(t) if t.is_nan() => unknown = true,
                Some(t) => {
                    if s.min_s.is_none_or(|m| t < m) {
                        s.min_s = Some(t);
                        s.min_node = Some(name.clone());
                        s.min_at_time_s = Some(time_s);
                    }
                    if t < p.horizon_s && s.first_below_horizon_time_s.is_none() {
                        s.first_below_horizon_time_s = Some(time_s);
                    }
                }
                None => {}
            }
        }
        s.unknown_rows += usize::from(unknown);
    }

    /// Nodes watched (those with a critical temperature), in node order.
    pub fn watched(&self) -> &[String] {
        &self.names
    }

    /// `true` once any shutdown has latched.
    pub fn shutdown_latched(&self) -> bool {
        self.shutdown
    }
}

impl Protection for LibraryAlarm {
    fn check(
        &mut self,
        time_s: f64,
        estimate_c: &[f64],
        currents_a: &[f64],
        boundary_c: &[f64],
        signals: &[f64],
        events: &mut Vec<AlarmEvent>,
    ) {
        for (t, &node) in self.temps_c.iter_mut().zip(&self.nodes) {
            *t = estimate_c[node];
        }
        self.predict(time_s, estimate_c, currents_a, boundary_c, signals);
        let ambient_c = self
            .ambient_boundary
            .map_or(self.nominal_ambient_c, |b| boundary_c[b]);
        self.pending.clear();
        let status = self
            .alarm
            .tick(&self.temps_c, ambient_c, &self.time_to_limit_s, &mut |e| {
                self.pending.push(e)
            });
        self.shutdown |= status.shutdown;
        let margin_k = self.alarm.warning_margin_k();
        for e in &self.pending {
            // An index past the watched nodes cannot come, but would not
            // be a node either.
            let element = e.element.filter(|i| *i < self.nodes.len());
            let (level, kind) = describe(e.kind);
            let limit_c = element.and_then(|i| self.alarm.limit_c(i)).map(|l| {
                if level == "warning" {
                    l - margin_k
                } else {
                    l
                }
            });
            events.push(AlarmEvent {
                time_s,
                node: element.map(|i| self.names[i].clone()),
                level,
                kind,
                temp_c: element.map(|i| self.temps_c[i]),
                limit_c,
            });
        }
    }
}

/// (level, kind) names of a library event.
pub fn describe(kind: EventKind) -> (&'static str, &'static str) {
    match kind {
        EventKind::WarningRaised => ("warning", "raised"),
        EventKind::WarningCleared => ("warning", "cleared"),
        EventKind::ShutdownLatched => ("shutdown", "latched"),
        EventKind::PredictiveRaised => ("predictive", "raised"),
        EventKind::PredictiveCleared => ("predictive", "cleared"),
        EventKind::SensorInvalid => ("sensor", "invalid"),
        EventKind::SensorValid => ("sensor", "valid"),
        EventKind::Reset => ("reset", "reset"),
        EventKind::ClockFrozen => ("clock", "frozen"),
    }
}

/// A measured column mapped to a node.
#[derive(Debug, Clone, PartialEq)]
pub struct Sensor {
    /// Column name (or expression text).
    pub column: String,
    /// Node index.
    pub node: usize,
    /// Values per row \[degC\].
    pub values_c: Vec<f64>,
}

/// Error statistics of one held-out sensor.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Score {
    /// Column name.
    pub column: String,
    /// Node it is compared with.
    pub node: String,
    /// Mean squared error \[K^2\].
    pub mse_k2: f64,
    /// Root mean squared error \[K\].
    pub rmse_k: f64,
    /// Largest absolute error \[K\].
    pub max_abs_error_k: f64,
    /// Time of the largest error \[s\].
    pub max_error_time_s: f64,
}

/// Scores an estimate `[node][row]` against a sensor, over the rows that
/// have a reading (a `NaN` reading is missing and skipped).
pub fn score(sensor: &Sensor, node_name: &str, estimate: &[Vec<f64>], time_s: &[f64]) -> Score {
    let mut sum = ScoreSum::default();
    for ((e, m), t) in estimate[sensor.node]
        .iter()
        .zip(&sensor.values_c)
        .zip(time_s)
    {
        sum.push(*t, *e, *m);
    }
    sum.score(&sensor.column, node_name)
}

/// Per-step time statistics against a budget.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepTimes {
    /// What one step is: `library tick` (one call of the library
    /// observer's `tick`) or `trace row` (a host estimator's predict and
    /// update over one row).
    pub step: &'static str,
    /// Number of timed steps.
    pub steps: usize,
    /// Smallest \[ns\].
    pub min_ns: f64,
    /// Median \[ns\].
    pub p50_ns: f64,
    /// 90th percentile \[ns\].
    pub p90_ns: f64,
    /// 99th percentile \[ns\].
    pub p99_ns: f64,
    /// Largest \[ns\].
    pub max_ns: f64,
    /// Budget \[ns\] (0.1 ms).
    pub budget_ns: f64,
    /// `p99 / budget`.
    pub p99_over_budget: f64,
}

/// The per-step budget of the observer tick \[ns\] (0.1 ms).
pub const STEP_BUDGET_NS: f64 = 100_000.0;

impl StepTimes {
    /// Percentiles of library ticks' times \[ns\].
    pub fn from_ticks(ticks_ns: &TimeHistogram) -> Self {
        Self::from_histogram("library tick", ticks_ns)
    }

    /// Percentiles of per-row times \[ns\].
    pub fn from_samples(samples_ns: &TimeHistogram) -> Self {
        Self::from_histogram("trace row", samples_ns)
    }

    /// The element `round((n - 1) p)` of the sorted times, for `p` in
    /// 0, 0.5, 0.9, 0.99 and 1 (the smallest and largest exact, the others
    /// within [`TimeHistogram`]'s resolution).
    fn from_histogram(step: &'static str, h: &TimeHistogram) -> Self {
        let n = h.count();
        let pct = |p: f64| -> f64 {
            if n == 0 {
                return 0.0;
            }
            let k = ((n - 1) as f64 * p).round() as u64;
            h.nth(k).map_or(0.0, |v| v as f64)
        };
        let p99 = pct(0.99);
        Self {
            step,
            steps: n as usize,
            min_ns: h.min().map_or(0.0, |v| v as f64),
            p50_ns: pct(0.5),
            p90_ns: pct(0.9),
            p99_ns: p99,
            max_ns: h.max().map_or(0.0, |v| v as f64),
            budget_ns: STEP_BUDGET_NS,
            p99_over_budget: p99 / STEP_BUDGET_NS,
        }
    }
}

/// A trace's time turned into whole firmware ticks, as the replays tick
/// the library: the time asked for so far \[s\] and the ticks done \[us\];
/// a remainder shorter than a tick carries to the next row.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TickClock {
    asked_s: f64,
    done_us: u64,
}

impl TickClock {
    /// Asks for `dt_s` \[s\] more.
    pub fn ask(&mut self, dt_s: f64) {
        self.asked_s += dt_s;
    }

    /// Counts one more tick of `tick_us` \[us\] done if it fits in the
    /// time asked for; `false` when the next one does not.
    pub fn next_tick(&mut self, tick_us: u32) -> bool {
        let target_us = (self.asked_s * 1e6).round() as u64;
        let fits = self.done_us + u64::from(tick_us) <= target_us;
        if fits {
            self.done_us += u64::from(tick_us);
        }
        fits
    }

    /// The end of the ticks done \[s\].
    pub fn done_s(&self) -> f64 {
        self.done_us as f64 * 1e-6
    }
}

/// Host times \[ns\] counted in memory that does not grow with their
/// number: exact below 2048 ns, above in buckets of 1/1024 of their size
/// (a percentile is its bucket's lowest time, within 0.1 %); the smallest
/// and largest exact. Times beyond `u32::MAX` ns (4.3 s) count as that.
#[derive(Debug, Clone, Default)]
pub struct TimeHistogram {
    counts: Vec<u64>,
    n: u64,
    min: Option<u64>,
    max: Option<u64>,
}

/// Sub-buckets per power of two above the exact range.
const SUB_BITS: u32 = 10;

impl TimeHistogram {
    fn bucket(v: u64) -> usize {
        if v < 2 << SUB_BITS {
            v as usize
        } else {
            let e = 63 - v.leading_zeros() - SUB_BITS;
            (((e + 1) << SUB_BITS) as u64 + (v >> e) - (1 << SUB_BITS)) as usize
        }
    }

    fn lowest(b: usize) -> u64 {
        if b < 2 << SUB_BITS {
            b as u64
        } else {
            let e = (b >> SUB_BITS) - 1;
            (((b & ((1 << SUB_BITS) - 1)) + (1 << SUB_BITS)) as u64) << e
        }
    }

    /// Counts one time \[ns\].
    pub fn record(&mut self, ns: impl TryInto<u32>) {
        let v = u64::from(ns.try_into().unwrap_or(u32::MAX));
        let b = Self::bucket(v);
        if b >= self.counts.len() {
            self.counts.resize(b + 1, 0);
        }
        self.counts[b] += 1;
        self.n += 1;
        self.min = Some(self.min.map_or(v, |m| m.min(v)));
        self.max = Some(self.max.map_or(v, |m| m.max(v)));
    }

    /// How many times were counted.
    pub fn count(&self) -> u64 {
        self.n
    }

    /// The smallest time \[ns\].
    pub fn min(&self) -> Option<u64> {
        self.min
    }

    /// The largest time \[ns\].
    pub fn max(&self) -> Option<u64> {
        self.max
    }

    /// The `k`-th smallest time (0-based) \[ns\]: exact below 2048 ns,
    /// else its bucket's lowest (the largest exact).
    pub fn nth(&self, k: u64) -> Option<u64> {
        if k + 1 >= self.n {
            return self.max.filter(|_| k < self.n);
        }
        let mut below = 0;
        for (b, c) in self.counts.iter().enumerate() {
            below += c;
            if below > k {
                return Some(Self::lowest(b).max(self.min.unwrap_or(0)));
            }
        }
        None
    }
}

/// One row of a replay, as [`replay`] hands it on.
pub struct ReplayRow<'a> {
    /// The row's inputs (time, currents, boundaries, signals, readings).
    pub row: &'a InputRow,
    /// The estimate at the row, after its readings \[degC\].
    pub estimate_c: &'a [f64],
    /// The alarm events of the row, in order: the firmware observer's
    /// since the previous row, or the replay's [`Protection`]'s.
    pub events: &'a [AlarmEvent],
    /// What the firmware observer's protection acts on at the row (`None`
    /// for an estimator without one).
    pub protected: Option<&'a crate::library_observer::Protected>,
}

/// Runs `estimator` and `protection` over the rows of `source`, from
/// `init` \[degC\], fusing the readings `fused` (node, position in
/// [`InputRow::extra`]) at rows up to `fuse_until_s` \[s\] (all rows
/// without it); hands every row to `sink` and returns the step times. Row
/// `k`: update with row `k`'s readings, check, hand on, then predict over
/// `[t_k, t_k+1)` with row `k`'s inputs. Nothing is kept per row.
pub fn replay(
    estimator: &mut dyn Estimator,
    protection: &mut dyn Protection,
    init: &[f64],
    source: &mut dyn RowSource,
    fused: &[(usize, usize)],
    fuse_until_s: Option<f64>,
    sink: &mut dyn FnMut(&ReplayRow) -> Result<()>,
) -> Result<StepTimes> {
    estimator.reset(init);
    let mut samples = TimeHistogram::default();
    let mut events = Vec::new();
    let mut firmware_events = Vec::new();
    let mut protected = crate::library_observer::Protected::default();
    let mut start_s = None;
    let mut meas = Vec::with_capacity(fused.len());
    let mut current = source.next_row()?;
    while let Some(row) = current {
        let after = fuse_until_s.is_some_and(|until| row.time_s > until);
        meas.clear();
        meas.extend(fused.iter().map(|(node, j)| {
            Measurement {
                node: *node,
                value_c: if after { f64::NAN } else { row.extra[*j] },
                fault: row
                    .faults
                    .iter()
                    .find(|(slot, _)| slot == j && !after)
                    .map(|(_, fault)| *fault),
            }
        }));
        let start = Instant::now();
        estimator.update(&meas);
        let mut elapsed = start.elapsed();
        events.clear();
        firmware_events.clear();
        let firmware = estimator.firmware(&mut protected, &mut firmware_events);
        if firmware {
            // The firmware's own alarm, on its upper bounds, at the ticks
            // since the previous row.
            let t0 = *start_s.get_or_insert(row.time_s);
            let names = &estimator.info().nodes;
            events.extend(firmware_events.iter().map(|e| {
                let (level, kind) = describe(e.kind);
                AlarmEvent {
                    time_s: t0 + e.since_start_s,
                    node: e.node.and_then(|i| names.get(i).cloned()),
                    level,
                    kind,
                    temp_c: e.upper_c,
                    limit_c: e.limit_c,
                }
            }));
        } else {
            protection.check(
                row.time_s,
                estimator.estimate_c(),
                &row.currents,
                &row.boundaries,
                &row.signals,
                &mut events,
            );
        }
        sink(&ReplayRow {
            row: &row,
            estimate_c: estimator.estimate_c(),
            events: &events,
            protected: firmware.then_some(&protected),
        })?;
        let next = source.next_row()?;
        if let Some(next) = &next {
            let start = Instant::now();
            estimator.predict(
                next.time_s - row.time_s,
                &row.currents,
                &row.boundaries,
                &row.signals,
            );
            elapsed += start.elapsed();
        }
        samples.record(elapsed.as_nanos());
        current = next;
    }
    Ok(match estimator.take_tick_times_ns() {
        Some(ticks) => StepTimes::from_ticks(&ticks),
        None => StepTimes::from_samples(&samples),
    })
}

/// A `--truth` sensor's score, accumulated row by row (what [`score`]
/// computes over a whole series, in the same order).
#[derive(Debug, Clone, Default)]
pub struct ScoreSum {
    sq: f64,
    n: usize,
    worst: (f64, f64),
}

impl ScoreSum {
    /// Adds a row at `time_s` \[s\]: estimate and reading \[degC\] (a
    /// `NaN` reading is missing and skipped).
    pub fn push(&mut self, time_s: f64, estimate_c: f64, reading_c: f64) {
        if reading_c.is_nan() {
            return;
        }
        let err = estimate_c - reading_c;
        self.sq += err * err;
        self.n += 1;
        if err.abs() > self.worst.0 {
            self.worst = (err.abs(), time_s);
        }
    }

    /// The score of column `column` on node `node`.
    pub fn score(&self, column: &str, node: &str) -> Score {
        let mse = self.sq / self.n.max(1) as f64;
        Score {
            column: column.to_string(),
            node: node.to_string(),
            mse_k2: mse,
            rmse_k: mse.sqrt(),
            max_abs_error_k: self.worst.0,
            max_error_time_s: self.worst.1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model_file::InitialSpec;

    fn info(nodes: usize) -> PlantInfo {
        PlantInfo {
            name: "test".into(),
            nodes: (0..nodes).map(|i| format!("n{i}")).collect(),
            critical_c: vec![Some(100.0); nodes],
            inputs: Vec::new(),
            boundaries: Vec::new(),
            signals: Vec::new(),
            initial: InitialSpec::default(),
        }
    }

    fn settings(nodes: usize) -> AlarmSettings {
        AlarmSettings {
            rule: DeratingRule::hppa(),
            critical_c: vec![Some(100.0); nodes],
            warning_margin_k: 5.0,
            hysteresis_k: 2.0,
            debounce_rows: 1,
            horizon_s: 60.0,
            ambient_boundary: None,
            nominal_ambient_c: 20.0,
        }
    }

    /// Any number of watched nodes, on both sides of a part's end: the
    /// last element raises its own shutdown at the HPPA limit, 65.36 degC,
    /// and nothing else does.
    #[test]
    fn any_number_of_watched_nodes_alarms_on_its_own_elements() {
        let part = ALARM_PART;
        for n in [1, 3, part - 1, part, part + 1, 2 * part, 2 * part + 1, 300] {
            let mut alarm = LibraryAlarm::new(&info(n), &settings(n)).unwrap();
            let mut temps = vec![20.0; n];
            temps[n - 1] = 65.37;
            let mut events = Vec::new();
            alarm.check(0.0, &temps, &[], &[], &[], &mut events);
            let levels: Vec<_> = events.iter().map(|e| (e.level, e.kind)).collect();
            assert_eq!(
                levels,
                [("warning", "raised"), ("shutdown", "latched")],
                "{n}"
            );
            assert!(events
                .iter()
                .all(|e| e.node.as_deref() == Some(format!("n{}", n - 1).as_str())));
            assert!((events[1].limit_c.unwrap() - 65.36).abs() < 1e-12);
            assert!(alarm.shutdown_latched());
        }
    }

    /// More watched nodes than a part of a tick: the library's alarm,
    /// ticked in parts, is every element's own alarm. 250 elements through
    /// rows that cross each one's warning and shutdown at rows of its own,
    /// an invalid sample, and a fall back to the ambient: each element's
    /// events (level, kind, temperature and limit) are the ones an alarm of
    /// that element alone raises on its temperatures, and the latch is
    /// theirs.
    #[test]
    fn more_watched_nodes_than_a_part_are_each_elements_own_alarm() {
        let n = 2 * ALARM_PART + 58;
        let mut all = LibraryAlarm::new(&info(n), &settings(n)).unwrap();
        let mut alone: Vec<LibraryAlarm> = (0..n)
            .map(|_| LibraryAlarm::new(&info(1), &settings(1)).unwrap())
            .collect();
        let temp = |e: usize, row: usize| match (e % 50, row) {
            (3, 10) => f64::NAN,
            (_, 30..) if e % 2 == 1 => 20.0,
            _ => 20.0 + row as f64 * (1.0 + (e % 7) as f64 * 0.4),
        };
        let seen = |events: &[AlarmEvent]| -> Vec<_> {
            events
                .iter()
                .map(|ev| (ev.level, ev.kind, ev.temp_c.map(f64::to_bits), ev.limit_c))
                .collect()
        };
        let mut raised = 0;
        for row in 0..40 {
            let temps: Vec<f64> = (0..n).map(|e| temp(e, row)).collect();
            let mut events = Vec::new();
            all.check(row as f64, &temps, &[], &[], &[], &mut events);
            raised += events.len();
            for (e, own_alarm) in alone.iter_mut().enumerate() {
                let mut own = Vec::new();
                own_alarm.check(row as f64, &temps[e..=e], &[], &[], &[], &mut own);
                let name = format!("n{e}");
                let mine: Vec<AlarmEvent> = events
                    .iter()
                    .filter(|ev| ev.node.as_deref() == Some(name.as_str()))
                    .cloned()
                    .collect();
                assert_eq!(seen(&mine), seen(&own), "element {e}, row {row}");
            }
            let latched = alone.iter().any(LibraryAlarm::shutdown_latched);
            assert_eq!(all.shutdown_latched(), latched, "row {row}");
        }
        // Warnings and shutdowns raised, the odd ones' cleared, the NaN
        // samples' sensor events: the rows did exercise the alarm.
        assert!(raised > n, "{raised}");
    }
}
