//! The winding's own resistance as a sensor of a [`NetworkObserver`]: a
//! resistance measured through a source's winding (the drive's `V/I`, a DC
//! injection at standstill, a resistance observer) read as the temperature
//! its `R(T)` implies on the node that source heats.
//!
//! # The reading
//!
//! With `R(T) = r0 + s T` (`s > 0`, `r0` extrapolated to 0 degC), a
//! resistance `R` \[ohm\] is the *mean* winding temperature
//! (solenoid-layers-runaway.md, "Calibration without knowing the
//! conductivity"; [`crate::protect::resistance_sensor`]):
//!
//! ```text
//! T = (R - r0) / s
//! ```
//!
//! [`NetworkObserver::resistance_reading`] turns one measurement into the
//! [`TimedReading`] of that sensor's slot in
//! [`NetworkInputs::readings`](super::NetworkInputs), so from there on it is
//! a reading like a thermocouple's: the same age limit, consistency band
//! against the physics, stuck and drift screens, innovation gate,
//! [`SensorStatus`](crate::observer::SensorStatus) and fault campaign. The
//! tick itself is unchanged (a thermocouple-only tick pays nothing).
//!
//! * **Below [`ResistanceSensor::min_current_a`] there is no reading**
//!   (`None`: "predict only"): `V/I` noise grows as `1 / I^2`, and at
//!   zero current there is nothing to divide by.
//! * **A measurement that cannot be a winding's is a fault, never a
//!   temperature**: a resistance or current that is NaN or infinite
//!   ([`SensorFault::NotFinite`]), a resistance `<= 0` (not a resistive
//!   drop: a sign error, a short) or one that implies a temperature
//!   outside [`ResistanceSensor::range_c`] ([`SensorFault::OutOfRange`]:
//!   an open lead reads far too hot, a shorted turn or a wrong channel
//!   too cold).
//!
//! # Its noise
//!
//! A resistance measured to a relative standard deviation `f`
//! ([`ResistanceSensor::noise_fraction`], 0.01 for 1 %) is a temperature
//! to `f R(T) / s` \[K\]: 2.5 K at 20 degC and 3.3 K at 100 degC for copper
//! at 1 %, ten times a thermocouple's. The steady gain is solved with each
//! sensor's own noise (a thermocouple's is
//! [`NetworkSettings::sensor_sigma_k`](super::NetworkSettings::sensor_sigma_k)),
//! taken for the resistance at [`ResistanceSensor::noise_reference_c`]
//! (default 100 degC: a winding's working range; the gate then judges a
//! colder reading by a noise slightly wider than its own, the safe side).
//!
//! # Against the physics
//!
//! The screens that hold a reading against the unfused shadow model (see
//! "Sensors against the physics" in [`super`]: the band below which a
//! reading is colder than physics, the drift hold) were drawn for a
//! thermocouple's tenths of a kelvin. A resistance sensor's are taken
//! `sqrt(gate_threshold) sigma_k` lower (10.8 K for copper at 1 %, at the
//! default gate): without it, the band's fixed 3 K refuses a cold-side
//! share of the noise of every reading near the ambient (measured on
//! `drive-3node`: 38 of 3 600 readings refused, every one cold, which
//! biases the estimate hot). A resistance 10 % low (25-35 K cold) is
//! still far below the widened band.
//!
//! # Its `R(T)` must be measured
//!
//! The sensor's `R(T)` defaults to the source's, but a thermal model's
//! resistance may be a guess that calibration compensated elsewhere
//! (`drive-3node`'s is 4 % low, and its fitted capacities and conductances
//! 4 % low with it): read through it, a true resistance reads
//! `(1/alpha + T) * 4 %` hot, 10.6 K at 20 degC. Give the sensor the
//! winding's measured `R(T)` ([`ResistanceSensor::measured`]: an ohmmeter
//! on the cold winding at a known temperature, with the material's
//! `alpha`). Measured on `drive-3node` (`host-tests/tests/resistance_sensor.rs`).
//!
//! # In flash
//!
//! The sensor kinds are a table of their own ([`SensorKind`] per sensor),
//! beside [`NetworkParts`](super::NetworkParts): an observer with resistance
//! sensors is assembled by [`NetworkObserver::from_parts_with_sensors`];
//! [`NetworkObserver::from_parts`] is every sensor a thermocouple (what a
//! generated module of a thermocouple-only model calls, its tables
//! unchanged), and refuses tables solved with another sensor noise.

