//! The time-varying filter: configuration, per-device state, predict and the
//! sequential Joseph-form correction.

use nalgebra::allocator::Allocator;
use nalgebra::{Cholesky, Const, DefaultAllocator, Dim, DimName, OMatrix, OVector, RealField, U1};

use super::gate::{
    gate_all, usable, GateCounters, GatePolicy, SensorVerdict, UpdateReport, CHI2_1DOF_999,
};
use super::{FilterAllocator, SensorAllocator};
use crate::error::BuildError;
use crate::sizes::Length;

/// The discrete model and noise, validated once and shared by every device
/// that uses it (N states, M inputs, P sensors, each a nalgebra dimension:
/// `Const<N>` on an MCU, `Dyn` on a host with the `alloc` feature).
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanConfig<T: RealField + Copy, N: Length, M: Dim, P: Length>
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    pub(crate) f: OMatrix<T, N, N>,
    pub(crate) g: OMatrix<T, N, M>,
    /// `H^T`: column `j` is sensor `j`'s row of `H`, contiguous in memory.
    pub(crate) ht: OMatrix<T, N, P>,
    pub(crate) q: OMatrix<T, N, N>,
    pub(crate) r: OVector<T, P>,
    pub(crate) gate: GatePolicy<T>,
    /// Variances added to the diagonal of `P` on recovery.
    pub(crate) recovery_variance: OVector<T, N>,
    /// First of the trailing states whose row of `F` is a unit row (random
    /// walks, such as bias states): `N` when there are none.
    pub(crate) walk_from: usize,
    /// The states each sensor's row of `H` reads: derived from `ht` by
    /// every constructor (nothing changes `ht` after).
    pub(crate) reads: P::Array<Reads<N>>,
}

/// The states one sensor's row of `H` reads: the indices of its entries
/// that are not zero, ascending. A thermocouple reads one node (and a
/// boundary offset), so the correction's `H x` takes those terms alone: the
/// rest are multiply-adds by zero, one instruction each on an FPU but a
/// soft-float pair on a core without one (the real motor's reading tick on
/// a Cortex-M0: 14 states, one or two read).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Reads<N: Length> {
    states: N::Array<u16>,
    count: u16,
}

impl<N: Length> Copy for Reads<N> where N::Array<u16>: Copy {}

impl<const N: usize> Reads<Const<N>> {
    /// Nothing read (and a filter's state indices fit the `u16`s).
    const NONE: Self = {
        assert!(N <= 1 << 16, "at most 65 536 filter states");
        Self {
            states: [0; N],
            count: 0,
        }
    };

    /// These states and `state` after them (at most `N`).
    const fn push(mut self, state: usize) -> Self {
        if (self.count as usize) < N {
            self.states[self.count as usize] = state as u16;
            self.count += 1;
        }
        self
    }

    /// Sensor `j`'s reads from the rows of `H^T` (the tables' layout).
    const fn of_rows<const P: usize>(ht: &[[f32; P]; N], j: usize) -> Self {
        let mut reads = Self::NONE;
        let mut i = 0;
        while i < N {
            if ht[i][j] != 0.0 {
                reads = reads.push(i);
            }
            i += 1;
        }
        reads
    }
}

impl<N: Length> Reads<N> {
    /// Sensor `j`'s reads from `H^T` (a filter's state indices fit the
    /// `u16`s: a state beyond is not read, and the build refuses it).
    fn of<T: RealField + Copy, P: Dim>(ht: &OMatrix<T, N, P>, j: usize) -> Self
    where
        DefaultAllocator: Allocator<N, P>,
    {
        let mut reads = Self {
            states: ht.shape_generic().0.filled(0),
            count: 0,
        };
        for (i, h) in ht.column(j).iter().enumerate() {
            if *h != T::zero() {
                if let Some(slot) = reads.states.as_mut().get_mut(usize::from(reads.count)) {
                    *slot = i as u16;
                    reads.count += 1;
                }
            }
        }
        reads
    }

    /// `h . x` for sensor `j`'s column `h` of `H^T`, over the states read.
    /// For a finite `x` and at most two states read (a thermocouple reads
    /// its node, and a boundary offset) it is the dense dot product's value
    /// to the bit (a zero may differ in sign only: nalgebra's sum begins at
    /// its first term, this one at `+0`); with more, the same terms summed
    /// in another order.
    #[inline]
    pub(crate) fn dot<T: RealField + Copy, P: Dim>(
        &self,
        ht: &OMatrix<T, N, P>,
        j: usize,
        x: &OVector<T, N>,
    ) -> T
    where
        DefaultAllocator: Allocator<N, P> + Allocator<N>,
    {
        let n = ht.nrows();
        let Some(h) = ht.as_slice().get(j * n..(j + 1) * n) else {
            return T::zero();
        };
        let mut sum = T::zero();
        for &i in self.states.as_ref().iter().take(self.count as usize) {
            if let (Some(h), Some(x)) = (h.get(i as usize), x.get(i as usize)) {
                sum += *h * *x;
            }
        }
        sum
    }
}

/// Every sensor's [`Reads`] from the rows of `H^T` (the tables' layout),
/// in a `const fn`.
pub(crate) const fn reads_of_rows<const N: usize, const P: usize>(
    ht: &[[f32; P]; N],
) -> [Reads<Const<N>>; P] {
    let mut reads = [Reads::NONE; P];
    let mut j = 0;
    while j < P {
        reads[j] = Reads::of_rows(ht, j);
        j += 1;
    }
    reads
}

/// Every sensor's [`Reads`] from `H^T`.
fn reads_of<T: RealField + Copy, N: Length, P: Length>(ht: &OMatrix<T, N, P>) -> P::Array<Reads<N>>
where
    DefaultAllocator: Allocator<N, P>,
{
    ht.shape_generic().1.each(|j| Reads::of(ht, j))
}

/// Input handling of one predict step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InputStatus {
    /// All inputs were finite and used.
    Used,
    /// Some input was NaN or infinite: the input term `G u` was dropped for
    /// this step (`x = F x`) so the estimate is not poisoned.
    Dropped,
    /// Some input was out of its plausible range and was clamped to it
    /// (the input rules of [`crate::input`]); the clamped value was used.
    Clamped,
}

