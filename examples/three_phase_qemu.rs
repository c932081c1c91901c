//! README's three-phase walkthrough on a Cortex-M4F, under QEMU: the
//! observer `coil-thermal codegen` generated from
//! `host-tests/models/three-phase-1tc-fitted.toml` (three phases and a
//! housing, one housing thermocouple, no `bias_sources`) ticked at 1 ms over
//! the held-out bench hour (`support/three_phase.rs`). The host test
//! `host-tests/tests/three_phase_walkthrough.rs` runs the same replay
//! through the same module and must print the same lines
//! (`three_phase_qemu.expected`, which CI compares with this firmware's
//! output); the phases it estimates are scored against the bench's phase
//! thermocouples, which it never sees.
//!
//! ```text
//! cargo build --profile firmware --features firmware --example three_phase_qemu --target thumbv7em-none-eabihf
//! qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -icount shift=7 \
//!   -semihosting-config enable=on,target=native -kernel target/thumbv7em-none-eabihf/firmware/examples/three_phase_qemu
//! ```
//!
//! The `cost:` line is printed but not compared.
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;
use exit::fail;

#[path = "support/cost.rs"]
mod cost;

#[path = "support/host_out.rs"]
mod host_out;
use host_out::Host;

#[path = "generated/three_phase_1tc.rs"]
mod model;

#[path = "support/three_phase.rs"]
mod three_phase;

use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;

#[entry]
fn main() -> ! {
    let Some(mut peripherals) = cortex_m::Peripherals::take() else {
        fail("peripherals taken twice")
    };
    cost::paint_stack();
    let meter = cost::Meter::new(&mut peripherals.SYST);
    // The generated module's observer, assembled by the compiler (a
    // `static` in flash).
    let observer = &model::OBSERVER;
    let mut ticks = cost::Stats::default();
    let summary = three_phase::replay(observer, &mut Host, |tick| {
        let (_steps, n) = meter.measure(&mut *tick);
        ticks.add(n);
    });
    let Ok(summary) = summary else { fail("replay") };
    let (flash, ram) = cost::image_sizes();
    hprintln!(
        "cost: three-phase observer (4 nodes, 3 currents, 1 sensor) tick mean {} worst {} instructions over {} ticks; stack {} B; flash {} B, static RAM {} B",
        ticks.mean(),
        ticks.worst(),
        ticks.count(),
        cost::stack_peak(),
        flash,
        ram
    );
    exit::exit(summary.worst_phase_error_k < 1.0 && summary.worst_cold_miss_k < 0.0)
}
