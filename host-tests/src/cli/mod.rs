//! The `coil-thermal` command line: argument definitions and dispatch.
//!
//! Every subcommand lives in its own module and returns `anyhow::Result`;
//! [`main_entry`] prints the error chain to stderr and exits non-zero.
//! Summaries go to stdout, as text or (with `--json`) as one JSON object.

// The argument docs are also the `--help` text, where units read `[s]`,
// `[degC]`: not intra-doc links.
#![allow(rustdoc::broken_intra_doc_links)]

mod bench_cmd;
mod calibrate_cmd;
mod codegen_cmd;
mod common;
mod faults_cmd;
mod limits_cmd;
mod plot_cmd;
mod replay_cmd;
mod simulate_cmd;

use std::path::PathBuf;
use std::process::ExitCode;

use crate::calibrate::Weighting;
use clap::{Args, Parser, Subcommand, ValueEnum};

pub use common::{ModelSpec, NOT_YET};

/// Thermal models of electromagnetic actuators: simulate, replay recorded
/// traces, calibrate parameters, time the hot path and plot.
///
/// Units: temperatures in degC, currents in A, times in s, powers in W,
/// capacities in J/K, conductances in W/K. Trace files are CSV with a header
/// row; model files are TOML (see host-tests/MODEL_FORMAT.md).
#[derive(Debug, Parser)]
#[command(name = "coil-thermal", version, propagate_version = true)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Simulate a model under constant currents or a current trace; write
    /// `time_s` then one column per node [degC].
    Simulate(SimulateArgs),
    /// Run the observer (model, filter, protection) over a recorded trace and
    /// score it against held-out sensors.
    Replay(Box<ReplayArgs>),
    /// Time to limit of each element, maximum safe currents (for a horizon and
    /// for ever) and runaway currents; `--study` for the Omnimagnet's table.
    Limits(LimitsArgs),
    /// Print the derated alarm limit: T_amb + (T_crit - T_amb) * product of
    /// the derating factors.
    AlarmLimit(AlarmLimitArgs),
    /// Fit model parameters to one or more traces by bounded
    /// Levenberg-Marquardt; write the fitted model file.
    Calibrate(CalibrateArgs),
    /// Per-step times of the hot-path steppers against the 0.1 ms budget.
    Bench(BenchArgs),
    /// Plot estimated vs measured temperatures and currents (PNG or SVG).
    Plot(PlotArgs),
    /// Write a `no_std` Rust module holding a model's firmware observer,
    /// solved on this host, as `const` data (the MCU computes no exponential
    /// and no Riccati solution).
    ///
    /// For a model file, the tables are solved by the coil-thermal library
    /// itself at the model's own sizes: codegen writes a small generator
    /// program, compiles it against the library with cargo and runs it. So
    /// it needs cargo (on PATH, or $CARGO) and the coil-thermal library's
    /// source on this host (by default the tree this tool was built from;
    /// --library DIR for another). The first run compiles the library and
    /// its dependencies (measured: about 20 s to a minute on a 2-core host
    /// with the dependencies downloaded; more if cargo must download them),
    /// kept for later runs (about 2 s) in $CARGO_TARGET_DIR/coil-thermal-codegen,
    /// else $XDG_CACHE_HOME/coil-thermal/codegen, else
    /// ~/.cache/coil-thermal/codegen (--target-dir DIR: DIR/coil-thermal-codegen).
    /// `--device` needs neither: its sizes are built into this tool.
    Codegen(codegen_cmd::CodegenArgs),
    /// The fault campaign: every fault class x every sensor x several
    /// onsets against the clean run (time to flag, estimate error, shutdown
    /// delay, false trips), each figure against its goal.
    Faults(faults_cmd::FaultsArgs),
}

/// A time window of a run's output: the model runs from the start (so
/// its state is right), only the written rows, the scores and the summary
/// are limited to the window.
#[derive(Debug, Clone, Default, Args)]
pub struct WindowArgs {
    /// Write and score from this time on [s] (the run still starts at the
    /// trace's first row).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub from_s: Option<f64>,
    /// Write and score up to this time [s].
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub to_s: Option<f64>,
}

