//! The grid observer in fixed point (Q32.32) on a Cortex-M0 under QEMU's
//! `microbit` machine (nRF51, 16 KiB of RAM): a 3 x 4 HPPA-parameter grid
//! (the 84-coil grid's configuration and state do not fit 16 KiB in Q32)
//! with its alarm and current limiter, and the instructions of every tick
//! counted.
//!
//! ```text
//! cargo build --profile firmware --features firmware --example observer_m0 --target thumbv6m-none-eabi
//! qemu-system-arm -cpu cortex-m0 -machine microbit -nographic -icount shift=7 \
//!   -semihosting-config enable=on,target=native -kernel target/thumbv6m-none-eabi/firmware/examples/observer_m0
//! ```
//!
//! Coil (1, 2) carries 3.0 A for 30 s, enough for its protective upper bound
//! (the estimate plus the default model-uncertainty margin, 0.65 of the rise)
//! to enter the limiter's taper band. Checks (exit 1 on a mismatch): the Q32
//! temperatures agree with the same grid stepped in `f32` to 5 mK; the Q32
//! limits agree with the `f32` limiter applied to the `f32` upper bound of the
//! `f32` temperatures to 0.02 A; the hot coil's limit is tapered and every
//! other coil's is the full hardware limit. The cost
//! line is printed but not part of the expected output.
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;
use exit::fail;

#[path = "support/cost.rs"]
mod cost;

use coil_thermal::grid::GridConfig;
use coil_thermal::nalgebra::Const;
use coil_thermal::observer::grid::DEFAULT_MARGIN;
use coil_thermal::observer::{GridInputs, GridObserver, ProtectionPlan};
use coil_thermal::protect::alarm::AlarmBuilder;
use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
use coil_thermal::protect::margin::UpperBoundBuilder;
use coil_thermal::{CoilGrid, GridState, Scalar, Q32};
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;

const ROWS: usize = 3;
const COLS: usize = 4;
const N: usize = ROWS * COLS;
const TICKS: u32 = 30_000;
const HOT: (usize, usize) = (1, 2);
/// The hot coil's current \[A\].
const HOT_A: f32 = 3.0;

/// Without an FPU the `f32` time to limit (a division and a short `ln`
/// series per coil, all in software, ~3 800 instructions) is the heaviest
/// stage: one coil per part; the bound (~1 500 per coil) two coils per part,
/// the limiter (~1 350) three. 23 stages, none in the three ticks after an
/// update that prepare its rows of neighbour heat (nearly as heavy as a
/// stage here: `wait_for_rows`), so six per 10 ms update interval: a pass
/// takes about 38 ms, passes run back to back, each on the temperatures of
/// the update before it starts, and the limits lag the model by at most
/// two passes (about 80 ms, against coil time constants of seconds; see
/// `GridObserver`'s docs). Stages on the row ticks made the worst tick
/// 11 344 instructions; nine ticks (two, four, one and two parts) kept
/// every update's own pass, at a worst tick of 15 552.
const M0_PLAN: ProtectionPlan = ProtectionPlan {
    bound_parts: 6,
    time_to_limit_parts: 12,
    alarm_parts: 1,
    limiter_parts: 4,
    wait_for_rows: true,
};

#[entry]
fn main() -> ! {
    cost::paint_stack();
    let Some(mut peripherals) = cortex_m::Peripherals::take() else {
        fail("peripherals")
    };
    let meter = cost::Meter::new(&mut peripherals.SYST);
    match run(&meter) {
        Ok(()) => exit::exit(true),
        Err(what) => fail(what),
    }
}

