//! Per-coil current limits that tighten as a coil nears its alarm limit, and
//! weights that let an over-actuated commutation prefer cooler coils.
//!
//! # Shape: `sqrt` of the temperature headroom
//!
//! With `T_start = T_alarm - taper_k`,
//!
//! ```text
//! headroom = clamp((T_alarm - T) / taper_k, 0, 1)
//! i_limit  = max(i_hw * sqrt(headroom), i_floor)
//! ```
//!
//! Joule power goes with `I^2`, so `sqrt` makes the *allowed power* fall
//! linearly with the temperature headroom: full power up to `T_start`, none
//! (or the floor's) at `T_alarm`. Since a coil's steady rise above its
//! surroundings is proportional to its power, this acts as a proportional
//! controller on power: a coil driven at its limit settles inside the taper
//! band instead of oscillating between full current and the shutdown. The
//! current is continuous in temperature and monotone non-increasing; it is
//! steep just below `T_alarm`, where power (not current) is what heats. The
//! coil resistance rises with temperature (`R(T) = 0.026 T + 5.166` ohm for
//! the HPPA), so the real allowed power tapers slightly later than linear;
//! the derating factors cover that.
//!
//! `T_alarm` is an input, not configuration: pass the alarm limits from
//! [`AlarmConfig::alarm_limits_c`](super::alarm::AlarmConfig::alarm_limits_c)
//! so the taper follows the measured ambient like the alarm does. Because the
//! band is given by its width, `T_start < T_alarm` holds for every ambient.
//!
//! # Weight: the unused fraction of the allowed rise
//!
//! ```text
//! weight = clamp((T_alarm - T) / max(T_alarm - T_ambient, taper_k), 0, 1)
//! ```
//!
//! 1 at ambient, 0 at the alarm limit, and strictly decreasing in between, so
//! of two coils the cooler one always weighs more, even well below
//! `T_start` where both may carry the full hardware current. Using `max` with
//! `taper_k` keeps the divisor positive, and a NaN ambient falls back to the
//! taper band (NaN loses in [`Scalar::max`]).
//!
//! # A limit in the drive's own unit
//!
//! A voltage-driven winding (a PWM duty `D` on a supply `V`, see
//! [`Drive::Voltage`](crate::network::Drive::Voltage)) is limited by its
//! duty, not its current. [`drive_limit`] turns the current limit `I_lim`
//! into the effective voltage and duty that draw it at the winding's
//! estimated temperature `T`:
//!
//! ```text
//! V_lim = I_lim R(T)                 (a linear voltage drive's limit)
//! D_max = clamp((I_lim R(T) / V)^2, 0, 1)
//! ```
//!
//! Held at `D_max`, the coil's heat `D_max V^2 / R(T')` equals the current
//! limit's `I_lim^2 R(T)` at `T' = T` and is *below* it at any hotter `T'`
//! (the current limit's heat rises with `T'`, the duty's falls), so a coil
//! heating from `T` under the duty stays below the path the current limit
//! allows. `R` is taken at the estimate, not at the upper bound: a hotter
//! `R` would give a larger duty. With a supply reading that is NaN,
//! infinite, zero or negative the duty limit is **zero** and flagged
//! ([`DriveFlags::SUPPLY_INVALID`]): without the supply the heat a duty
//! makes is unknown, the last valid reading may be lower than the supply
//! now (a duty computed from it would overshoot the current limit by the
//! ratio squared), and a de-energised solenoid valve is the fail-safe
//! position it is designed for. The effective voltage limit `V_lim` needs
//! no supply and stays published.
//!
//! # Invalid inputs
//!
//! A non-finite temperature or alarm limit gives the floor current and zero
//! weight, and is flagged. In fixed point there are no non-finite values;
//! saturated extremes simply clamp.

use core::ops::Range;

use crate::error::BuildError;
use crate::input::DriveFlags;
use crate::scalar::Scalar;
use crate::sizes::{Element, Length};
use nalgebra::Const;

/// A voltage-driven winding's limit in its drive's units (see "A limit in
/// the drive's own unit").
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveLimit {
    /// The largest PWM duty in `[0, 1]` (dimensionless); zero for an
    /// invalid supply reading or an invalid current limit.
    pub duty: f32,
    /// The largest effective voltage `sqrt(D) V` \[V\] (a linear drive's
    /// voltage limit), `>= 0`; zero for an invalid current limit.
    pub voltage_v: f32,
    /// [`DriveFlags::SUPPLY_INVALID`] when the supply reading was unusable,
    /// [`DriveFlags::RESISTANCE_INVALID`] when `R(T)` was not positive.
    pub flags: DriveFlags,
}

