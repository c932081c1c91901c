//! `coil-thermal calibrate`.

use std::io::IsTerminal;
use std::time::Instant;

use anyhow::{Context, Result};
use serde_json::json;

use super::common;
use super::CalibrateArgs;
use serde::Serialize;

use crate::calibrate::{
    access_param, default_bounds, first_readings, fit, FitData, FitOptions, FitReport, ParamSpec,
    Weighting,
};
use crate::margin;
use crate::model_file::{Model, ModelFile};
use crate::observer::{score, Score};
use crate::sim::{
    by_node, check_temperatures, check_work, initial_temps, plant_info, simulate, Drive, FilePlant,
    Plant,
};
use crate::synth::Rng;

/// The fitted model's file text, and whether it is the input model file
/// with only the fitted values changed (its comments, key order and
/// number formats kept). A built-in model, or a file the edit cannot
/// reproduce exactly (checked by parsing the edited text back and
/// comparing it with the fit), is written plainly from the parsed model.
fn fitted_text(model: &str, fitted: &ModelFile) -> Result<(String, bool)> {
    let plain = fitted.to_toml()?;
    let common::ModelSpec::File(path) = common::ModelSpec::parse(model)? else {
        return Ok((plain, false));
    };
    let source = std::fs::read_to_string(&path)
        .with_context(|| format!("{}: cannot read model file", path.display()))?;
    match with_values_of(&source, &plain) {
        Some(edited)
            if ModelFile::parse(&edited, model)
                .ok()
                .and_then(|m| m.to_toml().ok())
                .is_some_and(|t| t == plain) =>
        {
            Ok((edited, true))
        }
        _ => {
            eprintln!(
                "warning: {model}: the fitted values could not be written into the file as it is; \
                 the fitted file is written from the parsed model, without the input's comments"
            );
            Ok((plain, false))
        }
    }
}

/// `source` with every value that `fitted` holds differently replaced
/// (the value's surrounding comments and spacing kept), keys and tables
/// that `fitted` adds appended; `None` if either does not parse.
fn with_values_of(source: &str, fitted: &str) -> Option<String> {
    let mut doc: toml_edit::DocumentMut = source.parse().ok()?;
    let new: toml_edit::DocumentMut = fitted.parse().ok()?;
    merge_table(doc.as_table_mut(), new.as_table());
    Some(doc.to_string())
}

fn merge_table(old: &mut dyn toml_edit::TableLike, new: &dyn toml_edit::TableLike) {
    for (key, item) in new.iter() {
        match old.get_mut(key) {
            Some(slot) => merge_item(slot, item),
            None => {
                old.insert(key, item.clone());
            }
        }
    }
}

fn merge_item(old: &mut toml_edit::Item, new: &toml_edit::Item) {
    use toml_edit::{Item, Value};
    match (old, new) {
        (Item::ArrayOfTables(o), Item::ArrayOfTables(n)) => {
            for (i, table) in n.iter().enumerate() {
                match o.get_mut(i) {
                    Some(slot) => merge_table(slot, table),
                    None => o.push(table.clone()),
                }
            }
        }
        (Item::Value(Value::Array(o)), Item::Value(Value::Array(n))) if o.len() == n.len() => {
            for (i, v) in n.iter().enumerate() {
                if let Some(slot) = o.get_mut(i) {
                    merge_value(slot, v);
                }
            }
        }
        (Item::Value(o), Item::Value(n)) => {
            if let (Some(ot), Some(nt)) = (o.as_inline_table_mut(), n.as_inline_table()) {
                merge_table(ot, nt);
            } else {
                merge_value(o, n);
            }
        }
        (o, n) => match (o.as_table_like_mut(), n.as_table_like()) {
            (Some(ot), Some(nt)) => merge_table(ot, nt),
            _ => *o = n.clone(),
        },
    }
}

/// Replaces `old` by `new` unless they are the same number or text,
/// keeping `old`'s decoration (the comment after it).
fn merge_value(old: &mut toml_edit::Value, new: &toml_edit::Value) {
    use toml_edit::Value;
    let number = |v: &Value| match v {
        Value::Integer(i) => Some(*i.value() as f64),
        Value::Float(f) => Some(*f.value()),
        _ => None,
    };
    let bare = |v: &Value| {
        let mut v = v.clone();
        v.decor_mut().clear();
        v.to_string()
    };
    let same = match (number(old), number(new)) {
        (Some(a), Some(b)) => a == b,
        _ => bare(old) == bare(new),
    };
    if !same {
        let decor = old.decor().clone();
        *old = new.clone();
        *old.decor_mut() = decor;
    }
}

