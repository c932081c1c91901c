//! The filter's physics against the nonlinear model in absolute terms.
//!
//! The truth here is the filter's own device, `Omnimagnet::PAPER`,
//! integrated nonlinearly (`Omnimagnet::step_rk4`: `R(T)` Joule power,
//! `c_p(T)`, Appendix B's radiation, temperature-dependent convection).
//! **It shares every parameter with the filter**: the same tables, the
//! same conductances, capacities, radiators and `R0`. So these tests
//! measure only what the filter adds, the linearisation (re-linearised
//! every 5 K) and the Joule input `R(T) I^2` at the estimated
//! temperatures; a wrong model (a second radiator on the outer surface, a
//! conductance read the wrong way) is in the truth and the filter alike and
//! passes here. A relative check (better than the cold model, as in the
//! host tests) let the Joule power at `R(20 degC)` through: open loop it
//! left the solenoids 5.7-8.8 K low, with thermocouples the biases soaked
//! up the missing power (6-11 W) while the temperatures still looked right.
//!
//! Whether the truth is physical is claimed only against truths the code
//! did not produce: the paper's printed 3 A / 60 min figure (75.3, 71.1,
//! 66.0 degC) and its 3.8 A experiment (115 degC within 2 h), in
//! `omnimagnet::tests` (`matches_the_papers_3_a_figure`,
//! `reaches_what_the_papers_experiments_reached`). The 3 A run below is
//! that figure's run, and its truth is asserted to meet it; both runs stay
//! below 93 degC (the insulation limit is 120 degC, the paper's stop
//! 115 degC), inside what those two figures cover.

use super::*;
use crate::filter::testutil::Rng;
use crate::omnimagnet::{RelinearizeConfig, NODE_NAMES};

const AMBIENT_C: f64 = 22.0;
/// Predict step \[s\]: the nonlinear reference is stepped at the same
/// rate (RK4 at 0.1 s is exact to far below a millikelvin here; the
/// fastest node's time constant is about 0.25 s, see `step_rk4`).
const DT_S: f64 = 0.1;
/// Thermocouple period \[s\] (2 Hz, the filter's design).
const SAMPLE_S: f64 = 0.5;

/// The runs: all three solenoids at 3.8 A for 40 min (92.7 degC) and at
/// 3 A for 1 h (78.1 degC).
const RUNS: [(f64, f64); 2] = [(3.8, 2400.0), (3.0, 3600.0)];

struct Outcome {
    /// Largest |estimate - truth| of any element from `score_from_s` \[K\].
    worst_k: f64,
    worst_node: usize,
    worst_at_s: f64,
    /// Largest |heat bias| of any solenoid from `score_from_s` \[W\].
    worst_bias_w: f64,
    /// The truth's hottest element at the end \[degC\].
    hottest_c: f64,
    /// The truth's Joule power of each solenoid at the end \[W\].
    joule_w: [f64; SOLENOIDS],
    swaps: usize,
}

/// The observer (f64, default settings, re-linearising, a fresh gain after
/// each swap) and the nonlinear truth, both from the ambient, all three
/// solenoids at `current_a` for `duration_s`; with `thermocouples`, the six
/// readings of the truth plus 0.1 K noise at 2 Hz, else open loop.
fn run(current_a: f64, duration_s: f64, thermocouples: bool, score_from_s: f64) -> Outcome {
    let model = Omnimagnet::PAPER;
    let start = [AMBIENT_C; NODES];
    let config = RelinearizeConfig {
        dt_s: DT_S,
        ..RelinearizeConfig::default()
    };
    let mut relin = Relinearizer::new(model, config, &start, AMBIENT_C).unwrap();
    let mut obs = OmnimagnetObserver::<f64>::new(
        &model,
        relin.active(),
        &ObserverSettings::DEFAULT,
        &start,
        AMBIENT_C,
    )
    .unwrap();
    let mut truth = start;
    let currents = [current_a; SOLENOIDS];
    let mut rng = Rng::new(7);
    let per_sample = (SAMPLE_S / DT_S).round() as usize;
    let mut out = Outcome {
        worst_k: 0.0,
        worst_node: 0,
        worst_at_s: 0.0,
        worst_bias_w: 0.0,
        hottest_c: 0.0,
        joule_w: [0.0; SOLENOIDS],
        swaps: 0,
    };
    for k in 1..=(duration_s / DT_S).round() as usize {
        let now_s = k as f64 * DT_S;
        obs.predict(&currents, AMBIENT_C);
        model.step_rk4(&mut truth, &currents, AMBIENT_C, DT_S);
        if obs.follow(&mut relin, AMBIENT_C) == RelinearizePoll::Swapped {
            out.swaps += 1;
            let gain = obs.config().solve_gain().unwrap();
            obs.install_gain(gain).unwrap();
        }
        if thermocouples && k % per_sample == 0 {
            let z: [Option<f64>; THERMOCOUPLES] =
                core::array::from_fn(|j| Some(truth[THERMOCOUPLE_NODES[j]] + 0.1 * rng.gauss()));
            obs.correct(&z);
        }
        if now_s < score_from_s {
            continue;
        }
        for (i, (est, truth)) in obs.temperatures_c().iter().zip(&truth).enumerate() {
            if (est - truth).abs() > out.worst_k {
                (out.worst_k, out.worst_node, out.worst_at_s) = ((est - truth).abs(), i, now_s);
            }
        }
        for b in obs.heat_bias_w() {
            out.worst_bias_w = out.worst_bias_w.max(b.abs());
        }
    }
    out.hottest_c = truth.iter().copied().fold(f64::MIN, f64::max);
    for (p, s) in out.joule_w.iter_mut().zip(&model.geometry().solenoids) {
        *p = s.resistance().at_c(truth[s.node]) * current_a * current_a;
    }
    out
}

