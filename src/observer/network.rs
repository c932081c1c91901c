//! One observer for any device described as a [`Network`]: the tick API of
//! [`OmniObserver`](super::OmniObserver) (same clock, inputs, readings,
//! protection cycle, snapshots) for your own actuator.
//!
//! * model: the network's exact zero-order-hold step ([`crate::discretize`],
//!   solved in `f64` at build time), run in `f32` on *deviations* from an
//!   origin with the rounding carried ([`compensated_add`]), so that it does
//!   not drift from the exact `f64` solution over hours (see "f32 without
//!   drift" below);
//! * filter: a heat-input bias state per current input (like the
//!   Omnimagnet's; shared in proportion to the Joule power when the
//!   sensors cannot tell the currents' heat apart, see "One sensor sees
//!   one heat"), the Joule power `R(T) I^2` at the *estimated* winding
//!   temperature every step, and the steady-state Kalman gain for the
//!   sensors you name (`sensor_nodes[j]` = the node thermocouple `j`
//!   measures), solved in `f64` and cast; optionally a time-varying warm-up
//!   first ([`NetworkSettings::warmup_corrections`]: full covariance from a
//!   widened prior, sequential Joseph updates, then the steady gain), which
//!   pulls a far-off start in within minutes (from 10 K off: 0.84 K after
//!   2 min against 4.98 K with the steady gain alone, test
//!   `a_time_varying_warm_up_pulls_a_wrong_start_in_sooner`);
//! * protection, every [`NetworkSettings::protect_period_steps`] steps, one
//!   stage per tick (a time-to-limit slice, the derated alarm, the limiter),
//!   on the protective upper bound of [`crate::protect::margin`]: `k sigma`
//!   from the steady covariance on every node and a model margin on the
//!   nodes no sensor measures. Elements get a limit by their critical
//!   temperature ([`NetworkObserverBuilder::critical_c`]); the others are
//!   estimated but never limit anything.
//!
//! The filter state has `N + M` entries (temperatures, then biases), one
//! more with a boundary offset (see "A boundary offset that never cools").
//! Stable Rust cannot write `N + M` as a type, so it is the extra parameter
//! `X` of [`NetworkObserver`], checked at compile time (`X == N + M` or
//! `N + M + 1`) and at build against the settings: write
//! `NetworkObserver<3, 1, 1, 4, 1>` for 3 nodes, 1 boundary, 1 current,
//! 4 states, 1 sensor.
//!
//! # Your own device
//!
//! A winding (node 0) in a housing (node 1) on a heatsink (node 2) cooled by
//! the ambient (boundary 0), one current, one thermocouple on the housing:
//!
//! ```
//! use coil_thermal::observer::network::{NetworkInputs, NetworkObserver, NetworkObserverBuilder};
//! use coil_thermal::observer::TimedReading;
//! use coil_thermal::{Network, Reading, Resistance};
//!
//! let network: Network<3, 1, 1> = Network::new([60.0, 400.0, 900.0])? // J/K
//!     .connect(0, 1, 0.8)? // W/K
//!     .connect(1, 2, 2.0)?
//!     .connect_boundary(2, 0, 1.2)?
//!     .joule_source(0, 0, Resistance::with_alpha(1.2, 0.00393, 20.0))?; // ohm at 20 degC
//! // Winding insulation 155 degC, housing 80 degC (a touch limit), heatsink free.
//! let observer: NetworkObserver<3, 1, 1, 4, 1> = NetworkObserverBuilder::new(&network, [1])
//!     .critical_c([Some(155.0), Some(80.0), None])
//!     .build()?;
//! let mut state = observer.state(&[20.0; 3], &[20.0]);
//! for tick in 0..2_000u32 {
//!     let now_us = tick * 1000;
//!     // A thermocouple sample every 500 ms (here a constant 20.5 degC).
//!     let reading = (tick % 500 == 0).then_some(TimedReading {
//!         result: Ok(Reading::new(20.5)),
//!         sampled_at_us: now_us,
//!     });
//!     let inputs = NetworkInputs {
//!         currents_a: [3.0],   // measured winding current [A]
//!         boundary_c: [20.0],  // ambient [degC]
//!         readings: [reading],
//!         now_us,
//!         elapsed_us: 1000,    // since the previous tick [us]
//!     };
//!     let out = observer.tick(&mut state, &inputs);
//!     let _command_a = out.limits[0].clamp_a(3.0); // what the drive may apply
//! }
//! let out = state.outputs();
//! assert!(out.temps_c[0] > out.temps_c[1] && out.flags.is_clean());
//! # Ok::<(), coil_thermal::BuildError>(())
//! ```
//!
//! # Voltage-driven coils
//!
//! A 24 V solenoid valve on a PWM duty `D` with a measured supply `V` and
//! no current sensing heats by `D V^2 / R(T)`, which *falls* as it heats.
//! Describe its winding with [`Network::voltage_source`] (or
//! [`Network::joule_source`]: the observer needs only `R(T)` and the node,
//! and a measured current is exact whatever drives the coil), and tick
//! with [`NetworkObserver::tick_voltage`], giving a
//! [`VoltageDrive`] for the driven inputs. Each
//! becomes the current the winding draws at its *estimated* temperature,
//! `I = sqrt(D) V / R(T_est)`, so that the step's `R(T_est) I^2` is
//! `D V^2 / R(T_est)`; the per-step path is [`tick`](NetworkObserver::tick)'s,
//! unchanged (a current-driven tick costs not a cycle more). Within one
//! tick's catch-up steps `T_est` is the tick's first (at 1 ms steps the
//! winding moves by 1e-5 K a step). The time-to-limit predictor then holds
//! that current over its horizon with `R` at the alarm limit, which
//! over-states a voltage-driven coil's heat (its true heat falls as it
//! warms): the answer stays on the early side. The limit is published in
//! the drive's own units by [`NetworkObserver::drive_limit`]: `D_max =
//! (I_lim R(T_est) / V)^2` in `[0, 1]`, zero for a NaN, zero or negative
//! supply reading (see [`crate::protect::limiter`], "A limit in the
//! drive's own unit"). Tested against an independent `f64` RK4 of `C dT/dt
//! = D V^2 / (R0 (1 + alpha (T - T_ref))) - (T - T_a) / R_th` and its
//! closed-form steady state, and in closed loop (a duty held at the
//! published limit keeps the coil under its derated alarm limit):
//! `voltage_drive` tests of this module.
//!
//! # Limits per current: the incidence
//!
//! Each element with a limit derates *every* current that heats it, not
//! one current per element: a housing heated by three phases is protected
//! by derating all three. The limiter's taper (see
//! [`crate::protect::limiter`]) gives each limited element a factor
//! `sqrt(headroom)` in `[0, 1]`, and current `m` is held at
//! `hardware_limit_a[m]` times the smallest factor among the elements it
//! heats. By default an element counts as heated by current `m` when its
//! steady-state sensitivity `dT_i/dP_m` \[K/W\] (from `-A^-1 B`) is at least
//! [`NetworkSettings::incidence_fraction`] (default 0.1) of its largest
//! sensitivity to any current; [`NetworkObserverBuilder::incidence`]
//! overrides it.
//!
//! # f32 without drift
//!
//! A 1 ms step changes a winding by 1e-5 K or less, while `f32` near
//! 100 degC resolves only 8e-6 K: `x' = Ad x + ...` in `f32` rounds a large
//! share of every increment away, and the error accumulates over hours
//! (the generic [`predict_mean`](crate::filter::predict_mean) on absolute
//! temperatures read 5.5 K low after 2 h at 8 A in issue 16). Here the step
//! is written as an increment, `x' = x + ((Ad - I) x + Bd (p + b) +
//! Gd (T_b - T_0) + c)`, with `Ad - I` and the constant `c` formed in `f64`,
//! and the increment is added with the rounding carried to the next step
//! ([`compensated_add`], one residual per node in the state). Tested:
//! 2 h at 8 A open loop, within 0.01 K of the `f64` reference
//! (`f32_does_not_drift`). `predict_mean` keeps its plain form: it serves
//! the general filter, whose `F` need not be a heat network's, and whose
//! state has no place for a residual; the time-varying filter it belongs to
//! runs in `f64` where it matters.
//!
//! # Model step and ticks
//!
//! The model steps every [`NetworkSettings::step_us`] of measured time,
//! which need not be the loop's tick ([`NetworkSettings::loop_period_us`]):
//! a step of 5 or 10 ms loses nothing on a device whose fastest node has a
//! time constant of seconds, and costs the step's arithmetic once per step
//! instead of once per tick (the rule the Omnimagnet observer has kept
//! since its multi-rate model). Every tick accounts each current's `I^2`
//! times its elapsed time (one account, in `observer::clock`, shared with
//! the Omnimagnet's), and a step heats with the mean `I^2` of the time it
//! covers, `R(T)` at its start estimate times that mean (no root is
//! taken: a soft-float `sqrtf` per current on a core without an FPU): the
//! exact mean power for a current that changes from tick to
//! tick (PWM, commutation), where the held current of the tick the step
//! lands on would sample it. The same holds for a 1 ms step on a loop whose
//! ticks jitter, since a step then spans two ticks' currents: a 2 ms square
//! wave on 1.1 / 0.9 ms ticks, whose long ticks carry the current, read
//! 0.40 K cold of a 4.4 K rise (9 %) before the account and 4e-5 K off an
//! `f64` RK4 of the nonlinear network with it (`multi_rate_tests.rs`; a 5
//! ms step on a 1 ms loop under a PWM whose steps all land on off ticks:
//! 2.8e-3 K, the heating of the time not yet stepped). When the held
//! currents did not change within a step, or the ticks land on the steps'
//! boundaries, the step takes the held currents as they are: to the bit the
//! model without the account. Only a step or a reading moves the estimate,
//! so the temperatures and the times to limit are published on those ticks
//! (and the times on a protection stage's). A tick that runs a step longer
//! than the loop's tick is busy, as a catch-up is. The shadow's block (see
//! "Sensors against the physics" below) that such a step completes waits
//! for the first tick without a step or a reading, which it makes busy (its
//! exact step of a whole block is the shadow's heaviest piece: about 5 900
//! instructions in soft-float; at most one block waits). With the model
//! step in integer arithmetic, a correction's move of the estimate is
//! read into the step's states on the next such tick as well (one piece
//! a tick; see "The model step in integer arithmetic"), which it makes
//! busy, so that the next step's tick does not carry it. Every protection
//! stage (the predictor's, the alarm, the limiter) waits out up to three
//! busy ticks in a row (a step's, its block's and a reading's; one more
//! with the integer step's read, one more with a correction's second tick,
//! see "A correction in two ticks") before it runs all the same, so that
//! it lands on a light tick. Unlike the Omnimagnet's, a step here does not wait a
//! tick for a reading's correction ([`StepClock::defer`]): on the
//! Cortex-M0 its clock code cost the 2-node footprint 280 B and the M4F
//! ticks up to 8 %, for a worst tick the stages' waiting lowered instead. The Cortex-M0 run of
//! `network_roundtrip` steps every 10 ms on its 1 ms loop
//! (`drive-3node-integer.toml`): 1 015 instructions a tick on average,
//! against 4 880 at 1 ms, every printed figure within 10 mK of the 1 ms
//! `f32` firmware's (docs/cost.md); its worst tick, 7 245, is a
//! predictor stage's (a step's tick that completed a block was 10 587).
//!
//! # The model step in integer arithmetic
//!
//! Without an FPU every `f32` operation of the step above is a software
//! routine, about 200 instructions a multiply-add on a Cortex-M0. With
//! [`NetworkSettings::integer_model_step`] (and the `integer-step` feature)
//! the step runs in integer arithmetic instead
//! ([`FixedStep`](crate::discretize::fixed::FixedStep)): each node has a
//! Q16.48 state (3.6e-15 K) in the observer state, the increment is formed
//! from the same `f32` tables as `i32` rows scaled by powers of two, 32 x
//! 32 -> 64-bit products, and added exactly; the `f32` estimate is the
//! state's image. A deviation moved since the step wrote it (a correction,
//! the common-mode rule, a start) moves the integer state by the same
//! amount, exactly, before the next step (`network/integer.rs`). So the
//! filter, the bound and the protection see the estimate as with the `f32`
//! step, and a correction moves what the next step starts from. The same
//! bits on every core, so the host's replay of a model file that asks for
//! it is the firmware to the bit. Tested: 2 h at 8 A open loop within
//! 1e-5 K of the `f64` RK4 (`the_integer_step_does_not_drift_either`,
//! 5.8e-6 K), an hour of readings beside the `f32` step (1.2e-5 K
//! apart), and the step
//! against the `f64` recursion of its tables. The shadow's block (see
//! "Sensors against the physics") steps in the same integer form where its
//! tables fit its scales (else in `f32`), its deviation and carry taken as
//! one Q16.48 state per node for the block: within 1e-5 K of the exact
//! solution over 1 600 s of heating and cooling
//! (`the_integer_block_step_follows_the_exact_solution`); on the Cortex-M0
//! the real motor's heaviest tick, which carries a block, fell from 48 195
//! to 42 590 instructions with it. A setting, so the host replays either
//! from one observer type; the feature keeps the integer step's code out of
//! an `f32` firmware, whose generated observer never asks for it (without
//! the feature such settings are refused).
//!
//! # A correction in two ticks
//!
//! On a core without an FPU a correction, about forty soft-float
//! operations (the screens, the gate, the update, the biases' floors), is
//! the heaviest thing a multi-rate model's tick can carry: 4 620
//! instructions at worst on the Cortex-M0 `network_roundtrip`, whose model
//! steps cost 3 760. With [`NetworkSettings::correction_in_two_ticks`] the
//! readings are screened, gated and fused on their tick, and the end of
//! the correction, the biases' floors and their check against the model's
//! uncertainty ([`InputFlags::HEAT_BIAS_BEYOND_MODEL`]), waits for the
//! next tick, where it runs before anything else: before that tick's
//! currents are taken (the floors are at the Joule power of the currents
//! the correction saw), its model step and its own correction. So every
//! step and every correction starts from the estimate the one-tick
//! correction would have left, to the bit
//! (`a_correction_in_two_ticks_is_the_same_estimate`: 400 s with readings
//! on every phase of the step and a dozen in a row, with 10 ms and 2 ms
//! steps, the start's warm-up and the integer step). What a firmware sees:
//! - the estimate is published on the second tick, complete; the first
//!   publishes the sensors' verdicts and `corrected`, and keeps the last
//!   temperatures;
//! - no protection stage runs on the first tick (it judges the finished
//!   estimate a tick later, not counted as one of a busy tick's waits), so
//!   a limit can come a tick later than with the one-tick correction;
//! - between the two ticks, [`NetworkObserver::temps_c`],
//!   [`NetworkObserver::heat_bias_w`], [`NetworkObserver::save`] and the
//!   state's fields read the fused estimate before its floors;
//! - the bias flag is raised on the second tick.
//!
//! Both ticks are light ones on the Cortex-M0 example: its worst tick fell
//! to 3 863 instructions (a predictor stage's; the fusion's tick 3 209,
//! the floors' under 1 000). It needs a model step longer than the loop's
//! tick: otherwise the second tick always steps and carries the floors as
//! well, so the setting is refused there. It is refused on a target with
//! an FPU too, whose observer compiles no second tick: there the whole
//! correction is a light tick (about 600 instructions on the M4F), and the
//! second tick's test cost every tick (the M4F network's mean 299 -> 328
//! in a first version).
//!
//! # No model refresh, no single-sensor rule
//!
//! The Omnimagnet observer refuses a sensor set that a single fault leaves
//! a solenoid without a thermocouple unless the firmware re-linearises its
//! model ([`OmniSettings::model_refresh_s`](super::OmniSettings::model_refresh_s)):
//! its plant is nonlinear (conductances that move with temperature), and
//! its build-time linearisation at the ambient is 3.7 K off a hot solenoid
//! left to the model alone. Here the network *is* linear: its conductances
//! and capacities are constants, and its one nonlinearity, `R(T)`, is taken
//! at the estimated winding temperature every step. There is no operating
//! point to go stale, so nothing to refresh and no such rule: a node left
//! to the model alone is off by the model's parameter error, which the
//! unmeasured margin ([`NetworkSettings::unmeasured_margin`]) and the doubt
//! rule's shadow bound cover (`drive-3node` at 6 A, one housing
//! thermocouple: every goal of the fault campaign met without a refresh,
//! docs/protection.md). A sensor set that
//! leaves a limited element unobservable is refused as ever
//! ([`BuildError::Unobservable`]).
//!
//! # Sensors against the physics
//!
//! The filter explains a disagreement between its model and a
//! thermocouple as a heat bias and a temperature correction, so a sensor
//! that lies slowly (detached and reading the room, stuck, drifting) drags
//! the estimate with it, and the innovation gate, judging the dragged
//! estimate, never sees it. So a *shadow* of the model runs beside the
//! filter: the same network from the same start at the measured currents
//! (`R(T)` at its own temperature) and boundaries, with no reading and no
//! bias, advanced by the exact zero-order hold of one correction period
//! ([`ShadowTables`]; the period's mean `I^2`, the rounding carried).
//! Before a correction, a reading colder than
//! `shadow - (consistency_offset_k + consistency_fraction * max(0, shadow - ambient))`
//! (defaults 3 K and 0.25: the model's uncertainty, a fixed part and a
//! share of the rise) is not fused and is reported as
//! [`SensorStatus::ColderThanPhysics`]. Hotter readings are fused as ever:
//! a model that runs cold must be corrected by its sensors, and erring hot
//! is the safe side. When every reading of a correction is colder than
//! physics (all sensors agree with each other and not with the physics: a
//! common-mode fault), the estimate is raised to the shadow wherever it is
//! below it, the negative heat biases are dropped, and the tick is flagged
//! [`InputFlags::SENSORS_COLDER_THAN_PHYSICS`]: the protection then runs on
//! the model until a sensor agrees with it again. A reading that repeats
//! its value (to the bit) while the shadow at its node has moved by more
//! than [`SensorChecks::stuck_threshold_k`] (1 K) within 120 s, or
//! since the reading last changed by more than that plus the band's share
//! of the node's rise then, is stuck ([`SensorStatus::Stuck`]) and not
//! fused until it moves: a test that does not lean on the estimate the
//! sensor drags. A reading the gate
//! refused twice in a row, colder than the estimate and the shadow, is held
//! out of the gate's recovery while it keeps drifting colder than the
//! shadow (the estimate raised to the shadow when nothing else is fused),
//! and while any sensor is in doubt every limited element is protected on
//! the hotter of the estimate's and the shadow's upper bound (see
//! docs/protection.md). Its cost: a block step
//! (`N^2 + N (M + B)` multiply-adds) once per correction period.
//!
//! Two rules keep a lying sensor from teaching the model's *heat*, which
//! outlasts the lie: the heat biases explain a sensor's disagreement for
//! as long as the model runs, so what one learns from a sensor that is
//! dropped stays in the estimate.
//! * **No heat taken away by default.** After each correction every bias is
//!   projected onto its floor, `-max_cooling_bias_fraction * P_m` (default
//!   0), with the temperatures by their regression on it
//!   ([`project_onto_floor`](crate::filter::project_onto_floor)): a reading
//!   colder than the model still corrects the temperatures, never the heat.
//!   With one sensor a cold drift and a model that runs hot look the same,
//!   and the safe reading of the two is the hot one. Measured in the fault
//!   campaign (`drive-3node`, one housing thermocouple drifting -0.05 K/s at
//!   6 A): the hot spot read 28.8 K cold with a free bias, 0.72 K off with
//!   the floor. A model known to run hot declares the share by which it may
//!   ([`NetworkSettings::max_cooling_bias_fraction`]).
//! * **A stuck sensor gives back what it taught.** When the stuck test
//!   sees a sensor, the biases go back to their values when its reading
//!   last changed ([`condition_on`](crate::filter::condition_on)): on the
//!   same trace with the housing sensor stuck at 1800 s while the drive
//!   cooled, the hot spot read 6.3 K hot an hour on; now 0.9 K after the
//!   verdict.
//!
//! # One sensor sees one heat: the shared bias
//!
//! A heat-input bias per current needs sensors that can tell the
//! currents' heat apart: three phases of a winding under one housing
//! thermocouple cannot (the most common device there is), the three bias
//! random walks are not observable apart and no steady gain exists
//! ([`BuildError::NotConverged`]). So by default ([`BiasMode::Auto`]) the
//! builder solves the per-source gain first and, when it does not
//! converge (or converges only to rounding, to biases so uncertain that a
//! limited element would be refused as unobservable, as a network padded
//! to a size class can), gives the biased sources **one heat bias shared
//! in proportion to their Joule power** instead: the state keeps one bias entry per
//! source (`X = N + M`, the tables' shapes unchanged), the process noise of
//! the bias block is the rank one `q w w^T`, `w_m` each source's share of
//! the nominal Joule power (its hardware limit squared times `R` at the
//! origin temperature), so the solved biases stay proportional to `w` (the
//! gain is solved in reduced coordinates, the shared bias in one slot). The
//! prior's bias block is written as the exact outer product of its
//! diagonal's square roots, which is how [`NetworkObserver::from_parts`]
//! and a generated module know the layout without another table.
//!
//! On the tick, after each correction, the sum of the shared biases is
//! redistributed among the shared sources in proportion to their present
//! Joule power (`I^2 R(T)` at the estimate, plus `1e-4` of the nominal
//! power so that with no current, or current-sensor noise at standstill,
//! the shares stay at `w`): heat a model misses with a resistance or a
//! loss that scales with the power goes where the power is, so a held
//! rotor's phase at twice the current of the other two gets four times the
//! missing heat and its estimate is not read cold (measured, three phases
//! under a housing thermocouple, every phase resistance 20 % high, a held
//! rotor at 14, 7, 7 A: the hottest phase within 0.11 K once settled and
//! its upper bound never below the plant, against 2.0 K cold with the
//! shares frozen at `w` and 18 K open loop; `host-tests/tests/shared_bias.rs`).
//! The floors hold per source (the shared sum is projected onto the sum of
//! the sources' floors, which with the biases in proportion to the present
//! powers is each source's floor), a stuck sensor gives back the shared
//! sum it taught, and the heat-bias alarm judges each source's share.
//!
//! Its limits: the sensors see one heat, so how it divides between the
//! sources is an assumption (in proportion to the power), not a
//! measurement. Heat that is not proportional to the Joule power (a
//! bearing, iron losses, a neighbour) is put on the phases carrying the
//! current, and while the currents change the filter's fixed gain was
//! solved for the nominal shares, not the present ones. When one source's
//! heat is what the model misses (a winding in a device whose other
//! sources are well known), name it alone in
//! [`NetworkObserverBuilder::bias_sources`]: that is the better choice,
//! and on a real motor's recording a shared copper bias was once measured
//! worse than the winding's bias alone. The shared bias is the default
//! whose job is to build and to err hot. Per-source biases stay the
//! default wherever they converge (every such table is what it was, to
//! the bit); [`BiasMode::PerSource`] refuses instead of sharing and
//! [`BiasMode::Shared`] (or [`NetworkObserverBuilder::shared_bias`]) asks
//! for a shared bias on chosen sources; `bias_sources` wins over both (a
//! source left out has no bias, shared or not).
//!
//! # Heat biases that fade: a correlation time
//!
//! By default each heat bias is a random walk: what it learns stays until a
//! reading says otherwise. [`NetworkSettings::bias_tau_s`] makes it a
//! first-order Gauss-Markov process instead (decaying towards zero with
//! that time constant, its steady standard deviation
//! `sqrt(bias_noise_w2_per_s * bias_tau_s / 2)`): for a device whose
//! missing heat is a bounded share of a loss that comes and goes (a
//! motor's copper at changing load), heat learnt under load fades at
//! standstill. The mean decays once per correction period by one
//! exponential (test `a_heat_bias_with_a_correlation_time_decays_towards_zero`
//! in `host-tests/tests/boundary_offset.rs`: `exp(-1)` after one `tau`, to
//! 0.1 %). A decaying bias need not be observable for the steady gain to
//! exist, so with it [`BiasMode::Auto`] keeps a bias per source where the
//! sensors cannot tell them apart; ask for the shared one with
//! [`NetworkObserverBuilder::shared_bias`].
//!
//! # A boundary offset that never cools
//!
//! A boundary's thermocouple may read below the temperature the network's
//! links see (a water outlet's against the water in the jacket: on the real
//! motor of docs/hust.md the stator sits up to 3.7 K above the outlet at
//! rest, where no heat explains it). One sensor cannot tell that from heat
//! in the winding, and the heat bias takes it for copper heat, which reads
//! an unseen winding hot (15 K on a water-cooled housing behind a coolant
//! reading 3 K low, test
//! `a_boundary_offset_keeps_a_warm_coolant_from_passing_for_copper_heat`).
//! [`NetworkSettings::boundary_offset`] adds one state (`X = N + M + 1`):
//! an offset added to that boundary's reading in the model step, a
//! first-order Gauss-Markov process (`boundary_offset_std_k`,
//! `boundary_offset_tau_s`: a few K, hours), kept at or above 0 after every
//! correction: it may warm the boundary the network sees, never cool it
//! below its reading, as a heat bias may add heat and not take it away.
//! The heat biases' floors and the offset's move each other through their
//! regressions (a warmer coolant and more copper heat explain the same
//! reading), so they are projected in turn, eight times, the biases' last:
//! the biases hold their floors exactly, the offset to within a few
//! hundredths of a kelvin (0.03 K in the test below). Tested against an
//! `f64` plant whose coolant stands 3 K above its reading: the offset
//! converges on 2.98 K and the unseen winding to 3e-5 K with the heat bias
//! frozen, and behind a reading 3 K *high* the offset stays at 0 and the
//! winding is no colder than without the state
//! (`host-tests/tests/boundary_offset.rs`). Its cost: one more state in
//! every table (`(N + M + 1)^2` for the covariances) and eight floor
//! projections a correction.
//!
//! # Readings, clock, snapshots
//!
//! As for [`OmniObserver`](super::OmniObserver): readings arrive as
//! [`TimedReading`]s and are reported per sensor as [`SensorStatus`]; the
//! elapsed time is turned into whole steps by the [`StepClock`] (at most
//! `max_steps_per_tick`, the rest dropped and flagged); a snapshot holds the
//! node temperatures and the latched shutdown, the biases restart at zero.
//!
//! # Sizes
//!
//! The observer is [`NetworkObserverOf`]`<Z, X, P>` over the network's
//! [`Sizes`] `Z`, its filter's states `X` and its sensors `P`;
//! [`NetworkObserver`]`<N, B, M, X, P>` is the one an MCU flashes, every
//! size a `Const` (arrays and `SMatrix`es, placed by the compiler). The
//! state, the tick (model step, correction, protection's stages), the
//! solve and the assembly are written once, for every size; with the
//! `alloc` feature a host builds `RunTimeObserver`, the observer of `Dyn`
//! sizes, at a model file's own size (`run_time.rs`: a 300-node, 72-source
//! motor in `host-tests/tests/run_time_network.rs`), the start, the
//! restores and the snapshot included (see [`crate::sizes`]).
//!
//! # Where the code is
//!
//! This file: the settings, the builder, the configuration and state
//! types, and the tick (the hot path's entry: `tick`, `tick_voltage`).
//! Beside it, one file a concept: `model_step.rs` (the model step and
//! the biases' decay), `correct.rs` (the readings' screens and the
//! fusion), `protection.rs` (the protection's stages), `restart.rs`
//! (save, restores, start), `resistance.rs` (a winding as its own
//! sensor), `bias.rs` (the heat biases' layout), `solve.rs` (the build's
//! solve: model, gain, predictor), `parts.rs` (the solved tables an MCU
//! keeps in flash), `assemble.rs` (an observer from them) and
//! `run_time.rs` (the observer at a model's own size).

