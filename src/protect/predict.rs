//! Predicted time to the alarm limit, for the present currents.
//!
//! # The linear response, in modes
//!
//! With the Joule powers `p` and boundary temperatures `T_b` held, a network
//! relaxes to its steady state `T_ss = -A^-1 (B p + G T_b + d)` along
//!
//! ```text
//! T(t) = T_ss + exp(A t) (T_0 - T_ss) = T_ss + V diag(exp(lambda t)) z,   z = V^-1 (T_0 - T_ss)
//! ```
//!
//! `A = -C^-1 K` with `C` the diagonal of capacities and `K` the symmetric
//! conductance matrix (pairs are stored once), so `A` is similar to the
//! symmetric `-C^(-1/2) K C^(-1/2)` and `A = V diag(lambda) V^-1` with real,
//! decaying modes, `lambda_j < 0`, found by Jacobi rotations at build time. Element `e`'s distance from its
//! steady state is a sum of decaying exponentials `c_ej exp(lambda_j t)`,
//! `c_ej = V_ej z_j`. Split by the sign of `c_ej`:
//!
//! ```text
//! T_e(t) - T_ss,e = P_e(t) - Q_e(t),   P = sum_{c > 0} c e^(lambda t),   Q = sum_{c < 0} |c| e^(lambda t)
//! ```
//!
//! Both `P` and `Q` are non-negative, non-increasing and **convex**. That
//! gives a rigorous upper bound of `T_e` on any bracket `[a, b]` from values
//! at its ends: the chord of `P` lies above `P`, and each tangent of `Q` lies
//! below `Q`, so
//!
//! ```text
//! T_e(t) - T_ss,e <= chord_P(t) - max(Q(a) + Q'(a)(t - a), Q(b) + Q'(b)(t - b))   on [a, b],
//! ```
//!
//! a concave piecewise-linear function with one kink whose first crossing of
//! the limit is found in closed form. Its gap to the truth is second order
//! in the bracket width.
//!
//! # The horizon grid
//!
//! `K` positive times `t_1 .. t_K`, geometric from `first_s` to `last_s`
//! (defaults: `K = 48`, 1 s to 4 h, ratio 1.226), plus `t_0 = 0`. The table
//! `exp(lambda_j t_k)` is `K x N` numbers: the modal form stores `N` numbers
//! per horizon where a table of `exp(A t_k)` would store `N^2` (for `N = 16`,
//! `K = 48` in `f32`: 3 KiB against 48 KiB). The whole configuration is
//! `(K + 2N + 2(M + B + 1) + 1) N + K + 3M` numbers, 8 KiB for the Omnimagnet
//! (`N = 16`, `B = 1`, `M = 3`) in `f32`.
//!
//! Element `e`'s time to limit is the first crossing of the bound in the
//! first bracket where it reaches the limit. Beyond `t_K`, `T_e <= T_ss,e +
//! P_e(t_K)` (as `Q >= 0`): below the limit means **never** (`None`);
//! otherwise the answer is `t_K` (conservative: the element may cross later,
//! or never). An element already at or above its limit gets `Some(0)`.
//!
//! **Guarantee (linear model):** the predicted time is never later than the
//! true first crossing, whatever the grid; the grid only sets how much
//! earlier it may be (tested against the analytic single-node formula and
//! against an `f64` RK4 integration of random networks). Measured: at most
//! 2.1 % early on the single node, worst where the limit sits 0.1 K below the
//! steady state and the approach is flattest. In `f32` the rounding of the
//! steady state can move the answer by about `1e-7 (T_ss - T_0)` divided by
//! the heating rate at the crossing (11 us in the tests' worst case, a 20 A
//! step towards 4820 degC), far below a tick.
//!
//! # Conservative treatment of `R(T)`
//!
//! The powers are evaluated at the resistance each winding would have at the
//! *alarm limit of its own node* (or at its present temperature, if higher):
//! `p_m = R_m(max(T_node, L_node)) I_m^2`. Until some winding passes its
//! limit, the true power is at most that, and since `A` has non-negative
//! off-diagonal entries (`exp(A t) >= 0`), more power means higher
//! temperatures everywhere at every time. So the earliest predicted time over
//! all elements is never later than the true earliest crossing of the
//! nonlinear model; each element's own prediction is never later than its true
//! crossing unless a winding crosses its limit first (and that winding's
//! earlier time is then the one that matters). For a negative slope
//! (`R` falling with temperature) the larger of `R(T_node)` and `R(L_node)` is
//! used, which is conservative only while the winding does not cool.
//!
//! # Slicing: one horizon per tick
//!
//! [`LimitPredictor::predict`] evaluates every horizon at once. For the 1 ms
//! loop, [`PredictorState::tick`] evaluates `points_per_tick` horizons per
//! call (default one) on a *snapshot* of the inputs taken at the start of a
//! sweep, and publishes the answers when the sweep ends (at most `K + 1`
//! ticks later), aged by the time since the snapshot: for inputs held since
//! the snapshot, the aged answer keeps the guarantee. The snapshot's powers
//! are the per-winding *peak* since the previous snapshot, so a current that
//! varies within a sweep (commutation) is covered; a step up in current
//! reaches the published answer within two sweeps (98 ms at 1 ms and the
//! defaults), far inside any useful alarm horizon. Pass RMS currents instead
//! if peak powers are too pessimistic for your drive.
//!
//! Where one horizon is more than a tick's budget,
//! [`PredictorBuilder::elements_per_tick`] splits it: at most that many
//! elements per call, the snapshot in calls of its own (the windings'
//! part of the steady state, `k_d + Kp p`; its boundaries' part `Kb T_b`
//! with the headroom and `T_0 - T_ss`; the modal amplitudes, that many
//! at a call), the same answers to the bit (the Omnimagnet's nine
//! limited nodes in slices of five on a Cortex-M4F: 2 250 to 2 500
//! instructions a slice instead of about 3 600 for a horizon; its
//! snapshot alone was about 2 050 instead of 5 200 with the first
//! horizon, and `observer_m4`'s combined worst fell 6 756 -> 6 551 when
//! the steady state took two calls; on a Cortex-M0 in soft-float the real
//! motor's whole snapshot was its worst tick, 32 000 instructions, in two
//! calls 18 600 at worst, in three 15 979 (its modal amplitudes), with
//! one amplitude a call 13 257, below its model-step ticks' worst;
//! `docs/cost.md`). The windings' part
//! takes their peak powers at its call; the boundaries, `T_0` and the
//! limits are those of the next call's operating point, and the answers
//! age from the first call: older than they are by the time between the
//! two, so earlier (conservative).
//!
//! Smaller still, [`PredictorState::tick_in_halves`] takes each element's
//! horizon in two calls: its modal parts `P`, `Q`, `Q'` (held in the
//! caller's [`HalfElement`], so that a state that never halves, the
//! Omnimagnet's, keeps its size), then its crossing. The same answers to
//! the bit, each horizon in twice the calls; the network observer does so
//! at one element a stage (`predictor_elements_per_stage = 1`, the
//! Cortex-M0 examples: `network_roundtrip`'s heaviest predictor stage
//! 4 906 -> 3 826 instructions).
//!
//! # Cost per call (`N` elements, `M` windings, `B` boundaries)
//!
//! | step | flops |
//! |---|---|
//! | snapshot (powers, steady state, modes) | `2N^2 + 4N(M + B + 1) + 4M` |
//! | one horizon | at most `5N^2 + 30N` (elements already resolved are skipped) |
//!
//! For `N = 16`: about 1 700 flops per tick for the sliced predictor, 65 000
//! for a full sweep. Bounded loops only, no allocation, no panic: non-finite
//! inputs give `Some(NaN)` for every element ("unknown"), which the alarm
//! counts as below the horizon.
//!
//! # Any size: [`ModalPredictor`]
//!
//! The configuration and every function of a sweep are written over the
//! network's [`Sizes`]: [`LimitPredictor`] and [`Operating`] are
//! [`ModalPredictor`] and [`OperatingPoint`] with arrays
//! ([`ConstSizes`]), what an MCU flashes; with the `alloc` feature,
//! [`PredictorBuilder::build_from`] a model file's network on a host gives
//! the same predictor with `Vec`s of the model's lengths
//! (`RunTimeSizes`), so the host's time to
//! limit and safe currents of a 300-node motor are this code's. The staged
//! [`PredictorState`] stays const-generic: it is the MCU's.

use core::ops::Range;

use nalgebra::{Const, RealField};

use super::modal::Modal;
use crate::error::BuildError;
use crate::network::{Network, NetworkDescription};
use crate::sizes::{BoundaryVector, ConstSizes, Element, InputVector, Length, NodeVector, Sizes};

/// The default number of positive horizons `K` in the grid.
pub const DEFAULT_GRID_POINTS: usize = 48;

/// Builds a [`LimitPredictor`]; every parameter has a documented default.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PredictorBuilder {
    first_s: f64,
    last_s: f64,
    tick_s: f64,
    points_per_tick: usize,
    elements_per_tick: usize,
}

