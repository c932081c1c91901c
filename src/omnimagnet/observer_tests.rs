//! Tests of the observer on synthetic truth from the nonlinear model with
//! every parameter perturbed (the filter's model is never the truth's).
//! Meant for `cargo test --release`.

use super::*;
use crate::filter::testutil::Rng;
use crate::omnimagnet::{
    Contact, ConvectionParams, Peer, Preset, Radiator, RelinearizeConfig, NODE_NAMES,
    PAPER_OMNIMAGNET,
};

const AMBIENT_C: f64 = 22.0;
const SAMPLE_S: f64 = 0.5;

/// A factor uniform in [1 - a, 1 + a].
fn factor(rng: &mut Rng, a: f64) -> f64 {
    1.0 + a * (2.0 * rng.uniform() - 1.0)
}

/// The paper's Omnimagnet with every parameter scaled independently by a
/// factor in [1 - a, 1 + a]: each element's capacity (volume), each
/// conductance, each radiator's emissivity, each convection group's `h`,
/// each `R0`.
///
/// A convective conductance is `h_group * area`, and the group's `h` is
/// itself perturbed: drawing the area factor independently would compound
/// to `(1 + a)^2` (+44 % at `a = 0.2`), more than the "up to 20 %".
/// So each convective contact draws its *total* factor in [1 - a, 1 + a] and
/// its area takes that total divided by its group's factor.
fn perturbed(seed: u64, a: f64) -> Omnimagnet {
    let mut rng = Rng::new(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x1234_5678);
    let mut g = PAPER_OMNIMAGNET;
    for e in g.elements.iter_mut() {
        e.volume_m3 *= factor(&mut rng, a);
    }
    let mut conv = ConvectionParams::PAPER;
    conv.scale.iter_mut().for_each(|s| *s = factor(&mut rng, a));
    let air = g.inside_air_node;
    let elements = g.elements;
    let group_scale = |solid: usize| {
        elements[solid]
            .convection
            .map_or(1.0, |c| conv.scale[c.group.index()])
    };
    let mut contacts: Vec<Contact> = g.contacts.to_vec();
    for c in contacts.iter_mut() {
        let convective_solid = match c.peer {
            Peer::Ambient => Some(c.node),
            Peer::Node(j) if j == air => Some(c.node),
            Peer::Node(j) if c.node == air => Some(j),
            Peer::Node(_) => None,
        };
        let total = factor(&mut rng, a);
        let f = convective_solid.map_or(total, |s| total / group_scale(s));
        c.area_m2.iter_mut().for_each(|s| *s *= f);
    }
    g.contacts = Box::leak(contacts.into_boxed_slice());
    let mut radiators: Vec<Radiator> = g.radiators.to_vec();
    for r in radiators.iter_mut() {
        r.emissivity = (r.emissivity * factor(&mut rng, a)).min(1.0);
    }
    g.radiators = Box::leak(radiators.into_boxed_slice());
    for s in g.solenoids.iter_mut() {
        s.r0_ohm *= factor(&mut rng, a);
    }
    Omnimagnet::new(g, conv).unwrap()
}

/// Mean of `I^2` over `[t, t + dt]` per solenoid, as an RMS current \[A\]:
/// what a controller integrating its own current commands would pass.
fn rms_currents(preset: &Preset, t: f64, dt: f64) -> [f64; SOLENOIDS] {
    const SUB: usize = 16;
    let mut acc = [0.0; SOLENOIDS];
    for k in 0..SUB {
        let c = preset.currents_a(t + (k as f64 + 0.5) * dt / SUB as f64);
        for m in 0..SOLENOIDS {
            acc[m] += c[m] * c[m] / SUB as f64;
        }
    }
    acc.map(f64::sqrt)
}

/// The truth: the nonlinear model, integrated by RK4 with RMS currents;
/// and the information bound ("oracle"): the *nominal* model's unmeasured
/// elements driven by the *true* solenoid temperatures from the true start.
/// No estimator that uses the solenoid thermocouples and the nominal model
/// does better: the unmeasured elements have no sources, so their
/// temperatures follow from conductance ratios and capacities the sensors
/// cannot see.
struct Truth {
    model: Omnimagnet,
    temps_c: [f64; NODES],
    oracle_c: [f64; NODES],
    t_s: f64,
    step_s: f64,
}

impl Truth {
    fn advance_to(&mut self, preset: &Preset, t_end: f64) {
        while self.t_s < t_end - 1e-9 {
            let dt = self.step_s.min(t_end - self.t_s);
            let cur = rms_currents(preset, self.t_s, dt);
            self.oracle_c[..SOLENOIDS].copy_from_slice(&self.temps_c[..SOLENOIDS]);
            self.model.step_rk4(&mut self.temps_c, &cur, AMBIENT_C, dt);
            Omnimagnet::PAPER.step_rk4(&mut self.oracle_c, &cur, AMBIENT_C, dt);
            self.oracle_c[..SOLENOIDS].copy_from_slice(&self.temps_c[..SOLENOIDS]);
            self.t_s += dt;
        }
    }
}

/// What a thermocouple does in a run.
#[derive(Clone, Copy, PartialEq)]
enum Failure {
    None,
    /// Reads this value from `at_s` on, no fault bit.
    Reads {
        sensor: usize,
        at_s: f64,
        value_c: f64,
    },
    /// The driver reports open circuit from `at_s` on.
    DriverOpen {
        sensor: usize,
        at_s: f64,
    },
    /// Jumps by `offset_k` from `at_s` on, no fault bit.
    Jumps {
        sensor: usize,
        at_s: f64,
        offset_k: f64,
    },
    /// Freezes at its value at `at_s`, no fault bit.
    Sticks {
        sensor: usize,
        at_s: f64,
    },
}

struct Scenario {
    preset: Preset,
    seed: u64,
    perturbation: f64,
    /// Filter predict step \[s\].
    dt_s: f64,
    duration_s: f64,
    /// Errors are scored from here on \[s\].
    score_from_s: f64,
    settings: ObserverSettings,
    failure: Failure,
    relinearize: bool,
    /// Solve and install a new gain after every model swap.
    refresh_gain: bool,
    /// Truth RK4 step \[s\] (with the RMS current over the step: the 10 Hz
    /// ripple of the rotating dipole's `I^2` moves a solenoid by about
    /// 3e-4 K, so averaging it is exact for this purpose).
    truth_step_s: f64,
}

