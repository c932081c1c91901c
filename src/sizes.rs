//! A network's sizes, known when the firmware is compiled or only when a
//! model file is read.
//!
//! An MCU's observer has its sizes as const generics: every vector is an
//! array, placed by the compiler, with no allocation and no length to
//! check. A host reading a model file learns its sizes at run time (a
//! motor's network from a design tool has hundreds of nodes). [`Sizes`] is
//! the one face both show to the code that holds a vector per node, per
//! boundary or per input: [`ConstSizes`] makes each an array (`[U; N]`),
//! and, with the `alloc` feature, `RunTimeSizes` a `Vec` of the model's
//! length. Code written over `S: Sizes` reads its vectors as slices
//! ([`AsRef<[U]>`]), so the MCU and the host run the same code: for
//! [`ConstSizes`] it compiles to what the arrays compiled to before (every
//! length a constant), for `RunTimeSizes` to loops over the model's
//! lengths.
//!
//! Only the build-time analyses and the time-to-limit predictor are
//! written over [`Sizes`] so far ([`crate::protect::predict`],
//! [`crate::protect::safe_current`], [`crate::protect::runaway`], the
//! steady state); the observers keep their const generics.

use core::fmt::Debug;

/// What a vector element must be: cloned into place, compared and shown
/// (every scalar, `Option` of one, and a vector of them).
pub trait Element: Clone + Debug + PartialEq {}

impl<U: Clone + Debug + PartialEq> Element for U {}

/// A vector of a [`Sizes`]'s length, read and written as a slice.
pub trait Vector<U>: AsRef<[U]> + AsMut<[U]> + Clone + Debug + PartialEq {}

impl<U, V: AsRef<[U]> + AsMut<[U]> + Clone + Debug + PartialEq> Vector<U> for V {}

/// The sizes of a network: `N` state nodes, `B` boundaries and `M` inputs
/// (current sources), and the vector types of each length.
pub trait Sizes: Copy + Debug + PartialEq {
    /// A value per state node.
    type Nodes<U: Element>: Vector<U>;
    /// A value per boundary node.
    type Boundaries<U: Element>: Vector<U>;
    /// A value per input (current source).
    type Inputs<U: Element>: Vector<U>;

    /// Number of state nodes `N`.
    fn nodes(&self) -> usize;
    /// Number of boundaries `B`.
    fn boundaries(&self) -> usize;
    /// Number of inputs `M`.
    fn inputs(&self) -> usize;

    /// A node vector with every entry `fill` (`[fill; N]`: the splat the
    /// compiler knows, on the hot path).
    fn nodes_of<U: Element + Copy>(&self, fill: U) -> Self::Nodes<U>;
    /// A boundary vector with every entry `fill`.
    fn boundaries_of<U: Element + Copy>(&self, fill: U) -> Self::Boundaries<U>;
    /// An input vector with every entry `fill`.
    fn inputs_of<U: Element + Copy>(&self, fill: U) -> Self::Inputs<U>;
    /// A node vector of clones of `row` (a matrix by rows, at build time).
    fn rows_of<U: Element>(&self, row: U) -> Self::Nodes<U>;
}

/// Sizes fixed at compile time: every vector an array (an MCU).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ConstSizes<const N: usize, const B: usize, const M: usize>;

impl<const N: usize, const B: usize, const M: usize> Sizes for ConstSizes<N, B, M> {
    type Nodes<U: Element> = [U; N];
    type Boundaries<U: Element> = [U; B];
    type Inputs<U: Element> = [U; M];

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
    fn nodes_of<U: Element + Copy>(&self, fill: U) -> [U; N] {
        [fill; N]
    }

    #[inline(always)]
    fn boundaries_of<U: Element + Copy>(&self, fill: U) -> [U; B] {
        [fill; B]
    }

    #[inline(always)]
    fn inputs_of<U: Element + Copy>(&self, fill: U) -> [U; M] {
        [fill; M]
    }

    fn rows_of<U: Element>(&self, row: U) -> [U; N] {
        core::array::from_fn(|_| row.clone())
    }
}

#[cfg(feature = "alloc")]
pub use run_time::RunTimeSizes;

#[cfg(feature = "alloc")]
mod run_time {
    use alloc::vec;
    use alloc::vec::Vec;

    use super::{Element, Sizes};

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
        type Nodes<U: Element> = Vec<U>;
        type Boundaries<U: Element> = Vec<U>;
        type Inputs<U: Element> = Vec<U>;

        fn nodes(&self) -> usize {
            self.nodes
        }

        fn boundaries(&self) -> usize {
            self.boundaries
        }

        fn inputs(&self) -> usize {
            self.inputs
        }

        fn nodes_of<U: Element + Copy>(&self, fill: U) -> Vec<U> {
            vec![fill; self.nodes]
        }

        fn boundaries_of<U: Element + Copy>(&self, fill: U) -> Vec<U> {
            vec![fill; self.boundaries]
        }

        fn inputs_of<U: Element + Copy>(&self, fill: U) -> Vec<U> {
            vec![fill; self.inputs]
        }

        fn rows_of<U: Element>(&self, row: U) -> Vec<U> {
            vec![row; self.nodes]
        }
    }
}
