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
//! # How `Ry` is shared between the contacts of one side
//!
//! A fitted `Ry` is the resistance from a coil to the *row* beside it: the
//! report fitted one number per direction, whatever the stencil. A
//! herringbone coil meets that row through two contacts, each along half of
//! its side, so each contact carries half the area and twice the
//! resistance: `2 Ry` each, `Ry` for the side. In general a stencil with `k`
//! cross-row contacts on a side joins each through `k Ry`
//! ([`Stencil::cross_row_contacts`]), so every stencil gives a coil the same
//! cross-row conductance `1 / Ry` per side and a parameter set means the
//! same physics with the brick and the rectangular stencil.
//!
//! The measurement decides it (hppa-coil-grid.md, the report's Figure 26:
//! one coil alone rises about 0.35 times as much as all coils on, at equal
//! power per coil). With the report's FDM fit on the 7 x 12 grid, sharing
//! gives 0.36; the full `Ry` on each of the two contacts (twice the
//! cross-row conductance) gives 0.28, and with the digest's halved values
//! 0.20: half the single-coil rise, the unsafe direction for hottest-coil
//! limiting (`grid::tests::one_coil_rises_a_third_of_all_coils_as_measured`).
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

    /// The number `k` of cross-row contacts a coil has on one side, over
    /// which its `Ry` is shared (each contact `k Ry`, see the module docs);
    /// zero for a stencil without cross-row links.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] when the sides or the parities have
    /// different counts: the contacts' conductances could not be symmetric.
    pub fn cross_row_contacts(&self) -> Result<u8, BuildError> {
        let count = |matrix: &[[Link; 3]; 3], side: usize| {
            matrix[side].iter().filter(|&&l| l == Link::Y).count() as u8
        };
        let k = count(&self.even, 0);
        let all = [
            count(&self.even, 2),
            count(&self.odd, 0),
            count(&self.odd, 2),
        ];
        if all.iter().any(|&c| c != k) {
            return Err(BuildError::InvalidParameter {
                name: "stencil: sides with different numbers of cross-row contacts",
            });
        }
        Ok(k)
    }

    /// Checks that no coil links to itself, that every link has its reverse
    /// through the same resistance, for both parities, that no in-row link
    /// goes through `Ry` (nor a cross-row one through `Rx`), and that every
    /// side has the same number of cross-row contacts.
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
        for matrix in [&self.even, &self.odd] {
            let in_row_y = matrix[1].contains(&Link::Y);
            let cross_x = matrix[0].contains(&Link::X) || matrix[2].contains(&Link::X);
            if in_row_y || cross_x {
                return Err(BuildError::InvalidParameter {
                    name: "stencil: Rx links a row, Ry links rows",
                });
            }
        }
        self.cross_row_contacts().map(|_| ())
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
    fn herringbone_shares_ry_between_two_contacts_per_side() {
        assert_eq!(Stencil::HPPA_HERRINGBONE.cross_row_contacts(), Ok(2));
        assert_eq!(Stencil::RECTANGULAR.cross_row_contacts(), Ok(1));
        let mut one_sided = Stencil::HPPA_HERRINGBONE;
        one_sided.even[0][0] = Link::None;
        one_sided.odd[2][2] = Link::None;
        assert!(one_sided.cross_row_contacts().is_err());
        assert!(one_sided.validate().is_err());
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
