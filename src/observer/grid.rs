//! One observer per coil grid: the HPPA model, its alarms, its current
//! limiter and a per-coil time to limit behind one `tick`.
//!
//! [`GridObserver`] is the configuration (built and validated once, shared
//! by every device of the kind), [`GridObserverState`] the per-device state,
//! and [`GridObserver::tick`] the whole per-tick path:
//!
//! 1. the measured elapsed time becomes whole model steps of the grid's tick
//!    (`tick_dt_s`, stable by construction) through the [`StepClock`]: a late
//!    tick sub-steps, an early one carries its time, a stall beyond
//!    `max_steps_per_tick` is dropped and flagged
//!    ([`InputFlags::ELAPSED_INVALID`]); a clock that gives no time for
//!    100 ticks in a row is flagged ([`InputFlags::CLOCK_FROZEN`]) and for
//!    1000 latches the shutdown (the model is lost; see
//!    [`super::clock`] and [`GridObserver::with_frozen_clock`]);
//! 2. the steps are [`CoilGrid::ticks_spread`] (Joule energy accumulated,
//!    a slice of the next update done, the grid updated every
//!    `ticks_per_update` steps): the temperatures of as many
//!    [`CoilGrid::tick`]s to the bit, without a tick that carries the whole
//!    update;
//! 3. after a tick in which the grid updated (temperatures change only then),
//!    the protection runs once, spread over the next ticks (eight with the
//!    default [`ProtectionPlan`]) so that no tick carries both a grid update
//!    and a large share of the protection: coil powers and the bound `U`,
//!    then the per-coil time to limit (by default in two parts of the
//!    coils), the alarm (three) and the current limiter (two), and the
//!    hottest coil.
//!    Between updates the protection outputs stand, because nothing they
//!    depend on has changed except the currents, which the limiter does not
//!    take. So the limits lag the model by at most the plan's ticks (8 ms at
//!    the HPPA's rate, against thermal time constants of minutes), and the
//!    alarm's debounce counts protection passes, not ticks. A pass is never
//!    restarted: an update during a pass marks it stale, and another pass
//!    follows as soon as it ends (the later stages then read the newer
//!    temperatures, which the bound `U` below still covers at the held
//!    currents). With `ticks_per_update` above the plan's ticks every update
//!    gets its own pass; with fewer, passes run back to back and the limits
//!    lag by at most two passes. The stages skip update ticks, so
//!    [`GridObserver::new`] requires `ticks_per_update >= 2 *
//!    max_steps_per_tick`: then no two ticks in a row update the grid and
//!    the protection can never be starved, whatever the tick pattern.
//!
//! # Acting on an upper bound
//!
//! The grid runs open loop: no sensor corrects a coil, so every estimate
//! carries the model's whole parameter error, and a protection that held
//! the estimates at the alarm limit would let a coil whose capacity and
//! conductances are 20 % low and resistance 20 % high run 27 K past it
//! (measured; see [`crate::protect::margin`]). The alarm, the limiter and
//! the time to limit therefore act on each coil's protective upper bound,
//! `T + f max(T - T_ref, 0) + offset_k`, the estimate plus a
//! model-uncertainty margin on its rise above the colder of the coolant and
//! the ambient: [`DEFAULT_MARGIN`] (`f` = 0.65, which bounds +-20 % on every
//! parameter), set by [`GridObserver::with_margin`] or per coil by
//! [`GridObserver::with_upper_bound`]. The outputs carry both the mean
//! (`temps_c`) and the bound (`upper_c`); the alarm's events report the
//! bound. The bound is taken once per pass, by the time-to-limit stage
//! (the alarm and the limiter read it from there, so within a pass they act
//! on the temperatures the time to limit saw); [`UncertaintyMargin::ZERO`]
//! skips it and gives the protection on the mean, to the bit. The bound costs a comparison, a
//! multiply and two additions per coil and pass, and the mean limit as much
//! again in the time to limit.
//!
//! # Time to limit per coil
//!
//! The full modal predictor of [`crate::protect::predict`] needs `N x N`
//! matrices, 28 KiB for 84 coils in `f32`: too big for an MCU. Instead each
//! coil is a first-order node with a rigorous upper bound on its neighbours:
//!
//! * powers at the resistance of the alarm limit (or of the present
//!   temperature, if higher), `p_i = R(max(T_i, L_i)) I_i^2`, as the modal
//!   predictor does;
//! * `U = max(max_i T_i, max_i (p_i + G_z T_c + G_a,i T_a) / (G_z + G_a,i))`:
//!   by the maximum principle no coil of the grid ever exceeds `U` at these
//!   powers and boundaries (at the hottest coil, neighbours are cooler, so it
//!   can rise only while it is below its own isolated steady state);
//! * coil `i` with every neighbour held at `U` obeys
//!   `C y' = p_i + G_n,i (U - y) + G_z (T_c - y) + G_a,i (T_a - y)`, and by
//!   comparison `T_i(t) <= y(t)`: its crossing of `L_i`,
//!   `tau ln((y_ss - T_i) / (y_ss - L_i))`, is never later than the truth;
//! * with a margin, `L_i` is the coil's *mean limit*, the estimate at which
//!   its upper bound reaches the alarm limit
//!   ([`ElementBound::mean_limit_c`](crate::protect::margin::ElementBound::mean_limit_c)),
//!   so the time is the bound's (the powers stay at the resistance of the
//!   alarm limit itself, the higher one).
//!
//! The bound is tight for the hottest coil of a uniformly heated region and
//! pessimistic for cold coils beside a hot one (they are assumed to sit next
//! to the hottest possible neighbour); a single powered coil is predicted to
//! run towards its isolated steady state. Cost: two passes over the coils
//! and one `ln` per coil that is predicted to cross (a short series, within
//! a few ulps of libm's, the accuracy of every other `f32` step here). `f32`
//! throughout (also for fixed-point grids: the answer is a time, not a
//! temperature).
//!
//! # Configuration in flash
//!
//! [`GridObserver::parts`] reads a built observer into plain tables
//! ([`GridParts`]), `write_rust` prints them as Rust, and the `const fn`
//! [`GridObserver::from_parts`] assembles them again, to the bit: a
//! `static` the compiler evaluates, so the configuration lives in flash
//! and nothing of it is derived on the target
//! (`coil-thermal codegen --device hppa-grid`; see
//! `src/observer/grid/parts.rs`).
//!
//! # Warm restart
//!
//! [`GridObserver::save`] writes the coil temperatures and the latched
//! shutdown with [`snapshot::save`]; [`GridObserver::restore`] checks them
//! against this configuration's [`fingerprint`](GridObserver::fingerprint)
//! (the model *and* the protection: alarm, derating, limiter, margin) and
//! refuses anything else; [`GridObserver::conservative_state`] is the
//! documented start after a refusal: the grid has no sensors, so every coil
//! starts where its upper bound is at the start of its limiter's taper band
//! (alarm limit at the nominal ambient minus `taper_k`), and the shutdown
//! starts latched. A restored latch, and the conservative state's, shows in
//! the state's outputs at once (`outputs().alarm.shutdown`), before the
//! first tick, and survives every tick: only the deliberate
//! [`GridObserver::clear_shutdown`], which the application calls after
//! inspecting the device, clears it. Once cleared, no coil has more
//! headroom than the taper, and the model cools the coils at the modelled
//! rate until it knows better.
//!
//! [`GridObserver::restore_after`] is the restore for a grid that was off for
//! a known time: the saved coils cooled by the grid's network with no
//! current ([`GridObserver::cooled_c`]: Taylor steps of the exponential
//! with a rigorous remainder, `f64`), never below the exact cooled state and
//! within about 1 mK of it. An unknown off time means no cooling.

