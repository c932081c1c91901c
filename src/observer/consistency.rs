//! The physics alone, as a witness against the sensors: a *shadow* of the
//! model that no reading corrects and no heat bias moves, and the test a
//! reading must pass against it before the filter may fuse it.
//!
//! # Why
//!
//! The filter explains a disagreement between its model and a thermocouple
//! as a heat bias and a temperature correction, so a sensor that lies
//! slowly (detached and reading the room, stuck, drifting) drags the
//! estimate with it and the innovation gate, judging the dragged estimate,
//! never sees it: six thermocouples all reading 22 degC on an Omnimagnet at
//! 7 A took the estimates 114-138 K below the truth and put the shutdown
//! off by an hour. The gate cannot be the judge of a sensor that moves
//! the estimate it is judged against.
//!
//! # The rule
//!
//! The shadow runs the same network from the same start, at the measured
//! currents (`R(T)` at its own temperature) and boundaries, advanced one
//! block of `block_steps` model steps at a time by the exact
//! zero-order-hold of the block (the block's mean `I^2`), with the rounding
//! carried. A reading is *colder than physics* when it is below
//!
//! `shadow - (offset_k + fraction * max(0, shadow - ambient))`,
//!
//! the model's uncertainty: a fixed part and a share of the rise. Such a
//! reading is never fused (reported as
//! [`SensorStatus::ColderThanPhysics`](super::omnimagnet::SensorStatus::ColderThanPhysics)).
//! Readings hotter than the shadow are fused as ever: a model that runs
//! cold must be corrected by its sensors, and erring hot is the safe side.
//! When every reading of a correction is colder than physics (a common-mode
//! fault: all sensors agree with each other and not with the physics), the
//! estimate is raised to the shadow wherever it is below it, and the
//! negative heat biases are dropped: what was dragged comes back, and the
//! protection runs on the model until a sensor agrees with it again.

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, VectorView, U1};

use super::vocabulary::{SensorChecks, SensorStatus};
#[cfg(feature = "integer-step")]
use crate::discretize::fixed::{step_in_memory, FixedStep, StepMemory};
use crate::error::BuildError;
use crate::filter::GatePolicy;
use crate::network::{compensated_add, DeviationResistance};
use crate::protect::margin::UpperBound;
use crate::scalar::Scalar;
use crate::sizes::{BoundaryVector, InputVector, Length, NetworkAllocator, NodeVector, Sizes};

/// The band a reading must keep to below the shadow: the model's
/// uncertainty.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Band {
    /// Fixed part \[K\].
    pub offset_k: f32,
    /// Share of the rise above the ambient (dimensionless).
    pub fraction: f32,
}

impl Band {
    /// The lowest temperature \[degC\] a reading of a node whose shadow is
    /// `shadow_c` \[degC\] may have at the ambient `ambient_c` \[degC\]
    /// (NaN, so no verdict, when either is NaN).
    pub(crate) fn lowest_c(&self, shadow_c: f32, ambient_c: f32) -> f32 {
        // `Scalar::max`, a comparison (NaN to zero as `f32::max`): the
        // inherent `max` is a call to `fmaxf` where there is no VMAXNM.
        let rise = Scalar::max(shadow_c - ambient_c, 0.0);
        shadow_c - (self.offset_k + self.fraction * rise)
    }

    /// Takes every sample colder than its node's band out of the
    /// correction, marking it [`SensorStatus::ColderThanPhysics`];
    /// `shadow_c[j]` is the shadow's temperature at sensor `j`'s node
    /// \[degC\].
    pub(crate) fn screen<P: Length>(
        &self,
        samples: &mut P::Array<Option<f32>>,
        statuses: &mut P::Array<SensorStatus>,
        shadow_c: &P::Array<f32>,
        ambient_c: f32,
    ) {
        let screened = samples.as_mut().iter_mut().zip(statuses.as_mut());
        for ((sample, status), shadow_c) in screened.zip(shadow_c.as_ref()) {
            let Some(t) = *sample else { continue };
            let lowest_c = self.lowest_c(*shadow_c, ambient_c);
            if t < lowest_c {
                *sample = None;
                *status = SensorStatus::ColderThanPhysics {
                    below_k: lowest_c - t,
                };
            }
        }
    }
}

/// The largest heat-input bias the model's uncertainty allows, the
/// band's image in watts: a bias `b_m` \[W\] on input `m` is beyond the
/// model when
///
/// `|b_m| > offset_w[m] + fraction * |P_m|`,
///
/// `P_m` the input's Joule power \[W\] at the estimate, `offset_w[m]` the
/// steady heat on input `m` whose rise at its hottest node is the band's
/// fixed part (`offset_k / max_i (-(Ad - I))^-1 Bd`), `fraction` the band's
/// share of the rise (in a linear network the rise is proportional to the
/// heat, so a 25 % error in the rise is a 25 % error in the heat).
///
/// A bias beyond it is flagged
/// ([`InputFlags::HEAT_BIAS_BEYOND_MODEL`](crate::InputFlags::HEAT_BIAS_BEYOND_MODEL))
/// and left as it is: a stuck thermocouple took a bias to -57 W (healthy
/// ones stay within +-1.2 W at moderate currents), but the Omnimagnet's
/// linearisation at the ambient needs more than the bound near its 3.8 A
/// limit (a healthy 3.8 A heating is flagged in 288 ticks), so the flag is
/// an alarm for the engineer, not a verdict the protection acts on
/// (holding negative biases at the bound, or taking the flag as a lost
/// measurement, shut that healthy run down at 1 963 s instead of 2 210 s).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BiasBound<M: Length> {
    /// The band's fixed part as a steady heat on each input \[W\]
    /// (infinite: no bound).
    pub offset_w: M::Array<f32>,
    /// Share of the Joule power (dimensionless).
    pub fraction: f32,
}

impl<M: Length> BiasBound<M> {
    /// The bound of `band` for the block model `Ad - I` (`phi_minus_i`,
    /// dimensionless) and its power columns `bd_power` \[K/W\] (any step:
    /// the steady rise does not depend on it), solved in `f64`. An input
    /// that heats no node, or a singular network, is left unbounded.
    pub(crate) fn new<N: Dim>(
        band: &Band,
        phi_minus_i: &OMatrix<f32, N, N>,
        bd_power: &OMatrix<f32, N, M>,
    ) -> Self
    where
        DefaultAllocator: Allocator<N, N> + Allocator<N, M>,
    {
        let mut offset_w = bd_power.shape_generic().1.filled(f32::INFINITY);
        if let Some(inverse) = (-phi_minus_i.map(f64::from)).try_inverse() {
            // dT/dP = (I - Ad)^-1 Bd \[K/W\], >= 0 for a heat network.
            let rise = inverse * bd_power.map(f64::from);
            for (m, offset) in offset_w.as_mut().iter_mut().enumerate() {
                let hottest = rise.column(m).iter().fold(0.0f64, |a, r| a.max(*r));
                if hottest.is_finite() && hottest > 0.0 {
                    *offset = (f64::from(band.offset_k) / hottest) as f32;
                }
            }
        }
        Self {
            offset_w,
            fraction: band.fraction,
        }
    }

    /// Which of the biases `biases_w` \[W\] are beyond the bound at the
    /// inputs' Joule powers `powers_w` \[W\] (see the type's docs). NaN
    /// passes unflagged (no verdict).
    pub(crate) fn beyond(&self, biases_w: &[f32], powers_w: &M::Array<f32>) -> M::Array<bool> {
        let mut beyond = M::filled_like(powers_w, false);
        for (((bias, offset), power), beyond) in biases_w
            .iter()
            .zip(self.offset_w.as_ref())
            .zip(powers_w.as_ref())
            .zip(beyond.as_mut().iter_mut())
        {
            *beyond = bias.abs() > offset + self.fraction * power.abs();
        }
        beyond
    }
}

/// Corrections an element stays in doubt after the last sign of trouble
/// with its sensors (30 s at the default 2 Hz).
pub(crate) const DOUBT_HOLD_CORRECTIONS: u16 = 60;

/// The solenoids (current inputs) whose measurement is in doubt: one of
/// their thermocouples was not fused (a fault, refused twice in a row by
/// the gate, or by the band, stuck, silent, too old) and none was fused,
/// within the last [`DOUBT_HOLD_CORRECTIONS`] corrections.
///
/// While one is in doubt, the protection of every limited element acts on
/// the hotter of the estimate and the shadow (the inputs' elements exchange
/// heat, so what was dragged on one is felt by the others' models): the
/// estimate is then the model alone (a
/// lost sensor) or what a lying sensor dragged before it was caught, and
/// the shadow is the physics no reading moved. So a fault that is flagged
/// can only make the protection err hot, never later: one thermocouple per
/// solenoid drifting down 0.05 K/s delayed the Omnimagnet's shutdown at
/// 7 A by 4.8 s before. The shadow, linearised at the ambient, runs hot
/// at the Omnimagnet's currents (all sensors detached at 7 A shut down
/// 9.6 s before the clean run).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Suspicion<M: Length> {
    /// Corrections of doubt left per input.
    left: M::Array<u16>,
}

impl<M: Length> Suspicion<M> {
    /// No doubt, on `inputs` inputs.
    pub(crate) fn new(inputs: M) -> Self {
        Self {
            left: inputs.filled(0),
        }
    }

    /// One correction's verdicts: doubt renewed where `doubt`, one
    /// correction less elsewhere.
    pub(crate) fn note(&mut self, doubt: &M::Array<bool>) {
        for (left, doubt) in self.left.as_mut().iter_mut().zip(doubt.as_ref()) {
            *left = if *doubt {
                DOUBT_HOLD_CORRECTIONS
            } else {
                left.saturating_sub(1)
            };
        }
    }

    /// Renews the doubt where `doubt`, leaving the rest as it is (a tick
    /// without a correction: a silent sensor).
    pub(crate) fn renew(&mut self, doubt: &M::Array<bool>) {
        for (left, doubt) in self.left.as_mut().iter_mut().zip(doubt.as_ref()) {
            if *doubt {
                *left = DOUBT_HOLD_CORRECTIONS;
            }
        }
    }

