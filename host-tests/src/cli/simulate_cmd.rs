//! `coil-thermal simulate`.

use anyhow::{bail, Context, Result};
use serde_json::json;

use coil_thermal::omnimagnet::{Omnimagnet, Preset, EXPERIMENT_STOP_C};

use super::common::{self, ModelSpec};
use super::SimulateArgs;
use crate::devices;
use crate::model_file::InputHold;
use crate::plot::{render, Decimated, PlotData};
use crate::sim::{
    check_row_temperatures, Drive, InputRow, PlantInfo, RowSource, TraceDrive, Work, MAX_CELLS,
    MAX_ROWS,
};
use crate::synth::Rng;
use crate::trace::{CsvOut, TraceFile};

/// Runs `simulate`.
pub fn run(a: SimulateArgs) -> Result<()> {
    let spec = ModelSpec::parse(&a.model.model)?;
    if a.pattern.is_some() && spec != ModelSpec::Hppa {
        bail!("--pattern applies to --model hppa only");
    }
    if a.preset.is_some() && spec != ModelSpec::Omnimagnet {
        bail!("--preset applies to --model omnimagnet only");
    }
    if let Some(k) = a.noise_k.filter(|k| !(k.is_finite() && *k >= 0.0)) {
        bail!("--noise-k must be finite and >= 0 K, got {k}");
    }
    let mut plant = common::plant(&a.model)?;
    let info = plant.info().clone();
    common::check_current_a_has_inputs(&a.current_a, &info.name, info.inputs.len())?;
    let bind = common::bindings(&a.trace_args)?;
    if let Some(t) = a.ambient_c.filter(|t| !t.is_finite()) {
        bail!("--ambient-c must be finite, got {t}");
    }
    let mut preset_init = None;
    let mut preset_name = None;
    // A trace is streamed; the other drives are generated in memory.
    let file = match &a.trace {
        Some(path) => {
            if a.ambient_c.is_some() {
                bail!("--ambient-c applies to constant currents; with --trace use --boundary COL=NAME or --const COL=VALUE");
            }
            Some(common::scan_trace(path, &a.trace_args)?)
        }
        None => None,
    };
    let mut trace_drive = match &file {
        Some(f) => Some(TraceDrive::new(&info, f, &bind, InputHold::Start)?),
        None => None,
    };
    let memory = if trace_drive.is_some() {
        None
    } else if let Some(pattern) = a.pattern {
        let (rows, cols) = common::grid_dims(&a.model);
        let amps = match a.current_a.as_slice() {
            [] => 0.7,
            [i] if i.is_finite() => *i,
            _ => bail!("--pattern takes one --current-a value (the driven coils' current) [A]"),
        };
        let currents: Vec<f64> = (0..info.inputs.len())
            .map(|k| {
                if devices::pattern_on(pattern.name(), rows, cols, k / cols, k % cols) {
                    amps
                } else {
                    0.0
                }
            })
            .collect();
        let duration = a.duration_s.unwrap_or(1800.0);
        Some(Drive::constant(
            &info,
            duration,
            a.dt_s,
            &currents,
            a.ambient_c,
            &bind,
        )?)
    } else if let Some(name) = &a.preset {
        let preset = devices::omnimagnet_preset(name)?;
        if preset != Preset::PassiveCooling {
            preset_name = Some(preset.name());
        }
        let ambient = a.ambient_c.unwrap_or(devices::OMNIMAGNET_DEFAULT_AMBIENT_C);
        let default_duration = if matches!(preset, Preset::RotatingDipole { .. }) {
            600.0
        } else {
            Preset::DURATION_S
        };
        let duration = a.duration_s.unwrap_or(default_duration);
        let dt = a.dt_s.min(preset.step_s());
        let mut drive = Drive::constant(&info, duration, dt, &[0.0], Some(ambient), &bind)?;
        for (k, t) in drive.time_s.iter().enumerate() {
            // Currents at the interval's midpoint (as Preset::run).
            let i = preset.currents_a(t + 0.5 * dt);
            for (m, series) in drive.currents.iter_mut().enumerate() {
                series[k] = i[m];
            }
        }
        let init = preset.initial_temps_c(&Omnimagnet::PAPER, ambient);
        preset_init = Some(init.to_vec());
        Some(drive)
    } else {
        let Some(duration) = a.duration_s else {
            bail!("give --duration-s S with --current-a, or --trace IN.csv");
        };
        // A model without a current input runs on its other heat (fixed
        // powers, losses of `--const` signals) without one.
        if a.current_a.is_empty() && !info.inputs.is_empty() {
            bail!("give --current-a A[,A...] (or --trace IN.csv, --pattern, --preset)");
        }
        if let Some(bad) = a.current_a.iter().find(|v| !v.is_finite()) {
            bail!("--current-a must be finite, got {bad}");
        }
        Some(Drive::constant(
            &info,
            duration,
            a.dt_s,
            &a.current_a,
            a.ambient_c,
            &bind,
        )?)
    };
    // `--resample-s`: checked before the pass (a bad period would never
    // end it), refused after the trace's own errors.
    let resample_period = match (&file, a.resample_s) {
        (Some(f), Some(p)) => Some(resample_check(f, &info, p)),
        _ => None,
    };
    let period = resample_period
        .as_ref()
        .and_then(|r| r.as_ref().ok())
        .copied();
    let window = common::window(&a.window);
    let inside = |t: f64| (window.0..=window.1).contains(&t);
    // The pass before the run: the trace's errors, the first row, the
    // model's work and the rows in the window.
    let mut first: Option<InputRow> = None;
    let mut work = Work::default();
    let mut rows_inside = 0usize;
    let (mut t_first, mut t_last) = (f64::NAN, f64::NAN);
    {
        let mut source = source(&mut trace_drive, memory.as_ref(), period)?;
        while let Some(row) = source.next_row()? {
            work.push(plant.as_ref(), row.time_s);
            rows_inside += usize::from(inside(row.time_s));
            if first.is_none() {
                t_first = row.time_s;
            }
            t_last = row.time_s;
            first.get_or_insert(row);
        }
    }
    if let Some(d) = trace_drive.as_mut() {
        d.check()?;
    }
    if let Some(r) = resample_period {
        r?;
    }
    let first = first.context("the run has no row")?;
    let init = match preset_init {
        Some(t) => t,
        None => crate::sim::initial_temps_at(&info, &first.boundaries, &[])?,
    };
    common::check_window(&a.window, rows_inside, t_first, t_last)?;
    work.check(plant.as_ref(), "simulate")?;
    // The run starts at the first row; only its output is windowed.
    let mut names = info.nodes.clone();
    if a.with_inputs {
        names.extend(info.inputs.iter().map(|ch| ch.column.clone()));
        names.extend(info.boundaries.iter().map(|ch| ch.column.clone()));
    }
    let mut out = CsvOut::create(&a.out, &names)?;
    // The noise of node `i` at window row `k` is draw `i * rows + k` of
    // one generator, as when it was added node by node.
    let noise = a.noise_k.filter(|k| *k > 0.0);
    let mut rngs: Vec<Rng> = (0..info.nodes.len())
        .map(|i| Rng::new(a.seed).skipping_normals((i * rows_inside) as u64))
        .collect();
    let n = info.nodes.len();
    let mut hot = common::HotSpot::new(n);
    let mut final_c = vec![f64::NAN; n];
    let mut first_critical: Vec<Option<f64>> = vec![None; n];
    let mut first_stop: Vec<Option<f64>> = vec![None; n];
    let mut figure = a.plot.as_ref().map(|_| {
        (
            vec![Decimated::default(); n],
            vec![Decimated::default(); info.inputs.len()],
        )
    });
    let (mut t0, mut t1) = (f64::NAN, f64::NAN);
    let mut values = Vec::with_capacity(names.len());
    plant.reset(&init);
    let mut source = source(&mut trace_drive, memory.as_ref(), period)?;
    let mut prev: Option<InputRow> = None;
    while let Some(row) = source.next_row()? {
        if let Some(p) = &prev {
            plant.step(
                row.time_s - p.time_s,
                &p.currents,
                &p.boundaries,
                &p.signals,
            );
        }
        let t = row.time_s;
        let temps = plant.temps_c();
        check_row_temperatures(&info, t, temps, "simulate")?;
        if inside(t) {
            if t0.is_nan() {
                t0 = t;
            }
            t1 = t;
            hot.push(t, temps);
            final_c.copy_from_slice(temps);
            for (i, v) in temps.iter().enumerate() {
                if let Some(limit_c) = info.critical_c[i] {
                    if first_critical[i].is_none() && *v >= limit_c {
                        first_critical[i] = Some(t);
                    }
                }
                if first_stop[i].is_none() && *v >= EXPERIMENT_STOP_C {
                    first_stop[i] = Some(t);
                }
            }
            values.clear();
            match noise {
                Some(sigma) => values.extend(
                    temps
                        .iter()
                        .zip(&mut rngs)
                        .map(|(v, rng)| v + sigma * rng.normal()),
                ),
                None => values.extend_from_slice(temps),
            }
            if a.with_inputs {
                values.extend_from_slice(&row.currents);
                values.extend_from_slice(&row.boundaries);
            }
            out.row(t, values.iter().copied())?;
            if let Some((nodes, currents)) = figure.as_mut() {
                nodes.iter_mut().zip(temps).for_each(|(d, v)| d.push(t, *v));
                currents
                    .iter_mut()
                    .zip(&row.currents)
                    .for_each(|(d, v)| d.push(t, *v));
            }
        }
        prev = Some(row);
    }
    drop(source);
    out.finish()?;
    if let Some(path) = &a.write_model {
        std::fs::write(path, common::model_file(&a.model)?.to_toml()?)?;
    }
    let maxima: Vec<f64> = hot.max.iter().map(|m| m.0).collect();
    if let (Some(path), Some((nodes, currents))) = (&a.plot, &figure) {
        let current_max: Vec<f64> = currents.iter().map(Decimated::max).collect();
        let data = PlotData {
            title: format!("{}: simulation", info.name),
            estimated: common::plotted_by_max(&maxima)
                .into_iter()
                .enumerate()
                .map(|(c, i)| nodes[i].series(info.nodes[i].clone(), c))
                .collect(),
            currents: common::plotted_by_max(&current_max)
                .into_iter()
                .map(|i| currents[i].series(format!("{} [A]", info.inputs[i].name), i))
                .collect(),
            node_limits: common::plotted_by_max(&maxima)
                .into_iter()
                .enumerate()
                .filter_map(|(c, i)| {
                    info.critical_c[i].map(|limit_c| crate::plot::NodeLimit {
                        node: info.nodes[i].clone(),
                        kind: "critical".into(),
                        limit_c,
                        color: c,
                    })
                })
                .collect(),
            ..PlotData::default()
        };
        render(&data, path, 1200, 800)?;
    }
    let hot = hot.hottest();
    let mut max_c = serde_json::Map::new();
    let mut final_map = serde_json::Map::new();
    for (i, node) in info.nodes.iter().enumerate() {
        max_c.insert(node.clone(), json!(maxima[i]));
        final_map.insert(node.clone(), json!(final_c[i]));
    }
    // First time each node passes its critical temperature, and for an
    // Omnimagnet heating preset the paper's experiment stop (115 degC on a
    // solenoid): what a reader checks the model against.
    let mut critical = serde_json::Map::new();
    for (i, limit) in info.critical_c.iter().enumerate() {
        if let Some(limit_c) = limit {
            critical.insert(
                info.nodes[i].clone(),
                json!({"critical_c": limit_c, "first_time_s": first_critical[i]}),
            );
        }
    }
    let experiment_stop = preset_name.map(|_| {
        let stop_s = Omnimagnet::PAPER
            .geometry()
            .solenoids
            .iter()
            .filter_map(|s| first_stop[s.node])
            .reduce(f64::min);
        json!({"stop_c": EXPERIMENT_STOP_C, "first_time_s": stop_s})
    });
    let final_c = final_map;
    let duration_s = t1 - t0;
    let summary = json!({
        "command": "simulate",
        "model": info.name,
        "nodes": info.nodes,
        "rows": rows_inside,
        "duration_s": duration_s,
        "final_c": final_c,
        "max_c": max_c,
        "hot_spot": {"node": info.nodes[hot.0], "max_c": hot.1, "time_s": hot.2},
        "critical": critical,
        "experiment_stop": experiment_stop,
        "out": a.out.display().to_string(),
        "plot": a.plot.as_ref().map(|p| p.display().to_string()),
    });
    if a.json {
        common::print_json(&summary);
    } else {
        println!(
            "simulated `{}`: {} nodes, {} rows over {:.3} s -> {}",
            info.name,
            info.nodes.len(),
            rows_inside,
            duration_s,
            a.out.display()
        );
        println!("{:<24} {:>12} {:>12}", "node", "final [degC]", "max [degC]");
        for n in &info.nodes {
            println!(
                "{:<24} {:>12.3} {:>12.3}",
                n,
                final_c[n].as_f64().unwrap_or(f64::NAN),
                max_c[n].as_f64().unwrap_or(0.0)
            );
        }
        println!(
            "hot spot: {} at {:.3} degC (t = {:.1} s)",
            info.nodes[hot.0], hot.1, hot.2
        );
        for (name, c) in &critical {
            if let Some(t) = c["first_time_s"].as_f64() {
                println!(
                    "critical: {name} reaches {:.1} degC at t = {t:.1} s",
                    c["critical_c"].as_f64().unwrap_or(f64::NAN)
                );
            }
        }
        if let Some(stop) = &experiment_stop {
            match stop["first_time_s"].as_f64() {
                Some(t) => println!(
                    "experiment stop: a solenoid reaches {EXPERIMENT_STOP_C} degC at t = {t:.1} s \
                     (the paper's heating runs stopped there, or after 2 h)"
                ),
                None => println!("experiment stop: no solenoid reaches {EXPERIMENT_STOP_C} degC"),
            }
        }
    }
    Ok(())
}

