//! The HPPA coil grid: one thermal node per stator coil of a planar actuator.
//!
//! The Herringbone Pattern Planar Actuator report (Stoeck, TU/e 2011) tracks
//! every coil's temperature with an explicit finite-difference model fast
//! enough for the 1 ms control loop. This module is that model on the
//! network core's rules, for a grid of `ROWS x COLS` coils in any
//! [`Scalar`]:
//!
//! ```text
//! C dT_rc/dt = R(T_rc) I_rc^2 + sum_k G_k (T_k - T_rc) + (T_coolant - T_rc) / Rz
//! ```
//!
//! * neighbours `k` from a [`Stencil`] per row parity (herringbone by
//!   default), joined by `G = 1/Rx` in a row and `1/Ry` to each neighbouring
//!   row, shared by that side's contacts (`1/(2 Ry)` each in the
//!   herringbone, see [`stencil`]); `Rx`, `Ry` are the resistances *between
//!   two coils* (see [`params`] for how each of the report's tables is
//!   read);
//! * a neighbour outside the grid is the report's padding cell at the
//!   measured ambient temperature, joined through the same resistance, or
//!   nothing at all with [`Border::Adiabatic`];
//! * `R(T)` is the HPPA fit `0.026 T + 5.166` ohm by default
//!   ([`Resistance::HPPA_COIL`]), or any [`Resistance`];
//! * the coolant (base) and ambient temperatures are inputs every tick.
//!
//! # Multi-rate
//!
//! The controller calls [`CoilGrid::tick`] at its own rate (`tick_dt_s`,
//! 1 ms for the HPPA). Each tick only adds `I^2` to a per-coil account;
//! every `ticks_per_update` ticks the grid takes one explicit step of
//! `ticks_per_update * tick_dt_s` with the Joule energy of all those ticks,
//! `R(T) tick_dt sum I^2` (`R` at the last updated temperature, the same for
//! every tick of the interval, so one multiply per coil per update gives
//! what a multiply per tick would). No Joule
//! heat is lost by decimating: the only differences from updating every tick
//! are that `R(T)` and the heat flows are evaluated at the last updated
//! temperatures (a lag of at most one grid step) and that the coolant and
//! ambient temperatures are those held at the update tick. The report found a
//! thermal cycle of seconds adequate; the host tests bound the difference.
//!
//! On an MCU, [`CoilGrid::tick_spread`] gives the same temperatures to the bit
//! with the update's work spread over the ticks in between (see
//! [`UpdateWork`]), so no tick carries the whole update.
//!
//! # Precision
//!
//! A 1 ms increment of a coil is about `1e-4` K, within a few ulps of a
//! 50 degC `f32`, so plain `T += dT` would stall a degree short of steady
//! state. Each coil carries the rounding residue of its last update
//! ([`GridState::carry_c`], compensated summation), which makes `f32` track
//! the `f64` reference to millikelvin; for fixed point the residue is zero.
//!
//! # Stability
//!
//! The explicit step is a weighted average of old temperatures when
//! `dt sum(G) / C < 1` at every coil; [`CoilGrid::new`] refuses any other grid
//! step with [`BuildError::UnstableStep`].

mod hottest;
pub mod params;
pub mod stencil;
mod step;

pub use hottest::CoilTemp;
pub use params::{Convention, GridParams, HppaPreset};
pub use stencil::{Link, Stencil};
pub use step::{TickOutcome, UpdateWork};

use crate::error::BuildError;
use crate::input::{InputLimits, ScalarLimits};
use crate::network::{Network, Resistance};
use crate::scalar::Scalar;

/// What lies beyond the border coils.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Border {
    /// The report's one-cell padding at the measured ambient temperature:
    /// every stencil link that leaves the grid goes to ambient through its
    /// own `Rx` or `Ry`.
    Ambient,
    /// No heat crosses the border (for symmetry and steady-state checks).
    Adiabatic,
}

/// The whole build-time description of a grid, in SI units and `f64`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridConfig {
    /// Thermal parameters, stored between coils.
    pub params: GridParams,
    /// Neighbour stencil per row parity.
    pub stencil: Stencil,
    /// Border model.
    pub border: Border,
    /// Coil resistance `R(T)` \[ohm\], the same for every coil; must be
    /// positive over the limits' temperature range.
    pub resistance: Resistance,
    /// Interval between calls of [`CoilGrid::tick`] \[s\].
    pub tick_dt_s: f64,
    /// Ticks per grid update (1: update every tick).
    pub ticks_per_update: u32,
    /// Plausible input ranges (see [`crate::input`]).
    pub limits: InputLimits,
}

