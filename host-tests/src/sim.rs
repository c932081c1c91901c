//! Plants (thermal models the tool can run) and their input series.
//!
//! A [`Plant`] is anything with named nodes that advances over an interval
//! with currents, boundary temperatures and extra signals held (zero-order
//! hold: row `k`'s inputs act over `[t_k, t_k+1)`). [`FilePlant`] runs a
//! model file on the library's explicit step at the network's own size
//! ([`RunTimeStepper`], the `alloc` twin of `ExplicitStepper`); the
//! Omnimagnet's nonlinear model is another `Plant` on the library's RK4.

use anyhow::{anyhow, bail, Context, Result};
use coil_thermal::network::{RunTimeState, RunTimeStepper};
use coil_thermal::InputLimits;

use crate::dynamic_network::DynNetwork;
use crate::model_file::{InitialPolicy, InitialSpec, InputHold, Model};
use crate::trace::{num, ColumnExpr, Trace};

mod stream;
pub use stream::{DriveRows, InputRow, RowSource, TraceDrive, TraceRows};

/// One named input channel of a plant.
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// Name (input, boundary).
    pub name: String,
    /// Default trace column or expression.
    pub column: String,
    /// Value used when the trace lacks the column (boundaries only).
    pub default_value: Option<f64>,
}

/// What a plant exposes: names and units are fixed (nodes in degC, inputs in
/// A, boundaries in degC, signals in their own unit).
#[derive(Debug, Clone, PartialEq)]
pub struct PlantInfo {
    /// Model name.
    pub name: String,
    /// Node names in state order (also the CSV column names).
    pub nodes: Vec<String>,
    /// Critical temperature of each node \[degC\].
    pub critical_c: Vec<Option<f64>>,
    /// Current inputs \[A\].
    pub inputs: Vec<Channel>,
    /// Boundaries \[degC\].
    pub boundaries: Vec<Channel>,
    /// Extra signal columns (speed, ...).
    pub signals: Vec<String>,
    /// Initial temperature policy.
    pub initial: InitialSpec,
}

/// A thermal model stepped over a trace.
pub trait Plant {
    /// Names and bindings.
    fn info(&self) -> &PlantInfo;
    /// Sets every node temperature \[degC\].
    fn reset(&mut self, temps_c: &[f64]);
    /// Advances by `dt_s` \[s\] with inputs held: `currents_a` per input,
    /// `boundary_c` per boundary, `signals` per signal.
    fn step(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]);
    /// Node temperatures \[degC\].
    fn temps_c(&self) -> &[f64];
    /// How many internal steps [`Self::step`] takes for an interval `dt_s`
    /// \[s\] (as `f64`: an absurd interval gives an absurd count, not an
    /// overflow); 1 for a plant that steps once.
    fn steps_for(&self, _dt_s: f64) -> f64 {
        1.0
    }
}

impl<P: Plant + ?Sized> Plant for Box<P> {
    fn info(&self) -> &PlantInfo {
        (**self).info()
    }
    fn reset(&mut self, temps_c: &[f64]) {
        (**self).reset(temps_c);
    }
    fn step(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        (**self).step(dt_s, currents_a, boundary_c, signals);
    }
    fn temps_c(&self) -> &[f64] {
        (**self).temps_c()
    }
    fn steps_for(&self, dt_s: f64) -> f64 {
        (**self).steps_for(dt_s)
    }
}

/// Input limits of the host's steppers: wide enough never to clamp a
/// recorded input (the library's defaults, 100 A and -60 .. 400 degC, are
/// the firmware's plausibility limits); non-finite inputs are still held.
pub const HOST_INPUT_LIMITS: InputLimits = InputLimits {
    max_current_a: 1e9,
    min_temp_c: -273.15,
    max_temp_c: 1e6,
};

