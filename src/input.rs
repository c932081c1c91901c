//! What the per-tick path does with bad input.
//!
//! Every stepper takes its inputs (coil currents, boundary temperatures) raw
//! from the controller and passes each through [`InputLimits`] first. Nothing
//! here panics or errs: a bad value is replaced by a safe one, and the
//! returned [`InputFlags`] say which rule fired, so the caller can log it or
//! raise an alarm. The rules, chosen so that a bad input never makes the model
//! *cooler* than the truth:
//!
//! | input | bad when | what the step uses | flag |
//! |---|---|---|---|
//! | current \[A\] | NaN or infinite | the last valid current of that input (held) | [`InputFlags::CURRENT_NOT_FINITE`] |
//! | current \[A\] | `abs(I) > max_current_a` | `±max_current_a` (clamped, and held) | [`InputFlags::CURRENT_CLAMPED`] |
//! | temperature \[degC\] | NaN, infinite, or outside `[min_temp_c, max_temp_c]` | the last valid temperature (held) | [`InputFlags::TEMPERATURE_INVALID`] |
//!
//! Holding the last valid current, rather than assuming zero, keeps the heat
//! input of a coil whose current sensor dropped out. The observers apply
//! the rules on every tick, also on one that takes no model step (no
//! elapsed time, or an early tick): its bad inputs are flagged and its good
//! ones held, so the next step uses them.

//!
//! # Voltage-driven inputs
//!
//! A coil on a PWM duty `D` with a measured supply `V` (or a linear
//! voltage `V`, `D = 1`) and no current sensing gives a [`VoltageDrive`]
//! per tick instead of a current
//! ([`NetworkObserver::tick_voltage`](crate::observer::NetworkObserver::tick_voltage)).
//! Its rules, checked before the drive becomes a current, again chosen so
//! that a bad drive never makes the model cooler than the truth:
//!
//! | input | bad when | what the step uses | flag |
//! |---|---|---|---|
//! | duty | NaN, infinite or negative | the last valid current of that input (held) | [`DriveFlags::DUTY_INVALID`] (and [`InputFlags::CURRENT_NOT_FINITE`]) |
//! | duty | above 1 | 1 (full on: no drive applies more) | [`DriveFlags::DUTY_CLAMPED`] |
//! | supply \[V\] | NaN, infinite, zero or negative | the last valid current of that input (held) | [`DriveFlags::SUPPLY_INVALID`] (and [`InputFlags::CURRENT_NOT_FINITE`]) |
//!
//! A supply reading of zero is taken as a missing reading, not as a coil
//! switched off: a dead ADC channel reads zero, and taking it at its word
//! would let the model cool a coil that may still be driven. The drive's
//! limit for an invalid supply is a duty of zero (see
//! [`crate::protect::limiter::drive_limit`]).

use crate::scalar::Scalar;

/// The methods and `|` of a `u8` bit set of rules that fired.
macro_rules! flag_set {
    ($name:ident) => {
        impl $name {
            /// `true` when no rule fired.
            #[inline]
            pub const fn is_clean(self) -> bool {
                self.0 == 0
            }
            /// `true` when every flag in `other` is set in `self`.
            #[inline]
            pub const fn contains(self, other: Self) -> bool {
                self.0 & other.0 == other.0
            }
            /// The union of two flag sets.
            #[inline]
            #[must_use]
            pub const fn union(self, other: Self) -> Self {
                Self(self.0 | other.0)
            }
            /// Raw bits (for logging).
            #[inline]
            pub const fn bits(self) -> u8 {
                self.0
            }
        }

        impl core::ops::BitOr for $name {
            type Output = Self;
            fn bitor(self, rhs: Self) -> Self {
                self.union(rhs)
            }
        }

        impl core::ops::BitOrAssign for $name {
            fn bitor_assign(&mut self, rhs: Self) {
                *self = self.union(rhs);
            }
        }
    };
}

/// Bit set of the voltage-drive rules that fired during one tick (see
/// "Voltage-driven inputs" above).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveFlags(u8);

