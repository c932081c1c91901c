//! The exact step in integer arithmetic, for a core without a
//! floating-point unit.
//!
//! The step is the one of [`super`] in deviation coordinates,
//!
//! ```text
//! x' = x + (Ad - I) x + Bd p + Gd y + c
//! ```
//!
//! (`x` the nodes' deviations from an origin \[K\], `p` the Joule powers
//! \[W\], `y` the boundaries' deviations \[K\], `c` the constant term \[K\]),
//! with the tables solved in `f64` and rounded once to `f32`
//! ([`StepTables`], the network observer's). Three choices make it cheap
//! without an FPU and as precise as the network observer's `f32` step with
//! its carried residual:
//!
//! * **State in Q16.48** (an `i64` per node: +-32 768 K in steps of
//!   3.6e-15 K): an increment of a slow node, 1e-7 K a step, is added with
//!   its rounding far below anything it accumulates to, where a plain `f32`
//!   temperature rounds it away near 100 K (see
//!   [`compensated_add`](crate::network::compensated_add)). Q32.32 is not
//!   enough: the same rounding of a constant-power step, 1e-10 K, repeats
//!   every millisecond, and a 1 000 s mode sums it to 1e-4 K (measured:
//!   Q32.32 states left a 3-node step under a constant ambient 3.4e-5 K
//!   off the `f64` recursion of its tables, Q16.48 states 6.7e-8 K, the
//!   inputs' rounding; see `the_integer_step_follows_the_f64_step`).
//! * **Coefficients scaled per row and per group** (temperatures, powers,
//!   boundaries): each group of a row is an `i32` table with its own power
//!   of two, so that its largest entry keeps 31 bits whatever its magnitude
//!   (`Ad - I` is about 1e-5, `Bd` 1e-4 K/J, `Gd` 1e-6 at a 1 ms step), and
//!   the sum of the group's magnitudes stays within 2^31. Every product is
//!   a 32 x 32 -> 64-bit integer multiply (`smlal` on a Cortex-M4, a short
//!   routine on a Cortex-M0, against about 200 instructions for a soft-float
//!   multiply-add); a group's sum is at most 2^62, so it never overflows.
//! * **Inputs of known range in Q12.20, powers in block floating point**:
//!   the nodes' and boundaries' deviations the step multiplies are `i32`
//!   Q12.20 (+-2 048 K from the origin in steps of 9.5e-7 K, finer than an
//!   `f32` near 100 degC; a boundary is clamped to the input limits
//!   before, a node beyond saturates there). The
//!   Joule powers have no such range (a winding at the current limit may
//!   take kilowatts, a sensor coil milliwatts), so they share one exponent
//!   per step, the largest power's, and each keeps its `f32` mantissa
//!   shifted to it: the powers' sum keeps `f32`'s relative precision.
//!
//! Every rounding is to nearest, so none drifts one way. The arithmetic is
//! integer throughout (the conversions from and to `f32` too), so a host
//! and any target compute the same bits.
//!
//! # In the network observer
//!
//! [`NetworkSettings::integer_model_step`](crate::observer::network::NetworkSettings::integer_model_step)
//! (a model file's `[observer] integer_model_step`, with the
//! `integer-step` feature) makes it the network observer's model step,
//! whose states it keeps between steps. On a Cortex-M0 the real motor's
//! mean tick is 17 063 instructions with it (and the predictor split by
//! element) against 36 759 all in `f32`; on a Cortex-M4F the `f32` step, a fused multiply-add an
//! entry, is cheaper than its shifts and conversions (the same form on
//! every core doubled the ticks there), so it is the file's choice
//! (docs/cost.md, "The model step in integer arithmetic").

use super::StepTables;
use crate::sizes::{BoundaryVector, ConstSizes, InputVector, Length, NodeVector, Sizes};

#[cfg(feature = "integer-step")]
mod memory;
#[cfg(feature = "integer-step")]
pub(crate) use memory::{step_in_memory, StepMemory};

/// Fractional bits of a node's state: Q16.48 in an `i64`.
pub const STATE_FRACTION_BITS: u32 = 48;
/// Fractional bits of a temperature the step multiplies: Q12.20 in an `i32`.
pub const INPUT_FRACTION_BITS: u32 = 20;

