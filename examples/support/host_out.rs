//! `core::fmt` to the host's console over semihosting, for the firmware
//! examples whose replays write to any `core::fmt::Write` (the host tests
//! run the same replays into a `String`).

/// Writes each piece to the host as it comes.
pub struct Host;

impl core::fmt::Write for Host {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        cortex_m_semihosting::hprint!("{}", s);
        Ok(())
    }
}
