//! One observer per Omnimagnet behind the same tick API as [`super::grid`]:
//! the Kalman observer of [`crate::omnimagnet::observer`] with its
//! protection.
//!
//! * model and filter: the 19-state steady-state filter of
//!   [`OmnimagnetObserver`](crate::omnimagnet::observer::OmnimagnetObserver)
//!   (16 element temperatures and a heat-input bias per solenoid, Joule
//!   power `R(T) I^2` at the estimated solenoid temperatures), in `f32`:
//!   [`MeanModel::predict`] every model step and
//!   [`update_steady`] when thermocouple readings arrive. The configuration
//!   holds the gain, the measurement model and the gate; the *state* holds
//!   the [`MeanModel`] (the linearisation the predict runs on), because
//!   the operating point is a property of the device, not of its type;
//! * re-linearisation off the tick: a lower-priority task runs a
//!   [`Relinearizer`](crate::omnimagnet::Relinearizer) on the published
//!   estimate, turns each new [`Linearization`] into a model with
//!   [`OmniObserver::prepare_model`] and hands it over (a
//!   [`Mailbox`](super::Mailbox)); the control loop installs it between two
//!   ticks with [`OmniObserver::install_model`] (`O(N)`: the estimate is
//!   re-based, the temperatures do not jump). The steady-state gain stays the
//!   build-time one: a gain for a model some kelvin away is suboptimal, not
//!   unstable (see the filter's module docs for the measured effect);
//! * protection: alarms on the wire and cover insulation of each solenoid
//!   (nodes 7 .. 12, [`ALARM_NODES`]), the current limiter on the three
//!   solenoid currents, and the sliced modal time-to-limit predictor.
//!
//! The time-varying filter of every model step is not offered here: its
//! covariance predict costs about 8 400 multiply-adds a step and one of its
//! corrections about 12 000, beyond a 1 ms tick's budget on a Cortex-M4F,
//! so the steady-state gain runs from the first tick ([`OmniObserver::new`]
//! refuses `GainMode::TimeVarying` and a warm-up). The one exception is the
//! start without a history ([`OmniObserver::start`], "Start without
//! history" below), which holds its covariance once per correction period,
//! in slices.
//!
//! ```
//! use coil_thermal::observer::omnimagnet::{OmniObserver, OmniSettings, OmniInputs};
//! use coil_thermal::omnimagnet::{Omnimagnet, Relinearizer, RelinearizeConfig, RelinearizePoll, NODES};
//!
//! let model = Omnimagnet::PAPER;
//! let omni = OmniObserver::new(&model, &[22.0; NODES], 22.0, &OmniSettings::default())?;
//! let mut state = omni.state(&[22.0; NODES], 22.0);
//! // Background task: re-linearise 5 K away from the active point.
//! let mut relinearizer =
//!     Relinearizer::new(model, RelinearizeConfig::default(), &[22.0; NODES], 22.0)?;
//! let inputs = OmniInputs {
//!     currents_a: [3.8; 3],
//!     ambient_c: 22.0,
//!     readings: [None; 6],
//!     now_us: 0,
//!     elapsed_us: 1000,
//! };
//! for _ in 0..1000 {
//!     omni.tick(&mut state, &inputs); // the control interrupt
//! }
//! // Far from the active point (here forced by asking at +10 K):
//! let hot = state.outputs().temps_c.map(|t| f64::from(t) + 10.0);
//! while relinearizer.poll(&hot, 22.0) != RelinearizePoll::Swapped {}
//! let next = omni.prepare_model(relinearizer.active())?; // background
//! let before = state.outputs().temps_c;
//! omni.install_model(&mut state, &next)?; // between two ticks
//! assert_eq!(state.model.origin_c()[0], hot[0] as f32);
//! assert!((omni.temps_c(&state)[0] - before[0]).abs() < 1e-4);
//! # Ok::<(), coil_thermal::BuildError>(())
//! ```
//!
//! # Configuration in flash
//!
//! Everything [`OmniObserver::new`] solves (linearisation, steady-state
//! gain, the predictor's modes, the protection) can be solved on a host:
//! [`OmniObserver::parts`] gives it as plain tables ([`OmniParts`]),
//! [`OmniParts::write_rust`] writes them as Rust (`coil-thermal codegen
//! --device omnimagnet`), and the `const fn` [`OmniObserver::from_parts`]
//! assembles them, so a `static` initialised with it is evaluated by the
//! compiler and stays in flash; the tick takes `&self` and needs only the
//! state in RAM (`examples/observer_m4.rs`, `docs/cost.md`). `from_parts`
//! copies the tables without arithmetic, so the observer is `new`'s to the
//! bit; the snapshot fingerprint is carried in the parts, not recomputed.
//!
//! # Model step and ticks
//!
//! The model steps every [`OmniSettings::step_us`] of measured time, which
//! need not be the loop's tick ([`OmniSettings::loop_period_us`]): the
//! fastest Omnimagnet node (the paper sheet) has a time constant near
//! 0.25 s and the solenoids minutes, so a step of 5 or 10 ms loses nothing
//! the thermocouples could see, and costs the 336 multiply-adds of the
//! predict once per step instead of once per tick (`observer_m4`: the
//! Omnimagnet part 2 102 -> 1 040 instructions mean at 5 ms,
//! `docs/cost.md`). Every tick accounts each solenoid's `I^2` times its
//! elapsed time, and a step heats with the mean `I^2` of the time it
//! covers times `R(T)` at its start estimate: the exact mean power for a
//! current that changes every tick (PWM, commutation), where the held
//! current of the tick the step lands on would sample it and could read
//! cold (0.74 K cold after 30 s of a 2 ms square wave at 5 ms steps, in
//! `host-tests/tests/omni_multirate.rs`; with the mean, within 1.6 mK of
//! the nonlinear model and at most 0.8 mK colder than the 1 ms run). When
//! the currents held over a step did not change, the step takes them as
//! they are, to the bit as a model without the account (the defaults keep
//! every result of a 1 ms model).
//!
//! What a longer step costs: the estimate lags the clock by the time not
//! yet stepped (less than a step; at most a step and a tick after a
//! deferral below), the published temperatures move once per step, and
//! `max_steps_per_tick` bounds a catch-up in steps, so 1 at 5 ms still
//! takes up 5 ms of late time per tick at the price of one step. A tick
//! that runs a step longer than the loop's tick is busy, as a catch-up is
//! (the predictor slice waits a tick), and a tick that brings readings
//! defers its step to the next tick ([`StepClock::defer`], never twice in
//! a row, no time dropped) and runs the heat-bias check of its correction
//! on the next tick too: a correction and a step on one tick would make
//! the heaviest tick. The correction then fuses readings a step's time
//! younger than the model, which the steady gain takes as it takes a
//! reading a few milliseconds old. `protect_period_steps`,
//! `protect_phase_steps` and the correction period are in model steps or
//! seconds: at 5 ms, 8 and 1 steps keep the 40 ms cycle and put it 5 ms
//! after a 20 ms grid update (`examples/observer_m4.rs`).
//!
//! # Protection cycle
//!
//! A 1 ms step changes a solenoid by about 1e-4 K, so the protection need
//! not follow every step: it runs once every
//! [`OmniSettings::protect_period_steps`] model steps (default 16 ms), one
//! stage per tick so that no tick carries more than one: a predictor slice
//! (one horizon; or, with [`OmniSettings::predictor_slices_per_cycle`] and
//! [`OmniSettings::predictor_nodes_per_slice`], several smaller slices on
//! consecutive ticks: the snapshot alone in two (its steady state, then
//! its modal amplitudes), then at most that many nodes of
//! a horizon each), then the alarm, then the limiter. Between cycles the
//! outputs stand, except the times to limit, which are aged every tick. The
//! slice is put off by one tick when that tick also corrects or catches up
//! (never twice in a row), so a correction tick does not carry the most
//! expensive stage. The limits lag the model by at most a cycle and three
//! ticks (20 ms at the defaults, against time constants of seconds), and the
//! alarm's debounce and event stamps count cycles, not ticks.
//! [`OmniSettings::protect_phase_steps`] starts every cycle after the first
//! that many steps after its period's boundary, so that the stages can be
//! kept off the ticks another observer in the same loop makes heavy
//! (`examples/observer_m4.rs` puts them between the grid's protection
//! stages).
//!
//! The predictor is built for one slice per cycle (`tick_s` = the cycle)
//! and is fed the largest current of each solenoid since its last slice, so
//! its conservative bound still covers currents that vary within a cycle.
//! Each slice ages its answers by one cycle; the real time it lags behind
//! (a put-off slice, a catch-up, dropped time) is counted and subtracted
//! from the published times to limit, so they stay never later than the
//! model's.
//!
//! # Model refresh
//!
//! With the build-time linearisation at the ambient, a solenoid whose only
//! thermocouple fails is left to a model that runs 3.7 K off at 7 A
//! (2.6 K at 3.1 A; issue 17 asks for 2 K), and the doubt rule can only
//! make its protection err hot. Re-linearised at the estimate every 10 to
//! 30 s, the model alone stays within 0.1 K (docs/protection.md, "One
//! thermocouple per solenoid"). So a sensor set in which a single fault
//! leaves a solenoid without a thermocouple ([`needs_model_refresh`]; every
//! solenoid carries alarm elements) is accepted only together with that
//! refresh: [`OmniSettings::model_refresh_s`] declares the period of the
//! firmware's background task (at most [`MAX_MODEL_REFRESH_S`]), and
//! [`OmniObserver::new`] and [`OmniObserver::from_parts`] refuse the set
//! without it ([`BuildError::ModelRefreshRequired`], naming the solenoid).
//! Two thermocouples on every solenoid need none.
//!
//! A declared refresh is watched: every tick adds its model steps to a
//! saturating count that [`OmniObserver::install_model`] resets, and a
//! count beyond [`MODEL_STALE_PERIODS`] periods flags the tick
//! [`InputFlags::MODEL_STALE`] (one add and one compare per tick; a
//! refresh not declared never goes stale). While stale, the alarm and the
//! limiter act on the hotter of the estimate's and the unfused shadow's
//! upper bounds on every alarm element: the protection of a solenoid in
//! doubt (the doubt rule of docs/protection.md), the same code. The
//! next install ends it. The counter is state, not snapshot: a restored
//! state starts it at zero with the build-time model, as it starts the
//! model.
//!
//! # Rules shared with the network observer, and why it is not one
//!
//! Every rule the two filtered observers both apply is written once and
//! used by both: the settings ([`SensorChecks`]), the consistency band and
//! the stuck test (`consistency::screen_readings`), silence
//! (`SilenceWatch`), the stuck sensor's rewind (`consistency::StuckRewind`:
//! what a thermocouple taught the heat-input biases before it was found
//! stuck goes back; the Omnimagnet gained it in issue 37, 144 more
//! instructions on a correction tick, QEMU `observer_m4`; test
//! `a_thermocouple_stuck_while_its_solenoid_heats_gives_back_the_heat_it_taught`),
//! the doubt (`sensor_doubt`, `Suspicion`) and the protection on the
//! shadow while a measurement is in doubt or the model stale
//! (`consistency::protect_on_shadow`), the model refresh's watchdog
//! (`consistency::RefreshWatchdog`, [`MODEL_STALE_PERIODS`]), the drift
//! hold (below), the latch
//! (`cycle::Latch`: latched, restored, clock lost, cleared; the grid's
//! too), the protection cycle and its stage dispatch
//! (`cycle::ProtectionStages::run_due`: which stage a tick runs, the
//! bookkeeping after it, the ageing of the answers; each observer says
//! only what its stages do), the step's `I^2` account
//! (`clock::StepAccount`), the snapshot writer (`snapshot::save_state`), the gain's tables
//! ([`GainTables`](super::network::GainTables)), the start's rules
//! ([`super::start`]) and the outputs ([`super::FilteredOutputs`]).
//!
//! Two rules stay the Omnimagnet's own:
//!
//! * **no bias floor.** The network observer holds every heat-input bias at
//!   or above `-max_cooling_bias_fraction * P` (default 0: no heat taken
//!   away), right for a linear network whose `R(T)` is taken at the
//!   estimate: there a cold drift and a model that runs hot look the same,
//!   and a model known to run hot declares the share. The Omnimagnet's
//!   build-time linearisation at the ambient is such a model, by up to a
//!   quarter of the heat: its conductances are the cold ones, so it
//!   over-predicts a hot solenoid's temperature, and a healthy *negative*
//!   bias corrects it. With six healthy thermocouples against the RK4
//!   plant the biases settle at -7.0, -11.8 and -34.5 W after 15 min at
//!   7 A (up to 17 % of the Joule power; 28 % after 30 min at 3.1 A), the
//!   solenoids within 0.28 K of the plant; held at the floor, 0.68 K
//!   (test `the_omnimagnets_healthy_heat_bias_is_negative_and_a_floor_would_cost_accuracy`),
//!   and a stuck thermocouple's solenoid 2.56 K off instead of 1.91 K.
//!   Without a refresh the share keeps growing: after 1 h, 60 % on
//!   solenoid 3 at 3.1 and 4 A (a scratch run of the same drive at 1 to
//!   8 A, not kept as a test), so a declared share that spares the
//!   healthy run would bound little. So negative biases are dropped only
//!   once the model is re-linearised, on the solenoids in doubt
//!   (`drop_cold_biases`), where the model needs no bias;
//! * **the model refresh** (above): the network observer has none, because
//!   its network is linear; the watchdog is written for any observer that
//!   declares one.
//!
//! The drift hold (`consistency::DriftHold`: a reading the gate refused
//! `suspect_after` times in a row, colder than the estimate and than the
//! shadow, is held out of the gate's recovery while it drifts) is the
//! network observer's too. The recovery it guards against fuses only after
//! a run of corrections in which *every* present reading was refused, so
//! with several thermocouples reading it never takes one drifting
//! thermocouple (the fault campaign's drift class meets its goals either
//! way, `host-tests/tests/faults_cli.rs`,
//! `one_per_solenoid_stuck_and_drift_meet_the_goals`). It matters when the
//! drifting thermocouple is the only one left: one per solenoid, two of
//! them open, the third drifting down 0.05 K/s at 4 A put the published
//! bound 3.7 K below the plant at solenoid 1 before the consistency band
//! caught the reading; held, 0.92 K (test
//! `a_lone_thermocouple_drifting_cold_is_held_out_of_the_gates_recovery`).
//! Its cost on a correction tick with no sensor in question, one pass of
//! compares: about 65 instructions (QEMU `observer_m4`, 2 479 -> 2 544
//! mean), and 40 B of state. (Fewer than three thermocouples the
//! Omnimagnet does not take at all: every set of one or two is refused at
//! build time, unobservable or without a steady gain; test
//! `every_set_of_one_or_two_thermocouples_is_refused`.)
//!
//! The Omnimagnet cannot be the network observer over its own network at
//! no cost. Its conductances move with temperature
//! (`Omnimagnet` is not a [`Network`](crate::Network) of constants), so a
//! network observer would run the build-time linearisation for ever (3.7 K
//! off a solenoid left to the model at 7 A) or carry the refresh: the
//! model in the *state* (the [`MeanModel`], in RAM: the Omnimagnet state is
//! 3 552 B where the network observer keeps its tables in flash), its
//! install between ticks (3 060 instructions, QEMU `observer_m4`) and the
//! watchdog's add and compare on every tick, work the linear network
//! observer's tick (network_roundtrip 389 mean / 1 074 worst,
//! motor_qemu 1 173 / 3 435, ticking their generated `static OBSERVER`)
//! has no room for. What both can share they share (above); what follows from a
//! nonlinear plant stays here.
//!
//! # Warm restart and the latch
//!
//! [`OmniObserver::save`] writes the node estimates and the latched
//! shutdown; [`OmniObserver::restore`] checks them against this
//! configuration's fingerprint (the filter *and* the protection: alarm,
//! derating, limiter, `k_sigma`, margin) and refuses anything else, and
//! [`OmniObserver::conservative_state`] is the start after a refusal (the
//! thermocouples' readings, every other node no cooler than the hottest).
//! A restored latch shows in the state's outputs at once
//! (`outputs().alarm.shutdown`, before the first tick), and the
//! conservative state starts latched: a refused snapshot may have held a
//! latch. Only the deliberate [`OmniObserver::clear_shutdown`], called by
//! the application after inspecting the device, clears it.
//! A clock that gives no elapsed time for
//! [`OmniSettings::frozen_loss_ticks`] ticks in a row (1000 by default;
//! flagged [`InputFlags::CLOCK_FROZEN`] from `frozen_flag_ticks`, 100)
//! latches it too: the model is lost (see [`super::clock`]).
//!
//! [`OmniObserver::restore_after`] is the restore for a device that was off
//! for a known time: the saved estimates cooled by the nonlinear model with
//! no current ([`Omnimagnet::cooled_c`]: frozen pieces, each an exact
//! linear solution), never below the model's exact cooled state and within
//! 0.5 K of it (measured from 1 s to 10 h after realistic heating runs:
//! at most +0.42 K for the model's cooling, +0.31 K for this restore's).
//! One linearisation at the ambient would cool far too slowly (18.3 K
//! above after the paper's run). An unknown off time means
//! no cooling there; [`OmniObserver::restore_with_readings`] finds it from
//! the thermocouples instead (see [`super::start`]): the shortest off time,
//! within the snapshot's age, whose cooled state brings some solenoid
//! within `k_sigma` thermocouple deviations (0.75 K) of its reading (of
//! the solenoids the saved state puts above their readings), every read
//! solenoid at its hotter reading. Saved at the limit and restored
//! 15 min later after 10 min off, it errs hot by at most 1.2 K on any node
//! (the known off time: 0.07 K), where the uncooled restore refuses 2 393
//! healthy readings in 5 min (`start_tests.rs`).
//!
//! # Start without history
//!
//! After a reset with no snapshot to trust (the first boot, a refused
//! snapshot, a product that keeps none), [`OmniObserver::start`] makes a
//! state that is safe from the first tick and converges on the
//! thermocouples, the network observer's start ([`super::start`]) with
//! what the Omnimagnet needs on top:
//!
//! * **mean**: each solenoid at its readings (the hotter of its two); the
//!   other nodes at the steady state of the nonlinear model's network with
//!   the solenoids, every heat source, held there
//!   ([`start::held_steady_state_c`], secant conductances at the start's
//!   temperatures, three passes), each between the coolest reading and the
//!   hottest; each wire or cover insulation no hotter than where its
//!   steady upper bound is [`start::START_BELOW_LIMIT_K`] below its alarm
//!   limit. At the hottest point of a protected run the solenoids sit some
//!   kelvin above the cover's limit: the network observer's mean (every
//!   unread node at the hottest reading) puts the frames 5 to 14 K too hot
//!   there, whose heat drives a cover's estimate a kelvin up within
//!   seconds, past its limit: the shutdown latched;
//! * **covariance**: the steady prior widened on every node no
//!   thermocouple reads, each insulation to a bound
//!   [`start::START_BELOW_LIMIT_K`] below its alarm limit, the other nodes
//!   to the widest of those (from the wire's 163 degC limit: about 25 K);
//! * **held once per correction period**: the per-step covariance predict
//!   is too costly (above), so the covariance is propagated with the
//!   period's transition, the one the unfused shadow already steps with
//!   (no new table), as `F (P+ - P_ss) F^T + M` from the steady solution,
//!   in slices on the light ticks (no correction, no protection stage, no
//!   model step longer than the tick lasted): 19 columns, 8 row pairs, 19
//!   mirrored columns, 5 slices that prepare the next correction's gain,
//!   `S` and `M H^T` after the new prior and after a correction, 58
//!   slices per 0.5 s of at most about 400 multiply-adds each, as many a
//!   light tick as fit a period's propagation into half the light ticks
//!   the declared loop leaves (one at 1 ms; all at a 100 ms loop, whose
//!   five ticks a period would otherwise leave the prior ten periods
//!   behind the readings and the gate refusing healthy ones). The readings' information within a period adds
//!   up (a `3 x 3` weight: any number of corrections, in any order). A
//!   correction during the warm-up is then the steady filter's own code
//!   on that gain (the gate judges against the covariance held). Against
//!   the per-step time-varying filter in `f64` the held priors agree
//!   within 1.3e-4 (relative) after 200 periods. Measured in
//!   `examples/omni_start_m4.rs` (Cortex-M4F, `observer_m4`'s 5 ms
//!   configuration): plain ticks 837 instructions mean, 3 312 worst (the
//!   steady filter's state: 671 and 3 022), a correction 3 023 (2 288);
//!   the start itself, once, 2.9 million; the state 7 208 B (the
//!   covariance and what the correction needs, 3.7 KiB; a state of the
//!   [`NoWarmUp`] flavour, which [`OmniObserver::state`] and the restores
//!   without readings return, 3 496 B: it holds none of it);
//! * **the protection follows it**: the upper bound widens by `k` times the
//!   held deviation, on the insulations no higher than
//!   [`start::START_BELOW_LIMIT_K`] below the limit
//!   ([`start::capped_extra_k`]: the start assumes the protection held
//!   before the reset, and the wires' far limit would otherwise widen the
//!   covers past theirs within half a second); the limiter starts in its
//!   taper band (2.53 A of 8 A) and the time to limit follows the widened
//!   bound. No shutdown is latched;
//! * **the shadow follows the estimate** until the start no longer widens
//!   any solenoid's or insulation's bound by 0.1 K
//!   ([`start::START_FORGOTTEN_K`], 9.5 to 18 min after the resets
//!   below), then runs free. The warm-up itself ends when every variance
//!   is within 5 % of the steady posterior's: the core (2.5 h time
//!   constant) keeps an excess for hours, so the held covariance runs to
//!   [`start::MAX_START_CORRECTIONS`] corrections (9.1 h), at the cost
//!   above.
//!
//! The model refresh coexists: [`OmniObserver::install_model`] re-bases the
//! mean, which moves no covariance, and the held covariance propagates with
//! the build-time linearisation, as the steady gain does (a hot device's
//! conductances are larger, so the cold model forgets the start more
//! slowly: the safe side).
//!
//! Measured against the paper's nonlinear model (RK4, `f64`) driven by
//! what the observer allows of 8 A after 3 h at the limit and a reset 0 s,
//! 1 min, 10 min and 1 h later (`start_tests.rs`): no insulation within
//! 3.3 K of its limit, every node's upper bound above the truth from 1 s
//! on, no healthy reading refused, the last minute's currents within 0.1 %
//! of a warm start's. The ambient start (`state(ambient)`) puts the bounds
//! 23 to 59 K below the truth, refuses the readings and, 10 min after the
//! reset, lets the insulations run 50 K past their limits; the start's
//! mean with the steady covariance misses the core's heat by 5.3 K.
//!
//! # Readings
//!
//! Each thermocouple reading arrives on its own, as a [`TimedReading`]: the
//! driver's [`SensorResult`](crate::sensors::SensorResult) and the time it was sampled on the same
//! microsecond clock as [`OmniInputs::now_us`]. A fault is not fused and is
//! reported as [`SensorStatus::Fault`]; a reading older than
//! `max_reading_age_us` is not fused and reported [`SensorStatus::TooOld`]; a
//! reading the innovation gate refuses is [`SensorStatus::Rejected`]. A late
//! reading younger than the limit is fused as if it were taken now: the
//! thermal time constants are seconds, a few milliseconds of age are within
//! the thermocouple's noise. The steady-state gain assumes a correction every
//! `reading_period_steps`; irregular arrivals make it slightly suboptimal, not
//! unstable (the gain is that of a stable filter, see [`crate::filter`]).
//!
//! # Limits per solenoid
//!
//! Solenoid `m` is limited by whichever of its wire (node `7 + 2m`) or cover
//! insulation (node `8 + 2m`) has less headroom to its alarm limit; the
//! limiter sees that headroom below the cover's limit.
//!
//! # Acting on an upper bound
//!
//! The alarm, the limiter and the time to limit act on each node's
//! protective upper bound (see [`crate::protect::margin`]), published next
//! to the mean as [`OmniOutputs::upper_c`]:
//!
//! * `k sigma` on every node, `sigma` the node's standard deviation in the
//!   steady-state prior (just before a correction, the largest of the
//!   cycle), computed once at build time: with the steady-state gain it is
//!   constant. [`OmniSettings::k_sigma`], default 3;
//! * the model-uncertainty margin on every node no thermocouple in use
//!   measures ([`OmniSettings::unmeasured_margin`], default
//!   [`UncertaintyMargin::OMNIMAGNET_UNMEASURED_20_PERCENT`], 5 % of the
//!   rise above the ambient), because the covariance reports the noise the
//!   filter was told about, not the model's parameter error (NEES about
//!   13 000 at +-20 %). Every alarm node is unmeasured: the covers carry the
//!   critical 120 degC and no thermocouple.
//!
//! The predictor runs on the mean, towards each node's mean limit (where
//! its bound reaches the alarm limit). The bound is taken in the alarm and
//! limiter stages of each cycle (16 nodes' comparison, multiply and
//! additions, twice per cycle, not per tick); with `k_sigma` 0 and
//! [`UncertaintyMargin::ZERO`] the protection acts on the mean, to the
//! bit.

