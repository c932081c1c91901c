//! The model's way from a recording to the firmware, end to end:
//!
//! 1. `host-tests/traces/drive-3node.csv` is a bench recording (made from
//!    `host-tests/models/drive-3node-truth.toml` by `coil-thermal simulate`
//!    on a current profile, with 0.1 K of seeded noise on the two
//!    thermocouples: a bench whose truth we know);
//! 2. `coil-thermal calibrate` fits `drive-3node.toml` (a guess 5-20 % off)
//!    to it: `drive-3node-fitted.toml`;
//! 3. `coil-thermal codegen` writes `examples/generated/drive_3node.rs`;
//! 4. the firmware `examples/network_roundtrip.rs` replays the trace in
//!    QEMU and prints `examples/network_roundtrip.expected` (CI compares).
//!
//! Here: steps 2 and 3 reproduce the committed files byte for byte, the
//! generated observer is the builder's to the bit, and the host replay of
//! step 4 (the same `support/roundtrip.rs`, the same generated module)
//! prints exactly what the firmware printed, checksum of every tick
//! included. The physics: the unmeasured winding's estimate stays within
//! 1 K of the bench's winding thermocouple (which the observer never sees).

use std::path::{Path, PathBuf};

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::observer::network::{NetworkObserverBuilder, NetworkSettings};
use coil_thermal_host::model_file::{Model, ModelFile};

#[path = "../../examples/generated/drive_3node.rs"]
mod model;

#[path = "../../examples/generated/drive_3node_integer.rs"]
mod model_integer;

#[path = "../../examples/support/roundtrip.rs"]
mod roundtrip;

#[path = "generated/all_input_terms.rs"]
mod all_input_terms;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The Cortex-M0 model files are their `f32` firmware's files with the
/// integer model step, a one-element predictor stage, 10 ms model
/// steps on their 1 ms loop and (the drive's, whose correction was its
/// heaviest tick) a correction in two ticks, and nothing else: a new
/// fit of the source file (`calibrate`) must be copied to them.
#[test]
fn the_cortex_m0_model_files_are_their_sources_but_their_cost_keys() {
    for (source, integer, two_ticks) in [
        ("drive-3node-fitted.toml", "drive-3node-integer.toml", true),
        (
            "hust_motor_slot_fitted.toml",
            "hust_motor_slot_integer.toml",
            false,
        ),
    ] {
        let table = |file: &str| -> toml::Table {
            read(&root().join("host-tests/models").join(file))
                .parse()
                .unwrap_or_else(|e| panic!("{file}: {e}"))
        };
        let (mut from, mut to) = (table(source), table(integer));
        let observer = to
            .get_mut("observer")
            .and_then(toml::Value::as_table_mut)
            .expect("an [observer] table");
        assert_eq!(
            observer.remove("integer_model_step"),
            Some(toml::Value::Boolean(true))
        );
        assert_eq!(
            observer.remove("predictor_elements_per_stage"),
            Some(toml::Value::Integer(1))
        );
        assert_eq!(
            observer.remove("correction_in_two_ticks"),
            two_ticks.then_some(toml::Value::Boolean(true))
        );
        assert_eq!(
            observer.remove("step_us"),
            Some(toml::Value::Integer(10_000))
        );
        assert_eq!(
            observer.remove("loop_period_us"),
            Some(toml::Value::Integer(1000))
        );
        let name =
            |t: &mut toml::Table| t.remove("name").and_then(|n| n.as_str().map(String::from));
        let (a, b) = (name(&mut from).unwrap(), name(&mut to).unwrap());
        assert_eq!(b, format!("{a}-integer"));
        assert_eq!(
            from, to,
            "{integer} is no longer {source} with its cost keys: copy it again"
        );
    }
}

