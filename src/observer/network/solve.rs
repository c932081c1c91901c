//! The solve over sizes: what the settings alone decide (the clock, the
//! periods), the filter's configuration and its steady gain in the bias
//! layout the settings ask for. Run by the MCU builder's
//! [`NetworkObserverBuilder::parts`](super::NetworkObserverBuilder::parts)
//! (`Const` sizes, into tables) and by a host's run-time build (`Dyn`);
//! the assembly ([`super::assemble`]) reads its results.

use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, U1};

use super::bias::{nominal_powers_w, shared_in_prior, tie_block, BiasLayout, BiasModeOf};
use super::resistance::{sensor_variances_k2, SensorKind};
use super::{ModelOf, NetworkSettings, ObserverAllocator, PREDICTOR_POINTS};
use crate::error::{check, BuildError};
use crate::filter::{KalmanConfig, SteadyStateGain};
use crate::network::NetworkDescription;
use crate::observer::clock::StepClock;
use crate::observer::tables::invalid;
use crate::protect::predict::{ModalPredictor, PredictorBuilder};
use crate::sizes::{InputVector, Length, NodeVector, Sizes};

/// What the settings alone decide: the clock, the protection period \[us\]
/// and the correction period (model steps).
pub(super) struct Timing {
    pub(super) clock: StepClock,
    pub(super) protect_period_us: u32,
    pub(super) correction_period: u32,
}

/// The state has the offset's entry exactly when the settings ask for a
/// boundary offset, on a boundary that exists.
pub(super) fn check_offset(
    s: &NetworkSettings,
    (n, b, m): (usize, usize, usize),
    states: usize,
) -> Result<(), BuildError> {
    let wanted = s.boundary_offset.is_some_and(|o| o < b);
    check(
        s.boundary_offset.is_none_or(|o| o < b) && (states == n + m + 1) == wanted,
        "boundary_offset",
    )
}

pub(super) fn timing(s: &NetworkSettings) -> Result<Timing, BuildError> {
    check(s.origin_c.is_finite(), "origin_c")?;
    let nonneg = |v: f64| v.is_finite() && v >= 0.0;
    check(
        s.sensor_sigma_k.is_finite() && s.sensor_sigma_k > 0.0,
        "sensor_sigma_k",
    )?;
    check(nonneg(s.node_noise_k2_per_s), "node_noise_k2_per_s")?;
    check(nonneg(s.bias_noise_w2_per_s), "bias_noise_w2_per_s")?;
    check(nonneg(s.bias_tau_s), "bias_tau_s")?;
    if s.boundary_offset.is_some() {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        check(positive(s.boundary_offset_std_k), "boundary_offset_std_k")?;
        check(positive(s.boundary_offset_tau_s), "boundary_offset_tau_s")?;
    }
    check(nonneg(s.recovery_sigma_k), "recovery_sigma_k")?;
    check(nonneg(s.recovery_bias_sigma_w), "recovery_bias_sigma_w")?;
    s.checks.validate()?;
    check(
        nonneg(s.max_cooling_bias_fraction),
        "max_cooling_bias_fraction",
    )?;
    let clock = StepClock::new(s.step_us, s.max_steps_per_tick)?
        .with_frozen_limits(s.frozen_flag_ticks, s.frozen_loss_ticks)?;
    let period = s.protect_period_steps;
    let protect_period_us = period
        .checked_mul(s.step_us)
        .filter(|_| period >= 4 * s.max_steps_per_tick)
        .ok_or(BuildError::InvalidParameter {
            name: "protect_period_steps",
        })?;
    let ratio = s.correction_period_s / clock.step_s();
    check(
        ratio.is_finite() && (0.5..=f64::from(u32::MAX)).contains(&ratio),
        "correction_period_s",
    )?;
    Ok(Timing {
        clock,
        protect_period_us,
        correction_period: (libm::round(ratio) as u32).max(1),
    })
}

/// How the heat-input biases are laid out, over sizes, borrowed.
pub(super) type BiasChoice<'a, Z> = BiasModeOf<&'a InputVector<Z, bool>>;

