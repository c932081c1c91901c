//! The hot path: the per-tick Joule account and the grid update.
//!
//! Both are bounded loops over `[[S; COLS]; ROWS]` with const bounds, no
//! allocation, no reachable panic (every neighbour row and column range is
//! taken with `get`, which cannot fail for the ranges built here).
//!
//! # Spreading the update
//!
//! [`CoilGrid::tick`] does the whole grid update in the tick that completes
//! `ticks_per_update`, which makes that tick the most expensive one by far on
//! an MCU. [`CoilGrid::tick_spread`] gives bit-identical temperatures with
//! bounded work in every tick, keeping an [`UpdateWork`] beside the state:
//!
//! * the heat from the neighbouring coils depends only on the temperatures of
//!   the last update, so it is summed a few rows per tick while the squared
//!   currents accumulate (the update tick sums whatever rows are left);
//! * `R(T) tick_dt` depends only on those temperatures too, so the ticks
//!   add `I^2` alone and the update multiplies the sum by it once per coil.
//!
//! Both paths share one update order (neighbour heat summed apart, in
//! direction order, then added to the Joule and boundary terms), which is
//! what makes them agree to the bit in floating point; the unit tests check
//! it for several shapes, decimations and bad inputs.

use core::ops::Range;

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

/// The part of the next grid update done ahead by [`CoilGrid::tick_spread`],
/// kept beside a [`GridState`] (per device, not part of a snapshot: it is
/// derived from the state by [`CoilGrid::update_work`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UpdateWork<S, const ROWS: usize, const COLS: usize> {
    /// Heat from the neighbouring coils over the coming grid step \[J\], for
    /// the rows before `rows_done`.
    neighbour_j: [[S; COLS]; ROWS],
    /// `R(T) tick_dt` \[ohm s\] of each coil at the temperature of the last
    /// update, for the rows before `rows_done`: taken in the ticks between
    /// updates so that the update tick only multiplies it by `sum I^2`.
    r_tick_dt: [[S; COLS]; ROWS],
    /// Rows whose neighbour heat and `R(T) tick_dt` are done.
    rows_done: usize,
}