use crate::sizes::ConstSizes;
use nalgebra::{Const, SVector};

use super::clock::{step_square_currents, ClockState, Deferral, StepAccount, StepClock};
use super::consistency::{
    drop_cold_biases, protect_on_shadow, screen_readings, sensor_doubt, Band, BiasBound, BlockMean,
    DriftHold, GateView, RefreshWatchdog, SilenceWatch, StuckRewind, StuckTest, StuckWatch,
    Suspicion,
};
use super::cycle::{
    aged_time_to_limit, record_verdicts, sample_readings, Latch, Protecting, ProtectionCycle,
    ProtectionStages, Stage,
};
use super::snapshot::{self, Fingerprint, Restored, SnapshotError, SnapshotMeta};
use super::start::{self, HeldCovariance, HeldLayout, PeriodTransition};
use super::vocabulary::{ConstOutputs, SensorChecks, EVENT_CAPACITY};
pub use super::vocabulary::{SensorStatus, TimedReading};
use super::warm_up::Flavour;
pub use super::warm_up::{NoWarmUp, WarmUp};
use crate::error::BuildError;
use crate::filter::{update_against, update_steady, SteadyEstimate, UpdateReport};
use crate::input::{InputFlags, InputLimits, ScalarLimits};
use crate::omnimagnet::observer::{
    GainMode, MeanModel, ObserverConfig, ObserverSettings, INPUTS, STATES,
};
use crate::omnimagnet::{
    CoolingPath, Linearization, Omnimagnet, COVER_INSULATION_LIMIT_C, NODES, SOLENOIDS,
    THERMOCOUPLES, THERMOCOUPLE_NODES, WIRE_INSULATION_LIMIT_C,
};
use crate::protect::alarm::{AlarmBuilder, AlarmConfig, AlarmState, AlarmStatus, ResetError};
use crate::protect::derating::DeratingRule;
use crate::protect::events::EventQueue;
use crate::protect::limiter::{CoilLimit, LimiterConfig};
use crate::protect::margin::{UncertaintyMargin, UpperBound, UpperBoundBuilder};
use crate::protect::predict::{
    AnswersWhenAsked, LimitPredictor, Operating, PredictorBuilder, PredictorState,
};

mod parts;

pub use parts::{FilterTables, MeanModelTables, OmniParts, ProtectionTables};

/// Elements with an alarm: wire and cover insulation of each solenoid.
pub const ALARM_NODES: [usize; 6] = [7, 8, 9, 10, 11, 12];
/// Refresh periods without an [`OmniObserver::install_model`] after which
/// a declared model refresh ([`OmniSettings::model_refresh_s`]) is stale
/// and the tick flags [`InputFlags::MODEL_STALE`] (the watchdog every
/// observer with a model refresh shares).
pub use super::consistency::MODEL_STALE_PERIODS;
pub use super::tables::PREDICTOR_POINTS;
/// The slowest model refresh \[s\] that makes a placement with one
/// thermocouple on a solenoid acceptable ([`BuildError::ModelRefreshRequired`]).
/// Measured with one thermocouple per solenoid (`coil-thermal faults
/// --sensors 0,2,4`): the lost sensor's solenoid is 0.04, 0.06, 0.09, 0.17
/// and 0.38 K off at 7 A with a refresh every 10, 20, 30, 60 and 120 s
/// (3.7 K with none), so within 30 s, and the 90 s before the watchdog
/// ([`MODEL_STALE_PERIODS`]) gives up on a dead task, stay well inside
/// issue 17's 2 K.
pub const MAX_MODEL_REFRESH_S: f64 = 30.0;
/// [`MAX_MODEL_REFRESH_S`] \[us\], for the integer checks.
const MAX_MODEL_REFRESH_US: u64 = (MAX_MODEL_REFRESH_S * 1e6) as u64;
/// The nodes the thermocouples read, the solenoids, in the order of the
/// start's held covariance (see [`OmniObserver::start`]).
const MEASURED_NODES: [usize; SOLENOIDS] = [0, 1, 2];
/// Each thermocouple's place in [`MEASURED_NODES`].
const SENSOR_MEASURED: [usize; THERMOCOUPLES] = {
    let mut out = [0; THERMOCOUPLES];
    let mut j = 0;
    while j < THERMOCOUPLES {
        let mut k = 0;
        let mut found = false;
        while k < SOLENOIDS {
            if MEASURED_NODES[k] == THERMOCOUPLE_NODES[j] {
                out[j] = k;
                found = true;
            }
            k += 1;
        }
        assert!(found, "every thermocouple reads a measured node");
        j += 1;
    }
    out
};
/// The start's covariance as the Omnimagnet holds it.
type StartCovariance = HeldCovariance<STATES, SOLENOIDS, THERMOCOUPLES>;

