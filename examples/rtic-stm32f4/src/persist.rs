//! The observer's snapshots in non-volatile storage, through the
//! ecosystem's `embedded-storage` traits: any `NorFlash` (the MCU's own
//! flash, an SPI NOR; here `board.rs`'s simulated one).
//!
//! Two slots of whole erase units take the records in turn, and the one
//! the next save writes is erased after each save: a power loss in the
//! middle of a write (or of that erase) leaves the other slot's record,
//! the last good one, and the brown-out's save has only to program
//! [`RECORD_LEN`] bytes (no erase: a 16 KiB sector of an STM32F4 takes
//! hundreds of milliseconds to erase, more than a supply holds up).
//!
//! A record (little endian):
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | magic `b"CTPR"` |
//! | 4 | 4 | sequence number: the newest record wins (wrapping) |
//! | 8 | 1 | why it was saved: 0 periodic, 1 at the power-off ([`Saved`]) |
//! | 9 | 3 | zero |
//! | 12 | `SNAPSHOT_LEN` | the generated `save_snapshot`'s bytes |
//! | 12 + `SNAPSHOT_LEN` | 4 | CRC-32 of every byte before it |
//!
//! The CRC covers the header too: a torn write or a half-erased slot is no
//! record. The snapshot carries its own checks (its CRC, the model's
//! fingerprint, its age), made by the generated `restore_state`.

use crate::model::SNAPSHOT_LEN;
use coil_thermal::observer::snapshot::crc32;
use embedded_storage::nor_flash::NorFlash;

/// Save a snapshot every 10 s of 1 ms ticks, and at the brown-out
/// warning.
pub const SAVE_EVERY_TICKS: u32 = 10_000;
/// The oldest snapshot a clock may restore, and the longest off time a
/// restore without one considers \[s\].
pub const MAX_AGE_S: u32 = 3600;

const MAGIC: [u8; 4] = *b"CTPR";
const HEADER_LEN: usize = 12;
/// Bytes of a record: the header, the snapshot, the CRC.
pub const RECORD_LEN: usize = HEADER_LEN + SNAPSHOT_LEN + 4;
/// A record padded to any write size up to 32 bytes.
const BUF_LEN: usize = RECORD_LEN.next_multiple_of(32);

/// Why a snapshot was saved.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Saved {
    /// Every [`SAVE_EVERY_TICKS`]: the device may have run (and heated)
    /// for up to that long after it.
    Periodic,
    /// At the brown-out warning, the drive off: the state at the power-off.
    PowerOff,
}

/// The snapshots' two slots at the start of `flash`.
pub struct Store<F> {
    flash: F,
    /// The slot holding the newest record, and its sequence number.
    newest: Option<(u32, u32)>,
    /// Whether the slot the next save writes is known to be erased.
    next_erased: bool,
}

impl<F: NorFlash> Store<F> {
    /// A slot: the record rounded up to whole erase units.
    const SLOT_LEN: u32 = RECORD_LEN.next_multiple_of(F::ERASE_SIZE) as u32;

    /// The store in `flash` (two slots from offset 0).
    pub fn new(flash: F) -> Self {
        const { assert!(RECORD_LEN.next_multiple_of(F::WRITE_SIZE) <= BUF_LEN) };
        Self {
            flash,
            newest: None,
            next_erased: false,
        }
    }

    /// The newest intact record's snapshot, and why it was saved; `None`
    /// when neither slot holds one (the first boot, or both lost).
    pub fn load(&mut self) -> Option<([u8; SNAPSHOT_LEN], Saved)> {
        let mut found: Option<(u32, u32, [u8; SNAPSHOT_LEN], Saved)> = None;
        for slot in 0..2 {
            let mut buf = [0u8; BUF_LEN];
            let len = RECORD_LEN.next_multiple_of(F::READ_SIZE);
            let read = self.flash.read(slot * Self::SLOT_LEN, &mut buf[..len]);
            let Some((sequence, snapshot, saved)) = read.ok().and_then(|()| parse(&buf)) else {
                continue;
            };
            // Wrapping: the newer is less than half the range ahead.
            if found.is_none_or(|(_, newest, ..)| (sequence.wrapping_sub(newest) as i32) > 0) {
                found = Some((slot, sequence, snapshot, saved));
            }
        }
        self.newest = found.map(|(slot, sequence, ..)| (slot, sequence));
        self.next_erased = false;
        found.map(|(_, _, snapshot, saved)| (snapshot, saved))
    }

    /// Stores `snapshot` in the slot that does not hold the newest record,
    /// then erases the other one for the next save.
    ///
    /// # Errors
    /// The flash's. A failed erase or write leaves the newest record
    /// stored before the newest; a failed erase after the write leaves
    /// the next save to erase its slot first.
    pub fn save(&mut self, snapshot: &[u8; SNAPSHOT_LEN], saved: Saved) -> Result<(), F::Error> {
        let (slot, sequence) = match self.newest {
            Some((slot, sequence)) => (1 - slot, sequence.wrapping_add(1)),
            None => (0, 0),
        };
        let at = slot * Self::SLOT_LEN;
        if !self.next_erased {
            self.flash.erase(at, at + Self::SLOT_LEN)?;
        }
        self.next_erased = false;
        let mut buf = [0xFFu8; BUF_LEN];
        buf[..4].copy_from_slice(&MAGIC);
        buf[4..8].copy_from_slice(&sequence.to_le_bytes());
        buf[8..12].copy_from_slice(&[saved as u8, 0, 0, 0]);
        buf[HEADER_LEN..HEADER_LEN + SNAPSHOT_LEN].copy_from_slice(snapshot);
        let crc = crc32(&buf[..HEADER_LEN + SNAPSHOT_LEN]);
        buf[HEADER_LEN + SNAPSHOT_LEN..RECORD_LEN].copy_from_slice(&crc.to_le_bytes());
        let len = RECORD_LEN.next_multiple_of(F::WRITE_SIZE);
        self.flash.write(at, &buf[..len])?;
        self.newest = Some((slot, sequence));
        let other = (1 - slot) * Self::SLOT_LEN;
        self.flash.erase(other, other + Self::SLOT_LEN)?;
        self.next_erased = true;
        Ok(())
    }
}

/// A record's sequence number, snapshot and why it was saved, if `buf`
/// holds an intact one.
fn parse(buf: &[u8; BUF_LEN]) -> Option<(u32, [u8; SNAPSHOT_LEN], Saved)> {
    let (body, crc) = buf[..RECORD_LEN].split_at(HEADER_LEN + SNAPSHOT_LEN);
    if body[..4] != MAGIC || crc32(body).to_le_bytes() != crc {
        return None;
    }
    let saved = match body[8..12] {
        [0, 0, 0, 0] => Saved::Periodic,
        [1, 0, 0, 0] => Saved::PowerOff,
        _ => return None,
    };
    let sequence = u32::from_le_bytes([body[4], body[5], body[6], body[7]]);
    let mut snapshot = [0u8; SNAPSHOT_LEN];
    snapshot.copy_from_slice(&body[HEADER_LEN..]);
    Some((sequence, snapshot, saved))
}
