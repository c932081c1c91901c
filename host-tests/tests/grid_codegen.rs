//! The HPPA grid observer in flash: `examples/generated/hppa_grid.rs`
//! (written by `coil-thermal codegen --device hppa-grid`) holds a
//! `static OBSERVER` the compiler assembles with the `const fn`
//! `GridObserver::from_parts`; `examples/observer_m4.rs` ticks it.
//!
//! Here, as for the Omnimagnet (`omnimagnet_codegen.rs`): the committed
//! file is what the generator writes today (stale after a change of the
//! grid's settings or tables: the failure says the command that
//! regenerates it), the static is `GridObserver::new`'s configuration to
//! the bit (every table, both fingerprints), the two give the same outputs,
//! to the bit, on every tick of a run that heats a row into its taper
//! (late ticks, a stall, idle ticks) and a margin set on either keeps them
//! equal; the parts of other scalars and margins (`f64`, `Q32`, no margin)
//! assemble to their observers too; and bad parts are refused by name.

use coil_thermal::observer::{GridInputs, GridObserver, GridParts};
use coil_thermal::protect::alarm::AlarmBuilder;
use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::limiter::LimiterConfig;
use coil_thermal::protect::margin::UncertaintyMargin;
use coil_thermal::{BuildError, GridConfig, Scalar, Q32};
use coil_thermal_host::codegen::{generate_grid, grid_observer, GRID_COMMAND, GRID_FILE};

mod common;

#[path = "../../examples/generated/hppa_grid.rs"]
mod generated;

#[test]
fn the_committed_module_is_what_codegen_writes() {
    common::assert_committed_is_fresh(
        GRID_FILE,
        GRID_COMMAND,
        &generate_grid().expect("generates"),
    );
}

#[test]
fn the_static_is_the_built_observer_to_the_bit() {
    let built = grid_observer().expect("builds");
    assert_eq!(built.parts(), generated::PARTS);
    // `Debug` writes every float as the shortest text that reads back to
    // its bits (and tells -0.0 from 0.0): equal text, equal tables.
    assert_eq!(format!("{built:?}"), format!("{:?}", generated::OBSERVER));
    assert_eq!(built.fingerprint(), generated::OBSERVER.fingerprint());
    let again = GridObserver::from_parts(&built.parts()).expect("assembles");
    assert_eq!(format!("{built:?}"), format!("{again:?}"));
    // The model's fingerprint is carried as its CRC register: a margin set
    // on the static feeds it as on the built observer.
    let margin = UncertaintyMargin {
        rise_fraction: 0.3,
        offset_k: 1.0,
    };
    let a = built.clone().with_margin(margin).expect("margin");
    let b = generated::OBSERVER
        .clone()
        .with_margin(margin)
        .expect("margin");
    assert_eq!(a.fingerprint(), b.fingerprint());
    assert_ne!(a.fingerprint(), built.fingerprint());
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
}

/// The generated configuration's grid, alarm and limiter in `S`, updated
/// every `ticks_per_update` ticks.
fn observer_in<S: Scalar>(
    ticks_per_update: u32,
    margin: UncertaintyMargin,
) -> Result<GridObserver<S, 7, 12, 84>, BuildError> {
    let config = GridConfig {
        ticks_per_update,
        ..GridConfig::default()
    };
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 84]).build::<S>()?;
    let limiter = LimiterConfig::new([3.0; 84], 10.0, 0.0)?;
    GridObserver::new(&config, alarm, limiter, 4).and_then(|g| g.with_margin(margin))
}

fn round_trips<S: Scalar>(observer: &GridObserver<S, 7, 12, 84>) {
    let parts = observer.parts();
    let again = GridObserver::from_parts(&parts).expect("assembles");
    assert_eq!(format!("{observer:?}"), format!("{again:?}"));
    assert_eq!(again.parts(), parts);
}

#[test]
fn every_scalar_and_margin_round_trips_through_its_parts() {
    round_trips(&observer_in::<f32>(20, UncertaintyMargin::ZERO).expect("f32"));
    round_trips(&observer_in::<f64>(20, UncertaintyMargin::GRID_20_PERCENT).expect("f64"));
    let q32 = observer_in::<Q32>(20, UncertaintyMargin::GRID_20_PERCENT).expect("Q32");
    round_trips(&q32);
    // No margin is `None`, and assembles to the zero bound's fast path.
    let plain = observer_in::<f32>(20, UncertaintyMargin::ZERO).expect("f32");
    assert!(plain.parts().bound.is_none());
    assert!(plain.upper_bound().is_zero());
    // Q32 parts are written by their bits, each a `const fn` call.
    let mut text = String::new();
    q32.parts().write_rust(&mut text).expect("writes");
    let inverse_capacity = q32.parts().model.inverse_capacity.to_bits();
    assert!(
        text.contains(&format!(
            "inverse_capacity: coil_thermal::Q32::from_bits({inverse_capacity}),"
        )),
        "{}",
        &text[..text.len().min(2000)]
    );
}

