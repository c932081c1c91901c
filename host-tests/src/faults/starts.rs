//! The campaign's start classes: a reset with no snapshot at the hottest
//! point of the run after 0 s, 1 min, 10 min and 1 h off, and a restore
//! whose off time is unknown, each with the drive *obeying the limits*
//! (closed loop: every input carries the demand clamped to the
//! observer's limit of the tick before), the plant cooling with no current
//! while the device is off.
//!
//! The hottest point is the time at which the clean closed-loop run's
//! hottest alarm node is hottest. After the restart the run goes on for
//! the whole heating time again. Per case ([`StartScore`]):
//!
//! * **over limit**: the largest rise of any limited plant node above its
//!   derated alarm limit over the whole run (before and after the
//!   restart); the goal is never (`<= 0`);
//! * **under bound**: the largest amount by which the truth of a limited
//!   node no sensor reads stands above its published upper bound, from the
//!   second correction period after the restart on; goal at most
//!   [`UNDER_BOUND_GOAL_K`];
//! * **refused**: healthy readings after the restart that were not fused;
//!   goal none;
//! * the first limit after the restart, as a share of the demand (how
//!   much the start holds back), and when the limit first came back to
//!   the clean run's (`recovered_s`).

use serde::Serialize;

use super::{
    CaseReport, FaultClass, Harness, Injected, RunResult, RunScore, SnapshotOutcome, Subject,
    TickInputs, TickView,
};
use coil_thermal::observer::TimedReading;
use coil_thermal::{Reading, SensorFault};

/// Goal: the upper bound of a limited node no sensor reads is at most this
/// far below the truth from the second correction period after a restart
/// \[K\] (issue 35).
pub const UNDER_BOUND_GOAL_K: f64 = 1.0;

/// A start case's scores (see the module docs).
#[derive(Debug, Clone, Default, Serialize)]
pub struct StartScore {
    /// The device's off time before the restart \[s\].
    pub off_s: f64,
    /// The restart's time in the run, the hottest point \[s\].
    pub restart_s: f64,
    /// Largest truth above its derated alarm limit, any limited node, the
    /// whole run \[K\] (`<= 0`: never above).
    pub over_limit_k: f64,
    /// Largest truth above the upper bound of a limited node no sensor
    /// reads, from the second correction period after the restart \[K\]
    /// (negative: the bound covered the truth by that much at the
    /// tightest; `None`: every limited node is read).
    pub under_bound_k: Option<f64>,
    /// Healthy readings after the restart that were not fused.
    pub refused: u32,
    /// The tightest input limit at the first tick after the restart, as a
    /// share of the demand.
    pub first_limit_share: f64,
}

/// One restart of a closed-loop run.
#[derive(Debug, Clone, Copy)]
struct Restart {
    class: FaultClass,
    at_s: f64,
    off_s: f64,
}

impl FaultClass {
    /// A start class's off time \[s\] (`restore-unknown-off`: the
    /// campaign's power-off time).
    fn start_off_s(self, power_off_s: f64) -> f64 {
        match self {
            Self::Reset1Min => 60.0,
            Self::Reset10Min => 600.0,
            Self::Reset1H => 3600.0,
            Self::RestoreUnknownOff => power_off_s,
            _ => 0.0,
        }
    }
}

