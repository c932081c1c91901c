//! `coil-thermal faults` (issue 17's fault campaign) on a short
//! configuration: the report's structure, a few facts it must show, and
//! its argument errors.

use assert_cmd::cargo::cargo_bin_cmd;
use predicates::str::contains;
use serde_json::Value;

fn ct() -> assert_cmd::Command {
    cargo_bin_cmd!("coil-thermal")
}

fn json_run(args: &[&str]) -> Value {
    let out = ct()
        .args(args)
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    let text = String::from_utf8(out).unwrap();
    assert_eq!(text.trim().lines().count(), 1, "one JSON line: {text}");
    serde_json::from_str(&text).unwrap()
}

fn cases<'v>(report: &'v Value, class: &str) -> Vec<&'v Value> {
    report["cases"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|c| c["class"] == class)
        .collect()
}

/// 7 A (the clean run shuts down at about 507 s), three sensors, two
/// onsets, four classes.
#[test]
fn overload_open_circuit_flagged_at_once_and_spikes_trip_on_time() {
    let r = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--sensors",
        "0,2,4",
        "--duration-s",
        "600",
        "--onset-s",
        "60,200",
        "--classes",
        "open,spikes,corrupt-snapshot,frozen-clock",
        "--json",
    ]);
    assert_eq!(r["model"], "omnimagnet");
    assert_eq!(r["sensors"], serde_json::json!([0, 2, 4]));
    let clean_s = r["clean"]["shutdown_s"].as_f64().expect("7 A shuts down");
    assert!((400.0..600.0).contains(&clean_s), "{clean_s}");
    // 3 sensors x 2 onsets for each per-sensor class, 2 for the others.
    assert_eq!(r["cases"].as_array().unwrap().len(), 6 + 6 + 2 + 2);
    for c in cases(&r, "open") {
        let flag = c["flag_s"].as_f64().expect("open circuit flagged");
        assert!(flag <= 1.0, "{c}");
        // (No bound on the estimate error here: with sensors 0,2,4 an open
        // thermocouple leaves its solenoid unmeasured, 3.8 K off for #4.)
        assert_eq!(c["lost_shutdown"], false, "{c}");
        assert_eq!(c["late_shutdown"], false, "{c}");
    }
    for c in cases(&r, "spikes") {
        assert!(c["flag_s"].as_f64().unwrap() <= 1.0, "{c}");
        let delay = c["shutdown_delay_s"].as_f64().expect("trips under spikes");
        assert!(delay <= 1.0, "{c}");
    }
    // The only sensor drifting -0.05 K/s: once the gate has refused it
    // twice it is held out of the gate's recovery and the estimate goes
    // back to the model (it was dragged 7.8 K below the truth).
    for c in cases(&r, "drift") {
        assert_eq!(c["flag_goal_met"], true, "{c}");
        assert!(c["max_error_tc_k"].as_f64().unwrap() <= 2.0, "{c}");
        assert!(c["max_error_hot_spot_k"].as_f64().unwrap() <= 2.0, "{c}");
    }
    for c in cases(&r, "corrupt-snapshot") {
        assert_eq!(c["snapshot"]["refused"], true, "{c}");
        assert_eq!(c["snapshot"]["starts_latched"], true, "{c}");
    }
    for c in cases(&r, "frozen-clock") {
        // The model is lost 1 s after the clock stops: a safe shutdown.
        assert!(c["shutdown_delay_s"].as_f64().unwrap() < 0.0, "{c}");
    }
    let summary = &r["summary"];
    assert_eq!(summary["lost_shutdowns"], 0);
    assert_eq!(summary["late_shutdowns"], 0);
    assert_eq!(summary["classes"].as_array().unwrap().len(), 4);
    assert_eq!(summary["goals"].as_array().unwrap().len(), 6);
}

/// A sub-critical current: the clean run never shuts down, nor does a
/// spike train; a stale snapshot's latched start is a protective trip.
#[test]
fn no_false_trip_under_spikes_below_the_limit() {
    let r = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "3.1",
        "--duration-s",
        "300",
        "--sensors",
        "1,3,5",
        "--max-snapshot-age-s",
        "60",
        "--classes",
        "spikes,stale-snapshot",
        "--json",
    ]);
    assert!(r["clean"]["shutdown_s"].is_null(), "{}", r["clean"]);
    assert_eq!(r["onsets_s"], serde_json::json!([60.0, 150.0]));
    for c in cases(&r, "spikes") {
        assert!(c["shutdown_s"].is_null(), "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
    }
    for c in cases(&r, "stale-snapshot") {
        assert_eq!(c["snapshot"]["refused"], true, "{c}");
        assert_eq!(c["protective_trip"], true, "{c}");
    }
    assert_eq!(r["summary"]["false_trips_spikes"], 0);
}

