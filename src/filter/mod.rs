//! Discrete Kalman filter: a generic, allocation-free observer for linear
//! models given as plain matrices (the device models discretise themselves
//! and hand over `F`, `G`, `H`, `Q`, `R`).
//!
//! # Symbols
//! | symbol | size | meaning |
//! |---|---|---|
//! | `x` | N | state estimate (e.g. node temperatures) |
//! | `u` | M | inputs of one step (powers, ambient, constant terms folded in by the caller) |
//! | `F` | N x N | state transition of one predict step: `x[k+1] = F x[k] + G u[k] + w` |
//! | `G` | N x M | input matrix |
//! | `Q` | N x N | covariance of the process noise `w` per step |
//! | `H` | P x N | measurement matrix, row `h_j` for sensor `j`: `z_j = h_j x + v_j` |
//! | `R` | P x P | measurement noise covariance, diagonal: `r_j = var(v_j)` |
//! | `P` | N x N | estimate covariance (the field `cov`; the dimension `P` is the sensor count) |
//! | `K` | N x P | gain: `x += K nu` |
//! | `nu` | | innovation `z_j - h_j x` |
//! | `S` | | innovation variance `h_j P h_j^T + r_j` |
//!
//! # Time-varying filter
//! [`predict`] runs every tick: `x = F x + G u`, `P = F P F^T + Q`. A non-finite
//! `u` drops the `G u` term for that tick ([`InputStatus::Dropped`]).
//! [`update`] runs whenever readings arrive, as `[Option<T>; P]` (a `Vec`
//! at run-time sizes, see "Sizes" below); `None`, NaN
//! or infinite means "no reading" ([`SensorVerdict::Missing`]), never an error.
//! Because `R` is diagonal the readings are independent, so the batch update
//! equals `P` scalar updates in sequence: no matrix inverse, bounded work.
//! Each uses the Joseph form `P = (I - k h) P (I - k h)^T + k r k^T`, a sum
//! of positive semi-definite terms that stays PSD under rounding, followed
//! by symmetrisation.
//!
//! # Gate
//! Each present reading is tested against the prior of the correction:
//! `nis = nu^2 / S` is chi-square with 1 dof for a healthy sensor, and a
//! reading with `nis > threshold` (default [`CHI2_1DOF_999`] = 10.83, a 0.1 %
//! false-alarm rate) is [`SensorVerdict::Rejected`] and not fused, so an open,
//! shorted, jumping or stuck thermocouple cannot drag the estimate. Gating
//! against the prior (not sequentially) makes the verdicts independent of the
//! sensor order and identical in the steady-state mode. A sensor rejected
//! `suspect_after` (default 3) times in a row is reported suspect
//! ([`UpdateReport::suspect`]); one fused reading clears it.
//!
//! # Virtual sensors
//! [`update_virtual`] fuses a reading outside the configured sensors with its
//! own row and variance (a winding's temperature from its resistance, whose
//! variance changes with the current); see [`virtual_sensor`].
//!
//! # Recovery
//! After a large model error the estimate can be far off with a small `P`:
//! then every healthy reading fails the gate and the filter would never
//! recover. Policy: if every present reading is rejected in `recover_after`
//! consecutive corrections (default 5), `P` is inflated by adding a
//! configured diagonal (default `1e4 max(r)`, a 100-sigma widening), the
//! same readings are gated again and the accepted ones fused, and the report
//! says [`UpdateReport::recovered`]. Readings that still fail keep counting,
//! so recovery repeats every `recover_after` corrections, widening further.
//! A single bad sensor never triggers it: the others are fused.
//!
//! # A state with a floor
//! [`project_onto_floor`] keeps one state at or above a bound after a
//! correction by conditioning the estimate on the bound (every state moves
//! by its regression on the bounded one), the observers' way of never
//! letting a sensor explain the device as heating less than the model
//! allows.
//!
//! # Steady-state mode
//! For a time-invariant model the covariance converges, so the gain can be
//! computed once ([`SteadyStateGain::solve`]) and the per-tick cost drops to
//! [`predict_mean`] (a mat-vec). Readings arrive every `k` predicts (e.g. 500
//! for 2 Hz thermocouples and a 1 kHz loop), so the prior before a correction
//! follows the k-step model `F^k`, `Q_k = sum_{i<k} F^i Q F^iT`, and solves
//! the discrete algebraic Riccati equation of (`F^k`, `H`, `Q_k`, `R`), solved
//! by doubling and checked against one step of the recursion
//! ([`crate::BuildError::NotConverged`] otherwise). [`update_steady`] gates
//! with the stored `S`, then:
//! * all `P` readings fused: `x += K (z - H x)`;
//! * some missing or rejected: `K`'s columns assume the other sensors'
//!   information, so they are not used; instead the accepted subset `s` is
//!   fused with `x += M H_s^T (H_s M H_s^T + R_s)^-1 nu_s`, from `M H^T` and
//!   `S = H M H^T + R` stored with the gain: the optimal update for the
//!   subset given `M` (what sequential Joseph updates from `M` give, to
//!   rounding), at `O(N P + P^3)`, never touching an `N x N` matrix. The
//!   next correction again assumes `M`, slightly optimistic after a missed
//!   reading (the filter's one approximation; the time-varying filter has
//!   none).
//! * recovery: as above, with `M` inflated by the same diagonal `D` (through
//!   `M H^T + D H^T` and `S + H D H^T`).
//!
//! # Costs (N = 16, M = 3, P = 6; multiply-adds, one flop = half of one)
//! | call | multiply-adds | when |
//! |---|---|---|
//! | [`predict_mean`] | 304 (`F x` 256 + `G u` 48) | every tick, steady mode |
//! | [`predict`] | ~8.5 k (`F P F^T` 8192 + mean) | every tick, time-varying |
//! | [`update`], 6 readings | ~10 k (gate 6 x 290, Joseph 6 x 1.3 k) | per correction |
//! | [`update_steady`], all fused | 192 (`H x` 96 + `K nu` 96) | per correction |
//! | [`update_steady`], fallback | <= ~190 (`N P` 96, Cholesky and solves of `S` ~90) | a correction with a sensor out |
//!
//! At 1 kHz with 2 Hz corrections: about 17 Mflop/s time-varying, 0.6 Mflop/s
//! steady-state.
//!
//! # Memory (N = 16, M = 3, P = 6, f32; f64 doubles it)
//! * [`KalmanConfig`] ~2.7 KiB (shared), [`KalmanState`] ~1.1 KiB,
//!   [`SteadyStateGain`] ~3 KiB (shared), [`SteadyEstimate`] 80 B.
//! * Stack, estimated from the N x N temporaries each call holds (about 1 KiB
//!   each; not measured): [`predict`] ~2 KiB, [`update`] ~2 KiB,
//!   [`update_steady`] 0.3 KiB,
//!   [`SteadyStateGain::solve`] ~20 KiB (build time: run it before the
//!   control loop's task starts, or on the host), [`observability()`] ~3 KiB.
//!
//! # Precision
//! Generic over `T: RealField + Copy`: f32 and f64. For `F = e^{A dt}` with a
//! 1 ms step, `F` differs from `I` in the 5th digit, so f32 keeps only about
//! two digits of `A dt`: solve the steady state in f64 where possible. The
//! Omnimagnet-sized test shows the f32 solver itself agrees with f64 on the
//! same rounded model to about 1e-4 relative.
//!
//! # Sizes
//! `N`, `M` and `P` are nalgebra dimensions: `Const<N>` on an MCU (every
//! matrix an `SMatrix`, every per-sensor vector an array, placed by the
//! compiler) and `Dyn` on a host with the `alloc` feature (a model file's
//! network at its own size: a 300-node motor's steady gain with four
//! thermocouples solves in 0.3 s, test
//! `the_300_node_motors_steady_gain_at_its_own_size`). The same functions
//! serve both; per-sensor vectors that are not matrix entries (verdicts,
//! counters) are [`crate::sizes::Length`]'s arrays. One caveat measured:
//! on a host, nalgebra multiplies dynamic matrices larger than 5 x 5
//! with `matrixmultiply`, whose sums run in another order, so a `Dyn`
//! build agrees with a `Const` one to rounding (1e-13 relative), not to
//! the bit.
//!
//! Types holding nalgebra matrices do not implement `defmt::Format` (nalgebra's
//! matrices do not); the report types do.

