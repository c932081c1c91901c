//! The model refresh rule and its watchdog (issue 17): a sensor set a
//! single fault leaves a solenoid without a thermocouple is refused unless
//! a refresh is declared, and a declared refresh that stops puts the
//! protection on the shadow's bound.

use super::*;
use crate::sensors::Reading;

const AMBIENT_C: f64 = 22.0;
const ONE_PER_SOLENOID: [bool; THERMOCOUPLES] = [true, false, true, false, true, false];

fn settings(sensors: [bool; THERMOCOUPLES], refresh_s: Option<f64>) -> OmniSettings {
    let defaults = OmniSettings::default();
    OmniSettings {
        filter: ObserverSettings {
            sensors,
            ..defaults.filter
        },
        model_refresh_s: refresh_s,
        ..defaults
    }
}

fn build(
    sensors: [bool; THERMOCOUPLES],
    refresh_s: Option<f64>,
) -> Result<OmniObserver, BuildError> {
    OmniObserver::new(
        &Omnimagnet::PAPER,
        &[AMBIENT_C; NODES],
        AMBIENT_C,
        &settings(sensors, refresh_s),
    )
}

#[test]
fn a_solenoid_a_single_fault_leaves_unmeasured_needs_a_declared_refresh() {
    let refused = |sensors, refresh_s| match build(sensors, refresh_s) {
        Err(BuildError::ModelRefreshRequired {
            solenoid,
            sensors,
            max_refresh_s,
        }) => {
            assert_eq!(max_refresh_s, 30.0);
            Some((solenoid, sensors))
        }
        Err(other) => panic!("{other:?}"),
        Ok(_) => None,
    };
    // One per solenoid: the first solenoid is named, with its one sensor.
    assert_eq!(refused(ONE_PER_SOLENOID, None), Some((0, 1)));
    // Two on solenoids 1 and 2, one on 3.
    let third_alone = [true, true, true, true, false, true];
    assert_eq!(refused(third_alone, None), Some((2, 1)));
    // Slower than the bound: refused too; at the bound and faster: built.
    assert_eq!(refused(ONE_PER_SOLENOID, Some(30.001)), Some((0, 1)));
    assert_eq!(refused(ONE_PER_SOLENOID, Some(30.0)), None);
    assert_eq!(refused(third_alone, Some(10.0)), None);
    // Two on every solenoid (the campaign's six): no refresh needed, and a
    // declared one of any period is accepted.
    assert_eq!(refused([true; THERMOCOUPLES], None), None);
    assert_eq!(refused([true; THERMOCOUPLES], Some(120.0)), None);
    assert_eq!(needs_model_refresh(&[true; THERMOCOUPLES]), None);
    assert_eq!(needs_model_refresh(&ONE_PER_SOLENOID), Some(0));
    // A period that is no period.
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e12] {
        assert_eq!(
            build([true; THERMOCOUPLES], Some(bad)).err(),
            Some(BuildError::InvalidParameter {
                name: "model_refresh_s"
            }),
            "{bad}"
        );
    }
    // The message says what to do.
    let text = BuildError::ModelRefreshRequired {
        solenoid: 0,
        sensors: 1,
        max_refresh_s: 30.0,
    }
    .to_string();
    for word in [
        "solenoid 0",
        "second thermocouple",
        "model_refresh_s",
        "30 s",
    ] {
        assert!(text.contains(word), "{text}");
    }
}

