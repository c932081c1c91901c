//! The network observer's protection (the operating point and the mean
//! limits, the answers' ageing, the published upper bound, the alarm and
//! the limiter) and its stages in the protection cycle
//! ([`crate::observer::cycle`]), written once for every size.

use super::*;

/// The protection's stages, written once for every size.
impl<Z: Sizes, X: Length, P: Length> NetworkObserverOf<Z, X, P>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
    NodeVector<Z, Option<f32>>: KeptAnswers + Answers<f32, Z::NodeDim>,
{
    pub(super) fn ambient(&self, boundary_c: &BoundaryVector<Z, f32>) -> f32 {
        boundary_c
            .as_ref()
            .get(self.ambient_boundary)
            .copied()
            .unwrap_or(self.origin_c)
    }

    /// The predictor's operating point; its limits from `mean_limits`,
    /// formed again only when the ambient moved.
    #[inline(never)]
    pub(super) fn operating(
        &self,
        mean_limits: &mut AmbientLimits<Z::NodeDim>,
        temps_c: &NodeVector<Z, f32>,
        currents_a: &InputVector<Z, f32>,
        boundary_c: &BoundaryVector<Z, f32>,
        ambient_c: f32,
    ) -> OperatingPoint<f32, Z> {
        let limits_c = mean_limits
            .at(ambient_c, |ambient_c| self.mean_limits_c(ambient_c))
            .clone();
        OperatingPoint {
            temps_c: temps_c.clone(),
            currents_a: currents_a.clone(),
            boundary_c: boundary_c.clone(),
            limits_c,
        }
    }

    /// Each node's limit for the predictor at `ambient_c` \[degC\]: the
    /// mean's temperature at which the upper bound reaches the alarm limit,
    /// `+inf` for a node without a limit or a winding.
    fn mean_limits_c(&self, ambient_c: f32) -> NodeVector<Z, f32> {
        // In place over the alarm limits (`from_fn`'s closure, out of line,
        // cost the Cortex-M0 footprint 160 B).
        let mut limits_c = self.alarm.alarm_limits_c(ambient_c);
        let critical_c = self.alarm.critical_c().as_ref();
        let source_node = self.source_node.as_ref();
        for (i, limit_c) in limits_c.as_mut().iter_mut().enumerate() {
            let unlimited = critical_c.get(i).is_some_and(|c| *c >= NO_LIMIT_C as f32);
            *limit_c = match self.bound.element(i) {
                // No limit and no winding (whose power is taken at its
                // node's limit, which must be finite): "never" without a
                // horizon, so that a sweep ends once the limited elements
                // are resolved, however many unlimited nodes there are.
                _ if unlimited && !source_node.contains(&i) => f32::INFINITY,
                // The predictor follows the mean towards the temperature at
                // which the upper bound reaches the alarm limit.
                Some(bound) => bound.mean_limit_c(*limit_c, ambient_c),
                None => NO_LIMIT_C as f32,
            };
        }
        limits_c
    }

    // One copy on a core without an FPU (the cycle ages in two places).
    #[cfg_attr(not(target_abi = "eabihf"), inline(never))]
    fn age_time_to_limit<W>(&self, state: &mut NetworkObserverStateOf<Z, X, P, W>) {
        let lag_s = state.cycle.lag_s();
        let ttl = state.predictor.time_to_limit_s();
        for ((time, answer), limited) in state
            .outputs
            .time_to_limit_s
            .as_mut()
            .iter_mut()
            .zip(ttl.as_ref())
            .zip(self.limited.as_ref())
        {
            *time = if *limited {
                aged_time_to_limit(*answer, lag_s)
            } else {
                None
            };
        }
    }

    /// Publishes every node's upper bound: of the estimate, and while a
    /// sensor's measurement is in doubt, on every limited element of the
    /// hotter of the estimate's and the shadow's (see
    /// [`Suspicion`](super::consistency::Suspicion); the Omnimagnet's rule:
    /// the nodes exchange heat, so what a lying sensor dragged on its node
    /// is felt by the others' estimates).
    ///
    /// With `widen`, while a warm-up holds its own covariance, each bound
    /// is widened by it ([`start::bound_extra_k`]).
    pub(super) fn publish_upper<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        ambient_c: f32,
        widen: bool,
    ) {
        let out = &mut state.outputs;
        self.bound
            .upper_c(&out.temps_c, ambient_c, &mut out.upper_c);
        if let (true, Some(cov)) = (widen && state.warmup_left > 0, state.warm.held()) {
            // The covariance held, not the steady one (see `super::start`).
            let sigmas = out
                .upper_c
                .as_mut()
                .iter_mut()
                .zip(self.bound_sigma_k.as_ref());
            for (i, (upper, sigma)) in sigmas.enumerate() {
                let variance = cov.get((i, i)).copied().unwrap_or(f32::NAN);
                *upper += start::bound_extra_k(variance, *sigma, self.k_sigma);
            }
        }
        if !state.suspect.any() {
            return;
        }
        let shadow_c = Z::NodeDim::mapped(state.shadow.devs_k(), |dev_k| self.origin_c + dev_k);
        let limited = self.limited.as_ref();
        let limited = (0..limited.len()).filter(|i| limited.get(*i).copied().unwrap_or(false));
        protect_on_shadow(&self.bound, &shadow_c, ambient_c, &mut out.upper_c, limited);
    }

    /// The derated alarm on the published upper bounds at `ambient_c`
    /// \[degC\], at the kept limits where there are (see
    /// [`Self::kept_alarm_limits_c`]).
    #[inline(always)]
    fn alarm_tick<W>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        ambient_c: f32,
    ) -> AlarmStatus {
        let derating_c = state.alarm.derating_ambient_c(ambient_c);
        let kept = self.kept_alarm_limits_c(&mut state.alarm_limits, derating_c);
        let out = &state.outputs;
        state.alarm.tick_at_limits(
            &self.alarm,
            &out.upper_c,
            ambient_c,
            kept.as_ref(),
            &out.time_to_limit_s,
            &mut state.events,
        )
    }

    /// The derated alarm limits \[degC\] at `ambient_c` \[degC\].
    #[inline(always)]
    fn alarm_limits_c(
        &self,
        kept: &mut KeptAlarmLimits<Z::NodeDim>,
        ambient_c: f32,
    ) -> NodeVector<Z, f32> {
        self.kept_alarm_limits_c(kept, ambient_c)
            .unwrap_or_else(|| self.alarm.alarm_limits_c(ambient_c))
    }

    /// The derated alarm limits \[degC\] at `ambient_c` \[degC\] as `kept`
    /// has them. On a core without an FPU they are formed again only when
    /// the ambient moved (each is a derating, four soft-float routines:
    /// the Cortex-M0's alarm and limiter stages about 900 and 1 100
    /// instructions less), out of line as the two stages share it. On a
    /// core with an FPU none are kept (`None`: formed where they are used,
    /// the alarm derating its own): kept, they cost the M4F's network
    /// ticks up to 7 instructions more on average (measured).
    #[cfg(not(target_abi = "eabihf"))]
    #[inline(always)]
    fn kept_alarm_limits_c(
        &self,
        kept: &mut KeptAlarmLimits<Z::NodeDim>,
        ambient_c: f32,
    ) -> Option<NodeVector<Z, f32>> {
        Some(self.kept_limits_at(kept, ambient_c))
    }

    /// The body of [`Self::kept_alarm_limits_c`] on a core without an FPU
    /// (a `Some` the compiler sees, so that the alarm's own derating is not
    /// linked: the 2-node Cortex-M0 footprint 1 032 B).
    #[cfg(not(target_abi = "eabihf"))]
    #[inline(never)]
    fn kept_limits_at(
        &self,
        kept: &mut KeptAlarmLimits<Z::NodeDim>,
        ambient_c: f32,
    ) -> NodeVector<Z, f32> {
        kept.at(ambient_c, |a| self.alarm.alarm_limits_c(a)).clone()
    }

    /// See the other [`Self::kept_alarm_limits_c`].
    #[cfg(target_abi = "eabihf")]
    #[inline(always)]
    fn kept_alarm_limits_c(
        &self,
        _: &mut KeptAlarmLimits<Z::NodeDim>,
        _: f32,
    ) -> Option<NodeVector<Z, f32>> {
        None
    }

    /// The limiter at the published upper bounds and the alarm limits at
    /// `ambient_c` \[degC\] (from `kept`, see [`Self::alarm_limits_c`]): a
    /// taper factor per limited element, each current held at its
    /// hardware limit times the smallest factor of the elements it heats.
    pub(super) fn limit(
        &self,
        out: &mut FilteredOutputs<Z::NodeDim, Z::InputDim, Z::NodeDim, P>,
        kept: &mut KeptAlarmLimits<Z::NodeDim>,
        ambient_c: f32,
    ) {
        let mut limits_c = self.alarm_limits_c(kept, ambient_c);
        // Only the limited elements' factors are read below: an infinite
        // limit makes the limiter pass the others over at the cost of a
        // test (their taper, root and weight are soft-float on an M0).
        for (limit_c, limited) in limits_c.as_mut().iter_mut().zip(self.limited.as_ref()) {
            if !limited {
                *limit_c = f32::INFINITY;
            }
        }
        let mut factors = Z::NodeDim::filled_like(&self.limited, CoilLimit::<f32>::default());
        self.limiter
            .apply(&out.upper_c, &limits_c, ambient_c, &mut factors);
        for (m, (limit, hardware_a)) in out
            .limits
            .as_mut()
            .iter_mut()
            .zip(self.hardware_limit_a.as_ref())
            .enumerate()
        {
            let mut factor = 1.0f32;
            let mut weight = 1.0f32;
            let mut invalid = false;
            let rows = factors.as_ref().iter().zip(self.incidence.as_ref());
            for ((f, row), limited) in rows.zip(self.limited.as_ref()) {
                if *limited && row.as_ref().get(m).copied().unwrap_or(false) {
                    // Comparisons (a NaN loses, as in `f32::min`): without
                    // VMAXNM `f32::min` is a call to `fminf`.
                    if f.current_a < factor {
                        factor = f.current_a;
                    }
                    if f.weight < weight {
                        weight = f.weight;
                    }
                    invalid |= f.invalid;
                }
            }
            *limit = CoilLimit {
                current_a: if invalid { 0.0 } else { hardware_a * factor },
                weight: if invalid { 0.0 } else { weight },
                invalid,
            };
        }
    }
}

