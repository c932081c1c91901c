//! The firmware observer of a model file: what `coil-thermal codegen`
//! flashes, resolved once from the file's `[observer]` table and the
//! library's defaults, for every host command that runs it.
//!
//! `codegen` writes these settings into the generator it compiles;
//! `replay` builds its [`ObserverEstimator`](crate::library_observer) from
//! the same [`FirmwareConfig`], so the derating, the sensor noise, the
//! correction period, the limits and the bias states the host replays are
//! the ones the MCU runs. A key missing from the table takes the value
//! `codegen` gives it (the library's [`NetworkSettings::DEFAULT`], the
//! derating product 0.648 of [`DeratingRule::omnimagnet`], an 8 A hardware
//! limit); a model file without a table runs with all of them.

use coil_thermal::observer::network::{NetworkSettings, SensorKind};
use coil_thermal::protect::derating::{DeratingFactor, DeratingRule};
use coil_thermal::protect::margin::UncertaintyMargin;

use crate::codegen::ObserverSpec;
use crate::model_file::Model;
use crate::sensor_kinds::{SensorEntry, SensorKindSpec};

/// Every current's hardware limit when the table has none \[A\] (as
/// `codegen`).
pub const DEFAULT_HARDWARE_LIMIT_A: f64 = 8.0;

/// The firmware observer's settings of one model file.
#[derive(Debug, Clone, PartialEq)]
pub struct FirmwareConfig {
    /// The file has an `[observer]` table (without one, every value is
    /// `codegen`'s default and `codegen` refuses the file: no sensor).
    pub from_table: bool,
    /// The node of each `[observer] sensors` entry, in sensor order.
    pub sensor_nodes: Vec<usize>,
    /// Each `[observer] sensors` entry's kind, in sensor order.
    pub sensors: Vec<SensorEntry>,
    /// What the library's observer takes each of them for, in sensor
    /// order: a temperature, or a winding's resistance (its tables are
    /// then solved with that sensor's own noise, as `codegen` solves them).
    pub sensor_kinds: Vec<SensorKind>,
    /// Critical temperature of each node \[degC\] (`[[node]] critical_c`).
    pub critical_c: Vec<Option<f64>>,
    /// Every current's hardware limit \[A\].
    pub hardware_limit_a: f64,
    /// The product of the alarm's derating factors (dimensionless, in
    /// (0, 1]).
    pub derating: f64,
    /// The library settings, the table's keys over the defaults.
    pub settings: NetworkSettings,
    /// Which of the network's sources carry a heat-input bias.
    pub bias_sources: Vec<bool>,
    /// The biased sources share one heat bias in proportion to their Joule
    /// power (`[observer] shared_bias`, `BiasMode::Shared`); else
    /// `BiasMode::Auto`.
    pub shared_bias: bool,
}

