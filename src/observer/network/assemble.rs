//! The network observer assembled from its solved pieces, written once
//! for every size.
//!
//! [`NetworkObserver::from_parts`](super::NetworkObserver::from_parts)
//! reads an MCU's tables (arrays, in flash) into these pieces; a host
//! with a model read at run time (`Dyn` sizes) solves them at the model's
//! own size. Either way [`NetworkObserverOf::assemble`] checks them and
//! derives the rest (the filter's configuration, the protection, the
//! shadow, the fingerprint) by the same code, so an observer of `Const`
//! and one of `Dyn` sizes from the same model hold the same numbers.

use nalgebra::{DefaultAllocator, OMatrix, OVector, U1};

use super::bias::{nominal_powers_w, shared_in_prior, BiasLayout};
use super::resistance::{check_kinds, sensor_variances_k2, SensorKind};
use super::solve::{check_offset, filter_config, timing, two_tick_corrections};
use super::{NetworkObserverOf, NetworkSettings, ObserverAllocator, NO_LIMIT_C, PREDICTOR_POINTS};
use crate::discretize::fixed::FixedStep;
use crate::error::{check, BuildError};
use crate::filter::{FilterAllocator, SteadyStateGain};
use crate::input::InputLimits;
use crate::network::{DeviationResistance, ScalarResistance};
use crate::observer::consistency::{BiasBound, Shadow};
use crate::observer::snapshot::Fingerprint;
use crate::protect::alarm::AlarmBuilder;
use crate::protect::derating::{DeratingFactor, DeratingRule};
use crate::protect::limiter::LimiterConfig;
use crate::protect::margin::{UncertaintyMargin, UpperBound, UpperBoundBuilder};
use crate::protect::predict::ModalPredictor;
use crate::sizes::{InputVector, Length, NetworkAllocator, NodeVector, Sizes};

/// One step of the discretised network in the observer's deviation
/// coordinates: `x' = x + (Ad - I) x + Bd p + Gd y + c`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StepMatrices<Z: Sizes>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    /// `Ad - I` (dimensionless).
    pub(crate) phi_minus_i: OMatrix<f32, Z::NodeDim, Z::NodeDim>,
    /// `Bd` of the powers \[K/J\].
    pub(crate) bd_power: OMatrix<f32, Z::NodeDim, Z::InputDim>,
    /// `Gd` of the boundaries (dimensionless).
    pub(crate) gd_boundary: OMatrix<f32, Z::NodeDim, Z::BoundaryDim>,
    /// `c` \[K\].
    pub(crate) constant_k: OVector<f32, Z::NodeDim>,
}

impl<Z: Sizes> StepMatrices<Z>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    fn is_finite(&self) -> bool {
        let finite = |v: &f32| v.is_finite();
        self.phi_minus_i.iter().all(finite)
            && self.bd_power.iter().all(finite)
            && self.gd_boundary.iter().all(finite)
            && self.constant_k.iter().all(finite)
    }

    /// The step in integer arithmetic ([`FixedStep::of_entries`]); `None`
    /// where the tables do not fit its scales (an MCU's tables are
    /// `const`, made by `ConstFixedStep::of`).
    #[cfg(feature = "alloc")]
    pub(crate) fn fixed(&self, sizes: Z) -> Option<FixedStep<Z>> {
        FixedStep::of_entries(
            sizes,
            |i, j| self.phi_minus_i[(i, j)],
            |i, m| self.bd_power[(i, m)],
            |i, b| self.gd_boundary[(i, b)],
            |i| self.constant_k[i],
        )
    }
}

/// The model step and the shadow's block in integer arithmetic, each if
/// any.
pub(crate) type IntegerSteps<Z> = (Option<FixedStep<Z>>, Option<FixedStep<Z>>);

/// What [`NetworkObserverOf::assemble`] reads: the builder's inputs and
/// the solved tables, in `f32` as the observer holds them.
pub(crate) struct Solved<Z: Sizes, X: Length, P: Length>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    pub(crate) sizes: Z,
    pub(crate) sensor_nodes: P::Array<usize>,
    pub(crate) kinds: P::Array<SensorKind>,
    pub(crate) critical_c: NodeVector<Z, Option<f64>>,
    pub(crate) derating_product: f64,
    pub(crate) hardware_limit_a: InputVector<Z, f64>,
    pub(crate) incidence: NodeVector<Z, InputVector<Z, bool>>,
    /// `Ad` of the model step, the filter's `F`.
    pub(crate) ad: OMatrix<f32, Z::NodeDim, Z::NodeDim>,
    pub(crate) step: StepMatrices<Z>,
    pub(crate) source_node: InputVector<Z, usize>,
    pub(crate) resistance: InputVector<Z, ScalarResistance<f32>>,
    pub(crate) gain: SteadyStateGain<f32, X, P>,
    pub(crate) predictor: ModalPredictor<f32, Z, PREDICTOR_POINTS>,
    /// The shadow's block step and its length in model steps.
    pub(crate) block: (StepMatrices<Z>, u32),
    /// The model step and the shadow's block in integer arithmetic, as
    /// the settings ask (an error where they cannot be).
    pub(crate) integer: Result<IntegerSteps<Z>, BuildError>,
}

