//! A network's sizes, known when the firmware is compiled or only when a
//! model file is read.
//!
//! An MCU's observer has its sizes as const generics: every vector is an
//! array, placed by the compiler, with no allocation and no length to
//! check. A host reading a model file learns its sizes at run time (a
//! motor's network from a design tool has hundreds of nodes). One
//! abstraction serves both: a size is a nalgebra dimension ([`Dim`]) that
//! is a [`Length`], `Const<N>` on an MCU and `Dyn` on a host (the `alloc`
//! feature). A matrix over it is nalgebra's `OMatrix` (for `Const` the same
//! type as `SMatrix`, on the stack; for `Dyn` a `DMatrix` on the heap); a
//! plain vector (temperatures, verdicts, counters) is its
//! [`Length::Array`], `[U; N]` or a `Vec<U>` of the model's length.
//!
//! [`Sizes`] are a network's three dimensions, nodes, boundaries and
//! inputs, with their vectors [`NodeVector`], [`BoundaryVector`] and
//! [`InputVector`]: [`ConstSizes`] on an MCU, `RunTimeSizes` on a host.
//! Code written over them reads its vectors as slices ([`AsRef<[U]>`]), so
//! the MCU and the host run the same code: for `Const` sizes it compiles
//! to what the arrays compiled to before (every length a constant), for
//! `Dyn` to loops over the model's lengths. Code over a network's matrices
//! states the allocations it needs once, as
//! `DefaultAllocator: NetworkAllocator<Z>` ([`NetworkAllocator`]).
//!
//! Written over sizes so far: the build-time analyses and the
//! time-to-limit predictor with its per-tick state
//! ([`crate::protect::predict`], [`crate::protect::safe_current`],
//! [`crate::protect::runaway`], the steady state), the state space and its
//! exact discretisation and integer step ([`crate::network::StateSpace`],
//! [`crate::discretize`]), the Kalman filter ([`crate::filter`]:
//! `KalmanConfig<T, N, M, P>` over three dimensions), the alarm, the
//! current limiter and the upper bound ([`crate::protect::alarm`],
//! [`crate::protect::limiter`], [`crate::protect::margin`], over their
//! elements `N`), and the filtered observers' pieces: the sensor checks
//! (the stuck test and its rewind, the drift hold, silence, doubt), the
//! shadow model, the protection cycle and its latch, the model step's
//! energy account and the outputs
//! ([`crate::observer::FilteredOutputs`]). Each compiles for `Const`
//! sizes to what the arrays compiled to before, but for register
//! allocation: the MCU examples' goldens are unchanged and their
//! instruction counts within a few (the moves are in docs/cost.md). The
//! network observer's configuration and state are types over sizes
//! ([`crate::observer::NetworkObserverOf`]`<Z, X, P>`, whose `Const` sizes
//! are `NetworkObserver<N, B, M, X, P>`), and its model step and
//! protection stages are written once for every size; its correction, its
//! tick, its builder and its start and restore rules are still the `Const`
//! sizes' alone, so a host cannot build or tick one of `Dyn` sizes yet.

use core::fmt::Debug;

use nalgebra::allocator::Allocator;
use nalgebra::{Const, Dim};

/// What a vector element must be: cloned into place, compared and shown
/// (every scalar, `Option` of one, and a vector of them).
pub trait Element: Clone + Debug + PartialEq {}

impl<U: Clone + Debug + PartialEq> Element for U {}

/// A vector of a [`Sizes`]'s length, read and written as a slice.
pub trait Vector<U>: AsRef<[U]> + AsMut<[U]> + Clone + Debug + PartialEq {}

impl<U, V: AsRef<[U]> + AsMut<[U]> + Clone + Debug + PartialEq> Vector<U> for V {}

/// A nalgebra dimension with a plain vector of its length: `[U; N]` for
/// `Const<N>` (an MCU: the array the compiler places), a `Vec<U>` for
/// `Dyn` (a host, with the `alloc` feature). For what is not a matrix
/// entry (a sensor's verdict, counter or reads), beside the matrices of
/// the same dimension.
pub trait Length: Dim {
    /// A value per index of this dimension.
    type Array<U: Element>: Vector<U>;

