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

use super::{Drive, Network};
use crate::error::BuildError;

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
        if !currents_a.iter().chain(boundary_c).all(|v| v.is_finite()) {
            return Err(BuildError::InvalidParameter {
                name: "currents_a/boundary_c",
            });
        }
        // Voltage-driven sources are linearised at the warmest boundary
        // first (or 0 degC without one), then at each iterate.
        let start = boundary_c.iter().copied().fold(0.0f64, f64::max);
        let mut at = [start; N];
        let voltage = self
            .sources
            .iter()
            .flatten()
            .any(|s| s.drive == Drive::Voltage);
        for _ in 0..MAX_NEWTON {
            let (k, q) = self.steady_system(currents_a, boundary_c, true, &at);
            let t = match solve_m_matrix(k, q) {
                Ok(t) => t,
                Err(()) => {
                    // Tell runaway apart from a node with no way out.
                    let (k0, q0) = self.steady_system(currents_a, boundary_c, false, &at);
                    return match solve_m_matrix(k0, q0) {
                        Ok(_) => Err(BuildError::NoSteadyState),
                        Err(()) => Err(BuildError::Singular),
                    };
                }
            };
            let moved = t
                .iter()
                .zip(&at)
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

    /// `K` and `q` of the module docs; `with_feedback = false` drops the
    /// `s I^2` terms (constant resistance at 0 degC, used to classify failure).
    /// Voltage-driven sources are linearised at `at` \[degC\].
    fn steady_system(
        &self,
        currents_a: &[f64; M],
        boundary_c: &[f64; B],
        with_feedback: bool,
        at: &[f64; N],
    ) -> ([[f64; N]; N], [f64; N]) {
        let mut k = [[0.0; N]; N];
        let mut q = self.fixed_power_w;
        for i in 0..N {
            for j in 0..N {
                if j != i {
                    let g = self.conductance_w_per_k(i, j);
                    k[i][j] = -g;
                    k[i][i] += g;
                }
            }
            for (g, tb) in self.boundary_w_per_k[i].iter().zip(boundary_c) {
                k[i][i] += g;
                q[i] += g * tb;
            }
        }
        for (source, current) in self.sources.iter().zip(currents_a) {
            if let Some(s) = source.filter(|s| s.drive == Drive::Voltage) {
                // P(T) ~ P(T_k) + P'(T_k) (T - T_k), P' = -s u / R^2.
                let u = current * current;
                let r = s.resistance.at_c(at[s.node]);
                if r > 0.0 {
                    let p = u / r;
                    let dp = -s.resistance.slope_ohm_per_k * u / (r * r);
                    q[s.node] += p - dp * at[s.node];
                    k[s.node][s.node] -= dp;
                }
            } else if let Some(s) = source {
                let i2 = current * current;
                q[s.node] += s.resistance.r_at_0c_ohm * i2;
                if with_feedback {
                    k[s.node][s.node] -= s.resistance.slope_ohm_per_k * i2;
                }
            }
        }
        (k, q)
    }
}

/// Solves `K x = q` for a Z-matrix `K` by elimination without pivoting;
/// `Err(())` when a pivot is not positive (K is not a non-singular M-matrix).
pub(crate) fn solve_m_matrix<const N: usize>(
    mut k: [[f64; N]; N],
    mut q: [f64; N],
) -> Result<[f64; N], ()> {
    let scale = k
        .iter()
        .enumerate()
        .map(|(i, row)| row[i].abs())
        .fold(0.0, f64::max);
    for p in 0..N {
        let pivot = k[p][p];
        if pivot.partial_cmp(&(PIVOT_EPSILON * scale)) != Some(core::cmp::Ordering::Greater) {
            return Err(());
        }
        for r in (p + 1)..N {
            let factor = k[r][p] / pivot;
            if factor != 0.0 {
                for c in p..N {
                    k[r][c] -= factor * k[p][c];
                }
                q[r] -= factor * q[p];
            }
        }
    }
    let mut x = [0.0; N];
    for r in (0..N).rev() {
        let mut acc = q[r];
        for c in (r + 1)..N {
            acc -= k[r][c] * x[c];
        }
        x[r] = acc / k[r][r];
    }
    Ok(x)
}
