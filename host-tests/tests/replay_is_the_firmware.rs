//! What `replay` prints for a model file is what the MCU computes from it:
//! the protection the generated module acts on (each limited node's upper
//! bound and derated alarm limit, the current limit of each input, the
//! alarm's events) and the derating product, compared row by row with the
//! module `coil-thermal codegen` generated from the same file
//! (`examples/generated/drive_3node.rs`, from `drive-3node-fitted.toml`),
//! ticked directly at 1 ms on the host over the bench recording with its
//! currents raised by 60 %, so that the winding crosses its limit and the
//! alarm and the limiter act.
//!
//! The replay's observer is the library's, its nodes and sources padded to
//! a size class (its sensors exactly the file's): the padding adds exact
//! zeros to every sum, so its tables and every tick are the generated
//! module's to the bit. `replay` hands the observer each cell as `f64`
//! (times `--current-scale`) rounded once to `f32`, as this test hands
//! them to the module, and writes each `f32` it computed as the shortest
//! decimal that reads back as that `f32`. Temperatures, upper bounds,
//! alarm limits and the input's limit are compared bit for bit, the
//! events by level, kind, node and tick. So are the HPPA grid's
//! (`hppa_grid.rs`) and the Cortex-M0 footprint example's
//! (`two_node_coil.rs`, generated with a sensor named on `codegen`'s
//! command line: `replay --measure` names the same one).

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::TimedReading;
use coil_thermal::Reading;
use serde_json::Value;
use tempfile::TempDir;

mod common;

#[path = "../../examples/generated/drive_3node.rs"]
mod model;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The factor on every current of the trace (`replay --current-scale`).
const CURRENT_SCALE: f64 = 1.6;

/// One row of the generated observer's outputs: the estimates and upper
/// bounds of the nodes \[degC\], the derated alarm limits of the limited
/// nodes \[degC\], the input's limit \[A\] and the alarm flags.
#[derive(Debug, Clone, PartialEq)]
struct Row {
    temps_c: [f32; 3],
    upper_c: [f32; 3],
    alarm_limit_c: [Option<f32>; 3],
    limit_a: f32,
    flags: [bool; 3],
}

/// An alarm event: its time \[s\], level, kind and node.
type Event = (f64, String, String, Option<usize>);

/// The generated observer over the bench trace at 1 ms ticks, as `replay`
/// hands it over (each row's inputs held for its second, its reading given
/// to the second's first tick): every row's outputs, and every event with
/// its time \[s\] as (level, kind, node).
fn generated() -> (Vec<Row>, Vec<Event>) {
    let text = std::fs::read_to_string(root().join("host-tests/traces/drive-3node.csv")).unwrap();
    let rows: Vec<[f32; 4]> = text
        .lines()
        .skip(1)
        .map(|l| {
            // As `replay` reads a cell: in `f64`, the current times the
            // scale in `f64`, each rounded once to `f32`.
            let v: Vec<f64> = l.split(',').skip(1).map(|f| f.parse().unwrap()).collect();
            [
                (v[0] * CURRENT_SCALE) as f32,
                v[1] as f32,
                v[2] as f32,
                v[3] as f32,
            ]
        })
        .collect();
    let observer = model::observer().expect("the generated parts assemble");
    let mut state = model::initial_state(&observer, rows[0][1]);
    let row = |state: &model::State, ambient_c: f32| {
        let o = state.outputs();
        Row {
            temps_c: o.temps_c,
            upper_c: o.upper_c,
            alarm_limit_c: core::array::from_fn(|i| observer.alarm().alarm_limit_c(i, ambient_c)),
            limit_a: model::input_limits_a(&o.limits)[0],
            flags: [o.alarm.warning, o.alarm.predictive, o.alarm.shutdown],
        }
    };
    let mut out = vec![row(&state, rows[0][1])];
    let mut events = Vec::new();
    let mut now_us: u32 = 0;
    for [current_a, ambient_c, _, housing_tc] in &rows[..rows.len() - 1] {
        let currents_a = model::source_currents_a(&[*current_a], &[]);
        let reading = |now_us| {
            [Some(TimedReading {
                result: Ok(Reading::new(*housing_tc)),
                sampled_at_us: now_us,
            })]
        };
        common::tick_row(
            &observer,
            &mut state,
            currents_a,
            [*ambient_c],
            reading,
            &mut now_us,
            &mut events,
        );
        out.push(row(&state, *ambient_c));
    }
    (out, events)
}

