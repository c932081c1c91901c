//! MAX31865 RTD-to-digital converter (PT100 / PT1000 with a reference
//! resistor on the board).
//!
//! # Register map
//!
//! One byte per address; the first byte of a transaction is the address, with
//! bit 7 set for a write (`address | 0x80`). Consecutive bytes of the same
//! transaction go to (or come from) consecutive addresses.
//!
//! | addr | name | content |
//! |---|---|---|
//! | 0x00 | CONFIG | VBIAS (7), auto conversion (6), 1-shot (5), 3-wire (4), fault detection cycle (3:2), fault status clear (1), 50 Hz filter (0) |
//! | 0x01, 0x02 | RTD MSB, LSB | 15-bit ratio R_RTD / R_REF in 15:1 (full scale 2^15), fault bit in 0 |
//! | 0x03..0x06 | HFT MSB/LSB, LFT MSB/LSB | high and low fault thresholds on the RTD code (reset 0xFFFF and 0x0000: never trip) |
//! | 0x07 | FAULT STATUS | RTD high threshold (7), RTD low threshold (6), REFIN- > 0.85 VBIAS (5), REFIN- < 0.85 VBIAS, FORCE- open (4), RTDIN- < 0.85 VBIAS, FORCE- open (3), over/under-voltage (2); 1:0 unused |
//!
//! The chip measures the ratio of the RTD to the reference resistor; the
//! temperature comes from [`resistive::Sensor`](super::resistive::Sensor)
//! (Callendar-Van Dusen for platinum), so it has the accuracy of that module
//! plus the 15-bit quantisation (0.03 K per count for a PT100 with a 430 ohm
//! reference).
//!
//! # Faults in [`decode`]
//!
//! In order; the first that applies is returned:
//!
//! 1. FAULT STATUS bits 1:0 set: [`SensorFault::InvalidData`] (unused bits:
//!    not a working chip).
//! 2. Bits 5, 4 or 3 (the voltage checks of the fault detection cycle: an
//!    open RTD, force or reference connection): [`SensorFault::OpenCircuit`].
//! 3. Bit 2 (an input above VDD or below GND): [`SensorFault::ShortToVcc`],
//!    as the MAX31856's out-of-rails flag.
//! 4. Bits 7 or 6 (the code crossed a fault threshold):
//!    [`SensorFault::OutOfRange`].
//! 5. The RTD register's fault bit without any status bit:
//!    [`SensorFault::InvalidData`].
//! 6. Code 0 (no voltage across the RTD): [`SensorFault::ShortToGnd`]; code
//!    0x7FFF (R_RTD at or above R_REF, an open RTD with the detection cycle
//!    not run): [`SensorFault::OpenCircuit`].
//! 7. A temperature outside the sensor's range: [`SensorFault::OutOfRange`].
//!
//! The status bits latch: once set they stay until [`Max31865::clear_faults`].
//! This driver does not run the chip's fault detection cycle (CONFIG 3:2);
//! bits 5:3 are set only if the user runs it.

use embedded_hal::spi::{Mode, Operation, SpiDevice, MODE_1};

use super::resistive::Sensor;
use super::{Error, Reading, SensorFault, SensorResult};
use crate::error::BuildError;

/// SPI mode of the MAX31865 (it also accepts mode 3).
pub const SPI_MODE: Mode = MODE_1;
/// Highest SPI clock the MAX31865 supports \[Hz\].
pub const MAX_SPI_FREQUENCY_HZ: u32 = 5_000_000;
/// RTD code that stands for R_RTD = R_REF.
pub const FULL_SCALE_COUNTS: u32 = 1 << 15;

/// First register of the block [`decode_block`] expects (RTD MSB).
pub const READ_BLOCK_START: u8 = RTD_MSB;
/// Length of that block: RTD MSB, RTD LSB, the four threshold bytes, FAULT
/// STATUS.
pub const READ_BLOCK_LEN: usize = 7;

const WRITE: u8 = 0x80;
const CONFIG: u8 = 0x00;
const RTD_MSB: u8 = 0x01;

const CONFIG_VBIAS: u8 = 0x80;
const CONFIG_AUTO_CONVERSION: u8 = 0x40;
const CONFIG_THREE_WIRE: u8 = 0x10;
const CONFIG_FAULT_CLEAR: u8 = 0x02;
const CONFIG_FILTER_50HZ: u8 = 0x01;
/// CONFIG bits that read back as written (1-shot, the detection cycle and
/// the fault clear end by themselves).
const CONFIG_PERSISTENT: u8 = CONFIG_VBIAS | CONFIG_AUTO_CONVERSION | CONFIG_THREE_WIRE | 0x01;

