//! Integration tests of the `coil-thermal` binary: every subcommand, and
//! every class of bad input (non-zero exit, message naming file, line and
//! column).

use std::fs;
use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use predicates::prelude::*;
use predicates::str::contains;
use serde_json::Value;
use tempfile::TempDir;

fn ct() -> assert_cmd::Command {
    cargo_bin_cmd!("coil-thermal")
}

fn models(name: &str) -> String {
    format!("{}/models/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn write(dir: &TempDir, name: &str, text: &str) -> PathBuf {
    let p = dir.path().join(name);
    fs::write(&p, text).unwrap();
    p
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn json_of(out: &[u8]) -> Value {
    let text = std::str::from_utf8(out).unwrap();
    assert_eq!(
        text.trim().lines().count(),
        1,
        "one JSON object on one line: {text}"
    );
    serde_json::from_str(text).unwrap()
}

/// A two-node-coil input trace: current steps, 1 s rows.
fn coil_trace(dir: &TempDir, current_a: f64) -> PathBuf {
    let mut text = String::from("time_s,current\n");
    for k in 0..=1200 {
        let i = if k < 800 { current_a } else { 0.0 };
        text.push_str(&format!("{k},{i}\n"));
    }
    write(dir, "coil.csv", &text)
}

fn png_size(path: &Path) -> (u32, u32) {
    let bytes = fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert!(bytes.len() > 10_000, "a real picture, not an empty file");
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let reader = decoder.read_info().unwrap();
    let info = reader.info();
    (info.width, info.height)
}

#[test]
fn help_documents_every_subcommand_with_units() {
    for (cmd, must) in [
        (
            "simulate",
            vec![
                "--duration-s",
                "[s]",
                "[A]",
                "[degC]",
                "--trace",
                "--plot",
                "--json",
            ],
        ),
        (
            "replay",
            vec![
                "--truth",
                "--measure",
                "[degC]",
                "--json",
                "--factors",
                "--critical-c",
                "--warning-margin-k",
                "--hysteresis-k",
                "[K]",
                "--debounce-rows",
                "--ambient-boundary",
            ],
        ),
        (
            "calibrate",
            vec!["--params", "[J/K]", "[W/K]", "--trace", "--json"],
        ),
        ("bench", vec!["--json", "[ms]"]),
        ("plot", vec!["--out", "[px]", "[degC]"]),
        ("limits", vec!["--current-a", "[A]", "[s]"]),
        ("alarm-limit", vec!["--critical-c", "[degC]", "--factors"]),
    ] {
        let out = ct().args([cmd, "--help"]).assert().success();
        let text = String::from_utf8(out.get_output().stdout.clone()).unwrap();
        for m in must {
            assert!(text.contains(m), "`{cmd} --help` lacks `{m}`:\n{text}");
        }
    }
}

#[test]
fn simulate_solenoid_writes_time_then_stable_node_names() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("sol.csv");
    let assert = ct()
        .args([
            "simulate",
            "--model",
            "solenoid",
            "--layers",
            "20",
            "--current-a",
            "5",
        ])
        .args([
            "--duration-s",
            "600",
            "--dt-s",
            "10",
            "--json",
            "--out",
            s(&out),
        ])
        .assert()
        .success();
    let j = json_of(&assert.get_output().stdout);
    assert_eq!(j["rows"], 61);
    let hot = j["hot_spot"]["max_c"].as_f64().unwrap();
    assert!(hot > 30.0 && hot < 180.0, "{hot}");
    let text = fs::read_to_string(&out).unwrap();
    let header = text.lines().next().unwrap();
    let mut want = vec!["time_s".to_string()];
    want.extend((0..20).map(|i| format!("layer_{i:02}")));
    assert_eq!(header, want.join(","));
    assert_eq!(text.lines().count(), 62);
}

#[test]
fn simulate_model_file_with_trace_and_plots() {
    let dir = TempDir::new().unwrap();
    let trace = coil_trace(&dir, 2.0);
    let out = dir.path().join("sim.csv");
    let png = dir.path().join("sim.png");
    let svg = dir.path().join("sim.svg");
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&trace),
    ])
    .args(["--out", s(&out), "--plot", s(&png)])
    .assert()
    .success()
    .stdout(contains("hot spot: coil"));
    assert_eq!(png_size(&png), (1200, 800));
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--current-a",
        "1.5",
    ])
    .args(["--duration-s", "100", "--out", s(&out), "--plot", s(&svg)])
    .assert()
    .success();
    let text = fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.contains("width=\"1200\""));
    // Per-input constant currents: the wrong count is refused.
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--current-a",
        "1,2",
    ])
    .args(["--duration-s", "10", "--out", s(&out)])
    .assert()
    .failure()
    .stderr(contains(
        "--current-a has 2 values but model `two-node-coil` has 1 current input",
    ));
}