use nalgebra::DefaultAllocator;

use crate::error::{check, BuildError};
use crate::network::{Network, Resistance};
use crate::observer::vocabulary::TimedReading;
use crate::sensors::{Reading, SensorFault, SensorResult};
use crate::sizes::{Length, Sizes};

#[cfg(any(doc, test))]
use super::NetworkObserver;
use super::{NetworkObserverOf, ObserverAllocator};

/// The temperature \[degC\] at which a resistance sensor's relative noise
/// is turned into kelvin for the steady gain, by default.
pub const DEFAULT_NOISE_REFERENCE_C: f64 = 100.0;

/// The temperatures \[degC\] a winding's resistance may imply by default:
/// colder or hotter is a fault (see the module docs).
pub const DEFAULT_RANGE_C: (f64, f64) = (-60.0, 300.0);

/// What one sensor of a [`NetworkObserver`] is.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorKind {
    /// A thermocouple (or any sensor read as a temperature) on its node,
    /// of noise [`NetworkSettings::sensor_sigma_k`](super::NetworkSettings::sensor_sigma_k).
    #[default]
    Thermocouple,
    /// A source's winding resistance (see the module docs).
    Resistance(ResistanceSensor),
}

impl SensorKind {
    /// Every sensor a thermocouple.
    pub const fn thermocouples<const P: usize>() -> [SensorKind; P] {
        [SensorKind::Thermocouple; P]
    }

    /// The resistance sensor, if this is one.
    pub fn resistance(&self) -> Option<&ResistanceSensor> {
        match self {
            Self::Thermocouple => None,
            Self::Resistance(r) => Some(r),
        }
    }
}

/// A source's winding resistance read as its node's temperature (see the
/// module docs). Plain `f64` data, so a generated module holds it as a
/// `const`; checked when the observer is built or assembled.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ResistanceSensor {
    /// The source (current input) whose winding is measured.
    pub source: usize,
    /// The node that source heats: the node the reading is of.
    pub node: usize,
    /// The winding's resistance extrapolated to 0 degC \[ohm\].
    pub r_at_0c_ohm: f64,
    /// The winding's `dR/dT` \[ohm/K\] (`> 0`).
    pub slope_ohm_per_k: f64,
    /// The resistance's relative standard deviation (dimensionless, `> 0`;
    /// 0.01 for 1 %).
    pub noise_fraction: f64,
    /// The temperature \[degC\] at which `noise_fraction` is taken in
    /// kelvin for the steady gain ([`Self::sigma_k`]).
    pub noise_reference_c: f64,
    /// The least current magnitude \[A\] at which a resistance is a
    /// reading (`> 0`); below it [`NetworkObserver::resistance_reading`]
    /// gives none.
    pub min_current_a: f64,
    /// The coldest temperature a reading may imply \[degC\].
    pub min_c: f64,
    /// The hottest temperature a reading may imply \[degC\].
    pub max_c: f64,
}

