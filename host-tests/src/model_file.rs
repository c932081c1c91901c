//! The model file: a thermal network described in TOML (see
//! `host-tests/MODEL_FORMAT.md` for the format with a full example).
//!
//! [`ModelFile`] is the serde image of the file (what is read, fitted and
//! written back); [`Model`] is the validated, index-resolved form that the
//! simulator runs: a [`DynNetwork`] plus the names and the input bindings.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use coil_thermal::{Network, Resistance, SolenoidParams};
use serde::{Deserialize, Serialize};

use crate::dynamic_network::DynNetwork;

/// A model file as written on disk.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// Short name of the model (for reports and plots).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Free text: where the numbers come from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Largest `h sum(G)/C` of one explicit sub-step (default 0.5): trace
    /// intervals are split into equal sub-steps to stay below it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_step_ratio: Option<f64>,
    /// Which row's inputs act over an interval (default `start`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_hold: Option<InputHold>,
    /// State nodes (`[[node]]`).
    #[serde(rename = "node")]
    pub nodes: Vec<NodeSpec>,
    /// Boundaries with a given temperature (`[[boundary]]`).
    #[serde(rename = "boundary", default)]
    pub boundaries: Vec<BoundarySpec>,
    /// Conductances (`[[conductance]]`).
    #[serde(rename = "conductance", default)]
    pub conductances: Vec<ConductanceSpec>,
    /// Joule sources (`[[source]]`).
    #[serde(rename = "source", default)]
    pub sources: Vec<SourceSpec>,
    /// Conductors split over several nodes (`[[conductor]]`): one total
    /// loss scale shared by their sources in proportion to capacity.
    #[serde(rename = "conductor", default, skip_serializing_if = "Vec::is_empty")]
    pub conductors: Vec<ConductorSpec>,
    /// Constant powers (`[[fixed_power]]`).
    #[serde(rename = "fixed_power", default, skip_serializing_if = "Vec::is_empty")]
    pub fixed_powers: Vec<FixedPowerSpec>,
    /// Speed-dependent losses without a current (`[[speed_loss]]`).
    #[serde(rename = "speed_loss", default, skip_serializing_if = "Vec::is_empty")]
    pub speed_losses: Vec<SpeedLossSpec>,
    /// Losses polynomial in a current and a speed, on one node or split
    /// between two (`[[loss]]`).
    #[serde(rename = "loss", default, skip_serializing_if = "Vec::is_empty")]
    pub losses: Vec<LossSpec>,
    /// Initial temperature policy (`[initial]`).
    #[serde(default)]
    pub initial: InitialSpec,
    /// What the firmware observer needs beyond the network (`[observer]`:
    /// sensors, limits; see `coil-thermal codegen`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub observer: Option<crate::codegen::ObserverSpec>,
}

/// Which row's inputs (currents, boundaries, signals) act over the interval
/// `[t_k, t_k+1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InputHold {
    /// Row `k`'s (zero-order hold of sampled inputs; the default).
    #[default]
    Start,
    /// Row `k+1`'s: each step uses the inputs of the row it ends at, as an
    /// explicit Euler integration of a logged trace often does (the HUST
    /// authors' published network).
    End,
}

/// The capacity of a sensor node left without one, as a fraction of the
/// node it lags: small enough that the node does not feel it (its heat
/// flow is this fraction of the node's own rate), large enough to keep
/// the network well conditioned.
pub const LAG_CAPACITY_FRACTION: f64 = 1e-4;

/// A state node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeSpec {
    /// Unique name (used by conductances, sources, `--measure`, CSV headers).
    pub name: String,
    /// Heat capacity \[J/K\], > 0. A sensor node (`lags`) may leave it out:
    /// [`LAG_CAPACITY_FRACTION`] of the node it lags.
    #[serde(default = "unset_capacity", skip_serializing_if = "is_unset")]
    pub capacity_j_per_k: f64,
    /// Critical temperature \[degC\] for limits and alarms (optional).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub critical_c: Option<f64>,
    /// A sensor that lags this state node by `time_constant_s`: a
    /// thermistor glued to the end turns, a thermocouple in a potted well
    /// (the conductance `capacity / time_constant_s` to it is added; name
    /// this node in `[observer] sensors` and `--measure`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lags: Option<String>,
    /// The sensor's first-order time constant \[s\] (finite, > 0; with
    /// `lags` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_constant_s: Option<f64>,
}

fn unset_capacity() -> f64 {
    f64::NAN
}

fn is_unset(capacity: &f64) -> bool {
    capacity.is_nan()
}

/// A boundary node: its temperature comes from a trace column or a constant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoundarySpec {
    /// Unique name (ambient, coolant, ...), distinct from the node names.
    pub name: String,
    /// Trace column (or expression) giving its temperature \[degC\];
    /// defaults to the boundary's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub column: Option<String>,
    /// Constant temperature \[degC\], used when the trace has no such column.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value_c: Option<f64>,
}

/// A conductance between two nodes, or a node and a boundary. Exactly one
/// of `g_w_per_k`, `r_k_per_w`, or `h_w_per_m2k` with `area_m2`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConductanceSpec {
    /// Name for calibration (`conductance.<name>`); default `<a>-<b>`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The two ends: node or boundary names (at least one a node).
    pub between: [String; 2],
    /// Conductance \[W/K\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub g_w_per_k: Option<f64>,
    /// Thermal resistance \[K/W\] (`g = 1/r`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub r_k_per_w: Option<f64>,
    /// Convection coefficient \[W/(m^2 K)\] (`g = h * area`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub h_w_per_m2k: Option<f64>,
    /// Convection area \[m^2\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub area_m2: Option<f64>,
    /// Correction factor multiplying the conductance (default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub factor: Option<f64>,
    /// Optional speed dependence (`[conductance.speed]`, forced convection).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<ConductanceSpeedSpec>,
}

/// A conductance that depends on a speed signal `f = column / reference`:
/// `G(f) = factor (1 + a1 f + a2 f^2) / (1 / G0 + r_exp_k_per_w exp(-exp_rate f))`
/// with `G0` the conductance the entry gives (`g_w_per_k`, `r_k_per_w` or
/// `h_w_per_m2k` times `area_m2`). The polynomial is the usual forced-convection
/// law (`h` growing with the air speed); the exponential is a series
/// resistance that fades as the speed rises (e.g. an air gap or an end-space
/// path, the form of the HUST published network). Negative values of the
/// polynomial count as 0 (no path).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConductanceSpeedSpec {
    /// Trace column (or expression) of the speed, in the unit of `reference`.
    pub column: String,
    /// Reference speed (same unit as the column, e.g. rpm), > 0.
    pub reference: f64,
    /// Linear coefficient of the conductance factor (default 0).
    #[serde(default)]
    pub a1: f64,
    /// Quadratic coefficient of the conductance factor (default 0).
    #[serde(default)]
    pub a2: f64,
    /// Series resistance at `f = 0` that fades with speed \[K/W\] (default 0).
    #[serde(default)]
    pub r_exp_k_per_w: f64,
    /// Its decay rate per unit of `f` (default 0: constant).
    #[serde(default)]
    pub exp_rate: f64,
}

impl ConductanceSpeedSpec {
    /// The conductance \[W/K\] at speed signal `value` for a base
    /// conductance `g0_w_per_k` (already multiplied by `factor`).
    pub fn at(&self, g0_w_per_k: f64, value: f64) -> f64 {
        let f = per_unit(value, self.reference);
        let poly = (1.0 + self.a1 * f + self.a2 * f * f).max(0.0);
        if g0_w_per_k <= 0.0 || poly == 0.0 {
            return 0.0;
        }
        let r = 1.0 / g0_w_per_k + self.r_exp_k_per_w * (-self.exp_rate * f).exp();
        poly / r
    }
}

