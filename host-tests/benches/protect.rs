//! The per-tick protection path against the 0.1 ms share of a 1 ms loop,
//! alone and together with the models it protects:
//!
//! * `protect tick, N = 16`: the sliced time-to-limit predictor, the alarm
//!   tick and the current limiter on the Omnimagnet's network
//!   ([`ProtectTick`]);
//! * `grid observer + protection, 84 coils f32`: commands clamped by the
//!   limits, then `GridObserver::tick` (grid step; after each update, which
//!   comes every 10 ticks, the time to limit, the alarm and the limiter);
//!   timed over one update cycle of 10 ticks ([`GridLoop`]), and the two
//!   heaviest ticks alone (the grid update, the time-to-limit stage);
//! * `omnimagnet observer + protection, f32`: commands clamped, then
//!   `OmniObserver::tick` (model predict, predictor slice, alarm on six
//!   elements, limiter) without readings ([`OmniLoop`]).
//!
//! A full predictor sweep and a safe-current bound are measured too, as the
//! costs of calls that are not meant for every tick. The fixtures are the
//! ones `coil-thermal bench` times (`coil_thermal_host::bench`).
//!
//! `cargo bench -p coil-thermal-host --bench protect`

use std::hint::black_box;
use std::time::Duration;

use coil_thermal::protect::safe_current::Horizon;
use coil_thermal_host::bench::{GridLoop, OmniLoop, ProtectTick, GRID_TICKS_PER_UPDATE};
use criterion::{criterion_group, criterion_main, BatchSize, Criterion};

fn bench(c: &mut Criterion) {
    let mut protect = ProtectTick::new();
    c.bench_function(
        "protect tick (predictor slice + alarm + limiter), N = 16",
        |b| b.iter(|| black_box(protect.tick())),
    );
    let mut grid = GridLoop::new();
    c.bench_function(
        &format!("grid observer + protection, 84 coils f32, {GRID_TICKS_PER_UPDATE} ticks (one update cycle)"),
        |b| {
            b.iter(|| {
                for _ in 0..GRID_TICKS_PER_UPDATE {
                    black_box(grid.tick());
                }
            })
        },
    );
    // The heaviest single ticks: the grid update, and the time-to-limit
    // stage that follows it (each from a fresh copy of the aligned loop).
    for (phase, name) in [(0, "grid update"), (1, "time to limit")] {
        let mut aligned = GridLoop::new();
        aligned.align(phase);
        c.bench_function(
            &format!("grid observer + protection, 84 coils f32, one tick: {name}"),
            |b| {
                b.iter_batched_ref(
                    || aligned.clone(),
                    |l| black_box(l.tick()),
                    BatchSize::SmallInput,
                )
            },
        );
    }
    let mut omni = OmniLoop::new();
    let mut now_us = 0u32;
    c.bench_function("omnimagnet observer + protection, f32, one tick", |b| {
        b.iter(|| {
            now_us = now_us.wrapping_add(1000);
            black_box(omni.tick(now_us))
        })
    });
    let predictor = protect.predictor().clone();
    let op = *protect.operating();
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

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(30);
    targets = bench
}
criterion_main!(benches);
