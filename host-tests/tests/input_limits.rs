//! A generated module's `input_limits_a`: the observer limits each of its
//! currents (a source's current times its speed factor, a loss carried as
//! `sqrt(P)`), while a drive commands its model file's inputs (a motor's
//! `|i_s|`). The generated function takes each input to the smallest
//! published limit among the currents it drives.
//!
//! Here, on the test model with every kind of heat input
//! (`host-tests/models/all-input-terms.toml`: a winding with a speed
//! factor, a second input, a speed loss, a split and a constant loss):
//! the mapping picks exactly the input's own currents, and in closed loop
//! on the host's `f64` plant of the same model file (not the code under
//! test) a drive held to it keeps the winding below its derated alarm
//! limit, where the same drive unheld crosses it.

use coil_thermal::observer::TimedReading;
use coil_thermal::protect::limiter::CoilLimit;
use coil_thermal::Reading;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::sim::{FilePlant, Plant};

#[path = "generated/all_input_terms.rs"]
mod model;

const WINDING: usize = 0;
const STATOR: usize = 1;

fn limit(current_a: f32) -> CoilLimit<f32> {
    CoilLimit {
        current_a,
        weight: 1.0,
        invalid: false,
    }
}

#[test]
fn each_input_takes_the_smallest_limit_of_its_own_currents() {
    assert_eq!(model::INPUT_NAMES, ["current", "aux"]);
    // The winding (input 0, with its speed factor) and the aux source
    // (input 1) are currents 0 and 1; the rest are losses, the smallest
    // limits here, which no input drives.
    let mut limits = [limit(0.5); model::CURRENTS];
    limits[0] = limit(90.0);
    limits[1] = limit(40.0);
    assert_eq!(model::input_limits_a(&limits), [90.0, 40.0]);
    limits[0] = limit(30.0);
    assert_eq!(model::input_limits_a(&limits), [30.0, 40.0]);
    // A latched shutdown publishes zero everywhere.
    assert_eq!(
        model::input_limits_a(&[CoilLimit::default(); model::CURRENTS]),
        [0.0, 0.0]
    );
}

/// The drive of the closed loop: the hardware limit on the winding at
/// 3000 rpm (its speed factor 1.35 in power) and 20 A of aux, on an 85
/// degC coolant.
const DEMAND_A: [f32; model::INPUTS] = [150.0, 20.0];
const SPEED_RPM: f32 = 3000.0;
const COOLANT_C: f32 = 85.0;
const AMBIENT_C: f32 = 25.0;
const SECONDS: u32 = 1500;
/// The plant and the drive's command move every 100 ms; the observer
/// ticks every 1 ms and reads the stator once a second.
const PLANT_STEP_MS: u32 = 100;

struct Run {
    /// The plant's hottest winding temperature \[degC\].
    max_winding_c: f64,
    final_winding_c: f64,
    /// The winding's current at the end \[A\].
    final_current_a: f32,
    shutdown: bool,
}

fn run(held: bool) -> Run {
    let file = ModelFile::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models/all-input-terms.toml"),
    )
    .unwrap();
    let mut plant = FilePlant::new(Model::build(&file).unwrap()).unwrap();
    let observer = model::observer().expect("the generated parts assemble");
    let boundary_c = [COOLANT_C, AMBIENT_C];
    let start_c = [f64::from(COOLANT_C); model::NODES];
    plant.reset(&start_c);
    let mut state = observer.state(&[COOLANT_C; model::NODES], &boundary_c);
    let mut current_a = DEMAND_A;
    let mut run = Run {
        max_winding_c: f64::MIN,
        final_winding_c: 0.0,
        final_current_a: 0.0,
        shutdown: false,
    };
    let mut now_us: u32 = 0;
    for step in 0..SECONDS * 1000 / PLANT_STEP_MS {
        if held {
            let allowed = model::input_limits_a(&state.outputs().limits);
            for (c, (d, a)) in current_a.iter_mut().zip(DEMAND_A.iter().zip(allowed)) {
                *c = d.min(a);
            }
        }
        // The loss terms read the winding's current as a signal.
        let signals = [SPEED_RPM, current_a[0]];
        let currents = model::source_currents_a(&current_a, &signals);
        for k in 0..PLANT_STEP_MS {
            let read = k == 0 && step % (1000 / PLANT_STEP_MS) == 0;
            let reading = read.then_some(TimedReading {
                result: Ok(Reading::new(plant.temps_c()[STATOR] as f32)),
                sampled_at_us: now_us,
            });
            let inputs = model::Inputs {
                currents_a: currents,
                boundary_c,
                readings: [reading],
                now_us,
                elapsed_us: 1000,
            };
            observer.tick(&mut state, &inputs);
            now_us = now_us.wrapping_add(1000);
        }
        plant.step(
            f64::from(PLANT_STEP_MS) / 1000.0,
            &current_a.map(f64::from),
            &boundary_c.map(f64::from),
            &signals.map(f64::from),
        );
        let winding_c = plant.temps_c()[WINDING];
        run.max_winding_c = run.max_winding_c.max(winding_c);
        run.final_winding_c = winding_c;
        run.shutdown |= state.outputs().alarm.shutdown;
    }
    run.final_current_a = current_a[0];
    run
}

#[test]
fn a_drive_held_to_its_input_limits_keeps_the_winding_below_its_alarm_limit() {
    let observer = model::observer().unwrap();
    let alarm_c = f64::from(observer.alarm().alarm_limits_c(AMBIENT_C)[WINDING]);
    let free = run(false);
    let held = run(true);
    println!(
        "alarm limit {alarm_c:.2} degC; unheld: winding up to {:.2} degC (shutdown {}); held: up to {:.2}, {:.2} at the end at {:.1} A (shutdown {})",
        free.max_winding_c, free.shutdown, held.max_winding_c, held.final_winding_c, held.final_current_a, held.shutdown
    );
    assert!(
        free.max_winding_c > alarm_c + 5.0,
        "the unheld drive must cross the alarm limit for this test to mean anything"
    );
    assert!(
        held.max_winding_c < alarm_c,
        "held to input_limits_a the winding reached {:.2} degC, over its {alarm_c:.2} degC limit",
        held.max_winding_c
    );
    assert!(!held.shutdown, "the held drive latched a shutdown");
    // Held, not starved: the drive settles inside the limiter's taper
    // band (10 K) widened by the observer's margin on the unmeasured
    // winding, at a current below the demand.
    assert!(
        held.final_winding_c > alarm_c - 20.0,
        "held at {:.2} degC, far below the {alarm_c:.2} degC limit",
        held.final_winding_c
    );
    assert!(held.final_current_a < 0.95 * DEMAND_A[0]);
}
