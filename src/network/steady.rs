//! The exact steady state of a network, with the rise of `R(T)` included.
//!
//! Joule power `(r0 + s T) I^2` is affine in the winding temperature, so the
//! steady state solves one *linear* system `K T = q`:
//!
//! ```text
//! K_ii = sum_j G_ij + sum_b G_ib - sum_{m at i} s_m I_m^2,   K_ij = -G_ij
//! q_i  = sum_b G_ib T_b + sum_{m at i} r0_m I_m^2 + P_i
//! ```
//!
//! `K` has non-positive off-diagonal entries (a Z-matrix). A stable steady
//! state exists exactly when `K` is a non-singular M-matrix, which Gaussian
//! elimination *without pivoting* detects: every pivot is positive. When the
//! `R(T)` feedback `s I^2` makes a pivot non-positive, the coil runs away (the
//! "quasi thermal runaway" of solenoid-layers-runaway.md) and the solve
//! returns [`BuildError::NoSteadyState`].
//!
//! A voltage-driven source's power `V_eff^2 / R(T)` is not affine in `T`:
//! it is linearised at the previous iterate (Newton's method,
//! `P(T) ~ P(T_k) + P'(T_k) (T - T_k)` with `P' = -s V_eff^2 / R^2 <= 0`,
//! which only adds to the diagonal of `K`) and the linear solve repeated
//! until the temperatures move by less than 1e-9 K (at most 100 solves).
//! `1/R(T)` is convex and falling, so the iterates approach the one steady
//! state from one side; the falling power never makes a pivot smaller, so
//! a voltage drive never runs away.
//!
//! Build-time code: `O(N^3)` work and `N^2` `f64` on the stack (56 KiB for
//! N = 84), meant for the host or for small networks on target.

use super::description::{Boundaries, Inputs, Nodes};
use super::{Drive, Network, NetworkDescription};
use crate::error::BuildError;
use crate::sizes::{NodeVector, Sizes};

/// Newton iterations at most for voltage-driven sources.
const MAX_NEWTON: usize = 100;
/// Largest move \[K\] of the last Newton iterate.
const NEWTON_TOLERANCE_K: f64 = 1e-9;

/// Relative size under which a pivot counts as zero.
const PIVOT_EPSILON: f64 = 1e-12;

impl<const N: usize, const B: usize, const M: usize> Network<N, B, M> {
    /// The steady-state temperatures \[degC\] at constant currents \[A\] and
    /// boundary temperatures \[degC\], with `R(T)` rising as the coils heat.
    ///
    /// Errors: [`BuildError::NoSteadyState`] when the currents drive thermal
    /// runaway, [`BuildError::Singular`] when some node has no path to a
    /// boundary, [`BuildError::InvalidParameter`] for non-finite inputs.
    pub fn steady_state(
        &self,
        currents_a: &[f64; M],
        boundary_c: &[f64; B],
    ) -> Result<[f64; N], BuildError> {
        steady_state_of(self, currents_a, boundary_c)
    }
}

/// [`Network::steady_state`] of any network description (a model file's
/// network on a host, at its own size). Build-time code: `O(N^3)` work,
/// `N^2` numbers.
///
/// # Errors
/// As [`Network::steady_state`]; [`BuildError::InvalidParameter`] too for
/// currents or boundaries of another length than the network's.
pub fn steady_state_of<W: NetworkDescription>(
    network: &W,
    currents_a: &Inputs<W, f64>,
    boundary_c: &Boundaries<W, f64>,
) -> Result<Nodes<W, f64>, BuildError> {
    let sizes = network.sizes();
    let (currents, boundary) = (currents_a.as_ref(), boundary_c.as_ref());
    let finite = currents.iter().chain(boundary).all(|v| v.is_finite());
    if !finite || currents.len() != sizes.inputs() || boundary.len() != sizes.boundaries() {
        return Err(BuildError::InvalidParameter {
            name: "currents_a/boundary_c",
        });
    }
    // Voltage-driven sources are linearised at the warmest boundary
    // first (or 0 degC without one), then at each iterate.
    let start = boundary.iter().copied().fold(0.0f64, f64::max);
    let mut at = sizes.nodes_of(start);
    let voltage = (0..sizes.inputs())
        .filter_map(|m| network.joule_source_of(m))
        .any(|s| s.drive == Drive::Voltage);
    for _ in 0..MAX_NEWTON {
        let (k, q) = steady_system(sizes, network, currents, boundary, true, at.as_ref());
        let t = match solve_m_matrix(k, q) {
            Ok(t) => t,
            Err(()) => {
                // Tell runaway apart from a node with no way out.
                let (k0, q0) =
                    steady_system(sizes, network, currents, boundary, false, at.as_ref());
                return match solve_m_matrix(k0, q0) {
                    Ok(_) => Err(BuildError::NoSteadyState),
                    Err(()) => Err(BuildError::Singular),
                };
            }
        };
        let moved = t
            .as_ref()
            .iter()
            .zip(at.as_ref())
            .fold(0.0f64, |acc, (a, b)| acc.max((a - b).abs()));
        if !voltage || moved < NEWTON_TOLERANCE_K {
            return Ok(t);
        }
        at = t;
    }
    Err(BuildError::NotConverged {
        name: "steady_state",
    })
}

