//! `f32` arithmetic for a core without an FPU (Cortex-M0/M0+), in integer
//! code written for what Thumb-1 has: a 32 x 32 -> 32-bit multiply and no
//! `clz`, `umull` or divide instruction.
//!
//! On such a core every `f32` add, multiply and compare is a call into the
//! compiler's routines (`__aeabi_fadd`, `__aeabi_fmul`, `__aeabi_fcmplt`,
//! ...). Rust's are written once for every float width: their multiply
//! forms a 64-bit product through `__aeabi_lmul`, their add normalises
//! through `__clzsi2`, and a compare goes through a three-way one. In the
//! M0 network observer's heaviest ticks (`network_roundtrip` under QEMU,
//! the time-to-limit predictor's element) those routines were seven tenths
//! of the instructions. The ones here take a product from four 12-bit
//! partial products, an add's alignment and rounding in one 32-bit word,
//! the result's sign and exponent as one word the rounded significand
//! adds to, and a compare as two integer ones: per call about 25
//! instructions fewer for an add and 28 for a multiply (measured in QEMU
//! on the M0: 103 -> 78 and 114 -> 86 with the call), a subnormal operand
//! or result in a slower path of its own. With them `network_roundtrip`'s M0 tick went from 661
//! / 5 778 instructions (mean / worst) to 621 / 4 906, and `motor_qemu`'s
//! from 2 426 / 11 789 to 2 171 / 10 816 (docs/cost.md). A divide stays
//! the compiler's: a restoring division in Rust compiled to twice its
//! instructions.
//!
//! The functions give the same results **to the bit**: IEEE 754 binary32,
//! rounded to nearest with ties to even, subnormals in and out, signed
//! zeros and infinities; a NaN result is the compiler's (a NaN operand
//! quieted, the first one if both; `0 x inf` and `inf - inf` give the
//! positive quiet NaN `0x7FC0_0000`). So a firmware that uses them computes
//! what the host replays and what the tests validated, in fewer
//! instructions: the M0 examples' goldens are unchanged to the bit. Tested
//! against the host's hardware `f32` on every pair of a list of edge
//! values and on millions of random pairs, and at the hard cases (close
//! exponents, cancellations, results at the range's ends, ties).
//!
//! They are plain functions; a firmware opts in to them as its `f32`
//! routines with one line at its crate root,
//! [`soft_float_routines!()`](crate::soft_float_routines), which defines
//! the `__aeabi_*` symbols the compiler calls (the linker then takes no
//! routine of the same name from the compiler's library; `.ci/run` checks
//! that the M0 examples link these). The library itself defines no
//! symbol: a firmware that already has faster routines (an RP2040's, in
//! its boot ROM) keeps them. They cost flash: about 600 B more than the
//! compiler's (the two-node footprint example, which does not use them,
//! would grow from 24 576 to 25 192 B, over its 24 KiB goal).
//!
//! No function here uses a float operation (it would call itself) or a
//! 64-bit one (each would be a call on Thumb-1).

/// The sign bit.
const SIGN: u32 = 0x8000_0000;
/// `+inf`; every magnitude above it is a NaN.
const INF: u32 = 0x7F80_0000;
/// The significand's stored bits.
const FRACTION: u32 = 0x007F_FFFF;
/// The significand's implicit leading one.
const HIDDEN: u32 = 0x0080_0000;
/// The bit that makes a NaN quiet.
const QUIET: u32 = 0x0040_0000;
/// The quiet NaN an invalid operation gives.
const INVALID: u32 = 0x7FC0_0000;

/// `a + b`, rounded to nearest even (see the module docs).
#[inline]
pub fn add(a: f32, b: f32) -> f32 {
    f32::from_bits(add_bits(a.to_bits(), b.to_bits()))
}

/// `a - b`, rounded to nearest even (see the module docs).
#[inline]
pub fn sub(a: f32, b: f32) -> f32 {
    f32::from_bits(add_bits(a.to_bits(), b.to_bits() ^ SIGN))
}