/// Runs `calibrate`.
pub fn run(a: CalibrateArgs) -> Result<()> {
    let file = common::model_file(&a.model)?;
    let model = Model::build(&file)?;
    let info = plant_info(&model);
    let bind = common::bindings(&a.trace_args)?;
    let params = a
        .params
        .iter()
        .map(|p| ParamSpec::parse(p).with_context(|| format!("--params `{p}`")))
        .collect::<Result<Vec<_>>>()?;
    let all_traces = a.traces.len() + a.validate.len();
    let mut data = Vec::new();
    let mut held_out = Vec::new();
    for (k, path) in a.traces.iter().chain(&a.validate).enumerate() {
        let trace = common::read_trace(path, &a.trace_args)?;
        let bind = common::trace_bindings(&bind, &a.trace_const, k, all_traces)?;
        let d = FitData {
            label: path.display().to_string(),
            drive: Drive::from_trace(&info, &trace, &bind)?.held(model.input_hold),
            // A missing reading (empty or NaN cell) gives no residual.
            targets: common::sensors_with(&a.measure, "--measure", &info, &trace, true)?,
            init: first_readings(&common::sensors_with(
                &a.init, "--init", &info, &trace, true,
            )?),
        };
        check_work(
            &FilePlant::new(Model::build(&file)?)?,
            &d.drive.time_s,
            &d.label,
        )?;
        if k < a.traces.len() {
            data.push(d);
        } else {
            held_out.push(d);
        }
    }
    if a.max_iterations == 0 {
        anyhow::bail!("--max-iterations must be at least 1");
    }
    if a.starts == 0 || a.starts > MAX_STARTS {
        anyhow::bail!("--starts must be in 1..={MAX_STARTS}, got {}", a.starts);
    }
    let opts = FitOptions {
        max_iterations: a.max_iterations,
        stride: a.stride.max(1),
        progress: !a.no_progress && std::io::stderr().is_terminal(),
        weighting: a.weighting,
        trace_weights: trace_weights(&a.weight, data.len())?,
    };
    let start = Instant::now();
    let (fitted, report, starts) = if a.starts > 1 {
        multi_start(&file, &params, &data, &opts, a.starts, a.starts_seed)?
    } else {
        let (fitted, report) = fit(&file, &params, &data, &opts)?;
        (fitted, report, Vec::new())
    };
    let seconds = start.elapsed().as_secs_f64();
    let validation = held_out
        .iter()
        .map(|d| validate(&fitted, d))
        .collect::<Result<Vec<_>>>()?;
    // The margin of the nodes the product's sensors do not see, measured
    // by the firmware's observer on the held-out recordings.
    let mut fitted = fitted;
    let margin_checks = match &fitted.observer {
        Some(spec) if !held_out.is_empty() => {
            let model = Model::build(&fitted)?;
            held_out
                .iter()
                .filter_map(|d| margin::check(&model, spec, d).transpose())
                .collect::<Result<Vec<_>>>()?
        }
        _ => Vec::new(),
    };
    let margin_written = margin::written_margin(&margin_checks);
    if let (Some(m), Some(spec)) = (margin_written, fitted.observer.as_mut()) {
        spec.unmeasured_margin = Some(m);
    }
    let (text, kept_comments) = fitted_text(&a.model.model, &fitted)?;
    std::fs::write(&a.out, text)
        .with_context(|| format!("{}: cannot write the fitted model", a.out.display()))?;
    let figures = match &a.plot {
        Some(path) => super::plot_cmd::fit_report(&fitted, &data, path)?,
        None => Vec::new(),
    };
    if a.json {
        common::print_json(&json!({
            "command": "calibrate",
            "model": info.name,
            "fit": report,
            "validation": validation,
            "margin": {
                "checks": margin_checks,
                "written": margin_written,
            },
            "starts": starts,
            "seconds": seconds,
            "out": a.out.display().to_string(),
            "plots": figures.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        }));
        return Ok(());
    }
    println!(
        "calibrated `{}` on {} trace(s): {} iterations, {} evaluations, {:.2} s ({})",
        info.name,
        data.len(),
        report.iterations,
        report.evaluations,
        seconds,
        report.stop_reason
    );
    println!(
        "{:<36} {:>14} {:>14} {:>12}  bounds",
        "parameter", "initial", "fitted", "std error"
    );
    for p in &report.params {
        let se = p
            .std_error
            .map_or_else(|| "-".to_string(), |e| format!("{e:.3e}"));
        let note = match p.bound {
            Some(b) => format!(
                "  AT {} BOUND (widen it in --params if physics allows)",
                b.to_uppercase()
            ),
            None => String::new(),
        };
        println!(
            "{:<36} {:>14.6e} {:>14.6e} {:>12}  [{:.3e}, {:.3e}]{note}",
            p.name, p.initial, p.fitted, se, p.lo, p.hi,
        );
    }
    // What an unidentified parameter means for the firmware's estimate.
    for p in &report.params {
        let relative = p
            .std_error
            .map(|e| e / p.fitted.abs().max(f64::MIN_POSITIVE));
        if relative.is_none_or(|r| r > UNIDENTIFIED_RELATIVE_ERROR) {
            println!(
                "  {}: not pinned down by these recordings ({}): what the observer estimates for the nodes it governs rests on its value; a sensor the product has corrects what it sees, but a node no sensor reads (a heatsink, a winding) may be off by what this parameter is. Give --validate a recording with a bench thermocouple on such a node: calibrate then measures the margin the product needs there",
                p.name,
                relative.map_or("no standard error: the fit's covariance is singular, some parameter has no effect on these readings".into(), |r| format!(
                    "standard error {:.0} % of its value",
                    100.0 * r
                ))
            );
        }
    }
    // Strongly correlated pairs: the data cannot tell these apart.
    let mut pairs = Vec::new();
    for (i, row) in report.correlations.iter().enumerate() {
        for (j, c) in row.iter().enumerate().skip(i + 1) {
            if let Some(c) = c.filter(|c| c.abs() >= 0.9) {
                pairs.push(format!(
                    "  {} ~ {}: {c:+.3}",
                    report.params[i].name, report.params[j].name
                ));
            }
        }
    }
    if pairs.is_empty() {
        println!("no pair of free parameters correlated beyond |0.9|");
    } else {
        println!("correlations beyond |0.9| (the JSON has the full matrix):");
        pairs.iter().for_each(|p| println!("{p}"));
    }
    println!(
        "{:<48} {:>16} {:>16} {:>10}",
        "trace", "RMSE before [K]", "RMSE after [K]", "weight"
    );
    for t in &report.traces {
        println!(
            "{:<48} {:>16.4} {:>16.4} {:>10.4}",
            t.trace, t.rmse_before_k, t.rmse_after_k, t.weight
        );
        for s in &t.sensors {
            println!(
                "  {:<20} -> {:<16} RMSE {:.4} K, max {:.4} K, {} readings fitted, {} missing",
                s.score.column,
                s.score.node,
                s.score.rmse_k,
                s.score.max_abs_error_k,
                s.rows_fitted,
                s.rows_missing
            );
        }
    }
    println!(
        "weighting: {} (--weighting rows|traces, --weight K:W)",
        match a.weighting {
            Weighting::Rows => "rows, every reading the same",
            Weighting::Traces => "traces, every trace the same in total",
        }
    );
    if !starts.is_empty() {
        print_starts(&starts);
    }
    for v in &validation {
        println!(
            "held out {:<38} RMSE {:.4} K (not fitted)",
            v.trace, v.rmse_k
        );
        for s in &v.sensors {
            println!(
                "  {:<20} -> {:<16} RMSE {:.4} K, max {:.4} K",
                s.column, s.node, s.rmse_k, s.max_abs_error_k
            );
        }
    }
    print_margin(&margin_checks, margin_written);
    println!(
        "fitted model written to {}{}",
        a.out.display(),
        if kept_comments {
            " (the input file with only the fitted values changed)"
        } else {
            ""
        }
    );
    for p in &figures {
        println!("fit report drawn to {}", p.display());
    }
    Ok(())
}