impl Scenario {
    fn new(preset: Preset, seed: u64) -> Self {
        Self {
            preset,
            seed,
            perturbation: 0.2,
            dt_s: 0.1,
            duration_s: 3600.0,
            score_from_s: 1200.0,
            settings: ObserverSettings::DEFAULT,
            failure: Failure::None,
            relinearize: true,
            refresh_gain: true,
            truth_step_s: 0.1,
        }
    }
}

struct Outcome {
    /// Per element RMS of (estimate - truth) over the scored window \[K\].
    rms_k: [f64; NODES],
    /// The same for the oracle (the information bound) \[K\].
    bound_k: [f64; NODES],
    /// Largest |error| of any element in the scored window \[K\].
    max_k: f64,
    /// Largest |error| of any element after a failure \[K\].
    max_after_failure_k: f64,
    /// Mean NEES of the 16 temperatures over the scored window.
    nees: f64,
    /// Time from the failure to the first flag \[s\].
    flagged_after_s: Option<f64>,
    /// Healthy sensors ever flagged.
    false_flags: usize,
    /// Model swaps during the run.
    swaps: usize,
}

fn run(sc: &Scenario) -> Outcome {
    let truth_model = perturbed(sc.seed, sc.perturbation);
    let start = match sc.preset {
        Preset::PassiveCooling => Preset::PASSIVE_COOLING.initial_temps_c(&truth_model, AMBIENT_C),
        _ => [AMBIENT_C; NODES],
    };
    let mut truth = Truth {
        model: truth_model,
        temps_c: start,
        oracle_c: start,
        t_s: 0.0,
        step_s: sc.truth_step_s,
    };
    let nominal = Omnimagnet::PAPER;
    let wrong = start.map(|t| t + 10.0);
    let cfg = RelinearizeConfig {
        dt_s: sc.dt_s,
        ..RelinearizeConfig::default()
    };
    let mut relin = Relinearizer::new(nominal, cfg, &wrong, AMBIENT_C).unwrap();
    let mut obs =
        OmnimagnetObserver::<f64>::new(&nominal, relin.active(), &sc.settings, &wrong, AMBIENT_C)
            .unwrap();
    let mut noise = Rng::new(sc.seed ^ 0xABCD_EF01);
    let steps = (sc.duration_s / sc.dt_s).round() as usize;
    let per_sample = (SAMPLE_S / sc.dt_s).round() as usize;
    let mut sq = [0.0; NODES];
    let mut sq_oracle = [0.0; NODES];
    let (mut n, mut nees, mut max_k, mut max_after) = (0usize, 0.0, 0.0f64, 0.0f64);
    let mut flagged_after_s = None;
    let mut false_flags = 0;
    let mut stuck_value = None;
    let mut swaps = 0;
    for k in 0..steps {
        let t = k as f64 * sc.dt_s;
        let cur = rms_currents(&sc.preset, t, sc.dt_s);
        obs.predict(&cur, AMBIENT_C);
        if sc.relinearize {
            let poll = obs.follow(&mut relin, AMBIENT_C);
            swaps += usize::from(poll == RelinearizePoll::Swapped);
            if poll == RelinearizePoll::Swapped && sc.refresh_gain {
                let gain = obs.config().solve_gain().unwrap();
                obs.install_gain(gain).unwrap();
            }
        }
        if (k + 1) % per_sample != 0 {
            continue;
        }
        let now = (k + 1) as f64 * sc.dt_s;
        truth.advance_to(&sc.preset, now);
        let mut samples: [Option<Result<f64, SensorFault>>; THERMOCOUPLES] =
            core::array::from_fn(|j| {
                Some(Ok(
                    truth.temps_c[THERMOCOUPLE_NODES[j]] + 0.1 * noise.gauss()
                ))
            });
        let failed = match sc.failure {
            Failure::None => None,
            Failure::Reads {
                sensor,
                at_s,
                value_c,
            } if now >= at_s => {
                samples[sensor] = Some(Ok(value_c));
                Some((sensor, at_s))
            }
            Failure::DriverOpen { sensor, at_s } if now >= at_s => {
                samples[sensor] = Some(Err(SensorFault::OpenCircuit));
                Some((sensor, at_s))
            }
            Failure::Jumps {
                sensor,
                at_s,
                offset_k,
            } if now >= at_s => {
                if let Some(Ok(v)) = samples[sensor] {
                    samples[sensor] = Some(Ok(v + offset_k));
                }
                Some((sensor, at_s))
            }
            Failure::Sticks { sensor, at_s } if now >= at_s => {
                let v = *stuck_value.get_or_insert(match samples[sensor] {
                    Some(Ok(v)) => v,
                    _ => unreachable!(),
                });
                samples[sensor] = Some(Ok(v));
                Some((sensor, at_s))
            }
            _ => None,
        };
        let rep = obs.correct_samples(&samples);
        for j in 0..THERMOCOUPLES {
            if rep.flagged(j) {
                match failed {
                    Some((s, at)) if s == j => {
                        flagged_after_s.get_or_insert(now - at);
                    }
                    _ => false_flags += 1,
                }
            }
        }
        let est = obs.temperatures_c();
        let err: [f64; NODES] = core::array::from_fn(|i| est[i] - truth.temps_c[i]);
        if failed.is_some() {
            max_after = err.iter().fold(max_after, |m, e| m.max(e.abs()));
        }
        if now >= sc.score_from_s {
            n += 1;
            for i in 0..NODES {
                sq[i] += err[i] * err[i];
                let e = truth.oracle_c[i] - truth.temps_c[i];
                sq_oracle[i] += e * e;
            }
            max_k = err.iter().fold(max_k, |m, e| m.max(e.abs()));
            let cov = match obs.mode() {
                GainMode::TimeVarying => obs.state().filter.cov,
                GainMode::SteadyState => *obs.config().gain().posterior(),
            };
            let p = cov.fixed_view::<NODES, NODES>(0, 0).into_owned();
            let e = SVector::<f64, NODES>::from_column_slice(&err);
            nees += (e.transpose() * p.try_inverse().unwrap() * e)[(0, 0)];
        }
    }
    Outcome {
        rms_k: sq.map(|s| (s / n.max(1) as f64).sqrt()),
        bound_k: sq_oracle.map(|s| (s / n.max(1) as f64).sqrt()),
        max_k,
        max_after_failure_k: max_after,
        nees: nees / n.max(1) as f64,
        flagged_after_s,
        false_flags,
        swaps,
    }
}

