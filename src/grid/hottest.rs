//! Hottest-coil queries, for derating and alarms: no allocation, `O(ROWS *
//! COLS * K)` comparisons.

use super::GridState;
use crate::scalar::Scalar;

/// One coil and its temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CoilTemp<S> {
    /// Row of the coil.
    pub row: usize,
    /// Column of the coil.
    pub col: usize,
    /// Its temperature \[degC\].
    pub temp_c: S,
}

impl<S: Scalar, const ROWS: usize, const COLS: usize> GridState<S, ROWS, COLS> {
    /// The hottest coil; the first in row-major order on a tie. The same
    /// as `hottest_k::<1>()` (a test checks it), in one comparison per coil.
    pub fn hottest(&self) -> CoilTemp<S> {
        let mut top = CoilTemp {
            row: 0,
            col: 0,
            temp_c: self
                .temps_c
                .first()
                .and_then(|r| r.first())
                .copied()
                .unwrap_or(S::ZERO),
        };
        for (row, temps) in self.temps_c.iter().enumerate() {
            for (col, &temp_c) in temps.iter().enumerate() {
                // Strict `>`: the earlier coil stays ahead on a tie (and a
                // NaN never takes the place, as in `hottest_k`).
                if temp_c > top.temp_c {
                    top = CoilTemp { row, col, temp_c };
                }
            }
        }
        top
    }

    /// The `K` hottest coils, hottest first, ties in row-major order.
    /// `K` may not exceed `ROWS * COLS` (checked at compile time).
    pub fn hottest_k<const K: usize>(&self) -> [CoilTemp<S>; K] {
        const { assert!(K <= ROWS * COLS, "K exceeds the number of coils") };
        let mut top = [CoilTemp {
            row: 0,
            col: 0,
            temp_c: S::ZERO,
        }; K];
        let mut filled = 0;
        for (row, temps) in self.temps_c.iter().enumerate() {
            for (col, &temp_c) in temps.iter().enumerate() {
                let candidate = CoilTemp { row, col, temp_c };
                // Insertion into the sorted prefix; strict `>` keeps the
                // earlier coil ahead on a tie.
                let mut at = filled.min(K);
                while at > 0 && top.get(at - 1).is_some_and(|t| temp_c > t.temp_c) {
                    at -= 1;
                }
                if at < K {
                    let end = filled.min(K - 1);
                    if let Some(slice) = top.get_mut(at..=end) {
                        slice.rotate_right(1);
                        slice[0] = candidate;
                    }
                    filled = (filled + 1).min(K);
                }
            }
        }
        top
    }
}
