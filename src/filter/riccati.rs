//! Steady-state filter: the k-step model, the discrete algebraic Riccati
//! equation (solved by structure-preserving doubling) and the constant-gain
//! correction with its missing-sensor fallback.

use nalgebra::{Cholesky, RealField, SMatrix, SVector};

use super::gate::{gate_all, judge, usable, GateCounters, SensorVerdict, UpdateReport};
use super::kalman::{add_diagonal, fuse_accepted, fuse_scalar, max_abs, KalmanConfig};
use crate::error::BuildError;

/// Upper bound on doubling steps: step `i` covers `2^i` correction periods,
/// so 64 steps exceed any horizon a filter meets.
const MAX_DOUBLINGS: usize = 64;

/// The steady-state solution for corrections every `period` predict steps.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyStateGain<T: RealField + Copy, const N: usize, const P: usize> {
    period: u32,
    gain: SMatrix<T, N, P>,
    prior: SMatrix<T, N, N>,
    posterior: SMatrix<T, N, N>,
    innovation_var: SVector<T, P>,
}

/// Per-device state of the steady-state filter: the estimate and the gate
/// memory (no covariance: it is constant and lives in [`SteadyStateGain`]).
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SteadyEstimate<T: RealField + Copy, const N: usize, const P: usize> {
    /// State estimate `x`.
    pub x: SVector<T, N>,
    /// Rejection counters.
    pub gate: GateCounters<P>,
}

impl<T: RealField + Copy, const N: usize, const P: usize> SteadyEstimate<T, N, P> {
    /// An estimate starting at `x0`.
    pub fn new(x0: SVector<T, N>) -> Self {
        Self {
            x: x0,
            gate: GateCounters::new(),
        }
    }
}

/// `(F^k, sum_{i<k} F^i Q F^iT)`: the transition and process noise of `k`
/// predict steps, by binary powering (at most 2 log2(k) compositions).
pub fn k_step_model<T: RealField + Copy, const N: usize>(
    f: &SMatrix<T, N, N>,
    q: &SMatrix<T, N, N>,
    k: u32,
) -> (SMatrix<T, N, N>, SMatrix<T, N, N>) {
    // Segments of one time-invariant model commute, so the order in which the
    // binary pieces are composed does not matter.
    let compose = |(fa, qa): &(SMatrix<T, N, N>, SMatrix<T, N, N>),
                   (fb, qb): &(SMatrix<T, N, N>, SMatrix<T, N, N>)| {
        let mut qn = *qb;
        qn.quadform_tr(T::one(), fb, qa, T::one());
        (fb * fa, qn.symmetric_part())
    };
    let mut acc = (SMatrix::<T, N, N>::identity(), SMatrix::<T, N, N>::zeros());
    let mut pow = (*f, *q);
    let mut rest = k;
    while rest > 0 {
        if rest & 1 == 1 {
            acc = compose(&acc, &pow);
        }
        rest >>= 1;
        if rest > 0 {
            pow = compose(&pow, &pow);
        }
    }
    acc
}

/// Stabilising solution `X` of the filter DARE
/// `X = A X A^T - A X H^T (H X H^T + R)^-1 H X A^T + Q` by the
/// structure-preserving doubling algorithm (Chu, Fan, Lin 2005, applied to the
/// dual control DARE with `A -> F^T`), quadratically convergent.
fn solve_dare<T: RealField + Copy, const N: usize, const P: usize>(
    a: &SMatrix<T, N, N>,
    ht: &SMatrix<T, N, P>,
    r: &SVector<T, P>,
    q: &SMatrix<T, N, N>,
) -> Result<SMatrix<T, N, N>, BuildError> {
    let err = BuildError::NotConverged {
        name: "steady_state_gain",
    };
    let eye = SMatrix::<T, N, N>::identity();
    let mut ak = a.transpose();
    // G0 = H^T R^-1 H; R is diagonal and positive.
    let mut gk = SMatrix::<T, N, N>::zeros();
    for (j, rj) in r.iter().enumerate() {
        let h = ht.column(j);
        gk.ger(T::one() / *rj, &h, &h, T::one());
    }
    let mut xk = *q;
    let tol = T::default_epsilon() * nalgebra::convert(1e3);
    for _ in 0..MAX_DOUBLINGS {
        let w = (eye + gk * xk).try_inverse().ok_or(err)?;
        let aw = ak * w;
        let a_next = aw * ak;
        let g_next = (gk + aw * gk * ak.transpose()).symmetric_part();
        let x_next = (xk + ak.transpose() * xk * w * ak).symmetric_part();
        if !x_next.iter().all(|v| v.is_finite()) {
            return Err(err);
        }
        let change = max_abs(&(x_next - xk));
        let scale = max_abs(&x_next);
        ak = a_next;
        gk = g_next;
        xk = x_next;
        if change <= tol * scale {
            return Ok(xk);
        }
    }
    Err(err)
}

