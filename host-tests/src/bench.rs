//! Per-step timings of the hot-path steppers on this host.
//!
//! Each measurement steps a model many times (at least `min_time` of wall
//! clock) and reports the median over `repeats` runs of the mean time per
//! step \[ns\]. Keys name the model, its size, the scalar type and the unit,
//! e.g. `network_16_f32_ns` (library `ExplicitStepper`, a 16-node chain with a
//! current input per node) or `dynamic_84_f64_ns` (the host's runtime-size
//! network). Device models and the filter:
//!
//! * `grid_84_{f32,f64,q32}_ns`: one 1 ms `CoilGrid::<S, 7, 12>::tick` of
//!   the HPPA grid (FDM-fitted parameters, update every tick: the worst
//!   case), every coil at 1 A;
//! * `omnimagnet_predict_{f32,f64}_ns`: mean-only predict `x = F x + G u` of
//!   the Omnimagnet's 16-node model linearised at 20 degC and discretised
//!   (zero-order hold) for 0.1 s, inputs `[I1^2, I2^2, I3^2, T_amb, 1]`;
//! * `omnimagnet_correct_steady_f32_ns`: the library filter's steady-state
//!   correction with the six thermocouples (`measurement_matrix`), process
//!   noise `Q = 1e-4 I` K^2 per step, readings `R = 0.25` K^2;
//!   `omnimagnet_correct_tv_f32_ns`: the time-varying correction (gate,
//!   sequential Joseph updates) with the same model, from the same prior
//!   covariance each time (its copy included);
//! * `protect_tick_16_f32_ns`: a protection tick on the Omnimagnet network
//!   (16 elements): predictor slice, alarm tick and current limiter.
//!
//! In JSON each key `<name>_ns` also has `<name>_budget_ratio`.

use std::hint::black_box;
use std::time::{Duration, Instant};

use coil_thermal::{
    ExplicitStepper, InputLimits, Network, NetworkState, Resistance, Scalar, SolenoidParams, Q32,
};
use serde::Serialize;

use crate::dynamic_network::DynNetwork;

/// One measured step.
#[derive(Debug, Clone, Serialize)]
pub struct Timing {
    /// Key (`<model>_<size>_<scalar>_ns`).
    pub key: String,
    /// Median time per step \[ns\].
    pub ns: f64,
    /// `ns / 100 000` (the 0.1 ms budget).
    pub budget_ratio: f64,
}

/// A chain of `N` nodes, each heated by its own input, node 0 and node
/// `N-1` cooled: the shape of a layered winding.
pub fn chain<const N: usize>() -> Network<N, 1, N> {
    let mut net = Network::new([50.0; N]).expect("valid capacities");
    for i in 0..N.saturating_sub(1) {
        net = net.connect(i, i + 1, 2.0).expect("valid conductance");
    }
    net = net
        .connect_boundary(0, 0, 1.0)
        .and_then(|n| n.connect_boundary(N - 1, 0, 1.0))
        .expect("valid boundary");
    for i in 0..N {
        net = net
            .joule_source(i, i, Resistance::with_alpha(1.0, 0.0039, 20.0))
            .expect("valid source");
    }
    net
}

fn measure(key: String, min_time: Duration, repeats: usize, mut step: impl FnMut()) -> Timing {
    // Calibrate the batch size to about min_time.
    let mut batch = 1usize;
    loop {
        let start = Instant::now();
        for _ in 0..batch {
            step();
        }
        if start.elapsed() >= min_time / 4 || batch >= 1 << 30 {
            break;
        }
        batch *= 2;
    }
    let mut runs: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let start = Instant::now();
            for _ in 0..batch {
                step();
            }
            start.elapsed().as_nanos() as f64 / batch as f64
        })
        .collect();
    runs.sort_by(f64::total_cmp);
    let ns = runs[runs.len() / 2];
    Timing {
        key,
        ns,
        budget_ratio: ns / crate::observer::STEP_BUDGET_NS,
    }
}

fn library_step<S: Scalar, const N: usize, const B: usize, const M: usize>(
    key: &str,
    net: &Network<N, B, M>,
    dt_s: f64,
    min_time: Duration,
    repeats: usize,
) -> Timing {
    let limits = InputLimits::default();
    let stepper =
        ExplicitStepper::<S, N, B, M>::new(net, dt_s, limits).expect("stable bench network");
    let mut state = NetworkState::<S, N, B, M>::uniform(20.0);
    let currents = [S::from_f64(1.5); M];
    let boundary = [S::from_f64(20.0); B];
    measure(key.to_string(), min_time, repeats, || {
        black_box(stepper.step(
            black_box(&mut state),
            black_box(&currents),
            black_box(&boundary),
        ));
    })
}

