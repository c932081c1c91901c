//! `replay --raw-counts`: `--measure` columns that hold a resistive
//! sensor's raw ADC counts rather than its temperature, converted row by
//! row by the library's `ResistiveInput::convert`, the conversion the
//! generated module's `convert_counts` calls on the MCU. A count that
//! converts to a fault (an open or shorted sensor, a count that is no ADC
//! code, a temperature outside the sensor's range) becomes no reading (an
//! empty cell: the observer predicts on the model) and is counted and
//! reported as that fault; it is never a temperature. A cell that is not a
//! whole count in `0 ..= u32::MAX` is refused, naming the row.

use std::collections::BTreeMap;

use anyhow::{bail, Result};
use coil_thermal::sensors::SensorFault;

use crate::sensor_kinds::AdcSensor;
use crate::sim::{InputRow, RowSource};

/// One converted column: its position in each row's `extra` and its
/// sensor.
#[derive(Debug, Clone)]
pub struct RawColumn {
    /// The column's text (for messages).
    pub column: String,
    /// Position of its value in [`InputRow::extra`].
    pub slot: usize,
    /// The sensor's conversion.
    pub sensor: AdcSensor,
    /// The faults met, by kind, with their count.
    pub faults: BTreeMap<String, usize>,
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
            let Some(k) = counts(row.extra[c.slot], &c.column, row.time_s)? else {
                continue;
            };
            row.extra[c.slot] = match c.sensor.input.convert(k) {
                Ok(reading) => f64::from(reading.temp_c),
                Err(fault) => {
                    *c.faults.entry(fault_name(fault)).or_default() += 1;
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
            format!(
                "raw counts `{}` ({}, the library's conversion): {}",
                c.column,
                c.sensor.kind,
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
