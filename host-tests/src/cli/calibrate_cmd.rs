//! `coil-thermal calibrate`.

use std::io::IsTerminal;
use std::time::Instant;

use anyhow::{Context, Result};
use serde_json::json;

use super::common;
use super::CalibrateArgs;
use crate::calibrate::{fit, FitData, FitOptions, ParamSpec};
use crate::model_file::Model;
use crate::sim::{plant_info, Drive};

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
    let mut data = Vec::new();
    for path in &a.traces {
        let trace = common::read_trace(path, a.trace_args.sample_period_s)?;
        data.push(FitData {
            label: path.display().to_string(),
            drive: Drive::from_trace(&info, &trace, &bind)?.held(model.input_hold),
            targets: common::sensors(&a.measure, "--measure", &info, &trace)?,
            init: common::sensors(&a.init, "--init", &info, &trace)?
                .into_iter()
                .map(|s| (s.node, s.values_c[0]))
                .collect(),
        });
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
    std::fs::write(&a.out, fitted.to_toml()?)
        .with_context(|| format!("{}: cannot write the fitted model", a.out.display()))?;
    if a.json {
        common::print_json(&json!({
            "command": "calibrate",
            "model": info.name,
            "fit": report,
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
    println!("fitted model written to {}", a.out.display());
    Ok(())
}
