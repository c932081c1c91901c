//! The explicit step of a network whose sizes are known only at run time
//! (the `alloc` feature: a host running a model file of any size).
//!
//! [`RunTimeStepper`] is [`ExplicitStepper`](super::ExplicitStepper) with
//! its coefficients in vectors: built by the same checks and packing from
//! any [`NetworkDescription`], stepped by the same kernel
//! ([`gather_energy`], [`apply_energy`]), so that a network stepped at its
//! own size gives the const-generic stepper's temperatures to the bit. No
//! padding, no size class: a network of any size memory holds. A step
//! allocates nothing (its scratch lives in the state).

use alloc::vec::Vec;

use super::{checked_step, explicit_step, packed_pairs, Coefficients, PackedRow, StateParts};
use crate::error::BuildError;
use crate::input::{InputFlags, InputLimits, ScalarLimits};
use crate::network::{NetworkDescription, Resistance, ScalarResistance};
use crate::scalar::Scalar;

/// A validated explicit stepper of run-time sizes: immutable configuration,
/// shareable.
#[derive(Debug, Clone)]
pub struct RunTimeStepper<S> {
    dt_s: f64,
    dt: S,
    nodes: usize,
    boundaries: usize,
    /// `G_ij dt` \[J/K\] of every node's pairs with later nodes, node after
    /// node (node `i`'s in `row_start[i]..row_start[i + 1]`).
    pair_g_dt: Vec<S>,
    /// The later node `j` of each packed pair.
    pair_node: Vec<usize>,
    /// Where each node's pairs start in [`Self::pair_g_dt`] (`nodes + 1`
    /// entries).
    row_start: Vec<usize>,
    /// `G_ib dt` \[J/K\], `boundaries` per node.
    boundary_g_dt: Vec<S>,
    /// `1 / C_i` \[K/J\].
    inverse_capacity: Vec<S>,
    /// Fixed power times dt \[J\] per node.
    fixed_energy_j: Vec<S>,
    source_node: Vec<usize>,
    resistance: Vec<ScalarResistance<S>>,
    limits: ScalarLimits<S>,
    stability_ratio: f64,
}

/// The per-device state of a [`RunTimeStepper`]: temperatures and the last
/// valid inputs, sized by [`RunTimeStepper::state`].
#[derive(Debug, Clone, PartialEq)]
pub struct RunTimeState<S> {
    /// Node temperatures \[degC\].
    pub temps_c: Vec<S>,
    /// Last valid current of each input \[A\].
    pub held_currents_a: Vec<S>,
    /// Last valid temperature of each boundary \[degC\].
    pub held_boundary_c: Vec<S>,
    /// What each node's temperature could not hold \[K\] (see
    /// [`compensated_add`](super::compensated_add)).
    pub residual_c: Vec<S>,
    /// The step's energy per node \[J\] (scratch: a step allocates nothing).
    energy_j: Vec<S>,
}

/// A state, a current or a boundary list whose length is not the
/// stepper's: the step did nothing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SizeMismatch;

impl core::fmt::Display for SizeMismatch {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("a state or input list does not have the stepper's size")
    }
}

