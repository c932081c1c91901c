//! Per-step timings of the hot-path steppers on this host.
//!
//! Each measurement steps a model many times (at least `min_time` of wall
//! clock) and reports the median over `repeats` runs of the mean time per
//! step \[ns\]. Keys name the model, its size, the scalar type and the unit,
//! e.g. `network_16_f32_ns` (library `ExplicitStepper`, a 16-node chain with a
//! current input per node) or `dynamic_84_f64_ns` (the host's runtime-size
//! network). Stage 2 adds `grid_84_f32_ns`, `omnimagnet_predict_f32_ns` and
//! the filter.

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
    out
}