/// Shift from a temperature group's sum (`2^(scale + 20)`) to the state.
const TEMP_SHIFT: i32 = INPUT_FRACTION_BITS as i32 - STATE_FRACTION_BITS as i32;
/// Shift from a power group's sum (`2^(scale + 150 - exponent)`, see
/// [`FixedInputs`]) to the state, less the scale and plus the exponent.
const POWER_SHIFT: i32 = 150 - STATE_FRACTION_BITS as i32;
/// Smallest row scale: a group whose entries reach 2^30 (no physical step)
/// is refused.
const MIN_SCALE: i32 = 0;
/// Largest row scale: keeps every shift below 64. A group whose largest
/// entry is below 2^-31 (every entry of it then below 1e-9 of a step)
/// is held with fewer than 31 bits.
const MAX_SCALE: i32 = 62;

/// One step of [`StepTables`] in integer arithmetic (see the module docs).
/// Derived from the tables by [`FixedStep::of`], in a `const fn`, so a
/// generated observer's step is assembled by the compiler.
/// Over a network's [`Sizes`] (an MCU's: [`ConstFixedStep`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FixedStep<Z: Sizes> {
    /// `(Ad - I) 2^temp_scale[i]`, row `i`.
    temps: NodeVector<Z, NodeVector<Z, i32>>,
    /// `Bd 2^power_scale[i]` \[K/W\].
    powers: NodeVector<Z, InputVector<Z, i32>>,
    /// `Gd 2^boundary_scale[i]`.
    boundaries: NodeVector<Z, BoundaryVector<Z, i32>>,
    temp_scale: NodeVector<Z, u8>,
    power_scale: NodeVector<Z, u8>,
    boundary_scale: NodeVector<Z, u8>,
    /// `c` in Q16.48 \[K\].
    constant: NodeVector<Z, i64>,
}

/// The integer step of an MCU's network: `N` nodes, `B` boundaries, `M`
/// inputs known when the firmware is compiled.
pub type ConstFixedStep<const N: usize, const B: usize, const M: usize> =
    FixedStep<ConstSizes<N, B, M>>;

/// The inputs of one step: the Joule powers in block floating point and
/// the boundaries' deviations in Q12.20.
#[derive(Debug, Clone, PartialEq)]
pub struct FixedInputs<Z: Sizes> {
    /// Each power's mantissa at the shared exponent (`p = mantissa
    /// 2^(exponent - 150)`).
    power_mantissas: InputVector<Z, i32>,
    /// The shared exponent, biased as `f32`'s (0 with no power).
    power_exponent: i32,
    /// The boundaries' deviations, Q12.20 \[K\].
    boundaries: BoundaryVector<Z, i32>,
}

impl<Z: Sizes> FixedInputs<Z> {
    /// The inputs of a step with Joule powers `powers_w` \[W\] and boundary
    /// deviations `boundaries_k` \[K\]; `None` if one is not finite (the
    /// caller keeps its state rather than step on it). A boundary beyond
    /// +-2 048 K saturates there (the input limits clamp far inside).
    #[inline]
    pub fn new(
        powers_w: &InputVector<Z, f32>,
        boundaries_k: &BoundaryVector<Z, f32>,
    ) -> Option<Self> {
        let mut inputs = powers_w.as_ref().iter().chain(boundaries_k.as_ref());
        if !inputs.all(|v| finite_bits(*v)) {
            return None;
        }
        let split = Z::InputDim::mapped(powers_w, |p| split(*p));
        let power_exponent = split.as_ref().iter().map(|(_, e)| *e).max().unwrap_or(0);
        let power_mantissas =
            Z::InputDim::mapped(&split, |(m, e)| shift_round_i32(*m, power_exponent - e));
        Some(Self {
            power_mantissas,
            power_exponent,
            boundaries: Z::BoundaryDim::mapped(boundaries_k, |t| input_of_f32(*t)),
        })
    }
}

impl<const N: usize, const B: usize, const M: usize> ConstFixedStep<N, B, M> {
    /// The integer step of `tables`; `None` if an entry is not finite or a
    /// group's entries reach 2^30 (see [`FixedStep`]'s scales).
    pub const fn of(tables: &StepTables<N, B, M>) -> Option<Self> {
        let mut step = Self {
            temps: [[0; N]; N],
            powers: [[0; M]; N],
            boundaries: [[0; B]; N],
            temp_scale: [0; N],
            power_scale: [0; N],
            boundary_scale: [0; N],
            constant: [0; N],
        };
        let mut i = 0;
        while i < N {
            let Some(s) = scale_row(&tables.phi_minus_i[i], &mut step.temps[i]) else {
                return None;
            };
            step.temp_scale[i] = s;
            let Some(s) = scale_row(&tables.bd_power[i], &mut step.powers[i]) else {
                return None;
            };
            step.power_scale[i] = s;
            let Some(s) = scale_row(&tables.gd_boundary[i], &mut step.boundaries[i]) else {
                return None;
            };
            step.boundary_scale[i] = s;
            let c = tables.constant_k[i];
            if !finite_bits(c) {
                return None;
            }
            step.constant[i] = state_of_f32(c);
            i += 1;
        }
        Some(step)
    }
}

