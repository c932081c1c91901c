//! Protection that errs hot: the upper bound on an element's temperature
//! that the limiter, the alarm and the time to limit act on, in place of the
//! model's mean estimate.
//!
//! # Why
//!
//! A protection that acts on the mean estimate holds the *estimate* below the
//! alarm limit; the device runs hotter by whatever the model gets wrong. The
//! published models are wrong by a lot: their capacities, conductances and
//! winding resistances are fitted or tabulated to about +-20 %, convection
//! coefficients to worse. A Kalman filter does not help with that: its
//! covariance describes the noise it was told about, not the parameter
//! error (the Omnimagnet filter's NEES is about 13 000 for 16 states at
//! +-20 %; see the README). So the bound has two parts:
//!
//! ```text
//! T_up = T + k sigma + offset_k + f max(T - T_ref, 0)
//! ```
//!
//! * `k sigma` \[K\]: the filter's own uncertainty (sensor noise, the start),
//!   `sigma` the element's steady-state standard deviation, constant with a
//!   steady-state gain and so computed once at build time; zero for an
//!   open-loop model (no filter);
//! * `offset_k` \[K\] and `f` (dimensionless) are the [`UncertaintyMargin`]:
//!   the model's parameter error, for every element no sensor corrects
//!   (an open-loop grid's every coil, a filtered device's unmeasured
//!   elements). `T_ref` \[degC\] is the temperature the element is cooled
//!   towards (the ambient; for a coil grid the colder of the coolant and
//!   the ambient).
//!
//! # Why a fraction of the rise
//!
//! A parameter error scales the temperature *rise*, not the temperature: at
//! the ambient every model is right. For one element,
//! `C dT/dt = P - G (T - T_ref)` with `P = R I^2`: if the real power is up to
//! `(1 + d)` times the model's (`R` off by `d`) and the real `G` and `C`
//! are down to `(1 - d)` times the model's, the real rise from rest at a
//! held current is at most
//!
//! ```text
//! max(P'/P * G/G', P'/P * C/C') = (1 + d) / (1 - d)
//! ```
//!
//! times the model's at every instant (the response moves from the initial
//! slope `P / C` to the steady state `P / G`, and both ratios are bounded),
//! so `f = 2 d / (1 - d)`: 0.5 for `d` = 20 %
//! ([`UncertaintyMargin::for_parameter_error`]). A resistance that rises
//! with temperature adds the rise of `R(T)` between the estimate and the
//! real temperature (about 7 % for a copper winding estimated 18 K low at
//! 65 degC). An element *without* a heat source follows its neighbours
//! through conductance ratios: next to a measured element (a filtered
//! winding) its error is a few per cent of its rise, next to estimated ones
//! it inherits theirs and can add up to `(1 + d) / (1 - d)` again (a
//! divider). So the defaults ([`UncertaintyMargin::GRID_20_PERCENT`],
//! [`UncertaintyMargin::OMNIMAGNET_UNMEASURED_20_PERCENT`]) follow from
//! this bound and are checked by the closed-loop Monte Carlo of
//! `host-tests/tests/protect_margin.rs` (plants with every parameter off by
//! up to +-20 %, corners included, protected by the nominal observer). A
//! fixed offset does not bound a multiplicative error: it is too large when
//! cold and too small when hot, so `offset_k` is for errors that do not
//! scale with the power (a boundary temperature measured elsewhere, a
//! sensor's calibration).
//!
//! # Acting on the bound
//!
//! The limiter and the alarm take `T_up` in place of `T`, so they hold the
//! *bound* below the alarm limit and report it in their events. The time
//! to limit is asked of the model in mean terms: `T_up` is increasing in `T`,
//! so `T_up` reaches the limit `L` exactly when the mean reaches
//!
//! ```text
//! L_mean = (L - o) - f / (1 + f) max(L - o - T_ref, 0),   o = offset_k + k sigma
//! ```
//!
//! ([`ElementBound::mean_limit_c`]), and the predictors run unchanged on the
//! mean with that limit.
//!
//! # Zero
//!
//! With no margin and `k = 0` every bound is the estimate itself and every
//! mean limit the limit, to the bit (`T + 0 = T`, and the fraction's terms
//! are skipped when it is zero), so an observer built with
//! [`UncertaintyMargin::ZERO`] behaves exactly as one without this module.
//!
//! # Cost
//!
//! Per element and use: two additions, a comparison and, inside the rise, a
//! multiply; no division, no loop but over the elements.
//!
//! ```
//! use coil_thermal::protect::margin::{UncertaintyMargin, UpperBoundBuilder};
//!
//! // +-20 % on every parameter of two elements; the second one also has a
//! // filter's 0.2 K standard deviation, taken three times.
//! let bound = UpperBoundBuilder::new(UncertaintyMargin::for_parameter_error(0.2))
//!     .sigma(3.0, [0.0, 0.2])
//!     .build::<f32>()?;
//! let mut upper_c = [0.0; 2];
//! bound.upper_c(&[60.0, 60.0], 20.0, &mut upper_c);
//! assert_eq!(upper_c[0], 80.0); // 40 K rise, half of it again
//! assert!((upper_c[1] - 80.6).abs() < 1e-4);
//! // The mean temperature at which the bound reaches a 65.36 degC limit.
//! let e = bound.element(0).unwrap();
//! assert!((e.mean_limit_c(65.36, 20.0) - (20.0 + 45.36 / 1.5)).abs() < 1e-4);
//! # Ok::<(), coil_thermal::BuildError>(())
//! ```