fn fmt_row(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:5.2}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Slack of the filter over the information bound \[K\]: the oracle knows
/// the true start and the noise-free solenoid temperatures, the filter
/// starts 10 K wrong (largest excess measured: 0.24 K, the core in
/// passive cooling, seed 2, whose 2.5 h time constant keeps part of the
/// start error after 20 min).
const BOUND_SLACK_K: f64 = 0.3;
const TARGET_K: f64 = 0.5;

/// Checks one run: the solenoids within 0.05 K (README: 0.01-0.02 K), every element within the
/// 0.5 K target or, where the information bound makes that impossible,
/// within the bound plus the slack. Returns the elements that missed 0.5 K.
fn check_accuracy(label: &str, o: &Outcome) -> Vec<usize> {
    let bound = &o.bound_k;
    let mut missed = Vec::new();
    for i in 0..NODES {
        let rms = o.rms_k[i];
        if i < SOLENOIDS {
            assert!(rms < 0.05, "{label}: {} rms {rms:.3} K", NODE_NAMES[i]);
        }
        if rms >= TARGET_K {
            missed.push(i);
            assert!(
                rms < bound[i] + BOUND_SLACK_K,
                "{label}: {} rms {rms:.2} K, bound {:.2} K",
                NODE_NAMES[i],
                bound[i]
            );
        }
    }
    missed
}

const PRESETS: [Preset; 5] = [
    Preset::ALL_THREE,
    Preset::SOLENOID_1,
    Preset::SOLENOIDS_2_AND_3,
    Preset::ROTATING_DIPOLE,
    Preset::PASSIVE_COOLING,
];

/// Runs every preset with three seeds of `+-perturbation` parameter errors
/// and checks each run with [`check_accuracy`]; also requires the RMS over
/// all 16 elements within 0.5 K. Returns the element-runs that missed
/// 0.5 K on their own and the largest element RMS of any run \[K\].
fn sweep(perturbation: f64) -> (usize, f64) {
    let mut missed_total = 0;
    let mut worst_k = 0.0f64;
    let mut nees = Vec::new();
    println!(
        "+-{:.0} %: preset  seed  max_K  all_rms_K  per-element RMS [K] (node order)",
        perturbation * 100.0
    );
    for preset in PRESETS {
        for seed in 1..=3 {
            let mut sc = Scenario::new(preset, seed);
            sc.perturbation = perturbation;
            let o = run(&sc);
            let label = format!("{} seed {seed}", preset.name());
            let all = (o.rms_k.iter().map(|v| v * v).sum::<f64>() / NODES as f64).sqrt();
            println!(
                "{:16} {seed:4}  {:5.2}  {all:9.2}  [{}]",
                preset.name(),
                o.max_k,
                fmt_row(&o.rms_k)
            );
            println!("{:16} bound            [{}]", "", fmt_row(&o.bound_k));
            // The RMS over the elements meets 0.5 K, or (where the
            // information bound makes that impossible) the bound's RMS plus
            // the slack.
            let bound_all = (o.bound_k.iter().map(|v| v * v).sum::<f64>() / NODES as f64).sqrt();
            assert!(
                all < TARGET_K.max(bound_all + BOUND_SLACK_K),
                "{label}: RMS over the elements {all:.2} K, bound {bound_all:.2} K"
            );
            let missed = check_accuracy(&label, &o);
            for i in &missed {
                println!(
                    "  {label}: {} misses 0.5 K: {:.2} K (bound {:.2} K)",
                    NODE_NAMES[*i], o.rms_k[*i], o.bound_k[*i]
                );
            }
            missed_total += missed.len();
            worst_k = o.rms_k.iter().fold(worst_k, |w, r| w.max(*r));
            assert_eq!(o.false_flags, 0, "{label}: healthy sensor flagged");
            assert!(o.swaps > 0, "{label}: the model never followed the device");
            nees.push(o.nees);
        }
    }
    let mean_nees = nees.iter().sum::<f64>() / nees.len() as f64;
    println!(
        "element-runs missing 0.5 K: {missed_total} of {}; mismatched-model mean NEES (16 dof): {mean_nees:.0}",
        NODES * PRESETS.len() * 3
    );
    (missed_total, worst_k)
}

/// The test: every preset, three seeds of +-20 % errors in every
/// parameter, filter at 0.1 s (the 1 ms run is below), 1 h, scored after
/// 20 min. The RMS over the 16 elements stays within 0.5 K in every run.
///
/// Element by element, a few unmeasured elements (inside air, core, paper,
/// frame 4: far from the solenoids, coupled through the most uncertain
/// convective paths) miss 0.5 K in the hottest presets, and the oracle
/// misses them by as much: with the solenoids as the only measured nodes,
/// their error is the model's, and no filter can remove it. So the test
/// holds each element to that information bound (plus the slack for the
/// wrong start) and then shows the misses are model error: the same sweep
/// with +-5 % errors has every element of every run within 0.5 K, and the
/// worst element error shrinks in proportion to the parameter error (a
/// filter defect would not).
#[test]
fn accuracy_under_20_percent_parameter_errors() {
    let (missed, worst_20) = sweep(0.2);
    // The measured figure (README): a regression shows up here.
    assert!(missed <= 22, "{missed} element-runs miss 0.5 K");
    let (missed_5, worst_5) = sweep(0.05);
    assert_eq!(missed_5, 0, "+-5 %: element-runs missing 0.5 K");
    let ratio = worst_5 / worst_20;
    println!("worst element RMS: +-20 % {worst_20:.2} K, +-5 % {worst_5:.2} K, ratio {ratio:.2}");
    assert!(
        (0.15..0.4).contains(&ratio),
        "worst element error does not scale with the model error: {ratio:.2}"
    );
}

