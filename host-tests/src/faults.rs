//! The fault campaign of issue 17: every fault class on every sensor at
//! several onset times, each run against the clean run, for a safety
//! engineer signing off a sensor placement (`coil-thermal faults`).
//!
//! The observer under test is the library's [`OmniObserver`] (the tick API a
//! firmware calls); the truth is the paper's nonlinear Omnimagnet
//! ([`OmnimagnetPlant`], RK4), heated at constant currents from the ambient.
//! The thermocouples read the plant's solenoid nodes every
//! `reading_every` model steps (2 Hz at the defaults), the loop of
//! `tests/sensor_consistency.rs`, through a converter ([`SensorModel`]):
//! by default rounded to the MAX31855's 0.25 K codes, as the product's
//! converter reports them, optionally with seeded Gaussian noise (exact
//! readings, the truth to the bit, with a quantum of 0). Each case injects one fault from its
//! onset to the end of the run (or restarts the observer at its onset) and
//! is scored against its *reference*: the clean run with the same current
//! schedule (for the restart cases, the observer kept ticking through the
//! off time).
//!
//! Per case:
//!
//! * **time to flag** \[s\] after the onset: the first tick at or after the
//!   onset where the observer says something is wrong. For a sensor fault:
//!   a faulty sensor's [`SensorStatus`] is neither `Fused` nor `NoReading`
//!   (a fault, a gate rejection, too old, colder than the physics), or the
//!   tick's flags carry [`InputFlags::SENSORS_COLDER_THAN_PHYSICS`] or
//!   [`InputFlags::HEAT_BIAS_BEYOND_MODEL`] (a bias beyond the model's
//!   uncertainty: the observer does not say which sensor drags it). A
//!   dropout (no readings) shows as `NoReading`, which the observer cannot
//!   tell from a sample not yet due: never flagged by the observer. Frozen
//!   clock: [`InputFlags::CLOCK_FROZEN`] or the shutdown. Huge current:
//!   [`InputFlags::CURRENT_CLAMPED`] / `CURRENT_NOT_FINITE`. A refused
//!   snapshot is flagged at the restart (0 s) by the refusal itself. The
//!   model refresh stopping (`refresh-stops`, run only with a refresh):
//!   [`InputFlags::MODEL_STALE`];
//! * **detectable** \[s\] after the onset, for the two faults that start
//!   harmless: a *drift* from the first reading whose offset from the
//!   truth exceeds the band the model's uncertainty allows at the truth
//!   (`consistency_offset_k + consistency_fraction * rise`, 3 K + 25 % at
//!   the defaults: before that the reading is one the physics cannot tell
//!   from a healthy one), a *stuck* sensor from the first reading more
//!   than the stuck threshold (1 K) off the truth (before that it reads
//!   the truth). The flag goals count from there: a drift within
//!   [`FLAG_GOAL_S`] of becoming detectable, a stuck sensor within
//!   [`STUCK_FLAG_GOAL_S`]. A *dropout* is detectable at the first
//!   reading it withholds (an onset between two readings withholds
//!   nothing until the next is due); every other fault is detectable at
//!   its onset.
//!   The time to flag itself is always counted from the onset;
//! * **largest estimate error** \[K\] from the onset to the shutdown (or
//!   the end): `|estimate - truth|` on the thermocouple nodes, and on the
//!   hot spot, the alarm element ([`ALARM_NODES`]) hottest in the truth;
//! * **shutdown** and its delay against the reference (negative: earlier);
//!   **lost** (the reference shut down, the case did not within the run),
//!   **late** (more than [`LATE_S`] after the reference), **false trip** (a
//!   shutdown where the reference has none). A shutdown that is the
//!   documented reaction to the fault (frozen clock: the model is lost; huge
//!   current: clamped to the input limit, the observer heats at it; a
//!   refused snapshot: the conservative start is latched) is counted as a
//!   **protective trip**, not a false one.
//!
//! A sensor set that leaves a solenoid with one thermocouple (`--sensors
//! 0,2,4`) is accepted by the observer only with a declared model refresh
//! (`OmniSettings::model_refresh_s`, issue 17): the campaign declares
//! [`DEFAULT_REFRESH_S`] for it and re-linearises the model at the
//! estimate at that period, as the firmware's background task does
//! (`--relinearize-s` overrides it; `0` declares none, which such a set
//! refuses at build).

use coil_thermal::observer::omnimagnet::needs_model_refresh;
use coil_thermal::observer::omnimagnet::ALARM_NODES;
use coil_thermal::observer::snapshot::snapshot_len;
use coil_thermal::observer::SensorChecks;
use coil_thermal::observer::{
    OmniInputs, OmniObserver, OmniObserverState, OmniSettings, SensorStatus, TimedReading,
};
use coil_thermal::omnimagnet::observer::ObserverSettings;
use coil_thermal::omnimagnet::{Omnimagnet, NODES, SOLENOIDS, THERMOCOUPLES, THERMOCOUPLE_NODES};
use coil_thermal::{InputFlags, Reading, SensorFault};
use serde::Serialize;

use crate::devices::OmnimagnetPlant;
use crate::sim::Plant;

pub mod network;
pub mod starts;
pub use network::run_model;
pub use starts::{StartScore, UNDER_BOUND_GOAL_K};

/// A shutdown later than the reference's by more than this is late \[s\]
/// (issue 17).
pub const LATE_S: f64 = 1.0;
/// Goal: every single-sensor fault flagged within this time \[s\]...
pub const FLAG_GOAL_S: f64 = 1.0;
/// ...except a stuck sensor, within this one \[s\].
pub const STUCK_FLAG_GOAL_S: f64 = 10.0;
/// Goal on the largest estimate error meanwhile \[K\].
pub const ERROR_GOAL_K: f64 = 2.0;
/// Drift rate of the `drift` class \[K/s\].
pub const DRIFT_K_PER_S: f64 = -0.05;
/// Height of the jumps and spikes \[K\].
pub const JUMP_K: f64 = 50.0;
/// The current a `huge-current` fault reports \[A\].
pub const HUGE_CURRENT_A: f32 = 1e20;
/// The model refresh the campaign declares, and runs, for an Omnimagnet
/// sensor set that needs one (one thermocouple on a solenoid) \[s\]: the
/// period docs/protection.md measured every goal at.
pub const DEFAULT_REFRESH_S: f64 = 10.0;
/// The step the thermocouples' readings are rounded to by default \[K\]:
/// the MAX31855's (`coil_thermal::sensors::max31855::THERMOCOUPLE_LSB_C`),
/// the converter the product targets.
pub const DEFAULT_SENSOR_QUANTUM_K: f64 = 0.25;
/// The seed of the readings' noise by default.
pub const DEFAULT_NOISE_SEED: u64 = 17;

/// A fault class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FaultClass {
    /// Open thermocouple ([`SensorFault::OpenCircuit`]).
    Open,
    /// Shorted to ground ([`SensorFault::ShortToGnd`]).
    ShortGnd,
    /// Shorted to the supply ([`SensorFault::ShortToVcc`]).
    ShortVcc,
    /// Holds the value it read at the onset.
    Stuck,
    /// Drifts by [`DRIFT_K_PER_S`] from the onset.
    Drift,
    /// Reads [`JUMP_K`] too hot from the onset.
    JumpUp,
    /// Reads [`JUMP_K`] too cold from the onset.
    JumpDown,
    /// One reading in two [`JUMP_K`] too hot.
    Spikes,
    /// No readings from the onset.
    Dropout,
    /// Every thermocouple reads the ambient (detached) from the onset.
    AllDetached,
    /// Every thermocouple holds its onset value.
    AllStuck,
    /// The tick's clock gives no elapsed time from the onset.
    FrozenClock,
    /// The current input reads [`HUGE_CURRENT_A`] on every solenoid.
    HugeCurrent,
    /// Restart at the onset from a snapshot with one byte flipped.
    CorruptSnapshot,
    /// Restart from a snapshot older than the policy allows (the device off
    /// for the policy's age and a minute).
    StaleSnapshot,
    /// Restart after the device was off (no current) for the off time,
    /// through `restore_after`.
    PowerOff,
    /// The model refresh (the firmware's background task that
    /// re-linearises the model) stops at the onset; run only with a
    /// refresh.
    RefreshStops,
    /// Reset with no snapshot at the hottest point of the closed-loop run,
    /// at once (see [`starts`]).
    #[serde(rename = "reset-0s")]
    Reset0s,
    /// The same after 1 min off.
    #[serde(rename = "reset-1min")]
    Reset1Min,
    /// The same after 10 min off.
    #[serde(rename = "reset-10min")]
    Reset10Min,
    /// The same after 1 h off.
    #[serde(rename = "reset-1h")]
    Reset1H,
    /// Saved at the hottest point, off for the off time, restored with
    /// the off time unknown (the readings at the restore say it).
    RestoreUnknownOff,
}

