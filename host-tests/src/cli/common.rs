//! What the subcommands share: model dispatch, flag parsing, sensors.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use coil_thermal::protect::derating::{DeratingFactor, DeratingRule};
use coil_thermal::SolenoidParams;

use super::{ModelArgs, TraceArgs};
use crate::devices;
use crate::model_file::{Model, ModelFile};
use crate::observer::Sensor;
use crate::plot::PlotData;
use crate::sim::{Bindings, FilePlant, Plant, PlantInfo, TraceDrive};
use crate::trace::{ColumnExpr, TimeSource, Trace, TraceFile};

/// Marker text of every "not yet available" error (tests look for it).
pub const NOT_YET: &str = "not yet available";

/// The model named by `--model`.
#[derive(Debug, Clone, PartialEq)]
pub enum ModelSpec {
    /// The HPPA coil grid (`src/grid`), as a model file.
    Hppa,
    /// The Omnimagnet (`src/omnimagnet`), nonlinear.
    Omnimagnet,
    /// The layered solenoid of `coil_thermal::solenoid`.
    Solenoid,
    /// A model file.
    File(PathBuf),
}

impl ModelSpec {
    /// Parses `--model`: a built-in name or an existing file.
    pub fn parse(text: &str) -> Result<Self> {
        Ok(match text {
            "hppa" => Self::Hppa,
            "omnimagnet" => Self::Omnimagnet,
            "solenoid" => Self::Solenoid,
            path => {
                let p = PathBuf::from(path);
                if !p.is_file() {
                    bail!(
                        "unknown model `{path}`: not one of hppa, omnimagnet, solenoid, and no such model file"
                    );
                }
                Self::File(p)
            }
        })
    }
}

/// Names of the derating factors given on the command line (the HPPA
/// report's meaning when there are four).
const FACTOR_NAMES: [&str; 8] = [
    "factor_1", "factor_2", "factor_3", "factor_4", "factor_5", "factor_6", "factor_7", "factor_8",
];

/// The derating rule from `--factors`, or `default`.
pub fn derating_rule(factors: &[f64], default: DeratingRule) -> Result<DeratingRule> {
    if factors.is_empty() {
        return Ok(default);
    }
    if factors.len() > FACTOR_NAMES.len() {
        bail!(
            "--factors: at most {} factors, got {}",
            FACTOR_NAMES.len(),
            factors.len()
        );
    }
    if let Some((k, v)) = factors
        .iter()
        .enumerate()
        .find(|(_, v)| !(**v > 0.0 && **v <= 1.0))
    {
        bail!("--factors: factor {} is {v}; each must be in (0, 1]", k + 1);
    }
    let list: Vec<DeratingFactor> = factors
        .iter()
        .zip(FACTOR_NAMES)
        .map(|(v, n)| DeratingFactor::new(n, *v))
        .collect();
    DeratingRule::new(&list).map_err(|e| anyhow::anyhow!("--factors: {e}"))
}

/// The device's own derating rule: the HPPA report's for `hppa`, the
/// Omnimagnet's (no magnet plate) for `omnimagnet`, none (product 1) for
/// other models.
pub fn default_rule(spec: &ModelSpec) -> DeratingRule {
    match spec {
        ModelSpec::Hppa => DeratingRule::hppa(),
        ModelSpec::Omnimagnet => DeratingRule::omnimagnet(),
        _ => DeratingRule::new(&[]).expect("an empty rule is valid"),
    }
}

/// The HPPA grid size from `--rows`/`--cols` (defaults 7 x 12).
pub fn grid_dims(args: &ModelArgs) -> (usize, usize) {
    (
        args.rows.unwrap_or(devices::DEFAULT_ROWS),
        args.cols.unwrap_or(devices::DEFAULT_COLS),
    )
}

fn check_grid_flags(args: &ModelArgs, spec: &ModelSpec) -> Result<()> {
    if *spec != ModelSpec::Hppa
        && (args.rows.is_some() || args.cols.is_some() || args.grid_params.is_some())
    {
        bail!("--rows, --cols and --grid-params apply to --model hppa only");
    }
    Ok(())
}

/// The model as a model file (every model a file can describe; the
/// Omnimagnet linearised at 20 degC, see [`model_file_at`]).
pub fn model_file(args: &ModelArgs) -> Result<ModelFile> {
    model_file_at(args, devices::OMNIMAGNET_DEFAULT_AMBIENT_C)
}

