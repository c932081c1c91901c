//! `coil-thermal replay`.

use anyhow::{bail, Context, Result};
use serde_json::json;

use super::common;
use super::plot_cmd::ReplaySeries;
use super::ReplayArgs;
use crate::devices;
use crate::firmware::{FirmwareConfig, Override};
use crate::grid_firmware::{self, GridFirmwareEstimator};
use crate::library_observer::{FusionStats, ObserverEstimator};
use crate::limits::TimeToLimit;
use crate::model_file::Model;
use crate::observer::Measurement;
use crate::observer::{
    replay, AlarmEvent, AlarmSettings, Estimator, LibraryAlarm, Protection, ScoreSum,
};
use crate::omni_firmware::{self, OmniFirmwareEstimator, OmniOverrides};
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
        warning_margin_k: non_negative(
            a.warning_margin_k.unwrap_or(HOST_WARNING_MARGIN_K),
            "--warning-margin-k",
        )?,
        hysteresis_k: non_negative(
            a.hysteresis_k.unwrap_or(HOST_HYSTERESIS_K),
            "--hysteresis-k",
        )?,
        debounce_rows: debounce_rows(a, median_row_s)?,
        horizon_s: positive(a.horizon_s.unwrap_or(HOST_HORIZON_S), "--horizon-s")?,
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
    let s = a.debounce_s.unwrap_or(HOST_DEBOUNCE_S);
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

/// The plausible-current limit of a model file without an `[observer]`
/// table \[A\] (see [`firmware_config`]).
pub const NO_TABLE_MAX_CURRENT_A: f64 = 1600.0;

/// The host alarm's defaults (the explicit stepper; the firmware observer
/// has its own alarm): the warning's margin
/// below the alarm limit \[K\], its hysteresis \[K\], the debounce \[s\]
/// and the predictive horizon \[s\].
const HOST_WARNING_MARGIN_K: f64 = 5.0;
const HOST_HYSTERESIS_K: f64 = 2.0;
const HOST_DEBOUNCE_S: f64 = 3.0;
const HOST_HORIZON_S: f64 = 60.0;

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
/// and their median spacing.
struct Survey {
    first: Option<InputRow>,
    first_readings: Vec<Option<f64>>,
    inside: usize,
    window_gaps: crate::trace::GapMedian,
}

/// The pass before the run: every row's channels and sensors evaluated
/// (their errors kept for the checks), and what the run needs first.
fn survey(
    drive: &mut TraceDrive,
    sensors: &[(StreamSensor, bool)],
    until_s: Option<f64>,
    window: (f64, f64),
    raw: &[crate::raw_sensors::RawColumn],
) -> Result<Survey> {
    let mut s = Survey {
        first: None,
        first_readings: vec![None; sensors.len()],
        inside: 0,
        window_gaps: crate::trace::GapMedian::default(),
    };
    let mut last_inside: Option<f64> = None;
    let mut rows = drive.rows()?;
    let mut rows = crate::raw_sensors::ConvertedRows::new(&mut rows, raw.to_vec());
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
        s.first.get_or_insert_with(|| row.clone());
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

/// No host alarm: the firmware's observer raises its own (the replay
/// reads its events instead of calling this).
struct Unwatched;

impl Protection for Unwatched {
    fn check(
        &mut self,
        _: f64,
        _: &[f64],
        _: &[f64],
        _: &[f64],
        _: &[f64],
        _: &mut Vec<AlarmEvent>,
    ) {
    }
}

/// Which estimator a replay runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Path {
    /// The firmware's `NetworkObserver` of the model file.
    Firmware,
    /// Open loop on the library's explicit stepper (a network that changes
    /// with a signal).
    Stepper,
}

/// Refuses every flag given that does not apply to the estimator `path`
/// runs, naming the flag and why (a flag is never ignored; `why` says why
/// the path is the stepper's).
fn refuse_inapplicable(a: &ReplayArgs, path: Path, why: &str) -> Result<()> {
    let host_alarm_only: [(&str, bool); 6] = [
        ("--warning-margin-k", a.warning_margin_k.is_some()),
        ("--hysteresis-k", a.hysteresis_k.is_some()),
        ("--debounce-s", a.debounce_s.is_some()),
        ("--debounce-rows", a.debounce_rows.is_some()),
        ("--horizon-s", a.horizon_s.is_some()),
        ("--ambient-boundary", a.ambient_boundary.is_some()),
    ];
    // The stepper runs the model open loop: no filter, so no noise.
    let firmware_only: [(&str, bool); 4] = [
        ("--tick-us", a.tick_us.is_some()),
        ("--bias-noise-w2-per-s", a.bias_noise_w2_per_s.is_some()),
        ("--measurement-noise-k", a.measurement_noise_k.is_some()),
        (
            "--process-noise-k2-per-s",
            a.process_noise_k2_per_s.is_some(),
        ),
    ];
    if path == Path::Firmware {
        if let Some((flag, _)) = host_alarm_only.iter().find(|(_, given)| *given) {
            bail!(
                "{flag} sets the host's alarm on an estimate; this replay runs the firmware's NetworkObserver, whose own alarm (on its upper bounds, \
                 with the derating of the model file's [observer] table) is what the MCU raises: drop {flag}"
            );
        }
    } else if let Some((flag, _)) = firmware_only.iter().find(|(_, given)| *given) {
        bail!(
            "{flag} sets the firmware's NetworkObserver; this replay runs the model open loop on the explicit stepper ({why}): drop {flag}"
        );
    }
    Ok(())
}