impl FaultClass {
    /// Every class, in report order.
    pub const ALL: [Self; 22] = [
        Self::Open,
        Self::ShortGnd,
        Self::ShortVcc,
        Self::Stuck,
        Self::Drift,
        Self::JumpUp,
        Self::JumpDown,
        Self::Spikes,
        Self::Dropout,
        Self::AllDetached,
        Self::AllStuck,
        Self::FrozenClock,
        Self::HugeCurrent,
        Self::CorruptSnapshot,
        Self::StaleSnapshot,
        Self::PowerOff,
        Self::RefreshStops,
        Self::Reset0s,
        Self::Reset1Min,
        Self::Reset10Min,
        Self::Reset1H,
        Self::RestoreUnknownOff,
    ];

    /// The name on the command line and in the report.
    pub fn name(self) -> &'static str {
        match self {
            Self::Open => "open",
            Self::ShortGnd => "short-gnd",
            Self::ShortVcc => "short-vcc",
            Self::Stuck => "stuck",
            Self::Drift => "drift",
            Self::JumpUp => "jump-up",
            Self::JumpDown => "jump-down",
            Self::Spikes => "spikes",
            Self::Dropout => "dropout",
            Self::AllDetached => "all-detached",
            Self::AllStuck => "all-stuck",
            Self::FrozenClock => "frozen-clock",
            Self::HugeCurrent => "huge-current",
            Self::CorruptSnapshot => "corrupt-snapshot",
            Self::StaleSnapshot => "stale-snapshot",
            Self::PowerOff => "power-off",
            Self::RefreshStops => "refresh-stops",
            Self::Reset0s => "reset-0s",
            Self::Reset1Min => "reset-1min",
            Self::Reset10Min => "reset-10min",
            Self::Reset1H => "reset-1h",
            Self::RestoreUnknownOff => "restore-unknown-off",
        }
    }

    /// The class named `name`.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }

    /// A fault of one sensor (run on each sensor in use).
    pub fn per_sensor(self) -> bool {
        matches!(
            self,
            Self::Open
                | Self::ShortGnd
                | Self::ShortVcc
                | Self::Stuck
                | Self::Drift
                | Self::JumpUp
                | Self::JumpDown
                | Self::Spikes
                | Self::Dropout
        )
    }

    /// A restart with the drive obeying the limits, scored by [`starts`].
    pub fn is_start(self) -> bool {
        matches!(
            self,
            Self::Reset0s
                | Self::Reset1Min
                | Self::Reset10Min
                | Self::Reset1H
                | Self::RestoreUnknownOff
        )
    }

    /// A shutdown is the documented reaction to this fault.
    pub fn trips_by_design(self) -> bool {
        matches!(
            self,
            Self::FrozenClock | Self::HugeCurrent | Self::CorruptSnapshot | Self::StaleSnapshot
        )
    }

    /// Issue 17's goal on the time to flag \[s\], for the single-sensor
    /// classes the observer can see (`None`: no goal).
    pub fn flag_goal_s(self) -> Option<f64> {
        match self {
            Self::Stuck => Some(STUCK_FLAG_GOAL_S),
            c if c.per_sensor() => Some(FLAG_GOAL_S),
            _ => None,
        }
    }
}

/// Input currents over time: a recorded trace's rows.
#[derive(Debug, Clone, Default)]
pub struct CurrentTrace {
    /// Row times from the run's start \[s\], increasing.
    pub time_s: Vec<f64>,
    /// Currents per row, one per model input \[A\].
    pub currents_a: Vec<Vec<f64>>,
}

impl CurrentTrace {
    /// The currents held at `t_s` \[s\] (the last row at or before it; the
    /// first row before the trace starts).
    pub fn at(&self, t_s: f64) -> &[f64] {
        let k = self.time_s.partition_point(|t| *t <= t_s);
        self.currents_a
            .get(k.saturating_sub(1))
            .map_or(&[], Vec::as_slice)
    }
}

/// What to run.
#[derive(Debug, Clone)]
pub struct FaultConfig {
    /// Constant current of each model input (each solenoid) \[A\]
    /// (without `trace`).
    pub currents_a: Vec<f64>,
    /// Currents from a recorded trace instead, held from each row to the
    /// next; the run lasts `duration_s` (the CLI sets the trace's span).
    pub trace: Option<CurrentTrace>,
    /// Heating time \[s\] (the off time of a restart case comes on top).
    pub duration_s: f64,
    /// The observer's model step, one tick \[us\].
    pub step_us: u32,
    /// Model steps between two thermocouple samples (the correction period).
    pub reading_every: u32,
    /// Ambient \[degC\].
    pub ambient_c: f64,
    /// Thermocouples in use (the Omnimagnet's: order of
    /// [`THERMOCOUPLE_NODES`]; a model file's: its observer's sensors).
    pub sensors: Vec<bool>,
    /// Onset times \[s\]; empty: 60 s and half the clean shutdown time (or
    /// half the duration without one).
    pub onsets_s: Vec<f64>,
    /// Classes to run; empty: all.
    pub classes: Vec<FaultClass>,
    /// Off time of the `power-off` case \[s\].
    pub off_s: f64,
    /// Oldest snapshot a restart accepts \[s\].
    pub max_snapshot_age_s: u32,
    /// The Omnimagnet's model refresh \[s\]: declared to the observer
    /// (`OmniSettings::model_refresh_s`) and run, the model re-linearised
    /// at its estimate at this period (`OmniObserver::prepare_model` and
    /// `install_model`, what a firmware's background task does). `None`:
    /// [`DEFAULT_REFRESH_S`] for a sensor set that needs a refresh, none
    /// otherwise; `Some(0.0)`: none (the build-time linearisation at the
    /// ambient throughout), which a sensor set that needs one refuses at
    /// build.
    pub relinearize_s: Option<f64>,
    /// How the thermocouples read (healthy or faulty): noise and the
    /// converter's quantum.
    pub sensor_model: SensorModel,
    /// The observer's stuck-test tolerance \[K\]
    /// (`SensorChecks::stuck_tolerance_k`).
    /// `None`: a model file's `[observer] stuck_tolerance_k`, else the
    /// library's default (0, to the bit).
    pub stuck_tolerance_k: Option<f64>,
}

/// How a thermocouple's converter turns a temperature into a reading: the
/// temperature plus Gaussian noise, rounded to a multiple of the quantum
/// (0 for either: none). Every reading the campaign gives the observer
/// passes through it, a faulty one too (a drift, a jump, a detached
/// sensor reading the ambient are read through the converter; a stuck
/// sensor repeats the converter's reading at its onset, to the bit).
///
/// The noise is a function of the seed, the sensor and the reading's
/// number alone, so a run is reproducible and a healthy sensor reads the
/// same in a fault case as in the clean run it is judged against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorModel {
    /// Readings are multiples of this \[K\] (0: exact).
    pub quantum_k: f64,
    /// Standard deviation of the Gaussian noise added before the rounding
    /// \[K\] (0: none).
    pub noise_k: f64,
    /// The noise's seed.
    pub seed: u64,
}

impl SensorModel {
    /// Readings as the plant's truth, to the bit.
    pub const EXACT: Self = Self {
        quantum_k: 0.0,
        noise_k: 0.0,
        seed: DEFAULT_NOISE_SEED,
    };

    /// What sensor `sensor`'s `reading`-th reading of `value_c` \[degC\]
    /// says.
    pub fn read(&self, value_c: f32, sensor: usize, reading: u64) -> f32 {
        let mut v = f64::from(value_c);
        if self.noise_k > 0.0 {
            v += self.noise_k * gaussian(self.seed, sensor as u64, reading);
        }
        if self.quantum_k > 0.0 {
            v = (v / self.quantum_k).round() * self.quantum_k;
        }
        v as f32
    }
}

impl Default for SensorModel {
    fn default() -> Self {
        Self {
            quantum_k: DEFAULT_SENSOR_QUANTUM_K,
            ..Self::EXACT
        }
    }
}

/// A reading the observer was given and did not fuse. `NoReading` and
/// `Silent` say that none reached it: a winding's resistance is no reading
/// below its least current (the drive cannot divide by nothing), which is
/// not a refusal. A thermocouple's reading always reaches it.
pub(crate) fn refused(status: &SensorStatus) -> bool {
    !matches!(
        status,
        SensorStatus::Fused { .. } | SensorStatus::NoReading | SensorStatus::Silent { .. }
    )
}

/// What sensor `j` of `subject` reads of `value_c` \[degC\] at its
/// `reading`-th reading: the campaign's converter `model`, or the sensor's
/// own where it is not a thermocouple ([`Subject::sensor_model`]).
pub(crate) fn read_sensor<S: Subject>(
    subject: &S,
    model: &SensorModel,
    value_c: f32,
    j: usize,
    reading: u64,
) -> f32 {
    subject
        .sensor_model(j, value_c, *model)
        .read(value_c, j, reading)
}

/// SplitMix64's output function: a well-mixed 64-bit hash of `x`.
fn mix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// A standard normal number determined by `(seed, sensor, reading)`
/// (Box-Muller on two hashed uniforms).
fn gaussian(seed: u64, sensor: u64, reading: u64) -> f64 {
    let key = mix64(seed ^ mix64(sensor ^ mix64(reading)));
    // Uniforms in (0, 1] and [0, 1) from 53 bits each.
    let unit = |bits: u64| (bits >> 11) as f64 / (1u64 << 53) as f64;
    let u1 = 1.0 - unit(mix64(key));
    let u2 = unit(mix64(key ^ 0x5851_f42d_4c95_7f2d));
    (-2.0 * u1.ln()).sqrt() * (core::f64::consts::TAU * u2).cos()
}

