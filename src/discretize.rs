//! Exact zero-order-hold discretisation, for any step.
//!
//! For `dT/dt = A T + B p + G T_b + d` with inputs held constant over a step
//! `h`, the exact step is
//!
//! ```text
//! T[k+1] = E T[k] + Phi B p[k] + Phi G T_b[k] + Phi d,
//! E = exp(A h),   Phi = integral_0^h exp(A s) ds.
//! ```
//!
//! Both come from one scaling-and-squaring pass, with no augmented matrix (so
//! the sizes stay the network's own, `N`, `M`, `B`): Taylor series of `E` and
//! `Phi` at `h / 2^s` with `||A h / 2^s||_1 <= 1/4`, where 16 terms leave a
//! truncation error below 1e-20, then `s` doublings
//!
//! ```text
//! Phi(2h) = Phi(h) (I + E(h)),   E(2h) = E(h)^2.
//! ```
//!
//! Build-time code (`O(N^3 log ||A h||)`), `no_std`, no allocation for a
//! network of [`ConstSizes`] (one read at run time, `RunTimeSizes`, gets
//! its matrices on the heap: see [`crate::sizes`]). The step itself
//! ([`Discrete::step`]) is a matrix-vector product and works in `f32`.

pub mod fixed;

use crate::error::BuildError;
use crate::network::StateSpace;
use crate::sizes::{ConstSizes, NetworkAllocator, Sizes};
use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, RealField, SMatrix};

/// One step of a network's exact zero-order hold in the network
/// observer's deviation coordinates (see "f32 without drift" in
/// [`network`](crate::observer::network)): the model's step
/// ([`ModelTables`](crate::observer::network::ModelTables)) or the
/// shadow's block of a correction period
/// ([`ShadowTables`](crate::observer::network::ShadowTables)), every entry
/// solved in `f64` and rounded once to `f32`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepTables<const N: usize, const B: usize, const M: usize> {
    /// `Ad - I`, formed in `f64` (dimensionless).
    pub phi_minus_i: [[f32; N]; N],
    /// `Bd` of the Joule powers over the step \[K/W\].
    pub bd_power: [[f32; M]; N],
    /// `Gd` of the boundaries (dimensionless).
    pub gd_boundary: [[f32; B]; N],
    /// `dd + (Ad - I) T_0 + Gd T_0` \[K\], formed in `f64`.
    pub constant_k: [f32; N],
}

/// A square `f64` matrix of dimension `D` (`Const<N>` or `Dyn`).
pub type Square<D> = OMatrix<f64, D, D>;

/// Taylor terms kept at the scaled step.
const TAYLOR_TERMS: usize = 16;
/// Most halvings of the step (bounds the loop; `||A h|| < 2^58` always fits).
const MAX_SQUARINGS: u32 = 60;

/// `exp(A h)` and `integral_0^h exp(A s) ds` by scaling and squaring.
///
/// Errors with [`BuildError::InvalidTimeStep`] for `h` not finite or `<= 0`,
/// and [`BuildError::InvalidParameter`] when `A h` is not finite or too large.
pub fn expm_with_integral<D: Dim>(
    a: &OMatrix<f64, D, D>,
    h: f64,
) -> Result<(Square<D>, Square<D>), BuildError>
where
    DefaultAllocator: Allocator<D, D>,
{
    let mut work = SlicedExpm::new(a, h)?;
    // Bounded: at most TAYLOR_TERMS / 2 + MAX_SQUARINGS slices.
    while !work.slice() {}
    Ok(work.result())
}

/// Products of `N x N` matrices one [`SlicedExpm::slice`] performs at most.
pub const MATMULS_PER_SLICE: usize = 2;

#[derive(Debug, Clone, Copy, PartialEq)]
enum ExpmPhase {
    Taylor { next_term: usize },
    Squaring { left: u32 },
    Done,
}

