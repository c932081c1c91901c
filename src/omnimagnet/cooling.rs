//! Downtime cooling of the nonlinear model (issue 17): where the device is
//! after `off` seconds with no current, never below the exact solution of
//! the nonlinear model and within 0.5 K of it, in bounded work.
//!
//! One linearisation at the ambient cools too slowly (the device radiates
//! and convects more while it is hot: the secant conductances
//! `sigma eps S (T^2 + T_0^2)(T + T_0)` and `h(T) S` grow with the
//! temperature), so the result is safe but far above the truth. Here the
//! off time is cut into pieces, and each piece is the *exact* zero-current
//! solution of the network frozen at one state:
//!
//! ```text
//! x(t_k+1) = exp(A(T_lin) h_k) x(t_k),   x = T - T_0,   h_k = t_k+1 - t_k,
//! ```
//!
//! (the secant network's zero-current steady state is the ambient itself, so
//! the excess obeys `x' = A x` exactly). Each piece is solved twice: frozen
//! at its start, then frozen at the end state that first pass found, the
//! coldest state of the piece, where the exchange with the ambient is
//! weakest (and with each node's capacity at the hotter of the two states:
//! copper's `c_p` grows with the temperature), so the windings cool no
//! faster than the device does. The nodes the windings feed through the
//! inside air and the frames (core, air, frames, paper) cool a little too
//! fast that way (the weaker internal exchange starves them), and hotter in
//! the first pass; so every node takes the hotter of the two, and the
//! piece's end state carries on (`exp(A h) >= 0`: a hotter start stays
//! hotter). The error then errs hot. The pieces
//! are geometric in time ([`COOLING_FIRST_PIECE_S`], ratio
//! [`COOLING_PIECE_RATIO`]) because the device cools on every scale from
//! the paper sheet's quarter second to the slowest mode's hours, at most
//! [`COOLING_MAX_PIECES`] of them (the last piece takes whatever time is
//! left, still frozen at its cold end).
//!
//! The sign is not a theorem (copper's `c_p` and `k` also move with the
//! temperature, the other way); it is measured, against a fine `f64` RK4
//! integration of the nonlinear model from heating runs (all three
//! solenoids at 3.8 A to 115 degC, shorter and single-solenoid runs) over
//! off times from 1 s to 10 h: see `host-tests/tests/downtime_cooling.rs`
//! and the README's figures.
//!
//! Work: two linearisations (about 20 `pow` each) and two `16 x 16`
//! scaling-and-squaring exponentials per piece, `f64`, no allocation, no
//! panic; 4.6 ms for a 10 h off time on the host (x86-64), not measured on
//! target (soft `f64` on a Cortex-M4F: expect some hundreds of ms).
//! Restore-time code, not for the tick.

use super::{Omnimagnet, NODES};
use crate::discretize::expm_with_integral;
use nalgebra::SVector;

/// [`Omnimagnet::cooled_c`] of one start at many off times: the state at
/// the end of every whole piece is kept (7 KiB), so a further off time
/// costs the piece it ends in and the whole pieces not reached before (the
/// same pieces in the same order, so the same result to the bit). For a
/// search over the off time
/// ([`crate::observer::start::earliest_off_time_s`]), at the restore.
#[derive(Debug, Clone)]
pub(crate) struct CoolingPath<'a> {
    model: &'a Omnimagnet,
    temps_c: [f64; NODES],
    ambient_c: f64,
    /// The excess over the ambient at the end of whole piece `p`.
    ends: [SVector<f64, NODES>; COOLING_MAX_PIECES as usize],
    /// Whole pieces whose end is known.
    known: usize,
    /// A whole piece failed (no cooling from there on, the safe side).
    failed: bool,
}

impl<'a> CoolingPath<'a> {
    /// The path of `model` cooling from `temps_c` \[degC\] at the ambient
    /// `ambient_c` \[degC\].
    pub(crate) fn new(model: &'a Omnimagnet, temps_c: &[f64; NODES], ambient_c: f64) -> Self {
        Self {
            model,
            temps_c: *temps_c,
            ambient_c,
            ends: [SVector::zeros(); COOLING_MAX_PIECES as usize],
            known: 0,
            failed: false,
        }
    }

