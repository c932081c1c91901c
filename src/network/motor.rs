//! A three-phase motor from its datasheet: "a motor in minutes".
//!
//! For the engineer coming from ODrive, VESC or moteus, whose protection
//! today is two thresholds on one thermistor. [`MotorBuilder`] takes the
//! thermal and electrical lines of a datasheet (SI units, every unit in the
//! name) and gives a [`Network`] for a
//! [`NetworkObserver`](crate::observer::network::NetworkObserver), with the
//! critical temperatures, the hardware limits and the sensor node the
//! observer's builder needs.
//!
//! # Datasheet values
//!
//! The two-body model of the maxon data sheets (and the sheets that give the
//! same four thermal numbers): a winding that heats a housing (stator) that
//! loses heat to the ambient. A sheet with a single winding-to-ambient
//! resistance and time constant does not say how they split between the
//! two; this builder needs both.
//!
//! | field | datasheet line (maxon numbering) |
//! |---|---|
//! | `r_winding_housing_k_per_w` | thermal resistance winding-housing `R_th1` (18) |
//! | `r_housing_ambient_k_per_w` | thermal resistance housing-ambient `R_th2` (17) |
//! | [`MotorHeatCapacity::TimeConstants`] | thermal time constant winding `tau_w` (19) and motor `tau_m` (20) |
//! | [`MotorHeatCapacity::Capacities`] | heat capacities, when the sheet gives them |
//! | `phase_resistance_ohm` at `resistance_ref_c` | terminal resistance phase to phase (10) **divided by 2**, at 25 degC |
//! | `alpha_per_k` | 0.00393 for copper (maxon uses 0.0039) |
//! | `continuous_current_a` | nominal (max. continuous) current (6), as a per-phase RMS |
//! | `winding_limit_c` | max. permissible winding temperature (22), the insulation class |
//!
//! The time constants are maxon's: `tau_w = C_w R_th1` and `tau_m = C_h
//! R_th2`, so `C_w = tau_w / R_th1`, `C_h = tau_m / R_th2` (maxon "Key
//! information", the thermal section).
//!
//! **Resistance per phase.** `phase_resistance_ohm` is the star-equivalent
//! resistance of one phase (line to neutral): half the terminal resistance
//! "phase to phase" of a maxon sheet; what ODrive's calibration reports as
//! `phase_resistance` (check your tool: a line-to-line figure is twice it).
//! For a delta-wound motor the star equivalent is still half the terminal
//! resistance; the phase nodes then stand for the star equivalent (exact for
//! balanced currents).
//!
//! **Currents per phase RMS.** Every current here is the RMS of one phase's
//! line current. A maxon EC sheet rates its currents for block commutation
//! (two phases carrying the DC current `I` in series: loss `R_pp I^2`); the
//! sinusoidal current with the same loss has a per-phase RMS of
//! `I sqrt(2/3)`.
//!
//! # The network: three phase windings and a housing
//!
//! ```text
//!                c                c
//!   phase A (0) --- phase B (1) --- phase C (2)     (and c from A to C)
//!         \              |              /
//!       G_wh/3         G_wh/3         G_wh/3
//!            \           |           /
//!                 housing (3), C_h
//!                        |
//!                     1/R_th2
//!                        |
//!                ambient (boundary 0)
//! ```
//!
//! Each phase has a third of the winding's capacity `C_w / 3` and its own
//! Joule source `R(T) I_m^2` (current `m` heats phase `m`); `G_wh = 1 /
//! R_th1`.
//!
//! **Why this shape.** The datasheet knows two bodies, so the housing is one
//! node and the winding's capacity and resistance are the datasheet's. The
//! winding is split into its phases because the currents arrive per phase
//! and because the one case a single winding node cannot see is a stalled
//! or holding rotor, where DC puts twice the mean loss in one phase. No
//! more nodes (slot and end turns, rotor, bearings): a datasheet gives
//! nothing to place them with; a calibrated model does (see "Real data:
//! the HUST motor" in the crate docs).
//!
//! With equal RMS currents the three phases move
//! together, the couplings `c` carry nothing, and the network *is* the
//! datasheet's two-body model: the steady rise is `P (R_th1 + R_th2)` and
//! the step response has the datasheet's capacities and resistances
//! exactly (tested against the closed form). The split only shows when the
//! phases carry different heat: a locked rotor holding DC in the pattern
//! `(1, -1/2, -1/2)` puts a quarter of the hot phase's loss in each of the
//! other two, and the hot phase rises above the housing by
//!
//! ```text
//! T_A - T_h = 1.5 P_A R_th1 (1 + g / (g + 3 c)),   g = G_wh / 3,
//! ```
//!
//! from the mean phase rise `1.5 P_A R_th1` (`c` infinite: the datasheet's
//! one winding node) to twice that (`c = 0`).
//!
//! **The coupling.** `c` \[W/K\] stands for the heat a phase passes to its
//! neighbours through the shared teeth, yoke and end turns; no datasheet
//! gives it. The default is `c = 0` (independent phases), which makes a
//! locked rotor's hot phase rise twice as much above the housing as the
//! mean: the conservative bound of this shape. With it a DC current `I` at
//! standstill heats the hot phase above the housing as much as a balanced
//! set of RMS `I` (amplitude `sqrt(2) I`) would: a standstill current held
//! to the continuous RMS rating is safe. A locked-rotor test measures `c`: hold
//! DC `(I, -I/2, -I/2)`, read the hot and a cold phase's steady temperatures
//! (their resistances, or two thermistors), then `T_A - T_B = 0.75 P_A / (g
//! + 3 c)` gives `c` ([`MotorBuilder::phase_coupling_w_per_k`]).
//!
//! # Currents into the tick
//!
//! The observer's 1 ms tick holds each current for its step and heats the
//! phase with `R(T) I^2`, so what it wants is the **RMS of each phase
//! current over the last tick**: the square root of the mean of `i^2` over
//! the current loop's samples (one `sqrt` per phase per tick), or:
//!
//! * from the FOC's `Id`, `Iq` in steady rotation (an electrical period
//!   well below the winding's time constant `tau_w`):
//!   [`DqScaling::balanced_phase_currents_a`], each phase
//!   `sqrt((Id^2 + Iq^2) / 2)` for the amplitude-invariant Clarke/Park
//!   (copper loss `1.5 R (Id^2 + Iq^2)`, ODrive, VESC, moteus) or
//!   `sqrt((Id^2 + Iq^2) / 3)` for the power-invariant one (loss
//!   `R (Id^2 + Iq^2)`);
//! * at standstill or a crawl the phase currents are DC and their split
//!   depends on the electrical angle: [`DqScaling::phase_currents_at_angle_a`]
//!   (inverse Park and Clarke at the angle: exact, the instantaneous
//!   currents are the DC ones), or without an angle
//!   [`DqScaling::worst_phase_currents_a`] (the worst angle, hot phase on
//!   A: `(|I|, |I|/2, |I|/2)` amplitude-invariant; the right total loss and
//!   the hottest phase the angle can make);
//! * the measured phase currents sampled once per tick only at standstill
//!   or a crawl: at speed a 1 ms sample of a sine aliases (at an electrical
//!   frequency a multiple of 500 Hz every sample lands on the same phase).
//!
//! The limiter's limits are in the measure of the inputs: per-phase RMS with
//! the balanced mapping (turn one back into an `|I_dq|` limit with
//! [`DqScaling::dq_limit_a`]), the phase amplitude with the worst-phase one
//! (then phase A's limit is the `|I_dq|` limit itself, amplitude-invariant,
//! and `peak_current_a` caps an amplitude: stricter by `sqrt(2)`).
//!
//! # Example: a maxon EC 13, 6 W
//!
//! maxon EC 13 Ø13 mm, brushless, 6 Watt, order number 305192 (12 V),
//! maxon catalogue data sheet, lines 6, 8, 10, 17-20, 22: nominal current
//! 0.645 A, starting current 2.09 A, terminal resistance phase to phase
//! 5.74 ohm, thermal resistance housing-ambient 32 K/W, winding-housing
//! 2.46 K/W, thermal time constant winding 0.72 s, motor 188 s, max.
//! permissible winding temperature 155 degC. Its sheet says the nominal
//! current at 25 degC ambient brings the winding to 155 degC; this model
//! gives 146.6 degC from the copper loss alone: the rest is iron and
//! friction loss at nominal speed, which the builder does not model (add an
//! estimate to a copy of the network, `motor.network().clone()
//! .fixed_power(HOUSING_NODE, watts)?`, and build the observer on that).
//! maxon's `tau_w = C_w R_th1` is not itself a mode of the two bodies: the
//! winding's fast mode is 0.686 s here for `tau_w` 0.72 s, the slow one
//! 197 s for `tau_m` 188 s (the tests hold the response to the closed form
//! of the two bodies, to 1e-10 of the rise).
//!
//! ```
//! use coil_thermal::network::motor::{DqScaling, MotorBuilder, MotorDatasheet, MotorHeatCapacity, MotorSensor};
//! use coil_thermal::observer::network::{NetworkInputs, NetworkObserver, NetworkObserverBuilder, NetworkSettings};
//!
//! let block_to_rms = (2.0f64 / 3.0).sqrt(); // maxon rates block commutation
//! let motor = MotorBuilder::new(MotorDatasheet {
//!     r_winding_housing_k_per_w: 2.46,
//!     r_housing_ambient_k_per_w: 32.0,
//!     heat_capacity: MotorHeatCapacity::TimeConstants { tau_winding_s: 0.72, tau_housing_s: 188.0 },
//!     phase_resistance_ohm: 5.74 / 2.0, // phase to phase / 2
//!     resistance_ref_c: 25.0,
//!     alpha_per_k: 0.00393,
//!     continuous_current_a: 0.645 * block_to_rms,
//!     peak_current_a: 2.09 * block_to_rms, // starting current at 12 V
//!     winding_limit_c: 155.0,
//!     housing_limit_c: None,
//! })
//! .build()?;
//! // At the nominal current and 25 degC the winding settles near 155 degC.
//! let hot_c = motor.continuous_winding_c(25.0)?;
//! assert!(hot_c > 140.0 && hot_c < 155.0);
//!
//! // N = 4 nodes, B = 1 ambient, M = 3 phases, X = N + M = 7, P = 1 sensor.
//! let observer: NetworkObserver<4, 1, 3, 7, 1> =
//!     NetworkObserverBuilder::new(motor.network(), [motor.sensor_node(MotorSensor::Housing)])
//!         .critical_c(motor.critical_c())
//!         .hardware_limit_a(motor.hardware_limit_a())
//!         // One sensor cannot tell three phases' heat apart: no bias states
//!         // (with a winding thermistor the default's gain does not converge).
//!         .settings(NetworkSettings { bias_noise_w2_per_s: 0.0, ..NetworkSettings::DEFAULT })
//!         .build()?;
//! let mut state = observer.state(&[25.0; 4], &[25.0]);
//! let scaling = DqScaling::AmplitudeInvariant; // ODrive, VESC, moteus
//! let iq_a = 0.645 * block_to_rms as f32 * core::f32::consts::SQRT_2; // |I_dq| at nominal
//! for tick in 0..5_000u32 {
//!     let inputs = NetworkInputs {
//!         currents_a: scaling.balanced_phase_currents_a(0.0, iq_a), // spinning
//!         boundary_c: [25.0],
//!         readings: [None], // a housing `TimedReading` when one arrives
//!         now_us: tick * 1000,
//!         elapsed_us: 1000,
//!     };
//!     let out = observer.tick(&mut state, &inputs);
//!     let _iq_limit_a = scaling.dq_limit_a(out.limits[0].current_a);
//! }
//! let out = state.outputs();
//! // 5 s at the nominal current: the winding (tau 0.72 s) is well above the
//! // housing (tau 188 s), the three phases alike, nothing limited yet.
//! assert!(out.temps_c[0] > out.temps_c[3] + 5.0 && out.temps_c[3] > 25.0);
//! assert!((out.temps_c[0] - out.temps_c[2]).abs() < 1e-3);
//! assert!(!out.alarm.shutdown && out.limits[0].current_a > 1.5);
//! # Ok::<(), coil_thermal::BuildError>(())
//! ```

