//! Link-time proof that the per-tick path cannot panic.
//!
//! The panic handler below calls a function that exists nowhere. If any panic
//! (a bounds check, an `unwrap`, a division check) were still reachable from
//! `main` after optimisation, the linker would need that symbol and the build
//! would fail with "undefined symbol: hot_path_has_a_reachable_panic". So a
//! successful `cargo build --release` of this example *is* the check.
//!
//! Everything that may legitimately fail (building the models) happens with
//! inputs the optimiser cannot see through (`black_box`), and failures exit
//! through semihosting instead of panicking. The stepped inputs include NaN
//! and infinities, also hidden behind `black_box`.
#![no_std]
#![no_main]

use coil_thermal::{ExplicitStepper, InputLimits, Network, NetworkState, Resistance, Q32};
use core::hint::black_box;
use cortex_m_rt::entry;
use cortex_m_semihosting::debug;

fn network() -> Result<Network<3, 1, 1>, coil_thermal::BuildError> {
    Network::new(black_box([68.7, 40.0, 400.0]))?
        .connect(0, 1, black_box(0.35))?
        .connect(1, 2, black_box(0.8))?
        .connect_boundary(2, 0, black_box(1.5))?
        .joule_source(0, 0, Resistance::HPPA_COIL)
}

#[entry]
fn main() -> ! {
    let ok = match network() {
        Ok(net) => {
            let limits = InputLimits::default();
            match (
                ExplicitStepper::<f32, 3, 1, 1>::new(&net, black_box(1e-3), limits),
                ExplicitStepper::<Q32, 3, 1, 1>::new(&net, black_box(1e-3), limits),
            ) {
                (Ok(float_stepper), Ok(fixed_stepper)) => {
                    let mut state = NetworkState::<f32, 3, 1, 1>::uniform(20.0);
                    let mut fixed_state = NetworkState::<Q32, 3, 1, 1>::uniform(20.0);
                    for k in 0..black_box(1000u32) {
                        let current = black_box([if k % 7 == 0 { f32::NAN } else { 1.0 }]);
                        let ambient = black_box([if k % 11 == 0 { f32::INFINITY } else { 20.0 }]);
                        black_box(float_stepper.step(&mut state, &current, &ambient));
                        let fixed_in = [<Q32 as coil_thermal::Scalar>::from_f32(current[0])];
                        let fixed_amb = [<Q32 as coil_thermal::Scalar>::from_f32(ambient[0])];
                        black_box(fixed_stepper.step(&mut fixed_state, &fixed_in, &fixed_amb));
                    }
                    black_box(&state);
                    black_box(&fixed_state);
                    true
                }
                _ => false,
            }
        }
        Err(_) => false,
    };
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    extern "C" {
        fn hot_path_has_a_reachable_panic() -> !;
    }
    // SAFETY: never executed in a successful build: the symbol does not exist,
    // so the link fails if this handler is reachable at all (see module docs).
    unsafe { hot_path_has_a_reachable_panic() }
}