/// [`model_file`] with the Omnimagnet linearised at `omnimagnet_op_c`
/// \[degC\] (every node and the ambient).
pub fn model_file_at(args: &ModelArgs, omnimagnet_op_c: f64) -> Result<ModelFile> {
    let spec = ModelSpec::parse(&args.model)?;
    check_grid_flags(args, &spec)?;
    let mut file = match spec {
        ModelSpec::Hppa => {
            let (rows, cols) = grid_dims(args);
            let params = devices::grid_preset(args.grid_params.as_deref().unwrap_or("fdm-fitted"))?;
            devices::grid_file(rows, cols, &params)
        }
        ModelSpec::Omnimagnet => devices::omnimagnet_file(omnimagnet_op_c),
        ModelSpec::Solenoid => ModelFile::solenoid(&SolenoidParams::HESE, args.layers),
        ModelSpec::File(p) => ModelFile::load(&p),
    }?;
    for lag in &args.sensor_lags {
        add_sensor_lag(&mut file, lag)?;
    }
    Ok(file)
}

/// Adds `--sensor-lag NODE=TAU_S`: a node `NODE_lag` following NODE with
/// a first-order lag `tau` \[s\] (capacity `c`, conductance `c / tau`).
fn add_sensor_lag(file: &mut ModelFile, flag: &str) -> Result<()> {
    let (node, tau) = split_mapping(flag, "--sensor-lag", "NODE=TAU_S")?;
    let tau_s: f64 = tau
        .parse()
        .ok()
        .filter(|t: &f64| t.is_finite() && *t > 0.0)
        .with_context(|| format!("--sensor-lag `{flag}`: `{tau}` is not a finite time > 0 s"))?;
    let names: Vec<String> = file.nodes.iter().map(|n| n.name.clone()).collect();
    let Some(spec) = file.nodes.iter().find(|n| n.name == node) else {
        bail!(
            "--sensor-lag `{flag}`: the model has no node `{node}` (nodes: {})",
            names.join(", ")
        );
    };
    let lag = format!("{node}_lag");
    if names.contains(&lag) {
        bail!("--sensor-lag `{flag}`: the model already has a node `{lag}`");
    }
    let capacity = spec.capacity_j_per_k * crate::model_file::LAG_CAPACITY_FRACTION;
    file.nodes.push(crate::model_file::NodeSpec {
        name: lag.clone(),
        capacity_j_per_k: capacity,
        critical_c: None,
        lags: None,
        time_constant_s: None,
    });
    file.conductances
        .push(crate::model_file::ConductanceSpec::g(
            node,
            &lag,
            capacity / tau_s,
        ));
    Ok(())
}

/// The model as a runnable plant: the Omnimagnet's nonlinear model, every
/// other model as a model file on the library's explicit stepper.
pub fn plant(args: &ModelArgs) -> Result<Box<dyn Plant>> {
    let spec = ModelSpec::parse(&args.model)?;
    check_grid_flags(args, &spec)?;
    if spec == ModelSpec::Omnimagnet {
        if !args.sensor_lags.is_empty() {
            bail!("--sensor-lag: simulate runs the Omnimagnet's nonlinear model, which has no place for a lag node; use its model file (`simulate --model omnimagnet --write-model omni.toml`) instead");
        }
        return Ok(Box::new(devices::OmnimagnetPlant::default()));
    }
    let file = model_file(args)?;
    Ok(Box::new(FilePlant::new(Model::build(&file)?)?))
}

/// Splits `LEFT=RIGHT` at the last `=`.
pub fn split_mapping<'a>(text: &'a str, flag: &str, form: &str) -> Result<(&'a str, &'a str)> {
    match text.rsplit_once('=') {
        Some((l, r)) if !l.trim().is_empty() && !r.trim().is_empty() => Ok((l.trim(), r.trim())),
        _ => bail!("{flag} `{text}`: expected {form}"),
    }
}

/// The trace bindings from the flags.
pub fn bindings(args: &TraceArgs) -> Result<Bindings> {
    let mut b = Bindings::default();
    if let Some(k) = args.current_scale {
        if !(k.is_finite() && k >= 0.0) {
            bail!("--current-scale must be finite and >= 0, got {k}");
        }
        b.current_scale = Some(k);
    }
    for c in &args.currents {
        let (e, input) = split_mapping(c, "--current", "EXPR=INPUT")?;
        b.currents.push((
            ColumnExpr::parse(e).with_context(|| format!("--current `{c}`"))?,
            input.into(),
        ));
    }
    for c in &args.boundaries {
        let (e, name) = split_mapping(c, "--boundary", "EXPR=BOUNDARY")?;
        b.boundaries.push((
            ColumnExpr::parse(e).with_context(|| format!("--boundary `{c}`"))?,
            name.into(),
        ));
    }
    for c in &args.constants {
        let (col, v) = split_mapping(c, "--const", "COL=VALUE")?;
        b.constants.push((col.into(), constant(v, c)?));
    }
    Ok(b)
}

