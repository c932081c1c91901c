//! `coil-thermal plot`.

use anyhow::{bail, Context, Result};
use serde_json::json;

use super::common;
use super::PlotArgs;
use crate::plot::{render, PlotData, Series};
use crate::trace::{ColumnExpr, TimeSource, Trace, TIME_COLUMN};

/// Runs `plot`.
pub fn run(a: PlotArgs) -> Result<()> {
    let est = Trace::read(&a.estimate, None)?;
    let columns: Vec<String> = if a.nodes.is_empty() {
        est.headers()
            .iter()
            .filter(|h| *h != TIME_COLUMN)
            .cloned()
            .collect()
    } else {
        a.nodes.clone()
    };
    if columns.is_empty() {
        bail!(
            "{}: no temperature columns besides `{TIME_COLUMN}`",
            a.estimate.display()
        );
    }
    let mut data = PlotData {
        title: a
            .title
            .clone()
            .unwrap_or_else(|| a.estimate.display().to_string()),
        ..PlotData::default()
    };
    for (i, c) in columns.iter().enumerate() {
        data.estimated.push(Series {
            label: c.clone(),
            time_s: est.time_s().to_vec(),
            values: est.column(c)?,
            color: i,
        });
    }
    if let Some(path) = &a.trace {
        let trace = Trace::read_with(
            path,
            &TimeSource {
                column: a.time_column.clone(),
                sample_period_s: a.sample_period_s,
            },
        )?;
        for m in &a.measure {
            let (col, node) = common::split_mapping(m, "--measure", "COL=NODE")?;
            let color = columns.iter().position(|c| c == node).with_context(|| {
                format!(
                    "--measure `{m}`: no column `{node}` in {} (columns: {})",
                    a.estimate.display(),
                    columns.join(", ")
                )
            })?;
            let expr = ColumnExpr::parse(col)?;
            // Missing readings (empty or NaN cells) are left out.
            let (time_s, values) = trace
                .time_s()
                .iter()
                .zip(trace.eval_with(&expr, true)?)
                .filter(|(_, v)| !v.is_nan())
                .unzip();
            data.measured.push(Series {
                label: format!("{col} (measured)"),
                time_s,
                values,
                color,
            });
        }
        for (i, c) in a.currents.iter().enumerate() {
            let expr = ColumnExpr::parse(c)?;
            data.currents.push(Series {
                label: format!("{c} [A]"),
                time_s: trace.time_s().to_vec(),
                values: trace.eval(&expr)?,
                color: i,
            });
        }
    } else if !a.measure.is_empty() || !a.currents.is_empty() {
        bail!("--measure and --current read the recorded trace: pass --trace IN.csv");
    }
    for l in &a.limits {
        let (label, v) = common::split_mapping(l, "--limit-c", "LABEL=C")?;
        let v: f64 = v
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .with_context(|| format!("--limit-c `{l}`: `{v}` is not a finite number"))?;
        data.limits.push((label.to_string(), v));
    }
    for t in &a.alarms {
        if !t.is_finite() {
            bail!("--alarm-s must be finite, got {t}");
        }
        data.alarms.push((*t, "alarm".into()));
    }
    common::check_plot_values(&data)?;
    render(&data, &a.out, a.width, a.height)?;
    if a.json {
        common::print_json(&json!({
            "command": "plot",
            "out": a.out.display().to_string(),
            "width": a.width,
            "height": a.height,
            "series": data.estimated.len() + data.measured.len() + data.currents.len(),
        }));
    } else {
        println!("wrote {} ({}x{} px)", a.out.display(), a.width, a.height);
    }
    Ok(())
}