/// A fitted parameter whose standard error exceeds this share of its value
/// is reported as not pinned down by the recordings.
const UNIDENTIFIED_RELATIVE_ERROR: f64 = 0.5;

/// What the held-out recordings say of the unmeasured nodes' margin.
fn print_margin(checks: &[margin::MarginCheck], written: Option<f64>) {
    for c in checks {
        println!(
            "margin check on {} (the firmware observer, the product's sensors only, margin {:.0} % of the rise):",
            c.trace,
            100.0 * c.margin
        );
        for n in &c.nodes {
            let needed = if n.needed_margin.is_finite() {
                format!("{:.1} %", 100.0 * n.needed_margin)
            } else {
                format!("- (never {} K above the ambient)", margin::MIN_RISE_K)
            };
            println!(
                "  {:<20} -> {:<16} truth above its upper bound at most {:+.2} K (at {:.0} s); needs a margin of {needed}",
                n.column, n.node, n.worst_above_bound_k, n.at_s
            );
        }
    }
    if let Some(m) = written {
        println!(
            "[observer] unmeasured_margin = {m} written (the share of the rise the held-out truth needed, rounded up to {} %): codegen flashes it",
            100.0 * margin::MARGIN_STEP
        );
    }
}

/// The relative weight of each fitted trace from `--weight K:W` (K the
/// trace's 1-based --trace position): 1 unless given.
fn trace_weights(flags: &[String], traces: usize) -> Result<Vec<f64>> {
    let mut weights = vec![1.0; traces];
    for f in flags {
        let (k, w) = f
            .split_once(':')
            .with_context(|| format!("--weight `{f}`: expected K:W (e.g. 2:3.5)"))?;
        let k: usize = k
            .trim()
            .parse()
            .with_context(|| format!("--weight `{f}`: `{k}` is not a trace position"))?;
        if k == 0 || k > traces {
            anyhow::bail!(
                "--weight `{f}`: trace {k} does not exist (1..={traces}, counting --trace only; a --validate trace is not fitted)"
            );
        }
        let w: f64 = w
            .trim()
            .parse()
            .with_context(|| format!("--weight `{f}`: `{w}` is not a number"))?;
        if !(w.is_finite() && w > 0.0) {
            anyhow::bail!(
                "--weight `{f}`: a weight must be finite and above 0, got {w} (drop the --trace to leave it out)"
            );
        }
        weights[k - 1] = w;
    }
    Ok(weights)
}