use core::ops::Range;

use nalgebra::Const;

use crate::error::{check, BuildError};
use crate::scalar::Scalar;
use crate::sizes::{Element, Length};

/// The model-uncertainty margin of an element: how much hotter than the
/// model's estimate it may be, `offset_k + rise_fraction * (T - T_ref)`
/// (see the module docs). Plain settings; validated by
/// [`UpperBoundBuilder::build`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UncertaintyMargin {
    /// Fraction of the estimated rise above the element's reference
    /// temperature (dimensionless, finite, `>= 0`).
    pub rise_fraction: f64,
    /// Constant part \[K\] (finite, `>= 0`).
    pub offset_k: f64,
}

impl UncertaintyMargin {
    /// No margin: the protection acts on the estimate (as before this
    /// module existed, to the bit).
    pub const ZERO: Self = Self {
        rise_fraction: 0.0,
        offset_k: 0.0,
    };

    /// The default of [`GridObserver`](crate::observer::GridObserver): the
    /// HPPA grid, open loop, with every capacity, conductance and winding
    /// resistance off by up to +-20 %: `f` = 0.65. The first-order bound
    /// `(1 + d) / (1 - d)` = 1.5, times the rise of the copper's `R(T)`
    /// between the estimate and the truth at the alarm limit (7.3 % for the
    /// HPPA coil: 18 K low at 65.36 degC), is 1.61; 0.65 keeps about 1 K in
    /// hand. Measured (`host-tests/tests/protect_margin.rs`, 100 plants,
    /// a 5 x 6 grid under a plate at 3 A): the worst plant, every capacity
    /// and conductance 20 % low and every resistance 20 % high, peaks 2.5 K
    /// below the alarm limit (0.6: 1.1 K below; 0.55 and 0.5: 0.4 and 2.0 K
    /// above; no margin: 27 K above). It costs 16 % of the current the
    /// matched model is allowed.
    pub const GRID_20_PERCENT: Self = Self {
        rise_fraction: 0.65,
        offset_k: 0.0,
    };

    /// The default of [`OmniObserver`](crate::observer::OmniObserver) for
    /// the elements without a thermocouple (the insulation that carries the
    /// limits, the frames, the core): `f` = 0.05 of their rise above the
    /// ambient. The solenoids are measured, so their error is what the
    /// filter leaves (its heat-bias states absorb the power and conductance
    /// errors); an unheated element between a measured one and the ambient
    /// rises `w = g_in / (g_in + g_out)` times as much, and `d` on each
    /// conductance moves `w` by about `2 d (1 - w)`: a few per cent for the
    /// covers, which sit close to their solenoids. Measured
    /// (`host-tests/tests/protect_margin.rs`, 104 plants at 5 A on all
    /// three, four of them with convection 40 % low): 0.02 is the smallest
    /// fraction that keeps every cover below its alarm limit (0.1 K to
    /// spare), 0.05 keeps 1.9 K; without a margin 9 of the 100 +-20 %
    /// plants pass it (by up to 0.3 K; 1.1 K with convection 40 % low). It
    /// costs 2.4 % of the current the matched model is allowed.
    pub const OMNIMAGNET_UNMEASURED_20_PERCENT: Self = Self {
        rise_fraction: 0.05,
        offset_k: 0.0,
    };

