//! Voltage-driven coils (issue 38, item 4), against references written here:
//! an `f64` RK4 of `C dT/dt = D V^2 / (R0 (1 + alpha (T - T_ref))) - (T -
//! T_a) / R_th` (never the library's right-hand side), its closed-form
//! steady state (the positive root of a quadratic), and a closed loop on a
//! two-node plant integrated the same way.

use super::*;
use crate::network::{Drive, Resistance};
use crate::sensors::Reading;

/// A 24 V solenoid valve's winding: 30 ohm at 20 degC, copper.
const R0_OHM: f64 = 30.0;
const ALPHA_PER_K: f64 = 0.00393;
const T_REF_C: f64 = 20.0;
/// Winding heat capacity \[J/K\] and its resistance to the ambient \[K/W\].
const C_J_PER_K: f64 = 60.0;
const RTH_K_PER_W: f64 = 4.0;
const AMBIENT_C: f64 = 25.0;

/// `R0 (1 + alpha (T - T_ref))` \[ohm\], written out (not `Resistance`).
fn r_ohm(t_c: f64) -> f64 {
    R0_OHM * (1.0 + ALPHA_PER_K * (t_c - T_REF_C))
}

/// `dT/dt` \[K/s\] of the one-node coil under duty `d` on `v` volts.
fn one_node_rate(t_c: f64, d: f64, v: f64) -> f64 {
    (d * v * v / r_ohm(t_c) - (t_c - AMBIENT_C) / RTH_K_PER_W) / C_J_PER_K
}

/// One classical RK4 step of `h` \[s\] of a scalar ODE.
fn rk4_scalar(t: f64, h: f64, f: impl Fn(f64) -> f64) -> f64 {
    let k1 = f(t);
    let k2 = f(t + h / 2.0 * k1);
    let k3 = f(t + h / 2.0 * k2);
    let k4 = f(t + h * k3);
    t + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
}

/// The steady state in closed form: `D V^2 R_th = R0 (1 + alpha (T -
/// T_ref)) (T - T_a)`, a quadratic `a T^2 + b T + c = 0` with `a = R0
/// alpha > 0`; its larger root is the physical one.
fn closed_form_steady_c(d: f64, v: f64) -> f64 {
    let k = 1.0 - ALPHA_PER_K * T_REF_C;
    let a = R0_OHM * ALPHA_PER_K;
    let b = R0_OHM * (k - ALPHA_PER_K * AMBIENT_C);
    let c = -R0_OHM * k * AMBIENT_C - d * v * v * RTH_K_PER_W;
    (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a)
}

fn one_node_coil() -> Network<1, 1, 1> {
    Network::new([C_J_PER_K])
        .and_then(|n| n.connect_boundary(0, 0, 1.0 / RTH_K_PER_W))
        .and_then(|n| n.voltage_source(0, 0, Resistance::with_alpha(R0_OHM, ALPHA_PER_K, T_REF_C)))
        .unwrap()
}

fn no_readings<const B: usize, const M: usize, const P: usize>(
    boundary_c: [f32; B],
    now_us: u32,
) -> NetworkInputs<B, M, P> {
    NetworkInputs {
        currents_a: [0.0; M],
        boundary_c,
        readings: [None; P],
        now_us,
        elapsed_us: 1000,
    }
}

#[test]
fn voltage_drive_network_matches_the_closed_form() {
    let net = one_node_coil();
    assert_eq!(net.source(0).unwrap().drive, Drive::Voltage);
    let (d, v) = (0.8f64, 24.0f64);
    let v_eff = (d * v * v).sqrt();
    // The right-hand side and the steady state (Newton) against the formula.
    for t in [-20.0, 25.0, 80.0, 150.0] {
        let lib = net.derivative_k_per_s(&[t], &[v_eff], &[AMBIENT_C])[0];
        assert!((lib - one_node_rate(t, d, v)).abs() < 1e-12, "{t}: {lib}");
    }
    let want = closed_form_steady_c(d, v);
    let got = net.steady_state(&[v_eff], &[AMBIENT_C]).unwrap()[0];
    std::println!("steady state: closed form {want:.9} degC, network {got:.9} degC");
    assert!((got - want).abs() < 1e-9, "{got} vs {want}");
    // The power falls as the coil heats: no runaway, whatever the voltage.
    let hot = net.steady_state(&[1e4], &[AMBIENT_C]).unwrap()[0];
    assert!(hot.is_finite() && hot > want);
    assert_eq!(
        crate::protect::runaway::runaway_current_a(&net, 0, &[v_eff]),
        Ok(None)
    );
}

