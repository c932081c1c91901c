//! The hot-path explicit step of a network, in any [`Scalar`].
//!
//! Forward Euler on the energy balance, written as a sum of pair *flows*:
//! each conductance's flow `G dt (T_j - T_i)` \[J\] is computed once and added
//! to one node and subtracted from the other, so the step conserves energy
//! exactly as the network does (up to the rounding of the final `/ C`).
//!
//! Stability and positivity: the new temperature of node `i` is a weighted
//! average of the old temperatures with weights `1 - dt sum(G_i)/C_i` and
//! `dt G_ij / C_i`, plus the heat input. With `dt sum(G_i)/C_i < 1` every
//! weight is positive: no oscillation, no overshoot of the boundary
//! temperatures. [`ExplicitStepper::new`] refuses any `dt` that breaks this.

use super::{Network, NetworkDescription, ScalarResistance};

#[cfg(feature = "alloc")]
mod run_time;
use crate::error::BuildError;
use crate::input::{InputFlags, InputLimits, ScalarLimits};
use crate::scalar::Scalar;
#[cfg(feature = "alloc")]
pub use run_time::{RunTimeState, RunTimeStepper, SizeMismatch};

/// A validated explicit stepper: immutable configuration, shareable.
#[derive(Debug, Clone)]
pub struct ExplicitStepper<S, const N: usize, const B: usize, const M: usize> {
    dt_s: f64,
    dt: S,
    /// `G_ij dt` \[J/K\] of node `i`'s pairs with a later node `j`, in
    /// increasing `j`, packed at the start of row `i` (`pair_count[i]` of
    /// them; unconnected pairs are not stored, so a step costs the
    /// connections, not `N^2`).
    pair_g_dt: [[S; N]; N],
    /// The later node `j` of each packed pair.
    pair_node: [[u16; N]; N],
    /// Pairs packed in each row.
    pair_count: [u16; N],
    /// `G_ib dt` \[J/K\].
    boundary_g_dt: [[S; B]; N],
    /// `1 / C_i` \[K/J\].
    inverse_capacity: [S; N],
    /// Fixed power times dt \[J\] per node.
    fixed_energy_j: [S; N],
    source_node: [usize; M],
    resistance: [ScalarResistance<S>; M],
    limits: ScalarLimits<S>,
    stability_ratio: f64,
}

/// The per-device state of a network stepper: temperatures and the last
/// valid inputs (held when an input turns bad, see [`crate::input`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetworkState<S, const N: usize, const B: usize, const M: usize> {
    /// Node temperatures \[degC\].
    pub temps_c: [S; N],
    /// Last valid current of each input \[A\].
    pub held_currents_a: [S; M],
    /// Last valid temperature of each boundary \[degC\].
    pub held_boundary_c: [S; B],
    /// The part of each node's temperature that its `f32` value could not
    /// hold \[K\] (compensated summation, see [`compensated_add`]).
    pub residual_c: [S; N],
}

impl<S: Scalar, const N: usize, const B: usize, const M: usize> NetworkState<S, N, B, M> {
    /// Every node at `temp_c`, every boundary at `temp_c`, currents zero.
    pub fn uniform(temp_c: f64) -> Self {
        Self {
            temps_c: [S::from_f64(temp_c); N],
            held_currents_a: [S::ZERO; M],
            held_boundary_c: [S::from_f64(temp_c); B],
            residual_c: [S::ZERO; N],
        }
    }
}

