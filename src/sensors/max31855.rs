//! MAX31855 cold-junction-compensated thermocouple-to-digital converter.
//!
//! # Frame format
//!
//! The chip has no registers and no input: every read clocks out one 32-bit
//! frame, most significant bit first.
//!
//! | bits | content |
//! |---|---|
//! | D31..D18 | thermocouple temperature, 14-bit two's complement, 0.25 degC LSB (-2048 .. +2047.75 degC) |
//! | D17 | reserved, always 0 |
//! | D16 | fault: 1 when any of SCV, SCG, OC is set |
//! | D15..D4 | cold-junction (die) temperature, 12-bit two's complement, 0.0625 degC LSB (-128 .. +127.9375 degC) |
//! | D3 | reserved, always 0 |
//! | D2 | SCV: thermocouple shorted to VCC |
//! | D1 | SCG: thermocouple shorted to GND |
//! | D0 | OC: thermocouple open |
//!
//! The thermocouple value is already cold-junction compensated, but *not*
//! linearised: the chip assumes a constant Seebeck coefficient for its
//! thermocouple type (MAX31855K, J, N, T, E, R, S), so away from room
//! temperature the value deviates from the NIST tables by up to a few kelvin.
//!
//! # Fault handling in [`decode`]
//!
//! * A reserved bit set is [`SensorFault::InvalidData`]: the frame is not
//!   from a working chip (a floating or pulled-up MISO reads `0xFFFF_FFFF`).
//! * Otherwise any of OC, SCG, SCV is the matching fault (OC first, then SCG,
//!   then SCV, if several are set), even if D16 is clear: a flagged reading is
//!   never used.
//! * D16 without any cause bit is [`SensorFault::InvalidData`].
//!
//! A MISO held low reads `0x0000_0000`, a valid 0 degC / 0 degC frame that no
//! format check can catch; the stuck check of [`check`](super::check) does,
//! as soon as the estimate moves.
//!
//! # Timing
//!
//! Pulling CS low aborts the conversion in progress, and a conversion takes up
//! to 100 ms. Read no more often than every 100 ms (for example from a slow
//! task, handing the [`Reading`] to the 1 ms loop): polled every control tick
//! the chip never finishes a conversion and keeps returning the same frame.

use embedded_hal::spi::{Mode, SpiDevice, MODE_0};

use super::{Error, Reading, SensorFault};

/// SPI mode of the MAX31855: clock idles low, data sampled on the rising
/// edge.
pub const SPI_MODE: Mode = MODE_0;
/// Highest SPI clock the MAX31855 supports \[Hz\].
pub const MAX_SPI_FREQUENCY_HZ: u32 = 5_000_000;
/// Longest conversion time \[ms\]; reading more often aborts conversions.
pub const MAX_CONVERSION_TIME_MS: u32 = 100;

/// Weight of one LSB of the thermocouple temperature \[degC\].
pub const THERMOCOUPLE_LSB_C: f32 = 0.25;
/// Weight of one LSB of the cold-junction temperature \[degC\].
pub const COLD_JUNCTION_LSB_C: f32 = 0.0625;

const OPEN_CIRCUIT: u32 = 1 << 0;
const SHORT_TO_GND: u32 = 1 << 1;
const SHORT_TO_VCC: u32 = 1 << 2;
const RESERVED: u32 = (1 << 17) | (1 << 3);
const FAULT: u32 = 1 << 16;

/// Decode one frame, as clocked out of the chip (D31 first, so the four bytes
/// big-endian).
///
/// Needs no bus, so DMA users can call it on their own buffer.
///
/// # Errors
/// The fault the frame reports, or [`SensorFault::InvalidData`] for a frame
/// that breaks the format (see the [module documentation](self)).
pub fn decode(frame: u32) -> Result<Reading, SensorFault> {
    if frame & RESERVED != 0 {
        return Err(SensorFault::InvalidData);
    }
    if frame & OPEN_CIRCUIT != 0 {
        return Err(SensorFault::OpenCircuit);
    }
    if frame & SHORT_TO_GND != 0 {
        return Err(SensorFault::ShortToGnd);
    }
    if frame & SHORT_TO_VCC != 0 {
        return Err(SensorFault::ShortToVcc);
    }
    if frame & FAULT != 0 {
        return Err(SensorFault::InvalidData);
    }

    // Arithmetic shifts of the reinterpreted frame sign-extend each field.
    let signed = frame as i32;
    let thermocouple_code = signed >> 18;
    let cold_junction_code = (signed << 16) >> 20;
    // Both codes fit in 14 bits, so the conversion to f32 and the scaling by
    // a power of two are exact.
    Ok(Reading {
        temp_c: thermocouple_code as f32 * THERMOCOUPLE_LSB_C,
        cold_junction_c: Some(cold_junction_code as f32 * COLD_JUNCTION_LSB_C),
    })
}