/// `a * b`, rounded to nearest even (see the module docs).
#[inline]
pub fn mul(a: f32, b: f32) -> f32 {
    f32::from_bits(mul_bits(a.to_bits(), b.to_bits()))
}

/// `a < b` (IEEE: false if either is a NaN; `-0 < +0` is false).
#[inline]
pub fn lt(a: f32, b: f32) -> bool {
    let (a, b) = (a.to_bits(), b.to_bits());
    !unordered_bits(a, b) && less_bits(a, b)
}

/// `a <= b` (IEEE: false if either is a NaN).
#[inline]
pub fn le(a: f32, b: f32) -> bool {
    let (a, b) = (a.to_bits(), b.to_bits());
    !unordered_bits(a, b) && !less_bits(b, a)
}

/// `a == b` (IEEE: false if either is a NaN; `-0 == +0`).
#[inline]
pub fn eq(a: f32, b: f32) -> bool {
    let (a, b) = (a.to_bits(), b.to_bits());
    !unordered_bits(a, b) && (a == b || (a | b) << 1 == 0)
}

/// `a` or `b` is a NaN.
#[inline]
pub fn unordered(a: f32, b: f32) -> bool {
    unordered_bits(a.to_bits(), b.to_bits())
}

#[inline(always)]
fn unordered_bits(a: u32, b: u32) -> bool {
    a << 1 > INF << 1 || b << 1 > INF << 1
}

/// `a < b` for two floats that are not NaNs.
#[inline(always)]
fn less_bits(a: u32, b: u32) -> bool {
    let (ia, ib) = (a as i32, b as i32);
    if (ia & ib) < 0 {
        // Two negatives order backwards as integers.
        ia > ib
    } else {
        // Only `-0 < +0` is false where the integers are ordered.
        ia < ib && (a | b) << 1 != 0
    }
}

/// Defines the `f32` routines a Cortex-M0/M0+ firmware's compiler calls
/// (`__aeabi_fadd`, `__aeabi_fsub`, `__aeabi_fmul` and the `__aeabi_fcmp*`
/// family) as this crate's [`soft_float`](crate::soft_float)
/// functions: the same results to the bit, in fewer instructions (see the
/// module docs for the figures). Invoke it once, at the firmware's crate
/// root; it defines nothing on a target other than 32-bit Arm with the
/// soft-float ABI (`thumbv6m-none-eabi`, `thumbv7m-none-eabi`, ...).
///
/// ```ignore
/// #![no_std]
/// #![no_main]
/// coil_thermal::soft_float_routines!();
/// ```
///
/// The symbols are unmangled (`#[no_mangle]`): a crate that forbids
/// `unsafe_code` must allow it where it invokes the macro, and a firmware
/// that already defines these symbols (an RP2040 HAL's ROM routines) must
/// not invoke it.
#[macro_export]
macro_rules! soft_float_routines {
    () => {
        #[cfg(all(target_arch = "arm", not(target_abi = "eabihf")))]
        const _: () = {
            /// `a + b` (`coil_thermal::soft_float::add`).
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fadd(a: f32, b: f32) -> f32 {
                $crate::soft_float::add(a, b)
            }
            /// `a - b` (`coil_thermal::soft_float::sub`).
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fsub(a: f32, b: f32) -> f32 {
                $crate::soft_float::sub(a, b)
            }
            /// `a * b` (`coil_thermal::soft_float::mul`).
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fmul(a: f32, b: f32) -> f32 {
                $crate::soft_float::mul(a, b)
            }
            /// `a == b`.
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fcmpeq(a: f32, b: f32) -> i32 {
                $crate::soft_float::eq(a, b) as i32
            }
            /// `a < b`.
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fcmplt(a: f32, b: f32) -> i32 {
                $crate::soft_float::lt(a, b) as i32
            }
            /// `a <= b`.
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fcmple(a: f32, b: f32) -> i32 {
                $crate::soft_float::le(a, b) as i32
            }
            /// `a >= b`.
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fcmpge(a: f32, b: f32) -> i32 {
                $crate::soft_float::le(b, a) as i32
            }
            /// `a > b`.
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fcmpgt(a: f32, b: f32) -> i32 {
                $crate::soft_float::lt(b, a) as i32
            }
            /// `a` or `b` is a NaN.
            #[no_mangle]
            pub extern "aapcs" fn __aeabi_fcmpun(a: f32, b: f32) -> i32 {
                $crate::soft_float::unordered(a, b) as i32
            }
        };
    };
}

