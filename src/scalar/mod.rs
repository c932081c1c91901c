//! One scalar abstraction for `f32`, `f64` and fixed point.
//!
//! Every hot-path stepper (the coil grid, the lumped network's explicit step,
//! the current limiter) is generic over [`Scalar`], so the same code runs on a
//! Cortex-M4F in `f32`, on the host in `f64`, and on a Cortex-M0 without an FPU
//! in fixed point.
//!
//! # Which fixed format, and why
//!
//! The one fixed-point scalar is [`Q32`]: the `fixed` crate's `I32F32`
//! (64-bit, 32 integer bits, 32 fraction bits) with saturating arithmetic,
//! so nothing wraps or panics. It holds every quantity the models use in
//! one format:
//!
//! | quantity | typical value | Q32.32 |
//! |---|---|---|
//! | temperature | -50 .. 500 degC, mK resolution | range ±2.1e9, resolution 2.3e-10 |
//! | step coefficient `dt/C` | 1e-5 .. 1e-2 1/(J/K)·s | 1e-5 is 43 000 LSB: 2e-5 relative |
//! | energy per step `G dt dT` | 1e-7 .. 1 J | resolution 2.3e-10 J |
//! | current, power | 0 .. 100 A, 0 .. 1e4 W | exact to 2.3e-10 |
//!
//! A 32-bit format cannot: Q16.16 resolves 1.5e-5, so a 1 ms temperature
//! increment of a coil (about 4e-5 K) is rounded by a third of itself every
//! tick, and `dt/C = 1e-5` is a single LSB. The tests in this module show it.
//! On a Cortex-M0 a Q32.32 multiply is a 64x64 multiply in software, so
//! [`Q32`] carries its own: four 32x32 partial products, each from four
//! 16x16 `MULS` on ARMv6-M, a seventh of the generic 128-bit multiply's
//! instructions (see [`Q32`]). The grid's multi-rate update (see
//! `grid`) is the other lever that keeps the fixed-point tick cheap.

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

mod q32;
pub use q32::Q32;

/// The arithmetic the thermal models need, for `f32`, `f64` and [`Q32`].
///
/// The operators saturate for fixed point and follow IEEE 754 for floats.
/// Conversions from floats are for building and for inputs; they never panic
/// (a NaN becomes zero in fixed point, so callers validate inputs first: see
/// [`Scalar::is_finite`] on the *float* side).
pub trait Scalar:
    Copy
    + PartialOrd
    + Default
    + Debug
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    /// Additive identity.
    const ZERO: Self;
    /// Multiplicative identity.
    const ONE: Self;
    /// The largest finite value of the type.
    const MAX: Self;
    /// A multiply costs about as much as a load (a hardware float
    /// multiply): worth spending one to save a compare and branch.
    const CHEAP_MULTIPLY: bool = true;
    /// Converts from `f64`, saturating to the range of fixed-point types; NaN
    /// becomes zero for fixed point.
    fn from_f64(value: f64) -> Self;
    /// Converts from `f32`, with the same rules as [`Scalar::from_f64`].
    fn from_f32(value: f32) -> Self;
    /// Converts to `f64` (exact for every type here).
    fn to_f64(self) -> f64;
    /// Converts to `f32` (rounded).
    fn to_f32(self) -> f32;
    /// `false` for NaN and infinities; always `true` for fixed point.
    fn is_finite(self) -> bool;
    /// The larger of two values; for floats a NaN operand loses.
    fn max(self, other: Self) -> Self;
    /// The smaller of two values; for floats a NaN operand loses.
    fn min(self, other: Self) -> Self;
    /// Absolute value (saturating for fixed point).
    fn abs(self) -> Self;
    /// Square root; zero for negative inputs.
    fn sqrt(self) -> Self;
    /// Clamps `self` into `[lo, hi]` (assumes `lo <= hi`); never panics.
    #[inline]
    fn clamp_to(self, lo: Self, hi: Self) -> Self {
        self.max(lo).min(hi)
    }
}