/// The control loop's rate: predict every 1 ms (steady-state gain after
/// the warm-up, re-linearising), the rotating dipole's 10 Hz `I^2` ripple
/// resolved, 20 min, scored after 10 min. The same figures as the 0.1 s
/// runs.
#[test]
fn one_ms_rotating_dipole() {
    let mut sc = Scenario::new(Preset::ROTATING_DIPOLE, 1);
    sc.dt_s = 1e-3;
    sc.duration_s = 1200.0;
    sc.score_from_s = 600.0;
    sc.truth_step_s = 0.01;
    let o = run(&sc);
    println!("1 ms rotating dipole: rms [{}]", fmt_row(&o.rms_k));
    println!("             bound:     [{}]", fmt_row(&o.bound_k));
    let missed = check_accuracy("1 ms rotating dipole", &o);
    assert!(missed.is_empty(), "{missed:?}");
    assert_eq!(o.false_flags, 0);
    assert!(o.swaps > 0);
}

fn failure_run(failure: Failure) -> Outcome {
    let mut sc = Scenario::new(Preset::ALL_THREE, 2);
    sc.duration_s = 1500.0;
    sc.score_from_s = 600.0;
    sc.failure = failure;
    run(&sc)
}

/// One thermocouple fails open mid-run, seen as a 1372 degC reading (no
/// fault bit) or as the driver's `OpenCircuit`; or jumps by 5 K. The
/// estimates stay within 2 K of the truth and the sensor is flagged within
/// 1 s; no healthy sensor is flagged.
#[test]
fn failed_thermocouple_is_flagged_within_1_s() {
    let at_s = 600.2;
    for (name, failure) in [
        (
            "open, 1372 degC",
            Failure::Reads {
                sensor: 2,
                at_s,
                value_c: 1372.0,
            },
        ),
        (
            "open, driver fault",
            Failure::DriverOpen { sensor: 0, at_s },
        ),
        (
            "jump +5 K",
            Failure::Jumps {
                sensor: 4,
                at_s,
                offset_k: 5.0,
            },
        ),
    ] {
        let o = failure_run(failure);
        println!(
            "{name}: flagged after {:?} s, max error after failure {:.2} K",
            o.flagged_after_s, o.max_after_failure_k
        );
        let latency = o.flagged_after_s.expect("never flagged");
        assert!(latency <= 1.0, "{name}: flagged after {latency} s");
        assert!(
            o.max_after_failure_k < 2.0,
            "{name}: {}",
            o.max_after_failure_k
        );
        assert_eq!(o.false_flags, 0, "{name}");
    }
}

/// A thermocouple sticks (no fault bit) while the coil heats: fused while
/// within the gate, flagged once the truth has moved away; the estimates
/// stay within 2 K.
#[test]
fn stuck_thermocouple_is_flagged_and_does_not_drag() {
    let o = failure_run(Failure::Sticks {
        sensor: 1,
        at_s: 120.2,
    });
    println!(
        "stuck: flagged after {:?} s, max error after failure {:.2} K",
        o.flagged_after_s, o.max_after_failure_k
    );
    let latency = o.flagged_after_s.expect("never flagged");
    // README: after 15 s of heating (14.8 s measured).
    assert!(latency <= 20.0, "flagged after {latency} s");
    assert!(o.max_after_failure_k < 2.0, "{}", o.max_after_failure_k);
    assert_eq!(o.false_flags, 0);
}

/// NEES on the matched model: the truth is the observer's own augmented
/// linear model (`F`, `G`, `Q`, `R`, start drawn from its start covariance)
/// at 0.5 s, so the filter is consistent by construction if it is wired
/// right (deviation coordinates, input columns, steady gain). With `R`
/// runs and 19 states the ensemble mean of a chi-square(19) has standard
/// deviation sqrt(2 * 19 / R); the time average has at most that spread, so
/// the 99.9 % band is 19 +- 3.29 sqrt(38 / R). Time-varying: 50 runs of
/// 10 min. Steady state: 30 runs of 30 min scored over the last 10 min,
/// after the warm-up has switched to the steady gain.
#[test]
fn nees_is_consistent_on_the_matched_model() {
    let op = [40.0; NODES];
    let lin = Omnimagnet::PAPER
        .linearize(&op, AMBIENT_C, SAMPLE_S)
        .unwrap();
    for mode in [GainMode::TimeVarying, GainMode::SteadyState] {
        let mut settings = ObserverSettings::DEFAULT;
        settings.mode = mode;
        let (runs, steps, score_from) = match mode {
            GainMode::TimeVarying => (50, 1200, 240),
            GainMode::SteadyState => (30, 3600, 2400),
        };
        let mut rng = Rng::new(99);
        let (mut total, mut n) = (0.0, 0usize);
        let mut switched = None;
        for _ in 0..runs {
            let mut obs =
                OmnimagnetObserver::<f64>::new(&Omnimagnet::PAPER, &lin, &settings, &op, AMBIENT_C)
                    .unwrap();
            let k = obs.config().kalman().clone();
            let (f, g, h, q) = (*k.f(), *k.g(), k.h(), *k.q());
            // Start: the prior's common and independent parts, the biases.
            let common = settings.initial_common_sigma_k * rng.gauss();
            let mut x = SVector::<f64, STATES>::from_fn(|i, _| {
                if i < NODES {
                    obs.state().filter.x[i] + common + settings.initial_sigma_k * rng.gauss()
                } else {
                    settings.initial_bias_sigma_w * rng.gauss()
                }
            });
            let u = SVector::<f64, INPUTS>::from_column_slice(&[0.0, 0.0, 0.0, AMBIENT_C, 1.0]);
            for step in 0..steps {
                let w = SVector::<f64, STATES>::from_fn(|i, _| q[(i, i)].sqrt() * rng.gauss());
                x = f * x + g * u + w;
                obs.predict(&[0.0; SOLENOIDS], AMBIENT_C);
                let z = h * x;
                let readings: [Option<f64>; THERMOCOUPLES] = core::array::from_fn(|j| {
                    Some(z[j] + obs.config().origin_c()[THERMOCOUPLE_NODES[j]] + 0.1 * rng.gauss())
                });
                obs.correct(&readings);
                if obs.mode() == GainMode::SteadyState {
                    switched.get_or_insert(step);
                }
                if step >= score_from {
                    assert_eq!(obs.mode(), mode);
                    let cov = match obs.mode() {
                        GainMode::TimeVarying => obs.state().filter.cov,
                        GainMode::SteadyState => *obs.config().gain().posterior(),
                    };
                    let e = x - obs.state().filter.x;
                    total += (e.transpose() * cov.try_inverse().unwrap() * e)[(0, 0)];
                    n += 1;
                }
            }
        }
        let mean = total / n as f64;
        println!("matched-model NEES ({mode:?}): {mean:.2} (19 dof), steady after {switched:?} corrections");
        let half = 3.29 * (38.0 / runs as f64).sqrt();
        assert!(
            (19.0 - half..=19.0 + half).contains(&mean),
            "{mode:?}: mean NEES {mean}"
        );
    }
}

