//! The simulated board (not part of the firmware's 30 lines), shared with
//! the embassy example (`examples/support/sim_board.rs`), and the 1 ms
//! SysTick: a product's drivers go here.

use cortex_m::peripheral::{syst::SystClkSource, SYST};

#[path = "../../support/sim_board.rs"]
mod sim;
pub use sim::*;

/// The core clock SysTick counts \[Hz\]: QEMU's netduinoplus2 runs the
/// STM32F405 at 168 MHz from reset. A real board runs at 16 MHz (HSI) until
/// its firmware sets up the PLL: use the HCLK the clock tree gives.
pub const CORE_HZ: u32 = 168_000_000;

/// Starts SysTick: an interrupt every [`TICK_US`] on the core clock.
pub fn start_systick_1ms(mut syst: SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(CORE_HZ / 1_000_000 * TICK_US - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
}
