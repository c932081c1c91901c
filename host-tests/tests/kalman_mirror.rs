//! The run-time-size filter of `replay --measure` (`kalman.rs`) is the
//! library's filter: same results on fixed-size instances, including the
//! gate, missing readings and the recovery.

use coil_thermal::discretize;
use coil_thermal::filter::{predict, update, KalmanConfig, KalmanState};
use coil_thermal_host::kalman::{self, DynKalman, DynKalmanState};
use nalgebra::{DMatrix, DVector, SMatrix, SVector};

/// A 4-node chain with boundary links: a thermal network's `A`.
fn chain_a() -> SMatrix<f64, 4, 4> {
    let c = [1200.0, 2900.0, 800.0, 6800.0];
    let g = [(0, 1, 2.0), (0, 2, 600.0), (1, 2, 50.0), (2, 3, 32.0)];
    let mut a = SMatrix::<f64, 4, 4>::zeros();
    for (i, j, gij) in g {
        a[(i, j)] += gij / c[i];
        a[(j, i)] += gij / c[j];
        a[(i, i)] -= gij / c[i];
        a[(j, j)] -= gij / c[j];
    }
    a[(3, 3)] -= 148.0 / c[3];
    a
}

fn dyn_of<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> DMatrix<f64> {
    DMatrix::from_column_slice(R, C, m.as_slice())
}

#[test]
fn expm_matches_the_library_bit_for_bit() {
    let a = chain_a();
    for h in [0.1, 1.0, 7.5, 600.0] {
        let (e, phi) = discretize::expm_with_integral(&a, h).unwrap();
        let (de, dphi) = kalman::expm_with_integral(&dyn_of(&a), h).unwrap();
        assert_eq!(de.as_slice(), e.as_slice(), "exp(A h), h = {h}");
        assert_eq!(dphi.as_slice(), phi.as_slice(), "integral, h = {h}");
    }
    assert!(kalman::expm_with_integral(&dyn_of(&a), 0.0).is_err());
    assert!(kalman::expm_with_integral(&dyn_of(&a), f64::NAN).is_err());
}

#[test]
fn filter_matches_the_library_bit_for_bit() {
    let (f, phi) = discretize::expm_with_integral(&chain_a(), 1.0).unwrap();
    let mut b = SMatrix::<f64, 4, 3>::zeros();
    b[(0, 0)] = 1.0 / 1200.0;
    b[(1, 1)] = 1.0 / 2900.0;
    b[(3, 2)] = 148.0 / 6800.0;
    let g = phi * b;
    let mut h = SMatrix::<f64, 2, 4>::zeros();
    h[(0, 1)] = 1.0;
    h[(1, 3)] = 1.0;
    let q = SMatrix::<f64, 4, 4>::from_diagonal(&SVector::from([1e-4, 2e-4, 1e-4, 5e-5]));
    let r = SVector::<f64, 2>::from([0.04, 0.09]);
    let cfg = KalmanConfig::<f64, 4, 3, 2>::new(f, g, h, q, r).unwrap();
    let dcfg = DynKalman::new(
        dyn_of(&f),
        dyn_of(&g),
        dyn_of(&h),
        dyn_of(&q),
        DVector::from_column_slice(r.as_slice()),
    )
    .unwrap();
    let x0 = SVector::<f64, 4>::from([25.0, 25.5, 25.2, 25.1]);
    let p0 = SMatrix::<f64, 4, 4>::identity() * 4.0;
    let mut st = KalmanState::<f64, 4, 2>::new(x0, p0);
    let mut dst = DynKalmanState::new(DVector::from_column_slice(x0.as_slice()), dyn_of(&p0), 2);
    let mut recovered = 0;
    let mut rejected = 0;
    let mut missing = 0;
    for k in 0..400 {
        let u = SVector::<f64, 3>::from([300.0 + (k % 37) as f64 * 10.0, 120.0, 25.0]);
        predict(&cfg, &mut st, &u);
        kalman::predict(&dcfg, &mut dst, &DVector::from_column_slice(u.as_slice()));
        // Healthy readings, a missing one, and a stuck-high stretch on both
        // sensors (k in 200..220) that the gate rejects and that triggers
        // the recovery.
        let mut z = [Some(25.0 + 0.01 * k as f64), Some(25.3 + 0.004 * k as f64)];
        if k % 11 == 3 {
            z[1] = None;
        }
        if (200..220).contains(&k) {
            z = [Some(90.0), Some(95.0)];
        }
        let rep = update(&cfg, &mut st, &z);
        let drep = kalman::update(&dcfg, &mut dst, &z);
        assert_eq!(
            drep.verdicts.as_slice(),
            rep.verdicts.as_slice(),
            "step {k}"
        );
        assert_eq!(drep.suspect.as_slice(), rep.suspect.as_slice(), "step {k}");
        assert_eq!(drep.recovered, rep.recovered, "step {k}");
        assert_eq!(dst.x.as_slice(), st.x.as_slice(), "x at step {k}");
        assert_eq!(dst.cov.as_slice(), st.cov.as_slice(), "P at step {k}");
        recovered += usize::from(rep.recovered);
        rejected += rep.rejected();
        missing += rep
            .verdicts
            .iter()
            .filter(|v| matches!(v, coil_thermal::filter::SensorVerdict::Missing))
            .count();
    }
    // The sequence exercised every branch.
    assert!(
        recovered > 0 && rejected > 0 && missing > 0,
        "{recovered} {rejected} {missing}"
    );
}