/// The firmware observer a replay runs: the model file's `[observer]`
/// table over `codegen`'s defaults (the built-in devices: their own
/// derating rule), then each flag that changes it, listed as an override.
fn firmware_config(
    a: &ReplayArgs,
    spec: &common::ModelSpec,
    model_file: &crate::model_file::ModelFile,
    model: &Model,
    fused_nodes: &[usize],
) -> Result<(FirmwareConfig, Vec<Override>)> {
    let mut config = FirmwareConfig::of(model, model_file.observer.as_ref())?;
    // A built-in device has no `[observer]` table: its own derating rule.
    if matches!(
        spec,
        common::ModelSpec::Hppa | common::ModelSpec::Omnimagnet
    ) {
        config.derating = common::default_rule(spec).product();
    }
    if !config.from_table {
        // No firmware is generated from a file without a table (codegen
        // needs its sensors); an analysis model's currents (a motor's
        // 400 A) are not clamped at the default 100 A.
        config.settings.max_current_a = NO_TABLE_MAX_CURRENT_A;
    }
    let mut overrides = Vec::new();
    if !a.factors.is_empty() {
        let rule = common::derating_rule(&a.factors, common::default_rule(spec))?;
        overrides.push(Override {
            flag: "--factors",
            what: format!(
                "derating product {:.4} instead of {:.4}",
                rule.product(),
                config.derating
            ),
        });
        config.derating = rule.product();
    }
    if let Some(c) = a.critical_c {
        if !c.is_finite() {
            bail!("--critical-c must be finite, got {c}");
        }
        overrides.push(Override {
            flag: "--critical-c",
            what: format!("every node's critical temperature {c} degC"),
        });
        config.critical_c = vec![Some(c); model.nodes.len()];
    }
    let settings = &mut config.settings;
    /// A noise flag: its value, its name and unit, whether 0 is allowed,
    /// and the setting it overrides.
    struct Noise<'s> {
        flag: &'static str,
        value: Option<f64>,
        name: &'static str,
        unit: &'static str,
        zero_allowed: bool,
        setting: &'s mut f64,
    }
    let noises = [
        Noise {
            flag: "--measurement-noise-k",
            value: a.measurement_noise_k,
            name: "sensor noise",
            unit: "K",
            zero_allowed: false,
            setting: &mut settings.sensor_sigma_k,
        },
        Noise {
            flag: "--process-noise-k2-per-s",
            value: a.process_noise_k2_per_s,
            name: "node noise",
            unit: "K^2/s",
            zero_allowed: true,
            setting: &mut settings.node_noise_k2_per_s,
        },
        Noise {
            flag: "--bias-noise-w2-per-s",
            value: a.bias_noise_w2_per_s,
            name: "bias noise",
            unit: "W^2/s",
            zero_allowed: true,
            setting: &mut settings.bias_noise_w2_per_s,
        },
    ];
    for Noise {
        flag,
        value,
        name,
        unit,
        zero_allowed,
        setting,
    } in noises
    {
        let Some(v) = value else { continue };
        if !(v.is_finite() && (v > 0.0 || (zero_allowed && v == 0.0))) {
            let bound = if zero_allowed { ">= 0" } else { "> 0" };
            bail!("{flag} must be finite and {bound}, got {v}");
        }
        if v != *setting {
            overrides.push(Override {
                flag,
                what: format!("{name} {v} {unit} instead of {} {unit}", *setting),
            });
        }
        *setting = v;
    }
    if let Some(t) = a.tick_us {
        if t == 0 {
            bail!("--tick-us must be at least 1");
        }
        if t != settings.step_us || t != settings.loop_tick_us() {
            overrides.push(Override {
                flag: "--tick-us",
                what: format!(
                    "ticks and model steps of {t} us instead of model steps of {} us on ticks of {} us",
                    settings.step_us,
                    settings.loop_tick_us()
                ),
            });
            settings.step_us = t;
            settings.loop_period_us = t;
        }
    }
    if config.from_table && !fused_nodes.is_empty() && fused_nodes != config.sensor_nodes.as_slice()
    {
        let names = |nodes: &[usize]| {
            nodes
                .iter()
                .map(|n| model.nodes[*n].as_str())
                .collect::<Vec<_>>()
                .join(", ")
        };
        overrides.push(Override {
            flag: "--measure",
            what: format!(
                "sensors on [{}] instead of the firmware's [{}]",
                names(fused_nodes),
                names(&config.sensor_nodes)
            ),
        });
    }
    Ok((config, overrides))
}

/// The first of each truth sensor's rows where the truth was above the
/// upper bound of its node ("cold misses": the protection acted on a bound
/// below the truth).
#[derive(Debug, Clone, Default, serde::Serialize)]
struct ColdMisses {
    column: String,
    node: String,
    /// Rows where the truth was above the upper bound.
    rows: usize,
    /// The largest excess \[K\] and its time \[s\].
    worst_k: Option<f64>,
    worst_at_s: Option<f64>,
    /// The first such row's time \[s\].
    first_at_s: Option<f64>,
}

impl ColdMisses {
    fn push(&mut self, time_s: f64, truth_c: f64, upper_c: f64) {
        if truth_c.is_nan() || truth_c <= upper_c {
            return;
        }
        let excess = truth_c - upper_c;
        self.rows += 1;
        self.first_at_s.get_or_insert(time_s);
        if self.worst_k.is_none_or(|w| excess > w) {
            self.worst_k = Some(excess);
            self.worst_at_s = Some(time_s);
        }
    }
}

