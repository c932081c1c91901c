//! The machinery the Omnimagnet and the network observer share around
//! their models: the protection cycle (one stage per tick), the sorting of
//! fresh readings, the filter's verdicts as sensor statuses, and the latch
//! made visible ([`Latch`], the grid's too).
//!
//! # The protection cycle
//!
//! Every `protect_period_us` of simulated time the protection runs three
//! stages, one per tick, so that no tick carries more than one expensive
//! piece: a slice of the time-to-limit predictor (on the largest current
//! held since the previous slice, so a short pulse between two slices is
//! not missed), the derated alarm on the upper bounds, then the limiter.
//! A tick that already ran a correction or a catch-up of several model
//! steps puts the predictor slice off to the next tick, once. The limits
//! therefore lag the model by at most a cycle and three ticks, and the
//! predictor's answers are aged by the time it lags (`lag_s`). With
//! `with_busy_waits(n)` every stage may wait out `n` busy ticks: at most a
//! cycle and `3 (n + 1)` ticks (12 ms for the network observer's 3 at a
//! 1 ms loop). Which stage a tick runs, the bookkeeping after it and the
//! ageing are [`ProtectionStages::run_due`], every filtered observer's. A phase
//! (`with_phase`) makes every slice after the first due that much after
//! its period's boundary; the lag stays the real one.

use super::clock::TickSteps;
use super::snapshot::SnapshotMeta;
use super::vocabulary::{SensorStatus, TimedReading};
use crate::filter::SensorVerdict;
use crate::protect::alarm::{AlarmConfig, AlarmState, AlarmStatus, ResetError};
use crate::protect::events::{EventKind, EventQueue};
use crate::protect::limiter::{hold_shutdown, CoilLimit};
use crate::scalar::Scalar;
use crate::sizes::Length;

/// A protection stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Stage {
    /// Waiting for the next period.
    Idle,
    /// A time-to-limit predictor slice.
    Predict,
    /// The derated alarm.
    Alarm,
    /// The current limiter.
    Limit,
}

/// Where a state is in its protection cycle, with `M` currents.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ProtectionCycle<M: Length> {
    /// Largest held current magnitude since the last predictor slice \[A\].
    peak_currents_a: M::Array<f32>,
    /// Simulated time minus the predictor's own ageing \[us\].
    lag_us: u32,
    stage: Stage,
    /// Busy ticks the due stage has waited.
    put_off: u8,
    /// Busy ticks every stage may wait (see [`Self::with_busy_waits`]; 0:
    /// a predictor slice waits one, the alarm and the limiter none).
    busy_waits: u8,
    /// How much later than a whole period each slice after the first is
    /// due \[us\] (see [`Self::with_phase`]).
    phase_us: u32,
    /// Predictor slices per cycle (see [`Self::with_slices`]).
    slices: u32,
    /// Slices of this cycle still to run.
    slices_left: u32,
}

impl<M: Length> ProtectionCycle<M> {
    /// A cycle of `currents` whose first stage, the predictor slice, is
    /// due at once (a new state's limits are valid from its first ticks).
    pub(crate) fn new(currents: M) -> Self {
        Self {
            peak_currents_a: currents.filled(0.0),
            lag_us: 0,
            stage: Stage::Predict,
            put_off: 0,
            busy_waits: 0,
            phase_us: 0,
            slices: 1,
            slices_left: 1,
        }
    }

    /// The same cycle with `slices` (at least 1) predictor slices on
    /// consecutive ticks before the alarm, each due as the first is (put
    /// off once by a busy tick), each caught up by its share of the period
    /// ([`Self::predicted`]): for a predictor whose slice budget is below
    /// one horizon.
    pub(crate) fn with_slices(mut self, slices: u32) -> Self {
        self.slices = slices.max(1);
        self.slices_left = self.slices;
        self
    }

    /// The same cycle with every stage (the predictor's slices, the alarm,
    /// the limiter) waiting up to `waits` busy ticks in a row before it
    /// runs all the same: for a model step several ticks long, whose step
    /// ticks are busy and may come next to a reading's, so that a stage
    /// lands on a light tick (at most `waits` ticks later).
    pub(crate) fn with_busy_waits(mut self, waits: u8) -> Self {
        self.busy_waits = waits;
        self
    }

