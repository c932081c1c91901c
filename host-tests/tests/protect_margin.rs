//! Protection that errs hot under model error (issue 15, section 3): the
//! *nominal* observers, their limiter clamping the commanded currents every
//! tick, keep plants whose every effective parameter is off by up to +-20 %
//! below their alarm limits (and so far below their critical temperatures),
//! because the limiter, the alarm and the time to limit act on the
//! protective upper bound (`coil_thermal::protect::margin`), not on the mean.
//!
//! Per device: at least 100 perturbed plants (the corners, where every parameter
//! sits at +-20 % in the directions that heat or speed the plant, and
//! random draws from a fixed seed), under a duty harder than nominal. A run
//! *overheats* when any watched element of the plant passes its derated
//! alarm limit (the temperature the protection promises to hold, as in
//! `protect_closed_loop.rs`); the test also counts runs past the critical
//! temperature itself. Both must be zero with the default margins; the same
//! plants with a zero margin overheat (counted and asserted on the
//! corners, so the test can fail). The cost: the current the margin takes
//! from the matched plant (plant = the observer's model).
//!
//! * HPPA grid: a 5 x 6 grid (30 coils, the HPPA's herringbone stencil,
//!   FDM fit, ambient padding), not the 84 coils: the plant is a dense f64
//!   RK4 written here from the stencil matrices, `O(N^2)` per step, and 100
//!   plants of 84 coils would take minutes. 12 of the 30 coils are interior
//!   (all 6 neighbours are coils), as under the HPPA's plate. The observer
//!   ticks every 10 ms (not 1 ms) and updates the grid every 0.1 s, the
//!   plant takes one RK4 step of 0.1 s per update with the RMS current of
//!   its ticks (the fastest perturbed mode decays at about 0.07 1/s): 20
//!   min of duty per plant. Duty: a plate commutating its coils at 3 A
//!   (twice the report's validation amplitude), sweeping, parked over the
//!   centre, sweeping.
//! * Omnimagnet: the nonlinear 16-node model with its capacities, conductive
//!   contacts, convection (each group's `h`, each convective contact),
//!   emissivities and `R0`s perturbed, stepped by its own RK4; the observer
//!   is the library's [`OmniObserver`] linearised at 80 degC, fusing the six
//!   thermocouples read from the plant at 2 Hz. Model step and tick 0.5 s
//!   (one correction per tick; the closed-loop test's 0.1 s would take five
//!   times as long), protection cycle 2 s. Duty: all three solenoids
//!   demanded at 5 A for 90 min (the paper's 3.8 A reaches 115 degC in 71
//!   min; 5 A is 1.7 times the power). Besides the +-20 % plants, four
//!   corners with convection and radiation 40 % low ("convection by more").
//!   The limiting element is a cover insulation (120 degC critical, no
//!   thermocouple): it gets `k sigma` and the unmeasured margin.
//!
//! `cargo test --release -p coil-thermal-host --test protect_margin -- --nocapture`

use std::f64::consts::PI;

use coil_thermal::grid::{Link, Stencil};
use coil_thermal::observer::grid::DEFAULT_MARGIN;
use coil_thermal::observer::omnimagnet::TimedReading;
use coil_thermal::observer::omnimagnet::ALARM_NODES;
use coil_thermal::observer::{GridInputs, GridObserver};
use coil_thermal::observer::{OmniInputs, OmniObserver, OmniSettings};
use coil_thermal::omnimagnet::observer::ObserverSettings;
use coil_thermal::omnimagnet::{
    Contact, ConvectionParams, Omnimagnet, Peer, Radiator, CRITICAL_TEMPS_C, NODES,
    PAPER_OMNIMAGNET, THERMOCOUPLE_NODES,
};
use coil_thermal::protect::alarm::AlarmBuilder;
use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::limiter::LimiterConfig;
use coil_thermal::protect::margin::UncertaintyMargin;
use coil_thermal::{GridConfig, GridParams, Reading};
use coil_thermal_host::devices::OmnimagnetPlant;
use coil_thermal_host::sim::Plant;
use coil_thermal_host::synth::Rng;

