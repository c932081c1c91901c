//! `[[speed_loss]]`: a speed-only loss `p1 f + p2 f^2` at a node.

use std::path::Path;

use coil_thermal_host::calibrate::access_param;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sim::{simulate, Drive, FilePlant};

const ONE_NODE: &str = r#"
name = "iron"
[[node]]
name = "stator"
capacity_j_per_k = 500.0
[[boundary]]
name = "coolant"
value_c = 20.0
[[conductance]]
between = ["stator", "coolant"]
g_w_per_k = 10.0
[[speed_loss]]
node = "stator"
column = "speed"
reference = 4000.0
p1_w = 30.0
p2_w = 50.0
"#;

fn steady_c(file: &ModelFile, speed: f64) -> f64 {
    let mut plant = FilePlant::new(Model::build(file).unwrap()).unwrap();
    let rows = 20_000;
    let drive = Drive {
        time_s: (0..rows).map(|k| k as f64).collect(),
        currents: vec![],
        boundaries: vec![vec![20.0; rows]],
        signals: vec![vec![speed; rows]],
    };
    *simulate(&mut plant, &drive, &[20.0])
        .last()
        .unwrap()
        .first()
        .unwrap()
}

#[test]
fn steady_state_is_boundary_plus_loss_over_conductance() {
    let file = ModelFile::parse(ONE_NODE, "one.toml").unwrap();
    // f = 0.5: P = 15 + 12.5 = 27.5 W over 10 W/K.
    assert!((steady_c(&file, 2000.0) - 22.75).abs() < 1e-9);
    // f = 1: 80 W.
    assert!((steady_c(&file, 4000.0) - 28.0).abs() < 1e-9);
    // Standstill: no loss; a negative polynomial is clamped to zero.
    assert!((steady_c(&file, 0.0) - 20.0).abs() < 1e-12);
    let mut neg = file.clone();
    access_param(&mut neg, "speed_loss.stator.p1_w", Some(-100.0)).unwrap();
    assert!((steady_c(&neg, 2000.0) - 20.0).abs() < 1e-12);
}

#[test]
fn calibration_names_round_trip_and_bad_files_are_refused() {
    let mut file = ModelFile::parse(ONE_NODE, "one.toml").unwrap();
    assert_eq!(
        access_param(&mut file, "speed_loss.stator.p2_w", Some(70.0)).unwrap(),
        50.0
    );
    let again = ModelFile::parse(&file.to_toml().unwrap(), "again.toml").unwrap();
    assert_eq!(again.speed_losses[0].p2_w, 70.0);
    assert!(access_param(&mut file, "speed_loss.stator.p3_w", None).is_err());
    assert!(access_param(&mut file, "speed_loss.rotor.p1_w", None).is_err());
    let bad_ref = ONE_NODE.replace("reference = 4000.0", "reference = 0.0");
    let e = ModelFile::parse(&bad_ref, "x.toml")
        .and_then(|f| Model::build(&f))
        .unwrap_err();
    assert!(format!("{e:#}").contains("reference"), "{e:#}");
    let bad_node = ONE_NODE.replace("node = \"stator\"\ncolumn", "node = \"rotor\"\ncolumn");
    let e = ModelFile::parse(&bad_node, "x.toml")
        .and_then(|f| Model::build(&f))
        .unwrap_err();
    assert!(format!("{e:#}").contains("unknown node"), "{e:#}");
    assert!(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/hust_motor.toml"
    ))
    .exists());
}