use super::clock::{ClockState, StepClock};
use super::cycle::Latch;
use super::snapshot::{self, Fingerprint, Restored, SnapshotError};
use crate::error::BuildError;
use crate::grid::{Border, CoilGrid, CoilTemp, GridConfig, GridState, UpdateWork};
use crate::input::InputFlags;
use crate::protect::alarm::{AlarmConfig, AlarmState, AlarmStatus, ResetError};
use crate::protect::events::EventQueue;
use crate::protect::limiter::{hold_shutdown, CoilLimit, LimiterConfig};
use crate::protect::margin::{UncertaintyMargin, UpperBound, UpperBoundBuilder};
use crate::scalar::Scalar;
use crate::sizes::Element;
use nalgebra::Const;

mod parts;

pub use parts::{GridModelTables, GridParts, TimeToLimitTables};

pub use super::vocabulary::EVENT_CAPACITY;

/// The model-uncertainty margin [`GridObserver::new`] sets:
/// [`UncertaintyMargin::GRID_20_PERCENT`] (the grid runs open loop, so every
/// coil's estimate carries the model's whole parameter error).
pub const DEFAULT_MARGIN: UncertaintyMargin = UncertaintyMargin::GRID_20_PERCENT;

/// Ticks after a grid update until its protection pass is complete with the
/// default [`ProtectionPlan`] (the outputs lag the model by at most this many
/// ticks; see the module docs).
pub const PROTECTION_TICKS: u32 = ProtectionPlan::DEFAULT.ticks();

/// How the protection pass after each grid update is cut into ticks, one
/// stage per tick, in order: the bound `U` (with the coil powers and alarm
/// limits), the time to limit, the alarm and the current limiter, each in
/// `*_parts` row-major shares of the coils.
///
/// More parts make each tick lighter and the pass longer: the limits lag
/// the model by [`ProtectionPlan::ticks`] ticks (see the module docs). The
/// [default](ProtectionPlan::DEFAULT) suits an 84-coil grid on a
/// Cortex-M4F, whose alarm ticks are the heaviest (each element can raise
/// events in the same pass). Without an FPU the `f32` time to limit
/// dominates instead: `examples/observer_m0.rs` gives it one coil per
/// tick, in a pass longer than the update interval (passes then run back
/// to back, see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProtectionPlan {
    /// Parts of the first step: alarm limits, coil powers and the bound.
    pub bound_parts: u8,
    /// Parts of the per-coil time to limit.
    pub time_to_limit_parts: u8,
    /// Parts of the alarm.
    pub alarm_parts: u8,
    /// Parts of the current limiter (the last also publishes the
    /// temperatures and the hottest coil).
    pub limiter_parts: u8,
    /// No stage in a tick that prepares a row of the next grid update
    /// (neighbour heat and `R(T) tick_dt`, see [`CoilGrid::tick_spread`]),
    /// so that no tick carries both: the worst tick is the heavier of the
    /// two instead of their sum. The pass then takes the grid's row ticks
    /// longer ([`GridObserver::protection_ticks`], for one model step per
    /// tick). A stage is put off at most [`CoilGrid::row_ticks`] ticks in
    /// a row, so a controller that catches up several steps every tick
    /// (and so prepares a row in every tick between updates) still gets a
    /// stage at least every `row_ticks + 1` ticks that do not update.
    pub wait_for_rows: bool,
}

impl ProtectionPlan {
    /// One tick for the bound, two for the time to limit, three for the
    /// alarm and two for the limiter: eight ticks.
    pub const DEFAULT: Self = Self {
        bound_parts: 1,
        time_to_limit_parts: 2,
        alarm_parts: 3,
        limiter_parts: 2,
        wait_for_rows: false,
    };

    /// Ticks of one protection pass: the sum of the parts.
    pub const fn ticks(&self) -> u32 {
        self.bound_parts as u32
            + self.time_to_limit_parts as u32
            + self.alarm_parts as u32
            + self.limiter_parts as u32
    }

    /// Stage `index` of the pass (from 0): its step, part and parts.
    fn stage(&self, index: u32) -> Option<(Step, u8, u8)> {
        let steps = [
            (Step::Bound, self.bound_parts),
            (Step::TimeToLimit, self.time_to_limit_parts),
            (Step::Alarm, self.alarm_parts),
            (Step::Limiter, self.limiter_parts),
        ];
        let mut index = index;
        for (step, parts) in steps {
            match u8::try_from(index) {
                Ok(part) if part < parts => return Some((step, part, parts)),
                _ => index -= u32::from(parts),
            }
        }
        None
    }
}

impl Default for ProtectionPlan {
    fn default() -> Self {
        Self::DEFAULT
    }
}

// Neighbour offsets, the order of the per-direction tables: the grid
// model's own.
use crate::grid::DIRECTIONS;

/// The configuration of one grid device: model, protection and clock.
/// `N` must be `ROWS * COLS` (checked at compile time).
#[derive(Debug, Clone)]
pub struct GridObserver<S: Element, const ROWS: usize, const COLS: usize, const N: usize> {
    grid: CoilGrid<S, ROWS, COLS>,
    alarm: AlarmConfig<S, Const<N>>,
    limiter: LimiterConfig<S, Const<N>>,
    clock: StepClock,
    plan: ProtectionPlan,
    ttl: TimeToLimit<ROWS, COLS>,
    /// Each coil's protective upper bound (see [`GridObserver::with_margin`]).
    bound: UpperBound<S, Const<N>>,
    /// `bound` is zero: the protection reads the temperatures themselves.
    bound_is_zero: bool,
    restart_c: f64,
    /// The fingerprint of the model alone; [`Self::fingerprint`] adds the
    /// protection to it.
    model_fingerprint: Fingerprint,
    fingerprint: u32,
}

/// Constants of the time-to-limit bound, `f32`.
#[derive(Debug, Clone)]
struct TimeToLimit<const ROWS: usize, const COLS: usize> {
    coils: [[TtlCoil; COLS]; ROWS],
    /// Conductance to the base \[W/K\].
    base_g: f32,
    /// `R(0 degC)` \[ohm\] and `dR/dT` \[ohm/K\].
    r0_ohm: f32,
    slope_ohm_per_k: f32,
}

/// One coil's constants of the bound. The reciprocals and `tau` are kept so
/// that the per-coil passes have no division but the crossing time's: each
/// is a software routine on an MCU without an FPU.
#[derive(Debug, Clone, Copy, Default)]
struct TtlCoil {
    /// Sum of the conductances to neighbouring coils, `G_n,i` \[W/K\].
    neighbour_g: f32,
    /// Conductance to the ambient padding, `G_a,i` \[W/K\].
    ambient_g: f32,
    /// `1 / (G_z + G_a,i)` \[K/W\], of the isolated steady state.
    isolated_r: f32,
    /// `1 / (G_n,i + G_z + G_a,i)` \[K/W\].
    total_r: f32,
    /// `C / (G_n,i + G_z + G_a,i)` \[s\], the coil's time constant.
    tau_s: f32,
}

/// What a protection stage does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    /// Alarm limits at the held ambient, coil powers and the bound `U`.
    Bound,
    /// Time to limit of some coils.
    TimeToLimit,
    /// The alarm of some coils, with the new times.
    Alarm,
    /// The current limiter of some coils; after the last part, the
    /// published temperatures and the hottest coil.
    Limiter,
}

