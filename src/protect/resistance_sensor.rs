//! A winding's resistance as a virtual temperature sensor, and a drift check.
//!
//! # The reading
//!
//! With `R(T) = r0 + s T` (`s > 0`), a coil whose drive knows its voltage `V`
//! and current `I` measures its own *mean* winding temperature
//! (solenoid-layers-runaway.md, "Calibration without knowing the
//! conductivity"):
//!
//! ```text
//! R = V / I,   T = (R - r0) / s
//! ```
//!
//! `V` must be the resistive drop: sample it where `dI/dt` is small, or
//! subtract `L dI/dt`. The noise follows by first-order propagation of
//! independent voltage and current noise (standard deviations `sigma_V`,
//! `sigma_I`):
//!
//! ```text
//! var(R) = (sigma_V^2 + R^2 sigma_I^2) / I^2,   var(T) = var(R) / s^2
//! ```
//!
//! so it grows as `1 / I^2`: below `min_current_a` there is no reading
//! (`None`, "predict only"). The reading's `variance_k2` is the measurement
//! variance `r` for a Kalman filter, whose measurement row for it is the
//! winding's mean (the coil node of a lumped model, the resistance-weighted
//! layer average of a layered one). It is the mean, not the hot spot:
//! protection must still act on the modelled hot spot.
//!
//! # The drift check
//!
//! Degrading conductivity (epoxy cracked by thermal cycling, the note's
//! warning) makes the real winding hotter than its model at the same current.
//! [`DriftState::update`] keeps an exponentially weighted mean of the
//! residual `T_reading - T_model` over the readings, with time constant
//! `window_s`, and flags the coil when the mean's magnitude has stayed above
//! `threshold_k` for `hold_s`; the flag clears when it falls below half the
//! threshold. `T_model` must not have seen the reading: use the open-loop
//! model or the filter's prediction *before* its update, since a filter that
//! fused the reading would pull its estimate onto it. With white reading noise
//! of variance `r`, the mean's noise has variance `r beta / (2 - beta)`
//! (`beta` the weight per reading): keep `threshold_k` several of its
//! standard deviations.
//!
//! Everything here is `f32`, O(1), allocation-free and panic-free.

use crate::error::{check, BuildError};
use crate::network::Resistance;

/// The winding's mean temperature, from its resistance.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MeanTemperatureReading {
    /// Mean winding temperature \[degC\].
    pub temp_c: f32,
    /// Its variance \[K^2\]: the measurement noise for a Kalman filter.
    pub variance_k2: f32,
    /// The measured resistance \[ohm\].
    pub resistance_ohm: f32,
}

/// The virtual sensor's configuration: the winding's `R(T)` and the noise of
/// the voltage and current it reads.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ResistanceSensor {
    r_at_0c_ohm: f32,
    slope_ohm_per_k: f32,
    voltage_var_v2: f32,
    current_var_a2: f32,
    min_current_a: f32,
}

impl ResistanceSensor {
    /// A sensor for a winding with resistance `resistance` (slope > 0),
    /// voltage noise `voltage_std_v` \[V\] and current noise `current_std_a`
    /// \[A\] (standard deviations, finite, >= 0), reading only at
    /// `|I| >= min_current_a` \[A\] (finite, > 0).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the parameter.
    pub fn new(
        resistance: Resistance,
        voltage_std_v: f64,
        current_std_a: f64,
        min_current_a: f64,
    ) -> Result<Self, BuildError> {
        check(
            resistance.r_at_0c_ohm.is_finite()
                && resistance.slope_ohm_per_k.is_finite()
                && resistance.slope_ohm_per_k > 0.0,
            "resistance",
        )?;
        check(
            voltage_std_v.is_finite() && voltage_std_v >= 0.0,
            "voltage_std_v",
        )?;
        check(
            current_std_a.is_finite() && current_std_a >= 0.0,
            "current_std_a",
        )?;
        check(
            min_current_a.is_finite() && min_current_a > 0.0,
            "min_current_a",
        )?;
        Ok(Self {
            r_at_0c_ohm: resistance.r_at_0c_ohm as f32,
            slope_ohm_per_k: resistance.slope_ohm_per_k as f32,
            voltage_var_v2: (voltage_std_v * voltage_std_v) as f32,
            current_var_a2: (current_std_a * current_std_a) as f32,
            min_current_a: min_current_a as f32,
        })
    }