/// Per-device filter state: the estimate, its covariance and the gate memory.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone, PartialEq)]
pub struct KalmanState<T: RealField + Copy, N: Dim, P: Length>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// State estimate `x`.
    pub x: OVector<T, N>,
    /// Estimate covariance `P` (symmetric positive semi-definite).
    pub cov: OMatrix<T, N, N>,
    /// Rejection counters.
    pub gate: GateCounters<P>,
}

impl<T: RealField + Copy, N: Dim, P: Length> Copy for KalmanState<T, N, P>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
    OVector<T, N>: Copy,
    OMatrix<T, N, N>: Copy,
    GateCounters<P>: Copy,
{
}

impl<T: RealField + Copy, N: Dim, P: Length> KalmanState<T, N, P>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    /// A state with estimate `x0` and covariance `p0` (the caller's prior),
    /// for `sensors` sensors.
    pub fn for_sensors(x0: OVector<T, N>, p0: OMatrix<T, N, N>, sensors: P) -> Self {
        Self {
            x: x0,
            cov: p0,
            gate: GateCounters::new(sensors),
        }
    }

    /// A state with estimate `x0` and covariance `p0` (the caller's prior),
    /// for a number of sensors known when compiling.
    pub fn new(x0: OVector<T, N>, p0: OMatrix<T, N, N>) -> Self
    where
        P: DimName,
    {
        Self::for_sensors(x0, p0, P::name())
    }
}

fn all_finite<T: RealField + Copy, R: Dim, C: Dim>(m: &OMatrix<T, R, C>) -> bool
where
    DefaultAllocator: Allocator<R, C>,
{
    m.iter().all(|v| v.is_finite())
}

/// `m += diag(v)`.
pub(crate) fn add_diagonal<T: RealField + Copy, N: Dim>(m: &mut OMatrix<T, N, N>, v: &OVector<T, N>)
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    for (i, vi) in v.iter().enumerate() {
        m[(i, i)] += *vi;
    }
}

/// Largest absolute entry (0 for an empty matrix).
pub(crate) fn max_abs<T: RealField + Copy, R: Dim, C: Dim>(m: &OMatrix<T, R, C>) -> T
where
    DefaultAllocator: Allocator<R, C>,
{
    m.iter().fold(T::zero(), |acc, v| acc.max(v.abs()))
}

/// Checks that `q` is finite, symmetric to rounding and positive semi-definite
/// (to rounding), and returns its exactly symmetric part.
pub(crate) fn validate_psd<T: RealField + Copy, N: Dim>(
    q: &OMatrix<T, N, N>,
    name: &'static str,
) -> Result<OMatrix<T, N, N>, BuildError>
where
    DefaultAllocator: Allocator<N, N>,
{
    if !all_finite(q) {
        return Err(BuildError::InvalidParameter { name });
    }
    let scale = max_abs(q);
    let eps = T::default_epsilon();
    // Matrices computed by a discretisation are symmetric only to rounding.
    let sym_tol = eps.sqrt() * scale;
    let t = q.transpose();
    if q.iter()
        .zip(t.iter())
        .any(|(a, b)| (*a - *b).abs() > sym_tol)
    {
        return Err(BuildError::InvalidParameter { name });
    }
    let sym = q.symmetric_part();
    // A semi-definite matrix plus a small ridge is definite; an indefinite one
    // (an eigenvalue below -ridge) is not.
    if scale == T::zero() {
        return Ok(sym);
    }
    let (rows, columns) = q.shape_generic();
    let n: T = nalgebra::convert(q.nrows() as f64);
    let ridge = eps * n * nalgebra::convert(64.0) * scale;
    let ridged = sym.clone() + OMatrix::<T, N, N>::identity_generic(rows, columns) * ridge;
    if Cholesky::new(ridged).is_none() {
        return Err(BuildError::InvalidParameter { name });
    }
    Ok(sym)
}

