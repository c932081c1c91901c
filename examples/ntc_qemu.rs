//! An NTC thermistor read through the ADC of a simulated board, on a
//! Cortex-M4F under QEMU (issue 38, item 5): the firmware observer that
//! `coil-thermal codegen` generates from
//! `host-tests/models/drive-3node-ntc.toml` (`examples/generated/drive_3node_ntc.rs`:
//! a 10 kohm B3950 NTC on the housing, 10 kohm pull-up, 12-bit ADC), fed
//! through the module's `convert_counts`, the library's
//! `ResistiveInput::convert`.
//!
//! QEMU's `mps2-an386` models no usable ADC, so the example has its own
//! [`SimAdc`]: it turns the plant's housing temperature into the count a
//! ratiometric 12-bit ADC reads at the divider's node, by the NTC's beta
//! equation and the divider written out here (not the library's inverse).
//! The plant is the model file's network stepped by explicit Euler in
//! `f32`, its winding resistance 5 % above the model's. At 4 A, then 2 A
//! from 300 s, the ADC is read once a second; from 150 s to 210 s the NTC's
//! wire is open: the node sits at the reference (count 4095), which the
//! conversion reports as `OpenCircuit` and the observer as a sensor fault,
//! never as a temperature, and the estimate runs on the model meanwhile.
//!
//! ```text
//! cargo build --profile firmware --features firmware --example ntc_qemu --target thumbv7em-none-eabihf
//! qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -icount shift=7 \
//!   -semihosting-config enable=on,target=native -kernel target/thumbv7em-none-eabihf/firmware/examples/ntc_qemu
//! ```
//!
//! Each line: the time, the current, the ADC count and what the conversion
//! made of it, the observer's view of the sensor, and the housing's and
//! the winding's estimate against the plant. It exits 0 when every open
//! count was a fault, the winding's estimate moved no further than 0.25 K
//! from the plant's beyond where the episode found it, and ended within
//! 0.5 K.
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;
use exit::fail;

#[path = "generated/drive_3node_ntc.rs"]
mod model;

use coil_thermal::observer::{SensorStatus, TimedReading};
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;

/// The ambient \[degC\].
const AMBIENT_C: f32 = 25.0;
/// The observer's tick \[us\] (the model's `step_us`).
const TICK_US: u32 = 1000;
/// Ticks between ADC reads (1 s, the model's `correction_period_s`).
const READ_TICKS: u32 = 1000;
/// The run \[s\].
const RUN_S: u32 = 480;
/// The open-circuit episode \[s\].
const OPEN_S: (u32, u32) = (150, 210);

/// The simulated ADC: a 12-bit ratiometric converter on the node of a
/// 10 kohm pull-up and the NTC to ground (the model file's divider).
struct SimAdc {
    open: bool,
}

impl SimAdc {
    /// The count at `temp_c` \[degC\]: the NTC by its beta equation
    /// `R = R25 exp(B (1/T - 1/T25))`, the node at `R / (R + R_ref)` of the
    /// reference, rounded to the nearest code and held below 4096. An open
    /// NTC leaves the node at the reference: the top code.
    fn read(&self, temp_c: f32) -> u32 {
        if self.open {
            return 4095;
        }
        let (r25_ohm, beta_k, r_ref_ohm) = (10_000.0_f32, 3950.0_f32, 10_000.0_f32);
        let r_ohm = r25_ohm * libm::expf(beta_k * (1.0 / (temp_c + 273.15) - 1.0 / 298.15));
        let counts = libm::roundf(4096.0 * r_ohm / (r_ohm + r_ref_ohm));
        (counts as u32).min(4095)
    }
}

/// The plant: the model's network (winding, housing, heatsink), its
/// winding resistance 5 % above the model's.
struct Plant {
    temps_c: [f32; 3],
}

impl Plant {
    fn step(&mut self, current_a: f32, dt_s: f32) {
        let [w, h, s] = self.temps_c;
        let r_ohm = 1.05 * (1.10568 + 0.004716 * w);
        let power_w = r_ohm * current_a * current_a;
        let (wh, hs, sa) = (
            0.911_942_2 * (w - h),
            2.300_547 * (h - s),
            1.0568617 * (s - AMBIENT_C),
        );
        self.temps_c = [
            w + dt_s * (power_w - wh) / 69.12866,
            h + dt_s * (wh - hs) / 365.08216,
            s + dt_s * (hs - sa) / 912.43755,
        ];
    }
}

