//! The grid observer as data, for a configuration in flash.
//!
//! [`GridObserver::new`] derives every table of the tick from the grid's
//! parameters (conductances per direction, reciprocals, the time to
//! limit's constants, the restart temperature, the fingerprint): 6.6 KiB
//! for the 84-coil HPPA in `f32`, which, built on the target, live in RAM.
//! As for the Omnimagnet (see its parts):
//!
//! * [`GridObserver::parts`] reads them into a [`GridParts`]: the grid's
//!   [`GridConfig`], its coefficient tables, the protection and the clock,
//!   nothing computed again;
//! * `write_rust` (on the `f32` and [`Q32`](crate::Q32) parts) writes them
//!   as a Rust expression (what `coil-thermal codegen --device hppa-grid`
//!   puts in `examples/generated/hppa_grid.rs`);
//! * [`GridObserver::from_parts`] is a `const fn` that checks the parts
//!   and copies them: a `static` initialised with it is assembled by the
//!   compiler and lands in flash.
//!
//! `GridObserver` is generic over the scalar, and a `const fn` cannot call
//! a trait method: `from_parts` only moves `Copy` values, so one assembly
//! serves every scalar. For the same reason it cannot test a scalar table
//! for NaN: it checks what is not in the scalar (the grid's configuration,
//! the stability ratio, the time to limit's `f32` constants, the clock,
//! the plan, the restart temperature) and trusts the scalar tables as
//! `parts()` read them from a validated observer; the host round trip
//! (`host-tests/tests/grid_codegen.rs`) checks the generated file against
//! `new`'s observer to the bit.

use core::fmt::{self, Write};

use super::{GridObserver, ProtectionPlan, TimeToLimit, TtlCoil};
use crate::error::BuildError;
use crate::grid::{Border, CoilGrid, GridConfig, GridParams, Link, Stencil};
use crate::input::{InputLimits, ScalarLimits};
use crate::network::Resistance;
use crate::observer::snapshot::Fingerprint;
use crate::observer::tables::{
    bound_rows, finite, finite_rows, invalid, upper_bound, write_alarm, write_clock, write_limiter,
    AlarmTables, ClockTables, Fields, LimiterTables, Literal,
};
use crate::protect::margin::UpperBound;
use crate::scalar::{Scalar, Q32};

/// The grid model ([`CoilGrid`]) as data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridModelTables<S, const ROWS: usize, const COLS: usize> {
    /// The configuration the grid was built from.
    pub config: GridConfig,
    /// The largest `dt sum(G) / C` over the coils (dimensionless, below 1).
    pub stability_ratio: f64,
    /// `G dt` per grid step towards each neighbour direction \[J/K\],
    /// directions in the order `(-1, -1), (-1, 0), (-1, 1), (0, -1),
    /// (0, 1), (1, -1), (1, 0), (1, 1)`.
    pub neighbour_g_dt: [[[S; COLS]; ROWS]; 8],
    /// Whether each direction has a link in even (`[d][0]`) and odd rows.
    pub direction_used: [[bool; 2]; 8],
    /// `G dt` to the ambient padding per grid step \[J/K\].
    pub ambient_g_dt: [[S; COLS]; ROWS],
    /// `dt / Rz` per grid step \[J/K\].
    pub base_g_dt: S,
    /// `1 / C` \[K/J\].
    pub inverse_capacity: S,
    /// `R(0 degC) * tick_dt` \[ohm s\].
    pub r_at_0c_tick_dt: S,
    /// `dR/dT * tick_dt` \[ohm s / K\].
    pub slope_tick_dt: S,
    /// The plausible inputs in the scalar \[A, degC\].
    pub limits: ScalarLimits<S>,
}

/// The constants of the per-coil time-to-limit bound (`f32`, see the
/// grid observer's module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeToLimitTables<const N: usize> {
    /// Per coil, row-major: the conductance to its neighbours `G_n`
    /// \[W/K\], to the ambient padding `G_a` \[W/K\], `1 / (G_z + G_a)`
    /// \[K/W\], `1 / (G_n + G_z + G_a)` \[K/W\] and its time constant \[s\].
    pub coils: [[f32; 5]; N],
    /// Conductance to the base `G_z` \[W/K\].
    pub base_g: f32,
    /// `R(0 degC)` \[ohm\].
    pub r0_ohm: f32,
    /// `dR/dT` \[ohm/K\].
    pub slope_ohm_per_k: f32,
}

