//! Steady-state filter: the k-step model, the discrete algebraic Riccati
//! equation (solved by structure-preserving doubling) and the constant-gain
//! correction with its missing-sensor fallback.

use nalgebra::allocator::Allocator;
use nalgebra::{Cholesky, DefaultAllocator, Dim, DimName, OMatrix, OVector, RealField, U1};

use super::gate::{judge, usable, GateCounters, SensorVerdict, UpdateReport};
use super::kalman::{add_diagonal, fuse_scalar, max_abs, KalmanConfig};
use super::{FilterAllocator, SensorAllocator};
use crate::error::BuildError;
use crate::sizes::Length;

/// Upper bound on doubling steps: step `i` covers `2^i` correction periods,
/// so 64 steps exceed any horizon a filter meets.
const MAX_DOUBLINGS: usize = 64;

/// The steady-state solution for corrections every `period` predict steps
/// (`N` states and `P` sensors, nalgebra dimensions).
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, PartialEq)]
pub struct SteadyStateGain<T: RealField + Copy, N: Dim, P: Dim>
where
    DefaultAllocator: SensorAllocator<N, P>,
{
    pub(crate) period: u32,
    pub(crate) gain: OMatrix<T, N, P>,
    pub(crate) prior: OMatrix<T, N, N>,
    pub(crate) posterior: OMatrix<T, N, N>,
    pub(crate) innovation_var: OVector<T, P>,
    /// `M H^T`: with `S` below, the update of any sensor subset from `M`
    /// without touching an `N x N` matrix.
    pub(crate) prior_ht: OMatrix<T, N, P>,
    /// Innovation covariance `S = H M H^T + R` of all sensors.
    pub(crate) innovation_cov: OMatrix<T, P, P>,
}

impl<T: RealField + Copy, N: Dim, P: Dim> Copy for SteadyStateGain<T, N, P>
where
    DefaultAllocator: SensorAllocator<N, P>,
    OMatrix<T, N, P>: Copy,
    OMatrix<T, N, N>: Copy,
    OMatrix<T, P, P>: Copy,
    OVector<T, P>: Copy,
{
}

/// Per-device state of the steady-state filter: the estimate and the gate
/// memory (no covariance: it is constant and lives in [`SteadyStateGain`]).
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, PartialEq)]
pub struct SteadyEstimate<T: RealField + Copy, N: Dim, P: Length>
where
    DefaultAllocator: Allocator<N>,
{
    /// State estimate `x`.
    pub x: OVector<T, N>,
    /// Rejection counters.
    pub gate: GateCounters<P>,
}

impl<T: RealField + Copy, N: Dim, P: Length> Copy for SteadyEstimate<T, N, P>
where
    DefaultAllocator: Allocator<N>,
    OVector<T, N>: Copy,
    GateCounters<P>: Copy,
{
}

impl<T: RealField + Copy, N: Dim, P: Length> SteadyEstimate<T, N, P>
where
    DefaultAllocator: Allocator<N>,
{
    /// An estimate starting at `x0`, for `sensors` sensors.
    pub fn for_sensors(x0: OVector<T, N>, sensors: P) -> Self {
        Self {
            x: x0,
            gate: GateCounters::new(sensors),
        }
    }

    /// An estimate starting at `x0`, for a number of sensors known when
    /// compiling.
    pub fn new(x0: OVector<T, N>) -> Self
    where
        P: DimName,
    {
        Self::for_sensors(x0, P::name())
    }
}