/// A loss polynomial in a current and a speed (iron, magnet, friction,
/// stray and AC losses of a machine):
/// `P = max(0, sum_k c_k i^(i_k) f^(f_k))` \[W\] with `i = |current| / current.reference`
/// and `f = |speed| / speed.reference`. On one node, or split between two:
/// `nodes[0]` takes `a P` and `nodes[1]` `(1 - a) P`, with
/// `a = clip(sum_k c_k i^(i_k) f^(f_k), 0, 1)` over the `split` terms.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossSpec {
    /// Name for calibration (`loss.<name>.power.<k>`, `loss.<name>.split.<k>`).
    pub name: String,
    /// The heated node, or two nodes sharing the loss by `split`.
    pub nodes: Vec<String>,
    /// The current signal (needed by a term with `i > 0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub current: Option<ScaledSignal>,
    /// The speed signal (needed by a term with `f > 0`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<ScaledSignal>,
    /// Terms of the power, `c` in W.
    pub power: Vec<LossTerm>,
    /// Terms of the fraction going to `nodes[0]` (dimensionless); required
    /// with two nodes, refused with one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub split: Vec<LossTerm>,
}

/// A trace signal divided by a reference: `|column| / reference` ([`per_unit`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaledSignal {
    /// Trace column or expression (e.g. `hypot(IdRef,IqRef)`, `speed`).
    pub column: String,
    /// Reference value in the column's unit, > 0.
    pub reference: f64,
}

/// One term `c i^i f^f` of a [`LossSpec`] polynomial.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossTerm {
    /// Coefficient (W in `power`, dimensionless in `split`).
    pub c: f64,
    /// Power of the scaled current (default 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub i: u32,
    /// Power of the scaled speed (default 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub f: u32,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

/// Largest power of `i` or `f` in a loss term (a 4th power already spans
/// every loss law in use; more would only amplify noise in the signal).
pub const MAX_LOSS_EXPONENT: u32 = 4;

/// A signal per unit of its reference, by magnitude: a machine turning
/// backwards (a negative speed) or a current of either sign loses and
/// convects as it does forwards, so a negative signal never takes a loss
/// away (which would read cold).
pub fn per_unit(value: f64, reference: f64) -> f64 {
    value.abs() / reference
}

/// Evaluates `sum c i^i f^f`.
fn polynomial(terms: &[LossTerm], i: f64, f: f64) -> f64 {
    terms
        .iter()
        .map(|t| t.c * i.powi(t.i as i32) * f.powi(t.f as i32))
        .sum()
}

/// A Joule source: `P = scale * R(T_node) * I^2 * (1 + a1 f + a2 f^2)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SourceSpec {
    /// Name for calibration (`source.<name>.<param>`); default: the node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Heated node.
    pub node: String,
    /// Current input name (several sources may share one, e.g. series
    /// layers); default: the source name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input: Option<String>,
    /// Default trace column (or expression) of the input's current \[A\];
    /// default: the input name. `--current COL=INPUT` overrides.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub column: Option<String>,
    /// Resistance at `t_ref_c` \[ohm\] (form 1, with `alpha_per_k`, `t_ref_c`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub r0_ohm: Option<f64>,
    /// Temperature coefficient \[1/K\] (form 1; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha_per_k: Option<f64>,
    /// Reference temperature of `r0_ohm` \[degC\] (form 1; default 20).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub t_ref_c: Option<f64>,
    /// Slope dR/dT \[ohm/K\] (form 2, with `r_at_0c_ohm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slope_ohm_per_k: Option<f64>,
    /// Resistance extrapolated to 0 degC \[ohm\] (form 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub r_at_0c_ohm: Option<f64>,
    /// Power scale `k` (default 1; 1.5 for amplitude-invariant d/q currents).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    /// Power scale per kJ/K of the heated node's capacity (instead of
    /// `scale`): `k = scale_per_kj * C / 1000 J/K`. Sources of one
    /// conductor given the same value share one loss density, so that the
    /// copper of each node heats in proportion to its mass (capacity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_per_kj: Option<f64>,
    /// Optional speed-dependent factor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<SpeedSpec>,
    /// What the input is (default `current`): `pwm` makes it a PWM duty in
    /// `[0, 1]` on the supply `supply_v` or `supply_column`, `voltage` a
    /// linear voltage \[V\]; both heat by `scale D V^2 / R(T)` (see
    /// `coil_thermal::network::Drive`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub drive: Option<DriveKind>,
    /// Constant supply of a `pwm` drive \[V\] (or give `supply_column`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_v: Option<f64>,
    /// Trace column (or expression) of a `pwm` drive's measured supply \[V\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supply_column: Option<String>,
}

/// What a `[[source]]`'s input is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DriveKind {
    /// The winding current \[A\]: `P = scale R(T) I^2`.
    Current,
    /// A PWM duty in `[0, 1]` on a supply: `P = scale D V^2 / R(T)`.
    Pwm,
    /// A linear voltage \[V\]: `P = scale V^2 / R(T)`.
    Voltage,
}

/// Where a voltage-driven source's voltage comes from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VoltageSource {
    /// A PWM duty (the input) on a constant supply \[V\].
    PwmConstant(f64),
    /// A PWM duty (the input) on a measured supply (index into
    /// [`Model::signals`]).
    PwmSignal(usize),
    /// The input is the voltage \[V\].
    Linear,
}

/// Speed factor `1 + a1 f + a2 f^2` with `f = |column| / reference`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedSpec {
    /// Trace column (or expression) of the speed, in the unit of `reference`.
    pub column: String,
    /// Reference speed (same unit as the column, e.g. rpm), > 0.
    pub reference: f64,
    /// Linear coefficient (default 0).
    #[serde(default)]
    pub a1: f64,
    /// Quadratic coefficient (default 0).
    #[serde(default)]
    pub a2: f64,
}

/// One conductor lumped into several nodes (a winding's slot copper and
/// overhangs): its sources together dissipate `scale R |i|^2`, each node
/// the share `C_node / sum C` of it, so every part heats at one loss
/// density and the total is the electrical one (`scale = 1.5` for
/// amplitude-invariant d/q currents) whatever capacities a fit gives the
/// nodes. Its sources give neither `scale` nor `scale_per_kj`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConductorSpec {
    /// Name for calibration (`conductor.<name>.scale`).
    pub name: String,
    /// The sources (their names) that make up the conductor.
    pub sources: Vec<String>,
    /// Power scale of the whole conductor (dimensionless, >= 0).
    pub scale: f64,
}

/// A loss that depends on a speed signal only (iron, magnet, friction):
/// `P = max(0, p1_w f + p2_w f^2)` with `f = |column| / reference`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedLossSpec {
    /// Name for calibration (`speed_loss.<name>.p1_w`); default: the node.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Heated node.
    pub node: String,
    /// Trace column (or expression) of the speed, in the unit of `reference`.
    pub column: String,
    /// Reference speed (same unit as the column, e.g. rpm), > 0.
    pub reference: f64,
    /// Power at `f = 1` of the linear (hysteresis-like) term \[W\].
    #[serde(default)]
    pub p1_w: f64,
    /// Power at `f = 1` of the quadratic (eddy-current-like) term \[W\].
    #[serde(default)]
    pub p2_w: f64,
}

impl SpeedLossSpec {
    /// Calibration name.
    pub fn key(&self) -> &str {
        self.name.as_deref().unwrap_or(&self.node)
    }
}

/// How a speed loss is driven: (signal index, reference, p1 \[W\], p2 \[W\]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpeedLossDrive {
    /// Index into [`Model::signals`].
    pub signal: usize,
    /// Reference speed.
    pub reference: f64,
    /// Linear coefficient \[W\].
    pub p1_w: f64,
    /// Quadratic coefficient \[W\].
    pub p2_w: f64,
}

/// A constant power at a node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixedPowerSpec {
    /// Heated node.
    pub node: String,
    /// Power \[W\].
    pub power_w: f64,
}