#[test]
fn replay_scores_truth_sensors_reports_alarms_and_step_times() {
    let dir = TempDir::new().unwrap();
    let trace = coil_trace(&dir, 4.0);
    let sim = dir.path().join("sim.csv");
    // The reference: the same model stepped explicitly in 10 ms steps
    // (`max_step_ratio` 0.0075 W/K / J/K * 0.01 s), close to exact.
    let fine = write(
        &dir,
        "fine.toml",
        &format!(
            "max_step_ratio = 0.000075\n{}",
            fs::read_to_string(models("two-node-coil.toml")).unwrap()
        ),
    );
    ct().args(["simulate", "--model", s(&fine), "--trace", s(&trace)])
        .args(["--out", s(&sim)])
        .assert()
        .success();
    // A "recording": the inputs plus the simulated coil temperature as a
    // sensor column, so the open-loop replay (the library observer, exact
    // zero-order hold at 1 ms in f32) must score ~0 error.
    let inputs = fs::read_to_string(&trace).unwrap();
    let temps = fs::read_to_string(&sim).unwrap();
    let mut rec = String::new();
    for (a, b) in inputs.lines().zip(temps.lines()) {
        let coil = b.split(',').nth(1).unwrap();
        rec.push_str(&format!(
            "{a},{}\n",
            if coil == "coil" { "T_coil" } else { coil }
        ));
    }
    let rec = write(&dir, "rec.csv", &rec);
    let est = dir.path().join("est.csv");
    let png = dir.path().join("replay.png");
    let assert = ct()
        .args([
            "replay",
            "--model",
            &models("two-node-coil.toml"),
            "--trace",
            s(&rec),
        ])
        .args([
            "--truth",
            "T_coil=coil",
            "--out",
            s(&est),
            "--plot",
            s(&png),
            "--json",
        ])
        .assert()
        .success();
    let j = json_of(&assert.get_output().stdout);
    let truth = &j["truth"][0];
    assert_eq!(truth["node"], "coil");
    assert!(truth["mse_k2"].as_f64().unwrap() < 1e-5, "{truth}");
    assert!(truth["max_abs_error_k"].as_f64().unwrap() < 0.01, "{truth}");
    assert!(truth["rmse_k"].as_f64().is_some() && truth["max_abs_error_k"].as_f64().is_some());
    // 4 A heats the coil past its derated limit (the firmware's default
    // derating product 0.648 of its 155 degC critical temperature at the
    // 20 degC ambient: 107.48 degC): warning first, then the shutdown.
    let (warnings, shutdowns) = (events_of(&j, "warning"), events_of(&j, "shutdown"));
    assert_eq!(warnings[0]["kind"], "raised");
    assert_eq!(warnings[0]["node"], "coil");
    let limit_c = 20.0 + (155.0 - 20.0) * 0.648;
    assert!(
        (warnings[0]["limit_c"].as_f64().unwrap() - (limit_c - 5.0)).abs() < 1e-3,
        "{j}"
    );
    assert!(
        (shutdowns[0]["limit_c"].as_f64().unwrap() - limit_c).abs() < 1e-3,
        "{j}"
    );
    assert!((j["alarm"]["derating_product"].as_f64().unwrap() - 0.648).abs() < 1e-12);
    let predictive_s = events_of(&j, "predictive")[0]["time_s"].as_f64().unwrap();
    assert!(
        predictive_s < warnings[0]["time_s"].as_f64().unwrap(),
        "{j}"
    );
    let st = &j["step_time"];
    assert_eq!(st["budget_ns"], 100000.0);
    assert!(st["p50_ns"].as_f64().unwrap() <= st["p99_ns"].as_f64().unwrap());
    // Every 1 ms library tick of the 1200 s is timed.
    assert_eq!(st["step"], "library tick");
    assert_eq!(st["steps"], 1_200_000);
    assert!(st["min_ns"].as_f64().unwrap() <= st["p50_ns"].as_f64().unwrap());
    assert_eq!(png_size(&png), (1200, 800));
    // The text summary names the same things.
    ct().args([
        "replay",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&rec),
    ])
    .args(["--truth", "T_coil=coil", "--out", s(&est)])
    .assert()
    .success()
    .stdout(
        contains("MSE [K^2]")
            .and(contains(
                "time to limit (the firmware's, on its upper bounds): shortest",
            ))
            .and(contains("observer: the firmware's NetworkObserver"))
            .and(contains("cold misses T_coil -> coil"))
            .and(contains("first predictive raised at t ="))
            .and(contains("warning raised at t ="))
            .and(contains("shutdown latched at t ="))
            .and(contains(
                "library tick time [us] over 1200000 ticks of 1 ms",
            ))
            .and(contains("0.1 ms budget")),
    );
}

