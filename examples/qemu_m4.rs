//! Firmware check on the Cortex-M4F under QEMU: builds a lumped network on
//! target, steps it in `f32` at 1 ms, and compares the result with the exact
//! (zero-order-hold) solution and the steady state computed on target in `f64`.
//! Exits 0 when every check passes, non-zero on a mismatch or a panic.
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;

use coil_thermal::discretize::zoh;
use coil_thermal::{ExplicitStepper, InputLimits, Network, NetworkState, Resistance};
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use nalgebra::SVector;

/// A coil (node 0) on a former (node 1) in a housing (node 2) cooled to ambient.
fn coil_in_housing() -> Result<Network<3, 1, 1>, coil_thermal::BuildError> {
    Network::new([68.7, 40.0, 400.0])?
        .connect(0, 1, 0.35)?
        .connect(1, 2, 0.8)?
        .connect_boundary(2, 0, 1.5)?
        .connect_boundary(0, 0, 0.02)?
        .joule_source(0, 0, Resistance::HPPA_COIL)
}

fn run() -> Result<(), &'static str> {
    let network = coil_in_housing().map_err(|_| "network build")?;
    let stepper = ExplicitStepper::<f32, 3, 1, 1>::new(&network, 1e-3, InputLimits::default())
        .map_err(|_| "stepper build")?;
    let mut state = NetworkState::<f32, 3, 1, 1>::uniform(20.0);
    let current_a = [1.2f32];
    let ambient_c = [20.0f32];
    for _ in 0..60_000 {
        stepper.step(&mut state, &current_a, &ambient_c);
    }
    // Reference: 60 exact (ZOH) steps of 1 s in f64, with the Joule power
    // R(T) I^2 re-evaluated at the start of each second; holding R for 1 s
    // errs by far less than the 0.02 K tolerance.
    let exact = zoh(&network.state_space(&[20.0; 3]), 1.0).map_err(|_| "zoh")?;
    let mut x = SVector::<f64, 3>::from_element(20.0);
    for _ in 0..60 {
        let p = Resistance::HPPA_COIL.at_c(x[0]) * 1.2 * 1.2;
        x = exact.step(&x, &SVector::from_element(p), &SVector::from_element(20.0));
    }
    let mut worst_k = 0.0f64;
    for i in 0..3 {
        worst_k = worst_k.max(libm::fabs(x[i] - state.temps_c[i] as f64));
    }
    hprintln!(
        "network f32 after 60 s: coil {} degC, former {} degC, housing {} degC; max |f32 - zoh| = {} K",
        state.temps_c[0],
        state.temps_c[1],
        state.temps_c[2],
        worst_k
    );
    if worst_k > 0.02 {
        return Err("f32 explicit step disagrees with the exact step");
    }
    let steady = network
        .steady_state(&[1.2], &[20.0])
        .map_err(|_| "steady state")?;
    hprintln!("steady state: coil {} degC", steady[0]);
    if !(steady[0] > state.temps_c[0] as f64 && steady[0] < 200.0) {
        return Err("steady state implausible");
    }
    Ok(())
}

#[entry]
fn main() -> ! {
    match run() {
        Ok(()) => {
            hprintln!("qemu_m4: all checks passed");
            exit::exit(true)
        }
        Err(what) => {
            hprintln!("qemu_m4: FAILED: {}", what);
            exit::exit(false)
        }
    }
}
