//! Link-time proof that the per-tick path cannot panic.
//!
//! The panic handler below calls a function that exists nowhere. If any panic
//! (a bounds check, an `unwrap`, a division check) were still reachable from
//! `main` after optimisation, the linker would need that symbol and the build
//! would fail with "undefined symbol: hot_path_has_a_reachable_panic". So a
//! successful `cargo build --release` of this example *is* the check.
//!
//! Everything that may legitimately fail (building the models) happens with
//! inputs the optimiser cannot see through (`black_box`), and failures exit
//! through semihosting instead of panicking. The stepped inputs include NaN
//! and infinities, also hidden behind `black_box`.
//!
//! Every public per-tick function is called (the list `docs/cost.md`
//! gives as what is proven):
//!
//! * the grid: `GridObserver::tick` in `f32` (84 coils), `Q32` and `f64`
//!   (12 coils; the spread step, one step or a catch-up, the update, time
//!   to limit, alarm and limiter in parts, hottest coil) and the bare
//!   `CoilGrid::tick`, `accumulate`, `update`, `tick_spread` and
//!   `ticks_spread` in `f32` and `Q32`;
//! * the protection's blocks called directly: the alarm's `tick` and
//!   `tick_part`, the limiter's `apply`, `apply_part` and `clamp_a` (`f32`,
//!   `Q32`), the time-to-limit predictor's `tick` and `predict` (`f32`);
//! * the Omnimagnet: `OmniObserver::tick` and `install_model` (`f32`:
//!   the carried mean predict, `update_steady`, the shadow and the reading
//!   screens, predictor slice, alarm, limiter; on an opaque state, so the
//!   start's held covariance too: its slices, its correction, its widened
//!   bound) and the Kalman
//!   `OmnimagnetObserver::predict`, `correct`, `correct_samples` and
//!   `correct_winding` in `f32` and `f64`, in both gain modes;
//! * the generic `NetworkObserver::tick` (`f32`), with a winding
//!   resistance sensor's reading path (`resistance_reading`,
//!   `voltage_current_reading`);
//! * the filters: the time-varying `predict` and `update` (`f32`) and
//!   `update_virtual` (`f32`, `f64`);
//! * the network steppers (`f32`, `Q32`) and the integer step of
//!   `discretize::fixed` (`FixedInputs::new`, `FixedStep::step`,
//!   `f32_of_state`), the protective upper bounds and
//!   mean limits of `protect::margin` (`f32`, `Q32`, parts out of range);
//! * the sensor decoders `max31855::decode`, `max31856::decode` and the
//!   plausibility `sensors::check`;
//! * on the Cortex-M0, the crate's `f32` routines (`soft_float`: add,
//!   subtract, multiply, compares), the firmware's through
//!   `soft_float_routines!()`.
//!
//! `.ci/run` links it for the Cortex-M4F and for the Cortex-M0
//! (`thumbv6m-none-eabi`), where the fixed-point subset is proven: the
//! `Q32` grid observer and bare grid, the steppers, the bounds and the
//! sensor decoders (the software-float observers do not fit its flash
//! together; see `checks`). Checked by inserting a `panic!` in
//! `OmnimagnetObserver::predict`, `CoilGrid::tick` (both targets),
//! `filter::update_virtual`, `max31855::decode` (M0),
//! `PredictorState::tick` (M4F), `AlarmState::tick_part` (M0) and
//! `soft_float`'s add and multiply (M0): each link fails.
#![no_std]
#![no_main]
// The Cortex-M0 build proves a subset (see `checks`).
#![cfg_attr(not(target_abi = "eabihf"), allow(dead_code, unused_imports))]

// On the Cortex-M0 the crate's `f32` routines are the firmware's (the M0
// examples take them): their code is proven with the rest.
coil_thermal::soft_float_routines!();