/// Which elements are observable from which thermocouples, for the 16-node
/// model and for the observer's augmented model (with the heat biases).
#[test]
fn observability_of_sensor_sets() {
    let lin = Omnimagnet::PAPER
        .linearize(&[AMBIENT_C; NODES], AMBIENT_C, 1e-3)
        .unwrap();
    let obs = OmnimagnetObserver::<f64>::new(
        &Omnimagnet::PAPER,
        &lin,
        &ObserverSettings::DEFAULT,
        &[AMBIENT_C; NODES],
        AMBIENT_C,
    )
    .unwrap();
    let sets: [(&str, [bool; THERMOCOUPLES]); 6] = [
        ("all six", [true; 6]),
        ("one per solenoid", [true, false, true, false, true, false]),
        ("solenoid 1 only", [true, true, false, false, false, false]),
        ("solenoid 2 only", [false, false, true, true, false, false]),
        ("solenoid 3 only", [false, false, false, false, true, true]),
        (
            "one thermocouple",
            [true, false, false, false, false, false],
        ),
    ];
    let mut results = Vec::new();
    for (name, sel) in sets {
        let e = element_observability(&lin, &sel);
        let a = obs.config().observability(&sel, 1e-9);
        let marks: String = a
            .observable
            .iter()
            .map(|o| if *o { '+' } else { '.' })
            .collect();
        let worst = e.unobservable_share.iter().fold(0.0f64, |m, s| m.max(*s));
        println!(
            "{name:18} 16-node rank {:2} (worst share {worst:.1e}); augmented rank {:2} [{marks}]",
            e.rank, a.rank
        );
        results.push((e, a));
    }
    // All six and one per solenoid see the same three nodes.
    assert_eq!(results[0].0, results[1].0);
    assert_eq!(results[0].1, results[1].1);
    // The network is connected and each solenoid feeds all others through
    // it, so the 16 temperatures are observable from any one node; the
    // three biases need all three solenoids measured.
    for (e, _) in &results {
        assert!(e.is_full(), "rank {}", e.rank);
    }
    assert!(results[0].1.is_full());
    assert_eq!(results[2].0, results[5].0);
    for (_, a) in &results[2..] {
        assert!(!a.is_full(), "one node cannot separate three biases");
    }
}

/// A model swap: `F` and `G` follow at once, the estimate is continuous
/// (only its origin moves), the gain is marked stale until a new one is
/// installed. Keeping the stale gain costs almost nothing in accuracy.
#[test]
fn relinearization_swaps_the_model_and_keeps_the_estimate() {
    let nominal = Omnimagnet::PAPER;
    let start = [AMBIENT_C; NODES];
    let mut relin =
        Relinearizer::new(nominal, RelinearizeConfig::default(), &start, AMBIENT_C).unwrap();
    let mut obs = OmnimagnetObserver::<f64>::new(
        &nominal,
        relin.active(),
        &ObserverSettings::DEFAULT,
        &start,
        AMBIENT_C,
    )
    .unwrap();
    // Move the estimate 8 K up: the relinearizer must start and swap.
    obs.correct(&[Some(30.0); THERMOCOUPLES]);
    let mut swapped = false;
    for _ in 0..100 {
        let before = obs.temperatures_c();
        if obs.follow(&mut relin, AMBIENT_C) == RelinearizePoll::Swapped {
            let after = obs.temperatures_c();
            for i in 0..NODES {
                assert!((before[i] - after[i]).abs() < 1e-9, "node {i}");
            }
            swapped = true;
            break;
        }
    }
    assert!(swapped);
    assert!(obs.gain_is_stale());
    let f = obs.config().kalman().f();
    let ad = &relin.active().discrete.ad;
    assert_eq!(f.fixed_view::<NODES, NODES>(0, 0).into_owned(), *ad);
    assert_eq!(
        obs.config().origin_c().as_slice(),
        &relin.active().op_temps_c[..]
    );
    let gain = obs.config().solve_gain().unwrap();
    obs.install_gain(gain).unwrap();
    assert!(!obs.gain_is_stale());
    // A gain for another period is refused.
    let mut other = obs.config().clone();
    other.period += 1;
    assert!(obs.install_gain(other.solve_gain().unwrap()).is_err());
    // Another step is refused and changes nothing.
    let lin = nominal.linearize(&start, AMBIENT_C, 0.5).unwrap();
    let snapshot = obs.clone();
    assert_eq!(
        obs.install_linearization(&lin),
        Err(BuildError::InvalidTimeStep)
    );
    assert_eq!(obs, snapshot);

    let fresh = run(&Scenario::new(Preset::ALL_THREE, 1));
    let mut stale_sc = Scenario::new(Preset::ALL_THREE, 1);
    stale_sc.refresh_gain = false;
    let stale = run(&stale_sc);
    let worst = (0..NODES)
        .map(|i| (fresh.rms_k[i] - stale.rms_k[i]).abs())
        .fold(0.0, f64::max);
    println!("stale vs refreshed gain: largest RMS difference {worst:.4} K");
    // Measured 0.015 K on the model that reaches 115 degC (0.001 K, README's
    // figure, on the cooler one before it): a gain a few kelvin stale is
    // suboptimal, not wrong.
    assert!(worst < 0.02, "{worst}");
}

