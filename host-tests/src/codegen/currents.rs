//! The generated module's `source_currents_a`: every current of the
//! firmware observer from the model file's current inputs and signals, as
//! `f32` Rust, the same arithmetic as the host's
//! [`Model::effective_currents`](crate::model_file::Model::effective_currents).
//!
//! The observer's network has one Joule source per current (see the
//! model file's equations in `host-tests/MODEL_FORMAT.md`):
//! * a `[[source]]` carries its input's current, times
//!   `sqrt(max(0, 1 + a1 f + a2 f^2))` when it has a speed factor (its
//!   power scale is folded into its resistance);
//! * a `[[speed_loss]]` is a 1 ohm source carrying `sqrt(P(f))`;
//! * a `[[loss]]` is one 1 ohm source per node carrying `sqrt` of its
//!   node's share of `P(i, f)`.
//!
//! Signals enter by magnitude per unit of their reference (`|s| / ref`).
//! Unlike the host, which reads finite traces, a NaN signal is kept: the
//! currents it drives are NaN, and the observer holds a NaN current at its
//! last valid value, flagged (`NetworkInputs::currents_a`), rather than
//! reading a missing speed as standstill.

use std::fmt::Write as _;

use coil_thermal::VoltageDrive;

use crate::model_file::{LossTerm, Model, SourceKind, VoltageSource};

/// What one current of the observer is made of.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum CurrentOf {
    /// `[[source]]`: model input `input`, with its speed factor
    /// (signal, reference, a1, a2) when it has one.
    Input {
        input: usize,
        speed: Option<(usize, f64, f64, f64)>,
    },
    /// `[[speed_loss]]` number `k`.
    SpeedLoss(usize),
    /// `[[loss]]` number `k`, on its first node or its second.
    Loss { k: usize, second: bool },
}

/// Every current of `model`'s network, in its source order
/// ([`Model::source_kinds`]).
pub(super) fn currents_of(model: &Model) -> Vec<CurrentOf> {
    model
        .source_kinds()
        .map(|kind| match kind {
            SourceKind::Drive(k) => CurrentOf::Input {
                input: model.drives[k].input,
                speed: model.drives[k].speed,
            },
            SourceKind::SpeedLoss(k) => CurrentOf::SpeedLoss(k),
            SourceKind::Loss { k, second } => CurrentOf::Loss { k, second },
        })
        .collect()
}

/// Refuses a speed or loss coefficient or reference beyond `f32`'s range,
/// or a reference below its smallest normal number (it divides): the
/// generated arithmetic is `f32`, and an infinite literal is not Rust.
pub(super) fn check_f32_range(model: &Model) -> anyhow::Result<()> {
    // (table, value, is a reference)
    let mut values = Vec::new();
    for d in &model.drives {
        if let Some((_, r, a1, a2)) = d.speed {
            let t = "[source.speed]";
            values.extend([(t, r, true), (t, a1, false), (t, a2, false)]);
        }
    }
    for l in &model.speed_losses {
        let t = "[[speed_loss]]";
        values.extend([
            (t, l.reference, true),
            (t, l.p1_w, false),
            (t, l.p2_w, false),
        ]);
    }
    for l in &model.losses {
        let t = "[[loss]]";
        values.extend(l.current.iter().chain(&l.speed).map(|(_, r)| (t, *r, true)));
        values.extend(
            l.power
                .iter()
                .chain(&l.split)
                .map(|term| (t, term.c, false)),
        );
    }
    for (table, v, reference) in values {
        if v.abs() > f64::from(f32::MAX) || (reference && v < f64::from(f32::MIN_POSITIVE)) {
            anyhow::bail!("{table}: {v:e} is beyond the f32 range of the firmware's arithmetic");
        }
    }
    Ok(())
}

/// A literal `f32` that reads back as `v` rounded to `f32`.
fn lit(v: f64) -> String {
    // `{:?}` of the rounded f32 is the shortest text that reads back to it.
    #[allow(clippy::cast_possible_truncation)]
    let f = v as f32;
    format!("{f:?}_f32")
}

/// The per-unit signals the body names, as `u0, u1, ...`.
#[derive(Default)]
struct PerUnit {
    pairs: Vec<(usize, f64)>,
}

impl PerUnit {
    fn name(&mut self, signal: usize, reference: f64) -> String {
        let k = match self
            .pairs
            .iter()
            .position(|&(s, r)| s == signal && r.to_bits() == reference.to_bits())
        {
            Some(k) => k,
            None => {
                self.pairs.push((signal, reference));
                self.pairs.len() - 1
            }
        };
        format!("u{k}")
    }
}

