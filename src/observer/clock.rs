//! From the controller's measured elapsed time to whole model steps.
//!
//! A 1 ms loop is never exactly 1 ms: ticks jitter, run late, or are missed
//! when a higher-priority task overruns. The observer is therefore driven by
//! the *measured* elapsed time in integer microseconds (what an MCU timer
//! gives, with no float and no drift), never by an assumed period.
//!
//! [`StepClock`] keeps the time not yet simulated (the *debt*, always below one
//! model step) and answers how many model steps this tick must take. A tick
//! that arrives 3.4 ms after the last one takes 3 steps and carries 0.4 ms;
//! the next normal tick then takes 1 step and carries 0.4 ms again, so no time
//! is ever lost or invented, and every step keeps the stable step size it was
//! built with.
//!
//! Bounded work: at most `max_steps_per_tick` steps per call. Time beyond that
//! (a stall of the control loop) is dropped and reported with
//! [`InputFlags::ELAPSED_INVALID`](crate::InputFlags::ELAPSED_INVALID), so the
//! caller knows the estimate skipped a stretch of time.
//!
//! # A frozen clock
//!
//! A timer that stops (`elapsed_us = 0` on every tick) would stop the model:
//! the coils heat at 9 A while the estimate stands still, with nothing
//! flagged. So the clock counts the consecutive ticks with no elapsed time
//! ([`ClockState::frozen_ticks`]); an early tick (some time, less than a
//! step) is not frozen: its time is carried. From
//! [`StepClock::frozen_flag_ticks`] such ticks on (default
//! [`DEFAULT_FROZEN_FLAG_TICKS`], 100: 0.1 s at a 1 ms loop) every tick is
//! flagged [`InputFlags::CLOCK_FROZEN`]; from
//! [`StepClock::frozen_loss_ticks`] on (default
//! [`DEFAULT_FROZEN_LOSS_TICKS`], 1000: 1 s, against thermal time constants
//! of seconds to minutes) the model is taken as lost
//! ([`TickSteps::clock_lost`]) and the observers latch the shutdown through
//! the alarm's latch, with a
//! [`ClockFrozen`](crate::protect::events::EventKind::ClockFrozen) event.
//! Set both with [`StepClock::with_frozen_limits`]. One tick with elapsed
//! time ends the count (the latch stays until its deliberate clear).

use crate::error::BuildError;
use crate::input::InputFlags;
use crate::sizes::Length;

/// The step size and the catch-up limit (configuration).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepClock {
    pub(crate) step_us: u32,
    pub(crate) max_steps_per_tick: u32,
    pub(crate) frozen_flag_ticks: u32,
    pub(crate) frozen_loss_ticks: u32,
}

/// Consecutive ticks without elapsed time from which every tick is flagged
/// [`InputFlags::CLOCK_FROZEN`] (0.1 s at a 1 ms loop).
pub const DEFAULT_FROZEN_FLAG_TICKS: u32 = 100;
/// Consecutive ticks without elapsed time from which the model is taken as
/// lost and the shutdown latches (1 s at a 1 ms loop).
pub const DEFAULT_FROZEN_LOSS_TICKS: u32 = 1000;

/// The time not yet simulated (per-device state) \[us\].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClockState {
    /// Elapsed time carried to the next tick, below one step \[us\].
    pub debt_us: u32,
    /// Consecutive ticks with no elapsed time (saturating; see the module
    /// docs).
    pub frozen_ticks: u32,
}

/// Steps handed back to the next tick ([`StepClock::defer`]; per-device
/// state, next to a [`ClockState`], for a clock that defers).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Deferral {
    /// Steps the last tick handed back: the next tick takes them on top of
    /// its catch-up bound.
    pub steps: u32,
    /// This tick took deferred steps: it may not defer (never twice in a
    /// row).
    pub took: bool,
}

/// How many model steps a tick takes, and what was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickSteps {
    /// Model steps to take now.
    pub steps: u32,
    /// Time dropped because it exceeded the catch-up limit \[us\].
    pub dropped_us: u32,
    /// [`InputFlags::ELAPSED_INVALID`] when time was dropped,
    /// [`InputFlags::CLOCK_FROZEN`] when the clock has stood still for
    /// [`StepClock::frozen_flag_ticks`] ticks or more.
    pub flags: InputFlags,
    /// The clock has stood still for [`StepClock::frozen_loss_ticks`] ticks
    /// or more: the model is lost (the observers latch the shutdown).
    pub clock_lost: bool,
}

