//! The state through a power cycle, as a firmware keeps it: the generated
//! module's `start_state`, `save_snapshot` and `restore_state` (those of
//! the RTIC example's `model.rs`; `codegen` writes them into every network
//! module, and `codegen_round_trip` holds the committed modules to it).

use coil_thermal::observer::snapshot::{snapshot_len, SnapshotError};
use coil_thermal::observer::TimedReading;
use coil_thermal::Reading;

#[path = "../../examples/rtic-stm32f4/src/model.rs"]
mod model;

#[path = "../../examples/generated/drive_3node.rs"]
mod drive_3node;

use model::{
    observer, restore_state, save_snapshot, start_state, Observer, OffTime, State, NODES,
    SNAPSHOT_LEN,
};

const AMBIENT_C: f32 = 20.0;
/// The oldest snapshot a restore takes \[s\] (the RTIC example's).
const MAX_AGE_S: u32 = 3600;
const WINDING: usize = 0;
const HOUSING: usize = 1;

/// The example's plant (`examples/support/sim_board.rs`: model.toml's
/// network, its resistance 5 % high) stepped 1 ms in `f64` at `current_a`.
fn step_plant(plant_c: &mut [f64; NODES], current_a: f64) {
    let [w, h, s] = *plant_c;
    let power_w = 1.05 * 1.2 * (1.0 + 0.00393 * (w - 20.0)) * current_a * current_a;
    let (wh, hs, sa) = (w - h, 2.0 * (h - s), 1.5 * (s - f64::from(AMBIENT_C)));
    *plant_c = [
        w + 1e-3 * (power_w - wh) / 4.0,
        h + 1e-3 * (wh - hs) / 60.0,
        s + 1e-3 * (hs - sa) / 300.0,
    ];
}

/// `seconds` of the drive asking 10 A, clamped to the limits, the housing
/// read every 500 ms; from `state` on the plant `plant_c`.
fn run(observer: &Observer, state: &mut State, plant_c: &mut [f64; NODES], seconds: u32) {
    for k in 1..=seconds * 1000 {
        let current_a = state.outputs().limits[0].clamp_a(10.0);
        step_plant(plant_c, f64::from(current_a));
        let now_us = k * 1000;
        let reading = TimedReading {
            result: Ok(Reading::new(plant_c[HOUSING] as f32)),
            sampled_at_us: now_us,
        };
        let inputs = model::Inputs {
            currents_a: [current_a],
            boundary_c: [AMBIENT_C],
            readings: [(k % 500 == 0).then_some(reading)],
            now_us,
            elapsed_us: 1000,
        };
        observer.tick(state, &inputs);
    }
}

/// The observer after 60 s of overload from a plant 1 K above the ambient,
/// and the plant.
fn warm() -> (Observer, State, [f64; NODES]) {
    let observer = observer().unwrap();
    let mut plant_c = [f64::from(AMBIENT_C) + 1.0; NODES];
    let mut state = start_state(&observer, &[Some(plant_c[HOUSING] as f32)], AMBIENT_C);
    run(&observer, &mut state, &mut plant_c, 60);
    (observer, state, plant_c)
}

fn bits(temps_c: &[f32; NODES]) -> [u32; NODES] {
    temps_c.map(f32::to_bits)
}

#[test]
fn a_snapshot_restores_to_the_bit_and_cools_over_the_rtcs_off_time() {
    assert_eq!(SNAPSHOT_LEN, snapshot_len(NODES));
    let (observer, state, _) = warm();
    let saved_c = observer.temps_c(&state);
    assert!(saved_c[WINDING] > 70.0, "{saved_c:?}");
    let mut bytes = [0u8; SNAPSHOT_LEN];
    save_snapshot(&observer, &state, 1_000, &mut bytes);
    let readings = [Some(saved_c[HOUSING])];
    // Restored at once: the saved state to the bit.
    let off = OffTime::SinceSave { now_s: 1_000 };
    let (restored, refused) = restore_state(&observer, &bytes, off, 3600, &readings, AMBIENT_C);
    assert_eq!(refused, None);
    assert_eq!(bits(&observer.temps_c(&restored)), bits(&saved_c));
    assert!(!restored.outputs().alarm.shutdown);
    // 60 s later on the RTC: cooled exactly over the snapshot's age.
    let off = OffTime::SinceSave { now_s: 1_060 };
    let (restored, refused) = restore_state(&observer, &bytes, off, 3600, &readings, AMBIENT_C);
    assert_eq!(refused, None);
    let cooled_c = observer.cooled_c(&saved_c, &[AMBIENT_C], 60.0);
    assert_eq!(bits(&observer.temps_c(&restored)), bits(&cooled_c));
    assert!(cooled_c[WINDING] < saved_c[WINDING] - 20.0, "{cooled_c:?}");
}