/// What the Omnimagnet's warm-up holds (the `H` of its [`WarmUp`]
/// flavour, opaque): the start's covariance while the warm-up of
/// [`OmniObserver::start`] runs (about 3.7 KiB) and its widening of the
/// alarm elements' bounds. A state of the [`NoWarmUp`] flavour carries
/// neither.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone)]
pub struct OmniHeld {
    /// The start's covariance while its warm-up runs; idle when the state
    /// was given the flavour by [`OmniObserver::with_warm_up`].
    cov: StartCovariance,
    /// The start's widening of each [`ALARM_NODES`] element's bound at
    /// the last protection stage \[K\] (the predictor's limits follow it).
    extra_k: [f32; ALARM_NODES.len()],
}

impl OmniHeld {
    /// Nothing held: the steady filter from the first tick.
    fn idle() -> Self {
        Self {
            cov: StartCovariance::idle(),
            extra_k: [0.0; ALARM_NODES.len()],
        }
    }
}

/// An Omnimagnet state's warm-up flavour (see [`super::warm_up`]):
/// [`NoWarmUp`], or [`WarmUp`] holding [`OmniHeld`] (sealed).
pub trait OmniWarmUpKind: Flavour<OmniHeld> {}

impl<W: Flavour<OmniHeld>> OmniWarmUpKind for W {}

/// No widening of the alarm elements' bounds (a state without a warm-up,
/// or one whose warm-up has ended).
const NO_EXTRA_K: [f32; ALARM_NODES.len()] = [0.0; ALARM_NODES.len()];

/// A limit no Omnimagnet winding reaches \[degC\], for the predictor,
/// which takes each winding's power at its node's limit (so it must be
/// finite there; the other nodes without an alarm get `+inf` and cost no
/// predictor work).
const NO_LIMIT_C: f32 = 1000.0;

/// Build settings, each with a default.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OmniSettings {
    /// Model step \[us\]. Default 1000. Several ticks long, the steps
    /// take the mean `I^2` of their ticks (see "Model step and ticks" in
    /// the module docs); set [`Self::loop_period_us`] to the loop's tick.
    pub step_us: u32,
    /// Catch-up bound, model steps per tick (a deferred step comes on
    /// top). Default 4.
    pub max_steps_per_tick: u32,
    /// The Kalman filter: sensor subset, noise, gate, correction period
    /// (the steady-state gain is solved for one correction every
    /// `correction_period_s`). `mode` must be [`GainMode::SteadyState`] and
    /// `warmup_corrections` 0: the tick API runs no time-varying warm-up
    /// (see the module docs). Default: [`ObserverSettings::DEFAULT`] with
    /// those two and a thermocouple noise of 0.25 K instead of the paper's
    /// calibrated 0.1 K. Without the warm-up the gate judges the first
    /// readings against the *converged* covariance, and 0.25 K lets a start
    /// some tenths of a kelvin off (a state made from the readings, a
    /// snapshot a few seconds old) be corrected at once instead of waiting
    /// for the gate's recovery (`recover_after` corrections, 2.5 s).
    pub filter: ObserverSettings,
    /// Oldest reading still fused \[us\]. Default 100 000.
    pub max_reading_age_us: u32,
    /// Hardware current limit of each solenoid \[A\]. Default 8.
    pub hardware_limit_a: f64,
    /// Width of the limiter's taper band \[K\]. Default 10.
    pub taper_k: f64,
    /// Model steps per protection cycle (see the module docs), at least
    /// `(2 slices + 2) max_steps_per_tick` with `slices` the
    /// [`Self::predictor_slices_per_cycle`]: a cycle takes at most that
    /// many ticks (each slice put off once, the alarm and the limiter; 4
    /// with one slice), so it always ends before the next is due and the
    /// predictor's lag stays bounded. Default 16.
    pub protect_period_steps: u32,
    /// Model steps by which every protection cycle after the first starts
    /// later than its period's boundary, less than `protect_period_steps`:
    /// with a period that is a multiple of another observer's update
    /// period in the same loop, the predictor slice can be put on the
    /// ticks that observer leaves light (see `examples/observer_m4.rs`).
    /// The published times to limit are aged by the real lag. Default 0.
    pub protect_phase_steps: u32,
    /// How many steady-state standard deviations of the filter are added
    /// to every element's estimate in its protective upper bound
    /// (dimensionless, finite, `>= 0`; see [`crate::protect::margin`]).
    /// Default 3 (a Gaussian error exceeds it 0.13 % of the time).
    pub k_sigma: f64,
    /// The model-uncertainty margin of the elements without a
    /// thermocouple, on their rise above the ambient (the filter's
    /// covariance does not describe parameter error; see
    /// [`crate::protect::margin`]). Default
    /// [`UncertaintyMargin::OMNIMAGNET_UNMEASURED_20_PERCENT`]. With `k_sigma`
    /// 0 and [`UncertaintyMargin::ZERO`] the protection acts on the
    /// estimate itself.
    pub unmeasured_margin: UncertaintyMargin,
    /// Consecutive ticks without elapsed time from which every tick is
    /// flagged [`InputFlags::CLOCK_FROZEN`] (see [`super::clock`]). Default
    /// 100 (0.1 s at a 1 ms loop).
    pub frozen_flag_ticks: u32,
    /// Consecutive ticks without elapsed time from which the model is taken
    /// as lost: the shutdown latches with a
    /// [`ClockFrozen`](crate::protect::events::EventKind::ClockFrozen)
    /// event. At least `frozen_flag_ticks`. Default 1000 (1 s).
    pub frozen_loss_ticks: u32,
    /// The checks the thermocouples are held to against the physics and
    /// the bound on what they leave uncertain (as the network observer's,
    /// [`NetworkSettings::checks`](super::NetworkSettings::checks)).
    /// Default [`SensorChecks::DEFAULT`].
    pub checks: SensorChecks,
    /// The control loop's nominal tick \[us\]. Default 1000. A model step
    /// longer than it (`step_us` of several ticks: the multi-rate model,
    /// see "Model step and ticks" in the module docs) makes every tick
    /// that runs a step busy, as a catch-up is: the predictor slice is put
    /// off to the next tick. With `step_us` equal to it nothing changes.
    pub loop_period_us: u32,
    /// Predictor slices per protection cycle, on consecutive ticks (each
    /// put off once by a busy tick), at least 1; `protect_period_steps`
    /// must then be at least `(2 slices + 2) max_steps_per_tick` and the
    /// cycle's length in microseconds a multiple of it. Default 1. With
    /// [`Self::predictor_nodes_per_slice`], a sweep of the same length in
    /// cheaper ticks.
    pub predictor_slices_per_cycle: u32,
    /// At most this many nodes' horizons per predictor slice, at least 1
    /// (the snapshot that starts a sweep then takes two slices of its own;
    /// see [`PredictorBuilder::elements_per_tick`]). Default `u32::MAX`:
    /// a whole horizon, the snapshot with the first.
    pub predictor_nodes_per_slice: u32,
    /// The period \[s\] at which the firmware re-linearises the model at
    /// the estimate in a background task
    /// ([`OmniObserver::prepare_model`], then
    /// [`OmniObserver::install_model`] between two ticks); `None`: never,
    /// the build-time linearisation throughout. Declared, it is watched:
    /// [`MODEL_STALE_PERIODS`] periods of model time without an install
    /// flag every tick [`InputFlags::MODEL_STALE`] and put the protection
    /// on the hotter of the estimate's and the shadow's upper bounds (see
    /// "Model refresh" in the module docs). A sensor set that leaves a
    /// solenoid with at most one thermocouple needs it, at most
    /// [`MAX_MODEL_REFRESH_S`] ([`BuildError::ModelRefreshRequired`]).
    /// The watchdog counts installs, not changes: a task whose
    /// [`Relinearizer`](crate::omnimagnet::Relinearizer) did not swap in a
    /// period installs its active linearisation again (the estimate does
    /// not move). Finite and `> 0`. Default `None`.
    pub model_refresh_s: Option<f64>,
}

impl Default for OmniSettings {
    fn default() -> Self {
        Self {
            step_us: 1000,
            max_steps_per_tick: 4,
            filter: ObserverSettings {
                thermocouple_sigma_k: 0.25,
                warmup_corrections: 0,
                ..ObserverSettings::DEFAULT
            },
            max_reading_age_us: 100_000,
            hardware_limit_a: 8.0,
            taper_k: 10.0,
            protect_period_steps: 16,
            protect_phase_steps: 0,
            k_sigma: 3.0,
            unmeasured_margin: UncertaintyMargin::OMNIMAGNET_UNMEASURED_20_PERCENT,
            frozen_flag_ticks: super::clock::DEFAULT_FROZEN_FLAG_TICKS,
            frozen_loss_ticks: super::clock::DEFAULT_FROZEN_LOSS_TICKS,
            checks: SensorChecks::DEFAULT,
            loop_period_us: 1000,
            predictor_slices_per_cycle: 1,
            predictor_nodes_per_slice: u32::MAX,
            model_refresh_s: None,
        }
    }
}

/// The inputs of one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OmniInputs {
    /// Solenoid currents \[A\]; NaN holds the last valid one.
    pub currents_a: [f32; SOLENOIDS],
    /// Ambient temperature \[degC\].
    pub ambient_c: f32,
    /// Fresh readings, one slot per thermocouple ([`THERMOCOUPLE_NODES`]).
    pub readings: [Option<TimedReading>; THERMOCOUPLES],
    /// Now, on the readings' microsecond clock \[us\] (wrapping).
    pub now_us: u32,
    /// Measured time since the previous tick \[us\].
    pub elapsed_us: u32,
}

/// What one tick produced (`Copy`, for [`Shared`](super::Shared)): the
/// filtered observers' outputs, over the [`NODE_NAMES`](crate::omnimagnet::NODE_NAMES),
/// a time to limit for each of the [`ALARM_NODES`].
pub type OmniOutputs = ConstOutputs<NODES, SOLENOIDS, { ALARM_NODES.len() }, THERMOCOUPLES>;

/// The configuration of one Omnimagnet device.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone)]
pub struct OmniObserver {
    filter: ObserverConfig<f32>,
    alarm: AlarmConfig<f32, Const<6>>,
    limiter: LimiterConfig<f32, Const<SOLENOIDS>>,
    predictor: LimitPredictor<f32, NODES, 1, SOLENOIDS, PREDICTOR_POINTS>,
    /// Each node's protective upper bound, on its rise above the ambient.
    bound: UpperBound<f32, Const<NODES>>,
    clock: StepClock,
    limits: ScalarLimits<f32>,
    max_reading_age_us: u32,
    /// Model step \[us\].
    step_us: u32,
    /// Length of a protection cycle \[us\]: `protect_period_steps` steps.
    protect_period_us: u32,
    /// The cycles' phase \[us\]: `protect_phase_steps` steps.
    protect_phase_us: u32,
    fingerprint: u32,
    /// Fingerprint of the nonlinear model the observer was built from
    /// (see [`OmniObserver::restore_after`]). The model itself is not kept:
    /// its geometry holds references, and the configuration stays plain
    /// data (all-zero bits valid, which `examples/panic_free.rs` relies on).
    plant_fingerprint: u32,
    /// The unfused shadow of the model (built-time linearisation, one
    /// correction period per step) the readings are held against.
    shadow: MeanModel<f32>,
    /// Model steps per shadow step.
    shadow_block_steps: u32,
    /// The consistency band.
    band: Band,
    /// The band's image on the heat-input biases.
    bias_bound: BiasBound<Const<SOLENOIDS>>,
    stuck_test: StuckTest,
    /// No reading for this long makes a thermocouple silent \[us\]: two
    /// correction periods.
    silent_after_us: u32,
    /// The control loop's nominal tick \[us\] ([`OmniSettings::loop_period_us`]).
    loop_period_us: u32,
    /// Slices of the start's held covariance per light tick (see
    /// [`Self::held_slices_per_tick`]).
    held_slices_per_tick: u32,
    /// The share of a protection cycle each predictor slice catches up
    /// \[us\].
    predictor_slice_us: u32,
    /// The declared model refresh's watchdog ([`InputFlags::MODEL_STALE`];
    /// none declared: never stale).
    refresh: RefreshWatchdog,
}

/// The per-device state.
///
/// `W` says whether it can run the start's warm-up (see
/// [`OmniWarmUpKind`]): [`NoWarmUp`] for the states of
/// [`OmniObserver::state`], [`OmniObserver::restore`],
/// [`OmniObserver::restore_after`] and [`OmniObserver::conservative_state`],
/// which hold no start covariance and whose ticks are compiled without the
/// warm-up's code; [`WarmUp`] (the default) for those of
/// [`OmniObserver::start`], [`OmniObserver::restore_with_readings`] and
/// [`OmniObserver::with_warm_up`], the one type of a firmware that
/// restores and falls back to a start.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone)]
#[repr(C)]
pub struct OmniObserverState<W = WarmUp<OmniHeld>> {
    // Laid out as declared (`repr(C)`), the fields every tick reads
    // first (see `NetworkObserverState`: a Cortex-M4F float load reaches
    // 1 020 bytes from its base).
    /// The time not yet simulated.
    pub clock: ClockState,
    held_currents_a: [f32; SOLENOIDS],
    held_ambient_c: f32,
    /// The energy account of the step in progress (see "Model step and
    /// ticks" in the module docs).
    step_account: StepAccount<Const<SOLENOIDS>>,
    /// Model steps since the state was made or a model was last
    /// installed (saturating), for the refresh watchdog.
    model_age_steps: u32,
    cycle: ProtectionCycle<Const<SOLENOIDS>>,
    /// Model steps handed to the next tick (see [`StepClock::defer`]).
    deferral: Deferral,
    shadow_block: BlockMean<Const<SOLENOIDS>>,
    silence: SilenceWatch<Const<THERMOCOUPLES>>,
    outputs: OmniOutputs,
    /// The filter's estimate (deviations from `model`'s origin \[K\], then
    /// the heat-input biases \[W\]) and gate memory.
    pub estimate: SteadyEstimate<f32, Const<STATES>, Const<THERMOCOUPLES>>,
    /// What each node's deviation could not hold \[K\] (the carry of
    /// [`MeanModel::predict`]).
    residual_k: [f32; NODES],
    /// The filter input of the last step (powers \[W\], ambient \[degC\], 1).
    input: SVector<f32, INPUTS>,
    /// The linear model the predict runs on (see
    /// [`OmniObserver::install_model`]).
    pub model: MeanModel<f32>,
    /// The shadow's deviations from its origin \[K\] (biases zero).
    shadow_x: SVector<f32, STATES>,
    shadow_residual_k: [f32; NODES],
    /// The predictor's sweep.
    pub predictor: PredictorState<f32, ConstSizes<NODES, 1, SOLENOIDS>, AnswersWhenAsked>,
    /// The alarm's state.
    pub alarm: AlarmState<f32, Const<6>>,
    /// Alarm events not yet drained.
    pub events: EventQueue<EVENT_CAPACITY>,
    stuck: StuckWatch<Const<THERMOCOUPLES>>,
    /// The heat-input biases when each thermocouple's reading last
    /// changed: where a stuck one's biases go back to.
    rewind: StuckRewind<Const<THERMOCOUPLES>, Const<SOLENOIDS>>,
    /// The readings held out of the gate's recovery as drifting colder
    /// than the physics.
    drift: DriftHold<Const<THERMOCOUPLES>>,
    /// The solenoids whose measurement is in doubt.
    suspect: Suspicion<Const<SOLENOIDS>>,
    /// The last tick corrected with a multi-rate model: the heat-bias
    /// check is this tick's (see [`OmniObserver::tick`]).
    bias_check_due: bool,
    /// A model re-linearised at the estimate has been installed
    /// ([`OmniObserver::install_model`]): it needs no heat bias, so a
    /// doubted solenoid's negative one is dropped.
    relinearised: bool,
    /// What the start's warm-up holds (see [`OmniObserver::start`]):
    /// nothing in the [`NoWarmUp`] flavour.
    warm: W,
}

