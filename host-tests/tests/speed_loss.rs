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
    // Turning backwards loses as much: f = |speed| / reference (a signed f
    // would make the linear term negative and read 1.5 K cold here).
    assert!((steady_c(&file, -2000.0) - 22.75).abs() < 1e-9);
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
    assert_eq!(ticks.count(), 10_000);
}

/// Two nodes cooled apart, sharing one `[[loss]]` (current x speed
/// polynomial) by a split polynomial; the second conductance varies with
/// speed by `[conductance.speed]`.
const SPLIT: &str = r#"
name = "split"
[[node]]
name = "stator"
capacity_j_per_k = 400.0
[[node]]
name = "rotor"
capacity_j_per_k = 300.0
[[boundary]]
name = "coolant"
value_c = 20.0
[[conductance]]
between = ["stator", "coolant"]
g_w_per_k = 10.0
[[conductance]]
between = ["rotor", "coolant"]
r_k_per_w = 0.05
[conductance.speed]
column = "speed"
reference = 4000.0
a1 = 0.5
r_exp_k_per_w = 0.2
exp_rate = 1.5
[[loss]]
name = "rest"
nodes = ["stator", "rotor"]
current = { column = "current", reference = 100.0 }
speed = { column = "speed", reference = 4000.0 }
power = [{ c = 20.0, f = 1 }, { c = 100.0, i = 1, f = 1 }, { c = 5.0, i = 2 }]
split = [{ c = 0.9 }, { c = -0.2, f = 1 }, { c = -0.1, i = 1, f = 1 }]
"#;

/// Steady temperatures \[degC\] of every node at constant signals
/// (`current`, `speed`), from the model file run by the tool.
fn steady_split(src: &str, current: f64, speed: f64) -> Vec<f64> {
    let file = ModelFile::parse(src, "split.toml").unwrap();
    let model = Model::build(&file).unwrap();
    // The conductance names `speed` first, the loss adds `current`.
    assert_eq!(model.signals, ["speed", "current"]);
    let mut plant = FilePlant::new(model).unwrap();
    let rows = 20_000;
    let drive = Drive {
        time_s: (0..rows).map(|k| k as f64).collect(),
        currents: vec![],
        boundaries: vec![vec![20.0; rows]],
        signals: vec![vec![speed; rows], vec![current; rows]],
    };
    simulate(&mut plant, &drive, &[20.0, 20.0])
        .last()
        .unwrap()
        .clone()
}

#[test]
fn loss_polynomial_split_and_speed_dependent_conductance_reach_their_analytic_steady_state() {
    for (current, speed) in [
        (0.0_f64, 0.0_f64),
        (50.0, 1000.0),
        (100.0, 4000.0),
        (180.0, 3000.0),
        // A negative current or speed (a d/q component, turning backwards)
        // by its magnitude: the losses and the rotor's convection as forwards.
        (-180.0, -3000.0),
        (50.0, -1000.0),
    ] {
        let (i, f) = (current.abs() / 100.0, speed.abs() / 4000.0);
        let p = 20.0 * f + 100.0 * i * f + 5.0 * i * i;
        let a = (0.9 - 0.2 * f - 0.1 * i * f).clamp(0.0, 1.0);
        let g_rotor = (1.0 + 0.5 * f) / (0.05 + 0.2 * (-1.5 * f).exp());
        let t = steady_split(SPLIT, current, speed);
        let want = [20.0 + a * p / 10.0, 20.0 + (1.0 - a) * p / g_rotor];
        for (got, want) in t.iter().zip(want) {
            assert!(
                (got - want).abs() < 1e-6,
                "{current} A {speed} rpm: {got} vs {want}"
            );
        }
    }
    // The split is clipped to [0, 1]: at i = 10 and f = 1 the polynomial is
    // 0.9 - 0.2 - 1.0 < 0, so the rotor takes all of the loss.
    let t = steady_split(SPLIT, 1000.0, 4000.0);
    assert!((t[0] - 20.0).abs() < 1e-9, "{t:?}");
    assert!(t[1] > 100.0);
}

