//! The nonlinear model `dT/dt = f(T, I, T_0)` (paper's Eq. 1) in `f64`, with
//! copper `c_p(T)`, `k(T)` (Eq. A1, A2), `R(T)` (Eq. A3), `h(T)` from the
//! natural-convection correlations (Table 5) and radiation in the geometry's
//! [`RadiationForm`].
//!
//! Every exchange is written as a conductance that depends on temperature:
//! convection `h(T_s, T_f) S`, radiation `sigma eps S (T^2 + T_0^2)(T + T_0)`
//! for Eq. 1 (so that times `T - T_0` it is `sigma eps S (T^4 - T_0^4)`
//! exactly, kelvin) or Appendix B's `sigma eps S T_0^3`. The
//! nonlinear right-hand side and the linearisation then share one code path,
//! and the linear model differs only by freezing those conductances.
//!
//! `no_std`, allocation-free, `O(contacts)` work with about 20 `pow` calls:
//! usable on target for re-linearisation.

use super::data::{
    Contact, Correlation, Peer, RadiationForm, Solenoid, SurfaceConvection, NODES, SOLENOIDS,
};
use super::Omnimagnet;
use crate::network::Resistance;

/// Stefan-Boltzmann constant \[W/(m^2 K^4)\].
pub const STEFAN_BOLTZMANN_W_PER_M2_K4: f64 = 5.670_374e-8;
/// Offset from degC to K.
pub const ZERO_C_IN_K: f64 = 273.15;
/// Gravity \[m/s^2\].
const GRAVITY_M_PER_S2: f64 = 9.806_65;
/// Smallest surface-to-fluid difference \[K\] put into the Rayleigh number:
/// the correlations are outside their range there anyway, and the floor keeps
/// `h > 0` at a cold start so the linearisation there is not adiabatic.
pub const MIN_CONVECTION_DELTA_K: f64 = 1.0;

/// Dry air at atmospheric pressure, at a film temperature: the paper does
/// not give the properties it used, so these are Sutherland's laws (viscosity
/// and conductivity) and the ideal gas (density, `beta = 1/T`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirProperties {
    /// Thermal conductivity \[W/(m K)\].
    pub conductivity_w_per_m_k: f64,
    /// Kinematic viscosity \[m^2/s\].
    pub kinematic_viscosity_m2_per_s: f64,
    /// Thermal diffusivity \[m^2/s\].
    pub diffusivity_m2_per_s: f64,
    /// Prandtl number.
    pub prandtl: f64,
    /// Expansion coefficient \[1/K\].
    pub expansion_per_k: f64,
}

impl AirProperties {
    /// At film temperature `film_k` \[K\] (about 1 % of tables over 250-400 K).
    pub fn at_k(film_k: f64) -> Self {
        const CP_J_PER_KG_K: f64 = 1007.0;
        const R_J_PER_KG_K: f64 = 287.05;
        const P_PA: f64 = 101_325.0;
        let t = film_k / ZERO_C_IN_K;
        let sutherland = |s: f64| t * libm::sqrt(t) * (ZERO_C_IN_K + s) / (film_k + s);
        let mu = 1.716e-5 * sutherland(110.4);
        let k = 0.0241 * sutherland(194.0);
        let rho = P_PA / (R_J_PER_KG_K * film_k);
        let nu = mu / rho;
        Self {
            conductivity_w_per_m_k: k,
            kinematic_viscosity_m2_per_s: nu,
            diffusivity_m2_per_s: k / (rho * CP_J_PER_KG_K),
            prandtl: mu * CP_J_PER_KG_K / k,
            expansion_per_k: 1.0 / film_k,
        }
    }
}

/// Uncorrected natural-convection `h` \[W/(m^2 K)\] of a surface at
/// `surface_c` in a fluid at `fluid_c` \[degC\], length `length_m` \[m\].
pub fn natural_convection_h_w_per_m2_k(
    correlation: Correlation,
    length_m: f64,
    surface_c: f64,
    fluid_c: f64,
) -> f64 {
    let delta = libm::fabs(surface_c - fluid_c).max(MIN_CONVECTION_DELTA_K);
    let air = AirProperties::at_k(0.5 * (surface_c + fluid_c) + ZERO_C_IN_K);
    let ra = GRAVITY_M_PER_S2 * air.expansion_per_k * delta * length_m * length_m * length_m
        / (air.kinematic_viscosity_m2_per_s * air.diffusivity_m2_per_s);
    let pr = air.prandtl;
    let nu = match correlation {
        Correlation::CattonEnclosure => (0.18 * libm::pow(pr / (0.2 + pr) * ra, 0.29)).max(1.0),
        Correlation::ChurchillChuVertical => {
            let denom = libm::pow(1.0 + libm::pow(0.492 / pr, 9.0 / 16.0), 8.0 / 27.0);
            let root = 0.825 + 0.387 * libm::pow(ra, 1.0 / 6.0) / denom;
            root * root
        }
        Correlation::PlateFacingUp => 0.54 * libm::pow(ra, 0.25),
        Correlation::PlateFacingDown => 0.52 * libm::pow(ra, 0.2),
    };
    nu * air.conductivity_w_per_m_k / length_m
}