    /// A margin of `rise_fraction` (dimensionless) and `offset_k` \[K\].
    pub const fn new(rise_fraction: f64, offset_k: f64) -> Self {
        Self {
            rise_fraction,
            offset_k,
        }
    }

    /// The first-order bound of the module docs for power, conductances and
    /// capacity each off by up to `delta` (0.2 for +-20 %):
    /// `f = 2 delta / (1 - delta)`, no offset. A `delta` outside `[0, 1)`
    /// gives a fraction the builder refuses.
    pub const fn for_parameter_error(delta: f64) -> Self {
        Self {
            rise_fraction: 2.0 * delta / (1.0 - delta),
            offset_k: 0.0,
        }
    }

    /// Whether both parts are zero.
    pub fn is_zero(&self) -> bool {
        self.rise_fraction == 0.0 && self.offset_k == 0.0
    }
}

impl Default for UncertaintyMargin {
    fn default() -> Self {
        Self::ZERO
    }
}

/// One element's bound, in scalar `S`, ready for the tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ElementBound<S> {
    /// `f` (dimensionless).
    pub(crate) rise_fraction: S,
    /// `f / (1 + f)` (dimensionless), for the mean limit.
    pub(crate) limit_fraction: S,
    /// `offset_k + k sigma` \[K\].
    pub(crate) offset_k: S,
}

impl<S: Scalar> ElementBound<S> {
    /// No margin.
    pub const ZERO: Self = Self {
        rise_fraction: S::ZERO,
        limit_fraction: S::ZERO,
        offset_k: S::ZERO,
    };

    /// The fraction of the rise `f` (dimensionless).
    pub fn rise_fraction(&self) -> S {
        self.rise_fraction
    }

    /// The constant part, `offset_k + k sigma` \[K\].
    pub fn offset_k(&self) -> S {
        self.offset_k
    }

    /// The protective upper bound \[degC\] of an element estimated at
    /// `temp_c` \[degC\] with reference `reference_c` \[degC\]:
    /// `T + o + f max(T - T_ref, 0)`. A NaN estimate gives NaN (which the
    /// limiter and the alarm treat as invalid), and with a non-zero
    /// fraction so does a NaN reference: the bound is never lost silently.
    #[inline]
    pub fn upper_c(&self, temp_c: S, reference_c: S) -> S {
        let mut upper_c = temp_c + self.offset_k;
        if self.rise_fraction > S::ZERO {
            let rise_k = temp_c - reference_c;
            if rise_k > S::ZERO || !rise_k.is_finite() {
                upper_c += self.rise_fraction * rise_k;
            }
        }
        upper_c
    }

    /// The mean temperature \[degC\] at which [`Self::upper_c`] reaches
    /// `limit_c` \[degC\] (reference `reference_c` \[degC\]): the limit a
    /// predictor of the mean is given (see the module docs).
    #[inline]
    pub fn mean_limit_c(&self, limit_c: S, reference_c: S) -> S {
        let shifted_c = limit_c - self.offset_k;
        if self.limit_fraction > S::ZERO {
            let rise_k = shifted_c - reference_c;
            if rise_k > S::ZERO || !rise_k.is_finite() {
                return shifted_c - self.limit_fraction * rise_k;
            }
        }
        shifted_c
    }
}

/// The upper bounds of `N` elements (configuration: built once by
/// [`UpperBoundBuilder`], shared, read by the tick).
#[derive(Debug, Clone, PartialEq)]
pub struct UpperBound<S: Element, N: Length> {
    pub(crate) elements: N::Array<ElementBound<S>>,
}

#[cfg(feature = "defmt")]
impl<S: Element + defmt::Format, const N: usize> defmt::Format for UpperBound<S, Const<N>> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "UpperBound {{ elements: {} }}", self.elements)
    }
}

impl<S: Scalar, const N: usize> UpperBound<S, Const<N>> {
    /// No margin on any element: every bound is the estimate.
    pub const ZERO: Self = Self {
        elements: [ElementBound::ZERO; N],
    };
}

