//! What `replay` prints for a voltage-driven model is what the MCU
//! computes from it: `models/solenoid-valve-24v.toml` (a coil on a PWM
//! duty with a measured supply, a housing thermocouple) replayed over two
//! hours with its thermocouple fused, compared row by row with the module
//! `coil-thermal codegen` generated from the same file
//! (`tests/generated/solenoid_valve_24v.rs`) ticked directly at 1 ms with
//! `tick_voltage` and its `input_drive_limits`: the estimates, the upper
//! bounds, the derated alarm limits, the duty limit, the alarm flags and
//! events, and how often the library's drive rules fired (a dead supply
//! channel reading 0 V, a duty above 1).
//!
//! The trace asks for full duty on 20 V, then on 28 V (the coil would pass
//! its limit: the duty limit acts and the warning rises), then a low duty.
//! The housing column is the model's own simulation (`simulate` on a fine
//! step), so the thermocouple agrees with the model as a healthy one would.
//!
//! As `replay_is_the_firmware.rs`: the replay's observer is the library's
//! padded to a size class, whose padding adds exact zeros (and whose
//! padding nodes, without a limit or a winding, the predictor skips), so
//! values and the duty limit are compared to the bit, the events by
//! level, kind, node and tick.

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::TimedReading;
use coil_thermal::{DriveFlags, Reading};
use serde_json::Value;
use tempfile::TempDir;

mod common;

#[path = "generated/solenoid_valve_24v.rs"]
mod valve;

fn model_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/solenoid-valve-24v.toml")
}

/// The model file's fixed ambient \[degC\].
const AMBIENT_C: f32 = 25.0;

/// The duty and supply \[V\] asked at second `t`.
fn drive_at(t: usize) -> (f32, f32) {
    match t {
        // A dead supply channel for five seconds: read as 0 V.
        3000..=3004 => (1.0, 0.0),
        // A controller's overshoot: a duty above 1.
        4000..=4009 => (1.2, 28.0),
        0..=1799 => (1.0, 20.0),
        1800..=5399 => (1.0, 28.0),
        _ => (0.3, 24.0),
    }
}

const SECONDS: usize = 7200;

/// The trace (one row a second: duty, supply) and the housing
/// thermocouple's column from the model's fine simulation of it.
fn recording(dir: &Path) -> (PathBuf, Vec<[f32; 3]>) {
    let mut trace = String::from("time_s,duty,supply_v\n");
    for t in 0..=SECONDS {
        let (d, v) = drive_at(t);
        trace.push_str(&format!("{t},{d},{v}\n"));
    }
    let input = dir.join("in.csv");
    std::fs::write(&input, &trace).unwrap();
    let fine = dir.join("fine.toml");
    let text = std::fs::read_to_string(model_path()).unwrap();
    std::fs::write(&fine, format!("max_step_ratio = 0.0001\n{text}")).unwrap();
    let sim = dir.join("sim.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model"])
        .arg(&fine)
        .arg("--trace")
        .arg(&input)
        .arg("--out")
        .arg(&sim)
        .assert()
        .success();
    let sim_text = std::fs::read_to_string(&sim).unwrap();
    let header: Vec<&str> = sim_text.lines().next().unwrap().split(',').collect();
    let housing = header.iter().position(|h| *h == "housing").unwrap();
    let mut out = String::from("time_s,duty,supply_v,housing_tc\n");
    let mut rows = Vec::new();
    for (line, sim_line) in trace.lines().skip(1).zip(sim_text.lines().skip(1)) {
        let tc: f32 = sim_line.split(',').nth(housing).unwrap().parse().unwrap();
        out.push_str(&format!("{line},{tc}\n"));
        // As `replay` reads a cell: `f64`, rounded once to `f32`.
        let v: Vec<f32> = line
            .split(',')
            .skip(1)
            .map(|f| f.parse::<f64>().unwrap() as f32)
            .collect();
        rows.push([v[0], v[1], tc]);
    }
    let rec = dir.join("rec.csv");
    std::fs::write(&rec, out).unwrap();
    (rec, rows)
}

/// One row of the generated observer's outputs.
#[derive(Debug, Clone)]
struct Row {
    temps_c: [f32; 2],
    upper_c: [f32; 2],
    alarm_limit_c: [f32; 2],
    duty_limit: f32,
    flags: [bool; 3],
}

type Event = (f64, String, String, Option<usize>);

/// Ticks on which each drive rule fired: duty invalid, duty above 1,
/// supply invalid, resistance invalid.
type FlagTicks = [u64; 4];

