//! `coil-thermal codegen --device`: the reference devices, whose
//! observers have fixed sizes, solved in this process and written with a
//! `static OBSERVER` the compiler assembles (`from_parts` is a `const fn`):
//! the configuration in flash, nothing built on the target.
//!
//! * `omnimagnet`: `OmniObserver::new` with [`omnimagnet_settings`]
//!   (`examples/generated/omnimagnet.rs`, [`OMNIMAGNET_COMMAND`]);
//! * `hppa-grid`: the 84-coil grid observer with its protection plan
//!   (`examples/generated/hppa_grid.rs`, [`GRID_COMMAND`]).

use std::fmt::Write as _;

use anyhow::Result;

use super::rustfmt;

/// The command that writes [`OMNIMAGNET_FILE`] (printed by the round-trip
/// test when the committed file is stale).
pub const OMNIMAGNET_COMMAND: &str =
    "cargo run --release -p coil-thermal-host --bin coil-thermal -- codegen --device omnimagnet --out examples/generated/omnimagnet.rs";

/// Where the generated Omnimagnet observer is committed, from the
/// workspace root.
pub const OMNIMAGNET_FILE: &str = "examples/generated/omnimagnet.rs";

/// The operating point and ambient of the generated Omnimagnet observer
/// \[degC\] (`examples/observer_m4.rs`'s).
pub const OMNIMAGNET_AMBIENT_C: f64 = 22.0;

/// The settings of the generated Omnimagnet observer, `examples/observer_m4.rs`'s:
/// the defaults with a 5 ms model step (the fastest node's time constant
/// is 0.25 s, the solenoids' minutes) on the mean `I^2` of its ticks, one
/// step of catch-up per tick (5 ms of late time), and limits and times to
/// limit every 40 ms (8 steps, a multiple of the grid's 20 ms update),
/// 5 ms (1 step) after its boundary: the two predictor slices, the alarm
/// and the limiter then run about 5 ms after a grid update, among the
/// ticks where the grid prepares the next update's rows (1 to 7 after
/// one) and runs no protection stage. At 2 steps (10 ms) the slices met
/// the grid's protection stages (from tick 8): `observer_m4`'s combined
/// worst was 6 361 instructions, 5 648 at 1 step.
/// Five nodes per slice keep every slice under 4 000 instructions
/// (`docs/cost.md`).
pub fn omnimagnet_settings() -> coil_thermal::observer::omnimagnet::OmniSettings {
    coil_thermal::observer::omnimagnet::OmniSettings {
        step_us: 5_000,
        max_steps_per_tick: 1,
        protect_period_steps: 8,
        protect_phase_steps: 1,
        predictor_slices_per_cycle: 2,
        predictor_nodes_per_slice: 5,
        ..Default::default()
    }
}

/// What `codegen --device omnimagnet` may change of
/// [`omnimagnet_settings`]: the thermocouples fitted and the firmware's
/// declared model refresh (`OmniSettings::model_refresh_s`), which a
/// sensor set that leaves a solenoid with one thermocouple needs. The
/// default (all six, no refresh) is `examples/observer_m4.rs`'s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OmniCodegen {
    /// Which of the six thermocouples are fitted.
    pub thermocouples: [bool; coil_thermal::omnimagnet::THERMOCOUPLES],
    /// The declared re-linearisation period \[s\] (`None`: none).
    pub model_refresh_s: Option<f64>,
}

impl Default for OmniCodegen {
    fn default() -> Self {
        Self {
            thermocouples: [true; coil_thermal::omnimagnet::THERMOCOUPLES],
            model_refresh_s: None,
        }
    }
}

impl OmniCodegen {
    /// The command line's options for this choice (empty for the default).
    fn options(&self) -> String {
        let mut o = String::new();
        if self.thermocouples.iter().any(|f| !f) {
            let on: Vec<String> = (0..self.thermocouples.len())
                .filter(|j| self.thermocouples[*j])
                .map(|j| j.to_string())
                .collect();
            let _ = write!(o, " --thermocouples {}", on.join(","));
        }
        if let Some(r) = self.model_refresh_s {
            let _ = write!(o, " --model-refresh-s {r}");
        }
        o
    }
}