/// A [`GridObserver`] as data (see the module docs). `N` is `ROWS * COLS`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridParts<S, const ROWS: usize, const COLS: usize, const N: usize> {
    /// The grid model.
    pub model: GridModelTables<S, ROWS, COLS>,
    /// The alarm of every coil, index `row * COLS + col`.
    pub alarm: AlarmTables<S, N>,
    /// The current limiter of every coil.
    pub limiter: LimiterTables<S, N>,
    /// Each coil's upper bound: the share of its rise `f`
    /// (dimensionless), `f / (1 + f)` and its offset \[K\]; `None`: no
    /// margin, the protection acts on the estimate.
    pub bound: Option<[[S; 3]; N]>,
    /// The time to limit's constants.
    pub time_to_limit: TimeToLimitTables<N>,
    /// How the protection pass is cut into ticks.
    pub plan: ProtectionPlan,
    /// The step clock (its step is the grid's tick).
    pub clock: ClockTables,
    /// The mean temperature of the conservative state \[degC\].
    pub restart_c: f64,
    /// The model's fingerprint so far (a CRC register, fed further when
    /// the margin changes).
    pub model_fingerprint: u32,
    /// The snapshot fingerprint of this configuration.
    pub fingerprint: u32,
}

const fn positive(value: f64) -> bool {
    value.is_finite() && value > 0.0
}

/// What `CoilGrid::new` refuses of a configuration, as far as a `const fn`
/// can tell (the stencil's symmetry is not checked).
const fn config_is_valid(c: &GridConfig) -> bool {
    let p = &c.params;
    let l = &c.limits;
    positive(p.rx_between_coils_k_per_w())
        && positive(p.ry_between_coils_k_per_w())
        && positive(p.rz_k_per_w())
        && positive(p.capacity_j_per_k())
        && positive(c.tick_dt_s)
        && c.ticks_per_update >= 1
        && c.resistance.r_at_0c_ohm.is_finite()
        && c.resistance.slope_ohm_per_k.is_finite()
        && positive(l.max_current_a)
        && l.min_temp_c.is_finite()
        && l.max_temp_c.is_finite()
        && l.min_temp_c < l.max_temp_c
}

