//! The grid's first 15 minutes against the report's own fits of its four
//! calibration runs (hppa-coil-grid.md: all coils, one row, one line, one
//! coil, 0.7 A per powered coil, from 20 degC).
//!
//! A protection that is right at steady state but slow in the transient is
//! cold exactly when a drive pushes a short overload, so the hottest coil of
//! the library's default grid must never run more than 5 % below any of the
//! report's fits of a run over its first 900 s. The fits, evaluated outside
//! the library's stepper:
//!
//! * all coils on: the report's single-node fit of that run (`Rtot`
//!   5.49 K/W, `Ctot` 59.4 J/K), in closed form with the same `R(T)`;
//! * every pattern: the RC-network stepwise fit (8.76, 2.83, 5.47 K/W,
//!   57.5 J/K) and global fit (14.1, 3.02, 5.32 K/W, 56.4 J/K), both fitted
//!   by the report to all four runs, read per element (between coils is
//!   twice: `grid::params`), on the independent dense RK4 reference
//!   (`grid_reference.rs`).
//!
//! Steady states are not the subject here (the capacity does not enter
//! them), but the same table shows they did not move: the hottest coil's
//! steady rise stays at or above every fit's, and within 15 % of the RC fits'
//! (`grid::tests::the_fitted_sets_predict_the_calibration_patterns_alike`).
//!
//! `cargo test --release -p coil-thermal-host --test grid_transient -- --nocapture`
//! prints the table of docs/validation.md.

use coil_thermal::grid::{CoilGrid, GridConfig, GridParams, GridState, Stencil};
use coil_thermal_host::grid_reference::{GridReference, ReferenceParams};

const ROWS: usize = 7;
const COLS: usize = 12;
const START_C: f64 = 20.0;
const CURRENT_A: f64 = 0.7;
/// The window the transient is judged over \[s\].
const WINDOW_S: usize = 900;
/// How far below a fit the model may run in the window.
const BAND: f64 = 0.05;
/// The HPPA resistance fit, `R(T) = 0.026 T + 5.166` ohm.
const R_AT_0C_OHM: f64 = 5.166;
const SLOPE_OHM_PER_K: f64 = 0.026;

type Pattern = fn(usize, usize) -> bool;

/// The report's four calibration patterns on the 7 x 12 grid (the same
/// coils as the committed calibration traces).
const PATTERNS: [(&str, Pattern); 4] = [
    ("all on", |_, _| true),
    ("one row", |row, _| row == 3),
    ("one line", |_, col| col == 5),
    ("one coil", |row, col| (row, col) == (3, 5)),
];

fn currents(pattern: Pattern) -> [f64; ROWS * COLS] {
    std::array::from_fn(|k| {
        if pattern(k / COLS, k % COLS) {
            CURRENT_A
        } else {
            0.0
        }
    })
}

/// One fit's or the model's hottest-coil rise above the start at every
/// second of the window (index = seconds), and its steady rise \[K\].
struct Rise {
    curve_k: Vec<f64>,
    steady_k: f64,
}

fn hottest(temps_c: impl IntoIterator<Item = f64>) -> f64 {
    temps_c.into_iter().fold(f64::MIN, f64::max) - START_C
}

/// The library's grid with `config` at 10 ms ticks, f64.
fn model(config: GridConfig, pattern: Pattern) -> Rise {
    let config = GridConfig {
        tick_dt_s: 0.01,
        ..config
    };
    let grid = CoilGrid::<f64, ROWS, COLS>::new(&config).unwrap();
    let flat = currents(pattern);
    let currents: [[f64; COLS]; ROWS] =
        std::array::from_fn(|r| std::array::from_fn(|c| flat[r * COLS + c]));
    let mut state = GridState::uniform(START_C);
    let mut curve_k = vec![0.0];
    for _ in 0..WINDOW_S {
        for _ in 0..100 {
            grid.tick(&mut state, &currents, START_C, START_C);
        }
        curve_k.push(hottest(state.temps_c.iter().flatten().copied()));
    }
    let net = grid.to_network::<{ ROWS * COLS }>().unwrap();
    let steady = net.steady_state(&flat, &[START_C, START_C]).unwrap();
    Rise {
        curve_k,
        steady_k: hottest(steady),
    }
}

/// A per-element RC-network set of the report on the dense RK4 reference.
fn rc_fit(rx: f64, ry: f64, rz: f64, c: f64, pattern: Pattern) -> Rise {
    let params = ReferenceParams {
        rx_k_per_w: 2.0 * rx,
        ry_k_per_w: 2.0 * ry,
        rz_k_per_w: rz,
        capacity_j_per_k: c,
        ..ReferenceParams::HPPA_FDM
    };
    let reference = GridReference::assemble(ROWS, COLS, &Stencil::HPPA_HERRINGBONE, &params);
    let flat = currents(pattern);
    let mut temps = vec![START_C; reference.coils()];
    let mut curve_k = vec![0.0];
    for _ in 0..WINDOW_S {
        reference.integrate(&mut temps, &flat, START_C, START_C, 1.0, 0.25);
        curve_k.push(hottest(temps.iter().copied()));
    }
    // Long enough for the slowest mode (about 330 s) to have died out.
    reference.integrate(&mut temps, &flat, START_C, START_C, 12_000.0, 0.5);
    Rise {
        curve_k,
        steady_k: hottest(temps),
    }
}