impl<W: OmniWarmUpKind> OmniObserverState<W> {
    /// The outputs of the last tick.
    pub fn outputs(&self) -> &OmniOutputs {
        &self.outputs
    }

    /// The start's warm-up runs: the filter holds the covariance of
    /// [`OmniObserver::start`] until it settles on the steady one.
    pub fn warming_up(&self) -> bool {
        self.warm.held().is_some_and(|held| held.cov.active())
    }

    /// The start's widening of each [`ALARM_NODES`] element's bound at
    /// the last protection stage \[K\] (none without a warm-up).
    fn held_extra_k(&self) -> &[f32; ALARM_NODES.len()] {
        self.warm.held().map_or(&NO_EXTRA_K, |held| &held.extra_k)
    }

    /// This state in the flavour `V`, holding `warm`.
    fn flavoured<V>(self, warm: V) -> OmniObserverState<V> {
        // Field by field: `..self` cannot change a type parameter on
        // stable Rust (type-changing struct update is unstable).
        OmniObserverState {
            estimate: self.estimate,
            model: self.model,
            input: self.input,
            alarm: self.alarm,
            predictor: self.predictor,
            clock: self.clock,
            events: self.events,
            held_currents_a: self.held_currents_a,
            held_ambient_c: self.held_ambient_c,
            cycle: self.cycle,
            residual_k: self.residual_k,
            shadow_x: self.shadow_x,
            shadow_residual_k: self.shadow_residual_k,
            stuck: self.stuck,
            rewind: self.rewind,
            drift: self.drift,
            silence: self.silence,
            shadow_block: self.shadow_block,
            suspect: self.suspect,
            outputs: self.outputs,
            step_account: self.step_account,
            bias_check_due: self.bias_check_due,
            deferral: self.deferral,
            relinearised: self.relinearised,
            model_age_steps: self.model_age_steps,
            warm,
        }
    }

    /// What the shutdown latch touches (its rules are every observer's).
    fn latch(&mut self) -> Latch<'_, f32, Const<{ ALARM_NODES.len() }>, EVENT_CAPACITY> {
        Latch {
            alarm: &mut self.alarm,
            events: &mut self.events,
            published: &mut self.outputs.alarm,
            limits: &mut self.outputs.limits,
        }
    }
}

impl OmniObserver {
    /// Linearises `model` at `op_temps_c` and `ambient_c` \[degC\], builds the
    /// filter (solving the steady gain: tens of KiB of stack in `f64`), the
    /// predictor and the protection.
    ///
    /// # Errors
    /// Those of the linearisation, the filter, the gain solver, the
    /// predictor, the alarm, the limiter and the clock, naming the parameter;
    /// `filter.mode` or `filter.warmup_corrections` asking for the
    /// time-varying filter.
    pub fn new(
        model: &Omnimagnet,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        settings: &OmniSettings,
    ) -> Result<Self, BuildError> {
        let clock = StepClock::new(settings.step_us, settings.max_steps_per_tick)?
            .with_frozen_limits(settings.frozen_flag_ticks, settings.frozen_loss_ticks)?;
        let dt_s = clock.step_s();
        let period = settings.protect_period_steps;
        let slices = settings.predictor_slices_per_cycle;
        // A cycle takes at most two ticks per slice (one put off) and the
        // alarm's and the limiter's: it ends before the next is due.
        let cycle_ticks = slices.saturating_mul(2).saturating_add(2);
        let protect_period_us = period.checked_mul(settings.step_us);
        let Some(protect_period_us) = protect_period_us.filter(|us| {
            slices >= 1
                && us % slices == 0
                && period >= cycle_ticks.saturating_mul(settings.max_steps_per_tick)
        }) else {
            return Err(BuildError::InvalidParameter {
                name: "protect_period_steps",
            });
        };
        if settings.protect_phase_steps >= period {
            return Err(BuildError::InvalidParameter {
                name: "protect_phase_steps",
            });
        }
        // Below the period, so no overflow.
        let protect_phase_us = settings.protect_phase_steps * settings.step_us;
        if settings.filter.mode != GainMode::SteadyState {
            return Err(BuildError::InvalidParameter {
                name: "filter.mode",
            });
        }
        if settings.filter.warmup_corrections != 0 {
            return Err(BuildError::InvalidParameter {
                name: "filter.warmup_corrections",
            });
        }
        settings.checks.validate()?;
        let filter = Self::build_filter(model, op_temps_c, ambient_c, dt_s, &settings.filter)?;
        let rule = DeratingRule::omnimagnet();
        let (w, c) = (WIRE_INSULATION_LIMIT_C, COVER_INSULATION_LIMIT_C);
        let alarm = AlarmBuilder::new(&rule, [w, c, w, c, w, c]).build::<f32>()?;
        let limiter = LimiterConfig::new(
            [settings.hardware_limit_a; SOLENOIDS],
            settings.taper_k,
            0.0,
        )?;
        if settings.predictor_nodes_per_slice == 0 {
            return Err(BuildError::InvalidParameter {
                name: "predictor_nodes_per_slice",
            });
        }
        let predictor = Self::predictor(
            model,
            op_temps_c,
            ambient_c,
            dt_s * f64::from(period) / f64::from(slices),
            settings.predictor_nodes_per_slice,
        )?;
        let bound = Self::build_bound(&filter, settings)?;
        let refresh = RefreshWatchdog::new(settings.model_refresh_s, settings.step_us)?;
        check_refresh(
            &settings.filter.sensors,
            refresh.bound_steps(),
            settings.step_us,
        )?;
        let fingerprint =
            Self::fingerprint_of(&filter, settings, &alarm, &limiter, &bound, &refresh);
        let shadow_block_steps = filter.period().max(1);
        let shadow = Self::build_shadow(
            model,
            op_temps_c,
            ambient_c,
            dt_s * f64::from(shadow_block_steps),
        )?;
        let band = settings.checks.band();
        let (phi_minus_i, bd_power) = shadow.power_response();
        let bias_bound = BiasBound::new(&band, &phi_minus_i, &bd_power);
        Ok(Self {
            filter,
            alarm,
            limiter,
            predictor,
            bound,
            clock,
            limits: InputLimits::default().to_scalar(),
            max_reading_age_us: settings.max_reading_age_us,
            step_us: settings.step_us,
            protect_period_us,
            protect_phase_us,
            fingerprint,
            plant_fingerprint: plant_fingerprint(model),
            shadow,
            shadow_block_steps,
            band,
            bias_bound,
            stuck_test: settings
                .checks
                .stuck_test(settings.filter.correction_period_s),
            silent_after_us: shadow_block_steps
                .saturating_mul(settings.step_us)
                .saturating_mul(2),
            loop_period_us: settings.loop_period_us,
            held_slices_per_tick: Self::held_slices_per_tick(
                settings.step_us,
                settings.loop_period_us,
                shadow_block_steps,
                protect_period_us,
                slices,
            ),
            predictor_slice_us: protect_period_us / slices,
            refresh,
        })
    }

    /// Slices of the start's held covariance per light tick: enough that a
    /// correction period's propagation fits in half the light ticks the
    /// declared loop leaves a period ([`start`]'s "A covariance per
    /// correction period, in slices"). A period's ticks less its
    /// correction, its protection stages (each cycle's predictor slices,
    /// the alarm and the limiter) and, for a model step longer than the
    /// loop's tick, the ticks that step. One at a 1 ms loop (the flashed
    /// 5 ms configuration leaves about 380 light ticks a period), a whole
    /// period's 58 at a loop of the model's 100 ms step.
    /// `step_us`, `loop_period_us` \[us\], `period_steps` model steps a
    /// correction period, `protect_period_us` \[us\] and
    /// `predictor_slices` per protection cycle.
    pub(crate) const fn held_slices_per_tick(
        step_us: u32,
        loop_period_us: u32,
        period_steps: u32,
        protect_period_us: u32,
        predictor_slices: u32,
    ) -> u32 {
        let period_us = period_steps.saturating_mul(step_us);
        let ticks = match period_us.checked_div(loop_period_us) {
            Some(ticks) => ticks,
            None => 0,
        };
        let cycles = if protect_period_us == 0 {
            period_us
        } else {
            period_us.div_ceil(protect_period_us)
        };
        let stages = cycles.saturating_mul(predictor_slices.saturating_add(2));
        let stepping = if step_us > loop_period_us {
            period_steps
        } else {
            0
        };
        let light = ticks
            .saturating_sub(1)
            .saturating_sub(stages)
            .saturating_sub(stepping);
        start::slices_per_tick(start::period_slices(STATES, NODES), light)
    }

    #[inline(never)]
    fn build_shadow(
        model: &Omnimagnet,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        block_s: f64,
    ) -> Result<MeanModel<f32>, BuildError> {
        Ok(MeanModel::new(
            &model.linearize(op_temps_c, ambient_c, block_s)?,
        ))
    }

    // The build steps run in frames of their own (`inline(never)`): on an
    // MCU their matrix temporaries would otherwise add up in one frame.
    #[inline(never)]
    fn predictor(
        model: &Omnimagnet,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        slice_s: f64,
        nodes_per_slice: u32,
    ) -> Result<LimitPredictor<f32, NODES, 1, SOLENOIDS, PREDICTOR_POINTS>, BuildError> {
        PredictorBuilder::new()
            .tick_s(slice_s)
            .elements_per_tick(usize::try_from(nodes_per_slice).unwrap_or(usize::MAX))
            .build(&model.network(op_temps_c, ambient_c)?)
    }

    #[inline(never)]
    fn build_filter(
        model: &Omnimagnet,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        dt_s: f64,
        settings: &ObserverSettings,
    ) -> Result<ObserverConfig<f32>, BuildError> {
        let lin = model.linearize(op_temps_c, ambient_c, dt_s)?;
        ObserverConfig::new(model, &lin, settings)
    }

    /// The protective upper bound: `k_sigma` times each node's standard
    /// deviation in the steady-state prior (just before a correction, the
    /// largest of the cycle; constant with the steady gain), and the
    /// unmeasured margin on every node no thermocouple in use measures.
    #[inline(never)]
    fn build_bound(
        filter: &ObserverConfig<f32>,
        settings: &OmniSettings,
    ) -> Result<UpperBound<f32, Const<NODES>>, BuildError> {
        let prior = filter.gain().prior();
        let sigma_k: [f64; NODES] =
            core::array::from_fn(|i| libm::sqrt(f64::from(prior[(i, i)]).max(0.0)));
        for node in ALARM_NODES {
            let sigma = sigma_k.get(node).copied().unwrap_or(f64::INFINITY);
            settings.checks.observable(node, true, sigma)?;
        }
        let mut margins = [settings.unmeasured_margin; NODES];
        let used = filter.settings().sensors.iter();
        for (node, used) in THERMOCOUPLE_NODES.iter().zip(used) {
            if let (true, Some(margin)) = (*used, margins.get_mut(*node)) {
                *margin = UncertaintyMargin::ZERO;
            }
        }
        UpperBoundBuilder::per_element(margins)
            .sigma(settings.k_sigma, sigma_k)
            .build()
    }

    /// Each node's protective upper bound (see [`OmniSettings::k_sigma`]
    /// and [`OmniSettings::unmeasured_margin`]).
    pub fn upper_bound(&self) -> &UpperBound<f32, Const<NODES>> {
        &self.bound
    }

    /// Model steps without an [`Self::install_model`] after which the
    /// declared model refresh is stale ([`InputFlags::MODEL_STALE`]):
    /// [`MODEL_STALE_PERIODS`] times [`OmniSettings::model_refresh_s`],
    /// rounded up to whole steps; `None` when no refresh is declared.
    pub fn model_stale_after_steps(&self) -> Option<u32> {
        self.refresh.declared_steps()
    }

    /// What a snapshot must have been made with: the filter's matrices and
    /// gain, and the whole protection: the protection period, the alarm
    /// (critical temperatures, derating, margins, debounce), the limiter
    /// (hardware limit, taper, floor) and every node's upper bound
    /// (`k_sigma` and the model-uncertainty margin), and a declared model
    /// refresh's watchdog (folded in only when declared, so a configuration
    /// without one keeps its fingerprint). The mean temperatures a
    /// snapshot holds do not depend on the protection, but its latch was
    /// judged against it: a snapshot from another protection is refused.
    #[inline(never)]
    fn fingerprint_of(
        filter: &ObserverConfig<f32>,
        settings: &OmniSettings,
        alarm: &AlarmConfig<f32, Const<6>>,
        limiter: &LimiterConfig<f32, Const<SOLENOIDS>>,
        bound: &UpperBound<f32, Const<NODES>>,
        refresh: &RefreshWatchdog,
    ) -> u32 {
        let kalman = filter.kalman();
        let widen = |m: &[f32], f: Fingerprint| m.iter().fold(f, |f, v| f.f64(f64::from(*v)));
        let mut fingerprint = Fingerprint::new()
            .u32(settings.step_us)
            .u32(filter.period());
        fingerprint = widen(kalman.f().as_slice(), fingerprint);
        fingerprint = widen(kalman.g().as_slice(), fingerprint);
        fingerprint = widen(kalman.q().as_slice(), fingerprint);
        fingerprint = widen(kalman.r().as_slice(), fingerprint);
        fingerprint = widen(filter.gain().gain().as_slice(), fingerprint);
        fingerprint = fingerprint
            .f64s(&[settings.hardware_limit_a, settings.taper_k])
            .u32(settings.protect_period_steps);
        let fingerprint = alarm.fingerprint(fingerprint);
        let fingerprint = limiter.fingerprint(fingerprint);
        let mut fingerprint = bound.fingerprint(fingerprint);
        if let Some(steps) = refresh.declared_steps() {
            fingerprint = fingerprint.u32(steps);
        }
        fingerprint.finish()
    }