#[test]
fn a_refused_snapshot_gives_the_safe_start_and_why() {
    let (observer, state, plant_c) = warm();
    let mut bytes = [0u8; SNAPSHOT_LEN];
    save_snapshot(&observer, &state, 1_000, &mut bytes);
    let mut corrupted = bytes;
    corrupted[SNAPSHOT_LEN / 2] ^= 0x10;
    // The same network at another fit: another configuration.
    let other = drive_3node::observer().unwrap();
    let mut foreign = [0u8; drive_3node::SNAPSHOT_LEN];
    drive_3node::save_snapshot(
        &other,
        &drive_3node::initial_state(&other, 20.0),
        1_000,
        &mut foreign,
    );
    let since = |now_s| OffTime::SinceSave { now_s };
    let cases: [(&[u8], OffTime, SnapshotError); 7] = [
        (
            &[],
            OffTime::Unknown,
            SnapshotError::BufferTooSmall {
                needed: SNAPSHOT_LEN,
            },
        ),
        (&[0xFF; SNAPSHOT_LEN], since(1_000), SnapshotError::BadMagic),
        (&corrupted, since(1_000), SnapshotError::CrcMismatch),
        (&corrupted, OffTime::Unknown, SnapshotError::CrcMismatch),
        (&foreign, since(1_000), SnapshotError::ConfigMismatch),
        (
            &bytes,
            since(1_000 + MAX_AGE_S + 1),
            SnapshotError::Stale {
                age_s: MAX_AGE_S + 1,
            },
        ),
        (&bytes, since(999), SnapshotError::FromFuture),
    ];
    let readings = [Some(plant_c[HOUSING] as f32)];
    // The safe start: the hot winding no sensor reads is under its upper
    // bound from the start, and nothing is latched.
    let start = start_state(&observer, &readings, AMBIENT_C);
    let out = start.outputs();
    assert!(
        f64::from(out.upper_c[WINDING]) > plant_c[WINDING],
        "{out:?} vs {plant_c:?}"
    );
    assert!(
        !out.alarm.shutdown && out.limits[0].current_a > 0.0,
        "{out:?}"
    );
    for (bytes, off, why) in cases {
        let (state, refused) =
            restore_state(&observer, bytes, off, MAX_AGE_S, &readings, AMBIENT_C);
        assert_eq!(refused, Some(why));
        assert_eq!(state.outputs(), start.outputs(), "{why}");
        assert_eq!(
            bits(&observer.temps_c(&state)),
            bits(&observer.temps_c(&start))
        );
    }
}

#[test]
fn an_unknown_off_time_is_found_from_the_boot_readings() {
    // Saved on the uptime clock of the last run (5000 s); the boot's clock
    // starts again at 0, so no off time is known. The device was off 300 s
    // (the truth: the saved state cooled by the observer's own model); the
    // housing reads its truth.
    let (observer, state, _) = warm();
    let saved_c = observer.temps_c(&state);
    let mut bytes = [0u8; SNAPSHOT_LEN];
    save_snapshot(&observer, &state, 5_000, &mut bytes);
    let truth_c = observer.cooled_c(&saved_c, &[AMBIENT_C], 300.0);
    let readings = [Some(truth_c[HOUSING])];
    let (restored, refused) = restore_state(
        &observer,
        &bytes,
        OffTime::Unknown,
        MAX_AGE_S,
        &readings,
        AMBIENT_C,
    );
    assert_eq!(refused, None);
    let restored_c = observer.temps_c(&restored);
    println!("saved {saved_c:?}, truth after 300 s {truth_c:?}, restored {restored_c:?}");
    // The least cooling the reading allows: no node colder than the truth
    // (to the f32 rounding), the winding far below its saved temperature,
    // the housing no warmer than its reading.
    for (node, (r, t)) in restored_c.iter().zip(&truth_c).enumerate() {
        assert!(
            *r >= t - 1e-3,
            "node {node}: restored {r} below the truth {t}"
        );
    }
    assert!(
        restored_c[WINDING] < truth_c[WINDING] + 2.0,
        "{restored_c:?}"
    );
    assert!(restored_c[HOUSING] <= truth_c[HOUSING]);
    // With a clock that ran on the uptime, the snapshot is from the future.
    let off = OffTime::SinceSave { now_s: 0 };
    let (_, refused) = restore_state(&observer, &bytes, off, MAX_AGE_S, &readings, AMBIENT_C);
    assert_eq!(refused, Some(SnapshotError::FromFuture));
    // No reading: nothing says the device cooled; the saved state, hot.
    let (uncooled, refused) = restore_state(
        &observer,
        &bytes,
        OffTime::Unknown,
        MAX_AGE_S,
        &[None],
        AMBIENT_C,
    );
    assert_eq!(refused, None);
    assert_eq!(bits(&observer.temps_c(&uncooled)), bits(&saved_c));
}

#[test]
fn a_latched_shutdown_outlives_the_restore() {
    let observer = observer().unwrap();
    // The generated module's `State`: the start's flavour.
    let latched = observer.with_warm_up(observer.conservative_state(&[Some(25.0)], &[AMBIENT_C]));
    assert!(latched.outputs().alarm.shutdown);
    let mut bytes = [0u8; SNAPSHOT_LEN];
    save_snapshot(&observer, &latched, 100, &mut bytes);
    for off in [OffTime::SinceSave { now_s: 160 }, OffTime::Unknown] {
        let (state, refused) =
            restore_state(&observer, &bytes, off, MAX_AGE_S, &[Some(24.0)], AMBIENT_C);
        assert_eq!(refused, None);
        assert!(state.outputs().alarm.shutdown, "{off:?}");
        assert_eq!(state.outputs().limits[0].current_a, 0.0);
    }
}
