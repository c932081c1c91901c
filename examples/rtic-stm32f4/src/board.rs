//! The simulated board (not part of the firmware's lines): the drive, the
//! plant and the thermocouple of `examples/support/sim_board.rs` (shared
//! with the embassy example), the 1 ms SysTick, and what outlives a power
//! cycle: a flash (`examples/support/sim_flash.rs`), a real-time clock on
//! its backup battery and the plant's heat. A product's drivers go here.
//!
//! The run is three boots, each a real reset of the MCU (QEMU keeps the
//! RAM the startup code leaves alone, `.uninit`, which stands in for the
//! flash, the RTC and the plant):
//!
//! 1. the first power-on, the flash erased: 12 s of the drive's profile,
//!    then a brown-out warning, the drive off, and the power gone 5 ms
//!    later; off for 10 s, the RTC running;
//! 2. the same 12 s from the restored state; off for 600 s, and the RTC's
//!    battery flat: it has lost its time at the next boot;
//! 3. 6 s from the restored state, then the program ends.
//!
//! Each boot prints the state the firmware starts from against the plant,
//! and each run's end the line of `sim_board.rs`.

use core::mem::MaybeUninit;

use coil_thermal::observer::snapshot::SnapshotError;
use coil_thermal::protect::limiter::CoilLimit;
use cortex_m::peripheral::{syst::SystClkSource, SCB, SYST};
use cortex_m_semihosting::{debug, hprint, hprintln};

use crate::model::{Inputs, Outputs, CURRENTS, NODES, NODE_NAMES, SENSORS};

// Shared with the embassy example, which uses other parts of it.
#[allow(dead_code)]
#[path = "../../support/sim_board.rs"]
mod sim;
pub use sim::{AMBIENT_C, TICK_US};

#[path = "../../support/sim_flash.rs"]
mod flash;
pub use flash::SimFlash;

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

/// One boot's run and the power cycle after it.
struct Run {
    /// Ticks until the brown-out warning (the last run: until the end).
    ticks: u32,
    /// How long the power then stays off \[s\].
    off_s: u32,
    /// Whether the RTC keeps its time through it.
    rtc_keeps_time: bool,
}

static RUNS: [Run; 3] = [
    Run {
        ticks: 12_000,
        off_s: 10,
        rtc_keeps_time: true,
    },
    Run {
        ticks: 12_000,
        off_s: 600,
        rtc_keeps_time: false,
    },
    Run {
        ticks: 6_000,
        off_s: 0,
        rtc_keeps_time: false,
    },
];

/// Ticks the supply holds up after the brown-out warning.
const HOLD_UP_TICKS: u32 = 5;
/// The simulated flash: two pages.
const FLASH_LEN: usize = 2 * SimFlash::PAGE;
/// Marks the retained RAM as written by this program.
const POWERED: u32 = 0xC0FF_EE01;

/// What outlives a power cycle, but the flash.
struct Power {
    /// [`POWERED`] once the first power-on has set the rest.
    magic: u32,
    /// Boots so far.
    boots: u32,
    /// The plant \[degC\].
    plant_c: [f32; NODES],
    /// The RTC's counter \[s\].
    rtc_s: u32,
    /// 1 while the RTC has kept its time since it was set.
    rtc_set: u32,
    /// How long the last power cycle was off \[s\].
    off_s: u32,
}

struct Retained {
    power: Power,
    flash: [u8; FLASH_LEN],
}

// Left alone by the startup code, and by QEMU's reset.
#[link_section = ".uninit.board"]
static mut RETAINED: MaybeUninit<Retained> = MaybeUninit::uninit();

/// The simulated board: the drive, the plant and the thermocouple, the
/// RTC, the supply.
pub struct Board {
    sim: sim::Board,
    power: &'static mut Power,
    run: &'static Run,
    brown_out_at: Option<u32>,
}

