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
use crate::network::{Drive, Inputs, NetworkDescription, Nodes};
use crate::sizes::{NodeVector, Sizes};

/// Most Jacobi sweeps (converged networks need 6 to 10).
pub(crate) const MAX_SWEEPS: usize = 64;

/// A square matrix over a network's nodes, by rows.
pub(crate) type NodeMatrix<S> = NodeVector<S, NodeVector<S, f64>>;

/// `K` of the module docs \[W/K\], with `feedback_w_per_k[i]` (`s I^2` of the
/// windings at node `i`) subtracted from the diagonal.
pub(crate) fn conductance_matrix<W: NetworkDescription>(
    network: &W,
    feedback_w_per_k: &Nodes<W, f64>,
) -> NodeMatrix<W::Sizes> {
    let sizes = network.sizes();
    let mut k = sizes.rows_of(sizes.nodes_of(0.0));
    let rows = k.as_mut();
    // Each pair is stored once: its conductance goes both ways.
    for i in 0..rows.len() {
        for (j, g) in network.later_pairs_w_per_k(i) {
            set(rows, i, j, -g);
            set(rows, j, i, -g);
        }
    }
    for (i, (row, f)) in rows.iter_mut().zip(feedback_w_per_k.as_ref()).enumerate() {
        if let Some(diagonal) = row.as_mut().get_mut(i) {
            *diagonal = network.conductance_sum_w_per_k(i) - f;
        }
    }
    k
}

/// `rows[i][j] = value`, if there is such an entry.
fn set<R: AsMut<[f64]>>(rows: &mut [R], i: usize, j: usize, value: f64) {
    if let Some(entry) = rows.get_mut(i).and_then(|r| r.as_mut().get_mut(j)) {
        *entry = value;
    }
}

/// The feedback `s I^2` \[W/K\] of every winding at these currents, summed
/// per node.
pub(crate) fn feedback_w_per_k<W: NetworkDescription>(
    network: &W,
    currents_a: &Inputs<W, f64>,
) -> Nodes<W, f64> {
    let mut feedback = network.sizes().nodes_of(0.0);
    for (m, current) in currents_a.as_ref().iter().enumerate() {
        // A voltage drive's feedback is negative (its power falls as it
        // heats): left out, which keeps the analysis on the hot side.
        if let Some(source) = network
            .joule_source_of(m)
            .filter(|s| s.drive == Drive::Current)
        {
            if let Some(f) = feedback.as_mut().get_mut(source.node) {
                *f += source.resistance.slope_ohm_per_k * current * current;
            }
        }
    }
    feedback
}

/// Eigen-decomposition of a symmetric matrix: `a = U diag(values) U^T`,
/// eigenvector `j` in column `j` of `vectors`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SymmetricEigen<S: Sizes> {
    pub values: NodeVector<S, f64>,
    pub vectors: NodeMatrix<S>,
}

/// Cyclic Jacobi. Errors with `InvalidParameter { name: "network" }` for a
/// non-finite matrix or (never seen in practice) no convergence. Build-time
/// code: it indexes its square matrix, whose every row is `N` long.
pub(crate) fn symmetric_eigen<S: Sizes>(
    sizes: S,
    mut matrix: NodeMatrix<S>,
) -> Result<SymmetricEigen<S>, BuildError> {
    let bad = BuildError::InvalidParameter { name: "network" };
    let n = sizes.nodes();
    let a = matrix.as_mut();
    let finite = a
        .iter()
        .all(|row| row.as_ref().iter().all(|v| v.is_finite()));
    if !finite || a.iter().any(|row| row.as_ref().len() != n) {
        return Err(bad);
    }
    let mut vectors = sizes.rows_of(sizes.nodes_of(0.0));
    let u = vectors.as_mut();
    for (i, row) in u.iter_mut().enumerate() {
        row.as_mut()[i] = 1.0;
    }
    let scale: f64 = a.iter().flat_map(|row| row.as_ref()).map(|v| v * v).sum();
    let mut converged = false;
    for _ in 0..MAX_SWEEPS {
        let mut off = 0.0;
        for p in 0..n {
            for q in (p + 1)..n {
                let apq = a[p].as_ref()[q];
                off += apq * apq;
            }
        }
        if off <= 1e-30 * scale {
            converged = true;
            break;
        }
        for p in 0..n {
            for q in (p + 1)..n {
                let apq = a[p].as_ref()[q];
                if apq == 0.0 {
                    continue;
                }
                // The rotation that zeroes a[p][q] (Golub & Van Loan 8.5.2),
                // with the smaller angle for stability.
                let theta = (a[q].as_ref()[q] - a[p].as_ref()[p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + libm::sqrt(theta * theta + 1.0));
                let c = 1.0 / libm::sqrt(t * t + 1.0);
                let s = t * c;
                for row in a.iter_mut() {
                    rotate(row.as_mut(), p, q, c, s);
                }
                for k in 0..n {
                    let apk = a[p].as_ref()[k];
                    let aqk = a[q].as_ref()[k];
                    a[p].as_mut()[k] = c * apk - s * aqk;
                    a[q].as_mut()[k] = s * apk + c * aqk;
                }
                for row in u.iter_mut() {
                    rotate(row.as_mut(), p, q, c, s);
                }
            }
        }
    }
    if !converged {
        return Err(bad);
    }
    let mut values = sizes.nodes_of(0.0);
    for (i, v) in values.as_mut().iter_mut().enumerate() {
        *v = a[i].as_ref()[i];
    }
    Ok(SymmetricEigen { values, vectors })
}

/// Columns `p` and `q` of one row through the rotation `(c, s)`.
fn rotate(row: &mut [f64], p: usize, q: usize, c: f64, s: f64) {
    let (xp, xq) = (row[p], row[q]);
    row[p] = c * xp - s * xq;
    row[q] = s * xp + c * xq;
}

/// `dT/dt = A T + ...` in modes: `A = V diag(lambda) V^-1`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Modal<S: Sizes> {
    /// Eigenvalues of `A` \[1/s\]; all negative for a stable network.
    pub lambda_per_s: NodeVector<S, f64>,
    /// `V = C^(-1/2) U`: row `i` holds node `i`'s share of every mode.
    pub v: NodeMatrix<S>,
    /// `V^-1 = U^T C^(1/2)`.
    pub v_inv: NodeMatrix<S>,
}

