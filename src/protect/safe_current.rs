//! Maximum safe current over a horizon, by superposition in power.
//!
//! With the powers held, the network is linear in the Joule powers, so the
//! temperature of element `e` splits into a *free* part (the present state
//! relaxing, the boundaries, the fixed powers and any powers held constant)
//! and a *load* part proportional to the power that is being sized:
//!
//! ```text
//! T_e(t) = F_e(t) + x L_e(t),   L(t) = (I - exp(A t)) (-A^-1) B p_1 = Phi(t) B p_1
//! ```
//!
//! where `p_1` is the load's power at `x = 1` and `x` is the factor sought:
//! `k^2` for a common scale `k` on every current (power goes with `I^2`), or
//! `I_m^2` for one coil's current with its power per ampere squared as `p_1`.
//! Every element must stay at or below its limit `L_e` over `[0, t_h]`.
//!
//! # The maximum over the horizon
//!
//! The load part starts at zero and is **monotone non-decreasing**:
//! `dL/dt = exp(A t) B p_1 >= 0`, because `exp(A t)` is elementwise
//! non-negative for a conduction matrix (non-negative off-diagonal entries)
//! and the powers are non-negative. So heating from equilibrium (a constant
//! free part) reaches its maximum at `t_h`, and on any bracket `[a, b]` the
//! load part is at most its value at `b`.
//!
//! The free part need not be monotone (a hot coil cooling while its
//! neighbour warms). On each bracket of the predictor's horizon grid (plus
//! `t_h` itself) it is bounded termwise in modes, `c exp(lambda t) <=
//! c exp(lambda a)` for `c > 0` and `<= c exp(lambda b)` for `c < 0`
//! ([`predict`](super::predict): `P(a) - Q(b)`). Each bracket then gives a
//! linear constraint `alpha_e + x beta_e <= L_e`, solved in closed form; the
//! answer is the smallest over brackets and elements, and it is never
//! larger than the true largest safe factor of the linear model.
//! [`Horizon::Forever`] adds the tail `[t_K, inf)`, where the free part is at
//! most `F_ss + P(t_K)` and the load part at most its steady value.
//!
//! # `R(T)`
//!
//! As in the predictor, each winding's power is evaluated at the resistance
//! it has at its node's alarm limit (or present temperature, if higher).
//! While the winding stays below its limit the true power is smaller, so
//! the true temperatures stay below the bounded ones: the answer is safe
//! for the nonlinear model, and conservative by the ratio
//! `R(T_present) / R(T_limit)` in power when the coil is far below its limit
//! (an `f64` fixed point on the real `R(T)` is what
//! [`study`](super::study) does, at build time).
//!
//! # Duty cycle
//!
//! `duty` multiplies the load's power: a coil pulsed at peak current `I`
//! for a fraction `duty` of a period `T_p` heats like a steady `duty R I^2`
//! when `T_p` is much shorter than the thermal time constants. The ripple
//! this ignores is about `duty (1 - duty) R I^2 T_p / C_node` \[K\] peak to
//! peak on the winding node; keep it inside the derating margin.
//!
//! # Cost
//!
//! Two modal evaluations per grid point up to `t_h`: about
//! `6 N^2 (K_h + 1)` flops for `K_h` grid points below the horizon (50 000
//! for `N = 16` and the whole default grid). Bounded, allocation-free and
//! panic-free, but meant for planning calls, not every tick.

use nalgebra::RealField;

use super::predict::{ModalPredictor, OperatingPoint};
use crate::sizes::{InputVector, NodeVector, Sizes};

/// How far ahead the limits must hold.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Horizon<T> {
    /// Over `[0, t]` \[s\], `t > 0`.
    Seconds(T),
    /// For ever: the transient and the steady state.
    Forever,
}

/// The largest safe value of a current or scale, and what bounds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SafeLimit<T> {
    /// The largest safe scale (dimensionless) or current \[A\]; `+inf` when
    /// nothing bounds it (no power to scale), `0` when not even zero is safe
    /// or an input was invalid.
    pub value: T,
    /// The element whose limit binds, if one does.
    pub binding_element: Option<usize>,
    /// `false` when some element passes its limit within the horizon even at
    /// zero load (it is already too hot, or the rest of the load is too
    /// much), or when an input was not finite (or, with `Vec`s, not of the
    /// network's length).
    pub feasible: bool,
}

impl<T: RealField + Copy> SafeLimit<T> {
    fn invalid() -> Self {
        Self {
            value: T::zero(),
            binding_element: None,
            feasible: false,
        }
    }
}

impl<T: RealField + Copy, S: Sizes, const K: usize> ModalPredictor<T, S, K> {
    /// The largest common scale `k` on the present currents `op.currents_a`
    /// such that no element passes its limit over `horizon`, with the load
    /// pulsed at `duty` (in `(0, 1]`; 1 for continuous). Safe currents are
    /// `k * op.currents_a`.
    pub fn max_common_scale(
        &self,
        op: &OperatingPoint<T, S>,
        horizon: Horizon<T>,
        duty: T,
    ) -> SafeLimit<T> {
        let mut load = self.conservative_powers_w(op);
        for p in load.as_mut() {
            *p *= duty;
        }
        let free = self.sizes.inputs_of(T::zero());
        let limit = self.max_load_factor(op, &free, &load, horizon, duty);
        SafeLimit {
            value: limit.value.sqrt(),
            ..limit
        }
    }

