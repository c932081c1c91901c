//! The integer step's memory between steps, for an observer whose `f32`
//! estimate is the image of the step's own states: the network observer's
//! estimate and its shadow's (see "The model step in integer arithmetic"
//! in [`crate::observer::network`]).
//!
//! The step's own state, one Q16.48 temperature per node, stays in the
//! observer state between steps ([`StepMemory`]), and the `f32`
//! estimate is its image. Reading the estimate back into the integer state
//! every step (two `f32` conversions per node) and writing what the image
//! does not hold into a residual (two more) cost more on a Cortex-M0 than
//! the step's products; so the integer states are the step's memory, and
//! the estimate is read back only where it was moved since the step wrote
//! it (a correction, the common-mode rule, a start or a restore). The move
//! is then added to the integer state exactly (both are whole multiples of
//! 2^-48 K within the state's range), so a correction moves what the next
//! step starts from, and nothing the integer state held below the image's
//! last bit is lost. A correction's move is read on the first tick without
//! a step or a reading after it ([`StepMemory::read_between_steps`]),
//! where a step several ticks long leaves room, rather than by the next
//! step: the same states to the bit, off the step's tick.

use super::{f32_of_state, finite_bits, state_of_f32, FixedInputs, FixedStep};
use crate::sizes::{BoundaryVector, InputVector, Length, NodeVector, Sizes};

/// The integer step's memory in an observer state: each node's Q16.48
/// deviation \[K\] and the bits of the `f32` estimate it last wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct StepMemory<N: Length> {
    /// Q16.48 deviations from the origin \[K\].
    states: N::Array<i64>,
    /// The `f32` bits the last step wrote to each deviation.
    written: N::Array<u32>,
    /// `false` until the first step: the states are then read from the
    /// estimate and its residual.
    valid: bool,
    /// The estimate waits to be read in on a tick between steps (see
    /// [`Self::read_between_steps`]): a correction's move, or, in an
    /// observer state's memory before its first step, all of it.
    read_due: bool,
}

impl<N: Length> StepMemory<N> {
    /// No step taken yet for `nodes`; the first step reads the estimate (a
    /// shadow's memory, which no tick between steps reads).
    pub(crate) fn new(nodes: N) -> Self {
        Self {
            states: nodes.filled(0),
            written: nodes.filled(0),
            valid: false,
            read_due: false,
        }
    }

    /// No step taken yet, the estimate to be read in on the first tick
    /// between steps (an observer state's memory: a start or a restore
    /// reads its estimate off the first step's tick).
    pub(crate) fn unread(nodes: N) -> Self {
        Self {
            read_due: true,
            ..Self::new(nodes)
        }
    }

    /// The estimate was set anew, its carry with it (a shadow reseeded):
    /// the next step reads it whole, as before the first step.
    pub(crate) fn forget(&mut self) {
        self.valid = false;
        self.read_due = false;
    }

    /// Whether the estimate waits to be read in between steps: a
    /// correction's move, or ([`Self::unread`]) all of it.
    pub(crate) const fn read_due(&self) -> bool {
        self.read_due
    }

    /// A correction moved the estimate: its move is read in on the next
    /// tick without a step ([`Self::read_between_steps`]), or by the
    /// next step (before the first step, with the rest of the estimate).
    pub(crate) fn corrected(&mut self) {
        self.read_due |= self.valid;
    }

    /// On a tick without a model step or a reading: reads a correction's
    /// move of the estimate `x` into the states now, or before the first
    /// step the whole estimate with its carry `residual_k` \[K\], so that
    /// the next step's tick does not pay for it as well as for the step
    /// (on a Cortex-M0, two soft conversions per node; the heaviest of the
    /// real motor's step ticks after a correction, and the network's first
    /// step). The same states to the bit as the step's own read (the
    /// moves are exact). Returns whether it read them (the tick is busy
    /// then); a non-finite deviation is left to the step, which keeps the
    /// estimate.
    pub(crate) fn read_between_steps(&mut self, x: &[f32], residual_k: &N::Array<f32>) -> bool {
        if !core::mem::take(&mut self.read_due) {
            return false;
        }
        let Some(states) = self.read_moves(x, residual_k) else {
            return false;
        };
        self.states = states;
        for (written, xi) in self.written.as_mut().iter_mut().zip(x.iter()) {
            *written = xi.to_bits();
        }
        self.valid = true;
        true
    }

    /// The states with the moves of `x` since the last write read in (all
    /// of `x` and its residual `residual_k` before the first step);
    /// `None` for a non-finite deviation or residual.
    #[inline(always)]
    fn read_moves(&self, x: &[f32], residual_k: &N::Array<f32>) -> Option<N::Array<i64>> {
        let mut states = self.states.clone();
        let read = states
            .as_mut()
            .iter_mut()
            .zip(x.iter())
            .zip(self.written.as_ref());
        for (i, ((q, xi), written)) in read.enumerate() {
            let bits = xi.to_bits();
            if self.valid && bits == *written {
                continue;
            }
            if !finite_bits(*xi) {
                return None;
            }
            *q = if self.valid {
                // Moved since the last step: the move, exactly.
                let before = f32::from_bits(*written);
                q.saturating_add(state_of_f32(*xi).saturating_sub(state_of_f32(before)))
            } else {
                let r = residual_k.as_ref().get(i).copied().unwrap_or(0.0);
                if !finite_bits(r) {
                    return None;
                }
                state_of_f32(*xi).saturating_add(state_of_f32(r))
            };
        }
        Some(states)
    }
}