/// Refuses `--resample-s` as the whole-trace code did: a period that is
/// not finite and positive, or more output rows or values than a run
/// writes; returns the period \[s\].
fn resample_check(file: &TraceFile, info: &PlantInfo, period_s: f64) -> Result<f64> {
    if !(period_s.is_finite() && period_s > 0.0) {
        bail!("--resample-s must be finite and > 0 s, got {period_s}");
    }
    let (t0, t1) = (file.first_time_s(), file.last_time_s());
    let steps_f = ((t1 - t0) / period_s).floor();
    let channels = info.inputs.len() + info.boundaries.len() + info.signals.len() + 1;
    if steps_f + 1.0 > MAX_ROWS as f64 || (steps_f + 1.0) * channels as f64 > MAX_CELLS as f64 {
        bail!(
            "--resample-s {} s over the trace's {:.3} s is {:.3e} rows; at most {MAX_ROWS} rows \
             and {MAX_CELLS:.0e} values are written: raise --resample-s",
            crate::trace::num(period_s),
            t1 - t0,
            steps_f + 1.0
        );
    }
    Ok(period_s)
}

/// The run's rows: the trace's (every `period_s` with `--resample-s`), or
/// the generated drive's.
fn source<'s>(
    trace: &'s mut Option<TraceDrive<'_>>,
    memory: Option<&'s Drive>,
    period_s: Option<f64>,
) -> Result<Box<dyn RowSource + 's>> {
    Ok(match (trace.as_mut(), memory) {
        (Some(t), _) => {
            let (t0, t1) = (t.file().first_time_s(), t.file().last_time_s());
            let rows = t.rows()?;
            match period_s {
                Some(p) => Box::new(Resampled::new(Box::new(rows), t0, t1, p)),
                None => Box::new(rows),
            }
        }
        (None, Some(d)) => Box::new(d.rows()),
        (None, None) => bail!("no input rows"),
    })
}