#[test]
fn text_report_names_the_goals() {
    ct().args([
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--duration-s",
        "120",
        "--onset-s",
        "30",
        "--classes",
        "jump-down",
    ])
    .assert()
    .success()
    .stdout(contains("jump-down"))
    .stdout(contains("no lost shutdown"));
}

#[test]
fn argument_errors_are_clear() {
    let cases: [(&[&str], &str); 10] = [
        (
            &[
                "--model",
                "omnimagnet",
                "--current-a",
                "7",
                "--reading-period-ms",
                "250",
            ],
            "whole number",
        ),
        (&["--model", "omnimagnet"], "--current-a"),
        (
            &["--model", "omnimagnet", "--current-a", "7,7"],
            "1 or 3 values",
        ),
        (
            &[
                "--model",
                "omnimagnet",
                "--current-a",
                "7",
                "--sensors",
                "6",
            ],
            "no thermocouple 6",
        ),
        (
            &[
                "--model",
                "omnimagnet",
                "--current-a",
                "7",
                "--classes",
                "melted",
            ],
            "unknown class `melted`",
        ),
        (
            &["--model", "hppa", "--current-a", "7"],
            "not yet available",
        ),
        (&["--model", "nosuch", "--current-a", "7"], "unknown model"),
        (
            &[
                "--model",
                "omnimagnet",
                "--current-a",
                "7",
                "--duration-s",
                "-1",
            ],
            "--duration-s",
        ),
        (
            &[
                "--model",
                "omnimagnet",
                "--current-a",
                "7",
                "--sensor-quantum-k",
                "-0.25",
            ],
            "--sensor-quantum-k must be finite and >= 0",
        ),
        (
            &[
                "--model",
                "omnimagnet",
                "--current-a",
                "7",
                "--sensor-noise-k",
                "NaN",
            ],
            "--sensor-noise-k must be finite and >= 0",
        ),
    ];
    for (args, message) in cases {
        ct().arg("faults")
            .args(args)
            .assert()
            .failure()
            .stderr(contains(message));
    }
}

/// On a recorded trace: the currents of its rows drive the plant for its
/// span; 7 A then a rest at 2 A, which the clean run survives.
#[test]
fn runs_on_a_trace() {
    let dir = tempfile::TempDir::new().unwrap();
    let path = dir.path().join("omni.csv");
    let mut text = String::from("time_s,I1_a,I2_a,I3_a,ambient\n");
    for t in 0..=300 {
        let i = if t < 150 { 7.0 } else { 2.0 };
        text.push_str(&format!("{t},{i},{i},{},23\n", 0.5 * i));
    }
    std::fs::write(&path, text).unwrap();
    let r = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--trace",
        path.to_str().unwrap(),
        "--sensors",
        "0,3,4",
        "--classes",
        "jump-up,power-off",
        "--off-s",
        "30",
        "--json",
    ]);
    assert_eq!(r["duration_s"], 300.0);
    assert!(r["trace"].as_str().unwrap().ends_with("omni.csv"));
    assert!(r["clean"]["shutdown_s"].is_null());
    assert_eq!(r["onsets_s"], serde_json::json!([60.0, 150.0]));
    for c in cases(&r, "jump-up") {
        assert!(c["flag_s"].as_f64().unwrap() <= 1.0, "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
    }
    for c in cases(&r, "power-off") {
        assert_eq!(c["snapshot"]["refused"], false, "{c}");
        assert!(c["max_error_tc_k"].as_f64().unwrap() < 1.0, "{c}");
    }
}