const STATUS_HIGH_THRESHOLD: u8 = 0x80;
const STATUS_LOW_THRESHOLD: u8 = 0x40;
const STATUS_OPEN: u8 = 0x20 | 0x10 | 0x08;
const STATUS_OVER_UNDER_VOLTAGE: u8 = 0x04;
const STATUS_UNUSED: u8 = 0x03;

const RTD_FAULT: u16 = 0x0001;
const CODE_MAX: u16 = 0x7FFF;

/// How the RTD is wired to the chip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Wiring {
    /// Two wires (the lead resistance adds to the RTD's).
    #[default]
    TwoWire,
    /// Three wires (the chip cancels one lead).
    ThreeWire,
    /// Four wires (Kelvin connection).
    FourWire,
}

/// Mains rejection of the chip's filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MainsFilter {
    /// Reject 50 Hz.
    Hz50,
    /// Reject 60 Hz (reset default).
    #[default]
    Hz60,
}

/// The ratio-to-temperature half of the chip: its reference resistor and the
/// sensor on it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Converter {
    reference_resistance_ohm: f32,
    sensor: Sensor,
}

impl Converter {
    /// The board's reference resistor `reference_resistance_ohm` \[ohm\]
    /// (430 ohm on PT100 boards, 4300 ohm on PT1000 boards) and the sensor.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] if the resistance is not finite or
    /// not strictly positive.
    pub const fn new(reference_resistance_ohm: f32, sensor: Sensor) -> Result<Self, BuildError> {
        if !reference_resistance_ohm.is_finite() || reference_resistance_ohm <= 0.0 {
            return Err(BuildError::InvalidParameter {
                name: "reference_resistance_ohm",
            });
        }
        Ok(Self {
            reference_resistance_ohm,
            sensor,
        })
    }

    /// The reference resistor \[ohm\].
    pub const fn reference_resistance_ohm(&self) -> f32 {
        self.reference_resistance_ohm
    }

    /// The sensor.
    pub const fn sensor(&self) -> &Sensor {
        &self.sensor
    }
}

/// Decode the RTD register pair (`rtd`: MSB first) and the FAULT STATUS
/// register ([`Reading::cold_junction_c`] `None`: an RTD has no cold
/// junction).
///
/// Needs no bus, so DMA users can call it on their own buffer.
///
/// # Errors
/// The fault the registers report, in the order of the
/// [module documentation](self).
pub fn decode(converter: &Converter, rtd: u16, fault_status: u8) -> SensorResult {
    if fault_status & STATUS_UNUSED != 0 {
        return Err(SensorFault::InvalidData);
    }
    if fault_status & STATUS_OPEN != 0 {
        return Err(SensorFault::OpenCircuit);
    }
    if fault_status & STATUS_OVER_UNDER_VOLTAGE != 0 {
        return Err(SensorFault::ShortToVcc);
    }
    if fault_status & (STATUS_HIGH_THRESHOLD | STATUS_LOW_THRESHOLD) != 0 {
        return Err(SensorFault::OutOfRange);
    }
    if rtd & RTD_FAULT != 0 {
        return Err(SensorFault::InvalidData);
    }
    let code = rtd >> 1;
    if code == 0 {
        return Err(SensorFault::ShortToGnd);
    }
    if code == CODE_MAX {
        return Err(SensorFault::OpenCircuit);
    }
    // The code is below 2^15: exact in f32.
    let resistance_ohm =
        converter.reference_resistance_ohm * code as f32 / FULL_SCALE_COUNTS as f32;
    let temp_c = converter.sensor.temp_c(resistance_ohm)?;
    Ok(Reading::new(temp_c))
}

/// Decode the block RTD MSB .. FAULT STATUS as [`Max31865::read_raw`]
/// returns it.
///
/// # Errors
/// As [`decode`].
pub fn decode_block(converter: &Converter, block: &[u8; READ_BLOCK_LEN]) -> SensorResult {
    let [msb, lsb, _, _, _, _, status] = *block;
    decode(converter, u16::from_be_bytes([msb, lsb]), status)
}

/// MAX31865 driver on an embedded-hal 1.0 SPI device (the device owns chip
/// select).
#[derive(Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Max31865<SPI> {
    spi: SPI,
    converter: Converter,
    config: u8,
}

impl<SPI> Max31865<SPI> {
    /// Wrap the SPI device. No bus traffic until [`configure`](Self::configure).
    pub const fn new(spi: SPI, converter: Converter) -> Self {
        Self {
            spi,
            converter,
            config: 0,
        }
    }

    /// Give the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }
}

