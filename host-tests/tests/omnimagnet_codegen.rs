//! The Omnimagnet observer in flash: `examples/generated/omnimagnet.rs`
//! (written by `coil-thermal codegen --device omnimagnet`) holds a
//! `static OBSERVER` the compiler assembles with the `const fn`
//! `OmniObserver::from_parts`; `examples/observer_m4.rs` ticks it.
//!
//! Here: the committed file is what the generator writes today (stale
//! after a change of the observer's settings or tables: the failure says
//! the command that regenerates it), the static is `OmniObserver::new`'s
//! configuration to the bit (every table, the fingerprint), the two give
//! the same outputs, to the bit, on every tick of a 20 s run with readings
//! and a sensor fault, and bad parts are refused by name.

use coil_thermal::observer::omnimagnet::{OmniInputs, OmniObserver, TimedReading};
use coil_thermal::omnimagnet::{NODES, THERMOCOUPLES};
use coil_thermal::{BuildError, Reading, SensorFault};
use coil_thermal_host::codegen::{
    generate_omnimagnet, omnimagnet_observer, OMNIMAGNET_COMMAND, OMNIMAGNET_FILE,
};

mod common;

#[path = "../../examples/generated/omnimagnet.rs"]
mod generated;

#[test]
fn the_committed_module_is_what_codegen_writes() {
    let fresh = generate_omnimagnet().expect("generates");
    common::assert_committed_is_fresh(OMNIMAGNET_FILE, OMNIMAGNET_COMMAND, &fresh);
}

#[test]
fn the_static_is_the_built_observer_to_the_bit() {
    let built = omnimagnet_observer().expect("builds");
    assert_eq!(built.parts(), generated::PARTS);
    // `Debug` writes every float as the shortest text that reads back to
    // its bits (and tells -0.0 from 0.0): equal text, equal tables.
    assert_eq!(format!("{built:?}"), format!("{:?}", generated::OBSERVER));
    assert_eq!(built.fingerprint(), generated::OBSERVER.fingerprint());
    let again = OmniObserver::from_parts(&built.parts()).expect("assembles");
    assert_eq!(format!("{built:?}"), format!("{again:?}"));
}

#[test]
fn the_static_ticks_as_the_built_observer() {
    let built = omnimagnet_observer().expect("builds");
    let flash: &'static OmniObserver = &generated::OBSERVER;
    let start = [22.5f32; NODES];
    let mut a = built.state(&start, 22.0);
    let mut b = flash.state(&start, 22.0);
    let mut now_us = 0u32;
    let mut corrections = 0;
    for k in 0..20_000u32 {
        let elapsed_us = if k % 2 == 0 { 1_100 } else { 900 };
        now_us = now_us.wrapping_add(elapsed_us);
        let mut readings = [None; THERMOCOUPLES];
        if k % 500 == 499 {
            for (j, slot) in readings.iter_mut().enumerate() {
                let result = if j == 5 && k > 10_000 {
                    Err(SensorFault::OpenCircuit)
                } else {
                    Ok(Reading::new(22.0 + 0.0004 * k as f32 + 0.05 * j as f32))
                };
                *slot = Some(TimedReading {
                    result,
                    sampled_at_us: now_us,
                });
            }
        }
        let inputs = OmniInputs {
            currents_a: [3.8, 3.0 + (k % 7) as f32 * 0.1, 2.0],
            ambient_c: 22.0,
            readings,
            now_us,
            elapsed_us,
        };
        let out_a = *built.tick(&mut a, &inputs);
        let out_b = *flash.tick(&mut b, &inputs);
        assert_eq!(format!("{out_a:?}"), format!("{out_b:?}"), "tick {k}");
        corrections += usize::from(out_a.corrected);
    }
    assert_eq!(corrections, 40);
    assert!(
        a.outputs().temps_c[0] > 22.5,
        "the run heats the solenoids: {:?}",
        a.outputs().temps_c
    );
}