/// Which model to run.
#[derive(Debug, Clone, Args)]
pub struct ModelArgs {
    /// Model: `hppa` (the HPPA coil grid, one node per coil), `omnimagnet`
    /// (the paper's 16-node model: nonlinear RK4 in `simulate`/`replay`,
    /// linearised at the ambient in `limits`/`calibrate`), `solenoid`
    /// (layered HeSE coil), or a model file path (TOML).
    #[arg(long, value_name = "hppa|omnimagnet|solenoid|FILE")]
    pub model: String,
    /// Number of winding layers of `--model solenoid` (1..=64; the outer
    /// surface is water cooled from 16 layers on).
    #[arg(long, value_name = "N", default_value_t = 30)]
    pub layers: usize,
    /// HPPA grid rows (`--model hppa`; default 7). Built-in sizes (rows x
    /// cols): 7x12, 12x7, 6x12, 12x6, 4x4, 3x4, 3x3, 2x3.
    #[arg(long, value_name = "R")]
    pub rows: Option<usize>,
    /// HPPA grid columns (`--model hppa`; default 12).
    #[arg(long, value_name = "C")]
    pub cols: Option<usize>,
    /// HPPA parameter set (`--model hppa`): `fdm-fitted` (report Table 7's
    /// resistances with the 56.4 J/K capacity of its other fits, the
    /// default), `calculated`, `stepwise-fit`, `global-fit`.
    #[arg(long, value_name = "SET")]
    pub grid_params: Option<String>,
    /// A sensor with a first-order lag of TAU [s] on NODE: adds node
    /// `NODE_lag` (1e-4 of NODE's capacity [J/K], linked to NODE
    /// only, by capacity / TAU [W/K]) to measure with `COL=NODE_lag`;
    /// `calibrate` fits the lag as `conductance.NODE-NODE_lag`. Repeatable.
    #[arg(long = "sensor-lag", value_name = "NODE=TAU_S")]
    pub sensor_lags: Vec<String>,
}

/// How trace columns feed the model.
#[derive(Debug, Clone, Args, Default)]
pub struct TraceArgs {
    /// Sample period [s] for traces without a `time_s` column (row k is at
    /// k * period).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    pub sample_period_s: Option<f64>,
    /// The trace's time column [s] (default `time_s`), e.g. `--time-column
    /// time` for a recording's own `time,temperature` header.
    #[arg(long, value_name = "NAME")]
    pub time_column: Option<String>,
    /// Current input from a trace column or expression [A]: `COL=INPUT`,
    /// e.g. `i_coil=current` or `hypot(IdFbk,IqFbk)=current` (also `abs(C)`,
    /// `scale(C,K)`), or a step profile `T:A,T:A,...` held from each time
    /// [s] (`0:16.37,40:0=coil`: 16.37 A from 0 s, off from 40 s). Default:
    /// the source's `column`, else the input's name.
    #[arg(long = "current", value_name = "EXPR=INPUT")]
    pub currents: Vec<String>,
    /// Boundary temperature from a trace column [degC]: `COL=BOUNDARY`.
    /// Default: the boundary's `column`, else its name, else its `value_c`.
    #[arg(long = "boundary", value_name = "EXPR=BOUNDARY")]
    pub boundaries: Vec<String>,
    /// A constant for a column the trace lacks (in the column's unit), e.g.
    /// `speed=1500` [rpm] for a speed-dependent source, or a step profile
    /// `T:V,T:V,...` (each value from its time [s] on).
    #[arg(long = "const", value_name = "COL=VALUE")]
    pub constants: Vec<String>,
    /// Multiplies every current input by K (dimensionless, >= 0): the same
    /// trajectory at a harder or lighter duty (power goes with K^2).
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    pub current_scale: Option<f64>,
}

/// HPPA grid drive patterns: the report's four calibration patterns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Pattern {
    /// Every coil driven.
    All,
    /// The middle row (`rows / 2`) driven.
    Row,
    /// The middle line (column `(cols - 1) / 2`) driven.
    Line,
    /// The centre coil (middle row, middle line) driven.
    OneCoil,
}

