//! The device's thermal model: the network of `model.toml` (winding,
//! housing, heatsink, one current, a thermocouple on the housing) and its
//! observer.
//!
//! Written by hand until `coil-thermal codegen --model model.toml --out
//! src/model.rs` generates it; the firmware uses only the items below, so
//! the generated file replaces this one without other changes. This version
//! builds the observer on the MCU with the library's builder (discretisation
//! and a small Riccati solve in `f64`, a few KiB of stack, once at start).

use coil_thermal::observer::network::{
    NetworkInputs, NetworkObserver, NetworkObserverBuilder, NetworkObserverState,
};
use coil_thermal::{BuildError, Network, Resistance};

/// Nodes: winding, housing, heatsink.
pub const NODES: usize = 3;
/// Boundaries: the ambient.
pub const BOUNDARIES: usize = 1;
/// Current inputs: the winding's.
pub const CURRENTS: usize = 1;
/// Filter states: the nodes, then one heat-input bias per current.
pub const STATES: usize = NODES + CURRENTS;
/// Thermocouples: one, on the housing.
pub const SENSORS: usize = 1;

/// The observer of this device.
pub type Observer = NetworkObserver<NODES, BOUNDARIES, CURRENTS, STATES, SENSORS>;
/// Its per-device state.
pub type State = NetworkObserverState<NODES, BOUNDARIES, CURRENTS, STATES, SENSORS>;
/// The inputs of one tick.
pub type Inputs = NetworkInputs<BOUNDARIES, CURRENTS, SENSORS>;

/// The node names, in the order of `model.toml` (and of every node array).
pub const NODE_NAMES: [&str; NODES] = ["winding", "housing", "heatsink"];

/// Builds the observer (solves the filter's steady gain: call once, at
/// start, not in the 1 ms loop).
///
/// # Errors
/// What the network or the observer builder refuses (none for this model).
pub fn observer() -> Result<Observer, BuildError> {
    let network: Network<NODES, BOUNDARIES, CURRENTS> =
        Network::new([4.0, 60.0, 300.0])? // J/K
            .connect(0, 1, 1.0)? // winding - housing, W/K
            .connect(1, 2, 2.0)? // housing - heatsink
            .connect_boundary(2, 0, 1.5)? // heatsink - ambient
            .joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0))?; // ohm at 20 degC
    NetworkObserverBuilder::new(&network, [1]) // thermocouple 0 on the housing
        .critical_c([Some(130.0), Some(80.0), None]) // degC
        .build()
}

/// A state with every node and the boundary at `ambient_c` \[degC\].
pub fn initial_state(observer: &Observer, ambient_c: f32) -> State {
    observer.state(&[ambient_c; NODES], &[ambient_c; BOUNDARIES])
}