/// [`expm_with_integral`] cut into slices of bounded work, for a task that
/// must not block: each [`SlicedExpm::slice`] does at most
/// [`MATMULS_PER_SLICE`] matrix products. The slices compute exactly what the
/// one-shot call computes, in the same order, so the results are equal bit for
/// bit. A full run takes `TAYLOR_TERMS / 2 + s` slices (8 + s), `s` the number
/// of squarings (`||A h||_1 <= 2^s / 4`).
#[derive(Debug, Clone, PartialEq)]
pub struct SlicedExpm<D: Dim>
where
    DefaultAllocator: Allocator<D, D>,
{
    x: OMatrix<f64, D, D>,
    term: OMatrix<f64, D, D>,
    e: OMatrix<f64, D, D>,
    phi: OMatrix<f64, D, D>,
    scaled_h: f64,
    squarings: u32,
    phase: ExpmPhase,
}

impl<D: Dim> SlicedExpm<D>
where
    DefaultAllocator: Allocator<D, D>,
{
    /// Chooses the scaling for `exp(A h)` (`O(N^2)` work); no product yet.
    pub fn new(a: &OMatrix<f64, D, D>, h: f64) -> Result<Self, BuildError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(BuildError::InvalidTimeStep);
        }
        let ah = a * h;
        if !ah.iter().all(|v| v.is_finite()) {
            return Err(BuildError::InvalidParameter { name: "a" });
        }
        let norm = ah
            .column_iter()
            .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
            .fold(0.0, f64::max);
        let mut squarings = 0;
        let mut scale = 1.0;
        while norm * scale > 0.25 {
            squarings += 1;
            scale *= 0.5;
            if squarings > MAX_SQUARINGS {
                return Err(BuildError::InvalidParameter { name: "a" });
            }
        }
        let scaled_h = h * scale;
        let (rows, columns) = a.shape_generic();
        let identity = OMatrix::<f64, D, D>::identity_generic(rows, columns);
        Ok(Self {
            x: a * scaled_h,
            term: identity.clone(),
            e: identity.clone(),
            phi: identity,
            scaled_h,
            squarings,
            phase: ExpmPhase::Taylor { next_term: 1 },
        })
    }

    /// Does one slice of work; `true` once the result is ready.
    pub fn slice(&mut self) -> bool {
        self.phase = match self.phase {
            ExpmPhase::Taylor { next_term } => {
                // E = sum X^k / k!, Phi / h_s = sum X^k / (k+1)!
                let end = (next_term + MATMULS_PER_SLICE).min(TAYLOR_TERMS);
                for k in next_term..end {
                    self.term = &self.term * &self.x / (k as f64);
                    self.e += &self.term;
                    self.phi += &self.term / ((k + 1) as f64);
                }
                if end < TAYLOR_TERMS {
                    ExpmPhase::Taylor { next_term: end }
                } else {
                    self.phi *= self.scaled_h;
                    match self.squarings {
                        0 => ExpmPhase::Done,
                        left => ExpmPhase::Squaring { left },
                    }
                }
            }
            ExpmPhase::Squaring { left } => {
                // Phi(2h) = Phi(h) (I + E(h)), E(2h) = E(h)^2
                let (rows, columns) = self.e.shape_generic();
                self.phi *= OMatrix::<f64, D, D>::identity_generic(rows, columns) + &self.e;
                self.e = &self.e * &self.e;
                if left <= 1 {
                    ExpmPhase::Done
                } else {
                    ExpmPhase::Squaring { left: left - 1 }
                }
            }
            ExpmPhase::Done => ExpmPhase::Done,
        };
        self.phase == ExpmPhase::Done
    }

    /// `true` once every slice is done.
    pub fn is_done(&self) -> bool {
        self.phase == ExpmPhase::Done
    }

    /// The number of squarings chosen for this `A h`.
    pub fn squarings(&self) -> u32 {
        self.squarings
    }

    /// `(exp(A h), integral_0^h exp(A s) ds)`; meaningful once
    /// [`SlicedExpm::is_done`].
    pub fn result(&self) -> (OMatrix<f64, D, D>, OMatrix<f64, D, D>) {
        (self.e.clone(), self.phi.clone())
    }
}

