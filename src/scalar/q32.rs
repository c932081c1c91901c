//! [`Q32`]: saturating Q32.32 fixed point whose multiply and divide suit a
//! Cortex-M0 (see the type's docs).

use core::fmt;
use core::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

use fixed::types::I32F32;

use super::Scalar;

/// Saturating Q32.32 fixed point (`I32F32`): the scalar for MCUs without an
/// FPU. Arithmetic saturates at `±2^31` instead of wrapping or panicking;
/// see the [module docs](crate::scalar) for the range and resolution of each
/// quantity.
///
/// The arithmetic is the `fixed` crate's `Saturating<I32F32>` to the bit
/// (the tests compare every operator with it, and the Cortex-M0 example's
/// outputs did not move by a bit when it changed). Two operators are
/// computed differently, for an MCU without an FPU (instruction counts from
/// the Cortex-M0 example under QEMU):
///
/// * **Multiply.** `fixed` forms the product as an `i128` multiply with an
///   overflow check. ARMv6-M has no 32x32 -> 64 multiply, so LLVM lowers that
///   to about twenty calls of `__aeabi_lmul`, some 1 000 instructions per
///   multiply. [`Q32`] multiplies the magnitudes from four 32x32 -> 64
///   partial products and, on ARMv6-M and ARMv8-M Baseline (the build
///   script sets `no_long_multiply` for them), forms each of those from four
///   16x16 `MULS`: 152 instructions. Elsewhere the partial products are
///   single `UMULL`s.
/// * **Divide.** `fixed` divides a 128-bit dividend by a 128-bit divisor,
///   about 3 500 instructions; [`Q32`] takes the integer part with one
///   64-bit division and the 32 fraction bits by long division on the
///   remainder, about 800. Division by zero saturates (`x / 0` is `MAX` or
///   `MIN` by the sign of `x`, `0 / 0` is zero) where `fixed` panics, so no
///   operator of the hot path has a panic path.
#[derive(Clone, Copy, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(transparent)]
pub struct Q32(I32F32);

impl Q32 {
    /// The smallest value, `-2^31`.
    pub const MIN: Self = Self(I32F32::MIN);

    /// The value whose raw two's-complement bits are `bits` (value
    /// `bits / 2^32`).
    #[inline]
    pub const fn from_bits(bits: i64) -> Self {
        Self(I32F32::from_bits(bits))
    }

    /// The raw bits (value times `2^32`).
    #[inline]
    pub const fn to_bits(self) -> i64 {
        self.0.to_bits()
    }

    /// From the `fixed` crate's type, bit for bit.
    #[inline]
    pub const fn from_fixed(value: I32F32) -> Self {
        Self(value)
    }

    /// To the `fixed` crate's type, bit for bit (for its formatting,
    /// parsing and the rest of its API).
    #[inline]
    pub const fn to_fixed(self) -> I32F32 {
        self.0
    }

    /// The value of sign `negative` and magnitude `magnitude` in bits,
    /// saturated to `MIN` or `MAX` beyond the range.
    #[inline(always)]
    fn saturated(negative: bool, magnitude: u128) -> Self {
        if negative {
            if magnitude <= 1 << 63 {
                Self::from_bits((magnitude as u64).wrapping_neg() as i64)
            } else {
                Self::MIN
            }
        } else if magnitude < 1 << 63 {
            Self::from_bits(magnitude as i64)
        } else {
            Self::MAX
        }
    }
}

impl fmt::Debug for Q32 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl fmt::Display for Q32 {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for Q32 {
    fn format(&self, f: defmt::Formatter<'_>) {
        // An f32 is what a log reader wants; the conversion is exact to 24 bits.
        defmt::write!(f, "{=f32}", self.to_f32());
    }
}

impl Add for Q32 {
    type Output = Self;
    #[inline]
    fn add(self, rhs: Self) -> Self {
        Self(self.0.saturating_add(rhs.0))
    }
}

impl Sub for Q32 {
    type Output = Self;
    #[inline]
    fn sub(self, rhs: Self) -> Self {
        Self(self.0.saturating_sub(rhs.0))
    }
}

impl Neg for Q32 {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self(self.0.saturating_neg())
    }
}

impl AddAssign for Q32 {
    #[inline]
    fn add_assign(&mut self, rhs: Self) {
        *self = *self + rhs;
    }
}

