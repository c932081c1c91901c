//! The generated module's sensor conversions: for each `[observer] sensors`
//! entry read by the MCU's ADC (an NTC, a KTY, a platinum RTD; see
//! [`crate::sensor_kinds`]), the library's `ResistiveInput` as a constant,
//! and `convert_counts(j, counts)`, the ADC count -> `SensorResult` the
//! firmware calls before it hands the reading to the observer. The
//! constant is built by the same `const fn` constructors from the file's
//! numbers, so the MCU converts exactly as `replay` and the tests do.
//!
//! A model whose sensors are all thermocouples gets none of it (its module
//! is unchanged). A `resistance` entry (a winding's resistance) gets a
//! `SENSOR_KINDS` table ([`write_kinds`]): its tables are solved with the
//! sensor's own noise, and `observer()` assembles them with
//! `NetworkObserver::from_parts_with_sensors`.

use std::fmt::Write;

use coil_thermal::observer::network::SensorKind;
use coil_thermal::sensors::resistive::Topology;

use crate::sensor_kinds::{AdcSensor, Curve, SensorEntry};

/// The `SENSOR_KINDS` table of a model with a winding-resistance sensor
/// (`kinds[j]`: what sensor `j` is, see
/// [`SensorEntry::library_kind`](crate::sensor_kinds::SensorEntry::library_kind)),
/// as a `const` of plain data; nothing for a model whose every sensor is a
/// temperature (its module, and its `observer()`'s `from_parts`, are then
/// unchanged).
pub fn write_kinds(o: &mut String, labels: &[String], kinds: &[SensorKind]) {
    if kinds.iter().all(|k| k.resistance().is_none()) {
        return;
    }
    let items: Vec<String> = labels
        .iter()
        .zip(kinds)
        .map(|(label, kind)| match kind.resistance() {
            None => format!("    // {label}: a temperature\n    SensorKind::Thermocouple,"),
            Some(r) => format!(
                "    // {label}: a winding's resistance, read at |I| >= {min:?} A\n    SensorKind::Resistance(ResistanceSensor {{\n        source: {source},\n        node: {node},\n        r_at_0c_ohm: {r0:?},\n        slope_ohm_per_k: {slope:?},\n        noise_fraction: {noise:?},\n        noise_reference_c: {reference:?},\n        min_current_a: {min:?},\n        min_c: {lo:?},\n        max_c: {hi:?},\n    }}),",
                source = r.source,
                node = r.node,
                r0 = r.r_at_0c_ohm,
                slope = r.slope_ohm_per_k,
                noise = r.noise_fraction,
                reference = r.noise_reference_c,
                min = r.min_current_a,
                lo = r.min_c,
                hi = r.max_c,
            ),
        })
        .collect();
    let _ = write!(
        o,
        r#"
/// What each sensor is, in sensor order: a temperature (a thermocouple, or
/// a resistive sensor converted by [`convert_counts`] where it has one), or
/// a winding's resistance, read through its `R(T)`. The tables of [`PARTS`]
/// were solved with each sensor's own noise, so [`observer`] assembles them
/// with these kinds. Feed a resistance sensor's slot of
/// `Inputs::readings` with `observer.resistance_reading(j, ohm, current_a,
/// sampled_at_us)` (or `voltage_current_reading`): no reading below its
/// least current, a fault for a measurement that cannot be the winding's.
pub const SENSOR_KINDS: [coil_thermal::observer::network::SensorKind; SENSORS] = {{
    use coil_thermal::observer::network::{{ResistanceSensor, SensorKind}};
    [
{}
    ]
}};
"#,
        items.join("\n")
    );
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