/// Column `name` of a CSV the tool wrote.
fn csv_column(path: &Path, name: &str) -> Vec<f64> {
    let text = fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let k = lines
        .next()
        .unwrap()
        .split(',')
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("{path:?} has no column `{name}`"));
    lines
        .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
        .collect()
}

/// Pixels of exactly this colour in a PNG (the plot's markers are drawn
/// without anti-aliasing).
fn pixels_of(path: &Path, rgb: [u8; 3]) -> usize {
    let decoder = png::Decoder::new(std::io::BufReader::new(fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let step = info.color_type.samples();
    buf[..info.buffer_size()]
        .chunks(step)
        .filter(|p| p[..3] == rgb)
        .count()
}

/// The orange of the plot's warning markers.
const WARNING_ORANGE: [u8; 3] = [255, 140, 0];

/// Replays the two-node coil through its firmware observer under the HPPA
/// derating rule (`--factors`, an override of the file's 0.648); returns
/// the JSON summary, the coil's estimate and upper bound, and the times.
fn replay_derated(dir: &TempDir, current_a: f64) -> (Value, Vec<f64>, Vec<f64>, Vec<f64>) {
    // On for 400 s, then 1200 s of cooling, 1 s rows.
    let mut text = String::from("time_s,current\n");
    for k in 0..=1600 {
        let i = if k < 400 { current_a } else { 0.0 };
        text.push_str(&format!("{k},{i}\n"));
    }
    let trace = write(dir, "step.csv", &text);
    let est = dir.path().join("est.csv");
    let png = dir.path().join("alarm.png");
    let out = ct()
        .args([
            "replay",
            "--model",
            &models("two-node-coil.toml"),
            "--trace",
            s(&trace),
        ])
        .args(["--factors", "0.875,0.9,0.9,0.8"])
        .args(["--out", s(&est), "--plot", s(&png), "--json"])
        .assert()
        .success();
    let j = json_of(&out.get_output().stdout);
    let orange = pixels_of(&png, WARNING_ORANGE);
    // The plot's warning markers are the JSON's warnings.
    let warnings = j["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["level"] == "warning" && e["kind"] == "raised")
        .count();
    assert_eq!(orange > 0, warnings > 0, "{orange} orange pixels, {j}");
    (
        j,
        csv_column(&est, "coil"),
        csv_column(&est, "upper_c.coil"),
        csv_column(&est, "time_s"),
    )
}

// The rule by hand: 155 degC critical, 20 degC ambient (the model's
// boundary), product 0.875 * 0.9 * 0.9 * 0.8 = 0.567; the firmware warns
// 5 K below it.
const DERATED_LIMIT_C: f64 = 20.0 + (155.0 - 20.0) * 0.567;
const WARNING_C: f64 = DERATED_LIMIT_C - 5.0;

/// The events of one level, in order.
fn events_of<'a>(j: &'a Value, level: &str) -> Vec<&'a Value> {
    j["alarms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["level"] == level)
        .collect()
}

/// The event at `event_s` \[s\] came from a crossing of `level_c` by the
/// upper bound `upper_c` (sampled at `time_s`, one row a second): rising
/// (`up`) or falling through it in the second before the event (the
/// firmware debounces 10 ticks of 1 ms).
fn crossed_at(upper_c: &[f64], time_s: &[f64], event_s: f64, level_c: f64, up: bool) -> bool {
    let k = time_s.iter().position(|t| *t >= event_s).unwrap();
    let above = |i: usize| upper_c[i] > level_c;
    k >= 2 && above(k) == up && (above(k - 1) != up || above(k - 2) != up)
}

#[test]
fn replay_crossing_the_derated_limit_warns_then_latches_the_shutdown() {
    let dir = TempDir::new().unwrap();
    // 4 A for 400 s, then off: the coil passes 96.5 degC, then cools.
    let (j, coil_c, upper_c, time_s) = replay_derated(&dir, 4.0);
    // The protection acts on a bound above the estimate.
    assert!(upper_c.iter().zip(&coil_c).all(|(u, t)| u >= t), "{j}");
    let warnings = events_of(&j, "warning");
    let shutdowns = events_of(&j, "shutdown");
    let (w, sd) = (warnings[0], shutdowns[0]);
    assert_eq!(
        (&w["kind"], &w["node"]),
        (&"raised".into(), &"coil".into()),
        "{j}"
    );
    let at = |e: &Value| e["time_s"].as_f64().unwrap();
    assert!(crossed_at(&upper_c, &time_s, at(w), WARNING_C, true), "{w}");
    // The firmware's limits are f32.
    assert!(
        (w["limit_c"].as_f64().unwrap() - WARNING_C).abs() < 1e-3,
        "{w}"
    );
    assert_eq!(sd["kind"], "latched", "{j}");
    assert!(
        crossed_at(&upper_c, &time_s, at(sd), DERATED_LIMIT_C, true),
        "{sd}"
    );
    assert!(
        (sd["limit_c"].as_f64().unwrap() - DERATED_LIMIT_C).abs() < 1e-3,
        "{sd}"
    );
    assert!(sd["temp_c"].as_f64().unwrap() > DERATED_LIMIT_C);
    assert!(at(w) < at(sd));
    // Cooling after 400 s clears the warning (2 K hysteresis) but never
    // the latched shutdown.
    assert_eq!((warnings.len(), shutdowns.len()), (2, 1), "{j}");
    assert_eq!(warnings[1]["kind"], "cleared");
    assert!(
        crossed_at(&upper_c, &time_s, at(warnings[1]), WARNING_C - 2.0, false),
        "{}",
        warnings[1]
    );
    assert_eq!(j["alarm"]["shutdown_latched"], true);
    assert_eq!(j["alarm"]["by"], "firmware");
    assert!((j["alarm"]["derating_product"].as_f64().unwrap() - 0.567).abs() < 1e-12);
    // The override is named: this is not what the file flashes.
    assert_eq!(
        j["firmware_observer"]["overrides"][0]["flag"], "--factors",
        "{j}"
    );
}

#[test]
fn replay_predictive_alarm_leads_the_shutdown() {
    let dir = TempDir::new().unwrap();
    // The current is held from the start, as the prediction assumes: the
    // firmware's predictive alarm (60 s horizon, on the upper bound) must
    // lead the shutdown by about the horizon.
    let (j, _, upper_c, time_s) = replay_derated(&dir, 4.0);
    let predictive = events_of(&j, "predictive");
    assert_eq!(predictive[0]["kind"], "raised", "{j}");
    assert_eq!(predictive[0]["node"], "coil");
    let shutdown_s = events_of(&j, "shutdown")[0]["time_s"].as_f64().unwrap();
    let lead_s = shutdown_s - predictive[0]["time_s"].as_f64().unwrap();
    assert!((50.0..=75.0).contains(&lead_s), "lead {lead_s} s: {j}");
    // Off at 400 s: the alarm clears once the bound is below the limit.
    let cleared = predictive.iter().find(|e| e["kind"] == "cleared").unwrap();
    let cleared_s = cleared["time_s"].as_f64().unwrap();
    assert!(cleared_s > 400.0, "{j}");
    let k = time_s.iter().position(|t| *t >= cleared_s).unwrap();
    assert!(upper_c[k] < DERATED_LIMIT_C + 1.0, "{j}");
}

#[test]
fn replay_below_the_derated_limit_raises_nothing() {
    let dir = TempDir::new().unwrap();
    // 3.3 A for 400 s: the coil heats well above ambient but its upper
    // bound stays below the warning level of the same rule, and its steady
    // state at 3.3 A would too, so the predictive alarm stays quiet as well.
    let (j, coil_c, upper_c, _) = replay_derated(&dir, 3.3);
    let peak_c = upper_c.iter().copied().fold(f64::MIN, f64::max);
    assert!(peak_c < WARNING_C, "peak upper bound {peak_c} degC");
    assert!(coil_c.iter().copied().fold(f64::MIN, f64::max) > 50.0);
    assert_eq!(j["alarms"].as_array().unwrap().len(), 0, "{j}");
    assert_eq!(j["alarm"]["shutdown_latched"], false);
    assert_eq!(j["alarm"]["watched_nodes"], 1);
}

#[test]
fn calibrate_fits_a_perturbed_model_back_and_writes_it() {
    let dir = TempDir::new().unwrap();
    let trace = coil_trace(&dir, 2.0);
    let sim = dir.path().join("sim.csv");
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&trace),
    ])
    .args(["--out", s(&sim)])
    .assert()
    .success();
    let inputs = fs::read_to_string(&trace).unwrap();
    let temps = fs::read_to_string(&sim).unwrap();
    let rec: String = inputs
        .lines()
        .zip(temps.lines())
        .map(|(a, b)| format!("{a},{}\n", b.split_once(',').unwrap().1))
        .collect();
    let rec = write(&dir, "rec.csv", &rec);
    let start = fs::read_to_string(models("two-node-coil.toml"))
        .unwrap()
        .replace("capacity_j_per_k = 200.0", "capacity_j_per_k = 300.0")
        .replace("g_w_per_k = 1.5", "g_w_per_k = 1.0");
    let start = write(&dir, "start.toml", &start);
    let fitted = dir.path().join("fitted.toml");
    let assert = ct()
        .args([
            "calibrate",
            "--model",
            s(&start),
            "--trace",
            s(&rec),
            "--trace",
            s(&rec),
        ])
        .args(["--measure", "coil=coil", "--measure", "housing=housing"])
        .args(["--params", "capacity.coil,conductance.coil-housing=0.1:10"])
        .args(["--out", s(&fitted), "--json"])
        .assert()
        .success();
    let j = json_of(&assert.get_output().stdout);
    let params = j["fit"]["params"].as_array().unwrap();
    let c = params[0]["fitted"].as_f64().unwrap();
    let g = params[1]["fitted"].as_f64().unwrap();
    assert!(
        (c - 200.0).abs() < 0.5 && (g - 1.5).abs() < 0.005,
        "{c} {g}"
    );
    assert_eq!(j["fit"]["traces"].as_array().unwrap().len(), 2);
    assert!(j["fit"]["traces"][0]["rmse_after_k"].as_f64().unwrap() < 0.01);
    // The fitted file is a valid model.
    ct().args(["simulate", "--model", s(&fitted), "--current-a", "1"])
        .args(["--duration-s", "10", "--out", s(&sim)])
        .assert()
        .success();
    // Text mode prints the per-trace fit error.
    ct().args(["calibrate", "--model", s(&start), "--trace", s(&rec)])
        .args([
            "--measure",
            "coil=coil",
            "--params",
            "capacity.coil",
            "--out",
            s(&fitted),
        ])
        .assert()
        .success()
        .stdout(contains("RMSE after [K]").and(contains("capacity.coil")));
    // Unknown parameter names are named.
    ct().args(["calibrate", "--model", s(&start), "--trace", s(&rec)])
        .args([
            "--measure",
            "coil=coil",
            "--params",
            "capacity.rotor",
            "--out",
            s(&fitted),
        ])
        .assert()
        .failure()
        .stderr(contains("no node `rotor`"));
}

