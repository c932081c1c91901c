//! The Omnimagnet observer's start without history on a Cortex-M4F, under
//! QEMU: `OmniObserver::start` on a hot device, then 20 s of the 1 ms loop
//! during its warm-up (the start's covariance held once per correction
//! period, in slices on the light ticks, the corrections against it),
//! with the instructions of every tick counted, against the same 20 s from
//! `OmniObserver::state` (the steady filter).
//!
//! ```text
//! cargo build --profile firmware --features firmware --example omni_start_m4 --target thumbv7em-none-eabihf
//! qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -icount shift=7 \
//!   -semihosting-config enable=on,target=native -kernel target/thumbv7em-none-eabihf/firmware/examples/omni_start_m4
//! ```
//!
//! Configuration: `observer_m4`'s generated Omnimagnet (`examples/generated/
//! omnimagnet.rs`: 5 ms model step, 1 ms loop, protection every 40 ms in
//! two predictor slices), a `static` in flash. The device: an `f64`
//! reference (the paper's model linearised at 70 degC, 5 ms steps) from a
//! hot state (solenoids near 75 degC, the insulations a little cooler, the
//! core still near the room), all three solenoids at 3 A; the six
//! thermocouples read it every 500 ms.
//!
//! Checks (exit 1 on any mismatch): the start latches nothing and puts the
//! limits in the taper band; the warm-up still runs after 20 s; every
//! reading tick corrects and every reading is fused; the solenoid estimates end within 0.3 K of the
//! reference. The cost lines are printed but not part of the expected
//! output.
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;
use exit::fail;

#[path = "support/cost.rs"]
mod cost;

#[path = "generated/omnimagnet.rs"]
mod omnimagnet_flash;

use coil_thermal::observer::omnimagnet::{
    OmniInputs, OmniObserver, OmniObserverState, OmniWarmUpKind, SensorStatus, TimedReading,
};
use coil_thermal::omnimagnet::{Linearization, Omnimagnet, NODES, THERMOCOUPLE_NODES};
use coil_thermal::Reading;
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use nalgebra::SVector;

const TICKS: u32 = 20_000;
const AMBIENT_C: f64 = 22.0;
const CURRENTS_A: [f64; 3] = [3.0; 3];

#[entry]
fn main() -> ! {
    cost::paint_stack();
    let Some(mut peripherals) = cortex_m::Peripherals::take() else {
        fail("peripherals")
    };
    let meter = cost::Meter::new(&mut peripherals.SYST);
    match run(&meter, &omnimagnet_flash::OBSERVER) {
        Ok(()) => exit::exit(true),
        Err(what) => fail(what),
    }
}

/// What one 20 s run measured.
#[derive(Default)]
struct Measured {
    plain: cost::Stats,
    corrected: cost::Stats,
    refused: u32,
    worst_error_k: f64,
}