/// What both builds solve, in this order (the builder's `parts` at an
/// MCU's sizes, the run-time build at a model's own): the model over one
/// step, the steady gain in the bias layout asked for, the time-to-limit
/// predictor over the protection's cycle, and the model over the shadow's
/// block of one correction period.
pub(super) struct Solution<Z: Sizes, X: Length, P: Length>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    pub(super) timing: Timing,
    pub(super) model: ModelOf<Z>,
    pub(super) gain: SteadyStateGain<f32, X, P>,
    pub(super) predictor: ModalPredictor<f32, Z, PREDICTOR_POINTS>,
    pub(super) block: ModelOf<Z>,
}

/// What the gain solve reads of a builder, over sizes.
pub(super) struct GainSpec<'a, Z: Sizes, P: Length> {
    pub(super) settings: &'a NetworkSettings,
    pub(super) sensor_nodes: &'a P::Array<usize>,
    pub(super) kinds: &'a P::Array<SensorKind>,
    pub(super) critical_c: &'a NodeVector<Z, Option<f64>>,
    pub(super) hardware_limit_a: &'a InputVector<Z, f64>,
    pub(super) bias_sources: &'a InputVector<Z, bool>,
    pub(super) bias_mode: BiasChoice<'a, Z>,
}

impl<Z: Sizes, P: Length> GainSpec<'_, Z, P> {
    /// The [`Solution`] of `network` with `states` filter states.
    ///
    /// # Errors
    /// The settings' timing refused, a network that does not discretise,
    /// a gain that does not converge (or leaves a limited element
    /// unobserved), a predictor that does not build.
    pub(super) fn solve<W: NetworkDescription<Sizes = Z>, X: Length>(
        &self,
        network: &W,
        states: X,
    ) -> Result<Solution<Z, X, P>, BuildError>
    where
        DefaultAllocator: ObserverAllocator<Z, X, P>,
    {
        let s = self.settings;
        let timing = timing(s)?;
        let dt_s = timing.clock.step_s();
        let model = ModelOf::build(network, dt_s, s.origin_c)?;
        let gain = self.solve_biased_gain(&model, timing.correction_period, states)?;
        let predictor = PredictorBuilder::new()
            .tick_s(dt_s * f64::from(s.protect_period_steps))
            .elements_per_tick(elements_per_stage(s))
            .build_from(network)?;
        let block_s = dt_s * f64::from(timing.correction_period);
        let block = ModelOf::build(network, block_s, s.origin_c)?;
        Ok(Solution {
            timing,
            model,
            gain,
            predictor,
            block,
        })
    }

    /// Whether `gain` leaves every limited element within
    /// `max_element_sigma_k` (the check of
    /// [`NetworkObserver::from_parts`], which refuses it otherwise).
    fn observes_limited<X: Length>(&self, gain: &SteadyStateGain<f32, X, P>) -> bool
    where
        DefaultAllocator: ObserverAllocator<Z, X, P>,
    {
        self.critical_c
            .as_ref()
            .iter()
            .enumerate()
            .all(|(node, critical)| {
                let sigma_k = libm::sqrtf(gain.prior[(node, node)].max(0.0));
                self.settings
                    .checks
                    .observable(node, critical.is_some(), f64::from(sigma_k))
                    .is_ok()
            })
    }

    /// The steady gain in the layout the bias mode asks for: per source,
    /// shared, or per source with the shared bias as the fallback when the
    /// per-source solve does not converge ([`BiasMode::Auto`](super::BiasMode::Auto)). Without
    /// bias noise every mode is per source (nothing is driven, nothing to
    /// share).
    pub(super) fn solve_biased_gain<X: Length>(
        &self,
        model: &ModelOf<Z>,
        period: u32,
        states: X,
    ) -> Result<SteadyStateGain<f32, X, P>, BuildError>
    where
        DefaultAllocator: ObserverAllocator<Z, X, P>,
    {
        let s = self.settings;
        let n = model.ad.nrows();
        let per_source = || BiasLayout::<Z::InputDim>::per_source(self.bias_sources.clone());
        let shared = |mask: &InputVector<Z, bool>| {
            if s.bias_noise_w2_per_s <= 0.0 {
                return None;
            }
            let nominal_w = nominal_powers_w::<Z::InputDim>(
                self.hardware_limit_a,
                &model.resistance,
                s.origin_c,
            );
            BiasLayout::shared(self.bias_sources.clone(), mask, &nominal_w)
        };
        let all = Z::InputDim::mapped(self.bias_sources, |_| true);
        let sensor_var_k2 = sensor_variances_k2::<P>(self.kinds, s.sensor_sigma_k);
        let solve =
            |layout: &BiasLayout<Z::InputDim>| -> Result<SteadyStateGain<f32, X, P>, BuildError> {
                let gain = solve_gain(
                    model,
                    (self.sensor_nodes, &sensor_var_k2),
                    s,
                    layout,
                    period,
                    states,
                )?;
                // The tables must say which biases are shared (`from_parts`
                // reads it back from the prior alone): a tie the rounding broke,
                // or a per-source solution correlated to the bit, is refused
                // rather than assembled into another observer.
                let read = if s.bias_noise_w2_per_s > 0.0 {
                    shared_in_prior(layout.shared_mask_dim(), n, |i, j| gain.prior[(i, j)])
                } else {
                    Z::InputDim::mapped(self.bias_sources, |_| false)
                };
                if read == layout.shared_mask() {
                    Ok(gain)
                } else {
                    Err(BuildError::NotConverged {
                        name: "steady_state_gain",
                    })
                }
            };
        match self.bias_mode {
            BiasModeOf::PerSource => solve(&per_source()),
            BiasModeOf::Shared(mask) => solve(&shared(mask).unwrap_or_else(per_source)),
            BiasModeOf::Auto => match solve(&per_source()) {
                Err(refused @ BuildError::NotConverged { .. }) => match shared(&all) {
                    Some(layout) => solve(&layout).map_err(|_| refused),
                    None => Err(refused),
                },
                // Converged, but to biases so uncertain that a limited
                // element is left unobservable (`from_parts` would refuse
                // it): the sensors cannot tell the biases apart either, to
                // rounding. The shared bias if it does better.
                Ok(gain) if !self.observes_limited(&gain) => match shared(&all) {
                    Some(layout) => match solve(&layout) {
                        Ok(shared) if self.observes_limited(&shared) => Ok(shared),
                        _ => Ok(gain),
                    },
                    None => Ok(gain),
                },
                solved => solved,
            },
        }
    }
}

