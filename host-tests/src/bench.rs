//! Per-step timings of the hot-path steppers on this host.
//!
//! Each measurement steps a model many times (at least `min_time` of wall
//! clock) and reports the median over `repeats` runs of the mean time per
//! step \[ns\]. Keys name the model, its size, the scalar type and the unit,
//! e.g. `network_16_f32_ns` (library `ExplicitStepper`, a 16-node chain with a
//! current input per node; chains of 3, 16, 84 and 336 nodes). Device
//! models and the filter:
//!
//! * `grid_84_{f32,f64,q32}_ns`: one 1 ms `CoilGrid::<S, 7, 12>::tick` of
//!   the HPPA grid (FDM-fitted parameters, update every tick: the worst
//!   case), every coil at 1 A;
//! * `omnimagnet_predict_{f32,f64}_ns`: mean-only predict `x = F x + G u` of
//!   the Omnimagnet's 16-node model linearised at 20 degC and discretised
//!   (zero-order hold) for 0.1 s, inputs `[I1^2, I2^2, I3^2, T_amb, 1]`;
//! * `omnimagnet_correct_steady_f32_ns`: the library filter's steady-state
//!   correction with the six thermocouples (`measurement_matrix`), process
//!   noise `Q = 1e-4 I` K^2 per step, readings `R = 0.25` K^2;
//!   `omnimagnet_correct_tv_f32_ns`: the time-varying correction (gate,
//!   sequential Joseph updates) with the same model, from the same prior
//!   covariance each time (its copy included);
//! * the Omnimagnet's 19-state observer (`OmnimagnetObserver`, 1 ms,
//!   linearised and started at a warm state, the fixture of the criterion
//!   bench `omnimagnet_filter`): `omnimagnet_predict_steady_{f32,f64}_ns`
//!   (the carried mean predict of the steady-state gain),
//!   `omnimagnet_predict_tv_{f32,f64}_ns` (the time-varying covariance
//!   predict), `omnimagnet_correct6_{steady,tv}_{f32,f64}_ns` (a correction
//!   with all six thermocouples fused) and `omnimagnet_solve_gain_f64_ns`
//!   (the background gain solve);
//! * `protect_tick_16_f32_ns`: a protection tick on the Omnimagnet network
//!   (16 elements): predictor slice, alarm tick and current limiter
//!   ([`ProtectTick`]);
//! * `grid_observer_84_f32_ns`: model and protection of the HPPA grid
//!   together, the mean 1 ms tick over whole update cycles ([`GridLoop`]);
//! * `omnimagnet_observer_16_f32_ns`: model and protection of one
//!   Omnimagnet together, one 1 ms tick without readings ([`OmniLoop`]);
//! * `network_observer_84_f32_ns`: the library's `NetworkObserver` on the
//!   HPPA grid's 84 coils as a model file, at its own size, the
//!   mean 1 ms tick (`replay` prints the distribution).
//!
//! In JSON each key `<name>_ns` also has `<name>_budget_ratio`.

use coil_thermal::nalgebra::Const;
use std::hint::black_box;
use std::time::{Duration, Instant};

use coil_thermal::observer::omnimagnet::NoWarmUp;
use coil_thermal::observer::{
    GridInputs, GridObserver, GridObserverState, OmniInputs, OmniObserver, OmniObserverState,
    OmniSettings,
};
use coil_thermal::protect::alarm::{AlarmBuilder, AlarmConfig, AlarmState, AlarmStatus};
use coil_thermal::protect::derating::DeratingRule;
use coil_thermal::protect::events::EventQueue;
use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
use coil_thermal::protect::predict::{
    ConstPredictorState, LimitPredictor, Operating, PredictorBuilder, PredictorState,
};
use coil_thermal::{
    ExplicitStepper, InputLimits, Network, NetworkState, Resistance, Scalar, SolenoidParams, Q32,
};
use serde::Serialize;

/// One measured step.
#[derive(Debug, Clone, Serialize)]
pub struct Timing {
    /// Key (`<model>_<size>_<scalar>_ns`).
    pub key: String,
    /// Median time per step \[ns\].
    pub ns: f64,
    /// `ns / 100 000` (the 0.1 ms budget).
    pub budget_ratio: f64,
}