impl Default for PredictorBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl PredictorBuilder {
    /// Defaults: horizons from 1 s to 4 h (14 400 s), a 1 ms tick, one
    /// horizon per tick.
    pub fn new() -> Self {
        Self {
            first_s: 1.0,
            last_s: 14_400.0,
            tick_s: 1e-3,
            points_per_tick: 1,
            elements_per_tick: usize::MAX,
        }
    }

    /// The first and last positive horizons \[s\]: finite, `0 < first < last`.
    /// Set `last_s` a few times the slowest time constant for tight "never"
    /// answers.
    pub fn grid_s(mut self, first_s: f64, last_s: f64) -> Self {
        self.first_s = first_s;
        self.last_s = last_s;
        self
    }

    /// The period \[s\] of [`PredictorState::tick`], finite and > 0: the
    /// published times age by this much per call.
    pub fn tick_s(mut self, tick_s: f64) -> Self {
        self.tick_s = tick_s;
        self
    }

    /// Horizons evaluated per [`PredictorState::tick`], at least 1 (`K + 1`
    /// evaluates a whole sweep every tick).
    pub fn points_per_tick(mut self, points: usize) -> Self {
        self.points_per_tick = points;
        self
    }

    /// At most `elements` element evaluations per [`PredictorState::tick`]
    /// (at least 1; default unbounded): a horizon whose open elements are
    /// more is split over several ticks, and the snapshot that starts a
    /// sweep takes three ticks of its own (the windings' part of the
    /// steady state, its boundaries' part, then the modal amplitudes). For a
    /// tick budget below one
    /// horizon's cost (the Omnimagnet's nine limited nodes on a
    /// Cortex-M4F); `points_per_tick` then only bounds the ticks that fit.
    /// The answers are the same to the bit; a sweep takes more ticks.
    pub fn elements_per_tick(mut self, elements: usize) -> Self {
        self.elements_per_tick = elements;
        self
    }

    /// Validates the parameters and decomposes `network` (build time,
    /// `O(N^3)`, `f64`), then converts to `T`.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming a bad parameter,
    /// [`BuildError::MissingSource`] if a current input has no winding,
    /// [`BuildError::Singular`] if some node has no path to a boundary.
    pub fn build<
        T: RealField + Copy,
        const N: usize,
        const B: usize,
        const M: usize,
        const K: usize,
    >(
        &self,
        network: &Network<N, B, M>,
    ) -> Result<LimitPredictor<T, N, B, M, K>, BuildError> {
        self.build_from(network)
    }

    /// [`Self::build`] for any network description: a [`Network`], or a
    /// model file's network at its own size on a host (a
    /// [`ModalPredictor`] whose vectors are `Vec`s, the same code).
    ///
    /// # Errors
    /// As [`Self::build`].
    pub fn build_from<T: RealField + Copy, W: NetworkDescription, const K: usize>(
        &self,
        network: &W,
    ) -> Result<ModalPredictor<T, W::Sizes, K>, BuildError> {
        const { assert!(K >= 2, "the grid needs at least two horizons") };
        let sizes = network.sizes();
        let param = |ok: bool, name: &'static str| {
            if ok {
                Ok(())
            } else {
                Err(BuildError::InvalidParameter { name })
            }
        };
        param(
            self.first_s.is_finite()
                && self.last_s.is_finite()
                && self.first_s > 0.0
                && self.last_s > self.first_s,
            "first_s/last_s",
        )?;
        param(self.tick_s.is_finite() && self.tick_s > 0.0, "tick_s")?;
        param(
            (1..=K + 1).contains(&self.points_per_tick),
            "points_per_tick",
        )?;
        param(self.elements_per_tick >= 1, "elements_per_tick")?;
        if let Some(input) = (0..sizes.inputs()).find(|&m| network.joule_source_of(m).is_none()) {
            return Err(BuildError::MissingSource { input });
        }
        let modal = Modal::new(network, &sizes.nodes_of(0.0))?;
        let lambda_per_s = modal.lambda_per_s.as_ref();
        if !lambda_per_s.iter().all(|&l| l < 0.0) {
            return Err(BuildError::Singular);
        }
        let to_t = |x: f64| T::from_subset(&x);
        // A network's capacities are finite and positive.
        let cap = |i: usize| network.capacity_at_j_per_k(i);
        let node_rates = |rate: &dyn Fn(usize) -> f64| {
            let mut rates = sizes.nodes_of(0.0);
            for (i, r) in rates.as_mut().iter_mut().enumerate() {
                *r = rate(i);
            }
            rates
        };

        // -A^-1 x = V diag(-1/lambda) V^-1 x, for a vector of rates x [K/s].
        let inverse_rate = node_rates(&|j| -1.0 / lambda_per_s[j]);
        let ones = sizes.nodes_of(1.0);
        let steady_gain = |rates: &NodeVector<W::Sizes, f64>| {
            let mut modes = modal.to_modes(rates);
            for (z, w) in modes.as_mut().iter_mut().zip(inverse_rate.as_ref()) {
                *z *= w;
            }
            modal.node_values(&modes, &ones)
        };
        // A node vector in `T`.
        let in_t = |row: &NodeVector<W::Sizes, f64>| {
            let mut out = sizes.nodes_of(T::zero());
            for (o, x) in out.as_mut().iter_mut().zip(row.as_ref()) {
                *o = to_t(*x);
            }
            out
        };

        let mut gain_power = sizes.rows_of(sizes.inputs_of(T::zero()));
        let mut windings = sizes.inputs_of(Winding::default());
        for (m, winding) in windings.as_mut().iter_mut().enumerate() {
            let source = network
                .joule_source_of(m)
                .ok_or(BuildError::MissingSource { input: m })?;
            let gain = steady_gain(&node_rates(&|i| {
                if i == source.node {
                    1.0 / cap(i)
                } else {
                    0.0
                }
            }));
            for (row, g) in gain_power.as_mut().iter_mut().zip(gain.as_ref()) {
                row.as_mut()[m] = to_t(*g);
            }
            *winding = Winding {
                node: source.node,
                r_at_0c_ohm: to_t(source.resistance.r_at_0c_ohm),
                slope_ohm_per_k: to_t(source.resistance.slope_ohm_per_k),
            };
        }
        let mut gain_boundary = sizes.rows_of(sizes.boundaries_of(T::zero()));
        for b in 0..sizes.boundaries() {
            let gain = steady_gain(&node_rates(&|i| {
                network.boundary_link_w_per_k(i, b) / cap(i)
            }));
            for (row, g) in gain_boundary.as_mut().iter_mut().zip(gain.as_ref()) {
                row.as_mut()[b] = to_t(*g);
            }
        }
        let offset = steady_gain(&node_rates(&|i| network.fixed_power_at_w(i) / cap(i)));

        let ratio = libm::pow(self.last_s / self.first_s, 1.0 / (K - 1) as f64);
        let mut grid_s = [T::zero(); K];
        let mut decay: [_; K] = core::array::from_fn(|_| sizes.nodes_of(T::zero()));
        for (k, (t_k, row)) in grid_s.iter_mut().zip(&mut decay).enumerate() {
            let t = if k + 1 == K {
                self.last_s
            } else {
                self.first_s * libm::pow(ratio, k as f64)
            };
            *t_k = to_t(t);
            for (d, l) in row.as_mut().iter_mut().zip(lambda_per_s) {
                *d = to_t(libm::exp(l * t));
            }
        }
        let slowest = lambda_per_s
            .iter()
            .fold(0.0f64, |acc, &l| acc.max(-1.0 / l));
        let matrix_of = |m: &crate::protect::modal::NodeMatrix<W::Sizes>| {
            let mut out = sizes.rows_of(sizes.nodes_of(T::zero()));
            for (o, row) in out.as_mut().iter_mut().zip(m.as_ref()) {
                *o = in_t(row);
            }
            out
        };
        Ok(ModalPredictor {
            grid_s,
            decay,
            lambda_per_s: in_t(&modal.lambda_per_s),
            v: matrix_of(&modal.v),
            v_inv: matrix_of(&modal.v_inv),
            gain_power,
            gain_boundary,
            offset_c: in_t(&offset),
            windings,
            sizes,
            tick_s: to_t(self.tick_s),
            points_per_tick: self.points_per_tick,
            elements_per_tick: self.elements_per_tick,
            slowest_time_constant_s: slowest,
        })
    }
}

/// One winding as the predictor sees it: its node and `R(T) = r0 + s T`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Winding<T> {
    pub node: usize,
    pub r_at_0c_ohm: T,
    pub slope_ohm_per_k: T,
}

impl<T: RealField + Copy> Default for Winding<T> {
    fn default() -> Self {
        Self {
            node: 0,
            r_at_0c_ohm: T::zero(),
            slope_ohm_per_k: T::zero(),
        }
    }
}

/// The present operating point of a network of `N` nodes, `B` boundaries
/// and `M` windings (arrays: an MCU's), in the predictor's float type.
pub type Operating<T, const N: usize, const B: usize, const M: usize> =
    OperatingPoint<T, ConstSizes<N, B, M>>;

