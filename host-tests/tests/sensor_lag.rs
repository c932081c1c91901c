//! A sensor that lags its winding (issue 38, item 2): a thermistor in the
//! end turns reads the winding 30 s late. Read as the winding itself, the
//! observer takes the lag for a winding colder than its physics while it
//! heats (and refuses the reading) and for heat that is not there while
//! it cools; read as a
//! sensor node that lags the winding (`Network::connect_sensor`), the lag
//! is physics and the winding's estimate follows the truth.
//!
//! The plant is written here, not taken from the library: a winding
//! (60 J/K, `R(T) = 1.2 (1 + 0.00393 (T - 20))` ohm) in a housing
//! (400 J/K) on a heatsink (900 J/K) to a 22 degC ambient, and an ideal
//! first-order sensor `tau dT_s/dt = T_w - T_s` that draws no heat,
//! integrated by RK4 at 1 ms in `f64`.

use coil_thermal::observer::{
    NetworkInputs, NetworkObserver, NetworkObserverBuilder, SensorStatus, TimedReading,
};
use coil_thermal::{Network, Reading, Resistance};

const AMBIENT_C: f64 = 22.0;
const TAU_S: f64 = 30.0;
const C_W: f64 = 60.0;
const C_H: f64 = 400.0;
const C_S: f64 = 900.0;
const G_WH: f64 = 0.8;
const G_HS: f64 = 2.0;
const G_SA: f64 = 1.2;

fn resistance() -> Resistance {
    Resistance::with_alpha(1.2, 0.00393, 20.0)
}

/// Winding, housing, heatsink and the sensor \[degC\].
fn derivative(t: &[f64; 4], current_a: f64) -> [f64; 4] {
    let r = 1.2 * (1.0 + 0.00393 * (t[0] - 20.0));
    let q_wh = G_WH * (t[0] - t[1]);
    let q_hs = G_HS * (t[1] - t[2]);
    let q_sa = G_SA * (t[2] - AMBIENT_C);
    [
        (r * current_a * current_a - q_wh) / C_W,
        (q_wh - q_hs) / C_H,
        (q_hs - q_sa) / C_S,
        (t[0] - t[3]) / TAU_S,
    ]
}

fn rk4(t: &mut [f64; 4], current_a: f64, h: f64) {
    let add = |x: &[f64; 4], k: &[f64; 4], s: f64| core::array::from_fn(|n| x[n] + s * k[n]);
    let k1 = derivative(t, current_a);
    let k2 = derivative(&add(t, &k1, h / 2.0), current_a);
    let k3 = derivative(&add(t, &k2, h / 2.0), current_a);
    let k4 = derivative(&add(t, &k3, h), current_a);
    for n in 0..4 {
        t[n] += h / 6.0 * (k1[n] + 2.0 * k2[n] + 2.0 * k3[n] + k4[n]);
    }
}

/// The drive: 8 A for 10 min, off 5 min, 8 A again for 10 min \[A\].
fn current_at(t_s: f64) -> f64 {
    if t_s < 600.0 || (900.0..1500.0).contains(&t_s) {
        8.0
    } else {
        0.0
    }
}

#[derive(Debug, Default)]
struct Score {
    /// Largest truth above the winding's estimate \[K\].
    winding_cold_k: f64,
    /// Largest estimate above the truth \[K\].
    winding_hot_k: f64,
    /// Largest truth above the winding's published upper bound \[K\].
    winding_above_bound_k: f64,
    /// Readings not fused.
    refused: u32,
}

