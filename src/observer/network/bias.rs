//! How the heat-input biases are laid out: which sources carry one, and
//! which *share* one heat bias in proportion to their Joule power (see
//! "One sensor sees one heat: the shared bias" in [`super`]).
//!
//! The state keeps one bias entry per source (`X = N + M`) whatever the
//! layout, so the solved tables keep their shapes. A shared bias is the
//! rank-one process noise `q w w^T` on the shared sources' block, with
//! `w_m` each source's share of the nominal Joule power: the steady
//! solution then holds the shared biases exactly proportional to `w`, and
//! its bias block is the outer product `s s^T` of its diagonal's square
//! roots, which [`shared_in_tables`] reads back from the tables alone (a
//! generated module needs no extra field to know its layout).

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};

use crate::sizes::Length;

use crate::network::ScalarResistance;

/// Which sources' heat-input biases are estimated separately and which
/// share one (see [`NetworkObserverBuilder::bias_mode`](super::NetworkObserverBuilder::bias_mode)),
/// with `Mask` one flag per source: [`BiasMode`] on an MCU,
/// [`RunTimeBiasMode`](super::RunTimeBiasMode) at sizes read at run time.
/// A source left out of
/// [`bias_sources`](super::NetworkObserverBuilder::bias_sources) has no
/// bias in any mode: `bias_sources` wins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BiasModeOf<Mask> {
    /// A bias per source wherever the sensors can tell them apart (the
    /// per-source steady gain converges and leaves every limited element
    /// within `max_element_sigma_k`); otherwise one heat bias shared by
    /// every biased source in proportion to its Joule power. The default.
    Auto,
    /// A bias per source, or [`BuildError::NotConverged`](crate::BuildError::NotConverged)
    /// when the sensors cannot tell them apart (the behaviour before the
    /// shared bias existed).
    PerSource,
    /// The sources `m` with `shared[m]` (and in `bias_sources`) share one
    /// heat bias in proportion to their Joule power; the other biased
    /// sources keep their own. Fewer than two such sources (with a positive
    /// nominal power) is [`BiasMode::PerSource`].
    Shared(Mask),
}

/// [`BiasModeOf`] of `M` sources known when the firmware is compiled.
pub type BiasMode<const M: usize> = BiasModeOf<[bool; M]>;

impl<Mask> Default for BiasModeOf<Mask> {
    /// [`BiasModeOf::Auto`] (whatever the mask: an array of more than 32
    /// flags has no `Default`).
    fn default() -> Self {
        Self::Auto
    }
}

impl<Mask> BiasModeOf<Mask> {
    /// The same mode, its mask borrowed.
    pub fn as_ref(&self) -> BiasModeOf<&Mask> {
        match self {
            Self::Auto => BiasModeOf::Auto,
            Self::PerSource => BiasModeOf::PerSource,
            Self::Shared(mask) => BiasModeOf::Shared(mask),
        }
    }
}

/// The weight of a source's nominal share in the present shares: the
/// shares are `(P_m + SHARE_NOMINAL_WEIGHT P_nom,m) / sum`, so at currents
/// below about 1 % of the hardware limits (`P < 1e-4 P_nom`: standstill,
/// current-sensor noise) the shared heat stays at the nominal shares
/// instead of hopping between phases with the noise, and above them it
/// follows the present power within a fraction of a percent.
pub(crate) const SHARE_NOMINAL_WEIGHT: f32 = 1e-4;

/// The layout of the heat-input biases (see the module docs), over the
/// sources' dimension `M`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BiasLayout<M: Length> {
    /// Source `m` carries a bias (its own or a share of the shared one).
    pub(crate) biased: M::Array<bool>,
    /// Source `m`'s nominal share of the shared bias (dimensionless; the
    /// shared sources' sum to 1, 0 for every other source).
    pub(crate) share: M::Array<f64>,
}

impl<M: Length> BiasLayout<M> {
    /// A bias per source in `biased`, none shared.
    pub(crate) fn per_source(biased: M::Array<bool>) -> Self {
        Self {
            share: M::filled_like(&biased, 0.0),
            biased,
        }
    }

