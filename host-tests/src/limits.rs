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

use anyhow::{bail, Result};
use coil_thermal::protect::predict::{Operating, PredictorBuilder, DEFAULT_GRID_POINTS};
use coil_thermal::protect::runaway::{hot_spot_current_a, runaway_current_a};
use coil_thermal::protect::safe_current::Horizon;
use coil_thermal::{Network, Resistance};
use serde::Serialize;

use crate::dynamic_network::DynNetwork;

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

/// Computes the limits, on a thread with a large stack (the padded
/// matrices live on the stack).
pub fn compute(query: &LimitsQuery) -> Result<LimitsReport> {
    let n = query.network.nodes();
    let m = query.network.sources().len();
    if query.network.boundaries() > 2 {
        bail!(
            "limits: the model has {} boundaries; at most 2 are supported",
            query.network.boundaries()
        );
    }
    if query.network.boundaries() == 0 {
        bail!("limits: the model has no boundary, so no steady state");
    }
    let Some(&class) = SIZE_CLASSES.iter().find(|&&p| p >= n.max(m)) else {
        bail!(
            "limits: the model has {n} nodes and {m} sources; at most {} of each are supported",
            SIZE_CLASSES[SIZE_CLASSES.len() - 1]
        );
    };
    let q = query.clone();
    std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(move || match class {
            4 => sized::<4>(&q),
            8 => sized::<8>(&q),
            16 => sized::<16>(&q),
            32 => sized::<32>(&q),
            64 => sized::<64>(&q),
            _ => sized::<96>(&q),
        })?
        .join()
        .map_err(|_| anyhow::anyhow!("limits: the computation panicked"))?
}

fn lib_err(what: &str) -> impl Fn(coil_thermal::BuildError) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("limits: {what}: {e}")
}

/// The padded library network of a dynamic one (see the module docs).
pub fn padded<const P: usize>(net: &DynNetwork) -> Result<Network<P, 2, P>> {
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
    for i in n..P {
        lib = lib
            .connect_boundary(i, 0, 1.0)
            .map_err(lib_err("padding"))?;
    }
    for (k, s) in net.sources().iter().enumerate() {
        lib = lib
            .joule_source(k, s.node, s.resistance)
            .map_err(lib_err("source"))?;
    }
    let spare = if n < P { n } else { 0 };
    for k in net.sources().len()..P {
        lib = lib
            .joule_source(k, spare, Resistance::constant(1.0))
            .map_err(lib_err("padding source"))?;
    }
    for (i, p) in net.fixed_powers_w().iter().enumerate() {
        if *p != 0.0 {
            lib = lib.fixed_power(i, *p).map_err(lib_err("fixed power"))?;
        }
    }
    Ok(lib)
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
    // Horizons up to ten times the slowest time constant, so "never" is
    // tight.
    let probe = PredictorBuilder::new()
        .build::<f64, P, 2, P, DEFAULT_GRID_POINTS>(&lib)
        .map_err(lib_err("predictor"))?;
    let slowest = probe.slowest_time_constant_s();
    let last = (10.0 * slowest).max(14_400.0);
    let first = (last * 1e-6).min(1.0);
    let predictor = PredictorBuilder::new()
        .grid_s(first, last)
        .build::<f64, P, 2, P, DEFAULT_GRID_POINTS>(&lib)
        .map_err(lib_err("predictor"))?;
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