/// How the node temperatures start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InitialPolicy {
    /// Every node at the mean of the boundary temperatures at the first row.
    #[default]
    Boundary,
    /// Every node at `uniform_c`.
    Uniform,
    /// Nodes with a mapped measured column (`--measure`, `--truth`,
    /// `--init`) start at its first value; the others as `Boundary`.
    Measured,
}

/// The `[initial]` table.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InitialSpec {
    /// The policy (default `boundary`).
    #[serde(default)]
    pub policy: InitialPolicy,
    /// Temperature \[degC\] for `uniform`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uniform_c: Option<f64>,
}

/// Line (1-based) of the `index`-th `[[table]]` header in `src`, for messages.
pub fn table_line(src: &str, table: &str, index: usize) -> Option<usize> {
    let header = format!("[[{table}]]");
    src.lines()
        .enumerate()
        .filter(|(_, l)| l.trim_start().starts_with(&header))
        .nth(index)
        .map(|(n, _)| n + 1)
}

/// Line and column (1-based) of a byte offset.
pub fn line_col(src: &str, offset: usize) -> (usize, usize) {
    let before = &src[..offset.min(src.len())];
    let line = before.matches('\n').count() + 1;
    let col = before
        .rfind('\n')
        .map_or(before.len(), |p| before.len() - p - 1)
        + 1;
    (line, col)
}

impl ModelFile {
    /// Parses TOML; errors carry `file:line:col`.
    pub fn parse(src: &str, file: &str) -> Result<Self> {
        let parsed: Self = toml::from_str(src).map_err(|e| {
            let (line, col) = e.span().map_or((1, 1), |s| line_col(src, s.start));
            anyhow::anyhow!("{file}:{line}:{col}: {}", e.message().trim())
        })?;
        // Validate now, so semantic errors also point at the file.
        Model::build(&parsed).map_err(|e| {
            let msg = format!("{e:#}");
            let loc = locate(src, &msg).unwrap_or(1);
            anyhow::anyhow!("{file}:{loc}:1: {msg}")
        })?;
        Ok(parsed)
    }

    /// Reads and validates a model file.
    pub fn load(path: &Path) -> Result<Self> {
        let src = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read model file", path.display()))?;
        Self::parse(&src, &path.display().to_string())
    }

    /// The file as TOML text.
    pub fn to_toml(&self) -> Result<String> {
        Ok(toml::to_string_pretty(self)?)
    }

    /// A library network with named nodes, as a model file: how device
    /// models built in Rust reach the host tool. `input_names[m]` names the
    /// current input of source `m` (sources sharing a name share a current).
    pub fn from_network<const N: usize, const B: usize, const M: usize>(
        net: &Network<N, B, M>,
        node_names: &[String; N],
        boundary_names: &[String; B],
        input_names: &[String; M],
    ) -> Self {
        let nodes = node_names
            .iter()
            .enumerate()
            .map(|(i, name)| NodeSpec {
                name: name.clone(),
                capacity_j_per_k: net.capacity_j_per_k(i).unwrap_or(f64::NAN),
                critical_c: None,
                lags: None,
                time_constant_s: None,
            })
            .collect();
        let boundaries = boundary_names
            .iter()
            .map(|name| BoundarySpec {
                name: name.clone(),
                column: None,
                value_c: None,
            })
            .collect();
        let mut conductances = Vec::new();
        for a in 0..N {
            for b in (a + 1)..N {
                let g = net.conductance_w_per_k(a, b);
                if g != 0.0 {
                    conductances.push(ConductanceSpec::g(&node_names[a], &node_names[b], g));
                }
            }
            for (bd, bname) in boundary_names.iter().enumerate() {
                let g = net.boundary_conductance_w_per_k(a, bd);
                if g != 0.0 {
                    conductances.push(ConductanceSpec::g(&node_names[a], bname, g));
                }
            }
        }
        let mut per_node = [0usize; N];
        for m in 0..M {
            if let Some(s) = net.source(m) {
                per_node[s.node] += 1;
            }
        }
        let sources = (0..M)
            .filter_map(|m| net.source(m).map(|s| (m, s)))
            .map(|(m, s)| SourceSpec {
                // Named after the node, or node_m when a node has several.
                name: Some(if per_node[s.node] > 1 {
                    format!("{}_{m}", node_names[s.node])
                } else {
                    node_names[s.node].clone()
                }),
                node: node_names[s.node].clone(),
                input: Some(input_names[m].clone()),
                column: None,
                r0_ohm: None,
                alpha_per_k: None,
                t_ref_c: None,
                slope_ohm_per_k: Some(s.resistance.slope_ohm_per_k),
                r_at_0c_ohm: Some(s.resistance.r_at_0c_ohm),
                scale: None,
                scale_per_kj: None,
                speed: None,
                // A network's voltage-driven source takes its effective
                // voltage as a linear voltage.
                drive: (s.drive == coil_thermal::Drive::Voltage).then_some(DriveKind::Voltage),
                supply_v: None,
                supply_column: None,
            })
            .collect();
        let fixed_powers = (0..N)
            .filter(|&i| net.fixed_power_w(i) != 0.0)
            .map(|i| FixedPowerSpec {
                node: node_names[i].clone(),
                power_w: net.fixed_power_w(i),
            })
            .collect();
        Self {
            name: None,
            description: None,
            max_step_ratio: None,
            input_hold: None,
            nodes,
            boundaries,
            conductances,
            sources,
            conductors: Vec::new(),
            fixed_powers,
            speed_losses: Vec::new(),
            losses: Vec::new(),
            initial: InitialSpec::default(),
            observer: None,
        }
    }

    /// The layered solenoid of [`coil_thermal::solenoid`] with `layers`
    /// layers (1..=64), from the library's own network: nodes `layer_00`
    /// (innermost) ..., boundary `water` (16 degC unless a trace column
    /// `water` is given), one series input `current`.
    pub fn solenoid(params: &SolenoidParams, layers: usize) -> Result<Self> {
        macro_rules! build {
            ($($n:literal)*) => {
                match layers {
                    $($n => Self::solenoid_sized::<$n>(params),)*
                    _ => bail!("--layers must be 1..=64, got {layers}"),
                }
            };
        }
        build!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29 30
            31 32 33 34 35 36 37 38 39 40 41 42 43 44 45 46 47 48 49 50 51 52 53 54 55 56 57 58
            59 60 61 62 63 64)
    }

    fn solenoid_sized<const L: usize>(params: &SolenoidParams) -> Result<Self> {
        let net = params
            .network::<L>()
            .map_err(|e| anyhow::anyhow!("solenoid: {e}"))?;
        let names: [String; L] = core::array::from_fn(|i| format!("layer_{i:02}"));
        let inputs: [String; L] = core::array::from_fn(|_| "current".to_string());
        let mut file = Self::from_network(&net, &names, &["water".to_string()], &inputs);
        file.name = Some(format!("solenoid-{L}"));
        file.description = Some(format!(
            "{L}-layer HeSE solenoid section (coil_thermal::solenoid, default parameters)"
        ));
        file.boundaries[0].value_c = Some(16.0);
        for node in &mut file.nodes {
            // Gap-filling epoxy rated 180 degC (solenoid-layers-runaway.md).
            node.critical_c = Some(180.0);
        }
        Ok(file)
    }
}

/// Finds the line of the table an error message names (`[[kind]] #k`).
fn locate(src: &str, msg: &str) -> Option<usize> {
    let start = msg.find("[[")?;
    let rest = &msg[start + 2..];
    let end = rest.find("]]")?;
    let kind = &rest[..end];
    let hash = rest[end..].find('#')?;
    let digits: String = rest[end + hash + 1..]
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    let k: usize = digits.parse().ok()?;
    table_line(src, kind, k.checked_sub(1)?)
}

impl ConductanceSpec {
    /// A plain `g_w_per_k` conductance between `a` and `b`.
    pub fn g(a: &str, b: &str, g_w_per_k: f64) -> Self {
        Self {
            name: None,
            between: [a.to_string(), b.to_string()],
            g_w_per_k: Some(g_w_per_k),
            r_k_per_w: None,
            h_w_per_m2k: None,
            area_m2: None,
            factor: None,
            speed: None,
        }
    }