impl SubAssign for Q32 {
    #[inline]
    fn sub_assign(&mut self, rhs: Self) {
        *self = *self - rhs;
    }
}

impl Mul for Q32 {
    type Output = Self;
    /// `floor(a b / 2^32)` in bits, saturated: `fixed`'s `saturating_mul`.
    #[inline(always)]
    fn mul(self, rhs: Self) -> Self {
        let (a, b) = (self.to_bits(), rhs.to_bits());
        // A coil without current, a coil inside the grid (no ambient
        // link): two compares in line instead of a call and the partial
        // products.
        if a == 0 || b == 0 {
            return Self::ZERO;
        }
        mul_nonzero(a, b)
    }
}

/// [`Q32`]'s product of two non-zero bit patterns, out of line: the
/// partial products are too long to copy into every caller.
#[inline(never)]
fn mul_nonzero(a: i64, b: i64) -> Q32 {
    {
        let negative = (a < 0) != (b < 0);
        let (quotient, overflow, inexact) = mul_shift_32(a.unsigned_abs(), b.unsigned_abs());
        // The floor of a negative quotient: one more when bits were shifted
        // out.
        let (magnitude, carry) = quotient.overflowing_add(u64::from(negative && inexact));
        if overflow || carry {
            return if negative { Q32::MIN } else { Q32::MAX };
        }
        Q32::saturated(negative, u128::from(magnitude))
    }
}

impl Div for Q32 {
    type Output = Self;
    /// `fixed`'s saturating division (truncated toward zero), and a
    /// saturated (not panicking) division by zero: `MAX` or `MIN` by the
    /// sign of the dividend, zero for `0 / 0`.
    #[inline]
    fn div(self, rhs: Self) -> Self {
        let (a, b) = (self.to_bits(), rhs.to_bits());
        let negative = (a < 0) != (b < 0);
        match div_shift_32(a.unsigned_abs(), b.unsigned_abs()) {
            Some(quotient) => Self::saturated(negative, u128::from(quotient)),
            None if a == 0 => Self::ZERO,
            None => Self::saturated(negative, u128::MAX),
        }
    }
}

/// `floor(n 2^32 / d)` of two 64-bit magnitudes; `None` when `d` is zero or
/// the quotient needs more than 64 bits (both saturate).
///
/// The integer part is one `u64` division; the 32 fraction bits come from
/// restoring long division on the remainder, a fixed 32 rounds of shift,
/// compare and subtract (see [`Q32`] for the cost).
#[inline]
fn div_shift_32(n: u64, d: u64) -> Option<u64> {
    let whole = n.checked_div(d)?;
    if whole >> 32 != 0 {
        return None;
    }
    // remainder < d <= 2^63, so doubling it never overflows.
    let mut remainder = n - whole * d;
    let mut fraction = 0u64;
    for _ in 0..32 {
        remainder <<= 1;
        fraction <<= 1;
        if remainder >= d {
            remainder -= d;
            fraction |= 1;
        }
    }
    Some((whole << 32) | fraction)
}

/// `(a b) >> 32` of two 64-bit magnitudes when it fits 64 bits, whether it
/// did not (`overflow`), and whether any bit shifted out was set.
///
/// A partial product with a zero high word is skipped: most operands of
/// the thermal models are below one (coefficients, temperature
/// differences), so most multiplies take one or two of the four, each
/// four `MULS` and their carries on ARMv6-M.
#[inline(always)]
fn mul_shift_32(a: u64, b: u64) -> (u64, bool, bool) {
    let (a_lo, a_hi) = (a as u32, (a >> 32) as u32);
    let (b_lo, b_hi) = (b as u32, (b >> 32) as u32);
    let lo = widening_mul(a_lo, b_lo);
    // a b = hi 2^64 + (cross_1 + cross_2) 2^32 + lo; every term but `lo`
    // is a whole multiple of 2^32, so the shift is exact term by term.
    let mut quotient = lo >> 32;
    let mut overflow = false;
    if b_hi != 0 {
        let (sum, carry) = quotient.overflowing_add(widening_mul(a_lo, b_hi));
        quotient = sum;
        overflow |= carry;
    }
    if a_hi != 0 {
        let (sum, carry) = quotient.overflowing_add(widening_mul(a_hi, b_lo));
        quotient = sum;
        overflow |= carry;
        if b_hi != 0 {
            let hi = widening_mul(a_hi, b_hi);
            let (sum, carry) = quotient.overflowing_add(hi << 32);
            quotient = sum;
            overflow |= carry || hi >> 32 != 0;
        }
    }
    (quotient, overflow, lo as u32 != 0)
}

