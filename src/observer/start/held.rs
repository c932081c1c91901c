//! The start's covariance held by an observer whose tick cannot afford a
//! covariance predict per model step (see the module docs of
//! [`super`], "A covariance per correction period, in slices").
//!
//! The filter's states are `X`: the first `T` have dynamics, the others
//! are random walks (unit rows of the transition), so one correction
//! period's transition is `F = [[I + Phi', Gamma], [0, I]]` with `Phi'`
//! (`T x T`) and `Gamma` (`T x (X - T)`). The sensors read `K` of the
//! states (`measured`), each with its own noise.
//!
//! What is held: the prior `P` of the current period and the information
//! fused against it since, `lambda_k = sum 1 / r` of the readings fused on
//! measured state `k` (`K` numbers). The posterior is then
//!
//! ```text
//! P+ = P - P[:, N] W P[N, :],   W = L (I + A L)^-1 = S (I + S A S)^-1 S,
//! ```
//!
//! with `A = P[N, N]`, `L = diag(lambda)` and `S = sqrt(L)`: the batch
//! update of every reading fused, whatever their number and order (`R`
//! diagonal), so readings that arrive on their own within a period cost a
//! `K x K` solve each and no `X x X` work. Once per correction period the
//! next prior is formed from the steady solution (`M` the prior, `P_ss` the
//! posterior, `M = F P_ss F^T + Q_k`):
//!
//! ```text
//! P_next = F (P+ - P_ss) F^T + M,
//! ```
//!
//! which needs no `Q_k` (`M` carries it) and whose error term is the
//! start's excess over the steady state, which the period's transition
//! contracts. That propagation is cut into slices of at most
//! `(T + 1) X + K X` multiply-adds (the columns of `F (P+ - P_ss)`, then
//! the rows of the lower triangle of its product with `F^T`, two rows a
//! slice, then a slice that mirrors and adds `M`), one per light tick, in
//! a second buffer-free pass over the one `X x X` matrix: the prior's
//! columns at the measured states are kept aside, so the corrections that
//! arrive while the slices run still have their prior.

use nalgebra::{SMatrix, SVector};

use super::{MAX_START_CORRECTIONS, SETTLED_FRACTION, START_FORGOTTEN_K};
use crate::filter::SensorVerdict;

/// The propagation's progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// The buffer holds the prior of the current period.
    Ready,
    /// Column `j` of `F (P+ - P_ss)` is next.
    Columns(u16),
    /// Row pair `p` of the lower triangle of `F (P+ - P_ss) F^T` is next.
    Rows(u16),
    /// Column `j`'s lower triangle mirrored and `M` added is next.
    Mirror(u16),
    /// The next prior taken.
    Finish,
}

impl Phase {
    /// The phase after slice `k` of `count` in `phase`: its next slice,
    /// or `then` after the last.
    fn after(k: usize, count: usize, phase: fn(u16) -> Self, then: Self) -> Self {
        if k + 1 < count {
            phase((k + 1) as u16)
        } else {
            then
        }
    }
}

/// One correction period's transition `F = [[I + Phi', Gamma], [0, I]]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PeriodTransition<'a, const T: usize, const G: usize> {
    /// `Phi - I` (`T x T`, dimensionless).
    pub(crate) phi_minus_i: &'a SMatrix<f32, T, T>,
    /// Its first `X - T` columns are `Gamma`: how the random walks enter
    /// the dynamic states over a period.
    pub(crate) gamma: &'a SMatrix<f32, T, G>,
}

/// What a slice of the propagation reads: the correction period's model
/// steps and transition, and the steady solution's covariances and its
/// recovery variances.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Propagation<'a, const T: usize, const G: usize, const X: usize> {
    /// Model steps per correction period.
    pub(crate) period: u32,
    /// The period's transition.
    pub(crate) transition: PeriodTransition<'a, T, G>,
    /// The steady solution's prior covariance.
    pub(crate) steady_prior: &'a SMatrix<f32, X, X>,
    /// The steady solution's posterior covariance.
    pub(crate) steady_posterior: &'a SMatrix<f32, X, X>,
    /// The filter's recovery variances.
    pub(crate) recovery: &'a SVector<f32, X>,
}

/// What the held covariance knows of its observer: `X` states, `K` of
/// them measured by `P` sensors.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeldLayout<const X: usize, const K: usize, const P: usize> {
    /// The measured states.
    pub(crate) measured: [usize; K],
    /// Each sensor's place in `measured` (`None`: not fitted, never fused).
    pub(crate) sensors: [Option<usize>; P],
    /// Each sensor's noise variance \[K^2\].
    pub(crate) r: [f32; P],
    /// The steady prior's standard deviations, the upper bound's `sigma`.
    pub(crate) steady_sigma: [f32; X],
    /// The upper bound's `k` (of `k sigma`).
    pub(crate) k_sigma: f32,
    /// The states [`HeldCovariance::forgotten`] watches.
    pub(crate) watched: [bool; X],
}

