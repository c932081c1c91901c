//! Alarm events and the fixed-capacity queue that carries them to the caller.
//!
//! The alarm pushes one [`AlarmEvent`] per state change; the caller drains
//! them with [`EventQueue::pop`] outside the control loop (to a log, a
//! display, a supervisor).
//!
//! # Overflow policy: the newest event is dropped, and counted
//!
//! When the queue is full, an incoming event is dropped and
//! [`EventQueue::dropped`] is incremented. The queue therefore always holds an
//! unbroken run of events from the oldest undrained one on: the first fault in
//! a cascade, usually the one that explains the rest, survives. Nothing of the
//! *present* is lost by dropping the newest, because the alarm state itself
//! always reports which alarms are active; only the history is cut, and the
//! counter says by how much.

use heapless::Deque;

/// What happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EventKind {
    /// The element rose above its warning level (debounced).
    WarningRaised,
    /// The element fell below its warning level minus the hysteresis
    /// (debounced).
    WarningCleared,
    /// The element rose above its shutdown level (debounced); latched until
    /// [`Reset`](EventKind::Reset).
    ShutdownLatched,
    /// The predicted time to the alarm limit fell below the horizon
    /// (debounced).
    PredictiveRaised,
    /// The predicted time to the alarm limit rose above the horizon plus its
    /// hysteresis (debounced).
    PredictiveCleared,
    /// The element's temperature (or, with no element, the ambient) was not
    /// finite; the alarm holds its state for it.
    SensorInvalid,
    /// The element's temperature (or the ambient) is finite again.
    SensorValid,
    /// The latched shutdown was reset (no element).
    Reset,
    /// The observer's clock gave no elapsed time for its loss limit of
    /// ticks: the model is lost, and the shutdown was latched (no element;
    /// see [`crate::observer::clock`]).
    ClockFrozen,
}

/// One alarm event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AlarmEvent {
    /// The alarm tick count when it happened (the first tick is 1; a
    /// [`Reset`](EventKind::Reset) carries the count of the last tick).
    pub tick: u64,
    /// The element index, or `None` for the ambient sensor and for a reset.
    pub element: Option<usize>,
    /// What happened.
    pub kind: EventKind,
}

/// A fixed-capacity FIFO of [`AlarmEvent`]s with an overflow counter.
///
/// `CAP` must be at least 1 (checked at compile time).
#[derive(Debug, Clone)]
pub struct EventQueue<const CAP: usize> {
    queue: Deque<AlarmEvent, CAP>,
    dropped: u32,
}

impl<const CAP: usize> Default for EventQueue<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> EventQueue<CAP> {
    /// An empty queue (usable in a `static`).
    pub const fn new() -> Self {
        Self {
            queue: Deque::new(),
            dropped: 0,
        }
    }

    /// Appends an event. If the queue is full the event is dropped, counted
    /// in [`dropped`](Self::dropped), and handed back.
    ///
    /// # Errors
    /// The rejected event, when the queue is full.
    pub fn push(&mut self, event: AlarmEvent) -> Result<(), AlarmEvent> {
        self.queue.push_back(event).inspect_err(|_| {
            self.dropped = self.dropped.saturating_add(1);
        })
    }

    /// Removes and returns the oldest event.
    pub fn pop(&mut self) -> Option<AlarmEvent> {
        self.queue.pop_front()
    }

    /// Events waiting to be drained.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// `true` when no event is waiting.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// The capacity, `CAP`.
    pub const fn capacity(&self) -> usize {
        CAP
    }

    /// Events dropped because the queue was full, since the last
    /// [`take_dropped`](Self::take_dropped) (saturates at `u32::MAX`).
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// `true` if any event was dropped since the last
    /// [`take_dropped`](Self::take_dropped).
    pub fn overflowed(&self) -> bool {
        self.dropped > 0
    }

    /// Returns the dropped count and sets it back to zero (acknowledges the
    /// overflow).
    pub fn take_dropped(&mut self) -> u32 {
        core::mem::take(&mut self.dropped)
    }
}

// `heapless::Deque` has no `defmt::Format`, so log the summary by hand.
#[cfg(feature = "defmt")]
impl<const CAP: usize> defmt::Format for EventQueue<CAP> {
    fn format(&self, f: defmt::Formatter<'_>) {
        defmt::write!(
            f,
            "EventQueue {{ len: {}, capacity: {}, dropped: {} }}",
            self.len(),
            CAP,
            self.dropped
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn event(tick: u64) -> AlarmEvent {
        AlarmEvent {
            tick,
            element: Some((tick % 7) as usize),
            kind: EventKind::WarningRaised,
        }
    }

    #[test]
    fn fifo_order_and_newest_dropped() {
        let mut queue = EventQueue::<3>::new();
        for tick in 1..=5 {
            let result = queue.push(event(tick));
            assert_eq!(result.is_err(), tick > 3);
        }
        assert_eq!(queue.dropped(), 2);
        assert!(queue.overflowed());
        // The oldest three survive, in order.
        let ticks: [u64; 3] = core::array::from_fn(|_| queue.pop().map_or(0, |e| e.tick));
        assert_eq!(ticks, [1, 2, 3]);
        assert!(queue.pop().is_none());
        assert_eq!(queue.take_dropped(), 2);
        assert!(!queue.overflowed());
    }

    #[test]
    fn no_event_lost_under_interleaved_drain() {
        // A deterministic but irregular producer/consumer: every event raised
        // is either delivered or counted, never neither.
        let mut queue = EventQueue::<4>::new();
        let (mut raised, mut delivered, mut next_tick) = (0u32, 0u32, 1u64);
        let mut last_delivered_tick = 0;
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        for _ in 0..10_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            for _ in 0..(state % 5) {
                let _ = queue.push(event(next_tick));
                next_tick += 1;
                raised += 1;
            }
            for _ in 0..((state >> 8) % 4) {
                if let Some(e) = queue.pop() {
                    // FIFO: ticks delivered strictly increase.
                    assert!(e.tick > last_delivered_tick);
                    last_delivered_tick = e.tick;
                    delivered += 1;
                }
            }
        }
        while queue.pop().is_some() {
            delivered += 1;
        }
        assert!(
            queue.dropped() > 0,
            "the test must overflow to mean anything"
        );
        assert!(delivered > 0);
        assert_eq!(delivered + queue.dropped(), raised);
    }
}
