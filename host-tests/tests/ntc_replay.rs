//! `replay --raw-counts` (issue 38, item 5): a model file whose
//! `[observer] sensors` names an NTC on the ADC
//! (`host-tests/models/drive-3node-ntc.toml`) replays a recording of the
//! NTC's raw ADC counts exactly as the same observer fed the converted
//! temperatures; an open NTC in the recording (the top code) is a fault,
//! reported, never fused as a temperature, and handed to the observer as
//! the fault it is: the replay is the generated module fed
//! `convert_counts`, row for row and to the bit.
//!
//! The counts are made here from the bench recording's housing thermocouple
//! (`host-tests/traces/drive-3node.csv`) by the NTC's beta equation and the
//! divider, in `f64`, independently of the library's inverse.

use std::fs;
use std::path::PathBuf;

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::sensors::resistive::{Divider, ResistiveInput, Sensor, Topology};
use tempfile::TempDir;

mod common;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The model file's NTC: 10 kohm B3950 to ground, 10 kohm pull-up, 12 bits.
fn counts_at(temp_c: f64) -> u32 {
    let r = 10_000.0 * (3950.0 * (1.0 / (temp_c + 273.15) - 1.0 / 298.15)).exp();
    ((4096.0 * r / (r + 10_000.0)).round() as u32).min(4095)
}

/// Rows whose NTC wire is open: the node at the reference, the top code.
const OPEN_ROWS: std::ops::Range<usize> = 1200..1300;

fn replay(dir: &TempDir, trace: &str, measure: &str, raw: bool) -> (String, String) {
    let out = dir.path().join(format!("{measure}.csv"));
    let mut cmd = cargo_bin_cmd!("coil-thermal");
    cmd.arg("replay")
        .arg("--model")
        .arg(root().join("models/drive-3node-ntc.toml"))
        .arg("--trace")
        .arg(dir.path().join(trace))
        .args(["--measure", &format!("{measure}=housing")])
        .arg("--out")
        .arg(&out);
    if raw {
        cmd.arg("--raw-counts");
    }
    let output = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(
        output.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    (stdout, fs::read_to_string(out).unwrap())
}

#[test]
fn raw_counts_replay_as_the_converted_readings_and_an_open_ntc_is_a_fault() {
    let bench = fs::read_to_string(root().join("traces/drive-3node.csv")).unwrap();
    let input = ResistiveInput::new(
        Divider::new(Topology::SensorToGround, 10_000.0, 12).unwrap(),
        Sensor::ntc_beta(10_000.0, 25.0, 3950.0).unwrap(),
    );
    let dir = TempDir::new().unwrap();
    let (mut raw, mut converted) = (
        String::from("time_s,current,ambient,counts\n"),
        String::from("time_s,current,ambient,temp\n"),
    );
    let mut faults = 0;
    for (k, line) in bench.lines().skip(1).enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        let housing_c: f64 = f[4].parse().unwrap();
        let counts = if OPEN_ROWS.contains(&k) {
            4095
        } else {
            counts_at(housing_c)
        };
        raw.push_str(&format!("{},{},{},{counts}\n", f[0], f[1], f[2]));
        // The converted reading as the firmware's `convert_counts` gives
        // it; a fault is no reading (an empty cell).
        let cell = match input.convert(counts) {
            Ok(r) => format!("{:?}", f64::from(r.temp_c)),
            Err(_) => {
                faults += 1;
                String::new()
            }
        };
        converted.push_str(&format!("{},{},{},{cell}\n", f[0], f[1], f[2]));
    }
    assert_eq!(faults, OPEN_ROWS.len());
    fs::write(dir.path().join("raw.csv"), raw).unwrap();
    fs::write(dir.path().join("converted.csv"), converted).unwrap();

    let (raw_stdout, raw_out) = replay(&dir, "raw.csv", "counts", true);
    let (converted_stdout, converted_out) = replay(&dir, "converted.csv", "temp", false);
    // Without `--raw-counts` the ADC sensor's column is read as degC, and
    // the replay says so (counts would not pass unnoticed).
    assert!(
        converted_stdout.contains(
            "note: --measure temp: the model file's sensor is on an ADC (ntc); its column is read as degC"
        ),
        "{converted_stdout}"
    );
    assert!(!raw_stdout.contains("note: --measure"), "{raw_stdout}");
    assert!(
        raw_stdout.contains(&format!(
            "raw counts `counts` (ntc, the library's conversion): faults, not fused, never read as temperatures: OpenCircuit {}",
            OPEN_ROWS.len()
        )),
        "{raw_stdout}"
    );
    // Row for row the same estimates, bounds and limits up to the open
    // wire (the files differ only in the measured column's name); from
    // there the raw replay hands the observer the fault itself, as the
    // MCU does, where a converted recording can only leave the cell empty.
    let raw_rows: Vec<String> = raw_out
        .replace("counts", "temp")
        .lines()
        .map(String::from)
        .collect();
    let converted_rows: Vec<&str> = converted_out.lines().collect();
    assert!(raw_rows.len() > 3000);
    assert_eq!(raw_rows.len(), converted_rows.len());
    for k in 0..=OPEN_ROWS.start + 1 {
        assert_eq!(raw_rows[k], converted_rows[k], "line {k}");
    }
    // The generated module ticked with `convert_counts` on each row's
    // counts, at 1 ms as `replay` ticks it: the raw replay's every row.
    let firmware = generated(&raw_trace_counts(&bench));
    assert_eq!(firmware.len(), raw_rows.len() - 1);
    for (k, (line, (temps_c, upper_c))) in raw_rows.iter().skip(1).zip(&firmware).enumerate() {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        // time, winding, housing, heatsink, upper_c.winding,
        // alarm_limit_c.winding, upper_c.housing, ...
        for (r, e) in [
            (v[1], temps_c[0]),
            (v[2], temps_c[1]),
            (v[3], temps_c[2]),
            (v[4], upper_c[0]),
            (v[6], upper_c[1]),
        ] {
            assert!(common::same_f32(r, e), "row {k}: replay {r}, generated {e}");
        }
    }

    // Read as temperatures, the same counts would be ~2000 degC: the
    // conversion is what the replay used (its winding estimate stays a
    // winding's).
    let last = raw_out.lines().last().unwrap();
    let winding: f64 = last.split(',').nth(1).unwrap().parse().unwrap();
    assert!((20.0..200.0).contains(&winding), "{last}");
}

