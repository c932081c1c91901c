//! Whether a state can run a warm-up: a type parameter of the states of
//! the observers that have one ([`NetworkObserverState`](super::NetworkObserverState),
//! [`OmniObserverState`](super::OmniObserverState)), chosen by the
//! constructor and resolved at compile time.
//!
//! A warm-up (the start without history's, [`super::start`], and on the
//! network observer the configured one of
//! [`NetworkSettings::warmup_corrections`](super::NetworkSettings::warmup_corrections))
//! holds a covariance of its own and corrects against it: kilobytes of
//! code every tick could reach while a runtime flag decided whether it
//! ran, and on the Omnimagnet kilobytes of RAM in every state. A product
//! that starts from a snapshot or from a known state never runs it, so
//! its state says so in its type ([`NoWarmUp`]): it holds nothing, and its
//! tick is compiled without the warm-up's code. The states a start
//! returns ([`WarmUp`], the default of each state type) hold what their
//! observer's warm-up needs (`H`: the network's covariance, the
//! Omnimagnet's [`OmniHeld`](super::omnimagnet::OmniHeld)) and tick as
//! ever.
//!
//! Each observer names its flavours by a trait of its own over
//! [`Flavour`] with its held type fixed
//! ([`network::WarmUpKind`](super::network::WarmUpKind),
//! [`omnimagnet::OmniWarmUpKind`](super::omnimagnet::OmniWarmUpKind)).

/// The flavour of a state that runs no warm-up (the steady gain from the
/// first correction): what the `state`, `restore` and
/// `conservative_state` constructors return. It holds nothing, and a
/// firmware that ticks only such states links none of the warm-up's code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct NoWarmUp;

/// The flavour of a state that can run the warm-up: what `start` and
/// `with_warm_up` return, and the default of the state types (so that a
/// restore and its fallback, a start, are one type). Holds what the
/// observer's warm-up needs, `H` (see the module docs).
#[derive(Debug, Clone)]
pub struct WarmUp<H> {
    /// What the warm-up holds while it runs.
    pub(crate) held: H,
}

/// A state's warm-up flavour holding `H` while it warms up: [`NoWarmUp`]
/// or [`WarmUp<H>`] (sealed).
pub trait Flavour<H>: sealed::Held<H> + Clone + core::fmt::Debug {}

impl<H> Flavour<H> for NoWarmUp {}
impl<H: Clone + core::fmt::Debug> Flavour<H> for WarmUp<H> {}

pub(crate) mod sealed {
    use super::{NoWarmUp, WarmUp};

    /// What a flavour holds: always nothing for [`NoWarmUp`], a constant
    /// the compiler folds, so that every branch of the warm-up falls away
    /// from its tick.
    pub trait Held<H> {
        /// What is held.
        fn held(&self) -> Option<&H>;
        /// [`Self::held`], mutable.
        fn held_mut(&mut self) -> Option<&mut H>;
    }

    impl<H> Held<H> for NoWarmUp {
        #[inline(always)]
        fn held(&self) -> Option<&H> {
            None
        }
        #[inline(always)]
        fn held_mut(&mut self) -> Option<&mut H> {
            None
        }
    }

    impl<H> Held<H> for WarmUp<H> {
        #[inline(always)]
        fn held(&self) -> Option<&H> {
            Some(&self.held)
        }
        #[inline(always)]
        fn held_mut(&mut self) -> Option<&mut H> {
            Some(&mut self.held)
        }
    }
}
