//! Thermal runaway: the current above which a winding has no steady state.
//!
//! A winding with `R(T) = r0 + s T`, `s > 0`, at current `I` adds `s I^2`
//! \[W/K\] of *negative* conductance to its node (the steady state solves
//! `(K - s I^2 e_n e_n^T) T = q`, see `network`'s `steady` module). A stable
//! steady state exists while that symmetric matrix stays positive definite.
//! The update is rank one, so with `K_0` the conductance matrix (including
//! the other windings' feedback at their currents)
//!
//! ```text
//! det(K_0 - s I^2 e_n e_n^T) = det(K_0) (1 - s I^2 (K_0^-1)_nn)
//! I_runaway^2 = 1 / (s (K_0^-1)_nn)
//! ```
//!
//! For a single node with conductance `G` to the ambient this is the closed
//! form `I^2 = G / s`. `(K_0^-1)_nn` is the node's thermal resistance to the
//! boundaries \[K/W\]: how far a watt at that node raises it. This is the
//! solenoid note's quasi runaway taken to its limit; long before it, the rise
//! grows much faster than `I^2` (the note's rule of thumb: once the absolute
//! winding temperature has risen by about half the absolute ambient), which
//! is why the hot-spot current of [`hot_spot_current_a`] is the one to
//! design with.
//!
//! Build-time code (`f64`, `O(N^3)`, bounded iterations), for any network
//! description: a [`Network`](crate::network::Network) with arrays and no
//! allocation, or a model file's network at its own size on a host (the
//! `alloc` feature's `RunTimeSizes`).

use super::modal::{conductance_matrix, feedback_w_per_k, symmetric_eigen};
use crate::error::BuildError;
use crate::network::{
    one_winding_steady, steady_state_of, Boundaries, Inputs, NetworkDescription, Nodes,
    OneWindingSteady,
};
use crate::sizes::Sizes;

/// Bisection steps for [`hot_spot_current_a`] (2^-200 of the bracket: the
/// loop stops at `f64` resolution long before).
const BISECTION_STEPS: usize = 200;
/// Doublings of the search bracket from 1 A (up to 2^64 A).
const DOUBLINGS: usize = 64;

/// One winding's runaway figures.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CoilRunaway {
    /// The current \[A\] above which no steady state exists; `None` for a
    /// winding whose resistance does not rise with temperature.
    pub runaway_current_a: Option<f64>,
    /// The current \[A\] above which the steady state passes some element's
    /// limit (or does not exist); `None` if no current does.
    pub hot_spot_current_a: Option<f64>,
}

/// The current \[A\] of winding `coil` above which no steady state exists,
/// with the other windings at `currents_a` (the entry of `coil` is ignored);
/// `None` if its resistance does not rise with temperature.
///
/// # Errors
/// [`BuildError::MissingSource`] for a winding without a source,
/// [`BuildError::NoSteadyState`] if the other windings already run away,
/// [`BuildError::Singular`] if a node has no path to a boundary,
/// [`BuildError::InvalidParameter`] for non-finite currents or not one
/// per input.
pub fn runaway_current_a<W: NetworkDescription>(
    network: &W,
    coil: usize,
    currents_a: &Inputs<W, f64>,
) -> Result<Option<f64>, BuildError> {
    let sizes = network.sizes();
    let source = network
        .joule_source_of(coil)
        .ok_or(BuildError::MissingSource { input: coil })?;
    let currents = currents_a.as_ref();
    if !currents.iter().all(|i| i.is_finite()) || currents.len() != sizes.inputs() {
        return Err(BuildError::InvalidParameter { name: "currents_a" });
    }
    let slope = source.resistance.slope_ohm_per_k;
    // A voltage-driven coil's power falls as it heats: it cannot run away.
    if slope <= 0.0 || source.drive == crate::network::Drive::Voltage {
        return Ok(None);
    }
    let mut others = currents_a.clone();
    if let Some(i) = others.as_mut().get_mut(coil) {
        *i = 0.0;
    }
    let feedback = feedback_w_per_k(network, &others);
    let eigen = symmetric_eigen(sizes, conductance_matrix(network, &feedback))?;
    let values = eigen.values.as_ref();
    let largest = values.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    if !values.iter().all(|&v| v > 1e-12 * largest) {
        let bare = symmetric_eigen(sizes, conductance_matrix(network, &sizes.nodes_of(0.0)))?;
        return Err(
            if bare.values.as_ref().iter().all(|&v| v > 1e-12 * largest) {
                BuildError::NoSteadyState
            } else {
                BuildError::Singular
            },
        );
    }
    let node = source.node;
    let vectors = eigen.vectors.as_ref();
    let row = vectors
        .get(node)
        .ok_or(BuildError::InvalidParameter { name: "network" })?;
    let resistance_k_per_w: f64 = values
        .iter()
        .zip(row.as_ref())
        .map(|(mu, u)| u * u / mu)
        .sum();
    Ok(Some(libm::sqrt(1.0 / (slope * resistance_k_per_w))))
}