/// `(F^k, sum_{i<k} F^i Q F^iT)`: the transition and process noise of `k`
/// predict steps, by binary powering (at most 2 log2(k) compositions).
pub fn k_step_model<T: RealField + Copy, N: Dim>(
    f: &OMatrix<T, N, N>,
    q: &OMatrix<T, N, N>,
    k: u32,
) -> (OMatrix<T, N, N>, OMatrix<T, N, N>)
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    // Segments of one time-invariant model commute, so the order in which the
    // binary pieces are composed does not matter.
    let compose = |(fa, qa): &(OMatrix<T, N, N>, OMatrix<T, N, N>),
                   (fb, qb): &(OMatrix<T, N, N>, OMatrix<T, N, N>)| {
        let mut qn = qb.clone();
        qn.quadform_tr(T::one(), fb, qa, T::one());
        (fb * fa, qn.symmetric_part())
    };
    let (rows, columns) = f.shape_generic();
    let mut acc = (
        OMatrix::<T, N, N>::identity_generic(rows, columns),
        OMatrix::<T, N, N>::zeros_generic(rows, columns),
    );
    let mut pow = (f.clone(), q.clone());
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
fn solve_dare<T: RealField + Copy, N: Dim, P: Dim>(
    a: &OMatrix<T, N, N>,
    ht: &OMatrix<T, N, P>,
    r: &OVector<T, P>,
    q: &OMatrix<T, N, N>,
) -> Result<OMatrix<T, N, N>, BuildError>
where
    DefaultAllocator: SensorAllocator<N, P>,
{
    let err = BuildError::NotConverged {
        name: "steady_state_gain",
    };
    let (rows, columns) = a.shape_generic();
    let eye = OMatrix::<T, N, N>::identity_generic(rows, columns);
    let mut ak = a.transpose();
    // G0 = H^T R^-1 H; R is diagonal and positive.
    let mut gk = OMatrix::<T, N, N>::zeros_generic(rows, columns);
    for (j, rj) in r.iter().enumerate() {
        let h = ht.column(j);
        gk.ger(T::one() / *rj, &h, &h, T::one());
    }
    let mut xk = q.clone();
    let tol = T::default_epsilon() * nalgebra::convert(1e3);
    for _ in 0..MAX_DOUBLINGS {
        let w = (&eye + &gk * &xk).try_inverse().ok_or(err)?;
        let aw = &ak * &w;
        let a_next = &aw * &ak;
        let g_next = (&gk + &aw * &gk * ak.transpose()).symmetric_part();
        let x_next = (&xk + ak.transpose() * &xk * &w * &ak).symmetric_part();
        if !x_next.iter().all(|v| v.is_finite()) {
            return Err(err);
        }
        let change = max_abs(&(&x_next - &xk));
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

impl<T: RealField + Copy, N: Dim, P: Dim> SteadyStateGain<T, N, P>
where
    DefaultAllocator: SensorAllocator<N, P>,
{
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
    /// 20 N^2 scalars (about 20 KiB for N = 16 in f32, an estimate).
    pub fn solve<M: Dim>(cfg: &KalmanConfig<T, N, M, P>, period: u32) -> Result<Self, BuildError>
    where
        N: Length,
        P: Length,
        DefaultAllocator: FilterAllocator<N, M, P>,
    {
        if period == 0 {
            return Err(BuildError::InvalidParameter { name: "period" });
        }
        let (fk, qk) = k_step_model(&cfg.f, &cfg.q, period);
        let prior = solve_dare(&fk, &cfg.ht, &cfg.r, &qk)?;

        let mut posterior = prior.clone();
        let mut scratch = OVector::<T, N>::zeros_generic(prior.shape_generic().0, U1);
        for (j, rj) in cfg.r.iter().enumerate() {
            let h: OVector<T, N> = cfg.ht.column(j).into_owned();
            // The reading is irrelevant to the covariance; zero keeps x finite.
            let z = h.dot(&scratch);
            if !fuse_scalar(&mut scratch, &mut posterior, &h, *rj, z) {
                return Err(BuildError::Singular);
            }
        }
        let mut next = qk;
        next.quadform_tr(T::one(), &fk, &posterior, T::one());
        let residual = max_abs(&(next - &prior));
        let bound = T::default_epsilon().sqrt() * max_abs(&prior);
        if !residual.is_finite() || residual > bound {
            return Err(BuildError::NotConverged {
                name: "steady_state_gain",
            });
        }

        // K = M H^T S^-1 with S = H M H^T + R, symmetric positive definite.
        let h = cfg.ht.transpose();
        let hm = h * &prior;
        let mut s = &hm * &cfg.ht;
        add_diagonal(&mut s, &cfg.r);
        let s = s.symmetric_part();
        let innovation_var = s.diagonal();
        let chol = Cholesky::new(s.clone()).ok_or(BuildError::Singular)?;
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
            prior_ht: hm.transpose(),
            innovation_cov: s,
        })
    }

    /// Predict steps per correction this solution was made for.
    pub fn period(&self) -> u32 {
        self.period
    }

    /// Steady-state gain `K` (N x P) for a correction with all sensors.
    pub fn gain(&self) -> &OMatrix<T, N, P> {
        &self.gain
    }

    /// Steady-state prior covariance `M` (just before a correction).
    pub fn prior(&self) -> &OMatrix<T, N, N> {
        &self.prior
    }

    /// Steady-state posterior covariance (just after a full correction).
    pub fn posterior(&self) -> &OMatrix<T, N, N> {
        &self.posterior
    }

    /// Steady-state innovation variance `S_jj = h_j M h_j^T + r_j` per sensor.
    pub fn innovation_var(&self) -> &OVector<T, P> {
        &self.innovation_var
    }

    /// Steady-state innovation covariance `S = H M H^T + R` (P x P).
    pub fn innovation_cov(&self) -> &OMatrix<T, P, P> {
        &self.innovation_cov
    }

    /// `M H^T` (N x P): the columns the update of any sensor subset combines.
    pub fn prior_ht(&self) -> &OMatrix<T, N, P> {
        &self.prior_ht
    }
}