impl<S: Scalar, N: Length> UpperBound<S, N> {
    /// Every element's bound.
    pub fn elements(&self) -> &N::Array<ElementBound<S>> {
        &self.elements
    }

    /// Element `index`'s bound (`None` beyond `N`).
    pub fn element(&self, index: usize) -> Option<&ElementBound<S>> {
        self.elements.as_ref().get(index)
    }

    /// Whether no element has a margin (the bound is the estimate).
    pub fn is_zero(&self) -> bool {
        self.elements
            .as_ref()
            .iter()
            .all(|e| *e == ElementBound::ZERO)
    }

    /// Feeds every element's margin (fraction of the rise and offset) to a
    /// snapshot fingerprint.
    #[must_use]
    pub fn fingerprint(&self, fp: crate::observer::Fingerprint) -> crate::observer::Fingerprint {
        self.elements.as_ref().iter().fold(fp, |fp, e| {
            fp.f64(e.rise_fraction.to_f64()).f64(e.offset_k.to_f64())
        })
    }

    /// The upper bound of every element \[degC\] from the estimates
    /// `temps_c` \[degC\] and the reference `reference_c` \[degC\], into
    /// `out`. O(N), allocation-free, panic-free.
    pub fn upper_c(&self, temps_c: &N::Array<S>, reference_c: S, out: &mut N::Array<S>) {
        let all = 0..temps_c.as_ref().len();
        self.upper_part(temps_c, reference_c, out, all);
    }

    /// [`Self::upper_c`] for the elements in `elements` only (cut to `N`),
    /// the others left as they are: for a caller that spreads its
    /// protection over several ticks.
    pub fn upper_part(
        &self,
        temps_c: &N::Array<S>,
        reference_c: S,
        out: &mut N::Array<S>,
        elements: Range<usize>,
    ) {
        let n = temps_c.as_ref().len();
        let range = elements.start.min(n)..elements.end.min(n);
        let (Some(bounds), Some(temps_c), Some(out)) = (
            self.elements.as_ref().get(range.clone()),
            temps_c.as_ref().get(range.clone()),
            out.as_mut().get_mut(range),
        ) else {
            return;
        };
        for ((bound, temp_c), out) in bounds.iter().zip(temps_c).zip(out) {
            *out = bound.upper_c(*temp_c, reference_c);
        }
    }

    /// The mean limit of every element \[degC\] (see
    /// [`ElementBound::mean_limit_c`]) for the limits `limits_c` \[degC\] and
    /// the reference `reference_c` \[degC\].
    pub fn mean_limits_c(&self, limits_c: &N::Array<S>, reference_c: S) -> N::Array<S> {
        let mut out = limits_c.clone();
        for (bound, limit_c) in self.elements.as_ref().iter().zip(out.as_mut()) {
            *limit_c = bound.mean_limit_c(*limit_c, reference_c);
        }
        out
    }
}

/// Builds and validates an [`UpperBound`]: the model margin of each element
/// and, for a filtered model, `k` times each element's standard deviation.
#[derive(Debug, Clone, PartialEq)]
pub struct UpperBoundBuilder<N: Length> {
    margins: N::Array<UncertaintyMargin>,
    k_sigma: f64,
    sigma_k: N::Array<f64>,
}

impl<const N: usize> UpperBoundBuilder<Const<N>> {
    /// The same `margin` on every element, no `k sigma`.
    pub fn new(margin: UncertaintyMargin) -> Self {
        Self::per_element([margin; N])
    }

    /// A margin per element (e.g. [`UncertaintyMargin::ZERO`] on the
    /// elements a sensor measures), no `k sigma`.
    pub fn per_element(margins: [UncertaintyMargin; N]) -> Self {
        Self::of(margins)
    }
}

impl<N: Length> UpperBoundBuilder<N> {
    /// [`UpperBoundBuilder::per_element`] for elements of any [`Length`]
    /// (a `Vec` for `Dyn`, a model's size read at run time).
    pub fn of(margins: N::Array<UncertaintyMargin>) -> Self {
        Self {
            sigma_k: N::filled_like(&margins, 0.0),
            margins,
            k_sigma: 0.0,
        }
    }

    /// Adds `k` (dimensionless, finite, `>= 0`) times each element's
    /// standard deviation `sigma_k` \[K\] (finite, `>= 0`), e.g. the square
    /// roots of a steady-state filter's covariance diagonal.
    pub fn sigma(mut self, k: f64, sigma_k: N::Array<f64>) -> Self {
        self.k_sigma = k;
        self.sigma_k = sigma_k;
        self
    }