    /// A vector with every entry `fill`.
    fn filled<U: Element + Copy>(self, fill: U) -> Self::Array<U>;

    /// A vector of `f(i)` for every index `i`, in order.
    fn each<U: Element>(self, f: impl FnMut(usize) -> U) -> Self::Array<U>;

    /// A vector of `from`'s length with every entry `fill`.
    fn filled_like<U: Element, V: Element + Copy>(from: &Self::Array<U>, fill: V)
        -> Self::Array<V>;

    /// `f` of every entry of `from`, in order (nothing to check on the
    /// tick's path).
    fn mapped<U: Element, V: Element>(
        from: &Self::Array<U>,
        f: impl FnMut(&U) -> V,
    ) -> Self::Array<V>;
}

impl<const N: usize> Length for Const<N> {
    type Array<U: Element> = [U; N];

    #[inline(always)]
    fn filled<U: Element + Copy>(self, fill: U) -> [U; N] {
        [fill; N]
    }

    #[inline(always)]
    fn each<U: Element>(self, f: impl FnMut(usize) -> U) -> [U; N] {
        core::array::from_fn(f)
    }

    #[inline(always)]
    fn filled_like<U: Element, V: Element + Copy>(_: &[U; N], fill: V) -> [V; N] {
        [fill; N]
    }

    #[inline(always)]
    fn mapped<U: Element, V: Element>(from: &[U; N], mut f: impl FnMut(&U) -> V) -> [V; N] {
        // Indexed rather than `each_ref().map(f)`, whose array of `N`
        // references the compiler may build first (the 84-coil grid's
        // derated limits on the M4F: 294 instructions more).
        core::array::from_fn(|i| f(&from[i]))
    }
}

/// The sizes of a network: `N` state nodes, `B` boundaries and `M` inputs
/// (current sources), each a dimension with its vectors ([`Length`]).
pub trait Sizes: Copy + Debug + PartialEq {
    /// The state nodes' dimension (`Const<N>` or `Dyn`).
    type NodeDim: Length;
    /// The boundaries' dimension.
    type BoundaryDim: Length;
    /// The inputs' dimension.
    type InputDim: Length;

    /// Number of state nodes `N`.
    fn nodes(&self) -> usize;
    /// Number of boundaries `B`.
    fn boundaries(&self) -> usize;
    /// Number of inputs `M`.
    fn inputs(&self) -> usize;

    /// The state nodes as a nalgebra dimension.
    fn node_dim(&self) -> Self::NodeDim {
        Self::NodeDim::from_usize(self.nodes())
    }
    /// The boundaries as a nalgebra dimension.
    fn boundary_dim(&self) -> Self::BoundaryDim {
        Self::BoundaryDim::from_usize(self.boundaries())
    }
    /// The inputs as a nalgebra dimension.
    fn input_dim(&self) -> Self::InputDim {
        Self::InputDim::from_usize(self.inputs())
    }

    /// A node vector with every entry `fill` (`[fill; N]`: the splat the
    /// compiler knows, on the hot path).
    #[inline(always)]
    fn nodes_of<U: Element + Copy>(&self, fill: U) -> NodeVector<Self, U> {
        self.node_dim().filled(fill)
    }
    /// A boundary vector with every entry `fill`.
    #[inline(always)]
    fn boundaries_of<U: Element + Copy>(&self, fill: U) -> BoundaryVector<Self, U> {
        self.boundary_dim().filled(fill)
    }
    /// An input vector with every entry `fill`.
    #[inline(always)]
    fn inputs_of<U: Element + Copy>(&self, fill: U) -> InputVector<Self, U> {
        self.input_dim().filled(fill)
    }
    /// A node vector of clones of `row` (a matrix by rows, at build time).
    fn rows_of<U: Element>(&self, row: U) -> NodeVector<Self, U> {
        self.node_dim().each(|_| row.clone())
    }
}

