//! MAX31856 precision thermocouple-to-digital converter with linearisation.
//!
//! # Register map
//!
//! One byte per address; the first byte of a transaction is the address, with
//! bit 7 set for a write (`address | 0x80`). Consecutive bytes of the same
//! transaction go to (or come from) consecutive addresses.
//!
//! | addr | name | content |
//! |---|---|---|
//! | 0x00 | CR0 | CMODE (7), 1SHOT (6), OCFAULT (5:4), CJ disable (3), FAULT mode (2), FAULTCLR (1), 50 Hz (0) |
//! | 0x01 | CR1 | AVGSEL (6:4), TC TYPE (3:0) |
//! | 0x02 | MASK | 1 = that fault does not assert the FAULT pin (bits 5:0, same order as SR 5:0) |
//! | 0x03, 0x04 | CJHF, CJLF | cold-junction high/low fault thresholds, signed, 1 degC LSB |
//! | 0x05..0x08 | LTHFTH/L, LTLFTH/L | thermocouple high/low fault thresholds, signed 16 bit, 0.0625 degC LSB |
//! | 0x09 | CJTO | cold-junction offset (left at its reset value 0) |
//! | 0x0A, 0x0B | CJTH, CJTL | cold-junction temperature: signed 14 bit in CJTH 7:0 and CJTL 7:2, 0.015625 degC LSB |
//! | 0x0C..0x0E | LTCBH, LTCBM, LTCBL | linearised thermocouple temperature: signed 19 bit in LTCBH 7:0, LTCBM 7:0, LTCBL 7:5, 0.0078125 degC LSB |
//! | 0x0F | SR | fault status, see [`FaultStatus`] |
//!
//! Unlike the MAX31855 the chip linearises the thermocouple curve itself (for
//! types B, E, J, K, N, R, S and T) and converts continuously in the
//! background, so it may be read at any rate: a read returns the latest
//! conversion. After [`Max31856::configure`] the first conversion takes up to
//! about 200 ms; until then the temperature registers read 0 degC.
//!
//! # Reading and faults
//!
//! [`Max31856::read`] fetches the six bytes CJTH..SR in one transaction and
//! [`decode`]s them. Any SR bit set makes the sample a fault (see
//! [`FaultStatus::fault`] for the mapping); the driver runs the chip in
//! comparator mode, so SR follows the conditions and needs no clearing.

use embedded_hal::spi::{Mode, Operation, SpiDevice, MODE_1};

use super::{Error, Reading, SensorFault};

/// SPI mode of the MAX31856 (it also accepts mode 3): data sampled on the
/// falling edge.
pub const SPI_MODE: Mode = MODE_1;
/// Highest SPI clock the MAX31856 supports \[Hz\].
pub const MAX_SPI_FREQUENCY_HZ: u32 = 5_000_000;

/// Weight of one LSB of the linearised thermocouple temperature \[degC\].
pub const THERMOCOUPLE_LSB_C: f32 = 0.0078125;
/// Weight of one LSB of the cold-junction temperature \[degC\].
pub const COLD_JUNCTION_LSB_C: f32 = 0.015625;
/// Weight of one LSB of the thermocouple fault thresholds \[degC\].
const THRESHOLD_LSB_C: f32 = 0.0625;

/// First register of the block [`decode`] expects (CJTH).
pub const READ_BLOCK_START: u8 = CJTH;
/// Length of that block: CJTH, CJTL, LTCBH, LTCBM, LTCBL, SR.
pub const READ_BLOCK_LEN: usize = 6;

const WRITE: u8 = 0x80;

const CR0: u8 = 0x00;
const CJTH: u8 = 0x0A;
const SR: u8 = 0x0F;
/// CR0 through LTLFTL: everything [`Max31856::configure`] writes.
const CONFIG_LEN: usize = 9;