impl Pattern {
    /// Stable name.
    pub fn name(self) -> &'static str {
        match self {
            Self::All => "all",
            Self::Row => "row",
            Self::Line => "line",
            Self::OneCoil => "one-coil",
        }
    }
}

/// `simulate` arguments.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Constant current per input [A]: one value for every input, or one per
    /// input in model order (`3,3,3`). Not with --trace.
    #[arg(
        long,
        value_name = "A[,A...]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    current_a: Vec<f64>,
    /// Input trace (CSV) instead of constant currents.
    #[arg(long, value_name = "IN.csv", conflicts_with_all = ["current_a", "duration_s"])]
    trace: Option<PathBuf>,
    /// Duration with constant currents [s] (>= 0).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    duration_s: Option<f64>,
    /// Output sample period with constant currents [s] (> 0; the model
    /// sub-steps internally as stability requires).
    #[arg(
        long,
        value_name = "S",
        default_value_t = 1.0,
        allow_negative_numbers = true
    )]
    dt_s: f64,
    /// Ambient: the temperature of every boundary with constant currents
    /// [degC] (default: each boundary's `value_c`).
    #[arg(long, value_name = "C", allow_negative_numbers = true)]
    ambient_c: Option<f64>,
    /// HPPA grid drive pattern (`--model hppa`): every driven coil at
    /// `--current-a` (default 0.7 A) for `--duration-s` (default 1800 s).
    #[arg(long, value_enum, conflicts_with = "trace")]
    pattern: Option<Pattern>,
    /// Omnimagnet preset (`--model omnimagnet`): `all-three` (3.8 A),
    /// `solenoid-1` (3.13 A), `solenoids-2-3` (3.04 A), `cooling` (from the
    /// end of all-three), `rotating-dipole` (3.8 A peak, 5 Hz); duration
    /// `--duration-s` (default 7200 s).
    #[arg(long, value_name = "PRESET", conflicts_with_all = ["trace", "current_a"])]
    preset: Option<String>,
    /// With --trace: output every S seconds [s] (inputs held between trace
    /// rows), instead of at the trace's rows.
    #[arg(
        long,
        value_name = "S",
        requires = "trace",
        allow_negative_numbers = true
    )]
    resample_s: Option<f64>,
    /// Add seeded Gaussian noise of this standard deviation [K] to the
    /// written temperatures (synthetic measurements).
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    noise_k: Option<f64>,
    /// Seed of --noise-k.
    #[arg(long, value_name = "SEED", default_value_t = 1)]
    seed: u64,
    /// Also write the input columns (currents [A], boundaries [degC]) after
    /// the node columns, so the output is a complete trace for `replay` or
    /// `calibrate`.
    #[arg(long)]
    with_inputs: bool,
    #[command(flatten)]
    trace_args: TraceArgs,
    #[command(flatten)]
    window: WindowArgs,
    /// Output CSV: `time_s` [s] then one column per node [degC].
    #[arg(long, value_name = "OUT.csv")]
    out: PathBuf,
    /// Also plot the run (`.png` or `.svg`).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Write the model actually run as a model file (e.g. the solenoid's).
    #[arg(long, value_name = "MODEL.toml")]
    write_model: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

