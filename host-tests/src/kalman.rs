//! Sensor fusion with disturbance states for `replay --disturbance`: the
//! library's time-varying Kalman filter (`coil_thermal::filter::predict`,
//! `update`, discretised by `coil_thermal::discretize::expm_with_integral`)
//! on a model file.
//!
//! # Sizes
//! The library filter has const-generic sizes; a model file's size is known
//! only at run time. The host builds the model's matrices (below) at
//! run-time size and copies them into `KalmanConfig<f64, C, C, C>` for the
//! smallest `C` of [`FILTER_CLASSES`] that holds the states, the inputs and
//! the sensors; padding states, inputs and sensors are zero rows and
//! columns (a padding state stays at zero with zero variance, a padding
//! sensor never has a reading). Every exponential, predict, gate and update
//! is the library's.
//!
//! # The model the filter runs
//! The model file's network is linear except for `R(T)`: for every node `i`
//! `C_i dT_i/dt = sum_j G_ij (T_j - T_i) + sum_b G_ib (T_b - T_i) + P_i + d_i`.
//! As the library's observer does, the Joule powers `max(R(T_est), 0) I^2` are
//! evaluated at the current estimate each step and enter as inputs, so `A`
//! stays constant and is discretised once per sample period (exact ZOH:
//! `F = exp(A dt)`, `G = Phi [B | G_b | d]`, `Phi = int_0^dt exp(A s) ds`).
//! A model whose conductances change with speed (`[conductance.speed]`)
//! has each row's network held over its interval, as the open-loop replay
//! does: `A` is rebuilt and rediscretised whenever a row's conductances
//! differ from the last ones (the covariance carries over; a learned
//! sensor noise is set again before every correction, as always).
//!
//! # Disturbance states (why one sensor corrects the others)
//! With temperatures alone as states, a sensor pulls its own node and, through
//! the few W/K between nodes, barely the others: the model's error in the
//! heat *input* (unmodelled iron or AC losses, a resistance a few percent off)
//! remains and the unmeasured nodes drift. Each `--disturbance NODES` adds one
//! state `d` \[W\]: an unmodelled heat spread over `NODES` in proportion to
//! their capacities (a loss density uniform over the material, as copper
//! losses are over the copper), modelled as a first-order Gauss-Markov process
//! `dd/dt = -d / tau + w` with stationary standard deviation `sigma_d`. The
//! filter estimates `d` from the measured node and the same `d` heats the
//! unmeasured ones. The decay (rather than a random walk) keeps the variance of
//! a poorly observable disturbance bounded.
//!
//! # Boundary offsets (`--boundary-offset`)
//! A measured boundary need not be the temperature the network's links
//! see: a sensor offset on the boundary reading, or a coolant outlet that
//! is not the jacket's effective temperature. Each `--boundary-offset
//! BOUNDARY` adds one state `o` \[K\] with `T_b,eff = T_b,measured + o`: it
//! enters every link to that boundary exactly as the boundary does
//! (`dT_i/dt += G_ib o / C_i`, the boundary's input column of `B` copied
//! into `A`), a first-order Gauss-Markov process like the disturbances
//! (`do/dt = -o / tau_o + w`, stationary standard deviation `sigma_o`).
//! It starts at 0 with variance `sigma_o^2`. With
//! `--boundary-offset-floor-k K` every correction ends with the offset
//! projected onto `o >= K` (the temperatures moved by their regression on
//! it, as the disturbance floor): at 0 the offset may warm the links,
//! never cool them below the boundary's reading.
//!
//! # Noise
//! * Temperatures: white heat-flow noise, `Q_T = q dt I` with `q` in K^2/s
//!   (`--process-noise-k2-per-s`).
//! * Disturbances: `Q_d = sigma_d^2 (1 - exp(-2 dt / tau))` per step, the exact
//!   discrete variance of the Gauss-Markov process.
//! * Boundary offsets: `Q_o = sigma_o^2 (1 - exp(-2 dt / tau_o))` per step.
//! * Sensors: `r = sigma^2` with `sigma` in K (`--measurement-noise-k`).
//!
//! Cross-terms of `Q` between temperatures and disturbances (or offsets) over one step
//! are neglected (a step is short against every time constant).

use anyhow::{anyhow, bail, Result};
use coil_thermal::discretize::expm_with_integral;
use coil_thermal::filter::{
    predict, update, KalmanConfig, KalmanState, SensorVerdict, CHI2_1DOF_999,
};
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::dynamic_network::DynNetwork;
use crate::model_file::Model;
use crate::observer::{Estimator, Measurement};
use crate::sim::{plant_info, PlantInfo};

/// The padded sizes `C` of the filter: `KalmanConfig<f64, C, C, C>` holds
/// states (temperatures and disturbances), inputs (sources, boundaries and
/// the constant) and sensors up to `C` each.
pub const FILTER_CLASSES: [usize; 3] = [8, 16, 32];

/// What one correction did, at run-time size.
struct Correction {
    verdicts: Vec<SensorVerdict>,
    recovered: bool,
}

/// The size-independent face of the library filter padded to a class.
///
/// Padding states have zero rows in `F`, `G` and `Q` (they stay at zero
/// with zero variance), padding inputs zero columns in `G`, padding sensors
/// a zero row in `H` and never a reading.
trait PaddedFilter: Send {
    /// Discretises `dx/dt = A x + B u` for `dt_s` (the library's
    /// `expm_with_integral`: `F = exp(A dt)`, `G = Phi B`) and builds the
    /// library's `KalmanConfig` with `H`, `Q` (states x states), `r` per
    /// sensor, the gate threshold and the recovery variances.
    #[allow(clippy::too_many_arguments)]
    fn configure(
        &mut self,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        dt_s: f64,
        h: &DMatrix<f64>,
        q: &DMatrix<f64>,
        r: &[f64],
        gate: f64,
        recovery: &[f64],
    ) -> Result<()>;
    /// Estimate `x0` with a diagonal covariance `p0_diag`, gate memory
    /// cleared.
    fn reset(&mut self, x0: &[f64], p0_diag: &[f64]);
    /// The library's full predict with inputs `u`.
    fn predict(&mut self, u: &[f64]);
    /// The library's correction with readings `z` (one per sensor).
    fn update(&mut self, z: &[Option<f64>]) -> Correction;
    /// The first `out.len()` states of the estimate.
    fn estimate(&self, out: &mut [f64]);
    /// Sensor `j`'s noise variance \[K^2\] from the next correction on.
    fn set_measurement_variance(&mut self, j: usize, variance_k2: f64);
    /// Moves the estimate onto `x[k] >= floor` with the posterior
    /// covariance (the library's `project_onto_floor`).
    fn project_onto_floor(&mut self, k: usize, floor: f64) -> bool;
}