/// The present operating point, in the predictor's float type, with
/// vectors of the sizes `S` ([`Operating`] on an MCU).
#[derive(Debug, Clone, PartialEq)]
pub struct OperatingPoint<T: Element, S: Sizes> {
    /// Element temperatures \[degC\] (a model's or filter's estimate).
    pub temps_c: NodeVector<S, T>,
    /// Winding currents \[A\] (sign is irrelevant: power goes with `I^2`).
    pub currents_a: InputVector<S, T>,
    /// Boundary temperatures \[degC\], assumed held over the horizon.
    pub boundary_c: BoundaryVector<S, T>,
    /// Each element's alarm limit \[degC\], finite (e.g. from
    /// [`AlarmConfig::alarm_limits_c`](super::alarm::AlarmConfig::alarm_limits_c)),
    /// or `+inf` for an element without one that is not a winding's node
    /// (its answer is "never" and its horizons are skipped; a winding's
    /// power is taken at its node's limit, which must be finite).
    pub limits_c: NodeVector<S, T>,
}

/// Copied where its vectors are (arrays: an MCU's).
impl<T: Element, S: Sizes> Copy for OperatingPoint<T, S>
where
    NodeVector<S, T>: Copy,
    InputVector<S, T>: Copy,
    BoundaryVector<S, T>: Copy,
{
}

impl<T: RealField + Copy, S: Sizes> OperatingPoint<T, S> {
    /// `true` when every vector has the length `sizes` give it (always,
    /// with arrays; a `Vec` of another length is an operating point of
    /// another network).
    pub fn fits(&self, sizes: &S) -> bool {
        self.temps_c.as_ref().len() == sizes.nodes()
            && self.limits_c.as_ref().len() == sizes.nodes()
            && self.currents_a.as_ref().len() == sizes.inputs()
            && self.boundary_c.as_ref().len() == sizes.boundaries()
    }

    /// `true` when every input is finite (a limit may also be `+inf`: an
    /// element that has none).
    pub fn is_finite(&self) -> bool {
        self.temps_c
            .as_ref()
            .iter()
            .chain(self.currents_a.as_ref())
            .chain(self.boundary_c.as_ref())
            .all(|v| v.is_finite())
            && self
                .limits_c
                .as_ref()
                .iter()
                .all(|l| l.is_finite() || *l > T::zero())
    }
}

/// The time-to-limit predictor's configuration for `N` elements, `B`
/// boundaries, `M` windings and `K` horizons, in `T` (`f32` on target):
/// a [`ModalPredictor`] whose vectors are arrays.
///
/// Built once by [`PredictorBuilder::build`], then only read. See the module
/// docs for the method and its guarantee.
pub type LimitPredictor<
    T,
    const N: usize,
    const B: usize,
    const M: usize,
    const K: usize = DEFAULT_GRID_POINTS,
> = ModalPredictor<T, ConstSizes<N, B, M>, K>;

/// The time-to-limit predictor's configuration for a network of sizes `S`
/// and `K` horizons, in `T`: [`LimitPredictor`] on an MCU (arrays), or a
/// model file's network at its own size on a host
/// ([`PredictorBuilder::build_from`] with the `alloc` feature's
/// `RunTimeSizes`). One code: see the
/// module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct ModalPredictor<T: Element, S: Sizes, const K: usize = DEFAULT_GRID_POINTS> {
    /// Positive horizons `t_1 .. t_K` \[s\].
    pub(crate) grid_s: [T; K],
    /// `exp(lambda_j t_k)`, row `k` for `t_{k+1}`.
    pub(crate) decay: [NodeVector<S, T>; K],
    pub(crate) lambda_per_s: NodeVector<S, T>,
    pub(crate) v: NodeVector<S, NodeVector<S, T>>,
    pub(crate) v_inv: NodeVector<S, NodeVector<S, T>>,
    /// Steady rise per watt of each winding \[K/W\].
    pub(crate) gain_power: NodeVector<S, InputVector<S, T>>,
    /// Steady temperature per degree of each boundary (dimensionless).
    pub(crate) gain_boundary: NodeVector<S, BoundaryVector<S, T>>,
    /// Steady rise from the fixed powers \[K\].
    pub(crate) offset_c: NodeVector<S, T>,
    pub(crate) windings: InputVector<S, Winding<T>>,
    pub(crate) sizes: S,
    pub(crate) tick_s: T,
    pub(crate) points_per_tick: usize,
    pub(crate) slowest_time_constant_s: f64,
    /// At most this many element evaluations per sliced tick
    /// ([`PredictorBuilder::elements_per_tick`]).
    pub(crate) elements_per_tick: usize,
}

/// `start + sum(gains * inputs)`, summed in order.
#[inline(always)]
fn dot_onto<T: RealField + Copy, V: AsRef<[T]>>(start: T, gains: &V, inputs: &V) -> T {
    let mut sum = start;
    for (g, x) in gains.as_ref().iter().zip(inputs.as_ref()) {
        sum += *g * *x;
    }
    sum
}

/// The `P`, `Q` and `Q'` of the module docs for one element at one time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Parts<T> {
    /// Sum of the positive modal terms \[K\].
    pub p: T,
    /// Sum of the magnitudes of the negative modal terms \[K\].
    pub q: T,
    /// `dQ/dt` \[K/s\], never positive.
    pub dq: T,
}

impl<T: RealField + Copy> Default for Parts<T> {
    fn default() -> Self {
        Self {
            p: T::zero(),
            q: T::zero(),
            dq: T::zero(),
        }
    }
}

/// A snapshot: steady state, modes and limits at the sweep's start (`V`
/// a vector over the nodes).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Snapshot<V> {
    /// Limit minus steady state \[K\].
    headroom_k: V,
    /// Modal amplitudes `V^-1 (T_0 - T_ss)`.
    modes: V,
    valid: bool,
}

/// How far [`LimitPredictor::evaluate_point`] got.
#[derive(Debug, Clone, Copy, PartialEq)]
struct PointProgress {
    /// The element to resume the point at (`N`: the point is complete).
    next_element: usize,
    /// The sweep is over (every element resolved, or the last point done).
    sweep_over: bool,
    /// Elements evaluated.
    evaluated: usize,
}

/// One element's answer while a sweep runs.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Crossing<T> {
    Open,
    At(T),
    Never,
}

impl<T: RealField + Copy, S: Sizes, const K: usize> ModalPredictor<T, S, K> {
    /// The positive horizons of the grid \[s\].
    pub fn grid_s(&self) -> &[T; K] {
        &self.grid_s
    }

    /// The slowest time constant of the network \[s\] (`-1 / lambda_max`);
    /// make the last horizon a few times this for tight "never" answers.
    pub fn slowest_time_constant_s(&self) -> f64 {
        self.slowest_time_constant_s
    }

    /// The period of [`PredictorState::tick`] \[s\].
    pub fn tick_s(&self) -> T {
        self.tick_s
    }

    /// `op` is finite and this network's (see [`OperatingPoint::fits`]):
    /// otherwise every answer is "unknown" (`Some(NaN)`).
    #[inline(always)]
    pub(super) fn takes(&self, op: &OperatingPoint<T, S>) -> bool {
        op.fits(&self.sizes) && op.is_finite()
    }

    /// Each winding's Joule power \[W\] at the resistance it would have at the
    /// alarm limit of its node (or its present temperature, if higher): the
    /// conservative powers of the module docs.
    pub(super) fn conservative_powers_w(&self, op: &OperatingPoint<T, S>) -> InputVector<S, T> {
        let mut powers = self.sizes.inputs_of(T::zero());
        let windings = powers.as_mut().iter_mut().zip(self.windings.as_ref());
        for ((p, w), i) in windings.zip(op.currents_a.as_ref()) {
            *p = self.conservative_resistance_ohm(w, op) * *i * *i;
        }
        powers
    }

    /// `max(R(T_node), R(L_node))`, floored at zero \[ohm\].
    ///
    /// Taken as `R` of the warmer (or, for a negative slope, the cooler)
    /// of the two temperatures: a rounded multiply-add is monotone, so
    /// that is the larger `R` to the bit, for one `R(T)` instead of two
    /// (a soft-float multiply-add per winding on every predictor stage
    /// of a core without an FPU); both where it is not finite, and on a
    /// core with an FPU.
    pub(super) fn conservative_resistance_ohm(
        &self,
        w: &Winding<T>,
        op: &OperatingPoint<T, S>,
    ) -> T {
        let nan = T::from_subset(&f64::NAN);
        let temp = op.temps_c.as_ref().get(w.node).copied().unwrap_or(nan);
        let limit = op.limits_c.as_ref().get(w.node).copied().unwrap_or(nan);
        let r = larger_resistance_ohm(w, temp, limit);
        if r > T::zero() {
            r
        } else if r.is_finite() {
            T::zero()
        } else {
            nan
        }
    }

