//! The observers in the 1 ms loop of a Cortex-M4F, under QEMU: the 84-coil
//! HPPA grid and an Omnimagnet (the 19-state steady-state Kalman filter fed
//! by six thermocouples) with their protection, on a 20 s trace segment, with the
//! instructions of every tick counted.
//!
//! ```text
//! cargo build --profile firmware --features firmware --example observer_m4 --target thumbv7em-none-eabihf
//! qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -icount shift=7 \
//!   -semihosting-config enable=on,target=native -kernel target/thumbv7em-none-eabihf/firmware/examples/observer_m4
//! ```
//!
//! Configuration: the grid accounts Joule energy every 1 ms tick and
//! updates its temperatures every 20 ms; the Omnimagnet accounts each
//! solenoid's `I^2` every tick, steps its model every 5 ms on the mean,
//! and refreshes its limits and times to limit every 40 ms, 5 ms after a
//! grid update, its predictor in two slices of at most five nodes
//! (`docs/cost.md` gives the figures). Both configurations are generated
//! on the host (`examples/generated/`, by `coil-thermal codegen --device
//! omnimagnet` and `--device hppa-grid`) and assembled by the compiler:
//! `static`s in flash, ticked by reference; only the states are in RAM.
//! The grid's protection runs in 22 stages, none in a tick that prepares a
//! row of the next update (ticks 1 to 7 after one): 12 stages per 20 ms
//! update interval; a pass takes about 37 ms, passes run back to back, and
//! the limits lag the model by at most two passes (about 80 ms; the
//! fastest coil time constant is seconds).
//!
//! The trace segment is synthetic (made here, deterministic): coil (3, 5) at
//! 2 A and row 1 at 1 A on the grid, all three solenoids at 3.8 A on the
//! Omnimagnet; the tick period jitters between 1100 and 900 us, and one tick
//! comes 3.4 ms late, followed by one 0 us later (a catch-up of 3 steps, then
//! none). The thermocouples read an `f64` reference (the same
//! linear model stepped in `f64` from a state 0.5 K hotter on the solenoids
//! than the observer's start) plus fixed offsets, every 500 ms; sensor 5
//! goes open circuit at 10 s, one reading arrives 30 ms late (fused) and one
//! 200 ms late (refused as too old).
//!
//! Checks (exit 1 on any mismatch): the grid observer equals the bare grid
//! stepped as many times; the filter pulls the solenoid estimates to within
//! 0.3 K of the reference; every sensor status is the expected one; no
//! alarm; full current allowed; snapshots of both observers restore
//! exactly, and a corrupted one is refused; a model re-linearised at the
//! final estimate installs without moving it. The cost lines (instructions
//! under `-icount`) are printed but not part of the expected output.
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;
use exit::fail;

#[path = "support/cost.rs"]
mod cost;

// Both configurations, generated on the host by `coil-thermal codegen
// --device omnimagnet` and `--device hppa-grid` and assembled by the
// compiler: `static`s in flash, nothing of them built here.
#[path = "generated/hppa_grid.rs"]
mod grid_flash;
#[path = "generated/omnimagnet.rs"]
mod omnimagnet_flash;

use coil_thermal::observer::omnimagnet::{OmniObserver, SensorStatus, TimedReading};
use coil_thermal::observer::{GridInputs, GridObserver, OmniInputs, SnapshotError};
use coil_thermal::omnimagnet::observer::MeanModel;
use coil_thermal::omnimagnet::{Omnimagnet, NODES, THERMOCOUPLE_NODES};
use coil_thermal::{CoilGrid, GridState, Reading, SensorFault};
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;
use nalgebra::SVector;

type Grid = GridObserver<f32, 7, 12, 84>;
const TICKS: u32 = 20_000;
const AMBIENT_C: f64 = 22.0;
const OFFSETS_K: [f64; 6] = [0.1, -0.1, 0.05, -0.05, 0.15, -0.15];

#[entry]
fn main() -> ! {
    cost::paint_stack();
    let Some(mut peripherals) = cortex_m::Peripherals::take() else {
        fail("peripherals")
    };
    let meter = cost::Meter::new(&mut peripherals.SYST);
    match run(&meter, &grid_flash::OBSERVER, &omnimagnet_flash::OBSERVER) {
        Ok(()) => exit::exit(true),
        Err(what) => fail(what),
    }
}