    /// Some input is in doubt.
    pub(crate) fn any(&self) -> bool {
        self.left.as_ref().iter().any(|l| *l > 0)
    }
}

/// One sensor's sign of trouble this tick, for [`Suspicion`]: `Some(true)`
/// when its reading was not fused for a reason that puts its measurement in
/// doubt (a fault, too old, colder than the physics, stuck, silent, or
/// refused by the gate `rejections >= 2` times in a row: a single rejection
/// is the gate refusing a spike), `Some(false)` when it was fused, `None`
/// when it said nothing.
pub(crate) fn sensor_doubt(status: &SensorStatus, rejections: u16) -> Option<bool> {
    match status {
        SensorStatus::Fused { .. } => Some(false),
        SensorStatus::NoReading => None,
        SensorStatus::Rejected { .. } => (rejections >= 2).then_some(true),
        _ => Some(true),
    }
}

/// Drops the negative heat-input biases \[W\] of the inputs in doubt: a
/// sensor that lied cold before it was caught left its input's bias
/// negative, and with no reading fused the model would go on heating too
/// little on it (one thermocouple per Omnimagnet solenoid drifting -0.05
/// K/s: the estimate went on falling behind the truth after the gate had
/// refused the sensor). Without the bias the estimate returns toward the
/// model; erring hot, a positive bias is kept.
pub(crate) fn drop_cold_biases<'b, M: Length>(
    biases_w: impl Iterator<Item = &'b mut f32>,
    doubt: &M::Array<bool>,
) {
    for (bias, doubt) in biases_w.zip(doubt.as_ref()) {
        if *doubt && *bias < 0.0 {
            *bias = 0.0;
        }
    }
}

/// Raises each upper bound \[degC\] in `nodes` to the shadow's,
/// `shadow_upper_c`, where that is hotter (or NaN: a NaN must win, the
/// limiter then gives the floor): the protection while a measurement is
/// in doubt (see [`Suspicion`]) or the model is stale (see
/// [`RefreshWatchdog`]).
pub(crate) fn raise_to_shadow<S: Scalar>(
    upper_c: &mut [S],
    shadow_upper_c: &[S],
    nodes: impl Iterator<Item = usize>,
) {
    for node in nodes {
        if let (Some(u), Some(s)) = (upper_c.get_mut(node), shadow_upper_c.get(node)) {
            // Not `max`: a NaN must win (`partial_cmp` is `None` for NaN
            // alone; a fixed-point scalar has none).
            if s.partial_cmp(s).is_none() || *s > *u {
                *u = *s;
            }
        }
    }
}

/// The protection on the shadow, every observer's: while a measurement is
/// in doubt ([`Suspicion`]) or the model is stale ([`RefreshWatchdog`]),
/// each upper bound \[degC\] of `upper_c` in `nodes` (the elements with a
/// limit) is raised to the bound `bound` gives the shadow's temperatures
/// `shadow_c` \[degC\] at the ambient `ambient_c` \[degC\], where that is
/// hotter ([`raise_to_shadow`]). The estimate is then the model alone or
/// what a lying sensor dragged, the shadow the physics no reading moved:
/// a flagged fault can only make the protection err hot.
pub(crate) fn protect_on_shadow<S: Scalar, N: Length>(
    bound: &UpperBound<S, N>,
    shadow_c: &N::Array<S>,
    ambient_c: S,
    upper_c: &mut N::Array<S>,
    nodes: impl Iterator<Item = usize>,
) {
    // Every entry is written by `upper_c`.
    let mut shadow_upper_c = N::filled_like(shadow_c, S::ZERO);
    bound.upper_c(shadow_c, ambient_c, &mut shadow_upper_c);
    raise_to_shadow(upper_c.as_mut(), shadow_upper_c.as_ref(), nodes);
}

/// Refresh periods without a model install after which a declared model
/// refresh is stale (the watchdog, `RefreshWatchdog`, of every observer
/// whose model is refreshed): one refresh missed or late is a busy
/// background task, three in a row a dead one.
pub const MODEL_STALE_PERIODS: u32 = 3;

/// The watchdog of a declared model refresh (a background task that
/// re-linearises a nonlinear plant's model at the estimate and installs it
/// between ticks; the Omnimagnet's `model_refresh_s`): every tick adds its
/// model steps to a saturating count that an install resets, and a count
/// beyond [`MODEL_STALE_PERIODS`] periods flags the tick
/// [`InputFlags::MODEL_STALE`] and puts the protection on the shadow
/// ([`protect_on_shadow`]). One add and one compare per tick; a refresh
/// not declared never goes stale (the bound is `u32::MAX`, which the
/// saturating count never exceeds). The count is state, the bound
/// configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct RefreshWatchdog {
    /// Model steps without an install after which the model is stale;
    /// `u32::MAX`: no refresh declared.
    stale_after_steps: u32,
}

impl RefreshWatchdog {
    /// The bound for a declared refresh of `refresh_s` \[s\] at a model
    /// step of `step_us` \[us\]: [`MODEL_STALE_PERIODS`] periods rounded up
    /// to whole steps; no refresh declared (`None`): never stale.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] (`"model_refresh_s"`) for a period
    /// that is not finite, not positive, or whose watchdog does not fit a
    /// `u32` of steps.
    pub(crate) fn new(refresh_s: Option<f64>, step_us: u32) -> Result<Self, BuildError> {
        let Some(refresh_s) = refresh_s else {
            return Ok(Self::from_steps(u32::MAX));
        };
        let invalid = BuildError::InvalidParameter {
            name: "model_refresh_s",
        };
        if !(refresh_s.is_finite() && refresh_s > 0.0) || step_us == 0 {
            return Err(invalid);
        }
        let steps =
            libm::ceil(f64::from(MODEL_STALE_PERIODS) * refresh_s * 1e6 / f64::from(step_us));
        if steps < f64::from(u32::MAX) {
            Ok(Self::from_steps((steps as u32).max(1)))
        } else {
            Err(invalid)
        }
    }

    /// The watchdog whose bound is `stale_after_steps` model steps
    /// (`u32::MAX`: no refresh declared), as the tables carry it.
    pub(crate) const fn from_steps(stale_after_steps: u32) -> Self {
        Self { stale_after_steps }
    }

    /// The bound in model steps, `u32::MAX` when no refresh is declared
    /// (the tables' and the fingerprint's form).
    pub(crate) const fn bound_steps(&self) -> u32 {
        self.stale_after_steps
    }

    /// The bound in model steps; `None` when no refresh is declared.
    pub(crate) const fn declared_steps(&self) -> Option<u32> {
        if self.stale_after_steps == u32::MAX {
            None
        } else {
            Some(self.stale_after_steps)
        }
    }

    /// The model whose age is `age_steps` (model steps since the state was
    /// made or a model last installed) is stale.
    #[inline]
    pub(crate) fn stale(&self, age_steps: u32) -> bool {
        age_steps > self.stale_after_steps
    }

    /// A tick's `steps` model steps on the count `age_steps`; whether the
    /// model is now stale (the tick is flagged [`InputFlags::MODEL_STALE`]).
    #[inline]
    pub(crate) fn aged(&self, age_steps: &mut u32, steps: u32) -> bool {
        *age_steps = age_steps.saturating_add(steps);
        self.stale(*age_steps)
    }
}

/// How long the shadow's movement under an unchanged reading is watched
/// at the threshold alone before the window restarts \[s\]: within it, a
/// move of the physics by the threshold makes the reading stuck whatever
/// the device's temperature (the fast test); the slow approach of a model
/// to a steady state a little off the device's (while a quantised
/// thermocouple at a steady temperature repeats its code) moves it by well
/// under the threshold in a window. Since the reading's last change the
/// slow test applies instead (see [`StuckWatch`]).
pub(crate) const STUCK_WINDOW_S: f64 = 120.0;

/// The readings in [`STUCK_WINDOW_S`] at one per `correction_period_s`
/// \[s\] (at least 2).
pub(crate) fn stuck_window(correction_period_s: f64) -> u32 {
    let n = libm::ceil(STUCK_WINDOW_S / correction_period_s);
    if n.is_finite() && n >= 2.0 {
        n.min(f64::from(u32::MAX)) as u32
    } else {
        2
    }
}

/// The checks' settings as the tick's screens take them. Here, not with
/// the settings in [`super::vocabulary`]: the vocabulary names the
/// settings, the screens that read them are this module's (and the
/// vocabulary imports nothing from it).
impl SensorChecks {
    /// The consistency band, in the tick's `f32`.
    pub(crate) fn band(&self) -> Band {
        Band {
            offset_k: self.consistency_offset_k as f32,
            fraction: self.consistency_fraction as f32,
        }
    }

    /// The stuck test for readings every `correction_period_s` \[s\].
    pub(crate) fn stuck_test(&self, correction_period_s: f64) -> StuckTest {
        StuckTest {
            threshold_k: self.stuck_threshold_k as f32,
            tolerance_k: self.stuck_tolerance_k as f32,
            window: stuck_window(correction_period_s),
        }
    }
}

