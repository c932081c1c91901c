//! An independent f64 reference for the coil grid.
//!
//! It shares nothing with the grid's stepper but the *description*: the
//! stencil's two 3x3 link matrices and the raw parameter values. From them it
//! assembles the dense ODE
//!
//! ```text
//! C dT/dt = K T + g_base (T_coolant - T) + g_amb (T_ambient - T) + (r0 + s T) I^2
//! ```
//!
//! (`K` the symmetric conduction matrix with `-sum` on the diagonal), and
//! integrates it with classical fourth-order Runge-Kutta over each
//! sample-and-hold interval, at a step of at most `max_h_s`. The fastest mode
//! of the HPPA grid decays at about 0.045 1/s, so with `h = 0.25 s` RK4's
//! error is below 1e-9 K (the tests check by halving the step).

use coil_thermal::grid::{Link, Stencil};

/// The dense f64 model of a `rows x cols` coil grid.
#[derive(Debug, Clone)]
pub struct GridReference {
    n: usize,
    /// Row-major `n x n` conduction matrix \[W/K\].
    k: Vec<f64>,
    g_base_w_per_k: f64,
    g_ambient_w_per_k: Vec<f64>,
    capacity_j_per_k: f64,
    r_at_0c_ohm: f64,
    slope_ohm_per_k: f64,
}

/// The raw numbers the reference is built from (SI, between coils).
#[derive(Debug, Clone, Copy)]
pub struct ReferenceParams {
    /// Between-coils `Rx` \[K/W\].
    pub rx_k_per_w: f64,
    /// Between-coils `Ry` \[K/W\]: a coil to the next row, shared by the
    /// stencil's contacts on that side.
    pub ry_k_per_w: f64,
    /// Coil to base \[K/W\].
    pub rz_k_per_w: f64,
    /// Coil capacity \[J/K\].
    pub capacity_j_per_k: f64,
    /// `R(0 degC)` \[ohm\].
    pub r_at_0c_ohm: f64,
    /// `dR/dT` \[ohm/K\].
    pub slope_ohm_per_k: f64,
    /// Padding at ambient (`true`) or adiabatic border.
    pub ambient_border: bool,
}

impl ReferenceParams {
    /// The library's default set (`GridParams::FDM_FITTED`): the report's
    /// FDM fit, Table 7's resistances between coils, with the capacity of
    /// the report's other fits of the same runs (56.4 J/K; Table 7 prints
    /// 68.7), the HPPA resistance fit and the ambient padding.
    pub const HPPA_FDM: Self = Self {
        rx_k_per_w: 19.8,
        ry_k_per_w: 6.99,
        rz_k_per_w: 5.74,
        capacity_j_per_k: 56.4,
        r_at_0c_ohm: 5.166,
        slope_ohm_per_k: 0.026,
        ambient_border: true,
    };
}

impl GridReference {
    /// Assembles the ODE of a `rows x cols` grid from the stencil matrices.
    ///
    /// Panics if the assembled conduction matrix is not symmetric (the
    /// stencil would not conserve energy).
    pub fn assemble(rows: usize, cols: usize, stencil: &Stencil, p: &ReferenceParams) -> Self {
        let n = rows * cols;
        let mut k = vec![0.0; n * n];
        let mut g_ambient = vec![0.0; n];
        for r in 0..rows {
            let matrix = if r % 2 == 0 {
                &stencil.even
            } else {
                &stencil.odd
            };
            for c in 0..cols {
                let i = r * cols + c;
                for (a, line) in matrix.iter().enumerate() {
                    // A side's 1/Ry is shared by its cross-row contacts.
                    let contacts = line.iter().filter(|l| **l == Link::Y).count().max(1);
                    for (b, link) in line.iter().enumerate() {
                        let g = match link {
                            Link::None => continue,
                            Link::X => 1.0 / p.rx_k_per_w,
                            Link::Y => 1.0 / (p.ry_k_per_w * contacts as f64),
                        };
                        let (rr, cc) = (r as i64 + a as i64 - 1, c as i64 + b as i64 - 1);
                        if rr >= 0 && cc >= 0 && (rr as usize) < rows && (cc as usize) < cols {
                            let j = rr as usize * cols + cc as usize;
                            k[i * n + j] = g;
                        } else if p.ambient_border {
                            g_ambient[i] += g;
                        }
                    }
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                assert_eq!(k[i * n + j], k[j * n + i], "asymmetric link {i} {j}");
            }
            let sum: f64 = (0..n).map(|j| k[i * n + j]).sum();
            k[i * n + i] = -sum;
        }
        Self {
            n,
            k,
            g_base_w_per_k: 1.0 / p.rz_k_per_w,
            g_ambient_w_per_k: g_ambient,
            capacity_j_per_k: p.capacity_j_per_k,
            r_at_0c_ohm: p.r_at_0c_ohm,
            slope_ohm_per_k: p.slope_ohm_per_k,
        }
    }

    /// Number of coils.
    pub fn coils(&self) -> usize {
        self.n
    }

    /// `dT/dt` \[K/s\] into `out`.
    fn derivative(&self, t: &[f64], i2: &[f64], coolant_c: f64, ambient_c: f64, out: &mut [f64]) {
        for i in 0..self.n {
            let row = &self.k[i * self.n..(i + 1) * self.n];
            let conduction: f64 = row.iter().zip(t).map(|(g, t)| g * t).sum();
            let q = conduction
                + self.g_base_w_per_k * (coolant_c - t[i])
                + self.g_ambient_w_per_k[i] * (ambient_c - t[i])
                + (self.r_at_0c_ohm + self.slope_ohm_per_k * t[i]) * i2[i];
            out[i] = q / self.capacity_j_per_k;
        }
    }

    /// Integrates `temps_c` over `duration_s` with constant currents \[A\] and
    /// boundary temperatures \[degC\], RK4 at a step of at most `max_h_s`.
    pub fn integrate(
        &self,
        temps_c: &mut [f64],
        currents_a: &[f64],
        coolant_c: f64,
        ambient_c: f64,
        duration_s: f64,
        max_h_s: f64,
    ) {
        let steps = (duration_s / max_h_s).ceil().max(1.0) as usize;
        let h = duration_s / steps as f64;
        let i2: Vec<f64> = currents_a.iter().map(|i| i * i).collect();
        let n = self.n;
        let (mut k1, mut k2, mut k3, mut k4, mut tmp) = (
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
            vec![0.0; n],
        );
        for _ in 0..steps {
            self.derivative(temps_c, &i2, coolant_c, ambient_c, &mut k1);
            for i in 0..n {
                tmp[i] = temps_c[i] + 0.5 * h * k1[i];
            }
            self.derivative(&tmp, &i2, coolant_c, ambient_c, &mut k2);
            for i in 0..n {
                tmp[i] = temps_c[i] + 0.5 * h * k2[i];
            }
            self.derivative(&tmp, &i2, coolant_c, ambient_c, &mut k3);
            for i in 0..n {
                tmp[i] = temps_c[i] + h * k3[i];
            }
            self.derivative(&tmp, &i2, coolant_c, ambient_c, &mut k4);
            for i in 0..n {
                temps_c[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
}
