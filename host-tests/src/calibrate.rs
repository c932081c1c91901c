//! Calibration: bounded Levenberg-Marquardt over named model parameters.
//!
//! Parameters are addressed by name in the model file (see [`ParamSpec`]).
//! Each has a box `[lo, hi]`. A parameter whose box is strictly positive is
//! fitted in `ln p` (capacities, conductances, resistances: scale-free steps,
//! and positivity for free); any other in `p / s` with `s` its starting
//! magnitude. Steps are projected onto the box. The Jacobian is by forward
//! differences (backward at an upper bound). The damped normal equations
//! `(J'J + lambda diag(J'J)) dx = -J'r` are solved by Cholesky
//! (Marquardt's scaling); lambda falls by 3 after a successful step and rises
//! by 4 after a failed one.
//!
//! The residuals are simulated minus measured temperatures \[K\] of every
//! target sensor at every `stride`-th row (row 0, the initial state, is
//! skipped), over every trace; a missing reading (`NaN`, an empty cell)
//! gives no residual. Each residual is scaled by the square root of its
//! trace's weight (see [`Weighting`]), and the standard errors and
//! correlations come from the same weighted residuals.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use crate::model_file::{Model, ModelFile};
use crate::observer::{score, Score, Sensor};
use crate::sim::{initial_temps, plant_info, simulate, Drive, FilePlant, Plant};

/// A parameter to fit and its bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSpec {
    /// Name, e.g. `capacity.winding`, `conductance.winding-stator`,
    /// `conductance.<name>.factor`, `conductance.<name>.h_w_per_m2k`,
    /// `source.<name>.r0_ohm` (also `alpha_per_k`, `slope_ohm_per_k`,
    /// `r_at_0c_ohm`, `scale`, `speed_a1`, `speed_a2`), `fixed_power.<node>`,
    /// `speed_loss.<name>.p1_w` (and `.p2_w`),
    /// and for the HPPA grid `grid.rx_k_per_w`, `grid.ry_k_per_w` (between
    /// two coils), `grid.rz_k_per_w`, `grid.capacity_j_per_k` (every coil at
    /// once, see [`crate::devices`]).
    pub name: String,
    /// Lower bound (None: the default for the parameter).
    pub lo: Option<f64>,
    /// Upper bound.
    pub hi: Option<f64>,
}

impl ParamSpec {
    /// Parses `NAME` or `NAME=LO:HI` (either side of `:` may be empty).
    pub fn parse(text: &str) -> Result<Self> {
        let (name, bounds) = match text.split_once('=') {
            Some((n, b)) => (n.trim(), Some(b)),
            None => (text.trim(), None),
        };
        if name.is_empty() {
            bail!("empty parameter name in `{text}`");
        }
        let (mut lo, mut hi) = (None, None);
        if let Some(b) = bounds {
            let (l, h) = b
                .split_once(':')
                .with_context(|| format!("`{text}`: bounds are LO:HI"))?;
            let num = |s: &str| -> Result<Option<f64>> {
                let s = s.trim();
                if s.is_empty() {
                    return Ok(None);
                }
                let v: f64 = s
                    .parse()
                    .with_context(|| format!("`{text}`: `{s}` is not a number"))?;
                if v.is_nan() {
                    bail!("`{text}`: NaN bound");
                }
                Ok(Some(v))
            };
            lo = num(l)?;
            hi = num(h)?;
        }
        Ok(Self {
            name: name.to_string(),
            lo,
            hi,
        })
    }
}

fn node_mut<'a>(
    file: &'a mut ModelFile,
    name: &str,
) -> Result<&'a mut crate::model_file::NodeSpec> {
    let names: Vec<String> = file.nodes.iter().map(|n| n.name.clone()).collect();
    file.nodes
        .iter_mut()
        .find(|n| n.name == name)
        .with_context(|| format!("no node `{name}` (nodes: {})", names.join(", ")))
}

/// Reads (`set = None`) or writes a named parameter; returns the value
/// before the write. `A|B|...` ties parameters: one value, written to all,
/// read from the first (e.g. one copper-loss density for several sources).
pub fn access_param(file: &mut ModelFile, name: &str, set: Option<f64>) -> Result<f64> {
    let mut parts = name.split('|');
    let first = parts.next().unwrap_or(name);
    let old = access_one(file, first.trim(), set)?;
    for other in parts {
        access_one(file, other.trim(), set)?;
    }
    Ok(old)
}