#[test]
fn the_static_ticks_as_the_built_observer() {
    let built = grid_observer().expect("builds");
    let flash: &'static GridObserver<f32, 7, 12, 84> = &generated::OBSERVER;
    let mut a = built.state(22.0);
    let mut b = flash.state(22.0);
    // Row 3 at the hardware limit heats into the limiter's taper; the other
    // coils at 1 A.
    let mut currents = [[1.0f32; 12]; 7];
    currents[3] = [3.0; 12];
    let (mut tapered, mut predictive) = (false, false);
    for k in 0..90_000u32 {
        let elapsed_us = match k {
            30_000 => 3_400,
            30_001 => 0,
            // A stall beyond the catch-up bound: time dropped and flagged.
            50_000 => 9_000,
            k if (60_000..60_200).contains(&k) => 0,
            k if k % 2 == 0 => 1_100,
            _ => 900,
        };
        let inputs = GridInputs {
            currents_a: &currents,
            coolant_c: 22.0,
            ambient_c: 22.0 + (k / 10_000) as f32 * 0.1,
            elapsed_us,
        };
        let out_a = *built.tick(&mut a, &inputs);
        let out_b = *flash.tick(&mut b, &inputs);
        assert_eq!(format!("{out_a:?}"), format!("{out_b:?}"), "tick {k}");
        tapered |= out_a.limits.iter().any(|l| l.current_a < 3.0);
        predictive |= out_a.alarm.predictive;
    }
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
    assert!(tapered && predictive, "the run reaches the protection");
}

#[test]
fn bad_parts_are_refused_by_name() {
    let refused = |parts: &GridParts<f32, 7, 12, 84>| match GridObserver::from_parts(parts) {
        Err(BuildError::InvalidParameter { name }) => name,
        Err(other) => panic!("refused as {other:?}"),
        Ok(_) => panic!("accepted"),
    };
    let good = generated::PARTS;
    let mut p = good;
    p.model.config.tick_dt_s = f64::NAN;
    assert_eq!(refused(&p), "model.config");
    let mut p = good;
    p.model.config.ticks_per_update = 0;
    assert_eq!(refused(&p), "model.config");
    let mut p = good;
    p.model.stability_ratio = 1.0;
    assert_eq!(refused(&p), "model.stability_ratio");
    let mut p = good;
    p.time_to_limit.coils[40][4] = f32::INFINITY;
    assert_eq!(refused(&p), "time_to_limit");
    let mut p = good;
    p.restart_c = f64::NAN;
    assert_eq!(refused(&p), "restart_c");
    let mut p = good;
    p.clock.step_us = 0;
    assert_eq!(refused(&p), "clock.step_us");
    let mut p = good;
    p.clock.max_steps_per_tick = 0;
    assert_eq!(refused(&p), "clock.max_steps_per_tick");
    let mut p = good;
    p.clock.frozen_loss_ticks = p.clock.frozen_flag_ticks - 1;
    assert_eq!(refused(&p), "clock.frozen_loss_ticks");
    let mut p = good;
    p.clock.frozen_flag_ticks = 0;
    assert_eq!(refused(&p), "clock.frozen_flag_ticks");
    let mut p = good;
    p.clock.max_steps_per_tick = 11;
    assert_eq!(refused(&p), "model.config.ticks_per_update");
    let mut p = good;
    p.plan.alarm_parts = 0;
    assert_eq!(refused(&p), "plan");
    // Eight ticks per update, seven of them preparing rows: no tick left
    // for a stage that waits for the rows.
    let mut p = good;
    p.model.config.ticks_per_update = 8;
    assert_eq!(refused(&p), "plan.wait_for_rows");
    // `new` refuses the same configuration.
    let built = observer_in::<f32>(8, UncertaintyMargin::GRID_20_PERCENT)
        .and_then(|g| g.with_protection_plan(good.plan));
    assert!(built.is_err());
    assert!(GridObserver::from_parts(&good).is_ok());
}
