//! Resistive temperature sensors (NTC thermistors, platinum RTDs, KTY silicon
//! PTCs) read
//! through a resistive divider by a ratiometric ADC.
//!
//! # Conversion
//!
//! [`ResistiveInput::convert`] turns one ADC count into a [`SensorResult`]:
//! count -> divider ratio -> sensor resistance \[ohm\] -> temperature \[degC\].
//! It is pure, allocation-free, panic-free and has no unbounded loop.
//!
//! | kind | constructor | reference equation (R in ohm, T in K, t in degC) | conversion error vs the f64 reference |
//! |---|---|---|---|
//! | NTC, beta | [`Sensor::ntc_beta`] | 1/T = 1/T0 + ln(R/R0)/beta | 3.7e-5 K |
//! | NTC, Steinhart-Hart | [`Sensor::ntc_steinhart_hart`] | 1/T = a + b ln R + c (ln R)^3 | 6.2e-5 K |
//! | NTC, manufacturer's R-T table | [`Sensor::ntc_table`] | 1/T linear in ln R between points (piecewise beta) | 4.6e-5 K vs that interpolation; 8.7e-3 K vs the Steinhart-Hart curve a 5 K table was made from |
//! | PT100 / PT1000 | [`Sensor::rtd`], [`Sensor::PT100`], [`Sensor::PT1000`] | Callendar-Van Dusen, IEC 60751: R = R0 (1 + A t + B t^2 + C (t - 100) t^3), C = 0 for t >= 0 | 4.1e-5 K (-40 .. 150 degC through the divider); 1.5e-4 K over -200 .. 850 degC from resistance |
//! | KTY83-110/120/150, KTY84-130/150 (silicon PTC) | [`Sensor::KTY83_110`], [`Sensor::KTY84_130`], any PTC table: [`Sensor::ptc_table`] | the datasheet's R-T table, T linear in R between rows | 1.8e-5 K vs that interpolation; the table's own accuracy (its off-grid rows from their 10 K neighbours): 0.12 K |
//!
//! The error column is the largest difference between this module's `f32`
//! arithmetic and the same equation evaluated in `f64` by the tests (closed
//! forms for the NTCs, a 200-step bisection of the forward equation for the
//! RTD), over every count of a 12-bit ADC whose temperature is inside
//! -40 .. 150 degC, both topologies (the tests `*_matches_the_f64_reference`,
//! which hold it below 0.001 K). Quantisation is separate: see below. The
//! sensor's own tolerance (NTC R25 and beta class, RTD class A/B) and the
//! reference resistor's tolerance come on top and are not modelled here.
//!
//! # KTY tables: where the rows come from
//!
//! [`KTY83_110_TABLE`] and [`KTY84_130_TABLE`] are the typical-resistance
//! tables of the Philips/NXP datasheets "KTY83 series, Silicon temperature
//! sensors" (1998 Apr 09 and later revisions) and "KTY84 series" (same
//! family). The stored copies of those datasheets at hand
//! (<https://manualmachine.com/philips/kty83120/4243353-datasheet>,
//! <https://dtsheet.com/doc/219619/philips-kty84-151>) show only their first
//! pages (type list, R25 / R100 limits), not the table; the rows were read
//! from public transcriptions of the tables that agree row for row (two for
//! the KTY83, three for the KTY84). What the copies do show is checked by
//! the tests: the table's 1000 ohm at 25 degC is inside the KTY83-110's R25
//! of 990 .. 1010 ohm, and 1000 ohm at 100 degC inside the KTY84-130's R100
//! of 970 .. 1030 ohm. A part's tolerance (those ranges: about +-1 % and
//! +-3 %, several kelvin) comes on top of the typical curve and is not
//! modelled.
//!
//! # Divider and ADC
//!
//! The ADC is ratiometric (its reference is the divider's supply), `bits`
//! wide, ideal: count `k` stands for the ratio `k / 2^bits` of the node
//! voltage to the reference voltage.
//!
//! | [`Topology`] | wiring | sensor resistance |
//! |---|---|---|
//! | [`Topology::SensorToGround`] | V_ref - R_ref - node - sensor - GND | R = R_ref k / (2^bits - k) |
//! | [`Topology::SensorToSupply`] | V_ref - sensor - node - R_ref - GND | R = R_ref (2^bits - k) / k |
//!
//! # Faults
//!
//! A temperature is returned only for a count strictly between the rails and
//! a temperature inside the sensor's range ([`Sensor::with_range`]):
//!
//! | count | [`Topology::SensorToGround`] | [`Topology::SensorToSupply`] |
//! |---|---|---|
//! | >= 2^bits (not an ADC code) | [`SensorFault::InvalidData`] | [`SensorFault::InvalidData`] |
//! | top rail (>= 2^bits - 1 - margin) | [`SensorFault::OpenCircuit`] | [`SensorFault::ShortToVcc`] (sensor shorted: node at the supply) |
//! | bottom rail (<= margin) | [`SensorFault::ShortToGnd`] (sensor shorted: node at ground) | [`SensorFault::OpenCircuit`] |
//! | temperature outside the range | [`SensorFault::OutOfRange`] | [`SensorFault::OutOfRange`] |
//!
//! The rail margin is [`Divider::with_rail_margin`] (0 by default: only the
//! extreme codes). A node wire shorted to a rail reads like the sensor fault
//! of that rail; a broken reference resistor reads like the opposite rail.
//! An open or shorted sensor never becomes a temperature either way.
//!
//! # Quantisation at 12 bits
//!
//! Temperature step of one count \[K\] (the mean of the steps to the two
//! neighbouring codes), and the largest end-to-end error over -40 .. 150 degC
//! of a true temperature rounded to the nearest code and converted back
//! (quantisation plus arithmetic, an ideal ADC, exact resistors); both from
//! the f64 reference by the test `quantisation_steps_match_the_documented_table`:
//!
//! | sensor, R_ref | -40 degC | 25 degC | 150 degC | worst error, -40 .. 150 degC |
//! |---|---|---|---|---|
//! | NTC 10 kohm B3950, 10 kohm | 0.142 | 0.022 | 0.578 | 0.27 |
//! | NTC 10 kohm Steinhart-Hart (the test's part), 10 kohm | 0.099 | 0.025 | 0.457 | 0.23 |
//! | PT100, 100 ohm | 0.209 | 0.277 | 0.433 | 0.21 |
//! | PT100, 1 kohm | 0.725 | 0.775 | 0.876 | 0.43 |
//! | PT1000, 1 kohm | 0.209 | 0.277 | 0.433 | 0.21 |
//! | KTY83-110, 1 kohm | 0.113 | 0.127 | 0.212 | 0.11 |
//! | KTY84-130, 1 kohm | (table starts at -40) | 0.139 | 0.184 | 0.09 |
//!
//! The two topologies give the same figures (one's ratio is one minus the
//! other's). So at 12 bits the arithmetic is far inside 0.1 K, but the
//! quantisation is not, anywhere over the whole -40 .. 150 degC: a 10 kohm
//! NTC with a 10 kohm R_ref resolves 0.1 K only around room temperature (the
//! step passes 0.1 K below about -34 degC and above about 89 degC), and an
//! RTD on a plain divider needs a wider ADC (each extra bit halves the step)
//! or a bridge with an amplifier (the MAX31865). A KTY on 1 kohm comes
//! closest of the kinds here (0.09 .. 0.11 K worst): its ohms per kelvin are
//! a larger fraction of its resistance than a platinum RTD's.
//!
//! # Reading
//!
//! A resistive sensor has no cold junction: [`ResistiveInput::convert`]'s
//! [`Reading::cold_junction_c`] is `None`.

use libm::{logf, sqrtf};

use super::{Reading, SensorFault, SensorResult};
use crate::error::BuildError;

/// 0 degC in kelvin.
const ZERO_C_IN_K: f32 = 273.15;

/// IEC 60751 Callendar-Van Dusen coefficient A \[1/degC\].
pub const CVD_A: f32 = 3.9083e-3;
/// IEC 60751 Callendar-Van Dusen coefficient B \[1/degC^2\].
pub const CVD_B: f32 = -5.775e-7;
/// IEC 60751 Callendar-Van Dusen coefficient C \[1/degC^4\], used below
/// 0 degC only.
pub const CVD_C: f32 = -4.183e-12;
/// Lowest temperature IEC 60751 defines the platinum curve for \[degC\].
pub const RTD_MIN_C: f32 = -200.0;
/// Highest temperature IEC 60751 defines the platinum curve for \[degC\].
pub const RTD_MAX_C: f32 = 850.0;
/// Default range of the NTC kinds with an equation \[degC\]: the usual
/// datasheet operating range of epoxy and glass NTCs.
pub const NTC_DEFAULT_RANGE_C: (f32, f32) = (-55.0, 150.0);
/// Newton steps of the Callendar-Van Dusen inversion below 0 degC. Starting
/// from the quadratic (C = 0) solution, 2.4 K from the root at -200 degC and
/// 0.01 K at -40 degC, one step leaves 2.5e-3 K at -200 degC and two steps
/// 3e-9 K (in f64); four leave margin for `f32` rounding.
const CVD_NEWTON_STEPS: usize = 4;