/// Open loop for an hour at duty 0.8 on 24 V, then 0.3 on 27 V: the
/// observer's estimate against the RK4 at every second, and its end
/// against the closed form.
#[test]
fn voltage_drive_observer_follows_an_independent_rk4() {
    let net = one_node_coil();
    let obs: NetworkObserver<1, 1, 1, 2, 1> = NetworkObserverBuilder::new(&net, [0])
        .hardware_limit_a([1.0])
        .build()
        .unwrap();
    let mut state = obs.state(&[AMBIENT_C as f32], &[AMBIENT_C as f32]);
    let mut truth = AMBIENT_C;
    let mut worst = 0.0f64;
    let mut k = 0u32;
    for (d, v) in [(0.8f64, 24.0f64), (0.3, 27.0)] {
        for _ in 0..3600 {
            for _ in 0..1000 {
                let now_us = k.wrapping_mul(1000);
                let drive = [Some(VoltageDrive::pwm(d as f32, v as f32))];
                let (_, flags) = obs.tick_voltage(&mut state, &no_readings([25.0], now_us), &drive);
                assert!(flags.is_clean());
                k += 1;
            }
            for _ in 0..10 {
                truth = rk4_scalar(truth, 0.1, |t| one_node_rate(t, d, v));
            }
            let est = f64::from(obs.temps_c(&state)[0]);
            worst = worst.max((est - truth).abs());
        }
        let steady = closed_form_steady_c(d, v);
        let est = f64::from(obs.temps_c(&state)[0]);
        std::println!(
            "D = {d}, V = {v}: closed form {steady:.4} degC, RK4 {truth:.4} degC, observer {est:.4} degC"
        );
        assert!((truth - steady).abs() < 1e-3, "RK4 {truth} vs {steady}");
        assert!((est - steady).abs() < 0.01, "observer {est} vs {steady}");
    }
    std::println!("worst observer - RK4 over 2 h: {worst:.3e} K");
    assert!(worst < 0.01, "observer off the RK4 by {worst} K");
}

/// Winding (0, 40 J/K) in a housing (1, 300 J/K) with a thermocouple, to
/// the ambient; the valve is asked for full duty on a supply that rises
/// from 24 V to 30 V, which would take the winding far beyond its 110 degC.
#[test]
fn voltage_drive_duty_held_at_the_limit_keeps_the_coil_under_its_alarm_limit() {
    const G_WH: f64 = 0.5;
    const G_HA: f64 = 0.3;
    const C_W: f64 = 40.0;
    const C_H: f64 = 300.0;
    let net: Network<2, 1, 1> = Network::new([C_W, C_H])
        .and_then(|n| n.connect(0, 1, G_WH))
        .and_then(|n| n.connect_boundary(1, 0, G_HA))
        .and_then(|n| n.voltage_source(0, 0, Resistance::with_alpha(R0_OHM, ALPHA_PER_K, T_REF_C)))
        .unwrap();
    let obs: NetworkObserver<2, 1, 1, 3, 1> = NetworkObserverBuilder::new(&net, [1])
        .critical_c([Some(110.0), None])
        // The most the valve draws: 30 V on its resistance at 0 degC.
        .hardware_limit_a([30.0 / r_ohm(0.0)])
        .build()
        .unwrap();
    let alarm_c = f64::from(obs.alarm().alarm_limits_c(AMBIENT_C as f32)[0]);
    let open_loop = {
        // Full duty on 30 V, held: the winding's steady state.
        let v_eff = 30.0;
        net.steady_state(&[v_eff], &[AMBIENT_C]).unwrap()[0]
    };
    let mut state = obs.state(&[AMBIENT_C as f32; 2], &[AMBIENT_C as f32]);
    let (mut tw, mut th) = (AMBIENT_C, AMBIENT_C);
    let mut hottest = f64::NEG_INFINITY;
    let mut min_duty = 1.0f32;
    let mut duty = 1.0f32;
    for k in 0..(3 * 3_600_000u32) {
        let now_us = k.wrapping_mul(1000);
        let supply = if k < 3_600_000 { 24.0f32 } else { 30.0 };
        let mut inp = no_readings([AMBIENT_C as f32], now_us);
        if k % 500 == 0 {
            inp.readings = [Some(TimedReading {
                result: Ok(Reading::new(th as f32)),
                sampled_at_us: now_us,
            })];
        }
        let drive = [Some(VoltageDrive::pwm(duty, supply))];
        obs.tick_voltage(&mut state, &inp, &drive);
        // The controller asks for full duty; the drive holds it to the limit.
        duty = obs.drive_limit(&state, 0, supply).duty.min(1.0);
        min_duty = min_duty.min(duty);
        // The plant: its own two-node right-hand side, RK4 at 1 ms.
        let d = f64::from(duty_applied(duty));
        let v = f64::from(supply);
        let f = |w: f64, h: f64| {
            (
                (d * v * v / r_ohm(w) - G_WH * (w - h)) / C_W,
                (G_WH * (w - h) - G_HA * (h - AMBIENT_C)) / C_H,
            )
        };
        let dt = 1e-3;
        let k1 = f(tw, th);
        let k2 = f(tw + dt / 2.0 * k1.0, th + dt / 2.0 * k1.1);
        let k3 = f(tw + dt / 2.0 * k2.0, th + dt / 2.0 * k2.1);
        let k4 = f(tw + dt * k3.0, th + dt * k3.1);
        tw += dt / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        th += dt / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        hottest = hottest.max(tw);
    }
    std::println!(
        "full duty asked on 24 V then 30 V: open loop {open_loop:.1} degC; closed loop hottest {hottest:.2} degC, alarm limit {alarm_c:.2} degC, duty down to {min_duty:.3}, end {tw:.2} degC"
    );
    assert!(open_loop > alarm_c + 20.0, "the test must need the limit");
    assert!(min_duty < 0.9, "the limit must act: {min_duty}");
    assert!(hottest < alarm_c, "{hottest} degC over {alarm_c} degC");
    // Not throttled to nothing: the coil settles within 10 K of its limit.
    assert!(tw > alarm_c - 10.0, "{tw} degC");
}

