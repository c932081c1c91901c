//! The campaign on a model file: its `[observer]` table built into the
//! library's network observer (as `codegen` builds the firmware's), run
//! against the model itself as the plant ([`FilePlant`], the explicit
//! stepper), the thermocouples reading the truth at the observer's sensor
//! nodes.
//!
//! The observer is the library's [`RunTimeObserver`]: the firmware's
//! observer at the model's own size (as `replay` runs it,
//! [`crate::library_observer`]), with one sensor per `[observer]` sensor
//! and no cap on nodes, sources or sensors below what memory allows. The
//! model's sources keep their heat biases at the model file's bias noise
//! (the `[observer]` table's, or the default, as `codegen` builds it),
//! each its own where the sensors can tell them apart and one shared in
//! proportion to their Joule power where they cannot (the builder's
//! default [`BiasMode::Auto`](coil_thermal::observer::network::BiasMode):
//! three phases under one housing thermocouple need no `bias_sources`
//! line): the campaign runs the firmware's filter, heat-bias alarm and
//! all, and its starts and restores (test
//! `the_campaign_runs_a_model_of_any_size`).

use coil_thermal::observer::network::{
    NetworkInputsOf, NetworkSettings, ResistanceSensor, RunTimeObserver, RunTimeObserverState,
};
use coil_thermal::observer::snapshot::snapshot_len;
use coil_thermal::observer::SensorChecks;
use coil_thermal::{SensorFault, SensorResult, VoltageDrive};
use nalgebra::Dyn;

use super::{
    frozen_ticks, reading_period_s, run_on, Consistency, FaultConfig, FaultError, FaultReport,
    Subject, TickInputs, TickView,
};
use crate::codegen::FirmwareInputs;
use crate::codegen::ObserverSpec;
use crate::firmware::FirmwareConfig;
use crate::library_observer::firmware_observer_spec;
use crate::model_file::{Model, VoltageSource};
use crate::sim::{FilePlant, Plant};

/// A model file's observer at its own size, with its plant.
struct NetSubject {
    name: String,
    observer: RunTimeObserver,
    settings: NetworkSettings,
    plant: FilePlant,
    /// The model's nodes.
    nodes: usize,
    /// The observer's boundaries and sources (a model without a source
    /// has one that never carries current, see [`firmware_observer_spec`]).
    boundaries: usize,
    sources: usize,
    /// Per node: it has a critical temperature.
    limited: Vec<bool>,
    sensor_nodes: Vec<usize>,
    alarm_nodes: Vec<usize>,
    /// The generated module's currents and drives from the model's inputs
    /// (each power scale folded into its resistance, as `codegen` builds
    /// the network).
    firmware_inputs: FirmwareInputs,
    /// Per source: the model input it is driven by.
    source_input: Vec<usize>,
    /// Some source is driven by a voltage: the observer takes the drives
    /// through `tick_voltage`, and their limits are duties (or volts) from
    /// `drive_limit`.
    voltage_driven: bool,
    /// Per sensor: a winding's resistance (read in ohms, see
    /// [`resistance_measured`]), or `None` for a temperature.
    resistances: Vec<Option<ResistanceSensor>>,
}

/// The observer's state and the inputs its ticks fill (held here so that
/// a tick allocates nothing).
#[derive(Debug, Clone)]
struct NetState {
    observer: RunTimeObserverState,
    inputs: NetworkInputsOf<Dyn, Dyn, Dyn>,
    drives: Vec<Option<VoltageDrive>>,
}

/// What the drive measures of a winding whose campaign reading is
/// `reading` (the truth at its node with the sensor's noise, or a fault):
/// the ohms its `R(T)` gives that temperature; an open winding `+inf` (no
/// current, a `V/I` that does not exist); a short to ground 0 ohm and one
/// to the supply a negative resistance (a drop of the wrong sign). The
/// observer's `resistance_reading` then turns it into the reading or fault
/// the firmware fuses.
fn resistance_measured(sensor: &ResistanceSensor, reading: SensorResult) -> f32 {
    match reading {
        Ok(r) => (sensor.r_at_0c_ohm + sensor.slope_ohm_per_k * f64::from(r.temp_c)) as f32,
        Err(SensorFault::OpenCircuit) => f32::INFINITY,
        Err(SensorFault::ShortToGnd) => 0.0,
        Err(SensorFault::ShortToVcc) => -(sensor.r_at_0c_ohm as f32),
        Err(_) => f32::NAN,
    }
}