/// `replay` arguments.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    #[command(flatten)]
    model: ModelArgs,
    #[command(flatten)]
    window: WindowArgs,
    /// Recorded trace (CSV) with inputs and measured temperatures.
    #[arg(long, value_name = "IN.csv")]
    trace: PathBuf,
    #[command(flatten)]
    trace_args: TraceArgs,
    /// A fused sensor: `COL=NODE` [degC], or a comma list of them; an
    /// empty or `NaN` cell is a missing reading. Repeatable (at most 4). The
    /// library's `NetworkObserver` ticks every `--tick-us` and fuses each
    /// row's reading as a thermocouple of NODE (steady-state gain for the
    /// firmware's correction period; heat-input biases as the firmware: see
    /// --bias-noise-w2-per-s). With `--model omnimagnet` the flashed
    /// `OmniObserver` fuses them: up to its six thermocouples, two on each
    /// solenoid node.
    #[arg(long = "measure", value_name = "COL=NODE")]
    measure: Vec<String>,
    /// The firmware observer's tick and model step [us]: the trace's rows
    /// are replayed in ticks of this length, each timed. Default: the model
    /// file's `[observer] step_us` (1000); another value is an override,
    /// named in the output.
    #[arg(long, value_name = "US")]
    tick_us: Option<u32>,
    /// The library observer's heat-input bias noise [W^2/s] with --measure:
    /// overrides the model file's `[observer] bias_noise_w2_per_s`
    /// (default: the file's, else 1e-3, as `codegen` builds the firmware).
    /// 0 freezes the biases (temperatures corrected, no heat estimated),
    /// for sensors that cannot see every source's bias.
    #[arg(long, value_name = "W2_PER_S", allow_negative_numbers = true)]
    bias_noise_w2_per_s: Option<f64>,
    /// Fusion: process noise of every temperature state [K^2/s] (white heat
    /// flow; per step `Q = q dt`). Default: the model file's `[observer]
    /// node_noise_k2_per_s`, else the library's 1e-4, which the firmware
    /// runs; another value is an override, named in the output.
    #[arg(long, value_name = "K2_PER_S", allow_negative_numbers = true)]
    process_noise_k2_per_s: Option<f64>,
    /// Fusion: standard deviation of every fused sensor [K]. Default: the
    /// model file's `[observer] sensor_sigma_k` (the noise `codegen` builds
    /// the firmware with), else codegen's 0.25.
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    measurement_noise_k: Option<f64>,
    /// A held-out sensor, only scored: `COL=NODE` [degC], or a comma list;
    /// rows with an empty or `NaN` cell are not scored. A column also
    /// fused by --measure is refused (its score would not be held out).
    #[arg(long = "truth", value_name = "COL=NODE")]
    truth: Vec<String>,
    /// A column that only sets a node's initial temperature (with
    /// `[initial] policy = "measured"`): `COL=NODE` [degC], or a comma
    /// list (the first reading of each).
    #[arg(long = "init", value_name = "COL=NODE")]
    init: Vec<String>,
    /// Alarm: derating factors, each in (0, 1] (dimensionless): alarm limit
    /// = ambient + (critical - ambient) * product, the shutdown level.
    /// Default: the firmware's, the model file's `[observer] derating` (else
    /// codegen's 0.648); the HPPA rule (0.875,0.9,0.9,0.8) for hppa, the
    /// Omnimagnet rule (0.9,0.9,0.8) for omnimagnet. Given, it is an
    /// override of the firmware's, named in the output.
    #[arg(
        long,
        value_name = "a,b,...",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    factors: Vec<f64>,
    /// Alarm: one critical temperature for every node [degC], instead of
    /// the model's (`critical_c` per node in a model file; 100 degC per
    /// coil for hppa; 120 degC cover and 240 degC wire insulation for
    /// omnimagnet). Nodes without one are not watched.
    #[arg(long, value_name = "C", allow_negative_numbers = true)]
    critical_c: Option<f64>,
    /// Host alarm (open loop on the explicit stepper only; refused with the
    /// firmware's observer, whose own alarm runs): the warning rises
    /// this far below the alarm limit [K] (default 5).
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    warning_margin_k: Option<f64>,
    /// Host alarm only: hysteresis below the warning level that clears a
    /// warning (and below the alarm limit that allows a reset) [K] (default 2).
    #[arg(long, value_name = "K", allow_negative_numbers = true)]
    hysteresis_k: Option<f64>,
    /// Host alarm only (default 3 s): evidence (net, up/down counter) to raise or clear an alarm,
    /// in seconds of trace [s]: the rows it spans at the trace's median row
    /// spacing, at least 1 (a sparse trace alarms on its first row beyond
    /// the level).
    #[arg(
        long,
        value_name = "S",
        allow_negative_numbers = true,
        conflicts_with = "debounce_rows"
    )]
    debounce_s: Option<f64>,
    /// Host alarm only: the debounce in trace rows instead of --debounce-s; 1 raises
    /// on the first row beyond the level.
    #[arg(long, value_name = "ROWS")]
    debounce_rows: Option<u16>,
    /// Host alarm only (default 60 s): the predictive alarm rises when a watched node's predicted
    /// time to its alarm limit, with the row's currents and boundaries held,
    /// falls below this horizon [s] (and clears 10 s above it).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    horizon_s: Option<f64>,
    /// Host alarm only: the boundary whose temperature is the measured ambient of the
    /// derating rule. Default: the boundary named `ambient`, else the first.
    #[arg(long, value_name = "BOUNDARY")]
    ambient_boundary: Option<String>,
    /// Fuse the --measure sensors up to this time [s] only, then predict
    /// open loop (the score of --truth after it is the prediction's).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    measure_until_s: Option<f64>,
    /// The --measure columns of the model file's ADC sensors (an
    /// `[observer] sensors` entry of kind ntc, kty83, kty84, pt100 or
    /// pt1000) hold raw ADC counts, converted by the library's conversion
    /// the generated module's `convert_counts` calls: a count that is a
    /// fault (open, short, out of range) is no reading, reported, never a
    /// temperature. Refused when no --measure column is of such a sensor.
    #[arg(long)]
    raw_counts: bool,
    /// Output CSV: `time_s` [s] then the estimate of every node [degC]
    /// (optional: without it only the summary is printed).
    #[arg(long, value_name = "OUT.csv")]
    out: Option<PathBuf>,
    /// Also plot estimated vs measured (`.png` or `.svg`).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

