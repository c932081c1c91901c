//! Readings outside the configured sensors: a *virtual sensor* whose noise
//! changes from reading to reading, fused like a thermocouple.
//!
//! The example is a winding's mean temperature from its resistance
//! ([`crate::protect::resistance_sensor`]): its variance grows as `1 / I^2`,
//! so it cannot be a fixed entry of `R`. Each reading brings its own
//! measurement row `h` (for a lumped model, the unit vector of the winding's
//! node) and variance `r`, is gated against the filter's threshold like a
//! configured sensor, and, if accepted, is fused as one scalar update.
//!
//! [`update_virtual`] is the exact Joseph update of the time-varying
//! filter's propagated covariance, `O(N^2)`. There is no steady-state
//! variant, on purpose: a steady gain is solved for a fixed sensor set and
//! fixed `R`, and a reading outside that design can only be fused from a
//! stored covariance that does not know it. Tried with the steady
//! posterior on the Omnimagnet test (`resistance_readings_are_fused_like_a_thermocouple`),
//! the estimate went *worse* (0.30 K against 0.24 K without the reading,
//! against 0.03 K time-varying): a resistance reading of a solenoid without
//! a thermocouple cannot teach a stored covariance that solenoid's heat
//! bias. A device that fuses virtual readings runs the time-varying filter
//! ([`crate::omnimagnet::observer::OmnimagnetObserver::correct_winding`] switches to
//! it).
//!
//! It does not touch the configured sensors' rejection counters: a virtual
//! sensor's verdict is returned to the caller, who keeps its own (for a
//! winding, [`crate::protect::resistance_sensor::DriftState`] watches the
//! residual instead). A non-finite `z`, a non-finite `h`, or `r` not finite
//! and positive is [`SensorVerdict::Missing`]: nothing changes.

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OVector, RealField};

use super::gate::{judge, SensorVerdict};
use super::kalman::{fuse_scalar, KalmanConfig, KalmanState};
use super::FilterAllocator;
use crate::sizes::Length;

/// `true` when the reading can be used at all.
fn usable_reading<T: RealField + Copy, N: Dim>(h: &OVector<T, N>, z: T, r: T) -> bool
where
    DefaultAllocator: Allocator<N>,
{
    z.is_finite() && r.is_finite() && r > T::zero() && h.iter().all(|v| v.is_finite())
}

/// Gates and fuses one virtual reading `z = h x + v`, `var(v) = r`, into the
/// time-varying filter `state` (see the module docs).
pub fn update_virtual<T: RealField + Copy, N: Length, M: Dim, P: Length>(
    cfg: &KalmanConfig<T, N, M, P>,
    state: &mut KalmanState<T, N, P>,
    h: &OVector<T, N>,
    z: T,
    r: T,
) -> SensorVerdict
where
    DefaultAllocator: FilterAllocator<N, M, P>,
{
    if !usable_reading(h, z, r) {
        return SensorVerdict::Missing;
    }
    let s = h.dot(&(&state.cov * h)) + r;
    let verdict = judge(z - h.dot(&state.x), s, cfg.gate.threshold);
    match verdict {
        SensorVerdict::Fused { nis } if !fuse_scalar(&mut state.x, &mut state.cov, h, r, z) => {
            SensorVerdict::Rejected { nis }
        }
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::testutil::{RandomSystem, Rng};
    use crate::filter::update;
    use nalgebra::{Const, SMatrix, SVector, U1};

    type Cfg = KalmanConfig<f64, Const<4>, U1, Const<2>>;

    fn system(seed: u64) -> (Cfg, RandomSystem<4, 2>, Rng) {
        let mut rng = Rng::new(seed);
        let sys = RandomSystem::<4, 2>::new(&mut rng, 0.98, 0.01);
        let cfg = Cfg::new(sys.f, rng.matrix(), sys.h, sys.q, sys.r).unwrap();
        (cfg, sys, rng)
    }

    /// A virtual reading is the same update as a configured sensor with the
    /// same row and variance: checked against a filter that has it as its
    /// only sensor.
    #[test]
    fn a_virtual_reading_equals_a_configured_sensor() {
        for seed in 1..20 {
            let (cfg, sys, mut rng) = system(seed);
            let h: SVector<f64, 4> = rng.matrix();
            let r = 0.05 + rng.uniform();
            let one = KalmanConfig::<f64, Const<4>, U1, U1>::new(
                sys.f,
                SMatrix::zeros(),
                h.transpose(),
                sys.q,
                SVector::<f64, 1>::new(r),
            )
            .unwrap();
            let x0: SVector<f64, 4> = rng.matrix();
            let a: SMatrix<f64, 4, 4> = rng.matrix();
            let p0 = a * a.transpose() + SMatrix::identity();
            let z = h.dot(&x0) + 0.3 * rng.gauss();
            let mut virt = KalmanState::<f64, Const<4>, Const<2>>::new(x0, p0);
            let mut conf = KalmanState::<f64, Const<4>, U1>::new(x0, p0);
            let v = update_virtual(&cfg, &mut virt, &h, z, r);
            let c = update(&one, &mut conf, &[Some(z)]).verdicts[0];
            assert_eq!(v, c, "seed {seed}");
            assert!((virt.x - conf.x).abs().max() < 1e-12, "seed {seed}");
            assert!((virt.cov - conf.cov).abs().max() < 1e-12, "seed {seed}");
        }
    }

    /// Bad readings change nothing; an implausible one is rejected.
    #[test]
    fn bad_and_implausible_readings() {
        let (cfg, _, _) = system(3);
        let h = SVector::<f64, 4>::new(1.0, 0.0, 0.0, 0.0);
        let p0 = SMatrix::<f64, 4, 4>::identity() * 0.01;
        let zero = SVector::<f64, 4>::zeros();
        for (hh, z, r) in [
            (h, f64::NAN, 0.1),
            (h, f64::INFINITY, 0.1),
            (h, 1.0, 0.0),
            (h, 1.0, -1.0),
            (h, 1.0, f64::NAN),
            (h * f64::NAN, 1.0, 0.1),
        ] {
            let mut state = KalmanState::<f64, Const<4>, Const<2>>::new(zero, p0);
            let before = state;
            assert_eq!(
                update_virtual(&cfg, &mut state, &hh, z, r),
                SensorVerdict::Missing
            );
            assert_eq!(state, before);
        }
        // 30 K off with a 0.1 K sigma and a 0.1 K prior: far past the gate.
        let mut state = KalmanState::<f64, Const<4>, Const<2>>::new(zero, p0);
        let v = update_virtual(&cfg, &mut state, &h, 30.0, 0.01);
        assert!(v.is_rejected() && state.x == zero);
    }
}
