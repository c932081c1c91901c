//! Limits of any network with run-time sizes: time to limit per element,
//! maximum safe currents and runaway currents, by the library's
//! `coil_thermal::protect` at the model's own size.
//!
//! The library's predictor, steady state and runaway analyses are written
//! over [`coil_thermal::sizes::Sizes`]: the firmware's arrays, or here the
//! `Vec`s of a [`DynNetwork`] (its `NetworkDescription::Sizes` is
//! `RunTimeSizes`). So the host runs the library's own code on a model
//! file of any size and any number of boundaries: no padding, no size
//! class, no large stack.
//!
//! Everything starts from equilibrium with no current at the given boundary
//! temperatures, and the currents are held from `t = 0`.

use anyhow::{bail, Result};
use coil_thermal::network::steady_state_of;
use coil_thermal::protect::predict::{
    ModalPredictor, OperatingPoint, PredictorBuilder, DEFAULT_GRID_POINTS,
};
use coil_thermal::protect::runaway::coil_runaway;
use coil_thermal::protect::safe_current::Horizon;
use coil_thermal::sizes::RunTimeSizes;
use coil_thermal::BuildError;
use serde::Serialize;

use crate::dynamic_network::DynNetwork;
use crate::model_file::Model;

/// The library's predictor of a model file's network, at its own size.
pub type RunTimePredictor = ModalPredictor<f64, RunTimeSizes, DEFAULT_GRID_POINTS>;

/// The limit given to elements without one \[degC\]: far above anything a
/// network reaches, so it never binds (reported as no limit).
pub const NO_LIMIT_C: f64 = 1e9;

/// What to compute.
#[derive(Debug, Clone)]
pub struct LimitsQuery {
    /// The network.
    pub network: DynNetwork,
    /// Current of every source \[A\] (held from `t = 0`).
    pub currents_a: Vec<f64>,
    /// Temperature of every boundary \[degC\].
    pub boundary_c: Vec<f64>,
    /// Limit of every node \[degC\]; `None`: no limit.
    pub limits_c: Vec<Option<f64>>,
    /// Horizon of the safe current \[s\] (`Forever` is always reported too).
    pub horizon_s: Option<f64>,
    /// Sources whose per-coil figures are computed (indices).
    pub coils: Vec<usize>,
}

/// A safe scale or current and what bounds it.
#[derive(Debug, Clone, Serialize)]
pub struct Safe {
    /// The value (scale, or current \[A\]); `None` when unbounded.
    pub value: Option<f64>,
    /// Index of the binding node.
    pub binding_node: Option<usize>,
    /// `false` when some element passes its limit even without this load.
    pub feasible: bool,
}

/// Per-coil figures.
#[derive(Debug, Clone, Serialize)]
pub struct CoilLimits {
    /// Source index.
    pub source: usize,
    /// Largest current \[A\] of this coil over the horizon (others held).
    pub max_current_horizon_a: Option<Safe>,
    /// ... for ever.
    pub max_current_forever_a: Safe,
    /// Above this current \[A\] no steady state exists (`None`: R does not rise).
    pub runaway_current_a: Option<f64>,
    /// Above this current \[A\] the steady state passes a limit.
    pub hot_spot_current_a: Option<f64>,
    /// Why a runaway figure could not be computed.
    pub error: Option<String>,
}

/// The answers.
#[derive(Debug, Clone, Serialize)]
pub struct LimitsReport {
    /// Start temperature of each node \[degC\] (equilibrium, no current).
    pub start_c: Vec<f64>,
    /// Steady temperature of each node at the currents \[degC\], if one exists.
    pub steady_c: Option<Vec<f64>>,
    /// Time to its limit of each node \[s\] (never later than the truth of
    /// the linear model; `None`: never, or no limit).
    pub time_to_limit_s: Vec<Option<f64>>,
    /// Largest common scale on the currents over the horizon.
    pub common_scale_horizon: Option<Safe>,
    /// ... for ever.
    pub common_scale_forever: Safe,
    /// Per coil.
    pub coils: Vec<CoilLimits>,
    /// Slowest time constant of the network \[s\].
    pub slowest_time_constant_s: f64,
}

/// An error of the library, with what was being computed.
fn lib_err(what: &str) -> impl Fn(BuildError) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("{what}: {e}")
}

/// Computes the limits.
///
/// # Errors
/// A model without a boundary (no steady state), inputs of another length
/// than the model's, or a network the library refuses.
pub fn compute(q: &LimitsQuery) -> Result<LimitsReport> {
    let net = &q.network;
    let (n, m) = (net.nodes(), net.sources().len());
    has_a_boundary(net, "limits")?;
    if q.currents_a.len() != m || q.boundary_c.len() != net.boundaries() || q.limits_c.len() != n {
        bail!(
            "limits: one current per source, one temperature per boundary and one limit per node"
        );
    }
    let limits: Vec<f64> = q.limits_c.iter().map(|l| l.unwrap_or(NO_LIMIT_C)).collect();
    let start = steady_state_of(net, &vec![0.0; m], &q.boundary_c)
        .map_err(lib_err("equilibrium without current"))?;
    let steady = steady_state_of(net, &q.currents_a, &q.boundary_c).ok();
    let (predictor, slowest) = predictor_for(net)?;
    let op = OperatingPoint {
        temps_c: start.clone(),
        currents_a: q.currents_a.clone(),
        boundary_c: q.boundary_c.clone(),
        limits_c: limits.clone(),
    };
    let mut ttl = vec![None; n];
    predictor.predict(&op, &mut ttl);
    let horizon = q.horizon_s.map(Horizon::Seconds);
    let common_h = horizon.map(|h| safe(predictor.max_common_scale(&op, h, 1.0)));
    let common_f = safe(predictor.max_common_scale(&op, Horizon::Forever, 1.0));
    let mut coils = Vec::new();
    for &c in &q.coils {
        let (runaway, hot, error) =
            match coil_runaway(net, c, &q.currents_a, &q.boundary_c, &limits) {
                Ok(f) => (f.runaway_current_a, f.hot_spot_current_a, None),
                Err(e) => (None, None, Some(e.to_string())),
            };
        coils.push(CoilLimits {
            source: c,
            max_current_horizon_a: horizon
                .map(|h| safe(predictor.max_coil_current_a(c, &op, h, 1.0))),
            max_current_forever_a: safe(predictor.max_coil_current_a(
                c,
                &op,
                Horizon::Forever,
                1.0,
            )),
            runaway_current_a: runaway,
            hot_spot_current_a: hot,
            error,
        });
    }
    Ok(LimitsReport {
        start_c: start,
        steady_c: steady,
        time_to_limit_s: ttl
            .iter()
            .zip(&q.limits_c)
            .map(|(t, l)| if l.is_some() { *t } else { None })
            .collect(),
        common_scale_horizon: common_h,
        common_scale_forever: common_f,
        coils,
        slowest_time_constant_s: slowest,
    })
}