#[entry]
fn main() -> ! {
    let Ok(observer) = model::observer() else {
        fail("the generated parts were refused")
    };
    let mut plant = Plant {
        temps_c: [AMBIENT_C; 3],
    };
    let mut adc = SimAdc { open: false };
    // The first read starts the observer (no snapshot: a first boot).
    let first = model::convert_counts(0, adc.read(plant.temps_c[1]));
    let Some(Ok(first)) = first else {
        fail("the first reading is a fault")
    };
    let mut state = model::start_state(&observer, &[Some(first.temp_c)], AMBIENT_C);
    let mut inputs = model::Inputs {
        currents_a: [0.0],
        boundary_c: [AMBIENT_C],
        readings: [None],
        now_us: 0,
        elapsed_us: TICK_US,
    };
    let (mut open_faults, mut open_reads, mut worst_open_k) = (0, 0, 0.0_f32);
    // The winding's error when the wire opens: the episode must not add
    // to it (the model carries the estimate, no fault is fused).
    let mut onset_error_k = f32::INFINITY;
    let mut ticks: u32 = 0;
    let mut end_error_k = f32::INFINITY;
    while ticks < RUN_S * 1000 {
        ticks += 1;
        let t_s = ticks / 1000;
        let current_a = if t_s < 300 { 4.0 } else { 2.0 };
        plant.step(current_a, TICK_US as f32 * 1e-6);
        adc.open = (OPEN_S.0..OPEN_S.1).contains(&t_s);
        inputs.now_us = ticks.wrapping_mul(TICK_US);
        inputs.currents_a = [current_a];
        let read = ticks.is_multiple_of(READ_TICKS);
        let counts = adc.read(plant.temps_c[1]);
        inputs.readings = [None];
        if read {
            let Some(result) = model::convert_counts(0, counts) else {
                fail("sensor 0 has no ADC conversion")
            };
            if adc.open {
                open_reads += 1;
                if result == Err(coil_thermal::SensorFault::OpenCircuit) {
                    open_faults += 1;
                }
            }
            inputs.readings = [Some(TimedReading {
                result,
                sampled_at_us: inputs.now_us,
            })];
        }
        let out = observer.tick(&mut state, &inputs);
        let winding_error_k = out.temps_c[0] - plant.temps_c[0];
        if adc.open {
            worst_open_k = worst_open_k.max(libm::fabsf(winding_error_k));
        } else if t_s < OPEN_S.0 {
            onset_error_k = libm::fabsf(winding_error_k);
        }
        end_error_k = libm::fabsf(winding_error_k);
        if read && (t_s.is_multiple_of(60) || t_s == OPEN_S.0 + 1 || t_s == OPEN_S.1) {
            let conversion = model::convert_counts(0, counts);
            let status = match out.sensors[0] {
                SensorStatus::Fused { .. } => "fused",
                SensorStatus::Fault(_) => "fault",
                SensorStatus::Rejected { .. } => "rejected",
                _ => "other",
            };
            match conversion {
                Some(Ok(r)) => hprintln!(
                    "t={:3} s I={:.1} A adc {:4} -> {:6.2} degC ({}) housing est {:6.2} plant {:6.2}  winding est {:6.2} plant {:6.2}",
                    t_s, current_a, counts, r.temp_c, status,
                    out.temps_c[1], plant.temps_c[1], out.temps_c[0], plant.temps_c[0]
                ),
                Some(Err(fault)) => hprintln!(
                    "t={:3} s I={:.1} A adc {:4} -> fault {:?} ({}) housing est {:6.2} plant {:6.2}  winding est {:6.2} plant {:6.2}",
                    t_s, current_a, counts, fault, status,
                    out.temps_c[1], plant.temps_c[1], out.temps_c[0], plant.temps_c[0]
                ),
                None => fail("sensor 0 has no ADC conversion"),
            }
        }
    }
    hprintln!(
        "open circuit: {} of {} reads a fault; winding {:.2} K off the plant when it opened, at most {:.2} K through it, {:.2} K at the end",
        open_faults,
        open_reads,
        onset_error_k,
        worst_open_k,
        end_error_k
    );
    exit::exit(
        open_reads > 0
            && open_faults == open_reads
            && worst_open_k < onset_error_k + 0.25
            && end_error_k < 0.5,
    )
}