impl<Z: Sizes> FixedStep<Z> {
    /// [`ConstFixedStep::of`] over any sizes, the tables given by entry:
    /// `phi_minus_i(i, j)` of `Ad - I`, `bd_power(i, m)` of `Bd` \[K/J\],
    /// `gd_boundary(i, b)` of `Gd` and `constant_k(i)` of `c` \[K\] (not a
    /// `const fn`: for an observer built at run time). The same scales and
    /// entries as `of` of the same tables.
    pub fn of_entries(
        sizes: Z,
        phi_minus_i: impl Fn(usize, usize) -> f32,
        bd_power: impl Fn(usize, usize) -> f32,
        gd_boundary: impl Fn(usize, usize) -> f32,
        constant_k: impl Fn(usize) -> f32,
    ) -> Option<Self> {
        fn scaled<D: Length>(dim: D, entry: impl Fn(usize) -> f32) -> Option<(D::Array<i32>, u8)> {
            let row = dim.each(entry);
            let mut out = dim.filled(0);
            let scale = scale_row(row.as_ref(), out.as_mut())?;
            Some((out, scale))
        }
        let mut step = Self {
            temps: sizes.rows_of(sizes.nodes_of(0)),
            powers: sizes.rows_of(sizes.inputs_of(0)),
            boundaries: sizes.rows_of(sizes.boundaries_of(0)),
            temp_scale: sizes.nodes_of(0),
            power_scale: sizes.nodes_of(0),
            boundary_scale: sizes.nodes_of(0),
            constant: sizes.nodes_of(0),
        };
        for i in 0..sizes.nodes() {
            let (row, s) = scaled(sizes.node_dim(), |j| phi_minus_i(i, j))?;
            step.temps.as_mut()[i] = row;
            step.temp_scale.as_mut()[i] = s;
            let (row, s) = scaled(sizes.input_dim(), |m| bd_power(i, m))?;
            step.powers.as_mut()[i] = row;
            step.power_scale.as_mut()[i] = s;
            let (row, s) = scaled(sizes.boundary_dim(), |b| gd_boundary(i, b))?;
            step.boundaries.as_mut()[i] = row;
            step.boundary_scale.as_mut()[i] = s;
            let c = constant_k(i);
            if !finite_bits(c) {
                return None;
            }
            step.constant.as_mut()[i] = state_of_f32(c);
        }
        Some(step)
    }

    /// One step of the states `states` (Q16.48 deviations \[K\]) with
    /// `inputs`. Saturating; allocation-free, panic-free, `O(N (N + M +
    /// B))` integer multiply-adds.
    #[inline]
    pub fn step(&self, states: &mut NodeVector<Z, i64>, inputs: &FixedInputs<Z>) {
        let temps = Z::NodeDim::mapped(states, |q| input_of_state(*q));
        // By index, as the rows are laid out (each length the nodes'):
        // zipped, the Cortex-M0 motor example's worst tick took 41
        // instructions more (seven row pointers in its eight low
        // registers).
        let (temp, boundary, power) = (
            self.temps.as_ref(),
            self.boundaries.as_ref(),
            self.powers.as_ref(),
        );
        let (temp_scale, boundary_scale, power_scale) = (
            self.temp_scale.as_ref(),
            self.boundary_scale.as_ref(),
            self.power_scale.as_ref(),
        );
        let constant = self.constant.as_ref();
        let states = states.as_mut();
        for i in 0..states.len() {
            let increment = constant[i]
                .saturating_add(group(
                    temp[i].as_ref(),
                    temps.as_ref(),
                    i32::from(temp_scale[i]) + TEMP_SHIFT,
                ))
                .saturating_add(group(
                    boundary[i].as_ref(),
                    inputs.boundaries.as_ref(),
                    i32::from(boundary_scale[i]) + TEMP_SHIFT,
                ))
                .saturating_add(group(
                    power[i].as_ref(),
                    inputs.power_mantissas.as_ref(),
                    i32::from(power_scale[i]) + POWER_SHIFT - inputs.power_exponent,
                ));
            states[i] = states[i].saturating_add(increment);
        }
    }
}