/// The duty the plant sees: the one applied this tick (the drive applies
/// the published limit from the next PWM period on).
fn duty_applied(duty: f32) -> f32 {
    duty
}

#[test]
fn the_duty_limit_is_the_current_limit_in_the_drives_unit() {
    let r = Resistance::with_alpha(R0_OHM, ALPHA_PER_K, T_REF_C).to_scalar::<f32>();
    let r_ohm = |temp_c: f32| r.r_at_0c_ohm + r.slope_ohm_per_k * temp_c;
    let limit = CoilLimit {
        current_a: 0.5,
        weight: 1.0,
        invalid: false,
    };
    // 0.5 A through 30 ohm (20 degC) on 24 V: (15 / 24)^2.
    let l = drive_limit(&limit, r_ohm(20.0), 24.0);
    assert!((l.duty - (15.0f32 / 24.0).powi(2)).abs() < 1e-6, "{l:?}");
    assert!((l.voltage_v - 15.0).abs() < 1e-5 && l.flags.is_clean());
    // More than the supply gives: full on, never above 1.
    assert_eq!(drive_limit(&limit, r_ohm(20.0), 10.0).duty, 1.0);
    // A missing supply: duty zero, flagged; the voltage limit stays.
    for supply in [f32::NAN, 0.0, -24.0, f32::INFINITY] {
        let l = drive_limit(&limit, r_ohm(20.0), supply);
        assert_eq!(l.duty, 0.0, "{supply}");
        assert!(l.flags.contains(DriveFlags::SUPPLY_INVALID));
        assert!((l.voltage_v - 15.0).abs() < 1e-5);
    }
    // An invalid current limit or estimate: zero, never NaN.
    let bad = CoilLimit {
        invalid: true,
        ..limit
    };
    assert_eq!(drive_limit(&bad, r_ohm(20.0), 24.0).duty, 0.0);
    let l = drive_limit(&limit, r_ohm(f32::NAN), 24.0);
    assert_eq!((l.duty, l.voltage_v), (0.0, 0.0));
    assert!(l.flags.contains(DriveFlags::RESISTANCE_INVALID));
}