    /// The smallest current \[A\] that gives a reading.
    pub fn min_current_a(&self) -> f32 {
        self.min_current_a
    }

    /// The mean winding temperature from the resistive voltage `voltage_v`
    /// \[V\] and current `current_a` \[A\]; `None` below the minimum current,
    /// for non-finite inputs, or for a non-positive resistance (wrong sign:
    /// not a resistive drop).
    #[inline]
    pub fn read(&self, voltage_v: f32, current_a: f32) -> Option<MeanTemperatureReading> {
        if !(voltage_v.is_finite() && current_a.abs() >= self.min_current_a) {
            return None;
        }
        let resistance_ohm = voltage_v / current_a;
        if !(resistance_ohm > 0.0 && resistance_ohm.is_finite()) {
            return None;
        }
        let temp_c = (resistance_ohm - self.r_at_0c_ohm) / self.slope_ohm_per_k;
        let variance_r = (self.voltage_var_v2
            + resistance_ohm * resistance_ohm * self.current_var_a2)
            / (current_a * current_a);
        let variance_k2 = variance_r / (self.slope_ohm_per_k * self.slope_ohm_per_k);
        (temp_c.is_finite() && variance_k2.is_finite()).then_some(MeanTemperatureReading {
            temp_c,
            variance_k2,
            resistance_ohm,
        })
    }
}

/// The drift check's configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriftConfig {
    weight: f32,
    threshold_k: f32,
    hold_readings: u32,
}

impl DriftConfig {
    /// Readings arrive every `reading_period_s` \[s\]; the residual is
    /// averaged over about `window_s` \[s\] (`>= reading_period_s`); the flag
    /// rises once the mean residual's magnitude has exceeded `threshold_k`
    /// \[K\] (> 0) for `hold_s` \[s\] (>= 0). All finite.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the parameter.
    pub fn new(
        reading_period_s: f64,
        window_s: f64,
        threshold_k: f64,
        hold_s: f64,
    ) -> Result<Self, BuildError> {
        check(
            reading_period_s.is_finite() && reading_period_s > 0.0,
            "reading_period_s",
        )?;
        check(
            window_s.is_finite() && window_s >= reading_period_s,
            "window_s",
        )?;
        check(threshold_k.is_finite() && threshold_k > 0.0, "threshold_k")?;
        check(hold_s.is_finite() && hold_s >= 0.0, "hold_s")?;
        let hold = libm::ceil(hold_s / reading_period_s);
        check(hold < u32::MAX as f64, "hold_s")?;
        Ok(Self {
            weight: (reading_period_s / window_s) as f32,
            threshold_k: threshold_k as f32,
            hold_readings: hold as u32,
        })
    }

    /// The weight of each new residual in the mean (dimensionless).
    pub fn weight(&self) -> f32 {
        self.weight
    }
}

/// What the drift check concluded after a reading.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriftStatus {
    /// Exponentially weighted mean of `T_reading - T_model` \[K\]; positive:
    /// the winding is hotter than modelled.
    pub mean_residual_k: f32,
    /// The mismatch has exceeded the threshold for the hold time.
    pub flagged: bool,
}

/// The drift check's per-coil state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriftState {
    status: DriftStatus,
    primed: bool,
    over: u32,
}