#[inline(never)]
fn run(meter: &cost::Meter) -> Result<(), &'static str> {
    let config = GridConfig {
        ticks_per_update: 10,
        ..GridConfig::default()
    };
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; N]);
    let observer = GridObserver::<Q32, ROWS, COLS, N>::new(
        &config,
        alarm.build().map_err(|_| "alarm")?,
        LimiterConfig::new([6.0; N], 10.0, 0.0).map_err(|_| "limiter")?,
        4,
    )
    .and_then(|observer| observer.with_protection_plan(M0_PLAN))
    .map_err(|_| "observer")?;
    let reference = CoilGrid::<f32, ROWS, COLS>::new(&config).map_err(|_| "f32 grid")?;
    let reference_limiter =
        LimiterConfig::<f32, Const<N>>::new([6.0; N], 10.0, 0.0).map_err(|_| "f32 limiter")?;
    let reference_alarm = alarm.build::<f32>().map_err(|_| "f32 alarm")?;
    let reference_bound = UpperBoundBuilder::<Const<N>>::new(DEFAULT_MARGIN)
        .build::<f32>()
        .map_err(|_| "f32 bound")?;

    let mut state = observer.state(20.0);
    let mut ref_state = GridState::<f32, ROWS, COLS>::uniform(20.0);
    let mut currents = [[Q32::ZERO; COLS]; ROWS];
    currents[HOT.0][HOT.1] = Q32::from_f32(HOT_A);
    let mut ref_currents = [[0.0f32; COLS]; ROWS];
    ref_currents[HOT.0][HOT.1] = HOT_A;
    let twenty = Q32::from_f64(20.0);

    let mut stats = cost::Stats::default();
    // Per tick after a grid update (0: the update itself).
    let mut phases = [cost::Stats::default(); 10];
    let mut phase = 0usize;
    for _ in 0..TICKS {
        let inputs = GridInputs {
            currents_a: &currents,
            coolant_c: twenty,
            ambient_c: twenty,
            elapsed_us: 1000,
        };
        let (updated, insn) = meter.measure(|| observer.tick(&mut state, &inputs).updated);
        stats.add(insn);
        if updated {
            phase = 0;
        }
        if let Some(stats) = phases.get_mut(phase) {
            stats.add(insn);
        }
        phase += 1;
        reference.tick(&mut ref_state, &ref_currents, 20.0, 20.0);
    }
    // Let the staged protection finish on the last temperatures: the pass
    // under way, then the one it owes the last update.
    for _ in 0..2 * observer.protection_ticks() {
        let inputs = GridInputs {
            currents_a: &currents,
            coolant_c: twenty,
            ambient_c: twenty,
            elapsed_us: 0,
        };
        observer.tick(&mut state, &inputs);
    }
    let run_stack = cost::stack_peak();

    let mut worst_k = 0.0f32;
    for (q_row, f_row) in state.grid.temps_c.iter().zip(&ref_state.temps_c) {
        for (q, f) in q_row.iter().zip(f_row) {
            worst_k = worst_k.max((q.to_f32() - f).abs());
        }
    }
    let mut ref_limits = [CoilLimit::default(); N];
    let Ok(ref_temps) = <&[f32; N]>::try_from(ref_state.temps_c.as_flattened()) else {
        return Err("flatten");
    };
    // The grid observer's margin is taken above the colder of coolant and
    // ambient, both 20 degC here.
    let mut ref_upper = [0.0f32; N];
    reference_bound.upper_c(ref_temps, 20.0, &mut ref_upper);
    reference_limiter.apply(
        &ref_upper,
        &reference_alarm.alarm_limits_c(20.0),
        20.0,
        &mut ref_limits,
    );
    let out = state.outputs();
    let mut worst_a = 0.0f32;
    for (q, f) in out.limits.iter().zip(&ref_limits) {
        worst_a = worst_a.max((q.current_a.to_f32() - f.current_a).abs());
    }
    let hot = HOT.0 * COLS + HOT.1;
    let hot_limit = out.limits[hot].current_a.to_f32();
    let others_full = out
        .limits
        .iter()
        .enumerate()
        .all(|(i, l)| i == hot || l.current_a.to_f32() == 6.0);
    hprintln!(
        "q32 grid after 30 s at {} A: coil ({}, {}) at {} degC (f32 {} degC), max |q32 - f32| {} K",
        HOT_A,
        HOT.0,
        HOT.1,
        out.temps_c[HOT.0][HOT.1].to_f32(),
        ref_state.temps_c[HOT.0][HOT.1],
        worst_k
    );
    hprintln!(
        "limit of the hot coil {} A (f32 {} A), max |q32 - f32| {} A, others full: {}",
        hot_limit,
        ref_limits[hot].current_a,
        worst_a,
        others_full
    );
    let (flash, ram) = cost::image_sizes();
    hprintln!(
        "cost: grid+limiter q32 mean {} worst {} insn; flash {} B ram {} B (static {} B, stack peak {} B)",
        stats.mean(),
        stats.worst(),
        flash,
        ram + run_stack,
        ram,
        run_stack
    );
    for (phase, stats) in phases.iter().enumerate() {
        hprintln!(
            "cost: tick {} after an update: mean {} worst {} insn",
            phase,
            stats.mean(),
            stats.worst()
        );
    }
    let ok = stats.count() == TICKS
        && worst_k < 5e-3
        && worst_a < 0.02
        && hot_limit < 6.0
        && hot_limit > 0.0
        && others_full;
    if ok {
        Ok(())
    } else {
        Err("a check failed")
    }
}
