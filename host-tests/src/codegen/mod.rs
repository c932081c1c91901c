//! `coil-thermal codegen`: a model file to a `no_std` Rust module that
//! holds a [`NetworkObserver`](coil_thermal::observer::network::NetworkObserver)
//! solved on the host, as `const` data in flash.
//!
//! # How the tables are solved: by the library, at the model's own sizes
//!
//! The observer is const-generic in its sizes, and a compiled tool cannot
//! instantiate sizes it was not compiled for. So the generator writes the
//! model's network as Rust (the module's `network()`), compiles a small
//! program with the model's exact sizes against this library (cargo, in
//! [`work_dir`], the dependencies built once and reused), and runs it: it
//! calls
//! [`NetworkObserverBuilder::parts`](coil_thermal::observer::network::NetworkObserverBuilder::parts),
//! the same solve as `build()` on the MCU, and prints the tables with
//! [`NetworkParts::write_rust`](coil_thermal::observer::network::NetworkParts::write_rust).
//! The tables carry what the assembly derives from them too
//! ([`AssembledTables`](coil_thermal::observer::network::AssembledTables)),
//! so the module's `static OBSERVER` is
//! `NetworkObserver::from_assembled_parts(&PARTS)`, a `const fn` the
//! compiler evaluates: no exponential, no Riccati solution, no eigenvalue,
//! no assembly and no `f64` on the MCU, and the same observer to the bit as
//! the builder's (`from_parts(&PARTS)`, which checks the assembled tables
//! against its own derivation).
//!
//! # What a model needs
//!
//! The `[observer]` table of the model file (see `host-tests/MODEL_FORMAT.md`)
//! names the sensors (`sensors = ["housing"]`: the node each thermocouple
//! measures) and optionally the hardware current limit and a few settings.
//! Critical temperatures come from the nodes' `critical_c`; a source's
//! `scale` is folded into its resistance (`k R(T) I^2`). Each network
//! source is one current of the observer, in source order: the
//! `[[source]]`s (sources sharing an input, series layers, get the same
//! current), then the speed and `[[loss]]` losses as 1 ohm sources. The
//! generated `source_currents_a(input_a, signal)` makes them from the
//! model's current inputs and signals (the speed), as the host does
//! (the `currents` submodule). Only a conductance that depends on a
//! signal is refused: it changes the network, and the tables are solved
//! for one.
//!
//! # Built-in devices: `--device omnimagnet`, `--device hppa-grid`
//!
//! The reference devices have fixed sizes, so they are solved in this
//! process and written with a `static OBSERVER` the compiler assembles
//! (the `devices` submodule: [`generate_omnimagnet`], [`generate_grid`]).

use std::ffi::OsString;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::model_file::{Model, ModelFile};

pub mod build_hint;
mod currents;
mod devices;
mod sensors;

pub use currents::FirmwareInputs;
use currents::{
    check_f32_range, currents_of, input_limits_fn, source_currents_fn, source_drives_fn, CurrentOf,
};
pub use devices::*;

