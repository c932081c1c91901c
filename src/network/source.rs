//! Heat sources: Joule heating of a winding with temperature-dependent
//! resistance.
//!
//! Both forms found in the references reduce to one straight line in degC:
//!
//! * copper with a temperature coefficient (Omnimagnet Eq. A3, solenoid note):
//!   `R(T) = R0 (1 + alpha (T - T_ref))`, built with [`Resistance::with_alpha`];
//! * the HPPA coil's measured linear fit `R(T) = 0.026 T + 5.166` ohm (T in
//!   degC), built with [`Resistance::linear_fit`] or taken as
//!   [`Resistance::HPPA_COIL`].
//!
//! Stored as `R(T) = r_at_0c + slope * T`, one multiply and one add per tick.
//!
//! A network refuses (at build, [`Resistance::check`]) a line with a
//! negative slope or with `R(0 degC) <= 0`: a winding's resistance rises
//! with temperature and is positive at 0 degC (copper, aluminium), and a
//! falling line was once used to fake `1/R(T)` for a coil driven by a
//! voltage. Such a coil is a [`Drive::Voltage`] source.
//!
//! # Two drives
//!
//! * [`Drive::Current`]: the input is the winding's current `I` \[A\] and
//!   its heat is `P = R(T) I^2`, rising as the winding heats (the
//!   quasi-runaway of solenoid-layers-runaway.md);
//! * [`Drive::Voltage`]: the input is the *effective* voltage
//!   `V_eff = sqrt(D) V` \[V\] of a PWM duty `D` on a supply `V` (or a
//!   linear voltage, `D = 1`), and the heat is `P = V_eff^2 / R(T) = D V^2 /
//!   R(T)`, *falling* as the winding heats: a voltage-driven coil cannot
//!   run away (the solenoid note's advice: a voltage limit on the source).
//!
//! The observers keep one per-tick power, `R(T) I^2`: a voltage-driven input
//! is handed to them as the current it draws at the estimated winding
//! temperature, `I = V_eff / R(T_est)`, so that `R(T_est) I^2 = D V^2 /
//! R(T_est)` exactly (see [`crate::input::VoltageDrive`]).

use crate::error::BuildError;
use crate::scalar::Scalar;

/// What drives a winding, and so what its input means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Drive {
    /// The input is the winding current \[A\]: `P = R(T) I^2`.
    #[default]
    Current,
    /// The input is the effective voltage `V_eff = sqrt(D) V` \[V\] (a PWM
    /// duty `D` in `[0, 1]` on a supply `V`, or a linear voltage with `D =
    /// 1`): `P = V_eff^2 / R(T)`.
    Voltage,
}

/// A winding's electrical resistance as a straight line in temperature.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Resistance {
    /// Resistance extrapolated to 0 degC \[ohm\].
    pub r_at_0c_ohm: f64,
    /// Slope dR/dT \[ohm/K\]; zero for a constant resistance.
    pub slope_ohm_per_k: f64,
}

impl Resistance {
    /// The HPPA coil: `R(T) = 0.026 T + 5.166` ohm, about 5.69 ohm at 20 degC
    /// (hppa-coil-grid.md, measured at 20 and 50 degC).
    pub const HPPA_COIL: Self = Self::linear_fit(0.026, 5.166);

    /// Copper's temperature coefficient at 20 degC \[1/K\].
    pub const ALPHA_COPPER_PER_K: f64 = 0.0039;

    /// A temperature-independent resistance \[ohm\].
    pub const fn constant(r_ohm: f64) -> Self {
        Self {
            r_at_0c_ohm: r_ohm,
            slope_ohm_per_k: 0.0,
        }
    }

    /// `R(T) = slope * T + r_at_0c` with T in degC (the HPPA form `a T + b`).
    pub const fn linear_fit(slope_ohm_per_k: f64, r_at_0c_ohm: f64) -> Self {
        Self {
            r_at_0c_ohm,
            slope_ohm_per_k,
        }
    }