/// The current \[A\] of winding `coil` above which the steady state at
/// boundaries `boundary_c` \[degC\] passes some element's limit `limits_c`
/// \[degC\] (`+inf`: no limit) or does not exist, with the other windings at
/// `currents_a`. `Some(0)` if even zero current is too much; `None` if no
/// current is (a winding whose resistance does not rise, heating only
/// elements without limits).
///
/// Bisection on the steady state between zero and the runaway current (or
/// a bracket found by doubling), to `f64` resolution. For a current-driven
/// winding in a network without voltage-driven sources each steady state
/// of the search is a rank-one update of the one at zero current (see the
/// module docs: two solves, then `O(N)` a current); otherwise a full
/// [`steady_state_of`] a current.
///
/// # Errors
/// As [`runaway_current_a`], and [`BuildError::InvalidParameter`] for a NaN
/// limit, non-finite boundary temperatures, or vectors of other lengths
/// than the network's.
pub fn hot_spot_current_a<W: NetworkDescription>(
    network: &W,
    coil: usize,
    currents_a: &Inputs<W, f64>,
    boundary_c: &Boundaries<W, f64>,
    limits_c: &Nodes<W, f64>,
) -> Result<Option<f64>, BuildError> {
    let figures = coil_runaway(network, coil, currents_a, boundary_c, limits_c)?;
    Ok(figures.hot_spot_current_a)
}

/// [`runaway_current_a`] and [`hot_spot_current_a`] of winding `coil` at
/// once: for a current-driven winding in a network without voltage-driven
/// sources both come from two linear solves (the steady state at zero
/// current and the node's response to a watt: the runaway current is
/// `1 / sqrt(s u_n)`, each current of the hot-spot search `O(N)`; the
/// same runaway as the eigen-decomposition's to 1e-9); otherwise from
/// [`runaway_current_a`] and a full steady state a current.
///
/// # Errors
/// As [`hot_spot_current_a`].
pub fn coil_runaway<W: NetworkDescription>(
    network: &W,
    coil: usize,
    currents_a: &Inputs<W, f64>,
    boundary_c: &Boundaries<W, f64>,
    limits_c: &Nodes<W, f64>,
) -> Result<CoilRunaway, BuildError> {
    let limits = limits_c.as_ref();
    if limits.iter().any(|l| l.is_nan()) || limits.len() != network.sizes().nodes() {
        return Err(BuildError::InvalidParameter { name: "limits_c" });
    }
    // A current-driven winding's steady states as a rank-one update of the
    // one at zero current (see `hot_spot_below`) give the runaway too:
    // `(K_0^-1)_nn` is the update's `u_n`, one solve where the
    // eigen-decomposition costs tens of them (`limits` of the 300-node
    // motor with 24 windings: 13.4 -> 2.5 s).
    let one = one_winding_steady(network, coil, currents_a, boundary_c);
    let runaway = match &one {
        Ok(Some(one)) => one.runaway_current_a(),
        _ => runaway_current_a(network, coil, currents_a)?,
    };
    Ok(CoilRunaway {
        runaway_current_a: runaway,
        hot_spot_current_a: hot_spot_below(
            network, coil, currents_a, boundary_c, limits, runaway, one,
        )?,
    })
}

