//! `coil-thermal replay`.

use anyhow::{bail, Context, Result};
use serde_json::json;

use super::common;
use super::plot_cmd::ReplaySeries;
use super::ReplayArgs;
use crate::devices;
use crate::kalman::{KalmanEstimator, KalmanOptions, NoiseFromReadings};
use crate::library_observer::{BiasNoiseFrom, BiasSettings, Fusion, ObserverEstimator};
use crate::limits::TimeToLimit;
use crate::model_file::Model;
use crate::observer::Measurement;
use crate::observer::{replay, AlarmEvent, AlarmSettings, Estimator, LibraryAlarm, ScoreSum};
use crate::plot::render;
use crate::sim::{FilePlant, InputRow, Plant, PlantInfo, RowSource, TraceDrive};
use crate::trace::CsvOut;
use common::{SensorFlags, StreamSensor};

/// Alarm events printed in the text summary (`--json` has them all).
const MAX_PRINTED_EVENTS: usize = 20;

/// The alarm settings from the flags: the model's critical temperatures (or
/// `--critical-c`), the device's derating rule (or `--factors`), the
/// measured ambient from `--ambient-boundary` (default `ambient`, else the
/// first boundary).
fn alarm_settings(
    a: &ReplayArgs,
    info: &PlantInfo,
    first_boundaries_c: &[f64],
    median_row_s: f64,
) -> Result<AlarmSettings> {
    let spec = common::ModelSpec::parse(&a.model.model)?;
    let rule = common::derating_rule(&a.factors, common::default_rule(&spec))?;
    let non_negative = |v: f64, flag: &str| {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            bail!("{flag} must be finite and >= 0 K, got {v}")
        }
    };
    let positive = |v: f64, flag: &str| {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            bail!("{flag} must be finite and > 0 s, got {v}")
        }
    };
    if let Some(c) = a.critical_c.filter(|c| !c.is_finite()) {
        bail!("--critical-c must be finite, got {c}");
    }
    let ambient_boundary = match &a.ambient_boundary {
        Some(name) => Some(
            info.boundaries
                .iter()
                .position(|b| &b.name == name)
                .with_context(|| {
                    format!(
                        "--ambient-boundary: model `{}` has no boundary `{name}` (boundaries: {})",
                        info.name,
                        info.boundaries
                            .iter()
                            .map(|b| b.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                })?,
        ),
        None => info
            .boundaries
            .iter()
            .position(|b| b.name == "ambient")
            .or((!info.boundaries.is_empty()).then_some(0)),
    };
    let nominal_ambient_c = ambient_boundary
        .and_then(|b| first_boundaries_c.get(b).copied())
        .filter(|t| t.is_finite())
        .unwrap_or(devices::GRID_DEFAULT_C);
    Ok(AlarmSettings {
        rule,
        critical_c: match a.critical_c {
            Some(c) => vec![Some(c); info.nodes.len()],
            None => info.critical_c.clone(),
        },
        warning_margin_k: non_negative(a.warning_margin_k, "--warning-margin-k")?,
        hysteresis_k: non_negative(a.hysteresis_k, "--hysteresis-k")?,
        debounce_rows: debounce_rows(a, median_row_s)?,
        horizon_s: positive(a.horizon_s, "--horizon-s")?,
        ambient_boundary,
        nominal_ambient_c,
    })
}

/// The alarm's debounce in rows: `--debounce-rows`, or `--debounce-s`
/// over the trace's median row spacing `row_s` \[s\] (at least 1 row).
fn debounce_rows(a: &ReplayArgs, row_s: f64) -> Result<u16> {
    if let Some(rows) = a.debounce_rows {
        if rows == 0 {
            bail!("--debounce-rows must be at least 1");
        }
        return Ok(rows);
    }
    let s = a.debounce_s;
    if !(s.is_finite() && s >= 0.0) {
        bail!("--debounce-s must be finite and >= 0 s, got {s}");
    }
    let rows = if row_s > 0.0 {
        (s / row_s).round()
    } else {
        1.0
    };
    Ok(rows.clamp(1.0, f64::from(u16::MAX)) as u16)
}

/// The most library ticks one replay runs (about 14 h of trace at 1 ms).
const MAX_TICKS: f64 = 5e7;

/// Prints the event counts per level and kind, the first predictive
/// alarm, and the other events (at most [`MAX_PRINTED_EVENTS`]): with
/// currents that move every row the predictive alarm can rise and clear
/// often, and it would hide the rest.
fn print_events(log: &EventLog) {
    if log.total == 0 {
        println!("alarm events: none");
        return;
    }
    println!(
        "alarm events: {} ({})",
        log.total,
        log.counts
            .iter()
            .map(|(k, n)| format!("{k} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let line = |e: &AlarmEvent| {
        let at = match (&e.node, e.temp_c, e.limit_c) {
            (Some(n), Some(t), Some(l)) => format!(": {n} at {t:.2} degC (level {l:.2} degC)"),
            (Some(n), _, _) => format!(": {n}"),
            _ => String::new(),
        };
        println!("{} {} at t = {:.1} s{at}", e.level, e.kind, e.time_s);
    };
    if let Some(first) = &log.first_predictive {
        print!("first ");
        line(first);
    }
    log.others.iter().for_each(line);
    if log.others_total > MAX_PRINTED_EVENTS {
        println!(
            "... and {} more (--json lists every event)",
            log.others_total - MAX_PRINTED_EVENTS
        );
    }
}

/// A model file run open loop on the library's explicit stepper at the
/// trace's rows (for models whose network changes with a signal).
struct PlantEstimator(FilePlant);

impl Estimator for PlantEstimator {
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
        "explicit-stepper"
    }
}

/// The alarm events a replay keeps for `--json` and the figure (the first
/// ones; the counts cover all).
const MAX_KEPT_EVENTS: usize = 10_000;

/// What a replay's pass over the trace before the run found: the first
/// row's inputs, each sensor's first reading, the rows inside the window
/// and their median spacing, the peak heating power.
struct Survey {
    first: Option<InputRow>,
    first_readings: Vec<Option<f64>>,
    inside: usize,
    window_gaps: crate::trace::GapMedian,
    peak_heating_w: f64,
}

/// The pass before the run: every row's channels and sensors evaluated
/// (their errors kept for the checks), and what the run needs first.
fn survey(
    drive: &mut TraceDrive,
    model: &Model,
    sensors: &[(StreamSensor, bool)],
    until_s: Option<f64>,
    window: (f64, f64),
    peak: bool,
) -> Result<Survey> {
    let mut s = Survey {
        first: None,
        first_readings: vec![None; sensors.len()],
        inside: 0,
        window_gaps: crate::trace::GapMedian::default(),
        peak_heating_w: 0.0,
    };
    let net = &model.network;
    let fixed_w: f64 = net.fixed_powers_w().iter().sum();
    let mut effective = Vec::new();
    let mut last_inside: Option<f64> = None;
    let mut rows = drive.rows()?;
    while let Some(row) = rows.next_row()? {
        for ((sensor, fused), first) in sensors.iter().zip(&mut s.first_readings) {
            let masked = *fused && until_s.is_some_and(|u| row.time_s > u);
            let v = row.extra[sensor.slot];
            if first.is_none() && !v.is_nan() && !masked {
                *first = Some(v);
            }
        }
        if (window.0..=window.1).contains(&row.time_s) {
            s.inside += 1;
            if let Some(prev) = last_inside {
                s.window_gaps.push(row.time_s - prev);
            }
            last_inside = Some(row.time_s);
        }
        let first = s.first.get_or_insert_with(|| row.clone());
        if peak {
            // The sources' R I^2 at the first row's boundary temperature
            // (20 degC without a boundary) plus the fixed powers.
            let t_c = first.boundaries.first().copied().unwrap_or(20.0);
            model.effective_currents(&row.currents, &row.signals, &mut effective);
            let joule: f64 = net
                .sources()
                .iter()
                .zip(&effective)
                .map(|(src, i)| {
                    let r = src.resistance.r_at_0c_ohm + src.resistance.slope_ohm_per_k * t_c;
                    r.max(0.0) * i * i
                })
                .sum();
            s.peak_heating_w = s.peak_heating_w.max(joule + fixed_w);
        }
    }
    Ok(s)
}

/// The alarm events of a replay: the first [`MAX_KEPT_EVENTS`], and the
/// counts and first lines the text summary prints of all of them.
#[derive(Default)]
struct EventLog {
    kept: Vec<AlarmEvent>,
    total: usize,
    counts: Vec<(String, usize)>,
    first_predictive: Option<AlarmEvent>,
    others: Vec<AlarmEvent>,
    others_total: usize,
}

impl EventLog {
    fn push(&mut self, e: &AlarmEvent) {
        self.total += 1;
        if self.kept.len() < MAX_KEPT_EVENTS {
            self.kept.push(e.clone());
        }
        let key = format!("{} {}", e.level, e.kind);
        match self.counts.iter_mut().find(|(k, _)| *k == key) {
            Some((_, n)) => *n += 1,
            None => self.counts.push((key, 1)),
        }
        if e.level == "predictive" {
            if self.first_predictive.is_none() {
                self.first_predictive = Some(e.clone());
            }
        } else {
            self.others_total += 1;
            if self.others.len() < MAX_PRINTED_EVENTS {
                self.others.push(e.clone());
            }
        }
    }
}

/// Runs `replay`.
pub fn run(a: ReplayArgs) -> Result<()> {
    let model_file = common::model_file(&a.model)?;
    let model = Model::build(&model_file)?;
    let info = crate::sim::plant_info(&model);
    let file = common::scan_trace(&a.trace, &a.trace_args)?;
    let bind = common::bindings(&a.trace_args)?;
    let mut drive = TraceDrive::new(&info, &file, &bind, model.input_hold)?;
    let mut measured = SensorFlags::new(&a.measure, "--measure", &info, &mut drive, true);
    let mut truth = SensorFlags::new(&a.truth, "--truth", &info, &mut drive, true);
    let mut init_only = SensorFlags::new(&a.init, "--init", &info, &mut drive, true);
    // A sensor's first reading sets its node's start (with the `measured`
    // policy): the fused ones', then the truth and initial-only ones'.
    let mut all: Vec<(StreamSensor, bool)> = Vec::new();
    for (flags, fused) in [(&measured, true), (&truth, false), (&init_only, false)] {
        all.extend(flags.sensors().into_iter().map(|s| (s, fused)));
    }
    let window = common::window(&a.window);
    let survey = survey(
        &mut drive,
        &model,
        &all,
        a.measure_until_s,
        window,
        !a.disturbance.is_empty() && a.disturbance_std_w.is_none(),
    )?;
    drive.check()?;
    measured.check(&drive)?;
    truth.check(&drive)?;
    init_only.check(&drive)?;
    let (measured, truth) = (measured.sensors(), truth.sensors());
    // The fused sensors' noise: the flag, else the file's `[observer]`
    // value (what the generated firmware runs with), else 0.2 K.
    let file_sensor_sigma_k = model_file.observer.as_ref().and_then(|o| o.sensor_sigma_k);
    let (measurement_noise_k, sensor_sigma_from) =
        match (a.measurement_noise_k, file_sensor_sigma_k) {
            (Some(v), _) => (v, "flag"),
            (None, Some(v)) => (v, "model-file"),
            (None, None) => (0.2, "default"),
        };
    if a.boundary_offset_floor_k.is_some() && a.boundary_offset.is_empty() {
        bail!(
            "--boundary-offset-floor-k bounds the --boundary-offset states: give --boundary-offset BOUNDARY"
        );
    }
    if a.disturbance_floor_share.is_some() && a.disturbance.is_empty() {
        bail!(
            "--disturbance-floor-share bounds the --disturbance states: give --disturbance NODES"
        );
    }
    if let Some(t) = truth
        .iter()
        .find(|t| measured.iter().any(|m| m.column == t.column))
    {
        bail!(
            "--truth `{}` is also fused by --measure: its score would not be held out. \
             Score a sensor that is not fused, or fuse it only up to a time with --measure-until-s and read the prediction after it",
            t.column
        );
    }
    if let Some(until) = a.measure_until_s {
        if !until.is_finite() {
            bail!("--measure-until-s must be finite, got {until}");
        }
        if measured.is_empty() {
            bail!("--measure-until-s needs a --measure sensor");
        }
    }
    let first_row = survey.first.as_ref().context("the trace has no row")?;
    let median_row_s = file.median_gap_s()?;
    // The row-rate Kalman filter runs with a disturbance or a boundary
    // offset state or a learned sensor noise; otherwise the library's
    // observer.
    let kalman_filter =
        !a.disturbance.is_empty() || !a.boundary_offset.is_empty() || a.noise_half_window_rows > 0;
    if !kalman_filter {
        let span_s = file.last_time_s() - file.first_time_s();
        let ticks = span_s * 1e6 / f64::from(a.tick_us.max(1));
        if ticks > MAX_TICKS {
            bail!(
                "replay: the trace spans {span_s:.3e} s, {ticks:.3e} library ticks of {} us; at most {MAX_TICKS:.0e}: \
                 raise --tick-us, or run the row-rate Kalman filter with --disturbance",
                a.tick_us
            );
        }
    }
    if a.bias_noise_w2_per_s.is_some() {
        if kalman_filter {
            bail!("--bias-noise-w2-per-s is the library observer's: not with --disturbance or --boundary-offset");
        }
        if measured.is_empty() {
            bail!("--bias-noise-w2-per-s needs a --measure sensor (open loop has no bias)");
        }
    }
    let settings = alarm_settings(&a, &info, &first_row.boundaries, median_row_s)?;
    let rule_product = settings.rule.product();
    let predictor = TimeToLimit::new(&model)?;
    let mut protection = LibraryAlarm::new(&info, &settings)?.with_time_to_limit(
        &info,
        predictor,
        settings.horizon_s,
    )?;
    // The library's observer at `--tick-us` ticks, fusing the `--measure`
    // sensors as thermocouples; with `--disturbance` or `--boundary-offset`
    // the library's time-varying Kalman filter at the trace's rows instead.
    let mut observer = None;
    let mut kalman = None;
    let mut disturbance_std = None;
    // The library's observer holds one network; conductances that change
    // with speed run open loop on the library's explicit stepper instead,
    // or fused on the Kalman filter, which rediscretises when they change.
    let open_loop = measured.is_empty() && !kalman_filter;
    let mut stepped = if model.has_varying_conductances() && open_loop {
        Some(PlantEstimator(FilePlant::new(model.clone())?))
    } else {
        None
    };
    let estimator: &mut dyn Estimator = if let Some(s) = stepped.as_mut() {
        s
    } else if !kalman_filter {
        let fusion = (!measured.is_empty()).then(|| Fusion {
            sensor_nodes: measured.iter().map(|m| m.node).collect(),
            sensor_sigma_k: measurement_noise_k,
            node_noise_k2_per_s: a.process_noise_k2_per_s,
            correction_period_s: median_row_s,
            biases: BiasSettings::firmware(model_file.observer.as_ref(), a.bias_noise_w2_per_s),
        });
        observer.insert(ObserverEstimator::with_fusion(
            model.clone(),
            a.tick_us,
            fusion,
        )?)
    } else {
        if measured.is_empty() {
            bail!("--disturbance and --boundary-offset need at least one --measure sensor");
        }
        let disturbances = a
            .disturbance
            .iter()
            .map(|d| {
                d.split(',')
                    .map(|n| {
                        let n = n.trim();
                        info.nodes.iter().position(|x| x == n).with_context(|| {
                            format!(
                                "--disturbance `{d}`: model `{}` has no node `{n}` (nodes: {})",
                                info.name,
                                info.nodes.join(", ")
                            )
                        })
                    })
                    .collect::<Result<Vec<_>>>()
            })
            .collect::<Result<Vec<_>>>()?;
        let disturbance_std_w = match a.disturbance_std_w {
            Some(w) => w,
            None => (0.1 * survey.peak_heating_w).max(0.01),
        };
        disturbance_std = (!disturbances.is_empty()).then_some(disturbance_std_w);
        let boundary_offsets = a
            .boundary_offset
            .iter()
            .map(|b| {
                let b = b.trim();
                info.boundaries
                    .iter()
                    .position(|x| x.name == b)
                    .with_context(|| {
                        format!(
                            "--boundary-offset: model `{}` has no boundary `{b}` (boundaries: {})",
                            info.name,
                            info.boundaries
                                .iter()
                                .map(|x| x.name.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        )
                    })
            })
            .collect::<Result<Vec<_>>>()?;
        let opts = KalmanOptions {
            process_noise_k2_per_s: a.process_noise_k2_per_s,
            measurement_noise_k,
            initial_std_k: a.initial_std_k,
            disturbances,
            disturbance_std_w,
            disturbance_tau_s: a.disturbance_tau_s,
            boundary_offsets,
            boundary_offset_std_k: a.boundary_offset_std_k,
            boundary_offset_tau_s: a.boundary_offset_tau_s,
            boundary_offset_floor_k: a.boundary_offset_floor_k,
            gate: a.gate,
            noise_from_readings: (a.noise_half_window_rows > 0).then_some(NoiseFromReadings {
                half_window: a.noise_half_window_rows,
                memory: a.noise_memory_rows,
            }),
            disturbance_floor_share: a.disturbance_floor_share,
        };
        let nodes: Vec<usize> = measured.iter().map(|m| m.node).collect();
        kalman.insert(KalmanEstimator::new(model, &nodes, opts)?)
    };
    common::check_window(
        &a.window,
        survey.inside,
        file.first_time_s(),
        file.last_time_s(),
    )?;
    let first: Vec<(usize, f64)> = all
        .iter()
        .zip(&survey.first_readings)
        .filter_map(|((s, _), v)| v.map(|v| (s.node, v)))
        .collect();
    let init = crate::sim::initial_temps_at(&info, &first_row.boundaries, &first)?;
    // The model runs from the first row; the rows written, the scores, the
    // hot spot, the listed alarm events and the plot are the window's.
    let inside = |t: f64| (window.0..=window.1).contains(&t);
    let mut out = match &a.out {
        Some(path) => Some(CsvOut::create(path, &info.nodes)?),
        None => None,
    };
    let mut scores = vec![ScoreSum::default(); truth.len()];
    let mut hot = common::HotSpot::new(info.nodes.len());
    let mut events = EventLog::default();
    let mut figure = a
        .plot
        .as_ref()
        .map(|_| ReplaySeries::new(&info, &truth, &measured));
    let fused: Vec<(usize, usize)> = measured.iter().map(|m| (m.node, m.slot)).collect();
    let mut rows = drive.rows()?;
    let times = replay(
        estimator,
        &mut protection,
        &init,
        &mut rows,
        &fused,
        a.measure_until_s,
        &mut |r| {
            let t = r.row.time_s;
            crate::sim::check_row_temperatures(&info, t, r.estimate_c, "replay")?;
            if !inside(t) {
                return Ok(());
            }
            if let Some(out) = out.as_mut() {
                out.row(t, r.estimate_c.iter().copied())?;
            }
            for (sum, s) in scores.iter_mut().zip(&truth) {
                sum.push(t, r.estimate_c[s.node], r.row.extra[s.slot]);
            }
            hot.push(t, r.estimate_c);
            r.events.iter().for_each(|e| events.push(e));
            if let Some(f) = figure.as_mut() {
                f.push(r, a.measure_until_s);
            }
            Ok(())
        },
    )?;
    if let Some(out) = out {
        out.finish()?;
    }
    let scores: Vec<crate::observer::Score> = scores
        .iter()
        .zip(&truth)
        .map(|(sum, s)| sum.score(&s.column, &info.nodes[s.node]))
        .collect();
    let rows_inside = survey.inside;
    let kind = estimator.kind();
    let observer_fusion = observer.as_ref().filter(|_| !measured.is_empty()).map(|o| {
        let biases = o.biases();
        json!({
            "bias_noise_w2_per_s": biases.map(|b| b.bias_noise_w2_per_s),
            "bias_noise_from": biases.map(|b| b.from.name()),
            "max_cooling_bias_fraction": biases.map(|b| b.max_cooling_bias_fraction),
            "sensor_sigma_k": measurement_noise_k,
            "sensor_sigma_from": sensor_sigma_from,
            "sensors": o.stats().iter().zip(&measured).map(|(s, m)| json!({
                "column": m.column,
                "node": info.nodes[s.node],
                "fused": s.fused,
                "rejected": s.rejected,
                "stuck": s.stuck,
                "colder_than_physics": s.colder_than_physics,
            })).collect::<Vec<_>>(),
        })
    });
    let fusion = kalman.as_ref().map(|k| {
        json!({
            "sensors": k.stats().iter().zip(&measured).zip(k.noise_k()).map(|((s, m), noise)| json!({
                "column": m.column,
                "node": info.nodes[s.node],
                "fused": s.fused,
                "rejected": s.rejected,
                "stuck": s.stuck,
                "colder_than_physics": s.colder_than_physics,
                "noise_k": noise,
                "rejected_at_s": s.rejected_at_s,
            })).collect::<Vec<_>>(),
            "sensor_sigma_k": measurement_noise_k,
            "sensor_sigma_from": sensor_sigma_from,
            "recoveries": k.recoveries(),
            "final_disturbances_w": k.disturbances_w(),
            "final_boundary_offsets_k": a.boundary_offset.iter().map(|b| b.trim()).zip(k.boundary_offsets_k())
                .map(|(b, o)| json!({"boundary": b, "offset_k": o})).collect::<Vec<_>>(),
        })
    });
    if let (Some(path), Some(f)) = (&a.plot, figure) {
        let data = f.figure(&info, &a.trace, &events.kept, &settings);
        render(&data, path, 1200, 800)?;
    }
    let hot = hot.hottest();
    let ttl = protection.time_to_limit();
    let summary = json!({
        "command": "replay",
        "hot_spot": {"node": info.nodes[hot.0], "max_c": hot.1, "time_s": hot.2},
        "model": info.name,
        "estimator": kind,
        "fusion": fusion.or(observer_fusion),
        "trace": a.trace.display().to_string(),
        "rows": rows_inside,
        "truth": scores,
        "alarm": {
            "watched_nodes": protection.watched().len(),
            "derating_product": rule_product,
            "shutdown_latched": protection.shutdown_latched(),
            "time_to_limit": ttl,
        },
        "alarms": events.kept,
        "alarms_total": events.total,
        "step_time": times,
        "disturbance_std_w": disturbance_std,
        "out": a.out.as_ref().map(|p| p.display().to_string()),
    });
    if a.json {
        common::print_json(&summary);
        return Ok(());
    }
    println!(
        "replayed `{}` ({}) over {} rows of {}{}",
        info.name,
        kind,
        rows_inside,
        a.trace.display(),
        a.out
            .as_ref()
            .map_or(String::new(), |p| format!(" -> {}", p.display()))
    );
    println!(
        "hot spot: {} at {:.3} degC (t = {:.1} s)",
        info.nodes[hot.0], hot.1, hot.2
    );
    if !scores.is_empty() {
        println!(
            "{:<20} {:<16} {:>10} {:>10} {:>12} {:>10}",
            "truth column", "node", "MSE [K^2]", "RMSE [K]", "max err [K]", "at [s]"
        );
        for s in &scores {
            println!(
                "{:<20} {:<16} {:>10.4} {:>10.4} {:>12.4} {:>10.1}",
                s.column, s.node, s.mse_k2, s.rmse_k, s.max_abs_error_k, s.max_error_time_s
            );
        }
    }
    if let Some(o) = observer.as_ref().filter(|_| !measured.is_empty()) {
        if let Some(b) = o.biases() {
            let from = match b.from {
                BiasNoiseFrom::Flag => "--bias-noise-w2-per-s",
                BiasNoiseFrom::ModelFile => "the model file's [observer]",
                BiasNoiseFrom::Default => "the library's default",
            };
            if b.bias_noise_w2_per_s > 0.0 {
                println!(
                    "heat-input biases: the model's sources, noise {:e} W^2/s ({from}), floor -{} x P (the firmware's filter)",
                    b.bias_noise_w2_per_s, b.max_cooling_bias_fraction
                );
            } else {
                println!("heat-input biases: frozen at zero, noise 0 W^2/s ({from}): temperatures corrected, no heat estimated");
            }
        }
        for (s, m) in o.stats().iter().zip(&measured) {
            println!(
                "fused {} -> {}: {} readings fused, {} rejected by the gate, {} stuck, {} colder than the physics",
                m.column, info.nodes[s.node], s.fused, s.rejected, s.stuck, s.colder_than_physics
            );
        }
    }
    if let Some(k) = &kalman {
        for ((s, m), noise) in k.stats().iter().zip(&measured).zip(k.noise_k()) {
            println!(
                "fused {} -> {}: {} readings fused, {} rejected by the gate, noise {noise:.3} K{}",
                m.column,
                info.nodes[s.node],
                s.fused,
                s.rejected,
                if a.noise_half_window_rows > 0 {
                    " (learned from its readings)"
                } else {
                    ""
                }
            );
        }
        for (b, o) in a.boundary_offset.iter().zip(k.boundary_offsets_k()) {
            println!("boundary offset {}: {o:.3} K at the end", b.trim());
        }
        if a.disturbance_std_w.is_none() && !a.disturbance.is_empty() {
            println!(
                "disturbance std {:.3} W: 10 % of the trace's peak heating power (--disturbance-std-w W to choose)",
                disturbance_std.unwrap_or(0.0)
            );
        }
        if k.recoveries() > 0 {
            println!("covariance recoveries: {}", k.recoveries());
        }
    }
    println!(
        "alarm: {} watched nodes, derating product {:.4}, shutdown {}",
        protection.watched().len(),
        rule_product,
        if protection.shutdown_latched() {
            "latched"
        } else {
            "not latched"
        }
    );
    if let Some(t) = &ttl {
        let shortest = match (t.min_s, &t.min_node, t.min_at_time_s) {
            (Some(m), Some(n), Some(at)) => format!("shortest {m:.1} s ({n} at t = {at:.1} s)"),
            _ => "never reached on any row".into(),
        };
        let below = t
            .first_below_horizon_time_s
            .map_or("never".into(), |at| format!("first at t = {at:.1} s"));
        println!(
            "time to limit: {shortest}; below the {} s horizon: {below}; one full sweep p50 {:.0} ns, max {:.0} ns",
            t.horizon_s, t.sweep_p50_ns, t.sweep_max_ns
        );
        if t.unknown_rows > 0 {
            println!(
                "time to limit unknown (non-finite input) on {} rows",
                t.unknown_rows
            );
        }
    }
    print_events(&events);
    let t = &times;
    match &observer {
        Some(o) => println!(
            "library tick time [us] over {} ticks of {} ms (NetworkObserver padded to {} nodes): min {:.2}, median {:.2}, p99 {:.2}, max {:.2}; p99 is {:.4} of the 0.1 ms budget",
            t.steps,
            f64::from(o.tick_us()) * 1e-3,
            o.size_class(),
            t.min_ns * 1e-3,
            t.p50_ns * 1e-3,
            t.p99_ns * 1e-3,
            t.max_ns * 1e-3,
            t.p99_over_budget
        ),
        None => println!(
            "step time [us] per trace row of {:.3} s (the library filter's predict and update): min {:.2}, median {:.2}, p99 {:.2}, max {:.2}; p99 is {:.4} of the 0.1 ms budget",
            survey.window_gaps.median().unwrap_or(median_row_s),
            t.min_ns * 1e-3,
            t.p50_ns * 1e-3,
            t.p99_ns * 1e-3,
            t.max_ns * 1e-3,
            t.p99_over_budget
        ),
    }
    Ok(())
}