impl StepClock {
    /// A clock for model steps of `step_us` \[us\] taking at most
    /// `max_steps_per_tick` steps per tick.
    pub fn new(step_us: u32, max_steps_per_tick: u32) -> Result<Self, BuildError> {
        if step_us == 0 {
            return Err(BuildError::InvalidTimeStep);
        }
        if max_steps_per_tick == 0 {
            return Err(BuildError::InvalidParameter {
                name: "max_steps_per_tick",
            });
        }
        Ok(Self {
            step_us,
            max_steps_per_tick,
            frozen_flag_ticks: DEFAULT_FROZEN_FLAG_TICKS,
            frozen_loss_ticks: DEFAULT_FROZEN_LOSS_TICKS,
        })
    }

    /// This clock with a frozen clock flagged after `flag_ticks` and taken
    /// as a loss of the model after `loss_ticks` consecutive ticks without
    /// elapsed time (see the module docs; defaults
    /// [`DEFAULT_FROZEN_FLAG_TICKS`] and [`DEFAULT_FROZEN_LOSS_TICKS`]).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming `frozen_flag_ticks` when it
    /// is 0, or `frozen_loss_ticks` when it is below `flag_ticks`.
    pub fn with_frozen_limits(
        mut self,
        flag_ticks: u32,
        loss_ticks: u32,
    ) -> Result<Self, BuildError> {
        if flag_ticks == 0 {
            return Err(BuildError::InvalidParameter {
                name: "frozen_flag_ticks",
            });
        }
        if loss_ticks < flag_ticks {
            return Err(BuildError::InvalidParameter {
                name: "frozen_loss_ticks (below frozen_flag_ticks)",
            });
        }
        self.frozen_flag_ticks = flag_ticks;
        self.frozen_loss_ticks = loss_ticks;
        Ok(self)
    }

    /// Consecutive ticks without elapsed time from which ticks are flagged
    /// [`InputFlags::CLOCK_FROZEN`].
    pub fn frozen_flag_ticks(&self) -> u32 {
        self.frozen_flag_ticks
    }

    /// Consecutive ticks without elapsed time from which the model is lost.
    pub fn frozen_loss_ticks(&self) -> u32 {
        self.frozen_loss_ticks
    }

    /// The model step \[us\].
    pub fn step_us(&self) -> u32 {
        self.step_us
    }

    /// The model step \[s\].
    pub fn step_s(&self) -> f64 {
        self.step_us as f64 * 1e-6
    }

    /// Adds `elapsed_us` \[us\] of real time and returns the steps to take.
    /// Never panics; saturating arithmetic throughout.
    pub fn advance(&self, state: &mut ClockState, elapsed_us: u32) -> TickSteps {
        self.advance_with(state, elapsed_us, 0)
    }

    /// [`Self::advance`] for a clock that defers ([`Self::defer`]): the
    /// steps the last tick handed back come on top of the catch-up bound.
    pub fn advance_deferring(
        &self,
        state: &mut ClockState,
        deferral: &mut Deferral,
        elapsed_us: u32,
    ) -> TickSteps {
        let extra = core::mem::take(&mut deferral.steps);
        deferral.took = extra > 0;
        self.advance_with(state, elapsed_us, extra)
    }

    #[inline(always)]
    fn advance_with(&self, state: &mut ClockState, elapsed_us: u32, extra: u32) -> TickSteps {
        state.frozen_ticks = if elapsed_us == 0 {
            state.frozen_ticks.saturating_add(1)
        } else {
            0
        };
        let mut steps = self.advance_time(state, elapsed_us, extra);
        if state.frozen_ticks >= self.frozen_flag_ticks {
            steps.flags |= InputFlags::CLOCK_FROZEN;
        }
        steps.clock_lost = state.frozen_ticks >= self.frozen_loss_ticks;
        steps
    }