/// The library's [`RunTimeStepper`] of a model file's network at its own
/// size, with its state (see [`FilePlant`]).
struct Stepper {
    /// The network stepped now (the model's, or with its speed-dependent
    /// conductances at the last row's signals).
    network: DynNetwork,
    /// The network changed since the stepper was built.
    rebuild: bool,
    /// Built for the network in force and the last step length.
    stepper: Option<RunTimeStepper<f64>>,
    state: Option<RunTimeState<f64>>,
}

impl Stepper {
    /// Sets the node temperatures, clears the carry (the inputs held stay).
    fn reset(&mut self, temps_c: &[f64]) {
        if let Some(state) = &mut self.state {
            state.temps_c.copy_from_slice(temps_c);
            state.residual_c.fill(0.0);
        }
    }

    /// Steps `network` from now on (rebuilt at the next step).
    fn set_network(&mut self, network: DynNetwork) {
        self.network = network;
        self.rebuild = true;
    }

    /// `substeps` library steps of `h_s` with these inputs held; the
    /// temperatures into `temps_c`. The stepper is rebuilt when the step
    /// length or the network changed.
    fn step(
        &mut self,
        h_s: f64,
        substeps: usize,
        currents_a: &[f64],
        boundary_c: &[f64],
        temps_c: &mut [f64],
    ) -> Result<()> {
        if self.rebuild || self.stepper.as_ref().is_none_or(|s| s.dt_s() != h_s) {
            self.stepper = Some(
                RunTimeStepper::new(&self.network, h_s, HOST_INPUT_LIMITS)
                    .map_err(|e| anyhow!("explicit step of {h_s} s: {e}"))?,
            );
            self.rebuild = false;
        }
        let Some(stepper) = &self.stepper else {
            unreachable!("built above")
        };
        let state = self.state.get_or_insert_with(|| {
            let mut s = stepper.state(0.0);
            s.temps_c.copy_from_slice(temps_c);
            s
        });
        for _ in 0..substeps {
            stepper
                .step(state, currents_a, boundary_c)
                .map_err(|e| anyhow!("explicit step: {e}"))?;
        }
        temps_c.copy_from_slice(&state.temps_c);
        Ok(())
    }
}

/// The names and bindings of a model file.
pub fn plant_info(model: &Model) -> PlantInfo {
    PlantInfo {
        name: model.name.clone(),
        nodes: model.nodes.clone(),
        critical_c: model.critical_c.clone(),
        inputs: model
            .inputs
            .iter()
            .map(|i| Channel {
                name: i.name.clone(),
                column: i.column.clone(),
                default_value: None,
            })
            .collect(),
        boundaries: model
            .boundaries
            .iter()
            .map(|b| Channel {
                name: b.name.clone(),
                column: b.column.clone().unwrap_or_else(|| b.name.clone()),
                default_value: b.value_c,
            })
            .collect(),
        signals: model.signals.clone(),
        initial: model.initial.clone(),
    }
}

/// A model file run on the library's explicit stepper.
///
/// The network is stepped at its own size by the library's
/// [`RunTimeStepper`] (`f64`; the same checks, packing and kernel as the
/// MCU's `ExplicitStepper`, so the same temperatures to the bit as a
/// const-generic stepper of the network): no size class, no cap. An
/// interval is split into equal steps so that `h sum(G_i) / C_i` stays at or
/// below the model's `max_step_ratio` at every node (the library refuses a
/// ratio of 1 or more); the stepper is rebuilt when the step length
/// changes.
pub struct FilePlant {
    model: Model,
    info: PlantInfo,
    temps: Vec<f64>,
    effective: Vec<f64>,
    stepper: Stepper,
}

impl std::fmt::Debug for FilePlant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FilePlant")
            .field("model", &self.model.name)
            .field("temps", &self.temps)
            .finish_non_exhaustive()
    }
}

impl Clone for FilePlant {
    fn clone(&self) -> Self {
        let mut plant = Self::new(self.model.clone()).expect("the model was built before");
        plant.reset(&self.temps);
        plant
    }
}