/// A chain of `N` nodes, each heated by its own input, node 0 and node
/// `N-1` cooled: the shape of a layered winding.
pub fn chain<const N: usize>() -> Network<N, 1, N> {
    let mut net = Network::new([50.0; N]).expect("valid capacities");
    for i in 0..N.saturating_sub(1) {
        net = net.connect(i, i + 1, 2.0).expect("valid conductance");
    }
    net = net
        .connect_boundary(0, 0, 1.0)
        .and_then(|n| n.connect_boundary(N - 1, 0, 1.0))
        .expect("valid boundary");
    for i in 0..N {
        net = net
            .joule_source(i, i, Resistance::with_alpha(1.0, 0.0039, 20.0))
            .expect("valid source");
    }
    net
}

fn measure(key: String, min_time: Duration, repeats: usize, mut step: impl FnMut()) -> Timing {
    // Calibrate the batch size to about min_time.
    let mut batch = 1usize;
    loop {
        let start = Instant::now();
        for _ in 0..batch {
            step();
        }
        if start.elapsed() >= min_time / 4 || batch >= 1 << 30 {
            break;
        }
        batch *= 2;
    }
    let mut runs: Vec<f64> = (0..repeats.max(1))
        .map(|_| {
            let start = Instant::now();
            for _ in 0..batch {
                step();
            }
            start.elapsed().as_nanos() as f64 / batch as f64
        })
        .collect();
    runs.sort_by(f64::total_cmp);
    let ns = runs[runs.len() / 2];
    Timing {
        key,
        ns,
        budget_ratio: ns / crate::observer::STEP_BUDGET_NS,
    }
}

fn library_step<S: Scalar, const N: usize, const B: usize, const M: usize>(
    key: &str,
    net: &Network<N, B, M>,
    dt_s: f64,
    min_time: Duration,
    repeats: usize,
) -> Timing {
    let limits = InputLimits::default();
    let stepper =
        ExplicitStepper::<S, N, B, M>::new(net, dt_s, limits).expect("stable bench network");
    let mut state = NetworkState::<S, N, B, M>::uniform(20.0);
    let currents = [S::from_f64(1.5); M];
    let boundary = [S::from_f64(20.0); B];
    measure(key.to_string(), min_time, repeats, || {
        black_box(stepper.step(
            black_box(&mut state),
            black_box(&currents),
            black_box(&boundary),
        ));
    })
}

fn scalar_steps<const N: usize, const B: usize, const M: usize>(
    model: &str,
    net: &Network<N, B, M>,
    dt_s: f64,
    min_time: Duration,
    repeats: usize,
    out: &mut Vec<Timing>,
) {
    out.push(library_step::<f32, N, B, M>(
        &format!("{model}_{N}_f32_ns"),
        net,
        dt_s,
        min_time,
        repeats,
    ));
    out.push(library_step::<f64, N, B, M>(
        &format!("{model}_{N}_f64_ns"),
        net,
        dt_s,
        min_time,
        repeats,
    ));
    out.push(library_step::<Q32, N, B, M>(
        &format!("{model}_{N}_q32_ns"),
        net,
        dt_s,
        min_time,
        repeats,
    ));
}

fn grid_tick<S: Scalar>(key: &str, min_time: Duration, repeats: usize) -> Timing {
    use coil_thermal::grid::{CoilGrid, GridConfig, GridParams, GridState};
    let grid = CoilGrid::<S, 7, 12>::new(&GridConfig::hppa(GridParams::FDM_FITTED))
        .expect("the HPPA defaults are valid");
    let mut state = GridState::<S, 7, 12>::uniform(20.0);
    let currents = [[S::from_f64(1.0); 12]; 7];
    let (coolant, ambient) = (S::from_f64(20.0), S::from_f64(21.0));
    measure(key.to_string(), min_time, repeats, || {
        black_box(grid.tick(
            black_box(&mut state),
            black_box(&currents),
            coolant,
            ambient,
        ));
    })
}