/// Where the sensor sits in the divider.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Topology {
    /// The sensor from the ADC node to ground, the reference resistor from
    /// the reference voltage to the node (the usual NTC pull-up).
    SensorToGround,
    /// The sensor from the reference voltage to the ADC node, the reference
    /// resistor from the node to ground.
    SensorToSupply,
}

/// The divider and the ratiometric ADC that reads it.
///
/// Built with [`Divider::new`], which validates every parameter; all
/// builders are `const fn`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Divider {
    topology: Topology,
    reference_resistance_ohm: f32,
    bits: u8,
    rail_margin_counts: u32,
}

impl Divider {
    /// A divider with the reference resistor `reference_resistance_ohm`
    /// \[ohm\] and an ADC of `bits` bits (1 ..= 24, so that every count is
    /// exact in `f32`). Only the two extreme codes count as rails.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if the resistance is not finite or not
    /// strictly positive, or `bits` is outside 1 ..= 24.
    pub const fn new(
        topology: Topology,
        reference_resistance_ohm: f32,
        bits: u8,
    ) -> Result<Self, BuildError> {
        if !reference_resistance_ohm.is_finite() || reference_resistance_ohm <= 0.0 {
            return Err(BuildError::InvalidParameter {
                name: "reference_resistance_ohm",
            });
        }
        if bits < 1 || bits > 24 {
            return Err(BuildError::InvalidParameter { name: "bits" });
        }
        Ok(Self {
            topology,
            reference_resistance_ohm,
            bits,
            rail_margin_counts: 0,
        })
    }

    /// Also treat counts within `counts` of either extreme code as that rail
    /// (an ADC's offset and gain errors keep an open sensor a few counts off
    /// the extreme code).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if the two rails would overlap
    /// (`2 * counts + 2 > 2^bits`).
    pub const fn with_rail_margin(self, counts: u32) -> Result<Self, BuildError> {
        // Both sides are below 2^25 + 2, no overflow.
        if counts > (self.full_scale_counts() >> 1) - 1 {
            return Err(BuildError::InvalidParameter {
                name: "rail_margin_counts",
            });
        }
        Ok(Self {
            rail_margin_counts: counts,
            ..self
        })
    }

    /// Where the sensor sits.
    pub const fn topology(&self) -> Topology {
        self.topology
    }

    /// The reference resistor \[ohm\].
    pub const fn reference_resistance_ohm(&self) -> f32 {
        self.reference_resistance_ohm
    }

    /// ADC width \[bit\].
    pub const fn bits(&self) -> u8 {
        self.bits
    }

    /// Counts next to each extreme code that also count as the rail.
    pub const fn rail_margin_counts(&self) -> u32 {
        self.rail_margin_counts
    }

    /// `2^bits`: the count that would stand for the full reference voltage
    /// (one more than the largest code).
    pub const fn full_scale_counts(&self) -> u32 {
        1 << self.bits
    }

    /// The sensor resistance \[ohm\] that `counts` stands for.
    ///
    /// # Errors
    /// [`SensorFault::InvalidData`] for a count that is not an ADC code;
    /// the rail faults of the [module documentation](self) for a count on a
    /// rail.
    pub fn resistance_ohm(&self, counts: u32) -> Result<f32, SensorFault> {
        let full = self.full_scale_counts();
        if counts >= full {
            return Err(SensorFault::InvalidData);
        }
        let (at_bottom, at_top) = (
            counts <= self.rail_margin_counts,
            counts >= full - 1 - self.rail_margin_counts,
        );
        match (self.topology, at_bottom, at_top) {
            (Topology::SensorToGround, true, _) => Err(SensorFault::ShortToGnd),
            (Topology::SensorToGround, _, true) => Err(SensorFault::OpenCircuit),
            (Topology::SensorToSupply, true, _) => Err(SensorFault::OpenCircuit),
            (Topology::SensorToSupply, _, true) => Err(SensorFault::ShortToVcc),
            (topology, false, false) => {
                // 0 < counts < full <= 2^24: both are exact in f32 and
                // non-zero, so the quotient is finite and positive.
                let low = counts as f32;
                let high = (full - counts) as f32;
                Ok(match topology {
                    Topology::SensorToGround => self.reference_resistance_ohm * low / high,
                    Topology::SensorToSupply => self.reference_resistance_ohm * high / low,
                })
            }
        }
    }
}

/// One point of a manufacturer's resistance-temperature table.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TablePoint {
    /// Temperature \[degC\].
    pub temp_c: f32,
    /// Resistance at that temperature \[ohm\].
    pub resistance_ohm: f32,
}

/// A table point from literals (for the built-in tables).
const fn point(temp_c: f32, resistance_ohm: f32) -> TablePoint {
    TablePoint {
        temp_c,
        resistance_ohm,
    }
}

/// The typical resistance-temperature table of the KTY83-110, KTY83-120 and
/// KTY83-150 (Philips/NXP KTY83 series datasheet, the resistance table of its
/// characteristics section; sensor current 1 mA): -55 .. 175 degC in 10 K
/// steps plus -55, 25, 125 and 175 degC, resistances in ohm rounded to
/// 1 ohm.
///
/// The tolerance of a real part comes on top: R25 is 990 .. 1010 ohm for the
/// KTY83-110, 980 .. 1020 ohm for the -120 and 950 .. 1050 ohm for the -150
/// (the datasheet's quick reference data).
pub const KTY83_110_TABLE: [TablePoint; 27] = [
    point(-55.0, 500.0),
    point(-50.0, 525.0),
    point(-40.0, 577.0),
    point(-30.0, 632.0),
    point(-20.0, 691.0),
    point(-10.0, 754.0),
    point(0.0, 820.0),
    point(10.0, 889.0),
    point(20.0, 962.0),
    point(25.0, 1000.0),
    point(30.0, 1039.0),
    point(40.0, 1118.0),
    point(50.0, 1202.0),
    point(60.0, 1288.0),
    point(70.0, 1379.0),
    point(80.0, 1472.0),
    point(90.0, 1569.0),
    point(100.0, 1670.0),
    point(110.0, 1774.0),
    point(120.0, 1882.0),
    point(125.0, 1937.0),
    point(130.0, 1993.0),
    point(140.0, 2107.0),
    point(150.0, 2225.0),
    point(160.0, 2346.0),
    point(170.0, 2471.0),
    point(175.0, 2535.0),
];

/// The typical resistance-temperature table of the KTY84-130 and KTY84-150
/// (Philips/NXP KTY84 series datasheet, the resistance table of its
/// characteristics section; sensor current 2 mA): -40 .. 300 degC in 10 K
/// steps plus 25 degC, resistances in ohm rounded to 1 ohm.
///
/// The tolerance of a real part comes on top: R100 is 970 .. 1030 ohm for the
/// KTY84-130 and 950 .. 1050 ohm for the KTY84-150 (the datasheet's quick
/// reference data), a few kelvin.
pub const KTY84_130_TABLE: [TablePoint; 36] = [
    point(-40.0, 359.0),
    point(-30.0, 391.0),
    point(-20.0, 424.0),
    point(-10.0, 460.0),
    point(0.0, 498.0),
    point(10.0, 538.0),
    point(20.0, 581.0),
    point(25.0, 603.0),
    point(30.0, 626.0),
    point(40.0, 672.0),
    point(50.0, 722.0),
    point(60.0, 773.0),
    point(70.0, 826.0),
    point(80.0, 882.0),
    point(90.0, 940.0),
    point(100.0, 1000.0),
    point(110.0, 1062.0),
    point(120.0, 1127.0),
    point(130.0, 1194.0),
    point(140.0, 1262.0),
    point(150.0, 1334.0),
    point(160.0, 1407.0),
    point(170.0, 1482.0),
    point(180.0, 1560.0),
    point(190.0, 1640.0),
    point(200.0, 1722.0),
    point(210.0, 1807.0),
    point(220.0, 1893.0),
    point(230.0, 1982.0),
    point(240.0, 2073.0),
    point(250.0, 2166.0),
    point(260.0, 2261.0),
    point(270.0, 2357.0),
    point(280.0, 2452.0),
    point(290.0, 2542.0),
    point(300.0, 2624.0),
];