/// The `[observer]` table of a model file: what the firmware observer needs
/// beyond the network.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObserverSpec {
    /// Each sensor, in sensor order: a node name (a thermocouple) or its
    /// kind and parameters (see [`crate::sensor_kinds`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensors: Vec<crate::sensor_kinds::SensorEntry>,
    /// Every current's hardware limit \[A\] (default 8).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hardware_limit_a: Option<f64>,
    /// Largest plausible current \[A\] before it is clamped and flagged
    /// (default 100).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_current_a: Option<f64>,
    /// Product of the derating factors of the alarm limits (default 0.648,
    /// the HPPA rule without its magnet-plate factor).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub derating: Option<f64>,
    /// Model step \[us\] (default 1000). Longer than the loop's tick
    /// (`loop_period_us`), the steps take the mean `I^2` of their ticks
    /// (see `NetworkSettings::loop_period_us`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_us: Option<u32>,
    /// The control loop's tick \[us\] (default: the model step): what
    /// `replay` ticks at, and the firmware's loop.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loop_period_us: Option<u32>,
    /// Thermocouple noise standard deviation \[K\] (default 0.25).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_sigma_k: Option<f64>,
    /// Growth rate of each node's temperature variance \[K^2/s\] (the
    /// model's error in its heat balance; default 1e-4, see
    /// `NetworkSettings::node_noise_k2_per_s`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node_noise_k2_per_s: Option<f64>,
    /// Time between thermocouple samples the gain is solved for \[s\]
    /// (default 0.5).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_period_s: Option<f64>,
    /// Growth rate of each heat-input bias variance \[W^2/s\] (default
    /// 1e-3; 0 when the sensors cannot tell the currents' heat apart).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_noise_w2_per_s: Option<f64>,
    /// Correlation time of each heat-input bias \[s\] (default 0: a random
    /// walk; see `NetworkSettings::bias_tau_s`): the bias decays towards 0
    /// with it, its steady standard deviation `sqrt(bias_noise_w2_per_s *
    /// bias_tau_s / 2)` \[W\].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_tau_s: Option<f64>,
    /// Largest heat the thermocouples may explain away, as a share of each
    /// current's Joule power (default 0: a reading colder than the model
    /// never takes heat away; see `NetworkSettings::max_cooling_bias_fraction`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_cooling_bias_fraction: Option<f64>,
    /// How far a reading may move and still count as unchanged for the
    /// stuck test \[K\] (default 0: to the bit; see
    /// `SensorChecks::stuck_tolerance_k`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stuck_tolerance_k: Option<f64>,
    /// The model step in integer arithmetic, for a core without an FPU
    /// (default false: the `f32` step; see
    /// `NetworkSettings::integer_model_step`). `replay` runs the step the
    /// file asks for, so it stays the firmware to the bit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integer_model_step: Option<bool>,
    /// At most this many element evaluations of the time-to-limit
    /// predictor per protection stage (default 0: a whole horizon a stage;
    /// see `NetworkSettings::predictor_elements_per_stage`): a lower worst
    /// tick without an FPU, the same answers a little later.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predictor_elements_per_stage: Option<u16>,
    /// A correction in two ticks, for a core without an FPU (default
    /// false; see `NetworkSettings::correction_in_two_ticks`): the
    /// readings' fusion on their tick, the biases' floors on the next, the
    /// same estimate to the bit. Refused by a firmware built for a core
    /// with an FPU.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_in_two_ticks: Option<bool>,
    /// Model-uncertainty margin of the nodes no sensor measures, as a share
    /// of their rise above the ambient (dimensionless, `>= 0`; default
    /// 0.05, the Omnimagnet's): the share by which the truth of such a node
    /// may stand above its estimate. `calibrate --validate` measures it on
    /// a recording the fit did not see and writes it here.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unmeasured_margin: Option<f64>,
    /// The margin's fixed part on those nodes \[K\] (`>= 0`; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unmeasured_margin_offset_k: Option<f64>,
    /// The `[[source]]`s (by name) whose heat-input bias the observer
    /// estimates; the others', and every speed and `[[loss]]` source's,
    /// stay exactly 0 (`NetworkObserverBuilder::bias_sources`). Default:
    /// every source. For more sources than the sensors can tell apart:
    /// one sensor sees one heat.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_sources: Option<Vec<String>>,
    /// The biased sources (every source, or those `bias_sources` names)
    /// share one heat bias in proportion to their Joule power
    /// (`BiasMode::Shared`), also where the sensors could tell their biases
    /// apart (with `bias_tau_s`, decaying biases always can). Default
    /// false: each its own where the steady gain exists, else shared
    /// (`BiasMode::Auto`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shared_bias: Option<bool>,
    /// The `[[boundary]]` (by name) whose temperature the network sees may
    /// stand above its reading by an estimated offset, never below it
    /// (`NetworkSettings::boundary_offset`; one more filter state). Default:
    /// none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boundary_offset: Option<String>,
    /// The offset's steady standard deviation \[K\] (default 2).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boundary_offset_std_k: Option<f64>,
    /// The offset's correlation time \[s\] (default 7200).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boundary_offset_tau_s: Option<f64>,
}

/// What to generate.
#[derive(Debug, Clone)]
pub struct CodegenRequest {
    /// The model file.
    pub model: PathBuf,
    /// Sensor nodes by name; overrides `[observer] sensors` when not empty.
    pub sensors: Vec<String>,
    /// The `coil-thermal` library the generator compiles against (default:
    /// the one this tool was built from).
    pub library: Option<PathBuf>,
    /// The directory under which the generator crates and their cargo
    /// target directory go, in `<DIR>/coil-thermal-codegen` (default: see
    /// [`work_dir`]).
    pub target_dir: Option<PathBuf>,
}

fn rust_str(s: &str) -> String {
    format!("{s:?}")
}

fn list<T: std::fmt::Debug>(values: &[T]) -> String {
    let items: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
    format!("[{}]", items.join(", "))
}

/// The model, checked for the firmware observer, with everything the
/// generated module names.
struct Plan {
    model: Model,
    name: String,
    source: String,
    spec: ObserverSpec,
    sensor_nodes: Vec<usize>,
    /// What each sensor is (the library's kind: a temperature or a
    /// winding's resistance).
    sensor_kinds: Vec<coil_thermal::observer::network::SensorKind>,
    /// Per source: (node, `k R(0 degC)` \[ohm\], `k dR/dT` \[ohm/K\]).
    sources: Vec<(usize, f64, f64)>,
    /// What each source's current is made of.
    currents: Vec<CurrentOf>,
}

fn plan(req: &CodegenRequest) -> Result<Plan> {
    let file = ModelFile::load(&req.model)?;
    let model = Model::build(&file)?;
    let mut spec = file.observer.clone().unwrap_or_default();
    if !req.sensors.is_empty() {
        spec.sensors = req.sensors.iter().map(|s| s.as_str().into()).collect();
    }
    if spec.sensors.is_empty() {
        bail!(
            "{}: no sensor: name the node each thermocouple measures in `[observer] sensors = [\"node\"]` or with --sensor NODE (a firmware observer needs at least one)",
            req.model.display()
        );
    }
    if model.has_varying_conductances() {
        bail!(
            "{}: a conductance that depends on a signal (`[conductance.speed]`) changes the network with every row, and the firmware observer's tables are solved for one network; generate from a model without it",
            req.model.display()
        );
    }
    if model.network.boundaries() == 0 {
        bail!(
            "{}: the model has no [[boundary]] (the ambient)",
            req.model.display()
        );
    }
    if model.drives.is_empty() {
        bail!(
            "{}: the model has no [[source]] (no current)",
            req.model.display()
        );
    }
    let sensor_nodes = spec
        .sensors
        .iter()
        .map(|s| s.node_index(&model))
        .collect::<Result<Vec<_>>>()?;
    let sensor_kinds = spec
        .sensors
        .iter()
        .map(|s| s.library_kind(&model))
        .collect::<Result<Vec<_>>>()
        .with_context(|| req.model.display().to_string())?;
    if let Some(name) = &spec.boundary_offset {
        crate::firmware::boundary_index(&model, name)?;
    }
    check_f32_range(&model).with_context(|| req.model.display().to_string())?;
    let currents = currents_of(&model);
    let sources = model
        .firmware_network()
        .sources()
        .iter()
        .map(|s| {
            (
                s.node,
                s.resistance.r_at_0c_ohm,
                s.resistance.slope_ohm_per_k,
            )
        })
        .collect();
    let name = model.name.clone();
    let source = req.model.file_name().map_or_else(
        || req.model.display().to_string(),
        |f| f.to_string_lossy().into_owned(),
    );
    Ok(Plan {
        model,
        name,
        source,
        spec,
        sensor_nodes,
        sensor_kinds,
        sources,
        currents,
    })
}