/// The duty and effective-voltage limits of a voltage-driven winding with
/// current limit `limit` and resistance `resistance_ohm` \[ohm\] (its
/// `R(T)` at its estimated temperature), on a supply measured at
/// `supply_v` \[V\] (see "A limit in the drive's own unit"). Panic-free
/// for any input; a NaN anywhere gives a zero limit, never a NaN one.
pub fn drive_limit(limit: &CoilLimit<f32>, resistance_ohm: f32, supply_v: f32) -> DriveLimit {
    let mut flags = DriveFlags::NONE;
    let r = resistance_ohm;
    if !(r.is_finite() && r > 0.0) {
        flags |= DriveFlags::RESISTANCE_INVALID;
    }
    let current_a = if limit.invalid || !limit.current_a.is_finite() {
        0.0
    } else {
        limit.current_a.abs()
    };
    let voltage_v = if flags.is_clean() {
        let v = current_a * r;
        if v.is_finite() {
            v
        } else {
            0.0
        }
    } else {
        0.0
    };
    if !(supply_v.is_finite() && supply_v > 0.0) {
        flags |= DriveFlags::SUPPLY_INVALID;
    }
    let duty = if flags.contains(DriveFlags::SUPPLY_INVALID) {
        0.0
    } else {
        let ratio = voltage_v / supply_v;
        // `min` before squaring: a ratio beyond 1 is full on anyway.
        let ratio = if ratio.is_finite() {
            ratio.min(1.0)
        } else {
            0.0
        };
        ratio * ratio
    };
    DriveLimit {
        duty,
        voltage_v,
        flags,
    }
}

/// The limiter configuration for `N` coils, in scalar `S`.
#[derive(Debug, Clone, PartialEq)]
pub struct LimiterConfig<S: Element, N: Length> {
    pub(crate) hardware_limit_a: N::Array<S>,
    pub(crate) taper_k: S,
    /// `1 / taper_k` \[1/K\]: the taper is a multiply per coil, where a
    /// division is a software routine on a core without an FPU.
    pub(crate) taper_per_k: S,
    pub(crate) floor_a: S,
}

#[cfg(feature = "defmt")]
impl<S: Element + defmt::Format, const N: usize> defmt::Format for LimiterConfig<S, Const<N>> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "LimiterConfig {{ hardware_limit_a: {}, taper_k: {}, floor_a: {} }}",
            self.hardware_limit_a,
            self.taper_k,
            self.floor_a
        )
    }
}

/// One coil's limit for this tick.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CoilLimit<S> {
    /// The largest current magnitude allowed \[A\], in
    /// `[floor_a, hardware_limit_a]`.
    pub current_a: S,
    /// Preference for this coil in \[0, 1\] (dimensionless): higher is cooler.
    pub weight: S,
    /// The coil's temperature or alarm limit was not finite: `current_a` is
    /// the floor and `weight` zero.
    pub invalid: bool,
}

impl<S: Scalar> CoilLimit<S> {
    /// Clamps a signed current command `current_a` \[A\] to
    /// `[-self.current_a, self.current_a]`.
    #[inline]
    pub fn clamp_a(&self, current_a: S) -> S {
        current_a.clamp_to(-self.current_a, self.current_a)
    }
}

/// A latched shutdown allows no current: every limit to zero \[A\] (and
/// weight zero), whatever the limiter computed. The observers apply it to
/// their published limits after every tick while the shutdown is latched, so
/// a controller that clamps its commands to the limits cuts the current even
/// if it ignores the alarm flag; the limiter computes normal limits again
/// after the deliberate clear. `O(len)`, panic-free.
pub fn hold_shutdown<S: Scalar>(limits: &mut [CoilLimit<S>]) {
    for limit in limits {
        limit.current_a = S::ZERO;
        limit.weight = S::ZERO;
    }
}

/// What a [`LimiterConfig::apply`] call did, over all coils.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LimiterStatus {
    /// Coils whose limit is below their hardware limit.
    pub limited: usize,
    /// Coils with a non-finite temperature or alarm limit (given the floor).
    pub invalid: usize,
}