struct Filter<const C: usize> {
    config: Option<KalmanConfig<f64, C, C, C>>,
    state: KalmanState<f64, C, C>,
    sensors: usize,
}

/// `m` in the top-left corner of an `R x K` zero matrix.
fn pad<const R: usize, const K: usize>(m: &DMatrix<f64>) -> SMatrix<f64, R, K> {
    let mut out = SMatrix::<f64, R, K>::zeros();
    for i in 0..m.nrows() {
        for j in 0..m.ncols() {
            out[(i, j)] = m[(i, j)];
        }
    }
    out
}

impl<const C: usize> Filter<C> {
    fn boxed(sensors: usize) -> Box<dyn PaddedFilter> {
        Box::new(Self {
            config: None,
            state: KalmanState::new(SVector::zeros(), SMatrix::zeros()),
            sensors,
        })
    }
}

impl<const C: usize> PaddedFilter for Filter<C> {
    fn configure(
        &mut self,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        dt_s: f64,
        h: &DMatrix<f64>,
        q: &DMatrix<f64>,
        r: &[f64],
        gate: f64,
        recovery: &[f64],
    ) -> Result<()> {
        let lib = |e: coil_thermal::BuildError| anyhow!("Kalman filter: {e}");
        let (f, phi) = expm_with_integral(&pad::<C, C>(a), dt_s).map_err(lib)?;
        let g = phi * pad::<C, C>(b);
        let mut rr = SVector::<f64, C>::repeat(1.0);
        rr.as_mut_slice()[..r.len()].copy_from_slice(r);
        let mut rec = SVector::<f64, C>::zeros();
        rec.as_mut_slice()[..recovery.len()].copy_from_slice(recovery);
        let config = KalmanConfig::new(f, g, pad::<C, C>(h), pad::<C, C>(q), rr)
            .and_then(|c| c.with_gate(gate))
            .and_then(|c| c.with_recovery(5, rec))
            .map_err(lib)?;
        self.config = Some(config);
        Ok(())
    }

    fn reset(&mut self, x0: &[f64], p0_diag: &[f64]) {
        let mut x = SVector::<f64, C>::zeros();
        x.as_mut_slice()[..x0.len()].copy_from_slice(x0);
        let mut p = SVector::<f64, C>::zeros();
        p.as_mut_slice()[..p0_diag.len()].copy_from_slice(p0_diag);
        self.state = KalmanState::new(x, SMatrix::from_diagonal(&p));
    }

    fn predict(&mut self, u: &[f64]) {
        let Some(config) = &self.config else { return };
        let mut uu = SVector::<f64, C>::zeros();
        uu.as_mut_slice()[..u.len()].copy_from_slice(u);
        predict(config, &mut self.state, &uu);
    }

    fn update(&mut self, z: &[Option<f64>]) -> Correction {
        let Some(config) = &self.config else {
            return Correction {
                verdicts: vec![SensorVerdict::Missing; self.sensors],
                recovered: false,
            };
        };
        let mut zz = [None; C];
        zz[..z.len()].copy_from_slice(z);
        let report = update(config, &mut self.state, &zz);
        Correction {
            verdicts: report.verdicts[..self.sensors].to_vec(),
            recovered: report.recovered,
        }
    }

    fn estimate(&self, out: &mut [f64]) {
        out.copy_from_slice(&self.state.x.as_slice()[..out.len()]);
    }

    fn project_onto_floor(&mut self, k: usize, floor: f64) -> bool {
        coil_thermal::filter::project_onto_floor(&mut self.state.x, &self.state.cov, k, floor)
    }

    fn set_measurement_variance(&mut self, j: usize, variance_k2: f64) {
        if let Some(config) = &mut self.config {
            // A variance the library refuses (not finite and positive)
            // leaves the last one in place.
            let _ = config.set_measurement_variance(j, variance_k2);
        }
    }
}

/// A sensor's noise learned from its own readings, independent of the
/// model: the scatter of each reading about the mean of the readings
/// `half_window` either side of it (a reading is judged once `half_window`
/// more have arrived), averaged over about `memory` readings (a running
/// mean until then, exponential after). A thermal signal is smooth over a
/// few tens of seconds; what scatters about its own short mean is the
/// converter's and the wiring's noise.
#[derive(Debug, Clone)]
struct NoiseWatch {
    half_window: usize,
    memory: usize,
    recent: std::collections::VecDeque<f64>,
    judged: usize,
    variance_k2: f64,
}

impl NoiseWatch {
    fn new(half_window: usize, memory: usize) -> Self {
        Self {
            half_window,
            memory: memory.max(1),
            recent: std::collections::VecDeque::with_capacity(2 * half_window + 1),
            judged: 0,
            variance_k2: 0.0,
        }
    }

    /// Takes a reading \[degC\]; the noise variance \[K^2\] once one
    /// reading has been judged. A non-finite reading (which the filter
    /// treats as missing) is not taken: it would poison the mean.
    fn push(&mut self, reading_c: f64) -> Option<f64> {
        if !reading_c.is_finite() {
            return self.variance_k2();
        }
        let width = 2 * self.half_window + 1;
        if self.recent.len() == width {
            self.recent.pop_front();
        }
        self.recent.push_back(reading_c);
        if self.recent.len() == width {
            let mean = self.recent.iter().sum::<f64>() / width as f64;
            let deviation = self.recent[self.half_window] - mean;
            self.judged += 1;
            let weight = 1.0 / self.judged.min(self.memory) as f64;
            self.variance_k2 += weight * (deviation * deviation - self.variance_k2);
        }
        self.variance_k2()
    }

    /// The noise variance \[K^2\] learned so far (none before a reading
    /// has been judged).
    fn variance_k2(&self) -> Option<f64> {
        (self.judged > 0).then_some(self.variance_k2)
    }
}