/// A network discretised exactly for one step `dt_s`, in `f32` or `f64`,
/// with matrices of the network's [`Sizes`] `Z`.
#[derive(Debug, Clone, PartialEq)]
pub struct Discrete<T: RealField + Copy, Z: Sizes>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    /// The step \[s\].
    pub dt_s: f64,
    /// State transition `exp(A dt)`.
    pub ad: OMatrix<T, Z::NodeDim, Z::NodeDim>,
    /// Power input matrix `Phi B` \[K/W\].
    pub bd_power: OMatrix<T, Z::NodeDim, Z::InputDim>,
    /// Boundary matrix `Phi G` (dimensionless).
    pub gd_boundary: OMatrix<T, Z::NodeDim, Z::BoundaryDim>,
    /// Constant term `Phi d` \[K\].
    pub dd: OVector<T, Z::NodeDim>,
}

/// Discretises a state space exactly for a step `dt_s` \[s\].
pub fn zoh<Z: Sizes>(ss: &StateSpace<Z>, dt_s: f64) -> Result<Discrete<f64, Z>, BuildError>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    let (ad, phi) = expm_with_integral(&ss.a, dt_s)?;
    Ok(Discrete {
        dt_s,
        ad,
        bd_power: &phi * &ss.b_power,
        gd_boundary: &phi * &ss.g_boundary,
        dd: &phi * &ss.d,
    })
}

impl<Z: Sizes> Discrete<f64, Z>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    /// The same model in another float type (`f32` for an MCU with an FPU).
    pub fn cast<T: RealField + Copy>(&self) -> Discrete<T, Z> {
        Discrete {
            dt_s: self.dt_s,
            ad: self.ad.clone().cast(),
            bd_power: self.bd_power.clone().cast(),
            gd_boundary: self.gd_boundary.clone().cast(),
            dd: self.dd.clone().cast(),
        }
    }
}

impl<T: RealField + Copy, Z: Sizes> Discrete<T, Z>
where
    DefaultAllocator: NetworkAllocator<Z>,
{
    /// One exact step: `T <- Ad T + Bd p + Gd T_b + dd`, with the Joule powers
    /// `powers_w` \[W\] and boundary temperatures \[degC\] held over the step.
    pub fn step(
        &self,
        temps_c: &OVector<T, Z::NodeDim>,
        powers_w: &OVector<T, Z::InputDim>,
        boundary_c: &OVector<T, Z::BoundaryDim>,
    ) -> OVector<T, Z::NodeDim> {
        &self.ad * temps_c + &self.bd_power * powers_w + &self.gd_boundary * boundary_c + &self.dd
    }
}