fn access_one(file: &mut ModelFile, name: &str, set: Option<f64>) -> Result<f64> {
    let (kind, rest) = name
        .split_once('.')
        .with_context(|| format!("parameter `{name}`: expected KIND.NAME[.FIELD]"))?;
    match kind {
        "capacity" => {
            let n = node_mut(file, rest)?;
            let old = n.capacity_j_per_k;
            if let Some(v) = set {
                n.capacity_j_per_k = v;
            }
            Ok(old)
        }
        "conductance" => {
            let keys: Vec<String> = file.conductances.iter().map(|c| c.key()).collect();
            let (key, field) = if let Some(k) = keys.iter().find(|k| k.as_str() == rest) {
                (k.clone(), "g")
            } else {
                match rest.rsplit_once('.') {
                    Some((k, f)) if keys.iter().any(|x| x == k) => (k.to_string(), f),
                    _ => bail!(
                        "parameter `{name}`: no conductance `{rest}` (conductances: {})",
                        keys.join(", ")
                    ),
                }
            };
            let c = file
                .conductances
                .iter_mut()
                .find(|c| c.key() == key)
                .expect("key listed above");
            match field {
                "g" => {
                    let old = c.base_w_per_k()?;
                    if let Some(v) = set {
                        if c.r_k_per_w.is_some() {
                            c.r_k_per_w = Some(1.0 / v);
                        } else if let (Some(_), Some(a)) = (c.h_w_per_m2k, c.area_m2) {
                            c.h_w_per_m2k = Some(v / a);
                        } else {
                            c.g_w_per_k = Some(v);
                        }
                    }
                    Ok(old)
                }
                "factor" => {
                    let old = c.factor.unwrap_or(1.0);
                    if let Some(v) = set {
                        c.factor = Some(v);
                    }
                    Ok(old)
                }
                "h_w_per_m2k" => {
                    let old = c.h_w_per_m2k.with_context(|| {
                        format!("`{name}`: conductance `{key}` has no h_w_per_m2k")
                    })?;
                    if let Some(v) = set {
                        c.h_w_per_m2k = Some(v);
                    }
                    Ok(old)
                }
                "speed_a1" | "speed_a2" | "r_exp_k_per_w" | "exp_rate" => {
                    let law = c.speed.as_mut().with_context(|| {
                        format!("`{name}`: conductance `{key}` has no [conductance.speed]")
                    })?;
                    let v = match field {
                        "speed_a1" => &mut law.a1,
                        "speed_a2" => &mut law.a2,
                        "r_exp_k_per_w" => &mut law.r_exp_k_per_w,
                        _ => &mut law.exp_rate,
                    };
                    let old = *v;
                    if let Some(new) = set {
                        *v = new;
                    }
                    Ok(old)
                }
                f => bail!(
                    "parameter `{name}`: unknown conductance field `{f}` (factor, h_w_per_m2k, speed_a1, speed_a2, r_exp_k_per_w, exp_rate)"
                ),
            }
        }
        "source" => {
            let (key, field) = rest
                .rsplit_once('.')
                .with_context(|| format!("parameter `{name}`: expected source.NAME.FIELD"))?;
            let keys: Vec<String> = file.sources.iter().map(|s| s.key().to_string()).collect();
            let s = file
                .sources
                .iter_mut()
                .find(|s| s.key() == key)
                .with_context(|| {
                    format!(
                        "parameter `{name}`: no source `{key}` (sources: {})",
                        keys.join(", ")
                    )
                })?;
            let slot: &mut Option<f64> = match field {
                "r0_ohm" => &mut s.r0_ohm,
                "alpha_per_k" => &mut s.alpha_per_k,
                "slope_ohm_per_k" => &mut s.slope_ohm_per_k,
                "r_at_0c_ohm" => &mut s.r_at_0c_ohm,
                "scale_per_kj" => &mut s.scale_per_kj,
                "scale" => {
                    if s.scale.is_none() {
                        s.scale = Some(1.0);
                    }
                    &mut s.scale
                }
                "speed_a1" | "speed_a2" => {
                    let sp = s
                        .speed
                        .as_mut()
                        .with_context(|| format!("`{name}`: source `{key}` has no [source.speed]"))?;
                    let v = if field == "speed_a1" { &mut sp.a1 } else { &mut sp.a2 };
                    let old = *v;
                    if let Some(new) = set {
                        *v = new;
                    }
                    return Ok(old);
                }
                f => bail!(
                    "parameter `{name}`: unknown source field `{f}` (r0_ohm, alpha_per_k, slope_ohm_per_k, r_at_0c_ohm, scale, scale_per_kj, speed_a1, speed_a2)"
                ),
            };
            let old =
                slot.with_context(|| format!("`{name}`: source `{key}` does not use `{field}`"))?;
            if let Some(v) = set {
                *slot = Some(v);
            }
            Ok(old)
        }
        "fixed_power" => {
            let f = file
                .fixed_powers
                .iter_mut()
                .find(|f| f.node == rest)
                .with_context(|| {
                    format!("parameter `{name}`: no [[fixed_power]] at node `{rest}`")
                })?;
            let old = f.power_w;
            if let Some(v) = set {
                f.power_w = v;
            }
            Ok(old)
        }
        "speed_loss" => {
            let (key, field) = rest
                .rsplit_once('.')
                .with_context(|| format!("parameter `{name}`: expected speed_loss.NAME.FIELD"))?;
            let l = file
                .speed_losses
                .iter_mut()
                .find(|l| l.key() == key)
                .with_context(|| format!("parameter `{name}`: no [[speed_loss]] `{key}`"))?;
            let v = match field {
                "p1_w" => &mut l.p1_w,
                "p2_w" => &mut l.p2_w,
                f => bail!("parameter `{name}`: unknown speed_loss field `{f}` (p1_w, p2_w)"),
            };
            let old = *v;
            if let Some(new) = set {
                *v = new;
            }
            Ok(old)
        }
        "loss" => {
            // loss.NAME.power.K or loss.NAME.split.K (K: 0-based term).
            let mut it = rest.rsplitn(3, '.');
            let (k, kind, key) = (it.next(), it.next(), it.next());
            let (Some(k), Some(kind), Some(key)) = (k, kind, key) else {
                bail!("parameter `{name}`: expected loss.NAME.power.K or loss.NAME.split.K")
            };
            let k: usize = k
                .parse()
                .with_context(|| format!("parameter `{name}`: `{k}` is not a term index"))?;
            let l = file
                .losses
                .iter_mut()
                .find(|l| l.name == key)
                .with_context(|| format!("parameter `{name}`: no [[loss]] `{key}`"))?;
            let terms = match kind {
                "power" => &mut l.power,
                "split" => &mut l.split,
                f => bail!("parameter `{name}`: unknown loss field `{f}` (power, split)"),
            };
            let t = terms
                .get_mut(k)
                .with_context(|| format!("parameter `{name}`: no term {k}"))?;
            let old = t.c;
            if let Some(v) = set {
                t.c = v;
            }
            Ok(old)
        }
        "conductor" => {
            let (key, field) = rest
                .split_once('.')
                .with_context(|| format!("parameter `{name}`: expected conductor.NAME.scale"))?;
            if field != "scale" {
                bail!("parameter `{name}`: unknown conductor field `{field}` (scale)");
            }
            let keys: Vec<String> = file.conductors.iter().map(|c| c.name.clone()).collect();
            let c = file
                .conductors
                .iter_mut()
                .find(|c| c.name == key)
                .with_context(|| {
                    format!(
                        "parameter `{name}`: no conductor `{key}` (conductors: {})",
                        keys.join(", ")
                    )
                })?;
            let old = c.scale;
            if let Some(v) = set {
                c.scale = v;
            }
            Ok(old)
        }
        "grid" => crate::devices::access_grid_param(file, rest, set)
            .with_context(|| format!("parameter `{name}`")),
        k => bail!(
            "parameter `{name}`: unknown kind `{k}` (capacity, conductance, source, conductor, fixed_power, speed_loss, loss, grid)"
        ),
    }
}