/// The same model with the integer model step, one predictor element a
/// stage and 10 ms model steps on the 1 ms loop (`drive-3node-integer.toml`,
/// `examples/generated/drive_3node_integer.rs`), which `network_roundtrip`
/// ticks on the Cortex-M0: the host prints what QEMU printed there
/// (`examples/network_roundtrip_m0.expected`), and those lines are the
/// 1 ms `f32` firmware's within 2 mK on the estimates, 10 mK on the upper
/// bounds (the 10 ms model's steady covariance: 7 mK lower at 5 A, 4 mK
/// higher at 1 A), and on the times to limit at most 5 s later and 10 s
/// earlier (993 s where the `f32` firmware's fresher sweep says 999 s: one
/// element a stage, each element's horizon in two, so its answers are
/// older; earlier, the safe side).
#[test]
fn the_host_replay_prints_what_the_cortex_m0_printed() {
    let observer = model_integer::observer().expect("the generated parts assemble");
    let mut text = String::new();
    let summary = roundtrip::replay(&observer, &mut text, |tick| {
        tick();
    })
    .expect("replays");
    let golden = read(&root().join("examples/network_roundtrip_m0.expected"));
    assert_eq!(
        text, golden,
        "the host replay differs from the Cortex-M0's output"
    );
    let float = read(&root().join("examples/network_roundtrip.expected"));
    // Each line's numbers (the last line's without its checksum), each
    // with the token before it.
    let numbers = |t: &str| -> Vec<(String, f64)> {
        let t = t.split(", checksum").next().unwrap_or_default();
        let tokens: Vec<&str> = t.split_whitespace().collect();
        tokens
            .iter()
            .enumerate()
            .filter_map(|(k, w)| {
                let v: f64 = w
                    .trim_end_matches(|c: char| !c.is_ascii_digit())
                    .parse()
                    .ok()?;
                Some((k.checked_sub(1).map_or("", |p| tokens[p]).to_string(), v))
            })
            .collect()
    };
    let (m0, f32_run) = (numbers(&golden), numbers(&float));
    assert_eq!(m0.len(), f32_run.len());
    for ((label, a), (_, b)) in m0.iter().zip(&f32_run) {
        // (earlier, later) than the `f32` firmware
        let (earlier, later) = match label.as_str() {
            "ttl" => (10.0, 5.0),
            "upper" => (0.01, 0.01),
            _ => (0.002, 0.002),
        };
        assert!(
            a - b <= later && b - a <= earlier,
            "{label} {a} on the Cortex-M0, {b} in f32 at 1 ms"
        );
    }
    assert_ne!(golden, float, "the checksums tell the two apart");
    assert!(summary.worst_winding_error_k < 1.0);
}

#[test]
fn the_host_replay_prints_what_the_firmware_printed() {
    let observer = model::observer().expect("the generated parts assemble");
    let mut text = String::new();
    let summary = roundtrip::replay(&observer, &mut text, |tick| {
        tick();
    })
    .expect("replays");
    assert_eq!(
        text,
        read(&root().join("examples/network_roundtrip.expected")),
        "the host replay differs from the firmware's golden output"
    );
    // Against the measurement the observer never saw.
    assert!(
        summary.worst_winding_error_k < 1.0,
        "winding estimate off the bench thermocouple by {} K",
        summary.worst_winding_error_k
    );
    assert_eq!(summary.corrections, roundtrip::SECONDS);
}

#[test]
fn the_generated_observer_is_the_builders() {
    let network = model::network().expect("the generated network builds");
    let parts = NetworkObserverBuilder::new(&network, [1])
        .critical_c([Some(155.0), Some(80.0), None])
        .hardware_limit_a([6.0])
        .settings(NetworkSettings {
            correction_period_s: 1.0,
            bias_noise_w2_per_s: 1e-4,
            ..NetworkSettings::DEFAULT
        })
        .parts::<{ model::STATES }>()
        .expect("solves");
    // Every table, to the bit: the text written by `write_rust` reads back
    // as the solved `f32`s.
    assert_eq!(parts, model::PARTS);
    assert_eq!(
        model::observer().expect("assembles").fingerprint(),
        NetworkObserverBuilder::new(&network, [1])
            .critical_c([Some(155.0), Some(80.0), None])
            .hardware_limit_a([6.0])
            .settings(NetworkSettings {
                correction_period_s: 1.0,
                bias_noise_w2_per_s: 1e-4,
                ..NetworkSettings::DEFAULT
            })
            .build::<{ model::STATES }>()
            .expect("builds")
            .fingerprint()
    );
}