use crate::sizes::{
    BoundaryVector, ConstSizes, InputVector, Length, NetworkAllocator, NodeVector, Sizes,
};
use nalgebra::{Const, DefaultAllocator, Dim, OMatrix, OVector, SMatrix, U1};

use super::clock::{step_square_currents, ClockState, StepAccount, StepClock};
use bias::{
    condition_shared_sum, present_shares, set_shared, shared_sum_w, BiasFloors, SharedColumn,
};

use super::consistency::{
    protect_on_shadow, screen_readings, sensor_doubt, BlockMean, DriftHold, GateView, Shadow,
    ShadowState, SilenceWatch, StuckEvents, StuckRewind, StuckTest, StuckWatch, Suspicion,
};
use super::cycle::aged_time_to_limit;
use super::cycle::{
    record_verdicts, sample_readings, AmbientLimits, Latch, Protecting, ProtectionCycle,
    ProtectionStages,
};
use super::snapshot::{self, Restored, SnapshotError, SnapshotMeta};
use super::start;
use super::vocabulary::{
    ConstOutputs, FilteredOutputs, SensorChecks, SensorStatus, TimedReading, EVENT_CAPACITY,
};
use super::warm_up::Flavour;
#[cfg(feature = "integer-step")]
use crate::discretize::fixed::{step_in_memory, StepMemory};
use crate::discretize::zoh;
use crate::error::{check, BuildError};
use crate::filter::{
    predict_cov, update, update_steady, FilterAllocator, KalmanConfig, KalmanState, SteadyEstimate,
    SteadyStateGain,
};
use crate::input::{DriveFlags, VoltageDrive};
use crate::input::{InputFlags, ScalarLimits};
use crate::network::{
    compensated_add, state_space_of, DeviationResistance, Network, NetworkDescription,
    ScalarResistance,
};
use crate::protect::alarm::{AlarmConfig, AlarmState, AlarmStatus, ResetError};
use crate::protect::derating::DeratingRule;
use crate::protect::events::EventQueue;
use crate::protect::limiter::{drive_limit, DriveLimit};
use crate::protect::limiter::{CoilLimit, LimiterConfig};
use crate::protect::margin::{UncertaintyMargin, UpperBound};
use crate::protect::predict::{
    Answers, HalfElement, KeptAnswers, ModalPredictor, OperatingPoint, PredictorState,
};