/// Default box for a parameter starting at `value`: a factor 10 either way
/// for positive quantities, `[0, 10 |v| + 0.01]` for temperature
/// coefficients, unbounded otherwise.
pub fn default_bounds(name: &str, value: f64) -> (f64, f64) {
    let field = name.rsplit('.').next().unwrap_or("");
    let positive = name.starts_with("capacity.")
        || name.starts_with("conductance.")
        || name.starts_with("grid.")
        || name.starts_with("conductor.")
        || matches!(field, "r0_ohm" | "r_at_0c_ohm" | "scale" | "scale_per_kj");
    if positive && value > 0.0 {
        (value / 10.0, value * 10.0)
    } else if matches!(field, "alpha_per_k" | "slope_ohm_per_k") {
        (0.0, 10.0 * value.abs() + 0.01)
    } else {
        (f64::NEG_INFINITY, f64::INFINITY)
    }
}

/// One trace to fit: its inputs and the measured nodes.
#[derive(Debug, Clone)]
pub struct FitData {
    /// Label (file name).
    pub label: String,
    /// Inputs.
    pub drive: Drive,
    /// Measured sensors the fit matches.
    pub targets: Vec<Sensor>,
    /// Nodes that start at a measured value without being fitted (`--init`):
    /// (node index, temperature \[degC\]). They win over a target's.
    pub init: Vec<(usize, f64)>,
}

