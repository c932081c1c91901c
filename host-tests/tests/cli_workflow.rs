//! Issue 19's workflow on someone else's recordings, command by command:
//! a `time,temperature` recording with its currents as a step profile
//! documented beside it, imported without a converter, calibrated on two
//! recordings with their own ambients and validated on a third, replayed
//! with missing readings, fused up to a time and then predicted, and
//! plotted.
//!
//! The recordings are the two-node coil's own simulation (so the fit has a
//! known answer: the coil's 200 J/K), with the time column renamed and
//! readings left out.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use assert_cmd::cargo::cargo_bin_cmd;
use predicates::str::contains;
use serde_json::Value;
use tempfile::TempDir;

fn ct() -> assert_cmd::Command {
    cargo_bin_cmd!("coil-thermal")
}

fn model() -> String {
    format!("{}/models/two-node-coil.toml", env!("CARGO_MANIFEST_DIR"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn json(out: &assert_cmd::assert::Assert) -> Value {
    serde_json::from_slice(&out.get_output().stdout).unwrap()
}

/// The coil's simulated temperature every second for 1000 s, `current_a`
/// until `off_s`, at `ambient_c`, as a recording `time,temperature` (and a
/// copy `housing_t` of the housing); every 97th row (from row 5) has an
/// empty temperature cell when `holes`.
fn recording(
    dir: &TempDir,
    name: &str,
    current_a: f64,
    off_s: u32,
    ambient_c: f64,
    holes: bool,
) -> PathBuf {
    let input = dir.path().join(format!("{name}_in.csv"));
    fs::write(
        &input,
        format!("time_s,current\n0,{current_a}\n{off_s},0\n1000,0\n"),
    )
    .unwrap();
    let sim = dir.path().join(format!("{name}_sim.csv"));
    ct().args(["simulate", "--model", &model(), "--trace", s(&input)])
        .args([
            "--resample-s",
            "1",
            "--const",
            &format!("ambient={ambient_c}"),
        ])
        .args(["--out", s(&sim)])
        .assert()
        .success();
    let text = fs::read_to_string(&sim).unwrap();
    let mut out = String::from("time,temperature,housing_t\n");
    for (k, line) in text.lines().skip(1).enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        let temp = if holes && k % 97 == 5 { "" } else { f[1] };
        out.push_str(&format!("{},{temp},{}\n", f[0], f[2]));
    }
    let path = dir.path().join(format!("{name}.csv"));
    fs::write(&path, out).unwrap();
    path
}

/// Rows of a recording made by [`recording`], and its empty cells.
const ROWS: usize = 1001;
const HOLES: usize = 11; // rows 5, 102, ..., 975

fn truth_rmse(j: &Value, column: &str) -> f64 {
    j["truth"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["column"] == column)
        .unwrap_or_else(|| panic!("no score of {column}: {j}"))["rmse_k"]
        .as_f64()
        .unwrap()
}

#[test]
fn a_time_temperature_recording_with_a_step_profile_imports_without_a_converter() {
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, true);
    let replay = |profile: &str| {
        json(
            &ct()
                .args(["replay", "--model", &model(), "--trace", s(&rec)])
                .args(["--time-column", "time"])
                .args(["--current", &format!("{profile}=current")])
                .args(["--truth", "temperature=coil,housing_t=housing", "--json"])
                .assert()
                .success(),
        )
    };
    let right = replay("0:3,400:0");
    let wrong = replay("0:3,300:0");
    // The library observer at 1 ms ticks against the 1 s simulation.
    assert!(truth_rmse(&right, "temperature") < 0.05, "{right}");
    assert!(truth_rmse(&right, "housing_t") < 0.05, "{right}");
    assert!(truth_rmse(&wrong, "temperature") > 1.0, "{wrong}");
    assert_eq!(right["schema_version"], 1);
    // The same profile as a --const of the input's column.
    let j = json(
        &ct()
            .args(["replay", "--model", &model(), "--trace", s(&rec)])
            .args(["--time-column", "time", "--const", "current=0:3,400:0"])
            .args(["--truth", "temperature=coil", "--json"])
            .assert()
            .success(),
    );
    assert_eq!(
        truth_rmse(&j, "temperature"),
        truth_rmse(&right, "temperature")
    );
    // And plotted against the recording's own time column.
    let png = dir.path().join("rec.png");
    ct().args(["plot", "--estimate", s(&dir.path().join("rec_sim.csv"))])
        .args(["--trace", s(&rec), "--time-column", "time"])
        .args(["--measure", "temperature=coil", "--out", s(&png)])
        .assert()
        .success();
    assert!(fs::metadata(&png).unwrap().len() > 10_000);
}

/// Calibrates the capacity of the coil, started at 300 J/K, on two
/// recordings at their own currents and ambients, validated on a third.
fn calibrate(dir: &TempDir, validation_ambient: bool) -> Value {
    let r1 = recording(dir, "r1", 3.0, 400, 20.0, false);
    let r2 = recording(dir, "r2", 2.5, 600, 25.0, false);
    let r3 = recording(dir, "r3", 3.2, 300, 22.0, false);
    let start = dir.path().join("start.toml");
    let text = fs::read_to_string(model()).unwrap();
    fs::write(
        &start,
        text.replace("capacity_j_per_k = 200.0", "capacity_j_per_k = 300.0"),
    )
    .unwrap();
    let mut cmd = ct();
    cmd.args(["calibrate", "--model", s(&start), "--time-column", "time"])
        .args(["--trace", s(&r1), "--trace", s(&r2), "--validate", s(&r3)])
        .args(["--trace-const", "1:current=0:3,400:0"])
        .args([
            "--trace-const",
            "2:current=0:2.5,600:0",
            "--trace-const",
            "2:ambient=25",
        ])
        .args(["--trace-const", "3:current=0:3.2,300:0"])
        .args(["--measure", "temperature=coil", "--params", "capacity.coil"])
        .args(["--out", s(&dir.path().join("fitted.toml")), "--json"]);
    if validation_ambient {
        cmd.args(["--trace-const", "3:ambient=22"]);
    }
    json(&cmd.assert().success())
}

#[test]
fn calibrate_takes_per_trace_constants_and_scores_a_held_out_trace() {
    let dir = TempDir::new().unwrap();
    let j = calibrate(&dir, true);
    assert_eq!(j["schema_version"], 1);
    let fitted = j["fit"]["params"][0]["fitted"].as_f64().unwrap();
    assert!((fitted - 200.0).abs() < 0.5, "{j}");
    for t in j["fit"]["traces"].as_array().unwrap() {
        assert!(t["rmse_after_k"].as_f64().unwrap() < 0.01, "{j}");
    }
    // The fitted file is the input file with only the fitted value
    // changed: its comments and key order survive, and the value is the
    // fit's (the JSON report's figure is 1 ulp off the file's).
    let start = fs::read_to_string(dir.path().join("start.toml")).unwrap();
    let out = fs::read_to_string(dir.path().join("fitted.toml")).unwrap();
    let changed: Vec<(&str, &str)> = start
        .lines()
        .zip(out.lines())
        .filter(|(a, b)| a != b)
        .collect();
    assert_eq!(start.lines().count(), out.lines().count(), "{out}");
    assert_eq!(changed.len(), 1, "{changed:?}");
    assert_eq!(changed[0].0, "capacity_j_per_k = 300.0");
    let (key, value) = changed[0].1.split_once(" = ").unwrap();
    assert_eq!(key, "capacity_j_per_k");
    let written: f64 = value.parse().unwrap();
    assert!((written / fitted - 1.0).abs() < 1e-14, "{written} {fitted}");
    assert!(
        out.starts_with("# A coil on a housing in still air"),
        "{out}"
    );
    let v = &j["validation"][0];
    assert!(v["trace"].as_str().unwrap().ends_with("r3.csv"), "{j}");
    assert!(v["rmse_k"].as_f64().unwrap() < 0.01, "{j}");
    // The held-out score sees what the fit did not: the third recording
    // replayed at the model's 20 degC instead of its own 22 degC.
    let dir = TempDir::new().unwrap();
    let wrong = calibrate(&dir, false);
    let rmse = wrong["validation"][0]["rmse_k"].as_f64().unwrap();
    assert!(rmse > 1.0, "{wrong}");
}

#[test]
fn replay_skips_missing_readings_and_fuses_until_a_time() {
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, true);
    let base = |extra: &[&str]| {
        let mut c = ct();
        c.args(["replay", "--model", &model(), "--trace", s(&rec)])
            .args(["--time-column", "time", "--current", "0:3,400:0=current"])
            .args(extra)
            .arg("--json");
        c
    };
    let readings = |j: &Value| {
        let f = &j["fusion"]["sensors"][0];
        f["fused"].as_u64().unwrap() + f["rejected"].as_u64().unwrap()
    };
    let j = json(&base(&["--measure", "temperature=coil"]).assert().success());
    // Every reading but the last row's (fused by the tick after it, and
    // the trace ends there).
    assert_eq!(readings(&j), (ROWS - HOLES - 1) as u64, "{j}");
    // Fused to 100 s (rows 0..=100, one of them empty), then predicted: the
    // housing's held-out score is the prediction's.
    let j = json(
        &base(&["--measure", "temperature=coil", "--measure-until-s", "100"])
            .args(["--truth", "housing_t=housing"])
            .assert()
            .success(),
    );
    assert_eq!(readings(&j), 100, "{j}");
    assert!(truth_rmse(&j, "housing_t") < 0.05, "{j}");
    // The same column fused and scored is no held-out score.
    base(&[
        "--measure",
        "temperature=coil",
        "--truth",
        "temperature=coil",
    ])
    .assert()
    .failure()
    .stderr(contains("--truth `temperature` is also fused by --measure"))
    .stderr(contains("--measure-until-s"));
}

