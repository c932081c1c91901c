//! Issue 17: the latch survives everything but a deliberate clear, and
//! input faults are never silent, for both observers (and the Omnimagnet
//! filter's own `predict`).

use coil_thermal::filter::InputStatus;
use coil_thermal::grid::GridConfig;
use coil_thermal::observer::snapshot::snapshot_len;
use coil_thermal::observer::{
    GridInputs, GridObserver, GridObserverState, OmniInputs, OmniObserver, OmniSettings,
    SnapshotError,
};
use coil_thermal::omnimagnet::observer::{ObserverSettings, OmnimagnetObserver};
use coil_thermal::omnimagnet::{Omnimagnet, NODES};
use coil_thermal::protect::alarm::{AlarmBuilder, ResetError};
use coil_thermal::protect::derating::{DeratingFactor, DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::events::EventKind;
use coil_thermal::protect::limiter::LimiterConfig;
use coil_thermal::protect::margin::UncertaintyMargin;
use coil_thermal::{GridParams, InputFlags};

type Grid = GridObserver<f32, 7, 12, 84>;
type GridState = GridObserverState<f32, 7, 12, 84>;

fn grid() -> Grid {
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 84])
        .build()
        .unwrap();
    let limiter = LimiterConfig::new([3.0; 84], 10.0, 0.0).unwrap();
    let config = GridConfig {
        ticks_per_update: 10,
        ..GridConfig::hppa(GridParams::FDM_FITTED)
    };
    Grid::new(&config, alarm, limiter, 4).unwrap()
}

fn grid_tick(grid: &Grid, state: &mut GridState, currents: &[[f32; 12]; 7], elapsed_us: u32) {
    grid.tick(
        state,
        &GridInputs {
            currents_a: currents,
            coolant_c: 20.0,
            ambient_c: 20.0,
            elapsed_us,
        },
    );
}

fn omni() -> OmniObserver {
    OmniObserver::new(
        &Omnimagnet::PAPER,
        &[22.0; NODES],
        22.0,
        &OmniSettings::default(),
    )
    .unwrap()
}

fn omni_inputs(currents_a: [f32; 3], elapsed_us: u32) -> OmniInputs {
    OmniInputs {
        currents_a,
        ambient_c: 22.0,
        readings: [None; 6],
        now_us: 0,
        elapsed_us,
    }
}

fn reset_events(events: &mut coil_thermal::protect::events::EventQueue<16>) -> usize {
    let mut resets = 0;
    while let Some(event) = events.pop() {
        resets += usize::from(event.kind == EventKind::Reset);
    }
    resets
}

/// A refused snapshot starts latched, the latch shows before the first
/// tick and on every tick, and only `clear_shutdown` clears it.
#[test]
fn grid_conservative_state_starts_latched_until_the_deliberate_clear() {
    let grid = grid();
    let mut state = grid.conservative_state(20.0);
    assert!(state.alarm.shutdown_latched());
    assert!(state.outputs().alarm.shutdown, "before the first tick");
    // Latched: no current allowed (it allowed the full 3 A before).
    assert!(state.outputs().limits.iter().all(|l| l.current_a == 0.0));
    let idle = [[0.0f32; 12]; 7];
    // Too early: the alarm has not yet seen the coils settle below reset.
    assert!(grid.clear_shutdown(&mut state).is_err());
    let mut cleared_at = None;
    for k in 0..20_000u32 {
        grid_tick(&grid, &mut state, &idle, 1000);
        assert!(state.outputs().alarm.shutdown, "tick {k}: the latch holds");
        assert!(
            state.outputs().limits.iter().all(|l| l.current_a == 0.0),
            "tick {k}: no current while latched"
        );
        if k % 100 == 99 && grid.clear_shutdown(&mut state).is_ok() {
            cleared_at = Some(k);
            break;
        }
    }
    let cleared_at = cleared_at.expect("the idle grid settles below reset");
    assert!(
        !state.outputs().alarm.shutdown,
        "cleared at tick {cleared_at}"
    );
    assert!(!state.alarm.shutdown_latched());
    assert_eq!(reset_events(&mut state.events), 1);
    for _ in 0..100 {
        grid_tick(&grid, &mut state, &idle, 1000);
        assert!(!state.outputs().alarm.shutdown);
    }
    // The limiter's next pass gives the cold coils their full current back.
    assert!(state.outputs().limits.iter().all(|l| l.current_a == 3.0));
}