/// Stuck readings, told without the estimate they drag: a reading that
/// has not changed (to the bit) while the shadow model at its node moved,
///
/// * within [`STUCK_WINDOW_S`] (a restarting window), by more than the
///   threshold (the fast test: the heating rates that matter, 0.1-0.5 K/s,
///   are flagged within seconds), or
/// * since the reading last changed, by more than the threshold plus the
///   band's share of the node's rise (`fraction * |shadow - ambient|`,
///   taken when the reading changed): the slow test.
///
/// Why the slow test: a live sensor repeats its code only while the truth
/// moves less than its quantum, so what the shadow moves since the last
/// change beyond that is the shadow's own error, and that error is the
/// band's share of a rise. A shadow whose rise and time constant are 25 %
/// off (slower) still creeps after the device has settled on one code:
/// about `1.25 R^0.2 q^0.8` (1.0 K for a rise `R` of 100 K and a quantum
/// `q` of 0.25 K, 1.2 K for 200 K) after a heating, about the shadow's
/// remaining rise after a cooling to the ambient; the share of the rise at
/// the change covers both (25 K and 0.2 K). Near the ambient the share is
/// small and the slow test takes a reading stuck at the threshold: a
/// housing sensor stuck at the onset of a trace that warms it 1 K in
/// 273 s but never 1 K within one window was flagged 338 s after it stuck
/// with the window alone (65 s after the truth was 1 K off it).
///
/// The verdict holds until the reading changes: a stuck sensor stays out
/// of the correction even when the physics later moves slowly (before, the
/// window's restart let it back in, and a stuck thermocouple at 3.1 A
/// dragged its solenoid's estimate 9 K). Four scalars and a count per
/// sensor; no history.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StuckWatch<P: Length> {
    /// Each sensor's reading when it last changed (by more than the
    /// test's tolerance) \[degC\] (NaN: none yet).
    last_c: P::Array<f32>,
    /// The shadow at the sensor's node when the reading last changed
    /// \[degC\].
    shadow_at_change_c: P::Array<f32>,
    /// What the shadow may move since the change under a live reading
    /// \[K\]: the threshold plus the band's share of the rise there.
    allowance_k: P::Array<f32>,
    /// The shadow at the sensor's node when the window last restarted
    /// \[degC\].
    shadow_at_window_c: P::Array<f32>,
    /// Readings since the window restarted.
    since: P::Array<u32>,
    /// Judged stuck, until the reading changes.
    stuck: P::Array<bool>,
}

impl<P: Length> StuckWatch<P> {
    /// No reading seen yet, on `sensors` sensors.
    pub(crate) fn new(sensors: P) -> Self {
        Self {
            last_c: sensors.filled(f32::NAN),
            shadow_at_change_c: sensors.filled(f32::NAN),
            allowance_k: sensors.filled(f32::NAN),
            shadow_at_window_c: sensors.filled(f32::NAN),
            since: sensors.filled(0),
            stuck: sensors.filled(false),
        }
    }

    /// Takes every stuck sample out of the correction, marking it
    /// [`SensorStatus::Stuck`] (see the type's docs); `shadow_c[j]` is the
    /// shadow at sensor `j`'s node \[degC\], `ambient_c` the ambient
    /// \[degC\], `fraction` the band's share of the rise. NaN gives no
    /// verdict. Returns which readings changed and which sensors were
    /// judged stuck at this screen.
    pub(crate) fn screen(
        &mut self,
        samples: &mut P::Array<Option<f32>>,
        statuses: &mut P::Array<SensorStatus>,
        shadow_c: &P::Array<f32>,
        ambient_c: f32,
        test: &StuckTest,
        fraction: f32,
    ) -> StuckEvents<P> {
        let mut events = StuckEvents::<P> {
            changed: P::filled_like::<_, bool>(&*samples, false),
            became_stuck: P::filled_like::<_, bool>(&*samples, false),
        };
        // Slices of stated types: the vectors are of the sensors' length.
        let changed: &mut [bool] = events.changed.as_mut();
        let became: &mut [bool] = events.became_stuck.as_mut();
        let last_c: &mut [f32] = self.last_c.as_mut();
        let shadow_at_change_c: &mut [f32] = self.shadow_at_change_c.as_mut();
        let allowance_k: &mut [f32] = self.allowance_k.as_mut();
        let shadow_at_window_c: &mut [f32] = self.shadow_at_window_c.as_mut();
        let since_readings: &mut [u32] = self.since.as_mut();
        let stuck_now: &mut [bool] = self.stuck.as_mut();
        let shadow_c: &[f32] = shadow_c.as_ref();
        for (j, ((sample, status), (changed, became_stuck))) in samples
            .as_mut()
            .iter_mut()
            .zip(statuses.as_mut().iter_mut())
            .zip(changed.iter_mut().zip(became.iter_mut()))
            .enumerate()
        {
            let (
                Some(t),
                Some(last),
                Some(at_change),
                Some(allowance),
                Some(at_window),
                Some(since),
                Some(stuck),
                Some(shadow),
            ) = (
                *sample,
                last_c.get_mut(j),
                shadow_at_change_c.get_mut(j),
                allowance_k.get_mut(j),
                shadow_at_window_c.get_mut(j),
                since_readings.get_mut(j),
                stuck_now.get_mut(j),
                shadow_c.get(j),
            )
            else {
                continue;
            };
            let moved = if test.tolerance_k > 0.0 {
                // NaN (no reading yet): a new value.
                let step_k = (t - *last).abs();
                step_k.is_nan() || step_k > test.tolerance_k
            } else {
                t.to_bits() != last.to_bits()
            };
            if moved {
                // A new value: both references restart.
                *last = t;
                *at_change = *shadow;
                *allowance = test.threshold_k + fraction * (*shadow - ambient_c).abs();
                *at_window = *shadow;
                *since = 0;
                *stuck = false;
                *changed = true;
                continue;
            }
            if *since >= test.window && !*stuck {
                // A window without a verdict: the fast test restarts.
                *at_window = *shadow;
                *since = 0;
            }
            *since = since.saturating_add(1);
            let in_window_k = (*shadow - *at_window).abs();
            let since_change_k = (*shadow - *at_change).abs();
            let was_stuck = *stuck;
            *stuck |= in_window_k > test.threshold_k || since_change_k > *allowance;
            *became_stuck = *stuck && !was_stuck;
            if *stuck {
                *sample = None;
                *status = SensorStatus::Stuck {
                    model_moved_k: since_change_k.max(in_window_k),
                };
            }
        }
        events
    }
}

/// What one screen of the [`StuckWatch`] saw, per sensor.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StuckEvents<P: Length> {
    /// The reading changed (by more than the test's tolerance): the
    /// references restarted.
    pub changed: P::Array<bool>,
    /// Judged stuck at this screen, not before.
    pub became_stuck: P::Array<bool>,
}

/// The stuck sensor's rewind: each sensor's heat-input biases \[W\] when
/// its reading last changed, and the step that takes back what it taught
/// them once it is found stuck. Until the stuck test sees it, an unchanged
/// reading under a moving physics is fused like any other, and what it
/// teaches a bias stays after the sensor is dropped (a housing
/// thermocouple stuck while the drive cooled left a positive bias: the hot
/// spot read 6.3 K hot an hour on). One rule for the Omnimagnet and the
/// network observers.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StuckRewind<P: Length, M: Length> {
    /// Sensor `j`'s biases when its reading last changed \[W\].
    bias_at_change_w: P::Array<M::Array<f32>>,
}

impl<P: Length, M: Length> StuckRewind<P, M> {
    /// No bias noted (zero: a bias starts at zero), for `sensors`
    /// sensors and `inputs` inputs.
    pub(crate) fn new(sensors: P, inputs: M) -> Self {
        let none = inputs.filled(0.0);
        Self {
            bias_at_change_w: sensors.each(|_| none.clone()),
        }
    }

    /// After a stuck screen (`events`): notes the biases (`x[first_bias
    /// ..][..M]`) at every sensor whose reading changed, and puts each
    /// bias not in `skip` back at its value when a sensor just found stuck
    /// last changed, the other states moving by their regression on it
    /// ([`condition_on`](crate::filter::condition_on) with `cov`, the
    /// steady posterior); `also(x, at_change)` then takes back what the
    /// skipped biases learnt (the network's shared heat).
    #[inline]
    pub(crate) fn rewind<S: Dim>(
        &mut self,
        x: &mut OVector<f32, S>,
        cov: &OMatrix<f32, S, S>,
        first_bias: usize,
        events: &StuckEvents<P>,
        skip: &M::Array<bool>,
        mut also: impl FnMut(&mut OVector<f32, S>, &M::Array<f32>),
    ) where
        DefaultAllocator: Allocator<S, S> + Allocator<S>,
    {
        for ((at_change, changed), became_stuck) in self
            .bias_at_change_w
            .as_mut()
            .iter_mut()
            .zip(events.changed.as_ref())
            .zip(events.became_stuck.as_ref())
        {
            if *changed {
                for (m, bias) in at_change.as_mut().iter_mut().enumerate() {
                    *bias = x.get(first_bias + m).copied().unwrap_or(0.0);
                }
            } else if *became_stuck {
                for (m, (bias, skip)) in at_change.as_ref().iter().zip(skip.as_ref()).enumerate() {
                    if *skip {
                        continue;
                    }
                    crate::filter::condition_on(x, cov, first_bias + m, *bias);
                }
                also(x, at_change);
            }
        }
    }
}

/// Readings the gate refused as colder than the estimate, held out of the
/// gate's *recovery* while they move away from the physics.
///
/// Why: the gate judges a reading against the estimate it pulls, and after
/// `recover_after` corrections in which every reading was refused it widens
/// the covariance and fuses them anyway (the model may be what is wrong). A
/// thermocouple drifting down 0.05 K/s on a model file's only sensor was
/// refused four times in a row, then the recovery fused it in one step
/// (the housing's estimate fell 0.9 K at once) and the steady gain followed
/// it again until the next refusals: a ratchet that left the estimate 4.3 K
/// below the truth (7.8 K from the later onset) while the reading was still
/// inside the physics band. The shadow breaks the tie the gate cannot: a
/// reading the gate refused `suspect_after` times in a row, colder than
/// the estimate and than the shadow, is *held* (not offered to the gate, so
/// no recovery takes it; reported [`SensorStatus::Rejected`]) for as long as
/// the gate would still refuse it against the estimate. The caller raises
/// the estimate to the shadow when nothing else was fused (erring hot: the
/// physics no reading moved).
///
/// A model that is off (not a sensor) must still be corrected: a held
/// reading whose offset from the shadow has not grown colder by the stuck
/// threshold within the stuck window is released to the gate and its
/// recovery (a steady offset is the model's error; a drift moves), and is
/// not held again before it is fused once.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DriftHold<P: Length> {
    /// `reading - shadow` when the hold began \[K\].
    offset_at_hold_k: P::Array<f32>,
    /// Readings since the hold began.
    since: P::Array<u32>,
    /// [`HoldFlags`] of each sensor: a byte, not three `bool`s (the
    /// Omnimagnet's six sensors: 12 B of RAM fewer).
    flags: P::Array<u8>,
}