    /// Steady state \[degC\] and modal amplitudes for initial temperatures
    /// `temps_c`, winding powers `powers_w` and boundaries `boundary_c`:
    /// `T_ss = Kp p + Kb T_b + k_d`, `z = V^-1 (T_0 - T_ss)`.
    ///
    /// The amplitudes from the difference, not as `V^-1 T_0` less the
    /// modal gains' `V^-1 T_ss`: the two terms are each far larger than
    /// their difference (`V^-1`'s rows sum to a hundred in magnitude for
    /// the real motor, thousands of kelvin at the operating point) and
    /// cancel in `f32`; and it is `N` multiply-adds a row where the gains
    /// took `N + M + B + 1`.
    pub(super) fn steady_and_modes(
        &self,
        temps_c: &NodeVector<S, T>,
        powers_w: &InputVector<S, T>,
        boundary_c: &BoundaryVector<S, T>,
        with_fixed: bool,
    ) -> (NodeVector<S, T>, NodeVector<S, T>) {
        let (steady, mut modes) = self.steady_and_offset(temps_c, powers_w, boundary_c, with_fixed);
        self.to_modes(&mut modes);
        (steady, modes)
    }

    /// The first half of [`Self::steady_and_modes`]: the steady state
    /// \[degC\] and `T_0 - T_ss` \[K\].
    fn steady_and_offset(
        &self,
        temps_c: &NodeVector<S, T>,
        powers_w: &InputVector<S, T>,
        boundary_c: &BoundaryVector<S, T>,
        with_fixed: bool,
    ) -> (NodeVector<S, T>, NodeVector<S, T>) {
        let mut steady = self.sizes.nodes_of(T::zero());
        let rows = steady
            .as_mut()
            .iter_mut()
            .zip(self.gain_power.as_ref())
            .zip(self.gain_boundary.as_ref())
            .zip(self.offset_c.as_ref());
        for (((ss, gp), gb), k) in rows {
            let start = if with_fixed { *k } else { T::zero() };
            *ss = dot_onto(dot_onto(start, gp, powers_w), gb, boundary_c);
        }
        let mut from_steady = self.sizes.nodes_of(T::zero());
        let pairs = temps_c.as_ref().iter().zip(steady.as_ref());
        for (d, (t, ss)) in from_steady.as_mut().iter_mut().zip(pairs) {
            *d = *t - *ss;
        }
        (steady, from_steady)
    }

    /// The second half of [`Self::steady_and_modes`], in place:
    /// `T_0 - T_ss` \[K\] in, the modal amplitudes `V^-1 (T_0 - T_ss)`
    /// \[K\] out.
    #[inline(always)]
    fn to_modes(&self, values: &mut NodeVector<S, T>) {
        let from_steady = values.clone();
        for (z, v_inv_row) in values.as_mut().iter_mut().zip(self.v_inv.as_ref()) {
            *z = mode(v_inv_row, &from_steady);
        }
    }

    /// `P`, `Q`, `Q'` of element `row` (a row of `V`) for modal amplitudes
    /// `modes` at the time whose `exp(lambda t)` is `decay` (all ones: t =
    /// 0, as `c * 1 == c` to the bit).
    #[inline(always)]
    pub(super) fn parts(
        &self,
        row: &NodeVector<S, T>,
        modes: &NodeVector<S, T>,
        decay: &NodeVector<S, T>,
    ) -> Parts<T> {
        let mut parts = Parts::default();
        let terms = (row.as_ref().iter().zip(modes.as_ref()))
            .zip(self.lambda_per_s.as_ref())
            .zip(decay.as_ref());
        for (((v, z), lambda), d) in terms {
            let c = *v * *z;
            let term = c * *d;
            // The sign bit, not `c > 0` (a software compare on a core
            // without an FPU): a zero `c` adds nothing either way.
            if c.is_sign_positive() {
                parts.p += term;
            } else {
                cold_path();
                parts.q -= term;
                parts.dq -= term * *lambda;
            }
        }
        parts
    }

    /// Time \[s\] of grid point `k` (0 is `t = 0`) and its decay row.
    #[inline]
    pub(super) fn point(&self, k: usize) -> Option<(T, Option<&NodeVector<S, T>>)> {
        if k == 0 {
            return Some((T::zero(), None));
        }
        let t = *self.grid_s.get(k - 1)?;
        Some((t, Some(self.decay.get(k - 1)?)))
    }

    fn snapshot(
        &self,
        op: &OperatingPoint<T, S>,
        powers_w: &InputVector<S, T>,
    ) -> Snapshot<NodeVector<S, T>> {
        let mut snapshot = self.steady_snapshot(op, powers_w);
        self.to_modes(&mut snapshot.modes);
        snapshot
    }

    /// A snapshot's first half in one stage: the headroom, and `T_0 -
    /// T_ss` where the modal amplitudes go, for [`Self::to_modes`] to turn
    /// into them. A split sweep takes it in two stages
    /// ([`Self::start_snapshot`], [`Self::finish_steady`]); so does this
    /// one on a core without an FPU (one piece of code: its soft-float
    /// sums dwarf a second pass, and the M0 footprint has no room for
    /// two). On one with an FPU, the rows in one pass with each sum in a
    /// register ([`Self::fused_snapshot`]): in two, the M4F motor's
    /// snapshot tick cost some 50 instructions more (measured). The
    /// three forms are the same to the bit (tested).
    fn steady_snapshot(
        &self,
        op: &OperatingPoint<T, S>,
        powers_w: &InputVector<S, T>,
    ) -> Snapshot<NodeVector<S, T>> {
        if cfg!(target_abi = "eabihf") {
            return self.fused_snapshot(op, powers_w);
        }
        let mut snapshot = Snapshot {
            headroom_k: self.sizes.nodes_of(T::zero()),
            modes: self.sizes.nodes_of(T::zero()),
            valid: true,
        };
        self.start_snapshot(&mut snapshot, powers_w, 0..self.sizes.nodes());
        self.finish_steady(&mut snapshot, op);
        snapshot
    }

    /// [`Self::steady_snapshot`] in one pass over the rows.
    fn fused_snapshot(
        &self,
        op: &OperatingPoint<T, S>,
        powers_w: &InputVector<S, T>,
    ) -> Snapshot<NodeVector<S, T>> {
        let mut snapshot = Snapshot {
            headroom_k: self.sizes.nodes_of(T::zero()),
            modes: self.sizes.nodes_of(T::zero()),
            valid: self.takes(op) && powers_w.as_ref().iter().all(|p| p.is_finite()),
        };
        let gains = self
            .gain_power
            .as_ref()
            .iter()
            .zip(self.gain_boundary.as_ref());
        let node = (self.offset_c.as_ref().iter())
            .zip(op.temps_c.as_ref())
            .zip(op.limits_c.as_ref());
        let rows = snapshot
            .headroom_k
            .as_mut()
            .iter_mut()
            .zip(snapshot.modes.as_mut())
            .zip(gains)
            .zip(node);
        for (((h, d), (gp, gb)), ((k, t), l)) in rows {
            let steady = dot_onto(dot_onto(*k, gp, powers_w), gb, &op.boundary_c);
            *d = *t - steady;
            *h = *l - steady;
        }
        snapshot
    }

    /// A snapshot's first part (a split sweep's first stages): `headroom_k`
    /// takes the steady state's sum over the fixed powers and the
    /// windings' `powers_w` \[W\] for the rows in `rows` (the snapshot is
    /// valid if the powers are finite, set with the first row), for
    /// [`Self::finish_steady`] to complete.
    #[cfg_attr(not(target_abi = "eabihf"), inline(never))]
    fn start_snapshot(
        &self,
        snapshot: &mut Snapshot<NodeVector<S, T>>,
        powers_w: &InputVector<S, T>,
        rows: Range<usize>,
    ) {
        if rows.start == 0 {
            snapshot.valid = powers_w.as_ref().iter().all(|p| p.is_finite());
        }
        let all = snapshot
            .headroom_k
            .as_mut()
            .iter_mut()
            .zip(self.gain_power.as_ref())
            .zip(self.offset_c.as_ref());
        for (r, ((sum, gp), k)) in all.enumerate() {
            if rows.contains(&r) {
                *sum = dot_onto(*k, gp, powers_w);
            }
        }
    }

    /// Rows of [`Self::start_snapshot`] a split sweep's stage forms: as
    /// many products as an amplitude stage's `elements_per_tick` rows of
    /// `N` (each row is `M` products), at least one.
    fn windings_rows_per_stage(&self) -> usize {
        let (n, m) = (self.sizes.nodes(), self.sizes.inputs());
        self.elements_per_tick.saturating_mul((n / m.max(1)).max(1))
    }

    /// A snapshot's second part (a split sweep's second stage): the
    /// steady state completed with `op`'s boundaries, each row summed as
    /// `k_d + Kp p + Kb T_b` in one pass would be, to the bit; the
    /// headroom to `op`'s limits; and `T_0 - T_ss` from `op`'s
    /// temperatures, where the modal amplitudes go, for [`Self::to_modes`]
    /// to turn into them (valid if `op` is finite too).
    fn finish_steady(&self, snapshot: &mut Snapshot<NodeVector<S, T>>, op: &OperatingPoint<T, S>) {
        snapshot.valid &= self.takes(op);
        let rows = snapshot
            .headroom_k
            .as_mut()
            .iter_mut()
            .zip(snapshot.modes.as_mut())
            .zip(self.gain_boundary.as_ref())
            .zip(op.temps_c.as_ref())
            .zip(op.limits_c.as_ref());
        for ((((h, d), gb), t), l) in rows {
            let steady = dot_onto(*h, gb, &op.boundary_c);
            *d = *t - steady;
            *h = *l - steady;
        }
    }