#[inline(never)]
fn run(
    meter: &cost::Meter,
    grid: &'static Grid,
    omni: &'static OmniObserver,
) -> Result<(), &'static str> {
    // The reference the grid observer is checked against, built here from
    // the configuration the generated one carries.
    let bare = CoilGrid::<f32, 7, 12>::new(grid.grid().config()).map_err(|_| "bare grid")?;

    let lin = reference().ok_or("reference linearisation")?;
    let build_stack = cost::stack_peak();
    cost::paint_stack();
    let depth_at_loop = stack_top() - cortex_m::register::msp::read() as usize;

    let mut currents = [[0.0f32; 12]; 7];
    currents[3][5] = 2.0;
    currents[1] = [1.0; 12];
    let mut gs = grid.state(AMBIENT_C);
    let mut bare_state = GridState::uniform(AMBIENT_C);
    let mut os = omni.state(&[AMBIENT_C as f32; NODES], AMBIENT_C as f32);
    let mut truth = SVector::<f64, NODES>::repeat(AMBIENT_C);
    for node in 0..3 {
        truth[node] += 0.5;
    }
    let omni_currents = [3.8f32; 3];

    let (mut plain, mut corrected) = (cost::Stats::default(), cost::Stats::default());
    let (mut omni_plain, mut omni_corrected) = (cost::Stats::default(), cost::Stats::default());
    let mut omni_after_fault = cost::Stats::default();
    let mut now_us = 0u32;
    let mut steps_total = 0u32;
    let mut statuses_ok = true;
    let mut grid_cost = cost::Stats::default();
    for k in 0..TICKS {
        let elapsed_us = match k {
            7_000 => 3_400,
            7_001 => 0,
            _ if k % 2 == 0 => 1_100,
            _ => 900,
        };
        now_us = now_us.wrapping_add(elapsed_us);
        let mut readings = [None; 6];
        let reading_tick = k % 500 == 499;
        if reading_tick {
            for (j, slot) in readings.iter_mut().enumerate() {
                let temp_c = (truth[THERMOCOUPLE_NODES[j]] + OFFSETS_K[j]) as f32;
                let result = if j == 5 && k > 10_000 {
                    Err(SensorFault::OpenCircuit)
                } else {
                    Ok(Reading::new(temp_c))
                };
                let age_us = match (j, k) {
                    (0, 2_999) => 30_000,
                    (1, 3_999) => 200_000,
                    _ => 0,
                };
                *slot = Some(TimedReading {
                    result,
                    sampled_at_us: now_us.wrapping_sub(age_us),
                });
            }
        }
        let grid_in = GridInputs {
            currents_a: &currents,
            coolant_c: AMBIENT_C as f32,
            ambient_c: AMBIENT_C as f32,
            elapsed_us,
        };
        let omni_in = OmniInputs {
            currents_a: omni_currents,
            ambient_c: AMBIENT_C as f32,
            readings,
            now_us,
            elapsed_us,
        };
        let (steps, grid_insn) = meter.measure(|| grid.tick(&mut gs, &grid_in).steps);
        // Only the tick is counted, not the example's copy of its outputs.
        let ((), omni_insn) = meter.measure(|| {
            omni.tick(&mut os, &omni_in);
        });
        let omni_out = *os.outputs();
        let insn = grid_insn + omni_insn;
        if omni_out.corrected {
            corrected.add(insn);
            omni_corrected.add(omni_insn);
            if k > 10_000 {
                omni_after_fault.add(omni_insn);
            }
        } else {
            plain.add(insn);
            omni_plain.add(omni_insn);
        }
        for _ in 0..steps {
            bare.tick(
                &mut bare_state,
                &currents,
                AMBIENT_C as f32,
                AMBIENT_C as f32,
            );
            truth = lin.step_current_squared(&truth, &[3.8; 3], AMBIENT_C);
        }
        grid_cost.add(grid_insn);
        steps_total += steps;
        if reading_tick {
            statuses_ok &= sensors_as_expected(k, &omni_out.sensors);
        }
    }
    // Let the grid's staged protection finish on the last temperatures:
    // the pass under way, then the one it owes the last update.
    for _ in 0..2 * grid.protection_ticks() {
        let idle = GridInputs {
            currents_a: &currents,
            coolant_c: AMBIENT_C as f32,
            ambient_c: AMBIENT_C as f32,
            elapsed_us: 0,
        };
        grid.tick(&mut gs, &idle);
    }
    let run_stack = cost::stack_peak();

    let g = gs.outputs();
    let o = os.outputs();
    hprintln!(
        "grid: {} steps, hottest coil ({}, {}) at {} degC, limit {} A, time to limit {:?} s, predictive alarm {}",
        steps_total,
        g.hottest.row,
        g.hottest.col,
        g.hottest.temp_c,
        g.limits[3 * 12 + 5].current_a,
        g.time_to_limit_s[3 * 12 + 5],
        g.alarm.predictive
    );
    // 20 000 ticks of 1 ms on average, plus the 1.4 ms of the late pair.
    let grid_ok = steps_total == TICKS + 1
        && gs.grid.temps_c == bare_state.temps_c
        && (g.hottest.row, g.hottest.col) == (3, 5);
    let mut worst_k = 0.0f64;
    for node in 0..3 {
        worst_k = worst_k.max(libm::fabs(o.temps_c[node] as f64 - truth[node]));
    }
    hprintln!(
        "omnimagnet: solenoids {} {} {} degC, reference {} {} {} degC, max error {} K",
        o.temps_c[0],
        o.temps_c[1],
        o.temps_c[2],
        truth[0] as f32,
        truth[1] as f32,
        truth[2] as f32,
        worst_k as f32
    );
    let omni_ok = worst_k < 0.3;
    let protect_ok = !g.alarm.warning
        && !g.alarm.shutdown
        && !o.alarm.warning
        && !o.alarm.shutdown
        && g.limits.iter().all(|l| l.current_a == 3.0)
        && o.limits.iter().all(|l| l.current_a == 8.0);
    hprintln!(
        "checks: grid {}, filter {}, sensors {}, protection {}",
        grid_ok,
        omni_ok,
        statuses_ok,
        protect_ok
    );

    let snapshot_ok = snapshots(grid, &gs, omni, &os);
    hprintln!("snapshots: {}", snapshot_ok);

    // A re-linearisation at the present estimate, made as a background task
    // would (f64, off the tick), installed between two ticks.
    let next = relinearised(omni, &omni.temps_c(&os)).ok_or("re-linearisation")?;
    let before = omni.temps_c(&os);
    let ((), install_insn) = meter.measure(|| {
        if omni.install_model(&mut os, &next).is_err() {
            fail("install");
        }
    });
    let moved_k = omni
        .temps_c(&os)
        .iter()
        .zip(before)
        .fold(0.0f32, |m, (a, b)| m.max(libm::fabsf(a - b)));
    let relinearised_ok = moved_k < 1e-4 && *os.model.origin_c() != *omni.filter().origin_c();
    hprintln!("relinearised model installed: {}", relinearised_ok);
    hprintln!(
        "cost: installing a re-linearised model {} insn",
        install_insn
    );

    hprintln!(
        "cost: grid part (84-coil model and its protection) mean {} worst {} insn",
        grid_cost.mean(),
        grid_cost.worst()
    );
    // What the ticks read or write outside flash: both states. Both
    // configurations are the generated `static`s in flash (checked: their
    // addresses are not in RAM).
    let omni_config = (size_of::<OmniObserver>(), in_flash(omni));
    let grid_config = (size_of::<Grid>(), in_flash(grid));
    let (omni_state, grid_state) = (size_of_val(&os), size_of_val(&gs));
    hprintln!(
        "cost: ram of the running observers {} B (omnimagnet state {} B, grid state {} B; not counted: the configurations in flash, omnimagnet {} B: {}, grid {} B: {}); tick stack {} B",
        omni_state + grid_state,
        omni_state,
        grid_state,
        omni_config.0,
        omni_config.1,
        grid_config.0,
        grid_config.1,
        run_stack.saturating_sub(depth_at_loop)
    );
    let (flash, ram) = cost::image_sizes();
    hprintln!(
        "cost: grid+omni+protect mean {} worst {} insn; with correction mean {} worst {} insn; flash {} B ram {} B (static {} B, stack peak {} B build, {} B ticking)",
        plain.mean(),
        plain.worst(),
        corrected.mean(),
        corrected.worst(),
        flash,
        ram + build_stack.max(run_stack),
        ram,
        build_stack,
        run_stack
    );
    hprintln!(
        "cost: omnimagnet part mean {} worst {} insn; with correction mean {} worst {} insn, after the sensor fault mean {} worst {} insn",
        omni_plain.mean(),
        omni_plain.worst(),
        omni_corrected.mean(),
        omni_corrected.worst(),
        omni_after_fault.mean(),
        omni_after_fault.worst()
    );
    if !(grid_ok && omni_ok && statuses_ok && protect_ok && snapshot_ok && relinearised_ok) {
        return Err("a check failed");
    }
    if !(omni_config.1 && grid_config.1) {
        return Err("a configuration is not in flash");
    }
    if corrected.count() != TICKS / 500 {
        return Err("corrections counted");
    }
    Ok(())
}

