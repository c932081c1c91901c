//! Sensor fusion for `replay --measure`: the library's Kalman filter
//! (`coil_thermal::filter`) on a model file, at run-time size.
//!
//! # Why a mirror
//! The library filter has const-generic sizes; a model file's size is known
//! only at run time. [`DynKalman`] is the library's time-varying filter with
//! `nalgebra::DMatrix`: the same predict (`x = F x + G u`,
//! `P = F P F^T + Q`, symmetrised), the same gate (every reading against the
//! prior, chi-square 1 dof, default [`CHI2_1DOF_999`]), the same sequential
//! Joseph update and the same suspect and recovery counters, with the same
//! nalgebra operations in the same order, so that on a fixed-size instance
//! both give identical results (tested in `tests/kalman_mirror.rs`).
//! [`expm_with_integral`] mirrors `coil_thermal::discretize::expm_with_integral`
//! the same way.
//!
//! # The model the filter runs
//! The model file's network is linear except for `R(T)`: for every node `i`
//! `C_i dT_i/dt = sum_j G_ij (T_j - T_i) + sum_b G_ib (T_b - T_i) + P_i + d_i`.
//! As the library's observer does, the Joule powers `max(R(T_est), 0) I^2` are
//! evaluated at the current estimate each step and enter as inputs, so `A`
//! stays constant and is discretised once per sample period (exact ZOH:
//! `F = exp(A dt)`, `G = Phi [B | G_b | d]`, `Phi = int_0^dt exp(A s) ds`).
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
//! # Noise
//! * Temperatures: white heat-flow noise, `Q_T = q dt I` with `q` in K^2/s
//!   (`--process-noise-k2-per-s`).
//! * Disturbances: `Q_d = sigma_d^2 (1 - exp(-2 dt / tau))` per step, the exact
//!   discrete variance of the Gauss-Markov process.
//! * Sensors: `r = sigma^2` with `sigma` in K (`--measurement-noise-k`).
//!
//! Cross-terms of `Q` between temperatures and disturbances over one step
//! are neglected (a step is short against every time constant).

use anyhow::{bail, Result};
use coil_thermal::filter::{SensorVerdict, CHI2_1DOF_999};
use nalgebra::{DMatrix, DVector};

use crate::model_file::Model;
use crate::observer::{Estimator, Measurement};
use crate::sim::{FilePlant, Plant, PlantInfo};

/// Taylor terms at the scaled step (as the library).
const TAYLOR_TERMS: usize = 16;
/// Most halvings of the step (as the library).
const MAX_SQUARINGS: u32 = 60;

/// `exp(A h)` and `integral_0^h exp(A s) ds` by scaling and squaring: the
/// library's `expm_with_integral` at run-time size.
pub fn expm_with_integral(a: &DMatrix<f64>, h: f64) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    if !(h.is_finite() && h > 0.0) {
        bail!("the step must be finite and > 0 s, got {h}");
    }
    let n = a.nrows();
    let ah = a * h;
    if !ah.iter().all(|v| v.is_finite()) {
        bail!("the system matrix is not finite");
    }
    let norm = ah
        .column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    if !norm.is_finite() {
        bail!("the system matrix is not finite");
    }
    let mut squarings = 0;
    let mut scale = 1.0;
    while norm * scale > 0.25 {
        squarings += 1;
        scale *= 0.5;
        if squarings > MAX_SQUARINGS {
            bail!("the system matrix is too large");
        }
    }
    let scaled_h = h * scale;
    let x = a * scaled_h;
    let identity = DMatrix::<f64>::identity(n, n);
    let mut term = identity.clone();
    let mut e = identity.clone();
    let mut phi = identity.clone();
    for k in 1..TAYLOR_TERMS {
        term = term * &x / (k as f64);
        e += &term;
        phi += &term / ((k + 1) as f64);
    }
    let mut phi = phi * scaled_h;
    for _ in 0..squarings {
        phi *= &identity + &e;
        e = &e * &e;
    }
    Ok((e, phi))
}

