//! Tests of the predictor and the safe-current bounds against independent
//! answers: the analytic single node, `f64` RK4 on the nonlinear right-hand
//! side, and brute-force searches.

use super::*;
use crate::network::Resistance;
use crate::protect::alarm::{AlarmBuilder, AlarmState};
use crate::protect::derating::DeratingRule;
use crate::protect::events::EventQueue;
use crate::protect::safe_current::Horizon;
use proptest::prelude::*;

/// One classical RK4 step of the nonlinear network (with `R(T)`).
fn rk4<const N: usize, const B: usize, const M: usize>(
    network: &Network<N, B, M>,
    t: &mut [f64; N],
    currents: &[f64; M],
    boundary: &[f64; B],
    dt: f64,
) {
    let f = |x: &[f64; N]| network.derivative_k_per_s(x, currents, boundary);
    let add = |x: &[f64; N], k: &[f64; N], h: f64| {
        let mut y = *x;
        for i in 0..N {
            y[i] += h * k[i];
        }
        y
    };
    let k1 = f(t);
    let k2 = f(&add(t, &k1, dt / 2.0));
    let k3 = f(&add(t, &k2, dt / 2.0));
    let k4 = f(&add(t, &k3, dt));
    for i in 0..N {
        t[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
}

/// Each element's first crossing of its limit in an RK4 run (interpolated
/// inside the step), or `None` within `t_end`.
fn rk4_crossings<const N: usize, const B: usize, const M: usize>(
    network: &Network<N, B, M>,
    start: [f64; N],
    currents: &[f64; M],
    boundary: &[f64; B],
    limits: &[f64; N],
    dt: f64,
    t_end: f64,
) -> [Option<f64>; N] {
    let mut t = start;
    let mut crossings = [None; N];
    for e in 0..N {
        if t[e] >= limits[e] {
            crossings[e] = Some(0.0);
        }
    }
    let steps = (t_end / dt).ceil() as usize;
    for step in 0..steps {
        let before = t;
        rk4(network, &mut t, currents, boundary, dt);
        for e in 0..N {
            if crossings[e].is_none() && t[e] >= limits[e] {
                let fraction = (limits[e] - before[e]) / (t[e] - before[e]);
                crossings[e] = Some((step as f64 + fraction) * dt);
            }
        }
        if crossings.iter().all(Option::is_some) {
            break;
        }
    }
    crossings
}

fn single_node(r: Resistance) -> Network<1, 1, 1> {
    Network::new([68.7])
        .unwrap()
        .connect_boundary(0, 0, 0.5)
        .unwrap()
        .joule_source(0, 0, r)
        .unwrap()
}

fn op<T: RealField + Copy, const N: usize, const B: usize, const M: usize>(
    temps: [f64; N],
    currents: [f64; M],
    boundary: [f64; B],
    limits: [f64; N],
) -> Operating<T, N, B, M> {
    let t = |x: f64| T::from_subset(&x);
    Operating {
        temps_c: temps.map(t),
        currents_a: currents.map(t),
        boundary_c: boundary.map(t),
        limits_c: limits.map(t),
    }
}

#[test]
fn single_rc_node_matches_the_analytic_time() {
    // t = -tau ln(1 - (T_lim - T_0) / (T_ss - T_0)), tau = C / G.
    let network = single_node(Resistance::constant(6.0));
    let p64 = PredictorBuilder::new()
        .build::<f64, 1, 1, 1, 48>(&network)
        .unwrap();
    let p32 = PredictorBuilder::new()
        .build::<f32, 1, 1, 1, 48>(&network)
        .unwrap();
    let tau = 68.7 / 0.5;
    let mut worst = 0.0f64;
    for (t0, current, limit) in [
        (20.0, 1.5, 40.0),
        (20.0, 1.5, 46.9),
        (30.0, 5.0, 65.0),
        (20.0, 20.0, 21.0),
        (45.0, 2.0, 60.0),
        (20.0, 3.0, 120.0),
    ] {
        let steady = 20.0 + 6.0 * current * current / 0.5;
        let exact = -tau * libm::log(1.0 - (limit - t0) / (steady - t0));
        let mut out = [None];
        p64.predict(&op([t0], [current], [20.0], [limit]), &mut out);
        let got = out[0].unwrap();
        assert!(
            got <= exact,
            "{t0} {current} {limit}: {got} later than {exact}"
        );
        let early = (exact - got) / exact;
        worst = worst.max(early);
        // The bound is second order in the bracket width (ratio 1.226); it is
        // loosest where the approach is flattest (0.1 K below steady state).
        assert!(early < 0.03, "{t0} {current} {limit}: {got} vs {exact}");
        let mut out32 = [None];
        p32.predict(&op([t0], [current], [20.0], [limit]), &mut out32);
        let got32 = out32[0].unwrap() as f64;
        // f32 rounds the steady state (4820 degC at 20 A) to 5e-4 K.
        assert!(
            got32 <= exact * (1.0 + 1e-4) + 1e-4,
            "f32 {got32} vs {exact}"
        );
        assert!(
            (got32 - got).abs() < 1e-4 * exact + 1e-3,
            "f32 {got32} vs f64 {got}"
        );
    }
    std::println!("single node: worst earliness {:.3} %", 100.0 * worst);
    let mut out = [None];
    // Steady state below the limit: never.
    p64.predict(&op([20.0], [1.5], [20.0], [47.5]), &mut out);
    assert_eq!(out, [None]);
    // Already past it.
    p64.predict(&op([50.0], [0.0], [20.0], [47.5]), &mut out);
    assert_eq!(out, [Some(0.0)]);
    // Invalid input: unknown, never "never".
    p64.predict(&op([f64::NAN], [1.0], [20.0], [47.5]), &mut out);
    assert!(out[0].unwrap().is_nan());
}

#[test]
fn temperature_rise_of_r_is_covered() {
    // With R(T) the truth heats faster than at R(T_0); evaluating R at the
    // limit keeps the prediction early, and the gap is what that costs.
    let network = single_node(Resistance::HPPA_COIL);
    let predictor = PredictorBuilder::new()
        .build::<f64, 1, 1, 1, 48>(&network)
        .unwrap();
    for (current, limit) in [(2.0, 60.0), (2.5, 90.0), (4.0, 150.0)] {
        let mut out = [None];
        predictor.predict(&op([20.0], [current], [20.0], [limit]), &mut out);
        let truth = rk4_crossings(
            &network,
            [20.0],
            &[current],
            &[20.0],
            &[limit],
            1e-3,
            5000.0,
        )[0]
        .unwrap();
        let got = out[0].unwrap();
        assert!(got <= truth, "{current} A: {got} vs {truth}");
        assert!(got > 0.5 * truth, "{current} A: {got} vs {truth}");
    }
}

/// A random connected network of three nodes with two windings.
#[derive(Debug, Clone)]
struct Case {
    capacity: [f64; 3],
    pair: [f64; 3],
    to_boundary: [f64; 3],
    slopes: [f64; 2],
    nodes: [usize; 2],
    currents: [f64; 2],
    start: [f64; 3],
    limits: [f64; 3],
}

fn case() -> impl Strategy<Value = Case> {
    (
        prop::array::uniform3(5.0f64..100.0),
        prop::array::uniform3(0.1f64..2.0),
        prop::array::uniform3(0.0f64..1.0),
        prop::array::uniform2(0.0f64..0.03),
        prop::array::uniform2(0usize..3),
        prop::array::uniform2(0.0f64..3.0),
        prop::array::uniform3(20.0f64..60.0),
        prop::array::uniform3(5.0f64..80.0),
    )
        .prop_map(
            |(capacity, pair, mut to_boundary, slopes, nodes, currents, start, margin)| {
                to_boundary[2] += 0.2;
                let limits = core::array::from_fn(|i| start[i] + margin[i]);
                Case {
                    capacity,
                    pair,
                    to_boundary,
                    slopes,
                    nodes,
                    currents,
                    start,
                    limits,
                }
            },
        )
}

fn build(case: &Case) -> Network<3, 1, 2> {
    let mut n = Network::new(case.capacity)
        .unwrap()
        .connect(0, 1, case.pair[0])
        .unwrap()
        .connect(1, 2, case.pair[1])
        .unwrap()
        .connect(0, 2, case.pair[2] * 0.3)
        .unwrap();
    for i in 0..3 {
        n = n.connect_boundary(i, 0, case.to_boundary[i]).unwrap();
    }
    for m in 0..2 {
        let r = Resistance::linear_fit(case.slopes[m], 4.0);
        n = n.joule_source(m, case.nodes[m], r).unwrap();
    }
    n
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Never later than an f64 RK4 integration of the nonlinear model.
    #[test]
    fn prediction_is_never_later_than_rk4(case in case()) {
        let network = build(&case);
        let t_end = 3000.0;
        let p64 = PredictorBuilder::new().grid_s(0.5, t_end).build::<f64, 3, 1, 2, 48>(&network).unwrap();
        let p32 = PredictorBuilder::new().grid_s(0.5, t_end).build::<f32, 3, 1, 2, 48>(&network).unwrap();
        let op64 = op::<f64, 3, 1, 2>(case.start, case.currents, [20.0], case.limits);
        let mut got = [None; 3];
        p64.predict(&op64, &mut got);
        let mut got32 = [None; 3];
        p32.predict(&op(case.start, case.currents, [20.0], case.limits), &mut got32);
        let truth = rk4_crossings(&network, case.start, &case.currents, &[20.0], &case.limits, 0.01, t_end);
        // Each element's guarantee holds up to the first winding crossing.
        let winding_first = case
            .nodes
            .iter()
            .filter_map(|&n| truth[n])
            .fold(f64::INFINITY, f64::min);
        for e in 0..3 {
            let Some(true_t) = truth[e] else { continue };
            if true_t > winding_first {
                continue;
            }
            // RK4's interpolated crossing is good to ~1e-6 s here.
            let slack = 1e-6 * true_t + 1e-5;
            let p = got[e];
            prop_assert!(p.is_some_and(|p| p <= true_t + slack), "element {e}: {p:?} vs {true_t}");
            let p = got32[e].map(f64::from);
            prop_assert!(p.is_some_and(|p| p <= true_t * (1.0 + 1e-4) + 1e-3), "f32 element {e}: {p:?} vs {true_t}");
        }
        let first_true = truth.iter().flatten().fold(f64::INFINITY, |a, &b| a.min(b));
        let first_pred = got.iter().flatten().fold(f64::INFINITY, |a, &b| a.min(b));
        prop_assert!(first_pred <= first_true + 1e-5);
    }
}

fn four_node() -> Network<4, 1, 1> {
    // A coil (0) in a bobbin (1) on a plate (2) cooled to the ambient, and
    // a small sensor lug (3) on the coil.
    Network::new([68.7, 20.0, 400.0, 2.0])
        .unwrap()
        .connect(0, 1, 0.8)
        .unwrap()
        .connect(1, 2, 0.5)
        .unwrap()
        .connect(0, 3, 0.3)
        .unwrap()
        .connect_boundary(2, 0, 1.5)
        .unwrap()
        .connect_boundary(3, 0, 0.02)
        .unwrap()
        .joule_source(0, 0, Resistance::HPPA_COIL)
        .unwrap()
}

#[test]
fn sliced_answers_are_the_full_answers_aged() {
    let network = four_node();
    let predictor = PredictorBuilder::new()
        .build::<f32, 4, 1, 1, 48>(&network)
        .unwrap();
    let op = op::<f32, 4, 1, 1>([35.0, 30.0, 25.0, 33.0], [1.6], [20.0], [65.36; 4]);
    let mut full = [None; 4];
    predictor.predict(&op, &mut full);
    let mut state = PredictorState::new(&predictor, &op);
    assert_eq!(state.time_to_limit_s(), &full);
    // The same state keeping no answers makes the same ones when asked.
    let mut asked = PredictorState::when_asked(&predictor, &op);
    let bits = |a: Option<f32>| a.map(f32::to_bits);
    assert_eq!(asked.time_to_limit_s(), full);
    assert_eq!(asked.time_to_limit_of(4), None);
    let tick = predictor.tick_s();
    for k in 1..=500 {
        let out = *state.tick(&predictor, &op);
        asked.tick(&predictor, &op);
        assert_eq!(asked.time_to_limit_s().map(bits), out.map(bits));
        for e in 0..4 {
            assert_eq!(bits(asked.time_to_limit_of(e)), bits(out[e]));
            let (Some(f), Some(o)) = (full[e], out[e]) else {
                assert_eq!(full[e], out[e]);
                continue;
            };
            // Held inputs: the aged answer is the full one minus the time
            // since the snapshot, which is at most two sweeps (98 ticks) old.
            assert!(
                o <= f + 1e-4 && o >= f - 98.0 * tick - 1e-3,
                "tick {k}, element {e}: {o} vs {f}"
            );
        }
    }
}

/// With more windings than a stage's budget (`elements_per_tick * N / M`
/// rows: one element, four nodes and two windings make two rows a stage),
/// the windings' part of the steady state takes stages of its own, all at
/// the peak powers of the sweep's start: a current that rises during them
/// counts in the next sweep, not in half of this one's rows. The snapshot
/// is the one of the start's powers to the bit.
#[test]
fn a_split_sweeps_windings_rows_take_the_powers_of_its_start() {
    let network = Network::<4, 1, 2>::new([40.0, 55.0, 300.0, 9.0])
        .and_then(|n| n.joule_source(0, 0, Resistance::HPPA_COIL))
        .and_then(|n| n.joule_source(1, 1, Resistance::HPPA_COIL))
        .and_then(|n| n.connect(0, 2, 0.6))
        .and_then(|n| n.connect(1, 2, 0.9))
        .and_then(|n| n.connect(2, 3, 0.2))
        .and_then(|n| n.connect_boundary(2, 0, 1.5))
        .unwrap();
    let split = PredictorBuilder::new()
        .elements_per_tick(1)
        .build::<f32, 4, 1, 2, 48>(&network)
        .unwrap();
    let limits = [90.0; 4];
    let start = op::<f32, 4, 1, 2>([35.0, 30.0, 25.0, 24.0], [1.6, 0.8], [20.0], limits);
    let rising = op::<f32, 4, 1, 2>([35.0, 30.0, 25.0, 24.0], [3.0, 2.5], [20.0], limits);
    let mut state = PredictorState::new(&split, &start);
    // The first stage freezes the start's peak and forms two rows; the
    // second, under a higher current, the other two at the same powers.
    state.tick(&split, &start);
    assert_eq!((state.phase, state.next_element), (SweepPhase::Windings, 2));
    state.tick(&split, &rising);
    assert_eq!((state.phase, state.next_element), (SweepPhase::Powers, 0));
    state.tick(&split, &start);
    while state.phase != SweepPhase::Sweeping {
        state.tick(&split, &start);
    }
    let powers = split.conservative_powers_w(&start);
    assert_eq!(state.snapshot, split.snapshot(&start, &powers));
    // The rise is the next sweep's peak.
    assert_eq!(state.peak_power_w, split.conservative_powers_w(&rising));
}

#[test]
fn a_sweep_split_by_elements_gives_the_same_answers_in_more_ticks() {
    // The same sweep with at most 1, 2 or 3 element evaluations per tick
    // (and the snapshot in three ticks of its own): every sweep it completes
    // publishes the whole sweep's answers to the bit, in more ticks than
    // one horizon per tick takes.
    let network = four_node();
    let op = op::<f32, 4, 1, 1>([35.0, 30.0, 25.0, 33.0], [1.6], [20.0], [65.36; 4]);
    let whole = PredictorBuilder::new()
        .build::<f32, 4, 1, 1, 48>(&network)
        .unwrap();
    let powers = whole.conservative_powers_w(&op);
    let expected = whole.full_sweep(&op, &powers);
    let ticks_per_sweep = |predictor: &LimitPredictor<f32, 4, 1, 1, 48>| {
        let mut state = PredictorState::new(predictor, &op);
        let (mut sweeps, mut ticks, mut first_sweep_ticks) = (0, 0, 0);
        while sweeps < 3 {
            state.tick(predictor, &op);
            ticks += 1;
            if state.phase == SweepPhase::Idle {
                assert_eq!(state.published, expected, "sweep {sweeps}");
                sweeps += 1;
                if first_sweep_ticks == 0 {
                    first_sweep_ticks = ticks;
                }
            }
            assert!(ticks < 10_000, "a sweep must end");
        }
        first_sweep_ticks
    };
    let one_point = ticks_per_sweep(&whole);
    let mut last = one_point;
    for elements in [3, 2, 1] {
        let split = PredictorBuilder::new()
            .elements_per_tick(elements)
            .build::<f32, 4, 1, 1, 48>(&network)
            .unwrap();
        // The snapshot is stages of their own, the windings' part of the
        // steady state, its boundaries' part with the headroom and
        // `T_0 - T_ss`, then the modal amplitudes `elements` at a time,
        // and is the whole snapshot to the bit.
        let mut state = PredictorState::new(&split, &op);
        state.tick(&split, &op);
        assert_eq!(state.phase, SweepPhase::Powers);
        state.tick(&split, &op);
        for stage in 0..4usize.div_ceil(elements) {
            assert_eq!(state.phase, SweepPhase::Steady, "amplitudes' stage {stage}");
            state.tick(&split, &op);
        }
        assert_eq!(state.phase, SweepPhase::Sweeping);
        assert_eq!((state.next_point, state.next_element), (0, 0));
        assert_eq!(state.snapshot, split.snapshot(&op, &powers));
        let ticks = ticks_per_sweep(&split);
        assert!(
            ticks > last,
            "{elements} per tick: {ticks} ticks, {last} before"
        );
        last = ticks;
    }
    assert!(PredictorBuilder::new()
        .elements_per_tick(0)
        .build::<f32, 4, 1, 1, 48>(&network)
        .is_err());
}

#[test]
fn an_element_in_two_stages_gives_the_same_answers_in_twice_the_stages() {
    // One element a stage, each element's horizon in two stages (its
    // parts, then its crossing): every sweep publishes the whole sweep's
    // answers to the bit, as the one-stage elements do, and its horizons
    // take twice the stages. A lug without a limit (`+inf`) is resolved
    // without a stage; a sweep that starts over (a fresh state) drops parts
    // formed for another.
    let network = four_node();
    let mut op = op::<f32, 4, 1, 1>([35.0, 30.0, 25.0, 33.0], [1.6], [20.0], [65.36; 4]);
    op.limits_c[3] = f32::INFINITY;
    let split = PredictorBuilder::new()
        .elements_per_tick(1)
        .build::<f32, 4, 1, 1, 48>(&network)
        .unwrap();
    let powers = split.conservative_powers_w(&op);
    let expected = split.full_sweep(&op, &powers);
    assert!(
        expected[..3]
            .iter()
            .any(|c| matches!(c, Crossing::At(t) if *t > 0.0)),
        "{expected:?}"
    );
    assert_eq!(expected[3], Crossing::Never);
    let mut whole = PredictorState::new(&split, &op);
    let mut halved = PredictorState::new(&split, &op);
    let mut half = HalfElement::new();
    let (mut whole_ticks, mut halved_ticks) = (Vec::new(), Vec::new());
    for tick in 0..2_000 {
        whole.tick(&split, &op);
        halved.tick_in_halves(&split, &op, &mut half);
        for (state, ends) in [(&whole, &mut whole_ticks), (&halved, &mut halved_ticks)] {
            if state.phase == SweepPhase::Idle {
                assert_eq!(state.published, expected, "tick {tick}");
                ends.push(tick);
            }
        }
    }
    assert!(whole_ticks.len() >= 3 && halved_ticks.len() >= 2);
    let period = |ends: &[usize]| ends[1] - ends[0];
    let (snapshot_stages, horizon_stages) = (2 + 4, period(&whole_ticks) - 6);
    assert_eq!(
        period(&halved_ticks),
        snapshot_stages + 2 * horizon_stages,
        "{whole_ticks:?} {halved_ticks:?}"
    );
    // Parts formed for another sweep are not taken.
    let mut fresh = PredictorState::new(&split, &op);
    let mut stale = HalfElement {
        formed: Some(Parts {
            p: 1e6,
            q: 0.0,
            dq: 0.0,
        }),
    };
    for _ in 0..period(&halved_ticks) {
        fresh.tick_in_halves(&split, &op, &mut stale);
        if fresh.phase == SweepPhase::Idle {
            assert_eq!(fresh.published, expected);
        }
    }
}

#[test]
fn an_element_without_a_limit_is_never_and_leaves_the_others_alone() {
    // The lug (3) without a limit (`+inf`) against the lug at a limit it
    // cannot reach (1000 degC): the same answers for the others, `None`
    // for the lug, in the full sweep and in the slices. A NaN or `-inf`
    // limit is still an invalid input ("unknown" for every element).
    let network = four_node();
    let predictor = PredictorBuilder::new()
        .build::<f32, 4, 1, 1, 48>(&network)
        .unwrap();
    let limits = [65.36, 65.36, 65.36, 1000.0];
    let finite = op::<f32, 4, 1, 1>([35.0, 30.0, 25.0, 33.0], [1.6], [20.0], limits);
    let mut unbounded = finite;
    unbounded.limits_c[3] = f32::INFINITY;
    let (mut a, mut b) = ([None; 4], [None; 4]);
    predictor.predict(&finite, &mut a);
    predictor.predict(&unbounded, &mut b);
    assert!(a[0].is_some_and(|t| t.is_finite() && t > 0.0), "{a:?}");
    assert_eq!(a[..3], b[..3]);
    assert_eq!(b[3], None);
    // Sliced, a sweep may end sooner (the lug no longer holds it open), so
    // the answers are the full ones aged by less: never later than them.
    let mut sliced = PredictorState::new(&predictor, &unbounded);
    for _ in 0..200 {
        let out = *sliced.tick(&predictor, &unbounded);
        for e in 0..3 {
            let (Some(o), Some(f)) = (out[e], a[e]) else {
                assert_eq!(out[e], a[e]);
                continue;
            };
            assert!(o <= f + 1e-4, "element {e}: {o} vs {f}");
        }
        assert_eq!(out[3], None);
    }
    for bad in [f32::NAN, f32::NEG_INFINITY] {
        let mut invalid = finite;
        invalid.limits_c[3] = bad;
        let mut out = [None; 4];
        predictor.predict(&invalid, &mut out);
        assert!(out.iter().all(|t| t.is_some_and(f32::is_nan)), "{out:?}");
    }
}

/// Replays a current trace at 1 ms on an RK4 truth, with the sliced f32
/// predictor and the alarm on the truth's temperatures; returns (tick the
/// predictive alarm rose, tick the truth crossed its alarm limit).
fn replay(trace: impl Fn(f64) -> f64, horizon_s: f64, debounce: u16) -> (usize, usize) {
    let network = four_node();
    let predictor = PredictorBuilder::new()
        .build::<f32, 4, 1, 1, 48>(&network)
        .unwrap();
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [100.0; 4])
        .horizon_s(horizon_s)
        .debounce_ticks(debounce)
        .build::<f32>()
        .unwrap();
    let limits = alarm.alarm_limits_c(20.0);
    let mut alarm_state = AlarmState::new(&alarm);
    let mut events = EventQueue::<16>::new();
    let mut t = [20.0f64; 4];
    let op_at = |t: &[f64; 4], current: f64| Operating {
        temps_c: t.map(|x| x as f32),
        currents_a: [current as f32],
        boundary_c: [20.0f32],
        limits_c: limits,
    };
    let mut state = PredictorState::new(&predictor, &op_at(&t, trace(0.0)));
    let mut raised = None;
    for tick in 1..3_000_000 {
        let time = tick as f64 * 1e-3;
        let current = trace(time);
        rk4(&network, &mut t, &[current], &[20.0], 1e-3);
        let op = op_at(&t, current);
        let ttl = *state.tick(&predictor, &op);
        let status = alarm_state.tick(&alarm, &op.temps_c, 20.0, &ttl, &mut events);
        if status.predictive && raised.is_none() {
            raised = Some(tick);
        }
        if t.iter().zip(&limits).any(|(t, l)| *t >= *l as f64) {
            return (raised.expect("crossed without a predictive alarm"), tick);
        }
    }
    panic!("the trace never crossed the limit");
}

#[test]
fn predictive_alarm_fires_a_horizon_ahead_on_replayed_traces() {
    let horizon = 30.0;
    type Trace = fn(f64) -> f64;
    let traces: [(&str, Trace); 3] = [
        ("constant", |_| 1.6),
        ("step", |t| if t < 100.0 { 1.0 } else { 1.8 }),
        // Commutation-like: 2.4 A peak at 20 Hz, rectified sine.
        ("ripple", |t| {
            2.4 * libm::sin(2.0 * core::f64::consts::PI * 20.0 * t).abs()
        }),
    ];
    for (name, trace) in traces {
        let (raised, crossed) = replay(trace, horizon, 1);
        let lead_s = (crossed - raised) as f64 * 1e-3;
        std::println!(
            "{name}: predictive alarm {lead_s:.1} s before the limit (horizon {horizon} s)"
        );
        assert!(lead_s >= horizon - 1e-3, "{name}: lead {lead_s} s");
    }
    // The constant trace also shows how early: R at the limit costs some
    // lead, but the alarm is not absurdly early.
    let (raised, crossed) = replay(|_| 1.6, horizon, 1);
    assert!(((crossed - raised) as f64) * 1e-3 < 3.0 * horizon);
}

#[test]
fn common_scale_of_two_coupled_nodes_matches_brute_force() {
    // Coil 0 (winding 0) and coil 1 (winding 1), coupled, node 1 cooled;
    // coil 0 starts hot, so its free response falls while coil 1's rises.
    for slope in [0.0, 0.026] {
        let network: Network<2, 1, 2> = Network::new([50.0, 200.0])
            .unwrap()
            .connect(0, 1, 0.5)
            .unwrap()
            .connect_boundary(1, 0, 1.0)
            .unwrap()
            .connect_boundary(0, 0, 0.05)
            .unwrap()
            .joule_source(0, 0, Resistance::linear_fit(slope, 5.166))
            .unwrap()
            .joule_source(1, 1, Resistance::linear_fit(slope, 3.0))
            .unwrap();
        let predictor = PredictorBuilder::new()
            .build::<f64, 2, 1, 2, 48>(&network)
            .unwrap();
        let start = [45.0, 30.0];
        let currents = [1.5, 1.0];
        let limits = [80.0, 60.0];
        let horizon = 120.0;
        let op = op::<f64, 2, 1, 2>(start, currents, [20.0], limits);
        let scale = predictor
            .max_common_scale(&op, Horizon::Seconds(horizon), 1.0)
            .value;
        // Brute force: the largest scale on a grid whose fine-step nonlinear
        // run stays below both limits over the horizon.
        let safe = |k: f64| {
            let mut t = start;
            for _ in 0..(horizon / 0.01) as usize {
                rk4(
                    &network,
                    &mut t,
                    &[k * currents[0], k * currents[1]],
                    &[20.0],
                    0.01,
                );
                if t[0] > limits[0] || t[1] > limits[1] {
                    return false;
                }
            }
            true
        };
        let coarse = (0..400)
            .map(|i| i as f64 * 0.01)
            .take_while(|&k| safe(k))
            .last()
            .unwrap();
        let brute = (0..100)
            .map(|i| coarse + i as f64 * 1e-4)
            .take_while(|&k| safe(k))
            .last()
            .unwrap();
        std::println!("slope {slope}: scale {scale:.4}, brute force {brute:.4}");
        assert!(scale <= brute + 1e-4, "{scale} vs {brute}");
        let tolerance = if slope == 0.0 { 0.015 } else { 0.12 };
        assert!(scale >= brute * (1.0 - tolerance), "{scale} vs {brute}");

        // Per coil: coil 0's current with coil 1 at 1 A.
        let coil = predictor
            .max_coil_current_a(0, &op, Horizon::Seconds(horizon), 1.0)
            .value;
        let safe_coil = |i: f64| {
            let mut t = start;
            for _ in 0..(horizon / 0.01) as usize {
                rk4(&network, &mut t, &[i, currents[1]], &[20.0], 0.01);
                if t[0] > limits[0] || t[1] > limits[1] {
                    return false;
                }
            }
            true
        };
        let coarse = (0..1000)
            .map(|i| i as f64 * 0.01)
            .take_while(|&i| safe_coil(i))
            .last()
            .unwrap();
        let brute = (0..100)
            .map(|i| coarse + i as f64 * 1e-4)
            .take_while(|&i| safe_coil(i))
            .last()
            .unwrap();
        std::println!("slope {slope}: coil 0 {coil:.4} A, brute force {brute:.4} A");
        assert!(
            coil <= brute + 1e-4 && coil >= brute * (1.0 - tolerance),
            "{coil} vs {brute}"
        );
    }
}

#[test]
fn forever_scale_puts_the_steady_hot_spot_on_its_limit() {
    let network = four_node();
    let constant = Network::<1, 1, 1>::new([68.7])
        .unwrap()
        .connect_boundary(0, 0, 0.5)
        .unwrap()
        .joule_source(0, 0, Resistance::constant(6.0))
        .unwrap();
    // Constant R from equilibrium: exact, the steady state on the limit.
    let p1 = PredictorBuilder::new()
        .build::<f64, 1, 1, 1, 48>(&constant)
        .unwrap();
    let s = p1.max_common_scale(&op([20.0], [1.0], [20.0], [50.0]), Horizon::Forever, 1.0);
    assert!(
        (s.value - libm::sqrt(30.0 * 0.5 / 6.0)).abs() < 1e-9,
        "{s:?}"
    );
    assert_eq!(s.binding_element, Some(0));
    // Half duty doubles the power allowed.
    let half = p1.max_common_scale(&op([20.0], [1.0], [20.0], [50.0]), Horizon::Forever, 0.5);
    assert!((half.value / s.value - libm::sqrt(2.0)).abs() < 1e-9);
    // R(T): at the returned scale the true steady state is at most the limit,
    // and it is what R at the limit costs.
    let predictor = PredictorBuilder::new()
        .build::<f64, 4, 1, 1, 48>(&network)
        .unwrap();
    let limits = [65.36; 4];
    let op4 = op::<f64, 4, 1, 1>([20.0; 4], [1.0], [20.0], limits);
    let s = predictor.max_common_scale(&op4, Horizon::Forever, 1.0);
    let steady = network.steady_state(&[s.value], &[20.0]).unwrap();
    let peak = steady.iter().fold(f64::MIN, |a, &b| a.max(b));
    assert!(peak <= 65.36 && peak > 62.0, "{peak}");
    // A long horizon approaches the forever answer from above.
    let long = predictor.max_common_scale(&op4, Horizon::Seconds(1e5), 1.0);
    assert!(long.value >= s.value && long.value < 1.001 * s.value);
    // Too hot already: infeasible; bad inputs: zero.
    let hot = op::<f64, 4, 1, 1>([70.0; 4], [1.0], [20.0], limits);
    let r = predictor.max_common_scale(&hot, Horizon::Seconds(10.0), 1.0);
    assert!(!r.feasible && r.value == 0.0);
    let r = predictor.max_common_scale(&op4, Horizon::Seconds(f64::NAN), 1.0);
    assert!(!r.feasible);
    let r = predictor.max_coil_current_a(3, &op4, Horizon::Forever, 1.0);
    assert!(!r.feasible);
    // No current: nothing to scale.
    let idle = op::<f64, 4, 1, 1>([20.0; 4], [0.0], [20.0], limits);
    assert!(predictor
        .max_common_scale(&idle, Horizon::Forever, 1.0)
        .value
        .is_infinite());
}

#[test]
fn builder_rejects_bad_parameters() {
    let network = four_node();
    let err = |b: PredictorBuilder| b.build::<f32, 4, 1, 1, 8>(&network).unwrap_err();
    assert_eq!(
        err(PredictorBuilder::new().grid_s(10.0, 1.0)),
        BuildError::InvalidParameter {
            name: "first_s/last_s"
        }
    );
    assert_eq!(
        err(PredictorBuilder::new().tick_s(0.0)),
        BuildError::InvalidParameter { name: "tick_s" }
    );
    assert_eq!(
        err(PredictorBuilder::new().points_per_tick(10)),
        BuildError::InvalidParameter {
            name: "points_per_tick"
        }
    );
    let isolated: Network<2, 1, 1> = Network::new([1.0, 1.0])
        .unwrap()
        .connect_boundary(0, 0, 1.0)
        .unwrap()
        .joule_source(0, 0, Resistance::constant(1.0))
        .unwrap();
    assert_eq!(
        PredictorBuilder::new()
            .build::<f32, 2, 1, 1, 8>(&isolated)
            .unwrap_err(),
        BuildError::Singular
    );
    let no_source: Network<1, 1, 1> = Network::new([1.0])
        .unwrap()
        .connect_boundary(0, 0, 1.0)
        .unwrap();
    assert!(PredictorBuilder::new()
        .build::<f32, 1, 1, 1, 8>(&no_source)
        .is_err());
}

/// A stiff motor-like network: a slot winding (0) and an end winding (1)
/// in a stator (2) in a housing (3) on a coolant (boundary 0), a rotor (4)
/// across the air gap; two copper sources and one iron loss. Its
/// eigenvectors are far from orthogonal, so `V^-1` has large entries.
fn stiff_motor() -> Network<5, 2, 3> {
    Network::new([40.0, 25.0, 3000.0, 12000.0, 1500.0])
        .and_then(|n| n.connect(0, 1, 4.0))
        .and_then(|n| n.connect(0, 2, 12.0))
        .and_then(|n| n.connect(1, 3, 0.8))
        .and_then(|n| n.connect(2, 3, 60.0))
        .and_then(|n| n.connect(2, 4, 3.0))
        .and_then(|n| n.connect_boundary(3, 0, 150.0))
        .and_then(|n| n.connect_boundary(4, 1, 0.6))
        .and_then(|n| n.joule_source(0, 0, Resistance::with_alpha(0.05, 0.00393, 20.0)))
        .and_then(|n| n.joule_source(1, 1, Resistance::with_alpha(0.03, 0.00393, 20.0)))
        .and_then(|n| n.joule_source(2, 2, Resistance::constant(0.01)))
        .unwrap()
}

#[test]
fn modal_amplitudes_hold_f64s_in_f32_on_a_stiff_network() {
    // `z = V^-1 (T_0 - T_ss)`: the f32 amplitudes against the f64
    // predictor's, at a hot operating point away from its steady state.
    // Formed as `V^-1 T_0` less the modal gains' `V^-1 T_ss` (the form
    // before, printed for the record) the two large terms cancel.
    let net = stiff_motor();
    let p64 = PredictorBuilder::new()
        .build::<f64, 5, 2, 3, 48>(&net)
        .unwrap();
    let p32 = PredictorBuilder::new()
        .build::<f32, 5, 2, 3, 48>(&net)
        .unwrap();
    let temps = [118.0, 131.0, 71.5, 48.25, 63.0];
    let powers = [412.0, 233.0, 180.0];
    let boundary = [40.0, 25.0];
    let (_, z64) = p64.steady_and_modes(&temps, &powers, &boundary, true);
    let (_, z32) = p32.steady_and_modes(
        &temps.map(|t| t as f32),
        &powers.map(|p| p as f32),
        &boundary.map(|b| b as f32),
        true,
    );
    let scale = z64.iter().fold(0.0f64, |m, z| m.max(z.abs()));
    let error = |z: &[f32; 5]| {
        z.iter()
            .zip(&z64)
            .map(|(a, b)| (f64::from(*a) - b).abs())
            .fold(0.0f64, f64::max)
            / scale
    };
    // The form before: `V^-1 T_0` less the modal gains (`V^-1` times the
    // steady gains, in `f64`, then held in `f32` as its tables were).
    let modal = |i: usize, column: &dyn Fn(usize) -> f64| -> f32 {
        (0..5).map(|j| p64.v_inv[i][j] * column(j)).sum::<f64>() as f32
    };
    let mut before = [0.0f32; 5];
    for (i, z) in before.iter_mut().enumerate() {
        let mut m = -modal(i, &|j| p64.offset_c[j]);
        for k in 0..3 {
            m -= modal(i, &|j| p64.gain_power[j][k]) * powers[k] as f32;
        }
        for k in 0..2 {
            m -= modal(i, &|j| p64.gain_boundary[j][k]) * boundary[k] as f32;
        }
        for k in 0..5 {
            m += p32.v_inv[i][k] * temps[k] as f32;
        }
        *z = m;
    }
    let v_inv_row = p64
        .v_inv
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0f64, f64::max);
    std::println!(
        "largest |V^-1| row {v_inv_row:.1}, |z| up to {scale:.2}: f32 error {:.2e} of it, {:.2e} the form before",
        error(&z32),
        error(&before)
    );
    // The form before is 6.9e-7 off here: the bound tells the two apart.
    assert!(error(&z32) < 4e-7, "{:e}", error(&z32));
}