/// `sum_j row[j] inputs[j]`, shifted right by `shift` (rounded) into
/// Q16.48. The sum is at most 2^62 (see `scale_row`), so neither it nor the
/// rounding's half overflows.
#[inline(always)]
fn group(row: &[i32], inputs: &[i32], shift: i32) -> i64 {
    let mut sum = 0i64;
    for (c, x) in row.iter().zip(inputs) {
        sum = sum.wrapping_add(mul_wide(*c, *x));
    }
    shift_round(sum, shift)
}

/// `a b` exactly: the 32 x 32 -> 64-bit product (`smull` on ARMv7-M), or
/// on ARMv6-M (a Cortex-M0, which multiplies 32 x 32 -> 32 bits only and
/// gets a 64 x 64-bit routine from the compiler, about 48 instructions)
/// four 16 x 16-bit products ([`mul_wide_halves`]). The same value on
/// every core.
#[inline(always)]
fn mul_wide(a: i32, b: i32) -> i64 {
    // Only ARMv6-M among the targets lacks 32-bit atomics.
    #[cfg(all(target_arch = "arm", not(target_has_atomic = "32")))]
    {
        mul_wide_halves(a, b)
    }
    #[cfg(not(all(target_arch = "arm", not(target_has_atomic = "32"))))]
    {
        i64::from(a) * i64::from(b)
    }
}

/// `a b` exactly from four 16 x 16-bit products: each partial product
/// fits an `i32` (`|hi| <= 2^15`, `lo < 2^16`) but the low one, which fits
/// a `u32`. Measured on the Cortex-M0: the real motor's mean tick 22 049
/// -> 19 976 instructions.
#[inline(always)]
#[cfg_attr(
    not(any(test, all(target_arch = "arm", not(target_has_atomic = "32")))),
    allow(dead_code)
)]
fn mul_wide_halves(a: i32, b: i32) -> i64 {
    let (a_hi, a_lo) = (a >> 16, a & 0xffff);
    let (b_hi, b_lo) = (b >> 16, b & 0xffff);
    let high = i64::from(a_hi * b_hi) << 32;
    let middle = (i64::from(a_hi * b_lo) + i64::from(a_lo * b_hi)) << 16;
    let low = i64::from((a_lo as u32) * (b_lo as u32));
    high + middle + low
}

/// `value 2^-shift` for `|value| <= 2^62` (a group's sum), rounded half
/// up; saturating for a left shift.
///
/// The rounding is `((value >> (shift - 1)) + 1) >> 1`, which equals
/// `(value + 2^(shift - 1)) >> shift` (the bit below the kept ones decides,
/// the lower ones cannot carry into it) with one variable shift instead
/// of two.
#[inline(always)]
fn shift_round(value: i64, shift: i32) -> i64 {
    if shift >= 63 {
        0
    } else if shift > 0 {
        (shift_right(value, shift.unsigned_abs() - 1) + 1) >> 1
    } else {
        let left = shift.unsigned_abs().min(63);
        let shifted = value << left;
        if shifted >> left == value {
            shifted
        } else if value < 0 {
            i64::MIN
        } else {
            i64::MAX
        }
    }
}

/// `value >> shift` (arithmetic) for `shift < 64`: the logical shift of
/// its complement when it is negative (`!(!v >> s) = floor(v 2^-s)`).
#[inline(always)]
fn shift_right(value: i64, shift: u32) -> i64 {
    let sign = (value >> 63) as u64;
    (shift_right_u64(value as u64 ^ sign, shift) ^ sign) as i64
}

/// `value >> shift` (logical) for `shift < 64`, from 32-bit halves: on
/// ARMv6-M the compiler's 64-bit shift by a variable is a call
/// (`__aeabi_llsr`), about twice these instructions. The same value on
/// every core (tested against the native shift).
#[inline(always)]
fn shift_right_u64(value: u64, shift: u32) -> u64 {
    let (high, low) = ((value >> 32) as u32, value as u32);
    let (high, low) = if shift >= 32 {
        (0, high >> (shift & 31))
    } else if shift > 0 {
        (high >> shift, (low >> shift) | (high << (32 - shift)))
    } else {
        (high, low)
    };
    (u64::from(high) << 32) | u64::from(low)
}

