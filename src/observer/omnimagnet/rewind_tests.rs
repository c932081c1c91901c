//! The stuck sensor's rewind on the Omnimagnet (`consistency::StuckRewind`,
//! the network observer's rule): a thermocouple that sticks while its
//! solenoid heats is fused until the stuck test sees it, and what it
//! taught the heat-input biases meanwhile goes back. The readings are the
//! paper's nonlinear model integrated in `f64` (RK4, 10 ms steps,
//! [`Omnimagnet::step_rk4`]); the reference is the same run with the
//! sensor healthy. Without the rewind the bias stays where the stuck
//! reading took it (-0.36 W at the verdict, against -0.01 W).

use super::*;
use crate::sensors::Reading;

const AMBIENT_C: f64 = 22.0;
/// Every solenoid's current \[A\].
const CURRENT_A: f64 = 7.0;
/// When thermocouple 0 (solenoid 1) sticks \[s\]: its solenoid still
/// heats at about 0.2 K/s.
const STICK_S: u32 = 40;
/// The run \[s\].
const RUN_S: u32 = 150;

/// A healthy thermocouple's reading of `temp_c` \[degC\]: a uniform error of
/// at most 0.05 K (no healthy reading repeats to the bit).
fn noisy(seed: &mut u64, temp_c: f64) -> f32 {
    *seed = seed
        .wrapping_mul(6_364_136_223_846_793_005)
        .wrapping_add(1_442_695_040_888_963_407);
    let u = (*seed >> 11) as f64 / (1u64 << 53) as f64;
    (temp_c + 0.1 * (u - 0.5)) as f32
}

/// What one run saw.
#[derive(Debug)]
struct Run {
    /// Solenoid 1's heat-input bias \[W\] after every tick.
    bias_w: Vec<f32>,
    /// The tick of the stuck verdict on thermocouple 0.
    verdict: Option<usize>,
}

/// 7 A on every solenoid from the ambient, the six thermocouples read
/// every 0.5 s (tick `k` brings them when `k % 500 == 0`); thermocouple 0
/// stuck at its reading of [`STICK_S`] from then on when `stuck`.
fn run(stuck: bool) -> Run {
    let observer = OmniObserver::new(
        &Omnimagnet::PAPER,
        &[AMBIENT_C; NODES],
        AMBIENT_C,
        &OmniSettings::default(),
    )
    .unwrap();
    let amb = AMBIENT_C as f32;
    let mut state = observer.state(&[amb; NODES], amb);
    let mut plant = [AMBIENT_C; NODES];
    let mut seed = 0x2545_F491_4F6C_DD1Du64;
    let mut stuck_c = None;
    let mut out = Run {
        bias_w: Vec::new(),
        verdict: None,
    };
    for k in 0..RUN_S * 1000 {
        if k % 10 == 0 {
            Omnimagnet::PAPER.step_rk4(&mut plant, &[CURRENT_A; SOLENOIDS], AMBIENT_C, 0.01);
        }
        let now_us = (k + 1) * 1000;
        let readings = if k % 500 == 0 {
            let mut r = THERMOCOUPLE_NODES.map(|n| noisy(&mut seed, plant[n]));
            if stuck && k >= STICK_S * 1000 {
                r[0] = *stuck_c.get_or_insert(r[0]);
            }
            r.map(|temp_c| {
                Some(TimedReading {
                    result: Ok(Reading::new(temp_c)),
                    sampled_at_us: now_us,
                })
            })
        } else {
            [None; THERMOCOUPLES]
        };
        let inputs = OmniInputs {
            currents_a: [CURRENT_A as f32; SOLENOIDS],
            ambient_c: amb,
            readings,
            now_us,
            elapsed_us: 1000,
        };
        let o = *observer.tick(&mut state, &inputs);
        if out.verdict.is_none() && matches!(o.sensors[0], SensorStatus::Stuck { .. }) {
            out.verdict = Some(k as usize);
        }
        out.bias_w.push(observer.heat_bias_w(&state)[0]);
    }
    out
}

#[test]
fn a_thermocouple_stuck_while_its_solenoid_heats_gives_back_the_heat_it_taught() {
    let healthy = run(false);
    let stuck = run(true);
    assert_eq!(healthy.verdict, None, "no healthy reading is stuck");
    let verdict = stuck.verdict.expect("the stuck test sees it");
    // Its last change: the correction of `STICK_S`, whose screen notes the
    // biases before it fuses.
    let stick = STICK_S as usize * 1000 - 1;
    let at_stick_w = stuck.bias_w[stick];
    let taught_w = stuck.bias_w[verdict - 1] - at_stick_w;
    let healthy_moved_w = healthy.bias_w[verdict - 1] - healthy.bias_w[stick];
    let after_w = stuck.bias_w[verdict];
    println!(
        "stuck at {} s, verdict at {} ms: bias {at_stick_w:.3} W at the stick, \
         taught {taught_w:.3} W (healthy run {healthy_moved_w:.3} W), \
         {after_w:.3} W after the verdict (healthy run {:.3} W)",
        STICK_S, verdict, healthy.bias_w[verdict]
    );
    // The stuck reading, colder than the heating solenoid, taught its bias
    // a cooling the plant's readings did not (the test can tell).
    assert!(taught_w < -0.25, "{taught_w}");
    assert!(healthy_moved_w.abs() < 0.05, "{healthy_moved_w}");
    // The verdict takes it back: the bias where it was when the reading
    // last changed, and where the healthy run's is.
    assert!(
        (after_w - at_stick_w).abs() < 0.05,
        "{after_w} vs {at_stick_w}"
    );
    assert!(
        (after_w - healthy.bias_w[verdict]).abs() < 0.05,
        "{after_w} vs {}",
        healthy.bias_w[verdict]
    );
}