    /// `R(T) = r_ref (1 + alpha (T - t_ref))`: `r_ref_ohm` at `t_ref_c` \[degC\],
    /// `alpha_per_k` \[1/K\].
    pub fn with_alpha(r_ref_ohm: f64, alpha_per_k: f64, t_ref_c: f64) -> Self {
        let slope = r_ref_ohm * alpha_per_k;
        Self {
            r_at_0c_ohm: r_ref_ohm - slope * t_ref_c,
            slope_ohm_per_k: slope,
        }
    }

    /// Resistance at `temp_c` \[ohm\], never negative.
    pub fn at_c(&self, temp_c: f64) -> f64 {
        (self.r_at_0c_ohm + self.slope_ohm_per_k * temp_c).max(0.0)
    }

    /// The temperature \[degC\] at which the winding has resistance `r_ohm`:
    /// the inverse of [`Resistance::at_c`], for a resistance-based virtual
    /// sensor. `None` for a constant resistance or a non-finite result.
    pub fn temp_c_at(&self, r_ohm: f64) -> Option<f64> {
        if self.slope_ohm_per_k == 0.0 {
            return None;
        }
        let t = (r_ohm - self.r_at_0c_ohm) / self.slope_ohm_per_k;
        t.is_finite().then_some(t)
    }

    /// Checks a winding's line for source `input`: both coefficients finite
    /// ([`BuildError::InvalidResistance`]), `R(0 degC) > 0`
    /// ([`BuildError::InvalidResistance`]) and a slope `>= 0`
    /// ([`BuildError::FallingResistance`]). A falling line has no meaning
    /// for a winding: for a coil driven by a voltage, whose *power* falls
    /// as it heats, use [`Drive::Voltage`].
    pub fn check(&self, input: usize) -> Result<(), BuildError> {
        if !(self.r_at_0c_ohm.is_finite() && self.slope_ohm_per_k.is_finite())
            || self.r_at_0c_ohm <= 0.0
        {
            return Err(BuildError::InvalidResistance { input });
        }
        if self.slope_ohm_per_k < 0.0 {
            return Err(BuildError::FallingResistance { input });
        }
        Ok(())
    }

    /// Heat \[W\] of a winding at `temp_c` driven by `input`: `R(T) I^2`
    /// for a current \[A\], `V_eff^2 / R(T)` for an effective voltage \[V\]
    /// (zero where `R(T) <= 0`: never a heat sink, never infinite).
    pub fn power_w(&self, drive: Drive, temp_c: f64, input: f64) -> f64 {
        let r = self.at_c(temp_c);
        match drive {
            Drive::Current => r * input * input,
            Drive::Voltage if r > 0.0 => input * input / r,
            Drive::Voltage => 0.0,
        }
    }

    /// `true` when both coefficients are finite and the resistance is positive
    /// at `temp_c`.
    pub fn is_valid_at(&self, temp_c: f64) -> bool {
        self.r_at_0c_ohm.is_finite()
            && self.slope_ohm_per_k.is_finite()
            && self.r_at_0c_ohm + self.slope_ohm_per_k * temp_c > 0.0
    }

    /// The coefficients in a stepper's scalar type.
    pub fn to_scalar<S: Scalar>(&self) -> ScalarResistance<S> {
        ScalarResistance {
            r_at_0c_ohm: S::from_f64(self.r_at_0c_ohm),
            slope_ohm_per_k: S::from_f64(self.slope_ohm_per_k),
        }
    }
}

/// [`Resistance`] in a stepper's scalar type, for the per-tick Joule power.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarResistance<S> {
    /// Resistance extrapolated to 0 degC \[ohm\].
    pub r_at_0c_ohm: S,
    /// Slope dR/dT \[ohm/K\].
    pub slope_ohm_per_k: S,
}

impl<S: Scalar> ScalarResistance<S> {
    /// Joule power `R(T) I^2` \[W\] at winding temperature `temp_c`, with the
    /// resistance floored at zero so that an absurdly cold estimate can never
    /// make a coil a heat sink.
    #[inline]
    pub fn joule_power_w(&self, temp_c: S, current_a: S) -> S {
        self.resistance_ohm(temp_c) * current_a * current_a
    }