impl DriveFlags {
    /// Every drive was used as given.
    pub const NONE: Self = Self(0);
    /// A duty was NaN, infinite or negative: the input's last valid
    /// current was held.
    pub const DUTY_INVALID: Self = Self(1);
    /// A duty above 1 was taken as 1.
    pub const DUTY_CLAMPED: Self = Self(2);
    /// A supply reading was NaN, infinite, zero or negative: the input's
    /// last valid current was held, and its duty limit is zero.
    pub const SUPPLY_INVALID: Self = Self(4);
    /// The winding's resistance at the estimate was not positive or the
    /// current it gives not finite (a corrupted estimate): the last valid
    /// current was held.
    pub const RESISTANCE_INVALID: Self = Self(8);
}

flag_set!(DriveFlags);

/// One tick's drive of a voltage-driven winding: a PWM duty on a measured
/// supply, or a linear voltage (`duty = 1`, `supply_v` the voltage).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct VoltageDrive {
    /// PWM duty in `[0, 1]` (dimensionless).
    pub duty: f32,
    /// Measured supply (or applied) voltage \[V\], > 0. A bipolar linear
    /// drive gives its magnitude: heat goes with `V^2`.
    pub supply_v: f32,
}

impl VoltageDrive {
    /// A PWM duty `duty` in `[0, 1]` on a supply of `supply_v` \[V\].
    pub const fn pwm(duty: f32, supply_v: f32) -> Self {
        Self { duty, supply_v }
    }

    /// A linear voltage `voltage_v` \[V\] (duty 1).
    pub const fn linear(voltage_v: f32) -> Self {
        Self {
            duty: 1.0,
            supply_v: voltage_v,
        }
    }

    /// The effective voltage `sqrt(D) V` \[V\] (the voltage whose square
    /// is the mean `D V^2` a PWM drive puts across the winding), after the
    /// rules of "Voltage-driven inputs": NaN for a drive whose current
    /// must be held, with the rules that fired. Panic-free for any input.
    #[inline]
    pub fn effective_v(&self) -> (f32, DriveFlags) {
        let mut flags = DriveFlags::NONE;
        let duty = if !(self.duty.is_finite() && self.duty >= 0.0) {
            flags |= DriveFlags::DUTY_INVALID;
            f32::NAN
        } else if self.duty > 1.0 {
            flags |= DriveFlags::DUTY_CLAMPED;
            1.0
        } else {
            self.duty
        };
        if !(self.supply_v.is_finite() && self.supply_v > 0.0) {
            flags |= DriveFlags::SUPPLY_INVALID;
            return (f32::NAN, flags);
        }
        (libm::sqrtf(duty) * self.supply_v, flags)
    }
}

/// Bit set of the input rules that fired during one step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InputFlags(u8);

impl InputFlags {
    /// No rule fired: every input was used as given.
    pub const NONE: Self = Self(0);
    /// At least one current was NaN or infinite; its last valid value was used.
    pub const CURRENT_NOT_FINITE: Self = Self(1);
    /// At least one current exceeded `max_current_a` and was clamped.
    pub const CURRENT_CLAMPED: Self = Self(2);
    /// At least one boundary temperature was invalid; its last valid value was used.
    pub const TEMPERATURE_INVALID: Self = Self(4);
    /// The elapsed time was invalid (NaN, negative, or beyond the allowed
    /// catch-up) and was replaced as documented by the stepper.
    pub const ELAPSED_INVALID: Self = Self(8);
    /// The clock has given no elapsed time for the configured number of
    /// consecutive ticks (see [`crate::observer::clock`]): the model is
    /// standing still.
    pub const CLOCK_FROZEN: Self = Self(16);
    /// Every reading of this tick's correction was colder than the physics
    /// allows (a common-mode sensor fault, see
    /// [`NetworkObserver`](crate::observer::NetworkObserver)'s "Sensors
    /// against the physics"): none was fused, and the estimate was raised
    /// to the model's.
    pub const SENSORS_COLDER_THAN_PHYSICS: Self = Self(32);
    /// A heat-input bias the filter estimated at this tick's correction is
    /// beyond what the model's uncertainty allows (see the observers'
    /// "Sensors against the physics"): a sensor drags the estimate, or the
    /// device gets heat (or loses it) the model does not know. An alarm
    /// for the engineer; the estimate is left as it is.
    pub const HEAT_BIAS_BEYOND_MODEL: Self = Self(64);
    /// The model refresh the configuration declares
    /// ([`OmniSettings::model_refresh_s`](crate::observer::OmniSettings::model_refresh_s))
    /// has not happened for
    /// [`MODEL_STALE_PERIODS`](crate::observer::omnimagnet::MODEL_STALE_PERIODS)
    /// refresh periods of model time: the background task that
    /// re-linearises the model is dead or starved. Set on every tick until
    /// the next `install_model`; meanwhile the protection acts on the hotter
    /// of the estimate's and the unfused shadow's upper bounds, as for a
    /// sensor in doubt.
    pub const MODEL_STALE: Self = Self(128);
}