const CR0_AUTO_CONVERSION: u8 = 0x80;
const CR0_ONE_SHOT: u8 = 0x40;
const CR0_OPEN_CIRCUIT_SHIFT: u8 = 4;
const CR0_FAULT_CLEAR: u8 = 0x02;
const CR0_FILTER_50HZ: u8 = 0x01;
/// CR0 bits that read back as written (1SHOT and FAULTCLR clear themselves).
const CR0_PERSISTENT: u8 = !(CR0_ONE_SHOT | CR0_FAULT_CLEAR);
const CR1_AVERAGING_SHIFT: u8 = 4;
const CR1_USED: u8 = 0x7F;
const MASK_USED: u8 = 0x3F;

/// Thermocouple type: selects the chip's linearisation table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ThermocoupleType {
    /// Type B (Pt-30%Rh / Pt-6%Rh).
    B,
    /// Type E (chromel / constantan).
    E,
    /// Type J (iron / constantan).
    J,
    /// Type K (chromel / alumel), the chip's reset default.
    #[default]
    K,
    /// Type N (nicrosil / nisil).
    N,
    /// Type R (Pt-13%Rh / Pt).
    R,
    /// Type S (Pt-10%Rh / Pt).
    S,
    /// Type T (copper / constantan).
    T,
}

impl ThermocoupleType {
    const fn code(self) -> u8 {
        match self {
            Self::B => 0,
            Self::E => 1,
            Self::J => 2,
            Self::K => 3,
            Self::N => 4,
            Self::R => 5,
            Self::S => 6,
            Self::T => 7,
        }
    }
}

/// Samples averaged per conversion. More samples cut noise but lengthen the
/// conversion (and the sensor's delay seen by the filter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Averaging {
    /// One sample: lowest delay (reset default).
    #[default]
    Samples1,
    /// Two samples.
    Samples2,
    /// Four samples.
    Samples4,
    /// Eight samples.
    Samples8,
    /// Sixteen samples.
    Samples16,
}

impl Averaging {
    const fn code(self) -> u8 {
        match self {
            Self::Samples1 => 0,
            Self::Samples2 => 1,
            Self::Samples4 => 2,
            Self::Samples8 => 3,
            Self::Samples16 => 4,
        }
    }
}

/// Mains frequency the input filter rejects. Pick the local grid's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MainsFilter {
    /// Reject 50 Hz.
    Hz50,
    /// Reject 60 Hz (reset default).
    #[default]
    Hz60,
}

/// Open-thermocouple detection (CR0 OCFAULT). The mode depends on the total
/// series resistance `Rs` of thermocouple, leads and input filter, and on the
/// input filter's time constant; detection lengthens some conversions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OpenCircuitDetection {
    /// No detection: an open thermocouple reads as a drifting temperature.
    Disabled,
    /// `Rs` < 5 kOhm: ordinary thermocouples with short leads.
    #[default]
    LowImpedance,
    /// 5 kOhm < `Rs` < 40 kOhm, input time constant < 2 ms.
    HighImpedanceFast,
    /// 5 kOhm < `Rs` < 40 kOhm, input time constant > 2 ms.
    HighImpedanceSlow,
}

impl OpenCircuitDetection {
    const fn code(self) -> u8 {
        match self {
            Self::Disabled => 0,
            Self::LowImpedance => 1,
            Self::HighImpedanceFast => 2,
            Self::HighImpedanceSlow => 3,
        }
    }
}