    /// The configuration fingerprint that snapshots carry.
    pub fn fingerprint(&self) -> u32 {
        self.fingerprint
    }

    /// The filter configuration (measurement model, gate, steady gain, the
    /// build-time model).
    pub fn filter(&self) -> &ObserverConfig<f32> {
        &self.filter
    }

    /// The model step \[s\].
    pub fn step_s(&self) -> f64 {
        self.clock.step_s()
    }

    /// The alarm configuration of the [`ALARM_NODES`] elements (their
    /// limits at an ambient).
    pub fn alarm(&self) -> &AlarmConfig<f32, Const<6>> {
        &self.alarm
    }

    /// A state with every node at `temps_c` \[degC\], the build-time model,
    /// zero heat-input biases, the ambient at `ambient_c` \[degC\], no
    /// current, no alarm.
    ///
    /// It runs no warm-up ([`NoWarmUp`]): it holds no start covariance, and
    /// a firmware that ticks only such states links none of the warm-up's
    /// code. [`Self::with_warm_up`] gives it the flavour of
    /// [`Self::start`]'s states.
    pub fn state(&self, temps_c: &[f32; NODES], ambient_c: f32) -> OmniObserverState<NoWarmUp> {
        self.state_holding(temps_c, ambient_c, NoWarmUp)
    }

    /// [`Self::state`] in the flavour `W`, holding `warm` (made in place:
    /// a start's state is not moved from one flavour to the other).
    fn state_holding<W: OmniWarmUpKind>(
        &self,
        temps_c: &[f32; NODES],
        ambient_c: f32,
        warm: W,
    ) -> OmniObserverState<W> {
        let model = *self.filter.model();
        let mut x = SVector::<f32, STATES>::zeros();
        for (i, t) in temps_c.iter().enumerate() {
            x[i] = *t - model.origin_c()[i];
        }
        let mut input = SVector::<f32, INPUTS>::zeros();
        input[SOLENOIDS] = ambient_c;
        input[INPUTS - 1] = 1.0;
        let op = self.operating(
            temps_c,
            &[0.0; SOLENOIDS],
            ambient_c,
            &[0.0; ALARM_NODES.len()],
        );
        let mut state = OmniObserverState {
            estimate: SteadyEstimate::new(x),
            model,
            input,
            alarm: AlarmState::new(&self.alarm),
            predictor: PredictorState::when_asked(&self.predictor, &op),
            clock: ClockState::default(),
            events: EventQueue::new(),
            held_currents_a: [0.0; SOLENOIDS],
            held_ambient_c: ambient_c,
            // The first ticks run a whole cycle: outputs valid from the start.
            cycle: ProtectionCycle::new(Const::<SOLENOIDS>)
                .with_phase(self.protect_phase_us)
                .with_slices(self.protect_period_us / self.predictor_slice_us.max(1)),
            shadow_x: SVector::from_fn(|i, _| {
                temps_c
                    .get(i)
                    .map_or(0.0, |t| t - self.shadow.origin_c()[i])
            }),
            shadow_block: BlockMean::new(Const::<SOLENOIDS>),
            residual_k: [0.0; NODES],
            shadow_residual_k: [0.0; NODES],
            stuck: StuckWatch::new(Const),
            rewind: StuckRewind::new(Const, Const),
            drift: DriftHold::new(Const),
            silence: SilenceWatch::new(Const),
            suspect: Suspicion::new(Const),
            outputs: OmniOutputs {
                temps_c: *temps_c,
                upper_c: *temps_c,
                limits: [CoilLimit::default(); SOLENOIDS],
                time_to_limit_s: [None; ALARM_NODES.len()],
                alarm: AlarmStatus::default(),
                sensors: [SensorStatus::NoReading; THERMOCOUPLES],
                corrected: false,
                flags: InputFlags::NONE,
                steps: 0,
                dropped_us: 0,
                tick: 0,
            },
            step_account: StepAccount::new(Const::<SOLENOIDS>),
            bias_check_due: false,
            deferral: Deferral::default(),
            relinearised: false,
            model_age_steps: 0,
            warm,
        };
        // Limits valid from the first tick: without this the first ticks
        // (until the cycle reaches the limiter) would clamp every command to
        // the default zero-current limit.
        self.limit(&mut state.outputs, ambient_c);
        state
    }

    /// `state` in the flavour that can run the start's warm-up
    /// ([`WarmUp`], the type [`Self::start`] returns), holding nothing yet:
    /// it ticks as it would have, to the bit. For a firmware that keeps
    /// one state type for a restore and its fallback, a start.
    pub fn with_warm_up(&self, state: OmniObserverState<NoWarmUp>) -> OmniObserverState {
        state.flavoured(WarmUp {
            held: OmniHeld::idle(),
        })
    }

    /// The estimated temperature of every element \[degC\] now (the
    /// outputs carry the same after each tick).
    pub fn temps_c<W: OmniWarmUpKind>(&self, state: &OmniObserverState<W>) -> [f32; NODES] {
        let origin = state.model.origin_c();
        core::array::from_fn(|i| origin[i] + state.estimate.x[i])
    }

    /// The estimated heat-input bias of each solenoid \[W\]: what the
    /// model misses in its heat balance.
    pub fn heat_bias_w<W: OmniWarmUpKind>(&self, state: &OmniObserverState<W>) -> [f32; SOLENOIDS] {
        core::array::from_fn(|m| state.estimate.x[NODES + m])
    }

    /// Turns a linearisation made off the tick (a
    /// [`Relinearizer`](crate::omnimagnet::Relinearizer) in a lower-priority
    /// task) into a model for [`Self::install_model`]. `O(N^3)` in `f64`:
    /// not for the tick.
    ///
    /// # Errors
    /// [`BuildError::InvalidTimeStep`] when `lin` is not for this
    /// observer's step; [`BuildError::InvalidParameter`] (`"model"`) for a
    /// model with a non-finite entry.
    pub fn prepare_model(&self, lin: &Linearization) -> Result<MeanModel<f32>, BuildError> {
        let model = MeanModel::<f32>::new(lin);
        self.check_model(&model)?;
        Ok(model)
    }

    fn check_model(&self, model: &MeanModel<f32>) -> Result<(), BuildError> {
        if model.dt_s() != self.clock.step_s() {
            return Err(BuildError::InvalidTimeStep);
        }
        if !model.is_finite() {
            return Err(BuildError::InvalidParameter { name: "model" });
        }
        Ok(())
    }

    /// Makes `model` the one `state` predicts with, between two ticks:
    /// the estimate is re-based on the new origin (the temperatures do not
    /// move), the biases and the gate memory are kept. `O(N)`, bounded,
    /// allocation-free, panic-free (about 1.4 KiB copied).
    ///
    /// # Errors
    /// As [`Self::prepare_model`]; nothing changes then.
    pub fn install_model<W: OmniWarmUpKind>(
        &self,
        state: &mut OmniObserverState<W>,
        model: &MeanModel<f32>,
    ) -> Result<(), BuildError> {
        self.check_model(model)?;
        state.model.rebase(&mut state.estimate.x, model);
        state.model = *model;
        state.relinearised = true;
        // The refresh the watchdog waits for.
        state.model_age_steps = 0;
        Ok(())
    }

    fn operating(
        &self,
        temps_c: &[f32; NODES],
        currents_a: &[f32; SOLENOIDS],
        ambient_c: f32,
        held_extra_k: &[f32; ALARM_NODES.len()],
    ) -> Operating<f32, NODES, 1, SOLENOIDS> {
        let alarm_limits = self.alarm.alarm_limits_c(ambient_c);
        let mut limits_c = [f32::INFINITY; NODES];
        for node in self.filter.solenoid_nodes() {
            if let Some(slot) = limits_c.get_mut(*node) {
                *slot = NO_LIMIT_C;
            }
        }
        for ((node, limit), extra_k) in ALARM_NODES.iter().zip(alarm_limits).zip(held_extra_k) {
            // The predictor follows the mean: it is asked when the mean
            // reaches the temperature at which the upper bound reaches the
            // limit (the start's widened bound while it is held).
            if let (Some(slot), Some(bound)) = (limits_c.get_mut(*node), self.bound.element(*node))
            {
                *slot = bound.mean_limit_c(limit - extra_k, ambient_c);
            }
        }
        Operating {
            temps_c: *temps_c,
            currents_a: *currents_a,
            boundary_c: [ambient_c],
            limits_c,
        }
    }

