//! The Omnimagnet paper's `t_max` / `I_max` study, for any network.
//!
//! The Omnimagnet runs in bursts and rarely reaches steady state, so its
//! paper asks two questions per combination of powered solenoids
//! (omnimagnet-16-node.md, "Experiments and limits"): how long can it run at
//! a current before the first element reaches its limit
//! ([`max_safe_time_s`]), and what current is safe for a given time
//! ([`max_safe_current_a`]). Each powered winding carries the same current.
//!
//! # Exact in `R(T)`
//!
//! At constant currents the Joule power `(r0 + s T) I^2` is affine in the
//! winding temperature, so the *nonlinear* model is an exact linear ODE with
//! the feedback `s I^2` moved into the conduction matrix (`A_I`, still
//! symmetrisable, see [`predict`](super::predict)). From the start `T_0`,
//!
//! ```text
//! T(t) = T_0 + V diag((exp(lambda_j t) - 1) / lambda_j) V^-1 (dT/dt)(0),
//! ```
//!
//! which also holds at and beyond runaway (`lambda_j >= 0`). No
//! linearisation, no time stepping.
//!
//! # Monotone, so one evaluation per question
//!
//! The device starts in equilibrium at the ambient with no current (the
//! paper's experiments; the fixed powers included). Switching currents on is
//! then a non-negative step in power, and since `exp(A_I t)` is elementwise
//! non-negative, every temperature rises monotonically. So:
//!
//! * the time to the first limit is found by doubling and then bisecting on
//!   "some element is at or above its limit at `t`", and it is "never"
//!   (`None`) exactly when the steady state exists and stays at or below
//!   every limit;
//! * the temperatures at `t` are the maxima over `[0, t]`, and they grow
//!   with the current, so the safe current for a time `t` is a bisection on
//!   the current with a single evaluation at `t` each.
//!
//! Build-time code: `f64`, `O(N^3)` per current tried (one Jacobi
//! decomposition), about 200 tries per answer; a few milliseconds for
//! `N = 16`. Bounded loops, no allocation, no panic.

use super::modal::{feedback_w_per_k, Modal};
use crate::error::BuildError;
use crate::network::Network;
use crate::sizes::ConstSizes;

/// The seven combinations of three powered solenoids (inner, middle, outer),
/// in the order single coils, pairs, all three.
pub const POWERED_COMBINATIONS: [[bool; 3]; 7] = [
    [true, false, false],
    [false, true, false],
    [false, false, true],
    [true, true, false],
    [true, false, true],
    [false, true, true],
    [true, true, true],
];

/// Bisection steps (the loops stop at `f64` resolution sooner).
const BISECTION_STEPS: usize = 200;
/// Doublings of the search bracket (2^80 from the start: any finite answer).
const DOUBLINGS: usize = 80;
/// The first time tried \[s\] when searching for a crossing.
const FIRST_TIME_S: f64 = 1e-3;

/// Per-element limits and the ambient for the study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StudyLimits<const N: usize> {
    limits_c: [f64; N],
    ambient_c: f64,
}

impl<const N: usize> StudyLimits<N> {
    /// Each element's limit `limits_c` \[degC\] (`+inf` for an element
    /// without one; the paper uses 115 degC) and the ambient `ambient_c`
    /// \[degC\] of every boundary, where the device starts in equilibrium.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] for a NaN limit or a non-finite
    /// ambient.
    pub fn new(limits_c: [f64; N], ambient_c: f64) -> Result<Self, BuildError> {
        if limits_c.iter().any(|l| l.is_nan()) {
            return Err(BuildError::InvalidParameter { name: "limits_c" });
        }
        if !ambient_c.is_finite() {
            return Err(BuildError::InvalidParameter { name: "ambient_c" });
        }
        Ok(Self {
            limits_c,
            ambient_c,
        })
    }

    /// The limits \[degC\].
    pub fn limits_c(&self) -> &[f64; N] {
        &self.limits_c
    }

    /// The ambient \[degC\].
    pub fn ambient_c(&self) -> f64 {
        self.ambient_c
    }
}

