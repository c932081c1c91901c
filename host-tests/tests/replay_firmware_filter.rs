//! `replay --measure` runs the firmware's filter: the library observer
//! padded to a size class, the model's sources with their heat-input biases
//! at the model file's `[observer]` settings, the padding's left out. Its
//! estimate is the one of the observer `coil-thermal codegen` generated
//! from the same file (`examples/generated/drive_3node.rs`, from
//! `drive-3node-fitted.toml`), ticked directly at 1 ms over the bench
//! recording `host-tests/traces/drive-3node.csv`, to the bit; so are the
//! real motor's and the every-term model's, whose speed factors and losses
//! the host computes as the module's `source_currents_a` does, in `f32`.

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::network::{
    NetworkInputs, NetworkObserver, NetworkObserverState, WarmUpKind,
};
use coil_thermal::observer::TimedReading;
use coil_thermal::Reading;
use coil_thermal_host::codegen::FirmwareInputs;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sim::{simulate, Drive, FilePlant};
use serde_json::Value;
use tempfile::TempDir;

mod common;

#[path = "../../examples/generated/drive_3node.rs"]
mod model;

#[path = "../../examples/generated/hust_motor.rs"]
mod hust_motor;

#[path = "../../examples/generated/hust_motor_integer.rs"]
mod hust_motor_integer;

#[path = "../../examples/support/motor_drive.rs"]
mod motor_drive;

#[path = "generated/all_input_terms.rs"]
mod all_input_terms;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// `(current, ambient, winding_tc, housing_tc)` of every row of the trace.
fn trace_rows() -> Vec<[f32; 4]> {
    let text = std::fs::read_to_string(root().join("host-tests/traces/drive-3node.csv")).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            // As `replay` reads a cell: `f64`, rounded once to `f32`.
            let v: Vec<f32> = l
                .split(',')
                .skip(1)
                .map(|f| f.parse::<f64>().unwrap() as f32)
                .collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect()
}

/// A generated (firmware) observer ticked at 1 ms as the replay hands a
/// trace over: each row's currents and boundaries held for its second,
/// the row's readings given to the second's first tick. Returns the node
/// temperatures at every row (the start, then after each second) and the
/// heat-input biases at the end \[W\].
#[allow(clippy::type_complexity)]
fn tick_each_second<
    const N: usize,
    const B: usize,
    const M: usize,
    const X: usize,
    const P: usize,
    W: WarmUpKind<X>,
>(
    observer: &NetworkObserver<N, B, M, X, P>,
    mut state: NetworkObserverState<N, B, M, X, P, W>,
    rows: &[([f32; M], [f32; B], [Option<f32>; P])],
) -> (Vec<[f32; N]>, [f32; M]) {
    let mut out = vec![state.outputs().temps_c];
    let mut now_us: u32 = 0;
    for (currents_a, boundary_c, readings_c) in &rows[..rows.len() - 1] {
        for k in 0..1000 {
            now_us += 1000;
            let readings = readings_c.map(|r| {
                r.filter(|_| k == 0).map(|temp_c| TimedReading {
                    result: Ok(Reading::new(temp_c)),
                    sampled_at_us: now_us,
                })
            });
            let inputs = NetworkInputs {
                currents_a: *currents_a,
                boundary_c: *boundary_c,
                readings,
                now_us,
                elapsed_us: 1000,
            };
            observer.tick(&mut state, &inputs);
        }
        out.push(state.outputs().temps_c);
    }
    (out, observer.heat_bias_w(&state))
}

/// The generated `drive-3node` observer over its bench trace (the housing
/// thermocouple fused).
fn firmware_estimates(rows: &[[f32; 4]]) -> Vec<[f32; 3]> {
    let observer = model::observer().expect("the generated parts assemble");
    let state = model::initial_state(&observer, rows[0][1]);
    let rows: Vec<_> = rows
        .iter()
        .map(|[current_a, ambient_c, _, housing_tc]| {
            (
                model::source_currents_a(&[*current_a], &[]),
                [*ambient_c],
                [Some(*housing_tc)],
            )
        })
        .collect();
    tick_each_second(&observer, state, &rows).0
}

