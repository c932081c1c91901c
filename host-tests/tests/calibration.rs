//! Calibration recovers known parameters from noisy synthetic traces.
//!
//! Traces are made from the example models with their file values (the
//! truth), plus seeded Gaussian noise on the measured temperatures; the fit
//! starts from values off by 30-60 % and must land within the stated
//! tolerances.

use std::path::Path;

use coil_thermal_host::calibrate::{access_param, fit, FitData, FitOptions, ParamSpec};
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::observer::Sensor;
use coil_thermal_host::sim::{by_node, initial_temps, simulate, Drive, FilePlant, Plant};
use coil_thermal_host::synth::{noisy, steps, Rng};

fn model(name: &str) -> ModelFile {
    let path = format!("{}/models/{name}", env!("CARGO_MANIFEST_DIR"));
    ModelFile::load(Path::new(&path)).unwrap()
}

/// Simulates `truth` over `drive` and returns noisy sensors on `nodes`.
fn recording(
    truth: &ModelFile,
    drive: &Drive,
    nodes: &[&str],
    sigma: f64,
    rng: &mut Rng,
) -> Vec<Sensor> {
    let model = Model::build(truth).unwrap();
    let mut plant = FilePlant::new(model.clone()).unwrap();
    let info = plant.info().clone();
    let init = initial_temps(&info, drive, &[]).unwrap();
    let states = by_node(&simulate(&mut plant, drive, &init));
    nodes
        .iter()
        .map(|n| {
            let node = model.node_index(n).unwrap();
            Sensor {
                column: n.to_string(),
                node,
                values_c: noisy(&states[node], sigma, rng),
            }
        })
        .collect()
}

fn two_node_drive(segments: &[(f64, f64)]) -> Drive {
    let (time_s, current) = steps(segments, 1.0);
    let n = time_s.len();
    Drive {
        time_s,
        currents: vec![current],
        boundaries: vec![vec![20.0; n]],
        signals: vec![],
    }
}

#[test]
fn two_node_coil_parameters_are_recovered_from_two_noisy_traces() {
    let truth = model("two-node-coil.toml");
    let mut rng = Rng::new(2024);
    let drives = [
        two_node_drive(&[(600.0, 2.0), (600.0, 1.0), (900.0, 0.0)]),
        two_node_drive(&[(300.0, 3.0), (900.0, 0.0), (900.0, 1.5)]),
    ];
    let data: Vec<FitData> = drives
        .iter()
        .enumerate()
        .map(|(i, d)| FitData {
            label: format!("trace {i}"),
            drive: d.clone(),
            targets: recording(&truth, d, &["coil", "housing"], 0.05, &mut rng),
            init: Vec::new(),
        })
        .collect();
    // The resistance is known (measured); capacities and conductances are
    // not. (With r0 free too, only ratios would be identifiable.)
    let names = [
        ("capacity.coil", 1.5),
        ("capacity.housing", 0.6),
        ("conductance.coil-housing", 1.6),
        ("conductance.housing-air.h_w_per_m2k", 0.7),
    ];
    let mut start = truth.clone();
    let mut want = Vec::new();
    for (name, factor) in names {
        let v = access_param(&mut start, name, None).unwrap();
        want.push(v);
        access_param(&mut start, name, Some(v * factor)).unwrap();
    }
    let params: Vec<ParamSpec> = names
        .iter()
        .map(|(n, _)| ParamSpec::parse(n).unwrap())
        .collect();
    let (fitted, report) = fit(&start, &params, &data, &FitOptions::default()).unwrap();
    eprintln!("{report:#?}");
    for (p, w) in report.params.iter().zip(&want) {
        let rel = (p.fitted - w).abs() / w;
        // Stated tolerance: 2 % with 0.05 K noise on 2 x 2100 samples.
        assert!(
            rel < 0.02,
            "{}: fitted {} vs true {w} ({:.2} %)",
            p.name,
            p.fitted,
            100.0 * rel
        );
        assert!(!p.at_bound);
        // White noise: the Jacobian's standard error is honest, the error
        // within 4 of them, and each small (under 1 % of the value).
        let se = p.std_error.expect("a free parameter has a standard error");
        assert!(se > 0.0 && se < 0.01 * w, "{}: se {se}", p.name);
        assert!(
            (p.fitted - w).abs() < 4.0 * se,
            "{}: {} vs {w}, se {se}",
            p.name,
            p.fitted
        );
    }
    for (i, row) in report.correlations.iter().enumerate() {
        assert!((row[i].unwrap() - 1.0).abs() < 1e-9);
        assert!(row.iter().all(|c| c.unwrap().abs() <= 1.0 + 1e-9));
    }
    for t in &report.traces {
        // The residual is the noise: RMSE close to sigma = 0.05 K.
        assert!(t.rmse_after_k < 0.06, "{}: {}", t.trace, t.rmse_after_k);
        assert!(
            t.rmse_before_k > 1.0,
            "the start was really off: {}",
            t.rmse_before_k
        );
    }
    // The fitted file is valid and carries the fitted numbers.
    let reread = ModelFile::parse(&fitted.to_toml().unwrap(), "fitted.toml").unwrap();
    let mut reread_mut = reread.clone();
    let c = access_param(&mut reread_mut, "capacity.coil", None).unwrap();
    assert_eq!(c, report.params[0].fitted);
    // The form of the conductance is kept (h and area, not a bare g).
    let air = reread
        .conductances
        .iter()
        .find(|c| c.key() == "housing-air")
        .unwrap();
    assert!(air.h_w_per_m2k.is_some() && air.g_w_per_k.is_none());
}