impl ResistanceSensor {
    /// The resistance of `network`'s source `source` (its `R(T)`, its
    /// node), measured to a relative standard deviation `noise_fraction`
    /// (0.01 for 1 %), a reading only at `|I| >= min_current_a` \[A\].
    /// Noise reference [`DEFAULT_NOISE_REFERENCE_C`], range
    /// [`DEFAULT_RANGE_C`].
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the parameter (`source`: no
    /// such source, or its `R(T)` does not rise with temperature).
    pub fn of_source<const N: usize, const B: usize, const M: usize>(
        network: &Network<N, B, M>,
        source: usize,
        noise_fraction: f64,
        min_current_a: f64,
    ) -> Result<Self, BuildError> {
        let joule = network
            .source(source)
            .ok_or(BuildError::InvalidParameter { name: "source" })?;
        Self {
            source,
            node: joule.node,
            r_at_0c_ohm: joule.resistance.r_at_0c_ohm,
            slope_ohm_per_k: joule.resistance.slope_ohm_per_k,
            noise_fraction,
            noise_reference_c: DEFAULT_NOISE_REFERENCE_C,
            min_current_a,
            min_c: DEFAULT_RANGE_C.0,
            max_c: DEFAULT_RANGE_C.1,
        }
        .checked()
    }

    /// The same sensor reading through the winding's measured `R(T)`
    /// rather than the model's (see "Its `R(T)` must be measured").
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] (`resistance`) for a slope that is
    /// not positive or a non-finite value.
    pub fn measured(self, resistance: Resistance) -> Result<Self, BuildError> {
        Self {
            r_at_0c_ohm: resistance.r_at_0c_ohm,
            slope_ohm_per_k: resistance.slope_ohm_per_k,
            ..self
        }
        .checked()
    }

    /// The same sensor with the range of temperatures a reading may imply
    /// \[degC\] (`min_c < max_c`, finite).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] (`range_c`).
    pub fn range_c(self, min_c: f64, max_c: f64) -> Result<Self, BuildError> {
        Self {
            min_c,
            max_c,
            ..self
        }
        .checked()
    }

    /// The same sensor with its noise taken in kelvin at `temp_c` \[degC\].
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] (`noise_reference_c`).
    pub fn noise_reference_c(self, temp_c: f64) -> Result<Self, BuildError> {
        Self {
            noise_reference_c: temp_c,
            ..self
        }
        .checked()
    }

    /// The noise standard deviation \[K\] the steady gain is solved with:
    /// `noise_fraction R(noise_reference_c) / slope`.
    pub fn sigma_k(&self) -> f64 {
        let r = self.r_at_0c_ohm + self.slope_ohm_per_k * self.noise_reference_c;
        self.noise_fraction * r / self.slope_ohm_per_k
    }

    /// Validates every field (as the builder and
    /// [`NetworkObserver::from_parts_with_sensors`] do).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the field.
    pub fn checked(self) -> Result<Self, BuildError> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        check(
            self.r_at_0c_ohm.is_finite() && positive(self.slope_ohm_per_k),
            "resistance",
        )?;
        check(positive(self.noise_fraction), "noise_fraction")?;
        check(positive(self.min_current_a), "min_current_a")?;
        check(
            self.min_c.is_finite() && self.max_c.is_finite() && self.min_c < self.max_c,
            "range_c",
        )?;
        check(
            self.noise_reference_c.is_finite()
                && self.r_at_0c_ohm + self.slope_ohm_per_k * self.noise_reference_c > 0.0,
            "noise_reference_c",
        )?;
        // The range must imply positive resistances only, so that a
        // reading inside it is a resistive drop.
        check(
            self.r_at_0c_ohm + self.slope_ohm_per_k * self.min_c > 0.0,
            "range_c",
        )?;
        check(positive(self.sigma_k()), "noise_fraction")?;
        Ok(self)
    }

    /// The reading of `resistance_ohm` \[ohm\] measured at `current_a`
    /// \[A\], exactly as [`NetworkObserver::resistance_reading`] of an
    /// observer with this sensor gives it (the same `f32` conversion):
    /// `None` below [`Self::min_current_a`], a [`SensorFault`] for a
    /// measurement that cannot be the winding's (see the module docs).
    /// For a host tool that converts a recording's ohms as the MCU would;
    /// the firmware calls the observer's method, which holds the
    /// conversion ready. No panic.
    pub fn read(&self, resistance_ohm: f32, current_a: f32) -> Option<SensorResult> {
        self.conversion().read(resistance_ohm, current_a)
    }

    /// The conversion the tick-side call holds, in `f32`.
    pub(super) fn conversion(&self) -> Conversion {
        Conversion {
            r_at_0c_ohm: self.r_at_0c_ohm as f32,
            slope_ohm_per_k: self.slope_ohm_per_k as f32,
            min_current_a: self.min_current_a as f32,
            min_c: self.min_c as f32,
            max_c: self.max_c as f32,
        }
    }
}

