//! Downtime cooling: `restore_after` given the power-off time decays the
//! saved state to the exact cooled state, never below it and at most what
//! README promises above it (the grid 2e-3 K, a network 1e-2 K, the
//! Omnimagnet 0.42 K), for every observer, against independent references (an `f64`
//! RK4 integration of the zero-current network or of the nonlinear plant,
//! fine steps; the closed form for one node).

use coil_thermal::grid::GridConfig;
use coil_thermal::observer::network::{NetworkObserver, NetworkObserverBuilder};
use coil_thermal::observer::snapshot::snapshot_len;
use coil_thermal::observer::{GridInputs, GridObserver};
use coil_thermal::protect::alarm::AlarmBuilder;
use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::limiter::LimiterConfig;
use coil_thermal::{GridParams, Network, Resistance};

/// The off times every observer is held to \[s\] (0, 1 s, 10 min, 2 h, 10 h
/// and some between).
const OFF_TIMES_S: [f64; 12] = [
    0.0, 1.0, 10.0, 60.0, 300.0, 600.0, 1800.0, 3600.0, 7200.0, 14_400.0, 21_600.0, 36_000.0,
];

/// A denser sweep, 1 s to 10 h, for the Omnimagnet's nonlinear cooling,
/// whose sign is measured rather than proven.
const DENSE_OFF_TIMES_S: [f64; 25] = [
    0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 45.0, 60.0, 120.0, 240.0, 300.0, 450.0, 600.0, 900.0, 1200.0,
    1800.0, 2700.0, 3600.0, 5400.0, 7200.0, 10_800.0, 14_400.0, 21_600.0, 28_800.0, 36_000.0,
];

/// How far above the exact cooled state each observer may restore \[K\]:
/// what README promises, per observer (measured: grid 1.01e-3, network
/// 4.2e-3, Omnimagnet model 0.415 and observer 0.306 K; the Omnimagnet's
/// nonlinear plant cools faster than its linearised model). The model's
/// worst starts are past the cover's 120 degC (2 h at 3.8 A, 152.8 degC:
/// 0.415 K; 4.5 A for 50 min: 0.400 K); from the paper's run (115 degC)
/// 0.305 K, 0.373 K with the ambient changed to 5 or 35 degC while off.
/// The observer is tested from the paper's run and 20 min at 3.8 A.
const GRID_MAX_ABOVE_K: f64 = 2e-3;
const NETWORK_MAX_ABOVE_K: f64 = 1e-2;
const OMNI_MODEL_MAX_ABOVE_K: f64 = 0.42;
const OMNI_OBSERVER_MAX_ABOVE_K: f64 = 0.32;

/// Largest excess over the reference and whether any node fell below it.
#[derive(Debug, Default, Clone, Copy)]
struct Excess {
    above_k: f64,
    below_k: f64,
}

impl Excess {
    fn add(&mut self, got: f64, want: f64) {
        self.above_k = self.above_k.max(got - want);
        self.below_k = self.below_k.max(want - got);
    }
    /// Never below; at most `max_above_k` above (each observer's bound:
    /// what it achieves with a small margin, not one loose bound for all).
    fn check(&self, what: &str, max_above_k: f64) {
        eprintln!("{what}: {:.2e} K above", self.above_k);
        assert!(self.below_k <= 0.0, "{what}: {:.2e} K below", self.below_k);
        assert!(
            self.above_k <= max_above_k,
            "{what}: {:.3e} K above (at most {max_above_k:e})",
            self.above_k
        );
    }
}

