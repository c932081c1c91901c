//! One step of the 84-coil HPPA grid (7 x 12, herringbone, ambient padding,
//! R(T)) in f32, f64 and Q32, against the report's 0.1 ms per step.
//!
//! `cargo bench -p coil-thermal-host --bench grid_step`
//!
//! * `update`: one grid update (all flows, the compensated temperature add);
//! * `tick`: one 1 kHz controller tick with an update every tick (input
//!   checks, Joule accounting, update): the cost of the undecimated observer;
//! * `tick_decimated_10`: the average tick when the grid updates every 10.
use coil_thermal::grid::{CoilGrid, GridConfig, GridState};
use coil_thermal::{Scalar, Q32};
use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::time::Duration;

const BUDGET_NS: f64 = 100_000.0;

fn bench_scalar<S: Scalar>(c: &mut Criterion, name: &str) {
    let grid = CoilGrid::<S, 7, 12>::new(&GridConfig::default()).unwrap();
    let decimated = CoilGrid::<S, 7, 12>::new(&GridConfig {
        ticks_per_update: 10,
        ..GridConfig::default()
    })
    .unwrap();
    let currents: [[S; 12]; 7] = std::array::from_fn(|r| {
        std::array::from_fn(|c| S::from_f64(((r * 12 + c) % 5) as f64 * 0.3))
    });
    let (coolant, ambient) = (S::from_f64(19.0), S::from_f64(22.0));
    let mut state = GridState::<S, 7, 12>::uniform(20.0);
    let mut group = c.benchmark_group(format!("grid_7x12/{name}"));
    group.bench_function("update", |b| b.iter(|| grid.update(black_box(&mut state))));
    let mut state = GridState::<S, 7, 12>::uniform(20.0);
    group.bench_function("tick", |b| {
        b.iter(|| {
            grid.tick(
                black_box(&mut state),
                black_box(&currents),
                coolant,
                ambient,
            )
        })
    });
    let mut state = GridState::<S, 7, 12>::uniform(20.0);
    group.bench_function("tick_decimated_10", |b| {
        b.iter(|| {
            decimated.tick(
                black_box(&mut state),
                black_box(&currents),
                coolant,
                ambient,
            )
        })
    });
    group.finish();
    let _ = BUDGET_NS;
}

fn benches(c: &mut Criterion) {
    bench_scalar::<f32>(c, "f32");
    bench_scalar::<f64>(c, "f64");
    bench_scalar::<Q32>(c, "q32");
}

criterion_group! {
    name = grid;
    config = Criterion::default()
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2))
        .sample_size(30);
    targets = benches
}
criterion_main!(grid);
