//! `coil-thermal limits` and `alarm-limit`, on `coil_thermal::protect`.

use anyhow::{bail, Context, Result};
use coil_thermal::nalgebra::Const;
use coil_thermal::omnimagnet::{Omnimagnet, EXPERIMENT_STOP_C, NODES, NODE_NAMES};
use coil_thermal::protect::derating::DeratingRule;
use coil_thermal::protect::study::{
    max_safe_current_a, max_safe_time_s, StudyLimits, POWERED_COMBINATIONS,
};
use serde_json::json;

use super::common::{self, ModelSpec};
use super::{AlarmLimitArgs, LimitsArgs};
use crate::devices;
use crate::limits::{compute, LimitsQuery, Safe};
use crate::model_file::Model;

/// Runs `alarm-limit`.
pub fn alarm_limit(a: AlarmLimitArgs) -> Result<()> {
    if !(a.critical_c.is_finite() && a.ambient_c.is_finite()) {
        bail!("--critical-c and --ambient-c must be finite");
    }
    let rule = common::derating_rule(&a.factors, DeratingRule::hppa())?;
    let limit = rule.alarm_limit_c(a.critical_c, a.ambient_c);
    let factors: Vec<_> = rule
        .factors()
        .iter()
        .map(|f| json!({"name": f.name, "value": f.value}))
        .collect();
    if a.json {
        common::print_json(&json!({
            "command": "alarm-limit",
            "critical_c": a.critical_c,
            "ambient_c": a.ambient_c,
            "factors": factors,
            "product": rule.product(),
            "alarm_limit_c": limit,
        }));
        return Ok(());
    }
    let list = rule
        .factors()
        .iter()
        .map(|f| format!("{} {}", f.name, f.value))
        .collect::<Vec<_>>()
        .join(" x ");
    println!("alarm limit = T_amb + (T_crit - T_amb) * product, capped at T_crit [degC]");
    println!(
        "  product = {} = {:.6}",
        if list.is_empty() {
            "1 (no factors)"
        } else {
            &list
        },
        rule.product()
    );
    println!(
        "  = {} + ({} - {}) * {:.6} = {:.2} degC",
        a.ambient_c,
        a.critical_c,
        a.ambient_c,
        rule.product(),
        limit
    );
    if a.factors.is_empty() {
        println!(
            "note: the HPPA report states 60 degC for its 100 degC coils at 20 degC ambient; its own factors give 65.36 degC (the report rounded down)"
        );
    }
    Ok(())
}

fn fmt_opt(v: Option<f64>, unit: &str) -> String {
    match v {
        Some(v) if v.is_infinite() => "unbounded".into(),
        Some(v) => format!("{v:.3} {unit}"),
        None => "never".into(),
    }
}

fn fmt_safe(s: &Safe, nodes: &[String], unit: &str) -> String {
    let value = match s.value {
        Some(v) => format!("{v:.4} {unit}"),
        None => "unbounded".into(),
    };
    let bind = s
        .binding_node
        .map(|i| format!(" (binding: {})", nodes[i]))
        .unwrap_or_default();
    let feas = if s.feasible { "" } else { " INFEASIBLE" };
    format!("{value}{bind}{feas}")
}