impl NetSubject {
    fn build(
        model: &Model,
        spec: &ObserverSpec,
        sensor_nodes: Vec<usize>,
        cfg: &FaultConfig,
    ) -> Result<Self, FaultError> {
        let invalid = |e: anyhow::Error| FaultError::Invalid(format!("{e:#}"));
        // The firmware's settings (the `[observer]` table over codegen's
        // defaults, as `replay` and `codegen` resolve them), with the
        // campaign's step, reading period, stuck tolerance and origin.
        let firmware = FirmwareConfig::of(model, Some(spec)).map_err(invalid)?;
        let (flag, loss) = frozen_ticks(cfg.step_us);
        let settings = NetworkSettings {
            step_us: cfg.step_us,
            correction_period_s: reading_period_s(cfg),
            checks: SensorChecks {
                stuck_tolerance_k: cfg
                    .stuck_tolerance_k
                    .unwrap_or(firmware.settings.checks.stuck_tolerance_k),
                ..firmware.settings.checks
            },
            origin_c: cfg.ambient_c,
            frozen_flag_ticks: flag,
            frozen_loss_ticks: loss,
            ..firmware.settings
        };
        // Each sensor's kind, as `codegen` solves the tables with it (a
        // resistance with its own noise).
        let (network, run_time) = firmware_observer_spec(
            model,
            &firmware,
            settings,
            sensor_nodes.clone(),
            firmware.sensor_kinds.clone(),
        )
        .map_err(invalid)?;
        let observer = RunTimeObserver::build_at_run_time(&network, &run_time).map_err(|e| {
            // The same words as `codegen` and `replay`.
            match crate::codegen::build_hint::observer_build_hint(&e, settings.bias_noise_w2_per_s)
            {
                Some(hint) => FaultError::Invalid(format!(
                    "the observer of model `{}` does not build: {e}; {hint}",
                    model.name
                )),
                None => FaultError::Build(e),
            }
        })?;
        if let Some(k) = model
            .drives
            .iter()
            .position(|d| matches!(d.voltage, Some(VoltageSource::PwmSignal(_))))
        {
            return Err(FaultError::Invalid(format!(
                "model `{}`: [[source]] #{} takes its supply from a trace column, and the campaign has no signal columns; \
                 give it a constant supply_v for the campaign",
                model.name,
                k + 1
            )));
        }
        let plant = FilePlant::new(model.clone()).map_err(invalid)?;
        let mut alarm_nodes: Vec<usize> = (0..model.nodes.len())
            .filter(|n| model.critical_c[*n].is_some())
            .collect();
        if alarm_nodes.is_empty() {
            alarm_nodes = (0..model.nodes.len()).collect();
        }
        Ok(Self {
            name: model.name.clone(),
            observer,
            settings,
            plant,
            nodes: model.nodes.len(),
            boundaries: network.boundaries(),
            sources: network.sources().len(),
            limited: model.critical_c.iter().map(Option::is_some).collect(),
            sensor_nodes,
            alarm_nodes,
            firmware_inputs: FirmwareInputs::new(model),
            source_input: model.drives.iter().map(|d| d.input).collect(),
            voltage_driven: model.has_voltage_drives(),
            resistances: firmware
                .sensor_kinds
                .iter()
                .map(|k| k.resistance().copied())
                .collect(),
        })
    }

    /// `observer` with the inputs its ticks fill.
    fn held(&self, observer: RunTimeObserverState) -> NetState {
        NetState {
            observer,
            inputs: NetworkInputsOf {
                currents_a: vec![0.0; self.sources],
                boundary_c: vec![0.0; self.boundaries],
                readings: vec![None; self.sensor_nodes.len()],
                now_us: 0,
                elapsed_us: 0,
            },
            drives: vec![None; self.sources],
        }
    }

