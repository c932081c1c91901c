//! A model file at its own size (issue 37, item 4): the library's
//! [`RunTimeStepper`] (the `alloc` twin of the MCU's `ExplicitStepper`) is
//! the const-generic stepper to the bit, and `simulate`, `calibrate` and an
//! open-loop `replay` run a 300-node, 72-source motor network through it
//! (no size class, no cap) against an independent integration of the same
//! equations; the exact discretisation and the Kalman filter run at
//! run-time sizes (`Dyn`), and the motor's steady gain is solved at its
//! own size; `replay` and `faults` run the firmware's observer of the
//! motor (the library's `RunTimeObserver`) at its own size.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::discretize::{zoh, Discrete};
use coil_thermal::filter::{
    predict, predict_mean, update, update_steady, KalmanConfig, KalmanState, SteadyEstimate,
    SteadyStateGain,
};
use coil_thermal::nalgebra::{Const, DMatrix, DVector, DefaultAllocator, Dyn, SMatrix, SVector};
use coil_thermal::network::{state_space_of, RunTimeStepper, SizeMismatch};
use coil_thermal::sizes::{NetworkAllocator, Sizes};
use coil_thermal::{ExplicitStepper, InputFlags, InputLimits, Network, NetworkState, Resistance};
use coil_thermal_host::dynamic_network::DynNetwork;
use coil_thermal_host::model_file::{Model, ModelFile};
use coil_thermal_host::synth::Rng;
use tempfile::TempDir;

/// Every input plausible but a NaN or an absurd current: the input rules
/// fire and are compared too.
fn limits() -> InputLimits {
    InputLimits {
        max_current_a: 50.0,
        min_temp_c: -50.0,
        max_temp_c: 200.0,
    }
}

/// A connected 6-node network with 2 boundaries, 3 sources (two on one
/// node), parallel paths and a fixed power.
fn six_nodes(rng: &mut Rng) -> Network<6, 2, 3> {
    six_nodes_at_run_time(rng).to_network().unwrap()
}

/// [`six_nodes`] as a model file's network: sizes known at run time.
fn six_nodes_at_run_time(rng: &mut Rng) -> DynNetwork {
    let caps = (0..6).map(|_| 5.0 + 50.0 * rng.uniform()).collect();
    let mut net = DynNetwork::new(caps, 2).unwrap();
    for (a, b) in [
        (0, 1),
        (1, 2),
        (2, 3),
        (3, 4),
        (4, 5),
        (5, 0),
        (1, 0),
        (0, 3),
    ] {
        net.connect(a, b, 0.1 + 2.0 * rng.uniform()).unwrap();
    }
    net.connect_boundary(0, 0, 0.5 + rng.uniform()).unwrap();
    net.connect_boundary(4, 1, 0.5 + rng.uniform()).unwrap();
    for node in [0, 3, 3] {
        let r = Resistance::with_alpha(0.5 + rng.uniform(), 0.0039, 20.0);
        net.joule_source(node, r).unwrap();
    }
    net.fixed_power(2, 3.0 * rng.uniform()).unwrap();
    net
}

/// The run-time stepper of a network is its const-generic stepper to the
/// bit, in `f64` and `f32` (the same checks, packing and kernel), input
/// rules included (a NaN current held, an absurd one clamped, a boundary
/// out of range held, each flagged alike); and a state or input of
/// another size is refused, the state untouched.
#[test]
fn the_run_time_stepper_is_the_const_generic_ones_to_the_bit() {
    fn compare<S: coil_thermal::Scalar + core::fmt::Debug>(net: &Network<6, 2, 3>, rng: &mut Rng) {
        let dt = 0.7 / 6.0;
        let fixed = ExplicitStepper::<S, 6, 2, 3>::new(net, dt, limits()).unwrap();
        let run_time = RunTimeStepper::<S>::new(net, dt, limits()).unwrap();
        assert_eq!(run_time.stability_ratio(), fixed.stability_ratio());
        let mut a = NetworkState::<S, 6, 2, 3>::uniform(25.0);
        let mut b = run_time.state(25.0);
        for k in 0..5000 {
            let mut currents = [0; 3].map(|_| S::from_f64(12.0 * rng.uniform()));
            let mut boundary = [S::from_f64(20.0 + 5.0 * rng.uniform()); 2];
            match k % 997 {
                5 => currents[1] = S::from_f64(f64::NAN),
                6 => currents[2] = S::from_f64(1e4),
                7 => boundary[0] = S::from_f64(1e3),
                _ => {}
            }
            let flags_a = fixed.step(&mut a, &currents, &boundary);
            let flags_b = run_time.step(&mut b, &currents, &boundary).unwrap();
            assert_eq!(flags_a, flags_b, "step {k}");
            assert_eq!(a.temps_c.to_vec(), b.temps_c, "step {k}");
            assert_eq!(a.residual_c.to_vec(), b.residual_c, "step {k}");
        }
        assert!(
            a.temps_c.iter().all(|t| t.to_f64() > 25.0),
            "{:?}",
            a.temps_c
        );
        let before = b.clone();
        let zero = S::from_f64(0.0);
        assert_eq!(
            run_time.step(&mut b, &[zero; 2], &[zero; 2]),
            Err(SizeMismatch)
        );
        assert_eq!(
            run_time.step(&mut b, &[zero; 3], &[zero; 1]),
            Err(SizeMismatch)
        );
        let mut other = RunTimeStepper::<S>::new(&six_nodes(rng), dt, limits())
            .unwrap()
            .state(25.0);
        other.temps_c.pop();
        assert_eq!(
            run_time.step(&mut other, &[zero; 3], &[zero; 2]),
            Err(SizeMismatch)
        );
        assert_eq!(b, before);
    }
    let mut rng = Rng::new(37);
    for _ in 0..5 {
        let net = six_nodes(&mut rng);
        compare::<f64>(&net, &mut rng);
        compare::<f32>(&net, &mut rng);
    }
    // The flags a held input raises are the ones documented.
    let net = six_nodes(&mut rng);
    let s = RunTimeStepper::<f64>::new(&net, 0.01, limits()).unwrap();
    let mut state = s.state(25.0);
    let flags = s
        .step(&mut state, &[f64::NAN, 1.0, 1.0], &[20.0, 20.0])
        .unwrap();
    assert_eq!(flags, InputFlags::CURRENT_NOT_FINITE);
}

