//! A voltage-driven coil in a model file (issue 38, item 4):
//! `models/solenoid-valve-24v.toml`, a 24 V valve on a PWM duty with a
//! measured supply. The simulator against an RK4 written here (never the
//! library's right-hand side), the model file's refusals, and a trace
//! simulated and replayed through the command line.

use std::fs;
use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sim::{FilePlant, Plant};
use tempfile::TempDir;

fn valve_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/solenoid-valve-24v.toml")
}

fn valve_text() -> String {
    fs::read_to_string(valve_path()).unwrap()
}

fn build(text: &str) -> anyhow::Result<Model> {
    Model::build(&ModelFile::parse(text, "valve.toml")?)
}

/// The valve's numbers, copied from the file.
const C_COIL: f64 = 45.0;
const C_HOUSING: f64 = 150.0;
const G_COIL_HOUSING: f64 = 0.25;
const G_HOUSING_AIR: f64 = 10.0 * 0.015;
const AMBIENT_C: f64 = 25.0;

fn r_ohm(t_c: f64) -> f64 {
    58.0 * (1.0 + 0.00393 * (t_c - 20.0))
}

/// `(dT_coil/dt, dT_housing/dt)` \[K/s\] at duty `d` on `v` volts.
fn rates(t: [f64; 2], d: f64, v: f64) -> [f64; 2] {
    let q = G_COIL_HOUSING * (t[0] - t[1]);
    [
        (d * v * v / r_ohm(t[0]) - q) / C_COIL,
        (q - G_HOUSING_AIR * (t[1] - AMBIENT_C)) / C_HOUSING,
    ]
}

fn rk4(t: [f64; 2], h: f64, d: f64, v: f64) -> [f64; 2] {
    let add = |a: [f64; 2], k: [f64; 2], s: f64| [a[0] + s * k[0], a[1] + s * k[1]];
    let k1 = rates(t, d, v);
    let k2 = rates(add(t, k1, h / 2.0), d, v);
    let k3 = rates(add(t, k2, h / 2.0), d, v);
    let k4 = rates(add(t, k3, h), d, v);
    [0, 1].map(|n| t[n] + h / 6.0 * (k1[n] + 2.0 * k2[n] + 2.0 * k3[n] + k4[n]))
}

/// Duty 0.9 on 24 V, then 0.5 on 28 V, two hours each, sampled at 1 s.
#[test]
fn the_valve_simulates_as_an_independent_rk4_of_d_v2_over_r() {
    let model = build(&valve_text()).unwrap();
    assert!(model.has_voltage_drives());
    assert_eq!(model.signals, ["supply_v"]);
    let mut plant = FilePlant::new(model).unwrap();
    plant.reset(&[AMBIENT_C; 2]);
    let mut truth = [AMBIENT_C; 2];
    let mut worst = 0.0f64;
    for (d, v) in [(0.9, 24.0), (0.5, 28.0)] {
        for _ in 0..7200 {
            plant.step(1.0, &[d], &[AMBIENT_C], &[v]);
            for _ in 0..10 {
                truth = rk4(truth, 0.1, d, v);
            }
            let t = plant.temps_c();
            worst = worst
                .max((t[0] - truth[0]).abs())
                .max((t[1] - truth[1]).abs());
        }
        let t = plant.temps_c();
        println!(
            "D = {d}, V = {v}: coil {:.4} degC (RK4 {:.4}), housing {:.4} degC (RK4 {:.4})",
            t[0], truth[0], t[1], truth[1]
        );
        // Two hours is 10 of the slowest time constants: both settled,
        // and an explicit step's fixed point is the exact steady state.
        assert!((t[0] - truth[0]).abs() < 0.01 && (t[1] - truth[1]).abs() < 0.01);
    }
    println!("worst simulator - RK4 over 4 h: {worst:.4} K");
    // The explicit 1 s step's transient error, far below a sensor's.
    assert!(worst < 0.3, "{worst} K");
}