/// Runs `limits`.
pub fn limits(a: LimitsArgs) -> Result<()> {
    let spec = ModelSpec::parse(&a.model.model)?;
    if let Some(h) = a.horizon_s {
        if !(h.is_finite() && h > 0.0) {
            bail!("--horizon-s must be finite and > 0 s, got {h}");
        }
    }
    if let Some(t) = a.ambient_c.filter(|t| !t.is_finite()) {
        bail!("--ambient-c must be finite, got {t}");
    }
    if let Some(t) = a.limit_c.filter(|t| !t.is_finite()) {
        bail!("--limit-c must be finite, got {t}");
    }
    if let Some(bad) = a.current_a.iter().find(|v| !v.is_finite()) {
        bail!("--current-a must be finite, got {bad}");
    }
    if a.study {
        if spec != ModelSpec::Omnimagnet {
            bail!("--study applies to --model omnimagnet only");
        }
        return study(&a);
    }
    if a.pattern.is_some() && spec != ModelSpec::Hppa {
        bail!("--pattern applies to --model hppa only");
    }
    let op_c = a.ambient_c.unwrap_or(devices::OMNIMAGNET_DEFAULT_AMBIENT_C);
    let file = common::model_file_at(&a.model, op_c)?;
    let model = Model::build(&file)?;
    // A model file's element limits are derated as its firmware derates
    // them (the `[observer]` table's product, else codegen's 0.648); the
    // built-in devices by their own rules.
    let default_rule = match spec {
        ModelSpec::Hppa | ModelSpec::Omnimagnet => common::default_rule(&spec),
        _ => crate::firmware::FirmwareConfig::of(&model, file.observer.as_ref())?.rule(),
    };
    let rule = common::derating_rule(&a.factors, default_rule)?;
    if !model.signals.is_empty() {
        bail!(
            "limits: model `{}` needs signal columns ({}); constant-signal limits are not supported",
            model.name,
            model.signals.join(", ")
        );
    }
    // Currents per input.
    let inputs = &model.inputs;
    common::check_current_a_has_inputs(&a.current_a, &model.name, inputs.len())?;
    let per_input: Vec<f64> = if let Some(pattern) = a.pattern {
        let (rows, cols) = common::grid_dims(&a.model);
        let amps = match a.current_a.as_slice() {
            [] => 0.7,
            [i] => *i,
            _ => bail!("--pattern takes one --current-a value [A]"),
        };
        (0..inputs.len())
            .map(|k| {
                if devices::pattern_on(pattern.name(), rows, cols, k / cols, k % cols) {
                    amps
                } else {
                    0.0
                }
            })
            .collect()
    } else {
        match (a.current_a.len(), inputs.len()) {
            (0, 0) => Vec::new(),
            (0, _) => bail!("give --current-a A[,A...] (or --pattern for --model hppa)"),
            (1, m) => vec![a.current_a[0]; m],
            (n, m) if n == m => a.current_a.clone(),
            (n, m) => bail!(
                "--current-a has {n} values but model `{}` has {m} current inputs ({})",
                model.name,
                inputs
                    .iter()
                    .map(|i| i.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    };
    if model.has_voltage_drives() {
        bail!(
            "limits: model `{}` has a voltage-driven [[source]] (drive = \"pwm\" or \"voltage\"): \
             `limits` takes currents only; simulate or replay the duty instead",
            model.name
        );
    }
    let mut currents = Vec::new();
    model.effective_currents(&per_input, &[], &mut currents);
    let boundary_c: Vec<f64> = model
        .boundaries
        .iter()
        .map(|b| {
            a.ambient_c.or(b.value_c).with_context(|| {
                format!("boundary `{}` has no temperature: pass --ambient-c", b.name)
            })
        })
        .collect::<Result<_>>()?;
    let ambient = boundary_c.iter().sum::<f64>() / boundary_c.len().max(1) as f64;
    let limits_c: Vec<Option<f64>> = model
        .critical_c
        .iter()
        .map(|c| match a.limit_c {
            Some(l) => Some(l),
            None => c.map(|c| rule.alarm_limit_c(c, ambient)),
        })
        .collect();
    let Some(highest) = limits_c.iter().flatten().copied().reduce(f64::max) else {
        bail!(
            "model `{}` has no critical_c on any node: pass --limit-c C",
            model.name
        );
    };
    // The predictor evaluates each winding's R(T) at its node's limit, so
    // every node needs a finite one: nodes without a critical temperature
    // take the model's highest limit (marked "assumed").
    let assumed: Vec<bool> = limits_c.iter().map(Option::is_none).collect();
    let limits_c: Vec<Option<f64>> = limits_c
        .iter()
        .map(|l| Some(l.unwrap_or(highest)))
        .collect();
    // Sources per coil selection.
    let source_label = |k: usize| -> String {
        let input = &inputs[model.drives[k].input].name;
        let shared = model
            .drives
            .iter()
            .filter(|d| d.input == model.drives[k].input)
            .count()
            > 1;
        if shared {
            format!("{input}@{}", model.nodes[model.network.sources()[k].node])
        } else {
            input.clone()
        }
    };
    let coils: Vec<usize> = if a.coils.is_empty() {
        (0..currents.len())
            .filter(|&k| currents[k] != 0.0)
            .take(16)
            .collect()
    } else {
        let mut list = Vec::new();
        for name in &a.coils {
            let idx = inputs
                .iter()
                .position(|i| &i.name == name)
                .with_context(|| {
                    format!(
                        "--coil `{name}`: model `{}` has no such input (inputs: {})",
                        model.name,
                        inputs
                            .iter()
                            .map(|i| i.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                })?;
            list.extend((0..model.drives.len()).filter(|&k| model.drives[k].input == idx));
        }
        list
    };
    // The firmware's limiter, alarm and time to limit act on its upper
    // bound, not on the estimate: each element's limit for the model's
    // mean is the temperature at which that bound reaches its limit.
    let (mean_limits_c, bound) = mean_limits(&spec, &file, &model, &limits_c, &boundary_c)?;
    let query = LimitsQuery {
        network: model.network.clone(),
        currents_a: currents.clone(),
        boundary_c: boundary_c.clone(),
        limits_c: mean_limits_c.clone(),
        horizon_s: a.horizon_s,
        coils,
    };
    let report = compute(&query)?;
    let nodes = &model.nodes;
    let scaled = |s: &Safe| -> Option<Vec<f64>> {
        s.value
            .map(|k| per_input.iter().map(|i| i * k).collect::<Vec<f64>>())
    };
    if a.json {
        let mut ttl = serde_json::Map::new();
        let mut lim = serde_json::Map::new();
        let mut mean_lim = serde_json::Map::new();
        for (i, n) in nodes.iter().enumerate() {
            ttl.insert(n.clone(), json!(report.time_to_limit_s[i]));
            lim.insert(n.clone(), json!(limits_c[i]));
            mean_lim.insert(n.clone(), json!(mean_limits_c[i]));
        }
        let coils: Vec<_> = report
            .coils
            .iter()
            .map(|c| {
                json!({
                    "coil": source_label(c.source),
                    "current_a": currents[c.source],
                    "max_current_horizon_a": c.max_current_horizon_a,
                    "max_current_forever_a": c.max_current_forever_a,
                    "runaway_current_a": c.runaway_current_a,
                    "hot_spot_current_a": c.hot_spot_current_a,
                    "error": c.error,
                })
            })
            .collect();
        common::print_json(&json!({
            "command": "limits",
            "model": model.name,
            "currents_a": per_input,
            "boundary_c": boundary_c,
            "derating_product": if a.limit_c.is_some() { None } else { Some(rule.product()) },
            "limits_c": lim,
            "acts_on": "upper bound",
            "upper_bound": bound,
            "mean_limits_c": mean_lim,
            "assumed_limit_nodes": nodes.iter().zip(&assumed).filter(|(_, a)| **a).map(|(n, _)| n.clone()).collect::<Vec<_>>(),
            "time_to_limit_s": ttl,
            "horizon_s": a.horizon_s,
            "common_scale_horizon": report.common_scale_horizon,
            "common_scale_forever": report.common_scale_forever,
            "max_currents_horizon_a": report.common_scale_horizon.as_ref().and_then(scaled),
            "max_currents_forever_a": scaled(&report.common_scale_forever),
            "coils": coils,
            "slowest_time_constant_s": report.slowest_time_constant_s,
        }));
        return Ok(());
    }
    println!(
        "limits of `{}` at {} (boundaries {:?} degC), from equilibrium without current",
        model.name,
        if per_input.len() <= 6 {
            format!("{per_input:?} A")
        } else {
            format!(
                "{} driven inputs (max {:.3} A)",
                per_input.iter().filter(|i| **i != 0.0).count(),
                per_input.iter().fold(0.0f64, |m, i| m.max(i.abs()))
            )
        },
        boundary_c
    );
    match a.limit_c {
        Some(l) => println!("element limits: {l} degC (--limit-c)"),
        None => println!(
            "element limits: critical temperatures derated by product {:.4} at {ambient} degC",
            rule.product()
        ),
    }
    println!(
        "on the firmware's upper bound ({bound}): \"mean at limit\" is the estimate at which the bound reaches the limit"
    );
    println!(
        "{:<24} {:>12} {:>14} {:>14} {:>16}",
        "element", "limit [degC]", "mean at limit", "steady [degC]", "time to limit"
    );
    // Limit the table for large grids: the elements that reach their limit
    // first, then the hottest.
    let mut order: Vec<usize> = (0..nodes.len())
        .filter(|&i| limits_c[i].is_some())
        .collect();
    order.sort_by(|&x, &y| {
        let t = |i: usize| report.time_to_limit_s[i].unwrap_or(f64::INFINITY);
        let s = |i: usize| report.steady_c.as_ref().map_or(0.0, |v| -v[i]);
        t(x).total_cmp(&t(y)).then(s(x).total_cmp(&s(y)))
    });
    let shown = if nodes.len() > 20 { 10 } else { order.len() };
    for &i in order.iter().take(shown) {
        println!(
            "{:<24} {:>12} {:>14} {:>14} {:>16}",
            nodes[i],
            format!(
                "{:.2}{}",
                limits_c[i].unwrap_or(f64::NAN),
                if assumed[i] { "*" } else { "" }
            ),
            format!("{:.2}", mean_limits_c[i].unwrap_or(f64::NAN)),
            report
                .steady_c
                .as_ref()
                .map_or("none".into(), |v| format!("{:.2}", v[i])),
            fmt_opt(report.time_to_limit_s[i], "s")
        );
    }
    if assumed.iter().any(|a| *a) {
        println!("* no critical temperature: the model's highest limit is assumed");
    }
    if shown < order.len() {
        println!(
            "... {} more elements (use --json for all)",
            order.len() - shown
        );
    }
    if let (Some(h), Some(s)) = (a.horizon_s, &report.common_scale_horizon) {
        println!(
            "max common current scale for {h} s: {}",
            fmt_safe(s, nodes, "x")
        );
    }
    println!(
        "max common current scale for ever: {}",
        fmt_safe(&report.common_scale_forever, nodes, "x")
    );
    if !report.coils.is_empty() {
        if report
            .coils
            .iter()
            .any(|c| !c.max_current_forever_a.feasible)
        {
            println!("! infeasible: the other coils alone take some element past its limit");
        }
        println!(
            "{:<22} {:>10} {:>16} {:>16} {:>14} {:>14}",
            "coil", "I [A]", "max I horizon", "max I forever", "runaway [A]", "hot spot [A]"
        );
        for c in &report.coils {
            println!(
                "{:<22} {:>10.3} {:>16} {:>16} {:>14} {:>14}{}",
                source_label(c.source),
                currents[c.source],
                c.max_current_horizon_a
                    .as_ref()
                    .and_then(|s| s.value)
                    .map_or("-".into(), |v| format!("{v:.3}")),
                c.max_current_forever_a
                    .value
                    .map_or("unbounded".into(), |v| format!(
                        "{v:.3}{}",
                        if c.max_current_forever_a.feasible {
                            ""
                        } else {
                            "!"
                        }
                    )),
                c.runaway_current_a
                    .map_or("none".into(), |v| format!("{v:.3}")),
                c.hot_spot_current_a
                    .map_or("none".into(), |v| format!("{v:.3}")),
                c.error
                    .as_ref()
                    .map(|e| format!("  ({e})"))
                    .unwrap_or_default()
            );
        }
    }
    Ok(())
}

/// Each element's limit for the model's mean \[degC\]: the estimate at
/// which the upper bound the firmware protects on reaches `limits_c`
/// \[degC\] (`boundary_c` \[degC\] the boundaries), and a description of
/// that bound. The built-in devices: their flashed observers' margins (the
/// grid's on the rise above the colder of its coolant and ambient, the
/// Omnimagnet's `k sigma` and unmeasured margin); a model file: the
/// `NetworkObserver` `codegen` flashes from its `[observer]` table, at the
/// model's own size.
fn mean_limits(
    spec: &ModelSpec,
    file: &crate::model_file::ModelFile,
    model: &Model,
    limits_c: &[Option<f64>],
    boundary_c: &[f64],
) -> Result<(Vec<Option<f64>>, String)> {
    match spec {
        ModelSpec::Hppa => {
            let margin = coil_thermal::observer::grid::DEFAULT_MARGIN;
            let bound = coil_thermal::protect::margin::UpperBoundBuilder::<Const<1>>::new(margin)
                .build::<f64>()
                .map_err(|e| anyhow::anyhow!("the grid's upper bound: {e}"))?;
            let element = bound.elements()[0];
            let reference_c = boundary_c.iter().copied().fold(f64::INFINITY, f64::min);
            Ok((
                limits_c
                    .iter()
                    .map(|l| l.map(|l| element.mean_limit_c(l, reference_c)))
                    .collect(),
                format!(
                    "the grid observer's: {} x the rise above the colder of coolant and ambient, + {} K",
                    margin.rise_fraction, margin.offset_k
                ),
            ))
        }
        ModelSpec::Omnimagnet => {
            let observer = crate::codegen::omnimagnet_observer()?;
            let bound = observer.upper_bound();
            let reference_c = boundary_c.first().copied().unwrap_or(f64::NAN);
            Ok((
                limits_c
                    .iter()
                    .enumerate()
                    .map(|(i, l)| {
                        l.map(|l| {
                            bound.element(i).map_or(l, |e| {
                                f64::from(e.mean_limit_c(l as f32, reference_c as f32))
                            })
                        })
                    })
                    .collect(),
                "the flashed OmniObserver's: k sigma with its six thermocouples, and its margin on the unmeasured elements' rise".into(),
            ))
        }
        _ => {
            let config = crate::firmware::FirmwareConfig::of(model, file.observer.as_ref())?;
            let sensors = config.sensor_nodes.clone();
            let observer = crate::library_observer::ObserverEstimator::firmware(
                model.clone(),
                config.settings.loop_tick_us(),
                &config,
                &sensors,
            )
            .context(
                "limits act on the upper bound of the firmware's observer, which does not build",
            )?;
            Ok((
                observer.mean_limits_c(limits_c, boundary_c),
                format!(
                    "the firmware's NetworkObserver from {}: k sigma with its {} sensor(s), and the unmeasured margin",
                    if config.from_table { "the [observer] table" } else { "codegen's defaults" },
                    sensors.len()
                ),
            ))
        }
    }
}

fn combination_name(powered: &[bool; 3]) -> String {
    powered
        .iter()
        .enumerate()
        .filter(|(_, on)| **on)
        .map(|(k, _)| (k + 1).to_string())
        .collect::<Vec<_>>()
        .join("+")
}

/// The Omnimagnet study: seven combinations of powered solenoids.
fn study(a: &LimitsArgs) -> Result<()> {
    let ambient = a.ambient_c.unwrap_or(devices::OMNIMAGNET_DEFAULT_AMBIENT_C);
    let currents = if a.current_a.is_empty() {
        vec![2.0, 5.0, 10.0, 20.0, 50.0]
    } else {
        a.current_a.clone()
    };
    if let Some(t) = a.time_s.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        bail!("--time-s must be finite and > 0 s, got {t}");
    }
    let times = if a.time_s.is_empty() {
        vec![60.0, 600.0, 3600.0]
    } else {
        a.time_s.clone()
    };
    let limit = a.limit_c.unwrap_or(EXPERIMENT_STOP_C);
    let model = Omnimagnet::PAPER;
    let net = model
        .network(&[ambient; NODES], ambient)
        .map_err(|e| anyhow::anyhow!("omnimagnet network: {e}"))?;
    let mut limits = [f64::INFINITY; NODES];
    for s in &model.geometry().solenoids {
        limits[s.node] = limit;
    }
    let study_limits =
        StudyLimits::new(limits, ambient).map_err(|e| anyhow::anyhow!("study limits: {e}"))?;
    let mut rows = Vec::new();
    for powered in POWERED_COMBINATIONS {
        let name = combination_name(&powered);
        let t: Vec<Option<f64>> = currents
            .iter()
            .map(|&i| max_safe_time_s(&net, &study_limits, powered, i))
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("max safe time of {name}: {e}"))?;
        let c: Vec<f64> = times
            .iter()
            .map(|&s| max_safe_current_a(&net, &study_limits, powered, s))
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("max safe current of {name}: {e}"))?;
        rows.push((name, t, c));
    }
    if a.json {
        let list: Vec<_> = rows
            .iter()
            .map(|(n, t, c)| {
                json!({"powered": n, "max_safe_time_s": t,
                       "max_safe_current_a": c.iter().map(|v| v.is_finite().then_some(*v)).collect::<Vec<_>>()})
            })
            .collect();
        common::print_json(&json!({
            "command": "limits",
            "study": true,
            "model": "omnimagnet",
            "ambient_c": ambient,
            "limit_c": limit,
            "limited_nodes": [NODE_NAMES[0], NODE_NAMES[1], NODE_NAMES[2]],
            "currents_a": currents,
            "times_s": times,
            "combinations": list,
        }));
        return Ok(());
    }
    println!(
        "Omnimagnet study: solenoids at {limit} degC from equilibrium at {ambient} degC (network linearised at the ambient, R(T) exact)"
    );
    print!("{:<10}", "powered");
    for i in &currents {
        print!(" {:>14}", format!("t_max@{i}A [s]"));
    }
    for t in &times {
        print!(" {:>14}", format!("I_max@{t}s [A]"));
    }
    println!();
    for (n, t, c) in &rows {
        print!("{n:<10}");
        for v in t {
            print!(" {:>14}", v.map_or("never".into(), |v| format!("{v:.1}")));
        }
        for v in c {
            print!(
                " {:>14}",
                if v.is_finite() {
                    format!("{v:.3}")
                } else {
                    "unbounded".into()
                }
            );
        }
        println!();
    }
    Ok(())
}
