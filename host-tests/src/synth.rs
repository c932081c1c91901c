//! Synthetic traces for tests and examples: a seeded Gaussian noise source
//! and a CSV writer, so generated "recordings" are reproducible bit for bit.

use std::path::Path;

use anyhow::Result;

/// SplitMix64 with Box-Muller normals: small, seeded, reproducible.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
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

    /// The generator after `n` more [`Self::normal`] draws (two 64-bit
    /// draws each), without drawing them.
    pub fn skipping_normals(mut self, n: u64) -> Self {
        self.0 = self
            .0
            .wrapping_add(n.wrapping_mul(2).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        self
    }

    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// A piecewise-constant profile sampled every `dt_s`: `(duration s, value)`
/// segments; returns (time \[s\], value).
pub fn steps(segments: &[(f64, f64)], dt_s: f64) -> (Vec<f64>, Vec<f64>) {
    let mut t = Vec::new();
    let mut v = Vec::new();
    let mut k = 0usize;
    for (duration, value) in segments {
        let n = (duration / dt_s).round() as usize;
        for _ in 0..n {
            t.push(k as f64 * dt_s);
            v.push(*value);
            k += 1;
        }
    }
    (t, v)
}

/// Adds Gaussian noise of standard deviation `sigma` to a copy of `values`.
pub fn noisy(values: &[f64], sigma: f64, rng: &mut Rng) -> Vec<f64> {
    values.iter().map(|v| v + sigma * rng.normal()).collect()
}

/// Writes a CSV with the given columns (all of equal length).
pub fn write_columns(path: &Path, columns: &[(&str, &[f64])]) -> Result<()> {
    let mut w = csv::Writer::from_path(path)?;
    w.write_record(columns.iter().map(|c| c.0))?;
    let rows = columns.first().map_or(0, |c| c.1.len());
    for k in 0..rows {
        w.write_record(columns.iter().map(|c| format!("{}", c.1[k])))?;
    }
    w.flush()?;
    Ok(())
}