/// Solves `S_ss w_s = nu_s` on the sensors `used` (`w` is zero elsewhere) by
/// Cholesky; `None` unless `S_ss` is positive definite and `w` finite.
///
/// The unused rows and columns are replaced by those of the identity, so one
/// fixed-size factorisation serves every subset: `O(P^3 / 6)`.
fn solve_subset<T: RealField + Copy, P: Length>(
    s: &OMatrix<T, P, P>,
    nu: &OVector<T, P>,
    used: &P::Array<bool>,
) -> Option<OVector<T, P>>
where
    DefaultAllocator: Allocator<P, P> + Allocator<P>,
{
    let (rows, columns) = s.shape_generic();
    let p = s.nrows();
    let used = used.as_ref();
    let mut l = OMatrix::<T, P, P>::zeros_generic(rows, columns);
    let mut w = OVector::<T, P>::zeros_generic(rows, U1);
    for i in 0..p {
        if !used[i] {
            l[(i, i)] = T::one();
            continue;
        }
        for j in 0..i {
            if !used[j] {
                continue;
            }
            let mut v = s[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v / l[(j, j)];
        }
        let mut d = s[(i, i)];
        for k in 0..i {
            d -= l[(i, k)] * l[(i, k)];
        }
        // Also refuses NaN.
        if d.partial_cmp(&T::zero()) != Some(core::cmp::Ordering::Greater) {
            return None;
        }
        l[(i, i)] = d.sqrt();
        w[i] = nu[i];
    }
    // L y = nu, then L^T w = y (unused rows stay zero: their row of L is e_i
    // and their right-hand side zero).
    for i in 0..p {
        let mut v = w[i];
        for k in 0..i {
            v -= l[(i, k)] * w[k];
        }
        w[i] = v / l[(i, i)];
    }
    for i in (0..p).rev() {
        let mut v = w[i];
        for k in i + 1..p {
            v -= l[(k, i)] * w[k];
        }
        w[i] = v / l[(i, i)];
    }
    w.iter().all(|v| v.is_finite()).then_some(w)
}

/// `x += M H_s^T (H_s M H_s^T + R_s)^-1 nu_s` over the fused sensors `s`
/// (the batch form of the sequential update from the prior `M`, equal to it
/// up to rounding because `R` is diagonal), from `mht = M H^T` and
/// `S = H M H^T + R`. Fused verdicts become rejected if it is not finite.
/// `O(N P + P^3)`, against `O(P N^2)` for the sequential Joseph updates.
fn fuse_subset<T: RealField + Copy, N: Dim, P: Length>(
    x: &mut OVector<T, N>,
    mht: &OMatrix<T, N, P>,
    s: &OMatrix<T, P, P>,
    nu: &OVector<T, P>,
    verdicts: &mut P::Array<SensorVerdict>,
) where
    DefaultAllocator: SensorAllocator<N, P>,
{
    let used = P::mapped(verdicts, SensorVerdict::is_fused);
    let step = solve_subset(s, nu, &used).map(|w| {
        let mut x_new = x.clone();
        x_new.gemv(T::one(), mht, &w, T::one());
        x_new
    });
    match step {
        Some(x_new) if x_new.iter().all(|v| v.is_finite()) => *x = x_new,
        _ => {
            for v in verdicts.as_mut().iter_mut() {
                if let SensorVerdict::Fused { nis } = *v {
                    *v = SensorVerdict::Rejected { nis };
                }
            }
        }
    }
}

/// Steady-state correction, to be called once every `ss.period()` calls of
/// [`super::predict_mean`].
///
/// Every present reading is gated with the stored innovation variance. If all
/// `P` are fused, `x += K (z - H x)` (2 N P multiply-adds). Otherwise (a
/// sensor missing or rejected) the full gain is wrong (its columns assume the
/// other sensors' information), so this correction uses the optimal update
/// for the accepted subset `s` given the stored prior `M`,
/// `x += M H_s^T (H_s M H_s^T + R_s)^-1 nu_s`, from the stored `M H^T` and
/// `S` (a `P x P` Cholesky and an `N x P` product, `O(N P + P^3)`; the same
/// result as sequential Joseph updates from `M`, to rounding). The stored
/// `M` is then slightly optimistic for the next correction (a missed reading
/// leaves more uncertainty); the gate uses the same `M`, so this is the
/// filter's only approximation. Recovery inflates `M` by the same diagonal as
/// [`super::update`], through `M H^T` and `S` only (`O(N P^2)`).
pub fn update_steady<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    ss: &SteadyStateGain<T, N, P>,
    est: &mut SteadyEstimate<T, N, P>,
    z: &P::Array<Option<T>>,
) -> UpdateReport<P>
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    update_against(
        cfg,
        &ss.gain,
        &ss.innovation_var,
        &ss.prior_ht,
        &ss.innovation_cov,
        est,
        z,
    )
}