/// `sum_k c_k i^(i_k) f^(f_k)` as Rust over the per-unit variables.
fn polynomial(terms: &[LossTerm], i: Option<&str>, f: Option<&str>) -> String {
    let mut parts = Vec::new();
    for t in terms {
        let mut factors = vec![lit(t.c)];
        for (var, power) in [(i, t.i), (f, t.f)] {
            // The model file refuses a power of a signal the loss lacks.
            if let Some(var) = var {
                factors.extend((0..power).map(|_| var.to_string()));
            }
        }
        parts.push(factors.join(" * "));
    }
    if parts.is_empty() {
        "0.0_f32".into()
    } else {
        parts.join(" + ")
    }
}

/// The generated module's `input_limits_a`: each model input's limit
/// from the observer's published limits, the smallest among the currents
/// the input drives (every current has the `[observer]` hardware limit,
/// so that is the input's hardware limit times the smallest taper).
pub(super) fn input_limits_fn(inputs: usize, currents: &[CurrentOf]) -> String {
    let limits: Vec<String> = (0..inputs)
        .map(|k| {
            let driven: Vec<String> = currents
                .iter()
                .enumerate()
                .filter(|(_, c)| matches!(c, CurrentOf::Input { input, .. } if *input == k))
                .map(|(m, _)| format!("limits[{m}].current_a"))
                .collect();
            // `Model::build` gives every input a source.
            let (first, rest) = driven
                .split_first()
                .map_or(("0.0_f32", &[][..]), |(f, r)| (f.as_str(), r));
            rest.iter()
                .fold(first.to_string(), |acc, l| format!("{acc}.min({l})"))
        })
        .collect();
    let mut o = String::new();
    o.push_str(concat!(
        "/// The largest current of each model input \\[A\\] the limiter allows\n",
        "/// now (in [`INPUT_NAMES`] order), from the published limits\n",
        "/// (`Outputs::limits`): the smallest among the currents the input\n",
        "/// drives. Those share the input's hardware limit, so this is that limit\n",
        "/// times the smallest taper (`sqrt` of the headroom) of any element they\n",
        "/// heat. A speed factor scales a current and its heat together and\n",
        "/// leaves the taper as it is: hold the input's own current (`|i_s|` of\n",
        "/// a motor, not its effective current) to this. Loss currents (speed and\n",
        "/// `[[loss]]` terms) are no input's and limit none. A latched shutdown\n",
        "/// gives zero.\n",
        "pub fn input_limits_a(limits: &[CoilLimit<f32>; CURRENTS]) -> [f32; INPUTS] {\n",
    ));
    let _ = writeln!(o, "    [{}]\n}}\n", limits.join(", "));
    o
}

