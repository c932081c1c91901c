//! The winding's own resistance as the only sensor of `drive-3node` (issue
//! 38, item 3), checked against the bench's winding thermocouple, which
//! the observer never sees.
//!
//! The bench (`host-tests/traces/drive-3node.csv`, made from
//! `drive-3node-truth.toml`) recorded no resistance, so one is
//! synthesised from its truth: every second, `R = R_truth(winding_tc) (1 +
//! 0.01 n)`, `R_truth` the truth file's winding (1.25 ohm at 20 degC,
//! 0.00393 /K), `winding_tc` the bench's winding thermocouple and `n` a
//! standard normal from the seeded [`Rng`] (seed [`SEED`]): a drive's `V/I`
//! to 1 %. The housing thermocouple is removed. The observer reads the
//! resistance through the winding's *measured* `R(T)` (the truth's: an
//! ohmmeter on the cold winding), while its thermal model keeps the guessed
//! (or fitted) parameters, `R(T)` 4 % low included.

use coil_thermal::observer::network::{
    NetworkInputs, NetworkObserver, NetworkObserverBuilder, NetworkSettings, ResistanceSensor,
};
use coil_thermal::observer::SensorStatus;
use coil_thermal::{Network, Resistance};
use coil_thermal_host::synth::Rng;

#[path = "../../examples/generated/drive_3node.rs"]
#[allow(unused)]
mod fitted;

const TRACE: &str = include_str!("../traces/drive-3node.csv");
/// The seed of the synthesised resistance noise.
const SEED: u64 = 38;
/// The winding's measured `R(T)`: the bench truth's.
const TRUTH_R: Resistance = Resistance::linear_fit(1.25 * 0.00393, 1.25 * (1.0 - 0.00393 * 20.0));

type Observer = NetworkObserver<3, 1, 1, 4, 1>;

/// `drive-3node.toml`, the guess before calibration.
fn guessed() -> Network<3, 1, 1> {
    Network::new([60.0, 400.0, 900.0])
        .and_then(|n| n.connect(0, 1, 0.8))
        .and_then(|n| n.connect(1, 2, 2.0))
        .and_then(|n| n.connect_boundary(2, 0, 1.2))
        .and_then(|n| n.joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0)))
        .expect("a valid network")
}

fn observer(network: &Network<3, 1, 1>, sensor_r: Resistance) -> Observer {
    let sensor = ResistanceSensor::of_source(network, 0, 0.01, 0.5)
        .and_then(|s| s.measured(sensor_r))
        .expect("a valid sensor");
    // The housing thermocouple's slot is the resistance's: the sensor map
    // says "housing", the resistance sensor moves it to the winding.
    NetworkObserverBuilder::new(network, [1])
        .critical_c([Some(155.0), Some(80.0), None])
        .hardware_limit_a([6.0])
        .settings(NetworkSettings {
            correction_period_s: 1.0,
            bias_noise_w2_per_s: 1e-4,
            ..NetworkSettings::DEFAULT
        })
        .resistance_sensor(0, sensor)
        .build()
        .expect("builds")
}

/// What a run over the recorded hour measured.
#[derive(Debug, Default)]
struct Run {
    /// RMSE of the winding estimate against `winding_tc`, after 60 s \[K\].
    rmse_k: f64,
    /// Its worst error after 60 s \[K\].
    worst_k: f64,
    /// Its worst error before the offset starts (all of it without one) \[K\].
    worst_before_offset_k: f64,
    /// Seconds after the offset starts until a reading is first refused,
    /// and how.
    first_flag: Option<(u32, SensorStatus)>,
    /// Readings fused, refused.
    fused: u32,
    refused: u32,
}

