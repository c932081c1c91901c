//! Host-side (std) tooling for `coil-thermal`: the `coil-thermal` command-line
//! tool and the pieces it is built from.
//!
//! Layers, bottom up:
//!
//! * [`dynamic_network`]: the run-time description of a model file's
//!   network (it computes nothing: every step runs in the library, at the
//!   model's own size);
//! * [`model_file`]: the TOML model format (`MODEL_FORMAT.md`) and its
//!   validated, index-resolved [`model_file::Model`];
//! * [`trace`]: strict CSV traces with `file:line:col` errors and column
//!   expressions;
//! * [`sim`]: the [`sim::Plant`] trait (file models now; grid and Omnimagnet
//!   later), input bindings and open-loop simulation;
//! * [`observer`]: replay with an [`observer::Estimator`] and a
//!   [`observer::Protection`] stage, scoring and step timing;
//! * [`grid_firmware`], [`omni_firmware`]: `replay --model hppa` and `--model
//!   omnimagnet` through the observers the firmware flashes for them;
//! * [`library_observer`]: the library's network observer at 1 ms ticks on
//!   a model file at its own size (the replay's estimator);
//! * [`calibrate`]: bounded Levenberg-Marquardt over named parameters;
//! * [`plot`], [`bench`](mod@bench): figures and per-step timings;
//! * [`synth`]: seeded synthetic traces for tests;
//! * [`traces`]: the generator of the committed synthetic HPPA current traces;
//! * [`grid_reference`]: an independent dense f64 reference for the coil grid;
//! * [`limits`](mod@limits): time to limit, safe and runaway currents of any network, at its own size;
//! * [`devices`]: the HPPA grid and the Omnimagnet as plants and model files;
//! * [`faults`]: issue 17's fault campaign (every fault class x sensor x
//!   onset against the clean run);
//! * [`codegen`]: a model file to a firmware module with the observer's
//!   tables solved on the host;
//! * [`cli`]: the command-line front end.

pub mod alloc_count;
pub mod bench;
pub mod calibrate;
pub mod cli;
pub mod codegen;
pub mod devices;
pub mod dynamic_network;
pub mod faults;
pub mod firmware;
pub mod grid_firmware;
pub mod grid_reference;
pub mod library_observer;
pub mod limits;
pub mod margin;
pub mod model_file;
pub mod observer;
pub mod omni_firmware;
pub mod plot;
pub mod raw_sensors;
pub mod sensor_kinds;
pub mod sim;
pub mod synth;
pub mod trace;
pub mod traces;