/// The board and its flash after a power-on; call once, at the boot.
pub fn power_on() -> (Board, SimFlash<'static>) {
    // SAFETY: `init` calls this once, before any task, so this is the one
    // reference to RETAINED. A `u32` read of whatever the RAM holds is the
    // first power-on's test (every bit pattern is a `u32`).
    let retained = unsafe {
        let ptr = (&raw mut RETAINED).cast::<Retained>();
        if (&raw const (*ptr).power.magic).read_volatile() != POWERED {
            ptr.write(Retained {
                power: Power {
                    magic: POWERED,
                    boots: 0,
                    plant_c: sim::Board::new().plant_c(),
                    rtc_s: 0,
                    rtc_set: 1,
                    off_s: 0,
                },
                flash: [0xFF; FLASH_LEN],
            });
        }
        &mut *ptr
    };
    let (power, flash) = (&mut retained.power, &mut retained.flash);
    power.boots += 1;
    let run = &RUNS[(power.boots as usize - 1).min(RUNS.len() - 1)];
    let board = Board {
        sim: sim::Board::with_plant(power.plant_c),
        power,
        run,
        brown_out_at: None,
    };
    let flash = SimFlash::new(flash).expect("whole pages");
    (board, flash)
}

impl Board {
    /// The RTC's time \[s\], when it has kept it through the power-off.
    pub fn rtc_s(&self) -> Option<u32> {
        (self.power.rtc_set == 1).then_some(self.power.rtc_s)
    }

    /// The clock that stamps the snapshots \[s\]: the RTC's counter (from
    /// 0 again after it lost its time).
    pub fn clock_s(&self) -> u32 {
        self.power.rtc_s
    }

    /// What the thermocouple reads now \[degC\].
    pub fn readings_c(&self) -> [Option<f32>; SENSORS] {
        self.sim.readings_c()
    }

    /// One 1 ms period of the drive at its demand clamped to `limits` (off
    /// after the brown-out warning), of the plant it heats and of the RTC;
    /// the power cycle once the supply is gone.
    pub fn drive(&mut self, limits: &[CoilLimit<f32>; CURRENTS]) {
        match self.brown_out_at {
            None => self.sim.drive(limits),
            Some(at) if self.sim.ticks() < at + HOLD_UP_TICKS => self.sim.drive_off(),
            Some(_) => self.power_cycle(),
        }
        if self.sim.ticks().is_multiple_of(1000) {
            self.power.rtc_s += 1;
        }
    }

    /// What the observer gets this tick.
    pub fn inputs(&self) -> Inputs {
        self.sim.inputs()
    }

    /// At the end of the run, prints its line; then the brown-out warning
    /// (the run's last) or the program's end.
    pub fn report(&mut self, out: &Outputs) {
        if self.sim.ticks() != self.run.ticks {
            return;
        }
        if self.run.off_s == 0 {
            self.sim.print("after", out);
            debug::exit(debug::EXIT_SUCCESS);
        }
        self.sim.print("brown-out after", out);
        self.brown_out_at = Some(self.sim.ticks());
    }

    /// Whether the brown-out warning came this tick (a product: the PVD's
    /// interrupt, or its flag).
    pub fn brown_out(&self) -> bool {
        self.brown_out_at == Some(self.sim.ticks())
    }

    /// Prints the state the firmware starts from against the plant, and a
    /// refused snapshot's reason.
    pub fn report_boot(&self, out: &Outputs, refused: Option<SnapshotError>) {
        match (self.power.boots, self.rtc_s()) {
            (1, _) => hprint!("boot 1 (first power-on, the flash erased):"),
            (boot, Some(_)) => hprint!(
                "boot {} (off {} s, the RTC kept its time):",
                boot,
                self.power.off_s
            ),
            (boot, None) => hprint!(
                "boot {} (off {} s, the RTC lost its time):",
                boot,
                self.power.off_s
            ),
        }
        let plant_c = self.sim.plant_c();
        for (i, name) in NODE_NAMES.iter().enumerate() {
            hprint!(
                " {} {:.2} degC (upper {:.2}, plant {:.2}),",
                name,
                out.temps_c[i],
                out.upper_c[i],
                plant_c[i]
            );
        }
        hprint!(
            " limit {:.2} A, shutdown {}",
            out.limits[0].current_a,
            out.alarm.shutdown
        );
        match refused {
            Some(why) => hprintln!(", snapshot refused: {}", why),
            None => hprintln!(),
        }
    }

    /// The supply is gone: the plant cools over the run's off time, the
    /// RTC runs on or loses its time, and the MCU starts again.
    fn power_cycle(&mut self) -> ! {
        let off_s = self.run.off_s;
        self.sim.unpowered(off_s);
        self.power.plant_c = self.sim.plant_c();
        self.power.off_s = off_s;
        if self.run.rtc_keeps_time {
            self.power.rtc_s += off_s;
        } else {
            (self.power.rtc_s, self.power.rtc_set) = (0, 0);
        }
        SCB::sys_reset()
    }
}