/// Calibrates the coil's capacity from 300 J/K on `rec` (measured policy
/// when `model` says so) with `extra` flags.
fn calibrate_on(dir: &TempDir, model: &Path, recs: &[&Path], extra: &[&str]) -> Value {
    let mut cmd = ct();
    cmd.args(["calibrate", "--model", s(model), "--time-column", "time"]);
    for r in recs {
        cmd.args(["--trace", s(r)]);
    }
    json(
        &cmd.args(["--const", "current=0:3,400:0"])
            .args(["--measure", "temperature=coil", "--params", "capacity.coil"])
            .args(["--out", s(&dir.path().join("f.toml")), "--json"])
            .args(extra)
            .assert()
            .success(),
    )
}

/// The coil model starting its capacity at `capacity` [J/K], with the
/// `initial` policy, written to `dir`.
fn start_model(dir: &TempDir, name: &str, capacity: &str, policy: &str) -> PathBuf {
    let path = dir.path().join(name);
    let text = fs::read_to_string(model())
        .unwrap()
        .replace(
            "capacity_j_per_k = 200.0",
            &format!("capacity_j_per_k = {capacity}"),
        )
        .replace("policy = \"boundary\"", &format!("policy = \"{policy}\""));
    fs::write(&path, text).unwrap();
    path
}

