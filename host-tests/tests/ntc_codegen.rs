//! `codegen` of a model file with an NTC on the ADC
//! (`host-tests/models/drive-3node-ntc.toml`): it reproduces
//! `examples/generated/drive_3node_ntc.rs` (what `examples/ntc_qemu.rs`
//! flashes), whose `convert_counts` is the library's conversion of the
//! file's divider at every 12-bit count, checked against the NTC's beta
//! equation written out here; a resistance sensor is refused by name.

use std::path::PathBuf;

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::sensors::SensorFault;
use tempfile::TempDir;

#[path = "../../examples/generated/drive_3node_ntc.rs"]
mod model;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_generated_conversion_is_the_ntc_through_its_divider() {
    let mut worst_k: f64 = 0.0;
    for counts in 0..4096u32 {
        let got = model::convert_counts(0, counts).unwrap();
        match counts {
            0 => assert_eq!(got, Err(SensorFault::ShortToGnd)),
            4095 => assert_eq!(got, Err(SensorFault::OpenCircuit)),
            _ => {
                // The divider and the beta equation, in f64.
                let r = 10_000.0 * f64::from(counts) / f64::from(4096 - counts);
                let t = 1.0 / (1.0 / 298.15 + (r / 10_000.0).ln() / 3950.0) - 273.15;
                match got {
                    Ok(reading) => worst_k = worst_k.max((f64::from(reading.temp_c) - t).abs()),
                    Err(fault) => {
                        assert_eq!(fault, SensorFault::OutOfRange);
                        assert!(!(-55.0..=150.0).contains(&t), "{counts}: {t}");
                    }
                }
            }
        }
    }
    assert!(worst_k < 1e-3, "{worst_k}");
    assert_eq!(model::convert_counts(1, 2048), None);
}

#[test]
fn codegen_reproduces_the_ntc_module() {
    let dir = TempDir::new().unwrap();
    let generated = dir.path().join("model.rs");
    let models = root().join("host-tests/models");
    cargo_bin_cmd!("coil-thermal")
        .arg("codegen")
        .arg("--model")
        .arg(models.join("drive-3node-ntc.toml"))
        .arg("--out")
        .arg(&generated)
        .assert()
        .success();
    assert_eq!(
        std::fs::read_to_string(&generated).unwrap(),
        std::fs::read_to_string(root().join("examples/generated/drive_3node_ntc.rs")).unwrap(),
        "codegen no longer reproduces examples/generated/drive_3node_ntc.rs"
    );
}
