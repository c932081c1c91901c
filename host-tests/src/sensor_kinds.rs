//! The kind of each `[observer] sensors` entry of a model file: a node name
//! (a thermocouple, as every file before kinds), or an inline table naming
//! the kind and its parameters:
//!
//! ```toml
//! [observer]
//! sensors = [
//!     "housing",                                   # a thermocouple
//!     { node = "end_turns", kind = "ntc", beta_k = 3950, r25_ohm = 10000,
//!       r_ref_ohm = 10000, topology = "sensor_to_ground", adc_bits = 12 },
//!     { node = "slot", kind = "kty84", r_ref_ohm = 1000,
//!       topology = "sensor_to_ground", adc_bits = 12 },
//!     { source = "winding", kind = "resistance", noise_fraction = 0.01,
//!       min_current_a = 0.5 },
//! ]
//! ```
//!
//! A resistive kind (`ntc`, `kty83`, `kty84`, `pt100`, `pt1000`) is read by
//! the MCU's ADC through a divider: [`SensorEntry::adc`] holds the library's
//! [`ResistiveInput`], the one conversion (ADC count -> [`SensorResult`])
//! that `codegen`'s generated module and the host tools call. A
//! `resistance` entry is a `[[source]]`'s winding read as a temperature
//! (the library's `ResistanceSensor`). Unknown keys, a value of the wrong
//! type and parameters the library refuses are refused with a message
//! naming the key (see `host-tests/MODEL_FORMAT.md`).

use std::collections::BTreeMap;

use coil_thermal::observer::network::{ResistanceSensor, SensorKind};
use coil_thermal::sensors::resistive::{Divider, ResistiveInput, Sensor, Topology};
use coil_thermal::sensors::SensorResult;
use coil_thermal::BuildError;
use serde::{Deserialize, Serialize};

use crate::model_file::Model;

/// A resistive sensor on the ADC: which curve, and its divider.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdcSensor {
    /// The kind's name as the file spells it (`ntc`, `kty84`, ...).
    pub kind: &'static str,
    /// The curve's parameters as the file gives them (for `codegen`).
    pub curve: Curve,
    /// The file's `min_c`, `max_c` \[degC\], if given.
    pub range_c: Option<(f32, f32)>,
    /// The library's conversion (divider, ADC width, curve, range).
    pub input: ResistiveInput,
}

/// A resistive sensor's curve, as the library's constructor takes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Curve {
    /// `Sensor::ntc_beta(r0_ohm, t0_c, beta_k)`.
    Beta {
        /// Resistance at `t0_c` \[ohm\].
        r0_ohm: f32,
        /// Its temperature \[degC\].
        t0_c: f32,
        /// Beta \[K\].
        beta_k: f32,
    },
    /// `Sensor::ntc_steinhart_hart(a, b, c)`.
    SteinhartHart([f32; 3]),
    /// `Sensor::KTY83_110`.
    Kty83,
    /// `Sensor::KTY84_130`.
    Kty84,
    /// `Sensor::PT100`.
    Pt100,
    /// `Sensor::PT1000`.
    Pt1000,
}

/// A winding's resistance as a sensor, by the `[[source]]`'s name.
#[derive(Debug, Clone, PartialEq)]
pub struct ResistanceEntry {
    /// The `[[source]]` whose winding is measured.
    pub source: String,
    /// The resistance's relative standard deviation (0.01 for 1 %).
    pub noise_fraction: f64,
    /// The least current magnitude \[A\] at which a resistance is a reading.
    pub min_current_a: f64,
    /// The winding's measured `R(T)`: resistance at 0 degC \[ohm\] and its
    /// slope \[ohm/K\] (both or neither; default: the source's own).
    pub measured: Option<(f64, f64)>,
    /// The temperatures a reading may imply \[degC\] (default the
    /// library's, -60 .. 300).
    pub range_c: Option<(f64, f64)>,
    /// Where the relative noise is taken in kelvin \[degC\] (default 100).
    pub noise_reference_c: Option<f64>,
}