use coil_thermal::discretize::fixed::{f32_of_state, FixedInputs, FixedStep};
use coil_thermal::filter::{predict, update, update_virtual, KalmanConfig, KalmanState};
use coil_thermal::grid::GridConfig;
use coil_thermal::observer::network::{NetworkObserverState, WarmUpKind};
use coil_thermal::observer::omnimagnet::TimedReading;
use coil_thermal::observer::{
    GridInputs, GridObserver, NetworkInputs, NetworkObserver, OmniInputs, OmniObserver, StepTables,
};
use coil_thermal::omnimagnet::observer::{MeanModel, OmnimagnetObserver};
use coil_thermal::omnimagnet::NODES;
use coil_thermal::protect::alarm::{AlarmBuilder, AlarmState};
use coil_thermal::protect::derating::{DeratingRule, HPPA_CRITICAL_C};
use coil_thermal::protect::events::EventQueue;
use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
use coil_thermal::protect::margin::{UncertaintyMargin, UpperBoundBuilder};
use coil_thermal::protect::predict::{LimitPredictor, Operating, PredictorState};
use coil_thermal::protect::resistance_sensor::MeanTemperatureReading;
use coil_thermal::sensors::{max31855, max31856, PlausibilityCheck, PlausibilityState};
use coil_thermal::{
    CoilGrid, ExplicitStepper, GridState, InputLimits, Network, NetworkState, Reading, Resistance,
    Scalar, SensorFault, Q32,
};
use core::hint::black_box;
use cortex_m_rt::entry;
use cortex_m_semihosting::debug;
use nalgebra::{Const, SMatrix, SVector, U1};

fn network() -> Result<Network<3, 1, 1>, coil_thermal::BuildError> {
    Network::new(black_box([68.7, 40.0, 400.0]))?
        .connect(0, 1, black_box(0.35))?
        .connect(1, 2, black_box(0.8))?
        .connect_boundary(2, 0, black_box(1.5))?
        .joule_source(0, 0, Resistance::HPPA_COIL)
}

type Grid = GridObserver<f32, 7, 12, 84>;

fn grid_observer() -> Result<Grid, coil_thermal::BuildError> {
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 84]).build()?;
    let limiter = LimiterConfig::new(black_box([3.0; 84]), 10.0, 0.0)?;
    let config = GridConfig {
        ticks_per_update: black_box(10),
        ..GridConfig::default()
    };
    Grid::new(&config, alarm, limiter, black_box(4))
}

/// An Omnimagnet configuration the optimiser knows nothing about.
///
/// The real build (`OmniObserver::new`: linearisation, Riccati solver, modal
/// decomposition) runs once before the loop and still holds bounds checks on
/// the model's table indices, which would fail this link although the tick
/// has none. So the tick is proven on opaque configuration bits instead,
/// which covers every configuration, valid or not; `observer_m4` runs the
/// real build.
#[inline(never)]
fn omni_config() -> Option<OmniObserver> {
    // SAFETY: every field of `OmniObserver` (f32 and f64 matrices and
    // arrays, integers, bools, `Option`s of those, `GainMode` whose first
    // variant is 0; no references, no `NonZero`, no enum without a zero
    // variant) has all-zero bits as a valid value. The value is hidden
    // behind `black_box`.
    Some(black_box(unsafe { core::mem::zeroed() }))
}

/// A generic network observer's configuration the optimiser knows nothing
/// about, for the same reason as [`omni_config`] (its build solves a
/// Riccati equation with checked indices).
#[inline(never)]
fn network_config() -> Option<NetworkObserver<3, 1, 1, 4, 1>> {
    // SAFETY: as for `omni_config`: every field (f32 matrices and arrays,
    // usize, u32, bool, the protection configurations `OmniObserver` also
    // holds) has all-zero bits as a valid value. Hidden behind `black_box`.
    Some(black_box(unsafe { core::mem::zeroed() }))
}

/// The generic observer's tick with hostile inputs, on both state
/// flavours: without the warm-up (`state`), and with it on an opaque
/// state (`start`'s flavour, its count and its end unknown: the
/// time-varying covariance, its correction and its widened bound).
#[inline(never)]
fn network_observer() -> bool {
    let Some(obs) = network_config() else {
        return false;
    };
    network_ticks(&obs, obs.state(&[20.0; 3], &[20.0]));
    network_ticks(
        &obs,
        black_box(obs.with_warm_up(obs.state(&[20.0; 3], &[20.0]))),
    );
    true
}