#[test]
fn ill_formed_losses_and_speed_laws_are_refused_with_the_entry_named() {
    let cases = [
        (
            "split = [{ c = 0.9 }, { c = -0.2, f = 1 }, { c = -0.1, i = 1, f = 1 }]",
            "",
            "two nodes need",
        ),
        (
            "{ c = 5.0, i = 2 }]",
            "{ c = 5.0, i = 5 }]",
            "powers above 4",
        ),
        (
            "current = { column = \"current\", reference = 100.0 }\n",
            "",
            "uses i but the loss has no `current`",
        ),
        (
            "reference = 100.0",
            "reference = 0.0",
            "current.reference must be finite and > 0",
        ),
        (
            "r_exp_k_per_w = 0.2",
            "r_exp_k_per_w = -0.2",
            "r_exp_k_per_w must be finite and >= 0",
        ),
        (
            "nodes = [\"stator\", \"rotor\"]",
            "nodes = [\"stator\", \"stator\"]",
            "must differ",
        ),
    ];
    for (from, to, want) in cases {
        let mut src = SPLIT.replace(from, to);
        if want == "two nodes need" {
            src = src.replace("\n\n", "\n");
        }
        let err = ModelFile::parse(&src, "bad.toml").unwrap_err().to_string();
        assert!(err.contains(want), "{want}: {err}");
        assert!(err.starts_with("bad.toml:"), "{err}");
    }
}

/// `input_hold = "end"`: a step uses the inputs of the row it ends at (an
/// explicit Euler of a logged trace); `start` (the default) those of the
/// row it starts at.
#[test]
fn input_hold_end_applies_the_next_rows_inputs() {
    let src = r#"
[[node]]
name = "n"
capacity_j_per_k = 100.0
[[boundary]]
name = "coolant"
value_c = 20.0
[[conductance]]
between = ["n", "coolant"]
g_w_per_k = 1.0
[[speed_loss]]
node = "n"
column = "speed"
reference = 1.0
p1_w = 1.0
"#;
    let drive = Drive {
        time_s: vec![0.0, 1.0, 2.0],
        currents: vec![],
        boundaries: vec![vec![20.0; 3]],
        signals: vec![vec![0.0, 50.0, 100.0]],
    };
    for (hold, first) in [("", 0.0), ("input_hold = \"end\"\n", 50.0)] {
        let file = ModelFile::parse(&format!("{hold}{src}"), "hold.toml").unwrap();
        let model = Model::build(&file).unwrap();
        let held = drive.clone().held(model.input_hold);
        let mut plant = FilePlant::new(model).unwrap();
        let t = simulate(&mut plant, &held, &[20.0]);
        // One explicit step of 1 s (h G / C = 0.01): T1 = 20 + P / C.
        assert!(
            (t[1][0] - (20.0 + first / 100.0)).abs() < 1e-12,
            "{hold}: {t:?}"
        );
    }
}

/// One winding lumped into a slot and an overhang node, insulated (1e-9
/// W/K to the coolant), both sources on one current with no scale yet.
const SLOT_AND_OVERHANG: &str = r#"
[[node]]
name = "slot"
capacity_j_per_k = 2000.0
[[node]]
name = "overhang"
capacity_j_per_k = 1000.0
[[boundary]]
name = "coolant"
value_c = 20.0
[[conductance]]
between = ["slot", "coolant"]
g_w_per_k = 1e-9
[[conductance]]
between = ["overhang", "coolant"]
g_w_per_k = 1e-9
[[source]]
name = "slot"
node = "slot"
input = "current"
r0_ohm = 0.01
[[source]]
name = "overhang"
node = "overhang"
input = "current"
r0_ohm = 0.01
"#;