/// The filter's tuning (see the module docs for the units and the model).
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanOptions {
    /// Heat-flow noise of every temperature state \[K^2/s\].
    pub process_noise_k2_per_s: f64,
    /// Standard deviation of every fused sensor \[K\].
    pub measurement_noise_k: f64,
    /// Standard deviation of the initial temperatures \[K\].
    pub initial_std_k: f64,
    /// Disturbance states: each a set of node indices sharing one unmodelled
    /// heat \[W\] in proportion to their capacities.
    pub disturbances: Vec<Vec<usize>>,
    /// Stationary standard deviation of each disturbance \[W\].
    pub disturbance_std_w: f64,
    /// Correlation time of each disturbance \[s\].
    pub disturbance_tau_s: f64,
    /// Boundary offset states: each a boundary index whose effective
    /// temperature is the measured one plus an estimated offset \[K\].
    pub boundary_offsets: Vec<usize>,
    /// Stationary standard deviation of each boundary offset \[K\].
    pub boundary_offset_std_k: f64,
    /// Correlation time of each boundary offset \[s\].
    pub boundary_offset_tau_s: f64,
    /// Keep each boundary offset at or above this \[K\] (after every
    /// correction, with the temperatures by their regression on it, as
    /// the disturbance floor); `Some(0.0)`: the links never see a boundary
    /// colder than its reading, so the offset may explain a sensor that
    /// reads hot against the boundary but never cools the model. `None`:
    /// no floor.
    pub boundary_offset_floor_k: Option<f64>,
    /// Gate threshold on `nu^2 / S` (chi-square, 1 dof).
    pub gate: f64,
    /// Learn each sensor's noise from its own readings (see
    /// [`NoiseFromReadings`]); `measurement_noise_k` is then the floor.
    pub noise_from_readings: Option<NoiseFromReadings>,
    /// Keep each disturbance at or above `-share` times the Joule power
    /// of the sources on its nodes (after every correction, with the
    /// temperatures by their regression on it, as the firmware's heat
    /// biases: `NetworkSettings::max_cooling_bias_fraction`); `None`: no
    /// floor.
    pub disturbance_floor_share: Option<f64>,
}

/// Each fused sensor's noise learned from its readings: the standard
/// deviation of a reading about the mean of its neighbours, `half_window`
/// readings either side, averaged over about `memory` readings. The
/// filter uses the larger of it and `measurement_noise_k`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseFromReadings {
    /// Readings either side of the judged one.
    pub half_window: usize,
    /// Readings the average spans (exponential memory).
    pub memory: usize,
}

impl Default for KalmanOptions {
    fn default() -> Self {
        Self {
            process_noise_k2_per_s: 1e-4,
            measurement_noise_k: 0.2,
            initial_std_k: 2.0,
            disturbances: Vec::new(),
            disturbance_std_w: 50.0,
            disturbance_tau_s: 1800.0,
            boundary_offsets: Vec::new(),
            boundary_offset_std_k: 2.0,
            boundary_offset_tau_s: 7200.0,
            boundary_offset_floor_k: None,
            gate: CHI2_1DOF_999,
            noise_from_readings: None,
            disturbance_floor_share: None,
        }
    }
}

impl KalmanOptions {
    /// Checks the numbers.
    pub fn validate(&self) -> Result<()> {
        let pos = |v: f64, what: &str| -> Result<()> {
            if !(v.is_finite() && v > 0.0) {
                bail!("{what} must be finite and > 0, got {v}");
            }
            Ok(())
        };
        if !(self.process_noise_k2_per_s.is_finite() && self.process_noise_k2_per_s >= 0.0) {
            bail!(
                "--process-noise-k2-per-s must be finite and >= 0, got {}",
                self.process_noise_k2_per_s
            );
        }
        pos(self.measurement_noise_k, "--measurement-noise-k")?;
        pos(self.initial_std_k, "--initial-std-k")?;
        pos(self.disturbance_std_w, "--disturbance-std-w")?;
        pos(self.disturbance_tau_s, "--disturbance-tau-s")?;
        pos(self.boundary_offset_std_k, "--boundary-offset-std-k")?;
        pos(self.boundary_offset_tau_s, "--boundary-offset-tau-s")?;
        pos(self.gate, "--gate")?;
        if let Some(floor) = self.boundary_offset_floor_k {
            if !floor.is_finite() {
                bail!("--boundary-offset-floor-k must be finite, got {floor}");
            }
        }
        if let Some(share) = self.disturbance_floor_share {
            if !(share.is_finite() && share >= 0.0) {
                bail!("--disturbance-floor-share must be finite and >= 0, got {share}");
            }
        }
        if let Some(n) = self.noise_from_readings {
            if n.half_window == 0 || n.memory == 0 {
                bail!(
                    "--noise-half-window-rows and --noise-memory-rows must be >= 1, got {} and {}",
                    n.half_window,
                    n.memory
                );
            }
        }
        Ok(())
    }
}

/// Fusion statistics of one sensor over a replay.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FusionStats {
    /// Node index.
    pub node: usize,
    /// Readings fused.
    pub fused: usize,
    /// Readings rejected by the gate.
    pub rejected: usize,
    /// Readings judged stuck against the physics (the library observer's
    /// stuck watch; always 0 for the row-rate Kalman filter).
    pub stuck: usize,
    /// Readings refused as colder than the physics (the library
    /// observer's band; always 0 for the row-rate Kalman filter).
    pub colder_than_physics: usize,
    /// When the gate rejected a reading: seconds after the trace's first
    /// row, the first [`MAX_REJECTED_TIMES`] (the row-rate Kalman filter;
    /// empty for the library observer).
    pub rejected_at_s: Vec<f64>,
}

impl FusionStats {
    /// Nothing counted yet for the sensor on `node`.
    pub fn new(node: usize) -> Self {
        Self {
            node,
            fused: 0,
            rejected: 0,
            stuck: 0,
            colder_than_physics: 0,
            rejected_at_s: Vec::new(),
        }
    }
}

/// How many rejection times [`FusionStats::rejected_at_s`] keeps (the count
/// in [`FusionStats::rejected`] goes on).
pub const MAX_REJECTED_TIMES: usize = 10_000;

