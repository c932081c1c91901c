//! Deterministic instruction counts on QEMU, and flash/RAM figures, shared
//! by the firmware examples (`#[path]`-included, not an example itself).
//!
//! Under `qemu-system-arm -icount shift=N` every executed instruction
//! advances the virtual clock by `2^N` ns, and SysTick on the core clock
//! counts that clock, so a SysTick interval is proportional to the number of
//! instructions executed, independent of the host's speed. The ratio is
//! calibrated at boot with a block of 1000 `nop`s (minus an empty call), so
//! the figures are instructions, not ticks. SysTick is 24 bits: at
//! `shift=7` (about 1 600 SysTick counts per 1 000 instructions) it wraps
//! after about 10 million instructions, far beyond any measured span, and
//! the modular difference of two readings is exact below that.

use core::ptr::addr_of;
use cortex_m::peripheral::{syst::SystClkSource, SYST};

const RELOAD: u32 = 0x00FF_FFFF;

/// A calibrated instruction meter on SysTick.
pub struct Meter {
    overhead_ticks: u32,
    ticks_per_1000: u32,
}

#[inline(never)]
fn nops_1000() {
    // SAFETY: `nop` has no effect on memory, registers or flags.
    unsafe { core::arch::asm!(".rept 1000", "nop", ".endr", options(nomem, nostack)) }
}

#[inline(never)]
fn empty() {
    core::hint::black_box(());
}

#[inline(always)]
fn now() -> u32 {
    SYST::get_current()
}

impl Meter {
    /// Starts SysTick on the core clock and calibrates.
    pub fn new(syst: &mut SYST) -> Self {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(RELOAD);
        syst.clear_current();
        syst.enable_counter();
        let mut meter = Self {
            overhead_ticks: 0,
            ticks_per_1000: 1,
        };
        let (_, empty_ticks) = meter.raw(empty);
        let (_, nop_ticks) = meter.raw(nops_1000);
        meter.overhead_ticks = empty_ticks;
        meter.ticks_per_1000 = nop_ticks.saturating_sub(empty_ticks).max(1);
        meter
    }

    fn raw<R>(&self, f: impl FnOnce() -> R) -> (R, u32) {
        let start = now();
        let r = f();
        let end = now();
        (r, start.wrapping_sub(end) & RELOAD)
    }

    /// Runs `f` and returns its result and the instructions it executed.
    pub fn measure<R>(&self, f: impl FnOnce() -> R) -> (R, u32) {
        let (r, ticks) = self.raw(f);
        let net = ticks.saturating_sub(self.overhead_ticks) as u64;
        (r, (net * 1000 / self.ticks_per_1000 as u64) as u32)
    }
}

/// Mean and worst of a series of counts.
#[derive(Default, Clone, Copy)]
pub struct Stats {
    count: u32,
    sum: u64,
    worst: u32,
}

impl Stats {
    /// Adds one count.
    pub fn add(&mut self, value: u32) {
        self.count += 1;
        self.sum += value as u64;
        self.worst = self.worst.max(value);
    }
    /// The mean (0 when empty).
    pub fn mean(&self) -> u32 {
        (self.sum / self.count.max(1) as u64) as u32
    }
    /// The largest.
    pub fn worst(&self) -> u32 {
        self.worst
    }
    /// How many.
    pub fn count(&self) -> u32 {
        self.count
    }
    /// Both series as one.
    // Only the examples that split their ticks.
    #[allow(dead_code)]
    pub fn and(&self, other: &Stats) -> Stats {
        Stats {
            count: self.count + other.count,
            sum: self.sum + other.sum,
            worst: self.worst.max(other.worst),
        }
    }
}

/// Where a tick's instructions go, by kind: the ticks that fuse a reading,
/// and the others, those with a model step and those between steps (a
/// protection stage, the shadow's waiting block, or nothing: the cheapest
/// of them is the tick's fixed cost).
#[derive(Default, Clone, Copy)]
// Not every example that includes this file splits its ticks.
#[allow(dead_code)]
pub struct Split {
    /// The ticks that fused a reading.
    pub corrected: Stats,
    /// Of the others, those that took a model step.
    pub stepped: Stats,
    /// Of the others, those without a model step (a protection stage, a
    /// waiting block, or nothing).
    pub between: Stats,
    /// The cheapest of the others.
    pub least: u32,
}

#[allow(dead_code)]
impl Split {
    /// Adds one tick's count: a tick that brought a reading, or one that
    /// took `steps` model steps.
    pub fn add(&mut self, value: u32, corrected: bool, steps: u32) {
        if corrected {
            self.corrected.add(value);
        } else {
            if steps > 0 {
                self.stepped.add(value);
            } else {
                self.between.add(value);
            }
            let first = self.stepped.count() + self.between.count() == 1;
            self.least = if first { value } else { self.least.min(value) };
        }
    }

    /// Prints the split as a `cost:` line.
    pub fn print(&self) {
        let plain = self.stepped.and(&self.between);
        cortex_m_semihosting::hprintln!(
            "cost: split: cheapest tick {} instructions; ticks without a reading mean {} worst {} (with a model step mean {} worst {}, without one mean {} worst {}); with a reading mean {} worst {}",
            self.least,
            plain.mean(),
            plain.worst(),
            self.stepped.mean(),
            self.stepped.worst(),
            self.between.mean(),
            self.between.worst(),
            self.corrected.mean(),
            self.corrected.worst()
        );
    }
}

extern "C" {
    static __erodata: u8;
    static __sdata: u8;
    static __edata: u8;
    static __ebss: u8;
    static _stack_start: u8;
}

const PAINT: u32 = 0xA5A5_A5A5;

fn symbol(s: *const u8) -> usize {
    s as usize
}

/// Flash bytes (vector table, code and read-only data from address 0, and
/// the initial values of `.data`) and static RAM bytes (`.data` + `.bss`).
pub fn image_sizes() -> (usize, usize) {
    // Only the addresses of the linker's symbols are taken, never their
    // contents, which needs no `unsafe`.
    let (erodata, sdata, edata, ebss) = (
        symbol(addr_of!(__erodata)),
        symbol(addr_of!(__sdata)),
        symbol(addr_of!(__edata)),
        symbol(addr_of!(__ebss)),
    );
    (erodata + (edata - sdata), ebss - sdata)
}

fn stack_region() -> (usize, usize) {
    (symbol(addr_of!(__ebss)), symbol(addr_of!(_stack_start)))
}

/// Fills the unused stack (from the end of `.bss` to 256 bytes below the
/// present stack pointer) with a pattern, for [`stack_peak`].
#[inline(never)]
pub fn paint_stack() {
    let (bottom, _) = stack_region();
    let limit = cortex_m::register::msp::read() as usize - 256;
    let mut at = (bottom + 3) & !3;
    while at < limit {
        // SAFETY: [bottom, limit) lies between the end of the statics and
        // below this function's frame: memory no one uses yet. Aligned.
        unsafe { core::ptr::write_volatile(at as *mut u32, PAINT) };
        at += 4;
    }
}

/// The deepest stack use since [`paint_stack`] \[bytes\]: the distance from
/// the top of RAM to the lowest word that no longer holds the pattern.
pub fn stack_peak() -> usize {
    let (bottom, top) = stack_region();
    let mut at = (bottom + 3) & !3;
    // SAFETY: reads of RAM between the statics and the stack top, aligned.
    while at < top && unsafe { core::ptr::read_volatile(at as *const u32) } == PAINT {
        at += 4;
    }
    top - at
}
