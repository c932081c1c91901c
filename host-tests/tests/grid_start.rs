//! The grid's start without a history (issue 35): the grid has no sensor,
//! so after a reset with no snapshot every coil starts where its upper
//! bound is 1 K under its alarm limit, unlatched, and the model cools it.
//! Checked against the dense `f64` reference grid (RK4) driven by what the
//! observer allows (closed loop), reset at the end of a 20 min run that
//! held two coils at their limit.

use coil_thermal::grid::GridConfig;
use coil_thermal::observer::start::START_BELOW_LIMIT_K;
use coil_thermal::observer::{GridInputs, GridObserver, GridObserverState};
use coil_thermal::protect::alarm::AlarmBuilder;
use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::limiter::LimiterConfig;
use coil_thermal::{GridParams, Stencil};
use coil_thermal_host::grid_reference::{GridReference, ReferenceParams};

type Grid = GridObserver<f32, 7, 12, 84>;
type State = GridObserverState<f32, 7, 12, 84>;

fn grid() -> Grid {
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 84])
        .build()
        .unwrap();
    let limiter = LimiterConfig::new([6.0; 84], 10.0, 0.0).unwrap();
    let config = GridConfig {
        ticks_per_update: 10,
        ..GridConfig::hppa(GridParams::FDM_FITTED)
    };
    Grid::new(&config, alarm, limiter, 4).unwrap()
}

/// Two coils asked for 6 A, the rest for 1 A.
fn demand_a(coil: usize) -> f64 {
    if coil == 3 * 12 + 5 || coil == 3 * 12 + 6 {
        6.0
    } else {
        1.0
    }
}

#[derive(Debug)]
struct Run {
    /// Largest truth above its alarm limit, any coil \[K\].
    over_limit_k: f64,
    /// Largest truth above its upper bound, any coil, after the first
    /// protection pass \[K\].
    under_bound_k: f64,
    /// The hot coils' mean current over the last minute \[A\].
    late_current_a: f64,
}

/// `seconds` of closed loop at 1 ms ticks, the reference integrated over
/// each 100 ms with the limits held.
fn drive(grid: &Grid, state: &mut State, plant: &mut [f64], seconds: u32) -> Run {
    let reference = GridReference::assemble(
        7,
        12,
        &Stencil::HPPA_HERRINGBONE,
        &ReferenceParams::HPPA_FDM,
    );
    let limits_c: Vec<f64> = grid
        .alarm()
        .alarm_limits_c(20.0)
        .iter()
        .map(|l| f64::from(*l))
        .collect();
    let mut run = Run {
        over_limit_k: f64::NEG_INFINITY,
        under_bound_k: f64::NEG_INFINITY,
        late_current_a: 0.0,
    };
    let mut late = (0.0, 0u32);
    for block in 0..seconds * 10 {
        let out = *state.outputs();
        let applied: Vec<f64> = (0..84)
            .map(|c| demand_a(c).min(f64::from(out.limits[c].current_a)))
            .collect();
        let currents: [[f32; 12]; 7] =
            core::array::from_fn(|r| core::array::from_fn(|c| applied[r * 12 + c] as f32));
        for _ in 0..100 {
            grid.tick(
                state,
                &GridInputs {
                    currents_a: &currents,
                    coolant_c: 20.0,
                    ambient_c: 20.0,
                    elapsed_us: 1000,
                },
            );
        }
        reference.integrate(plant, &applied, 20.0, 20.0, 0.1, 0.1);
        let upper = state.outputs().upper_c;
        for (c, truth) in plant.iter().enumerate() {
            run.over_limit_k = run.over_limit_k.max(truth - limits_c[c]);
            if block > 0 {
                let bound = f64::from(upper[c / 12][c % 12]);
                run.under_bound_k = run.under_bound_k.max(truth - bound);
            }
        }
        if block >= (seconds - 60) * 10 {
            late = (late.0 + applied[3 * 12 + 5], late.1 + 1);
        }
    }
    run.late_current_a = late.0 / f64::from(late.1.max(1));
    run
}

#[test]
fn a_grid_reset_without_history_starts_below_its_limits_and_never_passes_them() {
    let grid = grid();
    let mut plant = vec![20.0; 84];
    let mut state = grid.state(20.0);
    let warm = drive(&grid, &mut state, &mut plant, 1200);
    let hottest = plant.iter().copied().fold(f64::MIN, f64::max);
    // The reset, at the end of the run.
    let mut started = grid.start(20.0);
    let first = *started.outputs();
    let limits_c = grid.alarm().alarm_limits_c(20.0);
    for (r, row) in first.upper_c.iter().enumerate() {
        for (c, upper) in row.iter().enumerate() {
            let below = limits_c[r * 12 + c] - upper;
            assert!(
                below >= START_BELOW_LIMIT_K - 0.01,
                "coil ({r}, {c}) starts {below} K under its limit"
            );
        }
    }
    assert!(!first.alarm.shutdown, "the start latches nothing");
    let after = drive(&grid, &mut started, &mut plant.clone(), 1200);
    println!(
        "warm run: hottest coil {hottest:.1} degC, {warm:?}; after the start: {after:?}; first limit {:.2} A",
        first.limits[3 * 12 + 5].current_a
    );
    assert!(warm.over_limit_k <= 0.0 && after.over_limit_k <= 0.0);
    assert!(after.under_bound_k <= 1.0, "{after:?}");
    // The current comes back as the model cools the start: within 5 % of
    // the warm run's over the last minute.
    assert!(
        (after.late_current_a - warm.late_current_a).abs() <= 0.05 * warm.late_current_a,
        "{after:?} against {warm:?}"
    );
    // The start the README's grid example had, the ambient, reads the hot
    // coils far below the truth.
    let mut cold = grid.state(20.0);
    let ambient = drive(&grid, &mut cold, &mut plant, 60);
    assert!(ambient.under_bound_k > 10.0, "{ambient:?}");
}
