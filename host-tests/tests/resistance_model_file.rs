//! A winding's resistance as the only sensor, from the model file to the
//! MCU (issue 38, items 3 and 5): `host-tests/models/drive-3node-resistance.toml`
//! (`drive-3node-fitted.toml` with no thermocouple, `[observer] sensors =
//! [{ source = "winding", kind = "resistance", ... }]`).
//!
//! * `codegen` writes `examples/generated/drive_3node_resistance.rs`: its
//!   tables solved with the resistance's own noise, its `SENSOR_KINDS`, and
//!   `observer()` by `from_parts_with_sensors`, the builder's observer to
//!   the bit.
//! * `replay` of the file on `host-tests/traces/drive-3node-resistance.csv`
//!   (the bench hour `drive-3node.csv` with a `winding_ohm` column) prints
//!   what that module computes, ticked on the host at 1 ms with its ohms
//!   through `resistance_reading` at the row's current.
//! * Over the hour the winding is held within 1 K of the bench's winding
//!   thermocouple, which neither sees (the goal).
//!
//! The trace's `winding_ohm` is synthesised as in `resistance_sensor.rs`:
//! every second `R = R_truth(winding_tc) (1 + 0.01 n)`, the truth file's
//! winding (1.25 ohm at 20 degC, 0.00393 /K), `n` a standard normal from
//! the seeded [`Rng`]: a drive's `V/I` to 1 %. The committed file is this
//! test's output (`COIL_THERMAL_REGENERATE=1` writes it).

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::network::NetworkObserver;
use coil_thermal_host::synth::Rng;
use serde_json::Value;
use tempfile::TempDir;

mod common;

#[path = "../../examples/generated/drive_3node_resistance.rs"]
mod model;

/// The seed of the synthesised resistance noise (`resistance_sensor.rs`'s).
const SEED: u64 = 38;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

const TRACE: &str = "host-tests/traces/drive-3node-resistance.csv";

/// `drive-3node.csv` with the synthesised `winding_ohm` column.
fn synthesised() -> String {
    let bench = std::fs::read_to_string(root().join("host-tests/traces/drive-3node.csv")).unwrap();
    let mut rng = Rng::new(SEED);
    let mut out = String::new();
    for (k, line) in bench.lines().enumerate() {
        if k == 0 {
            out.push_str(line);
            out.push_str(",winding_ohm\n");
            continue;
        }
        let winding_tc: f64 = line.split(',').nth(3).unwrap().parse().unwrap();
        let r_truth = 1.25 * (1.0 + 0.00393 * (winding_tc - 20.0));
        let ohm = r_truth * (1.0 + 0.01 * rng.normal());
        out.push_str(&format!("{line},{ohm:.6}\n"));
    }
    out
}

#[test]
fn the_committed_trace_is_this_tests_output() {
    let path = root().join(TRACE);
    let made = synthesised();
    if std::env::var_os("COIL_THERMAL_REGENERATE").is_some() {
        std::fs::write(&path, &made).unwrap();
    }
    assert!(
        std::fs::read_to_string(&path).unwrap() == made,
        "{TRACE} is not this test's output: COIL_THERMAL_REGENERATE=1 cargo test --release -p coil-thermal-host --test resistance_model_file"
    );
}

#[test]
fn codegen_reproduces_the_committed_module_and_it_is_the_builders() {
    let dir = TempDir::new().unwrap();
    let generated = dir.path().join("model.rs");
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(root().join("host-tests/models/drive-3node-resistance.toml"))
        .arg("--out")
        .arg(&generated)
        .assert()
        .success();
    assert!(
        std::fs::read_to_string(&generated).unwrap()
            == std::fs::read_to_string(root().join("examples/generated/drive_3node_resistance.rs"))
                .unwrap(),
        "codegen no longer reproduces examples/generated/drive_3node_resistance.rs"
    );
    // It names the run-time assembly that equals its static: the one
    // with the sensor kinds.
    assert!(std::fs::read_to_string(&generated)
        .unwrap()
        .contains("`Observer::from_parts_with_sensors(&PARTS, &SENSOR_KINDS)` is"));
    // The tables are the builder's with the resistance sensor, and they
    // are refused as a thermocouple's (another noise, another gain).
    let network = model::network().unwrap();
    let sensor = model::SENSOR_KINDS[0].resistance().copied().unwrap();
    assert_eq!((sensor.source, sensor.node), (0, 0));
    let built: model::Observer =
        coil_thermal::observer::network::NetworkObserverBuilder::new(&network, [0])
            .critical_c(model::PARTS.critical_c)
            .hardware_limit_a(model::PARTS.hardware_limit_a)
            .settings(model::PARTS.settings)
            .resistance_sensor(0, sensor)
            .build()
            .unwrap();
    let assembled = model::observer().unwrap();
    assert_eq!(built.fingerprint(), assembled.fingerprint());
    let at_run_time =
        NetworkObserver::from_parts_with_sensors(&model::PARTS, &model::SENSOR_KINDS).unwrap();
    assert_eq!(built.fingerprint(), at_run_time.fingerprint());
    assert!(NetworkObserver::from_parts(&model::PARTS).is_err());
}

/// One row of the generated observer's outputs: the nodes' estimates and
/// upper bounds \[degC\], the input's limit \[A\], the alarm flags.
#[derive(Debug, Clone, PartialEq)]
struct Row {
    temps_c: [f32; 3],
    upper_c: [f32; 3],
    limit_a: f32,
    flags: [bool; 3],
}