/// Replays the hour at 1 ms ticks. `offset`: the resistance's relative
/// error from `offset_from_s` on; `read`: whether the observer gets the
/// resistance at all (without: the model alone).
fn run(observer: &Observer, offset: f64, offset_from_s: u32, read: bool) -> Run {
    let mut rng = Rng::new(SEED);
    let mut state = observer.state(&[22.0; 3], &[22.0]);
    let mut run = Run::default();
    let mut sum_sq = 0.0;
    let mut count = 0u32;
    let mut now_us: u32 = 0;
    for (second, line) in TRACE.lines().skip(1).enumerate() {
        let second = second as u32;
        let f: Vec<f64> = line
            .split(',')
            .map(|v| v.parse().expect("a number"))
            .collect();
        let (current_a, ambient_c, winding_tc) = (f[1], f[2], f[3]);
        let noise = 0.01 * rng.normal();
        let error = if second >= offset_from_s { offset } else { 0.0 };
        let r_truth = TRUTH_R.r_at_0c_ohm + TRUTH_R.slope_ohm_per_k * winding_tc;
        let resistance_ohm = (r_truth * (1.0 + noise) * (1.0 + error)) as f32;
        for k in 0..1000u32 {
            let reading = if k == 0 && read {
                observer.resistance_reading(0, resistance_ohm, current_a as f32, now_us)
            } else {
                None
            };
            let inputs = NetworkInputs {
                currents_a: [current_a as f32],
                boundary_c: [ambient_c as f32],
                readings: [reading],
                now_us,
                elapsed_us: 1000,
            };
            let out = observer.tick(&mut state, &inputs);
            if k == 0 && read {
                match out.sensors[0] {
                    SensorStatus::Fused { .. } => run.fused += 1,
                    SensorStatus::NoReading => {}
                    status => {
                        run.refused += 1;
                        if second >= offset_from_s && run.first_flag.is_none() {
                            run.first_flag = Some((second - offset_from_s, status));
                        }
                    }
                }
            }
            now_us = now_us.wrapping_add(1000);
        }
        // The estimate at the end of the second, against the bench's
        // winding thermocouple read at the next row: both at `second + 1`.
        let Some(next) = TRACE.lines().nth(second as usize + 2) else {
            break;
        };
        let truth: f64 = next
            .split(',')
            .nth(3)
            .and_then(|v| v.parse().ok())
            .expect("truth");
        let e = (f64::from(state.outputs().temps_c[0]) - truth).abs();
        if second + 1 >= 60 {
            run.worst_k = run.worst_k.max(e);
            sum_sq += e * e;
            count += 1;
            if second + 1 < offset_from_s {
                run.worst_before_offset_k = run.worst_before_offset_k.max(e);
            }
        }
    }
    run.rmse_k = (sum_sq / f64::from(count)).sqrt();
    run
}

const NEVER: u32 = u32::MAX;

/// The calibrated model (`drive-3node-fitted.toml`, the one `codegen`
/// flashes) with the model file's observer settings: the goal.
#[test]
fn the_resistance_alone_holds_the_winding_within_1_k_of_the_bench() {
    let network = fitted::network().expect("the generated network builds");
    let observer = observer(&network, TRUTH_R);
    let with = run(&observer, 0.0, NEVER, true);
    let without = run(&observer, 0.0, NEVER, false);
    eprintln!("fitted model, resistance every second at 1 %: {with:?}");
    eprintln!("fitted model, no reading (the model alone): {without:?}");
    assert!(with.worst_k < 1.0, "{with:?}");
    assert!(with.rmse_k < 0.3, "{with:?}");
    // Every reading fused: the noise is the sensor's, none of it refused.
    assert_eq!((with.fused, with.refused), (3601, 0), "{with:?}");
}

/// The guess before calibration (`drive-3node.toml`): its model alone is
/// 7 K off; the resistance halves that, but a reading 2.5-3.3 K noisy
/// cannot hold a model this wrong within 1 K (the floor of the heat bias
/// keeps the model's excess heat: see the test's figures in the report).
#[test]
fn the_resistance_pulls_the_uncalibrated_guess_towards_the_bench() {
    let observer = observer(&guessed(), TRUTH_R);
    let with = run(&observer, 0.0, NEVER, true);
    let without = run(&observer, 0.0, NEVER, false);
    eprintln!("guessed model, resistance every second at 1 %: {with:?}");
    eprintln!("guessed model, no reading (the model alone): {without:?}");
    assert!(without.worst_k > 6.0, "{without:?}");
    assert!(with.worst_k < 0.6 * without.worst_k, "{with:?}");
    assert!(with.rmse_k < 0.6 * without.rmse_k, "{with:?}");
}

#[test]
fn the_models_guessed_r_of_t_reads_the_winding_hot() {
    // Read through the thermal model's `R(T)` (4 % low) rather than the
    // measured one: every reading is 10-14 K hot, and the gate refuses it
    // or the estimate follows it.
    let network = guessed();
    let model_r = Resistance::with_alpha(1.2, 0.00393, 20.0);
    let observer = observer(&network, model_r);
    let r = run(&observer, 0.0, NEVER, true);
    eprintln!("guessed model, read through the model's R(T): {r:?}");
    assert!(r.worst_k > 5.0, "{r:?}");
}

#[test]
fn a_resistance_off_by_10_percent_is_flagged() {
    let network = fitted::network().expect("the generated network builds");
    let observer = observer(&network, TRUTH_R);
    for offset in [0.10, -0.10] {
        let r = run(&observer, offset, 1800, true);
        eprintln!("offset {offset:+} from 1800 s: {r:?}");
        assert!(r.worst_before_offset_k < 1.0, "{r:?}");
        let (after_s, status) = r.first_flag.expect("flagged");
        assert!(after_s <= 2, "{r:?}");
        if offset > 0.0 {
            // 10 % high is 25-35 K hot: the innovation gate.
            assert!(
                matches!(status, SensorStatus::Rejected { .. }),
                "{status:?}"
            );
        } else {
            // 10 % low is as cold: below the physics' band.
            assert!(
                matches!(status, SensorStatus::ColderThanPhysics { .. }),
                "{status:?}"
            );
        }
    }
}
