//! The real motor's generated observer on a drive of load and speed steps,
//! shared by the firmware (`examples/motor_qemu.rs`, in QEMU) and the host
//! (`host-tests/tests/replay_firmware_filter.rs`): the same code, the same
//! generated module (`crate::hust_motor`, `coil-thermal codegen` of
//! `host-tests/models/hust_motor_slot_fitted.toml`), so the two print the
//! same lines to the bit, and the host holds the estimates against
//! `coil-thermal replay` of the same drive.
//!
//! The drive: a minute each of standstill, 300 A at 3000 rpm, 150 A at
//! 500 rpm, 80 A at 4000 rpm and 250 A at 1500 rpm, coolant and ambient at
//! 25 degC. Two observers run in lockstep at 1 ms ticks, each second's
//! current and speed made into the observer's currents by the generated
//! `source_currents_a` (the copper's AC factor, the iron and magnet
//! losses): one open loop, and one fusing an end-winding thermocouple that
//! reads the open-loop end winding plus 0.5 K a minute (a heat the model
//! lacks), once a second. The limit printed is the drive's, on `|i_s|`
//! (the generated `input_limits_a`).

use core::fmt::Write;

use coil_thermal::observer::TimedReading;
use coil_thermal::Reading;

use crate::hust_motor as model;

#[path = "checksum.rs"]
mod checksum;

/// Seconds of the drive.
pub const SECONDS: u32 = 300;
/// Coolant and ambient \[degC\].
pub const AMBIENT_C: f32 = 25.0;
/// How fast the thermocouple leaves the open-loop end winding \[K/s\].
pub const RAMP_K_PER_S: f32 = 0.5 / 60.0;
/// The end winding's index (its thermocouple's node).
pub const END_WINDING: usize = 2;
/// The active winding's index.
pub const ACTIVE_WINDING: usize = 0;

/// |i_s| \[A\] and speed \[rpm\] in second `t`.
pub fn drive(t: u32) -> (f32, f32) {
    match t / 60 {
        0 => (0.0, 0.0),
        1 => (300.0, 3000.0),
        2 => (150.0, 500.0),
        3 => (80.0, 4000.0),
        _ => (250.0, 1500.0),
    }
}

/// One second's start: its number, the open-loop and the fused node
/// temperatures \[degC\] and the thermocouple's reading \[degC\].
// Read by the host test only (the firmware passes `|_| {}`).
#[allow(dead_code)]
pub struct Second<'a> {
    /// Seconds from the start.
    pub t_s: u32,
    /// Open-loop estimate.
    pub open_c: &'a [f32; model::NODES],
    /// Fused estimate.
    pub fused_c: &'a [f32; model::NODES],
    /// The end-winding thermocouple.
    pub reading_c: f32,
}

/// What the whole run showed.
#[derive(Debug, Default, Clone, Copy)]
pub struct Summary {
    /// FNV-1a over every fused tick's temperatures, upper bounds and limits.
    pub checksum: u32,
    /// `|fused - reading|` of the end winding at the end \[K\].
    pub end_error_k: f32,
    /// How far the thermocouple is from open loop at the end \[K\].
    pub open_error_k: f32,
    /// The active winding's copper heat bias at the end \[W\].
    pub copper_bias_w: f32,
    /// Fused ticks with a correction.
    pub corrections: u32,
}

/// Runs the drive: the fused observer's ticks through `tick` (the firmware
/// counts their instructions there), every second's start to
/// `each_second` (the host keeps them), a line a minute to `out`.
///
/// # Errors
/// A failed write.
pub fn replay<W: Write>(
    observer: &model::Observer,
    out: &mut W,
    mut tick: impl FnMut(&mut dyn FnMut() -> u32),
    mut each_second: impl FnMut(&Second),
) -> Result<Summary, core::fmt::Error> {
    let mut open = model::initial_state(observer, AMBIENT_C);
    let mut fused = model::initial_state(observer, AMBIENT_C);
    let mut summary = Summary {
        checksum: checksum::START,
        ..Summary::default()
    };
    let mut now_us: u32 = 0;
    for t_s in 0..=SECONDS {
        let (open_c, fused_c) = (open.outputs().temps_c, fused.outputs().temps_c);
        let reading_c = open_c[END_WINDING] + RAMP_K_PER_S * t_s as f32;
        each_second(&Second {
            t_s,
            open_c: &open_c,
            fused_c: &fused_c,
            reading_c,
        });
        let (current_a, speed_rpm) = drive(t_s);
        if t_s % 60 == 0 {
            let o = fused.outputs();
            writeln!(
                out,
                "t={t_s:3} s  {current_a:3.0} A {speed_rpm:4.0} rpm  end winding {:.3} (open {:.3}, tc {reading_c:.3})  active {:.3}  slot centre {:.3} degC  limit {:.1} A  bias {:.2} W",
                fused_c[END_WINDING],
                open_c[END_WINDING],
                fused_c[ACTIVE_WINDING],
                fused_c[1],
                model::input_limits_a(&o.limits)[0],
                observer.heat_bias_w(&fused)[0],
            )?;
        }
        if t_s == SECONDS {
            summary.end_error_k = (fused_c[END_WINDING] - reading_c).abs();
            summary.open_error_k = reading_c - open_c[END_WINDING];
            break;
        }
        let currents_a = model::source_currents_a(&[current_a], &[speed_rpm]);
        let boundary_c = [AMBIENT_C; model::BOUNDARIES];
        for k in 0..1000u32 {
            let mut inputs = model::Inputs {
                currents_a,
                boundary_c,
                readings: [None],
                now_us,
                elapsed_us: 1000,
            };
            observer.tick(&mut open, &inputs);
            inputs.readings = [(k == 0).then_some(TimedReading {
                result: Ok(Reading::new(reading_c)),
                sampled_at_us: now_us,
            })];
            let mut published = None;
            tick(&mut || {
                let o = observer.tick(&mut fused, &inputs);
                let steps = o.steps;
                published = Some(*o);
                steps
            });
            if let Some(o) = published {
                summary.corrections += u32::from(o.corrected);
                summary.checksum = checksum::fold(summary.checksum, &o);
            }
            now_us = now_us.wrapping_add(1000);
        }
    }
    summary.copper_bias_w = observer.heat_bias_w(&fused)[0];
    writeln!(
        out,
        "drove {SECONDS} s at 1 ms: {} corrections; end winding {:.3} K from its thermocouple (open loop {:.3} K), copper bias {:.2} W, checksum {:08x}",
        summary.corrections,
        summary.end_error_k,
        summary.open_error_k,
        summary.copper_bias_w,
        summary.checksum
    )?;
    Ok(summary)
}