/// The hot-spot current of [`hot_spot_current_a`], bracketed by the
/// winding's `runaway` current (`None`: found by doubling).
fn hot_spot_below<W: NetworkDescription>(
    network: &W,
    coil: usize,
    currents_a: &Inputs<W, f64>,
    boundary_c: &Boundaries<W, f64>,
    limits: &[f64],
    runaway: Option<f64>,
    one: Result<Option<OneWindingSteady<Nodes<W, f64>>>, BuildError>,
) -> Result<Option<f64>, BuildError> {
    // A current-driven winding's steady states as a rank-one update of
    // the one at zero current (`one`, where it applies): `O(N)` a current
    // of the search, not a solve.
    let one = match one {
        Ok(one) => one,
        Err(BuildError::NoSteadyState) => return Ok(Some(0.0)),
        Err(e) => return Err(e),
    };
    let safe = |current: f64| -> Result<bool, BuildError> {
        if let Some(one) = &one {
            return Ok(one.within(current, limits));
        }
        let mut currents = currents_a.clone();
        if let Some(i) = currents.as_mut().get_mut(coil) {
            *i = current;
        }
        match steady_state_of(network, &currents, boundary_c) {
            Ok(t) => Ok(t.as_ref().iter().zip(limits).all(|(t, l)| t <= l)),
            Err(BuildError::NoSteadyState) => Ok(false),
            Err(e) => Err(e),
        }
    };
    if !safe(0.0)? {
        return Ok(Some(0.0));
    }
    let mut high = match runaway {
        Some(i) => i,
        None => {
            let mut high = 1.0;
            let mut found = false;
            for _ in 0..DOUBLINGS {
                if !safe(high)? {
                    found = true;
                    break;
                }
                high *= 2.0;
            }
            if !found {
                return Ok(None);
            }
            high
        }
    };
    let mut low = 0.0;
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (low + high);
        if mid <= low || mid >= high {
            break;
        }
        if safe(mid)? {
            low = mid;
        } else {
            high = mid;
        }
    }
    Ok(Some(low))
}