/// The Omnimagnet observer built on the host as `new` builds it
/// ([`Omnimagnet::PAPER`](coil_thermal::omnimagnet::Omnimagnet::PAPER) at
/// [`OMNIMAGNET_AMBIENT_C`], [`omnimagnet_settings`]).
///
/// # Errors
/// A refusal of the library's builder.
pub fn omnimagnet_observer() -> Result<coil_thermal::observer::omnimagnet::OmniObserver> {
    omnimagnet_observer_with(&OmniCodegen::default())
}

/// [`omnimagnet_observer`] with the thermocouples and the model refresh
/// of `choice`.
///
/// # Errors
/// A refusal of the library's builder (a sensor set that needs a model
/// refresh without one, or with a period above the library's bound:
/// `BuildError::ModelRefreshRequired`, which names the solenoid).
pub fn omnimagnet_observer_with(
    choice: &OmniCodegen,
) -> Result<coil_thermal::observer::omnimagnet::OmniObserver> {
    use coil_thermal::omnimagnet::{Omnimagnet, NODES};
    let defaults = omnimagnet_settings();
    let settings = coil_thermal::observer::omnimagnet::OmniSettings {
        filter: coil_thermal::omnimagnet::observer::ObserverSettings {
            sensors: choice.thermocouples,
            ..defaults.filter
        },
        model_refresh_s: choice.model_refresh_s,
        ..defaults
    };
    coil_thermal::observer::omnimagnet::OmniObserver::new(
        &Omnimagnet::PAPER,
        &[OMNIMAGNET_AMBIENT_C; NODES],
        OMNIMAGNET_AMBIENT_C,
        &settings,
    )
    .map_err(|e| anyhow::anyhow!("the Omnimagnet observer: {e}"))
}

/// `coil-thermal codegen --device omnimagnet`: the Omnimagnet observer of
/// [`omnimagnet_observer`] as a `no_std` module whose `static OBSERVER` is
/// assembled by the compiler
/// ([`OmniObserver::from_parts`](coil_thermal::observer::omnimagnet::OmniObserver::from_parts)
/// is a `const fn`): the configuration in flash, nothing built on the
/// target. The sizes are fixed, so no generator program is compiled: the
/// library solves it in this process.
///
/// # Errors
/// A refusal of the library's builder.
pub fn generate_omnimagnet() -> Result<String> {
    generate_omnimagnet_with(&OmniCodegen::default())
}

/// [`generate_omnimagnet`] with the thermocouples and the model refresh of
/// `choice` (`codegen --device omnimagnet --thermocouples J,...
/// --model-refresh-s S`); the default writes the committed module.
///
/// # Errors
/// A refusal of the library's builder (see [`omnimagnet_observer_with`]).
pub fn generate_omnimagnet_with(choice: &OmniCodegen) -> Result<String> {
    let observer = omnimagnet_observer_with(choice)?;
    let s = omnimagnet_settings();
    let options = choice.options();
    let device = format!("omnimagnet{options}");
    let command = format!("{OMNIMAGNET_COMMAND}{options}");
    let about = format!(
        "//! The Omnimagnet observer of `examples/observer_m4.rs` (`Omnimagnet::PAPER`\n\
         //! linearised at {ambient} degC, ambient {ambient} degC, a {step} us model step,\n\
         //! protection every {period} steps with phase {phase} in {slices} predictor slices,\n\
         //! the other settings as `omnimagnet_settings` in `host-tests/src/codegen.rs`),\n",
        ambient = OMNIMAGNET_AMBIENT_C,
        period = s.protect_period_steps,
        phase = s.protect_phase_steps,
        step = s.step_us,
        slices = s.predictor_slices_per_cycle,
    );
    flash_module(&FlashModule {
        about: &about,
        command: &command,
        device: &device,
        assembly: "OmniObserver::from_parts",
        imports: "coil_thermal::observer::omnimagnet::{OmniObserver, OmniParts}",
        parts_type: "OmniParts",
        parts_doc: "Every table of the observer, solved on the host in `f64` and rounded\n/// once to `f32`.",
        observer_type: "OmniObserver",
        what: "Omnimagnet",
        write: &|o| observer.parts().write_rust(o),
    })
}

