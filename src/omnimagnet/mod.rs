//! The Omnimagnet: a 16-node lumped-capacitance model of three nested
//! solenoids around a ferromagnetic sphere (Esmailie, Cavilla, Abbott, Ameel,
//! "Thermal Model of an Omnimagnet for Performance Assessment and Temperature
//! Control", ASME J. Thermal Sci. Eng. Appl., 2021).
//!
//! # Elements
//!
//! Every element is one node (Biot < 0.1): the three copper solenoids (inner
//! 1, middle 2, outer 3), four aluminium frames, wire and cover insulation of
//! each solenoid, the trapped air inside, the spherical core and an
//! insulating paper; see [`NODE_NAMES`]. The ambient is the one boundary. The
//! tables (volumes, materials, contact areas and thicknesses per direction,
//! fitted correction factors) are `const` data in [`data`]; another
//! Omnimagnet is another [`OmnimagnetGeometry`].
//!
//! The energy balance of element `i` (paper's Eq. 1) is
//!
//! ```text
//! C_i(T_i) dT_i/dt = R_i(T_i) I_i^2 + sum_j G_ij(T) (T_j - T_i) + G_i0(T) (T_0 - T_i)
//! ```
//!
//! with conduction, convection `h S` and radiation all written as
//! conductances that depend on temperature ([`Omnimagnet::conductances`]).
//!
//! # The conductance choice
//!
//! As printed, the conduction term of row `i` uses the *neighbour's*
//! conductivity and thickness, `kappa_j S / dx_j`, so rows `i` and `j` see
//! different conductances and the model creates or destroys heat at every
//! contact. Here each contact and direction has one conductance, used in both
//! rows: the two half-thickness resistances in series,
//!
//! ```text
//! G_ijm = CF_ijm S_ijm / (dx_im / (2 k_i) + dx_jm / (2 k_j)),
//! ```
//!
//! because a lumped node sits at its element's centre, so heat crossing the
//! contact travels half of each element. It conserves energy (the sum of
//! `C_i A_ij` over `i` is zero for every internal column) and it reduces to
//! the printed term when one side dominates, up to the factor 2 of the half
//! thickness. [`Omnimagnet::literal_state_space`] keeps the printed reading
//! for comparison. Measured (tests, all three solenoids at 3.8 A, ambient
//! 22 degC):
//!
//! | | symmetric (this crate) | literal (as printed) |
//! |---|---|---|
//! | worst `sum_i C_i A_ij + G_j0` | 1e-14 W/K | 5808 W/K (solenoid 2) |
//! | slowest mode of `A` | 8.7e-5 1/s (3.2 h) | 3e-14 1/s (undamped) |
//! | solenoid 1 after 1 h | 69.4 degC | 204.7 degC |
//! | steady state / 115 degC | 74.4 degC, never | none; 115 degC at 2000 s |
//!
//! The literal rows pump heat from low-conductivity nodes into high ones, so
//! almost nothing reaches the covers that touch the ambient: the model has
//! practically no steady state and runs away under any constant current.
//!
//! # Linearisation
//!
//! [`Omnimagnet::network`] freezes every conductance and capacity at an
//! operating point and returns a [`Network`](crate::network::Network) with
//! `R(T)` Joule sources, so `state_space()` and
//! [`zoh`](crate::discretize::zoh) give the paper's
//! `dT/dt = A T + B U + G T_0` (Appendix B), with `U = I^2` through
//! `b_current_squared`. Convection and radiation are frozen in *secant* form:
//! `h(T_op) S` and `sigma eps S (T^2 + T_0^2)(T + T_0)` at the operating point
//! (kelvin), which is `sigma eps S (T^4 - T_0^4) / (T - T_0)` exactly. So the
//! linear model is exact at the operating point (and at equilibrium with the
//! ambient), stays a conductance network (energy-conserving, no offset term),
//! and its error grows with the distance from the operating point; the tangent
//! `4 sigma eps S T^3` would match the slope but needs an affine offset.
//! [`Relinearizer`] redoes this as the device heats, in bounded slices.
//!
//! # What is estimated, and how sensitive it is
//!
//! The paper gives neither the correlations' characteristic lengths nor its
//! air properties. The lengths are estimated from the geometry (see
//! [`data::INSIDE_GAP_CM`], [`data::PLATE_LENGTH_CM`],
//! [`data::OUTER_HEIGHT_CM`]); air properties are Sutherland's laws for dry
//! air at the film temperature ([`AirProperties`]). Each convection group's
//! `h` can be scaled or replaced ([`ConvectionParams`]). All three solenoids
//! at 3.8 A from 22 degC (hottest solenoid, nonlinear model):
//!
//! | `h` | time to 50 degC | after 2 h | steady state | `t_max` (115 degC) |
//! |---|---|---|---|---|
//! | x2 | 1344 s | 57.8 degC | 59.1 degC | never |
//! | x1 (paper's CFs) | 1026 s | 72.1 degC | 74.4 degC | never |
//! | x0.5 | 930 s | 90.4 degC | 94.2 degC | never |
//! | x0.25 | - | - | 115.5 degC | > 2 h |
//!
//! So with the paper's fitted correction factors *on an energy-conserving
//! network*, the Omnimagnet does not reach 115 degC at 3.8 A; the paper's
//! experiments stopped at 115 degC or 2 h. The factors (convection CFs of
//! 1.96 .. 2.88) were fitted to the paper's own implementation and do not
//! transfer unchanged: calibrate `scale` (or the conduction CFs) against
//! thermocouple data before trusting `t_max`. The qualitative findings hold:
//! all three on is the worst case, the inner solenoid is the hottest.
//!
//! The corrected `h` lies between 6 and 26 W/(m^2 K) for surface-to-air
//! differences of 1 .. 60 K (the horizontal plate facing up exceeds the
//! paper's 25 W/(m^2 K) bound above about 50 K).
//!
//! # Observer
//!
//! [`observer`]: the Kalman observer of every element from the six
//! thermocouples (steady-state or time-varying gain, innovation gate, heat-
//! input bias states, following the [`Relinearizer`]).