/// A [`ResistanceSensor`] as the observer holds it (`f32`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Conversion {
    r_at_0c_ohm: f32,
    slope_ohm_per_k: f32,
    min_current_a: f32,
    min_c: f32,
    max_c: f32,
}

impl Conversion {
    /// The conversion as a row of the assembled tables
    /// ([`super::AssembledTables::resistance_sensors`]): `R(0 degC)`
    /// \[ohm\], `dR/dT` \[ohm/K\], the minimum current \[A\], the lowest and
    /// the highest reading \[degC\].
    pub(super) fn row(&self) -> [f32; 5] {
        [
            self.r_at_0c_ohm,
            self.slope_ohm_per_k,
            self.min_current_a,
            self.min_c,
            self.max_c,
        ]
    }

    /// The conversion of a [`Self::row`], copied (a `const fn`, for an
    /// observer assembled by the compiler).
    pub(super) const fn of_row(row: &[f32; 5]) -> Self {
        Self {
            r_at_0c_ohm: row[0],
            slope_ohm_per_k: row[1],
            min_current_a: row[2],
            min_c: row[3],
            max_c: row[4],
        }
    }

    /// The reading of `resistance_ohm` \[ohm\] measured at `current_a`
    /// \[A\]: `None` below the minimum current, a fault for anything that
    /// is not a winding's resistance (see the module docs). No panic, no
    /// branch on uninitialised data: every comparison is written so that
    /// NaN fails it.
    #[inline]
    pub(super) fn read(&self, resistance_ohm: f32, current_a: f32) -> Option<SensorResult> {
        if !(resistance_ohm.is_finite() && current_a.is_finite()) {
            return Some(Err(SensorFault::NotFinite));
        }
        if current_a.abs() < self.min_current_a {
            return None;
        }
        if resistance_ohm <= 0.0 {
            return Some(Err(SensorFault::OutOfRange));
        }
        let temp_c = (resistance_ohm - self.r_at_0c_ohm) / self.slope_ohm_per_k;
        if !temp_c.is_finite() {
            return Some(Err(SensorFault::NotFinite));
        }
        if !(temp_c >= self.min_c && temp_c <= self.max_c) {
            return Some(Err(SensorFault::OutOfRange));
        }
        // No cold junction: it repeats the temperature, as the resistive
        // sensors' readings do.
        Some(Ok(Reading::new(temp_c)))
    }
}

/// The resistance readings, written once for every size.
impl<Z: Sizes, X: Length, P: Length> NetworkObserverOf<Z, X, P>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    /// Sensor `sensor`'s reading from a winding resistance `resistance_ohm`
    /// \[ohm\] measured at current `current_a` \[A\] (the drive's `V/I`, a
    /// DC injection's current), sampled at `sampled_at_us` on the tick's
    /// clock \[us\]: put it in that sensor's slot of
    /// [`NetworkInputs::readings`](super::NetworkInputs).
    ///
    /// `None` (no reading, "predict only") when `|current_a|` is below the
    /// sensor's [`ResistanceSensor::min_current_a`], or when `sensor` is not
    /// a resistance sensor of this observer. A reading whose result is a
    /// [`SensorFault`] for a measurement that cannot be the winding's: NaN
    /// or infinite values, a resistance `<= 0`, a temperature outside the
    /// sensor's range (see the module docs). O(1), allocation-free and
    /// panic-free.
    pub fn resistance_reading(
        &self,
        sensor: usize,
        resistance_ohm: f32,
        current_a: f32,
        sampled_at_us: u32,
    ) -> Option<TimedReading> {
        let conversion = self.resistance_sensors.as_ref().get(sensor)?.as_ref()?;
        conversion
            .read(resistance_ohm, current_a)
            .map(|result| TimedReading {
                result,
                sampled_at_us,
            })
    }

    /// [`Self::resistance_reading`] of `R = voltage_v / current_a` from the
    /// winding's resistive voltage drop `voltage_v` \[V\] (sampled where
    /// `dI/dt` is small, or with `L dI/dt` taken off) and its current
    /// `current_a` \[A\].
    pub fn voltage_current_reading(
        &self,
        sensor: usize,
        voltage_v: f32,
        current_a: f32,
        sampled_at_us: u32,
    ) -> Option<TimedReading> {
        let conversion = self.resistance_sensors.as_ref().get(sensor)?.as_ref()?;
        // Below the minimum current the division is not attempted: no
        // reading rather than a huge or infinite resistance.
        if current_a.is_finite() && current_a.abs() < conversion.min_current_a {
            return None;
        }
        self.resistance_reading(sensor, voltage_v / current_a, current_a, sampled_at_us)
    }
}