/// Any `f32`: finite values of every size, both zeros, the infinities and
/// NaN.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -1e4f32..1e4,
        1 => proptest::num::f32::ANY,
        1 => prop::sample::select(vec![0.0, -0.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN]),
    ]
}

proptest! {
    /// The conservative resistance, `R` of the warmer temperature (the
    /// cooler for a negative slope), is the larger of the two `R`s to the
    /// bit, NaN where that is NaN, for any inputs; a constant resistance
    /// (a zero slope) is `R(0 degC)` at any temperature, an infinite one
    /// too.
    #[test]
    fn the_conservative_resistance_is_the_larger_of_the_two_to_the_bit(
        temp in any_f32(), limit in any_f32(), r0 in any_f32(), slope in any_f32(),
        edge in 0usize..4,
    ) {
        // A zero slope against an infinite temperature, half the time.
        let (temp, slope) = match edge {
            0 => (f32::INFINITY, 0.0),
            1 => (f32::NEG_INFINITY, -0.0),
            _ => (temp, slope),
        };
        let predictor = PredictorBuilder::new()
            .build::<f32, 4, 1, 1, 48>(&four_node())
            .unwrap();
        let winding = Winding { node: 0, r_at_0c_ohm: r0, slope_ohm_per_k: slope };
        let mut operating = op::<f32, 4, 1, 1>([20.0; 4], [1.0], [20.0], [100.0; 4]);
        operating.temps_c[0] = temp;
        operating.limits_c[0] = limit;
        let got = predictor.conservative_resistance_ohm(&winding, &operating);
        // The two `R`s, the larger kept (`max` drops a NaN operand).
        let at = |t: f32| if slope == 0.0 { r0 } else { r0 + slope * t };
        let r = at(temp).max(at(limit));
        let want = if r > 0.0 { r } else if r.is_finite() { 0.0 } else { f32::NAN };
        prop_assert!(
            got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
            "{got} against {want}"
        );
    }
}