impl<SPI: SpiDevice> Max31865<SPI> {
    /// Bias on, automatic conversion, the given wiring and mains filter,
    /// latched faults cleared; then read CONFIG back.
    ///
    /// # Errors
    /// [`Error::Bus`] if a transfer failed; [`Error::Sensor`] with
    /// [`SensorFault::InvalidData`] if CONFIG does not read back as written
    /// (no chip, or a broken bus).
    pub fn configure(
        &mut self,
        wiring: Wiring,
        filter: MainsFilter,
    ) -> Result<(), Error<SPI::Error>> {
        let mut config = CONFIG_VBIAS | CONFIG_AUTO_CONVERSION;
        if wiring == Wiring::ThreeWire {
            config |= CONFIG_THREE_WIRE;
        }
        if filter == MainsFilter::Hz50 {
            config |= CONFIG_FILTER_50HZ;
        }
        self.config = config;
        self.spi
            .write(&[WRITE | CONFIG, config | CONFIG_FAULT_CLEAR])
            .map_err(Error::Bus)?;
        let mut actual = [0u8];
        self.spi
            .transaction(&mut [Operation::Write(&[CONFIG]), Operation::Read(&mut actual)])
            .map_err(Error::Bus)?;
        if actual[0] & CONFIG_PERSISTENT != config {
            return Err(Error::Sensor(SensorFault::InvalidData));
        }
        Ok(())
    }

    /// Clear the latched fault status (the configuration is kept).
    ///
    /// # Errors
    /// The SPI device's error if the transfer failed.
    pub fn clear_faults(&mut self) -> Result<(), SPI::Error> {
        self.spi
            .write(&[WRITE | CONFIG, self.config | CONFIG_FAULT_CLEAR])
    }

    /// Read and decode the RTD ratio and the fault status (one 8-byte
    /// transaction).
    ///
    /// # Errors
    /// [`Error::Bus`] if the transfer failed; [`Error::Sensor`] with the
    /// fault [`decode`] found otherwise.
    pub fn read(&mut self) -> Result<Reading, Error<SPI::Error>> {
        let block = self.read_raw().map_err(Error::Bus)?;
        decode_block(&self.converter, &block).map_err(Error::Sensor)
    }

    /// Read the raw block [`decode_block`] takes, for logging and
    /// diagnostics.
    ///
    /// # Errors
    /// The SPI device's error if the transfer failed.
    pub fn read_raw(&mut self) -> Result<[u8; READ_BLOCK_LEN], SPI::Error> {
        let mut block = [0u8; READ_BLOCK_LEN];
        self.spi.transaction(&mut [
            Operation::Write(&[READ_BLOCK_START]),
            Operation::Read(&mut block),
        ])?;
        Ok(block)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensors::test_support::FailingSpi;
    use embedded_hal::spi::ErrorKind;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction};
    use proptest::prelude::*;

    fn pt100() -> Converter {
        Converter::new(430.0, Sensor::PT100).unwrap()
    }

    /// IEC 60751 forward above 0 degC, in f64, for the expected codes.
    fn pt100_ohm(t: f64) -> f64 {
        100.0 * (1.0 + 3.9083e-3 * t - 5.775e-7 * t * t)
    }

    fn rtd_word(t: f64) -> u16 {
        ((pt100_ohm(t) / 430.0 * 32768.0).round() as u16) << 1
    }

    #[test]
    fn decodes_pt100_codes_to_within_one_count() {
        // One count is 430/32768 ohm: 0.034 K at 0 degC.
        for t in [0.0, 25.0, 100.0, 150.0, 400.0] {
            let reading = decode(&pt100(), rtd_word(t), 0).unwrap();
            assert!((reading.temp_c as f64 - t).abs() < 0.02, "{t}: {reading:?}");
            assert_eq!(reading.cold_junction_c, None);
        }
        // Half a count is 0.017 K at 0 degC: the bound above is tight enough
        // to catch a code taken from the wrong bits (`rtd` instead of
        // `rtd >> 1` doubles the ratio).
    }

    #[test]
    fn each_status_bit_maps_to_its_fault() {
        let good = rtd_word(25.0);
        for (status, fault) in [
            (0x80, SensorFault::OutOfRange),
            (0x40, SensorFault::OutOfRange),
            (0x20, SensorFault::OpenCircuit),
            (0x10, SensorFault::OpenCircuit),
            (0x08, SensorFault::OpenCircuit),
            (0x04, SensorFault::ShortToVcc),
            (0x02, SensorFault::InvalidData),
            (0x01, SensorFault::InvalidData),
            // Wiring faults before thresholds.
            (0x88, SensorFault::OpenCircuit),
            (0x84, SensorFault::ShortToVcc),
        ] {
            assert_eq!(decode(&pt100(), good | RTD_FAULT, status), Err(fault));
            assert_eq!(decode(&pt100(), good, status), Err(fault));
        }
    }

