//! `coil-thermal codegen`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;

use crate::codegen::{
    generate, generate_grid, generate_omnimagnet_with, CodegenRequest, OmniCodegen,
};

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

/// `codegen` arguments: a model file (solved by a generator compiled
/// against the coil-thermal library's source with cargo, see
/// [`crate::codegen::generate`]) or a built-in device.
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
    /// The coil-thermal library's source to solve with: a directory holding
    /// coil-thermal's Cargo.toml (default: the source tree this tool was
    /// built from).
    #[arg(long, value_name = "DIR")]
    library: Option<PathBuf>,
    /// Where the generator is built, in DIR/coil-thermal-codegen (default:
    /// $CARGO_TARGET_DIR/coil-thermal-codegen, else
    /// $XDG_CACHE_HOME/coil-thermal/codegen, else
    /// $HOME/.cache/coil-thermal/codegen, else the system's temp
    /// directory; never the library's own `target`).
    #[arg(long, value_name = "DIR")]
    target_dir: Option<PathBuf>,
    /// With `--device omnimagnet`: the thermocouples fitted, by index 0-5
    /// (default all six; `0,2,4` is one per solenoid, which needs
    /// `--model-refresh-s`).
    #[arg(long, value_name = "J,...", value_delimiter = ',')]
    thermocouples: Vec<usize>,
    /// With `--device omnimagnet`: the period \[s\] of the firmware's
    /// model refresh (`OmniSettings::model_refresh_s`: a background task
    /// re-linearising the model, watched by the observer), at most 30 s.
    #[arg(long, value_name = "S")]
    model_refresh_s: Option<f64>,
}

/// Runs `codegen`.
pub fn run(a: CodegenArgs) -> Result<()> {
    let (text, source) = match (a.device, a.model) {
        (Some(Device::Omnimagnet), _) => {
            let mut choice = OmniCodegen {
                model_refresh_s: a.model_refresh_s,
                ..OmniCodegen::default()
            };
            if !a.thermocouples.is_empty() {
                choice.thermocouples = [false; coil_thermal::omnimagnet::THERMOCOUPLES];
                for j in &a.thermocouples {
                    let Some(fitted) = choice.thermocouples.get_mut(*j) else {
                        anyhow::bail!(
                            "--thermocouples: the Omnimagnet has thermocouples 0 to {}, got {j}",
                            coil_thermal::omnimagnet::THERMOCOUPLES - 1
                        );
                    };
                    *fitted = true;
                }
            }
            (
                generate_omnimagnet_with(&choice)?,
                "the Omnimagnet".to_string(),
            )
        }
        (Some(Device::HppaGrid), _) => {
            if !a.thermocouples.is_empty() || a.model_refresh_s.is_some() {
                anyhow::bail!("--thermocouples and --model-refresh-s are for --device omnimagnet");
            }
            (generate_grid()?, "the HPPA grid".to_string())
        }
        (None, Some(model)) => {
            if !a.thermocouples.is_empty() || a.model_refresh_s.is_some() {
                anyhow::bail!(
                    "--thermocouples and --model-refresh-s are for --device omnimagnet; \
                     a model file names its sensors in `[observer] sensors` (or --sensor NODE) \
                     and its network observer needs no model refresh"
                );
            }
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