#[inline(never)]
fn network_ticks<W: WarmUpKind<4>>(
    obs: &NetworkObserver<3, 1, 1, 4, 1>,
    mut state: NetworkObserverState<3, 1, 1, 4, 1, W>,
) {
    for k in 0..black_box(2000u32) {
        let current = black_box(if k % 7 == 0 { f32::NAN } else { 8.0 });
        let temp = black_box(if k % 11 == 0 { f32::INFINITY } else { 20.0 });
        let elapsed_us = black_box(if k % 13 == 0 { u32::MAX } else { 1000 });
        let reading = black_box(TimedReading {
            result: if k % 5 == 0 {
                Err(SensorFault::OpenCircuit)
            } else {
                Ok(Reading::new(temp))
            },
            sampled_at_us: k,
        });
        // A winding resistance sensor's reading path, as hostile
        // (`observer::network::resistance`).
        let resistance = black_box(if k % 3 == 0 { -temp } else { temp * 0.01 });
        let from_resistance = if k % 2 == 0 {
            obs.resistance_reading(0, resistance, current, k)
        } else {
            obs.voltage_current_reading(0, resistance, current, k)
        };
        black_box(obs.tick(
            &mut state,
            &NetworkInputs {
                currents_a: [current],
                boundary_c: [temp],
                readings: [from_resistance.or(Some(reading))],
                now_us: k.wrapping_mul(1000),
                elapsed_us,
            },
        ));
    }
}

/// A re-linearised model the optimiser knows nothing about, for
/// `OmniObserver::install_model` (built by `prepare_model` off the tick).
#[inline(never)]
fn omni_model() -> MeanModel<f32> {
    // SAFETY: `MeanModel` holds f32 matrices and an f64; all-zero bits are
    // a valid value of each. Hidden behind `black_box`.
    black_box(unsafe { core::mem::zeroed() })
}

/// The observers' ticks with hostile inputs.
#[inline(never)]
fn observers() -> bool {
    let model = omni_model();
    let (Ok(grid), Some(omni)) = (grid_observer(), omni_config()) else {
        return false;
    };
    let mut gs = grid.state(20.0);
    // Opaque, so that the tick's paths for a state made by `start` (its
    // held covariance: the slices, the correction against it, the widened
    // bound) are linked too: `start` itself, like `new`, reads the model's
    // geometry tables and runs before the loop.
    let mut os = black_box(omni.state(&[22.0; NODES], 22.0));
    for k in 0..black_box(2000u32) {
        let current = black_box(if k % 7 == 0 { f32::NAN } else { 2.0 });
        let temp = black_box(if k % 11 == 0 { f32::INFINITY } else { 20.0 });
        let currents = [[current; 12]; 7];
        let elapsed_us = black_box(if k % 13 == 0 { u32::MAX } else { 1000 });
        black_box(grid.tick(
            &mut gs,
            &GridInputs {
                currents_a: &currents,
                coolant_c: temp,
                ambient_c: temp,
                elapsed_us,
            },
        ));
        let reading = black_box(TimedReading {
            result: if k % 5 == 0 {
                Err(SensorFault::OpenCircuit)
            } else {
                Ok(Reading::new(temp))
            },
            sampled_at_us: k,
        });
        if k % 97 == 0 {
            black_box(omni.install_model(&mut os, &model).is_ok());
        }
        black_box(omni.tick(
            &mut os,
            &OmniInputs {
                currents_a: [current; 3],
                ambient_c: temp,
                readings: [Some(reading); 6],
                now_us: k.wrapping_mul(1000),
                elapsed_us,
            },
        ));
    }
    true
}

/// The time-varying filter's predict and update.
#[inline(never)]
fn time_varying_filter() -> bool {
    let f = black_box(SMatrix::<f32, 4, 4>::identity() * 0.99);
    let cfg = KalmanConfig::<f32, Const<4>, U1, Const<2>>::new(
        f,
        black_box(SMatrix::<f32, 4, 1>::repeat(0.01)),
        black_box(SMatrix::<f32, 2, 4>::identity()),
        SMatrix::<f32, 4, 4>::identity() * 1e-3,
        SVector::<f32, 2>::repeat(0.1),
    );
    let Ok(cfg) = cfg else { return false };
    let mut state = KalmanState::new(SVector::repeat(20.0), SMatrix::identity());
    for k in 0..black_box(100u32) {
        let u = black_box(SVector::<f32, 1>::new(if k % 3 == 0 {
            f32::NAN
        } else {
            1.0
        }));
        black_box(predict(&cfg, &mut state, &u));
        let z = black_box([Some(20.5), if k % 2 == 0 { None } else { Some(f32::NAN) }]);
        black_box(update(&cfg, &mut state, &z));
    }
    true
}