/// [`update_steady`]'s correction against any prior given by its gain
/// `K = M H^T S^-1` (all `P` sensors), `S`'s diagonal, `M H^T` and `S`:
/// the steady solution's, or a covariance held elsewhere (the start's,
/// see [`crate::observer::start`], whose holder updates it). Inlined in
/// both: as a call, `observer_m4`'s steady correction tick cost 120
/// instructions more.
#[inline(always)]
pub(crate) fn update_against<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    gain: &OMatrix<T, N, P>,
    innovation_var: &OVector<T, P>,
    prior_ht: &OMatrix<T, N, P>,
    innovation_cov: &OMatrix<T, P, P>,
    est: &mut SteadyEstimate<T, N, P>,
    z: &P::Array<Option<T>>,
) -> UpdateReport<P>
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    let mut verdicts = P::filled_like(z, SensorVerdict::Missing);
    let mut nu = OVector::<T, P>::zeros_generic(innovation_var.shape_generic().0, U1);
    let readings = verdicts.as_mut().iter_mut().zip(z.as_ref());
    for (j, ((verdict, zj), reads)) in readings.zip(cfg.reads.as_ref()).enumerate() {
        let Some(zj) = usable(*zj) else { continue };
        nu[j] = zj - reads.dot(&cfg.ht, j, &est.x);
        *verdict = judge(nu[j], innovation_var[j], cfg.gate.threshold);
    }
    let recovered = est.gate.record_gate(&verdicts, cfg.gate.recover_after);
    if recovered {
        recover_and_fuse(cfg, prior_ht, innovation_cov, est, z, &nu, &mut verdicts);
    } else if verdicts.as_ref().iter().all(|v| v.is_fused()) {
        let mut x_new = est.x.clone();
        super::add_product(&mut x_new, gain, &nu);
        if x_new.iter().all(|v| v.is_finite()) {
            est.x = x_new;
        } else {
            for v in verdicts.as_mut().iter_mut() {
                if let SensorVerdict::Fused { nis } = *v {
                    *v = SensorVerdict::Rejected { nis };
                }
            }
        }
    } else if verdicts.as_ref().iter().any(|v| v.is_fused()) {
        fuse_subset(&mut est.x, prior_ht, innovation_cov, &nu, &mut verdicts);
    }
    let suspect = est.gate.record_sensors(&verdicts, cfg.gate.suspect_after);
    UpdateReport {
        verdicts,
        suspect,
        recovered,
    }
}