/// The steady states of a network as one current-driven winding's current
/// `I` varies, the others held: `K` changes by a rank-one term at the
/// winding's node `n` and `q` by one entry (see the module docs), so with
/// `w = K_0^-1 q_0` (the steady state at `I = 0`) and `u = K_0^-1 e_n`
///
/// ```text
/// T_n(I) = (w_n + I^2 r0 u_n) / (1 - s I^2 u_n)
/// T(I)   = w + I^2 (r0 + s T_n(I)) u
/// ```
///
/// (a steady state while the denominator is positive): two solves, then
/// `O(N)` a current where [`steady_state_of`] takes `O(N^3)`. For a search
/// over one winding's current (the hot-spot current of
/// [`crate::protect::runaway`]); not for a network with a voltage-driven
/// source, whose steady state is no linear solve.
pub(crate) struct OneWindingSteady<V> {
    /// `K_0^-1 q_0`: the steady state at zero current \[degC\].
    at_zero_c: V,
    /// `K_0^-1 e_n`: each node's rise per watt at the winding's node
    /// \[K/W\].
    per_watt_k_per_w: V,
    node: usize,
    r0_ohm: f64,
    slope_ohm_per_k: f64,
}

impl<V: AsRef<[f64]>> OneWindingSteady<V> {
    /// The current \[A\] above which no steady state exists (the
    /// denominator's zero, `I^2 = 1 / (s u_n)`, `u_n` the node's
    /// resistance to the boundaries, see [`crate::protect::runaway`]);
    /// `None` for a resistance that does not rise with temperature.
    pub(crate) fn runaway_current_a(&self) -> Option<f64> {
        let u_n = self.per_watt_k_per_w.as_ref().get(self.node).copied()?;
        (self.slope_ohm_per_k > 0.0 && u_n > 0.0)
            .then(|| libm::sqrt(1.0 / (self.slope_ohm_per_k * u_n)))
    }

    /// Whether the steady state at `current_a` \[A\] exists and keeps
    /// every node at or below its limit `limits_c` \[degC\].
    pub(crate) fn within(&self, current_a: f64, limits_c: &[f64]) -> bool {
        let (w, u) = (self.at_zero_c.as_ref(), self.per_watt_k_per_w.as_ref());
        let (Some(w_n), Some(u_n)) = (w.get(self.node), u.get(self.node)) else {
            return false;
        };
        let u2 = current_a * current_a;
        let denominator = 1.0 - self.slope_ohm_per_k * u2 * u_n;
        if denominator.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            // Runaway (or NaN): no steady state.
            return false;
        }
        let t_n = (w_n + u2 * self.r0_ohm * u_n) / denominator;
        let power_w = u2 * (self.r0_ohm + self.slope_ohm_per_k * t_n);
        w.iter()
            .zip(u)
            .zip(limits_c)
            .all(|((w, u), limit)| w + power_w * u <= *limit)
    }
}

/// [`OneWindingSteady`] of input `coil` with the other inputs at
/// `currents_a` \[A\] (its own entry ignored) and the boundaries at
/// `boundary_c` \[degC\]; `Ok(None)` where it does not apply (no such
/// current-driven winding, or a voltage-driven source in the network).
///
/// # Errors
/// As [`steady_state_of`] at zero current of `coil`.
pub(crate) fn one_winding_steady<W: NetworkDescription>(
    network: &W,
    coil: usize,
    currents_a: &Inputs<W, f64>,
    boundary_c: &Boundaries<W, f64>,
) -> Result<Option<OneWindingSteady<Nodes<W, f64>>>, BuildError> {
    let sizes = network.sizes();
    let voltage = (0..sizes.inputs())
        .filter_map(|m| network.joule_source_of(m))
        .any(|s| s.drive == Drive::Voltage);
    let Some(source) = network.joule_source_of(coil) else {
        return Ok(None);
    };
    if voltage || source.drive != Drive::Current {
        return Ok(None);
    }
    let mut currents = currents_a.clone();
    if let Some(i) = currents.as_mut().get_mut(coil) {
        *i = 0.0;
    }
    // Validates the inputs and tells runaway from a node without a way out.
    let at_zero_c = steady_state_of(network, &currents, boundary_c)?;
    let (k, _) = steady_system(
        sizes,
        network,
        currents.as_ref(),
        boundary_c.as_ref(),
        true,
        at_zero_c.as_ref(),
    );
    let mut unit = sizes.nodes_of(0.0);
    if let Some(e) = unit.as_mut().get_mut(source.node) {
        *e = 1.0;
    }
    let per_watt_k_per_w = solve_m_matrix(k, unit).map_err(|()| BuildError::Singular)?;
    Ok(Some(OneWindingSteady {
        at_zero_c,
        per_watt_k_per_w,
        node: source.node,
        r0_ohm: source.resistance.r_at_0c_ohm,
        slope_ohm_per_k: source.resistance.slope_ohm_per_k,
    }))
}