fn fitted(j: &Value) -> f64 {
    j["fit"]["params"][0]["fitted"].as_f64().unwrap()
}

#[test]
fn calibrate_skips_missing_readings_and_starts_from_the_first_present_one() {
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, true);
    let start = start_model(&dir, "start.toml", "300.0", "boundary");
    let j = calibrate_on(&dir, &start, &[&rec], &[]);
    assert!((fitted(&j) - 200.0).abs() < 0.5, "{j}");
    let sensor = &j["fit"]["traces"][0]["sensors"][0];
    // Rows 1..=1000 less the 11 empty cells (row 0 is the start).
    assert_eq!(sensor["rows_fitted"], (ROWS - 1 - HOLES) as u64, "{j}");
    assert_eq!(sensor["rows_missing"], HOLES as u64, "{j}");
    assert!(sensor["rmse_k"].as_f64().unwrap() < 0.01, "{j}");
    // From 60 s on, both readings of the first row missing: with the
    // measured policy each node starts from its first present reading
    // (row 1, 61 s), not a NaN and not the ambient.
    let text = fs::read_to_string(&rec).unwrap();
    let mut late = String::from("time,temperature,housing_t\n");
    for (k, line) in text.lines().skip(61).enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        if k == 0 {
            late.push_str(&format!("{},,\n", f[0]));
        } else {
            late.push_str(&format!("{line}\n"));
        }
    }
    let late_rec = dir.path().join("late.csv");
    fs::write(&late_rec, late).unwrap();
    let measured = start_model(&dir, "measured.toml", "300.0", "measured");
    let init = ["--init", "housing_t=housing"];
    let j = calibrate_on(&dir, &measured, &[&late_rec], &init);
    let sensor = &j["fit"]["traces"][0]["sensors"][0];
    // The first row and the 10 holes from row 102 on.
    assert_eq!(sensor["rows_missing"], 11, "{j}");
    let rmse_init = sensor["rmse_k"].as_f64().unwrap();
    // Without --init the housing starts at the ambient, not its reading.
    let no_init = calibrate_on(&dir, &measured, &[&late_rec], &[]);
    let rmse_no_init = no_init["fit"]["traces"][0]["sensors"][0]["rmse_k"]
        .as_f64()
        .unwrap();
    assert!((fitted(&j) - 200.0).abs() < 2.0, "{j}");
    assert!(rmse_init < 0.1, "{j}");
    assert!(rmse_no_init > 2.0 * rmse_init, "{no_init}");
    // A missing input is still an error: the model cannot run without it.
    let holed_input = dir.path().join("holed_input.csv");
    fs::write(
        &holed_input,
        "time,temperature,current\n0,20,3\n1,20.2,\n2,20.5,3\n",
    )
    .unwrap();
    ct().args(["calibrate", "--model", s(&start), "--time-column", "time"])
        .args(["--trace", s(&holed_input), "--current", "current=current"])
        .args(["--measure", "temperature=coil", "--params", "capacity.coil"])
        .args(["--out", s(&dir.path().join("g.toml"))])
        .assert()
        .failure()
        .stderr(contains("holed_input.csv:3:3"));
}

