//! A NOR flash simulated in RAM, behind the `embedded-storage` traits a
//! flash driver implements (`ReadNorFlash`, `NorFlash`): the RTIC
//! example's non-volatile storage in QEMU, which models no flash
//! controller. A product uses its flash driver instead (the MCU's own
//! flash, or an SPI NOR).
//!
//! What a NOR flash does, and this one checks: an erase sets whole pages
//! to `0xFF`; a write only clears bits (a cell written twice holds the AND
//! of both); an erase range must be page-aligned and a write
//! double-word-aligned (the geometry of an STM32G4's or L4's own flash:
//! 2 KiB pages, 64-bit programming), and neither may leave the device.
//! A misuse returns the trait's `NorFlashErrorKind`.

use embedded_storage::nor_flash::{
    check_erase, check_read, check_write, ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash,
};

/// A NOR flash whose cells are the bytes of `mem` (a whole number of
/// pages), as they are: a flash keeps its contents through a power cycle.
pub struct SimFlash<'a> {
    mem: &'a mut [u8],
}

impl<'a> SimFlash<'a> {
    /// Bytes of a page, the erase unit.
    pub const PAGE: usize = 2048;

    /// The flash whose cells are `mem`; `None` unless `mem` is a whole
    /// number of pages.
    pub fn new(mem: &'a mut [u8]) -> Option<Self> {
        mem.len().is_multiple_of(Self::PAGE).then_some(Self { mem })
    }
}

impl ErrorType for SimFlash<'_> {
    type Error = NorFlashErrorKind;
}

impl ReadNorFlash for SimFlash<'_> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        check_read(self, offset, bytes.len())?;
        let from = offset as usize;
        let cells = self
            .mem
            .get(from..from + bytes.len())
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        bytes.copy_from_slice(cells);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl NorFlash for SimFlash<'_> {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = Self::PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        check_erase(self, from, to)?;
        self.mem
            .get_mut(from as usize..to as usize)
            .ok_or(NorFlashErrorKind::OutOfBounds)?
            .fill(0xFF);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        check_write(self, offset, bytes.len())?;
        let from = offset as usize;
        let cells = self
            .mem
            .get_mut(from..from + bytes.len())
            .ok_or(NorFlashErrorKind::OutOfBounds)?;
        // Programming only clears bits: an unerased cell keeps its zeros.
        for (cell, byte) in cells.iter_mut().zip(bytes) {
            *cell &= byte;
        }
        Ok(())
    }
}