/// The Omnimagnet filter model: `(F, G, H, Q, R)` in `f64`.
type OmniModel = (
    nalgebra::SMatrix<f64, 16, 16>,
    nalgebra::SMatrix<f64, 16, 5>,
    nalgebra::SMatrix<f64, 6, 16>,
    nalgebra::SMatrix<f64, 16, 16>,
    nalgebra::SVector<f64, 6>,
);

fn omnimagnet_model() -> OmniModel {
    use coil_thermal::omnimagnet::{measurement_matrix, Omnimagnet, NODES};
    let lin = Omnimagnet::PAPER
        .linearize(&[20.0; NODES], 20.0, 0.1)
        .expect("the paper's model linearises");
    let mut g = nalgebra::SMatrix::<f64, 16, 5>::zeros();
    for m in 0..3 {
        g.set_column(m, &lin.bd_current_squared.column(m));
    }
    g.set_column(3, &lin.discrete.gd_boundary.column(0));
    g.set_column(4, &lin.discrete.dd);
    (
        lin.discrete.ad,
        g,
        measurement_matrix(),
        nalgebra::SMatrix::<f64, 16, 16>::identity() * 1e-4,
        nalgebra::SVector::<f64, 6>::repeat(0.25),
    )
}

/// The Omnimagnet's 16-state filter of [`omnimagnet_model`] in `T`.
fn omnimagnet_filter<T: nalgebra::RealField + Copy>(
) -> coil_thermal::filter::KalmanConfig<T, Const<16>, Const<5>, Const<6>> {
    let (f, g, h, q, r) = omnimagnet_model();
    coil_thermal::filter::KalmanConfig::new(f.cast(), g.cast(), h.cast(), q.cast(), r.cast())
        .expect("valid filter model")
}

fn omnimagnet_predict<T: nalgebra::RealField + Copy>(
    key: &str,
    min_time: Duration,
    repeats: usize,
) -> Timing {
    use coil_thermal::filter::predict_mean;
    let cfg = omnimagnet_filter::<T>();
    let mut x = nalgebra::SVector::<T, 16>::repeat(T::from_subset(&20.0));
    let u = nalgebra::SVector::<f64, 5>::from([9.0, 9.0, 9.0, 20.0, 1.0]).cast::<T>();
    measure(key.to_string(), min_time, repeats, || {
        black_box(predict_mean(&cfg, black_box(&mut x), black_box(&u)));
    })
}

fn omnimagnet_correct(min_time: Duration, repeats: usize, out: &mut Vec<Timing>) {
    use coil_thermal::filter::{
        predict, update, update_steady, KalmanState, SteadyEstimate, SteadyStateGain,
    };
    let cfg = omnimagnet_filter::<f32>();
    let x0 = nalgebra::SVector::<f32, 16>::repeat(20.0);
    let z = [
        Some(20.3f32),
        Some(20.1),
        Some(19.8),
        Some(20.2),
        Some(20.0),
        Some(19.9),
    ];
    let steady = SteadyStateGain::solve(&cfg, 1).expect("the Riccati equation converges");
    let mut est = SteadyEstimate::new(x0);
    out.push(measure(
        "omnimagnet_correct_steady_f32_ns".into(),
        min_time,
        repeats,
        || {
            black_box(update_steady(
                &cfg,
                &steady,
                black_box(&mut est),
                black_box(&z),
            ));
            est.x = x0;
        },
    ));
    let mut state = KalmanState::new(x0, nalgebra::SMatrix::<f32, 16, 16>::identity());
    let u = nalgebra::SVector::<f32, 5>::from([9.0, 9.0, 9.0, 20.0, 1.0]);
    for _ in 0..50 {
        predict(&cfg, &mut state, &u);
        update(&cfg, &mut state, &z);
    }
    predict(&cfg, &mut state, &u);
    let prior = state;
    out.push(measure(
        "omnimagnet_correct_tv_f32_ns".into(),
        min_time,
        repeats,
        || {
            state.x = prior.x;
            state.cov = prior.cov;
            black_box(update(&cfg, black_box(&mut state), black_box(&z)));
        },
    ));
}

