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
    println!("fitted model written to {}", a.out.display());
    Ok(())
}