/// `replay` of the bench trace on the fitted model, fusing the housing
/// thermocouple with the firmware's sensor noise (0.25 K, the library's
/// default, which the generated module has); the estimate CSV's rows and
/// the JSON summary.
fn replay(dir: &Path, extra: &[&str]) -> (Vec<Vec<f64>>, Value) {
    let out = dir.join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join("host-tests/models/drive-3node-fitted.toml"))
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args([
            "--measure",
            "housing_tc=housing",
            "--truth",
            "winding_tc=winding",
        ])
        .args(["--measurement-noise-k", "0.25", "--json", "--out"])
        .arg(&out)
        .args(extra)
        .assert()
        .success();
    let json = serde_json::from_slice(&a.get_output().stdout).unwrap();
    (estimate_rows(&out), json)
}

/// The node estimates of every row of a `replay --out` CSV \[degC\].
fn estimate_rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(1).map(|v| v.parse().unwrap()).collect())
        .collect()
}

/// Asserts that `replay`'s estimates are a generated observer's to the
/// bit, row by row and node by node (the CSV holds each `f32` as the
/// decimal that reads back to it).
fn assert_bit_equal<const N: usize>(
    replayed: &[Vec<f64>],
    generated: &[[f32; N]],
    names: &[&str; N],
) {
    assert_eq!(replayed.len(), generated.len());
    for (t, (r, g)) in replayed.iter().zip(generated).enumerate() {
        for (node, (r, g)) in r.iter().zip(g).enumerate() {
            assert!(
                common::same_f32(*r, *g),
                "row {t}, node {}: replay {r} vs generated {g} (off by {} K)",
                names[node],
                (f64::from(*r as f32) - f64::from(*g)).abs()
            );
        }
    }
}

#[test]
fn the_fused_replay_is_the_generated_firmware_observer() {
    let tmp = TempDir::new().unwrap();
    let rows = trace_rows();
    let firmware = firmware_estimates(&rows);
    let (replayed, json) = replay(tmp.path(), &[]);
    // The file's `[observer] bias_noise_w2_per_s = 1e-4`, as generated.
    let fusion = &json["fusion"];
    assert_eq!(fusion["bias_noise_w2_per_s"], 1e-4);
    assert_eq!(fusion["bias_noise_from"], "model-file");
    assert_eq!(fusion["max_cooling_bias_fraction"], 0.0);
    assert_bit_equal(&replayed, &firmware, &model::NODE_NAMES);
    eprintln!(
        "replay is the generated observer to the bit over {} rows",
        rows.len()
    );
    // The firmware's winding against the bench thermocouple it never saw
    // (codegen_round_trip: worst 0.66 K after the first minute).
    let max = json["truth"][0]["max_abs_error_k"].as_f64().unwrap();
    assert!(max < 1.0, "winding off the bench thermocouple by {max} K");
    // Frozen biases are another filter: the replay no longer matches it.
    let (frozen, json) = replay(tmp.path(), &["--bias-noise-w2-per-s", "0"]);
    assert_eq!(json["fusion"]["bias_noise_w2_per_s"], 0.0);
    assert_eq!(json["fusion"]["bias_noise_from"], "flag");
    let apart = frozen
        .iter()
        .zip(&firmware)
        .map(|(r, f)| (r[0] - f64::from(f[0])).abs())
        .fold(0.0, f64::max);
    eprintln!("frozen biases: winding up to {apart:.3} K from the firmware's");
    assert!(apart > 0.05, "frozen {apart} K");
}