    /// [`Self::advance_deferring`], then this tick's steps handed to the
    /// next tick ([`Self::defer`]) when `reading`: the Omnimagnet
    /// observer's rule for a model step several ticks long, whose step
    /// waits a tick for a correction's (the two together would make the
    /// heaviest tick). The network observer does not defer (its module
    /// docs, "Model step and ticks", say why).
    #[inline(always)]
    pub(crate) fn advance_around_readings(
        &self,
        state: &mut ClockState,
        deferral: &mut Deferral,
        elapsed_us: u32,
        reading: bool,
    ) -> TickSteps {
        let mut steps = self.advance_deferring(state, deferral, elapsed_us);
        if reading {
            self.defer(state, deferral, &mut steps);
        }
        steps
    }

    /// Hands this tick's steps back (`steps.steps` becomes 0): the next
    /// tick takes them, beyond its catch-up bound, so no time is dropped
    /// for them. For a tick that already carries other heavy work (a
    /// correction) when a model step is several ticks long: the step then
    /// ends one tick later (the next tick must come through
    /// [`Self::advance_deferring`]). At most once in a row and never with
    /// dropped time, so the steps of one tick stay bounded by
    /// `max_steps_per_tick` plus the deferred ones. Returns whether it
    /// deferred.
    pub fn defer(
        &self,
        state: &mut ClockState,
        deferral: &mut Deferral,
        steps: &mut TickSteps,
    ) -> bool {
        if steps.steps == 0 || steps.dropped_us > 0 || deferral.steps > 0 || deferral.took {
            return false;
        }
        state.debt_us = state
            .debt_us
            .saturating_add(steps.steps.saturating_mul(self.step_us));
        deferral.steps = steps.steps;
        steps.steps = 0;
        true
    }

    fn advance_time(&self, state: &mut ClockState, elapsed_us: u32, extra: u32) -> TickSteps {
        let max_steps = self.max_steps_per_tick.saturating_add(extra);
        // `new` refuses a zero step; `max(1)` lets the compiler see it, so no
        // division check (and no panic path) is left in the tick.
        let step_us = self.step_us.max(1);
        let (due, remainder) = whole_steps(state.debt_us, elapsed_us, step_us);
        if due <= max_steps as u64 {
            state.debt_us = remainder;
            TickSteps {
                steps: due as u32,
                dropped_us: 0,
                flags: InputFlags::NONE,
                clock_lost: false,
            }
        } else {
            let excess_steps = due - max_steps as u64;
            let dropped = excess_steps.saturating_mul(self.step_us as u64);
            state.debt_us = remainder;
            TickSteps {
                steps: max_steps,
                dropped_us: u32::try_from(dropped).unwrap_or(u32::MAX),
                flags: InputFlags::ELAPSED_INVALID,
                clock_lost: false,
            }
        }
    }
}

/// The energy account of the model step in progress, for a step several
/// ticks long (the multi-rate model of both filtered observers): each
/// current's `I^2` times the time it was held \[A^2 us\] over the ticks
/// the clock's debt covers, and whether the held currents changed within
/// the step (per-device state).
///
/// Each tick's held current heats for the tick's elapsed time, so the
/// steps taken on a tick (and any time dropped with them) get the energy
/// of the whole interval they cover, `sum(I^2 dt) / (steps step_us +
/// dropped_us)`, and the time carried past them starts the next step's
/// account at the held current. A step several ticks long then heats with
/// the exact mean power of its ticks' currents at its start temperature,
/// where the held current of the tick it lands on would sample (alias) a
/// current that changes within the step, and could read cold (0.74 K cold
/// after 30 s of a 2 ms square wave at 5 ms steps on the Omnimagnet,
/// `host-tests/tests/omni_multirate.rs`).
///
/// The account is kept by segments of constant held currents: a tick that
/// holds them adds its time to the segment, an integer add; a tick that
/// moves them first closes the segment, `I^2` times its time for each
/// current. The `f32` multiplies then come with a change of current, not
/// with every tick (on a core without an FPU, about 300 instructions a
/// current on every tick of the step).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StepAccount<M: Length> {
    /// Each current's `I^2` times the time it was held \[A^2 us\], over
    /// the closed segments of the clock's debt.
    i2_a2_us: M::Array<f32>,
    /// The open segment: the time \[us\] of the clock's debt at the
    /// currents held now.
    held_us: u32,
    /// The held currents changed within the step in progress: its power
    /// takes the mean `I^2`, not the held current.
    mixed: bool,
}