impl Default for FaultConfig {
    fn default() -> Self {
        Self {
            currents_a: vec![7.0; SOLENOIDS],
            trace: None,
            duration_s: 1800.0,
            step_us: 100_000,
            reading_every: 5,
            ambient_c: 22.0,
            sensors: vec![true; THERMOCOUPLES],
            onsets_s: Vec::new(),
            classes: Vec::new(),
            off_s: 600.0,
            max_snapshot_age_s: 3600,
            relinearize_s: None,
            sensor_model: SensorModel::default(),
            stuck_tolerance_k: None,
        }
    }
}

/// A run's scores.
#[derive(Debug, Clone, Default, Serialize)]
pub struct RunScore {
    /// First shutdown \[s\] (`None`: none within the run).
    pub shutdown_s: Option<f64>,
    /// Largest `|estimate - truth|` on the thermocouple nodes \[K\] (from
    /// the onset for a case, from the start for the clean run).
    pub max_error_tc_k: f64,
    /// Largest `|estimate - truth|` on the alarm element hottest in the
    /// truth \[K\].
    pub max_error_hot_spot_k: f64,
    /// Ticks where a healthy sensor was not fused although it read.
    pub healthy_flagged: u32,
    /// Ticks flagged [`InputFlags::HEAT_BIAS_BEYOND_MODEL`] (in the clean
    /// run: false bias alarms).
    pub bias_alarm_ticks: u32,
    /// Largest `|reading - truth|` of a healthy sensor's reading \[K\]:
    /// the converter's quantum and noise ([`SensorModel`]).
    pub max_reading_error_k: f64,
    /// Longest a healthy sensor's reading repeated its value to the bit,
    /// from the first reading of the value to its last repetition \[s\]
    /// (what the observer's stuck test must tell from a stuck sensor).
    pub longest_repeat_s: f64,
}

/// A restart case's snapshot.
#[derive(Debug, Clone, Serialize)]
pub struct SnapshotOutcome {
    /// `restore` refused it.
    pub refused: bool,
    /// Why (the library's error), if refused.
    pub error: Option<String>,
    /// The state it started from showed the shutdown latched before the
    /// first tick.
    pub starts_latched: bool,
}

/// One case of the matrix.
#[derive(Debug, Clone, Serialize)]
pub struct CaseReport {
    /// Fault class.
    pub class: FaultClass,
    /// Faulty sensor (index into [`THERMOCOUPLE_NODES`]) for the
    /// single-sensor classes.
    pub sensor: Option<usize>,
    /// Onset \[s\].
    pub onset_s: f64,
    /// Time to flag after the onset \[s\] (`None`: never flagged).
    pub flag_s: Option<f64>,
    /// When the fault became detectable, after the onset \[s\] (see the
    /// module docs; 0 for the faults detectable at once, `None`: never
    /// within the run).
    pub detectable_s: Option<f64>,
    /// The flag goal was met: flagged within the class's goal after the
    /// fault became detectable, or never detectable (`None`: no goal).
    pub flag_goal_met: Option<bool>,
    /// The case's run.
    #[serde(flatten)]
    pub score: RunScore,
    /// The reference's shutdown \[s\].
    pub reference_shutdown_s: Option<f64>,
    /// `shutdown - reference` \[s\] (negative: earlier) when both exist.
    pub shutdown_delay_s: Option<f64>,
    /// The reference shut down, this case did not.
    pub lost_shutdown: bool,
    /// Later than the reference by more than [`LATE_S`].
    pub late_shutdown: bool,
    /// A shutdown where the reference has none, not the class's documented
    /// reaction.
    pub false_trip: bool,
    /// A shutdown where the reference has none, the class's documented
    /// reaction.
    pub protective_trip: bool,
    /// Restart cases: the snapshot's fate.
    pub snapshot: Option<SnapshotOutcome>,
    /// Start cases: their scores (see [`starts`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub start: Option<StartScore>,
}

/// Per-class summary.
#[derive(Debug, Clone, Serialize)]
pub struct ClassSummary {
    /// Fault class.
    pub class: FaultClass,
    /// Cases run.
    pub cases: usize,
    /// Cases never flagged (a power-off restart has nothing to flag).
    pub unflagged: usize,
    /// Worst time to flag among the flagged cases \[s\].
    pub worst_flag_s: Option<f64>,
    /// Worst time from becoming detectable to the flag \[s\], among the
    /// flagged cases that became detectable.
    pub worst_flag_after_detectable_s: Option<f64>,
    /// Issue 17's goal on it \[s\].
    pub flag_goal_s: Option<f64>,
    /// Worst thermocouple-node error \[K\].
    pub worst_error_tc_k: f64,
    /// Worst hot-spot error \[K\].
    pub worst_error_hot_spot_k: f64,
    /// Latest shutdown against the reference \[s\].
    pub worst_delay_s: Option<f64>,
    /// Lost shutdowns.
    pub lost: usize,
    /// Late shutdowns.
    pub late: usize,
    /// False trips.
    pub false_trips: usize,
    /// Protective trips.
    pub protective_trips: usize,
}

/// One of issue 17's done-when goals.
#[derive(Debug, Clone, Serialize)]
pub struct Goal {
    /// What it asks.
    pub goal: String,
    /// Met on this run.
    pub met: bool,
    /// The figure.
    pub detail: String,
}

/// The whole matrix's summary.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Per class, in report order.
    pub classes: Vec<ClassSummary>,
    /// Cases run.
    pub cases: usize,
    /// Lost shutdowns.
    pub lost_shutdowns: usize,
    /// Shutdowns later than the reference's by more than [`LATE_S`].
    pub late_shutdowns: usize,
    /// False trips (all classes).
    pub false_trips: usize,
    /// False trips under spike trains.
    pub false_trips_spikes: usize,
    /// Refused snapshots whose start was not latched.
    pub refused_not_latched: usize,
    /// Issue 17's goals.
    pub goals: Vec<Goal>,
}

/// Version of the JSON report's layout ([`FaultReport::schema_version`]):
/// the host tool's one JSON schema version (docs/json.md), under which
/// every subcommand's summary is documented.
pub const SCHEMA_VERSION: u32 = 1;

/// The campaign's report.
#[derive(Debug, Clone, Serialize)]
pub struct FaultReport {
    /// Layout version ([`SCHEMA_VERSION`]).
    pub schema_version: u32,
    /// Model name.
    pub model: String,
    /// Constant currents \[A\] (empty with a trace).
    pub currents_a: Vec<f64>,
    /// The trace the currents came from, if any.
    pub trace: Option<String>,
    /// Heating time \[s\].
    pub duration_s: f64,
    /// Model step \[us\].
    pub step_us: u32,
    /// Thermocouple sample period \[s\].
    pub reading_period_s: f64,
    /// Thermocouples in use.
    pub sensors: Vec<usize>,
    /// Onsets \[s\].
    pub onsets_s: Vec<f64>,
    /// The model refresh declared and run \[s\] (0: none).
    pub relinearize_s: f64,
    /// The readings' quantum \[K\] ([`SensorModel::quantum_k`]; 0: exact).
    pub sensor_quantum_k: f64,
    /// The readings' noise \[K\] ([`SensorModel::noise_k`]; 0: none).
    pub sensor_noise_k: f64,
    /// The noise's seed ([`SensorModel::seed`]).
    pub sensor_noise_seed: u64,
    /// The observer's stuck-test tolerance \[K\] (0: an unchanged reading
    /// is the same to the bit).
    pub stuck_tolerance_k: f64,
    /// The heat-bias noise the observer runs with \[W^2/s\] (a model
    /// file's network observer: its `[observer]` table's or the default,
    /// as the firmware's); absent for the Omnimagnet's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bias_noise_w2_per_s: Option<f64>,
    /// The clean run.
    pub clean: RunScore,
    /// Every case.
    pub cases: Vec<CaseReport>,
    /// The summary.
    pub summary: Summary,
}

/// The campaign's errors (bad configuration).
#[derive(Debug, thiserror::Error)]
pub enum FaultError {
    /// A parameter out of range.
    #[error("{0}")]
    Invalid(String),
    /// The observer did not build.
    #[error("the observer does not build: {0}")]
    Build(coil_thermal::BuildError),
}

/// One fault in a run.
#[derive(Debug, Clone, Copy)]
struct Injected {
    class: FaultClass,
    sensor: Option<usize>,
    onset_s: f64,
}

/// What a restart does.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Restart {
    /// No restart.
    None,
    /// The reference of a restart: zero current from `at_s` for `off_s`,
    /// the observer ticking through.
    TickThrough { at_s: f64, off_s: f64 },
    /// Save at `at_s`, off (no current, no tick) for `off_s`, then restore
    /// (a byte flipped first with `corrupt`; `restore_after` with `cool`,
    /// else `restore`).
    Restore {
        at_s: f64,
        off_s: f64,
        corrupt: bool,
        cool: bool,
    },
}

