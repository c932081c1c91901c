//! Steps the 84-coil HPPA grid on a Cortex-M4F under QEMU, and counts the
//! instructions of its ticks.
//!
//! ```text
//! cargo build --profile firmware --features firmware --example grid_qemu --target thumbv7em-none-eabihf
//! qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -icount shift=7 \
//!   -semihosting-config enable=on,target=native -kernel target/thumbv7em-none-eabihf/firmware/examples/grid_qemu
//! ```
//!
//! Two checks, exit code 0 when both hold: the default HPPA grid (f32,
//! herringbone, R(T), 1 ms ticks, grid update every 10 ticks) heats only the
//! powered coil's neighbourhood, and an adiabatic constant-R grid with all
//! coils at 0.7 A settles at `P Rz` above the coolant (closed form).
//!
//! The cost lines (not part of the expected output): the bare
//! [`CoilGrid::tick`] of the first check, and the grid observer in
//! `observer_m4`'s configuration (update every 20 ticks, the default
//! protection plan, coil (3, 5) at 2 A and row 1 at 1 A) per tick after an
//! update: tick 0 is the update, ticks 1 to 8 the protection stages.
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;
use exit::fail;

#[path = "support/cost.rs"]
mod cost;

use coil_thermal::grid::{Border, CoilGrid, GridConfig, GridState};
use coil_thermal::observer::{GridInputs, GridObserver, ProtectionPlan};
use coil_thermal::protect::alarm::AlarmBuilder;
use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::limiter::LimiterConfig;
use coil_thermal::Resistance;
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;

type Hppa = CoilGrid<f32, 7, 12>;
/// Ticks per grid update of the observer measured (as in `observer_m4`).
const PHASES: usize = 20;
/// `observer_m4`'s protection plan: 22 stages, none in a tick that
/// prepares a row of the next update (ticks 1 to 7 after one), so 12 per
/// update interval: a pass takes about 37 ticks, passes run back to back,
/// and the limits lag the model by at most two passes (about 80 ms; the
/// fastest coil time constant is seconds).
const M4_PLAN: ProtectionPlan = ProtectionPlan {
    bound_parts: 2,
    time_to_limit_parts: 6,
    alarm_parts: 8,
    limiter_parts: 6,
    wait_for_rows: true,
};

#[entry]
fn main() -> ! {
    cost::paint_stack();
    let Some(mut peripherals) = cortex_m::Peripherals::take() else {
        fail("peripherals")
    };
    let meter = cost::Meter::new(&mut peripherals.SYST);
    let grid = Hppa::new(&GridConfig {
        ticks_per_update: 10,
        ..GridConfig::default()
    });
    let Ok(grid) = grid else { fail("build") };
    let mut state = GridState::uniform(20.0);
    let mut currents = [[0.0f32; 12]; 7];
    currents[3][5] = 2.0;
    let mut bare = cost::Stats::default();
    for _ in 0..60_000 {
        let (_, insn) = meter.measure(|| grid.tick(&mut state, &currents, 20.0, 20.0));
        bare.add(insn);
    }
    let top = state.hottest_k::<3>();
    for t in &top {
        hprintln!(
            "60 s at 2 A: coil ({}, {}) at {} degC",
            t.row,
            t.col,
            t.temp_c
        );
    }
    let hottest_ok = (top[0].row, top[0].col) == (3, 5) && top[0].temp_c > 20.5;

    let flat = Hppa::new(&GridConfig {
        border: Border::Adiabatic,
        resistance: Resistance::constant(5.69),
        tick_dt_s: 1.0,
        ..GridConfig::default()
    });
    let Ok(flat) = flat else {
        fail("build adiabatic")
    };
    let mut state = GridState::uniform(20.0);
    for _ in 0..8_000 {
        flat.tick(&mut state, &[[0.7; 12]; 7], 20.0, 20.0);
    }
    let expected = 20.0 + 5.69 * 0.49 * 5.74;
    let centre = state.temps_c[3][5];
    hprintln!(
        "all on, adiabatic: {} degC (P Rz: {} degC)",
        centre,
        expected
    );
    let steady_ok = (centre - expected).abs() < 1e-3;
    hprintln!(
        "cost: CoilGrid::tick (84 coils, update every 10) mean {} worst {} insn",
        bare.mean(),
        bare.worst()
    );
    let counted = observer_cost(&meter, ProtectionPlan::DEFAULT, false)
        && observer_cost(&meter, M4_PLAN, true);
    let (flash, ram) = cost::image_sizes();
    let stack = cost::stack_peak();
    hprintln!(
        "cost: flash {} B ram {} B (static {} B, stack peak {} B)",
        flash,
        ram + stack,
        ram,
        stack
    );
    exit::exit(hottest_ok && steady_ok && counted)
}

/// The grid observer of `observer_m4` alone with the protection cut as
/// `plan` says, its cost per tick after an update when `phases`; `true`
/// when every tick was counted.
#[inline(never)]
fn observer_cost(meter: &cost::Meter, plan: ProtectionPlan, phases: bool) -> bool {
    let config = GridConfig {
        ticks_per_update: PHASES as u32,
        ..GridConfig::default()
    };
    let Ok(alarm) = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 84]).build::<f32>()
    else {
        fail("alarm")
    };
    let Ok(limiter) = LimiterConfig::new([3.0; 84], 10.0, 0.0) else {
        fail("limiter")
    };
    let observer = GridObserver::<f32, 7, 12, 84>::new(&config, alarm, limiter, 4)
        .and_then(|observer| observer.with_protection_plan(plan));
    let Ok(observer) = observer else {
        fail("observer")
    };
    let mut state = observer.state(22.0);
    let mut currents = [[0.0f32; 12]; 7];
    currents[3][5] = 2.0;
    currents[1] = [1.0; 12];
    let mut all = cost::Stats::default();
    let mut by_phase = [cost::Stats::default(); PHASES];
    let mut phase = 0usize;
    for k in 0..20_000u32 {
        let inputs = GridInputs {
            currents_a: &currents,
            coolant_c: 22.0,
            ambient_c: 22.0,
            elapsed_us: if k % 2 == 0 { 1_100 } else { 900 },
        };
        let (updated, insn) = meter.measure(|| observer.tick(&mut state, &inputs).updated);
        if updated {
            phase = 0;
        }
        all.add(insn);
        if let Some(stats) = by_phase.get_mut(phase) {
            stats.add(insn);
        }
        phase += 1;
    }
    hprintln!(
        "cost: grid observer (84 coils, update every 20, protection in {} ticks) mean {} worst {} insn",
        plan.ticks(),
        all.mean(),
        all.worst()
    );
    if phases {
        for (phase, stats) in by_phase.iter().enumerate() {
            hprintln!(
                "cost: tick {} after an update: mean {} worst {} insn",
                phase,
                stats.mean(),
                stats.worst()
            );
        }
    }
    all.count() == 20_000
}