    /// The sources in `biased` and `mask` share one bias, in proportion to
    /// their nominal powers `nominal_w` \[W\]; a source of the mask with no
    /// nominal power carries no heat and gets no bias. `None` when fewer
    /// than two sources would share it (nothing to share: per source).
    pub(crate) fn shared(
        biased: M::Array<bool>,
        mask: &M::Array<bool>,
        nominal_w: &M::Array<f64>,
    ) -> Option<Self> {
        let (mask, nominal_w) = (mask.as_ref(), nominal_w.as_ref());
        let member = |m: usize| biased.as_ref()[m] && mask[m];
        let sources = biased.as_ref().len();
        let sharing = (0..sources)
            .filter(|m| member(*m) && nominal_w[*m] > 0.0)
            .count();
        if sharing < 2 {
            return None;
        }
        let total: f64 = (0..sources)
            .filter(|m| member(*m) && nominal_w[*m] > 0.0)
            .map(|m| nominal_w[m])
            .sum();
        if !(total.is_finite() && total > 0.0) {
            return None;
        }
        let mut layout = Self::per_source(biased.clone());
        for m in (0..sources).filter(|m| member(*m)) {
            if nominal_w[m] > 0.0 {
                layout.share.as_mut()[m] = nominal_w[m] / total;
            } else {
                layout.biased.as_mut()[m] = false;
            }
        }
        Some(layout)
    }

    /// Whether source `m` is in the shared bias.
    pub(crate) fn is_shared(&self, m: usize) -> bool {
        self.share.as_ref().get(m).is_some_and(|s| *s > 0.0)
    }

    /// Whether source `m` carries a bias.
    pub(crate) fn is_biased(&self, m: usize) -> bool {
        self.biased.as_ref().get(m).copied().unwrap_or(false)
    }

    /// Source `m`'s nominal share of the shared bias (0 out of range).
    pub(crate) fn share_of(&self, m: usize) -> f64 {
        self.share.as_ref().get(m).copied().unwrap_or(0.0)
    }

    /// The number of sources.
    pub(crate) fn sources(&self) -> usize {
        self.share.as_ref().len()
    }

    /// The sources' dimension.
    pub(crate) fn shared_mask_dim(&self) -> M {
        M::from_usize(self.sources())
    }

    /// The shared sources.
    pub(crate) fn shared_mask(&self) -> M::Array<bool> {
        M::mapped(&self.share, |s| *s > 0.0)
    }

    /// The first shared source: the slot that carries the shared bias in
    /// the reduced coordinates of the gain solve (`None`: none shared).
    pub(crate) fn lead(&self) -> Option<usize> {
        (0..self.sources()).find(|m| self.is_shared(*m))
    }
}

/// Each source's nominal Joule power \[W\]: at its hardware limit `limit_a`
/// \[A\] and its resistance at `origin_c` \[degC\] (floored at zero), in
/// `f64` from the tables' `f32` resistance so that the build and
/// [`NetworkObserver::from_parts`](super::NetworkObserver::from_parts)
/// find the same shares to the bit.
pub(crate) fn nominal_powers_w<M: Length>(
    limit_a: &M::Array<f64>,
    resistance: &M::Array<ScalarResistance<f32>>,
    origin_c: f64,
) -> M::Array<f64> {
    let mut nominal_w = M::mapped(limit_a, |_| 0.0);
    for ((p, limit_a), r) in nominal_w
        .as_mut()
        .iter_mut()
        .zip(limit_a.as_ref())
        .zip(resistance.as_ref())
    {
        let ohm = f64::from(r.r_at_0c_ohm) + f64::from(r.slope_ohm_per_k) * origin_c;
        let power = ohm.max(0.0) * limit_a * limit_a;
        *p = if power.is_finite() { power } else { 0.0 };
    }
    nominal_w
}

/// Ties the shared sources' block of `cov` (biases from state `first`) to
/// rank one: `s_a s_b` from the `f64` diagonal `diag_w2` \[W^2\], so that
/// the tables say which biases share one (see [`shared_in_prior`]).
pub(crate) fn tie_block<X: Dim>(
    cov: &mut OMatrix<f32, X, X>,
    first: usize,
    diag_w2: &[f64],
    shared: &[bool],
) where
    DefaultAllocator: Allocator<X, X>,
{
    let sd = |m: usize| libm::sqrt(diag_w2[m].max(0.0)) as f32;
    for a in (0..shared.len()).filter(|a| shared[*a]) {
        for b in (0..shared.len()).filter(|b| shared[*b]) {
            cov[(first + a, first + b)] = sd(a) * sd(b);
        }
    }
}

