//! The model-uncertainty margin of a user's own device, measured rather
//! than borrowed (`calibrate --validate`).
//!
//! The firmware protects every node no sensor measures on its upper bound,
//! the estimate plus `k sigma` plus a margin on its rise above the ambient
//! (`[observer] unmeasured_margin`, by default 5 %: the Omnimagnet's,
//! measured at +-20 % parameter error). A bench recording the fit did not
//! see, with a thermocouple on a node the product will not have (the
//! winding), says how far the truth of that node rises above what the
//! firmware's observer publishes: [`check`] runs the observer `codegen`
//! flashes (the fitted file's `[observer]` table, [`FirmwareConfig`]) over
//! the recording, fusing only the product's sensors, and compares each
//! other bench-measured node with its upper bound at every row after the
//! first two correction periods. The share of the rise that would have
//! covered the truth at every row is the margin the device needs; the
//! fitted file gets it rounded up to the next [`MARGIN_STEP`], at least one
//! step ([`written_margin`]), so that `codegen` flashes it.

use anyhow::{bail, Result};
use serde::Serialize;

use crate::calibrate::{first_readings, FitData};
use crate::codegen::ObserverSpec;
use crate::firmware::FirmwareConfig;
use crate::library_observer::ObserverEstimator;
use crate::model_file::Model;
use crate::observer::{Estimator, Measurement};
use crate::sim::{initial_temps, plant_info};

/// Rows whose estimated rise above the ambient is below this only check
/// the bound, not the share \[K\]: a share of a rise near zero says
/// nothing.
pub const MIN_RISE_K: f64 = 2.0;

/// The written margin is a whole number of these (dimensionless).
pub const MARGIN_STEP: f64 = 0.01;

/// One bench-measured node the product's sensors do not see.
#[derive(Debug, Clone, Serialize)]
pub struct NodeCheck {
    /// Node name.
    pub node: String,
    /// The recording's column.
    pub column: String,
    /// Largest truth above the upper bound with the file's margin \[K\]
    /// (negative: the bound covered the truth at every row, by at least
    /// that much).
    pub worst_above_bound_k: f64,
    /// When \[s\] from the recording's start.
    pub at_s: f64,
    /// The share of the rise that covers the truth at every row with a
    /// rise of at least [`MIN_RISE_K`] (dimensionless; may be negative).
    pub needed_margin: f64,
}

/// What one recording says of the margin.
#[derive(Debug, Clone, Serialize)]
pub struct MarginCheck {
    /// The recording.
    pub trace: String,
    /// The margin the observer ran with: the share of the rise and the
    /// fixed part \[K\].
    pub margin: f64,
    /// The margin's fixed part \[K\].
    pub margin_offset_k: f64,
    /// Per bench-measured node no product sensor reads.
    pub nodes: Vec<NodeCheck>,
}