#[test]
fn from_parts_refuses_what_new_refuses_and_the_fingerprint_covers_the_refresh() {
    let six = build([true; THERMOCOUPLES], None).unwrap();
    assert_eq!(six.model_stale_after_steps(), None);
    let declared = build([true; THERMOCOUPLES], Some(10.0)).unwrap();
    // Three periods of 10 s at the default 1 ms step.
    assert_eq!(declared.model_stale_after_steps(), Some(30_000));
    // A snapshot of one is refused by the other; without a refresh the
    // fingerprint is what it was before the setting existed (the refresh is
    // folded in only when declared), so it differs only by the refresh.
    assert_ne!(six.fingerprint(), declared.fingerprint());
    let amb = AMBIENT_C as f32;
    let mut bytes = [0u8; crate::observer::snapshot::snapshot_len(NODES)];
    declared
        .save(&declared.state(&[30.0; NODES], amb), 100, &mut bytes)
        .unwrap();
    assert!(declared.restore(&bytes, 100, 3600, amb).is_ok());
    assert_eq!(
        six.restore(&bytes, 100, 3600, amb).err(),
        Some(crate::observer::snapshot::SnapshotError::ConfigMismatch)
    );
    let mut parts = six.parts();
    assert_eq!(parts.model_stale_after_steps, u32::MAX);
    assert!(OmniObserver::from_parts(&parts).is_ok());
    parts.filter.settings.sensors = ONE_PER_SOLENOID;
    assert!(matches!(
        OmniObserver::from_parts(&parts),
        Err(BuildError::ModelRefreshRequired { solenoid: 0, .. })
    ));
    // 90 s of 1 ms steps is the slowest watchdog accepted (30 s periods).
    parts.model_stale_after_steps = 90_001;
    assert!(OmniObserver::from_parts(&parts).is_err());
    parts.model_stale_after_steps = 90_000;
    assert!(OmniObserver::from_parts(&parts).is_ok());
    // The round trip carries it.
    let one = build(ONE_PER_SOLENOID, Some(10.0)).unwrap();
    let again = OmniObserver::from_parts(&one.parts()).unwrap();
    assert_eq!(again.model_stale_after_steps(), Some(30_000));
    assert_eq!(again.fingerprint(), one.fingerprint());
}

/// One tick of 1 ms at 7 A, with readings every 500 ms when given.
fn tick<W: OmniWarmUpKind>(
    observer: &OmniObserver,
    state: &mut OmniObserverState<W>,
    k: u32,
    readings_c: Option<[f32; THERMOCOUPLES]>,
) -> OmniOutputs {
    let now_us = (k + 1) * 1000;
    let readings = match readings_c {
        Some(r) if k.is_multiple_of(500) => r.map(|temp_c| {
            Some(TimedReading {
                result: Ok(Reading::new(temp_c)),
                sampled_at_us: now_us,
            })
        }),
        _ => [None; THERMOCOUPLES],
    };
    let inputs = OmniInputs {
        currents_a: [7.0; SOLENOIDS],
        ambient_c: AMBIENT_C as f32,
        readings,
        now_us,
        elapsed_us: 1000,
    };
    *observer.tick(state, &inputs)
}