/// What a correction fuses against: the gain of all the sensors, the
/// innovation variances, `M H^T` and `S` of the prior after the
/// information fused since (see [`crate::filter::update_steady`]).
pub(crate) type Correction<'a, const X: usize, const P: usize> = (
    &'a SMatrix<f32, X, P>,
    &'a SVector<f32, P>,
    &'a SMatrix<f32, X, P>,
    &'a SMatrix<f32, P, P>,
);

/// The start's covariance, held until it settles on the steady one (see
/// the module docs). `X` states, `K` of them measured by `P` sensors.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HeldCovariance<const X: usize, const K: usize, const P: usize> {
    layout: HeldLayout<X, K, P>,
    /// Held (the start's warm-up runs).
    active: bool,
    /// The prior while [`Phase::Ready`], else the propagation in progress.
    cov: SMatrix<f32, X, X>,
    /// The prior's columns at the measured states.
    cols: SMatrix<f32, X, K>,
    /// The prior's diagonal (for the upper bound, through the slices).
    prior_var: [f32; X],
    /// [`super::bound_extra_k`] of each prior variance \[K\].
    extra_k: [f32; X],
    /// Information fused on each measured state against the prior (in
    /// the propagation under way, if any) \[1/K^2\].
    info: [f32; K],
    /// Information fused since the propagation under way began: carried
    /// to the next prior.
    info_late: [f32; K],
    /// `W` of all the information fused against the prior.
    weight: SMatrix<f32, K, K>,
    /// The prior's columns at the measured states after the information.
    frame_cols: SMatrix<f32, X, K>,
    /// What a correction fuses against ([`Self::correction`]): the gain,
    /// the innovation variances, `M H^T`, `S`, and `S^-1`'s rows summed
    /// per measured state.
    gain_all: SMatrix<f32, X, P>,
    innovation_var: SVector<f32, P>,
    prior_ht: SMatrix<f32, X, P>,
    innovation_cov: SMatrix<f32, P, P>,
    node_inverse: SMatrix<f32, K, P>,
    /// What waits for the information or the prior that changed, one
    /// slice each: 5 the weight, 4 the prior's columns after the
    /// information, 3 `M H^T` and `S`, 2 `S^-1`, 1 the gain, 0 nothing. A
    /// correction that finds them waiting makes them at once.
    stale: u8,
    /// `P[:, N] W` of the propagation under way.
    gain: SMatrix<f32, X, K>,
    phase: Phase,
    /// Model steps not yet propagated.
    steps: u32,
    /// Corrections the warm-up has left.
    corrections_left: u16,
    /// The propagation under way had information.
    had_info: bool,
    /// Every variance of its posterior within [`SETTLED_FRACTION`] of the
    /// steady posterior's so far.
    settled: bool,
    /// A recovery inflated the prior while the propagation ran: its result
    /// is inflated too.
    inflate: bool,
    /// A prior after information widened no watched bound by
    /// [`START_FORGOTTEN_K`] (and it stays so).
    forgotten: bool,
}

/// The lower Cholesky factor of the symmetric `s` (rows first), `None`
/// unless it is positive definite (NaN included).
fn cholesky<const P: usize>(s: &SMatrix<f32, P, P>) -> Option<[[f32; P]; P]> {
    let mut l = [[0.0f32; P]; P];
    for i in 0..P {
        for j in 0..=i {
            let mut v = s[(i, j)];
            for k in 0..j {
                v -= l[i][k] * l[j][k];
            }
            if i == j {
                if v.is_nan() || v <= 0.0 {
                    return None;
                }
                l[i][i] = libm::sqrtf(v);
            } else {
                l[i][j] = v / l[j][j];
            }
        }
    }
    Some(l)
}

/// `x` of `L L^T x = b` for the factor `l` of [`cholesky`].
fn cholesky_solve<const P: usize>(l: &[[f32; P]; P], b: [f32; P]) -> [f32; P] {
    let mut x = b;
    for i in 0..P {
        let mut v = x[i];
        for k in 0..i {
            v -= l[i][k] * x[k];
        }
        x[i] = v / l[i][i];
    }
    for i in (0..P).rev() {
        let mut v = x[i];
        for k in i + 1..P {
            v -= l[k][i] * x[k];
        }
        x[i] = v / l[i][i];
    }
    x
}