/// The measurement noise variance \[K^2\] of each sensor: a thermocouple's
/// `sensor_sigma_k^2` (the very value every sensor had before sensor kinds
/// existed, so thermocouple-only tables are unchanged to the bit), a
/// resistance sensor's [`ResistanceSensor::sigma_k`] squared.
pub(super) fn sensor_variances_k2<P: Length>(
    kinds: &P::Array<SensorKind>,
    thermocouple_sigma_k: f64,
) -> P::Array<f64> {
    P::mapped(kinds, |kind| match kind {
        SensorKind::Thermocouple => thermocouple_sigma_k * thermocouple_sigma_k,
        SensorKind::Resistance(r) => {
            let sigma = r.sigma_k();
            sigma * sigma
        }
    })
}

/// Checks the kinds against the sensor map and the network's sources: a
/// resistance sensor reads its source's node.
pub(super) fn check_kinds(
    kinds: &[SensorKind],
    sensor_nodes: &[usize],
    source_node: &[usize],
) -> Result<(), BuildError> {
    for (kind, node) in kinds.iter().zip(sensor_nodes) {
        if let SensorKind::Resistance(r) = kind {
            let r = r.checked()?;
            if source_node.get(r.source) != Some(&r.node) || r.node != *node {
                return Err(BuildError::InvalidParameter {
                    name: "resistance_sensor",
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn copper() -> ResistanceSensor {
        let network: Network<2, 1, 1> = Network::new([60.0, 400.0])
            .and_then(|n| n.connect(0, 1, 0.8))
            .and_then(|n| n.connect_boundary(1, 0, 1.2))
            .and_then(|n| n.joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0)))
            .expect("a valid network");
        ResistanceSensor::of_source(&network, 0, 0.01, 0.5).expect("valid")
    }

    #[test]
    fn a_resistance_reads_the_temperature_its_r_of_t_implies() {
        let s = copper();
        let c = s.conversion();
        // R(T) = 1.2 (1 + 0.00393 (T - 20)): 60 degC is 1.388640 ohm.
        let r60 = (1.2 * (1.0 + 0.00393 * 40.0)) as f32;
        let Some(Ok(reading)) = c.read(r60, 2.0) else {
            panic!("a reading")
        };
        assert!((reading.temp_c - 60.0).abs() < 1e-3, "{reading:?}");
        // The noise: 1 % of R(100 degC) over the slope.
        let expected = 0.01 * (1.0 / 0.00393 + 80.0);
        assert!((s.sigma_k() - expected).abs() < 1e-9, "{}", s.sigma_k());
    }

    #[test]
    fn below_the_least_current_there_is_no_reading_and_nonsense_is_a_fault() {
        let c = copper().conversion();
        assert_eq!(c.read(1.3, 0.49), None);
        assert_eq!(c.read(1.3, -0.49), None);
        assert!(matches!(c.read(1.3, -0.5), Some(Ok(_))));
        assert_eq!(c.read(f32::NAN, 2.0), Some(Err(SensorFault::NotFinite)));
        assert_eq!(c.read(1.3, f32::NAN), Some(Err(SensorFault::NotFinite)));
        assert_eq!(
            c.read(f32::INFINITY, 2.0),
            Some(Err(SensorFault::NotFinite))
        );
        assert_eq!(c.read(0.0, 2.0), Some(Err(SensorFault::OutOfRange)));
        assert_eq!(c.read(-1.3, 2.0), Some(Err(SensorFault::OutOfRange)));
        // An open lead: twice the resistance, 274 degC... and ten times.
        assert_eq!(c.read(12.0, 2.0), Some(Err(SensorFault::OutOfRange)));
        assert_eq!(c.read(0.5, 2.0), Some(Err(SensorFault::OutOfRange)));
    }

    #[test]
    fn the_host_conversion_is_the_observers() {
        use super::super::NetworkObserverBuilder;
        let network: Network<2, 1, 1> = Network::new([60.0, 400.0])
            .and_then(|n| n.connect(0, 1, 0.8))
            .and_then(|n| n.connect_boundary(1, 0, 1.2))
            .and_then(|n| n.joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0)))
            .expect("a valid network");
        let sensor = copper();
        let observer: NetworkObserver<2, 1, 1, 3, 1> = NetworkObserverBuilder::new(&network, [1])
            .resistance_sensor(0, sensor)
            .build()
            .expect("builds");
        for (r, i) in [
            (1.3, 2.0),
            (1.388_64, -0.7),
            (1.2, 0.1),
            (0.0, 3.0),
            (f32::NAN, 1.0),
        ] {
            assert_eq!(
                sensor.read(r, i),
                observer.resistance_reading(0, r, i, 7).map(|t| t.result),
                "{r} ohm at {i} A"
            );
        }
    }

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            any::<u32>().prop_map(f32::from_bits),
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
            Just(0.0f32),
            Just(-0.0f32),
            Just(f32::MAX),
            Just(f32::MIN_POSITIVE),
            -1e3f32..1e3,
        ]
    }

    proptest! {
        /// NaN, infinite, extreme, negative resistances, currents and
        /// voltages at the reading path and through the tick: nothing
        /// panics, nothing below the least current is a reading, every
        /// measurement that cannot be a winding's is a fault, every
        /// temperature handed on is finite and in range, and the estimate
        /// stays finite.
        #[test]
        fn no_input_panics_and_every_bad_one_is_a_fault(
            inputs in proptest::collection::vec((any_f32(), any_f32(), any_f32()), 1..40),
        ) {
            use super::super::{NetworkInputs, NetworkObserverBuilder};
            let network: Network<2, 1, 1> = Network::new([60.0, 400.0])
                .and_then(|n| n.connect(0, 1, 0.8))
                .and_then(|n| n.connect_boundary(1, 0, 1.2))
                .and_then(|n| n.joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0)))
                .expect("a valid network");
            let sensor = ResistanceSensor::of_source(&network, 0, 0.01, 0.5).expect("valid");
            let observer: NetworkObserver<2, 1, 1, 3, 1> = NetworkObserverBuilder::new(&network, [1])
                .critical_c([Some(155.0), None])
                .resistance_sensor(0, sensor)
                .build()
                .expect("builds");
            let mut state = observer.state(&[20.0; 2], &[20.0]);
            for (k, (r, i, v)) in inputs.iter().enumerate() {
                let now_us = k as u32 * 1000;
                for (reading, measured) in [
                    (observer.resistance_reading(0, *r, *i, now_us), *r),
                    (observer.voltage_current_reading(0, *v, *i, now_us), *v / *i),
                ] {
                    match reading.map(|t| t.result) {
                        None => prop_assert!(i.is_finite() && i.abs() < 0.5),
                        Some(Ok(t)) => {
                            prop_assert!(measured.is_finite() && measured > 0.0);
                            prop_assert!(i.is_finite() && i.abs() >= 0.5);
                            prop_assert!(t.temp_c.is_finite());
                            prop_assert!((-60.0..=300.0).contains(&t.temp_c));
                        }
                        Some(Err(fault)) => prop_assert!(matches!(
                            fault,
                            SensorFault::NotFinite | SensorFault::OutOfRange
                        )),
                    }
                    if !(measured.is_finite() && measured > 0.0) {
                        prop_assert!(!matches!(reading.map(|t| t.result), Some(Ok(_))));
                    }
                    let inputs = NetworkInputs {
                        currents_a: [*i],
                        boundary_c: [20.0],
                        readings: [reading],
                        now_us,
                        elapsed_us: 1000,
                    };
                    let out = observer.tick(&mut state, &inputs);
                    prop_assert!(out.temps_c.iter().all(|t| t.is_finite()));
                }
            }
        }
    }

    #[test]
    fn flashed_tables_need_their_sensor_kinds() {
        use super::super::NetworkObserverBuilder;
        let network: Network<2, 1, 1> = Network::new([60.0, 400.0])
            .and_then(|n| n.connect(0, 1, 0.8))
            .and_then(|n| n.connect_boundary(1, 0, 1.2))
            .and_then(|n| n.joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0)))
            .expect("a valid network");
        let builder = NetworkObserverBuilder::new(&network, [1])
            .critical_c([Some(155.0), None])
            .resistance_sensor(0, copper());
        let parts = builder.parts::<3>().expect("solves");
        // The slot reads the source's node, not the map's housing.
        assert_eq!(parts.sensor_nodes, [0]);
        let built: NetworkObserver<2, 1, 1, 3, 1> = builder.build().expect("builds");
        let assembled =
            NetworkObserver::from_parts_with_sensors(&parts, &builder.kinds()).expect("assembles");
        assert_eq!(built.fingerprint(), assembled.fingerprint());
        // Assembled as thermocouples' tables, they are refused.
        assert!(matches!(
            NetworkObserver::from_parts(&parts),
            Err(BuildError::InvalidParameter {
                name: "sensor_kinds"
            })
        ));
        // A thermocouple-only observer's fingerprint differs (its gain).
        let thermocouple: NetworkObserver<2, 1, 1, 3, 1> =
            NetworkObserverBuilder::new(&network, [0])
                .critical_c([Some(155.0), None])
                .build()
                .expect("builds");
        assert_ne!(thermocouple.fingerprint(), built.fingerprint());
        assert_eq!(thermocouple.resistance_reading(0, 1.3, 2.0, 0), None);
        // A sensor that does not exist.
        assert!(matches!(
            NetworkObserverBuilder::new(&network, [1])
                .resistance_sensor(1, copper())
                .build::<3>(),
            Err(BuildError::InvalidParameter {
                name: "resistance_sensor"
            })
        ));
    }

    #[test]
    fn invalid_sensors_are_refused_by_name() {
        let s = copper();
        let name = |r: Result<ResistanceSensor, BuildError>| match r {
            Err(BuildError::InvalidParameter { name }) => name,
            other => panic!("expected a refusal, got {other:?}"),
        };
        assert_eq!(
            name(s.measured(Resistance {
                r_at_0c_ohm: 1.0,
                slope_ohm_per_k: -0.001
            })),
            "resistance"
        );
        assert_eq!(name(s.range_c(100.0, 50.0)), "range_c");
        assert_eq!(name(s.noise_reference_c(f64::NAN)), "noise_reference_c");
        assert_eq!(
            name(
                ResistanceSensor {
                    min_current_a: 0.0,
                    ..s
                }
                .checked()
            ),
            "min_current_a"
        );
        assert_eq!(
            name(
                ResistanceSensor {
                    noise_fraction: f64::INFINITY,
                    ..s
                }
                .checked()
            ),
            "noise_fraction"
        );
    }
}