#[test]
fn calibrate_weighs_by_rows_or_traces_and_by_given_weights() {
    let dir = TempDir::new().unwrap();
    // Two coils that disagree: a long recording of the 200 J/K coil and a
    // short one (150 s) of a 150 J/K coil.
    let long = recording(&dir, "long", 3.0, 400, 20.0, false);
    let light = start_model(&dir, "light.toml", "150.0", "boundary");
    let input = dir.path().join("short_in.csv");
    fs::write(&input, "time_s,current\n0,3\n150,3\n").unwrap();
    let sim = dir.path().join("short_sim.csv");
    ct().args(["simulate", "--model", s(&light), "--trace", s(&input)])
        .args(["--resample-s", "1", "--out", s(&sim)])
        .assert()
        .success();
    let mut short_text = String::from("time,temperature,housing_t\n");
    for line in fs::read_to_string(&sim).unwrap().lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        short_text.push_str(&format!("{},{},{}\n", f[0], f[1], f[2]));
    }
    let short = dir.path().join("short.csv");
    fs::write(&short, short_text).unwrap();
    let start = start_model(&dir, "start.toml", "300.0", "boundary");
    let both = [long.as_path(), short.as_path()];
    let rows = calibrate_on(&dir, &start, &both, &[]);
    let traces = calibrate_on(&dir, &start, &both, &["--weighting", "traces"]);
    let heavy = calibrate_on(&dir, &start, &both, &["--weight", "2:20"]);
    let (r, t, h) = (fitted(&rows), fitted(&traces), fitted(&heavy));
    // Each alone gives its own coil; together they fall between, nearer
    // the short one when every trace weighs the same (measured: 189.7 by
    // rows, 167.1 by traces, 157.1 with the short one weighted 20).
    let alone = |rec: &Path| fitted(&calibrate_on(&dir, &start, &[rec], &[]));
    assert!((alone(&long) - 200.0).abs() < 0.5);
    assert!((alone(&short) - 150.0).abs() < 0.5);
    assert!(r > t && t > 150.0, "rows {r}, traces {t}");
    assert!(r > h && h > 150.0, "rows {r}, short x20 {h}");
    let weights = |j: &Value| -> Vec<f64> {
        j["fit"]["traces"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t["weight"].as_f64().unwrap())
            .collect()
    };
    assert_eq!(weights(&rows), [1.0, 1.0]);
    // 1000 and 150 readings share 1150: 575 each.
    let w = weights(&traces);
    assert!(
        (w[0] - 0.575).abs() < 1e-9 && (w[1] - 575.0 / 150.0).abs() < 1e-9,
        "{w:?}"
    );
    // The standard error comes from the weighted residuals.
    let se = |j: &Value| j["fit"]["params"][0]["std_error"].as_f64().unwrap();
    for j in [&rows, &traces] {
        assert!(se(j) > 0.0 && se(j).is_finite(), "{j}");
    }
    assert!((se(&rows) - se(&traces)).abs() > 0.01 * se(&rows));
    for bad in ["1:0", "2:-1", "1:NaN", "1:inf"] {
        ct().args(["calibrate", "--model", s(&start), "--time-column", "time"])
            .args(["--trace", s(&long), "--trace", s(&short)])
            .args(["--const", "current=0:3,400:0", "--weight", bad])
            .args(["--measure", "temperature=coil", "--params", "capacity.coil"])
            .args(["--out", s(&dir.path().join("f.toml"))])
            .assert()
            .failure()
            .stderr(contains("a weight must be finite and above 0"));
    }
    ct().args(["calibrate", "--model", s(&start), "--time-column", "time"])
        .args(["--trace", s(&long), "--weight", "2:1"])
        .args(["--const", "current=0:3,400:0"])
        .args(["--measure", "temperature=coil", "--params", "capacity.coil"])
        .args(["--out", s(&dir.path().join("f.toml"))])
        .assert()
        .failure()
        .stderr(contains("trace 2 does not exist"));
}

