//! A model file at its own size (issue 37, item 4): the library's
//! [`RunTimeStepper`] (the `alloc` twin of the MCU's `ExplicitStepper`) is
//! the const-generic stepper to the bit, and `simulate`, `calibrate` and an
//! open-loop `replay` run a 300-node, 72-source motor network through it
//! (no size class, no cap) against an independent integration of the same
//! equations.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use assert_cmd::cargo::cargo_bin_cmd;
use coil_thermal::network::{RunTimeStepper, SizeMismatch};
use coil_thermal::{ExplicitStepper, InputFlags, InputLimits, Network, NetworkState, Resistance};
use coil_thermal_host::dynamic_network::DynNetwork;
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
    net.to_network().unwrap()
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

/// Slots of the 300-node motor.
const SLOTS: usize = 36;

/// A conductance of the motor network: its two ends (node names, or a
/// boundary's) \[W/K\].
struct Link {
    a: String,
    b: String,
    g_w_per_k: f64,
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
            "\n[[source]]\nname = \"copper_{k}\"\nnode = \"{node}\"\ninput = \"i{}\"\nr0_ohm = {R20_OHM:?}\nalpha_per_k = {ALPHA_PER_K:?}\nt_ref_c = 20.0\n",
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
    let (nodes, links, sources) = motor();
    let index = |name: &str| nodes.iter().position(|(n, _)| n == name);
    let boundary = |name: &str| match name {
        "coolant" => COOLANT_C,
        "ambient" => AMBIENT_C,
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
            out[n] += R20_OHM * (1.0 + ALPHA_PER_K * (t[n] - 20.0)) * current_a * current_a;
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
    for _ in 0..(duration_s / h).round() as usize {
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

/// Every row of a CSV after its header.
fn rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

/// `replay` of a model larger than the firmware's observer is solved for
/// on the host runs it open loop at its own size on the same stepper, and
/// says so (no flag of the filter taken, no time to limit claimed): over a
/// 30-min recording of the 300-node motor it gives `simulate`'s
/// temperatures row for row, to the CSV's 6 decimals.
#[test]
fn replay_runs_a_300_node_motor_open_loop_at_its_own_size() {
    let tmp = TempDir::new().unwrap();
    let model = tmp.path().join("motor-300.toml");
    std::fs::write(&model, motor_file(40.0)).unwrap();
    let recording = tmp.path().join("bench.csv");
    cargo_bin_cmd!("coil-thermal")
        .args(["simulate", "--model"])
        .arg(&model)
        .args(["--current-a", "45", "--duration-s", "1800", "--dt-s", "10"])
        .args(["--with-inputs", "--out"])
        .arg(&recording)
        .assert()
        .success();
    let out = tmp.path().join("replay.csv");
    let start = Instant::now();
    let run = cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(&model)
        .arg("--trace")
        .arg(&recording)
        .arg("--out")
        .arg(&out)
        .assert()
        .success();
    let replay_s = start.elapsed().as_secs_f64();
    let text = String::from_utf8_lossy(&run.get_output().stdout).into_owned();
    assert!(
        text.contains("open loop, the firmware's observer: the model has 300 nodes and 72 sources"),
        "{text}"
    );
    assert!(text.contains("time to limit: not computed"), "{text}");
    // The filter's flags do not apply, and are refused by name.
    cargo_bin_cmd!("coil-thermal")
        .args(["replay", "--model"])
        .arg(&model)
        .arg("--trace")
        .arg(&recording)
        .args(["--measurement-noise-k", "0.5"])
        .assert()
        .failure()
        .stderr(predicates::str::contains(
            "--measurement-noise-k sets the firmware's NetworkObserver",
        ));
    let simulated = rows(&recording);
    let replayed = rows(&out);
    let (sim_header, _) = last_row(&recording);
    let (replay_header, _) = last_row(&out);
    assert_eq!(replayed.len(), simulated.len());
    let mut worst = 0.0f64;
    for (name, _) in motor().0 {
        let s = sim_header.iter().position(|h| *h == name).unwrap();
        let r = replay_header.iter().position(|h| *h == name).unwrap();
        for (sim, rep) in simulated.iter().zip(&replayed) {
            worst = worst.max((sim[s] - rep[r]).abs());
        }
    }
    eprintln!(
        "replay, 300 nodes x 1800 s: {replay_s:.2} s wall; worst {worst:.1e} K from simulate"
    );
    assert!(worst <= 1.5e-6, "{worst}");
}
