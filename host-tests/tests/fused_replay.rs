//! `replay --measure` on a synthetic recording whose plant has a heat the
//! model does not know: the firmware's observer fusing the housing sensor
//! through the coil's heat bias recovers the unmeasured coil, where the
//! open-loop model and the temperatures-only fusion (frozen biases) cannot.

use std::path::Path;

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal_host::calibrate::access_param;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sim::{simulate, Drive, FilePlant};
use serde_json::Value;
use tempfile::TempDir;

fn model_path() -> String {
    format!("{}/models/two-node-coil.toml", env!("CARGO_MANIFEST_DIR"))
}

/// The coil of `two-node-coil.toml` with 40 % more resistance than the model
/// believes (an unmodelled heat), driven by steps of current.
fn recording(dir: &Path) -> std::path::PathBuf {
    let mut truth = ModelFile::load(Path::new(&model_path())).unwrap();
    let r0 = access_param(&mut truth, "source.coil.r0_ohm", None).unwrap();
    access_param(&mut truth, "source.coil.r0_ohm", Some(1.4 * r0)).unwrap();
    let mut plant = FilePlant::new(Model::build(&truth).unwrap()).unwrap();
    let rows = 4000;
    let current: Vec<f64> = (0..rows)
        .map(|k| match (k / 800) % 3 {
            0 => 1.5,
            1 => 0.5,
            _ => 1.0,
        })
        .collect();
    let drive = Drive {
        time_s: (0..rows).map(|k| k as f64).collect(),
        currents: vec![current.clone()],
        boundaries: vec![vec![20.0; rows]],
        signals: vec![],
    };
    let temps = simulate(&mut plant, &drive, &[20.0, 20.0]);
    let mut text = String::from("time_s,current,T_coil,T_housing\n");
    for (k, t) in temps.iter().enumerate() {
        text.push_str(&format!("{k},{},{:.2},{:.2}\n", current[k], t[0], t[1]));
    }
    let p = dir.join("rec.csv");
    std::fs::write(&p, text).unwrap();
    p
}

fn coil_mse(trace: &Path, out: &Path, extra: &[&str]) -> Value {
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", &model_path(), "--trace"])
        .arg(trace)
        .args(["--truth", "T_coil=coil", "--json", "--out"])
        .arg(out)
        .args(extra)
        .assert()
        .success();
    serde_json::from_slice(&a.get_output().stdout).unwrap()
}

/// Runs `replay` on `rec` with `args` and checks it is refused with `msg`
/// on stderr.
fn refused(rec: &Path, out: &Path, args: &[&str], msg: &str) {
    cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", &model_path(), "--trace"])
        .arg(rec)
        .args(args)
        .arg("--out")
        .arg(out)
        .assert()
        .failure()
        .stderr(predicates::str::contains(msg));
}

/// The firmware's filter (the library's default bias noise, 1e-3 W^2/s: the
/// model file has no `[observer]` table) learns the coil's missing heat
/// from the housing, fusing every reading: the unmeasured coil is far
/// better than with the biases frozen (`--bias-noise-w2-per-s 0`: the
/// temperatures corrected, the heat not) and than open loop, where the
/// unmodelled heat matters (over 1 K^2).
#[test]
fn the_housing_sensor_corrects_the_unmeasured_coil_through_its_heat_bias() {
    let tmp = TempDir::new().unwrap();
    let rec = recording(tmp.path());
    let out = tmp.path().join("e.csv");
    let measure = ["--measure", "T_housing=housing"];
    let firmware = coil_mse(&rec, &out, &measure);
    let frozen = coil_mse(
        &rec,
        &out,
        &[&measure[..], &["--bias-noise-w2-per-s", "0"]].concat(),
    );
    let open = coil_mse(&rec, &out, &[]);
    assert_eq!(open["estimator"], "network-observer");
    assert_eq!(firmware["estimator"], "network-observer");
    assert!(firmware["fusion"]["sensors"][0]["fused"].as_u64().unwrap() > 3900);
    assert_eq!(firmware["fusion"]["bias_noise_w2_per_s"], 1e-3);
    assert_eq!(firmware["fusion"]["bias_noise_from"], "default");
    assert_eq!(firmware["fusion"]["max_cooling_bias_fraction"], 0.0);
    assert_eq!(frozen["fusion"]["bias_noise_w2_per_s"], 0.0);
    assert_eq!(frozen["fusion"]["bias_noise_from"], "flag");
    assert!(open["fusion"].is_null());
    let mse = |j: &Value| j["truth"][0]["mse_k2"].as_f64().unwrap();
    let (b, z, o) = (mse(&firmware), mse(&frozen), mse(&open));
    eprintln!("coil MSE: open loop {o:.3}, frozen biases {z:.3}, the firmware's filter {b:.3} K^2");
    assert!(
        o > 1.0,
        "the unmodelled heat must matter: open loop {o} K^2"
    );
    assert!(b < 0.3 * z, "the heat bias: {b} vs frozen {z} K^2");
    assert!(b < 0.05 * o, "the heat bias: {b} vs open loop {o} K^2");
    // The text summary says which filter ran.
    let text = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", &model_path(), "--trace"])
        .arg(&rec)
        .args(measure)
        .assert()
        .success();
    let text = String::from_utf8_lossy(&text.get_output().stdout).into_owned();
    assert!(
        text.contains(
            "heat-input biases: the model's sources, noise 1e-3 W^2/s (the library's default)"
        ),
        "{text}"
    );
}

