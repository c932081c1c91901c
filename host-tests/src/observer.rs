//! Replay: an estimator and a protection stage run over a recorded trace.
//!
//! The composition mirrors the library's observer tick: *predict* with the
//! inputs, *update* with the measurements, then *check* the estimate. Stage 1
//! ships [`OpenLoop`] (the model alone: `update` ignores measurements) and
//! [`CriticalThreshold`] alarms; the Kalman filter (`src/filter`) becomes a
//! second [`Estimator`] and the derating/alarm rules of `src/protect` a second
//! [`Protection`], with no change to [`replay`].

use std::time::Instant;

use anyhow::Result;
use serde::Serialize;

use crate::sim::{initial_temps, Drive, Plant, PlantInfo};

/// A measured temperature for one node at one row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// Node index.
    pub node: usize,
    /// Measured value \[degC\].
    pub value_c: f64,
}

/// A state estimator over a plant.
pub trait Estimator {
    /// The plant's names.
    fn info(&self) -> &PlantInfo;
    /// Sets the estimate \[degC\].
    fn reset(&mut self, temps_c: &[f64]);
    /// Time update over `dt_s` with inputs held (see [`Plant::step`]).
    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]);
    /// Measurement update (fused sensors only).
    fn update(&mut self, measured: &[Measurement]);
    /// Current estimate \[degC\].
    fn estimate_c(&self) -> &[f64];
    /// Short description for reports (e.g. `open-loop`).
    fn kind(&self) -> &'static str;
}

/// The model alone: measurements are not fused.
pub struct OpenLoop<P>(pub P);

impl<P: Plant> Estimator for OpenLoop<P> {
    fn info(&self) -> &PlantInfo {
        self.0.info()
    }
    fn reset(&mut self, temps_c: &[f64]) {
        self.0.reset(temps_c);
    }
    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        self.0.step(dt_s, currents_a, boundary_c, signals);
    }
    fn update(&mut self, _measured: &[Measurement]) {}
    fn estimate_c(&self) -> &[f64] {
        self.0.temps_c()
    }
    fn kind(&self) -> &'static str {
        "open-loop"
    }
}

/// An alarm raised or cleared.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AlarmEvent {
    /// Time \[s\].
    pub time_s: f64,
    /// Node name.
    pub node: String,
    /// `raised` or `cleared`.
    pub kind: &'static str,
    /// Estimated temperature \[degC\].
    pub temp_c: f64,
    /// Limit it was compared with \[degC\].
    pub limit_c: f64,
}

/// A protection stage: looks at each estimate, reports alarm transitions.
pub trait Protection {
    /// Checks the estimate at `time_s`; pushes transitions to `events`.
    fn check(&mut self, time_s: f64, estimate_c: &[f64], events: &mut Vec<AlarmEvent>);
}

/// Stage-1 placeholder until `src/protect`: an alarm per node above its
/// `critical_c`, cleared `hysteresis_k` below it.
pub struct CriticalThreshold {
    nodes: Vec<String>,
    critical_c: Vec<Option<f64>>,
    hysteresis_k: f64,
    active: Vec<bool>,
}

impl CriticalThreshold {
    /// From the plant's critical temperatures.
    pub fn new(info: &PlantInfo, hysteresis_k: f64) -> Self {
        Self {
            nodes: info.nodes.clone(),
            critical_c: info.critical_c.clone(),
            hysteresis_k,
            active: vec![false; info.nodes.len()],
        }
    }
}

