//! The thermal network every device model is built from.
//!
//! A network has `N` *state* nodes with heat capacity `C_i` \[J/K\], `B`
//! *boundary* nodes whose temperatures are inputs each tick (ambient air,
//! coolant), and `M` current inputs, each heating one node through a
//! [`Resistance`] `R(T)` (or `M` inputs of which some are effective
//! voltages, `P = V_eff^2 / R(T)`: see [`Drive`] and
//! [`Network::voltage_source`]). Nodes are joined by conductances `G` \[W/K\], stored
//! once per pair, so every watt that leaves one node arrives at the other and
//! the network conserves energy by construction. The energy balance of node
//! `i` is
//!
//! ```text
//! C_i dT_i/dt = sum_j G_ij (T_j - T_i) + sum_b G_ib (T_b - T_i) + R_i(T_i) I_i^2 + P_i
//! ```
//!
//! [`Network`] is the build-time description in `f64`. From it come
//!
//! * [`Network::state_space`]: `dT/dt = A T + B p + G T_b + d` at an operating
//!   point (the Omnimagnet paper's form, with the Joule powers `p` as inputs);
//! * [`Network::steady_state`]: the exact steady state *including* the rise of
//!   `R(T)`, or [`BuildError::NoSteadyState`] when the winding would run away;
//! * [`Network::energy_rates`]: the energy account `P_in = P_stored + P_out`;
//! * [`ExplicitStepper`]: the hot-path fixed step in any [`Scalar`](crate::Scalar),
//!   refused at build time when it would be unstable; with the `alloc`
//!   feature (a host), `RunTimeStepper`, the same step of a network whose
//!   sizes are known only at run time, from any [`NetworkDescription`];
//! * the exact zero-order-hold step of [`crate::discretize`].

mod description;
mod explicit;
pub mod motor;
mod source;
mod steady;
pub use steady::steady_state_of;
pub(crate) use steady::{one_winding_steady, OneWindingSteady};

pub use description::{Boundaries, Inputs, NetworkDescription, Nodes};
pub use explicit::{compensated_add, ExplicitStepper, NetworkState};
#[cfg(feature = "alloc")]
pub use explicit::{RunTimeState, RunTimeStepper, SizeMismatch};
pub use motor::{DqScaling, Motor, MotorBuilder, MotorDatasheet, MotorHeatCapacity, MotorSensor};
pub use source::{DeviationResistance, Drive, JouleSource, Resistance, ScalarResistance};

use crate::error::BuildError;
use crate::sizes::{ConstSizes, NetworkAllocator, Sizes};
use nalgebra::{DefaultAllocator, OMatrix, OVector, U1};

/// A lumped thermal network, described in `f64` at build time.
///
/// `N` state nodes, `B` boundary nodes, `M` current inputs.
#[derive(Debug, Clone, PartialEq)]
pub struct Network<const N: usize, const B: usize, const M: usize> {
    capacity_j_per_k: [f64; N],
    /// `pair_w_per_k[i][j]` for `i < j` only: each pair is stored once.
    pair_w_per_k: [[f64; N]; N],
    boundary_w_per_k: [[f64; B]; N],
    sources: [Option<JouleSource>; M],
    fixed_power_w: [f64; N],
}