fn scalar_steps<const N: usize, const B: usize, const M: usize>(
    model: &str,
    net: &Network<N, B, M>,
    dt_s: f64,
    min_time: Duration,
    repeats: usize,
    out: &mut Vec<Timing>,
) {
    out.push(library_step::<f32, N, B, M>(
        &format!("{model}_{N}_f32_ns"),
        net,
        dt_s,
        min_time,
        repeats,
    ));
    out.push(library_step::<f64, N, B, M>(
        &format!("{model}_{N}_f64_ns"),
        net,
        dt_s,
        min_time,
        repeats,
    ));
    out.push(library_step::<Q32, N, B, M>(
        &format!("{model}_{N}_q32_ns"),
        net,
        dt_s,
        min_time,
        repeats,
    ));
}

fn dynamic_step<const N: usize, const B: usize, const M: usize>(
    net: &Network<N, B, M>,
    dt_s: f64,
    min_time: Duration,
    repeats: usize,
) -> Timing {
    let dyn_net = DynNetwork::from_network(net).expect("valid network");
    let mut temps = vec![20.0; N];
    let currents = vec![1.5; M];
    let boundary = vec![20.0; B];
    let mut scratch = Vec::new();
    measure(format!("dynamic_{N}_f64_ns"), min_time, repeats, || {
        dyn_net.euler_step(
            black_box(&mut temps),
            black_box(&currents),
            black_box(&boundary),
            dt_s,
            &mut scratch,
        );
    })
}

fn grid_tick<S: Scalar>(key: &str, min_time: Duration, repeats: usize) -> Timing {
    use coil_thermal::grid::{CoilGrid, GridConfig, GridParams, GridState};
    let grid = CoilGrid::<S, 7, 12>::new(&GridConfig::hppa(GridParams::FDM_FITTED))
        .expect("the HPPA defaults are valid");
    let mut state = GridState::<S, 7, 12>::uniform(20.0);
    let currents = [[S::from_f64(1.0); 12]; 7];
    let (coolant, ambient) = (S::from_f64(20.0), S::from_f64(21.0));
    measure(key.to_string(), min_time, repeats, || {
        black_box(grid.tick(
            black_box(&mut state),
            black_box(&currents),
            coolant,
            ambient,
        ));
    })
}

/// The Omnimagnet filter model: `(F, G, H, Q, R)` in `f64`.
type OmniModel = (
    nalgebra::SMatrix<f64, 16, 16>,
    nalgebra::SMatrix<f64, 16, 5>,
    nalgebra::SMatrix<f64, 6, 16>,
    nalgebra::SMatrix<f64, 16, 16>,
    nalgebra::SVector<f64, 6>,
);

fn omnimagnet_model() -> OmniModel {
    use coil_thermal::omnimagnet::{measurement_matrix, Omnimagnet, NODES};
    let lin = Omnimagnet::PAPER
        .linearize(&[20.0; NODES], 20.0, 0.1)
        .expect("the paper's model linearises");
    let mut g = nalgebra::SMatrix::<f64, 16, 5>::zeros();
    for m in 0..3 {
        g.set_column(m, &lin.bd_current_squared.column(m));
    }
    g.set_column(3, &lin.discrete.gd_boundary.column(0));
    g.set_column(4, &lin.discrete.dd);
    (
        lin.discrete.ad,
        g,
        measurement_matrix(),
        nalgebra::SMatrix::<f64, 16, 16>::identity() * 1e-4,
        nalgebra::SVector::<f64, 6>::repeat(0.25),
    )
}

fn omnimagnet_predict<T: nalgebra::RealField + Copy>(
    key: &str,
    min_time: Duration,
    repeats: usize,
) -> Timing {
    use coil_thermal::filter::{predict_mean, KalmanConfig};
    let (f, g, h, q, r) = omnimagnet_model();
    let cfg = KalmanConfig::<T, 16, 5, 6>::new(f.cast(), g.cast(), h.cast(), q.cast(), r.cast())
        .expect("valid filter model");
    let mut x = nalgebra::SVector::<T, 16>::repeat(T::from_subset(&20.0));
    let u = nalgebra::SVector::<f64, 5>::from([9.0, 9.0, 9.0, 20.0, 1.0]).cast::<T>();
    measure(key.to_string(), min_time, repeats, || {
        black_box(predict_mean(&cfg, black_box(&mut x), black_box(&u)));
    })
}

