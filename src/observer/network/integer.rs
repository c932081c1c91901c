//! The network observer's model step in integer arithmetic (the
//! `integer-step` feature; see "The model step in integer arithmetic" in
//! the parent module).
//!
//! The step's own state, one Q16.48 temperature per node, stays in the
//! observer state between steps ([`IntegerStates`]), and the `f32`
//! estimate is its image. Reading the estimate back into the integer state
//! every step (two `f32` conversions per node) and writing what the image
//! does not hold into a residual (two more) cost more on a Cortex-M0 than
//! the step's products; so the integer states are the step's memory, and
//! the estimate is read back only where it was moved since the step wrote
//! it (a correction, the common-mode rule, a start or a restore). The move
//! is then added to the integer state exactly (both are whole multiples of
//! 2^-48 K within the state's range), so a correction moves what the next
//! step starts from, and nothing the integer state held below the image's
//! last bit is lost.

use nalgebra::SVector;

use crate::discretize::fixed::{f32_of_state, finite_bits, state_of_f32, FixedInputs, FixedStep};

/// The integer step's memory in an observer state: each node's Q16.48
/// deviation \[K\] and the bits of the `f32` estimate it last wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct IntegerStates<const N: usize> {
    /// Q16.48 deviations from the origin \[K\].
    states: [i64; N],
    /// The `f32` bits the last step wrote to each deviation.
    written: [u32; N],
    /// `false` until the first step: the states are then read from the
    /// estimate and its residual.
    valid: bool,
}

impl<const N: usize> IntegerStates<N> {
    /// No step taken yet.
    pub(crate) const fn new() -> Self {
        Self {
            states: [0; N],
            written: [0; N],
            valid: false,
        }
    }
}

/// One model step of the deviations `x` (their first `N` entries) with
/// the Joule powers `power` \[W\] and boundary deviations `boundary` \[K\].
/// `false` (nothing changed) for a non-finite input or deviation (only a
/// corrupted state gets one): the caller keeps its estimate, as the `f32`
/// step does. Out of line, so that the tick around it keeps its
/// registers.
#[inline(never)]
pub(crate) fn integer_predict<const N: usize, const B: usize, const M: usize, const X: usize>(
    step: &FixedStep<N, B, M>,
    memory: &mut IntegerStates<N>,
    x: &mut SVector<f32, X>,
    residual_k: &[f32; N],
    power: &SVector<f32, M>,
    boundary: &SVector<f32, B>,
) -> bool {
    let Some(inputs) = FixedInputs::new(&(*power).into(), &(*boundary).into()) else {
        return false;
    };
    let mut states = memory.states;
    for (i, (q, xi)) in states.iter_mut().zip(x.iter()).enumerate() {
        let bits = xi.to_bits();
        if memory.valid && bits == memory.written[i] {
            continue;
        }
        if !finite_bits(*xi) {
            return false;
        }
        *q = if memory.valid {
            // Moved since the last step: the move, exactly.
            let before = f32::from_bits(memory.written[i]);
            q.saturating_add(state_of_f32(*xi).saturating_sub(state_of_f32(before)))
        } else {
            let r = residual_k.get(i).copied().unwrap_or(0.0);
            if !finite_bits(r) {
                return false;
            }
            state_of_f32(*xi).saturating_add(state_of_f32(r))
        };
    }
    step.step(&mut states, &inputs);
    for ((xi, written), q) in x.iter_mut().zip(memory.written.iter_mut()).zip(&states) {
        *xi = f32_of_state(*q);
        *written = xi.to_bits();
    }
    memory.states = states;
    memory.valid = true;
    true
}