impl Plan {
    /// Current `k`'s entry of `CURRENT_NAMES`: its node and what drives it.
    fn current_name(&self, k: usize, c: CurrentOf) -> String {
        let node = &self.model.nodes[self.sources[k].0];
        match c {
            CurrentOf::Input { input, speed } => format!(
                "{node}: {}{}",
                self.model.inputs[input].name,
                if speed.is_some() {
                    " x speed factor"
                } else {
                    ""
                }
            ),
            CurrentOf::SpeedLoss(_) => format!("{node}: speed loss"),
            CurrentOf::Loss { k, .. } => format!("{node}: loss {k}"),
        }
    }

    /// The boundary with an offset state (`[observer] boundary_offset`,
    /// checked by `plan`).
    fn offset_boundary(&self) -> Option<usize> {
        let name = self.spec.boundary_offset.as_ref()?;
        self.model.boundaries.iter().position(|b| &b.name == name)
    }

    /// The derating's and the margin's reference: the boundary named
    /// `ambient` (as `replay` has it), else the first.
    fn ambient_boundary(&self) -> usize {
        self.model
            .boundaries
            .iter()
            .position(|b| b.name == "ambient")
            .unwrap_or(0)
    }

    /// Some sensor is a winding's resistance (the module then has
    /// `SENSOR_KINDS`, and `observer()` assembles with them).
    fn has_resistance_sensor(&self) -> bool {
        self.sensor_kinds.iter().any(|k| k.resistance().is_some())
    }

    fn sizes(&self) -> (usize, usize, usize, usize) {
        let n = self.model.nodes.len();
        let b = self.model.network.boundaries();
        let m = self.sources.len();
        (n, b, m, self.sensor_nodes.len())
    }

