//! README's "A three-phase motor with one thermocouple", run as a new user
//! would, every command as README shows it:
//!
//! 1. the bench recordings `host-tests/traces/three-phase-bench.csv` (fit)
//!    and `three-phase-validation.csv` (held out) are the simulation of
//!    `models/three-phase-1tc-truth.toml` (the guess's capacities and
//!    conductances 6-18 % off) with 0.1 K of seeded noise on a thermocouple
//!    in each phase and one on the housing (a bench; the product keeps the
//!    housing's only): this file makes them, and checks the committed ones
//!    are its output (`COIL_THERMAL_REGENERATE=1` writes them);
//! 2. `calibrate` fits the guess `models/three-phase-1tc.toml` to the bench
//!    recording, validated on the held-out one, into
//!    `models/three-phase-1tc-fitted.toml` (checked byte for byte);
//! 3. `replay` of the held-out recording with the housing thermocouple
//!    fused scores the three phases, which the product does not measure,
//!    against the bench's phase thermocouples;
//! 4. `codegen` writes `examples/generated/three_phase_1tc.rs` with no
//!    `bias_sources` line (one heat shared by the phases), checked byte for
//!    byte; `examples/three_phase_qemu.rs` runs it in QEMU (CI compares
//!    its lines), and here the same replay prints the same lines.

use std::path::{Path, PathBuf};

use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sim::{FilePlant, Plant};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Phase currents \[A RMS\] and the ambient \[degC\] of a segment, from
/// its start \[s\].
type Segment = (u32, [f64; 3], f64);

/// The fit: a load cycle with a locked rotor (phase a carrying the
/// holding current, b and c half of it) and a rest.
const BENCH: [Segment; 6] = [
    (0, [6.0, 6.0, 6.0], 24.0),
    (900, [0.0, 0.0, 0.0], 24.5),
    (1500, [8.0, 4.0, 4.0], 25.0),
    (2400, [7.0, 7.0, 7.0], 25.5),
    (3000, [3.0, 3.0, 3.0], 26.0),
    (3600, [3.0, 3.0, 3.0], 26.0),
];

/// Held out: another cycle, the lock on phase b.
const VALIDATION: [Segment; 6] = [
    (0, [4.0, 4.0, 4.0], 25.0),
    (600, [7.5, 7.5, 7.5], 25.0),
    (1500, [4.5, 9.0, 4.5], 25.5),
    (2100, [0.0, 0.0, 0.0], 25.5),
    (2700, [6.5, 6.5, 6.5], 25.0),
    (3600, [6.5, 6.5, 6.5], 25.0),
];

/// The seeded noise: xorshift64* and Box-Muller.
struct Noise(u64);

impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let r = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        ((r >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn gaussian(&mut self, sigma: f64) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        sigma * (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// A recording of the truth model over `profile`: one row a second, the
/// plant stepped at 0.1 s, every thermocouple with 0.1 K of noise.
fn recording(profile: &[Segment], seed: u64) -> String {
    let path = root().join("host-tests/models/three-phase-1tc-truth.toml");
    let model = Model::build(&ModelFile::load(&path).unwrap()).unwrap();
    let mut plant = FilePlant::new(model).unwrap();
    let start_c = profile[0].2;
    plant.reset(&[start_c; 4]);
    let mut noise = Noise(seed);
    let mut out = String::from("time_s,ia,ib,ic,ambient,a_tc,b_tc,c_tc,housing_tc\n");
    let end = profile.last().unwrap().0;
    for t in 0..=end {
        let seg = profile.iter().rev().find(|s| s.0 <= t).unwrap();
        let (currents, ambient) = (seg.1, seg.2);
        let temps = plant.temps_c().to_vec();
        let tc: Vec<String> = temps
            .iter()
            .map(|v| format!("{:.3}", v + noise.gaussian(0.1)))
            .collect();
        out.push_str(&format!(
            "{t},{},{},{},{ambient},{}\n",
            currents[0],
            currents[1],
            currents[2],
            tc.join(",")
        ));
        for _ in 0..10 {
            plant.step(0.1, &currents, &[ambient], &[]);
        }
    }
    out
}

#[test]
fn the_bench_recordings_are_the_truth_models() {
    for (name, profile, seed) in [
        ("three-phase-bench", &BENCH, 0x003f_a5e1),
        ("three-phase-validation", &VALIDATION, 0x0007_a11d),
    ] {
        let text = recording(profile, seed);
        let path = root().join(format!("host-tests/traces/{name}.csv"));
        if std::env::var_os("COIL_THERMAL_REGENERATE").is_some() {
            std::fs::write(&path, &text).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            committed == text,
            "{} is not this test's output: COIL_THERMAL_REGENERATE=1 cargo test --release -p coil-thermal-host --test three_phase_walkthrough",
            path.display()
        );
    }
}

use assert_cmd::cargo::cargo_bin_cmd;

#[path = "../../examples/generated/three_phase_1tc.rs"]
mod model;

#[path = "../../examples/support/three_phase.rs"]
mod three_phase;

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// README's steps 2 and 4 (`calibrate` on the bench recording, validated
/// on the held-out one; `codegen` of the fitted file) reproduce the
/// committed files byte for byte, and the fit finds the bench's truth
/// (which the guess missed by 6-18 %) within 1 %.
#[test]
fn calibrate_then_codegen_reproduce_the_committed_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let models = root().join("host-tests/models");
    let fitted = dir.path().join("three-phase-1tc-fitted.toml");
    cargo_bin_cmd!("coil-thermal")
        .arg("calibrate")
        .arg("--model")
        .arg(models.join("three-phase-1tc.toml"))
        .arg("--trace")
        .arg(root().join("host-tests/traces/three-phase-bench.csv"))
        .args(["--measure", "a_tc=a,b_tc=b,c_tc=c,housing_tc=housing"])
        .args([
            "--params",
            "capacity.a,capacity.b,capacity.c,capacity.housing,conductance.a-housing,conductance.b-housing,conductance.c-housing,conductance.housing-air",
            "--no-progress",
        ])
        .arg("--validate")
        .arg(root().join("host-tests/traces/three-phase-validation.csv"))
        .arg("--out")
        .arg(&fitted)
        .assert()
        .success();
    let text = read(&fitted);
    assert_eq!(
        text,
        read(&models.join("three-phase-1tc-fitted.toml")),
        "calibrate no longer reproduces three-phase-1tc-fitted.toml: regenerate it and the module (README, \"A three-phase motor with one thermocouple\")"
    );
    assert!(
        !text
            .lines()
            .any(|l| l.trim_start().starts_with("bias_sources")),
        "the walkthrough needs no bias_sources line"
    );
    // Against the bench's truth, which the fit never read.
    let truth = Model::build(&ModelFile::load(&models.join("three-phase-1tc-truth.toml")).unwrap())
        .unwrap();
    let fit = Model::build(&ModelFile::load(&fitted).unwrap()).unwrap();
    let pairs = |m: &Model| -> Vec<f64> { m.network.pairs().iter().map(|p| p.g_w_per_k).collect() };
    let links = |m: &Model| -> Vec<f64> { m.network.links().iter().map(|l| l.g_w_per_k).collect() };
    for (what, t, f) in [
        (
            "capacity",
            truth.network.capacities_j_per_k().to_vec(),
            fit.network.capacities_j_per_k().to_vec(),
        ),
        ("conductance", pairs(&truth), pairs(&fit)),
        ("boundary conductance", links(&truth), links(&fit)),
    ] {
        for (i, (t, f)) in t.iter().zip(&f).enumerate() {
            assert!(
                (f / t - 1.0).abs() < 0.01,
                "{what} {i}: fitted {f}, truth {t}"
            );
        }
    }
    let generated = dir.path().join("model.rs");
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(&fitted)
        .arg("--out")
        .arg(&generated)
        .assert()
        .success();
    assert_eq!(
        read(&generated),
        read(&root().join("examples/generated/three_phase_1tc.rs")),
        "codegen no longer reproduces examples/generated/three_phase_1tc.rs"
    );
}

/// README's step 3: `replay` of the held-out hour with the product's one
/// housing thermocouple fused scores the three phases against the bench's
/// phase thermocouples (the truth's simulation with 0.1 K of noise), and
/// the upper bound the protection acts on is never below them.
#[test]
fn replay_scores_the_phases_the_product_does_not_measure() {
    let out = cargo_bin_cmd!("coil-thermal")
        .arg("replay")
        .arg("--model")
        .arg(root().join("host-tests/models/three-phase-1tc-fitted.toml"))
        .arg("--trace")
        .arg(root().join("host-tests/traces/three-phase-validation.csv"))
        .args([
            "--measure",
            "housing_tc=housing",
            "--truth",
            "a_tc=a,b_tc=b,c_tc=c",
            "--json",
        ])
        .assert()
        .success();
    let j: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    assert_eq!(j["estimator"], "network-observer", "{j}");
    for s in j["truth"].as_array().unwrap() {
        println!("{s}");
        // 0.1 K of thermocouple noise is in the truth column itself.
        assert!(s["rmse_k"].as_f64().unwrap() < 0.15, "{s}");
        assert!(s["max_abs_error_k"].as_f64().unwrap() < 0.6, "{s}");
    }
    for c in j["cold_misses"].as_array().unwrap() {
        assert_eq!(c["rows"], 0, "{c}");
    }
}

/// README's last step: the host replay of the generated module prints what
/// the firmware printed in QEMU (`examples/three_phase_qemu.expected`),
/// checksum of every tick's outputs included; each phase within 1 K of its
/// bench thermocouple after the first minute, and never above its upper
/// bound.
#[test]
fn the_host_replay_prints_what_the_firmware_printed() {
    let observer = model::observer().expect("the generated parts assemble");
    let mut text = String::new();
    let summary = three_phase::replay(&observer, &mut text, |tick| {
        tick();
    })
    .expect("replays");
    assert_eq!(
        text,
        read(&root().join("examples/three_phase_qemu.expected")),
        "the host replay differs from the firmware's golden output"
    );
    assert!(summary.worst_phase_error_k < 1.0, "{summary:?}");
    assert!(summary.worst_cold_miss_k < 0.0, "{summary:?}");
}

mod common;

/// The currents of the held-out hour doubled (`replay --current-scale`), so
/// that the phases pass their derated limits and the limiter and the
/// alarm act.
const CURRENT_SCALE: f64 = 2.0;

/// What the protection acts on, `replay` of the fitted file against the
/// generated module (one heat shared by the three phases, the housing
/// thermocouple fused) ticked at 1 ms on the host as `replay` hands it the
/// held-out hour: every node's estimate and upper bound, every limited
/// node's derated alarm limit and every phase's current limit to the bit,
/// every event on the same tick.
#[test]
fn the_replay_is_the_generated_module_to_the_bit() {
    let trace = root().join("host-tests/traces/three-phase-validation.csv");
    let dir = tempfile::TempDir::new().unwrap();
    let out = dir.path().join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .arg("replay")
        .arg("--model")
        .arg(root().join("host-tests/models/three-phase-1tc-fitted.toml"))
        .arg("--trace")
        .arg(&trace)
        .args(["--measure", "housing_tc=housing", "--json", "--out"])
        .arg(&out)
        .args(["--current-scale", &CURRENT_SCALE.to_string()])
        .assert()
        .success();
    let json: serde_json::Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    assert_eq!(
        json["firmware_observer"]["overrides"],
        serde_json::json!([])
    );
    let text = read(&out);
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let replayed: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    // time_s, ia, ib, ic, ambient, ..., housing_tc: each cell as `replay`
    // reads it, `f64` rounded once to `f32` (the currents after the scale).
    let rows: Vec<Vec<f64>> = read(&trace)
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let observer = model::observer().expect("the generated parts assemble");
    let mut state = model::initial_state(&observer, rows[0][4] as f32);
    let (mut events, mut now_us, mut lowest_a) = (Vec::new(), 0u32, f32::INFINITY);
    // The ambient the last ticks held (the derating follows it).
    let mut held_ambient_c = rows[0][4] as f32;
    assert_eq!(replayed.len(), rows.len());
    for (t, (row, r)) in rows.iter().zip(&replayed).enumerate() {
        let o = state.outputs();
        for (i, name) in model::NODE_NAMES.iter().enumerate() {
            let mut expected = vec![(name.to_string(), o.temps_c[i])];
            expected.push((format!("upper_c.{name}"), o.upper_c[i]));
            if let Some(limit_c) = observer.alarm().alarm_limit_c(i, held_ambient_c) {
                expected.push((format!("alarm_limit_c.{name}"), limit_c));
            }
            for (column, e) in expected {
                let v = r[col(&column)];
                assert!(
                    common::same_f32(v, e),
                    "row {t}, {column}: replay {v}, generated {e}"
                );
            }
        }
        for (input, limit_a) in model::INPUT_NAMES
            .iter()
            .zip(model::input_limits_a(&o.limits))
        {
            let v = r[col(&format!("limit_a.{input}"))];
            assert!(
                common::same_f32(v, limit_a),
                "row {t}, {input}: replay {v} A, generated {limit_a} A"
            );
            lowest_a = lowest_a.min(limit_a);
        }
        if t + 1 == rows.len() {
            break;
        }
        held_ambient_c = row[4] as f32;
        let currents = [1, 2, 3].map(|k| (row[k] * CURRENT_SCALE) as f32);
        let reading = |now_us| {
            [Some(coil_thermal::observer::TimedReading {
                result: Ok(coil_thermal::Reading::new(row[8] as f32)),
                sampled_at_us: now_us,
            })]
        };
        common::tick_row(
            &observer,
            &mut state,
            model::source_currents_a(&currents, &[]),
            [held_ambient_c],
            reading,
            &mut now_us,
            &mut events,
        );
    }
    // The doubled currents make the protection act.
    assert!(
        f64::from(lowest_a) < model::PARTS.hardware_limit_a[0],
        "lowest limit {lowest_a} A"
    );
    let replayed_events = common::json_events(&json);
    eprintln!("{} events, lowest limit {lowest_a} A", events.len());
    assert!(!events.is_empty());
    assert_eq!(replayed_events.len(), events.len(), "{json}");
    for (r, g) in replayed_events.iter().zip(&events) {
        assert_eq!((&r.1, &r.2), (&g.1, &g.2), "{r:?} vs {g:?}");
        assert_eq!(r.3.as_deref(), g.3.map(|i| model::NODE_NAMES[i]));
        assert!((r.0 - g.0).abs() < 1e-6, "{r:?} vs {g:?}");
    }
}