/// `value` lies below RAM (in the image's flash), not in `.data`, `.bss`
/// or the stack.
fn in_flash<T>(value: &T) -> bool {
    extern "C" {
        static __sdata: u8;
    }
    (value as *const T as usize) < core::ptr::addr_of!(__sdata) as usize
}

/// The top of the stack (its first address above RAM's end).
fn stack_top() -> usize {
    extern "C" {
        static _stack_start: u8;
    }
    core::ptr::addr_of!(_stack_start) as usize
}

/// The model at the estimate `temps_c` \[degC\], as the background task's
/// `Relinearizer` would produce it (here in one call).
#[inline(never)]
fn relinearised(omni: &OmniObserver, temps_c: &[f32; NODES]) -> Option<MeanModel<f32>> {
    let op = temps_c.map(f64::from);
    let lin = Omnimagnet::PAPER
        .linearize(&op, AMBIENT_C, omni.step_s())
        .ok()?;
    omni.prepare_model(&lin).ok()
}

#[inline(never)]
fn reference() -> Option<coil_thermal::omnimagnet::Linearization> {
    Omnimagnet::PAPER
        .linearize(&[AMBIENT_C; NODES], AMBIENT_C, 1e-3)
        .ok()
}

/// Sensor 5 is open from 10 s; sensor 1's reading at 4 s is 200 ms old.
fn sensors_as_expected(k: u32, sensors: &[SensorStatus; 6]) -> bool {
    sensors.iter().enumerate().all(|(j, s)| match (j, k, s) {
        (5, k, SensorStatus::Fault(SensorFault::OpenCircuit)) if k > 10_000 => true,
        (1, 3_999, SensorStatus::TooOld { age_us: 200_000 }) => true,
        (_, _, SensorStatus::Fused { .. }) => !(j == 5 && k > 10_000 || j == 1 && k == 3_999),
        _ => false,
    })
}