impl<S: Scalar, const N: usize> LimiterConfig<S, Const<N>> {
    /// Validates a configuration: each coil's hardware current limit
    /// `hardware_limit_a` \[A\] (finite, > 0), the width of the taper band
    /// below the alarm limit `taper_k` \[K\] (finite, > 0), and the current
    /// left at and above the alarm limit `floor_a` \[A\] (finite, >= 0, not
    /// above any hardware limit; 0 for a full stop).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the parameter. The checks are
    /// made on the values converted to `S`, so a `taper_k` too small for the
    /// fixed-point resolution is rejected rather than divided by.
    pub fn new(hardware_limit_a: [f64; N], taper_k: f64, floor_a: f64) -> Result<Self, BuildError> {
        Self::of(&hardware_limit_a, taper_k, floor_a)
    }
}

impl<S: Scalar, N: Length> LimiterConfig<S, N> {
    /// [`LimiterConfig::new`] for coils of any [`Length`] (a `Vec` for
    /// `Dyn`, a model's size read at run time).
    ///
    /// # Errors
    /// As [`LimiterConfig::new`].
    pub fn of(
        hardware_limit_a: &N::Array<f64>,
        taper_k: f64,
        floor_a: f64,
    ) -> Result<Self, BuildError> {
        let config = Self {
            hardware_limit_a: N::mapped(hardware_limit_a, |&a| S::from_f64(a)),
            taper_k: S::from_f64(taper_k),
            taper_per_k: S::from_f64(1.0 / taper_k),
            floor_a: S::from_f64(floor_a),
        };
        let positive = |raw: f64, converted: S| raw.is_finite() && converted > S::ZERO;
        let hardware_ok = hardware_limit_a
            .as_ref()
            .iter()
            .zip(config.hardware_limit_a.as_ref())
            .all(|(&raw, &converted)| positive(raw, converted) && converted >= config.floor_a);
        if !(positive(taper_k, config.taper_k) && config.taper_per_k > S::ZERO) {
            return Err(BuildError::InvalidParameter { name: "taper_k" });
        }
        if !(floor_a.is_finite() && floor_a >= 0.0) {
            return Err(BuildError::InvalidParameter { name: "floor_a" });
        }
        if !hardware_ok {
            // Distinguish a bad hardware limit from a floor above a good one.
            let name = if hardware_limit_a
                .as_ref()
                .iter()
                .all(|&a| a.is_finite() && a > 0.0)
            {
                "floor_a"
            } else {
                "hardware_limit_a"
            };
            return Err(BuildError::InvalidParameter { name });
        }
        Ok(config)
    }

    /// The limit and weight of every coil for temperatures `temps_c` \[degC\],
    /// alarm limits `alarm_limits_c` \[degC\] and ambient `ambient_c`
    /// \[degC\], written to `out`.
    ///
    /// O(N), allocation-free, panic-free; every division is by a value the
    /// constructor or a `max` keeps positive.
    pub fn apply(
        &self,
        temps_c: &N::Array<S>,
        alarm_limits_c: &N::Array<S>,
        ambient_c: S,
        out: &mut N::Array<CoilLimit<S>>,
    ) -> LimiterStatus {
        let all = 0..temps_c.as_ref().len();
        self.apply_part(temps_c, alarm_limits_c, ambient_c, out, all)
    }

    /// [`Self::apply`] for the coils in `coils` only (cut to `N`), the
    /// others' limits left as they are: for a caller that spreads the
    /// limiter over several control ticks. The status counts those coils.
    pub fn apply_part(
        &self,
        temps_c: &N::Array<S>,
        alarm_limits_c: &N::Array<S>,
        ambient_c: S,
        out: &mut N::Array<CoilLimit<S>>,
        coils: Range<usize>,
    ) -> LimiterStatus {
        let mut status = LimiterStatus::default();
        let n = temps_c.as_ref().len();
        let coils = coils.start.min(n)..coils.end.min(n);
        let (Some(temps_c), Some(alarm_limits_c), Some(hardware_a), Some(out)) = (
            temps_c.as_ref().get(coils.clone()),
            alarm_limits_c.as_ref().get(coils.clone()),
            self.hardware_limit_a.as_ref().get(coils.clone()),
            out.as_mut().get_mut(coils),
        ) else {
            return status;
        };
        let inputs = temps_c
            .iter()
            .zip(alarm_limits_c.iter())
            .zip(hardware_a.iter());
        for (limit, ((&temp_c, &alarm_c), &hardware_a)) in out.iter_mut().zip(inputs) {
            *limit = self.coil(temp_c, alarm_c, ambient_c, hardware_a);
            status.invalid += usize::from(limit.invalid);
            status.limited += usize::from(limit.current_a < hardware_a);
        }
        status
    }

