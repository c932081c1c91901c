//! Saving, restoring and starting the network observer (see
//! [`crate::observer::start`] for the rules of the start without a
//! history, [`crate::observer::snapshot`] for the snapshot's format),
//! written once for every size: the MCU's `Const` sizes and a host's
//! run-time ones.

use super::*;

/// Saving, restoring and starting, written once for every size.
impl<Z: Sizes, X: Length, P: Length> NetworkObserverOf<Z, X, P>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
    NodeVector<Z, Option<f32>>: KeptAnswers + Answers<f32, Z::NodeDim>,
{
    /// Writes a snapshot of the node estimates \[degC\] and the latched
    /// shutdown, stamped `now_s` \[s\]; returns its length
    /// ([`snapshot_len(N)`](super::snapshot::snapshot_len) bytes). The
    /// biases are not saved: a restored state starts them at zero.
    pub fn save<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &NetworkObserverStateOf<Z, X, P, W>,
        now_s: u32,
        out: &mut [u8],
    ) -> Result<usize, SnapshotError> {
        snapshot::save_state(
            self.temps_c(state).as_ref(),
            self.fingerprint,
            now_s,
            &state.alarm,
            out,
        )
    }

    /// Restores a state saved by [`Self::save`] with this configuration at
    /// most `max_age_s` \[s\] before `now_s` \[s\], the boundaries at
    /// `boundary_c` \[degC\]. A latched shutdown stays latched. Like every
    /// restore, a state without a warm-up ([`NoWarmUp`], as
    /// [`Self::state`]'s); [`Self::with_warm_up`] makes it the type of
    /// [`Self::start`]'s.
    ///
    /// # Errors
    /// Why the snapshot was refused; start from
    /// [`Self::conservative_state`] then.
    pub fn restore(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        boundary_c: &BoundaryVector<Z, f32>,
    ) -> Result<NetworkObserverStateOf<Z, X, P, NoWarmUp>, SnapshotError> {
        self.restore_after(bytes, now_s, max_age_s, boundary_c, None)
    }

    /// [`Self::restore`] for a device that was off for `off_s` \[s\]: the
    /// saved node estimates decayed by the network's exact zero-current
    /// solution over the off time, with the boundaries held at `boundary_c`
    /// \[degC\] (and the network's fixed powers on),
    /// `T_ss + exp(A off) (T_saved - T_ss)`, from the modes the time-to-limit
    /// predictor already holds
    /// ([`LimitPredictor::cooled_c`](crate::protect::predict::LimitPredictor::cooled_c)):
    /// `O(N^2)` work and `N` exponentials, never below the exact cooled state
    /// (a guard of about 1 mK covers the `f32` rounding). A latched shutdown
    /// stays latched.
    ///
    /// `off_s` is capped at the snapshot's age; `None`, a NaN or a negative
    /// time mean an *unknown* off time and restore the saved state uncooled
    /// ([`snapshot::off_time_s`]); `Some(0.0)` restores it to the bit. A
    /// boundary temperature outside the input limits (or not finite) also
    /// restores uncooled: the cooling would have nothing sure to head for.
    ///
    /// # Errors
    /// Those of [`Self::restore`].
    pub fn restore_after(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        boundary_c: &BoundaryVector<Z, f32>,
        off_s: Option<f32>,
    ) -> Result<NetworkObserverStateOf<Z, X, P, NoWarmUp>, SnapshotError> {
        let saved_c = self.sizes().nodes_of(0.0);
        let snap = Restored::read(bytes, self.fingerprint, now_s, max_age_s, saved_c)?;
        let off_s = snap.off_time_s(off_s);
        Ok(self.restored(&snap.saved_c, &snap.meta, boundary_c, off_s))
    }

    /// [`Self::restore`] for a device whose off time is unknown (no
    /// real-time clock), with what the sensors read now, `readings_c`
    /// \[degC\] (`None` or non-finite: no reading): the saved estimates
    /// cooled by the shortest off time, within the snapshot's age, that
    /// brings some sensor's node within `k_sigma` sensor deviations
    /// (0.75 K at the defaults) of its reading
    /// ([`start::earliest_off_time_s`]: of the sensors the saved state puts
    /// above their readings), and every sensor's node at its reading
    /// ([`start::at_readings`]): the least cooling the readings allow, so the
    /// nodes no sensor reads err hot, and the sensors' first readings
    /// agree with the estimate (none refused, none colder than the
    /// physics). A reading colder than the coldest boundary (no cooling
    /// reaches it: a faulty sensor) is left out. With no usable reading (or a boundary outside
    /// the input limits), the saved state uncooled, as
    /// [`Self::restore_after`] with `None`. A latched shutdown stays
    /// latched.
    ///
    /// # Errors
    /// Those of [`Self::restore`].
    pub fn restore_with_readings(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        boundary_c: &BoundaryVector<Z, f32>,
        readings_c: &P::Array<Option<f32>>,
    ) -> Result<NetworkObserverStateOf<Z, X, P, NoWarmUp>, SnapshotError> {
        let saved_c = self.sizes().nodes_of(0.0);
        let snap = Restored::read(bytes, self.fingerprint, now_s, max_age_s, saved_c)?;
        let tolerance_k = start::restore_tolerance_k(self.k_sigma, self.kalman.r().iter().copied());
        let coldest_c = boundary_c
            .as_ref()
            .iter()
            .fold(f32::INFINITY, |a, b| a.min(*b));
        let mut readings_c = readings_c.clone();
        let every_sensor = core::iter::repeat(true);
        start::restore_readings(readings_c.as_mut(), every_sensor, coldest_c, tolerance_k);
        let saved_c = start::cooled_to_readings(
            &snap.saved_c,
            |t| self.cooled_c(&snap.saved_c, boundary_c, t),
            self.sensor_nodes.as_ref(),
            readings_c.as_ref(),
            tolerance_k,
            snap.age_s(),
        );
        Ok(self.restored(&saved_c, &snap.meta, boundary_c, 0.0))
    }

    /// The state restored from `saved_c` \[degC\] after `off_s` \[s\] off.
    fn restored(
        &self,
        saved_c: &NodeVector<Z, f32>,
        meta: &SnapshotMeta,
        boundary_c: &BoundaryVector<Z, f32>,
        off_s: f32,
    ) -> NetworkObserverStateOf<Z, X, P, NoWarmUp> {
        let mut held_c = boundary_c.clone();
        let rejected = self
            .limits
            .accept_temperatures(boundary_c.as_ref(), held_c.as_mut());
        let temps_c = if off_s > 0.0 && rejected == InputFlags::NONE {
            self.cooled_c(saved_c, boundary_c, off_s)
        } else {
            saved_c.clone()
        };
        let mut state = self.state(&temps_c, boundary_c);
        state.latch().restore(meta);
        state
    }

    /// The start without a history (the first boot, a refused snapshot, a
    /// product that keeps none), safe from the first tick (see
    /// [`super::start`]): every node a sensor reads now at its reading
    /// `readings_c` \[degC\] (`None` or non-finite: no reading), every
    /// other node no cooler than the hottest reading or the ambient, with
    /// a variance that puts each limited element's upper bound
    /// [`start::START_BELOW_LIMIT_K`] below its alarm limit; the
    /// time-varying filter holds that covariance (the gate judges against
    /// it, the upper bound widens by it) until it has settled on the
    /// steady one. No shutdown is latched: the limiter starts in its taper
    /// band and opens as the sensors teach the filter. The boundaries at
    /// `boundary_c` \[degC\]. The state is of the [`WarmUp`] flavour: a
    /// firmware that calls `start` links the warm-up's code, one that never
    /// does need not (see [`WarmUpKind`]).
    pub fn start(
        &self,
        readings_c: &P::Array<Option<f32>>,
        boundary_c: &BoundaryVector<Z, f32>,
    ) -> NetworkObserverStateOf<Z, X, P> {
        let sizes = self.sizes();
        let mut held_c = sizes.boundaries_of(self.origin_c);
        let _ = self
            .limits
            .accept_temperatures(boundary_c.as_ref(), held_c.as_mut());
        let ambient_c = self.ambient(&held_c);
        let temps = self.conservative_start_c(readings_c, ambient_c);
        let state = self.state(&temps, boundary_c);
        let mut read = sizes.nodes_of(false);
        let sensor_nodes = self.sensor_nodes.as_ref();
        for (reading, node) in readings_c.as_ref().iter().zip(sensor_nodes) {
            let slot = read.as_mut().get_mut(*node);
            if let (true, Some(r)) = (reading.is_some_and(f32::is_finite), slot) {
                *r = true;
            }
        }
        let mut steady_upper_c = sizes.nodes_of(0.0);
        self.bound.upper_c(&temps, ambient_c, &mut steady_upper_c);
        let limits_c = self.alarm.alarm_limits_c(ambient_c);
        let sigma_k = start::start_sigma_k(
            read.as_ref(),
            steady_upper_c.as_ref(),
            limits_c.as_ref(),
            self.limited.as_ref(),
            self.bound_sigma_k.as_ref(),
            self.k_sigma,
        );
        let mut cov = self.gain.prior().clone();
        for (i, sigma) in sigma_k.enumerate() {
            if let Some(sigma) = sigma {
                cov[(i, i)] = cov[(i, i)].max(sigma * sigma);
            }
        }
        let mut state = state.flavoured(WarmUp { held: cov });
        state.warmup_left = start::MAX_START_CORRECTIONS;
        state.warmup_until_steady = true;
        self.publish_upper(&mut state, ambient_c, true);
        self.limit(&mut state.outputs, &mut state.alarm_limits, ambient_c);
        state
    }

    /// The node temperatures \[degC\] `off_s` \[s\] after `temps_c` with no
    /// current and the boundaries at `boundary_c` \[degC\]: the exact
    /// zero-current solution of the observer's network, never below it (see
    /// [`Self::restore_after`]; an off time that is not positive returns
    /// `temps_c`).
    pub fn cooled_c(
        &self,
        temps_c: &NodeVector<Z, f32>,
        boundary_c: &BoundaryVector<Z, f32>,
        off_s: f32,
    ) -> NodeVector<Z, f32> {
        self.predictor.cooled_c(temps_c, boundary_c, off_s)
    }

    /// [`snapshot::conservative_start`] of `readings_c` \[degC\] on the
    /// sensors' nodes at `ambient_c` \[degC\].
    fn conservative_start_c(
        &self,
        readings_c: &P::Array<Option<f32>>,
        ambient_c: f32,
    ) -> NodeVector<Z, f32> {
        let mut temps_c = self.sizes().nodes_of(0.0);
        snapshot::conservative_start_into(
            readings_c.as_ref(),
            self.sensor_nodes.as_ref(),
            ambient_c,
            temps_c.as_mut(),
        );
        temps_c
    }

    /// The documented start when no snapshot can be trusted
    /// ([`snapshot::conservative_start`]): measured nodes at their readings
    /// \[degC\], every other node no cooler than the hottest reading or the
    /// ambient, and the shutdown *latched* (published from the start, every
    /// current limit zero) until [`Self::clear_shutdown`]: nothing says the
    /// device is not hotter than that start. A state without a warm-up
    /// ([`NoWarmUp`], as [`Self::state`]'s).
    pub fn conservative_state(
        &self,
        readings_c: &P::Array<Option<f32>>,
        boundary_c: &BoundaryVector<Z, f32>,
    ) -> NetworkObserverStateOf<Z, X, P, NoWarmUp> {
        let ambient_c = self.ambient(boundary_c);
        let temps = self.conservative_start_c(readings_c, ambient_c);
        let mut state = self.state(&temps, boundary_c);
        state.latch().latch();
        state
    }

    /// The deliberate clear of a latched shutdown (restored, set by
    /// [`Self::conservative_state`], raised by the alarm or by a frozen
    /// clock), for the application to call after inspecting the device;
    /// nothing else clears it. It is [`AlarmState::reset`] under its
    /// conditions (every element's upper bound valid and below its alarm
    /// limit minus the hysteresis for the alarm's debounce). On success a
    /// `Reset` event is queued, the published `alarm.shutdown` is `false` at
    /// once, and the current limits come back with the next limiter stage.
    /// Not for the tick: call it between two ticks.
    ///
    /// # Errors
    /// Why not, naming the first element that blocks it; nothing changes
    /// then.
    pub fn clear_shutdown<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &mut NetworkObserverStateOf<Z, X, P, W>,
    ) -> Result<(), ResetError> {
        state.latch().clear(&self.alarm)
    }
}
