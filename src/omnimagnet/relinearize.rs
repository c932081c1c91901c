//! Re-linearisation as the device heats, in bounded slices.
//!
//! `A`, `B`, `G` depend on temperature (copper `c_p`, `k`, `R`, `h`, the
//! radiation `T^3`), so a model linearised cold drifts as the coils heat.
//! [`Relinearizer::poll`] is meant for a lower-priority loop than the 1 ms
//! tick: each call does at most one slice of work, and the active
//! [`Linearization`] is replaced only when a new one is complete.
//!
//! | slice | work (N = 16) |
//! |---|---|
//! | idle check | 17 subtractions and compares |
//! | build | conductances (33 contacts, ~20 `pow`), network, `A`, `||A h||_1` |
//! | exp | one [`SlicedExpm::slice`]: at most 2 products `N x N x N` (8192 MACs) |
//! | finish | `Phi B`, `Phi G`, `Phi d` (1280 MACs), swap |
//!
//! One cycle is `1 + 1 + 8 + s + 1` slices, `s` the number of squarings
//! (`||A dt||_1 <= 2^s / 4`; 0 at dt = 1 ms, at most 60). The exponential is
//! [`crate::discretize`]'s own, run slice by slice, so the result is
//! bit-for-bit the one-shot [`Omnimagnet::linearize`].

use super::data::{NODES, SOLENOIDS};
use super::linearize::Linearization;
use super::Omnimagnet;
use crate::discretize::{Discrete, SlicedExpm};
use crate::error::BuildError;
use crate::network::ConstStateSpace;
use nalgebra::SMatrix;

pub use crate::discretize::MATMULS_PER_SLICE;

type Square = SMatrix<f64, NODES, NODES>;

/// When to re-linearise, and the discrete step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelinearizeConfig {
    /// Re-linearise once any node is this far from the operating point \[K\].
    pub node_threshold_k: f64,
    /// Or once the ambient is this far from the operating ambient \[K\].
    pub ambient_threshold_k: f64,
    /// Discrete step of the produced model \[s\].
    pub dt_s: f64,
}

impl Default for RelinearizeConfig {
    /// 5 K on any node, 2 K on the ambient, 1 ms step.
    fn default() -> Self {
        Self {
            node_threshold_k: 5.0,
            ambient_threshold_k: 2.0,
            dt_s: 1e-3,
        }
    }
}

/// What one [`Relinearizer::poll`] did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RelinearizePoll {
    /// Nothing to do: the active model is close enough.
    Idle,
    /// A threshold was crossed; the operating point was captured.
    Started,
    /// One slice of an ongoing linearisation was done.
    Working,
    /// The new linearisation is complete and now active.
    Swapped,
    /// Building failed (non-finite operating point); the old model stays.
    Failed(BuildError),
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    Idle,
    Build,
    Exponential,
    Finish,
}

/// Working matrices of one linearisation in progress.
#[derive(Debug, Clone, PartialEq)]
struct Work {
    op_temps_c: [f64; NODES],
    op_ambient_c: f64,
    ss: ConstStateSpace<NODES, 1, SOLENOIDS>,
    expm: SlicedExpm<nalgebra::Const<NODES>>,
}

/// Keeps an active linearisation and replaces it, slice by slice, when the
/// device has moved away from its operating point. No allocation; about
/// 16.3 KiB (the geometry, the active model and five 16 x 16 work matrices).
#[derive(Debug, Clone, PartialEq)]
pub struct Relinearizer {
    model: Omnimagnet,
    config: RelinearizeConfig,
    active: Linearization,
    phase: Phase,
    work: Work,
    slices_this_cycle: usize,
}

