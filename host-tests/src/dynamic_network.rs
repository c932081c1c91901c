//! The run-time *description* of a model file's network.
//!
//! A model file has a size known only at run time, while the library's
//! [`Network`] has const-generic sizes. [`DynNetwork`] holds the same
//! description (capacities, pair conductances stored once, boundary
//! conductances, Joule sources with the library's [`Resistance`], fixed
//! powers) in `Vec`s, validated as the library validates it. It computes
//! nothing: it is a [`NetworkDescription`] whose sizes are
//! `RunTimeSizes`, so the library steps it (`RunTimeStepper`) and solves
//! its steady state, time to limit, safe and runaway currents, and builds
//! the firmware's network observer (`RunTimeObserver`, which the replay
//! and the fault campaign run), at its own size.

use coil_thermal::network::{JouleSource, NetworkDescription};
use coil_thermal::sizes::RunTimeSizes;
use coil_thermal::{Drive, Network, Resistance};

/// A conductance between two state nodes `a < b` \[W/K\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// Lower node index.
    pub a: usize,
    /// Higher node index.
    pub b: usize,
    /// Conductance \[W/K\].
    pub g_w_per_k: f64,
}

/// A conductance from a state node to a boundary \[W/K\].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryLink {
    /// State node index.
    pub node: usize,
    /// Boundary index.
    pub boundary: usize,
    /// Conductance \[W/K\].
    pub g_w_per_k: f64,
}

/// A Joule source: input slot `k` heats `node` with `R(T_node) I_k^2`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Source {
    /// Heated state node.
    pub node: usize,
    /// Resistance line `R(T)`.
    pub resistance: Resistance,
}

/// Why a dynamic network could not be built (as
/// [`coil_thermal::BuildError`], with indices that refer to the description).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DynError {
    /// Capacity not finite or not > 0 J/K.
    #[error("heat capacity of node {0} must be finite and > 0 J/K")]
    Capacity(usize),
    /// Conductance not finite or negative.
    #[error("conductance between {0} and {1} must be finite and >= 0 W/K")]
    Conductance(usize, usize),
    /// Index out of range.
    #[error("node index {0} is out of range")]
    OutOfRange(usize),
    /// Conductance from a node to itself.
    #[error("conductance from node {0} to itself")]
    SelfLoop(usize),
    /// Resistance coefficients not finite.
    #[error("resistance of source {0} must be finite")]
    Resistance(usize),
    /// Fixed power not finite.
    #[error("fixed power at node {0} must be finite")]
    Power(usize),
}

/// A thermal network with runtime sizes (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct DynNetwork {
    capacity_j_per_k: Vec<f64>,
    boundaries: usize,
    /// Sorted by `(a, b)`, one entry per pair (parallel paths summed).
    pairs: Vec<Pair>,
    /// Sorted by `(node, boundary)`, one entry per link.
    links: Vec<BoundaryLink>,
    sources: Vec<Source>,
    fixed_power_w: Vec<f64>,
    /// `max_i sum(G_i) / C_i` \[1/s\].
    max_rate_per_s: f64,
}

impl DynNetwork {
    /// `capacities.len()` isolated nodes with these capacities \[J/K\] and
    /// `boundaries` boundary nodes.
    pub fn new(capacity_j_per_k: Vec<f64>, boundaries: usize) -> Result<Self, DynError> {
        if let Some(i) = capacity_j_per_k
            .iter()
            .position(|c| !(c.is_finite() && *c > 0.0))
        {
            return Err(DynError::Capacity(i));
        }
        let n = capacity_j_per_k.len();
        Ok(Self {
            capacity_j_per_k,
            boundaries,
            pairs: Vec::new(),
            links: Vec::new(),
            sources: Vec::new(),
            fixed_power_w: vec![0.0; n],
            max_rate_per_s: 0.0,
        })
    }

    /// Number of state nodes.
    pub fn nodes(&self) -> usize {
        self.capacity_j_per_k.len()
    }

    /// Number of boundary nodes.
    pub fn boundaries(&self) -> usize {
        self.boundaries
    }

    /// The Joule sources, one per current slot (in input order).
    pub fn sources(&self) -> &[Source] {
        &self.sources
    }

    /// Capacities \[J/K\].
    pub fn capacities_j_per_k(&self) -> &[f64] {
        &self.capacity_j_per_k
    }

    /// Pair conductances, sorted.
    pub fn pairs(&self) -> &[Pair] {
        &self.pairs
    }

