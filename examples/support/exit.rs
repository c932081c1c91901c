//! How every firmware example ends: semihosting exit codes that QEMU passes
//! on as its own, so CI sees success, a failed check, a panic or a hard fault.

use cortex_m_rt::{exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hprintln};

/// Ends the run with status 0 (`ok`) or 1.
pub fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    // Only reached outside QEMU (no debugger attached): park the core.
    loop {
        cortex_m::asm::wfi();
    }
}

/// Prints why and ends the run with status 1.
#[allow(dead_code)] // not every example has a failure path of its own
pub fn fail(what: &str) -> ! {
    hprintln!("failed: {}", what);
    exit(false)
}

#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    exit(false)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("panic: {}", info);
    exit(false)
}