/// Each fused sensor's counts, as JSON.
fn sensor_stats_json(
    stats: &[FusionStats],
    measured: &[StreamSensor],
    info: &PlantInfo,
) -> Vec<serde_json::Value> {
    stats
        .iter()
        .zip(measured)
        .map(|(s, m)| {
            json!({
                "column": m.column,
                "node": info.nodes[s.node],
                "fused": s.fused,
                "rejected": s.rejected,
                "stuck": s.stuck,
                "colder_than_physics": s.colder_than_physics,
            })
        })
        .collect()
}

/// Each fused sensor's counts, one line each.
fn print_sensor_stats(stats: &[FusionStats], measured: &[StreamSensor], info: &PlantInfo) {
    for (s, m) in stats.iter().zip(measured) {
        println!(
            "fused {} -> {}: {} readings fused, {} rejected by the gate, {} stuck, {} colder than the physics",
            m.column, info.nodes[s.node], s.fused, s.rejected, s.stuck, s.colder_than_physics
        );
    }
}

/// The overrides of the flashed Omnimagnet observer's settings (the
/// noise flags; `firmware_config` has checked their values), and the
/// flags it refuses: its derating and critical temperatures are the
/// device's, its tick the loop's.
fn omni_overrides(a: &ReplayArgs) -> Result<Vec<Override>> {
    if !a.factors.is_empty() || a.critical_c.is_some() {
        let flag = if a.factors.is_empty() {
            "--critical-c"
        } else {
            "--factors"
        };
        bail!(
            "{flag}: the flashed Omnimagnet observer derates the device's own critical temperatures by the device's rule \
             (what `codegen --device omnimagnet` flashes; neither is a setting of it): drop {flag}"
        );
    }
    if a.tick_us.is_some_and(|t| t != omni_firmware::TICK_US) {
        bail!(
            "--tick-us: the flashed Omnimagnet observer ticks every {} us (its model steps are 5 ms on the ticks' mean I^2): drop --tick-us",
            omni_firmware::TICK_US
        );
    }
    let flashed = omni_firmware::settings(
        [true; coil_thermal::omnimagnet::THERMOCOUPLES],
        &OmniOverrides::default(),
    );
    let f = &flashed.filter;
    let mut overrides = Vec::new();
    for (flag, value, name, unit, was) in [
        (
            "--measurement-noise-k",
            a.measurement_noise_k,
            "thermocouple noise",
            "K",
            f.thermocouple_sigma_k,
        ),
        (
            "--process-noise-k2-per-s",
            a.process_noise_k2_per_s,
            "every node's noise",
            "K^2/s",
            f.node_noise_k2_per_s[0],
        ),
        (
            "--bias-noise-w2-per-s",
            a.bias_noise_w2_per_s,
            "bias noise",
            "W^2/s",
            f.bias_noise_w2_per_s,
        ),
    ] {
        if let Some(v) = value.filter(|v| *v != was) {
            overrides.push(Override {
                flag,
                what: format!("{name} {v} {unit} instead of {was} {unit}"),
            });
        }
    }
    Ok(overrides)
}

/// The unit of a model input's limit: `a` (amperes) for a current, `duty`
/// for a PWM duty, `v` (volts) for a linear voltage (the generated
/// module's `input_limits_a` and `input_drive_limits`).
fn input_limit_unit(model: &Model, input: usize) -> &'static str {
    use crate::model_file::VoltageSource;
    match model
        .drives
        .iter()
        .find(|d| d.input == input)
        .and_then(|d| d.voltage)
    {
        None => "a",
        Some(VoltageSource::Linear) => "v",
        Some(_) => "duty",
    }
}