/// Classical RK4 of `x' = A x` over `t_s` in steps of at most `dt_s`.
fn rk4_linear<const N: usize>(a: &[[f64; N]; N], x: &mut [f64; N], t_s: f64, dt_s: f64) {
    if t_s <= 0.0 {
        return;
    }
    let steps = (t_s / dt_s).ceil() as usize;
    let h = t_s / steps as f64;
    let f = |x: &[f64; N]| -> [f64; N] {
        core::array::from_fn(|i| (0..N).map(|j| a[i][j] * x[j]).sum())
    };
    let add = |x: &[f64; N], k: &[f64; N], s: f64| -> [f64; N] {
        core::array::from_fn(|i| x[i] + s * k[i])
    };
    for _ in 0..steps {
        let k1 = f(x);
        let k2 = f(&add(x, &k1, 0.5 * h));
        let k3 = f(&add(x, &k2, 0.5 * h));
        let k4 = f(&add(x, &k3, h));
        for i in 0..N {
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
}

// ---------------------------------------------------------------- grid --

type Grid = GridObserver<f32, 7, 12, 84>;

fn grid() -> Grid {
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 84])
        .build()
        .unwrap();
    let limiter = LimiterConfig::new([3.0; 84], 10.0, 0.0).unwrap();
    let config = GridConfig {
        ticks_per_update: 10,
        ..GridConfig::hppa(GridParams::FDM_FITTED)
    };
    Grid::new(&config, alarm, limiter, 4).unwrap()
}

/// A heating run on the observer itself: a hot band of coils at 2.5 A and
/// the rest at 0.8 A for `heat_s`, 20 degC coolant and ambient; returns the
/// snapshot.
fn grid_heated_snapshot(grid: &Grid, heat_s: u32, latched: bool) -> Vec<u8> {
    let mut currents = [[0.8f32; 12]; 7];
    for row in currents.iter_mut().take(4).skip(2) {
        for c in row.iter_mut().take(7).skip(3) {
            *c = 2.5;
        }
    }
    let mut state = if latched {
        grid.conservative_state(20.0)
    } else {
        grid.state(20.0)
    };
    for _ in 0..heat_s * 1000 {
        grid.tick(
            &mut state,
            &GridInputs {
                currents_a: &currents,
                coolant_c: 20.0,
                ambient_c: 20.0,
                elapsed_us: 1000,
            },
        );
    }
    let mut buf = vec![0u8; snapshot_len(84)];
    grid.save(&state, 1_000, &mut buf).unwrap();
    buf
}

#[test]
fn grid_downtime_cooling_is_within_2_mk_above_the_exact_and_never_below() {
    let grid = grid();
    let network = grid.grid().to_network::<84>().unwrap();
    let ss = network.state_space(&[20.0; 84]);
    let a: [[f64; 84]; 84] = core::array::from_fn(|i| core::array::from_fn(|j| ss.a[(i, j)]));
    let ambient = 20.0;
    let mut table = Vec::new();
    for heat_s in [120u32, 360] {
        let snapshot = grid_heated_snapshot(&grid, heat_s, false);
        let saved = grid.restore(&snapshot, 1_000, 100_000, ambient).unwrap();
        let saved_c: [f64; 84] =
            core::array::from_fn(|i| saved.outputs().temps_c[i / 12][i % 12] as f64);
        let hottest = saved_c.iter().cloned().fold(0.0, f64::max);
        assert!(hottest > 60.0, "a realistic hot start: {hottest}");
        let mut x: [f64; 84] = core::array::from_fn(|i| saved_c[i] - ambient);
        let mut t = 0.0;
        for off_s in OFF_TIMES_S {
            rk4_linear(&a, &mut x, off_s - t, 1.0);
            t = off_s;
            let state = grid
                .restore_after(
                    &snapshot,
                    1_000 + 36_000,
                    100_000,
                    ambient,
                    Some(off_s as f32),
                )
                .unwrap();
            let got = state.outputs().temps_c;
            let mut excess = Excess::default();
            for i in 0..84 {
                excess.add(got[i / 12][i % 12] as f64, ambient + x[i]);
            }
            if off_s == 0.0 {
                assert_eq!(
                    got,
                    saved.outputs().temps_c,
                    "off time 0: the saved state to the bit"
                );
            } else {
                excess.check(
                    &format!("grid, heated {heat_s} s, off {off_s} s"),
                    GRID_MAX_ABOVE_K,
                );
            }
            table.push((
                heat_s,
                off_s,
                excess.above_k,
                hottest,
                x.iter().cloned().fold(0.0, f64::max),
            ));
        }
    }
    for (heat, off, above, hottest, left) in &table {
        println!("grid heated {heat:>4} s (hottest {hottest:6.2}) off {off:>7} s: +{above:.4} K (exact hottest rise {left:.3} K)");
    }
}