#[test]
fn bad_parts_are_refused_by_name() {
    let refused =
        |parts: &coil_thermal::observer::omnimagnet::OmniParts| match OmniObserver::from_parts(
            parts,
        ) {
            Err(BuildError::InvalidParameter { name }) => name,
            Err(other) => panic!("refused as {other:?}"),
            Ok(_) => panic!("accepted"),
        };
    let mut p = generated::PARTS;
    p.filter.gain.gain[3][2] = f32::NAN;
    assert_eq!(refused(&p), "filter.gain");
    let mut p = generated::PARTS;
    p.shadow.phi_minus_i[0][0] = f32::INFINITY;
    assert_eq!(refused(&p), "shadow");
    let mut p = generated::PARTS;
    p.protection.predictor.winding_node[1] = NODES;
    assert_eq!(refused(&p), "protection.predictor");
    let mut p = generated::PARTS;
    p.filter.solenoid_nodes[0] = NODES;
    assert_eq!(refused(&p), "filter.solenoid_nodes");
    let mut p = generated::PARTS;
    p.protect_phase_us = p.protect_period_us;
    assert_eq!(refused(&p), "protect_phase_us");
    let mut p = generated::PARTS;
    p.filter.settings.warmup_corrections = 1;
    assert_eq!(refused(&p), "filter.settings");
    let mut p = generated::PARTS;
    p.clock.step_us = 0;
    assert_eq!(refused(&p), "clock.step_us");
}

#[test]
fn nan_limits_and_bias_bounds_are_refused() {
    let refused = |parts: &coil_thermal::observer::omnimagnet::OmniParts| {
        matches!(
            OmniObserver::from_parts(parts),
            Err(BuildError::InvalidParameter { name }) if name == "checks" || name == "limits"
        )
    };
    let mut p = generated::PARTS;
    p.checks.bias_offset_w[2] = f32::NAN;
    assert!(refused(&p));
    let mut p = generated::PARTS;
    p.max_current_a = f32::NAN;
    assert!(refused(&p));
    // An unbounded bias is `+inf`, and accepted.
    let mut p = generated::PARTS;
    p.checks.bias_offset_w[0] = f32::INFINITY;
    assert!(OmniObserver::from_parts(&p).is_ok());
}

/// One thermocouple per solenoid (0, 2, 4) needs the firmware's model
/// refresh: `codegen --device omnimagnet --thermocouples 0,2,4` alone is
/// refused with the library's reason, and with `--model-refresh-s 10` it
/// writes parts that assemble into the built observer (the sensor set, the
/// watched refresh and the fingerprint), the command named in the header.
#[test]
fn one_per_solenoid_generates_with_a_declared_model_refresh() {
    use coil_thermal_host::codegen::{
        generate_omnimagnet_with, omnimagnet_observer_with, OmniCodegen,
    };
    let one_each = OmniCodegen {
        thermocouples: [true, false, true, false, true, false],
        model_refresh_s: None,
    };
    let refused = generate_omnimagnet_with(&one_each).unwrap_err().to_string();
    assert!(refused.contains("model_refresh_s"), "{refused}");
    let declared = OmniCodegen {
        model_refresh_s: Some(10.0),
        ..one_each
    };
    let text = generate_omnimagnet_with(&declared).expect("generates");
    assert!(
        text.contains("codegen --device omnimagnet --thermocouples 0,2,4 --model-refresh-s 10`"),
        "{}",
        &text[..800]
    );
    let built = omnimagnet_observer_with(&declared).expect("builds");
    let parts = built.parts();
    assert!(parts.model_stale_after_steps < u32::MAX);
    assert_ne!(
        built.fingerprint(),
        omnimagnet_observer().unwrap().fingerprint()
    );
    let again = OmniObserver::from_parts(&parts).expect("assembles");
    assert_eq!(again.fingerprint(), built.fingerprint());
    // The command line: refused without the refresh, written with it.
    let out = tempfile::TempDir::new().unwrap();
    let file = out.path().join("omni.rs");
    let ct = || assert_cmd::Command::cargo_bin("coil-thermal").unwrap();
    ct().args([
        "codegen",
        "--device",
        "omnimagnet",
        "--thermocouples",
        "0,2,4",
        "--out",
    ])
    .arg(&file)
    .assert()
    .failure()
    .stderr(predicates::str::contains("model_refresh_s"));
    ct().args([
        "codegen",
        "--device",
        "omnimagnet",
        "--thermocouples",
        "0,2,4",
        "--model-refresh-s",
        "10",
        "--out",
    ])
    .arg(&file)
    .assert()
    .success();
    assert_eq!(std::fs::read_to_string(&file).unwrap(), text);
    ct().args([
        "codegen",
        "--device",
        "omnimagnet",
        "--thermocouples",
        "6",
        "--out",
        "-",
    ])
    .assert()
    .failure()
    .stderr(predicates::str::contains("thermocouples 0 to 5"));
    let model = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/models/drive-3node-fitted.toml"
    );
    ct().args([
        "codegen",
        "--model",
        model,
        "--model-refresh-s",
        "10",
        "--out",
        "-",
    ])
    .assert()
    .failure()
    .stderr(predicates::str::contains("for --device omnimagnet"));
}