/// The grid's restored latch is in the outputs before and after the first
/// ticks.
#[test]
fn grid_restored_latch_shows_from_the_start() {
    let grid = grid();
    let mut live = grid.state(20.0);
    live.alarm.latch_shutdown();
    let mut buf = [0u8; snapshot_len(84)];
    grid.save(&live, 100, &mut buf).unwrap();
    let mut state = grid.restore(&buf, 110, 600, 20.0).unwrap();
    assert!(state.outputs().alarm.shutdown);
    for _ in 0..50 {
        grid_tick(&grid, &mut state, &[[0.0; 12]; 7], 1000);
        assert!(state.outputs().alarm.shutdown);
    }
}

/// The Omnimagnet: a restored latch shows before the first tick and on
/// tick 1 (it showed `false` until the protection cycle's alarm stage).
#[test]
fn omni_restored_latch_shows_before_and_on_the_first_tick() {
    let omni = omni();
    let mut live = omni.state(&[60.0; NODES], 22.0);
    live.alarm.latch_shutdown();
    let mut buf = [0u8; snapshot_len(NODES)];
    omni.save(&live, 100, &mut buf).unwrap();
    let mut state = omni.restore(&buf, 110, 600, 22.0).unwrap();
    assert!(state.outputs().alarm.shutdown, "before the first tick");
    assert!(state.outputs().limits.iter().all(|l| l.current_a == 0.0));
    for k in 0..100 {
        let out = *omni.tick(&mut state, &omni_inputs([0.0; 3], 1000));
        assert!(out.alarm.shutdown, "tick {}", k + 1);
        assert!(
            out.limits.iter().all(|l| l.current_a == 0.0),
            "tick {}",
            k + 1
        );
    }
}

/// The Omnimagnet's conservative state starts latched (it started
/// unlatched at the readings and allowed full current) until the
/// deliberate clear.
#[test]
fn omni_conservative_state_starts_latched_until_the_deliberate_clear() {
    let omni = omni();
    let readings = [Some(55.4), None, Some(40.0), None, None, None];
    let mut state = omni.conservative_state(&readings, 22.0);
    assert!(state.alarm.shutdown_latched());
    assert!(state.outputs().alarm.shutdown, "before the first tick");
    assert!(matches!(
        omni.clear_shutdown(&mut state),
        Err(ResetError::NotSettled { .. } | ResetError::TooHot { .. })
    ));
    let mut cleared = false;
    for k in 0..5_000u32 {
        let out = *omni.tick(&mut state, &omni_inputs([0.0; 3], 1000));
        assert!(out.alarm.shutdown, "tick {k}: the latch holds");
        if k % 50 == 49 && omni.clear_shutdown(&mut state).is_ok() {
            cleared = true;
            break;
        }
    }
    assert!(cleared, "55 degC is below every reset threshold");
    assert!(!state.outputs().alarm.shutdown);
    assert_eq!(reset_events(&mut state.events), 1);
    let mut out = *omni.tick(&mut state, &omni_inputs([0.0; 3], 1000));
    assert!(!out.alarm.shutdown);
    // Within a protection cycle the limiter allows current again.
    for _ in 0..32 {
        out = *omni.tick(&mut state, &omni_inputs([0.0; 3], 1000));
    }
    assert!(
        out.limits.iter().all(|l| l.current_a > 0.0),
        "{:?}",
        out.limits
    );
}