impl FilePlant {
    /// Wraps a validated model.
    ///
    /// # Errors
    /// A network the library's stepper refuses (a voltage-driven source is
    /// driven by the current it draws, so none is).
    pub fn new(model: Model) -> Result<Self> {
        let info = plant_info(&model);
        // The library's checks now, not at the first row: a step of the
        // fastest node's own time constant's ratio.
        let h_s = model.max_step_ratio / model.network.max_rate_per_s().max(f64::MIN_POSITIVE);
        RunTimeStepper::<f64>::new(&model.network, h_s.min(1.0), HOST_INPUT_LIMITS)
            .map_err(|e| anyhow!("model `{}`: {e}", model.name))?;
        let n = model.nodes.len();
        Ok(Self {
            stepper: Stepper {
                network: model.network.clone(),
                rebuild: true,
                stepper: None,
                state: None,
            },
            model,
            info,
            temps: vec![0.0; n],
            effective: Vec::new(),
        })
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// Number of equal explicit steps for an interval `dt_s` \[s\] (see the
    /// type's docs).
    pub fn substeps(&self, dt_s: f64) -> usize {
        let n = self.steps_for(dt_s);
        if n.is_finite() {
            n as usize
        } else {
            1
        }
    }
}

impl Plant for FilePlant {
    fn info(&self) -> &PlantInfo {
        &self.info
    }

    fn reset(&mut self, temps_c: &[f64]) {
        self.temps.copy_from_slice(temps_c);
        self.stepper.reset(temps_c);
    }

    fn step(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], signals: &[f64]) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        self.model
            .effective_currents(currents_a, signals, &mut self.effective);
        // The conductances of this row, held over the interval like every
        // other input; the stepper is rebuilt only on a change.
        if let Some(net) = self.model.changed_network(signals, &self.stepper.network) {
            self.stepper.set_network(net);
        }
        let n = self.substeps(dt_s);
        if self.model.has_voltage_drives() {
            // A voltage-driven winding draws `V_eff / R(T)`: its current is
            // taken at the temperature each sub-step starts from, as the
            // explicit step takes `R(T)` for a current.
            let mut currents = self.effective.clone();
            for _ in 0..n {
                currents.copy_from_slice(&self.effective);
                self.model.currents_at(&mut currents, &self.temps);
                let _ =
                    self.stepper
                        .step(dt_s / n as f64, 1, &currents, boundary_c, &mut self.temps);
            }
            return;
        }
        // A step the library refuses (only an overflowing rate can make
        // one) leaves the state where it is, as the library's own input
        // rules do.
        let _ = self.stepper.step(
            dt_s / n as f64,
            n,
            &self.effective,
            boundary_c,
            &mut self.temps,
        );
    }

    fn temps_c(&self) -> &[f64] {
        &self.temps
    }

    fn steps_for(&self, dt_s: f64) -> f64 {
        // The network in force: speed-dependent conductances swap it per row.
        (dt_s * self.stepper.network.max_rate_per_s() / self.model.max_step_ratio)
            .ceil()
            .max(1.0)
    }
}

/// Refuses a run that would take more than [`MAX_MODEL_STEPS`] internal
/// model steps over `time_s` \[s\] (a stiff model, a huge row gap or a
/// very long span), before it starts, naming what to change.
pub fn check_work(plant: &dyn Plant, time_s: &[f64], what: &str) -> Result<()> {
    let mut work = Work::default();
    for t in time_s {
        work.push(plant, *t);
    }
    work.check(plant, what)
}

/// The internal model steps of a run, counted row by row (for
/// [`check_work`] over rows that are not held).
#[derive(Debug, Clone, Default)]
pub struct Work {
    total: f64,
    /// The widest gap \[s\] and the time it starts at \[s\].
    widest: (f64, f64),
    first_s: Option<f64>,
    last_s: Option<f64>,
}