    /// The module's head: sizes, names, types and `network()`.
    fn head(&self) -> String {
        let (n, b, m, p) = self.sizes();
        let net = &self.model.network;
        let mut o = String::new();
        let _ = writeln!(
            o,
            "//! The thermal observer of `{}`, generated by `coil-thermal codegen` from\n//! `{}`. Do not edit: change the model file and generate again.\n//!\n//! Everything the tick needs is solved on the host and held in [`PARTS`];\n//! the compiler assembles it into [`OBSERVER`] (flash), so the firmware\n//! holds no exponential, no Riccati solution and no assembly. The state\n//! starts from [`start_state`] (no history) or [`restore_state`] (a\n//! snapshot of [`save_snapshot`], [`SNAPSHOT_LEN`] bytes, kept in\n//! non-volatile storage through the power cycle).",
            self.name, self.source
        );
        if self.spec.integer_model_step == Some(true) {
            // Without the feature the static `OBSERVER` does not assemble.
            o.push_str("//!\n//! The model step runs in integer arithmetic (`[observer]\n//! integer_model_step`): build with coil-thermal's `integer-step` feature.\n");
        }
        o.push_str("//!\n//! | node | critical \\[degC\\] | thermocouple |\n//! |---|---|---|\n");
        for (i, name) in self.model.nodes.iter().enumerate() {
            let crit = self.model.critical_c[i].map_or("-".to_string(), |c| format!("{c}"));
            let sensors: Vec<String> = self
                .sensor_nodes
                .iter()
                .enumerate()
                .filter(|(_, s)| **s == i)
                .map(|(j, _)| j.to_string())
                .collect();
            let _ = writeln!(o, "//! | {name} | {crit} | {} |", sensors.join(", "));
        }
        o.push_str(
            "\n#![allow(dead_code, clippy::approx_constant, clippy::excessive_precision, clippy::unreadable_literal)]\n\n",
        );
        o.push_str("use coil_thermal::observer::network::{\n    NetworkInputs, NetworkObserver, NetworkObserverState, NetworkOutputs, NetworkParts,\n};\nuse coil_thermal::observer::snapshot::{self, RestorePolicy, SnapshotError};\nuse coil_thermal::protect::limiter::CoilLimit;\nuse coil_thermal::{BuildError, Network, Resistance};\n");
        if self.model.has_voltage_drives() {
            o.push_str("use coil_thermal::VoltageDrive;\n");
        }
        o.push('\n');
        let _ = writeln!(o, "/// State nodes.\npub const NODES: usize = {n};");
        let _ = writeln!(
            o,
            "/// Boundaries (given temperatures).\npub const BOUNDARIES: usize = {b};"
        );
        let _ = writeln!(o, "/// The boundary that is the ambient (the derating's and the margin's\n/// reference): the one named `ambient`, else the first.\npub const AMBIENT_BOUNDARY: usize = {};", self.ambient_boundary());
        let _ = writeln!(
            o,
            "/// Currents: one per Joule source.\npub const CURRENTS: usize = {m};"
        );
        if self.offset_boundary().is_some() {
            let _ = writeln!(o, "/// Filter states: the nodes, a heat-input bias per current, then the\n/// boundary offset.\npub const STATES: usize = NODES + CURRENTS + 1;");
        } else {
            let _ = writeln!(o, "/// Filter states: the nodes, then a heat-input bias per current.\npub const STATES: usize = NODES + CURRENTS;");
        }
        let _ = writeln!(o, "/// Thermocouples.\npub const SENSORS: usize = {p};");
        let inputs: Vec<&str> = self.model.inputs.iter().map(|i| i.name.as_str()).collect();
        let _ = writeln!(o, "/// Current inputs of the model file (sources may share one).\npub const INPUTS: usize = {};", inputs.len());
        let names = |v: &[&str]| {
            format!(
                "[{}]",
                v.iter().map(|s| rust_str(s)).collect::<Vec<_>>().join(", ")
            )
        };
        let nodes: Vec<&str> = self.model.nodes.iter().map(String::as_str).collect();
        let bounds: Vec<&str> = self
            .model
            .boundaries
            .iter()
            .map(|b| b.name.as_str())
            .collect();
        let labels: Vec<String> = self.spec.sensors.iter().map(|s| s.label()).collect();
        let sensors: Vec<&str> = labels.iter().map(String::as_str).collect();
        let _ = writeln!(
            o,
            "/// Node names, in state order.\npub const NODE_NAMES: [&str; NODES] = {};",
            names(&nodes)
        );
        let _ = writeln!(
            o,
            "/// Boundary names.\npub const BOUNDARY_NAMES: [&str; BOUNDARIES] = {};",
            names(&bounds)
        );
        let columns: Vec<&str> = self
            .model
            .inputs
            .iter()
            .map(|i| i.column.as_str())
            .collect();
        let _ = writeln!(
            o,
            "/// Input names.\npub const INPUT_NAMES: [&str; INPUTS] = {};\n/// Each input's trace column (or expression) in the model file.\npub const INPUT_COLUMNS: [&str; INPUTS] = {};",
            names(&inputs),
            names(&columns)
        );
        let _ = writeln!(o, "/// The node each thermocouple measures, by name.\npub const SENSOR_NAMES: [&str; SENSORS] = {};", names(&sensors));
        sensors::write(&mut o, &self.spec.sensors);
        sensors::write_kinds(&mut o, &labels, &self.sensor_kinds);
        let _ = writeln!(
            o,
            "/// Signals the model's speed and loss terms read (e.g. a speed in the\n/// unit of its reference).\npub const SIGNALS: usize = {};",
            self.model.signals.len()
        );
        let signals: Vec<&str> = self.model.signals.iter().map(String::as_str).collect();
        let _ = writeln!(
            o,
            "/// Signal names (trace columns or expressions).\npub const SIGNAL_NAMES: [&str; SIGNALS] = {};",
            names(&signals)
        );
        let current_names: Vec<String> = self
            .currents
            .iter()
            .enumerate()
            .map(|(k, c)| self.current_name(k, *c))
            .collect();
        let current_names: Vec<&str> = current_names.iter().map(String::as_str).collect();
        let _ = writeln!(
            o,
            "/// What each current of the observer is (a source and its input, or a\n/// loss carried as `sqrt(P)` through 1 ohm).\npub const CURRENT_NAMES: [&str; CURRENTS] = {};",
            names(&current_names)
        );
        o.push_str("\n/// The configuration.\npub type Observer = NetworkObserver<NODES, BOUNDARIES, CURRENTS, STATES, SENSORS>;\n/// The per-device state.\npub type State = NetworkObserverState<NODES, BOUNDARIES, CURRENTS, STATES, SENSORS>;\n/// One tick's inputs.\npub type Inputs = NetworkInputs<BOUNDARIES, CURRENTS, SENSORS>;\n/// One tick's outputs.\npub type Outputs = NetworkOutputs<NODES, CURRENTS, SENSORS>;\n\n");
        o.push_str(&source_currents_fn(&self.model, &self.currents));
        o.push_str(&input_limits_fn(self.model.inputs.len(), &self.currents));
        if self.model.has_voltage_drives() {
            o.push_str(&source_drives_fn(&self.model));
        }
        o.push_str("/// The network the tables were solved from (for host checks; the\n/// firmware needs only [`PARTS`]).\n///\n/// # Errors\n/// None for a generated file; the type is the builder's.\npub fn network() -> Result<Network<NODES, BOUNDARIES, CURRENTS>, BuildError> {\n");
        // A chain of builder calls, each but the last with `?`.
        let mut calls = vec![format!("Network::new({})", list(net.capacities_j_per_k()))];
        for pair in net.pairs() {
            calls.push(format!(
                ".connect({}, {}, {:?})",
                pair.a, pair.b, pair.g_w_per_k
            ));
        }
        for link in net.links() {
            calls.push(format!(
                ".connect_boundary({}, {}, {:?})",
                link.node, link.boundary, link.g_w_per_k
            ));
        }
        for (k, (node, r0, slope)) in self.sources.iter().enumerate() {
            calls.push(format!(
                ".joule_source({k}, {node}, Resistance::linear_fit({slope:?}, {r0:?}))"
            ));
        }
        for (node, p) in net.fixed_powers_w().iter().enumerate() {
            if *p != 0.0 {
                calls.push(format!(".fixed_power({node}, {p:?})"));
            }
        }
        let _ = writeln!(o, "    {}\n}}", calls.join("?\n        "));
        o
    }