/// `Ad`, `Bd` of the powers and `Gd` of the boundaries, in `f64`.
pub(super) type DiscreteF64<'a, Z> = (
    &'a OMatrix<f64, <Z as Sizes>::NodeDim, <Z as Sizes>::NodeDim>,
    &'a OMatrix<f64, <Z as Sizes>::NodeDim, <Z as Sizes>::InputDim>,
    &'a OMatrix<f64, <Z as Sizes>::NodeDim, <Z as Sizes>::BoundaryDim>,
);

/// `F = [[Ad, Bd_p], [0, I]]`, `H` from the sensor map, `Q`, `R` and the
/// gate, in `f64` (the filter's configuration; its gain is solved apart).
/// A bias left out of `bias_sources` gets neither process noise nor
/// recovery widening.
///
/// The shared bias (see [`BiasLayout`]) enters in one of two coordinates:
/// `reduced`, the gain solve's, where the lead shared source's slot holds
/// the shared bias `S` (its column of `F` is `Bd w`, its noise `q`) and the
/// other shared slots are idle (no column, no noise), so the random walks
/// the sensors cannot tell apart are never driven; or the state's, where
/// every shared source's bias is `w_m S`: the rank-one noise `q w w^T` and
/// a recovery widening of `w_m^2` times the bias's (the configuration the
/// tick's warm-up runs). Without a shared source both are today's.
pub(super) fn filter_config<Z: Sizes, X: Length, P: Length>(
    (ad, bd_power, gd_boundary): DiscreteF64<'_, Z>,
    (sensor_nodes, sensor_var_k2): (&P::Array<usize>, &P::Array<f64>),
    s: &NetworkSettings,
    layout: &BiasLayout<Z::InputDim>,
    reduced: bool,
    (dt_s, states): (f64, X),
) -> Result<KalmanConfig<f64, X, U1, P>, BuildError>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    let (n, m) = (ad.nrows(), bd_power.ncols());
    let sensors = P::from_usize(sensor_nodes.as_ref().len());
    let lead = layout.lead();
    let mut f = OMatrix::<f64, X, X>::identity_generic(states, states);
    for i in 0..n {
        for j in 0..n {
            f[(i, j)] = ad[(i, j)];
        }
        for k in 0..m {
            // The bias adds to the Joule power, so it enters like it.
            f[(i, n + k)] = if reduced && layout.is_shared(k) {
                if Some(k) == lead {
                    (0..m).map(|q| bd_power[(i, q)] * layout.share_of(q)).sum()
                } else {
                    0.0
                }
            } else {
                bd_power[(i, k)]
            };
        }
    }
    if s.bias_tau_s > 0.0 {
        // Gauss-Markov biases (`bias_tau_s`): each decays alike, so the
        // shared bias's reduced slot decays as the biases it stands for.
        let decay = libm::exp(-dt_s / s.bias_tau_s);
        for k in (0..m).filter(|k| layout.is_biased(*k)) {
            f[(n + k, n + k)] = decay;
        }
    }
    let mut h = OMatrix::<f64, P, X>::zeros_generic(sensors, states);
    for (j, node) in sensor_nodes.as_ref().iter().enumerate() {
        h[(j, *node)] = 1.0;
    }
    let mut q = OMatrix::<f64, X, X>::zeros_generic(states, states);
    let mut recovery = OVector::<f64, X>::zeros_generic(states, U1);
    let offset = s.boundary_offset.filter(|_| states.value() == n + m + 1);
    if let Some(b) = offset {
        // The offset enters like its boundary (`Gd`'s column), and decays.
        for i in 0..n {
            f[(i, n + m)] = gd_boundary[(i, b)];
        }
        f[(n + m, n + m)] = libm::exp(-dt_s / s.boundary_offset_tau_s);
    }
    for i in 0..n + m {
        let (noise, widen) = if i < n {
            (s.node_noise_k2_per_s, s.recovery_sigma_k)
        } else if layout.is_shared(i - n) {
            // Set below.
            (0.0, 0.0)
        } else if layout.is_biased(i - n) {
            (s.bias_noise_w2_per_s, s.recovery_bias_sigma_w)
        } else {
            (0.0, 0.0)
        };
        q[(i, i)] = noise * dt_s;
        recovery[i] = widen * widen;
    }
    if offset.is_some() {
        let variance_k2 = s.boundary_offset_std_k * s.boundary_offset_std_k;
        q[(n + m, n + m)] = 2.0 * variance_k2 / s.boundary_offset_tau_s * dt_s;
        recovery[n + m] = variance_k2;
    }
    if let Some(lead) = lead {
        let q_shared = s.bias_noise_w2_per_s * dt_s;
        let widen_w2 = s.recovery_bias_sigma_w * s.recovery_bias_sigma_w;
        if reduced {
            q[(n + lead, n + lead)] = q_shared;
            recovery[n + lead] = widen_w2;
        } else {
            for a in (0..m).filter(|a| layout.is_shared(*a)) {
                for b in (0..m).filter(|b| layout.is_shared(*b)) {
                    q[(n + a, n + b)] = q_shared * (layout.share_of(a) * layout.share_of(b));
                }
                recovery[n + a] = widen_w2 * layout.share_of(a) * layout.share_of(a);
            }
        }
    }
    // Each sensor's own noise (a thermocouple's `sensor_sigma_k^2`).
    let r = OVector::<f64, P>::from_iterator_generic(
        sensors,
        U1,
        sensor_var_k2.as_ref().iter().copied(),
    );
    // The input enters the mean predict only (see `Model`): the filter's
    // `G` is a placeholder column the gain solver never reads.
    let g = OMatrix::<f64, X, U1>::zeros_generic(states, U1);
    KalmanConfig::new(f, g, h, q, r)?
        .with_gate(s.gate_threshold)?
        .with_suspect_after(s.suspect_after)
        .with_recovery(s.recover_after, recovery)
}