impl GridConfig {
    /// The HPPA defaults with these parameters: herringbone stencil, ambient
    /// padding, `R(T) = 0.026 T + 5.166` ohm, 1 ms ticks, update every tick.
    pub const fn hppa(params: GridParams) -> Self {
        Self {
            params,
            stencil: Stencil::HPPA_HERRINGBONE,
            border: Border::Ambient,
            resistance: Resistance::HPPA_COIL,
            tick_dt_s: 1e-3,
            ticks_per_update: 1,
            limits: InputLimits {
                max_current_a: 100.0,
                min_temp_c: -60.0,
                max_temp_c: 400.0,
            },
        }
    }
}

impl Default for GridConfig {
    /// [`GridConfig::hppa`] with [`GridParams::FDM_FITTED`].
    fn default() -> Self {
        Self::hppa(GridParams::FDM_FITTED)
    }
}

/// Neighbour offsets `(d_row, d_col)`, the order of the coefficient arrays
/// (and of the grid observer's per-direction tables).
pub(crate) const DIRECTIONS: [(isize, isize); 8] = [
    (-1, -1),
    (-1, 0),
    (-1, 1),
    (0, -1),
    (0, 1),
    (1, -1),
    (1, 0),
    (1, 1),
];

/// A validated coil grid: immutable configuration and the precomputed
/// per-coil coefficients of the hot path. Shareable; the per-device state is
/// [`GridState`].
#[derive(Debug, Clone)]
pub struct CoilGrid<S, const ROWS: usize, const COLS: usize> {
    pub(crate) config: GridConfig,
    pub(crate) stability_ratio: f64,
    /// `G dt` per grid step \[J/K\] towards each direction; zero where there
    /// is no link or the neighbour is outside the grid.
    pub(crate) neighbour_g_dt: [[[S; COLS]; ROWS]; 8],
    /// Whether direction `d` has any link in even (`[d][0]`) / odd rows.
    pub(crate) direction_used: [[bool; 2]; 8],
    /// `G dt` to the ambient padding per grid step \[J/K\].
    pub(crate) ambient_g_dt: [[S; COLS]; ROWS],
    /// `dt / Rz` per grid step \[J/K\].
    pub(crate) base_g_dt: S,
    /// `1 / C` \[K/J\].
    pub(crate) inverse_capacity: S,
    /// `R(0 degC) * tick_dt` \[ohm s\].
    pub(crate) r_at_0c_tick_dt: S,
    /// `dR/dT * tick_dt` \[ohm s / K\].
    pub(crate) slope_tick_dt: S,
    /// Rows of neighbour heat [`CoilGrid::tick_spread`] sums per tick.
    pub(crate) rows_per_tick: usize,
    pub(crate) limits: ScalarLimits<S>,
}

/// The per-device state of a grid: what a snapshot saves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridState<S, const ROWS: usize, const COLS: usize> {
    /// Coil temperatures \[degC\].
    pub temps_c: [[S; COLS]; ROWS],
    /// Rounding residue of each coil's last update \[K\], added to its next
    /// increment (compensated summation; always zero in fixed point).
    pub carry_c: [[S; COLS]; ROWS],
    /// Sum of the squared held currents of the ticks since the last grid
    /// update \[A^2\]: the update multiplies it by `R(T) tick_dt` at the
    /// temperatures it starts from (constant over the interval), one
    /// multiply per coil per update instead of per tick; see
    /// [`CoilGrid::pending_joule_j`] for the energy.
    pub pending_current_sq_a2: [[S; COLS]; ROWS],
    /// Ticks accumulated since the last grid update.
    pub pending_ticks: u32,
    /// Last valid current of each coil \[A\].
    pub held_currents_a: [[S; COLS]; ROWS],
    /// Last valid coolant (base) temperature \[degC\].
    pub held_coolant_c: S,
    /// Last valid ambient temperature \[degC\].
    pub held_ambient_c: S,
}

impl<S: Scalar, const ROWS: usize, const COLS: usize> GridState<S, ROWS, COLS> {
    /// Every coil, the coolant and the ambient at `temp_c` \[degC\], no current.
    pub fn uniform(temp_c: f64) -> Self {
        let t = S::from_f64(temp_c);
        Self {
            temps_c: [[t; COLS]; ROWS],
            carry_c: [[S::ZERO; COLS]; ROWS],
            pending_current_sq_a2: [[S::ZERO; COLS]; ROWS],
            pending_ticks: 0,
            held_currents_a: [[S::ZERO; COLS]; ROWS],
            held_coolant_c: t,
            held_ambient_c: t,
        }
    }
}