/// The fitted model's open-loop score on a held-out trace.
#[derive(Debug, Serialize)]
struct Validation {
    /// Trace file.
    trace: String,
    /// RMSE over its sensors (root of the mean of their MSEs) [K].
    rmse_k: f64,
    /// Per-sensor scores.
    sensors: Vec<Score>,
}

/// Runs `fitted` open loop over a held-out trace from the start the fit
/// uses (the model's initial policy with the first readings) and scores it.
fn validate(fitted: &ModelFile, d: &FitData) -> Result<Validation> {
    let mut plant = FilePlant::new(Model::build(fitted)?)?;
    let info = plant.info().clone();
    let init = initial_temps(&info, &d.drive, &first_readings(&d.targets))?;
    let est = by_node(&simulate(&mut plant, &d.drive, &init));
    check_temperatures(
        &info,
        &d.drive.time_s,
        &est,
        &format!("--validate {}", d.label),
    )?;
    let sensors: Vec<Score> = d
        .targets
        .iter()
        .map(|t| score(t, &info.nodes[t.node], &est, &d.drive.time_s))
        .collect();
    let mse = sensors.iter().map(|s| s.mse_k2).sum::<f64>() / sensors.len().max(1) as f64;
    Ok(Validation {
        trace: d.label.clone(),
        rmse_k: mse.sqrt(),
        sensors,
    })
}

/// The most `--starts` (each is a full fit).
const MAX_STARTS: usize = 1000;

/// Starts within this relative cost of the best reach "the same fit".
const SAME_COST: f64 = 0.01;

/// A parameter that differs by more than this (relative) between two
/// starts of the same fit is not pinned down by the traces.
const TRADE_OFF: f64 = 0.05;