#[test]
fn bench_json_names_model_size_scalar_and_unit() {
    let assert = ct()
        .args(["bench", "--json", "--min-time-ms", "1", "--repeats", "1"])
        .assert()
        .success();
    let j = json_of(&assert.get_output().stdout);
    for key in [
        "network_3_f32_ns",
        "network_16_f32_ns",
        "network_16_f64_ns",
        "network_84_q32_ns",
        "solenoid_30_f32_ns",
        "grid_observer_84_f32_ns",
        "network_observer_84_f32_ns",
    ] {
        assert!(j[key].as_f64().is_some_and(|v| v > 0.0), "{key}: {j}");
    }
    assert_eq!(j["budget_ns"], 100000.0);
}

#[test]
fn plot_draws_estimate_against_measurement() {
    let dir = TempDir::new().unwrap();
    let trace = coil_trace(&dir, 2.0);
    let sim = dir.path().join("sim.csv");
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&trace),
    ])
    .args(["--out", s(&sim)])
    .assert()
    .success();
    let png = dir.path().join("p.png");
    let assert = ct()
        .args([
            "plot",
            "--estimate",
            s(&sim),
            "--trace",
            s(&trace),
            "--current",
            "current",
        ])
        .args([
            "--limit-c",
            "coil critical=155",
            "--out",
            s(&png),
            "--width",
            "640",
        ])
        .args(["--height", "480", "--alarm-s", "700", "--json"])
        .assert()
        .success();
    assert_eq!(json_of(&assert.get_output().stdout)["width"], 640);
    assert_eq!(png_size(&png), (640, 480));
    ct().args([
        "plot",
        "--estimate",
        s(&sim),
        "--out",
        s(&dir.path().join("p.gif")),
    ])
    .assert()
    .failure()
    .stderr(contains(".png or .svg"));
}