/// Everything [`Max31856::configure`] writes. Conversion is always
/// continuous, with the cold-junction sensor on and faults in comparator mode.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Linearisation table. Default K.
    pub thermocouple: ThermocoupleType,
    /// Samples per conversion. Default 1.
    pub averaging: Averaging,
    /// Mains rejection. Default 60 Hz, as the chip resets.
    pub mains_filter: MainsFilter,
    /// Open-circuit detection. Default on, for `Rs` < 5 kOhm.
    pub open_circuit: OpenCircuitDetection,
    /// MASK register: a set bit (in [`FaultStatus`] bit order, 5:0) keeps
    /// that fault off the FAULT pin. Default 0: every fault drives the pin,
    /// which is harmless if it is not connected.
    pub fault_pin_mask: u8,
    /// TCLOW is set below this thermocouple temperature \[degC\], rounded to
    /// 0.0625 degC and saturated to the register's -2048 .. +2047.9375 degC.
    /// NaN means no limit. Default -2048 (no limit).
    pub thermocouple_low_fault_c: f32,
    /// TCHIGH is set above this thermocouple temperature \[degC\]; rounding,
    /// saturation and NaN as for the low limit. Default +2047.9375 (no
    /// limit).
    pub thermocouple_high_fault_c: f32,
    /// CJLOW is set below this cold-junction temperature \[degC\]. Default
    /// -128 (no limit).
    pub cold_junction_low_fault_c: i8,
    /// CJHIGH is set above this cold-junction temperature \[degC\]. Default
    /// +127 (no limit).
    pub cold_junction_high_fault_c: i8,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            thermocouple: ThermocoupleType::K,
            averaging: Averaging::Samples1,
            mains_filter: MainsFilter::Hz60,
            open_circuit: OpenCircuitDetection::LowImpedance,
            fault_pin_mask: 0,
            thermocouple_low_fault_c: -2048.0,
            thermocouple_high_fault_c: 2047.9375,
            cold_junction_low_fault_c: i8::MIN,
            cold_junction_high_fault_c: i8::MAX,
        }
    }
}

impl Config {
    /// CR0 with or without continuous conversion.
    fn cr0(&self, auto_conversion: bool) -> u8 {
        let mut cr0 = self.open_circuit.code() << CR0_OPEN_CIRCUIT_SHIFT;
        if auto_conversion {
            cr0 |= CR0_AUTO_CONVERSION;
        }
        if self.mains_filter == MainsFilter::Hz50 {
            cr0 |= CR0_FILTER_50HZ;
        }
        cr0
    }

    /// CR0 (without conversion) through LTLFTL, in register order.
    fn registers(&self) -> [u8; CONFIG_LEN] {
        let [high_msb, high_lsb] =
            threshold_code(self.thermocouple_high_fault_c, i16::MAX).to_be_bytes();
        let [low_msb, low_lsb] =
            threshold_code(self.thermocouple_low_fault_c, i16::MIN).to_be_bytes();
        [
            self.cr0(false),
            (self.averaging.code() << CR1_AVERAGING_SHIFT) | self.thermocouple.code(),
            self.fault_pin_mask & MASK_USED,
            self.cold_junction_high_fault_c.to_be_bytes()[0],
            self.cold_junction_low_fault_c.to_be_bytes()[0],
            high_msb,
            high_lsb,
            low_msb,
            low_lsb,
        ]
    }
}

/// A thermocouple threshold in register units; `as` saturates out-of-range
/// values, and NaN gets the caller's "no limit" code.
fn threshold_code(limit_c: f32, no_limit: i16) -> i16 {
    if limit_c.is_nan() {
        no_limit
    } else {
        libm::roundf(limit_c / THRESHOLD_LSB_C) as i16
    }
}

/// The fault status register (SR, 0x0F).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultStatus(pub u8);

impl FaultStatus {
    /// CJRANGE: the cold junction is outside -55 .. +125 degC.
    pub const COLD_JUNCTION_RANGE: u8 = 0x80;
    /// TCRANGE: the thermocouple is outside its type's range (or its input
    /// voltage outside the ADC's).
    pub const THERMOCOUPLE_RANGE: u8 = 0x40;
    /// CJHIGH: the cold junction is above CJHF.
    pub const COLD_JUNCTION_HIGH: u8 = 0x20;
    /// CJLOW: the cold junction is below CJLF.
    pub const COLD_JUNCTION_LOW: u8 = 0x10;
    /// TCHIGH: the thermocouple is above LTHFT.
    pub const THERMOCOUPLE_HIGH: u8 = 0x08;
    /// TCLOW: the thermocouple is below LTLFT.
    pub const THERMOCOUPLE_LOW: u8 = 0x04;
    /// OVUV: a thermocouple input is above VDD or below GND.
    pub const OVER_UNDER_VOLTAGE: u8 = 0x02;
    /// OPEN: the thermocouple is open.
    pub const OPEN: u8 = 0x01;