/// The 19-state Omnimagnet observer at 1 ms in `mode`, linearised and
/// started where the paper's three-solenoid run reaches 50 degC.
fn kalman_observer<T: nalgebra::RealField + Copy>(
    mode: coil_thermal::omnimagnet::observer::GainMode,
) -> coil_thermal::omnimagnet::observer::OmnimagnetObserver<T> {
    use coil_thermal::omnimagnet::observer::{ObserverSettings, OmnimagnetObserver};
    use coil_thermal::omnimagnet::{Omnimagnet, Preset, NODES};
    let model = Omnimagnet::PAPER;
    let mut warm = [22.0; NODES];
    Preset::ALL_THREE.run(&model, &mut warm, 22.0, |t| t[0] >= 50.0);
    let lin = model
        .linearize(&warm, 22.0, 1e-3)
        .expect("the paper's model linearises");
    let settings = ObserverSettings {
        warmup_corrections: 0,
        mode,
        ..ObserverSettings::DEFAULT
    };
    let mut obs =
        OmnimagnetObserver::new(&model, &lin, &settings, &warm, 22.0).expect("the observer builds");
    obs.set_mode(mode);
    obs
}

/// The 19-state observer's predict and six-sensor correction in both gain
/// modes, in `T` (`name` its suffix).
fn kalman_observer_calls<T: nalgebra::RealField + Copy>(
    name: &str,
    min_time: Duration,
    repeats: usize,
    out: &mut Vec<Timing>,
) {
    use coil_thermal::omnimagnet::observer::GainMode;
    use coil_thermal::omnimagnet::THERMOCOUPLE_NODES;
    let currents: [T; 3] = [nalgebra::convert(3.8); 3];
    let ambient: T = nalgebra::convert(22.0);
    for (mode, label) in [
        (GainMode::SteadyState, "steady"),
        (GainMode::TimeVarying, "tv"),
    ] {
        let mut obs = kalman_observer::<T>(mode);
        out.push(measure(
            format!("omnimagnet_predict_{label}_{name}_ns"),
            min_time,
            repeats,
            || {
                black_box(obs.predict(black_box(&currents), black_box(ambient)));
            },
        ));
        let mut obs = kalman_observer::<T>(mode);
        let t = obs.temperatures_c();
        let z = core::array::from_fn(|j| Some(t[THERMOCOUPLE_NODES[j]]));
        out.push(measure(
            format!("omnimagnet_correct6_{label}_{name}_ns"),
            min_time,
            repeats,
            || {
                black_box(obs.correct(black_box(&z)));
            },
        ));
    }
}

/// The per-tick protection path on the Omnimagnet's 16-node network with
/// its inputs held: one predictor slice, the alarm tick on every node and
/// the current limiter on the three solenoids. One implementation for
/// `coil-thermal bench` and the criterion bench `protect`.
pub struct ProtectTick {
    predictor: LimitPredictor<f32, 16, 1, 3, 48>,
    alarm: AlarmConfig<f32, Const<16>>,
    limiter: LimiterConfig<f32, Const<3>>,
    op: Operating<f32, 16, 1, 3>,
    state: ConstPredictorState<f32, 16, 1, 3>,
    alarm_state: AlarmState<f32, Const<16>>,
    events: EventQueue<32>,
    coil_limits: [CoilLimit<f32>; 3],
}

impl Default for ProtectTick {
    fn default() -> Self {
        Self::new()
    }
}

impl ProtectTick {
    /// The Omnimagnet network linearised at 20 degC, nodes at 30 to 45 degC,
    /// currents 3, 2.5 and 3.5 A, the Omnimagnet derating rule (nodes
    /// without a critical temperature take the highest, 240 degC).
    pub fn new() -> Self {
        use coil_thermal::omnimagnet::{Omnimagnet, CRITICAL_TEMPS_C, NODES};
        let net = Omnimagnet::PAPER
            .network(&[20.0; NODES], 20.0)
            .expect("the paper's model builds");
        let predictor = PredictorBuilder::new()
            .build::<f32, 16, 1, 3, 48>(&net)
            .expect("the Omnimagnet network decomposes");
        let highest = CRITICAL_TEMPS_C
            .iter()
            .flatten()
            .fold(0.0f64, |a, b| a.max(*b));
        let critical = CRITICAL_TEMPS_C.map(|c| c.unwrap_or(highest));
        let alarm = AlarmBuilder::new(&DeratingRule::omnimagnet(), critical)
            .build::<f32>()
            .expect("valid alarm");
        let limiter =
            LimiterConfig::<f32, Const<3>>::new([8.0; 3], 10.0, 0.0).expect("valid limiter");
        let op = Operating {
            temps_c: core::array::from_fn(|i| 30.0 + i as f32),
            currents_a: [3.0, 2.5, 3.5],
            boundary_c: [20.0],
            limits_c: alarm.alarm_limits_c(20.0),
        };
        Self {
            state: PredictorState::new(&predictor, &op),
            alarm_state: AlarmState::new(&alarm),
            predictor,
            alarm,
            limiter,
            op,
            events: EventQueue::new(),
            coil_limits: [CoilLimit::default(); 3],
        }
    }