/// `replay` of the same trace and file, fusing the housing thermocouple,
/// with no flag that changes the firmware's observer: the estimate CSV's
/// header and rows, and the JSON summary.
fn replayed(dir: &Path) -> (Vec<String>, Vec<Vec<f64>>, Value) {
    let out = dir.join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join("host-tests/models/drive-3node-fitted.toml"))
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args(["--measure", "housing_tc=housing"])
        .args(["--current-scale", &CURRENT_SCALE.to_string()])
        .args(["--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows, json)
}

/// The columns compared, by their CSV header (index into a row), with
/// the generated row's value.
fn compared(header: &[String], g: &Row) -> Vec<(usize, f32)> {
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let mut v: Vec<(usize, f32)> = ["winding", "housing", "heatsink"]
        .iter()
        .zip(g.temps_c)
        .map(|(n, t)| (col(n), t))
        .collect();
    for (i, n) in ["winding", "housing"].iter().enumerate() {
        v.push((
            col(&format!("alarm_limit_c.{n}")),
            g.alarm_limit_c[i].unwrap(),
        ));
        v.push((col(&format!("upper_c.{n}")), g.upper_c[i]));
    }
    v
}

#[test]
fn replay_prints_the_generated_modules_protection() {
    let tmp = TempDir::new().unwrap();
    let (header, replay_rows, json) = replayed(tmp.path());
    let (firmware_rows, firmware_events) = generated();
    assert_eq!(
        header,
        [
            "time_s",
            "winding",
            "housing",
            "heatsink",
            "upper_c.winding",
            "alarm_limit_c.winding",
            "upper_c.housing",
            "alarm_limit_c.housing",
            "limit_a.current",
            "warning",
            "predictive",
            "shutdown",
        ]
    );
    // The derating the replay ran is the generated module's.
    assert_eq!(
        json["firmware_observer"]["derating_product"].as_f64(),
        Some(model::PARTS.derating_product),
        "{json}"
    );
    assert_eq!(json["firmware_observer"]["overrides"], Value::Array(vec![]));
    assert_eq!(replay_rows.len(), firmware_rows.len());
    for (t, (r, g)) in replay_rows.iter().zip(&firmware_rows).enumerate() {
        for (k, e) in compared(&header, g) {
            assert!(
                common::same_f32(r[k], e),
                "row {t}, {}: replay {}, generated {e}",
                header[k],
                r[k]
            );
        }
        assert!(
            common::same_f32(r[8], g.limit_a),
            "row {t}: limit replay {} A, generated {} A",
            r[8],
            g.limit_a
        );
    }
    // The raised currents make the protection act: a limit below the
    // hardware's 6 A, a warning and a shutdown, which the test compares.
    assert!(firmware_rows.iter().any(|g| g.limit_a < 5.0));
    let replay_events = common::json_events(&json);
    assert!(
        firmware_events.iter().any(|e| e.1 == "shutdown"),
        "{firmware_events:?}"
    );
    eprintln!("{} events", firmware_events.len());
    assert_eq!(replay_events.len(), firmware_events.len(), "{json}");
    for (r, g) in replay_events.iter().zip(&firmware_events) {
        assert_eq!((&r.1, &r.2), (&g.1, &g.2), "{r:?} vs {g:?}");
        assert_eq!(r.3.as_deref(), g.3.map(|i| model::NODE_NAMES[i]));
        // The same tick (times in s of whole ticks of 1 ms).
        assert!((r.0 - g.0).abs() < 1e-6, "{r:?} vs {g:?}");
    }
}

#[path = "../../examples/generated/hust_motor.rs"]
mod hust_motor;

#[path = "generated/all_input_terms.rs"]
mod all_input_terms;

#[path = "../../examples/generated/drive_3node_resistance.rs"]
mod drive_3node_resistance;

/// The settings `replay` resolves from a model file (`FirmwareConfig`) are
/// the ones `codegen` solved its generated module with, for every shipped
/// model file with a generated module: the library settings, the sensor
/// nodes, the critical temperatures, the derating product and the hardware
/// limit.
#[test]
fn replays_settings_are_the_generated_modules() {
    use coil_thermal_host::codegen::ObserverSpec;
    use coil_thermal_host::firmware::FirmwareConfig;
    use coil_thermal_host::model_file::{Model, ModelFile};

    fn check<const N: usize, const B: usize, const M: usize, const X: usize, const P: usize>(
        file: &str,
        parts: &coil_thermal::observer::network::NetworkParts<N, B, M, X, P>,
    ) -> FirmwareConfig {
        let path = root().join("host-tests").join(file);
        let model_file = ModelFile::load(&path).unwrap();
        let model = Model::build(&model_file).unwrap();
        let spec: Option<&ObserverSpec> = model_file.observer.as_ref();
        let config = FirmwareConfig::of(&model, spec).unwrap();
        assert!(config.from_table, "{file}");
        assert_eq!(config.settings, parts.settings, "{file}");
        assert_eq!(config.sensor_nodes, parts.sensor_nodes, "{file}");
        assert_eq!(config.critical_c, parts.critical_c, "{file}");
        assert_eq!(config.derating, parts.derating_product, "{file}");
        for h in parts.hardware_limit_a {
            assert_eq!(config.hardware_limit_a, h, "{file}");
        }
        config
    }
    fn kinds<const N: usize, const B: usize, const M: usize, const X: usize, const P: usize>(
        file: &str,
        parts: &coil_thermal::observer::network::NetworkParts<N, B, M, X, P>,
        kinds: &[coil_thermal::observer::network::SensorKind; P],
    ) {
        assert_eq!(check(file, parts).sensor_kinds, kinds, "{file}");
    }
    let thermocouple = |p| vec![coil_thermal::observer::network::SensorKind::Thermocouple; p];
    for (file, config) in [
        (
            "drive-3node-fitted",
            check("models/drive-3node-fitted.toml", &model::PARTS),
        ),
        (
            "hust_motor_slot_fitted",
            check("models/hust_motor_slot_fitted.toml", &hust_motor::PARTS),
        ),
        (
            "all-input-terms",
            check("models/all-input-terms.toml", &all_input_terms::PARTS),
        ),
    ] {
        assert_eq!(
            config.sensor_kinds,
            thermocouple(config.sensor_nodes.len()),
            "{file}"
        );
    }
    kinds(
        "models/drive-3node-resistance.toml",
        &drive_3node_resistance::PARTS,
        &drive_3node_resistance::SENSOR_KINDS,
    );
}

#[path = "../../examples/generated/hppa_grid.rs"]
mod hppa_grid;

/// `replay --model hppa` (README's main job) runs the grid observer the
/// firmware flashes (`examples/generated/hppa_grid.rs`, `observer_m4`),
/// not a network observer over the grid: every coil's estimate, upper
/// bound, alarm limit and current limit, and every event, are the
/// generated module's to the bit, ticked directly at 1 ms over the validation trace.
#[test]
fn replay_of_hppa_is_the_flashed_grid_observer() {
    use coil_thermal::observer::grid::GridInputs;
    const ROWS: usize = 7;
    const COLS: usize = 12;
    let trace = root().join("host-tests/traces/validation.csv");
    let tmp = TempDir::new().unwrap();
    let out = tmp.path().join("grid.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", "hppa", "--trace"])
        .arg(&trace)
        .args(["--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(json["estimator"], "grid-observer", "{json}");
    assert_eq!(json["firmware_observer"]["kind"], "grid-observer");
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let replayed: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let col = |name: String| header.iter().position(|h| *h == name).unwrap();
    // The trace: time, then every coil's current row by row.
    let rows: Vec<Vec<f32>> = std::fs::read_to_string(&trace)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .map(|l| {
            l.split(',')
                .skip(1)
                .map(|v| v.parse::<f64>().unwrap() as f32)
                .collect()
        })
        .collect();
    assert_eq!(rows.len(), replayed.len());
    let observer = &hppa_grid::OBSERVER;
    let mut state = observer.state(20.0);
    let mut currents = [[0.0f32; COLS]; ROWS];
    let mut events = Vec::new();
    let mut now_ms = 0u32;
    for (k, (row, r)) in rows.iter().zip(&replayed).enumerate() {
        let o = state.outputs();
        let ambient_c = state.alarm.ambient_c();
        for i in 0..ROWS * COLS {
            let name = format!("coil_r{}_c{}", i / COLS, i % COLS);
            let (t, u) = (o.temps_c[i / COLS][i % COLS], o.upper_c[i / COLS][i % COLS]);
            let limit_c = observer.alarm().alarm_limit_c(i, ambient_c).unwrap();
            for (column, e) in [
                (name.clone(), t),
                (format!("upper_c.{name}"), u),
                (format!("alarm_limit_c.{name}"), limit_c),
            ] {
                let v = r[col(column.clone())];
                assert!(common::same_f32(v, e), "row {k}, {column}: {v} vs {e}");
            }
            let l = r[col(format!("limit_a.{name}"))];
            assert!(
                common::same_f32(l, o.limits[i].current_a),
                "row {k}, {name}"
            );
        }
        if k + 1 == rows.len() {
            break;
        }
        for (i, a) in row.iter().enumerate() {
            currents[i / COLS][i % COLS] = *a;
        }
        for _ in 0..100 {
            let inputs = GridInputs {
                currents_a: &currents,
                coolant_c: 20.0,
                ambient_c: 20.0,
                elapsed_us: 1000,
            };
            observer.tick(&mut state, &inputs);
            now_ms += 1;
            while let Some(e) = state.events.pop() {
                events.push((f64::from(now_ms) * 1e-3, e.element));
            }
        }
    }
    eprintln!("grid: {} events", events.len());
    let replayed_events = json["alarms"].as_array().unwrap();
    assert_eq!(json["alarms_total"], events.len(), "{}", events.len());
    for (r, (t, element)) in replayed_events.iter().zip(&events) {
        assert!(
            (r["time_s"].as_f64().unwrap() - t).abs() < 1e-6,
            "{r} vs {t}"
        );
        assert_eq!(
            r["node"].as_str().map(String::from),
            element.map(|i| format!("coil_r{}_c{}", i / COLS, i % COLS))
        );
    }
}

#[path = "../../examples/generated/two_node_coil.rs"]
mod two_node_coil;

/// The two-node coil's trace: an hour at 1 s of current steps that take
/// the coil past its derated limit, and a housing thermocouple read from
/// an independent integration of the coil with 10 % more resistance than
/// the model (so the filter's heat bias has something to find): the
/// columns `time_s,current,housing_tc`.
fn two_node_trace() -> String {
    let mut csv = String::from("time_s,current,housing_tc\n");
    let (mut coil_c, mut housing_c) = (20.0f64, 20.0f64);
    for t in 0..3600 {
        let current_a = match t {
            0..600 => 4.0,
            600..1200 => 1.5,
            1200..2700 => 4.5,
            _ => 0.5,
        };
        csv.push_str(&format!("{t},{current_a},{housing_c:.3}\n"));
        // Explicit Euler at 10 ms: the coil (200 J/K, 5.69 ohm x 1.1 at
        // 20 degC, 0.0039/K) on the housing (900 J/K, 1.5 W/K) in air
        // (0.5 W/K to 20 degC).
        for _ in 0..100 {
            let r = 1.1 * 5.69 * (1.0 + 0.0039 * (coil_c - 20.0));
            let to_housing = 1.5 * (coil_c - housing_c);
            coil_c += 0.01 * (r * current_a * current_a - to_housing) / 200.0;
            housing_c += 0.01 * (to_housing - 0.5 * (housing_c - 20.0)) / 900.0;
        }
    }
    csv
}

/// The footprint example's module (`examples/generated/two_node_coil.rs`:
/// `codegen --model two-node-coil.toml --sensor housing`, a file with no
/// `[observer]` table, so every setting is the defaults) is what `replay`
/// of the same file with the same sensor runs, to the bit: temperatures,
/// upper bounds, the derated alarm limit, the input's limit and the events,
/// over an hour in which the coil passes its limit.
#[test]
fn replay_with_the_codegen_sensor_is_the_footprint_module() {
    let tmp = TempDir::new().unwrap();
    let trace = tmp.path().join("coil.csv");
    std::fs::write(&trace, two_node_trace()).unwrap();
    let out = tmp.path().join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join("host-tests/models/two-node-coil.toml"))
        .arg("--trace")
        .arg(&trace)
        .args(["--measure", "housing_tc=housing", "--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(
        json["firmware_observer"]["derating_product"].as_f64(),
        Some(two_node_coil::PARTS.derating_product),
        "{json}"
    );
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };
    let replayed: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();

    // The module, ticked as `replay` ticks its observer.
    let trace_text = two_node_trace();
    let rows: Vec<[f32; 2]> = trace_text
        .lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').skip(1).map(|f| f.parse().unwrap()).collect();
            [v[0] as f32, v[1] as f32]
        })
        .collect();
    let observer = two_node_coil::observer().expect("the generated parts assemble");
    let ambient_c = 20.0_f32;
    let mut state = two_node_coil::initial_state(&observer, ambient_c);
    let mut events = Vec::new();
    let mut now_us: u32 = 0;
    let mut lowest_limit_a = f32::INFINITY;
    for (t, r) in replayed.iter().enumerate() {
        let o = state.outputs();
        let limit_a = two_node_coil::input_limits_a(&o.limits)[0];
        lowest_limit_a = lowest_limit_a.min(limit_a);
        let alarm_limit_c = observer.alarm().alarm_limit_c(0, ambient_c).unwrap();
        for (name, value) in [
            ("coil", o.temps_c[0]),
            ("housing", o.temps_c[1]),
            ("upper_c.coil", o.upper_c[0]),
            ("alarm_limit_c.coil", alarm_limit_c),
            ("limit_a.current", limit_a),
        ] {
            assert!(
                common::same_f32(r[col(name)], value),
                "row {t}, {name}: replay {}, generated {value}",
                r[col(name)]
            );
        }
        let Some([current_a, housing_tc]) = rows.get(t).copied() else {
            break;
        };
        if t + 1 == replayed.len() {
            break;
        }
        common::tick_row(
            &observer,
            &mut state,
            two_node_coil::source_currents_a(&[current_a], &[]),
            [ambient_c],
            |now_us| {
                [Some(TimedReading {
                    result: Ok(Reading::new(housing_tc)),
                    sampled_at_us: now_us,
                })]
            },
            &mut now_us,
            &mut events,
        );
    }
    assert_eq!(replayed.len(), rows.len());
    // The protection acted: the limiter cut the current and the alarm
    // raised events, on the same ticks as the module's.
    assert!(lowest_limit_a < 3.0, "lowest limit {lowest_limit_a} A");
    assert!(events.iter().any(|e| e.1 == "shutdown"), "{events:?}");
    eprintln!(
        "{} rows to the bit; {} events, lowest limit {lowest_limit_a} A",
        replayed.len(),
        events.len()
    );
    let replay_events = common::json_events(&json);
    assert_eq!(replay_events.len(), events.len(), "{json}");
    for (r, g) in replay_events.iter().zip(&events) {
        assert_eq!((&r.1, &r.2), (&g.1, &g.2), "{r:?} vs {g:?}");
        assert_eq!(r.3.as_deref(), g.3.map(|i| two_node_coil::NODE_NAMES[i]));
        assert!((r.0 - g.0).abs() < 1e-6, "{r:?} vs {g:?}");
    }
}
