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

use crate::error::BuildError;
use crate::input::InputFlags;

/// The step size and the catch-up limit (configuration).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StepClock {
    step_us: u32,
    max_steps_per_tick: u32,
}

/// The time not yet simulated (per-device state) \[us\].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ClockState {
    /// Elapsed time carried to the next tick, below one step \[us\].
    pub debt_us: u32,
}

/// How many model steps a tick takes, and what was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TickSteps {
    /// Model steps to take now.
    pub steps: u32,
    /// Time dropped because it exceeded the catch-up limit \[us\].
    pub dropped_us: u32,
    /// [`InputFlags::ELAPSED_INVALID`] when time was dropped.
    pub flags: InputFlags,
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
        })
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
        // `new` refuses a zero step; `max(1)` lets the compiler see it, so no
        // division check (and no panic path) is left in the tick.
        let step_us = self.step_us.max(1);
        // In 32 bits whenever the sum fits (always, short of a 71-minute
        // stall): one `udiv` on a Cortex-M4 where the 64-bit division is a
        // library call of a hundred instructions or more.
        let (due, remainder) = match state.debt_us.checked_add(elapsed_us) {
            Some(total_us) => (u64::from(total_us / step_us), total_us % step_us),
            None => {
                let total_us = u64::from(state.debt_us) + u64::from(elapsed_us);
                let step_us = u64::from(step_us);
                (total_us / step_us, (total_us % step_us) as u32)
            }
        };
        if due <= self.max_steps_per_tick as u64 {
            state.debt_us = remainder;
            TickSteps {
                steps: due as u32,
                dropped_us: 0,
                flags: InputFlags::NONE,
            }
        } else {
            let excess_steps = due - self.max_steps_per_tick as u64;
            let dropped = excess_steps.saturating_mul(self.step_us as u64);
            state.debt_us = remainder;
            TickSteps {
                steps: self.max_steps_per_tick,
                dropped_us: u32::try_from(dropped).unwrap_or(u32::MAX),
                flags: InputFlags::ELAPSED_INVALID,
            }
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
    fn invalid_clocks_are_refused() {
        assert_eq!(StepClock::new(0, 1), Err(BuildError::InvalidTimeStep));
        assert!(StepClock::new(1000, 0).is_err());
    }
}