impl<S: Scalar, const ROWS: usize, const COLS: usize> CoilGrid<S, ROWS, COLS> {
    /// Validates `config` and precomputes the step coefficients.
    ///
    /// Errors: an invalid parameter, stencil, resistance, tick or limit;
    /// [`BuildError::UnstableStep`] naming the coil `row * COLS + col` with the
    /// largest `dt sum(G) / C` when that reaches 1 at the grid step
    /// `ticks_per_update * tick_dt_s`.
    pub fn new(config: &GridConfig) -> Result<Self, BuildError> {
        const { assert!(ROWS > 0 && COLS > 0, "a coil grid needs at least one coil") };
        let p = &config.params;
        p.validate()?;
        config.stencil.validate()?;
        config.limits.validate()?;
        let tick = config.tick_dt_s;
        if !(tick.is_finite() && tick > 0.0) {
            return Err(BuildError::InvalidTimeStep);
        }
        if config.ticks_per_update == 0 {
            return Err(BuildError::InvalidParameter {
                name: "ticks_per_update",
            });
        }
        // The `I^2` account of an interval must stay in range, with a
        // factor 2 to spare: fixed point saturates, which would lose heat
        // (read cold).
        let max_a = config.limits.max_current_a;
        if max_a * max_a * 2.0 * f64::from(config.ticks_per_update) >= S::MAX.to_f64() {
            return Err(BuildError::InvalidParameter {
                name: "ticks_per_update (max_current_a^2 over an update beyond the scalar's range)",
            });
        }
        let r = config.resistance;
        let plausible = |t: f64| r.is_valid_at(t);
        if !(plausible(config.limits.min_temp_c) && plausible(config.limits.max_temp_c)) {
            return Err(BuildError::InvalidResistance { input: 0 });
        }
        let dt = tick * f64::from(config.ticks_per_update);
        let mut grid = Self {
            config: *config,
            stability_ratio: 0.0,
            neighbour_g_dt: [[[S::ZERO; COLS]; ROWS]; 8],
            direction_used: [[false; 2]; 8],
            ambient_g_dt: [[S::ZERO; COLS]; ROWS],
            base_g_dt: S::from_f64(p.gz_w_per_k() * dt),
            inverse_capacity: S::from_f64(1.0 / p.capacity_j_per_k()),
            r_at_0c_tick_dt: S::from_f64(r.r_at_0c_ohm * tick),
            slope_tick_dt: S::from_f64(r.slope_ohm_per_k * tick),
            rows_per_tick: Self::rows_per_tick_at(config.ticks_per_update),
            limits: config.limits.to_scalar(),
        };
        let mut worst = (0, 0.0f64);
        for row in 0..ROWS {
            for col in 0..COLS {
                let mut ambient_g = 0.0;
                let mut total_g = p.gz_w_per_k();
                for (d, &(d_row, d_col)) in DIRECTIONS.iter().enumerate() {
                    let g = grid.link_conductance(row, d_row, d_col);
                    if g == 0.0 {
                        continue;
                    }
                    // `get_mut`: the optimiser loses `d < 8` here, and the
                    // panic-free proof (examples/panic_free.rs) builds a grid.
                    if let Some(used) = grid.direction_used.get_mut(d) {
                        used[row % 2] = true;
                    }
                    if Self::neighbour(row, col, d_row, d_col).is_some() {
                        if let Some(slot) = grid.neighbour_g_dt.get_mut(d) {
                            slot[row][col] = S::from_f64(g * dt);
                        }
                        total_g += g;
                    } else if config.border == Border::Ambient {
                        ambient_g += g;
                        total_g += g;
                    }
                }
                grid.ambient_g_dt[row][col] = S::from_f64(ambient_g * dt);
                let ratio = dt * total_g / p.capacity_j_per_k();
                if ratio > worst.1 {
                    worst = (row * COLS + col, ratio);
                }
            }
        }
        if worst.1 >= 1.0 {
            return Err(BuildError::UnstableStep {
                node: worst.0,
                ratio: worst.1 as f32,
            });
        }
        grid.stability_ratio = worst.1;
        Ok(grid)
    }

    /// Rows of neighbour heat [`CoilGrid::tick_spread`] sums per tick at
    /// `ticks_per_update` ticks per update (at least 1): every row done by
    /// the tick before the update, which then only finishes; with an update
    /// every tick, that tick does it all.
    pub(crate) const fn rows_per_tick_at(ticks_per_update: u32) -> usize {
        match ticks_per_update {
            0 | 1 => ROWS,
            n => ROWS.div_ceil(n as usize - 1),
        }
    }