impl<S: Scalar> RunTimeStepper<S> {
    /// Builds the stepper of `network` for a fixed step `dt_s` \[s\], with
    /// the errors of [`ExplicitStepper::new`](super::ExplicitStepper::new).
    pub fn new(
        network: &impl NetworkDescription,
        dt_s: f64,
        limits: InputLimits,
    ) -> Result<Self, BuildError> {
        let stability_ratio = checked_step(network, dt_s, limits)?;
        let (nodes, boundaries) = (network.node_count(), network.boundary_count());
        let mut pair_g_dt = Vec::new();
        let mut pair_node = Vec::new();
        let mut row_start = Vec::with_capacity(nodes + 1);
        let mut boundary_g_dt = Vec::with_capacity(nodes * boundaries);
        for i in 0..nodes {
            row_start.push(pair_g_dt.len());
            for (g_dt, j) in packed_pairs::<S>(network, i, dt_s) {
                pair_g_dt.push(g_dt);
                pair_node.push(j);
            }
            boundary_g_dt.extend(
                (0..boundaries).map(|b| S::from_f64(network.boundary_link_w_per_k(i, b) * dt_s)),
            );
        }
        row_start.push(pair_g_dt.len());
        let sources: Vec<_> = (0..network.input_count())
            .map(|m| match network.joule_source_of(m) {
                Some(s) => (s.node, s.resistance.to_scalar()),
                // `checked_step` refuses a missing source.
                None => (0, Resistance::constant(0.0).to_scalar()),
            })
            .collect();
        Ok(Self {
            dt_s,
            dt: S::from_f64(dt_s),
            nodes,
            boundaries,
            pair_g_dt,
            pair_node,
            row_start,
            boundary_g_dt,
            inverse_capacity: (0..nodes)
                .map(|i| S::from_f64(1.0 / network.capacity_at_j_per_k(i)))
                .collect(),
            fixed_energy_j: (0..nodes)
                .map(|i| S::from_f64(network.fixed_power_at_w(i) * dt_s))
                .collect(),
            source_node: sources.iter().map(|s| s.0).collect(),
            resistance: sources.iter().map(|s| s.1).collect(),
            limits: limits.to_scalar(),
            stability_ratio,
        })
    }

    /// The fixed step \[s\].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The largest `dt * sum(G) / C` over the nodes (below 1 by construction).
    pub fn stability_ratio(&self) -> f64 {
        self.stability_ratio
    }

    /// Number of state nodes.
    pub fn nodes(&self) -> usize {
        self.nodes
    }

    /// A state for this stepper: every node and boundary at `temp_c`
    /// \[degC\], currents zero.
    pub fn state(&self, temp_c: f64) -> RunTimeState<S> {
        RunTimeState {
            temps_c: alloc::vec![S::from_f64(temp_c); self.nodes],
            held_currents_a: alloc::vec![S::ZERO; self.source_node.len()],
            held_boundary_c: alloc::vec![S::from_f64(temp_c); self.boundaries],
            residual_c: alloc::vec![S::ZERO; self.nodes],
            energy_j: alloc::vec![S::ZERO; self.nodes],
        }
    }

    /// Advances `state` by one step with these inputs (one current per
    /// input \[A\], one temperature per boundary \[degC\]), as
    /// [`ExplicitStepper::step`](super::ExplicitStepper::step): bad inputs
    /// replaced and flagged, bounded `O(P + N B + M)` work, no panic, no
    /// allocation.
    ///
    /// # Errors
    /// [`SizeMismatch`], the state untouched, when `state` is not this
    /// stepper's size or an input list is not.
    pub fn step(
        &self,
        state: &mut RunTimeState<S>,
        currents_a: &[S],
        boundary_c: &[S],
    ) -> Result<InputFlags, SizeMismatch> {
        let sized = |len: usize, of: usize| len == of;
        if !(sized(state.temps_c.len(), self.nodes)
            && sized(state.residual_c.len(), self.nodes)
            && sized(state.energy_j.len(), self.nodes)
            && sized(state.held_currents_a.len(), self.source_node.len())
            && sized(currents_a.len(), self.source_node.len())
            && sized(state.held_boundary_c.len(), self.boundaries)
            && sized(boundary_c.len(), self.boundaries))
        {
            return Err(SizeMismatch);
        }
        state.energy_j.copy_from_slice(&self.fixed_energy_j);
        let rows = self.row_start.windows(2).enumerate().map(|(i, w)| {
            let pairs = w[0]..w[1];
            let b = i * self.boundaries;
            PackedRow {
                g_dt: self.pair_g_dt.get(pairs.clone()).unwrap_or(&[]),
                node: self.pair_node.get(pairs).unwrap_or(&[]),
                boundary_g_dt: self
                    .boundary_g_dt
                    .get(b..b + self.boundaries)
                    .unwrap_or(&[]),
            }
        });
        Ok(explicit_step(
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
                energy_j: &mut state.energy_j,
            },
            currents_a,
            boundary_c,
        ))
    }
}
