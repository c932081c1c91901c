//! The per-tick protection path for a 16-element network (the Omnimagnet's
//! size): the sliced time-to-limit predictor, the alarm tick and the current
//! limiter, against the 0.1 ms share of a 1 ms loop. A full predictor sweep
//! and a safe-current bound are measured too, as the costs of calls that are
//! not meant for every tick.
//!
//! `cargo bench -p coil-thermal-host --bench protect`

use std::hint::black_box;

use coil_thermal::protect::alarm::{AlarmBuilder, AlarmState};
use coil_thermal::protect::derating::{DeratingRule, OMNIMAGNET_COVER_INSULATION_CRITICAL_C};
use coil_thermal::protect::events::EventQueue;
use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
use coil_thermal::protect::predict::{Operating, PredictorBuilder, PredictorState};
use coil_thermal::protect::safe_current::Horizon;
use coil_thermal::{Network, Resistance};
use criterion::{criterion_group, criterion_main, Criterion};

/// A 16-node chain-and-ring network with three windings, shaped like the
/// Omnimagnet (three solenoids, frames, insulation, air, core).
fn network() -> Network<16, 1, 3> {
    let capacity = core::array::from_fn(|i| 20.0 + 37.0 * ((i * 7) % 11) as f64);
    let mut n = Network::new(capacity).unwrap();
    for i in 0..15 {
        n = n.connect(i, i + 1, 0.2 + 0.05 * (i % 4) as f64).unwrap();
    }
    for i in (0..16).step_by(3) {
        n = n.connect(i, (i + 5) % 16, 0.1).unwrap();
    }
    for i in [5, 6, 8, 11, 12, 15] {
        n = n.connect_boundary(i, 0, 0.3).unwrap();
    }
    for (m, r0) in [3.2, 2.8, 3.1].into_iter().enumerate() {
        n = n
            .joule_source(m, m, Resistance::with_alpha(r0, 0.0039, 20.0))
            .unwrap();
    }
    n
}

fn bench(c: &mut Criterion) {
    let network = network();
    let predictor = PredictorBuilder::new()
        .build::<f32, 16, 1, 3, 48>(&network)
        .unwrap();
    let alarm = AlarmBuilder::new(
        &DeratingRule::omnimagnet(),
        [OMNIMAGNET_COVER_INSULATION_CRITICAL_C; 16],
    )
    .build::<f32>()
    .unwrap();
    let limiter = LimiterConfig::<f32, 3>::new([8.0; 3], 10.0, 0.0).unwrap();
    let ambient = 20.0f32;
    let limits = alarm.alarm_limits_c(ambient);
    let op = Operating {
        temps_c: core::array::from_fn(|i| 30.0 + i as f32),
        currents_a: [3.0, 2.5, 3.5],
        boundary_c: [ambient],
        limits_c: limits,
    };
    let mut state = PredictorState::new(&predictor, &op);
    let mut alarm_state = AlarmState::new(&alarm);
    let mut events = EventQueue::<32>::new();
    let mut coil_limits = [CoilLimit::default(); 3];

    c.bench_function(
        "protect tick (predictor slice + alarm + limiter), N = 16",
        |b| {
            b.iter(|| {
                let op = black_box(&op);
                let ttl = *state.tick(&predictor, op);
                let status = alarm_state.tick(&alarm, &op.temps_c, ambient, &ttl, &mut events);
                let coil_temps = [op.temps_c[0], op.temps_c[1], op.temps_c[2]];
                let coil_alarm = [limits[0], limits[1], limits[2]];
                limiter.apply(&coil_temps, &coil_alarm, ambient, &mut coil_limits);
                while events.pop().is_some() {}
                black_box((status, coil_limits))
            })
        },
    );
    c.bench_function("predictor slice only, N = 16", |b| {
        b.iter(|| black_box(*state.tick(&predictor, black_box(&op))))
    });
    c.bench_function("full predictor sweep (48 horizons), N = 16", |b| {
        let mut out = [None; 16];
        b.iter(|| {
            predictor.predict(black_box(&op), &mut out);
            black_box(out)
        })
    });
    c.bench_function("max common scale, 600 s horizon, N = 16", |b| {
        b.iter(|| {
            black_box(predictor.max_common_scale(black_box(&op), Horizon::Seconds(600.0), 1.0))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