    /// Its calibration name: `name`, or `<a>-<b>`.
    pub fn key(&self) -> String {
        self.name
            .clone()
            .unwrap_or_else(|| format!("{}-{}", self.between[0], self.between[1]))
    }

    /// Conductance \[W/K\] (before `factor`), or why it is ill-formed.
    pub fn base_w_per_k(&self) -> Result<f64> {
        match (
            self.g_w_per_k,
            self.r_k_per_w,
            self.h_w_per_m2k,
            self.area_m2,
        ) {
            (Some(g), None, None, None) => Ok(g),
            (None, Some(r), None, None) => {
                if !(r.is_finite() && r > 0.0) {
                    bail!("r_k_per_w must be finite and > 0 K/W, got {r}");
                }
                Ok(1.0 / r)
            }
            (None, None, Some(h), Some(a)) => Ok(h * a),
            _ => bail!(
                "give exactly one of g_w_per_k, r_k_per_w, or h_w_per_m2k together with area_m2"
            ),
        }
    }
}

/// Lowest temperature at which every `[[source]]`'s `R(T)` must be above
/// 0 ohm \[degC\]: the lowest rated temperature of military-grade parts
/// (-55 to 125 degC), and so the coldest a device is started from (a
/// winding switched on in a cold store). A boundary `value_c` or an `[initial]
/// uniform_c` below it extends the range.
pub const RESISTANCE_CHECK_LOW_C: f64 = -55.0;

/// Lowest top of the range over which `R(T)` must be above 0 ohm \[degC\]:
/// above the 220 degC of insulation class R, the hottest common one for
/// windings, so even a model without `critical_c` is checked over every
/// temperature a working winding reaches.
pub const RESISTANCE_CHECK_HIGH_C: f64 = 250.0;

/// How far above the highest `critical_c` `R(T)` must still be above
/// 0 ohm \[K\]: a simulation, a replay and the time-to-limit predictor run
/// past the critical temperature (the shutdown latches above it and the
/// stored heat carries the winding on, a runaway or a fault drives it
/// further), and the model must still make heat there.
pub const RESISTANCE_CHECK_MARGIN_K: f64 = 50.0;

/// The temperatures over which every `[[source]]`'s resistance must stay
/// above 0 ohm \[degC\]: from [`RESISTANCE_CHECK_LOW_C`] (or the lowest
/// boundary `value_c` or `[initial] uniform_c`, if colder) to the highest
/// `critical_c` plus [`RESISTANCE_CHECK_MARGIN_K`], at least
/// [`RESISTANCE_CHECK_HIGH_C`] (or the highest `value_c` or `uniform_c`, if
/// hotter). `R(T)` is a line, so it is above 0 over the range when it is
/// at both ends.
pub fn resistance_check_range_c(file: &ModelFile) -> (f64, f64) {
    let given: Vec<f64> = file
        .boundaries
        .iter()
        .filter_map(|b| b.value_c)
        .chain(file.initial.uniform_c)
        .filter(|t| t.is_finite())
        .collect();
    let low = given.iter().fold(RESISTANCE_CHECK_LOW_C, |a, t| a.min(*t));
    let high = file
        .nodes
        .iter()
        .filter_map(|n| n.critical_c)
        .filter(|t| t.is_finite())
        .map(|t| t + RESISTANCE_CHECK_MARGIN_K)
        .chain(given.iter().copied())
        .fold(RESISTANCE_CHECK_HIGH_C, f64::max);
    (low, high)
}

impl SourceSpec {
    /// Its calibration name: `name`, or the node.
    pub fn key(&self) -> &str {
        self.name.as_deref().unwrap_or(&self.node)
    }

    /// Its input name: `input`, or the source name.
    pub fn input_name(&self) -> &str {
        self.input.as_deref().unwrap_or_else(|| self.key())
    }

    /// The resistance line, or why it is ill-formed.
    pub fn resistance(&self) -> Result<Resistance> {
        let form1 = self.r0_ohm.is_some() || self.alpha_per_k.is_some() || self.t_ref_c.is_some();
        let form2 = self.slope_ohm_per_k.is_some() || self.r_at_0c_ohm.is_some();
        let r = match (form1, form2) {
            (true, false) => {
                let r0 = self
                    .r0_ohm
                    .context("r0_ohm is required with alpha_per_k/t_ref_c")?;
                Resistance::with_alpha(
                    r0,
                    self.alpha_per_k.unwrap_or(0.0),
                    self.t_ref_c.unwrap_or(20.0),
                )
            }
            (false, true) => Resistance::linear_fit(
                self.slope_ohm_per_k.unwrap_or(0.0),
                self.r_at_0c_ohm
                    .context("r_at_0c_ohm is required with slope_ohm_per_k")?,
            ),
            _ => bail!(
                "give either r0_ohm (+ alpha_per_k, t_ref_c) or r_at_0c_ohm (+ slope_ohm_per_k)"
            ),
        };
        let t_ref = self.t_ref_c.unwrap_or(20.0);
        if !r.is_valid_at(t_ref) {
            bail!("resistance must be finite and > 0 ohm at {t_ref} degC");
        }
        Ok(r)
    }

    /// The resistance line, refused if it falls with temperature or
    /// reaches 0 ohm anywhere in `range_c` (see
    /// [`resistance_check_range_c`]): a resistance at or below 0 would make
    /// no heat, or take heat out of its node (a coil that cools itself).
    pub fn resistance_over(&self, range_c: (f64, f64)) -> Result<Resistance> {
        let r = self.resistance()?;
        let (low, high) = range_c;
        let form1 = self.r_at_0c_ohm.is_none() && self.slope_ohm_per_k.is_none();
        let (key, value, unit) = if form1 {
            ("alpha_per_k", self.alpha_per_k.unwrap_or(0.0), "1/K")
        } else {
            (
                "slope_ohm_per_k",
                self.slope_ohm_per_k.unwrap_or(0.0),
                "ohm/K",
            )
        };
        if r.slope_ohm_per_k < 0.0 {
            bail!(
                "{key} = {value} {unit} makes the resistance fall as the source heats up; \
                 a winding's resistance rises with temperature (copper and aluminium: alpha_per_k \
                 about +0.0039 1/K), and one that falls would take a hot winding for one making \
                 less heat than it does: give {key} >= 0 (a sign error?)"
            );
        }
        for t in [low, high] {
            if !r.is_valid_at(t) {
                // Only a sloped line reaches 0 (a flat one is > 0 at t_ref).
                let zero_c = -r.r_at_0c_ohm / r.slope_ohm_per_k;
                let n = |v: Option<f64>, default: f64| crate::trace::num(v.unwrap_or(default));
                let (line, fix) = if form1 {
                    (
                        format!(
                            "{} (1 + {} (T - {}))",
                            n(self.r0_ohm, f64::NAN),
                            n(self.alpha_per_k, 0.0),
                            n(self.t_ref_c, 20.0)
                        ),
                        "r0_ohm [ohm], alpha_per_k [1/K] (copper: 0.00393) and t_ref_c [degC]",
                    )
                } else {
                    (
                        format!(
                            "{} + {} T",
                            n(self.r_at_0c_ohm, f64::NAN),
                            n(self.slope_ohm_per_k, 0.0)
                        ),
                        "r_at_0c_ohm [ohm] and slope_ohm_per_k [ohm/K] (the resistance at 0 degC and its rise per kelvin)",
                    )
                };
                bail!(
                    "the resistance R(T) = {line} ohm reaches 0 ohm at {zero_c:.1} degC, \
                     inside the range checked, {low} to {high} degC ({RESISTANCE_CHECK_LOW_C} degC, \
                     or the coldest boundary value_c, up to the highest critical_c plus \
                     {RESISTANCE_CHECK_MARGIN_K} K, at least {RESISTANCE_CHECK_HIGH_C} degC): at \
                     and below it the source would make no heat, or take heat out of its node; \
                     check {fix}"
                );
            }
        }
        Ok(r)
    }
}