/// One start of a multi-start fit.
#[derive(Debug, Serialize)]
struct StartResult {
    /// 0: the model's values; then the seeded points.
    start: usize,
    /// Starting values, in `--params` order.
    initial: Vec<f64>,
    /// Fitted values.
    fitted: Vec<f64>,
    /// Half the sum of squared residuals after the fit [K^2].
    cost_after: f64,
    /// `true` for the start kept.
    best: bool,
    /// Parameters that differ by more than 5 % from the best start's while
    /// the cost is within 1 % of it (a trade-off the traces do not pin
    /// down).
    trade_offs: Vec<String>,
}

/// Fits from `starts` points with fixed bounds (each `--params` bound, else
/// the default around the model's value) and keeps the lowest cost.
fn multi_start(
    file: &ModelFile,
    params: &[ParamSpec],
    data: &[FitData],
    opts: &FitOptions,
    starts: usize,
    seed: u64,
) -> Result<(ModelFile, FitReport, Vec<StartResult>)> {
    let mut base = file.clone();
    let mut fixed = Vec::new();
    for p in params {
        let value = access_param(&mut base, &p.name, None)?;
        let (lo, hi) = default_bounds(&p.name, value);
        fixed.push(ParamSpec {
            name: p.name.clone(),
            lo: Some(p.lo.unwrap_or(lo)),
            hi: Some(p.hi.unwrap_or(hi)),
        });
    }
    let mut rng = Rng::new(seed);
    let mut best: Option<(ModelFile, FitReport, usize)> = None;
    let mut results = Vec::new();
    for start in 0..starts {
        let mut from = file.clone();
        let mut initial = Vec::new();
        for p in &fixed {
            let (lo, hi) = (p.lo.unwrap_or(f64::NAN), p.hi.unwrap_or(f64::NAN));
            let value = if start == 0 {
                access_param(&mut from, &p.name, None)?
            } else if lo > 0.0 && hi.is_finite() {
                (lo.ln() + rng.uniform() * (hi / lo).ln()).exp()
            } else if lo.is_finite() && hi.is_finite() {
                lo + rng.uniform() * (hi - lo)
            } else {
                anyhow::bail!(
                    "--starts: parameter `{}` has no finite bounds to draw starts from; give NAME=LO:HI",
                    p.name
                );
            };
            access_param(&mut from, &p.name, Some(value))?;
            initial.push(value);
        }
        let (fitted, report) = fit(&from, &fixed, data, opts)?;
        results.push(StartResult {
            start,
            initial,
            fitted: report.params.iter().map(|r| r.fitted).collect(),
            cost_after: report.cost_after,
            best: false,
            trade_offs: Vec::new(),
        });
        if best
            .as_ref()
            .is_none_or(|(_, b, _)| report.cost_after < b.cost_after)
        {
            best = Some((fitted, report, start));
        }
    }
    let Some((fitted, report, best_start)) = best else {
        anyhow::bail!("--starts: no start ran");
    };
    let best_fitted: Vec<f64> = report.params.iter().map(|r| r.fitted).collect();
    for r in &mut results {
        r.best = r.start == best_start;
        if r.cost_after <= report.cost_after * (1.0 + SAME_COST) + 1e-12 {
            r.trade_offs = fixed
                .iter()
                .zip(r.fitted.iter().zip(&best_fitted))
                .filter(|(_, (a, b))| (*a - *b).abs() > TRADE_OFF * b.abs().max(1e-300))
                .map(|(p, _)| p.name.clone())
                .collect();
        }
    }
    Ok((fitted, report, results))
}

/// The multi-start table and any trade-off warning.
fn print_starts(starts: &[StartResult]) {
    println!("multi-start: {} starts", starts.len());
    for r in starts {
        let values: Vec<String> = r.fitted.iter().map(|v| format!("{v:.6e}")).collect();
        println!(
            "  start {:>3}: cost {:.6e} K^2, fitted [{}]{}",
            r.start,
            r.cost_after,
            values.join(", "),
            if r.best { "  BEST" } else { "" }
        );
    }
    for r in starts.iter().filter(|r| !r.trade_offs.is_empty()) {
        println!(
            "warning: start {} reaches the best cost (within 1 %) with {} more than 5 % away: \
             the traces do not pin them down (they trade off); add a trace that excites them differently or fix one",
            r.start,
            r.trade_offs.join(", ")
        );
    }
}