impl<Z: Sizes, X: Length, P: Length> NetworkObserverOf<Z, X, P>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    /// Checks the solved pieces against each other and `s`, and derives
    /// the observer from them (see the module docs).
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming what is inconsistent (see
    /// [`NetworkObserver::from_parts`](super::NetworkObserver::from_parts)).
    pub(crate) fn assemble(
        s: &NetworkSettings,
        solved: Solved<Z, X, P>,
    ) -> Result<Self, BuildError> {
        let Solved {
            sizes,
            sensor_nodes,
            kinds,
            critical_c,
            derating_product,
            hardware_limit_a,
            incidence,
            ad,
            step,
            source_node,
            resistance,
            gain,
            predictor,
            block: (block, block_steps),
            integer,
        } = solved;
        let (n, m) = (sizes.nodes(), sizes.inputs());
        let states = gain.prior.shape_generic().0;
        let timing = timing(s)?;
        check_offset(s, (n, sizes.boundaries(), m), states.value())?;
        check(sensor_nodes.as_ref().iter().all(|i| *i < n), "sensor_nodes")?;
        check(s.ambient_boundary < sizes.boundaries(), "ambient_boundary")?;
        check(
            critical_c
                .as_ref()
                .iter()
                .all(|c| c.is_none_or(|c| c.is_finite() && c < NO_LIMIT_C)),
            "critical_c",
        )?;
        check(
            hardware_limit_a
                .as_ref()
                .iter()
                .all(|a| a.is_finite() && *a > 0.0),
            "hardware_limit_a",
        )?;
        check(source_node.as_ref().iter().all(|i| *i < n), "source_node")?;
        check_kinds(kinds.as_ref(), sensor_nodes.as_ref(), source_node.as_ref())?;
        let sensor_var_k2 = sensor_variances_k2::<P>(&kinds, s.sensor_sigma_k);
        let finite = |v: &f32| v.is_finite();
        check(
            resistance
                .as_ref()
                .iter()
                .all(|r| r.r_at_0c_ohm.is_finite() && r.slope_ohm_per_k.is_finite())
                && ad.iter().all(finite)
                && step.is_finite(),
            "model",
        )?;
        check(gain.period == timing.correction_period, "gain.period")?;
        check(
            gain.gain.iter().all(finite)
                && gain.prior.iter().all(finite)
                && gain.posterior.iter().all(finite)
                && gain.innovation_var.iter().all(finite)
                && gain.prior_ht.iter().all(finite)
                && gain.innovation_cov.iter().all(finite),
            "gain",
        )?;
        check(
            solved_with(&gain, sensor_nodes.as_ref(), sensor_var_k2.as_ref()),
            "sensor_kinds",
        )?;
        let input_limits = InputLimits {
            max_current_a: s.max_current_a,
            ..InputLimits::default()
        };
        input_limits
            .validate()
            .map_err(|_| BuildError::InvalidParameter {
                name: "max_current_a",
            })?;
        check(
            block_steps == timing.correction_period,
            "shadow.block_steps",
        )?;
        check(block.is_finite(), "shadow")?;
        let (integer_step, integer_block) = match integer {
            Ok(steps) => (Ok(steps.0), steps.1),
            Err(e) => (Err(e), None),
        };
        // Refused below without the feature, so always `None` then.
        #[cfg(not(feature = "integer-step"))]
        let _ = integer_block;
        let band = s.checks.band();
        let shadow = Shadow {
            bias_bound: BiasBound::new(&band, &block.phi_minus_i, &block.bd_power),
            phi_minus_i: block.phi_minus_i,
            bd_power: block.bd_power,
            gd_boundary: block.gd_boundary,
            constant_k: block.constant_k,
            block_steps,
            waits_for_light_tick: s.step_us > s.loop_tick_us(),
            #[cfg(feature = "integer-step")]
            integer_block,
            band,
        };

        // The filter's configuration from the stored `Ad` and `Bd` (exact
        // in `f64`, so its `f32` image is the solved one to the bit).
        let nominal_w = nominal_powers_w::<Z::InputDim>(&hardware_limit_a, &resistance, s.origin_c);
        let layout = layout_of(s, &gain, n, sizes.input_dim(), &nominal_w);
        let kalman = filter_config::<Z, X, P>(
            (
                &ad.cast::<f64>(),
                &step.bd_power.clone().cast(),
                &step.gd_boundary.clone().cast(),
            ),
            (&sensor_nodes, &sensor_var_k2),
            s,
            &layout,
            false,
            (timing.clock.step_s(), states),
        )?
        .cast::<f32>();
        let limited = Z::NodeDim::mapped(&critical_c, |c| c.is_some());
        let critical = Z::NodeDim::mapped(&critical_c, |c| c.unwrap_or(NO_LIMIT_C));
        let rule = DeratingRule::new(&[DeratingFactor::new("derating_product", derating_product)])?;
        let alarm = AlarmBuilder::of(&rule, critical)
            .nominal_ambient_c(s.origin_c)
            .build::<f32>()?;
        // The taper's factor per element, scaled by each current's
        // hardware limit afterwards (see "Limits per current").
        let limiter = LimiterConfig::of(&sizes.nodes_of(1.0), s.taper_k, 0.0)?;
        for (node, critical) in critical_c.as_ref().iter().enumerate() {
            let sigma_k = libm::sqrtf(gain.prior[(node, node)].max(0.0));
            s.checks
                .observable(node, critical.is_some(), f64::from(sigma_k))?;
        }
        let bound = upper_bound(&sizes, &gain, sensor_nodes.as_ref(), s)?;

        let mut fingerprint = Fingerprint::new()
            .u32(s.step_us)
            .u32(timing.correction_period)
            .u32(s.protect_period_steps)
            .f64(s.origin_c)
            .f64(s.taper_k);
        for v in kalman.f().iter().chain(gain.gain.iter()) {
            fingerprint = fingerprint.f64(f64::from(*v));
        }
        for v in step.bd_power.iter().chain(step.gd_boundary.iter()) {
            fingerprint = fingerprint.f64(f64::from(*v));
        }
        fingerprint = fingerprint.f64s(hardware_limit_a.as_ref());
        for n in sensor_nodes.as_ref() {
            fingerprint = fingerprint.u32(*n as u32);
        }
        // A resistance sensor's conversion too (a thermocouple-only
        // observer's fingerprint as before sensor kinds).
        for r in kinds.as_ref().iter().filter_map(SensorKind::resistance) {
            fingerprint = fingerprint
                .u32(r.source as u32)
                .f64(r.r_at_0c_ohm)
                .f64(r.slope_ohm_per_k)
                .f64(r.sigma_k());
        }
        // The protection too: a saved latch and temperatures were judged
        // against these limits (as the grid's and the Omnimagnet's).
        for row in incidence.as_ref() {
            for heats in row.as_ref() {
                fingerprint = fingerprint.u32(u32::from(*heats));
            }
        }
        let fingerprint = bound.fingerprint(limiter.fingerprint(alarm.fingerprint(fingerprint)));
        let integer_step = integer_step?;
        two_tick_corrections(s)?;
        // Refused above without the feature, so always `None` here then.
        #[cfg(not(feature = "integer-step"))]
        let _ = integer_step;
        let origin_c = s.origin_c as f32;
        Ok(Self {
            phi_minus_i: step.phi_minus_i,
            bd_power: step.bd_power,
            gd_boundary: step.gd_boundary,
            constant_k: step.constant_k,
            origin_c,
            resistance: Z::InputDim::mapped(&resistance, |r| {
                DeviationResistance::about(r, origin_c)
            }),
            source_node,
            kalman,
            resistance_sensors: P::mapped(&kinds, |k| k.resistance().map(|r| r.conversion())),
            noise_allowance_k: P::mapped(&kinds, |k| {
                k.resistance()
                    .map_or(0.0, |r| (libm::sqrt(s.gate_threshold) * r.sigma_k()) as f32)
            }),
            sensor_nodes,
            limited,
            incidence,
            hardware_limit_a: Z::InputDim::mapped(&hardware_limit_a, |a| *a as f32),
            alarm,
            limiter,
            predictor,
            bound,
            k_sigma: s.k_sigma as f32,
            bound_sigma_k: sizes
                .node_dim()
                .each(|i| libm::sqrtf(gain.prior[(i, i)].max(0.0))),
            gain,
            shadow,
            warmup_corrections: s.warmup_corrections,
            cooling_bias_fraction: s.max_cooling_bias_fraction as f32,
            bias_decay_per_step: if s.bias_tau_s > 0.0 {
                (timing.clock.step_s() / s.bias_tau_s) as f32
            } else {
                0.0
            },
            offset_boundary: s.boundary_offset,
            decays: s.bias_tau_s > 0.0 || s.boundary_offset.is_some(),
            #[cfg(not(target_abi = "eabihf"))]
            correction_in_two_ticks: s.correction_in_two_ticks,
            offset_decay_per_step: if s.boundary_offset.is_some() {
                (timing.clock.step_s() / s.boundary_offset_tau_s) as f32
            } else {
                0.0
            },
            shared_bias: layout.shared_mask(),
            nominal_power_w: sizes.input_dim().each(|k| {
                if layout.is_shared(k) {
                    nominal_w.as_ref()[k] as f32
                } else {
                    0.0
                }
            }),
            stuck_test: s.checks.stuck_test(s.correction_period_s),
            silent_after_us: timing
                .correction_period
                .saturating_mul(s.step_us)
                .saturating_mul(2),
            clock: timing.clock,
            limits: input_limits.to_scalar(),
            ambient_boundary: s.ambient_boundary,
            max_reading_age_us: s.max_reading_age_us,
            step_us: s.step_us,
            loop_period_us: s.loop_tick_us(),
            protect_period_us: timing.protect_period_us,
            fingerprint: fingerprint.finish(),
            #[cfg(feature = "integer-step")]
            integer_step,
        })
    }
}