impl Work {
    /// Counts the interval up to the row at `time_s` \[s\].
    pub fn push(&mut self, plant: &dyn Plant, time_s: f64) {
        if let Some(prev) = self.last_s {
            let dt = time_s - prev;
            self.total += plant.steps_for(dt);
            if dt > self.widest.0 {
                self.widest = (dt, prev);
            }
        }
        self.first_s.get_or_insert(time_s);
        self.last_s = Some(time_s);
    }

    /// Refuses more than [`MAX_MODEL_STEPS`] (see [`check_work`]).
    pub fn check(&self, plant: &dyn Plant, what: &str) -> Result<()> {
        let total = self.total;
        if total > MAX_MODEL_STEPS || !total.is_finite() {
            let per_s = plant.steps_for(1e6) / 1e6;
            bail!(
                "{what}: the run needs {total:.3e} internal steps of model `{}`, at most {MAX_MODEL_STEPS:.0e}: \
                 its stable step is {:.3e} s (a tiny capacity_j_per_k or a huge g_w_per_k makes it stiff: check the model for a typo) \
                 and the rows span {:.3e} s (widest gap {:.3e} s after t = {} s)",
                plant.info().name,
                1.0 / per_s,
                self.last_s.unwrap_or(0.0) - self.first_s.unwrap_or(0.0),
                self.widest.0,
                num(self.widest.1)
            );
        }
        Ok(())
    }
}

/// Temperatures beyond this are a runaway, not a result \[degC\] (copper
/// melts at 1085 degC; every insulation class is far below).
pub const RUNAWAY_C: f64 = 5000.0;

/// Refuses a non-finite or absurd temperature in `states` `[node][row]`
/// \[degC\] at `time_s` \[s\]: the first such value, with its node, time and
/// the likely cause.
pub fn check_temperatures(
    info: &PlantInfo,
    time_s: &[f64],
    states: &[Vec<f64>],
    what: &str,
) -> Result<()> {
    let mut first: Option<(usize, usize, f64)> = None;
    for (node, series) in states.iter().enumerate() {
        if let Some(k) = series
            .iter()
            .position(|v| !(v.is_finite() && *v > -273.15 && *v < RUNAWAY_C))
        {
            if first.is_none_or(|(_, f, _)| k < f) {
                first = Some((node, k, series[k]));
            }
        }
    }
    let Some((node, k, v)) = first else {
        return Ok(());
    };
    Err(runaway(
        info,
        node,
        v,
        time_s.get(k).copied().unwrap_or(f64::NAN),
        what,
    ))
}

/// Refuses one row's temperatures `temps_c` \[degC\] at `time_s` \[s\]
/// as [`check_temperatures`] does (its first bad node), for a run checked
/// row by row.
pub fn check_row_temperatures(
    info: &PlantInfo,
    time_s: f64,
    temps_c: &[f64],
    what: &str,
) -> Result<()> {
    match temps_c
        .iter()
        .position(|v| !(v.is_finite() && *v > -273.15 && *v < RUNAWAY_C))
    {
        Some(node) => Err(runaway(info, node, temps_c[node], time_s, what)),
        None => Ok(()),
    }
}

fn runaway(info: &PlantInfo, node: usize, v: f64, time_s: f64, what: &str) -> anyhow::Error {
    anyhow!(
        "{what}: model `{}` ran away: node `{}` is {} degC at t = {} s (outside -273.15 .. {RUNAWAY_C} degC). \
         The heating outgrows the cooling: a current beyond the model's range, or a resistance temperature \
         coefficient (alpha_per_k, slope_ohm_per_k) that makes the power grow faster than the losses \
         (thermal runaway; `coil-thermal limits` gives each input's runaway current); no result is written",
        info.name,
        info.nodes[node],
        num(v),
        num(time_s)
    )
}

/// The most output rows a run writes (constant currents, resampling).
pub const MAX_ROWS: usize = 20_000_000;

/// The most values (rows x (nodes + inputs + boundaries)) a run holds
/// (about 1.6 GB as `f64`, before the copies of the output).
pub const MAX_CELLS: usize = 200_000_000;