    /// [`Omnimagnet::cooled_c`] after `off_s` \[s\].
    pub(crate) fn cooled_c(&mut self, off_s: f64) -> [f64; NODES] {
        let (temps_c, ambient_c) = (&self.temps_c, self.ambient_c);
        if !(off_s > 0.0 && ambient_c.is_finite() && temps_c.iter().all(|t| t.is_finite())) {
            return *temps_c;
        }
        let mut x = SVector::<f64, NODES>::from_fn(|i, _| temps_c[i] - ambient_c);
        let mut start_s = 0.0;
        let mut length_s = COOLING_FIRST_PIECE_S;
        for piece in 0..COOLING_MAX_PIECES as usize {
            let last = piece + 1 == COOLING_MAX_PIECES as usize || start_s + length_s >= off_s;
            let h = if last { off_s - start_s } else { length_s };
            if last {
                let Some(end) = self.model.piece(&x, ambient_c, h) else {
                    return *temps_c;
                };
                x = end;
                break;
            }
            if piece < self.known {
                x = self.ends[piece];
            } else {
                let end = match self.model.piece(&x, ambient_c, h) {
                    Some(end) if !self.failed => end,
                    _ => {
                        self.failed = true;
                        return *temps_c;
                    }
                };
                self.ends[piece] = end;
                self.known = piece + 1;
                x = end;
            }
            start_s += length_s;
            length_s *= COOLING_PIECE_RATIO;
        }
        core::array::from_fn(|i| ambient_c + x[i])
    }
}

/// Length of the first piece \[s\].
pub const COOLING_FIRST_PIECE_S: f64 = 1.0;
/// Each piece is this much longer than the one before.
pub const COOLING_PIECE_RATIO: f64 = 1.2;
/// Most pieces: with the defaults they cover 38 h (10 h takes 49) before
/// the last piece has to stretch (still frozen at its cold end, so still
/// hot, if looser).
pub const COOLING_MAX_PIECES: u32 = 56;

impl Omnimagnet {
    /// The node temperatures \[degC\] `off_s` \[s\] after `temps_c` with no
    /// current and the ambient at `ambient_c` \[degC\] (see the module
    /// docs): at or above the nonlinear model's zero-current solution, within
    /// 0.5 K of it (measured).
    ///
    /// `off_s` not positive (or NaN) returns `temps_c`; so does a
    /// non-finite ambient or a piece whose linearisation or exponential
    /// fails (non-finite or implausible temperatures): no cooling, the safe
    /// side. A node below the ambient is cooled from its own temperature
    /// like every other (the linear pieces need no sign).
    pub fn cooled_c(&self, temps_c: &[f64; NODES], ambient_c: f64, off_s: f64) -> [f64; NODES] {
        if !(off_s > 0.0 && ambient_c.is_finite() && temps_c.iter().all(|t| t.is_finite())) {
            return *temps_c;
        }
        let mut x = SVector::<f64, NODES>::from_fn(|i, _| temps_c[i] - ambient_c);
        let mut start_s = 0.0;
        let mut length_s = COOLING_FIRST_PIECE_S;
        for piece in 0..COOLING_MAX_PIECES {
            let last = piece + 1 == COOLING_MAX_PIECES || start_s + length_s >= off_s;
            let h = if last { off_s - start_s } else { length_s };
            let Some(end) = self.piece(&x, ambient_c, h) else {
                return *temps_c;
            };
            x = end;
            if last {
                break;
            }
            start_s += length_s;
            length_s *= COOLING_PIECE_RATIO;
        }
        core::array::from_fn(|i| ambient_c + x[i])
    }

    /// One piece of `h` \[s\] from the excess `x` over the ambient
    /// `ambient_c` \[degC\] (see the module docs): frozen at its start,
    /// then at that solution's end, every node the hotter of the two.
    fn piece(
        &self,
        x: &SVector<f64, NODES>,
        ambient_c: f64,
        h: f64,
    ) -> Option<SVector<f64, NODES>> {
        let first = self.frozen_piece(x, x, ambient_c, h)?;
        let end = self.frozen_piece(x, &first, ambient_c, h)?;
        // Each node at the hotter of the two frozen solutions: a node the
        // cold end's weaker internal exchange starves (the core, the
        // air, the frames, fed by the windings) is hotter in the start's.
        Some(end.zip_map(&first, f64::max))
    }

    /// `exp(A(T_0 + at) h) x`, or `None` if that fails or is not finite.
    fn frozen_piece(
        &self,
        x: &SVector<f64, NODES>,
        at: &SVector<f64, NODES>,
        ambient_c: f64,
        h: f64,
    ) -> Option<SVector<f64, NODES>> {
        let lin: [f64; NODES] = core::array::from_fn(|i| ambient_c + at[i]);
        let mut a = self.state_space(&lin, ambient_c).ok()?.a;
        // Capacities at the hotter of the two states (copper's c_p grows
        // with the temperature: the larger capacity cools slower). Row i of
        // A is -K_i / C_i, so it scales by C_i(lin) / C_i(hot).
        let hot: [f64; NODES] = core::array::from_fn(|i| ambient_c + x[i].max(at[i]));
        let c_lin = self.capacities_j_per_k(&lin);
        let c_hot = self.capacities_j_per_k(&hot);
        for i in 0..NODES {
            let scale = c_lin[i] / c_hot[i];
            for j in 0..NODES {
                a[(i, j)] *= scale;
            }
        }
        let (e, _) = expm_with_integral(&a, h).ok()?;
        let out = e * x;
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
}