/// Slices of [`HeldCovariance::work`] one correction period takes, for
/// `x` states of which `t` have dynamics: the start, `x` columns, `t / 2`
/// row pairs, `x` mirrored columns, the finish, and the five refresh
/// slices after the new prior and after a correction.
pub(crate) const fn period_slices(x: usize, t: usize) -> u32 {
    (2 * x + t.div_ceil(2) + 2 + 2 * 5) as u32
}

/// Slices per light tick that propagate a period's covariance within half
/// a correction period: `period_slices` spread over half the
/// `light_ticks` a period leaves (at least one tick, at least one slice
/// each). A 1 kHz loop has hundreds of light ticks a period and takes one
/// slice each; a loop at the model's 100 ms step has about three, and
/// one slice each would leave the prior some ten periods behind the
/// readings (the gate then judges them against a stale covariance and
/// refuses healthy ones).
pub(crate) const fn slices_per_tick(period_slices: u32, light_ticks: u32) -> u32 {
    let ticks = if light_ticks / 2 > 1 {
        light_ticks / 2
    } else {
        1
    };
    period_slices.div_ceil(ticks)
}

/// Column `j` of a column-major `R x C` slice (`None` past the end).
fn column<const R: usize>(m: &[f32], j: usize) -> Option<&[f32]> {
    m.chunks_exact(R).nth(j)
}

impl<const X: usize, const K: usize, const P: usize> HeldCovariance<X, K, P> {
    /// Nothing held: the steady filter from the first tick.
    pub(crate) fn idle() -> Self {
        Self {
            layout: HeldLayout {
                measured: [0; K],
                sensors: [None; P],
                r: [0.0; P],
                steady_sigma: [0.0; X],
                k_sigma: 0.0,
                watched: [false; X],
            },
            active: false,
            cov: SMatrix::zeros(),
            cols: SMatrix::zeros(),
            prior_var: [0.0; X],
            extra_k: [0.0; X],
            info: [0.0; K],
            info_late: [0.0; K],
            weight: SMatrix::zeros(),
            frame_cols: SMatrix::zeros(),
            gain_all: SMatrix::zeros(),
            innovation_var: SVector::zeros(),
            prior_ht: SMatrix::zeros(),
            innovation_cov: SMatrix::zeros(),
            node_inverse: SMatrix::zeros(),
            stale: 0,
            gain: SMatrix::zeros(),
            phase: Phase::Ready,
            steps: 0,
            corrections_left: 0,
            had_info: false,
            settled: false,
            inflate: false,
            forgotten: false,
        }
    }

    /// Holds `cov` \[K^2, and the squares of the random walks' units\] as
    /// the prior of the first period, for the observer `layout`.
    pub(crate) fn start(cov: SMatrix<f32, X, X>, layout: HeldLayout<X, K, P>) -> Self {
        let mut held = Self {
            layout,
            active: true,
            cov,
            corrections_left: MAX_START_CORRECTIONS,
            ..Self::idle()
        };
        held.take_prior();
        while held.stale > 0 {
            held.refresh();
        }
        held
    }

    /// The warm-up runs.
    pub(crate) fn active(&self) -> bool {
        self.active
    }

    /// Ends the warm-up: the steady filter from now on.
    pub(crate) fn end(&mut self) {
        self.active = false;
    }

    /// A prior propagated from a posterior with information has widened
    /// no watched state's upper bound by [`START_FORGOTTEN_K`] or more:
    /// what the start guessed no longer shows in their bounds (other
    /// states may still be held). Once true, it stays true.
    pub(crate) fn forgotten(&self) -> bool {
        self.forgotten
    }

    /// How much wider than the steady one the upper bound of state `i` is
    /// \[K\] ([`super::bound_extra_k`] of the held prior; 0 when nothing is
    /// held).
    pub(crate) fn bound_extra_k(&self, i: usize) -> f32 {
        match self.extra_k.get(i) {
            Some(extra) if self.active => *extra,
            _ => 0.0,
        }
    }

    /// [`Self::bound_extra_k`] of every state, from the prior's diagonal.
    fn widen(&mut self) {
        let sigmas = self.layout.steady_sigma.iter();
        for ((extra, var), sigma) in self.extra_k.iter_mut().zip(&self.prior_var).zip(sigmas) {
            *extra = super::bound_extra_k(*var, *sigma, self.layout.k_sigma);
        }
    }