/// A value per state node of sizes `Z` (`[U; N]` or a `Vec`).
pub type NodeVector<Z, U> = <<Z as Sizes>::NodeDim as Length>::Array<U>;
/// A value per boundary of sizes `Z`.
pub type BoundaryVector<Z, U> = <<Z as Sizes>::BoundaryDim as Length>::Array<U>;
/// A value per input (current source) of sizes `Z`.
pub type InputVector<Z, U> = <<Z as Sizes>::InputDim as Length>::Array<U>;

/// The nalgebra allocations of a network's matrices and vectors
/// (`N x N`, `N x B`, `N x M`, and vectors of each length): one bound,
/// `DefaultAllocator: NetworkAllocator<Z>`, for code over a
/// [`Sizes`] `Z` (Rust elaborates a trait's supertraits, not the other
/// bounds of a where clause). Implemented by nalgebra's
/// `DefaultAllocator` for every [`ConstSizes`], and for `RunTimeSizes`.
pub trait NetworkAllocator<Z: Sizes>:
    Allocator<Z::NodeDim, Z::NodeDim>
    + Allocator<Z::NodeDim, Z::BoundaryDim>
    + Allocator<Z::NodeDim, Z::InputDim>
    + Allocator<Z::NodeDim>
    + Allocator<Z::BoundaryDim>
    + Allocator<Z::InputDim>
{
}

impl<Z: Sizes, A> NetworkAllocator<Z> for A where
    A: Allocator<Z::NodeDim, Z::NodeDim>
        + Allocator<Z::NodeDim, Z::BoundaryDim>
        + Allocator<Z::NodeDim, Z::InputDim>
        + Allocator<Z::NodeDim>
        + Allocator<Z::BoundaryDim>
        + Allocator<Z::InputDim>
{
}

/// Sizes fixed at compile time: every vector an array (an MCU).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ConstSizes<const N: usize, const B: usize, const M: usize>;

impl<const N: usize, const B: usize, const M: usize> Sizes for ConstSizes<N, B, M> {
    type NodeDim = Const<N>;
    type BoundaryDim = Const<B>;
    type InputDim = Const<M>;

    #[inline(always)]
    fn nodes(&self) -> usize {
        N
    }

    #[inline(always)]
    fn boundaries(&self) -> usize {
        B
    }

    #[inline(always)]
    fn inputs(&self) -> usize {
        M
    }

    #[inline(always)]
    fn node_dim(&self) -> Const<N> {
        Const
    }

    #[inline(always)]
    fn boundary_dim(&self) -> Const<B> {
        Const
    }

    #[inline(always)]
    fn input_dim(&self) -> Const<M> {
        Const
    }
}

#[cfg(feature = "alloc")]
pub use run_time::RunTimeSizes;

#[cfg(feature = "alloc")]
mod run_time {
    use alloc::vec;
    use alloc::vec::Vec;

    use nalgebra::Dyn;

    use super::{Element, Length, Sizes};

    impl Length for Dyn {
        type Array<U: Element> = Vec<U>;

        fn filled<U: Element + Copy>(self, fill: U) -> Vec<U> {
            vec![fill; self.0]
        }

        fn each<U: Element>(self, f: impl FnMut(usize) -> U) -> Vec<U> {
            (0..self.0).map(f).collect()
        }

        fn filled_like<U: Element, V: Element + Copy>(from: &Vec<U>, fill: V) -> Vec<V> {
            vec![fill; from.len()]
        }

        fn mapped<U: Element, V: Element>(from: &Vec<U>, f: impl FnMut(&U) -> V) -> Vec<V> {
            from.iter().map(f).collect()
        }
    }

    /// Sizes read at run time: every vector a `Vec` of the model's length
    /// (a host; allocates where a vector is made).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
    pub struct RunTimeSizes {
        /// State nodes `N`.
        pub nodes: usize,
        /// Boundaries `B`.
        pub boundaries: usize,
        /// Inputs `M`.
        pub inputs: usize,
    }

    impl Sizes for RunTimeSizes {
        type NodeDim = Dyn;
        type BoundaryDim = Dyn;
        type InputDim = Dyn;

        fn nodes(&self) -> usize {
            self.nodes
        }

        fn boundaries(&self) -> usize {
            self.boundaries
        }

        fn inputs(&self) -> usize {
            self.inputs
        }
    }
}
