//! What a stepper reads of a network, whatever holds it.
//!
//! [`Network`] holds a description whose sizes are const generics, as an
//! MCU needs. A model file read on a host has its sizes only at run time
//! (a motor's network from a design tool has hundreds of nodes); the host
//! keeps that description in vectors. [`NetworkDescription`] is the one
//! face both show to the code that builds a stepper from them, so that a
//! network of any size runs through the library's own step
//! ([`ExplicitStepper`](super::ExplicitStepper) on the MCU, and, with the
//! `alloc` feature, `RunTimeStepper` on a host), not through a copy of it.

use super::{JouleSource, Network};
use crate::sizes::{BoundaryVector, ConstSizes, InputVector, NodeVector, Sizes};

/// A value per state node of network `W`: an array for a [`Network`], a
/// `Vec` for one read at run time.
pub type Nodes<W, U> = NodeVector<<W as NetworkDescription>::Sizes, U>;

/// A value per boundary of network `W`.
pub type Boundaries<W, U> = BoundaryVector<<W as NetworkDescription>::Sizes, U>;

/// A value per input (current source) of network `W`.
pub type Inputs<W, U> = InputVector<<W as NetworkDescription>::Sizes, U>;

/// A thermal network as a stepper reads it: sizes, capacities, the
/// conductances of each node to its later neighbours and to the
/// boundaries, fixed powers and Joule sources (every quantity in SI units,
/// temperatures in degC).
pub trait NetworkDescription {
    /// The sizes of the vectors over this network's nodes, boundaries and
    /// inputs: arrays for a [`Network`] ([`ConstSizes`]), `Vec`s of its
    /// lengths for one read at run time
    /// (`RunTimeSizes`). What the analyses
    /// written over [`Sizes`] (the steady state, the time-to-limit
    /// predictor, the runaway currents) take and return for it.
    type Sizes: Sizes;

    /// This network's [`Self::Sizes`].
    fn sizes(&self) -> Self::Sizes;

    /// Number of state nodes.
    fn node_count(&self) -> usize;

    /// Number of boundary nodes.
    fn boundary_count(&self) -> usize;

    /// Number of current inputs (one Joule source each).
    fn input_count(&self) -> usize;

    /// Heat capacity of state node `node` \[J/K\] (NaN out of range).
    fn capacity_at_j_per_k(&self, node: usize) -> f64;

    /// The conductances \[W/K\] from `node` to each later node `j > node`
    /// it is connected to, as `(j, g)` in increasing `j` (a pair stored
    /// once, parallel paths summed; a zero conductance may be listed).
    fn later_pairs_w_per_k(&self, node: usize) -> impl Iterator<Item = (usize, f64)> + '_;

    /// Conductance from state node `node` to boundary `boundary` \[W/K\].
    fn boundary_link_w_per_k(&self, node: usize, boundary: usize) -> f64;

    /// Sum of all conductances at `node` \[W/K\] (neighbours and
    /// boundaries): what bounds a stable explicit step.
    fn conductance_sum_w_per_k(&self, node: usize) -> f64;

    /// Fixed power at `node` \[W\].
    fn fixed_power_at_w(&self, node: usize) -> f64;

    /// The Joule source of current input `input` (`None`: none attached).
    fn joule_source_of(&self, input: usize) -> Option<JouleSource>;
}

impl<const N: usize, const B: usize, const M: usize> NetworkDescription for Network<N, B, M> {
    type Sizes = ConstSizes<N, B, M>;

    fn sizes(&self) -> ConstSizes<N, B, M> {
        ConstSizes
    }

    fn node_count(&self) -> usize {
        N
    }

    fn boundary_count(&self) -> usize {
        B
    }

    fn input_count(&self) -> usize {
        M
    }

    fn capacity_at_j_per_k(&self, node: usize) -> f64 {
        self.capacity_j_per_k(node).unwrap_or(f64::NAN)
    }

    fn later_pairs_w_per_k(&self, node: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let row = self.pair_w_per_k.get(node);
        ((node + 1)..N).map(move |j| (j, row.and_then(|r| r.get(j)).copied().unwrap_or(0.0)))
    }

    fn boundary_link_w_per_k(&self, node: usize, boundary: usize) -> f64 {
        self.boundary_conductance_w_per_k(node, boundary)
    }

    fn conductance_sum_w_per_k(&self, node: usize) -> f64 {
        self.total_conductance_w_per_k(node)
    }

    fn fixed_power_at_w(&self, node: usize) -> f64 {
        self.fixed_power_w(node)
    }

    fn joule_source_of(&self, input: usize) -> Option<JouleSource> {
        self.source(input)
    }
}