/// MAX31855 driver on an embedded-hal 1.0 SPI device (the device owns chip
/// select).
#[derive(Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Max31855<SPI> {
    spi: SPI,
}

impl<SPI> Max31855<SPI> {
    /// Wrap the SPI device. No bus traffic: the chip needs no configuration.
    pub const fn new(spi: SPI) -> Self {
        Self { spi }
    }

    /// Give the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }
}

impl<SPI: SpiDevice> Max31855<SPI> {
    /// Read and decode one frame (one 4-byte SPI transaction).
    ///
    /// # Errors
    /// [`Error::Bus`] if the transfer failed; [`Error::Sensor`] with the fault
    /// [`decode`] found otherwise.
    pub fn read(&mut self) -> Result<Reading, Error<SPI::Error>> {
        let frame = self.read_frame().map_err(Error::Bus)?;
        decode(frame).map_err(Error::Sensor)
    }

    /// Read one raw frame without decoding it, for logging and diagnostics.
    ///
    /// # Errors
    /// The SPI device's error if the transfer failed.
    pub fn read_frame(&mut self) -> Result<u32, SPI::Error> {
        let mut bytes = [0u8; 4];
        self.spi.read(&mut bytes)?;
        Ok(u32::from_be_bytes(bytes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensors::test_support::FailingSpi;
    use embedded_hal::spi::ErrorKind;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction};
    use proptest::prelude::*;

    /// A frame from the datasheet's bit patterns (Tables 4 and 5) plus the
    /// low fault nibble.
    fn frame(thermocouple_bits: u32, cold_junction_bits: u32, faults: u32) -> u32 {
        (thermocouple_bits << 18) | (cold_junction_bits << 4) | faults
    }

    /// The datasheet's thermocouple examples: (D31..D18, degC).
    // Grouped as the datasheet prints them, so they can be checked by eye.
    #[allow(clippy::unusual_byte_groupings)]
    const THERMOCOUPLE_EXAMPLES: [(u32, f32); 8] = [
        (0b0110_0100_0000_00, 1600.0),
        (0b0011_1110_1000_00, 1000.0),
        (0b0000_0110_0100_11, 100.75),
        (0b0000_0001_1001_00, 25.0),
        (0b0000_0000_0000_00, 0.0),
        (0b1111_1111_1111_11, -0.25),
        (0b1111_1111_1111_00, -1.0),
        (0b1111_0000_0110_00, -250.0),
    ];

    /// The datasheet's cold-junction examples: (D15..D4, degC).
    const COLD_JUNCTION_EXAMPLES: [(u32, f32); 8] = [
        (0b0111_1111_0000, 127.0),
        (0b0110_0100_1001, 100.5625),
        (0b0001_1001_0000, 25.0),
        (0b0000_0000_0000, 0.0),
        (0b1111_1111_1111, -0.0625),
        (0b1111_1111_0000, -1.0),
        (0b1110_1100_0000, -20.0),
        (0b1100_1001_0000, -55.0),
    ];

    #[test]
    fn decodes_every_datasheet_example_pair() {
        for (tc_bits, tc_c) in THERMOCOUPLE_EXAMPLES {
            for (cj_bits, cj_c) in COLD_JUNCTION_EXAMPLES {
                assert_eq!(
                    decode(frame(tc_bits, cj_bits, 0)),
                    Ok(Reading {
                        temp_c: tc_c,
                        cold_junction_c: Some(cj_c)
                    }),
                    "tc {tc_bits:014b} cj {cj_bits:012b}"
                );
            }
        }
    }

    #[test]
    fn extremes_of_both_fields() {
        let max = decode(frame(0x1FFF, 0x7FF, 0)).unwrap();
        assert_eq!((max.temp_c, max.cold_junction_c), (2047.75, Some(127.9375)));
        let min = decode(frame(0x2000, 0x800, 0)).unwrap();
        assert_eq!((min.temp_c, min.cold_junction_c), (-2048.0, Some(-128.0)));
    }

    #[test]
    fn each_fault_bit_maps_to_its_fault() {
        // A faulted frame from a real chip: +25 degC die, garbage TC value.
        let base = frame(0x1FFF, 0b0001_1001_0000, 0);
        for (bits, fault) in [
            (OPEN_CIRCUIT, SensorFault::OpenCircuit),
            (SHORT_TO_GND, SensorFault::ShortToGnd),
            (SHORT_TO_VCC, SensorFault::ShortToVcc),
        ] {
            assert_eq!(decode(base | FAULT | bits), Err(fault));
            // A cause bit without D16 is still a fault, never a reading.
            assert_eq!(decode(base | bits), Err(fault));
        }
    }

    #[test]
    fn several_fault_bits_report_open_first_then_gnd() {
        assert_eq!(decode(FAULT | 0b111), Err(SensorFault::OpenCircuit));
        assert_eq!(decode(FAULT | 0b110), Err(SensorFault::ShortToGnd));
        assert_eq!(decode(FAULT | 0b101), Err(SensorFault::OpenCircuit));
    }

    #[test]
    fn format_violations_are_invalid_data() {
        assert_eq!(decode(FAULT), Err(SensorFault::InvalidData));
        assert_eq!(decode(1 << 17), Err(SensorFault::InvalidData));
        assert_eq!(decode(1 << 3), Err(SensorFault::InvalidData));
        // MISO floating high.
        assert_eq!(decode(u32::MAX), Err(SensorFault::InvalidData));
        // MISO held low is indistinguishable from 0 degC / 0 degC.
        assert_eq!(
            decode(0),
            Ok(Reading {
                temp_c: 0.0,
                cold_junction_c: Some(0.0)
            })
        );
    }

    #[test]
    fn driver_reads_one_four_byte_frame() {
        // +100.75 degC, +25.0 degC die.
        let bytes = frame(0x193, 0x190, 0).to_be_bytes();
        let expectations = [
            Transaction::transaction_start(),
            Transaction::read_vec(bytes.to_vec()),
            Transaction::transaction_end(),
        ];
        let mut sensor = Max31855::new(Mock::new(&expectations));
        assert_eq!(
            sensor.read(),
            Ok(Reading {
                temp_c: 100.75,
                cold_junction_c: Some(25.0)
            })
        );
        sensor.release().done();
    }

    #[test]
    fn driver_reports_sensor_faults_as_sensor_errors() {
        let mut expectations = Vec::new();
        for faults in [
            FAULT | OPEN_CIRCUIT,
            FAULT | SHORT_TO_GND,
            FAULT | SHORT_TO_VCC,
        ] {
            expectations.push(Transaction::transaction_start());
            expectations.push(Transaction::read_vec(
                frame(0, 0b1100_1001_0000, faults).to_be_bytes().to_vec(),
            ));
            expectations.push(Transaction::transaction_end());
        }
        let mut sensor = Max31855::new(Mock::new(&expectations));
        for fault in [
            SensorFault::OpenCircuit,
            SensorFault::ShortToGnd,
            SensorFault::ShortToVcc,
        ] {
            let error = sensor.read().unwrap_err();
            assert_eq!(error, Error::Sensor(fault));
            assert_eq!(SensorFault::from(error), fault);
        }
        sensor.release().done();
    }

    #[test]
    fn driver_read_frame_returns_raw_bits() {
        let expectations = [
            Transaction::transaction_start(),
            Transaction::read_vec(vec![0x12, 0x34, 0x56, 0x78]),
            Transaction::transaction_end(),
        ];
        let mut sensor = Max31855::new(Mock::new(&expectations));
        assert_eq!(sensor.read_frame(), Ok(0x1234_5678));
        sensor.release().done();
    }

    #[test]
    fn driver_reports_bus_errors_as_bus_errors() {
        let mut sensor = Max31855::new(FailingSpi);
        let error = sensor.read().unwrap_err();
        assert_eq!(error, Error::Bus(ErrorKind::Other));
        assert_eq!(error.fault(), SensorFault::Bus);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        #[test]
        fn decode_never_panics_and_respects_the_format(frame in any::<u32>()) {
            let flagged = frame & (FAULT | OPEN_CIRCUIT | SHORT_TO_GND | SHORT_TO_VCC) != 0;
            let corrupt = frame & RESERVED != 0;
            match decode(frame) {
                Ok(reading) => {
                    prop_assert!(!flagged && !corrupt);
                    prop_assert!((-2048.0..=2047.75).contains(&reading.temp_c));
                    let cj_c = reading.cold_junction_c.unwrap_or(f32::NAN);
                    prop_assert!((-128.0..=127.9375).contains(&cj_c));
                    prop_assert_eq!(reading.temp_c % THERMOCOUPLE_LSB_C, 0.0);
                    prop_assert_eq!(cj_c % COLD_JUNCTION_LSB_C, 0.0);
                }
                Err(fault) => {
                    prop_assert!(flagged || corrupt);
                    prop_assert!(matches!(
                        fault,
                        SensorFault::OpenCircuit
                            | SensorFault::ShortToGnd
                            | SensorFault::ShortToVcc
                            | SensorFault::InvalidData
                    ));
                }
            }
        }

        #[test]
        fn decode_inverts_encoding(tc in -8192i32..8192, cj in -2048i32..2048) {
            let encoded = ((tc as u32 & 0x3FFF) << 18) | ((cj as u32 & 0xFFF) << 4);
            let reading = decode(encoded).unwrap();
            prop_assert_eq!(reading.temp_c, tc as f32 * 0.25);
            prop_assert_eq!(reading.cold_junction_c, Some(cj as f32 * 0.0625));
        }
    }
}