/// The sources each model input drives (the generated module's
/// `input_limits_a`: an input's limit is the smallest of theirs).
fn input_sources(model: &Model) -> Vec<Vec<usize>> {
    (0..model.inputs.len())
        .map(|k| {
            model
                .source_kinds()
                .enumerate()
                .filter(|(_, kind)| {
                    matches!(kind, crate::model_file::SourceKind::Drive(d) if model.drives[*d].input == k)
                })
                .map(|(m, _)| m)
                .collect()
        })
        .collect()
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
    // A winding resistance's column is ohms: converted in every pass, as
    // the MCU's `resistance_reading` converts them. `--raw-counts`: the
    // ADC sensors' columns too. Without it such a column is a temperature
    // (a logger that converted it): said, never assumed without a word.
    let (adc, ohms): (Vec<_>, Vec<_>) = converted_columns(
        &measured.sensors(),
        &FirmwareConfig::of(&model, model_file.observer.as_ref())?,
        &model,
    )
    .into_iter()
    .partition(|c| matches!(c.sensor, crate::raw_sensors::Conversion::Adc(_)));
    let mut raw = ohms;
    if a.raw_counts {
        if adc.is_empty() {
            bail!(
                "--raw-counts: no --measure column is of an ADC sensor of the model file (an `[observer] sensors` entry of kind ntc, kty83, kty84, pt100 or pt1000, measured in its order); a thermocouple's column is already a temperature"
            );
        }
        raw.extend(adc);
    } else if !a.json {
        for c in &adc {
            println!(
                "note: --measure {}: the model file's sensor is on an ADC ({}); its column is read as degC (give --raw-counts if it holds the ADC's counts)",
                c.column,
                c.sensor.kind()
            );
        }
    }
    if !a.json {
        for c in &raw {
            if let crate::raw_sensors::Conversion::Resistance { sensor, .. } = &c.sensor {
                println!(
                    "--measure {}: a winding's resistance [ohm], read as the firmware reads it (R(T) = {} + {} T ohm, no reading below {} A, a fault outside {} .. {} degC)",
                    c.column,
                    sensor.r_at_0c_ohm,
                    sensor.slope_ohm_per_k,
                    sensor.min_current_a,
                    sensor.min_c,
                    sensor.max_c
                );
            }
        }
    }
    let survey = survey(&mut drive, &all, a.measure_until_s, window, &raw)?;
    drive.check()?;
    measured.check(&drive)?;
    truth.check(&drive)?;
    init_only.check(&drive)?;
    let (measured, truth) = (measured.sensors(), truth.sensors());
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
    // A network that changes with a signal runs open loop on the explicit
    // stepper (the firmware's observer holds one fixed network, and refuses
    // such a model with sensors); otherwise the firmware's observer, at the
    // model's own size.
    let stepper_why = "its network changes with a signal";
    let path = if model.has_varying_conductances() && measured.is_empty() {
        Path::Stepper
    } else {
        Path::Firmware
    };
    if a.bias_noise_w2_per_s.is_some() && measured.is_empty() {
        bail!("--bias-noise-w2-per-s needs a --measure sensor (open loop has no bias)");
    }
    refuse_inapplicable(&a, path, stepper_why)?;
    let spec = common::ModelSpec::parse(&a.model.model)?;
    let fused_nodes: Vec<usize> = measured.iter().map(|m| m.node).collect();
    let (config, mut overrides) = firmware_config(&a, &spec, &model_file, &model, &fused_nodes)?;
    // `--model omnimagnet` as flashed: the device's own observer.
    let flashed_omni = path == Path::Firmware && spec == common::ModelSpec::Omnimagnet;
    if flashed_omni {
        overrides = omni_overrides(&a)?;
    }
    // The firmware's loop: its model steps may span several ticks.
    let tick_us = config.settings.loop_tick_us();
    if path == Path::Firmware {
        let span_s = file.last_time_s() - file.first_time_s();
        let ticks = span_s * 1e6 / f64::from(tick_us.max(1));
        if ticks > MAX_TICKS {
            bail!(
                "replay: the trace spans {span_s:.3e} s, {ticks:.3e} firmware ticks of {tick_us} us; at most {MAX_TICKS:.0e}: \
                 raise --tick-us"
            );
        }
    }
    let settings = alarm_settings(&a, &info, &first_row.boundaries, median_row_s)?;
    let settings = AlarmSettings {
        rule: if path == Path::Firmware {
            config.rule()
        } else {
            settings.rule
        },
        critical_c: config.critical_c.clone(),
        ..settings
    };
    let rule_product = settings.rule.product();
    // The host's alarm on the estimate, for the estimators without a
    // protection of their own (the firmware's observer has its own), with
    // the library's time-to-limit predictor at the model's own size.
    let mut host_alarm = (path != Path::Firmware)
        .then(|| -> Result<LibraryAlarm> {
            let alarm = LibraryAlarm::new(&info, &settings)?;
            alarm.with_time_to_limit(&info, TimeToLimit::new(&model)?, settings.horizon_s)
        })
        .transpose()?;
    let mut unwatched = Unwatched;
    let protection: &mut dyn Protection = match host_alarm.as_mut() {
        Some(p) => p,
        None => &mut unwatched,
    };
    let mut observer = None;
    let mut stepped = (path == Path::Stepper)
        .then(|| FilePlant::new(model.clone()).map(PlantEstimator))
        .transpose()?;
    // `--model hppa` as flashed (the report's 7 x 12 grid, its FDM fit, no
    // thermocouple): the device's own grid observer.
    let flashed_grid = path == Path::Firmware
        && spec == common::ModelSpec::Hppa
        && common::grid_dims(&a.model) == (grid_firmware::ROWS, grid_firmware::COLS)
        && a.model
            .grid_params
            .as_deref()
            .is_none_or(|p| p == "fdm-fitted")
        && measured.is_empty();
    if flashed_grid && a.tick_us.is_some_and(|t| t != grid_firmware::TICK_US) {
        bail!(
            "--tick-us: the flashed HPPA grid observer ticks every {} us (its steps are the grid's own): drop --tick-us",
            grid_firmware::TICK_US
        );
    }
    let mut grid = None;
    let mut omni = None;
    let estimator: &mut dyn Estimator = if let Some(s) = stepped.as_mut() {
        s
    } else if flashed_grid {
        let rule = common::derating_rule(&a.factors, common::default_rule(&spec))?;
        let critical_c = a
            .critical_c
            .unwrap_or(coil_thermal::protect::derating::HPPA_CRITICAL_C);
        grid.insert(GridFirmwareEstimator::new(info.clone(), &rule, critical_c)?)
    } else if flashed_omni {
        omni.insert(OmniFirmwareEstimator::new(
            info.clone(),
            &fused_nodes,
            &OmniOverrides {
                sensor_sigma_k: a.measurement_noise_k,
                node_noise_k2_per_s: a.process_noise_k2_per_s,
                bias_noise_w2_per_s: a.bias_noise_w2_per_s,
            },
        )?)
    } else {
        observer.insert(ObserverEstimator::firmware(
            model.clone(),
            tick_us,
            &config,
            &fused_nodes,
        )?)
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
    // The firmware's protection columns: each limited node's upper bound
    // and derated limit, each input's current limit, the alarm flags.
    let limited: Vec<usize> = (0..info.nodes.len())
        .filter(|i| config.critical_c.get(*i).copied().flatten().is_some())
        .collect();
    let input_sources = input_sources(&model);
    let limit_units: Vec<&str> = (0..info.inputs.len())
        .map(|k| input_limit_unit(&model, k))
        .collect();
    let mut columns = info.nodes.clone();
    if path == Path::Firmware {
        for &i in &limited {
            columns.push(format!("upper_c.{}", info.nodes[i]));
            columns.push(format!("alarm_limit_c.{}", info.nodes[i]));
        }
        for (input, unit) in info.inputs.iter().zip(&limit_units) {
            columns.push(format!("limit_{unit}.{}", input.name));
        }
        columns.extend(["warning", "predictive", "shutdown"].map(String::from));
    }
    let mut out = match &a.out {
        Some(path) => Some(CsvOut::create(path, &columns)?),
        None => None,
    };
    let mut cold_misses: Vec<ColdMisses> = truth
        .iter()
        .map(|t| ColdMisses {
            column: t.column.clone(),
            node: info.nodes[t.node].clone(),
            ..ColdMisses::default()
        })
        .collect();
    let mut highest_upper: Vec<Option<(f64, f64)>> = vec![None; info.nodes.len()];
    let mut lowest_limit_a: Vec<Option<(f64, f64)>> = vec![None; info.inputs.len()];
    let mut final_protection = None;
    // The firmware's shortest time to limit: (s, node, at s).
    let mut shortest_ttl: Option<(f64, usize, f64)> = None;
    let mut scores = vec![ScoreSum::default(); truth.len()];
    let mut hot = common::HotSpot::new(info.nodes.len());
    let mut events = EventLog::default();
    let mut figure = a
        .plot
        .as_ref()
        .map(|_| ReplaySeries::new(&info, &truth, &measured));
    let fused: Vec<(usize, usize)> = measured.iter().map(|m| (m.node, m.slot)).collect();
    let mut rows = drive.rows()?;
    let mut rows = crate::raw_sensors::ConvertedRows::new(&mut rows, raw);
    let times = replay(
        estimator,
        protection,
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
            let input_limits: Vec<f64> = r.protected.map_or_else(Vec::new, |p| {
                input_sources
                    .iter()
                    .map(|ms| {
                        ms.iter()
                            .map(|m| p.drive_limit[*m].unwrap_or(p.source_limit_a[*m]))
                            // A NaN (no drive limit yet) stays NaN.
                            .fold(f64::INFINITY, |a, l| if l.is_nan() { l } else { a.min(l) })
                    })
                    .collect()
            });
            if let Some(p) = r.protected {
                for (c, s) in cold_misses.iter_mut().zip(&truth) {
                    c.push(t, r.row.extra[s.slot], p.upper_c[s.node]);
                }
                for &i in &limited {
                    if highest_upper[i].is_none_or(|(u, _)| p.upper_c[i] > u) {
                        highest_upper[i] = Some((p.upper_c[i], t));
                    }
                    if let Some(ttl) = p.time_to_limit_s[i] {
                        if shortest_ttl.is_none_or(|(s, _, _)| ttl < s) {
                            shortest_ttl = Some((ttl, i, t));
                        }
                    }
                }
                for (low, l) in lowest_limit_a.iter_mut().zip(&input_limits) {
                    // NaN: a drive's limit before its first row.
                    if !l.is_nan() && low.is_none_or(|(v, _)| *l < v) {
                        *low = Some((*l, t));
                    }
                }
                final_protection = Some((p.clone(), input_limits.clone()));
            }
            if let Some(out) = out.as_mut() {
                let protection = r.protected.map_or_else(Vec::new, |p| {
                    let mut v = Vec::new();
                    for &i in &limited {
                        v.push(p.upper_c[i]);
                        v.push(p.alarm_limit_c[i].unwrap_or(f64::NAN));
                    }
                    v.extend(&input_limits);
                    v.extend([p.warning, p.predictive, p.shutdown].map(|f| f64::from(u8::from(f))));
                    v
                });
                out.row(t, r.estimate_c.iter().copied().chain(protection))?;
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
    let table = model_file.observer.as_ref();
    let from = |flag: bool, key: bool| {
        if flag {
            "flag"
        } else if key {
            "model-file"
        } else {
            "default"
        }
    };
    let sensor_sigma_from = from(
        a.measurement_noise_k.is_some(),
        table.is_some_and(|t| t.sensor_sigma_k.is_some()),
    );
    let omni_fusion = omni.as_ref().filter(|_| !measured.is_empty()).map(|o| {
        let f = &o.settings().filter;
        json!({
            "bias_noise_w2_per_s": f.bias_noise_w2_per_s,
            "sensor_sigma_k": f.thermocouple_sigma_k,
            "sensor_sigma_from": if a.measurement_noise_k.is_some() { "flag" } else { "device" },
            "correction_period_s": f.correction_period_s,
            "sensors": sensor_stats_json(o.stats(), &measured, &info),
        })
    });
    let observer_fusion = observer.as_ref().filter(|_| !measured.is_empty()).map(|o| {
        let s = &o.config().settings;
        json!({
            "bias_noise_w2_per_s": s.bias_noise_w2_per_s,
            "bias_noise_from": from(
                a.bias_noise_w2_per_s.is_some(),
                table.is_some_and(|t| t.bias_noise_w2_per_s.is_some()),
            ),
            "max_cooling_bias_fraction": s.max_cooling_bias_fraction,
            "sensor_sigma_k": s.sensor_sigma_k,
            "sensor_sigma_from": sensor_sigma_from,
            "correction_period_s": s.correction_period_s,
            "sensors": sensor_stats_json(o.stats(), &measured, &info),
        })
    });
    let grid_json = grid.as_ref().map(|_| {
        json!({
            "kind": "grid-observer",
            "settings_from": "the device (codegen --device hppa-grid, examples/observer_m4)",
            "derating_product": rule_product,
            "hardware_limit_a": crate::codegen::GRID_HARDWARE_LIMIT_A,
            "step_us": grid_firmware::TICK_US,
            "overrides": overrides.iter().map(|o| json!({"flag": o.flag, "what": o.what})).collect::<Vec<_>>(),
        })
    });
    let omni_json = omni.as_ref().map(|o| {
        let s = o.settings();
        json!({
            "kind": "omni-observer",
            "settings_from": "the device (codegen --device omnimagnet, examples/observer_m4)",
            "derating_product": rule_product,
            "thermocouples_fitted": s.filter.sensors,
            "sensor_sigma_k": s.filter.thermocouple_sigma_k,
            "correction_period_s": s.filter.correction_period_s,
            "hardware_limit_a": s.hardware_limit_a,
            "model_step_us": s.step_us,
            "step_us": omni_firmware::TICK_US,
            "overrides": overrides.iter().map(|o| json!({"flag": o.flag, "what": o.what})).collect::<Vec<_>>(),
        })
    });
    let firmware_json = observer.as_ref().map(|o| {
        let c = o.config();
        json!({
            "settings_from": if c.from_table { "model-file [observer]" } else { "defaults (no [observer] table)" },
            "derating_product": c.derating,
            "sensor_sigma_k": c.settings.sensor_sigma_k,
            "correction_period_s": c.settings.correction_period_s,
            "node_noise_k2_per_s": c.settings.node_noise_k2_per_s,
            "bias_noise_w2_per_s": c.settings.bias_noise_w2_per_s,
            "hardware_limit_a": c.hardware_limit_a,
            "max_current_a": c.settings.max_current_a,
            "step_us": c.settings.step_us,
            "loop_period_us": c.settings.loop_tick_us(),
            "overrides": overrides.iter().map(|o| json!({"flag": o.flag, "what": o.what})).collect::<Vec<_>>(),
        })
    });
    let protection_json = final_protection.as_ref().map(|(p, input_limits)| {
        json!({
            "nodes": limited.iter().map(|&i| json!({
                "node": info.nodes[i],
                "upper_c": p.upper_c[i],
                "alarm_limit_c": p.alarm_limit_c[i],
                "highest_upper_c": highest_upper[i].map(|h| h.0),
                "highest_upper_at_s": highest_upper[i].map(|h| h.1),
                "time_to_limit_s": p.time_to_limit_s[i],
            })).collect::<Vec<_>>(),
            "shortest_time_to_limit": shortest_ttl.map(|(s, i, at)| json!({
                "s": s, "node": info.nodes[i], "at_s": at,
            })),
            "inputs": info.inputs.iter().zip(input_limits).zip(&lowest_limit_a).zip(&limit_units).map(|(((input, l), low), unit)| {
                // A current's limit keeps its `_a` keys; a duty's or a
                // voltage's is named by its unit.
                let mut v = json!({"input": input.name, "unit": unit, "lowest_limit_at_s": low.map(|v| v.1)});
                v[format!("limit_{unit}")] = json!(l);
                v[format!("lowest_limit_{unit}")] = json!(low.map(|v| v.0));
                v
            }).collect::<Vec<_>>(),
            "warning": p.warning,
            "predictive": p.predictive,
            "shutdown": p.shutdown,
        })
    });
    if let (Some(path), Some(f)) = (&a.plot, figure) {
        let data = f.figure(&info, &a.trace, &events.kept, &settings);
        render(&data, path, 1200, 800)?;
    }
    let hot = hot.hottest();
    // The host's time-to-limit sweep watches the estimate: only for the
    // estimators without a protection of their own.
    let ttl = host_alarm.as_ref().and_then(LibraryAlarm::time_to_limit);
    let shutdown_latched = match (&final_protection, &host_alarm) {
        (Some((p, _)), _) => p.shutdown,
        (None, Some(h)) => h.shutdown_latched(),
        (None, None) => false,
    };
    let summary = json!({
        "command": "replay",
        "hot_spot": {"node": info.nodes[hot.0], "max_c": hot.1, "time_s": hot.2},
        "model": info.name,
        "estimator": kind,
        "fusion": observer_fusion.or(omni_fusion),
        "trace": a.trace.display().to_string(),
        "rows": rows_inside,
        "truth": scores,
        "firmware_observer": firmware_json.or(grid_json).or(omni_json),
        "protection": protection_json,
        "drive_flag_ticks": observer
            .as_ref()
            .filter(|_| model.has_voltage_drives())
            .map(|o| o.drive_flag_ticks()),
        "cold_misses": (path == Path::Firmware).then_some(&cold_misses),
        "alarm": {
            "by": if path == Path::Firmware { "firmware" } else { "host" },
            "watched_nodes": limited.len(),
            "derating_product": rule_product,
            "shutdown_latched": shutdown_latched,
            "time_to_limit": ttl,
        },
        "alarms": events.kept,
        "alarms_total": events.total,
        "step_time": times,
        "out": a.out.as_ref().map(|p| p.display().to_string()),
    });
    if a.json {
        common::print_json(&summary);
        return Ok(());
    }
    for line in crate::raw_sensors::report(&rows.columns) {
        println!("{line}");
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
    if grid.is_some() {
        println!(
            "observer: the firmware's HPPA GridObserver (what `codegen --device hppa-grid` flashes and examples/observer_m4 runs): derating product {rule_product:.4}, grid updates every 20 ms, hardware limit {} A, no thermocouple",
            crate::codegen::GRID_HARDWARE_LIMIT_A
        );
        for o in &overrides {
            println!("override {}: {} (not what the MCU runs)", o.flag, o.what);
        }
    } else if let Some(o) = omni.as_ref() {
        let s = o.settings();
        let fitted: Vec<&str> = (0..s.filter.sensors.len())
            .filter(|j| s.filter.sensors[*j])
            .map(|j| info.nodes[coil_thermal::omnimagnet::THERMOCOUPLE_NODES[j]].as_str())
            .collect();
        println!(
            "observer: the firmware's OmniObserver (what `codegen --device omnimagnet` flashes and examples/observer_m4 runs): derating product {rule_product:.4}, \
             model step {} us on ticks of {} us, thermocouples on {} ({}), noise {} K, correction period {} s, hardware limit {} A",
            s.step_us,
            omni_firmware::TICK_US,
            fitted.join(", "),
            if measured.is_empty() { "fitted, none read: the protection takes the unfused model's bound" } else { "fused" },
            s.filter.thermocouple_sigma_k,
            s.filter.correction_period_s,
            s.hardware_limit_a
        );
        for o in &overrides {
            println!("override {}: {} (not what the MCU runs)", o.flag, o.what);
        }
        print_sensor_stats(o.stats(), &measured, &info);
    } else if let Some(o) = observer.as_ref() {
        let c = o.config();
        println!(
            "observer: the firmware's NetworkObserver from {} (what codegen flashes): derating product {:.4}, sensor noise {} K, correction period {} s, hardware limit {} A, plausible up to {} A",
            if c.from_table { "the model file's [observer] table" } else { "codegen's defaults (the file has no [observer] table, so no firmware is generated from it; currents plausible up to 1600 A, not 100 A)" },
            c.derating,
            c.settings.sensor_sigma_k,
            c.settings.correction_period_s,
            c.hardware_limit_a,
            c.settings.max_current_a
        );
        if spec == common::ModelSpec::Hppa {
            println!(
                "note: `--model {}` is flashed as its own device observer (codegen --device); this replay runs the NetworkObserver over the same network, with the device's derating",
                a.model.model
            );
        }
        for o in &overrides {
            println!(
                "override {}: {} (not what the MCU runs from this file)",
                o.flag, o.what
            );
        }
    } else {
        println!(
            "estimator: {kind}, a host-only estimator (not what any firmware runs): open loop, {stepper_why}; the alarm below is the host's, on its estimate"
        );
    }
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
    if let Some(o) = observer.as_ref() {
        let c = o.config();
        let s = &c.settings;
        let bias_from = match from(
            a.bias_noise_w2_per_s.is_some(),
            table.is_some_and(|t| t.bias_noise_w2_per_s.is_some()),
        ) {
            "flag" => "--bias-noise-w2-per-s",
            "model-file" => "the model file's [observer]",
            _ => "the library's default",
        };
        if s.step_us != s.loop_tick_us() {
            println!(
                "model step {} us on ticks of {} us: each step heats with the mean I^2 of the ticks it covers (the firmware's multi-rate model)",
                s.step_us,
                s.loop_tick_us()
            );
        }
        if measured.is_empty() {
            println!("observer: open loop (no --measure): the firmware's model step and protection, no sensor");
        } else if s.bias_noise_w2_per_s > 0.0 {
            println!(
                "heat-input biases: the model's sources, noise {:e} W^2/s ({bias_from}), floor -{} x P (the firmware's filter)",
                s.bias_noise_w2_per_s, s.max_cooling_bias_fraction
            );
        } else {
            println!("heat-input biases: frozen at zero, noise 0 W^2/s ({bias_from}): temperatures corrected, no heat estimated");
        }
        if !measured.is_empty() {
            let rows_s = survey.window_gaps.median().unwrap_or(median_row_s);
            if (rows_s - s.correction_period_s).abs() > 0.1 * s.correction_period_s {
                println!(
                    "note: readings arrive every {rows_s:.3} s; the firmware's gain is solved for {:.3} s ([observer] correction_period_s{}), as on the MCU",
                    s.correction_period_s,
                    if table.is_some_and(|t| t.correction_period_s.is_some()) { "" } else { ", codegen's default" }
                );
            }
        }
        print_sensor_stats(o.stats(), &measured, &info);
        let f = o.drive_flag_ticks();
        if model.has_voltage_drives() {
            if f.is_clean() {
                println!("voltage drives: every duty and supply used as recorded");
            } else {
                println!(
                    "voltage drives (the library's rules, as on the MCU): duty invalid on {} ticks, duty above 1 on {}, supply invalid on {}, resistance invalid on {} (an invalid one holds the last valid current; an invalid supply's duty limit is 0)",
                    f.duty_invalid, f.duty_clamped, f.supply_invalid, f.resistance_invalid
                );
            }
        }
    }
    if path == Path::Firmware {
        if let Some((p, input_limits)) = &final_protection {
            for &i in &limited {
                if let Some((u, at)) = highest_upper[i] {
                    println!(
                        "protection {}: upper bound at most {u:.2} degC (t = {at:.1} s), derated alarm limit {} at the end",
                        info.nodes[i],
                        p.alarm_limit_c[i].map_or("none".into(), |l| format!("{l:.2} degC")),
                    );
                }
            }
            for (((input, l), low), unit) in info
                .inputs
                .iter()
                .zip(input_limits)
                .zip(&lowest_limit_a)
                .zip(&limit_units)
            {
                if let Some((v, at)) = low {
                    match *unit {
                        "duty" => println!(
                            "duty limit {}: lowest {v:.3} (t = {at:.1} s), {l:.3} at the end",
                            input.name
                        ),
                        "v" => println!(
                            "voltage limit {}: lowest {v:.2} V (t = {at:.1} s), {l:.2} V at the end",
                            input.name
                        ),
                        _ => println!(
                            "current limit {}: lowest {v:.2} A (t = {at:.1} s), {l:.2} A at the end",
                            input.name
                        ),
                    }
                }
            }
        }
        for c in &cold_misses {
            match (c.worst_k, c.worst_at_s) {
                (Some(w), Some(at)) => println!(
                    "cold misses {} -> {}: the truth above the upper bound on {} rows, worst {w:.3} K at t = {at:.1} s (first at t = {:.1} s)",
                    c.column,
                    c.node,
                    c.rows,
                    c.first_at_s.unwrap_or(at)
                ),
                _ => println!(
                    "cold misses {} -> {}: none (the truth never above the upper bound)",
                    c.column, c.node
                ),
            }
        }
    }
    println!(
        "alarm{}: {} watched nodes, derating product {:.4}, shutdown {}",
        if path == Path::Firmware {
            " (the firmware's, on its upper bounds)"
        } else {
            " (the host's, on the estimate)"
        },
        limited.len(),
        rule_product,
        if shutdown_latched {
            "latched"
        } else {
            "not latched"
        }
    );
    if path == Path::Firmware {
        match shortest_ttl {
            Some((s, i, at)) => println!(
                "time to limit (the firmware's, on its upper bounds): shortest {s:.1} s ({} at t = {at:.1} s)",
                info.nodes[i]
            ),
            None => println!("time to limit (the firmware's, on its upper bounds): never reached on any row"),
        }
    }
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
    let device = if omni.is_some() {
        Some("Omnimagnet")
    } else {
        grid.as_ref().map(|_| "grid")
    };
    if let Some(device) = device {
        println!(
            "{device} observer tick time [us] over {} ticks of 1 ms: min {:.2}, median {:.2}, p99 {:.2}, max {:.2}; p99 is {:.4} of the 0.1 ms budget",
            t.steps,
            t.min_ns * 1e-3,
            t.p50_ns * 1e-3,
            t.p99_ns * 1e-3,
            t.max_ns * 1e-3,
            t.p99_over_budget
        );
        return Ok(());
    }
    match &observer {
        Some(o) => println!(
            "library tick time [us] over {} ticks of {} ms (NetworkObserver of the model's {} nodes): min {:.2}, median {:.2}, p99 {:.2}, max {:.2}; p99 is {:.4} of the 0.1 ms budget",
            t.steps,
            f64::from(o.tick_us()) * 1e-3,
            o.nodes(),
            t.min_ns * 1e-3,
            t.p50_ns * 1e-3,
            t.p99_ns * 1e-3,
            t.max_ns * 1e-3,
            t.p99_over_budget
        ),
        None => println!(
            "step time [us] per trace row of {:.3} s (the library's explicit stepper): min {:.2}, median {:.2}, p99 {:.2}, max {:.2}; p99 is {:.4} of the 0.1 ms budget",
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

/// Each `--measure` column that is an `[observer] sensors` ADC sensor's or
/// winding resistance's (the fused sensors are the file's, in order): what
/// `--raw-counts` converts, and the ohms converted always.
fn converted_columns(
    measured: &[common::StreamSensor],
    config: &FirmwareConfig,
    model: &Model,
) -> Vec<crate::raw_sensors::RawColumn> {
    use crate::raw_sensors::Conversion;
    measured
        .iter()
        .zip(&config.sensors)
        .zip(config.sensor_nodes.iter().zip(&config.sensor_kinds))
        .filter(|((m, _), (node, _))| m.node == **node)
        .filter_map(|((m, s), (_, kind))| {
            let sensor = match (s.adc(), kind.resistance()) {
                (Some(a), _) => Conversion::Adc(*a),
                (None, Some(r)) => Conversion::Resistance {
                    sensor: *r,
                    input: model.drives.get(r.source)?.input,
                },
                (None, None) => return None,
            };
            Some(crate::raw_sensors::RawColumn {
                column: m.column.clone(),
                slot: m.slot,
                sensor,
                faults: Default::default(),
                below_least_current: 0,
            })
        })
        .collect()
}