/// Rounds and packs a finite result: `sign`, the biased exponent `exp` of
/// the significand `w`'s bit 30 (the implicit one; lower for a subnormal
/// result with `exp` 1), and the bits below the result's last in `w`'s
/// bits 6..0 (bit 0 set if anything nonzero was shifted out).
#[inline(always)]
fn round_pack(sign: u32, exp: i32, w: u32) -> u32 {
    // One compare for both ends of the range.
    if (exp - 1) as u32 >= 0xFE {
        return sign | beyond_normal(exp, w);
    }
    // The implicit one adds 1 to the exponent field, and a carry out of
    // the significand goes on into it (to infinity from the largest).
    sign | ((((exp - 1) as u32) << 23) + rounded(w))
}

/// [`round_pack`]'s magnitude for an exponent beyond the normal range:
/// infinity above it, a subnormal (or zero) below.
#[cold]
#[inline(never)]
fn beyond_normal(exp: i32, w: u32) -> u32 {
    if exp >= 0xFF {
        INF
    } else {
        round_subnormal(exp, w)
    }
}

/// [`round_pack`] of a result below the smallest normal (`exp <= 0`):
/// the significand shifted to exponent 1, then rounded (a carry makes it
/// the smallest normal).
#[inline(always)]
fn round_subnormal(exp: i32, w: u32) -> u32 {
    let shift = (1 - exp) as u32;
    let w = if shift < 32 {
        (w >> shift) | ((w << (32 - shift) != 0) as u32)
    } else {
        (w != 0) as u32
    };
    rounded(w)
}

/// Leading zeros of a nonzero `x`, without a call (Thumb-1 has no `clz`).
#[inline(always)]
fn leading_zeros(mut x: u32) -> u32 {
    let mut n = 0;
    if x < 1 << 16 {
        n += 16;
        x <<= 16;
    }
    if x < 1 << 24 {
        n += 8;
        x <<= 8;
    }
    if x < 1 << 28 {
        n += 4;
        x <<= 4;
    }
    if x < 1 << 30 {
        n += 2;
        x <<= 2;
    }
    if x < 1 << 31 {
        n += 1;
    }
    n
}

/// A nonzero finite magnitude's biased exponent (below 1 for a subnormal)
/// and significand with its leading one at bit 23.
#[inline(always)]
fn unpack(abs: u32) -> (i32, u32) {
    let exp = (abs >> 23) as i32;
    if exp != 0 {
        return (exp, (abs & FRACTION) | HIDDEN);
    }
    let shift = leading_zeros(abs) - 8;
    (1 - shift as i32, abs << shift)
}

/// A NaN operand quieted (the first if both are), for a NaN result.
#[inline(always)]
fn nan_operand(a: u32, b: u32) -> Option<u32> {
    if a & !SIGN > INF {
        Some(a | QUIET)
    } else if b & !SIGN > INF {
        Some(b | QUIET)
    } else {
        None
    }
}