impl<M: Length> StepAccount<M> {
    /// An empty account of `currents` (a new state: no debt).
    pub(crate) fn new(currents: M) -> Self {
        Self {
            i2_a2_us: currents.filled(0.0),
            held_us: 0,
            mixed: false,
        }
    }

    /// Whether a tick's `incoming` currents \[A\] may move the `held`
    /// ones while a step is in progress (`debt_before_us` \[us\] of it
    /// covered): asked before the input rules take them, so a current they
    /// refuse counts as moved too, which only costs the mean of a step
    /// whose current stayed (the same energy). Bits, not values: an
    /// integer compare on a core without an FPU. A move closes the open
    /// segment at the `held` currents.
    #[inline(always)]
    pub(crate) fn moves(
        &mut self,
        debt_before_us: u32,
        incoming: &M::Array<f32>,
        held: &M::Array<f32>,
    ) -> bool {
        let moved = debt_before_us > 0
            && incoming
                .as_ref()
                .iter()
                .zip(held.as_ref())
                .any(|(a, b)| a.to_bits() != b.to_bits());
        if moved && self.held_us > 0 {
            let held_us = self.held_us as f32;
            for (s, i) in self.i2_a2_us.as_mut().iter_mut().zip(held.as_ref()) {
                *s += i * i * held_us;
            }
            self.held_us = 0;
        }
        moved
    }

    /// Accounts for a tick of `elapsed_us` \[us\] at `held_a` \[A\]
    /// (`moved`: [`Self::moves`] of its currents; `debt_before_us` the
    /// clock's debt before it and `debt_after_us` after, `steps` of
    /// `step_us` taken on it). Returns the mean square current \[A^2\] of
    /// this tick's steps when the held currents changed within them;
    /// `None` when they did not, and the steps take the held currents, to
    /// the bit as a model without the account.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn account(
        &mut self,
        held_a: &M::Array<f32>,
        moved: bool,
        debt_before_us: u32,
        debt_after_us: u32,
        elapsed_us: u32,
        steps: &TickSteps,
        step_us: u32,
    ) -> Option<M::Array<f32>> {
        if debt_before_us == 0 && debt_after_us == 0 {
            // Ticks on the steps' boundaries (the usual loop): a step
            // ended with the tick before, so the account is empty, and
            // this tick's steps end with it.
            return None;
        }
        let mixed = self.mixed || moved;
        if steps.steps == 0 {
            // The open segment is part of the clock's debt, so bounded.
            self.held_us = self.held_us.saturating_add(elapsed_us);
            self.mixed = mixed;
            return None;
        }
        let mean = mixed.then(|| {
            // The steps and the dropped time cover the debt before this
            // tick and this tick's time up to the new debt.
            let covered_us = steps
                .steps
                .saturating_mul(step_us)
                .saturating_add(steps.dropped_us);
            // The open segment's time and this tick's up to the new debt:
            // what the closed segments (the rest of the debt before this
            // tick) leave of the covered time. Negative after a deferral,
            // whose carried time this tick's current is charged for: the
            // energy stays whole.
            let closed_us = debt_before_us.saturating_sub(self.held_us);
            let at_held_us = if covered_us >= closed_us {
                (covered_us - closed_us) as f32
            } else {
                -((closed_us - covered_us) as f32)
            };
            let per_us = 1.0 / covered_us.max(1) as f32;
            let mut mean = M::filled_like(held_a, 0.0);
            let sums = self.i2_a2_us.as_ref();
            for ((mean, s), i) in mean.as_mut().iter_mut().zip(sums).zip(held_a.as_ref()) {
                let energy = s + i * i * at_held_us;
                // Not below zero (only a deferral's redistribution could
                // get there, and the carry then holds more than its share).
                *mean = if energy > 0.0 { energy * per_us } else { 0.0 };
            }
            mean
        });
        // The time carried past the steps opens the next step's account
        // at the held currents.
        if mixed {
            self.i2_a2_us = M::filled_like(&self.i2_a2_us, 0.0);
        }
        self.held_us = debt_after_us;
        self.mixed = false;
        mean
    }
}

