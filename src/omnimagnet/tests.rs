//! Tests of the Omnimagnet model against independent answers: an adaptive
//! Dormand-Prince integrator written here, table values typed from the paper
//! and from air-property tables, and the one-shot discretisation.
//!
//! Slow ones are meant for `cargo test --release`.

use super::presets::hottest_solenoid_c;
use super::*;
use nalgebra::SVector;

const AMBIENT_C: f64 = 22.0;
const PAPER: Omnimagnet = Omnimagnet::PAPER;

/// Dormand-Prince 5(4) with step control, on the model's `f`: a different
/// integrator (adaptive, error-controlled) from the model's fixed RK4.
fn dopri45(
    model: &Omnimagnet,
    temps: &mut [f64; NODES],
    currents: &[f64; SOLENOIDS],
    duration_s: f64,
    tol_k: f64,
) {
    const C: [f64; 7] = [0.0, 0.2, 0.3, 0.8, 8.0 / 9.0, 1.0, 1.0];
    const A: [[f64; 6]; 7] = [
        [0.0; 6],
        [0.2, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
        [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
        [
            19372.0 / 6561.0,
            -25360.0 / 2187.0,
            64448.0 / 6561.0,
            -212.0 / 729.0,
            0.0,
            0.0,
        ],
        [
            9017.0 / 3168.0,
            -355.0 / 33.0,
            46732.0 / 5247.0,
            49.0 / 176.0,
            -5103.0 / 18656.0,
            0.0,
        ],
        [
            35.0 / 384.0,
            0.0,
            500.0 / 1113.0,
            125.0 / 192.0,
            -2187.0 / 6784.0,
            11.0 / 84.0,
        ],
    ];
    const B5: [f64; 7] = [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
        0.0,
    ];
    const B4: [f64; 7] = [
        5179.0 / 57600.0,
        0.0,
        7571.0 / 16695.0,
        393.0 / 640.0,
        -92097.0 / 339200.0,
        187.0 / 2100.0,
        1.0 / 40.0,
    ];
    let _ = C;
    let mut t = 0.0;
    let mut h: f64 = 0.01;
    while t < duration_s {
        h = h.min(duration_s - t);
        let mut k = [[0.0; NODES]; 7];
        for s in 0..7 {
            let mut y = *temps;
            for (r, a) in A[s].iter().enumerate().take(s) {
                for i in 0..NODES {
                    y[i] += h * a * k[r][i];
                }
            }
            k[s] = model.derivative_k_per_s(&y, currents, AMBIENT_C);
        }
        let mut y5 = *temps;
        let mut err: f64 = 0.0;
        for i in 0..NODES {
            let (mut d5, mut d4) = (0.0, 0.0);
            for s in 0..7 {
                d5 += B5[s] * k[s][i];
                d4 += B4[s] * k[s][i];
            }
            y5[i] += h * d5;
            err = err.max((h * (d5 - d4)).abs());
        }
        if err <= tol_k {
            *temps = y5;
            t += h;
        }
        h *= (0.9 * (tol_k / err.max(1e-300)).powf(0.2)).clamp(0.2, 5.0);
    }
}

fn max_abs_diff(a: &[f64; NODES], b: &[f64; NODES]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn tables_are_valid_and_converted_once() {
    assert_eq!(
        Omnimagnet::new(PAPER_OMNIMAGNET, ConvectionParams::PAPER),
        Ok(PAPER)
    );
    let g = PAPER.geometry();
    assert!((g.elements[0].volume_m3 - 326e-6).abs() < 1e-15);
    assert!((g.elements[6].volume_m3 - 92.36e-6).abs() < 1e-15);
    assert!((g.elements[12].thickness_m[2] - 0.1367).abs() < 1e-15);
    // Contact 5-12: 3.6 cm^2 in y carries CF 0.60 (the printed "y").
    let c512 = g
        .contacts
        .iter()
        .find(|c| c.node == 4 && c.peer == Peer::Node(11))
        .unwrap();
    assert_eq!(c512.area_m2, [0.0, 3.6e-4, 0.0]);
    assert_eq!(c512.conduction_cf, [1.0, 0.6, 1.0]);
    // Eq. A1 and A2 at 20 degC, typed by hand: 316.21 + 0.3177*293.15 -
    // 3.5e-4*293.15^2 = 379.26, 420.75 - 0.068493*293.15 = 400.67.
    let cu = g.elements[0].material;
    assert!((cu.specific_heat_j_per_kg_k.at_k(293.15) - 379.263).abs() < 1e-2);
    assert!((cu.conductivity_w_per_m_k.at_k(293.15) - 400.672).abs() < 1e-2);
    assert_eq!(NODE_NAMES[13], "inside_air");
    assert_eq!(g.elements[g.inside_air_node].material, data::TRAPPED_AIR);

    let mut bad = PAPER_OMNIMAGNET;
    bad.elements[3].volume_m3 = 0.0;
    assert!(Omnimagnet::new(bad, ConvectionParams::PAPER).is_err());
    let mut bad = PAPER_OMNIMAGNET;
    bad.inside_air_node = 16;
    assert!(Omnimagnet::new(bad, ConvectionParams::PAPER).is_err());
    assert!(PAPER
        .with_convection(ConvectionParams::scaled(-1.0))
        .is_err());
}

#[test]
fn air_properties_match_tables() {
    // Incropera Table A.4, air at 300 K and 350 K.
    for (t, k, nu, pr) in [
        (300.0, 0.0263, 15.89e-6, 0.707),
        (350.0, 0.030, 20.92e-6, 0.700),
    ] {
        let a = AirProperties::at_k(t);
        assert!((a.conductivity_w_per_m_k / k - 1.0).abs() < 0.03, "{t}");
        assert!(
            (a.kinematic_viscosity_m2_per_s / nu - 1.0).abs() < 0.03,
            "{t}"
        );
        assert!((a.prandtl / pr - 1.0).abs() < 0.03, "{t}");
    }
}

#[test]
fn measurement_rows_pick_the_solenoid_nodes() {
    let h = measurement_matrix();
    let mut t = SVector::<f64, NODES>::from_fn(|i, _| i as f64 * 10.0);
    t[0] = 55.0;
    let y = h * t;
    assert_eq!(y.as_slice(), &[55.0, 55.0, 10.0, 10.0, 20.0, 20.0]);
}

/// Piecewise-linear run: re-linearise every `dt_s` at the current state and
/// take one exact ZOH step in the paper's form (U = I^2).
fn piecewise(literal: bool, cur: &[f64; 3], t: &mut [f64; NODES], dt_s: f64, steps: usize) {
    for _ in 0..steps {
        let ss = if literal {
            PAPER.literal_state_space(t, AMBIENT_C).unwrap()
        } else {
            PAPER.state_space(t, AMBIENT_C).unwrap()
        };
        let (e, phi) = crate::discretize::expm_with_integral(&ss.a, dt_s).unwrap();
        let x = SVector::<f64, NODES>::from_column_slice(t);
        let u = SVector::<f64, 3>::from_fn(|m, _| cur[m] * cur[m]);
        let nx = e * x + phi * (ss.b_current_squared * u + ss.g_boundary * AMBIENT_C);
        t.copy_from_slice(nx.as_slice());
    }
}

/// A hot, non-uniform state (mid-way through an all-three run).
fn hot_state() -> [f64; NODES] {
    let mut t = [AMBIENT_C; NODES];
    Preset::ALL_THREE.run(&PAPER, &mut t, AMBIENT_C, |t| t[0] >= 60.0);
    t
}

#[test]
fn nonlinear_rk4_matches_adaptive_dormand_prince() {
    // Heating from the ambient, then cooling from the hot state.
    for (start, cur, dur) in [
        ([AMBIENT_C; NODES], [3.8; 3], 1200.0),
        (hot_state(), [0.0; 3], 600.0),
        ([AMBIENT_C; NODES], [3.13, 0.0, 0.0], 600.0),
    ] {
        let mut rk4 = start;
        for _ in 0..(dur / 0.5) as usize {
            PAPER.step_rk4(&mut rk4, &cur, AMBIENT_C, 0.5);
        }
        let mut reference = start;
        dopri45(&PAPER, &mut reference, &cur, dur, 1e-9);
        let err = max_abs_diff(&rk4, &reference);
        println!("rk4(0.5 s) vs dopri45: {err:.2e} K over {dur} s");
        assert!(max_abs_diff(&rk4, &start) > 3.0, "must move");
        assert!(err < 1e-4, "{err}");
    }
}

#[test]
fn nonlinear_energy_account_closes_with_either_radiation_form() {
    // Ambient loss written out from the tables, apart from the model's
    // factorised conductances: Eq. 1's T^4 in kelvin, or Appendix B's
    // conductance sigma eps S T_0^3.
    let t = hot_state();
    let cur = [3.8, 1.0, 2.5];
    for form in [RadiationForm::StefanBoltzmann, RadiationForm::AppendixB] {
        let mut g = PAPER_OMNIMAGNET;
        g.radiation = form;
        let model = Omnimagnet::new(g, ConvectionParams::PAPER).unwrap();
        let mut out_w = 0.0;
        for c in g.contacts.iter().filter(|c| c.peer == Peer::Ambient) {
            let s = g.elements[c.node].convection.unwrap();
            out_w += model.h_w_per_m2_k(&s, t[c.node], AMBIENT_C)
                * c.area_m2.iter().sum::<f64>()
                * (t[c.node] - AMBIENT_C);
        }
        let mut radiated_w = 0.0;
        for r in g.radiators {
            let (tk, t0) = (t[r.node] + 273.15, AMBIENT_C + 273.15);
            radiated_w += 5.670374e-8
                * r.emissivity
                * r.area_m2
                * match form {
                    RadiationForm::StefanBoltzmann => tk.powi(4) - t0.powi(4),
                    RadiationForm::AppendixB => t0.powi(3) * (tk - t0),
                };
        }
        out_w += radiated_w;
        let joule_w: f64 = model.joule_powers_w(&t, &cur).iter().sum();
        let caps = model.capacities_j_per_k(&t);
        let dtdt = model.derivative_k_per_s(&t, &cur, AMBIENT_C);
        let stored_w: f64 = caps.iter().zip(dtdt).map(|(c, d)| c * d).sum();
        println!(
            "{form:?}: joule {joule_w:.3} W, stored {stored_w:.3} W, out {out_w:.3} W \
             (radiated {radiated_w:.3} W)"
        );
        assert!(out_w > 10.0 && radiated_w > 1.0);
        assert!((joule_w - stored_w - out_w).abs() < 1e-9 * joule_w);
    }
}

#[test]
fn linear_model_is_exact_at_its_operating_point() {
    for op in [[AMBIENT_C; NODES], hot_state()] {
        let net = PAPER.network(&op, AMBIENT_C).unwrap();
        let cur = [3.8, 0.5, 2.0];
        let lin = net.derivative_k_per_s(&op, &cur, &[AMBIENT_C]);
        let nl = PAPER.derivative_k_per_s(&op, &cur, AMBIENT_C);
        for i in 0..NODES {
            assert!((lin[i] - nl[i]).abs() < 1e-12 + 1e-10 * nl[i].abs(), "{i}");
        }
    }
}

#[test]
fn symmetric_conductances_conserve_energy_the_literal_reading_does_not() {
    let op = hot_state();
    let caps = PAPER.capacities_j_per_k(&op);
    let sym = PAPER.state_space(&op, AMBIENT_C).unwrap();
    let lit = PAPER.literal_state_space(&op, AMBIENT_C).unwrap();
    let to_ambient = PAPER.conductances(&op, AMBIENT_C).ambient_w_per_k;
    // sum_i C_i A_ij = -G_j0: zero for internal columns, the ambient
    // conductance for the others [W/K].
    let imbalance = |a: &nalgebra::SMatrix<f64, NODES, NODES>, j: usize| {
        (0..NODES).map(|i| caps[i] * a[(i, j)]).sum::<f64>() + to_ambient[j]
    };
    let (mut worst_sym, mut worst_lit, mut worst_node) = (0.0_f64, 0.0_f64, 0);
    for j in 0..NODES {
        worst_sym = worst_sym.max(imbalance(&sym.a, j).abs());
        if imbalance(&lit.a, j).abs() > worst_lit {
            worst_lit = imbalance(&lit.a, j).abs();
            worst_node = j;
        }
    }
    println!(
        "column imbalance: symmetric {worst_sym:.1e} W/K, literal {worst_lit:.0} W/K at {}",
        NODE_NAMES[worst_node]
    );
    assert!(worst_sym < 1e-9);
    assert!(worst_lit > 1000.0);
    // The literal generator leaks almost nothing to the ambient: its slowest
    // mode is numerically undamped, the symmetric one decays in hours.
    let slowest = |a: &nalgebra::SMatrix<f64, NODES, NODES>| {
        a.complex_eigenvalues()
            .iter()
            .map(|e| e.re.abs())
            .fold(f64::INFINITY, f64::min)
    };
    println!(
        "slowest mode: symmetric {:.2e} 1/s, literal {:.2e} 1/s",
        slowest(&sym.a),
        slowest(&lit.a)
    );
    assert!(slowest(&sym.a) > 2e-5);
    assert!(slowest(&lit.a) < 1e-9);
}

#[test]
fn literal_reading_has_no_steady_state_the_symmetric_one_has() {
    let cur = [3.8; 3];
    let (mut lit, mut sym) = ([AMBIENT_C; NODES], [AMBIENT_C; NODES]);
    let mut reference = [AMBIENT_C; NODES];
    let mut lit_t115 = None;
    for k in 1..=360 {
        piecewise(true, &cur, &mut lit, 10.0, 1);
        piecewise(false, &cur, &mut sym, 10.0, 1);
        if lit_t115.is_none() && lit[..3].iter().any(|v| *v >= EXPERIMENT_STOP_C) {
            lit_t115 = Some(k * 10);
        }
    }
    for _ in 0..7200 {
        PAPER.step_rk4(&mut reference, &cur, AMBIENT_C, 0.5);
    }
    // The symmetric network's steady state with R(T): fixed point of the
    // frozen-conductance network, checked by the nonlinear residual.
    let mut steady = sym;
    for _ in 0..40 {
        steady = PAPER
            .network(&steady, AMBIENT_C)
            .unwrap()
            .steady_state(&cur, &[AMBIENT_C])
            .unwrap();
    }
    let residual = PAPER.derivative_k_per_s(&steady, &cur, AMBIENT_C);
    println!(
        "all three at 3.8 A, 1 h: symmetric {:.1} degC (nonlinear {:.1}), literal {:.1} degC; \
         literal reaches 115 degC at {:?} s; symmetric steady state {:.1} degC",
        sym[0], reference[0], lit[0], lit_t115, steady[0]
    );
    // The piecewise-linear symmetric run is the nonlinear model.
    assert!((sym[0] - reference[0]).abs() < 0.5);
    assert!(residual.iter().all(|r| r.abs() < 1e-6), "{residual:?}");
    assert!(steady[0].is_finite() && steady[0] > reference[0]);
    // The literal one creates heat: far above the conserving model.
    assert!(lit[0] - sym[0] > 50.0);
}

/// Polls until the relinearizer is idle again; returns the slices used.
fn finish_cycle(r: &mut Relinearizer, temps: &[f64; NODES]) -> usize {
    let mut polls = 0;
    while r.is_working() {
        polls += 1;
        assert!(polls < 100, "unbounded");
        let p = r.poll(temps, AMBIENT_C);
        assert!(!matches!(p, RelinearizePoll::Failed(_)), "{p:?}");
    }
    r.slices_this_cycle()
}

#[test]
fn relinearizer_slices_are_bounded_and_bitwise_equal_to_one_shot() {
    let hot = hot_state();
    for dt in [1e-3, 0.5, 10.0] {
        let config = RelinearizeConfig {
            dt_s: dt,
            ..RelinearizeConfig::default()
        };
        let mut r = Relinearizer::new(PAPER, config, &[AMBIENT_C; NODES], AMBIENT_C).unwrap();
        assert_eq!(
            r.poll(&[AMBIENT_C; NODES], AMBIENT_C),
            RelinearizePoll::Idle
        );
        assert_eq!(r.poll(&hot, AMBIENT_C), RelinearizePoll::Started);
        let slices = finish_cycle(&mut r, &hot);
        // Expected squarings from ||A dt||_1 <= 2^s / 4, computed here.
        let a = PAPER.state_space(&hot, AMBIENT_C).unwrap().a * dt;
        let norm = (0..NODES)
            .map(|j| (0..NODES).map(|i| a[(i, j)].abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let s = if norm <= 0.25 {
            0
        } else {
            (norm / 0.25).log2().ceil() as usize
        };
        println!("dt {dt} s: {slices} slices ({s} squarings)");
        assert_eq!(slices, 11 + s);
        let one_shot = PAPER.linearize(&hot, AMBIENT_C, dt).unwrap();
        assert_eq!(r.active(), &one_shot);
        assert_eq!(r.poll(&hot, AMBIENT_C), RelinearizePoll::Idle);
    }
    let bytes = core::mem::size_of::<Relinearizer>();
    println!("Relinearizer: {bytes} bytes");
    assert!(bytes < 17 * 1024);
    // The ambient threshold triggers too; NaN never does; a failed build
    // keeps the old model.
    let mut r = Relinearizer::new(
        PAPER,
        RelinearizeConfig::default(),
        &[AMBIENT_C; NODES],
        AMBIENT_C,
    )
    .unwrap();
    assert!(r.needs_relinearization(&[AMBIENT_C; NODES], AMBIENT_C + 2.5));
    assert!(!r.needs_relinearization(&[f64::NAN; NODES], f64::NAN));
    let before = r.active().clone();
    let mut bad = [AMBIENT_C; NODES];
    bad[3] = f64::INFINITY;
    r.request(&bad, AMBIENT_C);
    assert!(matches!(
        r.poll(&bad, AMBIENT_C),
        RelinearizePoll::Failed(_)
    ));
    assert!(!r.is_working());
    assert_eq!(r.active(), &before);
    assert!(Relinearizer::new(
        PAPER,
        RelinearizeConfig {
            node_threshold_k: 0.0,
            ..RelinearizeConfig::default()
        },
        &[AMBIENT_C; NODES],
        AMBIENT_C
    )
    .is_err());
}

#[test]
fn linearised_error_grows_with_distance_and_relinearisation_bounds_it() {
    // All three at 3.8 A for 1 h from the ambient, dt = 0.5 s, paper's U = I^2
    // form. Reference: the nonlinear model (checked against Dormand-Prince).
    let dt = 0.5;
    let cur = [3.8; 3];
    let config = RelinearizeConfig {
        node_threshold_k: 2.0,
        ambient_threshold_k: 1.0,
        dt_s: dt,
    };
    let start = [AMBIENT_C; NODES];
    let once = PAPER.linearize(&start, AMBIENT_C, dt).unwrap();
    let mut relin = Relinearizer::new(PAPER, config, &start, AMBIENT_C).unwrap();
    let mut reference = start;
    let mut x_once = SVector::<f64, NODES>::from_column_slice(&start);
    let mut x_relin = x_once;
    let (mut err_once, mut err_relin, mut cycles) = ([0.0; 3], 0.0_f64, 0);
    for k in 1..=7200 {
        PAPER.step_rk4(&mut reference, &cur, AMBIENT_C, dt);
        x_once = once.step_current_squared(&x_once, &cur, AMBIENT_C);
        x_relin = relin
            .active()
            .step_current_squared(&x_relin, &cur, AMBIENT_C);
        // The relinearizer sees the linear model's own estimate (as it would
        // see a filter's), one slice per step.
        let mut est = [0.0; NODES];
        est.copy_from_slice(x_relin.as_slice());
        if relin.poll(&est, AMBIENT_C) == RelinearizePoll::Swapped {
            cycles += 1;
        }
        let e = |x: &SVector<f64, NODES>| {
            (0..NODES)
                .map(|i| (x[i] - reference[i]).abs())
                .fold(0.0, f64::max)
        };
        err_relin = err_relin.max(e(&x_relin));
        match k {
            120 => err_once[0] = e(&x_once),
            1200 => err_once[1] = e(&x_once),
            7200 => err_once[2] = e(&x_once),
            _ => {}
        }
    }
    println!(
        "linearised once at the ambient: max error {:.3} K at 1 min, {:.2} K at 10 min, \
         {:.2} K at 1 h; re-linearised ({cycles} swaps, 2 K threshold): max {:.3} K over 1 h",
        err_once[0], err_once[1], err_once[2], err_relin
    );
    assert!(err_once[0] < 0.05);
    assert!(err_once[0] < err_once[1] && err_once[1] < err_once[2]);
    assert!(err_once[2] > 5.0);
    assert!(err_relin < 0.5 && err_relin < err_once[2] / 10.0);
}

/// State after a full 2 h run (no stop), and the first time the hottest
/// solenoid reached 115 degC, if it did.
fn two_hours(model: &Omnimagnet, currents_a: [f64; 3]) -> ([f64; NODES], Option<f64>) {
    let mut t = [AMBIENT_C; NODES];
    let mut t115 = None;
    let dt = 0.5;
    for k in 0..(Preset::DURATION_S / dt) as usize {
        if t115.is_none() && hottest_solenoid_c(model, &t) >= EXPERIMENT_STOP_C {
            t115 = Some(k as f64 * dt);
        }
        model.step_rk4(&mut t, &currents_a, AMBIENT_C, dt);
    }
    (t, t115)
}

/// The paper's one printed transient (its cooling study, text beside its
/// Fig. 7): its fitted model, which matched the experiments within about
/// 4 % NRMSE, after all three solenoids at 3 A for 60 min, solenoids 1, 2, 3
/// \[degC\]. The ambient is not stated; the experiments' room was 22 degC.
const PAPER_3A_60MIN_C: [f64; SOLENOIDS] = [75.3, 71.1, 66.0];
/// The band on each rise above [`AMBIENT_C`] against the paper's: 5 % cold
/// to 10 % hot (a protection model may read hot more than cold).
const RISE_BAND: (f64, f64) = (-0.05, 0.10);

/// All three solenoids at 3 A for 60 min from the ambient (the model's own
/// RK4 at 0.5 s, as [`Preset`] runs it).
fn three_amps_for_an_hour(model: &Omnimagnet) -> [f64; NODES] {
    let mut t = [AMBIENT_C; NODES];
    for _ in 0..7200 {
        model.step_rk4(&mut t, &[3.0; SOLENOIDS], AMBIENT_C, 0.5);
    }
    t
}

/// Each solenoid's rise after 3 A for 60 min relative to the paper's, minus
/// one (`-0.05` = 5 % cold), and whether the figure holds: every rise in
/// [`RISE_BAND`] and the order inner > middle > outer.
pub(super) fn against_the_3a_figure(model: &Omnimagnet) -> ([f64; NODES], [f64; SOLENOIDS], bool) {
    let t = three_amps_for_an_hour(model);
    let rel: [f64; SOLENOIDS] =
        core::array::from_fn(|k| (t[k] - AMBIENT_C) / (PAPER_3A_60MIN_C[k] - AMBIENT_C) - 1.0);
    let in_band = rel.iter().all(|r| (RISE_BAND.0..=RISE_BAND.1).contains(r));
    (t, rel, in_band && t[0] > t[1] && t[1] > t[2])
}

#[test]
fn matches_the_papers_3_a_figure() {
    // Checked against what the code did not produce: the paper's printed
    // 75.3, 71.1, 66.0 degC. Eq. 1's radiation read the outer solenoids
    // 11 % and 21 % cold here; a second radiator on the outer surface
    // (solenoid 3 radiating as well as cover 3) reads solenoid 3 7.5 % cold
    // and fails this test, while it still passed the 3.8 A one.
    let (t, rel, holds) = against_the_3a_figure(&PAPER);
    println!(
        "all three at 3 A, 60 min: solenoids {:.1} {:.1} {:.1} degC (paper {:?}), rises \
         {:+.1} % {:+.1} % {:+.1} %; covers {:.1} {:.1} {:.1} degC",
        t[0],
        t[1],
        t[2],
        PAPER_3A_60MIN_C,
        100.0 * rel[0],
        100.0 * rel[1],
        100.0 * rel[2],
        t[8],
        t[10],
        t[12]
    );
    for (k, r) in rel.iter().enumerate() {
        assert!(
            (RISE_BAND.0..=RISE_BAND.1).contains(r),
            "solenoid {}: {:.1} degC, rise {:+.1} % against the paper's {} degC",
            k + 1,
            t[k],
            100.0 * r,
            PAPER_3A_60MIN_C[k]
        );
    }
    assert!(t[0] > t[1] && t[1] > t[2], "{:?}", &t[..3]);
    assert!(holds);
}

#[test]
fn reaches_what_the_papers_experiments_reached() {
    // The paper ran all three solenoids at 3.8 A from the ambient until the
    // hottest solenoid reached 115 degC (or 2 h); its fitted model matched
    // that run with an NRMSE of 2.1 %. So the device reached 115 degC within
    // 2 h, and a model that does not reads cold.
    let t_max = Preset::ALL_THREE
        .time_to_limit_s(&PAPER, AMBIENT_C, EXPERIMENT_STOP_C)
        .expect("all three at 3.8 A must reach 115 degC within 2 h");
    let mut at_stop = [AMBIENT_C; NODES];
    Preset::ALL_THREE.run(&PAPER, &mut at_stop, AMBIENT_C, |t| {
        hottest_solenoid_c(&PAPER, t) >= EXPERIMENT_STOP_C
    });
    println!(
        "all three at 3.8 A: 115 degC after {t_max:.0} s; solenoids {:.1} {:.1} {:.1}, \
         covers {:.1} {:.1} {:.1} degC",
        at_stop[0], at_stop[1], at_stop[2], at_stop[8], at_stop[10], at_stop[12]
    );
    assert!(t_max < Preset::DURATION_S);
    // The inner solenoid is the hottest (it sees no ambient), then the
    // middle; each cover stays below its solenoid (the cover carries the
    // 120 degC limit but no thermocouple).
    assert!(at_stop[0] > at_stop[1] && at_stop[1] > at_stop[2]);
    assert!(at_stop[8] < at_stop[0] && at_stop[10] < at_stop[1] && at_stop[12] < at_stop[2]);
    assert!(at_stop[8] < COVER_INSULATION_LIMIT_C);

    // The seven combinations of powered solenoids at 3.8 A (the paper's
    // experiment design), ranked by the hottest solenoid after 2 h: all
    // three is the worst case, every pair is worse than either of its
    // members alone, and alone the inner solenoid heats fastest, then the
    // middle one. Whenever the inner one is powered it is the hottest.
    let hottest = |mask: usize| {
        let cur = [0, 1, 2].map(|k| if mask & (1 << k) != 0 { 3.8 } else { 0.0 });
        let (t, _) = two_hours(&PAPER, cur);
        if mask & 1 != 0 {
            assert!(t[0] >= t[1] && t[0] >= t[2], "{mask:03b}: {:?}", &t[..3]);
        }
        hottest_solenoid_c(&PAPER, &t)
    };
    let end: Vec<f64> = (0..8)
        .map(|m| if m == 0 { AMBIENT_C } else { hottest(m) })
        .collect();
    println!(
        "hottest solenoid after 2 h at 3.8 A, by powered set (bit k = solenoid k+1): {end:.1?}"
    );
    for mask in 1..7 {
        assert!(end[7] > end[mask], "{mask:03b}");
    }
    for (pair, a, b) in [
        (0b011, 0b001, 0b010),
        (0b101, 0b001, 0b100),
        (0b110, 0b010, 0b100),
    ] {
        assert!(end[pair] > end[a] && end[pair] > end[b], "{pair:03b}");
    }
    assert!(end[0b001] > end[0b010] && end[0b010] > end[0b100]);
}

/// The module docs' sensitivity table: each reading the paper leaves open,
/// and each estimated quantity, changed alone from [`Omnimagnet::PAPER`];
/// `t_max` to 115 degC with all three at 3.8 A \[s\], the hottest solenoid
/// after 2 h without the stop \[degC\], and the three solenoids after 3 A
/// for 60 min \[degC\] with whether the paper's figure holds
/// ([`against_the_3a_figure`]). Keeps the docs the tested figures.
#[test]
fn sensitivity_table_of_the_module_docs() {
    fn leak<T>(v: Vec<T>) -> &'static [T] {
        Box::leak(v.into_boxed_slice())
    }
    let base = data::PAPER_OMNIMAGNET;
    let scaled = |f: &dyn Fn(&mut OmnimagnetGeometry)| {
        let mut g = base;
        f(&mut g);
        Omnimagnet::new(g, ConvectionParams::PAPER).unwrap()
    };
    let h = |factor: f64| {
        PAPER
            .with_convection(ConvectionParams::scaled(factor))
            .unwrap()
    };
    type Row = (&'static str, Omnimagnet, Option<f64>, f64, [f64; 3], bool);
    let rows: [Row; 16] = [
        (
            "this crate",
            PAPER,
            Some(3556.0),
            152.8,
            [78.1, 71.3, 64.9],
            true,
        ),
        (
            "Eq. 1 radiation (Stefan-Boltzmann)",
            scaled(&|g| g.radiation = RadiationForm::StefanBoltzmann),
            Some(4256.0),
            132.7,
            [73.5, 65.5, 56.8],
            false,
        ),
        (
            "half thicknesses",
            scaled(&|g| {
                g.elements
                    .iter_mut()
                    .for_each(|e| e.thickness_m = e.thickness_m.map(|d| d * 0.5))
            }),
            Some(4367.0),
            134.3,
            [72.9, 69.1, 65.5],
            true,
        ),
        (
            "Table 7 convection CFs",
            scaled(&|g| g.convection_cf = data::TABLE_7_CONVECTION_CF),
            None,
            95.9,
            [62.1, 54.2, 46.8],
            false,
        ),
        (
            "no Table 6 conduction CFs",
            scaled(&|g| {
                g.contacts = leak(
                    g.contacts
                        .iter()
                        .map(|c| Contact {
                            conduction_cf: [1.0; 3],
                            ..*c
                        })
                        .collect(),
                )
            }),
            Some(4912.0),
            132.5,
            [69.3, 65.2, 61.6],
            false,
        ),
        (
            "solenoid 3 radiates as well",
            scaled(&|g| {
                let mut r = g.radiators.to_vec();
                r.push(data::SOLENOID_3_RADIATOR);
                g.radiators = leak(r);
            }),
            Some(3674.0),
            148.3,
            [76.9, 69.9, 62.7],
            false,
        ),
        (
            "solenoid 3 radiates instead of cover 3",
            scaled(&|g| {
                let mut r: Vec<Radiator> = g
                    .radiators
                    .iter()
                    .filter(|r| r.node != 12)
                    .copied()
                    .collect();
                r.push(data::SOLENOID_3_RADIATOR);
                g.radiators = leak(r);
            }),
            Some(3558.0),
            152.7,
            [78.1, 71.3, 64.8],
            true,
        ),
        (
            "no radiation",
            scaled(&|g| g.radiators = &[]),
            Some(3412.0),
            159.5,
            [79.7, 73.4, 67.7],
            true,
        ),
        (
            "convection lengths x0.5",
            scaled(&|g| {
                g.elements
                    .iter_mut()
                    .filter_map(|e| e.convection.as_mut())
                    .for_each(|c| c.length_m *= 0.5)
            }),
            Some(4014.0),
            139.7,
            [74.6, 67.9, 61.6],
            false,
        ),
        (
            "convection lengths x2",
            scaled(&|g| {
                g.elements
                    .iter_mut()
                    .filter_map(|e| e.convection.as_mut())
                    .for_each(|c| c.length_m *= 2.0)
            }),
            Some(3381.0),
            161.3,
            [79.9, 73.4, 66.9],
            true,
        ),
        (
            "h x0.8",
            h(0.8),
            Some(3264.0),
            169.3,
            [81.3, 75.0, 68.8],
            false,
        ),
        (
            "h x1.2",
            h(1.2),
            Some(3937.0),
            140.2,
            [75.3, 68.2, 61.5],
            false,
        ),
        (
            "capacities x0.8",
            scaled(&|g| g.elements.iter_mut().for_each(|e| e.volume_m3 *= 0.8)),
            Some(2845.0),
            161.5,
            [85.5, 77.6, 69.9],
            false,
        ),
        (
            "capacities x1.2",
            scaled(&|g| g.elements.iter_mut().for_each(|e| e.volume_m3 *= 1.2)),
            Some(4268.0),
            144.3,
            [71.9, 66.2, 60.6],
            false,
        ),
        (
            "frame volumes read as totals (x0.5)",
            scaled(&|g| g.elements[3..7].iter_mut().for_each(|e| e.volume_m3 *= 0.5)),
            Some(3346.0),
            155.4,
            [80.2, 73.3, 66.4],
            true,
        ),
        (
            "R0 x0.9",
            scaled(&|g| g.solenoids.iter_mut().for_each(|s| s.r0_ohm *= 0.9)),
            Some(4352.0),
            137.6,
            [72.2, 66.3, 60.6],
            false,
        ),
    ];
    let mut wrong = Vec::new();
    for (name, model, doc_t_max, doc_end, doc_3a, doc_holds) in rows {
        let (end, t_max) = two_hours(&model, [3.8; 3]);
        let end = hottest_solenoid_c(&model, &end);
        let (t3, rel, holds) = against_the_3a_figure(&model);
        println!(
            "| {name} | {} | {end:.1} degC | {:.1} / {:.1} / {:.1} degC ({:+.1} / {:+.1} / {:+.1} %) | {} |",
            t_max.map_or("never".to_string(), |t| format!("{t:.0} s")),
            t3[0],
            t3[1],
            t3[2],
            100.0 * rel[0],
            100.0 * rel[1],
            100.0 * rel[2],
            if holds { "holds" } else { "fails" },
        );
        let t_max_ok = match (t_max, doc_t_max) {
            (Some(got), Some(doc)) => (got - doc).abs() <= 1.0,
            (None, None) => true,
            _ => false,
        };
        let three_ok = (0..3).all(|k| (t3[k] - doc_3a[k]).abs() < 0.06);
        if !t_max_ok || (end - doc_end).abs() >= 0.06 || !three_ok || holds != doc_holds {
            wrong.push(name);
        }
    }
    assert!(wrong.is_empty(), "rows off the docs: {wrong:?}");
}

#[test]
fn presets_are_the_papers_experiments() {
    assert_eq!(Preset::SOLENOID_1.currents_a(100.0), [3.13, 0.0, 0.0]);
    assert_eq!(Preset::SOLENOIDS_2_AND_3.currents_a(0.0), [0.0, 3.04, 3.04]);
    assert_eq!(Preset::ALL_THREE.currents_a(5.0), [3.8; 3]);
    assert_eq!(Preset::PASSIVE_COOLING.currents_a(5.0), [0.0; 3]);
    // Rotating dipole: constant magnitude, in the plane normal to (1,1,1),
    // mean square A^2/2 per solenoid.
    let (a, f) = (3.8, 5.0);
    let p = Preset::RotatingDipole {
        amplitude_a: a,
        frequency_hz: f,
    };
    let n = 1000;
    let mut mean_sq = [0.0; 3];
    for k in 0..n {
        let i = p.currents_a(k as f64 / (n as f64 * f));
        assert!(i.iter().sum::<f64>().abs() < 1e-12);
        let mag: f64 = i.iter().map(|v| v * v).sum();
        assert!((mag - 1.5 * a * a).abs() < 1e-9);
        for m in 0..3 {
            mean_sq[m] += i[m] * i[m] / n as f64;
        }
    }
    for m in mean_sq {
        assert!((m - a * a / 2.0).abs() < 1e-9);
    }
    // Passive cooling starts where all-three heating ended, and cools.
    let hot = Preset::PASSIVE_COOLING.initial_temps_c(&PAPER, AMBIENT_C);
    assert!(hot[0] >= EXPERIMENT_STOP_C);
    let mut t = hot;
    let mut last = t[0];
    Preset::PASSIVE_COOLING.run(&PAPER, &mut t, AMBIENT_C, |t| {
        let ok = t[0] <= last + 1e-12;
        last = t[0];
        !ok
    });
    // Two hours later the inner solenoid is within 13 K of the ambient
    // (12.1 K measured: the thermally isolated core, 2.2 kJ/K, cools
    // slowest, and Appendix B's radiation takes less than Eq. 1's).
    assert!(t[0] < AMBIENT_C + 13.0, "{}", t[0]);
    let names: Vec<_> = Preset::ALL.iter().map(|p| p.name()).collect();
    assert_eq!(
        names,
        [
            "solenoid_1",
            "solenoids_2_3",
            "all_three",
            "passive_cooling",
            "rotating_dipole"
        ]
    );
}