/// The analyses written over `Sizes` give, on a network's run-time
/// description (`Vec`s), the const-generic network's answers to the bit:
/// the steady state, the time-to-limit predictor's every answer at random
/// operating points (in `f64` and `f32`; some elements without a limit,
/// some at or past theirs, a non-finite input), its safe currents and
/// downtime cooling, and the runaway and hot-spot currents; vectors of
/// another length are refused.
#[test]
fn the_run_time_analyses_are_the_const_generic_ones_to_the_bit() {
    use coil_thermal::network::steady_state_of;
    use coil_thermal::protect::predict::{Operating, OperatingPoint, PredictorBuilder};
    use coil_thermal::protect::runaway::{hot_spot_current_a, runaway_current_a};
    use coil_thermal::protect::safe_current::Horizon;
    use coil_thermal::BuildError;

    fn predictions<T: coil_thermal::nalgebra::RealField + Copy>(
        fixed: &Network<6, 2, 3>,
        run_time: &DynNetwork,
        rng: &mut Rng,
    ) {
        let to_t = |x: f64| T::from_subset(&x);
        let builder = PredictorBuilder::new().grid_s(0.5, 5000.0);
        let a = builder.build::<T, 6, 2, 3, 24>(fixed).unwrap();
        let b = builder.build_from::<T, _, 24>(run_time).unwrap();
        for k in 0..200 {
            let mut op = Operating::<T, 6, 2, 3> {
                temps_c: [0; 6].map(|_| to_t(20.0 + 80.0 * rng.uniform())),
                currents_a: [0; 3].map(|_| to_t(15.0 * rng.uniform())),
                boundary_c: [0; 2].map(|_| to_t(15.0 + 10.0 * rng.uniform())),
                limits_c: [0; 6].map(|_| to_t(60.0 + 100.0 * rng.uniform())),
            };
            op.limits_c[k % 6] = to_t(f64::INFINITY);
            if k % 50 == 7 {
                op.temps_c[1] = to_t(f64::NAN);
            }
            let op_b = OperatingPoint {
                temps_c: op.temps_c.to_vec(),
                currents_a: op.currents_a.to_vec(),
                boundary_c: op.boundary_c.to_vec(),
                limits_c: op.limits_c.to_vec(),
            };
            let (mut ttl_a, mut ttl_b) = ([None; 6], vec![None; 6]);
            a.predict(&op, &mut ttl_a);
            b.predict(&op_b, &mut ttl_b);
            // `Option<T>` of NaN is not equal to itself: compare the bits
            // through their debug form.
            assert_eq!(format!("{ttl_a:?}"), format!("{ttl_b:?}"), "op {k}");
            for horizon in [Horizon::Seconds(to_t(300.0)), Horizon::Forever] {
                let (sa, sb) = (
                    a.max_common_scale(&op, horizon, to_t(0.5)),
                    b.max_common_scale(&op_b, horizon, to_t(0.5)),
                );
                assert_eq!(format!("{sa:?}"), format!("{sb:?}"), "op {k}");
                for coil in 0..4 {
                    let (ca, cb) = (
                        a.max_coil_current_a(coil, &op, horizon, to_t(1.0)),
                        b.max_coil_current_a(coil, &op_b, horizon, to_t(1.0)),
                    );
                    assert_eq!(format!("{ca:?}"), format!("{cb:?}"), "op {k}");
                }
            }
            let off_s = to_t(1000.0 * rng.uniform());
            let (ca, cb) = (
                a.cooled_c(&op.temps_c, &op.boundary_c, off_s),
                b.cooled_c(&op_b.temps_c, &op_b.boundary_c, off_s),
            );
            assert_eq!(format!("{ca:?}"), format!("{cb:?}"), "op {k}");
        }
        assert_eq!(a.slowest_time_constant_s(), b.slowest_time_constant_s());
    }

    let mut rng = Rng::new(53);
    for _ in 0..5 {
        let run_time = six_nodes_at_run_time(&mut rng);
        let fixed: Network<6, 2, 3> = run_time.to_network().unwrap();
        for _ in 0..20 {
            let currents = [0; 3].map(|_| 20.0 * rng.uniform());
            let boundary = [0; 2].map(|_| 10.0 + 20.0 * rng.uniform());
            let limits = [0; 6].map(|_| 80.0 + 100.0 * rng.uniform());
            let steady = fixed.steady_state(&currents, &boundary);
            let steady_b = steady_state_of(&run_time, &currents.to_vec(), &boundary.to_vec());
            assert_eq!(steady.map(|t| t.to_vec()), steady_b);
            for coil in 0..3 {
                assert_eq!(
                    runaway_current_a(&fixed, coil, &currents),
                    runaway_current_a(&run_time, coil, &currents.to_vec())
                );
                assert_eq!(
                    hot_spot_current_a(&fixed, coil, &currents, &boundary, &limits),
                    hot_spot_current_a(
                        &run_time,
                        coil,
                        &currents.to_vec(),
                        &boundary.to_vec(),
                        &limits.to_vec()
                    )
                );
            }
        }
        predictions::<f64>(&fixed, &run_time, &mut rng);
        predictions::<f32>(&fixed, &run_time, &mut rng);
    }
    // Vectors of another length than the network's are refused.
    let run_time = six_nodes_at_run_time(&mut rng);
    let refused = BuildError::InvalidParameter {
        name: "currents_a/boundary_c",
    };
    assert_eq!(
        steady_state_of(&run_time, &vec![1.0; 2], &vec![20.0; 2]),
        Err(refused)
    );
    assert_eq!(
        steady_state_of(&run_time, &vec![1.0; 3], &vec![20.0; 3]),
        Err(refused)
    );
    assert_eq!(
        runaway_current_a(&run_time, 0, &vec![1.0; 4]),
        Err(BuildError::InvalidParameter { name: "currents_a" })
    );
    assert!(
        hot_spot_current_a(&run_time, 0, &vec![1.0; 3], &vec![20.0; 2], &vec![90.0; 5]).is_err()
    );
    // ... and give the predictor's "unknown" answers: every time to limit
    // `Some(NaN)`, an invalid safe current, no cooling.
    let predictor = PredictorBuilder::new()
        .build_from::<f64, _, 24>(&run_time)
        .unwrap();
    let op = OperatingPoint {
        temps_c: vec![40.0; 5],
        currents_a: vec![5.0; 3],
        boundary_c: vec![20.0; 2],
        limits_c: vec![90.0; 6],
    };
    let mut ttl = vec![None; 6];
    predictor.predict(&op, &mut ttl);
    assert!(ttl.iter().all(|t| t.is_some_and(f64::is_nan)), "{ttl:?}");
    let op = OperatingPoint {
        temps_c: vec![40.0; 6],
        ..op
    };
    let mut short = vec![None; 5];
    predictor.predict(&op, &mut short);
    assert!(
        short.iter().all(|t| t.is_some_and(f64::is_nan)),
        "{short:?}"
    );
    predictor.predict(&op, &mut ttl);
    assert!(ttl.iter().all(|t| t.is_none_or(|t| !t.is_nan())), "{ttl:?}");
    let unfit = OperatingPoint {
        boundary_c: vec![20.0; 3],
        ..op.clone()
    };
    let safe = predictor.max_common_scale(&unfit, Horizon::Forever, 1.0);
    assert!(!safe.feasible && safe.value == 0.0, "{safe:?}");
    let warm = vec![60.0; 6];
    assert_eq!(predictor.cooled_c(&warm, &vec![20.0; 1], 100.0), warm);
    assert!(predictor.cooled_c(&warm, &vec![20.0; 2], 100.0)[0] < 60.0);
}

/// Slots of the 300-node motor.
const SLOTS: usize = 36;

/// A conductance of the motor network: its two ends (node names, or a
/// boundary's) \[W/K\].
struct Link {
    a: String,
    b: String,
    g_w_per_k: f64,
}

/// The predictor's per-tick state at run-time sizes (`Vec` sweeps and
/// answers) is the MCU's (arrays) to the bit: sliced sweeps (two elements
/// a tick, and one in two halves, as the network observer on a core
/// without an FPU takes them) over 600 ticks whose operating point moves
/// every tick, with a NaN temperature and an unlimited node now and then;
/// and the sweep that keeps no answers makes the same ones when asked.
#[test]
fn the_sliced_predictor_at_run_time_sizes_is_the_const_generic_one_to_the_bit() {
    use coil_thermal::protect::predict::{
        AnswersWhenAsked, HalfElement, Operating, OperatingPoint, PredictorBuilder, PredictorState,
    };

    let mut rng = Rng::new(71);
    let run_time = six_nodes_at_run_time(&mut rng);
    let fixed: Network<6, 2, 3> = run_time.to_network().unwrap();
    let builder = PredictorBuilder::new()
        .grid_s(0.5, 5000.0)
        .tick_s(0.1)
        .elements_per_tick(2);
    let a = builder.build::<f32, 6, 2, 3, 24>(&fixed).unwrap();
    let b = builder.build_from::<f32, _, 24>(&run_time).unwrap();
    let op_at = |rng: &mut Rng, k: usize| {
        let mut op = Operating::<f32, 6, 2, 3> {
            temps_c: [0; 6].map(|_| 20.0 + 80.0 * rng.uniform() as f32),
            currents_a: [0; 3].map(|_| 15.0 * rng.uniform() as f32),
            boundary_c: [0; 2].map(|_| 15.0 + 10.0 * rng.uniform() as f32),
            limits_c: [0; 6].map(|_| 60.0 + 100.0 * rng.uniform() as f32),
        };
        if k % 37 == 5 {
            op.limits_c[k % 6] = f32::INFINITY;
        }
        if k % 101 == 17 {
            op.temps_c[2] = f32::NAN;
        }
        let op_b = OperatingPoint {
            temps_c: op.temps_c.to_vec(),
            currents_a: op.currents_a.to_vec(),
            boundary_c: op.boundary_c.to_vec(),
            limits_c: op.limits_c.to_vec(),
        };
        (op, op_b)
    };
    let (op, op_b) = op_at(&mut rng, 0);
    let (mut whole_a, mut whole_b) = (PredictorState::new(&a, &op), PredictorState::new(&b, &op_b));
    let (mut halved_a, mut halved_b) = (whole_a.clone(), whole_b.clone());
    let (mut half_a, mut half_b) = (HalfElement::new(), HalfElement::new());
    let mut asked_a = PredictorState::<_, _, AnswersWhenAsked>::when_asked(&a, &op);
    let mut asked_b = PredictorState::<_, _, AnswersWhenAsked>::when_asked(&b, &op_b);
    let mut answered = 0;
    for k in 1..=600 {
        let (op, op_b) = op_at(&mut rng, k);
        let (ta, tb) = (whole_a.tick(&a, &op), whole_b.tick(&b, &op_b));
        // `Option` of NaN is not equal to itself: the bits through their
        // debug form.
        assert_eq!(format!("{ta:?}"), format!("{tb:?}"), "tick {k}");
        answered += ta
            .iter()
            .filter(|t| matches!(t, Some(t) if t.is_finite()))
            .count();
        let (ha, hb) = (
            halved_a.tick_in_halves(&a, &op, &mut half_a),
            halved_b.tick_in_halves(&b, &op_b, &mut half_b),
        );
        assert_eq!(format!("{ha:?}"), format!("{hb:?}"), "tick {k}, in halves");
        asked_a.tick(&a, &op);
        asked_b.tick(&b, &op_b);
        let (aa, ab) = (asked_a.time_to_limit_s(), asked_b.time_to_limit_s());
        assert_eq!(format!("{aa:?}"), format!("{ab:?}"), "tick {k}, when asked");
        assert_eq!(
            format!("{aa:?}"),
            format!("{ta:?}"),
            "tick {k}, kept and asked"
        );
    }
    // The sweeps completed and answered (not all "never" or NaN).
    assert!(answered > 600, "{answered} finite answers");
}

