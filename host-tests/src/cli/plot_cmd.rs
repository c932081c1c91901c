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
    let data = data.windowed(a.from_s, a.to_s)?;
    common::check_plot_values(&data)?;
    render(&data, &a.out, a.width, a.height)?;
    if a.json {
        common::print_json(&json!({
            "command": "plot",
            "out": a.out.display().to_string(),
            "width": a.width,
            "height": a.height,
            "series": data.estimated.len() + data.measured.len() + data.currents.len(),
            "limit_lines": crate::plot::limit_lines(&data).len(),
            "window_s": [data.estimated.iter().filter_map(|s| s.time_s.first()).copied().reduce(f64::min),
                         data.estimated.iter().filter_map(|s| s.time_s.last()).copied().reduce(f64::max)],
        }));
    } else {
        println!("wrote {} ({}x{} px)", a.out.display(), a.width, a.height);
    }
    Ok(())
}

/// The fit report of `calibrate`: per trace, the fitted model (solid)
/// against each measured column (thick dashed) and their residuals \[K\],
/// with the currents. One figure per trace: `path` for one trace, else
/// `NAME-1.ext`, `NAME-2.ext`, ... Returns the files written.
pub fn fit_report(
    fitted: &crate::model_file::ModelFile,
    data: &[crate::calibrate::FitData],
    path: &std::path::Path,
) -> Result<Vec<std::path::PathBuf>> {
    use crate::model_file::Model;
    use crate::sim::{by_node, initial_temps, plant_info, simulate, FilePlant};
    let model = Model::build(fitted)?;
    let info = plant_info(&model);
    let mut plant = FilePlant::new(model)?;
    let mut written = Vec::new();
    for (k, d) in data.iter().enumerate() {
        let first = crate::calibrate::first_readings(&d.targets);
        let init = initial_temps(&info, &d.drive, &first)?;
        let est = by_node(&simulate(&mut plant, &d.drive, &init));
        let series = |label: String, values: Vec<f64>, color: usize| Series {
            label,
            time_s: d.drive.time_s.clone(),
            values,
            color,
        };
        let mut nodes: Vec<usize> = d.targets.iter().map(|t| t.node).collect();
        nodes.dedup();
        let mut rms = Vec::new();
        let figure = PlotData {
            estimated: nodes
                .iter()
                .map(|n| {
                    series(
                        format!("{} (fitted model)", info.nodes[*n]),
                        est[*n].clone(),
                        *n,
                    )
                })
                .collect(),
            measured: d
                .targets
                .iter()
                .map(|t| {
                    series(
                        format!("{} (measured -> {})", t.column, info.nodes[t.node]),
                        t.values_c.clone(),
                        t.node,
                    )
                })
                .collect(),
            residuals: d
                .targets
                .iter()
                .map(|t| {
                    let r: Vec<f64> = est[t.node]
                        .iter()
                        .zip(&t.values_c)
                        .map(|(e, m)| e - m)
                        .collect();
                    let finite: Vec<f64> = r.iter().copied().filter(|v| v.is_finite()).collect();
                    let mse =
                        finite.iter().map(|v| v * v).sum::<f64>() / finite.len().max(1) as f64;
                    rms.push(format!("{} {:.3} K", t.column, mse.sqrt()));
                    series(format!("{} (model - measured)", t.column), r, t.node)
                })
                .collect(),
            currents: common::plotted(&d.drive.currents)
                .into_iter()
                .map(|i| {
                    series(
                        format!("{} [A]", info.inputs[i].name),
                        d.drive.currents[i].clone(),
                        i,
                    )
                })
                .collect(),
            node_limits: nodes
                .iter()
                .filter_map(|n| {
                    info.critical_c[*n].map(|c| crate::plot::NodeLimit {
                        node: info.nodes[*n].clone(),
                        kind: "critical".into(),
                        limit_c: c,
                        color: *n,
                    })
                })
                .collect(),
            ..PlotData::default()
        };
        let figure = PlotData {
            title: format!(
                "{}: fit on {} (RMSE {})",
                info.name,
                d.label,
                rms.join(", ")
            ),
            ..figure
        };
        let out = if data.len() == 1 {
            path.to_path_buf()
        } else {
            let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("fit");
            let ext = path.extension().and_then(|s| s.to_str()).unwrap_or("png");
            path.with_file_name(format!("{stem}-{}.{ext}", k + 1))
        };
        render(&figure, &out, 1200, 900)?;
        written.push(out);
    }
    Ok(written)
}