/// f32 and f64 observers on the same 1 ms inputs and readings, 10 min of
/// heating without re-linearisation (so the deviations grow to 15 K), agree
/// within README's 0.05 K (measured: 0.035 K). The difference is f32's rounding of
/// `F = I + A dt` (about three digits of `A dt`) and of the solved gain, a
/// model error far below the parameter uncertainty.
#[test]
fn f32_matches_f64_at_1_ms() {
    let nominal = Omnimagnet::PAPER;
    let truth_model = perturbed(4, 0.2);
    let preset = Preset::ALL_THREE;
    let start = [AMBIENT_C; NODES];
    let mut settings = ObserverSettings::DEFAULT;
    settings.warmup_corrections = 0;
    let lin = nominal.linearize(&start, AMBIENT_C, 1e-3).unwrap();
    let mut o64 =
        OmnimagnetObserver::<f64>::new(&nominal, &lin, &settings, &start, AMBIENT_C).unwrap();
    let mut o32 =
        OmnimagnetObserver::<f32>::new(&nominal, &lin, &settings, &start, AMBIENT_C).unwrap();
    let mut truth = start;
    let mut rng = Rng::new(5);
    let mut worst: f64 = 0.0;
    for k in 0..600_000usize {
        let cur = preset.currents_a(0.0);
        o64.predict(&cur, AMBIENT_C);
        o32.predict(&cur.map(|c| c as f32), AMBIENT_C as f32);
        if (k + 1) % 500 == 0 {
            truth_model.step_rk4(&mut truth, &cur, AMBIENT_C, SAMPLE_S);
            let z: [f64; THERMOCOUPLES] =
                core::array::from_fn(|j| truth[THERMOCOUPLE_NODES[j]] + 0.1 * rng.gauss());
            o64.correct(&z.map(Some));
            o32.correct(&z.map(|v| Some(v as f32)));
            let (a, b) = (o64.temperatures_c(), o32.temperatures_c());
            for i in 0..NODES {
                worst = worst.max((a[i] - f64::from(b[i])).abs());
            }
        }
    }
    println!("f32 vs f64 over 10 min at 1 ms: largest difference {worst:.4} K");
    assert!(worst < 0.05, "{worst}");
}

/// Open loop (no reading), 2 h at 3.8 A on all three solenoids at 1 ms,
/// steady-state mode: the `f32` observer's mean predict, with the rounding
/// carried, stays within 0.01 K of the same predict in `f64` (the paper's
/// experiment heats the nodes 90 K above the operating point). The
/// difference left is `f32`'s rounding of the model's entries, not of the
/// 7.2 million increments.
#[test]
fn f32_open_loop_does_not_drift_over_two_hours() {
    let nominal = Omnimagnet::PAPER;
    let start = [AMBIENT_C; NODES];
    let mut settings = ObserverSettings::DEFAULT;
    settings.warmup_corrections = 0;
    let lin = nominal.linearize(&start, AMBIENT_C, 1e-3).unwrap();
    let mut o64 =
        OmnimagnetObserver::<f64>::new(&nominal, &lin, &settings, &start, AMBIENT_C).unwrap();
    let mut o32 =
        OmnimagnetObserver::<f32>::new(&nominal, &lin, &settings, &start, AMBIENT_C).unwrap();
    let cur = [3.8; SOLENOIDS];
    for _ in 0..7_200_000u32 {
        o64.predict(&cur, AMBIENT_C);
        o32.predict(&cur.map(|c| c as f32), AMBIENT_C as f32);
    }
    let (a, b) = (o64.temperatures_c(), o32.temperatures_c());
    let worst = (0..NODES).fold(0.0f64, |w, i| w.max((a[i] - f64::from(b[i])).abs()));
    let hottest = a.iter().fold(f64::MIN, |h, t| h.max(*t));
    println!(
        "f32 open loop, 2 h at 3.8 A: hottest {hottest:.2} degC, largest difference {worst:.5} K"
    );
    assert!(hottest > 100.0, "the run must heat: {hottest}");
    assert!(worst < 0.01, "{worst}");
}