impl<S: Scalar, const ROWS: usize, const COLS: usize, const N: usize>
    GridObserver<S, ROWS, COLS, N>
{
    /// Every table of this configuration as data (see the module docs):
    /// `from_parts(&self.parts())` is this observer, to the bit.
    pub fn parts(&self) -> GridParts<S, ROWS, COLS, N> {
        let g = &self.grid;
        let t = &self.ttl;
        GridParts {
            model: GridModelTables {
                config: g.config,
                stability_ratio: g.stability_ratio,
                neighbour_g_dt: g.neighbour_g_dt,
                direction_used: g.direction_used,
                ambient_g_dt: g.ambient_g_dt,
                base_g_dt: g.base_g_dt,
                inverse_capacity: g.inverse_capacity,
                r_at_0c_tick_dt: g.r_at_0c_tick_dt,
                slope_tick_dt: g.slope_tick_dt,
                limits: g.limits,
            },
            alarm: AlarmTables::of(&self.alarm),
            limiter: LimiterTables::of(&self.limiter),
            bound: if self.bound_is_zero {
                None
            } else {
                Some(bound_rows(&self.bound))
            },
            time_to_limit: TimeToLimitTables {
                coils: core::array::from_fn(|i| {
                    let c = t.coils.as_flattened().get(i).copied().unwrap_or_default();
                    [c.neighbour_g, c.ambient_g, c.isolated_r, c.total_r, c.tau_s]
                }),
                base_g: t.base_g,
                r0_ohm: t.r0_ohm,
                slope_ohm_per_k: t.slope_ohm_per_k,
            },
            plan: self.plan,
            clock: ClockTables::of(&self.clock),
            restart_c: self.restart_c,
            model_fingerprint: self.model_fingerprint.register(),
            fingerprint: self.fingerprint,
        }
    }

    /// The observer of `parts`, typically written by
    /// `coil-thermal codegen --device hppa-grid`: a `const fn`, so a
    /// `static` initialised with it is evaluated by the compiler and lands
    /// in flash. Copies the tables (no arithmetic, no scalar compared: see
    /// the module docs).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the first inconsistent part:
    /// a grid configuration `CoilGrid::new` refuses (`model.config`: a
    /// resistance, capacity, tick or input limit not finite and positive, no
    /// ticks per update), a stability ratio outside `[0, 1)`
    /// (`model.stability_ratio`), a non-finite time-to-limit constant
    /// (`time_to_limit`) or restart temperature (`restart_c`), a clock the
    /// tick cannot run (`clock.step_us`, `clock.max_steps_per_tick`,
    /// `clock.frozen_flag_ticks`, `clock.frozen_loss_ticks`), fewer than
    /// `2 * max_steps_per_tick` ticks per update
    /// (`model.config.ticks_per_update`), or a plan
    /// [`GridObserver::with_protection_plan`] refuses (`plan`,
    /// `plan.wait_for_rows`).
    pub const fn from_parts(parts: &GridParts<S, ROWS, COLS, N>) -> Result<Self, BuildError> {
        const { assert!(N == ROWS * COLS, "N must be ROWS * COLS") };
        let m = &parts.model;
        if !config_is_valid(&m.config) {
            return Err(invalid("model.config"));
        }
        if !(m.stability_ratio >= 0.0 && m.stability_ratio < 1.0) {
            return Err(invalid("model.stability_ratio"));
        }
        let t = &parts.time_to_limit;
        if !(finite_rows(&t.coils) && finite(&[t.base_g, t.r0_ohm, t.slope_ohm_per_k])) {
            return Err(invalid("time_to_limit"));
        }
        if !parts.restart_c.is_finite() {
            return Err(invalid("restart_c"));
        }
        let clock = match parts.clock.clock() {
            Ok(clock) => clock,
            Err(e) => return Err(e),
        };
        // As `new`: the protection stages need ticks without an update.
        let ticks_per_update = m.config.ticks_per_update;
        if ticks_per_update < clock.max_steps_per_tick.saturating_mul(2) {
            return Err(invalid("model.config.ticks_per_update"));
        }
        // As `with_protection_plan`.
        let plan = &parts.plan;
        if plan.bound_parts == 0
            || plan.time_to_limit_parts == 0
            || plan.alarm_parts == 0
            || plan.limiter_parts == 0
            || plan.ticks() > (u8::MAX - 1) as u32
        {
            return Err(invalid("plan"));
        }
        let rows_per_tick = CoilGrid::<S, ROWS, COLS>::rows_per_tick_at(ticks_per_update);
        let row_ticks = ROWS.div_ceil(rows_per_tick) as u32;
        if plan.wait_for_rows && row_ticks >= ticks_per_update - 1 {
            return Err(invalid("plan.wait_for_rows"));
        }

        let mut coils = [[TtlCoil {
            neighbour_g: 0.0,
            ambient_g: 0.0,
            isolated_r: 0.0,
            total_r: 0.0,
            tau_s: 0.0,
        }; COLS]; ROWS];
        let mut i = 0;
        while i < N {
            let c = &t.coils[i];
            coils[i / COLS][i % COLS] = TtlCoil {
                neighbour_g: c[0],
                ambient_g: c[1],
                isolated_r: c[2],
                total_r: c[3],
                tau_s: c[4],
            };
            i += 1;
        }
        let (bound, bound_is_zero) = match &parts.bound {
            Some(rows) => (upper_bound(rows), false),
            None => (UpperBound::ZERO, true),
        };
        Ok(Self {
            grid: CoilGrid {
                config: m.config,
                stability_ratio: m.stability_ratio,
                neighbour_g_dt: m.neighbour_g_dt,
                direction_used: m.direction_used,
                ambient_g_dt: m.ambient_g_dt,
                base_g_dt: m.base_g_dt,
                inverse_capacity: m.inverse_capacity,
                r_at_0c_tick_dt: m.r_at_0c_tick_dt,
                slope_tick_dt: m.slope_tick_dt,
                rows_per_tick,
                limits: m.limits,
            },
            alarm: parts.alarm.config(),
            limiter: parts.limiter.config(),
            clock,
            plan: parts.plan,
            ttl: TimeToLimit {
                coils,
                base_g: t.base_g,
                r0_ohm: t.r0_ohm,
                slope_ohm_per_k: t.slope_ohm_per_k,
            },
            bound,
            bound_is_zero,
            restart_c: parts.restart_c,
            model_fingerprint: Fingerprint::from_register(parts.model_fingerprint),
            fingerprint: parts.fingerprint,
        })
    }
}