fn add_bits(a: u32, b: u32) -> u32 {
    // The magnitudes shifted up a bit: the exponent is the top byte, and
    // they order as the magnitudes do.
    let (ka, kb) = (a << 1, b << 1);
    if is_special(ka) || is_special(kb) {
        // A zero, the common case, here; the rest out of line.
        if kb == 0 && ka <= INF << 1 {
            // Two zeros: -0 only if both are.
            return if ka == 0 { a & b } else { a };
        }
        if ka == 0 && kb <= INF << 1 {
            return b;
        }
        return add_special(a, b);
    }
    // `x` the larger magnitude: its sign is the result's.
    let (x, y) = if ka >= kb { (a, b) } else { (b, a) };
    let shift = ((x << 1) >> 24) - ((y << 1) >> 24);
    if shift > 25 {
        // `y` is below a quarter of `x`'s last place (of the place below,
        // if `x` is a power of two): `x` is the rounded sum.
        return x;
    }
    // `x`'s sign and exponent less the implicit one: the rounded
    // significand (its leading one at bit 23) adds the exponent back, and
    // a carry out of it goes on into the exponent (to infinity from the
    // largest finite).
    let base = (x & !FRACTION) - HIDDEN;
    let mx = significand_at_30(x);
    // `y` aligned, what falls off kept as a sticky bit (nothing does for
    // a shift up to 7: the low 7 bits are zeros).
    let my = significand_at_30(y);
    let my = (my >> shift) | ((my & ((1 << shift) - 1) != 0) as u32);
    if (a ^ b) & SIGN == 0 {
        let w = mx + my;
        if w >= 1 << 31 {
            // One place up.
            if x << 1 >= 0xFE << 24 {
                return (x & SIGN) | INF;
            }
            return base + HIDDEN + rounded((w >> 1) | (w & 1));
        }
        return base + rounded(w);
    }
    let w = mx - my;
    if w >= 1 << 30 {
        return base + rounded(w);
    }
    if w >= 1 << 29 && x << 1 >= 2 << 24 {
        // One place down, the exponent still normal.
        return base - HIDDEN + rounded(w << 1);
    }
    if w == 0 {
        // `x - x` is +0 when rounding to nearest.
        return 0;
    }
    cancelled(x & SIGN, ((x << 1) >> 24) as i32, w)
}

/// `w`'s bits 30..7 rounded to nearest even on its bits 6..0: the
/// significand with its leading one at bit 23 (`2^24` when it carries).
#[inline(always)]
fn rounded(w: u32) -> u32 {
    (w + 0x3F + ((w >> 7) & 1)) >> 7
}

/// `x` is zero, subnormal, infinite or NaN, for `x` shifted up a bit
/// (its exponent field 0 or 255).
#[inline(always)]
fn is_special(shifted: u32) -> bool {
    shifted.wrapping_add(1 << 24) < 2 << 24
}

/// A normal `x`'s significand with its implicit one at bit 30.
#[inline(always)]
fn significand_at_30(x: u32) -> u32 {
    ((x << 8) | SIGN) >> 1
}

/// The end of a subtraction that cancelled more than one leading bit
/// (`w` nonzero, below `2^29`, or `2^30` at the exponent 1): normalised,
/// but not below the exponent 1 (a subnormal result). Exact, so not
/// rounded: it takes exponents at most one apart, and `w`'s bits below the
/// last place are zeros once shifted up.
#[cold]
#[inline(never)]
fn cancelled(sign: u32, exp: i32, w: u32) -> u32 {
    let up = (leading_zeros(w) - 1).min(exp as u32 - 1);
    // The exponent stays at least 1; below the implicit one, a subnormal.
    sign | ((((exp as u32) - up - 1) << 23) + ((w << up) >> 7))
}

/// [`add_bits`] where an operand is a subnormal, an infinity or a NaN (a
/// zero with a number that is not a NaN [`add_bits`] took in line).
#[cold]
#[inline(never)]
fn add_special(a: u32, b: u32) -> u32 {
    if let Some(nan) = nan_operand(a, b) {
        return nan;
    }
    let (abs_a, abs_b) = (a & !SIGN, b & !SIGN);
    if abs_a == INF {
        return if a ^ b == SIGN { INVALID } else { a };
    }
    if abs_b == INF {
        return b;
    }
    add_subnormal(a, b)
}