/// The most explicit model steps one run may take (sub-steps summed over
/// every row): about a minute of host time for a small model.
pub const MAX_MODEL_STEPS: f64 = 2e8;

/// How trace columns map onto a plant (from the command line).
#[derive(Debug, Clone, Default)]
pub struct Bindings {
    /// `--current EXPR=INPUT`.
    pub currents: Vec<(ColumnExpr, String)>,
    /// `--boundary EXPR=NAME`.
    pub boundaries: Vec<(ColumnExpr, String)>,
    /// `--const COL=VALUE`: a constant ([`ColumnExpr::Constant`]) or a step
    /// profile ([`ColumnExpr::Steps`]) for a column the trace lacks.
    pub constants: Vec<(String, ColumnExpr)>,
    /// `--current-scale K`: every current input multiplied by `K` (a
    /// harder or lighter duty on the same trajectory); `None`: 1.
    pub current_scale: Option<f64>,
}

impl Bindings {
    /// The column expression current input `input` reads: its last
    /// `--current` binding, else the input's own column.
    pub fn current_column(&self, input: &Channel) -> String {
        self.currents
            .iter()
            .rev()
            .find(|(_, n)| *n == input.name)
            .map_or(input.column.clone(), |(e, _)| e.to_string())
    }

    /// Where boundary `b`'s values come from: its last `--boundary`
    /// expression, else the trace's column (`trace_has_column`), else a
    /// `--const` of that column, else the boundary's own value (`Err`,
    /// held on every row).
    pub fn boundary_column(&self, b: &Channel, trace_has_column: bool) -> Result<String, f64> {
        let bound = self.boundaries.iter().rev().find(|(_, n)| *n == b.name);
        let constant = self.constants.iter().any(|(c, _)| *c == b.column);
        match (bound, b.default_value) {
            (Some((e, _)), _) => Ok(e.to_string()),
            (None, Some(v)) if !trace_has_column && !constant => Err(v),
            (None, _) => Ok(b.column.clone()),
        }
    }

    /// Refuses a `--current` or `--boundary` that names no input or
    /// boundary of `info`, listing the ones it has.
    ///
    /// # Errors
    /// The first unknown name.
    pub fn check_names(&self, info: &PlantInfo) -> Result<()> {
        for (_, name) in &self.currents {
            if !info.inputs.iter().any(|i| &i.name == name) {
                bail!(
                    "--current: model `{}` has no current input `{name}` (inputs: {})",
                    info.name,
                    names(&info.inputs)
                );
            }
        }
        for (_, name) in &self.boundaries {
            if !info.boundaries.iter().any(|b| &b.name == name) {
                bail!(
                    "--boundary: model `{}` has no boundary `{name}` (boundaries: {})",
                    info.name,
                    names(&info.boundaries)
                );
            }
        }
        Ok(())
    }
}

/// Input series of a run, one value per row: `[channel][row]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Drive {
    /// Row times \[s\].
    pub time_s: Vec<f64>,
    /// Currents per input \[A\].
    pub currents: Vec<Vec<f64>>,
    /// Boundary temperatures \[degC\].
    pub boundaries: Vec<Vec<f64>>,
    /// Extra signals.
    pub signals: Vec<Vec<f64>>,
}

impl Drive {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// `true` without rows.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Inputs of row `k`, into reusable buffers.
    pub fn row(
        &self,
        k: usize,
        currents: &mut Vec<f64>,
        boundary: &mut Vec<f64>,
        signals: &mut Vec<f64>,
    ) {
        currents.clear();
        currents.extend(self.currents.iter().map(|c| c[k]));
        boundary.clear();
        boundary.extend(self.boundaries.iter().map(|c| c[k]));
        signals.clear();
        signals.extend(self.signals.iter().map(|c| c[k]));
    }