/// The generic observer keeps the same promises: its conservative state is
/// latched with no current allowed, a frozen clock latches it, and only the
/// deliberate clear releases it.
#[test]
fn network_observer_latch_holds_the_current_at_zero_until_the_clear() {
    use coil_thermal::observer::network::{NetworkInputs, NetworkObserver, NetworkObserverBuilder};
    use coil_thermal::{Network, Resistance};
    // Winding (0), housing (1), heatsink (2) to the ambient; thermocouple on
    // the housing.
    let network: Network<3, 1, 1> = Network::new([400.0, 1200.0, 3000.0])
        .unwrap()
        .connect(0, 1, 2.0)
        .unwrap()
        .connect(1, 2, 4.0)
        .unwrap()
        .connect_boundary(2, 0, 1.5)
        .unwrap()
        .joule_source(0, 0, Resistance::with_alpha(0.5, 0.00393, 20.0))
        .unwrap();
    let observer: NetworkObserver<3, 1, 1, 4, 1> = NetworkObserverBuilder::new(&network, [1])
        .critical_c([Some(155.0), Some(80.0), None])
        .build()
        .unwrap();
    let inputs = |elapsed_us: u32| NetworkInputs {
        currents_a: [5.0],
        boundary_c: [20.0],
        readings: [None],
        now_us: 0,
        elapsed_us,
    };
    let mut state = observer.conservative_state(&[Some(30.0)], &[20.0]);
    assert!(state.outputs().alarm.shutdown, "before the first tick");
    assert!(state.outputs().limits[0].current_a == 0.0);
    let mut cleared = false;
    for k in 0..20_000u32 {
        let out = *observer.tick(&mut state, &inputs(1000));
        if !cleared {
            assert!(
                out.alarm.shutdown && out.limits[0].current_a == 0.0,
                "tick {k}"
            );
            cleared = k % 100 == 99 && observer.clear_shutdown(&mut state).is_ok();
        }
    }
    assert!(cleared, "30 degC is below every reset threshold");
    let out = *observer.tick(&mut state, &inputs(1000));
    assert!(
        !out.alarm.shutdown && out.limits[0].current_a > 0.0,
        "{out:?}"
    );
    // A frozen clock: flagged, then the model is lost and the latch holds
    // the current at zero.
    let mut latched_at = None;
    for k in 0..1200u32 {
        let out = *observer.tick(&mut state, &inputs(0));
        if out.alarm.shutdown && latched_at.is_none() {
            latched_at = Some(k);
        }
        if latched_at.is_some() {
            assert_eq!(out.limits[0].current_a, 0.0, "tick {k}");
        }
    }
    assert_eq!(latched_at, Some(999), "the 1000th frozen tick latches");
}

/// A huge current whose Joule power overflows `f32` is clamped by the
/// input rules (`InputLimits::default`, 100 A) and reported; the solenoid
/// heats as at the clamp, it does not cool.
#[test]
fn omnimagnet_predict_clamps_an_overflowing_current_and_reports_it() {
    let model = Omnimagnet::PAPER;
    let lin = model.linearize(&[22.0; NODES], 22.0, 1e-3).unwrap();
    let settings = ObserverSettings {
        warmup_corrections: 0,
        ..ObserverSettings::DEFAULT
    };
    let new = || OmnimagnetObserver::<f32>::new(&model, &lin, &settings, &[22.0; NODES], 22.0);
    let (mut huge, mut clamp) = (new().unwrap(), new().unwrap());
    let before = huge.temperatures_c();
    for _ in 0..1000 {
        assert_eq!(huge.predict(&[1e20, 0.0, 0.0], 22.0), InputStatus::Clamped);
        assert_eq!(clamp.predict(&[100.0, 0.0, 0.0], 22.0), InputStatus::Used);
    }
    let (after, at_clamp) = (huge.temperatures_c(), clamp.temperatures_c());
    assert!(after.iter().all(|t| t.is_finite()));
    // Node 7: solenoid 0's winding.
    assert!(after[7] > before[7] + 1.0, "{} -> {}", before[7], after[7]);
    assert_eq!(after, at_clamp, "the clamped current is what is used");
    // Negative huge currents too; a NaN is held (the last input), reported.
    assert_eq!(huge.predict(&[-1e20, 0.0, 0.0], 22.0), InputStatus::Clamped);
    assert_eq!(
        huge.predict(&[f32::NAN, 0.0, 0.0], 22.0),
        InputStatus::Dropped
    );
    assert_eq!(huge.predict(&[3.0, 0.0, 0.0], 1e6), InputStatus::Dropped);
}