    /// What a correction fuses against (see [`Correction`]): made by the
    /// slices after the information or the prior changed; here only if
    /// none ran since (then this call does their work).
    pub(crate) fn correction(&mut self) -> Correction<'_, X, P> {
        while self.stale > 0 {
            self.refresh();
        }
        (
            &self.gain_all,
            &self.innovation_var,
            &self.prior_ht,
            &self.innovation_cov,
        )
    }

    /// One stage of what [`Self::correction`] needs (see `stale`): the
    /// weight of the information (a `K x K` Cholesky, `K` solves), the
    /// prior's columns after it (`X x K x K` multiply-adds), `M H^T` and
    /// `S`, `S^-1` (a `P x P` Cholesky, `P` solves), the gain
    /// `M H^T S^-1` through the measured states (`X x K x P`).
    fn refresh(&mut self) {
        match self.stale {
            1 => self.gain_all = self.frame_cols * self.node_inverse,
            2 => self.invert(),
            3 => self.innovations(),
            4 => {
                let a = self.block(&self.cols);
                // P+[:, N] = P[:, N] (I - W A).
                let z = SMatrix::<f32, K, K>::identity() - self.weight * a;
                self.frame_cols = self.cols * z;
            }
            _ => self.reweigh(),
        }
        self.stale = self.stale.saturating_sub(1);
    }

    /// `M H^T`, `S` and its diagonal of the prior after the information.
    fn innovations(&mut self) {
        let block = self.block(&self.frame_cols);
        let (sensors, r) = (&self.layout.sensors, &self.layout.r);
        let columns = self.prior_ht.as_mut_slice().chunks_exact_mut(X);
        for (j, ((k, rj), column)) in sensors.iter().zip(r).zip(columns).enumerate() {
            let source = k.and_then(|k| self.frame_cols.as_slice().chunks_exact(X).nth(k));
            match source {
                Some(source) => column.copy_from_slice(source),
                None => column.fill(0.0),
            }
            for (i, l) in sensors.iter().enumerate() {
                let v = match (k, l) {
                    (Some(k), Some(l)) => block.get((*l, *k)).copied().unwrap_or(0.0),
                    _ => 0.0,
                };
                let noise = if i == j { *rj } else { 0.0 };
                if let Some(slot) = self.innovation_cov.get_mut((i, j)) {
                    *slot = v + noise;
                }
            }
            if let (Some(slot), Some(v)) = (
                self.innovation_var.get_mut(j),
                self.innovation_cov.get((j, j)),
            ) {
                *slot = *v;
            }
        }
    }

    /// The rows of `S^-1` summed per measured state: `M H^T S^-1` is then
    /// the prior's columns after the information times them. One
    /// Cholesky factor, `P` pairs of triangular solves (zero if `S` is not
    /// positive definite: no correction, the safe side).
    fn invert(&mut self) {
        self.node_inverse = SMatrix::zeros();
        let Some(l) = cholesky(&self.innovation_cov) else {
            return;
        };
        for j in 0..P {
            let mut unit = [0.0f32; P];
            if let Some(u) = unit.get_mut(j) {
                *u = 1.0;
            }
            let x = cholesky_solve(&l, unit);
            for (v, k) in x.iter().zip(&self.layout.sensors) {
                if let Some(slot) = k.and_then(|k| self.node_inverse.get_mut((k, j))) {
                    *slot += v;
                }
            }
        }
    }

    /// The rows at the measured states of `cols` (`K x K`).
    fn block(&self, cols: &SMatrix<f32, X, K>) -> SMatrix<f32, K, K> {
        SMatrix::from_fn(|k, l| {
            self.layout
                .measured
                .get(k)
                .and_then(|i| cols.get((*i, l)))
                .copied()
                .unwrap_or(0.0)
        })
    }

    /// Counts one correction whose readings had `verdicts` (the fused
    /// ones' information, `sum 1 / r` \[1/K^2\] per measured state, is
    /// added) and, after a recovery, the inflation `recovery` of the
    /// prior's diagonal. The warm-up ends after [`MAX_START_CORRECTIONS`].
    pub(crate) fn corrected(
        &mut self,
        verdicts: &[SensorVerdict; P],
        recovery: Option<&SVector<f32, X>>,
    ) {
        let mine = if self.phase == Phase::Ready {
            &mut self.info
        } else {
            &mut self.info_late
        };
        let fused = verdicts
            .iter()
            .zip(&self.layout.sensors)
            .zip(&self.layout.r);
        for ((verdict, k), r) in fused {
            let added = 1.0 / r;
            if let (true, true, Some(total)) = (
                verdict.is_fused(),
                added.is_finite() && added > 0.0,
                k.and_then(|k| mine.get_mut(k)),
            ) {
                *total += added;
            }
        }
        if let Some(d) = recovery {
            for (k, i) in self.layout.measured.iter().enumerate() {
                if let (Some(slot), Some(add)) = (self.cols.get_mut((*i, k)), d.get(*i)) {
                    *slot += add;
                }
            }
            for (v, add) in self.prior_var.iter_mut().zip(d.iter()) {
                *v += add;
            }
            self.widen();
            if self.phase == Phase::Ready {
                for (i, add) in d.iter().enumerate() {
                    if let Some(slot) = self.cov.get_mut((i, i)) {
                        *slot += add;
                    }
                }
            } else {
                self.inflate = true;
            }
        }
        self.stale = 5;
        self.corrections_left = self.corrections_left.saturating_sub(1);
        if self.corrections_left == 0 {
            self.active = false;
        }
    }

    /// `W` of all the information fused against the prior (zero if its
    /// solve fails: no information, the safe side).
    fn reweigh(&mut self) {
        let a = self.block(&self.cols);
        let mut root = [0.0f32; K];
        for (r, (info, late)) in root.iter_mut().zip(self.info.iter().zip(&self.info_late)) {
            let total = info + late;
            *r = if total.is_finite() && total > 0.0 {
                libm::sqrtf(total)
            } else {
                0.0
            };
        }
        // B = I + S A S, symmetric positive definite; W = S B^-1 S.
        let b = SMatrix::<f32, K, K>::from_fn(|k, l| {
            let delta = if k == l { 1.0 } else { 0.0 };
            let at = |m: usize| root.get(m).copied().unwrap_or(0.0);
            delta + at(k) * a.get((k, l)).copied().unwrap_or(0.0) * at(l)
        });
        let mut weight = SMatrix::<f32, K, K>::zeros();
        let Some(factor) = cholesky(&b) else {
            self.weight = weight;
            return;
        };
        for (l, root_l) in root.iter().enumerate() {
            if *root_l == 0.0 {
                continue;
            }
            let mut unit = [0.0f32; K];
            if let Some(u) = unit.get_mut(l) {
                *u = *root_l;
            }
            let column = cholesky_solve(&factor, unit);
            for (k, v) in column.iter().enumerate() {
                if let (Some(slot), Some(root_k)) = (weight.get_mut((k, l)), root.get(k)) {
                    *slot = root_k * v;
                }
            }
        }
        self.weight = weight.symmetric_part();
    }

    /// Up to `slices` slices of [`Self::work`] in a row, fewer when the
    /// propagation is done or waits for its period's model steps: a loop
    /// whose light ticks are too few for one slice each (see
    /// [`slices_per_tick`]). `Some(settled)` as [`Self::work`] when a new
    /// prior is ready (the slices stop there).
    pub(crate) fn work_slices<const T: usize, const G: usize>(
        &mut self,
        slices: u32,
        propagation: &Propagation<'_, T, G, X>,
    ) -> Option<bool> {
        let mut done = self.work(propagation);
        let mut left = slices.saturating_sub(1);
        while done.is_none() && left > 0 && !self.waiting(propagation.period) {
            done = self.work(propagation);
            left -= 1;
        }
        done
    }

    /// Nothing to slice until the period's model steps are in.
    fn waiting(&self, period: u32) -> bool {
        self.stale == 0 && self.phase == Phase::Ready && self.steps < period.max(1)
    }

    /// Adds `steps` model steps to the time not yet propagated.
    pub(crate) fn stepped(&mut self, steps: u32) {
        self.steps = self.steps.saturating_add(steps);
    }

    /// One slice of the propagation (call it on light ticks) with what
    /// `propagation` holds. `Some(settled)` when a new prior is
    /// ready: `settled` when the posterior it came from had information
    /// and every variance within [`SETTLED_FRACTION`] of the steady
    /// posterior's (the warm-up may end). At most `(T + 1) X + K X`
    /// multiply-adds a slice: `X` columns, `T / 2` row pairs, `X` mirrored
    /// columns, the refresh of the weight and the frame after a
    /// correction or a new prior, about `2 X + T / 2 + 4` slices a
    /// period.
    pub(crate) fn work<const T: usize, const G: usize>(
        &mut self,
        propagation: &Propagation<'_, T, G, X>,
    ) -> Option<bool> {
        let Propagation {
            period,
            ref transition,
            steady_prior,
            steady_posterior,
            recovery,
        } = *propagation;
        if self.stale > 0 {
            self.refresh();
            return None;
        }
        match self.phase {
            Phase::Ready => {
                let period = period.max(1);
                if self.steps >= period {
                    // At most one more period owed: a loop too slow for
                    // the slices propagates less often (see the docs).
                    self.steps = (self.steps - period).min(period);
                    self.gain = self.cols * self.weight;
                    self.had_info = self.info.iter().any(|i| *i > 0.0);
                    self.settled = true;
                    self.phase = Phase::Columns(0);
                }
                None
            }
            Phase::Columns(j) => {
                let j = usize::from(j);
                self.column_slice(j, transition, steady_posterior);
                self.phase = Phase::after(j, X, Phase::Columns, Phase::Rows(0));
                None
            }
            Phase::Rows(p) => {
                let p = usize::from(p);
                self.row_slice(p, transition);
                if let Some(other) = T.checked_sub(p + 1).filter(|o| *o > p) {
                    self.row_slice(other, transition);
                }
                self.phase = Phase::after(p, T.div_ceil(2), Phase::Rows, Phase::Mirror(0));
                None
            }
            Phase::Mirror(j) => {
                let j = usize::from(j);
                self.mirror_slice::<T>(j, steady_prior, recovery);
                self.phase = Phase::after(j, X, Phase::Mirror, Phase::Finish);
                None
            }
            Phase::Finish => {
                self.finish();
                let widened = (0..X).any(|i| {
                    self.layout.watched.get(i).copied().unwrap_or(false)
                        && self.bound_extra_k(i) >= START_FORGOTTEN_K
                });
                self.forgotten |= self.had_info && !widened;
                Some(self.had_info && self.settled)
            }
        }
    }

    /// Column `j` of `F (P+ - P_ss)` in place of the prior's column `j`.
    fn column_slice<const T: usize, const G: usize>(
        &mut self,
        j: usize,
        transition: &PeriodTransition<'_, T, G>,
        steady_posterior: &SMatrix<f32, X, X>,
    ) {
        // P[N, j] = P[j, N]: row `j` of the columns kept aside.
        let row: [f32; K] = core::array::from_fn(|k| self.cols.get((j, k)).copied().unwrap_or(0.0));
        let Some(post) = column::<X>(steady_posterior.as_slice(), j) else {
            return;
        };
        let Some(col) = self.cov.as_mut_slice().chunks_exact_mut(X).nth(j) else {
            return;
        };
        // D[:, j] = P[:, j] - G P[N, j] - P_ss[:, j].
        let mut d = [0.0f32; X];
        for (i, ((d, p), s)) in d.iter_mut().zip(col.iter()).zip(post).enumerate() {
            let mut v = *p - *s;
            for (k, r) in row.iter().enumerate() {
                v -= self.gain.get((i, k)).copied().unwrap_or(0.0) * r;
            }
            *d = v;
        }
        let limit = SETTLED_FRACTION * post.get(j).copied().unwrap_or(0.0);
        let dj = d.get(j).copied().unwrap_or(f32::NAN);
        if dj.is_nan() || dj > limit {
            self.settled = false;
        }
        // Y[:, j] = F D[:, j]: the dynamic rows, the walks' rows as they are.
        let mut y = [0.0f32; T];
        for (acc, v) in y.iter_mut().zip(&d) {
            *acc = *v;
        }
        for (phi_col, v) in transition.phi_minus_i.as_slice().chunks_exact(T).zip(&d) {
            for (acc, m) in y.iter_mut().zip(phi_col) {
                *acc += *m * *v;
            }
        }
        let walks = d.iter().skip(T);
        for (gamma_col, v) in transition.gamma.as_slice().chunks_exact(T).zip(walks) {
            for (acc, m) in y.iter_mut().zip(gamma_col) {
                *acc += *m * *v;
            }
        }
        for (c, v) in col
            .iter_mut()
            .zip(d.iter().enumerate().map(|(i, d)| y.get(i).unwrap_or(d)))
        {
            *c = *v;
        }
    }

    /// Row `i < T` of the lower triangle of `Y F^T`, `Y = F (P+ - P_ss)`
    /// held in the buffer: entries `0..=i`.
    fn row_slice<const T: usize, const G: usize>(
        &mut self,
        i: usize,
        transition: &PeriodTransition<'_, T, G>,
    ) {
        let data = self.cov.as_mut_slice();
        let y: [f32; X] = core::array::from_fn(|k| data.get(k * X + i).copied().unwrap_or(0.0));
        // (Y F^T)[i, j] = y[j] + sum_k Phi'[j, k] y[k] + sum_m Gamma[j, m] y[T + m].
        let mut acc = [0.0f32; T];
        for (a, v) in acc.iter_mut().zip(&y).take(i + 1) {
            *a = *v;
        }
        for (phi_col, v) in transition.phi_minus_i.as_slice().chunks_exact(T).zip(&y) {
            for (a, m) in acc.iter_mut().zip(phi_col).take(i + 1) {
                *a += *m * *v;
            }
        }
        let walks = y.iter().skip(T);
        for (gamma_col, v) in transition.gamma.as_slice().chunks_exact(T).zip(walks) {
            for (a, m) in acc.iter_mut().zip(gamma_col).take(i + 1) {
                *a += *m * *v;
            }
        }
        for (j, v) in acc.iter().enumerate().take(i + 1) {
            if let Some(slot) = data.get_mut(j * X + i) {
                *slot = *v;
            }
        }
    }

    /// Column `j`'s lower triangle mirrored (the walks' rows from `Y`'s
    /// upper part) and `M` added, with the recovery's inflation on the
    /// diagonal if one is pending. Each column's pairs are its own: no
    /// slice reads what another wrote.
    fn mirror_slice<const T: usize>(
        &mut self,
        j: usize,
        steady_prior: &SMatrix<f32, X, X>,
        recovery: &SVector<f32, X>,
    ) {
        let m = steady_prior.as_slice();
        let data = self.cov.as_mut_slice();
        for i in j + 1..X {
            // Entry (i, j) below the diagonal, (j, i) above it.
            let (low, up) = (j * X + i, i * X + j);
            let (Some(l), Some(u)) = (data.get(low).copied(), data.get(up).copied()) else {
                continue;
            };
            let v = if i < T {
                l
            } else if j < T {
                u
            } else {
                0.5 * (l + u)
            };
            if let (Some(slot), Some(add)) = (data.get_mut(low), m.get(low)) {
                *slot = v + add;
            }
            if let (Some(slot), Some(add)) = (data.get_mut(up), m.get(up)) {
                *slot = v + add;
            }
        }
        let diagonal = j * X + j;
        let inflation = if self.inflate {
            recovery.get(j).copied().unwrap_or(0.0)
        } else {
            0.0
        };
        if let (Some(slot), Some(add)) = (data.get_mut(diagonal), m.get(diagonal)) {
            *slot += add + inflation;
        }
    }

    /// The next prior taken, its information carried.
    fn finish(&mut self) {
        self.inflate = false;
        self.info = self.info_late;
        self.info_late = [0.0; K];
        self.take_prior();
        self.phase = Phase::Ready;
    }

    /// The buffer as the prior: its diagonal and measured columns kept
    /// aside (the weight and the frame for the next slice).
    fn take_prior(&mut self) {
        for (i, v) in self.prior_var.iter_mut().enumerate() {
            let d = self.cov.get((i, i)).copied().unwrap_or(f32::NAN);
            // A variance is not negative (rounding); NaN stays NaN.
            *v = if d < 0.0 { 0.0 } else { d };
        }
        self.widen();
        for (k, i) in self.layout.measured.iter().enumerate() {
            for r in 0..X {
                if let (Some(slot), Some(v)) = (self.cols.get_mut((r, k)), self.cov.get((r, *i))) {
                    *slot = *v;
                }
            }
        }
        self.stale = 5;
    }

    /// The prior held (tests).
    #[cfg(test)]
    pub(crate) fn prior(&self) -> Option<&SMatrix<f32, X, X>> {
        (self.phase == Phase::Ready).then_some(&self.cov)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::{update, KalmanConfig, KalmanState, SteadyStateGain};
    use nalgebra::{Const, Matrix1, SMatrix, SVector, U1};

    type Cfg = KalmanConfig<f64, Const<3>, U1, U1>;

    const FUSED: [SensorVerdict; 1] = [SensorVerdict::Fused { nis: 0.0 }];

    fn layout(steady: &SteadyStateGain<f32, Const<3>, U1>) -> HeldLayout<3, 1, 1> {
        HeldLayout {
            measured: [0],
            sensors: [Some(0)],
            r: [0.04],
            steady_sigma: core::array::from_fn(|i| steady.prior()[(i, i)].sqrt()),
            k_sigma: 3.0,
            watched: [true; 3],
        }
    }

    /// One correction period of a two-node chain (state 1) whose first node
    /// is read, with a heat-bias random walk (state 2) entering it.
    fn period_model() -> Cfg {
        let f = SMatrix::<f64, 3, 3>::new(
            0.90, 0.05, 0.10, //
            0.02, 0.95, 0.00, //
            0.00, 0.00, 1.00,
        );
        let q = SMatrix::<f64, 3, 3>::from_diagonal(&SVector::from([0.01, 0.01, 0.001]));
        let h = SMatrix::<f64, 1, 3>::new(1.0, 0.0, 0.0);
        Cfg::new(f, SMatrix::zeros(), h, q, Matrix1::new(0.04)).unwrap()
    }

    /// Runs `periods` periods of one reading each from `p0`, held and in
    /// `f64`, and returns the largest relative difference of the priors'
    /// variances and the period (1-based) at which the held one settled.
    fn held_against_exact(p0: SMatrix<f64, 3, 3>, periods: u32) -> (f64, Option<u32>) {
        let cfg = period_model();
        let steady = SteadyStateGain::solve(&cfg, 1).unwrap().cast::<f32>();
        let phi_minus_i: SMatrix<f32, 2, 2> =
            (cfg.f().fixed_view::<2, 2>(0, 0) - SMatrix::<f64, 2, 2>::identity()).cast();
        let gamma: SMatrix<f32, 2, 1> = cfg.f().fixed_view::<2, 1>(0, 2).into_owned().cast();
        let transition = PeriodTransition {
            phi_minus_i: &phi_minus_i,
            gamma: &gamma,
        };
        let mut held = HeldCovariance::<3, 1, 1>::start(p0.cast(), layout(&steady));
        let mut exact = KalmanState::<f64, Const<3>, U1>::new(SVector::zeros(), p0);
        let (mut worst, mut settled) = (0.0f64, None);
        let recovery = SVector::<f32, 3>::zeros();
        for period in 1..=periods {
            held.corrected(&FUSED, None);
            exact.x = SVector::zeros();
            update(&cfg, &mut exact, &[Some(0.0)]);
            let mut next = *cfg.q();
            next.quadform_tr(1.0, cfg.f(), &exact.cov, 1.0);
            exact.cov = next;
            held.stepped(1);
            let mut done = None;
            while done.is_none() {
                done = held.work(&Propagation {
                    period: 1,
                    transition,
                    steady_prior: steady.prior(),
                    steady_posterior: steady.posterior(),
                    recovery: &recovery,
                });
            }
            if done == Some(true) && settled.is_none() {
                settled = Some(period);
            }
            let prior = held.prior().unwrap();
            for i in 0..3 {
                let rel = f64::from(prior[(i, i)]) / exact.cov[(i, i)] - 1.0;
                worst = worst.max(rel.abs());
            }
            assert_eq!(*prior, prior.transpose());
        }
        (worst, settled)
    }

    #[test]
    fn the_held_prior_is_the_riccati_recursion_and_settles() {
        let cfg = period_model();
        let m = *SteadyStateGain::solve(&cfg, 1).unwrap().prior();
        // The unread node and the walk start far wider than the steady.
        let mut p0 = m;
        p0[(1, 1)] += 400.0;
        p0[(2, 2)] += 4.0;
        let (worst, settled) = held_against_exact(p0, 300);
        assert!(worst < 1e-3, "{worst}");
        let settled = settled.expect("settles");
        assert!(settled > 5, "{settled}");
        // From the steady prior itself: settled at the first period.
        let (worst, settled) = held_against_exact(m, 3);
        assert!(worst < 1e-4, "{worst}");
        assert_eq!(settled, Some(1));
    }

    #[test]
    fn readings_fused_on_their_own_are_the_batch_update() {
        // Two readings of the measured state in one period, fused one at a
        // time, give the frame of both at once (the information adds).
        let cfg = period_model();
        let mut p0 = *SteadyStateGain::solve(&cfg, 1).unwrap().prior();
        p0[(1, 1)] += 9.0;
        let steady = SteadyStateGain::solve(&cfg, 1).unwrap().cast::<f32>();
        let mut held = HeldCovariance::<3, 1, 1>::start(p0.cast(), layout(&steady));
        held.corrected(&FUSED, None);
        held.corrected(&FUSED, None);
        let (_, innovation_var, cols, _) = held.correction();
        // Exact: one reading of variance 0.02.
        let mut exact = KalmanState::<f64, Const<3>, U1>::new(SVector::zeros(), p0);
        let twice = Cfg::new(
            *cfg.f(),
            SMatrix::zeros(),
            cfg.h(),
            *cfg.q(),
            Matrix1::new(0.02),
        )
        .unwrap();
        update(&twice, &mut exact, &[Some(0.0)]);
        for i in 0..3 {
            let rel = f64::from(cols[(i, 0)]) / exact.cov[(i, 0)] - 1.0;
            assert!(rel.abs() < 1e-5, "{i}: {rel}");
        }
        let s = exact.cov[(0, 0)] + 0.04;
        assert!((f64::from(innovation_var[0]) / s - 1.0).abs() < 1e-5);
    }
}