/// How the traces of a fit share the weight.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Weighting {
    /// Every reading weighs the same: a trace weighs by its number of
    /// readings (least squares over all rows; the long traces dominate).
    #[default]
    Rows,
    /// Every trace weighs the same in total: each residual is scaled by
    /// `1 / sqrt(readings of its trace)` (a short step test counts as much
    /// as a long duty cycle).
    Traces,
}

/// Options of [`fit`].
#[derive(Debug, Clone)]
pub struct FitOptions {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Use every `stride`-th row.
    pub stride: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// How the traces share the weight.
    pub weighting: Weighting,
    /// A relative weight (> 0, dimensionless) per trace in `data` order,
    /// multiplying [`Weighting`]'s (empty: all 1). The weights are
    /// normalised to a mean of 1 per residual, so the cost stays in K^2 of
    /// the same size and a weight scales only the trace's share.
    pub trace_weights: Vec<f64>,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            max_iterations: 100,
            stride: 1,
            progress: false,
            weighting: Weighting::Rows,
            trace_weights: Vec::new(),
        }
    }
}

/// A fitted parameter.
#[derive(Debug, Clone, Serialize)]
pub struct ParamResult {
    /// Name.
    pub name: String,
    /// Starting value.
    pub initial: f64,
    /// Fitted value.
    pub fitted: f64,
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
    /// `true` when the fit ended on a bound.
    pub at_bound: bool,
    /// Which bound: `lower` or `upper` (None inside the box).
    pub bound: Option<&'static str>,
    /// Standard error at the optimum (same unit as the value), from the
    /// Jacobian: `s^2 (J'J)^-1` with `s^2` the residual variance; None for
    /// a parameter on a bound. The residuals of a thermal trace are
    /// correlated in time, so it is a lower bound on the real uncertainty.
    pub std_error: Option<f64>,
}

/// Fit error of one trace.
#[derive(Debug, Clone, Serialize)]
pub struct TraceFit {
    /// Trace label.
    pub trace: String,
    /// RMSE over its sensors before the fit \[K\].
    pub rmse_before_k: f64,
    /// RMSE after \[K\].
    pub rmse_after_k: f64,
    /// Weight of each of its squared residuals in the fit (normalised: 1
    /// for every trace with `--weighting rows` and no `--weight`).
    pub weight: f64,
    /// Per-sensor scores after the fit.
    pub sensors: Vec<SensorFit>,
}

/// One measured column of a trace after the fit.
#[derive(Debug, Clone, Serialize)]
pub struct SensorFit {
    /// Its score over its readings.
    #[serde(flatten)]
    pub score: Score,
    /// Readings the fit used (present, every `stride`-th row, row 0 the
    /// start excluded).
    pub rows_fitted: usize,
    /// Missing readings (empty or `NaN` cells) over the whole trace.
    pub rows_missing: usize,
}