    /// The same cycle with every slice after the first due `phase_us`
    /// \[us\] later: the slices land `phase_us` after the period's
    /// boundaries, for example on the ticks another observer sharing the
    /// loop leaves light. The lag the answers are aged by stays the real
    /// one (at most a period and `phase_us` plus three ticks).
    pub(crate) fn with_phase(mut self, phase_us: u32) -> Self {
        self.phase_us = phase_us;
        self
    }

    /// Accounts for a tick of `elapsed_us` \[us\] and its model steps
    /// (`steps` of `step_us`, with the time the clock could not simulate)
    /// at the held currents \[A\]: the peaks take them when the tick took a
    /// step or lasted some time (a tick between the steps of a model step
    /// several ticks long heats all the same).
    pub(crate) fn stepped(
        &mut self,
        steps: &TickSteps,
        step_us: u32,
        elapsed_us: u32,
        held_currents_a: &M::Array<f32>,
    ) {
        if steps.steps > 0 || elapsed_us > 0 {
            self.held(held_currents_a);
        }
        self.lag_us = self
            .lag_us
            .saturating_add(steps.steps.saturating_mul(step_us))
            .saturating_add(steps.dropped_us);
    }

    /// The peaks take `currents_a` \[A\].
    fn held(&mut self, currents_a: &M::Array<f32>) {
        let peaks = self.peak_currents_a.as_mut().iter_mut();
        for (peak, i) in peaks.zip(currents_a.as_ref()) {
            // As `max` (a NaN current leaves the peak), without its call.
            if i.abs() > *peak {
                *peak = i.abs();
            }
        }
    }

    /// The stage this tick runs, if any (`busy`: a correction or a
    /// catch-up already ran this tick).
    pub(crate) fn due(&mut self, busy: bool, period_us: u32) -> Stage {
        if self.stage == Stage::Idle && self.lag_us >= period_us.saturating_add(self.phase_us) {
            self.stage = Stage::Predict;
        }
        let waits = match (self.busy_waits, self.stage) {
            (0, Stage::Predict) => 1,
            (waits, _) => waits,
        };
        match self.stage {
            Stage::Idle => Stage::Idle,
            _ if busy && self.put_off < waits => {
                self.put_off += 1;
                Stage::Idle
            }
            stage => {
                self.put_off = 0;
                stage
            }
        }
    }

    /// The currents the predictor slice takes: the largest held since the
    /// previous slice \[A\].
    pub(crate) fn peak_currents_a(&self) -> &M::Array<f32> {
        &self.peak_currents_a
    }

    /// A predictor slice ran: its time is caught up by `slice_us` (the
    /// period over the slices per cycle), the peaks restart from the held
    /// currents, and after the cycle's last slice the alarm is next.
    pub(crate) fn predicted(&mut self, slice_us: u32, held_currents_a: &M::Array<f32>) {
        self.lag_us = self.lag_us.saturating_sub(slice_us);
        self.peak_currents_a = M::mapped(held_currents_a, |i| i.abs());
        self.slices_left = self.slices_left.saturating_sub(1);
        if self.slices_left == 0 {
            self.slices_left = self.slices;
            self.stage = Stage::Alarm;
        }
    }

    /// The alarm ran: the limiter is next.
    pub(crate) fn alarmed(&mut self) {
        self.stage = Stage::Limit;
    }

    /// The limiter ran: the cycle waits for the next period.
    pub(crate) fn limited(&mut self) {
        self.stage = Stage::Idle;
    }

    /// How far the predictor lags the model \[s\].
    pub(crate) fn lag_s(&self) -> f32 {
        self.lag_us as f32 * 1e-6
    }
}

/// A filtered observer with its state, borrowed for one tick's protection
/// stage: the receiver of [`ProtectionStages`].
pub(crate) struct Protecting<'a, O, S> {
    /// The observer's configuration.
    pub observer: &'a O,
    /// Its per-device state.
    pub state: &'a mut S,
}