    /// Validates and converts to `S`.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the parameter: a fraction, an
    /// offset, `k` or a `sigma_k` that is not finite or is negative.
    pub fn build<S: Scalar>(&self) -> Result<UpperBound<S, N>, BuildError> {
        // `sigma` may have been given another length (a run-time size).
        check(
            self.sigma_k.as_ref().len() == self.margins.as_ref().len(),
            "sigma_k",
        )?;
        let nonneg = |v: f64| v.is_finite() && v >= 0.0;
        check(nonneg(self.k_sigma), "k_sigma")?;
        let mut elements = N::filled_like(&self.margins, ElementBound::ZERO);
        let margins = self.margins.as_ref().iter().zip(self.sigma_k.as_ref());
        for (element, (margin, sigma_k)) in elements.as_mut().iter_mut().zip(margins) {
            let f = margin.rise_fraction;
            check(nonneg(f), "UncertaintyMargin::rise_fraction")?;
            check(nonneg(margin.offset_k), "UncertaintyMargin::offset_k")?;
            check(nonneg(*sigma_k), "sigma_k")?;
            let offset_k = margin.offset_k + self.k_sigma * sigma_k;
            check(offset_k.is_finite(), "sigma_k")?;
            *element = ElementBound {
                rise_fraction: S::from_f64(f),
                limit_fraction: S::from_f64(f / (1.0 + f)),
                offset_k: S::from_f64(offset_k),
            };
        }
        Ok(UpperBound { elements })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scalar::Q32;

    fn bound<S: Scalar>(f: f64, offset_k: f64, k: f64, sigma_k: f64) -> UpperBound<S, Const<1>> {
        UpperBoundBuilder::new(UncertaintyMargin::new(f, offset_k))
            .sigma(k, [sigma_k])
            .build()
            .unwrap()
    }

    #[test]
    fn zero_margin_is_the_estimate_to_the_bit() {
        let zero = UpperBound::<f32, Const<1>>::ZERO;
        let built = bound::<f32>(0.0, 0.0, 3.0, 0.0);
        assert_eq!(zero, built);
        assert!(built.is_zero());
        let e = built.elements()[0];
        for t in [
            -40.0f32,
            0.0,
            20.0,
            20.000_002,
            65.36,
            1e30,
            f32::INFINITY,
            f32::MAX,
        ] {
            for r in [-10.0f32, 20.0, 100.0] {
                assert_eq!(e.upper_c(t, r).to_bits(), t.to_bits(), "{t} {r}");
                assert_eq!(e.mean_limit_c(t, r).to_bits(), t.to_bits(), "{t} {r}");
            }
        }
        assert!(e.upper_c(f32::NAN, 20.0).is_nan());
        let q = UpperBound::<Q32, Const<1>>::ZERO.elements()[0];
        let t = Q32::from_f64(63.123_456_789);
        assert_eq!(q.upper_c(t, Q32::from_f64(20.0)), t);
        assert_eq!(q.mean_limit_c(t, Q32::from_f64(20.0)), t);
    }

    #[test]
    fn the_bound_and_the_mean_limit_invert_each_other() {
        // f64, f32 and Q32 over fractions, offsets, limits and references,
        // including limits below the reference plus offset.
        let mut worst = [0.0f64; 3];
        for f in [0.0, 0.1, 0.35, 0.5, 0.65, 2.0] {
            for o in [0.0, 0.4, 3.0] {
                for l in [25.0, 65.36, 84.8, 200.0] {
                    for r in [-5.0, 20.0, 24.0, 70.0] {
                        let b64 = bound::<f64>(f, o, 0.0, 0.0).elements()[0];
                        let m = b64.mean_limit_c(l, r);
                        worst[0] = worst[0].max((b64.upper_c(m, r) - l).abs());
                        // Increasing in T: just below the mean limit, below L.
                        assert!(b64.upper_c(m - 1e-6, r) < l);
                        let b32 = bound::<f32>(f, o, 0.0, 0.0).elements()[0];
                        let (l32, r32) = (l as f32, r as f32);
                        let m32 = b32.mean_limit_c(l32, r32);
                        worst[1] = worst[1].max(f64::from(b32.upper_c(m32, r32) - l32).abs());
                        let bq = bound::<Q32>(f, o, 0.0, 0.0).elements()[0];
                        let (lq, rq) = (Q32::from_f64(l), Q32::from_f64(r));
                        let mq = bq.mean_limit_c(lq, rq);
                        worst[2] = worst[2].max((bq.upper_c(mq, rq) - lq).to_f64().abs());
                    }
                }
            }
        }
        println!("|upper(mean_limit(L)) - L|: f64 {worst:?} K (f64, f32, Q32)");
        assert!(worst[0] < 1e-12, "{worst:?}");
        assert!(worst[1] < 1e-4, "{worst:?}");
        assert!(worst[2] < 1e-7, "{worst:?}");
    }

    #[test]
    fn the_bound_covers_the_documented_form() {
        let b = bound::<f64>(0.5, 1.0, 3.0, 0.2).elements()[0];
        // 40 K above the reference: 40 + 0.5 * 40 + 1 + 0.6.
        assert!((b.upper_c(60.0, 20.0) - 81.6).abs() < 1e-12);
        // Below the reference only the offsets count.
        assert!((b.upper_c(15.0, 20.0) - 16.6).abs() < 1e-12);
        assert!((b.offset_k() - 1.6).abs() < 1e-12);
        assert_eq!(b.rise_fraction(), 0.5);
        // A NaN reference with a fraction: NaN, never the bare estimate.
        assert!(b.upper_c(60.0, f64::NAN).is_nan());
        assert!(b.mean_limit_c(60.0, f64::NAN).is_nan());
        assert!((UncertaintyMargin::for_parameter_error(0.2).rise_fraction - 0.5).abs() < 1e-15);
    }

    #[test]
    fn bad_settings_are_refused_by_name() {
        let name = |r: Result<UpperBound<f32, Const<2>>, BuildError>| match r {
            Err(BuildError::InvalidParameter { name }) => name,
            other => panic!("{other:?}"),
        };
        let m = UncertaintyMargin::new;
        assert_eq!(
            name(UpperBoundBuilder::new(m(-0.1, 0.0)).build()),
            "UncertaintyMargin::rise_fraction"
        );
        assert_eq!(
            name(UpperBoundBuilder::new(m(f64::NAN, 0.0)).build()),
            "UncertaintyMargin::rise_fraction"
        );
        assert_eq!(
            name(UpperBoundBuilder::new(UncertaintyMargin::for_parameter_error(1.0)).build()),
            "UncertaintyMargin::rise_fraction"
        );
        assert_eq!(
            name(UpperBoundBuilder::new(m(0.5, -1.0)).build()),
            "UncertaintyMargin::offset_k"
        );
        assert_eq!(
            name(
                UpperBoundBuilder::new(m(0.5, 0.0))
                    .sigma(f64::INFINITY, [0.1; 2])
                    .build()
            ),
            "k_sigma"
        );
        assert_eq!(
            name(
                UpperBoundBuilder::new(m(0.5, 0.0))
                    .sigma(3.0, [0.1, -0.1])
                    .build()
            ),
            "sigma_k"
        );
        assert_eq!(
            name(UpperBoundBuilder::per_element([m(0.5, 0.0), m(0.5, f64::INFINITY)]).build()),
            "UncertaintyMargin::offset_k"
        );
        assert!(
            UpperBoundBuilder::<Const<2>>::new(UncertaintyMargin::GRID_20_PERCENT)
                .build::<f32>()
                .is_ok()
        );
    }

    #[test]
    fn parts_write_only_their_elements() {
        let b: UpperBound<f32, Const<4>> = UpperBoundBuilder::new(UncertaintyMargin::new(1.0, 0.0))
            .build()
            .unwrap();
        let mut out = [-1.0f32; 4];
        b.upper_part(&[30.0; 4], 20.0, &mut out, 1..3);
        assert_eq!(out, [-1.0, 40.0, 40.0, -1.0]);
        b.upper_part(&[30.0; 4], 20.0, &mut out, 3..10);
        assert_eq!(out, [-1.0, 40.0, 40.0, 40.0]);
        let limits = b.mean_limits_c(&[60.0; 4], 20.0);
        assert_eq!(limits, [40.0; 4]);
    }
}
