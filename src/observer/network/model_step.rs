//! The network observer's model step (the `f32` step on deviations with
//! its rounding carried, or the integer one; the biases' decay; the
//! shadow model's block), written once for every size.

use super::*;

/// The model step, written once for every size.
impl<Z: Sizes, X: Length, P: Length> NetworkObserverOf<Z, X, P>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    /// `steps` model steps at the held boundaries and the square currents
    /// of the step: `mean_sq_a2` \[A^2\], the account's mean `I^2` when
    /// the held currents changed within the steps, else the held currents
    /// squared. The estimate's and the shadow's (see [`Shadow::stepped`];
    /// `readings`: this tick's). Returns whether a piece put off to a tick
    /// without a step or a reading ran (the shadow's waiting block, or a
    /// correction's move read into the integer step's states): the tick is
    /// busy then.
    #[inline(always)]
    pub(super) fn step_model<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        steps: u32,
        mean_sq_a2: Option<InputVector<Z, f32>>,
        readings: &P::Array<Option<TimedReading>>,
    ) -> bool {
        if steps == 0 {
            let block_stepped = self.shadow.between_steps(
                &mut state.shadow,
                &mut state.shadow_waiting_block,
                &state.held_boundary_c,
                &self.source_node,
                &self.resistance,
                self.origin_c,
                || readings.as_ref().iter().any(Option::is_some),
            );
            // One put-off piece a light tick: a correction's move (or,
            // before the first step, the whole estimate) waits for the
            // next one when the block took this one.
            #[cfg(feature = "integer-step")]
            if !block_stepped
                && state.integer.read_due()
                && readings.as_ref().iter().all(Option::is_none)
            {
                return state
                    .integer
                    .read_between_steps(state.estimate.x.as_slice(), &state.residual_k);
            }
            return block_stepped;
        }
        let sq_a2 = step_square_currents::<Z::InputDim>(mean_sq_a2, &state.held_currents_a);
        // The usual tick's one step out of the catch-up's loop: in it, the
        // step's operands were loaded before the loop and spilled (+57
        // instructions on the M4F network's tick, measured).
        self.predict(state, &sq_a2);
        for _ in 1..steps {
            self.predict(state, &sq_a2);
        }
        self.shadow.stepped(
            &mut state.shadow,
            &mut state.shadow_waiting_block,
            steps,
            &sq_a2,
            &state.held_boundary_c,
            &self.source_node,
            &self.resistance,
            self.origin_c,
        )
    }

    /// One mean predict with the held boundaries and the step's square
    /// currents `sq_a2` \[A^2\] (see "f32 without drift").
    // Inlined on a core with an FPU, where its call costs a tenth of the
    // plain tick; on one without, its soft-float work dwarfs the call
    // and the copy would cost the M0 footprint half a kilobyte (and, in
    // the tick, every tick's registers and stack: +540 instructions on
    // the M0 network's tick without a step, measured).
    #[cfg_attr(target_abi = "eabihf", inline(always))]
    #[cfg_attr(not(target_abi = "eabihf"), inline(never))]
    fn predict<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        sq_a2: &InputVector<Z, f32>,
    ) {
        let x = &state.estimate.x;
        let (nodes, inputs) = self.bd_power.shape_generic();
        let (n, m_all) = (nodes.value(), inputs.value());
        let mut power = OVector::<f32, Z::InputDim>::zeros_generic(inputs, U1);
        for (m, ((node, r), i2)) in self
            .source_node
            .as_ref()
            .iter()
            .zip(self.resistance.as_ref())
            .zip(sq_a2.as_ref())
            .enumerate()
        {
            let dev_k = x.get(*node).copied().unwrap_or(0.0);
            // The bias adds to the power; `R(T)` at the estimate.
            power[m] = r.resistance_ohm(dev_k) * i2 + x[n + m];
        }
        let held_boundary_c = state.held_boundary_c.as_ref();
        let mut boundary = OVector::<f32, Z::BoundaryDim>::from_fn_generic(
            self.gd_boundary.shape_generic().1,
            U1,
            |k, _| held_boundary_c[k] - self.origin_c,
        );
        if let Some(b) = self.offset_boundary {
            // The boundary the links see: its reading plus the offset.
            if let (Some(y), Some(offset_k)) = (boundary.get_mut(b), x.get(n + m_all)) {
                *y += *offset_k;
            }
        }
        match self.integer_model_step(state, &power, &boundary) {
            // A non-finite input or deviation: the estimate is kept.
            Some(false) => return,
            Some(true) => {}
            None => {
                let x = &mut state.estimate.x;
                let temps = x.rows_generic(0, nodes).into_owned();
                let mut increment = self.constant_k.clone();
                increment.gemv(1.0, &self.phi_minus_i, &temps, 1.0);
                increment.gemv(1.0, &self.bd_power, &power, 1.0);
                increment.gemv(1.0, &self.gd_boundary, &boundary, 1.0);
                if !increment.iter().all(|v| v.is_finite()) {
                    // Only a corrupted state gets here (held inputs are finite):
                    // keep the estimate rather than spread NaN.
                    return;
                }
                for ((xi, residual), inc) in x
                    .iter_mut()
                    .zip(state.residual_k.as_mut().iter_mut())
                    .zip(increment.iter())
                {
                    *xi = compensated_add(*xi, *inc, residual);
                }
            }
        }
        if let (true, Some(cov)) = (state.warmup_left > 0, state.warm.held_mut()) {
            predict_cov(&self.kalman, cov);
        }
    }

    /// The model step in integer arithmetic, if the settings ask for it
    /// (only with the `integer-step` feature): `Some(stepped)`, `None` for
    /// the `f32` step.
    #[inline(always)]
    fn integer_model_step<W>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        power: &OVector<f32, Z::InputDim>,
        boundary: &OVector<f32, Z::BoundaryDim>,
    ) -> Option<bool> {
        #[cfg(feature = "integer-step")]
        if let Some(step) = &self.integer_step {
            let (inputs, boundaries) = (power.shape_generic().0, boundary.shape_generic().0);
            return Some(step_in_memory(
                step,
                &mut state.integer,
                state.estimate.x.as_mut_slice(),
                &state.residual_k,
                &inputs.each(|m| power[m]),
                &boundaries.each(|k| boundary[k]),
            ));
        }
        #[cfg(not(feature = "integer-step"))]
        let _ = (state, power, boundary);
        None
    }

    /// The biases' mean decay (see [`NetworkSettings::bias_tau_s`]), once
    /// a correction period: `exp(-steps / (bias_tau_s / step))` in one
    /// factor, since a per-step factor `1 - 5.6e-7` (1 ms, 30 min) is held
    /// by `f32` to a few ulps only and would misstate the time constant.
    pub(super) fn decay_biases<W>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        steps: u32,
    ) {
        if !self.decays {
            return;
        }
        state.bias_steps = state.bias_steps.saturating_add(steps);
        if state.bias_steps < self.gain.period {
            return;
        }
        let [bias_factor, offset_factor] = if state.bias_steps == self.gain.period {
            state.period_decay
        } else {
            self.decay_factors(state.bias_steps)
        };
        state.bias_steps = 0;
        let (n, m) = (self.limited.as_ref().len(), self.source_node.as_ref().len());
        if self.bias_decay_per_step > 0.0 {
            let biases = state.estimate.x.as_mut_slice().get_mut(n..n + m);
            for bias in biases.unwrap_or_default() {
                *bias *= bias_factor;
            }
        }
        if let Some(offset_k) = state.estimate.x.get_mut(n + m) {
            *offset_k *= offset_factor;
        }
    }

    /// The heat biases' and the boundary offset's decay factors over
    /// `steps` model steps (dimensionless).
    pub(super) fn decay_factors(&self, steps: u32) -> [f32; 2] {
        let elapsed = steps as f32;
        [
            libm::expf(-self.bias_decay_per_step * elapsed),
            libm::expf(-self.offset_decay_per_step * elapsed),
        ]
    }
}