/// What a filtered observer (the network, the Omnimagnet) does in each
/// stage of its protection cycle. The cycle's rules, which stage a tick
/// runs, the bookkeeping after it and the ageing of the answers, are the
/// provided [`Self::run_due`], the same for every observer.
pub(crate) trait ProtectionStages<M: Length> {
    /// The state's cycle and the currents it holds now \[A\].
    fn cycle_and_held(&mut self) -> (&mut ProtectionCycle<M>, &M::Array<f32>);
    /// Model time one predictor stage catches up \[us\] (the period over
    /// the slices per cycle).
    fn predictor_slice_us(&self) -> u32;
    /// A time-to-limit predictor slice on the cycle's peak currents.
    fn predict(&mut self);
    /// The derated alarm on the published upper bounds (the answers are
    /// aged just before).
    fn alarm(&mut self);
    /// The current limiter on the published upper bounds.
    fn limit(&mut self);
    /// Publishes the predictor's answers made older by the cycle's lag.
    fn age_time_to_limit(&mut self);

    /// Runs the stage due this tick, if any (`busy`: a correction or a
    /// step longer than the loop's tick already ran; `held`: no stage may
    /// run this tick, whatever its waits, and the tick is not one of them
    /// (a correction waiting for its second tick); `period_us`: the
    /// protection period \[us\]), and ages the published times to limit
    /// when the model's time (`model_moved`: steps taken or time dropped)
    /// or the predictor moved. Returns the stage run.
    #[inline(always)]
    fn run_due(&mut self, busy: bool, held: bool, period_us: u32, model_moved: bool) -> Stage {
        let stage = if held {
            Stage::Idle
        } else {
            self.cycle_and_held().0.due(busy, period_us)
        };
        match stage {
            Stage::Idle => {}
            Stage::Predict => {
                self.predict();
                let slice_us = self.predictor_slice_us();
                let (cycle, held_a) = self.cycle_and_held();
                cycle.predicted(slice_us, held_a);
            }
            Stage::Alarm => {
                self.age_time_to_limit();
                self.alarm();
                self.cycle_and_held().0.alarmed();
            }
            Stage::Limit => {
                self.limit();
                self.cycle_and_held().0.limited();
            }
        }
        // The lag moves with the model's time and the predictor's stages;
        // the alarm's stage aged the answers just before it, and nothing
        // has moved them since.
        if stage != Stage::Alarm && (model_moved || stage != Stage::Idle) {
            self.age_time_to_limit();
        }
        stage
    }
}

/// Sorts the fresh readings: each usable one's temperature \[degC\], and
/// the status of each that is not (too old, from the future, a sensor
/// fault); sensors without a reading get `NoReading`.
pub(crate) fn sample_readings<P: Length>(
    readings: &P::Array<Option<TimedReading>>,
    now_us: u32,
    max_age_us: u32,
    statuses: &mut P::Array<SensorStatus>,
) -> P::Array<Option<f32>> {
    let mut samples = P::filled_like(readings, None);
    let sampled = samples
        .as_mut()
        .iter_mut()
        .zip(statuses.as_mut().iter_mut());
    for ((sample, status), reading) in sampled.zip(readings.as_ref()) {
        *status = match reading.map(|r| r.sample_c(now_us, max_age_us)) {
            None => SensorStatus::NoReading,
            Some(Ok(temp_c)) => {
                *sample = Some(temp_c);
                SensorStatus::NoReading
            }
            Some(Err(status)) => status,
        };
    }
    samples
}

/// The filter's verdict on each reading it was given (`given[j]`) as the
/// sensor's status.
pub(crate) fn record_verdicts<P: Length>(
    statuses: &mut P::Array<SensorStatus>,
    verdicts: &P::Array<SensorVerdict>,
    given: &P::Array<bool>,
) {
    let recorded = statuses.as_mut().iter_mut().zip(verdicts.as_ref());
    for ((status, verdict), given) in recorded.zip(given.as_ref()) {
        if *given {
            *status = match *verdict {
                SensorVerdict::Fused { nis } => SensorStatus::Fused { nis },
                SensorVerdict::Rejected { nis } => SensorStatus::Rejected { nis },
                SensorVerdict::Missing => SensorStatus::NoReading,
            };
        }
    }
}

/// Latches the shutdown and shows it at once: the published alarm says
/// so and every current limit is zero (until the deliberate clear).
pub(crate) fn latch_and_publish<S: Scalar, N: Length>(
    alarm: &mut AlarmState<S, N>,
    published: &mut AlarmStatus,
    limits: &mut [CoilLimit<S>],
) {
    alarm.latch_shutdown();
    published.shutdown = true;
    hold_shutdown(limits);
}

