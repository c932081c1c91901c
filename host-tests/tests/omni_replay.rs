//! `replay --model omnimagnet` runs the observer the firmware flashes for
//! the Omnimagnet (`examples/generated/omnimagnet.rs`, what `codegen
//! --device omnimagnet` writes and `examples/observer_m4` runs), not a
//! network observer over its linearised network: every node's estimate,
//! every alarm node's upper bound and derated limit, each solenoid's
//! current limit and every alarm event equal the generated module ticked
//! directly at 1 ms over the same trace, to the bit.
//!
//! The trace is the paper's nonlinear Omnimagnet (the library's RK4, an
//! independent plant: its radiation and convection are not the observer's
//! linearisation at 22 degC) at 3.8 A in all three solenoids for an hour,
//! its six thermocouples reading their solenoids with a deterministic
//! scatter: the cover insulations reach their derated limits, so the
//! limiter and the alarm act.

use std::fmt::Write as _;
use std::path::Path;

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::omnimagnet::ALARM_NODES;
use coil_thermal::observer::{OmniInputs, TimedReading};
use coil_thermal::omnimagnet::{Omnimagnet, NODES, NODE_NAMES, THERMOCOUPLES, THERMOCOUPLE_NODES};
use coil_thermal::Reading;
use serde_json::Value;
use tempfile::TempDir;

mod common;

#[path = "../../examples/generated/omnimagnet.rs"]
mod omnimagnet;

const AMBIENT_C: f64 = 22.0;
const CURRENT_A: f64 = 3.8;
const ROWS: usize = 3601;
/// The thermocouples' columns (their slots' order).
const TC: [&str; THERMOCOUPLES] = ["tc1a", "tc1b", "tc2a", "tc2b", "tc3a", "tc3b"];

/// The trace, one row a second: time, currents, ambient, the six
/// readings (each row's as `f32`, what the replay and the module get),
/// and the truth of two wire insulations.
fn trace(path: &Path) -> Vec<[f32; THERMOCOUPLES]> {
    let model = Omnimagnet::PAPER;
    let mut temps = [AMBIENT_C; NODES];
    let mut text = String::from("time_s,I1_a,I2_a,I3_a,ambient");
    for c in TC {
        write!(text, ",{c}").unwrap();
    }
    text.push_str(",truth_w1,truth_w3\n");
    let mut readings = Vec::with_capacity(ROWS);
    for k in 0..ROWS {
        let z: [f32; THERMOCOUPLES] = core::array::from_fn(|j| {
            // A scatter of +-0.1 K, different per thermocouple.
            let scatter = 0.1 * ((k * 7 + j * 3) % 5) as f64 / 2.0 - 0.1;
            (temps[THERMOCOUPLE_NODES[j]] + scatter) as f32
        });
        write!(text, "{k},{CURRENT_A},{CURRENT_A},{CURRENT_A},{AMBIENT_C}").unwrap();
        for v in z {
            write!(text, ",{v}").unwrap();
        }
        writeln!(text, ",{},{}", temps[7], temps[11]).unwrap();
        readings.push(z);
        for _ in 0..4 {
            model.step_rk4(&mut temps, &[CURRENT_A; 3], AMBIENT_C, 0.25);
        }
    }
    std::fs::write(path, text).unwrap();
    readings
}