#[path = "../../examples/generated/drive_3node_ntc.rs"]
#[allow(unused)]
mod model;

/// Each row's (current \[A\], ambient \[degC\], ADC counts) of the raw
/// recording the test writes.
fn raw_trace_counts(bench: &str) -> Vec<(f32, f32, u32)> {
    bench
        .lines()
        .skip(1)
        .enumerate()
        .map(|(k, line)| {
            let f: Vec<&str> = line.split(',').collect();
            let counts = if OPEN_ROWS.contains(&k) {
                4095
            } else {
                counts_at(f[4].parse().unwrap())
            };
            // As `replay` reads a cell: `f64`, rounded once to `f32`.
            let cell = |i: usize| f[i].parse::<f64>().unwrap() as f32;
            (cell(1), cell(2), counts)
        })
        .collect()
}

/// The generated module over `rows` at 1 ms ticks, as `replay` hands them
/// over (each row held for its second, its reading, `convert_counts` of
/// its counts, given to the second's first tick): per row, the nodes'
/// estimates and the winding's and the housing's upper bounds \[degC\].
fn generated(rows: &[(f32, f32, u32)]) -> Vec<([f32; 3], [f32; 2])> {
    use coil_thermal::observer::TimedReading;
    let observer = model::observer().unwrap();
    let mut state = model::initial_state(&observer, rows[0].1);
    let row = |state: &model::State| {
        let o = state.outputs();
        (o.temps_c, [o.upper_c[0], o.upper_c[1]])
    };
    let mut out = vec![row(&state)];
    let mut now_us: u32 = 0;
    for (current_a, ambient_c, counts) in &rows[..rows.len() - 1] {
        let currents_a = model::source_currents_a(&[*current_a], &[]);
        let reading = |now_us| {
            [
                model::convert_counts(0, *counts).map(|result| TimedReading {
                    result,
                    sampled_at_us: now_us,
                }),
            ]
        };
        common::tick_row(
            &observer,
            &mut state,
            currents_a,
            [*ambient_c],
            reading,
            &mut now_us,
            &mut Vec::new(),
        );
        out.push(row(&state));
    }
    out
}

#[test]
fn raw_counts_without_an_adc_sensor_is_refused() {
    let out = cargo_bin_cmd!("coil-thermal")
        .arg("replay")
        .arg("--model")
        .arg(root().join("models/drive-3node-fitted.toml"))
        .arg("--trace")
        .arg(root().join("traces/drive-3node.csv"))
        .args(["--measure", "housing_tc=housing", "--raw-counts"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("--raw-counts"), "{stderr}");
}