/// The library's `KalmanConfig` at run-time size (N states, M inputs,
/// P sensors).
#[derive(Debug, Clone, PartialEq)]
pub struct DynKalman {
    /// State transition `F` (N x N).
    pub f: DMatrix<f64>,
    /// Input matrix `G` (N x M).
    pub g: DMatrix<f64>,
    /// `H^T` (N x P): column `j` is sensor `j`'s row of `H`.
    pub ht: DMatrix<f64>,
    /// Process noise per step (N x N).
    pub q: DMatrix<f64>,
    /// Measurement noise variances (P).
    pub r: DVector<f64>,
    /// Gate threshold on `nu^2 / S`.
    pub threshold: f64,
    /// Suspect after this many consecutive rejections (0: never).
    pub suspect_after: u16,
    /// Recovery after this many all-rejected corrections (0: never).
    pub recover_after: u16,
    /// Variances added to the diagonal of `P` on recovery.
    pub recovery_variance: DVector<f64>,
}

impl DynKalman {
    /// The library's defaults: gate [`CHI2_1DOF_999`], suspect after 3,
    /// recovery after 5 adding `1e4 max(r)` to every diagonal entry.
    pub fn new(
        f: DMatrix<f64>,
        g: DMatrix<f64>,
        h: DMatrix<f64>,
        q: DMatrix<f64>,
        r: DVector<f64>,
    ) -> Result<Self> {
        let n = f.nrows();
        if f.ncols() != n || g.nrows() != n || h.ncols() != n || q.shape() != (n, n) {
            bail!("inconsistent filter matrix sizes");
        }
        if h.nrows() != r.len() {
            bail!("one measurement noise per sensor row");
        }
        if r.iter().any(|v| !v.is_finite() || *v <= 0.0) {
            bail!("measurement noise variances must be finite and > 0");
        }
        if ![&f, &g, &h, &q]
            .iter()
            .all(|m| m.iter().all(|v| v.is_finite()))
        {
            bail!("filter matrices must be finite");
        }
        let r_max = r.iter().fold(0.0f64, |a, v| a.max(*v));
        Ok(Self {
            f,
            g,
            ht: h.transpose(),
            q: q.symmetric_part(),
            r,
            threshold: CHI2_1DOF_999,
            suspect_after: 3,
            recover_after: 5,
            recovery_variance: DVector::repeat(n, r_max * 1e4),
        })
    }
}

/// The library's `KalmanState` (with its `GateCounters`) at run-time size.
#[derive(Debug, Clone, PartialEq)]
pub struct DynKalmanState {
    /// Estimate.
    pub x: DVector<f64>,
    /// Covariance.
    pub cov: DMatrix<f64>,
    /// Consecutive rejections per sensor.
    pub consecutive_rejections: Vec<u16>,
    /// Consecutive corrections with every present reading rejected.
    pub all_rejected_streak: u16,
}

impl DynKalmanState {
    /// A state with estimate `x0`, covariance `p0` and `sensors` counters.
    pub fn new(x0: DVector<f64>, p0: DMatrix<f64>, sensors: usize) -> Self {
        Self {
            x: x0,
            cov: p0,
            consecutive_rejections: vec![0; sensors],
            all_rejected_streak: 0,
        }
    }
}

/// What a correction did (the library's `UpdateReport`).
#[derive(Debug, Clone, PartialEq)]
pub struct DynUpdateReport {
    /// One verdict per sensor.
    pub verdicts: Vec<SensorVerdict>,
    /// Suspect flags after this correction.
    pub suspect: Vec<bool>,
    /// The covariance was inflated and the readings re-gated.
    pub recovered: bool,
}

/// Full predict (the library's `predict`); `false` when a non-finite input
/// dropped the `G u` term.
pub fn predict(cfg: &DynKalman, state: &mut DynKalmanState, u: &DVector<f64>) -> bool {
    let prev = state.x.clone();
    state.x.gemv(1.0, &cfg.f, &prev, 0.0);
    let used = u.iter().all(|v| v.is_finite());
    if used {
        state.x.gemv(1.0, &cfg.g, u, 1.0);
    }
    let prev = state.cov.clone();
    state.cov.copy_from(&cfg.q);
    state.cov.quadform_tr(1.0, &cfg.f, &prev, 1.0);
    state.cov = state.cov.symmetric_part();
    used
}