#[test]
fn replay_of_the_omnimagnet_is_the_flashed_omni_observer() {
    let tmp = TempDir::new().unwrap();
    let (trace_path, out) = (tmp.path().join("omni.csv"), tmp.path().join("out.csv"));
    let readings = trace(&trace_path);
    let measure: Vec<String> = TC
        .iter()
        .zip(THERMOCOUPLE_NODES)
        .map(|(c, n)| format!("{c}={}", NODE_NAMES[n]))
        .collect();
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", "omnimagnet", "--trace"])
        .arg(&trace_path)
        .args(["--measure", &measure.join(",")])
        .args([
            "--truth",
            "truth_w1=wire_insulation_1,truth_w3=wire_insulation_3",
        ])
        .args(["--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(json["estimator"], "omni-observer", "{json}");
    assert_eq!(json["firmware_observer"]["kind"], "omni-observer");
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let replayed: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(replayed.len(), ROWS);
    let col = |name: &str| {
        header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };

    let observer = &omnimagnet::OBSERVER;
    let ambient = AMBIENT_C as f32;
    let mut state = observer.state(&[ambient; NODES], ambient);
    let limits_c = observer.alarm().alarm_limits_c(ambient);
    let mut events = Vec::new();
    let mut now_us = 0u32;
    let close = common::same_f32;
    for (k, (z, r)) in readings.iter().zip(&replayed).enumerate() {
        let o = state.outputs();
        for (n, name) in NODE_NAMES.iter().enumerate() {
            assert!(
                close(r[col(name)], o.temps_c[n]),
                "row {k}, {name}: {} vs {}",
                r[col(name)],
                o.temps_c[n]
            );
        }
        for (e, &n) in ALARM_NODES.iter().enumerate() {
            let name = NODE_NAMES[n];
            let u = r[col(&format!("upper_c.{name}"))];
            assert!(
                close(u, o.upper_c[n]),
                "row {k}, upper bound of {name}: {u} vs {}",
                o.upper_c[n]
            );
            let l = r[col(&format!("alarm_limit_c.{name}"))];
            assert!(close(l, limits_c[e]), "row {k}, alarm limit of {name}");
        }
        for (m, limit) in o.limits.iter().enumerate() {
            let l = r[col(&format!("limit_a.current_{}", m + 1))];
            assert!(
                close(l, limit.current_a),
                "row {k}, limit of current_{}",
                m + 1
            );
        }
        let flags = [o.alarm.warning, o.alarm.predictive, o.alarm.shutdown];
        for (name, f) in ["warning", "predictive", "shutdown"].iter().zip(flags) {
            assert_eq!(r[col(name)], f64::from(u8::from(f)), "row {k}, {name}");
        }
        if k + 1 == ROWS {
            break;
        }
        for tick in 0..1000 {
            now_us = now_us.wrapping_add(1000);
            let inputs = OmniInputs {
                currents_a: [CURRENT_A as f32; 3],
                ambient_c: ambient,
                readings: core::array::from_fn(|j| {
                    (tick == 0).then_some(TimedReading {
                        result: Ok(Reading::new(z[j])),
                        sampled_at_us: now_us,
                    })
                }),
                now_us,
                elapsed_us: 1000,
            };
            observer.tick(&mut state, &inputs);
            while let Some(e) = state.events.pop() {
                let node = e.element.map(|i| NODE_NAMES[ALARM_NODES[i]]);
                events.push((f64::from(now_us) * 1e-6, node));
            }
        }
    }
    eprintln!("omnimagnet: {} events", events.len());
    // The run is one that exercises the protection.
    assert!(
        events.len() >= 3 && state.outputs().alarm.shutdown,
        "{events:?}"
    );
    let replayed_events = json["alarms"].as_array().unwrap();
    assert_eq!(json["alarms_total"], events.len(), "{json}");
    for (r, (t, node)) in replayed_events.iter().zip(&events) {
        assert!(
            (r["time_s"].as_f64().unwrap() - t).abs() < 1e-6,
            "{r} vs {t}"
        );
        assert_eq!(r["node"].as_str(), *node, "{r}");
    }
    // The derating printed is the one the flashed alarm limits above use.
    assert_eq!(
        json["alarm"]["derating_product"].as_f64().unwrap(),
        coil_thermal::protect::derating::DeratingRule::omnimagnet().product()
    );
    // The upper bound acted on is above the nonlinear plant's wire
    // insulations: no cold miss.
    for c in json["cold_misses"].as_array().unwrap() {
        assert_eq!(c["rows"], 0, "{c}");
    }
}

/// Flags that are not settings of the flashed Omnimagnet observer are
/// refused, naming the flag; a thermocouple where it has none too.
#[test]
fn replay_of_the_omnimagnet_refuses_what_it_does_not_flash() {
    let tmp = TempDir::new().unwrap();
    let trace_path = tmp.path().join("omni.csv");
    std::fs::write(
        &trace_path,
        "time_s,I1_a,I2_a,I3_a,ambient,tc\n0,1,1,1,22,22\n1,1,1,1,22,22.1\n",
    )
    .unwrap();
    for (args, says) in [
        (&["--factors", "1"][..], "--factors"),
        (&["--critical-c", "150"][..], "--critical-c"),
        (&["--tick-us", "500"][..], "--tick-us"),
        (
            &["--measure", "tc=core"][..],
            "two thermocouples on each of",
        ),
        (&["--measure", "tc=solenoid_1"][..], "with at most one"),
    ] {
        let a = cargo_bin_cmd!("coil-thermal")
            .args(["replay", "--model", "omnimagnet", "--trace"])
            .arg(&trace_path)
            .args(args)
            .assert()
            .failure();
        let err = String::from_utf8_lossy(&a.get_output().stderr).to_string();
        assert!(err.contains(says), "{args:?}: {err}");
    }
}
