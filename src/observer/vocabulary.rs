//! The words every observer speaks: a timed sensor sample, what became of
//! it, and the capacity of the alarm event queue. No device owns them
//! (the grid, the Omnimagnet and the network observers, the consistency
//! screen and the protection cycle all use them).

use crate::sensors::{SensorFault, SensorResult};

/// Capacity of each observer's alarm event queue.
pub const EVENT_CAPACITY: usize = 16;

/// One sensor sample and when it was taken.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimedReading {
    /// The driver's result.
    pub result: SensorResult,
    /// Sample time on the tick's microsecond clock \[us\] (wrapping).
    pub sampled_at_us: u32,
}

impl TimedReading {
    /// The reading \[degC\] if it can be fused at `now_us` \[us\]: not a
    /// fault, not older than `max_age_us` \[us\], finite; otherwise what
    /// to report. Shared by the observers' corrections.
    pub(crate) fn sample_c(&self, now_us: u32, max_age_us: u32) -> Result<f32, SensorStatus> {
        match self.result {
            Err(fault) => Err(SensorStatus::Fault(fault)),
            Ok(r) => {
                let age_us = now_us.wrapping_sub(self.sampled_at_us);
                if age_us > max_age_us {
                    Err(SensorStatus::TooOld { age_us })
                } else if !r.temp_c.is_finite() {
                    Err(SensorStatus::Fault(SensorFault::NotFinite))
                } else {
                    Ok(r.temp_c)
                }
            }
        }
    }
}

/// What happened to one sensor's sample this tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorStatus {
    /// No reading arrived.
    #[default]
    NoReading,
    /// Fused, with its normalised innovation squared (dimensionless).
    Fused {
        /// `nu^2 / S`.
        nis: f32,
    },
    /// Refused by the innovation gate.
    Rejected {
        /// `nu^2 / S`.
        nis: f32,
    },
    /// The sensor reported a fault; not fused.
    Fault(SensorFault),
    /// Older than `max_reading_age_us`; not fused.
    TooOld {
        /// Its age \[us\].
        age_us: u32,
    },
    /// Colder than the physics allows: below the band of the observer's
    /// unfused shadow model (see the network observer's "Sensors against
    /// the physics"); not fused.
    ColderThanPhysics {
        /// How far below the band's lower edge \[K\].
        below_k: f32,
    },
    /// Silent: no reading (not even a fault) for more than two correction
    /// periods; a dropout (a cable, a driver, a bus).
    Silent {
        /// Since the last reading \[ms\].
        for_ms: u32,
    },
    /// Stuck: the reading has not moved while the shadow model at its node
    /// moved by more than the stuck threshold within the stuck window, or
    /// by more than the threshold plus the band's share of the rise since
    /// the reading last changed; not fused until it moves.
    Stuck {
        /// How far the shadow moved since the reading last changed or
        /// within the window, the larger \[K\].
        model_moved_k: f32,
    },
}