/// Ambient and coolant \[degC\].
const AMBIENT_C: f64 = 20.0;
/// Largest parameter error, each way.
const DELTA: f64 = 0.2;
/// Random plants per device, besides the corners.
const RANDOM_PLANTS: usize = 92;

/// A factor in `[1 - DELTA, 1 + DELTA]` from the host crate's seeded
/// generator: uniform, or at one of the two ends (`vertex`).
fn factor(rng: &mut Rng, vertex: bool) -> f64 {
    let u = rng.uniform();
    if vertex {
        if u < 0.5 {
            1.0 - DELTA
        } else {
            1.0 + DELTA
        }
    } else {
        1.0 + DELTA * (2.0 * u - 1.0)
    }
}

/// How the plants are drawn: the named corners, then random draws.
#[derive(Debug, Clone, Copy)]
enum Draw {
    /// Every factor of a kind at one end: capacities, coil-to-coil
    /// conductances, conductances to the boundaries (base, ambient; for the
    /// Omnimagnet convection and radiation), winding resistances.
    Corner {
        capacity: f64,
        links: f64,
        boundary: f64,
        resistance: f64,
    },
    /// Independent factors, uniform in the band.
    Uniform(u64),
    /// Independent factors, each at one end of the band.
    Vertex(u64),
}

/// The corners: the winding resistance always +20 % (more heat), the rest
/// in the combinations that make the plant hotter or faster than the model.
fn corners() -> Vec<Draw> {
    let (lo, hi) = (1.0 - DELTA, 1.0 + DELTA);
    let mut out = Vec::new();
    for capacity in [lo, hi] {
        for (links, boundary) in [(lo, lo), (hi, lo), (lo, hi), (hi, hi)] {
            out.push(Draw::Corner {
                capacity,
                links,
                boundary,
                resistance: hi,
            });
        }
    }
    out
}

fn draws() -> Vec<Draw> {
    let mut out = corners();
    for k in 0..RANDOM_PLANTS as u64 {
        out.push(if k % 2 == 0 {
            Draw::Uniform(k)
        } else {
            Draw::Vertex(k)
        });
    }
    out
}

/// Factors for one plant: `kind` 0 capacities, 1 links, 2 boundaries, 3
/// resistances; one call per parameter, in a fixed order.
struct Factors {
    draw: Draw,
    rng: Rng,
}

impl Factors {
    fn new(draw: Draw) -> Self {
        let seed = match draw {
            Draw::Uniform(s) | Draw::Vertex(s) => s,
            Draw::Corner { .. } => 0,
        };
        Self {
            draw,
            rng: Rng::new(seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x005e_ed15),
        }
    }

    fn next(&mut self, kind: usize) -> f64 {
        match self.draw {
            Draw::Corner {
                capacity,
                links,
                boundary,
                resistance,
            } => [capacity, links, boundary, resistance][kind],
            Draw::Uniform(_) => factor(&mut self.rng, false),
            Draw::Vertex(_) => factor(&mut self.rng, true),
        }
    }
}

/// What one closed-loop run showed.
#[derive(Debug, Clone)]
struct Run {
    draw: String,
    /// Highest plant temperature of any watched element \[degC\].
    peak_c: f64,
    /// Its element.
    peak_element: usize,
    /// Highest plant temperature minus the element's alarm limit \[K\].
    over_limit_k: f64,
    /// Highest plant temperature minus the element's critical temperature
    /// \[K\].
    over_critical_k: f64,
    /// Delivered over demanded current, `sum |I_applied| / sum |I_demanded|`.
    delivered_share: f64,
}