impl Restart {
    /// Zero-current window `(from, to]` \[s\].
    fn off_window(self) -> Option<(f64, f64)> {
        match self {
            Self::None => None,
            Self::TickThrough { at_s, off_s } | Self::Restore { at_s, off_s, .. } => {
                Some((at_s, at_s + off_s))
            }
        }
    }
}

/// What the campaign needs of an observer under test and its plant: the
/// Omnimagnet's [`OmniObserver`] ([`OmniSubject`]) or a model file's
/// `NetworkObserver` ([`run_model`]). Node indices are the plant's, which
/// are the observer's.
pub trait Subject {
    /// The observer's state.
    type State;
    /// Model name for the report.
    fn name(&self) -> String;
    /// The plant node each thermocouple reads, in sensor order.
    fn sensor_nodes(&self) -> &[usize];
    /// The nodes whose estimate protects (the hot spot is the hottest in
    /// the truth).
    fn alarm_nodes(&self) -> &[usize];
    /// Current inputs of the plant.
    fn inputs(&self) -> usize;
    /// A fresh plant, the truth.
    fn plant(&self) -> Box<dyn Plant>;
    /// The observer's consistency band and stuck threshold.
    fn consistency(&self) -> Consistency;
    /// A state with every node at `ambient_c` \[degC\].
    fn state(&self, ambient_c: f32) -> Self::State;
    /// One tick.
    fn tick(&self, state: &mut Self::State, inputs: &TickInputs<'_>) -> TickView;
    /// How sensor `sensor` reads where it is not the campaign's
    /// thermocouple (`campaign`): a winding's resistance reads with its
    /// own relative noise, as kelvin at the truth `truth_c` \[degC\], and
    /// no quantum. Default: the campaign's.
    fn sensor_model(&self, _sensor: usize, _truth_c: f32, campaign: SensorModel) -> SensorModel {
        campaign
    }
    /// How much lower than [`Self::consistency`]'s the band of sensor
    /// `sensor` lies \[K\] (a winding resistance's, by its noise); default 0.
    fn band_widening_k(&self, _sensor: usize) -> f64 {
        0.0
    }
    /// The heat-bias noise of the observer's bias states \[W^2/s\], for
    /// the report (default: not reported).
    fn bias_noise_w2_per_s(&self) -> Option<f64> {
        None
    }
    /// The model refresh the observer declares, which the campaign runs
    /// \[s\] (default 0: none).
    fn refresh_s(&self) -> f64 {
        0.0
    }
    /// Re-linearises the model at the estimate (default: nothing to do).
    fn relinearize(&self, _state: &mut Self::State, _temps_c: &[f32], _ambient_c: f64) {}
    /// The snapshot of `state` at `now_s` \[s\] (`None`: refused).
    fn save(&self, state: &Self::State, now_s: u32) -> Option<Vec<u8>>;
    /// Restores a snapshot (`off_s`: the known off time \[s\], cooled).
    ///
    /// # Errors
    /// The library's refusal, as text.
    fn restore(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        off_s: Option<f32>,
    ) -> Result<Self::State, String>;
    /// The latched start from the sensors after a refused snapshot.
    fn conservative_state(&self, readings_c: &[Option<f32>], ambient_c: f32) -> Self::State;
    /// The start without a history from the sensors' readings now (the
    /// library's safe start).
    fn start(&self, readings_c: &[Option<f32>], ambient_c: f32) -> Self::State;
    /// Restores a snapshot whose off time is unknown, from the readings
    /// now.
    ///
    /// # Errors
    /// The library's refusal, as text.
    fn restore_with_readings(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        readings_c: &[Option<f32>],
    ) -> Result<Self::State, String>;
    /// Each plant node's derated alarm limit at `ambient_c` \[degC\]
    /// (`None`: not limited).
    fn alarm_limits_c(&self, ambient_c: f32) -> Vec<Option<f32>>;
    /// The state's outputs as the campaign reads them.
    fn view(&self, state: &Self::State) -> TickView;
    /// The state shows the shutdown latched.
    fn latched(&self, state: &Self::State) -> bool;
}

/// The band within which a reading is one the physics cannot tell from a
/// healthy one (see the module docs).
#[derive(Debug, Clone, Copy)]
pub struct Consistency {
    /// Fixed part \[K\].
    pub offset_k: f64,
    /// Part proportional to the rise over the ambient.
    pub fraction: f64,
    /// A reading this far off the truth is detectably stuck \[K\].
    pub stuck_threshold_k: f64,
    /// The observer's stuck-test tolerance \[K\] (0: to the bit).
    pub stuck_tolerance_k: f64,
}

/// One tick's inputs.
#[derive(Debug, Clone, Copy)]
pub struct TickInputs<'a> {
    /// Per plant input \[A\].
    pub currents_a: &'a [f32],
    /// Ambient \[degC\].
    pub ambient_c: f32,
    /// Per thermocouple.
    pub readings: &'a [Option<TimedReading>],
    /// Clock \[us\].
    pub now_us: u32,
    /// Time since the last tick \[us\].
    pub elapsed_us: u32,
}

/// What the campaign reads of a tick's outputs.
#[derive(Debug, Clone)]
pub struct TickView {
    /// Estimate per plant node \[degC\].
    pub temps_c: Vec<f32>,
    /// Per thermocouple.
    pub sensors: Vec<SensorStatus>,
    /// The tick's flags.
    pub flags: InputFlags,
    /// The shutdown is latched.
    pub shutdown: bool,
    /// Each plant node's protective upper bound \[degC\] (NaN where the
    /// observer has none).
    pub upper_c: Vec<f32>,
    /// The current each plant input may carry \[A\] (the limiter's).
    pub limits_a: Vec<f32>,
}

/// The Omnimagnet: the library's [`OmniObserver`] against the paper's
/// nonlinear plant.
pub struct OmniSubject {
    observer: OmniObserver,
    settings: OmniSettings,
    /// The declared model refresh \[s\] (0: none).
    refresh_s: f64,
}

impl OmniSubject {
    /// The observer of `cfg` (its sensors, step, reading period and model
    /// refresh: see [`FaultConfig::relinearize_s`]).
    ///
    /// # Errors
    /// Not six sensor flags, or an observer that does not build (a sensor
    /// set that needs a model refresh with `relinearize_s` 0 or above the
    /// observer's bound: [`coil_thermal::BuildError::ModelRefreshRequired`]).
    pub fn new(cfg: &FaultConfig) -> Result<Self, FaultError> {
        let sensors: [bool; THERMOCOUPLES] = cfg.sensors.clone().try_into().map_err(|_| {
            FaultError::Invalid(format!("the Omnimagnet has {THERMOCOUPLES} thermocouples"))
        })?;
        let defaults = OmniSettings::default();
        let (flag, loss) = frozen_ticks(cfg.step_us);
        let refresh_s = match cfg.relinearize_s {
            None if needs_model_refresh(&sensors).is_some() => DEFAULT_REFRESH_S,
            None => 0.0,
            Some(r) => r,
        };
        let settings = OmniSettings {
            step_us: cfg.step_us,
            // One step per tick: the loop ticks at the step (a longer
            // nominal loop than the step would make every tick busy and
            // put every predictor and warm-up slice off).
            loop_period_us: cfg.step_us,
            filter: ObserverSettings {
                sensors,
                correction_period_s: reading_period_s(cfg),
                ..defaults.filter
            },
            frozen_flag_ticks: flag,
            frozen_loss_ticks: loss,
            model_refresh_s: (refresh_s > 0.0).then_some(refresh_s),
            checks: SensorChecks {
                stuck_tolerance_k: cfg
                    .stuck_tolerance_k
                    .unwrap_or(defaults.checks.stuck_tolerance_k),
                ..defaults.checks
            },
            ..defaults
        };
        let observer = OmniObserver::new(
            &Omnimagnet::PAPER,
            &[cfg.ambient_c; NODES],
            cfg.ambient_c,
            &settings,
        )
        .map_err(FaultError::Build)?;
        Ok(Self {
            observer,
            settings,
            refresh_s,
        })
    }
}

/// The frozen-clock counts (to flag, to declare the model lost) at a
/// step of `step_us`: they are ticks; keep their real time (0.1 s, 1 s, at
/// a 1 ms loop).
fn frozen_ticks(step_us: u32) -> (u32, u32) {
    let per_100ms = (100_000 / step_us.max(1)).max(1);
    (per_100ms, 10 * per_100ms)
}

/// Readings \[degC\] per sensor in the observer's fixed slots (`None` past
/// the given ones).
fn sensor_slots<const P: usize>(readings_c: &[Option<f32>]) -> [Option<f32>; P] {
    core::array::from_fn(|j| readings_c.get(j).copied().flatten())
}

/// The thermocouple sample period \[s\].
fn reading_period_s(cfg: &FaultConfig) -> f64 {
    f64::from(cfg.reading_every * cfg.step_us) * 1e-6
}

impl Subject for OmniSubject {
    type State = OmniObserverState;