/// Issue 17's hardest placement: one thermocouple per solenoid. At 3.1 A
/// (no clean shutdown, slow heating) a stuck sensor is flagged within the
/// goal once it is off the truth by the stuck threshold and drags no
/// estimate more than 2 K; at 7 A a drift delays no shutdown (its
/// solenoid's protection falls back on the hotter of the estimate and the
/// physics once the drift is flagged). No heat-bias alarm in a clean run.
#[test]
fn one_per_solenoid_stuck_and_drift_meet_the_goals() {
    let slow = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "3.1",
        "--sensors",
        "0,2,4",
        "--classes",
        "stuck",
        "--json",
    ]);
    assert_eq!(slow["schema_version"], 1);
    assert_eq!(slow["clean"]["bias_alarm_ticks"], 0);
    for c in cases(&slow, "stuck") {
        assert_eq!(c["flag_goal_met"], true, "{c}");
        let detectable = c["detectable_s"].as_f64().expect("detectable");
        assert!(c["flag_s"].as_f64().unwrap() <= detectable + 10.0, "{c}");
        assert!(c["max_error_tc_k"].as_f64().unwrap() < 2.0, "{c}");
        assert!(c["max_error_hot_spot_k"].as_f64().unwrap() < 2.0, "{c}");
    }
    let fast = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--sensors",
        "0,2,4",
        "--duration-s",
        "600",
        "--classes",
        "drift",
        "--json",
    ]);
    assert_eq!(fast["clean"]["bias_alarm_ticks"], 0);
    for c in cases(&fast, "drift") {
        assert_eq!(c["flag_goal_met"], true, "{c}");
        assert_eq!(c["late_shutdown"], false, "{c}");
        assert_eq!(c["lost_shutdown"], false, "{c}");
    }
    assert_eq!(fast["summary"]["late_shutdowns"], 0);
    // Re-linearised every 10 s (the documented configuration for one per
    // solenoid), a -0.05 K/s drift no longer drags its solenoid 2.1 K:
    // once it is in doubt its negative heat bias is dropped and the
    // estimate returns toward the model.
    let relin = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "3.1",
        "--sensors",
        "0,2,4",
        "--relinearize-s",
        "10",
        "--classes",
        "drift,open",
        "--json",
    ]);
    for class in ["drift", "open"] {
        for c in cases(&relin, class) {
            assert_eq!(c["flag_goal_met"], true, "{c}");
            assert!(c["max_error_tc_k"].as_f64().unwrap() <= 2.0, "{c}");
            assert!(c["max_error_hot_spot_k"].as_f64().unwrap() <= 2.0, "{c}");
        }
    }
}

/// A model file (`--model FILE.toml`): its `[observer]` table built into
/// the library's network observer, the model itself as the plant, one
/// thermocouple on the housing. At 6 A the clean run latches (at about
/// 458 s); a detached (open), stuck or ambient-reading housing sensor is
/// flagged, and no shutdown is lost or late.
#[test]
fn a_model_file_runs_the_matrix_on_its_network_observer() {
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/drive-3node-fitted.toml"
    );
    let r = json_run(&[
        "faults",
        "--model",
        model,
        "--current-a",
        "6",
        "--duration-s",
        "600",
        "--onset-s",
        "60,200",
        "--classes",
        "open,stuck,drift,all-detached,spikes,corrupt-snapshot",
        "--json",
    ]);
    assert_eq!(r["model"], "drive-3node");
    assert_eq!(r["sensors"], serde_json::json!([0]));
    // The firmware's filter: the file's heat-bias noise (as `codegen`
    // builds it), not frozen biases.
    assert_eq!(r["bias_noise_w2_per_s"], 0.0001);
    assert_eq!(r["clean"]["bias_alarm_ticks"], 0);
    let clean_s = r["clean"]["shutdown_s"].as_f64().expect("6 A shuts down");
    assert!((300.0..600.0).contains(&clean_s), "{clean_s}");
    assert_eq!(r["clean"]["healthy_flagged"], 0);
    // 1 sensor x 2 onsets for each class.
    assert_eq!(r["cases"].as_array().unwrap().len(), 12);
    for c in r["cases"].as_array().unwrap() {
        assert_eq!(c["lost_shutdown"], false, "{c}");
        assert_eq!(c["late_shutdown"], false, "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
        assert!(c["flag_s"].as_f64().is_some(), "flagged: {c}");
    }
    for class in ["open", "all-detached", "spikes"] {
        for c in cases(&r, class) {
            assert!(c["flag_s"].as_f64().unwrap() <= 1.0, "{c}");
        }
    }
    // The estimate goal on the sensor's node and on the winding no sensor
    // sees: a cold drift may not take heat away from the model (it dragged
    // the winding 28.8 K cold before the bias floor).
    for class in ["stuck", "drift"] {
        for c in cases(&r, class) {
            assert_eq!(c["flag_goal_met"], true, "{c}");
            assert!(c["max_error_tc_k"].as_f64().unwrap() <= 2.0, "{c}");
            assert!(c["max_error_hot_spot_k"].as_f64().unwrap() <= 2.0, "{c}");
        }
    }
    for c in cases(&r, "corrupt-snapshot") {
        assert_eq!(c["snapshot"]["refused"], true, "{c}");
        assert_eq!(c["snapshot"]["starts_latched"], true, "{c}");
    }
    // Its sensors are the model's: one.
    ct().args([
        "faults",
        "--model",
        model,
        "--current-a",
        "6",
        "--sensors",
        "1",
    ])
    .assert()
    .failure()
    .stderr(contains("no thermocouple 1"));
    // A model without `[observer] sensors` has no thermocouple to fault.
    let bare = concat!(env!("CARGO_MANIFEST_DIR"), "/models/drive-3node-truth.toml");
    ct().args(["faults", "--model", bare, "--current-a", "6"])
        .assert()
        .failure()
        .stderr(contains("[observer] sensors"));
}