/// `bind` for the `k`-th (0-based) of `traces` traces: the
/// `--trace-const K:COL=VALUE` flags of trace `k + 1` added after (so
/// winning over) every `--const`.
pub fn trace_bindings(
    bind: &Bindings,
    flags: &[String],
    k: usize,
    traces: usize,
) -> Result<Bindings> {
    let mut out = bind.clone();
    for f in flags {
        let (index, mapping) = f
            .split_once(':')
            .with_context(|| format!("--trace-const `{f}`: expected K:COL=VALUE"))?;
        let index: usize = index
            .trim()
            .parse()
            .ok()
            .filter(|i| (1..=traces).contains(i))
            .with_context(|| {
                format!("--trace-const `{f}`: `{index}` is not a trace position 1..={traces} (every --trace, then every --validate)")
            })?;
        if index != k + 1 {
            continue;
        }
        let (col, v) = split_mapping(mapping, "--trace-const", "K:COL=VALUE")?;
        out.constants.push((col.into(), constant(v, f)?));
    }
    Ok(out)
}

/// A `--const` value: a finite number or a step profile `T:V,T:V,...`.
pub fn constant(value: &str, flag_text: &str) -> Result<ColumnExpr> {
    match ColumnExpr::parse(value) {
        Ok(e @ (ColumnExpr::Constant(_) | ColumnExpr::Steps(_))) => Ok(e),
        Ok(_) => bail!(
            "--const `{flag_text}`: `{value}` is not a finite number or a step profile TIME_S:VALUE,TIME_S:VALUE,..."
        ),
        Err(e) => Err(e.context(format!("--const `{flag_text}`"))),
    }
}

/// Refuses `--current-a` values for a model with no current input (no
/// `[[source]]`): there is nothing for them to set, and they used to be
/// dropped without a word. With inputs, one value for every input or one
/// per input is the caller's (and the drive's) to check.
pub fn check_current_a_has_inputs(current_a: &[f64], model: &str, inputs: usize) -> Result<()> {
    if inputs == 0 && !current_a.is_empty() {
        bail!(
            "--current-a: model `{model}` has no current input (no [[source]]), so there is no \
             current to set: leave --current-a out (a [[loss]]'s current is a signal: give it \
             with --const COL=VALUE)"
        );
    }
    Ok(())
}

/// Reads a trace with the time flags (`--time-column`,
/// `--sample-period-s`); warns on stderr of non-numeric cells in columns
/// (refused only if a flag uses them).
pub fn read_trace(path: &Path, args: &TraceArgs) -> Result<Trace> {
    let trace = Trace::read_with(
        path,
        &TimeSource {
            column: args.time_column.clone(),
            sample_period_s: args.sample_period_s,
        },
    )?;
    for w in trace.non_numeric() {
        eprintln!("warning: {w}");
    }
    Ok(trace)
}

/// Scans a trace with the time flags for a streamed run (see
/// [`crate::trace::TraceFile`]); warns on stderr of non-numeric cells in
/// columns (refused only if a flag uses them).
pub fn scan_trace(path: &Path, args: &TraceArgs) -> Result<TraceFile> {
    let file = TraceFile::scan(
        path,
        &TimeSource {
            column: args.time_column.clone(),
            sample_period_s: args.sample_period_s,
        },
    )?;
    for w in file.non_numeric() {
        eprintln!("warning: {w}");
    }
    Ok(file)
}

/// A sensor of a streamed trace: its column, node and position in
/// [`crate::sim::InputRow::extra`].
#[derive(Debug, Clone, PartialEq)]
pub struct StreamSensor {
    /// Column name (or expression text).
    pub column: String,
    /// Node index.
    pub node: usize,
    /// Position of its reading in each row's `extra`.
    pub slot: usize,
}

/// `COL=NODE` flags resolved on a streamed trace: the streaming form of
/// [`sensors_with`], each item with the error it met, reported by
/// [`Self::check`] after a pass in the order `sensors_with` reports.
pub struct SensorFlags {
    flag: String,
    items: Vec<(String, Result<StreamSensor>)>,
}

