//! Steps the 84-coil HPPA grid on a Cortex-M4F under QEMU.
//!
//! `cargo run --example grid_qemu --target thumbv7em-none-eabihf --features firmware`
//!
//! Two checks, exit code 0 when both hold: the default HPPA grid (f32,
//! herringbone, R(T), 1 ms ticks, grid update every 10 ticks) heats only the
//! powered coil's neighbourhood, and an adiabatic constant-R grid with all
//! coils at 0.7 A settles at `P Rz` above the coolant (closed form).
#![no_std]
#![no_main]

#[path = "support/exit.rs"]
mod exit;
use exit::fail;

use coil_thermal::grid::{Border, CoilGrid, GridConfig, GridState};
use coil_thermal::Resistance;
use cortex_m_rt::entry;
use cortex_m_semihosting::hprintln;

type Hppa = CoilGrid<f32, 7, 12>;

#[entry]
fn main() -> ! {
    let grid = Hppa::new(&GridConfig {
        ticks_per_update: 10,
        ..GridConfig::default()
    });
    let Ok(grid) = grid else { fail("build") };
    let mut state = GridState::uniform(20.0);
    let mut currents = [[0.0f32; 12]; 7];
    currents[3][5] = 2.0;
    for _ in 0..60_000 {
        grid.tick(&mut state, &currents, 20.0, 20.0);
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
    exit::exit(hottest_ok && steady_ok)
}
