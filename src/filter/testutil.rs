//! Deterministic random numbers and random systems for the filter tests.

use nalgebra::{SMatrix, SVector};

/// SplitMix64: tiny, seeded, good enough for test noise.
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1).
    pub fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal by Box-Muller.
    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (core::f64::consts::TAU * u2).cos()
    }

    pub fn matrix<const R: usize, const C: usize>(&mut self) -> SMatrix<f64, R, C> {
        SMatrix::from_fn(|_, _| self.gauss())
    }
}

/// A random stable `F` (spectral radius <= `radius` via the infinity norm), a
/// random `Q = L L^T * q_scale`, random `H`, `r` in [0.05, 1].
pub struct RandomSystem<const N: usize, const P: usize> {
    pub f: SMatrix<f64, N, N>,
    pub q: SMatrix<f64, N, N>,
    pub h: SMatrix<f64, P, N>,
    pub r: SVector<f64, P>,
}

impl<const N: usize, const P: usize> RandomSystem<N, P> {
    pub fn new(rng: &mut Rng, radius: f64, q_scale: f64) -> Self {
        let f: SMatrix<f64, N, N> = rng.matrix();
        let norm_inf = f
            .row_iter()
            .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let f = f * (radius / norm_inf);
        let l: SMatrix<f64, N, N> = rng.matrix();
        let q = (l * l.transpose() * q_scale).symmetric_part();
        let h = rng.matrix();
        let r = SVector::from_fn(|_, _| 0.05 + 0.95 * rng.uniform());
        Self { f, q, h, r }
    }

    /// A sample of `N(0, cov)` via Cholesky (cov must be positive definite).
    pub fn sample(rng: &mut Rng, cov: &SMatrix<f64, N, N>) -> SVector<f64, N> {
        let l = nalgebra::Cholesky::new(*cov)
            .expect("positive definite")
            .l();
        let e: SVector<f64, N> = rng.matrix();
        l * e
    }
}

/// Symmetric and positive semi-definite to `tol * trace`.
pub fn is_sym_psd<const N: usize>(p: &SMatrix<f64, N, N>, tol: f64) -> bool {
    let sym = (p - p.transpose()).abs().max() <= 1e-12 * p.abs().max().max(1.0);
    let scale = p.trace().abs().max(1e-300);
    // Cholesky of p + d I succeeds iff the smallest eigenvalue exceeds -d.
    let ridged = p.symmetric_part() + SMatrix::<f64, N, N>::identity() * (tol * scale);
    sym && nalgebra::Cholesky::new(ridged).is_some()
}

/// A 16-node thermal chain like the Omnimagnet's (explicit step, 1 ms):
/// heat capacities 50..400 J/K, neighbour conductances 0.05..2 W/K, losses to
/// ambient at a few nodes; six thermocouples, two each on nodes 0, 1, 2.
pub fn thermal_chain_16() -> (SMatrix<f64, 16, 16>, SMatrix<f64, 6, 16>) {
    let dt = 1e-3;
    let c = SVector::<f64, 16>::from_fn(|i, _| 50.0 + 25.0 * ((i * 7) % 15) as f64);
    let mut a = SMatrix::<f64, 16, 16>::zeros();
    for i in 0..15 {
        let g = 0.05 + 0.13 * ((i * 5) % 15) as f64;
        a[(i, i + 1)] += g / c[i];
        a[(i + 1, i)] += g / c[i + 1];
        a[(i, i)] -= g / c[i];
        a[(i + 1, i + 1)] -= g / c[i + 1];
    }
    for i in [2usize, 5, 6, 8, 10, 12, 15] {
        a[(i, i)] -= 0.1 / c[i];
    }
    let f = SMatrix::<f64, 16, 16>::identity() + a * dt;
    let mut h = SMatrix::<f64, 6, 16>::zeros();
    for j in 0..6 {
        h[(j, j / 2)] = 1.0;
    }
    (f, h)
}
