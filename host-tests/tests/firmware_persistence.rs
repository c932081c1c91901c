//! The RTIC example's persistence on the host: its two-slot record store
//! (`examples/rtic-stm32f4/src/persist.rs`) on the simulated NOR flash
//! (`examples/support/sim_flash.rs`), through power lost anywhere in a
//! save; and README's copy of that firmware and of what it prints in QEMU.

use std::cell::Cell;

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

#[path = "../../examples/rtic-stm32f4/src/model.rs"]
mod model;

// The save period and the age are the firmware's only.
#[allow(dead_code)]
#[path = "../../examples/rtic-stm32f4/src/persist.rs"]
mod persist;

#[path = "../../examples/support/sim_flash.rs"]
mod sim_flash;

use model::SNAPSHOT_LEN;
use persist::{Saved, Store};
use sim_flash::SimFlash;

/// A snapshot whose every byte is `fill`.
fn snapshot(fill: u8) -> [u8; SNAPSHOT_LEN] {
    [fill; SNAPSHOT_LEN]
}

#[test]
fn the_store_keeps_the_newest_record_through_power_cycles() {
    let mut mem = [0xFFu8; 2 * SimFlash::PAGE];
    let mut store = Store::new(SimFlash::new(&mut mem).unwrap());
    assert_eq!(store.load(), None, "an erased flash holds no record");
    store.save(&snapshot(1), Saved::Periodic).unwrap();
    let mut store = Store::new(SimFlash::new(&mut mem).unwrap());
    assert_eq!(store.load(), Some((snapshot(1), Saved::Periodic)));
    // Many saves, each after a power cycle or not.
    for k in 2..40u8 {
        let saved = if k % 3 == 0 {
            Saved::PowerOff
        } else {
            Saved::Periodic
        };
        store.save(&snapshot(k), saved).unwrap();
        if k % 2 == 0 {
            store = Store::new(SimFlash::new(&mut mem).unwrap());
            assert_eq!(store.load(), Some((snapshot(k), saved)), "save {k}");
        }
    }
    // The slot the next save writes is erased already.
    let written = mem
        .chunks(SimFlash::PAGE)
        .filter(|p| p.iter().any(|b| *b != 0xFF));
    assert_eq!(written.count(), 1);
}

/// A flash whose power fails after `budget` more byte operations (a byte
/// erased or programmed): the operation in progress stops there, as far
/// as it got, and every later one fails.
struct Failing<'a> {
    flash: SimFlash<'a>,
    budget: &'a Cell<usize>,
}

#[derive(Debug)]
struct PowerLost;

impl NorFlashError for PowerLost {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::Other
    }
}

impl ErrorType for Failing<'_> {
    type Error = PowerLost;
}

impl ReadNorFlash for Failing<'_> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), PowerLost> {
        self.flash.read(offset, bytes).map_err(|_| PowerLost)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl NorFlash for Failing<'_> {
    const WRITE_SIZE: usize = SimFlash::WRITE_SIZE;
    const ERASE_SIZE: usize = SimFlash::ERASE_SIZE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), PowerLost> {
        // A page erased in part: its first bytes are 0xFF, the rest as
        // they were (a real one is undefined: the CRC has to tell).
        let done = (to - from).min(self.budget.get() as u32);
        self.budget.set(self.budget.get() - done as usize);
        let mut page = vec![0u8; (to - from) as usize];
        self.flash.read(from, &mut page).map_err(|_| PowerLost)?;
        page[..done as usize].fill(0xFF);
        self.flash.erase(from, to).map_err(|_| PowerLost)?;
        self.flash.write(from, &page).map_err(|_| PowerLost)?;
        if done < to - from {
            return Err(PowerLost);
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), PowerLost> {
        let done = bytes.len().min(self.budget.get());
        self.budget.set(self.budget.get() - done);
        let mut part = vec![0xFFu8; bytes.len()];
        part[..done].copy_from_slice(&bytes[..done]);
        self.flash.write(offset, &part).map_err(|_| PowerLost)?;
        if done < bytes.len() {
            return Err(PowerLost);
        }
        Ok(())
    }
}

fn failing<'a>(mem: &'a mut [u8], power: &'a Cell<usize>) -> Failing<'a> {
    Failing {
        flash: SimFlash::new(mem).unwrap(),
        budget: power,
    }
}