#[test]
fn calibrate_then_codegen_reproduce_the_committed_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let fitted = dir.path().join("drive-3node-fitted.toml");
    let models = root().join("host-tests/models");
    cargo_bin_cmd!("coil-thermal")
        .arg("calibrate")
        .arg("--model")
        .arg(models.join("drive-3node.toml"))
        .arg("--trace")
        .arg(root().join("host-tests/traces/drive-3node.csv"))
        .args(["--measure", "winding_tc=winding", "--measure", "housing_tc=housing"])
        .args([
            "--params",
            "capacity.winding,capacity.housing,capacity.heatsink,conductance.winding-housing,conductance.housing-heatsink,conductance.heatsink-air",
            "--no-progress",
        ])
        .arg("--out")
        .arg(&fitted)
        .assert()
        .success();
    assert_eq!(
        read(&fitted),
        read(&models.join("drive-3node-fitted.toml")),
        "calibrate no longer reproduces drive-3node-fitted.toml: regenerate it and the module (README, \"Your own device\")"
    );
    let generated = dir.path().join("model.rs");
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(models.join("drive-3node-fitted.toml"))
        .arg("--out")
        .arg(&generated)
        .assert()
        .success();
    let text = read(&generated);
    assert_eq!(
        text,
        read(&root().join("examples/generated/drive_3node.rs")),
        "codegen no longer reproduces examples/generated/drive_3node.rs"
    );
    // What the tick needs is data: no exponential is left for the MCU.
    assert!(!text.contains("expm") && text.contains("Observer::from_assembled_parts(&PARTS)"));
}

#[test]
fn codegen_refuses_what_the_firmware_observer_cannot_take() {
    let models = root().join("host-tests/models");
    // No sensor named.
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(models.join("two-node-coil.toml"))
        .args(["--out", "-"])
        .assert()
        .failure()
        .stderr(predicates::str::contains("no sensor"));
    // A sensor on a node the model does not have.
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(models.join("two-node-coil.toml"))
        .args(["--sensor", "lid", "--out", "-"])
        .assert()
        .failure()
        .stderr(predicates::str::contains("lid"));
    // A conductance that changes with the speed changes the network the
    // tables are solved for (speed losses and factors are inputs: see
    // the real motor's module below).
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(models.join("hust-published.toml"))
        .args(["--sensor", "stator", "--out", "-"])
        .assert()
        .failure()
        .stderr(predicates::str::contains("[conductance.speed]"));
    // A coefficient the firmware's f32 arithmetic cannot hold.
    let dir = tempfile::tempdir().unwrap();
    let huge = dir.path().join("huge.toml");
    std::fs::write(
        &huge,
        read(&models.join("all-input-terms.toml")).replace("p1_w = 80.0", "p1_w = 1e40"),
    )
    .unwrap();
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(&huge)
        .args(["--out", "-"])
        .assert()
        .failure()
        .stderr(predicates::str::contains(
            "[[speed_loss]]: 1e40 is beyond the f32 range",
        ));
}

