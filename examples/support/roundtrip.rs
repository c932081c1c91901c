//! The codegen round trip's replay, shared by the firmware
//! (`examples/network_roundtrip.rs`, in QEMU) and the host
//! (`host-tests/tests/codegen_round_trip.rs`): the same code, the same
//! generated observer (`crate::model`, from `coil-thermal codegen`), the same
//! recorded trace, so the two print the same lines to the bit.
//!
//! The trace is `host-tests/traces/drive-3node.csv` (1 s rows: `time_s`,
//! `current` \[A\], `ambient` \[degC\], and two bench thermocouples,
//! `winding_tc` and `housing_tc` \[degC\]). The observer runs at 1 ms ticks:
//! the row's current and ambient held for the second, the housing
//! thermocouple fused once a second (its sample time is the second's
//! start); the winding thermocouple is *not* given to the observer: it is
//! what the estimate of the unmeasured winding is scored against.

use core::fmt::Write;

use crate::model;

#[path = "second.rs"]
mod second;

/// The recorded trace.
pub const TRACE_CSV: &str = include_str!("../../host-tests/traces/drive-3node.csv");
/// Seconds of the trace replayed.
pub const SECONDS: u32 = 3600;
/// A line every this many seconds.
pub const PRINT_EVERY_S: u32 = 300;

/// What the whole run showed.
#[derive(Debug, Default, Clone, Copy)]
pub struct Summary {
    /// FNV-1a over every tick's published temperatures, upper bounds and
    /// limits (their bits).
    pub checksum: u32,
    /// Largest `|winding estimate - winding_tc|` over the printed seconds
    /// after the first minute \[K\].
    pub worst_winding_error_k: f32,
    /// Ticks with a correction.
    pub corrections: u32,
}

fn alarm_word(a: &coil_thermal::protect::alarm::AlarmStatus) -> &'static str {
    if a.shutdown {
        "SHUTDOWN"
    } else if a.warning {
        "warning"
    } else if a.predictive {
        "predictive"
    } else {
        "clear"
    }
}

/// One trace row: (current \[A\], ambient \[degC\], winding_tc, housing_tc
/// \[degC\]).
fn row(line: &str) -> Option<(f32, f32, f32, f32)> {
    let mut fields = line
        .split(',')
        .skip(1)
        .map(|f| f.trim().parse::<f32>().ok());
    Some((
        fields.next()??,
        fields.next()??,
        fields.next()??,
        fields.next()??,
    ))
}

/// Replays [`SECONDS`] of the trace through `observer`, each tick run by
/// `tick` (the firmware counts its instructions there), printing to `out`.
///
/// # Errors
/// A trace row that does not parse, or a failed write.
pub fn replay<W: Write>(
    observer: &model::Observer,
    out: &mut W,
    mut tick: impl FnMut(&mut dyn FnMut() -> u32),
) -> Result<Summary, &'static str> {
    let mut state = model::initial_state(observer, 22.0);
    let mut summary = Summary {
        checksum: second::START,
        ..Summary::default()
    };
    let mut now_us: u32 = 0;
    for (second, line) in TRACE_CSV.lines().skip(1).take(SECONDS as usize).enumerate() {
        let (current_a, ambient_c, winding_tc, housing_tc) = row(line).ok_or("trace row")?;
        summary.corrections += second::run(
            observer,
            &mut state,
            [current_a],
            [ambient_c],
            [Some(housing_tc)],
            &mut now_us,
            &mut summary.checksum,
            &mut tick,
        )?;
        let t_s = second as u32 + 1;
        let o = state.outputs();
        if t_s >= 60 {
            let error = (o.temps_c[0] - winding_tc).abs();
            summary.worst_winding_error_k = summary.worst_winding_error_k.max(error);
        }
        if t_s.is_multiple_of(PRINT_EVERY_S) {
            let ttl = o.time_to_limit_s[0].unwrap_or(f32::INFINITY);
            writeln!(
                out,
                "t={t_s:4} s  I={current_a:.1} A  est {:.3} {:.3} {:.3} degC  winding_tc {winding_tc:.3}  upper {:.3}  limit {:.3} A  ttl {ttl:.0} s  alarm {}",
                o.temps_c[0],
                o.temps_c[1],
                o.temps_c[2],
                o.upper_c[0],
                o.limits[0].current_a,
                alarm_word(&o.alarm),
            )
            .map_err(|_| "write")?;
        }
    }
    writeln!(
        out,
        "replayed {SECONDS} s at 1 ms: {} corrections, worst |winding - winding_tc| after 60 s {:.3} K, checksum {:08x}",
        summary.corrections, summary.worst_winding_error_k, summary.checksum
    )
    .map_err(|_| "write")?;
    Ok(summary)
}
