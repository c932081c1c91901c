//! Limits of any network with runtime sizes: time to limit per element,
//! maximum safe currents and runaway currents, by the library's
//! `coil_thermal::protect` (const-generic on `Network<N, B, M>`).
//!
//! # Size dispatch by padding
//!
//! A [`DynNetwork`] of `n` nodes, `b <= 2` boundaries and `m` sources is
//! copied into a `Network<P, 2, P>` for the smallest `P` in [`SIZE_CLASSES`]
//! with `P >= max(n, m)`. Padding nodes (capacity 1 J/K, 1 W/K to boundary 0,
//! no limit) are not connected to the real nodes, so they change no real
//! temperature, mode or limit; padding sources carry no current (they sit on
//! a padding node, or on node 0 when there is none, at zero current: no
//! power). A padding boundary has no links. Larger networks are refused with
//! a clear message.
//!
//! Everything starts from equilibrium with no current at the given boundary
//! temperatures, and the currents are held from `t = 0`.

use anyhow::{bail, Context, Result};
use coil_thermal::protect::predict::{
    LimitPredictor, Operating, PredictorBuilder, DEFAULT_GRID_POINTS,
};
use coil_thermal::protect::runaway::{hot_spot_current_a, runaway_current_a};
use coil_thermal::protect::safe_current::Horizon;
use coil_thermal::{Network, Resistance};
use serde::Serialize;

use crate::dynamic_network::DynNetwork;
use crate::model_file::Model;

/// The padded sizes `P` (nodes and sources) that are instantiated.
pub const SIZE_CLASSES: [usize; 6] = [4, 8, 16, 32, 64, 96];

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
    /// Padded size used.
    pub size_class: usize,
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

/// The smallest size class that holds `nodes` nodes and `sources` sources.
fn size_class(network: &DynNetwork, what: &str) -> Result<usize> {
    if network.boundaries() == 0 {
        bail!("{what}: the model has no boundary, so no steady state");
    }
    class_of(network, &SIZE_CLASSES, what)
}

/// Runs `job` on a thread with a large stack: the padded matrices of the
/// larger size classes live on the stack while they are built (256 MiB).
pub fn on_big_stack<R: Send + 'static>(
    what: &str,
    job: impl FnOnce() -> Result<R> + Send + 'static,
) -> Result<R> {
    std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(job)?
        .join()
        .map_err(|_| anyhow::anyhow!("{what}: the computation panicked"))?
}

/// Computes the limits, on a thread with a large stack (the padded
/// matrices live on the stack).
pub fn compute(query: &LimitsQuery) -> Result<LimitsReport> {
    let class = size_class(&query.network, "limits")?;
    let q = query.clone();
    on_big_stack("limits", move || match class {
        4 => sized::<4>(&q),
        8 => sized::<8>(&q),
        16 => sized::<16>(&q),
        32 => sized::<32>(&q),
        64 => sized::<64>(&q),
        _ => sized::<96>(&q),
    })
}

fn lib_err(what: &str) -> impl Fn(coil_thermal::BuildError) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("padded network: {what}: {e}")
}

/// The padded library network of a dynamic one (see the module docs).
pub fn padded<const P: usize>(net: &DynNetwork) -> Result<Network<P, 2, P>> {
    padded_with::<P>(net, Padding::DECAYING)
}

/// How [`padded_with`] fills the padding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Padding {
    /// Padding nodes get 1 W/K to boundary 0 (a 1 s decay: what a modal
    /// predictor or an exact discretisation wants); `false` leaves them
    /// isolated (rate 0: what an explicit step of any length wants).
    pub link_to_boundary: bool,
    /// Every real source's resistance is multiplied by this (the host
    /// then feeds currents divided by its square root: the same power).
    pub resistance_scale: f64,
}

impl Padding {
    /// Padding nodes decaying to boundary 0, resistances as given.
    pub const DECAYING: Self = Self {
        link_to_boundary: true,
        resistance_scale: 1.0,
    };
    /// Isolated padding nodes, resistances as given.
    pub const ISOLATED: Self = Self {
        link_to_boundary: false,
        resistance_scale: 1.0,
    };
}

/// The smallest of `classes` that holds the nodes and sources of
/// `network` (with at most 2 boundaries).
pub fn class_of(network: &DynNetwork, classes: &[usize], what: &str) -> Result<usize> {
    let n = network.nodes();
    let m = network.sources().len();
    if network.boundaries() > 2 {
        bail!(
            "{what}: the model has {} boundaries; at most 2 are supported",
            network.boundaries()
        );
    }
    classes
        .iter()
        .copied()
        .find(|&p| p >= n.max(m))
        .with_context(|| {
            format!(
                "{what}: the model has {n} nodes and {m} sources; at most {} of each are supported here \
                 (its tables are solved at a padded const-generic size; `simulate`, `calibrate` \
                 and an open-loop `replay` run a model of any size)",
                classes.last().copied().unwrap_or(0)
            )
        })
}