#[test]
fn a_power_loss_anywhere_in_a_save_keeps_the_last_good_record() {
    // Records 1 and 2 stored; the save of 3 loses the power after every
    // byte operation in turn (the erase of its slot after a boot, the
    // write, the erase of the other slot), then the boot loads: record 2
    // until 3 is wholly written, record 3 after.
    let save_len = 2 * SimFlash::PAGE + persist::RECORD_LEN.next_multiple_of(8);
    let (mut last_good, mut newest) = (0, 0);
    for budget in 0..=save_len + 1 {
        for booted in [false, true] {
            let mut mem = [0xFFu8; 2 * SimFlash::PAGE];
            let power = Cell::new(usize::MAX);
            let mut store = Store::new(failing(&mut mem, &power));
            store.save(&snapshot(1), Saved::Periodic).unwrap();
            store.save(&snapshot(2), Saved::PowerOff).unwrap();
            let mut store = if booted {
                // The slot to write is then not known to be erased.
                let mut store = Store::new(failing(&mut mem, &power));
                store.load();
                store
            } else {
                store
            };
            power.set(budget);
            let _ = store.save(&snapshot(3), Saved::Periodic);
            let loaded = Store::new(SimFlash::new(&mut mem).unwrap()).load();
            match loaded {
                Some((s, Saved::PowerOff)) if s == snapshot(2) => last_good += 1,
                Some((s, Saved::Periodic)) if s == snapshot(3) => newest += 1,
                other => panic!("power lost after {budget} bytes, booted {booted}: {other:?}"),
            }
        }
    }
    println!("power lost at each of {} points: the last good record {last_good} times, the new one {newest}", 2 * (save_len + 2));
    assert!(last_good > 0 && newest > 0);
}

#[test]
fn the_simulated_flash_is_a_nor_flash() {
    let mut mem = [0u8; 2 * SimFlash::PAGE];
    assert!(SimFlash::new(&mut mem[..100]).is_none(), "not whole pages");
    let mut flash = SimFlash::new(&mut mem).unwrap();
    assert_eq!(flash.capacity(), 4096);
    let page = SimFlash::PAGE as u32;
    assert_eq!(flash.erase(0, 100), Err(NorFlashErrorKind::NotAligned));
    assert_eq!(
        flash.erase(page, 3 * page),
        Err(NorFlashErrorKind::OutOfBounds)
    );
    assert_eq!(flash.write(4, &[0; 8]), Err(NorFlashErrorKind::NotAligned));
    assert_eq!(flash.write(0, &[0; 5]), Err(NorFlashErrorKind::NotAligned));
    assert_eq!(
        flash.write(2 * page, &[0; 8]),
        Err(NorFlashErrorKind::OutOfBounds)
    );
    let mut buf = [0u8; 8];
    assert_eq!(
        flash.read(2 * page - 4, &mut buf),
        Err(NorFlashErrorKind::OutOfBounds)
    );
    // An erase sets its pages to 0xFF, and only them.
    flash.erase(page, 2 * page).unwrap();
    flash.read(page - 4, &mut buf).unwrap();
    assert_eq!(buf, [0, 0, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF]);
    // A write only clears bits: twice, the AND of both.
    flash.write(page, &[0xF0; 8]).unwrap();
    flash.write(page, &[0x3C; 8]).unwrap();
    flash.read(page, &mut buf).unwrap();
    assert_eq!(buf, [0x30; 8]);
}

fn read(path: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(path);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn the_readme_shows_the_rtic_firmware_and_what_it_prints() {
    let readme = read("README.md");
    let main = read("examples/rtic-stm32f4/src/main.rs");
    // The file less its module docs, as README shows it.
    let body: String = main
        .lines()
        .skip_while(|l| l.starts_with("//!"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(
        readme.contains(&format!("```rust,ignore\n{body}```")),
        "README's RTIC firmware is not examples/rtic-stm32f4/src/main.rs"
    );
    let expected = read("examples/rtic-stm32f4/qemu.expected");
    assert!(
        readme.contains(&format!("```text\n{expected}```")),
        "README's RTIC output is not examples/rtic-stm32f4/qemu.expected"
    );
}