/// A generated module holding one observer's parts and the `static`
/// the compiler assembles from them.
struct FlashModule<'a> {
    /// The module docs' opening lines (`//!`), what the observer is.
    about: &'a str,
    /// The command that writes the module.
    command: &'a str,
    /// `--device`'s value.
    device: &'a str,
    /// The `const fn` that assembles the parts.
    assembly: &'a str,
    /// What the module imports (a `use` path).
    imports: &'a str,
    parts_type: &'a str,
    /// The parts' doc comment (after the first `/// `).
    parts_doc: &'a str,
    observer_type: &'a str,
    /// The device, in the panic message of parts that do not assemble.
    what: &'a str,
    /// Writes the parts' expression.
    write: &'a dyn Fn(&mut String) -> std::fmt::Result,
}

fn flash_module(m: &FlashModule<'_>) -> Result<String> {
    let mut o = String::new();
    let _ = write!(
        o,
        "{about}\
         //! generated by\n\
         //! `coil-thermal codegen --device {device}`. Do not edit: generate again with\n\
         //! `{command}`.\n\
         //!\n\
         //! [`OBSERVER`] is a `static` the compiler assembles from [`PARTS`]\n\
         //! (`{assembly}` is a `const fn`): the configuration is\n\
         //! in flash and never built on the target; only the state is in RAM.\n\n\
         #![allow(\n    dead_code,\n    clippy::approx_constant,\n    clippy::excessive_precision,\n    clippy::unreadable_literal\n)]\n\n\
         use {imports};\n\n\
         /// {parts_doc}\n\
         pub const PARTS: {parts_type} = ",
        about = m.about,
        device = m.device,
        command = m.command,
        assembly = m.assembly,
        imports = m.imports,
        parts_doc = m.parts_doc,
        parts_type = m.parts_type,
    );
    (m.write)(&mut o).map_err(|_| anyhow::anyhow!("formatting the parts"))?;
    let _ = write!(
        o,
        ";\n\n/// The observer, assembled by the compiler (a bad table is a compile\n\
         /// error): in flash.\n\
         pub static OBSERVER: {observer_type} = match {assembly}(&PARTS) {{\n    \
         Ok(observer) => observer,\n    \
         Err(_) => panic!(\"the generated {what} parts do not assemble\"),\n}};\n",
        observer_type = m.observer_type,
        assembly = m.assembly,
        what = m.what,
    );
    Ok(rustfmt(&o).unwrap_or(o))
}

/// The command that writes [`GRID_FILE`] (printed by the round-trip test
/// when the committed file is stale).
pub const GRID_COMMAND: &str =
    "cargo run --release -p coil-thermal-host --bin coil-thermal -- codegen --device hppa-grid --out examples/generated/hppa_grid.rs";

/// Where the generated HPPA grid observer is committed, from the workspace
/// root.
pub const GRID_FILE: &str = "examples/generated/hppa_grid.rs";

/// The generated grid observer's type: the 7 x 12 HPPA in `f32`.
pub type HppaGridObserver = coil_thermal::observer::GridObserver<f32, 7, 12, 84>;

/// Grid updates every this many 1 ms ticks (20 ms) in the generated grid
/// observer.
pub const GRID_TICKS_PER_UPDATE: u32 = 20;

/// The generated grid observer's catch-up bound (model steps per tick).
pub const GRID_MAX_STEPS_PER_TICK: u32 = 4;

/// Every coil's hardware current limit in the generated grid observer
/// \[A\].
pub const GRID_HARDWARE_LIMIT_A: f64 = 3.0;

/// The grid's protection in `examples/observer_m4.rs`, in 22 stages, none
/// in a tick that prepares a row of the next update (ticks 1 to 7 after
/// one): 12 stages per 20 ms update interval, no grid tick above about
/// 3 900 instructions; a pass takes about 37 ms, passes run back to back,
/// and the limits lag the model by at most two passes (about 80 ms; the
/// fastest coil time constant is seconds).
pub const GRID_PLAN: coil_thermal::observer::ProtectionPlan =
    coil_thermal::observer::ProtectionPlan {
        bound_parts: 2,
        time_to_limit_parts: 6,
        alarm_parts: 8,
        limiter_parts: 6,
        wait_for_rows: true,
    };