impl<T: RealField + Copy, N: Length, M: Dim, P: Length> KalmanConfig<T, N, M, P>
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    /// Validates and builds the configuration.
    ///
    /// * `f`: state transition `F` (N x N), one predict step.
    /// * `g`: input matrix `G` (N x M); the caller folds powers, ambient and
    ///   constant terms into `u`.
    /// * `h`: measurement matrix `H` (P x N), one row per sensor.
    /// * `q`: process noise covariance `Q` per step (N x N), symmetric PSD.
    /// * `r`: measurement noise variance of each sensor (> 0, units of the
    ///   reading squared).
    ///
    /// Defaults: gate threshold [`CHI2_1DOF_999`], suspect after 3 consecutive
    /// rejections, recovery after 5 all-rejected corrections adding
    /// `1e4 * max(r)` to every diagonal entry of `P` (a 100-sigma widening for
    /// states in the units of the readings; see [`Self::with_recovery`]).
    ///
    /// A filter needs states and sensors: `N = 0` is refused as a bad `f`,
    /// `P = 0` as a bad `h`, and so are mismatched shapes (a run-time size).
    pub fn new(
        f: OMatrix<T, N, N>,
        g: OMatrix<T, N, M>,
        h: OMatrix<T, P, N>,
        q: OMatrix<T, N, N>,
        r: OVector<T, P>,
    ) -> Result<Self, BuildError> {
        let (n, p) = (f.nrows(), h.nrows());
        // A state index must fit the `u16` of a sensor's `Reads`.
        if n == 0 || n > 1 << 16 || f.ncols() != n || g.nrows() != n || q.shape() != (n, n) {
            return Err(BuildError::InvalidParameter { name: "f" });
        }
        if p == 0 || h.ncols() != n || r.nrows() != p {
            return Err(BuildError::InvalidParameter { name: "h" });
        }
        if !all_finite(&f) {
            return Err(BuildError::InvalidParameter { name: "f" });
        }
        if !all_finite(&g) {
            return Err(BuildError::InvalidParameter { name: "g" });
        }
        if !all_finite(&h) {
            return Err(BuildError::InvalidParameter { name: "h" });
        }
        let q = validate_psd(&q, "q")?;
        if r.iter().any(|v| !v.is_finite() || *v <= T::zero()) {
            return Err(BuildError::InvalidParameter { name: "r" });
        }
        let r_max = r.iter().fold(T::zero(), |a, v| a.max(*v));
        let unit_row =
            |i: usize| (0..n).all(|k| f[(i, k)] == if k == i { T::one() } else { T::zero() });
        let walk_from = (0..n).rev().take_while(|i| unit_row(*i)).fold(n, |_, i| i);
        let ht = h.transpose();
        let recovery_variance =
            OVector::repeat_generic(f.shape_generic().0, U1, r_max * nalgebra::convert(1e4));
        Ok(Self {
            f,
            g,
            reads: reads_of(&ht),
            ht,
            q,
            r,
            gate: GatePolicy {
                threshold: nalgebra::convert(CHI2_1DOF_999),
                suspect_after: 3,
                recover_after: 5,
            },
            recovery_variance,
            walk_from,
        })
    }

    /// Sets the gate threshold on `nu^2 / S` (> 0; `+inf` disables the gate).
    pub fn with_gate(mut self, threshold: T) -> Result<Self, BuildError> {
        if threshold.partial_cmp(&T::zero()) != Some(core::cmp::Ordering::Greater) {
            return Err(BuildError::InvalidParameter { name: "threshold" });
        }
        self.gate.threshold = threshold;
        Ok(self)
    }

    /// Flags a sensor suspect after `count` consecutive rejections (0: never).
    pub fn with_suspect_after(mut self, count: u16) -> Self {
        self.gate.suspect_after = count;
        self
    }

    /// Recovery policy: after `after` consecutive corrections in which every
    /// present reading was rejected (0: never), add `variance` (finite, >= 0,
    /// units of each state squared) to the diagonal of `P` and re-gate.
    pub fn with_recovery(
        mut self,
        after: u16,
        variance: OVector<T, N>,
    ) -> Result<Self, BuildError> {
        if variance.nrows() != self.f.nrows()
            || variance.iter().any(|v| !v.is_finite() || *v < T::zero())
        {
            return Err(BuildError::InvalidParameter { name: "variance" });
        }
        self.gate.recover_after = after;
        self.recovery_variance = variance;
        Ok(self)
    }

    /// State transition `F`.
    pub fn f(&self) -> &OMatrix<T, N, N> {
        &self.f
    }

    /// Input matrix `G`.
    pub fn g(&self) -> &OMatrix<T, N, M> {
        &self.g
    }

    /// Measurement matrix `H` (P x N).
    pub fn h(&self) -> OMatrix<T, P, N> {
        self.ht.transpose()
    }

    /// Process noise `Q` (exactly symmetric).
    pub fn q(&self) -> &OMatrix<T, N, N> {
        &self.q
    }

    /// Measurement noise variances `r`.
    pub fn r(&self) -> &OVector<T, P> {
        &self.r
    }

    /// Replaces sensor `sensor`'s noise variance (units of the reading
    /// squared, finite and > 0) between corrections: for a sensor whose
    /// noise is learned at run time (a converter that turns out noisier
    /// than its data sheet). Refused, and nothing changed, for a sensor
    /// index out of range or a variance that is not finite and positive.
    /// The recovery variance set at build stays as it is.
    pub fn set_measurement_variance(
        &mut self,
        sensor: usize,
        variance: T,
    ) -> Result<(), BuildError> {
        if !(variance.is_finite() && variance > T::zero()) {
            return Err(BuildError::InvalidParameter { name: "variance" });
        }
        let slot = self
            .r
            .get_mut(sensor)
            .ok_or(BuildError::InvalidParameter { name: "sensor" })?;
        *slot = variance;
        Ok(())
    }

    /// Gate and recovery settings.
    pub fn gate(&self) -> &GatePolicy<T> {
        &self.gate
    }
}

/// Mean-only predict: `x = F x + G u`. The per-tick path of the steady-state
/// filter (N^2 + N M multiply-adds). Non-finite inputs drop the `G u` term.
///
/// In `f32` on absolute temperatures at a 1 ms step this rounds away much of
/// every increment and drifts (2.6 K in 2 h at 8 A on a 3-node network);
/// it keeps no residual because its `F` is any model's and its `x` has no
/// room for one. A thermal observer in `f32` should predict deviations with
/// the rounding carried, as
/// [`NetworkObserver`](crate::observer::NetworkObserver) does (within
/// 1e-5 K of `f64` there), or run this in `f64`.
pub fn predict_mean<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    x: &mut OVector<T, N>,
    u: &OVector<T, M>,
) -> InputStatus
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    let prev = x.clone();
    x.gemv(T::one(), &cfg.f, &prev, T::zero());
    if u.iter().all(|v| v.is_finite()) {
        x.gemv(T::one(), &cfg.g, u, T::one());
        InputStatus::Used
    } else {
        InputStatus::Dropped
    }
}

/// Full predict: `x = F x + G u`, `P = F P F^T + Q`, exactly symmetric.
/// When `F` ends in a block of random-walk states (unit rows, found at build
/// time), that block and the symmetry of `P` are exploited: about 40 % fewer
/// multiply-adds for the Omnimagnet's 16 + 3 states, same result to
/// rounding; otherwise the plain product.
pub fn predict<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    state: &mut KalmanState<T, N, P>,
    u: &OVector<T, M>,
) -> InputStatus
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    let status = predict_mean(cfg, &mut state.x, u);
    predict_cov(cfg, &mut state.cov);
    status
}

/// The covariance half of [`predict`]: `P = F P F^T + Q`, exactly
/// symmetric (for a caller that runs its own mean predict, as the network
/// observer's time-varying warm-up does).
pub(crate) fn predict_cov<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    cov: &mut OMatrix<T, N, N>,
) where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    if cfg.walk_from < cov.nrows() {
        propagate_cov(&cfg.f, &cfg.q, cfg.walk_from, cov);
    } else {
        // Without random walks the plain product, so that models without
        // them keep their results bit for bit.
        let prev = cov.clone();
        cov.copy_from(&cfg.q);
        cov.quadform_tr(T::one(), &cfg.f, &prev, T::one());
        *cov = cov.symmetric_part();
    }
}

/// Rows per register block of [`propagate_cov`].
const BLOCK: usize = 8;

