//! The observer of `model.rs` ticked every 1 ms from an RTIC 2 hardware task
//! bound to SysTick, on an STM32F405 (runs in QEMU's netduinoplus2), its
//! state kept through power cycles in flash (`persist.rs`). This file is
//! the whole firmware; `board.rs` stands in for the hardware (the drive
//! and its current sense, a thermocouple on a simulated plant, a flash, an
//! RTC, the supply, the semihosting output) and is what a real board
//! replaces with its drivers.
#![no_std]
#![no_main]

mod board;
mod model;
mod persist;

#[rtic::app(device = stm32f4::stm32f405, peripherals = false, dispatchers = [SPI1])]
mod app {
    use crate::board::{self, Board, SimFlash, AMBIENT_C};
    use crate::model::{
        observer, restore_state, save_snapshot, start_state, Observer, OffTime, State, SNAPSHOT_LEN,
    };
    use crate::persist::{Saved, Store, MAX_AGE_S, SAVE_EVERY_TICKS};

    #[shared]
    struct Shared {}

    #[local]
    struct Local {
        observer: Observer,
        state: State,
        board: Board,
        store: Store<SimFlash<'static>>,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        // From the generated tables: nothing is solved on the MCU.
        let observer = observer().expect("the model builds");
        let (board, flash) = board::power_on();
        let mut store = Store::new(flash);
        // The last snapshot cooled over the off time: the RTC's if it was
        // saved at the power-off, else the least the thermocouple allows.
        // None, or refused: the safe start without history.
        let readings_c = board.readings_c();
        let (state, refused) = match store.load() {
            Some((snapshot, saved)) => {
                let off = match (saved, board.rtc_s()) {
                    (Saved::PowerOff, Some(now_s)) => OffTime::SinceSave { now_s },
                    _ => OffTime::Unknown,
                };
                restore_state(&observer, &snapshot, off, MAX_AGE_S, &readings_c, AMBIENT_C)
            }
            None => (start_state(&observer, &readings_c, AMBIENT_C), None),
        };
        board.report_boot(state.outputs(), refused);
        board::start_systick_1ms(cx.core.SYST);
        let local = Local {
            observer,
            state,
            board,
            store,
        };
        (Shared {}, local)
    }

    #[task(binds = SysTick, priority = 2, local = [observer, state, board])]
    fn tick(cx: tick::Context) {
        let (observer, state, board) = (cx.local.observer, cx.local.state, cx.local.board);
        // The drive clamps its command to the limits of the last tick.
        board.drive(&state.outputs().limits);
        let out = observer.tick(state, &board.inputs());
        board.report(out);
        // A snapshot at the brown-out warning and every SAVE_EVERY_TICKS,
        // for the flash task to store off the tick.
        let saved = if board.brown_out() {
            Saved::PowerOff
        } else if out.tick % SAVE_EVERY_TICKS == 0 {
            Saved::Periodic
        } else {
            return;
        };
        let mut snapshot = [0; SNAPSHOT_LEN];
        save_snapshot(observer, state, board.clock_s(), &mut snapshot);
        // Busy with the last one: this one is dropped, the next comes.
        let _ = save::spawn(snapshot, saved);
    }

    #[task(priority = 1, local = [store])]
    async fn save(cx: save::Context, snapshot: [u8; SNAPSHOT_LEN], saved: Saved) {
        // A failed save leaves the last good record the newest.
        let _ = cx.local.store.save(&snapshot, saved);
    }
}