impl ResistanceEntry {
    /// The library's sensor for the winding of `model`'s `[[source]]`
    /// `source` heating `node`, whose own `R(T)` is `resistance` (the
    /// model file's line, without the source's power `scale`: the
    /// winding's ohms as the drive measures them), unless the entry gives
    /// the measured one. The same plain data `codegen` writes into the
    /// generated module and `replay` and `faults` build their observer
    /// with.
    ///
    /// # Errors
    /// The library's refusal, naming the parameter.
    pub fn sensor(
        &self,
        source: usize,
        node: usize,
        resistance: coil_thermal::Resistance,
    ) -> Result<ResistanceSensor, BuildError> {
        let (r0, slope) = self
            .measured
            .unwrap_or((resistance.r_at_0c_ohm, resistance.slope_ohm_per_k));
        let (min_c, max_c) = self
            .range_c
            .unwrap_or(coil_thermal::observer::network::resistance::DEFAULT_RANGE_C);
        ResistanceSensor {
            source,
            node,
            r_at_0c_ohm: r0,
            slope_ohm_per_k: slope,
            noise_fraction: self.noise_fraction,
            noise_reference_c: self
                .noise_reference_c
                .unwrap_or(coil_thermal::observer::network::resistance::DEFAULT_NOISE_REFERENCE_C),
            min_current_a: self.min_current_a,
            min_c,
            max_c,
        }
        .checked()
    }
}

/// What one `[observer] sensors` entry is.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorKindSpec {
    /// A thermocouple (or any sensor whose column is a temperature).
    Thermocouple,
    /// A resistive sensor on the ADC.
    Adc(AdcSensor),
    /// A winding's resistance.
    Resistance(ResistanceEntry),
}

/// One `[observer] sensors` entry: where it measures and what it is. It
/// keeps the text it was read from, so a file written back reads the same.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawEntry", into = "RawEntry")]
pub struct SensorEntry {
    /// The node it measures (a `resistance` entry: empty, see
    /// [`Self::node_index`]).
    pub node: String,
    /// Its kind and parameters.
    pub kind: SensorKindSpec,
    raw: RawEntry,
}

/// The file's spelling: a node name or an inline table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
enum RawEntry {
    Node(String),
    Table(BTreeMap<String, toml::Value>),
}

impl From<SensorEntry> for RawEntry {
    fn from(e: SensorEntry) -> Self {
        e.raw
    }
}

impl std::fmt::Display for SensorEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.label())
    }
}

impl From<&str> for SensorEntry {
    /// A thermocouple on `node`.
    fn from(node: &str) -> Self {
        Self::thermocouple(node)
    }
}

/// The resistive kinds and their curves' keys.
const ADC_KINDS: [&str; 5] = ["ntc", "kty83", "kty84", "pt100", "pt1000"];
/// Every kind.
const KINDS: &str = "thermocouple, ntc, kty83, kty84, pt100, pt1000, resistance";
/// The divider's keys, shared by every resistive kind.
const DIVIDER_KEYS: [&str; 6] = [
    "r_ref_ohm",
    "topology",
    "adc_bits",
    "rail_margin_counts",
    "min_c",
    "max_c",
];

impl SensorEntry {
    /// A thermocouple on `node` (what a plain node name in the file is).
    pub fn thermocouple(node: &str) -> Self {
        Self {
            node: node.to_string(),
            kind: SensorKindSpec::Thermocouple,
            raw: RawEntry::Node(node.to_string()),
        }
    }

    /// The index of the node this sensor measures in `model`: its `node`,
    /// or for a `resistance` entry the node its source heats.
    ///
    /// # Errors
    /// No such node or `[[source]]`.
    pub fn node_index(&self, model: &Model) -> anyhow::Result<usize> {
        match &self.kind {
            SensorKindSpec::Resistance(_) => Ok(model.drives[self.source_index(model)?].node),
            _ => model.node_index(&self.node),
        }
    }