pub mod data;
mod linearize;
mod nonlinear;
pub mod observer;
pub mod presets;
mod relinearize;

#[cfg(test)]
mod tests;

pub use data::{
    Contact, ConvectionGroup, Correlation, Element, KelvinPoly, Material, OmnimagnetGeometry, Peer,
    Radiator, Solenoid, SurfaceConvection, CONVECTION_GROUPS, NODES, PAPER_OMNIMAGNET, SOLENOIDS,
};
pub use linearize::Linearization;
pub use nonlinear::{natural_convection_h_w_per_m2_k, AirProperties, Conductances};
pub use presets::Preset;
pub use relinearize::{RelinearizeConfig, RelinearizePoll, Relinearizer, MATMULS_PER_SLICE};

use crate::error::BuildError;
use nalgebra::SMatrix;

/// Stable node names, in node order (used by the CLI).
pub const NODE_NAMES: [&str; NODES] = [
    "solenoid_1",
    "solenoid_2",
    "solenoid_3",
    "frame_1",
    "frame_2",
    "frame_3",
    "frame_4",
    "wire_insulation_1",
    "cover_insulation_1",
    "wire_insulation_2",
    "cover_insulation_2",
    "wire_insulation_3",
    "cover_insulation_3",
    "inside_air",
    "core",
    "paper",
];

/// Cover insulation melting point \[degC\]: the limiting temperature.
pub const COVER_INSULATION_LIMIT_C: f64 = 120.0;
/// Wire insulation limit \[degC\] (without the cover).
pub const WIRE_INSULATION_LIMIT_C: f64 = 240.0;
/// The experiments' stop temperature \[degC\], 5 K below the cover limit; the
/// paper's `t_max` study uses it on the solenoid temperatures.
pub const EXPERIMENT_STOP_C: f64 = 115.0;