impl Relinearizer {
    /// Linearises once at `temps_c`, `ambient_c` \[degC\] (one-shot,
    /// build time) and validates `config`.
    pub fn new(
        model: Omnimagnet,
        config: RelinearizeConfig,
        temps_c: &[f64; NODES],
        ambient_c: f64,
    ) -> Result<Self, BuildError> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(config.node_threshold_k) {
            return Err(BuildError::InvalidParameter {
                name: "node_threshold_k",
            });
        }
        if !positive(config.ambient_threshold_k) {
            return Err(BuildError::InvalidParameter {
                name: "ambient_threshold_k",
            });
        }
        let active = model.linearize(temps_c, ambient_c, config.dt_s)?;
        let work = Work {
            op_temps_c: *temps_c,
            op_ambient_c: ambient_c,
            ss: model.state_space(temps_c, ambient_c)?,
            expm: SlicedExpm::new(&Square::zeros(), config.dt_s)?,
        };
        Ok(Self {
            model,
            config,
            active,
            phase: Phase::Idle,
            work,
            slices_this_cycle: 0,
        })
    }

    /// The linearisation in use.
    pub fn active(&self) -> &Linearization {
        &self.active
    }

    /// `true` while a linearisation is in progress.
    pub fn is_working(&self) -> bool {
        self.phase != Phase::Idle
    }

    /// Slices done so far in the current (or last) cycle, the trigger
    /// included.
    pub fn slices_this_cycle(&self) -> usize {
        self.slices_this_cycle
    }

    /// `true` when `temps_c` or `ambient_c` \[degC\] is beyond a threshold
    /// from the active operating point (never for NaN inputs).
    pub fn needs_relinearization(&self, temps_c: &[f64; NODES], ambient_c: f64) -> bool {
        let moved = temps_c
            .iter()
            .zip(&self.active.op_temps_c)
            .any(|(t, op)| libm::fabs(t - op) > self.config.node_threshold_k);
        moved || libm::fabs(ambient_c - self.active.op_ambient_c) > self.config.ambient_threshold_k
    }

    /// Starts a linearisation at `temps_c`, `ambient_c` now, whatever the
    /// thresholds (abandons one in progress).
    pub fn request(&mut self, temps_c: &[f64; NODES], ambient_c: f64) {
        self.work.op_temps_c = *temps_c;
        self.work.op_ambient_c = ambient_c;
        self.phase = Phase::Build;
        self.slices_this_cycle = 1;
    }

    /// Does at most one slice of work (see the module table). `temps_c` and
    /// `ambient_c` \[degC\] are the current estimate; they are read only when
    /// idle, to decide whether to start.
    pub fn poll(&mut self, temps_c: &[f64; NODES], ambient_c: f64) -> RelinearizePoll {
        match self.phase {
            Phase::Idle => {
                if self.needs_relinearization(temps_c, ambient_c) {
                    self.request(temps_c, ambient_c);
                    RelinearizePoll::Started
                } else {
                    RelinearizePoll::Idle
                }
            }
            phase => {
                self.slices_this_cycle = self.slices_this_cycle.saturating_add(1);
                match self.slice(phase) {
                    Ok(Phase::Idle) => RelinearizePoll::Swapped,
                    Ok(_) => RelinearizePoll::Working,
                    Err(e) => {
                        self.phase = Phase::Idle;
                        RelinearizePoll::Failed(e)
                    }
                }
            }
        }
    }

    /// One slice; returns the phase it left.
    fn slice(&mut self, phase: Phase) -> Result<Phase, BuildError> {
        let w = &mut self.work;
        self.phase = match phase {
            Phase::Idle => Phase::Idle,
            Phase::Build => {
                w.ss = self.model.state_space(&w.op_temps_c, w.op_ambient_c)?;
                w.expm = SlicedExpm::new(&w.ss.a, self.config.dt_s)?;
                Phase::Exponential
            }
            Phase::Exponential => {
                if w.expm.slice() {
                    Phase::Finish
                } else {
                    Phase::Exponential
                }
            }
            Phase::Finish => {
                let (ad, phi) = w.expm.result();
                let bd_power = phi * w.ss.b_power;
                self.active = Linearization {
                    op_temps_c: w.op_temps_c,
                    op_ambient_c: w.op_ambient_c,
                    bd_current_squared: self.model.current_squared_input(&bd_power, &w.op_temps_c),
                    discrete: Discrete {
                        dt_s: self.config.dt_s,
                        ad,
                        bd_power,
                        gd_boundary: phi * w.ss.g_boundary,
                        dd: phi * w.ss.d,
                    },
                };
                Phase::Idle
            }
        };
        Ok(self.phase)
    }
}