    fn name(&self) -> String {
        "omnimagnet".into()
    }
    fn sensor_nodes(&self) -> &[usize] {
        &THERMOCOUPLE_NODES
    }
    fn alarm_nodes(&self) -> &[usize] {
        &ALARM_NODES
    }
    fn inputs(&self) -> usize {
        SOLENOIDS
    }
    fn plant(&self) -> Box<dyn Plant> {
        Box::new(OmnimagnetPlant::default())
    }
    fn consistency(&self) -> Consistency {
        Consistency {
            offset_k: self.settings.checks.consistency_offset_k,
            fraction: self.settings.checks.consistency_fraction,
            stuck_threshold_k: self.settings.checks.stuck_threshold_k,
            stuck_tolerance_k: self.settings.checks.stuck_tolerance_k,
        }
    }
    fn state(&self, ambient_c: f32) -> OmniObserverState {
        self.observer
            .with_warm_up(self.observer.state(&[ambient_c; NODES], ambient_c))
    }
    fn tick(&self, state: &mut OmniObserverState, i: &TickInputs<'_>) -> TickView {
        let inputs = OmniInputs {
            currents_a: core::array::from_fn(|m| i.currents_a.get(m).copied().unwrap_or(0.0)),
            ambient_c: i.ambient_c,
            readings: core::array::from_fn(|j| i.readings.get(j).copied().flatten()),
            now_us: i.now_us,
            elapsed_us: i.elapsed_us,
        };
        self.observer.tick(state, &inputs);
        self.view(state)
    }
    fn view(&self, state: &OmniObserverState) -> TickView {
        let out = state.outputs();
        TickView {
            temps_c: out.temps_c.to_vec(),
            sensors: out.sensors.to_vec(),
            flags: out.flags,
            shutdown: out.alarm.shutdown,
            upper_c: out.upper_c.to_vec(),
            limits_a: out.limits.iter().map(|l| l.current_a).collect(),
        }
    }
    fn alarm_limits_c(&self, ambient_c: f32) -> Vec<Option<f32>> {
        let limits = self.observer.alarm().alarm_limits_c(ambient_c);
        let mut all = vec![None; NODES];
        for (node, limit) in ALARM_NODES.iter().zip(limits) {
            all[*node] = Some(limit);
        }
        all
    }
    fn start(&self, readings_c: &[Option<f32>], ambient_c: f32) -> OmniObserverState {
        let readings: [Option<f32>; THERMOCOUPLES] = sensor_slots(readings_c);
        self.observer
            .start(&Omnimagnet::PAPER, &readings, ambient_c)
    }
    fn restore_with_readings(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        readings_c: &[Option<f32>],
    ) -> Result<OmniObserverState, String> {
        let readings: [Option<f32>; THERMOCOUPLES] = sensor_slots(readings_c);
        self.observer
            .restore_with_readings(
                &Omnimagnet::PAPER,
                bytes,
                now_s,
                max_age_s,
                ambient_c,
                &readings,
            )
            .map_err(|e| e.to_string())
    }
    fn refresh_s(&self) -> f64 {
        self.refresh_s
    }
    fn relinearize(&self, state: &mut OmniObserverState, temps_c: &[f32], ambient_c: f64) {
        let op_c: [f64; NODES] =
            core::array::from_fn(|n| temps_c.get(n).copied().map_or(ambient_c, f64::from));
        // Kept as it was if the estimate is not a valid operating point.
        let dt_s = f64::from(self.settings.step_us) * 1e-6;
        let Ok(lin) = Omnimagnet::PAPER.linearize(&op_c, ambient_c, dt_s) else {
            return;
        };
        if let Ok(model) = self.observer.prepare_model(&lin) {
            let _ = self.observer.install_model(state, &model);
        }
    }
    fn save(&self, state: &OmniObserverState, now_s: u32) -> Option<Vec<u8>> {
        let mut bytes = vec![0u8; snapshot_len(NODES)];
        self.observer.save(state, now_s, &mut bytes).ok()?;
        Some(bytes)
    }
    fn restore(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        off_s: Option<f32>,
    ) -> Result<OmniObserverState, String> {
        // `restore` is `restore_after` with no off time: no special case.
        self.observer
            .restore_after(
                &Omnimagnet::PAPER,
                bytes,
                now_s,
                max_age_s,
                ambient_c,
                off_s,
            )
            .map(|s| self.observer.with_warm_up(s))
            .map_err(|e| e.to_string())
    }
    fn conservative_state(&self, readings_c: &[Option<f32>], ambient_c: f32) -> OmniObserverState {
        let readings: [Option<f32>; THERMOCOUPLES] = sensor_slots(readings_c);
        self.observer
            .with_warm_up(self.observer.conservative_state(&readings, ambient_c))
    }
    fn latched(&self, state: &OmniObserverState) -> bool {
        state.outputs().alarm.shutdown
    }
}

/// The subject and the run parameters.
struct Harness<'c, S> {
    cfg: &'c FaultConfig,
    subject: S,
    dt_s: f64,
}

/// A run's raw result.
struct RunResult {
    score: RunScore,
    flag_s: Option<f64>,
    detectable_s: Option<f64>,
    snapshot: Option<SnapshotOutcome>,
}

impl<'c, S: Subject> Harness<'c, S> {
    fn new(cfg: &'c FaultConfig, subject: S) -> Self {
        Self {
            cfg,
            subject,
            dt_s: f64::from(cfg.step_us) * 1e-6,
        }
    }

    /// Whether this tick's outputs show `fault`.
    fn flagged(fault: &Injected, out: &TickView) -> bool {
        let sensor_flag = |j: usize| {
            !matches!(
                out.sensors.get(j),
                Some(SensorStatus::Fused { .. } | SensorStatus::NoReading) | None
            )
        };
        let common = out.flags.contains(InputFlags::SENSORS_COLDER_THAN_PHYSICS)
            || out.flags.contains(InputFlags::HEAT_BIAS_BEYOND_MODEL);
        match fault.class {
            FaultClass::FrozenClock => out.flags.contains(InputFlags::CLOCK_FROZEN) || out.shutdown,
            FaultClass::HugeCurrent => {
                out.flags.contains(InputFlags::CURRENT_CLAMPED)
                    || out.flags.contains(InputFlags::CURRENT_NOT_FINITE)
            }
            FaultClass::CorruptSnapshot | FaultClass::StaleSnapshot | FaultClass::PowerOff => false,
            c if c.is_start() => false,
            FaultClass::RefreshStops => out.flags.contains(InputFlags::MODEL_STALE),
            _ => match fault.sensor {
                Some(j) => common || sensor_flag(j),
                None => common || (0..out.sensors.len()).any(sensor_flag),
            },
        }
    }

    /// Restores after a restart; the state to go on from and what happened.
    #[allow(clippy::too_many_arguments)]
    fn restore(
        &self,
        saved: &mut [u8],
        saved_at_s: u32,
        off_s: f64,
        corrupt: bool,
        cool: bool,
        truth: &[f32],
        reading: u64,
    ) -> (S::State, SnapshotOutcome) {
        let amb = self.cfg.ambient_c as f32;
        let now_s = saved_at_s + off_s.round() as u32;
        if corrupt {
            let mid = saved.len() / 2;
            saved[mid] ^= 0x5a;
        }
        let max_age_s = self.cfg.max_snapshot_age_s;
        let off = cool.then_some(off_s as f32);
        let restored = self.subject.restore(saved, now_s, max_age_s, amb, off);
        let (state, error) = match restored {
            Ok(state) => (state, None),
            Err(e) => {
                // What the sensors read at the restart.
                let model = &self.cfg.sensor_model;
                let readings: Vec<Option<f32>> = truth
                    .iter()
                    .zip(&self.cfg.sensors)
                    .enumerate()
                    .map(|(j, (t, used))| {
                        used.then(|| read_sensor(&self.subject, model, *t, j, reading))
                    })
                    .collect();
                (self.subject.conservative_state(&readings, amb), Some(e))
            }
        };
        let outcome = SnapshotOutcome {
            refused: error.is_some(),
            error,
            starts_latched: self.subject.latched(&state),
        };
        (state, outcome)
    }