/// A winding's resistance as the only sensor
/// (`drive-3node-resistance.toml`): the campaign builds the observer with
/// the resistance sensor as `codegen` does and hands it what the drive
/// measures (the truth's ohms with the sensor's 1 % noise; an open winding
/// `+inf`, a short 0 ohm or a negative drop). Every fault is flagged within
/// 1 s of becoming detectable (a drift once it leaves the sensor's band,
/// which lies lower by the resistance's noise), no shutdown is lost and
/// none is false; after a reset 10 min off no healthy reading is refused
/// and the plant stays under its limits. (A reset within a minute of
/// overheating trips: the start cannot see the housing, which only the
/// thermocouple this model lacks measured, and takes it as hot as the
/// winding's reading, above the housing's 80 degC; the note of issue 38
/// gives the figures.)
#[test]
fn a_winding_resistance_runs_the_campaign() {
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/drive-3node-resistance.toml"
    );
    let r = json_run(&[
        "faults",
        "--model",
        model,
        "--current-a",
        "6",
        "--duration-s",
        "600",
        "--onset-s",
        "60,200",
        "--classes",
        "open,short-gnd,short-vcc,jump-up,jump-down,spikes,drift,dropout,reset-10min",
        "--json",
    ]);
    assert_eq!(r["model"], "drive-3node-resistance");
    assert_eq!(r["clean"]["healthy_flagged"], 0);
    assert!(
        r["clean"]["shutdown_s"].as_f64().is_some(),
        "6 A shuts down"
    );
    for c in r["cases"].as_array().unwrap() {
        assert_eq!(c["lost_shutdown"], false, "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
        if c["class"] != "reset-10min" {
            assert!(c["flag_s"].as_f64().is_some(), "flagged: {c}");
            assert_eq!(c["flag_goal_met"], true, "{c}");
        }
    }
    for class in ["open", "short-gnd", "short-vcc", "jump-up", "jump-down"] {
        for c in cases(&r, class) {
            assert!(c["flag_s"].as_f64().unwrap() <= 0.1, "{c}");
        }
    }
    for c in cases(&r, "reset-10min") {
        assert_eq!(c["start"]["refused"], 0, "{c}");
        assert!(c["start"]["over_limit_k"].as_f64().unwrap() <= 0.0, "{c}");
    }
}

/// A second source on the housing, the node its one thermocouple is on:
/// the campaign's observer cannot carry a bias on each (its steady gain
/// does not converge) and shares one heat bias between them by default;
/// `[observer] bias_sources` naming the winding's source builds it, and with the second
/// source carrying a negligible heat (1 nano-ohm) the campaign is the
/// one-source model's.
#[test]
fn bias_sources_let_the_campaign_run_what_one_sensor_can_see() {
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/drive-3node-fitted.toml"
    );
    let text = std::fs::read_to_string(model).unwrap();
    let extra = "[[source]]\nname = \"extra\"\nnode = \"housing\"\ninput = \"current\"\nr0_ohm = 1e-9\n\n[observer]";
    let two = text.replace("[observer]", extra);
    let tmp = tempfile::TempDir::new().unwrap();
    let path = tmp.path().join("two.toml");
    let args = |m: &str| {
        [
            "faults",
            "--model",
            m,
            "--current-a",
            "6",
            "--duration-s",
            "600",
            "--onset-s",
            "60",
            "--classes",
            "stuck,drift",
            "--json",
        ]
        .map(String::from)
    };
    std::fs::write(&path, &two).unwrap();
    let p = path.to_str().unwrap();
    // The default builds: the two sources share one heat bias in
    // proportion to their Joule power, where a bias per source has no
    // steady gain.
    ct().args(args(p)).assert().success();
    std::fs::write(
        &path,
        two.replace("[observer]", "[observer]\nbias_sources = [\"winding\"]"),
    )
    .unwrap();
    let named = json_run(&args(p).each_ref().map(String::as_str));
    let one = json_run(&args(model).each_ref().map(String::as_str));
    let shutdown = |r: &Value| r["clean"]["shutdown_s"].as_f64().expect("6 A shuts down");
    assert!(
        (shutdown(&named) - shutdown(&one)).abs() <= 0.01,
        "{} vs {}",
        shutdown(&named),
        shutdown(&one)
    );
    for (a, b) in named["cases"]
        .as_array()
        .unwrap()
        .iter()
        .zip(one["cases"].as_array().unwrap())
    {
        for key in ["flag_s", "max_error_tc_k", "max_error_hot_spot_k"] {
            let (x, y) = (a[key].as_f64().unwrap(), b[key].as_f64().unwrap());
            assert!(
                (x - y).abs() <= 1e-3 * y.abs().max(1.0),
                "{key}: {x} vs {y}"
            );
        }
    }
}