fn nis_f32(nis: f64) -> f32 {
    nis as f32
}

fn judge(nu: f64, s: f64, threshold: f64) -> SensorVerdict {
    let nis = nu * nu / s;
    if !nis.is_finite() || !s.is_finite() || s <= 0.0 {
        return SensorVerdict::Rejected { nis: f32::INFINITY };
    }
    if nis > threshold {
        SensorVerdict::Rejected { nis: nis_f32(nis) }
    } else {
        SensorVerdict::Fused { nis: nis_f32(nis) }
    }
}

fn usable(z: Option<f64>) -> Option<f64> {
    z.filter(|v| v.is_finite())
}

fn gate_all(
    cfg: &DynKalman,
    x: &DVector<f64>,
    cov: &DMatrix<f64>,
    z: &[Option<f64>],
) -> Vec<SensorVerdict> {
    let mut verdicts = vec![SensorVerdict::Missing; z.len()];
    for (j, (verdict, zj)) in verdicts.iter_mut().zip(z).enumerate() {
        let Some(zj) = usable(*zj) else { continue };
        let h = cfg.ht.column(j);
        let s = h.dot(&(cov * h)) + cfg.r[j];
        let nu = zj - h.dot(x);
        *verdict = judge(nu, s, cfg.threshold);
    }
    verdicts
}

fn fuse_scalar(
    x: &mut DVector<f64>,
    cov: &mut DMatrix<f64>,
    h: &DVector<f64>,
    r: f64,
    z: f64,
) -> bool {
    let b = &*cov * h;
    let s = h.dot(&b) + r;
    if !s.is_finite() || s <= 0.0 {
        return false;
    }
    let k = b.clone() / s;
    let nu = z - h.dot(x);
    let mut x_new = x.clone();
    x_new.axpy(nu, &k, 1.0);
    if !x_new.iter().all(|v| v.is_finite()) {
        return false;
    }
    let mut w = cov.clone();
    w.ger(-1.0, &k, &b, 1.0);
    let c = &w * h;
    w.ger(-1.0, &c, &k, 1.0);
    w.ger(r, &k, &k, 1.0);
    let w = w.symmetric_part();
    if !w.iter().all(|v| v.is_finite()) {
        return false;
    }
    *x = x_new;
    *cov = w;
    true
}

