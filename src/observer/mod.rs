//! Into the controller: the pieces that put the models in a 1 ms loop.
//!
//! * [`clock`]: the measured elapsed time, in integer microseconds, turned
//!   into whole model steps with the remainder carried (jitter, late and
//!   missed ticks), bounded per tick;
//! * [`shared`]: outputs published to lower-priority tasks and readings
//!   handed in from them through `critical-section`, no lock held longer than
//!   a copy;
//! * [`grid`]: one observer per coil grid (model, alarms, limiter, time to
//!   limit) behind `tick(inputs) -> outputs`;
//! * [`omnimagnet`]: the same for an Omnimagnet (the 19-state steady-state
//!   Kalman observer fed by thermocouples, protection), with re-linearised
//!   models made off the tick and installed between ticks;
//! * [`network`]: the same for any [`Network`](crate::Network) you build
//!   (your own actuator): steady-state Kalman filter on the sensors you
//!   name, heat-input biases, `f32` without drift, a limiter that derates
//!   every current heating a limited element;
//! * all protect on an upper bound of each element's temperature, not on
//!   the mean estimate: the estimate plus a model-uncertainty margin (and,
//!   for the filtered Omnimagnet, `k sigma`), see
//!   [`crate::protect::margin`]; the outputs carry both;
//! * [`snapshot`]: warm restart from a versioned, CRC-checked byte buffer, and
//!   the conservative start when a snapshot is refused;
//! * [`vocabulary`]: what every observer speaks (a timed sample, what
//!   became of it, the event queue's capacity), owned by no device;
//! * [`start`]: safe from the first tick without a history (the start's
//!   covariance, held by the filter and by the upper bound until it
//!   settles) and the restore whose off time only the sensors know.
//!
//! The modules import each other in layers, with no cycle: the
//! vocabulary and the clock below the shared rules (the consistency
//! screens, the protection cycle, the tables), those below the three
//! observers; and nothing here is imported by the layers under the
//! observers (`discretize`, `filter`, `protect`, ...). The host test
//! `module_layers` reads the source and holds this.

pub mod clock;
mod consistency;
mod cycle;
pub mod grid;
pub mod network;
pub mod omnimagnet;
pub mod shared;
pub mod snapshot;
pub mod start;
mod tables;
pub mod vocabulary;
pub mod warm_up;

pub use clock::{
    ClockState, StepClock, TickSteps, DEFAULT_FROZEN_FLAG_TICKS, DEFAULT_FROZEN_LOSS_TICKS,
};
pub use grid::{
    GridInputs, GridObserver, GridObserverState, GridOutputs, GridParts, ProtectionPlan,
    PROTECTION_TICKS,
};
pub use network::{
    NetworkInputs, NetworkInputsOf, NetworkObserver, NetworkObserverBuilder, NetworkObserverOf,
    NetworkObserverState, NetworkObserverStateOf, NetworkOutputs, NetworkOutputsOf,
    NetworkSettings, ObserverAllocator,
};
pub use omnimagnet::{OmniInputs, OmniObserver, OmniObserverState, OmniOutputs, OmniSettings};
pub use shared::{Mailbox, Shared};
pub use snapshot::{
    conservative_start, restore, save, Fingerprint, RestorePolicy, SnapshotError, SnapshotMeta,
};
pub use tables::{AlarmTables, ChecksTables, ClockTables, KalmanTables, LimiterTables, StepTables};
pub use vocabulary::{
    ConstOutputs, FilteredOutputs, SensorChecks, SensorStatus, TimedReading, EVENT_CAPACITY,
};