/// The network observer's protection stages; the cycle's rules are
/// [`ProtectionStages::run_due`]'s.
impl<Z: Sizes, X: Length, P: Length, W> ProtectionStages<Z::InputDim>
    for Protecting<'_, NetworkObserverOf<Z, X, P>, NetworkObserverStateOf<Z, X, P, W>>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
    NodeVector<Z, Option<f32>>: KeptAnswers + Answers<f32, Z::NodeDim>,
    W: Flavour<OMatrix<f32, X, X>>,
{
    #[inline(always)]
    fn cycle_and_held(&mut self) -> (&mut ProtectionCycle<Z::InputDim>, &InputVector<Z, f32>) {
        (&mut self.state.cycle, &self.state.held_currents_a)
    }

    #[inline(always)]
    fn predictor_slice_us(&self) -> u32 {
        self.observer.protect_period_us
    }

    #[inline(always)]
    fn predict(&mut self) {
        let (observer, state) = (self.observer, &mut *self.state);
        let op = observer.operating(
            &mut state.mean_limits,
            &state.outputs.temps_c,
            state.cycle.peak_currents_a(),
            &state.held_boundary_c,
            observer.ambient(&state.held_boundary_c),
        );
        // The smallest stage: half an element's horizon.
        let half = (observer.predictor.elements_per_tick == 1).then_some(&mut state.predictor_half);
        state.predictor.tick_with(&observer.predictor, &op, half);
    }

    #[inline(always)]
    fn alarm(&mut self) {
        let (observer, state) = (self.observer, &mut *self.state);
        let ambient_c = observer.ambient(&state.held_boundary_c);
        // The alarm judges the evidence: the steady bound, also while a
        // warm-up's wider covariance is held (its doubt is the limiter's;
        // see `super::start`).
        observer.publish_upper(state, ambient_c, false);
        state.outputs.alarm = observer.alarm_tick(state, ambient_c);
        if state.warmup_left > 0 && state.warm.held().is_some() {
            observer.publish_upper(state, ambient_c, true);
        }
    }

    #[inline(always)]
    fn limit(&mut self) {
        let (observer, state) = (self.observer, &mut *self.state);
        let ambient_c = observer.ambient(&state.held_boundary_c);
        observer.publish_upper(state, ambient_c, true);
        observer.limit(&mut state.outputs, &mut state.alarm_limits, ambient_c);
    }

    #[inline(always)]
    fn age_time_to_limit(&mut self) {
        self.observer.age_time_to_limit(self.state);
    }
}
