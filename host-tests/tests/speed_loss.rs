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

/// The replay's library observer gets a speed-dependent model as effective
/// currents folded on the host (`library_observer` module docs): a speed
/// loss, and a winding whose power has a scale and a speed factor, driven
/// at 300 A (three times the observer's 100 A plausibility limit, which the
/// host's current scaling keeps clear of). The steady state is the
/// boundary plus the power over the conductance.
#[test]
fn the_library_observer_runs_speed_losses_and_large_currents_as_effective_currents() {
    use coil_thermal_host::library_observer::ObserverEstimator;
    use coil_thermal_host::observer::Estimator;
    let text = format!(
        "{ONE_NODE}
[[source]]
node = \"stator\"
input = \"current\"
column = \"current\"
r0_ohm = 0.001
alpha_per_k = 0.0
t_ref_c = 20.0
scale = 0.5
[source.speed]
column = \"speed\"
reference = 4000.0
a1 = 0.2
a2 = 0.1
"
    );
    let model = Model::build(&ModelFile::parse(&text, "motor.toml").unwrap()).unwrap();
    // 0.1 s ticks: 20 time constants of 50 s in 10 000 ticks.
    let mut observer = ObserverEstimator::new(model, 100_000).unwrap();
    observer.reset(&[20.0]);
    for _ in 0..1000 {
        observer.predict(1.0, &[300.0], &[20.0], &[2000.0]);
    }
    // f = 0.5: loss 27.5 W; winding 0.5 * 1 mOhm * 300^2 * (1 + 0.1 +
    // 0.025) = 50.625 W; 78.125 W over 10 W/K.
    let t = observer.estimate_c()[0];
    assert!((t - 27.8125).abs() < 2e-3, "{t}");
    let ticks = observer.take_tick_times_ns().unwrap();
    assert_eq!(ticks.len(), 10_000);
}