/// `value 2^-shift` for `shift >= 0`, rounded half up.
#[inline(always)]
const fn shift_round_i32(value: i32, shift: i32) -> i32 {
    if shift >= 31 {
        0
    } else if shift > 0 {
        ((value as i64 + (1i64 << (shift - 1))) >> shift) as i32
    } else {
        value
    }
}

/// A finite `f32` by its bits (integer work on a core without an FPU).
#[inline(always)]
pub(crate) const fn finite_bits(v: f32) -> bool {
    v.to_bits() & 0x7fff_ffff < 0x7f80_0000
}

/// A finite `f32` as (signed mantissa with its leading bit, biased
/// exponent): `v = mantissa 2^(exponent - 150)`; zero is `(0, 0)`.
#[inline(always)]
const fn split(v: f32) -> (i32, i32) {
    let bits = v.to_bits();
    let biased = ((bits >> 23) & 0xff) as i32;
    let fraction = (bits & 0x007f_ffff) as i32;
    let (mantissa, exponent) = if biased == 0 {
        (fraction, 1)
    } else {
        (fraction | 0x0080_0000, biased)
    };
    if mantissa == 0 {
        return (0, 0);
    }
    if bits >> 31 == 1 {
        (-mantissa, exponent)
    } else {
        (mantissa, exponent)
    }
}

/// `round(v 2^fraction_bits)` of a finite `v`, saturating to `i64`.
#[inline(always)]
const fn fixed_of_f32(v: f32, fraction_bits: i32) -> i64 {
    let (mantissa, exponent) = split(v);
    // v 2^f = mantissa 2^(exponent - 150 + f).
    let up = exponent - 150 + fraction_bits;
    let magnitude = mantissa.unsigned_abs() as i64;
    let scaled = if up >= 0 {
        if up > 39 {
            i64::MAX
        } else {
            magnitude << up
        }
    } else if up <= -25 {
        0
    } else {
        (magnitude + (1i64 << (-up - 1))) >> -up
    };
    if mantissa < 0 {
        -scaled
    } else {
        scaled
    }
}

/// A finite `f32` \[K\] as a state (Q16.48), rounded to nearest,
/// saturating.
#[inline(always)]
pub const fn state_of_f32(v: f32) -> i64 {
    fixed_of_f32(v, STATE_FRACTION_BITS as i32)
}

/// A finite `f32` \[K\] as an input (Q12.20), rounded to nearest,
/// saturating.
#[inline(always)]
pub const fn input_of_f32(v: f32) -> i32 {
    saturate_i32(fixed_of_f32(v, INPUT_FRACTION_BITS as i32))
}

/// A state (Q16.48) as an input (Q12.20), rounded to nearest, saturating.
#[inline(always)]
pub fn input_of_state(q: i64) -> i32 {
    const DROP: u32 = STATE_FRACTION_BITS - INPUT_FRACTION_BITS;
    saturate_i32(q.saturating_add(1 << (DROP - 1)) >> DROP)
}

/// `q` saturated to the `i32` range.
#[inline(always)]
const fn saturate_i32(q: i64) -> i32 {
    if q > i32::MAX as i64 {
        i32::MAX
    } else if q < i32::MIN as i64 {
        i32::MIN
    } else {
        q as i32
    }
}

/// A state (Q16.48) \[K\] as `f32`, rounded to nearest (half away from
/// zero), by integer operations only: the same bits on every core, and no
/// software floating point on one without an FPU.
#[inline]
pub fn f32_of_state(q: i64) -> f32 {
    let magnitude = q.unsigned_abs();
    if magnitude == 0 {
        return 0.0;
    }
    // The leading bit's weight is 2^(top - 48): |q| < 2^63 keeps the
    // exponent within 2^15, and the smallest state, 2^-48, is normal.
    let upper = (magnitude >> 32) as u32;
    let top = if upper != 0 {
        63 - upper.leading_zeros() as i32
    } else {
        31 - (magnitude as u32).leading_zeros() as i32
    };
    let mut biased = top - STATE_FRACTION_BITS as i32 + 127;
    let mut mantissa = if top > 23 {
        // Rounded half up as in `shift_round`.
        let shift = (top - 23).unsigned_abs();
        (shift_right_u64(magnitude, shift - 1) + 1) >> 1
    } else {
        magnitude << (23 - top)
    };
    if mantissa >> 24 != 0 {
        // Rounded up to the next power of two.
        mantissa >>= 1;
        biased += 1;
    }
    let sign = if q < 0 { 1u32 << 31 } else { 0 };
    f32::from_bits(sign | ((biased as u32) << 23) | (mantissa as u32 & 0x007f_ffff))
}