/// A stator of 36 slots, each with two copper layers (each a Joule source
/// on its phase), the slot liner, the tooth and its tip, the yoke segment
/// and the end winding at each end (8 nodes a slot); a housing and a rotor
/// in six segments each: 300 nodes, 72 sources, 3 phase currents, a
/// coolant and an ambient boundary. Returns the node names with their
/// capacities \[J/K\], the links, and the sources (node, phase).
#[allow(clippy::type_complexity)]
fn motor() -> (Vec<(String, f64)>, Vec<Link>, Vec<(String, usize)>) {
    let mut nodes = Vec::new();
    let mut links = Vec::new();
    let mut sources = Vec::new();
    let mut link = |a: String, b: String, g_w_per_k: f64| links.push(Link { a, b, g_w_per_k });
    for s in 0..SLOTS {
        let next = (s + 1) % SLOTS;
        let n = |part: &str, s: usize| format!("{part}_{s}");
        for (part, c) in [
            ("cu_in", 15.0),
            ("cu_out", 15.0),
            ("liner", 3.0),
            ("tooth", 40.0),
            ("tip", 10.0),
            ("yoke", 60.0),
            ("end_front", 20.0),
            ("end_back", 20.0),
        ] {
            nodes.push((n(part, s), c));
        }
        for (a, b, g) in [
            ("cu_in", "cu_out", 4.0),
            ("cu_in", "liner", 3.0),
            ("cu_out", "liner", 3.0),
            ("liner", "tooth", 6.0),
            ("liner", "yoke", 5.0),
            ("tooth", "tip", 8.0),
            ("tooth", "yoke", 10.0),
            ("end_front", "cu_in", 2.0),
            ("end_front", "cu_out", 2.0),
            ("end_back", "cu_in", 2.0),
            ("end_back", "cu_out", 2.0),
        ] {
            link(n(a, s), n(b, s), g);
        }
        for (part, g) in [("yoke", 6.0), ("end_front", 0.5), ("end_back", 0.5)] {
            link(n(part, s), n(part, next), g);
        }
        let segment = s / 6;
        link(n("tip", s), n("rotor", segment), 0.3);
        link(n("yoke", s), n("housing", segment), 12.0);
        link(n("end_front", s), n("housing", segment), 0.3);
        link(n("end_back", s), n("housing", segment), 0.3);
        let phase = (s / 2) % 3;
        sources.push((n("cu_in", s), phase));
        sources.push((n("cu_out", s), phase));
    }
    for k in 0..6 {
        nodes.push((format!("housing_{k}"), 800.0));
        nodes.push((format!("rotor_{k}"), 500.0));
        link(format!("housing_{k}"), "coolant".into(), 40.0);
        link(format!("rotor_{k}"), "ambient".into(), 0.8);
        link(format!("rotor_{k}"), format!("rotor_{}", (k + 1) % 6), 5.0);
        link(format!("rotor_{k}"), format!("housing_{k}"), 0.2);
    }
    (nodes, links, sources)
}

/// The copper's resistance at 20 degC \[ohm\] and its temperature
/// coefficient \[1/K\].
const R20_OHM: f64 = 0.02;
const ALPHA_PER_K: f64 = 0.0039;
/// The boundaries \[degC\].
const COOLANT_C: f64 = 40.0;
const AMBIENT_C: f64 = 25.0;

/// The motor as a model file, its housing-to-coolant conductance of
/// segment 0 at `g0_w_per_k` and named `jacket_0` (for `calibrate`),
/// every node starting at the coolant's 40 degC.
fn motor_file(g0_w_per_k: f64) -> String {
    motor_file_with(g0_w_per_k, ALPHA_PER_K)
}

/// [`motor_file`] with the copper's temperature coefficient at
/// `alpha_per_k` \[1/K\].
fn motor_file_with(g0_w_per_k: f64, alpha_per_k: f64) -> String {
    let (nodes, links, sources) = motor();
    let mut t = String::from(
        "name = \"motor-300\"\ndescription = \"36-slot stator, housing and rotor: 300 nodes, 72 copper sources\"\nmax_step_ratio = 0.05\n",
    );
    for (name, c) in &nodes {
        let critical = if name.starts_with("end_") {
            "critical_c = 180.0\n"
        } else {
            ""
        };
        let _ = write!(
            t,
            "\n[[node]]\nname = \"{name}\"\ncapacity_j_per_k = {c:?}\n{critical}"
        );
    }
    for (name, c) in [("coolant", COOLANT_C), ("ambient", AMBIENT_C)] {
        let _ = write!(t, "\n[[boundary]]\nname = \"{name}\"\nvalue_c = {c:?}\n");
    }
    for l in &links {
        let (name, g) = if l.a == "housing_0" && l.b == "coolant" {
            ("name = \"jacket_0\"\n", g0_w_per_k)
        } else {
            ("", l.g_w_per_k)
        };
        let _ = write!(
            t,
            "\n[[conductance]]\n{name}between = [\"{}\", \"{}\"]\ng_w_per_k = {g:?}\n",
            l.a, l.b
        );
    }
    for (k, (node, phase)) in sources.iter().enumerate() {
        let _ = write!(
            t,
            "\n[[source]]\nname = \"copper_{k}\"\nnode = \"{node}\"\ninput = \"i{}\"\nr0_ohm = {R20_OHM:?}\nalpha_per_k = {alpha_per_k:?}\nt_ref_c = 20.0\n",
            ["a", "b", "c"][*phase]
        );
    }
    t.push_str("\n[initial]\npolicy = \"uniform\"\nuniform_c = 40.0\n");
    t
}

/// An independent integration of the motor's energy balance (classical
/// RK4 in `f64` on the link list, `R(T)` at each stage; no library code)
/// from every node at `start_c` \[degC\], `current_a` \[A\] in every
/// phase for `duration_s` \[s\]: each node's temperature by name.
fn reference(start_c: f64, current_a: f64, duration_s: f64) -> Vec<(String, f64)> {
    let boundary_c = [COOLANT_C, AMBIENT_C];
    reference_trajectory(
        start_c,
        boundary_c,
        current_a,
        duration_s,
        ALPHA_PER_K,
        |_, _| true,
    )
}

