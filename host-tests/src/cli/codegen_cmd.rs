//! `coil-thermal codegen`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use crate::codegen::{generate, CodegenRequest};

/// `codegen` arguments.
#[derive(Debug, Args)]
pub struct CodegenArgs {
    /// The model file (TOML, with an `[observer]` table naming the sensors;
    /// see host-tests/MODEL_FORMAT.md).
    #[arg(long, value_name = "FILE.toml")]
    model: PathBuf,
    /// Where to write the module (`-`: stdout).
    #[arg(long, value_name = "FILE.rs")]
    out: PathBuf,
    /// The node a thermocouple measures (repeat, in sensor order); overrides
    /// `[observer] sensors`.
    #[arg(long = "sensor", value_name = "NODE")]
    sensors: Vec<String>,
    /// The coil-thermal library to solve with (default: the one this tool
    /// was built from).
    #[arg(long, value_name = "DIR")]
    library: Option<PathBuf>,
    /// Cargo target directory for the generator (default: $CARGO_TARGET_DIR,
    /// else the library's `target`).
    #[arg(long, value_name = "DIR")]
    target_dir: Option<PathBuf>,
}

/// Runs `codegen`.
pub fn run(a: CodegenArgs) -> Result<()> {
    let text = generate(&CodegenRequest {
        model: a.model.clone(),
        sensors: a.sensors,
        library: a.library,
        target_dir: a.target_dir,
    })?;
    if a.out.as_os_str() == "-" {
        print!("{text}");
    } else {
        std::fs::write(&a.out, &text)
            .with_context(|| format!("{}: cannot write", a.out.display()))?;
        eprintln!(
            "{}: the observer of {} ({} lines)",
            a.out.display(),
            a.model.display(),
            text.lines().count()
        );
    }
    Ok(())
}