/// All conductances of the model at one state \[W/K\]: the network the
/// nonlinear model is at that instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conductances {
    /// Symmetric node-to-node conductances (conduction and inside-air
    /// convection), zero on the diagonal.
    pub pair_w_per_k: [[f64; NODES]; NODES],
    /// Conductance of each node to the ambient (convection plus secant
    /// radiation).
    pub ambient_w_per_k: [f64; NODES],
}

impl Conductances {
    fn zero() -> Self {
        Self {
            pair_w_per_k: [[0.0; NODES]; NODES],
            ambient_w_per_k: [0.0; NODES],
        }
    }

    fn add_pair(&mut self, i: usize, j: usize, g: f64) {
        self.pair_w_per_k[i][j] += g;
        self.pair_w_per_k[j][i] += g;
    }
}

fn to_k(temp_c: f64) -> f64 {
    temp_c + ZERO_C_IN_K
}

impl Solenoid {
    /// Eq. A3 as the network's affine resistance in degC.
    pub fn resistance(&self) -> Resistance {
        Resistance::with_alpha(self.r0_ohm, self.alpha0_per_k, self.t_ref_k - ZERO_C_IN_K)
    }
}

impl Omnimagnet {
    /// Heat capacities `rho V c_p(T)` \[J/K\] at `temps_c`.
    pub fn capacities_j_per_k(&self, temps_c: &[f64; NODES]) -> [f64; NODES] {
        let mut c = [0.0; NODES];
        for ((c, e), t) in c.iter_mut().zip(&self.geometry.elements).zip(temps_c) {
            let m = &e.material;
            *c = m.density_kg_per_m3 * e.volume_m3 * m.specific_heat_j_per_kg_k.at_k(to_k(*t));
        }
        c
    }

    /// Corrected `h` \[W/(m^2 K)\] of a surface: the correlation times the
    /// group's Table 7 factor and the user scale, or the user's fixed value.
    pub fn h_w_per_m2_k(&self, surface: &SurfaceConvection, surface_c: f64, fluid_c: f64) -> f64 {
        let g = surface.group.index();
        if let Some(h) = self.convection.fixed_h_w_per_m2_k[g] {
            return h;
        }
        self.geometry.convection_cf[g]
            * self.convection.scale[g]
            * natural_convection_h_w_per_m2_k(
                surface.correlation,
                surface.length_m,
                surface_c,
                fluid_c,
            )
    }

    pub(crate) fn conductivity_w_per_m_k(&self, node: usize, temp_c: f64) -> f64 {
        self.geometry.elements[node]
            .material
            .conductivity_w_per_m_k
            .at_k(to_k(temp_c))
    }

    /// Symmetric conduction conductance of a solid-solid contact \[W/K\]:
    /// per direction, the two printed one-sided conductances `k S / dx` in
    /// series (full thicknesses), times `CF`; see the module docs of
    /// [`super`] for why full and not half thicknesses.
    fn conduction_w_per_k(&self, c: &Contact, j: usize, temps_c: &[f64; NODES]) -> f64 {
        let (i, e) = (c.node, &self.geometry.elements);
        let inv_k_i = 1.0 / self.conductivity_w_per_m_k(i, temps_c[i]);
        let inv_k_j = 1.0 / self.conductivity_w_per_m_k(j, temps_c[j]);
        let mut g = 0.0;
        for m in 0..3 {
            if c.area_m2[m] > 0.0 {
                let r = e[i].thickness_m[m] * inv_k_i + e[j].thickness_m[m] * inv_k_j;
                g += c.conduction_cf[m] * c.area_m2[m] / r;
            }
        }
        g
    }

    /// Every conductance at node temperatures `temps_c` and ambient
    /// `ambient_c` \[degC\].
    pub fn conductances(&self, temps_c: &[f64; NODES], ambient_c: f64) -> Conductances {
        self.conductances_with(temps_c, ambient_c, true)
    }