mod constraint;
mod gate;
mod kalman;
pub mod observability;
mod riccati;
pub mod virtual_sensor;

pub use constraint::{condition_on, project_onto_floor};
pub use gate::{GateCounters, GatePolicy, SensorVerdict, UpdateReport, CHI2_1DOF_999};
pub(crate) use kalman::predict_cov;
pub(crate) use kalman::reads_of_rows;
pub use kalman::{predict, predict_mean, update, InputStatus, KalmanConfig, KalmanState};
pub use observability::{observability, Observability};
pub(crate) use riccati::update_against;
pub use riccati::{k_step_model, update_steady, SteadyEstimate, SteadyStateGain};
pub use virtual_sensor::update_virtual;

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, OMatrix, OVector, RealField};

/// The nalgebra allocations of a filter's matrices over `N` states and `P`
/// sensors (`N x N`, `N x P`, `P x N`, `P x P`, and vectors of each
/// length): one bound, `DefaultAllocator: SensorAllocator<N, P>`, for code
/// over the dimensions (see [`crate::sizes`]).
pub trait SensorAllocator<N: Dim, P: Dim>:
    Allocator<N, N> + Allocator<N, P> + Allocator<P, N> + Allocator<P, P> + Allocator<N> + Allocator<P>
{
}

impl<N: Dim, P: Dim, A> SensorAllocator<N, P> for A where
    A: Allocator<N, N>
        + Allocator<N, P>
        + Allocator<P, N>
        + Allocator<P, P>
        + Allocator<N>
        + Allocator<P>
{
}

