//! Observability of (`F`, `H`) from a subset of sensors: rank and, per state,
//! whether the state is determined by the readings.
//!
//! # Method
//! The observable subspace is the smallest `F^T`-invariant subspace that
//! contains the selected rows `h_j^T` of `H` (the row space of the
//! observability matrix `[H; H F; ...; H F^(N-1)]`). Instead of forming that
//! `N P x N` matrix, whose rows grow or shrink like `|lambda|^i` and lose rank
//! numerically, an orthonormal basis of the subspace is built by a block
//! Arnoldi process: start from the `h_j`, and for each basis vector `q` add
//! the part of `F_c^T q` orthogonal to the basis (Gram-Schmidt twice), if it
//! is larger than `tol * ||F_c||_F`. `F_c = F - (tr F / N) I` is `F` shifted by
//! its mean eigenvalue: a shift leaves every Krylov subspace unchanged, and
//! for `F = e^{A dt}` with a small step it removes the dominant identity part
//! so the dynamics are not lost to rounding. At most `N + P` candidates are
//! examined, so the work is O(N^2 (N + P)) and bounded.
//!
//! State `i` is observable iff the unit vector `e_i` lies in the observable
//! subspace, i.e. its component in the unobservable subspace (the orthogonal
//! complement) vanishes: `1 - sum_k Q_ik^2 <= tol` for the basis `Q`.
//!
//! Stack: two N x N matrices plus a few vectors (4.3 KiB for N = 16 in f64).

use nalgebra::{RealField, SMatrix, SVector};

/// Observability of one sensor subset.
///
/// Holds `T` arrays only, but is generic over `T`, which need not implement
/// `defmt::Format`; it is a build-time result, so it has no defmt derive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observability<T, const N: usize> {
    /// Dimension of the observable subspace (rank of the observability
    /// matrix); `N` means fully observable.
    pub rank: usize,
    /// Per state: determined by the selected sensors' readings over time.
    pub observable: [bool; N],
    /// Per state: squared norm of `e_i`'s component in the unobservable
    /// subspace, in \[0, 1\]: 0 fully observable, 1 invisible to the sensors.
    pub unobservable_share: [T; N],
}

impl<T, const N: usize> Observability<T, N> {
    /// True when every state is observable.
    pub fn is_full(&self) -> bool {
        self.rank == N
    }
}

/// Rank and per-state observability of (`f`, rows of `h` with `sensors[j]`).
///
/// `tol` is relative (e.g. `1e-9` in f64, `1e-4` in f32): a new direction
/// counts if its size exceeds `tol * ||F_c||_F` (or `tol * ||h_j||` for a
/// sensor row), and a state is observable if its unobservable share is at
/// most `tol`. Non-finite input gives rank 0 and nothing observable.
pub fn observability<T: RealField + Copy, const N: usize, const P: usize>(
    f: &SMatrix<T, N, N>,
    h: &SMatrix<T, P, N>,
    sensors: &[bool; P],
    tol: T,
) -> Observability<T, N> {
    let mut basis = SMatrix::<T, N, N>::zeros();
    let mut rank = 0usize;
    let finite = f.iter().chain(h.iter()).all(|v| v.is_finite()) && tol.is_finite();
    if finite {
        let n: T = nalgebra::convert(N as f64);
        let shift = f.trace() / n;
        let fct = (f - SMatrix::<T, N, N>::identity() * shift).transpose();
        let f_scale = fct.norm();

        for (j, _) in sensors.iter().enumerate().filter(|(_, on)| **on) {
            let w: SVector<T, N> = h.row(j).transpose();
            let scale = w.norm();
            try_extend(&mut basis, &mut rank, w, tol * scale);
        }
        // Each basis vector is expanded once; the basis has at most N vectors,
        // so the loop runs at most N times.
        let mut next = 0usize;
        while next < rank && rank < N {
            let w = fct * basis.column(next);
            try_extend(&mut basis, &mut rank, w, tol * f_scale);
            next += 1;
        }
    }

    let mut observable = [false; N];
    let mut unobservable_share = [T::one(); N];
    for (i, (obs, share)) in observable
        .iter_mut()
        .zip(unobservable_share.iter_mut())
        .enumerate()
    {
        let inside = basis
            .row(i)
            .iter()
            .take(rank)
            .fold(T::zero(), |a, v| a + *v * *v);
        *share = (T::one() - inside).max(T::zero()).min(T::one());
        *obs = finite && *share <= tol;
    }
    Observability {
        rank,
        observable,
        unobservable_share,
    }
}

/// Adds the part of `w` orthogonal to the first `rank` basis columns if it is
/// larger than `threshold`.
fn try_extend<T: RealField + Copy, const N: usize>(
    basis: &mut SMatrix<T, N, N>,
    rank: &mut usize,
    mut w: SVector<T, N>,
    threshold: T,
) {
    if *rank >= N {
        return;
    }
    // Classical Gram-Schmidt twice is as orthogonal as modified GS and simpler
    // ("twice is enough", Giraud et al. 2005).
    for _ in 0..2 {
        for q in basis.column_iter().take(*rank) {
            let c = q.dot(&w);
            w.axpy(-c, &q, T::one());
        }
    }
    let norm = w.norm();
    if norm > threshold && norm > T::zero() {
        basis.set_column(*rank, &(w / norm));
        *rank += 1;
    }
}