/// [`padded`] with the padding chosen by `padding`.
pub fn padded_with<const P: usize>(net: &DynNetwork, padding: Padding) -> Result<Network<P, 2, P>> {
    let n = net.nodes();
    let mut caps = [1.0; P];
    caps[..n].copy_from_slice(net.capacities_j_per_k());
    let mut lib = Network::new(caps).map_err(lib_err("capacities"))?;
    for p in net.pairs() {
        lib = lib
            .connect(p.a, p.b, p.g_w_per_k)
            .map_err(lib_err("conductance"))?;
    }
    for l in net.links() {
        lib = lib
            .connect_boundary(l.node, l.boundary, l.g_w_per_k)
            .map_err(lib_err("boundary conductance"))?;
    }
    if padding.link_to_boundary {
        for i in n..P {
            lib = lib
                .connect_boundary(i, 0, 1.0)
                .map_err(lib_err("padding"))?;
        }
    }
    let k = padding.resistance_scale;
    for (m, s) in net.sources().iter().enumerate() {
        let r = Resistance {
            r_at_0c_ohm: s.resistance.r_at_0c_ohm * k,
            slope_ohm_per_k: s.resistance.slope_ohm_per_k * k,
        };
        lib = lib.joule_source(m, s.node, r).map_err(lib_err("source"))?;
    }
    // Padding sources (no current, ever) sit on a node that already holds
    // a winding, so that padding makes no node a winding's node: the
    // library's predictor skips a node without a limit unless a winding
    // is on it, and the padded observer's sweeps are then the model's own.
    let spare = match net.sources().first() {
        Some(s) => s.node,
        None if n < P => n,
        None => 0,
    };
    for m in net.sources().len()..P {
        lib = lib
            .joule_source(m, spare, Resistance::constant(1.0))
            .map_err(lib_err("padding source"))?;
    }
    for (i, p) in net.fixed_powers_w().iter().enumerate() {
        if *p != 0.0 {
            lib = lib.fixed_power(i, *p).map_err(lib_err("fixed power"))?;
        }
    }
    Ok(lib)
}

/// The time-to-limit predictor of a padded network, with horizons up to ten
/// times its slowest time constant (at least 4 h) so that "never" is tight,
/// and that time constant \[s\].
fn predictor_for<const P: usize>(
    lib: &Network<P, 2, P>,
) -> Result<(LimitPredictor<f64, P, 2, P>, f64)> {
    let probe = PredictorBuilder::new()
        .build::<f64, P, 2, P, DEFAULT_GRID_POINTS>(lib)
        .map_err(lib_err("predictor"))?;
    let slowest = probe.slowest_time_constant_s();
    let last = (10.0 * slowest).max(14_400.0);
    let first = (last * 1e-6).min(1.0);
    let predictor = PredictorBuilder::new()
        .grid_s(first, last)
        .build::<f64, P, 2, P, DEFAULT_GRID_POINTS>(lib)
        .map_err(lib_err("predictor"))?;
    Ok((predictor, slowest))
}

fn safe(s: coil_thermal::protect::safe_current::SafeLimit<f64>, n: usize) -> Safe {
    Safe {
        value: s.value.is_finite().then_some(s.value),
        binding_node: s.binding_element.filter(|&e| e < n),
        feasible: s.feasible,
    }
}

fn sized<const P: usize>(q: &LimitsQuery) -> Result<LimitsReport> {
    let n = q.network.nodes();
    let lib = padded::<P>(&q.network)?;
    let mut currents = [0.0; P];
    currents[..q.currents_a.len()].copy_from_slice(&q.currents_a);
    let mut boundary = [q.boundary_c[0]; 2];
    boundary[..q.boundary_c.len()].copy_from_slice(&q.boundary_c);
    let mut limits = [NO_LIMIT_C; P];
    for (l, v) in limits.iter_mut().zip(&q.limits_c) {
        *l = v.unwrap_or(NO_LIMIT_C);
    }
    let start = lib
        .steady_state(&[0.0; P], &boundary)
        .map_err(lib_err("equilibrium without current"))?;
    let steady = lib.steady_state(&currents, &boundary).ok();
    let (predictor, slowest) = predictor_for(&lib)?;
    let op = Operating {
        temps_c: start,
        currents_a: currents,
        boundary_c: boundary,
        limits_c: limits,
    };
    let mut ttl = [None; P];
    predictor.predict(&op, &mut ttl);
    let horizon = q.horizon_s.map(Horizon::Seconds);
    let common_h = horizon.map(|h| safe(predictor.max_common_scale(&op, h, 1.0), n));
    let common_f = safe(predictor.max_common_scale(&op, Horizon::Forever, 1.0), n);
    let mut coils = Vec::new();
    for &c in &q.coils {
        let (runaway, hot, error) = match (
            runaway_current_a(&lib, c, &currents),
            hot_spot_current_a(&lib, c, &currents, &boundary, &limits),
        ) {
            (Ok(r), Ok(h)) => (r, h, None),
            (Err(e), _) | (_, Err(e)) => (None, None, Some(e.to_string())),
        };
        coils.push(CoilLimits {
            source: c,
            max_current_horizon_a: horizon
                .map(|h| safe(predictor.max_coil_current_a(c, &op, h, 1.0), n)),
            max_current_forever_a: safe(
                predictor.max_coil_current_a(c, &op, Horizon::Forever, 1.0),
                n,
            ),
            runaway_current_a: runaway,
            hot_spot_current_a: hot,
            error,
        });
    }
    Ok(LimitsReport {
        size_class: P,
        start_c: start[..n].to_vec(),
        steady_c: steady.map(|s| s[..n].to_vec()),
        time_to_limit_s: (0..n)
            .map(|i| {
                if q.limits_c[i].is_some() {
                    ttl[i]
                } else {
                    None
                }
            })
            .collect(),
        common_scale_horizon: common_h,
        common_scale_forever: common_f,
        coils,
        slowest_time_constant_s: slowest,
    })
}