impl DriftState {
    /// Folds in one reading (`None`: no reading this time, nothing changes)
    /// against the model's mean winding temperature `model_mean_c` \[degC\].
    /// A non-finite model temperature is skipped like a missing reading.
    #[inline]
    pub fn update(
        &mut self,
        config: &DriftConfig,
        reading: Option<MeanTemperatureReading>,
        model_mean_c: f32,
    ) -> DriftStatus {
        let Some(reading) = reading else {
            return self.status;
        };
        let residual = reading.temp_c - model_mean_c;
        if !residual.is_finite() {
            return self.status;
        }
        let mean = &mut self.status.mean_residual_k;
        if self.primed {
            *mean += config.weight * (residual - *mean);
        } else {
            *mean = residual;
            self.primed = true;
        }
        let magnitude = mean.abs();
        if magnitude > config.threshold_k {
            self.over = self.over.saturating_add(1);
            if self.over > config.hold_readings {
                self.status.flagged = true;
            }
        } else {
            self.over = 0;
            if magnitude < 0.5 * config.threshold_k {
                self.status.flagged = false;
            }
        }
        self.status
    }

    /// The status after the last reading.
    pub fn status(&self) -> DriftStatus {
        self.status
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::Network;

    /// xorshift64* and Box-Muller: seeded Gaussian noise without a dependency.
    struct Rng(u64);
    impl Rng {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }
        fn gauss(&mut self) -> f64 {
            let (u, v) = (self.uniform(), self.uniform());
            libm::sqrt(-2.0 * libm::log(u)) * libm::cos(2.0 * core::f64::consts::PI * v)
        }
    }

    #[test]
    fn reading_inverts_the_resistance_model() {
        let r = Resistance::with_alpha(3.2, 0.0039, 20.0);
        let sensor = ResistanceSensor::new(r, 0.0, 0.0, 0.5).unwrap();
        for (t, i) in [(20.0, 3.0), (87.5, -2.0), (140.0, 0.5), (-10.0, 40.0)] {
            let v = r.at_c(t) * i;
            let reading = sensor.read(v as f32, i as f32).unwrap();
            assert!(
                (reading.temp_c as f64 - t).abs() < 2e-3,
                "{t}: {}",
                reading.temp_c
            );
            assert_eq!(reading.variance_k2, 0.0);
        }
        assert_eq!(sensor.read(1.0, 0.49), None);
        assert_eq!(sensor.read(f32::NAN, 2.0), None);
        assert_eq!(sensor.read(-3.0, 2.0), None, "negative resistance");
        assert!(ResistanceSensor::new(Resistance::constant(3.0), 0.0, 0.0, 1.0).is_err());
        assert!(ResistanceSensor::new(r, -1.0, 0.0, 1.0).is_err());
        assert!(ResistanceSensor::new(r, 0.0, 0.0, 0.0).is_err());
    }

    #[test]
    fn variance_matches_monte_carlo() {
        let r = Resistance::HPPA_COIL;
        let (sigma_v, sigma_i) = (5e-3, 1e-3);
        let sensor = ResistanceSensor::new(r, sigma_v, sigma_i, 0.1).unwrap();
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        for (t, i) in [(40.0, 0.5), (80.0, 2.0)] {
            let v = r.at_c(t) * i;
            let predicted = sensor.read(v as f32, i as f32).unwrap().variance_k2 as f64;
            let n = 200_000;
            let (mut sum, mut sum2) = (0.0, 0.0);
            for _ in 0..n {
                let vn = v + sigma_v * rng.gauss();
                let i_n = i + sigma_i * rng.gauss();
                let temp = sensor.read(vn as f32, i_n as f32).unwrap().temp_c as f64;
                sum += temp;
                sum2 += temp * temp;
            }
            let mean = sum / n as f64;
            let variance = sum2 / n as f64 - mean * mean;
            // Sampling error of a variance from 2e5 samples: 0.3 %; f32 and
            // the second-order terms add less than that here.
            let ratio = variance / predicted;
            std::println!("{t} degC, {i} A: Monte Carlo / first-order variance = {ratio:.4}");
            assert!(
                (ratio - 1.0).abs() < 0.02,
                "at {t} degC, {i} A: ratio {ratio}"
            );
            assert!((mean - t).abs() < 0.05, "{mean}");
        }
    }