proptest! {
    /// The snapshot's three forms are one: in one pass over the rows (a
    /// core with an FPU), in the two parts a split sweep takes in stages
    /// of their own, and as the steady state and `T_0 - T_ss` of
    /// `steady_and_offset`; the same bits for any inputs (a NaN where
    /// the other has one), the same validity.
    #[test]
    fn the_snapshot_is_the_same_in_one_pass_and_in_two(
        temps in prop::array::uniform4(any_f32()),
        limits in prop::array::uniform4(any_f32()),
        currents in prop::array::uniform2(any_f32()),
        boundary in prop::array::uniform2(any_f32()),
    ) {
        // Every column of the steady state in use: a fixed power, two
        // windings and two boundaries (a sum in another order rounds
        // apart).
        let network = Network::<4, 2, 2>::new([40.0, 55.0, 300.0, 9.0])
            .and_then(|n| n.joule_source(0, 0, Resistance::HPPA_COIL))
            .and_then(|n| n.joule_source(1, 1, Resistance::HPPA_COIL))
            .and_then(|n| n.fixed_power(2, 3.3))
            .and_then(|n| n.connect(0, 2, 0.6))
            .and_then(|n| n.connect(1, 2, 0.9))
            .and_then(|n| n.connect(2, 3, 0.2))
            .and_then(|n| n.connect_boundary(2, 0, 1.5))
            .and_then(|n| n.connect_boundary(3, 1, 0.07))
            .unwrap();
        let predictor = PredictorBuilder::new()
            .build::<f32, 4, 2, 2, 48>(&network)
            .unwrap();
        let operating = Operating {
            temps_c: temps,
            currents_a: currents,
            boundary_c: boundary,
            limits_c: limits,
        };
        let powers = predictor.conservative_powers_w(&operating);
        let fused = predictor.fused_snapshot(&operating, &powers);
        let mut parts = Snapshot {
            headroom_k: [f32::NAN; 4],
            modes: [f32::NAN; 4],
            valid: false,
        };
        // The windings' part in stages of rows (a split sweep's), as one
        // pass over them would form it.
        for rows in [0..1, 1..3, 3..4] {
            predictor.start_snapshot(&mut parts, &powers, rows);
        }
        predictor.finish_steady(&mut parts, &operating);
        let (steady, from_steady) =
            predictor.steady_and_offset(&temps, &powers, &boundary, true);
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        prop_assert_eq!(fused.valid, parts.valid);
        for i in 0..4 {
            prop_assert!(same(fused.headroom_k[i], parts.headroom_k[i]), "headroom {}", i);
            prop_assert!(same(fused.modes[i], parts.modes[i]), "modes {}", i);
            prop_assert!(same(fused.modes[i], from_steady[i]), "T_0 - T_ss {}", i);
            prop_assert!(same(fused.headroom_k[i], limits[i] - steady[i]), "steady {}", i);
        }
    }
}