/// On its recorded trace the drive's housing warms 1 K in 273 s but never
/// 1 K within the stuck test's 120 s window before about 300 s: a sensor
/// stuck at the 60 s onset is flagged within 10 s of the truth leaving its
/// reading by 1 K (the slow test, since the reading's last change; with
/// the window alone it was 65 s late), and the estimate stays within 2 K.
#[test]
fn a_sensor_stuck_near_the_ambient_on_the_trace_is_flagged_in_time() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let model = format!("{dir}/models/drive-3node-fitted.toml");
    let trace = format!("{dir}/traces/drive-3node.csv");
    let r = json_run(&[
        "faults",
        "--model",
        &model,
        "--trace",
        &trace,
        "--classes",
        "stuck",
        "--onset-s",
        "60,1800",
        "--json",
    ]);
    assert_eq!(r["clean"]["healthy_flagged"], 0);
    let stuck = cases(&r, "stuck");
    assert_eq!(stuck.len(), 2);
    // Stuck at 1800 s while the drive cools: once flagged, the heat the
    // unchanged reading taught goes back (6.3 K hot at the winding an hour
    // on before).
    for c in &stuck {
        assert!(c["max_error_hot_spot_k"].as_f64().unwrap() <= 2.0, "{c}");
    }
    let c = stuck[0];
    let (flag_s, detectable_s) = (
        c["flag_s"].as_f64().expect("flagged"),
        c["detectable_s"].as_f64().expect("detectable"),
    );
    assert!(
        (0.0..=10.0).contains(&(flag_s - detectable_s)),
        "flagged {flag_s} s, detectable {detectable_s} s"
    );
    assert_eq!(c["flag_goal_met"], true, "{c}");
    assert!(c["max_error_tc_k"].as_f64().unwrap() <= 2.0, "{c}");
}

/// One thermocouple per solenoid is accepted only with the model refresh
/// (issue 17): the campaign declares and runs it by default (10 s), and
/// `--relinearize-s 0` (no refresh) is refused at build, naming the
/// solenoid and what to do.
#[test]
fn one_per_solenoid_needs_the_model_refresh() {
    ct().args([
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--sensors",
        "0,2,4",
        "--relinearize-s",
        "0",
        "--classes",
        "open",
    ])
    .assert()
    .failure()
    .stderr(contains("solenoid 0"))
    .stderr(contains("model_refresh_s"))
    .stderr(contains("--relinearize-s"));
    // Slower than the observer's bound (30 s): refused too.
    ct().args([
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--sensors",
        "0,2,4",
        "--relinearize-s",
        "31",
        "--classes",
        "open",
    ])
    .assert()
    .failure()
    .stderr(contains("at most 30 s"));
    // Six thermocouples need none, and get none by default.
    let six = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--duration-s",
        "100",
        "--classes",
        "open",
        "--json",
    ]);
    assert_eq!(six["relinearize_s"], 0.0);
    // Without the refresh an open sensor left its solenoid 3.7 K off at
    // 7 A; with it, the model alone follows.
    let r = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--sensors",
        "0,2,4",
        "--duration-s",
        "600",
        "--classes",
        "open,refresh-stops",
        "--json",
    ]);
    assert_eq!(r["relinearize_s"], 10.0);
    for c in cases(&r, "open") {
        assert!(c["max_error_tc_k"].as_f64().unwrap() <= 2.0, "{c}");
        assert!(c["max_error_hot_spot_k"].as_f64().unwrap() <= 2.0, "{c}");
    }
    // The background task dies at the onset: flagged `MODEL_STALE` once
    // three periods (30 s) have passed since its last install, and the
    // protection then errs hot (the shadow's bound): never later than the
    // clean run, never lost.
    let stops = cases(&r, "refresh-stops");
    assert_eq!(stops.len(), 2);
    for c in stops {
        let flag = c["flag_s"].as_f64().expect("a dead refresh is flagged");
        assert!((20.0..=30.5).contains(&flag), "{c}");
        let delay = c["shutdown_delay_s"].as_f64().expect("shuts down");
        assert!(delay <= 0.0, "{c}");
        assert_eq!(c["lost_shutdown"], false, "{c}");
        assert!(c["max_error_hot_spot_k"].as_f64().unwrap() <= 2.0, "{c}");
    }
    // No refresh, no such case.
    ct().args([
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--classes",
        "refresh-stops",
    ])
    .assert()
    .failure()
    .stderr(contains("needs a model refresh"));
}