#[test]
fn a_voltage_drive_without_its_supply_or_with_a_falling_resistance_is_refused() {
    let text = valve_text();
    let err = |edits: &[(&str, &str)]| {
        let mut t = text.clone();
        for (from, to) in edits {
            assert!(t.contains(from), "{from}");
            t = t.replace(from, to);
        }
        format!("{:#}", build(&t).unwrap_err())
    };
    let e = err(&[("supply_column = \"supply_v\"\n", "")]);
    assert!(e.contains("drive = \"pwm\" needs its supply"), "{e}");
    let e = err(&[("supply_column = \"supply_v\"", "supply_v = 0.0")]);
    assert!(e.contains("supply_v must be finite and > 0 V"), "{e}");
    let e = err(&[("drive = \"pwm\"", "drive = \"voltage\"")]);
    assert!(e.contains("belong to drive = \"pwm\""), "{e}");
    // No `1/R(T)` by a falling line: refused, pointing at the drive.
    let e = err(&[("alpha_per_k = 0.00393", "alpha_per_k = -0.002")]);
    assert!(e.contains("makes the resistance fall"), "{e}");
    let e = err(&[("r0_ohm = 58.0", "r0_ohm = 0.0")]);
    assert!(e.contains("> 0 ohm"), "{e}");
    // The library refuses the same lines by itself.
    let falling = coil_thermal::Resistance::linear_fit(-0.002, 58.0);
    let net = coil_thermal::Network::<1, 1, 1>::new([45.0]).unwrap();
    assert_eq!(
        net.clone().voltage_source(0, 0, falling).err(),
        Some(coil_thermal::BuildError::FallingResistance { input: 0 })
    );
    assert_eq!(
        net.joule_source(0, 0, coil_thermal::Resistance::constant(0.0))
            .err(),
        Some(coil_thermal::BuildError::InvalidResistance { input: 0 })
    );
}

/// A trace of the valve (duty steps on a supply that sags and recovers)
/// simulated finely, then replayed through the library observer in open
/// loop: the coil's estimate follows the simulated truth.
#[test]
fn a_valve_trace_simulates_and_replays() {
    let dir = TempDir::new().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    // One row a second: the simulation's rows are the trace's.
    let steps = [
        (1.0, 24.0),
        (0.6, 22.0),
        (0.3, 27.0),
        (0.8, 24.5),
        (0.0, 24.0),
    ];
    let mut trace = String::from("time_s,duty,supply_v\n");
    for t in 0..=6000usize {
        let (duty, supply) = steps[(t / 1200).min(4)];
        trace.push_str(&format!("{t},{duty},{supply}\n"));
    }
    let input = dir.path().join("in.csv");
    fs::write(&input, trace).unwrap();
    // The reference: the valve stepped explicitly at about 10 ms.
    let fine = dir.path().join("fine.toml");
    fs::write(&fine, format!("max_step_ratio = 0.0001\n{}", valve_text())).unwrap();
    let sim = dir.path().join("sim.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model", &s(&fine), "--trace", &s(&input)])
        .args(["--out", &s(&sim)])
        .assert()
        .success();
    let sim_text = fs::read_to_string(&sim).unwrap();
    let header: Vec<&str> = sim_text.lines().next().unwrap().split(',').collect();
    let coil = header.iter().position(|h| *h == "coil").unwrap();
    let peak = sim_text
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(coil)?.parse::<f64>().ok())
        .fold(f64::NEG_INFINITY, f64::max);
    println!("simulated coil peak {peak:.2} degC");
    assert!(peak > 60.0, "the valve must heat: {peak}");
    // The recording: the simulated coil as a truth column.
    let rec = dir.path().join("rec.csv");
    let mut text = String::new();
    let inputs = fs::read_to_string(&input).unwrap();
    for (k, (line, sim_line)) in inputs.lines().zip(sim_text.lines()).enumerate() {
        let cells: Vec<&str> = sim_line.split(',').collect();
        let coil_cell = if k == 0 { "T_coil" } else { cells[coil] };
        text.push_str(&format!("{line},{coil_cell}\n"));
    }
    fs::write(&rec, text).unwrap();
    let out = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model", &s(&valve_path()), "--trace", &s(&rec)])
        .args(["--truth", "T_coil=coil", "--json"])
        .assert()
        .success();
    let j: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    let truth = &j["truth"][0];
    println!("replay against the simulated coil: {truth}");
    assert!(truth["max_abs_error_k"].as_f64().unwrap() < 0.05, "{truth}");
}