#[test]
fn inputs_readings_and_settings_are_validated() {
    let nominal = Omnimagnet::PAPER;
    let start = [AMBIENT_C; NODES];
    let lin = nominal.linearize(&start, AMBIENT_C, 1e-3).unwrap();
    let build = |s: &ObserverSettings| {
        OmnimagnetObserver::<f32>::new(&nominal, &lin, s, &start, AMBIENT_C).map(|_| ())
    };
    let name = |r: Result<(), BuildError>| match r {
        Err(BuildError::InvalidParameter { name }) => name,
        other => panic!("{other:?}"),
    };
    let mut s = ObserverSettings::DEFAULT;
    s.sensors = [false; THERMOCOUPLES];
    assert_eq!(name(build(&s)), "sensors");
    let mut s = ObserverSettings::DEFAULT;
    s.thermocouple_sigma_k = 0.0;
    assert_eq!(name(build(&s)), "thermocouple_sigma_k");
    let mut s = ObserverSettings::DEFAULT;
    s.node_noise_k2_per_s[3] = f64::NAN;
    assert_eq!(name(build(&s)), "node_noise_k2_per_s");
    let mut s = ObserverSettings::DEFAULT;
    s.correction_period_s = 1e-5;
    assert_eq!(name(build(&s)), "correction_period_s");
    let mut s = ObserverSettings::DEFAULT;
    s.gate_threshold = 0.0;
    assert_eq!(name(build(&s)), "threshold");
    let mut bad = start;
    bad[5] = f64::INFINITY;
    assert_eq!(
        name(
            OmnimagnetObserver::<f64>::new(
                &nominal,
                &lin,
                &ObserverSettings::DEFAULT,
                &bad,
                AMBIENT_C
            )
            .map(|_| ())
        ),
        "initial_temps_c"
    );

    // One thermocouple per solenoid: the others are Disabled whatever they
    // read, and the steady gain ignores them.
    let settings = ObserverSettings::with_sensors([true, false, true, false, true, false]);
    let mut obs =
        OmnimagnetObserver::<f32>::new(&nominal, &lin, &settings, &start, AMBIENT_C).unwrap();
    for j in [1, 3, 5] {
        assert!(obs
            .config()
            .gain()
            .gain()
            .column(j)
            .iter()
            .all(|v| *v == 0.0));
    }
    let rep = obs.correct(&[
        Some(22.0),
        Some(1e30),
        Some(22.0),
        Some(f32::NAN),
        None,
        None,
    ]);
    assert_eq!(rep.verdicts[1], ThermocoupleVerdict::Disabled);
    assert_eq!(rep.verdicts[3], ThermocoupleVerdict::Disabled);
    assert_eq!(rep.verdicts[4], ThermocoupleVerdict::Missing);
    assert_eq!(rep.fused(), 2);
    // A driver fault is reported and flagged at once, not fused.
    let rep = obs.correct_samples(&[
        Some(Ok(22.0)),
        None,
        Some(Err(SensorFault::ShortToGnd)),
        None,
        Some(Ok(22.0)),
        None,
    ]);
    assert_eq!(
        rep.verdicts[2],
        ThermocoupleVerdict::Faulted(SensorFault::ShortToGnd)
    );
    assert!(rep.flagged(2) && !rep.flagged(0));
    assert_eq!(rep.fused(), 2);
    // Non-finite inputs: the last finite ones are held, nothing is poisoned.
    let before = obs.temperatures_c();
    assert_eq!(obs.predict(&[3.8; 3], AMBIENT_C as f32), InputStatus::Used);
    assert_eq!(
        obs.predict(&[f32::NAN, 3.8, 3.8], AMBIENT_C as f32),
        InputStatus::Dropped
    );
    assert_eq!(obs.predict(&[3.8; 3], f32::INFINITY), InputStatus::Dropped);
    let after = obs.temperatures_c();
    assert!(after.iter().all(|t| t.is_finite()));
    assert!(after[0] > before[0], "held power still heats");
    // The sizes the module docs state.
    let (cfg, st) = (
        core::mem::size_of::<ObserverConfig<f32>>(),
        core::mem::size_of::<ObserverState<f32>>(),
    );
    println!("f32 sizes: config {cfg} B, state {st} B");
    assert!(cfg <= 10 * 1024 && st <= 2 * 1024, "{cfg} {st}");
}

/// The structured mean predict is the general `F x + G u` of the augmented
/// model: the same numbers for any state (biases included) and input, at
/// the cold and at a hot operating point.
#[test]
fn mean_model_predict_is_the_full_product() {
    let mut rng = Rng::new(7);
    for op_c in [AMBIENT_C, 90.0] {
        let model = Omnimagnet::PAPER;
        let lin = model.linearize(&[op_c; NODES], AMBIENT_C, 0.5).unwrap();
        let cfg = ObserverConfig::<f64>::new(&model, &lin, &ObserverSettings::DEFAULT).unwrap();
        for _ in 0..20 {
            let x0 = SVector::<f64, STATES>::from_fn(|i, _| {
                if i < NODES {
                    10.0 * rng.gauss()
                } else {
                    3.0 * rng.gauss()
                }
            });
            let u = SVector::<f64, INPUTS>::from([
                20.0 * rng.uniform(),
                5.0 * rng.uniform(),
                40.0 * rng.uniform(),
                AMBIENT_C + rng.gauss(),
                1.0,
            ]);
            let mut full = x0;
            crate::filter::predict_mean(cfg.kalman(), &mut full, &u);
            let mut structured = x0;
            cfg.model().predict(&mut structured, &u, &mut [0.0; NODES]);
            let diff = (full - structured).abs().max();
            assert!(
                diff < 1e-12 * (1.0 + full.abs().max()),
                "{op_c} degC: {diff}"
            );
        }
    }
}

