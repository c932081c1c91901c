//! `coil-thermal faults` start classes (issue 35): a reset with no snapshot
//! at the hottest point of a closed-loop run after 0 s, 1 min, 10 min and
//! 1 h off, and a restore whose off time is unknown, on a model file's
//! network observer (the firmware's), the drive obeying its limits, at the
//! firmware's 1 ms step. Goals: the plant never above its derated alarm
//! limit, no healthy reading refused, the upper bound of every limited node
//! no sensor reads at most 1 K below the truth from the second correction
//! period on. The Omnimagnet's `OmniObserver` runs the two hardest
//! classes (the longest reset, the restore) against its nonlinear plant,
//! at its flashed 5 ms model step, and every class on a loop at the
//! campaign's default 100 ms step.

use assert_cmd::cargo::cargo_bin_cmd;
use serde_json::Value;

const STARTS: &str = "reset-0s,reset-1min,reset-10min,reset-1h,restore-unknown-off";

fn starts(model: &str, current_a: &str, classes: &str, step_us: &str) -> Value {
    let path = if model == "omnimagnet" {
        model.to_string()
    } else {
        format!("{}/models/{model}.toml", env!("CARGO_MANIFEST_DIR"))
    };
    let out = cargo_bin_cmd!("coil-thermal")
        .args([
            "faults",
            "--model",
            &path,
            "--current-a",
            current_a,
            "--duration-s",
            "1200",
            "--step-us",
            step_us,
            "--classes",
            classes,
            "--json",
        ])
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    serde_json::from_slice(&out).unwrap()
}

fn check(model: &str, current_a: &str, classes: &str, step_us: &str) {
    let r = starts(model, current_a, classes, step_us);
    let cases = r["cases"].as_array().unwrap();
    assert_eq!(cases.len(), classes.split(',').count(), "{r}");
    for c in cases {
        let s = &c["start"];
        println!(
            "{model} {current_a} A {}: off {} s, restart {:.0} s, over limit {:+.2} K, under bound {}, refused {}, first limit {:.0} %",
            c["class"],
            s["off_s"],
            s["restart_s"].as_f64().unwrap(),
            s["over_limit_k"].as_f64().unwrap(),
            s["under_bound_k"],
            s["refused"],
            100.0 * s["first_limit_share"].as_f64().unwrap()
        );
        assert!(s["over_limit_k"].as_f64().unwrap() <= 0.0, "{c}");
        assert_eq!(s["refused"], 0, "{c}");
        assert!(s["under_bound_k"].as_f64().unwrap() <= 1.0, "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
        // A restart holds the current back at first: the start does not
        // assume a cold device.
        if c["class"] != "restore-unknown-off" {
            assert!(s["first_limit_share"].as_f64().unwrap() < 0.7, "{c}");
        }
    }
    for goal in r["summary"]["goals"].as_array().unwrap() {
        if goal["goal"].as_str().unwrap().starts_with("starts:") {
            assert_eq!(goal["met"], true, "{goal}");
        }
    }
}

#[test]
fn drive_3node_starts_safe_after_every_off_time() {
    check("drive-3node", "8", STARTS, "1000");
}

#[test]
fn a_three_phase_motor_with_one_housing_thermocouple_starts_safe() {
    check("three-phase-1tc", "15", STARTS, "1000");
}

/// The Omnimagnet's restore with the off time unknown used to refuse every
/// healthy reading (5 268 here): its outer solenoid warms from the inner
/// one while the device is off, so its reading fitted the uncooled
/// snapshot and the off-time search stopped at 0 s, leaving the inner
/// solenoid 22 K hot. At the flashed Omnimagnet's 5 ms model step (one
/// step a tick here; the figures are those of 1 ms steps to 0.01 K).
#[test]
fn the_omnimagnet_restarts_safe_after_an_hour_and_an_unknown_off_time() {
    check(
        "omnimagnet",
        "7,3.1,3.1",
        "reset-1h,restore-unknown-off",
        "5000",
    );
}

/// At the campaign's default 100 ms step (a loop at the model's step,
/// five ticks per 0.5 s correction period) the start's held covariance
/// took one slice a light tick, about ten correction periods per
/// propagation: every start class refused 3 000 to 6 500 healthy readings
/// against the stale prior. The slices per tick now follow the declared
/// loop; the figures are those of the 5 ms run to 0.1 K.
#[test]
fn the_omnimagnet_starts_safe_on_a_loop_at_its_100_ms_step() {
    check("omnimagnet", "7,3.1,3.1", STARTS, "100000");
}