#[inline(never)]
fn solve_gain<Z: Sizes, X: Length, P: Length>(
    model: &ModelOf<Z>,
    (sensor_nodes, sensor_var_k2): (&P::Array<usize>, &P::Array<f64>),
    s: &NetworkSettings,
    layout: &BiasLayout<Z::InputDim>,
    period: u32,
    states: X,
) -> Result<SteadyStateGain<f32, X, P>, BuildError>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    let kalman = filter_config::<Z, X, P>(
        (&model.ad, &model.bd_power_f64, &model.gd_boundary_f64),
        (sensor_nodes, sensor_var_k2),
        s,
        layout,
        true,
        (model.dt_s, states),
    )?;
    let mut gain = SteadyStateGain::solve(&kalman, period)?;
    let (n, m) = (model.ad.nrows(), layout.sources());
    // A left-out bias (and an idle shared slot) is never driven, so its
    // row and column of every table is zero in exact arithmetic; the
    // doubling's inverse may leave rounding there, and an exact zero is
    // what `from_parts` reads back.
    let lead = layout.lead();
    for k in (0..m).filter(|k| !layout.is_biased(*k) || (layout.is_shared(*k) && Some(*k) != lead))
    {
        let i = n + k;
        gain.gain.row_mut(i).fill(0.0);
        gain.prior_ht.row_mut(i).fill(0.0);
        for cov in [&mut gain.prior, &mut gain.posterior] {
            cov.row_mut(i).fill(0.0);
            cov.column_mut(i).fill(0.0);
        }
    }
    let Some(lead) = lead else {
        return Ok(gain.cast());
    };
    // Back to the state's coordinates: bias `m` is `w_m S` with `S` in the
    // lead's slot, `x = T y` (`T` the identity but for the shared columns).
    let mut t = OMatrix::<f64, X, X>::identity_generic(states, states);
    for k in (0..m).filter(|k| layout.is_shared(*k)) {
        t[(n + k, n + k)] = 0.0;
        t[(n + k, n + lead)] = layout.share_of(k);
    }
    let spread = |cov: &OMatrix<f64, X, X>| (&t * cov * t.transpose()).symmetric_part();
    gain.gain = &t * &gain.gain;
    gain.prior_ht = &t * &gain.prior_ht;
    gain.prior = spread(&gain.prior);
    gain.posterior = spread(&gain.posterior);
    let sources = Z::InputDim::from_usize(m);
    let diag = |cov: &OMatrix<f64, X, X>| sources.each(|k| cov[(n + k, n + k)]);
    let (prior_w2, posterior_w2) = (diag(&gain.prior), diag(&gain.posterior));
    let mut cast: SteadyStateGain<f32, X, P> = gain.cast();
    let shared = layout.shared_mask();
    tie_block(&mut cast.prior, n, prior_w2.as_ref(), shared.as_ref());
    tie_block(
        &mut cast.posterior,
        n,
        posterior_w2.as_ref(),
        shared.as_ref(),
    );
    Ok(cast)
}

/// Refuses [`NetworkSettings::correction_in_two_ticks`] where it does not
/// apply: on a core with an FPU, whose whole correction is a light tick
/// and whose observer compiles no second tick (see the state's
/// `floors_due`), and with a model step no longer than the loop's tick,
/// where the second tick would always step.
pub(super) const fn two_tick_corrections(s: &NetworkSettings) -> Result<(), BuildError> {
    if !s.correction_in_two_ticks {
        return Ok(());
    }
    if cfg!(target_abi = "eabihf") {
        return Err(invalid(
            "correction_in_two_ticks (for a core without an FPU; this target has one)",
        ));
    }
    if s.step_us <= s.loop_tick_us() {
        return Err(invalid(
            "correction_in_two_ticks (needs step_us longer than the loop's tick)",
        ));
    }
    Ok(())
}

/// The predictor's element evaluations per stage
/// ([`NetworkSettings::predictor_elements_per_stage`]; 0: unbounded).
pub(super) const fn elements_per_stage(s: &NetworkSettings) -> usize {
    match s.predictor_elements_per_stage {
        0 => usize::MAX,
        n => n as usize,
    }
}