macro_rules! impl_float_scalar {
    ($t:ty, $sqrt:path) => {
        impl Scalar for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const MAX: Self = <$t>::MAX;
            #[inline]
            fn from_f64(value: f64) -> Self {
                value as $t
            }
            #[inline]
            fn from_f32(value: f32) -> Self {
                value as $t
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
            #[inline]
            fn to_f32(self) -> f32 {
                self as f32
            }
            // With an FPU, `x - x` (+0 for every finite `x`, NaN for NaN
            // and the infinities) is a subtraction and a comparison, where
            // LLVM expands `is_finite` and its combinations with other
            // comparisons into some twenty integer instructions on
            // ARMv7E-M. Without one (ARMv6-M, soft-float ABIs) the
            // subtraction is a library call and the bit test is cheaper.
            #[cfg(not(all(target_arch = "arm", not(target_abi = "eabihf"))))]
            #[inline]
            fn is_finite(self) -> bool {
                self - self == 0.0
            }
            #[cfg(all(target_arch = "arm", not(target_abi = "eabihf")))]
            #[inline]
            fn is_finite(self) -> bool {
                <$t>::is_finite(self)
            }
            // `max`/`min` with the std semantics (a NaN loses), written as
            // comparisons: ARMv7E-M has no VMAXNM, so `f32::max` is a call to
            // `fmaxf`, and the hot loops make several per coil.
            #[inline]
            fn max(self, other: Self) -> Self {
                if self < other || self.is_nan() {
                    other
                } else {
                    self
                }
            }
            #[inline]
            fn min(self, other: Self) -> Self {
                if self > other || self.is_nan() {
                    other
                } else {
                    self
                }
            }
            #[inline]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline]
            fn sqrt(self) -> Self {
                if self > 0.0 {
                    $sqrt(self)
                } else {
                    0.0
                }
            }
        }
    };
}

impl_float_scalar!(f32, libm::sqrtf);
impl_float_scalar!(f64, libm::sqrt);

#[cfg(test)]
mod tests {
    use super::*;

    fn generic_ops<S: Scalar>() -> [f64; 6] {
        let a = S::from_f64(123.456);
        let b = S::from_f64(-7.25);
        [
            (a + b).to_f64(),
            (a - b).to_f64(),
            (a * b).to_f64(),
            (a / b).to_f64(),
            S::from_f64(2.0).sqrt().to_f64(),
            b.abs().max(S::ONE).to_f64(),
        ]
    }

    #[test]
    fn all_scalars_agree_with_f64() {
        let want = generic_ops::<f64>();
        let f32s = generic_ops::<f32>();
        let q = generic_ops::<Q32>();
        for k in 0..want.len() {
            assert!((f32s[k] - want[k]).abs() <= 1e-5 * want[k].abs().max(1.0));
            assert!((q[k] - want[k]).abs() <= 1e-8 * want[k].abs().max(1.0));
        }
    }

    #[test]
    fn fixed_point_saturates_and_swallows_nan() {
        assert_eq!(Q32::from_f64(1e300), Q32::MAX);
        assert_eq!(Q32::from_f64(f64::NAN), Q32::ZERO);
        assert_eq!(Q32::from_f32(f32::NEG_INFINITY).to_f64(), -2147483648.0);
        let big = Q32::from_f64(2e9);
        assert_eq!(big + big, Q32::MAX);
        assert_eq!(big * big, Q32::MAX);
        // The trait method, not `Saturating`'s inherent one (which panics).
        assert_eq!(Scalar::sqrt(Q32::from_f64(-4.0)), Q32::ZERO);
    }

    #[test]
    fn q32_resolves_step_coefficients_that_q16_cannot() {
        // dt/C for a 68.7 J/K coil at 1 ms.
        let coefficient = 1e-3 / 68.7;
        let q32 = Q32::from_f64(coefficient).to_f64();
        assert!(((q32 - coefficient) / coefficient).abs() < 1e-4);
        let q16 = fixed::types::I16F16::saturating_from_num(coefficient).to_num::<f64>();
        assert!(((q16 - coefficient) / coefficient).abs() > 0.01);
    }
}