    /// One controller tick: model steps from the elapsed time (each a filter
    /// predict), a correction if readings arrived, then at most one stage of
    /// the protection cycle (see the module docs). Bounded
    /// (`max_steps_per_tick` steps, one correction, one stage),
    /// allocation-free, panic-free.
    pub fn tick<'s, W: OmniWarmUpKind>(
        &self,
        state: &'s mut OmniObserverState<W>,
        inputs: &OmniInputs,
    ) -> &'s OmniOutputs {
        let debt_before_us = state.clock.debt_us;
        let steps = self.clock.advance_around_readings(
            &mut state.clock,
            &mut state.deferral,
            inputs.elapsed_us,
            self.step_us > self.loop_period_us && inputs.readings.iter().any(Option::is_some),
        );
        if steps.clock_lost {
            // The model stands still: latched until the deliberate clear.
            state.latch().clock_lost();
        }
        let mut flags = steps.flags;
        // The refresh watchdog: one add and one compare per tick.
        if self.refresh.aged(&mut state.model_age_steps, steps.steps) {
            flags |= InputFlags::MODEL_STALE;
        }
        let moved =
            state
                .step_account
                .moves(debt_before_us, &inputs.currents_a, &state.held_currents_a);
        flags |= self
            .limits
            .accept_currents(&inputs.currents_a, &mut state.held_currents_a);
        flags |= self
            .limits
            .accept_temperature(inputs.ambient_c, &mut state.held_ambient_c);
        let mean_sq_a2 = state.step_account.account(
            &state.held_currents_a,
            moved,
            debt_before_us,
            state.clock.debt_us,
            inputs.elapsed_us,
            &steps,
            self.step_us,
        );
        for _ in 0..steps.steps {
            // The held inputs are finite, so the input is always renewed.
            match &mean_sq_a2 {
                None => self.filter.joule_input(
                    &state.model,
                    &state.estimate.x,
                    &state.held_currents_a,
                    state.held_ambient_c,
                    &mut state.input,
                ),
                Some(mean_sq_a2) => self.filter.joule_input_mean_sq(
                    &state.model,
                    &state.estimate.x,
                    mean_sq_a2,
                    state.held_ambient_c,
                    &mut state.input,
                ),
            };
            state
                .model
                .predict(&mut state.estimate.x, &state.input, &mut state.residual_k);
        }
        state.cycle.stepped(
            &steps,
            self.step_us,
            inputs.elapsed_us,
            &state.held_currents_a,
        );
        // The shadow's blocks take each step's mean `I^2`.
        let block_sq_a2 = (steps.steps > 0)
            .then(|| step_square_currents::<Const<SOLENOIDS>>(mean_sq_a2, &state.held_currents_a))
            .and_then(|step_sq_a2| {
                state
                    .shadow_block
                    .add(steps.steps, &step_sq_a2, self.shadow_block_steps)
            })
            .map(|block| block.mean_sq_a2());
        if let Some(block_sq_a2) = block_sq_a2 {
            let mut u = SVector::<f32, INPUTS>::zeros();
            self.filter.joule_input_mean_sq(
                &self.shadow,
                &state.shadow_x,
                &block_sq_a2,
                state.held_ambient_c,
                &mut u,
            );
            self.shadow
                .predict(&mut state.shadow_x, &u, &mut state.shadow_residual_k);
        }
        if core::mem::take(&mut state.bias_check_due) {
            flags |= self.check_heat_bias(state);
        }
        let (corrected, disagree) = self.correct(state, inputs);
        flags |= disagree;
        // Only a step or a reading (a correction, a common-mode pull)
        // moves the estimate.
        if steps.steps > 0 || inputs.readings.iter().any(Option::is_some) {
            state.outputs.temps_c = self.temps_c(state);
        }
        state.outputs.corrected = corrected;

        // A catch-up, or a step longer than the loop's tick.
        let busy = corrected || steps.steps.saturating_mul(self.step_us) > self.loop_period_us;
        let stage = Protecting {
            observer: self,
            state: &mut *state,
        }
        .run_due(
            busy,
            false,
            self.protect_period_us,
            steps.steps > 0 || steps.dropped_us > 0,
        );
        if state.warming_up() {
            // The start's covariance: slices on a light tick (no
            // correction, no protection stage, no step longer than the
            // loop's tick unless the tick lasted as long: a loop slower
            // than declared is never starved of its slices).
            let owed_us = steps.steps.saturating_mul(self.step_us);
            let lasted = steps.steps <= 1 && owed_us <= inputs.elapsed_us;
            let light = stage == Stage::Idle && !corrected && (!busy || lasted);
            if let Some(held) = state.warm.held_mut() {
                self.hold_start(&mut held.cov, steps.steps, light, inputs.elapsed_us);
            }
        }
        state.outputs.finish_tick(flags, &steps);
        &state.outputs
    }

    /// The predictor's answers for the [`ALARM_NODES`], made older by the
    /// time it lags behind (never later than its own answer).
    fn age_time_to_limit<W: OmniWarmUpKind>(&self, state: &mut OmniObserverState<W>) {
        let lag_s = state.cycle.lag_s();
        let predictor = &state.predictor;
        for (time, node) in state.outputs.time_to_limit_s.iter_mut().zip(ALARM_NODES) {
            *time = aged_time_to_limit(predictor.time_to_limit_of(node), lag_s);
        }
    }

    /// Publishes every node's upper bound: of the estimate, and while a
    /// solenoid's measurement is in doubt or the declared model refresh is
    /// stale, on every alarm element of the hotter of the estimate and the
    /// shadow (see [`Suspicion`]): the solenoids exchange heat, so what a
    /// lying sensor dragged on one is felt by the model of the others; and
    /// a placement that needs the refresh cannot be trusted on a model the
    /// refresh no longer follows.
    fn publish_upper<W: OmniWarmUpKind>(&self, state: &mut OmniObserverState<W>) {
        let stale = self.refresh.stale(state.model_age_steps);
        let amb = state.held_ambient_c;
        let out = &mut state.outputs;
        self.bound.upper_c(&out.temps_c, amb, &mut out.upper_c);
        match state.warm.held_mut() {
            // The covariance held, not the steady one (see `super::start`).
            Some(held) if held.cov.active() => {
                self.widen_held(&held.cov, &mut out.upper_c, &mut held.extra_k, amb);
            }
            Some(held) => held.extra_k = NO_EXTRA_K,
            None => {}
        }
        if !state.suspect.any() && !stale {
            return;
        }
        let origin = self.shadow.origin_c();
        let shadow_c: [f32; NODES] = core::array::from_fn(|i| origin[i] + state.shadow_x[i]);
        protect_on_shadow(
            &self.bound,
            &shadow_c,
            amb,
            &mut out.upper_c,
            ALARM_NODES.into_iter(),
        );
    }

    /// Widens the steady bounds `upper_c` \[degC\] by the start's held
    /// covariance (see [`start::capped_extra_k`]): on each wire and cover
    /// insulation no higher than [`start::START_BELOW_LIMIT_K`] below its
    /// alarm limit at the ambient `ambient_c` \[degC\] (those widenings
    /// kept in `alarm_extra_k` \[K\] for the predictor).
    fn widen_held(
        &self,
        held: &StartCovariance,
        upper_c: &mut [f32; NODES],
        alarm_extra_k: &mut [f32; ALARM_NODES.len()],
        ambient_c: f32,
    ) {
        let steady_c = *upper_c;
        for (i, upper) in upper_c.iter_mut().enumerate() {
            *upper += held.bound_extra_k(i);
        }
        let limits_c = self.alarm.alarm_limits_c(ambient_c);
        for ((node, limit), slot) in ALARM_NODES.iter().zip(limits_c).zip(alarm_extra_k) {
            if let (Some(upper), Some(steady)) = (upper_c.get_mut(*node), steady_c.get(*node)) {
                let extra_k = start::capped_extra_k(held.bound_extra_k(*node), *steady, limit);
                *upper = steady + extra_k;
                *slot = extra_k;
            }
        }
    }

    /// Which solenoids lost their measurement this tick: a thermocouple in
    /// use on it was refused or failed (a fault, too old, colder than the
    /// physics, stuck, silent, rejected by the gate twice in a row) and
    /// none of its thermocouples was fused. A single gate rejection is no
    /// doubt: the gate refusing a spike is the gate at work, and the sensor
    /// is fused again at its next reading.
    fn suspect_solenoids(
        &self,
        statuses: &[SensorStatus; THERMOCOUPLES],
        rejections: &[u16; THERMOCOUPLES],
    ) -> [bool; SOLENOIDS] {
        let mut doubt = [false; SOLENOIDS];
        let mut fused = [false; SOLENOIDS];
        let fitted = self.filter.settings().sensors;
        // `THERMOCOUPLE_NODES` are the solenoid nodes 0..3: the node is the
        // solenoid's index.
        let sensors = statuses.iter().zip(rejections).zip(fitted);
        for (((status, rejections), fitted), m) in sensors.zip(THERMOCOUPLE_NODES) {
            let (true, Some(doubt), Some(fused)) = (fitted, doubt.get_mut(m), fused.get_mut(m))
            else {
                continue;
            };
            match sensor_doubt(status, *rejections) {
                Some(false) => *fused = true,
                Some(true) => *doubt = true,
                None => {}
            }
        }
        core::array::from_fn(|m| doubt[m] && !fused[m])
    }

    /// The limiter on the three solenoids at the published upper bounds.
    fn limit(&self, out: &mut OmniOutputs, ambient_c: f32) {
        let temps = alarm_temps(&out.upper_c);
        let limits_c = self.alarm.alarm_limits_c(ambient_c);
        let mut solenoid_c = [f32::NAN; SOLENOIDS];
        let mut solenoid_limit_c = [f32::NAN; SOLENOIDS];
        for (m, (t, l)) in solenoid_c
            .iter_mut()
            .zip(solenoid_limit_c.iter_mut())
            .enumerate()
        {
            let (Some(wire), Some(cover), Some(lw), Some(lc)) = (
                temps.get(2 * m),
                temps.get(2 * m + 1),
                limits_c.get(2 * m),
                limits_c.get(2 * m + 1),
            ) else {
                continue;
            };
            let (hw, hc) = (lw - wire, lc - cover);
            // NaN must reach the limiter (which then gives the floor), so no
            // `min`, which would let it lose.
            let headroom = if hw.is_finite() && hc.is_finite() {
                // A comparison: `f32::min` is a call to `fminf` without
                // VMAXNM.
                if hc < hw {
                    hc
                } else {
                    hw
                }
            } else {
                f32::NAN
            };
            *t = lc - headroom;
            *l = *lc;
        }
        self.limiter
            .apply(&solenoid_c, &solenoid_limit_c, ambient_c, &mut out.limits);
    }

    /// Sorts the readings, holds each against the shadow model (see the
    /// network observer's "Sensors against the physics"), and runs one
    /// steady-state correction if any is usable; returns whether it ran and
    /// the common-mode flag.
    fn correct<W: OmniWarmUpKind>(
        &self,
        state: &mut OmniObserverState<W>,
        inputs: &OmniInputs,
    ) -> (bool, InputFlags) {
        if inputs.readings.iter().all(Option::is_none) {
            // Most ticks: nothing to sort, screen or fuse; only the silence
            // watch runs (the same statuses as the full path below).
            let fitted = self.filter.settings().sensors;
            state.outputs.sensors = [SensorStatus::NoReading; THERMOCOUPLES];
            state.silence.watch(
                &fitted.map(|f| !f),
                inputs.now_us,
                self.silent_after_us,
                &mut state.outputs.sensors,
            );
            return (false, InputFlags::NONE);
        }
        self.fuse_readings(state, inputs)
    }

    /// The correction of a tick that brought readings. Out of line: it is
    /// large (screens, gate, gain, doubt), and when the compiler inlined
    /// it, or gave the whole of [`Self::correct`] its frame, every tick
    /// without a reading paid for its prologue (about 150 instructions
    /// in `observer_m4`).
    #[inline(never)]
    fn fuse_readings<W: OmniWarmUpKind>(
        &self,
        state: &mut OmniObserverState<W>,
        inputs: &OmniInputs,
    ) -> (bool, InputFlags) {
        let fitted = self.filter.settings().sensors;
        let mut samples = sample_readings::<Const<THERMOCOUPLES>>(
            &inputs.readings,
            inputs.now_us,
            self.max_reading_age_us,
            &mut state.outputs.sensors,
        );
        // Only the fitted thermocouples count (an unfitted one is never
        // heard, so the silence watch hears it always).
        state.silence.watch(
            &core::array::from_fn(|j| inputs.readings[j].is_some() || !fitted[j]),
            inputs.now_us,
            self.silent_after_us,
            &mut state.outputs.sensors,
        );
        for (sample, fitted) in samples.iter_mut().zip(fitted) {
            if !fitted {
                *sample = None;
            }
        }
        let shadow_origin = self.shadow.origin_c();
        let shadow_c = THERMOCOUPLE_NODES.map(|n| shadow_origin[n] + state.shadow_x[n]);
        let (mut common_mode, stuck_events) = screen_readings(
            &self.band,
            &self.stuck_test,
            &mut state.stuck,
            &mut samples,
            &mut state.outputs.sensors,
            &shadow_c,
            state.held_ambient_c,
        );
        // What a thermocouple taught the biases before it was found stuck
        // goes back (the network observer's rule).
        state.rewind.rewind(
            &mut state.estimate.x,
            self.filter.gain().posterior(),
            NODES,
            &stuck_events,
            &[false; SOLENOIDS],
            |_, _| {},
        );
        // A reading the gate keeps refusing as colder than the estimate
        // and the physics is held out of its recovery (the network
        // observer's rule; see `DriftHold`); none left to fuse is a
        // common-mode fault.
        common_mode |= self.hold_drifting(state, &mut samples, &shadow_c);
        let mut flags = InputFlags::NONE;
        if common_mode {
            // A common-mode fault: what the sensors dragged comes back.
            flags = InputFlags::SENSORS_COLDER_THAN_PHYSICS;
            let origin = *state.model.origin_c();
            let x = &mut state.estimate.x;
            for i in 0..NODES {
                let shadow = shadow_origin[i] + state.shadow_x[i];
                if origin[i] + x[i] < shadow {
                    x[i] = shadow - origin[i];
                    state.residual_k[i] = 0.0;
                }
            }
            for m in 0..SOLENOIDS {
                x[NODES + m] = x[NODES + m].max(0.0);
            }
        }
        let samples = samples.map(|t| t.map(Ok));
        let z = self.filter.deviations(&state.model, &samples);
        if z.iter().all(Option::is_none) {
            let suspect = self.suspect_solenoids(
                &state.outputs.sensors,
                &state.estimate.gate.consecutive_rejections,
            );
            if suspect.contains(&true) {
                state.suspect.note(&suspect);
                self.drop_cold_biases(state, &suspect);
            }
            return (false, flags);
        }
        let report = if state.warming_up() {
            self.correct_held(state, &z)
        } else {
            update_steady(
                self.filter.kalman(),
                self.filter.gain(),
                &mut state.estimate,
                &z,
            )
        };
        record_verdicts::<Const<THERMOCOUPLES>>(
            &mut state.outputs.sensors,
            &report.verdicts,
            &z.map(|z| z.is_some()),
        );
        let suspect = self.suspect_solenoids(
            &state.outputs.sensors,
            &state.estimate.gate.consecutive_rejections,
        );
        if self.step_us > self.loop_period_us {
            // Multi-rate: the check waits for the next tick, which the
            // correction's deferred step makes light.
            state.bias_check_due = true;
        } else {
            flags |= self.check_heat_bias(state);
        }
        state.suspect.note(&suspect);
        self.drop_cold_biases(state, &suspect);
        (true, flags)
    }

    /// [`DriftHold::screen`] on a correction's `samples` (the shadow at
    /// each thermocouple `shadow_c` \[degC\]), with the gate's view of each
    /// thermocouple: the estimate at its node and its innovation variance
    /// (the warm-up's while it runs, as its correction gates with; else
    /// the steady gain's). Returns whether a reading was held and none is
    /// left to fuse ([`DriftHold::screen`]).
    fn hold_drifting<W: OmniWarmUpKind>(
        &self,
        state: &mut OmniObserverState<W>,
        samples: &mut [Option<f32>; THERMOCOUPLES],
        shadow_c: &[f32; THERMOCOUPLES],
    ) -> bool {
        let OmniObserverState {
            drift,
            outputs,
            estimate,
            model,
            warm,
            ..
        } = state;
        let origin = model.origin_c();
        let steady = self.filter.gain().innovation_var();
        drift.screen(
            samples,
            &mut outputs.sensors,
            shadow_c,
            &estimate.gate.consecutive_rejections,
            self.filter.kalman().gate(),
            &self.stuck_test,
            |j| {
                let node = THERMOCOUPLE_NODES[j];
                let innovation_var_k2 = match warm.held_mut() {
                    // Made here for the correction that follows.
                    Some(held) if held.cov.active() => held.cov.correction().1[j],
                    _ => steady[j],
                };
                GateView {
                    estimate_c: origin[node] + estimate.x[node],
                    innovation_var_k2,
                }
            },
        )
    }

    /// The heat-input biases against the band's image at the last step's
    /// Joule powers (at the estimate): [`InputFlags::HEAT_BIAS_BEYOND_MODEL`]
    /// when one is beyond it.
    fn check_heat_bias<W: OmniWarmUpKind>(&self, state: &OmniObserverState<W>) -> InputFlags {
        let powers_w = core::array::from_fn(|m| state.input[m]);
        let biases_w = state.estimate.x.as_slice().get(NODES..).unwrap_or_default();
        if self.bias_bound.beyond(biases_w, &powers_w).contains(&true) {
            InputFlags::HEAT_BIAS_BEYOND_MODEL
        } else {
            InputFlags::NONE
        }
    }

    /// [`drop_cold_biases`] on the solenoids in doubt, once the model is
    /// re-linearised ([`Self::install_model`]): linearised at the estimate
    /// it needs no bias, so a negative one is what a lying sensor dragged.
    /// The build-time linearisation at the ambient runs hot, and a healthy
    /// negative bias corrects it: dropping it put a stuck thermocouple's
    /// solenoid (one per solenoid, 3.1 A) 2.56 K off instead of 1.91 K.
    fn drop_cold_biases<W: OmniWarmUpKind>(
        &self,
        state: &mut OmniObserverState<W>,
        doubt: &[bool; SOLENOIDS],
    ) {
        if state.relinearised {
            drop_cold_biases::<Const<SOLENOIDS>>(state.estimate.x.iter_mut().skip(NODES), doubt);
        }
    }

    /// The correction of the start's warm-up (see [`Self::start`]): gated
    /// and fused against the covariance held (its columns at the
    /// solenoids, made by a light tick before), the readings' information
    /// counted, and the shadow moved to the estimate until the solenoids'
    /// and the insulations' bounds have forgotten the start
    /// ([`start::START_FORGOTTEN_K`]). About 300 multiply-adds: the
    /// subset update (`6 x 6` Cholesky, `19 x 6`) and its `19 x 6` and
    /// `6 x 6` inputs.
    #[inline(never)]
    fn correct_held<W: OmniWarmUpKind>(
        &self,
        state: &mut OmniObserverState<W>,
        z: &[Option<f32>; THERMOCOUPLES],
    ) -> UpdateReport<Const<THERMOCOUPLES>> {
        let kalman = self.filter.kalman();
        let Some(OmniHeld { cov: held, .. }) = state.warm.held_mut() else {
            return update_steady(kalman, self.filter.gain(), &mut state.estimate, z);
        };
        let (gain, innovation_var, prior_ht, innovation_cov) = held.correction();
        let report = update_against(
            kalman,
            gain,
            innovation_var,
            prior_ht,
            innovation_cov,
            &mut state.estimate,
            z,
        );
        let recovery = report.recovered.then_some(&kalman.recovery_variance);
        held.corrected(&report.verdicts, recovery);
        if !held.forgotten() {
            // The shadow, started from the start's guesses, knows no more
            // than the filter: it follows the filter until the solenoids'
            // and the insulations' bounds have forgotten the start, then
            // runs free (the core's excess may be held for hours).
            let origin = state.model.origin_c();
            let shadow_origin = self.shadow.origin_c();
            for i in 0..NODES {
                state.shadow_x[i] = origin[i] + state.estimate.x[i] - shadow_origin[i];
            }
            state.shadow_residual_k = [0.0; NODES];
        }
        report
    }

    /// The start's warm-up between corrections: the model steps counted
    /// and, on a light tick (no correction, no protection stage), slices
    /// of the held covariance's propagation (at most about 400
    /// multiply-adds each, see [`super::start`]); the warm-up ends once the
    /// posterior has settled on the steady one. The period's transition is
    /// the shadow's: the build-time linearisation stepped over one
    /// correction period.
    ///
    /// A light tick takes [`Self::held_slices_per_tick`] slices, times the
    /// loop's ticks it lasted (`elapsed_us` over the declared loop period:
    /// a loop slower than declared still propagates once a period).
    ///
    /// Not generic over the state's flavour (it takes what the warm-up
    /// holds): compiled in this crate as before the flavours, its slices
    /// keep their code; instantiated in the firmware's crate, the row
    /// pairs took about 900 instructions more each (measured,
    /// `omni_start_m4`).
    #[inline(never)]
    fn hold_start(&self, held: &mut StartCovariance, steps: u32, light: bool, elapsed_us: u32) {
        held.stepped(steps);
        if !light {
            return;
        }
        let transition = PeriodTransition {
            phi_minus_i: &self.shadow.phi_minus_i,
            gamma: &self.shadow.g,
        };
        let gain = self.filter.gain();
        let mut slices = self.held_slices_per_tick;
        if elapsed_us / 2 >= self.loop_period_us {
            let ticks_lasted = elapsed_us / self.loop_period_us.max(1);
            slices = slices
                .saturating_mul(ticks_lasted)
                .min(start::period_slices(STATES, NODES));
        }
        let propagation = start::Propagation {
            period: self.shadow_block_steps,
            transition,
            steady_prior: gain.prior(),
            steady_posterior: gain.posterior(),
            recovery: &self.filter.kalman().recovery_variance,
        };
        let settled = held.work_slices(slices, &propagation);
        if settled == Some(true) {
            held.end();
        }
    }
    /// Writes a snapshot of the node estimates \[degC\] and the latched
    /// shutdown, stamped `now_s` \[s\]; returns its length
    /// (`snapshot_len(16)` bytes). The heat-input biases are not saved: a
    /// restored state starts them at zero with the build-time model, and the
    /// thermocouples bring them back within minutes.
    pub fn save<W: OmniWarmUpKind>(
        &self,
        state: &OmniObserverState<W>,
        now_s: u32,
        out: &mut [u8],
    ) -> Result<usize, SnapshotError> {
        let temps_c = self.temps_c(state);
        snapshot::save_state(&temps_c, self.fingerprint, now_s, &state.alarm, out)
    }

    /// Restores a state saved by [`Self::save`] with this configuration at
    /// most `max_age_s` \[s\] before `now_s` \[s\]. A latched shutdown stays
    /// latched.
    ///
    /// # Errors
    /// Why the snapshot was refused; start from
    /// [`Self::conservative_state`] then.
    pub fn restore(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
    ) -> Result<OmniObserverState<NoWarmUp>, SnapshotError> {
        self.restore_cooled(bytes, now_s, max_age_s, ambient_c, None, |saved_c, _| {
            Ok(*saved_c)
        })
    }

    /// [`Self::restore`] for a device that was off for `off_s` \[s\]: the
    /// saved node estimates cooled with no current at the ambient
    /// `ambient_c` \[degC\] by [`Self::cooled_c`], never below the nonlinear
    /// model's exact cooled state and within 0.5 K of it (measured). A
    /// latched shutdown stays latched.
    ///
    /// `model` must be the model the observer was built from (checked by a
    /// fingerprint of its capacities and conductances at two states; the
    /// configuration does not keep the model: its geometry holds
    /// references).
    ///
    /// `off_s` is capped at the snapshot's age; `None`, a NaN or a negative
    /// time mean an *unknown* off time and restore the saved state uncooled
    /// ([`snapshot::off_time_s`]); `Some(0.0)` restores it to the bit, as
    /// [`Self::restore`] does. An ambient outside the input limits restores
    /// uncooled as well.
    ///
    /// # Errors
    /// Those of [`Self::restore`];
    /// [`SnapshotError::CoolingModelMismatch`] for another `model` (when
    /// there is cooling to do).
    pub fn restore_after(
        &self,
        model: &Omnimagnet,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        off_s: Option<f32>,
    ) -> Result<OmniObserverState<NoWarmUp>, SnapshotError> {
        self.restore_cooled(
            bytes,
            now_s,
            max_age_s,
            ambient_c,
            off_s,
            |saved_c, off_s| self.cooled_c(model, saved_c, ambient_c, off_s),
        )
    }

    /// The snapshot checked, its temperatures passed through `cool` (with
    /// the off time, when there is cooling to do: positive and the ambient
    /// valid), the latch restored and shown.
    fn restore_cooled(
        &self,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        off_s: Option<f32>,
        cool: impl FnOnce(&[f32; NODES], f32) -> Result<[f32; NODES], SnapshotError>,
    ) -> Result<OmniObserverState<NoWarmUp>, SnapshotError> {
        let snap = Restored::read(bytes, self.fingerprint, now_s, max_age_s, [0.0; NODES])?;
        let (saved_c, meta, off_s) = (snap.saved_c, snap.meta, snap.off_time_s(off_s));
        let mut held_c = ambient_c;
        let ambient_ok = self.limits.accept_temperature(ambient_c, &mut held_c) == InputFlags::NONE;
        let temps_c = if off_s > 0.0 && ambient_ok {
            cool(&saved_c, off_s)?
        } else {
            saved_c
        };
        Ok(self.restored(&temps_c, &meta, ambient_c))
    }

    /// The state at `temps_c` \[degC\], the snapshot's latch restored and
    /// shown.
    fn restored(
        &self,
        temps_c: &[f32; NODES],
        meta: &SnapshotMeta,
        ambient_c: f32,
    ) -> OmniObserverState<NoWarmUp> {
        let mut state = self.state(temps_c, ambient_c);
        state.latch().restore(meta);
        state
    }

    /// [`Self::restore`] for a device whose off time is unknown (no
    /// real-time clock), with what the thermocouples read now, `readings_c`
    /// \[degC\] (`None`, non-finite or an unfitted thermocouple: no
    /// reading): the saved estimates cooled, by the nonlinear model with no
    /// current ([`Self::cooled_c`]), for the shortest off time within the
    /// snapshot's age that brings some thermocouple's solenoid within
    /// `k_sigma` thermocouple deviations (0.75 K at the defaults) of its
    /// reading ([`start::earliest_off_time_s`]: of the solenoids the saved
    /// state puts above their readings), and every measured solenoid at
    /// its hotter reading ([`start::at_readings`]): the least cooling the readings
    /// allow, so the nodes no thermocouple reads (the insulations, the
    /// core) err hot, and the first readings agree with the estimate (none
    /// refused, none colder than the physics). A reading colder than the
    /// ambient by more than that tolerance (no cooling reaches it: a faulty
    /// sensor) is left out. With no usable reading, or an ambient
    /// `ambient_c` \[degC\] outside the input limits, the saved state
    /// uncooled, as [`Self::restore_after`] with `None`. A latched shutdown
    /// stays latched. With readings, the state is held as [`Self::start`]
    /// holds it (the unread insulations capped and widened to 1 K under
    /// their limits, the covariance held until settled): the snapshot
    /// keeps no heat-input bias, and without one the build-time
    /// linearisation runs a hot device hotter than its thermocouples.
    ///
    /// `model` must be the model the observer was built from (as for
    /// [`Self::restore_after`]). Restore-time work, not for the tick: at
    /// most 53 cooled states on one cooling path whose pieces are kept
    /// ([`COOLING_MAX_PIECES`](crate::omnimagnet::COOLING_MAX_PIECES)
    /// pieces of two `16 x 16` exponentials, 7 KiB of stack), so about
    /// 1 + 53 / 56 times [`Self::restore_after`]'s work for the longest
    /// off time.
    ///
    /// # Errors
    /// Those of [`Self::restore`];
    /// [`SnapshotError::CoolingModelMismatch`] for another `model` (when
    /// there is cooling to do).
    pub fn restore_with_readings(
        &self,
        model: &Omnimagnet,
        bytes: &[u8],
        now_s: u32,
        max_age_s: u32,
        ambient_c: f32,
        readings_c: &[Option<f32>; THERMOCOUPLES],
    ) -> Result<OmniObserverState, SnapshotError> {
        let snap = Restored::read(bytes, self.fingerprint, now_s, max_age_s, [0.0; NODES])?;
        let (saved_c, meta) = (snap.saved_c, snap.meta);
        let mut held_c = ambient_c;
        let ambient_ok = self.limits.accept_temperature(ambient_c, &mut held_c) == InputFlags::NONE;
        let fitted = self.filter.settings().sensors;
        let r = self.filter.kalman().r();
        let tolerance_k = start::restore_tolerance_k(
            self.k_sigma(),
            r.iter()
                .zip(fitted)
                .filter(|(_, used)| *used)
                .map(|(r, _)| *r),
        );
        let mut readings_c = *readings_c;
        start::restore_readings(&mut readings_c, fitted, ambient_c, tolerance_k);
        let usable = readings_c.iter().any(Option::is_some);
        if !(ambient_ok && usable) {
            return Ok(self.with_warm_up(self.restored(&saved_c, &meta, ambient_c)));
        }
        if plant_fingerprint(model) != self.plant_fingerprint {
            return Err(SnapshotError::CoolingModelMismatch);
        }
        let path = core::cell::RefCell::new(CoolingPath::new(
            model,
            &saved_c.map(f64::from),
            f64::from(ambient_c),
        ));
        let temps_c = start::cooled_to_readings(
            &saved_c,
            |t: f32| rounded_up(&saved_c, &path.borrow_mut().cooled_c(f64::from(t))),
            &THERMOCOUPLE_NODES,
            &readings_c,
            tolerance_k,
            snap.age_s(),
        );
        // Held as a start is: the snapshot keeps no heat-input bias, and
        // without it the build-time linearisation runs a hot device hotter
        // than its readings; the held covariance lets the gate take them
        // and the shadow follow the estimate until the filter has settled.
        let mut state = self.held_start(temps_c, &read_nodes(&readings_c), ambient_c);
        state.latch().restore(&meta);
        Ok(state)
    }

    /// The node temperatures \[degC\] `off_s` \[s\] after `temps_c` with no
    /// current and the ambient at `ambient_c` \[degC\]: the nonlinear
    /// model's zero-current cooling by frozen pieces
    /// ([`Omnimagnet::cooled_c`], `f64`, at most
    /// [`COOLING_MAX_PIECES`](crate::omnimagnet::COOLING_MAX_PIECES) pieces
    /// of two `16 x 16` exponentials each), plus 1 mK for the rounding to
    /// `f32`. The reference is the nonlinear model (the plant), not the
    /// filter's linearisation: both settle at the ambient with no current,
    /// and the linearisation at a cold operating point cools too slowly.
    /// An off time that is not positive returns `temps_c`.
    ///
    /// # Errors
    /// [`SnapshotError::CoolingModelMismatch`] when `model` is not the
    /// model the observer was built from.
    pub fn cooled_c(
        &self,
        model: &Omnimagnet,
        temps_c: &[f32; NODES],
        ambient_c: f32,
        off_s: f32,
    ) -> Result<[f32; NODES], SnapshotError> {
        if off_s.is_nan() || off_s <= 0.0 {
            return Ok(*temps_c);
        }
        if plant_fingerprint(model) != self.plant_fingerprint {
            return Err(SnapshotError::CoolingModelMismatch);
        }
        let start = temps_c.map(f64::from);
        let cooled = model.cooled_c(&start, f64::from(ambient_c), f64::from(off_s));
        Ok(rounded_up(temps_c, &cooled))
    }

    /// The documented start when no snapshot can be trusted
    /// ([`snapshot::conservative_start`]): measured nodes at their readings
    /// \[degC\], every other node no cooler than the hottest reading or the
    /// ambient `ambient_c` \[degC\]. The shutdown is *latched* (and
    /// `outputs().alarm.shutdown` is `true` from the start): the refused
    /// snapshot may have recorded a latched shutdown, and the unmeasured
    /// windings may be hotter than any thermocouple, so the current stays
    /// cut until the application calls [`Self::clear_shutdown`].
    pub fn conservative_state(
        &self,
        readings_c: &[Option<f32>; THERMOCOUPLES],
        ambient_c: f32,
    ) -> OmniObserverState<NoWarmUp> {
        let temps = snapshot::conservative_start::<NODES, THERMOCOUPLES>(
            readings_c,
            &THERMOCOUPLE_NODES,
            ambient_c,
        );
        let mut state = self.state(&temps, ambient_c);
        state.latch().latch();
        state
    }

    /// The start without a history (the first boot, a refused snapshot, a
    /// product that keeps none), safe from the first tick (see "Start
    /// without history" in the module docs and [`super::start`]): every
    /// solenoid a thermocouple reads now at its reading `readings_c`
    /// \[degC\] (`None`, non-finite or an unfitted thermocouple: no
    /// reading; two on one solenoid: the hotter), a solenoid with no
    /// reading at the hottest reading (or the ambient `ambient_c`
    /// \[degC\]), every other node at the steady state of `model`'s network
    /// with the solenoids held there (between the coolest and the hottest
    /// reading) and each wire or cover insulation no hotter than where its
    /// upper bound is [`start::START_BELOW_LIMIT_K`] below its alarm limit;
    /// a variance that puts each insulation's upper bound
    /// [`start::START_BELOW_LIMIT_K`] below its alarm limit (the other
    /// unread nodes the widest of those). The filter holds that covariance
    /// (once per correction period, in slices on the light ticks): the
    /// gate judges against it, the upper bound (on the insulations no
    /// higher than the start's level), the limiter and the time to limit
    /// follow it, until the posterior has settled on the steady one (every
    /// variance within [`start::SETTLED_FRACTION`], or
    /// [`start::MAX_START_CORRECTIONS`] corrections); the shadow follows
    /// the estimate until the insulations' and solenoids' bounds have
    /// forgotten the start. No shutdown is latched (unlike
    /// [`Self::conservative_state`]): the limiter starts in its taper band
    /// and opens as the thermocouples teach the filter. The build-time
    /// model, no current, zero heat-input biases, as [`Self::state`].
    ///
    /// `model` must be the model the observer was built from (checked by
    /// the fingerprint [`Self::restore_after`] checks): the configuration
    /// does not keep it, and the mean needs its conductances at the start's
    /// temperatures (the build-time linearisation at the ambient puts the
    /// frames of a hot device kelvins too hot, enough to latch a cover's
    /// shutdown at the hottest point). Another model is not used: the
    /// unread nodes then start at the hottest reading, which errs hot.
    /// Start-time work, not for the tick: about 2.9 million instructions
    /// on a Cortex-M4F (three `f64` conductance evaluations and `16 x 16`
    /// solves).
    pub fn start(
        &self,
        model: &Omnimagnet,
        readings_c: &[Option<f32>; THERMOCOUPLES],
        ambient_c: f32,
    ) -> OmniObserverState {
        let fitted = self.filter.settings().sensors;
        let readings: [Option<f32>; THERMOCOUPLES] =
            core::array::from_fn(|j| readings_c[j].filter(|t| fitted[j] && t.is_finite()));
        // Two thermocouples on one solenoid: the hotter (the conservative
        // start takes the last).
        let mut hotter = readings;
        for (j, node) in THERMOCOUPLE_NODES.iter().enumerate() {
            for (i, other) in THERMOCOUPLE_NODES.iter().enumerate() {
                if let (true, Some(a), Some(b)) = (node == other, hotter[j], readings[i]) {
                    hotter[j] = Some(a.max(b));
                }
            }
        }
        let hottest_c = snapshot::conservative_start::<NODES, THERMOCOUPLES>(
            &hotter,
            &THERMOCOUPLE_NODES,
            ambient_c,
        );
        let read = read_nodes(&hotter);
        // The model the observer was built from, or no steady state: the
        // conservative start, which errs hot.
        let steady = (plant_fingerprint(model) == self.plant_fingerprint)
            .then(|| self.held_steady_start(model, &hottest_c, &hotter, ambient_c))
            .flatten();
        self.held_start(steady.unwrap_or(hottest_c), &read, ambient_c)
    }

    /// The state at `temps` \[degC\] (the nodes in `read` at their
    /// readings) held as [`Self::start`] holds it: each unread insulation
    /// capped where its bound is [`start::START_BELOW_LIMIT_K`] under its
    /// alarm limit, a variance that puts it there, the filter holding that
    /// covariance and the shadow following the estimate until both have
    /// settled (shared by [`Self::start`] and
    /// [`Self::restore_with_readings`]).
    fn held_start(
        &self,
        mut temps: [f32; NODES],
        read: &[bool; NODES],
        ambient_c: f32,
    ) -> OmniObserverState {
        let mut limits_c = [f32::INFINITY; NODES];
        let mut limited = [false; NODES];
        for (node, limit) in ALARM_NODES.iter().zip(self.alarm.alarm_limits_c(ambient_c)) {
            if let (Some(l), Some(on)) = (limits_c.get_mut(*node), limited.get_mut(*node)) {
                *l = limit;
                *on = true;
            }
        }
        let ceiling_c: [f32; NODES] = core::array::from_fn(|i| match self.bound.element(i) {
            Some(bound) if limited[i] => {
                bound.mean_limit_c(limits_c[i] - start::START_BELOW_LIMIT_K, ambient_c)
            }
            _ => f32::NAN,
        });
        start::cap_unread_c(&mut temps, read, &limited, &ceiling_c);
        let mut state = self.state_holding(
            &temps,
            ambient_c,
            WarmUp {
                held: OmniHeld::idle(),
            },
        );
        let mut steady_upper_c = [0.0; NODES];
        self.bound.upper_c(&temps, ambient_c, &mut steady_upper_c);
        let prior = self.filter.gain().prior();
        let steady_sigma: [f32; STATES] =
            core::array::from_fn(|i| libm::sqrtf(prior[(i, i)].max(0.0)));
        let node_sigma: [f32; NODES] = core::array::from_fn(|i| steady_sigma[i]);
        let k_sigma = self.k_sigma();
        let sigma_k = start::start_sigma_k(
            read,
            &steady_upper_c,
            &limits_c,
            &limited,
            &node_sigma,
            k_sigma,
        );
        let mut cov = *prior;
        for (i, sigma) in sigma_k.enumerate() {
            if let Some(sigma) = sigma {
                cov[(i, i)] = cov[(i, i)].max(sigma * sigma);
            }
        }
        let fitted = self.filter.settings().sensors;
        let r = self.filter.kalman().r();
        let layout = HeldLayout {
            measured: MEASURED_NODES,
            sensors: core::array::from_fn(|j| fitted[j].then_some(SENSOR_MEASURED[j])),
            r: core::array::from_fn(|j| r[j]),
            steady_sigma,
            k_sigma,
            // The solenoids and the insulations: once their bounds have
            // forgotten the start, the shadow is free (see `correct_held`).
            watched: core::array::from_fn(|i| {
                MEASURED_NODES.contains(&i) || limited.get(i) == Some(&true)
            }),
        };
        state.warm.held.cov = StartCovariance::start(cov, layout);
        self.publish_upper(&mut state);
        // The predictor's first sweep towards the held bound's limits.
        let op = self.operating(&temps, &[0.0; SOLENOIDS], ambient_c, state.held_extra_k());
        state.predictor = PredictorState::when_asked(&self.predictor, &op);
        self.limit(&mut state.outputs, ambient_c);
        state
    }

    /// The start's mean (see [`start::held_steady_state_c`]): the steady
    /// state of `model`'s network with the solenoids (every heat source)
    /// held at `hottest_c` (their readings, or the conservative start's
    /// where none arrived) and the ambient at `ambient_c` \[degC\], its
    /// secant conductances taken at the start's temperatures (three
    /// passes, each at the last one's result), each other node between the
    /// coolest reading (or the ambient) and its conservative start in
    /// `hottest_c` \[degC\]. `None` if a solve fails.
    fn held_steady_start(
        &self,
        model: &Omnimagnet,
        hottest_c: &[f32; NODES],
        readings_c: &[Option<f32>; THERMOCOUPLES],
        ambient_c: f32,
    ) -> Option<[f32; NODES]> {
        let held: [Option<f64>; NODES] = core::array::from_fn(|i| {
            MEASURED_NODES
                .contains(&i)
                .then(|| hottest_c.get(i).copied().map(f64::from))
                .flatten()
        });
        let amb = f64::from(ambient_c);
        let mut temps_c = hottest_c.map(f64::from);
        for _ in 0..3 {
            let g = model.conductances(&temps_c, amb);
            temps_c = start::held_steady_state_c(&g.pair_w_per_k, &g.ambient_w_per_k, amb, &held)?;
        }
        let coolest_c = readings_c
            .iter()
            .flatten()
            .fold(ambient_c, |a, t| a.min(*t));
        let out: [f32; NODES] = core::array::from_fn(|i| match held[i] {
            Some(_) => hottest_c[i],
            None => (temps_c[i] as f32).max(coolest_c).min(hottest_c[i]),
        });
        out.iter().all(|t| t.is_finite()).then_some(out)
    }

    /// The upper bound's `k` (of `k sigma`): a fitted thermocouple's
    /// solenoid carries no model margin, so its bound's offset is
    /// `k sigma` alone (0 if no bound has one).
    fn k_sigma(&self) -> f32 {
        let fitted = self.filter.settings().sensors;
        let prior = self.filter.gain().prior();
        for (node, used) in THERMOCOUPLE_NODES.iter().zip(fitted) {
            let (true, Some(bound), Some(var)) =
                (used, self.bound.element(*node), prior.get((*node, *node)))
            else {
                continue;
            };
            let k = bound.offset_k() / libm::sqrtf(*var);
            if k.is_finite() && k >= 0.0 {
                return k;
            }
        }
        0.0
    }

    /// The deliberate clear of a latched shutdown (restored from a
    /// snapshot, set by [`Self::conservative_state`], or raised by the
    /// alarm), for the application to call after inspecting the device;
    /// nothing else clears it (see [`GridObserver::clear_shutdown`](super::GridObserver::clear_shutdown)).
    /// It is [`AlarmState::reset`] under its conditions: every alarm
    /// element's upper bound valid and below its alarm limit minus the
    /// hysteresis for the alarm's `debounce_ticks` protection cycles. On
    /// success a [`Reset`](crate::protect::events::EventKind::Reset) event
    /// is queued and the published `alarm.shutdown` is `false` at once; the
    /// current limits, zero while latched, come back with the next limiter
    /// stage.
    /// Not for the tick: call it between two ticks.
    ///
    /// # Errors
    /// Why not, naming the first element that blocks it; nothing changes
    /// then.
    pub fn clear_shutdown<W: OmniWarmUpKind>(
        &self,
        state: &mut OmniObserverState<W>,
    ) -> Result<(), ResetError> {
        state.latch().clear(&self.alarm)
    }
}

