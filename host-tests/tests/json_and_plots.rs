//! The `--json` summaries carry their schema version (docs/json.md), and the
//! figures draw what they say: each node's own limit, truth and fused
//! sensors, the residual panel of `replay --truth` and `calibrate`, and the
//! time window of `plot`.

use std::fs;
use std::path::Path;

use assert_cmd::cargo::cargo_bin_cmd;
use serde_json::Value;
use tempfile::TempDir;

fn ct() -> assert_cmd::Command {
    cargo_bin_cmd!("coil-thermal")
}

fn root(path: &str) -> String {
    format!("{}/{path}", env!("CARGO_MANIFEST_DIR"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn json_of(args: &[&str]) -> Value {
    let out = ct().args(args).arg("--json").assert().success();
    let text = std::str::from_utf8(&out.get_output().stdout).unwrap();
    assert_eq!(text.trim().lines().count(), 1, "one line: {text}");
    serde_json::from_str(text).unwrap()
}

/// The first 600 s of the drive-3node recording (shorter replays).
fn short_trace(dir: &TempDir) -> String {
    let text = fs::read_to_string(root("traces/drive-3node.csv")).unwrap();
    let head: Vec<&str> = text.lines().take(602).collect();
    let path = dir.path().join("short.csv");
    fs::write(&path, head.join("\n") + "\n").unwrap();
    s(&path).to_string()
}

#[test]
fn every_json_summary_has_its_schema_version_and_command() {
    let tmp = TempDir::new().unwrap();
    let out = |name: &str| s(&tmp.path().join(name)).to_string();
    let (model, fitted) = (
        root("models/drive-3node.toml"),
        root("models/drive-3node-fitted.toml"),
    );
    let trace = short_trace(&tmp);
    let (sim, est, fit) = (out("sim.csv"), out("est.csv"), out("fit.toml"));
    let png = out("plot.png");
    let runs: Vec<(&str, Vec<&str>)> = vec![
        (
            "simulate",
            vec![
                "simulate",
                "--model",
                &fitted,
                "--current-a",
                "4",
                "--duration-s",
                "60",
                "--out",
                &sim,
            ],
        ),
        (
            "replay",
            vec![
                "replay",
                "--model",
                &fitted,
                "--trace",
                &trace,
                "--measure",
                "housing_tc=housing",
                "--truth",
                "winding_tc=winding",
                "--out",
                &est,
            ],
        ),
        (
            "calibrate",
            vec![
                "calibrate",
                "--model",
                &model,
                "--trace",
                &trace,
                "--measure",
                "winding_tc=winding",
                "--params",
                "capacity.winding",
                "--out",
                &fit,
                "--no-progress",
            ],
        ),
        (
            "limits",
            vec!["limits", "--model", &fitted, "--current-a", "8"],
        ),
        (
            "limits",
            vec![
                "limits",
                "--model",
                "omnimagnet",
                "--study",
                "--current-a",
                "5",
                "--time-s",
                "60",
            ],
        ),
        (
            "alarm-limit",
            vec!["alarm-limit", "--critical-c", "100", "--ambient-c", "20"],
        ),
        (
            "bench",
            vec!["bench", "--min-time-ms", "1", "--repeats", "1"],
        ),
        ("plot", vec!["plot", "--estimate", &sim, "--out", &png]),
        (
            "faults",
            vec![
                "faults",
                "--model",
                "omnimagnet",
                "--current-a",
                "7",
                "--classes",
                "open",
                "--sensors",
                "0,2,4",
            ],
        ),
    ];
    for (command, args) in runs {
        let j = json_of(&args);
        assert_eq!(j["schema_version"], 1, "{command}: {j}");
        assert_eq!(j["command"], command, "{args:?}");
    }
}

#[test]
fn replay_figure_draws_each_node_limit_truth_fused_and_residuals() {
    let tmp = TempDir::new().unwrap();
    let svg = tmp.path().join("replay.svg");
    let est = tmp.path().join("est.csv");
    let trace = short_trace(&tmp);
    ct().args([
        "replay",
        "--model",
        &root("models/drive-3node-fitted.toml"),
        "--trace",
        &trace,
    ])
    .args([
        "--measure",
        "housing_tc=housing",
        "--truth",
        "winding_tc=winding",
    ])
    .args(["--current-scale", "2", "--out", s(&est), "--plot", s(&svg)])
    .assert()
    .success();
    let text = fs::read_to_string(&svg).unwrap();
    // Both watched nodes' own limits, derated as the firmware derates them
    // (the file's default product 0.648 at the trace's 22 degC ambient):
    // winding 155 degC, housing 80 degC critical.
    for (node, critical_c) in [("winding", 155.0), ("housing", 80.0)] {
        let limit_c = 22.0 + (critical_c - 22.0) * 0.648;
        let label = format!("{node} alarm limit {limit_c:.1} degC");
        assert!(text.contains(&label), "{label}");
    }
    // The bound the protection acts on is drawn for each limited node.
    for legend in ["winding (upper bound)", "housing (upper bound)"] {
        assert!(text.contains(legend), "{legend} in the figure");
    }
    for legend in [
        "winding_tc (truth -&gt; winding)",
        "housing_tc (fused -&gt; housing)",
        "winding_tc (estimate - truth)",
        "residual [K]",
        "current [A]",
    ] {
        assert!(text.contains(legend), "{legend} in the figure");
    }
}

#[test]
fn calibrate_draws_a_fit_report_per_trace() {
    let tmp = TempDir::new().unwrap();
    let trace = short_trace(&tmp);
    let fig = tmp.path().join("fit.svg");
    let j = json_of(&[
        "calibrate",
        "--model",
        &root("models/drive-3node.toml"),
        "--trace",
        &trace,
        "--trace",
        &trace,
        "--measure",
        "winding_tc=winding",
        "--measure",
        "housing_tc=housing",
        "--params",
        "capacity.winding",
        "--out",
        s(&tmp.path().join("fit.toml")),
        "--plot",
        s(&fig),
        "--no-progress",
    ]);
    let plots: Vec<&str> = j["plots"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap())
        .collect();
    assert_eq!(plots.len(), 2, "{plots:?}");
    for (k, p) in plots.iter().enumerate() {
        assert!(p.ends_with(&format!("fit-{}.svg", k + 1)), "{p}");
        let text = fs::read_to_string(p).unwrap();
        assert!(text.contains("residual [K]") && text.contains("winding_tc (model - measured)"));
        assert!(
            text.contains("RMSE winding_tc"),
            "the title gives the fit's RMSE"
        );
    }
}

#[test]
fn plot_window_clips_and_limit_lines_are_labelled() {
    let tmp = TempDir::new().unwrap();
    let sim = tmp.path().join("sim.csv");
    ct().args([
        "simulate",
        "--model",
        &root("models/drive-3node-fitted.toml"),
        "--current-a",
        "4",
    ])
    .args(["--duration-s", "600", "--out", s(&sim)])
    .assert()
    .success();
    let svg = tmp.path().join("w.svg");
    let j = json_of(&[
        "plot",
        "--estimate",
        s(&sim),
        "--out",
        s(&svg),
        "--from-s",
        "100",
        "--to-s",
        "250",
        "--limit-c",
        "trip=60",
        "--limit-c",
        "derate=50",
    ]);
    assert_eq!(j["window_s"], serde_json::json!([100.0, 250.0]));
    assert_eq!(j["limit_lines"], 2);
    let text = fs::read_to_string(&svg).unwrap();
    assert!(text.contains("trip 60.0 degC") && text.contains("derate 50.0 degC"));
    let err = ct()
        .args([
            "plot",
            "--estimate",
            s(&sim),
            "--out",
            s(&svg),
            "--from-s",
            "900",
        ])
        .assert()
        .failure();
    let stderr = String::from_utf8_lossy(&err.get_output().stderr).to_string();
    assert!(stderr.contains("widen the plot window"), "{stderr}");
}

/// README's "host tool in five commands", as written (outputs into a
/// temporary directory; `codegen`, which compiles a generator crate, is
/// tested by `codegen_round_trip`).
#[test]
fn readme_host_tool_commands_run_as_written() {
    let tmp = TempDir::new().unwrap();
    let readme = include_str!("../../README.md");
    let section = readme
        .split("## The host tool in five commands")
        .nth(1)
        .expect("README has the five commands");
    let block = section.split("```").nth(1).expect("a code block");
    let commands: Vec<Vec<String>> = block
        .lines()
        .filter(|l| l.starts_with("coil-thermal "))
        .map(|l| l.split_whitespace().skip(1).map(str::to_string).collect())
        .collect();
    assert_eq!(commands.len(), 5, "{block}");
    let mut summaries = std::collections::HashMap::new();
    for mut args in commands.into_iter().filter(|a| a[0] != "codegen") {
        for k in 0..args.len() {
            if args[k] == "--out" || args[k] == "--plot" {
                args[k + 1] = s(&tmp.path().join(&args[k + 1])).to_string();
            }
        }
        let out = ct()
            .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
            .args(&args)
            .arg("--json")
            .assert()
            .success();
        let j: Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
        summaries.insert(args[0].clone(), j);
    }
    for file in ["sim.png", "fit.png", "est.png", "fitted.toml"] {
        assert!(tmp.path().join(file).is_file(), "{file} written");
    }
    // The figures README prints beside the commands are what they give,
    // at the precision README writes them.
    let figure = |after: &str, before: &str| -> f64 {
        let rest = &section[section
            .find(after)
            .unwrap_or_else(|| panic!("`{after}` in README"))
            + after.len()..];
        rest[..rest.find(before).unwrap()].trim().parse().unwrap()
    };
    let f = |j: &Value, path: &[&str]| -> f64 {
        path.iter()
            .fold(j, |v, k| &v[*k])
            .as_f64()
            .unwrap_or_else(|| panic!("{path:?} in {j}"))
    };
    let readme_winding_c = figure("a plot (winding ", " degC)");
    let winding_c = f(&summaries["simulate"], &["final_c", "winding"]);
    assert_eq!(
        format!("{winding_c:.1}"),
        format!("{readme_winding_c:.1}"),
        "README: 2 h at 4 A"
    );
    let readme_ttl_s = figure("at 8 A (winding ", " s)");
    let ttl_s = f(&summaries["limits"], &["time_to_limit_s", "winding"]);
    assert_eq!(ttl_s.round(), readme_ttl_s, "README: time to limit at 8 A");
    let readme_safe_a = figure("for 10 min (", " A)");
    let safe_a = summaries["limits"]["max_currents_horizon_a"][0]
        .as_f64()
        .unwrap();
    assert_eq!(
        format!("{safe_a:.1}"),
        format!("{readme_safe_a:.1}"),
        "README: safe current"
    );
    let readme_rmse_k = figure("never sees, at ", " K RMSE");
    let rmse_k = summaries["replay"]["truth"][0]["rmse_k"].as_f64().unwrap();
    assert_eq!(
        format!("{rmse_k:.2}"),
        format!("{readme_rmse_k:.2}"),
        "README: replay RMSE"
    );
}