#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum Kind {
    /// `inv_t0_per_k` = 1/T0, `inv_beta_per_k` = 1/beta.
    Beta {
        r0_ohm: f32,
        inv_t0_per_k: f32,
        inv_beta_per_k: f32,
    },
    SteinhartHart {
        a: f32,
        b: f32,
        c: f32,
    },
    Rtd {
        r0_ohm: f32,
    },
    /// An NTC's table, interpolated as piecewise beta.
    NtcTable(&'static [TablePoint]),
    /// A silicon PTC's table, interpolated linearly in R.
    PtcTable(&'static [TablePoint]),
}

/// A resistive temperature sensor: its resistance-temperature curve and the
/// range in which a temperature is plausible.
///
/// Built with the `const fn` constructors, which validate every parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sensor {
    kind: Kind,
    min_c: f32,
    max_c: f32,
}

/// `Ok` of a constructor whose arguments are literals known to be valid.
const fn expect_valid(sensor: Result<Sensor, BuildError>) -> Sensor {
    match sensor {
        Ok(sensor) => sensor,
        Err(_) => panic!("invalid built-in sensor"),
    }
}

impl Sensor {
    /// PT100 (R0 = 100 ohm), IEC 60751, over -200 .. 850 degC.
    pub const PT100: Self = expect_valid(Self::rtd(100.0));
    /// PT1000 (R0 = 1000 ohm), IEC 60751, over -200 .. 850 degC.
    pub const PT1000: Self = expect_valid(Self::rtd(1000.0));
    /// KTY83-110 / -120 / -150 silicon PTC by its datasheet table
    /// ([`KTY83_110_TABLE`]), over -55 .. 175 degC.
    pub const KTY83_110: Self = expect_valid(Self::ptc_table(&KTY83_110_TABLE));
    /// KTY84-130 / -150 silicon PTC by its datasheet table
    /// ([`KTY84_130_TABLE`]), over -40 .. 300 degC.
    pub const KTY84_130: Self = expect_valid(Self::ptc_table(&KTY84_130_TABLE));

    /// NTC by its beta equation: `r0_ohm` \[ohm\] at `t0_c` \[degC\]
    /// (usually 25 degC), and `beta_k` \[K\] (the datasheet's B25/85 or
    /// B25/50). Range [`NTC_DEFAULT_RANGE_C`].
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if a value is not finite, `r0_ohm`
    /// or `beta_k` is not strictly positive, or `t0_c` is at or below
    /// absolute zero.
    pub const fn ntc_beta(r0_ohm: f32, t0_c: f32, beta_k: f32) -> Result<Self, BuildError> {
        if !r0_ohm.is_finite() || r0_ohm <= 0.0 {
            return Err(BuildError::InvalidParameter { name: "r0_ohm" });
        }
        if !t0_c.is_finite() || t0_c <= -ZERO_C_IN_K {
            return Err(BuildError::InvalidParameter { name: "t0_c" });
        }
        if !beta_k.is_finite() || beta_k <= 0.0 {
            return Err(BuildError::InvalidParameter { name: "beta_k" });
        }
        Ok(Self {
            kind: Kind::Beta {
                r0_ohm,
                inv_t0_per_k: 1.0 / (t0_c + ZERO_C_IN_K),
                inv_beta_per_k: 1.0 / beta_k,
            },
            min_c: NTC_DEFAULT_RANGE_C.0,
            max_c: NTC_DEFAULT_RANGE_C.1,
        })
    }

    /// NTC by its Steinhart-Hart coefficients, `1/T = a + b ln R + c (ln R)^3`
    /// with T in K and R in ohm, as datasheets and fitting tools give them.
    /// Range [`NTC_DEFAULT_RANGE_C`].
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if a coefficient is not finite, `b`
    /// is not strictly positive or `c` is negative (either would let the
    /// curve turn back, so that one resistance had two temperatures).
    pub const fn ntc_steinhart_hart(a: f32, b: f32, c: f32) -> Result<Self, BuildError> {
        if !a.is_finite() {
            return Err(BuildError::InvalidParameter { name: "a" });
        }
        if !b.is_finite() || b <= 0.0 {
            return Err(BuildError::InvalidParameter { name: "b" });
        }
        if !c.is_finite() || c < 0.0 {
            return Err(BuildError::InvalidParameter { name: "c" });
        }
        Ok(Self {
            kind: Kind::SteinhartHart { a, b, c },
            min_c: NTC_DEFAULT_RANGE_C.0,
            max_c: NTC_DEFAULT_RANGE_C.1,
        })
    }

    /// Platinum RTD of `r0_ohm` \[ohm\] at 0 degC, IEC 60751 coefficients
    /// ([`CVD_A`], [`CVD_B`], [`CVD_C`]). Range [`RTD_MIN_C`] ..
    /// [`RTD_MAX_C`].
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if `r0_ohm` is not finite or not
    /// strictly positive.
    pub const fn rtd(r0_ohm: f32) -> Result<Self, BuildError> {
        if !r0_ohm.is_finite() || r0_ohm <= 0.0 {
            return Err(BuildError::InvalidParameter { name: "r0_ohm" });
        }
        Ok(Self {
            kind: Kind::Rtd { r0_ohm },
            min_c: RTD_MIN_C,
            max_c: RTD_MAX_C,
        })
    }

    /// NTC by a manufacturer's resistance-temperature table, interpolated as
    /// a beta curve between neighbouring points (1/T linear in ln R), which is
    /// exact for a beta-model part. Range: the table's first to last
    /// temperature; there is no extrapolation.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] (`"table"`) if the table has fewer
    /// than two points, a value is not finite, a resistance is not strictly
    /// positive, a temperature is at or below absolute zero, temperatures do
    /// not strictly increase, or resistances do not strictly decrease.
    pub const fn ntc_table(table: &'static [TablePoint]) -> Result<Self, BuildError> {
        match table_range_c(table, false) {
            Ok((min_c, max_c)) => Ok(Self {
                kind: Kind::NtcTable(table),
                min_c,
                max_c,
            }),
            Err(e) => Err(e),
        }
    }

    /// PTC (a silicon sensor such as the KTY family) by a manufacturer's
    /// resistance-temperature table, interpolated linearly in R between
    /// neighbouring points: a silicon sensor's curve is nearly linear, so a
    /// 10 K table interpolates within its own 1 ohm rounding (see
    /// [`Sensor::KTY84_130`]). Range: the table's first to last temperature;
    /// there is no extrapolation.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] (`"table"`) as for
    /// [`Sensor::ntc_table`], except that resistances must strictly
    /// increase.
    pub const fn ptc_table(table: &'static [TablePoint]) -> Result<Self, BuildError> {
        match table_range_c(table, true) {
            Ok((min_c, max_c)) => Ok(Self {
                kind: Kind::PtcTable(table),
                min_c,
                max_c,
            }),
            Err(e) => Err(e),
        }
    }

    /// Narrow the plausible range to `min_c ..= max_c` \[degC\]: what the
    /// sensor can physically see in this machine. A temperature outside it is
    /// [`SensorFault::OutOfRange`].
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if a limit is not finite,
    /// `min_c >= max_c`, or the range leaves the kind's own range (the
    /// constructor's default, which for an RTD is IEC 60751's and for a
    /// table is the table's).
    pub const fn with_range(self, min_c: f32, max_c: f32) -> Result<Self, BuildError> {
        let (kind_min_c, kind_max_c) = match self.kind {
            Kind::Beta { .. } | Kind::SteinhartHart { .. } => (-ZERO_C_IN_K, f32::MAX),
            Kind::Rtd { .. } => (RTD_MIN_C, RTD_MAX_C),
            Kind::NtcTable(table) | Kind::PtcTable(table) => match (table.first(), table.last()) {
                (Some(first), Some(last)) => (first.temp_c, last.temp_c),
                _ => return Err(BuildError::InvalidParameter { name: "table" }),
            },
        };
        if !min_c.is_finite() || min_c < kind_min_c {
            return Err(BuildError::InvalidParameter { name: "min_c" });
        }
        if !max_c.is_finite() || max_c <= min_c || max_c > kind_max_c {
            return Err(BuildError::InvalidParameter { name: "max_c" });
        }
        Ok(Self {
            min_c,
            max_c,
            ..self
        })
    }

    /// Lowest plausible temperature \[degC\].
    pub const fn min_c(&self) -> f32 {
        self.min_c
    }

    /// Highest plausible temperature \[degC\].
    pub const fn max_c(&self) -> f32 {
        self.max_c
    }