/// Prints a summary of `runs` and returns (runs over the alarm limit, runs
/// over the critical temperature).
fn summarise(device: &str, margin: &str, runs: &[Run]) -> (usize, usize) {
    let over_limit = runs.iter().filter(|r| r.over_limit_k > 0.0).count();
    let over_critical = runs.iter().filter(|r| r.over_critical_k > 0.0).count();
    let worst = runs
        .iter()
        .max_by(|a, b| a.over_limit_k.total_cmp(&b.over_limit_k))
        .unwrap();
    let share = runs.iter().map(|r| r.delivered_share).sum::<f64>() / runs.len() as f64;
    let least = runs
        .iter()
        .map(|r| r.delivered_share)
        .fold(f64::INFINITY, f64::min);
    println!(
        "{device}, {margin}: {} plants, {over_limit} over the alarm limit, {over_critical} over \
         the critical temperature; worst {} (element {}) peaks at {:.2} degC ({:+.2} K to its \
         limit, {:+.2} K to critical); delivered {:.1} % of the demand on average (least {:.1} %)",
        runs.len(),
        worst.draw,
        worst.peak_element,
        worst.peak_c,
        worst.over_limit_k,
        worst.over_critical_k,
        100.0 * share,
        100.0 * least,
    );
    (over_limit, over_critical)
}