/// [`reference`] with the boundaries at `boundary_c` (coolant, ambient)
/// \[degC\] and the copper's coefficient `alpha_per_k` \[1/K\], calling
/// `watch(t_s, temps_c)` (in [`motor`]'s node order) after every step, and
/// stopping early where it returns `false`.
fn reference_trajectory(
    start_c: f64,
    boundary_c: [f64; 2],
    current_a: f64,
    duration_s: f64,
    alpha_per_k: f64,
    mut watch: impl FnMut(f64, &[f64]) -> bool,
) -> Vec<(String, f64)> {
    let (nodes, links, sources) = motor();
    let index = |name: &str| nodes.iter().position(|(n, _)| n == name);
    let boundary = |name: &str| match name {
        "coolant" => boundary_c[0],
        "ambient" => boundary_c[1],
        other => panic!("no boundary {other}"),
    };
    let edges: Vec<(usize, Option<usize>, f64, f64)> = links
        .iter()
        .map(|l| {
            let a = index(&l.a).unwrap();
            match index(&l.b) {
                Some(b) => (a, Some(b), l.g_w_per_k, 0.0),
                None => (a, None, l.g_w_per_k, boundary(&l.b)),
            }
        })
        .collect();
    let heated: Vec<usize> = sources.iter().map(|(n, _)| index(n).unwrap()).collect();
    let rate = |t: &[f64], out: &mut [f64]| {
        out.fill(0.0);
        for &(a, b, g, t_b) in &edges {
            let flow = g * (b.map_or(t_b, |b| t[b]) - t[a]);
            out[a] += flow;
            if let Some(b) = b {
                out[b] -= flow;
            }
        }
        for &n in &heated {
            out[n] += R20_OHM * (1.0 + alpha_per_k * (t[n] - 20.0)) * current_a * current_a;
        }
        for (o, (_, c)) in out.iter_mut().zip(&nodes) {
            *o /= c;
        }
    };
    let n = nodes.len();
    let mut t = vec![start_c; n];
    let h = 0.01;
    let (mut k1, mut k2, mut k3, mut k4, mut y) = (
        vec![0.0; n],
        vec![0.0; n],
        vec![0.0; n],
        vec![0.0; n],
        vec![0.0; n],
    );
    for step in 1..=(duration_s / h).round() as usize {
        rate(&t, &mut k1);
        y.iter_mut()
            .zip(&t)
            .zip(&k1)
            .for_each(|((y, t), k)| *y = t + 0.5 * h * k);
        rate(&y, &mut k2);
        y.iter_mut()
            .zip(&t)
            .zip(&k2)
            .for_each(|((y, t), k)| *y = t + 0.5 * h * k);
        rate(&y, &mut k3);
        y.iter_mut()
            .zip(&t)
            .zip(&k3)
            .for_each(|((y, t), k)| *y = t + h * k);
        rate(&y, &mut k4);
        for i in 0..n {
            t[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        if !watch(step as f64 * h, &t) {
            break;
        }
    }
    nodes.into_iter().map(|(name, _)| name).zip(t).collect()
}

/// The header and last row of a CSV.
fn last_row(path: &Path) -> (Vec<String>, Vec<f64>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().split(',').map(String::from).collect();
    let last = lines
        .last()
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    (header, last)
}

/// `simulate` runs the 300-node motor at its own size (the library's
/// `RunTimeStepper`, no size class) and follows an independent RK4 of the
/// same equations: 20 min at 45 A per phase (the copper 2.9 kW in all at
/// 20 degC, the end windings to 85 degC) from the coolant's 40 degC, every
/// node within 1 mK (measured 7e-6 K: the explicit sub-steps at the file's
/// `max_step_ratio` of 0.05 resolve the slot liners' 0.2 s).
#[test]
fn simulate_runs_a_300_node_motor_at_its_own_size() {
    let tmp = TempDir::new().unwrap();
    let model = tmp.path().join("motor-300.toml");
    std::fs::write(&model, motor_file(40.0)).unwrap();
    let out = tmp.path().join("sim.csv");
    let start = Instant::now();
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model"])
        .arg(&model)
        .args(["--current-a", "45", "--duration-s", "1200"])
        .arg("--out")
        .arg(&out)
        .assert()
        .success();
    let simulate_s = start.elapsed().as_secs_f64();
    let (header, last) = last_row(&out);
    assert_eq!(header.len(), 301, "time and 300 nodes");
    let expected = reference(40.0, 45.0, 1200.0);
    let mut worst = (0.0f64, String::new());
    for (name, t) in &expected {
        let k = header.iter().position(|h| h == name).unwrap();
        let d = (last[k] - t).abs();
        if d > worst.0 {
            worst = (d, name.clone());
        }
    }
    let hottest = expected.iter().map(|(_, t)| *t).fold(f64::MIN, f64::max);
    eprintln!(
        "simulate, 300 nodes x 1200 s: {simulate_s:.2} s wall (with the process start); worst {:.2e} K off the RK4 at {}, hottest {hottest:.1} degC",
        worst.0, worst.1
    );
    assert!(hottest > 60.0, "the copper heats: {hottest}");
    assert!(worst.0 < 1e-3, "{worst:?}");
}

/// `calibrate` fits a 300-node model at its own size: a recording made
/// with segment 0's water-jacket conductance at 30 W/K (the file says 40)
/// gives it back from the housing's thermocouple.
#[test]
fn calibrate_fits_a_300_node_motor_at_its_own_size() {
    let tmp = TempDir::new().unwrap();
    let truth = tmp.path().join("truth.toml");
    std::fs::write(&truth, motor_file(30.0)).unwrap();
    let model = tmp.path().join("motor-300.toml");
    std::fs::write(&model, motor_file(40.0)).unwrap();
    let recording = tmp.path().join("bench.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model"])
        .arg(&truth)
        .args(["--current-a", "30", "--duration-s", "1800", "--dt-s", "10"])
        .arg("--out")
        .arg(&recording)
        .assert()
        .success();
    let fitted = tmp.path().join("fitted.toml");
    let start = Instant::now();
    cargo_bin_cmd!("coil-thermal")
        .args(["calibrate", "--model"])
        .arg(&model)
        .arg("--trace")
        .arg(&recording)
        .args([
            "--current",
            "30=ia",
            "--current",
            "30=ib",
            "--current",
            "30=ic",
        ])
        .args(["--measure", "housing_0=housing_0"])
        .args(["--params", "conductance.jacket_0=5:100", "--out"])
        .arg(&fitted)
        .assert()
        .success();
    let calibrate_s = start.elapsed().as_secs_f64();
    let text = std::fs::read_to_string(&fitted).unwrap();
    let g = text
        .split("name = \"jacket_0\"")
        .nth(1)
        .and_then(|rest| rest.lines().find(|l| l.starts_with("g_w_per_k")))
        .and_then(|l| l.split('=').nth(1))
        .map(|v| v.trim().parse::<f64>().unwrap())
        .expect("the fitted file keeps the jacket's conductance");
    eprintln!(
        "calibrate, 300 nodes x 1800 s: {calibrate_s:.2} s wall; jacket_0 {g:.4} W/K (truth 30)"
    );
    assert!((g - 30.0).abs() < 0.3, "{g} W/K");
}

/// `replay` of the 300-node motor runs the firmware's observer (what
/// `codegen` flashes from the file) at the model's own size: no size
/// class, no cap, no host-only stepper. Over ten minutes at 45 A per phase
/// from 40 degC, open loop its estimates stay within 1 mK of an
/// independent RK4 of the motor's equations (the copper some 40 K up), and
/// fusing four thermocouples read off `simulate`'s recording keeps them
/// there; the
/// filter's flags apply and the host alarm's are refused by name. Both
/// replays are timed (printed).
#[test]
fn replay_runs_the_firmware_observer_of_a_300_node_motor_at_its_own_size() {
    let tmp = TempDir::new().unwrap();
    let model = tmp.path().join("motor-300.toml");
    std::fs::write(&model, motor_file(40.0)).unwrap();
    let recording = tmp.path().join("bench.csv");
    let duration_s = 600.0;
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model"])
        .arg(&model)
        .args(["--current-a", "45", "--duration-s", "600", "--dt-s", "1"])
        .args(["--with-inputs", "--out"])
        .arg(&recording)
        .assert()
        .success();
    let truth = reference(40.0, 45.0, duration_s);
    let hottest = truth.iter().map(|(_, t)| *t).fold(f64::MIN, f64::max);
    assert!(hottest > 75.0, "the copper heats: {hottest}");
    let replay = |extra: &[&str]| {
        let out = tmp.path().join("replay.csv");
        let start = Instant::now();
        let run = cargo_bin_cmd!("coil-thermal")
            .args(["replay", "--model"])
            .arg(&model)
            .arg("--trace")
            .arg(&recording)
            .args(["--tick-us", "10000"])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .assert()
            .success();
        let wall_s = start.elapsed().as_secs_f64();
        let text = String::from_utf8_lossy(&run.get_output().stdout).into_owned();
        assert!(
            text.contains("observer: the firmware's NetworkObserver from codegen's defaults"),
            "{text}"
        );
        let (header, last) = last_row(&out);
        let worst = truth
            .iter()
            .map(|(name, t)| {
                let k = header.iter().position(|h| h == name).unwrap();
                (last[k] - t).abs()
            })
            .fold(0.0f64, f64::max);
        (wall_s, worst, text)
    };
    let (open_s, open_worst, _) = replay(&[]);
    let measure = [
        "--measure",
        "end_front_0=end_front_0",
        "--measure",
        "end_back_12=end_back_12",
        "--measure",
        "end_front_24=end_front_24",
        "--measure",
        "housing_0=housing_0",
    ];
    let (fused_s, fused_worst, text) = replay(&measure);
    eprintln!(
        "replay of the 300-node motor, {duration_s} s at 10 ms ticks: open loop {open_s:.2} s wall, worst {open_worst:.1e} K off the RK4; four thermocouples {fused_s:.2} s, worst {fused_worst:.1e} K"
    );
    assert!(text.contains("end_front_0"), "{text}");
    // Measured 9.6e-5 K open loop and 8.2e-5 K fused (the `f32` model
    // step's rounding, carried).
    assert!(open_worst < 1e-3, "{open_worst}");
    assert!(fused_worst < 1e-3, "{fused_worst}");
    // The host alarm's flags do not apply to the firmware's observer, and
    // are refused by name.
    cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(&model)
        .arg("--trace")
        .arg(&recording)
        .args(["--horizon-s", "60"])
        .assert()
        .failure()
        .stderr(predicates::str::contains(
            "--horizon-s sets the host's alarm on an estimate",
        ));
}

/// The first time any node of the 300-node motor reaches its limit
/// `limit_c(name)` \[degC\] in the independent RK4, from 40 degC
/// everywhere (both boundaries at 40 degC) at `current_a` per phase: the
/// node and the time \[s\].
fn first_to_reach(
    limit_c: impl Fn(&str) -> f64,
    current_a: f64,
    alpha_per_k: f64,
) -> (String, f64) {
    let (names, ..) = motor();
    let limits_c: Vec<f64> = names.iter().map(|(name, _)| limit_c(name)).collect();
    let mut first = None;
    reference_trajectory(
        40.0,
        [40.0, 40.0],
        current_a,
        3600.0,
        alpha_per_k,
        |t_s, temps| {
            first = temps
                .iter()
                .zip(&limits_c)
                .position(|(t, limit_c)| *t >= *limit_c)
                .map(|i| (names[i].0.clone(), t_s));
            first.is_none()
        },
    );
    first.expect("the motor reaches its limit within an hour")
}

/// `limits` runs the library's time-to-limit predictor, safe and runaway
/// currents on the 300-node motor at its own size (no size class): from
/// the coolant's 40 degC everywhere (every boundary at 40 degC), 70 A per
/// phase, every element limited at 150 degC. It acts on the upper bound
/// of the firmware's observer of the file, built at the model's size:
/// each limit becomes the estimate at which that bound reaches 150 degC.
/// The earliest answer is never later than an independent RK4 of the
/// same equations reaching those limits (the predictor takes each winding's
/// `R` at its limit, 1.40 times its `R` at 40 degC: measured 17 % early);
/// with `R` constant (and 85 A: the steady state at 70 A stays below the
/// limit), the predictor's one approximation is its grid's brackets:
/// within 3 % of the RK4 (the library's `limits::compute`, the code the
/// command calls).
#[test]
fn limits_predicts_a_300_node_motor_at_its_own_size() {
    let tmp = TempDir::new().unwrap();
    let model = tmp.path().join("motor-300.toml");
    std::fs::write(&model, motor_file(40.0)).unwrap();
    let start = Instant::now();
    let run = cargo_bin_cmd!("coil-thermal")
        .args(["limits", "--model"])
        .arg(&model)
        .args(["--current-a", "70", "--ambient-c", "40", "--limit-c", "150"])
        .args(["--coil", "ia", "--json"])
        .assert()
        .success();
    let limits_s = start.elapsed().as_secs_f64();
    println!("limits of the 300-node motor (24 coils' figures): {limits_s:.2} s");
    let json: serde_json::Value = serde_json::from_slice(&run.get_output().stdout).unwrap();
    assert_eq!(json["acts_on"], "upper bound", "{json}");
    assert!(
        json["upper_bound"]
            .as_str()
            .unwrap()
            .contains("the firmware's NetworkObserver"),
        "{json}"
    );
    let earliest = |ttl: &mut dyn Iterator<Item = (String, Option<f64>)>| {
        ttl.filter_map(|(node, t)| t.map(|t| (node, t)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap()
    };
    let (node, predicted_s) = earliest(
        &mut json["time_to_limit_s"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(n, t)| (n.clone(), t.as_f64())),
    );
    // The limits act on the firmware's upper bound: each node's limit for
    // the model's temperatures is the mean at which that bound reaches
    // 150 degC.
    let mean_limit_c = |name: &str| json["mean_limits_c"][name].as_f64().unwrap();
    assert!(mean_limit_c("cu_in_0") < 150.0, "{json}");
    let (true_node, true_s) = first_to_reach(mean_limit_c, 70.0, ALPHA_PER_K);
    println!("R(T): first to its limit {node} at {predicted_s:.2} s; the RK4: {true_node} at {true_s:.2} s");
    assert!(
        predicted_s <= true_s && predicted_s >= 0.8 * true_s,
        "{predicted_s} s, {true_s} s"
    );

    // `R` constant: only the grid's brackets between the two.
    let text = motor_file_with(40.0, 0.0);
    let file = coil_thermal_host::model_file::ModelFile::parse(&text, "motor-300.toml").unwrap();
    let motor = coil_thermal_host::model_file::Model::build(&file).unwrap();
    let n = motor.nodes.len();
    let start = Instant::now();
    let report = coil_thermal_host::limits::compute(&coil_thermal_host::limits::LimitsQuery {
        network: motor.network.clone(),
        currents_a: vec![85.0; 72],
        boundary_c: vec![40.0, 40.0],
        limits_c: vec![Some(150.0); n],
        horizon_s: Some(60.0),
        coils: Vec::new(),
    })
    .unwrap();
    let compute_s = start.elapsed().as_secs_f64();
    let (node, predicted_s) = earliest(
        &mut motor
            .nodes
            .iter()
            .cloned()
            .zip(report.time_to_limit_s.iter().copied()),
    );
    let (true_node, true_s) = first_to_reach(|_| 150.0, 85.0, 0.0);
    println!("R constant ({compute_s:.2} s): first to its limit {node} at {predicted_s:.2} s; the RK4: {true_node} at {true_s:.2} s");
    assert!(
        predicted_s <= true_s && predicted_s >= 0.97 * true_s,
        "{predicted_s} s, {true_s} s"
    );
}

/// Any value: finite, extreme, infinite or NaN.
fn any_value() -> impl proptest::strategy::Strategy<Value = f64> {
    use proptest::prelude::*;
    prop_oneof![
        -50.0..300.0f64,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(f64::MAX),
        Just(-f64::MAX),
        Just(1e-300),
    ]
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]

    /// The analyses at run-time sizes take any input without a panic: an
    /// operating point of any lengths and values, any horizon, duty, coil
    /// and off time. One of another network's lengths, or with a value
    /// that is not finite (a limit may be `+inf`), gets the "unknown"
    /// answers (every time to limit `Some(NaN)`, an invalid safe current);
    /// the steady state and the runaway current refuse one.
    #[test]
    fn the_run_time_analyses_take_any_input(
        temps in proptest::collection::vec(any_value(), 0..9),
        currents in proptest::collection::vec(any_value(), 0..5),
        boundary in proptest::collection::vec(any_value(), 0..4),
        limits in proptest::collection::vec(any_value(), 0..9),
        horizon_s in any_value(),
        duty in any_value(),
        off_s in any_value(),
        coil in 0usize..5,
    ) {
        use coil_thermal::network::steady_state_of;
        use coil_thermal::protect::predict::{OperatingPoint, PredictorBuilder};
        use coil_thermal::protect::runaway::runaway_current_a;
        use coil_thermal::protect::safe_current::Horizon;

        let network = six_nodes_at_run_time(&mut Rng::new(7));
        let predictor = PredictorBuilder::new()
            .build_from::<f64, _, 16>(&network)
            .unwrap();
        let op: OperatingPoint<f64, coil_thermal::sizes::RunTimeSizes> = OperatingPoint {
            temps_c: temps,
            currents_a: currents,
            boundary_c: boundary,
            limits_c: limits,
        };
        let fits = op.temps_c.len() == 6
            && op.limits_c.len() == 6
            && op.currents_a.len() == 3
            && op.boundary_c.len() == 2;
        let finite = (op.temps_c.iter())
            .chain(&op.currents_a)
            .chain(&op.boundary_c)
            .all(|v| v.is_finite())
            && op.limits_c.iter().all(|l| l.is_finite() || *l > 0.0);
        let mut ttl = vec![None; 6];
        predictor.predict(&op, &mut ttl);
        if !(fits && finite) {
            proptest::prop_assert!(ttl.iter().all(|t| t.is_some_and(f64::is_nan)), "{:?}", ttl);
        }
        for horizon in [Horizon::Seconds(horizon_s), Horizon::Forever] {
            let common = predictor.max_common_scale(&op, horizon, duty);
            let one = predictor.max_coil_current_a(coil, &op, horizon, duty);
            if !(fits && finite) {
                proptest::prop_assert!(!common.feasible && common.value == 0.0);
                proptest::prop_assert!(!one.feasible && one.value == 0.0);
            }
        }
        let cooled = predictor.cooled_c(&op.temps_c, &op.boundary_c, off_s);
        proptest::prop_assert_eq!(cooled.len(), op.temps_c.len());
        let steady = steady_state_of(&network, &op.currents_a, &op.boundary_c);
        let runaway = runaway_current_a(&network, coil.min(2), &op.currents_a);
        if op.currents_a.len() != 3 || !op.currents_a.iter().all(|i| i.is_finite()) {
            proptest::prop_assert!(steady.is_err() && runaway.is_err());
        }
    }
}

/// The filter of a network: `F = Ad`, `G = [Bd | Gd | dd]` (inputs the
/// Joule powers, the boundaries and 1), thermocouples on `sensors`,
/// `Q` of `node_noise_k2_per_s`, `R` of `sigma_k`, all as `DMatrix`es.
struct FilterMatrices {
    f: DMatrix<f64>,
    g: DMatrix<f64>,
    h: DMatrix<f64>,
    q: DMatrix<f64>,
    r: DVector<f64>,
}

/// [`FilterMatrices`] from a discretised network of any sizes.
fn filter_matrices<Z: Sizes>(d: &Discrete<f64, Z>, sensors: &[usize]) -> FilterMatrices
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    let (n, m, b) = (d.ad.nrows(), d.bd_power.ncols(), d.gd_boundary.ncols());
    let g = DMatrix::from_fn(n, m + b + 1, |i, j| match j {
        j if j < m => d.bd_power[(i, j)],
        j if j < m + b => d.gd_boundary[(i, j - m)],
        _ => d.dd[i],
    });
    let mut h = DMatrix::zeros(sensors.len(), n);
    for (j, &node) in sensors.iter().enumerate() {
        h[(j, node)] = 1.0;
    }
    FilterMatrices {
        f: DMatrix::from_column_slice(n, n, d.ad.as_slice()),
        g,
        h,
        q: DMatrix::identity(n, n) * (1e-4 * d.dt_s),
        r: DVector::repeat(sensors.len(), 0.25 * 0.25),
    }
}

/// The filter at run-time sizes (`Dyn`).
type RunTimeFilter = KalmanConfig<f64, Dyn, Dyn, Dyn>;

fn run_time_filter(m: &FilterMatrices) -> RunTimeFilter {
    KalmanConfig::new(
        m.f.clone(),
        m.g.clone(),
        m.h.clone(),
        m.q.clone(),
        m.r.clone(),
    )
    .unwrap()
}

/// Largest difference of two equally long slices relative to the larger's
/// largest entry.
fn relative_gap(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = a.iter().chain(b).fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

/// The exact discretisation and the Kalman filter of a network read at
/// run time (`Dyn` dimensions: the host's) are the const-generic
/// network's (`Const<N>`: the MCU's): one code path, the same functions
/// at two kinds of sizes. `Ad`, `Bd`, `Gd`, `dd`, the steady gain, its
/// prior, posterior and innovation covariance agree within 1e-13
/// relative, not to the bit: on a host, nalgebra multiplies dynamic
/// matrices larger than 5 x 5 with `matrixmultiply`, which sums in
/// another order (the tables an MCU flashes are solved on the host, by
/// `codegen`, in one of the two). A run of mean predicts and steady
/// corrections with missing, NaN and rejected readings gives the same
/// verdicts and estimates within 1e-9 K.
#[test]
fn the_filter_at_run_time_sizes_is_the_const_generic_one() {
    let mut rng = Rng::new(39);
    for _ in 0..3 {
        let dynamic = six_nodes_at_run_time(&mut rng);
        let fixed: Network<6, 2, 3> = dynamic.to_network().unwrap();
        let d_fixed = zoh(&fixed.state_space(&[20.0; 6]), 0.1).unwrap();
        let d_dyn = zoh(&state_space_of(&dynamic, &vec![20.0; 6]), 0.1).unwrap();
        for (a, b) in [
            (d_fixed.ad.as_slice(), d_dyn.ad.as_slice()),
            (d_fixed.bd_power.as_slice(), d_dyn.bd_power.as_slice()),
            (d_fixed.gd_boundary.as_slice(), d_dyn.gd_boundary.as_slice()),
            (d_fixed.dd.as_slice(), d_dyn.dd.as_slice()),
        ] {
            assert!(relative_gap(a, b) < 1e-13, "{a:?} {b:?}");
        }

        let sensors = [0, 4];
        let m = filter_matrices(&d_dyn, &sensors);
        let dyn_cfg = run_time_filter(&m);
        let const_cfg = KalmanConfig::<f64, Const<6>, Const<6>, Const<2>>::new(
            SMatrix::from_column_slice(m.f.as_slice()),
            SMatrix::from_column_slice(m.g.as_slice()),
            SMatrix::from_column_slice(m.h.as_slice()),
            SMatrix::from_column_slice(m.q.as_slice()),
            SVector::from_column_slice(m.r.as_slice()),
        )
        .unwrap();
        let period = 10;
        let dyn_gain = SteadyStateGain::solve(&dyn_cfg, period).unwrap();
        let const_gain = SteadyStateGain::solve(&const_cfg, period).unwrap();
        for (a, b) in [
            (dyn_gain.gain().as_slice(), const_gain.gain().as_slice()),
            (dyn_gain.prior().as_slice(), const_gain.prior().as_slice()),
            (
                dyn_gain.posterior().as_slice(),
                const_gain.posterior().as_slice(),
            ),
            (
                dyn_gain.innovation_cov().as_slice(),
                const_gain.innovation_cov().as_slice(),
            ),
        ] {
            assert!(relative_gap(a, b) < 1e-13, "{a:?} {b:?}");
        }

        let mut x_dyn = SteadyEstimate::for_sensors(DVector::repeat(6, 20.0), Dyn(2));
        let mut x_const = SteadyEstimate::<f64, Const<6>, Const<2>>::new(SVector::repeat(20.0));
        let mut rejected = 0;
        for k in 0..2000 {
            let powers: Vec<f64> = (0..3).map(|_| 5.0 * rng.uniform()).collect();
            let u = [&powers[..], &[20.0, 20.0, 1.0]].concat();
            predict_mean(&dyn_cfg, &mut x_dyn.x, &DVector::from_column_slice(&u));
            predict_mean(&const_cfg, &mut x_const.x, &SVector::from_column_slice(&u));
            if k % period as usize == 0 {
                let mut z = [
                    Some(x_const.x[0] + 0.3 * rng.normal()),
                    Some(x_const.x[4] - 0.2),
                ];
                match k % 70 {
                    0 => z[0] = None,
                    10 => z[1] = Some(f64::NAN),
                    20 => z[0] = Some(x_const.x[0] + 50.0),
                    _ => {}
                }
                let a = update_steady(&dyn_cfg, &dyn_gain, &mut x_dyn, &z.to_vec());
                let b = update_steady(&const_cfg, &const_gain, &mut x_const, &z);
                assert_eq!(a.verdicts, b.verdicts.to_vec(), "tick {k}");
                assert_eq!(a.suspect, b.suspect.to_vec(), "tick {k}");
                rejected += b.rejected();
            }
            let gap = (&x_dyn.x - DVector::from_column_slice(x_const.x.as_slice())).amax();
            assert!(gap < 1e-9, "tick {k}: {gap} K");
        }
        assert!(rejected >= 2, "the 50 K readings are rejected: {rejected}");
        assert!(x_const.x[0] > 21.0, "the powers heat: {}", x_const.x[0]);
    }
}

/// The steady Kalman gain of the 300-node motor with four thermocouples
/// (three end windings, a housing segment), solved at its own size
/// (300 states, `Dyn`) and timed: the exact discretisation of a 0.1 s
/// step, the doubling for corrections every second. Checked against the
/// time-varying filter, a different computation of the same covariance
/// (the predicts' propagation and the sequential Joseph updates): started
/// at the steady prior, one correction period of it returns to that
/// prior within 1e-9 relative (measured 1.4e-15); and a housing reading
/// one innovation sigma above the estimate warms the measured housing
/// segment by less than that and the yoke under it too.
#[test]
fn the_300_node_motors_steady_gain_at_its_own_size() {
    let file = ModelFile::parse(&motor_file(40.0), "motor-300.toml").unwrap();
    let model = Model::build(&file).unwrap();
    let net = &model.network;
    let names = &model.nodes;
    let node = |name: &str| names.iter().position(|n| n == name).unwrap();
    let sensors = [
        node("end_front_0"),
        node("end_back_12"),
        node("end_front_24"),
        node("housing_0"),
    ];
    let start = Instant::now();
    let d = zoh(&state_space_of(net, &vec![40.0; net.nodes()]), 0.1).unwrap();
    let discretise_s = start.elapsed().as_secs_f64();
    let m = filter_matrices(&d, &sensors);
    let cfg = run_time_filter(&m);
    let period = 10;
    let start = Instant::now();
    let gain = SteadyStateGain::solve(&cfg, period).unwrap();
    let solve_s = start.elapsed().as_secs_f64();
    eprintln!(
        "300-node motor: exact discretisation {discretise_s:.2} s, steady gain (300 states, 4 sensors) {solve_s:.2} s"
    );
    assert_eq!(gain.gain().shape(), (300, 4));

    let mut state = KalmanState::for_sensors(
        DVector::repeat(300, 40.0),
        gain.prior().clone(),
        Dyn(sensors.len()),
    );
    let z: Vec<Option<f64>> = sensors.iter().map(|&i| Some(state.x[i])).collect();
    let _ = update(&cfg, &mut state, &z);
    let u = DVector::from_element(cfg.g().ncols(), 0.0);
    for _ in 0..period {
        predict(&cfg, &mut state, &u);
    }
    let prior = gain.prior();
    let scale = prior.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    let off = (&state.cov - prior)
        .iter()
        .fold(0.0f64, |a, v| a.max(v.abs()));
    eprintln!(
        "one period of the time-varying filter from the steady prior: {:.1e} relative",
        off / scale
    );
    assert!(off <= 1e-9 * scale, "{off} of {scale}");

    let mut est = SteadyEstimate::for_sensors(DVector::repeat(300, 40.0), Dyn(sensors.len()));
    let housing = node("housing_0");
    let mut z: Vec<Option<f64>> = sensors.iter().map(|&i| Some(est.x[i])).collect();
    let sigma_k = gain.innovation_cov()[(3, 3)].sqrt();
    z[3] = Some(40.0 + sigma_k);
    let report = update_steady(&cfg, &gain, &mut est, &z);
    assert_eq!(report.fused(), 4);
    let moved = est.x[housing] - 40.0;
    assert!(moved > 0.0 && moved < sigma_k, "{moved} of {sigma_k}");
    assert!(est.x[node("yoke_0")] > 40.0, "{}", est.x[node("yoke_0")]);
}

/// The alarm, the current limiter and the upper bound over elements of a
/// run-time length (`Dyn`: `Vec`s) are the const-generic ones to the bit
/// (elementwise code, no matrix product): 5 elements over 20 000 ticks of
/// noisy temperatures that cross the warning and the alarm limit, with a
/// NaN temperature, a NaN ambient and predicted times to the limit, give
/// the same statuses, events, upper bounds and current limits; the
/// latched shutdown resets alike.
#[test]
fn the_protection_at_run_time_sizes_is_the_const_generic_one_to_the_bit() {
    use coil_thermal::protect::alarm::{AlarmBuilder, AlarmConfig, AlarmState};
    use coil_thermal::protect::derating::DeratingRule;
    use coil_thermal::protect::events::EventQueue;
    use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
    use coil_thermal::protect::margin::{UncertaintyMargin, UpperBoundBuilder};

    let rule = DeratingRule::hppa();
    let critical_c = [120.0, 130.0, 140.0, 150.0, 160.0];
    let alarm_fixed = AlarmBuilder::new(&rule, critical_c)
        .debounce_ticks(3)
        .build::<f64>()
        .unwrap();
    let alarm_dyn: AlarmConfig<f64, Dyn> = AlarmBuilder::<Dyn>::of(&rule, critical_c.to_vec())
        .debounce_ticks(3)
        .build()
        .unwrap();
    let hardware_a = [10.0, 12.0, 8.0, 9.0, 11.0];
    let limiter_fixed = LimiterConfig::<f64, _>::new(hardware_a, 15.0, 0.5).unwrap();
    let limiter_dyn = LimiterConfig::<f64, Dyn>::of(&hardware_a.to_vec(), 15.0, 0.5).unwrap();
    let margins = [0.05, 0.1, 0.0, 0.2, 0.05].map(|f| UncertaintyMargin::new(f, 0.5));
    let sigma_k = [0.3, 0.2, 0.1, 0.4, 0.0];
    let bound_fixed = UpperBoundBuilder::per_element(margins)
        .sigma(2.0, sigma_k)
        .build::<f64>()
        .unwrap();
    let bound_dyn = UpperBoundBuilder::<Dyn>::of(margins.to_vec())
        .sigma(2.0, sigma_k.to_vec())
        .build::<f64>()
        .unwrap();

    let mut state_fixed = AlarmState::new(&alarm_fixed);
    let mut state_dyn = AlarmState::new(&alarm_dyn);
    let (mut events_fixed, mut events_dyn) = (EventQueue::<64>::new(), EventQueue::<64>::new());
    let mut limits_fixed = [CoilLimit::default(); 5];
    let mut limits_dyn = vec![CoilLimit::default(); 5];
    let (mut upper_fixed, mut upper_dyn) = ([0.0; 5], vec![0.0; 5]);
    let mut rng = Rng::new(41);
    let (mut events, mut shutdowns, mut resets) = (0, 0, 0);
    for k in 0..20_000 {
        let phase = (k as f64 / 3000.0).sin();
        let mut temps: [f64; 5] =
            core::array::from_fn(|i| 60.0 + 45.0 * phase + 10.0 * i as f64 + rng.normal());
        let mut ambient_c = 25.0 + rng.normal();
        let mut time_s: [Option<f64>; 5] = core::array::from_fn(|i| {
            (temps[i] > 90.0 + 10.0 * i as f64).then(|| 100.0 * rng.uniform())
        });
        match k % 997 {
            3 => temps[2] = f64::NAN,
            4 => ambient_c = f64::NAN,
            5 => time_s[1] = Some(f64::NAN),
            _ => {}
        }
        bound_fixed.upper_c(&temps, ambient_c, &mut upper_fixed);
        bound_dyn.upper_c(&temps.to_vec(), ambient_c, &mut upper_dyn);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&upper_fixed), bits(&upper_dyn), "tick {k}");
        let a = state_fixed.tick(
            &alarm_fixed,
            &upper_fixed,
            ambient_c,
            &time_s,
            &mut events_fixed,
        );
        let b = state_dyn.tick(
            &alarm_dyn,
            &upper_dyn,
            ambient_c,
            &time_s.to_vec(),
            &mut events_dyn,
        );
        assert_eq!(a, b, "tick {k}");
        assert_eq!(
            state_fixed.elements().to_vec(),
            *state_dyn.elements(),
            "tick {k}"
        );
        while let Some(e) = events_fixed.pop() {
            assert_eq!(Some(e), events_dyn.pop(), "tick {k}");
            events += 1;
        }
        assert_eq!(events_dyn.pop(), None);
        let limits_c = alarm_fixed.alarm_limits_c(state_fixed.ambient_c());
        let limits_dyn_c = alarm_dyn.alarm_limits_c(state_dyn.ambient_c());
        assert_eq!(bits(&limits_c), bits(&limits_dyn_c), "tick {k}");
        let s = limiter_fixed.apply(&upper_fixed, &limits_c, ambient_c, &mut limits_fixed);
        let t = limiter_dyn.apply(&upper_dyn, &limits_c.to_vec(), ambient_c, &mut limits_dyn);
        assert_eq!(s, t, "tick {k}");
        assert_eq!(limits_fixed.to_vec(), limits_dyn, "tick {k}");
        if state_fixed.shutdown_latched() {
            shutdowns += 1;
            let a = state_fixed.reset(&alarm_fixed, &mut events_fixed);
            let b = state_dyn.reset(&alarm_dyn, &mut events_dyn);
            assert_eq!(a, b, "tick {k}");
            resets += usize::from(a.is_ok());
        }
    }
    assert!(
        events > 20 && shutdowns > 0 && resets > 0,
        "{events} {shutdowns} {resets}"
    );
}