/// `a b` as 64 bits: one `UMULL` where the core has it.
#[cfg(not(no_long_multiply))]
#[inline(always)]
fn widening_mul(a: u32, b: u32) -> u64 {
    u64::from(a) * u64::from(b)
}

/// `a b` as 64 bits on cores without a 32x32 -> 64 multiply (ARMv6-M):
/// four 16x16 -> 32 `MULS`, where `u64 * u64` would call `__aeabi_lmul`.
#[cfg(no_long_multiply)]
#[inline(always)]
fn widening_mul(a: u32, b: u32) -> u64 {
    widening_mul_16(a, b)
}

/// `a b` as 64 bits from 16-bit halves, in `u32` arithmetic only.
#[cfg_attr(not(no_long_multiply), allow(dead_code))]
#[inline(always)]
fn widening_mul_16(a: u32, b: u32) -> u64 {
    let (a0, a1) = (a & 0xffff, a >> 16);
    let (b0, b1) = (b & 0xffff, b >> 16);
    let low = a0 * b0;
    let (middle, middle_carry) = (a0 * b1).overflowing_add(a1 * b0);
    let (low, low_carry) = low.overflowing_add(middle << 16);
    // Cannot overflow: the full product is below 2^64.
    let high = (a1 * b1)
        .wrapping_add(middle >> 16)
        .wrapping_add(u32::from(middle_carry) << 16)
        .wrapping_add(u32::from(low_carry));
    (u64::from(high) << 32) | u64::from(low)
}

/// `2^32`: one in Q32.32 bits.
const ONE_BITS: f64 = 4_294_967_296.0;

