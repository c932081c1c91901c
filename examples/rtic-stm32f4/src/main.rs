//! The observer of `model.rs` ticked every 1 ms from an RTIC 2 hardware task
//! bound to SysTick, on an STM32F405 (runs in QEMU's netduinoplus2). This
//! file is the whole firmware; `board.rs` stands in for the hardware (the
//! drive and its current sense, a thermocouple on a simulated plant, the
//! semihosting output) and is what a real board replaces with its drivers.
#![no_std]
#![no_main]

mod board;
mod model;

#[rtic::app(device = stm32f4::stm32f405, peripherals = false)]
mod app {
    use crate::board::{self, Board};
    use crate::model::{initial_state, observer, Observer, State};

    #[shared]
    struct Shared {}

    #[local]
    struct Local {
        observer: Observer,
        state: State,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        // From the generated tables: nothing is solved on the MCU.
        let observer = observer().expect("the model builds");
        let state = initial_state(&observer, board::AMBIENT_C);
        board::start_systick_1ms(cx.core.SYST);
        (Shared {}, Local { observer, state })
    }

    #[task(binds = SysTick, local = [observer, state, board: Board = Board::new()])]
    fn tick(cx: tick::Context) {
        let (observer, state, board) = (cx.local.observer, cx.local.state, cx.local.board);
        // The drive clamps its command to the limits of the last tick.
        board.drive(&state.outputs().limits);
        let out = observer.tick(state, &board.inputs());
        board.report(out);
    }
}