/// Alternating projections of the heat biases' and the boundary offset's
/// floors after a correction (see [`NetworkSettings::boundary_offset`]).
const FLOOR_PASSES: usize = 8;

pub use super::tables::PREDICTOR_POINTS;
/// The critical temperature given to elements without a limit \[degC\]
/// (the alarm needs a finite one, and so does the time-to-limit predictor
/// on a winding's node, whose power it takes at the node's limit): never
/// reached by a device that works. The predictor skips any other node
/// without a limit (its answer is "never", at no cost), so that a sweep
/// ends once the limited elements are resolved.
pub const NO_LIMIT_C: f64 = 1000.0;

/// Build settings, each with a default ([`NetworkSettings::DEFAULT`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NetworkSettings {
    /// Model step \[us\]. Default 1000. Several ticks long, the steps
    /// take the mean `I^2` of their ticks (see "Model step and ticks" in
    /// the module docs); set [`Self::loop_period_us`] to the loop's tick.
    pub step_us: u32,
    /// The control loop's nominal tick \[us\]. Default 0: the loop ticks at
    /// the model step ([`Self::loop_tick_us`]). A model step longer than
    /// it (the multi-rate model) makes every tick that runs a step busy, as
    /// a catch-up is, and the protection's stages wait out busy ticks (see
    /// "Model step and ticks" in the module docs). With `step_us` equal to
    /// it nothing changes.
    pub loop_period_us: u32,
    /// Catch-up bound, model steps per tick. Default 4.
    pub max_steps_per_tick: u32,
    /// Thermocouple noise standard deviation \[K\]. Default 0.25 (as
    /// [`OmniSettings`](super::OmniSettings), for the same reason: the
    /// gate judges the first readings against the converged covariance).
    pub sensor_sigma_k: f64,
    /// Growth rate of each node's temperature variance \[K^2/s\] (model
    /// error in its heat balance). Default 1e-4.
    pub node_noise_k2_per_s: f64,
    /// Growth rate of each heat-input bias variance \[W^2/s\] (of the
    /// shared bias's, the sum of the shared sources', when the sensors
    /// cannot tell the currents' heat apart: see "One sensor sees one
    /// heat" in the module docs). Default 1e-3. 0 freezes the biases at
    /// zero.
    pub bias_noise_w2_per_s: f64,
    /// Correlation time of the heat-input biases \[s\] (finite, `>= 0`):
    /// each bias is a first-order Gauss-Markov process that decays towards
    /// zero with this time constant, driven by `bias_noise_w2_per_s`, so
    /// its steady standard deviation is `sqrt(bias_noise_w2_per_s *
    /// bias_tau_s / 2)` \[W\]. Default 0: no decay, a random walk (every
    /// table as before this setting, to the bit). A device whose missing
    /// heat is a bounded share of a loss that comes and goes (a motor's
    /// copper at changing load) sets it: with a random walk, heat learnt
    /// under load stays in the estimate at standstill, where no loss
    /// explains it; and a decaying bias keeps the steady gain solvable when
    /// the sensors cannot tell every bias apart (a decaying state need not
    /// be observable). The mean decays once per correction period (one
    /// exponential), the covariance every step.
    pub bias_tau_s: f64,
    /// The boundary whose temperature the network sees may stand above its
    /// reading by an estimated offset (see "A boundary offset that never
    /// cools" in the module docs); `None` (default): no offset state. With
    /// `Some(b)` the filter state has one more entry, `X = N + M + 1`.
    pub boundary_offset: Option<usize>,
    /// Steady standard deviation of the boundary offset \[K\] (finite,
    /// `> 0` with an offset). Default 2.
    pub boundary_offset_std_k: f64,
    /// Correlation time of the boundary offset \[s\] (finite, `> 0` with
    /// an offset): a first-order Gauss-Markov process. Default 7200.
    pub boundary_offset_tau_s: f64,
    /// Standard deviation the gate's recovery widens each temperature by
    /// \[K\]. Default 10.
    pub recovery_sigma_k: f64,
    /// Standard deviation the gate's recovery widens each bias by \[W\].
    /// Default 5.
    pub recovery_bias_sigma_w: f64,
    /// Time between thermocouple samples \[s\] the steady gain is solved
    /// for. Default 0.5.
    pub correction_period_s: f64,
    /// Gate threshold on `nu^2 / S` (chi-square, 1 dof). Default
    /// [`CHI2_1DOF_999`](crate::filter::CHI2_1DOF_999).
    pub gate_threshold: f64,
    /// Consecutive rejections before a sensor is suspect. Default 2.
    pub suspect_after: u16,
    /// Consecutive all-rejected corrections before recovery. Default 5.
    pub recover_after: u16,
    /// Oldest reading still fused \[us\]. Default 100 000.
    pub max_reading_age_us: u32,
    /// Width of the limiter's taper band \[K\]. Default 10.
    pub taper_k: f64,
    /// Model steps per protection cycle, at least `4 max_steps_per_tick`.
    /// Default 16.
    pub protect_period_steps: u32,
    /// Steady-state standard deviations in the upper bound (finite,
    /// `>= 0`). Default 3.
    pub k_sigma: f64,
    /// Model-uncertainty margin of the nodes no sensor measures, on their
    /// rise above the ambient. Default 5 % of the rise
    /// ([`UncertaintyMargin::OMNIMAGNET_UNMEASURED_20_PERCENT`], measured
    /// for the Omnimagnet at +-20 % parameter error: measure your own
    /// device's, see [`crate::protect::margin`]).
    pub unmeasured_margin: UncertaintyMargin,
    /// Least steady-state sensitivity `dT_i/dP_m`, as a fraction of element
    /// `i`'s largest, for current `m` to count as heating element `i` in
    /// the default incidence (dimensionless, in `(0, 1]`). Default 0.1.
    pub incidence_fraction: f64,
    /// The origin of the deviation coordinates and the nominal ambient
    /// \[degC\] (any value near the working range; the carry makes the
    /// choice a matter of a few bits). Default 20.
    pub origin_c: f64,
    /// Which boundary is the ambient (the derating's and the margin's
    /// reference). Default 0.
    pub ambient_boundary: usize,
    /// Consecutive ticks without elapsed time from which every tick is
    /// flagged [`InputFlags::CLOCK_FROZEN`] (see [`super::clock`]). Default
    /// 100 (0.1 s at a 1 ms loop).
    pub frozen_flag_ticks: u32,
    /// Corrections run by the time-varying filter before the steady gain
    /// takes over (the optional time-varying path): from the steady prior
    /// widened by the recovery variances (`recovery_sigma_k`,
    /// `recovery_bias_sigma_w`), each model step propagates the full
    /// covariance (`(N + M)^3` multiply-adds) and each correction is a
    /// sequential Joseph update, so a start that is far off (a
    /// conservative start, an uncooled restore) is pulled in within a few
    /// corrections rather than the steady gain's time constants. Armed in
    /// a state by [`NetworkObserver::with_warm_up`] (a state of
    /// [`NetworkObserver::state`] or a restore runs no warm-up until then:
    /// see [`WarmUpKind`]). Default 0 (steady gain from the first
    /// correction).
    pub warmup_corrections: u16,
    /// Largest plausible current magnitude \[A\]: beyond it a current is
    /// clamped and flagged (`InputFlags::CURRENT_CLAMPED`). Default 100
    /// ([`InputLimits::default`](crate::InputLimits)); a 400 A motor
    /// drive sets its own.
    pub max_current_a: f64,
    /// The checks the sensors are held to against the physics and the
    /// bound on what they leave uncertain (see "Sensors against the
    /// physics"). Default [`SensorChecks::DEFAULT`].
    pub checks: SensorChecks,
    /// Largest heat the thermocouples may explain away, as a share of each
    /// current's Joule power at the estimate (dimensionless, finite,
    /// `>= 0`): the floor of each heat-input bias is `-fraction * P_m`.
    /// Default 0: a reading colder than the model corrects the
    /// temperatures, never the model's heat, so a sensor drifting or stuck
    /// cold cannot drag the estimate below the model (one sensor cannot
    /// tell that from a model that runs hot; see "Sensors against the
    /// physics"). A model whose heat is over-predicted then reads hot
    /// (a model 10 % hot, one housing thermocouple, 8 A: the unmeasured
    /// winding 1.12 K hot after 2 h, no reading refused; with a share of
    /// 0.2, on the plant): give the share by which it may be, e.g. 0.1 for
    /// 10 %.
    pub max_cooling_bias_fraction: f64,
    /// Consecutive ticks without elapsed time from which the model is taken
    /// as lost: the shutdown latches with a
    /// [`ClockFrozen`](crate::protect::events::EventKind::ClockFrozen)
    /// event. At least `frozen_flag_ticks`. Default 1000 (1 s).
    pub frozen_loss_ticks: u32,
    /// The model step in integer arithmetic
    /// ([`FixedStep`](crate::discretize::fixed::FixedStep), see "The model
    /// step in integer arithmetic" in [`super::network`]): for a core
    /// without an FPU, where each `f32` multiply-add of the step is a
    /// software routine. Needs the `integer-step` feature (refused
    /// without). Default `false`: the `f32` step, cheaper with an FPU. The
    /// filter, the bound and the protection are `f32` either way.
    pub integer_model_step: bool,
    /// At most this many element evaluations of the time-to-limit
    /// predictor per protection stage (0, the default: a whole horizon,
    /// every limited element, per stage). With a bound, a horizon whose
    /// elements are more is split over stages and the sweep's snapshot
    /// takes three stages of its own (the windings' part of the steady
    /// state, its boundaries' part, then the modal amplitudes): the
    /// answers are the same, a sweep takes more stages
    /// (`elements` of them a horizon instead of one). For a
    /// core where one horizon's soft-float work is the worst tick (a
    /// Cortex-M0: 1 takes the real motor's worst tick from 86 493 to
    /// 63 389 instructions). 1, the smallest stage, takes each element's
    /// horizon in two (its modal parts, then its crossing; held in the
    /// state): the same answers to the bit, each horizon in twice the
    /// stages (`network_roundtrip` on the Cortex-M0: its ticks without a
    /// reading 4 906 -> 3 826 instructions at worst).
    pub predictor_elements_per_stage: u16,
    /// A correction in two ticks (see "A correction in two ticks" in
    /// [`super::network`]): the readings' fusion on the tick they arrive,
    /// the biases' floors and the bias check on the next tick, before
    /// anything else of it. The same estimate to the bit, published on the
    /// second tick. For a core without an FPU, where the whole correction
    /// was the heaviest tick (`network_roundtrip` on the Cortex-M0: its
    /// worst tick 4 620 -> 3 863 instructions). Refused where it does not
    /// apply: on a target with an FPU (`target_abi = "eabihf"`, which
    /// compiles no second tick), and with a model step no longer than the
    /// loop's tick (the second tick would always step). Default `false`:
    /// the whole correction on one tick.
    pub correction_in_two_ticks: bool,
}