/// The recovery of [`update_steady`] and [`update_against`]: the prior
/// inflated by the recovery diagonal `D` through `M H^T` and `S` only
/// (`(M + D) H^T = M H^T + D H^T`, `S + H D H^T`: the inflated prior is
/// never formed), every present reading gated again against it and the
/// accepted ones fused.
fn recover_and_fuse<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    prior_ht: &OMatrix<T, N, P>,
    innovation_cov: &OMatrix<T, P, P>,
    est: &mut SteadyEstimate<T, N, P>,
    z: &P::Array<Option<T>>,
    nu: &OVector<T, P>,
    verdicts: &mut P::Array<SensorVerdict>,
) where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    let d = &cfg.recovery_variance;
    let mut mht = prior_ht.clone();
    let mut s = innovation_cov.clone();
    for (j, hj) in cfg.ht.column_iter().enumerate() {
        for (n, dn) in d.iter().enumerate() {
            mht[(n, j)] += *dn * hj[n];
        }
        for (i, hi) in cfg.ht.column_iter().enumerate() {
            s[(i, j)] += hi.component_mul(&hj).dot(d);
        }
    }
    for (j, (verdict, zj)) in verdicts.as_mut().iter_mut().zip(z.as_ref()).enumerate() {
        if usable(*zj).is_some() {
            *verdict = judge(nu[j], s[(j, j)], cfg.gate.threshold);
        }
    }
    fuse_subset(&mut est.x, &mht, &s, nu, verdicts);
}