impl<S, const ROWS: usize, const COLS: usize> UpdateWork<S, ROWS, COLS> {
    /// Rows of the next update prepared so far: it changes in the ticks
    /// that prepare one.
    pub fn rows_done(&self) -> usize {
        self.rows_done
    }
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
    /// One controller tick: accepts the inputs, adds this tick's `I^2` to
    /// every coil's Joule account, and every `ticks_per_update` ticks
    /// updates the temperatures (with the energy `R(T) tick_dt sum I^2`).
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
        flags |= self.accept_boundaries(state, coolant_c, ambient_c);
        state.pending_ticks = state.pending_ticks.saturating_add(1);
        let updated = state.pending_ticks >= self.config.ticks_per_update;
        if updated {
            self.update(state);
        }
        TickOutcome { flags, updated }
    }

    /// [`CoilGrid::tick`] with the update spread over the ticks between
    /// updates (see the module docs): the same temperatures to the bit, and
    /// no tick doing more than one update's final pass plus a slice of
    /// `ceil(ROWS / (ticks_per_update - 1))` rows of neighbour heat.
    ///
    /// `work` must come from [`CoilGrid::update_work`] on this state, and be
    /// made again whenever the state is replaced or its temperatures are
    /// written other than by this method; otherwise the next update uses
    /// the neighbour heat of the old temperatures for the rows already
    /// summed.
    pub fn tick_spread(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        work: &mut UpdateWork<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
        coolant_c: S,
        ambient_c: S,
    ) -> TickOutcome {
        // `ticks_spread(.., 1)` written out: the loop's bookkeeping costs
        // about a hundred instructions a tick on the M4F.
        let mut flags = self.accumulate_repeated(state, currents_a, 1);
        flags |= self.accept_boundaries(state, coolant_c, ambient_c);
        state.pending_ticks = state.pending_ticks.saturating_add(1);
        let updated = state.pending_ticks >= self.config.ticks_per_update;
        let rows_end = if updated {
            ROWS
        } else {
            work.rows_done.saturating_add(self.rows_per_tick).min(ROWS)
        };
        let rows = work.rows_done..rows_end;
        self.prepare_rows(&state.temps_c, work, rows);
        work.rows_done = rows_end;
        if updated {
            self.finish_update(state, work);
            work.rows_done = 0;
        }
        TickOutcome { flags, updated }
    }

    /// `ticks` calls of [`CoilGrid::tick_spread`] with the same inputs (a
    /// controller catching up on missed ticks), bit-identical to them, for
    /// less work: the inputs are checked once per update interval, each
    /// coil's `I^2` of one tick is computed once and added `ticks`
    /// times, and only one slice of neighbour heat is summed (the update
    /// tick sums what is left). `updated` is true if any of the ticks
    /// updated the grid. `ticks == 0` only applies the input rules
    /// ([`CoilGrid::accept_inputs`]): the inputs are flagged and held.
    pub fn ticks_spread(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        work: &mut UpdateWork<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
        coolant_c: S,
        ambient_c: S,
        ticks: u32,
    ) -> TickOutcome {
        let mut outcome = TickOutcome {
            flags: InputFlags::NONE,
            updated: false,
        };
        if ticks == 0 {
            // No step (an early tick, or no elapsed time): the inputs are
            // still checked, flagged and held, so that the next step uses
            // them and a bad one is never silent.
            outcome.flags = self.accept_inputs(state, currents_a, coolant_c, ambient_c);
            return outcome;
        }
        let mut remaining = ticks;
        let mut sliced = false;
        // At most two passes for a catch-up shorter than an update interval,
        // and at most `ticks` passes in any case (each takes at least one).
        while remaining > 0 {
            // The ticks up to and including the next update share `R(T)`.
            let to_update = self
                .config
                .ticks_per_update
                .saturating_sub(state.pending_ticks)
                .max(1);
            let batch = remaining.min(to_update);
            remaining -= batch;
            outcome.flags |= self.accumulate_repeated(state, currents_a, batch);
            // Accepting the same boundary `batch` times is accepting it once.
            outcome.flags |= self.accept_boundaries(state, coolant_c, ambient_c);
            state.pending_ticks = state.pending_ticks.saturating_add(batch);
            let updated = state.pending_ticks >= self.config.ticks_per_update;
            let rows_end = if updated {
                ROWS
            } else if sliced {
                work.rows_done
            } else {
                work.rows_done.saturating_add(self.rows_per_tick).min(ROWS)
            };
            sliced = true;
            let rows = work.rows_done..rows_end;
            self.prepare_rows(&state.temps_c, work, rows);
            work.rows_done = rows_end;
            if updated {
                self.finish_update(state, work);
                work.rows_done = 0;
                outcome.updated = true;
            }
        }
        outcome
    }

    /// Ticks after an update in which [`CoilGrid::tick_spread`] prepares a
    /// row of the next update (the first ones of each interval).
    pub fn row_ticks(&self) -> u32 {
        let ticks = ROWS.div_ceil(self.rows_per_tick.max(1));
        u32::try_from(ticks).unwrap_or(u32::MAX)
    }

    /// A fresh [`UpdateWork`] for `state`: no neighbour heat summed yet.
    pub fn update_work(&self, _state: &GridState<S, ROWS, COLS>) -> UpdateWork<S, ROWS, COLS> {
        UpdateWork {
            neighbour_j: [[S::ZERO; COLS]; ROWS],
            r_tick_dt: [[S::ZERO; COLS]; ROWS],
            rows_done: 0,
        }
    }

    /// The Joule energy \[J\] of each coil accumulated since the last
    /// update, what the next update adds: `R(T) tick_dt sum I^2`, `R` at
    /// the present (last updated) temperature.
    pub fn pending_joule_j(&self, state: &GridState<S, ROWS, COLS>) -> [[S; COLS]; ROWS] {
        let mut joule_j = [[S::ZERO; COLS]; ROWS];
        let rows = joule_j
            .iter_mut()
            .zip(&state.temps_c)
            .zip(&state.pending_current_sq_a2);
        for ((e_row, t_row), i2_row) in rows {
            for ((e, t), i2) in e_row.iter_mut().zip(t_row).zip(i2_row) {
                *e = self.r_tick_dt(*t) * *i2;
            }
        }
        joule_j
    }

    /// `R(T) tick_dt` \[ohm s\] at coil temperature `temp_c` \[degC\],
    /// clamped to the input limits' temperature range: beyond it the winding
    /// has failed anyway, and a bounded `R` keeps a runaway estimate finite.
    ///
    /// Plain comparisons rather than [`Scalar::clamp_to`]: they differ only
    /// for a NaN temperature, whose coil is NaN after its next update
    /// whatever its Joule energy (the boundary terms carry the NaN), and they
    /// save eight instructions per coil of an update on an M4F.
    #[inline(always)]
    fn r_tick_dt(&self, temp_c: S) -> S {
        let (lo, hi) = (self.limits.min_temp_c, self.limits.max_temp_c);
        let t = if temp_c < lo {
            lo
        } else if temp_c > hi {
            hi
        } else {
            temp_c
        };
        let r = self.r_at_0c_tick_dt + self.slope_tick_dt * t;
        if r > S::ZERO {
            r
        } else {
            S::ZERO
        }
    }

    /// Applies the input rules of [`crate::input`] to every current and to
    /// the coolant and ambient, updating the held values the next step
    /// uses, without stepping or accumulating anything; says which rules
    /// fired. What [`CoilGrid::ticks_spread`] does for `ticks == 0`.
    pub fn accept_inputs(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
        coolant_c: S,
        ambient_c: S,
    ) -> InputFlags {
        let mut flags = self.accept_boundaries(state, coolant_c, ambient_c);
        for (incoming, held) in currents_a.iter().zip(state.held_currents_a.iter_mut()) {
            flags |= self.limits.accept_currents(incoming, held);
        }
        flags
    }

    fn accept_boundaries(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        coolant_c: S,
        ambient_c: S,
    ) -> InputFlags {
        self.limits
            .accept_temperature(coolant_c, &mut state.held_coolant_c)
            | self
                .limits
                .accept_temperature(ambient_c, &mut state.held_ambient_c)
    }

    /// The cheap per-tick part of [`CoilGrid::tick`]: accepts the currents
    /// and adds each coil's held `I^2` \[A^2\] to its pending account
    /// ([`GridState::pending_current_sq_a2`]; the next update turns it into
    /// Joule energy with `R` at the temperature it starts from, see
    /// [`CoilGrid::pending_joule_j`]). Does not count the tick.
    pub fn accumulate(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
    ) -> InputFlags {
        self.accumulate_repeated(state, currents_a, 1)
    }

    /// [`CoilGrid::accumulate`] `ticks` times (at least once). A current
    /// within the limits (the usual case) is taken with one comparison;
    /// anything else goes through the full input rules.
    fn accumulate_repeated(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
        ticks: u32,
    ) -> InputFlags {
        // Two copies of the loop: the repeat loop in the one-tick case
        // (every tick but a catch-up) would double its cost.
        if ticks > 1 {
            self.accumulate_loop::<true>(state, currents_a, ticks)
        } else {
            self.accumulate_loop::<false>(state, currents_a, 1)
        }
    }

    #[inline(always)]
    fn accumulate_loop<const REPEAT: bool>(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        currents_a: &[[S; COLS]; ROWS],
        ticks: u32,
    ) -> InputFlags {
        let mut flags = InputFlags::NONE;
        let max_a = self.limits.max_current_a;
        let max_sq_a2 = max_a * max_a;
        let rows = currents_a
            .iter()
            .zip(state.held_currents_a.iter_mut())
            .zip(state.pending_current_sq_a2.iter_mut());
        for ((incoming, held), pending) in rows {
            if !REPEAT && S::CHEAP_MULTIPLY {
                // The usual row: the sum of its squares below the square
                // of the limit (false for a NaN or an infinity) puts every
                // current within the limit (rounding is monotonic, so a
                // current above it has a square, and the row a sum, at
                // least `max_sq_a2`). Two instructions a coil here save a
                // compare and branch a coil below (9 -> 7 on an M4F); the
                // squares added are the same.
                let mut sum_sq = S::ZERO;
                for &i in incoming {
                    sum_sq += i * i;
                }
                if sum_sq < max_sq_a2 {
                    for ((&i, held), i2) in
                        incoming.iter().zip(held.iter_mut()).zip(pending.iter_mut())
                    {
                        *held = i;
                        *i2 += i * i;
                    }
                    continue;
                }
            }
            let coils = incoming.iter().zip(held.iter_mut()).zip(pending.iter_mut());
            for ((&i, held), i2) in coils {
                // `abs(i) <= max` is false for a NaN: those take the rules,
                // out of line so that the loop body stays small.
                if i.abs() <= max_a {
                    *held = i;
                } else {
                    flags |= self.accept_current_cold(i, held);
                }
                // The same square added `ticks` times, in sequence: the
                // bits of `ticks` separate ticks.
                let square = *held * *held;
                *i2 += square;
                if REPEAT {
                    for _ in 1..ticks {
                        *i2 += square;
                    }
                }
            }
        }
        flags
    }

    #[cold]
    #[inline(never)]
    fn accept_current_cold(&self, incoming_a: S, held_a: &mut S) -> InputFlags {
        self.limits.accept_current(incoming_a, held_a)
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
        let mut neighbour_j = [[S::ZERO; COLS]; ROWS];
        self.neighbour_heat(&state.temps_c, &mut neighbour_j, 0..ROWS);
        self.finish_update_unprepared(state, &mut neighbour_j);
    }

    /// The part of the next update that depends only on the present
    /// temperatures, for the coils of `rows`: the neighbour heat and
    /// `R(T) tick_dt`.
    fn prepare_rows(
        &self,
        temps_c: &[[S; COLS]; ROWS],
        work: &mut UpdateWork<S, ROWS, COLS>,
        rows: Range<usize>,
    ) {
        let (Some(t_rows), Some(r_rows)) = (
            temps_c.get(rows.clone()),
            work.r_tick_dt.get_mut(rows.clone()),
        ) else {
            return;
        };
        for (t_row, r_row) in t_rows.iter().zip(r_rows) {
            for (t, r) in t_row.iter().zip(r_row) {
                *r = self.r_tick_dt(*t);
            }
        }
        self.neighbour_heat(temps_c, &mut work.neighbour_j, rows);
    }

    /// Adds the heat each coil of `rows` receives from its neighbouring
    /// coils over one grid step, `sum_d G_d dt (T_d - T)` \[J\], to
    /// `neighbour_j`, directions in [`DIRECTIONS`] order.
    fn neighbour_heat(
        &self,
        temps_c: &[[S; COLS]; ROWS],
        neighbour_j: &mut [[S; COLS]; ROWS],
        rows: Range<usize>,
    ) {
        for row in rows {
            let (Some(t_row), Some(e_row)) = (temps_c.get(row), neighbour_j.get_mut(row)) else {
                return;
            };
            // One call per direction, in `DIRECTIONS` order, each with its
            // offsets known at compile time: straight-line loads instead of
            // run-time column ranges.
            self.neighbour_direction::<0>(row, temps_c, t_row, e_row);
            self.neighbour_direction::<1>(row, temps_c, t_row, e_row);
            self.neighbour_direction::<2>(row, temps_c, t_row, e_row);
            self.neighbour_direction::<3>(row, temps_c, t_row, e_row);
            self.neighbour_direction::<4>(row, temps_c, t_row, e_row);
            self.neighbour_direction::<5>(row, temps_c, t_row, e_row);
            self.neighbour_direction::<6>(row, temps_c, t_row, e_row);
            self.neighbour_direction::<7>(row, temps_c, t_row, e_row);
        }
    }

    /// The heat coil row `row` receives from its neighbours in direction
    /// `DIRECTIONS[D]`, added to `e_row`.
    #[inline(always)]
    fn neighbour_direction<const D: usize>(
        &self,
        row: usize,
        temps_c: &[[S; COLS]; ROWS],
        t_row: &[S; COLS],
        e_row: &mut [S; COLS],
    ) {
        let (Some(&(d_row, d_col)), Some(g_d), Some(used)) = (
            DIRECTIONS.get(D),
            self.neighbour_g_dt.get(D),
            self.direction_used.get(D),
        ) else {
            return;
        };
        if !used[row % 2] {
            return;
        }
        let (c_lo, c_hi) = inner_range(COLS, d_col);
        let (n_lo, n_hi) = (
            c_lo.wrapping_add_signed(d_col),
            c_hi.wrapping_add_signed(d_col),
        );
        let n_row = row.wrapping_add_signed(d_row);
        let (Some(t), Some(n), Some(g), Some(e)) = (
            t_row.get(c_lo..c_hi),
            temps_c.get(n_row).and_then(|r| r.get(n_lo..n_hi)),
            g_d.get(row).and_then(|r| r.get(c_lo..c_hi)),
            e_row.get_mut(c_lo..c_hi),
        ) else {
            // The neighbour row is outside the grid.
            return;
        };
        for (((e, g), t), n) in e.iter_mut().zip(g).zip(t).zip(n) {
            *e += *g * (*n - *t);
        }
    }

    /// The rest of the update once every row is prepared in `work`
    /// (its neighbour heat cleared here): Joule and boundary terms and the
    /// compensated temperature step.
    fn finish_update(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        work: &mut UpdateWork<S, ROWS, COLS>,
    ) {
        let (coolant, ambient) = (state.held_coolant_c, state.held_ambient_c);
        let rows = state
            .temps_c
            .iter_mut()
            .zip(state.carry_c.iter_mut())
            .zip(state.pending_current_sq_a2.iter_mut())
            .zip(work.neighbour_j.iter_mut().zip(&work.r_tick_dt))
            .zip(&self.ambient_g_dt);
        for ((((t_row, carry_row), i2_row), (n_row, r_row)), g_amb_row) in rows {
            let coils = t_row
                .iter_mut()
                .zip(carry_row.iter_mut())
                .zip(i2_row.iter_mut())
                .zip(n_row.iter_mut().zip(r_row))
                .zip(g_amb_row);
            for ((((t, carry), i2), (n, r_dt)), g_amb) in coils {
                self.step_coil(t, carry, i2, n, *r_dt, *g_amb, coolant, ambient);
            }
        }
        state.pending_ticks = 0;
    }

    /// [`CoilGrid::finish_update`] with `R(T) tick_dt` taken here, for the
    /// update of [`CoilGrid::update`] that nothing prepared (storing it
    /// first would cost a store and a load per coil).
    fn finish_update_unprepared(
        &self,
        state: &mut GridState<S, ROWS, COLS>,
        neighbour_j: &mut [[S; COLS]; ROWS],
    ) {
        let (coolant, ambient) = (state.held_coolant_c, state.held_ambient_c);
        let rows = state
            .temps_c
            .iter_mut()
            .zip(state.carry_c.iter_mut())
            .zip(state.pending_current_sq_a2.iter_mut())
            .zip(neighbour_j.iter_mut())
            .zip(&self.ambient_g_dt);
        for ((((t_row, carry_row), i2_row), n_row), g_amb_row) in rows {
            let coils = t_row
                .iter_mut()
                .zip(carry_row.iter_mut())
                .zip(i2_row.iter_mut())
                .zip(n_row.iter_mut())
                .zip(g_amb_row);
            for ((((t, carry), i2), n), g_amb) in coils {
                let r_dt = self.r_tick_dt(*t);
                self.step_coil(t, carry, i2, n, r_dt, *g_amb, coolant, ambient);
            }
        }
        state.pending_ticks = 0;
    }

    /// One coil's step: Joule, boundary and neighbour heat \[J\], then the
    /// compensated temperature step; clears its accounts.
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn step_coil(
        &self,
        t: &mut S,
        carry: &mut S,
        i2: &mut S,
        n: &mut S,
        r_dt: S,
        g_amb: S,
        coolant: S,
        ambient: S,
    ) {
        let mut e = r_dt * *i2;
        e += self.base_g_dt * (coolant - *t) + g_amb * (ambient - *t);
        e += *n;
        // Fast2Sum: `carry` keeps what `t + increment` rounded away.
        let increment = e * self.inverse_capacity + *carry;
        let new = *t + increment;
        *carry = increment - (new - *t);
        *t = new;
        *i2 = S::ZERO;
        *n = S::ZERO;
    }
}