/// The upper bounds and mean limits, in `f32` and `Q32`, with NaN,
/// infinities and parts beyond the elements.
#[inline(never)]
fn margins() -> bool {
    let builder = UpperBoundBuilder::new(UncertaintyMargin::new(black_box(0.65), black_box(0.5)))
        .sigma(black_box(3.0), black_box([0.1, 0.2, 0.3, 0.0]));
    let (Ok(float_bound), Ok(fixed_bound)) = (builder.build::<f32>(), builder.build::<Q32>())
    else {
        return false;
    };
    let mut upper = [0.0f32; 4];
    let mut fixed_upper = [<Q32 as coil_thermal::Scalar>::ZERO; 4];
    for k in 0..black_box(100u32) {
        let temp = black_box(if k % 7 == 0 { f32::NAN } else { 60.0 });
        let reference = black_box(if k % 11 == 0 { f32::INFINITY } else { 20.0 });
        let temps = [temp, -temp, 1e30, 20.0];
        let range = black_box(k as usize % 6)..black_box(k as usize % 9);
        float_bound.upper_part(&temps, reference, &mut upper, range.clone());
        float_bound.upper_c(&temps, reference, &mut upper);
        black_box(float_bound.mean_limits_c(&temps, reference));
        let fixed_temps = temps.map(<Q32 as coil_thermal::Scalar>::from_f32);
        let fixed_reference = <Q32 as coil_thermal::Scalar>::from_f32(reference);
        fixed_bound.upper_part(&fixed_temps, fixed_reference, &mut fixed_upper, range);
        black_box(fixed_bound.mean_limits_c(&fixed_temps, fixed_reference));
        if let Some(e) = float_bound.element(black_box(k as usize % 6)) {
            black_box(e.mean_limit_c(temp, reference));
        }
    }
    black_box(&upper);
    black_box(&fixed_upper);
    true
}

/// Everything, on the Cortex-M4F (`thumbv7em-none-eabihf`).
#[cfg(target_abi = "eabihf")]
fn checks() -> bool {
    observers()
        && small_grid_observer::<Q32>()
        && small_grid_observer::<f64>()
        && network_observer()
        && protection_blocks::<f32>()
        && protection_blocks::<Q32>()
        && time_to_limit()
        && time_varying_filter()
        && kalman_observers::<f32>()
        && kalman_observers::<f64>()
        && bare_grids::<f32>()
        && bare_grids::<Q32>()
        && sensor_decoders()
        && steppers()
        && margins()
}

/// On the Cortex-M0 (`thumbv6m-none-eabi`, no FPU) what a fixed-point
/// firmware runs: the `Q32` grid observer and bare grid, the steppers,
/// the bounds, the alarm and limiter blocks, the sensor decoders. The
/// `f32` and `f64` observers in software floating point do not fit the
/// microbit's 256 KiB of flash together, and are proven on the M4F build.
#[cfg(not(target_abi = "eabihf"))]
fn checks() -> bool {
    small_grid_observer::<Q32>()
        && bare_grids::<Q32>()
        && protection_blocks::<Q32>()
        && sensor_decoders()
        && steppers()
        && margins()
}

#[entry]
fn main() -> ! {
    let ok = checks();
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    loop {
        cortex_m::asm::wfi();
    }
}

/// The grid observer in `S`, 12 coils, hostile inputs: `Q32` (the
/// Cortex-M0's), and `f64` on the Cortex-M4F (the 84-coil `f32` one is in
/// [`observers`]).
#[inline(never)]
fn small_grid_observer<S: Scalar>() -> bool {
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 12]).build::<S>();
    let limiter = LimiterConfig::<S, Const<12>>::new(black_box([6.0; 12]), 10.0, 0.0);
    let config = GridConfig {
        ticks_per_update: black_box(10),
        ..GridConfig::default()
    };
    let (Ok(alarm), Ok(limiter)) = (alarm, limiter) else {
        return false;
    };
    let Ok(grid) = GridObserver::<S, 3, 4, 12>::new(&config, alarm, limiter, black_box(4)) else {
        return false;
    };
    let mut state = grid.state(20.0);
    for k in 0..black_box(500u32) {
        let current = S::from_f32(black_box(if k % 7 == 0 { 1e30 } else { 2.0 }));
        let temp = S::from_f32(black_box(if k % 11 == 0 { f32::NAN } else { 20.0 }));
        let elapsed_us = black_box(if k % 13 == 0 { u32::MAX } else { 1000 });
        black_box(grid.tick(
            &mut state,
            &GridInputs {
                currents_a: &[[current; 4]; 3],
                coolant_c: temp,
                ambient_c: temp,
                elapsed_us,
            },
        ));
    }
    true
}