// ---- bad input -------------------------------------------------------------

fn simulate_trace(dir: &TempDir, name: &str, text: &str) -> assert_cmd::assert::Assert {
    let trace = write(dir, name, text);
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&trace),
    ])
    .args(["--out", s(&dir.path().join("o.csv"))])
    .assert()
    .failure()
}

#[test]
fn bad_traces_are_refused_with_file_line_and_column() {
    let dir = TempDir::new().unwrap();
    let at = |name: &str| dir.path().join(name).display().to_string();
    simulate_trace(&dir, "missing.csv", "time_s,volts\n0,1\n").stderr(contains(format!(
        "{}:1: missing column `current`",
        at("missing.csv")
    )));
    simulate_trace(&dir, "misnamed.csv", "time_s,Current\n0,1\n")
        .stderr(contains("did you mean `Current`?"));
    simulate_trace(&dir, "text.csv", "time_s,current\n0,1\n1,2\n2,abc\n").stderr(contains(
        format!(
            "{}:4:2: column `current`: `abc` is not a number",
            at("text.csv")
        ),
    ));
    simulate_trace(&dir, "nan.csv", "time_s,current\n0,1\n1,NaN\n").stderr(contains(format!(
        "{}:3:2: column `current`: `NaN` is not a finite number",
        at("nan.csv")
    )));
    simulate_trace(&dir, "empty.csv", "time_s,current\n0,1\n1,\n").stderr(contains(format!(
        "{}:3:2: column `current`: empty cell",
        at("empty.csv")
    )));
    simulate_trace(&dir, "time.csv", "time_s,current\n0,1\n1,1\n0.5,1\n").stderr(contains(
        format!(
            "{}:4:1: column `time_s`: time must increase strictly",
            at("time.csv")
        ),
    ));
    simulate_trace(&dir, "ragged.csv", "time_s,current\n0,1\n1,1,7\n").stderr(contains(format!(
        "{}:3: row has 3 fields, the header has 2",
        at("ragged.csv")
    )));
    simulate_trace(&dir, "notime.csv", "current\n1\n")
        .stderr(contains("no `time_s` column").and(contains("--sample-period-s")));
    simulate_trace(&dir, "norows.csv", "time_s,current\n").stderr(contains("no data rows"));
    // Implicit time works (and a non-positive period is refused).
    let t = write(&dir, "implicit.csv", "current\n1\n1\n");
    let o = dir.path().join("o.csv");
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&t),
    ])
    .args(["--sample-period-s", "1", "--out", s(&o)])
    .assert()
    .success();
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&t),
    ])
    .args(["--sample-period-s", "-1", "--out", s(&o)])
    .assert()
    .failure()
    .stderr(contains("sample period must be > 0 s"));
    // A derived current from two columns, and a misnamed column in it.
    let dq = write(&dir, "dq.csv", "time_s,Id,Iq\n0,3,4\n1,3,4\n");
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&dq),
    ])
    .args(["--current", "hypot(Id,Iq)=current", "--out", s(&o)])
    .assert()
    .success();
    ct().args([
        "simulate",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&dq),
    ])
    .args(["--current", "hypot(Id,Iqq)=current", "--out", s(&o)])
    .assert()
    .failure()
    .stderr(contains("missing column `Iqq`").and(contains("did you mean `Iq`?")));
    // Truth columns are read as strictly as inputs.
    let tr = write(&dir, "truth.csv", "time_s,current,T\n0,1,20\n1,1,x\n");
    ct().args([
        "replay",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&tr),
    ])
    .args(["--truth", "T=coil", "--out", s(&o)])
    .assert()
    .failure()
    .stderr(contains(format!("{}:3:3: column `T`", at("truth.csv"))));
    ct().args([
        "replay",
        "--model",
        &models("two-node-coil.toml"),
        "--trace",
        s(&tr),
    ])
    .args(["--truth", "T=winding", "--out", s(&o)])
    .assert()
    .failure()
    .stderr(contains("no node `winding` (nodes: coil, housing)"));
}