/// The continuous-time state space of a network at an operating point:
///
/// `dT/dt = A T + B p + G T_b + d`, with `T` in degC, `p` the Joule power of
/// each current input \[W\], `T_b` the boundary temperatures \[degC\] and `d`
/// the fixed powers divided by the capacities \[K/s\].
///
/// Its matrices are of the network's [`Sizes`] `Z`: `SMatrix` for a
/// [`Network`] (`ConstSizes`), `DMatrix` for one read at run time (see
/// [`crate::sizes`]); [`ConstStateSpace`] names the first.
#[derive(Debug, Clone, PartialEq)]
pub struct StateSpace<Z: Sizes>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    /// Conduction matrix \[1/s\]: `A_ij = G_ij / C_i`, `A_ii = -sum(G_i*) / C_i`.
    pub a: OMatrix<f64, Z::NodeDim, Z::NodeDim>,
    /// Power input matrix \[K/(s W)\]: `1 / C_node` for each input's node.
    pub b_power: OMatrix<f64, Z::NodeDim, Z::InputDim>,
    /// Boundary matrix \[1/s\]: `G_ib / C_i`.
    pub g_boundary: OMatrix<f64, Z::NodeDim, Z::BoundaryDim>,
    /// Fixed powers over capacities \[K/s\].
    pub d: OVector<f64, Z::NodeDim>,
    /// The paper's input matrix for `U = I^2` at the operating point
    /// \[K/(s A^2)\]: `R(T_op) / C_node` (Omnimagnet Appendix B); for a
    /// voltage-driven input, `U = V_eff^2` and the entry is `1 / (R(T_op)
    /// C_node)` \[K/(s V^2)\].
    pub b_current_squared: OMatrix<f64, Z::NodeDim, Z::InputDim>,
}

/// The state space of a [`Network`] with `N` nodes, `B` boundaries and `M`
/// inputs (its matrices `SMatrix`).
pub type ConstStateSpace<const N: usize, const B: usize, const M: usize> =
    StateSpace<ConstSizes<N, B, M>>;

/// The state space of any network description at the operating point
/// `op_temps_c` \[degC\] (which only sets `b_current_squared`: `A`, `B`,
/// `G` of a network with constant conductances do not depend on
/// temperature); [`Network::state_space`] for a [`Network`], at its own
/// size for one read at run time.
pub fn state_space_of<W: NetworkDescription>(
    network: &W,
    op_temps_c: &Nodes<W, f64>,
) -> StateSpace<W::Sizes>
where
    DefaultAllocator: NetworkAllocator<W::Sizes>,
{
    let z = network.sizes();
    let (n, b, m) = (z.node_dim(), z.boundary_dim(), z.input_dim());
    let mut a = OMatrix::<f64, _, _>::zeros_generic(n, n);
    let mut g_boundary = OMatrix::<f64, _, _>::zeros_generic(n, b);
    let mut b_power = OMatrix::<f64, _, _>::zeros_generic(n, m);
    let mut b_current_squared = OMatrix::<f64, _, _>::zeros_generic(n, m);
    let mut d = OVector::<f64, _>::zeros_generic(n, U1);
    // Each node's conductances summed in the order of its neighbours'
    // indices, then its boundaries': a pair (i, j > i) reaches row j while
    // the rows are taken in order, before row j's own later pairs.
    let mut diagonal = OVector::<f64, _>::zeros_generic(n, U1);
    for i in 0..z.nodes() {
        let c = network.capacity_at_j_per_k(i);
        for (j, g) in network.later_pairs_w_per_k(i) {
            a[(i, j)] = g / c;
            a[(j, i)] = g / network.capacity_at_j_per_k(j);
            diagonal[i] += g;
            diagonal[j] += g;
        }
        let mut sum = diagonal[i];
        for k in 0..z.boundaries() {
            let g = network.boundary_link_w_per_k(i, k);
            g_boundary[(i, k)] = g / c;
            sum += g;
        }
        a[(i, i)] = -sum / c;
        d[i] = network.fixed_power_at_w(i) / c;
    }
    for k in 0..z.inputs() {
        if let Some(s) = network.joule_source_of(k) {
            let c = network.capacity_at_j_per_k(s.node);
            b_power[(s.node, k)] = 1.0 / c;
            let r = s.resistance.at_c(op_temps_c.as_ref()[s.node]);
            b_current_squared[(s.node, k)] = match s.drive {
                Drive::Current => r / c,
                // The input squared is `V_eff^2`: `1 / (R C)`.
                Drive::Voltage => 1.0 / (r * c),
            };
        }
    }
    StateSpace {
        a,
        b_power,
        g_boundary,
        d,
        b_current_squared,
    }
}