    fn run(&self, fault: Option<Injected>, restart: Restart) -> RunResult {
        let cfg = self.cfg;
        let amb = cfg.ambient_c;
        let subject = &self.subject;
        let mut state = subject.state(amb as f32);
        let mut plant = subject.plant();
        plant.reset(&vec![amb; plant.info().nodes.len()]);
        let boundary_c = vec![amb; plant.info().boundaries.len()];
        let sensor_nodes = subject.sensor_nodes();
        let sensors = sensor_nodes.len();
        let window = restart.off_window();
        let off_s = window.map_or(0.0, |(a, b)| b - a);
        let ticks = ((cfg.duration_s + off_s) / self.dt_s).round() as u64;
        let score_from_s = fault.map_or(0.0, |f| f.onset_s);
        let every = u64::from(cfg.reading_every.max(1));
        let zero_a = vec![0.0; subject.inputs()];
        let relin_every = (subject.refresh_s() / self.dt_s).round() as u64;
        let mut score = RunScore::default();
        let mut flag_s = None;
        let mut detectable_s = match fault.map(|f| f.class) {
            None | Some(FaultClass::Drift | FaultClass::Stuck | FaultClass::Dropout) => None,
            Some(_) => Some(0.0),
        };
        let mut snapshot = None;
        let mut saved: Option<(Vec<u8>, u32)> = None;
        let mut held: Option<Vec<f32>> = None;
        let model = &cfg.sensor_model;
        // Per sensor: its last healthy reading and when it was first read.
        let mut last_read: Vec<Option<(f32, f64)>> = vec![None; sensors];
        let mut faulty_readings = 0u64;
        let mut now_us = 0u32;
        for k in 0..ticks {
            let t_s = (k + 1) as f64 * self.dt_s;
            // Half a step of slack: the tick at the restart time saves the
            // snapshot, whatever the rounding of `t_s`.
            let half_dt = 0.5 * self.dt_s;
            let off = window.is_some_and(|(a, b)| t_s > a + half_dt && t_s <= b + half_dt);
            let currents: &[f64] = match (&cfg.trace, window) {
                _ if off => &zero_a,
                // After an off time the trace goes on where it stopped.
                (Some(trace), Some((_, back_s))) if t_s > back_s + half_dt => trace.at(t_s - off_s),
                (Some(trace), _) => trace.at(t_s),
                (None, _) => &cfg.currents_a,
            };
            plant.step(self.dt_s, currents, &boundary_c, &[]);
            now_us = now_us.wrapping_add(cfg.step_us);
            let plant_c = plant.temps_c();
            let truth: Vec<f32> = sensor_nodes.iter().map(|n| plant_c[*n] as f32).collect();
            if let Restart::Restore { corrupt, cool, .. } = restart {
                if off {
                    continue; // powered off: no tick
                }
                if let Some((bytes, at_s)) = saved.as_mut().filter(|_| snapshot.is_none()) {
                    let (s, outcome) =
                        self.restore(bytes, *at_s, off_s, corrupt, cool, &truth, k / every);
                    state = s;
                    if outcome.refused {
                        flag_s = Some(0.0);
                    }
                    snapshot = Some(outcome);
                }
            }
            // The number of the reading due at or last before this tick.
            let reading_no = k / every;
            let faulty = fault.filter(|f| t_s >= f.onset_s);
            if faulty.is_some() && held.is_none() {
                // What each sensor reads at the onset, repeated from then.
                held = Some(
                    truth
                        .iter()
                        .enumerate()
                        .map(|(j, t)| read_sensor(subject, model, *t, j, reading_no))
                        .collect(),
                );
            }
            let due = k % every == 0;
            if due && faulty.is_some() {
                faulty_readings += 1;
            }
            let mut readings = vec![None; sensors];
            for (j, slot) in readings.iter_mut().enumerate() {
                if !cfg.sensors[j] || !due {
                    continue;
                }
                let read = |value_c: f32| read_sensor(subject, model, value_c, j, reading_no);
                let mut result = Ok(read(truth[j]));
                let faulty_here = faulty.filter(|f| f.sensor.is_none_or(|s| s == j));
                if let Some(f) = faulty_here {
                    let since_s = t_s - f.onset_s;
                    result = match f.class {
                        FaultClass::Open => Err(SensorFault::OpenCircuit),
                        FaultClass::ShortGnd => Err(SensorFault::ShortToGnd),
                        FaultClass::ShortVcc => Err(SensorFault::ShortToVcc),
                        FaultClass::Stuck | FaultClass::AllStuck => {
                            Ok(held.as_ref().map_or(truth[j], |h| h[j]))
                        }
                        FaultClass::Drift => Ok(read(truth[j] + (DRIFT_K_PER_S * since_s) as f32)),
                        FaultClass::JumpUp => Ok(read(truth[j] + JUMP_K as f32)),
                        FaultClass::JumpDown => Ok(read(truth[j] - JUMP_K as f32)),
                        // The first faulty reading is a spike, then one in two.
                        FaultClass::Spikes if faulty_readings % 2 == 1 => {
                            Ok(read(truth[j] + JUMP_K as f32))
                        }
                        FaultClass::Dropout => {
                            // Detectable at the first reading it withholds.
                            detectable_s.get_or_insert(t_s - f.onset_s);
                            continue;
                        }
                        FaultClass::AllDetached => Ok(read(amb as f32)),
                        _ => result,
                    };
                } else if let Ok(value) = result {
                    // A healthy reading: the converter's error, and how
                    // long it has repeated its value.
                    let e = f64::from((value - truth[j]).abs());
                    score.max_reading_error_k = score.max_reading_error_k.max(e);
                    match last_read[j] {
                        Some((last, since)) if last.to_bits() == value.to_bits() => {
                            score.longest_repeat_s = score.longest_repeat_s.max(t_s - since);
                        }
                        _ => last_read[j] = Some((value, t_s)),
                    }
                }
                if let (Some(f), Ok(read), None) = (faulty, result, detectable_s) {
                    // A drift is judged by how far it has drifted, not by
                    // the sensor's noise on top (a winding resistance's is
                    // kelvins: its noise alone would make it "detectable").
                    let read = match f.class {
                        FaultClass::Drift => truth[j] + (DRIFT_K_PER_S * (t_s - f.onset_s)) as f32,
                        _ => read,
                    };
                    if f.sensor == Some(j) && self.detectable(f.class, j, read, truth[j]) {
                        detectable_s = Some(t_s - f.onset_s);
                    }
                }
                *slot = Some(TimedReading {
                    result: result.map(Reading::new),
                    sampled_at_us: now_us,
                });
            }
            let currents_a: Vec<f32> = match faulty.map(|f| f.class) {
                Some(FaultClass::HugeCurrent) => vec![HUGE_CURRENT_A; currents.len()],
                _ => currents.iter().map(|a| *a as f32).collect(),
            };
            let inputs = TickInputs {
                currents_a: &currents_a,
                ambient_c: amb as f32,
                readings: &readings,
                now_us,
                elapsed_us: match faulty.map(|f| f.class) {
                    Some(FaultClass::FrozenClock) => 0,
                    _ => cfg.step_us,
                },
            };
            let out = subject.tick(&mut state, &inputs);
            let task_dead = faulty.is_some_and(|f| f.class == FaultClass::RefreshStops);
            if relin_every > 0 && (k + 1) % relin_every == 0 && !task_dead {
                subject.relinearize(&mut state, &out.temps_c, amb);
            }
            if let (Restart::Restore { at_s, .. }, None) = (restart, &saved) {
                if t_s + 0.5 * self.dt_s >= at_s {
                    // The last snapshot before the power cut.
                    let now_s = t_s.round() as u32;
                    if let Some(bytes) = subject.save(&state, now_s) {
                        saved = Some((bytes, now_s));
                    }
                }
            }
            if let Some(f) = faulty {
                if flag_s.is_none() && Self::flagged(&f, &out) {
                    flag_s = Some(t_s - f.onset_s);
                }
            }
            if out.flags.contains(InputFlags::HEAT_BIAS_BEYOND_MODEL) {
                score.bias_alarm_ticks += 1;
            }
            for (j, status) in out.sensors.iter().enumerate() {
                let faulty_sensor = faulty.is_some_and(|f| f.sensor.is_none_or(|x| x == j));
                if readings[j].is_some() && !faulty_sensor && refused(status) {
                    score.healthy_flagged += 1;
                }
            }
            if t_s + 0.5 * self.dt_s >= score_from_s {
                let est = out.temps_c;
                for (j, node) in sensor_nodes.iter().enumerate() {
                    let e = (f64::from(est[*node]) - f64::from(truth[j])).abs();
                    score.max_error_tc_k = score.max_error_tc_k.max(e);
                }
                let hot = subject
                    .alarm_nodes()
                    .iter()
                    .copied()
                    .max_by(|a, b| plant_c[*a].total_cmp(&plant_c[*b]))
                    .unwrap_or(0);
                let e = (f64::from(est[hot]) - plant_c[hot]).abs();
                score.max_error_hot_spot_k = score.max_error_hot_spot_k.max(e);
            }
            if out.shutdown {
                score.shutdown_s = Some(t_s);
                break;
            }
        }
        RunResult {
            score,
            flag_s,
            detectable_s,
            snapshot,
        }
    }

    /// Whether a faulty `reading_c` of a `class` fault is one the observer
    /// can tell from the truth `truth_c` \[degC\] (see the module docs).
    fn detectable(&self, class: FaultClass, sensor: usize, reading_c: f32, truth_c: f32) -> bool {
        let s = self.subject.consistency();
        // The band of this sensor: a winding resistance's lies lower by
        // its noise (the library's resistance module, "Against the
        // physics").
        let offset_k = s.offset_k + self.subject.band_widening_k(sensor);
        let off_k = f64::from((reading_c - truth_c).abs());
        match class {
            FaultClass::Drift => {
                let rise_k = (f64::from(truth_c) - self.cfg.ambient_c).max(0.0);
                off_k > offset_k + s.fraction * rise_k
            }
            FaultClass::Stuck => off_k > s.stuck_threshold_k,
            _ => true,
        }
    }
}