use super::{Network, Resistance};
use crate::error::{check, BuildError};

/// The node of each phase winding (A, B, C); current input `m` heats node `m`.
pub const PHASE_NODES: [usize; 3] = [0, 1, 2];
/// The housing (stator) node.
pub const HOUSING_NODE: usize = 3;
/// The ambient: the network's only boundary.
pub const AMBIENT_BOUNDARY: usize = 0;
/// The motor's network: 4 nodes (3 phases, the housing), 1 boundary (the
/// ambient), 3 currents (the phases). Its observer is
/// `NetworkObserver<4, 1, 3, 7, P>`.
pub type MotorNetwork = Network<4, 1, 3>;

/// Highest temperature coefficient accepted \[1/K\]: copper is 0.00393,
/// aluminium 0.0040; 0.02 and above is a unit error (percent per kelvin).
const ALPHA_MAX_PER_K: f64 = 0.02;
/// Highest limit temperature accepted \[degC\] (class 240 insulation and a
/// margin); the observer needs limits below its `NO_LIMIT_C`.
const LIMIT_MAX_C: f64 = 400.0;

/// How the datasheet gives the heat capacities.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MotorHeatCapacity {
    /// Thermal time constants \[s\] (maxon lines 19, 20): `tau_winding_s =
    /// C_w R_th1`, `tau_housing_s = C_h R_th2` ("motor" or "stator").
    TimeConstants {
        /// Thermal time constant of the winding \[s\].
        tau_winding_s: f64,
        /// Thermal time constant of the motor (housing, stator) \[s\].
        tau_housing_s: f64,
    },
    /// Heat capacities \[J/K\], the whole winding and the housing.
    Capacities {
        /// All three phase windings together \[J/K\].
        winding_j_per_k: f64,
        /// Housing and stator \[J/K\].
        housing_j_per_k: f64,
    },
}