/// `limits` arguments.
#[derive(Debug, Args)]
pub struct LimitsArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// Constant current per input [A], held from equilibrium at the ambient:
    /// one value for every input or one per input (`3.8,3.8,3.8`). With
    /// --pattern: the driven coils' current (default 0.7 A). With --study:
    /// the currents of the max-safe-time table (default 2,5,10,20,50).
    #[arg(
        long,
        value_name = "A[,A...]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    current_a: Vec<f64>,
    /// HPPA grid drive pattern (`--model hppa`) instead of --current-a for
    /// every coil.
    #[arg(long, value_enum)]
    pattern: Option<Pattern>,
    /// Horizon of the maximum safe current [s] (> 0); the answer for ever is
    /// always given too.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    horizon_s: Option<f64>,
    /// Temperature of every boundary (ambient, coolant) [degC]; default:
    /// each boundary's `value_c` (20 degC for hppa and omnimagnet).
    #[arg(long, value_name = "C", allow_negative_numbers = true)]
    ambient_c: Option<f64>,
    /// Derating factors for the element limits, each in (0, 1]
    /// (dimensionless): limit = ambient + (critical - ambient) * product.
    /// Default: the HPPA rule (0.875,0.9,0.9,0.8) for hppa, the Omnimagnet
    /// rule (0.9,0.9,0.8) for omnimagnet, the firmware's for a model file
    /// (its `[observer] derating`, else codegen's 0.648).
    #[arg(
        long,
        value_name = "a,b,...",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    factors: Vec<f64>,
    /// One limit for every element [degC], instead of the derated critical
    /// temperatures (with --study: for the three solenoid nodes; default
    /// there 115 degC, the experiments' stop temperature).
    #[arg(long, value_name = "C", allow_negative_numbers = true)]
    limit_c: Option<f64>,
    /// Per-coil figures (max current, runaway current) for this input only;
    /// repeatable. Default: every driven input, at most 16.
    #[arg(long = "coil", value_name = "INPUT")]
    coils: Vec<String>,
    /// The Omnimagnet study (`--model omnimagnet`): max safe time of each of
    /// the seven combinations of powered solenoids at each --current-a, and
    /// the max safe current for each --time-s.
    #[arg(long)]
    study: bool,
    /// Run times for the study's max safe current [s] (> 0).
    #[arg(
        long,
        value_name = "S[,S...]",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    time_s: Vec<f64>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

/// `alarm-limit` arguments.
#[derive(Debug, Args)]
pub struct AlarmLimitArgs {
    /// Critical temperature of the element's material [degC].
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    critical_c: f64,
    /// Measured ambient temperature [degC].
    #[arg(long, value_name = "T", allow_negative_numbers = true)]
    ambient_c: f64,
    /// Derating factors, each in (0, 1] (dimensionless; at most 8). Default:
    /// the HPPA report's magnet plate 0.875, model error 0.9, unknown
    /// conditions 0.9, safety 0.8.
    #[arg(
        long,
        value_name = "a,b,c,d",
        value_delimiter = ',',
        allow_negative_numbers = true
    )]
    factors: Vec<f64>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