/// The bias layout the gain carries (see [`BiasLayout`]): with positive
/// bias noise, a bias of exactly zero steady prior variance was left out,
/// and the biases the prior ties ([`shared_in_prior`]) share one bias, in
/// the nominal shares of `nominal_w` \[W\]; with none, no bias is driven
/// and the flag keeps only the recovery widening (as ever). The biases
/// are the states from `first`.
pub(crate) fn layout_of<X: Length, P: Length, M: Length>(
    s: &NetworkSettings,
    gain: &SteadyStateGain<f32, X, P>,
    first: usize,
    sources: M,
    nominal_w: &M::Array<f64>,
) -> BiasLayout<M>
where
    DefaultAllocator: FilterAllocator<X, U1, P>,
{
    let prior = |i: usize, j: usize| gain.prior[(i, j)];
    let biased =
        sources.each(|k| !(s.bias_noise_w2_per_s > 0.0 && prior(first + k, first + k) == 0.0));
    if s.bias_noise_w2_per_s <= 0.0 {
        return BiasLayout::per_source(biased);
    }
    let tied = shared_in_prior(sources, first, prior);
    match BiasLayout::shared(biased.clone(), &tied, nominal_w) {
        Some(layout) => layout,
        None => BiasLayout::per_source(biased),
    }
}