/// [`runaway_current_a`] and [`hot_spot_current_a`] for every winding, the
/// others at `currents_a` each time.
///
/// # Errors
/// As [`hot_spot_current_a`].
pub fn runaway_report<W: NetworkDescription>(
    network: &W,
    currents_a: &Inputs<W, f64>,
    boundary_c: &Boundaries<W, f64>,
    limits_c: &Nodes<W, f64>,
) -> Result<Inputs<W, CoilRunaway>, BuildError> {
    let mut report = network.sizes().inputs_of(CoilRunaway {
        runaway_current_a: None,
        hot_spot_current_a: None,
    });
    for (coil, entry) in report.as_mut().iter_mut().enumerate() {
        *entry = coil_runaway(network, coil, currents_a, boundary_c, limits_c)?;
    }
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::{Network, Resistance};

    #[test]
    fn single_node_matches_the_closed_form() {
        for (g, slope) in [(0.5, 0.026), (2.0, 0.0125), (0.05, 1e-3)] {
            let network: Network<1, 1, 1> = Network::new([68.7])
                .unwrap()
                .connect_boundary(0, 0, g)
                .unwrap()
                .joule_source(0, 0, Resistance::linear_fit(slope, 5.166))
                .unwrap();
            let i = runaway_current_a(&network, 0, &[0.0]).unwrap().unwrap();
            let want = libm::sqrt(g / slope);
            assert!((i - want).abs() < 1e-12 * want, "{i} vs {want}");
            // Either side of it, as the steady-state solver sees it.
            assert!(network.steady_state(&[0.999 * i], &[20.0]).is_ok());
            assert_eq!(
                network.steady_state(&[1.001 * i], &[20.0]),
                Err(BuildError::NoSteadyState)
            );
        }
        let constant: Network<1, 1, 1> = Network::new([1.0])
            .unwrap()
            .connect_boundary(0, 0, 1.0)
            .unwrap()
            .joule_source(0, 0, Resistance::constant(2.0))
            .unwrap();
        assert_eq!(runaway_current_a(&constant, 0, &[0.0]), Ok(None));
        // 2 ohm, 1 W/K, limit 70 degC at 20 degC: I^2 = 50 / 2.
        let hot = hot_spot_current_a(&constant, 0, &[0.0], &[20.0], &[70.0])
            .unwrap()
            .unwrap();
        assert!((hot - 5.0).abs() < 1e-9, "{hot}");
    }

    /// The solenoid note's layered coil: `L` layers of 1 mm wire on a
    /// 16.7 mm former, former and outer surface water cooled at 16 degC,
    /// neighbouring layers joined through the winding's conductivity
    /// (1.05 W/(m K), the note's fit), per metre of coil length.
    pub(crate) fn layered_coil<const L: usize>(lambda_w_per_m_k: f64) -> Network<L, 1, L> {
        let (r0, dr, w) = (16.7e-3, 1e-3, 1e-3);
        let volumetric_j_per_m3_k = 3.8e6;
        let capacity = core::array::from_fn(|i| {
            let r = r0 + (i as f64 + 0.5) * dr;
            volumetric_j_per_m3_k * 2.0 * core::f64::consts::PI * r * dr
        });
        let mut network = Network::new(capacity).unwrap();
        // Conduction across a cylindrical shell between layer centres.
        let shell = |r_in: f64, r_out: f64| {
            2.0 * core::f64::consts::PI * lambda_w_per_m_k / libm::log(r_out / r_in)
        };
        for i in 0..L - 1 {
            let (ri, ro) = (r0 + (i as f64 + 0.5) * dr, r0 + (i as f64 + 1.5) * dr);
            network = network.connect(i, i + 1, shell(ri, ro)).unwrap();
        }
        network = network
            .connect_boundary(0, 0, shell(r0, r0 + 0.5 * dr))
            .unwrap()
            .connect_boundary(
                L - 1,
                0,
                shell(r0 + (L as f64 - 0.5) * dr, r0 + L as f64 * dr),
            )
            .unwrap();
        // Copper wire 1 mm^2, 1/w turns per metre of each layer.
        let ohm_per_m_20c = 1.72e-8 / 1e-6;
        for i in 0..L {
            let r = r0 + (i as f64 + 0.5) * dr;
            let length_m = 2.0 * core::f64::consts::PI * r / w;
            let resistance = Resistance::with_alpha(ohm_per_m_20c * length_m, 0.0039, 20.0);
            network = network.joule_source(i, i, resistance).unwrap();
        }
        network
    }

    /// The common-current runaway of a layered coil by bisection on the
    /// steady-state solver, as an independent path.
    fn runaway_by_bisection<const L: usize>(network: &Network<L, 1, L>) -> f64 {
        let (mut low, mut high) = (0.0, 1e4);
        for _ in 0..200 {
            let mid = 0.5 * (low + high);
            match network.steady_state(&[mid; L], &[16.0]) {
                Ok(_) => low = mid,
                Err(_) => high = mid,
            }
        }
        low
    }

    #[test]
    fn one_layer_of_a_layered_coil_matches_bisection() {
        // One layer's own runaway with the other layers at a common current:
        // the rank-one closed form against bisection on the solver.
        let network = layered_coil::<16>(1.05);
        let others = 0.6 * runaway_by_bisection(&network);
        let mut currents = [others; 16];
        let i = runaway_current_a(&network, 7, &currents).unwrap().unwrap();
        let (mut low, mut high) = (0.0, 10.0 * i);
        for _ in 0..200 {
            let mid = 0.5 * (low + high);
            currents[7] = mid;
            match network.steady_state(&currents, &[16.0]) {
                Ok(_) => low = mid,
                Err(_) => high = mid,
            }
        }
        assert!((i - low).abs() < 1e-9 * i, "{i} vs {low}");
        assert!(i > others, "the middle layer alone can carry more");
    }

    #[test]
    fn layered_coil_follows_the_fifty_percent_rule_of_thumb() {
        // The note: runaway "sets in" once the absolute winding temperature
        // has risen by about half the absolute ambient (16 degC = 289.15 K).
        // At the common current where the mean layer temperature has risen
        // that much, the model must be well into the steep part: a 5 % more
        // current raises the rise by far more than the 10 % of a constant
        // resistance, while the current is still clearly below runaway.
        let network = layered_coil::<20>(1.05);
        let runaway = runaway_by_bisection(&network);
        let mean_rise = |i: f64| {
            let t = network.steady_state(&[i; 20], &[16.0]).unwrap();
            t.iter().sum::<f64>() / 20.0 - 16.0
        };
        let target = 0.5 * (16.0 + 273.15);
        let (mut low, mut high) = (0.0, runaway);
        for _ in 0..200 {
            let mid = 0.5 * (low + high);
            if mean_rise(mid) < target {
                low = mid;
            } else {
                high = mid;
            }
        }
        let onset = low;
        let fraction = onset / runaway;
        let growth = mean_rise(1.05 * onset) / mean_rise(onset) - 1.0;
        std::println!(
            "layered coil: runaway {runaway:.3} A, 50 % onset {onset:.3} A ({fraction:.3}), \
             +5 % current gives +{:.1} % rise",
            100.0 * growth
        );
        assert!(
            (0.5..0.8).contains(&fraction),
            "onset at {fraction} of runaway"
        );
        assert!(growth > 0.15, "5 % more current: {growth} more rise");
        // With temperature-independent resistance the same coil at the same
        // current stays far cooler (the note's comparison).
        let constant = {
            let mut n: Network<20, 1, 20> = Network::new(core::array::from_fn(|i| {
                network.capacity_j_per_k(i).unwrap()
            }))
            .unwrap();
            for i in 0..20 {
                for j in (i + 1)..20 {
                    let g = network.conductance_w_per_k(i, j);
                    if g > 0.0 {
                        n = n.connect(i, j, g).unwrap();
                    }
                }
                let gb = network.boundary_conductance_w_per_k(i, 0);
                if gb > 0.0 {
                    n = n.connect_boundary(i, 0, gb).unwrap();
                }
                let r = network.source(i).unwrap().resistance.at_c(16.0);
                n = n.joule_source(i, i, Resistance::constant(r)).unwrap();
            }
            n
        };
        let t = constant.steady_state(&[onset; 20], &[16.0]).unwrap();
        let constant_rise = t.iter().sum::<f64>() / 20.0 - 16.0;
        std::println!(
            "constant R at the onset current: {constant_rise:.1} K rise against {target:.1} K"
        );
        assert!(constant_rise < 0.75 * target, "{constant_rise}");
    }

    /// Winding `coil`'s rank-one steady states against the full solve
    /// ([`Network::steady_state`], Gaussian elimination of the whole system
    /// at each current): every node within 1e-7 K, from both sides, at
    /// each of `currents_a`; and, for a winding that runs away, its
    /// runaway current against the eigen-decomposition's
    /// ([`runaway_current_a`], to 1e-9) and no steady state just beyond.
    fn check_against_full_solves<const N: usize, const B: usize, const M: usize>(
        network: &Network<N, B, M>,
        coil: usize,
        others: [f64; M],
        boundary: [f64; B],
        currents_a: &[f64],
    ) {
        let one = crate::network::one_winding_steady(network, coil, &others, &boundary)
            .unwrap()
            .expect("a current-driven winding");
        let runaway = runaway_current_a(network, coil, &others).unwrap();
        assert_eq!(one.runaway_current_a().is_some(), runaway.is_some());
        if let (Some(by_update), Some(runaway)) = (one.runaway_current_a(), runaway) {
            assert!(
                (by_update - runaway).abs() < 1e-9 * runaway,
                "coil {coil}: {by_update} A against {runaway} A"
            );
            let mut currents = others;
            currents[coil] = 1.01 * runaway;
            assert_eq!(
                network.steady_state(&currents, &boundary),
                Err(BuildError::NoSteadyState)
            );
            assert!(!one.within(1.01 * runaway, &[f64::MAX; N]));
        }
        for &current in currents_a {
            let mut currents = others;
            currents[coil] = current;
            let t = network.steady_state(&currents, &boundary).unwrap();
            let above = t.map(|t| t + 1e-7);
            assert!(one.within(current, &above), "coil {coil} at {current} A");
            for j in 0..N {
                let mut limits = above;
                limits[j] = t[j] - 1e-7;
                assert!(
                    !one.within(current, &limits),
                    "coil {coil} node {j} at {current} A"
                );
            }
        }
    }

    /// [`check_against_full_solves`] for each winding of a layered coil at
    /// currents up to 0.95 of its runaway, and for a network with two
    /// boundaries, a fixed power and two windings on one node (each taken
    /// in turn, the other held) beside a constant resistance.
    #[test]
    fn the_search_steady_states_are_the_full_solves() {
        let network = layered_coil::<12>(1.05);
        let others = [10.0; 12];
        for coil in 0..12 {
            let runaway = runaway_current_a(&network, coil, &others).unwrap().unwrap();
            let currents = [0.0, 0.2, 0.5, 0.8, 0.95].map(|share| share * runaway);
            check_against_full_solves(&network, coil, others, [16.0], &currents);
        }
        let mixed: Network<4, 2, 3> = Network::new([50.0, 80.0, 200.0, 900.0])
            .and_then(|n| n.connect(0, 1, 2.0))
            .and_then(|n| n.connect(1, 2, 1.5))
            .and_then(|n| n.connect(2, 3, 1.0))
            .and_then(|n| n.connect_boundary(3, 0, 2.0))
            .and_then(|n| n.connect_boundary(0, 1, 0.5))
            .and_then(|n| n.fixed_power(2, 5.0))
            .and_then(|n| n.joule_source(0, 1, Resistance::with_alpha(0.4, 0.00393, 20.0)))
            .and_then(|n| n.joule_source(1, 1, Resistance::with_alpha(0.2, 0.00393, 20.0)))
            .and_then(|n| n.joule_source(2, 2, Resistance::constant(0.5)))
            .unwrap();
        for coil in 0..3 {
            check_against_full_solves(
                &mixed,
                coil,
                [3.0, 4.0, 5.0],
                [20.0, 35.0],
                &[0.0, 1.5, 4.0, 7.0],
            );
        }
    }

    #[test]
    fn hot_spot_current_puts_the_hottest_element_on_its_limit() {
        let network = layered_coil::<12>(1.05);
        let limits = [180.0; 12];
        let report = runaway_report(&network, &[10.0; 12], &[16.0], &limits).unwrap();
        for (coil, r) in report.iter().enumerate() {
            let hot = r.hot_spot_current_a.unwrap();
            assert!(hot < r.runaway_current_a.unwrap());
            let mut currents = [10.0; 12];
            currents[coil] = hot;
            let t = network.steady_state(&currents, &[16.0]).unwrap();
            let peak = t.iter().fold(f64::MIN, |a, &b| a.max(b));
            assert!((peak - 180.0).abs() < 1e-6, "coil {coil}: {peak}");
        }
        // Already too hot at zero current of this coil.
        assert_eq!(
            hot_spot_current_a(&network, 0, &[10.0; 12], &[16.0], &[17.0; 12]),
            Ok(Some(0.0))
        );
        assert!(hot_spot_current_a(&network, 0, &[0.0; 12], &[16.0], &[f64::NAN; 12]).is_err());
    }
}