/// `calibrate` arguments.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    model: ModelArgs,
    /// A trace to fit (CSV); repeat for several.
    #[arg(long = "trace", value_name = "IN.csv", required = true)]
    traces: Vec<PathBuf>,
    #[command(flatten)]
    trace_args: TraceArgs,
    /// A measured column the fit matches: `COL=NODE` [degC], or a comma
    /// list of them; repeatable.
    #[arg(long = "measure", value_name = "COL=NODE", required = true)]
    measure: Vec<String>,
    /// A constant or step profile for one trace only: `K:COL=VALUE`, K the
    /// trace's 1-based position counting every --trace, then every
    /// --validate (e.g. `2:ambient=23.4` [degC], `1:current=0:16.37,40:0`
    /// [A]); it wins over --const for that trace. Repeatable.
    #[arg(long = "trace-const", value_name = "K:COL=VALUE")]
    trace_const: Vec<String>,
    /// A held-out trace (CSV), not fitted: the fitted model is run over it
    /// open loop and scored on the --measure columns (RMSE [K]); repeat for
    /// several.
    #[arg(long = "validate", value_name = "IN.csv")]
    validate: Vec<PathBuf>,
    /// A column that only sets a node's initial temperature (with
    /// `[initial] policy = "measured"`), not fitted: `COL=NODE` [degC];
    /// repeatable.
    #[arg(long = "init", value_name = "COL=NODE")]
    init: Vec<String>,
    /// Parameters to fit, comma separated, each `NAME` or `NAME=LO:HI`:
    /// `capacity.NODE` [J/K], `conductance.NAME` [W/K] (`.factor`,
    /// `.h_w_per_m2k` [W/(m^2 K)]), `source.NAME.r0_ohm` [ohm] (`.alpha_per_k`
    /// [1/K], `.slope_ohm_per_k` [ohm/K], `.r_at_0c_ohm` [ohm], `.scale`,
    /// `.speed_a1`, `.speed_a2`), `fixed_power.NODE` [W], `speed_loss.NAME.p1_w` (`.p2_w`) [W]; for `--model hppa`
    /// `grid.rx_k_per_w`, `grid.ry_k_per_w` [K/W] (between two coils: half
    /// the report's per-element values), `grid.rz_k_per_w` [K/W],
    /// `grid.capacity_j_per_k` [J/K]. Default bounds: a factor 10 around
    /// positive values.
    #[arg(
        long,
        value_name = "NAME[=LO:HI],...",
        value_delimiter = ',',
        required = true
    )]
    params: Vec<String>,
    /// Iteration limit of Levenberg-Marquardt.
    #[arg(long, value_name = "N", default_value_t = 100)]
    max_iterations: usize,
    /// Multi-start: fit from N starting points (the model's values, then
    /// N-1 seeded points log-uniform within each parameter's bounds, the
    /// bounds fixed for all) and keep the lowest cost. Starts that reach
    /// the best cost with different parameters are reported as a trade-off.
    #[arg(long, value_name = "N", default_value_t = 1)]
    starts: usize,
    /// Seed of the --starts points.
    #[arg(long, value_name = "SEED", default_value_t = 1)]
    starts_seed: u64,
    /// Fit every STRIDE-th row only (faster on long traces).
    #[arg(long, value_name = "STRIDE", default_value_t = 1)]
    stride: usize,
    /// How the traces share the fit: `rows` (every reading weighs the same,
    /// so a long trace dominates; least squares over all rows, the
    /// default) or `traces` (every trace weighs the same in total: each
    /// residual scaled by 1/sqrt(readings of its trace)). The standard
    /// errors and correlations use the same weights.
    #[arg(long, value_enum, value_name = "rows|traces", default_value_t = Weighting::Rows)]
    weighting: Weighting,
    /// A relative weight for one fitted trace: `K:W`, K its 1-based
    /// --trace position, W finite and > 0 (dimensionless, multiplies the
    /// --weighting); repeatable.
    #[arg(long, value_name = "K:W")]
    weight: Vec<String>,
    /// Where to write the fitted model file (TOML).
    #[arg(long, value_name = "FITTED.toml")]
    out: PathBuf,
    /// Also draw the fit report (`.png` or `.svg`): per trace, the fitted
    /// model against each measured column and the residuals [K]; with
    /// several traces, one figure each, numbered `NAME-1.png`, ...
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    no_progress: bool,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