/// The committed modules with speed and loss terms, each what `codegen`
/// makes of its model file today: the real motor's
/// (`examples/generated/hust_motor.rs`: the end-winding thermocouple, the
/// copper's heat bias, 400 A; `replay_firmware_filter` holds it against
/// `replay`) and the test model with every kind of heat input
/// (`host-tests/tests/generated/all_input_terms.rs`, below).
#[test]
fn codegen_reproduces_the_committed_speed_term_modules() {
    for (model, extra, module) in [
        (
            "host-tests/models/hust_motor_slot_fitted.toml",
            &[][..],
            "examples/generated/hust_motor.rs",
        ),
        (
            "host-tests/models/all-input-terms.toml",
            &[][..],
            "host-tests/tests/generated/all_input_terms.rs",
        ),
        // The Cortex-M0 runs of `network_roundtrip` and `motor_qemu`: the
        // integer model step.
        (
            "host-tests/models/drive-3node-integer.toml",
            &[][..],
            "examples/generated/drive_3node_integer.rs",
        ),
        (
            "host-tests/models/hust_motor_slot_integer.toml",
            &[][..],
            "examples/generated/hust_motor_integer.rs",
        ),
        // The Cortex-M0 footprint example's (`examples/footprint_m0.rs`).
        (
            "host-tests/models/two-node-coil.toml",
            &["--sensor", "housing"][..],
            "examples/generated/two_node_coil.rs",
        ),
    ] {
        let out = cargo_bin_cmd!("coil-thermal")
            .arg("codegen")
            .arg("--model")
            .arg(root().join(model))
            .args(extra)
            .args(["--out", "-"])
            .assert()
            .success();
        let text = String::from_utf8_lossy(&out.get_output().stdout).into_owned();
        assert_eq!(
            text,
            read(&root().join(module)),
            "codegen no longer reproduces {module}: cargo run --release -p coil-thermal-host --bin coil-thermal -- codegen --model {model} {} --out {module}",
            extra.join(" ")
        );
    }
    let motor = read(&root().join("examples/generated/hust_motor.rs"));
    assert!(motor.contains("pub const SIGNAL_NAMES: [&str; SIGNALS] = [\"speed\"];"));
    assert!(
        motor.contains("ambient_boundary: 1,"),
        "the ambient is the second boundary"
    );
}