impl Scalar for Q32 {
    const ZERO: Self = Self(I32F32::ZERO);
    const ONE: Self = Self(I32F32::ONE);
    const MAX: Self = Self(I32F32::MAX);
    // A software 64-bit product: about 150 instructions without a 32 x 32
    // -> 64 multiplier.
    const CHEAP_MULTIPLY: bool = false;
    #[inline]
    fn from_f64(value: f64) -> Self {
        // Rust's float-to-int `as` saturates and maps NaN to 0, so this path
        // has no panic (fixed's `saturating_from_num` panics on NaN).
        Self::from_bits(libm::round(value * ONE_BITS) as i64)
    }
    /// The same bits as `from_f64(value as f64)` in `f32` arithmetic (a
    /// sixth of the instructions without an FPU): scaling by `2^32` is
    /// exact in both (an overflow to infinity saturates like the `f64`
    /// value would), and both round the same exact value.
    #[inline]
    fn from_f32(value: f32) -> Self {
        Self::from_bits(libm::roundf(value * ONE_BITS as f32) as i64)
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self.0.to_num::<f64>()
    }
    #[inline]
    fn to_f32(self) -> f32 {
        self.0.to_num::<f32>()
    }
    #[inline]
    fn is_finite(self) -> bool {
        true
    }
    #[inline]
    fn max(self, other: Self) -> Self {
        if self >= other {
            self
        } else {
            other
        }
    }
    #[inline]
    fn min(self, other: Self) -> Self {
        if self <= other {
            self
        } else {
            other
        }
    }
    #[inline]
    fn abs(self) -> Self {
        Self(self.0.saturating_abs())
    }
    #[inline]
    fn sqrt(self) -> Self {
        if self.0 > I32F32::ZERO {
            Self(self.0.sqrt())
        } else {
            Self::ZERO
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fixed::Saturating;
    use proptest::prelude::*;

    /// Bit patterns where products overflow, round or change sign.
    const EDGES: [i64; 14] = [
        0,
        1,
        -1,
        2,
        -2,
        i64::MAX,
        i64::MIN,
        i64::MIN + 1,
        1 << 32,
        -(1 << 32),
        (1 << 32) + 1,
        (1 << 47) - 1,
        -(1 << 47),
        0x7fff_ffff_ffff_0001,
    ];

    fn reference_mul(a: i64, b: i64) -> i64 {
        let (a, b) = (
            Saturating(I32F32::from_bits(a)),
            Saturating(I32F32::from_bits(b)),
        );
        (a * b).0.to_bits()
    }

    #[test]
    fn multiply_matches_fixed_on_the_edges() {
        for a in EDGES {
            for b in EDGES {
                let got = (Q32::from_bits(a) * Q32::from_bits(b)).to_bits();
                assert_eq!(got, reference_mul(a, b), "{a:#x} * {b:#x}");
            }
        }
    }

    #[test]
    fn divide_matches_fixed_on_the_edges() {
        for a in EDGES {
            for b in EDGES.into_iter().filter(|&b| b != 0) {
                let want = (Saturating(I32F32::from_bits(a)) / Saturating(I32F32::from_bits(b))).0;
                let got = (Q32::from_bits(a) / Q32::from_bits(b)).to_bits();
                assert_eq!(got, want.to_bits(), "{a:#x} / {b:#x}");
            }
        }
    }

    #[test]
    fn from_f32_matches_from_f64() {
        let specials = [
            0.0, -0.0, 0.5, -0.5, 1.5e-10, -1.5e-10, 1.0e-45, 2.1e9, -2.2e9, 3.0e38,
        ];
        for x in specials
            .into_iter()
            .chain([f32::NAN, f32::INFINITY, f32::NEG_INFINITY])
        {
            assert_eq!(Q32::from_f32(x), Q32::from_f64(f64::from(x)), "{x}");
        }
        // Halfway cases: 2^-33 is half an LSB.
        for k in -8i32..8 {
            let x = (2 * k + 1) as f32 * 2f32.powi(-33);
            assert_eq!(Q32::from_f32(x), Q32::from_f64(f64::from(x)), "{x}");
        }
    }

    #[test]
    fn sixteen_bit_halves_multiply_exactly() {
        for a in [
            0,
            1,
            0xffff,
            0x1_0000,
            0xffff_ffff,
            0x8000_0000,
            0x1234_5678,
        ] {
            for b in [
                0,
                1,
                0xffff,
                0x1_0000,
                0xffff_ffff,
                0x8000_0001,
                0x9abc_def0,
            ] {
                assert_eq!(widening_mul_16(a, b), u64::from(a) * u64::from(b));
            }
        }
    }

    #[test]
    fn division_saturates_where_fixed_panics() {
        let two = Q32::from_f64(2.0);
        assert_eq!(two / Q32::ZERO, Q32::MAX);
        assert_eq!(-two / Q32::ZERO, Q32::MIN);
        assert_eq!(Q32::ZERO / Q32::ZERO, Q32::ZERO);
        assert_eq!(Q32::MAX / Q32::from_f64(0.5), Q32::MAX);
        assert_eq!(Q32::MAX / Q32::from_f64(-0.5), Q32::MIN);
        assert_eq!(Q32::from_f64(-7.5) / two, Q32::from_f64(-3.75));
    }

    proptest! {
        #[test]
        fn every_operator_matches_fixed_saturating(a in any::<i64>(), b in any::<i64>(),
                                                   shift in 0u32..64) {
            // Shifted operands reach the small values where rounding matters.
            let (a, b) = (a >> shift, b >> (63 - shift));
            let (qa, qb) = (Q32::from_bits(a), Q32::from_bits(b));
            let (fa, fb) = (Saturating(I32F32::from_bits(a)), Saturating(I32F32::from_bits(b)));
            prop_assert_eq!((qa * qb).to_bits(), (fa * fb).0.to_bits());
            prop_assert_eq!((qa + qb).to_bits(), (fa + fb).0.to_bits());
            prop_assert_eq!((qa - qb).to_bits(), (fa - fb).0.to_bits());
            prop_assert_eq!((-qa).to_bits(), (-fa).0.to_bits());
            if b != 0 {
                prop_assert_eq!((qa / qb).to_bits(), (fa / fb).0.to_bits());
                // Large over small: the quotients that saturate.
                let (fb2, qb2) = (Saturating(I32F32::from_bits(b >> 40 | 1)), Q32::from_bits(b >> 40 | 1));
                prop_assert_eq!((qa / qb2).to_bits(), (fa / fb2).0.to_bits());
            }
            let x = f32::from_bits(a as u32);
            prop_assert_eq!(Q32::from_f32(x), Q32::from_f64(f64::from(x)));
            prop_assert_eq!(widening_mul_16(a as u32, b as u32), u64::from(a as u32) * u64::from(b as u32));
        }
    }
}