/// [`SensorAllocator`] and the `M` inputs' (`N x M`, a vector of `M`): the
/// allocations of a [`KalmanConfig`].
pub trait FilterAllocator<N: Dim, M: Dim, P: Dim>:
    SensorAllocator<N, P> + Allocator<N, M> + Allocator<M>
{
}

impl<N: Dim, M: Dim, P: Dim, A> FilterAllocator<N, M, P> for A where
    A: SensorAllocator<N, P> + Allocator<N, M> + Allocator<M>
{
}

/// `y += a x`, column by column as nalgebra's `gemv(1, a, x, 1)` sums it
/// (so the same bits: `(1 a_ij) x_j + 1 y_i` is `y_i + a_ij x_j`), without
/// the multiplies by its unit `alpha` and `beta` that `gemv` forms unless
/// the compiler sees them constant. For the steady gain's correction
/// (`update_against`): a two-node generated observer built for a Cortex-M0
/// at the default release profile (`footprint_m0`) links 272 B less code;
/// with link-time optimisation the figures are as with `gemv`. Not for the
/// subset fusion's: its 19 x 6 on a Cortex-M4F was 30 instructions dearer
/// than `gemv` (measured).
#[inline(always)]
pub(crate) fn add_product<T: RealField + Copy, R: Dim, C: Dim>(
    y: &mut OVector<T, R>,
    a: &OMatrix<T, R, C>,
    x: &OVector<T, C>,
) where
    DefaultAllocator: Allocator<R, C> + Allocator<R> + Allocator<C>,
{
    // The storage's slices (`a`'s columns are its chunks of `R`): a
    // matrix view per column was measured far slower on the M4F.
    let rows = a.nrows();
    if rows == 0 {
        return;
    }
    let y = y.as_mut_slice();
    for (column, xj) in a.as_slice().chunks_exact(rows).zip(x.as_slice()) {
        for (yi, aij) in y.iter_mut().zip(column) {
            *yi += *aij * *xj;
        }
    }
}

#[cfg(test)]
pub(crate) mod testutil;