/// The square currents \[A^2\] a step heats with: the account's mean
/// `I^2` when the held currents changed within it (`mean_sq_a2`, from
/// [`StepAccount::account`]), else the held currents `held_a` \[A\]
/// squared. Powers are `R(T)` times these: no root is taken.
#[inline(always)]
pub(crate) fn step_square_currents<M: Length>(
    mean_sq_a2: Option<M::Array<f32>>,
    held_a: &M::Array<f32>,
) -> M::Array<f32> {
    mean_sq_a2.unwrap_or_else(|| M::mapped(held_a, |i| i * i))
}

/// `(debt_us + elapsed_us) / step_us` and its remainder, the sum taken
/// exactly (it may pass `u32`), with 32-bit divisions only: a Cortex-M0
/// has no divider at all, and a 64-bit division would link
/// `__aeabi_uldivmod` (about 900 B) for a 71-minute stall.
#[inline(always)]
fn whole_steps(debt_us: u32, elapsed_us: u32, step_us: u32) -> (u64, u32) {
    match debt_us.checked_add(elapsed_us) {
        // Always, short of a 71-minute stall: one division.
        Some(total_us) => (u64::from(total_us / step_us), total_us % step_us),
        None => {
            // Each term in whole steps and a remainder below a step; the
            // two remainders make at most one step more (compared against
            // `step - r2`, since `r1 + r2` itself may pass `u32`).
            let (q1, r1) = (elapsed_us / step_us, elapsed_us % step_us);
            let (q2, r2) = (debt_us / step_us, debt_us % step_us);
            let to_next_step = step_us - r2;
            let (carry, remainder) = if r1 >= to_next_step {
                (1, r1 - to_next_step)
            } else {
                (0, r1 + r2)
            };
            (u64::from(q1) + u64::from(q2) + carry, remainder)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jitter_is_carried_and_no_time_is_lost() {
        let clock = StepClock::new(1000, 10).unwrap();
        let mut state = ClockState::default();
        let elapsed = [1000, 950, 1050, 3400, 0, 600, 1000, 2];
        let mut steps = 0;
        for e in elapsed {
            let t = clock.advance(&mut state, e);
            assert!(t.flags.is_clean());
            steps += t.steps;
        }
        let total: u32 = elapsed.iter().sum();
        assert_eq!(steps * 1000 + state.debt_us, total);
        assert!(state.debt_us < 1000);
    }

    #[test]
    fn a_stall_is_bounded_and_reported() {
        let clock = StepClock::new(1000, 5).unwrap();
        let mut state = ClockState::default();
        let t = clock.advance(&mut state, 12_300);
        assert_eq!(t.steps, 5);
        assert_eq!(t.dropped_us, 7000);
        assert_eq!(state.debt_us, 300);
        assert!(t.flags.contains(InputFlags::ELAPSED_INVALID));
        let t = clock.advance(&mut state, u32::MAX);
        assert_eq!(t.steps, 5);
        assert!(t.flags.contains(InputFlags::ELAPSED_INVALID));
        // 300 us of debt plus u32::MAX overflows 32 bits: the 64-bit path
        // carries the remainder all the same.
        assert_eq!(
            state.debt_us as u64,
            (300 + u32::MAX as u64) % 1000,
            "remainder past 2^32"
        );
    }

    #[test]
    fn a_deferred_step_comes_with_the_next_tick_and_no_time_is_dropped() {
        let clock = StepClock::new(5000, 1).unwrap();
        let mut state = ClockState::default();
        let mut deferral = Deferral::default();
        let mut taken = 0;
        for _ in 0..4 {
            taken += clock
                .advance_deferring(&mut state, &mut deferral, 1000)
                .steps;
        }
        let mut t = clock.advance_deferring(&mut state, &mut deferral, 1000);
        assert_eq!((taken, t.steps), (0, 1));
        assert!(clock.defer(&mut state, &mut deferral, &mut t));
        assert_eq!((t.steps, state.debt_us), (0, 5000));
        // Once in a row only.
        let mut again = t;
        again.steps = 1;
        assert!(!clock.defer(&mut state, &mut deferral, &mut again));
        // A late tick: its own step and the deferred one, nothing dropped.
        let mut t = clock.advance_deferring(&mut state, &mut deferral, 5200);
        assert_eq!((t.steps, t.dropped_us, state.debt_us), (2, 0, 200));
        assert!(t.flags.is_clean());
        // Never twice in a row: the tick that takes them keeps them.
        assert!(!clock.defer(&mut state, &mut deferral, &mut t));
        assert_eq!(t.steps, 2);
        // The bound is back to one step.
        let t = clock.advance_deferring(&mut state, &mut deferral, 10_000);
        assert_eq!((t.steps, t.dropped_us, state.debt_us), (1, 5000, 200));
    }

    proptest::proptest! {
        /// The account by segments against an `f64` account tick by tick:
        /// each step's mean `I^2` is the energy of the time its tick
        /// covers over that time, and a step whose held currents did not
        /// change takes them (`None`) exactly when its ticks all held
        /// the same currents; with steps deferred past a reading's tick
        /// too (fails if a deferral's negative share is dropped).
        #[test]
        fn the_steps_mean_square_current_is_the_energy_of_their_ticks(
            ticks in proptest::collection::vec(
                (0u32..2600, 0usize..3, 0usize..3, proptest::bool::weighted(0.1)),
                1..400,
            ),
        ) {
            const STEP_US: u32 = 5000;
            let levels = [0.0f32, 3.7, 12.25];
            let clock = StepClock::new(STEP_US, 4).unwrap();
            let mut state = ClockState::default();
            let mut deferral = Deferral::default();
            let mut account = StepAccount::new(nalgebra::Const::<2>);
            let mut held = [0.0f32; 2];
            // The reference: each current's energy over the debt [A^2 us],
            // and whether the debt saw more than one set of currents.
            let mut energy = [0.0f64; 2];
            let mut changed = false;
            for (elapsed_us, a, b, reading) in ticks {
                let incoming = [levels[a], levels[b]];
                let debt_before_us = state.debt_us;
                // A reading's tick hands its steps to the next (the
                // Omnimagnet's rule): a debt beyond a step, and a tick
                // charged for time the deferred steps carried.
                let steps =
                    clock.advance_around_readings(&mut state, &mut deferral, elapsed_us, reading);
                let moved = account.moves(debt_before_us, &incoming, &held);
                changed |= debt_before_us > 0 && incoming != held;
                held = incoming;
                let mean = account.account(
                    &held, moved, debt_before_us, state.debt_us, elapsed_us, &steps, STEP_US,
                );
                let sq = held.map(|i| f64::from(i) * f64::from(i));
                if steps.steps == 0 {
                    for (e, q) in energy.iter_mut().zip(&sq) {
                        *e += q * f64::from(elapsed_us);
                    }
                    proptest::prop_assert!(mean.is_none());
                    continue;
                }
                let covered_us = f64::from(steps.steps * STEP_US + steps.dropped_us);
                let now_us = covered_us - f64::from(debt_before_us);
                let expected: [f64; 2] = core::array::from_fn(|m| {
                    ((energy[m] + sq[m] * now_us) / covered_us).max(0.0)
                });
                match mean {
                    Some(mean) => {
                        proptest::prop_assert!(changed);
                        for (got, want) in mean.iter().zip(&expected) {
                            proptest::prop_assert!(
                                (f64::from(*got) - want).abs() <= 1e-5 * want.max(1.0),
                                "{got} A^2, {want} A^2 in f64"
                            );
                        }
                    }
                    None => {
                        proptest::prop_assert!(!changed);
                        for (q, want) in sq.iter().zip(&expected) {
                            proptest::prop_assert!((q - want).abs() <= 1e-9 * want.max(1.0));
                        }
                    }
                }
                energy = sq.map(|q| q * f64::from(state.debt_us));
                changed = false;
            }
        }
    }

    /// `whole_steps` by the 64-bit division it replaces.
    fn whole_steps_u64(debt_us: u32, elapsed_us: u32, step_us: u32) -> (u64, u32) {
        let total_us = u64::from(debt_us) + u64::from(elapsed_us);
        let step_us = u64::from(step_us);
        (total_us / step_us, (total_us % step_us) as u32)
    }

    #[test]
    fn whole_steps_past_u32_match_the_64_bit_division_at_the_extremes() {
        let edges = [
            0,
            1,
            2,
            999,
            1000,
            1001,
            0x7fff_ffff,
            0x8000_0000,
            0x8000_0001,
            u32::MAX - 1,
            u32::MAX,
        ];
        let mut past_u32 = 0;
        for debt in edges {
            for elapsed in edges {
                for step in edges.iter().copied().filter(|s| *s > 0) {
                    past_u32 += u32::from(debt.checked_add(elapsed).is_none());
                    assert_eq!(
                        whole_steps(debt, elapsed, step),
                        whole_steps_u64(debt, elapsed, step),
                        "debt {debt} us, elapsed {elapsed} us, step {step} us"
                    );
                }
            }
        }
        // The halves' path was taken, not only the 32-bit sum's.
        assert!(past_u32 > 100, "{past_u32}");
    }

    proptest::proptest! {
        #[test]
        fn whole_steps_match_the_64_bit_division(
            debt in proptest::prelude::any::<u32>(),
            elapsed in proptest::prelude::any::<u32>(),
            step in proptest::prop_oneof![1u32..5000, 1u32..],
        ) {
            proptest::prop_assert_eq!(
                whole_steps(debt, elapsed, step),
                whole_steps_u64(debt, elapsed, step)
            );
        }

        #[test]
        fn a_stall_drops_what_the_64_bit_arithmetic_drops(
            debt in proptest::prelude::any::<u32>(),
            elapsed in proptest::prelude::any::<u32>(),
            step in proptest::prop_oneof![1u32..5000, 1u32..],
            max_steps in proptest::prop_oneof![1u32..16, 1u32..],
        ) {
            let clock = StepClock::new(step, max_steps).unwrap();
            let mut state = ClockState { debt_us: debt, frozen_ticks: 0 };
            let t = clock.advance(&mut state, elapsed);
            let (due, remainder) = whole_steps_u64(debt, elapsed, step);
            let taken = due.min(u64::from(max_steps));
            let dropped = (due - taken).saturating_mul(u64::from(step));
            proptest::prop_assert_eq!(u64::from(t.steps), taken);
            proptest::prop_assert_eq!(u64::from(t.dropped_us), dropped.min(u64::from(u32::MAX)));
            proptest::prop_assert_eq!(state.debt_us, remainder);
            proptest::prop_assert_eq!(t.flags.contains(InputFlags::ELAPSED_INVALID), due > taken);
        }
    }

    #[test]
    fn invalid_clocks_are_refused() {
        assert_eq!(StepClock::new(0, 1), Err(BuildError::InvalidTimeStep));
        assert!(StepClock::new(1000, 0).is_err());
        let clock = StepClock::new(1000, 4).unwrap();
        assert!(clock.with_frozen_limits(0, 10).is_err());
        assert!(clock.with_frozen_limits(10, 9).is_err());
        assert!(clock.with_frozen_limits(10, 10).is_ok());
    }

    #[test]
    fn a_frozen_clock_is_flagged_then_lost_and_one_tick_of_time_ends_it() {
        let clock = StepClock::new(1000, 4).unwrap();
        assert_eq!(clock.frozen_flag_ticks(), DEFAULT_FROZEN_FLAG_TICKS);
        assert_eq!(clock.frozen_loss_ticks(), DEFAULT_FROZEN_LOSS_TICKS);
        let clock = clock.with_frozen_limits(3, 5).unwrap();
        let mut state = ClockState::default();
        let mut seen = [(false, false); 6];
        for s in &mut seen {
            let t = clock.advance(&mut state, 0);
            *s = (t.flags.contains(InputFlags::CLOCK_FROZEN), t.clock_lost);
        }
        let (f, t) = (false, true);
        assert_eq!(seen, [(f, f), (f, f), (t, f), (t, f), (t, t), (t, t)]);
        // An early tick (time below a step) is not frozen.
        let t = clock.advance(&mut state, 1);
        assert_eq!(
            (t.steps, t.flags, t.clock_lost),
            (0, InputFlags::NONE, false)
        );
        assert_eq!(state.frozen_ticks, 0);
    }
}
