//! The hot path: the per-tick Joule account and the grid update.
//!
//! Both are bounded loops over `[[S; COLS]; ROWS]` with const bounds, no
//! allocation, no reachable panic (every neighbour row and column range is
//! taken with `get`, which cannot fail for the ranges built here).

use super::{CoilGrid, GridState, DIRECTIONS};
use crate::input::InputFlags;
use crate::scalar::Scalar;

/// What one [`CoilGrid::tick`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickOutcome {
    /// The input rules that fired (see [`crate::input`]).
    pub flags: InputFlags,
    /// `true` when this tick ran a grid update (every `ticks_per_update`).
    pub updated: bool,
}

/// Indices `[lo, hi)` of the cells whose neighbour at offset `d` along an
/// axis of length `len` (at least 1) is inside the axis.
#[inline(always)]
const fn inner_range(len: usize, d: isize) -> (usize, usize) {
    if d < 0 {
        (1, len)
    } else if d > 0 {
        (0, len - 1)
    } else {
        (0, len)
    }
}

impl<S: Scalar, const ROWS: usize, const COLS: usize> CoilGrid<S, ROWS, COLS> {
    /// One controller tick: accepts the inputs, adds this tick's Joule energy
    /// `R(T) I^2 tick_dt` of every coil, and every `ticks_per_update` ticks
    /// updates the temperatures.
    ///
    /// `currents_a[row][col]` \[A\] (the sign does not matter), `coolant_c`
    /// the water-cooled base \[degC\], `ambient_c` the air around the border
    /// \[degC\] (ignored, but still checked, with [`super::Border::Adiabatic`]).
    /// Bad inputs are held or clamped as in [`crate::input`].
    pub fn tick(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
        coolant_c: S,
        ambient_c: S,
    ) -> TickOutcome {
        let mut flags = self.accumulate(state, currents_a);
        flags |= self
            .limits
            .accept_temperature(coolant_c, &mut state.held_coolant_c);
        flags |= self
            .limits
            .accept_temperature(ambient_c, &mut state.held_ambient_c);
        state.pending_ticks = state.pending_ticks.saturating_add(1);
        let updated = state.pending_ticks >= self.config.ticks_per_update;
        if updated {
            self.update(state);
        }
        TickOutcome { flags, updated }
    }

    /// The cheap per-tick part of [`CoilGrid::tick`]: accepts the currents
    /// and adds `R(T) I^2 tick_dt` \[J\] to each coil's pending energy, with
    /// `R` at the last updated temperature. Does not count the tick.
    ///
    /// The temperature entering `R(T)` is clamped to the input limits'
    /// temperature range: beyond it the winding has failed anyway, and a
    /// bounded `R` keeps a runaway estimate finite.
    pub fn accumulate(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
    ) -> InputFlags {
        let mut flags = InputFlags::NONE;
        let (t_lo, t_hi) = (self.limits.min_temp_c, self.limits.max_temp_c);
        for (((incoming, held), temps), pending) in currents_a
            .iter()
            .zip(state.held_currents_a.iter_mut())
            .zip(&state.temps_c)
            .zip(state.pending_joule_j.iter_mut())
        {
            flags |= self.limits.accept_currents(incoming, held);
            for ((i, t), e) in held.iter().zip(temps).zip(pending.iter_mut()) {
                let r_dt = (self.r_at_0c_tick_dt + self.slope_tick_dt * t.clamp_to(t_lo, t_hi))
                    .max(S::ZERO);
                *e += r_dt * *i * *i;
            }
        }
        flags
    }

    /// One explicit grid step of `grid_dt_s` with the pending Joule energy
    /// and the held coolant and ambient temperatures; clears the pending
    /// energy and tick count. [`CoilGrid::tick`] calls it every
    /// `ticks_per_update` ticks; calling it at other times steps the grid by
    /// `grid_dt_s` all the same.
    ///
    /// Jacobi form: every flow is computed from the old temperatures, and
    /// the flow from `a` to `b` is the exact negative of the flow from `b`
    /// to `a` (same coefficient, negated difference), so heat moves between
    /// coils without loss.
    pub fn update(&self, state: &mut GridState<S, ROWS, COLS>) {
        let old = &state.temps_c;
        let coolant = state.held_coolant_c;
        let ambient = state.held_ambient_c;
        let mut energy_j = state.pending_joule_j;
        for ((e_row, t_row), g_amb_row) in energy_j.iter_mut().zip(old).zip(&self.ambient_g_dt) {
            for ((e, t), g_amb) in e_row.iter_mut().zip(t_row).zip(g_amb_row) {
                *e += self.base_g_dt * (coolant - *t) + *g_amb * (ambient - *t);
            }
        }
        for ((&(d_row, d_col), g_d), used) in DIRECTIONS
            .iter()
            .zip(&self.neighbour_g_dt)
            .zip(&self.direction_used)
        {
            let (r_lo, r_hi) = inner_range(ROWS, d_row);
            let (c_lo, c_hi) = inner_range(COLS, d_col);
            let (n_lo, n_hi) = (
                c_lo.wrapping_add_signed(d_col),
                c_hi.wrapping_add_signed(d_col),
            );
            for row in r_lo..r_hi {
                if !used[row % 2] {
                    continue;
                }
                let n_row = row.wrapping_add_signed(d_row);
                let (Some(t), Some(n), Some(g), Some(e)) = (
                    old.get(row).and_then(|r| r.get(c_lo..c_hi)),
                    old.get(n_row).and_then(|r| r.get(n_lo..n_hi)),
                    g_d.get(row).and_then(|r| r.get(c_lo..c_hi)),
                    energy_j.get_mut(row).and_then(|r| r.get_mut(c_lo..c_hi)),
                ) else {
                    continue;
                };
                for (((e, g), t), n) in e.iter_mut().zip(g).zip(t).zip(n) {
                    *e += *g * (*n - *t);
                }
            }
        }
        for ((t_row, carry_row), e_row) in state
            .temps_c
            .iter_mut()
            .zip(state.carry_c.iter_mut())
            .zip(&energy_j)
        {
            for ((t, carry), e) in t_row.iter_mut().zip(carry_row.iter_mut()).zip(e_row) {
                // Fast2Sum: `carry` keeps what `t + increment` rounded away.
                let increment = *e * self.inverse_capacity + *carry;
                let new = *t + increment;
                *carry = increment - (new - *t);
                *t = new;
            }
        }
        state.pending_joule_j = [[S::ZERO; COLS]; ROWS];
        state.pending_ticks = 0;
    }
}
