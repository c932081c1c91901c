//! A lower bound on one state, kept by projecting the estimate.
//!
//! Some states have a side that physics or safety forbids: the observers'
//! heat-input bias may say the device heats *more* than the model (a model
//! that runs cold must be corrected), but a bias that says it heats *less*
//! is what a thermocouple drifting or stuck cold looks like, and with one
//! sensor the two cannot be told apart. Clamping the bias alone is not
//! enough: the correction that pushed it below its floor also moved the
//! temperatures, through the bias's covariance with them (a housing sensor
//! reading cold pulls an unmeasured winding further down than the housing,
//! because the filter explains it as less winding heat).
//!
//! So the estimate is *projected*: with the Gaussian posterior `N(x, P)`,
//! the most probable state on the bound `x_k = floor` is
//!
//! `x' = x - P e_k (x_k - floor) / P_kk`
//!
//! (the estimate conditioned on `x_k = floor`; the projection in the
//! `P^-1` norm, Simon and Chia's estimate projection). Every state moves by
//! its regression on `x_k`: for the bias, exactly to the floor; for a
//! temperature, back by what that part of the correction had given it.
//! [`condition_on`] is the same step to a given value.

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, RealField};

/// Moves `x` onto `x[k] >= floor` if it is below (see the module docs),
/// with the covariance `cov` the estimate was corrected with; returns
/// whether it moved. A NaN `x[k]` or `floor`, or `k` out of range, leaves
/// `x` as it is. Cost: `N` multiply-adds.
pub fn project_onto_floor<T: RealField + Copy, N: Dim>(
    x: &mut OVector<T, N>,
    cov: &OMatrix<T, N, N>,
    k: usize,
    floor: T,
) -> bool
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    // Not `>=`: a NaN compares false either way and must not move `x`.
    match x.get(k) {
        Some(xk) if *xk < floor => condition_on(x, cov, k, floor),
        _ => false,
    }
}

/// Moves `x` to the most probable state with `x[k] = value` under
/// `N(x, cov)`: `x[k]` to `value`, every other state by its regression on
/// `x[k]` (`x -= P e_k (x_k - value) / P_kk`). The way to take back what a
/// state learnt from a sensor found lying (a stuck thermocouple's heat
/// bias goes back to its value when the reading last moved, and the
/// temperatures with it). A state with no variance (or a NaN one) is set
/// alone; a non-finite `value` or `x[k]`, or `k` out of range, leaves `x`
/// as it is; returns whether it moved. Cost: `N` multiply-adds.
pub fn condition_on<T: RealField + Copy, N: Dim>(
    x: &mut OVector<T, N>,
    cov: &OMatrix<T, N, N>,
    k: usize,
    value: T,
) -> bool
where
    DefaultAllocator: Allocator<N, N> + Allocator<N>,
{
    let Some(xk) = x.get(k).copied() else {
        return false;
    };
    if !(xk.is_finite() && value.is_finite()) {
        return false;
    }
    let pkk = cov.get((k, k)).copied().unwrap_or_else(T::zero);
    if pkk > T::zero() {
        let shift = (xk - value) / pkk;
        for (i, xi) in x.iter_mut().enumerate() {
            if let Some(pik) = cov.get((i, k)) {
                *xi -= *pik * shift;
            }
        }
    }
    // Exactly on the value, whatever the rounding of `P_kk / P_kk`.
    if let Some(xk) = x.get_mut(k) {
        *xk = value;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    /// The projection is the conditional mean of a Gaussian, written out
    /// by hand for two states.
    #[test]
    fn the_projection_is_the_mean_conditioned_on_the_bound() {
        // Temperature 2 K, bias -3 W; var 0.5 K^2, 4 W^2, cov 1.2 K W.
        let cov = Matrix2::new(0.5, 1.2, 1.2, 4.0);
        let mut x = Vector2::new(2.0f64, -3.0);
        assert!(project_onto_floor(&mut x, &cov, 1, 0.0));
        // E[T | b = 0] = 2 + (1.2 / 4) (0 - (-3)) = 2.9.
        assert!((x[0] - 2.9).abs() < 1e-12, "{}", x[0]);
        assert_eq!(x[1], 0.0);
    }

    #[test]
    fn a_state_above_its_floor_or_nan_is_left_alone() {
        let cov = Matrix2::new(1.0, 0.5, 0.5, 1.0);
        for (x, floor) in [
            (Vector2::new(1.0f32, 0.5), 0.0),
            (Vector2::new(1.0, 0.0), 0.0),
            (Vector2::new(1.0, f32::NAN), 0.0),
            (Vector2::new(1.0, -1.0), f32::NAN),
        ] {
            let mut moved = x;
            assert!(!project_onto_floor(&mut moved, &cov, 1, floor));
            assert_eq!(moved.map(f32::to_bits), x.map(f32::to_bits));
        }
        let mut x = Vector2::new(1.0f32, -1.0);
        assert!(!project_onto_floor(&mut x, &cov, 2, 0.0));
        assert_eq!(x, Vector2::new(1.0, -1.0));
    }

    #[test]
    fn conditioning_on_the_present_value_changes_nothing() {
        let cov = Matrix2::new(0.5, 1.2, 1.2, 4.0);
        let mut x = Vector2::new(2.0f64, -3.0);
        assert!(condition_on(&mut x, &cov, 1, -3.0));
        assert_eq!(x, Vector2::new(2.0, -3.0));
        // And back and forth returns to the start (a linear map).
        assert!(condition_on(&mut x, &cov, 1, 1.5));
        assert!(condition_on(&mut x, &cov, 1, -3.0));
        assert!((x[0] - 2.0).abs() < 1e-12 && x[1] == -3.0);
        assert!(!condition_on(&mut x, &cov, 1, f64::INFINITY));
        assert!(!condition_on(&mut x, &cov, 5, 0.0));
    }

    #[test]
    fn a_state_without_variance_is_clamped_alone() {
        let cov = Matrix2::new(1.0, 0.0, 0.0, 0.0);
        let mut x = Vector2::new(1.0f32, -2.0);
        assert!(project_onto_floor(&mut x, &cov, 1, -0.5));
        assert_eq!(x, Vector2::new(1.0, -0.5));
    }
}