    #[test]
    fn rtd_codes_at_the_rails_are_faults() {
        assert_eq!(decode(&pt100(), 0, 0), Err(SensorFault::ShortToGnd));
        assert_eq!(decode(&pt100(), 0xFFFE, 0), Err(SensorFault::OpenCircuit));
        assert_eq!(decode(&pt100(), 0xFFFF, 0), Err(SensorFault::InvalidData));
        assert_eq!(
            decode(&pt100(), rtd_word(25.0) | RTD_FAULT, 0),
            Err(SensorFault::InvalidData)
        );
        // 2 ohm: far below -200 degC.
        assert_eq!(
            decode(&pt100(), ((2.0f64 / 430.0 * 32768.0) as u16) << 1, 0),
            Err(SensorFault::OutOfRange)
        );
    }

    #[test]
    fn converter_rejects_invalid_reference() {
        for r in [0.0, -430.0, f32::NAN, f32::INFINITY] {
            assert_eq!(
                Converter::new(r, Sensor::PT100),
                Err(BuildError::InvalidParameter {
                    name: "reference_resistance_ohm"
                })
            );
        }
    }

    #[test]
    fn configure_writes_clears_and_verifies() {
        let expectations = [
            Transaction::transaction_start(),
            Transaction::write_vec(vec![0x80, 0xC0 | 0x10 | 0x01 | 0x02]),
            Transaction::transaction_end(),
            Transaction::transaction_start(),
            Transaction::write(0x00),
            Transaction::read(0xD1),
            Transaction::transaction_end(),
            Transaction::transaction_start(),
            Transaction::write_vec(vec![0x80, 0xD3]),
            Transaction::transaction_end(),
        ];
        let mut sensor = Max31865::new(Mock::new(&expectations), pt100());
        assert_eq!(
            sensor.configure(Wiring::ThreeWire, MainsFilter::Hz50),
            Ok(())
        );
        assert_eq!(sensor.clear_faults(), Ok(()));
        sensor.release().done();
    }

    #[test]
    fn configure_detects_a_chip_that_does_not_answer() {
        let expectations = [
            Transaction::transaction_start(),
            Transaction::write_vec(vec![0x80, 0xC2]),
            Transaction::transaction_end(),
            Transaction::transaction_start(),
            Transaction::write(0x00),
            Transaction::read(0xFF),
            Transaction::transaction_end(),
        ];
        let mut sensor = Max31865::new(Mock::new(&expectations), pt100());
        assert_eq!(
            sensor.configure(Wiring::FourWire, MainsFilter::Hz60),
            Err(Error::Sensor(SensorFault::InvalidData))
        );
        sensor.release().done();
    }

    #[test]
    fn read_fetches_the_block_in_one_transaction() {
        let [msb, lsb] = rtd_word(100.0).to_be_bytes();
        let expectations = [
            Transaction::transaction_start(),
            Transaction::write(0x01),
            Transaction::read_vec(vec![msb, lsb, 0xFF, 0xFF, 0x00, 0x00, 0x00]),
            Transaction::transaction_end(),
            Transaction::transaction_start(),
            Transaction::write(0x01),
            Transaction::read_vec(vec![msb, lsb | 1, 0xFF, 0xFF, 0x00, 0x00, 0x08]),
            Transaction::transaction_end(),
        ];
        let mut sensor = Max31865::new(Mock::new(&expectations), pt100());
        let reading = sensor.read().unwrap();
        assert!((reading.temp_c - 100.0).abs() < 0.02, "{reading:?}");
        assert_eq!(sensor.read(), Err(Error::Sensor(SensorFault::OpenCircuit)));
        sensor.release().done();
    }

    #[test]
    fn bus_errors_are_bus_errors() {
        let mut sensor = Max31865::new(FailingSpi, pt100());
        assert_eq!(sensor.read(), Err(Error::Bus(ErrorKind::Other)));
        assert_eq!(
            sensor.configure(Wiring::TwoWire, MainsFilter::Hz60),
            Err(Error::Bus(ErrorKind::Other))
        );
        assert_eq!(sensor.clear_faults(), Err(ErrorKind::Other));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        #[test]
        fn decode_never_panics_and_never_returns_a_bad_temperature(
            rtd in any::<u16>(),
            status in any::<u8>(),
            reference in 1.0f32..1e5,
        ) {
            let converter = Converter::new(reference, Sensor::PT100).unwrap();
            if let Ok(reading) = decode(&converter, rtd, status) {
                prop_assert_eq!(status, 0);
                prop_assert_eq!(rtd & RTD_FAULT, 0);
                prop_assert!(reading.temp_c.is_finite());
                prop_assert!((-200.0..=850.0).contains(&reading.temp_c));
            }
            if status != 0 || rtd >> 1 == 0 || rtd >> 1 == CODE_MAX {
                prop_assert!(decode(&converter, rtd, status).is_err());
            }
        }
    }
}