#[test]
fn bad_models_and_arguments_are_refused() {
    let dir = TempDir::new().unwrap();
    let o = dir.path().join("o.csv");
    let sim = |model: &str| {
        ct().args([
            "simulate",
            "--model",
            model,
            "--current-a",
            "1",
            "--duration-s",
            "10",
        ])
        .args(["--out", s(&o)])
        .assert()
        .failure()
    };
    sim("nosuch").stderr(contains("unknown model `nosuch`"));
    let syntax = write(
        &dir,
        "syntax.toml",
        "[[node]]\nname = \"a\"\ncapacity_j_per_k = = 3\n",
    );
    sim(s(&syntax)).stderr(contains(format!("{}:3:", syntax.display())));
    let unknown = write(
        &dir,
        "unknown.toml",
        "[[node]]\nname = \"a\"\ncapacity_j_per_k = 3.0\n\n[[boundary]]\nname = \"air\"\nvalue_c = 20.0\n\n[[conductance]]\nbetween = [\"a\", \"air\"]\ng_w_per_k = 1.0\n\n[[conductance]]\nbetween = [\"a\", \"aer\"]\ng_w_per_k = 1.0\n",
    );
    sim(s(&unknown)).stderr(contains(format!(
        "{}:13:1: [[conductance]] #2 `a-aer`: unknown node or boundary `aer`",
        unknown.display()
    )));
    let field = write(
        &dir,
        "field.toml",
        "[[node]]\nname = \"a\"\ncapacity = 3.0\n",
    );
    sim(s(&field)).stderr(contains("unknown field `capacity`"));
    let negative = write(
        &dir,
        "neg.toml",
        "[[node]]\nname = \"a\"\ncapacity_j_per_k = -3.0\n",
    );
    sim(s(&negative)).stderr(contains(format!(
        "{}:1:1: [[node]] #1 `a`: capacity_j_per_k",
        negative.display()
    )));
    // Negative and NaN durations, NaN currents.
    let two = models("two-node-coil.toml");
    for (flag, value, msg) in [
        (
            "--duration-s",
            "-5",
            "--duration-s must be finite and >= 0 s",
        ),
        (
            "--duration-s",
            "nan",
            "--duration-s must be finite and >= 0 s",
        ),
        ("--dt-s", "0", "--dt-s must be finite and > 0 s"),
    ] {
        let mut args = vec!["simulate", "--model", &two, "--current-a", "1"];
        if flag != "--duration-s" {
            args.extend(["--duration-s", "10"]);
        }
        args.extend([flag, value, "--out", s(&o)]);
        ct().args(&args).assert().failure().stderr(contains(msg));
    }
    ct().args([
        "simulate",
        "--model",
        &two,
        "--current-a",
        "nan",
        "--duration-s",
        "1",
        "--out",
        s(&o),
    ])
    .assert()
    .failure()
    .stderr(contains("--current-a must be finite"));
    ct().args([
        "simulate",
        "--model",
        &two,
        "--current-a",
        "1",
        "--out",
        s(&o),
    ])
    .assert()
    .failure()
    .stderr(contains("--duration-s"));
    // Replay: the predictive horizon and the current scale.
    let trace = coil_trace(&dir, 1.0);
    for (flag, value, msg) in [
        // The host alarm's flags do not apply to the firmware's observer.
        ("--horizon-s", "60", "drop --horizon-s"),
        ("--debounce-rows", "3", "drop --debounce-rows"),
        (
            "--current-scale",
            "-1",
            "--current-scale must be finite and >= 0",
        ),
        (
            "--current-scale",
            "nan",
            "--current-scale must be finite and >= 0",
        ),
    ] {
        ct().args(["replay", "--model", &two, "--trace", s(&trace)])
            .args([flag, value, "--out", s(&o)])
            .assert()
            .failure()
            .stderr(contains(msg));
    }
}

