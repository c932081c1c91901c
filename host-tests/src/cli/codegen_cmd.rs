//! `coil-thermal codegen`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use crate::codegen::{generate, generate_grid, generate_omnimagnet, CodegenRequest};

/// A built-in device whose observer `codegen` writes without a model file.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Device {
    /// The Omnimagnet (`Omnimagnet::PAPER`) with `examples/observer_m4.rs`'s
    /// settings: a module whose `static OBSERVER` is assembled by the
    /// compiler (the configuration in flash).
    Omnimagnet,
    /// The 84-coil HPPA grid with `examples/observer_m4.rs`'s settings (20 ms
    /// updates, HPPA derating, 3 A limiter, its protection plan): a module
    /// whose `static OBSERVER` is assembled by the compiler.
    HppaGrid,
}

/// `codegen` arguments.
#[derive(Debug, Args)]
pub struct CodegenArgs {
    /// The model file (TOML, with an `[observer]` table naming the sensors;
    /// see host-tests/MODEL_FORMAT.md).
    #[arg(
        long,
        value_name = "FILE.toml",
        required_unless_present = "device",
        conflicts_with = "device"
    )]
    model: Option<PathBuf>,
    /// A built-in device instead of a model file.
    #[arg(long, value_enum)]
    device: Option<Device>,
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
    let (text, source) = match (a.device, a.model) {
        (Some(Device::Omnimagnet), _) => (generate_omnimagnet()?, "the Omnimagnet".to_string()),
        (Some(Device::HppaGrid), _) => (generate_grid()?, "the HPPA grid".to_string()),
        (None, Some(model)) => {
            let text = generate(&CodegenRequest {
                model: model.clone(),
                sensors: a.sensors,
                library: a.library,
                target_dir: a.target_dir,
            })?;
            (text, model.display().to_string())
        }
        (None, None) => anyhow::bail!("codegen needs --model FILE.toml or --device"),
    };
    if a.out.as_os_str() == "-" {
        print!("{text}");
    } else {
        std::fs::write(&a.out, &text)
            .with_context(|| format!("{}: cannot write", a.out.display()))?;
        eprintln!(
            "{}: the observer of {} ({} lines)",
            a.out.display(),
            source,
            text.lines().count()
        );
    }
    Ok(())
}
