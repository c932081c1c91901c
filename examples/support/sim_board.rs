//! The simulated board of the two firmware crates (`examples/rtic-stm32f4`,
//! `examples/embassy-stm32f4`, each `#[path]`-including it): what a real
//! board does with its drivers, here with a plant in place of the device.
//! Not part of either firmware's own lines: a product replaces it.
//!
//! * The drive asks for 3 A for the first second, then 10 A (an overload),
//!   and applies the demand clamped to the observer's limit; its current
//!   sense reads the applied current exactly.
//! * The plant is the network of `model.toml` stepped by explicit Euler in
//!   `f32`, started 1 K warmer than the observer and with a winding
//!   resistance 5 % above the model's (so the filter has an offset and a heat
//!   bias to find). Its housing is what the thermocouple reads, every
//!   500 ms. It stands in for the device: these are not measurements.
//! * After 6 s, one line on semihosting (estimates, their protective upper
//!   bounds, the plant, the limit, the alarm), and QEMU exits with status 0;
//!   a panic exits with status 1. (The RTIC example runs longer, through
//!   power cycles: its `board.rs`.)

use crate::model::{Inputs, CURRENTS, NODES, NODE_NAMES, SENSORS};
use coil_thermal::observer::network::NetworkOutputs;
use coil_thermal::observer::TimedReading;
use coil_thermal::protect::limiter::CoilLimit;
use coil_thermal::Reading;
use cortex_m_semihosting::{debug, hprint, hprintln};
use panic_semihosting as _;

/// The ambient \[degC\].
pub const AMBIENT_C: f32 = 20.0;
/// The observer's tick \[us\].
pub const TICK_US: u32 = 1000;
const RUN_TICKS: u32 = 6000;
const READING_TICKS: u32 = 500;
const HOUSING: usize = 1;

/// The simulated drive, plant and thermocouple.
pub struct Board {
    ticks: u32,
    applied_a: f32,
    plant_c: [f32; NODES],
}

impl Board {
    /// At rest, the plant 1 K above the ambient.
    pub const fn new() -> Self {
        Self::with_plant([AMBIENT_C + 1.0; NODES])
    }

    /// At rest, the plant at `plant_c` \[degC\] (after a power cycle).
    pub const fn with_plant(plant_c: [f32; NODES]) -> Self {
        Self {
            ticks: 0,
            applied_a: 0.0,
            plant_c,
        }
    }

    /// The plant's temperatures \[degC\].
    pub fn plant_c(&self) -> [f32; NODES] {
        self.plant_c
    }

    /// Ticks since the board was made.
    pub fn ticks(&self) -> u32 {
        self.ticks
    }

    /// One 1 ms period of the drive at its demand clamped to `limits`, and
    /// of the plant it heats.
    pub fn drive(&mut self, limits: &[CoilLimit<f32>; CURRENTS]) {
        self.ticks += 1;
        let demand_a = if self.ticks <= 1000 { 3.0 } else { 10.0 };
        self.applied_a = limits[0].clamp_a(demand_a);
        self.step_plant();
    }

    /// One 1 ms period with the drive off (its supply failing).
    pub fn drive_off(&mut self) {
        self.ticks += 1;
        self.applied_a = 0.0;
        self.step_plant();
    }

    /// `off_s` \[s\] without power: the plant cools.
    pub fn unpowered(&mut self, off_s: u32) {
        self.applied_a = 0.0;
        for _ in 0..off_s * (1_000_000 / TICK_US) {
            self.step_plant();
        }
    }

    /// The plant over one tick at the applied current: model.toml's
    /// network, its resistance 5 % high.
    fn step_plant(&mut self) {
        let [w, h, s] = self.plant_c;
        let r_ohm = 1.05 * 1.2 * (1.0 + 0.00393 * (w - 20.0));
        let power_w = r_ohm * self.applied_a * self.applied_a;
        let (wh, hs, sa) = (1.0 * (w - h), 2.0 * (h - s), 1.5 * (s - AMBIENT_C));
        let dt_s = TICK_US as f32 * 1e-6;
        self.plant_c = [
            w + dt_s * (power_w - wh) / 4.0,
            h + dt_s * (wh - hs) / 60.0,
            s + dt_s * (hs - sa) / 300.0,
        ];
    }

    /// What the thermocouple reads now \[degC\] (at the boot).
    pub fn readings_c(&self) -> [Option<f32>; SENSORS] {
        [Some(self.plant_c[HOUSING])]
    }

    /// What the observer gets this tick: the measured current, the ambient,
    /// and the thermocouple's reading when one is due.
    pub fn inputs(&self) -> Inputs {
        let now_us = self.ticks * TICK_US;
        let reading = TimedReading {
            result: Ok(Reading::new(self.plant_c[HOUSING])),
            sampled_at_us: now_us,
        };
        Inputs {
            currents_a: [self.applied_a],
            boundary_c: [AMBIENT_C],
            readings: [self.ticks.is_multiple_of(READING_TICKS).then_some(reading)],
            now_us,
            elapsed_us: TICK_US,
        }
    }

    /// After the run, prints one line and ends the program.
    pub fn report(&self, out: &NetworkOutputs<NODES, CURRENTS, SENSORS>) {
        if self.ticks < RUN_TICKS {
            return;
        }
        self.print("after", out);
        debug::exit(debug::EXIT_SUCCESS);
    }

    /// Prints one line: `{label} {ticks} ms:`, each node's estimate, upper
    /// bound and plant temperature, the current, its limit and the alarm.
    pub fn print(&self, label: &str, out: &NetworkOutputs<NODES, CURRENTS, SENSORS>) {
        hprint!("{} {} ms:", label, self.ticks);
        for (i, name) in NODE_NAMES.iter().enumerate() {
            let (estimate_c, upper_c) = (out.temps_c[i], out.upper_c[i]);
            hprint!(
                " {} {:.2} degC (upper {:.2}, plant {:.2}),",
                name,
                estimate_c,
                upper_c,
                self.plant_c[i]
            );
        }
        hprintln!(
            " applied {:.2} A, limit {:.2} A, warning {}, predictive {}, shutdown {}",
            self.applied_a,
            out.limits[0].current_a,
            out.alarm.warning,
            out.alarm.predictive,
            out.alarm.shutdown
        );
    }
}