/// What the shutdown latch touches in an observer's state, borrowed for
/// one rule: its alarm's state and event queue, and the published alarm
/// and current limits. The rules of the latch are the same for every
/// observer (the grid, the Omnimagnet, the network): latched, the
/// published alarm says so at once and every current limit is zero until
/// the deliberate clear.
pub(crate) struct Latch<'a, S: Scalar, E: Length, const CAP: usize> {
    /// The alarm's state (`E` elements).
    pub alarm: &'a mut AlarmState<S, E>,
    /// The state's event queue.
    pub events: &'a mut EventQueue<CAP>,
    /// The published alarm summary.
    pub published: &'a mut AlarmStatus,
    /// The published current limits.
    pub limits: &'a mut [CoilLimit<S>],
}

impl<S: Scalar, E: Length, const CAP: usize> Latch<'_, S, E, CAP> {
    /// Latches the shutdown and shows it ([`latch_and_publish`]): a
    /// conservative start, a snapshot that held a latch.
    pub(crate) fn latch(self) {
        latch_and_publish(self.alarm, self.published, self.limits);
    }

    /// Latches the shutdown if the snapshot `meta` recorded one.
    pub(crate) fn restore(self, meta: &SnapshotMeta) {
        if meta.shutdown_latched {
            self.latch();
        }
    }

    /// The model is lost (a clock frozen for `frozen_loss_ticks`): latched
    /// with a [`EventKind::ClockFrozen`] event, shown at once.
    pub(crate) fn clock_lost(self) {
        self.alarm
            .latch_shutdown_for(EventKind::ClockFrozen, self.events);
        self.published.shutdown = true;
        hold_shutdown(self.limits);
    }

    /// The deliberate clear ([`AlarmState::reset`] under its conditions,
    /// judged by `config`): on success a `Reset` event is queued and the
    /// published alarm is clear at once; the limits come back with the
    /// next limiter stage.
    ///
    /// # Errors
    /// Why not, naming the first element that blocks it; nothing changes
    /// then.
    pub(crate) fn clear(self, config: &AlarmConfig<S, E>) -> Result<(), ResetError> {
        self.alarm.reset(config, self.events)?;
        self.published.shutdown = self.alarm.shutdown_latched();
        Ok(())
    }
}

/// Limits \[degC\] of `N` elements that depend on the ambient alone (the
/// derated alarm limits, the predictor's mean limits), kept with the
/// ambient \[degC\] they were formed at: the ambient moves far less often
/// than a protection stage runs, and each formed limit is a derating (and
/// for the predictor a bound's shift), soft-float routines an element on a
/// core without an FPU.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct AmbientLimits<N: Length> {
    /// The bits of the ambient the limits were formed at; `None` before
    /// the first.
    ambient_bits: Option<u32>,
    limits_c: N::Array<f32>,
}

impl<N: Length> AmbientLimits<N> {
    /// No limits of `elements` formed yet.
    pub(crate) fn new(elements: N) -> Self {
        Self {
            ambient_bits: None,
            limits_c: elements.filled(0.0),
        }
    }

    /// The limits at `ambient_c` \[degC\]: the kept ones when it has the
    /// same bits, else `form(ambient_c)`, kept. The same bits as forming
    /// them every time (`form` is a function of the ambient alone).
    pub(crate) fn at(
        &mut self,
        ambient_c: f32,
        form: impl FnOnce(f32) -> N::Array<f32>,
    ) -> &N::Array<f32> {
        let bits = ambient_c.to_bits();
        if self.ambient_bits != Some(bits) {
            self.limits_c = form(ambient_c);
            self.ambient_bits = Some(bits);
        }
        &self.limits_c
    }
}