/// A grid tick that takes no model step (elapsed 0, or an early tick
/// below one step) still validates its inputs, flags the bad ones and
/// updates the held values, so the next step uses them.
#[test]
fn grid_tick_without_a_step_validates_and_holds_its_inputs() {
    let grid = grid();
    let mut state = grid.state(20.0);
    let mut currents = [[0.0f32; 12]; 7];
    currents[3][5] = 2.0;
    for elapsed_us in [0, 400] {
        let out = *grid.tick(
            &mut state,
            &GridInputs {
                currents_a: &currents,
                coolant_c: 25.0,
                ambient_c: 21.0,
                elapsed_us,
            },
        );
        assert_eq!(out.steps, 0);
        assert!(out.flags.is_clean());
    }
    assert_eq!(
        state.grid.held_currents_a[3][5], 2.0,
        "held on a stepless tick"
    );
    assert_eq!(state.grid.held_coolant_c, 25.0);
    assert_eq!(state.grid.held_ambient_c, 21.0);
    let mut bad = currents;
    bad[3][5] = f32::NAN;
    bad[0][0] = 500.0;
    let out = *grid.tick(
        &mut state,
        &GridInputs {
            currents_a: &bad,
            coolant_c: f32::NAN,
            ambient_c: 1e6,
            elapsed_us: 0,
        },
    );
    assert_eq!(out.steps, 0);
    for flag in [
        InputFlags::CURRENT_NOT_FINITE,
        InputFlags::CURRENT_CLAMPED,
        InputFlags::TEMPERATURE_INVALID,
    ] {
        assert!(out.flags.contains(flag), "{:?}", out.flags);
    }
    assert_eq!(state.grid.held_currents_a[3][5], 2.0, "NaN holds the last");
    assert_eq!(state.grid.held_currents_a[0][0], 100.0, "clamped and held");
    assert_eq!(state.grid.held_coolant_c, 25.0);
}

/// The same for the Omnimagnet observer (it validated before stepping
/// already: a regression test).
#[test]
fn omni_tick_without_a_step_validates_and_holds_its_inputs() {
    let omni = omni();
    let mut state = omni.state(&[22.0; NODES], 22.0);
    let out = *omni.tick(&mut state, &omni_inputs([f32::NAN, 1e20, 2.0], 0));
    assert_eq!(out.steps, 0);
    assert!(out.flags.contains(InputFlags::CURRENT_NOT_FINITE));
    assert!(out.flags.contains(InputFlags::CURRENT_CLAMPED));
    let out = *omni.tick(
        &mut state,
        &OmniInputs {
            ambient_c: f32::NAN,
            ..omni_inputs([0.0; 3], 300)
        },
    );
    assert_eq!(out.steps, 0);
    assert!(out.flags.contains(InputFlags::TEMPERATURE_INVALID));
}

fn grid_built(
    critical_c: [f64; 84],
    rule: &DeratingRule,
    hardware_a: f64,
    taper_k: f64,
    margin: UncertaintyMargin,
) -> Grid {
    let alarm = AlarmBuilder::new(rule, critical_c).build().unwrap();
    let limiter = LimiterConfig::new([hardware_a; 84], taper_k, 0.0).unwrap();
    let config = GridConfig {
        ticks_per_update: 10,
        ..GridConfig::hppa(GridParams::FDM_FITTED)
    };
    Grid::new(&config, alarm, limiter, 4)
        .unwrap()
        .with_margin(margin)
        .unwrap()
}