/// The energy account of a network at one instant \[W\].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EnergyRates {
    /// Joule plus fixed power put into the nodes \[W\].
    pub input_w: f64,
    /// Rate of change of the stored heat `sum C_i dT_i/dt` \[W\].
    pub stored_w: f64,
    /// Heat flowing into the boundary nodes \[W\] (negative when they heat).
    pub to_boundaries_w: f64,
}

impl EnergyRates {
    /// `input - stored - out` \[W\]: zero up to rounding for a valid network.
    pub fn imbalance_w(&self) -> f64 {
        self.input_w - self.stored_w - self.to_boundaries_w
    }
}

fn valid_conductance(g: f64) -> bool {
    g.is_finite() && g >= 0.0
}

impl<const N: usize, const B: usize, const M: usize> Network<N, B, M> {
    /// A network of `N` isolated nodes with these heat capacities \[J/K\].
    pub fn new(capacity_j_per_k: [f64; N]) -> Result<Self, BuildError> {
        if let Some(node) = capacity_j_per_k
            .iter()
            .position(|c| !(c.is_finite() && *c > 0.0))
        {
            return Err(BuildError::InvalidCapacity { node });
        }
        Ok(Self {
            capacity_j_per_k,
            pair_w_per_k: [[0.0; N]; N],
            boundary_w_per_k: [[0.0; B]; N],
            sources: [None; M],
            fixed_power_w: [0.0; N],
        })
    }

    /// Adds a conductance `g_w_per_k` \[W/K\] between state nodes `a` and `b`
    /// (added to any already there: parallel paths sum).
    pub fn connect(mut self, a: usize, b: usize, g_w_per_k: f64) -> Result<Self, BuildError> {
        if a >= N {
            return Err(BuildError::NodeOutOfRange { index: a });
        }
        if b >= N {
            return Err(BuildError::NodeOutOfRange { index: b });
        }
        if a == b {
            return Err(BuildError::SelfLoop { node: a });
        }
        if !valid_conductance(g_w_per_k) {
            return Err(BuildError::InvalidConductance { node: a, other: b });
        }
        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
        self.pair_w_per_k[lo][hi] += g_w_per_k;
        Ok(self)
    }

    /// Makes state node `sensor` a sensor that lags node `of` by the time
    /// constant `time_constant_s` \[s\] (finite, `> 0`): a conductance
    /// `C_sensor / time_constant_s` \[W/K\] joins them, so that with the
    /// sensor's own capacity small against its node's, the sensor follows
    /// `tau dT_s/dt = T_of - T_s`.
    ///
    /// A thermistor glued to the end turns, or a thermocouple in a potted
    /// well, reads its winding seconds to tens of seconds late; an
    /// observer that reads it as the winding itself takes the lag for a
    /// cold winding while it heats. Measure the sensor node instead
    /// ([`crate::observer::NetworkObserverBuilder::new`]'s `sensor_nodes`)
    /// and the filter sees the lag as physics. Give the sensor node a
    /// capacity small against its node's (the model file's default is
    /// 1e-3 of it: the heat it draws is then negligible), and add no other
    /// conductance to it unless the sensor also sees something else (its
    /// leads, the air).
    pub fn connect_sensor(
        self,
        of: usize,
        sensor: usize,
        time_constant_s: f64,
    ) -> Result<Self, BuildError> {
        let Some(capacity) = self.capacity_j_per_k(sensor) else {
            return Err(BuildError::NodeOutOfRange { index: sensor });
        };
        if !(time_constant_s.is_finite() && time_constant_s > 0.0) {
            return Err(BuildError::InvalidParameter {
                name: "time_constant_s",
            });
        }
        self.connect(of, sensor, capacity / time_constant_s)
    }