/// Critical temperature of each node \[degC\], `None` where the paper gives
/// none. Cover insulation (120 degC) is limiting but carries no thermocouple.
pub const CRITICAL_TEMPS_C: [Option<f64>; NODES] = {
    let mut t = [None; NODES];
    t[7] = Some(WIRE_INSULATION_LIMIT_C);
    t[9] = Some(WIRE_INSULATION_LIMIT_C);
    t[11] = Some(WIRE_INSULATION_LIMIT_C);
    t[8] = Some(COVER_INSULATION_LIMIT_C);
    t[10] = Some(COVER_INSULATION_LIMIT_C);
    t[12] = Some(COVER_INSULATION_LIMIT_C);
    t
};

/// Number of embedded thermocouples: two per solenoid.
pub const THERMOCOUPLES: usize = 6;
/// The node each thermocouple measures: both thermocouples of a solenoid sit
/// near its centre (middle layer), so each measures its solenoid node. The
/// ambient thermocouple is an input (the boundary), not a measurement.
pub const THERMOCOUPLE_NODES: [usize; THERMOCOUPLES] = [0, 0, 1, 1, 2, 2];

/// The measurement matrix `H` (6 x 16): row `r` is 1 at
/// `THERMOCOUPLE_NODES[r]`, so `y = H T` in degC.
pub fn measurement_matrix() -> SMatrix<f64, THERMOCOUPLES, NODES> {
    let mut h = SMatrix::zeros();
    for (row, node) in THERMOCOUPLE_NODES.iter().enumerate() {
        h[(row, *node)] = 1.0;
    }
    h
}

/// How the convective `h` of each group is set: the fitted correlation times
/// a user scale, or a fixed value (for calibration or the paper's forced-
/// convection study with `h` = 5 .. 1000 W/(m^2 K)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConvectionParams {
    /// Multiplies the corrected correlation `h` of each [`ConvectionGroup`]
    /// (dimensionless, `>= 0`; 1 = the paper's fit).
    pub scale: [f64; CONVECTION_GROUPS],
    /// Replaces the group's `h` \[W/(m^2 K)\] (Table 7 and `scale` unused)
    /// when `Some`.
    pub fixed_h_w_per_m2_k: [Option<f64>; CONVECTION_GROUPS],
}

impl ConvectionParams {
    /// The paper's correlations and correction factors, unscaled.
    pub const PAPER: Self = Self {
        scale: [1.0; CONVECTION_GROUPS],
        fixed_h_w_per_m2_k: [None; CONVECTION_GROUPS],
    };

    /// Every group's `h` multiplied by `factor` (sensitivity studies).
    pub const fn scaled(factor: f64) -> Self {
        Self {
            scale: [factor; CONVECTION_GROUPS],
            fixed_h_w_per_m2_k: [None; CONVECTION_GROUPS],
        }
    }
}

impl Default for ConvectionParams {
    fn default() -> Self {
        Self::PAPER
    }
}

/// A validated Omnimagnet model: the geometry tables and the convection
/// settings. Configuration only; temperatures are the caller's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Omnimagnet {
    geometry: OmnimagnetGeometry,
    convection: ConvectionParams,
}

