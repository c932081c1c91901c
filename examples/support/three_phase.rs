//! README's three-phase walkthrough, its last step: the observer generated
//! from `host-tests/models/three-phase-1tc-fitted.toml`
//! (`examples/generated/three_phase_1tc.rs`: three phases, a housing, one
//! housing thermocouple, no `bias_sources`) over the held-out bench
//! recording `host-tests/traces/three-phase-validation.csv`, shared by the
//! firmware (`examples/three_phase_qemu.rs`, in QEMU) and the host
//! (`host-tests/tests/three_phase_walkthrough.rs`), which must print the
//! same lines to the bit.
//!
//! The recording has 1 s rows: `time_s`, the phase currents `ia`, `ib`,
//! `ic` \[A RMS\], `ambient` \[degC\], a bench thermocouple in each phase
//! (`a_tc`, `b_tc`, `c_tc`) and the housing's (`housing_tc`). The observer
//! runs at 1 ms: the row's currents and ambient held for the second, the
//! housing thermocouple fused once a second; the phase thermocouples are
//! what its estimates of the phases it never sees are scored against.

use core::fmt::Write;

use crate::model;

#[path = "second.rs"]
mod second;

/// The held-out recording.
pub const TRACE_CSV: &str = include_str!("../../host-tests/traces/three-phase-validation.csv");
/// Seconds replayed: the whole recording.
pub const SECONDS: u32 = 3600;
/// A line every this many seconds.
pub const PRINT_EVERY_S: u32 = 300;

/// What the whole run showed.
#[derive(Debug, Default, Clone, Copy)]
pub struct Summary {
    /// FNV-1a over every tick's published temperatures, upper bounds and
    /// limits (their bits).
    pub checksum: u32,
    /// Largest `|phase estimate - phase thermocouple|` of any phase over
    /// the seconds after the first minute \[K\].
    pub worst_phase_error_k: f32,
    /// Largest `phase thermocouple - upper bound` of any phase \[K\]
    /// (below zero: the bound the protection acts on was never cold).
    pub worst_cold_miss_k: f32,
}

/// One row: the phase currents \[A\], the ambient, the phase
/// thermocouples and the housing's \[degC\].
fn row(line: &str) -> Option<([f32; 3], f32, [f32; 3], f32)> {
    let mut f = line
        .split(',')
        .skip(1)
        .map(|v| v.trim().parse::<f32>().ok());
    let mut next = || f.next().flatten();
    Some((
        [next()?, next()?, next()?],
        next()?,
        [next()?, next()?, next()?],
        next()?,
    ))
}

/// Replays [`SECONDS`] of the recording through `observer`, each tick run
/// by `tick` (the firmware counts its instructions there), printing to
/// `out`.
///
/// # Errors
/// A row that does not parse, or a failed write.
pub fn replay<W: Write>(
    observer: &model::Observer,
    out: &mut W,
    mut tick: impl FnMut(&mut dyn FnMut() -> u32),
) -> Result<Summary, &'static str> {
    let first = TRACE_CSV.lines().nth(1).and_then(row).ok_or("trace row")?;
    // Known cold at the start (the bench's first row): every node at the
    // ambient.
    let mut state = model::initial_state(observer, first.1);
    let mut summary = Summary {
        checksum: second::START,
        worst_cold_miss_k: f32::NEG_INFINITY,
        ..Summary::default()
    };
    let mut now_us: u32 = 0;
    for (second, line) in TRACE_CSV.lines().skip(1).take(SECONDS as usize).enumerate() {
        let (phase_a, ambient_c, phase_tc, housing_tc) = row(line).ok_or("trace row")?;
        second::run(
            observer,
            &mut state,
            model::source_currents_a(&phase_a, &[]),
            [ambient_c],
            [Some(housing_tc)],
            &mut now_us,
            &mut summary.checksum,
            &mut tick,
        )?;
        let t_s = second as u32 + 1;
        let o = state.outputs();
        for (p, tc) in phase_tc.iter().enumerate() {
            if t_s >= 60 {
                let error = (o.temps_c[p] - tc).abs();
                summary.worst_phase_error_k = summary.worst_phase_error_k.max(error);
            }
            summary.worst_cold_miss_k = summary.worst_cold_miss_k.max(tc - o.upper_c[p]);
        }
        if t_s.is_multiple_of(PRINT_EVERY_S) {
            let limits = model::input_limits_a(&o.limits);
            writeln!(
                out,
                "t={t_s:4} s  I={:.1}/{:.1}/{:.1} A  phases {:.2} {:.2} {:.2} degC (tc {:.2} {:.2} {:.2}, upper {:.2} {:.2} {:.2})  housing {:.2}  limit {:.2} A",
                phase_a[0],
                phase_a[1],
                phase_a[2],
                o.temps_c[0],
                o.temps_c[1],
                o.temps_c[2],
                phase_tc[0],
                phase_tc[1],
                phase_tc[2],
                o.upper_c[0],
                o.upper_c[1],
                o.upper_c[2],
                o.temps_c[3],
                limits[0].min(limits[1]).min(limits[2]),
            )
            .map_err(|_| "write")?;
        }
    }
    writeln!(
        out,
        "replayed {SECONDS} s at 1 ms: worst |phase - its thermocouple| after 60 s {:.3} K, truth above the upper bound by at most {:.3} K, checksum {:08x}",
        summary.worst_phase_error_k, summary.worst_cold_miss_k, summary.checksum
    )
    .map_err(|_| "write")?;
    Ok(summary)
}