flag_set!(InputFlags);

/// The plausible range of each input, fixed when a stepper is built.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct InputLimits {
    /// Largest plausible current magnitude \[A\] (the amplifier's limit).
    pub max_current_a: f64,
    /// Lowest plausible boundary temperature \[degC\].
    pub min_temp_c: f64,
    /// Highest plausible boundary temperature \[degC\].
    pub max_temp_c: f64,
}

impl Default for InputLimits {
    /// 100 A, -60 .. 400 degC: wide enough for any coil in the references.
    fn default() -> Self {
        Self {
            max_current_a: 100.0,
            min_temp_c: -60.0,
            max_temp_c: 400.0,
        }
    }
}

impl InputLimits {
    /// Checks that the limits themselves make sense.
    pub fn validate(&self) -> Result<(), crate::BuildError> {
        let ok_current = self.max_current_a.is_finite() && self.max_current_a > 0.0;
        let ok_temps = self.min_temp_c.is_finite()
            && self.max_temp_c.is_finite()
            && self.min_temp_c < self.max_temp_c;
        if !ok_current {
            return Err(crate::BuildError::InvalidParameter {
                name: "max_current_a",
            });
        }
        if !ok_temps {
            return Err(crate::BuildError::InvalidParameter {
                name: "min_temp_c/max_temp_c",
            });
        }
        Ok(())
    }

    /// The same limits converted once to the stepper's scalar.
    pub fn to_scalar<S: Scalar>(&self) -> ScalarLimits<S> {
        ScalarLimits {
            max_current_a: S::from_f64(self.max_current_a),
            min_temp_c: S::from_f64(self.min_temp_c),
            max_temp_c: S::from_f64(self.max_temp_c),
        }
    }
}

/// [`InputLimits`] in the stepper's scalar type (built once, used per tick).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScalarLimits<S> {
    /// Largest plausible current magnitude \[A\].
    pub max_current_a: S,
    /// Lowest plausible boundary temperature \[degC\].
    pub min_temp_c: S,
    /// Highest plausible boundary temperature \[degC\].
    pub max_temp_c: S,
}

impl<S: Scalar> ScalarLimits<S> {
    /// Applies the current rule to one input: updates `held` (the value the
    /// step will use) from `incoming`, and says which rule fired.
    #[inline]
    pub fn accept_current(&self, incoming_a: S, held_a: &mut S) -> InputFlags {
        if !incoming_a.is_finite() {
            return InputFlags::CURRENT_NOT_FINITE;
        }
        let clamped = incoming_a.clamp_to(-self.max_current_a, self.max_current_a);
        *held_a = clamped;
        if clamped == incoming_a {
            InputFlags::NONE
        } else {
            InputFlags::CURRENT_CLAMPED
        }
    }

    /// Applies the temperature rule to one boundary input.
    #[inline]
    pub fn accept_temperature(&self, incoming_c: S, held_c: &mut S) -> InputFlags {
        let plausible = incoming_c.is_finite()
            && incoming_c >= self.min_temp_c
            && incoming_c <= self.max_temp_c;
        if plausible {
            *held_c = incoming_c;
            InputFlags::NONE
        } else {
            InputFlags::TEMPERATURE_INVALID
        }
    }