impl<T: RealField + Copy, const N: usize, const P: usize> SteadyStateGain<T, N, P> {
    /// Solves the steady-state filter for one correction (all `P` sensors)
    /// every `period` predict steps (`period >= 1`).
    ///
    /// The covariance between corrections follows the `period`-step model
    /// `F_k = F^k`, `Q_k = sum_{i<k} F^i Q F^iT`; the prior `M` just before a
    /// correction solves the DARE of (`F_k`, `H`, `Q_k`, `R`). The result is
    /// checked against one step of the Riccati recursion (sequential Joseph
    /// update then `F_k P F_k^T + Q_k`): [`BuildError::NotConverged`] if the
    /// residual exceeds `sqrt(eps)` relative, which is what an unstable mode
    /// that no sensor observes produces.
    ///
    /// Build-time cost O(N^3 (log2(period) + doublings)); stack about
    /// 12 N^2 scalars (12 KiB for N = 16 in f32).
    pub fn solve<const M: usize>(
        cfg: &KalmanConfig<T, N, M, P>,
        period: u32,
    ) -> Result<Self, BuildError> {
        if period == 0 {
            return Err(BuildError::InvalidParameter { name: "period" });
        }
        let (fk, qk) = k_step_model(&cfg.f, &cfg.q, period);
        let prior = solve_dare(&fk, &cfg.ht, &cfg.r, &qk)?;

        let mut posterior = prior;
        let mut scratch = SVector::<T, N>::zeros();
        for (j, rj) in cfg.r.iter().enumerate() {
            let h: SVector<T, N> = cfg.ht.column(j).into_owned();
            // The reading is irrelevant to the covariance; zero keeps x finite.
            let z = h.dot(&scratch);
            if !fuse_scalar(&mut scratch, &mut posterior, &h, *rj, z) {
                return Err(BuildError::Singular);
            }
        }
        let mut next = qk;
        next.quadform_tr(T::one(), &fk, &posterior, T::one());
        let residual = max_abs(&(next - prior));
        let bound = T::default_epsilon().sqrt() * max_abs(&prior);
        if !residual.is_finite() || residual > bound {
            return Err(BuildError::NotConverged {
                name: "steady_state_gain",
            });
        }

        // K = M H^T S^-1 with S = H M H^T + R, symmetric positive definite.
        let h = cfg.ht.transpose();
        let hm = h * prior;
        let mut s = hm * cfg.ht;
        add_diagonal(&mut s, &cfg.r);
        let innovation_var = SVector::<T, P>::from_fn(|j, _| s[(j, j)]);
        let chol = Cholesky::new(s.symmetric_part()).ok_or(BuildError::Singular)?;
        let gain = chol.solve(&hm).transpose();
        if !gain.iter().all(|v| v.is_finite()) {
            return Err(BuildError::Singular);
        }
        Ok(Self {
            period,
            gain,
            prior,
            posterior,
            innovation_var,
        })
    }

    /// Predict steps per correction this solution was made for.
    pub fn period(&self) -> u32 {
        self.period
    }

    /// Steady-state gain `K` (N x P) for a correction with all sensors.
    pub fn gain(&self) -> &SMatrix<T, N, P> {
        &self.gain
    }

    /// Steady-state prior covariance `M` (just before a correction).
    pub fn prior(&self) -> &SMatrix<T, N, N> {
        &self.prior
    }

    /// Steady-state posterior covariance (just after a full correction).
    pub fn posterior(&self) -> &SMatrix<T, N, N> {
        &self.posterior
    }

    /// Steady-state innovation variance `S_jj = h_j M h_j^T + r_j` per sensor.
    pub fn innovation_var(&self) -> &SVector<T, P> {
        &self.innovation_var
    }
}

/// Steady-state correction, to be called once every `ss.period()` calls of
/// [`super::predict_mean`].
///
/// Every present reading is gated with the stored innovation variance. If all
/// `P` are fused, `x += K (z - H x)` (2 N P multiply-adds). Otherwise (a
/// sensor missing or rejected) the full gain is wrong (its columns assume the
/// other sensors' information), so this correction falls back to sequential
/// Joseph updates of the accepted readings starting from the stored prior
/// `M`: the optimal update for that sensor subset given `M`, bounded at
/// O(P N^2). The stored `M` is then slightly optimistic for the next
/// correction (a missed reading leaves more uncertainty); the gate uses the
/// same `M`, so this is the filter's only approximation. Recovery inflates a
/// copy of `M` the same way as [`super::update`].
pub fn update_steady<T: RealField + Copy, const N: usize, const M: usize, const P: usize>(
    cfg: &KalmanConfig<T, N, M, P>,
    ss: &SteadyStateGain<T, N, P>,
    est: &mut SteadyEstimate<T, N, P>,
    z: &[Option<T>; P],
) -> UpdateReport<P> {
    let mut verdicts = [SensorVerdict::Missing; P];
    let mut nu = SVector::<T, P>::zeros();
    for (j, (verdict, zj)) in verdicts.iter_mut().zip(z).enumerate() {
        let Some(zj) = usable(*zj) else { continue };
        nu[j] = zj - cfg.ht.column(j).dot(&est.x);
        *verdict = judge(nu[j], ss.innovation_var[j], cfg.gate.threshold);
    }
    let recovered = est.gate.record_gate(&verdicts, cfg.gate.recover_after);
    if recovered {
        let mut cov = ss.prior;
        add_diagonal(&mut cov, &cfg.recovery_variance);
        verdicts = gate_all(&est.x, &cov, &cfg.ht, &cfg.r, z, cfg.gate.threshold);
        fuse_accepted(&mut est.x, &mut cov, &cfg.ht, &cfg.r, z, &mut verdicts);
    } else if verdicts.iter().all(|v| v.is_fused()) {
        let mut x_new = est.x;
        x_new.gemv(T::one(), &ss.gain, &nu, T::one());
        if x_new.iter().all(|v| v.is_finite()) {
            est.x = x_new;
        } else {
            for v in verdicts.iter_mut() {
                if let SensorVerdict::Fused { nis } = *v {
                    *v = SensorVerdict::Rejected { nis };
                }
            }
        }
    } else if verdicts.iter().any(|v| v.is_fused()) {
        let mut cov = ss.prior;
        fuse_accepted(&mut est.x, &mut cov, &cfg.ht, &cfg.r, z, &mut verdicts);
    }
    let suspect = est.gate.record_sensors(&verdicts, cfg.gate.suspect_after);
    UpdateReport {
        verdicts,
        suspect,
        recovered,
    }
}