    /// Every boundary at `ambient_c` \[degC\].
    fn boundary_c(&self, ambient_c: f32) -> Vec<f32> {
        vec![ambient_c; self.boundaries]
    }

    /// One reading per sensor from `readings_c` \[degC\] (missing: none).
    fn readings(&self, readings_c: &[Option<f32>]) -> Vec<Option<f32>> {
        (0..self.sensor_nodes.len())
            .map(|j| readings_c.get(j).copied().flatten())
            .collect()
    }
}

impl Subject for NetSubject {
    type State = NetState;

    fn name(&self) -> String {
        self.name.clone()
    }
    fn sensor_nodes(&self) -> &[usize] {
        &self.sensor_nodes
    }
    fn alarm_nodes(&self) -> &[usize] {
        &self.alarm_nodes
    }
    fn inputs(&self) -> usize {
        self.plant.info().inputs.len()
    }
    fn plant(&self) -> Box<dyn Plant> {
        Box::new(self.plant.clone())
    }
    fn bias_noise_w2_per_s(&self) -> Option<f64> {
        Some(self.settings.bias_noise_w2_per_s)
    }
    fn sensor_model(
        &self,
        sensor: usize,
        truth_c: f32,
        campaign: super::SensorModel,
    ) -> super::SensorModel {
        match self.resistances.get(sensor).copied().flatten() {
            // The relative noise as kelvin at the truth: `f R(T) / s`.
            Some(r) => super::SensorModel {
                quantum_k: 0.0,
                noise_k: r.noise_fraction
                    * (r.r_at_0c_ohm / r.slope_ohm_per_k + f64::from(truth_c)),
                ..campaign
            },
            None => campaign,
        }
    }
    fn band_widening_k(&self, sensor: usize) -> f64 {
        // As the library lowers a resistance sensor's band.
        self.resistances
            .get(sensor)
            .copied()
            .flatten()
            .map_or(0.0, |r| self.settings.gate_threshold.sqrt() * r.sigma_k())
    }
    fn consistency(&self) -> Consistency {
        Consistency {
            offset_k: self.settings.checks.consistency_offset_k,
            fraction: self.settings.checks.consistency_fraction,
            stuck_threshold_k: self.settings.checks.stuck_threshold_k,
            stuck_tolerance_k: self.settings.checks.stuck_tolerance_k,
        }
    }
    fn state(&self, ambient_c: f32) -> Self::State {
        let state = self
            .observer
            .state(&vec![ambient_c; self.nodes], &self.boundary_c(ambient_c));
        self.held(self.observer.with_warm_up(state))
    }
    fn tick(&self, state: &mut Self::State, i: &TickInputs<'_>) -> TickView {
        let NetState {
            observer: observer_state,
            inputs,
            drives,
        } = state;
        // As the generated `source_currents_a` (no signal: the campaign
        // refuses speed terms).
        inputs.currents_a.fill(0.0);
        self.firmware_inputs
            .currents_a(i.currents_a, &[], &mut inputs.currents_a);
        for (j, r) in inputs.readings.iter_mut().enumerate() {
            let z = i.readings.get(j).copied().flatten();
            *r = match (z, self.resistances.get(j).copied().flatten()) {
                // A winding's resistance, read by the firmware's call at
                // its source's current.
                (Some(z), Some(sensor)) => self.observer.resistance_reading(
                    j,
                    resistance_measured(&sensor, z.result),
                    inputs.currents_a.get(sensor.source).copied().unwrap_or(0.0),
                    z.sampled_at_us,
                ),
                _ => z,
            };
        }
        inputs.boundary_c.fill(i.ambient_c);
        inputs.now_us = i.now_us;
        inputs.elapsed_us = i.elapsed_us;
        if self.voltage_driven {
            // As the generated `source_drives`: the trace's duty on the
            // supply times the power scale (folded into the resistance),
            // so the duty's own rules (flags, clamp) act on the trace's
            // duty.
            for (m, d) in drives.iter_mut().enumerate() {
                *d = self.firmware_inputs.drive(m, i.currents_a, &[]);
            }
            self.observer.tick_voltage(observer_state, inputs, drives);
        } else {
            self.observer.tick(observer_state, inputs);
        }
        self.view(state)
    }
    fn view(&self, state: &Self::State) -> TickView {
        let out = state.observer.outputs();
        // An input's limit: the tightest of its sources', as the
        // generated `input_drive_limits` gives it (a source carries its
        // input's current, its power scale in its resistance).
        let mut limits_a = vec![f32::INFINITY; self.inputs()];
        for (m, (input, limit)) in self.source_input.iter().zip(&out.limits).enumerate() {
            if let Some(l) = limits_a.get_mut(*input) {
                // A voltage drive's limit in its own unit: the duty on
                // its supply, or the voltage.
                let per_input = match self.firmware_inputs.limit_supply_v(m, &[]) {
                    Some(supply_v) => {
                        let d = self.observer.drive_limit(&state.observer, m, supply_v);
                        self.firmware_inputs
                            .drive_limit(m, d.duty, d.voltage_v)
                            .unwrap_or(f32::INFINITY)
                    }
                    None => limit.current_a,
                };
                *l = l.min(per_input);
            }
        }
        TickView {
            temps_c: out.temps_c.clone(),
            sensors: out.sensors.clone(),
            flags: out.flags,
            shutdown: out.alarm.shutdown,
            upper_c: out.upper_c.clone(),
            limits_a,
        }
    }
    fn alarm_limits_c(&self, ambient_c: f32) -> Vec<Option<f32>> {
        let limits = self.observer.alarm().alarm_limits_c(ambient_c);
        (0..self.nodes)
            .map(|n| self.limited[n].then_some(limits[n]))
            .collect()
    }
    fn start(&self, readings_c: &[Option<f32>], ambient_c: f32) -> Self::State {
        let readings = self.readings(readings_c);
        self.held(self.observer.start(&readings, &self.boundary_c(ambient_c)))
    }
    fn restore_with_readings(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        readings_c: &[Option<f32>],
    ) -> Result<Self::State, String> {
        let readings = self.readings(readings_c);
        let boundary_c = self.boundary_c(ambient_c);
        self.observer
            .restore_with_readings(bytes, now_s, max_age_s, &boundary_c, &readings)
            .map(|s| self.held(self.observer.with_warm_up(s)))
            .map_err(|e| e.to_string())
    }
    fn save(&self, state: &Self::State, now_s: u32) -> Option<Vec<u8>> {
        let mut bytes = vec![0u8; snapshot_len(self.nodes)];
        self.observer
            .save(&state.observer, now_s, &mut bytes)
            .ok()?;
        Some(bytes)
    }
    fn restore(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        off_s: Option<f32>,
    ) -> Result<Self::State, String> {
        let boundary_c = self.boundary_c(ambient_c);
        self.observer
            .restore_after(bytes, now_s, max_age_s, &boundary_c, off_s)
            .map(|s| self.held(self.observer.with_warm_up(s)))
            .map_err(|e| e.to_string())
    }
    fn conservative_state(&self, readings_c: &[Option<f32>], ambient_c: f32) -> Self::State {
        let readings = self.readings(readings_c);
        let state = self
            .observer
            .conservative_state(&readings, &self.boundary_c(ambient_c));
        self.held(self.observer.with_warm_up(state))
    }
    fn latched(&self, state: &Self::State) -> bool {
        state.observer.outputs().alarm.shutdown
    }
}