    /// A `resistance` entry's source index in `model`.
    ///
    /// # Errors
    /// Not a `resistance` entry, or no `[[source]]` of that name.
    pub fn source_index(&self, model: &Model) -> anyhow::Result<usize> {
        let SensorKindSpec::Resistance(r) = &self.kind else {
            anyhow::bail!("sensor `{}` is not a resistance sensor", self.label());
        };
        model
            .source_names
            .iter()
            .position(|name| *name == r.source)
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "[observer] sensors: no [[source]] `{}` for a resistance sensor (sources: {})",
                    r.source,
                    model.source_names.join(", ")
                )
            })
    }

    /// What the library's observer takes this sensor for: a temperature
    /// (a thermocouple, or a resistive sensor the MCU converts first), or
    /// the winding resistance of a `[[source]]` of `model` (see
    /// [`ResistanceEntry::sensor`]).
    ///
    /// # Errors
    /// No `[[source]]` of that name, or the library's refusal of the
    /// sensor, named.
    pub fn library_kind(&self, model: &Model) -> anyhow::Result<SensorKind> {
        let SensorKindSpec::Resistance(r) = &self.kind else {
            return Ok(SensorKind::Thermocouple);
        };
        let k = self.source_index(model)?;
        let drive = &model.drives[k];
        r.sensor(k, drive.node, drive.resistance)
            .map(SensorKind::Resistance)
            .map_err(|e| {
                anyhow::anyhow!(
                    "[observer] sensors: `{}`: the library refuses it: {e}",
                    self.label()
                )
            })
    }

    /// The resistive sensor's conversion, if this is one.
    pub fn adc(&self) -> Option<&AdcSensor> {
        match &self.kind {
            SensorKindSpec::Adc(a) => Some(a),
            _ => None,
        }
    }

    /// How the entry is named in messages: its node, or `resistance of
    /// <source>`.
    pub fn label(&self) -> String {
        match &self.kind {
            SensorKindSpec::Resistance(r) => format!("resistance of {}", r.source),
            _ => self.node.clone(),
        }
    }

    /// The kind's name as the file spells it.
    pub fn kind_name(&self) -> &'static str {
        match &self.kind {
            SensorKindSpec::Thermocouple => "thermocouple",
            SensorKindSpec::Adc(a) => a.kind,
            SensorKindSpec::Resistance(_) => "resistance",
        }
    }

    /// Converts a raw ADC count through the same library conversion the
    /// firmware calls; `None` for a kind without counts (a thermocouple's
    /// column is a temperature, a resistance sensor's ohms).
    pub fn convert_counts(&self, counts: u32) -> Option<SensorResult> {
        self.adc().map(|a| a.input.convert(counts))
    }
}

impl TryFrom<RawEntry> for SensorEntry {
    type Error = String;

    fn try_from(raw: RawEntry) -> Result<Self, String> {
        let table = match &raw {
            RawEntry::Node(node) => {
                if node.is_empty() {
                    return Err("[observer] sensors: an empty node name".into());
                }
                return Ok(Self {
                    node: node.clone(),
                    kind: SensorKindSpec::Thermocouple,
                    raw,
                });
            }
            RawEntry::Table(table) => table,
        };
        let t = Keys { table };
        let kind = t.string("kind")?.ok_or_else(|| {
            format!("[observer] sensors: an inline sensor needs `kind` (one of {KINDS})")
        })?;
        let (node, kind) = match kind.as_str() {
            "thermocouple" => {
                t.only(&["node", "kind"], "a thermocouple")?;
                (t.node()?, SensorKindSpec::Thermocouple)
            }
            "resistance" => {
                t.only(
                    &[
                        "source",
                        "kind",
                        "noise_fraction",
                        "min_current_a",
                        "r_at_0c_ohm",
                        "slope_ohm_per_k",
                        "min_c",
                        "max_c",
                        "noise_reference_c",
                    ],
                    "a resistance sensor (a [[source]]'s winding: `source`, not `node`)",
                )?;
                (String::new(), SensorKindSpec::Resistance(resistance(&t)?))
            }
            k if ADC_KINDS.contains(&k) => {
                let name = ADC_KINDS
                    .iter()
                    .find(|n| **n == k)
                    .copied()
                    .unwrap_or("ntc");
                (t.node()?, SensorKindSpec::Adc(adc(name, &t)?))
            }
            other => {
                return Err(format!(
                    "[observer] sensors: unknown kind `{other}` (one of {KINDS})"
                ))
            }
        };
        Ok(Self { node, kind, raw })
    }
}

/// Typed access to an inline table, every refusal naming its key.
struct Keys<'a> {
    table: &'a BTreeMap<String, toml::Value>,
}

impl Keys<'_> {
    fn only(&self, allowed: &[&str], what: &str) -> Result<(), String> {
        match self.table.keys().find(|k| !allowed.contains(&k.as_str())) {
            Some(k) => Err(format!(
                "[observer] sensors: unknown key `{k}` for {what} (its keys: {})",
                allowed.join(", ")
            )),
            None => Ok(()),
        }
    }

    fn string(&self, key: &str) -> Result<Option<String>, String> {
        match self.table.get(key) {
            None => Ok(None),
            Some(toml::Value::String(s)) => Ok(Some(s.clone())),
            Some(v) => Err(format!(
                "[observer] sensors: `{key}` must be a string, got {v}"
            )),
        }
    }

    fn node(&self) -> Result<String, String> {
        match self.string("node")? {
            Some(n) if !n.is_empty() => Ok(n),
            _ => Err("[observer] sensors: this sensor needs `node` (the node it measures)".into()),
        }
    }

    /// A finite number (an integer is taken as one).
    fn number(&self, key: &str) -> Result<Option<f64>, String> {
        let v = match self.table.get(key) {
            None => return Ok(None),
            Some(toml::Value::Float(f)) => *f,
            Some(toml::Value::Integer(i)) => *i as f64,
            Some(v) => {
                return Err(format!(
                    "[observer] sensors: `{key}` must be a number, got {v}"
                ))
            }
        };
        if v.is_finite() {
            Ok(Some(v))
        } else {
            Err(format!(
                "[observer] sensors: `{key}` must be finite, got {v}"
            ))
        }
    }

    fn required(&self, key: &str, what: &str) -> Result<f64, String> {
        self.number(key)?
            .ok_or_else(|| format!("[observer] sensors: {what} needs `{key}`"))
    }

    /// Both of two keys, or neither.
    fn pair(&self, a: &str, b: &str) -> Result<Option<(f64, f64)>, String> {
        match (self.number(a)?, self.number(b)?) {
            (Some(x), Some(y)) => Ok(Some((x, y))),
            (None, None) => Ok(None),
            _ => Err(format!(
                "[observer] sensors: `{a}` and `{b}` go together (give both or neither)"
            )),
        }
    }
}