/// The datasheet values of a three-phase motor, all in SI units (see the
/// module docs for where each comes from). Every field is explicit: there is
/// no default motor.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MotorDatasheet {
    /// Thermal resistance winding to housing `R_th1` \[K/W\], the whole
    /// winding.
    pub r_winding_housing_k_per_w: f64,
    /// Thermal resistance housing to ambient `R_th2` \[K/W\].
    pub r_housing_ambient_k_per_w: f64,
    /// Time constants or capacities.
    pub heat_capacity: MotorHeatCapacity,
    /// Resistance of one phase, star equivalent (phase to phase / 2)
    /// \[ohm\], at `resistance_ref_c`.
    pub phase_resistance_ohm: f64,
    /// Temperature of `phase_resistance_ohm` \[degC\] (maxon: 25).
    pub resistance_ref_c: f64,
    /// Temperature coefficient of the resistance \[1/K\], in `[0, 0.02)`
    /// (copper 0.00393; 0 for a constant resistance).
    pub alpha_per_k: f64,
    /// Continuous current, per-phase RMS \[A\].
    pub continuous_current_a: f64,
    /// The most the drive may apply, per-phase RMS \[A\], at least the
    /// continuous current: the limiter's ceiling for every phase.
    pub peak_current_a: f64,
    /// Highest permissible winding temperature \[degC\] (the insulation
    /// class: 130 B, 155 F, 180 H).
    pub winding_limit_c: f64,
    /// Highest permissible housing temperature \[degC\] (a touch limit, a
    /// bearing grease), `None` for none.
    pub housing_limit_c: Option<f64>,
}

/// Where the motor's one temperature sensor sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MotorSensor {
    /// A thermistor in the winding (end turns), taken as on phase A. Feed
    /// phase currents (or the angle mapping) at standstill, so that the
    /// phase it sits on is the phase the model heats.
    WindingThermistor,
    /// A thermocouple or thermistor on the housing (stator, flange).
    Housing,
}

/// Builds a [`Motor`] from a [`MotorDatasheet`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorBuilder {
    datasheet: MotorDatasheet,
    phase_coupling_w_per_k: f64,
}

impl MotorBuilder {
    /// Starts from the datasheet; phase coupling 0 (see the module docs).
    pub const fn new(datasheet: MotorDatasheet) -> Self {
        Self {
            datasheet,
            phase_coupling_w_per_k: 0.0,
        }
    }

    /// The conductance between each pair of phases \[W/K\], finite and
    /// `>= 0`. Default 0: independent phases, the conservative bound at a
    /// locked rotor (see the module docs for measuring it).
    pub const fn phase_coupling_w_per_k(mut self, c_w_per_k: f64) -> Self {
        self.phase_coupling_w_per_k = c_w_per_k;
        self
    }

