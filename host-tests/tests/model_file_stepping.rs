//! Model files stepped by the host's plant: a description read at run time
//! round-trips through the library's network, the solenoid's model file
//! steps like the library's own network, and a model file matches an
//! independent hand-written Euler loop of the published HUST equations.

use coil_thermal::{
    ExplicitStepper, InputLimits, Network, NetworkState, Resistance, SolenoidParams,
};
use coil_thermal_host::dynamic_network::DynNetwork;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sim::{simulate, Drive, FilePlant, Plant};
use coil_thermal_host::synth::Rng;

fn wide_limits() -> InputLimits {
    InputLimits {
        max_current_a: 1e6,
        min_temp_c: -1e6,
        max_temp_c: 1e6,
    }
}

/// A random connected network of 4 nodes, 2 boundaries, 3 sources, with
/// parallel conductances and fixed powers.
fn random_network(rng: &mut Rng) -> DynNetwork {
    let caps = (0..4).map(|_| 5.0 + 50.0 * rng.uniform()).collect();
    let mut net = DynNetwork::new(caps, 2).unwrap();
    for (a, b) in [(0, 1), (1, 2), (2, 3), (3, 0), (1, 0), (0, 2)] {
        net.connect(a, b, 0.1 + 2.0 * rng.uniform()).unwrap();
    }
    net.connect_boundary(0, 0, 0.5 + rng.uniform()).unwrap();
    net.connect_boundary(3, 1, 0.5 + rng.uniform()).unwrap();
    net.connect_boundary(3, 1, 0.2).unwrap();
    for node in [0, 2, 2] {
        let r = Resistance::with_alpha(0.5 + rng.uniform(), 0.0039, 20.0);
        net.joule_source(node, r).unwrap();
    }
    net.fixed_power(1, 3.0 * rng.uniform()).unwrap();
    net
}

/// A network description read at run time and the library's const
/// network built from it describe the same network: back to a description,
/// the same pairs, links, sources and fixed powers.
#[test]
fn a_description_survives_the_round_trip_through_the_library_network() {
    let mut rng = Rng::new(7);
    for _ in 0..20 {
        let dyn_net = random_network(&mut rng);
        let lib: Network<4, 2, 3> = dyn_net.to_network().unwrap();
        let back = DynNetwork::from_network(&lib).unwrap();
        assert_eq!(back.pairs(), dyn_net.pairs());
        assert_eq!(back.links(), dyn_net.links());
        assert_eq!(back.sources(), dyn_net.sources());
        assert_eq!(back.fixed_powers_w(), dyn_net.fixed_powers_w());
        assert_eq!(back.capacities_j_per_k(), dyn_net.capacities_j_per_k());
    }
}

#[test]
fn solenoid_model_file_runs_exactly_like_the_library_network() {
    let params = SolenoidParams::HESE;
    let lib = params.network::<30>().unwrap();
    // Through the TOML text, to cover the writer and the reader too.
    let text = ModelFile::solenoid(&params, 30).unwrap().to_toml().unwrap();
    let file = ModelFile::parse(&text, "solenoid.toml").unwrap();
    let model = Model::build(&file).unwrap();
    assert_eq!(model.nodes.len(), 30);
    assert_eq!(model.inputs.len(), 1, "one series current");
    let dt = 0.5;
    let mut plant = FilePlant::new(model).unwrap();
    assert_eq!(plant.substeps(dt), 1);
    let stepper = ExplicitStepper::<f64, 30, 1, 30>::new(&lib, dt, wide_limits()).unwrap();
    let mut state = NetworkState::<f64, 30, 1, 30>::uniform(16.0);
    plant.reset(&[16.0; 30]);
    for k in 0..2000 {
        let i = if k < 1500 { 6.0 } else { 0.0 };
        stepper.step(&mut state, &SolenoidParams::series_currents(i), &[16.0]);
        plant.step(dt, &[i], &[16.0], &[]);
        assert_close(plant.temps_c(), &state.temps_c, k);
    }
}

#[test]
fn hust_model_file_matches_a_hand_written_euler_loop() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/models/hust-ipmsm-3node.toml");
    let file = ModelFile::load(std::path::Path::new(path)).unwrap();
    let mut plant = FilePlant::new(Model::build(&file).unwrap()).unwrap();
    let n = 3000;
    let mut rng = Rng::new(11);
    let time_s: Vec<f64> = (0..n).map(|k| k as f64).collect();
    let current: Vec<f64> = (0..n)
        .map(|k| {
            if (k / 400) % 2 == 0 {
                250.0 + 20.0 * rng.normal()
            } else {
                10.0
            }
        })
        .collect();
    let speed: Vec<f64> = (0..n).map(|k| 4000.0 * (k as f64 / n as f64)).collect();
    let coolant: Vec<f64> = (0..n).map(|k| 25.0 + 0.001 * k as f64).collect();
    let drive = Drive {
        time_s,
        currents: vec![current.clone()],
        boundaries: vec![coolant.clone()],
        signals: vec![speed.clone()],
    };
    let out = simulate(&mut plant, &drive, &[30.0, 28.0, 26.0]);
    // The published baseline, written out: explicit Euler at 1 s.
    let (cw, cs, cr) = (3716.15, 5616.32, 5329.69);
    let (g_ws, g_sc, g_sr) = (1.0 / 0.01375, 1.0 / 0.01879, 20.0);
    let (mut tw, mut ts, mut tr) = (30.0, 28.0, 26.0);
    let mut hottest: f64 = tw;
    for k in 0..n - 1 {
        let f = speed[k] / 4000.0;
        let p = 1.5
            * 4.67e-3
            * current[k].powi(2)
            * (1.0 + 0.0039 * (tw - 20.0))
            * (1.0 + 0.02174 * f + 0.3874 * f * f);
        let q_ws = g_ws * (tw - ts);
        let q_sc = g_sc * (ts - coolant[k]);
        let q_sr = g_sr * (ts - tr);
        tw += (p - q_ws) / cw;
        ts += (q_ws - q_sc - q_sr) / cs;
        tr += q_sr / cr;
        hottest = hottest.max(tw);
        let got = &out[k + 1];
        for (a, b) in got.iter().zip([tw, ts, tr]) {
            assert!(
                (a - b).abs() < 1e-9,
                "row {}: {got:?} vs {:?}",
                k + 1,
                [tw, ts, tr]
            );
        }
    }
    assert!(hottest > 40.0, "the winding heats: {hottest}");
}

/// Two library runs of the same network at different padded sizes: equal
/// up to the f64 rounding level (a few ulp of a temperature).
fn assert_close(dynamic: &[f64], library: &[f64], step: usize) {
    for (node, (d, l)) in dynamic.iter().zip(library).enumerate() {
        assert!(
            (d - l).abs() <= 1e-11 * l.abs().max(1.0),
            "step {step} node {node}: {d} vs {l}"
        );
    }
}