/// The clean run and the single-fault cases with the thermocouples as the
/// MAX31855 reads them (0.25 K codes, the campaign's default): a healthy
/// quantised reading repeats its code for seconds to minutes, which the
/// stuck test (a reading unchanged to the bit while the physics moves)
/// must not take for a stuck sensor, and a false verdict would also take
/// back the heat the network observer learnt. No healthy reading is
/// refused and every goal holds on the Omnimagnet with one thermocouple
/// per solenoid at 3.1 A (the slowest heating) and on `drive-3node`'s
/// recorded hour (stuck at 60 s near the ambient and at 1800 s while it
/// cools). The readings really are quantised: off the truth by up to half
/// a code (0 with `--sensor-quantum-k 0`, where the readings differ every
/// time), and a code repeats.
#[test]
fn quantised_sensors_refuse_no_healthy_reading_and_keep_the_goals() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let model = format!("{dir}/models/drive-3node-fitted.toml");
    let trace = format!("{dir}/traces/drive-3node.csv");
    let omni = [
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "3.1",
        "--sensors",
        "0,2,4",
        "--duration-s",
        "600",
        "--onset-s",
        "60",
        "--classes",
        "stuck,drift,open",
        "--json",
    ];
    let drive = [
        "faults",
        "--model",
        &model,
        "--trace",
        &trace,
        "--onset-s",
        "60,1800",
        "--classes",
        "stuck,drift,spikes",
        "--json",
    ];
    for (args, min_repeat_s) in [(&omni[..], 5.0), (&drive[..], 30.0)] {
        let r = json_run(args);
        // The default: the MAX31855's code, no noise.
        assert_eq!(r["sensor_quantum_k"], 0.25, "{args:?}");
        assert_eq!(r["sensor_noise_k"], 0.0, "{args:?}");
        let clean = &r["clean"];
        assert_eq!(clean["healthy_flagged"], 0, "{args:?}: {clean}");
        assert_eq!(clean["bias_alarm_ticks"], 0, "{args:?}: {clean}");
        let off = clean["max_reading_error_k"].as_f64().unwrap();
        assert!((0.1..=0.125 + 1e-6).contains(&off), "{args:?}: {clean}");
        let repeat = clean["longest_repeat_s"].as_f64().unwrap();
        assert!(repeat >= min_repeat_s, "{args:?}: {clean}");
        for c in r["cases"].as_array().unwrap() {
            assert_eq!(c["healthy_flagged"], 0, "{c}");
            assert!(
                c["max_reading_error_k"].as_f64().unwrap() <= 0.125 + 1e-6,
                "{c}"
            );
        }
        for g in r["summary"]["goals"].as_array().unwrap() {
            assert_eq!(g["met"], true, "{args:?}: {g}");
        }
    }
    // Exact readings (the plant's truth to the bit) are what the campaign
    // judged before: never off the truth, never repeated while it heats.
    let mut exact = omni.to_vec();
    exact.extend(["--sensor-quantum-k", "0"]);
    let r = json_run(&exact);
    assert_eq!(r["sensor_quantum_k"], 0.0);
    assert_eq!(r["clean"]["max_reading_error_k"], 0.0);
    assert_eq!(r["clean"]["longest_repeat_s"], 0.0);
    // Noise is seeded: the same run twice reads the same; noise beyond
    // half a code shows it is there.
    let mut noisy = omni.to_vec();
    noisy.extend(["--sensor-noise-k", "0.1"]);
    let (a, b) = (json_run(&noisy), json_run(&noisy));
    assert_eq!(a, b);
    assert_eq!(a["sensor_noise_k"], 0.1);
    assert_eq!(a["sensor_noise_seed"], 17);
    assert!(a["clean"]["max_reading_error_k"].as_f64().unwrap() > 0.125);
}