    /// Validates the values and builds the network.
    ///
    /// # Errors
    /// [`BuildError::InvalidParameter`] naming the first invalid field:
    /// thermal resistances, time constants, capacities, resistance,
    /// currents, limits not finite and strictly positive (`alpha_per_k` in
    /// `[0, 0.02)`, `resistance_ref_c` in `[-60, 200]` degC, limits in `(0,
    /// 400]` degC, `peak_current_a >= continuous_current_a`,
    /// `phase_coupling_w_per_k >= 0`).
    pub fn build(&self) -> Result<Motor, BuildError> {
        let d = &self.datasheet;
        let positive = |v: f64, name: &'static str| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(BuildError::InvalidParameter { name })
            }
        };
        let r1 = positive(d.r_winding_housing_k_per_w, "r_winding_housing_k_per_w")?;
        let r2 = positive(d.r_housing_ambient_k_per_w, "r_housing_ambient_k_per_w")?;
        let (c_winding, c_housing) = match d.heat_capacity {
            MotorHeatCapacity::TimeConstants {
                tau_winding_s,
                tau_housing_s,
            } => (
                positive(tau_winding_s, "tau_winding_s")? / r1,
                positive(tau_housing_s, "tau_housing_s")? / r2,
            ),
            MotorHeatCapacity::Capacities {
                winding_j_per_k,
                housing_j_per_k,
            } => (
                positive(winding_j_per_k, "winding_j_per_k")?,
                positive(housing_j_per_k, "housing_j_per_k")?,
            ),
        };
        let r_phase = positive(d.phase_resistance_ohm, "phase_resistance_ohm")?;
        check(
            (-60.0..=200.0).contains(&d.resistance_ref_c),
            "resistance_ref_c",
        )?;
        check(
            (0.0..ALPHA_MAX_PER_K).contains(&d.alpha_per_k),
            "alpha_per_k",
        )?;
        let continuous = positive(d.continuous_current_a, "continuous_current_a")?;
        check(
            d.peak_current_a.is_finite() && d.peak_current_a >= continuous,
            "peak_current_a",
        )?;
        let limit = |v: f64| v.is_finite() && v > 0.0 && v <= LIMIT_MAX_C;
        check(limit(d.winding_limit_c), "winding_limit_c")?;
        check(d.housing_limit_c.is_none_or(limit), "housing_limit_c")?;
        let c = self.phase_coupling_w_per_k;
        check(c.is_finite() && c >= 0.0, "phase_coupling_w_per_k")?;
        let resistance = Resistance::with_alpha(r_phase, d.alpha_per_k, d.resistance_ref_c);

        // The capacities and the winding-housing conductance split evenly
        // over the phases, so that three equal currents give the two-body
        // model exactly.
        let c_phase = c_winding / 3.0;
        let g_phase = 1.0 / (3.0 * r1);
        let mut network = Network::new([c_phase, c_phase, c_phase, c_housing])?.connect_boundary(
            HOUSING_NODE,
            AMBIENT_BOUNDARY,
            1.0 / r2,
        )?;
        for (m, node) in PHASE_NODES.iter().enumerate() {
            network = network
                .connect(*node, HOUSING_NODE, g_phase)?
                .joule_source(m, *node, resistance)?;
        }
        if c > 0.0 {
            network = network
                .connect(0, 1, c)?
                .connect(1, 2, c)?
                .connect(0, 2, c)?;
        }
        Ok(Motor {
            network,
            datasheet: *d,
            phase_coupling_w_per_k: c,
        })
    }
}

/// A motor built from its datasheet: the network and what an observer's
/// builder needs.
#[derive(Debug, Clone, PartialEq)]
pub struct Motor {
    network: MotorNetwork,
    datasheet: MotorDatasheet,
    phase_coupling_w_per_k: f64,
}

impl Motor {
    /// The network (nodes: [`PHASE_NODES`], [`HOUSING_NODE`]; boundary:
    /// [`AMBIENT_BOUNDARY`]; current `m` heats phase `m`).
    pub fn network(&self) -> &MotorNetwork {
        &self.network
    }

    /// The datasheet it was built from.
    pub fn datasheet(&self) -> &MotorDatasheet {
        &self.datasheet
    }

    /// The conductance between each pair of phases \[W/K\].
    pub fn phase_coupling_w_per_k(&self) -> f64 {
        self.phase_coupling_w_per_k
    }

    /// Critical temperature of each node \[degC\]: the winding limit on the
    /// three phases, the housing limit (if any) on the housing. For
    /// `NetworkObserverBuilder::critical_c`.
    pub fn critical_c(&self) -> [Option<f64>; 4] {
        let w = Some(self.datasheet.winding_limit_c);
        [w, w, w, self.datasheet.housing_limit_c]
    }

    /// Each phase's hardware limit \[A\] (the datasheet's
    /// `peak_current_a`). For `NetworkObserverBuilder::hardware_limit_a`.
    pub fn hardware_limit_a(&self) -> [f64; 3] {
        [self.datasheet.peak_current_a; 3]
    }

    /// The node a sensor measures, for the observer's `sensor_nodes`.
    pub const fn sensor_node(&self, sensor: MotorSensor) -> usize {
        match sensor {
            MotorSensor::WindingThermistor => PHASE_NODES[0],
            MotorSensor::Housing => HOUSING_NODE,
        }
    }

    /// Steady temperatures \[degC\] of the phases and the housing at
    /// constant per-phase RMS currents \[A\] and ambient \[degC\], with
    /// `R(T)` rising (build-time code).
    ///
    /// # Errors
    /// [`BuildError::NoSteadyState`] when the currents drive thermal
    /// runaway; [`BuildError::InvalidParameter`] for non-finite inputs.
    pub fn steady_state_c(
        &self,
        phase_rms_a: [f64; 3],
        ambient_c: f64,
    ) -> Result<[f64; 4], BuildError> {
        self.network.steady_state(&phase_rms_a, &[ambient_c])
    }

    /// The steady winding temperature \[degC\] at the continuous current in
    /// every phase and `ambient_c` \[degC\]: compare it with the winding
    /// limit the datasheet rates the continuous current for.
    ///
    /// # Errors
    /// As [`Motor::steady_state_c`].
    pub fn continuous_winding_c(&self, ambient_c: f64) -> Result<f64, BuildError> {
        let i = self.datasheet.continuous_current_a;
        Ok(self.steady_state_c([i; 3], ambient_c)?[PHASE_NODES[0]])
    }
}