/// `sum_k m[start..start + BLOCK, k] w_k` for the column-major `m` with
/// `rows` rows (rows past the end of a column count as zero): a fixed-size
/// accumulator the compiler keeps in registers. Inlined, so that a
/// constant `rows` (a size known when compiling) stays one.
#[inline(always)]
fn block_combination<T: RealField + Copy>(
    m: &[T],
    rows: usize,
    start: usize,
    weights: impl Iterator<Item = T>,
) -> [T; BLOCK] {
    let mut acc = [T::zero(); BLOCK];
    for (col, w) in m.chunks_exact(rows).zip(weights) {
        match col.get(start..start + BLOCK) {
            Some(block) => {
                for (a, v) in acc.iter_mut().zip(block) {
                    *a += *v * w;
                }
            }
            None => {
                for (a, v) in acc.iter_mut().zip(col.iter().skip(start)) {
                    *a += *v * w;
                }
            }
        }
    }
    acc
}

/// Writes `acc` into `col[start..]`, as far as the column reaches.
fn store_block<T: Copy>(col: &mut [T], start: usize, acc: &[T; BLOCK]) {
    for (c, v) in col.iter_mut().skip(start).zip(acc) {
        *c = *v;
    }
}

/// `P = F P F^T + Q` for a symmetric `P` and `Q`, exactly symmetric, where
/// rows `a..N` of `F` are unit rows (`a = walk_from`, `N` for none), i.e.
/// `F = [[Phi, Gamma], [0, I]]`. Three exact savings over the plain product
/// (`2 N^3` multiply-adds), with `Y = F P`:
/// * `Y` is needed in rows `0..a` only: rows `a..N` of `F P` are those of `P`;
/// * only the lower triangle of `Y F^T` is formed, then mirrored;
/// * below the top-left block, `(Y F^T)[i, j] = (F P)[j, i]` for `i >= a`
///   (`P` symmetric, row `i` of `F` unit), and for `j >= a` it is `P[i, j]`,
///   so only the top-left `a x a` triangle needs a product.
///
/// About `a N^2 + N a (a + 1) / 2` multiply-adds: 8360 for the Omnimagnet's
/// 16 + 3 states against 13 718. Columns are walked contiguously (nalgebra
/// stores column-major) in blocks of [`BLOCK`] rows accumulated in
/// registers.
pub(crate) fn propagate_cov<T: RealField + Copy, N: Dim>(
    f: &OMatrix<T, N, N>,
    q: &OMatrix<T, N, N>,
    walk_from: usize,
    cov: &mut OMatrix<T, N, N>,
) where
    DefaultAllocator: Allocator<N, N>,
{
    let (rows, columns) = cov.shape_generic();
    let n = cov.nrows();
    if n == 0 {
        return;
    }
    let a = walk_from.min(n);
    let p = cov.clone();
    let fs = f.as_slice();
    // Y[:a, j] = sum_k F[:a, k] P[k, j], in blocks of rows held in registers.
    let mut y = OMatrix::<T, N, N>::zeros_generic(rows, columns);
    for (ycol, pcol) in y
        .as_mut_slice()
        .chunks_exact_mut(n)
        .zip(p.as_slice().chunks_exact(n))
    {
        for start in (0..a).step_by(BLOCK) {
            let acc = block_combination(fs, n, start, pcol.iter().copied());
            store_block(ycol, start, &acc);
        }
    }
    // C[i, j] = sum_k Y[i, k] F[j, k] for j <= i < a (blocks may reach above
    // the diagonal; those entries are not used).
    let ys = y.as_slice();
    let mut c = OMatrix::<T, N, N>::zeros_generic(rows, columns);
    for (j, ccol) in c.as_mut_slice().chunks_exact_mut(n).enumerate().take(a) {
        let fj = fs.iter().skip(j).step_by(n).copied();
        for start in (j - j % BLOCK..a).step_by(BLOCK) {
            let acc = block_combination(ys, n, start, fj.clone());
            store_block(ccol, start, &acc);
        }
    }
    for j in 0..n {
        for i in j..n {
            let v = if j >= a {
                p[(i, j)]
            } else if i >= a {
                y[(j, i)]
            } else {
                c[(i, j)]
            } + q[(i, j)];
            cov[(i, j)] = v;
            cov[(j, i)] = v;
        }
    }
}

/// One scalar measurement `z = h x + v`, `var(v) = r`, fused into (`x`, `P`)
/// with the Joseph form `P = (I - k h) P (I - k h)^T + k r k^T`.
///
/// The products with `I - k h` are done as rank-one updates (it *is* the
/// Joseph product, evaluated factor by factor, in O(N^2)): with `b = P h^T`,
/// `s = h b + r`, `k = b / s`: `W = (I - k h) P = P - k b^T`, then
/// `W (I - k h)^T = W - (W h^T) k^T`, then `+ r k k^T`.
///
/// Returns false (and changes nothing) if the result would not be finite.
pub(crate) fn fuse_scalar<T: RealField + Copy, N: Dim>(
    x: &mut OVector<T, N>,
    cov: &mut OMatrix<T, N, N>,
    h: &OVector<T, N>,
    r: T,
    z: T,
) -> bool
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    let b = &*cov * h;
    let s = h.dot(&b) + r;
    if !s.is_finite() || s <= T::zero() {
        return false;
    }
    let k = &b / s;
    let nu = z - h.dot(x);
    let mut x_new = x.clone();
    x_new.axpy(nu, &k, T::one());
    if !x_new.iter().all(|v| v.is_finite()) {
        return false;
    }
    let mut w = cov.clone();
    w.ger(-T::one(), &k, &b, T::one());
    let c = &w * h;
    w.ger(-T::one(), &c, &k, T::one());
    w.ger(r, &k, &k, T::one());
    let w = w.symmetric_part();
    if !w.iter().all(|v| v.is_finite()) {
        return false;
    }
    *x = x_new;
    *cov = w;
    true
}

/// Fuses the readings whose verdict is `Fused`, one scalar update each, in
/// sensor order. A reading that would make the state non-finite is turned
/// into a rejection.
pub(crate) fn fuse_accepted<T: RealField + Copy, N: Dim, P: Length>(
    x: &mut OVector<T, N>,
    cov: &mut OMatrix<T, N, N>,
    ht: &OMatrix<T, N, P>,
    r: &OVector<T, P>,
    z: &P::Array<Option<T>>,
    verdicts: &mut P::Array<SensorVerdict>,
) where
    DefaultAllocator: SensorAllocator<N, P>,
{
    let readings = verdicts.as_mut().iter_mut().zip(z.as_ref()).zip(r.iter());
    for (j, ((verdict, zj), rj)) in readings.enumerate() {
        let SensorVerdict::Fused { nis } = *verdict else {
            continue;
        };
        let Some(zj) = usable(*zj) else { continue };
        let h: OVector<T, N> = ht.column(j).into_owned();
        if !fuse_scalar(x, cov, &h, *rj, zj) {
            *verdict = SensorVerdict::Rejected { nis };
        }
    }
}

