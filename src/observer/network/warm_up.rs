//! Whether a state can run the time-varying warm-up: a type parameter of
//! [`NetworkObserverState`](super::NetworkObserverState), chosen by the
//! constructor and resolved at compile time.
//!
//! The warm-up (the start's, [`super::super::start`], and the configured
//! one of [`NetworkSettings::warmup_corrections`](super::NetworkSettings::warmup_corrections))
//! propagates a full covariance every model step and corrects with the
//! time-varying Kalman update: about 4.3 KiB of code on a Cortex-M0, which
//! every tick could reach while a runtime count decided whether it ran. A
//! product that starts from a snapshot or from a known state never runs
//! it, so its state says so in its type ([`NoWarmUp`]) and its tick is
//! compiled without that code; the states [`start`](super::NetworkObserver::start)
//! returns ([`WarmUp`], the default) tick as ever.

use nalgebra::SMatrix;

/// The flavour of a state that runs no warm-up (the steady gain from the
/// first correction): what [`state`](super::NetworkObserver::state),
/// the `restore` methods and
/// [`conservative_state`](super::NetworkObserver::conservative_state)
/// return. It holds nothing, and a firmware that ticks only such states
/// links none of the warm-up's code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NoWarmUp;

/// The flavour of a state that can run the time-varying warm-up: what
/// [`start`](super::NetworkObserver::start) and
/// [`with_warm_up`](super::NetworkObserver::with_warm_up) return, and the
/// default of [`NetworkObserverState`](super::NetworkObserverState) (so
/// that a restore and its fallback, a start, are one type). Holds the
/// warm-up's covariance (`X^2` floats).
#[derive(Debug, Clone)]
pub struct WarmUp<const X: usize> {
    /// The time-varying warm-up's covariance, while it runs.
    pub(super) cov: SMatrix<f32, X, X>,
}

/// A state's warm-up flavour: [`NoWarmUp`] or [`WarmUp`] (sealed).
pub trait WarmUpKind<const X: usize>: sealed::Held<X> + Clone + core::fmt::Debug {}

impl<const X: usize> WarmUpKind<X> for NoWarmUp {}
impl<const X: usize> WarmUpKind<X> for WarmUp<X> {}

pub(super) mod sealed {
    use super::{NoWarmUp, WarmUp};
    use nalgebra::SMatrix;

    /// The warm-up's covariance a flavour holds: always none for
    /// [`NoWarmUp`], a constant the compiler folds, so that every branch
    /// of the warm-up falls away from its tick. (Only the covariance: its
    /// count and end stay in the state, where a single matrix field kept
    /// the state's layout, and the start's tick, as they were.)
    pub trait Held<const X: usize> {
        /// The covariance held.
        fn cov(&self) -> Option<&SMatrix<f32, X, X>>;
        /// [`Self::cov`], mutable.
        fn cov_mut(&mut self) -> Option<&mut SMatrix<f32, X, X>>;
    }

    impl<const X: usize> Held<X> for NoWarmUp {
        #[inline(always)]
        fn cov(&self) -> Option<&SMatrix<f32, X, X>> {
            None
        }
        #[inline(always)]
        fn cov_mut(&mut self) -> Option<&mut SMatrix<f32, X, X>> {
            None
        }
    }

    impl<const X: usize> Held<X> for WarmUp<X> {
        #[inline(always)]
        fn cov(&self) -> Option<&SMatrix<f32, X, X>> {
            Some(&self.cov)
        }
        #[inline(always)]
        fn cov_mut(&mut self) -> Option<&mut SMatrix<f32, X, X>> {
            Some(&mut self.cov)
        }
    }
}