/// The library's network observer at the 300-node motor's own size (no
/// size class, no padding): `RunTimeObserver::build_at_run_time` solves
/// its 300 + 72-state filter (one heat bias shared by the 72 windings: 4
/// sensors cannot tell 72 biases apart), and its ticks, fed the
/// independent RK4 integration's temperatures at four thermocouples once
/// a second, keep every one of the 300 nodes on that integration, within
/// 0.02 K after two minutes at 45 A (the copper some 30 K up), each upper
/// bound at or above its estimate.
#[test]
fn the_library_observer_runs_a_300_node_motor_at_its_own_size() {
    use coil_thermal::observer::network::{
        NetworkInputsOf, NetworkSettings, RunTimeBiasMode, RunTimeObserver, RunTimeSpec, SensorKind,
    };
    use coil_thermal::observer::TimedReading;
    use coil_thermal::protect::derating::DeratingRule;
    use coil_thermal::Reading;

    let file = ModelFile::parse(&motor_file(40.0), "motor-300.toml").unwrap();
    let model = Model::build(&file).unwrap();
    let net = &model.network;
    let names = &model.nodes;
    let node = |name: &str| names.iter().position(|n| n == name).unwrap();
    let sensors = vec![
        node("end_front_0"),
        node("end_back_12"),
        node("end_front_24"),
        node("housing_0"),
    ];
    let (n, m) = (net.nodes(), net.sources().len());
    let spec = RunTimeSpec {
        sensor_kinds: vec![SensorKind::Thermocouple; sensors.len()],
        sensor_nodes: sensors.clone(),
        critical_c: names
            .iter()
            .map(|name| name.starts_with("cu_").then_some(180.0))
            .collect(),
        incidence: None,
        hardware_limit_a: vec![100.0; m],
        rule: DeratingRule::omnimagnet(),
        settings: NetworkSettings {
            origin_c: COOLANT_C,
            correction_period_s: 1.0,
            ..NetworkSettings::DEFAULT
        },
        bias_sources: vec![true; m],
        bias_mode: RunTimeBiasMode::Auto,
    };
    let start = Instant::now();
    let observer = RunTimeObserver::build_at_run_time(net, &spec).unwrap();
    let build_s = start.elapsed().as_secs_f64();
    // The truth, once a second, in the file's node order.
    let seconds = 120;
    let mut truth: Vec<Vec<f64>> = Vec::new();
    let (order, _, _) = motor();
    let to_file: Vec<usize> = names
        .iter()
        .map(|name| order.iter().position(|(o, _)| o == name).unwrap())
        .collect();
    reference_trajectory(
        COOLANT_C,
        [COOLANT_C, AMBIENT_C],
        45.0,
        f64::from(seconds),
        ALPHA_PER_K,
        |t_s, temps| {
            if (t_s - t_s.round()).abs() < 1e-6 {
                truth.push(to_file.iter().map(|&k| temps[k]).collect());
            }
            true
        },
    );
    assert_eq!(truth.len(), seconds as usize);
    let boundary_c = vec![COOLANT_C as f32, AMBIENT_C as f32];
    let mut state = observer.with_warm_up(observer.state(&vec![COOLANT_C as f32; n], &boundary_c));
    let mut now_us = 0u32;
    let start = Instant::now();
    for second in 0..seconds as usize {
        for k in 0..1000 {
            // The reading of the second just ended, sampled at its end.
            let readings = sensors
                .iter()
                .map(|&i| {
                    (k == 0 && second > 0).then(|| TimedReading {
                        result: Ok(Reading::new(truth[second - 1][i] as f32)),
                        sampled_at_us: now_us,
                    })
                })
                .collect();
            let inputs = NetworkInputsOf::<Dyn, Dyn, Dyn> {
                currents_a: vec![45.0; m],
                boundary_c: boundary_c.clone(),
                readings,
                now_us,
                elapsed_us: 1000,
            };
            let out = observer.tick(&mut state, &inputs);
            assert!(out.flags.is_clean(), "{:?}", out.flags);
            now_us = now_us.wrapping_add(1000);
        }
    }
    let tick_us = start.elapsed().as_secs_f64() * 1e6 / f64::from(seconds * 1000);
    let out = state.outputs();
    let end = &truth[seconds as usize - 1];
    let worst_k = out
        .temps_c
        .iter()
        .zip(end)
        .map(|(e, t)| (f64::from(*e) - t).abs())
        .fold(0.0, f64::max);
    let hottest = end.iter().copied().fold(f64::MIN, f64::max);
    eprintln!(
        "library observer, 300 nodes + 72 sources, 4 sensors: build {build_s:.2} s, {tick_us:.1} us a tick (host), worst {worst_k:.2e} K off the RK4 after {seconds} s, hottest {hottest:.1} degC"
    );
    assert!(hottest > COOLANT_C + 20.0, "the copper heats: {hottest}");
    assert!(worst_k < 0.02, "worst {worst_k} K");
    assert!(out.upper_c.iter().zip(&out.temps_c).all(|(u, t)| u >= t));
}