fn snapshots(
    grid: &Grid,
    gs: &coil_thermal::observer::GridObserverState<f32, 7, 12, 84>,
    omni: &OmniObserver,
    os: &coil_thermal::observer::OmniObserverState<coil_thermal::observer::omnimagnet::NoWarmUp>,
) -> bool {
    let mut buf = [0u8; coil_thermal::observer::snapshot::snapshot_len(84)];
    let grid_back = grid
        .save(gs, 100, &mut buf)
        .ok()
        .and_then(|_| grid.restore(&buf, 160, 600, AMBIENT_C).ok());
    let grid_ok = grid_back.is_some_and(|s| s.grid.temps_c == gs.grid.temps_c);
    buf[40] ^= 0x10;
    let refused = matches!(
        grid.restore(&buf, 160, 600, AMBIENT_C),
        Err(SnapshotError::CrcMismatch)
    );
    let omni_back = omni
        .save(os, 100, &mut buf)
        .ok()
        .and_then(|_| omni.restore(&buf, 160, 600, AMBIENT_C as f32).ok());
    let omni_ok = omni_back.is_some_and(|s| s.outputs().temps_c == omni.temps_c(os));
    let foreign = grid.restore(&buf, 160, 600, AMBIENT_C).is_err();
    grid_ok && refused && omni_ok && foreign
}
