//! A model file's network copied into a const-generic `Network<P, 2, P>`
//! of a size class `P`, for the one host user of a const-generic observer
//! left: the fault campaign ([`crate::faults`], whose subjects start and
//! restore, which the library's observer does at `Const` sizes only so
//! far). Everything else runs at the model's own size: the network
//! observer ([`crate::library_observer`]), the steady state, the
//! time-to-limit predictor and the safe and runaway currents
//! ([`crate::limits`]). Padding nodes (capacity 1 J/K, decaying to boundary 0 or
//! isolated) are not connected to the real nodes, so they change no real
//! temperature, mode or limit; padding sources carry no current.

use anyhow::Result;
use coil_thermal::{Network, Resistance};

use crate::dynamic_network::DynNetwork;

/// Runs `job` on a thread with a large stack: the padded matrices of the
/// larger size classes live on the stack while they are built (256 MiB).
pub fn on_big_stack<R: Send + 'static>(
    what: &str,
    job: impl FnOnce() -> Result<R> + Send + 'static,
) -> Result<R> {
    std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(job)?
        .join()
        .map_err(|_| anyhow::anyhow!("{what}: the computation panicked"))?
}

pub(crate) fn lib_err(what: &str) -> impl Fn(coil_thermal::BuildError) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("padded network: {what}: {e}")
}

/// How [`padded_with`] fills the padding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Padding {
    /// Padding nodes get 1 W/K to boundary 0 (a 1 s decay: what a modal
    /// predictor or an exact discretisation wants); `false` leaves them
    /// isolated (rate 0: what an explicit step of any length wants).
    pub link_to_boundary: bool,
    /// Every real source's resistance is multiplied by this (the host
    /// then feeds currents divided by its square root: the same power).
    pub resistance_scale: f64,
}

impl Padding {
    /// Padding nodes decaying to boundary 0, resistances as given.
    pub const DECAYING: Self = Self {
        link_to_boundary: true,
        resistance_scale: 1.0,
    };
    /// Isolated padding nodes, resistances as given.
    pub const ISOLATED: Self = Self {
        link_to_boundary: false,
        resistance_scale: 1.0,
    };
}

/// The padded library network of a dynamic one (see the module docs),
/// the padding chosen by `padding`.
pub fn padded_with<const P: usize>(net: &DynNetwork, padding: Padding) -> Result<Network<P, 2, P>> {
    let n = net.nodes();
    let mut caps = [1.0; P];
    caps[..n].copy_from_slice(net.capacities_j_per_k());
    let mut lib = Network::new(caps).map_err(lib_err("capacities"))?;
    for p in net.pairs() {
        lib = lib
            .connect(p.a, p.b, p.g_w_per_k)
            .map_err(lib_err("conductance"))?;
    }
    for l in net.links() {
        lib = lib
            .connect_boundary(l.node, l.boundary, l.g_w_per_k)
            .map_err(lib_err("boundary conductance"))?;
    }
    if padding.link_to_boundary {
        for i in n..P {
            lib = lib
                .connect_boundary(i, 0, 1.0)
                .map_err(lib_err("padding"))?;
        }
    }
    let k = padding.resistance_scale;
    for (m, s) in net.sources().iter().enumerate() {
        let r = Resistance {
            r_at_0c_ohm: s.resistance.r_at_0c_ohm * k,
            slope_ohm_per_k: s.resistance.slope_ohm_per_k * k,
        };
        lib = lib.joule_source(m, s.node, r).map_err(lib_err("source"))?;
    }
    // Padding sources (no current, ever) sit on a node that already holds
    // a winding, so that padding makes no node a winding's node: the
    // library's predictor skips a node without a limit unless a winding
    // is on it, and the padded observer's sweeps are then the model's own.
    let spare = match net.sources().first() {
        Some(s) => s.node,
        None if n < P => n,
        None => 0,
    };
    for m in net.sources().len()..P {
        lib = lib
            .joule_source(m, spare, Resistance::constant(1.0))
            .map_err(lib_err("padding source"))?;
    }
    for (i, p) in net.fixed_powers_w().iter().enumerate() {
        if *p != 0.0 {
            lib = lib.fixed_power(i, *p).map_err(lib_err("fixed power"))?;
        }
    }
    Ok(lib)
}
