//! A runtime-size mirror of the library's [`Network`] and
//! [`ExplicitStepper`](coil_thermal::ExplicitStepper), in `f64`.
//!
//! A model file has a size known only at run time, while the library's
//! network has const-generic sizes. This type holds the same description
//! (capacities, pair conductances stored once, boundary conductances, Joule
//! sources with the library's [`Resistance`], fixed powers) in `Vec`s and steps
//! it with *the same operations in the same order* as the library's explicit
//! step, so for any size both give bit-identical `f64` results (tested in
//! `tests/dynamic_agreement.rs`). Pairs are stored sparsely, which keeps
//! calibration of large, sparsely connected networks fast.
//!
//! The one addition is sub-stepping: [`DynNetwork::step`] splits an interval
//! into equal explicit steps so that `h sum(G_i) / C_i <= max_ratio` at every
//! node (the library's stepper refuses a ratio of 1 or more instead).

use coil_thermal::{Network, Resistance};

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

/// Why a dynamic network could not be built (mirrors
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

    /// Number of Joule sources (current slots of [`DynNetwork::step`]).
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

    /// Number of equal sub-steps for an interval `dt_s` so that every
    /// sub-step has `h * max_rate <= max_ratio`.
    pub fn substeps(&self, dt_s: f64, max_ratio: f64) -> usize {
        let n = (dt_s * self.max_rate_per_s / max_ratio).ceil();
        if n.is_finite() && n >= 1.0 {
            n as usize
        } else {
            1
        }
    }

    /// One explicit step of `h_s` \[s\]: the library's
    /// `ExplicitStepper::step` operation for operation (flows per pair, then
    /// boundaries, then Joule power `max(R(T), 0) I^2`, then `/ C`).
    /// `currents_a` has one entry per source, `boundary_c` per boundary.
    pub fn euler_step(
        &self,
        temps_c: &mut [f64],
        currents_a: &[f64],
        boundary_c: &[f64],
        h_s: f64,
        scratch: &mut Vec<f64>,
    ) {
        scratch.clear();
        scratch.extend(self.fixed_power_w.iter().map(|p| p * h_s));
        let energy = scratch.as_mut_slice();
        // Library order: for each node i, its pairs (i, j > i), then its
        // boundaries. Pairs and links are sorted by their first index.
        let (mut p, mut l) = (0, 0);
        for i in 0..temps_c.len() {
            let t_i = temps_c[i];
            while p < self.pairs.len() && self.pairs[p].a == i {
                let pair = self.pairs[p];
                let g_dt = pair.g_w_per_k * h_s;
                if g_dt != 0.0 {
                    let flow = g_dt * (temps_c[pair.b] - t_i);
                    energy[i] += flow;
                    energy[pair.b] -= flow;
                }
                p += 1;
            }
            while l < self.links.len() && self.links[l].node == i {
                let link = self.links[l];
                energy[i] += link.g_w_per_k * h_s * (boundary_c[link.boundary] - t_i);
                l += 1;
            }
        }
        for (s, current) in self.sources.iter().zip(currents_a) {
            let t = temps_c[s.node];
            let r = (s.resistance.r_at_0c_ohm + s.resistance.slope_ohm_per_k * t).max(0.0);
            energy[s.node] += r * current * current * h_s;
        }
        for ((t, e), c) in temps_c
            .iter_mut()
            .zip(energy.iter())
            .zip(&self.capacity_j_per_k)
        {
            *t += *e * (1.0 / c);
        }
    }

    /// Advances `temps_c` by `dt_s` with inputs held, in as many equal
    /// explicit sub-steps as `max_ratio` requires.
    pub fn step(
        &self,
        temps_c: &mut [f64],
        currents_a: &[f64],
        boundary_c: &[f64],
        dt_s: f64,
        max_ratio: f64,
        scratch: &mut Vec<f64>,
    ) {
        let n = self.substeps(dt_s, max_ratio);
        let h = dt_s / n as f64;
        for _ in 0..n {
            self.euler_step(temps_c, currents_a, boundary_c, h, scratch);
        }
    }

    /// `dT/dt` \[K/s\] of every node (the nonlinear right-hand side).
    pub fn derivative_k_per_s(
        &self,
        temps_c: &[f64],
        currents_a: &[f64],
        boundary_c: &[f64],
    ) -> Vec<f64> {
        let mut q = self.fixed_power_w.clone();
        for p in &self.pairs {
            let flow = p.g_w_per_k * (temps_c[p.b] - temps_c[p.a]);
            q[p.a] += flow;
            q[p.b] -= flow;
        }
        for l in &self.links {
            q[l.node] += l.g_w_per_k * (boundary_c[l.boundary] - temps_c[l.node]);
        }
        for (s, i) in self.sources.iter().zip(currents_a) {
            q[s.node] += s.resistance.at_c(temps_c[s.node]) * i * i;
        }
        q.iter()
            .zip(&self.capacity_j_per_k)
            .map(|(q, c)| q / c)
            .collect()
    }
}
