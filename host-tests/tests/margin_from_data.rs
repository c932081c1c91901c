//! A margin measured on the user's own device (issue 35, item 5):
//! `calibrate --validate` runs the firmware's observer over a recording the
//! fit did not see, finds how far the bench's winding thermocouple (a node
//! the product's one housing thermocouple does not read) rose above the
//! upper bound, and writes the margin that covers it into the fitted
//! file's `[observer]` table. `replay`, which reads the table as `codegen`
//! does, then finds no row where the winding's truth stands above its
//! upper bound; with the borrowed 5 % it finds thousands.
//!
//! The device: `drive-3node-truth.toml` (the bench); the model: the guess
//! `drive-3node.toml` with its winding-housing conductance 1.1 W/K (the
//! truth's is about 0.77), fitted on its heatsink's capacity alone, so the
//! winding runs hotter than the model says and no sensor of the product
//! can see it.

use std::fs;
use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use serde_json::Value;
use tempfile::TempDir;

fn models() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models")
}

fn run(args: &[&str]) -> Value {
    let out = cargo_bin_cmd!("coil-thermal")
        .args(args)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    serde_json::from_slice(&out).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Rows where the winding's truth is above the replayed upper bound, and
/// the worst \[K\].
fn cold_misses(model: &Path, recording: &Path) -> (u64, f64) {
    let r = run(&[
        "replay",
        "--model",
        s(model),
        "--trace",
        s(recording),
        "--measure",
        "housing_tc=housing",
        "--truth",
        "winding_tc=winding",
        "--json",
    ]);
    let miss = &r["cold_misses"][0];
    assert_eq!(miss["node"], "winding", "{r}");
    (
        miss["rows"].as_u64().unwrap(),
        miss["worst_k"].as_f64().unwrap_or(f64::NEG_INFINITY),
    )
}

#[test]
fn calibrate_measures_the_margin_and_replay_confirms_it() {
    let dir = TempDir::new().unwrap();
    // The held-out recording: the bench at 5 A for an hour from 24 degC,
    // 0.1 K of seeded thermocouple noise.
    let raw = dir.path().join("raw.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model"])
        .arg(models().join("drive-3node-truth.toml"))
        .args(["--current-a", "5", "--duration-s", "3600", "--dt-s", "1"])
        .args(["--ambient-c", "24", "--noise-k", "0.1", "--seed", "7"])
        .args(["--with-inputs", "--out", s(&raw)])
        .assert()
        .success();
    let text = fs::read_to_string(&raw).unwrap();
    let (header, rows) = text.split_once('\n').unwrap();
    assert_eq!(header, "time_s,winding,housing,heatsink,current,ambient");
    let recording = dir.path().join("validation.csv");
    fs::write(
        &recording,
        format!("time_s,winding_tc,housing_tc,heatsink,current,ambient\n{rows}"),
    )
    .unwrap();
    // The model whose winding runs cold.
    let guess = fs::read_to_string(models().join("drive-3node.toml")).unwrap();
    let cold = guess.replacen(
        "between = [\"winding\", \"housing\"]\ng_w_per_k = 0.8",
        "between = [\"winding\", \"housing\"]\ng_w_per_k = 1.1",
        1,
    );
    assert_ne!(cold, guess, "the winding-housing conductance is edited");
    let model = dir.path().join("cold.toml");
    fs::write(&model, cold).unwrap();
    let fitted = dir.path().join("fitted.toml");
    let trace = Path::new(env!("CARGO_MANIFEST_DIR")).join("traces/drive-3node.csv");
    let j = run(&[
        "calibrate",
        "--model",
        s(&model),
        "--trace",
        s(&trace),
        "--validate",
        s(&recording),
        "--measure",
        "winding_tc=winding",
        "--measure",
        "housing_tc=housing",
        "--params",
        "capacity.heatsink",
        "--out",
        s(&fitted),
        "--json",
    ]);
    let check = &j["margin"]["checks"][0]["nodes"][0];
    let needed = check["needed_margin"].as_f64().unwrap();
    let written = j["margin"]["written"].as_f64().unwrap();
    println!(
        "winding above its bound at most {} K with 5 %; needs {needed:.4}, written {written}",
        check["worst_above_bound_k"]
    );
    assert_eq!(check["node"], "winding");
    assert!(check["worst_above_bound_k"].as_f64().unwrap() > 1.0, "{j}");
    assert!(needed > 0.05, "the borrowed 5 % is not enough: {j}");
    assert!(written >= needed && written < needed + 0.0101, "{j}");
    let out = fs::read_to_string(&fitted).unwrap();
    assert!(
        out.contains(&format!("unmeasured_margin = {written}")),
        "{out}"
    );
    // `replay` reads the table as `codegen` does: no cold miss with the
    // measured margin; thousands with the borrowed one.
    let (rows, _) = cold_misses(&fitted, &recording);
    assert_eq!(rows, 0);
    let borrowed = dir.path().join("borrowed.toml");
    fs::write(
        &borrowed,
        out.replace(&format!("unmeasured_margin = {written}\n"), ""),
    )
    .unwrap();
    let (rows, worst_k) = cold_misses(&borrowed, &recording);
    println!("borrowed 5 %: {rows} rows above the bound, worst {worst_k:.2} K");
    assert!(rows > 1000 && worst_k > 1.0, "{rows} {worst_k}");
}