    /// The temperature \[degC\] of the sensor at `resistance_ohm` \[ohm\].
    ///
    /// # Errors
    /// [`SensorFault::OutOfRange`] if the temperature is outside
    /// [`min_c`](Self::min_c) ..= [`max_c`](Self::max_c), or the resistance
    /// is not finite and positive or has no temperature on the curve.
    pub fn temp_c(&self, resistance_ohm: f32) -> Result<f32, SensorFault> {
        if !resistance_ohm.is_finite() || resistance_ohm <= 0.0 {
            return Err(SensorFault::OutOfRange);
        }
        let temp_c = match self.kind {
            Kind::Beta {
                r0_ohm,
                inv_t0_per_k,
                inv_beta_per_k,
            } => kelvin_to_c(inv_t0_per_k + logf(resistance_ohm / r0_ohm) * inv_beta_per_k),
            Kind::SteinhartHart { a, b, c } => {
                let ln_r = logf(resistance_ohm);
                kelvin_to_c(a + ln_r * (b + c * ln_r * ln_r))
            }
            Kind::Rtd { r0_ohm } => cvd_temp_c(resistance_ohm / r0_ohm),
            Kind::NtcTable(table) => table_temp_c(table, resistance_ohm, Interpolation::Beta),
            Kind::PtcTable(table) => table_temp_c(table, resistance_ohm, Interpolation::Linear),
        };
        // NaN fails both comparisons, so it cannot pass as a temperature.
        if temp_c >= self.min_c && temp_c <= self.max_c {
            Ok(temp_c)
        } else {
            Err(SensorFault::OutOfRange)
        }
    }
}

/// Temperature \[degC\] from 1/T \[1/K\]; NaN (refused by the range check)
/// if 1/T is not positive, where the curve has no temperature.
fn kelvin_to_c(inv_t_per_k: f32) -> f32 {
    if inv_t_per_k > 0.0 {
        1.0 / inv_t_per_k - ZERO_C_IN_K
    } else {
        f32::NAN
    }
}

/// Invert Callendar-Van Dusen for `ratio` = R/R0.
///
/// At and above 0 degC the curve is the quadratic `1 + A t + B t^2`; its root
/// is taken in the form `2 (r - 1) / (A + sqrt(A^2 + 4 B (r - 1)))`, which
/// does not cancel near 0 degC. Below 0 degC that root starts a fixed number
/// of Newton steps on the full quartic. NaN (refused by the range check) where
/// the curve has no temperature.
fn cvd_temp_c(ratio: f32) -> f32 {
    let excess = ratio - 1.0;
    let discriminant = CVD_A * CVD_A + 4.0 * CVD_B * excess;
    if discriminant.is_nan() || discriminant < 0.0 {
        // Above the quadratic's vertex (about 3384 degC): not platinum.
        return f32::NAN;
    }
    let quadratic_c = 2.0 * excess / (CVD_A + sqrtf(discriminant));
    if excess >= 0.0 {
        return quadratic_c;
    }
    // Below the IEC range the quartic's slope can vanish: no root to refine.
    let mut t = quadratic_c.max(RTD_MIN_C - 50.0);
    for _ in 0..CVD_NEWTON_STEPS {
        let t2 = t * t;
        let residual = CVD_A * t + CVD_B * t2 + CVD_C * (t - 100.0) * t2 * t - excess;
        let slope = CVD_A + 2.0 * CVD_B * t + CVD_C * (4.0 * t - 300.0) * t2;
        t -= residual / slope;
    }
    t
}

/// The first and last temperature \[degC\] of a table whose temperatures
/// strictly increase and whose resistances strictly increase (`rising`, a
/// PTC) or decrease (an NTC), every value finite, resistances positive.
const fn table_range_c(table: &[TablePoint], rising: bool) -> Result<(f32, f32), BuildError> {
    const INVALID: BuildError = BuildError::InvalidParameter { name: "table" };
    let (first, last) = match (table.first(), table.last()) {
        (Some(first), Some(last)) if table.len() >= 2 => (*first, *last),
        _ => return Err(INVALID),
    };
    let mut i = 0;
    while i < table.len() {
        let point = table[i];
        if !point.temp_c.is_finite()
            || point.temp_c <= -ZERO_C_IN_K
            || !point.resistance_ohm.is_finite()
            || point.resistance_ohm <= 0.0
        {
            return Err(INVALID);
        }
        if i > 0 {
            let previous = table[i - 1];
            let monotone = if rising {
                point.resistance_ohm > previous.resistance_ohm
            } else {
                point.resistance_ohm < previous.resistance_ohm
            };
            if point.temp_c <= previous.temp_c || !monotone {
                return Err(INVALID);
            }
        }
        i += 1;
    }
    Ok((first.temp_c, last.temp_c))
}

/// How a table is read between its points.
#[derive(Clone, Copy)]
enum Interpolation {
    /// 1/T linear in ln R (piecewise beta): exact for a beta-model NTC.
    Beta,
    /// T linear in R: a silicon PTC's nearly linear curve.
    Linear,
}

/// Interpolate the table at `resistance_ohm` between the two points around
/// it. NaN (refused by the range check) outside the table.
fn table_temp_c(table: &[TablePoint], resistance_ohm: f32, interpolation: Interpolation) -> f32 {
    for pair in table.windows(2) {
        if let [cold, hot] = pair {
            // Resistances are monotone along the table (checked when built),
            // in either direction.
            let (low, high) = if cold.resistance_ohm < hot.resistance_ohm {
                (cold.resistance_ohm, hot.resistance_ohm)
            } else {
                (hot.resistance_ohm, cold.resistance_ohm)
            };
            if resistance_ohm >= low && resistance_ohm <= high {
                return match interpolation {
                    Interpolation::Beta => {
                        let ln_r = logf(resistance_ohm);
                        let (ln_cold, ln_hot) =
                            (logf(cold.resistance_ohm), logf(hot.resistance_ohm));
                        let (inv_cold, inv_hot) = (
                            1.0 / (cold.temp_c + ZERO_C_IN_K),
                            1.0 / (hot.temp_c + ZERO_C_IN_K),
                        );
                        let fraction = (ln_r - ln_cold) / (ln_hot - ln_cold);
                        kelvin_to_c(inv_cold + fraction * (inv_hot - inv_cold))
                    }
                    Interpolation::Linear => {
                        let fraction = (resistance_ohm - cold.resistance_ohm)
                            / (hot.resistance_ohm - cold.resistance_ohm);
                        cold.temp_c + fraction * (hot.temp_c - cold.temp_c)
                    }
                };
            }
        }
    }
    f32::NAN
}

/// A resistive sensor on a divider: the whole count-to-temperature path.
///
/// ```
/// use coil_thermal::sensors::resistive::{Divider, ResistiveInput, Sensor, Topology};
/// use coil_thermal::sensors::SensorFault;
///
/// // 10 kohm B3950 NTC to ground, 10 kohm pull-up, 12-bit ADC.
/// const INPUT: ResistiveInput = match (
///     Divider::new(Topology::SensorToGround, 10_000.0, 12),
///     Sensor::ntc_beta(10_000.0, 25.0, 3950.0),
/// ) {
///     (Ok(divider), Ok(sensor)) => ResistiveInput::new(divider, sensor),
///     _ => panic!("invalid sensor input"),
/// };
/// let reading = INPUT.convert(2048).unwrap();
/// assert!((reading.temp_c - 25.0).abs() < 1e-3);
/// assert_eq!(INPUT.convert(4095), Err(SensorFault::OpenCircuit));
/// assert_eq!(INPUT.convert(0), Err(SensorFault::ShortToGnd));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ResistiveInput {
    divider: Divider,
    sensor: Sensor,
}

impl ResistiveInput {
    /// Pair a validated divider with a validated sensor.
    pub const fn new(divider: Divider, sensor: Sensor) -> Self {
        Self { divider, sensor }
    }

    /// The divider and ADC.
    pub const fn divider(&self) -> &Divider {
        &self.divider
    }

    /// The sensor.
    pub const fn sensor(&self) -> &Sensor {
        &self.sensor
    }