/// The first present reading of each sensor, for a node that starts at a
/// measured value: (node index, temperature \[degC\]). A sensor with no
/// reading at all gives none.
pub fn first_readings(sensors: &[Sensor]) -> Vec<(usize, f64)> {
    sensors
        .iter()
        .filter_map(|s| {
            let v = s.values_c.iter().copied().find(|v| !v.is_nan())?;
            Some((s.node, v))
        })
        .collect()
}

/// The rows of `sensor` the fit compares: present readings at every
/// `stride`-th row from row 1.
fn fitted_rows(sensor: &Sensor, stride: usize) -> impl Iterator<Item = usize> + '_ {
    (1..sensor.values_c.len())
        .step_by(stride)
        .filter(|&k| !sensor.values_c[k].is_nan())
}

/// The outcome of [`fit`].
#[derive(Debug, Clone, Serialize)]
pub struct FitReport {
    /// Parameters.
    pub params: Vec<ParamResult>,
    /// Per-trace errors.
    pub traces: Vec<TraceFit>,
    /// LM iterations done.
    pub iterations: usize,
    /// Model evaluations (all traces each).
    pub evaluations: usize,
    /// Half the sum of squared residuals before \[K^2\].
    pub cost_before: f64,
    /// ... and after \[K^2\].
    pub cost_after: f64,
    /// Why the fit stopped.
    pub stop_reason: String,
    /// Correlation of every pair of parameters at the optimum (rows and
    /// columns in `params` order; None for a parameter on a bound).
    pub correlations: Vec<Vec<Option<f64>>>,
}

/// Standard errors (in `x`) and correlations of the free parameters from
/// the Jacobian `jac` at the optimum; `free[j]` is false for a parameter
/// held on a bound.
fn uncertainty(
    jac: &DMatrix<f64>,
    cost: f64,
    free: &[bool],
) -> (Vec<Option<f64>>, Vec<Vec<Option<f64>>>) {
    let n = free.len();
    let idx: Vec<usize> = (0..n).filter(|&j| free[j]).collect();
    let none = (vec![None; n], vec![vec![None; n]; n]);
    let dof = jac.nrows().saturating_sub(idx.len());
    if idx.is_empty() || dof == 0 {
        return none;
    }
    let jf = DMatrix::from_fn(jac.nrows(), idx.len(), |r, c| jac[(r, idx[c])]);
    let Some(inv) = (jf.transpose() * &jf).try_inverse() else {
        return none;
    };
    let s2 = 2.0 * cost / dof as f64;
    let mut se = vec![None; n];
    let mut corr = vec![vec![None; n]; n];
    for (a, &ja) in idx.iter().enumerate() {
        se[ja] = Some((s2 * inv[(a, a)]).max(0.0).sqrt());
        for (b, &jb) in idx.iter().enumerate() {
            let d = (inv[(a, a)] * inv[(b, b)]).sqrt();
            corr[ja][jb] = (d > 0.0).then(|| inv[(a, b)] / d);
        }
    }
    (se, corr)
}

struct Transform {
    log: bool,
    scale: f64,
    lo: f64,
    hi: f64,
}

impl Transform {
    fn to_x(&self, p: f64) -> f64 {
        if self.log {
            p.ln()
        } else {
            p / self.scale
        }
    }
    fn to_p(&self, x: f64) -> f64 {
        if self.log {
            x.exp()
        } else {
            x * self.scale
        }
    }
    fn x_bounds(&self) -> (f64, f64) {
        (self.to_x(self.lo), self.to_x(self.hi))
    }
}

struct Problem<'a> {
    base: ModelFile,
    names: Vec<String>,
    transforms: Vec<Transform>,
    data: &'a [FitData],
    inits: Vec<Vec<f64>>,
    stride: usize,
    /// Square root of each trace's residual weight.
    scales: Vec<f64>,
    evaluations: usize,
}

