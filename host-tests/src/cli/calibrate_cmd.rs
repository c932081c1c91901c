//! `coil-thermal calibrate`.

use std::io::IsTerminal;
use std::time::Instant;

use anyhow::{Context, Result};
use serde_json::json;

use super::common;
use super::CalibrateArgs;
use serde::Serialize;

use crate::calibrate::{fit, FitData, FitOptions, ParamSpec};
use crate::model_file::{Model, ModelFile};
use crate::observer::{score, Score};
use crate::sim::{
    by_node, check_temperatures, check_work, initial_temps, plant_info, simulate, Drive, FilePlant,
    Plant,
};

/// Runs `calibrate`.
pub fn run(a: CalibrateArgs) -> Result<()> {
    let file = common::model_file(&a.model)?;
    let info = plant_info(&Model::build(&file)?);
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
            drive: Drive::from_trace(&info, &trace, &bind)?,
            targets: common::sensors(&a.measure, "--measure", &info, &trace).context(
                "calibrate fits every row: fill or drop the rows without a reading (replay skips them)",
            )?,
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
    let opts = FitOptions {
        max_iterations: a.max_iterations,
        stride: a.stride.max(1),
        progress: !a.no_progress && std::io::stderr().is_terminal(),
    };
    let start = Instant::now();
    let (fitted, report) = fit(&file, &params, &data, &opts)?;
    let seconds = start.elapsed().as_secs_f64();
    let validation = held_out
        .iter()
        .map(|d| validate(&fitted, d))
        .collect::<Result<Vec<_>>>()?;
    std::fs::write(&a.out, fitted.to_toml()?)
        .with_context(|| format!("{}: cannot write the fitted model", a.out.display()))?;
    if a.json {
        common::print_json(&json!({
            "command": "calibrate",
            "schema_version": 2,
            "model": info.name,
            "fit": report,
            "validation": validation,
            "seconds": seconds,
            "out": a.out.display().to_string(),
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
        "{:<36} {:>14} {:>14}  bounds",
        "parameter", "initial", "fitted"
    );
    for p in &report.params {
        println!(
            "{:<36} {:>14.6e} {:>14.6e}  [{:.3e}, {:.3e}]{}",
            p.name,
            p.initial,
            p.fitted,
            p.lo,
            p.hi,
            if p.at_bound { "  AT BOUND" } else { "" }
        );
    }
    println!(
        "{:<48} {:>16} {:>16}",
        "trace", "RMSE before [K]", "RMSE after [K]"
    );
    for t in &report.traces {
        println!(
            "{:<48} {:>16.4} {:>16.4}",
            t.trace, t.rmse_before_k, t.rmse_after_k
        );
        for s in &t.sensors {
            println!(
                "  {:<20} -> {:<16} RMSE {:.4} K, max {:.4} K",
                s.column, s.node, s.rmse_k, s.max_abs_error_k
            );
        }
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
    println!("fitted model written to {}", a.out.display());
    Ok(())
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
    let first: Vec<(usize, f64)> = d.targets.iter().map(|t| (t.node, t.values_c[0])).collect();
    let init = initial_temps(&info, &d.drive, &first)?;
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