#[test]
fn a_refresh_that_stops_is_flagged_and_the_protection_takes_the_shadow_bound() {
    let observer = build(ONE_PER_SOLENOID, Some(10.0)).unwrap();
    let amb = AMBIENT_C as f32;
    let mut state = observer.state(&[amb; NODES], amb);
    // The independent physics: the same observer with no reading follows
    // the build-time model alone, the model its shadow runs.
    let mut physics = observer.state(&[amb; NODES], amb);
    let bound = observer.upper_bound();
    let upper = |temps_c: &[f32; NODES]| {
        let mut u = [0.0; NODES];
        bound.upper_c(temps_c, amb, &mut u);
        u
    };
    // The published bound is taken once per protection cycle (16 ms): it
    // lags the estimate by a few millikelvin.
    let own_bound = |out: &OmniOutputs| {
        let own = upper(&out.temps_c);
        ALARM_NODES
            .iter()
            .all(|n| (out.upper_c[*n] - own[*n]).abs() < 0.02)
    };
    // Healthy-looking readings up to 1.5 K colder than the model (inside its
    // 3 K band, moving, ramped in so that the gate fuses them): the
    // estimate is pulled below the shadow, so the two bounds differ.
    let readings_at = |k: u32, physics_c: &[f32; NODES]| {
        let below_k = (k as f32 * 5e-5).min(1.5);
        Some(THERMOCOUPLE_NODES.map(|n| physics_c[n] - below_k))
    };
    let stale_after = 30_000;
    let mut k = 0;
    let mut run_to = |state: &mut OmniObserverState<NoWarmUp>,
                      physics: &mut OmniObserverState<NoWarmUp>,
                      end: u32| {
        let mut last = None;
        while k < end {
            let p = tick(&observer, physics, k, None);
            let out = tick(&observer, state, k, readings_at(k, &p.temps_c));
            assert!(
                !state.suspect.any(),
                "tick {k}: {:?} (the test needs no sensor in doubt)",
                out.sensors
            );
            let stale = out.flags.contains(InputFlags::MODEL_STALE);
            assert_eq!(stale, state.model_age_steps > stale_after, "tick {k}");
            last = Some((out, p));
            k += 1;
        }
        last.unwrap()
    };
    // Never installed: fresh for three periods of model time, to the tick.
    let (out, _) = run_to(&mut state, &mut physics, stale_after);
    assert!(!out.flags.contains(InputFlags::MODEL_STALE));
    assert!(own_bound(&out), "not stale: its own bound {out:?}");
    let (out, _) = run_to(&mut state, &mut physics, stale_after + 1);
    assert!(
        out.flags.contains(InputFlags::MODEL_STALE),
        "one step later"
    );
    // Stale for a few protection cycles: every alarm element on the
    // hotter of its own bound and the physics' bound (the shadow steps the
    // same model per correction period: within 0.05 K of the 1 ms one).
    let (out, p) = run_to(&mut state, &mut physics, stale_after + 100);
    assert!(out.flags.contains(InputFlags::MODEL_STALE));
    let own = upper(&out.temps_c);
    let shadow = upper(&p.temps_c);
    for node in ALARM_NODES {
        assert!(
            shadow[node] > own[node] + 0.5,
            "node {node}: the test must tell them apart"
        );
        let err = (out.upper_c[node] - shadow[node]).abs();
        assert!(
            err < 0.05,
            "node {node}: {} vs {}",
            out.upper_c[node],
            shadow[node]
        );
    }
    // The task comes back: an install ends the flag at once and, with the
    // next protection cycle, the fallback.
    let lin = Omnimagnet::PAPER
        .linearize(&out.temps_c.map(f64::from), AMBIENT_C, observer.step_s())
        .unwrap();
    let model = observer.prepare_model(&lin).unwrap();
    observer.install_model(&mut state, &model).unwrap();
    let (out, _) = run_to(&mut state, &mut physics, stale_after + 101);
    assert!(!out.flags.contains(InputFlags::MODEL_STALE));
    let (out, _) = run_to(&mut state, &mut physics, stale_after + 200);
    assert!(own_bound(&out), "fresh again: its own bound {out:?}");
    // And stale again three periods after that install (made before the
    // tick of index `stale_after + 100`).
    let (out, _) = run_to(&mut state, &mut physics, 2 * stale_after + 100);
    assert!(!out.flags.contains(InputFlags::MODEL_STALE));
    let (out, _) = run_to(&mut state, &mut physics, 2 * stale_after + 101);
    assert!(out.flags.contains(InputFlags::MODEL_STALE));
}

#[test]
fn no_declared_refresh_never_goes_stale() {
    let observer = build([true; THERMOCOUPLES], None).unwrap();
    let amb = AMBIENT_C as f32;
    let mut state = observer.state(&[amb; NODES], amb);
    // The counter saturates rather than wraps: start it near the top.
    state.model_age_steps = u32::MAX - 10;
    for k in 0..100 {
        let out = tick(&observer, &mut state, k, None);
        assert!(!out.flags.contains(InputFlags::MODEL_STALE), "tick {k}");
    }
    assert_eq!(state.model_age_steps, u32::MAX);
}

/// Fewer than three thermocouples the Omnimagnet does not take: with one
/// or two, the biases of the solenoids they do not read are unobservable,
/// and every such set is refused at build time (docs/omnimagnet.md,
/// "Observability"), refresh declared or not.
#[test]
fn every_set_of_one_or_two_thermocouples_is_refused() {
    let mut sets = 0;
    for mask in 1u32..64 {
        if mask.count_ones() > 2 {
            continue;
        }
        sets += 1;
        let sensors = core::array::from_fn(|j| mask & (1 << j) != 0);
        let result = build(sensors, Some(10.0));
        assert!(
            matches!(
                result,
                Err(BuildError::Unobservable { .. } | BuildError::NotConverged { .. })
            ),
            "{sensors:?}: {:?}",
            result.map(|_| ())
        );
    }
    assert_eq!(sets, 21);
}
