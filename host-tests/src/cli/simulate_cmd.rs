//! `coil-thermal simulate`.

use anyhow::{bail, Result};
use serde_json::json;

use super::common::{self, ModelSpec, NOT_YET};
use super::SimulateArgs;
use crate::plot::{render, PlotData, Series};
use crate::sim::{by_node, initial_temps, simulate, Drive};
use crate::trace::write_csv;

/// Runs `simulate`.
pub fn run(a: SimulateArgs) -> Result<()> {
    let grid_flags = a.rows.is_some() || a.cols.is_some() || a.pattern.is_some();
    if grid_flags && ModelSpec::parse(&a.model.model)? != ModelSpec::Hppa {
        bail!("--rows, --cols and --pattern apply to --model hppa only");
    }
    let mut plant = common::plant(&a.model)?;
    if grid_flags {
        // Reached only once the grid plant exists (stage 2).
        bail!("--pattern is {NOT_YET}");
    }
    let info = plant.info().clone();
    let bind = common::bindings(&a.trace_args)?;
    let drive = match &a.trace {
        Some(path) => {
            if a.ambient_c.is_some() {
                bail!("--ambient-c applies to constant currents; with --trace use --boundary COL=NAME or --const COL=VALUE");
            }
            let trace = common::read_trace(path, a.trace_args.sample_period_s)?;
            Drive::from_trace(&info, &trace, &bind)?
        }
        None => {
            let Some(duration) = a.duration_s else {
                bail!("give --duration-s S with --current-a, or --trace IN.csv");
            };
            if a.current_a.is_empty() {
                bail!("give --current-a A[,A...] (or --trace IN.csv)");
            }
            if let Some(bad) = a.current_a.iter().find(|v| !v.is_finite()) {
                bail!("--current-a must be finite, got {bad}");
            }
            if let Some(t) = a.ambient_c.filter(|t| !t.is_finite()) {
                bail!("--ambient-c must be finite, got {t}");
            }
            Drive::constant(&info, duration, a.dt_s, &a.current_a, a.ambient_c, &bind)?
        }
    };
    let init = initial_temps(&info, &drive, &[])?;
    let states = by_node(&simulate(plant.as_mut(), &drive, &init));
    write_csv(&a.out, &info.nodes, &drive.time_s, &states)?;
    if let Some(path) = &a.write_model {
        std::fs::write(path, common::model_file(&a.model)?.to_toml()?)?;
    }
    if let Some(path) = &a.plot {
        let data = PlotData {
            title: format!("{}: simulation", info.name),
            estimated: info
                .nodes
                .iter()
                .zip(&states)
                .enumerate()
                .map(|(i, (n, v))| Series {
                    label: n.clone(),
                    time_s: drive.time_s.clone(),
                    values: v.clone(),
                    color: i,
                })
                .collect(),
            currents: info
                .inputs
                .iter()
                .zip(&drive.currents)
                .enumerate()
                .map(|(i, (ch, v))| Series {
                    label: format!("{} [A]", ch.name),
                    time_s: drive.time_s.clone(),
                    values: v.clone(),
                    color: i,
                })
                .collect(),
            limits: info
                .nodes
                .iter()
                .zip(&info.critical_c)
                .filter_map(|(n, c)| c.map(|c| (format!("{n} critical {c} degC"), c)))
                .take(1)
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
    let summary = json!({
        "command": "simulate",
        "model": info.name,
        "nodes": info.nodes,
        "rows": drive.len(),
        "duration_s": drive.time_s[last] - drive.time_s[0],
        "final_c": final_c,
        "max_c": max_c,
        "hot_spot": {"node": info.nodes[hot.0], "max_c": hot.1, "time_s": hot.2},
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
    }
    Ok(())
}