/// `scale_per_kj`: a source's power scale follows its node's capacity, and
/// a tied calibration name moves every source of one conductor at once.
#[test]
fn copper_loss_density_scales_with_capacity_and_ties_in_calibration() {
    let src = SLOT_AND_OVERHANG.replace("r0_ohm = 0.01\n", "r0_ohm = 0.01\nscale_per_kj = 0.5\n");
    let mut file = ModelFile::parse(&src, "density.toml").unwrap();
    let model = Model::build(&file).unwrap();
    // k = 0.5 per kJ/K: 1.0 on 2 kJ/K, 0.5 on 1 kJ/K.
    assert_eq!(model.drives[0].scale, 1.0);
    assert_eq!(model.drives[1].scale, 0.5);
    let tied = "source.slot.scale_per_kj|source.overhang.scale_per_kj";
    assert_eq!(access_param(&mut file, tied, Some(0.8)).unwrap(), 0.5);
    assert_eq!(file.sources[1].scale_per_kj, Some(0.8));
    let both = src.replace("scale_per_kj = 0.5\n", "scale_per_kj = 0.5\nscale = 1.0\n");
    let err = ModelFile::parse(&both, "both.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("scale or scale_per_kj"), "{err}");
}

/// `[[conductor]]`: one winding lumped into two nodes dissipates the
/// electrical `scale R I^2` in all, whatever capacities a fit gives its
/// nodes, and both parts heat at one loss density. Checked by energy: with
/// the nodes insulated, `sum C dT` over a run equals `scale R I^2 t`.
#[test]
fn a_conductor_dissipates_its_electrical_loss_shared_by_capacity() {
    let src = format!(
        "{SLOT_AND_OVERHANG}[[conductor]]\nname = \"winding\"\nsources = [\"slot\", \"overhang\"]\nscale = 1.5\n"
    );
    let current_a = 20.0;
    let seconds = 600;
    let run = |file: &ModelFile| -> Vec<f64> {
        let mut plant = FilePlant::new(Model::build(file).unwrap()).unwrap();
        let rows = seconds + 1;
        let drive = Drive {
            time_s: (0..rows).map(|k| k as f64).collect(),
            currents: vec![vec![current_a; rows]],
            boundaries: vec![vec![20.0; rows]],
            signals: vec![],
        };
        simulate(&mut plant, &drive, &[20.0, 20.0])
            .last()
            .unwrap()
            .clone()
    };
    let joule_j = 1.5 * 0.01 * current_a * current_a * seconds as f64;
    let mut file = ModelFile::parse(&src, "conductor.toml").unwrap();
    for capacities in [[2000.0, 1000.0], [5000.0, 300.0]] {
        access_param(&mut file, "capacity.slot", Some(capacities[0])).unwrap();
        access_param(&mut file, "capacity.overhang", Some(capacities[1])).unwrap();
        let model = Model::build(&file).unwrap();
        let total = capacities[0] + capacities[1];
        assert!((model.drives[0].scale - 1.5 * capacities[0] / total).abs() < 1e-12);
        assert!((model.drives[1].scale - 1.5 * capacities[1] / total).abs() < 1e-12);
        let end = run(&file);
        let stored_j: f64 = capacities
            .iter()
            .zip(&end)
            .map(|(c, t)| c * (t - 20.0))
            .sum();
        assert!(
            (stored_j / joule_j - 1.0).abs() < 1e-6,
            "{stored_j} J against {joule_j} J"
        );
        // One loss density: both parts rise alike.
        assert!((end[0] - end[1]).abs() < 1e-9, "{end:?}");
    }
    // The conductor's scale is a calibration name.
    assert_eq!(
        access_param(&mut file, "conductor.winding.scale", Some(1.2)).unwrap(),
        1.5
    );
    assert_eq!(file.conductors[0].scale, 1.2);
    let round = ModelFile::parse(&file.to_toml().unwrap(), "round.toml").unwrap();
    assert_eq!(round, file);
    // Ill-formed conductors are refused with the conductor named.
    for (bad, says) in [
        (
            src.replace(
                "r0_ohm = 0.01\n[[source]]",
                "r0_ohm = 0.01\nscale = 1.0\n[[source]]",
            ),
            "give neither scale nor scale_per_kj",
        ),
        (
            src.replace(
                "[\"slot\", \"overhang\"]\nscale",
                "[\"slot\", \"rotor\"]\nscale",
            ),
            "no source `rotor`",
        ),
        (
            src.replace(
                "[\"slot\", \"overhang\"]\nscale",
                "[\"slot\", \"slot\"]\nscale",
            ),
            "already in a conductor",
        ),
        (
            src.replace("scale = 1.5", "scale = -1.5"),
            "finite and >= 0",
        ),
        (
            src.replace("[\"slot\", \"overhang\"]\nscale", "[]\nscale"),
            "give its sources",
        ),
    ] {
        let err = ModelFile::parse(&bad, "bad.toml").unwrap_err().to_string();
        assert!(
            err.contains(says) && err.contains("winding"),
            "{says}: {err}"
        );
    }
}

/// The observers that hold one fixed network refuse a model whose
/// conductances change with speed, saying why and what runs it.
#[test]
fn fixed_network_observers_refuse_speed_dependent_conductances() {
    use coil_thermal_host::library_observer::ObserverEstimator;
    let model = Model::build(&ModelFile::parse(SPLIT, "split.toml").unwrap()).unwrap();
    assert!(model.has_varying_conductances());
    let err = ObserverEstimator::new(model.clone(), 1000)
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("speed-dependent conductances"), "{err}");
    assert!(err.contains("open loop"), "{err}");
    let plain = Model::build(&ModelFile::parse(ONE_NODE, "one.toml").unwrap()).unwrap();
    assert!(!plain.has_varying_conductances());
    assert!(plain.require_fixed_network("x").is_ok());
}