impl<T: RealField + Copy, const N: usize, const B: usize, const M: usize>
    Discrete<T, ConstSizes<N, B, M>>
{
    /// The combined input matrix `[Bd | Gd | dd]` for the input vector
    /// `u = [p; T_b; 1]`, the form a Kalman filter takes. `U` must equal
    /// `M + B + 1` (checked at compile time).
    pub fn input_matrix<const U: usize>(&self) -> SMatrix<T, N, U> {
        const { assert!(U == M + B + 1, "U must be M + B + 1") };
        let mut g = SMatrix::<T, N, U>::zeros();
        g.fixed_view_mut::<N, M>(0, 0).copy_from(&self.bd_power);
        g.fixed_view_mut::<N, B>(0, M).copy_from(&self.gd_boundary);
        g.fixed_view_mut::<N, 1>(0, M + B).copy_from(&self.dd);
        g
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::network::{Network, Resistance};
    use nalgebra::SVector;

    #[test]
    fn scalar_exponential_and_integral_match_closed_form() {
        for &(a, h) in &[(-0.5, 1.0), (-200.0, 0.3), (0.1, 2.0), (-1e-4, 1e-3)] {
            let (e, phi) = expm_with_integral(&SMatrix::<f64, 1, 1>::new(a), h).unwrap();
            let want_e = libm::exp(a * h);
            let want_phi = libm::expm1(a * h) / a;
            assert!(
                (e[0] - want_e).abs() <= 1e-13 * want_e.abs().max(1e-300),
                "{a} {h}"
            );
            assert!(
                (phi[0] - want_phi).abs() <= 1e-12 * want_phi.abs(),
                "{a} {h}"
            );
        }
    }

    #[test]
    fn rotation_generator_gives_rotation() {
        // exp([[0, w], [-w, 0]] t) is a rotation by w t: an answer independent of
        // the series used.
        let w = 3.0;
        let t = 2.5;
        let a = SMatrix::<f64, 2, 2>::new(0.0, w, -w, 0.0);
        let (e, _) = expm_with_integral(&a, t).unwrap();
        let (s, c) = libm::sincos(w * t);
        let want = SMatrix::<f64, 2, 2>::new(c, s, -s, c);
        assert!((e - want).abs().max() < 1e-12);
    }

    #[test]
    fn bad_steps_are_refused() {
        let a = SMatrix::<f64, 2, 2>::identity();
        assert_eq!(
            expm_with_integral(&a, 0.0),
            Err(BuildError::InvalidTimeStep)
        );
        assert_eq!(
            expm_with_integral(&a, f64::NAN),
            Err(BuildError::InvalidTimeStep)
        );
        let nan = SMatrix::<f64, 2, 2>::from_element(f64::NAN);
        assert!(expm_with_integral(&nan, 1.0).is_err());
    }

    fn three_node() -> Network<3, 1, 1> {
        Network::new([40.0, 15.0, 120.0])
            .unwrap()
            .connect(0, 1, 0.8)
            .unwrap()
            .connect(1, 2, 0.3)
            .unwrap()
            .connect_boundary(2, 0, 0.5)
            .unwrap()
            .connect_boundary(0, 0, 0.05)
            .unwrap()
            .fixed_power(1, 1.5)
            .unwrap()
            .joule_source(0, 0, Resistance::constant(4.0))
            .unwrap()
    }

    #[test]
    fn zoh_step_matches_many_tiny_euler_steps() {
        let net = three_node();
        let ss = net.state_space(&[20.0; 3]);
        let big_dt = 5.0;
        let d = zoh(&ss, big_dt).unwrap();
        let t0 = SVector::<f64, 3>::new(60.0, 30.0, 25.0);
        let p = SVector::<f64, 1>::new(4.0 * 2.0 * 2.0);
        let tb = SVector::<f64, 1>::new(20.0);
        let exact = d.step(&t0, &p, &tb);
        // Reference: 5e5 forward-Euler steps of the f64 right-hand side.
        let substeps = 500_000;
        let h = big_dt / substeps as f64;
        let mut t = [60.0, 30.0, 25.0];
        for _ in 0..substeps {
            let dtdt = net.derivative_k_per_s(&t, &[2.0], &[20.0]);
            for (t, r) in t.iter_mut().zip(dtdt) {
                *t += h * r;
            }
        }
        for i in 0..3 {
            assert!(
                (exact[i] - t[i]).abs() < 2e-5,
                "node {i}: {} vs {}",
                exact[i],
                t[i]
            );
        }
    }

    #[test]
    fn f32_model_tracks_f64() {
        let net = three_node();
        let d64 = zoh(&net.state_space(&[20.0; 3]), 1e-3).unwrap();
        let d32 = d64.cast::<f32>();
        let mut x64 = SVector::<f64, 3>::from_element(20.0);
        let mut x32 = SVector::<f32, 3>::from_element(20.0);
        for _ in 0..20_000 {
            x64 = d64.step(
                &x64,
                &SVector::from_element(16.0),
                &SVector::from_element(20.0),
            );
            x32 = d32.step(
                &x32,
                &SVector::from_element(16.0),
                &SVector::from_element(20.0),
            );
        }
        assert!(x64[0] > 21.0, "the test must actually heat: {}", x64[0]);
        for i in 0..3 {
            assert!((x64[i] - x32[i] as f64).abs() < 0.02, "node {i}");
        }
    }

    #[test]
    fn input_matrix_packs_inputs_in_order() {
        let d = zoh(&three_node().state_space(&[20.0; 3]), 0.5).unwrap();
        let g: SMatrix<f64, 3, 3> = d.input_matrix::<3>();
        let u = SVector::<f64, 3>::new(7.0, 21.0, 1.0);
        let x = SVector::<f64, 3>::new(30.0, 25.0, 22.0);
        let via_g = d.ad * x + g * u;
        let via_step = d.step(
            &x,
            &SVector::from_element(7.0),
            &SVector::from_element(21.0),
        );
        assert!((via_g - via_step).abs().max() < 1e-12);
    }
}
