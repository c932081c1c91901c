//! The generated module's sensor conversions: for each `[observer] sensors`
//! entry read by the MCU's ADC (an NTC, a KTY, a platinum RTD; see
//! [`crate::sensor_kinds`]), the library's `ResistiveInput` as a constant,
//! and `convert_counts(j, counts)`, the ADC count -> `SensorResult` the
//! firmware calls before it hands the reading to the observer. The
//! constant is built by the same `const fn` constructors from the file's
//! numbers, so the MCU converts exactly as `replay` and the tests do.
//!
//! A model whose sensors are all thermocouples gets none of it (its module
//! is unchanged). A `resistance` entry (a winding's resistance) is refused:
//! the generated observer is assembled from thermocouple-only parts
//! (`NetworkObserver::from_parts`), and a resistance sensor's tables are
//! solved with its own noise.

use std::fmt::Write;

use anyhow::{bail, Result};
use coil_thermal::sensors::resistive::Topology;

use crate::sensor_kinds::{AdcSensor, Curve, SensorEntry, SensorKindSpec};

/// Refuses the sensors `codegen` cannot generate yet.
///
/// # Errors
/// A `resistance` entry, named.
pub fn check(sensors: &[SensorEntry]) -> Result<()> {
    if let Some(s) = sensors
        .iter()
        .find(|s| matches!(s.kind, SensorKindSpec::Resistance(_)))
    {
        bail!(
            "[observer] sensors: `{}` (kind = \"resistance\"): codegen does not generate a winding-resistance sensor yet (its observer tables are solved with the sensor's own noise and assembled by `NetworkObserver::from_parts_with_sensors`); build it with the library's `NetworkObserverBuilder::resistance_sensor` (docs/observer.md)",
            s.label()
        );
    }
    Ok(())
}

/// `f32` as a Rust literal that reads back to the same value.
fn lit(v: f32) -> String {
    format!("{v:?}_f32")
}

/// The `const` expression of one sensor's `ResistiveInput`.
fn input_expr(a: &AdcSensor) -> String {
    let d = a.input.divider();
    let topology = match d.topology() {
        Topology::SensorToGround => "Topology::SensorToGround",
        Topology::SensorToSupply => "Topology::SensorToSupply",
    };
    let sensor = match a.curve {
        Curve::Beta {
            r0_ohm,
            t0_c,
            beta_k,
        } => format!(
            "Sensor::ntc_beta({}, {}, {})",
            lit(r0_ohm),
            lit(t0_c),
            lit(beta_k)
        ),
        Curve::SteinhartHart([a, b, c]) => format!(
            "Sensor::ntc_steinhart_hart({}, {}, {})",
            lit(a),
            lit(b),
            lit(c)
        ),
        Curve::Kty83 => "Ok(Sensor::KTY83_110)".into(),
        Curve::Kty84 => "Ok(Sensor::KTY84_130)".into(),
        Curve::Pt100 => "Ok(Sensor::PT100)".into(),
        Curve::Pt1000 => "Ok(Sensor::PT1000)".into(),
    };
    let range = match a.range_c {
        Some((lo, hi)) => format!("Some(({}, {}))", lit(lo), lit(hi)),
        None => "None".into(),
    };
    format!(
        "Some(resistive(Divider::new({topology}, {}, {}), {}, {sensor}, {range}))",
        lit(d.reference_resistance_ohm()),
        d.bits(),
        d.rail_margin_counts()
    )
}

/// Appends the conversions to the generated module `o` (nothing when no
/// sensor is on the ADC).
pub fn write(o: &mut String, sensors: &[SensorEntry]) {
    if sensors.iter().all(|s| s.adc().is_none()) {
        return;
    }
    let items: Vec<String> = sensors
        .iter()
        .map(|s| match s.adc() {
            Some(a) => format!("    // {}: {}\n    {},", s.label(), a.kind, input_expr(a)),
            None => format!(
                "    // {}: {} (its driver gives a temperature)\n    None,",
                s.label(),
                s.kind_name()
            ),
        })
        .collect();
    let _ = write!(
        o,
        r#"
/// Each sensor's ADC conversion (`coil_thermal::sensors::resistive`), in
/// sensor order: `Some` for a resistive sensor read by the MCU's ADC
/// through its divider (the model file's `[observer] sensors` entry),
/// `None` for a sensor whose driver gives a temperature.
pub const SENSOR_INPUTS: [Option<coil_thermal::sensors::resistive::ResistiveInput>; SENSORS] = {{
    use coil_thermal::sensors::resistive::{{Divider, Sensor, Topology}};
    [
{}
    ]
}};

/// Sensor `j`'s ADC count as a reading: a temperature, or a fault (open,
/// short, a count that is no ADC code, a temperature outside the sensor's
/// range), never a fault read as a temperature. `None` for a sensor
/// without an ADC conversion, or no sensor `j`.
pub fn convert_counts(j: usize, counts: u32) -> Option<coil_thermal::SensorResult> {{
    match SENSOR_INPUTS.get(j) {{
        Some(Some(input)) => Some(input.convert(counts)),
        _ => None,
    }}
}}

/// A divider, a curve and an optional range as one input; a parameter the
/// library refuses stops the build (the host checked them all).
const fn resistive(
    divider: Result<coil_thermal::sensors::resistive::Divider, BuildError>,
    rail_margin_counts: u32,
    sensor: Result<coil_thermal::sensors::resistive::Sensor, BuildError>,
    range_c: Option<(f32, f32)>,
) -> coil_thermal::sensors::resistive::ResistiveInput {{
    let divider = match divider {{
        Ok(d) => match d.with_rail_margin(rail_margin_counts) {{
            Ok(d) => d,
            Err(_) => panic!("rail margin refused"),
        }},
        Err(_) => panic!("divider refused"),
    }};
    let sensor = match (sensor, range_c) {{
        (Ok(s), None) => s,
        (Ok(s), Some((lo, hi))) => match s.with_range(lo, hi) {{
            Ok(s) => s,
            Err(_) => panic!("range refused"),
        }},
        (Err(_), _) => panic!("sensor refused"),
    }};
    coil_thermal::sensors::resistive::ResistiveInput::new(divider, sensor)
}}
"#,
        items.join("\n")
    );
}