    /// One tick; returns the alarm summary and the solenoids' limits.
    pub fn tick(&mut self) -> (AlarmStatus, [CoilLimit<f32>; 3]) {
        let op = black_box(&self.op);
        let ambient_c = op.boundary_c[0];
        let ttl = *self.state.tick(&self.predictor, op);
        let status =
            self.alarm_state
                .tick(&self.alarm, &op.temps_c, ambient_c, &ttl, &mut self.events);
        let coil_temps = [op.temps_c[0], op.temps_c[1], op.temps_c[2]];
        let coil_alarm = [op.limits_c[0], op.limits_c[1], op.limits_c[2]];
        self.limiter
            .apply(&coil_temps, &coil_alarm, ambient_c, &mut self.coil_limits);
        while self.events.pop().is_some() {}
        (status, self.coil_limits)
    }

    /// The predictor (for the benches of its other calls).
    pub fn predictor(&self) -> &LimitPredictor<f32, 16, 1, 3, 48> {
        &self.predictor
    }

    /// The operating point it protects.
    pub fn operating(&self) -> &Operating<f32, 16, 1, 3> {
        &self.op
    }
}

/// Grid updates of [`GridLoop`]: every 10 ticks, so that the observer's
/// three protection stages run between updates (`GridObserver`'s docs).
pub const GRID_TICKS_PER_UPDATE: u32 = 10;

/// Model and protection of the 84-coil HPPA grid together, as a controller
/// runs them every 1 ms tick: the commanded currents clamped by the last
/// limits, then one `GridObserver::tick` (grid step, and in the ticks after
/// each update the time to limit, the alarm and the limiter), `f32`. The
/// commands put 2.5 to 3 A on the middle rows so that the limiter tapers.
#[derive(Clone)]
pub struct GridLoop {
    observer: GridObserver<f32, 7, 12, 84>,
    state: GridObserverState<f32, 7, 12, 84>,
    demand_a: [[f32; 12]; 7],
    applied_a: [[f32; 12]; 7],
}

impl Default for GridLoop {
    fn default() -> Self {
        Self::new()
    }
}