/// Runs the firmware observer of `model` (its `[observer]` table `spec`)
/// over the recording `d`, fusing the product's sensors from `d`'s
/// readings, and checks every other node `d` measures against its upper
/// bound (see the module docs). `None` when the table names no sensor or
/// `d` measures no other node.
///
/// # Errors
/// A product sensor the recording has no `--measure` column for; an
/// observer that does not build.
pub fn check(model: &Model, spec: &ObserverSpec, d: &FitData) -> Result<Option<MarginCheck>> {
    let config = FirmwareConfig::of(model, Some(spec))?;
    config.require_temperature_sensors("calibrate --validate")?;
    if config.sensor_nodes.is_empty() {
        return Ok(None);
    }
    let mut fused = Vec::new();
    for (name, node) in spec.sensors.iter().zip(&config.sensor_nodes) {
        match d.targets.iter().position(|t| t.node == *node) {
            Some(k) => fused.push(k),
            None => bail!(
                "--validate {}: the observer's sensor `{name}` has no reading in it: give it with --measure COLUMN={name}",
                d.label
            ),
        }
    }
    let truths: Vec<usize> = (0..d.targets.len())
        .filter(|k| !config.sensor_nodes.contains(&d.targets[*k].node))
        .collect();
    if truths.is_empty() {
        return Ok(None);
    }
    let info = plant_info(model);
    let mut measured = first_readings(&d.targets);
    measured.extend(d.init.iter().copied());
    let init = initial_temps(&info, &d.drive, &measured)?;
    let mut observer = ObserverEstimator::firmware(
        model.clone(),
        config.settings.step_us,
        &config,
        &config.sensor_nodes,
    )?;
    observer.reset(&init);
    let margin = config.settings.unmeasured_margin;
    let ambient = config.settings.ambient_boundary;
    let drive = &d.drive;
    let from_s = drive.time_s[0] + 2.0 * config.settings.correction_period_s;
    let mut nodes: Vec<NodeCheck> = truths
        .iter()
        .map(|k| NodeCheck {
            node: info.nodes[d.targets[*k].node].clone(),
            column: d.targets[*k].column.clone(),
            worst_above_bound_k: f64::NEG_INFINITY,
            at_s: 0.0,
            needed_margin: f64::NEG_INFINITY,
        })
        .collect();
    let signals: Vec<f64> = Vec::new();
    for row in 0..drive.len() {
        let meas: Vec<Measurement> = fused
            .iter()
            .map(|k| Measurement {
                node: d.targets[*k].node,
                value_c: d.targets[*k].values_c[row],
                fault: None,
            })
            .collect();
        observer.update(&meas);
        let t_s = drive.time_s[row];
        if t_s >= from_s {
            let upper = &observer.protected().upper_c;
            let mean = observer.estimate_c();
            let ambient_c = drive.boundaries.get(ambient).map_or(f64::NAN, |b| b[row]);
            for (check, k) in nodes.iter_mut().zip(&truths) {
                let target = &d.targets[*k];
                let truth = target.values_c[row];
                if truth.is_nan() {
                    continue;
                }
                let above = truth - upper[target.node];
                if above > check.worst_above_bound_k {
                    check.worst_above_bound_k = above;
                    check.at_s = t_s - drive.time_s[0];
                }
                let rise = mean[target.node] - ambient_c;
                if rise >= MIN_RISE_K {
                    // The bound with a share `f`: upper + (f - f_used) rise.
                    let needed = margin.rise_fraction + above / rise;
                    check.needed_margin = check.needed_margin.max(needed);
                }
            }
        }
        if row + 1 < drive.len() {
            let currents: Vec<f64> = drive.currents.iter().map(|c| c[row]).collect();
            let boundaries: Vec<f64> = drive.boundaries.iter().map(|b| b[row]).collect();
            let row_signals: Vec<f64> = if drive.signals.is_empty() {
                signals.clone()
            } else {
                drive.signals.iter().map(|s| s[row]).collect()
            };
            observer.predict(
                drive.time_s[row + 1] - t_s,
                &currents,
                &boundaries,
                &row_signals,
            );
        }
    }
    Ok(Some(MarginCheck {
        trace: d.label.clone(),
        margin: margin.rise_fraction,
        margin_offset_k: margin.offset_k,
        nodes,
    }))
}

/// The margin to write from `checks`: the largest share any node of any
/// recording needed, rounded up to the next [`MARGIN_STEP`], at least one
/// step (`None` without a node that needed a share: no row rose
/// [`MIN_RISE_K`] above the ambient).
pub fn written_margin(checks: &[MarginCheck]) -> Option<f64> {
    let needed = checks
        .iter()
        .flat_map(|c| &c.nodes)
        .map(|n| n.needed_margin)
        .filter(|f| f.is_finite())
        .reduce(f64::max)?;
    let steps = (needed / MARGIN_STEP).ceil().max(1.0);
    // Printed with two decimals: no 0.07000000000000001.
    Some((steps * MARGIN_STEP * 100.0).round() / 100.0)
}
