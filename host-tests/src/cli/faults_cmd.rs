//! `coil-thermal faults`: the fault campaign (see [`crate::faults`]).

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;

use super::common::{self, ModelSpec, NOT_YET};
use super::TraceArgs;
use crate::devices::OmnimagnetPlant;
use crate::faults::{
    self, CaseReport, CurrentTrace, FaultClass, FaultConfig, FaultError, FaultReport, SensorModel,
};
use crate::model_file::{Model, ModelFile};
use crate::sim::{Drive, FilePlant, Plant};
use coil_thermal::omnimagnet::THERMOCOUPLES;
use coil_thermal::BuildError;

/// `faults` arguments.
#[derive(Debug, Args)]
pub struct FaultsArgs {
    /// Model: `omnimagnet` (the library's `OmniObserver` against the
    /// paper's nonlinear plant, six thermocouples on the solenoids at 2 Hz),
    /// or a model file FILE.toml (its `[observer]` table built into the
    /// library's `NetworkObserver`, the model itself as the plant, a
    /// thermocouple at each `[observer] sensors` node).
    #[arg(long, value_name = "omnimagnet|FILE.toml")]
    model: String,
    /// Thermocouples in use, by index (Omnimagnet: 0..=5, order of
    /// `THERMOCOUPLE_NODES`, e.g. `0,2,4`; a model file: into its
    /// `[observer] sensors`, the observer built with those only). Default:
    /// all.
    #[arg(long, value_name = "J[,J...]", value_delimiter = ',')]
    sensors: Vec<usize>,
    /// A recorded trace whose currents drive the plant (columns `I1_a`,
    /// `I2_a`, `I3_a` [A] or `--current EXPR=current_N`; `time_s` or
    /// --sample-period-s), held from row to row, for the trace's span; the
    /// ambient is the trace's first `ambient` [degC] (22 without one).
    #[arg(long, value_name = "IN.csv", conflicts_with_all = ["current_a", "duration_s"])]
    trace: Option<PathBuf>,
    #[command(flatten)]
    trace_args: TraceArgs,
    /// Constant current [A]: one for every input (solenoid) or one per
    /// input (`7,7,7`), from the ambient.
    #[arg(
        long,
        value_name = "A[,A...]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    current_a: Vec<f64>,
    /// Heating time of every run [s] with --current-a (a restart's off time
    /// comes on top). Default 1800.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    duration_s: Option<f64>,
    /// The observer's model step, one tick [us] (100 ms for speed; the
    /// firmware's is 1 ms).
    #[arg(long, value_name = "US", default_value_t = 100_000)]
    step_us: u32,
    /// Thermocouple sample period [ms], a whole number of steps: the
    /// observer's correction period.
    #[arg(long, value_name = "MS", default_value_t = 500)]
    reading_period_ms: u32,
    /// Fault onsets [s]. Default: 60 s and half the clean run's shutdown
    /// time (half the duration without one).
    #[arg(
        long,
        value_name = "S[,S...]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    onset_s: Vec<f64>,
    /// Fault classes to run (default: all): open, short-gnd, short-vcc,
    /// stuck, drift, jump-up, jump-down, spikes, dropout, all-detached,
    /// all-stuck, frozen-clock, huge-current, corrupt-snapshot,
    /// stale-snapshot, power-off, refresh-stops (the model refresh's task
    /// dies; by default run only with a refresh), and the start classes
    /// (closed loop, the drive obeying the limits, restarted at the hottest
    /// point of the run): reset-0s, reset-1min, reset-10min, reset-1h (no
    /// snapshot: the safe start from the readings), restore-unknown-off (a
    /// snapshot, the off time unknown, --off-s off).
    #[arg(long, value_name = "CLASS[,CLASS...]", value_delimiter = ',')]
    classes: Vec<String>,
    /// Off time of the power-off restart [s].
    #[arg(
        long,
        value_name = "S",
        default_value_t = 600.0,
        allow_negative_numbers = true
    )]
    off_s: f64,
    /// Oldest snapshot a restart accepts [s] (the stale case is off this
    /// long and a minute).
    #[arg(long, value_name = "S", default_value_t = 3600)]
    max_snapshot_age_s: u32,
    /// The Omnimagnet's model refresh [s]: declared to the observer
    /// (`OmniSettings::model_refresh_s`, watched: `MODEL_STALE`) and run,
    /// the model re-linearised at its estimate every S seconds as a
    /// firmware's background task does (`OmniObserver::prepare_model`,
    /// `install_model`). Default: 10 for a sensor set with one thermocouple
    /// on a solenoid (e.g. `--sensors 0,2,4`, which the observer accepts
    /// only with a refresh of at most 30 s), none otherwise; 0: none (the
    /// build-time linearisation at the ambient).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    relinearize_s: Option<f64>,
    /// The thermocouples' converter step [K]: every reading (healthy or
    /// faulty) is rounded to a multiple of Q, as the converter reports it.
    /// Default 0.25, the MAX31855's; 0: the plant's truth to the bit.
    #[arg(
        long,
        value_name = "Q",
        default_value_t = faults::DEFAULT_SENSOR_QUANTUM_K,
        allow_negative_numbers = true
    )]
    sensor_quantum_k: f64,
    /// Gaussian noise on every reading, before the rounding [K] (standard
    /// deviation; default 0). Seeded (--sensor-noise-seed): a run is
    /// reproducible, and a healthy sensor reads the same in a fault case as
    /// in the clean run.
    #[arg(
        long,
        value_name = "S",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    sensor_noise_k: f64,
    /// The seed of --sensor-noise-k.
    #[arg(long, value_name = "N", default_value_t = faults::DEFAULT_NOISE_SEED)]
    sensor_noise_seed: u64,
    /// The observer's stuck-test tolerance [K]: a reading that moves less
    /// than this counts as unchanged (`SensorChecks::stuck_tolerance_k`).
    /// Default: a model file's
    /// `[observer] stuck_tolerance_k`, else 0 (to the bit). About one code
    /// plus twice the noise: 0.3 for --sensor-noise-k 0.1.
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    stuck_tolerance_k: Option<f64>,
    /// Print the report as one JSON object.
    #[arg(long)]
    json: bool,
}