#[test]
fn grid_restore_after_keeps_the_latch_and_handles_odd_off_times() {
    let grid = grid();
    let snapshot = grid_heated_snapshot(&grid, 60, true);
    let saved = grid.restore(&snapshot, 1_000, 100_000, 20.0).unwrap();
    assert!(saved.outputs().alarm.shutdown);
    for off in [None, Some(f32::NAN), Some(-5.0), Some(0.0)] {
        let state = grid
            .restore_after(&snapshot, 2_000, 100_000, 20.0, off)
            .unwrap();
        assert!(state.outputs().alarm.shutdown, "{off:?}");
        assert_eq!(
            state.outputs().temps_c,
            saved.outputs().temps_c,
            "{off:?}: no cooling"
        );
    }
    // Huge: capped at the age (1000 s), and the latch holds.
    let capped = grid
        .restore_after(&snapshot, 2_000, 100_000, 20.0, Some(f32::INFINITY))
        .unwrap();
    let at_age = grid
        .restore_after(&snapshot, 2_000, 100_000, 20.0, Some(1_000.0))
        .unwrap();
    assert!(capped.outputs().alarm.shutdown);
    assert_eq!(capped.outputs().temps_c, at_age.outputs().temps_c);
    // Beyond the steps' reach (25 h) every coil is near the ambient, above it.
    let week = grid
        .restore_after(&snapshot, 1_000 + 604_800, 700_000, 20.0, Some(604_800.0))
        .unwrap();
    for t in week.outputs().temps_c.as_flattened() {
        assert!((20.0..20.01).contains(t), "{t}");
    }
    // The old restore still works, and refusals stay refusals.
    assert!(grid
        .restore_after(&snapshot[..10], 2_000, 100_000, 20.0, Some(10.0))
        .is_err());
}

// ------------------------------------------------------------- network --

/// Winding (0), housing (1), heatsink (2) to the ambient; thermocouple on
/// the housing (as in `restart_faults`).
fn small_network() -> Network<3, 1, 1> {
    Network::new([400.0, 1200.0, 3000.0])
        .unwrap()
        .connect(0, 1, 2.0)
        .unwrap()
        .connect(1, 2, 4.0)
        .unwrap()
        .connect_boundary(2, 0, 1.5)
        .unwrap()
        .joule_source(0, 0, Resistance::with_alpha(0.5, 0.00393, 20.0))
        .unwrap()
}

#[test]
fn network_downtime_cooling_is_within_10_mk_above_the_exact_and_never_below() {
    let network = small_network();
    let observer: NetworkObserver<3, 1, 1, 4, 1> = NetworkObserverBuilder::new(&network, [1])
        .critical_c([Some(155.0), Some(80.0), None])
        .build()
        .unwrap();
    let ss = network.state_space(&[20.0; 3]);
    let a: [[f64; 3]; 3] = core::array::from_fn(|i| core::array::from_fn(|j| ss.a[(i, j)]));
    let mut worst = 0.0f64;
    // Saved states: a heated winding, a hot housing, and a latched one;
    // ambients 20 and 35 degC (the latter above a node: it warms).
    for (saved_c, ambient, latched) in [
        ([140.0f32, 95.0, 60.0], 20.0f32, false),
        ([75.0, 78.0, 70.0], 20.0, true),
        ([60.0, 30.0, 25.0], 35.0, false),
    ] {
        let mut state = observer.state(&saved_c, &[ambient]);
        if latched {
            state = observer.conservative_state(&[Some(saved_c[1])], &[ambient]);
            state = {
                let mut s = observer.state(&saved_c, &[ambient]);
                s.alarm = state.alarm.clone();
                s
            };
        }
        let mut buf = [0u8; snapshot_len(3)];
        observer.save(&state, 100, &mut buf).unwrap();
        let mut x: [f64; 3] = core::array::from_fn(|i| saved_c[i] as f64 - ambient as f64);
        let mut t = 0.0;
        for off_s in OFF_TIMES_S {
            rk4_linear(&a, &mut x, off_s - t, 1.0);
            t = off_s;
            let restored = observer
                .restore_after(&buf, 100 + 40_000, 100_000, &[ambient], Some(off_s as f32))
                .unwrap();
            assert_eq!(restored.outputs().alarm.shutdown, latched);
            let got = observer.temps_c(&restored);
            if off_s == 0.0 {
                assert_eq!(got, saved_c, "off time 0: the saved state to the bit");
                continue;
            }
            let mut excess = Excess::default();
            for i in 0..3 {
                excess.add(got[i] as f64, ambient as f64 + x[i]);
            }
            excess.check(
                &format!("network {saved_c:?} at {ambient}, off {off_s} s"),
                NETWORK_MAX_ABOVE_K,
            );
            worst = worst.max(excess.above_k);
            println!(
                "network {saved_c:?} amb {ambient} off {off_s:>7} s: +{:.4} K",
                excess.above_k
            );
        }
        // Unknown off time: no cooling.
        let restored = observer
            .restore_after(&buf, 100 + 40_000, 100_000, &[ambient], None)
            .unwrap();
        assert_eq!(observer.temps_c(&restored), saved_c);
    }
    assert!(worst < 0.01, "the modal form is exact: {worst} K");
}