    /// Boundary conductances, sorted.
    pub fn links(&self) -> &[BoundaryLink] {
        &self.links
    }

    /// Fixed powers \[W\].
    pub fn fixed_powers_w(&self) -> &[f64] {
        &self.fixed_power_w
    }

    /// Adds `g_w_per_k` \[W/K\] between state nodes `a` and `b` (summed with
    /// any conductance already there, in call order, as the library does).
    pub fn connect(&mut self, a: usize, b: usize, g_w_per_k: f64) -> Result<(), DynError> {
        let n = self.nodes();
        if a >= n {
            return Err(DynError::OutOfRange(a));
        }
        if b >= n {
            return Err(DynError::OutOfRange(b));
        }
        if a == b {
            return Err(DynError::SelfLoop(a));
        }
        if !(g_w_per_k.is_finite() && g_w_per_k >= 0.0) {
            return Err(DynError::Conductance(a, b));
        }
        let (a, b) = if a < b { (a, b) } else { (b, a) };
        match self.pairs.binary_search_by(|p| (p.a, p.b).cmp(&(a, b))) {
            Ok(k) => self.pairs[k].g_w_per_k += g_w_per_k,
            Err(k) => self.pairs.insert(k, Pair { a, b, g_w_per_k }),
        }
        self.update_rate();
        Ok(())
    }

    /// Adds `g_w_per_k` \[W/K\] from state node `node` to boundary `boundary`.
    pub fn connect_boundary(
        &mut self,
        node: usize,
        boundary: usize,
        g_w_per_k: f64,
    ) -> Result<(), DynError> {
        if node >= self.nodes() {
            return Err(DynError::OutOfRange(node));
        }
        if boundary >= self.boundaries {
            return Err(DynError::OutOfRange(boundary));
        }
        if !(g_w_per_k.is_finite() && g_w_per_k >= 0.0) {
            return Err(DynError::Conductance(node, boundary));
        }
        match self
            .links
            .binary_search_by(|l| (l.node, l.boundary).cmp(&(node, boundary)))
        {
            Ok(k) => self.links[k].g_w_per_k += g_w_per_k,
            Err(k) => self.links.insert(
                k,
                BoundaryLink {
                    node,
                    boundary,
                    g_w_per_k,
                },
            ),
        }
        self.update_rate();
        Ok(())
    }

    /// Appends a Joule source heating `node`; returns its slot index.
    pub fn joule_source(&mut self, node: usize, resistance: Resistance) -> Result<usize, DynError> {
        if node >= self.nodes() {
            return Err(DynError::OutOfRange(node));
        }
        if !(resistance.r_at_0c_ohm.is_finite() && resistance.slope_ohm_per_k.is_finite()) {
            return Err(DynError::Resistance(self.sources.len()));
        }
        self.sources.push(Source { node, resistance });
        Ok(self.sources.len() - 1)
    }

    /// Multiplies source `source`'s resistance line by `factor` (a power
    /// scale folded into the winding: `k R(T) I^2`); nothing for a source
    /// it does not have.
    pub fn scale_resistance(&mut self, source: usize, factor: f64) {
        if let Some(s) = self.sources.get_mut(source) {
            s.resistance = Resistance::linear_fit(
                factor * s.resistance.slope_ohm_per_k,
                factor * s.resistance.r_at_0c_ohm,
            );
        }
    }

    /// Adds a constant power \[W\] at `node`.
    pub fn fixed_power(&mut self, node: usize, power_w: f64) -> Result<(), DynError> {
        if node >= self.nodes() {
            return Err(DynError::OutOfRange(node));
        }
        if !power_w.is_finite() {
            return Err(DynError::Power(node));
        }
        self.fixed_power_w[node] += power_w;
        Ok(())
    }

    fn update_rate(&mut self) {
        let mut total = vec![0.0; self.nodes()];
        for p in &self.pairs {
            total[p.a] += p.g_w_per_k;
            total[p.b] += p.g_w_per_k;
        }
        for l in &self.links {
            total[l.node] += l.g_w_per_k;
        }
        self.max_rate_per_s = total
            .iter()
            .zip(&self.capacity_j_per_k)
            .map(|(g, c)| g / c)
            .fold(0.0, f64::max);
    }

    /// `max_i sum(G_i) / C_i` \[1/s\]: an explicit step `h` is stable and
    /// positive when `h` times this is below 1.
    pub fn max_rate_per_s(&self) -> f64 {
        self.max_rate_per_s
    }