/// A network without a boundary has no steady state (nothing to predict
/// towards): refused, naming `what`.
fn has_a_boundary(net: &DynNetwork, what: &str) -> Result<()> {
    if net.boundaries() == 0 {
        bail!("{what}: the model has no boundary, so no steady state");
    }
    Ok(())
}

/// The library's time-to-limit predictor of a network at its own size,
/// with horizons up to ten times its slowest time constant (at least 4 h)
/// so that "never" is tight, and that time constant \[s\].
fn predictor_for(net: &DynNetwork) -> Result<(RunTimePredictor, f64)> {
    let probe: RunTimePredictor = PredictorBuilder::new()
        .build_from(net)
        .map_err(lib_err("predictor"))?;
    let slowest = probe.slowest_time_constant_s();
    let last = (10.0 * slowest).max(14_400.0);
    let first = (last * 1e-6).min(1.0);
    let predictor = PredictorBuilder::new()
        .grid_s(first, last)
        .build_from(net)
        .map_err(lib_err("predictor"))?;
    Ok((predictor, slowest))
}

fn safe(s: coil_thermal::protect::safe_current::SafeLimit<f64>) -> Safe {
    Safe {
        value: s.value.is_finite().then_some(s.value),
        binding_node: s.binding_element,
        feasible: s.feasible,
    }
}

/// Time to limit of every node of a model at a moving operating point: the
/// library's time-to-limit predictor at the model's own size (see the
/// module docs), one full sweep per call, for the replay's predictive alarm.
///
/// Each call holds the given currents and boundary temperatures from now
/// on, so the answer is the library's: never later than the linear model's
/// true first crossing, with `R(T)` evaluated conservatively.
pub struct TimeToLimit {
    model: Model,
    predictor: RunTimePredictor,
    op: OperatingPoint<f64, RunTimeSizes>,
    out: Vec<Option<f64>>,
}

impl TimeToLimit {
    /// Builds the predictor of `model`.
    ///
    /// # Errors
    /// A model without a boundary, or a network the library refuses.
    pub fn new(model: &Model) -> Result<Self> {
        let net = &model.network;
        has_a_boundary(net, "time to limit")?;
        let (predictor, _) = predictor_for(net)?;
        let (n, m, b) = (net.nodes(), net.sources().len(), net.boundaries());
        Ok(Self {
            model: model.clone(),
            predictor,
            op: OperatingPoint {
                temps_c: vec![0.0; n],
                currents_a: vec![0.0; m],
                boundary_c: vec![0.0; b],
                limits_c: vec![NO_LIMIT_C; n],
            },
            out: vec![None; n],
        })
    }

    /// The model it predicts for.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Every node's time to its limit \[s\] from the temperatures `temps_c`
    /// \[degC\] with the model's inputs `inputs_a` \[A\], `boundary_c`
    /// \[degC\] and `signals` held from now on (`None`: never, or the node
    /// has no limit in `limits_c`; `Some(0)`: at or past it; `Some(NaN)`:
    /// an input was not finite).
    ///
    /// A node without a limit is given the highest limit of the others for
    /// the predictor, which evaluates each winding's `R(T)` at its node's
    /// limit; its own answer is reported as `None`.
    pub fn predict(
        &mut self,
        temps_c: &[f64],
        inputs_a: &[f64],
        boundary_c: &[f64],
        signals: &[f64],
        limits_c: &[Option<f64>],
    ) -> &[Option<f64>] {
        let Some(highest) = limits_c.iter().flatten().copied().reduce(f64::max) else {
            self.out.fill(None);
            return &self.out;
        };
        let op = &mut self.op;
        if temps_c.len() != op.temps_c.len()
            || boundary_c.len() != op.boundary_c.len()
            || limits_c.len() != op.limits_c.len()
        {
            // Not this model's operating point: unknown.
            self.out.fill(Some(f64::NAN));
            return &self.out;
        }
        for (l, given) in op.limits_c.iter_mut().zip(limits_c) {
            *l = given.unwrap_or(highest);
        }
        op.temps_c.copy_from_slice(temps_c);
        op.boundary_c.copy_from_slice(boundary_c);
        self.model
            .effective_currents(inputs_a, signals, &mut op.currents_a);
        // A voltage-driven winding draws `V_eff / R(T)` at these temperatures.
        self.model.currents_at(&mut op.currents_a, temps_c);
        self.predictor.predict(op, &mut self.out);
        for (t, given) in self.out.iter_mut().zip(limits_c) {
            if given.is_none() {
                *t = None;
            }
        }
        &self.out
    }
}
