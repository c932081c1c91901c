//! `--measure` columns that hold what a sensor measures rather than its
//! temperature, converted row by row by the library's conversion, the one
//! the MCU calls:
//!
//! * `replay --raw-counts`: a resistive sensor's raw ADC counts, through
//!   `ResistiveInput::convert` (the generated module's `convert_counts`).
//!   A cell that is not a whole count in `0 ..= u32::MAX` is refused,
//!   naming the row.
//! * always, a winding's resistance \[ohm\] (an `[observer] sensors`
//!   entry of kind `resistance`), through `ResistanceSensor::read` at the
//!   row's current of the source's input (the observer's
//!   `resistance_reading`): below the sensor's least current it is no
//!   reading, and counted as such.
//!
//! A value that converts to a fault (an open or shorted sensor, a count
//! that is no ADC code, a resistance that cannot be the winding's, a
//! temperature outside the sensor's range) is never a temperature: its
//! cell becomes empty, the row carries the fault ([`InputRow::faults`]),
//! and the firmware's observer is handed the fault itself, as the MCU
//! hands it (the sensor shows `Fault`, nothing is fused); it is counted
//! and reported.

use std::collections::BTreeMap;

use anyhow::{bail, Result};
use coil_thermal::sensors::SensorFault;

use coil_thermal::observer::network::ResistanceSensor;

use crate::sensor_kinds::AdcSensor;
use crate::sim::{InputRow, RowSource};

/// What a converted column holds.
#[derive(Debug, Clone)]
pub enum Conversion {
    /// A resistive sensor's ADC counts.
    Adc(AdcSensor),
    /// A winding's resistance \[ohm\], read at the current of model input
    /// `input` in the same row.
    Resistance {
        /// The library's sensor.
        sensor: ResistanceSensor,
        /// The input whose current the source carries.
        input: usize,
    },
}

impl Conversion {
    /// The kind's name as the model file spells it.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Adc(a) => a.kind,
            Self::Resistance { .. } => "resistance",
        }
    }
}

/// One converted column: its position in each row's `extra` and its
/// sensor.
#[derive(Debug, Clone)]
pub struct RawColumn {
    /// The column's text (for messages).
    pub column: String,
    /// Position of its value in [`InputRow::extra`].
    pub slot: usize,
    /// The sensor's conversion.
    pub sensor: Conversion,
    /// The faults met, by kind, with their count.
    pub faults: BTreeMap<String, usize>,
    /// A resistance's values measured below its least current (no
    /// reading, not a fault).
    pub below_least_current: usize,
}

/// A row source whose raw columns come out as temperatures \[degC\] or
/// missing readings.
pub struct ConvertedRows<'a> {
    inner: &'a mut dyn RowSource,
    /// The converted columns, with the faults met so far.
    pub columns: Vec<RawColumn>,
}

impl<'a> ConvertedRows<'a> {
    /// Converts `columns` of `inner`'s rows.
    pub fn new(inner: &'a mut dyn RowSource, columns: Vec<RawColumn>) -> Self {
        Self { inner, columns }
    }
}

/// A cell as an ADC count; `None` for an empty cell.
fn counts(value: f64, column: &str, time_s: f64) -> Result<Option<u32>> {
    if value.is_nan() {
        return Ok(None);
    }
    if !(value >= 0.0 && value <= f64::from(u32::MAX) && value.fract() == 0.0) {
        bail!(
            "--raw-counts: column `{column}` at {time_s} s holds {value}, not an ADC count (a whole number >= 0)"
        );
    }
    Ok(Some(value as u32))
}

impl RowSource for ConvertedRows<'_> {
    fn next_row(&mut self) -> Result<Option<InputRow>> {
        let Some(mut row) = self.inner.next_row()? else {
            return Ok(None);
        };
        for c in &mut self.columns {
            let value = row.extra[c.slot];
            let result = match &c.sensor {
                Conversion::Adc(a) => {
                    let Some(k) = counts(value, &c.column, row.time_s)? else {
                        continue;
                    };
                    Some(a.input.convert(k))
                }
                Conversion::Resistance { sensor, input } => {
                    // An empty cell is no measurement (a logger's gap).
                    if value.is_nan() {
                        continue;
                    }
                    let current_a = row.currents.get(*input).copied().unwrap_or(0.0);
                    sensor.read(value as f32, current_a as f32)
                }
            };
            row.extra[c.slot] = match result {
                Some(Ok(reading)) => f64::from(reading.temp_c),
                Some(Err(fault)) => {
                    *c.faults.entry(fault_name(fault)).or_default() += 1;
                    row.faults.push((c.slot, fault));
                    f64::NAN
                }
                None => {
                    c.below_least_current += 1;
                    f64::NAN
                }
            };
        }
        Ok(Some(row))
    }
}

fn fault_name(fault: SensorFault) -> String {
    format!("{fault:?}")
}

/// One line per converted column: its sensor and the faults it met.
pub fn report(columns: &[RawColumn]) -> Vec<String> {
    columns
        .iter()
        .map(|c| {
            let faults: Vec<String> = c.faults.iter().map(|(k, n)| format!("{k} {n}")).collect();
            let what = match &c.sensor {
                Conversion::Adc(_) => "raw counts",
                Conversion::Resistance { .. } => "resistance [ohm]",
            };
            let below = match &c.sensor {
                Conversion::Resistance { sensor, .. } if c.below_least_current > 0 => format!(
                    "; {} below the least current ({} A): no reading",
                    c.below_least_current, sensor.min_current_a
                ),
                _ => String::new(),
            };
            format!(
                "{what} `{}` ({}, the library's conversion): {}{below}",
                c.column,
                c.sensor.kind(),
                if faults.is_empty() {
                    "no fault".to_string()
                } else {
                    format!(
                        "faults, not fused, never read as temperatures: {}",
                        faults.join(", ")
                    )
                }
            )
        })
        .collect()
}