    /// Whether every bit of `mask` is set.
    pub const fn contains(self, mask: u8) -> bool {
        self.0 & mask == mask
    }

    /// The most severe fault in the register, `None` if it is clear.
    ///
    /// | SR bits | fault |
    /// |---|---|
    /// | OPEN | [`SensorFault::OpenCircuit`] |
    /// | OVUV | [`SensorFault::ShortToVcc`] |
    /// | TCRANGE, CJRANGE, TCHIGH, TCLOW, CJHIGH, CJLOW | [`SensorFault::OutOfRange`] |
    ///
    /// OVUV is reported as a short to VCC because the chip has one flag for
    /// both directions: an input beyond a rail means the thermocouple touches
    /// a voltage outside the supply, such as the coil's drive. A plain short
    /// to GND stays inside the rails and does not set it.
    pub const fn fault(self) -> Option<SensorFault> {
        if self.0 & Self::OPEN != 0 {
            Some(SensorFault::OpenCircuit)
        } else if self.0 & Self::OVER_UNDER_VOLTAGE != 0 {
            Some(SensorFault::ShortToVcc)
        } else if self.0 != 0 {
            Some(SensorFault::OutOfRange)
        } else {
            None
        }
    }
}

/// Decode the register block CJTH, CJTL, LTCBH, LTCBM, LTCBL, SR
/// ([`READ_BLOCK_LEN`] bytes read from [`READ_BLOCK_START`]).
///
/// Needs no bus, so DMA users can call it on their own buffer.
///
/// # Errors
/// The fault [`FaultStatus::fault`] finds in SR.
pub fn decode(block: &[u8; READ_BLOCK_LEN]) -> Result<Reading, SensorFault> {
    let [cj_msb, cj_lsb, tc_high, tc_mid, tc_low, status] = *block;
    if let Some(fault) = FaultStatus(status).fault() {
        return Err(fault);
    }
    // Left-aligned two's complement: arithmetic shifts sign-extend and drop
    // the unused low bits. 14 and 19 bits convert to f32 exactly.
    let cold_junction_code = i16::from_be_bytes([cj_msb, cj_lsb]) >> 2;
    let thermocouple_code = i32::from_be_bytes([tc_high, tc_mid, tc_low, 0]) >> 13;
    Ok(Reading {
        temp_c: thermocouple_code as f32 * THERMOCOUPLE_LSB_C,
        cold_junction_c: Some(f32::from(cold_junction_code) * COLD_JUNCTION_LSB_C),
    })
}

/// MAX31856 driver on an embedded-hal 1.0 SPI device (the device owns chip
/// select).
#[derive(Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Max31856<SPI> {
    spi: SPI,
}

impl<SPI> Max31856<SPI> {
    /// Wrap the SPI device. No bus traffic: call [`Max31856::configure`]
    /// before reading, since the chip resets with conversions off.
    pub const fn new(spi: SPI) -> Self {
        Self { spi }
    }

    /// Give the SPI device back.
    pub fn release(self) -> SPI {
        self.spi
    }
}