#[test]
fn a_bad_margin_in_the_table_is_refused() {
    let dir = TempDir::new().unwrap();
    let text = fs::read_to_string(models().join("drive-3node.toml")).unwrap();
    let bad = dir.path().join("bad.toml");
    fs::write(
        &bad,
        text.replace("[observer]\n", "[observer]\nunmeasured_margin = -0.1\n"),
    )
    .unwrap();
    let trace = Path::new(env!("CARGO_MANIFEST_DIR")).join("traces/drive-3node.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", s(&bad), "--trace", s(&trace)])
        .args(["--measure", "housing_tc=housing"])
        .assert()
        .failure()
        .stderr(predicates::str::contains("unmeasured_margin"));
}

#[test]
fn calibrate_says_what_an_unidentified_parameter_means() {
    // Three phases at one current under one housing thermocouple: the
    // phases stay at one temperature, so no heat crosses between them and
    // the phase-to-phase conductance has no effect on the reading.
    let dir = TempDir::new().unwrap();
    let model = models().join("three-phase-1tc.toml");
    let recording = dir.path().join("rec.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model", s(&model), "--current-a", "8"])
        .args(["--duration-s", "1800", "--dt-s", "1", "--noise-k", "0.1"])
        .args(["--with-inputs", "--out", s(&recording)])
        .assert()
        .success();
    let out = cargo_bin_cmd!("coil-thermal")
        .args(["calibrate", "--model", s(&model), "--trace", s(&recording)])
        .args([
            "--measure",
            "housing=housing",
            "--params",
            "conductance.a-b",
        ])
        .args(["--out", s(&dir.path().join("fitted.toml"))])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let text = String::from_utf8(out).unwrap();
    let note = text
        .lines()
        .find(|l| l.contains("conductance.a-b: not pinned down"))
        .unwrap_or_else(|| panic!("{text}"));
    assert!(note.contains("a node no sensor reads"), "{note}");
    // An identified parameter gets no such note.
    let identified = cargo_bin_cmd!("coil-thermal")
        .args(["calibrate", "--model", s(&model), "--trace", s(&recording)])
        .args([
            "--measure",
            "housing=housing",
            "--params",
            "capacity.housing",
        ])
        .args(["--out", s(&dir.path().join("fitted2.toml"))])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let text = String::from_utf8(identified).unwrap();
    assert!(!text.contains("not pinned down"), "{text}");
}
