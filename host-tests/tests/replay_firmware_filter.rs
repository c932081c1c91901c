//! `replay --measure` runs the firmware's filter: the library observer
//! padded to a size class, the model's sources with their heat-input biases
//! at the model file's `[observer]` settings, the padding's left out. Its
//! estimate is the one of the observer `coil-thermal codegen` generated
//! from the same file (`examples/generated/drive_3node.rs`, from
//! `drive-3node-fitted.toml`), ticked directly at 1 ms over the bench
//! recording `host-tests/traces/drive-3node.csv`, within `f32` rounding.

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::TimedReading;
use coil_thermal::Reading;
use serde_json::Value;
use tempfile::TempDir;

#[path = "../../examples/generated/drive_3node.rs"]
mod model;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `(current, ambient, winding_tc, housing_tc)` of every row of the trace.
fn trace_rows() -> Vec<[f32; 4]> {
    let text = std::fs::read_to_string(root().join("host-tests/traces/drive-3node.csv")).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f32> = l.split(',').skip(1).map(|f| f.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect()
}

/// The generated (firmware) observer ticked at 1 ms as the replay hands
/// the trace over: each row's current and ambient held for its second, the
/// row's housing reading given to the second's first tick. Returns the node
/// temperatures at every row (the start, then after each second).
fn firmware_estimates(rows: &[[f32; 4]]) -> Vec<[f32; 3]> {
    let observer = model::observer().expect("the generated parts assemble");
    let mut state = model::initial_state(&observer, rows[0][1]);
    let mut out = vec![state.outputs().temps_c];
    let mut now_us: u32 = 0;
    for [current_a, ambient_c, _, housing_tc] in &rows[..rows.len() - 1] {
        for k in 0..1000 {
            now_us += 1000;
            let reading = (k == 0).then_some(TimedReading {
                result: Ok(Reading {
                    temp_c: *housing_tc,
                    cold_junction_c: 25.0,
                }),
                sampled_at_us: now_us,
            });
            let inputs = model::Inputs {
                currents_a: model::source_currents_a(&[*current_a]),
                boundary_c: [*ambient_c],
                readings: [reading],
                now_us,
                elapsed_us: 1000,
            };
            observer.tick(&mut state, &inputs);
        }
        out.push(state.outputs().temps_c);
    }
    out
}

/// `replay` of the bench trace on the fitted model, fusing the housing
/// thermocouple with the firmware's sensor noise (0.25 K, the library's
/// default, which the generated module has); the estimate CSV's rows and
/// the JSON summary.
fn replay(dir: &Path, extra: &[&str]) -> (Vec<Vec<f64>>, Value) {
    let out = dir.join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join("host-tests/models/drive-3node-fitted.toml"))
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args([
            "--measure",
            "housing_tc=housing",
            "--truth",
            "winding_tc=winding",
        ])
        .args(["--measurement-noise-k", "0.25", "--json", "--out"])
        .arg(&out)
        .args(extra)
        .assert()
        .success();
    let json = serde_json::from_slice(&a.get_output().stdout).unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    let rows = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(1).map(|v| v.parse().unwrap()).collect())
        .collect();
    (rows, json)
}

#[test]
fn the_fused_replay_is_the_generated_firmware_observer() {
    let tmp = TempDir::new().unwrap();
    let rows = trace_rows();
    let firmware = firmware_estimates(&rows);
    let (replayed, json) = replay(tmp.path(), &[]);
    // The file's `[observer] bias_noise_w2_per_s = 1e-4`, as generated.
    let fusion = &json["fusion"];
    assert_eq!(fusion["bias_noise_w2_per_s"], 1e-4);
    assert_eq!(fusion["bias_noise_from"], "model-file");
    assert_eq!(fusion["max_cooling_bias_fraction"], 0.0);
    assert_eq!(replayed.len(), firmware.len());
    // The CSV has 6 decimals; the padded observer's tables are solved at
    // another size, so they may differ from the generated ones in the last
    // bit of an `f32`.
    let mut worst = 0.0f64;
    for (k, (r, f)) in replayed.iter().zip(&firmware).enumerate() {
        for (node, (r, f)) in r.iter().zip(f).enumerate() {
            let d = (r - f64::from(*f)).abs();
            assert!(
                d <= 2e-5,
                "row {k}, node {node}: replay {r} vs firmware {f} (off by {d} K)"
            );
            worst = worst.max(d);
        }
    }
    eprintln!(
        "replay vs the generated observer: worst {worst:.2e} K over {} rows",
        rows.len()
    );
    // The firmware's winding against the bench thermocouple it never saw
    // (codegen_round_trip: worst 0.66 K after the first minute).
    let max = json["truth"][0]["max_abs_error_k"].as_f64().unwrap();
    assert!(max < 1.0, "winding off the bench thermocouple by {max} K");
    // Frozen biases are another filter: the replay no longer matches it.
    let (frozen, json) = replay(tmp.path(), &["--bias-noise-w2-per-s", "0"]);
    assert_eq!(json["fusion"]["bias_noise_w2_per_s"], 0.0);
    assert_eq!(json["fusion"]["bias_noise_from"], "flag");
    let apart = frozen
        .iter()
        .zip(&firmware)
        .map(|(r, f)| (r[0] - f64::from(f[0])).abs())
        .fold(0.0, f64::max);
    eprintln!("frozen biases: winding up to {apart:.3} K from the firmware's");
    assert!(apart > 0.05, "frozen {apart} K");
}

/// `replay` of the bench trace on `model`, fusing the housing thermocouple
/// with no noise flag; the estimate CSV's text and the JSON summary.
fn replay_without_noise_flag(dir: &Path, model: &Path) -> (String, Value) {
    let out = dir.join("plain.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(model)
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args(["--measure", "housing_tc=housing", "--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json = serde_json::from_slice(&a.get_output().stdout).unwrap();
    (std::fs::read_to_string(&out).unwrap(), json)
}

/// Without `--measurement-noise-k` the replay fuses with the model file's
/// `[observer] sensor_sigma_k`, the noise `codegen` builds the firmware
/// with: the same estimates as the flag with that value; a file without
/// the key falls back to 0.2 K and says so.
#[test]
fn the_model_files_sensor_noise_is_the_replays_default() {
    let tmp = TempDir::new().unwrap();
    let fitted = root().join("host-tests/models/drive-3node-fitted.toml");
    let text = std::fs::read_to_string(&fitted).unwrap();
    let with_key = tmp.path().join("with-sigma.toml");
    std::fs::write(
        &with_key,
        text.replacen("[observer]\n", "[observer]\nsensor_sigma_k = 0.25\n", 1),
    )
    .unwrap();
    let (from_file, json) = replay_without_noise_flag(tmp.path(), &with_key);
    assert_eq!(json["fusion"]["sensor_sigma_k"], 0.25);
    assert_eq!(json["fusion"]["sensor_sigma_from"], "model-file");
    let (_, flagged) = replay(tmp.path(), &[]);
    assert_eq!(flagged["fusion"]["sensor_sigma_from"], "flag");
    let from_flag = std::fs::read_to_string(tmp.path().join("est.csv")).unwrap();
    assert_eq!(from_file, from_flag);
    let (default, json) = replay_without_noise_flag(tmp.path(), &fitted);
    assert_eq!(json["fusion"]["sensor_sigma_k"], 0.2);
    assert_eq!(json["fusion"]["sensor_sigma_from"], "default");
    assert_ne!(default, from_flag);
}