/// How one Joule source is driven by the trace.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceDrive {
    /// Index into [`Model::inputs`].
    pub input: usize,
    /// Power scale `k`.
    pub scale: f64,
    /// Speed factor, if any: (signal index into [`Model::signals`], reference, a1, a2).
    pub speed: Option<(usize, f64, f64, f64)>,
    /// `Some` for a voltage-driven source: its input is a duty or a
    /// voltage, and its network slot carries the effective voltage
    /// `sqrt(scale D) V` until [`Model::currents_at`] turns it into the
    /// current the winding draws at a temperature.
    pub voltage: Option<VoltageSource>,
    /// The node it heats and its resistance line (for [`Model::currents_at`]).
    pub node: usize,
    /// Its `R(T)`.
    pub resistance: Resistance,
}

/// One current input of a model.
#[derive(Debug, Clone, PartialEq)]
pub struct InputSpec {
    /// Input name.
    pub name: String,
    /// Default column (or expression).
    pub column: String,
}

/// How a `[[loss]]` is driven.
#[derive(Debug, Clone, PartialEq)]
pub struct LossDrive {
    /// Current signal: (index into [`Model::signals`], reference).
    pub current: Option<(usize, f64)>,
    /// Speed signal: (index into [`Model::signals`], reference).
    pub speed: Option<(usize, f64)>,
    /// Power terms (`c` in W).
    pub power: Vec<LossTerm>,
    /// Fraction to the first node; empty for a loss on one node.
    pub split: Vec<LossTerm>,
}

impl LossDrive {
    /// The power of each of its nodes \[W\] (one or two).
    pub fn powers_w(&self, signals: &[f64]) -> (f64, Option<f64>) {
        let scaled = |s: Option<(usize, f64)>| s.map_or(0.0, |(k, r)| per_unit(signals[k], r));
        let (i, f) = (scaled(self.current), scaled(self.speed));
        let p = polynomial(&self.power, i, f).max(0.0);
        if self.split.is_empty() {
            (p, None)
        } else {
            let a = polynomial(&self.split, i, f).clamp(0.0, 1.0);
            (a * p, Some((1.0 - a) * p))
        }
    }
}

/// Where a speed-dependent conductance sits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Ends {
    /// Between two state nodes.
    Nodes(usize, usize),
    /// From a state node to a boundary.
    Boundary(usize, usize),
}

/// A speed-dependent conductance of a model.
#[derive(Debug, Clone, PartialEq)]
pub struct VaryingConductance {
    /// Its ends.
    pub ends: Ends,
    /// Its base conductance (times `factor`) \[W/K\].
    pub g0_w_per_k: f64,
    /// Index of its speed signal in [`Model::signals`].
    pub signal: usize,
    /// The law.
    pub law: ConductanceSpeedSpec,
}

/// What one network source carries (see [`Model::source_kinds`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SourceKind {
    /// `[[source]]` number `k`: its input's current ([`Model::drives`]).
    Drive(usize),
    /// `[[speed_loss]]` number `k` ([`Model::speed_losses`]).
    SpeedLoss(usize),
    /// `[[loss]]` number `k` ([`Model::losses`]), on its first node or,
    /// when it splits, its second.
    Loss {
        /// The loss.
        k: usize,
        /// Its second node's share.
        second: bool,
    },
}

/// A validated, index-resolved model.
#[derive(Debug, Clone)]
pub struct Model {
    /// Model name.
    pub name: String,
    /// Node names in state order.
    pub nodes: Vec<String>,
    /// Critical temperature of each node \[degC\], if given.
    pub critical_c: Vec<Option<f64>>,
    /// Boundaries in order.
    pub boundaries: Vec<BoundarySpec>,
    /// Current inputs in order of first use.
    pub inputs: Vec<InputSpec>,
    /// Extra signal columns the sources need (speed), in order.
    pub signals: Vec<String>,
    /// Drive of each Joule source (the network's first sources, in order).
    pub drives: Vec<SourceDrive>,
    /// Each `[[source]]`'s name (its `key()`), in the order of `drives`.
    pub source_names: Vec<String>,
    /// Speed losses: the network's sources after the Joule ones, each a
    /// constant 1 ohm driven by the effective current `sqrt(P)`.
    pub speed_losses: Vec<SpeedLossDrive>,
    /// `[[loss]]` entries: their sources follow the speed losses' (one per
    /// node, each a constant 1 ohm driven by `sqrt(P)`).
    pub losses: Vec<LossDrive>,
    /// Speed-dependent conductances (see [`Model::network_at`]).
    pub varying: Vec<VaryingConductance>,
    /// Which network sources carry a heat-input bias in the firmware
    /// observer (`[observer] bias_sources`, resolved; one flag per
    /// network source); `None`: every source.
    pub bias_sources: Option<Vec<bool>>,
    /// The network without the speed-dependent conductances.
    fixed_network: DynNetwork,
    /// The network, speed-dependent conductances at zero speed.
    pub network: DynNetwork,
    /// Sub-step ratio bound.
    pub max_step_ratio: f64,
    /// Which row's inputs act over an interval.
    pub input_hold: InputHold,
    /// Initial temperature policy.
    pub initial: InitialSpec,
}