impl NetworkSettings {
    /// The loop's tick \[us\]: [`Self::loop_period_us`], or the model
    /// step where it is 0.
    pub const fn loop_tick_us(&self) -> u32 {
        if self.loop_period_us == 0 {
            self.step_us
        } else {
            self.loop_period_us
        }
    }

    /// The defaults (see each field).
    pub const DEFAULT: Self = Self {
        step_us: 1000,
        loop_period_us: 0,
        max_steps_per_tick: 4,
        sensor_sigma_k: 0.25,
        node_noise_k2_per_s: 1e-4,
        bias_noise_w2_per_s: 1e-3,
        bias_tau_s: 0.0,
        boundary_offset: None,
        boundary_offset_std_k: 2.0,
        boundary_offset_tau_s: 7200.0,
        recovery_sigma_k: 10.0,
        recovery_bias_sigma_w: 5.0,
        correction_period_s: 0.5,
        gate_threshold: crate::filter::CHI2_1DOF_999,
        suspect_after: 2,
        recover_after: 5,
        max_reading_age_us: 100_000,
        taper_k: 10.0,
        protect_period_steps: 16,
        k_sigma: 3.0,
        unmeasured_margin: UncertaintyMargin::OMNIMAGNET_UNMEASURED_20_PERCENT,
        incidence_fraction: 0.1,
        origin_c: 20.0,
        ambient_boundary: 0,
        warmup_corrections: 0,
        max_current_a: 100.0,
        checks: SensorChecks::DEFAULT,
        max_cooling_bias_fraction: 0.0,
        frozen_flag_ticks: super::clock::DEFAULT_FROZEN_FLAG_TICKS,
        frozen_loss_ticks: super::clock::DEFAULT_FROZEN_LOSS_TICKS,
        integer_model_step: false,
        predictor_elements_per_stage: 0,
        correction_in_two_ticks: false,
    };
}

impl Default for NetworkSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The inputs of one tick, for `B` boundaries, `M` currents and `P`
/// sensors, each a dimension (`Const` on an MCU: [`NetworkInputs`], `Copy`
/// there).
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkInputsOf<B: Length, M: Length, P: Length> {
    /// Currents \[A\]; NaN holds the last valid one, beyond the input limits
    /// they are clamped (both flagged).
    pub currents_a: M::Array<f32>,
    /// Boundary temperatures \[degC\]; an invalid one holds the last valid.
    pub boundary_c: B::Array<f32>,
    /// Fresh readings, one slot per sensor (the builder's `sensor_nodes`).
    pub readings: P::Array<Option<TimedReading>>,
    /// Now, on the readings' microsecond clock \[us\] (wrapping).
    pub now_us: u32,
    /// Measured time since the previous tick \[us\].
    pub elapsed_us: u32,
}

impl<B: Length, M: Length, P: Length> Copy for NetworkInputsOf<B, M, P>
where
    B::Array<f32>: Copy,
    M::Array<f32>: Copy,
    P::Array<Option<TimedReading>>: Copy,
{
}

/// The inputs of one tick of a network of `B` boundaries and `M` currents
/// with `P` sensors, on an MCU.
pub type NetworkInputs<const B: usize, const M: usize, const P: usize> =
    NetworkInputsOf<Const<B>, Const<M>, Const<P>>;