#[test]
fn replay_without_out_prints_only_the_summary() {
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, false);
    let before = fs::read_dir(dir.path()).unwrap().count();
    let j = json(
        &ct()
            .current_dir(dir.path())
            .args(["replay", "--model", &model(), "--trace", s(&rec)])
            .args(["--time-column", "time", "--current", "0:3,400:0=current"])
            .args(["--truth", "temperature=coil", "--json"])
            .assert()
            .success(),
    );
    assert_eq!(j["out"], Value::Null);
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), before);
}

#[test]
fn a_closed_pipe_ends_the_tool_quietly() {
    // `coil-thermal ... | head -1` panicked with exit 101. Here the reader
    // is gone before the tool prints.
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, false);
    let mut child = Command::new(env!("CARGO_BIN_EXE_coil-thermal"))
        .args(["calibrate", "--model", &model(), "--trace", s(&rec)])
        .args(["--time-column", "time", "--const", "current=0:3,400:0"])
        .args(["--measure", "temperature=coil", "--params", "capacity.coil"])
        .args(["--out", s(&dir.path().join("f.toml"))])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `(time, column)` of a CSV written by the tool.
fn columns(path: &Path, name: &str) -> Vec<f64> {
    let text = fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let i = lines
        .next()
        .unwrap()
        .split(',')
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name}"));
    lines
        .map(|l| l.split(',').nth(i).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn a_sensor_lag_is_a_first_order_lag_the_winding_does_not_feel_and_calibrate_fits_it() {
    let dir = TempDir::new().unwrap();
    let run = |lag: Option<&str>, out: &str| {
        let out = dir.path().join(out);
        let mut c = ct();
        c.args(["simulate", "--model", &model(), "--current-a", "3"])
            .args(["--duration-s", "400", "--dt-s", "0.1", "--out", s(&out)]);
        if let Some(l) = lag {
            c.args(["--sensor-lag", l]);
        }
        c.assert().success();
        out
    };
    let lagged = run(Some("coil=3"), "lagged.csv");
    let plain = run(None, "plain.csv");
    let (coil, sensor) = (columns(&lagged, "coil"), columns(&lagged, "coil_lag"));
    let worst_feel = coil
        .iter()
        .zip(columns(&plain, "coil"))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        worst_feel < 0.005,
        "the winding feels its sensor: {worst_feel} K"
    );
    // The reference: y' = (x - y) / tau solved exactly for x linear between
    // the 0.1 s rows.
    let (tau, h) = (3.0, 0.1);
    let decay = f64::exp(-h / tau);
    let mut y = coil[0];
    let (mut worst, mut largest_lag) = (0.0f64, 0.0f64);
    for k in 1..coil.len() {
        let slope = (coil[k] - coil[k - 1]) / h;
        y = coil[k] - tau * slope + (y - coil[k - 1] + tau * slope) * decay;
        worst = worst.max((sensor[k] - y).abs());
        largest_lag = largest_lag.max(coil[k] - y);
    }
    // The lag is ~0.7 K; explicit sub-steps of 0.1 s err by h / (2 tau) of it.
    assert!(largest_lag > 0.5, "{largest_lag}");
    assert!(worst < 0.03, "{worst} K from a first-order lag of 3 s");
    // calibrate fits the lag: from 1 s back to 3 s (capacity 1e-4 of the
    // coil's 200 J/K, so 0.02 / 3 W/K).
    let j = json(
        &ct()
            .args(["calibrate", "--model", &model(), "--sensor-lag", "coil=1"])
            .args(["--trace", s(&lagged), "--const", "current=3"])
            .args(["--measure", "coil_lag=coil_lag"])
            .args(["--params", "conductance.coil-coil_lag"])
            .args(["--out", s(&dir.path().join("f.toml")), "--json"])
            .assert()
            .success(),
    );
    let g = j["fit"]["params"][0]["fitted"].as_f64().unwrap();
    assert!((g - 0.02 / 3.0).abs() < 1e-5, "{j}");
}