/// The protection's building blocks called directly, as a firmware that
/// composes its own observer calls them: the alarm's `tick` and
/// `tick_part`, the limiter's `apply`, `apply_part` and `clamp_a`, in `S`,
/// with NaN, infinities and parts beyond the elements.
#[inline(never)]
fn protection_blocks<S: Scalar>() -> bool {
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [HPPA_CRITICAL_C; 4]).build::<S>();
    let limiter = LimiterConfig::<S, Const<4>>::new(black_box([3.0; 4]), 10.0, 0.0);
    let (Ok(alarm), Ok(limiter)) = (alarm, limiter) else {
        return false;
    };
    let mut state = AlarmState::new(&alarm);
    let mut events = EventQueue::<8>::new();
    let mut limits = [CoilLimit::<S>::default(); 4];
    for k in 0..black_box(100u32) {
        let temp = S::from_f32(black_box(if k % 7 == 0 { f32::NAN } else { 160.0 }));
        let ambient = S::from_f32(black_box(if k % 11 == 0 { f32::INFINITY } else { 20.0 }));
        let temps = [
            temp,
            S::from_f32(-1e30),
            S::from_f32(1e30),
            S::from_f32(20.0),
        ];
        let time_to_limit_s = [Some(temp), None, Some(S::ZERO), Some(ambient)];
        let range = black_box(k as usize % 6)..black_box(k as usize % 9);
        black_box(state.tick(&alarm, &temps, ambient, &time_to_limit_s, &mut events));
        black_box(state.tick_part(
            &alarm,
            &temps,
            ambient,
            &time_to_limit_s,
            &mut events,
            range.clone(),
        ));
        let alarm_limits_c = alarm.alarm_limits_c(ambient);
        black_box(limiter.apply(&temps, &alarm_limits_c, ambient, &mut limits));
        black_box(limiter.apply_part(&temps, &alarm_limits_c, ambient, &mut limits, range));
        black_box(limits[k as usize % 4].clamp_a(temp));
        while events.pop().is_some() {}
    }
    black_box(&limits);
    true
}

/// A time-to-limit predictor the optimiser knows nothing about, for the
/// same reason as [`omni_config`] (its build decomposes the network into
/// modes with checked indices).
#[inline(never)]
fn limit_predictor() -> LimitPredictor<f32, 4, 1, 2> {
    // SAFETY: every field (f32 arrays, usize, f64, the windings' usize and
    // f32) has all-zero bits as a valid value. Hidden behind `black_box`.
    black_box(unsafe { core::mem::zeroed() })
}

/// The time-to-limit predictor's `tick` (a sweep in slices) and `predict`
/// (a full sweep), `f32`, hostile operating points.
#[inline(never)]
fn time_to_limit() -> bool {
    let predictor = limit_predictor();
    let operating = |k: u32| {
        let temp = black_box(if k.is_multiple_of(7) { f32::NAN } else { 60.0 });
        let current = black_box(if k.is_multiple_of(11) {
            f32::INFINITY
        } else {
            3.0
        });
        Operating {
            temps_c: [temp, 40.0, -1e30, 1e30],
            currents_a: [current, -current],
            boundary_c: [black_box(20.0)],
            limits_c: [155.0, f32::INFINITY, black_box(f32::NAN), 100.0],
        }
    };
    let mut state = PredictorState::new(&predictor, &operating(1));
    let mut full = [None; 4];
    for k in 0..black_box(100u32) {
        let op = operating(k);
        black_box(state.tick(&predictor, &op));
        if k % 10 == 0 {
            predictor.predict(&op, &mut full);
        }
    }
    black_box(&full);
    true
}

