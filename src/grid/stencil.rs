//! Which coils touch which: the neighbour stencil, as data.
//!
//! The HPPA report writes the finite-difference update with one 3x3
//! conductance matrix for even ("pair") rows and another for odd ("impair")
//! rows, because the herringbone rows are offset. A [`Stencil`] is exactly
//! that: two 3x3 matrices of [`Link`]s, indexed `[d_row + 1][d_col + 1]`, that
//! say through which resistance (`Rx` in a row, `Ry` across rows, or none) a
//! coil at `(row, col)` is joined to the coil at `(row + d_row, col + d_col)`.
//! Row 0 is even.
//!
//! # The HPPA interpretation
//!
//! Neighbouring rows are offset by half a coil (a brick pattern), odd rows
//! shifted towards larger columns. So a coil in an even row at column `c`
//! touches the rows above and below at columns `c - 1` and `c`; a coil in an
//! odd row touches them at `c` and `c + 1`; in its own row it touches `c - 1`
//! and `c + 1` through `Rx`. Cross-row contacts use `Ry`:
//!
//! ```text
//!   even rows          odd rows
//!   Y  Y  .            .  Y  Y
//!   X  .  X            X  .  X
//!   Y  Y  .            .  Y  Y
//! ```
//!
//! [`Stencil::RECTANGULAR`] is the plain 4-neighbour grid.
//!
//! # Symmetry
//!
//! A link from `(r, c)` to `(r', c')` must have its reverse, through the same
//! resistance, in the stencil of row `r'`: otherwise one coil would send heat
//! that the other does not receive. [`Stencil::validate`] checks it for every
//! parity pair (so for any grid size) and the grid refuses an asymmetric
//! stencil at build time.

use crate::error::BuildError;

/// The resistance joining a coil to one neighbour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Link {
    /// Not joined.
    None,
    /// Joined through `Rx` (in-row neighbour).
    X,
    /// Joined through `Ry` (cross-row neighbour).
    Y,
}

/// The neighbour stencil per row parity (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stencil {
    /// Links of a coil in an even row, indexed `[d_row + 1][d_col + 1]`.
    pub even: [[Link; 3]; 3],
    /// Links of a coil in an odd row, indexed `[d_row + 1][d_col + 1]`.
    pub odd: [[Link; 3]; 3],
}

const N: Link = Link::None;
const X: Link = Link::X;
const Y: Link = Link::Y;

impl Stencil {
    /// The HPPA herringbone (brick) pattern: odd rows offset by half a coil.
    pub const HPPA_HERRINGBONE: Self = Self {
        even: [[Y, Y, N], [X, N, X], [Y, Y, N]],
        odd: [[N, Y, Y], [X, N, X], [N, Y, Y]],
    };

    /// The plain rectangular 4-neighbour stencil.
    pub const RECTANGULAR: Self = Self {
        even: [[N, Y, N], [X, N, X], [N, Y, N]],
        odd: [[N, Y, N], [X, N, X], [N, Y, N]],
    };

    /// The link of a coil in row `row` to its neighbour at offset
    /// `(d_row, d_col)`; [`Link::None`] for offsets outside `-1..=1`.
    pub fn link(&self, row: usize, d_row: isize, d_col: isize) -> Link {
        let matrix = if row.is_multiple_of(2) {
            &self.even
        } else {
            &self.odd
        };
        let index = |d: isize| usize::try_from(d + 1).ok();
        match (index(d_row), index(d_col)) {
            (Some(i), Some(j)) => matrix
                .get(i)
                .and_then(|m| m.get(j))
                .copied()
                .unwrap_or(Link::None),
            _ => Link::None,
        }
    }

    /// Checks that no coil links to itself and that every link has its
    /// reverse through the same resistance, for both parities.
    pub fn validate(&self) -> Result<(), BuildError> {
        if self.even[1][1] != Link::None || self.odd[1][1] != Link::None {
            return Err(BuildError::InvalidParameter {
                name: "stencil: coil linked to itself",
            });
        }
        for row in 0..2usize {
            for d_row in -1..=1isize {
                for d_col in -1..=1isize {
                    // Row parity flips when the offset crosses one row.
                    let other_row = row + d_row.unsigned_abs();
                    if self.link(row, d_row, d_col) != self.link(other_row, -d_row, -d_col) {
                        return Err(BuildError::InvalidParameter {
                            name: "stencil: link without its reverse",
                        });
                    }
                }
            }
        }
        Ok(())
    }
}

impl Default for Stencil {
    /// [`Stencil::HPPA_HERRINGBONE`].
    fn default() -> Self {
        Self::HPPA_HERRINGBONE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_built_in_stencils_are_symmetric() {
        assert!(Stencil::HPPA_HERRINGBONE.validate().is_ok());
        assert!(Stencil::RECTANGULAR.validate().is_ok());
    }

    #[test]
    fn herringbone_even_row_touches_c_minus_1_and_c() {
        let s = Stencil::HPPA_HERRINGBONE;
        assert_eq!(s.link(0, 1, -1), Link::Y);
        assert_eq!(s.link(0, 1, 0), Link::Y);
        assert_eq!(s.link(0, 1, 1), Link::None);
        assert_eq!(s.link(1, -1, 1), Link::Y);
        assert_eq!(s.link(1, -1, -1), Link::None);
        assert_eq!(s.link(3, 0, -1), Link::X);
        assert_eq!(s.link(0, 2, 0), Link::None);
    }

    #[test]
    fn asymmetric_or_self_linked_stencils_are_refused() {
        let mut s = Stencil::HPPA_HERRINGBONE;
        s.odd[0][2] = Link::None;
        assert!(s.validate().is_err());
        let mut s = Stencil::RECTANGULAR;
        s.even[1][2] = Link::Y;
        assert!(s.validate().is_err());
        let mut s = Stencil::RECTANGULAR;
        s.odd[1][1] = Link::X;
        assert!(s.validate().is_err());
    }
}
