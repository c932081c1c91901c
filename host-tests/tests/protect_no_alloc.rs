//! The per-tick protection path (predictor slice, alarm, limiter, resistance
//! sensor, drift check) and the safe-current bound allocate nothing: every
//! allocation on this test's thread is counted.

use coil_thermal::nalgebra::Const;
use coil_thermal_host::alloc_count::{count_allocations, CountingAllocator};

use coil_thermal::protect::alarm::{AlarmBuilder, AlarmState};
use coil_thermal::protect::derating::DeratingRule;
use coil_thermal::protect::events::EventQueue;
use coil_thermal::protect::limiter::{CoilLimit, LimiterConfig};
use coil_thermal::protect::predict::{Operating, PredictorBuilder, PredictorState};
use coil_thermal::protect::resistance_sensor::{DriftConfig, DriftState, ResistanceSensor};
use coil_thermal::protect::safe_current::Horizon;
use coil_thermal::{Network, Resistance};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

#[test]
fn the_counter_sees_allocations() {
    let n = count_allocations(|| {
        std::hint::black_box(Vec::<u8>::with_capacity(std::hint::black_box(16)));
    });
    assert_eq!(n, 1);
}

#[test]
fn protection_ticks_allocate_nothing() {
    let network: Network<3, 1, 2> = Network::new([68.7, 40.0, 400.0])
        .unwrap()
        .connect(0, 1, 0.35)
        .unwrap()
        .connect(1, 2, 0.8)
        .unwrap()
        .connect_boundary(2, 0, 1.5)
        .unwrap()
        .joule_source(0, 0, Resistance::HPPA_COIL)
        .unwrap()
        .joule_source(1, 1, Resistance::HPPA_COIL)
        .unwrap();
    let predictor = PredictorBuilder::new()
        .build::<f32, 3, 1, 2, 48>(&network)
        .unwrap();
    let alarm = AlarmBuilder::new(&DeratingRule::hppa(), [100.0; 3])
        .build::<f32>()
        .unwrap();
    let limiter = LimiterConfig::<f32, Const<2>>::new([3.0; 2], 10.0, 0.0).unwrap();
    let sensor = ResistanceSensor::new(Resistance::HPPA_COIL, 0.01, 1e-3, 0.2).unwrap();
    let drift = DriftConfig::new(1e-3, 10.0, 3.0, 5.0).unwrap();
    let limits = alarm.alarm_limits_c(20.0);
    let mut op = Operating {
        temps_c: [30.0, 28.0, 22.0],
        currents_a: [1.5, 0.5],
        boundary_c: [20.0],
        limits_c: limits,
    };
    let mut state = PredictorState::new(&predictor, &op);
    let mut alarm_state = AlarmState::new(&alarm);
    let mut events = EventQueue::<8>::new();
    let mut coil_limits = [CoilLimit::default(); 2];
    let mut drift_state = DriftState::default();
    let n = count_allocations(|| {
        for k in 0..20_000 {
            op.temps_c[0] = 30.0 + k as f32 * 1e-3;
            op.currents_a[0] = if k % 97 == 0 { f32::NAN } else { 1.5 };
            let ttl = *state.tick(&predictor, std::hint::black_box(&op));
            alarm_state.tick(&alarm, &op.temps_c, 20.0, &ttl, &mut events);
            limiter.apply(
                &[op.temps_c[0], op.temps_c[1]],
                &[limits[0], limits[1]],
                20.0,
                &mut coil_limits,
            );
            let reading = sensor.read(1.5 * 6.0, 1.5);
            drift_state.update(&drift, reading, op.temps_c[0]);
            while events.pop().is_some() {}
        }
        let s = predictor.max_common_scale(&op, Horizon::Seconds(600.0), 1.0);
        let c = predictor.max_coil_current_a(1, &op, Horizon::Forever, 0.5);
        std::hint::black_box((s, c));
    });
    assert_eq!(n, 0);
}