/// The grid's fingerprint covers the protection: a snapshot written under
/// another critical temperature, derating, limiter or margin is refused
/// (it was accepted: the fingerprint covered the model only).
#[test]
fn grid_snapshot_from_another_protection_is_refused() {
    let rule = DeratingRule::hppa();
    let margin = UncertaintyMargin::GRID_20_PERCENT;
    let writer = grid_built([HPPA_CRITICAL_C; 84], &rule, 3.0, 10.0, margin);
    let mut buf = [0u8; snapshot_len(84)];
    writer.save(&writer.state(30.0), 100, &mut buf).unwrap();
    let same = grid_built([HPPA_CRITICAL_C; 84], &rule, 3.0, 10.0, margin);
    assert!(
        same.restore(&buf, 110, 600, 20.0).is_ok(),
        "same configuration"
    );
    let mut one_coil = [HPPA_CRITICAL_C; 84];
    one_coil[40] -= 10.0;
    let derated = DeratingRule::new(&[DeratingFactor::new("test", 0.9)]).unwrap();
    let others = [
        (
            "a critical temperature",
            grid_built(one_coil, &rule, 3.0, 10.0, margin),
        ),
        (
            "the derating",
            grid_built([HPPA_CRITICAL_C; 84], &derated, 3.0, 10.0, margin),
        ),
        (
            "the hardware limit",
            grid_built([HPPA_CRITICAL_C; 84], &rule, 2.5, 10.0, margin),
        ),
        (
            "the taper",
            grid_built([HPPA_CRITICAL_C; 84], &rule, 3.0, 8.0, margin),
        ),
        (
            "the margin",
            grid_built(
                [HPPA_CRITICAL_C; 84],
                &rule,
                3.0,
                10.0,
                UncertaintyMargin::ZERO,
            ),
        ),
    ];
    for (what, other) in others {
        assert_eq!(
            other.restore(&buf, 110, 600, 20.0).err(),
            Some(SnapshotError::ConfigMismatch),
            "{what}"
        );
    }
}

/// The Omnimagnet's fingerprint covers `k_sigma`, the margin and the
/// limiter as well as the filter.
#[test]
fn omni_snapshot_from_another_protection_is_refused() {
    let writer = omni();
    let mut buf = [0u8; snapshot_len(NODES)];
    writer
        .save(&writer.state(&[30.0; NODES], 22.0), 100, &mut buf)
        .unwrap();
    assert!(omni().restore(&buf, 110, 600, 22.0).is_ok());
    let build = |settings: OmniSettings| {
        OmniObserver::new(&Omnimagnet::PAPER, &[22.0; NODES], 22.0, &settings).unwrap()
    };
    let others = [
        (
            "k_sigma",
            OmniSettings {
                k_sigma: 2.0,
                ..OmniSettings::default()
            },
        ),
        (
            "the margin",
            OmniSettings {
                unmeasured_margin: UncertaintyMargin::ZERO,
                ..OmniSettings::default()
            },
        ),
        (
            "the hardware limit",
            OmniSettings {
                hardware_limit_a: 6.0,
                ..OmniSettings::default()
            },
        ),
    ];
    for (what, settings) in others {
        assert_eq!(
            build(settings).restore(&buf, 110, 600, 22.0).err(),
            Some(SnapshotError::ConfigMismatch),
            "{what}"
        );
    }
}

/// Nonzero reserved bytes refuse a snapshot through the observers too.
#[test]
fn observer_snapshot_with_reserved_bytes_set_is_refused() {
    let grid = grid();
    let mut buf = [0u8; snapshot_len(84)];
    grid.save(&grid.state(30.0), 100, &mut buf).unwrap();
    buf[18] = 0x5A;
    let crc = coil_thermal::observer::snapshot::crc32(&buf[..buf.len() - 4]);
    let at = buf.len() - 4;
    buf[at..].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(
        grid.restore(&buf, 110, 600, 20.0).err(),
        Some(SnapshotError::ReservedNotZero { offset: 18 })
    );
}