/// `K` and `q` of the module docs; with `with_feedback` false, without
/// the `R(T)` feedback on the diagonal; voltage-driven sources
/// linearised at `at` \[degC\].
fn steady_system<S: Sizes>(
    sizes: S,
    network: &impl NetworkDescription,
    currents_a: &[f64],
    boundary_c: &[f64],
    with_feedback: bool,
    at: &[f64],
) -> (NodeVector<S, NodeVector<S, f64>>, NodeVector<S, f64>) {
    let n = sizes.nodes();
    let mut k = sizes.rows_of(sizes.nodes_of(0.0));
    let mut q = sizes.nodes_of(0.0);
    let rows = k.as_mut();
    let q_rows = q.as_mut();
    // Each pair is stored once: its conductance goes both ways.
    for i in 0..n {
        for (j, g) in network.later_pairs_w_per_k(i) {
            rows[i].as_mut()[j] = -g;
            rows[j].as_mut()[i] = -g;
        }
    }
    for i in 0..n {
        let row = rows[i].as_mut();
        for j in 0..n {
            if j != i {
                row[i] -= row[j];
            }
        }
        q_rows[i] = network.fixed_power_at_w(i);
        for (b, tb) in boundary_c.iter().enumerate() {
            let g = network.boundary_link_w_per_k(i, b);
            row[i] += g;
            q_rows[i] += g * tb;
        }
    }
    for (m, current) in currents_a.iter().enumerate() {
        let Some(s) = network.joule_source_of(m) else {
            continue;
        };
        let (node, u) = (s.node, current * current);
        if s.drive == Drive::Voltage {
            // P(T) ~ P(T_k) + P'(T_k) (T - T_k), P' = -s u / R^2.
            let r = s.resistance.at_c(at[node]);
            if r > 0.0 {
                let p = u / r;
                let dp = -s.resistance.slope_ohm_per_k * u / (r * r);
                q_rows[node] += p - dp * at[node];
                rows[node].as_mut()[node] -= dp;
            }
        } else {
            q_rows[node] += s.resistance.r_at_0c_ohm * u;
            if with_feedback {
                rows[node].as_mut()[node] -= s.resistance.slope_ohm_per_k * u;
            }
        }
    }
    (k, q)
}

/// Gaussian elimination without pivoting of `k x = q`; `Err` at a pivot
/// that is not positive (`k` is then no non-singular M-matrix).
pub(crate) fn solve_m_matrix<V: AsRef<[f64]> + AsMut<[f64]> + Clone>(
    mut k: impl AsMut<[V]>,
    mut q: V,
) -> Result<V, ()> {
    let k = k.as_mut();
    let n = k.len();
    let scale = k
        .iter()
        .enumerate()
        .map(|(i, row)| row.as_ref()[i].abs())
        .fold(0.0, f64::max);
    for p in 0..n {
        let pivot = k[p].as_ref()[p];
        if pivot.partial_cmp(&(PIVOT_EPSILON * scale)) != Some(core::cmp::Ordering::Greater) {
            return Err(());
        }
        let (above, below) = k.split_at_mut(p + 1);
        let pivot_row = above[p].as_ref();
        for (r, row) in below.iter_mut().enumerate() {
            let row = row.as_mut();
            let factor = row[p] / pivot;
            if factor != 0.0 {
                for c in p..n {
                    row[c] -= factor * pivot_row[c];
                }
                let qp = q.as_ref()[p];
                q.as_mut()[p + 1 + r] -= factor * qp;
            }
        }
    }
    let mut x = q.clone();
    let xs = x.as_mut();
    for r in (0..n).rev() {
        let mut acc = q.as_ref()[r];
        for c in (r + 1)..n {
            acc -= k[r].as_ref()[c] * xs[c];
        }
        xs[r] = acc / k[r].as_ref()[r];
    }
    Ok(x)
}