/// One node: the closed form `T_a + (T_0 - T_a) exp(-G t / C)`.
#[test]
fn one_node_network_cools_by_the_closed_form() {
    let network: Network<1, 1, 1> = Network::new([500.0])
        .unwrap()
        .connect_boundary(0, 0, 2.0)
        .unwrap()
        .joule_source(0, 0, Resistance::constant(1.0))
        .unwrap();
    let observer: NetworkObserver<1, 1, 1, 2, 1> = NetworkObserverBuilder::new(&network, [0])
        .critical_c([Some(155.0)])
        .build()
        .unwrap();
    for off_s in OFF_TIMES_S {
        let got = observer.cooled_c(&[120.0], &[20.0], off_s as f32)[0] as f64;
        let want = 20.0 + 100.0 * (-2.0 * off_s / 500.0).exp();
        assert!(
            got >= want && got - want < 0.01,
            "off {off_s}: {got} against {want}"
        );
    }
}

// ---------------------------------------------------------- Omnimagnet --

mod omni {
    use coil_thermal::omnimagnet::{Omnimagnet, NODES};

    pub const AMBIENT_C: f64 = 22.0;

    /// A heating run of the nonlinear plant (RK4, 0.1 s) from the ambient.
    pub fn heated(currents_a: [f64; 3], heat_s: f64) -> [f64; NODES] {
        let model = Omnimagnet::PAPER;
        let mut t = [AMBIENT_C; NODES];
        let steps = (heat_s / 0.1).round() as usize;
        for _ in 0..steps {
            model.step_rk4(&mut t, &currents_a, AMBIENT_C, 0.1);
        }
        t
    }

    /// The nonlinear plant's zero-current cooling from `start` at every
    /// off time of `off_times_s` (RK4).
    pub fn cooled_reference(start: &[f64; NODES], off_times_s: &[f64]) -> Vec<[f64; NODES]> {
        cooled_reference_at(start, off_times_s, AMBIENT_C)
    }

    /// [`cooled_reference`] at another ambient \[degC\].
    pub fn cooled_reference_at(
        start: &[f64; NODES],
        off_times_s: &[f64],
        ambient_c: f64,
    ) -> Vec<[f64; NODES]> {
        let model = Omnimagnet::PAPER;
        let mut t = *start;
        let mut now = 0.0;
        let mut out = Vec::new();
        // 0.01 s steps for the first minute (the paper sheet's time constant
        // is 0.25 s), 0.1 s after it.
        for &off in off_times_s {
            while now < off - 1e-9 {
                let dt: f64 = if now < 60.0 { 0.01 } else { 0.1 };
                let dt = dt.min(off - now);
                model.step_rk4(&mut t, &[0.0; 3], ambient_c, dt);
                now += dt;
            }
            now = off;
            out.push(t);
        }
        out
    }