/// Runs the drive for 1800 s against `obs`, the thermistor's reading
/// (every 0.5 s, rounded to 0.1 K as a 12-bit NTC divider gives about
/// there) in its one slot; the winding is node 0.
fn run<const N: usize, const X: usize>(obs: &NetworkObserver<N, 1, 1, X, 1>) -> Score {
    let mut plant = [AMBIENT_C; 4];
    let mut state = obs.state(&[AMBIENT_C as f32; N], &[AMBIENT_C as f32]);
    let mut score = Score::default();
    for k in 0..1_800_000u32 {
        let t_s = f64::from(k) * 1e-3;
        let current_a = current_at(t_s);
        let now_us = k.wrapping_mul(1000);
        let read = k % 500 == 0;
        let readings = if read {
            let temp_c = ((plant[3] * 10.0).round() / 10.0) as f32;
            [Some(TimedReading {
                result: Ok(Reading::new(temp_c)),
                sampled_at_us: now_us,
            })]
        } else {
            [None]
        };
        let out = obs.tick(
            &mut state,
            &NetworkInputs {
                currents_a: [current_a as f32],
                boundary_c: [AMBIENT_C as f32],
                readings,
                now_us,
                elapsed_us: 1000,
            },
        );
        if read && !matches!(out.sensors[0], SensorStatus::Fused { .. }) {
            score.refused += 1;
        }
        let error = f64::from(out.temps_c[0]) - plant[0];
        score.winding_cold_k = score.winding_cold_k.max(-error);
        score.winding_hot_k = score.winding_hot_k.max(error);
        score.winding_above_bound_k = score
            .winding_above_bound_k
            .max(plant[0] - f64::from(out.upper_c[0]));
        rk4(&mut plant, current_a, 1e-3);
    }
    score
}

fn three_nodes() -> Network<3, 1, 1> {
    Network::new([C_W, C_H, C_S])
        .and_then(|n| n.connect(0, 1, G_WH))
        .and_then(|n| n.connect(1, 2, G_HS))
        .and_then(|n| n.connect_boundary(2, 0, G_SA))
        .and_then(|n| n.joule_source(0, 0, resistance()))
        .unwrap()
}

#[test]
fn a_lagging_thermistor_read_as_a_sensor_node_is_not_a_cold_winding() {
    // The thermistor as a fourth node, 1e-3 of the winding's capacity,
    // lagging it by 30 s.
    let lagged = Network::new([C_W, C_H, C_S, C_W * 1e-3])
        .and_then(|n| n.connect(0, 1, G_WH))
        .and_then(|n| n.connect(1, 2, G_HS))
        .and_then(|n| n.connect_boundary(2, 0, G_SA))
        .and_then(|n| n.connect_sensor(0, 3, TAU_S))
        .and_then(|n| n.joule_source(0, 0, resistance()))
        .unwrap();
    let with_lag = NetworkObserverBuilder::new(&lagged, [3])
        .critical_c([Some(155.0), None, None, None])
        .hardware_limit_a([10.0])
        .build::<5>()
        .unwrap();
    let lag = run(&with_lag);
    // The same thermistor read as the winding itself.
    let direct = NetworkObserverBuilder::new(&three_nodes(), [0])
        .critical_c([Some(155.0), None, None])
        .hardware_limit_a([10.0])
        .build::<4>()
        .unwrap();
    let naive = run(&direct);
    println!("sensor node: {lag:?}\nread as the winding: {naive:?}");
    // With the lag modelled the winding is followed within the reading's
    // 0.1 K rounding and the model's own error, and its upper bound is
    // never below the truth.
    assert!(lag.winding_cold_k < 0.5, "{lag:?}");
    assert!(lag.winding_hot_k < 0.5, "{lag:?}");
    assert!(lag.winding_above_bound_k <= 0.0, "{lag:?}");
    assert_eq!(lag.refused, 0, "{lag:?}");
    // Without it the healthy thermistor looks wrong: while the winding
    // heats it reads colder than the physics allows and is refused (the
    // sensor checks keep the estimate from going cold), while it cools it
    // reads warmer and the filter adds heat that is not there (2 568
    // readings refused, the winding 43 K hot when measured).
    assert!(naive.refused > 100, "{naive:?}");
    assert!(naive.winding_hot_k > 3.0, "{naive:?}");
}