/// The HPPA grid observer of `examples/observer_m4.rs`, built on the host
/// as `new` builds it: the default [`GridConfig`](coil_thermal::GridConfig)
/// (the report's FDM fit, herringbone stencil, ambient padding, 1 ms
/// ticks) updated every [`GRID_TICKS_PER_UPDATE`] ticks, the HPPA derating
/// of [`HPPA_CRITICAL_C`](coil_thermal::protect::derating::HPPA_CRITICAL_C)
/// on every coil, a limiter at [`GRID_HARDWARE_LIMIT_A`] with a 10 K taper
/// and no floor, at most [`GRID_MAX_STEPS_PER_TICK`] steps per tick, the
/// default margin, and [`GRID_PLAN`].
///
/// # Errors
/// A refusal of the library's builders.
pub fn grid_observer() -> Result<HppaGridObserver> {
    use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
    grid_observer_with(&DeratingRule::hppa(), HPPA_CRITICAL_C)
}

/// [`grid_observer`] with the alarm of `rule` on every coil's critical
/// temperature `critical_c` \[degC\] (`replay --factors`, `--critical-c`).
///
/// # Errors
/// A refusal of the library's builders.
pub fn grid_observer_with(
    rule: &coil_thermal::protect::derating::DeratingRule,
    critical_c: f64,
) -> Result<HppaGridObserver> {
    use coil_thermal::protect::alarm::AlarmBuilder;
    use coil_thermal::protect::limiter::LimiterConfig;
    let config = coil_thermal::GridConfig {
        ticks_per_update: GRID_TICKS_PER_UPDATE,
        ..coil_thermal::GridConfig::default()
    };
    let alarm = AlarmBuilder::new(rule, [critical_c; 84])
        .build::<f32>()
        .map_err(|e| anyhow::anyhow!("the grid's alarm: {e}"))?;
    let limiter = LimiterConfig::new([GRID_HARDWARE_LIMIT_A; 84], 10.0, 0.0)
        .map_err(|e| anyhow::anyhow!("the grid's limiter: {e}"))?;
    HppaGridObserver::new(&config, alarm, limiter, GRID_MAX_STEPS_PER_TICK)
        .and_then(|grid| grid.with_protection_plan(GRID_PLAN))
        .map_err(|e| anyhow::anyhow!("the grid observer: {e}"))
}

/// `coil-thermal codegen --device hppa-grid`: the grid observer of
/// [`grid_observer`] as a `no_std` module whose `static OBSERVER` is
/// assembled by the compiler
/// ([`GridObserver::from_parts`](coil_thermal::observer::GridObserver::from_parts)
/// is a `const fn`): the configuration in flash, nothing built on the
/// target.
///
/// # Errors
/// A refusal of the library's builders.
pub fn generate_grid() -> Result<String> {
    let observer = grid_observer()?;
    let p = GRID_PLAN;
    let about = format!(
        "//! The 84-coil HPPA grid observer of `examples/observer_m4.rs` (the default\n\
         //! `GridConfig` updated every {every} ticks, the HPPA derating on every coil, a\n\
         //! {limit} A limiter, {steps} steps of catch-up per tick, protection in {bound} + {ttl} +\n\
         //! {alarm} + {limiter} stages waiting for the rows: `grid_observer` in\n\
         //! `host-tests/src/codegen.rs`),\n",
        every = GRID_TICKS_PER_UPDATE,
        limit = GRID_HARDWARE_LIMIT_A,
        steps = GRID_MAX_STEPS_PER_TICK,
        bound = p.bound_parts,
        ttl = p.time_to_limit_parts,
        alarm = p.alarm_parts,
        limiter = p.limiter_parts,
    );
    flash_module(&FlashModule {
        about: &about,
        command: GRID_COMMAND,
        device: "hppa-grid",
        assembly: "GridObserver::from_parts",
        imports: "coil_thermal::observer::{GridObserver, GridParts}",
        parts_type: "GridParts<f32, 7, 12, 84>",
        parts_doc: "Every table of the observer, derived on the host in `f64` and rounded\n/// once to `f32`.",
        observer_type: "GridObserver<f32, 7, 12, 84>",
        what: "grid",
        write: &|o| observer.parts().write_rust(o),
    })
}