impl<S: Scalar, const N: usize, const B: usize, const M: usize> ExplicitStepper<S, N, B, M> {
    /// Builds the stepper for a fixed step `dt_s` \[s\].
    ///
    /// Errors: [`BuildError::InvalidTimeStep`], [`BuildError::MissingSource`],
    /// [`BuildError::UnstableStep`] naming the worst node when
    /// `dt * sum(G) / C >= 1` there, or an invalid `limits` parameter;
    /// [`BuildError::InvalidParameter`] `"voltage_source"` for a network with
    /// a voltage-driven source (its step takes currents only: drive it with
    /// the current the winding draws, `V_eff / R(T)`, as the observers do).
    pub fn new(
        network: &Network<N, B, M>,
        dt_s: f64,
        limits: InputLimits,
    ) -> Result<Self, BuildError> {
        const { assert!(N <= 1 << 16, "node indices are stored as u16") };
        let stability_ratio = checked_step(network, dt_s, limits)?;
        let mut stepper = Self {
            dt_s,
            dt: S::from_f64(dt_s),
            pair_g_dt: [[S::ZERO; N]; N],
            pair_node: [[0; N]; N],
            pair_count: [0; N],
            boundary_g_dt: [[S::ZERO; B]; N],
            inverse_capacity: [S::ZERO; N],
            fixed_energy_j: [S::ZERO; N],
            source_node: [0; M],
            resistance: [super::Resistance::constant(0.0).to_scalar(); M],
            limits: limits.to_scalar(),
            stability_ratio,
        };
        for i in 0..N {
            let mut count = 0;
            for (g_dt, j) in packed_pairs::<S>(network, i, dt_s) {
                // `N <= 2^16` (checked above) and `j < N`.
                stepper.pair_g_dt[i][count] = g_dt;
                stepper.pair_node[i][count] = j as u16;
                count += 1;
            }
            stepper.pair_count[i] = count as u16;
            for b in 0..B {
                stepper.boundary_g_dt[i][b] =
                    S::from_f64(network.boundary_link_w_per_k(i, b) * dt_s);
            }
            stepper.inverse_capacity[i] = S::from_f64(1.0 / network.capacity_at_j_per_k(i));
            stepper.fixed_energy_j[i] = S::from_f64(network.fixed_power_at_w(i) * dt_s);
        }
        for m in 0..M {
            if let Some(source) = network.joule_source_of(m) {
                stepper.source_node[m] = source.node;
                stepper.resistance[m] = source.resistance.to_scalar();
            }
        }
        Ok(stepper)
    }

    /// The fixed step \[s\].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The largest `dt * sum(G) / C` over the nodes (below 1 by construction).
    pub fn stability_ratio(&self) -> f64 {
        self.stability_ratio
    }

    /// Advances `state` by one step `dt_s` with these inputs.
    ///
    /// Bad inputs are replaced as documented in [`crate::input`] and the
    /// returned flags say which rule fired. Bounded `O(P + N B + M)` work
    /// for `P` connected pairs, no panic, no allocation.
    pub fn step(
        &self,
        state: &mut NetworkState<S, N, B, M>,
        currents_a: &[S; M],
        boundary_c: &[S; B],
    ) -> InputFlags {
        let mut energy_j = self.fixed_energy_j;
        let rows = self
            .pair_g_dt
            .iter()
            .zip(&self.pair_node)
            .zip(&self.pair_count)
            .zip(&self.boundary_g_dt)
            .map(|(((g_row, node_row), &count), boundary_row)| {
                let count = usize::from(count);
                PackedRow {
                    g_dt: g_row.get(..count).unwrap_or(&[]),
                    node: node_row.get(..count).unwrap_or(&[]),
                    boundary_g_dt: boundary_row,
                }
            });
        explicit_step(
            &Coefficients {
                rows,
                source_node: &self.source_node,
                resistance: &self.resistance,
                inverse_capacity: &self.inverse_capacity,
                limits: &self.limits,
                dt: self.dt,
            },
            StateParts {
                temps_c: &mut state.temps_c,
                residual_c: &mut state.residual_c,
                held_currents_a: &mut state.held_currents_a,
                held_boundary_c: &mut state.held_boundary_c,
                energy_j: &mut energy_j,
            },
            currents_a,
            boundary_c,
        )
    }
}