    /// Adds a conductance \[W/K\] from state node `node` to boundary `boundary`.
    pub fn connect_boundary(
        mut self,
        node: usize,
        boundary: usize,
        g_w_per_k: f64,
    ) -> Result<Self, BuildError> {
        if node >= N {
            return Err(BuildError::NodeOutOfRange { index: node });
        }
        if boundary >= B {
            return Err(BuildError::NodeOutOfRange { index: boundary });
        }
        if !valid_conductance(g_w_per_k) {
            return Err(BuildError::InvalidConductance {
                node,
                other: boundary,
            });
        }
        self.boundary_w_per_k[node][boundary] += g_w_per_k;
        Ok(self)
    }

    /// Makes current input `input` heat `node` through `resistance`:
    /// `P = R(T) I^2`. The line is checked by [`Resistance::check`]: a
    /// negative slope or `R(0 degC) <= 0` is refused.
    pub fn joule_source(
        self,
        input: usize,
        node: usize,
        resistance: Resistance,
    ) -> Result<Self, BuildError> {
        self.source_with(input, node, resistance, Drive::Current)
    }

    /// Makes input `input` a voltage-driven winding heating `node`: its
    /// input is the effective voltage `V_eff = sqrt(D) V` \[V\] (PWM duty
    /// `D` on supply `V`; a linear voltage has `D = 1`) and its heat is
    /// `P = V_eff^2 / R(T)`, falling as the winding heats (see
    /// [`Drive::Voltage`]). The line is checked as for
    /// [`joule_source`](Self::joule_source).
    pub fn voltage_source(
        self,
        input: usize,
        node: usize,
        resistance: Resistance,
    ) -> Result<Self, BuildError> {
        self.source_with(input, node, resistance, Drive::Voltage)
    }

    fn source_with(
        mut self,
        input: usize,
        node: usize,
        resistance: Resistance,
        drive: Drive,
    ) -> Result<Self, BuildError> {
        if node >= N {
            return Err(BuildError::NodeOutOfRange { index: node });
        }
        let slot = self
            .sources
            .get_mut(input)
            .ok_or(BuildError::NodeOutOfRange { index: input })?;
        resistance.check(input)?;
        *slot = Some(JouleSource {
            node,
            resistance,
            drive,
        });
        Ok(self)
    }

    /// Adds a constant power \[W\] at `node` (iron losses, electronics).
    pub fn fixed_power(mut self, node: usize, power_w: f64) -> Result<Self, BuildError> {
        if node >= N {
            return Err(BuildError::NodeOutOfRange { index: node });
        }
        if !power_w.is_finite() {
            return Err(BuildError::InvalidPower { node });
        }
        self.fixed_power_w[node] += power_w;
        Ok(self)
    }

    /// Heat capacity of state node `node` \[J/K\] (`None` out of range).
    pub fn capacity_j_per_k(&self, node: usize) -> Option<f64> {
        self.capacity_j_per_k.get(node).copied()
    }

    /// Conductance between state nodes `a` and `b` \[W/K\]; symmetric.
    pub fn conductance_w_per_k(&self, a: usize, b: usize) -> f64 {
        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
        self.pair_w_per_k
            .get(lo)
            .and_then(|row| row.get(hi))
            .copied()
            .unwrap_or(0.0)
    }

    /// Conductance from state node `node` to boundary `boundary` \[W/K\].
    pub fn boundary_conductance_w_per_k(&self, node: usize, boundary: usize) -> f64 {
        self.boundary_w_per_k
            .get(node)
            .and_then(|row| row.get(boundary))
            .copied()
            .unwrap_or(0.0)
    }

    /// The Joule source of current input `input`, if one is attached.
    pub fn source(&self, input: usize) -> Option<JouleSource> {
        self.sources.get(input).copied().flatten()
    }

    /// Fixed power at `node` \[W\].
    pub fn fixed_power_w(&self, node: usize) -> f64 {
        self.fixed_power_w.get(node).copied().unwrap_or(0.0)
    }