    /// `G` \[W/K\] of the stencil link of a coil in `row` towards
    /// `(d_row, d_col)`, regardless of the grid's extent.
    fn link_conductance(&self, row: usize, d_row: isize, d_col: isize) -> f64 {
        match self.config.stencil.link(row, d_row, d_col) {
            Link::None => 0.0,
            Link::X => self.config.params.gx_w_per_k(),
            // The side's `1 / Ry` shared by its contacts (stencil docs);
            // `validate` has checked the count at build.
            Link::Y => {
                let contacts = self.config.stencil.cross_row_contacts().unwrap_or(1).max(1);
                self.config.params.gy_w_per_k() / f64::from(contacts)
            }
        }
    }

    /// The coil at `(row + d_row, col + d_col)` if it is inside the grid.
    fn neighbour(row: usize, col: usize, d_row: isize, d_col: isize) -> Option<(usize, usize)> {
        let r = row.checked_add_signed(d_row).filter(|&r| r < ROWS)?;
        let c = col.checked_add_signed(d_col).filter(|&c| c < COLS)?;
        Some((r, c))
    }

    /// The configuration the grid was built from.
    pub fn config(&self) -> &GridConfig {
        &self.config
    }

    /// Interval between ticks \[s\].
    pub fn tick_dt_s(&self) -> f64 {
        self.config.tick_dt_s
    }

    /// Ticks per grid update.
    pub fn ticks_per_update(&self) -> u32 {
        self.config.ticks_per_update
    }

    /// The grid step, `ticks_per_update * tick_dt_s` \[s\].
    pub fn grid_dt_s(&self) -> f64 {
        self.config.tick_dt_s * f64::from(self.config.ticks_per_update)
    }

    /// The largest `dt sum(G) / C` over the coils (below 1 by construction).
    pub fn stability_ratio(&self) -> f64 {
        self.stability_ratio
    }

    /// Heat capacity of every coil \[J/K\].
    pub fn capacity_j_per_k(&self) -> f64 {
        self.config.params.capacity_j_per_k()
    }

    /// Conductance from every coil to the cooled base, `1 / Rz` \[W/K\].
    pub fn base_conductance_w_per_k(&self) -> f64 {
        self.config.params.gz_w_per_k()
    }

    /// Conductance \[W/K\] between coil `(row, col)` and the coil at
    /// `(row + d_row, col + d_col)`; zero when they are not linked or either
    /// lies outside the grid. Symmetric by construction.
    pub fn neighbour_conductance_w_per_k(
        &self,
        row: usize,
        col: usize,
        d_row: isize,
        d_col: isize,
    ) -> f64 {
        if row >= ROWS || col >= COLS || Self::neighbour(row, col, d_row, d_col).is_none() {
            return 0.0;
        }
        self.link_conductance(row, d_row, d_col)
    }

    /// Conductance \[W/K\] from coil `(row, col)` to the ambient padding (the
    /// sum of its links that leave the grid); zero for
    /// [`Border::Adiabatic`] or outside the grid.
    pub fn ambient_conductance_w_per_k(&self, row: usize, col: usize) -> f64 {
        if row >= ROWS || col >= COLS || self.config.border == Border::Adiabatic {
            return 0.0;
        }
        DIRECTIONS
            .iter()
            .filter(|&&(dr, dc)| Self::neighbour(row, col, dr, dc).is_none())
            .map(|&(dr, dc)| self.link_conductance(row, dr, dc))
            .sum()
    }

    /// The grid as a lumped [`Network`] for the protection and analysis code
    /// (time-to-limit, steady state, exact discretisation): node and current
    /// input `row * COLS + col`, boundary 0 the coolant, boundary 1 the
    /// ambient. `N` must be `ROWS * COLS` (checked at compile time). The
    /// network stores `N x N` `f64` conductances: 56 KiB for 84 coils, meant
    /// for the host or a build step rather than the MCU stack.
    pub fn to_network<const N: usize>(&self) -> Result<Network<N, 2, N>, BuildError> {
        const { assert!(N == ROWS * COLS, "N must be ROWS * COLS") };
        let mut net = Network::new([self.capacity_j_per_k(); N])?;
        for row in 0..ROWS {
            for col in 0..COLS {
                let node = row * COLS + col;
                for &(dr, dc) in &DIRECTIONS {
                    // Each pair once: only links towards a later node.
                    if let Some((r, c)) = Self::neighbour(row, col, dr, dc) {
                        let other = r * COLS + c;
                        if other > node {
                            let g = self.neighbour_conductance_w_per_k(row, col, dr, dc);
                            net = net.connect(node, other, g)?;
                        }
                    }
                }
                net = net
                    .connect_boundary(node, 0, self.base_conductance_w_per_k())?
                    .connect_boundary(node, 1, self.ambient_conductance_w_per_k(row, col))?
                    .joule_source(node, node, self.config.resistance)?;
            }
        }
        Ok(net)
    }
}

#[cfg(test)]
mod tests;