impl Literal for GridParams {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        out.write_str("coil_thermal::grid::GridParams::between_coils(")?;
        let values = [
            self.rx_between_coils_k_per_w(),
            self.ry_between_coils_k_per_w(),
            self.rz_k_per_w(),
            self.capacity_j_per_k(),
        ];
        for (k, v) in values.iter().enumerate() {
            if k > 0 {
                out.write_str(", ")?;
            }
            v.write(out)?;
        }
        out.write_char(')')
    }
}

impl Literal for Link {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        write!(out, "coil_thermal::grid::Link::{self:?}")
    }
}

impl Literal for Border {
    fn write(&self, out: &mut dyn Write) -> fmt::Result {
        write!(out, "coil_thermal::grid::Border::{self:?}")
    }
}

fn write_config(out: &mut Fields<'_>, c: &GridConfig) -> fmt::Result {
    // Destructured whole, so that a field added to the configuration is a
    // compile error here, not a field silently left out of the file.
    let GridConfig {
        params,
        stencil: Stencil { even, odd },
        border,
        resistance: Resistance {
            r_at_0c_ohm,
            slope_ohm_per_k,
        },
        tick_dt_s,
        ticks_per_update,
        limits:
            InputLimits {
                max_current_a,
                min_temp_c,
                max_temp_c,
            },
    } = c;
    let mut w = out.nested("config", "grid::GridConfig")?;
    w.field("params", params)?;
    let mut s = w.nested("stencil", "grid::Stencil")?;
    s.table("even", even)?;
    s.table("odd", odd)?;
    s.close(false)?;
    w.field("border", border)?;
    let mut r = w.nested("resistance", "network::Resistance")?;
    r.field("r_at_0c_ohm", r_at_0c_ohm)?;
    r.field("slope_ohm_per_k", slope_ohm_per_k)?;
    r.close(false)?;
    w.field("tick_dt_s", tick_dt_s)?;
    w.field("ticks_per_update", ticks_per_update)?;
    write_limits(
        &mut w,
        "input::InputLimits",
        [max_current_a, min_temp_c, max_temp_c],
    )?;
    w.close(false)
}

/// Writes the field `limits`, a `path` expression (`input::InputLimits`
/// or `input::ScalarLimits`) of the plausible inputs'
/// `[max_current_a, min_temp_c, max_temp_c]`.
fn write_limits(out: &mut Fields<'_>, path: &str, values: [&dyn Literal; 3]) -> fmt::Result {
    let mut w = out.nested("limits", path)?;
    for (name, value) in ["max_current_a", "min_temp_c", "max_temp_c"]
        .iter()
        .zip(values)
    {
        w.field(name, value)?;
    }
    w.close(false)
}