/// The coils of part `part` of `parts` of `n`, row-major.
fn part_of(n: usize, part: u8, parts: u8) -> core::ops::Range<usize> {
    let parts = usize::from(parts.max(1));
    let part = usize::from(part);
    n * part / parts..n * (part + 1) / parts
}

/// What one protection pass carries from stage to stage.
#[derive(Debug, Clone)]
struct ProtectPass<S, const N: usize> {
    /// Alarm limits at the held ambient \[degC\].
    limits_c: [S; N],
    /// Each coil's heat input from its power and the boundaries,
    /// `p_i + G_z T_c + G_a,i T_a` \[W\], fixed at the first stage so that
    /// the bound `U` holds for the powers the later stages use.
    own_inflow_w: [f32; N],
    /// The bound `U` \[degC\].
    bound_c: f32,
    /// The alarm status of the parts so far.
    alarm: AlarmStatus,
    /// Each coil's protective upper bound \[degC\], written by the time
    /// to limit parts for their coils; unused without a margin.
    upper_c: [S; N],
}

/// `ln(x)` for the time-to-limit ratio (`x >= 1`), within a few ulps of
/// libm's `logf` in about a third of its instructions (it runs for every
/// coil predicted to cross, 84 times per grid update on the HPPA): with
/// `x = m 2^e`, `m` in `[sqrt(1/2), sqrt(2))`, `ln m = 2 atanh(s)` for
/// `s = (m - 1) / (m + 1)`, `|s| < 0.172`, whose series to `s^7` leaves
/// less than `3e-8`. NaN, infinities and non-normal `x` go to `logf`.
fn ln(x: f32) -> f32 {
    if !(f32::MIN_POSITIVE..f32::INFINITY).contains(&x) {
        return libm::logf(x);
    }
    let bits = x.to_bits();
    let mut exponent = (bits >> 23) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > core::f32::consts::SQRT_2 {
        m *= 0.5;
        exponent += 1;
    }
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let series = 2.0 * s * (1.0 + s2 * (1.0 / 3.0 + s2 * (0.2 + s2 * (1.0 / 7.0))));
    exponent as f32 * core::f32::consts::LN_2 + series
}

/// The inputs of one tick. Currents by reference: 84 coils are 336 bytes.
#[derive(Debug, Clone, Copy)]
pub struct GridInputs<'a, S, const ROWS: usize, const COLS: usize> {
    /// Coil currents \[A\] (sign irrelevant); NaN holds the last valid one.
    pub currents_a: &'a [[S; COLS]; ROWS],
    /// Coolant (base) temperature \[degC\].
    pub coolant_c: S,
    /// Ambient temperature around the border \[degC\].
    pub ambient_c: S,
    /// Measured time since the previous tick \[us\].
    pub elapsed_us: u32,
}

/// What one tick produced: `Copy`, so it can be published through
/// [`Shared`](super::Shared).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GridOutputs<S, const ROWS: usize, const COLS: usize, const N: usize> {
    /// Coil temperature estimates \[degC\]: the model's mean.
    pub temps_c: [[S; COLS]; ROWS],
    /// Each coil's protective upper bound \[degC\], what the limiter and
    /// the alarm act on: the estimate plus the model-uncertainty margin
    /// ([`GridObserver::with_margin`]); equal to `temps_c` with
    /// [`UncertaintyMargin::ZERO`].
    pub upper_c: [[S; COLS]; ROWS],
    /// Per-coil current limit and preference weight, index `row * COLS + col`.
    pub limits: [CoilLimit<S>; N],
    /// Per-coil time until the upper bound reaches the alarm limit at the
    /// present currents \[s\] (`None`: never), index `row * COLS + col`;
    /// never later than the model's (see the module docs).
    pub time_to_limit_s: [Option<S>; N],
    /// The alarm summary.
    pub alarm: AlarmStatus,
    /// The hottest coil.
    pub hottest: CoilTemp<S>,
    /// Input rules that fired this tick, including
    /// [`InputFlags::ELAPSED_INVALID`] when time was dropped.
    pub flags: InputFlags,
    /// Model steps taken this tick.
    pub steps: u32,
    /// Time dropped by the catch-up limit this tick \[us\].
    pub dropped_us: u32,
    /// The grid updated this tick (the protection follows in the next
    /// [`GridObserver::protection_ticks`]).
    pub updated: bool,
    /// Ticks since the state was made.
    pub tick: u32,
}

/// The per-device state: model, alarm, clock, events and the last outputs.
#[derive(Debug, Clone)]
pub struct GridObserverState<S: Element, const ROWS: usize, const COLS: usize, const N: usize> {
    /// The grid model's state. Read it freely; the observer keeps work
    /// derived from its temperatures (see [`UpdateWork`]), so a state with
    /// other temperatures is made with [`GridObserver::restore`] or
    /// [`GridObserver::conservative_state`] rather than written here.
    pub grid: GridState<S, ROWS, COLS>,
    /// The grid update done ahead, a few rows per tick.
    work: UpdateWork<S, ROWS, COLS>,
    /// The alarm's state.
    pub alarm: AlarmState<S, Const<N>>,
    /// The time not yet simulated.
    pub clock: ClockState,
    /// Alarm events not yet drained by the application.
    pub events: EventQueue<EVENT_CAPACITY>,
    /// Next protection stage, from 1 (0: none pending; see
    /// [`ProtectionPlan`]).
    stage: u8,
    /// The grid updated while a pass was running: run another when it ends.
    pass_stale: bool,
    /// Stages put off in a row for the grid's rows
    /// ([`ProtectionPlan::wait_for_rows`]).
    waited: u8,
    /// What the protection stages hand on to each other.
    pass: ProtectPass<S, N>,
    outputs: GridOutputs<S, ROWS, COLS, N>,
}

impl<S: Scalar, const ROWS: usize, const COLS: usize, const N: usize>
    GridObserverState<S, ROWS, COLS, N>
{
    /// The outputs of the last tick.
    pub fn outputs(&self) -> &GridOutputs<S, ROWS, COLS, N> {
        &self.outputs
    }

    /// What the shutdown latch touches (its rules are every observer's).
    fn latch(&mut self) -> Latch<'_, S, Const<N>, EVENT_CAPACITY> {
        Latch {
            alarm: &mut self.alarm,
            events: &mut self.events,
            published: &mut self.outputs.alarm,
            limits: &mut self.outputs.limits,
        }
    }
}

