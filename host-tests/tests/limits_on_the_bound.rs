//! `limits` answers for the bound the firmware protects on: its time to
//! limit at a held current is the one the generated observer
//! (`examples/generated/drive_3node.rs`, ticked at 1 ms from the ambient,
//! its thermocouple silent) publishes for its upper bound, and it errs
//! early against what the module then does: its published bound crosses
//! the derated alarm limit no sooner (the predictor takes the winding's
//! resistance at its limit, the hot end), and its mean later still.

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::network::NetworkInputs;
use serde_json::Value;

#[path = "../../examples/generated/drive_3node.rs"]
mod model;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

const CURRENT_A: f32 = 8.0;
const AMBIENT_C: f32 = 22.0;

/// The generated observer held at [`CURRENT_A`] from the ambient: its
/// published time to limit of the winding after the first second, and
/// when its winding bound and mean first reach the winding's alarm limit
/// \[s\].
fn crossings() -> (f64, f64, f64) {
    let observer = model::observer().expect("the generated parts assemble");
    let mut state = model::initial_state(&observer, AMBIENT_C);
    let limit_c = observer.alarm().alarm_limit_c(0, AMBIENT_C).unwrap();
    let currents_a = model::source_currents_a(&[CURRENT_A], &[]);
    let (mut predicted_s, mut bound_s, mut mean_s) = (None, None, None);
    let mut now_us = 0u32;
    // The limiter would cut the current: the command is held regardless
    // (the question is when, not whether).
    for tick in 1..=400_000u32 {
        now_us = now_us.wrapping_add(1000);
        let inputs = NetworkInputs {
            currents_a,
            boundary_c: [AMBIENT_C],
            readings: [None],
            now_us,
            elapsed_us: 1000,
        };
        observer.tick(&mut state, &inputs);
        let o = state.outputs();
        let t = f64::from(tick) * 1e-3;
        if tick == 1000 {
            predicted_s = o.time_to_limit_s[0].map(|s| t + f64::from(s));
        }
        if bound_s.is_none() && o.upper_c[0] >= limit_c {
            bound_s = Some(t);
        }
        if mean_s.is_none() && o.temps_c[0] >= limit_c {
            mean_s = Some(t);
        }
        if mean_s.is_some() {
            break;
        }
    }
    (predicted_s.unwrap(), bound_s.unwrap(), mean_s.unwrap())
}

#[test]
fn limits_time_to_limit_is_when_the_flashed_bound_crosses() {
    let a = cargo_bin_cmd!("coil-thermal")
        .current_dir(root())
        .args([
            "limits",
            "--model",
            "host-tests/models/drive-3node-fitted.toml",
            "--current-a",
            "8",
            "--json",
        ])
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(json["acts_on"], "upper bound", "{json}");
    let ttl_s = json["time_to_limit_s"]["winding"].as_f64().unwrap();
    let (predicted_s, bound_s, mean_s) = crossings();
    eprintln!(
        "limits {ttl_s:.3} s; the flashed observer predicts {predicted_s:.3} s, its bound crosses at {bound_s:.3} s, its mean at {mean_s:.3} s"
    );
    // What the MCU prints, to the predictors' horizon grids (each up to
    // 2.1 % early: `coil_thermal::protect::predict`).
    assert!(
        (ttl_s - predicted_s).abs() <= 0.021 * ttl_s,
        "limits {ttl_s} s, firmware {predicted_s} s"
    );
    // Errs early, never late, against the bound the module publishes.
    assert!(ttl_s <= bound_s, "limits {ttl_s} s, bound {bound_s} s");
    // And on the bound, not the mean, which crosses well after.
    assert!(mean_s > bound_s + 5.0, "mean {mean_s} s, bound {bound_s} s");
}