/// The bare grid's `tick`, `accumulate`, `update`, `tick_spread` and
/// `ticks_spread` (catch-ups up to 40 ticks) in `S`, hostile
/// currents and boundaries.
#[inline(never)]
fn bare_grids<S: Scalar>() -> bool {
    let config = GridConfig {
        ticks_per_update: black_box(10),
        ..GridConfig::default()
    };
    let Ok(grid) = CoilGrid::<S, 7, 12>::new(&config) else {
        return false;
    };
    let mut state = GridState::<S, 7, 12>::uniform(20.0);
    let mut spread = GridState::<S, 7, 12>::uniform(20.0);
    let mut work = grid.update_work(&spread);
    for k in 0..black_box(100u32) {
        let current = S::from_f32(black_box(if k % 7 == 0 { f32::NAN } else { 2.0 }));
        let temp = S::from_f32(black_box(if k % 11 == 0 { f32::INFINITY } else { 20.0 }));
        let currents = [[current; 12]; 7];
        black_box(grid.tick(&mut state, &currents, temp, temp));
        black_box(grid.accumulate(&mut state, &currents));
        if k % 5 == 0 {
            grid.update(&mut state);
        }
        black_box(grid.tick_spread(&mut spread, &mut work, &currents, temp, temp));
        let catch_up = black_box(if k % 17 == 0 { 40 } else { k % 4 });
        black_box(grid.ticks_spread(&mut spread, &mut work, &currents, temp, temp, catch_up));
    }
    black_box(&state);
    black_box(&spread);
    true
}

/// An Omnimagnet Kalman observer the optimiser knows nothing about, for the
/// same reason as [`omni_config`].
#[inline(never)]
fn kalman_observer<T: nalgebra::RealField + Copy>() -> OmnimagnetObserver<T> {
    // SAFETY: every field (T matrices and arrays, integers, bools, the
    // settings' `[bool; 6]`, `GainMode` whose first variant is 0, the gate
    // counters) has all-zero bits as a valid value, for `f32` and `f64`.
    // Hidden behind `black_box`.
    black_box(unsafe { core::mem::zeroed() })
}

/// The Omnimagnet Kalman observer's per-tick calls in `T` (`predict`,
/// `correct`, `correct_samples`, `correct_winding` in both gain modes) and
/// `filter::update_virtual`, with NaN, infinities and faults.
#[inline(never)]
fn kalman_observers<T: nalgebra::RealField + Copy>() -> bool {
    let mut obs = kalman_observer::<T>();
    let cast = |v: f64| -> T { nalgebra::convert(v) };
    for k in 0..black_box(100u32) {
        let current = cast(black_box(if k % 7 == 0 { f64::NAN } else { 3.8 }));
        let ambient = cast(black_box(if k % 11 == 0 { f64::INFINITY } else { 22.0 }));
        black_box(obs.predict(&[current; 3], ambient));
        let reading = black_box(if k % 3 == 0 { None } else { Some(current) });
        black_box(obs.correct(&[reading; 6]));
        let sample = black_box(if k % 5 == 0 {
            Some(Err(SensorFault::OpenCircuit))
        } else {
            reading.map(Ok)
        });
        black_box(obs.correct_samples(&[sample; 6]));
        let winding = black_box(MeanTemperatureReading {
            temp_c: if k % 13 == 0 { f32::NAN } else { 60.0 },
            variance_k2: 0.25,
            resistance_ohm: 1.0,
        });
        black_box(obs.correct_winding(black_box(k as usize % 5), &winding));
    }
    black_box(&obs);
    let cfg = KalmanConfig::<T, Const<4>, U1, Const<2>>::new(
        black_box(SMatrix::identity() * cast(0.99)),
        black_box(SMatrix::repeat(cast(0.01))),
        black_box(SMatrix::identity()),
        SMatrix::identity() * cast(1e-3),
        SVector::repeat(cast(0.1)),
    );
    let Ok(cfg) = cfg else { return false };
    let mut state = KalmanState::new(SVector::repeat(cast(20.0)), SMatrix::identity());
    for k in 0..black_box(100u32) {
        let h = black_box(SVector::<T, 4>::new(
            T::one(),
            T::zero(),
            T::zero(),
            T::zero(),
        ));
        let z = cast(black_box(if k % 3 == 0 { f64::NAN } else { 20.5 }));
        black_box(update_virtual(&cfg, &mut state, &h, z, cast(0.01)));
    }
    black_box(&state);
    true
}