impl SensorFlags {
    /// Resolves `flags` (each may hold a comma list) on `drive`'s trace.
    pub fn new(
        flags: &[String],
        flag: &str,
        info: &PlantInfo,
        drive: &mut TraceDrive,
        allow_missing: bool,
    ) -> Self {
        let items = flags
            .iter()
            .flat_map(|f| split_list(f))
            .map(|m| {
                let sensor = (|| {
                    let (col, index, expr) = sensor_mapping(m, flag, info)?;
                    Ok(StreamSensor {
                        column: col.to_string(),
                        node: index,
                        slot: drive.add(&expr, allow_missing),
                    })
                })();
                (m.to_string(), sensor)
            })
            .collect();
        Self {
            flag: flag.to_string(),
            items,
        }
    }

    /// After a full pass: the first item's error, as [`sensors_with`]
    /// reports it (a bad flag, a failing cell, a column without a reading).
    pub fn check(&mut self, drive: &TraceDrive) -> Result<()> {
        let flag = &self.flag;
        for (m, item) in &mut self.items {
            let s = match item {
                Err(e) => return Err(std::mem::replace(e, anyhow::anyhow!("reported"))),
                Ok(s) => s,
            };
            if let Some(e) = drive.extra_error(s.slot) {
                bail!("{e} (for {flag} {m})");
            }
            if !drive.extra_seen(s.slot) {
                bail!("{flag} `{m}`: column `{}` has no reading at all", s.column);
            }
        }
        Ok(())
    }

    /// The sensors (after [`Self::check`]).
    pub fn sensors(&self) -> Vec<StreamSensor> {
        self.items
            .iter()
            .filter_map(|(_, s)| s.as_ref().ok().cloned())
            .collect()
    }
}

/// Splits a flag value at the commas outside parentheses: `a=n1,b=n2`
/// is two items, `hypot(A,B)=n1` one.
pub fn split_list(text: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, ch) in text.char_indices() {
        match ch {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' if depth == 0 => {
                out.push(text[start..i].trim());
                start = i + 1;
            }
            _ => {}
        }
    }
    out.push(text[start..].trim());
    out
}

/// One `COL=NODE` item of `flag`: the column's text, the node's index in
/// `info` and the column's expression.
fn sensor_mapping<'m>(
    m: &'m str,
    flag: &str,
    info: &PlantInfo,
) -> Result<(&'m str, usize, ColumnExpr)> {
    let (col, node) = split_mapping(m, flag, "COL=NODE")?;
    let index = info.nodes.iter().position(|n| n == node).with_context(|| {
        format!(
            "{flag} `{m}`: model `{}` has no node `{node}` (nodes: {})",
            info.name,
            info.nodes.join(", ")
        )
    })?;
    let expr = ColumnExpr::parse(col).with_context(|| format!("{flag} `{m}`"))?;
    Ok((col, index, expr))
}

/// Resolves `COL=NODE` flags (each may hold a comma list) to sensors on
/// `trace`: every cell must hold a finite number, or with `allow_missing`,
/// empty and `NaN` cells are missing readings (`NaN` in `values_c`),
/// skipped by fusion, scoring and calibration.
pub fn sensors_with(
    flags: &[String],
    flag: &str,
    info: &PlantInfo,
    trace: &Trace,
    allow_missing: bool,
) -> Result<Vec<Sensor>> {
    flags
        .iter()
        .flat_map(|f| split_list(f))
        .map(|m| {
            let (col, index, expr) = sensor_mapping(m, flag, info)?;
            let values_c = trace
                .eval_with(&expr, allow_missing)
                .map_err(|e| anyhow::anyhow!("{e} (for {flag} {m})"))?;
            if values_c.iter().all(|v| v.is_nan()) {
                bail!("{flag} `{m}`: column `{col}` has no reading at all");
            }
            Ok(Sensor {
                column: col.to_string(),
                node: index,
                values_c,
            })
        })
        .collect()
}

/// The version of every `--json` summary's layout (docs/json.md), printed
/// as its `schema_version`: raised when a field is renamed, removed or
/// changes meaning, so that a script can refuse a layout it does not know.
pub const JSON_SCHEMA_VERSION: u32 = 1;

/// Prints a JSON summary as one line on stdout, with its `schema_version`
/// (a report that carries its own, as `faults`, keeps it).
pub fn print_json(value: &serde_json::Value) {
    let mut value = value.clone();
    if let Some(object) = value.as_object_mut() {
        object
            .entry("schema_version")
            .or_insert(JSON_SCHEMA_VERSION.into());
    }
    println!(
        "{}",
        serde_json::to_string(&value).expect("JSON values serialise")
    );
}

