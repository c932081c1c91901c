//! The modal form of a network: real decaying modes, built once in `f64`.
//!
//! A network's conduction matrix is `A = -C^-1 K`, with `C` the diagonal of
//! heat capacities and `K` the symmetric conductance matrix (pairs stored
//! once, so `K_ij = K_ji`: the energy balance of `network`). So `A` is
//! similar to the symmetric matrix
//!
//! ```text
//! S = C^(1/2) A C^(-1/2) = -C^(-1/2) K C^(-1/2) = U diag(lambda) U^T
//! ```
//!
//! with `U` orthogonal and every `lambda_j` real, and
//! `A = V diag(lambda) V^-1` with `V = C^(-1/2) U`, `V^-1 = U^T C^(1/2)`.
//! The condition number of `V` is `sqrt(C_max / C_min)` (67 for the
//! Omnimagnet's air and core nodes), so the form is also safe in `f32`.
//!
//! A winding with `R(T) = r0 + s T` at a constant current adds `s I^2` of
//! *negative* conductance to its node's diagonal (the `steady` module's
//! `K`), which keeps `K` symmetric: the exact model at constant currents is
//! still modal, and a positive `lambda` is thermal runaway.
//!
//! The eigenvalues come from cyclic Jacobi rotations: `O(N^3)` per sweep,
//! quadratic convergence, at most [`MAX_SWEEPS`] sweeps, no allocation.

use crate::error::BuildError;
use crate::network::Network;

/// Most Jacobi sweeps (converged networks need 6 to 10).
pub(crate) const MAX_SWEEPS: usize = 64;

/// `K` of the module docs \[W/K\], with `feedback_w_per_k[i]` (`s I^2` of the
/// windings at node `i`) subtracted from the diagonal.
pub(crate) fn conductance_matrix<const N: usize, const B: usize, const M: usize>(
    network: &Network<N, B, M>,
    feedback_w_per_k: &[f64; N],
) -> [[f64; N]; N] {
    let mut k = [[0.0; N]; N];
    for (i, row) in k.iter_mut().enumerate() {
        for (j, entry) in row.iter_mut().enumerate() {
            *entry = if i == j {
                network.total_conductance_w_per_k(i) - feedback_w_per_k[i]
            } else {
                -network.conductance_w_per_k(i, j)
            };
        }
    }
    k
}

/// The feedback `s I^2` \[W/K\] of every winding at these currents, summed
/// per node.
pub(crate) fn feedback_w_per_k<const N: usize, const B: usize, const M: usize>(
    network: &Network<N, B, M>,
    currents_a: &[f64; M],
) -> [f64; N] {
    let mut feedback = [0.0; N];
    for (m, current) in currents_a.iter().enumerate() {
        // A voltage drive's feedback is negative (its power falls as it
        // heats): left out, which keeps the analysis on the hot side.
        if let Some(source) = network
            .source(m)
            .filter(|s| s.drive == crate::network::Drive::Current)
        {
            if let Some(f) = feedback.get_mut(source.node) {
                *f += source.resistance.slope_ohm_per_k * current * current;
            }
        }
    }
    feedback
}

/// Eigen-decomposition of a symmetric matrix: `a = U diag(values) U^T`,
/// eigenvector `j` in column `j` of `vectors`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SymmetricEigen<const N: usize> {
    pub values: [f64; N],
    pub vectors: [[f64; N]; N],
}

/// Cyclic Jacobi. Errors with `InvalidParameter { name: "network" }` for a
/// non-finite matrix or (never seen in practice) no convergence.
pub(crate) fn symmetric_eigen<const N: usize>(
    mut a: [[f64; N]; N],
) -> Result<SymmetricEigen<N>, BuildError> {
    let bad = BuildError::InvalidParameter { name: "network" };
    if !a.iter().flatten().all(|v| v.is_finite()) {
        return Err(bad);
    }
    let mut u = [[0.0; N]; N];
    for (i, row) in u.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let scale: f64 = a.iter().flatten().map(|v| v * v).sum();
    let mut converged = false;
    for _ in 0..MAX_SWEEPS {
        let mut off = 0.0;
        for p in 0..N {
            for q in (p + 1)..N {
                off += a[p][q] * a[p][q];
            }
        }
        if off <= 1e-30 * scale {
            converged = true;
            break;
        }
        for p in 0..N {
            for q in (p + 1)..N {
                let apq = a[p][q];
                if apq == 0.0 {
                    continue;
                }
                // The rotation that zeroes a[p][q] (Golub & Van Loan 8.5.2),
                // with the smaller angle for stability.
                let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + libm::sqrt(theta * theta + 1.0));
                let c = 1.0 / libm::sqrt(t * t + 1.0);
                let s = t * c;
                for k in 0..N {
                    let akp = a[k][p];
                    let akq = a[k][q];
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..N {
                    let apk = a[p][k];
                    let aqk = a[q][k];
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in u.iter_mut() {
                    let ukp = row[p];
                    let ukq = row[q];
                    row[p] = c * ukp - s * ukq;
                    row[q] = s * ukp + c * ukq;
                }
            }
        }
    }
    if !converged {
        return Err(bad);
    }
    let mut values = [0.0; N];
    for (i, v) in values.iter_mut().enumerate() {
        *v = a[i][i];
    }
    Ok(SymmetricEigen { values, vectors: u })
}

/// `dT/dt = A T + ...` in modes: `A = V diag(lambda) V^-1`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Modal<const N: usize> {
    /// Eigenvalues of `A` \[1/s\]; all negative for a stable network.
    pub lambda_per_s: [f64; N],
    /// `V = C^(-1/2) U`: row `i` holds node `i`'s share of every mode.
    pub v: [[f64; N]; N],
    /// `V^-1 = U^T C^(1/2)`.
    pub v_inv: [[f64; N]; N],
}