    /// The same description as a library network (for sizes known at
    /// compile time): `N` nodes, `B` boundaries, `M` sources.
    pub fn to_network<const N: usize, const B: usize, const M: usize>(
        &self,
    ) -> Result<Network<N, B, M>, coil_thermal::BuildError> {
        use coil_thermal::BuildError;
        if self.nodes() != N || self.boundaries != B || self.sources.len() != M {
            return Err(BuildError::InvalidParameter { name: "size" });
        }
        let mut c = [0.0; N];
        c.copy_from_slice(&self.capacity_j_per_k);
        let mut net = Network::new(c)?;
        for p in &self.pairs {
            net = net.connect(p.a, p.b, p.g_w_per_k)?;
        }
        for l in &self.links {
            net = net.connect_boundary(l.node, l.boundary, l.g_w_per_k)?;
        }
        for (k, s) in self.sources.iter().enumerate() {
            net = net.joule_source(k, s.node, s.resistance)?;
        }
        for (i, p) in self.fixed_power_w.iter().enumerate() {
            if *p != 0.0 {
                net = net.fixed_power(i, *p)?;
            }
        }
        Ok(net)
    }

    /// The description of a library network: the plug-in route for every
    /// device model built on [`Network`] (solenoid, and later grid and
    /// Omnimagnet networks).
    pub fn from_network<const N: usize, const B: usize, const M: usize>(
        net: &Network<N, B, M>,
    ) -> Result<Self, DynError> {
        let caps = (0..N)
            .map(|i| net.capacity_j_per_k(i).unwrap_or(f64::NAN))
            .collect();
        let mut dyn_net = Self::new(caps, B)?;
        for a in 0..N {
            for b in (a + 1)..N {
                let g = net.conductance_w_per_k(a, b);
                if g != 0.0 {
                    dyn_net.connect(a, b, g)?;
                }
            }
            for bd in 0..B {
                let g = net.boundary_conductance_w_per_k(a, bd);
                if g != 0.0 {
                    dyn_net.connect_boundary(a, bd, g)?;
                }
            }
            dyn_net.fixed_power(a, net.fixed_power_w(a))?;
        }
        for m in 0..M {
            let s = net.source(m).ok_or(DynError::OutOfRange(m))?;
            dyn_net.joule_source(s.node, s.resistance)?;
        }
        Ok(dyn_net)
    }
}

impl NetworkDescription for DynNetwork {
    type Sizes = RunTimeSizes;

    fn sizes(&self) -> RunTimeSizes {
        RunTimeSizes {
            nodes: self.nodes(),
            boundaries: self.boundaries,
            inputs: self.sources.len(),
        }
    }

    fn node_count(&self) -> usize {
        self.nodes()
    }

    fn boundary_count(&self) -> usize {
        self.boundaries
    }

    fn input_count(&self) -> usize {
        self.sources.len()
    }

    fn capacity_at_j_per_k(&self, node: usize) -> f64 {
        self.capacity_j_per_k.get(node).copied().unwrap_or(f64::NAN)
    }

    fn later_pairs_w_per_k(&self, node: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        // Sorted by `(a, b)`: node `node`'s pairs are one run, in increasing `b`.
        let start = self.pairs.partition_point(|p| p.a < node);
        self.pairs[start..]
            .iter()
            .take_while(move |p| p.a == node)
            .map(|p| (p.b, p.g_w_per_k))
    }

    fn boundary_link_w_per_k(&self, node: usize, boundary: usize) -> f64 {
        self.links
            .binary_search_by(|l| (l.node, l.boundary).cmp(&(node, boundary)))
            .map_or(0.0, |k| self.links[k].g_w_per_k)
    }

    fn conductance_sum_w_per_k(&self, node: usize) -> f64 {
        // As the library's `Network::total_conductance_w_per_k`: the pairs
        // in the order of the other node, then the boundaries.
        let pairs: f64 = self
            .pairs
            .iter()
            .filter(|p| p.a == node || p.b == node)
            .map(|p| p.g_w_per_k)
            .sum();
        let links: f64 = self
            .links
            .iter()
            .filter(|l| l.node == node)
            .map(|l| l.g_w_per_k)
            .sum();
        pairs + links
    }

    fn fixed_power_at_w(&self, node: usize) -> f64 {
        self.fixed_power_w.get(node).copied().unwrap_or(0.0)
    }

    fn joule_source_of(&self, input: usize) -> Option<JouleSource> {
        self.sources.get(input).map(|s| JouleSource {
            node: s.node,
            resistance: s.resistance,
            drive: Drive::Current,
        })
    }
}
