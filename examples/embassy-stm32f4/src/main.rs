//! The observer of `model.rs` ticked every 1 ms by an embassy `Ticker` in a
//! task on an `InterruptExecutor` (the UART4 interrupt, unused otherwise,
//! at priority 6), so every tick runs in interrupt context, above anything
//! thread mode does. STM32F405; embassy-time runs on TIM2.
//! `board.rs` stands in for the hardware as in the RTIC example.
//!
//! Built in CI, not run: under QEMU (7.2, `-machine netduinoplus2`)
//! `embassy_stm32::init` waits forever for the RCC's `HSIRDY` flag
//! (`rcc/f247.rs`), since QEMU's STM32F405 has no RCC model (its registers
//! read as zero). On a board, `cargo run --release` with a probe-rs runner
//! instead of the QEMU one in `.cargo/config.toml`.
#![no_std]
#![no_main]

mod board;
mod model;

use board::Board;
use cortex_m_rt::entry;
use embassy_executor::InterruptExecutor;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_time::{Duration, Ticker};
use model::{observer, start_state, Observer, State};

static OBSERVER_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART4() {
    // SAFETY: the executor was started on this interrupt.
    unsafe { OBSERVER_EXECUTOR.on_interrupt() }
}

#[embassy_executor::task]
async fn observe(observer: Observer, mut state: State, mut board: Board) {
    let mut ticker = Ticker::every(Duration::from_micros(board::TICK_US.into()));
    loop {
        ticker.next().await;
        // The drive clamps its command to the limits of the last tick.
        board.drive(&state.outputs().limits);
        let out = observer.tick(&mut state, &board.inputs());
        board.report(out);
    }
}

#[entry]
fn main() -> ! {
    let _peripherals = embassy_stm32::init(Default::default());
    // From the generated tables: nothing is solved on the MCU.
    let observer = observer().expect("the model builds");
    // The safe start without history, from what the thermocouple reads
    // (the RTIC example also keeps the state through power cycles).
    let board = Board::new();
    let state = start_state(&observer, &board.readings_c(), board::AMBIENT_C);
    interrupt::UART4.set_priority(Priority::P6);
    let spawner = OBSERVER_EXECUTOR.start(interrupt::UART4);
    spawner.spawn(observe(observer, state, board).expect("one observer task"));
    loop {
        // Thread mode has nothing else to do here.
        cortex_m::asm::wfi();
    }
}