/// `replay` of the bench trace on `model`, fusing the housing thermocouple
/// with no noise flag; the estimate CSV's text and the JSON summary.
fn replay_without_noise_flag(dir: &Path, model: &Path) -> (String, Value) {
    let out = dir.join("plain.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(model)
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args(["--measure", "housing_tc=housing", "--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json = serde_json::from_slice(&a.get_output().stdout).unwrap();
    (std::fs::read_to_string(&out).unwrap(), json)
}

/// Without `--measurement-noise-k` the replay fuses with the model file's
/// `[observer] sensor_sigma_k`, the noise `codegen` builds the firmware
/// with: the same estimates as the flag with that value; a file without
/// the key falls back to 0.2 K and says so.
#[test]
fn the_model_files_sensor_noise_is_the_replays_default() {
    let tmp = TempDir::new().unwrap();
    let fitted = root().join("host-tests/models/drive-3node-fitted.toml");
    let text = std::fs::read_to_string(&fitted).unwrap();
    let with_key = tmp.path().join("with-sigma.toml");
    std::fs::write(
        &with_key,
        text.replacen("[observer]\n", "[observer]\nsensor_sigma_k = 0.25\n", 1),
    )
    .unwrap();
    let (from_file, json) = replay_without_noise_flag(tmp.path(), &with_key);
    assert_eq!(json["fusion"]["sensor_sigma_k"], 0.25);
    assert_eq!(json["fusion"]["sensor_sigma_from"], "model-file");
    let (_, flagged) = replay(tmp.path(), &[]);
    assert_eq!(flagged["fusion"]["sensor_sigma_from"], "flag");
    let from_flag = std::fs::read_to_string(tmp.path().join("est.csv")).unwrap();
    assert_eq!(from_file, from_flag);
    // Without the key, codegen's default (the library's 0.25 K): the
    // replay is then the same as with the key at 0.25 K.
    let (default, json) = replay_without_noise_flag(tmp.path(), &fitted);
    assert_eq!(json["fusion"]["sensor_sigma_k"], 0.25);
    assert_eq!(json["fusion"]["sensor_sigma_from"], "default");
    assert_eq!(default, from_flag);
    // And another noise is another replay.
    let other = tmp.path().join("other-sigma.toml");
    std::fs::write(
        &other,
        text.replacen("[observer]\n", "[observer]\nsensor_sigma_k = 0.4\n", 1),
    )
    .unwrap();
    let (from_other, _) = replay_without_noise_flag(tmp.path(), &other);
    assert_ne!(from_other, default);
}

/// The real motor's seven-node model (`hust_motor_slot_fitted.toml`: copper
/// with an AC speed factor, speed-dependent iron and magnet losses) through
/// `codegen` (`examples/generated/hust_motor.rs`), on the drive of load and
/// speed steps of `examples/support/motor_drive.rs`:
/// * the host prints what the firmware printed in QEMU
///   (`examples/motor_qemu.expected`, checksum of every tick included);
/// * the fused estimate, its currents made by the generated
///   `source_currents_a` from |i_s| and the speed, is `replay`'s library
///   observer, which folds the same terms into effective currents on the
///   host, at every second;
/// * the thermocouple, 2.5 K above open loop after five minutes (a heat
///   the model lacks), pulls the end winding more than half way (at the
///   file's declared 0.5 K noise, to 0.16 K) and the copper's heat bias
///   takes up heat (2.69 W after five minutes, at the library's default
///   bias noise: with the file's node noise, 1.5e-3 K^2/s, the temperatures
///   take most of the correction; at the default 1e-4 the bias reached
///   12.12 W).
#[test]
fn the_real_motors_generated_observer_with_speed_terms_is_replays() {
    let observer = hust_motor::observer().expect("the generated parts assemble");
    the_motor_module_is_replays(
        &observer,
        "examples/motor_qemu.expected",
        "host-tests/models/hust_motor_slot_fitted.toml",
    );
}

/// [`the_real_motors_generated_observer_with_speed_terms_is_replays`] for
/// the same model with the integer model step
/// (`hust_motor_slot_integer.toml`, `examples/generated/hust_motor_integer.rs`):
/// the host prints what the Cortex-M0 printed in QEMU
/// (`examples/motor_qemu_m0.expected`), `replay` of its file is it to the
/// bit, and it reads as the `f32` step's module does (the printed lines
/// but the checksum equal).
#[test]
fn the_real_motors_integer_step_module_is_replays() {
    let observer = hust_motor_integer::observer().expect("the generated parts assemble");
    the_motor_module_is_replays(
        &observer,
        "examples/motor_qemu_m0.expected",
        "host-tests/models/hust_motor_slot_integer.toml",
    );
    let read = |f: &str| std::fs::read_to_string(root().join(f)).unwrap();
    let (float, integer) = (
        read("examples/motor_qemu.expected"),
        read("examples/motor_qemu_m0.expected"),
    );
    let without_checksum = |t: &str| t.split(", checksum").next().unwrap_or_default().to_string();
    assert_eq!(without_checksum(&float), without_checksum(&integer));
    assert_ne!(float, integer, "the checksums tell the two steps apart");
}

/// The real motor's generated `observer` (either step): the host prints
/// `expected`, and `replay --measure` of `model_file` is it to the bit.
fn the_motor_module_is_replays(observer: &hust_motor::Observer, expected: &str, model_file: &str) {
    use motor_drive::{drive, AMBIENT_C, SECONDS};
    let mut seconds = Vec::new();
    let mut text = String::new();
    let summary = motor_drive::replay(
        observer,
        &mut text,
        |tick| {
            tick();
        },
        |s| seconds.push((*s.fused_c, s.reading_c)),
    )
    .expect("replays");
    assert_eq!(
        text,
        std::fs::read_to_string(root().join(expected)).unwrap(),
        "the host run differs from the firmware's golden output {expected}"
    );

    // The same drive as a trace for `replay`.
    let tmp = TempDir::new().unwrap();
    let trace = tmp.path().join("motor.csv");
    let mut csv = String::from("time_s,IdFbk,IqFbk,speed,water_outlet,ambient,endwind_1\n");
    for (t, (_, reading_c)) in seconds.iter().enumerate() {
        let (current_a, speed_rpm) = drive(t as u32);
        // |i_s| split 3:4 between d and q: hypot gives it back.
        let (id, iq) = (-0.6 * current_a, 0.8 * current_a);
        csv.push_str(&format!(
            "{t},{id},{iq},{speed_rpm},{AMBIENT_C},{AMBIENT_C},{reading_c}\n"
        ));
    }
    std::fs::write(&trace, csv).unwrap();
    let out = tmp.path().join("est.csv");
    let a = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join(model_file))
        .arg("--trace")
        .arg(&trace)
        .args(["--measure", "endwind_1=end_winding", "--json", "--out"])
        .arg(&out)
        .assert()
        .success();
    let json: Value = serde_json::from_slice(&a.get_output().stdout).unwrap();
    // The file's `[observer] sensor_sigma_k`, as generated.
    assert_eq!(json["fusion"]["sensor_sigma_k"], 0.5);
    assert_eq!(json["fusion"]["sensor_sigma_from"], "model-file");
    assert_eq!(json["fusion"]["sensors"][0]["rejected"], 0, "{json}");
    let fused: Vec<_> = seconds.iter().map(|(f, _)| *f).collect();
    assert_bit_equal(&estimate_rows(&out), &fused, &hust_motor::NODE_NAMES);
    eprintln!(
        "replay is the generated motor observer to the bit over {} s; end winding {:.3} K from its thermocouple (open loop {:.3} K), copper bias {:.2} W",
        SECONDS, summary.end_error_k, summary.open_error_k, summary.copper_bias_w
    );
    assert!(
        summary.end_error_k < 0.5 * summary.open_error_k,
        "{summary:?}"
    );
    assert!(summary.copper_bias_w > 1.0, "{summary:?}");
}

/// The generated currents of the real motor: the speed by magnitude (a
/// motor turning backwards loses as forwards), the copper's AC factor and
/// the iron losses at their model-file values, and a NaN speed kept NaN on
/// every current it drives (the observer then holds their last value,
/// flagged) rather than read as standstill.
#[test]
fn the_real_motors_generated_currents_follow_the_model_file() {
    let forward = hust_motor::source_currents_a(&[200.0], &[3000.0]);
    assert_eq!(forward, hust_motor::source_currents_a(&[200.0], &[-3000.0]));
    // The file's slot copper: 1 + 0.02174 f + a2 f^2 at f = 0.75 (a2 the fit's).
    let f = 0.75_f32;
    let a2 = 0.163_817_15_f32;
    let factor = 1.0 + 0.02174 * f + a2 * f * f;
    assert!(
        (forward[0] - 200.0 * factor.sqrt()).abs() < 1e-3,
        "{forward:?}"
    );
    assert_eq!(forward[2], 200.0, "the end winding has no speed factor");
    // The teeth's iron: 390.55 W at 4000 rpm, linear in the speed.
    let teeth_w = forward[3] * forward[3];
    assert!((teeth_w - 390.553_9 * f).abs() < 1e-2, "{teeth_w} W");
    let lost = hust_motor::source_currents_a(&[200.0], &[f32::NAN]);
    for (k, name) in hust_motor::CURRENT_NAMES.iter().enumerate() {
        let driven_by_speed = name.contains("speed");
        assert_eq!(lost[k].is_nan(), driven_by_speed, "{name}: {}", lost[k]);
    }
}

proptest::proptest! {
    /// Any current and speed, NaN, infinities and extremes included: the
    /// generated currents never panic, are NaN wherever a NaN drives them
    /// (not read as zero), never negative for a loss, and finite for any
    /// plausible current and speed (an absurd speed's factor overflows to an
    /// infinite or NaN current); the observer ticked with them keeps finite
    /// temperatures and flags every current it clamps or holds.
    #[test]
    fn the_real_motors_generated_currents_take_any_input(
        current_a in proptest::num::f32::ANY,
        speed_rpm in proptest::num::f32::ANY,
    ) {
        let c = hust_motor::source_currents_a(&[current_a], &[speed_rpm]);
        for (k, name) in hust_motor::CURRENT_NAMES.iter().enumerate() {
            let by_current = !name.contains("speed loss");
            let by_speed = name.contains("speed");
            let nan_in = (by_current && current_a.is_nan()) || (by_speed && speed_rpm.is_nan());
            if nan_in {
                proptest::prop_assert!(c[k].is_nan(), "{}: {}", name, c[k]);
            }
            proptest::prop_assert!(by_current || c[k].is_nan() || c[k] >= 0.0, "{}: {}", name, c[k]);
        }
        // Plausible inputs give plausible currents.
        if current_a.abs() <= 1e3 && speed_rpm.abs() <= 1e5 {
            proptest::prop_assert!(c.iter().all(|i| i.is_finite()), "{:?}", c);
        }
        let observer = hust_motor::observer().unwrap();
        let mut state = hust_motor::initial_state(&observer, 25.0);
        let inputs = hust_motor::Inputs {
            currents_a: c,
            boundary_c: [25.0; hust_motor::BOUNDARIES],
            readings: [None],
            now_us: 1000,
            elapsed_us: 1000,
        };
        let out = *observer.tick(&mut state, &inputs);
        proptest::prop_assert!(out.temps_c.iter().all(|t| t.is_finite()), "{:?}", out.temps_c);
        let bad = c.iter().any(|i| !i.is_finite() || i.abs() > 500.0);
        proptest::prop_assert!(!bad || !out.flags.is_clean(), "{:?} unflagged: {:?}", c, out.flags);
    }

    /// The currents `replay` hands its observer (`FirmwareInputs`, the
    /// host's twin of the generated `source_currents_a`) are the generated
    /// modules' to the bit for any inputs and signals, NaN, infinities,
    /// negative and extreme values included (a NaN as a NaN): the real motor's (an AC
    /// factor, three speed losses) and the every-term model's (a power
    /// scale, a split loss polynomial in current and speed, a constant
    /// loss).
    #[test]
    fn replays_currents_are_the_generated_modules_to_the_bit(
        input_a in proptest::array::uniform2(proptest::num::f32::ANY),
        signal in proptest::array::uniform2(proptest::num::f32::ANY),
    ) {
        // A NaN is a NaN (the observer holds it, whatever its payload).
        let same = |host: &[f32], module: &[f32]| {
            host.len() == module.len()
                && host
                    .iter()
                    .zip(module)
                    .all(|(h, m)| h.to_bits() == m.to_bits() || (h.is_nan() && m.is_nan()))
        };
        let motor = FirmwareInputs::new(&load("hust_motor_slot_fitted.toml"));
        let mut host = vec![0.0; motor.len()];
        motor.currents_a(&input_a[..1], &signal[..1], &mut host);
        let module = hust_motor::source_currents_a(&[input_a[0]], &[signal[0]]);
        proptest::prop_assert!(same(&host, &module), "{:?} vs {:?}", host, module);
        let every = FirmwareInputs::new(&load("all-input-terms.toml"));
        let mut host = vec![0.0; every.len()];
        every.currents_a(&input_a, &signal, &mut host);
        let module = all_input_terms::source_currents_a(&input_a, &signal);
        proptest::prop_assert!(same(&host, &module), "{:?} vs {:?}", host, module);
    }
}

/// A shipped model file, built.
fn load(file: &str) -> Model {
    Model::build(&ModelFile::load(&root().join("host-tests/models").join(file)).unwrap()).unwrap()
}

/// The generated observer of the test model with every kind of heat input
/// (`host-tests/models/all-input-terms.toml`: sources on other nodes than
/// their index, a split loss, a constant loss, two current inputs, the
/// ambient the second boundary) is `replay`'s library observer over ten
/// minutes of current, speed and boundary steps, the stator thermocouple
/// fused; open loop it follows the host's own integration of the model
/// file (explicit Euler, converged) to 4 mK: every source heats its node
/// with the power the file gives it.
#[test]
fn a_generated_observer_with_every_input_term_is_replays() {
    const ROWS: usize = 600;
    // |i| [A], aux [A], speed [rpm], coolant and ambient [degC] by minute.
    let drive = |t: usize| -> (f32, f32, f32, f32, f32) {
        match t / 120 {
            0 => (0.0, 0.0, 0.0, 30.0, 22.0),
            1 => (120.0, 10.0, 3000.0, 30.0, 22.0),
            2 => (60.0, -15.0, -1500.0, 32.0, 25.0),
            3 => (150.0, 0.0, 6000.0, 32.0, 25.0),
            _ => (20.0, 20.0, 500.0, 28.0, 20.0),
        }
    };
    let observer = all_input_terms::observer().expect("the generated parts assemble");
    let start = || observer.state(&[30.0; all_input_terms::NODES], &[30.0, 22.0]);
    let rows = |readings: &dyn Fn(usize) -> Option<f32>| -> Vec<_> {
        (0..ROWS)
            .map(|t| {
                let (current_a, aux_a, speed_rpm, coolant_c, ambient_c) = drive(t);
                (
                    all_input_terms::source_currents_a(
                        &[current_a, aux_a],
                        &[speed_rpm, current_a],
                    ),
                    [coolant_c, ambient_c],
                    [readings(t)],
                )
            })
            .collect()
    };
    let (open, _) = tick_each_second(&observer, start(), &rows(&|_| None));
    // The stator's thermocouple reads 1 K above open loop: an offset the
    // fusion takes up.
    let reading = |t: usize| open[t][1] + 1.0;
    let (fused, _) = tick_each_second(&observer, start(), &rows(&|t| Some(reading(t))));

    let tmp = TempDir::new().unwrap();
    let trace = tmp.path().join("terms.csv");
    let mut csv = String::from("time_s,id,iq,aux,speed,coolant,ambient,stator_tc\n");
    for t in 0..ROWS {
        let (current_a, aux_a, speed_rpm, coolant_c, ambient_c) = drive(t);
        let (id, iq) = (-0.6 * current_a, 0.8 * current_a);
        csv.push_str(&format!(
            "{t},{id},{iq},{aux_a},{speed_rpm},{coolant_c},{ambient_c},{}\n",
            reading(t)
        ));
    }
    std::fs::write(&trace, csv).unwrap();
    let out = tmp.path().join("est.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(root().join("host-tests/models/all-input-terms.toml"))
        .arg("--trace")
        .arg(&trace)
        .args([
            "--measure",
            "stator_tc=stator",
            "--measurement-noise-k",
            "0.25",
        ])
        .args([
            "--init",
            "coolant=winding",
            "--init",
            "coolant=stator",
            "--init",
            "coolant=rotor",
        ])
        .arg("--out")
        .arg(&out)
        .assert()
        .success();
    assert_bit_equal(&estimate_rows(&out), &fused, &all_input_terms::NODE_NAMES);
    // The open loop against an independent integration of the model file:
    // the host's plant (`simulate`: its own network, explicit Euler
    // sub-steps, the file's effective currents in f64, R(T) per sub-step).
    let mut file = ModelFile::load(&root().join("host-tests/models/all-input-terms.toml")).unwrap();
    // Sub-steps of 0.1 % of the fastest node's time constant: converged to
    // 4 mK (0.134 K at the file's 0.5, 0.033 K at 0.01: Euler's error).
    file.max_step_ratio = Some(0.001);
    let mut plant = FilePlant::new(Model::build(&file).unwrap()).unwrap();
    let at = |k: usize| -> Vec<f64> {
        (0..ROWS)
            .map(|t| f64::from(<[f32; 5]>::from(drive(t))[k]))
            .collect()
    };
    let host = simulate(
        &mut plant,
        &Drive {
            time_s: (0..ROWS).map(|t| t as f64).collect(),
            currents: vec![at(0), at(1)],
            boundaries: vec![at(3), at(4)],
            signals: vec![at(2), at(0).iter().map(|i| i.abs()).collect()],
        },
        &[30.0; all_input_terms::NODES],
    );
    let apart = host
        .iter()
        .zip(&open)
        .flat_map(|(h, o)| h.iter().zip(o).map(|(h, o)| (h - f64::from(*o)).abs()))
        .fold(0.0, f64::max);
    let hottest = open.iter().map(|o| o[0]).fold(f32::MIN, f32::max);
    eprintln!("replay is the generated every-term observer to the bit over {ROWS} s; open loop vs the host's plant: worst {apart:.3} K, winding up to {hottest:.1} degC");
    assert!(hottest > 40.0, "the drive heats: {hottest}");
    assert!(apart < 0.01, "open loop {apart} K from the host's plant");
}
