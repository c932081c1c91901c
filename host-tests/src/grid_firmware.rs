//! `replay --model hppa`: the HPPA grid replayed through the observer the
//! firmware flashes for it, the `GridObserver` of
//! [`codegen::grid_observer`](crate::codegen::grid_observer)
//! (`examples/observer_m4.rs`, `codegen --device hppa-grid`), not a
//! `NetworkObserver` over the grid's network: its finite-difference
//! stepper, its 20 ms grid updates, its protection plan, its HPPA derating.
//!
//! Only the report's 7 x 12 grid with its FDM fit is flashed; other sizes
//! and presets replay through the network observer (`replay` says which).
//! The grid observer has no thermocouple: open loop, as on the MCU.

use std::time::Instant;

use anyhow::{bail, Result};
use coil_thermal::observer::grid::{GridInputs, GridObserverState};
use coil_thermal::protect::derating::DeratingRule;

use crate::codegen::{grid_observer_with, HppaGridObserver};
use crate::library_observer::{EventKindAt, Protected};
use crate::observer::{Estimator, Measurement, TickClock, TimeHistogram};
use crate::sim::PlantInfo;

/// The flashed grid's rows and columns.
pub const ROWS: usize = 7;
/// See [`ROWS`].
pub const COLS: usize = 12;

/// The tick of the flashed grid observer \[us\].
pub const TICK_US: u32 = 1000;

/// The HPPA grid observer replayed tick by tick (see the module docs).
pub struct GridFirmwareEstimator {
    info: PlantInfo,
    observer: HppaGridObserver,
    state: Box<GridObserverState<f32, ROWS, COLS, { ROWS * COLS }>>,
    currents_a: [[f32; COLS]; ROWS],
    coolant_c: f32,
    ambient_c: f32,
    coolant: usize,
    ambient: usize,
    clock: TickClock,
    temps: Vec<f64>,
    tick_ns: TimeHistogram,
    protected: Protected,
    events: Vec<EventKindAt>,
}

impl GridFirmwareEstimator {
    /// The flashed observer with the alarm of `rule` on every coil's
    /// `critical_c` \[degC\], for the plant `info` (the 7 x 12 grid's model
    /// file: its nodes the coils row by row, boundaries `coolant` and
    /// `ambient`).
    ///
    /// # Errors
    /// Another grid, or a refusal of the library's builders.
    pub fn new(info: PlantInfo, rule: &DeratingRule, critical_c: f64) -> Result<Self> {
        let n = ROWS * COLS;
        if info.nodes.len() != n || info.inputs.len() != n {
            bail!(
                "the flashed grid observer is {ROWS} x {COLS}; model `{}` has {} nodes",
                info.name,
                info.nodes.len()
            );
        }
        let boundary = |name: &str| {
            info.boundaries
                .iter()
                .position(|b| b.name == name)
                .ok_or_else(|| anyhow::anyhow!("the grid's model has no `{name}` boundary"))
        };
        let (coolant, ambient) = (boundary("coolant")?, boundary("ambient")?);
        let observer = grid_observer_with(rule, critical_c)?;
        let state = Box::new(observer.state(crate::devices::GRID_DEFAULT_C));
        Ok(Self {
            observer,
            state,
            currents_a: [[0.0; COLS]; ROWS],
            coolant_c: 0.0,
            ambient_c: 0.0,
            coolant,
            ambient,
            clock: TickClock::default(),
            temps: vec![0.0; n],
            tick_ns: TimeHistogram::default(),
            protected: Protected::for_sizes(n, n),
            events: Vec::new(),
            info,
        })
    }

    /// The published outputs into `temps` and `protected`.
    fn publish(&mut self) {
        let o = self.state.outputs();
        let ambient_c = self.state.alarm.ambient_c();
        let alarm = self.observer.alarm();
        for r in 0..ROWS {
            for c in 0..COLS {
                let i = r * COLS + c;
                self.temps[i] = f64::from(o.temps_c[r][c]);
                self.protected.upper_c[i] = f64::from(o.upper_c[r][c]);
                self.protected.alarm_limit_c[i] = alarm.alarm_limit_c(i, ambient_c).map(f64::from);
                self.protected.source_limit_a[i] = f64::from(o.limits[i].current_a);
                self.protected.time_to_limit_s[i] = o.time_to_limit_s[i].map(f64::from);
            }
        }
        self.protected.warning = o.alarm.warning;
        self.protected.shutdown = o.alarm.shutdown;
        self.protected.predictive = o.alarm.predictive;
    }
}

impl Estimator for GridFirmwareEstimator {
    fn info(&self) -> &PlantInfo {
        &self.info
    }

    /// The grid observer starts uniform: at the mean of `temps_c`.
    fn reset(&mut self, temps_c: &[f64]) {
        let mean = temps_c.iter().sum::<f64>() / temps_c.len().max(1) as f64;
        *self.state = self.observer.state(mean);
        self.clock = TickClock::default();
        self.events.clear();
        self.publish();
    }

    fn predict(&mut self, dt_s: f64, currents_a: &[f64], boundary_c: &[f64], _signals: &[f64]) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        for (i, a) in currents_a.iter().enumerate().take(ROWS * COLS) {
            self.currents_a[i / COLS][i % COLS] = *a as f32;
        }
        self.coolant_c = boundary_c[self.coolant] as f32;
        self.ambient_c = boundary_c[self.ambient] as f32;
        self.clock.ask(dt_s);
        while self.clock.next_tick(TICK_US) {
            let inputs = GridInputs {
                currents_a: &self.currents_a,
                coolant_c: self.coolant_c,
                ambient_c: self.ambient_c,
                elapsed_us: TICK_US,
            };
            let start = Instant::now();
            std::hint::black_box(self.observer.tick(&mut self.state, &inputs));
            self.tick_ns.record(start.elapsed().as_nanos());
            let upper = self.state.outputs().upper_c;
            let ambient_c = self.state.alarm.ambient_c();
            let alarm = self.observer.alarm();
            while let Some(e) = self.state.events.pop() {
                self.events.push(EventKindAt::of(
                    &e,
                    self.clock.done_s(),
                    e.element.map(|i| upper[i / COLS][i % COLS]),
                    e.element.and_then(|i| alarm.alarm_limit_c(i, ambient_c)),
                    alarm.warning_margin_k(),
                ));
            }
        }
        self.publish();
    }

    /// No thermocouple: the grid observer runs open loop.
    fn update(&mut self, _measured: &[Measurement]) {}

    fn estimate_c(&self) -> &[f64] {
        &self.temps
    }

    fn kind(&self) -> &'static str {
        "grid-observer"
    }

    fn take_tick_times_ns(&mut self) -> Option<TimeHistogram> {
        Some(std::mem::take(&mut self.tick_ns))
    }

    fn firmware(&mut self, out: &mut Protected, events: &mut Vec<EventKindAt>) -> bool {
        out.clone_from(&self.protected);
        events.append(&mut self.events);
        true
    }
}