impl<SPI: SpiDevice> Max31856<SPI> {
    /// Write `config` and start continuous conversion, then read the
    /// configuration back.
    ///
    /// Conversions are stopped while CR1 and the filter change (the datasheet
    /// forbids changing them during automatic conversion), and restarted
    /// last. Five short transactions; call at start-up, not in the loop.
    ///
    /// # Errors
    /// [`Error::Bus`] if a transfer failed; [`Error::Sensor`] with
    /// [`SensorFault::InvalidData`] if the registers do not read back as
    /// written (chip absent, unpowered, or SDO not connected).
    pub fn configure(&mut self, config: &Config) -> Result<(), Error<SPI::Error>> {
        let [current_cr0] = self.read_registers::<1>(CR0).map_err(Error::Bus)?;
        let stopped = current_cr0 & !(CR0_AUTO_CONVERSION | CR0_ONE_SHOT | CR0_FAULT_CLEAR);
        self.spi
            .write(&[WRITE | CR0, stopped])
            .map_err(Error::Bus)?;

        let registers = config.registers();
        let mut burst = [0u8; CONFIG_LEN + 1];
        burst[0] = WRITE | CR0;
        burst[1..].copy_from_slice(&registers);
        self.spi.write(&burst).map_err(Error::Bus)?;

        let running = config.cr0(true);
        self.spi
            .write(&[WRITE | CR0, running])
            .map_err(Error::Bus)?;

        let mut expected = registers;
        expected[0] = running;
        let actual = self.read_registers::<CONFIG_LEN>(CR0).map_err(Error::Bus)?;
        if !config_matches(&expected, &actual) {
            return Err(Error::Sensor(SensorFault::InvalidData));
        }
        Ok(())
    }

    /// Read and decode temperature, cold junction and fault status (one
    /// 7-byte transaction).
    ///
    /// # Errors
    /// [`Error::Bus`] if the transfer failed; [`Error::Sensor`] with the
    /// fault [`decode`] found otherwise.
    pub fn read(&mut self) -> Result<Reading, Error<SPI::Error>> {
        let block = self.read_raw().map_err(Error::Bus)?;
        decode(&block).map_err(Error::Sensor)
    }

    /// Read the raw block [`decode`] takes, for logging and diagnostics.
    ///
    /// # Errors
    /// The SPI device's error if the transfer failed.
    pub fn read_raw(&mut self) -> Result<[u8; READ_BLOCK_LEN], SPI::Error> {
        self.read_registers(READ_BLOCK_START)
    }

    /// Read only the fault status register, to see every fault that is set
    /// when [`Max31856::read`] reported the most severe one.
    ///
    /// # Errors
    /// The SPI device's error if the transfer failed.
    pub fn read_fault_status(&mut self) -> Result<FaultStatus, SPI::Error> {
        let [status] = self.read_registers::<1>(SR)?;
        Ok(FaultStatus(status))
    }

    fn read_registers<const N: usize>(&mut self, first: u8) -> Result<[u8; N], SPI::Error> {
        let mut values = [0u8; N];
        self.spi.transaction(&mut [
            Operation::Write(&[first & !WRITE]),
            Operation::Read(&mut values),
        ])?;
        Ok(values)
    }
}