fn finite_nonneg(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

fn check(ok: bool, name: &'static str) -> Result<(), BuildError> {
    if ok {
        Ok(())
    } else {
        Err(BuildError::InvalidParameter { name })
    }
}

impl Omnimagnet {
    /// The paper's Omnimagnet with its fitted correction factors.
    pub const PAPER: Self = Self {
        geometry: PAPER_OMNIMAGNET,
        convection: ConvectionParams::PAPER,
    };

    /// Validates the tables and the convection settings, so that no later
    /// call can index out of range or divide by a zero thickness.
    pub fn new(
        geometry: OmnimagnetGeometry,
        convection: ConvectionParams,
    ) -> Result<Self, BuildError> {
        let air = geometry.inside_air_node;
        check(air < NODES, "inside_air_node")?;
        for (n, e) in geometry.elements.iter().enumerate() {
            check(
                e.volume_m3.is_finite() && e.volume_m3 > 0.0,
                "elements.volume_m3",
            )?;
            let m = &e.material;
            check(
                m.density_kg_per_m3.is_finite() && m.density_kg_per_m3 > 0.0,
                "elements.material.density_kg_per_m3",
            )?;
            // Capacities and conductivities must stay positive over the whole
            // range a coil can reach (200 K .. 700 K).
            for t_k in [200.0, 450.0, 700.0] {
                let cp = m.specific_heat_j_per_kg_k.at_k(t_k);
                check(
                    cp.is_finite() && cp > 0.0,
                    "elements.material.specific_heat_j_per_kg_k",
                )?;
                let k = m.conductivity_w_per_m_k.at_k(t_k);
                check(
                    n == air || (k.is_finite() && k > 0.0),
                    "elements.material.conductivity_w_per_m_k",
                )?;
            }
            check(
                e.thickness_m.iter().all(|d| finite_nonneg(*d)),
                "elements.thickness_m",
            )?;
            if let Some(s) = e.convection {
                check(
                    s.length_m.is_finite() && s.length_m > 0.0,
                    "convection.length_m",
                )?;
            }
        }
        for c in geometry.contacts {
            check(c.node < NODES, "contacts.node")?;
            check(
                c.area_m2
                    .iter()
                    .chain(&c.conduction_cf)
                    .all(|v| finite_nonneg(*v)),
                "contacts.area_m2",
            )?;
            let convective_solid = match c.peer {
                Peer::Ambient => Some(c.node),
                Peer::Node(j) => {
                    check(j < NODES && j != c.node, "contacts.peer")?;
                    if c.node == air {
                        Some(j)
                    } else if j == air {
                        Some(c.node)
                    } else {
                        for m in 0..3 {
                            let dx = geometry.elements[c.node].thickness_m[m]
                                + geometry.elements[j].thickness_m[m];
                            check(c.area_m2[m] == 0.0 || dx > 0.0, "elements.thickness_m")?;
                        }
                        None
                    }
                }
            };
            if let Some(s) = convective_solid {
                check(
                    s != air && geometry.elements[s].convection.is_some(),
                    "elements.convection",
                )?;
            }
        }
        for r in geometry.radiators {
            check(r.node < NODES, "radiators.node")?;
            check(finite_nonneg(r.area_m2), "radiators.area_m2")?;
            check(
                finite_nonneg(r.emissivity) && r.emissivity <= 1.0,
                "radiators.emissivity",
            )?;
        }
        for s in &geometry.solenoids {
            check(s.node < NODES, "solenoids.node")?;
            check(s.r0_ohm.is_finite() && s.r0_ohm > 0.0, "solenoids.r0_ohm")?;
            check(
                s.alpha0_per_k.is_finite() && s.t_ref_k.is_finite(),
                "solenoids.alpha0_per_k",
            )?;
        }
        check(
            geometry.convection_cf.iter().all(|v| finite_nonneg(*v)),
            "convection_cf",
        )?;
        check(
            convection.scale.iter().all(|v| finite_nonneg(*v)),
            "convection.scale",
        )?;
        check(
            convection
                .fixed_h_w_per_m2_k
                .iter()
                .flatten()
                .all(|v| finite_nonneg(*v)),
            "convection.fixed_h_w_per_m2_k",
        )?;
        Ok(Self {
            geometry,
            convection,
        })
    }

    /// The same geometry with other convection settings.
    pub fn with_convection(&self, convection: ConvectionParams) -> Result<Self, BuildError> {
        Self::new(self.geometry, convection)
    }

    /// The geometry tables.
    pub fn geometry(&self) -> &OmnimagnetGeometry {
        &self.geometry
    }

    /// The convection settings.
    pub fn convection(&self) -> &ConvectionParams {
        &self.convection
    }
}