/// What one tick produced (`Copy`, for [`Shared`](super::Shared)): the
/// filtered observers' outputs, a time to limit for every node.
pub type NetworkOutputs<const N: usize, const M: usize, const P: usize> = ConstOutputs<N, M, N, P>;

/// Builds a [`NetworkObserver`]: the network, the sensor map, the limits;
/// everything else has a default ([`NetworkSettings::DEFAULT`]).
#[derive(Debug, Clone)]
pub struct NetworkObserverBuilder<
    'a,
    const N: usize,
    const B: usize,
    const M: usize,
    const P: usize,
> {
    network: &'a Network<N, B, M>,
    sensor_nodes: [usize; P],
    critical_c: [Option<f64>; N],
    incidence: Option<[[bool; M]; N]>,
    hardware_limit_a: [f64; M],
    rule: DeratingRule,
    settings: NetworkSettings,
    bias_sources: [bool; M],
    bias_mode: BiasMode<M>,
    sensor_kinds: [SensorKind; P],
    /// [`Self::resistance_sensor`] named a sensor that does not exist.
    bad_sensor: bool,
}

impl<'a, const N: usize, const B: usize, const M: usize, const P: usize>
    NetworkObserverBuilder<'a, N, B, M, P>
{
    /// Starts a builder for `network` with thermocouple `j` on node
    /// `sensor_nodes[j]`.
    pub fn new(network: &'a Network<N, B, M>, sensor_nodes: [usize; P]) -> Self {
        Self {
            network,
            sensor_nodes,
            critical_c: [None; N],
            incidence: None,
            hardware_limit_a: [8.0; M],
            rule: DeratingRule::omnimagnet(),
            settings: NetworkSettings::DEFAULT,
            bias_sources: [true; M],
            bias_mode: BiasMode::Auto,
            sensor_kinds: [SensorKind::Thermocouple; P],
            bad_sensor: false,
        }
    }

    /// Sensor `sensor` is the winding resistance `resistance` of one of the
    /// network's sources (see [`resistance`]): its node becomes that
    /// source's node, its noise the sensor's own, and its readings come
    /// from [`NetworkObserver::resistance_reading`]. An index beyond the
    /// sensors is refused at build (`resistance_sensor`).
    pub fn resistance_sensor(mut self, sensor: usize, resistance: ResistanceSensor) -> Self {
        match (
            self.sensor_kinds.get_mut(sensor),
            self.sensor_nodes.get_mut(sensor),
        ) {
            (Some(kind), Some(node)) => {
                *kind = SensorKind::Resistance(resistance);
                *node = resistance.node;
            }
            _ => self.bad_sensor = true,
        }
        self
    }

    /// What each sensor is (default: every one a thermocouple). A
    /// resistance sensor must read its source's node in the sensor map.
    pub fn sensor_kinds(mut self, kinds: [SensorKind; P]) -> Self {
        self.sensor_kinds = kinds;
        self
    }

    /// Each element's critical temperature \[degC\] (the lowest its
    /// materials bear), `None` for no limit. Default: none (an observer
    /// that estimates and never limits).
    pub fn critical_c(mut self, critical_c: [Option<f64>; N]) -> Self {
        self.critical_c = critical_c;
        self
    }

    /// The derating rule of the alarm limits. Default: model error 0.9,
    /// unknown conditions 0.9, safety 0.8 (product 0.648, the HPPA rule
    /// without its magnet-plate factor, [`DeratingRule::omnimagnet`]).
    pub fn derating(mut self, rule: DeratingRule) -> Self {
        self.rule = rule;
        self
    }

    /// Each current's hardware limit \[A\]. Default 8 A each.
    pub fn hardware_limit_a(mut self, limit_a: [f64; M]) -> Self {
        self.hardware_limit_a = limit_a;
        self
    }

    /// Which currents each element's limit derates (`incidence[i][m]`:
    /// current `m` heats element `i`). Default: from the network's
    /// steady-state sensitivities (see the module docs).
    pub fn incidence(mut self, incidence: [[bool; M]; N]) -> Self {
        self.incidence = Some(incidence);
        self
    }

    /// All other settings.
    pub fn settings(mut self, settings: NetworkSettings) -> Self {
        self.settings = settings;
        self
    }

    /// Which currents carry a heat-input bias state (`bias_sources[m]`:
    /// current `m`'s bias is estimated). Default: every one.
    ///
    /// A current left out keeps its bias at exactly zero: no process noise
    /// (`bias_noise_w2_per_s`), no recovery widening
    /// (`recovery_bias_sigma_w`) and no initial variance, so the steady
    /// solution holds its variance and gain rows at zero and the heat-bias
    /// alarm never sees it. Leave out a source whose bias no sensor can see
    /// (an unobservable random walk has no steady gain:
    /// [`BuildError::NotConverged`]) and padding sources that carry no
    /// current (a network padded to a size class), while the others keep
    /// their biases; `bias_noise_w2_per_s = 0` freezes all of them. Sources
    /// the sensors see but cannot tell apart need no naming: by default
    /// they share one bias ([`Self::bias_mode`]); naming the one whose heat
    /// the model misses is the better choice when it is known (see "One
    /// sensor sees one heat" in the module docs). This wins over
    /// [`Self::bias_mode`]: a source left out has no bias, shared or not.
    ///
    /// Only the solved tables change: a left-out bias has an exactly zero
    /// prior variance in [`GainTables`], which is how
    /// [`NetworkObserver::from_parts`] (and a generated module) knows it
    /// when `bias_noise_w2_per_s` is positive. Every source in gives the
    /// observer of a builder without this call, to the bit.
    pub fn bias_sources(mut self, bias_sources: [bool; M]) -> Self {
        self.bias_sources = bias_sources;
        self
    }

    /// Whether the biased sources' heat biases are estimated each on its
    /// own or shared (see "One sensor sees one heat: the shared bias" in
    /// the module docs). Default [`BiasMode::Auto`]: per source wherever
    /// the per-source steady gain converges (every table as before this
    /// setting existed, to the bit), else one heat bias shared by every
    /// biased source in proportion to its Joule power.
    ///
    /// [`Self::bias_sources`] wins: a source left out of it has no bias in
    /// any mode, shared or not. Without bias noise
    /// (`bias_noise_w2_per_s = 0`) every mode is per source.
    pub fn bias_mode(mut self, mode: BiasMode<M>) -> Self {
        self.bias_mode = mode;
        self
    }

    /// [`Self::bias_mode`]`(`[`BiasMode::Shared`]`(shared))`: the sources
    /// `m` with `shared[m]` (and in [`Self::bias_sources`]) share one heat
    /// bias in proportion to their Joule power, the other biased sources
    /// keep their own.
    pub fn shared_bias(self, shared: [bool; M]) -> Self {
        self.bias_mode(BiasMode::Shared(shared))
    }

    /// [`Self::parts`] then [`NetworkObserver::from_parts`]: validates
    /// everything, discretises the network, solves the steady
    /// gain (in `f64`: `O((N + M)^3)` per doubling, tens of KiB of stack
    /// for N + M around 20) and builds the protection.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the parameter
    /// (`sensor_nodes`, `critical_c`, `incidence_fraction`,
    /// `ambient_boundary`, `origin_c`, `protect_period_steps`, a noise or
    /// the settings of the alarm, limiter, margin); those of the network
    /// ([`BuildError::MissingSource`], [`BuildError::Singular`] when a node
    /// has no path to a boundary), of the discretisation and of the gain
    /// solver ([`BuildError::NotConverged`] when the sensors cannot see a
    /// bias, shared or not, or cannot tell them apart under
    /// [`BiasMode::PerSource`]: name the biases they can see in
    /// [`Self::bias_sources`], or set `bias_noise_w2_per_s` to 0).
    pub fn build<const X: usize>(&self) -> Result<NetworkObserver<N, B, M, X, P>, BuildError> {
        NetworkObserver::new(self)
    }

    /// What each sensor is, as [`NetworkObserver::from_parts_with_sensors`]
    /// takes it beside [`Self::parts`].
    pub fn kinds(&self) -> [SensorKind; P] {
        self.sensor_kinds
    }
}

/// The nalgebra allocations of a network observer over the sizes `Z`, its
/// filter's states `X` and sensors `P`: the network's matrices and the
/// filter's (one bound, `DefaultAllocator: ObserverAllocator<Z, X, P>`;
/// every `Const` size has them).
pub trait ObserverAllocator<Z: Sizes, X: Dim, P: Dim>:
    NetworkAllocator<Z> + FilterAllocator<X, U1, P>
{
}

impl<Z: Sizes, X: Dim, P: Dim, A> ObserverAllocator<Z, X, P> for A where
    A: NetworkAllocator<Z> + FilterAllocator<X, U1, P>
{
}

/// The configuration of one device's observer (see the module docs) on
/// an MCU: `N` nodes, `B` boundaries, `M` currents, `X` filter states and
/// `P` sensors known when the firmware is compiled ([`NetworkObserverOf`]
/// of `Const` sizes). `X` must be `N + M`.
pub type NetworkObserver<
    const N: usize,
    const B: usize,
    const M: usize,
    const X: usize,
    const P: usize,
> = NetworkObserverOf<ConstSizes<N, B, M>, Const<X>, Const<P>>;