    /// One coil: the formula of the module docs.
    #[inline]
    fn coil(&self, temp_c: S, alarm_c: S, ambient_c: S, hardware_a: S) -> CoilLimit<S> {
        if !(temp_c.is_finite() && alarm_c.is_finite()) {
            return CoilLimit {
                current_a: self.floor_a,
                weight: S::ZERO,
                invalid: true,
            };
        }
        let margin_k = alarm_c - temp_c;
        // The clamps of `headroom` and `current_a` cannot meet a NaN (finite
        // or infinite margin over a positive taper; a root in [0, 1]), so
        // they are plain comparisons: `Scalar::max`'s NaN test is a third of
        // a float comparison's cost on an M4F, twice per clamp.
        let headroom = ordered_clamp(margin_k * self.taper_per_k, S::ZERO, S::ONE);
        // Below the taper band (most coils, most of the time) the root is 1
        // exactly: no square root, which is software on an M0.
        let root = if headroom >= S::ONE {
            S::ONE
        } else {
            Scalar::sqrt(headroom)
        };
        let current_a = ordered_clamp(hardware_a * root, self.floor_a, hardware_a);
        let span_k = (alarm_c - ambient_c).max(self.taper_k);
        let weight = (margin_k / span_k).clamp_to(S::ZERO, S::ONE);
        CoilLimit {
            current_a,
            weight,
            invalid: false,
        }
    }

    /// The hardware current limits \[A\].
    pub fn hardware_limit_a(&self) -> &N::Array<S> {
        &self.hardware_limit_a
    }

    /// The width of the taper band below the alarm limit \[K\].
    pub fn taper_k(&self) -> S {
        self.taper_k
    }

    /// The current allowed at and above the alarm limit \[A\].
    pub fn floor_a(&self) -> S {
        self.floor_a
    }

    /// Feeds every parameter (hardware limits, taper, floor) to a snapshot
    /// fingerprint.
    #[must_use]
    pub fn fingerprint(&self, fp: crate::observer::Fingerprint) -> crate::observer::Fingerprint {
        self.hardware_limit_a
            .as_ref()
            .iter()
            .fold(fp, |fp, a| fp.f64(a.to_f64()))
            .f64s(&[self.taper_k.to_f64(), self.floor_a.to_f64()])
    }
}