/// The Omnimagnet observer's protection stages; the cycle's rules are
/// [`ProtectionStages::run_due`]'s.
impl<W: OmniWarmUpKind> ProtectionStages<Const<SOLENOIDS>>
    for Protecting<'_, OmniObserver, OmniObserverState<W>>
{
    #[inline(always)]
    fn cycle_and_held(&mut self) -> (&mut ProtectionCycle<Const<SOLENOIDS>>, &[f32; SOLENOIDS]) {
        (&mut self.state.cycle, &self.state.held_currents_a)
    }

    #[inline(always)]
    fn predictor_slice_us(&self) -> u32 {
        self.observer.predictor_slice_us
    }

    #[inline(always)]
    fn predict(&mut self) {
        let (observer, state) = (self.observer, &mut *self.state);
        let op = observer.operating(
            &state.outputs.temps_c,
            state.cycle.peak_currents_a(),
            state.held_ambient_c,
            state.held_extra_k(),
        );
        state.predictor.tick(&observer.predictor, &op);
    }

    #[inline(always)]
    fn alarm(&mut self) {
        let (observer, state) = (self.observer, &mut *self.state);
        observer.publish_upper(state);
        let out = &mut state.outputs;
        let temps = alarm_temps(&out.upper_c);
        out.alarm = state.alarm.tick(
            &observer.alarm,
            &temps,
            state.held_ambient_c,
            &out.time_to_limit_s,
            &mut state.events,
        );
    }

    #[inline(always)]
    fn limit(&mut self) {
        let (observer, state) = (self.observer, &mut *self.state);
        observer.publish_upper(state);
        observer.limit(&mut state.outputs, state.held_ambient_c);
    }

    #[inline(always)]
    fn age_time_to_limit(&mut self) {
        self.observer.age_time_to_limit(self.state);
    }
}