#[test]
fn speed_dependent_loss_coefficients_are_recovered() {
    // The HUST network with its published numbers as truth; fit the speed
    // polynomial and the winding-stator conductance from the winding and
    // stator temperatures.
    let truth = model("hust-ipmsm-3node.toml");
    let mut rng = Rng::new(99);
    let n = 4000;
    let time_s: Vec<f64> = (0..n).map(|k| k as f64).collect();
    let current: Vec<f64> = (0..n)
        .map(|k| if (k / 500) % 2 == 0 { 220.0 } else { 60.0 })
        .collect();
    let speed: Vec<f64> = (0..n)
        .map(|k| [500.0, 2000.0, 4000.0, 3000.0][(k / 700) % 4])
        .collect();
    let drive = Drive {
        time_s,
        currents: vec![current],
        boundaries: vec![vec![25.0; n]],
        signals: vec![speed],
    };
    let data = vec![FitData {
        label: "synthetic".into(),
        targets: recording(&truth, &drive, &["winding", "stator"], 0.05, &mut rng),
        init: Vec::new(),
        drive,
    }];
    let names = [
        ("source.winding.speed_a1", 0.1),
        ("source.winding.speed_a2", 0.2),
        ("conductance.winding-stator", 1.0 / 0.01375 * 1.4),
    ];
    let mut start = truth.clone();
    let mut want = Vec::new();
    for (name, v) in names {
        want.push(access_param(&mut start, name, None).unwrap());
        access_param(&mut start, name, Some(v)).unwrap();
    }
    let params = [
        ParamSpec::parse("source.winding.speed_a1=-1:2").unwrap(),
        ParamSpec::parse("source.winding.speed_a2=0:2").unwrap(),
        ParamSpec::parse("conductance.winding-stator").unwrap(),
    ];
    let (_, report) = fit(&start, &params, &data, &FitOptions::default()).unwrap();
    eprintln!("{report:#?}");
    let got: Vec<f64> = report.params.iter().map(|p| p.fitted).collect();
    // Stated tolerances: a1 within 0.02 absolute (true 0.02174), a2 within
    // 2 % (true 0.3874), the conductance within 1 %.
    assert!(
        (got[0] - want[0]).abs() < 0.02,
        "a1 {} vs {}",
        got[0],
        want[0]
    );
    assert!(
        (got[1] - want[1]).abs() < 0.02 * want[1],
        "a2 {} vs {}",
        got[1],
        want[1]
    );
    assert!(
        (got[2] - want[2]).abs() < 0.01 * want[2],
        "g {} vs {}",
        got[2],
        want[2]
    );
}

#[test]
fn parameter_names_and_bounds_are_checked() {
    let mut file = model("two-node-coil.toml");
    assert!(access_param(&mut file, "capacity.nope", None)
        .unwrap_err()
        .to_string()
        .contains("coil, housing"));
    assert!(access_param(&mut file, "source.coil.slope_ohm_per_k", None).is_err());
    assert!(access_param(&mut file, "wattage.coil", None).is_err());
    assert_eq!(
        access_param(&mut file, "conductance.housing-air", None).unwrap(),
        0.5
    );
    let p = ParamSpec::parse("capacity.coil=10:1000").unwrap();
    assert_eq!((p.lo, p.hi), (Some(10.0), Some(1000.0)));
    assert!(ParamSpec::parse("capacity.coil=abc:1").is_err());
    // A start outside its bounds is refused with the parameter's name.
    let drive = two_node_drive(&[(10.0, 1.0)]);
    let data = vec![FitData {
        label: "t".into(),
        targets: recording(&file, &drive, &["coil"], 0.0, &mut Rng::new(1)),
        init: Vec::new(),
        drive,
    }];
    let bad = [ParamSpec::parse("capacity.coil=300:400").unwrap()];
    let err = fit(&file, &bad, &data, &FitOptions::default()).unwrap_err();
    assert!(err.to_string().contains("capacity.coil"), "{err}");
}