#[test]
fn open_loop_tracks_the_nonlinear_model_within_0_35_k() {
    for (current_a, duration_s) in RUNS {
        let o = run(current_a, duration_s, false, 0.0);
        println!(
            "open loop, {current_a} A for {duration_s} s (hottest {:.2} degC, {} swaps): \
             worst element {:.3} K ({} at {:.0} s)",
            o.hottest_c, o.swaps, o.worst_k, NODE_NAMES[o.worst_node], o.worst_at_s
        );
        assert!(
            o.hottest_c > 70.0,
            "the run must heat: {} degC",
            o.hottest_c
        );
        if current_a == 3.0 && duration_s == 3600.0 {
            // The truth of this run is the model the paper's 3 A figure
            // holds (its own RK4 at 0.5 s there, 0.1 s here).
            let (paper_run, _, holds) =
                crate::omnimagnet::tests::against_the_3a_figure(&Omnimagnet::PAPER);
            assert!(holds, "the truth fails the paper's 3 A figure");
            assert!(
                (o.hottest_c - paper_run[0]).abs() < 0.01,
                "{} against {} degC",
                o.hottest_c,
                paper_run[0]
            );
        }
        // README's figure for the open-loop observer following the
        // re-linearisations (measured 0.27 K and 0.31 K, both on the outer
        // cover insulation, whose convection and radiation are the most
        // nonlinear terms). The Joule power at R(20 degC): 8.8 K and 5.7 K
        // (measured with Eq. 1's radiation).
        assert!(
            o.worst_k < 0.35,
            "{current_a} A: {} off by {} K at {} s",
            NODE_NAMES[o.worst_node],
            o.worst_k,
            o.worst_at_s
        );
    }
}

#[test]
fn heat_biases_stay_near_zero_on_the_matched_model() {
    for (current_a, duration_s) in RUNS {
        // From 10 min: the biases start with a 5 W standard deviation and
        // the warm-up gain settles in the first minutes.
        let o = run(current_a, duration_s, true, 600.0);
        println!(
            "six thermocouples, {current_a} A for {duration_s} s (Joule {:.1} W): \
             worst bias {:.3} W, worst element {:.3} K ({})",
            o.joule_w.iter().fold(f64::INFINITY, |a, b| a.min(*b)),
            o.worst_bias_w,
            o.worst_k,
            NODE_NAMES[o.worst_node]
        );
        // The device is the filter's own model, so a bias is only what
        // the linearisation misses between re-linearisations: measured
        // 0.53 W and 0.54 W, 1-2 % of each solenoid's 30-60 W. A Joule
        // power off by `alpha0 (T - 20)` (0.27 at 90 degC) shows here as
        // 5.7-11 W, while the fused temperatures stay within 0.2 K.
        assert!(
            o.worst_bias_w < 1.0,
            "{current_a} A: a heat bias of {} W on the matched model",
            o.worst_bias_w
        );
        assert!(
            o.worst_k < 0.2,
            "{current_a} A: {} off by {} K with six thermocouples",
            NODE_NAMES[o.worst_node],
            o.worst_k
        );
    }
}