    /// Holds the inputs as `hold` says: with [`InputHold::End`] every
    /// series moves one row earlier (row `k` then carries row `k+1`'s
    /// inputs, the last row its own), so the simulators' zero-order hold
    /// applies the inputs of the row each interval ends at.
    pub fn held(mut self, hold: InputHold) -> Self {
        if hold == InputHold::End {
            let advance = |v: &mut Vec<f64>| {
                if v.len() > 1 {
                    v.remove(0);
                    v.push(*v.last().expect("non-empty"));
                }
            };
            self.currents.iter_mut().for_each(advance);
            self.boundaries.iter_mut().for_each(advance);
            self.signals.iter_mut().for_each(advance);
        }
        self
    }

    /// Resolves every channel of `info` against a trace.
    pub fn from_trace(info: &PlantInfo, trace: &Trace, bind: &Bindings) -> Result<Self> {
        let file = trace.path().display().to_string();
        bind.check_names(info)?;
        let column = |text: &str, what: &str| -> Result<Vec<f64>> {
            let expr = ColumnExpr::parse(text).with_context(|| format!("{file}: {what}"))?;
            let cols = expr.columns();
            if let Some(missing) = cols.iter().find(|c| !trace.has_column(c)) {
                if let Some((_, v)) = bind.constants.iter().rev().find(|(c, _)| c == missing) {
                    if cols.len() == 1 {
                        return v
                            .at_times(trace.time_s())
                            .map_err(|e| anyhow!("{file}: --const {missing}: {e}"));
                    }
                }
            }
            trace
                .eval(&expr)
                .map_err(|e| anyhow::anyhow!("{e} (for {what})"))
        };
        let mut currents = Vec::new();
        for input in &info.inputs {
            let text = bind.current_column(input);
            let mut series = column(&text, &format!("current input `{}`", input.name))?;
            if let Some(k) = bind.current_scale {
                series.iter_mut().for_each(|i| *i *= k);
            }
            currents.push(series);
        }
        let mut boundaries = Vec::new();
        for b in &info.boundaries {
            let series = match bind.boundary_column(b, trace.has_column(&b.column)) {
                Ok(text) => column(&text, &format!("boundary `{}`", b.name))?,
                Err(value_c) => vec![value_c; trace.len()],
            };
            boundaries.push(series);
        }
        let mut signals = Vec::new();
        for s in &info.signals {
            signals.push(column(s, &format!("signal `{s}`"))?);
        }
        Ok(Self {
            time_s: trace.time_s().to_vec(),
            currents,
            boundaries,
            signals,
        })
    }

    /// Constant inputs on a uniform time grid `0, dt, ..., duration`.
    pub fn constant(
        info: &PlantInfo,
        duration_s: f64,
        dt_s: f64,
        currents_a: &[f64],
        ambient_c: Option<f64>,
        bind: &Bindings,
    ) -> Result<Self> {
        if !(duration_s.is_finite() && duration_s >= 0.0) {
            bail!("--duration-s must be finite and >= 0 s, got {duration_s}");
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            bail!("--dt-s must be finite and > 0 s, got {dt_s}");
        }
        let currents_a: Vec<f64> = match (currents_a.len(), info.inputs.len()) {
            (1, m) => vec![currents_a[0]; m],
            (n, m) if n == m => currents_a.to_vec(),
            (n, m) => bail!(
                "--current-a has {n} values but model `{}` has {m} current inputs ({})",
                info.name,
                names(&info.inputs)
            ),
        };
        let rows_f = (duration_s / dt_s).round() + 1.0;
        let cells = rows_f * (info.nodes.len() + info.inputs.len() + info.boundaries.len()) as f64;
        if rows_f > MAX_ROWS as f64 || cells > MAX_CELLS as f64 {
            bail!(
                "--duration-s {} s every --dt-s {} s is {rows_f:.3e} output rows of {} nodes; \
                 at most {MAX_ROWS} rows and {MAX_CELLS:.0e} values are written: raise --dt-s \
                 (the output period; the model sub-steps internally as stability requires) or shorten --duration-s",
                num(duration_s),
                num(dt_s),
                info.nodes.len()
            );
        }
        let rows = rows_f as usize;
        let time_s: Vec<f64> = (0..rows).map(|k| k as f64 * dt_s).collect();
        let lookup = |col: &str| -> Result<Option<Vec<f64>>> {
            bind.constants
                .iter()
                .rev()
                .find(|(c, _)| c == col)
                .map(|(_, v)| {
                    v.at_times(&time_s)
                        .map_err(|e| anyhow!("--const {col}: {e}"))
                })
                .transpose()
        };
        let mut boundaries = Vec::new();
        for b in &info.boundaries {
            let series = match (ambient_c, lookup(&b.column)?, b.default_value) {
                (Some(v), _, _) => vec![v; rows],
                (None, Some(series), _) => series,
                (None, None, Some(v)) => vec![v; rows],
                (None, None, None) => bail!(
                    "boundary `{}` has no temperature: pass --ambient-c or --const {}=VALUE",
                    b.name,
                    b.column
                ),
            };
            boundaries.push(series);
        }
        let mut signals = Vec::new();
        for s in &info.signals {
            let series = lookup(s)?.with_context(|| {
                format!("the model needs signal column `{s}`: pass --const {s}=VALUE or --trace")
            })?;
            signals.push(series);
        }
        Ok(Self {
            time_s,
            currents: currents_a.iter().map(|i| vec![*i; rows]).collect(),
            boundaries,
            signals,
        })
    }
}

