//! Building aside, stepping allocates nothing: every allocation made on this
//! test's thread is counted by a wrapping global allocator, and the per-tick
//! calls must leave the count unchanged.

use coil_thermal_host::alloc_count::{count_allocations, CountingAllocator};

use coil_thermal::discretize::zoh;
use coil_thermal::{ExplicitStepper, InputLimits, Network, NetworkState, Resistance, Scalar, Q32};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

fn network() -> Network<4, 2, 2> {
    Network::new([68.7, 40.0, 400.0, 12.0])
        .unwrap()
        .connect(0, 1, 0.35)
        .unwrap()
        .connect(1, 2, 0.8)
        .unwrap()
        .connect(3, 1, 0.2)
        .unwrap()
        .connect_boundary(2, 0, 1.5)
        .unwrap()
        .connect_boundary(3, 1, 0.1)
        .unwrap()
        .joule_source(0, 0, Resistance::HPPA_COIL)
        .unwrap()
        .joule_source(1, 3, Resistance::with_alpha(3.2, 0.0039, 20.0))
        .unwrap()
}

#[test]
fn the_counter_sees_allocations() {
    // Without this the test below could pass with a broken counter.
    let n = count_allocations(|| {
        let v: Vec<u8> = Vec::with_capacity(std::hint::black_box(16));
        std::hint::black_box(v);
    });
    assert_eq!(n, 1);
}

#[test]
fn network_steps_allocate_nothing() {
    let net = network();
    let limits = InputLimits::default();
    let f32_stepper = ExplicitStepper::<f32, 4, 2, 2>::new(&net, 1e-3, limits).unwrap();
    let q_stepper = ExplicitStepper::<Q32, 4, 2, 2>::new(&net, 1e-3, limits).unwrap();
    let exact = zoh(&net.state_space(&[20.0; 4]), 1e-3)
        .unwrap()
        .cast::<f32>();
    let mut state = NetworkState::<f32, 4, 2, 2>::uniform(20.0);
    let mut q_state = NetworkState::<Q32, 4, 2, 2>::uniform(20.0);
    let mut x = nalgebra::SVector::<f32, 4>::from_element(20.0);
    let n = count_allocations(|| {
        for k in 0..10_000 {
            let current = if k % 13 == 0 { f32::NAN } else { 1.5 };
            state.temps_c = std::hint::black_box(state.temps_c);
            f32_stepper.step(&mut state, &[current, 0.5], &[20.0, f32::INFINITY]);
            q_stepper.step(
                &mut q_state,
                &[Q32::from_f32(current), Q32::from_f64(0.5)],
                &[Q32::from_f64(20.0), Q32::from_f64(25.0)],
            );
            x = exact.step(
                &x,
                &nalgebra::SVector::from_element(10.0),
                &nalgebra::SVector::from_element(20.0),
            );
        }
    });
    assert_eq!(n, 0);
    assert!(state.temps_c[0] > 20.0 && x[0] > 20.0);
}

#[test]
fn network_observer_ticks_allocate_nothing() {
    use coil_thermal::observer::omnimagnet::TimedReading;
    use coil_thermal::observer::{NetworkInputs, NetworkObserver, NetworkObserverBuilder};
    use coil_thermal::{Reading, SensorFault};

    let net = network();
    // Two currents, one thermocouple: their heat biases cannot be told
    // apart, so noise 0 freezes them (as random walks they would leave the
    // winding at a steady sigma of 3 420 K, refused as `Unobservable`).
    let obs: NetworkObserver<4, 2, 2, 6, 1> = NetworkObserverBuilder::new(&net, [1])
        .critical_c([Some(155.0), Some(80.0), None, Some(120.0)])
        .settings(coil_thermal::observer::NetworkSettings {
            bias_noise_w2_per_s: 0.0,
            ..coil_thermal::observer::NetworkSettings::DEFAULT
        })
        .build()
        .unwrap();
    let mut state = obs.state(&[20.0; 4], &[20.0; 2]);
    let n = count_allocations(|| {
        for k in 0..20_000u32 {
            let current = if k % 13 == 0 { f32::NAN } else { 1.5 };
            let reading = TimedReading {
                result: if k % 1000 == 0 {
                    Err(SensorFault::OpenCircuit)
                } else {
                    Ok(Reading::new(21.0))
                },
                sampled_at_us: k.wrapping_mul(1000),
            };
            let out = obs.tick(
                &mut state,
                &NetworkInputs {
                    currents_a: [current, 0.5],
                    boundary_c: [20.0, f32::INFINITY],
                    readings: [(k % 500 == 0).then_some(reading)],
                    now_us: k.wrapping_mul(1000),
                    elapsed_us: if k % 97 == 0 { 7000 } else { 1000 },
                },
            );
            std::hint::black_box(out);
        }
    });
    assert_eq!(n, 0);
    // The loop ran the whole tick: corrections and protection cycles.
    assert!(state.outputs().tick == 20_000 && state.outputs().temps_c[0] > 20.0);
}