/// The scaling of the Clarke/Park transform that produced `Id`, `Iq`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DqScaling {
    /// `|I_dq|` is the phase current's amplitude (the 2/3 Clarke; ODrive,
    /// VESC, moteus): copper loss `1.5 R (Id^2 + Iq^2)`.
    AmplitudeInvariant,
    /// The `sqrt(2/3)` Clarke: copper loss `R (Id^2 + Iq^2)`.
    PowerInvariant,
}

impl DqScaling {
    /// `k` in the copper loss `k R (Id^2 + Iq^2)` (1.5 or 1).
    pub const fn loss_factor(self) -> f32 {
        match self {
            Self::AmplitudeInvariant => 1.5,
            Self::PowerInvariant => 1.0,
        }
    }

    /// Amplitude of each phase current \[A\] per ampere of `|I_dq|`: 1 or
    /// `sqrt(2/3)`.
    fn amplitude_per_dq(self) -> f32 {
        match self {
            Self::AmplitudeInvariant => 1.0,
            Self::PowerInvariant => 0.816_496_6, // sqrt(2/3)
        }
    }

    /// The per-phase RMS current \[A\] of a balanced set in steady rotation
    /// from `Id`, `Iq` \[A\]: `sqrt((Id^2 + Iq^2) / 2)` amplitude-invariant,
    /// `sqrt((Id^2 + Iq^2) / 3)` power-invariant. NaN in, NaN out (the
    /// observer holds the last valid current and flags it).
    pub fn phase_rms_a(self, id_a: f32, iq_a: f32) -> f32 {
        libm::hypotf(id_a, iq_a) * self.amplitude_per_dq() * core::f32::consts::FRAC_1_SQRT_2
    }

    /// The three per-phase RMS currents \[A\] in steady rotation (each
    /// [`DqScaling::phase_rms_a`]): the tick's `currents_a`.
    pub fn balanced_phase_currents_a(self, id_a: f32, iq_a: f32) -> [f32; 3] {
        [self.phase_rms_a(id_a, iq_a); 3]
    }

    /// The instantaneous phase currents \[A\] at electrical angle
    /// `theta_e_rad` (inverse Park, then inverse Clarke). At standstill or a
    /// crawl they are the DC phase currents, and the tick's `currents_a`.
    pub fn phase_currents_at_angle_a(self, id_a: f32, iq_a: f32, theta_e_rad: f32) -> [f32; 3] {
        let (s, c) = (libm::sinf(theta_e_rad), libm::cosf(theta_e_rad));
        let k = self.amplitude_per_dq();
        let alpha = k * (id_a * c - iq_a * s);
        let beta = k * (id_a * s + iq_a * c);
        let half_sqrt3 = 0.866_025_4; // sqrt(3) / 2
        [
            alpha,
            -0.5 * alpha + half_sqrt3 * beta,
            -0.5 * alpha - half_sqrt3 * beta,
        ]
    }

    /// The standstill currents at the worst angle \[A\], hot phase on A:
    /// `(a, a/2, a/2)` with `a` the phase amplitude (`|I_dq|`
    /// amplitude-invariant). The right total loss, and the hottest phase
    /// any angle can make; for standstill without an angle.
    pub fn worst_phase_currents_a(self, id_a: f32, iq_a: f32) -> [f32; 3] {
        let a = libm::hypotf(id_a, iq_a) * self.amplitude_per_dq();
        [a, 0.5 * a, 0.5 * a]
    }