impl Problem<'_> {
    fn file_at(&self, x: &DVector<f64>) -> Result<ModelFile> {
        let mut file = self.base.clone();
        for ((name, t), xi) in self.names.iter().zip(&self.transforms).zip(x.iter()) {
            access_param(&mut file, name, Some(t.to_p(*xi).clamp(t.lo, t.hi)))?;
        }
        Ok(file)
    }

    /// Simulated `[trace][node][row]`, or an error for an invalid model.
    fn simulate(&mut self, x: &DVector<f64>) -> Result<Vec<Vec<Vec<f64>>>> {
        self.evaluations += 1;
        let model = Model::build(&self.file_at(x)?)?;
        let mut plant = FilePlant::new(model)?;
        Ok(self
            .data
            .iter()
            .zip(&self.inits)
            .map(|(d, init)| crate::sim::by_node(&simulate(&mut plant, &d.drive, init)))
            .collect())
    }

    fn residuals(&mut self, x: &DVector<f64>) -> Option<DVector<f64>> {
        let sims = self.simulate(x).ok()?;
        let mut r = Vec::new();
        for ((d, sim), scale) in self.data.iter().zip(&sims).zip(&self.scales) {
            for t in &d.targets {
                let est = &sim[t.node];
                r.extend(fitted_rows(t, self.stride).map(|k| scale * (est[k] - t.values_c[k])));
            }
        }
        r.iter()
            .all(|v| v.is_finite())
            .then(|| DVector::from_vec(r))
    }
}

fn trace_fits(
    file: &ModelFile,
    data: &[FitData],
    inits: &[Vec<f64>],
) -> Result<Vec<(f64, Vec<Score>)>> {
    let model = Model::build(file)?;
    let mut plant = FilePlant::new(model)?;
    let nodes = plant.info().nodes.clone();
    Ok(data
        .iter()
        .zip(inits)
        .map(|(d, init)| {
            let est = crate::sim::by_node(&simulate(&mut plant, &d.drive, init));
            let scores: Vec<Score> = d
                .targets
                .iter()
                .map(|t| score(t, &nodes[t.node], &est, &d.drive.time_s))
                .collect();
            let mse = scores.iter().map(|s| s.mse_k2).sum::<f64>() / scores.len().max(1) as f64;
            (mse.sqrt(), scores)
        })
        .collect())
}

/// The weight of each squared residual per trace: [`Weighting`] times the
/// trace's relative weight, normalised to a mean of 1 over the residuals.
fn trace_weights(data: &[FitData], opts: &FitOptions, stride: usize) -> Result<Vec<f64>> {
    if !opts.trace_weights.is_empty() && opts.trace_weights.len() != data.len() {
        bail!(
            "{} trace weights for {} traces",
            opts.trace_weights.len(),
            data.len()
        );
    }
    if let Some(w) = opts
        .trace_weights
        .iter()
        .find(|w| !(w.is_finite() && **w > 0.0))
    {
        bail!("a trace weight must be finite and above 0, got {w}");
    }
    let rows: Vec<usize> = data
        .iter()
        .map(|d| {
            d.targets
                .iter()
                .map(|t| fitted_rows(t, stride).count())
                .sum()
        })
        .collect();
    let total: usize = rows.iter().sum();
    if total == 0 {
        bail!("no reading to fit: every --measure cell after the first row is empty or NaN");
    }
    let raw: Vec<f64> = rows
        .iter()
        .enumerate()
        .map(|(k, &n)| {
            let relative = opts.trace_weights.get(k).copied().unwrap_or(1.0);
            match opts.weighting {
                Weighting::Rows => relative,
                Weighting::Traces if n > 0 => relative / n as f64,
                Weighting::Traces => 0.0,
            }
        })
        .collect();
    let sum: f64 = raw.iter().zip(&rows).map(|(w, &n)| w * n as f64).sum();
    Ok(raw.iter().map(|w| w * total as f64 / sum).collect())
}

