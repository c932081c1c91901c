//! A model file with the multi-rate model (`[observer] step_us` of five
//! loop ticks, `loop_period_us`): `codegen` flashes both settings, and
//! `replay` runs what that firmware runs, ticks at the loop's period with
//! the model stepped every 5 ms on the mean `I^2` of its ticks, and says
//! so. On the bench hour of `drive-3node` (the recording the model was
//! fitted on, read by `replay` with the housing thermocouple fused) the
//! 5 ms model follows the 1 ms one within a few millikelvin, the heating
//! of the time not yet stepped (the library test
//! `observer::network::multi_rate` bounds it against an `f64` RK4).

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use serde_json::Value;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `drive-3node-fitted.toml` with 5 ms model steps on a 1 ms loop.
fn multi_rate_model(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(root().join("host-tests/models/drive-3node-fitted.toml"))
        .expect("the fitted model");
    assert!(text.contains("\n[observer]\n"), "an [observer] table");
    let text = text.replacen(
        "\n[observer]\n",
        "\n[observer]\nstep_us = 5000\nloop_period_us = 1000\n",
        1,
    );
    let path = dir.join("drive-3node-5ms.toml");
    std::fs::write(&path, text).expect("written");
    path
}

/// `replay` of `model` on the bench hour, the housing thermocouple fused;
/// the JSON summary and the winding's estimate at each row \[degC\].
fn replay(model: &Path, dir: &Path, extra: &[&str]) -> (Value, Vec<f64>) {
    let out = dir.join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(model)
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args(["--measure", "housing_tc=housing"])
        .args(extra)
        .args(["--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).expect("json");
    let text = std::fs::read_to_string(&out).expect("the estimates");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let col = header
        .iter()
        .position(|h| *h == "winding")
        .unwrap_or_else(|| panic!("a winding column in {header:?}"));
    let winding = lines
        .map(|l| {
            l.split(',')
                .nth(col)
                .expect("a cell")
                .parse()
                .expect("a number")
        })
        .collect();
    (json, winding)
}

#[test]
fn codegen_flashes_the_loop_period_and_the_step() {
    let dir = tempfile::tempdir().expect("tempdir");
    let model = multi_rate_model(dir.path());
    let out = cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(&model)
        .args(["--out", "-"])
        .assert()
        .success();
    let text = String::from_utf8_lossy(&out.get_output().stdout).into_owned();
    assert!(text.contains("step_us: 5000,"), "the model step");
    assert!(text.contains("loop_period_us: 1000,"), "the loop's tick");
}

#[test]
fn replay_runs_the_multi_rate_firmware_at_its_loop_period() {
    let dir = tempfile::tempdir().expect("tempdir");
    let multi = multi_rate_model(dir.path());
    let (json, five) = replay(&multi, dir.path(), &[]);
    let fw = &json["firmware_observer"];
    assert_eq!(fw["step_us"], 5000, "{fw}");
    assert_eq!(fw["loop_period_us"], 1000, "{fw}");
    assert_eq!(fw["overrides"], Value::Array(vec![]), "what the MCU runs");
    let text = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(&multi)
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args(["--measure", "housing_tc=housing"])
        .assert()
        .success();
    let text = String::from_utf8_lossy(&text.get_output().stdout).into_owned();
    assert!(
        text.contains("model step 5000 us on ticks of 1000 us"),
        "{text}"
    );
    assert!(text.contains(" ticks of 1 ms (NetworkObserver"), "{text}");
    let (_, one) = replay(
        &root().join("host-tests/models/drive-3node-fitted.toml"),
        dir.path(),
        &[],
    );
    assert_eq!(five.len(), one.len());
    let worst_k = five
        .iter()
        .zip(&one)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f64, f64::max);
    let rise_k = one.iter().fold(0.0f64, |m, t| m.max(t - 22.0));
    println!(
        "5 ms on a 1 ms loop against 1 ms: winding within {worst_k:.2e} K (rise {rise_k:.1} K)"
    );
    assert!(rise_k > 30.0, "the winding heats: {rise_k} K");
    assert!(worst_k < 0.01, "{worst_k} K");
    assert!(worst_k > 0.0, "the 5 ms model is another model");
}

#[test]
fn tick_us_replays_ticks_and_steps_of_its_own_and_says_so() {
    let dir = tempfile::tempdir().expect("tempdir");
    let multi = multi_rate_model(dir.path());
    let (json, _) = replay(&multi, dir.path(), &["--tick-us", "2000"]);
    let fw = &json["firmware_observer"];
    assert_eq!(fw["step_us"], 2000, "{fw}");
    assert_eq!(fw["loop_period_us"], 2000, "{fw}");
    assert_eq!(fw["overrides"][0]["flag"], "--tick-us", "{fw}");
    assert_eq!(
        fw["overrides"][0]["what"],
        "ticks and model steps of 2000 us instead of model steps of 5000 us on ticks of 1000 us"
    );
}