impl Protection for CriticalThreshold {
    fn check(&mut self, time_s: f64, estimate_c: &[f64], events: &mut Vec<AlarmEvent>) {
        for (i, (limit, t)) in self.critical_c.iter().zip(estimate_c).enumerate() {
            let Some(limit) = *limit else { continue };
            let kind = if !self.active[i] && *t >= limit {
                self.active[i] = true;
                "raised"
            } else if self.active[i] && *t < limit - self.hysteresis_k {
                self.active[i] = false;
                "cleared"
            } else {
                continue;
            };
            events.push(AlarmEvent {
                time_s,
                node: self.nodes[i].clone(),
                kind,
                temp_c: *t,
                limit_c: limit,
            });
        }
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

/// Scores an estimate `[node][row]` against a sensor.
pub fn score(sensor: &Sensor, node_name: &str, estimate: &[Vec<f64>], time_s: &[f64]) -> Score {
    let est = &estimate[sensor.node];
    let mut sq = 0.0;
    let mut worst = (0.0f64, 0.0);
    for (k, (e, m)) in est.iter().zip(&sensor.values_c).enumerate() {
        let err = e - m;
        sq += err * err;
        if err.abs() > worst.0 {
            worst = (err.abs(), time_s[k]);
        }
    }
    let mse = sq / est.len().max(1) as f64;
    Score {
        column: sensor.column.clone(),
        node: node_name.to_string(),
        mse_k2: mse,
        rmse_k: mse.sqrt(),
        max_abs_error_k: worst.0,
        max_error_time_s: worst.1,
    }
}

/// Per-step time statistics against a budget.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepTimes {
    /// Number of timed steps.
    pub steps: usize,
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
    /// Percentiles of `samples_ns` (sorted in place).
    pub fn from_samples(samples_ns: &mut [f64]) -> Self {
        samples_ns.sort_by(f64::total_cmp);
        let pct = |p: f64| -> f64 {
            if samples_ns.is_empty() {
                return 0.0;
            }
            let k = ((samples_ns.len() - 1) as f64 * p).round() as usize;
            samples_ns[k]
        };
        let p99 = pct(0.99);
        Self {
            steps: samples_ns.len(),
            p50_ns: pct(0.5),
            p90_ns: pct(0.9),
            p99_ns: p99,
            max_ns: samples_ns.last().copied().unwrap_or(0.0),
            budget_ns: STEP_BUDGET_NS,
            p99_over_budget: p99 / STEP_BUDGET_NS,
        }
    }
}

/// What a replay produced.
#[derive(Debug, Clone)]
pub struct ReplayResult {
    /// Estimates `[node][row]` \[degC\].
    pub estimate: Vec<Vec<f64>>,
    /// Scores of the `--truth` sensors.
    pub scores: Vec<Score>,
    /// Alarm transitions.
    pub alarms: Vec<AlarmEvent>,
    /// Timing of predict + update per row.
    pub times: StepTimes,
}

/// Runs `estimator` and `protection` over `drive`, fusing `measured` and
/// scoring `truth`. Row `k`: update with row `k`'s measurements, record,
/// check, then predict over `[t_k, t_k+1)` with row `k`'s inputs.
pub fn replay(
    estimator: &mut dyn Estimator,
    protection: &mut dyn Protection,
    drive: &Drive,
    measured: &[Sensor],
    truth: &[Sensor],
) -> Result<ReplayResult> {
    let info = estimator.info().clone();
    let first: Vec<(usize, f64)> = measured
        .iter()
        .chain(truth)
        .map(|s| (s.node, s.values_c[0]))
        .collect();
    estimator.reset(&initial_temps(&info, drive, &first)?);
    let rows = drive.len();
    let mut estimate = vec![Vec::with_capacity(rows); info.nodes.len()];
    let mut alarms = Vec::new();
    let mut samples = Vec::with_capacity(rows);
    let (mut c, mut b, mut s) = (Vec::new(), Vec::new(), Vec::new());
    let mut meas = Vec::with_capacity(measured.len());
    for k in 0..rows {
        meas.clear();
        meas.extend(measured.iter().map(|m| Measurement {
            node: m.node,
            value_c: m.values_c[k],
        }));
        let start = Instant::now();
        estimator.update(&meas);
        let mut elapsed = start.elapsed();
        for (series, t) in estimate.iter_mut().zip(estimator.estimate_c()) {
            series.push(*t);
        }
        protection.check(drive.time_s[k], estimator.estimate_c(), &mut alarms);
        if k + 1 < rows {
            drive.row(k, &mut c, &mut b, &mut s);
            let start = Instant::now();
            estimator.predict(drive.time_s[k + 1] - drive.time_s[k], &c, &b, &s);
            elapsed += start.elapsed();
        }
        samples.push(elapsed.as_nanos() as f64);
    }
    let scores = truth
        .iter()
        .map(|t| score(t, &info.nodes[t.node], &estimate, &drive.time_s))
        .collect();
    Ok(ReplayResult {
        estimate,
        scores,
        alarms,
        times: StepTimes::from_samples(&mut samples),
    })
}