impl GridLoop {
    /// The HPPA grid (FDM-fitted), the HPPA rule at 100 degC, 3 A hardware
    /// limit, 10 K taper; coils start at 55 degC, in the taper band.
    pub fn new() -> Self {
        use coil_thermal::grid::{GridConfig, GridParams};
        use coil_thermal::protect::derating::HPPA_CRITICAL_C;
        let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 84])
            .build::<f32>()
            .expect("valid alarm");
        let limiter = LimiterConfig::new([3.0; 84], 10.0, 0.0).expect("valid limiter");
        let config = GridConfig {
            ticks_per_update: GRID_TICKS_PER_UPDATE,
            ..GridConfig::hppa(GridParams::FDM_FITTED)
        };
        let observer =
            GridObserver::new(&config, alarm, limiter, 4).expect("the HPPA grid is valid");
        let state = observer.conservative_state(20.0);
        let demand_a = core::array::from_fn(|r| {
            core::array::from_fn(|c| {
                if (2..5).contains(&r) {
                    2.5 + 0.05 * c as f32
                } else {
                    0.5
                }
            })
        });
        Self {
            observer,
            state,
            demand_a,
            applied_a: [[0.0; 12]; 7],
        }
    }

    /// Ticks until the next tick is `phase` ticks after a grid update
    /// (0: the update tick itself, 1: the time-to-limit stage, 2: the alarm,
    /// 3: the limiter), for timing one kind of tick.
    pub fn align(&mut self, phase: u32) {
        loop {
            self.tick();
            if self.state.outputs().updated {
                break;
            }
        }
        for _ in 0..(phase + GRID_TICKS_PER_UPDATE - 1) % GRID_TICKS_PER_UPDATE {
            self.tick();
        }
    }

    /// `true` if the last tick updated the grid.
    pub fn updated(&self) -> bool {
        self.state.outputs().updated
    }

    /// One 1 ms tick; returns the smallest coil limit \[A\].
    pub fn tick(&mut self) -> f32 {
        let limits = &self.state.outputs().limits;
        let pairs = self
            .applied_a
            .as_flattened_mut()
            .iter_mut()
            .zip(self.demand_a.as_flattened());
        for ((applied, demand), limit) in pairs.zip(limits) {
            *applied = limit.clamp_a(*demand);
        }
        let inputs = GridInputs {
            currents_a: &self.applied_a,
            coolant_c: 20.0,
            ambient_c: 20.0,
            elapsed_us: 1000,
        };
        let smallest = self
            .observer
            .tick(&mut self.state, black_box(&inputs))
            .limits
            .iter()
            .fold(f32::INFINITY, |a, l| a.min(l.current_a));
        while self.state.events.pop().is_some() {}
        smallest
    }
}

/// Model and protection of one Omnimagnet together, every 1 ms tick: the
/// commanded currents clamped by the last limits, then one
/// `OmniObserver::tick` (model predict and predictor slice, alarm on the six
/// insulation nodes, limiter), without thermocouple readings (the filter's
/// correction is timed on its own, `omnimagnet_correct_*`).
pub struct OmniLoop {
    observer: OmniObserver,
    state: OmniObserverState<NoWarmUp>,
    demand_a: [f32; 3],
}

impl Default for OmniLoop {
    fn default() -> Self {
        Self::new()
    }
}

impl OmniLoop {
    /// The paper's Omnimagnet linearised at 60 degC, default settings
    /// (1 ms step); nodes at 70 degC, 5 A commanded on each solenoid.
    pub fn new() -> Self {
        use coil_thermal::omnimagnet::{Omnimagnet, NODES};
        let observer = OmniObserver::new(
            &Omnimagnet::PAPER,
            &[60.0; NODES],
            20.0,
            &OmniSettings::default(),
        )
        .expect("the paper's Omnimagnet builds");
        let state = observer.state(&[70.0; NODES], 20.0);
        Self {
            observer,
            state,
            demand_a: [5.0; 3],
        }
    }

    /// One 1 ms tick; returns the smallest solenoid limit \[A\].
    pub fn tick(&mut self, now_us: u32) -> f32 {
        let limits = self.state.outputs().limits;
        let mut currents_a = self.demand_a;
        for (i, l) in currents_a.iter_mut().zip(&limits) {
            *i = l.clamp_a(*i);
        }
        let inputs = OmniInputs {
            currents_a,
            ambient_c: 20.0,
            readings: [None; 6],
            now_us,
            elapsed_us: 1000,
        };
        let out = self.observer.tick(&mut self.state, black_box(&inputs));
        let smallest = out
            .limits
            .iter()
            .fold(f32::INFINITY, |a, l| a.min(l.current_a));
        while self.state.events.pop().is_some() {}
        smallest
    }
}

/// The library's `NetworkObserver` on the HPPA grid's 84 coils
/// (FDM-fitted, as a model file) at its own size, 1 ms ticks,
/// every coil at 1 A, open loop; the mean over many ticks (one in 16 runs
/// the time-to-limit slice).
fn network_observer_tick(min_time: Duration, repeats: usize) -> Timing {
    use crate::devices::{grid_file, DEFAULT_COLS, DEFAULT_ROWS};
    use crate::library_observer::ObserverEstimator;
    use crate::model_file::Model;
    use crate::observer::Estimator;
    let file = grid_file(
        DEFAULT_ROWS,
        DEFAULT_COLS,
        &coil_thermal::grid::GridParams::FDM_FITTED,
    )
    .expect("the HPPA grid builds");
    let model = Model::build(&file).expect("the HPPA grid is a valid model");
    let mut observer = ObserverEstimator::new(model, 1000).expect("the observer builds");
    let n = DEFAULT_ROWS * DEFAULT_COLS;
    observer.reset(&vec![20.0; n]);
    observer.hold_inputs(&vec![1.0; n], &[20.0, 20.0], &[]);
    measure(
        format!("network_observer_{}_f32_ns", observer.nodes()),
        min_time,
        repeats,
        || {
            black_box(observer.tick_once());
        },
    )
}