#[test]
fn multi_start_keeps_the_best_fit_and_flags_parameters_that_trade_off() {
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, false);
    let fit = |params: &str| {
        json(
            &ct()
                .args(["calibrate", "--model", &model(), "--trace", s(&rec)])
                .args(["--time-column", "time", "--const", "current=0:3,400:0"])
                .args(["--measure", "temperature=coil", "--params", params])
                .args([
                    "--starts",
                    "4",
                    "--out",
                    s(&dir.path().join("f.toml")),
                    "--json",
                ])
                .assert()
                .success(),
        )
    };
    // Both capacities are pinned by the step response: every start ends at
    // 200 and 900 J/K, no trade-off.
    let j = fit("capacity.coil=20:2000,capacity.housing=90:9000");
    let starts = j["starts"].as_array().unwrap();
    assert_eq!(starts.len(), 4);
    assert_eq!(starts.iter().filter(|r| r["best"] == true).count(), 1);
    for r in starts {
        assert!(
            (r["fitted"][0].as_f64().unwrap() - 200.0).abs() < 0.5,
            "{j}"
        );
        assert!(
            (r["fitted"][1].as_f64().unwrap() - 900.0).abs() < 5.0,
            "{j}"
        );
        assert!(r["trade_offs"].as_array().unwrap().is_empty(), "{j}");
    }
    // Resistance and its scale only act as their product: the starts agree
    // on the cost and on r0 * scale = 5.69 ohm, not on either.
    let j = fit("source.coil.r0_ohm,source.coil.scale");
    let starts = j["starts"].as_array().unwrap();
    let traded = starts
        .iter()
        .filter(|r| !r["trade_offs"].as_array().unwrap().is_empty())
        .count();
    assert!(traded >= 1, "{j}");
    for r in starts {
        let product = r["fitted"][0].as_f64().unwrap() * r["fitted"][1].as_f64().unwrap();
        assert!((product - 5.69).abs() < 0.01, "{j}");
    }
}