/// With 0.1 K of noise on the converter's codes, drive-3node's one housing
/// thermocouple detached at 60 s reads the room as changing codes: the bit
/// test never calls it stuck and the band holds it only after minutes,
/// 3.4 K off; a stuck-test tolerance of 0.3 K (one code and twice the
/// noise) calls it stuck once the physics moved 1 K, within 1 K of the
/// truth, and refuses no healthy reading.
#[test]
fn a_stuck_tolerance_sees_a_noisy_detached_sensor() {
    let dir = env!("CARGO_MANIFEST_DIR");
    let model = format!("{dir}/models/drive-3node-fitted.toml");
    let trace = format!("{dir}/traces/drive-3node.csv");
    let run = |tolerance: &str| {
        json_run(&[
            "faults",
            "--model",
            &model,
            "--trace",
            &trace,
            "--classes",
            "all-detached",
            "--onset-s",
            "60",
            "--sensor-noise-k",
            "0.1",
            "--stuck-tolerance-k",
            tolerance,
            "--json",
        ])
    };
    let error_k = |r: &Value| {
        cases(r, "all-detached")[0]["max_error_tc_k"]
            .as_f64()
            .unwrap()
    };
    let bit = run("0");
    assert_eq!(bit["stuck_tolerance_k"], 0.0);
    assert!(error_k(&bit) > 3.0, "{}", bit["cases"]);
    let tolerant = run("0.3");
    assert_eq!(tolerant["stuck_tolerance_k"], 0.3);
    assert_eq!(tolerant["clean"]["healthy_flagged"], 0);
    assert!(error_k(&tolerant) < 1.0, "{}", tolerant["cases"]);
    // A tolerance the observer cannot take is refused by name.
    ct().args([
        "faults",
        "--model",
        &model,
        "--current-a",
        "6",
        "--stuck-tolerance-k",
        "-1",
    ])
    .assert()
    .failure()
    .stderr(contains("stuck_tolerance_k"));
}

/// The bias floor in the campaign (issue 36, section 3): `drive-3node` at
/// the library's default heat-bias noise (1e-3 W^2/s; the file's 1e-4
/// line removed) on its recorded hour, the housing thermocouple drifting
/// cold. With the floor (no reading takes heat away from the model) the
/// unmeasured winding stays within 0.5 K; with the floor removed (a share
/// of 1e9 of the Joule power may be explained away) the drift drags it
/// 2.9-3.3 K cold and the campaign's 2 K goal is not met.
#[test]
fn the_campaign_shows_what_the_bias_floor_prevents() {
    let dir = tempfile::TempDir::new().unwrap();
    let fitted = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/drive-3node-fitted.toml"
    ))
    .unwrap();
    let default_noise = fitted.replace("bias_noise_w2_per_s = 1e-4\n", "");
    assert_ne!(default_noise, fitted);
    let trace = concat!(env!("CARGO_MANIFEST_DIR"), "/traces/drive-3node.csv");
    let worst = |text: &str, name: &str| {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let r = json_run(&[
            "faults",
            "--model",
            path.to_str().unwrap(),
            "--trace",
            trace,
            "--classes",
            "drift",
            "--json",
        ]);
        let hot_spot = cases(&r, "drift")
            .iter()
            .map(|c| c["max_error_hot_spot_k"].as_f64().unwrap())
            .fold(0.0, f64::max);
        let goal = r["summary"]["goals"]
            .as_array()
            .unwrap()
            .iter()
            .find(|g| {
                g["goal"]
                    .as_str()
                    .unwrap()
                    .contains("estimate error within")
            })
            .unwrap()["met"]
            .as_bool()
            .unwrap();
        (hot_spot, goal)
    };
    let (floor_k, floor_met) = worst(&default_noise, "floor.toml");
    let no_floor = default_noise.replace(
        "[observer]\n",
        "[observer]\nmax_cooling_bias_fraction = 1e9\n",
    );
    let (free_k, free_met) = worst(&no_floor, "free.toml");
    println!("drift on the hour: hot spot {floor_k:.2} K with the floor, {free_k:.2} K without");
    assert!(floor_k < 1.0 && floor_met, "{floor_k}");
    assert!(free_k > 2.0 && !free_met, "{free_k}");
}