/// The helpers and `source_currents_a` of the generated module.
pub(super) fn source_currents_fn(model: &Model, currents: &[CurrentOf]) -> String {
    let mut units = PerUnit::default();
    let mut lets = String::new();
    let mut exprs = Vec::new();
    for (k, l) in model.losses.iter().enumerate() {
        let i = l.current.map(|(s, r)| units.name(s, r));
        let f = l.speed.map(|(s, r)| units.name(s, r));
        let _ = writeln!(
            lets,
            "    let loss{k} = non_negative({});",
            polynomial(&l.power, i.as_deref(), f.as_deref())
        );
        if !l.split.is_empty() {
            let _ = writeln!(
                lets,
                "    let split{k} = unit_interval({});",
                polynomial(&l.split, i.as_deref(), f.as_deref())
            );
        }
    }
    for c in currents {
        exprs.push(match *c {
            CurrentOf::Input { input, speed: None } => format!("input_a[{input}]"),
            CurrentOf::Input {
                input,
                speed: Some((s, reference, a1, a2)),
            } => {
                let u = units.name(s, reference);
                format!(
                    "input_a[{input}] * root(1.0_f32 + {} * {u} + {} * {u} * {u})",
                    lit(a1),
                    lit(a2)
                )
            }
            CurrentOf::SpeedLoss(k) => {
                let l = &model.speed_losses[k];
                let u = units.name(l.signal, l.reference);
                format!("root({} * {u} + {} * {u} * {u})", lit(l.p1_w), lit(l.p2_w))
            }
            CurrentOf::Loss { k, second } => match (model.losses[k].split.is_empty(), second) {
                (true, _) => format!("root(loss{k})"),
                (false, false) => format!("root(split{k} * loss{k})"),
                (false, true) => format!("root((1.0_f32 - split{k}) * loss{k})"),
            },
        });
    }
    let mut o = String::new();
    o.push_str(
        "/// Each current of the observer \\[A\\] from the model file's current\n/// inputs \\[A\\] and signals (in [`INPUT_NAMES`] and [`SIGNAL_NAMES`]\n/// order): a source's input current, times `sqrt(max(0, 1 + a1 f + a2\n/// f^2))` when it has a speed factor; a speed or `[[loss]]` loss as a\n/// 1 ohm source carrying `sqrt(P)`. Signals count by magnitude, per unit\n/// of their reference. A NaN input or signal makes the currents it drives\n/// NaN, which the observer holds at their last valid value, flagged.\n",
    );
    o.push_str("pub fn source_currents_a(input_a: &[f32; INPUTS], signal: &[f32; SIGNALS]) -> [f32; CURRENTS] {\n");
    if units.pairs.is_empty() {
        o.push_str("    let _ = signal;\n");
    }
    for (k, (s, r)) in units.pairs.iter().enumerate() {
        let _ = writeln!(o, "    let u{k} = per_unit(signal[{s}], {});", lit(*r));
    }
    o.push_str(&lets);
    let _ = writeln!(o, "    [{}]\n}}\n", exprs.join(", "));
    if !units.pairs.is_empty() {
        o.push_str("/// `|value| / reference`, NaN kept.\nfn per_unit(value: f32, reference: f32) -> f32 {\n    <f32 as coil_thermal::Scalar>::abs(value) / reference\n}\n\n");
    }
    let roots = currents
        .iter()
        .any(|c| !matches!(c, CurrentOf::Input { speed: None, .. }));
    if roots {
        o.push_str("/// `sqrt(max(0, x))`, NaN kept.\nfn root(x: f32) -> f32 {\n    if x.is_nan() {\n        x\n    } else {\n        <f32 as coil_thermal::Scalar>::sqrt(x)\n    }\n}\n\n");
    }
    if !model.losses.is_empty() {
        o.push_str("/// `max(0, x)`, NaN kept.\nfn non_negative(x: f32) -> f32 {\n    if x < 0.0 {\n        0.0\n    } else {\n        x\n    }\n}\n\n");
        if model.losses.iter().any(|l| !l.split.is_empty()) {
            o.push_str("/// `x` clipped to `[0, 1]`, NaN kept.\nfn unit_interval(x: f32) -> f32 {\n    x.clamp(0.0, 1.0)\n}\n\n");
        }
    }
    o
}