/// The sources whose biases the steady prior ties into one shared bias
/// (the prior's entry `(i, j)` from `prior`, the biases at `first + m`): a
/// positive variance whose covariance with another source's is exactly
/// the product of their standard deviations (see [`tie_block`]). A
/// per-source solution is never tied to the bit unless its biases are
/// correlated to within `f32` rounding, i.e. already one bias.
pub(crate) fn shared_in_prior<M: Length>(
    sources: M,
    first: usize,
    prior: impl Fn(usize, usize) -> f32,
) -> M::Array<bool> {
    let count = sources.value();
    let sd = |m: usize| {
        let v = prior(first + m, first + m);
        (v > 0.0 && v.is_finite()).then(|| libm::sqrtf(v))
    };
    sources.each(|a| {
        let Some(sa) = sd(a) else { return false };
        (0..count).any(|b| {
            b != a
                && sd(b).is_some_and(|sb| {
                    prior(first + a, first + b) == sa * sb && prior(first + b, first + a) == sb * sa
                })
        })
    })
}

/// The shared heat's regression column under a covariance: `Cov(x_i, S)`
/// of every state with the sum `S` of the shared biases, and `Var(S)`
/// \[W^2\]. Formed once for every pass of the floors, whose covariance
/// does not change between passes (each pass formed it again: `X M + M^2`
/// adds, about 1 000 instructions of the three-phase reading tick on the
/// M4F).
#[derive(Debug, Clone)]
pub(crate) struct SharedColumn<X: Dim>
where
    DefaultAllocator: Allocator<X>,
{
    /// `Cov(x_i, S)` (in each state's unit times W).
    cov_with_sum: OVector<f32, X>,
    /// `Var(S)` \[W^2\].
    var_w2: f32,
}

impl<X: Dim> SharedColumn<X>
where
    DefaultAllocator: Allocator<X, X> + Allocator<X>,
{
    /// The column of the shared biases `shared` (at `n + m`) under `cov`.
    ///
    /// Generic over the sources' length `M` (not a slice): at a `Const`
    /// size the loops have a constant bound, which the Cortex-M0 build
    /// unrolls into less code than a run-time bound's loops.
    pub(crate) fn of<M: Length>(
        cov: &OMatrix<f32, X, X>,
        n: usize,
        shared: &M::Array<bool>,
    ) -> Self {
        let mut var_w2 = 0.0f32;
        let shared = shared.as_ref();
        let m_all = shared.len();
        for a in (0..m_all).filter(|a| shared[*a]) {
            for b in (0..m_all).filter(|b| shared[*b]) {
                var_w2 += cov.get((n + a, n + b)).copied().unwrap_or(0.0);
            }
        }
        let cov_with_sum = OVector::<f32, X>::from_fn_generic(cov.shape_generic().0, U1, |i, _| {
            let mut c = 0.0f32;
            for m in (0..m_all).filter(|m| shared[*m]) {
                c += cov.get((i, n + m)).copied().unwrap_or(0.0);
            }
            c
        });
        Self {
            cov_with_sum,
            var_w2,
        }
    }
}

/// Moves `x` to the most probable state whose shared biases (`shared`, at
/// `N + m`) sum to `value_w` \[W\] under the covariance whose shared
/// column is `column`: every state by its regression on the sum
/// (`x -= Cov(x, S) (S - value) / Var(S)`), then the shared biases set to
/// `value_w` in the proportions `shares` (summing to 1).
/// [`condition_on`](crate::filter::condition_on) on the sum of the shared
/// biases, which the sensors see as one heat. A non-finite value or sum
/// leaves `x` as it is. Cost: `X + M` multiply-adds.
pub(crate) fn condition_shared_sum<X: Dim, M: Length>(
    x: &mut OVector<f32, X>,
    n: usize,
    column: &SharedColumn<X>,
    shared: &M::Array<bool>,
    shares: &M::Array<f32>,
    value_w: f32,
) where
    DefaultAllocator: Allocator<X>,
{
    let sum_w = shared_sum_w::<X, M>(x, n, shared);
    if !(sum_w.is_finite() && value_w.is_finite()) {
        return;
    }
    if column.var_w2 > 0.0 && sum_w != value_w {
        let shift = (sum_w - value_w) / column.var_w2;
        for (xi, c) in x.iter_mut().zip(column.cov_with_sum.iter()) {
            *xi -= c * shift;
        }
    }
    set_shared::<X, M>(x, n, shared, shares, value_w);
}

