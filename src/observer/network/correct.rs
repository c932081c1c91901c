//! The network observer's correction: the readings' screens (the
//! consistency band, the stuck test with its rewind, silence, the drift
//! hold), the fusion with the steady gain, the bias floors and the shared
//! heat, written once for every size.

use super::*;

/// The correction, written once for every size.
impl<Z: Sizes, X: Length, P: Length> NetworkObserverOf<Z, X, P>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
    NodeVector<Z, Option<f32>>: KeptAnswers + Answers<f32, Z::NodeDim>,
{
    /// Sorts the readings, holds each against the shadow model, and runs
    /// one steady-state correction if any is usable; returns whether it ran
    /// and the common-mode flag.
    pub(super) fn correct<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        readings: &P::Array<Option<TimedReading>>,
        now_us: u32,
    ) -> (bool, InputFlags) {
        if readings.as_ref().iter().all(Option::is_none) {
            // Most ticks: nothing to sort, screen or fuse. The same statuses
            // and doubt as the full path below, which skips every screen
            // for a missing reading.
            state.outputs.sensors = P::filled_like(readings, SensorStatus::NoReading);
            state.silence.watch(
                &P::filled_like(readings, false),
                now_us,
                self.silent_after_us,
                &mut state.outputs.sensors,
            );
            self.note_doubt(state, false);
            return (false, InputFlags::NONE);
        }
        self.fuse_readings(state, readings, now_us)
    }

    /// The correction of a tick that brought readings; out of line so that
    /// the ticks without one do not pay for its frame.
    #[inline(never)]
    fn fuse_readings<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        readings: &P::Array<Option<TimedReading>>,
        now_us: u32,
    ) -> (bool, InputFlags) {
        let mut samples = sample_readings::<P>(
            readings,
            now_us,
            self.max_reading_age_us,
            &mut state.outputs.sensors,
        );
        state.silence.watch(
            &P::mapped(readings, |r| r.is_some()),
            now_us,
            self.silent_after_us,
            &mut state.outputs.sensors,
        );
        let ambient_c = self.ambient(&state.held_boundary_c);
        // A noisy sensor's band is wider by its noise (0 for a
        // thermocouple, whose screens are as they were, to the bit): see
        // `resistance`, "Against the physics".
        let mut shadow_c = P::mapped(&self.sensor_nodes, |node| {
            self.origin_c + state.shadow.dev_k(*node)
        });
        let allowances = self.noise_allowance_k.as_ref();
        for (shadow, allowance) in shadow_c.as_mut().iter_mut().zip(allowances) {
            *shadow -= *allowance;
        }
        let present = samples.as_ref().iter().any(Option::is_some);
        let (mut common_mode, stuck_events) = screen_readings::<P>(
            &self.shadow.band,
            &self.stuck_test,
            &mut state.stuck,
            &mut samples,
            &mut state.outputs.sensors,
            &shadow_c,
            ambient_c,
        );
        self.rewind_stuck_biases(state, &stuck_events);
        let warm_cov = if state.warmup_left > 0 {
            state.warm.held()
        } else {
            None
        };
        let x = &state.estimate.x;
        // Every reading refused, one held as drifting colder than the
        // physics: the estimate goes back to the model, as for a
        // common-mode fault.
        common_mode |= state.drift.screen(
            &mut samples,
            &mut state.outputs.sensors,
            &shadow_c,
            &state.estimate.gate.consecutive_rejections,
            self.kalman.gate(),
            &self.stuck_test,
            |j| GateView {
                estimate_c: self.origin_c
                    + self
                        .sensor_nodes
                        .as_ref()
                        .get(j)
                        .and_then(|node| x.get(*node))
                        .copied()
                        .unwrap_or(f32::NAN),
                innovation_var_k2: self.innovation_var_k2(warm_cov, j),
            },
        );
        let mut flags = InputFlags::NONE;
        if common_mode {
            // A common-mode fault: what the sensors dragged comes back.
            flags = InputFlags::SENSORS_COLDER_THAN_PHYSICS;
            let x = &mut state.estimate.x;
            for (i, shadow_k) in state.shadow.devs_k().as_ref().iter().enumerate() {
                if x[i] < *shadow_k {
                    x[i] = *shadow_k;
                    if let Some(r) = state.residual_k.as_mut().get_mut(i) {
                        *r = 0.0;
                    }
                }
            }
            let n = self.limited.as_ref().len();
            for m in 0..self.source_node.as_ref().len() {
                x[n + m] = x[n + m].max(0.0);
            }
        }
        // `H` holds the sensor map: a reading only needs the origin taken
        // off to be a deviation.
        let z = P::mapped(&samples, |t| t.map(|t| t - self.origin_c));
        if z.as_ref().iter().all(Option::is_none) {
            self.note_doubt(state, present);
            return (false, flags);
        }
        let warming = state.warmup_left > 0 && state.warm.held().is_some();
        let report = if let (true, Some(cov)) = (warming, state.warm.held_mut()) {
            state.warmup_left -= 1;
            let mut full = KalmanState {
                x: state.estimate.x.clone(),
                cov: cov.clone(),
                gate: state.estimate.gate.clone(),
            };
            let report = update(&self.kalman, &mut full, &z);
            state.estimate.x = full.x;
            state.estimate.gate = full.gate;
            *cov = full.cov;
            if state.warmup_until_steady {
                // The start's shadow knows no more than the filter: it
                // follows the filter until the start has settled.
                let x = &state.estimate.x;
                let devs_k = Z::NodeDim::mapped(state.shadow.devs_k(), |_| 0.0);
                let mut devs_k = devs_k;
                for (dev_k, x) in devs_k.as_mut().iter_mut().zip(x.iter()) {
                    *dev_k = *x;
                }
                state.shadow.reseed(devs_k);
                // The filter's estimate is of now: a waiting block would
                // take the shadow past it.
                state.shadow_waiting_block = None;
                if self.settled(cov) {
                    state.warmup_left = 0;
                }
            }
            report
        } else {
            update_steady(&self.kalman, &self.gain, &mut state.estimate, &z)
        };
        record_verdicts::<P>(
            &mut state.outputs.sensors,
            &report.verdicts,
            &P::mapped(&z, |z| z.is_some()),
        );
        #[cfg(not(target_abi = "eabihf"))]
        if self.correction_in_two_ticks {
            state.floors_due = Some(warming);
            self.note_doubt(state, true);
            return (true, flags);
        }
        self.finish_correction(state, warming, &mut flags);
        self.note_doubt(state, true);
        (true, flags)
    }

    /// The end of a correction: the biases' floors (with the covariance
    /// the correction used: the warm-up's if `warming`) and the check of
    /// the biases against the model's uncertainty.
    // One copy on a core without an FPU, whose two ticks call it.
    #[cfg_attr(not(target_abi = "eabihf"), inline(never))]
    pub(super) fn finish_correction<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        warming: bool,
        flags: &mut InputFlags,
    ) {
        let powers_w = self.keep_floors(state, warming);
        if self
            .biases_beyond(state, &powers_w)
            .as_ref()
            .contains(&true)
        {
            *flags |= InputFlags::HEAT_BIAS_BEYOND_MODEL;
        }
    }

    /// The gate's innovation variance of sensor `j` \[K^2\]: the steady
    /// gain's, or from `held`, the warm-up's covariance while it runs.
    fn innovation_var_k2(&self, held: Option<&OMatrix<f32, X, X>>, j: usize) -> f32 {
        let Some(cov) = held else {
            return self
                .gain
                .innovation_var()
                .get(j)
                .copied()
                .unwrap_or(f32::NAN);
        };
        let Some(node) = self.sensor_nodes.as_ref().get(j).copied() else {
            return f32::NAN;
        };
        let held = cov.get((node, node)).copied().unwrap_or(f32::NAN);
        held + self.kalman.r().get(j).copied().unwrap_or(f32::NAN)
    }

    /// Whether the warm-up's covariance has settled: every variance within
    /// [`start::SETTLED_FRACTION`] of the steady posterior's.
    fn settled(&self, cov: &OMatrix<f32, X, X>) -> bool {
        let steady = self.gain.posterior();
        (0..cov.nrows()).all(|i| cov[(i, i)] <= (1.0 + start::SETTLED_FRACTION) * steady[(i, i)])
    }

    /// Notes which sensors' measurements are in doubt this tick (see
    /// [`Suspicion`](super::consistency::Suspicion)): at a correction (some
    /// reading arrived), every sensor's verdict counts; between them only
    /// a silent sensor renews its doubt.
    fn note_doubt<W>(&self, state: &mut NetworkObserverStateOf<Z, X, P, W>, correction: bool) {
        let rejections = state.estimate.gate.consecutive_rejections.as_ref();
        let mut doubt = P::filled_like(&state.outputs.sensors, false);
        let judged = state.outputs.sensors.as_ref().iter().zip(rejections);
        for (doubt, (status, rejected)) in doubt.as_mut().iter_mut().zip(judged) {
            *doubt = sensor_doubt(status, *rejected).unwrap_or(false);
        }
        if correction {
            state.suspect.note(&doubt);
        } else if doubt.as_ref().contains(&true) {
            state.suspect.renew(&doubt);
        }
    }

    /// Takes back what a sensor found stuck taught the heat-input biases
    /// ([`StuckRewind`], the rule the Omnimagnet observer shares), the
    /// shared heat's sum too, in the present shares. `events`: this
    /// correction's stuck screen.
    fn rewind_stuck_biases<W>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        events: &StuckEvents<P>,
    ) {
        let shared = &self.shared_bias;
        let any_shared = shared.as_ref().contains(&true);
        let shares = if any_shared && events.became_stuck.as_ref().contains(&true) {
            present_shares::<Z::InputDim>(
                shared,
                &self.joule_powers_w(state),
                &self.nominal_power_w,
            )
        } else {
            Z::InputDim::filled_like(shared, 0.0)
        };
        let n = self.limited.as_ref().len();
        state.rewind.rewind(
            &mut state.estimate.x,
            self.gain.posterior(),
            n,
            events,
            shared,
            |x, at_change| {
                if any_shared {
                    // The shared heat goes back to its sum then, in the
                    // present shares.
                    let sum_w: f32 = shared
                        .as_ref()
                        .iter()
                        .zip(at_change.as_ref())
                        .filter(|(shared, _)| **shared)
                        .map(|(_, bias)| *bias)
                        .sum();
                    condition_shared_sum::<X, Z::InputDim>(
                        x,
                        n,
                        &SharedColumn::of::<Z::InputDim>(self.gain.posterior(), n, shared),
                        shared,
                        &shares,
                        sum_w,
                    );
                }
            },
        );
    }

    /// The covariance the floors project with: the warm-up's when the
    /// correction ran it (`warming`; held even when that correction ended
    /// it), else the steady posterior.
    fn floor_cov<'a, W: Flavour<OMatrix<f32, X, X>>>(
        &'a self,
        warm: &'a W,
        warming: bool,
    ) -> &'a OMatrix<f32, X, X> {
        match (warming, warm.held()) {
            (true, Some(cov)) => cov,
            _ => self.gain.posterior(),
        }
    }

    /// Keeps every heat-input bias at or above its floor and the boundary
    /// offset at or above 0 \[K\] (the boundary the network sees is never
    /// colder than its reading), with the covariance the correction used.
    /// Each projection moves the others' variables through its regression
    /// (a heat bias and the offset explain the same readings, so raising
    /// one lowers the other), so with an offset state they alternate,
    /// [`FLOOR_PASSES`] times, the biases' last: a cooling bias on a
    /// winding reads it cold (one pass of each left the winding 0.95 K
    /// under the plant behind a coolant reading 3 K high, against 0.07 K
    /// without the offset state; with eight, 0.066 K, the offset 0.03 K
    /// under 0, `host-tests/tests/boundary_offset.rs`). Not the exact
    /// joint projection: the offset is held to within hundredths of a
    /// kelvin of its floor, the biases exactly. Moving the temperatures
    /// alone to lift the offset is no way out: given a sensor on the
    /// housing, a warmer coolant means a cooler winding, and those lifts
    /// left the winding 4.4 K cold.
    ///
    /// The floors are taken once, at the Joule powers of the corrected
    /// estimate: the passes project onto fixed sets (what alternating
    /// projections converge on), and the powers, a soft-float routine per
    /// source on a core without an FPU, are not formed again per pass
    /// (the real motor's reading tick on the Cortex-M0: some 20 000
    /// instructions). Without an offset state the floors are taken in
    /// [`Self::keep_bias_floors`] as before: the shape that kept the M4F's
    /// ticks and the M0 footprint within their ceilings (docs/cost.md).
    ///
    /// Returns the Joule powers \[W\] the floors were taken at.
    fn keep_floors<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        warming: bool,
    ) -> InputVector<Z, f32> {
        if self.offset_boundary.is_none() {
            return self.keep_bias_floors(state, warming);
        }
        let powers_w = self.joule_powers_w(state);
        let floors = self.bias_floors(&powers_w);
        let mut column = None;
        for _ in 0..FLOOR_PASSES {
            let cov = self.floor_cov(&state.warm, warming);
            let offset = self.limited.as_ref().len() + self.source_node.as_ref().len();
            let offset_moved =
                crate::filter::project_onto_floor(&mut state.estimate.x, cov, offset, 0.0);
            let bias_moved = self.keep_bias_floors_at(state, warming, &floors, &mut column);
            // A pass that moved nothing leaves every later pass the same
            // state, covariance and floors: they would move nothing either.
            if !(offset_moved || bias_moved) {
                break;
            }
        }
        powers_w
    }

    /// Projects the estimate onto every heat-input bias's floor,
    /// `-cooling_bias_fraction * P_m` (see
    /// [`NetworkSettings::max_cooling_bias_fraction`]), with the covariance
    /// the correction used (the warm-up's while it runs, else the steady
    /// posterior): a bias below its floor goes to it and every temperature
    /// back by its regression on that bias
    /// ([`project_onto_floor`](crate::filter::project_onto_floor)). Exact
    /// for one bias; several are projected in turn on the same covariance.
    /// The floors are at the Joule powers of the estimate, which it
    /// returns \[W\].
    fn keep_bias_floors<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        warming: bool,
    ) -> InputVector<Z, f32> {
        let powers_w = self.joule_powers_w(state);
        let floors = self.bias_floors(&powers_w);
        let _ = self.keep_bias_floors_at(state, warming, &floors, &mut None);
        powers_w
    }

    /// The heat-input biases' floors at the Joule powers `powers_w` \[W\]:
    /// formed once for every pass of [`Self::keep_floors`] (eight of them
    /// formed each source's floor again: about 2 600 soft-float
    /// instructions of the real motor's reading tick on a Cortex-M0).
    fn bias_floors(&self, powers_w: &InputVector<Z, f32>) -> BiasFloors<Z::InputDim> {
        BiasFloors::at(
            powers_w,
            self.cooling_bias_fraction,
            &self.shared_bias,
            &self.nominal_power_w,
        )
    }

    /// [`Self::keep_bias_floors`] onto the floors `floors`; whether a
    /// bias was below its floor (the shared heat's proportions, set again
    /// each time, do not count: they move the estimate by its rounding).
    /// `column` is the shared heat's regression column under the floors'
    /// covariance, formed here when first needed and kept for the next
    /// pass.
    #[inline(never)]
    fn keep_bias_floors_at<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
        warming: bool,
        floors: &BiasFloors<Z::InputDim>,
        column: &mut Option<SharedColumn<X>>,
    ) -> bool {
        let cov = self.floor_cov(&state.warm, warming);
        let n = self.limited.as_ref().len();
        let mut moved = false;
        let own = floors.own_w.as_ref().iter().zip(self.shared_bias.as_ref());
        for (m, (floor_w, shared)) in own.enumerate() {
            if *shared {
                continue;
            }
            moved |= crate::filter::project_onto_floor(&mut state.estimate.x, cov, n + m, *floor_w);
        }
        if !self.shared_bias.as_ref().contains(&true) {
            return moved;
        }
        // The shared heat: its floor is the sum of the sources' floors
        // (with the biases in proportion to the present powers, each
        // source's floor holds when their sum does, to the shares' blend
        // with the nominal powers: 1e-4 of them), and it goes back to the
        // sources in proportion to their present power.
        let shared = &self.shared_bias;
        let sum_w = shared_sum_w::<X, Z::InputDim>(&state.estimate.x, n, shared);
        if sum_w < floors.shared_w {
            let column =
                column.get_or_insert_with(|| SharedColumn::of::<Z::InputDim>(cov, n, shared));
            condition_shared_sum::<X, Z::InputDim>(
                &mut state.estimate.x,
                n,
                column,
                shared,
                &floors.shares,
                floors.shared_w,
            );
            true
        } else {
            set_shared::<X, Z::InputDim>(&mut state.estimate.x, n, shared, &floors.shares, sum_w);
            moved
        }
    }

    /// The sources sharing one heat bias (see "One sensor sees one heat:
    /// the shared bias" in the module docs; none: a bias per source).
    pub fn shared_bias_sources(&self) -> InputVector<Z, bool> {
        self.shared_bias.clone()
    }

    /// Which heat-input biases are beyond the model's uncertainty (see
    /// "Sensors against the physics"), at the Joule powers `powers_w`
    /// \[W\] the floors were taken at: the held currents' at the estimate
    /// before the floors moved it (by a bias's regression, a change of
    /// `R(T)` far below the band's fraction of the power; forming them
    /// again cost a soft-float routine per source on a core without an
    /// FPU).
    fn biases_beyond<W>(
        &self,
        state: &NetworkObserverStateOf<Z, X, P, W>,
        powers_w: &InputVector<Z, f32>,
    ) -> InputVector<Z, bool> {
        let (n, m) = (self.limited.as_ref().len(), self.source_node.as_ref().len());
        self.shadow.bias_bound.beyond(
            state
                .estimate
                .x
                .as_slice()
                .get(n..n + m)
                .unwrap_or_default(),
            powers_w,
        )
    }

    /// Each current's Joule power \[W\], the held current at the estimated
    /// temperature of the node it heats.
    fn joule_powers_w<W>(&self, state: &NetworkObserverStateOf<Z, X, P, W>) -> InputVector<Z, f32> {
        let x = &state.estimate.x;
        let mut powers_w = Z::InputDim::filled_like(&state.held_currents_a, 0.0f32);
        for (power, ((node, r), i)) in powers_w.as_mut().iter_mut().zip(
            self.source_node
                .as_ref()
                .iter()
                .zip(self.resistance.as_ref())
                .zip(state.held_currents_a.as_ref()),
        ) {
            let r_ohm = r.resistance_ohm(x.get(*node).copied().unwrap_or(0.0));
            *power = r_ohm * *i * *i;
        }
        powers_w
    }
}