    /// Start states: all three at 3.8 A until the inner solenoid reaches
    /// 115 degC (the paper's run, 3556 s), the same for 20 min, the inner
    /// solenoid alone at 6 A for 15 min, and all three at 3.8 A for 2 h
    /// (past the paper's stop).
    pub fn starts() -> Vec<(&'static str, [f64; NODES])> {
        vec![
            ("3 x 3.8 A, 3556 s", heated([3.8; 3], 3556.0)),
            ("3 x 3.8 A, 1200 s", heated([3.8; 3], 1200.0)),
            ("inner 6 A, 900 s", heated([6.0, 0.0, 0.0], 900.0)),
            ("3 x 3.8 A, 7200 s", heated([3.8; 3], 7200.0)),
            ("3 x 4.5 A, 3000 s", heated([4.5; 3], 3000.0)),
            ("outer 6 A, 1800 s", heated([0.0, 0.0, 6.0], 1800.0)),
        ]
    }
}

#[test]
fn omnimagnet_model_cooling_is_within_0_42_k_above_the_plant_and_never_below() {
    use coil_thermal::omnimagnet::Omnimagnet;
    let model = Omnimagnet::PAPER;
    let mut worst = Excess::default();
    for (name, start) in omni::starts() {
        let reference = omni::cooled_reference(&start, &DENSE_OFF_TIMES_S);
        for (off, want) in DENSE_OFF_TIMES_S.iter().zip(&reference) {
            let got = model.cooled_c(&start, omni::AMBIENT_C, *off);
            let mut e = Excess::default();
            let mut below_node = None;
            for i in 0..16 {
                if want[i] - got[i] > e.below_k {
                    below_node = Some(i);
                }
                e.add(got[i], want[i]);
            }
            let hottest = want.iter().cloned().fold(0.0, f64::max);
            println!(
                "omni {name:<20} off {off:>7} s: +{:.4} K (below {:.2e} at {below_node:?}) hottest {hottest:.2}",
                e.above_k, e.below_k
            );
            worst.above_k = worst.above_k.max(e.above_k);
            worst.below_k = worst.below_k.max(e.below_k);
        }
    }
    // The ambient changed while the device was off: colder (a night) and
    // warmer than the heating run's.
    let (_, start) = &omni::starts()[0];
    for ambient_c in [5.0, 35.0] {
        let reference = omni::cooled_reference_at(start, &DENSE_OFF_TIMES_S, ambient_c);
        for (off, want) in DENSE_OFF_TIMES_S.iter().zip(&reference) {
            let got = model.cooled_c(start, ambient_c, *off);
            let mut e = Excess::default();
            for i in 0..16 {
                e.add(got[i], want[i]);
            }
            println!(
                "omni 3 x 3.8 A, 3556 s, off at {ambient_c} degC, {off:>7} s: +{:.4} K (below {:.2e})",
                e.above_k, e.below_k
            );
            worst.above_k = worst.above_k.max(e.above_k);
            worst.below_k = worst.below_k.max(e.below_k);
        }
    }
    println!("omni model worst: {worst:?}");
    // What one linearisation at the ambient (the observer's build point)
    // would give: safe, but far above the truth.
    let a = model
        .state_space(&[omni::AMBIENT_C; 16], omni::AMBIENT_C)
        .unwrap()
        .a;
    let reference = omni::cooled_reference(start, &DENSE_OFF_TIMES_S);
    let mut baseline = Excess::default();
    for (off, want) in DENSE_OFF_TIMES_S.iter().zip(&reference).skip(1) {
        let (e, _) = coil_thermal::discretize::expm_with_integral(&a, *off).unwrap();
        let x = e * coil_thermal::nalgebra::SVector::<f64, 16>::from_fn(|i, _| {
            start[i] - omni::AMBIENT_C
        });
        for i in 0..16 {
            baseline.add(omni::AMBIENT_C + x[i], want[i]);
        }
    }
    println!("omni one linearisation at the ambient: {baseline:?}");
    worst.check("omnimagnet model", OMNI_MODEL_MAX_ABOVE_K);
}