    /// Sum of all conductances at `node` \[W/K\] (neighbours and boundaries).
    pub fn total_conductance_w_per_k(&self, node: usize) -> f64 {
        let pairs: f64 = (0..N)
            .filter(|&j| j != node)
            .map(|j| self.conductance_w_per_k(node, j))
            .sum();
        let boundaries: f64 = self
            .boundary_w_per_k
            .get(node)
            .map_or(0.0, |row| row.iter().sum());
        pairs + boundaries
    }

    /// Checks that every current input has a source (steppers need them all).
    pub fn check_sources(&self) -> Result<(), BuildError> {
        match self.sources.iter().position(Option::is_none) {
            Some(input) => Err(BuildError::MissingSource { input }),
            None => Ok(()),
        }
    }

    /// Joule power of every input \[W\] at node temperatures `temps_c`
    /// (`currents_a[m]` is an effective voltage \[V\] for a voltage-driven
    /// input, see [`Drive`]).
    pub fn joule_powers_w(&self, temps_c: &[f64; N], currents_a: &[f64; M]) -> [f64; M] {
        let mut p = [0.0; M];
        for ((p, source), i) in p.iter_mut().zip(&self.sources).zip(currents_a) {
            if let Some(s) = source {
                *p = s.resistance.power_w(s.drive, temps_c[s.node], *i);
            }
        }
        p
    }

    /// Net heat flow into each node \[W\]: the right-hand side `C dT/dt`.
    pub fn heat_flows_w(
        &self,
        temps_c: &[f64; N],
        currents_a: &[f64; M],
        boundary_c: &[f64; B],
    ) -> [f64; N] {
        let mut q = self.fixed_power_w;
        for i in 0..N {
            for j in (i + 1)..N {
                let flow = self.pair_w_per_k[i][j] * (temps_c[j] - temps_c[i]);
                q[i] += flow;
                q[j] -= flow;
            }
            for (g, tb) in self.boundary_w_per_k[i].iter().zip(boundary_c) {
                q[i] += g * (tb - temps_c[i]);
            }
        }
        let powers = self.joule_powers_w(temps_c, currents_a);
        for (source, p) in self.sources.iter().zip(powers) {
            if let Some(s) = source {
                q[s.node] += p;
            }
        }
        q
    }

    /// `dT/dt` \[K/s\] of every node: the nonlinear right-hand side (with
    /// `R(T)`), for reference integrators and tests.
    pub fn derivative_k_per_s(
        &self,
        temps_c: &[f64; N],
        currents_a: &[f64; M],
        boundary_c: &[f64; B],
    ) -> [f64; N] {
        let mut q = self.heat_flows_w(temps_c, currents_a, boundary_c);
        for (q, c) in q.iter_mut().zip(&self.capacity_j_per_k) {
            *q /= c;
        }
        q
    }

    /// The energy account at one instant.
    pub fn energy_rates(
        &self,
        temps_c: &[f64; N],
        currents_a: &[f64; M],
        boundary_c: &[f64; B],
    ) -> EnergyRates {
        let input_w = self.joule_powers_w(temps_c, currents_a).iter().sum::<f64>()
            + self.fixed_power_w.iter().sum::<f64>();
        let stored_w = self
            .heat_flows_w(temps_c, currents_a, boundary_c)
            .iter()
            .sum();
        let mut to_boundaries_w = 0.0;
        for (row, t) in self.boundary_w_per_k.iter().zip(temps_c) {
            for (g, tb) in row.iter().zip(boundary_c) {
                to_boundaries_w += g * (t - tb);
            }
        }
        EnergyRates {
            input_w,
            stored_w,
            to_boundaries_w,
        }
    }

    /// The state space at the operating point `op_temps_c` \[degC\]
    /// (see [`state_space_of`]).
    pub fn state_space(&self, op_temps_c: &[f64; N]) -> ConstStateSpace<N, B, M> {
        state_space_of(self, op_temps_c)
    }
}

#[cfg(test)]
mod tests;