/// Whether `gain`'s innovation variances were solved with the sensor
/// noises `sensor_var_k2` \[K^2\]: `S_jj = M_nn + r_j` for sensor `j` on
/// node `n`, to the `f32` rounding of the tables (a relative 1e-4; the
/// noises of a thermocouple and of a resistance sensor differ by tens of
/// times).
fn solved_with<X: Length, P: Length>(
    gain: &SteadyStateGain<f32, X, P>,
    sensor_nodes: &[usize],
    sensor_var_k2: &[f64],
) -> bool
where
    DefaultAllocator: FilterAllocator<X, U1, P>,
{
    sensor_nodes
        .iter()
        .zip(sensor_var_k2)
        .zip(gain.innovation_var.iter())
        .all(|((node, r), s)| {
            let prior = gain.prior.get((*node, *node)).copied().unwrap_or(f32::NAN);
            let s = f64::from(*s);
            (s - f64::from(prior) - r).abs() <= 1e-4 * s
        })
}

/// `k sigma` from the steady prior on every node, the model margin on the
/// nodes no sensor measures.
pub(crate) fn upper_bound<Z: Sizes, X: Length, P: Length>(
    sizes: &Z,
    gain: &SteadyStateGain<f32, X, P>,
    sensor_nodes: &[usize],
    s: &NetworkSettings,
) -> Result<UpperBound<f32, Z::NodeDim>, BuildError>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    let prior = gain.prior();
    let sigma_k = sizes
        .node_dim()
        .each(|i| libm::sqrt(f64::from(prior[(i, i)]).max(0.0)));
    let mut margins = sizes.nodes_of(s.unmeasured_margin);
    for node in sensor_nodes {
        if let Some(m) = margins.as_mut().get_mut(*node) {
            *m = UncertaintyMargin::ZERO;
        }
    }
    UpperBoundBuilder::of(margins)
        .sigma(s.k_sigma, sigma_k)
        .build()
}