#[test]
fn a_sensor_lag_must_be_a_finite_positive_time() {
    for tau in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let net = Network::<2, 1, 0>::new([C_W, 0.06]).unwrap();
        assert!(net.connect_sensor(0, 1, tau).is_err(), "tau {tau}");
    }
    let net = Network::<2, 1, 0>::new([C_W, 0.06]).unwrap();
    assert!(
        net.connect_sensor(0, 2, 10.0).is_err(),
        "no such sensor node"
    );
    let net = Network::<2, 1, 0>::new([C_W, 0.06]).unwrap();
    let net = net.connect_sensor(0, 1, 10.0).unwrap();
    assert!((net.conductance_w_per_k(0, 1) - 0.006).abs() < 1e-15);
}

/// The device as a model file, the thermistor a `[[node]]` that `lags`
/// the winding (its capacity left to the default).
const MODEL: &str = r#"
name = "winding with a thermistor"

[[node]]
name = "winding"
capacity_j_per_k = 60.0
critical_c = 155.0

[[node]]
name = "housing"
capacity_j_per_k = 400.0

[[node]]
name = "heatsink"
capacity_j_per_k = 900.0

[[node]]
name = "winding_ntc"
lags = "winding"
time_constant_s = 30.0

[[boundary]]
name = "ambient"
value_c = 22.0

[[conductance]]
between = ["winding", "housing"]
g_w_per_k = 0.8

[[conductance]]
between = ["housing", "heatsink"]
g_w_per_k = 2.0

[[conductance]]
between = ["heatsink", "ambient"]
g_w_per_k = 1.2

[[source]]
name = "winding"
node = "winding"
input = "current"
r0_ohm = 1.2
alpha_per_k = 0.00393
t_ref_c = 20.0
"#;

#[test]
fn a_model_file_describes_the_lag_and_its_observer_follows_the_winding() {
    use coil_thermal_host::model_file::{Model, ModelFile, LAG_CAPACITY_FRACTION};
    let file = ModelFile::parse(MODEL, "lag.toml").unwrap();
    let model = Model::build(&file).unwrap();
    let net = model.network.to_network::<4, 1, 1>().unwrap();
    let c_ntc = C_W * LAG_CAPACITY_FRACTION;
    assert_eq!(net.capacity_j_per_k(3), Some(c_ntc));
    assert!((net.conductance_w_per_k(0, 3) - c_ntc / TAU_S).abs() < 1e-18);
    // What the file writes back keeps the lag, not a derived conductance.
    let text = file.to_toml().unwrap();
    assert!(text.contains("lags = \"winding\""), "{text}");
    let again = ModelFile::parse(&text, "again.toml").unwrap();
    assert_eq!(again.to_toml().unwrap(), text);
    let obs = NetworkObserverBuilder::new(&net, [3])
        .critical_c([Some(155.0), None, None, None])
        .hardware_limit_a([10.0])
        .build::<5>()
        .unwrap();
    let score = run(&obs);
    println!("model file's sensor node: {score:?}");
    assert!(score.winding_cold_k < 0.5, "{score:?}");
    assert!(score.winding_hot_k < 0.5, "{score:?}");
    assert!(score.winding_above_bound_k <= 0.0, "{score:?}");
    assert_eq!(score.refused, 0, "{score:?}");
}

#[test]
fn a_model_files_lag_is_refused_when_it_cannot_be_one() {
    use coil_thermal_host::model_file::ModelFile;
    let cases = [
        (
            "time_constant_s = 30.0",
            "time_constant_s = 0.0",
            "finite and > 0",
        ),
        (
            "time_constant_s = 30.0",
            "time_constant_s = nan",
            "finite and > 0",
        ),
        (
            "time_constant_s = 30.0",
            "",
            "`lags` needs `time_constant_s`",
        ),
        (
            "lags = \"winding\"",
            "lags = \"rotor\"",
            "lags unknown node `rotor`",
        ),
        (
            "lags = \"winding\"",
            "lags = \"winding_ntc\"",
            "cannot lag itself",
        ),
        ("lags = \"winding\"\n", "", "`time_constant_s` needs `lags`"),
    ];
    for (from, to, said) in cases {
        let text = MODEL.replacen(from, to, 1);
        let err = ModelFile::parse(&text, "lag.toml").unwrap_err().to_string();
        assert!(err.contains(said), "{from} -> {to}: {err}");
        assert!(err.contains("winding_ntc"), "{err}");
    }
}