/// The exact trajectory at one set of constant currents.
struct Trajectory<const N: usize, const B: usize, const M: usize> {
    start_c: [f64; N],
    modal: Modal<ConstSizes<N, B, M>>,
    /// `V^-1 dT/dt(0)`.
    initial_rate_modes: [f64; N],
}

impl<const N: usize, const B: usize, const M: usize> Trajectory<N, B, M> {
    fn new(
        network: &Network<N, B, M>,
        limits: &StudyLimits<N>,
        currents_a: &[f64; M],
    ) -> Result<Self, BuildError> {
        let boundary = [limits.ambient_c; B];
        let start_c = network.steady_state(&[0.0; M], &boundary)?;
        let modal = Modal::new(network, &feedback_w_per_k(network, currents_a))?;
        let rate = network.derivative_k_per_s(&start_c, currents_a, &boundary);
        Ok(Self {
            start_c,
            initial_rate_modes: modal.to_modes(&rate),
            modal,
        })
    }

    fn temps_c(&self, t_s: f64) -> [f64; N] {
        let weights = self.modal.lambda_per_s.map(|l| {
            let x = l * t_s;
            // expm1(x)/l, with the l -> 0 limit t.
            if x.abs() < 1e-12 {
                t_s
            } else {
                libm::expm1(x) / l
            }
        });
        let mut t = self.modal.node_values(&self.initial_rate_modes, &weights);
        for (t, t0) in t.iter_mut().zip(&self.start_c) {
            *t += t0;
        }
        t
    }

    /// Some element at or above its limit at `t_s` (NaN counts as above).
    fn exceeds(&self, limits: &StudyLimits<N>, t_s: f64) -> bool {
        self.temps_c(t_s)
            .iter()
            .zip(&limits.limits_c)
            .any(|(t, l)| t.partial_cmp(l) != Some(core::cmp::Ordering::Less))
    }
}

fn currents<const M: usize>(powered: &[bool; M], current_a: f64) -> [f64; M] {
    powered.map(|on| if on { current_a } else { 0.0 })
}

/// How long \[s\] the device can run from equilibrium at the ambient with
/// `current_a` \[A\] in every `powered` winding before the first element
/// reaches its limit; `None` if never (the steady state stays at or below
/// every limit). `Some(0)` if an element starts at or above its limit.
///
/// # Errors
/// [`BuildError::InvalidParameter`] for a non-finite current,
/// [`BuildError::Singular`] for a node with no path to a boundary, and any
/// error of building the trajectory.
pub fn max_safe_time_s<const N: usize, const B: usize, const M: usize>(
    network: &Network<N, B, M>,
    limits: &StudyLimits<N>,
    powered: [bool; M],
    current_a: f64,
) -> Result<Option<f64>, BuildError> {
    if !current_a.is_finite() {
        return Err(BuildError::InvalidParameter { name: "current_a" });
    }
    let currents = currents(&powered, current_a);
    let boundary = [limits.ambient_c; B];
    match network.steady_state(&currents, &boundary) {
        Ok(t) if t.iter().zip(&limits.limits_c).all(|(t, l)| t <= l) => return Ok(None),
        Ok(_) | Err(BuildError::NoSteadyState) => {}
        Err(e) => return Err(e),
    }
    let trajectory = Trajectory::new(network, limits, &currents)?;
    if trajectory.exceeds(limits, 0.0) {
        return Ok(Some(0.0));
    }
    let (mut low, mut high) = (0.0, FIRST_TIME_S);
    let mut found = false;
    for _ in 0..DOUBLINGS {
        if trajectory.exceeds(limits, high) {
            found = true;
            break;
        }
        low = high;
        high *= 2.0;
    }
    if !found {
        // The steady state is above a limit by a rounding error: the
        // crossing is too far away to matter; report the search's end.
        return Ok(Some(low));
    }
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (low + high);
        if mid <= low || mid >= high {
            break;
        }
        if trajectory.exceeds(limits, mid) {
            high = mid;
        } else {
            low = mid;
        }
    }
    Ok(Some(low))
}