/// The fault campaign runs the valve (on a constant supply: the campaign
/// has no signal columns, and says so for a measured one): the observer
/// ticks with `tick_voltage`, the limits it applies are duties.
#[test]
fn the_fault_campaign_runs_a_duty_driven_valve() {
    let dir = TempDir::new().unwrap();
    let measured = valve_path();
    cargo_bin_cmd!("coil-thermal")
        .args([
            "faults",
            "--model",
            measured.to_str().unwrap(),
            "--current-a",
            "1",
        ])
        .args(["--duration-s", "60"])
        .assert()
        .failure()
        .stderr(predicates::str::contains("give it a constant supply_v"));
    let constant = dir.path().join("valve-24v-constant.toml");
    fs::write(
        &constant,
        valve_text().replace("supply_column = \"supply_v\"", "supply_v = 24.0"),
    )
    .unwrap();
    let out = cargo_bin_cmd!("coil-thermal")
        .args(["faults", "--model", constant.to_str().unwrap()])
        // Full duty, which would take the coil past its limit.
        .args([
            "--current-a",
            "1",
            "--duration-s",
            "1800",
            "--onset-s",
            "300",
        ])
        .args(["--classes", "open,stuck,spikes", "--json"])
        .assert()
        .success();
    let r: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    println!("clean: {}", r["clean"]);
    assert_eq!(r["model"], "solenoid-valve-24v");
    assert_eq!(r["clean"]["healthy_flagged"], 0, "{}", r["clean"]);
    for c in r["cases"].as_array().unwrap() {
        println!(
            "{}: flag {} lost {} late {} false {}",
            c["class"], c["flag_s"], c["lost_shutdown"], c["late_shutdown"], c["false_trip"]
        );
        assert_eq!(c["lost_shutdown"], false, "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
    }
}

/// `codegen` of the valve writes `source_drives` (the duty on the measured
/// supply) and `input_drive_limits` (the limit as a duty), and leaves a
/// current-driven model's module as it was (the round-trip tests).
#[test]
fn codegen_writes_the_valves_drives() {
    let out = cargo_bin_cmd!("coil-thermal")
        .args([
            "codegen",
            "--model",
            valve_path().to_str().unwrap(),
            "--out",
            "-",
        ])
        .assert()
        .success();
    let text = String::from_utf8_lossy(&out.get_output().stdout).into_owned();
    let committed = fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/generated/solenoid_valve_24v.rs"),
    )
    .unwrap();
    assert_eq!(
        text, committed,
        "regenerate: cargo run --release -p coil-thermal-host --bin coil-thermal -- codegen --model host-tests/models/solenoid-valve-24v.toml --out host-tests/tests/generated/solenoid_valve_24v.rs"
    );
    assert!(text.contains("use coil_thermal::VoltageDrive;"));
    assert!(
        text.contains("[Some(VoltageDrive::pwm(input[0], 1.0_f32 * signal[0]))]"),
        "{text}"
    );
    assert!(text.contains("observer.drive_limit(state, 0, 1.0_f32 * signal[0]).duty"));
}

#[path = "generated/solenoid_valve_24v.rs"]
mod valve;

/// The generated firmware module in closed loop with the model file's own
/// simulator: full duty asked on a supply that rises from 24 V to 28 V,
/// the duty held to `input_drive_limits`, a housing thermocouple every
/// 500 ms. The coil (the simulator's) stays under its derated alarm limit.
#[test]
fn the_generated_valve_firmware_holds_the_coil_under_its_alarm_limit() {
    let observer = valve::observer().unwrap();
    let mut state = valve::initial_state(&observer, AMBIENT_C as f32);
    let alarm_c = f64::from(observer.alarm().alarm_limits_c(AMBIENT_C as f32)[0]);
    let mut plant = FilePlant::new(build(&valve_text()).unwrap()).unwrap();
    plant.reset(&[AMBIENT_C; 2]);
    let mut duty = 1.0f32;
    let (mut hottest, mut min_duty) = (f64::NEG_INFINITY, 1.0f32);
    for k in 0..(3 * 3_600_000u32) {
        let supply = if k < 3_600_000 { 24.0f32 } else { 28.0 };
        let now_us = k.wrapping_mul(1000);
        let signal = [supply];
        let mut inputs = valve::Inputs {
            currents_a: valve::source_currents_a(&[duty], &signal),
            boundary_c: [AMBIENT_C as f32],
            readings: [None],
            now_us,
            elapsed_us: 1000,
        };
        if k % 500 == 0 {
            inputs.readings = [Some(coil_thermal::observer::TimedReading {
                result: Ok(coil_thermal::Reading::new(plant.temps_c()[1] as f32)),
                sampled_at_us: now_us,
            })];
        }
        observer.tick_voltage(&mut state, &inputs, &valve::source_drives(&[duty], &signal));
        plant.step(1e-3, &[f64::from(duty)], &[AMBIENT_C], &[f64::from(supply)]);
        hottest = hottest.max(plant.temps_c()[0]);
        // The controller asks for full duty; the limit holds it.
        duty = valve::input_drive_limits(&observer, &state, &signal)[0].min(1.0);
        min_duty = min_duty.min(duty);
    }
    println!(
        "generated valve firmware, full duty asked on 24 V then 28 V: coil peak {hottest:.2} degC (alarm limit {alarm_c:.2}), duty down to {min_duty:.3}"
    );
    assert!(min_duty < 0.9, "the limit must act");
    assert!(hottest < alarm_c, "{hottest} over {alarm_c}");
}