/// Checks a network and a step `dt_s` \[s\] for an explicit stepper (see
/// [`ExplicitStepper::new`] for the errors); returns the largest
/// `dt * sum(G) / C` over the nodes.
pub(super) fn checked_step<D: NetworkDescription>(
    network: &D,
    dt_s: f64,
    limits: InputLimits,
) -> Result<f64, BuildError> {
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(BuildError::InvalidTimeStep);
    }
    for input in 0..network.input_count() {
        match network.joule_source_of(input) {
            None => return Err(BuildError::MissingSource { input }),
            Some(s) if s.drive == super::Drive::Voltage => {
                return Err(BuildError::InvalidParameter {
                    name: "voltage_source",
                })
            }
            Some(_) => {}
        }
    }
    limits.validate()?;
    let mut worst = (0, 0.0f64);
    for i in 0..network.node_count() {
        let c = network.capacity_at_j_per_k(i);
        let ratio = dt_s * network.conductance_sum_w_per_k(i) / c;
        if ratio > worst.1 {
            worst = (i, ratio);
        }
    }
    if worst.1 >= 1.0 {
        return Err(BuildError::UnstableStep {
            node: worst.0,
            ratio: worst.1 as f32,
        });
    }
    Ok(worst.1)
}

/// Node `i`'s pairs with later nodes as `(G_ij dt, j)` in the stepper's
/// scalar, in increasing `j`, without those that round to zero (they move
/// no heat, and a step costs the connections, not `N^2`).
pub(super) fn packed_pairs<S: Scalar>(
    network: &impl NetworkDescription,
    i: usize,
    dt_s: f64,
) -> impl Iterator<Item = (S, usize)> + '_ {
    network
        .later_pairs_w_per_k(i)
        .map(move |(j, g)| (S::from_f64(g * dt_s), j))
        .filter(|(g_dt, _)| *g_dt != S::ZERO)
}

/// What one explicit step reads of a stepper, whatever holds it (arrays
/// on the MCU, vectors on a host): the packed rows in node order, the
/// sources, the inverse capacities, the input rules and the step.
pub(super) struct Coefficients<'a, S, R> {
    /// Each node's packed pairs and boundary links, in node order.
    pub rows: R,
    /// The node each source heats.
    pub source_node: &'a [usize],
    /// Each source's `R(T)`.
    pub resistance: &'a [ScalarResistance<S>],
    /// `1 / C_i` \[K/J\].
    pub inverse_capacity: &'a [S],
    /// The input rules.
    pub limits: &'a ScalarLimits<S>,
    /// The step \[s\].
    pub dt: S,
}

/// What one explicit step writes of a state, whatever holds it.
pub(super) struct StateParts<'s, S> {
    /// Node temperatures \[degC\].
    pub temps_c: &'s mut [S],
    /// Their rounding carry \[K\].
    pub residual_c: &'s mut [S],
    /// The last valid currents \[A\].
    pub held_currents_a: &'s mut [S],
    /// The last valid boundary temperatures \[degC\].
    pub held_boundary_c: &'s mut [S],
    /// Each node's energy this step \[J\], holding the fixed powers'
    /// energy on entry.
    pub energy_j: &'s mut [S],
}

/// One explicit step: the input rules on `currents_a` \[A\] and
/// `boundary_c` \[degC\] (a bad value held, flagged), the energy each node
/// takes in ([`gather_energy`]), the temperatures raised
/// ([`apply_energy`]). The one step of [`ExplicitStepper`] and of its
/// run-time twin.
#[inline]
pub(super) fn explicit_step<'a, S, I, R>(
    c: &Coefficients<'a, S, R>,
    state: StateParts<'_, S>,
    currents_a: &[S],
    boundary_c: &[S],
) -> InputFlags
where
    S: Scalar + 'a,
    I: Copy + Into<usize> + 'a,
    R: Iterator<Item = PackedRow<'a, S, I>> + Clone,
{
    let flags = c.limits.accept_currents(currents_a, state.held_currents_a)
        | c.limits
            .accept_temperatures(boundary_c, state.held_boundary_c);
    let sources = c
        .source_node
        .iter()
        .copied()
        .zip(c.resistance)
        .zip(state.held_currents_a.iter().copied());
    gather_energy(
        state.temps_c,
        c.rows.clone(),
        state.held_boundary_c,
        sources,
        c.dt,
        state.energy_j,
    );
    apply_energy(
        state.temps_c,
        state.residual_c,
        state.energy_j,
        c.inverse_capacity,
    );
    flags
}