/// The largest current \[A\] that every `powered` winding can carry for
/// `time_s` \[s\] from equilibrium at the ambient without any element
/// reaching its limit. `+inf` when nothing is powered or no current reaches
/// a limit in that time; `0` when an element starts at or above its limit.
///
/// # Errors
/// [`BuildError::InvalidParameter`] for `time_s` not finite or not > 0, and
/// the errors of [`max_safe_time_s`].
pub fn max_safe_current_a<const N: usize, const B: usize, const M: usize>(
    network: &Network<N, B, M>,
    limits: &StudyLimits<N>,
    powered: [bool; M],
    time_s: f64,
) -> Result<f64, BuildError> {
    if !(time_s.is_finite() && time_s > 0.0) {
        return Err(BuildError::InvalidParameter { name: "time_s" });
    }
    let exceeds = |current_a: f64| -> Result<bool, BuildError> {
        Ok(
            Trajectory::new(network, limits, &currents(&powered, current_a))?
                .exceeds(limits, time_s),
        )
    };
    if !powered.iter().any(|&on| on) {
        return Ok(f64::INFINITY);
    }
    if exceeds(0.0)? {
        return Ok(0.0);
    }
    let (mut low, mut high) = (0.0, 1.0);
    let mut found = false;
    for _ in 0..DOUBLINGS {
        if exceeds(high)? {
            found = true;
            break;
        }
        low = high;
        high *= 2.0;
    }
    if !found {
        return Ok(f64::INFINITY);
    }
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (low + high);
        if mid <= low || mid >= high {
            break;
        }
        if exceeds(mid)? {
            high = mid;
        } else {
            low = mid;
        }
    }
    Ok(low)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::Resistance;

    /// Three nested solenoids on frames, a small-scale stand-in for the
    /// Omnimagnet: coils 0..3, frames 3..5, a core 5 and a cover 6.
    pub(crate) fn three_coils() -> Network<7, 1, 3> {
        Network::new([300.0, 260.0, 290.0, 130.0, 150.0, 1000.0, 8.0])
            .unwrap()
            .connect(0, 3, 0.9)
            .unwrap()
            .connect(0, 5, 0.4)
            .unwrap()
            .connect(1, 3, 0.7)
            .unwrap()
            .connect(1, 4, 0.6)
            .unwrap()
            .connect(2, 4, 0.8)
            .unwrap()
            .connect(2, 6, 1.1)
            .unwrap()
            .connect(3, 5, 0.3)
            .unwrap()
            .connect_boundary(4, 0, 0.35)
            .unwrap()
            .connect_boundary(6, 0, 0.9)
            .unwrap()
            .connect_boundary(5, 0, 0.05)
            .unwrap()
            .joule_source(0, 0, Resistance::with_alpha(3.2, 0.0039, 20.0))
            .unwrap()
            .joule_source(1, 1, Resistance::with_alpha(2.8, 0.0039, 20.0))
            .unwrap()
            .joule_source(2, 2, Resistance::with_alpha(3.1, 0.0039, 20.0))
            .unwrap()
    }

    /// RK4 on the nonlinear right-hand side: first time any element reaches
    /// its limit, linearly interpolated inside the step.
    fn rk4_first_crossing<const N: usize, const M: usize>(
        network: &Network<N, 1, M>,
        limits: &StudyLimits<N>,
        currents: &[f64; M],
        dt: f64,
        t_end: f64,
    ) -> Option<f64> {
        let ambient = [limits.ambient_c()];
        let mut t = network.steady_state(&[0.0; M], &ambient).unwrap();
        let f = |x: &[f64; N]| network.derivative_k_per_s(x, currents, &ambient);
        let margin = |x: &[f64; N]| {
            x.iter()
                .zip(limits.limits_c())
                .map(|(t, l)| t - l)
                .fold(f64::MIN, f64::max)
        };
        let steps = (t_end / dt) as usize;
        for step in 0..steps {
            let add = |x: &[f64; N], k: &[f64; N], h: f64| {
                let mut y = *x;
                for i in 0..N {
                    y[i] += h * k[i];
                }
                y
            };
            let k1 = f(&t);
            let k2 = f(&add(&t, &k1, dt / 2.0));
            let k3 = f(&add(&t, &k2, dt / 2.0));
            let k4 = f(&add(&t, &k3, dt));
            let before = margin(&t);
            for i in 0..N {
                t[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            let after = margin(&t);
            if after >= 0.0 {
                return Some((step as f64 + before / (before - after)) * dt);
            }
        }
        None
    }

    #[test]
    fn safe_time_matches_rk4_for_every_combination() {
        let network = three_coils();
        let limits = StudyLimits::new([115.0; 7], 20.0).unwrap();
        for powered in POWERED_COMBINATIONS {
            for current in [2.0, 3.5, 5.0] {
                let exact = max_safe_time_s(&network, &limits, powered, current).unwrap();
                let rk4 = rk4_first_crossing(
                    &network,
                    &limits,
                    &currents(&powered, current),
                    0.05,
                    40_000.0,
                );
                match (exact, rk4) {
                    (Some(a), Some(b)) => {
                        std::println!("{powered:?} {current} A: t_max {a:.3} s, RK4 {b:.3} s");
                        assert!(
                            (a - b).abs() < 1e-4 * b + 1e-3,
                            "{powered:?} {current}: {a} vs {b}"
                        )
                    }
                    (None, None) => {}
                    other => panic!("{powered:?} {current}: {other:?}"),
                }
            }
        }
    }

    #[test]
    fn safe_current_inverts_safe_time() {
        let network = three_coils();
        let limits = StudyLimits::new([115.0; 7], 20.0).unwrap();
        for powered in POWERED_COMBINATIONS {
            for time in [60.0, 600.0, 3600.0] {
                let current = max_safe_current_a(&network, &limits, powered, time).unwrap();
                assert!(current.is_finite() && current > 0.0);
                let at = max_safe_time_s(&network, &limits, powered, current).unwrap();
                if let Some(t) = at {
                    assert!((t - time).abs() < 1e-6 * time, "{powered:?}: {t} vs {time}");
                }
                let above = max_safe_time_s(&network, &limits, powered, current * 1.001)
                    .unwrap()
                    .unwrap();
                assert!(above < time);
            }
        }
        // All three on is the worst case, as in the paper.
        let all = max_safe_current_a(&network, &limits, [true; 3], 600.0).unwrap();
        for powered in &POWERED_COMBINATIONS[..6] {
            assert!(max_safe_current_a(&network, &limits, *powered, 600.0).unwrap() > all);
        }
    }

    #[test]
    fn never_zero_and_bad_inputs() {
        let network = three_coils();
        let limits = StudyLimits::new([115.0; 7], 20.0).unwrap();
        assert_eq!(max_safe_time_s(&network, &limits, [true; 3], 0.1), Ok(None));
        assert_eq!(
            max_safe_current_a(&network, &limits, [false; 3], 10.0),
            Ok(f64::INFINITY)
        );
        let hot = StudyLimits::new([115.0; 7], 130.0).unwrap();
        assert_eq!(
            max_safe_time_s(&network, &hot, [true; 3], 1.0),
            Ok(Some(0.0))
        );
        assert_eq!(max_safe_current_a(&network, &hot, [true; 3], 1.0), Ok(0.0));
        assert!(max_safe_time_s(&network, &limits, [true; 3], f64::NAN).is_err());
        assert!(max_safe_current_a(&network, &limits, [true; 3], 0.0).is_err());
        assert!(StudyLimits::new([f64::NAN; 7], 20.0).is_err());
        // Beyond runaway the answer is still finite and exact in R(T).
        let runaway = super::super::runaway::runaway_current_a(&network, 0, &[0.0; 3])
            .unwrap()
            .unwrap();
        let t = max_safe_time_s(&network, &limits, [true, false, false], 1.5 * runaway).unwrap();
        assert!(t.unwrap() > 0.0);
    }
}