    /// A coil (node 0) on a base plate (node 1) cooled to the ambient;
    /// `base_g` is the coil-to-base conductance.
    fn coil(base_g: f64) -> Network<2, 1, 1> {
        Network::new([68.7, 400.0])
            .unwrap()
            .connect(0, 1, base_g)
            .unwrap()
            .connect_boundary(1, 0, 1.5)
            .unwrap()
            .connect_boundary(0, 0, 0.02)
            .unwrap()
            .joule_source(0, 0, Resistance::HPPA_COIL)
            .unwrap()
    }

    /// Runs a heating hour at 1.2 A with readings every second; returns
    /// whether (and after how many seconds) the check flagged.
    fn run_drift(true_base_g: f64, seed: u64) -> (Option<usize>, f32) {
        let model = coil(0.35);
        let truth = coil(true_base_g);
        let (sigma_v, sigma_i) = (0.01, 2e-3);
        let sensor = ResistanceSensor::new(Resistance::HPPA_COIL, sigma_v, sigma_i, 0.2).unwrap();
        let config = DriftConfig::new(1.0, 120.0, 3.0, 60.0).unwrap();
        let mut state = DriftState::default();
        let mut rng = Rng(seed);
        let (mut t_model, mut t_true) = ([20.0; 2], [20.0; 2]);
        let current = 1.2;
        let mut flagged_at = None;
        for second in 0..3600 {
            for _ in 0..10 {
                let dm = model.derivative_k_per_s(&t_model, &[current], &[20.0]);
                let dt = truth.derivative_k_per_s(&t_true, &[current], &[20.0]);
                for n in 0..2 {
                    t_model[n] += 0.1 * dm[n];
                    t_true[n] += 0.1 * dt[n];
                }
            }
            let v = Resistance::HPPA_COIL.at_c(t_true[0]) * current + sigma_v * rng.gauss();
            let i = current + sigma_i * rng.gauss();
            let status = state.update(&config, sensor.read(v as f32, i as f32), t_model[0] as f32);
            if status.flagged && flagged_at.is_none() {
                flagged_at = Some(second);
            }
        }
        (flagged_at, state.status().mean_residual_k)
    }

    #[test]
    fn drift_check_flags_a_degraded_coil_and_not_a_healthy_one() {
        for seed in 1..=5 {
            let (healthy, residual) = run_drift(0.35, seed);
            assert_eq!(healthy, None, "seed {seed}: residual {residual}");
            assert!(residual.abs() < 1.5, "{residual}");
            // 30 % less conductance from the coil to its base.
            let (degraded, residual) = run_drift(0.7 * 0.35, seed);
            std::println!("seed {seed}: degraded coil flagged after {degraded:?} s, mean residual {residual:.2} K");
            assert!(degraded.is_some(), "seed {seed}: residual {residual}");
            assert!(residual > 3.0);
        }
    }

    #[test]
    fn drift_config_is_validated() {
        assert!(DriftConfig::new(0.0, 10.0, 1.0, 1.0).is_err());
        assert!(DriftConfig::new(1.0, 0.5, 1.0, 1.0).is_err());
        assert!(DriftConfig::new(1.0, 10.0, 0.0, 1.0).is_err());
        assert!(DriftConfig::new(1.0, 10.0, 1.0, f64::NAN).is_err());
        let mut state = DriftState::default();
        let config = DriftConfig::new(1.0, 10.0, 1.0, 0.0).unwrap();
        // Missing readings and NaN model temperatures change nothing.
        assert_eq!(state.update(&config, None, 20.0), DriftStatus::default());
        let reading = MeanTemperatureReading {
            temp_c: 25.0,
            variance_k2: 0.1,
            resistance_ohm: 6.0,
        };
        assert_eq!(
            state.update(&config, Some(reading), f32::NAN),
            DriftStatus::default()
        );
        assert!(state.update(&config, Some(reading), 20.0).flagged);
    }
}