/// [`add_bits`] with a subnormal operand (and no zero): as a normal one
/// without the implicit one, at the exponent 1.
fn add_subnormal(a: u32, b: u32) -> u32 {
    let (abs_a, abs_b) = (a & !SIGN, b & !SIGN);
    let (x, y) = if abs_a >= abs_b { (a, b) } else { (b, a) };
    let (exp_x, exp_y) = ((x >> 23) & 0xFF, (y >> 23) & 0xFF);
    let mx = ((x & FRACTION) | if exp_x != 0 { HIDDEN } else { 0 }) << 7;
    let my = ((y & FRACTION) | if exp_y != 0 { HIDDEN } else { 0 }) << 7;
    let exp_x = exp_x.max(1);
    let shift = exp_x - exp_y.max(1);
    let my = if shift < 32 {
        (my >> shift) | ((my & ((1u32 << shift) - 1) != 0) as u32)
    } else {
        1
    };
    let exp = exp_x as i32;
    if (a ^ b) & SIGN == 0 {
        let w = mx + my;
        if w >= 1 << 31 {
            return round_pack(x & SIGN, exp + 1, (w >> 1) | (w & 1));
        }
        return round_pack(x & SIGN, exp, w);
    }
    // Normalised, but not below the exponent 1; rounded, as a shift past
    // the sticky bit may have made it inexact.
    let w = mx - my;
    if w == 0 {
        return 0;
    }
    let up = (leading_zeros(w) - 1).min(exp as u32 - 1);
    round_pack(x & SIGN, exp - up as i32, w << up)
}

fn mul_bits(a: u32, b: u32) -> u32 {
    let (ka, kb) = (a << 1, b << 1);
    let sign = (a ^ b) & SIGN;
    let (exp_sum, ma, mb) = if is_special(ka) || is_special(kb) {
        // A zero times a finite number, the common case, here; the rest
        // out of line.
        if (ka == 0 && kb < INF << 1) || (kb == 0 && ka < INF << 1) {
            return sign;
        }
        match mul_special(a, b) {
            Ok(operands) => operands,
            Err(result) => return result,
        }
    } else {
        (
            ((ka >> 24) + (kb >> 24)) as i32,
            (a & FRACTION) | HIDDEN,
            (b & FRACTION) | HIDDEN,
        )
    };
    // The 48-bit product from 12-bit halves (each partial product fits
    // 32 bits): `high` its bits 47..24, `low` its bits 23..0.
    let (ah, al) = (ma >> 12, ma & 0xFFF);
    let (bh, bl) = (mb >> 12, mb & 0xFFF);
    let middle = ah * bl + al * bh;
    let low = ((middle & 0xFFF) << 12) + al * bl;
    let high = ah * bh + (middle >> 12) + (low >> 24);
    let low = low & 0xFF_FFFF;
    // The product's leading one is its bit 47 or 46: its top to bit 30,
    // what falls off kept as a sticky bit.
    if high >= 1 << 23 {
        let w = (high << 7) | (low >> 17) | ((low & 0x1_FFFF != 0) as u32);
        round_pack(sign, exp_sum - 126, w)
    } else {
        let w = (high << 8) | (low >> 16) | ((low & 0xFFFF != 0) as u32);
        round_pack(sign, exp_sum - 127, w)
    }
}

/// [`mul_bits`] where an operand is a subnormal, an infinity or a NaN (or
/// a zero times an infinity or a NaN): the result (`Err`), or, for two finite
/// nonzero operands, the sum of their biased exponents (below 2 with a
/// subnormal) and their significands with the leading ones at bit 23.
#[cold]
#[inline(never)]
fn mul_special(a: u32, b: u32) -> Result<(i32, u32, u32), u32> {
    if let Some(nan) = nan_operand(a, b) {
        return Err(nan);
    }
    let sign = (a ^ b) & SIGN;
    let (abs_a, abs_b) = (a & !SIGN, b & !SIGN);
    if abs_a == INF || abs_b == INF {
        return Err(if abs_a == 0 || abs_b == 0 {
            INVALID
        } else {
            sign | INF
        });
    }
    // No zero here: [`mul_bits`] took a zero times a finite number in
    // line, and a zero times an infinity is above.
    let (exp_a, ma) = unpack(abs_a);
    let (exp_b, mb) = unpack(abs_b);
    Ok((exp_a + exp_b, ma, mb))
}

#[cfg(test)]
mod tests;