/// The generated module's `source_drives` and `input_drive_limits`, for a
/// model with a voltage-driven `[[source]]` (`drive = "pwm"` or
/// `"voltage"`; nothing for a current-driven model, whose module is
/// unchanged). A `pwm` source's duty is its input, its supply the constant
/// `supply_v` or the signal `supply_column`; its power scale `k` (folded
/// into its resistance, see the module docs) multiplies the supply by
/// `k`: `V_eff = sqrt(D) k V` through `k R(T)` is `k D V^2 / R(T)`. A
/// linear `voltage` source is a duty of 1 on its input voltage.
pub(super) fn source_drives_fn(model: &Model) -> String {
    let mut exprs = Vec::new();
    for kind in model.source_kinds() {
        exprs.push(match kind {
            SourceKind::Drive(k) => {
                let d = &model.drives[k];
                let scale = lit(d.scale.max(0.0));
                match d.voltage {
                    None => "None".to_string(),
                    Some(VoltageSource::PwmConstant(v)) => format!(
                        "Some(VoltageDrive::pwm(input[{}], {scale} * {}))",
                        d.input,
                        lit(v)
                    ),
                    Some(VoltageSource::PwmSignal(s)) => format!(
                        "Some(VoltageDrive::pwm(input[{}], {scale} * signal[{s}]))",
                        d.input
                    ),
                    Some(VoltageSource::Linear) => format!(
                        "Some(VoltageDrive::linear({scale} * <f32 as coil_thermal::Scalar>::abs(input[{}])))",
                        d.input
                    ),
                }
            }
            _ => "None".to_string(),
        });
    }
    let mut o = String::new();
    o.push_str(concat!(
        "/// The voltage drive of each current (`None`: a current drive, taken\n",
        "/// from [`source_currents_a`]) from the model file's inputs (a PWM\n",
        "/// duty, or a voltage \\[V\\]) and signals (a measured supply \\[V\\]).\n",
        "/// Tick with `observer.tick_voltage(&mut state, &inputs, &source_drives(..))`:\n",
        "/// each becomes the current the winding draws at its estimated\n",
        "/// temperature; a NaN, negative or zero duty or supply is held and\n",
        "/// flagged (`DriveFlags`).\n",
        "pub fn source_drives(input: &[f32; INPUTS], signal: &[f32; SIGNALS]) -> [Option<VoltageDrive>; CURRENTS] {\n",
        "    let _ = signal;\n",
    ));
    let _ = writeln!(o, "    [{}]\n}}\n", exprs.join(", "));
    // Each voltage-driven input's limit in its own unit.
    let mut limits = Vec::new();
    for (k, _) in model.inputs.iter().enumerate() {
        let mut parts = Vec::new();
        for (m, kind) in model.source_kinds().enumerate() {
            let SourceKind::Drive(j) = kind else { continue };
            let d = &model.drives[j];
            if d.input != k {
                continue;
            }
            let scale = lit(d.scale.max(0.0));
            parts.push(match d.voltage {
                None => format!("outputs.limits[{m}].current_a"),
                Some(VoltageSource::PwmConstant(v)) => format!(
                    "observer.drive_limit(state, {m}, {scale} * {}).duty",
                    lit(v)
                ),
                Some(VoltageSource::PwmSignal(s)) => {
                    format!("observer.drive_limit(state, {m}, {scale} * signal[{s}]).duty")
                }
                Some(VoltageSource::Linear) => {
                    format!("observer.drive_limit(state, {m}, 1.0_f32).voltage_v / {scale}")
                }
            });
        }
        let (first, rest) = parts
            .split_first()
            .map_or(("0.0_f32".to_string(), &[][..]), |(f, r)| (f.clone(), r));
        limits.push(rest.iter().fold(first, |acc, l| format!("{acc}.min({l})")));
    }
    o.push_str(concat!(
        "/// Each model input's limit in its own unit, after a tick: a `pwm`\n",
        "/// input's largest duty in `[0, 1]` on its supply (`(I_lim R(T) / V)^2`,\n",
        "/// zero for a NaN, zero or negative supply reading), a `voltage`\n",
        "/// input's largest voltage \\[V\\], a current input's current \\[A\\]\n",
        "/// (as [`input_limits_a`]).\n",
        "pub fn input_drive_limits(observer: &Observer, state: &State, signal: &[f32; SIGNALS]) -> [f32; INPUTS] {\n",
        "    let _ = signal;\n",
        "    let outputs = state.outputs();\n",
        "    let _ = outputs;\n",
    ));
    let _ = writeln!(o, "    [{}]\n}}\n", limits.join(", "));
    o
}

/// The generated module's `source_currents_a` and `source_drives`, evaluated
/// on the host in the same `f32` operations, in the same order: what
/// `replay` hands the firmware observer, so that its estimates are the
/// module's to the bit (a speed factor's or a loss's `f32` root is not the
/// `f64` one of [`Model::effective_currents`] rounded once). The network it
/// drives is [`Model::firmware_network`]: each `[[source]]`'s power scale
/// folded into its resistance, as the module's.
#[derive(Debug, Clone)]
pub struct FirmwareInputs {
    model: Model,
    currents: Vec<CurrentOf>,
}

impl FirmwareInputs {
    /// The firmware inputs of `model`.
    pub fn new(model: &Model) -> Self {
        Self {
            currents: currents_of(model),
            model: model.clone(),
        }
    }

    /// Number of currents (the network's sources).
    pub fn len(&self) -> usize {
        self.currents.len()
    }

    /// `true` for a model without a current.
    pub fn is_empty(&self) -> bool {
        self.currents.is_empty()
    }