/// Three sources, one sensor: the sensor cannot tell their heats apart, so
/// a bias per source has no steady gain; the default shares one heat bias
/// between them (as the firmware's), the flag freezes the biases; with `[observer] bias_sources` naming the coil, the one heat
/// the sensor can see, it builds and recovers the coil's unmodelled heat
/// as the one-source model does.
#[test]
fn biases_no_sensor_can_tell_apart_are_shared_or_named() {
    let tmp = TempDir::new().unwrap();
    let rec = recording(tmp.path());
    let out = tmp.path().join("e.csv");
    let mut text = std::fs::read_to_string(model_path()).unwrap();
    let extra: String = ["coil", "housing"]
        .iter()
        .map(|node| {
            format!("[[source]]\nname = \"{node}-extra\"\nnode = \"{node}\"\ninput = \"aux\"\nr0_ohm = 1.0\n\n")
        })
        .collect();
    text = text.replace("[initial]", &format!("{extra}[initial]"));
    let model = tmp.path().join("three-sources.toml");
    std::fs::write(&model, &text).unwrap();
    let run = |extra: &[&str]| {
        let mut c = cargo_bin_cmd!("coil-thermal");
        c.args(["replay", "--model"])
            .arg(&model)
            .arg("--trace")
            .arg(&rec)
            .args([
                "--measure",
                "T_housing=housing",
                "--const",
                "aux=0",
                "--json",
                "--out",
            ])
            .arg(&out)
            .args(extra);
        c
    };
    // The default builds: the three sources share one heat bias in
    // proportion to their Joule power (one sensor sees one heat), where a
    // bias per source has no steady gain.
    run(&[]).assert().success();
    let mse = |a: assert_cmd::assert::Assert| -> f64 {
        let j: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
        j["truth"][0]["mse_k2"].as_f64().unwrap()
    };
    let a = run(&["--bias-noise-w2-per-s", "0"]).assert().success();
    let j: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(j["fusion"]["bias_noise_w2_per_s"], 0.0);
    let frozen = mse(
        run(&["--bias-noise-w2-per-s", "0", "--truth", "T_coil=coil"])
            .assert()
            .success(),
    );
    // The extra sources carry no current in the recording (`aux` is 0):
    // naming the coil alone gives the one-source observer's coil estimate.
    std::fs::write(
        &model,
        format!("{text}\n[observer]\nbias_sources = [\"coil\"]\n"),
    )
    .unwrap();
    let named = mse(run(&["--truth", "T_coil=coil"]).assert().success());
    let single = coil_mse(&rec, &out, &["--measure", "T_housing=housing"])["truth"][0]["mse_k2"]
        .as_f64()
        .unwrap();
    eprintln!("coil MSE: frozen {frozen:.3}, coil's bias alone {named:.3}, one-source model {single:.3} K^2");
    assert!(named < 0.3 * frozen, "{named} vs frozen {frozen} K^2");
    assert!(
        (named - single).abs() < 1e-3 * single.max(1e-3),
        "{named} vs {single} K^2"
    );
    // A name that is no source, or one given twice, is refused.
    for (list, says) in [
        (
            "[\"coil\", \"rotor\"]",
            "no [[source]] `rotor` (sources: coil, coil-extra, housing-extra)",
        ),
        ("[\"coil\", \"coil\"]", "`coil` given twice"),
    ] {
        std::fs::write(
            &model,
            format!("{text}\n[observer]\nbias_sources = {list}\n"),
        )
        .unwrap();
        run(&[])
            .assert()
            .failure()
            .stderr(predicates::str::contains(says));
    }
}

#[test]
fn bad_noise_flags_are_refused() {
    let tmp = TempDir::new().unwrap();
    let rec = recording(tmp.path());
    let out = tmp.path().join("e.csv");
    for (extra, msg) in [
        (
            &[
                "--measure",
                "T_housing=housing",
                "--measurement-noise-k",
                "0",
            ][..],
            "--measurement-noise-k",
        ),
        (
            &[
                "--measure",
                "T_housing=housing",
                "--process-noise-k2-per-s",
                "-1",
            ][..],
            "--process-noise-k2-per-s",
        ),
        (
            &[
                "--measure",
                "T_housing=housing",
                "--bias-noise-w2-per-s",
                "-1",
            ][..],
            "--bias-noise-w2-per-s",
        ),
        (
            &[
                "--measure",
                "T_housing=housing",
                "--bias-noise-w2-per-s",
                "NaN",
            ][..],
            "finite and >= 0",
        ),
        (
            &["--bias-noise-w2-per-s", "0"][..],
            "needs a --measure sensor",
        ),
    ] {
        refused(&rec, &out, extra, msg);
    }
}