#[test]
fn omni_observer_restore_after_cools_within_0_32_k_above_the_plant_and_never_below() {
    use coil_thermal::observer::{OmniObserver, OmniSettings, SnapshotError};
    use coil_thermal::omnimagnet::{Omnimagnet, NODES};
    let model = Omnimagnet::PAPER;
    let observer =
        OmniObserver::new(&model, &[22.0; NODES], 22.0, &OmniSettings::default()).unwrap();
    let mut worst = 0.0f64;
    for (k, (name, start)) in omni::starts().into_iter().take(2).enumerate() {
        let saved_c = start.map(|t| t as f32);
        let latched = k == 1;
        let mut state = observer.state(&saved_c, 22.0);
        if latched {
            let conservative = observer.conservative_state(&[None; 6], 22.0);
            state.alarm = conservative.alarm.clone();
        }
        let mut buf = [0u8; snapshot_len(NODES)];
        observer.save(&state, 10, &mut buf).unwrap();
        let start_f64 = saved_c.map(f64::from);
        let reference = omni::cooled_reference(&start_f64, &OFF_TIMES_S);
        for (off, want) in OFF_TIMES_S.iter().zip(&reference) {
            let restored = observer
                .restore_after(&model, &buf, 10 + 40_000, 100_000, 22.0, Some(*off as f32))
                .unwrap();
            assert_eq!(restored.outputs().alarm.shutdown, latched, "{name}");
            let got = observer.temps_c(&restored);
            if *off == 0.0 {
                assert_eq!(got, saved_c, "off time 0: the saved state to the bit");
                continue;
            }
            let mut e = Excess::default();
            for i in 0..NODES {
                e.add(got[i] as f64, want[i]);
            }
            e.check(
                &format!("omni observer {name}, off {off} s"),
                OMNI_OBSERVER_MAX_ABOVE_K,
            );
            worst = worst.max(e.above_k);
            println!(
                "omni observer {name:<20} off {off:>7} s: +{:.4} K",
                e.above_k
            );
        }
        let unknown = observer
            .restore_after(&model, &buf, 10 + 40_000, 100_000, 22.0, None)
            .unwrap();
        assert_eq!(
            observer.temps_c(&unknown),
            saved_c,
            "unknown off time: no cooling"
        );
    }
    println!("omni observer worst +{worst:.4} K");
    // Another model is refused when there is cooling to do.
    let other = model
        .with_convection(coil_thermal::omnimagnet::ConvectionParams {
            scale: [1.1; 3],
            ..coil_thermal::omnimagnet::ConvectionParams::PAPER
        })
        .unwrap();
    let mut buf = [0u8; snapshot_len(NODES)];
    let state = observer.state(&[80.0; NODES], 22.0);
    observer.save(&state, 10, &mut buf).unwrap();
    assert_eq!(
        observer
            .restore_after(&other, &buf, 100, 1000, 22.0, Some(60.0))
            .map(|_| ()),
        Err(SnapshotError::CoolingModelMismatch)
    );
    assert!(observer
        .restore_after(&other, &buf, 100, 1000, 22.0, None)
        .is_ok());
    // Huge off times: capped at the age, near the ambient, never below it.
    let week = observer
        .restore_after(
            &model,
            &buf,
            10 + 604_800,
            700_000,
            22.0,
            Some(f32::INFINITY),
        )
        .unwrap();
    for t in observer.temps_c(&week) {
        assert!((22.0..22.5).contains(&t), "{t}");
    }
}

/// What one 10 h cooling costs on the host (`--nocapture` prints it).
#[test]
fn omnimagnet_cooling_cost_on_the_host() {
    use coil_thermal::omnimagnet::{Omnimagnet, NODES};
    let model = Omnimagnet::PAPER;
    let start = [110.0; NODES];
    let begin = std::time::Instant::now();
    let n = 20;
    for _ in 0..n {
        std::hint::black_box(model.cooled_c(std::hint::black_box(&start), 22.0, 36_000.0));
    }
    println!(
        "omnimagnet cooled_c, 10 h: {:?} per call",
        begin.elapsed() / n
    );
}