impl<S: Subject> Harness<'_, S> {
    /// Every start class of `classes`: the clean closed-loop run, then one
    /// case per class restarted at its hottest point.
    pub(super) fn run_starts(&self, classes: &[FaultClass]) -> Vec<CaseReport> {
        let starts: Vec<FaultClass> = classes.iter().copied().filter(|c| c.is_start()).collect();
        if starts.is_empty() {
            return Vec::new();
        }
        let (clean, _, hottest_s) = self.closed_loop(None);
        starts
            .into_iter()
            .map(|class| {
                let restart = Restart {
                    class,
                    at_s: hottest_s,
                    off_s: class.start_off_s(self.cfg.off_s),
                };
                let (score, snapshot, _) = self.closed_loop(Some(restart));
                let fault = Injected {
                    class,
                    sensor: None,
                    onset_s: hottest_s,
                };
                let run = RunResult {
                    score: score.run.clone(),
                    flag_s: None,
                    detectable_s: None,
                    snapshot,
                };
                let mut case = super::case_report(fault, run, clean.run.shutdown_s);
                // A restarted run is another trajectory than the clean
                // one: whether it latches at the clean run's moment says
                // nothing. It is judged by the start goals (the plant
                // under its limit, the bound, the readings), and a
                // shutdown the clean run did not have stays a false trip.
                case.lost_shutdown = false;
                case.late_shutdown = false;
                case.start = Some(score.start);
                case
            })
            .collect()
    }

    /// One closed-loop run, restarted by `restart` if given: its scores,
    /// the snapshot's fate, and the time of the hottest alarm node's peak
    /// \[s\].
    fn closed_loop(&self, restart: Option<Restart>) -> (Scores, Option<SnapshotOutcome>, f64) {
        let cfg = self.cfg;
        let subject = &self.subject;
        let amb = cfg.ambient_c;
        let amb32 = amb as f32;
        let mut plant = subject.plant();
        plant.reset(&vec![amb; plant.info().nodes.len()]);
        let boundary_c = vec![amb; plant.info().boundaries.len()];
        let sensor_nodes = subject.sensor_nodes().to_vec();
        let limits_c = subject.alarm_limits_c(amb32);
        let unread_limited: Vec<usize> = (0..limits_c.len())
            .filter(|n| limits_c[*n].is_some() && !sensor_nodes.contains(n))
            .collect();
        let mut state = subject.state(amb32);
        let mut view = subject.view(&state);
        let dt = self.dt_s;
        let every = u64::from(cfg.reading_every.max(1));
        let period_s = dt * every as f64;
        let (off_from, off_to) = restart.map_or((f64::INFINITY, f64::INFINITY), |r| {
            (r.at_s, r.at_s + r.off_s)
        });
        let total_s = match restart {
            Some(r) => r.at_s + r.off_s + cfg.duration_s,
            None => cfg.duration_s,
        };
        let ticks = (total_s / dt).round() as u64;
        let half = 0.5 * dt;
        let model = &cfg.sensor_model;
        let mut scores = Scores::new(restart.map_or(0.0, |r| r.off_s), off_from);
        let mut saved: Option<(Vec<u8>, u32)> = None;
        let mut snapshot = None;
        let mut restarted = restart.is_none();
        let mut hottest = (f64::NEG_INFINITY, 0.0);
        let mut now_us = 0u32;
        let zero = vec![0.0; subject.inputs()];
        for k in 0..ticks {
            let t_s = (k + 1) as f64 * dt;
            now_us = now_us.wrapping_add(cfg.step_us);
            let off = t_s > off_from + half && t_s <= off_to + half;
            // The demand: the trace's time runs only while the device is on.
            let run_s = if t_s > off_to + half {
                t_s - (off_to - off_from)
            } else {
                t_s
            };
            let demand: &[f64] = match &cfg.trace {
                Some(trace) => trace.at(run_s),
                None => &cfg.currents_a,
            };
            let applied: Vec<f64> = if off {
                zero.clone()
            } else {
                demand
                    .iter()
                    .zip(&view.limits_a)
                    .map(|(d, l)| d.clamp(-f64::from(*l), f64::from(*l)))
                    .collect()
            };
            plant.step(dt, &applied, &boundary_c, &[]);
            if off {
                continue;
            }
            let plant_c = plant.temps_c().to_vec();
            let truth: Vec<f32> = sensor_nodes.iter().map(|n| plant_c[*n] as f32).collect();
            let reading_no = k / every;
            if !restarted && t_s > off_to - half {
                // The restart: what the sensors read now, then the start.
                let read_now: Vec<Option<f32>> = truth
                    .iter()
                    .zip(&cfg.sensors)
                    .enumerate()
                    .map(|(j, (t, used))| {
                        used.then(|| super::read_sensor(subject, model, *t, j, reading_no))
                    })
                    .collect();
                let class = restart.map(|r| r.class);
                state = match (class, &saved) {
                    (Some(FaultClass::RestoreUnknownOff), Some((bytes, at_s))) => {
                        let now_s = *at_s + (off_to - off_from).round() as u32;
                        let max_age_s = cfg.max_snapshot_age_s;
                        match subject
                            .restore_with_readings(bytes, now_s, max_age_s, amb32, &read_now)
                        {
                            Ok(s) => {
                                snapshot = Some(outcome(subject, &s, None));
                                s
                            }
                            Err(e) => {
                                let s = subject.start(&read_now, amb32);
                                snapshot = Some(outcome(subject, &s, Some(e)));
                                s
                            }
                        }
                    }
                    _ => subject.start(&read_now, amb32),
                };
                view = subject.view(&state);
                scores.first_limit(demand, &view.limits_a);
                restarted = true;
            }
            let due = k % every == 0;
            let readings: Vec<Option<TimedReading>> = (0..sensor_nodes.len())
                .map(|j| {
                    (due && cfg.sensors[j]).then(|| TimedReading {
                        result: Ok::<_, SensorFault>(Reading::new(super::read_sensor(
                            subject, model, truth[j], j, reading_no,
                        ))),
                        sampled_at_us: now_us,
                    })
                })
                .collect();
            let applied32: Vec<f32> = applied.iter().map(|a| *a as f32).collect();
            let inputs = TickInputs {
                currents_a: &applied32,
                ambient_c: amb32,
                readings: &readings,
                now_us,
                elapsed_us: cfg.step_us,
            };
            view = subject.tick(&mut state, &inputs);
            if restart.is_some() && saved.is_none() && t_s + half >= off_from {
                // The last snapshot before the power cut.
                let now_s = t_s.round() as u32;
                saved = subject.save(&state, now_s).map(|b| (b, now_s));
            }
            for n in subject.alarm_nodes() {
                if plant_c[*n] > hottest.0 {
                    hottest = (plant_c[*n], t_s);
                }
            }
            scores.tick(&ScoredTick {
                t_s,
                plant_c: &plant_c,
                view: &view,
                limits_c: &limits_c,
                unread_limited: &unread_limited,
                sensor_nodes: &sensor_nodes,
                alarm_nodes: subject.alarm_nodes(),
                read: &readings,
                restarted_s: off_to,
                bound_from_s: off_to + 2.0 * period_s,
            });
            if view.shutdown {
                scores.run.shutdown_s = Some(t_s);
                break;
            }
        }
        (scores, snapshot, hottest.1)
    }
}