/// The sum of the shared biases \[W\].
pub(crate) fn shared_sum_w<X: Dim, M: Length>(
    x: &OVector<f32, X>,
    n: usize,
    shared: &M::Array<bool>,
) -> f32
where
    DefaultAllocator: Allocator<X>,
{
    let shared = shared.as_ref();
    (0..shared.len())
        .filter(|m| shared[*m])
        .map(|m| x.get(n + m).copied().unwrap_or(0.0))
        .sum()
}

/// Sets the shared biases (at `N + m`) to `sum_w` \[W\] in the proportions
/// `shares`.
pub(crate) fn set_shared<X: Dim, M: Length>(
    x: &mut OVector<f32, X>,
    n: usize,
    shared: &M::Array<bool>,
    shares: &M::Array<f32>,
    sum_w: f32,
) where
    DefaultAllocator: Allocator<X>,
{
    let (shared, shares) = (shared.as_ref(), shares.as_ref());
    for (m, share) in shares.iter().enumerate().take(shared.len()) {
        if !shared[m] {
            continue;
        }
        if let Some(b) = x.get_mut(n + m) {
            *b = sum_w * share;
        }
    }
}

/// The present shares of the shared heat (dimensionless, summing to 1 over
/// `shared`): each source's Joule power `powers_w` \[W\] at the estimate,
/// plus [`SHARE_NOMINAL_WEIGHT`] of its nominal power `nominal_w` \[W\]
/// (which alone decides with no current); the nominal shares when the sum
/// is not a positive finite number.
pub(crate) fn present_shares<M: Length>(
    shared: &M::Array<bool>,
    powers_w: &M::Array<f32>,
    nominal_w: &M::Array<f32>,
) -> M::Array<f32> {
    let (shared, powers, nominal_of) = (shared.as_ref(), powers_w.as_ref(), nominal_w.as_ref());
    let weight = |m: usize, floor: f32| {
        if shared[m] {
            powers[m].abs() + floor * nominal_of[m]
        } else {
            0.0
        }
    };
    let sources = 0..shared.len();
    let total: f32 = sources
        .clone()
        .map(|m| weight(m, SHARE_NOMINAL_WEIGHT))
        .sum();
    let mut shares = M::filled_like(powers_w, 0.0);
    if total.is_finite() && total > 0.0 {
        for (m, share) in shares.as_mut().iter_mut().enumerate() {
            *share = weight(m, SHARE_NOMINAL_WEIGHT) / total;
        }
        return shares;
    }
    let nominal: f32 = sources.filter(|m| shared[*m]).map(|m| nominal_of[m]).sum();
    for (m, share) in shares.as_mut().iter_mut().enumerate() {
        if shared[m] && nominal > 0.0 {
            *share = nominal_of[m] / nominal;
        }
    }
    shares
}

/// The heat-input biases' floors at one set of Joule powers, formed once
/// for the projections that keep them (see
/// [`NetworkObserver::keep_floors`](super::NetworkObserver)): each own
/// bias's floor, the shared bias's and the shares it goes back to the
/// sources in.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BiasFloors<M: Length> {
    /// `-fraction |P_m|` \[W\] of each source with a bias of its own
    /// (unread for a shared one).
    pub own_w: M::Array<f32>,
    /// The shared bias's floor \[W\]: the sum of its sources' (unread
    /// without a shared bias).
    pub shared_w: f32,
    /// The shared heat's present shares ([`present_shares`]); all zero
    /// without a shared bias.
    pub shares: M::Array<f32>,
}

impl<M: Length> BiasFloors<M> {
    /// The floors at the Joule powers `powers_w` \[W\], taking away at most
    /// `cooling_fraction` of each source's power; `shared` and
    /// `nominal_w` \[W\] as [`present_shares`] takes them.
    pub(crate) fn at(
        powers_w: &M::Array<f32>,
        cooling_fraction: f32,
        shared: &M::Array<bool>,
        nominal_w: &M::Array<f32>,
    ) -> Self {
        let any_shared = shared.as_ref().contains(&true);
        Self {
            own_w: M::mapped(powers_w, |p| -cooling_fraction * p.abs()),
            shared_w: if any_shared {
                -cooling_fraction
                    * shared
                        .as_ref()
                        .iter()
                        .zip(powers_w.as_ref())
                        .filter(|(shared, _)| **shared)
                        .map(|(_, p)| p.abs())
                        .sum::<f32>()
            } else {
                0.0
            },
            shares: if any_shared {
                present_shares::<M>(shared, powers_w, nominal_w)
            } else {
                M::filled_like(powers_w, 0.0)
            },
        }
    }
}