/// The bits of a sensor's [`DriftHold`] flags.
struct HoldFlags;

impl HoldFlags {
    /// Held out of the gate.
    const HELD: u8 = 1;
    /// Moved colder than the shadow by the threshold while held.
    const DRIFTING: u8 = 2;
    /// Released after a steady window; not held again until fused.
    const SPENT: u8 = 4;
}

/// What [`DriftHold::screen`] needs of the filter for a sensor in
/// question.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GateView {
    /// The estimate at the sensor's node \[degC\].
    pub estimate_c: f32,
    /// The gate's innovation variance \[K^2\].
    pub innovation_var_k2: f32,
}

impl<P: Length> DriftHold<P> {
    /// Nothing held, on `sensors` sensors.
    pub(crate) fn new(sensors: P) -> Self {
        Self {
            offset_at_hold_k: sensors.filled(0.0),
            since: sensors.filled(0),
            flags: sensors.filled(0),
        }
    }

    /// Whether any sensor is held, spent, or refused `suspect_after` times
    /// in a row (`rejections`): when none is (a healthy correction's every
    /// time), [`Self::screen`] has nothing to do, and this one pass of
    /// compares is its cost (the Omnimagnet's six thermocouples: its loop
    /// cost their correction tick about 250 instructions on a
    /// Cortex-M4F).
    #[inline(always)]
    fn in_question(&self, rejections: &P::Array<u16>, suspect_after: u16) -> bool {
        // Folds without a branch per sensor (cheaper than `any` here).
        let flagged = self.flags.as_ref().iter().fold(0, |all, f| all | f);
        let most_rejections = rejections.as_ref().iter().fold(0, |most, r| most.max(*r));
        suspect_after != 0 && (flagged != 0 || most_rejections >= suspect_after)
    }

    /// Takes the held samples out of the correction (see the type's docs),
    /// marking them [`SensorStatus::Rejected`]; `rejections[j]` is the
    /// gate's consecutive refusals of sensor `j`, `gate` its policy (a
    /// sensor is in question from `suspect_after` refusals on), `stuck`
    /// the stuck test's settings, and `view(j)` the filter's view of
    /// sensor `j`, formed only for a sensor in question (a healthy
    /// sensor's every reading forms none).
    ///
    /// Returns whether a reading was held and none is left to fuse: every
    /// present reading refused, one as drifting colder than the physics.
    /// The caller then takes the estimate back to the shadow, as for a
    /// common-mode fault (both filtered observers' rule).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn screen(
        &mut self,
        samples: &mut P::Array<Option<f32>>,
        statuses: &mut P::Array<SensorStatus>,
        shadow_c: &P::Array<f32>,
        rejections: &P::Array<u16>,
        gate: &GatePolicy<f32>,
        stuck: &StuckTest,
        mut view: impl FnMut(usize) -> GateView,
    ) -> bool {
        let suspect_after = gate.suspect_after;
        if !self.in_question(rejections, suspect_after) {
            return false;
        }
        let mut any_held = false;
        let screened = samples
            .as_mut()
            .iter_mut()
            .zip(statuses.as_mut().iter_mut());
        for (j, (sample, status)) in screened.enumerate() {
            let (Some(t), Some(shadow), Some(&rejections)) = (
                *sample,
                shadow_c.as_ref().get(j),
                rejections.as_ref().get(j),
            ) else {
                continue;
            };
            let (Some(at), Some(since), Some(flags)) = (
                self.offset_at_hold_k.as_mut().get_mut(j),
                self.since.as_mut().get_mut(j),
                self.flags.as_mut().get_mut(j),
            ) else {
                continue;
            };
            if rejections == 0 {
                *flags &= !HoldFlags::SPENT;
            }
            let held = *flags & HoldFlags::HELD != 0;
            let spent = *flags & HoldFlags::SPENT != 0;
            if !held && (spent || rejections < suspect_after) {
                // Not in question (a healthy sensor's every reading): no
                // view, no NIS (on a core without an FPU, soft-float
                // operations fewer).
                continue;
            }
            let g = view(j);
            // A closure keeps the compares behind `held` (computed ahead,
            // they cost the M0 footprint 56 B).
            let colder = || t < *shadow && t < g.estimate_c;
            if !held && !colder() {
                // Not colder than the physics and the estimate.
                continue;
            }
            let nu = t - g.estimate_c;
            let nis = nu * nu / g.innovation_var_k2;
            // NaN refuses: no verdict is no admission.
            let refused = nis.is_nan() || nis > gate.threshold;
            if !held {
                if !refused {
                    continue;
                }
                *flags = HoldFlags::HELD;
                *at = t - shadow;
                *since = 0;
            }
            if !refused || t >= *shadow {
                // The gate takes it again against the estimate (nothing
                // flagged: its drift counts from the next hold, and the
                // screen's first pass finds no sensor in question).
                *flags = 0;
                continue;
            }
            *since = since.saturating_add(1);
            if *at - (t - shadow) > stuck.threshold_k {
                *flags |= HoldFlags::DRIFTING;
            }
            if *flags & HoldFlags::DRIFTING == 0 && *since >= stuck.window {
                // A steady offset: the model's error, for the recovery.
                *flags = HoldFlags::SPENT;
                continue;
            }
            *sample = None;
            *status = SensorStatus::Rejected { nis };
            any_held = true;
        }
        any_held && samples.as_ref().iter().all(Option::is_none)
    }
}

/// The stuck test's settings: the shadow's movement under an unchanged
/// reading that makes it stuck \[K\], within a window of readings (and,
/// with the band's share of the rise, since the reading last changed: see
/// [`StuckWatch`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct StuckTest {
    /// \[K\].
    pub threshold_k: f32,
    /// Readings in [`STUCK_WINDOW_S`].
    pub window: u32,
    /// How far a reading may move and still count as unchanged \[K\]
    /// (0: to the bit). A detached thermocouple's converter jitters by a
    /// code or two around the room's temperature: no two readings alike,
    /// so the bit test never sees it.
    pub tolerance_k: f32,
}

/// Holds this correction's samples against the physics: the band (colder
/// than physics), then the stuck test. Returns `true` for a common-mode
/// fault (some reading arrived and every one was refused) and the stuck
/// test's events.
pub(crate) fn screen_readings<P: Length>(
    band: &Band,
    stuck: &StuckTest,
    watch: &mut StuckWatch<P>,
    samples: &mut P::Array<Option<f32>>,
    statuses: &mut P::Array<SensorStatus>,
    shadow_c: &P::Array<f32>,
    ambient_c: f32,
) -> (bool, StuckEvents<P>) {
    let present = samples.as_ref().iter().any(Option::is_some);
    band.screen::<P>(samples, statuses, shadow_c, ambient_c);
    let events = watch.screen(samples, statuses, shadow_c, ambient_c, stuck, band.fraction);
    (
        present && samples.as_ref().iter().all(Option::is_none),
        events,
    )
}

/// Silent sensors: no reading, not even a fault, for longer than the
/// caller's limit (two correction periods) since the last one (or since the
/// watch began).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SilenceWatch<P: Length> {
    /// When each sensor was last heard \[us\] (or the watch began).
    last_heard_us: P::Array<u32>,
    /// The watch has begun: its first tick notes every sensor as heard
    /// (one flag, not an `Option` per sensor: the Omnimagnet's six
    /// sensors, 20 B of RAM fewer).
    begun: bool,
}

impl<P: Length> SilenceWatch<P> {
    /// Nothing heard yet, on `sensors` sensors.
    pub(crate) fn new(sensors: P) -> Self {
        Self {
            last_heard_us: sensors.filled(0),
            begun: false,
        }
    }

    /// Notes which sensors were heard at `now_us` \[us\] and marks those
    /// silent for more than `silent_after_us` \[us\] (if nothing else was
    /// reported for them this tick) [`SensorStatus::Silent`].
    pub(crate) fn watch(
        &mut self,
        heard: &P::Array<bool>,
        now_us: u32,
        silent_after_us: u32,
        statuses: &mut P::Array<SensorStatus>,
    ) {
        if !self.begun {
            self.last_heard_us = P::filled_like(heard, now_us);
            self.begun = true;
            return;
        }
        let watched = self.last_heard_us.as_mut().iter_mut().zip(heard.as_ref());
        for ((last, heard), status) in watched.zip(statuses.as_mut()) {
            if *heard {
                *last = now_us;
                continue;
            }
            let quiet_us = now_us.wrapping_sub(*last);
            if quiet_us > silent_after_us && *status == SensorStatus::NoReading {
                *status = SensorStatus::Silent {
                    for_ms: quiet_us / 1000,
                };
            }
        }
    }
}

/// The mean `I^2` of each current over a block of model steps.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct BlockMean<M: Length> {
    /// Sum over the block's steps of each current squared \[A^2\].
    i2_sum_a2: M::Array<f32>,
    steps: u32,
}

/// Copied where its sums are (arrays: an MCU's).
impl<M: Length> Copy for BlockMean<M> where M::Array<f32>: Copy {}

impl<M: Length> BlockMean<M> {
    /// An empty block of `currents`.
    pub(crate) fn new(currents: M) -> Self {
        Self {
            i2_sum_a2: currents.filled(0.0),
            steps: 0,
        }
    }

    /// An empty block of this one's currents.
    fn emptied(&self) -> Self {
        Self {
            i2_sum_a2: M::filled_like(&self.i2_sum_a2, 0.0),
            steps: 0,
        }
    }