/// The library's refusal, as the file's key.
fn refused(e: BuildError, key_of: &[(&str, &str)]) -> String {
    let BuildError::InvalidParameter { name } = e else {
        return format!("[observer] sensors: {e}");
    };
    let key = key_of
        .iter()
        .find(|(lib, _)| *lib == name)
        .map_or(name, |(_, key)| key);
    format!("[observer] sensors: `{key}` is impossible here (the library refuses {name}: see host-tests/MODEL_FORMAT.md for its range)")
}

fn adc(kind: &'static str, t: &Keys) -> Result<AdcSensor, String> {
    let what = format!("a {kind} sensor");
    let curve_keys: &[&str] = match kind {
        "ntc" => &["beta_k", "r25_ohm", "t0_c", "steinhart_hart"],
        _ => &[],
    };
    let mut allowed = vec!["node", "kind"];
    allowed.extend(DIVIDER_KEYS);
    allowed.extend(curve_keys);
    t.only(&allowed, &what)?;
    let topology = match t.string("topology")?.as_deref() {
        Some("sensor_to_ground") => Topology::SensorToGround,
        Some("sensor_to_supply") => Topology::SensorToSupply,
        Some(other) => {
            return Err(format!(
                "[observer] sensors: `topology` is `sensor_to_ground` (the sensor from the ADC node to ground, R_ref pulls up) or `sensor_to_supply`, got `{other}`"
            ))
        }
        None => return Err(format!("[observer] sensors: {what} needs `topology`")),
    };
    let r_ref = t.required("r_ref_ohm", &what)?;
    let bits = t.required("adc_bits", &what)?;
    if bits.fract() != 0.0 || !(1.0..=24.0).contains(&bits) {
        return Err(format!(
            "[observer] sensors: `adc_bits` is a whole number of bits, 1 ..= 24, got {bits}"
        ));
    }
    let margin = t.number("rail_margin_counts")?.unwrap_or(0.0);
    if margin.fract() != 0.0 || !(0.0..=f64::from(u32::MAX)).contains(&margin) {
        return Err(format!(
            "[observer] sensors: `rail_margin_counts` is a whole number of counts >= 0, got {margin}"
        ));
    }
    let keys = [
        ("reference_resistance_ohm", "r_ref_ohm"),
        ("bits", "adc_bits"),
        ("rail_margin_counts", "rail_margin_counts"),
        ("r0_ohm", "r25_ohm"),
        ("beta_k", "beta_k"),
        ("t0_c", "t0_c"),
        ("a", "steinhart_hart"),
        ("b", "steinhart_hart"),
        ("c", "steinhart_hart"),
        ("min_c", "min_c"),
        ("max_c", "max_c"),
    ];
    let divider = Divider::new(topology, r_ref as f32, bits as u8)
        .and_then(|d| d.with_rail_margin(margin as u32))
        .map_err(|e| refused(e, &keys))?;
    let curve = match kind {
        "ntc" => ntc(t, &what)?,
        "kty83" => Curve::Kty83,
        "kty84" => Curve::Kty84,
        "pt100" => Curve::Pt100,
        _ => Curve::Pt1000,
    };
    let sensor = match curve {
        Curve::Beta {
            r0_ohm,
            t0_c,
            beta_k,
        } => Sensor::ntc_beta(r0_ohm, t0_c, beta_k),
        Curve::SteinhartHart([a, b, c]) => Sensor::ntc_steinhart_hart(a, b, c),
        Curve::Kty83 => Ok(Sensor::KTY83_110),
        Curve::Kty84 => Ok(Sensor::KTY84_130),
        Curve::Pt100 => Ok(Sensor::PT100),
        Curve::Pt1000 => Ok(Sensor::PT1000),
    }
    .map_err(|e| refused(e, &keys))?;
    let range_c = t
        .pair("min_c", "max_c")?
        .map(|(lo, hi)| (lo as f32, hi as f32));
    let sensor = match range_c {
        Some((lo, hi)) => sensor.with_range(lo, hi).map_err(|e| refused(e, &keys))?,
        None => sensor,
    };
    Ok(AdcSensor {
        kind,
        curve,
        range_c,
        input: ResistiveInput::new(divider, sensor),
    })
}