/// Runs `faults`.
pub fn run(a: FaultsArgs) -> Result<()> {
    let file_model = match ModelSpec::parse(&a.model)? {
        ModelSpec::Omnimagnet => None,
        ModelSpec::File(p) => {
            let file = ModelFile::load(&p)?;
            let model = Model::build(&file)?;
            let spec = file.observer.clone().unwrap_or_default();
            Some((model, spec))
        }
        _ => bail!(
            "faults --model {}: {NOT_YET} (`omnimagnet` or a model file)",
            a.model
        ),
    };
    let plant: Box<dyn Plant> = match &file_model {
        None => Box::new(OmnimagnetPlant::default()),
        Some((model, _)) => Box::new(FilePlant::new(model.clone())?),
    };
    let inputs = plant.info().inputs.len();
    let mut cfg = FaultConfig::default();
    if let Some(path) = &a.trace {
        let trace = common::read_trace(path, &a.trace_args)?;
        let bind = common::bindings(&a.trace_args)?;
        let drive = Drive::from_trace(plant.info(), &trace, &bind)?;
        let (Some(&t0), Some(&t1)) = (drive.time_s.first(), drive.time_s.last()) else {
            bail!("{}: the trace has no rows", path.display());
        };
        if t1 <= t0 {
            bail!("{}: the trace spans no time", path.display());
        }
        cfg.duration_s = t1 - t0;
        cfg.ambient_c = drive
            .boundaries
            .first()
            .and_then(|b| b.first().copied())
            .unwrap_or(cfg.ambient_c);
        cfg.trace = Some(CurrentTrace {
            time_s: drive.time_s.iter().map(|t| t - t0).collect(),
            currents_a: (0..drive.len())
                .map(|k| (0..inputs).map(|m| drive.currents[m][k]).collect())
                .collect(),
        });
    }
    let currents_a: Vec<f64> = match a.current_a.as_slice() {
        [] if cfg.trace.is_some() => vec![0.0; inputs],
        [] => bail!("faults needs --current-a A (one for all inputs, or one per input) or --trace"),
        [one] => vec![*one; inputs],
        many if many.len() == inputs => many.to_vec(),
        other => bail!(
            "--current-a takes 1 or {inputs} values (the model's inputs), got {}",
            other.len()
        ),
    };
    let available = match &file_model {
        None => THERMOCOUPLES,
        Some((_, spec)) => spec.sensors.len(),
    };
    let mut sensors = vec![a.sensors.is_empty(); available];
    for &j in &a.sensors {
        match sensors.get_mut(j) {
            Some(s) => *s = true,
            None => bail!(
                "--sensors: no thermocouple {j} (the model has {available}: 0..={})",
                available.saturating_sub(1)
            ),
        }
    }
    let classes = a
        .classes
        .iter()
        .map(|name| {
            FaultClass::parse(name).ok_or_else(|| {
                let all: Vec<&str> = FaultClass::ALL.iter().map(|c| c.name()).collect();
                anyhow::anyhow!(
                    "--classes: unknown class `{name}` (one of {})",
                    all.join(", ")
                )
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let period_us = u64::from(a.reading_period_ms) * 1000;
    if a.step_us == 0 || period_us == 0 || period_us % u64::from(a.step_us) != 0 {
        bail!(
            "--reading-period-ms {} must be a positive whole number of --step-us {} steps",
            a.reading_period_ms,
            a.step_us
        );
    }
    let cfg = FaultConfig {
        currents_a,
        reading_every: u32::try_from(period_us / u64::from(a.step_us))?,
        duration_s: a.duration_s.unwrap_or(cfg.duration_s),
        step_us: a.step_us,
        sensors,
        onsets_s: a.onset_s,
        classes,
        off_s: a.off_s,
        max_snapshot_age_s: a.max_snapshot_age_s,
        relinearize_s: a.relinearize_s,
        sensor_model: SensorModel {
            quantum_k: a.sensor_quantum_k,
            noise_k: a.sensor_noise_k,
            seed: a.sensor_noise_seed,
        },
        stuck_tolerance_k: a.stuck_tolerance_k,
        ..cfg
    };
    let mut report = match &file_model {
        None => faults::run(&cfg).map_err(|e| match e {
            FaultError::Build(BuildError::ModelRefreshRequired { .. }) => anyhow::anyhow!(
                "faults --sensors {:?}: {e}; the campaign declares and runs the refresh with --relinearize-s S (default {} s for such a sensor set; 0 declares none)",
                a.sensors,
                faults::DEFAULT_REFRESH_S
            ),
            e => e.into(),
        })?,
        Some((model, spec)) => {
            // The observer is built with the sensors in use only.
            let mut spec = spec.clone();
            spec.sensors = spec
                .sensors
                .iter()
                .zip(&cfg.sensors)
                .filter(|(_, used)| **used)
                .map(|(name, _)| name.clone())
                .collect();
            let cfg = FaultConfig {
                sensors: vec![true; spec.sensors.len()],
                ..cfg
            };
            faults::run_model(model, &spec, &cfg)?
        }
    };
    report.trace = a.trace.as_ref().map(|p| p.display().to_string());
    if a.json {
        let mut summary = serde_json::to_value(&report)?;
        summary["command"] = "faults".into();
        common::print_json(&summary);
    } else {
        print_text(&report);
    }
    Ok(())
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn verdict(c: &CaseReport) -> String {
    let mut v = Vec::new();
    if c.lost_shutdown {
        v.push("LOST");
    }
    if c.late_shutdown {
        v.push("LATE");
    }
    if c.false_trip {
        v.push("FALSE-TRIP");
    }
    if c.protective_trip {
        v.push("protective-trip");
    }
    if let Some(s) = &c.snapshot {
        v.push(match (s.refused, s.starts_latched) {
            (true, true) => "refused,latched",
            (true, false) => "REFUSED-NOT-LATCHED",
            (false, _) => "restored",
        });
    }
    if c.flag_goal_met == Some(false) {
        v.push("FLAG-LATE");
    }
    if v.is_empty() {
        "ok".into()
    } else {
        v.join(" ")
    }
}

/// The start classes' table (closed loop: the drive obeys the limits).
fn print_starts(r: &FaultReport) {
    let starts: Vec<_> = r
        .cases
        .iter()
        .filter_map(|c| c.start.as_ref().map(|s| (c, s)))
        .collect();
    if starts.is_empty() {
        return;
    }
    println!();
    println!("starts (closed loop, restarted at the hottest point; goals: over_limit <= 0, under_bound <= 1 K, refused 0):");
    println!(
        "{:<20} {:>8} {:>10} {:>12} {:>13} {:>8} {:>11}",
        "class", "off_s", "restart_s", "over_limit_K", "under_bound_K", "refused", "first_limit"
    );
    for (c, s) in starts {
        println!(
            "{:<20} {:>8.0} {:>10.1} {:>+12.2} {:>13} {:>8} {:>10.0}%",
            c.class.name(),
            s.off_s,
            s.restart_s,
            s.over_limit_k,
            s.under_bound_k.map_or("-".into(), |u| format!("{u:+.2}")),
            s.refused,
            100.0 * s.first_limit_share
        );
    }
}

fn print_text(r: &FaultReport) {
    let drive = match &r.trace {
        Some(path) => format!("the currents of {path}"),
        None => format!("{:?} A", r.currents_a),
    };
    let refresh = if r.relinearize_s > 0.0 {
        format!("model re-linearised every {} s", r.relinearize_s)
    } else {
        "no model refresh".into()
    };
    let quantum = if r.sensor_quantum_k > 0.0 {
        format!("rounded to {} K", r.sensor_quantum_k)
    } else {
        "not rounded".into()
    };
    let noise = if r.sensor_noise_k > 0.0 {
        format!(
            "noise {} K (seed {})",
            r.sensor_noise_k, r.sensor_noise_seed
        )
    } else {
        "no noise".into()
    };
    println!(
        "fault campaign: {} at {drive} for {} s, step {} us, readings every {} s ({quantum}, {noise}), sensors {:?}, onsets {:?} s, {refresh}",
        r.model, r.duration_s, r.step_us, r.reading_period_s, r.sensors, r.onsets_s
    );
    println!(
        "clean run: shutdown {} s, max error {:.2} K on the thermocouple nodes, {:.2} K on the hot spot, {} healthy readings not fused, {} ticks with a heat bias beyond the model; readings off the truth by {:.3} K at most, one repeated for {:.1} s at most",
        opt(r.clean.shutdown_s, 1),
        r.clean.max_error_tc_k,
        r.clean.max_error_hot_spot_k,
        r.clean.healthy_flagged,
        r.clean.bias_alarm_ticks,
        r.clean.max_reading_error_k,
        r.clean.longest_repeat_s
    );
    println!();
    println!(
        "{:<17} {:>6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9} {:>9}  verdict",
        "class",
        "sensor",
        "onset_s",
        "detect_s",
        "flag_s",
        "err_tc_K",
        "err_hs_K",
        "shutdn_s",
        "delay_s"
    );
    for c in &r.cases {
        println!(
            "{:<17} {:>6} {:>8.1} {:>8} {:>8} {:>8.2} {:>8.2} {:>9} {:>9}  {}",
            c.class.name(),
            c.sensor.map_or("all".into(), |s| s.to_string()),
            c.onset_s,
            opt(c.detectable_s, 1),
            opt(c.flag_s, 1),
            c.score.max_error_tc_k,
            c.score.max_error_hot_spot_k,
            opt(c.score.shutdown_s, 1),
            opt(c.shutdown_delay_s, 1),
            verdict(c)
        );
    }
    println!();
    println!(
        "{:<17} {:>5} {:>9} {:>11} {:>11} {:>8} {:>8} {:>9} {:>11} {:>4} {:>4} {:>5} {:>5}",
        "summary",
        "cases",
        "unflagged",
        "worst_flag",
        "after_detect",
        "goal_s",
        "err_tc_K",
        "err_hs_K",
        "worst_delay",
        "lost",
        "late",
        "false",
        "prot"
    );
    for s in &r.summary.classes {
        println!(
            "{:<17} {:>5} {:>9} {:>11} {:>11} {:>8} {:>8.2} {:>9.2} {:>11} {:>4} {:>4} {:>5} {:>5}",
            s.class.name(),
            s.cases,
            s.unflagged,
            opt(s.worst_flag_s, 1),
            opt(s.worst_flag_after_detectable_s, 1),
            opt(s.flag_goal_s, 0),
            s.worst_error_tc_k,
            s.worst_error_hot_spot_k,
            opt(s.worst_delay_s, 1),
            s.lost,
            s.late,
            s.false_trips,
            s.protective_trips
        );
    }
    print_starts(r);
    println!();
    println!(
        "{} cases: {} lost shutdowns, {} late (> {} s), {} false trips ({} under spike trains)",
        r.summary.cases,
        r.summary.lost_shutdowns,
        r.summary.late_shutdowns,
        faults::LATE_S,
        r.summary.false_trips,
        r.summary.false_trips_spikes
    );
    for g in &r.summary.goals {
        println!(
            "[{}] {}: {}",
            if g.met { "met" } else { "NOT MET" },
            g.goal,
            g.detail
        );
    }
}