/// `faults` runs its campaign on the 300-node motor's firmware observer at
/// the model's own size, with six thermocouples (the campaign once took at
/// most 15 nodes and 4 sensors, in padded size classes): at 70 A per phase
/// the end windings reach their derated limit and the clean run shuts
/// down (measured: at 136.3 s); an open circuit on any of the six is flagged at once and loses
/// no shutdown, and a corrupt snapshot is refused and the restart starts
/// latched. Timed (printed; 4.3 s wall in release on the development
/// machine).
#[test]
fn faults_runs_the_campaign_on_a_300_node_motor_at_its_own_size() {
    let tmp = TempDir::new().unwrap();
    let model = tmp.path().join("motor-300.toml");
    let sensors = [
        "end_front_0",
        "end_back_6",
        "end_front_12",
        "end_back_18",
        "end_front_24",
        "housing_0",
    ];
    let observer = format!(
        "\n[observer]\nsensors = [{}]\n",
        sensors.map(|s| format!("\"{s}\"")).join(", ")
    );
    std::fs::write(&model, motor_file(40.0) + &observer).unwrap();
    let start = Instant::now();
    let run = cargo_bin_cmd!("coil-thermal")
        .args(["faults", "--model"])
        .arg(&model)
        .args(["--current-a", "70", "--duration-s", "1200"])
        .args(["--onset-s", "60", "--classes", "open,corrupt-snapshot"])
        .arg("--json")
        .assert()
        .success();
    let wall_s = start.elapsed().as_secs_f64();
    let r: serde_json::Value = serde_json::from_slice(&run.get_output().stdout).unwrap();
    let clean_s = r["clean"]["shutdown_s"].as_f64();
    eprintln!(
        "faults on the 300-node motor, six thermocouples, 1200 s at 100 ms steps: {wall_s:.1} s wall; clean shutdown at {clean_s:?} s"
    );
    assert_eq!(r["sensors"], serde_json::json!([0, 1, 2, 3, 4, 5]));
    assert_eq!(r["clean"]["healthy_flagged"], 0);
    assert!(clean_s.is_some(), "the clean run shuts down: {r}");
    let cases = r["cases"].as_array().unwrap();
    // Six open circuits, one onset each, and the snapshot case(s).
    let open: Vec<_> = cases.iter().filter(|c| c["class"] == "open").collect();
    assert_eq!(open.len(), 6, "{r}");
    for c in cases {
        assert_eq!(c["lost_shutdown"], false, "{c}");
        assert_eq!(c["false_trip"], false, "{c}");
    }
    for c in open {
        assert!(c["flag_s"].as_f64().unwrap() <= 1.0, "{c}");
    }
    let snapshot: Vec<_> = cases
        .iter()
        .filter(|c| c["class"] == "corrupt-snapshot")
        .collect();
    assert!(!snapshot.is_empty(), "{r}");
    for c in snapshot {
        assert_eq!(c["snapshot"]["refused"], true, "{c}");
        assert_eq!(c["snapshot"]["starts_latched"], true, "{c}");
    }
}