    /// Evaluates grid point `k` for the open elements from `first` on, at
    /// most `budget` of them (elements without a limit are resolved at no
    /// cost). Not inlined: inlined into the Omnimagnet's tick (since its
    /// state's flavour made the tick generic, instantiated in the
    /// firmware's crate) it made the predictor's stages about 200
    /// instructions dearer (`observer_m4`: combined worst 6 914 -> 7 048).
    ///
    /// `HALVES`: whether `half` may be `Some` (an element in two stages).
    /// With an FPU the sweep without halves keeps a copy of its own, the
    /// code it had before them (one test per element cost the M4F network's
    /// worst tick 14 instructions, measured); without one, one copy for
    /// both (a second would cost the M0 footprint its room).
    // The sweep's pieces one by one: borrowed from a `PredictorState` or
    // from `full_sweep`'s locals.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn evaluate_point<const HALVES: bool>(
        &self,
        snapshot: &Snapshot<NodeVector<S, T>>,
        k: usize,
        first: usize,
        budget: usize,
        prev: &mut NodeVector<S, Parts<T>>,
        sweep: &mut NodeVector<S, Crossing<T>>,
        half: Option<&mut Option<Parts<T>>>,
    ) -> PointProgress {
        let mut half = if HALVES { half } else { None };
        let n = self.sizes.nodes();
        let over = PointProgress {
            next_element: n,
            sweep_over: true,
            evaluated: 0,
        };
        let Some((t_b, decay)) = self.point(k) else {
            return over;
        };
        if !snapshot.valid {
            *sweep = self.sizes.nodes_of(Crossing::At(T::from_subset(&f64::NAN)));
            if let Some(formed) = half {
                *formed = None;
            }
            return over;
        }
        let t_a = match k {
            0 | 1 => T::zero(),
            _ => self.grid_s.get(k - 2).copied().unwrap_or(T::zero()),
        };
        // `t = 0` decays nothing: one loop for both, without a branch on
        // the decay per mode.
        let ones = self.sizes.nodes_of(T::one());
        // From `first` on by slicing, not `skip`: its `nth` walked the
        // skipped elements (and cost the M0 footprint its code).
        let elements = (sweep
            .as_mut()
            .get_mut(first..)
            .unwrap_or_default()
            .iter_mut())
        .zip(
            prev.as_mut()
                .get_mut(first..)
                .unwrap_or_default()
                .iter_mut(),
        )
        .zip(self.v.as_ref().get(first..).unwrap_or_default())
        .zip(
            snapshot
                .headroom_k
                .as_ref()
                .get(first..)
                .unwrap_or_default(),
        );
        let mut evaluated = 0;
        for (e, (((state, prev), row), &headroom)) in (first..).zip(elements) {
            if *state != Crossing::Open {
                continue;
            }
            if headroom > T::zero() && !headroom.is_finite() {
                // No limit (`+inf`): never, and not worth a horizon.
                *state = Crossing::Never;
                continue;
            }
            if evaluated == budget {
                return PointProgress {
                    next_element: e,
                    sweep_over: false,
                    evaluated,
                };
            }
            // With halves, the element's second stage takes the parts its
            // first formed.
            let now = match half.as_deref_mut().and_then(Option::take) {
                Some(formed) => formed,
                None => {
                    let now = self.parts(row, &snapshot.modes, decay.unwrap_or(&ones));
                    if let Some(slot) = half.as_deref_mut() {
                        // Its first stage: the parts alone.
                        *slot = Some(now);
                        return PointProgress {
                            next_element: e,
                            sweep_over: false,
                            evaluated: evaluated + 1,
                        };
                    }
                    now
                }
            };
            evaluated += 1;
            if k == 0 {
                if now.p - now.q >= headroom {
                    *state = Crossing::At(T::zero());
                }
            } else if let Some(t) = first_crossing(t_a, t_b, prev, &now, headroom) {
                *state = Crossing::At(t);
            }
            *prev = now;
        }
        let last = k >= K;
        if last {
            // The tail beyond t_K: T_e <= T_ss + P(t_K).
            let t_last = self.grid_s.last().copied().unwrap_or(T::zero());
            let elements = (sweep.as_mut().iter_mut())
                .zip(prev.as_ref())
                .zip(snapshot.headroom_k.as_ref());
            for ((state, prev), &headroom) in elements {
                if *state == Crossing::Open {
                    *state = if prev.p < headroom {
                        Crossing::Never
                    } else {
                        Crossing::At(t_last)
                    };
                }
            }
        }
        PointProgress {
            next_element: n,
            sweep_over: last || sweep.as_ref().iter().all(|s| *s != Crossing::Open),
            evaluated,
        }
    }

    /// Every element's time to its alarm limit \[s\] at the operating point
    /// `op` (`None`: never; `Some(0)`: at or past it; `Some(NaN)`: an input
    /// was not finite, or, with `Vec`s, `op` or `out` has another length
    /// than the network's, when every entry of `out` is `Some(NaN)`),
    /// written to `out`. One full sweep: see the module docs for the cost.
    pub fn predict(&self, op: &OperatingPoint<T, S>, out: &mut NodeVector<S, Option<T>>) {
        if out.as_ref().len() != self.sizes.nodes() {
            out.as_mut().fill(Some(T::from_subset(&f64::NAN)));
            return;
        }
        let powers = self.conservative_powers_w(op);
        let sweep = self.full_sweep(op, &powers);
        for (o, s) in out.as_mut().iter_mut().zip(sweep.as_ref()) {
            *o = published(*s, T::zero());
        }
    }

    fn full_sweep(
        &self,
        op: &OperatingPoint<T, S>,
        powers_w: &InputVector<S, T>,
    ) -> NodeVector<S, Crossing<T>> {
        let snapshot = self.snapshot(op, powers_w);
        let mut prev = self.sizes.nodes_of(Parts::default());
        let mut sweep = self.sizes.nodes_of(Crossing::Open);
        for k in 0..=K {
            let progress = self.evaluate_point::<ONE_COPY>(
                &snapshot,
                k,
                0,
                usize::MAX,
                &mut prev,
                &mut sweep,
                None,
            );
            if progress.sweep_over {
                break;
            }
        }
        sweep
    }
}

/// Whether [`ModalPredictor::evaluate_point`] has one copy, with and without
/// halves (a core without an FPU, whose flash is short), or two.
const ONE_COPY: bool = !cfg!(target_abi = "eabihf");

/// One modal amplitude \[K\]: the row `v_inv_row` of `V^-1` times
/// `T_0 - T_ss` (`from_steady`, \[K\]). Not inlined on a core without an
/// FPU, where its soft-float sums dwarf the call and its two callers'
/// copies cost the M0 footprint 400 B.
#[cfg_attr(target_abi = "eabihf", inline(always))]
#[cfg_attr(not(target_abi = "eabihf"), inline(never))]
fn mode<T: RealField + Copy, V: AsRef<[T]>>(v_inv_row: &V, from_steady: &V) -> T {
    let mut m = T::zero();
    for (vi, d) in v_inv_row.as_ref().iter().zip(from_steady.as_ref()) {
        m += *vi * *d;
    }
    m
}

/// Marks the branch that calls it as the unlikely one (Rust 1.95's
/// `core::hint::cold_path`; this crate's MSRV is 1.93): a call the
/// compiler keeps, to a function it knows is cold. In
/// [`ModalPredictor::parts`] it keeps the sign test a branch: without it
/// the compiler unrolled the loop and computed both arms of every mode, a
/// software add, subtract and multiply more per mode on a core without an
/// FPU (the M0 network's worst predictor stage 5 819 -> 6 124
/// instructions; with the mark 5 782).
#[cold]
#[inline(never)]
fn cold_path() {}

/// The larger of a winding's `R` at `temp` and at `limit` \[ohm\] (see
/// [`LimitPredictor::conservative_resistance_ohm`]): `R` of the warmer
/// temperature (the cooler for a negative slope), both `R`s where that is
/// not finite.
#[cfg(not(target_abi = "eabihf"))]
#[inline(always)]
fn larger_resistance_ohm<T: RealField + Copy>(w: &Winding<T>, temp: T, limit: T) -> T {
    if w.slope_ohm_per_k == T::zero() {
        // A constant resistance (a resistor, a loss carried through 1
        // ohm): its `R` at any temperature, with no choice to make (an
        // infinite temperature marks the snapshot invalid all the same).
        return w.r_at_0c_ohm;
    }
    // A NaN temperature is dropped (a NaN `limit` compares with nothing),
    // as `max` of the two `R`s drops its NaN `R`: compares, not `fmaxf`
    // and `fminf` (the M0 footprint).
    let temp_is_warmer = if w.slope_ohm_per_k >= T::zero() {
        temp > limit
    } else {
        temp < limit
    };
    let warmer = if temp_is_warmer || limit.partial_cmp(&limit).is_none() {
        temp
    } else {
        limit
    };
    let r = w.r_at_0c_ohm + w.slope_ohm_per_k * warmer;
    if r.is_finite() {
        r
    } else {
        // An infinity: a zero slope times an infinite temperature is NaN
        // where the other `R` is not.
        both_resistances_ohm(w, temp, limit)
    }
}