/// Rows sampled every `period_s` from the first time `t0` to the last
/// `t1`, each sample holding the inputs of the last row at or before it
/// (the last sample at `t1` when the grid stops short of it).
struct Resampled<'s> {
    rows: Box<dyn RowSource + 's>,
    t0: f64,
    t1: f64,
    period_s: f64,
    steps: usize,
    k: usize,
    extra_end: bool,
    current: Option<InputRow>,
    next: Option<InputRow>,
    started: bool,
}

impl<'s> Resampled<'s> {
    fn new(rows: Box<dyn RowSource + 's>, t0: f64, t1: f64, period_s: f64) -> Self {
        let steps = ((t1 - t0) / period_s).floor() as usize;
        let extra_end = t1 - (t0 + steps as f64 * period_s) > 1e-9 * period_s.max(1.0);
        Self {
            rows,
            t0,
            t1,
            period_s,
            steps,
            k: 0,
            extra_end,
            current: None,
            next: None,
            started: false,
        }
    }
}

impl RowSource for Resampled<'_> {
    fn next_row(&mut self) -> Result<Option<InputRow>> {
        if !self.started {
            self.started = true;
            self.current = self.rows.next_row()?;
            self.next = self.rows.next_row()?;
        }
        let t = if self.k <= self.steps {
            self.t0 + self.k as f64 * self.period_s
        } else if self.k == self.steps + 1 && self.extra_end {
            self.t1
        } else {
            return Ok(None);
        };
        while self.next.as_ref().is_some_and(|n| n.time_s <= t) {
            self.current = self.next.take();
            self.next = self.rows.next_row()?;
        }
        let Some(row) = self.current.as_ref() else {
            return Ok(None);
        };
        let out = InputRow {
            index: self.k,
            time_s: t,
            ..row.clone()
        };
        self.k += 1;
        Ok(Some(out))
    }
}