/// Correction (the library's `update`): `z[j] = None` (or non-finite) skips
/// sensor `j`; every present reading is gated against the prior, the accepted
/// ones fused one by one (Joseph form), then counters and recovery applied.
pub fn update(cfg: &DynKalman, state: &mut DynKalmanState, z: &[Option<f64>]) -> DynUpdateReport {
    let mut verdicts = gate_all(cfg, &state.x, &state.cov, z);
    // record_gate
    let present = verdicts
        .iter()
        .any(|v| !matches!(v, SensorVerdict::Missing));
    let mut recovered = false;
    if present {
        if verdicts.iter().all(|v| !v.is_fused()) {
            state.all_rejected_streak = state.all_rejected_streak.saturating_add(1);
            if cfg.recover_after != 0 && state.all_rejected_streak >= cfg.recover_after {
                state.all_rejected_streak = 0;
                recovered = true;
            }
        } else {
            state.all_rejected_streak = 0;
        }
    }
    if recovered {
        for (i, v) in cfg.recovery_variance.iter().enumerate() {
            state.cov[(i, i)] += *v;
        }
        verdicts = gate_all(cfg, &state.x, &state.cov, z);
    }
    for (j, (verdict, zj)) in verdicts.iter_mut().zip(z).enumerate() {
        let SensorVerdict::Fused { nis } = *verdict else {
            continue;
        };
        let Some(zj) = usable(*zj) else { continue };
        let h: DVector<f64> = cfg.ht.column(j).into_owned();
        if !fuse_scalar(&mut state.x, &mut state.cov, &h, cfg.r[j], zj) {
            *verdict = SensorVerdict::Rejected { nis };
        }
    }
    let mut suspect = vec![false; verdicts.len()];
    for ((count, verdict), flag) in state
        .consecutive_rejections
        .iter_mut()
        .zip(&verdicts)
        .zip(suspect.iter_mut())
    {
        match verdict {
            SensorVerdict::Fused { .. } => *count = 0,
            SensorVerdict::Rejected { .. } => *count = count.saturating_add(1),
            SensorVerdict::Missing => {}
        }
        *flag = cfg.suspect_after != 0 && *count >= cfg.suspect_after;
    }
    DynUpdateReport {
        verdicts,
        suspect,
        recovered,
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
    /// Gate threshold on `nu^2 / S` (chi-square, 1 dof).
    pub gate: f64,
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
            gate: CHI2_1DOF_999,
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
        pos(self.gate, "--gate")?;
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
}

/// A Kalman filter on a model file (see the module docs).
pub struct KalmanEstimator {
    model: Model,
    info: PlantInfo,
    opts: KalmanOptions,
    /// Temperature states then disturbance states.
    states: usize,
    /// Continuous `A` and input matrix `[B | G_b | d]`.
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    /// Cached filter for the last sample period.
    cfg: Option<(f64, DynKalman)>,
    sensors: Vec<usize>,
    state: DynKalmanState,
    temps: Vec<f64>,
    effective: Vec<f64>,
    stats: Vec<FusionStats>,
    recoveries: usize,
}

impl KalmanEstimator {
    /// A filter on `model` fusing sensors at `sensor_nodes` (node indices, in
    /// the order of the readings [`Estimator::update`] receives).
    pub fn new(model: Model, sensor_nodes: &[usize], opts: KalmanOptions) -> Result<Self> {
        opts.validate()?;
        if sensor_nodes.is_empty() {
            bail!("the Kalman filter needs at least one --measure sensor");
        }
        let info = FilePlant::new(model.clone()).info().clone();
        let net = &model.network;
        let n = net.nodes();
        let nd = opts.disturbances.len();
        let states = n + nd;
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
            if nodes.is_empty() {
                bail!("--disturbance: an empty node list");
            }
            if let Some(i) = nodes.iter().find(|i| **i >= n) {
                bail!("--disturbance: node index {i} out of range");
            }
            let total: f64 = nodes.iter().map(|i| caps[*i]).sum();
            for i in nodes {
                // Share caps[i] / total of d at node i: dT_i/dt += d / total.
                a[(*i, n + k)] += 1.0 / total;
            }
            a[(n + k, n + k)] = -1.0 / opts.disturbance_tau_s;
        }
        let stats = sensor_nodes
            .iter()
            .map(|&node| FusionStats {
                node,
                fused: 0,
                rejected: 0,
            })
            .collect();
        Ok(Self {
            state: DynKalmanState::new(
                DVector::zeros(states),
                DMatrix::zeros(states, states),
                sensor_nodes.len(),
            ),
            model,
            info,
            opts,
            states,
            a,
            b,
            cfg: None,
            sensors: sensor_nodes.to_vec(),
            temps: vec![0.0; n],
            effective: Vec::new(),
            stats,
            recoveries: 0,
        })
    }

    /// Makes `self.cfg` the filter for a sample period `dt_s` (discretised
    /// when the period changes).
    fn ensure_filter(&mut self, dt_s: f64) -> Result<()> {
        let stale = match &self.cfg {
            Some((dt, _)) => (dt - dt_s).abs() > 1e-9 * dt_s.abs().max(1.0),
            None => true,
        };
        if stale {
            let (f, phi) = expm_with_integral(&self.a, dt_s)?;
            let g = &phi * &self.b;
            let n = self.temps.len();
            let mut q = DMatrix::<f64>::zeros(self.states, self.states);
            for i in 0..n {
                q[(i, i)] = self.opts.process_noise_k2_per_s * dt_s;
            }
            let decay = (-2.0 * dt_s / self.opts.disturbance_tau_s).exp();
            for k in n..self.states {
                q[(k, k)] = self.opts.disturbance_std_w.powi(2) * (1.0 - decay);
            }
            let mut h = DMatrix::<f64>::zeros(self.sensors.len(), self.states);
            for (j, node) in self.sensors.iter().enumerate() {
                h[(j, *node)] = 1.0;
            }
            let r = DVector::repeat(self.sensors.len(), self.opts.measurement_noise_k.powi(2));
            let mut cfg = DynKalman::new(f, g, h, q, r)?;
            cfg.threshold = self.opts.gate;
            // Recovery returns to the prior's uncertainty: the library's
            // default (1e4 r on every state) would put hundreds of K^2 on the
            // unmeasured nodes, which one sensor cannot pull back, and the
            // disturbances would then swing them by tens of K.
            cfg.recovery_variance = self.prior_variances();
            self.cfg = Some((dt_s, cfg));
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
        self.state
            .x
            .iter()
            .skip(self.temps.len())
            .copied()
            .collect()
    }

    /// Initial variances: `initial_std_k^2` per temperature,
    /// `disturbance_std_w^2` per disturbance.
    fn prior_variances(&self) -> DVector<f64> {
        let n = self.temps.len();
        DVector::from_fn(self.states, |i, _| {
            if i < n {
                self.opts.initial_std_k.powi(2)
            } else {
                self.opts.disturbance_std_w.powi(2)
            }
        })
    }

    fn sync_temps(&mut self) {
        let n = self.temps.len();
        self.temps.copy_from_slice(&self.state.x.as_slice()[..n]);
    }
}

impl Estimator for KalmanEstimator {
    fn info(&self) -> &PlantInfo {
        &self.info
    }

    fn reset(&mut self, temps_c: &[f64]) {
        let n = self.temps.len();
        let mut x = DVector::zeros(self.states);
        x.as_mut_slice()[..n].copy_from_slice(temps_c);
        let p0 = DMatrix::from_diagonal(&self.prior_variances());
        self.state = DynKalmanState::new(x, p0, self.sensors.len());
        self.sync_temps();
    }

    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        let mut effective = std::mem::take(&mut self.effective);
        self.model
            .effective_currents(currents_a, signals, &mut effective);
        let net = &self.model.network;
        let mut u = DVector::zeros(self.b.ncols());
        for (s, (src, i)) in net.sources().iter().zip(&effective).enumerate() {
            let t = self.temps[src.node];
            let r = (src.resistance.r_at_0c_ohm + src.resistance.slope_ohm_per_k * t).max(0.0);
            u[s] = r * i * i;
        }
        let m = net.sources().len();
        for (k, t) in boundary_c.iter().enumerate() {
            u[m + k] = *t;
        }
        u[m + boundary_c.len()] = 1.0;
        self.effective = effective;
        // A sample period the model cannot be discretised for (non-finite or
        // not positive) leaves the estimate where it is.
        if self.ensure_filter(dt_s).is_err() {
            return;
        }
        let Some((_, cfg)) = &self.cfg else { return };
        predict(cfg, &mut self.state, &u);
        self.sync_temps();
    }

    fn update(&mut self, measured: &[Measurement]) {
        // Before the first predict there is no filter yet: one for a unit
        // step serves (a correction uses only H, r and the gate).
        if self.cfg.is_none() && self.ensure_filter(1.0).is_err() {
            return;
        }
        let Some((_, cfg)) = &self.cfg else { return };
        let z: Vec<Option<f64>> = self
            .sensors
            .iter()
            .enumerate()
            .map(|(j, node)| {
                measured
                    .get(j)
                    .filter(|m| m.node == *node)
                    .map(|m| m.value_c)
            })
            .collect();
        let report = update(cfg, &mut self.state, &z);
        for (s, v) in self.stats.iter_mut().zip(&report.verdicts) {
            match v {
                SensorVerdict::Fused { .. } => s.fused += 1,
                SensorVerdict::Rejected { .. } => s.rejected += 1,
                SensorVerdict::Missing => {}
            }
        }
        self.recoveries += usize::from(report.recovered);
        self.sync_temps();
    }

    fn estimate_c(&self) -> &[f64] {
        &self.temps
    }

    fn kind(&self) -> &'static str {
        "kalman"
    }
}