    /// Convert one ADC count ([`Reading::cold_junction_c`] `None`).
    ///
    /// # Errors
    /// The faults of the [module documentation](self): a count that is not
    /// an ADC code, on a rail, or giving a temperature outside the sensor's
    /// range is never a temperature.
    pub fn convert(&self, counts: u32) -> SensorResult {
        let resistance_ohm = self.divider.resistance_ohm(counts)?;
        let temp_c = self.sensor.temp_c(resistance_ohm)?;
        Ok(Reading::new(temp_c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const BITS: u8 = 12;
    const FULL: u32 = 1 << BITS;
    /// Largest error allowed between the conversion and the f64 reference
    /// equation at any in-range count \[K\].
    const MAX_ERROR_K: f64 = 0.001;
    /// Largest error of the 5 K table's interpolation against the
    /// Steinhart-Hart curve it was made from \[K\] (measured 8.7e-3 K).
    const TABLE_SOURCE_ERROR_K: f64 = 0.01;

    // ---- Independent f64 references: the datasheet equations, written out
    // again, never calling the code under test. ----

    const A: f64 = 3.9083e-3;
    const B: f64 = -5.775e-7;
    const C: f64 = -4.183e-12;
    const K0: f64 = 273.15;

    /// IEC 60751 forward: R/R0 at `t` degC.
    fn cvd_ratio(t: f64) -> f64 {
        let c = if t < 0.0 { C } else { 0.0 };
        1.0 + A * t + B * t * t + c * (t - 100.0) * t * t * t
    }

    /// IEC 60751 inverse by bisection of the forward equation (monotone over
    /// -250 .. 900 degC).
    fn cvd_temp(ratio: f64) -> f64 {
        let (mut lo, mut hi) = (-250.0, 900.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if cvd_ratio(mid) < ratio {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    fn beta_temp(r: f64, r0: f64, t0_c: f64, beta: f64) -> f64 {
        1.0 / (1.0 / (t0_c + K0) + (r / r0).ln() / beta) - K0
    }

    fn beta_resistance(t_c: f64, r0: f64, t0_c: f64, beta: f64) -> f64 {
        r0 * (beta * (1.0 / (t_c + K0) - 1.0 / (t0_c + K0))).exp()
    }

    fn sh_temp(r: f64, (a, b, c): (f64, f64, f64)) -> f64 {
        let l = r.ln();
        1.0 / (a + b * l + c * l * l * l) - K0
    }

    /// Steinhart-Hart forward by Cardano: solve c x^3 + b x + (a - 1/T) = 0.
    fn sh_resistance(t_c: f64, (a, b, c): (f64, f64, f64)) -> f64 {
        let y = (a - 1.0 / (t_c + K0)) / (2.0 * c);
        let x = (b / (3.0 * c)).powi(3);
        let s = (x + y * y).sqrt();
        ((s - y).cbrt() - (s + y).cbrt()).exp()
    }

    /// A 10 kohm NTC's published Steinhart-Hart coefficients (the common
    /// 10 kohm / 3950 K part: 1.009249522e-3, 2.378405444e-4, 2.019202697e-7).
    const SH: (f64, f64, f64) = (1.009249522e-3, 2.378405444e-4, 2.019202697e-7);

    /// Node voltage over reference voltage, from first principles: the
    /// element to ground over the sum.
    fn node_ratio(topology: Topology, sensor_ohm: f64, reference_ohm: f64) -> f64 {
        let to_ground = match topology {
            Topology::SensorToGround => sensor_ohm,
            Topology::SensorToSupply => reference_ohm,
        };
        to_ground / (sensor_ohm + reference_ohm)
    }

    /// Sensor resistance from a count, solving the divider the other way.
    fn count_resistance(topology: Topology, counts: u32, bits: u8, reference_ohm: f64) -> f64 {
        let x = counts as f64 / (1u64 << bits) as f64;
        match topology {
            Topology::SensorToGround => reference_ohm * x / (1.0 - x),
            Topology::SensorToSupply => reference_ohm * (1.0 - x) / x,
        }
    }

    /// A 5 K table of the Steinhart-Hart part, -55 .. 150 degC.
    static SH_TABLE: [TablePoint; 42] = {
        let mut table = [TablePoint {
            temp_c: 0.0,
            resistance_ohm: 0.0,
        }; 42];
        let mut i = 0;
        while i < 42 {
            table[i].temp_c = -55.0 + 5.0 * i as f32;
            i += 1;
        }
        table
    };

    /// `SH_TABLE` with its resistances filled from the f64 reference (static
    /// tables must be built at compile time, and `exp` is not `const`).
    fn sh_table() -> &'static [TablePoint] {
        use std::sync::OnceLock;
        static TABLE: OnceLock<[TablePoint; 42]> = OnceLock::new();
        TABLE.get_or_init(|| {
            let mut table = SH_TABLE;
            for point in &mut table {
                point.resistance_ohm = sh_resistance(point.temp_c as f64, SH) as f32;
            }
            table
        })
    }

    /// Piecewise-beta interpolation of a table, in f64.
    fn table_temp(table: &[TablePoint], r: f64) -> f64 {
        for pair in table.windows(2) {
            let (r1, r2) = (pair[0].resistance_ohm as f64, pair[1].resistance_ohm as f64);
            if r <= r1 && r >= r2 {
                let (t1, t2) = (pair[0].temp_c as f64 + K0, pair[1].temp_c as f64 + K0);
                let beta = (r1 / r2).ln() / (1.0 / t1 - 1.0 / t2);
                return 1.0 / (1.0 / t1 + (r / r1).ln() / beta) - K0;
            }
        }
        f64::NAN
    }

    /// The KTY83 series datasheet's typical table (KTY83-110/120/150),
    /// (degC, ohm), typed again here in the datasheet's own layout so a slip
    /// in the library's copy shows.
    const KTY83_ROWS: [(f64, f64); 27] = [
        (-55.0, 500.0),
        (-50.0, 525.0),
        (-40.0, 577.0),
        (-30.0, 632.0),
        (-20.0, 691.0),
        (-10.0, 754.0),
        (0.0, 820.0),
        (10.0, 889.0),
        (20.0, 962.0),
        (25.0, 1000.0),
        (30.0, 1039.0),
        (40.0, 1118.0),
        (50.0, 1202.0),
        (60.0, 1288.0),
        (70.0, 1379.0),
        (80.0, 1472.0),
        (90.0, 1569.0),
        (100.0, 1670.0),
        (110.0, 1774.0),
        (120.0, 1882.0),
        (125.0, 1937.0),
        (130.0, 1993.0),
        (140.0, 2107.0),
        (150.0, 2225.0),
        (160.0, 2346.0),
        (170.0, 2471.0),
        (175.0, 2535.0),
    ];

    /// The KTY84 series datasheet's typical table (KTY84-130/150), as above.
    const KTY84_ROWS: [(f64, f64); 36] = [
        (-40.0, 359.0),
        (-30.0, 391.0),
        (-20.0, 424.0),
        (-10.0, 460.0),
        (0.0, 498.0),
        (10.0, 538.0),
        (20.0, 581.0),
        (25.0, 603.0),
        (30.0, 626.0),
        (40.0, 672.0),
        (50.0, 722.0),
        (60.0, 773.0),
        (70.0, 826.0),
        (80.0, 882.0),
        (90.0, 940.0),
        (100.0, 1000.0),
        (110.0, 1062.0),
        (120.0, 1127.0),
        (130.0, 1194.0),
        (140.0, 1262.0),
        (150.0, 1334.0),
        (160.0, 1407.0),
        (170.0, 1482.0),
        (180.0, 1560.0),
        (190.0, 1640.0),
        (200.0, 1722.0),
        (210.0, 1807.0),
        (220.0, 1893.0),
        (230.0, 1982.0),
        (240.0, 2073.0),
        (250.0, 2166.0),
        (260.0, 2261.0),
        (270.0, 2357.0),
        (280.0, 2452.0),
        (290.0, 2542.0),
        (300.0, 2624.0),
    ];

    /// Straight line through the two rows around `x`, reading column `from`
    /// and returning column `to` (0 = degC, 1 = ohm); NaN outside the rows.
    fn rows_lerp(rows: &[(f64, f64)], x: f64, from: usize, to: usize) -> f64 {
        let col = |row: &(f64, f64), c: usize| if c == 0 { row.0 } else { row.1 };
        rows.windows(2)
            .find(|w| col(&w[0], from) <= x && x <= col(&w[1], from))
            .map(|w| {
                let f = (x - col(&w[0], from)) / (col(&w[1], from) - col(&w[0], from));
                col(&w[0], to) + f * (col(&w[1], to) - col(&w[0], to))
            })
            .unwrap_or(f64::NAN)
    }

    fn rows_temp(rows: &[(f64, f64)], r: f64) -> f64 {
        rows_lerp(rows, r, 1, 0)
    }

    fn rows_resistance(rows: &[(f64, f64)], t: f64) -> f64 {
        rows_lerp(rows, t, 0, 1)
    }

    /// One configuration under test: the sensor, its R_ref and the f64
    /// reference R -> T and T -> R.
    struct Case {
        name: &'static str,
        sensor: Sensor,
        reference_ohm: f32,
        temp: fn(f64) -> f64,
        resistance: fn(f64) -> f64,
        /// How far `temp` may be from the inverse of `resistance` \[K\]:
        /// the table's interpolation error against its source curve.
        source_error_k: f64,
    }

    fn cases() -> [Case; 8] {
        [
            Case {
                name: "NTC 10k B3950, R_ref 10k",
                sensor: Sensor::ntc_beta(10_000.0, 25.0, 3950.0).unwrap(),
                reference_ohm: 10_000.0,
                temp: |r| beta_temp(r, 10_000.0, 25.0, 3950.0),
                resistance: |t| beta_resistance(t, 10_000.0, 25.0, 3950.0),
                source_error_k: 0.0,
            },
            Case {
                name: "NTC 10k Steinhart-Hart, R_ref 10k",
                sensor: Sensor::ntc_steinhart_hart(SH.0 as f32, SH.1 as f32, SH.2 as f32).unwrap(),
                reference_ohm: 10_000.0,
                temp: |r| sh_temp(r, SH),
                resistance: |t| sh_resistance(t, SH),
                source_error_k: 0.0,
            },
            Case {
                name: "NTC 10k table (5 K), R_ref 10k",
                sensor: Sensor::ntc_table(sh_table()).unwrap(),
                reference_ohm: 10_000.0,
                temp: |r| table_temp(sh_table(), r),
                resistance: |t| sh_resistance(t, SH),
                source_error_k: TABLE_SOURCE_ERROR_K,
            },
            Case {
                name: "PT100, R_ref 100",
                sensor: Sensor::PT100,
                reference_ohm: 100.0,
                temp: |r| cvd_temp(r / 100.0),
                resistance: |t| 100.0 * cvd_ratio(t),
                source_error_k: 0.0,
            },
            Case {
                name: "PT100, R_ref 1k",
                sensor: Sensor::PT100,
                reference_ohm: 1000.0,
                temp: |r| cvd_temp(r / 100.0),
                resistance: |t| 100.0 * cvd_ratio(t),
                source_error_k: 0.0,
            },
            Case {
                name: "PT1000, R_ref 1k",
                sensor: Sensor::PT1000,
                reference_ohm: 1000.0,
                temp: |r| cvd_temp(r / 1000.0),
                resistance: |t| 1000.0 * cvd_ratio(t),
                source_error_k: 0.0,
            },
            Case {
                name: "KTY83-110, R_ref 1k",
                sensor: Sensor::KTY83_110,
                reference_ohm: 1000.0,
                temp: |r| rows_temp(&KTY83_ROWS, r),
                resistance: |t| rows_resistance(&KTY83_ROWS, t),
                source_error_k: 0.0,
            },
            Case {
                name: "KTY84-130, R_ref 1k",
                sensor: Sensor::KTY84_130,
                reference_ohm: 1000.0,
                temp: |r| rows_temp(&KTY84_ROWS, r),
                resistance: |t| rows_resistance(&KTY84_ROWS, t),
                source_error_k: 0.0,
            },
        ]
    }

    const TOPOLOGIES: [Topology; 2] = [Topology::SensorToGround, Topology::SensorToSupply];

    fn input(case: &Case, topology: Topology) -> ResistiveInput {
        ResistiveInput::new(
            Divider::new(topology, case.reference_ohm, BITS).unwrap(),
            case.sensor,
        )
    }

    #[test]
    fn every_in_range_count_matches_the_f64_reference() {
        for case in cases() {
            for topology in TOPOLOGIES {
                let input = input(&case, topology);
                let mut max_error_k: f64 = 0.0;
                let mut covered = 0;
                for counts in 1..FULL - 1 {
                    let r = count_resistance(topology, counts, BITS, case.reference_ohm as f64);
                    let expected_c = (case.temp)(r);
                    let got = input.convert(counts);
                    if (-40.0..=150.0).contains(&expected_c) {
                        let reading = got.unwrap_or_else(|f| {
                            panic!("{}, {topology:?}, count {counts}: {f:?}", case.name)
                        });
                        covered += 1;
                        let error_k = (reading.temp_c as f64 - expected_c).abs();
                        max_error_k = max_error_k.max(error_k);
                        assert!(
                            error_k < MAX_ERROR_K,
                            "{}, {topology:?}, count {counts}: {} vs {expected_c}",
                            case.name,
                            reading.temp_c
                        );
                        assert_eq!(reading.cold_junction_c, None);
                    } else if let Ok(reading) = got {
                        // Outside -40 .. 150 but inside the sensor's range.
                        let error_k = (reading.temp_c as f64 - expected_c).abs();
                        assert!(error_k < MAX_ERROR_K, "{} count {counts}", case.name);
                    }
                }
                assert!(covered > 100, "{}: only {covered} counts", case.name);
                println!(
                    "{:36} {topology:?}: {covered} counts in -40..150 degC, max error {max_error_k:.2e} K",
                    case.name
                );
            }
        }
    }

    #[test]
    fn rtd_matches_the_f64_reference_over_the_iec_range() {
        // Straight from resistance, so the Newton branch is exercised down to
        // -200 degC, where the C term is worth 2.4 K.
        let mut max_error_k: f64 = 0.0;
        for i in 0..=10_500 {
            let t = -200.0 + 0.1 * i as f64;
            let r = 100.0 * cvd_ratio(t);
            let expected_c = cvd_temp(r / 100.0);
            // The f32 resistance is what the conversion sees.
            let r32 = r as f32;
            let expected_c32 = cvd_temp(r32 as f64 / 100.0);
            assert!((expected_c - t).abs() < 1e-9);
            match Sensor::PT100.temp_c(r32) {
                Ok(got) => {
                    let error_k = (got as f64 - expected_c32).abs();
                    max_error_k = max_error_k.max(error_k);
                    assert!(error_k < MAX_ERROR_K, "{t} degC: {got}");
                }
                Err(fault) => {
                    // Only the f32 rounding of the range's ends may fall out.
                    assert_eq!(fault, SensorFault::OutOfRange);
                    assert!(i == 0 || i == 10_500, "{t} degC: {fault:?}");
                }
            }
        }
        println!("PT100 -200..850 degC: max error {max_error_k:.2e} K");
    }

    #[test]
    fn table_follows_its_steinhart_hart_source() {
        let sensor = Sensor::ntc_table(sh_table()).unwrap();
        let mut max_error_k: f64 = 0.0;
        for i in 0..=2050 {
            let t = -55.0 + 0.1 * i as f64;
            let r = sh_resistance(t, SH);
            if let Ok(got) = sensor.temp_c(r as f32) {
                max_error_k = max_error_k.max((got as f64 - t).abs());
            }
        }
        println!("table vs Steinhart-Hart -55..150 degC: max error {max_error_k:.2e} K");
        assert!(max_error_k < TABLE_SOURCE_ERROR_K, "{max_error_k}");
    }

    /// (case name, temperature, documented step of one count at 12 bits [K]).
    const QUANTISATION: [(&str, f64, f64); 17] = [
        ("NTC 10k B3950, R_ref 10k", -40.0, 0.142),
        ("NTC 10k B3950, R_ref 10k", 25.0, 0.022),
        ("NTC 10k B3950, R_ref 10k", 150.0, 0.578),
        ("PT100, R_ref 100", -40.0, 0.209),
        ("PT100, R_ref 100", 25.0, 0.277),
        ("PT100, R_ref 100", 150.0, 0.433),
        ("PT100, R_ref 1k", -40.0, 0.725),
        ("PT100, R_ref 1k", 25.0, 0.775),
        ("PT100, R_ref 1k", 150.0, 0.876),
        ("PT1000, R_ref 1k", -40.0, 0.209),
        ("PT1000, R_ref 1k", 25.0, 0.277),
        ("PT1000, R_ref 1k", 150.0, 0.433),
        ("KTY83-110, R_ref 1k", -40.0, 0.113),
        ("KTY83-110, R_ref 1k", 25.0, 0.127),
        ("KTY83-110, R_ref 1k", 150.0, 0.212),
        ("KTY84-130, R_ref 1k", 25.0, 0.139),
        ("KTY84-130, R_ref 1k", 150.0, 0.184),
    ];

    /// Quantise a true temperature through the divider (first principles,
    /// rounded to the nearest code) and convert it back: the end-to-end error
    /// stays within half the local step of one count.
    #[test]
    fn quantisation_steps_match_the_documented_table() {
        let mut mismatches = 0;
        for case in cases() {
            for topology in TOPOLOGIES {
                let input = input(&case, topology);
                let to_count = |t: f64| {
                    let x = node_ratio(topology, (case.resistance)(t), case.reference_ohm as f64);
                    (x * FULL as f64).round() as u32
                };
                let to_temp = |k: u32| {
                    (case.temp)(count_resistance(
                        topology,
                        k,
                        BITS,
                        case.reference_ohm as f64,
                    ))
                };
                let mut max_error_k: f64 = 0.0;
                for i in 0..=1900 {
                    let t = -40.0 + 0.1 * i as f64;
                    let k = to_count(t);
                    // The larger one-sided step (`max` skips the NaN of a
                    // neighbour beyond a table's end).
                    let step_k = (to_temp(k - 1) - to_temp(k))
                        .abs()
                        .max((to_temp(k) - to_temp(k + 1)).abs());
                    let quantised_c = to_temp(k);
                    let range = case.sensor.min_c() as f64..=case.sensor.max_c() as f64;
                    // NaN where the table has no such resistance.
                    if !range.contains(&quantised_c) {
                        // Rounding pushed a range's end (150 degC, or a
                        // table's first row) just past it.
                        assert_eq!(input.convert(k), Err(SensorFault::OutOfRange));
                        continue;
                    }
                    let got = input.convert(k).unwrap();
                    let error_k = (got.temp_c as f64 - t).abs();
                    max_error_k = max_error_k.max(error_k);
                    assert!(
                        error_k <= 0.5 * step_k * 1.05 + MAX_ERROR_K + case.source_error_k,
                        "{}, {topology:?}, {t} degC: {} (step {step_k})",
                        case.name,
                        got.temp_c
                    );
                }
                print!(
                    "{:36} {topology:?}: max quantised error {max_error_k:.3} K; step",
                    case.name
                );
                for t in [-40.0, 25.0, 150.0] {
                    let k = to_count(t);
                    let step_k = (to_temp(k - 1) - to_temp(k + 1)).abs() / 2.0;
                    print!(" {step_k:.3} K @ {t}");
                    if let Some((_, _, documented)) = QUANTISATION
                        .iter()
                        .find(|(name, at, _)| *name == case.name && *at == t)
                    {
                        if (step_k / documented - 1.0).abs() >= 0.05 {
                            mismatches += 1;
                            print!(" (documented {documented})");
                        }
                    }
                }
                println!();
            }
        }
        assert_eq!(
            mismatches, 0,
            "steps differ from QUANTISATION by 5 % or more"
        );
    }

    #[test]
    fn kty_tables_give_every_datasheet_row_back() {
        for (sensor, rows) in [
            (Sensor::KTY83_110, &KTY83_ROWS[..]),
            (Sensor::KTY84_130, &KTY84_ROWS[..]),
        ] {
            assert_eq!(sensor.min_c() as f64, rows[0].0);
            assert_eq!(sensor.max_c() as f64, rows[rows.len() - 1].0);
            for &(t, r) in rows {
                let got = sensor.temp_c(r as f32).unwrap();
                assert!((got as f64 - t).abs() < 1e-4, "{r} ohm: {got} vs {t}");
            }
            // No extrapolation past either end.
            assert_eq!(
                sensor.temp_c(rows[0].1 as f32 - 1.0),
                Err(SensorFault::OutOfRange)
            );
            let last = rows[rows.len() - 1].1 as f32;
            assert_eq!(sensor.temp_c(last + 1.0), Err(SensorFault::OutOfRange));
        }
        // The datasheets' quick-reference data: KTY83-110 R25 990 .. 1010
        // ohm, KTY84-130 R100 970 .. 1030 ohm; the typical tables sit inside.
        assert!((990.0..=1010.0).contains(&rows_resistance(&KTY83_ROWS, 25.0)));
        assert!((970.0..=1030.0).contains(&rows_resistance(&KTY84_ROWS, 100.0)));
    }

    /// The table's own accuracy: the datasheet rows off the 10 K grid
    /// (25 degC; the KTY83's 125 and 175 degC), predicted from their 10 K
    /// neighbours by the straight line the conversion draws. What is left
    /// is the curve's bend over 10 K plus the rows' 1 ohm rounding.
    #[test]
    fn kty_interpolation_between_rows_is_within_the_tables_rounding() {
        let mut worst_k: f64 = 0.0;
        for (rows, off_grid) in [
            (&KTY83_ROWS[..], &[25.0, 125.0, 175.0][..]),
            (&KTY84_ROWS[..], &[25.0][..]),
        ] {
            for &t in off_grid {
                let i = rows.iter().position(|row| row.0 == t).unwrap();
                let (below, above) = (rows[i - 1], rows.get(i + 1).copied());
                // The neighbours on the 10 K grid: 175 degC has none above,
                // so take the 10 K step below it (170 and 160 degC).
                let (a, b) = match above {
                    Some(above) => (below, above),
                    None => (rows[i - 2], below),
                };
                // Beyond the pair at 175 degC: extend its line.
                let slope_k_per_ohm = (b.0 - a.0) / (b.1 - a.1);
                let predicted_c = a.0 + (rows[i].1 - a.1) * slope_k_per_ohm;
                let error_k = (predicted_c - t).abs();
                println!("{t} degC row from its neighbours: {predicted_c:.3} degC");
                worst_k = worst_k.max(error_k);
            }
        }
        println!("KTY off-grid rows: worst {worst_k:.3} K");
        assert!(worst_k < 0.15, "{worst_k}");
    }

    fn rails(topology: Topology) -> (SensorFault, SensorFault) {
        match topology {
            Topology::SensorToGround => (SensorFault::ShortToGnd, SensorFault::OpenCircuit),
            Topology::SensorToSupply => (SensorFault::OpenCircuit, SensorFault::ShortToVcc),
        }
    }

    /// Every count of every case: rails and non-codes are faults, every
    /// reading is finite and in range.
    #[test]
    fn every_count_is_a_fault_or_a_plausible_temperature() {
        for case in cases() {
            for topology in TOPOLOGIES {
                let input = input(&case, topology);
                let (bottom, top) = rails(topology);
                assert_eq!(input.convert(0), Err(bottom), "{}", case.name);
                assert_eq!(input.convert(FULL - 1), Err(top), "{}", case.name);
                for counts in [FULL, FULL + 1, u32::MAX] {
                    assert_eq!(input.convert(counts), Err(SensorFault::InvalidData));
                }
                for counts in 0..FULL {
                    match input.convert(counts) {
                        Ok(reading) => {
                            assert!(reading.temp_c.is_finite());
                            assert!(reading.temp_c >= case.sensor.min_c());
                            assert!(reading.temp_c <= case.sensor.max_c());
                        }
                        Err(fault) => assert!(
                            counts == 0 || counts == FULL - 1 || fault == SensorFault::OutOfRange,
                            "{}, {topology:?}, {counts}: {fault:?}",
                            case.name
                        ),
                    }
                }
            }
        }
    }

    #[test]
    fn open_and_short_sensors_are_rail_faults() {
        // Resistances beyond any sensor: the ideal open and shorted sensor,
        // and a 1 mohm and 100 Mohm stand-in, through a first-principles
        // divider.
        for case in cases() {
            for topology in TOPOLOGIES {
                let input = input(&case, topology);
                let (bottom, top) = rails(topology);
                for (sensor_ohm, open) in [
                    (0.0, false),
                    (1e-3, false),
                    (1e8, true),
                    (f64::INFINITY, true),
                ] {
                    let x = if sensor_ohm.is_infinite() {
                        match topology {
                            Topology::SensorToGround => 1.0,
                            Topology::SensorToSupply => 0.0,
                        }
                    } else {
                        node_ratio(topology, sensor_ohm, case.reference_ohm as f64)
                    };
                    let counts = ((x * FULL as f64).round() as u32).min(FULL - 1);
                    let expected = match (topology, open) {
                        (Topology::SensorToGround, true) | (Topology::SensorToSupply, false) => top,
                        _ => bottom,
                    };
                    assert_eq!(
                        input.convert(counts),
                        Err(expected),
                        "{} {sensor_ohm}",
                        case.name
                    );
                }
            }
        }
    }

    #[test]
    fn rail_margin_widens_both_rails() {
        let divider = Divider::new(Topology::SensorToGround, 10_000.0, BITS)
            .and_then(|d| d.with_rail_margin(3))
            .unwrap();
        for counts in 0..=3 {
            assert_eq!(divider.resistance_ohm(counts), Err(SensorFault::ShortToGnd));
        }
        for counts in FULL - 4..FULL {
            assert_eq!(
                divider.resistance_ohm(counts),
                Err(SensorFault::OpenCircuit)
            );
        }
        assert!(divider.resistance_ohm(4).is_ok());
        assert!(divider.resistance_ohm(FULL - 5).is_ok());
        // The widest margin leaves no code between the rails; one more
        // would overlap them.
        let one_bit = Divider::new(Topology::SensorToSupply, 1.0, 1).unwrap();
        assert_eq!(one_bit.resistance_ohm(0), Err(SensorFault::OpenCircuit));
        assert_eq!(one_bit.resistance_ohm(1), Err(SensorFault::ShortToVcc));
        assert!(one_bit.with_rail_margin(0).is_ok());
        assert!(one_bit.with_rail_margin(1).is_err());
        assert!(divider.with_rail_margin(FULL / 2 - 1).is_ok());
        assert!(divider.with_rail_margin(FULL / 2).is_err());
    }

    #[test]
    fn range_limits_refuse_temperatures_outside() {
        let sensor = Sensor::PT100.with_range(0.0, 100.0).unwrap();
        assert_eq!(sensor.temp_c(100.0), Ok(0.0));
        assert!(sensor.temp_c(138.5).is_ok());
        assert_eq!(sensor.temp_c(99.9), Err(SensorFault::OutOfRange));
        assert_eq!(sensor.temp_c(138.6), Err(SensorFault::OutOfRange));
        for r in [0.0, -1.0, f32::NAN, f32::INFINITY, 1e30] {
            assert_eq!(Sensor::PT100.temp_c(r), Err(SensorFault::OutOfRange), "{r}");
        }
        let ntc = Sensor::ntc_beta(10_000.0, 25.0, 3950.0).unwrap();
        for r in [1e-30, 1e30, f32::MIN_POSITIVE] {
            assert_eq!(ntc.temp_c(r), Err(SensorFault::OutOfRange), "{r}");
        }
        // The table does not extrapolate.
        let table = Sensor::ntc_table(sh_table()).unwrap();
        let first = sh_table()[0].resistance_ohm;
        assert_eq!(table.temp_c(first * 1.01), Err(SensorFault::OutOfRange));
        assert!(table.temp_c(first).is_ok());
    }

    #[test]
    fn builders_reject_invalid_parameters() {
        let invalid = |r: Result<Sensor, BuildError>, name| {
            assert_eq!(r, Err(BuildError::InvalidParameter { name }));
        };
        let divider_invalid = |r: Result<Divider, BuildError>, name| {
            assert_eq!(r, Err(BuildError::InvalidParameter { name }));
        };
        use Topology::SensorToGround as G;
        for r in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            divider_invalid(Divider::new(G, r, 12), "reference_resistance_ohm");
            invalid(Sensor::rtd(r), "r0_ohm");
            invalid(Sensor::ntc_beta(r, 25.0, 3950.0), "r0_ohm");
            invalid(Sensor::ntc_beta(10e3, 25.0, r), "beta_k");
        }
        for bits in [0, 25, 32, 255] {
            divider_invalid(Divider::new(G, 1.0, bits), "bits");
        }
        assert!(Divider::new(G, 1.0, 1).is_ok());
        assert!(Divider::new(G, 1.0, 24).is_ok());
        invalid(Sensor::ntc_beta(10e3, -273.15, 3950.0), "t0_c");
        invalid(Sensor::ntc_beta(10e3, f32::NAN, 3950.0), "t0_c");
        invalid(Sensor::ntc_steinhart_hart(f32::NAN, 1e-4, 1e-7), "a");
        invalid(Sensor::ntc_steinhart_hart(1e-3, 0.0, 1e-7), "b");
        invalid(Sensor::ntc_steinhart_hart(1e-3, 1e-4, -1e-7), "c");
        invalid(Sensor::ntc_steinhart_hart(1e-3, 1e-4, f32::INFINITY), "c");
        invalid(Sensor::PT100.with_range(-201.0, 0.0), "min_c");
        invalid(Sensor::PT100.with_range(0.0, 851.0), "max_c");
        invalid(Sensor::PT100.with_range(10.0, 10.0), "max_c");
        invalid(Sensor::PT100.with_range(f32::NAN, 10.0), "min_c");
        invalid(Sensor::PT1000.with_range(0.0, f32::NAN), "max_c");
        invalid(Sensor::ntc_table(&[]), "table");
        static ONE: [TablePoint; 1] = [TablePoint {
            temp_c: 25.0,
            resistance_ohm: 10e3,
        }];
        invalid(Sensor::ntc_table(&ONE), "table");
        static RISING: [TablePoint; 2] = [
            TablePoint {
                temp_c: 0.0,
                resistance_ohm: 10e3,
            },
            TablePoint {
                temp_c: 25.0,
                resistance_ohm: 20e3,
            },
        ];
        invalid(Sensor::ntc_table(&RISING), "table");
        static UNSORTED: [TablePoint; 2] = [
            TablePoint {
                temp_c: 25.0,
                resistance_ohm: 20e3,
            },
            TablePoint {
                temp_c: 0.0,
                resistance_ohm: 10e3,
            },
        ];
        invalid(Sensor::ntc_table(&UNSORTED), "table");
        // A PTC table must rise; an NTC's falling table is refused.
        invalid(Sensor::ptc_table(&UNSORTED), "table");
        invalid(Sensor::ptc_table(sh_table()), "table");
        invalid(Sensor::ntc_table(&KTY84_130_TABLE), "table");
        invalid(Sensor::ptc_table(&ONE), "table");
        assert!(Sensor::ptc_table(&RISING).is_ok());
        let table = Sensor::ntc_table(sh_table()).unwrap();
        invalid(table.with_range(-60.0, 100.0), "min_c");
        assert!(table.with_range(-40.0, 150.0).is_ok());
        let ntc = Sensor::ntc_beta(10e3, 25.0, 3950.0).unwrap();
        assert_eq!((ntc.min_c(), ntc.max_c()), NTC_DEFAULT_RANGE_C);
        invalid(ntc.with_range(-300.0, 0.0), "min_c");
    }

    #[test]
    fn builders_work_in_const_context() {
        const INPUT: Result<ResistiveInput, BuildError> =
            match Divider::new(Topology::SensorToSupply, 1000.0, 16) {
                Ok(divider) => match Sensor::PT1000.with_range(-40.0, 200.0) {
                    Ok(sensor) => Ok(ResistiveInput::new(divider, sensor)),
                    Err(e) => Err(e),
                },
                Err(e) => Err(e),
            };
        let input = INPUT.unwrap();
        assert_eq!(input.divider().bits(), 16);
        assert_eq!(input.sensor().min_c(), -40.0);
        // Half scale: R = R_ref = R0, so 0 degC.
        assert_eq!(input.convert(1 << 15).map(|r| r.temp_c), Ok(0.0));
    }

    fn any_topology() -> impl Strategy<Value = Topology> {
        prop_oneof![
            Just(Topology::SensorToGround),
            Just(Topology::SensorToSupply)
        ]
    }

    fn any_sensor() -> impl Strategy<Value = Sensor> {
        prop_oneof![
            (1.0f32..1e6, -50.0f32..100.0, 1000.0f32..6000.0)
                .prop_map(|(r0, t0, beta)| Sensor::ntc_beta(r0, t0, beta).unwrap()),
            Just(Sensor::ntc_steinhart_hart(SH.0 as f32, SH.1 as f32, SH.2 as f32).unwrap()),
            Just(Sensor::ntc_table(sh_table()).unwrap()),
            (1.0f32..1e5).prop_map(|r0| Sensor::rtd(r0).unwrap()),
            Just(Sensor::KTY83_110),
            Just(Sensor::KTY84_130),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        #[test]
        fn convert_never_panics_and_never_returns_a_bad_temperature(
            topology in any_topology(),
            sensor in any_sensor(),
            log_reference in -3.0f32..9.0,
            bits in 1u8..=24,
            margin_fraction in 0.0f64..1.0,
            counts in prop_oneof![any::<u32>(), 0u32..4096, Just(0u32)],
        ) {
            let divider = Divider::new(topology, libm::powf(10.0, log_reference), bits).unwrap();
            let full = divider.full_scale_counts();
            let margin = ((full / 2 - 1) as f64 * margin_fraction * 0.01) as u32;
            let divider = divider.with_rail_margin(margin).unwrap();
            let input = ResistiveInput::new(divider, sensor);
            let (bottom, top) = rails(topology);
            let result = input.convert(counts);
            match result {
                Ok(reading) => {
                    prop_assert!(reading.temp_c.is_finite());
                    prop_assert!(reading.temp_c >= sensor.min_c() && reading.temp_c <= sensor.max_c());
                    prop_assert!(counts > margin && counts < full - 1 - margin);
                }
                Err(fault) if counts >= full => prop_assert_eq!(fault, SensorFault::InvalidData),
                Err(fault) if counts <= margin => prop_assert_eq!(fault, bottom),
                Err(fault) if counts >= full - 1 - margin => prop_assert_eq!(fault, top),
                Err(fault) => prop_assert_eq!(fault, SensorFault::OutOfRange),
            }
            // The extreme codes are always faults.
            prop_assert_eq!(input.convert(0), Err(bottom));
            prop_assert_eq!(input.convert(full - 1), Err(top));
        }
    }
}