/// An NTC by its beta (`beta_k`, `r25_ohm`, `t0_c` default 25) or its
/// Steinhart-Hart coefficients (`steinhart_hart = [a, b, c]`).
fn ntc(t: &Keys, what: &str) -> Result<Curve, String> {
    let sh = t.table.get("steinhart_hart");
    let beta = t.number("beta_k")?;
    match (sh, beta) {
        (Some(_), Some(_)) => Err(format!(
            "[observer] sensors: {what} takes `beta_k` (with `r25_ohm`) or `steinhart_hart`, not both"
        )),
        (Some(toml::Value::Array(abc)), None) => {
            if t.table.contains_key("r25_ohm") || t.table.contains_key("t0_c") {
                return Err(
                    "[observer] sensors: `r25_ohm` and `t0_c` belong to a beta NTC, not to `steinhart_hart`"
                        .to_string(),
                );
            }
            let nums: Option<Vec<f64>> = abc
                .iter()
                .map(|v| match v {
                    toml::Value::Float(f) => Some(*f),
                    toml::Value::Integer(i) => Some(*i as f64),
                    _ => None,
                })
                .collect();
            match nums.as_deref() {
                Some([a, b, c]) => Ok(Curve::SteinhartHart([*a as f32, *b as f32, *c as f32])),
                _ => Err("[observer] sensors: `steinhart_hart` is three numbers [a, b, c] (1/T = a + b ln R + c (ln R)^3, T in K, R in ohm)".into()),
            }
        }
        (Some(v), None) => Err(format!(
            "[observer] sensors: `steinhart_hart` is three numbers [a, b, c], got {v}"
        )),
        (None, Some(beta)) => {
            let r25 = t.required("r25_ohm", what)?;
            let t0 = t.number("t0_c")?.unwrap_or(25.0);
            Ok(Curve::Beta {
                r0_ohm: r25 as f32,
                t0_c: t0 as f32,
                beta_k: beta as f32,
            })
        }
        (None, None) => Err(format!(
            "[observer] sensors: {what} needs `beta_k` and `r25_ohm`, or `steinhart_hart`"
        )),
    }
}

fn resistance(t: &Keys) -> Result<ResistanceEntry, String> {
    let what = "a resistance sensor";
    let source = t.string("source")?.filter(|s| !s.is_empty()).ok_or_else(|| {
        "[observer] sensors: a resistance sensor needs `source` (the [[source]] whose winding it measures)".to_string()
    })?;
    let noise_fraction = t.required("noise_fraction", what)?;
    let min_current_a = t.required("min_current_a", what)?;
    let entry = ResistanceEntry {
        source,
        noise_fraction,
        min_current_a,
        measured: t.pair("r_at_0c_ohm", "slope_ohm_per_k")?,
        range_c: t.pair("min_c", "max_c")?,
        noise_reference_c: t.number("noise_reference_c")?,
    };
    // The library checks its fields once a source is known; the values
    // alone are checked here so that the file is refused on load.
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !positive(entry.noise_fraction) {
        return Err(format!(
            "[observer] sensors: `noise_fraction` is the resistance's relative standard deviation, > 0 (0.01 for 1 %), got {}",
            entry.noise_fraction
        ));
    }
    if !positive(entry.min_current_a) {
        return Err(format!(
            "[observer] sensors: `min_current_a` must be > 0 A, got {}",
            entry.min_current_a
        ));
    }
    if let Some((_, slope)) = entry.measured {
        if !positive(slope) {
            return Err(format!(
                "[observer] sensors: `slope_ohm_per_k` must be > 0 ohm/K (a winding's resistance rises with temperature), got {slope}"
            ));
        }
    }
    if let Some((lo, hi)) = entry.range_c {
        if lo >= hi {
            return Err(format!(
                "[observer] sensors: `min_c` ({lo}) must be below `max_c` ({hi})"
            ));
        }
    }
    Ok(entry)
}