/// The generated module over the recording at 1 ms, as `replay` hands it
/// over: each row's duty and supply held for its second, its reading given
/// to the second's first tick.
fn generated(rows: &[[f32; 3]]) -> (Vec<Row>, Vec<Event>, FlagTicks) {
    let observer = valve::observer().expect("the generated parts assemble");
    let mut state = valve::initial_state(&observer, AMBIENT_C);
    let row = |state: &valve::State, supply_v: f32| {
        let o = state.outputs();
        let limits = observer.alarm().alarm_limits_c(AMBIENT_C);
        Row {
            temps_c: o.temps_c,
            upper_c: o.upper_c,
            alarm_limit_c: limits,
            duty_limit: valve::input_drive_limits(&observer, state, &[supply_v])[0],
            flags: [o.alarm.warning, o.alarm.predictive, o.alarm.shutdown],
        }
    };
    let mut out = vec![row(&state, rows[0][1])];
    let (mut events, mut flag_ticks) = (Vec::new(), [0u64; 4]);
    // The MCU's clock wraps (a `u32` of microseconds: 71.6 minutes); the
    // events' times are counted apart.
    let (mut now_us, mut ticks) = (0u32, 0u64);
    for [duty, supply_v, housing_tc] in &rows[..rows.len() - 1] {
        let signal = [*supply_v];
        let drives = valve::source_drives(&[*duty], &signal);
        for k in 0..1000 {
            now_us = now_us.wrapping_add(1000);
            ticks += 1;
            let inputs = valve::Inputs {
                currents_a: valve::source_currents_a(&[*duty], &signal),
                boundary_c: [AMBIENT_C],
                readings: [(k == 0).then_some(TimedReading {
                    result: Ok(Reading::new(*housing_tc)),
                    sampled_at_us: now_us,
                })],
                now_us,
                elapsed_us: 1000,
            };
            let (_, flags) = observer.tick_voltage(&mut state, &inputs, &drives);
            for (n, f) in flag_ticks.iter_mut().zip([
                DriveFlags::DUTY_INVALID,
                DriveFlags::DUTY_CLAMPED,
                DriveFlags::SUPPLY_INVALID,
                DriveFlags::RESISTANCE_INVALID,
            ]) {
                *n += u64::from(flags.contains(f));
            }
            while let Some(e) = state.events.pop() {
                let (level, kind) = common::event_words(e.kind);
                events.push((
                    ticks as f64 * 1e-3,
                    level.to_string(),
                    kind.to_string(),
                    e.element,
                ));
            }
        }
        out.push(row(&state, *supply_v));
    }
    (out, events, flag_ticks)
}

#[test]
fn replay_of_a_voltage_driven_valve_is_the_generated_module() {
    let tmp = TempDir::new().unwrap();
    let (rec, rows) = recording(tmp.path());
    let out = tmp.path().join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(model_path())
        .arg("--trace")
        .arg(&rec)
        .args(["--measure", "housing_tc=housing", "--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(json["firmware_observer"]["overrides"], Value::Array(vec![]));
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        [
            "time_s",
            "coil",
            "housing",
            "upper_c.coil",
            "alarm_limit_c.coil",
            "upper_c.housing",
            "alarm_limit_c.housing",
            "limit_duty.duty",
            "warning",
            "predictive",
            "shutdown",
        ],
        "a duty input's limit is a duty"
    );
    let replayed: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let (firmware, firmware_events, flag_ticks) = generated(&rows);
    assert_eq!(replayed.len(), firmware.len());
    for (t, (r, g)) in replayed.iter().zip(&firmware).enumerate() {
        let expected = [
            g.temps_c[0],
            g.temps_c[1],
            g.upper_c[0],
            g.alarm_limit_c[0],
            g.upper_c[1],
            g.alarm_limit_c[1],
        ];
        for (k, e) in expected.iter().enumerate() {
            assert!(
                common::same_f32(r[k + 1], *e),
                "second {t}, {}: replay {}, generated {e}",
                header[k + 1],
                r[k + 1]
            );
        }
        if t == 0 {
            // Before the first tick: no supply seen, no duty limit.
            assert!(r[7].is_nan(), "{}", r[7]);
            continue;
        }
        assert!(
            common::same_f32(r[7], g.duty_limit),
            "second {t}: duty limit replay {}, generated {}",
            r[7],
            g.duty_limit
        );
        let flags = [r[8], r[9], r[10]].map(|v| v == 1.0);
        assert_eq!(flags, g.flags, "second {t}");
    }
    // The trace makes the protection act (else the comparison is idle):
    // the duty limit falls below full on 28 V, and the dead supply gives
    // a duty limit of 0 for its seconds.
    let lowest = firmware.iter().map(|g| g.duty_limit).fold(1.0f32, f32::min);
    assert_eq!(lowest, 0.0, "the dead supply's duty limit is 0");
    assert!(
        firmware[2000..3000].iter().any(|g| g.duty_limit < 0.95),
        "the limit must act on 28 V"
    );
    assert!(firmware_events.iter().any(|e| e.1 == "warning"));
    // The drive rules fired as on the MCU, and the replay says so.
    assert_eq!(flag_ticks[1], 10_000, "ten seconds above 1");
    assert_eq!(flag_ticks[2], 5_000, "five seconds of a dead supply");
    let ticks = &json["drive_flag_ticks"];
    assert_eq!(
        [
            &ticks["duty_invalid"],
            &ticks["duty_clamped"],
            &ticks["supply_invalid"],
            &ticks["resistance_invalid"],
        ]
        .map(|v| v.as_u64().unwrap()),
        flag_ticks,
        "{json}"
    );
    let replay_events = common::json_events(&json);
    assert_eq!(replay_events.len(), firmware_events.len(), "{json}");
    for (r, g) in replay_events.iter().zip(&firmware_events) {
        assert_eq!((&r.1, &r.2), (&g.1, &g.2), "{r:?} vs {g:?}");
        assert_eq!(r.3.as_deref(), g.3.map(|i| valve::NODE_NAMES[i]));
        // The same tick.
        assert!((r.0 - g.0).abs() < 1e-6, "{r:?} vs {g:?}");
    }
    let input = &json["protection"]["inputs"][0];
    assert_eq!(input["unit"], "duty", "{input}");
    assert!(input["lowest_limit_duty"].as_f64().is_some(), "{input}");
}
