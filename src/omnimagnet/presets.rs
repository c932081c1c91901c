//! The paper's experiments as current profiles, plus a rotating-dipole drive.
//!
//! Heating runs start with every node at the ambient and stop at
//! [`EXPERIMENT_STOP_C`] on a solenoid or after
//! [`Preset::DURATION_S`] (2 h), as the experiments did. Passive cooling
//! starts from the end of the all-three heating run (documented choice: the
//! hottest state the experiments reached), computed by
//! [`Preset::initial_temps_c`].

use super::data::{NODES, SOLENOIDS};
use super::{Omnimagnet, EXPERIMENT_STOP_C};

/// A current profile for the three solenoids.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Preset {
    /// Only solenoid 1 (inner), constant current \[A\].
    Solenoid1 {
        /// Current \[A\].
        current_a: f64,
    },
    /// Solenoids 2 and 3, each at a constant current \[A\].
    Solenoids2And3 {
        /// Current \[A\].
        current_a: f64,
    },
    /// All three solenoids at a constant current \[A\] (the worst case).
    AllThree {
        /// Current \[A\].
        current_a: f64,
    },
    /// No current; starts hot.
    PassiveCooling,
    /// A dipole of constant magnitude rotating about the (1, 1, 1) axis:
    /// `I_k = A cos(2 pi f t - 2 pi k / 3)`, k = 0, 1, 2. The three unit
    /// dipoles (one per solenoid, orthogonal) then sum to a vector of
    /// constant length `A sqrt(3/2)` in the plane normal to (1, 1, 1), the
    /// steady rotating field used to roll or spin tools in magnetic
    /// manipulation. (The solenoids' different dipole per ampere is ignored:
    /// the profile is for heating.) Mean `I_k^2 = A^2 / 2`.
    RotatingDipole {
        /// Peak current per solenoid \[A\].
        amplitude_a: f64,
        /// Rotation frequency \[Hz\].
        frequency_hz: f64,
    },
}

impl Preset {
    /// The paper's example: solenoid 1 at 3.13 A (NRMSE 2.5 %).
    pub const SOLENOID_1: Self = Self::Solenoid1 { current_a: 3.13 };
    /// The paper's example: solenoids 2 and 3 at 3.04 A (NRMSE 3.7 %).
    pub const SOLENOIDS_2_AND_3: Self = Self::Solenoids2And3 { current_a: 3.04 };
    /// The paper's example: all three at 3.8 A (NRMSE 2.1 %).
    pub const ALL_THREE: Self = Self::AllThree { current_a: 3.8 };
    /// The paper's example: passive cooling (NRMSE 2.7 %).
    pub const PASSIVE_COOLING: Self = Self::PassiveCooling;
    /// Rotating dipole, 3.8 A peak per solenoid at 5 Hz.
    pub const ROTATING_DIPOLE: Self = Self::RotatingDipole {
        amplitude_a: 3.8,
        frequency_hz: 5.0,
    };
    /// All of the above.
    pub const ALL: [Self; 5] = [
        Self::SOLENOID_1,
        Self::SOLENOIDS_2_AND_3,
        Self::ALL_THREE,
        Self::PASSIVE_COOLING,
        Self::ROTATING_DIPOLE,
    ];
    /// Length of an experiment \[s\]: 2 h.
    pub const DURATION_S: f64 = 7200.0;

    /// A stable name (for the CLI).
    pub const fn name(&self) -> &'static str {
        match self {
            Self::Solenoid1 { .. } => "solenoid_1",
            Self::Solenoids2And3 { .. } => "solenoids_2_3",
            Self::AllThree { .. } => "all_three",
            Self::PassiveCooling => "passive_cooling",
            Self::RotatingDipole { .. } => "rotating_dipole",
        }
    }

    /// Solenoid currents \[A\] at time `t_s` \[s\].
    pub fn currents_a(&self, t_s: f64) -> [f64; SOLENOIDS] {
        match *self {
            Self::Solenoid1 { current_a } => [current_a, 0.0, 0.0],
            Self::Solenoids2And3 { current_a } => [0.0, current_a, current_a],
            Self::AllThree { current_a } => [current_a; SOLENOIDS],
            Self::PassiveCooling => [0.0; SOLENOIDS],
            Self::RotatingDipole {
                amplitude_a,
                frequency_hz,
            } => {
                let phase = 2.0 * core::f64::consts::PI * frequency_hz * t_s;
                let third = 2.0 * core::f64::consts::PI / 3.0;
                [0.0, 1.0, 2.0].map(|k| amplitude_a * libm::cos(phase - k * third))
            }
        }
    }

    /// A step \[s\] that resolves the profile for [`Omnimagnet::step_rk4`]:
    /// 0.5 s, or 1/20 of a rotation period.
    pub fn step_s(&self) -> f64 {
        match *self {
            Self::RotatingDipole { frequency_hz, .. } if frequency_hz > 0.0 => {
                (0.05 / frequency_hz).min(0.5)
            }
            _ => 0.5,
        }
    }

    /// Start state \[degC\]: the ambient everywhere for heating; for passive
    /// cooling, the end of [`Preset::ALL_THREE`] (115 degC on a solenoid or
    /// 2 h). That costs up to 14 400 RK4 steps: host or build-time use.
    pub fn initial_temps_c(&self, model: &Omnimagnet, ambient_c: f64) -> [f64; NODES] {
        let mut temps = [ambient_c; NODES];
        if *self == Self::PassiveCooling {
            Self::ALL_THREE.run(model, &mut temps, ambient_c, |t| {
                hottest_solenoid_c(model, t) >= EXPERIMENT_STOP_C
            });
        }
        temps
    }

    /// Integrates the nonlinear model from `temps_c` with this profile until
    /// `stop(temps)` or [`Preset::DURATION_S`]; returns the time reached
    /// \[s\].
    pub fn run(
        &self,
        model: &Omnimagnet,
        temps_c: &mut [f64; NODES],
        ambient_c: f64,
        mut stop: impl FnMut(&[f64; NODES]) -> bool,
    ) -> f64 {
        let dt = self.step_s();
        let steps = libm::ceil(Self::DURATION_S / dt) as u64;
        for k in 0..steps {
            if stop(temps_c) {
                return k as f64 * dt;
            }
            let t = k as f64 * dt;
            // Currents at the step's midpoint: second-order in dt for the
            // sinusoidal profile.
            model.step_rk4(temps_c, &self.currents_a(t + 0.5 * dt), ambient_c, dt);
        }
        steps as f64 * dt
    }

    /// `t_max` \[s\]: time from the ambient until any solenoid reaches
    /// `limit_c` \[degC\], within 2 h (`None` if it does not).
    pub fn time_to_limit_s(&self, model: &Omnimagnet, ambient_c: f64, limit_c: f64) -> Option<f64> {
        let mut temps = self.initial_temps_c(model, ambient_c);
        let mut hit = false;
        let t = self.run(model, &mut temps, ambient_c, |t| {
            hit = hottest_solenoid_c(model, t) >= limit_c;
            hit
        });
        hit.then_some(t)
    }
}

/// The hottest solenoid temperature \[degC\] (what the thermocouples see).
pub fn hottest_solenoid_c(model: &Omnimagnet, temps_c: &[f64; NODES]) -> f64 {
    model
        .geometry()
        .solenoids
        .iter()
        .map(|s| temps_c[s.node])
        .fold(f64::NEG_INFINITY, f64::max)
}