/// The configuration of one device's observer over the network's [`Sizes`]
/// `Z`, its filter's states `X` and its sensors `P` (dimensions: `Const`
/// on an MCU, [`NetworkObserver`]).
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone)]
pub struct NetworkObserverOf<Z: Sizes, X: Length, P: Length>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    /// `Ad - I` (dimensionless), formed in `f64`.
    phi_minus_i: OMatrix<f32, Z::NodeDim, Z::NodeDim>,
    /// `Bd` of the powers \[K/J\].
    bd_power: OMatrix<f32, Z::NodeDim, Z::InputDim>,
    /// `Gd` of the boundaries (dimensionless).
    gd_boundary: OMatrix<f32, Z::NodeDim, Z::BoundaryDim>,
    /// `dd + (Ad - I) T_0 + Gd T_0` \[K\], formed in `f64`.
    constant_k: OVector<f32, Z::NodeDim>,
    /// The model step in integer arithmetic, if the settings ask for it
    /// (see "The model step in integer arithmetic"; the field exists with
    /// the `integer-step` feature only, so an `f32` firmware's observer is
    /// laid out as before it).
    #[cfg(feature = "integer-step")]
    integer_step: Option<crate::discretize::fixed::FixedStep<Z>>,
    origin_c: f32,
    source_node: InputVector<Z, usize>,
    /// Each winding's `R` in the state's deviations from `origin_c`.
    resistance: InputVector<Z, DeviationResistance>,
    kalman: KalmanConfig<f32, X, U1, P>,
    gain: SteadyStateGain<f32, X, P>,
    sensor_nodes: P::Array<usize>,
    limited: NodeVector<Z, bool>,
    incidence: NodeVector<Z, InputVector<Z, bool>>,
    hardware_limit_a: InputVector<Z, f32>,
    alarm: AlarmConfig<f32, Z::NodeDim>,
    limiter: LimiterConfig<f32, Z::NodeDim>,
    predictor: ModalPredictor<f32, Z, PREDICTOR_POINTS>,
    bound: UpperBound<f32, Z::NodeDim>,
    /// The bound's `k` (of `k sigma`).
    k_sigma: f32,
    /// The steady `sigma` in each node's bound \[K\] (of the prior).
    bound_sigma_k: NodeVector<Z, f32>,
    shadow: Shadow<Z>,
    stuck_test: StuckTest,
    /// No reading for this long makes a sensor silent \[us\]: two
    /// correction periods.
    silent_after_us: u32,
    warmup_corrections: u16,
    /// `max_cooling_bias_fraction` (dimensionless).
    cooling_bias_fraction: f32,
    /// The biases' decay per model step, `step / bias_tau_s`
    /// (dimensionless; 0: random walks, no decay).
    bias_decay_per_step: f32,
    /// The boundary with an offset state (at `N + M`), if any.
    offset_boundary: Option<usize>,
    /// A bias or the offset decays (one test on the tick's path).
    decays: bool,
    /// [`NetworkSettings::correction_in_two_ticks`] (refused on a core
    /// with an FPU: see the state's `floors_due`).
    #[cfg(not(target_abi = "eabihf"))]
    correction_in_two_ticks: bool,
    /// The offset's decay per model step, `step / boundary_offset_tau_s`
    /// (dimensionless).
    offset_decay_per_step: f32,
    /// The sources sharing one heat bias (see "One sensor sees one heat").
    shared_bias: InputVector<Z, bool>,
    /// Each shared source's nominal Joule power \[W\] (0 for the others):
    /// its share of the shared bias with no current.
    nominal_power_w: InputVector<Z, f32>,
    clock: StepClock,
    limits: ScalarLimits<f32>,
    ambient_boundary: usize,
    max_reading_age_us: u32,
    step_us: u32,
    /// The loop's nominal tick \[us\] ([`NetworkSettings::loop_period_us`]).
    loop_period_us: u32,
    protect_period_us: u32,
    fingerprint: u32,
    // Last, so that the fields every tick reads keep their offsets (a
    // Cortex-M load reaches 1020 bytes from its base in one instruction).
    /// Each resistance sensor's conversion (`None`: a thermocouple).
    resistance_sensors: P::Array<Option<resistance::Conversion>>,
    /// How far below the shadow each sensor's screens take its node \[K\]:
    /// its noise at the gate's width (0 for a thermocouple).
    noise_allowance_k: P::Array<f32>,
}

/// The per-device state.
///
/// `W` says whether it can run the time-varying warm-up (see
/// [`WarmUpKind`]): [`NoWarmUp`] for the states of
/// [`NetworkObserver::state`], the `restore` methods and
/// [`NetworkObserver::conservative_state`], whose ticks are compiled
/// without the warm-up's code; [`WarmUp`] (the default) for those of
/// [`NetworkObserver::start`] and [`NetworkObserver::with_warm_up`], the one
/// type of a firmware that restores and falls back to a start.
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
///
/// On an MCU: [`NetworkObserverStateOf`] of `Const` sizes.
pub type NetworkObserverState<
    const N: usize,
    const B: usize,
    const M: usize,
    const X: usize,
    const P: usize,
    W = WarmUp<SMatrix<f32, X, X>>,
> = NetworkObserverStateOf<ConstSizes<N, B, M>, Const<X>, Const<P>, W>;

/// The per-device state over the network's [`Sizes`] `Z`, the filter's
/// states `X` and the sensors `P` (see [`NetworkObserverState`]).
///
/// Holds nalgebra matrices, which do not implement `defmt::Format`.
#[derive(Debug, Clone)]
#[repr(C)]
pub struct NetworkObserverStateOf<Z: Sizes, X: Length, P: Length, W = WarmUp<OMatrix<f32, X, X>>>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    // Laid out as declared (`repr(C)`), the fields every tick reads
    // first: on the Cortex-M4F a float load reaches 1 020 bytes from its
    // base, and a field beyond costs an address computation per access
    // (32 bytes more state ahead of them cost the real motor's plain tick
    // 26 instructions).
    /// The filter's estimate (deviations from the origin \[K\], then the
    /// heat-input biases \[W\]) and gate memory.
    pub estimate: SteadyEstimate<f32, X, P>,
    /// What each node's `f32` deviation could not hold \[K\] (the carry of
    /// [`compensated_add`]). Zero with the integer step, whose states carry
    /// it (see "The model step in integer arithmetic").
    pub residual_k: NodeVector<Z, f32>,
    /// The integer step's own states (with the `integer-step` feature).
    #[cfg(feature = "integer-step")]
    integer: StepMemory<Z::NodeDim>,
    held_currents_a: InputVector<Z, f32>,
    held_boundary_c: BoundaryVector<Z, f32>,
    /// The time not yet simulated.
    pub clock: ClockState,
    cycle: ProtectionCycle<Z::InputDim>,
    shadow: ShadowState<Z>,
    /// Model steps since the biases' means last decayed.
    bias_steps: u32,
    /// The heat biases' and the boundary offset's decay factors over one
    /// correction period (dimensionless), formed with the state: the
    /// period's two `expf` cost the model step's tick that closes it some
    /// 1 500 instructions on a core without an FPU.
    period_decay: [f32; 2],
    outputs: FilteredOutputs<Z::NodeDim, Z::InputDim, Z::NodeDim, P>,
    silence: SilenceWatch<P>,
    /// The predictor's sweep.
    pub predictor: PredictorState<f32, Z>,
    /// The predictor's element between its two stages, when its sweep
    /// takes one element a stage
    /// ([`NetworkSettings::predictor_elements_per_stage`]). Beside the
    /// predictor: last in the state, it cost the M4F three-phase
    /// example's mean 2 instructions (the layout), here none.
    predictor_half: HalfElement<f32>,
    /// The alarm's state.
    pub alarm: AlarmState<f32, Z::NodeDim>,
    /// Alarm events not yet drained.
    pub events: EventQueue<EVENT_CAPACITY>,
    stuck: StuckWatch<P>,
    /// The heat-input biases when each sensor's reading last changed:
    /// where a stuck sensor's biases go back to.
    rewind: StuckRewind<P, Z::InputDim>,
    drift: DriftHold<P>,
    /// The sensors whose measurement is in doubt.
    suspect: Suspicion<P>,
    /// The predictor's limits at the ambient they were formed at.
    mean_limits: AmbientLimits<Z::NodeDim>,
    /// The time-varying warm-up's covariance, while it runs, if this
    /// flavour holds one.
    warm: W,
    /// Corrections the warm-up has left (0 throughout in a flavour
    /// without one).
    warmup_left: u16,
    /// The warm-up ends once its covariance has settled (the start's, see
    /// [`super::start`]), not after a count.
    warmup_until_steady: bool,
    /// The energy account of the model step in progress (see "Model step
    /// and ticks" in the module docs).
    step_account: StepAccount<Z::InputDim>,
    /// The shadow's complete block that waits for a light tick (see
    /// [`Shadow::stepped`]; apart from `shadow`, out of the hot fields).
    shadow_waiting_block: Option<BlockMean<Z::InputDim>>,
    /// The derated alarm limits at the ambient they were formed at (the
    /// alarm's and the limiter's; a core without an FPU's alone).
    alarm_limits: KeptAlarmLimits<Z::NodeDim>,
    /// The second tick of a correction in two ticks, if due (see
    /// [`NetworkSettings::correction_in_two_ticks`]): whether its first
    /// tick ran the warm-up's covariance. Only on a core without an FPU:
    /// with one the field and its test cost every tick (the M4F
    /// three-phase example's worst 1 981 -> 1 990 instructions, the
    /// motor's mean 1 026 -> 1 028).
    #[cfg(not(target_abi = "eabihf"))]
    floors_due: Option<bool>,
}

impl<Z: Sizes, X: Length, P: Length, W> NetworkObserverStateOf<Z, X, P, W>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
{
    /// The outputs of the last tick.
    pub fn outputs(&self) -> &FilteredOutputs<Z::NodeDim, Z::InputDim, Z::NodeDim, P> {
        &self.outputs
    }

    /// Whether a correction in two ticks waits for its second
    /// ([`NetworkSettings::correction_in_two_ticks`]).
    #[inline(always)]
    const fn correction_unfinished(&self) -> bool {
        #[cfg(not(target_abi = "eabihf"))]
        if self.floors_due.is_some() {
            return true;
        }
        false
    }

    /// The shutdown's latch over this state (see [`Latch`]).
    fn latch(&mut self) -> Latch<'_, f32, Z::NodeDim, EVENT_CAPACITY> {
        Latch {
            alarm: &mut self.alarm,
            events: &mut self.events,
            published: &mut self.outputs.alarm,
            limits: self.outputs.limits.as_mut(),
        }
    }

    /// This state in the flavour `V`, holding `warm`.
    fn flavoured<V>(self, warm: V) -> NetworkObserverStateOf<Z, X, P, V> {
        // Field by field: `..self` cannot change a type parameter on
        // stable Rust (type-changing struct update is unstable).
        NetworkObserverStateOf {
            estimate: self.estimate,
            residual_k: self.residual_k,
            #[cfg(feature = "integer-step")]
            integer: self.integer,
            alarm: self.alarm,
            predictor: self.predictor,
            mean_limits: self.mean_limits,
            alarm_limits: self.alarm_limits,
            clock: self.clock,
            events: self.events,
            held_currents_a: self.held_currents_a,
            held_boundary_c: self.held_boundary_c,
            cycle: self.cycle,
            shadow: self.shadow,
            stuck: self.stuck,
            rewind: self.rewind,
            drift: self.drift,
            suspect: self.suspect,
            silence: self.silence,
            warm,
            warmup_left: self.warmup_left,
            bias_steps: self.bias_steps,
            period_decay: self.period_decay,
            warmup_until_steady: self.warmup_until_steady,
            outputs: self.outputs,
            step_account: self.step_account,
            shadow_waiting_block: self.shadow_waiting_block,
            #[cfg(not(target_abi = "eabihf"))]
            floors_due: self.floors_due,
            predictor_half: self.predictor_half,
        }
    }
}

/// The default incidence: current `m` heats element `i` when `dT_i/dP_m`
/// at steady state is at least `fraction` of element `i`'s largest.
///
/// # Errors
/// [`BuildError::Singular`] when some node has no path to a boundary;
/// [`BuildError::InvalidParameter`] (`incidence_fraction`) outside `(0, 1]`.
pub fn default_incidence<const N: usize, const B: usize, const M: usize>(
    network: &Network<N, B, M>,
    fraction: f64,
) -> Result<[[bool; M]; N], BuildError> {
    default_incidence_of(network, fraction)
}

/// `incidence[i][m]`: current `m` heats element `i`, over the network's
/// sizes `Z` (`[[bool; M]; N]` on an MCU).
pub type Incidence<Z> = NodeVector<Z, InputVector<Z, bool>>;

/// What one tick of a network observer of sizes `Z` with sensors `P`
/// produced ([`NetworkOutputs`] on an MCU).
pub type NetworkOutputsOf<Z, P> =
    FilteredOutputs<<Z as Sizes>::NodeDim, <Z as Sizes>::InputDim, <Z as Sizes>::NodeDim, P>;