/// The continuous system of `net` with the disturbance and boundary
/// offset states of `opts` (indices already checked): `A` over
/// temperatures, disturbances and offsets, and the input matrix
/// `[B | G_b | d]` (sources, boundaries, the constant).
fn continuous_system(net: &DynNetwork, opts: &KalmanOptions) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = net.nodes();
    let nd = opts.disturbances.len();
    let states = n + nd + opts.boundary_offsets.len();
    let caps = net.capacities_j_per_k();
    let mut a = DMatrix::<f64>::zeros(states, states);
    for p in net.pairs() {
        a[(p.a, p.b)] += p.g_w_per_k / caps[p.a];
        a[(p.b, p.a)] += p.g_w_per_k / caps[p.b];
        a[(p.a, p.a)] -= p.g_w_per_k / caps[p.a];
        a[(p.b, p.b)] -= p.g_w_per_k / caps[p.b];
    }
    let sources = net.sources().len();
    let bounds = net.boundaries();
    let mut b = DMatrix::<f64>::zeros(states, sources + bounds + 1);
    for l in net.links() {
        a[(l.node, l.node)] -= l.g_w_per_k / caps[l.node];
        b[(l.node, sources + l.boundary)] += l.g_w_per_k / caps[l.node];
    }
    for (s, src) in net.sources().iter().enumerate() {
        b[(src.node, s)] = 1.0 / caps[src.node];
    }
    for (i, p) in net.fixed_powers_w().iter().enumerate() {
        b[(i, sources + bounds)] = p / caps[i];
    }
    for (k, nodes) in opts.disturbances.iter().enumerate() {
        let total: f64 = nodes.iter().map(|i| caps[*i]).sum();
        for i in nodes {
            // Share caps[i] / total of d at node i: dT_i/dt += d / total.
            a[(*i, n + k)] += 1.0 / total;
        }
        a[(n + k, n + k)] = -1.0 / opts.disturbance_tau_s;
    }
    for (k, &boundary) in opts.boundary_offsets.iter().enumerate() {
        let o = n + nd + k;
        // T_b,eff = T_b + o: the offset enters as the boundary does,
        // through the boundary's input column.
        for i in 0..n {
            a[(i, o)] = b[(i, sources + boundary)];
        }
        a[(o, o)] = -1.0 / opts.boundary_offset_tau_s;
    }
    (a, b)
}

/// A Kalman filter on a model file (see the module docs).
pub struct KalmanEstimator {
    model: Model,
    info: PlantInfo,
    opts: KalmanOptions,
    /// Temperature states, then disturbance states, then boundary
    /// offset states.
    states: usize,
    /// Disturbance states.
    disturbances: usize,
    /// Continuous `A` and input matrix `[B | G_b | d]`.
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    /// The network `a` and `b` were built from: the model's, or with
    /// speed-dependent conductances the last row's.
    network: DynNetwork,
    /// The library filter, padded; the sample period it was discretised
    /// for.
    filter: Box<dyn PaddedFilter>,
    period_s: Option<f64>,
    sensors: Vec<usize>,
    /// The estimate: temperatures, disturbances, boundary offsets.
    x: Vec<f64>,
    temps: Vec<f64>,
    effective: Vec<f64>,
    stats: Vec<FusionStats>,
    recoveries: usize,
    /// Time since the trace's first row \[s\]: the sum of the predicted
    /// intervals.
    elapsed_s: f64,
    /// Per sensor, with `noise_from_readings`.
    noise: Vec<NoiseWatch>,
    /// Per disturbance, the Joule power of the sources on its nodes at
    /// the last predict \[W\].
    disturbance_joule_w: Vec<f64>,
}

impl KalmanEstimator {
    /// A filter on `model` fusing sensors at `sensor_nodes` (node indices, in
    /// the order of the readings [`Estimator::update`] receives).
    pub fn new(model: Model, sensor_nodes: &[usize], opts: KalmanOptions) -> Result<Self> {
        opts.validate()?;
        if sensor_nodes.is_empty() {
            bail!("the Kalman filter needs at least one --measure sensor");
        }
        let info = plant_info(&model);
        let n = model.network.nodes();
        let nd = opts.disturbances.len();
        let no = opts.boundary_offsets.len();
        let states = n + nd + no;
        for nodes in &opts.disturbances {
            if nodes.is_empty() {
                bail!("--disturbance: an empty node list");
            }
            if let Some(i) = nodes.iter().find(|i| **i >= n) {
                bail!("--disturbance: node index {i} out of range");
            }
        }
        for (k, &boundary) in opts.boundary_offsets.iter().enumerate() {
            if boundary >= model.network.boundaries() {
                bail!("--boundary-offset: boundary index {boundary} out of range");
            }
            if opts.boundary_offsets[..k].contains(&boundary) {
                bail!(
                    "--boundary-offset: boundary `{}` given twice",
                    info.boundaries[boundary].name
                );
            }
        }
        let (a, b) = continuous_system(&model.network, &opts);
        let noise = opts
            .noise_from_readings
            .map(|n| vec![NoiseWatch::new(n.half_window, n.memory); sensor_nodes.len()])
            .unwrap_or_default();
        let stats = sensor_nodes
            .iter()
            .map(|&node| FusionStats::new(node))
            .collect();
        let size = states.max(b.ncols()).max(sensor_nodes.len());
        let filter = match FILTER_CLASSES.iter().find(|c| **c >= size) {
            Some(8) => Filter::<8>::boxed(sensor_nodes.len()),
            Some(16) => Filter::<16>::boxed(sensor_nodes.len()),
            Some(32) => Filter::<32>::boxed(sensor_nodes.len()),
            _ => bail!(
                "--measure: model `{}` needs {states} filter states ({n} nodes, {nd} disturbances, {no} boundary offsets), {} inputs and {} sensors; the filter holds at most {} of each",
                model.name,
                b.ncols(),
                sensor_nodes.len(),
                FILTER_CLASSES[FILTER_CLASSES.len() - 1]
            ),
        };
        Ok(Self {
            network: model.network.clone(),
            model,
            info,
            opts,
            states,
            disturbances: nd,
            a,
            b,
            filter,
            period_s: None,
            x: vec![0.0; states],
            sensors: sensor_nodes.to_vec(),
            temps: vec![0.0; n],
            effective: Vec::new(),
            stats,
            recoveries: 0,
            elapsed_s: 0.0,
            noise,
            disturbance_joule_w: vec![0.0; nd],
        })
    }