/// A fingerprint of a nonlinear Omnimagnet model: its capacities and
/// conductances at 22 and at 122 degC (ambient 22 degC), which every
/// parameter of the model moves.
fn plant_fingerprint(model: &Omnimagnet) -> u32 {
    let mut fp = Fingerprint::new();
    for temp_c in [22.0, 122.0] {
        let temps = [temp_c; NODES];
        let g = model.conductances(&temps, 22.0);
        fp = fp
            .f64s(&model.capacities_j_per_k(&temps))
            .f64s(g.pair_w_per_k.as_flattened())
            .f64s(&g.ambient_w_per_k);
    }
    fp.finish()
}

/// The cooled state `cooled_c` \[degC\] in `f32`, 1 mK up for the
/// rounding; a node whose cooled value is not finite keeps `temps_c`.
fn rounded_up(temps_c: &[f32; NODES], cooled_c: &[f64; NODES]) -> [f32; NODES] {
    let mut out = *temps_c;
    for (o, c) in out.iter_mut().zip(cooled_c) {
        let t = (c + 1e-3) as f32;
        if t.is_finite() {
            *o = t;
        }
    }
    out
}

/// The estimates of the [`ALARM_NODES`] \[degC\].
fn alarm_temps(temps_c: &[f32; NODES]) -> [f32; ALARM_NODES.len()] {
    ALARM_NODES.map(|node| temps_c.get(node).copied().unwrap_or(f32::NAN))
}

#[cfg(test)]
mod fuzz_tests;
#[cfg(test)]
mod refresh_tests;
#[cfg(test)]
mod rules_tests;
#[cfg(test)]
mod start_tests;

/// The nodes some thermocouple of `readings_c` reads.
fn read_nodes(readings_c: &[Option<f32>; THERMOCOUPLES]) -> [bool; NODES] {
    let mut read = [false; NODES];
    for (reading, node) in readings_c.iter().zip(THERMOCOUPLE_NODES) {
        if let (Some(_), Some(slot)) = (reading, read.get_mut(node)) {
            *slot = true;
        }
    }
    read
}

/// The first solenoid a single sensor fault would leave without a healthy
/// thermocouple among `sensors` (the thermocouples in use, order of
/// [`THERMOCOUPLE_NODES`]): one with at most one thermocouple. Such a
/// sensor set needs a declared model refresh
/// ([`OmniSettings::model_refresh_s`], [`BuildError::ModelRefreshRequired`]);
/// `None`: every solenoid has two.
pub const fn needs_model_refresh(sensors: &[bool; THERMOCOUPLES]) -> Option<usize> {
    match single_sensor_solenoid(sensors) {
        Some((solenoid, _)) => Some(solenoid),
        None => None,
    }
}

/// [`needs_model_refresh`] with the solenoid's count of thermocouples in
/// use (0 or 1).
const fn single_sensor_solenoid(sensors: &[bool; THERMOCOUPLES]) -> Option<(usize, usize)> {
    let mut m = 0;
    while m < SOLENOIDS {
        let mut count = 0;
        let mut j = 0;
        while j < THERMOCOUPLES {
            if sensors[j] && THERMOCOUPLE_NODES[j] == m {
                count += 1;
            }
            j += 1;
        }
        if count <= 1 {
            return Some((m, count));
        }
        m += 1;
    }
    None
}

/// A placement with a solenoid a single fault leaves to the model alone is
/// accepted only with a declared model refresh of at most
/// [`MAX_MODEL_REFRESH_S`] (its watchdog bound `stale_after_steps` at
/// `step_us` \[us\], `u32::MAX`: none). Every solenoid of the Omnimagnet
/// carries alarm elements ([`ALARM_NODES`]), so every one counts.
pub(crate) const fn check_refresh(
    sensors: &[bool; THERMOCOUPLES],
    stale_after_steps: u32,
    step_us: u32,
) -> Result<(), BuildError> {
    let Some((solenoid, sensors)) = single_sensor_solenoid(sensors) else {
        return Ok(());
    };
    let step_us = if step_us == 0 { 1 } else { step_us as u64 };
    let most_steps = (MODEL_STALE_PERIODS as u64 * MAX_MODEL_REFRESH_US).div_ceil(step_us);
    if stale_after_steps == u32::MAX || stale_after_steps as u64 > most_steps {
        return Err(BuildError::ModelRefreshRequired {
            solenoid,
            sensors,
            max_refresh_s: MAX_MODEL_REFRESH_S as f32,
        });
    }
    Ok(())
}