/// [`default_incidence`] of any network description (a [`Network`], or
/// a model's network at its own size on a host).
///
/// # Errors
/// As [`default_incidence`].
pub fn default_incidence_of<W: NetworkDescription>(
    network: &W,
    fraction: f64,
) -> Result<Incidence<W::Sizes>, BuildError>
where
    DefaultAllocator: NetworkAllocator<W::Sizes>,
{
    check(fraction > 0.0 && fraction <= 1.0, "incidence_fraction")?;
    let sizes = network.sizes();
    let ss = state_space_of(network, &sizes.nodes_of(0.0));
    let inverse = (-ss.a).try_inverse().ok_or(BuildError::Singular)?;
    // dT/dP = (-A)^-1 B \[K/W\]: every entry >= 0 for a heat network.
    let sensitivity = inverse * ss.b_power;
    let m = sizes.inputs();
    Ok(sizes.node_dim().each(|i| {
        let largest = (0..m).fold(0.0f64, |a, k| a.max(sensitivity[(i, k)]));
        sizes
            .input_dim()
            .each(|k| largest > 0.0 && sensitivity[(i, k)] >= fraction * largest)
    }))
}

/// The state and the tick, written once for every size.
impl<Z: Sizes, X: Length, P: Length> NetworkObserverOf<Z, X, P>
where
    DefaultAllocator: ObserverAllocator<Z, X, P>,
    NodeVector<Z, Option<f32>>: KeptAnswers + Answers<f32, Z::NodeDim>,
{
    /// The configuration fingerprint that snapshots carry.
    pub fn fingerprint(&self) -> u32 {
        self.fingerprint
    }

    /// The model step \[s\].
    pub fn step_s(&self) -> f64 {
        self.clock.step_s()
    }

    /// Which currents each element's limit derates (`[i][m]`).
    pub fn incidence(&self) -> &NodeVector<Z, InputVector<Z, bool>> {
        &self.incidence
    }

    /// Each node's protective upper bound.
    pub fn upper_bound(&self) -> &UpperBound<f32, Z::NodeDim> {
        &self.bound
    }

    /// The steady-state gain in use (`f32`, solved in `f64`).
    pub fn gain(&self) -> &SteadyStateGain<f32, X, P> {
        &self.gain
    }

    /// The alarm configuration (per-element limits at an ambient).
    pub fn alarm(&self) -> &AlarmConfig<f32, Z::NodeDim> {
        &self.alarm
    }

    /// The network's sizes (nodes, boundaries, currents).
    pub fn sizes(&self) -> Z {
        self.predictor.sizes
    }

    /// A state with every node at `temps_c` \[degC\], zero biases, the
    /// boundaries at `boundary_c` \[degC\], no current, no alarm; limits
    /// valid from the first tick. It runs no warm-up ([`NoWarmUp`]): the
    /// steady gain from the first correction, and its ticks link none of
    /// the warm-up's code. [`Self::with_warm_up`] gives it the flavour of
    /// [`Self::start`](NetworkObserver::start)'s states, with the
    /// configured warm-up ([`NetworkSettings::warmup_corrections`]) if any.
    pub fn state(
        &self,
        temps_c: &NodeVector<Z, f32>,
        boundary_c: &BoundaryVector<Z, f32>,
    ) -> NetworkObserverStateOf<Z, X, P, NoWarmUp> {
        let sizes = self.sizes();
        let (states, _) = self.gain.prior().shape_generic();
        let (_, sensors) = self.gain.prior_ht().shape_generic();
        let mut x = OVector::<f32, X>::zeros_generic(states, U1);
        for (x, t) in x.iter_mut().zip(temps_c.as_ref()) {
            *x = *t - self.origin_c;
        }
        let mut held_boundary_c = sizes.boundaries_of(self.origin_c);
        let _ = self
            .limits
            .accept_temperatures(boundary_c.as_ref(), held_boundary_c.as_mut());
        let ambient_c = self.ambient(&held_boundary_c);
        let mut mean_limits = AmbientLimits::new(sizes.node_dim());
        let op = self.operating(
            &mut mean_limits,
            temps_c,
            &sizes.inputs_of(0.0),
            &held_boundary_c,
            ambient_c,
        );
        let shadow_dev_k = sizes.node_dim().each(|i| x[i]);
        let mut state = NetworkObserverStateOf {
            estimate: SteadyEstimate::for_sensors(x, sensors),
            residual_k: sizes.nodes_of(0.0),
            #[cfg(feature = "integer-step")]
            integer: if self.integer_step.is_some() {
                StepMemory::unread(sizes.node_dim())
            } else {
                StepMemory::new(sizes.node_dim())
            },
            alarm: AlarmState::new(&self.alarm),
            predictor: PredictorState::new(&self.predictor, &op),
            mean_limits,
            alarm_limits: KeptAlarmLimits::new(sizes.node_dim()),
            clock: ClockState::default(),
            events: EventQueue::new(),
            held_currents_a: sizes.inputs_of(0.0),
            held_boundary_c,
            // With a step several ticks long, the stages wait out a step's
            // tick, its shadow block's, a reading's and (with the integer
            // step) the reading's move into its states (see "Model step and
            // ticks").
            cycle: ProtectionCycle::new(sizes.input_dim()).with_busy_waits(
                if self.step_us > self.loop_period_us {
                    3 + u8::from(self.steps_in_integers()) + u8::from(self.corrects_in_two_ticks())
                } else {
                    0
                },
            ),
            shadow: ShadowState::new(&sizes, shadow_dev_k),
            warm: NoWarmUp,
            warmup_left: 0,
            bias_steps: 0,
            period_decay: self.decay_factors(self.gain.period),
            warmup_until_steady: false,
            step_account: StepAccount::new(sizes.input_dim()),
            shadow_waiting_block: None,
            #[cfg(not(target_abi = "eabihf"))]
            floors_due: None,
            predictor_half: HalfElement::new(),
            stuck: StuckWatch::new(sensors),
            rewind: StuckRewind::new(sensors, sizes.input_dim()),
            drift: DriftHold::new(sensors),
            suspect: Suspicion::new(sensors),
            silence: SilenceWatch::new(sensors),
            outputs: FilteredOutputs {
                temps_c: temps_c.clone(),
                upper_c: temps_c.clone(),
                limits: sizes.inputs_of(CoilLimit::default()),
                time_to_limit_s: sizes.nodes_of(None),
                alarm: AlarmStatus::default(),
                sensors: sensors.filled(SensorStatus::NoReading),
                corrected: false,
                flags: InputFlags::NONE,
                steps: 0,
                dropped_us: 0,
                tick: 0,
            },
        };
        self.bound.upper_c(
            &state.outputs.temps_c,
            ambient_c,
            &mut state.outputs.upper_c,
        );
        self.limit(&mut state.outputs, &mut state.alarm_limits, ambient_c);
        state
    }

    /// `state` in the flavour that can run the time-varying warm-up
    /// ([`WarmUp`], what [`Self::start`](NetworkObserver::start) returns:
    /// one type for a firmware that restores a snapshot and falls back to
    /// a start), with the configured warm-up armed:
    /// [`NetworkSettings::warmup_corrections`] corrections from the steady
    /// prior widened by the recovery variances (none at the default 0: it
    /// then ticks as `state` would, to the bit).
    pub fn with_warm_up(
        &self,
        state: NetworkObserverStateOf<Z, X, P, NoWarmUp>,
    ) -> NetworkObserverStateOf<Z, X, P> {
        let mut cov = self.gain.prior().clone();
        for (i, v) in self.kalman.recovery_variance.iter().enumerate() {
            cov[(i, i)] += *v;
        }
        let mut state = state.flavoured(WarmUp { held: cov });
        state.warmup_left = self.warmup_corrections;
        state
    }

    /// The estimated offset of the boundary with an offset state
    /// ([`NetworkSettings::boundary_offset`]) \[K\], `>= 0` after every
    /// correction (with [`NetworkSettings::correction_in_two_ticks`], after
    /// its second tick); `None` without one.
    pub fn boundary_offset_k<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &NetworkObserverStateOf<Z, X, P, W>,
    ) -> Option<f32> {
        let sizes = self.sizes();
        self.offset_boundary.and_then(|_| {
            state
                .estimate
                .x
                .get(sizes.nodes() + sizes.inputs())
                .copied()
        })
    }

    /// The estimated heat-input bias of each current \[W\].
    pub fn heat_bias_w<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &NetworkObserverStateOf<Z, X, P, W>,
    ) -> InputVector<Z, f32> {
        let sizes = self.sizes();
        let first = sizes.nodes();
        sizes
            .input_dim()
            .each(|m| state.estimate.x.get(first + m).copied().unwrap_or(f32::NAN))
    }

    /// Whether a correction takes two ticks
    /// ([`NetworkSettings::correction_in_two_ticks`]).
    const fn corrects_in_two_ticks(&self) -> bool {
        #[cfg(not(target_abi = "eabihf"))]
        if self.correction_in_two_ticks {
            return true;
        }
        false
    }

    /// Whether the model steps in integer arithmetic.
    const fn steps_in_integers(&self) -> bool {
        #[cfg(feature = "integer-step")]
        if self.integer_step.is_some() {
            return true;
        }
        false
    }

    /// The estimated temperature of every node \[degC\] now.
    pub fn temps_c<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &NetworkObserverStateOf<Z, X, P, W>,
    ) -> NodeVector<Z, f32> {
        Z::NodeDim::from_usize(self.limited.as_ref().len())
            .each(|i| self.origin_c + state.estimate.x[i])
    }

    /// One controller tick: model steps from the elapsed time (each a filter
    /// predict), a correction if readings arrived, then at most one stage of
    /// the protection cycle. Bounded (`max_steps_per_tick` steps, one
    /// correction, one stage), allocation-free, panic-free.
    pub fn tick<'s, W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &'s mut NetworkObserverStateOf<Z, X, P, W>,
        inputs: &NetworkInputsOf<Z::BoundaryDim, Z::InputDim, P>,
    ) -> &'s FilteredOutputs<Z::NodeDim, Z::InputDim, Z::NodeDim, P> {
        let debt_before_us = state.clock.debt_us;
        let steps = self.clock.advance(&mut state.clock, inputs.elapsed_us);
        if steps.clock_lost {
            // The model stands still: latched until the deliberate clear.
            state.latch().clock_lost();
        }
        let mut flags = steps.flags;
        // A correction's second tick goes first: with the currents its
        // first saw, before this tick's step and correction; it is this
        // tick's one put-off piece when it does not step.
        #[cfg(not(target_abi = "eabihf"))]
        let floors_ran = match state.floors_due {
            Some(warming) => {
                state.floors_due = None;
                self.finish_correction(state, warming, &mut flags);
                true
            }
            None => false,
        };
        #[cfg(target_abi = "eabihf")]
        let floors_ran = false;
        let moved =
            state
                .step_account
                .moves(debt_before_us, &inputs.currents_a, &state.held_currents_a);
        flags |= self
            .limits
            .accept_currents(inputs.currents_a.as_ref(), state.held_currents_a.as_mut());
        flags |= self
            .limits
            .accept_temperatures(inputs.boundary_c.as_ref(), state.held_boundary_c.as_mut());
        // Each step heats with the mean `I^2` of the time it covers when
        // the held currents changed within it (see "Model step and ticks"
        // in the module docs): a jittering tick or a step several ticks
        // long would otherwise sample the current.
        let mean_sq_a2 = state.step_account.account(
            &state.held_currents_a,
            moved,
            debt_before_us,
            state.clock.debt_us,
            inputs.elapsed_us,
            &steps,
            self.step_us,
        );
        let put_off_ran = if floors_ran && steps.steps == 0 {
            true
        } else {
            self.step_model(state, steps.steps, mean_sq_a2, &inputs.readings)
        };
        self.decay_biases(state, steps.steps);
        state.cycle.stepped(
            &steps,
            self.step_us,
            inputs.elapsed_us,
            &state.held_currents_a,
        );
        let (corrected, disagree) = self.correct(state, &inputs.readings, inputs.now_us);
        flags |= disagree;
        #[cfg(feature = "integer-step")]
        if corrected {
            state.integer.corrected();
        }
        // Only a step or a reading (a correction) moves the estimate; a
        // correction in two ticks publishes it on its second.
        let unfinished = state.correction_unfinished();
        if (steps.steps > 0 || floors_ran || inputs.readings.as_ref().iter().any(Option::is_some))
            && !unfinished
        {
            state.outputs.temps_c = self.temps_c(state);
        }
        state.outputs.corrected = corrected;
        // A catch-up, a step longer than the loop's tick, or the shadow's
        // block that such a step put off.
        let busy = corrected
            || steps.steps.saturating_mul(self.step_us) > self.loop_period_us
            || put_off_ran;
        // No stage between a correction's two ticks: each judges the
        // finished estimate (not a busy tick's wait: it comes next).
        Protecting {
            observer: self,
            state: &mut *state,
        }
        .run_due(
            busy,
            unfinished,
            self.protect_period_us,
            steps.steps > 0 || steps.dropped_us > 0,
        );
        state.outputs.finish_tick(flags, &steps);
        &state.outputs
    }

    /// [`tick`](Self::tick) for windings driven by a voltage (see
    /// "Voltage-driven coils" above): each `Some` drive replaces the
    /// current of its input by the current the winding draws at the
    /// estimated temperature of the node it heats, `sqrt(D) V / R(T_est)`,
    /// so that every model step of this tick heats it by `D V^2 /
    /// R(T_est)`. A bad drive holds the input's last valid current (flagged
    /// here and as [`InputFlags::CURRENT_NOT_FINITE`] in the outputs); `None`
    /// inputs take `inputs.currents_a` as measured. Bounded, allocation-free,
    /// panic-free: one square root and one division per driven input more
    /// than [`tick`](Self::tick), which it then calls.
    pub fn tick_voltage<'s, W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &'s mut NetworkObserverStateOf<Z, X, P, W>,
        inputs: &NetworkInputsOf<Z::BoundaryDim, Z::InputDim, P>,
        drives: &InputVector<Z, Option<VoltageDrive>>,
    ) -> (&'s NetworkOutputsOf<Z, P>, DriveFlags) {
        let mut flags = DriveFlags::NONE;
        let mut driven = inputs.clone();
        for (((current, drive), node), r) in driven
            .currents_a
            .as_mut()
            .iter_mut()
            .zip(drives.as_ref())
            .zip(self.source_node.as_ref())
            .zip(self.resistance.as_ref())
        {
            if let Some(drive) = drive {
                let (v_eff, f) = drive.effective_v();
                flags |= f;
                let dev_k = state.estimate.x.get(*node).copied().unwrap_or(f32::NAN);
                *current = r.current_for_voltage_a(dev_k, v_eff);
                if f.is_clean() && current.is_nan() {
                    flags |= DriveFlags::RESISTANCE_INVALID;
                }
            }
        }
        (self.tick(state, &driven), flags)
    }

    /// The limit of voltage-driven input `input` in its drive's units (a
    /// duty and an effective voltage) for a supply measured at `supply_v`
    /// \[V\], from the published current limit and `R(T)` at the
    /// published estimate of the node it heats (see
    /// [`crate::protect::limiter::drive_limit`]: an invalid supply gives
    /// duty zero, flagged). Call after a tick; `O(1)`, panic-free; an input
    /// out of range gets a zero limit.
    pub fn drive_limit<W: Flavour<OMatrix<f32, X, X>>>(
        &self,
        state: &NetworkObserverStateOf<Z, X, P, W>,
        input: usize,
        supply_v: f32,
    ) -> DriveLimit {
        let out = &state.outputs;
        match (
            out.limits.as_ref().get(input),
            self.resistance.as_ref().get(input),
            self.source_node.as_ref().get(input),
        ) {
            (Some(limit), Some(r), Some(node)) => {
                let t = out.temps_c.as_ref().get(*node).copied().unwrap_or(f32::NAN);
                drive_limit(limit, r.line_ohm(t - self.origin_c), supply_v)
            }
            _ => DriveLimit::default(),
        }
    }
}