/// The series worth plotting: all of them up to 12, else the 8 with the
/// largest maximum (a grid has 84 coils).
pub fn plotted(series: &[Vec<f64>]) -> Vec<usize> {
    let maxima: Vec<f64> = series
        .iter()
        .map(|s| s.iter().copied().fold(f64::MIN, f64::max))
        .collect();
    plotted_by_max(&maxima)
}

/// [`plotted`] from each series' maximum.
pub fn plotted_by_max(maxima: &[f64]) -> Vec<usize> {
    if maxima.len() <= 12 {
        return (0..maxima.len()).collect();
    }
    let mut order: Vec<(usize, f64)> = maxima.iter().copied().enumerate().collect();
    order.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let mut keep: Vec<usize> = order.into_iter().take(8).map(|(i, _)| i).collect();
    keep.sort_unstable();
    keep
}

/// The hottest node of a run, row by row: each node's first maximum, and
/// of those the first node's with the largest.
#[derive(Debug, Clone)]
pub struct HotSpot {
    /// Per node: its maximum \[degC\] and the first time it had it \[s\].
    pub max: Vec<(f64, f64)>,
}

impl HotSpot {
    /// For `nodes` nodes.
    pub fn new(nodes: usize) -> Self {
        Self {
            max: vec![(f64::MIN, 0.0); nodes],
        }
    }

    /// Adds a row's temperatures \[degC\] at `time_s` \[s\].
    pub fn push(&mut self, time_s: f64, temps_c: &[f64]) {
        for (m, v) in self.max.iter_mut().zip(temps_c) {
            if *v > m.0 {
                *m = (*v, time_s);
            }
        }
    }

    /// (node, max degC, time s).
    pub fn hottest(&self) -> (usize, f64, f64) {
        let mut hot = (0, f64::MIN, 0.0);
        for (i, (v, t)) in self.max.iter().enumerate() {
            if *v > hot.1 {
                hot = (i, *v, *t);
            }
        }
        hot
    }
}

pub use crate::plot::MAX_PLOT_MAGNITUDE;

/// Refuses a plot whose series hold values no axis can span (e.g. `1e308`
/// from a runaway), naming the series and the time.
pub fn check_plot_values(data: &PlotData) -> Result<()> {
    for s in data
        .estimated
        .iter()
        .chain(&data.measured)
        .chain(&data.currents)
    {
        if let Some((t, v)) = s
            .time_s
            .iter()
            .zip(&s.values)
            .find(|(_, v)| v.is_infinite() || v.abs() > MAX_PLOT_MAGNITUDE)
        {
            bail!(
                "plot: series `{}` holds {} at t = {} s, beyond +-{MAX_PLOT_MAGNITUDE:e}: \
                 the run it comes from went wrong (a runaway?); plot other columns with --node",
                s.label,
                crate::trace::num(*v),
                crate::trace::num(*t)
            );
        }
    }
    Ok(())
}

/// The window's bounds \[s\] (infinite where not given): a row at `t` is
/// in it when `from <= t <= to`.
pub fn window(w: &super::WindowArgs) -> (f64, f64) {
    (
        w.from_s.unwrap_or(f64::NEG_INFINITY),
        w.to_s.unwrap_or(f64::INFINITY),
    )
}

/// Refuses a window whose bound is not finite, with `from >= to`, or
/// without a row (`inside` counts the run's rows in it; `t0`, `t1` are the
/// run's first and last time \[s\]).
pub fn check_window(w: &super::WindowArgs, inside: usize, t0: f64, t1: f64) -> Result<()> {
    for (flag, v) in [("--from-s", w.from_s), ("--to-s", w.to_s)] {
        if let Some(v) = v.filter(|v| !v.is_finite()) {
            bail!("{flag} must be a finite time [s], got {v}");
        }
    }
    let (from, to) = window(w);
    if from >= to {
        bail!("the window must have --from-s below --to-s, got {from} s and {to} s");
    }
    if inside == 0 {
        bail!("the window {from} s .. {to} s holds no row of the run ({t0} s .. {t1} s)");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_split_at_commas_outside_parentheses() {
        assert_eq!(split_list("a=n1,b=n2"), ["a=n1", "b=n2"]);
        assert_eq!(split_list("hypot(A,B)=n1, c=n2"), ["hypot(A,B)=n1", "c=n2"]);
        assert_eq!(split_list("a=n1,"), ["a=n1", ""]);
    }
}