/// Two scoring rules of the campaign at its default 100 ms step, all three
/// Omnimagnet solenoids at 7 A. A dropout whose onset falls between two
/// readings (the half-time onset, 252.1 s) withholds nothing until the
/// next reading is due: it is detectable from there (it was counted from
/// the onset, and the silence, two correction periods after the last
/// reading heard, came 1.1 s after it: the flag goal "not met" by one
/// tick). A restart is another trajectory than the clean closed loop
/// (which latches at about 709 s): a restarted run that does not latch
/// then is no lost shutdown (all five start classes were counted lost);
/// it is judged by the start goals.
#[test]
fn a_dropout_counts_from_its_first_withheld_reading_and_a_restart_loses_no_shutdown() {
    let r = json_run(&[
        "faults",
        "--model",
        "omnimagnet",
        "--current-a",
        "7",
        "--duration-s",
        "1800",
        "--classes",
        "dropout,reset-0s,reset-1h",
        "--json",
    ]);
    let dropouts = cases(&r, "dropout");
    assert_eq!(dropouts.len(), 12, "{r}");
    let between: Vec<_> = dropouts
        .iter()
        .filter(|c| c["onset_s"].as_f64().unwrap() > 100.0)
        .collect();
    assert!(!between.is_empty(), "{r}");
    for c in between {
        let detectable = c["detectable_s"].as_f64().unwrap();
        assert!(detectable > 0.05 && detectable < 0.5, "{c}");
        assert_eq!(c["flag_goal_met"], true, "{c}");
    }
    for class in ["reset-0s", "reset-1h"] {
        for c in cases(&r, class) {
            assert_eq!(c["lost_shutdown"], false, "{c}");
            assert!(c["reference_shutdown_s"].as_f64().is_some(), "{c}");
        }
    }
    for goal in r["summary"]["goals"].as_array().unwrap() {
        assert_eq!(goal["met"], true, "{goal}");
    }
}

/// A model whose observer estimates the ambient's offset
/// (`[observer] boundary_offset`, `drive-3node.toml` with one): the
/// campaign runs the firmware's observer with its offset state (its
/// padded observers once had no room for it and refused the file). At
/// 6 A the clean run shuts down no later than without the offset, and
/// within a fifth of its time; an open circuit is
/// flagged at once and a stuck sensor in time, none loses or delays the
/// shutdown or trips falsely, and no healthy reading is flagged.
#[test]
fn a_boundary_offset_runs_the_campaign() {
    let dir = tempfile::TempDir::new().unwrap();
    let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let text = std::fs::read_to_string(models.join("drive-3node.toml")).unwrap();
    let with_offset = text.replace(
        "[observer]\nsensors = [\"housing\"]",
        "[observer]\nsensors = [\"housing\"]\nboundary_offset = \"ambient\"",
    );
    assert!(with_offset.contains("boundary_offset"));
    let run = |text: &str, name: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        json_run(&[
            "faults",
            "--model",
            p.to_str().unwrap(),
            "--current-a",
            "6",
            "--duration-s",
            "600",
            "--onset-s",
            "60",
            "--classes",
            "open,stuck",
            "--json",
        ])
    };
    let r = run(&with_offset, "offset.toml");
    let plain = run(&text, "plain.toml");
    let clean_s = r["clean"]["shutdown_s"].as_f64().expect("6 A shuts down");
    let plain_s = plain["clean"]["shutdown_s"].as_f64().unwrap();
    eprintln!("clean shutdown with the offset {clean_s} s, without {plain_s} s");
    // The offset is never negative: it can only warm the estimate, and the
    // shutdown comes no later (measured 289.9 s against 317.1 s), nor
    // much earlier.
    assert!(
        clean_s <= plain_s && clean_s >= 0.8 * plain_s,
        "{clean_s} vs {plain_s}"
    );
    assert_eq!(r["clean"]["healthy_flagged"], 0);
    assert_eq!(r["cases"].as_array().unwrap().len(), 2);
    for c in r["cases"].as_array().unwrap() {
        assert_eq!(c["lost_shutdown"], false, "{c}");
        assert_eq!(c["late_shutdown"], false, "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
        assert_eq!(c["flag_goal_met"], true, "{c}");
    }
    for c in cases(&r, "open") {
        assert!(c["flag_s"].as_f64().unwrap() <= 1.0, "{c}");
    }
}