    /// Accounts for `steps` model steps at the square currents `sq_a2`
    /// \[A^2\] (each step's mean `I^2`); returns the block when a block of
    /// `block_steps` is complete (the steps past it start the next block
    /// at its mean). Its mean ([`Self::mean_sq_a2`]) is left to whoever
    /// steps the block: a block that waits for a light tick takes its
    /// division and multiplies there, not on the model step's tick. Square
    /// currents throughout, not RMS currents: a block's power is `R(T)`
    /// times its mean `I^2`, and no root is taken (on a core without an
    /// FPU, a soft-float `sqrtf` per current).
    pub(crate) fn add(
        &mut self,
        steps: u32,
        sq_a2: &M::Array<f32>,
        block_steps: u32,
    ) -> Option<Self> {
        if steps == 0 {
            return None;
        }
        let sums = self.i2_sum_a2.as_mut().iter_mut().zip(sq_a2.as_ref());
        if steps == 1 {
            // Most ticks: without the multiply by one step.
            for (sum, i2) in sums {
                *sum += i2;
            }
        } else {
            let n = steps as f32;
            for (sum, i2) in sums {
                *sum += i2 * n;
            }
        }
        self.steps = self.steps.saturating_add(steps);
        let block_steps = block_steps.max(1);
        if self.steps < block_steps {
            return None;
        }
        let empty = self.emptied();
        let complete = core::mem::replace(self, empty);
        let rest = complete.steps - block_steps;
        if rest > 0 {
            // Only a catch-up runs past the block: its steps past it open
            // the next block at the complete one's mean.
            let rest_steps = rest as f32;
            self.i2_sum_a2 = M::mapped(&complete.mean_sq_a2(), |i2| i2 * rest_steps);
            self.steps = rest;
        }
        Some(complete)
    }

    /// Each current's mean `I^2` over the block's steps \[A^2\] (one
    /// division, then a multiply per current).
    pub(crate) fn mean_sq_a2(&self) -> M::Array<f32> {
        let per_step = 1.0 / self.steps.max(1) as f32;
        M::mapped(&self.i2_sum_a2, |s| s * per_step)
    }
}

/// The network observer's shadow: the exact zero-order hold of one block
/// in the observer's deviation coordinates, and its band.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Shadow<Z: Sizes>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    /// `Ad - I` of one block (dimensionless).
    pub phi_minus_i: OMatrix<f32, Z::NodeDim, Z::NodeDim>,
    /// `Bd` of the powers over one block \[K/W\].
    pub bd_power: OMatrix<f32, Z::NodeDim, Z::InputDim>,
    /// `Gd` of the boundaries over one block (dimensionless).
    pub gd_boundary: OMatrix<f32, Z::NodeDim, Z::BoundaryDim>,
    /// The block's constant term in deviation coordinates \[K\].
    pub constant_k: OVector<f32, Z::NodeDim>,
    /// Model steps per block.
    pub block_steps: u32,
    /// A complete block waits for a tick without a step or a reading (a
    /// model step several ticks long; see [`Self::stepped`]).
    pub waits_for_light_tick: bool,
    /// The block's step in integer arithmetic, when the model steps in
    /// it and the block's tables fit its scales (see
    /// [`Self::block_step`]).
    #[cfg(feature = "integer-step")]
    pub integer_block: Option<FixedStep<Z>>,
    /// The consistency band.
    pub band: Band,
    /// The band's image on the heat-input biases.
    pub bias_bound: BiasBound<Z::InputDim>,
}

/// The network shadow's state: deviations from the observer's origin
/// \[K\], their carry, and the block in progress.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ShadowState<Z: Sizes> {
    dev_k: NodeVector<Z, f32>,
    residual_k: NodeVector<Z, f32>,
    block: BlockMean<Z::InputDim>,
    /// The integer block step's own states, whose image `dev_k` is (see
    /// [`StepMemory`]); unused by the `f32` block step.
    #[cfg(feature = "integer-step")]
    integer: StepMemory<Z::NodeDim>,
}

impl<Z: Sizes> ShadowState<Z> {
    /// A shadow of `sizes` at the deviations `dev_k` \[K\].
    pub(crate) fn new(sizes: &Z, dev_k: NodeVector<Z, f32>) -> Self {
        Self {
            residual_k: Z::NodeDim::filled_like(&dev_k, 0.0),
            dev_k,
            block: BlockMean::new(sizes.input_dim()),
            #[cfg(feature = "integer-step")]
            integer: StepMemory::new(sizes.node_dim()),
        }
    }

    /// The shadow's deviation of `node` from the origin \[K\] (NaN out of
    /// range).
    pub(crate) fn dev_k(&self, node: usize) -> f32 {
        self.dev_k.as_ref().get(node).copied().unwrap_or(f32::NAN)
    }

    /// All deviations \[K\].
    pub(crate) fn devs_k(&self) -> &NodeVector<Z, f32> {
        &self.dev_k
    }

    /// Moves the shadow to the deviations `dev_k` \[K\] (the carry
    /// cleared, the block in progress kept): the start's warm-up, while
    /// the shadow knows no more than the filter (see
    /// [`super::start`]).
    pub(crate) fn reseed(&mut self, dev_k: NodeVector<Z, f32>) {
        self.dev_k = dev_k;
        self.residual_k = Z::NodeDim::filled_like(&self.dev_k, 0.0);
        #[cfg(feature = "integer-step")]
        self.integer.forget();
    }
}