/// A bracket `[a, a + h]` of an element whose `P` and `Q` are two decaying
/// modes each (`c e^(lambda t)`, `c > 0`): the parts at both ends.
fn bracket_parts() -> impl Strategy<Value = (f64, f64, Parts<f64>, Parts<f64>)> {
    let mode = (0.01f64..50.0, -0.5f64..-1e-4);
    (
        0.0f64..500.0,
        0.1f64..300.0,
        [mode.clone(), mode.clone()],
        [mode.clone(), mode],
    )
        .prop_map(|(a, h, p_modes, q_modes)| {
            let at = |t: f64| Parts {
                p: p_modes.iter().map(|(c, l)| c * (l * t).exp()).sum(),
                q: q_modes.iter().map(|(c, l)| c * (l * t).exp()).sum(),
                dq: q_modes.iter().map(|(c, l)| c * l * (l * t).exp()).sum(),
            };
            (a, a + h, at(a), at(a + h))
        })
}

/// The bound of the module docs at `t` in `[a, b]`, from its definition:
/// the chord of `P` minus the larger of `Q`'s tangents at `a` and `b`.
fn bound_at(a: f64, b: f64, at_a: &Parts<f64>, at_b: &Parts<f64>, t: f64) -> f64 {
    let chord = at_a.p + (at_b.p - at_a.p) * (t - a) / (b - a);
    let tangent_a = at_a.q + at_a.dq * (t - a);
    let tangent_b = at_b.q + at_b.dq * (t - b);
    chord - tangent_a.max(tangent_b)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// The closed-form first crossing is the brute-force one: the bound
    /// sampled at 20 000 points of the bracket, the first sample at or
    /// above the headroom refined by bisection (the bound is concave, so
    /// below it before, and at or above it from there to the sample). A
    /// headroom within the sampling's reach of the bound's peak is skipped
    /// (a crossing between two samples could hide there).
    #[test]
    fn the_first_crossing_is_the_brute_force_one(
        (a, b, at_a, at_b) in bracket_parts(),
        share in -0.2f64..1.2,
    ) {
        const SAMPLES: usize = 20_000;
        let bound = |t: f64| bound_at(a, b, &at_a, &at_b, t);
        let t_of = |i: usize| a + (b - a) * i as f64 / SAMPLES as f64;
        let values: std::vec::Vec<f64> = (0..=SAMPLES).map(|i| bound(t_of(i))).collect();
        let (low, high) = values.iter().fold((f64::MAX, f64::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
        let headroom = low + share * (high - low);
        // The bound's largest slope times a sample's width.
        let step = values.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
        prop_assume!((headroom - high).abs() > 2.0 * step + 1e-9 * high.abs());
        let truth = values.iter().position(|v| *v >= headroom).map(|i| {
            if i == 0 {
                return a;
            }
            let (mut below, mut above) = (t_of(i - 1), t_of(i));
            for _ in 0..100 {
                let mid = 0.5 * (below + above);
                if bound(mid) >= headroom { above = mid } else { below = mid }
            }
            above
        });
        let found = first_crossing(a, b, &at_a, &at_b, headroom);
        match (found, truth) {
            (None, None) => {}
            (Some(t), Some(truth)) => prop_assert!(
                (t - truth).abs() <= 1e-9 * (b - a) + 1e-12 * b,
                "found {t}, brute force {truth} in [{a}, {b}]"
            ),
            _ => prop_assert!(false, "found {found:?}, brute force {truth:?} in [{a}, {b}]"),
        }
    }
}

proptest! {
    /// Any parts and headroom, NaN, the infinities and extremes among
    /// them: the first crossing is `None` or a time in its bracket `[a, b]`
    /// (never NaN: a NaN share of the bracket is taken as all of it), and
    /// never panics.
    #[test]
    fn a_first_crossing_stays_in_its_bracket_for_any_input(
        (a, h) in (0.0f32..1e4, 1e-3f32..1e4),
        at_a in (any_f32(), any_f32(), any_f32()),
        at_b in (any_f32(), any_f32(), any_f32()),
        headroom in any_f32(),
    ) {
        let b = a + h;
        let parts = |(p, q, dq): (f32, f32, f32)| Parts { p, q, dq };
        if let Some(t) = first_crossing(a, b, &parts(at_a), &parts(at_b), headroom) {
            prop_assert!((a..=b).contains(&t), "{t} outside [{a}, {b}]");
        }
    }
}