    /// [`Omnimagnet::conductances`], with the solid-solid conduction left out
    /// when `conduction` is false (for the literal reading's comparison).
    pub(crate) fn conductances_with(
        &self,
        temps_c: &[f64; NODES],
        ambient_c: f64,
        conduction: bool,
    ) -> Conductances {
        let mut out = Conductances::zero();
        let air = self.geometry.inside_air_node;
        for c in self.geometry.contacts {
            let area: f64 = c.area_m2.iter().sum();
            match c.peer {
                Peer::Ambient => {
                    if let Some(s) = &self.geometry.elements[c.node].convection {
                        out.ambient_w_per_k[c.node] +=
                            self.h_w_per_m2_k(s, temps_c[c.node], ambient_c) * area;
                    }
                }
                Peer::Node(j) if c.node == air || j == air => {
                    let solid = if c.node == air { j } else { c.node };
                    if let Some(s) = &self.geometry.elements[solid].convection {
                        let h = self.h_w_per_m2_k(s, temps_c[solid], temps_c[air]);
                        out.add_pair(solid, air, h * area);
                    }
                }
                Peer::Node(j) => {
                    if conduction {
                        let g = self.conduction_w_per_k(c, j, temps_c);
                        out.add_pair(c.node, j, g);
                    }
                }
            }
        }
        let t0 = to_k(ambient_c);
        for r in self.geometry.radiators {
            let t = to_k(temps_c[r.node]);
            let per_k4 = match self.geometry.radiation {
                RadiationForm::StefanBoltzmann => (t * t + t0 * t0) * (t + t0),
                RadiationForm::AppendixB => t0 * t0 * t0,
            };
            out.ambient_w_per_k[r.node] +=
                STEFAN_BOLTZMANN_W_PER_M2_K4 * r.emissivity * r.area_m2 * per_k4;
        }
        out
    }

    /// Joule power of each solenoid \[W\]: `R(T) I^2` (Eq. A3).
    pub fn joule_powers_w(
        &self,
        temps_c: &[f64; NODES],
        currents_a: &[f64; SOLENOIDS],
    ) -> [f64; SOLENOIDS] {
        let mut p = [0.0; SOLENOIDS];
        for ((p, s), i) in p.iter_mut().zip(&self.geometry.solenoids).zip(currents_a) {
            *p = s.resistance().at_c(temps_c[s.node]) * i * i;
        }
        p
    }

    /// Net heat flow into each node \[W\] (`C dT/dt`), and the heat leaving
    /// to the ambient \[W\].
    pub fn heat_flows_w(
        &self,
        temps_c: &[f64; NODES],
        currents_a: &[f64; SOLENOIDS],
        ambient_c: f64,
    ) -> ([f64; NODES], f64) {
        let g = self.conductances(temps_c, ambient_c);
        let mut q = [0.0; NODES];
        let mut to_ambient_w = 0.0;
        for i in 0..NODES {
            for j in (i + 1)..NODES {
                let flow = g.pair_w_per_k[i][j] * (temps_c[j] - temps_c[i]);
                q[i] += flow;
                q[j] -= flow;
            }
            let out = g.ambient_w_per_k[i] * (temps_c[i] - ambient_c);
            q[i] -= out;
            to_ambient_w += out;
        }
        let p = self.joule_powers_w(temps_c, currents_a);
        for (s, p) in self.geometry.solenoids.iter().zip(p) {
            q[s.node] += p;
        }
        (q, to_ambient_w)
    }

    /// `dT/dt` \[K/s\]: the nonlinear right-hand side.
    pub fn derivative_k_per_s(
        &self,
        temps_c: &[f64; NODES],
        currents_a: &[f64; SOLENOIDS],
        ambient_c: f64,
    ) -> [f64; NODES] {
        let (mut q, _) = self.heat_flows_w(temps_c, currents_a, ambient_c);
        for (q, c) in q.iter_mut().zip(self.capacities_j_per_k(temps_c)) {
            *q /= c;
        }
        q
    }

    /// One classical Runge-Kutta step of `dt_s` \[s\] with currents and
    /// ambient held: the model's own integrator (stable for `dt_s` up to
    /// about 0.5 s with the paper's data; the fastest node, the paper sheet,
    /// has a time constant near 0.25 s).
    pub fn step_rk4(
        &self,
        temps_c: &mut [f64; NODES],
        currents_a: &[f64; SOLENOIDS],
        ambient_c: f64,
        dt_s: f64,
    ) {
        let shifted = |k: &[f64; NODES], a: f64| {
            let mut out = *temps_c;
            for (o, k) in out.iter_mut().zip(k) {
                *o += a * k;
            }
            out
        };
        let k1 = self.derivative_k_per_s(temps_c, currents_a, ambient_c);
        let k2 = self.derivative_k_per_s(&shifted(&k1, 0.5 * dt_s), currents_a, ambient_c);
        let k3 = self.derivative_k_per_s(&shifted(&k2, 0.5 * dt_s), currents_a, ambient_c);
        let k4 = self.derivative_k_per_s(&shifted(&k3, dt_s), currents_a, ambient_c);
        for i in 0..NODES {
            temps_c[i] += dt_s / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
}