/// What happened to a restore.
fn outcome<S: Subject>(subject: &S, state: &S::State, error: Option<String>) -> SnapshotOutcome {
    SnapshotOutcome {
        refused: error.is_some(),
        error,
        starts_latched: subject.latched(state),
    }
}

/// One tick of a closed-loop run, as scored.
struct ScoredTick<'a> {
    t_s: f64,
    plant_c: &'a [f64],
    view: &'a TickView,
    limits_c: &'a [Option<f32>],
    unread_limited: &'a [usize],
    sensor_nodes: &'a [usize],
    alarm_nodes: &'a [usize],
    read: &'a [Option<TimedReading>],
    /// The restart \[s\]: readings and errors are scored after it.
    restarted_s: f64,
    /// Scoring of the bound from here \[s\].
    bound_from_s: f64,
}

/// A closed-loop run's scores as they accumulate.
struct Scores {
    run: RunScore,
    start: StartScore,
}

impl Scores {
    fn new(off_s: f64, restart_s: f64) -> Self {
        Self {
            run: RunScore::default(),
            start: StartScore {
                off_s,
                restart_s: if restart_s.is_finite() {
                    restart_s
                } else {
                    0.0
                },
                over_limit_k: f64::NEG_INFINITY,
                under_bound_k: None,
                refused: 0,
                first_limit_share: 1.0,
            },
        }
    }

    fn first_limit(&mut self, demand_a: &[f64], limits_a: &[f32]) {
        self.start.first_limit_share = demand_a
            .iter()
            .zip(limits_a)
            .filter(|(d, _)| d.abs() > 0.0)
            .map(|(d, l)| (f64::from(*l) / d.abs()).min(1.0))
            .fold(1.0, f64::min);
    }

    fn tick(&mut self, t: &ScoredTick<'_>) {
        for (node, limit) in t.limits_c.iter().enumerate() {
            if let (Some(limit), Some(truth)) = (limit, t.plant_c.get(node)) {
                self.start.over_limit_k = self.start.over_limit_k.max(truth - f64::from(*limit));
            }
        }
        if t.t_s <= t.restarted_s {
            return;
        }
        if t.t_s >= t.bound_from_s {
            for node in t.unread_limited {
                let under = t.plant_c[*node] - f64::from(t.view.upper_c[*node]);
                let worst = self.start.under_bound_k.map_or(under, |w| w.max(under));
                self.start.under_bound_k = Some(worst);
            }
        }
        for (j, reading) in t.read.iter().enumerate() {
            let refused = t.view.sensors.get(j).is_some_and(super::refused);
            if reading.is_some() && refused {
                self.start.refused += 1;
                self.run.healthy_flagged += 1;
            }
        }
        for node in t.sensor_nodes {
            let e = (f64::from(t.view.temps_c[*node]) - t.plant_c[*node]).abs();
            self.run.max_error_tc_k = self.run.max_error_tc_k.max(e);
        }
        if let Some(hot) = t
            .alarm_nodes
            .iter()
            .copied()
            .max_by(|a, b| t.plant_c[*a].total_cmp(&t.plant_c[*b]))
        {
            let e = (f64::from(t.view.temps_c[hot]) - t.plant_c[hot]).abs();
            self.run.max_error_hot_spot_k = self.run.max_error_hot_spot_k.max(e);
        }
    }
}