/// The thermocouple decoders and the plausibility check on every frame
/// pattern the optimiser cannot see.
#[inline(never)]
fn sensor_decoders() -> bool {
    let Ok(limits) = PlausibilityCheck::new(black_box(-50.0), black_box(400.0)) else {
        return false;
    };
    let mut plausibility = PlausibilityState::new();
    for k in 0..black_box(256u32) {
        let frame = black_box(k.wrapping_mul(0x9E37_79B9));
        let a = max31855::decode(frame);
        let block = black_box(frame.to_le_bytes());
        let b = max31856::decode(&[block[0], block[1], block[2], block[3], block[0], block[1]]);
        for reading in [a, b] {
            let temp_c = reading.map_or(f32::NAN, |r| r.temp_c);
            black_box(
                coil_thermal::sensors::check(
                    &limits,
                    &mut plausibility,
                    temp_c,
                    black_box(0.5),
                    black_box(if k % 9 == 0 { f32::INFINITY } else { 0.1 }),
                )
                .is_ok(),
            );
        }
    }
    true
}

#[inline(never)]
fn steppers() -> bool {
    match network() {
        Ok(net) => {
            let limits = InputLimits::default();
            match (
                ExplicitStepper::<f32, 3, 1, 1>::new(&net, black_box(1e-3), limits),
                ExplicitStepper::<Q32, 3, 1, 1>::new(&net, black_box(1e-3), limits),
            ) {
                (Ok(float_stepper), Ok(fixed_stepper)) => {
                    let mut state = NetworkState::<f32, 3, 1, 1>::uniform(20.0);
                    let mut fixed_state = NetworkState::<Q32, 3, 1, 1>::uniform(20.0);
                    for k in 0..black_box(1000u32) {
                        let current = black_box([if k % 7 == 0 { f32::NAN } else { 1.0 }]);
                        let ambient = black_box([if k % 11 == 0 { f32::INFINITY } else { 20.0 }]);
                        black_box(float_stepper.step(&mut state, &current, &ambient));
                        let fixed_in = [<Q32 as coil_thermal::Scalar>::from_f32(current[0])];
                        let fixed_amb = [<Q32 as coil_thermal::Scalar>::from_f32(ambient[0])];
                        black_box(fixed_stepper.step(&mut fixed_state, &fixed_in, &fixed_amb));
                    }
                    black_box(&state);
                    black_box(&fixed_state);
                    integer_step()
                }
                _ => false,
            }
        }
        Err(_) => false,
    }
}

/// `discretize::fixed`: the integer step on tables the optimiser cannot
/// see into, with NaN, infinite and extreme inputs and states.
#[inline(never)]
fn integer_step() -> bool {
    let tables: StepTables<3, 1, 1> = black_box(StepTables {
        phi_minus_i: [
            [-3.3e-5, 3.3e-5, 0.0],
            [5e-6, -1.2e-5, 7e-6],
            [0.0, 3e-6, -4.8e-6],
        ],
        bd_power: [[1.7e-5], [4e-11], [1e-16]],
        gd_boundary: [[1e-15], [1e-9], [1.7e-6]],
        constant_k: [0.0; 3],
    });
    let Some(step) = FixedStep::of(&tables) else {
        return false;
    };
    let mut states = black_box([0i64, i64::MAX, i64::MIN]);
    for k in 0..black_box(1000u32) {
        let power_w = black_box(if k % 7 == 0 { f32::NAN } else { f32::MAX });
        let boundary_k = black_box(if k % 11 == 0 { f32::INFINITY } else { -1e30 });
        if let Some(inputs) = FixedInputs::new(&[power_w], &[boundary_k]) {
            step.step(&mut states, &inputs);
        }
        black_box(states.map(f32_of_state));
    }
    true
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    extern "C" {
        fn hot_path_has_a_reachable_panic() -> !;
    }
    // SAFETY: never executed in a successful build: the symbol does not exist,
    // so the link fails if this handler is reachable at all (see module docs).
    unsafe { hot_path_has_a_reachable_panic() }
}
