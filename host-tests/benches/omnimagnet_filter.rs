//! The Omnimagnet observer's per-tick costs against the 0.1 ms budget of a
//! 1 ms control loop: predict (steady-state mean-only and time-varying),
//! a correction with six thermocouples (steady-state and time-varying gain),
//! and the background gain solve.
//!
//! `cargo bench -p coil-thermal-host --bench omnimagnet_filter`

use coil_thermal::omnimagnet::observer::{GainMode, ObserverSettings, OmnimagnetObserver};
use coil_thermal::omnimagnet::{Omnimagnet, Preset, NODES, THERMOCOUPLES, THERMOCOUPLE_NODES};
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::RealField;
use std::hint::black_box;

const AMBIENT_C: f64 = 22.0;

/// An observer at 1 ms, linearised and started at a warm state.
fn observer<T: RealField + Copy>(mode: GainMode) -> OmnimagnetObserver<T> {
    let model = Omnimagnet::PAPER;
    let mut warm = [AMBIENT_C; NODES];
    Preset::ALL_THREE.run(&model, &mut warm, AMBIENT_C, |t| t[0] >= 50.0);
    let lin = model.linearize(&warm, AMBIENT_C, 1e-3).unwrap();
    let mut settings = ObserverSettings::DEFAULT;
    settings.warmup_corrections = 0;
    // Stays in this mode (no switch to the steady gain after a correction).
    settings.mode = mode;
    let mut obs = OmnimagnetObserver::new(&model, &lin, &settings, &warm, AMBIENT_C).unwrap();
    obs.set_mode(mode);
    obs
}

/// Readings equal to the estimate: every one passes the gate and is fused.
fn readings<T: RealField + Copy>(obs: &OmnimagnetObserver<T>) -> [Option<T>; THERMOCOUPLES] {
    let t = obs.temperatures_c();
    core::array::from_fn(|j| Some(t[THERMOCOUPLE_NODES[j]]))
}

fn bench_type<T: RealField + Copy>(c: &mut Criterion, name: &str) {
    let currents: [T; 3] = [nalgebra::convert(3.8); 3];
    let ambient: T = nalgebra::convert(AMBIENT_C);
    for (mode, label) in [
        (GainMode::SteadyState, "steady"),
        (GainMode::TimeVarying, "time_varying"),
    ] {
        let mut obs = observer::<T>(mode);
        c.bench_function(&format!("omnimagnet_predict_{label}_{name}"), |b| {
            b.iter(|| obs.predict(black_box(&currents), black_box(ambient)))
        });
        let mut obs = observer::<T>(mode);
        let z = readings(&obs);
        c.bench_function(&format!("omnimagnet_correct6_{label}_{name}"), |b| {
            b.iter(|| {
                let rep = obs.correct(black_box(&z));
                assert_eq!(rep.fused(), THERMOCOUPLES);
                rep
            })
        });
    }
}

fn benches(c: &mut Criterion) {
    bench_type::<f32>(c, "f32");
    bench_type::<f64>(c, "f64");
    let obs = observer::<f64>(GainMode::SteadyState);
    c.bench_function("omnimagnet_solve_gain_f64", |b| {
        b.iter(|| obs.config().solve_gain().unwrap())
    });
}

criterion_group!(omnimagnet_filter, benches);
criterion_main!(omnimagnet_filter);