    /// Makes the library filter the one for a sample period `dt_s`
    /// (discretised when the period changes).
    fn ensure_filter(&mut self, dt_s: f64) -> Result<()> {
        let stale = match self.period_s {
            Some(dt) => (dt - dt_s).abs() > 1e-9 * dt_s.abs().max(1.0),
            None => true,
        };
        if stale {
            let n = self.temps.len();
            let mut q = DMatrix::<f64>::zeros(self.states, self.states);
            for i in 0..n {
                q[(i, i)] = self.opts.process_noise_k2_per_s * dt_s;
            }
            let decay = (-2.0 * dt_s / self.opts.disturbance_tau_s).exp();
            for k in n..n + self.disturbances {
                q[(k, k)] = self.opts.disturbance_std_w.powi(2) * (1.0 - decay);
            }
            let decay = (-2.0 * dt_s / self.opts.boundary_offset_tau_s).exp();
            for k in n + self.disturbances..self.states {
                q[(k, k)] = self.opts.boundary_offset_std_k.powi(2) * (1.0 - decay);
            }
            let mut h = DMatrix::<f64>::zeros(self.sensors.len(), self.states);
            for (j, node) in self.sensors.iter().enumerate() {
                h[(j, *node)] = 1.0;
            }
            let r = vec![self.opts.measurement_noise_k.powi(2); self.sensors.len()];
            // Recovery returns the sensed nodes to the prior's uncertainty: the library's
            // default (1e4 r on every state) would put hundreds of K^2 on the
            // unmeasured nodes, which one sensor cannot pull back, and the
            // disturbances would then swing them by tens of K.
            //
            // Only the sensed nodes are widened: a run of rejections says the
            // sensed node's estimate is off, not that every node or the
            // unmodelled heat is. Widening the unmeasured nodes or the
            // disturbances too hands them to the next readings of one sensor,
            // whose noise then swings the unmeasured nodes by several K; the
            // disturbances keep learning at their own process noise.
            let mut recovery = self.prior_variances();
            for (i, v) in recovery.iter_mut().enumerate() {
                if !self.sensors.contains(&i) {
                    *v = 0.0;
                }
            }
            self.filter.configure(
                &self.a,
                &self.b,
                dt_s,
                &h,
                &q,
                &r,
                self.opts.gate,
                recovery.as_slice(),
            )?;
            self.period_s = Some(dt_s);
        }
        Ok(())
    }

    /// Per-sensor fusion counts so far.
    pub fn stats(&self) -> &[FusionStats] {
        &self.stats
    }

    /// Covariance recoveries so far.
    pub fn recoveries(&self) -> usize {
        self.recoveries
    }

    /// Current disturbance estimates \[W\].
    pub fn disturbances_w(&self) -> Vec<f64> {
        let n = self.temps.len();
        self.x[n..n + self.disturbances].to_vec()
    }

    /// Each sensor's noise \[K\] as the filter now uses it: learned from
    /// its readings with [`KalmanOptions::noise_from_readings`] (at least
    /// `measurement_noise_k`), else `measurement_noise_k`.
    pub fn noise_k(&self) -> Vec<f64> {
        let floor = self.opts.measurement_noise_k;
        (0..self.sensors.len())
            .map(|j| {
                self.noise
                    .get(j)
                    .and_then(NoiseWatch::variance_k2)
                    .map_or(floor, |v| v.sqrt().max(floor))
            })
            .collect()
    }

    /// Current boundary offset estimates \[K\], in the order of
    /// [`KalmanOptions::boundary_offsets`].
    pub fn boundary_offsets_k(&self) -> Vec<f64> {
        self.x[self.temps.len() + self.disturbances..].to_vec()
    }

    /// Initial variances: `initial_std_k^2` per temperature,
    /// `disturbance_std_w^2` per disturbance, `boundary_offset_std_k^2` per
    /// boundary offset.
    fn prior_variances(&self) -> DVector<f64> {
        let n = self.temps.len();
        DVector::from_fn(self.states, |i, _| {
            if i < n {
                self.opts.initial_std_k.powi(2)
            } else if i < n + self.disturbances {
                self.opts.disturbance_std_w.powi(2)
            } else {
                self.opts.boundary_offset_std_k.powi(2)
            }
        })
    }

    fn sync_temps(&mut self) {
        let n = self.temps.len();
        self.filter.estimate(&mut self.x);
        self.temps.copy_from_slice(&self.x[..n]);
    }
}

impl Estimator for KalmanEstimator {
    fn info(&self) -> &PlantInfo {
        &self.info
    }

    fn reset(&mut self, temps_c: &[f64]) {
        let n = self.temps.len();
        let mut x = vec![0.0; self.states];
        x[..n].copy_from_slice(temps_c);
        self.filter.reset(&x, self.prior_variances().as_slice());
        self.sync_temps();
    }

    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        if dt_s.is_finite() && dt_s > 0.0 {
            self.elapsed_s += dt_s;
        }
        let mut effective = std::mem::take(&mut self.effective);
        self.model
            .effective_currents(currents_a, signals, &mut effective);
        // A voltage-driven winding draws `V_eff / R(T)` at the estimate.
        self.model.currents_at(&mut effective, &self.temps);
        let net = &self.model.network;
        let mut u = vec![0.0; self.b.ncols()];
        for (s, (src, i)) in net.sources().iter().zip(&effective).enumerate() {
            // The library's Joule power at the estimate.
            let r = src.resistance.to_scalar::<f64>();
            u[s] = r.joule_power_w(self.temps[src.node], *i);
        }
        // The disturbances' Joule powers: only the floor reads them.
        if self.opts.disturbance_floor_share.is_some() {
            for (k, nodes) in self.opts.disturbances.iter().enumerate() {
                self.disturbance_joule_w[k] = net
                    .sources()
                    .iter()
                    .zip(&u)
                    .filter(|(src, _)| nodes.contains(&src.node))
                    .map(|(_, p)| p)
                    .sum();
            }
        }
        let m = net.sources().len();
        for (k, t) in boundary_c.iter().enumerate() {
            u[m + k] = *t;
        }
        u[m + boundary_c.len()] = 1.0;
        self.effective = effective;
        // This row's conductances, held over the interval like every other
        // input; rediscretised only when they change.
        if let Some(net) = self.model.changed_network(signals, &self.network) {
            (self.a, self.b) = continuous_system(&net, &self.opts);
            self.network = net;
            self.period_s = None;
        }
        // A sample period the model cannot be discretised for (non-finite or
        // not positive) leaves the estimate where it is.
        if self.ensure_filter(dt_s).is_err() {
            return;
        }
        self.filter.predict(&u);
        self.sync_temps();
    }

    fn update(&mut self, measured: &[Measurement]) {
        // Before the first predict there is no filter yet: one for a unit
        // step serves (a correction uses only H, r and the gate).
        if self.period_s.is_none() && self.ensure_filter(1.0).is_err() {
            return;
        }
        let z: Vec<Option<f64>> = self
            .sensors
            .iter()
            .enumerate()
            .map(|(j, node)| {
                measured
                    .get(j)
                    .filter(|m| m.node == *node)
                    .map(|m| m.value_c)
                    // A missing reading (an empty or NaN cell) is no reading.
                    .filter(|v| !v.is_nan())
            })
            .collect();
        let floor_k2 = self.opts.measurement_noise_k.powi(2);
        for (j, (watch, reading)) in self.noise.iter_mut().zip(&z).enumerate() {
            if let Some(variance_k2) = reading.and_then(|v| watch.push(v)) {
                self.filter
                    .set_measurement_variance(j, variance_k2.max(floor_k2));
            }
        }
        let report = self.filter.update(&z);
        for (s, v) in self.stats.iter_mut().zip(&report.verdicts) {
            match v {
                SensorVerdict::Fused { .. } => s.fused += 1,
                SensorVerdict::Rejected { .. } => {
                    s.rejected += 1;
                    if s.rejected_at_s.len() < MAX_REJECTED_TIMES {
                        s.rejected_at_s.push(self.elapsed_s);
                    }
                }
                SensorVerdict::Missing => {}
            }
        }
        self.recoveries += usize::from(report.recovered);
        if let Some(share) = self.opts.disturbance_floor_share {
            let n = self.temps.len();
            for (k, joule_w) in self.disturbance_joule_w.iter().enumerate() {
                self.filter.project_onto_floor(n + k, -share * joule_w);
            }
        }
        if let Some(floor_k) = self.opts.boundary_offset_floor_k {
            for k in self.temps.len() + self.disturbances..self.states {
                self.filter.project_onto_floor(k, floor_k);
            }
        }
        self.sync_temps();
    }

    fn estimate_c(&self) -> &[f64] {
        &self.temps
    }

    fn kind(&self) -> &'static str {
        "kalman"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model_file::ModelFile;
    use crate::sim::{FilePlant, Plant};

    /// A coil on a water-cooled housing; the housing is sensed, the coil
    /// is not.
    const MODEL: &str = r#"
