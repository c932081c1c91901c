//! Innovation gate, per-sensor verdicts, rejection counters and the recovery
//! trigger. Shared by the time-varying and the steady-state correction.

use nalgebra::allocator::Allocator;
use nalgebra::{DefaultAllocator, Dim, DimName, OMatrix, OVector, RealField};

use crate::sizes::Length;

/// 99.9 % quantile of the chi-square distribution with 1 degree of freedom:
/// the default gate threshold on `nu^2 / S` (a true reading exceeds it with
/// probability 0.001, i.e. a 3.29-sigma innovation).
pub const CHI2_1DOF_999: f64 = 10.828;

/// What one correction did with one sensor's reading.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorVerdict {
    /// No reading (`None`, NaN or infinite): the sensor was skipped.
    Missing,
    /// The reading passed the gate and was fused.
    Fused {
        /// Normalised innovation squared `nu^2 / S` (dimensionless, chi-square
        /// with 1 dof for a healthy sensor and a consistent filter).
        nis: f32,
    },
    /// The reading failed the gate (`nis > threshold`) and was not fused.
    Rejected {
        /// Normalised innovation squared `nu^2 / S`; infinite if it overflowed.
        nis: f32,
    },
}

impl SensorVerdict {
    /// True for [`SensorVerdict::Fused`].
    pub fn is_fused(&self) -> bool {
        matches!(self, Self::Fused { .. })
    }

    /// True for [`SensorVerdict::Rejected`].
    pub fn is_rejected(&self) -> bool {
        matches!(self, Self::Rejected { .. })
    }
}

/// The outcome of one correction (`update` or `update_steady`), for `P`
/// sensors (`Const<P>`: arrays; `Dyn`: vectors).
#[derive(Debug, Clone, PartialEq)]
pub struct UpdateReport<P: Length> {
    /// One verdict per sensor, in the order of the rows of `H`.
    pub verdicts: P::Array<SensorVerdict>,
    /// Sensors rejected at least `suspect_after` times in a row (after this
    /// correction): probably open, shorted, stuck or detached.
    pub suspect: P::Array<bool>,
    /// Every present reading was rejected for `recover_after` corrections in a
    /// row, so the covariance was inflated and this correction re-gated (see
    /// the module docs, "Recovery").
    pub recovered: bool,
}

impl<P: Length> Copy for UpdateReport<P>
where
    P::Array<SensorVerdict>: Copy,
    P::Array<bool>: Copy,
{
}

#[cfg(feature = "defmt")]
impl<const P: usize> defmt::Format for UpdateReport<nalgebra::Const<P>> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "UpdateReport {{ verdicts: {}, suspect: {}, recovered: {} }}",
            self.verdicts,
            self.suspect,
            self.recovered
        )
    }
}

impl<P: Length> UpdateReport<P> {
    /// Number of fused readings.
    pub fn fused(&self) -> usize {
        self.verdicts
            .as_ref()
            .iter()
            .filter(|v| v.is_fused())
            .count()
    }

    /// Number of rejected readings.
    pub fn rejected(&self) -> usize {
        self.verdicts
            .as_ref()
            .iter()
            .filter(|v| v.is_rejected())
            .count()
    }

    /// True if any sensor is suspect.
    pub fn any_suspect(&self) -> bool {
        self.suspect.as_ref().iter().any(|&s| s)
    }
}

/// Per-device gate memory: consecutive rejections per sensor and the number of
/// consecutive corrections in which every present reading was rejected.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GateCounters<P: Length> {
    /// Consecutive rejections of each sensor; reset when it is fused, kept
    /// when it is missing (a missing reading says nothing about the sensor).
    pub consecutive_rejections: P::Array<u16>,
    /// Consecutive corrections with at least one reading and all rejected.
    pub all_rejected_streak: u16,
}

impl<P: Length> Copy for GateCounters<P> where P::Array<u16>: Copy {}

#[cfg(feature = "defmt")]
impl<const P: usize> defmt::Format for GateCounters<nalgebra::Const<P>> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(
            f,
            "GateCounters {{ consecutive_rejections: {}, all_rejected_streak: {} }}",
            self.consecutive_rejections,
            self.all_rejected_streak
        )
    }
}

impl<P: Length> GateCounters<P> {
    /// All counters at zero, for `sensors` sensors.
    pub fn new(sensors: P) -> Self {
        Self {
            consecutive_rejections: sensors.filled(0),
            all_rejected_streak: 0,
        }
    }

    /// Counts one correction's verdicts; returns true when the all-rejected
    /// streak reaches `recover_after` (0 disables recovery), and then restarts
    /// the streak so recovery fires at most once per `recover_after`.
    pub(crate) fn record_gate(
        &mut self,
        verdicts: &P::Array<SensorVerdict>,
        recover_after: u16,
    ) -> bool {
        let verdicts = verdicts.as_ref();
        let present = verdicts
            .iter()
            .any(|v| !matches!(v, SensorVerdict::Missing));
        let all_rejected = present && verdicts.iter().all(|v| !v.is_fused());
        if !present {
            return false;
        }
        if !all_rejected {
            self.all_rejected_streak = 0;
            return false;
        }
        self.all_rejected_streak = self.all_rejected_streak.saturating_add(1);
        if recover_after != 0 && self.all_rejected_streak >= recover_after {
            self.all_rejected_streak = 0;
            return true;
        }
        false
    }