impl<Z: Sizes> Shadow<Z>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    /// Accounts for `steps` (at least one) model steps at the square
    /// currents `sq_a2` \[A^2\] (each step's mean `I^2`) and advances the
    /// shadow by a complete block: at once, or with
    /// [`Self::waits_for_light_tick`] on the first later tick without a
    /// step or a reading ([`Self::between_steps`]), so that the block's
    /// step, the shadow's heaviest piece, lands beside neither (a second
    /// block completing first makes the waiting one step at once: bounded,
    /// one block step per call). Returns whether a block that waited
    /// stepped (the tick is busy then). `waiting` holds the block that
    /// waits, its sums of square currents (kept apart from `state`, out of
    /// the tick's hot fields; its mean is formed when it steps);
    /// `boundary_c` are the held boundaries, `origin_c` the origin
    /// \[degC\].
    #[allow(clippy::too_many_arguments)]
    // Inlined into the tick on a core with an FPU (its call and prologue
    // are a tenth of the three-phase plain tick there); not on one
    // without, whose footprint it would grow by 360 B.
    #[cfg_attr(target_abi = "eabihf", inline(always))]
    pub(crate) fn stepped(
        &self,
        state: &mut ShadowState<Z>,
        waiting: &mut Option<BlockMean<Z::InputDim>>,
        steps: u32,
        sq_a2: &InputVector<Z, f32>,
        boundary_c: &BoundaryVector<Z, f32>,
        source_node: &InputVector<Z, usize>,
        resistance: &InputVector<Z, DeviationResistance>,
        origin_c: f32,
    ) -> bool {
        let Some(complete) = state.block.add(steps, sq_a2, self.block_steps) else {
            return false;
        };
        let (block, waited) = if !self.waits_for_light_tick {
            (complete, false)
        } else {
            // It waits; one still waiting steps now (a whole block without
            // a light tick).
            match waiting.replace(complete) {
                Some(earlier) => (earlier, true),
                None => return false,
            }
        };
        self.block_step(state, &block, boundary_c, source_node, resistance, origin_c);
        waited
    }

    /// A tick without a model step: the waiting block's turn (see
    /// [`Self::stepped`]) unless it brought a reading (`reading`).
    /// Returns whether the waiting block stepped.
    #[allow(clippy::too_many_arguments)]
    #[cfg_attr(target_abi = "eabihf", inline(always))]
    pub(crate) fn between_steps(
        &self,
        state: &mut ShadowState<Z>,
        waiting: &mut Option<BlockMean<Z::InputDim>>,
        boundary_c: &BoundaryVector<Z, f32>,
        source_node: &InputVector<Z, usize>,
        resistance: &InputVector<Z, DeviationResistance>,
        origin_c: f32,
        reading: impl FnOnce() -> bool,
    ) -> bool {
        match waiting {
            Some(block) if !reading() => {
                self.block_step(state, block, boundary_c, source_node, resistance, origin_c);
                *waiting = None;
                true
            }
            _ => false,
        }
    }

    /// One block's exact step at its mean square currents \[A^2\].
    #[cfg_attr(target_abi = "eabihf", inline(always))]
    fn block_step(
        &self,
        state: &mut ShadowState<Z>,
        block: &BlockMean<Z::InputDim>,
        boundary_c: &BoundaryVector<Z, f32>,
        source_node: &InputVector<Z, usize>,
        resistance: &InputVector<Z, DeviationResistance>,
        origin_c: f32,
    ) {
        let mean_sq_a2 = block.mean_sq_a2();
        let (nodes, inputs) = self.bd_power.shape_generic();
        let mut power = OVector::<f32, Z::InputDim>::zeros_generic(inputs, U1);
        for (p, ((node, r), i2)) in power.iter_mut().zip(
            source_node
                .as_ref()
                .iter()
                .zip(resistance.as_ref())
                .zip(mean_sq_a2.as_ref()),
        ) {
            *p = r.resistance_ohm(state.dev_k(*node)) * i2;
        }
        let boundary_k = Z::BoundaryDim::mapped(boundary_c, |t| t - origin_c);
        // In integer arithmetic when the model steps in it: the block's
        // tables on the shadow's own Q16.48 states, kept between blocks
        // (read from the deviation and its carry before the first block
        // and after a reseed), the deviations their image. A non-finite
        // input or deviation (only a corrupted state) keeps the shadow
        // where it is, as the `f32` step does.
        #[cfg(feature = "integer-step")]
        if let Some(step) = &self.integer_block {
            step_in_memory(
                step,
                &mut state.integer,
                state.dev_k.as_mut(),
                &state.residual_k,
                &Z::InputDim::each(inputs, |m| power[m]),
                &boundary_k,
            );
            return;
        }
        let temps = VectorView::from_slice_generic(state.dev_k.as_ref(), nodes, U1);
        let boundaries = self.gd_boundary.shape_generic().1;
        let boundary = VectorView::from_slice_generic(boundary_k.as_ref(), boundaries, U1);
        let mut increment = self.constant_k.clone();
        increment.gemv(1.0, &self.phi_minus_i, &temps, 1.0);
        increment.gemv(1.0, &self.bd_power, &power, 1.0);
        increment.gemv(1.0, &self.gd_boundary, &boundary, 1.0);
        if increment.iter().all(|v| v.is_finite()) {
            for ((x, residual), inc) in state
                .dev_k
                .as_mut()
                .iter_mut()
                .zip(state.residual_k.as_mut().iter_mut())
                .zip(increment.iter())
            {
                *x = compensated_add(*x, *inc, residual);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sizes::ConstSizes;
    use nalgebra::{Const, SMatrix, SVector};

    /// One node, one boundary, one input.
    type One = ConstSizes<1, 1, 1>;

    const BAND: Band = Band {
        offset_k: 3.0,
        fraction: 0.25,
    };

    /// One node, capacity `c` \[J/K\], conductance `g` \[W/K\] to the
    /// ambient, stepped exactly over `dt` \[s\]: the steady rise per watt is
    /// `1 / g`, so the band's 3 K are `3 g` watts.
    #[test]
    fn bias_bound_is_the_band_over_the_steady_rise() {
        let (c, g, dt) = (400.0f64, 0.8f64, 0.5f64);
        let ad = libm::exp(-g * dt / c);
        let phi_minus_i = SMatrix::<f32, 1, 1>::new((ad - 1.0) as f32);
        let bd = SMatrix::<f32, 1, 1>::new(((1.0 - ad) / g) as f32);
        let bound = BiasBound::<Const<1>>::new(&BAND, &phi_minus_i, &bd);
        let expected_w = 3.0 * g;
        let got_w = f64::from(bound.offset_w[0]);
        assert!((got_w - expected_w).abs() < 1e-3 * expected_w, "{got_w}");
        // At 20 W of Joule power the limit is 2.4 + 5 W.
        let limit_w = bound.offset_w[0] + 0.25 * 20.0;
        for (bias, beyond) in [
            (0.0, false),
            (limit_w - 0.01, false),
            (-(limit_w - 0.01), false),
            (limit_w + 0.01, true),
            (-57.0, true),
            (f32::NAN, false),
        ] {
            assert_eq!(bound.beyond(&[bias], &[20.0]), [beyond], "{bias}");
        }
        // The test switched off (an infinite band) never flags.
        let off = Band {
            offset_k: f32::INFINITY,
            fraction: 0.25,
        };
        let bound = BiasBound::<Const<1>>::new(&off, &phi_minus_i, &bd);
        assert_eq!(bound.beyond(&[-1e6f32], &[20.0]), [false]);
    }

    /// One node, capacity 400 J/K, 0.8 W/K to a 20 degC ambient, a
    /// 2 ohm winding (no slope), blocks of 4 steps of 0.5 s, exact over a
    /// block; `waits` as a model step several ticks long sets it.
    fn one_node_shadow(waits: bool) -> Shadow<One> {
        let (c, g, block_s) = (400.0f64, 0.8f64, 2.0f64);
        let ad = libm::exp(-g * block_s / c);
        let phi_minus_i = SMatrix::<f32, 1, 1>::new((ad - 1.0) as f32);
        let bd_power = SMatrix::<f32, 1, 1>::new(((1.0 - ad) / g) as f32);
        Shadow {
            phi_minus_i,
            bd_power,
            gd_boundary: SMatrix::<f32, 1, 1>::new((1.0 - ad) as f32),
            constant_k: SVector::<f32, 1>::zeros(),
            block_steps: 4,
            waits_for_light_tick: waits,
            #[cfg(feature = "integer-step")]
            integer_block: None,
            band: BAND,
            bias_bound: BiasBound::new(&BAND, &phi_minus_i, &bd_power),
        }
    }

    const WINDING: [DeviationResistance; 1] = [DeviationResistance {
        r_at_origin_ohm: 2.0,
        slope_ohm_per_k: 0.0,
    }];

    /// Steps `steps` at `current_a` (its square, as the observers pass
    /// it) on a tick with or without a reading; says whether a block that
    /// waited stepped.
    fn tick_shadow(
        shadow: &Shadow<One>,
        state: &mut ShadowState<One>,
        waiting: &mut Option<BlockMean<Const<1>>>,
        steps: u32,
        current_a: f32,
        reading: bool,
    ) -> bool {
        let (boundary_c, node, origin_c) = (&[20.0], &[0], 20.0);
        if steps == 0 {
            return shadow.between_steps(
                state,
                waiting,
                boundary_c,
                node,
                &WINDING,
                origin_c,
                || reading,
            );
        }
        let sq_a2 = [current_a * current_a];
        shadow.stepped(
            state, waiting, steps, &sq_a2, boundary_c, node, &WINDING, origin_c,
        )
    }

    /// A block's mean `I^2` is its steps' sum over their count, formed
    /// when it is asked for; a catch-up's steps past the block open the
    /// next one at the complete block's mean, and a block that ends on its
    /// last step leaves the next one empty.
    #[test]
    fn a_block_is_the_mean_of_its_steps_and_a_catch_up_opens_the_next() {
        let mut block = BlockMean::new(Const::<2>);
        assert_eq!(block.add(1, &[4.0, 1.0], 4), None);
        assert_eq!(block.add(1, &[4.0, 1.0], 4), None);
        // 3 steps at [1, 7]: 5 steps in all, one past the block.
        let complete = block.add(3, &[1.0, 7.0], 4).expect("a complete block");
        // (4 + 4 + 3 * 1) / 5 and (1 + 1 + 3 * 7) / 5.
        assert_eq!(complete.mean_sq_a2(), [11.0 / 5.0, 23.0 / 5.0]);
        // The next block holds its one step at that mean, then 3 at [1, 1].
        let next = block.add(3, &[1.0, 1.0], 4).expect("a complete block");
        let expected = [(11.0 / 5.0 + 3.0) / 4.0, (23.0 / 5.0 + 3.0) / 4.0];
        for (got, want) in next.mean_sq_a2().iter().zip(expected) {
            assert!((got - want).abs() < 1e-6, "{got} vs {want}");
        }
        // Ended on its last step: the next block is empty.
        assert_eq!(block, BlockMean::new(Const::<2>));
    }

    /// A model stepping each tick steps the shadow's block on the tick
    /// that completes it; one whose step is several ticks long steps it on
    /// the first later tick without a step or a reading, to the same
    /// temperature (the block's mean `I^2` kept, the boundary held).
    #[test]
    fn a_complete_block_waits_for_a_light_tick_and_steps_the_same() {
        // At once: 4 steps at 5 A (50 W for 2 s).
        let at_once = one_node_shadow(false);
        let mut now = ShadowState::new(&One::default(), [0.0]);
        let mut none = None;
        for _ in 0..3 {
            assert!(!tick_shadow(&at_once, &mut now, &mut none, 1, 5.0, false));
            assert_eq!(now.devs_k(), &[0.0]);
        }
        assert!(!tick_shadow(&at_once, &mut now, &mut none, 1, 5.0, true));
        let expected_k = now.dev_k(0);
        // The exact rise of one block: 50 W over 2 s of a 500 s mode.
        let exact_k = 50.0 / 0.8 * (1.0 - libm::exp(-0.8 * 2.0 / 400.0));
        assert!(
            (f64::from(expected_k) - exact_k).abs() < 1e-5,
            "{expected_k} vs {exact_k}"
        );
        assert_eq!(none, None);

        // Waiting: the completing step tick and a reading's tick pass.
        let waiting = one_node_shadow(true);
        let mut later = ShadowState::new(&One::default(), [0.0]);
        let mut held = None;
        for _ in 0..4 {
            assert!(!tick_shadow(&waiting, &mut later, &mut held, 1, 5.0, false));
        }
        assert_eq!(held.map(|b| b.mean_sq_a2()), Some([25.0]));
        assert!(!tick_shadow(&waiting, &mut later, &mut held, 0, 0.0, true));
        assert_eq!(later.devs_k(), &[0.0]);
        // The first light tick: the block steps at its own current.
        assert!(tick_shadow(&waiting, &mut later, &mut held, 0, 0.0, false));
        assert_eq!(later.devs_k(), &[expected_k]);
        assert_eq!(held, None);
        assert!(!tick_shadow(&waiting, &mut later, &mut held, 0, 0.0, false));
        assert_eq!(later.devs_k(), &[expected_k]);

        // No light tick for a whole block: the waiting one steps when the
        // next completes (never two behind), and that one waits.
        let mut starved = ShadowState::new(&One::default(), [0.0]);
        let mut queue = None;
        let stepped: Vec<bool> = (0..8)
            .map(|_| tick_shadow(&waiting, &mut starved, &mut queue, 1, 5.0, true))
            .collect();
        assert_eq!(
            stepped,
            [false, false, false, false, false, false, false, true]
        );
        assert_eq!(starved.devs_k(), &[expected_k]);
        assert_eq!(queue.map(|b| b.mean_sq_a2()), Some([25.0]));
    }

    /// The shadow's block in integer arithmetic (a model that steps in
    /// it) follows the exact solution as the `f32` block does: 50 W into
    /// the one-node shadow for 500 blocks (1 000 s, two time constants),
    /// then 300 blocks at rest, against `62.5 (1 - exp(-t / 500 s))` and
    /// its decay, with a 1 K boundary offset held throughout.
    #[cfg(feature = "integer-step")]
    #[test]
    fn the_integer_block_step_follows_the_exact_solution() {
        use crate::discretize::StepTables;
        let f32_block = one_node_shadow(false);
        let tables = StepTables::<1, 1, 1> {
            phi_minus_i: [[f32_block.phi_minus_i[0]]],
            bd_power: [[f32_block.bd_power[0]]],
            gd_boundary: [[f32_block.gd_boundary[0]]],
            constant_k: [0.0],
        };
        let integer = Shadow {
            integer_block: FixedStep::of(&tables),
            ..one_node_shadow(false)
        };
        assert!(integer.integer_block.is_some());
        let exact = |t_s: f64, heated_s: f64| {
            let decay = |s: f64| libm::exp(-s / 500.0);
            let heat = if t_s <= heated_s {
                62.5 * (1.0 - decay(t_s))
            } else {
                62.5 * (1.0 - decay(heated_s)) * decay(t_s - heated_s)
            };
            // The boundary's 1 K settles with the same mode.
            heat + 1.0 - decay(t_s)
        };
        for shadow in [&f32_block, &integer] {
            let mut state = ShadowState::new(&One::default(), [0.0]);
            let mut none = None;
            for block in 1..=800u32 {
                let current_a = if block <= 500 { 5.0 } else { 0.0 };
                for _ in 0..4 {
                    shadow.stepped(
                        &mut state,
                        &mut none,
                        1,
                        &[current_a * current_a],
                        &[21.0],
                        &[0],
                        &WINDING,
                        20.0,
                    );
                }
                let t_s = 2.0 * f64::from(block);
                let want = exact(t_s, 1000.0);
                // The deviation and its carry (below the `f32` image's
                // last bit): the rounding of the `f32` tables alone.
                let got = f64::from(state.dev_k(0)) + f64::from(state.residual_k[0]);
                assert!((got - want).abs() < 1e-5, "block {block}: {got} vs {want}");
            }
        }
    }

    /// The stuck test of the campaigns: 1 K, the band's 25 %, a 240-reading
    /// window (120 s at 2 Hz).
    const STUCK: StuckTest = StuckTest {
        tolerance_k: 0.0,
        threshold_k: 1.0,
        window: 240,
    };

    /// One reading through a one-sensor watch: whether it was judged stuck.
    fn stuck(
        watch: &mut StuckWatch<Const<1>>,
        reading_c: f32,
        shadow_c: f32,
        test: &StuckTest,
    ) -> bool {
        let mut samples = [Some(reading_c)];
        let mut statuses = [SensorStatus::Fused { nis: 0.0 }];
        watch.screen(&mut samples, &mut statuses, &[shadow_c], 20.0, test, 0.25);
        assert_eq!(
            samples[0].is_none(),
            matches!(statuses[0], SensorStatus::Stuck { .. })
        );
        samples[0].is_none()
    }

    /// A stuck verdict from the window: the physics moves by the threshold
    /// within it; the verdict then holds while the reading repeats, even
    /// when the physics stands still for longer than the window; a new
    /// value ends it.
    #[test]
    fn stuck_verdict_holds_until_the_reading_moves() {
        let mut watch = StuckWatch::<Const<1>>::new(Const);
        let test = StuckTest {
            tolerance_k: 0.0,
            threshold_k: 1.0,
            window: 10,
        };
        let mut verdicts = Vec::new();
        let mut shadow = 50.0f32;
        for k in 0..40 {
            // The physics heats 0.3 K per reading for 10 readings, then
            // stands still; the reading never changes.
            if (1..=10).contains(&k) {
                shadow += 0.3;
            }
            verdicts.push(stuck(&mut watch, 50.0, shadow, &test));
        }
        // More than 1 K moved at the fourth reading (1.2 K): stuck from
        // there on.
        let first = verdicts.iter().position(|v| *v).unwrap();
        assert_eq!(first, 4);
        assert!(verdicts[first..].iter().all(|v| *v), "{verdicts:?}");
        // The reading moves: fused again.
        assert!(!stuck(&mut watch, 52.0, shadow, &test));
    }

    /// A detached thermocouple reads the room through a converter that
    /// jitters by a code (0.25 K) from reading to reading: to the bit it
    /// never repeats, so the bit test never sees it while the physics
    /// rises 3 K under it. With a tolerance of 0.3 K it is stuck once the
    /// physics has moved the threshold (1 K) past where the reading last
    /// moved; a live sensor with the same jitter that follows the physics
    /// is never stuck.
    #[test]
    fn a_tolerance_sees_a_jittering_reading_that_does_not_follow_the_physics() {
        let jitter = |k: u32| if k.is_multiple_of(2) { 0.0 } else { 0.25 };
        let verdicts = |tolerance_k: f32, follows: bool| {
            let test = StuckTest {
                tolerance_k,
                ..STUCK
            };
            let mut watch = StuckWatch::<Const<1>>::new(Const);
            (0..120u32)
                .map(|k| {
                    // The physics heats 0.025 K per reading (3 K in all).
                    let shadow_c = 22.0 + 0.025 * k as f32;
                    let truth_c = if follows { shadow_c } else { 22.0 };
                    // On the converter's 0.25 K codes, plus a code of jitter.
                    let reading_c = (truth_c / 0.25).floor() * 0.25 + jitter(k);
                    stuck(&mut watch, reading_c, shadow_c, &test)
                })
                .collect::<Vec<_>>()
        };
        assert!(
            verdicts(0.0, false).iter().all(|v| !v),
            "the bit test sees it"
        );
        let detached = verdicts(0.3, false);
        let first = detached.iter().position(|v| *v).expect("never stuck");
        // 1 K of physics is 40 readings; the band's share adds a little.
        assert!((40..=45).contains(&first), "stuck at reading {first}");
        assert!(detached[first..].iter().all(|v| *v));
        assert!(
            verdicts(0.3, true).iter().all(|v| !v),
            "a live sensor stuck"
        );
    }

    /// Near the ambient the slow test flags a reading stuck once the
    /// physics moved more than the threshold plus the band's share of the
    /// rise since the reading's last change, though it never moves the
    /// threshold within one window (the drive-3node trace's housing, 0.2 K
    /// a minute from 0.1 K above the ambient: 0.4 K per 120 s window).
    #[test]
    fn a_slow_move_since_the_last_change_makes_a_repeated_reading_stuck() {
        let mut watch = StuckWatch::<Const<1>>::new(Const);
        let per_reading_k = 0.2 / 120.0; // 0.2 K a minute at 2 Hz
        let allowance_k = 1.0 + 0.25 * 0.1;
        let mut first = None;
        for k in 0..2000u32 {
            let shadow = 20.1 + per_reading_k * k as f32;
            if stuck(&mut watch, 20.1, shadow, &STUCK) {
                first.get_or_insert(k);
            } else {
                assert!(first.is_none(), "verdict lapsed at reading {k}");
            }
        }
        let first = first.expect("never flagged");
        let moved_k = per_reading_k * first as f32;
        assert!(
            moved_k > allowance_k && moved_k < allowance_k + 2.0 * per_reading_k,
            "flagged at reading {first}, {moved_k} K moved"
        );
    }

    /// A live thermocouple quantised to 0.25 K following a first-order
    /// device (rise `R`, time constant `tau`) under a shadow whose rise and
    /// time constant are each 25 % off (above or below), heating from the
    /// ambient and cooling back to it: never stuck. The worst case is the
    /// shadow 25 % slower and higher: after the reading's last code it
    /// still creeps `1.25 R^0.2 q^0.8` (1.2 K at 200 K), more than the
    /// threshold, within the band's share of the rise.
    #[test]
    fn a_live_quantised_reading_under_a_shadow_25_percent_off_is_not_stuck() {
        let dt_s = 0.5f64;
        let ambient_c = 20.0f64;
        let code = |t: f64| ((t / 0.25).round() * 0.25) as f32;
        let mut worst_creep_k = 0.0f64;
        for rise_k in [2.0, 10.3, 50.1, 100.2, 199.9, 300.24] {
            for tau_s in [300.0, 1000.0, 3000.0] {
                for (gain, stretch) in [(1.25, 1.25), (0.75, 1.25), (1.25, 0.8), (0.75, 0.8)] {
                    for heating in [true, false] {
                        let mut watch = StuckWatch::<Const<1>>::new(Const);
                        let (mut last, mut at) = (f32::NAN, 0.0f64);
                        let steps = (12.0 * tau_s / dt_s) as u32;
                        for k in 0..=steps {
                            let t_s = f64::from(k) * dt_s;
                            let settle = |tau: f64| libm::exp(-t_s / tau);
                            let (truth, shadow) = if heating {
                                (
                                    ambient_c + rise_k * (1.0 - settle(tau_s)),
                                    ambient_c + gain * rise_k * (1.0 - settle(stretch * tau_s)),
                                )
                            } else {
                                (
                                    ambient_c + rise_k * settle(tau_s),
                                    ambient_c + rise_k * settle(stretch * tau_s),
                                )
                            };
                            let reading = code(truth);
                            if reading != last {
                                (last, at) = (reading, shadow);
                            }
                            worst_creep_k = worst_creep_k.max((shadow - at).abs());
                            assert!(
                                !stuck(&mut watch, reading, shadow as f32, &STUCK),
                                "rise {rise_k} K, tau {tau_s} s, gain {gain}, stretch {stretch}, \
                                 heating {heating}: stuck at {t_s} s, shadow {shadow} C, reading {reading} C"
                            );
                        }
                    }
                }
            }
        }
        // The case is real: the shadow crept beyond the threshold under an
        // unchanged live reading.
        assert!(worst_creep_k > 1.0, "{worst_creep_k}");
    }

    /// One sensor against a still shadow at 50 degC with the estimate on
    /// it (innovation variance 0.1 K^2, gate 10.83, suspect after 2, stuck
    /// test 1 K within 10 readings): whether each reading of `readings`
    /// is held, the gate refusing every reading it is offered.
    fn holds(readings: impl Iterator<Item = f32>) -> Vec<bool> {
        holds_against(readings, 50.0)
    }

    /// The stuck test (1 K within 10 readings) and the gate (NIS 10.83,
    /// recovery after 5 refusals) the drift hold's tests screen with.
    fn hold_policies() -> (StuckTest, GatePolicy<f32>) {
        let stuck = StuckTest {
            tolerance_k: 0.0,
            threshold_k: 1.0,
            window: 10,
        };
        let gate = GatePolicy {
            threshold: 10.83,
            suspect_after: 2,
            recover_after: 5,
        };
        (stuck, gate)
    }

    /// [`holds`] with the estimate at `estimate_c` \[degC\] (the shadow
    /// at 50 degC).
    fn holds_against(readings: impl Iterator<Item = f32>, estimate_c: f32) -> Vec<bool> {
        let mut hold = DriftHold::<Const<1>>::new(Const);
        let (stuck, gate) = hold_policies();
        let mut rejections = 0u16;
        readings
            .map(|t| {
                let mut samples = [Some(t)];
                let mut statuses = [SensorStatus::NoReading];
                let view = |_| GateView {
                    estimate_c,
                    innovation_var_k2: 0.1,
                };
                let held = hold.screen(
                    &mut samples,
                    &mut statuses,
                    &[50.0],
                    &[rejections],
                    &gate,
                    &stuck,
                    view,
                );
                assert_eq!(held, samples[0].is_none());
                if !held {
                    let nis = (t - estimate_c) * (t - estimate_c) / 0.1;
                    rejections = if nis > 10.83 { rejections + 1 } else { 0 };
                }
                held
            })
            .collect()
    }

    /// A reading drifting colder than the physics is held from its third
    /// refusal on, for as long as it drifts; one that comes back within
    /// the gate is the gate's again.
    #[test]
    fn a_reading_drifting_colder_than_the_physics_is_held() {
        // Fused at first (49 degC is inside the gate), refused twice, then
        // held while it drifts 0.2 K a reading.
        let drift = (0..60).map(|k| 49.0 - 0.2 * k as f32);
        let held = holds(drift);
        assert_eq!(held[..3], [false, false, false]);
        assert!(held[3..].iter().all(|h| *h), "{held:?}");
        let back = (0..20).map(|k| if k < 10 { 48.0 - 0.2 * k as f32 } else { 49.9 });
        let held = holds(back);
        assert!(held[2..10].iter().all(|h| *h), "{held:?}");
        assert!(held[10..].iter().all(|h| !*h), "{held:?}");
    }

    /// A steady offset below the physics (the model's error, not a drift)
    /// is released to the gate after the window and not held again; a
    /// reading hotter than the physics is never held.
    #[test]
    fn a_steady_offset_or_a_hot_reading_is_not_held() {
        let held = holds(core::iter::repeat_n(48.5, 40));
        assert!(held[2..11].iter().all(|h| *h), "{held:?}");
        assert!(held[11..].iter().all(|h| !*h), "{held:?}");
        assert!(holds(core::iter::repeat_n(52.0, 40)).iter().all(|h| !*h));
    }

    /// The screen reports a common-mode case only when the held reading
    /// was all there was to fuse: with another reading present it holds
    /// the cold one and leaves the other to the gate.
    #[test]
    fn a_hold_is_common_mode_only_when_nothing_else_is_left() {
        let (stuck, gate) = hold_policies();
        let view = |_| GateView {
            estimate_c: 50.0,
            innovation_var_k2: 0.1,
        };
        // Sensor 0 refused twice already, 2 K colder than the shadow and
        // the estimate (NIS 40); sensor 1 healthy.
        let screen = |other: Option<f32>| {
            let mut hold = DriftHold::<Const<2>>::new(Const);
            let mut samples = [Some(48.0), other];
            let mut statuses = [SensorStatus::NoReading; 2];
            let common = hold.screen(
                &mut samples,
                &mut statuses,
                &[50.0; 2],
                &[2, 0],
                &gate,
                &stuck,
                view,
            );
            (common, samples)
        };
        assert_eq!(screen(Some(50.0)), (false, [None, Some(50.0)]));
        assert_eq!(screen(None), (true, [None, None]));
    }

    /// A sensor released after a steady window is held again once the
    /// gate has fused one of its readings: the release lasts until then,
    /// not for ever.
    #[test]
    fn a_released_sensor_is_held_again_after_a_fused_reading() {
        let readings = core::iter::repeat_n(48.5, 40)
            .chain([50.0])
            .chain((0..20).map(|k| 48.5 - 0.2 * k as f32));
        let held = holds(readings);
        assert!(held[11..41].iter().all(|h| !*h), "{held:?}");
        assert_eq!(held[41..43], [false, false]);
        assert!(held[43..].iter().all(|h| *h), "{held:?}");
    }

    /// A reading below the shadow but above the estimate is not held,
    /// however often the gate refuses it: it is not colder than the
    /// physics, the estimate is (the gate's own business).
    #[test]
    fn a_reading_between_the_estimate_and_the_shadow_is_not_held() {
        // 3 K above the estimate: NIS 90 against the gate's 10.83.
        let held = holds_against(core::iter::repeat_n(48.0, 40), 45.0);
        assert!(held.iter().all(|h| !*h), "{held:?}");
        // The same reading against an estimate at the shadow is held.
        assert!(holds(core::iter::repeat_n(48.0, 40))[2..11]
            .iter()
            .all(|h| *h));
    }

    #[test]
    fn doubt_lasts_its_hold_then_clears() {
        let mut doubt = Suspicion::<Const<3>>::new(Const);
        assert!(!doubt.any());
        doubt.note(&[false, true, false]);
        assert!(doubt.any());
        for _ in 1..DOUBT_HOLD_CORRECTIONS {
            doubt.note(&[false; 3]);
            assert!(doubt.any());
        }
        doubt.note(&[false; 3]);
        assert!(!doubt.any());
    }

    /// The sensor checks at run-time sizes (`Dyn`: a host's model at its
    /// own size) are the const-generic ones to the bit: three sensors and
    /// two inputs through 3 000 corrections of readings that follow the
    /// physics, stick, drift colder, go missing or NaN, give the same
    /// screened samples, statuses, stuck events, holds, rewound biases,
    /// silences and doubt.
    #[cfg(feature = "alloc")]
    #[test]
    fn the_checks_at_run_time_sizes_are_the_const_generic_ones() {
        use alloc::vec::Vec;
        use nalgebra::{Dyn, SMatrix, SVector};
        let (stuck_test, gate) = hold_policies();
        let band = Band {
            offset_k: 2.0,
            fraction: 0.25,
        };
        let dyn3 = Dyn(3);
        let mut watch_c = StuckWatch::<Const<3>>::new(Const);
        let mut watch_d = StuckWatch::new(dyn3);
        let mut hold_c = DriftHold::<Const<3>>::new(Const);
        let mut hold_d = DriftHold::new(dyn3);
        let mut silence_c = SilenceWatch::<Const<3>>::new(Const);
        let mut silence_d = SilenceWatch::new(dyn3);
        let mut doubt_c = Suspicion::<Const<3>>::new(Const);
        let mut doubt_d = Suspicion::new(dyn3);
        let mut rewind_c = StuckRewind::<Const<3>, Const<2>>::new(Const, Const);
        let mut rewind_d = StuckRewind::new(dyn3, Dyn(2));
        let cov = SMatrix::<f32, 5, 5>::from_fn(|i, j| if i == j { 1.0 } else { 0.1 });
        let (mut x_c, mut x_d) = (SVector::<f32, 5>::zeros(), SVector::<f32, 5>::zeros());
        let mut seed = 7u32;
        let mut noise = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1 << 24) as f32 - 0.5
        };
        let (mut stuck_seen, mut held_seen) = (0, 0);
        for k in 0..3000u32 {
            let shadow = [
                50.0 + 0.01 * k as f32,
                45.0 + 0.02 * k as f32,
                60.0 - 0.005 * k as f32,
            ];
            let mut samples = [
                Some(shadow[0] + 0.2 * noise()),
                // Stuck from reading 500 on.
                Some(if k < 500 {
                    shadow[1] + 0.2 * noise()
                } else {
                    56.0
                }),
                // Drifting colder from 1 500 on, missing now and then.
                (k % 37 != 0).then(|| shadow[2] - (k.saturating_sub(1500)) as f32 * 0.02),
            ];
            if k % 211 == 0 {
                samples[0] = Some(f32::NAN);
            }
            let mut statuses = [SensorStatus::NoReading; 3];
            let mut samples_d: Vec<Option<f32>> = samples.to_vec();
            let mut statuses_d: Vec<SensorStatus> = statuses.to_vec();
            let (common_c, events_c) = screen_readings(
                &band,
                &stuck_test,
                &mut watch_c,
                &mut samples,
                &mut statuses,
                &shadow,
                20.0,
            );
            let (common_d, events_d) = screen_readings::<Dyn>(
                &band,
                &stuck_test,
                &mut watch_d,
                &mut samples_d,
                &mut statuses_d,
                &shadow.to_vec(),
                20.0,
            );
            assert_eq!(common_c, common_d, "{k}");
            assert_eq!(events_c.changed.to_vec(), events_d.changed, "{k}");
            assert_eq!(events_c.became_stuck.to_vec(), events_d.became_stuck, "{k}");
            stuck_seen += statuses
                .iter()
                .filter(|s| matches!(s, SensorStatus::Stuck { .. }))
                .count();
            let rejections = [0, 0, (k / 100) as u16 % 5];
            let view = |j: usize| GateView {
                estimate_c: shadow[j] - 0.5,
                innovation_var_k2: 0.1,
            };
            let held_c = hold_c.screen(
                &mut samples,
                &mut statuses,
                &shadow,
                &rejections,
                &gate,
                &stuck_test,
                view,
            );
            let held_d = hold_d.screen(
                &mut samples_d,
                &mut statuses_d,
                &shadow.to_vec(),
                &rejections.to_vec(),
                &gate,
                &stuck_test,
                view,
            );
            assert_eq!(held_c, held_d, "{k}");
            held_seen += usize::from(matches!(statuses[2], SensorStatus::Rejected { .. }));
            let heard = samples.map(|s| s.is_some());
            silence_c.watch(&heard, k * 500_000, 1_000_000, &mut statuses);
            silence_d.watch(&heard.to_vec(), k * 500_000, 1_000_000, &mut statuses_d);
            let bits =
                |v: &[Option<f32>]| v.iter().map(|s| s.map(f32::to_bits)).collect::<Vec<_>>();
            assert_eq!(bits(&samples), bits(&samples_d), "{k}");
            assert_eq!(statuses.to_vec(), statuses_d, "{k}");
            let doubt = statuses.map(|s| sensor_doubt(&s, 2).unwrap_or(false));
            doubt_c.note(&doubt);
            doubt_d.note(&doubt.to_vec());
            assert_eq!(doubt_c.any(), doubt_d.any(), "{k}");
            x_c[3] += 0.01;
            x_d[3] += 0.01;
            rewind_c.rewind(&mut x_c, &cov, 3, &events_c, &[false, false], |_, _| {});
            rewind_d.rewind(
                &mut x_d,
                &cov,
                3,
                &events_d,
                &alloc::vec![false, false],
                |_, _| {},
            );
            assert_eq!(x_c, x_d, "{k}");
        }
        assert!(
            stuck_seen > 100 && held_seen > 0,
            "{stuck_seen} {held_seen}"
        );
    }
}