#[inline(never)]
fn run(meter: &cost::Meter, omni: &'static OmniObserver) -> Result<(), &'static str> {
    let lin = reference().ok_or("reference linearisation")?;
    let hot = hot_state();
    let readings = THERMOCOUPLE_NODES.map(|n| Some(hot[n] as f32));
    let amb = AMBIENT_C as f32;
    let (mut started, start_insn) =
        meter.measure(|| omni.start(&Omnimagnet::PAPER, &readings, amb));
    let first = *started.outputs();
    let start_ok = !first.alarm.shutdown
        && first
            .limits
            .iter()
            .all(|l| l.current_a > 0.0 && l.current_a < 8.0);
    hprintln!(
        "start: limits {} {} {} A, warming up {}",
        first.limits[0].current_a,
        first.limits[1].current_a,
        first.limits[2].current_a,
        started.warming_up()
    );
    let from_start = ticks(meter, omni, &mut started, &lin, &hot);
    let warming = started.warming_up();
    let mut steady = omni.state(&hot.map(|t| t as f32), amb);
    let from_state = ticks(meter, omni, &mut steady, &lin, &hot);
    hprintln!(
        "after 20 s: warming up {}, refused {}, solenoids within {} K of the reference",
        warming,
        from_start.refused,
        from_start.worst_error_k as f32
    );
    let ok = start_ok
        && warming
        && from_start.corrected.count() == TICKS / 500
        && from_start.refused == 0
        && from_state.refused == 0
        && from_start.worst_error_k < 0.3;
    hprintln!("checks: {}", ok);
    hprintln!(
        "cost: omnimagnet from start (warm-up) mean {} worst {} insn; with correction mean {} worst {} insn",
        from_start.plain.mean(),
        from_start.plain.worst(),
        from_start.corrected.mean(),
        from_start.corrected.worst()
    );
    hprintln!(
        "cost: omnimagnet from state (steady) mean {} worst {} insn; with correction mean {} worst {} insn",
        from_state.plain.mean(),
        from_state.plain.worst(),
        from_state.corrected.mean(),
        from_state.corrected.worst()
    );
    let (flash, ram) = cost::image_sizes();
    hprintln!(
        "cost: start (once) {} insn; state {} B; flash {} B ram {} B (stack peak {} B)",
        start_insn,
        size_of::<OmniObserverState>(),
        flash,
        ram + cost::stack_peak(),
        cost::stack_peak()
    );
    if !ok {
        return Err("a check failed");
    }
    Ok(())
}

/// 20 s of the 1 ms loop on `state`, the reference stepped with the model.
#[inline(never)]
fn ticks<W: OmniWarmUpKind>(
    meter: &cost::Meter,
    omni: &OmniObserver,
    state: &mut OmniObserverState<W>,
    lin: &Linearization,
    hot: &[f64; NODES],
) -> Measured {
    let mut truth = SVector::<f64, NODES>::from_column_slice(hot);
    let mut measured = Measured::default();
    let mut now_us = 0u32;
    for k in 0..TICKS {
        now_us = now_us.wrapping_add(1000);
        let reading_tick = k % 500 == 0;
        let mut readings = [None; 6];
        if reading_tick {
            for (slot, node) in readings.iter_mut().zip(THERMOCOUPLE_NODES) {
                *slot = Some(TimedReading {
                    result: Ok(Reading::new(truth[node] as f32)),
                    sampled_at_us: now_us,
                });
            }
        }
        let inputs = OmniInputs {
            currents_a: CURRENTS_A.map(|a| a as f32),
            ambient_c: AMBIENT_C as f32,
            readings,
            now_us,
            elapsed_us: 1000,
        };
        let ((), insn) = meter.measure(|| {
            omni.tick(state, &inputs);
        });
        let out = state.outputs();
        if out.corrected {
            measured.corrected.add(insn);
        } else {
            measured.plain.add(insn);
        }
        if reading_tick {
            let fused = out
                .sensors
                .iter()
                .filter(|s| matches!(s, SensorStatus::Fused { .. }))
                .count();
            measured.refused += (6 - fused) as u32;
        }
        for _ in 0..out.steps {
            truth = lin.step_current_squared(&truth, &CURRENTS_A, AMBIENT_C);
        }
    }
    let temps = omni.temps_c(state);
    for node in 0..3 {
        let error_k = libm::fabs(f64::from(temps[node]) - truth[node]);
        measured.worst_error_k = measured.worst_error_k.max(error_k);
    }
    measured
}

/// The reference: the paper's model linearised at 70 degC for the
/// observer's 5 ms step.
#[inline(never)]
fn reference() -> Option<Linearization> {
    Omnimagnet::PAPER
        .linearize(&[70.0; NODES], AMBIENT_C, 5e-3)
        .ok()
}

/// A hot device: the solenoids near 75 degC, their insulations 1 to 2 K
/// cooler, the frames and the paper cooler still, the core near the room.
fn hot_state() -> [f64; NODES] {
    [
        75.0, 74.0, 76.0, 70.0, 69.0, 68.0, 60.0, 74.0, 73.0, 73.0, 72.0, 75.0, 72.0, 60.0, 30.0,
        62.0,
    ]
}