impl<N: Dim, P: Dim> SteadyStateGain<f64, N, P>
where
    DefaultAllocator: SensorAllocator<N, P>,
{
    /// The same solution in another float type: solved in `f64` (where
    /// the doubling keeps its accuracy), run in `f32`.
    pub fn cast<U: RealField + Copy>(&self) -> SteadyStateGain<U, N, P> {
        SteadyStateGain {
            period: self.period,
            gain: self.gain.clone().cast(),
            prior: self.prior.clone().cast(),
            posterior: self.posterior.clone().cast(),
            innovation_var: self.innovation_var.clone().cast(),
            prior_ht: self.prior_ht.clone().cast(),
            innovation_cov: self.innovation_cov.clone().cast(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::testutil::{RandomSystem, Rng};
    use crate::filter::{predict, predict_mean, update, KalmanState};
    use nalgebra::{Const, Matrix1, SMatrix, SVector, Vector1};

    type Cfg = KalmanConfig<f64, Const<4>, U1, Const<2>>;

    fn random_cfg(seed: u64) -> (Cfg, RandomSystem<4, 2>) {
        let mut rng = Rng::new(seed);
        let sys = RandomSystem::<4, 2>::new(&mut rng, 0.98, 0.01);
        let cfg = Cfg::new(sys.f, rng.matrix(), sys.h, sys.q, sys.r).unwrap();
        (cfg, sys)
    }

    /// Batch gain from a prior, by the matrix inverse: the independent answer.
    fn batch_gain(m: &SMatrix<f64, 4, 4>, sys: &RandomSystem<4, 2>) -> SMatrix<f64, 4, 2> {
        let s = sys.h * m * sys.h.transpose() + SMatrix::<f64, 2, 2>::from_diagonal(&sys.r);
        m * sys.h.transpose() * s.try_inverse().unwrap()
    }

    /// Random walk with a correction every k steps: F^k = 1, Q_k = k q, so
    /// M = (k q + sqrt((k q)^2 + 4 k q r)) / 2 and K = M / (M + r).
    #[test]
    fn random_walk_closed_form_any_period() {
        let (q, r) = (1e-3f64, 0.25f64);
        let cfg = KalmanConfig::<f64, U1, U1, U1>::new(
            Matrix1::new(1.0),
            Matrix1::new(0.0),
            Matrix1::new(1.0),
            Matrix1::new(q),
            Vector1::new(r),
        )
        .unwrap();
        for k in [1u32, 2, 7, 500] {
            let qk = k as f64 * q;
            let m = (qk + (qk * qk + 4.0 * qk * r).sqrt()) / 2.0;
            let ss = SteadyStateGain::solve(&cfg, k).unwrap();
            assert!((ss.prior()[(0, 0)] - m).abs() < 1e-12 * m, "k={k}");
            assert!((ss.gain()[(0, 0)] - m / (m + r)).abs() < 1e-12, "k={k}");
            assert!((ss.innovation_var()[0] - (m + r)).abs() < 1e-12);
        }
    }

    /// Binary powering against k plain steps of the recursion.
    #[test]
    fn k_step_model_matches_stepping() {
        let (_, sys) = random_cfg(1);
        for k in [1u32, 2, 3, 13, 64, 100] {
            let (fk, qk) = k_step_model(&sys.f, &sys.q, k);
            let (mut f_ref, mut q_ref) = (SMatrix::<f64, 4, 4>::identity(), SMatrix::zeros());
            for _ in 0..k {
                f_ref = sys.f * f_ref;
                q_ref = sys.f * q_ref * sys.f.transpose() + sys.q;
            }
            assert!((fk - f_ref).abs().max() < 1e-12, "k={k}");
            assert!(
                (qk - q_ref).abs().max() < 1e-12 * q_ref.abs().max(),
                "k={k}"
            );
        }
    }

    /// The steady-state prior and gain are the limits of the time-varying
    /// filter run with `k` predicts between full corrections.
    #[test]
    fn steady_state_is_limit_of_time_varying() {
        for (seed, k) in [(2u64, 1u32), (3, 1), (4, 7), (5, 50)] {
            let (cfg, sys) = random_cfg(seed);
            let ss = SteadyStateGain::solve(&cfg, k).unwrap();
            let mut st = KalmanState::new(SVector::zeros(), SMatrix::identity() * 5.0);
            let mut gain = SMatrix::<f64, 4, 2>::zeros();
            for _ in 0..3000 {
                for _ in 0..k {
                    predict(&cfg, &mut st, &Vector1::new(0.0));
                }
                gain = batch_gain(&st.cov, &sys);
                let _ = update(&cfg, &mut st, &[Some(0.0), Some(0.0)]);
            }
            let tol = 1e-9;
            assert!(
                (gain - ss.gain()).abs().max() < tol * gain.abs().max(),
                "seed {seed} k {k}"
            );
            assert!((st.cov - ss.posterior()).abs().max() < tol * st.cov.abs().max());
            for _ in 0..k {
                predict(&cfg, &mut st, &Vector1::new(0.0));
            }
            assert!((st.cov - ss.prior()).abs().max() < tol * st.cov.abs().max());
        }
    }

    /// With all sensors present the steady-state update is `x += K nu`; with
    /// one missing or rejected it equals the batch update of the remaining
    /// sensor from the stored prior (independent inverse formula).
    #[test]
    fn steady_update_full_and_missing_sensor() {
        let (cfg, sys) = random_cfg(6);
        let ss = SteadyStateGain::solve(&cfg, 10).unwrap();
        let x0 = SVector::<f64, 4>::new(0.1, -0.2, 0.3, 0.05);
        let z = sys.h * x0;
        let mut est = SteadyEstimate::new(SVector::zeros());
        let rep = update_steady(&cfg, &ss, &mut est, &[Some(z[0]), Some(z[1])]);
        assert_eq!(rep.fused(), 2);
        let expect = batch_gain(ss.prior(), &sys) * z;
        assert!((est.x - expect).abs().max() < 1e-10);

        // Sensor 1 alone: K_1 = M h1^T / (h1 M h1^T + r1).
        let h1 = sys.h.row(1).transpose();
        let k1 = ss.prior() * h1 / ((h1.transpose() * ss.prior() * h1)[(0, 0)] + sys.r[1]);
        let expect = k1 * z[1];
        for missing in [None, Some(f64::NAN), Some(1e6)] {
            let mut est = SteadyEstimate::new(SVector::zeros());
            let rep = update_steady(&cfg, &ss, &mut est, &[missing, Some(z[1])]);
            assert!(rep.verdicts[1].is_fused());
            assert!(!rep.verdicts[0].is_fused());
            assert_eq!(rep.verdicts[0].is_rejected(), missing == Some(1e6));
            assert!((est.x - expect).abs().max() < 1e-10, "{missing:?}");
        }
        // Nothing usable: x unchanged.
        let mut est = SteadyEstimate::new(x0);
        let rep = update_steady(&cfg, &ss, &mut est, &[None, Some(f64::INFINITY)]);
        assert_eq!(rep.fused(), 0);
        assert_eq!(est.x, x0);
    }

    /// Every subset of six sensors (missing or gated out): the update equals
    /// the batch formula with the subset's inverse from the stored prior and
    /// the sequential Joseph updates from it; after recovery, the same with
    /// the inflated prior.
    #[test]
    fn steady_update_every_sensor_subset() {
        use crate::filter::kalman::fuse_accepted;
        let mut rng = Rng::new(61);
        let sys = RandomSystem::<5, 6>::new(&mut rng, 0.97, 0.02);
        let cfg = KalmanConfig::<f64, Const<5>, U1, Const<6>>::new(
            sys.f,
            rng.matrix(),
            sys.h,
            sys.q,
            sys.r,
        )
        .unwrap()
        .with_gate(f64::INFINITY)
        .unwrap();
        let ss = SteadyStateGain::solve(&cfg, 3).unwrap();
        let x0: SVector<f64, 5> = rng.matrix();
        let zv: SVector<f64, 6> = sys.h * rng.matrix::<5, 1>();
        let batch = |m: &SMatrix<f64, 5, 5>, used: &[bool; 6], zv: &SVector<f64, 6>| {
            let idx: Vec<usize> = (0..6).filter(|j| used[*j]).collect();
            let hs =
                SMatrix::<f64, 6, 5>::from_fn(|r, c| idx.get(r).map_or(0.0, |j| sys.h[(*j, c)]));
            let mut s = hs * m * hs.transpose();
            for r in 0..6 {
                s[(r, r)] += idx.get(r).map_or(1.0, |j| sys.r[*j]);
            }
            let nu = SVector::<f64, 6>::from_fn(|r, _| {
                idx.get(r).map_or(0.0, |j| zv[*j] - (sys.h.row(*j) * x0)[0])
            });
            x0 + m * hs.transpose() * s.try_inverse().unwrap() * nu
        };
        for mask in 1u32..64 {
            let used: [bool; 6] = core::array::from_fn(|j| mask & (1 << j) != 0);
            let z: [Option<f64>; 6] = core::array::from_fn(|j| used[j].then_some(zv[j]));
            let mut est = SteadyEstimate::new(x0);
            let rep = update_steady(&cfg, &ss, &mut est, &z);
            assert_eq!(rep.fused(), mask.count_ones() as usize);
            let expect = batch(ss.prior(), &used, &zv);
            let tol = 1e-10 * (1.0 + expect.abs().max());
            assert!((est.x - expect).abs().max() < tol, "mask {mask:06b}");
            let (mut x_seq, mut cov) = (x0, *ss.prior());
            let mut verdicts = rep.verdicts;
            fuse_accepted(&mut x_seq, &mut cov, &cfg.ht, &cfg.r, &z, &mut verdicts);
            assert!((est.x - x_seq).abs().max() < tol, "mask {mask:06b}");
        }

        // Readings 100 sigma off: every one fails the gate against M, so
        // recovery (after 1) inflates M by D and fuses them against M + D.
        let d = SVector::<f64, 5>::from_fn(|i, _| 1e6 * (1.0 + i as f64));
        let cfg = cfg
            .with_gate(crate::filter::CHI2_1DOF_999)
            .unwrap()
            .with_recovery(1, d)
            .unwrap();
        let mut inflated = *ss.prior();
        add_diagonal(&mut inflated, &d);
        let far = sys.h * x0 + SVector::from_fn(|j, _| 100.0 * ss.innovation_var()[j].sqrt());
        for mask in [0b111111u32, 0b101101, 0b000100] {
            let used: [bool; 6] = core::array::from_fn(|j| mask & (1 << j) != 0);
            let z: [Option<f64>; 6] = core::array::from_fn(|j| used[j].then_some(far[j]));
            let mut est = SteadyEstimate::new(x0);
            let rep = update_steady(&cfg, &ss, &mut est, &z);
            assert!(rep.recovered);
            assert_eq!(rep.fused(), mask.count_ones() as usize);
            let expect = batch(&inflated, &used, &far);
            let tol = 1e-9 * (1.0 + expect.abs().max());
            assert!(
                (est.x - expect).abs().max() < tol,
                "recovery mask {mask:06b}"
            );
        }
    }

    /// Over a simulated run the steady-state filter (predict_mean, k = 20)
    /// tracks the time-varying filter once both have settled.
    #[test]
    fn steady_filter_tracks_time_varying() {
        let (cfg, sys) = random_cfg(8);
        let k = 20;
        let ss = SteadyStateGain::solve(&cfg, k).unwrap();
        let mut rng = Rng::new(99);
        let mut truth = SVector::<f64, 4>::zeros();
        let mut st = KalmanState::new(SVector::zeros(), *ss.posterior());
        let mut est = SteadyEstimate::new(SVector::zeros());
        for n in 0..400 {
            for t in 0..k {
                let u = Vector1::new(((n * k + t) as f64 * 0.01).sin());
                truth =
                    sys.f * truth + cfg.g() * u + RandomSystem::<4, 2>::sample(&mut rng, &sys.q);
                predict(&cfg, &mut st, &u);
                predict_mean(&cfg, &mut est.x, &u);
            }
            let z = sys.h * truth + SVector::from_fn(|j, _| sys.r[j].sqrt() * rng.gauss());
            let zs = [Some(z[0]), Some(z[1])];
            let a = update(&cfg, &mut st, &zs);
            let b = update_steady(&cfg, &ss, &mut est, &zs);
            assert_eq!(
                a.verdicts.map(|v| v.is_fused()),
                b.verdicts.map(|v| v.is_fused())
            );
            // Starting at the steady posterior, both are the same filter.
            assert!(
                (st.x - est.x).abs().max() < 1e-9 * (1.0 + st.x.abs().max()),
                "n={n}"
            );
        }
    }

    /// An unstable mode that no sensor sees has no steady state.
    #[test]
    fn unobservable_unstable_mode_does_not_converge() {
        let f = SMatrix::<f64, 2, 2>::new(0.9, 0.0, 0.0, 1.01);
        let h = SMatrix::<f64, 1, 2>::new(1.0, 0.0);
        let cfg = KalmanConfig::<f64, Const<2>, U1, U1>::new(
            f,
            SMatrix::zeros(),
            h,
            SMatrix::identity() * 0.01,
            Vector1::new(0.1),
        )
        .unwrap();
        assert_eq!(
            SteadyStateGain::solve(&cfg, 1),
            Err(BuildError::NotConverged {
                name: "steady_state_gain"
            })
        );
        assert_eq!(
            SteadyStateGain::solve(&cfg, 0),
            Err(BuildError::InvalidParameter { name: "period" })
        );
    }

    /// Recovery in steady-state mode: a wrong estimate is pulled back after
    /// `recover_after` all-rejected corrections.
    #[test]
    fn steady_recovery() {
        let (cfg, sys) = random_cfg(9);
        let cfg = cfg.with_recovery(2, SVector::repeat(1e6)).unwrap();
        let ss = SteadyStateGain::solve(&cfg, 5).unwrap();
        let mut est = SteadyEstimate::new(SVector::repeat(100.0));
        let z = [Some(0.0), Some(0.0)];
        let r1 = update_steady(&cfg, &ss, &mut est, &z);
        assert_eq!((r1.fused(), r1.recovered), (0, false));
        let r2 = update_steady(&cfg, &ss, &mut est, &z);
        assert!(r2.recovered);
        assert_eq!(r2.fused(), 2);
        // The readings see H x: that projection is now near zero.
        assert!((sys.h * est.x).abs().max() < 1.0, "{}", sys.h * est.x);
    }
}

#[cfg(test)]
mod sized_tests {
    use super::*;
    use crate::filter::testutil::thermal_chain_16;
    use nalgebra::{Const, SMatrix, SVector};

    /// The device's sizes: 16 states, 6 thermocouples at 2 Hz with 1 kHz
    /// predicts (period 500). The f32 solution agrees with the f64 one.
    #[test]
    fn omnimagnet_sized_period_500() {
        let (f, h) = thermal_chain_16();
        let q = SMatrix::<f64, 16, 16>::identity() * 1e-8;
        let r = SVector::<f64, 6>::repeat(0.01);
        let cfg =
            KalmanConfig::<f64, Const<16>, Const<3>, Const<6>>::new(f, SMatrix::zeros(), h, q, r)
                .unwrap();
        let ss = SteadyStateGain::solve(&cfg, 500).unwrap();
        assert!(ss.gain().iter().all(|v| v.is_finite()));

        let cfg32 = KalmanConfig::<f32, Const<16>, Const<3>, Const<6>>::new(
            f.cast(),
            SMatrix::zeros(),
            h.cast(),
            q.cast(),
            r.cast(),
        )
        .unwrap();
        let ss32 = SteadyStateGain::solve(&cfg32, 500).unwrap();
        // Compare with f64 on the same rounded model: F = I + A dt keeps only
        // ~2 digits of A dt in f32, a model error the solver cannot undo.
        let rounded = KalmanConfig::<f64, Const<16>, Const<3>, Const<6>>::new(
            cfg32.f().cast(),
            SMatrix::zeros(),
            cfg32.h().cast(),
            cfg32.q().cast(),
            cfg32.r().cast(),
        )
        .unwrap();
        let reference = SteadyStateGain::solve(&rounded, 500).unwrap();
        let scale = reference.gain().abs().max();
        let diff = (ss32.gain().cast::<f64>() - reference.gain()).abs().max();
        assert!(diff < 1e-3 * scale, "f32 gain off by {diff} (max {scale})");
    }
}