/// Runs every measurement.
pub fn run(min_time: Duration, repeats: usize) -> Vec<Timing> {
    let mut out = Vec::new();
    scalar_steps("network", &chain::<3>(), 1e-3, min_time, repeats, &mut out);
    scalar_steps("network", &chain::<16>(), 1e-3, min_time, repeats, &mut out);
    scalar_steps("network", &chain::<84>(), 1e-3, min_time, repeats, &mut out);
    // The size issue 20 measured the stepper's pair scan at (70-80 % of the
    // budget before it stored the connected pairs only).
    scalar_steps(
        "network",
        &chain::<336>(),
        1e-3,
        min_time,
        repeats,
        &mut out,
    );
    let sol = SolenoidParams::HESE
        .network::<30>()
        .expect("HeSE defaults are valid");
    scalar_steps("solenoid", &sol, 0.1, min_time, repeats, &mut out);
    out.push(grid_tick::<f32>("grid_84_f32_ns", min_time, repeats));
    out.push(grid_tick::<f64>("grid_84_f64_ns", min_time, repeats));
    out.push(grid_tick::<Q32>("grid_84_q32_ns", min_time, repeats));
    out.push(omnimagnet_predict::<f32>(
        "omnimagnet_predict_f32_ns",
        min_time,
        repeats,
    ));
    out.push(omnimagnet_predict::<f64>(
        "omnimagnet_predict_f64_ns",
        min_time,
        repeats,
    ));
    omnimagnet_correct(min_time, repeats, &mut out);
    kalman_observer_calls::<f32>("f32", min_time, repeats, &mut out);
    kalman_observer_calls::<f64>("f64", min_time, repeats, &mut out);
    let gain_observer =
        kalman_observer::<f64>(coil_thermal::omnimagnet::observer::GainMode::SteadyState);
    out.push(measure(
        "omnimagnet_solve_gain_f64_ns".into(),
        min_time,
        repeats,
        || {
            black_box(gain_observer.config().solve_gain().is_ok());
        },
    ));
    let mut protect = ProtectTick::new();
    out.push(measure(
        "protect_tick_16_f32_ns".into(),
        min_time,
        repeats,
        || {
            black_box(protect.tick());
        },
    ));
    // Whole update cycles, so every tick kind is in the mean.
    let mut grid = GridLoop::new();
    let mut timing = measure("grid_observer_84_f32_ns".into(), min_time, repeats, || {
        for _ in 0..GRID_TICKS_PER_UPDATE {
            black_box(grid.tick());
        }
    });
    timing.ns /= f64::from(GRID_TICKS_PER_UPDATE);
    timing.budget_ratio /= f64::from(GRID_TICKS_PER_UPDATE);
    out.push(timing);
    out.push(network_observer_tick(min_time, repeats));
    let mut omni = OmniLoop::new();
    let mut now_us = 0u32;
    out.push(measure(
        "omnimagnet_observer_16_f32_ns".into(),
        min_time,
        repeats,
        || {
            now_us = now_us.wrapping_add(1000);
            black_box(omni.tick(now_us));
        },
    ));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The phase-0 tick is the grid update; the next update comes a full
    /// cycle later. The fixture's commands are limited (it is in the taper).
    #[test]
    fn grid_loop_aligns_on_the_update_tick() {
        let mut l = GridLoop::new();
        l.align(0);
        let smallest_a = l.tick();
        assert!(l.updated());
        for _ in 1..GRID_TICKS_PER_UPDATE {
            l.tick();
            assert!(!l.updated());
        }
        l.tick();
        assert!(l.updated());
        assert!(smallest_a < 3.0, "{smallest_a}");
    }
}