#[test]
fn a_falling_or_non_positive_resistance_is_refused_at_build() {
    let base = || Network::<1, 1, 1>::new([10.0]).unwrap();
    let falling = Resistance::linear_fit(-0.002, 5.69);
    assert_eq!(
        base().joule_source(0, 0, falling).err(),
        Some(BuildError::FallingResistance { input: 0 })
    );
    assert_eq!(
        base().voltage_source(0, 0, falling).err(),
        Some(BuildError::FallingResistance { input: 0 })
    );
    for r0 in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert_eq!(
            base()
                .joule_source(0, 0, Resistance::linear_fit(0.01, r0))
                .err(),
            Some(BuildError::InvalidResistance { input: 0 }),
            "{r0}"
        );
    }
    // A constant (slope 0) is a winding; the explicit stepper takes
    // currents only and refuses a voltage drive by name.
    assert!(base().joule_source(0, 0, Resistance::constant(2.0)).is_ok());
    let volt = base()
        .connect_boundary(0, 0, 0.1)
        .and_then(|n| n.voltage_source(0, 0, Resistance::constant(2.0)))
        .unwrap();
    assert_eq!(
        crate::ExplicitStepper::<f32, 1, 1, 1>::new(&volt, 1e-3, Default::default()).err(),
        Some(BuildError::InvalidParameter {
            name: "voltage_source"
        })
    );
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
    /// NaN, infinite and extreme duties and supplies: nothing panics, the
    /// estimate stays finite, every bad drive is flagged (and its current
    /// held), and the duty limit is always a number in [0, 1].
    #[test]
    fn voltage_drive_any_duty_and_supply_is_flagged_never_a_panic(
        ticks in proptest::collection::vec(
            (proptest::num::f32::ANY, proptest::num::f32::ANY, 0u32..20_000),
            1..200,
        )
    ) {
        let net = one_node_coil();
        let obs: NetworkObserver<1, 1, 1, 2, 1> = NetworkObserverBuilder::new(&net, [0])
            .critical_c([Some(130.0)])
            .hardware_limit_a([1.0])
            .build()
            .unwrap();
        let mut state = obs.state(&[25.0], &[25.0]);
        let mut now = 0u32;
        for (duty, supply, dt) in ticks {
            now = now.wrapping_add(dt);
            let mut inp = no_readings([25.0], now);
            inp.elapsed_us = dt;
            let (out, flags) = obs.tick_voltage(&mut state, &inp, &[Some(VoltageDrive::pwm(duty, supply))]);
            proptest::prop_assert!(out.temps_c.iter().all(|t| t.is_finite()));
            let bad_duty = !(duty.is_finite() && duty >= 0.0);
            let bad_supply = !(supply.is_finite() && supply > 0.0);
            proptest::prop_assert_eq!(flags.contains(DriveFlags::DUTY_INVALID), bad_duty);
            proptest::prop_assert_eq!(flags.contains(DriveFlags::SUPPLY_INVALID), bad_supply);
            proptest::prop_assert_eq!(flags.contains(DriveFlags::DUTY_CLAMPED), !bad_duty && duty > 1.0);
            if bad_duty || bad_supply {
                proptest::prop_assert!(out.flags.contains(InputFlags::CURRENT_NOT_FINITE));
            }
            let limit = obs.drive_limit(&state, 0, supply);
            proptest::prop_assert!((0.0..=1.0).contains(&limit.duty), "{:?}", limit);
            proptest::prop_assert!(limit.voltage_v.is_finite() && limit.voltage_v >= 0.0);
            if bad_supply {
                proptest::prop_assert_eq!(limit.duty, 0.0);
                proptest::prop_assert!(limit.flags.contains(DriveFlags::SUPPLY_INVALID));
            }
        }
    }
}

/// The published duty limit is the current limit through `R` at the
/// published *estimate* of the winding (not at its upper bound, which
/// would give a larger duty), on the measured supply.
#[test]
fn voltage_drive_limit_takes_r_at_the_published_estimate() {
    let net = one_node_coil();
    let obs: NetworkObserver<1, 1, 1, 2, 1> = NetworkObserverBuilder::new(&net, [0])
        .critical_c([Some(90.0)])
        .hardware_limit_a([1.0])
        .build()
        .unwrap();
    let mut state = obs.state(&[AMBIENT_C as f32], &[AMBIENT_C as f32]);
    let mut duty = 1.0f32;
    for k in 0..1_200_000u32 {
        let drive = [Some(VoltageDrive::pwm(duty, 24.0))];
        obs.tick_voltage(
            &mut state,
            &no_readings([25.0], k.wrapping_mul(1000)),
            &drive,
        );
        // Held to the published limit: no shutdown, the taper acting.
        duty = obs.drive_limit(&state, 0, 24.0).duty;
    }
    let out = state.outputs();
    let (t, lim) = (
        f64::from(out.temps_c[0]),
        f64::from(out.limits[0].current_a),
    );
    // On a 60 V supply, so that the duty is not clipped at 1.
    let want = (lim * r_ohm(t) / 60.0).powi(2).min(1.0);
    let got = f64::from(obs.drive_limit(&state, 0, 60.0).duty);
    std::println!(
        "estimate {t:.3} degC, current limit {lim:.4} A: duty limit {got:.5} (formula {want:.5})"
    );
    assert!(
        lim > 0.05 && lim < 0.99 && want < 0.9,
        "the limiter must act: {lim}, {want}"
    );
    assert!(
        (got - want).abs() < 1e-4 * want.max(1e-3),
        "{got} vs {want}"
    );
}