/// [`larger_resistance_ohm`] on a core with an FPU, where the two
/// multiply-adds and a `max` cost less than the choice and its test
/// (the real motor's M4F worst tick 20 instructions more): both `R`s.
#[cfg(target_abi = "eabihf")]
#[inline(always)]
fn larger_resistance_ohm<T: RealField + Copy>(w: &Winding<T>, temp: T, limit: T) -> T {
    both_resistances_ohm(w, temp, limit)
}

/// Both of a winding's `R`s, at `temp` and at `limit`, the larger kept
/// \[ohm\]: on a core with an FPU always, elsewhere where an infinity is
/// involved (out of line there: never on a finite operating point).
#[cfg_attr(not(target_abi = "eabihf"), cold, inline(never))]
#[cfg_attr(target_abi = "eabihf", inline(always))]
fn both_resistances_ohm<T: RealField + Copy>(w: &Winding<T>, temp: T, limit: T) -> T {
    if w.slope_ohm_per_k == T::zero() {
        // A constant resistance, as [`larger_resistance_ohm`] takes it.
        return w.r_at_0c_ohm;
    }
    let at = |t: T| w.r_at_0c_ohm + w.slope_ohm_per_k * t;
    let (at_temp, at_limit) = (at(temp), at(limit));
    // `max` as a comparison (a NaN loses, as in `f32::max`): without
    // VMAXNM (ARMv7E-M) `f32::max` is a call to `fmaxf`.
    if at_temp < at_limit || at_temp.partial_cmp(&at_temp).is_none() {
        at_limit
    } else {
        at_temp
    }
}

/// The aged answer: `t - age`, floored at zero; NaN stays NaN.
fn published<T: RealField + Copy>(crossing: Crossing<T>, age_s: T) -> Option<T> {
    match crossing {
        Crossing::Never => None,
        Crossing::Open => Some(T::from_subset(&f64::NAN)),
        Crossing::At(t) => {
            let left = t - age_s;
            // Written so that NaN passes through (`max` would drop it).
            Some(if left < T::zero() { T::zero() } else { left })
        }
    }
}

/// First `t` in `[a, b]` where the bound of the module docs reaches
/// `headroom` (limit minus steady state), from the parts at `a` and `b`.
///
/// The bound is `min(L1, L2)`: `chord_P` minus each tangent of `Q` is a
/// line above `T_e - T_ss,e` of its own (`L1` from the tangent at `a`, `L2`
/// from the one at `b`), and the larger tangent is the smaller line. So
/// the bound is at or above the headroom exactly where both lines are: the
/// intersection of two intervals of `[a, b]`, whose left end is the answer.
/// Written without the kink: the lines' values at the bracket's ends decide
/// the case, and only a bracket the bound reaches the headroom in takes a
/// division (one or two; the kink's form took two in every bracket, each a
/// software routine on a core without an FPU).
#[inline]
fn first_crossing<T: RealField + Copy>(
    a: T,
    b: T,
    at_a: &Parts<T>,
    at_b: &Parts<T>,
    headroom: T,
) -> Option<T> {
    let h = b - a;
    let rise_a = at_a.dq * h;
    let rise_b = at_b.dq * h;
    // Each line at `a` (`start`) and at `b` (`end`).
    let l1 = Line {
        start: at_a.p - at_a.q,
        end: at_b.p - at_a.q - rise_a,
    };
    let l2 = Line {
        start: at_a.p - at_b.q + rise_b,
        end: at_b.p - at_b.q,
    };
    // A line below the headroom over the whole bracket keeps the bound
    // below it (NaN compares false here: no answer from NaN parts).
    if !(l1.reaches(headroom) && l2.reaches(headroom)) {
        return None;
    }
    // Each line's part of `[a, b]` at or above the headroom is `[0, 1]`,
    // `[u, 1]` (rising through it) or `[0, u]` (falling through it), in
    // `u = (t - a) / h`; the answer is the largest lower end if no upper
    // end lies before it.
    let u = match (l1.rises_through(headroom), l2.rises_through(headroom)) {
        (false, false) => return Some(a),
        (true, true) => {
            let (u1, u2) = (l1.crossing(headroom), l2.crossing(headroom));
            if u1 > u2 {
                u1
            } else {
                u2
            }
        }
        (l1_rises, _) => {
            let (rising, other) = if l1_rises { (l1, l2) } else { (l2, l1) };
            let u = rising.crossing(headroom);
            if other.falls_through(headroom) && u > other.crossing(headroom) {
                // The other line falls below the headroom before this
                // one rises to it.
                return None;
            }
            u
        }
    };
    Some(in_bracket(a, h, u))
}

/// `a + u h` for a share `u` of the bracket `[a, a + h]` \[s\], `u` taken
/// into `[0, 1]`: rounding can push a root out of the bracket, and the
/// bound reaches the headroom within it in any case.
#[inline(always)]
fn in_bracket<T: RealField + Copy>(a: T, h: T, u: T) -> T {
    let u = if u < T::one() { u } else { T::one() };
    a + if u > T::zero() { u * h } else { T::zero() }
}

/// One of the bound's two lines over a bracket, by its values at the
/// bracket's ends \[K\].
struct Line<T> {
    start: T,
    end: T,
}

impl<T: RealField + Copy> Line<T> {
    /// At or above `headroom` somewhere in the bracket.
    #[inline(always)]
    fn reaches(&self, headroom: T) -> bool {
        self.start >= headroom || self.end >= headroom
    }

    /// Below `headroom` at the start (so rising through it, given
    /// [`Self::reaches`]).
    #[inline(always)]
    fn rises_through(&self, headroom: T) -> bool {
        self.start < headroom
    }

    /// Below `headroom` at the end.
    #[inline(always)]
    fn falls_through(&self, headroom: T) -> bool {
        self.end < headroom
    }

    /// Where it equals `headroom`, as a share of the bracket (finite for
    /// a line through it: its ends straddle the headroom).
    #[inline(always)]
    fn crossing(&self, headroom: T) -> T {
        (headroom - self.start) / (self.end - self.start)
    }
}

/// Where a [`PredictorState`] keeps its answers (sealed) for the nodes'
/// dimension `D`: every element's time to its limit made at each tick
/// (the dimension's vector of `Option<T>`, `[Option<T>; N]` on an MCU, the
/// default: for an observer that reads them all on every tick, and
/// [`PredictorState::tick`] hands them out), or none ([`AnswersWhenAsked`]).
pub trait Answers<T, D: Length>:
    answers::Store<T, D> + Clone + core::fmt::Debug + PartialEq
{
}

impl<T: Element, const N: usize> Answers<T, Const<N>> for [Option<T>; N] {}
#[cfg(feature = "alloc")]
impl<T: Element> Answers<T, nalgebra::Dyn> for alloc::vec::Vec<Option<T>> {}
impl<T, D: Length> Answers<T, D> for AnswersWhenAsked {}

/// The [`Answers`] that keep every element's (sealed, and of no type
/// parameter, so that no other crate can make [`AnswersWhenAsked`] one):
/// the dimension's vector of `Option<T>`.
pub trait KeptAnswers {}

impl<T, const N: usize> KeptAnswers for [Option<T>; N] {}
#[cfg(feature = "alloc")]
impl<T> KeptAnswers for alloc::vec::Vec<Option<T>> {}

/// The answers kept by no [`PredictorState`]: each element's time to its
/// limit is made when asked ([`PredictorState::time_to_limit_of`]), from
/// the crossings the state keeps anyway. For an observer that reads a few
/// elements' (the Omnimagnet reads its six alarm elements' of 16: 128 B of
/// its state not kept).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct AnswersWhenAsked;

mod answers {
    use crate::sizes::{Element, Length};
    use nalgebra::Const;

    /// Keeps the answers made at each tick, or not.
    pub trait Store<T, D: Length> {
        /// The answers, each element's `make` of its crossing `from`.
        fn made<U: Element + Copy>(from: &D::Array<U>, make: impl FnMut(U) -> Option<T>) -> Self;
        /// Makes them again.
        fn remake<U: Element + Copy>(
            &mut self,
            from: &D::Array<U>,
            make: impl FnMut(U) -> Option<T>,
        );
    }