    /// The resistance `R(T)` \[ohm\] at winding temperature `temp_c`
    /// \[degC\], floored at zero as in [`joule_power_w`](Self::joule_power_w):
    /// times a mean square current \[A^2\], the mean Joule power of a
    /// step whose current varied.
    #[inline]
    pub fn resistance_ohm(&self, temp_c: S) -> S {
        floor_at_zero(self.r_at_0c_ohm + self.slope_ohm_per_k * temp_c)
    }
}

/// `r` floored at zero, NaN to zero as `max(r, 0)` does: a compare, not a
/// call (on a core without an FPU, `fmaxf` is one per winding and step).
#[inline(always)]
fn floor_at_zero<S: Scalar>(r: S) -> S {
    if r > S::ZERO {
        r
    } else {
        S::ZERO
    }
}

/// A winding's `R(T)` in an observer's deviation coordinates: the line
/// taken in `x = T - T_0` \[K\] about the origin `T_0` \[degC\] its state
/// is kept about, `R = R(T_0) + slope x`. `R(T_0)` is formed once, when
/// the observer is built, which spares a soft-float add per winding and
/// use (the Joule powers of every model step and correction) on a core
/// without an FPU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeviationResistance {
    /// Resistance at the origin `T_0` \[ohm\].
    pub r_at_origin_ohm: f32,
    /// Slope dR/dT \[ohm/K\].
    pub slope_ohm_per_k: f32,
}

impl DeviationResistance {
    /// The line `resistance` taken about the origin `origin_c` \[degC\].
    pub const fn about(resistance: &ScalarResistance<f32>, origin_c: f32) -> Self {
        Self {
            r_at_origin_ohm: resistance.r_at_0c_ohm + resistance.slope_ohm_per_k * origin_c,
            slope_ohm_per_k: resistance.slope_ohm_per_k,
        }
    }

    /// The line's value \[ohm\] at the deviation `dev_k` \[K\] from the
    /// origin, not floored (NaN in, NaN out), but for a constant
    /// resistance (a zero slope: a resistor, a loss carried through 1 ohm),
    /// which is `R(T_0)` at any deviation.
    #[inline]
    pub fn line_ohm(&self, dev_k: f32) -> f32 {
        // A zero slope (either sign), tested on its bits: on a core without
        // an FPU the multiply-add it spares is two soft-float calls.
        if self.slope_ohm_per_k.to_bits() << 1 == 0 {
            return self.r_at_origin_ohm;
        }
        self.r_at_origin_ohm + self.slope_ohm_per_k * dev_k
    }

    /// `R` \[ohm\] at the deviation `dev_k` \[K\], floored at zero as
    /// [`ScalarResistance::resistance_ohm`] is (NaN to zero): times a
    /// mean square current \[A^2\], a step's mean Joule power \[W\].
    #[inline]
    pub fn resistance_ohm(&self, dev_k: f32) -> f32 {
        floor_at_zero(self.line_ohm(dev_k))
    }

    /// The current \[A\] a winding at the deviation `dev_k` \[K\] draws
    /// under the effective voltage `v_eff` \[V\]: `V_eff / R`, so that
    /// its Joule power is `V_eff^2 / R`. NaN where `R <= 0` or the result
    /// is not finite (the observer then holds its last valid current).
    #[inline]
    pub fn current_for_voltage_a(&self, dev_k: f32, v_eff: f32) -> f32 {
        let r = self.line_ohm(dev_k);
        let i = v_eff / r;
        if r > 0.0 && i.is_finite() {
            i
        } else {
            f32::NAN
        }
    }
}