/// One model step of the deviations `x` \[K\] (their first `N` entries;
/// a `f32` estimate whose image the memory keeps, `residual_k` its carry
/// \[K\], read before the first step only) with the Joule powers
/// `powers_w` \[W\] and boundary deviations `boundary_k` \[K\]. `false`
/// (nothing changed) for a non-finite input or deviation (only a corrupted
/// state gets one): the caller keeps its estimate, as the `f32` step does.
/// Out of line, so that the tick around it keeps its registers.
#[inline(never)]
pub(crate) fn step_in_memory<Z: Sizes>(
    step: &FixedStep<Z>,
    memory: &mut StepMemory<Z::NodeDim>,
    x: &mut [f32],
    residual_k: &NodeVector<Z, f32>,
    powers_w: &InputVector<Z, f32>,
    boundary_k: &BoundaryVector<Z, f32>,
) -> bool {
    let Some(inputs) = FixedInputs::new(powers_w, boundary_k) else {
        return false;
    };
    let Some(mut states) = memory.read_moves(x, residual_k) else {
        return false;
    };
    step.step(&mut states, &inputs);
    let written = memory.written.as_mut().iter_mut();
    for ((xi, written), q) in x.iter_mut().zip(written).zip(states.as_ref()) {
        *xi = f32_of_state(*q);
        *written = xi.to_bits();
    }
    memory.states = states;
    memory.valid = true;
    memory.read_due = false;
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::discretize::StepTables;

    /// A 2-node step (a winding on a housing tied to the boundary).
    fn two_nodes() -> super::super::ConstFixedStep<2, 1, 1> {
        FixedStep::of(&StepTables::<2, 1, 1> {
            phi_minus_i: [[-2e-3, 2e-3], [5e-4, -8e-4]],
            bd_power: [[1.6e-4], [1e-7]],
            gd_boundary: [[0.0], [3e-4]],
            constant_k: [0.0, 0.0],
        })
        .expect("tables within the step's scales")
    }

    /// The estimate read in on a tick between steps, the whole of it
    /// with its carry before the first step and a correction's move
    /// later, leaves the states, and so every later step, the same to
    /// the bit as the step's own read would; each is read once (a second
    /// light tick reads nothing).
    #[test]
    fn a_read_between_steps_is_the_steps_own_read() {
        let step = two_nodes();
        let (power, boundary) = ([40.0], [0.5]);
        let residual = [1.5e-6f32, -2.5e-7];
        let mut x = [3.0f32, 1.0, 0.25];
        let mut early = StepMemory::unread(nalgebra::Const::<2>);
        let mut late = early.clone();
        assert!(early.read_due(), "the whole estimate before the first step");
        assert!(
            !StepMemory::new(nalgebra::Const::<2>).read_due(),
            "a shadow's: its step reads"
        );
        let mut x_late = x;
        // `early` reads the start between steps, `late` by its first step.
        assert!(early.read_between_steps(&x, &residual));
        assert!(!early.read_between_steps(&x, &residual), "read once");
        assert!(!early.read_due());
        let step_both = |x: &mut [f32; 3],
                         x_late: &mut [f32; 3],
                         early: &mut StepMemory<nalgebra::Const<2>>,
                         late: &mut StepMemory<nalgebra::Const<2>>| {
            assert!(step_in_memory(
                &step, early, x, &residual, &power, &boundary
            ));
            assert!(step_in_memory(
                &step, late, x_late, &residual, &power, &boundary
            ));
        };
        for _ in 0..5 {
            step_both(&mut x, &mut x_late, &mut early, &mut late);
            assert_eq!(early.states, late.states);
            // The correction: a move of each deviation, the bias untouched.
            for xs in [&mut x, &mut x_late] {
                xs[0] -= 0.3125e-2;
                xs[1] += 1.7e-3;
            }
            early.corrected();
            late.corrected();
            assert!(early.read_between_steps(&x, &residual));
            assert!(!early.read_between_steps(&x, &residual), "read once");
        }
        step_both(&mut x, &mut x_late, &mut early, &mut late);
        assert_eq!(early.states, late.states);
        assert_eq!(x, x_late);
        assert!(!late.read_due(), "the step read it");
        // A non-finite deviation is left to the step, which keeps the
        // estimate.
        x[1] = f32::NAN;
        early.corrected();
        let before = early.states;
        assert!(!early.read_between_steps(&x, &residual));
        assert_eq!(early.states, before);
    }
}