    /// Each current of the observer \[A\] from the model's inputs `input_a`
    /// \[A\] and `signal`s, as `source_currents_a`, into `out` (the first
    /// [`Self::len`]; a missing input or signal reads NaN, as a NaN cell
    /// does).
    pub fn currents_a(&self, input_a: &[f32], signal: &[f32], out: &mut [f32]) {
        let input = |k: usize| input_a.get(k).copied().unwrap_or(f32::NAN);
        let unit = |s: usize, reference: f64| {
            let v = signal.get(s).copied().unwrap_or(f32::NAN);
            <f32 as coil_thermal::Scalar>::abs(v) / f32_of(reference)
        };
        let currents = self.currents.iter().map(|c| match *c {
            CurrentOf::Input {
                input: k,
                speed: None,
            } => input(k),
            CurrentOf::Input {
                input: k,
                speed: Some((s, reference, a1, a2)),
            } => {
                let u = unit(s, reference);
                input(k) * root(1.0 + f32_of(a1) * u + f32_of(a2) * u * u)
            }
            CurrentOf::SpeedLoss(k) => {
                let l = &self.model.speed_losses[k];
                let u = unit(l.signal, l.reference);
                root(f32_of(l.p1_w) * u + f32_of(l.p2_w) * u * u)
            }
            CurrentOf::Loss { k, second } => {
                let l = &self.model.losses[k];
                let i = l.current.map(|(s, r)| unit(s, r));
                let f = l.speed.map(|(s, r)| unit(s, r));
                let loss = polynomial_f32(&l.power, i, f);
                let loss = if loss < 0.0 { 0.0 } else { loss };
                if l.split.is_empty() {
                    root(loss)
                } else {
                    let split = polynomial_f32(&l.split, i, f).clamp(0.0, 1.0);
                    if second {
                        root((1.0 - split) * loss)
                    } else {
                        root(split * loss)
                    }
                }
            }
        });
        for (o, c) in out.iter_mut().zip(currents) {
            *o = c;
        }
    }

    /// The voltage drive of network source `m` as `source_drives` gives it
    /// (`None`: a current drive), from the model's inputs (a duty or a
    /// voltage) and signals (a measured supply \[V\]).
    pub fn drive(&self, m: usize, input: &[f32], signal: &[f32]) -> Option<VoltageDrive> {
        let d = self.model.drives.get(m)?;
        let scale = f32_of(d.scale.max(0.0));
        let duty = input.get(d.input).copied().unwrap_or(f32::NAN);
        let signal = |s: usize| signal.get(s).copied().unwrap_or(f32::NAN);
        Some(match d.voltage? {
            VoltageSource::PwmConstant(v) => VoltageDrive::pwm(duty, scale * f32_of(v)),
            VoltageSource::PwmSignal(s) => VoltageDrive::pwm(duty, scale * signal(s)),
            VoltageSource::Linear => {
                VoltageDrive::linear(scale * <f32 as coil_thermal::Scalar>::abs(duty))
            }
        })
    }

    /// The supply \[V\] at which `input_drive_limits` asks the library for
    /// network source `m`'s drive limit: a `pwm` source's supply times its
    /// power scale, 1 V for a linear one (its voltage limit does not depend
    /// on it); `None` for a current drive.
    pub fn limit_supply_v(&self, m: usize, signal: &[f32]) -> Option<f32> {
        let d = self.model.drives.get(m)?;
        let scale = f32_of(d.scale.max(0.0));
        Some(match d.voltage? {
            VoltageSource::PwmConstant(v) => scale * f32_of(v),
            VoltageSource::PwmSignal(s) => scale * signal.get(s).copied().unwrap_or(f32::NAN),
            VoltageSource::Linear => 1.0,
        })
    }

    /// A voltage-driven source's limit in its input's unit from the
    /// library's drive limit at its drive, as `input_drive_limits`: a
    /// `pwm` input's duty, a linear input's voltage \[V\] (the effective
    /// voltage `voltage_v` over the source's power scale, in `f32`).
    pub fn drive_limit(&self, m: usize, duty: f32, voltage_v: f32) -> Option<f32> {
        let d = self.model.drives.get(m)?;
        Some(match d.voltage? {
            VoltageSource::Linear => voltage_v / f32_of(d.scale.max(0.0)),
            _ => duty,
        })
    }
}

/// `v` rounded to `f32`, as [`lit`] writes it.
#[allow(clippy::cast_possible_truncation)]
fn f32_of(v: f64) -> f32 {
    v as f32
}

/// The generated `root`: `sqrt`, NaN kept.
fn root(x: f32) -> f32 {
    if x.is_nan() {
        x
    } else {
        <f32 as coil_thermal::Scalar>::sqrt(x)
    }
}

/// [`polynomial`] evaluated as its Rust reads: each term `c * i * .. * f
/// * ..` left to right, the terms summed left to right.
fn polynomial_f32(terms: &[LossTerm], i: Option<f32>, f: Option<f32>) -> f32 {
    let term = |t: &LossTerm| {
        let mut p = f32_of(t.c);
        for (var, power) in [(i, t.i), (f, t.f)] {
            if let Some(v) = var {
                for _ in 0..power {
                    p *= v;
                }
            }
        }
        p
    };
    let mut terms = terms.iter();
    match terms.next() {
        None => 0.0,
        Some(first) => terms.fold(term(first), |sum, t| sum + term(t)),
    }
}