/// Compare written and read-back configuration, ignoring reserved and
/// self-clearing bits.
fn config_matches(expected: &[u8; CONFIG_LEN], actual: &[u8; CONFIG_LEN]) -> bool {
    let used = |index: usize| match index {
        0 => CR0_PERSISTENT,
        1 => CR1_USED,
        2 => MASK_USED,
        _ => 0xFF,
    };
    expected
        .iter()
        .zip(actual)
        .enumerate()
        .all(|(index, (e, a))| (e ^ a) & used(index) == 0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensors::test_support::FailingSpi;
    use embedded_hal::spi::ErrorKind;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction};
    use proptest::prelude::*;

    /// Registers 0x00..=0x08 as the default configuration writes them.
    const DEFAULT_REGISTERS: [u8; CONFIG_LEN] =
        [0x10, 0x03, 0x00, 0x7F, 0x80, 0x7F, 0xFF, 0x80, 0x00];

    fn block(cj: [u8; 2], tc: [u8; 3], status: u8) -> [u8; READ_BLOCK_LEN] {
        [cj[0], cj[1], tc[0], tc[1], tc[2], status]
    }

    fn read_transaction(first: u8, response: Vec<u8>) -> [Transaction<u8>; 4] {
        [
            Transaction::transaction_start(),
            Transaction::write(first),
            Transaction::read_vec(response),
            Transaction::transaction_end(),
        ]
    }

    fn write_transaction(bytes: Vec<u8>) -> [Transaction<u8>; 3] {
        [
            Transaction::transaction_start(),
            Transaction::write_vec(bytes),
            Transaction::transaction_end(),
        ]
    }

    /// The full configure sequence for `registers` (CR0 without CMODE
    /// first), with `current_cr0` as the chip's CR0 before and `readback` as
    /// what registers 0x00..=0x08 read afterwards.
    fn configure_transactions(
        current_cr0: u8,
        registers: [u8; CONFIG_LEN],
        readback: [u8; CONFIG_LEN],
    ) -> Vec<Transaction<u8>> {
        let mut burst = vec![0x80];
        burst.extend_from_slice(&registers);
        let mut all = Vec::new();
        all.extend(read_transaction(0x00, vec![current_cr0]));
        all.extend(write_transaction(vec![0x80, current_cr0 & 0x3D]));
        all.extend(write_transaction(burst));
        all.extend(write_transaction(vec![0x80, registers[0] | 0x80]));
        all.extend(read_transaction(0x00, readback.to_vec()));
        all
    }

    #[test]
    fn decodes_positive_and_negative_temperatures() {
        let cases = [
            ([0x64, 0x00, 0x00], 1600.0),
            ([0x3E, 0x80, 0x00], 1000.0),
            ([0x06, 0x40, 0x20], 100.0 + 1.0 / 128.0),
            ([0x01, 0x90, 0x00], 25.0),
            ([0x00, 0x00, 0x00], 0.0),
            ([0xFF, 0xFF, 0xE0], -0.0078125),
            ([0xFF, 0xF0, 0x00], -1.0),
            ([0xF0, 0x60, 0x00], -250.0),
            ([0x7F, 0xFF, 0xE0], 2048.0 - 1.0 / 128.0),
            ([0x80, 0x00, 0x00], -2048.0),
        ];
        let cold_junctions = [
            ([0x7F, 0xFC], 127.984375),
            ([0x64, 0x80], 100.5),
            ([0x19, 0x00], 25.0),
            ([0x00, 0x00], 0.0),
            ([0xFF, 0xFC], -0.015625),
            ([0xFF, 0x00], -1.0),
            ([0xC9, 0x00], -55.0),
            ([0x80, 0x00], -128.0),
        ];
        for (tc, tc_c) in cases {
            for (cj, cj_c) in cold_junctions {
                assert_eq!(
                    decode(&block(cj, tc, 0)),
                    Ok(Reading {
                        temp_c: tc_c,
                        cold_junction_c: Some(cj_c)
                    }),
                    "tc {tc:02X?} cj {cj:02X?}"
                );
            }
        }
    }

    #[test]
    fn unused_low_bits_are_ignored() {
        assert_eq!(
            decode(&block([0x19, 0x03], [0x01, 0x90, 0x1F], 0)),
            Ok(Reading {
                temp_c: 25.0,
                cold_junction_c: Some(25.0)
            })
        );
    }

    #[test]
    fn each_status_bit_maps_to_its_fault() {
        let reading = block([0x19, 0x00], [0x01, 0x90, 0x00], 0);
        for (bit, fault) in [
            (FaultStatus::OPEN, SensorFault::OpenCircuit),
            (FaultStatus::OVER_UNDER_VOLTAGE, SensorFault::ShortToVcc),
            (FaultStatus::THERMOCOUPLE_LOW, SensorFault::OutOfRange),
            (FaultStatus::THERMOCOUPLE_HIGH, SensorFault::OutOfRange),
            (FaultStatus::COLD_JUNCTION_LOW, SensorFault::OutOfRange),
            (FaultStatus::COLD_JUNCTION_HIGH, SensorFault::OutOfRange),
            (FaultStatus::THERMOCOUPLE_RANGE, SensorFault::OutOfRange),
            (FaultStatus::COLD_JUNCTION_RANGE, SensorFault::OutOfRange),
        ] {
            let mut faulted = reading;
            faulted[5] = bit;
            assert_eq!(decode(&faulted), Err(fault), "SR {bit:08b}");
            assert!(FaultStatus(bit).contains(bit));
        }
        assert_eq!(FaultStatus(0).fault(), None);
    }

    #[test]
    fn most_severe_status_bit_wins() {
        assert_eq!(FaultStatus(0xFF).fault(), Some(SensorFault::OpenCircuit));
        assert_eq!(FaultStatus(0xFE).fault(), Some(SensorFault::ShortToVcc));
        assert_eq!(FaultStatus(0xFC).fault(), Some(SensorFault::OutOfRange));
    }

    #[test]
    fn default_config_registers() {
        let config = Config::default();
        assert_eq!(config.registers(), DEFAULT_REGISTERS);
        // Continuous conversion, open-circuit detection for Rs < 5 kOhm,
        // cold junction on, comparator mode, 60 Hz.
        assert_eq!(config.cr0(true), 0x90);
    }

    #[test]
    fn custom_config_registers() {
        let config = Config {
            thermocouple: ThermocoupleType::T,
            averaging: Averaging::Samples16,
            mains_filter: MainsFilter::Hz50,
            open_circuit: OpenCircuitDetection::HighImpedanceSlow,
            fault_pin_mask: 0xFF,
            thermocouple_low_fault_c: -40.03,
            thermocouple_high_fault_c: 180.5,
            cold_junction_low_fault_c: -20,
            cold_junction_high_fault_c: 85,
        };
        // -40.03 rounds to -40.0 (0xFD80), 180.5 is 0x0B48.
        assert_eq!(
            config.registers(),
            [0x31, 0x47, 0x3F, 0x55, 0xEC, 0x0B, 0x48, 0xFD, 0x80]
        );
        assert_eq!(config.cr0(true), 0xB1);
        for (kind, expected) in [
            (ThermocoupleType::B, 0),
            (ThermocoupleType::E, 1),
            (ThermocoupleType::J, 2),
            (ThermocoupleType::N, 4),
            (ThermocoupleType::R, 5),
            (ThermocoupleType::S, 6),
        ] {
            assert_eq!(kind.code(), expected);
        }
        for (averaging, expected) in [
            (Averaging::Samples2, 1),
            (Averaging::Samples4, 2),
            (Averaging::Samples8, 3),
        ] {
            assert_eq!(averaging.code(), expected);
        }
        assert_eq!(OpenCircuitDetection::Disabled.code(), 0);
        assert_eq!(OpenCircuitDetection::HighImpedanceFast.code(), 2);
    }

    #[test]
    fn thresholds_saturate_and_nan_means_no_limit() {
        let config = Config {
            thermocouple_low_fault_c: f32::NAN,
            thermocouple_high_fault_c: f32::NAN,
            ..Config::default()
        };
        assert_eq!(config.registers(), DEFAULT_REGISTERS);
        let config = Config {
            thermocouple_low_fault_c: -1.0e9,
            thermocouple_high_fault_c: f32::INFINITY,
            ..Config::default()
        };
        assert_eq!(config.registers(), DEFAULT_REGISTERS);
    }

    #[test]
    fn configure_stops_writes_restarts_and_verifies() {
        // The chip was converting at 50 Hz with a pending one-shot and fault
        // clear: stop keeps the filter bit and drops the rest.
        let mut readback = DEFAULT_REGISTERS;
        readback[0] |= 0x80;
        // Reserved MASK bits reading as 1 are not a mismatch.
        readback[2] |= 0xC0;
        let expectations = configure_transactions(0xC3, DEFAULT_REGISTERS, readback);
        let mut sensor = Max31856::new(Mock::new(&expectations));
        assert_eq!(sensor.configure(&Config::default()), Ok(()));
        sensor.release().done();
    }

    #[test]
    fn configure_detects_a_chip_that_does_not_answer() {
        for readback in [[0x00; CONFIG_LEN], [0xFF; CONFIG_LEN]] {
            let expectations = configure_transactions(readback[0], DEFAULT_REGISTERS, readback);
            let mut sensor = Max31856::new(Mock::new(&expectations));
            assert_eq!(
                sensor.configure(&Config::default()),
                Err(Error::Sensor(SensorFault::InvalidData))
            );
            sensor.release().done();
        }
    }

    #[test]
    fn read_fetches_the_block_in_one_transaction() {
        let expectations =
            read_transaction(0x0A, block([0xC9, 0x00], [0xF0, 0x60, 0x00], 0).to_vec());
        let mut sensor = Max31856::new(Mock::new(&expectations));
        assert_eq!(
            sensor.read(),
            Ok(Reading {
                temp_c: -250.0,
                cold_junction_c: Some(-55.0)
            })
        );
        sensor.release().done();
    }

    #[test]
    fn read_reports_status_faults_and_read_fault_status_shows_all() {
        let mut expectations = Vec::new();
        expectations.extend(read_transaction(
            0x0A,
            block([0x19, 0x00], [0x01, 0x90, 0x00], 0x41).to_vec(),
        ));
        expectations.extend(read_transaction(0x0F, vec![0x41]));
        let mut sensor = Max31856::new(Mock::new(&expectations));
        assert_eq!(sensor.read(), Err(Error::Sensor(SensorFault::OpenCircuit)));
        let status = sensor.read_fault_status().unwrap();
        assert!(status.contains(FaultStatus::OPEN | FaultStatus::THERMOCOUPLE_RANGE));
        sensor.release().done();
    }

    #[test]
    fn bus_errors_are_bus_errors() {
        let mut sensor = Max31856::new(FailingSpi);
        assert_eq!(sensor.read(), Err(Error::Bus(ErrorKind::Other)));
        assert_eq!(
            sensor.configure(&Config::default()),
            Err(Error::Bus(ErrorKind::Other))
        );
        assert_eq!(sensor.read_fault_status(), Err(ErrorKind::Other));
        assert_eq!(
            SensorFault::from(sensor.read().unwrap_err()),
            SensorFault::Bus
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20_000))]

        #[test]
        fn decode_never_panics_and_respects_the_format(bytes in any::<[u8; 6]>()) {
            match decode(&bytes) {
                Ok(reading) => {
                    prop_assert_eq!(bytes[5], 0);
                    prop_assert!((-2048.0..=2048.0 - THERMOCOUPLE_LSB_C).contains(&reading.temp_c));
                    let cj_c = reading.cold_junction_c.unwrap_or(f32::NAN);
                    prop_assert!((-128.0..=127.984375).contains(&cj_c));
                    prop_assert_eq!(reading.temp_c % THERMOCOUPLE_LSB_C, 0.0);
                    prop_assert_eq!(cj_c % COLD_JUNCTION_LSB_C, 0.0);
                }
                Err(fault) => {
                    prop_assert_ne!(bytes[5], 0);
                    prop_assert_eq!(Some(fault), FaultStatus(bytes[5]).fault());
                }
            }
        }

        #[test]
        fn decode_inverts_encoding(tc in -(1i32 << 18)..(1 << 18), cj in -(1i16 << 13)..(1 << 13)) {
            let [tc_high, tc_mid, tc_low, _] = (tc << 13).to_be_bytes();
            let cj_bytes = (cj << 2).to_be_bytes();
            let reading = decode(&block(cj_bytes, [tc_high, tc_mid, tc_low], 0)).unwrap();
            prop_assert_eq!(reading.temp_c, tc as f32 / 128.0);
            prop_assert_eq!(reading.cold_junction_c, Some(f32::from(cj) / 64.0));
        }
    }
}