/// The size-independent face of a padded [`LimitPredictor`] with its
/// operating point.
trait PaddedPredictor: Send {
    /// One full sweep (see `LimitPredictor::predict`) over the first
    /// `temps_c.len()` nodes; the answers of those nodes go to `out`.
    fn predict(
        &mut self,
        temps_c: &[f64],
        currents_a: &[f64],
        boundary_c: &[f64],
        limits_c: &[f64],
        out: &mut [Option<f64>],
    );
}

struct Padded<const P: usize> {
    predictor: LimitPredictor<f64, P, 2, P>,
    op: Operating<f64, P, 2, P>,
    out: [Option<f64>; P],
}

impl<const P: usize> Padded<P> {
    fn build(network: &DynNetwork) -> Result<Box<dyn PaddedPredictor>> {
        let lib = padded::<P>(network)?;
        let (predictor, _) = predictor_for(&lib)?;
        Ok(Box::new(Self {
            predictor,
            op: Operating {
                temps_c: [0.0; P],
                currents_a: [0.0; P],
                boundary_c: [0.0; 2],
                limits_c: [NO_LIMIT_C; P],
            },
            out: [None; P],
        }))
    }
}

impl<const P: usize> PaddedPredictor for Padded<P> {
    fn predict(
        &mut self,
        temps_c: &[f64],
        currents_a: &[f64],
        boundary_c: &[f64],
        limits_c: &[f64],
        out: &mut [Option<f64>],
    ) {
        let n = temps_c.len();
        let op = &mut self.op;
        op.boundary_c = [boundary_c[0]; 2];
        op.boundary_c[..boundary_c.len()].copy_from_slice(boundary_c);
        // Padding nodes sit at their equilibrium with boundary 0 and never
        // reach their limit; padding sources carry no current.
        op.temps_c = [op.boundary_c[0]; P];
        op.temps_c[..n].copy_from_slice(temps_c);
        op.currents_a = [0.0; P];
        op.currents_a[..currents_a.len()].copy_from_slice(currents_a);
        op.limits_c = [NO_LIMIT_C; P];
        op.limits_c[..n].copy_from_slice(limits_c);
        self.predictor.predict(op, &mut self.out);
        out.copy_from_slice(&self.out[..n]);
    }
}

/// Time to limit of every node of a model at a moving operating point: the
/// library's [`LimitPredictor`] on the padded network (see the module docs),
/// one full sweep per call, for the replay's predictive alarm.
///
/// Each call holds the given currents and boundary temperatures from now
/// on, so the answer is the library's: never later than the linear model's
/// true first crossing, with `R(T)` evaluated conservatively.
pub struct TimeToLimit {
    model: Model,
    predictor: Box<dyn PaddedPredictor>,
    currents_a: Vec<f64>,
    limits_c: Vec<f64>,
    out: Vec<Option<f64>>,
}

impl TimeToLimit {
    /// Builds the predictor of `model` (on a large stack; the answer is
    /// boxed).
    ///
    /// # Errors
    /// More than 2 boundaries, none, more nodes or sources than the
    /// largest size class, or a network the library refuses.
    pub fn new(model: &Model) -> Result<Self> {
        let class = size_class(&model.network, "time to limit")?;
        let network = model.network.clone();
        let predictor = on_big_stack("time to limit", move || match class {
            4 => Padded::<4>::build(&network),
            8 => Padded::<8>::build(&network),
            16 => Padded::<16>::build(&network),
            32 => Padded::<32>::build(&network),
            64 => Padded::<64>::build(&network),
            _ => Padded::<96>::build(&network),
        })?;
        let n = model.nodes.len();
        Ok(Self {
            model: model.clone(),
            predictor,
            currents_a: Vec::new(),
            limits_c: vec![NO_LIMIT_C; n],
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
        for (l, given) in self.limits_c.iter_mut().zip(limits_c) {
            *l = given.unwrap_or(highest);
        }
        self.model
            .effective_currents(inputs_a, signals, &mut self.currents_a);
        // A voltage-driven winding draws `V_eff / R(T)` at these temperatures.
        self.model.currents_at(&mut self.currents_a, temps_c);
        self.predictor.predict(
            temps_c,
            &self.currents_a,
            boundary_c,
            &self.limits_c,
            &mut self.out,
        );
        for (t, given) in self.out.iter_mut().zip(limits_c) {
            if given.is_none() {
                *t = None;
            }
        }
        &self.out
    }
}