    impl<T, const N: usize> Store<T, Const<N>> for [Option<T>; N] {
        #[inline(always)]
        fn made<U: Element + Copy>(from: &[U; N], make: impl FnMut(U) -> Option<T>) -> Self {
            from.map(make)
        }
        #[inline(always)]
        fn remake<U: Element + Copy>(
            &mut self,
            from: &[U; N],
            mut make: impl FnMut(U) -> Option<T>,
        ) {
            for (out, crossing) in self.iter_mut().zip(from) {
                *out = make(*crossing);
            }
        }
    }

    #[cfg(feature = "alloc")]
    impl<T> Store<T, nalgebra::Dyn> for alloc::vec::Vec<Option<T>> {
        fn made<U: Element + Copy>(
            from: &alloc::vec::Vec<U>,
            make: impl FnMut(U) -> Option<T>,
        ) -> Self {
            from.iter().copied().map(make).collect()
        }
        fn remake<U: Element + Copy>(
            &mut self,
            from: &alloc::vec::Vec<U>,
            mut make: impl FnMut(U) -> Option<T>,
        ) {
            for (out, crossing) in self.iter_mut().zip(from) {
                *out = make(*crossing);
            }
        }
    }

    impl<T, D: Length> Store<T, D> for super::AnswersWhenAsked {
        #[inline(always)]
        fn made<U: Element + Copy>(_: &D::Array<U>, _: impl FnMut(U) -> Option<T>) -> Self {
            Self
        }
        #[inline(always)]
        fn remake<U: Element + Copy>(&mut self, _: &D::Array<U>, _: impl FnMut(U) -> Option<T>) {}
    }
}

/// The sliced predictor's per-device state: a sweep in progress and the
/// last published answers (as crossings and their age; each element's time
/// to its limit kept too unless `A` is [`AnswersWhenAsked`]).
///
/// Over the network's [`Sizes`] `S`, as its [`ModalPredictor`] (an MCU's
/// [`ConstPredictorState`]).
#[derive(Debug, Clone, PartialEq)]
pub struct PredictorState<T: Element, S: Sizes, A = NodeVector<S, Option<T>>> {
    snapshot: Snapshot<NodeVector<S, T>>,
    prev: NodeVector<S, Parts<T>>,
    sweep: NodeVector<S, Crossing<T>>,
    next_point: usize,
    /// Where the point in progress resumes (split points).
    next_element: usize,
    /// How much of its snapshot the sweep in progress has.
    phase: SweepPhase,
    sweep_age_s: T,
    published: NodeVector<S, Crossing<T>>,
    published_age_s: T,
    peak_power_w: InputVector<S, T>,
    /// The peak powers the sweep in progress took at its start \[W\]
    /// (the peak starts over then), kept while its stages form the
    /// windings' part of its steady state.
    snapshot_power_w: InputVector<S, T>,
    out: A,
}

/// The predictor's state of an MCU's network of `N` nodes, `B` boundaries
/// and `M` windings, keeping every element's answer.
pub type ConstPredictorState<T, const N: usize, const B: usize, const M: usize> =
    PredictorState<T, ConstSizes<N, B, M>>;

/// An element's modal parts formed by the first of its two stages, for its
/// second ([`PredictorState::tick_in_halves`]); empty between elements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HalfElement<T> {
    formed: Option<Parts<T>>,
}

impl<T> HalfElement<T> {
    /// Nothing formed.
    pub const fn new() -> Self {
        Self { formed: None }
    }
}

impl<T> Default for HalfElement<T> {
    fn default() -> Self {
        Self::new()
    }
}

/// How much of its snapshot a [`PredictorState`]'s sweep has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SweepPhase {
    /// No sweep runs: the next stage takes a snapshot.
    Idle,
    /// A split sweep forms the windings' part of its steady state, some
    /// rows a stage from `next_element` on
    /// ([`LimitPredictor::start_snapshot`]).
    Windings,
    /// A split sweep has the windings' part of its steady state: the
    /// next stage completes it with the boundaries, the headroom and `T_0
    /// - T_ss` ([`LimitPredictor::finish_steady`]).
    Powers,
    /// A split sweep has its steady state and `T_0 - T_ss`: the next
    /// stages form its modal amplitudes (from `next_element` on, into
    /// `prev`, until the last moves them into the snapshot).
    Steady,
    /// The snapshot is whole: the stages evaluate horizons.
    Sweeping,
}

impl<T: RealField + Copy, S: Sizes, A: Answers<T, S::NodeDim>> PredictorState<T, S, A> {
    /// A state whose first answers come from one full sweep at `op` (see
    /// [`PredictorState::new`]).
    fn build<const K: usize>(
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
    ) -> Self {
        let powers = predictor.conservative_powers_w(op);
        let first = predictor.full_sweep(op, &powers);
        Self {
            snapshot: predictor.snapshot(op, &powers),
            prev: predictor.sizes.nodes_of(Parts::default()),
            sweep: predictor.sizes.nodes_of(Crossing::Open),
            next_point: 0,
            next_element: 0,
            phase: SweepPhase::Idle,
            sweep_age_s: T::zero(),
            out: A::made(&first, |c| published(c, T::zero())),
            published: first,
            published_age_s: T::zero(),
            peak_power_w: powers.clone(),
            snapshot_power_w: powers,
        }
    }

    /// Element `i`'s time to its alarm limit \[s\] of the last tick, as
    /// `time_to_limit_s` has it (`None` too for no such element).
    pub fn time_to_limit_of(&self, i: usize) -> Option<T> {
        let crossing = *self.published.as_ref().get(i)?;
        published(crossing, self.published_age_s)
    }

    /// The tick of [`PredictorState::tick`], its answers kept as `A` keeps
    /// them.
    #[inline(always)]
    fn advance<const K: usize>(
        &mut self,
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
        mut half: Option<&mut HalfElement<T>>,
    ) {
        if self.phase != SweepPhase::Sweeping {
            // Parts formed for another sweep (or another state) are not
            // this one's.
            if let Some(half) = half.as_deref_mut() {
                half.formed = None;
            }
        }
        let tick_s = predictor.tick_s;
        self.sweep_age_s += tick_s;
        self.published_age_s += tick_s;
        let powers = predictor.conservative_powers_w(op);
        for (peak, p) in self.peak_power_w.as_mut().iter_mut().zip(powers.as_ref()) {
            // NaN must win here: it marks the snapshot invalid.
            if matches!(
                (*peak).partial_cmp(p),
                Some(core::cmp::Ordering::Less) | None
            ) {
                *peak = *p;
            }
        }
        let n = predictor.sizes.nodes();
        let split = predictor.elements_per_tick < n;
        let mut budget = predictor.elements_per_tick;
        for _ in 0..predictor.points_per_tick {
            if self.phase != SweepPhase::Sweeping {
                if split {
                    // The snapshot is stages of its own.
                    self.snapshot_stage(predictor, op, &powers);
                    break;
                }
                self.snapshot = predictor.steady_snapshot(op, &self.peak_power_w);
                self.peak_power_w.clone_from(&powers);
                self.sweep = predictor.sizes.nodes_of(Crossing::Open);
                self.sweep_age_s = T::zero();
                predictor.to_modes(&mut self.snapshot.modes);
                self.phase = SweepPhase::Sweeping;
            }
            let slot = half.as_deref_mut().map(|h| &mut h.formed);
            let (snapshot, point, first) = (&self.snapshot, self.next_point, self.next_element);
            let progress = if !ONE_COPY && slot.is_none() {
                predictor.evaluate_point::<false>(
                    snapshot,
                    point,
                    first,
                    budget,
                    &mut self.prev,
                    &mut self.sweep,
                    None,
                )
            } else {
                predictor.evaluate_point::<true>(
                    snapshot,
                    point,
                    first,
                    budget,
                    &mut self.prev,
                    &mut self.sweep,
                    slot,
                )
            };
            budget = budget.saturating_sub(progress.evaluated);
            if progress.next_element < n {
                self.next_element = progress.next_element;
                break;
            }
            self.next_element = 0;
            self.next_point += 1;
            if progress.sweep_over {
                self.published.clone_from(&self.sweep);
                self.published_age_s = self.sweep_age_s;
                self.next_point = 0;
                self.phase = SweepPhase::Idle;
                break;
            }
            if budget == 0 {
                break;
            }
        }
        let age = self.published_age_s;
        self.out
            .remake(&self.published, |crossing| published(crossing, age));
    }
}