fn names(ch: &[Channel]) -> String {
    ch.iter()
        .map(|c| c.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Initial node temperatures \[degC\] by the plant's policy. `measured` maps
/// node index to a first measured value.
pub fn initial_temps(
    info: &PlantInfo,
    drive: &Drive,
    measured: &[(usize, f64)],
) -> Result<Vec<f64>> {
    let first: Vec<f64> = drive.boundaries.iter().map(|b| b[0]).collect();
    initial_temps_at(info, &first, measured)
}

/// [`initial_temps`] from the first row's boundary temperatures
/// `boundaries_c` \[degC\].
pub fn initial_temps_at(
    info: &PlantInfo,
    boundaries_c: &[f64],
    measured: &[(usize, f64)],
) -> Result<Vec<f64>> {
    let boundary_mean = if boundaries_c.is_empty() {
        None
    } else {
        Some(boundaries_c.iter().sum::<f64>() / boundaries_c.len() as f64)
    };
    let fallback = || {
        boundary_mean
            .context("the model has no boundary: set [initial] policy = \"uniform\" with uniform_c")
    };
    let mut temps = match info.initial.policy {
        InitialPolicy::Uniform => vec![info.initial.uniform_c.unwrap_or(20.0); info.nodes.len()],
        InitialPolicy::Boundary | InitialPolicy::Measured => vec![fallback()?; info.nodes.len()],
    };
    if info.initial.policy == InitialPolicy::Measured {
        for (node, v) in measured {
            temps[*node] = *v;
        }
    }
    Ok(temps)
}

/// Runs a plant over a drive from `init`: the state at every row `[row][node]`.
pub fn simulate(plant: &mut dyn Plant, drive: &Drive, init: &[f64]) -> Vec<Vec<f64>> {
    plant.reset(init);
    let (mut c, mut b, mut s) = (Vec::new(), Vec::new(), Vec::new());
    let mut out = Vec::with_capacity(drive.len());
    out.push(plant.temps_c().to_vec());
    for k in 0..drive.len().saturating_sub(1) {
        drive.row(k, &mut c, &mut b, &mut s);
        plant.step(drive.time_s[k + 1] - drive.time_s[k], &c, &b, &s);
        out.push(plant.temps_c().to_vec());
    }
    out
}

/// Transposes `[row][node]` into `[node][row]`.
pub fn by_node(rows: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = rows.first().map_or(0, Vec::len);
    (0..n)
        .map(|i| rows.iter().map(|r| r[i]).collect())
        .collect()
}
