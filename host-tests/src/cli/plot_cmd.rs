//! `coil-thermal plot`.

use anyhow::{bail, Context, Result};
use serde_json::json;

use super::common;
use super::common::StreamSensor;
use super::PlotArgs;
use crate::observer::{AlarmEvent, AlarmSettings, ReplayRow};
use crate::plot::{render, Decimated, PlotData, Series};
use crate::sim::PlantInfo;
use crate::trace::{ColumnExpr, Evaluator, TimeSource, TraceFile, TIME_COLUMN};

/// Runs `plot`. Both files are streamed, twice each (a scan, then the
/// series), and each series kept [`Decimated`] inside the window: memory
/// does not grow with their length.
pub fn run(a: PlotArgs) -> Result<()> {
    let window = (
        a.from_s.unwrap_or(f64::NEG_INFINITY),
        a.to_s.unwrap_or(f64::INFINITY),
    );
    let inside = |t: f64| (window.0..=window.1).contains(&t);
    let est = TraceFile::scan(&a.estimate, &TimeSource::default())?;
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
    let mut ev = Evaluator::new(&est);
    for c in &columns {
        ev.add(&ColumnExpr::Column(c.clone()), false);
    }
    let series = stream_series(&est, &mut ev, inside)?;
    for (i, (c, d)) in columns.iter().zip(series).enumerate() {
        if let Some(e) = ev.error(i) {
            return Err(e.into());
        }
        data.estimated.push(d.series(c.clone(), i));
    }
    if let Some(path) = &a.trace {
        let trace = TraceFile::scan(
            path,
            &TimeSource {
                column: a.time_column.clone(),
                sample_period_s: a.sample_period_s,
            },
        )?;
        let mut ev = Evaluator::new(&trace);
        // Each flag as the whole-trace code met it: its error, or its
        // expression's position, label and colour.
        let mut planned: Vec<Result<(usize, String, usize)>> = Vec::new();
        for m in &a.measure {
            planned.push((|| {
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
                Ok((ev.add(&expr, true), format!("{col} (measured)"), color))
            })());
        }
        let measures = planned.len();
        for (i, c) in a.currents.iter().enumerate() {
            planned.push((|| {
                let expr = ColumnExpr::parse(c)?;
                Ok((ev.add(&expr, false), format!("{c} [A]"), i))
            })());
        }
        let series = stream_series(&trace, &mut ev, inside)?;
        for (k, p) in planned.into_iter().enumerate() {
            let (i, label, color) = p?;
            if let Some(e) = ev.error(i) {
                return Err(e.into());
            }
            let s = series[i].series(label, color);
            if k < measures {
                data.measured.push(s);
            } else {
                data.currents.push(s);
            }
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

/// Every expression of `ev` over the rows of `file` inside the window,
/// decimated (a missing reading, `NaN`, is left out).
fn stream_series(
    file: &TraceFile,
    ev: &mut Evaluator,
    inside: impl Fn(f64) -> bool,
) -> Result<Vec<Decimated>> {
    let mut series = Vec::new();
    let mut values = Vec::new();
    let mut rows = file.rows()?;
    while let Some(row) = rows.next_row()? {
        ev.eval(&row, &mut values);
        series.resize(values.len(), Decimated::default());
        if inside(row.time_s) {
            for (d, v) in series.iter_mut().zip(&values) {
                d.push(row.time_s, *v);
            }
        }
    }
    Ok(series)
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

/// What `replay --plot` draws, gathered row by row in bounded memory
/// (each series [`Decimated`]).
pub struct ReplaySeries {
    /// Per node, the estimate \[degC\].
    estimate: Vec<Decimated>,
    /// Per node, the firmware observer's upper bound \[degC\] (empty for
    /// an estimator without one).
    upper: Vec<Decimated>,
    /// Per `--truth` sensor: its readings and the estimate minus them
    /// \[degC\], \[K\].
    truth: Vec<(StreamSensor, Decimated, Decimated)>,
    /// Per `--measure` sensor (fused): its readings \[degC\].
    fused: Vec<(StreamSensor, Decimated)>,
    /// Per input, the current \[A\].
    currents: Vec<Decimated>,
}

impl ReplaySeries {
    /// For `info`'s nodes and inputs and these sensors.
    pub fn new(info: &PlantInfo, truth: &[StreamSensor], fused: &[StreamSensor]) -> Self {
        Self {
            estimate: vec![Decimated::default(); info.nodes.len()],
            upper: Vec::new(),
            truth: truth
                .iter()
                .map(|s| (s.clone(), Decimated::default(), Decimated::default()))
                .collect(),
            fused: fused
                .iter()
                .map(|s| (s.clone(), Decimated::default()))
                .collect(),
            currents: vec![Decimated::default(); info.inputs.len()],
        }
    }

    /// Adds a replayed row (fused readings after `fuse_until_s` \[s\] are
    /// not fused, and not drawn).
    pub fn push(&mut self, r: &ReplayRow, fuse_until_s: Option<f64>) {
        let t = r.row.time_s;
        for (d, v) in self.estimate.iter_mut().zip(r.estimate_c) {
            d.push(t, *v);
        }
        if let Some(p) = r.protected {
            if self.upper.is_empty() {
                self.upper = vec![Decimated::default(); p.upper_c.len()];
            }
            for (d, v) in self.upper.iter_mut().zip(&p.upper_c) {
                d.push(t, *v);
            }
        }
        for (s, readings, residual) in &mut self.truth {
            let m = r.row.extra[s.slot];
            readings.push(t, m);
            residual.push(t, r.estimate_c[s.node] - m);
        }
        let after = fuse_until_s.is_some_and(|u| t > u);
        for (s, readings) in &mut self.fused {
            readings.push(t, if after { f64::NAN } else { r.row.extra[s.slot] });
        }
        for (d, i) in self.currents.iter_mut().zip(&r.row.currents) {
            d.push(t, *i);
        }
    }

    /// The replay figure: the estimates (at most 12 nodes, else the 8
    /// hottest, plus every node a sensor sits on), each drawn node's
    /// derated alarm limit at the nominal ambient, truth and fused
    /// readings, warning, predictive and shutdown events, the residual of
    /// every truth column and the currents.
    pub fn figure(
        &self,
        info: &PlantInfo,
        trace: &std::path::Path,
        alarms: &[AlarmEvent],
        settings: &AlarmSettings,
    ) -> PlotData {
        let maxima: Vec<f64> = self.estimate.iter().map(Decimated::max).collect();
        let mut nodes = common::plotted_by_max(&maxima);
        for s in self
            .truth
            .iter()
            .map(|t| &t.0)
            .chain(self.fused.iter().map(|f| &f.0))
        {
            if !nodes.contains(&s.node) {
                nodes.push(s.node);
            }
        }
        let events = |level: &str| -> Vec<(f64, String)> {
            alarms
                .iter()
                .filter(|e| e.level == level && e.kind != "cleared")
                .map(|e| (e.time_s, e.node.clone().unwrap_or_default()))
                .collect()
        };
        let current_max: Vec<f64> = self.currents.iter().map(Decimated::max).collect();
        PlotData {
            title: format!("{}: replay of {}", info.name, trace.display()),
            estimated: nodes
                .iter()
                .map(|i| self.estimate[*i].series(format!("{} (estimate)", info.nodes[*i]), *i))
                .collect(),
            // The bound the protection acts on, for each drawn node with a
            // limit (the others' bound protects nothing).
            upper: nodes
                .iter()
                .filter(|i| settings.critical_c.get(**i).copied().flatten().is_some())
                .filter_map(|i| {
                    let u = self.upper.get(*i)?;
                    Some(u.series(format!("{} (upper bound)", info.nodes[*i]), *i))
                })
                .collect(),
            measured: self
                .truth
                .iter()
                .map(|(t, readings, _)| {
                    readings.series(
                        format!("{} (truth -> {})", t.column, info.nodes[t.node]),
                        t.node,
                    )
                })
                .collect(),
            fused: self
                .fused
                .iter()
                .map(|(m, readings)| {
                    readings.series(
                        format!("{} (fused -> {})", m.column, info.nodes[m.node]),
                        m.node,
                    )
                })
                .collect(),
            residuals: self
                .truth
                .iter()
                .map(|(t, _, residual)| {
                    residual.series(format!("{} (estimate - truth)", t.column), t.node)
                })
                .collect(),
            currents: common::plotted_by_max(&current_max)
                .into_iter()
                .map(|i| self.currents[i].series(format!("{} [A]", info.inputs[i].name), i))
                .collect(),
            node_limits: nodes
                .iter()
                .filter_map(|i| {
                    let critical_c = settings.critical_c.get(*i).copied().flatten()?;
                    Some(crate::plot::NodeLimit {
                        node: info.nodes[*i].clone(),
                        kind: "alarm limit".into(),
                        limit_c: settings
                            .rule
                            .alarm_limit_c(critical_c, settings.nominal_ambient_c),
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
}