/// One node's packed coefficients, as [`gather_energy`] reads them.
pub(super) struct PackedRow<'a, S, I> {
    /// `G_ij dt` \[J/K\] with each later node `j` it is connected to.
    pub g_dt: &'a [S],
    /// Those nodes `j`.
    pub node: &'a [I],
    /// `G_ib dt` \[J/K\] to each boundary.
    pub boundary_g_dt: &'a [S],
}

/// The heat each node takes in over one step \[J\], added to `energy_j`
/// (which holds the fixed powers' energy): each pair's flow `G dt (T_j -
/// T_i)` once, into one node and out of the other (the step conserves
/// energy as the network does), each boundary's flow, each source's `R(T)
/// I^2 dt` at its node's temperature. Rows in node order; a node index out
/// of range moves nothing (never a panic).
#[inline]
pub(super) fn gather_energy<'a, S: Scalar + 'a, I: Copy + Into<usize> + 'a>(
    temps_c: &[S],
    rows: impl Iterator<Item = PackedRow<'a, S, I>>,
    held_boundary_c: &[S],
    sources: impl Iterator<Item = ((usize, &'a ScalarResistance<S>), S)>,
    dt: S,
    energy_j: &mut [S],
) {
    for (i, (&t_i, row)) in temps_c.iter().zip(rows).enumerate() {
        // Pairs in increasing `j`, as the full scan took them: the same
        // sums to the bit.
        for (&g_dt, &j) in row.g_dt.iter().zip(row.node) {
            let j = j.into();
            let Some(&t_j) = temps_c.get(j) else { continue };
            let flow = g_dt * (t_j - t_i);
            if let Some(e_i) = energy_j.get_mut(i) {
                *e_i += flow;
            }
            if let Some(e_j) = energy_j.get_mut(j) {
                *e_j -= flow;
            }
        }
        if let Some(e_i) = energy_j.get_mut(i) {
            for (g_dt, t_b) in row.boundary_g_dt.iter().zip(held_boundary_c) {
                *e_i += *g_dt * (*t_b - t_i);
            }
        }
    }
    for ((node, r), current) in sources {
        if let (Some(t), Some(e)) = (temps_c.get(node), energy_j.get_mut(node)) {
            *e += r.joule_power_w(*t, current) * dt;
        }
    }
}

/// Each node's temperature raised by its energy over its capacity, the
/// rounding carried ([`compensated_add`]).
#[inline]
pub(super) fn apply_energy<S: Scalar>(
    temps_c: &mut [S],
    residual_c: &mut [S],
    energy_j: &[S],
    inverse_capacity: &[S],
) {
    for (((t, residual), e), inv_c) in temps_c
        .iter_mut()
        .zip(residual_c.iter_mut())
        .zip(energy_j)
        .zip(inverse_capacity)
    {
        *t = compensated_add(*t, *e * *inv_c, residual);
    }
}

/// `temp + increment`, carrying what rounding loses in `residual` to the next
/// step (Fast2Sum; valid because an increment is far smaller than the
/// temperature).
///
/// Why: at 1 ms a coil warms by 1e-5 K per step or less, while an `f32` near
/// 60 degC resolves only 3.8e-6 K. Plain `T += dT` then rounds a large share of
/// every increment away, and near steady state the increments vanish
/// altogether: a coil stepped in plain `f32` stalls more than 1 K short of its
/// steady state. With the residual carried, `f32` tracks `f64` to a few mK.
/// For fixed point the addition is exact and the residual stays zero.
#[inline]
pub fn compensated_add<S: Scalar>(temp: S, increment: S, residual: &mut S) -> S {
    let corrected = increment + *residual;
    let sum = temp + corrected;
    *residual = corrected - (sum - temp);
    sum
}