impl<S: Scalar, const ROWS: usize, const COLS: usize, const N: usize>
    GridObserver<S, ROWS, COLS, N>
{
    /// Validates and builds a grid observer.
    ///
    /// * `grid`: the grid model; its `tick_dt_s` is the model step and must
    ///   be a whole number of microseconds;
    /// * `alarm`, `limiter`: the protection of every coil (e.g. from
    ///   [`DeratingRule::hppa`](crate::protect::derating::DeratingRule::hppa)
    ///   and [`HPPA_CRITICAL_C`](crate::protect::derating::HPPA_CRITICAL_C));
    /// * `max_steps_per_tick`: the catch-up bound, which bounds a tick's work.
    ///
    /// # Errors
    /// Those of [`CoilGrid::new`] and [`StepClock::new`];
    /// [`BuildError::InvalidTimeStep`] for a tick that is not a whole number
    /// of microseconds; [`BuildError::InvalidParameter`] when
    /// `grid.ticks_per_update < 2 * max_steps_per_tick` (see the module docs:
    /// the protection stages need ticks without a grid update).
    pub fn new(
        grid: &GridConfig,
        alarm: AlarmConfig<S, Const<N>>,
        limiter: LimiterConfig<S, Const<N>>,
        max_steps_per_tick: u32,
    ) -> Result<Self, BuildError> {
        const { assert!(N == ROWS * COLS, "N must be ROWS * COLS") };
        let model = CoilGrid::<S, ROWS, COLS>::new(grid)?;
        let step_us = libm::round(grid.tick_dt_s * 1e6);
        if !(step_us >= 1.0 && step_us <= u32::MAX as f64)
            || libm::fabs(step_us - grid.tick_dt_s * 1e6) > 1e-6
        {
            return Err(BuildError::InvalidTimeStep);
        }
        let clock = StepClock::new(step_us as u32, max_steps_per_tick)?;
        // At least every other tick must be free of a grid update, or the
        // protection stages (which skip update ticks) could wait forever.
        if grid.ticks_per_update < max_steps_per_tick.saturating_mul(2) {
            return Err(BuildError::InvalidParameter {
                name: "GridConfig::ticks_per_update (below 2 * max_steps_per_tick)",
            });
        }
        let base_g = model.base_conductance_w_per_k();
        let mut ttl = TimeToLimit {
            coils: [[TtlCoil::default(); COLS]; ROWS],
            base_g: base_g as f32,
            r0_ohm: grid.resistance.r_at_0c_ohm as f32,
            slope_ohm_per_k: grid.resistance.slope_ohm_per_k as f32,
        };
        let mut fingerprint = Fingerprint::new()
            .u32(ROWS as u32)
            .u32(COLS as u32)
            .f64s(&[
                model.capacity_j_per_k(),
                model.base_conductance_w_per_k(),
                grid.resistance.r_at_0c_ohm,
                grid.resistance.slope_ohm_per_k,
                grid.tick_dt_s,
            ])
            .u32(grid.ticks_per_update)
            .u32(u32::from(grid.border == Border::Ambient));
        for row in 0..ROWS {
            for col in 0..COLS {
                let g: f64 = DIRECTIONS
                    .iter()
                    .map(|&(dr, dc)| model.neighbour_conductance_w_per_k(row, col, dr, dc))
                    .sum();
                let g_amb = model.ambient_conductance_w_per_k(row, col);
                ttl.coils[row][col] = TtlCoil {
                    neighbour_g: g as f32,
                    ambient_g: g_amb as f32,
                    isolated_r: (1.0 / (base_g + g_amb)) as f32,
                    total_r: (1.0 / (g + base_g + g_amb)) as f32,
                    tau_s: (model.capacity_j_per_k() / (g + base_g + g_amb)) as f32,
                };
                fingerprint = fingerprint.f64(g).f64(g_amb);
            }
        }
        let bound = UpperBoundBuilder::new(DEFAULT_MARGIN).build()?;
        let mut observer = Self {
            grid: model,
            alarm,
            limiter,
            clock,
            plan: ProtectionPlan::DEFAULT,
            ttl,
            bound_is_zero: bound.is_zero(),
            bound,
            restart_c: 0.0,
            model_fingerprint: fingerprint,
            fingerprint: 0,
        };
        observer.restart_c = observer.restart_temp();
        observer.fingerprint = observer.protected_fingerprint();
        Ok(observer)
    }

    /// The model's fingerprint with the protection added: the alarm
    /// (critical temperatures, derating, margins, debounce, horizons), the
    /// limiter (hardware limits, taper, floor) and every coil's upper
    /// bound (the model-uncertainty margin).
    fn protected_fingerprint(&self) -> u32 {
        let fp = self.alarm.fingerprint(self.model_fingerprint);
        let fp = self.limiter.fingerprint(fp);
        self.bound.fingerprint(fp).finish()
    }

    /// The mean temperature of [`Self::conservative_state`] \[degC\]: the
    /// lowest over the coils of the temperature whose upper bound is at the
    /// start of the limiter's taper band (alarm limit at 20 degC minus
    /// `taper_k`), with coolant and ambient at 20 degC. With a margin it is
    /// put 1 mK lower, so that rounding cannot place the bound inside the
    /// band.
    fn restart_temp(&self) -> f64 {
        self.temp_below_limits(self.limiter.taper_k())
    }

    /// The lowest over the coils of the temperature \[degC\] whose upper
    /// bound is `below_k` \[K\] under its alarm limit at 20 degC (1 mK
    /// lower with a margin: see [`Self::restart_temp`]).
    fn temp_below_limits(&self, below_k: S) -> f64 {
        let taper_k = below_k;
        let nominal_c = S::from_f64(20.0);
        let limits_c = self.alarm.alarm_limits_c(nominal_c);
        if self.bound.is_zero() {
            let lowest_c = limits_c
                .iter()
                .fold(f64::INFINITY, |lo, l| lo.min(l.to_f64()));
            return lowest_c - taper_k.to_f64();
        }
        let start_c = limits_c
            .iter()
            .zip(self.bound.elements())
            .fold(f64::INFINITY, |lo, (l, b)| {
                lo.min(b.mean_limit_c(*l - taper_k, nominal_c).to_f64())
            });
        start_c - 1e-3
    }

    /// This observer with every coil's protective upper bound (what the
    /// limiter, the alarm and the time to limit act on; see
    /// [`crate::protect::margin`]) given the model-uncertainty margin
    /// `margin`, taken on each coil's rise above the colder of the coolant
    /// and the ambient. [`Self::new`] sets [`DEFAULT_MARGIN`];
    /// [`UncertaintyMargin::ZERO`] makes the protection act on the estimate
    /// itself (as before the margin existed, to the bit).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming a fraction or offset that is
    /// not finite or is negative.
    pub fn with_margin(self, margin: UncertaintyMargin) -> Result<Self, BuildError> {
        Ok(self.with_upper_bound(UpperBoundBuilder::new(margin).build()?))
    }

    /// This observer with a bound per coil (index `row * COLS + col`), e.g.
    /// no margin on a coil that carries a sensor; see [`Self::with_margin`].
    pub fn with_upper_bound(mut self, bound: UpperBound<S, Const<N>>) -> Self {
        self.bound_is_zero = bound.is_zero();
        self.bound = bound;
        self.restart_c = self.restart_temp();
        self.fingerprint = self.protected_fingerprint();
        self
    }

    /// This observer with a frozen clock (no elapsed time on consecutive
    /// ticks) flagged [`InputFlags::CLOCK_FROZEN`] from `flag_ticks` and
    /// taken as a loss of the model from `loss_ticks` ticks on: the
    /// shutdown latches with a
    /// [`ClockFrozen`](crate::protect::events::EventKind::ClockFrozen)
    /// event. [`Self::new`] sets 100 and 1000 ticks (see
    /// [`StepClock::with_frozen_limits`]).
    ///
    /// # Errors
    /// Those of [`StepClock::with_frozen_limits`].
    pub fn with_frozen_clock(
        mut self,
        flag_ticks: u32,
        loss_ticks: u32,
    ) -> Result<Self, BuildError> {
        self.clock = self.clock.with_frozen_limits(flag_ticks, loss_ticks)?;
        Ok(self)
    }

    /// Each coil's protective upper bound.
    pub fn upper_bound(&self) -> &UpperBound<S, Const<N>> {
        &self.bound
    }

    /// This observer with the protection pass cut as `plan` says (the
    /// default is [`ProtectionPlan::DEFAULT`]).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] when a step has no part or the pass
    /// would take more than 254 ticks.
    pub fn with_protection_plan(mut self, plan: ProtectionPlan) -> Result<Self, BuildError> {
        let parts = [
            plan.bound_parts,
            plan.time_to_limit_parts,
            plan.alarm_parts,
            plan.limiter_parts,
        ];
        if parts.contains(&0) || plan.ticks() > u32::from(u8::MAX - 1) {
            return Err(BuildError::InvalidParameter {
                name: "ProtectionPlan (a step without parts, or above 254 ticks)",
            });
        }
        // Waiting for the rows needs a tick between updates without one.
        let between_updates = self.grid.ticks_per_update().saturating_sub(1);
        if plan.wait_for_rows && self.grid.row_ticks() >= between_updates {
            return Err(BuildError::InvalidParameter {
                name: "ProtectionPlan::wait_for_rows (every tick between updates prepares a row)",
            });
        }
        self.plan = plan;
        Ok(self)
    }

    /// Ticks after a grid update until its protection pass is complete: the
    /// outputs lag the model by at most this many ticks (with
    /// [`ProtectionPlan::wait_for_rows`], the plan's ticks and the grid's
    /// row ticks of each update interval the pass spans).
    pub fn protection_ticks(&self) -> u32 {
        if self.plan.wait_for_rows {
            let free = self
                .grid
                .ticks_per_update()
                .saturating_sub(1 + self.grid.row_ticks())
                .max(1);
            let intervals = self.plan.ticks().div_ceil(free);
            self.plan.ticks() + intervals * (self.grid.row_ticks() + 1)
        } else {
            self.plan.ticks()
        }
    }

    /// The grid model.
    pub fn grid(&self) -> &CoilGrid<S, ROWS, COLS> {
        &self.grid
    }

    /// The alarm configuration.
    pub fn alarm(&self) -> &AlarmConfig<S, Const<N>> {
        &self.alarm
    }

    /// The step clock.
    pub fn clock(&self) -> &StepClock {
        &self.clock
    }

    /// The configuration fingerprint that snapshots carry: the model
    /// (size, capacity, conductances, resistance, step, update interval,
    /// border) and the protection (the alarm's critical temperatures,
    /// derating, margins and debounce; the limiter's hardware limits, taper
    /// and floor; every coil's model-uncertainty margin). A snapshot taken
    /// under another protection is refused: its latch and temperatures were
    /// judged against other limits.
    pub fn fingerprint(&self) -> u32 {
        self.fingerprint
    }

    /// A fresh state: every coil, the coolant and the ambient at `temp_c`
    /// \[degC\], no current, no alarm.
    pub fn state(&self, temp_c: f64) -> GridObserverState<S, ROWS, COLS, N> {
        self.state_from(GridState::uniform(temp_c))
    }

    fn state_from(&self, grid: GridState<S, ROWS, COLS>) -> GridObserverState<S, ROWS, COLS, N> {
        let alarm = AlarmState::new(&self.alarm);
        let mut state = GridObserverState {
            outputs: GridOutputs {
                temps_c: grid.temps_c,
                upper_c: grid.temps_c,
                limits: [CoilLimit::default(); N],
                time_to_limit_s: [None; N],
                alarm: AlarmStatus::default(),
                hottest: grid.hottest(),
                flags: InputFlags::NONE,
                steps: 0,
                dropped_us: 0,
                updated: false,
                tick: 0,
            },
            work: self.grid.update_work(&grid),
            grid,
            alarm,
            clock: ClockState::default(),
            events: EventQueue::new(),
            stage: 0,
            pass_stale: false,
            waited: 0,
            pass: ProtectPass {
                limits_c: [S::ZERO; N],
                own_inflow_w: [0.0; N],
                bound_c: 0.0,
                alarm: AlarmStatus::default(),
                upper_c: [S::ZERO; N],
            },
        };
        self.protect(&mut state, false);
        state
    }

    /// One controller tick (see the module docs). Bounded work: at most
    /// `max_steps_per_tick` grid ticks and one protection pass;
    /// allocation-free and panic-free.
    pub fn tick<'s>(
        &self,
        state: &'s mut GridObserverState<S, ROWS, COLS, N>,
        inputs: &GridInputs<'_, S, ROWS, COLS>,
    ) -> &'s GridOutputs<S, ROWS, COLS, N> {
        let steps = self.clock.advance(&mut state.clock, inputs.elapsed_us);
        if steps.clock_lost {
            // The model stands still: latched until the deliberate clear.
            state.latch().clock_lost();
        }
        let rows_before = state.work.rows_done();
        let (grid, work, i) = (&mut state.grid, &mut state.work, inputs);
        let outcome = if steps.steps == 1 {
            self.grid
                .tick_spread(grid, work, i.currents_a, i.coolant_c, i.ambient_c)
        } else {
            // All the steps at once: a catch-up costs little more than one.
            self.grid.ticks_spread(
                grid,
                work,
                i.currents_a,
                i.coolant_c,
                i.ambient_c,
                steps.steps,
            )
        };
        let flags = steps.flags | outcome.flags;
        let updated = outcome.updated;
        if updated {
            // Temperatures changed: the protection runs in the next ticks. A
            // pass under way is finished first (restarting it could starve
            // the limiter whenever updates come less than a pass apart, e.g.
            // a controller ticking every 2 ms), then another one follows.
            if state.stage == 0 {
                state.stage = 1;
            } else {
                state.pass_stale = true;
            }
        } else if self.plan.wait_for_rows
            && state.stage != 0
            && state.work.rows_done() != rows_before
            && u32::from(state.waited) < self.grid.row_ticks().min(254)
        {
            // Put off, but never more than one interval's row ticks in a
            // row: a controller that always catches up several steps
            // prepares a row in every tick between updates, and the
            // protection must still progress.
            state.waited = state.waited.saturating_add(1);
        } else {
            state.waited = 0;
            self.protect_stage(state);
        }
        let out = &mut state.outputs;
        out.flags = flags;
        out.steps = steps.steps;
        out.dropped_us = steps.dropped_us;
        out.updated = updated;
        if out.alarm.shutdown {
            // Latched: no current until the deliberate clear.
            hold_shutdown(&mut out.limits);
        }
        out.tick = out.tick.wrapping_add(1);
        &state.outputs
    }

    /// One stage of the protection after a grid update, so that no tick
    /// carries both the update and the whole protection (see
    /// [`ProtectionPlan`]). `state.stage` is the next stage's number from 1
    /// (0: none pending).
    fn protect_stage(&self, state: &mut GridObserverState<S, ROWS, COLS, N>) {
        let Some(stage) = u32::from(state.stage)
            .checked_sub(1)
            .and_then(|i| self.plan.stage(i))
        else {
            return;
        };
        self.run_stage(state, stage, true);
        state.stage = if u32::from(state.stage) < self.plan.ticks() {
            state.stage + 1
        } else if state.pass_stale {
            state.pass_stale = false;
            1
        } else {
            0
        };
    }

    /// Every stage at once on the present temperatures, the alarm only when
    /// `alarm` (for a fresh or restored state).
    fn protect(&self, state: &mut GridObserverState<S, ROWS, COLS, N>, alarm: bool) {
        for index in 0..self.plan.ticks() {
            if let Some(stage) = self.plan.stage(index) {
                self.run_stage(state, stage, alarm);
            }
        }
        state.stage = 0;
        state.pass_stale = false;
    }

    fn run_stage(
        &self,
        state: &mut GridObserverState<S, ROWS, COLS, N>,
        (step, part, parts): (Step, u8, u8),
        alarm: bool,
    ) {
        let ambient_c = state.grid.held_ambient_c;
        // The rise the margin scales is taken above the colder boundary.
        let reference_c = Scalar::min(state.grid.held_coolant_c, ambient_c);
        let out = &mut state.outputs;
        let pass = &mut state.pass;
        let coils = part_of(N, part, parts);
        let last = part + 1 >= parts;
        match step {
            Step::Bound => {
                if part == 0 {
                    pass.limits_c = self.alarm.alarm_limits_c(ambient_c);
                    pass.bound_c = f32::NEG_INFINITY;
                }
                self.ttl_bound(&state.grid, pass, coils);
                // The answers are computed in the ticks after the update
                // they describe; the next stages use them as they are (ms).
            }
            Step::TimeToLimit => {
                self.ttl_coils(
                    &state.grid,
                    pass,
                    reference_c,
                    &mut out.time_to_limit_s,
                    coils,
                );
            }
            Step::Alarm => {
                if let (true, Ok(temps)) = (
                    alarm,
                    <&[S; N]>::try_from(state.grid.temps_c.as_flattened()),
                ) {
                    let temps = if self.bound_is_zero {
                        temps
                    } else {
                        &pass.upper_c
                    };
                    let status = state.alarm.tick_part(
                        &self.alarm,
                        temps,
                        ambient_c,
                        &out.time_to_limit_s,
                        &mut state.events,
                        coils,
                    );
                    pass.alarm = if part == 0 {
                        status
                    } else {
                        pass.alarm.union(status)
                    };
                    if last {
                        out.alarm = pass.alarm;
                    }
                }
            }
            Step::Limiter => {
                if let Ok(temps) = <&[S; N]>::try_from(state.grid.temps_c.as_flattened()) {
                    let temps = if self.bound_is_zero {
                        temps
                    } else {
                        &pass.upper_c
                    };
                    self.limiter.apply_part(
                        temps,
                        &pass.limits_c,
                        ambient_c,
                        &mut out.limits,
                        coils,
                    );
                }
                if last {
                    out.temps_c = state.grid.temps_c;
                    if self.bound_is_zero {
                        out.upper_c = state.grid.temps_c;
                    } else {
                        let published = out.upper_c.as_flattened_mut().iter_mut();
                        for (out, upper) in published.zip(&pass.upper_c) {
                            *out = *upper;
                        }
                    }
                    out.hottest = state.grid.hottest();
                }
            }
        }
    }

    /// First pass of the bound of the module docs for the coils in `coils`
    /// (row-major): each coil's power at the resistance of its limit (or
    /// temperature, if higher) and heat input, kept in `pass` with the bound
    /// `U` so far (the maximum over the parts).
    fn ttl_bound(
        &self,
        grid: &GridState<S, ROWS, COLS>,
        pass: &mut ProtectPass<S, N>,
        range: core::ops::Range<usize>,
    ) {
        let t = &self.ttl;
        let coolant = grid.held_coolant_c.to_f32();
        let ambient = grid.held_ambient_c.to_f32();
        let (Some(temps), Some(currents), Some(constants), Some(limits), Some(own_inflow_w)) = (
            grid.temps_c.as_flattened().get(range.clone()),
            grid.held_currents_a.as_flattened().get(range.clone()),
            t.coils.as_flattened().get(range.clone()),
            pass.limits_c.get(range.clone()),
            pass.own_inflow_w.get_mut(range),
        ) else {
            return;
        };
        let mut bound_c = pass.bound_c;
        let coils = temps
            .iter()
            .zip(currents)
            .zip(constants)
            .zip(limits)
            .zip(own_inflow_w.iter_mut());
        for ((((temp, current), coil), limit), inflow_w) in coils {
            let (temp, current) = (temp.to_f32(), current.to_f32());
            // `Scalar::max`, a comparison: the inherent `f32::max` is a call
            // to `fmaxf` on ARMv7E-M, four per coil here.
            let r_ohm = t.r0_ohm + t.slope_ohm_per_k * Scalar::max(temp, limit.to_f32());
            let power_w = Scalar::max(r_ohm, 0.0) * current * current;
            *inflow_w = power_w + t.base_g * coolant + coil.ambient_g * ambient;
            let isolated = *inflow_w * coil.isolated_r;
            // `bound_c` is never NaN, so these are `Scalar::max` (a NaN
            // loses) in half the instructions.
            if isolated > bound_c {
                bound_c = isolated;
            }
            if temp > bound_c {
                bound_c = temp;
            }
        }
        pass.bound_c = bound_c;
    }

    /// Second pass of the bound for the coils in `coils` (row-major): each
    /// coil's crossing time with every neighbour at `U`, from the heat
    /// inputs of the first pass. The crossing is the mean's of the coil's
    /// mean limit (where its upper bound reaches the alarm limit; see
    /// [`crate::protect::margin`]), the powers stay at the resistance of the
    /// alarm limit itself (higher, so the bound holds). With a margin, also
    /// each coil's protective upper bound, for the alarm and the limiter of
    /// the pass (the bound's constants are loaded here anyway).
    fn ttl_coils(
        &self,
        grid: &GridState<S, ROWS, COLS>,
        pass: &mut ProtectPass<S, N>,
        reference_c: S,
        out: &mut [Option<S>; N],
        range: core::ops::Range<usize>,
    ) {
        let t = &self.ttl;
        let bound_c = pass.bound_c;
        let with_upper = !self.bound_is_zero;
        let (
            Some(temps),
            Some(constants),
            Some(limits),
            Some(bounds),
            Some(own_inflow_w),
            Some(upper_c),
            Some(out),
        ) = (
            grid.temps_c.as_flattened().get(range.clone()),
            t.coils.as_flattened().get(range.clone()),
            pass.limits_c.get(range.clone()),
            self.bound.elements().get(range.clone()),
            pass.own_inflow_w.get(range.clone()),
            pass.upper_c.get_mut(range.clone()),
            out.get_mut(range),
        )
        else {
            return;
        };
        let coils = temps
            .iter()
            .zip(constants)
            .zip(limits.iter().zip(bounds))
            .zip(own_inflow_w.iter().zip(upper_c.iter_mut()))
            .zip(out.iter_mut());
        for ((((temp, coil), (limit, bound)), (own_inflow_w, upper_c)), out) in coils {
            if with_upper {
                *upper_c = bound.upper_c(*temp, reference_c);
            }
            let limit = bound.mean_limit_c(*limit, reference_c);
            let (temp, limit) = (temp.to_f32(), limit.to_f32());
            let steady = (own_inflow_w + coil.neighbour_g * bound_c) * coil.total_r;
            // A NaN anywhere reads "no time left", the conservative answer:
            // `below` is false for a NaN temperature or limit, and a NaN
            // steady state leads to a NaN time, which the alarm counts as
            // inside its horizon.
            let below = temp < limit;
            let crosses = steady > limit || steady.is_nan();
            *out = if !below {
                // At or past the limit, or not finite: no time left.
                Some(S::ZERO)
            } else if !crosses {
                None
            } else {
                Some(S::from_f32(
                    coil.tau_s * ln((steady - temp) / (steady - limit)),
                ))
            };
        }
    }

    /// Writes a snapshot of the coil temperatures and the latched shutdown,
    /// stamped `now_s` \[s\] on the application's clock; returns its length.
    /// `out` needs [`snapshot::snapshot_len`]`(N)` bytes.
    pub fn save(
        &self,
        state: &GridObserverState<S, ROWS, COLS, N>,
        now_s: u32,
        out: &mut [u8],
    ) -> Result<usize, SnapshotError> {
        let mut temps_c = [0.0f32; N];
        for (t, s) in temps_c.iter_mut().zip(state.grid.temps_c.as_flattened()) {
            *t = s.to_f32();
        }
        snapshot::save_state(&temps_c, self.fingerprint, now_s, &state.alarm, out)
    }

    /// Restores a state from a snapshot taken by [`Self::save`] with this
    /// configuration at most `max_age_s` \[s\] before `now_s` \[s\]; the
    /// coolant and ambient start at `ambient_c` \[degC\]. A latched shutdown
    /// stays latched.
    ///
    /// # Errors
    /// Why the snapshot was refused; start from
    /// [`Self::conservative_state`] then.
    pub fn restore(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f64,
    ) -> Result<GridObserverState<S, ROWS, COLS, N>, SnapshotError> {
        self.restore_after(bytes, now_s, max_age_s, ambient_c, None)
    }

    /// [`Self::restore`] for a grid that was off for `off_s` \[s\]: the saved
    /// coil temperatures cooled with no current, the coolant and the ambient
    /// at `ambient_c` \[degC\], by [`Self::cooled_c`] (never below the exact
    /// cooled state of the grid's network, within millikelvin of it for the
    /// HPPA). A latched shutdown stays latched.
    ///
    /// `off_s` is capped at the snapshot's age; `None`, a NaN or a negative
    /// time mean an *unknown* off time and restore the saved state uncooled
    /// ([`snapshot::off_time_s`]); `Some(0.0)` restores it to the bit, as
    /// [`Self::restore`] does.
    ///
    /// # Errors
    /// Those of [`Self::restore`].
    pub fn restore_after(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f64,
        off_s: Option<f32>,
    ) -> Result<GridObserverState<S, ROWS, COLS, N>, SnapshotError> {
        let snap = Restored::read(bytes, self.fingerprint, now_s, max_age_s, [0.0; N])?;
        let (temps_c, meta, off_s) = (snap.saved_c, snap.meta, snap.off_time_s(off_s));
        let mut grid = GridState::uniform(ambient_c);
        for (t, s) in grid.temps_c.as_flattened_mut().iter_mut().zip(&temps_c) {
            *t = S::from_f32(*s);
        }
        if off_s > 0.0 {
            grid.temps_c = self.cooled_c(&grid.temps_c, ambient_c, f64::from(off_s));
        }
        let mut state = self.state_from(grid);
        state.latch().restore(&meta);
        Ok(state)
    }

    /// The coil temperatures \[degC\] `off_s` \[s\] after `temps_c` with no
    /// current and the coolant and the ambient at `ambient_c` \[degC\]: an
    /// upper bound of the exact zero-current solution of the grid's network,
    /// `T_a + exp(A off) (T - T_a)`, within about 1 mK of it.
    ///
    /// The grid has too many coils for a modal form on an MCU (`N x N`), so
    /// the exponential is applied in steps `h`, each a Taylor series with a
    /// rigorous remainder: with `d` the largest `sum(G_i) / C` over the coils
    /// and `P = A + d I >= 0` (every entry; the coils' rows of the stencil),
    ///
    /// ```text
    /// exp(A h) x = e^(-d h) (sum_{k <= K} (h P)^k x / k! + r),   0 <= r <= max(x) sum_{k > K} (h |P|)^k / k!,
    /// ```
    ///
    /// and the step adds the bound of `r`, so every step is an upper bound;
    /// `exp(A h) >= 0` carries the bound from step to step. `h |P| <= 4`
    /// and `K = 28` make `r` below `1e-13 max(x)`, and the arithmetic is
    /// `f64`, so the bound is tight; 1 mK is added for the rounding of the
    /// temperatures. At most 128 steps (`512 / |P|` \[s\], 25 h for the
    /// HPPA); beyond them every coil is bounded by the hottest decayed
    /// through the base alone, `e^(-G_z t / C) max(x)` (the neighbour and
    /// padding terms only spread and lose heat). Work: at most
    /// `128 * 28` stencil products (`9 N` multiply-adds each), about 4 KiB
    /// of `f64` stack, no allocation, no panic.
    ///
    /// A coil saved *below* the ambient is taken at the ambient (the
    /// bound's `max(T - T_a, 0)`: warmer, so still an upper bound).
    /// `off_s` that is not positive, and an ambient that is not finite,
    /// return `temps_c` unchanged.
    pub fn cooled_c(
        &self,
        temps_c: &[[S; COLS]; ROWS],
        ambient_c: f64,
        off_s: f64,
    ) -> [[S; COLS]; ROWS] {
        const MAX_STEPS: u32 = 128;
        const TERMS: u32 = 28;
        const MAX_HP: f64 = 4.0;
        if !(off_s > 0.0 && ambient_c.is_finite()) {
            return *temps_c;
        }
        let capacity = self.grid.capacity_j_per_k();
        let base_g = self.grid.base_conductance_w_per_k();
        // Link conductance of each row towards each direction [W/K] (the
        // stencil's links depend on the row alone).
        let mut link = [[0.0f64; 8]; ROWS];
        for (row, l) in link.iter_mut().enumerate() {
            for (g, &(dr, dc)) in l.iter_mut().zip(&DIRECTIONS) {
                *g = (0..COLS).fold(0.0, |m, col| {
                    m.max(self.grid.neighbour_conductance_w_per_k(row, col, dr, dc))
                });
            }
        }
        let inside = |row: usize, col: usize, (dr, dc): (isize, isize)| {
            let r = row.checked_add_signed(dr).filter(|&r| r < ROWS)?;
            let c = col.checked_add_signed(dc).filter(|&c| c < COLS)?;
            Some((r, c))
        };
        // Diagonal of -A (sum(G_i) / C) and the shift d.
        let mut leak = [[0.0f64; COLS]; ROWS];
        let mut shift = 0.0f64;
        for row in 0..ROWS {
            for col in 0..COLS {
                let mut total = base_g + self.grid.ambient_conductance_w_per_k(row, col);
                for (g, dir) in link[row].iter().zip(&DIRECTIONS) {
                    if inside(row, col, *dir).is_some() {
                        total += g;
                    }
                }
                leak[row][col] = total / capacity;
                shift = shift.max(total / capacity);
            }
        }
        // |P|, the largest row sum of P = A + d I.
        let mut p_norm = 0.0f64;
        for row in 0..ROWS {
            for col in 0..COLS {
                let mut sum = shift - leak[row][col];
                for (g, dir) in link[row].iter().zip(&DIRECTIONS) {
                    if inside(row, col, *dir).is_some() {
                        sum += g / capacity;
                    }
                }
                p_norm = p_norm.max(sum);
            }
        }
        let mut x = [[0.0f64; COLS]; ROWS];
        for (xr, tr) in x.iter_mut().zip(temps_c) {
            for (x, t) in xr.iter_mut().zip(tr) {
                let excess = t.to_f64() - ambient_c;
                *x = if excess > 0.0 { excess } else { 0.0 };
            }
        }
        // Steps of at most MAX_HP / |P|; what the steps cannot cover goes to
        // the base-only bound.
        let reach_s = if p_norm > 0.0 {
            f64::from(MAX_STEPS) * MAX_HP / p_norm
        } else {
            f64::INFINITY
        };
        let stepped_s = off_s.min(reach_s);
        let steps = if p_norm > 0.0 {
            libm::ceil(stepped_s * p_norm / MAX_HP).clamp(1.0, f64::from(MAX_STEPS))
        } else {
            1.0
        };
        let h = stepped_s / steps;
        let hp = h * p_norm;
        // The tail sum_{k > K} hp^k / k! <= t_{K+1} / (1 - hp / (K + 2)),
        // a geometric bound (hp <= 4 < K + 2), without cancellation.
        let mut first_left_out = 1.0;
        for k in 1..=TERMS + 1 {
            first_left_out *= hp / f64::from(k);
        }
        let remainder = first_left_out / (1.0 - hp / f64::from(TERMS + 2));
        let decay = libm::exp(-h * shift);
        let mut next = x;
        for _ in 0..steps as u32 {
            let peak = x.as_flattened().iter().fold(0.0f64, |m, v| m.max(*v));
            let mut sum = x;
            let mut term = x;
            for k in 1..=TERMS {
                let scale = h / f64::from(k);
                for row in 0..ROWS {
                    for col in 0..COLS {
                        let mut acc = (shift - leak[row][col]) * term[row][col];
                        for (g, dir) in link[row].iter().zip(&DIRECTIONS) {
                            if let Some((r, c)) = inside(row, col, *dir) {
                                acc += g / capacity * term[r][c];
                            }
                        }
                        next[row][col] = scale * acc;
                    }
                }
                term = next;
                for (s, t) in sum.as_flattened_mut().iter_mut().zip(term.as_flattened()) {
                    *s += t;
                }
            }
            for (x, s) in x.as_flattened_mut().iter_mut().zip(sum.as_flattened()) {
                *x = decay * (s + remainder * peak);
            }
        }
        let rest_s = off_s - stepped_s;
        if rest_s > 0.0 {
            let peak = x.as_flattened().iter().fold(0.0f64, |m, v| m.max(*v));
            let bound = peak * libm::exp(-rest_s * base_g / capacity);
            x = [[bound; COLS]; ROWS];
        }
        let mut out = *temps_c;
        for (or, xr) in out.iter_mut().zip(&x) {
            for (o, x) in or.iter_mut().zip(xr) {
                let t = ambient_c + x + 1e-3;
                if t.is_finite() {
                    *o = S::from_f64(t);
                }
            }
        }
        out
    }

    /// The documented start when no snapshot can be trusted: every coil
    /// where its upper bound is at the start of the limiter's taper band
    /// (the lowest alarm limit at 20 degC ambient minus `taper_k`; the
    /// estimate itself there with no margin), or at `ambient_c` \[degC\] if
    /// that is hotter; coolant and ambient at `ambient_c`. The shutdown is
    /// *latched* (and `outputs().alarm.shutdown` is `true` from the start):
    /// a refused snapshot may have been the record of a latched shutdown,
    /// and the coils may be hotter than assumed, so the current stays cut
    /// until the application has inspected the device and calls
    /// [`Self::clear_shutdown`].
    pub fn conservative_state(&self, ambient_c: f64) -> GridObserverState<S, ROWS, COLS, N> {
        let mut grid = GridState::uniform(ambient_c);
        let hot = S::from_f64(self.restart_c.max(ambient_c));
        grid.temps_c = [[hot; COLS]; ROWS];
        let mut state = self.state_from(grid);
        state.latch().latch();
        state
    }

    /// The start without a history (the first boot, a product that keeps
    /// no snapshot; see [`super::start`]): the grid has no sensor to learn
    /// from, so every coil starts where its upper bound is
    /// [`START_BELOW_LIMIT_K`](super::start::START_BELOW_LIMIT_K) under its
    /// alarm limit at 20 degC (the hottest it can be if the protection held
    /// before the reset), or at `ambient_c` \[degC\] if that is hotter, and
    /// the model cools it from there at the modelled rate. Nothing is
    /// latched: the limiter starts in its taper band (at the default 10 K
    /// band, `sqrt(1/10)`: 32 % of the hardware current) and opens as the
    /// model cools the coils. [`Self::conservative_state`] is the start
    /// after a *refused* snapshot (which may have held a latch).
    /// Not for the tick: it solves each coil's start once.
    pub fn start(&self, ambient_c: f64) -> GridObserverState<S, ROWS, COLS, N> {
        let below_k = S::from_f64(f64::from(super::start::START_BELOW_LIMIT_K));
        let mut grid = GridState::uniform(ambient_c);
        let hot = S::from_f64(self.temp_below_limits(below_k).max(ambient_c));
        grid.temps_c = [[hot; COLS]; ROWS];
        self.state_from(grid)
    }

    /// The deliberate clear of a latched shutdown (one restored from a
    /// snapshot, set by [`Self::conservative_state`], or raised by the
    /// alarm), for the application to call after inspecting the device.
    /// Nothing else clears it: not a tick, not a reset of the MCU (the
    /// latch is saved in the snapshot). It is [`AlarmState::reset`] under
    /// its conditions: every coil's upper bound valid and below its alarm
    /// limit minus the hysteresis for the alarm's `debounce_ticks`
    /// protection passes (so a state must have ticked that long). On
    /// success a [`Reset`](crate::protect::events::EventKind::Reset) event
    /// is queued and the published `alarm.shutdown` is `false` at once; the
    /// current limits, zero while latched, come back with the next limiter
    /// stage.
    /// Not for the tick: call it between two ticks.
    ///
    /// # Errors
    /// Why not, naming the first coil that blocks it; nothing changes then.
    pub fn clear_shutdown(
        &self,
        state: &mut GridObserverState<S, ROWS, COLS, N>,
    ) -> Result<(), ResetError> {
        state.latch().clear(&self.alarm)
    }

    /// The temperature [`Self::conservative_state`] assumes \[degC\].
    pub fn restart_temp_c(&self) -> f64 {
        self.restart_c
    }
}