    /// Updates the per-sensor counters from the final verdicts and returns the
    /// suspect flags.
    pub(crate) fn record_sensors(
        &mut self,
        verdicts: &P::Array<SensorVerdict>,
        suspect_after: u16,
    ) -> P::Array<bool> {
        let mut suspect = P::filled_like(verdicts, false);
        for ((count, verdict), flag) in self
            .consecutive_rejections
            .as_mut()
            .iter_mut()
            .zip(verdicts.as_ref())
            .zip(suspect.as_mut().iter_mut())
        {
            match verdict {
                SensorVerdict::Fused { .. } => *count = 0,
                SensorVerdict::Rejected { .. } => *count = count.saturating_add(1),
                SensorVerdict::Missing => {}
            }
            *flag = suspect_after != 0 && *count >= suspect_after;
        }
        suspect
    }
}

impl<P: Length + DimName> Default for GateCounters<P> {
    fn default() -> Self {
        Self::new(P::name())
    }
}

/// Gate and recovery settings, part of the filter configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GatePolicy<T> {
    /// Reject a reading when `nu^2 / S` exceeds this (chi-square, 1 dof);
    /// `+inf` disables the gate.
    pub threshold: T,
    /// Flag a sensor suspect after this many consecutive rejections (0: never).
    pub suspect_after: u16,
    /// Inflate the covariance after this many consecutive corrections in which
    /// every present reading was rejected (0: never).
    pub recover_after: u16,
}

/// A reading usable for fusion: present and finite.
pub(crate) fn usable<T: RealField + Copy>(z: Option<T>) -> Option<T> {
    z.filter(|v| v.is_finite())
}

/// Normalised innovation squared as an `f32` for the report.
pub(crate) fn nis_f32<T: RealField + Copy>(nis: T) -> f32 {
    let wide: f64 = nalgebra::convert_unchecked(nis);
    wide as f32
}

/// Gates every present reading against the *prior* (before any of this
/// correction's readings is fused), so verdicts do not depend on sensor order
/// and match the steady-state gate exactly.
pub(crate) fn gate_all<T: RealField + Copy, N: Dim, P: Length>(
    x: &OVector<T, N>,
    cov: &OMatrix<T, N, N>,
    ht: &OMatrix<T, N, P>,
    r: &OVector<T, P>,
    z: &P::Array<Option<T>>,
    threshold: T,
) -> P::Array<SensorVerdict>
where
    DefaultAllocator: Allocator<N, N> + Allocator<N, P> + Allocator<N> + Allocator<P>,
{
    let mut verdicts = P::filled_like(z, SensorVerdict::Missing);
    for (j, (verdict, zj)) in verdicts.as_mut().iter_mut().zip(z.as_ref()).enumerate() {
        let Some(zj) = usable(*zj) else { continue };
        let h = ht.column(j);
        let s = h.dot(&(cov * h)) + r[j];
        let nu = zj - h.dot(x);
        *verdict = judge(nu, s, threshold);
    }
    verdicts
}

/// Verdict for one innovation `nu` with variance `s`.
pub(crate) fn judge<T: RealField + Copy>(nu: T, s: T, threshold: T) -> SensorVerdict {
    let nis = nu * nu / s;
    // A non-finite NIS (overflowing reading, degenerate S) is never fused.
    if !nis.is_finite() || !s.is_finite() || s <= T::zero() {
        return SensorVerdict::Rejected { nis: f32::INFINITY };
    }
    if nis > threshold {
        SensorVerdict::Rejected { nis: nis_f32(nis) }
    } else {
        SensorVerdict::Fused { nis: nis_f32(nis) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn judge_thresholds_and_degenerate_cases() {
        assert!(judge(1.0f64, 1.0, 10.83).is_fused());
        assert!(judge(3.2f64, 1.0, 10.83).is_fused()); // 10.24
        assert!(judge(3.3f64, 1.0, 10.83).is_rejected()); // 10.89
        assert!(judge(1e200f64, 1.0, 10.83).is_rejected());
        assert!(judge(1.0f64, 0.0, 10.83).is_rejected());
        assert!(judge(f64::NAN, 1.0, f64::INFINITY).is_rejected());
        // Disabled gate accepts any finite innovation.
        assert!(judge(1e100f64, 1.0, f64::INFINITY).is_fused());
    }

    #[test]
    fn counters_suspect_and_recovery_streak() {
        let rej = SensorVerdict::Rejected { nis: 99.0 };
        let ok = SensorVerdict::Fused { nis: 1.0 };
        let miss = SensorVerdict::Missing;
        let mut c = GateCounters::new(nalgebra::Const::<2>);
        // Sensor 1 rejected 3 times in a row, sensor 0 healthy: suspect, no recovery.
        for _ in 0..3 {
            assert!(!c.record_gate(&[ok, rej], 2));
            c.record_sensors(&[ok, rej], 3);
        }
        assert_eq!(c.record_sensors(&[miss, miss], 3), [false, true]);
        assert_eq!(c.consecutive_rejections, [0, 3]);
        // Fusing clears it.
        assert_eq!(c.record_sensors(&[ok, ok], 3), [false, false]);
        // All rejected twice -> recovery on the second; all-missing does not count.
        assert!(!c.record_gate(&[rej, rej], 2));
        assert!(!c.record_gate(&[miss, miss], 2));
        assert!(c.record_gate(&[rej, miss], 2));
        assert_eq!(c.all_rejected_streak, 0);
        // 0 disables recovery.
        for _ in 0..100 {
            assert!(!c.record_gate(&[rej, rej], 0));
        }
    }
}