/// The generated currents of the test model with every kind of heat input
/// (a speed factor on a scaled winding, a second winding, a speed loss, a
/// split current-and-speed loss, a constant loss) carry the power the
/// host's `Model::effective_currents` gives each source, at currents and
/// speeds of either sign, zero and past the split's clip: the same
/// arithmetic in `f32` (each drive's power scale is in the generated
/// resistance, so the host's effective current squared is the scale times
/// the generated one squared).
#[test]
fn the_generated_currents_carry_the_hosts_powers_for_every_input_term() {
    let file = ModelFile::load(&root().join("host-tests/models/all-input-terms.toml")).unwrap();
    let model = Model::build(&file).unwrap();
    assert_eq!(model.signals, all_input_terms::SIGNAL_NAMES);
    assert_eq!(model.network.sources().len(), all_input_terms::CURRENTS);
    let mut host = Vec::new();
    let mut checked = 0;
    for current_a in [0.0_f64, 35.0, -80.0, 150.0] {
        for aux_a in [0.0_f64, -12.0, 20.0] {
            for speed_rpm in [0.0_f64, 900.0, -2500.0, 3000.0, 6000.0] {
                model.effective_currents(
                    &[current_a, aux_a],
                    &[speed_rpm, current_a.abs()],
                    &mut host,
                );
                let generated = all_input_terms::source_currents_a(
                    &[current_a as f32, aux_a as f32],
                    &[speed_rpm as f32, current_a.abs() as f32],
                );
                for (k, (h, g)) in host.iter().zip(&generated).enumerate() {
                    let scale = model.drives.get(k).map_or(1.0, |d| d.scale);
                    let (want_w, got_w) = (h * h, scale * f64::from(*g).powi(2));
                    assert!(
                        (want_w - got_w).abs() <= 1e-5 * want_w.max(1.0),
                        "{} at {current_a} A, {aux_a} A, {speed_rpm} rpm: host {want_w} vs generated {got_w} (per unit of R)",
                        all_input_terms::CURRENT_NAMES[k]
                    );
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 4 * 3 * 5 * all_input_terms::CURRENTS);
}

#[test]
fn the_firmware_crates_carry_what_codegen_makes_of_their_models() {
    for krate in ["rtic-stm32f4", "embassy-stm32f4"] {
        let dir = root().join("examples").join(krate);
        let out = cargo_bin_cmd!("coil-thermal")
            .arg("codegen")
            .arg("--model")
            .arg(dir.join("model.toml"))
            .args(["--out", "-"])
            .assert()
            .success();
        assert_eq!(
            String::from_utf8_lossy(&out.get_output().stdout),
            read(&dir.join("src/model.rs")),
            "examples/{krate}/src/model.rs is not what codegen makes of its model.toml: regenerate it"
        );
    }
}

/// A winding split into slot (2 kJ/K) and overhang (1 kJ/K), a housing
/// thermocouple; `SLOT_SCALE` and `OVERHANG_SCALE` stand for what each
/// test puts after the sources.
const SPLIT_WINDING: &str = r#"
name = "split-winding"
[[node]]
name = "slot"
capacity_j_per_k = 2000.0
critical_c = 155.0
[[node]]
name = "overhang"
capacity_j_per_k = 1000.0
critical_c = 155.0
[[node]]
name = "housing"
capacity_j_per_k = 900.0
[[boundary]]
name = "ambient"
value_c = 20.0
[[conductance]]
between = ["slot", "overhang"]
g_w_per_k = 8.0
[[conductance]]
between = ["slot", "housing"]
g_w_per_k = 20.0
[[conductance]]
between = ["housing", "ambient"]
g_w_per_k = 1.0
[[source]]
name = "slot"
node = "slot"
input = "current"
r0_ohm = 0.01
alpha_per_k = 0.0039
SLOT_SCALE[[source]]
name = "overhang"
node = "overhang"
input = "current"
r0_ohm = 0.01
alpha_per_k = 0.0039
OVERHANG_SCALE"#;

/// `codegen` of model `text` (written as `name`) with the housing sensor:
/// the module's text, less the header lines that name the file.
fn generate(dir: &Path, name: &str, text: String) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    let out = cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(&path)
        .args(["--sensor", "housing", "--out", "-"])
        .assert()
        .success();
    String::from_utf8(out.get_output().stdout.clone())
        .unwrap()
        .lines()
        .filter(|l| !l.contains(name))
        .collect::<Vec<_>>()
        .join("\n")
}

/// A `[[conductor]]` reaches the firmware as the scales it stands for:
/// codegen of a winding split into slot (2 kJ/K) and overhang (1 kJ/K)
/// with one conductor of scale 1.5 writes the same module as the same
/// file with each source's scale written out (1.0 and 0.5).
#[test]
fn a_conductor_generates_the_firmware_of_its_explicit_scales() {
    let tmp = tempfile::TempDir::new().unwrap();
    let conductor = generate(
        tmp.path(),
        "conductor.toml",
        SPLIT_WINDING.replace("SLOT_SCALE", "").replace(
            "OVERHANG_SCALE",
            "[[conductor]]\nname = \"winding\"\nsources = [\"slot\", \"overhang\"]\nscale = 1.5\n",
        ),
    );
    let explicit = generate(
        tmp.path(),
        "explicit.toml",
        SPLIT_WINDING
            .replace("SLOT_SCALE", "scale = 1.0\n")
            .replace("OVERHANG_SCALE", "scale = 0.5\n"),
    );
    assert_eq!(conductor, explicit);
    assert!(conductor.contains("from_parts"), "{conductor}");
}

/// `[observer] bias_sources` reaches the firmware's tables: naming every
/// source writes the module of the default (every source biased), naming
/// the slot alone a different one.
#[test]
fn bias_sources_reach_the_generated_tables() {
    let tmp = tempfile::TempDir::new().unwrap();
    let with = |name: &str, observer: &str| {
        generate(
            tmp.path(),
            name,
            SPLIT_WINDING
                .replace("SLOT_SCALE", "")
                .replace("OVERHANG_SCALE", observer),
        )
    };
    let default = with("default.toml", "");
    let both = with(
        "both.toml",
        "[observer]\nbias_sources = [\"slot\", \"overhang\"]\n",
    );
    let slot = with("slot.toml", "[observer]\nbias_sources = [\"slot\"]\n");
    assert_eq!(both, default);
    assert_ne!(slot, default);
}