#[test]
fn current_scale_multiplies_every_current_of_the_trace() {
    let dir = TempDir::new().unwrap();
    let two = models("two-node-coil.toml");
    let run = |current_a: f64, scale: &str| {
        let trace = coil_trace(&dir, current_a);
        let out = dir.path().join(format!("sim-{current_a}-{scale}.csv"));
        ct().args(["simulate", "--model", &two, "--trace", s(&trace)])
            .args(["--current-scale", scale, "--out", s(&out)])
            .assert()
            .success();
        csv_column(&out, "coil")
    };
    let scaled = run(2.0, "1.5");
    let direct = run(3.0, "1");
    assert_eq!(scaled, direct);
    assert!(scaled.iter().copied().fold(f64::MIN, f64::max) > 60.0);
}

/// Opt-in: the real HUST motor data (set `COIL_THERMAL_HUST_DIR` to the
/// folder holding `id_N.csv`; CI points it at shared/data/hust-ipmsm).
#[test]
fn hust_baseline_replays_within_the_published_error_range() {
    let Ok(dir) = std::env::var("COIL_THERMAL_HUST_DIR") else {
        eprintln!("skipped: COIL_THERMAL_HUST_DIR is not set");
        return;
    };
    let tmp = TempDir::new().unwrap();
    let trace = Path::new(&dir).join("id_1.csv");
    let assert = ct()
        .args([
            "replay",
            "--model",
            &models("hust-ipmsm-3node.toml"),
            "--trace",
            s(&trace),
        ])
        .args([
            "--sample-period-s",
            "1",
            "--truth",
            "activewind_1=winding",
            "--json",
        ])
        .args(["--out", s(&tmp.path().join("e.csv"))])
        .assert()
        .success();
    let j = json_of(&assert.get_output().stdout);
    let mse = j["truth"][0]["mse_k2"].as_f64().unwrap();
    // The README: the baseline's winding MSE is from under 1 to over 30 K^2.
    assert!(mse < 30.0, "winding MSE {mse} K^2");
}