/// Runs the whole matrix on the Omnimagnet.
///
/// # Errors
/// A configuration out of range, or an observer that does not build.
pub fn run(cfg: &FaultConfig) -> Result<FaultReport, FaultError> {
    check(cfg)?;
    run_on(cfg, OmniSubject::new(cfg)?)
}

/// Checks what does not depend on the subject.
fn check(cfg: &FaultConfig) -> Result<(), FaultError> {
    let bad = |m: &str| Err(FaultError::Invalid(m.to_string()));
    if !(cfg.duration_s.is_finite() && cfg.duration_s > 0.0) {
        return bad("--duration-s must be finite and > 0");
    }
    if cfg.step_us == 0 || cfg.reading_every == 0 {
        return bad("--step-us and the reading period must be > 0");
    }
    if !cfg.sensors.iter().any(|s| *s) {
        return bad("at least one sensor must be in use");
    }
    if cfg.currents_a.iter().any(|a| !a.is_finite()) {
        return bad("--current-a must be finite");
    }
    if let Some(trace) = &cfg.trace {
        if trace.time_s.is_empty() || trace.time_s.len() != trace.currents_a.len() {
            return bad("the trace has no rows");
        }
        if trace.currents_a.iter().flatten().any(|a| !a.is_finite()) {
            return bad("the trace has a current that is not finite");
        }
    }
    if cfg.onsets_s.iter().any(|t| !(t.is_finite() && *t >= 0.0)) {
        return bad("--onset-s must be finite and >= 0");
    }
    if cfg
        .relinearize_s
        .is_some_and(|r| !(r.is_finite() && r >= 0.0))
    {
        return bad("--relinearize-s must be finite and >= 0");
    }
    if !(cfg.off_s.is_finite() && cfg.off_s >= 0.0) {
        return bad("--off-s must be finite and >= 0");
    }
    let m = &cfg.sensor_model;
    if !(m.quantum_k.is_finite() && m.quantum_k >= 0.0) {
        return bad("--sensor-quantum-k must be finite and >= 0");
    }
    if !(m.noise_k.is_finite() && m.noise_k >= 0.0) {
        return bad("--sensor-noise-k must be finite and >= 0");
    }
    Ok(())
}

/// Runs the whole matrix on `subject`.
///
/// # Errors
/// Currents or sensors that do not fit the subject.
pub fn run_on<S: Subject>(cfg: &FaultConfig, subject: S) -> Result<FaultReport, FaultError> {
    check(cfg)?;
    let bad = |m: String| Err(FaultError::Invalid(m));
    let inputs = subject.inputs();
    if cfg.sensors.len() != subject.sensor_nodes().len() {
        return bad(format!(
            "{} sensor flags for {} sensors",
            cfg.sensors.len(),
            subject.sensor_nodes().len()
        ));
    }
    if cfg.trace.is_none() && cfg.currents_a.len() != inputs {
        return bad(format!(
            "{} currents for {inputs} inputs",
            cfg.currents_a.len()
        ));
    }
    if let Some(trace) = &cfg.trace {
        if trace.currents_a.iter().any(|row| row.len() != inputs) {
            return bad(format!("the trace needs {inputs} currents per row"));
        }
    }
    let harness = Harness::new(cfg, subject);
    let trace_name = cfg.trace.as_ref().map(|_| String::new());
    let clean = harness.run(None, Restart::None).score;
    let onsets_s = if cfg.onsets_s.is_empty() {
        // Half the clean shutdown time, on a tenth of a second.
        let half = (5.0 * clean.shutdown_s.unwrap_or(cfg.duration_s)).floor() / 10.0;
        let mut onsets = vec![60.0_f64.min(half), half];
        onsets.dedup();
        onsets
    } else {
        cfg.onsets_s.clone()
    };
    let refresh_s = harness.subject.refresh_s();
    let classes = if cfg.classes.is_empty() {
        // The refresh can stop only where there is one.
        FaultClass::ALL
            .into_iter()
            .filter(|c| *c != FaultClass::RefreshStops || refresh_s > 0.0)
            .collect()
    } else if cfg.classes.contains(&FaultClass::RefreshStops) && refresh_s <= 0.0 {
        return bad(
            "--classes refresh-stops needs a model refresh (--relinearize-s S, the Omnimagnet only)"
                .into(),
        );
    } else {
        cfg.classes.clone()
    };
    let sensors: Vec<usize> = (0..cfg.sensors.len()).filter(|j| cfg.sensors[*j]).collect();
    let stale_off_s = f64::from(cfg.max_snapshot_age_s) + 60.0;
    let mut references: Vec<((u64, u64), Option<f64>)> = Vec::new();
    let mut cases = Vec::new();
    for &class in classes.iter().filter(|c| !c.is_start()) {
        for &onset_s in &onsets_s {
            let targets: Vec<Option<usize>> = if class.per_sensor() {
                sensors.iter().map(|j| Some(*j)).collect()
            } else {
                vec![None]
            };
            for sensor in targets {
                let fault = Injected {
                    class,
                    sensor,
                    onset_s,
                };
                let (restart, off_s) = match class {
                    FaultClass::CorruptSnapshot => (true, 0.0),
                    FaultClass::StaleSnapshot => (true, stale_off_s),
                    FaultClass::PowerOff => (true, cfg.off_s),
                    _ => (false, 0.0),
                };
                let (run, reference) = if restart {
                    let key = (onset_s.to_bits(), off_s.to_bits());
                    let found = references.iter().find(|(k, _)| *k == key);
                    let reference = match found {
                        Some((_, r)) => *r,
                        None => {
                            let r = harness
                                .run(
                                    None,
                                    Restart::TickThrough {
                                        at_s: onset_s,
                                        off_s,
                                    },
                                )
                                .score
                                .shutdown_s;
                            references.push((key, r));
                            r
                        }
                    };
                    let run = harness.run(
                        Some(fault),
                        Restart::Restore {
                            at_s: onset_s,
                            off_s,
                            corrupt: class == FaultClass::CorruptSnapshot,
                            cool: class == FaultClass::PowerOff,
                        },
                    );
                    // A shutdown due while the device is off is due at the
                    // restart (the first tick after the off time) at the
                    // earliest.
                    let back_s = onset_s + off_s + harness.dt_s;
                    let reference = reference.map(|r| if r > onset_s { r.max(back_s) } else { r });
                    (run, reference)
                } else {
                    (harness.run(Some(fault), Restart::None), clean.shutdown_s)
                };
                cases.push(case_report(fault, run, reference));
            }
        }
    }
    cases.extend(harness.run_starts(&classes));
    let summary = summarise(&classes, &cases);
    Ok(FaultReport {
        schema_version: SCHEMA_VERSION,
        model: harness.subject.name(),
        currents_a: if cfg.trace.is_some() {
            Vec::new()
        } else {
            cfg.currents_a.clone()
        },
        duration_s: cfg.duration_s,
        trace: trace_name,
        step_us: cfg.step_us,
        reading_period_s: reading_period_s(cfg),
        sensors,
        onsets_s,
        relinearize_s: refresh_s,
        sensor_quantum_k: cfg.sensor_model.quantum_k,
        sensor_noise_k: cfg.sensor_model.noise_k,
        sensor_noise_seed: cfg.sensor_model.seed,
        stuck_tolerance_k: harness.subject.consistency().stuck_tolerance_k,
        bias_noise_w2_per_s: harness.subject.bias_noise_w2_per_s(),
        clean,
        cases,
        summary,
    })
}

fn case_report(fault: Injected, run: RunResult, reference: Option<f64>) -> CaseReport {
    let shutdown = run.score.shutdown_s;
    let delay = shutdown.zip(reference).map(|(s, r)| s - r);
    let unexpected = reference.is_none() && shutdown.is_some();
    let flag_goal_met = fault
        .class
        .flag_goal_s()
        .map(|goal| match run.detectable_s {
            None => true,
            Some(d) => run.flag_s.is_some_and(|f| f <= d + goal + 1e-9),
        });
    CaseReport {
        class: fault.class,
        sensor: fault.sensor,
        onset_s: fault.onset_s,
        flag_s: run.flag_s,
        detectable_s: run.detectable_s,
        flag_goal_met,
        score: run.score,
        reference_shutdown_s: reference,
        shutdown_delay_s: delay,
        lost_shutdown: reference.is_some() && shutdown.is_none(),
        late_shutdown: delay.is_some_and(|d| d > LATE_S),
        false_trip: unexpected && !fault.class.trips_by_design(),
        protective_trip: unexpected && fault.class.trips_by_design(),
        snapshot: run.snapshot,
        start: None,
    }
}