    /// The generator program: the head, then a `main` that solves and
    /// prints the parts.
    fn generator_main(&self) -> String {
        let s = &self.spec;
        let mut settings = String::from("NetworkSettings::DEFAULT");
        let mut fields = Vec::new();
        if let Some(v) = s.step_us {
            fields.push(format!("step_us: {v}"));
        }
        if let Some(v) = s.loop_period_us {
            fields.push(format!("loop_period_us: {v}"));
        }
        if let Some(v) = s.sensor_sigma_k {
            fields.push(format!("sensor_sigma_k: {v:?}"));
        }
        if let Some(v) = s.node_noise_k2_per_s {
            fields.push(format!("node_noise_k2_per_s: {v:?}"));
        }
        if let Some(v) = s.correction_period_s {
            fields.push(format!("correction_period_s: {v:?}"));
        }
        if let Some(v) = s.max_current_a {
            fields.push(format!("max_current_a: {v:?}"));
        }
        if let Some(v) = s.bias_noise_w2_per_s {
            fields.push(format!("bias_noise_w2_per_s: {v:?}"));
        }
        if let Some(v) = s.bias_tau_s {
            fields.push(format!("bias_tau_s: {v:?}"));
        }
        if let Some(b) = self.offset_boundary() {
            fields.push(format!("boundary_offset: Some({b})"));
        }
        if let Some(v) = s.boundary_offset_std_k {
            fields.push(format!("boundary_offset_std_k: {v:?}"));
        }
        if let Some(v) = s.boundary_offset_tau_s {
            fields.push(format!("boundary_offset_tau_s: {v:?}"));
        }
        if let Some(v) = s.max_cooling_bias_fraction {
            fields.push(format!("max_cooling_bias_fraction: {v:?}"));
        }
        if let Some(v) = s.integer_model_step {
            fields.push(format!("integer_model_step: {v}"));
        }
        if let Some(v) = s.predictor_elements_per_stage {
            fields.push(format!("predictor_elements_per_stage: {v}"));
        }
        if let Some(v) = s.correction_in_two_ticks {
            fields.push(format!("correction_in_two_ticks: {v}"));
        }
        if let Some(v) = s.stuck_tolerance_k {
            fields.push(format!(
                "checks: coil_thermal::observer::SensorChecks {{ stuck_tolerance_k: {v:?}, ..coil_thermal::observer::SensorChecks::DEFAULT }}"
            ));
        }
        if s.unmeasured_margin.is_some() || s.unmeasured_margin_offset_k.is_some() {
            let default =
                coil_thermal::observer::network::NetworkSettings::DEFAULT.unmeasured_margin;
            fields.push(format!(
                "unmeasured_margin: coil_thermal::protect::margin::UncertaintyMargin::new({:?}, {:?})",
                s.unmeasured_margin.unwrap_or(default.rise_fraction),
                s.unmeasured_margin_offset_k.unwrap_or(default.offset_k)
            ));
        }
        let ambient = self.ambient_boundary();
        if ambient != 0 {
            fields.push(format!("ambient_boundary: {ambient}"));
        }
        if !fields.is_empty() {
            settings = format!(
                "NetworkSettings {{ {}, ..NetworkSettings::DEFAULT }}",
                fields.join(", ")
            );
        }
        let derating = match s.derating {
            Some(d) => format!("DeratingRule::new(&[DeratingFactor::new(\"derating\", {d:?})])?"),
            None => "DeratingRule::omnimagnet()".to_string(),
        };
        let hardware = s.hardware_limit_a.unwrap_or(8.0);
        // Only the solved tables carry it (a left-out bias has a zero
        // prior), so `from_parts` needs nothing more.
        let mut bias_sources = self.model.bias_sources.as_ref().map_or(String::new(), |b| {
            format!("\n        .bias_sources({})", list(b))
        });
        if self.has_resistance_sensor() {
            // The gain is solved with each sensor's own noise.
            bias_sources.push_str("\n        .sensor_kinds(head::SENSOR_KINDS)");
        }
        if s.shared_bias == Some(true) {
            // The tables say which biases share (a tied prior block), so
            // `from_parts` needs nothing more here either.
            bias_sources.push_str("\n        .shared_bias([true; head::CURRENTS])");
        }
        format!(
            "#[allow(dead_code, unused_imports)]\n#[path = \"head.rs\"]\nmod head;\n#[allow(dead_code)]\n#[path = \"build_hint.rs\"]\nmod build_hint;\n\nuse coil_thermal::observer::network::{{NetworkObserverBuilder, NetworkSettings}};\n#[allow(unused_imports)]\nuse coil_thermal::protect::derating::{{DeratingFactor, DeratingRule}};\n\nfn parts(settings: NetworkSettings) -> Result<String, coil_thermal::BuildError> {{\n    let network = head::network()?;\n    let parts = NetworkObserverBuilder::new(&network, {sensors})\n        .critical_c({critical})\n        .hardware_limit_a([{hardware:?}; head::CURRENTS])\n        .derating({derating})\n        .settings(settings){bias_sources}\n        .parts::<{{ head::STATES }}>()?;\n    let mut text = String::new();\n    parts.write_rust(&mut text).expect(\"a String grows\");\n    Ok(text)\n}}\n\nfn main() {{\n    let settings = {settings};\n    match parts(settings) {{\n        Ok(text) => print!(\"{{text}}\"),\n        Err(e) => {{\n            eprintln!(\"{error_marker}{{e}}\");\n            if let Some(hint) = build_hint::observer_build_hint(&e, settings.bias_noise_w2_per_s) {{\n                eprintln!(\"{hint_marker}{{hint}}\");\n            }}\n            std::process::exit({exit});\n        }}\n    }}\n}}\n",
            sensors = list(&self.sensor_nodes),
            critical = list(&self.model.critical_c),
            error_marker = REFUSED_MARKER,
            hint_marker = HINT_MARKER,
            exit = REFUSED_EXIT,
        )
    }
}