/// Runs the whole matrix on a model file's observer (`spec`, with
/// `sensors` the node names of the thermocouples in use) against the
/// model as the plant; `cfg.sensors` flags each of them.
///
/// # Errors
/// No sensor, an unknown node, speed-dependent terms, or an observer that
/// does not build.
pub fn run_model(
    model: &Model,
    spec: &ObserverSpec,
    cfg: &FaultConfig,
) -> Result<FaultReport, FaultError> {
    let invalid = |m: String| FaultError::Invalid(m);
    if spec.sensors.is_empty() {
        return Err(invalid(
            "the observer needs a sensor: name the node each thermocouple measures in the model's `[observer] sensors = [\"node\"]`".into(),
        ));
    }
    if !model.speed_losses.is_empty()
        || !model.losses.is_empty()
        || model.has_varying_conductances()
        || model.drives.iter().any(|d| d.speed.is_some())
    {
        return Err(invalid(
            "speed-dependent terms need a speed, and the campaign has no signal columns".into(),
        ));
    }
    let sensor_nodes = spec
        .sensors
        .iter()
        .map(|s| s.node_index(model))
        .collect::<anyhow::Result<Vec<_>>>()
        .map_err(|e| invalid(format!("{e:#}")))?;
    NetSubject::build(model, spec, sensor_nodes, cfg).and_then(|s| run_on(cfg, s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::faults::Subject;
    use crate::model_file::ModelFile;
    use coil_thermal::observer::TimedReading;
    use coil_thermal::Reading;

    /// The campaign's observer of `drive-3node-fitted.toml` with its
    /// winding's `[[source]]` lines replaced by `source`.
    fn subject(source: &str) -> NetSubject {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/models/drive-3node-fitted.toml"
        );
        let text = std::fs::read_to_string(path)
            .unwrap()
            .replace("r0_ohm = 1.2\nalpha_per_k = 0.00393\n", source);
        let file = ModelFile::parse(&text, "scaled.toml").unwrap();
        let spec = file.observer.clone().unwrap();
        let model = Model::build(&file).unwrap();
        let nodes = vec![spec.sensors[0].node_index(&model).unwrap()];
        NetSubject::build(&model, &spec, nodes, &FaultConfig::default()).unwrap()
    }

    /// A power scale (`scale = 1.5`, dq currents) is the winding's
    /// resistance times 1.5 in the observer the campaign runs, as in the
    /// one `codegen` flashes: the same estimate and the same limit on the
    /// input's own current, over half an hour at 5 A that takes the
    /// winding into the limiter's taper (where the scale used to enter as
    /// the current times `sqrt(1.5)`, whose limit in input amperes was
    /// the hardware limit over `sqrt(1.5)`).
    #[test]
    fn a_power_scale_is_the_windings_resistance_times_it() {
        let scaled = subject("r0_ohm = 1.2\nalpha_per_k = 0.00393\nscale = 1.5\n");
        let resistive = subject("r0_ohm = 1.8\nalpha_per_k = 0.00393\n");
        let (mut a, mut b) = (scaled.state(25.0), resistive.state(25.0));
        let mut lowest_a = f32::INFINITY;
        for k in 0..1_800_000u32 {
            let now_us = (k + 1) * 1000;
            let readings = [(k % 1000 == 0).then_some(TimedReading {
                result: Ok(Reading::new(25.0 + (k as f32) * 1e-5)),
                sampled_at_us: now_us,
            })];
            let inputs = TickInputs {
                currents_a: &[5.0],
                ambient_c: 25.0,
                readings: &readings,
                now_us,
                elapsed_us: 1000,
            };
            let (va, vb) = (
                scaled.tick(&mut a, &inputs),
                resistive.tick(&mut b, &inputs),
            );
            if k % 10_000 == 0 || k == 1_799_999 {
                for (ta, tb) in va.temps_c.iter().zip(&vb.temps_c) {
                    assert!((ta - tb).abs() < 1e-3, "tick {k}: {ta} vs {tb} degC");
                }
                let (la, lb) = (va.limits_a[0], vb.limits_a[0]);
                assert!((la - lb).abs() < 1e-3, "tick {k}: {la} vs {lb} A");
                lowest_a = lowest_a.min(la);
            }
        }
        assert!(
            lowest_a < 5.5,
            "the limiter acted: lowest {lowest_a} A of 6 A"
        );
    }
}