name = "jacket"
[[node]]
name = "coil"
capacity_j_per_k = 200.0
[[node]]
name = "housing"
capacity_j_per_k = 900.0
[[boundary]]
name = "coolant"
value_c = 30.0
[[conductance]]
between = ["coil", "housing"]
g_w_per_k = 2.0
[[conductance]]
between = ["housing", "coolant"]
g_w_per_k = 10.0
[[source]]
name = "coil"
node = "coil"
input = "current"
r0_ohm = 5.0
alpha_per_k = 0.0039
t_ref_c = 20.0
[initial]
policy = "boundary"
"#;

    /// The jacket plant and a filter on it fusing the housing (node 1),
    /// both started at the truth (every node at a measured reading).
    fn jacket(opts: KalmanOptions) -> (FilePlant, KalmanEstimator) {
        let model = Model::build(&ModelFile::parse(MODEL, "jacket.toml").unwrap()).unwrap();
        let mut plant = FilePlant::new(model.clone()).unwrap();
        let mut filter = KalmanEstimator::new(model, &[1], opts).unwrap();
        let start = [36.0, 33.0];
        plant.reset(&start);
        filter.reset(&start);
        (plant, filter)
    }

    /// The coil estimate against the plant run with the true coolant, over
    /// the last quarter of a run (see [`coil_errors`]).
    struct CoilErrors {
        /// Mean of `|estimate - truth|` \[K\].
        mean_k: f64,
        /// Largest `|estimate - truth|` \[K\].
        max_k: f64,
        /// Smallest `estimate - truth` \[K\] (negative: cold).
        coldest_k: f64,
        /// The filter's final boundary offsets \[K\].
        offsets_k: Vec<f64>,
    }

    /// The coil's errors over the last quarter of a 6000 s run when the
    /// filter is given a coolant reading `offset_k` below the truth (above
    /// it when negative).
    fn coil_errors(offset_k: f64, opts: KalmanOptions) -> CoilErrors {
        let (mut plant, mut filter) = jacket(opts);
        let rows = 6000;
        let (mut sum, mut max, mut coldest, mut count) = (0.0, 0.0_f64, f64::MAX, 0);
        for k in 0..rows {
            let t = k as f64;
            let current = match (k / 800) % 3 {
                0 => 1.5,
                1 => 0.5,
                _ => 1.0,
            };
            // A coolant swinging by 2 K with a 900 s period.
            let coolant = 30.0 + 2.0 * (2.0 * std::f64::consts::PI * t / 900.0).sin();
            plant.step(1.0, &[current], &[coolant], &[]);
            filter.predict(1.0, &[current], &[coolant - offset_k], &[]);
            filter.update(&[Measurement {
                node: 1,
                value_c: plant.temps_c()[1],
                fault: None,
            }]);
            if k >= 3 * rows / 4 {
                let e = filter.estimate_c()[0] - plant.temps_c()[0];
                sum += e.abs();
                max = max.max(e.abs());
                coldest = coldest.min(e);
                count += 1;
            }
        }
        CoilErrors {
            mean_k: sum / f64::from(count),
            max_k: max,
            coldest_k: coldest,
            offsets_k: filter.boundary_offsets_k(),
        }
    }

    /// The independent reference is the plant run with the true coolant;
    /// the filter is given a coolant reading 3 K low and the housing sensor.
    #[test]
    fn a_boundary_offset_state_recovers_an_unmeasured_node_behind_an_offset_boundary_sensor() {
        let offset = KalmanOptions {
            boundary_offsets: vec![0],
            boundary_offset_std_k: 3.0,
            boundary_offset_tau_s: 7200.0,
            ..KalmanOptions::default()
        };
        let heat = KalmanOptions {
            disturbances: vec![vec![0]],
            ..KalmanOptions::default()
        };
        let both = KalmanOptions {
            disturbances: vec![vec![0]],
            ..offset.clone()
        };
        // With an exact coolant reading the filter (temperatures only) is
        // exact, and an offset state stays at zero.
        let exact = coil_errors(0.0, KalmanOptions::default()).mean_k;
        let with_offset = coil_errors(0.0, offset.clone());
        let (exact_offset, zero) = (with_offset.mean_k, with_offset.offsets_k);
        // 3 K low: temperatures only, a heat disturbance on the coil, an
        // offset state, both.
        let plain = coil_errors(3.0, KalmanOptions::default()).mean_k;
        let heat_mean = coil_errors(3.0, heat).mean_k;
        let CoilErrors {
            mean_k: mean,
            max_k: max,
            offsets_k: found,
            ..
        } = coil_errors(3.0, offset);
        let both = coil_errors(3.0, both);
        let (both_mean, both_found) = (both.mean_k, both.offsets_k);
        eprintln!(
            "coil |error| mean [K] over the last quarter: exact coolant {exact:.4} ({exact_offset:.4} with the offset state); \
             coolant 3 K low: temperatures only {plain:.4}, heat disturbance {heat_mean:.3}, \
             offset state {mean:.4} (max {max:.4}, offset {:.3} K), both {both_mean:.3} (offset {:.3} K)",
            found[0], both_found[0]
        );
        assert!(
            exact < 0.01 && exact_offset < 0.01,
            "{exact} {exact_offset}"
        );
        assert!(zero[0].abs() < 0.01, "{zero:?}");
        // The offset state finds the offset and the coil converges to the
        // truth.
        assert!((found[0] - 3.0).abs() < 0.05, "{found:?}");
        assert!(max < 0.05, "{mean} / {max}");
        // Without it the coil stays off: a little with temperatures only
        // (the sensor holds the housing, the model pulls it to the cold
        // coolant), by 15 K with the heat disturbance, which explains the
        // cold model as heat in the coil (the housing right, the coil not).
        assert!(plain > 0.03 && plain > 5.0 * mean, "{plain} {mean}");
        assert!(heat_mean > 10.0, "{heat_mean}");
        // With both and the one sensor the split is the priors': a heat in
        // the coil and a coolant offset that leave the housing where it is
        // (`o = -d / G_housing-coolant`) form an unobservable direction
        // (exactly so for constant states, weakly with the decays), and the
        // coil is off along it.
        assert!(both_mean > 1.0, "{both_mean} {both_found:?}");
    }

    /// The floor at zero lets the offset warm the links, never cool them:
    /// behind a coolant reading 3 K low it is not in the way (the offset
    /// found, the coil exact); behind one 3 K high, which a free offset
    /// follows down to -3 K, it holds the offset at 0, and the coil reads
    /// no colder and no further off than with no offset state at all. The
    /// reference is the plant run with the true coolant.
    #[test]
    fn a_boundary_offset_floor_at_zero_never_cools_the_model() {
        let free = KalmanOptions {
            boundary_offsets: vec![0],
            boundary_offset_std_k: 3.0,
            boundary_offset_tau_s: 7200.0,
            ..KalmanOptions::default()
        };
        let floored = KalmanOptions {
            boundary_offset_floor_k: Some(0.0),
            ..free.clone()
        };
        let low = coil_errors(3.0, floored.clone());
        let free = coil_errors(-3.0, free);
        let high = coil_errors(-3.0, floored);
        let none = coil_errors(-3.0, KalmanOptions::default());
        eprintln!(
            "coolant 3 K low, floored: offset {:.3} K, coil max |error| {:.4} K; \
             3 K high: free offset {:.3} K (max {:.4} K), floored offset {:.4} K \
             (mean {:.4}, coldest {:.4} K; without the state {:.4}, {:.4} K)",
            low.offsets_k[0],
            low.max_k,
            free.offsets_k[0],
            free.max_k,
            high.offsets_k[0],
            high.mean_k,
            high.coldest_k,
            none.mean_k,
            none.coldest_k
        );
        assert!((low.offsets_k[0] - 3.0).abs() < 0.05 && low.max_k < 0.05);
        assert!((free.offsets_k[0] + 3.0).abs() < 0.05 && free.max_k < 0.05);
        assert!(
            high.offsets_k[0] >= 0.0 && high.offsets_k[0] < 1e-6,
            "{:?}",
            high.offsets_k
        );
        assert!(
            high.coldest_k >= none.coldest_k - 1e-3 && high.mean_k <= none.mean_k + 1e-3,
            "floored {} / {}, without the state {} / {}",
            high.mean_k,
            high.coldest_k,
            none.mean_k,
            none.coldest_k
        );
    }

    /// The learned noise is the sensor's: white noise of a known standard
    /// deviation on a slow ramp is found to within 10 %, and a clean ramp
    /// (a thermal signal alone) reads as almost no noise.
    #[test]
    fn the_noise_watch_finds_a_sensors_noise_and_not_its_signal() {
        let mut rng = crate::synth::Rng::new(3);
        for sigma in [0.1, 0.6] {
            let mut watch = NoiseWatch::new(10, 600);
            let mut found = None;
            for k in 0..3000 {
                let signal = 30.0 + 0.01 * f64::from(k);
                found = watch.push(signal + sigma * rng.normal());
            }
            let found = found.unwrap().sqrt();
            assert!((found - sigma).abs() < 0.1 * sigma, "{sigma}: {found}");
        }
        // Non-finite readings are skipped, not averaged in.
        let mut watch = NoiseWatch::new(10, 600);
        let mut found = None;
        for k in 0..3000 {
            let reading = match k % 97 {
                0 => f64::INFINITY,
                1 => f64::NAN,
                2 => f64::NEG_INFINITY,
                _ => 30.0 + 0.3 * rng.normal(),
            };
            found = watch.push(reading);
        }
        let found = found.unwrap().sqrt();
        assert!(
            (found - 0.3).abs() < 0.03,
            "with non-finite readings: {found}"
        );
        let mut watch = NoiseWatch::new(10, 600);
        let mut found = None;
        for k in 0..3000 {
            // A first-order rise, 20 K with a 300 s time constant.
            found = watch.push(30.0 + 20.0 * (1.0 - (-f64::from(k) / 300.0).exp()));
        }
        assert!(found.unwrap().sqrt() < 0.01, "{found:?}");
    }

    /// 6000 s of the jacket plant driven by 1.5 A / 0.5 A steps with
    /// `heat_ratio` times the model's coil heat, and the filter fusing its
    /// housing sensor with `noise_k` of seeded Gaussian noise; `each` sees
    /// every row after its correction.
    fn jacket_run(
        opts: KalmanOptions,
        heat_ratio: f64,
        noise_k: f64,
        mut each: impl FnMut(usize, &KalmanEstimator, &FilePlant),
    ) {
        let (mut plant, mut filter) = jacket(opts);
        let mut rng = crate::synth::Rng::new(11);
        for k in 0..6000 {
            let current = if (k / 1000) % 2 == 0 { 1.5 } else { 0.5 };
            plant.step(1.0, &[current * heat_ratio.sqrt()], &[30.0], &[]);
            filter.predict(1.0, &[current], &[30.0], &[]);
            filter.update(&[Measurement {
                node: 1,
                value_c: plant.temps_c()[1] + noise_k * rng.normal(),
                fault: None,
            }]);
            each(k, &filter, &plant);
        }
    }

    /// A housing sensor five times noisier than declared (1 K against
    /// 0.2 K), on a plant with 20 % more coil heat than the model (the
    /// filter has to find it through the sensor): learning the sensor's
    /// noise keeps the unmeasured coil closer to the plant (the
    /// independent reference) than trusting the declared figure.
    #[test]
    fn learning_a_noisy_sensors_noise_keeps_the_unmeasured_node_closer() {
        let run = |learn: bool| {
            let opts = KalmanOptions {
                disturbances: vec![vec![0]],
                disturbance_std_w: 2.0,
                noise_from_readings: learn.then_some(NoiseFromReadings {
                    half_window: 10,
                    memory: 600,
                }),
                ..KalmanOptions::default()
            };
            let (mut sum_sq, mut rows) = (0.0, 0.0);
            jacket_run(opts, 1.2, 1.0, |k, filter, plant| {
                if k >= 600 {
                    sum_sq += (filter.estimate_c()[0] - plant.temps_c()[0]).powi(2);
                    rows += 1.0;
                }
            });
            (sum_sq / rows).sqrt()
        };
        let (declared, learned) = (run(false), run(true));
        eprintln!("coil RMS error [K]: declared noise {declared:.3}, learned {learned:.3}");
        assert!(learned < 0.7 * declared, "{learned} vs {declared}");
    }

    /// A model that runs 25 % hot (the plant's coil has 80 % of the
    /// model's heat): free, the disturbance goes negative and takes the
    /// heat away; with the floor (`share` 0, the firmware's default for its
    /// heat biases) it never goes below zero, and the unmeasured coil reads
    /// hot against the plant (the independent reference), never cold.
    #[test]
    fn a_disturbance_floor_keeps_heat_from_being_taken_away() {
        let run = |floor: Option<f64>| {
            let opts = KalmanOptions {
                disturbances: vec![vec![0]],
                disturbance_std_w: 2.0,
                disturbance_floor_share: floor,
                ..KalmanOptions::default()
            };
            let (mut lowest_w, mut coldest_k, mut hottest_k) = (f64::INFINITY, 0.0_f64, 0.0_f64);
            jacket_run(opts, 0.8, 0.0, |_, filter, plant| {
                lowest_w = lowest_w.min(filter.disturbances_w()[0]);
                let error = filter.estimate_c()[0] - plant.temps_c()[0];
                coldest_k = coldest_k.min(error);
                hottest_k = hottest_k.max(error);
            });
            (lowest_w, coldest_k, hottest_k)
        };
        let (free_w, free_cold, _) = run(None);
        let (floor_w, floor_cold, floor_hot) = run(Some(0.0));
        eprintln!(
            "lowest disturbance {free_w:.3} / {floor_w:.3} W, coldest coil error {free_cold:.3} / {floor_cold:.3} K (free / floor 0), hottest with the floor {floor_hot:.3} K"
        );
        assert!(free_w < -1.0, "{free_w}");
        assert!(free_cold < -0.2, "free, the coil reads cold: {free_cold}");
        assert!(floor_w > -1e-9, "{floor_w}");
        assert!(floor_cold > -0.05, "{floor_cold}");
        assert!(floor_hot > 0.5, "the model's extra heat shows: {floor_hot}");
    }

    /// A block cooled through a path whose conductance grows with speed
    /// (`G = 10 (1 + f)` W/K, `f` = speed / 1000 rpm), unsensed: the filter's
    /// prediction is the exact solution of each interval's network, so
    /// across a speed step it follows the two exponentials of the
    /// analytic solution, not the first network's.
    #[test]
    fn the_filter_follows_a_network_whose_conductance_changes_with_speed() {
        const BLOCK: &str = r#"
name = "block"
[[node]]
name = "block"
capacity_j_per_k = 1000.0
[[node]]
name = "probe"
capacity_j_per_k = 1.0
[[boundary]]
name = "coolant"
value_c = 20.0
[[conductance]]
between = ["block", "coolant"]
g_w_per_k = 10.0
[conductance.speed]
column = "speed"
reference = 1000.0
a1 = 1.0
[[conductance]]
between = ["probe", "coolant"]
g_w_per_k = 1.0
"#;
        let model = Model::build(&ModelFile::parse(BLOCK, "block.toml").unwrap()).unwrap();
        assert_eq!(model.signals, ["speed"]);
        let mut filter = KalmanEstimator::new(model, &[1], KalmanOptions::default()).unwrap();
        filter.reset(&[60.0, 20.0]);
        let no_reading = [Measurement {
            node: 1,
            value_c: f64::NAN,
            fault: None,
        }];
        let mut worst_k: f64 = 0.0;
        for k in 1..=200 {
            let speed_rpm = if k <= 100 { 0.0 } else { 3000.0 };
            filter.predict(1.0, &[], &[20.0], &[speed_rpm]);
            filter.update(&no_reading);
            let t = f64::from(k);
            let exact_c = if k <= 100 {
                20.0 + 40.0 * (-10.0 * t / 1000.0).exp()
            } else {
                20.0 + 40.0 * (-1.0f64).exp() * (-40.0 * (t - 100.0) / 1000.0).exp()
            };
            worst_k = worst_k.max((filter.estimate_c()[0] - exact_c).abs());
        }
        assert!(worst_k < 1e-9, "worst error {worst_k} K");
    }

    #[test]
    fn a_boundary_offset_is_refused_for_an_unknown_or_repeated_boundary() {
        let model = Model::build(&ModelFile::parse(MODEL, "jacket.toml").unwrap()).unwrap();
        for offsets in [vec![1], vec![0, 0]] {
            let opts = KalmanOptions {
                boundary_offsets: offsets.clone(),
                ..KalmanOptions::default()
            };
            assert!(
                KalmanEstimator::new(model.clone(), &[1], opts).is_err(),
                "{offsets:?}"
            );
        }
        let opts = KalmanOptions {
            boundary_offset_tau_s: 0.0,
            ..KalmanOptions::default()
        };
        assert!(KalmanEstimator::new(model, &[1], opts).is_err());
    }
}