fn count_kind(
    events: &mut coil_thermal::protect::events::EventQueue<16>,
    kind: EventKind,
) -> usize {
    let mut n = 0;
    while let Some(event) = events.pop() {
        n += usize::from(event.kind == kind);
    }
    n
}

/// The timer freezes (`elapsed_us = 0` forever) at 9 A: the model stands
/// still at 20 degC, so the ticks are flagged from the 100th and the
/// shutdown latches at the 1000th, with one `ClockFrozen` event (it was
/// never flagged nor latched). Time coming back ends the flag, not the
/// latch.
#[test]
fn grid_frozen_clock_is_flagged_then_latches_the_shutdown() {
    let grid = grid();
    assert_eq!(grid.clock().frozen_flag_ticks(), 100);
    assert_eq!(grid.clock().frozen_loss_ticks(), 1000);
    let mut state = grid.state(20.0);
    let currents = [[9.0f32; 12]; 7];
    for k in 1..=1200u32 {
        let out = *grid.tick(
            &mut state,
            &GridInputs {
                currents_a: &currents,
                coolant_c: 20.0,
                ambient_c: 20.0,
                elapsed_us: 0,
            },
        );
        assert_eq!(
            out.flags.contains(InputFlags::CLOCK_FROZEN),
            k >= 100,
            "tick {k}"
        );
        assert_eq!(out.alarm.shutdown, k >= 1000, "tick {k}");
        assert_eq!(state.alarm.shutdown_latched(), k >= 1000, "tick {k}");
    }
    assert_eq!(state.grid.temps_c[3][5], 20.0, "the model stood still");
    assert_eq!(count_kind(&mut state.events, EventKind::ClockFrozen), 1);
    grid_tick(&grid, &mut state, &currents, 1000);
    let out = state.outputs();
    assert!(!out.flags.contains(InputFlags::CLOCK_FROZEN));
    assert!(out.alarm.shutdown, "the latch stays");
    // Configurable, validated.
    let quick = self::grid().with_frozen_clock(3, 5).unwrap();
    let mut state = quick.state(20.0);
    for _ in 0..5 {
        grid_tick(&quick, &mut state, &currents, 0);
    }
    assert!(state.outputs().alarm.shutdown);
    assert!(self::grid().with_frozen_clock(0, 5).is_err());
    assert!(self::grid().with_frozen_clock(6, 5).is_err());
}

/// The same for the Omnimagnet observer, with its settings.
#[test]
fn omni_frozen_clock_is_flagged_then_latches_the_shutdown() {
    let omni = omni();
    let mut state = omni.state(&[22.0; NODES], 22.0);
    for k in 1..=1100u32 {
        let out = *omni.tick(&mut state, &omni_inputs([8.0; 3], 0));
        assert_eq!(
            out.flags.contains(InputFlags::CLOCK_FROZEN),
            k >= 100,
            "tick {k}"
        );
        assert_eq!(out.alarm.shutdown, k >= 1000, "tick {k}");
    }
    assert_eq!(count_kind(&mut state.events, EventKind::ClockFrozen), 1);
    let settings = OmniSettings {
        frozen_flag_ticks: 2,
        frozen_loss_ticks: 4,
        ..OmniSettings::default()
    };
    let quick = OmniObserver::new(&Omnimagnet::PAPER, &[22.0; NODES], 22.0, &settings).unwrap();
    let mut state = quick.state(&[22.0; NODES], 22.0);
    for _ in 0..4 {
        quick.tick(&mut state, &omni_inputs([0.0; 3], 0));
    }
    assert!(state.outputs().alarm.shutdown);
    let bad = OmniSettings {
        frozen_loss_ticks: 1,
        ..settings
    };
    assert!(OmniObserver::new(&Omnimagnet::PAPER, &[22.0; NODES], 22.0, &bad).is_err());
}