/// Correction with whatever readings arrived: `z[j] = None` (or NaN/inf)
/// skips sensor `j`. Each present reading is gated against the prior, the
/// accepted ones are fused sequentially (Joseph form), and the rejection
/// counters and recovery policy are applied (see the module docs).
pub fn update<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    state: &mut KalmanState<T, N, P>,
    z: &P::Array<Option<T>>,
) -> UpdateReport<P>
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    let mut verdicts = gate_all(&state.x, &state.cov, &cfg.ht, &cfg.r, z, cfg.gate.threshold);
    let recovered = state.gate.record_gate(&verdicts, cfg.gate.recover_after);
    if recovered {
        add_diagonal(&mut state.cov, &cfg.recovery_variance);
        verdicts = gate_all(&state.x, &state.cov, &cfg.ht, &cfg.r, z, cfg.gate.threshold);
    }
    fuse_accepted(
        &mut state.x,
        &mut state.cov,
        &cfg.ht,
        &cfg.r,
        z,
        &mut verdicts,
    );
    let suspect = state.gate.record_sensors(&verdicts, cfg.gate.suspect_after);
    UpdateReport {
        verdicts,
        suspect,
        recovered,
    }
}

impl<N: Length, M: Dim, P: Length> KalmanConfig<f64, N, M, P>
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    /// The same filter in another float type: matrices built and checked in
    /// `f64`, run in `f32` on an MCU with an FPU.
    pub fn cast<U: RealField + Copy>(&self) -> KalmanConfig<U, N, M, P> {
        let ht = self.ht.clone().cast();
        KalmanConfig {
            f: self.f.clone().cast(),
            g: self.g.clone().cast(),
            reads: reads_of(&ht),
            ht,
            q: self.q.clone().cast(),
            r: self.r.clone().cast(),
            gate: GatePolicy {
                threshold: nalgebra::convert(self.gate.threshold),
                suspect_after: self.gate.suspect_after,
                recover_after: self.gate.recover_after,
            },
            recovery_variance: self.recovery_variance.clone().cast(),
            walk_from: self.walk_from,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::testutil::{is_sym_psd, RandomSystem, Rng};
    use nalgebra::{Const, Matrix1, SMatrix, SVector, Vector1, Vector2, Vector4};
    use proptest::prelude::*;

    type Cfg4 = KalmanConfig<f64, Const<4>, U1, Const<2>>;

    fn random_cfg(rng: &mut Rng) -> (Cfg4, RandomSystem<4, 2>, SMatrix<f64, 4, 1>) {
        let sys = RandomSystem::<4, 2>::new(rng, 0.95, 0.01);
        let g: SMatrix<f64, 4, 1> = rng.matrix();
        let cfg = Cfg4::new(sys.f, g, sys.h, sys.q, sys.r).unwrap();
        (cfg, sys, g)
    }

    /// The scalar random walk (F = H = 1, no input) and its closed-form
    /// steady prior variance `M = (q + sqrt(q^2 + 4 q r)) / 2`.
    fn random_walk<T: RealField + Copy>(q: T, r: T) -> (KalmanConfig<T, U1, U1, U1>, T) {
        let two = T::one() + T::one();
        let m = (q + (q * q + two * two * q * r).sqrt()) / two;
        let cfg = KalmanConfig::new(
            Matrix1::new(T::one()),
            Matrix1::new(T::zero()),
            Matrix1::new(T::one()),
            Matrix1::new(q),
            Vector1::new(r),
        )
        .unwrap();
        (cfg, m)
    }

    /// Scalar random walk (F = H = 1): the prior variance converges to
    /// M = (q + sqrt(q^2 + 4 q r)) / 2 and the gain to M / (M + r).
    #[test]
    fn random_walk_matches_closed_form() {
        let (q, r) = (0.3f64, 2.0f64);
        let (cfg, m) = random_walk(q, r);
        let mut st = KalmanState::new(Vector1::new(0.0), Matrix1::new(100.0));
        for _ in 0..200 {
            predict(&cfg, &mut st, &Vector1::new(0.0));
            let prior = st.cov[(0, 0)];
            let _ = update(&cfg, &mut st, &[Some(0.0)]);
            // Posterior = (1 - K) M and K = M / (M + r).
            let gain = 1.0 - st.cov[(0, 0)] / prior;
            if (prior - m).abs() < 1e-12 {
                assert!((gain - m / (m + r)).abs() < 1e-12);
            }
        }
        predict(&cfg, &mut st, &Vector1::new(0.0));
        assert!(
            (st.cov[(0, 0)] - m).abs() < 1e-12 * m,
            "{} vs {m}",
            st.cov[(0, 0)]
        );
    }

    /// A long `f32` run of the full filter on a stiff 16-node thermal chain
    /// (the Omnimagnet's shape: six thermocouples on three nodes, 1 ms
    /// steps) keeps the covariance exactly symmetric and positive definite
    /// after every correction. The Joseph form with its symmetric part is
    /// what holds it: the plain `(I - K H) P`, or either form without the
    /// symmetric part, leaves `P` unsymmetric from the first correction.
    #[test]
    fn a_long_f32_run_keeps_the_covariance_symmetric_and_positive_definite() {
        use crate::filter::testutil::thermal_chain_16;
        let (f, h) = thermal_chain_16();
        let cfg = KalmanConfig::<f32, Const<16>, U1, Const<6>>::new(
            f.cast::<f32>(),
            SMatrix::<f32, 16, 1>::zeros(),
            h.cast::<f32>(),
            SMatrix::<f32, 16, 16>::identity() * 1e-7,
            SVector::<f32, 6>::repeat(0.25 * 0.25),
        )
        .unwrap()
        .with_gate(f32::INFINITY)
        .unwrap();
        let mut st = KalmanState::new(
            SVector::<f32, 16>::repeat(20.0),
            SMatrix::<f32, 16, 16>::identity() * 4.0,
        );
        let mut rng = Rng::new(11);
        for step in 0..50_000u32 {
            predict(&cfg, &mut st, &Vector1::new(0.0));
            if step % 10 == 0 {
                // Readings of a device at 25 degC, 0.25 K of noise.
                let z: [Option<f32>; 6] =
                    core::array::from_fn(|_| Some(25.0 + 0.25 * (rng.uniform() as f32 - 0.5)));
                let report = update(&cfg, &mut st, &z);
                assert_eq!(report.fused(), 6, "step {step}");
                assert!(
                    st.cov == st.cov.transpose(),
                    "step {step}: P lost its symmetry by {}",
                    (st.cov - st.cov.transpose()).abs().max()
                );
                assert!(
                    st.cov.cast::<f64>().cholesky().is_some(),
                    "step {step}: P is not positive definite"
                );
            }
        }
    }

    /// Same in f32 (the generic path compiles and converges in single precision).
    #[test]
    fn random_walk_f32() {
        let (cfg, m) = random_walk(0.3f32, 2.0f32);
        let mut st = KalmanState::new(Vector1::new(0.0), Matrix1::new(100.0));
        for _ in 0..100 {
            predict(&cfg, &mut st, &Vector1::new(0.0));
            let _ = update(&cfg, &mut st, &[Some(0.0)]);
        }
        predict(&cfg, &mut st, &Vector1::new(0.0));
        assert!((st.cov[(0, 0)] - m).abs() < 1e-5 * m);
    }

    /// Sequential scalar Joseph updates equal the batch update with the matrix
    /// inverse, P+ = P - P H^T (H P H^T + R)^-1 H P (R diagonal), and the same
    /// for x.
    #[test]
    fn sequential_joseph_equals_batch_update() {
        let mut rng = Rng::new(7);
        for _ in 0..20 {
            let (cfg, sys, _) = random_cfg(&mut rng);
            let l: SMatrix<f64, 4, 4> = rng.matrix();
            let p0 = l * l.transpose() + SMatrix::identity() * 0.1;
            let x0: SVector<f64, 4> = rng.matrix();
            let z: SVector<f64, 2> = sys.h * x0 + rng.matrix::<2, 1>() * 0.1;
            let mut st = KalmanState::new(x0 + rng.matrix::<4, 1>() * 0.1, p0);
            let prior_x = st.x;
            let rep = update(
                &cfg.clone().with_gate(f64::INFINITY).unwrap(),
                &mut st,
                &[Some(z[0]), Some(z[1])],
            );
            assert_eq!(rep.fused(), 2);
            let s = sys.h * p0 * sys.h.transpose() + SMatrix::<f64, 2, 2>::from_diagonal(&sys.r);
            let k = p0 * sys.h.transpose() * s.try_inverse().unwrap();
            let p_batch = p0 - k * sys.h * p0;
            let x_batch = prior_x + k * (z - sys.h * prior_x);
            assert!((st.cov - p_batch).abs().max() < 1e-10 * p0.abs().max());
            assert!((st.x - x_batch).abs().max() < 1e-10 * (1.0 + x_batch.abs().max()));
        }
    }

    /// A variance set at run time is the one the next correction uses (the
    /// batch formula with the new `R`); bad values change nothing.
    #[test]
    fn a_measurement_variance_set_at_run_time_is_the_one_fused() {
        let mut rng = Rng::new(5);
        let (cfg, sys, _) = random_cfg(&mut rng);
        let mut cfg = cfg.with_gate(f64::INFINITY).unwrap();
        let before = *cfg.r();
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(cfg.set_measurement_variance(0, bad).is_err());
        }
        assert!(cfg.set_measurement_variance(2, 1.0).is_err());
        assert_eq!(*cfg.r(), before);
        let r_new = 9.0 * before[1];
        cfg.set_measurement_variance(1, r_new).unwrap();
        let p0 = SMatrix::<f64, 4, 4>::identity();
        let x0 = SVector::<f64, 4>::zeros();
        let z = SVector::<f64, 2>::new(0.0, 1.0);
        let mut st = KalmanState::new(x0, p0);
        update(&cfg, &mut st, &[None, Some(z[1])]);
        let h = sys.h.row(1);
        let s = (h * p0 * h.transpose())[(0, 0)] + r_new;
        let x_batch = p0 * h.transpose() * (z[1] / s);
        assert!((st.x - x_batch).abs().max() < 1e-12);
    }

    #[test]
    fn rejects_50_sigma_outlier_and_flags_suspect() {
        let mut rng = Rng::new(11);
        let (cfg, sys, _) = random_cfg(&mut rng);
        let mut st = KalmanState::new(SVector::zeros(), SMatrix::identity());
        // Settle on the truth x = 0 with clean readings.
        for _ in 0..50 {
            predict(&cfg, &mut st, &SVector::zeros());
            let rep = update(&cfg, &mut st, &[Some(0.0), Some(0.0)]);
            assert_eq!(rep.fused(), 2);
        }
        let before = st;
        predict(&cfg, &mut st, &SVector::zeros());
        let s1 = (sys.h.row(1) * st.cov * sys.h.row(1).transpose())[(0, 0)] + sys.r[1];
        let outlier = 50.0 * s1.sqrt();
        let mut last = None;
        for _ in 0..3 {
            let rep = update(&cfg, &mut st, &[Some(0.0), Some(outlier)]);
            assert!(rep.verdicts[0].is_fused());
            match rep.verdicts[1] {
                SensorVerdict::Rejected { nis } => assert!(nis > 2000.0, "nis {nis}"),
                v => panic!("outlier not rejected: {v:?}"),
            }
            assert!(!rep.recovered);
            last = Some(rep);
            predict(&cfg, &mut st, &SVector::zeros());
        }
        // Rejected 3 times in a row: suspect; the estimate stayed near the truth.
        assert_eq!(last.unwrap().suspect, [false, true]);
        assert!(
            st.x.abs().max() < 1e-9,
            "{:?} (before {:?})",
            st.x,
            before.x
        );
        // A good reading clears the suspicion.
        let rep = update(&cfg, &mut st, &[Some(0.0), Some(0.0)]);
        assert_eq!(rep.suspect, [false, false]);
        assert_eq!(rep.fused(), 2);
    }

    /// A model error leaves the estimate 50 units off with a tiny covariance:
    /// every reading is rejected. With recovery disabled it stays stuck; with
    /// recovery after 3 it inflates P, fuses, and converges to the truth.
    #[test]
    fn recovers_from_wrong_state() {
        let f = SMatrix::<f64, 3, 3>::new(0.9, 0.1, 0.0, 0.1, 0.8, 0.1, 0.0, 0.1, 0.9);
        let h = SMatrix::<f64, 2, 3>::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let base = KalmanConfig::<f64, Const<3>, U1, Const<2>>::new(
            f,
            SMatrix::zeros(),
            h,
            SMatrix::identity() * 1e-6,
            SVector::<f64, 2>::repeat(0.01),
        )
        .unwrap();
        let stuck_cfg = base.clone().with_recovery(0, SVector::zeros()).unwrap();
        let cfg = base.with_recovery(3, SVector::repeat(1e4)).unwrap();
        let start = KalmanState::new(SVector::repeat(50.0), SMatrix::identity() * 1e-4);

        let mut stuck = start;
        for _ in 0..100 {
            predict(&stuck_cfg, &mut stuck, &SVector::zeros());
            let rep = update(&stuck_cfg, &mut stuck, &[Some(0.0), Some(0.0)]);
            assert_eq!(rep.fused(), 0);
            assert!(!rep.recovered);
        }

        let mut st = start;
        let mut recovered_at = None;
        for i in 0..30 {
            predict(&cfg, &mut st, &SVector::zeros());
            let rep = update(&cfg, &mut st, &[Some(0.0), Some(0.0)]);
            if rep.recovered {
                assert!(recovered_at.is_none(), "recovery fired twice");
                recovered_at = Some(i);
                assert_eq!(rep.fused(), 2);
            } else if recovered_at.is_none() {
                assert_eq!(rep.fused(), 0);
            }
        }
        assert_eq!(recovered_at, Some(2));
        assert!(st.x.abs().max() < 0.5, "{:?}", st.x);
    }

    /// NEES e^T P^-1 e of a consistent filter is chi-square with N dof. The
    /// ensemble mean over R = 200 runs at one time has mean N = 4 and standard
    /// deviation sqrt(2 N / R) = 0.2; a time average of such means has at most
    /// that spread, so the 99.9 % band is 4 +- 3.29 * 0.2 = [3.34, 4.66].
    #[test]
    fn nees_is_consistent() {
        let mut rng = Rng::new(2024);
        let (cfg, sys, g) = random_cfg(&mut rng);
        let (runs, steps) = (200, 200);
        let mut total = 0.0;
        for _ in 0..runs {
            let p0 = SMatrix::<f64, 4, 4>::identity();
            let mut truth = RandomSystem::<4, 2>::sample(&mut rng, &p0);
            let mut st = KalmanState::new(SVector::zeros(), p0);
            for t in 0..steps {
                let u = Vector1::new((t as f64 * 0.1).sin());
                truth = sys.f * truth + g * u + RandomSystem::<4, 2>::sample(&mut rng, &sys.q);
                predict(&cfg, &mut st, &u);
                let z = sys.h * truth + SVector::from_fn(|j, _| sys.r[j].sqrt() * rng.gauss());
                let _ = update(&cfg, &mut st, &[Some(z[0]), Some(z[1])]);
                let e = truth - st.x;
                total += (e.transpose() * st.cov.try_inverse().unwrap() * e)[(0, 0)];
            }
        }
        let mean = total / (runs * steps) as f64;
        assert!((3.34..=4.66).contains(&mean), "mean NEES {mean}");
    }

    /// The structured propagation against the plain `F P F^T + Q` (f64), for
    /// no, some and only random-walk states.
    #[test]
    fn propagate_cov_matches_plain_product() {
        let mut rng = Rng::new(404);
        for walk_from in [7usize, 5, 2, 0] {
            let mut f: SMatrix<f64, 7, 7> = rng.matrix();
            for i in walk_from..7 {
                for k in 0..7 {
                    f[(i, k)] = if i == k { 1.0 } else { 0.0 };
                }
            }
            let l: SMatrix<f64, 7, 7> = rng.matrix();
            let p = (l * l.transpose()).symmetric_part();
            let lq: SMatrix<f64, 7, 7> = rng.matrix();
            let q = (lq * lq.transpose() * 0.01).symmetric_part();
            let cfg = KalmanConfig::<f64, Const<7>, U1, U1>::new(
                f,
                SMatrix::zeros(),
                SMatrix::<f64, 1, 7>::repeat(1.0),
                q,
                Vector1::new(1.0),
            )
            .unwrap();
            assert_eq!(cfg.walk_from, walk_from);
            let plain = f * p * f.transpose() + q;
            let mut fast = p;
            propagate_cov(&f, &q, cfg.walk_from, &mut fast);
            assert_eq!(fast, fast.transpose());
            let err = (fast - plain).abs().max();
            assert!(
                err < 1e-13 * plain.abs().max(),
                "walk_from {walk_from}: {err}"
            );
        }
    }

    #[test]
    fn non_finite_input_is_dropped() {
        let mut rng = Rng::new(3);
        let (cfg, sys, _) = random_cfg(&mut rng);
        let x0: SVector<f64, 4> = rng.matrix();
        let mut st = KalmanState::new(x0, SMatrix::identity());
        assert_eq!(
            predict(&cfg, &mut st, &Vector1::new(f64::NAN)),
            InputStatus::Dropped
        );
        assert!((st.x - sys.f * x0).abs().max() < 1e-15);
        assert_eq!(
            predict(&cfg, &mut st, &Vector1::new(1.0)),
            InputStatus::Used
        );
    }

    #[test]
    fn build_validates_each_parameter() {
        let mut rng = Rng::new(5);
        let sys = RandomSystem::<4, 2>::new(&mut rng, 0.9, 1.0);
        let g = SMatrix::<f64, 4, 1>::zeros();
        let name = |e: Result<Cfg4, BuildError>| match e {
            Err(BuildError::InvalidParameter { name }) => name,
            other => panic!("{other:?}"),
        };
        let mut f = sys.f;
        f[(1, 2)] = f64::NAN;
        assert_eq!(name(Cfg4::new(f, g, sys.h, sys.q, sys.r)), "f");
        let mut h = sys.h;
        h[(0, 0)] = f64::INFINITY;
        assert_eq!(name(Cfg4::new(sys.f, g, h, sys.q, sys.r)), "h");
        let mut q = sys.q;
        q[(0, 1)] += 1.0;
        assert_eq!(name(Cfg4::new(sys.f, g, sys.h, q, sys.r)), "q");
        let indefinite = SMatrix::<f64, 4, 4>::from_diagonal(&Vector4::new(1.0, 1.0, -1e-3, 1.0));
        assert_eq!(name(Cfg4::new(sys.f, g, sys.h, indefinite, sys.r)), "q");
        assert_eq!(
            name(Cfg4::new(sys.f, g, sys.h, sys.q, Vector2::new(1.0, 0.0))),
            "r"
        );
        // Singular PSD and zero Q are fine.
        let singular = SMatrix::<f64, 4, 4>::from_diagonal(&Vector4::new(1.0, 0.0, 0.0, 2.0));
        assert!(Cfg4::new(sys.f, g, sys.h, singular, sys.r).is_ok());
        assert!(Cfg4::new(sys.f, g, sys.h, SMatrix::zeros(), sys.r).is_ok());
        let cfg = Cfg4::new(sys.f, g, sys.h, sys.q, sys.r).unwrap();
        assert_eq!(name(cfg.clone().with_gate(0.0)), "threshold");
        assert_eq!(name(cfg.clone().with_gate(f64::NAN)), "threshold");
        assert_eq!(
            name(cfg.with_recovery(3, SVector::repeat(-1.0))),
            "variance"
        );
    }

    fn reading() -> impl Strategy<Value = Option<f64>> {
        prop_oneof![
            3 => (-10.0f64..10.0).prop_map(Some),
            1 => Just(None),
            1 => Just(Some(f64::NAN)),
            1 => Just(Some(f64::INFINITY)),
            1 => Just(Some(f64::NEG_INFINITY)),
            1 => Just(Some(1e300)),
            1 => Just(Some(-f64::MAX)),
        ]
    }

    /// An `f32` entry of `H` or `x`: zeros of both signs (as a selection
    /// matrix has), ones, and any finite value.
    fn sparse_entry() -> impl Strategy<Value = f32> {
        prop_oneof![
            4 => Just(0.0f32),
            1 => Just(-0.0f32),
            2 => Just(1.0f32),
            3 => -1e3f32..1e3,
        ]
    }

    proptest! {
        /// The correction's `H x` over the states a sensor reads is the
        /// dense dot product's value to the bit when it reads at most two
        /// (zeros of either sign in both), within the rounding of a
        /// reordered sum when it reads three; the flash tables' `const`
        /// form finds the same states as the builder's.
        #[test]
        fn the_reads_dot_is_the_dense_dot_to_the_bit(
            ht in proptest::array::uniform3(proptest::array::uniform2(sparse_entry())),
            x in proptest::array::uniform3(sparse_entry()),
        ) {
            let ht_m = SMatrix::<f32, 3, 2>::from_fn(|i, j| ht[i][j]);
            let x = SVector::<f32, 3>::from(x);
            let reads = reads_of(&ht_m);
            prop_assert_eq!(reads, reads_of_rows(&ht));
            for (j, reads) in reads.iter().enumerate() {
                let dense = ht_m.column(j).dot(&x);
                let sparse = reads.dot(&ht_m, j, &x);
                let read = (0..3).filter(|i| ht[*i][j] != 0.0).count();
                prop_assert_eq!(reads.count as usize, read);
                if read <= 2 {
                    prop_assert!(
                        sparse == dense && (dense == 0.0 || sparse.to_bits() == dense.to_bits()),
                        "sensor {}: {} vs {}", j, sparse, dense
                    );
                } else {
                    let scale: f32 = (0..3).map(|i| (ht[i][j] * x[i]).abs()).sum();
                    prop_assert!((sparse - dense).abs() <= 4.0 * f32::EPSILON * scale);
                }
            }
        }

        /// Joseph updates keep P symmetric PSD on random stable systems, with
        /// any mix of present, missing and outlying readings.
        #[test]
        fn joseph_keeps_cov_sym_psd(
            seed in any::<u64>(),
            radius in 0.1f64..0.999,
            q_scale in 1e-8f64..1.0,
            zs in proptest::collection::vec((reading(), reading()), 1..40),
            gate in prop_oneof![Just(10.83f64), Just(f64::INFINITY)],
        ) {
            let mut rng = Rng::new(seed);
            let sys = RandomSystem::<4, 2>::new(&mut rng, radius, q_scale);
            let cfg = Cfg4::new(sys.f, rng.matrix(), sys.h, sys.q, sys.r)
                .unwrap()
                .with_gate(gate)
                .unwrap();
            let mut st = KalmanState::new(SVector::zeros(), SMatrix::identity() * 10.0);
            for (a, b) in zs {
                predict(&cfg, &mut st, &Vector1::new(1.0));
                let _ = update(&cfg, &mut st, &[a, b]);
                prop_assert!(is_sym_psd(&st.cov, 1e-9), "{}", st.cov);
            }
        }

        /// None, NaN and inf readings never panic and never poison x or P;
        /// they are reported Missing.
        #[test]
        fn bad_readings_never_poison(
            seed in any::<u64>(),
            zs in proptest::collection::vec((reading(), reading()), 1..60),
            gate in prop_oneof![Just(10.83f64), Just(f64::INFINITY)],
        ) {
            let mut rng = Rng::new(seed);
            let (cfg, _, _) = random_cfg(&mut rng);
            let cfg = cfg.with_gate(gate).unwrap();
            let mut st = KalmanState::new(SVector::zeros(), SMatrix::identity());
            for (a, b) in zs {
                predict(&cfg, &mut st, &Vector1::new(0.5));
                let rep = update(&cfg, &mut st, &[a, b]);
                for (z, v) in [a, b].iter().zip(rep.verdicts) {
                    if !z.is_some_and(f64::is_finite) {
                        prop_assert_eq!(v, SensorVerdict::Missing);
                    }
                }
                prop_assert!(st.x.iter().all(|v| v.is_finite()), "{}", st.x);
                prop_assert!(st.cov.iter().all(|v| v.is_finite()), "{}", st.cov);
            }
        }
    }
}