impl FirmwareConfig {
    /// The firmware observer `codegen` would build from `model` and its
    /// `[observer]` table `spec` (sensor nodes by name resolved; the
    /// ambient is the boundary named `ambient`, else boundary 0).
    ///
    /// # Errors
    /// A sensor naming no node of the model; a derating outside (0, 1].
    pub fn of(model: &Model, spec: Option<&ObserverSpec>) -> anyhow::Result<Self> {
        let table = spec.cloned().unwrap_or_default();
        let mut settings = NetworkSettings::DEFAULT;
        if let Some(v) = table.step_us {
            settings.step_us = v;
        }
        if let Some(v) = table.loop_period_us {
            settings.loop_period_us = v;
        }
        if let Some(v) = table.sensor_sigma_k {
            settings.sensor_sigma_k = v;
        }
        if let Some(v) = table.node_noise_k2_per_s {
            settings.node_noise_k2_per_s = v;
        }
        if let Some(v) = table.correction_period_s {
            settings.correction_period_s = v;
        }
        if let Some(v) = table.max_current_a {
            settings.max_current_a = v;
        }
        if let Some(v) = table.bias_noise_w2_per_s {
            settings.bias_noise_w2_per_s = v;
        }
        if let Some(v) = table.bias_tau_s {
            settings.bias_tau_s = v;
        }
        if let Some(name) = &table.boundary_offset {
            settings.boundary_offset = Some(boundary_index(model, name)?);
        }
        if let Some(v) = table.boundary_offset_std_k {
            settings.boundary_offset_std_k = v;
        }
        if let Some(v) = table.boundary_offset_tau_s {
            settings.boundary_offset_tau_s = v;
        }
        if let Some(v) = table.max_cooling_bias_fraction {
            settings.max_cooling_bias_fraction = v;
        }
        if let Some(v) = table.stuck_tolerance_k {
            settings.checks.stuck_tolerance_k = v;
        }
        if let Some(v) = table.integer_model_step {
            settings.integer_model_step = v;
        }
        if let Some(v) = table.predictor_elements_per_stage {
            settings.predictor_elements_per_stage = v;
        }
        if let Some(v) = table.correction_in_two_ticks {
            settings.correction_in_two_ticks = v;
        }
        if table.unmeasured_margin.is_some() || table.unmeasured_margin_offset_k.is_some() {
            let default = settings.unmeasured_margin;
            let fraction = table.unmeasured_margin.unwrap_or(default.rise_fraction);
            let offset_k = table.unmeasured_margin_offset_k.unwrap_or(default.offset_k);
            let ok = |v: f64| v.is_finite() && v >= 0.0;
            if !(ok(fraction) && ok(offset_k)) {
                anyhow::bail!(
                    "[observer] unmeasured_margin ({fraction}) and unmeasured_margin_offset_k ({offset_k} K) must be finite and >= 0"
                );
            }
            settings.unmeasured_margin = UncertaintyMargin::new(fraction, offset_k);
        }
        settings.ambient_boundary = model
            .boundaries
            .iter()
            .position(|b| b.name == "ambient")
            .unwrap_or(0);
        let derating = table
            .derating
            .unwrap_or_else(|| DeratingRule::omnimagnet().product());
        if !(derating > 0.0 && derating <= 1.0) {
            anyhow::bail!("[observer] derating must be in (0, 1], got {derating}");
        }
        let sensor_nodes = table
            .sensors
            .iter()
            .map(|s| s.node_index(model))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let sensor_kinds = table
            .sensors
            .iter()
            .map(|s| s.library_kind(model))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let sources = model.network.sources().len();
        Ok(Self {
            from_table: spec.is_some(),
            sensor_nodes,
            sensor_kinds,
            sensors: table.sensors.clone(),
            critical_c: model.critical_c.clone(),
            hardware_limit_a: table.hardware_limit_a.unwrap_or(DEFAULT_HARDWARE_LIMIT_A),
            derating,
            settings,
            bias_sources: (0..sources).map(|m| model.carries_bias(m)).collect(),
            shared_bias: table.shared_bias.unwrap_or(false),
        })
    }

    /// Refuses a sensor whose readings `what` cannot take as the firmware
    /// does: a winding's resistance, which `replay` and `faults` fuse
    /// through the library's resistance sensor, and `what` does not.
    ///
    /// # Errors
    /// The first `resistance` entry, named.
    pub fn require_temperature_sensors(&self, what: &str) -> anyhow::Result<()> {
        match self
            .sensors
            .iter()
            .find(|s| matches!(s.kind, SensorKindSpec::Resistance(_)))
        {
            Some(s) => anyhow::bail!(
                "{what} does not take a winding's resistance (`[observer] sensors` entry `{}`, kind = \"resistance\"): it scores temperatures against temperatures; `replay`, `faults` and `codegen` take it",
                s.label()
            ),
            None => Ok(()),
        }
    }

    /// Some sensor is a winding's resistance.
    pub fn has_resistance_sensor(&self) -> bool {
        self.sensor_kinds.iter().any(|k| k.resistance().is_some())
    }

    /// The derating rule the alarm applies: the table's product as one
    /// factor, or the library's default rule itself (the same product).
    pub fn rule(&self) -> DeratingRule {
        if self.derating == DeratingRule::omnimagnet().product() {
            DeratingRule::omnimagnet()
        } else {
            DeratingRule::new(&[DeratingFactor::new("derating", self.derating)])
                .expect("a product in (0, 1] is one valid factor")
        }
    }
}

/// The index of `[[boundary]]` `name` (`[observer] boundary_offset`).
///
/// # Errors
/// No boundary of that name.
pub fn boundary_index(model: &Model, name: &str) -> anyhow::Result<usize> {
    model
        .boundaries
        .iter()
        .position(|b| b.name == name)
        .ok_or_else(|| {
            anyhow::anyhow!(
                "[observer] boundary_offset: no [[boundary]] `{name}` (boundaries: {})",
                model
                    .boundaries
                    .iter()
                    .map(|b| b.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })
}

/// A replay flag that changes the firmware's observer: named in the
/// output, since the run is then not what the MCU computes.
#[derive(Debug, Clone, PartialEq)]
pub struct Override {
    /// The flag (`--factors`).
    pub flag: &'static str,
    /// What it set, against the firmware's value (`derating 1 instead of
    /// 0.648`).
    pub what: String,
}
