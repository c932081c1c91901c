//! What the subcommands share: model dispatch, flag parsing, sensors.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use coil_thermal::SolenoidParams;

use super::{ModelArgs, TraceArgs};
use crate::model_file::{Model, ModelFile};
use crate::observer::Sensor;
use crate::sim::{Bindings, FilePlant, Plant, PlantInfo};
use crate::trace::{ColumnExpr, Trace};

/// Marker text of every "not yet available" error (tests look for it).
pub const NOT_YET: &str = "not yet available";

/// The model named by `--model`.
#[derive(Debug, Clone, PartialEq)]
pub enum ModelSpec {
    /// The HPPA coil grid (`src/grid`, stage 2).
    Hppa,
    /// The Omnimagnet (`src/omnimagnet`, stage 2).
    Omnimagnet,
    /// The layered solenoid of `coil_thermal::solenoid`.
    Solenoid,
    /// A model file.
    File(PathBuf),
}

impl ModelSpec {
    /// Parses `--model`: a built-in name or an existing file.
    pub fn parse(text: &str) -> Result<Self> {
        Ok(match text {
            "hppa" => Self::Hppa,
            "omnimagnet" => Self::Omnimagnet,
            "solenoid" => Self::Solenoid,
            path => {
                let p = PathBuf::from(path);
                if !p.is_file() {
                    bail!(
                        "unknown model `{path}`: not one of hppa, omnimagnet, solenoid, and no such model file"
                    );
                }
                Self::File(p)
            }
        })
    }
}

fn not_yet(what: &str, module: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "model `{what}` is {NOT_YET} in this build: it arrives with `{module}` (stage 2); use --model solenoid or a model file"
    )
}

/// The model as a model file (every model a file can describe).
pub fn model_file(args: &ModelArgs) -> Result<ModelFile> {
    match ModelSpec::parse(&args.model)? {
        ModelSpec::Hppa => Err(not_yet("hppa", "src/grid")),
        ModelSpec::Omnimagnet => Err(not_yet("omnimagnet", "src/omnimagnet")),
        ModelSpec::Solenoid => ModelFile::solenoid(&SolenoidParams::HESE, args.layers),
        ModelSpec::File(p) => ModelFile::load(&p),
    }
}

/// The model as a runnable plant. Stage 2 adds the grid and Omnimagnet
/// plants here (their library steppers behind [`Plant`]).
pub fn plant(args: &ModelArgs) -> Result<Box<dyn Plant>> {
    let file = model_file(args)?;
    Ok(Box::new(FilePlant::new(Model::build(&file)?)))
}

/// Splits `LEFT=RIGHT` at the last `=`.
pub fn split_mapping<'a>(text: &'a str, flag: &str, form: &str) -> Result<(&'a str, &'a str)> {
    match text.rsplit_once('=') {
        Some((l, r)) if !l.trim().is_empty() && !r.trim().is_empty() => Ok((l.trim(), r.trim())),
        _ => bail!("{flag} `{text}`: expected {form}"),
    }
}

/// The trace bindings from the flags.
pub fn bindings(args: &TraceArgs) -> Result<Bindings> {
    let mut b = Bindings::default();
    for c in &args.currents {
        let (e, input) = split_mapping(c, "--current", "EXPR=INPUT")?;
        b.currents.push((
            ColumnExpr::parse(e).with_context(|| format!("--current `{c}`"))?,
            input.into(),
        ));
    }
    for c in &args.boundaries {
        let (e, name) = split_mapping(c, "--boundary", "EXPR=BOUNDARY")?;
        b.boundaries.push((
            ColumnExpr::parse(e).with_context(|| format!("--boundary `{c}`"))?,
            name.into(),
        ));
    }
    for c in &args.constants {
        let (col, v) = split_mapping(c, "--const", "COL=VALUE")?;
        let value: f64 = v
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .with_context(|| format!("--const `{c}`: `{v}` is not a finite number"))?;
        b.constants.push((col.into(), value));
    }
    Ok(b)
}

/// Reads a trace with the sample period flag.
pub fn read_trace(path: &Path, sample_period_s: Option<f64>) -> Result<Trace> {
    Ok(Trace::read(path, sample_period_s)?)
}

/// Resolves `COL=NODE` flags to sensors on `trace`.
pub fn sensors(
    flags: &[String],
    flag: &str,
    info: &PlantInfo,
    trace: &Trace,
) -> Result<Vec<Sensor>> {
    flags
        .iter()
        .map(|m| {
            let (col, node) = split_mapping(m, flag, "COL=NODE")?;
            let index = info.nodes.iter().position(|n| n == node).with_context(|| {
                format!(
                    "{flag} `{m}`: model `{}` has no node `{node}` (nodes: {})",
                    info.name,
                    info.nodes.join(", ")
                )
            })?;
            let expr = ColumnExpr::parse(col).with_context(|| format!("{flag} `{m}`"))?;
            let values_c = trace
                .eval(&expr)
                .map_err(|e| anyhow::anyhow!("{e} (for {flag} {m})"))?;
            Ok(Sensor {
                column: col.to_string(),
                node: index,
                values_c,
            })
        })
        .collect()
}

/// Prints a JSON value as one line on stdout.
pub fn print_json(value: &serde_json::Value) {
    println!(
        "{}",
        serde_json::to_string(value).expect("JSON values serialise")
    );
}