/// Runs `f` on every draw, on two threads (the machine has two cores).
fn run_all(draws: &[Draw], f: impl Fn(Draw) -> Run + Sync) -> Vec<Run> {
    let half = draws.len().div_ceil(2);
    std::thread::scope(|s| {
        let handles: Vec<_> = draws
            .chunks(half)
            .map(|chunk| {
                let f = &f;
                s.spawn(move || chunk.iter().map(|d| f(*d)).collect::<Vec<_>>())
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    })
}

/// The derating rule by hand (`derating-rule.md`).
fn derated_c(critical_c: f64, factors: &[f64]) -> f64 {
    AMBIENT_C + (critical_c - AMBIENT_C) * factors.iter().product::<f64>()
}

// ------------------------------------------------------------------ HPPA

const ROWS: usize = 5;
const COLS: usize = 6;
const COILS: usize = ROWS * COLS;
/// Observer tick \[us\] and ticks per grid update (one plant step).
const GRID_TICK_US: u32 = 10_000;
const GRID_TICKS_PER_UPDATE: u32 = 10;
/// Duty length \[s\]: three phases of 400 s.
const GRID_DUTY_S: f64 = 1200.0;
/// Commutation amplitude \[A\]: twice the validation trajectory's 1.5 A,
/// and the coils' hardware limit.
const GRID_AMPLITUDE_A: f64 = 3.0;
/// Coil pitch \[m\] and the plate's half extents and commutation period.
const PITCH_M: f64 = 0.0225;
const PLATE_HALF_X_M: f64 = 0.034;
const PLATE_HALF_Y_M: f64 = 0.034;
const PLATE_PERIOD_M: f64 = 0.05;

/// The dense perturbed grid: `C_i dT_i/dt = sum_j K_ij T_j + g_b,i (T_c -
/// T_i) + g_a,i (T_a - T_i) + s_i (r0 + r1 T_i) I_i^2`, assembled here from
/// the stencil's link matrices and the report's raw values (Table 7,
/// between coils), every capacity, link, base and padding conductance and
/// winding resistance scaled by its own factor.
struct GridPlant {
    k: Vec<f64>,
    g_base: Vec<f64>,
    g_ambient: Vec<f64>,
    capacity: Vec<f64>,
    r_scale: Vec<f64>,
}

impl GridPlant {
    fn new(draw: Draw) -> Self {
        const RX: f64 = 19.8;
        const RY: f64 = 6.99;
        const RZ: f64 = 5.74;
        const C: f64 = 68.7;
        let stencil = Stencil::HPPA_HERRINGBONE;
        let mut f = Factors::new(draw);
        let n = COILS;
        let mut k = vec![0.0; n * n];
        let mut g_ambient = vec![0.0; n];
        for r in 0..ROWS {
            let matrix = if r % 2 == 0 {
                &stencil.even
            } else {
                &stencil.odd
            };
            for c in 0..COLS {
                let i = r * COLS + c;
                for (a, line) in matrix.iter().enumerate() {
                    let contacts = line.iter().filter(|l| **l == Link::Y).count().max(1);
                    for (b, link) in line.iter().enumerate() {
                        let g = match link {
                            Link::None => continue,
                            Link::X => 1.0 / RX,
                            Link::Y => 1.0 / (RY * contacts as f64),
                        };
                        let (rr, cc) = (r as i64 + a as i64 - 1, c as i64 + b as i64 - 1);
                        if rr >= 0 && cc >= 0 && (rr as usize) < ROWS && (cc as usize) < COLS {
                            let j = rr as usize * COLS + cc as usize;
                            // One factor per link, drawn by its lower end.
                            if i < j {
                                let g = g * f.next(1);
                                k[i * n + j] = g;
                                k[j * n + i] = g;
                            }
                        } else {
                            g_ambient[i] += g * f.next(2);
                        }
                    }
                }
            }
        }
        for i in 0..n {
            let sum: f64 = (0..n).filter(|j| *j != i).map(|j| k[i * n + j]).sum();
            k[i * n + i] = -sum;
        }
        let g_base = (0..n).map(|_| f.next(2) / RZ).collect();
        let capacity = (0..n).map(|_| C * f.next(0)).collect();
        let r_scale = (0..n).map(|_| f.next(3)).collect();
        Self {
            k,
            g_base,
            g_ambient,
            capacity,
            r_scale,
        }
    }

    fn derivative(&self, t: &[f64], i2: &[f64], out: &mut [f64]) {
        let n = COILS;
        for i in 0..n {
            let row = &self.k[i * n..(i + 1) * n];
            let conduction: f64 = row.iter().zip(t).map(|(g, t)| g * t).sum();
            let r = self.r_scale[i] * (5.166 + 0.026 * t[i]);
            let q =
                conduction + (self.g_base[i] + self.g_ambient[i]) * (AMBIENT_C - t[i]) + r * i2[i];
            out[i] = q / self.capacity[i];
        }
    }

    /// One RK4 step of `h_s` with held currents \[A\].
    fn step(&self, t: &mut [f64; COILS], currents_a: &[f64; COILS], h_s: f64) {
        let i2 = currents_a.map(|i| i * i);
        let (mut k1, mut k2, mut k3, mut k4) =
            ([0.0; COILS], [0.0; COILS], [0.0; COILS], [0.0; COILS]);
        let mut tmp = [0.0; COILS];
        self.derivative(t, &i2, &mut k1);
        for i in 0..COILS {
            tmp[i] = t[i] + 0.5 * h_s * k1[i];
        }
        self.derivative(&tmp, &i2, &mut k2);
        for i in 0..COILS {
            tmp[i] = t[i] + 0.5 * h_s * k2[i];
        }
        self.derivative(&tmp, &i2, &mut k3);
        for i in 0..COILS {
            tmp[i] = t[i] + h_s * k3[i];
        }
        self.derivative(&tmp, &i2, &mut k4);
        for i in 0..COILS {
            t[i] += h_s / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
}

/// The demanded currents at `t_s` \[s\]: a plate over the grid commutating
/// the coils under it at 3 A, sweeping in x at 0.05 Hz for 400 s, parked
/// over the centre for 400 s (each coil under it at a constant current, up
/// to 3 A: the fastest heating), sweeping again.
fn grid_demand(t_s: f64) -> [f64; COILS] {
    let (x_mid, y_mid) = (COLS as f64 * PITCH_M / 2.0, ROWS as f64 * PITCH_M / 2.0);
    let sweep = |t: f64| x_mid + 0.03 * (2.0 * PI * 0.05 * t).sin();
    let x = if (400.0..800.0).contains(&t_s) {
        x_mid + 0.006
    } else {
        sweep(t_s)
    };
    let mut out = [0.0; COILS];
    for r in 0..ROWS {
        for c in 0..COLS {
            let shift = if r % 2 == 1 { 0.5 } else { 0.0 };
            let (xc, yc) = (
                (c as f64 + 0.5 + shift) * PITCH_M,
                (r as f64 + 0.5) * PITCH_M,
            );
            if (xc - x).abs() < PLATE_HALF_X_M && (yc - y_mid).abs() < PLATE_HALF_Y_M {
                let phase = if r % 2 == 1 { PI / 2.0 } else { 0.0 };
                out[r * COLS + c] =
                    GRID_AMPLITUDE_A * (2.0 * PI * (xc - x) / PLATE_PERIOD_M + phase).sin();
            }
        }
    }
    out
}

type SmallGrid = GridObserver<f32, ROWS, COLS, COILS>;

fn grid_observer(margin: UncertaintyMargin) -> SmallGrid {
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; COILS])
        .build::<f32>()
        .unwrap();
    let limiter = LimiterConfig::new([GRID_AMPLITUDE_A; COILS], 10.0, 0.0).unwrap();
    let config = GridConfig {
        tick_dt_s: f64::from(GRID_TICK_US) * 1e-6,
        ticks_per_update: GRID_TICKS_PER_UPDATE,
        ..GridConfig::hppa(GridParams::FDM_FITTED)
    };
    SmallGrid::new(&config, alarm, limiter, 4)
        .unwrap()
        .with_margin(margin)
        .unwrap()
}

/// One closed-loop run: the nominal observer with `margin` protecting the
/// plant drawn by `draw` (`protected` false: the limiter is ignored).
fn grid_run(draw: Draw, margin: UncertaintyMargin, protected: bool) -> Run {
    let observer = grid_observer(margin);
    let mut state = observer.state(AMBIENT_C);
    let plant = GridPlant::new(draw);
    let mut plant_c = [AMBIENT_C; COILS];
    let limit_c = derated_c(HPPA_CRITICAL_C, &[0.875, 0.9, 0.9, 0.8]);
    let mut run = Run {
        draw: format!("{draw:?}"),
        peak_c: f64::NEG_INFINITY,
        peak_element: 0,
        over_limit_k: f64::NEG_INFINITY,
        over_critical_k: f64::NEG_INFINITY,
        delivered_share: 0.0,
    };
    let hold_s = f64::from(GRID_TICK_US * GRID_TICKS_PER_UPDATE) * 1e-6;
    let holds = (GRID_DUTY_S / hold_s).round() as usize;
    let (mut delivered, mut demanded) = (0.0, 0.0);
    let mut applied = [[0.0f32; COLS]; ROWS];
    for k in 0..holds {
        let demand = grid_demand(k as f64 * hold_s);
        let mut i2 = [0.0f64; COILS];
        for _ in 0..GRID_TICKS_PER_UPDATE {
            let limits = &state.outputs().limits;
            for (idx, a) in applied.as_flattened_mut().iter_mut().enumerate() {
                let want = demand[idx] as f32;
                *a = if protected {
                    limits[idx].clamp_a(want)
                } else {
                    want
                };
                i2[idx] += f64::from(*a).powi(2) / f64::from(GRID_TICKS_PER_UPDATE);
                delivered += f64::from(a.abs());
                demanded += f64::from(want.abs());
            }
            observer.tick(
                &mut state,
                &GridInputs {
                    currents_a: &applied,
                    coolant_c: AMBIENT_C as f32,
                    ambient_c: AMBIENT_C as f32,
                    elapsed_us: GRID_TICK_US,
                },
            );
        }
        plant.step(&mut plant_c, &i2.map(f64::sqrt), hold_s);
        for (i, t) in plant_c.iter().enumerate() {
            if *t > run.peak_c {
                run.peak_c = *t;
                run.peak_element = i;
            }
        }
    }
    run.over_limit_k = run.peak_c - limit_c;
    run.over_critical_k = run.peak_c - HPPA_CRITICAL_C;
    run.delivered_share = delivered / demanded;
    run
}

#[test]
fn grid_margin_keeps_perturbed_plants_below_their_limits() {
    let started = std::time::Instant::now();
    let matched = Draw::Corner {
        capacity: 1.0,
        links: 1.0,
        boundary: 1.0,
        resistance: 1.0,
    };
    let open = grid_run(matched, DEFAULT_MARGIN, false);
    let nominal = grid_run(matched, UncertaintyMargin::ZERO, true);
    let with_margin = grid_run(matched, DEFAULT_MARGIN, true);
    println!(
        "HPPA 5 x 6, matched plant: unprotected peak {:.2} degC; protected without margin {:.2} \
         degC, {:.1} % of the demanded current; with the default margin (f = {}) {:.2} degC, \
         {:.1} %: the margin costs {:.1} % of the current the matched model allows",
        open.peak_c,
        nominal.peak_c,
        100.0 * nominal.delivered_share,
        DEFAULT_MARGIN.rise_fraction,
        with_margin.peak_c,
        100.0 * with_margin.delivered_share,
        100.0 * (1.0 - with_margin.delivered_share / nominal.delivered_share),
    );
    // The duty is harder than the limit allows: unprotected it overheats.
    assert!(open.over_limit_k > 10.0, "{open:?}");

    let draws = draws();
    let runs = run_all(&draws, |d| grid_run(d, DEFAULT_MARGIN, true));
    let (over_limit, over_critical) = summarise("HPPA 5 x 6", "default margin", &runs);
    // Without the margin, the same plants (the corners: asserted, so that
    // this test can fail; all of them with COIL_THERMAL_MARGIN_ZERO_ALL set).
    let zero_draws: Vec<Draw> = if std::env::var_os("COIL_THERMAL_MARGIN_ZERO_ALL").is_some() {
        draws.clone()
    } else {
        corners()
    };
    let zero = run_all(&zero_draws, |d| grid_run(d, UncertaintyMargin::ZERO, true));
    let (zero_over_limit, _) = summarise("HPPA 5 x 6", "zero margin", &zero);
    println!("HPPA: {:.1} s", started.elapsed().as_secs_f64());
    assert_eq!(over_limit, 0);
    assert_eq!(over_critical, 0);
    assert!(zero_over_limit > 0, "the test must be able to fail");
}

// ------------------------------------------------------------ Omnimagnet

/// Model step, tick and thermocouple period \[us\]: 0.5 s (the readings at
/// their 2 Hz, one correction per tick), not 1 ms; the Omnimagnet's time
/// constants are minutes to hours.
const OMNI_STEP_US: u32 = 500_000;
/// Protection cycle: every 4 steps (2 s).
const OMNI_PROTECT_STEPS: u32 = 4;
/// Duty length \[s\].
const OMNI_DUTY_S: f64 = 5400.0;
/// Demanded current of every solenoid \[A\]: all three on is the hottest
/// case, 5 A (1.7 times the power of the paper's 3.8 A, which reaches
/// 115 degC after 71 min).
const OMNI_DEMAND_A: f64 = 5.0;
/// The observer's linearisation temperature \[degC\] (as in
/// `protect_closed_loop.rs`: near the alarm limits).
const OMNI_LINEARISED_AT_C: f64 = 80.0;
/// Watched nodes: wire and cover insulation of each solenoid, and their
/// critical temperatures \[degC\].
const OMNI_WATCHED: [(usize, f64); 6] = {
    let mut watched = [(0, 0.0); 6];
    let mut k = 0;
    while k < watched.len() {
        let node = ALARM_NODES[k];
        if let Some(critical_c) = CRITICAL_TEMPS_C[node] {
            watched[k] = (node, critical_c);
        }
        k += 1;
    }
    watched
};

/// The paper's Omnimagnet with its parameters scaled as `draw` says
/// (kinds: 0 each element's capacity through its volume; 1 each conductive
/// contact; 2 convection and radiation: each group's `h`, each convective
/// contact, each emissivity; 3 each solenoid's `R0`). A random convective
/// contact draws its *total* factor (as in the library's observer tests:
/// `h` times area would compound to +44 %).
fn omni_plant(draw: Draw) -> Omnimagnet {
    let mut f = Factors::new(draw);
    let mut g = PAPER_OMNIMAGNET;
    for e in g.elements.iter_mut() {
        e.volume_m3 *= f.next(0);
    }
    let mut conv = ConvectionParams::PAPER;
    conv.scale.iter_mut().for_each(|s| *s = f.next(2));
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
        let scale = match (convective_solid, draw) {
            (None, _) => f.next(1),
            // A corner's group scale is its whole convective factor.
            (Some(_), Draw::Corner { .. }) => 1.0,
            (Some(s), _) => f.next(2) / group_scale(s),
        };
        c.area_m2.iter_mut().for_each(|a| *a *= scale);
    }
    g.contacts = Box::leak(contacts.into_boxed_slice());
    let mut radiators: Vec<Radiator> = g.radiators.to_vec();
    for r in radiators.iter_mut() {
        r.emissivity = (r.emissivity * f.next(2)).min(1.0);
    }
    g.radiators = Box::leak(radiators.into_boxed_slice());
    for s in g.solenoids.iter_mut() {
        s.r0_ohm *= f.next(3);
    }
    Omnimagnet::new(g, conv).unwrap()
}

/// "Convection by more": the corners with convection and radiation 40 %
/// below the model's (the direction that heats), the rest at +-20 %.
fn convection_corners() -> Vec<Draw> {
    let (lo, hi) = (1.0 - DELTA, 1.0 + DELTA);
    let mut out = Vec::new();
    for capacity in [lo, hi] {
        for links in [lo, hi] {
            out.push(Draw::Corner {
                capacity,
                links,
                boundary: 1.0 - 2.0 * DELTA,
                resistance: hi,
            });
        }
    }
    out
}

fn omni_settings(k_sigma: f64, margin: UncertaintyMargin) -> OmniSettings {
    let defaults = OmniSettings::default();
    OmniSettings {
        step_us: OMNI_STEP_US,
        max_steps_per_tick: 1,
        protect_period_steps: OMNI_PROTECT_STEPS,
        filter: ObserverSettings {
            correction_period_s: f64::from(OMNI_STEP_US) * 1e-6,
            ..defaults.filter
        },
        k_sigma,
        unmeasured_margin: margin,
        ..defaults
    }
}

fn omni_observer(settings: &OmniSettings) -> OmniObserver {
    OmniObserver::new(
        &Omnimagnet::PAPER,
        &[OMNI_LINEARISED_AT_C; NODES],
        AMBIENT_C,
        settings,
    )
    .unwrap()
}

fn omni_run(draw: Draw, observer: &OmniObserver, protected: bool) -> Run {
    let mut state = observer.state(&[AMBIENT_C as f32; NODES], AMBIENT_C as f32);
    let mut plant = OmnimagnetPlant::new(omni_plant(draw));
    plant.reset(&[AMBIENT_C; NODES]);
    let factors = [0.9, 0.9, 0.8];
    let mut run = Run {
        draw: format!("{draw:?}"),
        peak_c: f64::NEG_INFINITY,
        peak_element: 0,
        over_limit_k: f64::NEG_INFINITY,
        over_critical_k: f64::NEG_INFINITY,
        delivered_share: 0.0,
    };
    let dt_s = f64::from(OMNI_STEP_US) * 1e-6;
    let (mut delivered, mut demanded) = (0.0, 0.0);
    let mut now_us = 0u32;
    for _ in 0..(OMNI_DUTY_S / dt_s).round() as u32 {
        let limits = state.outputs().limits;
        let want = OMNI_DEMAND_A as f32;
        let applied = limits.map(|l| if protected { l.clamp_a(want) } else { want });
        for a in applied {
            delivered += f64::from(a.abs());
            demanded += f64::from(want);
        }
        plant.step(dt_s, &applied.map(f64::from), &[AMBIENT_C], &[]);
        now_us = now_us.wrapping_add(OMNI_STEP_US);
        let temps = plant.temps_c();
        let readings = THERMOCOUPLE_NODES.map(|node| {
            Some(TimedReading {
                result: Ok(Reading::new(temps[node] as f32)),
                sampled_at_us: now_us,
            })
        });
        observer.tick(
            &mut state,
            &OmniInputs {
                currents_a: applied,
                ambient_c: AMBIENT_C as f32,
                readings,
                now_us,
                elapsed_us: OMNI_STEP_US,
            },
        );
        for (node, critical_c) in OMNI_WATCHED {
            let t = plant.temps_c()[node];
            let over_limit_k = t - derated_c(critical_c, &factors);
            if over_limit_k > run.over_limit_k {
                run.over_limit_k = over_limit_k;
                run.peak_c = t;
                run.peak_element = node;
            }
            run.over_critical_k = run.over_critical_k.max(t - critical_c);
        }
    }
    run.delivered_share = delivered / demanded;
    run
}

#[test]
fn omnimagnet_margin_keeps_perturbed_plants_below_their_limits() {
    let started = std::time::Instant::now();
    let defaults = OmniSettings::default();
    let default_observer =
        omni_observer(&omni_settings(defaults.k_sigma, defaults.unmeasured_margin));
    let zero_observer = omni_observer(&omni_settings(0.0, UncertaintyMargin::ZERO));
    let sigma_only = omni_observer(&omni_settings(defaults.k_sigma, UncertaintyMargin::ZERO));
    let bound = default_observer.upper_bound();
    let offsets: Vec<String> = bound
        .elements()
        .iter()
        .map(|e| format!("{:.3}", e.offset_k()))
        .collect();
    println!(
        "Omnimagnet: k sigma per node [K] (k = {}): {}",
        defaults.k_sigma,
        offsets.join(" ")
    );
    let matched = Draw::Corner {
        capacity: 1.0,
        links: 1.0,
        boundary: 1.0,
        resistance: 1.0,
    };
    let open = omni_run(matched, &zero_observer, false);
    let nominal = omni_run(matched, &zero_observer, true);
    let sigma = omni_run(matched, &sigma_only, true);
    let with_margin = omni_run(matched, &default_observer, true);
    println!(
        "Omnimagnet, matched plant: unprotected peak {:.2} degC; protected without margin \
         {:.2} degC, {:.1} % of the demanded current; k sigma alone {:.2} degC, {:.1} %; \
         with the default margin (k = {}, f = {} on the unmeasured nodes) {:.2} degC, {:.1} %: \
         the margin costs {:.1} % of the current the matched model allows",
        open.peak_c,
        nominal.peak_c,
        100.0 * nominal.delivered_share,
        sigma.peak_c,
        100.0 * sigma.delivered_share,
        defaults.k_sigma,
        defaults.unmeasured_margin.rise_fraction,
        with_margin.peak_c,
        100.0 * with_margin.delivered_share,
        100.0 * (1.0 - with_margin.delivered_share / nominal.delivered_share),
    );
    assert!(open.over_limit_k > 10.0, "{open:?}");

    let mut draws = draws();
    draws.extend(convection_corners());
    let runs = run_all(&draws, |d| omni_run(d, &default_observer, true));
    let (over_limit, over_critical) = summarise("Omnimagnet", "default margin", &runs);
    let zero_draws: Vec<Draw> = if std::env::var_os("COIL_THERMAL_MARGIN_ZERO_ALL").is_some() {
        draws.clone()
    } else {
        corners().into_iter().chain(convection_corners()).collect()
    };
    let zero = run_all(&zero_draws, |d| omni_run(d, &zero_observer, true));
    let (zero_over_limit, _) = summarise("Omnimagnet", "zero margin", &zero);
    println!("Omnimagnet: {:.1} s", started.elapsed().as_secs_f64());
    assert_eq!(over_limit, 0);
    assert_eq!(over_critical, 0);
    assert!(zero_over_limit > 0, "the test must be able to fail");
}
