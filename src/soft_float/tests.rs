//! The routines against the host's hardware `f32` (IEEE 754, round to
//! nearest even, subnormals kept), bit for bit; a NaN result against the
//! compiler's rule (the module docs).

use super::*;

/// A small xorshift generator: the same cases on every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 32) as u32
    }
}

/// The compiler's NaN for an operation on `a` and `b` whose result is NaN.
fn nan_of(a: u32, b: u32) -> u32 {
    if a & !SIGN > INF {
        a | QUIET
    } else if b & !SIGN > INF {
        b | QUIET
    } else {
        INVALID
    }
}

/// What an operation must give: the hardware's result, or the compiler's
/// NaN (`b` as the routine sees it: negated for a subtraction).
fn expected(hardware: f32, a: u32, b: u32) -> u32 {
    if hardware.is_nan() {
        nan_of(a, b)
    } else {
        hardware.to_bits()
    }
}

/// Checks every operation on `(a, b)`; returns the number of failures
/// (printing the first few).
fn check(a: u32, b: u32, failures: &mut u32) {
    let (x, y) = (f32::from_bits(a), f32::from_bits(b));
    let cases = [
        ("add", add(x, y).to_bits(), expected(x + y, a, b)),
        ("sub", sub(x, y).to_bits(), expected(x - y, a, b ^ SIGN)),
        ("mul", mul(x, y).to_bits(), expected(x * y, a, b)),
    ];
    for (name, got, want) in cases {
        if got != want {
            *failures += 1;
            if *failures < 10 {
                println!("{name}({a:#010x}, {b:#010x}) = {got:#010x}, want {want:#010x}");
            }
        }
    }
    let comparisons = [
        ("lt", lt(x, y), x < y),
        ("le", le(x, y), x <= y),
        ("eq", eq(x, y), x == y),
        ("unordered", unordered(x, y), x.partial_cmp(&y).is_none()),
    ];
    for (name, got, want) in comparisons {
        if got != want {
            *failures += 1;
            if *failures < 10 {
                println!("{name}({a:#010x}, {b:#010x}) = {got}, want {want}");
            }
        }
    }
}

/// Values at every edge: zeros, the subnormal range's ends, the normal
/// range's ends, ones and their neighbours, halfway cases, infinities and
/// NaNs of both signs and both kinds.
fn edges() -> Vec<u32> {
    let magnitudes = [
        0x0000_0000, // 0
        0x0000_0001, // smallest subnormal
        0x0000_0002,
        0x0000_0003,
        0x0040_0000, // a subnormal half the range
        0x007F_FFFF, // largest subnormal
        0x0080_0000, // smallest normal
        0x0080_0001,
        0x00FF_FFFF,
        0x0100_0000,
        0x3380_0000, // 2^-24: a half ulp of 1
        0x33C0_0000, // 1.5 * 2^-24
        0x3400_0000, // 2^-23: an ulp of 1
        0x3F00_0000, // 0.5
        0x3F7F_FFFF, // 1 - ulp
        0x3F80_0000, // 1
        0x3F80_0001, // 1 + ulp
        0x3F80_0003,
        0x3FC0_0000, // 1.5
        0x3FFF_FFFF, // 2 - ulp
        0x4000_0000, // 2
        0x4040_0000, // 3
        0x4B7F_FFFF, // 2^24 - 1
        0x4B80_0000, // 2^24
        0x5F80_0000, // 2^64
        0x1F80_0000, // 2^-64
        0x7E80_0000, // 2^126
        0x7F00_0000, // 2^127
        0x7F7F_FFFF, // largest finite
        0x7F7F_FFFE,
        0x7F80_0000, // inf
        0x7F80_0001, // signalling NaN
        0x7FC0_0000, // quiet NaN
        0x7FFF_FFFF,
    ];
    magnitudes.iter().flat_map(|m| [*m, *m | SIGN]).collect()
}

#[test]
fn every_pair_of_edges_is_the_hardware_result() {
    let edges = edges();
    let mut failures = 0;
    for &a in &edges {
        for &b in &edges {
            check(a, b, &mut failures);
        }
    }
    assert_eq!(failures, 0);
}

#[test]
fn random_operands_are_the_hardware_result() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let mut failures = 0;
    for _ in 0..2_000_000 {
        check(rng.next(), rng.next(), &mut failures);
    }
    assert_eq!(failures, 0);
}

/// Close exponents (the additions that cancel, the products and quotients
/// near 1), and results near the ends of the range (subnormal, overflow).
#[test]
fn operands_at_the_hard_cases_are_the_hardware_result() {
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    let mut failures = 0;
    for _ in 0..2_000_000 {
        let a = rng.next();
        let r = rng.next();
        let exp_a = (a >> 23) & 0xFF;
        // Exponents within 3 of `a`'s, or summing (differing) to the
        // range's ends.
        let exp_b = match r % 4 {
            0 => exp_a.saturating_add(r >> 30).min(0xFE),
            1 => exp_a.saturating_sub(r >> 30),
            2 => (254 + (r >> 29) % 8).saturating_sub(exp_a).min(0xFE),
            _ => (100 + (r >> 28) % 64).saturating_sub(exp_a / 2).min(0xFE),
        };
        let b = (rng.next() & (SIGN | FRACTION)) | (exp_b << 23);
        check(a, b, &mut failures);
        // `a` less a few ulps: a near-total cancellation.
        let near = (a & !SIGN).wrapping_sub(r % 5) | (!a & SIGN);
        check(a, near, &mut failures);
        // Few significant bits: exact results and ties.
        let short = a & 0xFFFF_0000;
        check(short, b & 0xFFF0_0000, &mut failures);
    }
    assert_eq!(failures, 0);
}