impl<const N: usize, const B: usize, const M: usize, const X: usize, const P: usize>
    NetworkObserver<N, B, M, X, P>
{
    fn new(b: &NetworkObserverBuilder<'_, N, B, M, P>) -> Result<Self, BuildError> {
        Self::from_parts_with_sensors(&b.parts()?, &b.sensor_kinds)
    }
}

/// The discretised network in the observer's coordinates, over the
/// network's [`Sizes`] `Z` (a [`Network`]'s or one read at run time).
struct ModelOf<Z: Sizes>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    dt_s: f64,
    ad: OMatrix<f64, Z::NodeDim, Z::NodeDim>,
    bd_power_f64: OMatrix<f64, Z::NodeDim, Z::InputDim>,
    gd_boundary_f64: OMatrix<f64, Z::NodeDim, Z::BoundaryDim>,
    phi_minus_i: OMatrix<f32, Z::NodeDim, Z::NodeDim>,
    bd_power: OMatrix<f32, Z::NodeDim, Z::InputDim>,
    gd_boundary: OMatrix<f32, Z::NodeDim, Z::BoundaryDim>,
    constant_k: OVector<f32, Z::NodeDim>,
    source_node: InputVector<Z, usize>,
    resistance: InputVector<Z, ScalarResistance<f32>>,
}

/// [`ModelOf`] a [`Network`] of const sizes.
type Model<const N: usize, const B: usize, const M: usize> = ModelOf<ConstSizes<N, B, M>>;

/// The derated alarm limits a state keeps per ambient: on a core without
/// an FPU (see [`NetworkObserver::alarm_limits_c`]).
#[cfg(not(target_abi = "eabihf"))]
type KeptAlarmLimits<N> = AmbientLimits<N>;

/// On a core with an FPU none are kept (see
/// [`NetworkObserver::alarm_limits_c`]): the state is as large as without
/// them (20 bytes more of it cost the M4F's motor and three-phase ticks 2
/// instructions on average, measured).
#[cfg(target_abi = "eabihf")]
type KeptAlarmLimits<N> = NoneKept<N>;

/// Nothing kept (see [`KeptAlarmLimits`]).
#[cfg(target_abi = "eabihf")]
#[derive(Debug, Clone, Copy, PartialEq)]
struct NoneKept<N>(core::marker::PhantomData<N>);

#[cfg(target_abi = "eabihf")]
impl<N> NoneKept<N> {
    fn new(_: N) -> Self {
        Self(core::marker::PhantomData)
    }
}

impl<Z: Sizes> ModelOf<Z>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    #[inline(never)]
    fn build<W: NetworkDescription<Sizes = Z>>(
        network: &W,
        dt_s: f64,
        origin_c: f64,
    ) -> Result<Self, BuildError> {
        let sizes = network.sizes();
        let (nodes, boundaries) = (sizes.node_dim(), sizes.boundary_dim());
        let d = zoh(&state_space_of(network, &sizes.nodes_of(origin_c)), dt_s)?;
        let phi_minus_i =
            &d.ad - OMatrix::<f64, Z::NodeDim, Z::NodeDim>::identity_generic(nodes, nodes);
        // T' = Ad T + Bd p + Gd T_b + dd with T = T_0 + x, T_b = T_0 + y:
        // x' - x = (Ad - I) x + Bd p + Gd y + [dd + (Ad - I) T_0 + Gd T_0],
        // the bracket (zero for a network without fixed power) in f64.
        let origin = OVector::<f64, Z::NodeDim>::from_element_generic(nodes, U1, origin_c);
        let boundary_origin =
            OVector::<f64, Z::BoundaryDim>::from_element_generic(boundaries, U1, origin_c);
        let constant = &d.dd + &phi_minus_i * origin + &d.gd_boundary * boundary_origin;
        let mut source_node = sizes.inputs_of(0);
        let mut resistance = sizes.inputs_of(crate::network::Resistance::constant(0.0).to_scalar());
        for (m, (node, r)) in source_node
            .as_mut()
            .iter_mut()
            .zip(resistance.as_mut())
            .enumerate()
        {
            let source = network
                .joule_source_of(m)
                .ok_or(BuildError::MissingSource { input: m })?;
            *node = source.node;
            *r = source.resistance.to_scalar();
        }
        Ok(Self {
            dt_s,
            phi_minus_i: phi_minus_i.cast(),
            bd_power: d.bd_power.clone().cast(),
            gd_boundary: d.gd_boundary.clone().cast(),
            constant_k: constant.cast(),
            ad: d.ad,
            bd_power_f64: d.bd_power,
            gd_boundary_f64: d.gd_boundary,
            source_node,
            resistance,
        })
    }
}

mod assemble;
mod bias;
mod correct;
mod model_step;
mod parts;
mod protection;
pub mod resistance;
mod restart;
#[cfg(feature = "alloc")]
mod run_time;
mod solve;
pub use super::warm_up::{NoWarmUp, WarmUp};
pub use bias::{BiasMode, BiasModeOf};
pub use parts::{
    AssembledTables, GainTables, ModelTables, NetworkParts, PredictorTables, ShadowTables,
};
pub use resistance::{ResistanceSensor, SensorKind};
#[cfg(feature = "alloc")]
pub use run_time::{RunTimeBiasMode, RunTimeObserver, RunTimeObserverState, RunTimeSpec};

/// A network state's warm-up flavour (see [`super::warm_up`]):
/// [`NoWarmUp`], or [`WarmUp`] holding the time-varying warm-up's
/// covariance (`X^2` floats) while it runs (the start's, and the
/// configured one of [`NetworkSettings::warmup_corrections`]). Only the
/// covariance: its count and end stay in the state.
pub trait WarmUpKind<const X: usize>: Flavour<SMatrix<f32, X, X>> {}

impl<const X: usize, W: Flavour<SMatrix<f32, X, X>>> WarmUpKind<X> for W {}

#[cfg(test)]
#[path = "network_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "network_voltage_tests.rs"]
mod voltage_drive;

#[cfg(test)]
#[path = "network/multi_rate_tests.rs"]
mod multi_rate;