fn write_model<S: Literal, const ROWS: usize, const COLS: usize>(
    out: &mut Fields<'_>,
    m: &GridModelTables<S, ROWS, COLS>,
) -> fmt::Result {
    let GridModelTables {
        config,
        stability_ratio,
        neighbour_g_dt,
        direction_used,
        ambient_g_dt,
        base_g_dt,
        inverse_capacity,
        r_at_0c_tick_dt,
        slope_tick_dt,
        limits:
            ScalarLimits {
                max_current_a,
                min_temp_c,
                max_temp_c,
            },
    } = m;
    let mut w = out.nested("model", "observer::grid::GridModelTables")?;
    write_config(&mut w, config)?;
    w.field("stability_ratio", stability_ratio)?;
    w.table("neighbour_g_dt", neighbour_g_dt)?;
    w.table("direction_used", direction_used)?;
    w.table("ambient_g_dt", ambient_g_dt)?;
    w.field("base_g_dt", base_g_dt)?;
    w.field("inverse_capacity", inverse_capacity)?;
    w.field("r_at_0c_tick_dt", r_at_0c_tick_dt)?;
    w.field("slope_tick_dt", slope_tick_dt)?;
    write_limits(
        &mut w,
        "input::ScalarLimits",
        [max_current_a, min_temp_c, max_temp_c],
    )?;
    w.close(false)
}

fn write_parts<S: Literal, const ROWS: usize, const COLS: usize, const N: usize>(
    parts: &GridParts<S, ROWS, COLS, N>,
    out: &mut dyn Write,
) -> fmt::Result {
    let GridParts {
        model,
        alarm,
        limiter,
        bound,
        time_to_limit:
            TimeToLimitTables {
                coils,
                base_g,
                r0_ohm,
                slope_ohm_per_k,
            },
        plan:
            ProtectionPlan {
                bound_parts,
                time_to_limit_parts,
                alarm_parts,
                limiter_parts,
                wait_for_rows,
            },
        clock,
        restart_c,
        model_fingerprint,
        fingerprint,
    } = parts;
    let mut w = Fields::open(out, "observer::grid::GridParts", 0)?;
    write_model(&mut w, model)?;
    write_alarm(&mut w, "alarm", alarm)?;
    write_limiter(&mut w, "limiter", limiter)?;
    w.optional_table("bound", bound.as_ref().map(|rows| rows.as_slice()))?;
    let mut t = w.nested("time_to_limit", "observer::grid::TimeToLimitTables")?;
    t.table("coils", coils)?;
    t.field("base_g", base_g)?;
    t.field("r0_ohm", r0_ohm)?;
    t.field("slope_ohm_per_k", slope_ohm_per_k)?;
    t.close(false)?;
    let mut p = w.nested("plan", "observer::ProtectionPlan")?;
    p.field("bound_parts", bound_parts)?;
    p.field("time_to_limit_parts", time_to_limit_parts)?;
    p.field("alarm_parts", alarm_parts)?;
    p.field("limiter_parts", limiter_parts)?;
    p.field("wait_for_rows", wait_for_rows)?;
    p.close(false)?;
    write_clock(&mut w, clock)?;
    w.field("restart_c", restart_c)?;
    w.field("model_fingerprint", model_fingerprint)?;
    w.field("fingerprint", fingerprint)?;
    w.close(true)
}

impl<const ROWS: usize, const COLS: usize, const N: usize> GridParts<f32, ROWS, COLS, N> {
    /// Writes these parts as a Rust expression of type
    /// `GridParts<f32, ROWS, COLS, N>` that names every type by its full
    /// path (`coil_thermal::`), for a `const` in a generated module.
    /// Reading it back gives these parts to the bit.
    ///
    /// # Errors
    /// Those of `out`.
    pub fn write_rust(&self, out: &mut dyn Write) -> fmt::Result {
        write_parts(self, out)
    }
}

impl<const ROWS: usize, const COLS: usize, const N: usize> GridParts<Q32, ROWS, COLS, N> {
    /// Writes these parts as a Rust expression of type
    /// `GridParts<Q32, ROWS, COLS, N>`, every fixed-point value by its bits
    /// (`Q32::from_bits`, a `const fn`); see the `f32` parts' `write_rust`.
    ///
    /// # Errors
    /// Those of `out`.
    pub fn write_rust(&self, out: &mut dyn Write) -> fmt::Result {
        write_parts(self, out)
    }
}