    /// Applies the current rule to each current of `incoming_a`, pairwise
    /// with `held_a` (of the same length: an array of the network's size,
    /// or a slice of a runtime-sized one).
    #[inline]
    pub fn accept_currents(&self, incoming_a: &[S], held_a: &mut [S]) -> InputFlags {
        let mut flags = InputFlags::NONE;
        for (incoming, held) in incoming_a.iter().zip(held_a.iter_mut()) {
            flags |= self.accept_current(*incoming, held);
        }
        flags
    }

    /// Applies the temperature rule to each temperature of `incoming_c`,
    /// pairwise with `held_c` (of the same length).
    #[inline]
    pub fn accept_temperatures(&self, incoming_c: &[S], held_c: &mut [S]) -> InputFlags {
        let mut flags = InputFlags::NONE;
        for (incoming, held) in incoming_c.iter().zip(held_c.iter_mut()) {
            flags |= self.accept_temperature(*incoming, held);
        }
        flags
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_currents_are_held_or_clamped_and_flagged() {
        let limits = InputLimits::default().to_scalar::<f32>();
        let mut held = 2.0f32;
        assert_eq!(
            limits.accept_current(f32::NAN, &mut held),
            InputFlags::CURRENT_NOT_FINITE
        );
        assert_eq!(held, 2.0);
        assert_eq!(
            limits.accept_current(f32::INFINITY, &mut held),
            InputFlags::CURRENT_NOT_FINITE
        );
        assert_eq!(held, 2.0);
        assert_eq!(
            limits.accept_current(-1e9, &mut held),
            InputFlags::CURRENT_CLAMPED
        );
        assert_eq!(held, -100.0);
        assert_eq!(limits.accept_current(3.5, &mut held), InputFlags::NONE);
        assert_eq!(held, 3.5);
    }

    #[test]
    fn implausible_temperatures_are_held_and_flagged() {
        let limits = InputLimits::default().to_scalar::<f64>();
        let mut held = [20.0, 25.0];
        let flags = limits.accept_temperatures(&[f64::NAN, 1e6], &mut held);
        assert!(flags.contains(InputFlags::TEMPERATURE_INVALID));
        assert_eq!(held, [20.0, 25.0]);
        assert!(limits
            .accept_temperatures(&[21.0, 24.0], &mut held)
            .is_clean());
        assert_eq!(held, [21.0, 24.0]);
    }

    #[test]
    fn bad_drives_are_flagged_and_give_no_voltage() {
        let ok = VoltageDrive::pwm(0.25, 24.0).effective_v();
        assert_eq!(ok, (12.0, DriveFlags::NONE));
        assert_eq!(
            VoltageDrive::linear(12.0).effective_v(),
            (12.0, DriveFlags::NONE)
        );
        let (v, f) = VoltageDrive::pwm(1.5, 24.0).effective_v();
        assert_eq!((v, f), (24.0, DriveFlags::DUTY_CLAMPED));
        for duty in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, -0.1] {
            let (v, f) = VoltageDrive::pwm(duty, 24.0).effective_v();
            assert!(v.is_nan() && f.contains(DriveFlags::DUTY_INVALID), "{duty}");
        }
        for supply in [f32::NAN, f32::INFINITY, 0.0, -24.0] {
            let (v, f) = VoltageDrive::pwm(0.5, supply).effective_v();
            assert!(
                v.is_nan() && f.contains(DriveFlags::SUPPLY_INVALID),
                "{supply}"
            );
        }
    }

    #[test]
    fn limits_are_validated() {
        let bad = InputLimits {
            max_current_a: f64::NAN,
            ..InputLimits::default()
        };
        assert!(bad.validate().is_err());
        let inverted = InputLimits {
            min_temp_c: 10.0,
            max_temp_c: 0.0,
            ..InputLimits::default()
        };
        assert!(inverted.validate().is_err());
        assert!(InputLimits::default().validate().is_ok());
    }
}