/// One input heating one node: `P = R(T_node) I^2` for a current drive,
/// `P = V_eff^2 / R(T_node)` for a voltage drive.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct JouleSource {
    /// The state node the winding heats.
    pub node: usize,
    /// The winding's resistance model.
    pub resistance: Resistance,
    /// What the input is: a current or an effective voltage.
    pub drive: Drive,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_reference_forms_reduce_to_the_same_line() {
        // HPPA: a T + b, about 5.69 ohm at 20 degC.
        assert!((Resistance::HPPA_COIL.at_c(20.0) - 5.686).abs() < 1e-12);
        assert!((Resistance::HPPA_COIL.at_c(50.0) - 6.466).abs() < 1e-12);
        // Omnimagnet solenoid 1: R0 = 3.2 ohm at 293.15 K, alpha0 = 0.0039.
        let r = Resistance::with_alpha(3.2, 0.0039, 20.0);
        assert!((r.at_c(20.0) - 3.2).abs() < 1e-12);
        assert!((r.at_c(120.0) - 3.2 * (1.0 + 0.39)).abs() < 1e-12);
        assert!((r.temp_c_at(r.at_c(87.5)).unwrap() - 87.5).abs() < 1e-9);
        assert_eq!(Resistance::constant(2.0).temp_c_at(2.0), None);
    }

    #[test]
    fn joule_power_in_every_scalar() {
        let r = Resistance::HPPA_COIL;
        let want = r.at_c(60.0) * 0.7 * 0.7;
        let f = r.to_scalar::<f32>().joule_power_w(60.0, 0.7) as f64;
        let q = r
            .to_scalar::<crate::Q32>()
            .joule_power_w(crate::Q32::from_f64(60.0), crate::Q32::from_f64(0.7))
            .to_f64();
        assert!((f - want).abs() < 1e-5);
        assert!((q - want).abs() < 1e-7);
        // Never a heat sink, however cold the estimate; a NaN estimate
        // floors to zero as `max(R, 0)` would.
        assert_eq!(r.to_scalar::<f64>().joule_power_w(-1000.0, 1.0), 0.0);
        assert_eq!(r.to_scalar::<f32>().resistance_ohm(f32::NAN), 0.0);
        assert_eq!(r.to_scalar::<f32>().resistance_ohm(-1000.0), 0.0);
    }

    /// About an origin, the line gives the `f64` line's `R` at `origin +
    /// deviation` (to `f32` rounding), floored at zero (NaN too), and
    /// the voltage drive's current `V / R` where `R > 0` only.
    #[test]
    fn a_line_about_an_origin_is_the_same_line() {
        let r = Resistance::with_alpha(3.2, 0.0039, 20.0);
        for origin_c in [-20.0f32, 20.0, 61.5] {
            let about = DeviationResistance::about(&r.to_scalar::<f32>(), origin_c);
            for dev_k in [-40.0f32, 0.0, 0.37, 150.0] {
                let want = r.at_c(f64::from(origin_c) + f64::from(dev_k));
                let got = f64::from(about.resistance_ohm(dev_k));
                assert!((got - want).abs() < 2e-6 * want, "{origin_c} {dev_k}");
                let i = f64::from(about.current_for_voltage_a(dev_k, 12.0));
                assert!((i - 12.0 / want).abs() < 2e-6 * i, "{origin_c} {dev_k}");
            }
            // Below the line's zero: no resistance, no current.
            assert_eq!(about.resistance_ohm(-1000.0 - origin_c), 0.0);
            assert!(about
                .current_for_voltage_a(-1000.0 - origin_c, 12.0)
                .is_nan());
            assert_eq!(about.resistance_ohm(f32::NAN), 0.0);
            assert!(about.current_for_voltage_a(f32::NAN, 12.0).is_nan());
        }
        // A constant resistance (a loss carried through 1 ohm) is 1 ohm at
        // any deviation, even one no temperature has.
        let loss = DeviationResistance::about(&Resistance::constant(1.0).to_scalar::<f32>(), 40.0);
        for dev_k in [-1e4f32, 0.0, 37.5, f32::INFINITY, f32::NAN] {
            assert_eq!(loss.resistance_ohm(dev_k), 1.0, "{dev_k}");
            assert_eq!(loss.current_for_voltage_a(dev_k, 3.0), 3.0, "{dev_k}");
        }
    }
}