/// Temperature from resistance as a virtual sensor: with readings from the
/// thermocouples on solenoids 1 and 3 only (solenoid 2's silent), solenoid
/// 2 carries a heat the model does not know (a 2 W bias: the three biases
/// need all three solenoids measured, see the observability test; built
/// for those two solenoids alone the filter has no steady-state gain and
/// says so). Its resistance reading (the drive's voltage and current through
/// [`ResistanceSensor`], 10 mV and 1 mA noise) makes it observable: the
/// estimate of solenoid 2 and its bias converge, whatever the configured gain mode, while
/// the thermocouple-only filter keeps the error. The first reading moves a
/// steady-state observer to the time-varying filter for good. A reading 15 K off (a
/// resistance that does not fit the model) is rejected by the gate.
#[test]
fn resistance_readings_are_fused_like_a_thermocouple() {
    use crate::protect::resistance_sensor::ResistanceSensor;
    const BIAS_W: f64 = 2.0;
    const CURRENT_A: f64 = 3.0;
    let op = [40.0; NODES];
    let lin = Omnimagnet::PAPER
        .linearize(&op, AMBIENT_C, SAMPLE_S)
        .unwrap();
    let solenoid = |m: usize| Omnimagnet::PAPER.geometry().solenoids[m];
    let sensors = [true, true, false, false, true, true];
    assert!(THERMOCOUPLE_NODES[..2]
        .iter()
        .all(|n| *n == solenoid(0).node));
    let virtual_sensor =
        |m: usize| ResistanceSensor::new(solenoid(m).resistance(), 0.01, 1e-3, 0.5).unwrap();
    // With thermocouples on solenoid 1 only, the other two biases are
    // random walks no sensor observes individually: their covariance grows
    // without bound, there is no steady-state gain, and the build says so.
    let mut steady = ObserverSettings::with_sensors([true, true, false, false, false, false]);
    steady.mode = GainMode::SteadyState;
    steady.warmup_corrections = 0;
    assert_eq!(
        OmnimagnetObserver::<f64>::new(&Omnimagnet::PAPER, &lin, &steady, &op, AMBIENT_C).err(),
        Some(crate::error::BuildError::NotConverged {
            name: "steady_state_gain"
        })
    );
    // Nor with thermocouples on solenoids 1 and 3: one combination of the
    // three biases is invisible to two nodes at steady state. (With Eq. 1's
    // radiation the doubling stalled on a covariance of 3e7 W^2 and passed
    // its residual check: a gain built on an unobservable mode.)
    let mut two = ObserverSettings::with_sensors(sensors);
    two.mode = GainMode::SteadyState;
    assert_eq!(
        OmnimagnetObserver::<f64>::new(&Omnimagnet::PAPER, &lin, &two, &op, AMBIENT_C).err(),
        Some(crate::error::BuildError::NotConverged {
            name: "steady_state_gain"
        })
    );
    // A steady-state observer (all six thermocouples) moves to the
    // time-varying filter for good at its first resistance reading.
    let mut six = ObserverSettings::DEFAULT;
    six.mode = GainMode::SteadyState;
    six.warmup_corrections = 0;
    let mut obs =
        OmnimagnetObserver::<f64>::new(&Omnimagnet::PAPER, &lin, &six, &op, AMBIENT_C).unwrap();
    assert_eq!(obs.mode(), GainMode::SteadyState);
    let r_ohm = solenoid(1).resistance().at_c(op[solenoid(1).node]);
    let reading = virtual_sensor(1)
        .read((r_ohm * CURRENT_A) as f32, CURRENT_A as f32)
        .unwrap();
    assert!(obs.correct_winding(1, &reading).is_fused());
    assert_eq!(obs.mode(), GainMode::TimeVarying);
    assert!(obs.state().virtual_readings);
    for mode in [GainMode::TimeVarying, GainMode::SteadyState] {
        // Built for all six; solenoid 2's two are silent at run time.
        let mut settings = ObserverSettings::DEFAULT;
        settings.mode = mode;
        settings.warmup_corrections = 0;
        let build = || {
            OmnimagnetObserver::<f64>::new(&Omnimagnet::PAPER, &lin, &settings, &op, AMBIENT_C)
                .unwrap()
        };
        let (mut plain, mut fused) = (build(), build());
        let config = plain.config().clone();
        let k = config.kalman();
        let (f, g) = (*k.f(), *k.g());
        let origin = *config.origin_c();
        // Truth: the filter's own linear model with the unknown heat.
        let mut truth = plain.state().filter.x;
        truth[NODES + 1] = BIAS_W;
        let mut rng = Rng::new(5);
        let currents = [CURRENT_A; SOLENOIDS];
        let mut u = SVector::<f64, INPUTS>::zeros();
        let steps = 7200; // 1 h at 0.5 s
        let (mut plain_err, mut fused_err, mut n) = (0.0, 0.0, 0);
        let mut verdicts = [0usize; 2];
        for step in 0..steps {
            config.joule_input(config.model(), &truth, &currents, AMBIENT_C, &mut u);
            truth = f * truth + g * u;
            let tc: [Option<f64>; THERMOCOUPLES] = core::array::from_fn(|j| {
                let node = THERMOCOUPLE_NODES[j];
                let reading = origin[node] + truth[node] + 0.1 * rng.gauss();
                sensors[j].then_some(reading)
            });
            for obs in [&mut plain, &mut fused] {
                obs.predict(&currents.map(|c| c), AMBIENT_C);
                obs.correct(&tc);
            }
            for m in 1..SOLENOIDS {
                let node = solenoid(m).node;
                let true_c = origin[node] + truth[node];
                let r_ohm = solenoid(m).resistance().at_c(true_c);
                let volts = r_ohm * CURRENT_A + 0.01 * rng.gauss();
                let amps = CURRENT_A + 1e-3 * rng.gauss();
                let reading = virtual_sensor(m).read(volts as f32, amps as f32).unwrap();
                let v = fused.correct_winding(m, &reading);
                verdicts[usize::from(v.is_fused())] += 1;
            }
            if step >= steps * 2 / 3 {
                let node = solenoid(1).node;
                plain_err += (plain.state().filter.x[node] - truth[node]).powi(2);
                fused_err += (fused.state().filter.x[node] - truth[node]).powi(2);
                n += 1;
            }
        }
        let plain_rms = (plain_err / n as f64).sqrt();
        let fused_rms = (fused_err / n as f64).sqrt();
        let bias = fused.heat_bias_w()[1];
        let plain_bias = plain.heat_bias_w()[1];
        println!(
            "{mode:?}: solenoid 2 RMS {plain_rms:.3} K without, {fused_rms:.3} K with its resistance; bias {plain_bias:.2} W without, {bias:.2} W with (true {BIAS_W}); {} of {} readings fused",
            verdicts[1],
            verdicts[0] + verdicts[1]
        );
        assert_eq!(plain.mode(), mode);
        assert_eq!(fused.mode(), GainMode::TimeVarying);
        assert!(fused.state().virtual_readings);
        assert!(plain_rms > 0.2, "{mode:?}: the premise: {plain_rms} K");
        assert!(fused_rms < plain_rms / 5.0, "{mode:?}: {fused_rms} K");
        assert!((bias - BIAS_W).abs() < 0.3, "{mode:?}: bias {bias} W");
        assert!(verdicts[0] * 100 < verdicts[1], "{mode:?}: {verdicts:?}");
        // A resistance that reads 15 K hot is not the winding's: rejected.
        let node = solenoid(1).node;
        let hot_c = origin[node] + truth[node] + 15.0;
        let r_ohm = solenoid(1).resistance().at_c(hot_c);
        let reading = virtual_sensor(1)
            .read((r_ohm * CURRENT_A) as f32, CURRENT_A as f32)
            .unwrap();
        let before = fused.state().filter.x;
        assert!(fused.correct_winding(1, &reading).is_rejected());
        assert_eq!(fused.state().filter.x, before);
        assert_eq!(
            fused.correct_winding(SOLENOIDS, &reading),
            SensorVerdict::Missing
        );
    }
}