/// Fits `params` of `file` to `data`. Returns the fitted file and a report.
pub fn fit(
    file: &ModelFile,
    params: &[ParamSpec],
    data: &[FitData],
    opts: &FitOptions,
) -> Result<(ModelFile, FitReport)> {
    if params.is_empty() {
        bail!("no parameters to fit: pass --params NAME[=LO:HI],...");
    }
    if data.is_empty() {
        bail!("no traces to fit: pass --trace FILE");
    }
    if data.iter().all(|d| d.targets.is_empty()) {
        bail!("no measured columns to fit: pass --measure COL=NODE");
    }
    let model = Model::build(file)?;
    let info = plant_info(&model);
    let inits = data
        .iter()
        .map(|d| {
            let mut first = first_readings(&d.targets);
            first.extend(d.init.iter().copied());
            initial_temps(&info, &d.drive, &first)
        })
        .collect::<Result<Vec<_>>>()?;
    let stride = opts.stride.max(1);
    let weights = trace_weights(data, opts, stride)?;
    let mut base = file.clone();
    let mut transforms = Vec::new();
    let mut x0 = Vec::new();
    let mut initial = Vec::new();
    for p in params {
        let v = access_param(&mut base, &p.name, None)?;
        let (dlo, dhi) = default_bounds(&p.name, v);
        let (lo, hi) = (p.lo.unwrap_or(dlo), p.hi.unwrap_or(dhi));
        if !(lo <= v && v <= hi) {
            bail!(
                "parameter `{}` starts at {v}, outside its bounds [{lo}, {hi}]",
                p.name
            );
        }
        if lo >= hi {
            bail!(
                "parameter `{}`: lower bound {lo} is not below upper bound {hi}",
                p.name
            );
        }
        let t = Transform {
            log: lo > 0.0,
            scale: if v != 0.0 {
                v.abs()
            } else if (hi - lo).is_finite() {
                (hi - lo) / 2.0
            } else {
                1.0
            },
            lo,
            hi,
        };
        x0.push(t.to_x(v));
        initial.push(v);
        transforms.push(t);
    }
    let mut prob = Problem {
        base,
        names: params.iter().map(|p| p.name.clone()).collect(),
        transforms,
        data,
        inits: inits.clone(),
        stride,
        scales: weights.iter().map(|w| w.sqrt()).collect(),
        evaluations: 0,
    };
    let before = trace_fits(file, data, &inits)?;
    let mut x = DVector::from_vec(x0);
    let mut r = prob
        .residuals(&x)
        .context("the starting model gives non-finite temperatures")?;
    let cost_before = 0.5 * r.norm_squared();
    let mut cost = cost_before;
    let bar = if opts.progress {
        let b = ProgressBar::new(opts.max_iterations as u64);
        b.set_style(
            ProgressStyle::with_template("{spinner} fit [{bar:30}] {pos}/{len} iterations  {msg}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    let n = x.len();
    let bounds: Vec<(f64, f64)> = prob.transforms.iter().map(Transform::x_bounds).collect();
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut stop = format!("iteration limit ({})", opts.max_iterations);
    'outer: while iterations < opts.max_iterations {
        iterations += 1;
        bar.set_position(iterations as u64);
        bar.set_message(format!("cost {cost:.6e} K^2"));
        // Forward-difference Jacobian in x.
        let mut jac = DMatrix::<f64>::zeros(r.len(), n);
        for j in 0..n {
            let h = 1e-6 * x[j].abs().max(1.0);
            let mut xp = x.clone();
            let step = if x[j] + h <= bounds[j].1 { h } else { -h };
            xp[j] += step;
            let rp = prob
                .residuals(&xp)
                .context("non-finite temperatures while differentiating")?;
            jac.set_column(j, &((rp - &r) / step));
        }
        let mut jtj = jac.transpose() * &jac;
        let mut g = jac.transpose() * &r;
        // Active set: a parameter on a bound whose descent direction points
        // out of the box is held this iteration, so the others still move
        // freely instead of being shortened by the projection.
        for j in 0..n {
            let held = (x[j] <= bounds[j].0 && g[j] > 0.0) || (x[j] >= bounds[j].1 && g[j] < 0.0);
            if held {
                jtj.row_mut(j).fill(0.0);
                jtj.column_mut(j).fill(0.0);
                jtj[(j, j)] = 1.0;
                g[j] = 0.0;
            }
        }
        let max_diag = jtj.diagonal().max().max(1e-300);
        loop {
            let mut a = jtj.clone();
            for i in 0..n {
                a[(i, i)] += lambda * jtj[(i, i)].max(1e-12 * max_diag);
            }
            let Some(chol) = a.cholesky() else {
                lambda *= 4.0;
                if lambda > 1e12 {
                    stop = "damping limit (singular normal equations)".into();
                    break 'outer;
                }
                continue;
            };
            let dx = chol.solve(&(-&g));
            let mut xn = &x + &dx;
            for (i, (lo, hi)) in bounds.iter().enumerate() {
                xn[i] = xn[i].clamp(*lo, *hi);
            }
            let step_norm = (&xn - &x).norm();
            let trial = prob.residuals(&xn);
            let trial_cost = trial
                .as_ref()
                .map_or(f64::INFINITY, |t| 0.5 * t.norm_squared());
            if trial_cost < cost {
                let rel = (cost - trial_cost) / cost.max(1e-300);
                x = xn;
                r = trial.expect("finite cost");
                cost = trial_cost;
                lambda = (lambda / 3.0).max(1e-12);
                if rel < 1e-10 || step_norm < 1e-10 * (1.0 + x.norm()) {
                    stop = "converged (cost or step below tolerance)".into();
                    break 'outer;
                }
                break;
            }
            lambda *= 4.0;
            if lambda > 1e12 || step_norm < 1e-14 * (1.0 + x.norm()) {
                stop = "converged (no further decrease)".into();
                break 'outer;
            }
        }
    }
    bar.finish_and_clear();
    // The Jacobian at the optimum, for the standard errors and correlations.
    let mut jac = DMatrix::<f64>::zeros(r.len(), n);
    let mut free = vec![true; n];
    for j in 0..n {
        let span = bounds[j].1 - bounds[j].0;
        let tol = if span.is_finite() { 1e-9 * span } else { 0.0 };
        if x[j] - bounds[j].0 <= tol || bounds[j].1 - x[j] <= tol {
            free[j] = false;
            continue;
        }
        let h = 1e-6 * x[j].abs().max(1.0);
        let step = if x[j] + h <= bounds[j].1 { h } else { -h };
        let mut xp = x.clone();
        xp[j] += step;
        match prob.residuals(&xp) {
            Some(rp) => jac.set_column(j, &((rp - &r) / step)),
            None => free[j] = false,
        }
    }
    let (se_x, correlations) = uncertainty(&jac, cost, &free);
    let fitted = prob.file_at(&x)?;
    let after = trace_fits(&fitted, data, &inits)?;
    let results = params
        .iter()
        .zip(&prob.transforms)
        .zip(x.iter().zip(&initial))
        .zip(&se_x)
        .map(|(((p, t), (xi, v0)), se)| {
            let fitted_v = t.to_p(*xi).clamp(t.lo, t.hi);
            let span = (t.hi - t.lo).abs();
            let tol = if span.is_finite() { 1e-9 * span } else { 0.0 };
            let bound = if (fitted_v - t.lo).abs() <= tol {
                Some("lower")
            } else if (t.hi - fitted_v).abs() <= tol {
                Some("upper")
            } else {
                None
            };
            ParamResult {
                name: p.name.clone(),
                initial: *v0,
                fitted: fitted_v,
                lo: t.lo,
                hi: t.hi,
                at_bound: bound.is_some(),
                bound,
                // dp/dx: p for a log parameter, the scale otherwise.
                std_error: se.map(|e| e * if t.log { fitted_v } else { t.scale }),
            }
        })
        .collect();
    let traces = data
        .iter()
        .zip(before.iter().zip(after))
        .zip(&weights)
        .map(|((d, (b, (rmse, scores))), &weight)| TraceFit {
            trace: d.label.clone(),
            rmse_before_k: b.0,
            rmse_after_k: rmse,
            weight,
            sensors: d
                .targets
                .iter()
                .zip(scores)
                .map(|(t, score)| SensorFit {
                    score,
                    rows_fitted: fitted_rows(t, stride).count(),
                    rows_missing: t.values_c.iter().filter(|v| v.is_nan()).count(),
                })
                .collect(),
        })
        .collect();
    Ok((
        fitted,
        FitReport {
            params: results,
            traces,
            iterations,
            evaluations: prob.evaluations,
            cost_before,
            cost_after: cost,
            stop_reason: stop,
            correlations,
        },
    ))
}
