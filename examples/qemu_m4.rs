//! Firmware smoke test for the Cortex-M4F under QEMU.
#![no_std]
#![no_main]

use coil_thermal::Scalar;
use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hprintln};

#[entry]
fn main() -> ! {
    let x = f32::from_f64(2.0).sqrt();
    hprintln!("sqrt2 = {}", x);
    let ok = (x - 1.414_213_5).abs() < 1e-6;
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {}
}

#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    debug::exit(debug::EXIT_FAILURE);
    loop {}
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    loop {}
}