/// The report's single-node fit of the all-coils run, with `R(T)`:
/// `Ctot dT/dt = (r0 + s T) I^2 - (T - T0) / Rtot` is linear in `T`.
fn one_node_fit() -> Rise {
    let (rtot, ctot) = (5.49, 59.4);
    let i2 = CURRENT_A * CURRENT_A;
    let g = 1.0 / rtot - SLOPE_OHM_PER_K * i2;
    let steady_k = (R_AT_0C_OHM + SLOPE_OHM_PER_K * START_C) * i2 / g;
    let tau_s = ctot / g;
    let curve_k = (0..=WINDOW_S)
        .map(|t| steady_k * (1.0 - (-(t as f64) / tau_s).exp()))
        .collect();
    Rise { curve_k, steady_k }
}

/// The report's fits of the run of `pattern`.
fn fits(name: &str, pattern: Pattern) -> Vec<(&'static str, Rise)> {
    let mut fits = vec![
        ("stepwise", rc_fit(8.76, 2.83, 5.47, 57.5, pattern)),
        ("global", rc_fit(14.1, 3.02, 5.32, 56.4, pattern)),
    ];
    if name == "all on" {
        fits.push(("1-D", one_node_fit()));
    }
    fits
}

/// The worst `model / fit - 1` over the window from its first second (the
/// start is where a short overload is decided), and when.
fn worst_shortfall(model: &Rise, fit: &Rise) -> (usize, f64) {
    (1..=WINDOW_S)
        .map(|t| (t, model.curve_k[t] / fit.curve_k[t] - 1.0))
        .fold((0, f64::MAX), |a, b| if b.1 < a.1 { b } else { a })
}

#[test]
fn the_first_15_minutes_are_never_more_than_5_percent_below_the_reports_fits() {
    let mut failures = Vec::new();
    for (name, pattern) in PATTERNS {
        let model = model(GridConfig::default(), pattern);
        for (fit_name, fit) in &fits(name, pattern) {
            let (worst_s, worst) = worst_shortfall(&model, fit);
            let steady = model.steady_k / fit.steady_k - 1.0;
            println!(
                "{name:8} vs {fit_name:8}: 15 min {:.2} K against {:.2} K ({:+.1} %), worst {:+.1} % at {worst_s} s; steady {:.2} K against {:.2} K ({:+.1} %)",
                model.curve_k[WINDOW_S],
                fit.curve_k[WINDOW_S],
                100.0 * (model.curve_k[WINDOW_S] / fit.curve_k[WINDOW_S] - 1.0),
                100.0 * worst,
                model.steady_k,
                fit.steady_k,
                100.0 * steady,
            );
            if worst < -BAND {
                failures.push(format!(
                    "{name} vs the {fit_name} fit: {:.1} % below at {worst_s} s",
                    -100.0 * worst
                ));
            }
            // The steady states as before: never below a fit, and within
            // the 15 % the fitted sets agree to.
            if !(0.0..0.15).contains(&steady) {
                failures.push(format!(
                    "{name} vs the {fit_name} fit: steady {:+.1} %",
                    100.0 * steady
                ));
            }
        }
    }
    // The readings weighed in `grid::params` (printed, not judged: the
    // assertions above are on the default the library ships).
    let table_7 = GridParams::FDM_TABLE_7;
    let fitted = GridParams::FDM_FITTED;
    let with_c = |c: f64| {
        GridConfig::hppa(GridParams::between_coils(
            fitted.rx_between_coils_k_per_w(),
            fitted.ry_between_coils_k_per_w(),
            fitted.rz_k_per_w(),
            c,
        ))
    };
    let candidates = [
        ("Table 7 as printed, C 68.7", GridConfig::hppa(table_7)),
        ("C per pair, 34.35", with_c(68.7 / 2.0)),
        (
            "Table 7, rectangular stencil",
            GridConfig {
                stencil: Stencil::RECTANGULAR,
                ..GridConfig::hppa(table_7)
            },
        ),
        (
            "Table 7, Rx Ry per element",
            GridConfig::hppa(GridParams::per_element(19.8, 6.99, 5.74, 68.7)),
        ),
        ("C 59.4 (1-D fit)", with_c(59.4)),
        ("C 57.5 (stepwise fit)", with_c(57.5)),
        ("C 56.4 (global fit, default)", with_c(56.4)),
    ];
    println!("worst shortfall in 900 s against the hottest fit | 15-min rise | steady rise [K]");
    for (name, pattern) in PATTERNS {
        let fits = fits(name, pattern);
        let hottest_fit = |f: fn(&Rise) -> f64| fits.iter().map(|(_, r)| f(r)).fold(0.0, f64::max);
        println!(
            "{name}: fits 15 min {:.2} K, steady {:.2} K (the hottest of {})",
            hottest_fit(|r| r.curve_k[WINDOW_S]),
            hottest_fit(|r| r.steady_k),
            fits.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
        );
        for (candidate, config) in candidates {
            let m = model(config, pattern);
            let worst = fits
                .iter()
                .map(|(_, f)| worst_shortfall(&m, f).1)
                .fold(f64::MAX, f64::min);
            println!(
                "  {candidate:30} {:+6.1} % | {:6.2} K | {:6.2} K",
                100.0 * worst,
                m.curve_k[WINDOW_S],
                m.steady_k
            );
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