/// The generator's exit code when the library's builder refuses the model
/// (a compile failure is cargo's, a crash the runtime's).
const REFUSED_EXIT: i32 = 3;
/// The generator's stderr line with the builder's error.
const REFUSED_MARKER: &str = "coil-thermal-codegen refused: ";
/// The generator's stderr line with what to change.
const HINT_MARKER: &str = "coil-thermal-codegen hint: ";

/// The library this tool was built from.
fn default_library() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Where `codegen` keeps its generator crates and their cargo target
/// directory (the library and its dependencies, built once and reused):
/// `<DIR>/coil-thermal-codegen` with `--target-dir DIR`; else
/// `$CARGO_TARGET_DIR/coil-thermal-codegen`; else a per-user cache,
/// `$XDG_CACHE_HOME/coil-thermal/codegen` (an absolute path), else
/// `$HOME/.cache/coil-thermal/codegen`; else
/// `<system temp dir>/coil-thermal-codegen`. Never the library's own
/// `target/`, which may be read-only or another build's. `env` looks up an
/// environment variable (`std::env::var_os` in the tool).
pub fn work_dir(target_dir: Option<&Path>, env: impl Fn(&str) -> Option<OsString>) -> PathBuf {
    let set = |name: &str| env(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    if let Some(dir) = target_dir {
        return dir.join("coil-thermal-codegen");
    }
    if let Some(dir) = set("CARGO_TARGET_DIR") {
        return dir.join("coil-thermal-codegen");
    }
    if let Some(dir) = set("XDG_CACHE_HOME").filter(|d| d.is_absolute()) {
        return dir.join("coil-thermal").join("codegen");
    }
    if let Some(home) = set("HOME") {
        return home.join(".cache").join("coil-thermal").join("codegen");
    }
    std::env::temp_dir().join("coil-thermal-codegen")
}

/// The library's source directory, checked: a directory holding
/// coil-thermal's `Cargo.toml`.
fn library_source(library: &Path, given: bool) -> Result<PathBuf> {
    let whose = if given {
        format!("--library {}", library.display())
    } else {
        format!(
            "{} (the coil-thermal source this tool was built from; pass --library DIR for another)",
            library.display()
        )
    };
    let expected = "codegen compiles its generator against the coil-thermal library's source: \
                    expected a directory holding coil-thermal's Cargo.toml ([package] name = \
                    \"coil-thermal\"), such as a checkout of its repository";
    let Ok(dir) = library.canonicalize() else {
        bail!("{whose}: no such directory; {expected}");
    };
    let manifest = dir.join("Cargo.toml");
    let Ok(text) = std::fs::read_to_string(&manifest) else {
        bail!("{whose}: no Cargo.toml there; {expected}");
    };
    let name = text
        .parse::<toml::Table>()
        .ok()
        .and_then(|t| t.get("package")?.get("name")?.as_str().map(String::from));
    match name.as_deref() {
        Some("coil-thermal") => Ok(dir),
        Some(other) => bail!("{whose}: its Cargo.toml is package `{other}`; {expected}"),
        None => bail!("{whose}: its Cargo.toml names no package; {expected}"),
    }
}

/// The cargo to build the generator with: `$CARGO`, else `cargo` on the
/// `PATH`, checked to run.
fn cargo_program() -> Result<OsString> {
    let (cargo, from_env) = match std::env::var_os("CARGO").filter(|c| !c.is_empty()) {
        Some(c) => (c, true),
        None => ("cargo".into(), false),
    };
    match Command::new(&cargo).arg("--version").output() {
        Ok(out) if out.status.success() => Ok(cargo),
        Ok(out) => bail!(
            "`{} --version` failed: {}",
            cargo.to_string_lossy(),
            String::from_utf8_lossy(&out.stderr).trim()
        ),
        Err(e) if from_env => bail!(
            "CARGO={}: cannot run it ({e}); codegen builds its generator with cargo: set CARGO \
             to cargo's path, or unset it to use the cargo on PATH",
            cargo.to_string_lossy()
        ),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => bail!(
            "cargo not found on PATH (and CARGO is not set): codegen compiles a small generator \
             program against the coil-thermal library with cargo; install Rust with cargo \
             (https://rustup.rs) or put cargo on PATH, or set CARGO=/path/to/cargo"
        ),
        Err(e) => bail!("cannot run cargo ({e}); codegen builds its generator with cargo"),
    }
}

/// Writes the generator crate, builds it and runs it; returns the parts'
/// Rust text.
fn solve(plan: &Plan, library: &Path, root: &Path, model: &Path) -> Result<String> {
    let cargo = cargo_program()?;
    // One crate per model and library (several may be generated at once,
    // e.g. by parallel tests, or from several checkouts into one cache),
    // all sharing one target directory for the library and its
    // dependencies.
    let head = plan.head();
    let main = plan.generator_main();
    let name = {
        use std::hash::{Hash, Hasher};
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        (&head, &main, library).hash(&mut hasher);
        format!("coil-thermal-codegen-{:016x}", hasher.finish())
    };
    let dir = root.join(&name);
    std::fs::create_dir_all(dir.join("src"))
        .with_context(|| format!("{}: cannot create the generator crate", dir.display()))?;
    // The integer model step's feature only where the file asks for it
    // (the library refuses its settings without it).
    let features = if plan.spec.integer_model_step == Some(true) {
        ", features = [\"integer-step\"]"
    } else {
        ""
    };
    let manifest = format!(
        "[package]\nname = \"{name}\"\nversion = \"0.0.0\"\nedition = \"2021\"\npublish = false\n\n[dependencies]\ncoil-thermal = {{ path = {:?}{features} }}\n\n[workspace]\n",
        library.display().to_string()
    );
    let write = |file: &str, text: &str| {
        std::fs::write(dir.join(file), text)
            .with_context(|| format!("{}: cannot write", dir.join(file).display()))
    };
    write("Cargo.toml", &manifest)?;
    // The library's lock pins the generator's dependencies to the versions
    // the library is tested with (and needs no registry when they are cached).
    let lock = library.join("Cargo.lock");
    if lock.exists() && !dir.join("Cargo.lock").exists() {
        std::fs::copy(&lock, dir.join("Cargo.lock"))?;
    }
    write("src/head.rs", &head)?;
    write("src/build_hint.rs", include_str!("build_hint.rs"))?;
    write("src/main.rs", &main)?;
    let target = root.join("target");
    let built = Command::new(&cargo)
        .args(["build", "--release", "--quiet", "--manifest-path"])
        .arg(dir.join("Cargo.toml"))
        .env("CARGO_TARGET_DIR", &target)
        .env_remove("RUSTFLAGS")
        .output()
        .context("cannot run cargo for the generator")?;
    if !built.status.success() {
        bail!(
            "compiling the generator (in {}) against the coil-thermal library at {} failed; is \
             that library the version this tool was built from (or pass --library DIR)? \
             cargo said:\n{}",
            dir.display(),
            library.display(),
            String::from_utf8_lossy(&built.stderr).trim_end()
        );
    }
    let program = target
        .join("release")
        .join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    let output = Command::new(&program)
        .output()
        .with_context(|| format!("{}: cannot run the generator", program.display()))?;
    if output.status.code() == Some(REFUSED_EXIT) {
        let stderr = String::from_utf8_lossy(&output.stderr);
        let line = |marker: &str| {
            stderr
                .lines()
                .find_map(|l| l.strip_prefix(marker))
                .map(str::to_string)
        };
        let error = line(REFUSED_MARKER).unwrap_or_else(|| stderr.trim().to_string());
        match line(HINT_MARKER) {
            Some(hint) => bail!(
                "{}: the coil-thermal library's observer builder refuses the model: {error}; {hint}",
                model.display()
            ),
            None => bail!(
                "{}: the coil-thermal library's observer builder refuses the model: {error}",
                model.display()
            ),
        }
    }
    if !output.status.success() {
        bail!(
            "the generator {} failed ({}):\n{}",
            program.display(),
            output.status,
            String::from_utf8_lossy(&output.stderr).trim_end()
        );
    }
    String::from_utf8(output.stdout).context("the generator printed non-UTF-8")
}

/// Generates the module for `req`; returns its text.
///
/// # Errors
/// A model the firmware observer cannot take (no sensor, speed terms, a
/// refusal of the library's builder, named with what to change); no cargo;
/// no coil-thermal source at the library path; or a failed generator build.
pub fn generate(req: &CodegenRequest) -> Result<String> {
    let plan = plan(req)?;
    let library = match &req.library {
        Some(dir) => library_source(dir, true)?,
        None => library_source(&default_library(), false)?,
    };
    let root = work_dir(req.target_dir.as_deref(), |name| std::env::var_os(name));
    let parts = solve(&plan, &library, &root, &req.model)?;
    let mut o = plan.head();
    o.push_str("\n/// Every table of the observer, solved on the host in `f64` and rounded\n/// once to `f32`.\npub const PARTS: NetworkParts<NODES, BOUNDARIES, CURRENTS, STATES, SENSORS> = ");
    o.push_str(parts.trim_end());
    o.push_str(";\n");
    if plan.has_resistance_sensor() {
        // The compiler's assembly copies the resistance conversions from
        // the assembled tables; the run-time assembly it names as its
        // equal needs the sensor kinds (from_parts refuses these tables).
        o.push_str(&STATES_AND_SNAPSHOTS.replace(
            "`Observer::from_parts(&PARTS)` is the same observer to the\n/// bit",
            "`Observer::from_parts_with_sensors(&PARTS, &SENSOR_KINDS)` is\n/// the same observer to the bit",
        ));
    } else {
        o.push_str(STATES_AND_SNAPSHOTS);
    }
    Ok(rustfmt(&o).unwrap_or(o))
}

/// The generated module's end: `observer()`, the states it starts from
/// and the snapshots that carry a state through a power cycle.
const STATES_AND_SNAPSHOTS: &str = r#"
/// The observer, assembled by the compiler from [`PARTS`] (copies only;
/// tables that do not assemble fail the build), in flash: tick it through
/// `&OBSERVER`. `Observer::from_parts(&PARTS)` is the same observer to the
/// bit, validated and derived again at run time.
pub static OBSERVER: Observer = match Observer::from_assembled_parts(&PARTS) {
    Ok(observer) => observer,
    Err(_) => panic!("PARTS do not assemble: generate this module again"),
};

/// A copy of [`OBSERVER`].
///
/// # Errors
/// None: the compiler assembled it; the type is the library's.
pub fn observer() -> Result<Observer, BuildError> {
    Ok(OBSERVER.clone())
}

/// A state with every node and boundary at `ambient_c` \[degC\]: for
/// every node *known* to be at the ambient (e.g. a test). A product starts
/// with [`start_state`] or [`restore_state`]: on a warm device this one
/// reads cold.
pub fn initial_state(observer: &Observer, ambient_c: f32) -> State {
    observer.with_warm_up(observer.state(&[ambient_c; NODES], &[ambient_c; BOUNDARIES]))
}

/// The safe start without a history (the first boot, a refused snapshot,
/// a product that keeps none), from what the thermocouples read now,
/// `readings_c` \[degC\] (`None`: no reading): every node a sensor reads
/// at its reading, every other node no cooler than the hottest reading or
/// `ambient_c`, with a variance that puts each limited element's upper
/// bound 1 K below its alarm limit. No shutdown is latched: the limiter
/// starts in its taper band and opens as the sensors teach the filter
/// (`NetworkObserver::start`). The boundaries at `ambient_c` \[degC\].
pub fn start_state(
    observer: &Observer,
    readings_c: &[Option<f32>; SENSORS],
    ambient_c: f32,
) -> State {
    observer.start(readings_c, &[ambient_c; BOUNDARIES])
}

/// Bytes of a snapshot ([`save_snapshot`], [`restore_state`]): the node
/// estimates, the latched shutdown, the time stamp, the configuration's
/// fingerprint and a CRC (`coil_thermal::observer::snapshot`).
pub const SNAPSHOT_LEN: usize = snapshot::snapshot_len(NODES);

/// Writes a snapshot of `state` into `buf`, stamped `now_s` \[s\] (the
/// clock [`OffTime::SinceSave`] reads, when there is one), for
/// non-volatile storage: every few seconds and at the brown-out warning.
/// `O(NODES)` work and a CRC; the heat biases are not saved (a restored
/// state starts them at zero).
pub fn save_snapshot(observer: &Observer, state: &State, now_s: u32, buf: &mut [u8; SNAPSHOT_LEN]) {
    // Never refused: the buffer is the snapshot's length.
    let _ = observer.save(state, now_s, buf);
}

/// How long the device was off, as the firmware knows it at the boot
/// ([`restore_state`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OffTime {
    /// Off from the snapshot's save until now, `now_s` \[s\] on a clock
    /// that ran through the power-off (a real-time clock) and stamped the
    /// snapshot: a save at the power-off (the brown-out warning's). The
    /// saved estimates cool exactly over the snapshot's age
    /// (`NetworkObserver::restore_after`); older than `max_age_s`,
    /// refused.
    SinceSave {
        /// Now \[s\], on the clock of [`save_snapshot`]'s `now_s`.
        now_s: u32,
    },
    /// Unknown: no clock ran through the power-off, or the snapshot is
    /// not the power-off's (a periodic save: the device may have run for
    /// up to a save period after it, which no restore sees). The device
    /// may have been off for anything up to `max_age_s`; the saved
    /// estimates cool by the shortest of those off times that the boot
    /// readings allow, the least cooling, so the nodes no sensor reads
    /// err hot (`NetworkObserver::restore_with_readings`).
    Unknown,
}