    /// The largest `|I_dq|` \[A\] whose balanced per-phase RMS is
    /// `phase_rms_a` \[A\]: a limiter's per-phase limit as a dq limit in
    /// rotation (the inverse of [`DqScaling::phase_rms_a`]).
    pub fn dq_limit_a(self, phase_rms_a: f32) -> f32 {
        phase_rms_a * core::f32::consts::SQRT_2 / self.amplitude_per_dq()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const AMBIENT_C: f64 = 25.0;

    /// maxon EC 13, 6 W, 305192 (the module example's sheet), with
    /// `alpha_per_k` and the capacities as given.
    fn ec13(alpha_per_k: f64) -> MotorDatasheet {
        let rms = libm::sqrt(2.0 / 3.0);
        MotorDatasheet {
            r_winding_housing_k_per_w: 2.46,
            r_housing_ambient_k_per_w: 32.0,
            heat_capacity: MotorHeatCapacity::TimeConstants {
                tau_winding_s: 0.72,
                tau_housing_s: 188.0,
            },
            phase_resistance_ohm: 5.74 / 2.0,
            resistance_ref_c: 25.0,
            alpha_per_k,
            continuous_current_a: 0.645 * rms,
            peak_current_a: 2.09 * rms,
            winding_limit_c: 155.0,
            housing_limit_c: Some(90.0),
        }
    }

    /// A larger hobby-sized motor with slower time constants (values of
    /// the order of a 5 kW outrunner's: not a specific sheet).
    fn outrunner() -> MotorDatasheet {
        MotorDatasheet {
            r_winding_housing_k_per_w: 0.35,
            r_housing_ambient_k_per_w: 1.1,
            heat_capacity: MotorHeatCapacity::Capacities {
                winding_j_per_k: 180.0,
                housing_j_per_k: 900.0,
            },
            phase_resistance_ohm: 0.028,
            resistance_ref_c: 20.0,
            alpha_per_k: 0.00393,
            continuous_current_a: 40.0,
            peak_current_a: 120.0,
            winding_limit_c: 130.0,
            housing_limit_c: None,
        }
    }

    /// Classical RK4 on the network's f64 right-hand side.
    fn rk4(net: &MotorNetwork, temps: &mut [f64; 4], currents: &[f64; 3], duration_s: f64, h: f64) {
        let steps = libm::round(duration_s / h) as usize;
        let shifted =
            |t: &[f64; 4], k: &[f64; 4], a: f64| core::array::from_fn(|i| t[i] + a * k[i]);
        for _ in 0..steps {
            let amb = [AMBIENT_C];
            let k1 = net.derivative_k_per_s(temps, currents, &amb);
            let k2 = net.derivative_k_per_s(&shifted(temps, &k1, h / 2.0), currents, &amb);
            let k3 = net.derivative_k_per_s(&shifted(temps, &k2, h / 2.0), currents, &amb);
            let k4 = net.derivative_k_per_s(&shifted(temps, &k3, h), currents, &amb);
            for i in 0..4 {
                temps[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }

    #[test]
    fn steady_rise_is_p_times_rth_with_the_resistance_fixed_point() {
        for (sheet, current_a) in [(ec13(0.00393), 0.5), (outrunner(), 40.0)] {
            let motor = MotorBuilder::new(sheet).build().unwrap();
            let r_tot = sheet.r_winding_housing_k_per_w + sheet.r_housing_ambient_k_per_w;
            // P(T) = 3 I^2 R_ref (1 + alpha (T - T_ref)) and T - T_a = P(T) R_tot:
            // linear in T, so dT = k (1 + alpha (T_a - T_ref)) / (1 - alpha k).
            let k = 3.0 * current_a * current_a * sheet.phase_resistance_ohm * r_tot;
            let alpha = sheet.alpha_per_k;
            let rise = k * (1.0 + alpha * (AMBIENT_C - sheet.resistance_ref_c)) / (1.0 - alpha * k);
            let power_w = rise / r_tot;
            let steady = motor.steady_state_c([current_a; 3], AMBIENT_C).unwrap();
            for node in PHASE_NODES {
                assert!((steady[node] - (AMBIENT_C + rise)).abs() < 1e-9 * rise);
            }
            let housing = AMBIENT_C + power_w * sheet.r_housing_ambient_k_per_w;
            assert!((steady[HOUSING_NODE] - housing).abs() < 1e-9 * rise);
        }
    }

    #[test]
    fn the_ec13_at_its_nominal_current_settles_near_its_rated_155_degc() {
        // maxon: the nominal current at 25 degC ambient reaches the maximum
        // winding temperature (155 degC). Copper loss alone gives 146.6:
        // iron and friction losses at nominal speed make up the rest.
        let motor = MotorBuilder::new(ec13(0.00393)).build().unwrap();
        let hot_c = motor.continuous_winding_c(AMBIENT_C).unwrap();
        assert!((hot_c - 146.6).abs() < 0.1, "{hot_c}");
        assert!(hot_c < 155.0 && hot_c > 155.0 - 0.1 * 130.0);
    }

    #[test]
    fn the_winding_step_response_has_the_datasheet_time_constants() {
        for sheet in [ec13(0.0), outrunner()] {
            let sheet = MotorDatasheet {
                alpha_per_k: 0.0,
                ..sheet
            };
            let motor = MotorBuilder::new(sheet).build().unwrap();
            let (r1, r2) = (
                sheet.r_winding_housing_k_per_w,
                sheet.r_housing_ambient_k_per_w,
            );
            let (cw, ch) = match sheet.heat_capacity {
                MotorHeatCapacity::TimeConstants {
                    tau_winding_s,
                    tau_housing_s,
                } => (tau_winding_s / r1, tau_housing_s / r2),
                MotorHeatCapacity::Capacities {
                    winding_j_per_k,
                    housing_j_per_k,
                } => (winding_j_per_k, housing_j_per_k),
            };
            // The two-body model: Cw w' = P - (w - h)/R1, Ch h' = (w - h)/R1 - h/R2.
            let current = sheet.continuous_current_a;
            let p = 3.0 * current * current * sheet.phase_resistance_ohm;
            let (a11, a12) = (-1.0 / (cw * r1), 1.0 / (cw * r1));
            let (a21, a22) = (1.0 / (ch * r1), -(1.0 / r1 + 1.0 / r2) / ch);
            let (tr, det) = (a11 + a22, a11 * a22 - a12 * a21);
            let disc = libm::sqrt(tr * tr - 4.0 * det);
            let (l_fast, l_slow) = ((tr - disc) / 2.0, (tr + disc) / 2.0);
            let w_ss = p * (r1 + r2);
            // w(t) = w_ss + a e^{l_fast t} + b e^{l_slow t}, w(0) = 0, w'(0) = P / Cw.
            let a = (p / cw - l_slow * (-w_ss)) / (l_fast - l_slow);
            let b = -w_ss - a;
            let closed = |t: f64| w_ss + a * libm::exp(l_fast * t) + b * libm::exp(l_slow * t);
            let tau_fast = -1.0 / l_fast;
            let tau_slow = -1.0 / l_slow;
            let h = tau_fast / 200.0;
            let mut temps = [AMBIENT_C; 4];
            let mut t = 0.0;
            for target in [tau_fast, 3.0 * tau_fast, tau_slow, 3.0 * tau_slow] {
                rk4(motor.network(), &mut temps, &[current; 3], target - t, h);
                t += libm::round((target - t) / h) * h;
                let want = closed(t);
                for node in PHASE_NODES {
                    let got = temps[node] - AMBIENT_C;
                    assert!((got - want).abs() < 1e-6 * w_ss, "t {t}: {got} vs {want}");
                }
            }
            if let MotorHeatCapacity::TimeConstants { tau_winding_s, .. } = sheet.heat_capacity {
                // maxon's winding constant is the fast mode when Cw << Ch.
                assert!((tau_fast - tau_winding_s).abs() < 0.06 * tau_winding_s);
            }
        }
    }

    #[test]
    fn equal_rms_currents_give_equal_phase_temperatures() {
        use crate::observer::network::{
            NetworkInputs, NetworkObserver, NetworkObserverBuilder, NetworkSettings,
        };
        let motor = MotorBuilder::new(outrunner())
            .phase_coupling_w_per_k(2.0)
            .build()
            .unwrap();
        let steady = motor.steady_state_c([40.0; 3], AMBIENT_C).unwrap();
        assert!((steady[0] - steady[1]).abs() < 1e-9 && (steady[0] - steady[2]).abs() < 1e-9);
        let observer: NetworkObserver<4, 1, 3, 7, 1> = NetworkObserverBuilder::new(
            motor.network(),
            [motor.sensor_node(MotorSensor::WindingThermistor)],
        )
        .critical_c(motor.critical_c())
        .hardware_limit_a(motor.hardware_limit_a())
        .settings(NetworkSettings {
            bias_noise_w2_per_s: 0.0,
            ..NetworkSettings::DEFAULT
        })
        .build()
        .unwrap();
        let mut state = observer.state(&[25.0; 4], &[25.0]);
        for tick in 0..20_000u32 {
            let inputs = NetworkInputs {
                currents_a: DqScaling::AmplitudeInvariant.balanced_phase_currents_a(-10.0, 55.0),
                boundary_c: [25.0],
                readings: [None],
                now_us: tick * 1000,
                elapsed_us: 1000,
            };
            observer.tick(&mut state, &inputs);
        }
        let t = state.outputs().temps_c;
        // The same 20 s from the f64 network by RK4.
        let rms = f64::from(DqScaling::AmplitudeInvariant.phase_rms_a(-10.0, 55.0));
        let mut reference = [AMBIENT_C; 4];
        rk4(motor.network(), &mut reference, &[rms; 3], 20.0, 0.01);
        for (got, want) in t.iter().zip(reference) {
            assert!((f64::from(*got) - want).abs() < 0.01, "{t:?} {reference:?}");
        }
        assert!(t[0] > 35.0, "{t:?}");
        assert!(
            (t[0] - t[1]).abs() < 1e-4 && (t[0] - t[2]).abs() < 1e-4,
            "{t:?}"
        );
    }

    #[test]
    fn a_locked_rotor_heats_the_hot_phase_as_the_closed_form_says() {
        // DC (I, -I/2, -I/2), constant resistance: P_A = R I^2, P_B = P_C = P_A / 4.
        for c in [0.0, 0.5, 5.0] {
            let sheet = MotorDatasheet {
                alpha_per_k: 0.0,
                ..outrunner()
            };
            let motor = MotorBuilder::new(sheet)
                .phase_coupling_w_per_k(c)
                .build()
                .unwrap();
            let i = 30.0;
            let steady = motor
                .steady_state_c([i, -i / 2.0, -i / 2.0], AMBIENT_C)
                .unwrap();
            let (r1, r2) = (
                sheet.r_winding_housing_k_per_w,
                sheet.r_housing_ambient_k_per_w,
            );
            let p_a = sheet.phase_resistance_ohm * i * i;
            let total = 1.5 * p_a;
            let housing = AMBIENT_C + total * r2;
            let g = 1.0 / (3.0 * r1);
            // Mean phase rise above the housing P R1; the spread from the
            // difference of the phase A and B balances.
            let mean = total * r1;
            let spread = 0.75 * p_a / (g + 3.0 * c);
            let hot = housing + mean + 2.0 / 3.0 * spread;
            let cold = hot - spread;
            assert!((steady[HOUSING_NODE] - housing).abs() < 1e-9 * total);
            assert!((steady[0] - hot).abs() < 1e-9 * total, "c {c}");
            assert!((steady[1] - cold).abs() < 1e-9 * total && (steady[2] - cold).abs() < 1e-9);
            let average = (steady[0] + steady[1] + steady[2]) / 3.0;
            assert!(steady[0] > average + 0.1);
            if c == 0.0 {
                // Independent phases: the hot phase rises twice the mean.
                assert!((steady[0] - housing - 2.0 * mean).abs() < 1e-9 * total);
            }
            // No angle heats any phase more than the worst-phase mapping
            // heats phase A (amplitude I, amplitude-invariant).
            let scaling = DqScaling::AmplitudeInvariant;
            let worst = scaling.worst_phase_currents_a(0.0, i as f32).map(f64::from);
            let bound = motor.steady_state_c(worst, AMBIENT_C).unwrap()[0];
            for step in 0..60 {
                let theta = f64::from(step) * core::f64::consts::PI / 30.0;
                let third = 2.0 * core::f64::consts::PI / 3.0;
                let phases = [0.0, third, -third].map(|phi| -i * libm::sin(theta - phi));
                let at_angle = motor.steady_state_c(phases, AMBIENT_C).unwrap();
                let hottest = at_angle[..3].iter().fold(f64::MIN, |m, t| m.max(*t));
                assert!(hottest <= bound + 1e-9, "c {c}, theta {theta}");
            }
            assert!((bound - hot).abs() < 1e-6 * total);
        }
    }

    #[test]
    fn dq_currents_carry_the_copper_loss_of_the_phase_currents() {
        let r = 0.15;
        let (id, iq) = (-3.0f32, 7.5f32);
        let dq2 = f64::from(id * id + iq * iq);
        for scaling in [DqScaling::AmplitudeInvariant, DqScaling::PowerInvariant] {
            // The phase amplitude per |I_dq|, from the definition of each
            // Clarke transform: 1 (the 2/3 form) or sqrt(2/3).
            let k = match scaling {
                DqScaling::AmplitudeInvariant => 1.0,
                DqScaling::PowerInvariant => libm::sqrt(2.0 / 3.0),
            };
            let balanced = scaling.balanced_phase_currents_a(id, iq);
            let balanced_loss: f64 = balanced.iter().map(|i| r * f64::from(i * i)).sum();
            let want_loss = f64::from(scaling.loss_factor()) * r * dq2;
            assert!((balanced_loss - want_loss).abs() < 1e-5 * want_loss);
            for step in 0..24 {
                let theta = f64::from(step) * 0.37;
                let third = 2.0 * core::f64::consts::PI / 3.0;
                let (id, iq) = (f64::from(id), f64::from(iq));
                // i_x = k (Id cos(theta - phi_x) - Iq sin(theta - phi_x)).
                let phases = [0.0, third, -third]
                    .map(|phi| k * (id * libm::cos(theta - phi) - iq * libm::sin(theta - phi)));
                let loss: f64 = phases.iter().map(|i| r * i * i).sum();
                assert!((loss - want_loss).abs() < 1e-9 * want_loss, "{theta}");
                let got = scaling.phase_currents_at_angle_a(id as f32, iq as f32, theta as f32);
                for (g, w) in got.iter().zip(phases) {
                    assert!(
                        (f64::from(*g) - w).abs() < 1e-4,
                        "{theta}: {got:?} {phases:?}"
                    );
                }
                // The worst phase bounds every angle's hottest phase.
                let worst = scaling.worst_phase_currents_a(id as f32, iq as f32);
                let hottest = phases.iter().fold(0.0f64, |m, i| m.max(i.abs()));
                assert!(f64::from(worst[0]) >= hottest - 1e-4);
            }
            let worst = scaling.worst_phase_currents_a(id, iq);
            let worst_loss: f64 = worst.iter().map(|i| r * f64::from(i * i)).sum();
            assert!((worst_loss - want_loss).abs() < 1e-5 * want_loss);
            // The dq limit gives back the phase RMS it came from.
            let rms = scaling.phase_rms_a(id, iq);
            assert!((scaling.dq_limit_a(rms) - libm::sqrtf(id * id + iq * iq)).abs() < 1e-4);
        }
    }

    #[test]
    fn invalid_values_are_rejected_by_name() {
        let good = ec13(0.00393);
        let cases: [(MotorDatasheet, &str); 16] = [
            (
                MotorDatasheet {
                    r_winding_housing_k_per_w: 0.0,
                    ..good
                },
                "r_winding_housing_k_per_w",
            ),
            (
                MotorDatasheet {
                    r_housing_ambient_k_per_w: f64::NAN,
                    ..good
                },
                "r_housing_ambient_k_per_w",
            ),
            (
                MotorDatasheet {
                    heat_capacity: MotorHeatCapacity::TimeConstants {
                        tau_winding_s: -1.0,
                        tau_housing_s: 188.0,
                    },
                    ..good
                },
                "tau_winding_s",
            ),
            (
                MotorDatasheet {
                    heat_capacity: MotorHeatCapacity::TimeConstants {
                        tau_winding_s: 0.72,
                        tau_housing_s: f64::INFINITY,
                    },
                    ..good
                },
                "tau_housing_s",
            ),
            (
                MotorDatasheet {
                    heat_capacity: MotorHeatCapacity::Capacities {
                        winding_j_per_k: 0.0,
                        housing_j_per_k: 5.0,
                    },
                    ..good
                },
                "winding_j_per_k",
            ),
            (
                MotorDatasheet {
                    heat_capacity: MotorHeatCapacity::Capacities {
                        winding_j_per_k: 0.3,
                        housing_j_per_k: -5.0,
                    },
                    ..good
                },
                "housing_j_per_k",
            ),
            (
                MotorDatasheet {
                    phase_resistance_ohm: -2.87,
                    ..good
                },
                "phase_resistance_ohm",
            ),
            (
                MotorDatasheet {
                    resistance_ref_c: f64::NAN,
                    ..good
                },
                "resistance_ref_c",
            ),
            (
                MotorDatasheet {
                    alpha_per_k: 0.393, // percent per kelvin
                    ..good
                },
                "alpha_per_k",
            ),
            (
                MotorDatasheet {
                    alpha_per_k: -0.001,
                    ..good
                },
                "alpha_per_k",
            ),
            (
                MotorDatasheet {
                    continuous_current_a: 0.0,
                    ..good
                },
                "continuous_current_a",
            ),
            (
                MotorDatasheet {
                    peak_current_a: 0.1,
                    ..good
                },
                "peak_current_a",
            ),
            (
                MotorDatasheet {
                    winding_limit_c: f64::NAN,
                    ..good
                },
                "winding_limit_c",
            ),
            (
                MotorDatasheet {
                    winding_limit_c: 1000.0,
                    ..good
                },
                "winding_limit_c",
            ),
            (
                MotorDatasheet {
                    housing_limit_c: Some(f64::INFINITY),
                    ..good
                },
                "housing_limit_c",
            ),
            (
                MotorDatasheet {
                    housing_limit_c: Some(-5.0),
                    ..good
                },
                "housing_limit_c",
            ),
        ];
        for (sheet, name) in cases {
            assert_eq!(
                MotorBuilder::new(sheet).build(),
                Err(BuildError::InvalidParameter { name }),
                "{name}"
            );
        }
        for c in [-1.0, f64::NAN] {
            assert_eq!(
                MotorBuilder::new(good).phase_coupling_w_per_k(c).build(),
                Err(BuildError::InvalidParameter {
                    name: "phase_coupling_w_per_k"
                })
            );
        }
        let motor = MotorBuilder::new(good).build().unwrap();
        assert_eq!(
            motor.critical_c(),
            [Some(155.0), Some(155.0), Some(155.0), Some(90.0)]
        );
        assert_eq!(motor.sensor_node(MotorSensor::Housing), HOUSING_NODE);
        // maxon's definitions: C = tau / R_th.
        let net = motor.network();
        assert!((net.capacity_j_per_k(0).unwrap() * 3.0 - 0.72 / 2.46).abs() < 1e-12);
        assert!((net.capacity_j_per_k(HOUSING_NODE).unwrap() - 188.0 / 32.0).abs() < 1e-12);
    }
}