impl Model {
    /// Validates a model file and resolves every name to an index. Errors
    /// name the table entry as `[[kind]] #k` (1-based).
    pub fn build(file: &ModelFile) -> Result<Self> {
        if file.nodes.is_empty() {
            bail!("the model has no [[node]]");
        }
        let mut names: BTreeMap<&str, Endpoint> = BTreeMap::new();
        let lags = sensor_lags(file)?;
        let caps: Vec<f64> = file
            .nodes
            .iter()
            .zip(&lags)
            .map(|(n, lag)| match lag {
                Some((of, _)) if n.capacity_j_per_k.is_nan() => {
                    file.nodes[*of].capacity_j_per_k * LAG_CAPACITY_FRACTION
                }
                _ => n.capacity_j_per_k,
            })
            .collect();
        for (k, n) in file.nodes.iter().enumerate() {
            if !(caps[k].is_finite() && caps[k] > 0.0) {
                bail!(
                    "[[node]] #{} `{}`: capacity_j_per_k must be finite and > 0 J/K, got {}",
                    k + 1,
                    n.name,
                    caps[k]
                );
            }
            if let Some(c) = n.critical_c {
                if !c.is_finite() {
                    bail!(
                        "[[node]] #{} `{}`: critical_c must be finite",
                        k + 1,
                        n.name
                    );
                }
            }
            if names.insert(&n.name, Endpoint::Node(k)).is_some() {
                bail!("[[node]] #{}: duplicate name `{}`", k + 1, n.name);
            }
        }
        for (k, b) in file.boundaries.iter().enumerate() {
            if names.insert(&b.name, Endpoint::Boundary(k)).is_some() {
                bail!("[[boundary]] #{}: duplicate name `{}`", k + 1, b.name);
            }
            if let Some(v) = b.value_c {
                if !v.is_finite() {
                    bail!(
                        "[[boundary]] #{} `{}`: value_c must be finite",
                        k + 1,
                        b.name
                    );
                }
            }
        }
        let known = || names.keys().copied().collect::<Vec<_>>().join(", ");
        let mut network = DynNetwork::new(caps.clone(), file.boundaries.len())?;
        for (k, lag) in lags.iter().enumerate() {
            if let Some((of, tau_s)) = lag {
                connect(&mut network, Ends::Nodes(*of, k), caps[k] / tau_s)?;
            }
        }
        let mut keys = BTreeMap::new();
        let mut signals: Vec<String> = Vec::new();
        let mut varying = Vec::new();
        for (k, c) in file.conductances.iter().enumerate() {
            let ctx = || format!("[[conductance]] #{} `{}`", k + 1, c.key());
            let ends = c
                .between
                .iter()
                .map(|n| {
                    names.get(n.as_str()).copied().with_context(|| {
                        format!(
                            "{}: unknown node or boundary `{n}` (known: {})",
                            ctx(),
                            known()
                        )
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            let g = c.base_w_per_k().with_context(ctx)? * c.factor.unwrap_or(1.0);
            if !(g.is_finite() && g >= 0.0) {
                bail!(
                    "{}: conductance must be finite and >= 0 W/K, got {g}",
                    ctx()
                );
            }
            if keys.insert(c.key(), k).is_some() {
                bail!("{}: duplicate conductance name (set `name`)", ctx());
            }
            let ends = match (ends[0], ends[1]) {
                (Endpoint::Node(a), Endpoint::Node(b)) => {
                    if a == b {
                        bail!("{}: a conductance from a node to itself", ctx());
                    }
                    Ends::Nodes(a, b)
                }
                (Endpoint::Node(a), Endpoint::Boundary(b))
                | (Endpoint::Boundary(b), Endpoint::Node(a)) => Ends::Boundary(a, b),
                _ => bail!("{}: joins two boundaries", ctx()),
            };
            match &c.speed {
                None => connect(&mut network, ends, g)?,
                Some(law) => {
                    if !(law.reference.is_finite() && law.reference > 0.0) {
                        bail!("{}: speed.reference must be finite and > 0", ctx());
                    }
                    if !(law.a1.is_finite() && law.a2.is_finite() && law.exp_rate.is_finite()) {
                        bail!("{}: speed.a1, a2 and exp_rate must be finite", ctx());
                    }
                    if !(law.r_exp_k_per_w.is_finite() && law.r_exp_k_per_w >= 0.0) {
                        bail!("{}: speed.r_exp_k_per_w must be finite and >= 0 K/W", ctx());
                    }
                    varying.push(VaryingConductance {
                        ends,
                        g0_w_per_k: g,
                        signal: signal_index(&mut signals, &law.column),
                        law: law.clone(),
                    });
                }
            }
        }
        let conductor_scales = conductor_scales(file)?;
        let resistance_range = resistance_check_range_c(file);
        let mut inputs: Vec<InputSpec> = Vec::new();
        // The network's sources go in the order `Model::source_kinds`
        // gives: the `[[source]]`s, the `[[speed_loss]]`es, the `[[loss]]`es.
        let mut drives = Vec::new();
        let mut source_keys = BTreeMap::new();
        for (k, s) in file.sources.iter().enumerate() {
            let ctx = || format!("[[source]] #{} `{}`", k + 1, s.key());
            let node = match names.get(s.node.as_str()) {
                Some(Endpoint::Node(i)) => *i,
                _ => bail!(
                    "{}: unknown node `{}` (nodes: {})",
                    ctx(),
                    s.node,
                    file.nodes
                        .iter()
                        .map(|n| n.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            };
            if source_keys.insert(s.key().to_string(), k).is_some() {
                bail!("{}: duplicate source name (set `name`)", ctx());
            }
            let resistance = s.resistance_over(resistance_range).with_context(ctx)?;
            network.joule_source(node, resistance)?;
            let input_name = s.input_name().to_string();
            let column = s.column.clone().unwrap_or_else(|| input_name.clone());
            let input = match inputs.iter().position(|i| i.name == input_name) {
                Some(i) => i,
                None => {
                    inputs.push(InputSpec {
                        name: input_name,
                        column,
                    });
                    inputs.len() - 1
                }
            };
            let scale = match (s.scale, s.scale_per_kj, conductor_scales[k]) {
                (None, None, Some((share, _))) => share,
                (_, _, Some((_, conductor))) => bail!(
                    "{}: its [[conductor]] `{conductor}` sets its scale; give neither scale nor scale_per_kj",
                    ctx()
                ),
                (Some(_), Some(_), None) => {
                    bail!("{}: give scale or scale_per_kj, not both", ctx())
                }
                (_, Some(d), None) => d * file.nodes[node].capacity_j_per_k / 1000.0,
                (k, None, None) => k.unwrap_or(1.0),
            };
            if !(scale.is_finite() && scale >= 0.0) {
                bail!("{}: scale must be finite and >= 0", ctx());
            }
            let speed = match &s.speed {
                None => None,
                Some(sp) => {
                    if !(sp.reference.is_finite() && sp.reference > 0.0) {
                        bail!("{}: speed.reference must be finite and > 0", ctx());
                    }
                    if !(sp.a1.is_finite() && sp.a2.is_finite()) {
                        bail!("{}: speed.a1 and speed.a2 must be finite", ctx());
                    }
                    let idx = signal_index(&mut signals, &sp.column);
                    Some((idx, sp.reference, sp.a1, sp.a2))
                }
            };
            let voltage = match (s.drive.unwrap_or(DriveKind::Current), s.supply_v, &s.supply_column) {
                (DriveKind::Current, None, None) => None,
                (DriveKind::Current, _, _) | (DriveKind::Voltage, _, Some(_)) | (DriveKind::Voltage, Some(_), _) => bail!(
                    "{}: supply_v and supply_column belong to drive = \"pwm\" (a duty on a supply)",
                    ctx()
                ),
                (DriveKind::Voltage, None, None) => Some(VoltageSource::Linear),
                (DriveKind::Pwm, Some(v), None) => {
                    if !(v.is_finite() && v > 0.0) {
                        bail!("{}: supply_v must be finite and > 0 V, got {v}", ctx());
                    }
                    Some(VoltageSource::PwmConstant(v))
                }
                (DriveKind::Pwm, None, Some(col)) => {
                    Some(VoltageSource::PwmSignal(signal_index(&mut signals, col)))
                }
                (DriveKind::Pwm, None, None) => bail!(
                    "{}: drive = \"pwm\" needs its supply: supply_v = 24.0 (constant) or supply_column = \"supply_v\" (measured)",
                    ctx()
                ),
                (DriveKind::Pwm, Some(_), Some(_)) => {
                    bail!("{}: give supply_v or supply_column, not both", ctx())
                }
            };
            if voltage.is_some() && speed.is_some() {
                bail!(
                    "{}: a speed factor belongs to a current-driven source (a motor's copper), not to drive = \"pwm\" or \"voltage\"",
                    ctx()
                );
            }
            drives.push(SourceDrive {
                input,
                scale,
                speed,
                voltage,
                node,
                resistance,
            });
        }
        let mut speed_losses = Vec::new();
        let mut loss_keys = BTreeMap::new();
        for (k, l) in file.speed_losses.iter().enumerate() {
            let ctx = || format!("[[speed_loss]] #{} `{}`", k + 1, l.key());
            let node = match names.get(l.node.as_str()) {
                Some(Endpoint::Node(i)) => *i,
                _ => bail!("{}: unknown node `{}`", ctx(), l.node),
            };
            if loss_keys.insert(l.key().to_string(), k).is_some() {
                bail!("{}: duplicate speed loss name (set `name`)", ctx());
            }
            if !(l.reference.is_finite() && l.reference > 0.0) {
                bail!("{}: reference must be finite and > 0", ctx());
            }
            if !(l.p1_w.is_finite() && l.p2_w.is_finite()) {
                bail!("{}: p1_w and p2_w must be finite", ctx());
            }
            // A 1 ohm constant resistance driven by sqrt(P) keeps the network
            // exactly the library's (a Joule source) while carrying any power.
            network.joule_source(node, Resistance::constant(1.0))?;
            speed_losses.push(SpeedLossDrive {
                signal: signal_index(&mut signals, &l.column),
                reference: l.reference,
                p1_w: l.p1_w,
                p2_w: l.p2_w,
            });
        }
        let mut losses = Vec::new();
        let mut loss_names = BTreeMap::new();
        for (k, l) in file.losses.iter().enumerate() {
            let ctx = || format!("[[loss]] #{} `{}`", k + 1, l.name);
            if loss_names.insert(l.name.clone(), k).is_some() {
                bail!("{}: duplicate loss name", ctx());
            }
            let nodes = l
                .nodes
                .iter()
                .map(|n| match names.get(n.as_str()) {
                    Some(Endpoint::Node(i)) => Ok(*i),
                    _ => bail!("{}: unknown node `{n}`", ctx()),
                })
                .collect::<Result<Vec<_>>>()?;
            match (nodes.len(), l.split.is_empty()) {
                (1, true) | (2, false) => {}
                (1, false) => bail!("{}: `split` needs two nodes", ctx()),
                (2, true) => bail!("{}: two nodes need `split` terms", ctx()),
                (n, _) => bail!("{}: `nodes` lists one or two nodes, got {n}", ctx()),
            }
            if nodes.len() == 2 && nodes[0] == nodes[1] {
                bail!("{}: the two nodes must differ", ctx());
            }
            let mut scaled =
                |s: &Option<ScaledSignal>, what: &str| -> Result<Option<(usize, f64)>> {
                    let Some(s) = s else { return Ok(None) };
                    if !(s.reference.is_finite() && s.reference > 0.0) {
                        bail!("{}: {what}.reference must be finite and > 0", ctx());
                    }
                    Ok(Some((signal_index(&mut signals, &s.column), s.reference)))
                };
            let current = scaled(&l.current, "current")?;
            let speed = scaled(&l.speed, "speed")?;
            for (kind, terms) in [("power", &l.power), ("split", &l.split)] {
                for (j, t) in terms.iter().enumerate() {
                    if !t.c.is_finite() {
                        bail!("{}: {kind} term {j}: c must be finite", ctx());
                    }
                    if t.i > MAX_LOSS_EXPONENT || t.f > MAX_LOSS_EXPONENT {
                        bail!(
                            "{}: {kind} term {j}: powers above {MAX_LOSS_EXPONENT} are refused",
                            ctx()
                        );
                    }
                    if t.i > 0 && current.is_none() {
                        bail!(
                            "{}: {kind} term {j} uses i but the loss has no `current`",
                            ctx()
                        );
                    }
                    if t.f > 0 && speed.is_none() {
                        bail!(
                            "{}: {kind} term {j} uses f but the loss has no `speed`",
                            ctx()
                        );
                    }
                }
            }
            if l.power.is_empty() {
                bail!("{}: no `power` terms", ctx());
            }
            for node in &nodes {
                network.joule_source(*node, Resistance::constant(1.0))?;
            }
            losses.push(LossDrive {
                current,
                speed,
                power: l.power.clone(),
                split: l.split.clone(),
            });
        }
        for (k, f) in file.fixed_powers.iter().enumerate() {
            let node = match names.get(f.node.as_str()) {
                Some(Endpoint::Node(i)) => *i,
                _ => bail!("[[fixed_power]] #{}: unknown node `{}`", k + 1, f.node),
            };
            network
                .fixed_power(node, f.power_w)
                .with_context(|| format!("[[fixed_power]] #{}", k + 1))?;
        }
        let max_step_ratio = file.max_step_ratio.unwrap_or(0.5);
        if !(max_step_ratio > 0.0 && max_step_ratio < 1.0) {
            bail!("max_step_ratio must be in (0, 1), got {max_step_ratio}");
        }
        if file.initial.policy == InitialPolicy::Uniform
            && !file.initial.uniform_c.is_some_and(f64::is_finite)
        {
            bail!("[initial] policy = \"uniform\" needs a finite uniform_c");
        }
        let bias_sources = match file.observer.as_ref().and_then(|o| o.bias_sources.as_ref()) {
            None => None,
            Some(names) => {
                let mut flags = vec![false; network.sources().len()];
                for name in names {
                    let Some(&k) = source_keys.get(name.as_str()) else {
                        bail!(
                            "[observer] bias_sources: no [[source]] `{name}` (sources: {})",
                            file.sources
                                .iter()
                                .map(|s| s.key())
                                .collect::<Vec<_>>()
                                .join(", ")
                        );
                    };
                    if std::mem::replace(&mut flags[k], true) {
                        bail!("[observer] bias_sources: `{name}` given twice");
                    }
                }
                Some(flags)
            }
        };
        let fixed_network = network.clone();
        for v in &varying {
            connect(&mut network, v.ends, v.law.at(v.g0_w_per_k, 0.0))?;
        }
        Ok(Self {
            name: file.name.clone().unwrap_or_else(|| "model".into()),
            nodes: file.nodes.iter().map(|n| n.name.clone()).collect(),
            critical_c: file.nodes.iter().map(|n| n.critical_c).collect(),
            boundaries: file.boundaries.clone(),
            inputs,
            signals,
            drives,
            source_names: file.sources.iter().map(|s| s.key().to_string()).collect(),
            speed_losses,
            losses,
            varying,
            bias_sources,
            fixed_network,
            network,
            max_step_ratio,
            input_hold: file.input_hold.unwrap_or_default(),
            initial: file.initial.clone(),
        })
    }

    /// Whether network source `m` carries a heat-input bias in the
    /// firmware observer: named in `[observer] bias_sources`, or any of
    /// the model's sources when the key is absent (an index beyond the
    /// model's, such as the source the host gives a model without one,
    /// never does).
    pub fn carries_bias(&self, m: usize) -> bool {
        match &self.bias_sources {
            Some(flags) => flags.get(m).copied().unwrap_or(false),
            None => m < self.network.sources().len(),
        }
    }

    /// Index of node `name`.
    pub fn node_index(&self, name: &str) -> Result<usize> {
        self.nodes.iter().position(|n| n == name).with_context(|| {
            format!(
                "model `{}` has no node `{name}` (nodes: {})",
                self.name,
                self.nodes.join(", ")
            )
        })
    }

    /// What each network source carries, in the network's order: the one
    /// place that order is written down (`Model::build` adds the sources
    /// in it; the test `source_kinds_follow_the_network_sources` holds the
    /// two together, and `codegen` generates the firmware's currents from
    /// it).
    pub fn source_kinds(&self) -> impl Iterator<Item = SourceKind> + '_ {
        let drives = (0..self.drives.len()).map(SourceKind::Drive);
        let speed_losses = (0..self.speed_losses.len()).map(SourceKind::SpeedLoss);
        let losses = self.losses.iter().enumerate().flat_map(|(k, l)| {
            let second = (!l.split.is_empty()).then_some(SourceKind::Loss { k, second: true });
            std::iter::once(SourceKind::Loss { k, second: false }).chain(second)
        });
        drives.chain(speed_losses).chain(losses)
    }

    /// The network the firmware observer runs (`codegen` generates it,
    /// `replay` ticks it): each `[[source]]`'s power scale folded into its
    /// resistance, `k R(T) I^2`, so that its current is the input's own
    /// (times its speed factor's root: see `codegen::FirmwareInputs`).
    pub fn firmware_network(&self) -> DynNetwork {
        let mut net = self.network.clone();
        for (k, d) in self.drives.iter().enumerate() {
            net.scale_resistance(k, d.scale);
        }
        net
    }

    /// Effective current of every network source \[A\]: `sqrt(k (1 + a1 f +
    /// a2 f^2)) |I|`, so that the library's `R(T) I^2` gives the source's
    /// power. `currents_a` per input, `signals` per signal.
    pub fn effective_currents(&self, currents_a: &[f64], signals: &[f64], out: &mut Vec<f64>) {
        out.clear();
        out.extend(self.source_kinds().map(|kind| match kind {
            SourceKind::Drive(k) => {
                let d = &self.drives[k];
                let mut factor = d.scale;
                if let Some((s, reference, a1, a2)) = d.speed {
                    let f = per_unit(signals[s], reference);
                    factor *= (1.0 + a1 * f + a2 * f * f).max(0.0);
                }
                let i = currents_a[d.input];
                match d.voltage {
                    // The effective voltage `sqrt(k D) V` (a duty is
                    // clamped to [0, 1]: no drive applies more or less).
                    Some(VoltageSource::PwmConstant(v)) => {
                        (factor * i.clamp(0.0, 1.0)).sqrt() * v.abs()
                    }
                    Some(VoltageSource::PwmSignal(k)) => {
                        let v = signals.get(k).copied().unwrap_or(f64::NAN);
                        (factor * i.clamp(0.0, 1.0)).sqrt() * v.abs()
                    }
                    Some(VoltageSource::Linear) => factor.sqrt() * i.abs(),
                    None if factor == 1.0 => i,
                    None => factor.sqrt() * i.abs(),
                }
            }
            SourceKind::SpeedLoss(k) => {
                let l = &self.speed_losses[k];
                let f = per_unit(signals[l.signal], l.reference);
                (l.p1_w * f + l.p2_w * f * f).max(0.0).sqrt()
            }
            SourceKind::Loss { k, second } => {
                let (first, split) = self.losses[k].powers_w(signals);
                if second { split.unwrap_or(0.0) } else { first }.sqrt()
            }
        }));
    }

    /// `true` when a `[[source]]` is driven by a voltage (`drive = "pwm"` or
    /// `"voltage"`): its slot of [`Self::effective_currents`] is an
    /// effective voltage until [`Self::currents_at`].
    pub fn has_voltage_drives(&self) -> bool {
        self.drives.iter().any(|d| d.voltage.is_some())
    }

    /// `true` when network source `source` is driven by a voltage (`drive
    /// = "pwm"` or `"voltage"`).
    pub fn is_voltage_driven(&self, source: usize) -> bool {
        self.drives.get(source).is_some_and(|d| d.voltage.is_some())
    }

    /// Turns the effective voltage `V_eff` of every voltage-driven source in
    /// `effective` (from [`Self::effective_currents`]) into the current its
    /// winding draws at node temperatures `temps_c`, `V_eff / R(T)`, so that
    /// the library's `R(T) I^2` is its heat `V_eff^2 / R(T)`. A resistance
    /// at or below zero gives no current (the line is refused where that
    /// can happen in the model's range).
    pub fn currents_at(&self, effective: &mut [f64], temps_c: &[f64]) {
        for (d, slot) in self.drives.iter().zip(effective.iter_mut()) {
            if d.voltage.is_some() {
                let r = d
                    .resistance
                    .at_c(temps_c.get(d.node).copied().unwrap_or(f64::NAN));
                *slot = if r > 0.0 { *slot / r } else { 0.0 };
            }
        }
    }

    /// `true` when a conductance depends on a signal: the network then
    /// changes from row to row ([`Self::network_at`]).
    pub fn has_varying_conductances(&self) -> bool {
        !self.varying.is_empty()
    }

    /// The network with every speed-dependent conductance at the row's
    /// `signals` (the fixed network when there is none).
    pub fn network_at(&self, signals: &[f64]) -> DynNetwork {
        let mut net = self.fixed_network.clone();
        for v in &self.varying {
            let g = v.law.at(v.g0_w_per_k, signals[v.signal]);
            // Finite and >= 0 by construction: `at` divides a clamped
            // polynomial by a positive resistance.
            let _ = connect(&mut net, v.ends, g);
        }
        net
    }

    /// The network of a row with `signals` when it differs from `current`
    /// (the one in force); `None` when it does not, and always for a model
    /// without speed-dependent conductances. The replays hold a row's
    /// network over its interval and rebuild what they derive from it only
    /// on a change.
    pub fn changed_network(&self, signals: &[f64], current: &DynNetwork) -> Option<DynNetwork> {
        if !self.has_varying_conductances() {
            return None;
        }
        let net = self.network_at(signals);
        (net != *current).then_some(net)
    }

    /// Refuses a model whose conductances depend on a signal, for a path
    /// (`what`) that works on one fixed network.
    pub fn require_fixed_network(&self, what: &str) -> Result<()> {
        if self.has_varying_conductances() {
            bail!(
                "model `{}` has speed-dependent conductances ([conductance.speed]); {what} needs a fixed network (replay it open loop without --measure: the explicit stepper follows the network row by row)",
                self.name
            );
        }
        Ok(())
    }
}

/// The scale of each source (in file order) that a `[[conductor]]` sets:
/// the conductor's `scale` times its node's share of the conductor's
/// capacity, with the conductor's name; `None` for a source in no conductor.
fn conductor_scales(file: &ModelFile) -> Result<Vec<Option<(f64, &str)>>> {
    let mut scales = vec![None; file.sources.len()];
    let mut names = BTreeMap::new();
    for (k, c) in file.conductors.iter().enumerate() {
        let ctx = || format!("[[conductor]] #{} `{}`", k + 1, c.name);
        if names.insert(c.name.as_str(), k).is_some() {
            bail!("{}: duplicate conductor name", ctx());
        }
        if !(c.scale.is_finite() && c.scale >= 0.0) {
            bail!("{}: scale must be finite and >= 0", ctx());
        }
        if c.sources.is_empty() {
            bail!("{}: give its sources", ctx());
        }
        let mut members = Vec::with_capacity(c.sources.len());
        for name in &c.sources {
            let Some(i) = file.sources.iter().position(|s| s.key() == name) else {
                bail!("{}: no source `{name}`", ctx());
            };
            if scales[i].is_some() || members.contains(&i) {
                bail!("{}: source `{name}` is already in a conductor", ctx());
            }
            members.push(i);
        }
        let capacity = |i: usize| -> Result<f64> {
            let node = &file.sources[i].node;
            file.nodes
                .iter()
                .find(|n| &n.name == node)
                .map(|n| n.capacity_j_per_k)
                .with_context(|| format!("{}: unknown node `{node}`", ctx()))
        };
        let total = members.iter().map(|&i| capacity(i)).sum::<Result<f64>>()?;
        if !(total.is_finite() && total > 0.0) {
            bail!(
                "{}: its nodes' capacities must sum to a finite value > 0",
                ctx()
            );
        }
        for &i in &members {
            scales[i] = Some((c.scale * capacity(i)? / total, c.name.as_str()));
        }
    }
    Ok(scales)
}

/// Index of `column` in `signals`, appended when new.
fn signal_index(signals: &mut Vec<String>, column: &str) -> usize {
    match signals.iter().position(|c| c == column) {
        Some(i) => i,
        None => {
            signals.push(column.to_string());
            signals.len() - 1
        }
    }
}

/// Each node's `lags`: the index of the node it lags and its time
/// constant \[s\], checked.
fn sensor_lags(file: &ModelFile) -> Result<Vec<Option<(usize, f64)>>> {
    let mut lags = Vec::with_capacity(file.nodes.len());
    for (k, n) in file.nodes.iter().enumerate() {
        let ctx = || format!("[[node]] #{} `{}`", k + 1, n.name);
        let lag = match (&n.lags, n.time_constant_s) {
            (None, None) => None,
            (Some(of), Some(tau_s)) => {
                let Some(i) = file.nodes.iter().position(|m| &m.name == of) else {
                    bail!("{}: lags unknown node `{of}`", ctx());
                };
                if i == k {
                    bail!("{}: a sensor cannot lag itself", ctx());
                }
                if !(tau_s.is_finite() && tau_s > 0.0) {
                    bail!(
                        "{}: time_constant_s must be finite and > 0 s, got {tau_s}",
                        ctx()
                    );
                }
                if file.nodes[i].capacity_j_per_k.is_nan() {
                    bail!("{}: lags `{of}`, which has no capacity of its own", ctx());
                }
                Some((i, tau_s))
            }
            (Some(_), None) => bail!("{}: `lags` needs `time_constant_s`", ctx()),
            (None, Some(_)) => bail!("{}: `time_constant_s` needs `lags`", ctx()),
        };
        lags.push(lag);
    }
    Ok(lags)
}

fn connect(net: &mut DynNetwork, ends: Ends, g: f64) -> Result<()> {
    match ends {
        Ends::Nodes(a, b) => net.connect(a, b, g)?,
        Ends::Boundary(a, b) => net.connect_boundary(a, b, g)?,
    }
    Ok(())
}

#[derive(Debug, Clone, Copy)]
enum Endpoint {
    Node(usize),
    Boundary(usize),
}