/// The state at the boot from a snapshot `bytes` of [`save_snapshot`],
/// cooled over the off time `off`, the boundaries at `ambient_c`
/// \[degC\]; `readings_c` \[degC\] is what the thermocouples read now.
/// A latched shutdown stays latched. A snapshot the observer refuses
/// (none, corrupted, another model or protection, older than `max_age_s`
/// \[s\], ...) gives [`start_state`] and why it was refused.
pub fn restore_state(
    observer: &Observer,
    bytes: &[u8],
    off: OffTime,
    max_age_s: u32,
    readings_c: &[Option<f32>; SENSORS],
    ambient_c: f32,
) -> (State, Option<SnapshotError>) {
    let boundary_c = [ambient_c; BOUNDARIES];
    let restored = match off {
        // Capped at the snapshot's age: off since the save.
        OffTime::SinceSave { now_s } => {
            observer.restore_after(bytes, now_s, max_age_s, &boundary_c, Some(f32::INFINITY))
        }
        // No clock: the snapshot's own stamp plus the longest off time
        // stands for now, so the readings choose among every off time.
        OffTime::Unknown => {
            let any_age = RestorePolicy {
                fingerprint: observer.fingerprint(),
                now_s: u32::MAX,
                max_age_s: u32::MAX,
            };
            snapshot::restore::<NODES>(bytes, &any_age).and_then(|(_, saved)| {
                let now_s = saved.saved_at_s.saturating_add(max_age_s);
                observer.restore_with_readings(bytes, now_s, max_age_s, &boundary_c, readings_c)
            })
        }
    };
    match restored {
        Ok(state) => (observer.with_warm_up(state), None),
        Err(refused) => (start_state(observer, readings_c, ambient_c), Some(refused)),
    }
}
"#;

/// The text through `rustfmt` (edition 2021), when one is installed: the
/// module then passes `cargo fmt --check` wherever it is committed.
fn rustfmt(text: &str) -> Option<String> {
    use std::io::Write as _;
    let mut child = Command::new("rustfmt")
        .args(["--edition", "2021", "--emit", "stdout", "--quiet"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .ok()?;
    child.stdin.take()?.write_all(text.as_bytes()).ok()?;
    let output = child.wait_with_output().ok()?;
    output
        .status
        .success()
        .then(|| String::from_utf8(output.stdout).ok())
        .flatten()
}