/// `--from-s`/`--to-s` limit what `replay` and `simulate` write and score,
/// while the model still runs from the first row: the windowed rows are
/// the full run's rows, to the bit, and the score is over the window only.
#[test]
fn a_time_window_writes_and_scores_the_full_runs_rows_inside_it() {
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, false);
    let lines = |p: &Path| -> Vec<String> {
        fs::read_to_string(p)
            .unwrap()
            .lines()
            .map(String::from)
            .collect()
    };
    let replay = |out: &Path, window: &[&str]| {
        json(
            &ct()
                .args(["replay", "--model", &model(), "--trace", s(&rec)])
                .args(["--time-column", "time", "--current", "0:3,400:0=current"])
                .args(["--truth", "housing_t=housing", "--out", s(out), "--json"])
                .args(window)
                .assert()
                .success(),
        )
    };
    let (full, part) = (dir.path().join("full.csv"), dir.path().join("part.csv"));
    let jf = replay(&full, &[]);
    let jw = replay(&part, &["--from-s", "199.5", "--to-s", "600"]);
    let (lf, lw) = (lines(&full), lines(&part));
    assert_eq!(lw[0], lf[0]);
    // Rows at 200 .. 600 s (time 200 s is row 200, line 201).
    assert_eq!(lw.len(), 1 + 401, "{}", lw.len());
    assert_eq!(lw[1..], lf[201..602]);
    assert_eq!(jw["rows"], 401, "{jw}");
    assert!(jw["truth"][0]["rmse_k"].as_f64().unwrap() > 0.0);
    let t = jw["truth"][0]["max_error_time_s"].as_f64().unwrap();
    assert!((200.0..=600.0).contains(&t), "{jw}");
    assert_eq!(jf["rows"], ROWS as u64);
    // simulate: the same rows as the whole run's, from the same start.
    let input = dir.path().join("rec_in.csv");
    let sim = |out: &Path, window: &[&str]| {
        ct().args(["simulate", "--model", &model(), "--trace", s(&input)])
            .args(["--resample-s", "1", "--out", s(out)])
            .args(window)
            .assert()
            .success();
    };
    sim(&full, &[]);
    sim(&part, &["--from-s", "900", "--to-s", "5000"]);
    let (lf, lw) = (lines(&full), lines(&part));
    assert_eq!(lw.len(), 1 + 101);
    assert_eq!(lw[1..], lf[901..]);
}

/// A fit stopped at a bound says which parameter hit which bound and how
/// to widen it, in the text and in `--json` (`bound`), instead of a bare
/// "converged".
#[test]
fn a_fit_at_its_bound_names_the_parameter_and_how_to_widen_it() {
    let dir = TempDir::new().unwrap();
    let rec = recording(&dir, "rec", 3.0, 400, 20.0, false);
    let start = start_model(&dir, "start.toml", "300.0", "boundary");
    let base = |json: bool| {
        let mut c = ct();
        c.args(["calibrate", "--model", s(&start), "--trace", s(&rec)])
            .args(["--time-column", "time", "--const", "current=0:3,400:0"])
            .args(["--measure", "temperature=coil"])
            .args(["--params", "capacity.coil=250:400"])
            .args(["--out", s(&dir.path().join("f.toml"))]);
        if json {
            c.arg("--json");
        }
        c
    };
    base(false)
        .assert()
        .success()
        .stdout(contains("AT LOWER BOUND (widen it in --params"));
    let j = json(&base(true).assert().success());
    assert_eq!(j["fit"]["params"][0]["bound"], "lower", "{j}");
    assert_eq!(fitted(&j), 250.0, "{j}");
}