/// The generated module over the trace at 1 ms ticks, as `replay` hands
/// it over (each row's inputs held for its second; its resistance, read at
/// the row's current, given to the second's first tick): every row's
/// outputs, the events (time \[s\], level, kind, node) and the rows' bench
/// winding thermocouple \[degC\].
type Events = Vec<(f64, String, String, Option<usize>)>;
fn generated() -> (Vec<Row>, Events, Vec<f64>) {
    let text = std::fs::read_to_string(root().join(TRACE)).unwrap();
    // time_s, current, ambient, winding_tc, housing_tc, winding_ohm
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|f| f.parse().unwrap()).collect())
        .collect();
    let observer = model::observer().expect("the generated parts assemble");
    let mut state = model::initial_state(&observer, rows[0][2] as f32);
    let row = |state: &model::State| {
        let o = state.outputs();
        Row {
            temps_c: o.temps_c,
            upper_c: o.upper_c,
            limit_a: model::input_limits_a(&o.limits)[0],
            flags: [o.alarm.warning, o.alarm.predictive, o.alarm.shutdown],
        }
    };
    let mut out = vec![row(&state)];
    let mut events = Vec::new();
    let mut now_us: u32 = 0;
    for r in &rows[..rows.len() - 1] {
        let (current_a, ambient_c, ohm) = (r[1] as f32, r[2] as f32, r[5] as f32);
        let currents_a = model::source_currents_a(&[current_a], &[]);
        let reading = |now_us| [observer.resistance_reading(0, ohm, current_a, now_us)];
        common::tick_row(
            &observer,
            &mut state,
            currents_a,
            [ambient_c],
            reading,
            &mut now_us,
            &mut events,
        );
        out.push(row(&state));
    }
    (out, events, rows.iter().map(|r| r[3]).collect())
}

#[test]
fn replay_is_the_generated_module_and_holds_the_winding_within_1_k() {
    let tmp = TempDir::new().unwrap();
    let out = tmp.path().join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join("host-tests/models/drive-3node-resistance.toml"))
        .arg("--trace")
        .arg(root().join(TRACE))
        .args(["--measure", "winding_ohm=winding"])
        .args(["--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(json["firmware_observer"]["overrides"], Value::Array(vec![]));
    assert_eq!(
        json["firmware_observer"]["derating_product"].as_f64(),
        Some(model::PARTS.derating_product)
    );
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let replayed: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (rows, events, winding_tc) = generated();
    assert_eq!(replayed.len(), rows.len());
    for (t, (r, g)) in replayed.iter().zip(&rows).enumerate() {
        for (i, name) in model::NODE_NAMES.iter().enumerate() {
            for (column, value) in [
                (name.to_string(), g.temps_c[i]),
                (format!("upper_c.{name}"), g.upper_c[i]),
            ] {
                let Some(k) = header.iter().position(|h| *h == column) else {
                    continue;
                };
                assert!(
                    common::same_f32(r[k], value),
                    "row {t}, {column}: replay {}, generated {value}",
                    r[k]
                );
            }
        }
        let limit = r[col("limit_a.current")];
        assert!(
            common::same_f32(limit, g.limit_a),
            "row {t}: {limit} A against {} A",
            g.limit_a
        );
    }
    let replay_events = common::json_events(&json);
    assert_eq!(replay_events.len(), events.len(), "{json}");
    for (r, g) in replay_events.iter().zip(&events) {
        assert_eq!((&r.1, &r.2), (&g.1, &g.2), "{r:?} vs {g:?}");
        // The same tick.
        assert!((r.0 - g.0).abs() < 1e-6, "{r:?} vs {g:?}");
    }
    // The goal: the winding within 1 K of the bench's winding
    // thermocouple (read at the next row: both at the second's end),
    // after the first minute.
    let worst = rows[61..]
        .iter()
        .zip(&winding_tc[61..])
        .map(|(g, tc)| (f64::from(g.temps_c[0]) - tc).abs())
        .fold(0.0, f64::max);
    eprintln!("winding against the bench thermocouple: worst {worst:.3} K");
    assert!(worst < 1.0, "{worst}");
}

/// `replay` reads the ohms as the firmware does: a row below the sensor's
/// least current (0.5 A) is no reading, a resistance that cannot be the
/// winding's (negative, far too high) a fault; both counted in the
/// summary, neither fused.
#[test]
fn replay_counts_readings_below_the_least_current_and_faults() {
    let text = std::fs::read_to_string(root().join(TRACE)).unwrap();
    let mut edited = String::new();
    for (k, line) in text.lines().enumerate() {
        let mut f: Vec<String> = line.split(',').map(String::from).collect();
        match k {
            // Rows 100..110 at 0.2 A; rows 200..205 a sign error, rows
            // 300..303 an open lead's 100 ohm (far above 300 degC).
            101..=110 => f[1] = "0.2".into(),
            201..=205 => f[5] = "-1.25".into(),
            301..=303 => f[5] = "100".into(),
            _ => {}
        }
        edited.push_str(&f.join(","));
        edited.push('\n');
    }
    let tmp = TempDir::new().unwrap();
    let trace = tmp.path().join("edited.csv");
    std::fs::write(&trace, edited).unwrap();
    let out = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join("host-tests/models/drive-3node-resistance.toml"))
        .arg("--trace")
        .arg(&trace)
        .args(["--measure", "winding_ohm=winding"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    assert!(
        stdout.contains(
            "resistance [ohm] `winding_ohm` (resistance, the library's conversion): faults, not fused, never read as temperatures: OutOfRange 8; 10 below the least current (0.5 A): no reading"
        ),
        "{stdout}"
    );
}