    /// The largest current \[A\] of winding `coil`, the other windings at
    /// their present currents (continuous), such that no element passes its
    /// limit over `horizon`, with this coil pulsed at `duty` (in `(0, 1]`).
    /// An out-of-range `coil` gives the invalid answer (zero, infeasible).
    pub fn max_coil_current_a(
        &self,
        coil: usize,
        op: &OperatingPoint<T, S>,
        horizon: Horizon<T>,
        duty: T,
    ) -> SafeLimit<T> {
        let Some(winding) = self.windings.as_ref().get(coil) else {
            return SafeLimit::invalid();
        };
        let mut others = self.conservative_powers_w(op);
        let mut unit = self.sizes.inputs_of(T::zero());
        if let (Some(o), Some(u)) = (others.as_mut().get_mut(coil), unit.as_mut().get_mut(coil)) {
            *o = T::zero();
            *u = self.conservative_resistance_ohm(winding, op) * duty;
        }
        let limit = self.max_load_factor(op, &others, &unit, horizon, duty);
        SafeLimit {
            value: limit.value.sqrt(),
            ..limit
        }
    }

    /// The largest `x` with `F(t) + x L(t) <= limits` over the horizon (module
    /// docs), `F` from `op` with powers `free_w`, `L` from powers `load_w`.
    fn max_load_factor(
        &self,
        op: &OperatingPoint<T, S>,
        free_w: &InputVector<S, T>,
        load_w: &InputVector<S, T>,
        horizon: Horizon<T>,
        duty: T,
    ) -> SafeLimit<T> {
        let horizon_ok = match horizon {
            Horizon::Seconds(t) => t > T::zero() && t.is_finite(),
            Horizon::Forever => true,
        };
        let inputs_ok = self.takes(op)
            && duty > T::zero()
            && duty <= T::one()
            && (free_w.as_ref().iter())
                .chain(load_w.as_ref())
                .all(|p| p.is_finite());
        if !(horizon_ok && inputs_ok) {
            return SafeLimit::invalid();
        }
        let (free_ss, free_modes) =
            self.steady_and_modes(&op.temps_c, free_w, &op.boundary_c, true);
        let (load_ss, load_modes) = self.steady_and_modes(
            &self.sizes.nodes_of(T::zero()),
            load_w,
            &self.sizes.boundaries_of(T::zero()),
            false,
        );

        let mut best = SafeLimit {
            value: T::from_subset(&f64::INFINITY),
            binding_element: None,
            feasible: true,
        };
        // P of the free part at each bracket's start, per element.
        let ones = self.sizes.nodes_of(T::one());
        let mut free_p_start = self.sizes.nodes_of(T::zero());
        for (p, row) in free_p_start.as_mut().iter_mut().zip(self.v.as_ref()) {
            *p = self.parts(row, &free_modes, &ones).p;
        }
        let mut horizon_decay = self.sizes.nodes_of(T::zero());
        let t_h = match horizon {
            Horizon::Seconds(t) => {
                let decays = horizon_decay.as_mut().iter_mut();
                for (d, l) in decays.zip(self.lambda_per_s.as_ref()) {
                    *d = (*l * t).exp();
                }
                Some(t)
            }
            Horizon::Forever => None,
        };
        // One bracket, from the previous end to the time whose decay is `end`.
        let mut bracket = |end: &NodeVector<S, T>| {
            let rows = (self.v.as_ref().iter())
                .zip(free_p_start.as_mut().iter_mut())
                .zip(free_ss.as_ref().iter().zip(load_ss.as_ref()))
                .zip(op.limits_c.as_ref())
                .enumerate();
            for (e, (((row, p_start), (f_ss, l_ss)), limit)) in rows {
                let free = self.parts(row, &free_modes, end);
                let load = self.parts(row, &load_modes, end);
                let alpha = *f_ss + *p_start - free.q;
                let beta = *l_ss + load.p - load.q;
                constrain(&mut best, e, alpha, beta, *limit);
                *p_start = free.p;
            }
        };
        // Bracket ends: every grid point below the horizon, then the horizon.
        for k in 1..=K {
            let Some((t, Some(decay))) = self.point(k) else {
                break;
            };
            if t_h.is_some_and(|t_h| t >= t_h) {
                break;
            }
            bracket(decay);
        }
        if t_h.is_some() {
            bracket(&horizon_decay);
            return best;
        }
        // Forever: the tail [t_K, inf).
        let rows = (free_p_start.as_ref().iter())
            .zip(free_ss.as_ref().iter().zip(load_ss.as_ref()))
            .zip(op.limits_c.as_ref())
            .enumerate();
        for (e, ((p_last, (f_ss, l_ss)), limit)) in rows {
            constrain(&mut best, e, *f_ss + *p_last, *l_ss, *limit);
        }
        best
    }
}

/// Tightens `best` with `alpha + x beta <= limit`.
#[inline]
fn constrain<T: RealField + Copy>(best: &mut SafeLimit<T>, e: usize, alpha: T, beta: T, limit: T) {
    let room = limit - alpha;
    if room < T::zero() {
        if best.feasible {
            best.binding_element = Some(e);
        }
        best.feasible = false;
        best.value = T::zero();
    } else if beta > T::zero() && best.feasible {
        let x = room / beta;
        if x < best.value {
            best.value = x;
            best.binding_element = Some(e);
        }
    }
}