/// A predictor's answer `time_s` \[s\] made older by `lag_s` \[s\] (the
/// real time it lags behind), never below zero; NaN ("unknown") and `None`
/// ("never") pass through. Shared by the observers.
pub(crate) fn aged_time_to_limit(time_s: Option<f32>, lag_s: f32) -> Option<f32> {
    time_s.map(|t| {
        let left = t - lag_s;
        if left < 0.0 {
            0.0
        } else {
            left
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Const;

    /// The ticks (1 ms steps, never busy) on which each stage runs over
    /// `ticks`, for a cycle of `period_us` with `phase_us`, and the largest
    /// lag seen just before a slice \[us\].
    fn stages(period_us: u32, phase_us: u32, ticks: u32) -> ([u32; 8], u32) {
        stages_sliced(period_us, phase_us, 1, ticks)
    }

    /// [`stages`] with `slices` predictor slices per cycle.
    fn stages_sliced(period_us: u32, phase_us: u32, per_cycle: u32, ticks: u32) -> ([u32; 8], u32) {
        let mut cycle = ProtectionCycle::new(Const::<1>)
            .with_phase(phase_us)
            .with_slices(per_cycle);
        let (mut slices, mut n, mut worst_lag) = ([0; 8], 0, 0);
        for tick in 0..ticks {
            let one = TickSteps {
                steps: 1,
                dropped_us: 0,
                flags: crate::input::InputFlags::NONE,
                clock_lost: false,
            };
            cycle.stepped(&one, 1000, 1000, &[1.0]);
            match cycle.due(false, period_us) {
                Stage::Predict => {
                    worst_lag = worst_lag.max(cycle.lag_us);
                    if let Some(s) = slices.get_mut(n) {
                        *s = tick;
                    }
                    n += 1;
                    cycle.predicted(period_us / per_cycle, &[1.0]);
                }
                Stage::Alarm => cycle.alarmed(),
                Stage::Limit => cycle.limited(),
                Stage::Idle => {}
            }
        }
        (slices, worst_lag)
    }

    #[test]
    fn a_phase_moves_every_slice_after_the_first_and_the_lag_stays_real() {
        // Period 40 ms: slices at ticks 0, 40, 80, ... without a phase, at
        // 0, 49, 89, 129, ... with 9 ms; the lag the answers are aged by is
        // the simulated time since the last slice's period, so it grows by
        // the phase (never smaller than the real lag: erring early).
        let (plain, plain_lag) = stages(40_000, 0, 330);
        assert_eq!(plain, [0, 40, 80, 120, 160, 200, 240, 280]);
        assert_eq!(plain_lag, 40_000);
        let (phased, phased_lag) = stages(40_000, 9_000, 330);
        assert_eq!(phased, [0, 49, 89, 129, 169, 209, 249, 289]);
        assert_eq!(phased_lag, 49_000);
    }

    #[test]
    fn two_slices_run_on_consecutive_ticks_and_catch_up_one_period() {
        // Slices at 0, 1, then 50, 51, 90, 91, ... (the first cycle's
        // second slice, like its first, catches up more than the time
        // there was): each catches up half a period, so the lag before a
        // cycle's first slice is the same as with one slice.
        let (sliced, lag) = stages_sliced(40_000, 9_000, 2, 140);
        assert_eq!(sliced, [0, 1, 50, 51, 90, 91, 130, 131]);
        assert_eq!(lag, 49_000);
    }

    /// The kept limits are formed again exactly when the ambient's bits
    /// move (`-0` after `+0` too, whose limits can differ in sign).
    /// The stages the cycle runs on ticks `0..ticks`, with every tick in
    /// `busy` busy.
    fn run(mut cycle: ProtectionCycle<Const<1>>, busy: &[u32], ticks: u32) -> [(u32, Stage); 6] {
        let one = TickSteps {
            steps: 1,
            dropped_us: 0,
            flags: crate::input::InputFlags::NONE,
            clock_lost: false,
        };
        let (mut ran, mut n) = ([(0, Stage::Idle); 6], 0);
        for tick in 0..ticks {
            cycle.stepped(&one, 1000, 1000, &[1.0]);
            let stage = cycle.due(busy.contains(&tick), 10_000);
            match stage {
                Stage::Idle => continue,
                Stage::Predict => cycle.predicted(10_000, &[1.0]),
                Stage::Alarm => cycle.alarmed(),
                Stage::Limit => cycle.limited(),
            }
            if let Some(r) = ran.get_mut(n) {
                *r = (tick, stage);
            }
            n += 1;
        }
        ran
    }

    /// An observer that logs what `run_due` asks of it.
    struct Logged {
        cycle: ProtectionCycle<Const<1>>,
        held_a: [f32; 1],
        log: Vec<&'static str>,
    }

    impl ProtectionStages<Const<1>> for Logged {
        fn cycle_and_held(&mut self) -> (&mut ProtectionCycle<Const<1>>, &[f32; 1]) {
            (&mut self.cycle, &self.held_a)
        }
        fn predictor_slice_us(&self) -> u32 {
            1000
        }
        fn predict(&mut self) {
            self.log.push("predict");
        }
        fn alarm(&mut self) {
            self.log.push("alarm");
        }
        fn limit(&mut self) {
            self.log.push("limit");
        }
        fn age_time_to_limit(&mut self) {
            self.log.push("age");
        }
    }

    /// The answers are aged after a stage that moved them (the
    /// predictor's), before the alarm judges them (once: nothing moves
    /// them in between), and whenever the model's time moved; a tick
    /// without either ages nothing.
    #[test]
    fn run_due_ages_the_answers_where_they_moved_and_before_the_alarm() {
        let mut o = Logged {
            cycle: ProtectionCycle::new(Const::<1>),
            held_a: [2.0],
            log: Vec::new(),
        };
        let tick = |o: &mut Logged, model_moved: bool| {
            o.log.clear();
            let stage = o.run_due(false, false, 1000, model_moved);
            (stage, o.log.clone())
        };
        assert_eq!(
            tick(&mut o, false),
            (Stage::Predict, vec!["predict", "age"])
        );
        assert_eq!(o.cycle.peak_currents_a(), &[2.0]);
        assert_eq!(tick(&mut o, false), (Stage::Alarm, vec!["age", "alarm"]));
        assert_eq!(tick(&mut o, true), (Stage::Limit, vec!["limit", "age"]));
        assert_eq!(tick(&mut o, true), (Stage::Idle, vec!["age"]));
        assert_eq!(tick(&mut o, false), (Stage::Idle, vec![]));
    }

    #[test]
    fn with_busy_waits_every_stage_waits_out_busy_ticks_a_bounded_number_of_times() {
        use Stage::*;
        // A period of 10 ticks (a slice is due at 0, then 10 ticks after
        // the one before); ticks 0-3 and 11-14 busy.
        let busy = [0, 1, 2, 3, 11, 12, 13, 14];
        // Without: only the slice waits, once; the alarm and the limiter
        // run on busy ticks (2 and 3, 13 and 14).
        assert_eq!(
            run(ProtectionCycle::new(Const::<1>), &busy, 16),
            [
                (1, Predict),
                (2, Alarm),
                (3, Limit),
                (12, Predict),
                (13, Alarm),
                (14, Limit)
            ]
        );
        // With two waits: the slice due at 0 waits 0 and 1 and runs on 2
        // all the same (busy); the alarm waits 3 and runs on 4, the
        // limiter on 5; the slice due at 12 waits 12 and 13 and runs on 14.
        assert_eq!(
            run(
                ProtectionCycle::new(Const::<1>).with_busy_waits(2),
                &busy,
                20
            ),
            [
                (2, Predict),
                (4, Alarm),
                (5, Limit),
                (14, Predict),
                (15, Alarm),
                (16, Limit)
            ]
        );
        // Lone busy ticks: each stage on the light tick after one.
        assert_eq!(
            run(
                ProtectionCycle::new(Const::<1>).with_busy_waits(2),
                &[0, 11, 13],
                18
            ),
            [
                (1, Predict),
                (2, Alarm),
                (3, Limit),
                (12, Predict),
                (14, Alarm),
                (15, Limit)
            ]
        );
    }

    #[test]
    fn ambient_limits_are_formed_again_when_the_ambient_moves() {
        let mut formed = 0;
        let mut limits = AmbientLimits::new(Const::<2>);
        let mut at = |limits: &mut AmbientLimits<Const<2>>, ambient_c: f32| {
            *limits.at(ambient_c, |a| {
                formed += 1;
                [a + 100.0, a + 50.0]
            })
        };
        assert_eq!(at(&mut limits, 20.0), [120.0, 70.0]);
        assert_eq!(at(&mut limits, 20.0), [120.0, 70.0]);
        assert_eq!(at(&mut limits, 25.0), [125.0, 75.0]);
        assert_eq!(at(&mut limits, 20.0), [120.0, 70.0]);
        at(&mut limits, 0.0);
        at(&mut limits, -0.0);
        assert!(at(&mut limits, f32::NAN)[0].is_nan());
        assert_eq!(at(&mut limits, 30.0), [130.0, 80.0]);
        assert_eq!(formed, 7);
    }
}