/// Scales one group of a row: `out[j] = round(row[j] 2^s)` with the
/// largest `s` (within [`MIN_SCALE`], [`MAX_SCALE`]) that keeps `sum_j
/// |out[j]| <= 2^30`; `None` if an entry is not finite or `s` would fall
/// below [`MIN_SCALE`].
const fn scale_row(row: &[f32], out: &mut [i32]) -> Option<u8> {
    let c = row.len();
    // The largest biased exponent: every |entry| < 2^(top - 126).
    let mut top = 0i32;
    let mut j = 0;
    while j < c {
        if !finite_bits(row[j]) {
            return None;
        }
        let (mantissa, exponent) = split(row[j]);
        if mantissa != 0 && exponent > top {
            top = exponent;
        }
        j += 1;
    }
    // Headroom for the sum of `c` entries, each below 2^(31 - spare).
    let mut spare = 0;
    while (1usize << spare) < c {
        spare += 1;
    }
    // |entry 2^s| < 2^(top - 126 + s) <= 2^(30 - spare): rounded, each
    // stays within an i32 and their sum within 2^31.
    let mut s = 156 - spare - top;
    if top == 0 || s > MAX_SCALE {
        s = MAX_SCALE;
    }
    if s < MIN_SCALE {
        return None;
    }
    let mut j = 0;
    while j < c && j < out.len() {
        out[j] = fixed_of_f32(row[j], s) as i32;
        j += 1;
    }
    Some(s as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random(seed: &mut u64) -> f64 {
        // xorshift64*: enough for test inputs.
        *seed ^= *seed >> 12;
        *seed ^= *seed << 25;
        *seed ^= *seed >> 27;
        (seed.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn conversions_round_to_nearest_and_saturate() {
        let two_48 = (1u64 << 48) as f64;
        for v in [
            0.0f32, -0.0, 1.0, -1.0, 0.5, 1e-10, 123.456, -98.765, 2.0e3, -3.0e4,
        ] {
            let q = state_of_f32(v);
            assert_eq!(q as f64, (f64::from(v) * two_48).round(), "{v}");
            if v.abs() > 1e-9 {
                assert_eq!(f32_of_state(q), v, "{v} back");
            }
            if v.abs() < 2048.0 {
                let input = input_of_f32(v);
                assert_eq!(
                    f64::from(input),
                    (f64::from(v) * 1_048_576.0).round(),
                    "{v} in"
                );
                assert_eq!(input_of_state(q), input, "{v} state in");
            }
        }
        assert_eq!(input_of_f32(3.0e3), i32::MAX);
        assert_eq!(input_of_f32(-3.0e3), i32::MIN);
        assert_eq!(state_of_f32(1.0e30), i64::MAX);
        assert_eq!(state_of_f32(-1.0e30), -i64::MAX);
        assert_eq!(input_of_state(i64::MAX), i32::MAX);
        assert_eq!(input_of_state(3 << 27), 2, "half rounds up");
        assert!(!finite_bits(f32::NAN) && !finite_bits(f32::INFINITY));
        assert!(finite_bits(f32::MAX) && finite_bits(f32::MIN_POSITIVE / 2.0));
    }

    #[test]
    fn a_state_to_f32_is_within_one_ulp() {
        let mut seed = 7u64;
        for _ in 0..10_000 {
            let v = (random(&mut seed) - 0.5) * 2000.0;
            let q = (v * (1u64 << 48) as f64) as i64;
            let exact = q as f64 / (1u64 << 48) as f64;
            let got = f64::from(f32_of_state(q));
            assert!(
                (got - exact).abs() <= exact.abs() * f64::from(f32::EPSILON),
                "{v}"
            );
        }
    }

    #[test]
    fn the_wide_product_is_exact() {
        let mut seed = 11u64;
        let edges = [
            0,
            1,
            -1,
            0xffff,
            -0x10000,
            i32::MAX,
            i32::MIN,
            12345,
            -54321,
        ];
        for a in edges {
            for b in edges {
                assert_eq!(
                    mul_wide_halves(a, b),
                    i64::from(a) * i64::from(b),
                    "{a} {b}"
                );
            }
        }
        for _ in 0..100_000 {
            let a = (random(&mut seed) * 4_294_967_296.0 - 2_147_483_648.0) as i32;
            let b = (random(&mut seed) * 4_294_967_296.0 - 2_147_483_648.0) as i32;
            assert_eq!(
                mul_wide_halves(a, b),
                i64::from(a) * i64::from(b),
                "{a} {b}"
            );
        }
    }

    #[test]
    fn the_shift_in_halves_is_the_native_shift() {
        let mut seed = 5u64;
        let mut values = std::vec![
            0i64,
            1,
            -1,
            i64::MAX,
            i64::MIN,
            1 << 32,
            -(1 << 32),
            0xffff_ffff
        ];
        for _ in 0..20_000 {
            let bits = (random(&mut seed) * 4_294_967_296.0) as u64
                | (((random(&mut seed) * 4_294_967_296.0) as u64) << 32);
            values.push(bits as i64);
        }
        for v in values {
            for shift in 0..64 {
                assert_eq!(shift_right(v, shift), v >> shift, "{v} >> {shift}");
                let u = v as u64;
                assert_eq!(shift_right_u64(u, shift), u >> shift, "{u} >> {shift}");
            }
            // A group's sum is within 2^62 (see `scale_row`).
            let sum = v >> 1;
            for shift in 1..63 {
                let expected = ((i128::from(sum) + (1i128 << (shift - 1))) >> shift) as i64;
                assert_eq!(
                    shift_round(sum, shift),
                    expected,
                    "{sum} >> {shift}, rounded"
                );
            }
        }
    }

    #[test]
    fn inputs_refuse_non_finite_values() {
        assert!(FixedInputs::<ConstSizes<1, 1, 1>>::new(&[f32::NAN], &[0.0]).is_none());
        assert!(FixedInputs::<ConstSizes<1, 1, 1>>::new(&[1.0], &[f32::INFINITY]).is_none());
        assert!(FixedInputs::<ConstSizes<1, 1, 2>>::new(&[1.0e30, 1.0e-30], &[0.0]).is_some());
    }

    #[test]
    fn oversized_or_non_finite_tables_are_refused() {
        let mut tables = StepTables::<1, 1, 1> {
            phi_minus_i: [[-1e-5]],
            bd_power: [[1e-4]],
            gd_boundary: [[1e-5]],
            constant_k: [0.0],
        };
        assert!(FixedStep::of(&tables).is_some());
        tables.bd_power = [[2.0e9]];
        assert!(FixedStep::of(&tables).is_none());
        tables.bd_power = [[f32::NAN]];
        assert!(FixedStep::of(&tables).is_none());
    }

    /// The 3-node coil of the network observer's tests: a winding (60 J/K)
    /// in a core (400 J/K) on a housing (900 J/K) tied to the ambient, and
    /// a sensor coil (`M = 2`) on the housing.
    fn three_nodes() -> crate::network::Network<3, 1, 2> {
        use crate::network::{Network, Resistance};
        Network::new([60.0, 400.0, 900.0])
            .and_then(|n| n.connect(0, 1, 2.0))
            .and_then(|n| n.connect(1, 2, 3.0))
            .and_then(|n| n.connect_boundary(2, 0, 1.5))
            .and_then(|n| n.joule_source(0, 0, Resistance::constant(0.3)))
            .and_then(|n| n.joule_source(1, 2, Resistance::constant(0.3)))
            .unwrap()
    }

    /// The step of `network` in deviations from `origin_c` solved in `f64`,
    /// and its tables rounded to `f32` as the network observer holds them.
    #[allow(clippy::type_complexity)]
    fn tables<const N: usize, const B: usize, const M: usize>(
        network: &crate::network::Network<N, B, M>,
        dt_s: f64,
        origin_c: f64,
    ) -> (
        crate::discretize::Discrete<f64, crate::sizes::ConstSizes<N, B, M>>,
        StepTables<N, B, M>,
    ) {
        let d = crate::discretize::zoh(&network.state_space(&[origin_c; N]), dt_s).unwrap();
        let phi = d.ad - nalgebra::SMatrix::<f64, N, N>::identity();
        let constant = d.dd
            + phi * nalgebra::SVector::<f64, N>::repeat(origin_c)
            + d.gd_boundary * nalgebra::SVector::<f64, B>::repeat(origin_c);
        let t = StepTables {
            phi_minus_i: core::array::from_fn(|i| core::array::from_fn(|j| phi[(i, j)] as f32)),
            bd_power: core::array::from_fn(|i| core::array::from_fn(|m| d.bd_power[(i, m)] as f32)),
            gd_boundary: core::array::from_fn(|i| {
                core::array::from_fn(|k| d.gd_boundary[(i, k)] as f32)
            }),
            constant_k: core::array::from_fn(|i| constant[i] as f32),
        };
        (d, t)
    }

    #[test]
    fn the_integer_step_follows_the_f64_step() {
        // 2 h at 19.2 W in the winding and 2 mW in the sensor coil (the
        // powers' shared exponent 13 binary orders apart) under an ambient
        // that swings +-5 K, then 1 h off, at 1 ms: the integer step against
        // the f64 recursion of the same f32 tables (its arithmetic alone)
        // and against the exact step (tables not rounded).
        let network = three_nodes();
        let (exact, t) = tables(&network, 1e-3, 20.0);
        let step = FixedStep::of(&t).unwrap();
        let mut q = [0i64; 3];
        let mut x = nalgebra::SVector::<f64, 3>::repeat(20.0);
        let mut rounded = [0.0f64; 3];
        let (mut worst, mut worst_rounded, mut worst_integer) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..10_800_000u32 {
            let on = k < 7_200_000;
            let powers_w: [f32; 2] = if on { [19.2, 0.002] } else { [0.0, 0.0] };
            let ambient_k = 5.0 * libm::sin(f64::from(k) * 1e-6) as f32;
            let inputs = FixedInputs::new(&powers_w, &[ambient_k]).unwrap();
            step.step(&mut q, &inputs);
            let p = nalgebra::SVector::<f64, 2>::from(powers_w.map(f64::from));
            let y = f64::from(ambient_k);
            x = exact.ad * x
                + exact.bd_power * p
                + exact.gd_boundary * nalgebra::SVector::<f64, 1>::repeat(20.0 + y)
                + exact.dd;
            let prev = rounded;
            for i in 0..3 {
                let mut inc = f64::from(t.constant_k[i]) + f64::from(t.gd_boundary[i][0]) * y;
                for m in 0..2 {
                    inc += f64::from(t.bd_power[i][m]) * p[m];
                }
                for j in 0..3 {
                    inc += f64::from(t.phi_minus_i[i][j]) * prev[j];
                }
                rounded[i] += inc;
            }
            if k % 1000 == 0 {
                for i in 0..3 {
                    let integer = q[i] as f64 / (1u64 << 48) as f64;
                    worst_integer = worst_integer.max((integer - rounded[i]).abs());
                    worst_rounded = worst_rounded.max((20.0 + rounded[i] - x[i]).abs());
                    worst = worst.max((20.0 + integer - x[i]).abs());
                }
            }
        }
        std::println!(
            "integer step: {worst_integer:e} K off the f64 step of the same f32 tables, \
             {worst:e} K off the exact step (the tables' rounding alone: {worst_rounded:e} K)"
        );
        // The inputs' rounding (Q12.20: the nodes' and the boundary's, each
        // within 4.8e-7 K, which the step carries as such) leaves the
        // integer step within 1e-6 K of its tables' f64 recursion (6.5e-7
        // K measured; 6.7e-8 K under a constant ambient); Q32.32 states
        // were 3.4e-5 K off.
        assert!(worst_integer < 1e-6, "{worst_integer} K");
        assert!(worst < 1e-5, "{worst} K");
    }

    #[test]
    fn extreme_inputs_saturate_without_a_panic() {
        // Run in a debug build too (overflow checks): every operation is
        // checked or saturating.
        let (_, t) = tables(&three_nodes(), 1e-3, 20.0);
        let step = FixedStep::of(&t).unwrap();
        let extremes = [
            0.0,
            -0.0,
            f32::MIN_POSITIVE / 4.0,
            1e-30,
            1e30,
            -1e30,
            f32::MAX,
            f32::MIN,
        ];
        for p0 in extremes {
            for p1 in extremes {
                for y in extremes {
                    let inputs = FixedInputs::new(&[p0, p1], &[y]).unwrap();
                    for start in [0, i64::MAX, i64::MIN, 1 << 60, -(1 << 60)] {
                        let mut q = [start; 3];
                        step.step(&mut q, &inputs);
                        let _ = q.map(f32_of_state);
                    }
                }
            }
        }
        // Powers at f32::MAX push the winding up, never wrapped below.
        let mut q = [0i64; 3];
        step.step(&mut q, &FixedInputs::new(&[f32::MAX, 0.0], &[0.0]).unwrap());
        assert_eq!(q[0], i64::MAX);
        assert!(FixedInputs::<ConstSizes<1, 1, 2>>::new(&[f32::NAN, 0.0], &[0.0]).is_none());
    }
}
