//! Network tests against closed forms and simulations written apart from the
//! stepper (the f64 right-hand side integrated by classical Runge-Kutta).

use super::*;
use crate::input::{InputFlags, InputLimits};
use crate::scalar::{Scalar, Q32};

/// One node, capacity 10 J/K, 0.5 W/K to a boundary, heated by 2 A through
/// a constant 1.25 ohm (5 W): tau = 20 s, final rise 10 K.
fn rc_node() -> Network<1, 1, 1> {
    Network::new([10.0])
        .unwrap()
        .connect_boundary(0, 0, 0.5)
        .unwrap()
        .joule_source(0, 0, Resistance::constant(1.25))
        .unwrap()
}

/// Classical RK4 on the network's own f64 right-hand side, with a step far
/// below the time constants: an integrator independent of the steppers.
fn rk4<const N: usize, const B: usize, const M: usize>(
    net: &Network<N, B, M>,
    temps: &mut [f64; N],
    currents: &[f64; M],
    boundary: &[f64; B],
    duration_s: f64,
    h: f64,
) {
    let steps = (duration_s / h).round() as usize;
    for _ in 0..steps {
        let shifted = |t: &[f64; N], k: &[f64; N], a: f64| {
            let mut out = *t;
            for i in 0..N {
                out[i] += a * k[i];
            }
            out
        };
        let k1 = net.derivative_k_per_s(temps, currents, boundary);
        let k2 = net.derivative_k_per_s(&shifted(temps, &k1, h / 2.0), currents, boundary);
        let k3 = net.derivative_k_per_s(&shifted(temps, &k2, h / 2.0), currents, boundary);
        let k4 = net.derivative_k_per_s(&shifted(temps, &k3, h), currents, boundary);
        for i in 0..N {
            temps[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
}

#[test]
fn single_rc_node_follows_the_analytic_exponential() {
    let net = rc_node();
    let stepper = ExplicitStepper::<f64, 1, 1, 1>::new(&net, 1e-3, InputLimits::default()).unwrap();
    let mut state = NetworkState::uniform(20.0);
    for k in 1..=60_000 {
        stepper.step(&mut state, &[2.0], &[20.0]);
        if k % 10_000 == 0 {
            let t = k as f64 * 1e-3;
            let analytic = 20.0 + 10.0 * (1.0 - libm::exp(-t / 20.0));
            // Forward Euler's global error is about dt/(2 tau) of the rise.
            assert!((state.temps_c[0] - analytic).abs() < 5e-4, "t = {t}");
        }
    }
}

#[test]
fn two_node_network_matches_its_closed_form() {
    // C1 = 2, C2 = 8 J/K; G12 = 1 W/K; node 2 to ground (0 degC) by 0.5 W/K.
    // A = [[-1/2, 1/2], [1/8, -1.5/8]]; free relaxation from (10, 0).
    let net: Network<2, 1, 0> = Network::new([2.0, 8.0])
        .unwrap()
        .connect(0, 1, 1.0)
        .unwrap()
        .connect_boundary(1, 0, 0.5)
        .unwrap();
    let (a11, a12, a21, a22) = (-0.5, 0.5, 0.125, -0.1875);
    let tr = a11 + a22;
    let det = a11 * a22 - a12 * a21;
    let disc = libm::sqrt(tr * tr / 4.0 - det);
    let (l1, l2) = (tr / 2.0 + disc, tr / 2.0 - disc);
    // x(t) = c1 v1 e^{l1 t} + c2 v2 e^{l2 t}, v = (a12, l - a11).
    let (v1, v2) = ((a12, l1 - a11), (a12, l2 - a11));
    // Solve c1 v1 + c2 v2 = (10, 0).
    let d = v1.0 * v2.1 - v2.0 * v1.1;
    let c1 = (10.0 * v2.1) / d;
    let c2 = -(10.0 * v1.1) / d;
    let closed = |t: f64| {
        (
            c1 * v1.0 * libm::exp(l1 * t) + c2 * v2.0 * libm::exp(l2 * t),
            c1 * v1.1 * libm::exp(l1 * t) + c2 * v2.1 * libm::exp(l2 * t),
        )
    };
    let ss = net.state_space(&[0.0; 2]);
    let exact = crate::discretize::zoh(&ss, 0.5).unwrap();
    let stepper = ExplicitStepper::<f64, 2, 1, 0>::new(&net, 1e-3, InputLimits::default()).unwrap();
    let mut explicit = NetworkState::<f64, 2, 1, 0>::uniform(0.0);
    explicit.temps_c = [10.0, 0.0];
    let mut zoh = nalgebra::SVector::<f64, 2>::new(10.0, 0.0);
    for k in 1..=20 {
        zoh = exact.step(
            &zoh,
            &nalgebra::SVector::zeros(),
            &nalgebra::SVector::zeros(),
        );
        for _ in 0..500 {
            stepper.step(&mut explicit, &[], &[0.0]);
        }
        let (w1, w2) = closed(k as f64 * 0.5);
        assert!((zoh[0] - w1).abs() < 1e-10 && (zoh[1] - w2).abs() < 1e-10);
        assert!((explicit.temps_c[0] - w1).abs() < 2e-3);
        assert!((explicit.temps_c[1] - w2).abs() < 2e-3);
    }
}

#[test]
fn steady_state_matches_a_long_simulation_with_rising_resistance() {
    let net: Network<3, 2, 2> = Network::new([50.0, 20.0, 200.0])
        .unwrap()
        .connect(0, 1, 0.4)
        .unwrap()
        .connect(1, 2, 1.1)
        .unwrap()
        .connect(0, 2, 0.1)
        .unwrap()
        .connect_boundary(2, 0, 2.0)
        .unwrap()
        .connect_boundary(0, 1, 0.05)
        .unwrap()
        .joule_source(0, 0, Resistance::with_alpha(3.2, 0.0039, 20.0))
        .unwrap()
        .joule_source(1, 1, Resistance::HPPA_COIL)
        .unwrap();
    let currents = [1.5, 0.7];
    let boundary = [18.0, 25.0];
    let steady = net.steady_state(&currents, &boundary).unwrap();
    let mut temps = [18.0; 3];
    rk4(&net, &mut temps, &currents, &boundary, 20_000.0, 0.5);
    for i in 0..3 {
        assert!((steady[i] - temps[i]).abs() < 1e-6, "node {i}");
    }
    let rates = net.energy_rates(&steady, &currents, &boundary);
    assert!(rates.stored_w.abs() < 1e-9);
    assert!((rates.input_w - rates.to_boundaries_w).abs() < 1e-9);
}

#[test]
fn runaway_current_is_where_the_steady_state_disappears() {
    // One node: G (T - Tb) = (r0 + s T) I^2 has a solution iff s I^2 < G.
    let g = 0.2;
    let r = Resistance::with_alpha(3.0, 0.0039, 20.0);
    let net: Network<1, 1, 1> = Network::new([30.0])
        .unwrap()
        .connect_boundary(0, 0, g)
        .unwrap()
        .joule_source(0, 0, r)
        .unwrap();
    let runaway_a = libm::sqrt(g / r.slope_ohm_per_k);
    let below = net.steady_state(&[0.99 * runaway_a], &[20.0]).unwrap()[0];
    let i2 = 0.99 * 0.99 * runaway_a * runaway_a;
    let closed = (g * 20.0 + r.r_at_0c_ohm * i2) / (g - r.slope_ohm_per_k * i2);
    assert!((below - closed).abs() < 1e-9 * closed);
    assert_eq!(
        net.steady_state(&[1.01 * runaway_a], &[20.0]),
        Err(BuildError::NoSteadyState)
    );
    let isolated: Network<1, 1, 1> = Network::new([30.0]).unwrap().joule_source(0, 0, r).unwrap();
    assert_eq!(
        isolated.steady_state(&[0.0], &[20.0]),
        Err(BuildError::Singular)
    );
}

#[test]
fn builders_name_the_bad_parameter() {
    assert_eq!(
        Network::<2, 1, 0>::new([1.0, f64::NAN]).err(),
        Some(BuildError::InvalidCapacity { node: 1 })
    );
    assert_eq!(
        Network::<2, 1, 0>::new([1.0, -3.0]).err(),
        Some(BuildError::InvalidCapacity { node: 1 })
    );
    let net = Network::<2, 1, 1>::new([1.0, 1.0]).unwrap();
    assert_eq!(
        net.clone().connect(0, 1, -0.1).err(),
        Some(BuildError::InvalidConductance { node: 0, other: 1 })
    );
    assert_eq!(
        net.clone().connect(0, 1, f64::INFINITY).err(),
        Some(BuildError::InvalidConductance { node: 0, other: 1 })
    );
    assert_eq!(
        net.clone().connect(1, 1, 1.0).err(),
        Some(BuildError::SelfLoop { node: 1 })
    );
    assert_eq!(
        net.clone().connect(0, 2, 1.0).err(),
        Some(BuildError::NodeOutOfRange { index: 2 })
    );
    assert_eq!(
        net.clone().connect_boundary(0, 1, 1.0).err(),
        Some(BuildError::NodeOutOfRange { index: 1 })
    );
    assert_eq!(
        net.clone().fixed_power(0, f64::NAN).err(),
        Some(BuildError::InvalidPower { node: 0 })
    );
    assert_eq!(
        ExplicitStepper::<f32, 2, 1, 1>::new(&net, 1e-3, InputLimits::default()).err(),
        Some(BuildError::MissingSource { input: 0 })
    );
    let net = net.joule_source(0, 0, Resistance::constant(1.0)).unwrap();
    for bad_dt in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert_eq!(
            ExplicitStepper::<f32, 2, 1, 1>::new(&net, bad_dt, InputLimits::default()).err(),
            Some(BuildError::InvalidTimeStep)
        );
    }
}

#[test]
fn unstable_explicit_step_is_refused_with_the_worst_node() {
    let net: Network<2, 1, 0> = Network::new([1.0, 0.01])
        .unwrap()
        .connect(0, 1, 1.0)
        .unwrap()
        .connect_boundary(0, 0, 1.0)
        .unwrap();
    // Node 1: dt * 1 / 0.01 = 100 dt, so dt = 0.0099 passes and 0.01 fails.
    assert!(ExplicitStepper::<f64, 2, 1, 0>::new(&net, 0.0099, InputLimits::default()).is_ok());
    match ExplicitStepper::<f64, 2, 1, 0>::new(&net, 0.01, InputLimits::default()) {
        Err(BuildError::UnstableStep { node, ratio }) => {
            assert_eq!(node, 1);
            assert!((ratio - 1.0).abs() < 1e-6);
        }
        other => panic!("expected UnstableStep, got {other:?}"),
    }
}

#[test]
fn bad_inputs_are_held_and_reported_never_propagated() {
    let net = rc_node();
    let stepper = ExplicitStepper::<f32, 1, 1, 1>::new(&net, 1e-2, InputLimits::default()).unwrap();
    let mut state = NetworkState::uniform(20.0);
    stepper.step(&mut state, &[2.0], &[20.0]);
    let flags = stepper.step(&mut state, &[f32::NAN], &[f32::INFINITY]);
    assert!(flags.contains(InputFlags::CURRENT_NOT_FINITE));
    assert!(flags.contains(InputFlags::TEMPERATURE_INVALID));
    assert_eq!(state.held_currents_a, [2.0]);
    assert_eq!(state.held_boundary_c, [20.0]);
    assert!(state.temps_c[0].is_finite() && state.temps_c[0] > 20.0);
}

#[test]
fn f32_and_fixed_point_steps_track_f64() {
    let net: Network<3, 1, 1> = Network::new([68.7, 68.7, 68.7])
        .unwrap()
        .connect(0, 1, 1.0 / 9.9)
        .unwrap()
        .connect(1, 2, 1.0 / 3.49)
        .unwrap()
        .connect_boundary(0, 0, 1.0 / 5.74)
        .unwrap()
        .connect_boundary(1, 0, 1.0 / 5.74)
        .unwrap()
        .connect_boundary(2, 0, 1.0 / 5.74)
        .unwrap()
        .joule_source(0, 1, Resistance::HPPA_COIL)
        .unwrap();
    let limits = InputLimits::default();
    let s64 = ExplicitStepper::<f64, 3, 1, 1>::new(&net, 1e-3, limits).unwrap();
    let s32 = ExplicitStepper::<f32, 3, 1, 1>::new(&net, 1e-3, limits).unwrap();
    let sq = ExplicitStepper::<Q32, 3, 1, 1>::new(&net, 1e-3, limits).unwrap();
    let mut x64 = NetworkState::uniform(20.0);
    let mut x32 = NetworkState::uniform(20.0);
    let mut xq = NetworkState::uniform(20.0);
    let (i64_, i32_, iq) = ([0.7f64], [0.7f32], [Q32::from_f64(0.7)]);
    // 600 s of 1 ms steps: a third of the coil's time constant.
    for _ in 0..600_000 {
        s64.step(&mut x64, &i64_, &[20.0]);
        s32.step(&mut x32, &i32_, &[20.0]);
        sq.step(&mut xq, &iq, &[Q32::from_f64(20.0)]);
    }
    assert!(x64.temps_c[1] > 21.0, "must heat: {}", x64.temps_c[1]);
    for i in 0..3 {
        // f32 at 1 ms: each increment (~1e-5 K) is rounded against a ~20 degC
        // state, which f32 resolves to 2e-6 K: a few percent of an increment,
        // which the rounding carry hands on to the next step. README's claim
        // (f32 within 0.01 mK of f64) is this bound; without the carry the
        // error is hundreds of times larger.
        let err_k = (x64.temps_c[i] - x32.temps_c[i] as f64).abs();
        println!("f32 node {i}: {err_k:.2e} K from f64");
        assert!(err_k < 1e-5, "f32 node {i}: {err_k} K");
        assert!(
            (x64.temps_c[i] - xq.temps_c[i].to_f64()).abs() < 1e-3,
            "Q32 node {i}"
        );
    }
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    /// A random 4-node network: capacities, pair conductances (some zero),
    /// boundary links to two boundaries, and one coil.
    fn network() -> impl Strategy<Value = (Network<4, 2, 1>, [f64; 4], [f64; 2], f64)> {
        (
            prop::array::uniform4(1.0f64..500.0),
            prop::array::uniform6(prop_oneof![Just(0.0), 0.01f64..5.0]),
            prop::array::uniform4(0.0f64..2.0),
            prop::array::uniform4(-20.0f64..150.0),
            prop::array::uniform2(-10.0f64..60.0),
            0.0f64..5.0,
            0usize..4,
        )
            .prop_map(|(c, g, gb, t0, tb, current, coil)| {
                let mut net = Network::<4, 2, 1>::new(c).unwrap();
                let pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];
                for ((a, b), g) in pairs.iter().zip(g) {
                    net = net.connect(*a, *b, g).unwrap();
                }
                for (i, g) in gb.iter().enumerate() {
                    net = net.connect_boundary(i, i % 2, *g + 0.01).unwrap();
                }
                net = net
                    .joule_source(0, coil, Resistance::with_alpha(2.0, 0.0039, 20.0))
                    .unwrap();
                (net, t0, tb, current)
            })
    }

    proptest! {
        #[test]
        fn explicit_step_conserves_energy((net, t0, tb, current) in network()) {
            let max_ratio = (0..4)
                .map(|i| net.total_conductance_w_per_k(i) / net.capacity_j_per_k(i).unwrap())
                .fold(0.0, f64::max);
            let dt = 0.5 / max_ratio;
            let stepper = ExplicitStepper::<f64, 4, 2, 1>::new(&net, dt, InputLimits::default()).unwrap();
            let mut state = NetworkState::<f64, 4, 2, 1> { temps_c: t0, held_currents_a: [0.0], held_boundary_c: tb, residual_c: [0.0; 4] };
            for _ in 0..50 {
                let before = state.temps_c;
                let rates = net.energy_rates(&before, &[current], &tb);
                stepper.step(&mut state, &[current], &tb);
                let stored_j: f64 = (0..4)
                    .map(|i| net.capacity_j_per_k(i).unwrap() * (state.temps_c[i] - before[i]))
                    .sum();
                let expected_j = (rates.input_w - rates.to_boundaries_w) * dt;
                let scale = 1.0 + rates.input_w.abs() * dt + rates.to_boundaries_w.abs() * dt;
                prop_assert!((stored_j - expected_j).abs() < 1e-9 * scale);
                prop_assert!(rates.imbalance_w().abs() < 1e-9 * (1.0 + rates.input_w.abs() + rates.to_boundaries_w.abs()));
            }
        }

        #[test]
        fn without_sources_every_node_relaxes_toward_the_boundaries((net, t0, tb, _c) in network()) {
            let steady = net.steady_state(&[0.0], &tb).unwrap();
            let (lo, hi) = (tb[0].min(tb[1]), tb[0].max(tb[1]));
            for t in steady {
                prop_assert!(t >= lo - 1e-9 && t <= hi + 1e-9);
            }
            let ss = net.state_space(&t0);
            let slowest = (0..4)
                .map(|i| net.capacity_j_per_k(i).unwrap())
                .sum::<f64>() / 0.04;
            let exact = crate::discretize::zoh(&ss, 40.0 * slowest).unwrap();
            let x = exact.step(
                &nalgebra::SVector::from(t0),
                &nalgebra::SVector::zeros(),
                &nalgebra::SVector::from(tb),
            );
            for i in 0..4 {
                prop_assert!((x[i] - steady[i]).abs() < 1e-6 * (1.0 + (t0[i] - steady[i]).abs()));
            }
        }

        #[test]
        fn no_input_makes_the_step_panic_or_go_non_finite(
            current in prop::num::f32::ANY,
            t_b in prop::num::f32::ANY,
        ) {
            let net = rc_node();
            let stepper = ExplicitStepper::<f32, 1, 1, 1>::new(&net, 0.1, InputLimits::default()).unwrap();
            let mut state = NetworkState::uniform(20.0);
            for _ in 0..10 {
                stepper.step(&mut state, &[current], &[t_b]);
            }
            prop_assert!(state.temps_c[0].is_finite());
            let sq = ExplicitStepper::<Q32, 1, 1, 1>::new(&net, 0.1, InputLimits::default()).unwrap();
            let mut qstate = NetworkState::uniform(20.0);
            for _ in 0..10 {
                sq.step(&mut qstate, &[Q32::from_f32(current)], &[Q32::from_f32(t_b)]);
            }
            prop_assert!(qstate.temps_c[0].to_f64() < 1e4);
        }
    }
}