/// What `replay --plot` draws.
pub struct ReplayFigure<'a> {
    /// The model's nodes and inputs.
    pub info: &'a crate::sim::PlantInfo,
    /// The replayed trace (for the title).
    pub trace: &'a std::path::Path,
    /// The replay's inputs, row by row.
    pub drive: &'a crate::sim::Drive,
    /// The estimate `[node][row]` \[degC\].
    pub estimate: &'a [Vec<f64>],
    /// The `--truth` sensors (scored, not fused).
    pub truth: &'a [crate::observer::Sensor],
    /// The `--measure` sensors (fused).
    pub fused: &'a [crate::observer::Sensor],
    /// The alarm events.
    pub alarms: &'a [crate::observer::AlarmEvent],
    /// The alarm settings (each node's derated limit).
    pub settings: &'a crate::observer::AlarmSettings,
}

/// The replay figure: the estimates (at most 12 nodes, else the 8 hottest,
/// plus every node a sensor sits on), each drawn node's derated alarm limit
/// at the nominal ambient, truth and fused readings, warning, predictive
/// and shutdown events, the residual of every truth column and the
/// currents.
pub fn replay_figure(f: &ReplayFigure) -> PlotData {
    // Missing readings (NaN cells) are left out of a line, not drawn as
    // spikes to the axis.
    let series = |label: String, values: &Vec<f64>, color: usize| {
        let (time_s, values) = f
            .drive
            .time_s
            .iter()
            .zip(values)
            .filter(|(_, v)| !v.is_nan())
            .map(|(t, v)| (*t, *v))
            .unzip();
        Series {
            label,
            time_s,
            values,
            color,
        }
    };
    let mut nodes = common::plotted(f.estimate);
    for s in f.truth.iter().chain(f.fused) {
        if !nodes.contains(&s.node) {
            nodes.push(s.node);
        }
    }
    let events = |level: &str| -> Vec<(f64, String)> {
        f.alarms
            .iter()
            .filter(|e| e.level == level && e.kind != "cleared")
            .map(|e| (e.time_s, e.node.clone().unwrap_or_default()))
            .collect()
    };
    PlotData {
        title: format!("{}: replay of {}", f.info.name, f.trace.display()),
        estimated: nodes
            .iter()
            .map(|i| {
                series(
                    format!("{} (estimate)", f.info.nodes[*i]),
                    &f.estimate[*i],
                    *i,
                )
            })
            .collect(),
        measured: f
            .truth
            .iter()
            .map(|t| {
                series(
                    format!("{} (truth -> {})", t.column, f.info.nodes[t.node]),
                    &t.values_c,
                    t.node,
                )
            })
            .collect(),
        fused: f
            .fused
            .iter()
            .map(|m| {
                series(
                    format!("{} (fused -> {})", m.column, f.info.nodes[m.node]),
                    &m.values_c,
                    m.node,
                )
            })
            .collect(),
        residuals: f
            .truth
            .iter()
            .map(|t| {
                let r: Vec<f64> = f.estimate[t.node]
                    .iter()
                    .zip(&t.values_c)
                    .map(|(e, m)| e - m)
                    .collect();
                series(format!("{} (estimate - truth)", t.column), &r, t.node)
            })
            .collect(),
        currents: common::plotted(&f.drive.currents)
            .into_iter()
            .map(|i| {
                series(
                    format!("{} [A]", f.info.inputs[i].name),
                    &f.drive.currents[i],
                    i,
                )
            })
            .collect(),
        node_limits: nodes
            .iter()
            .filter_map(|i| {
                let critical_c = f.settings.critical_c.get(*i).copied().flatten()?;
                Some(crate::plot::NodeLimit {
                    node: f.info.nodes[*i].clone(),
                    kind: "alarm limit".into(),
                    limit_c: f
                        .settings
                        .rule
                        .alarm_limit_c(critical_c, f.settings.nominal_ambient_c),
                    color: *i,
                })
            })
            .collect(),
        limits: Vec::new(),
        alarms: events("shutdown"),
        warnings: events("warning"),
        predictive: events("predictive"),
    }
}
