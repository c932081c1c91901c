//! `coil-thermal simulate`.

use anyhow::{bail, Result};
use serde_json::json;

use coil_thermal::omnimagnet::{Omnimagnet, Preset, EXPERIMENT_STOP_C};

use super::common::{self, ModelSpec};
use super::SimulateArgs;
use crate::devices;
use crate::plot::{render, PlotData, Series};
use crate::sim::{
    by_node, check_temperatures, check_work, initial_temps, simulate, Drive, MAX_CELLS, MAX_ROWS,
};
use crate::synth::Rng;
use crate::trace::write_csv;

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
    let bind = common::bindings(&a.trace_args)?;
    if let Some(t) = a.ambient_c.filter(|t| !t.is_finite()) {
        bail!("--ambient-c must be finite, got {t}");
    }
    let mut preset_init = None;
    let mut preset_name = None;
    let drive = if let Some(path) = &a.trace {
        if a.ambient_c.is_some() {
            bail!("--ambient-c applies to constant currents; with --trace use --boundary COL=NAME or --const COL=VALUE");
        }
        let trace = common::read_trace(path, &a.trace_args)?;
        let drive = Drive::from_trace(&info, &trace, &bind)?;
        match a.resample_s {
            Some(s) => resample(&drive, s)?,
            None => drive,
        }
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
        Drive::constant(&info, duration, a.dt_s, &currents, a.ambient_c, &bind)?
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
        drive
    } else {
        let Some(duration) = a.duration_s else {
            bail!("give --duration-s S with --current-a, or --trace IN.csv");
        };
        if a.current_a.is_empty() {
            bail!("give --current-a A[,A...] (or --trace IN.csv, --pattern, --preset)");
        }
        if let Some(bad) = a.current_a.iter().find(|v| !v.is_finite()) {
            bail!("--current-a must be finite, got {bad}");
        }
        Drive::constant(&info, duration, a.dt_s, &a.current_a, a.ambient_c, &bind)?
    };
    let init = match preset_init {
        Some(t) => t,
        None => initial_temps(&info, &drive, &[])?,
    };
    let window = common::window_rows(&a.window, &drive.time_s)?;
    check_work(plant.as_ref(), &drive.time_s, "simulate")?;
    let states = by_node(&simulate(plant.as_mut(), &drive, &init));
    check_temperatures(&info, &drive.time_s, &states, "simulate")?;
    // The run starts at the first row; only its output is windowed.
    let states: Vec<Vec<f64>> = states.iter().map(|s| s[window.clone()].to_vec()).collect();
    let drive = common::drive_window(&drive, &window);
    let mut names = info.nodes.clone();
    let mut written = states.clone();
    if let Some(sigma) = a.noise_k.filter(|k| *k > 0.0) {
        let mut rng = Rng::new(a.seed);
        for series in &mut written {
            for v in series.iter_mut() {
                *v += sigma * rng.normal();
            }
        }
    }
    if a.with_inputs {
        for (ch, series) in info.inputs.iter().zip(&drive.currents) {
            names.push(ch.column.clone());
            written.push(series.clone());
        }
        for (ch, series) in info.boundaries.iter().zip(&drive.boundaries) {
            names.push(ch.column.clone());
            written.push(series.clone());
        }
    }
    write_csv(&a.out, &names, &drive.time_s, &written)?;
    if let Some(path) = &a.write_model {
        std::fs::write(path, common::model_file(&a.model)?.to_toml()?)?;
    }
    if let Some(path) = &a.plot {
        let data = PlotData {
            title: format!("{}: simulation", info.name),
            estimated: common::plotted(&states)
                .into_iter()
                .enumerate()
                .map(|(c, i)| Series {
                    label: info.nodes[i].clone(),
                    time_s: drive.time_s.clone(),
                    values: states[i].clone(),
                    color: c,
                })
                .collect(),
            currents: common::plotted(&drive.currents)
                .into_iter()
                .map(|i| (i, (&info.inputs[i], &drive.currents[i])))
                .map(|(i, (ch, v))| Series {
                    label: format!("{} [A]", ch.name),
                    time_s: drive.time_s.clone(),
                    values: v.clone(),
                    color: i,
                })
                .collect(),
            node_limits: common::plotted(&states)
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
    let last = drive.len() - 1;
    let mut hot = (0, f64::MIN, 0.0);
    let mut max_c = serde_json::Map::new();
    let mut final_c = serde_json::Map::new();
    for (i, s) in states.iter().enumerate() {
        let (k, m) =
            s.iter().enumerate().fold(
                (0, f64::MIN),
                |acc, (k, v)| if *v > acc.1 { (k, *v) } else { acc },
            );
        if m > hot.1 {
            hot = (i, m, drive.time_s[k]);
        }
        max_c.insert(info.nodes[i].clone(), json!(m));
        final_c.insert(info.nodes[i].clone(), json!(s[last]));
    }
    // First time each node passes its critical temperature, and for an
    // Omnimagnet heating preset the paper's experiment stop (115 degC on a
    // solenoid): what a reader checks the model against.
    let first_at = |series: &[f64], limit_c: f64| {
        series
            .iter()
            .position(|v| *v >= limit_c)
            .map(|k| drive.time_s[k])
    };
    let mut critical = serde_json::Map::new();
    for (i, limit) in info.critical_c.iter().enumerate() {
        if let Some(limit_c) = limit {
            critical.insert(
                info.nodes[i].clone(),
                json!({"critical_c": limit_c, "first_time_s": first_at(&states[i], *limit_c)}),
            );
        }
    }
    let experiment_stop = preset_name.map(|_| {
        let stop_s = Omnimagnet::PAPER
            .geometry()
            .solenoids
            .iter()
            .filter_map(|s| first_at(&states[s.node], EXPERIMENT_STOP_C))
            .reduce(f64::min);
        json!({"stop_c": EXPERIMENT_STOP_C, "first_time_s": stop_s})
    });
    let summary = json!({
        "command": "simulate",
        "model": info.name,
        "nodes": info.nodes,
        "rows": drive.len(),
        "duration_s": drive.time_s[last] - drive.time_s[0],
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
            drive.len(),
            drive.time_s[last] - drive.time_s[0],
            a.out.display()
        );
        println!("{:<24} {:>12} {:>12}", "node", "final [degC]", "max [degC]");
        for (i, n) in info.nodes.iter().enumerate() {
            println!(
                "{:<24} {:>12.3} {:>12.3}",
                n,
                states[i][last],
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

/// The drive sampled every `period_s` from its first time to its last, each
/// sample holding the inputs of the last row at or before it.
fn resample(drive: &Drive, period_s: f64) -> Result<Drive> {
    if !(period_s.is_finite() && period_s > 0.0) {
        bail!("--resample-s must be finite and > 0 s, got {period_s}");
    }
    let (t0, t1) = (drive.time_s[0], drive.time_s[drive.len() - 1]);
    let steps_f = ((t1 - t0) / period_s).floor();
    let channels = drive.currents.len() + drive.boundaries.len() + drive.signals.len() + 1;
    if steps_f + 1.0 > MAX_ROWS as f64 || (steps_f + 1.0) * channels as f64 > MAX_CELLS as f64 {
        bail!(
            "--resample-s {} s over the trace's {:.3} s is {:.3e} rows; at most {MAX_ROWS} rows \
             and {MAX_CELLS:.0e} values are written: raise --resample-s",
            crate::trace::num(period_s),
            t1 - t0,
            steps_f + 1.0
        );
    }
    let steps = steps_f as usize;
    let mut time_s: Vec<f64> = (0..=steps).map(|k| t0 + k as f64 * period_s).collect();
    if t1 - time_s[steps] > 1e-9 * period_s.max(1.0) {
        time_s.push(t1);
    }
    let mut rows = Vec::with_capacity(time_s.len());
    let mut k = 0;
    for t in &time_s {
        while k + 1 < drive.len() && drive.time_s[k + 1] <= *t {
            k += 1;
        }
        rows.push(k);
    }
    let pick = |series: &Vec<Vec<f64>>| -> Vec<Vec<f64>> {
        series
            .iter()
            .map(|s| rows.iter().map(|&k| s[k]).collect())
            .collect()
    };
    Ok(Drive {
        currents: pick(&drive.currents),
        boundaries: pick(&drive.boundaries),
        signals: pick(&drive.signals),
        time_s,
    })
}