/// `x` clamped to `[lo, hi]` (`lo <= hi`) for an `x` that is not NaN: the
/// same as [`Scalar::clamp_to`] there, without its NaN tests.
#[inline(always)]
fn ordered_clamp<S: Scalar>(x: S, lo: S, hi: S) -> S {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scalar::Q32;
    use proptest::prelude::*;

    const HW_A: f64 = 3.0;
    const TAPER_K: f64 = 10.0;
    const ALARM_C: f64 = 65.36;
    const AMBIENT_C: f64 = 20.0;

    fn one<S: Scalar>(cfg: &LimiterConfig<S, Const<1>>, temp_c: f64) -> CoilLimit<S> {
        let mut out = [CoilLimit::default()];
        cfg.apply(
            &[S::from_f64(temp_c)],
            &[S::from_f64(ALARM_C)],
            S::from_f64(AMBIENT_C),
            &mut out,
        );
        out[0]
    }

    /// The closed form, written independently in f64.
    fn expected_a(temp_c: f64, floor_a: f64) -> f64 {
        let t_start = ALARM_C - TAPER_K;
        if temp_c <= t_start {
            HW_A
        } else if temp_c >= ALARM_C {
            floor_a
        } else {
            (HW_A * ((ALARM_C - temp_c) / (ALARM_C - t_start)).sqrt()).max(floor_a)
        }
    }

    #[test]
    fn table_against_closed_form() {
        let cfg = LimiterConfig::<f64, Const<1>>::new([HW_A], TAPER_K, 0.0).unwrap();
        // (temperature, limit): at T_start + 7.5 K a quarter of the headroom
        // is left, so half the current and a quarter of the power.
        let table = [
            (-40.0, 3.0),
            (20.0, 3.0),
            (55.36, 3.0),
            (62.86, 1.5),
            (65.36, 0.0),
            (200.0, 0.0),
        ];
        for (temp_c, want) in table {
            let got = one(&cfg, temp_c).current_a;
            assert!((got - want).abs() < 1e-12, "{temp_c}: {got} != {want}");
            assert!((got - expected_a(temp_c, 0.0)).abs() < 1e-12);
        }
        // Weight: the fraction of the 45.36 K allowed rise still unused.
        assert!((one(&cfg, 20.0).weight - 1.0).abs() < 1e-12);
        assert!((one(&cfg, 42.68).weight - 0.5).abs() < 1e-12);
        assert_eq!(one(&cfg, 70.0).weight, 0.0);
        assert_eq!(one(&cfg, 0.0).weight, 1.0);
    }

    #[test]
    fn floor_and_invalid_inputs() {
        let cfg = LimiterConfig::<f32, Const<1>>::new([HW_A], TAPER_K, 0.2).unwrap();
        assert_eq!(one(&cfg, 100.0).current_a, 0.2);
        assert!(!one(&cfg, 100.0).invalid);
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let limit = one(&cfg, bad);
            assert_eq!(
                (limit.current_a, limit.weight, limit.invalid),
                (0.2, 0.0, true)
            );
        }
        // A NaN alarm limit too, and it is counted.
        let cfg2 = LimiterConfig::<f32, Const<2>>::new([HW_A; 2], TAPER_K, 0.2).unwrap();
        let mut out = [CoilLimit::default(); 2];
        let status = cfg2.apply(&[30.0, 30.0], &[f32::NAN, 65.0], 20.0, &mut out);
        assert_eq!(
            status,
            LimiterStatus {
                limited: 1,
                invalid: 1
            }
        );
        assert!(out[0].invalid && !out[1].invalid);
        assert_eq!(out[1].current_a, 3.0);
        // A NaN ambient only changes the weight's span, to the taper band.
        let mut out = [CoilLimit::default()];
        cfg.apply(&[60.0], &[65.0], f32::NAN, &mut out);
        assert!((out[0].weight - 0.5).abs() < 1e-6 && !out[0].invalid);
    }

    #[test]
    fn clamp_a_is_symmetric() {
        let limit = CoilLimit {
            current_a: 1.5,
            weight: 1.0,
            invalid: false,
        };
        assert_eq!(limit.clamp_a(2.0), 1.5);
        assert_eq!(limit.clamp_a(-2.0), -1.5);
        assert_eq!(limit.clamp_a(0.3), 0.3);
    }

    #[test]
    fn config_is_validated() {
        let err = |hw: f64, taper: f64, floor: f64| {
            LimiterConfig::<f64, Const<2>>::new([HW_A, hw], taper, floor).unwrap_err()
        };
        let name = |name| BuildError::InvalidParameter { name };
        assert_eq!(err(0.0, 10.0, 0.0), name("hardware_limit_a"));
        assert_eq!(err(f64::NAN, 10.0, 0.0), name("hardware_limit_a"));
        assert_eq!(err(1.0, 0.0, 0.0), name("taper_k"));
        assert_eq!(err(1.0, f64::INFINITY, 0.0), name("taper_k"));
        assert_eq!(err(1.0, 10.0, -0.1), name("floor_a"));
        assert_eq!(err(1.0, 10.0, 1.5), name("floor_a"));
        // Below one Q32 LSB the taper would divide by zero: rejected.
        assert_eq!(
            LimiterConfig::<Q32, Const<1>>::new([HW_A], 1e-12, 0.0).unwrap_err(),
            name("taper_k")
        );
        assert!(LimiterConfig::<f64, Const<1>>::new([HW_A], 1e-12, 0.0).is_ok());
    }

    /// Fixed-point error against f64. Away from the alarm limit it is a few
    /// LSB of Q32 (2^-32 = 2.3e-10) times the slope: measured 3.9e-8 A over
    /// the band, bounded here by 1e-6 A. Just below the limit, `sqrt` is
    /// steepest: one LSB of headroom under the root is sqrt(2^-32) = 1.5e-5
    /// relative, so there the bound is 2e-5 * i_hw.
    const Q32_TOLERANCE_A: f64 = 1e-6;
    const Q32_TOLERANCE_NEAR_LIMIT_A: f64 = 2e-5 * HW_A;

    #[test]
    fn fixed_point_agrees_with_f64() {
        let cfg64 = LimiterConfig::<f64, Const<1>>::new([HW_A], TAPER_K, 0.0).unwrap();
        let cfgq = LimiterConfig::<Q32, Const<1>>::new([HW_A], TAPER_K, 0.0).unwrap();
        let error = |temp_c: f64| {
            let (a, q) = (one(&cfg64, temp_c), one(&cfgq, temp_c));
            assert!((a.weight - q.weight.to_f64()).abs() < 1e-8, "{temp_c}");
            (a.current_a - q.current_a.to_f64()).abs()
        };
        // 40 .. 80 degC in 0.2 mK steps, through the whole taper band.
        let band = (0..=200_000).map(|step| error(40.0 + f64::from(step) * 2e-4));
        let worst = band.fold(0.0, f64::max);
        assert!(worst <= Q32_TOLERANCE_A, "{worst}");
        // The error is real, so the tolerance is not vacuous.
        assert!(worst > 1e-9, "{worst}");
        // The last microkelvin below the limit, in 1e-10 K steps.
        let near = (0..=10_000).map(|k| error(ALARM_C - f64::from(k) * 1e-10));
        let worst_near = near.fold(0.0, f64::max);
        assert!(worst_near <= Q32_TOLERANCE_NEAR_LIMIT_A, "{worst_near}");
        assert!(worst_near > Q32_TOLERANCE_A, "{worst_near}");
    }

    /// A temperature strategy with the awkward values included.
    fn temperature() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => -300.0f64..400.0,
            2 => (ALARM_C - TAPER_K - 0.01)..(ALARM_C + 0.01),
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => Just(f64::NEG_INFINITY),
            1 => Just(f64::MAX),
            1 => Just(-f64::MAX),
            1 => Just(1e12),
            1 => Just(-1e12),
            1 => any::<f64>(),
        ]
    }

    /// Properties every scalar must meet: the limit stays within
    /// `[floor, hw]`, the weight within [0, 1], a non-finite temperature gets
    /// the floor, and a hotter coil never gets more current or weight.
    fn check_properties<S: Scalar>(a_c: f64, b_c: f64, floor_a: f64) -> Result<(), TestCaseError> {
        let cfg = LimiterConfig::<S, Const<1>>::new([HW_A], TAPER_K, floor_a).unwrap();
        let (la, lb) = (one(&cfg, a_c), one(&cfg, b_c));
        let hw = S::from_f64(HW_A);
        let floor = S::from_f64(floor_a);
        for (temp_c, limit) in [(a_c, la), (b_c, lb)] {
            prop_assert!(
                limit.current_a <= hw && limit.current_a >= floor,
                "{:?}",
                limit
            );
            prop_assert!(limit.weight >= S::ZERO && limit.weight <= S::ONE);
            if S::from_f64(temp_c).is_finite() {
                prop_assert!(!limit.invalid);
            } else {
                prop_assert!(limit.invalid && limit.current_a == floor);
            }
        }
        // Monotone over what the limiter actually sees (in Q32 a NaN has
        // already become 0 degC and infinities saturate).
        let (sa, sb) = (S::from_f64(a_c), S::from_f64(b_c));
        if sa.is_finite() && sb.is_finite() && sa <= sb {
            prop_assert!(la.current_a >= lb.current_a, "{a_c} {b_c} {la:?} {lb:?}");
            prop_assert!(la.weight >= lb.weight);
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        #[test]
        fn limiter_properties_f32(a in temperature(), b in temperature(), floor in 0.0f64..HW_A) {
            check_properties::<f32>(a, b, floor)?;
        }

        #[test]
        fn limiter_properties_f64(a in temperature(), b in temperature(), floor in 0.0f64..HW_A) {
            check_properties::<f64>(a, b, floor)?;
        }

        #[test]
        fn limiter_properties_q32(a in temperature(), b in temperature(), floor in 0.0f64..HW_A) {
            check_properties::<Q32>(a, b, floor)?;
        }

        /// Monotone within the taper band at fine spacing, where rounding
        /// could break it.
        #[test]
        fn limiter_monotone_in_band_q32(t in (ALARM_C - TAPER_K)..ALARM_C, dt in 0.0f64..1e-6) {
            check_properties::<Q32>(t, t + dt, 0.0)?;
            check_properties::<f32>(t, t + dt, 0.0)?;
        }
    }
}
