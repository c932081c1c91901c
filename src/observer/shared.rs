//! Sharing an observer's outputs and inputs between tasks.
//!
//! The control interrupt ticks the observer; a lower-priority task reads a
//! consistent copy of the outputs and hands in thermocouple readings that
//! arrive at their own pace. Both directions go through a
//! [`critical_section::Mutex`] around a [`Cell`]: the lock is held only for
//! the copy of a `Copy` value, never across a model step, so the interrupt's
//! latency grows by one `memcpy` at most.
//!
//! On a single-core Cortex-M the critical section masks interrupts
//! (`cortex-m`'s `critical-section-single-core` feature); on the host the
//! `std` implementation uses a global lock.

use core::cell::Cell;
use critical_section::Mutex;

/// The latest copy of a value published by one task for others to read.
#[derive(Debug)]
pub struct Shared<T: Copy> {
    value: Mutex<Cell<T>>,
}

impl<T: Copy> Shared<T> {
    /// A shared slot holding `initial`; `const`, so it can be a `static`.
    pub const fn new(initial: T) -> Self {
        Self {
            value: Mutex::new(Cell::new(initial)),
        }
    }

    /// Replaces the shared value (one copy under the lock).
    pub fn publish(&self, value: T) {
        critical_section::with(|cs| self.value.borrow(cs).set(value));
    }

    /// A consistent copy of the shared value (one copy under the lock).
    pub fn snapshot(&self) -> T {
        critical_section::with(|cs| self.value.borrow(cs).get())
    }
}

/// Readings handed from a slow task to the control interrupt, one slot per
/// sensor. A newer reading replaces an unread older one (the filter wants the
/// freshest); the number replaced is counted, never silent.
#[derive(Debug)]
pub struct Mailbox<T: Copy, const P: usize> {
    slots: Mutex<Cell<MailboxSlots<T, P>>>,
}

#[derive(Debug, Clone, Copy)]
struct MailboxSlots<T: Copy, const P: usize> {
    readings: [Option<T>; P],
    overwritten: u32,
}

impl<T: Copy, const P: usize> Mailbox<T, P> {
    /// An empty mailbox; `const`, so it can be a `static`.
    pub const fn new() -> Self {
        Self {
            slots: Mutex::new(Cell::new(MailboxSlots {
                readings: [None; P],
                overwritten: 0,
            })),
        }
    }

    /// Posts a reading for sensor `sensor`; `Err(reading)` if there is no
    /// such sensor. Replacing an unread reading is counted.
    pub fn post(&self, sensor: usize, reading: T) -> Result<(), T> {
        critical_section::with(|cs| {
            let cell = self.slots.borrow(cs);
            let mut slots = cell.get();
            let result = match slots.readings.get_mut(sensor) {
                Some(slot) => {
                    if slot.replace(reading).is_some() {
                        slots.overwritten = slots.overwritten.saturating_add(1);
                    }
                    Ok(())
                }
                None => Err(reading),
            };
            cell.set(slots);
            result
        })
    }

    /// Takes every waiting reading (leaving the mailbox empty) and the number
    /// of readings that were replaced unread since the last take.
    pub fn take_all(&self) -> ([Option<T>; P], u32) {
        critical_section::with(|cs| {
            let taken = self.slots.borrow(cs).replace(MailboxSlots {
                readings: [None; P],
                overwritten: 0,
            });
            (taken.readings, taken.overwritten)
        })
    }
}

impl<T: Copy, const P: usize> Default for Mailbox<T, P> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readers_see_whole_published_values() {
        static OUTPUTS: Shared<[u32; 64]> = Shared::new([0; 64]);
        let writer = std::thread::spawn(|| {
            for k in 1..=20_000u32 {
                OUTPUTS.publish([k; 64]);
            }
        });
        let mut last = 0;
        for _ in 0..20_000 {
            let copy = OUTPUTS.snapshot();
            // A torn copy would mix two publications.
            assert!(copy.iter().all(|v| *v == copy[0]));
            assert!(copy[0] >= last);
            last = copy[0];
        }
        writer.join().unwrap();
        assert_eq!(OUTPUTS.snapshot()[0], 20_000);
    }

    #[test]
    fn mailbox_keeps_the_freshest_and_counts_the_rest() {
        let mailbox: Mailbox<f32, 3> = Mailbox::new();
        assert_eq!(mailbox.post(0, 20.5), Ok(()));
        assert_eq!(mailbox.post(0, 21.0), Ok(()));
        assert_eq!(mailbox.post(2, 30.0), Ok(()));
        assert_eq!(mailbox.post(3, 1.0), Err(1.0));
        let (readings, overwritten) = mailbox.take_all();
        assert_eq!(readings, [Some(21.0), None, Some(30.0)]);
        assert_eq!(overwritten, 1);
        assert_eq!(mailbox.take_all(), ([None; 3], 0));
    }
}