fn summarise(classes: &[FaultClass], cases: &[CaseReport]) -> Summary {
    let mut per_class = Vec::new();
    for &class in classes {
        let mine: Vec<&CaseReport> = cases.iter().filter(|c| c.class == class).collect();
        let max = |f: &dyn Fn(&CaseReport) -> Option<f64>| {
            mine.iter().filter_map(|c| f(c)).reduce(f64::max)
        };
        per_class.push(ClassSummary {
            class,
            cases: mine.len(),
            // A power-off restart is no fault: nothing to flag.
            unflagged: mine
                .iter()
                .filter(|c| {
                    c.flag_s.is_none() && c.class != FaultClass::PowerOff && !c.class.is_start()
                })
                .count(),
            worst_flag_s: max(&|c| c.flag_s),
            worst_flag_after_detectable_s: max(&|c| {
                c.flag_s.zip(c.detectable_s).map(|(f, d)| f - d)
            }),
            flag_goal_s: class.flag_goal_s(),
            worst_error_tc_k: max(&|c| Some(c.score.max_error_tc_k)).unwrap_or(0.0),
            worst_error_hot_spot_k: max(&|c| Some(c.score.max_error_hot_spot_k)).unwrap_or(0.0),
            worst_delay_s: max(&|c| c.shutdown_delay_s),
            lost: mine.iter().filter(|c| c.lost_shutdown).count(),
            late: mine.iter().filter(|c| c.late_shutdown).count(),
            false_trips: mine.iter().filter(|c| c.false_trip).count(),
            protective_trips: mine.iter().filter(|c| c.protective_trip).count(),
        });
    }
    let count = |f: &dyn Fn(&CaseReport) -> bool| cases.iter().filter(|c| f(c)).count();
    let lost = count(&|c| c.lost_shutdown);
    let late = count(&|c| c.late_shutdown);
    let false_spikes = count(&|c| c.false_trip && c.class == FaultClass::Spikes);
    let refused_not_latched = count(&|c| {
        c.snapshot
            .as_ref()
            .is_some_and(|s| s.refused && !s.starts_latched)
    });
    let mut goals = Vec::new();
    // Per class: the cases that missed the flag goal and the worst of them.
    let mut flag_misses = Vec::new();
    for &class in classes {
        if class.flag_goal_s().is_none() {
            continue;
        }
        let mine = cases.iter().filter(|c| c.class == class);
        let missed: Vec<&CaseReport> = mine.filter(|c| c.flag_goal_met == Some(false)).collect();
        if missed.is_empty() {
            continue;
        }
        let never = missed.iter().filter(|c| c.flag_s.is_none()).count();
        let worst = missed.iter().filter_map(|c| c.flag_s).reduce(f64::max);
        flag_misses.push(format!(
            "{} {}/{} (never {never}{})",
            class.name(),
            missed.len(),
            cases.iter().filter(|c| c.class == class).count(),
            worst.map_or(String::new(), |w| format!(", worst {w:.1} s"))
        ));
    }
    goals.push(Goal {
        goal: format!(
            "every single-sensor fault flagged within {FLAG_GOAL_S} s (stuck {STUCK_FLAG_GOAL_S} s) of becoming detectable"
        ),
        met: flag_misses.is_empty(),
        detail: if flag_misses.is_empty() {
            "all flagged in time".into()
        } else {
            format!("missed: {}", flag_misses.join("; "))
        },
    });
    let worst_err = cases
        .iter()
        .filter(|c| c.class.per_sensor())
        .map(|c| c.score.max_error_tc_k.max(c.score.max_error_hot_spot_k))
        .fold(0.0, f64::max);
    goals.push(Goal {
        goal: format!("single-sensor faults: estimate error within {ERROR_GOAL_K} K"),
        met: worst_err <= ERROR_GOAL_K,
        detail: format!("worst {worst_err:.2} K"),
    });
    goals.push(Goal {
        goal: "no lost shutdown".into(),
        met: lost == 0,
        detail: format!("{lost} lost"),
    });
    goals.push(Goal {
        goal: format!("no shutdown later than {LATE_S} s after the clean run's"),
        met: late == 0,
        detail: format!("{late} late"),
    });
    goals.push(Goal {
        goal: "no false shutdown under spike trains".into(),
        met: false_spikes == 0,
        detail: format!("{false_spikes} false"),
    });
    goals.push(Goal {
        goal: "every refused snapshot starts latched".into(),
        met: refused_not_latched == 0,
        detail: format!(
            "{} refused, {refused_not_latched} not latched",
            count(&|c| c.snapshot.as_ref().is_some_and(|s| s.refused))
        ),
    });
    goals.extend(start_goals(cases));
    Summary {
        classes: per_class,
        cases: cases.len(),
        lost_shutdowns: lost,
        late_shutdowns: late,
        false_trips: count(&|c| c.false_trip),
        false_trips_spikes: false_spikes,
        refused_not_latched,
        goals,
    }
}

/// The start classes' goals (issue 35), when any ran: the plant never
/// above its derated alarm limit, no healthy reading refused, the bound of
/// every limited node no sensor reads within [`UNDER_BOUND_GOAL_K`] of the
/// truth from the second correction period.
fn start_goals(cases: &[CaseReport]) -> Vec<Goal> {
    let starts: Vec<&StartScore> = cases.iter().filter_map(|c| c.start.as_ref()).collect();
    if starts.is_empty() {
        return Vec::new();
    }
    let over: Vec<f64> = starts.iter().map(|s| s.over_limit_k).collect();
    let over_runs = over.iter().filter(|o| **o > 0.0).count();
    let worst_over = over.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let refused: u32 = starts.iter().map(|s| s.refused).sum();
    let under = starts
        .iter()
        .filter_map(|s| s.under_bound_k)
        .reduce(f64::max);
    vec![
        Goal {
            goal: "starts: the plant never above its derated alarm limit (drive obeying the limits)"
                .into(),
            met: over_runs == 0,
            detail: format!(
                "{over_runs} of {} runs above; closest {worst_over:+.2} K",
                starts.len()
            ),
        },
        Goal {
            goal: "starts: no healthy reading refused after the restart".into(),
            met: refused == 0,
            detail: format!("{refused} refused"),
        },
        Goal {
            goal: format!(
                "starts: every unmeasured limited node's upper bound at most {UNDER_BOUND_GOAL_K} K below the truth from the second correction period"
            ),
            met: under.is_none_or(|u| u <= UNDER_BOUND_GOAL_K),
            detail: under.map_or("every limited node is read".into(), |u| {
                format!("worst {u:+.2} K (truth above the bound)")
            }),
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn class_names_round_trip() {
        for class in FaultClass::ALL {
            assert_eq!(FaultClass::parse(class.name()), Some(class));
            let json = serde_json::to_value(class).unwrap();
            assert_eq!(json, class.name());
        }
        assert_eq!(FaultClass::parse("melted"), None);
    }

    #[test]
    fn trace_currents_are_held_row_to_row() {
        let trace = CurrentTrace {
            time_s: vec![0.0, 10.0, 20.0],
            currents_a: vec![vec![1.0; 3], vec![2.0; 3], vec![3.0; 3]],
        };
        for (t_s, a) in [
            (-1.0, 1.0),
            (0.0, 1.0),
            (9.99, 1.0),
            (10.0, 2.0),
            (1e6, 3.0),
        ] {
            assert_eq!(trace.at(t_s), [a; 3].as_slice(), "at {t_s} s");
        }
    }

    #[test]
    fn the_sensor_model_rounds_to_its_quantum_and_its_noise_is_seeded() {
        let q = SensorModel {
            quantum_k: 0.25,
            ..SensorModel::EXACT
        };
        for (t, read) in [(22.0, 22.0), (22.124, 22.0), (22.126, 22.25), (-0.3, -0.25)] {
            assert_eq!(q.read(t, 0, 0), read, "{t}");
        }
        assert_eq!(SensorModel::EXACT.read(22.123, 3, 9), 22.123);
        let noisy = SensorModel { noise_k: 0.1, ..q };
        let n = 20_000u64;
        let draws: Vec<f64> = (0..n).map(|k| 0.1 * gaussian(noisy.seed, 1, k)).collect();
        let mean = draws.iter().sum::<f64>() / n as f64;
        let sd = (draws.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert!(
            mean.abs() < 0.003 && (sd - 0.1).abs() < 0.003,
            "{mean} {sd}"
        );
        // Reproducible, on the grid, and not the same for every sensor.
        for k in 0..100 {
            let r = noisy.read(40.1, 2, k);
            assert_eq!(r, noisy.read(40.1, 2, k));
            assert_eq!(r % 0.25, 0.0, "{r}");
        }
        assert!((0..100).any(|k| noisy.read(40.1, 0, k) != noisy.read(40.1, 1, k)));
    }

    #[test]
    fn bad_configurations_are_refused() {
        for cfg in [
            FaultConfig {
                duration_s: 0.0,
                ..FaultConfig::default()
            },
            FaultConfig {
                sensors: vec![false; THERMOCOUPLES],
                ..FaultConfig::default()
            },
            FaultConfig {
                onsets_s: vec![f64::NAN],
                ..FaultConfig::default()
            },
            FaultConfig {
                relinearize_s: Some(f64::NAN),
                ..FaultConfig::default()
            },
            FaultConfig {
                sensor_model: SensorModel {
                    quantum_k: -0.25,
                    ..SensorModel::default()
                },
                ..FaultConfig::default()
            },
            FaultConfig {
                sensor_model: SensorModel {
                    noise_k: f64::INFINITY,
                    ..SensorModel::default()
                },
                ..FaultConfig::default()
            },
        ] {
            assert!(matches!(run(&cfg), Err(FaultError::Invalid(_))), "{cfg:?}");
        }
    }
}
