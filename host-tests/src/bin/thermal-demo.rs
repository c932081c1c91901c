//! A one-screen demonstration of the network core on the host: a coil on a
//! former in a housing, heated at 1.2 A for an hour, stepped at 1 ms in f32
//! and in Q32.32 fixed point, against the exact steady state.

use coil_thermal::{ExplicitStepper, InputLimits, Network, NetworkState, Resistance, Scalar, Q32};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let network: Network<3, 1, 1> = Network::new([68.7, 40.0, 400.0])?
        .connect(0, 1, 0.35)?
        .connect(1, 2, 0.8)?
        .connect_boundary(2, 0, 1.5)?
        .connect_boundary(0, 0, 0.02)?
        .joule_source(0, 0, Resistance::HPPA_COIL)?;
    let limits = InputLimits::default();
    let float_stepper = ExplicitStepper::<f32, 3, 1, 1>::new(&network, 1e-3, limits)?;
    let fixed_stepper = ExplicitStepper::<Q32, 3, 1, 1>::new(&network, 1e-3, limits)?;
    let mut float_state = NetworkState::<f32, 3, 1, 1>::uniform(20.0);
    let mut fixed_state = NetworkState::<Q32, 3, 1, 1>::uniform(20.0);
    let current_a = 1.2;
    println!("coil on a former in a housing, {current_a} A, ambient 20 degC, 1 ms steps");
    println!(
        "{:>8} {:>12} {:>12} {:>12}",
        "time_s", "coil_f32_c", "coil_q32_c", "housing_c"
    );
    for minute in 0..=60 {
        if minute % 10 == 0 {
            println!(
                "{:>8} {:>12.4} {:>12.4} {:>12.4}",
                minute * 60,
                float_state.temps_c[0],
                fixed_state.temps_c[0].to_f64(),
                float_state.temps_c[2]
            );
        }
        for _ in 0..60_000 {
            float_stepper.step(&mut float_state, &[current_a as f32], &[20.0]);
            fixed_stepper.step(
                &mut fixed_state,
                &[Q32::from_f64(current_a)],
                &[Q32::from_f64(20.0)],
            );
        }
    }
    let steady = network.steady_state(&[current_a], &[20.0])?;
    println!(
        "steady state (exact, with R(T)): coil {:.4} degC",
        steady[0]
    );
    let rates = network.energy_rates(&steady, &[current_a], &[20.0]);
    println!(
        "energy account at steady state: in {:.4} W, stored {:.2e} W, out {:.4} W",
        rates.input_w, rates.stored_w, rates.to_boundaries_w
    );
    Ok(())
}