/// `bench` arguments.
#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Least wall-clock time per measurement run [ms].
    #[arg(long, value_name = "MS", default_value_t = 40)]
    min_time_ms: u64,
    /// Runs per measurement (the median is reported).
    #[arg(long, value_name = "N", default_value_t = 5)]
    repeats: usize,
    /// Print one JSON object: one key per measured step in ns, e.g.
    /// `network_16_f32_ns`.
    #[arg(long)]
    json: bool,
}

/// `plot` arguments.
#[derive(Debug, Args)]
pub struct PlotArgs {
    /// Estimated temperatures: a CSV written by `simulate` or `replay`
    /// (`time_s` [s], then nodes [degC]).
    #[arg(long, value_name = "EST.csv")]
    estimate: PathBuf,
    /// Only these estimated columns (default: all).
    #[arg(long = "node", value_name = "NODE")]
    nodes: Vec<String>,
    /// Recorded trace with measured temperatures and currents (CSV).
    #[arg(long, value_name = "IN.csv")]
    trace: Option<PathBuf>,
    /// Sample period [s] of a trace without `time_s`.
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    sample_period_s: Option<f64>,
    /// The trace's time column [s] (default `time_s`).
    #[arg(long, value_name = "NAME")]
    time_column: Option<String>,
    /// A measured column drawn against a node: `COL=NODE` [degC].
    #[arg(long = "measure", value_name = "COL=NODE")]
    measure: Vec<String>,
    /// A current column or expression of the trace for the lower panel [A].
    #[arg(long = "current", value_name = "EXPR")]
    currents: Vec<String>,
    /// A horizontal limit line: `LABEL=VALUE` [degC].
    #[arg(long = "limit-c", value_name = "LABEL=C")]
    limits: Vec<String>,
    /// An alarm marker at this time [s]; repeatable.
    #[arg(long = "alarm-s", value_name = "S")]
    alarms: Vec<f64>,
    /// Output image (`.png` or `.svg`).
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Image width [px].
    #[arg(long, value_name = "PX", default_value_t = 1200)]
    width: u32,
    /// Image height [px].
    #[arg(long, value_name = "PX", default_value_t = 800)]
    height: u32,
    /// Title (default: the estimate file's name).
    #[arg(long)]
    title: Option<String>,
    /// Draw from this time on [s] (a time window with --to-s).
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    from_s: Option<f64>,
    /// Draw up to this time [s].
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    to_s: Option<f64>,
    /// Print the summary as one JSON object.
    #[arg(long)]
    json: bool,
}

/// Exits quietly (status 0) when stdout is a closed pipe, as in
/// `coil-thermal calibrate ... | head -1`: the reader wanted no more.
/// Every other panic keeps the default report.
fn exit_quietly_on_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let msg = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.contains("failed printing to stdout") && msg.contains("Broken pipe") {
            std::process::exit(0);
        }
        default(info);
    }));
}

/// Runs the tool with the process arguments; the exit code to return.
pub fn main_entry() -> ExitCode {
    exit_quietly_on_broken_pipe();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(a) => simulate_cmd::run(a),
        Command::Replay(a) => replay_cmd::run(*a),
        Command::Limits(a) => limits_cmd::limits(a),
        Command::AlarmLimit(a) => limits_cmd::alarm_limit(a),
        Command::Calibrate(a) => calibrate_cmd::run(a),
        Command::Bench(a) => bench_cmd::run(a),
        Command::Plot(a) => plot_cmd::run(a),
        Command::Codegen(a) => codegen_cmd::run(a),
        Command::Faults(a) => faults_cmd::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