impl<const N: usize> Modal<N> {
    /// The modes of `A = -C^-1 (K - diag(feedback))`.
    pub fn new<const B: usize, const M: usize>(
        network: &Network<N, B, M>,
        feedback_w_per_k: &[f64; N],
    ) -> Result<Self, BuildError> {
        let k = conductance_matrix(network, feedback_w_per_k);
        let mut root_c = [0.0; N];
        for (i, r) in root_c.iter_mut().enumerate() {
            // `Network::new` guarantees finite, positive capacities.
            *r = libm::sqrt(network.capacity_j_per_k(i).unwrap_or(1.0));
        }
        let mut s = [[0.0; N]; N];
        for i in 0..N {
            for j in 0..N {
                s[i][j] = -k[i][j] / (root_c[i] * root_c[j]);
            }
        }
        let eigen = symmetric_eigen(s)?;
        let mut v = [[0.0; N]; N];
        let mut v_inv = [[0.0; N]; N];
        for i in 0..N {
            for j in 0..N {
                v[i][j] = eigen.vectors[i][j] / root_c[i];
                v_inv[j][i] = eigen.vectors[i][j] * root_c[i];
            }
        }
        Ok(Self {
            lambda_per_s: eigen.values,
            v,
            v_inv,
        })
    }

    /// `V^-1 x`: modal amplitudes of a node vector.
    pub fn to_modes(&self, x: &[f64; N]) -> [f64; N] {
        let mut z = [0.0; N];
        for (z, row) in z.iter_mut().zip(&self.v_inv) {
            *z = row.iter().zip(x).map(|(a, b)| a * b).sum();
        }
        z
    }

    /// `V diag(w) z`: node values from weighted modal amplitudes.
    pub fn node_values(&self, z: &[f64; N], weights: &[f64; N]) -> [f64; N] {
        let mut x = [0.0; N];
        for (x, row) in x.iter_mut().zip(&self.v) {
            *x = row
                .iter()
                .zip(z)
                .zip(weights)
                .map(|((v, z), w)| v * z * w)
                .sum();
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discretize::expm_with_integral;
    use crate::network::Resistance;

    fn net() -> Network<4, 1, 1> {
        Network::new([68.7, 5.0, 400.0, 0.5])
            .unwrap()
            .connect(0, 1, 0.35)
            .unwrap()
            .connect(1, 2, 0.8)
            .unwrap()
            .connect(3, 1, 0.2)
            .unwrap()
            .connect_boundary(2, 0, 1.5)
            .unwrap()
            .connect_boundary(3, 0, 0.1)
            .unwrap()
            .joule_source(0, 0, Resistance::HPPA_COIL)
            .unwrap()
    }

    #[test]
    fn modes_reproduce_the_matrix_exponential() {
        // exp(A t) from the modes against scaling and squaring (a different
        // code path), with and without R(T) feedback.
        // 0.3 W/K of feedback is beyond this coil's runaway (0.21 W/K).
        for feedback in [[0.0; 4], [0.1, 0.0, 0.0, 0.0], [0.3, 0.0, 0.0, 0.0]] {
            let network = net();
            let modal = Modal::new(&network, &feedback).unwrap();
            let mut a = network.state_space(&[20.0; 4]).a;
            for (i, f) in feedback.iter().enumerate() {
                a[(i, i)] += f / network.capacity_j_per_k(i).unwrap();
            }
            let t = 37.0;
            let (e, _) = expm_with_integral(&a, t).unwrap();
            let decay = modal.lambda_per_s.map(|l| libm::exp(l * t));
            for col in 0..4 {
                let mut unit = [0.0; 4];
                unit[col] = 1.0;
                let x = modal.node_values(&modal.to_modes(&unit), &decay);
                for row in 0..4 {
                    assert!((x[row] - e[(row, col)]).abs() < 1e-12, "{row} {col}");
                }
            }
            // Stable modes exactly when the steady-state solver finds one.
            let current = libm::sqrt(feedback[0] / Resistance::HPPA_COIL.slope_ohm_per_k);
            assert_eq!(
                modal.lambda_per_s.iter().all(|&l| l < 0.0),
                network.steady_state(&[current], &[20.0]).is_ok()
            );
        }
    }

    #[test]
    fn jacobi_refuses_non_finite_input() {
        assert!(symmetric_eigen([[f64::NAN, 0.0], [0.0, 1.0]]).is_err());
        let e = symmetric_eigen([[2.0, 1.0], [1.0, 2.0]]).unwrap();
        let mut values = e.values;
        values.sort_by(f64::total_cmp);
        assert!((values[0] - 1.0).abs() < 1e-14 && (values[1] - 3.0).abs() < 1e-14);
    }
}