impl<S: Sizes> Modal<S> {
    /// The modes of `A = -C^-1 (K - diag(feedback))`.
    pub fn new<W: NetworkDescription<Sizes = S>>(
        network: &W,
        feedback_w_per_k: &NodeVector<S, f64>,
    ) -> Result<Self, BuildError> {
        let sizes = network.sizes();
        let n = sizes.nodes();
        let k = conductance_matrix(network, feedback_w_per_k);
        let mut root_c = sizes.nodes_of(0.0);
        for (i, r) in root_c.as_mut().iter_mut().enumerate() {
            // A network's capacities are finite and positive.
            *r = libm::sqrt(network.capacity_at_j_per_k(i));
        }
        let root_c = root_c.as_ref();
        let mut s = sizes.rows_of(sizes.nodes_of(0.0));
        for (i, (row, k_row)) in s.as_mut().iter_mut().zip(k.as_ref()).enumerate() {
            for (j, (entry, k_ij)) in row.as_mut().iter_mut().zip(k_row.as_ref()).enumerate() {
                *entry = -k_ij / (root_c[i] * root_c[j]);
            }
        }
        let eigen = symmetric_eigen(sizes, s)?;
        let mut v = sizes.rows_of(sizes.nodes_of(0.0));
        let mut v_inv = sizes.rows_of(sizes.nodes_of(0.0));
        let (rows, inv_rows) = (v.as_mut(), v_inv.as_mut());
        for (i, u_row) in eigen.vectors.as_ref().iter().enumerate() {
            for j in 0..n {
                let u = u_row.as_ref()[j];
                rows[i].as_mut()[j] = u / root_c[i];
                inv_rows[j].as_mut()[i] = u * root_c[i];
            }
        }
        Ok(Self {
            lambda_per_s: eigen.values,
            v,
            v_inv,
        })
    }

    /// `V^-1 x`: modal amplitudes of a node vector.
    pub fn to_modes(&self, x: &NodeVector<S, f64>) -> NodeVector<S, f64> {
        let mut z = x.clone();
        for (z, row) in z.as_mut().iter_mut().zip(self.v_inv.as_ref()) {
            *z = row
                .as_ref()
                .iter()
                .zip(x.as_ref())
                .map(|(a, b)| a * b)
                .sum();
        }
        z
    }

    /// `V diag(w) z`: node values from weighted modal amplitudes.
    pub fn node_values(
        &self,
        z: &NodeVector<S, f64>,
        weights: &NodeVector<S, f64>,
    ) -> NodeVector<S, f64> {
        let mut x = z.clone();
        for (x, row) in x.as_mut().iter_mut().zip(self.v.as_ref()) {
            *x = row
                .as_ref()
                .iter()
                .zip(z.as_ref())
                .zip(weights.as_ref())
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
    use crate::network::{Network, Resistance};
    use crate::sizes::ConstSizes;

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
        let two = ConstSizes::<2, 0, 0>;
        assert!(symmetric_eigen(two, [[f64::NAN, 0.0], [0.0, 1.0]]).is_err());
        let e = symmetric_eigen(two, [[2.0, 1.0], [1.0, 2.0]]).unwrap();
        let mut values = e.values;
        values.sort_by(f64::total_cmp);
        assert!((values[0] - 1.0).abs() < 1e-14 && (values[1] - 3.0).abs() < 1e-14);
    }
}