fn omnimagnet_correct(min_time: Duration, repeats: usize, out: &mut Vec<Timing>) {
    use coil_thermal::filter::{
        predict, update, update_steady, KalmanConfig, KalmanState, SteadyEstimate, SteadyStateGain,
    };
    let (f, g, h, q, r) = omnimagnet_model();
    let cfg = KalmanConfig::<f32, 16, 5, 6>::new(f.cast(), g.cast(), h.cast(), q.cast(), r.cast())
        .expect("valid filter model");
    let x0 = nalgebra::SVector::<f32, 16>::repeat(20.0);
    let z = [
        Some(20.3f32),
        Some(20.1),
        Some(19.8),
        Some(20.2),
        Some(20.0),
        Some(19.9),
    ];
    let steady = SteadyStateGain::solve(&cfg, 1).expect("the Riccati equation converges");
    let mut est = SteadyEstimate::new(x0);
    out.push(measure(
        "omnimagnet_correct_steady_f32_ns".into(),
        min_time,
        repeats,
        || {
            black_box(update_steady(
                &cfg,
                &steady,
                black_box(&mut est),
                black_box(&z),
            ));
            est.x = x0;
        },
    ));
    let mut state = KalmanState::new(x0, nalgebra::SMatrix::<f32, 16, 16>::identity());
    let u = nalgebra::SVector::<f32, 5>::from([9.0, 9.0, 9.0, 20.0, 1.0]);
    for _ in 0..50 {
        predict(&cfg, &mut state, &u);
        update(&cfg, &mut state, &z);
    }
    predict(&cfg, &mut state, &u);
    let prior = state;
    out.push(measure(
        "omnimagnet_correct_tv_f32_ns".into(),
        min_time,
        repeats,
        || {
            state.x = prior.x;
            state.cov = prior.cov;
            black_box(update(&cfg, black_box(&mut state), black_box(&z)));
        },
    ));
}

fn protect_tick(min_time: Duration, repeats: usize) -> Timing {
    use coil_thermal::omnimagnet::{Omnimagnet, CRITICAL_TEMPS_C, NODES};
    use coil_thermal::protect::alarm::{AlarmBuilder, AlarmState};
    use coil_thermal::protect::derating::DeratingRule;
    use coil_thermal::protect::events::EventQueue;
    use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
    use coil_thermal::protect::predict::{Operating, PredictorBuilder, PredictorState};
    let net = Omnimagnet::PAPER
        .network(&[20.0; NODES], 20.0)
        .expect("the paper's model builds");
    let predictor = PredictorBuilder::new()
        .build::<f32, 16, 1, 3, 48>(&net)
        .expect("the Omnimagnet network decomposes");
    let highest = CRITICAL_TEMPS_C
        .iter()
        .flatten()
        .fold(0.0f64, |a, b| a.max(*b));
    let critical = CRITICAL_TEMPS_C.map(|c| c.unwrap_or(highest));
    let alarm = AlarmBuilder::new(&DeratingRule::omnimagnet(), critical)
        .build::<f32>()
        .expect("valid alarm");
    let limiter = LimiterConfig::<f32, 3>::new([8.0; 3], 10.0, 0.0).expect("valid limiter");
    let ambient = 20.0f32;
    let limits = alarm.alarm_limits_c(ambient);
    let op = Operating {
        temps_c: core::array::from_fn(|i| 30.0 + i as f32),
        currents_a: [3.0, 2.5, 3.5],
        boundary_c: [ambient],
        limits_c: limits,
    };
    let mut state = PredictorState::new(&predictor, &op);
    let mut alarm_state = AlarmState::new(&alarm);
    let mut events = EventQueue::<32>::new();
    let mut coil_limits = [CoilLimit::default(); 3];
    measure("protect_tick_16_f32_ns".into(), min_time, repeats, || {
        let op = black_box(&op);
        let ttl = *state.tick(&predictor, op);
        let status = alarm_state.tick(&alarm, &op.temps_c, ambient, &ttl, &mut events);
        let coil_temps = [op.temps_c[0], op.temps_c[1], op.temps_c[2]];
        let coil_alarm = [limits[0], limits[1], limits[2]];
        limiter.apply(&coil_temps, &coil_alarm, ambient, &mut coil_limits);
        while events.pop().is_some() {}
        black_box((status, coil_limits));
    })
}

/// Runs every measurement.
pub fn run(min_time: Duration, repeats: usize) -> Vec<Timing> {
    let mut out = Vec::new();
    scalar_steps("network", &chain::<3>(), 1e-3, min_time, repeats, &mut out);
    scalar_steps("network", &chain::<16>(), 1e-3, min_time, repeats, &mut out);
    scalar_steps("network", &chain::<84>(), 1e-3, min_time, repeats, &mut out);
    let sol = SolenoidParams::HESE
        .network::<30>()
        .expect("HeSE defaults are valid");
    scalar_steps("solenoid", &sol, 0.1, min_time, repeats, &mut out);
    out.push(dynamic_step(&chain::<3>(), 1e-3, min_time, repeats));
    out.push(dynamic_step(&chain::<84>(), 1e-3, min_time, repeats));
    out.push(grid_tick::<f32>("grid_84_f32_ns", min_time, repeats));
    out.push(grid_tick::<f64>("grid_84_f64_ns", min_time, repeats));
    out.push(grid_tick::<Q32>("grid_84_q32_ns", min_time, repeats));
    out.push(omnimagnet_predict::<f32>(
        "omnimagnet_predict_f32_ns",
        min_time,
        repeats,
    ));
    out.push(omnimagnet_predict::<f64>(
        "omnimagnet_predict_f64_ns",
        min_time,
        repeats,
    ));
    omnimagnet_correct(min_time, repeats, &mut out);
    out.push(protect_tick(min_time, repeats));
    out
}
