//! The linear model at an operating point (paper's Appendix B).
//!
//! Capacities and conductances are frozen at `(T_op, T_0,op)`; convection and
//! radiation in secant form (see the module docs), so the linear right-hand
//! side equals the nonlinear one exactly at the operating point. `R(T)` stays
//! the affine Eq. A3 inside the network; the paper's `U = I^2` form freezes it
//! at `T_op` through `b_current_squared`.

use super::data::{Peer, NODES, SOLENOIDS};
use super::Omnimagnet;
use crate::discretize::{zoh, Discrete};
use crate::error::BuildError;
use crate::network::{ConstStateSpace, Network};
use crate::sizes::ConstSizes;
use nalgebra::{SMatrix, SVector};

/// The Omnimagnet network type: 16 states, 1 boundary (ambient), 3 currents.
pub type OmnimagnetNetwork = Network<NODES, 1, SOLENOIDS>;

/// A discretised linearisation and the point it was taken at.
#[derive(Debug, Clone, PartialEq)]
pub struct Linearization {
    /// Node temperatures of the operating point \[degC\].
    pub op_temps_c: [f64; NODES],
    /// Ambient of the operating point \[degC\].
    pub op_ambient_c: f64,
    /// The ZOH model for inputs `p` (Joule powers, W), `T_0` and `d`.
    pub discrete: Discrete<f64, ConstSizes<NODES, 1, SOLENOIDS>>,
    /// `Phi B_I2` \[K/A^2\]: the paper's input matrix for `U = I^2`, with
    /// `R(T_op)`.
    pub bd_current_squared: SMatrix<f64, NODES, SOLENOIDS>,
}

impl Linearization {
    /// One step in the paper's form `T <- Ad T + Bd U + Gd T_0`, `U = I^2`
    /// (currents \[A\], ambient \[degC\] held over the step).
    pub fn step_current_squared(
        &self,
        temps_c: &SVector<f64, NODES>,
        currents_a: &[f64; SOLENOIDS],
        ambient_c: f64,
    ) -> SVector<f64, NODES> {
        let u = SVector::<f64, SOLENOIDS>::from_fn(|m, _| currents_a[m] * currents_a[m]);
        self.discrete.ad * temps_c
            + self.bd_current_squared * u
            + self.discrete.gd_boundary * ambient_c
            + self.discrete.dd
    }
}

impl Omnimagnet {
    /// The network frozen at `op_temps_c` and `ambient_c` \[degC\].
    ///
    /// Errors from [`Network`] when the operating point is not finite (a
    /// capacity or conductance would not be).
    pub fn network(
        &self,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
    ) -> Result<OmnimagnetNetwork, BuildError> {
        let g = self.conductances(op_temps_c, ambient_c);
        let mut net = Network::new(self.capacities_j_per_k(op_temps_c))?;
        for i in 0..NODES {
            for j in (i + 1)..NODES {
                let gij = g.pair_w_per_k[i][j];
                if gij != 0.0 {
                    net = net.connect(i, j, gij)?;
                }
            }
            if g.ambient_w_per_k[i] != 0.0 {
                net = net.connect_boundary(i, 0, g.ambient_w_per_k[i])?;
            }
        }
        for (m, s) in self.geometry.solenoids.iter().enumerate() {
            net = net.joule_source(m, s.node, s.resistance())?;
        }
        Ok(net)
    }

    /// `dT/dt = A T + B p + G T_0` (and `b_current_squared`) at the
    /// operating point.
    pub fn state_space(
        &self,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
    ) -> Result<ConstStateSpace<NODES, 1, SOLENOIDS>, BuildError> {
        Ok(self.network(op_temps_c, ambient_c)?.state_space(op_temps_c))
    }

    /// The state space with `A` as printed (Eq. 1 read literally): row `i`
    /// of a conduction contact uses the neighbour's `k_j S / dx_j`, so
    /// `A_ij C_i != A_ji C_j`. Kept only to measure what the symmetric choice
    /// changes; `B`, `G` are those of [`Omnimagnet::state_space`].
    pub fn literal_state_space(
        &self,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
    ) -> Result<ConstStateSpace<NODES, 1, SOLENOIDS>, BuildError> {
        let mut ss = self.state_space(op_temps_c, ambient_c)?;
        let caps = self.capacities_j_per_k(op_temps_c);
        let g = self.conductances_with(op_temps_c, ambient_c, false);
        let mut a = SMatrix::<f64, NODES, NODES>::zeros();
        let mut couple = |row: usize, col: usize, g: f64| {
            a[(row, col)] += g / caps[row];
            a[(row, row)] -= g / caps[row];
        };
        for i in 0..NODES {
            for j in 0..NODES {
                if j != i && g.pair_w_per_k[i][j] != 0.0 {
                    couple(i, j, g.pair_w_per_k[i][j]);
                }
            }
        }
        let air = self.geometry.inside_air_node;
        for c in self.geometry.contacts {
            let Peer::Node(j) = c.peer else { continue };
            let i = c.node;
            if i == air || j == air {
                continue;
            }
            let (ki, kj) = (
                self.conductivity_w_per_m_k(i, op_temps_c[i]),
                self.conductivity_w_per_m_k(j, op_temps_c[j]),
            );
            let (mut gi, mut gj) = (0.0, 0.0);
            for m in 0..3 {
                let s = c.conduction_cf[m] * c.area_m2[m];
                if s > 0.0 {
                    let dx_i = self.geometry.elements[i].thickness_m[m];
                    let dx_j = self.geometry.elements[j].thickness_m[m];
                    if dx_i <= 0.0 || dx_j <= 0.0 {
                        return Err(BuildError::InvalidParameter {
                            name: "elements.thickness_m",
                        });
                    }
                    // Row i: the neighbour's kappa_j / dx_j (as printed).
                    gi += s * kj / dx_j;
                    gj += s * ki / dx_i;
                }
            }
            couple(i, j, gi);
            couple(j, i, gj);
        }
        ss.a = a;
        Ok(ss)
    }

    /// Linearises at `(op_temps_c, ambient_c)` and discretises for `dt_s`
    /// \[s\] in one go (the reference for [`super::Relinearizer`]).
    pub fn linearize(
        &self,
        op_temps_c: &[f64; NODES],
        ambient_c: f64,
        dt_s: f64,
    ) -> Result<Linearization, BuildError> {
        let ss = self.state_space(op_temps_c, ambient_c)?;
        let discrete = zoh(&ss, dt_s)?;
        let bd_current_squared = self.current_squared_input(&discrete.bd_power, op_temps_c);
        Ok(Linearization {
            op_temps_c: *op_temps_c,
            op_ambient_c: ambient_c,
            discrete,
            bd_current_squared,
        })
    }

    /// `Phi B_I2` \[K/A^2\] from `Phi B_p` \[K/W\]: since
    /// `B_I2 = B_p diag(R(T_op))` (Appendix B), column `m` is scaled by
    /// `R_m(T_op)`.
    pub(crate) fn current_squared_input(
        &self,
        bd_power: &SMatrix<f64, NODES, SOLENOIDS>,
        op_temps_c: &[f64; NODES],
    ) -> SMatrix<f64, NODES, SOLENOIDS> {
        let mut out = *bd_power;
        for (m, s) in self.geometry.solenoids.iter().enumerate() {
            let r_ohm = s.resistance().at_c(op_temps_c[s.node]);
            for i in 0..NODES {
                out[(i, m)] *= r_ohm;
            }
        }
        out
    }
}