impl<T: RealField + Copy, S: Sizes, A: Answers<T, S::NodeDim>> PredictorState<T, S, A> {
    /// One stage of a split sweep's snapshot (at this tick's `op` and
    /// conservative `powers_w` \[W\]), stages of their own: the windings'
    /// part of the steady state at their peak powers; its boundaries'
    /// part, the headroom and `T_0 - T_ss` at that stage's `op` (the
    /// answers age from the first stage: conservative); the modal
    /// amplitudes, `elements_per_tick` a stage. The same snapshot as one
    /// stage's, to the bit, for
    /// the same inputs. Not inlined: a sweep that is not split never runs
    /// it, and inlined it moved the M4F's worst ticks by up to 50
    /// instructions (measured).
    #[inline(never)]
    fn snapshot_stage<const K: usize>(
        &mut self,
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
        powers_w: &InputVector<S, T>,
    ) {
        let n = predictor.sizes.nodes();
        match self.phase {
            SweepPhase::Idle | SweepPhase::Windings => {
                if self.phase == SweepPhase::Idle {
                    // The sweep starts at the peak so far; the next peak
                    // starts over.
                    self.snapshot_power_w.clone_from(&self.peak_power_w);
                    self.peak_power_w.clone_from(powers_w);
                    self.sweep = predictor.sizes.nodes_of(Crossing::Open);
                    self.sweep_age_s = T::zero();
                    self.next_element = 0;
                }
                // The windings' part, some rows a stage, at the powers
                // frozen at the start.
                let first = self.next_element;
                let end = first
                    .saturating_add(predictor.windings_rows_per_stage())
                    .min(n);
                predictor.start_snapshot(&mut self.snapshot, &self.snapshot_power_w, first..end);
                if end < n {
                    self.next_element = end;
                    self.phase = SweepPhase::Windings;
                } else {
                    self.next_element = 0;
                    self.phase = SweepPhase::Powers;
                }
            }
            SweepPhase::Powers => {
                predictor.finish_steady(&mut self.snapshot, op);
                self.phase = SweepPhase::Steady;
            }
            SweepPhase::Steady | SweepPhase::Sweeping => {
                // `elements_per_tick` amplitudes a stage (each a row of
                // `V^-1`, cheaper than an element's horizon), kept in
                // `prev` (its first point sets it before reading it) so
                // that `T_0 - T_ss` stays whole until the last.
                let first = self.next_element;
                let end = first.saturating_add(predictor.elements_per_tick).min(n);
                let rows = self.prev.as_mut().get_mut(first..end).unwrap_or_default();
                let v_inv = predictor.v_inv.as_ref().get(first..end).unwrap_or_default();
                for (slot, v_inv_row) in rows.iter_mut().zip(v_inv) {
                    slot.p = mode(v_inv_row, &self.snapshot.modes);
                }
                if end < n {
                    self.next_element = end;
                    return;
                }
                let modes = self.snapshot.modes.as_mut().iter_mut();
                for (z, slot) in modes.zip(self.prev.as_ref()) {
                    *z = slot.p;
                }
                self.next_element = 0;
                self.phase = SweepPhase::Sweeping;
            }
        }
    }
}

impl<T: RealField + Copy, S: Sizes> PredictorState<T, S>
where
    NodeVector<S, Option<T>>: KeptAnswers + Answers<T, S::NodeDim>,
{
    /// A state whose first answers come from one full sweep at `op` (build
    /// time cost, so the first ticks already publish valid times).
    pub fn new<const K: usize>(
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
    ) -> Self {
        Self::build(predictor, op)
    }
}

impl<T: RealField + Copy, S: Sizes, A: KeptAnswers + Answers<T, S::NodeDim>>
    PredictorState<T, S, A>
{
    /// One tick: ages the published answers by the predictor's `tick_s`,
    /// evaluates `points_per_tick` horizons (or at most
    /// `elements_per_tick` elements, or the snapshot alone, when split) of
    /// the sweep in progress
    /// (starting a new sweep from `op` when none is), and returns every
    /// element's time to its alarm limit \[s\] (`None`: never), ready for
    /// [`AlarmState::tick`](super::alarm::AlarmState::tick).
    ///
    /// Bounded (`points_per_tick` horizons), allocation-free, panic-free.
    pub fn tick<const K: usize>(
        &mut self,
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
    ) -> &A {
        self.advance(predictor, op, None);
        &self.out
    }

    /// [`tick`](Self::tick) with each element's horizon in two stages, for
    /// a sweep of one element a stage on a core without an FPU: the
    /// element's modal parts, held in `half` (the caller's, so that a state
    /// that never halves keeps its size), then its crossing. The same
    /// answers as [`tick`](Self::tick)'s to the bit, each sweep taking its
    /// horizons' stages twice; a stage bounded by the heavier half.
    ///
    /// Bounded, allocation-free, panic-free.
    pub fn tick_in_halves<const K: usize>(
        &mut self,
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
        half: &mut HalfElement<T>,
    ) -> &A {
        self.advance(predictor, op, Some(half));
        &self.out
    }

    /// [`tick_in_halves`](Self::tick_in_halves) with `Some(half)`, else
    /// [`tick`](Self::tick): one copy of the tick for a caller that
    /// chooses at run time.
    pub(crate) fn tick_with<const K: usize>(
        &mut self,
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
        half: Option<&mut HalfElement<T>>,
    ) {
        self.advance(predictor, op, half);
    }

    /// The answers of the last [`tick`](Self::tick) \[s\].
    pub fn time_to_limit_s(&self) -> &A {
        &self.out
    }
}

impl<T: RealField + Copy, S: Sizes> PredictorState<T, S, AnswersWhenAsked> {
    /// [`PredictorState::new`] for a state that keeps no answers.
    pub fn when_asked<const K: usize>(
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
    ) -> Self {
        Self::build(predictor, op)
    }

    /// One tick, as [`PredictorState::tick`] of a state that keeps its
    /// answers: they are made when asked
    /// ([`time_to_limit_of`](Self::time_to_limit_of),
    /// [`time_to_limit_s`](Self::time_to_limit_s)).
    ///
    /// Bounded (`points_per_tick` horizons), allocation-free, panic-free.
    pub fn tick<const K: usize>(
        &mut self,
        predictor: &ModalPredictor<T, S, K>,
        op: &OperatingPoint<T, S>,
    ) {
        self.advance(predictor, op, None);
    }

    /// Every element's time to its alarm limit \[s\] of the last tick
    /// (`None`: never), made now.
    pub fn time_to_limit_s(&self) -> NodeVector<S, Option<T>> {
        let age = self.published_age_s;
        S::NodeDim::mapped(&self.published, |crossing| published(*crossing, age))
    }
}

#[cfg(test)]
#[path = "predict_tests.rs"]
mod tests;

/// Downtime cooling: the network's exact zero-current solution, from the
/// modes the predictor already holds (issue 17).
impl<T: RealField + Copy, S: Sizes, const K: usize> ModalPredictor<T, S, K> {
    /// The temperatures \[degC\] the network reaches from `temps_c` after
    /// `off_s` \[s\] with no current and the boundaries held at
    /// `boundary_c` \[degC\] (and the fixed powers on): the exact
    ///
    /// ```text
    /// T(off) = T_ss + V diag(exp(lambda off)) V^-1 (T_saved - T_ss),   T_ss = Kb T_b + k_d,
    /// ```
    ///
    /// each mode decayed on its own, plus a guard that covers the rounding
    /// of `T` (`1 mK` plus `64 N eps` times the magnitudes summed), so the
    /// result is never below the exact cooled state of the network. `O(N^2)`
    /// work and `N` exponentials, no matrix exponential, no allocation, no
    /// panic.
    ///
    /// `off_s == 0` returns `temps_c` to the bit; an off time that is not a
    /// number or negative means "unknown" and returns `temps_c` too (no
    /// cooling: the saved state is never below the cooled one); `+inf` (or
    /// any off time far beyond [`Self::slowest_time_constant_s`]) gives the
    /// steady state plus the guard. A result that is not finite (non-finite
    /// inputs) also falls back to `temps_c`, and so do vectors of another
    /// length than the network's (with `Vec`s).
    pub fn cooled_c(
        &self,
        temps_c: &NodeVector<S, T>,
        boundary_c: &BoundaryVector<S, T>,
        off_s: T,
    ) -> NodeVector<S, T> {
        // Not positive, or NaN: unknown, no cooling; so are vectors of
        // another network (`Vec`s of other lengths).
        let fits = temps_c.as_ref().len() == self.sizes.nodes()
            && boundary_c.as_ref().len() == self.sizes.boundaries();
        if !fits || off_s.partial_cmp(&T::zero()) != Some(core::cmp::Ordering::Greater) {
            return temps_c.clone();
        }
        let no_power = self.sizes.inputs_of(T::zero());
        let (steady, modes) = self.steady_and_modes(temps_c, &no_power, boundary_c, true);
        let mut decay = self.lambda_per_s.clone();
        for d in decay.as_mut() {
            *d = (*d * off_s).exp();
        }
        let eps = T::default_epsilon();
        let guard_factor = T::from_subset(&(64.0 * self.sizes.nodes() as f64)) * eps;
        let floor_k = T::from_subset(&1e-3);
        let mut out = temps_c.clone();
        let rows = self.v.as_ref().iter().zip(steady.as_ref());
        for (o, (row, ss)) in out.as_mut().iter_mut().zip(rows) {
            let mut sum = *ss;
            let mut magnitude = ss.abs();
            let terms = row.as_ref().iter().zip(modes.as_ref()).zip(decay.as_ref());
            for ((v, z), d) in terms {
                let c = *v * *z;
                sum += c * *d;
                magnitude += c.abs();
            }
            *o = sum + floor_k + guard_factor * magnitude;
        }
        if out.as_ref().iter().all(|t| t.is_finite()) {
            out
        } else {
            temps_c.clone()
        }
    }
}