#[cfg(test)]
mod tests {
    use super::ln;

    #[test]
    fn ln_is_within_a_few_ulps_of_the_f64_logarithm() {
        // Ratios from just above 1 (a coil far from its limit's crossing,
        // or a slow one) to 1e30, geometrically spaced, plus the points
        // where the reduction switches (powers of 2 and their sqrt(2)).
        let mut x = 1.0f32;
        let mut worst_ulps = 0.0f64;
        let mut check = |x: f32| {
            let got = ln(x) as f64;
            let want = (x as f64).ln();
            let ulp = f32::EPSILON as f64 * want.abs().max(f32::MIN_POSITIVE as f64);
            worst_ulps = worst_ulps.max((got - want).abs() / ulp);
        };
        while x < 1e30 {
            check(x);
            check(f32::from_bits(x.to_bits() + 1));
            x *= 1.0137;
        }
        for e in 0..40 {
            let p = (1u64 << e) as f32;
            for y in [p, p * core::f32::consts::SQRT_2] {
                for d in [-1i32, 0, 1] {
                    check(f32::from_bits(y.to_bits().wrapping_add_signed(d)).max(1.0));
                }
            }
        }
        assert!(worst_ulps <= 4.0, "{worst_ulps} ulps");
        assert_eq!(ln(1.0), 0.0);
        assert!(ln(f32::NAN).is_nan());
        assert_eq!(ln(f32::INFINITY), f32::INFINITY);
    }
}
