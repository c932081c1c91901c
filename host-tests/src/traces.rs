//! Synthetic coil-current traces for the 84-coil HPPA grid, and their CSV form.
//!
//! There is no public recording of the HPPA's currents, so these are made up,
//! reproducibly (no randomness beyond a fixed-seed SplitMix64), to look like
//! the report's experiments:
//!
//! * [`validation`]: the report's validation run, the magnet plate moving
//!   left-right (x) sinusoidally at 0.1 Hz with 10 cm amplitude; coils under
//!   the plate carry commutation-like currents set by the plate's position
//!   over each coil, the others zero. 300 s sampled at 10 Hz.
//! * [`calibration`]: the four calibration patterns at 0.7 A per coil (all
//!   coils, one row, one line, the centre coil), 1200 s on, then 600 s off.
//! * [`duty_cycle`]: one hour of sweeps, point-to-point moves, hovering and
//!   idling, sampled at 1 Hz, for drift and budget checks.
//!
//! # The grid and the plate
//!
//! 7 rows x 12 columns = 84 coils, pitch 22.5 mm (the coil width) in x and y,
//! odd rows shifted by half a coil in +x (the herringbone stencil's brick
//! pattern). "Row" is a grid row (constant y), "line" a grid column (constant
//! x). The plate is 112.5 mm (x) by 100 mm (y); a coil is energised while its
//! centre lies under the plate, with `I = A sin(2 pi (x_coil - x_plate) /
//! 50 mm + phase)`, the phase a quarter period on odd rows (the other coil
//! orientation of the herringbone).
//!
//! # CSV
//!
//! `#` comment lines (the header says the data are synthetic), then a
//! column line `time_s,I_r0_c0_a,I_r0_c1_a,...` (row-major), then one row
//! per sample: time \[s\], whole milliseconds, and the current of each coil
//! \[A\]. Sample-and-hold: a row's currents hold from its time until the next
//! row's time; the last row only marks the end of the trace.

use std::f64::consts::PI;
use std::fmt::Write as _;

/// Grid rows of the traces.
pub const ROWS: usize = 7;
/// Grid columns of the traces.
pub const COLS: usize = 12;
/// Coils in the traces.
pub const COILS: usize = ROWS * COLS;
/// Coil pitch \[m\] (the coil width of the report).
pub const PITCH_M: f64 = 0.0225;

/// A sample-and-hold current trace for the 84-coil grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Sample times \[s\], increasing, whole milliseconds.
    pub times_s: Vec<f64>,
    /// Coil currents \[A\] per sample, row-major.
    pub currents_a: Vec<[f64; COILS]>,
}

impl Trace {
    /// Number of hold intervals (samples minus the end marker).
    pub fn holds(&self) -> usize {
        self.times_s.len().saturating_sub(1)
    }

    /// Length of hold interval `k` in whole milliseconds.
    pub fn hold_ms(&self, k: usize) -> u64 {
        ((self.times_s[k + 1] - self.times_s[k]) * 1000.0).round() as u64
    }

    /// The currents of sample `k` as a grid \[A\].
    pub fn grid_a(&self, k: usize) -> [[f64; COLS]; ROWS] {
        std::array::from_fn(|r| std::array::from_fn(|c| self.currents_a[k][r * COLS + c]))
    }

    /// The CSV text, with `description` as extra comment lines.
    pub fn to_csv(&self, name: &str, description: &[&str]) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "# coil-thermal current trace `{name}`");
        out.push_str(
            "# SYNTHETIC: made by host-tests/src/bin/gen-traces.rs (host-tests/src/traces.rs),\n\
             # not a recording of the HPPA. Regenerate: cargo run -p coil-thermal-host --bin gen-traces\n",
        );
        for line in description {
            let _ = writeln!(out, "# {line}");
        }
        out.push_str(
            "# grid: 7 rows x 12 columns (84 coils), row 0 even, odd rows offset +half a coil in x\n\
             # columns: time_s [s], then I_r<row>_c<col>_a [A] per coil, row-major\n\
             # sample-and-hold: a row's currents hold until the next row's time_s; the last row ends the trace\n",
        );
        out.push_str("time_s");
        for r in 0..ROWS {
            for c in 0..COLS {
                let _ = write!(out, ",I_r{r}_c{c}_a");
            }
        }
        out.push('\n');
        for (t, currents) in self.times_s.iter().zip(&self.currents_a) {
            let _ = write!(out, "{t:.3}");
            for i in currents {
                out.push(',');
                out.push_str(&format_current(*i));
            }
            out.push('\n');
        }
        out
    }

    /// Parses the CSV form; checks the column count and whole-millisecond,
    /// increasing times.
    pub fn from_csv(text: &str) -> Result<Self, String> {
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let header = lines.next().ok_or("empty trace")?;
        if header.split(',').count() != COILS + 1 || !header.starts_with("time_s,") {
            return Err(format!("bad column line: {header}"));
        }
        let mut trace = Trace {
            times_s: Vec::new(),
            currents_a: Vec::new(),
        };
        for (n, line) in lines.enumerate() {
            let mut fields = line.split(',').map(str::parse::<f64>);
            let t = fields
                .next()
                .ok_or("empty row")?
                .map_err(|e| e.to_string())?;
            let ms = t * 1000.0;
            if (ms - ms.round()).abs() > 1e-6 || trace.times_s.last().is_some_and(|&p| t <= p) {
                return Err(format!("row {n}: time {t} not increasing whole ms"));
            }
            let mut currents = [0.0; COILS];
            for slot in currents.iter_mut() {
                *slot = fields
                    .next()
                    .ok_or(format!("row {n}: too few columns"))?
                    .map_err(|e| e.to_string())?;
            }
            if fields.next().is_some() {
                return Err(format!("row {n}: too many columns"));
            }
            trace.times_s.push(ms.round() / 1000.0);
            trace.currents_a.push(currents);
        }
        Ok(trace)
    }
}

/// Milliampere resolution, zero as `0` (most coils are off most of the time).
fn format_current(i: f64) -> String {
    let s = format!("{i:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    match s {
        "" | "-0" | "0" => "0".to_string(),
        _ => s.to_string(),
    }
}

/// Centre of coil `(row, col)` \[m\].
pub fn coil_centre_m(row: usize, col: usize) -> (f64, f64) {
    let shift = if row % 2 == 1 { 0.5 } else { 0.0 };
    (
        (col as f64 + 0.5 + shift) * PITCH_M,
        (row as f64 + 0.5) * PITCH_M,
    )
}

/// Commutation-like currents \[A\] with the plate centred at `(x, y)` \[m\].
pub fn plate_currents(x_m: f64, y_m: f64, amplitude_a: f64) -> [f64; COILS] {
    const HALF_X_M: f64 = 0.056_25;
    const HALF_Y_M: f64 = 0.05;
    const PERIOD_M: f64 = 0.05;
    let mut out = [0.0; COILS];
    for r in 0..ROWS {
        for c in 0..COLS {
            let (xc, yc) = coil_centre_m(r, c);
            if (xc - x_m).abs() < HALF_X_M && (yc - y_m).abs() < HALF_Y_M {
                let phase = if r % 2 == 1 { PI / 2.0 } else { 0.0 };
                out[r * COLS + c] = amplitude_a * (2.0 * PI * (xc - x_m) / PERIOD_M + phase).sin();
            }
        }
    }
    out
}

/// Middle of the grid \[m\].
fn grid_middle_m() -> (f64, f64) {
    (COLS as f64 * PITCH_M / 2.0, ROWS as f64 * PITCH_M / 2.0)
}

/// Rounds each current to the CSV's milliampere resolution, so that the
/// in-memory trace equals the parsed file.
fn quantised(currents: [f64; COILS]) -> [f64; COILS] {
    currents.map(|i| format_current(i).parse().unwrap_or(0.0))
}

/// Samples `currents(t)` every `sample_ms` for `duration_s`, plus the end row.
fn sampled(duration_s: u64, sample_ms: u64, currents: impl Fn(f64) -> [f64; COILS]) -> Trace {
    let mut trace = Trace {
        times_s: Vec::new(),
        currents_a: Vec::new(),
    };
    let samples = duration_s * 1000 / sample_ms;
    for k in 0..=samples {
        let t = (k * sample_ms) as f64 / 1000.0;
        trace.times_s.push(t);
        let i = if k == samples {
            [0.0; COILS]
        } else {
            currents(t)
        };
        trace.currents_a.push(quantised(i));
    }
    trace
}

/// The report's validation trajectory: 0.1 Hz, 10 cm amplitude in x,
/// 1.5 A commutation amplitude, 300 s at 10 Hz.
pub fn validation() -> Trace {
    let (x0, y0) = grid_middle_m();
    sampled(300, 100, |t| {
        plate_currents(x0 + 0.1 * (2.0 * PI * 0.1 * t).sin(), y0, 1.5)
    })
}

/// The four calibration patterns of the report.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pattern {
    /// All 84 coils.
    AllOn,
    /// Row 3 (the middle row).
    OneRow,
    /// Line (column) 5.
    OneLine,
    /// The centre coil, row 3 column 5 (x = 135 mm, the middle of the grid).
    OneCoil,
}

impl Pattern {
    /// All four, in the report's order.
    pub const ALL: [Pattern; 4] = [Self::AllOn, Self::OneRow, Self::OneLine, Self::OneCoil];

    /// File stem of the pattern's trace.
    pub fn name(self) -> &'static str {
        match self {
            Self::AllOn => "calibration_all_on",
            Self::OneRow => "calibration_one_row",
            Self::OneLine => "calibration_one_line",
            Self::OneCoil => "calibration_one_coil",
        }
    }

    fn on(self, row: usize, col: usize) -> bool {
        match self {
            Self::AllOn => true,
            Self::OneRow => row == 3,
            Self::OneLine => col == 5,
            Self::OneCoil => row == 3 && col == 5,
        }
    }
}

/// A calibration pattern at 0.7 A: on from 0 to 1200 s, off to 1800 s.
pub fn calibration(pattern: Pattern) -> Trace {
    let on: [f64; COILS] = std::array::from_fn(|k| {
        if pattern.on(k / COLS, k % COLS) {
            0.7
        } else {
            0.0
        }
    });
    Trace {
        times_s: vec![0.0, 1200.0, 1800.0],
        currents_a: vec![on, [0.0; COILS], [0.0; COILS]],
    }
}

/// SplitMix64: a fixed, dependency-free generator, so the traces never
/// change with a crate version.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[lo, hi)`.
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// What the plate does during one segment of the duty cycle.
#[derive(Debug, Clone, Copy)]
enum Segment {
    /// Sinusoidal sweep in x: amplitude \[m\], frequency \[Hz\], current \[A\].
    Sweep(f64, f64, f64),
    /// Cosine-profile move to an x offset \[m\] in a time \[s\], then hover.
    Move(f64, f64),
    /// Levitating in place (0.6 A commutation amplitude).
    Hover,
    /// Landed, all coils off.
    Idle,
}

/// One hour (3600 s) at 1 Hz: seeded random segments of 30 to 300 s.
pub fn duty_cycle() -> Trace {
    let mut rng = SplitMix64(0x4850_5041_2011);
    let (x_mid, y_mid) = grid_middle_m();
    let mut plan = Vec::new();
    let mut start = 0.0;
    let mut x = 0.0;
    while start < 3600.0 {
        let length = rng.uniform(30.0, 300.0).round();
        let y = y_mid + PITCH_M * (rng.uniform(0.0, 3.0).floor() - 1.0);
        let segment = match rng.uniform(0.0, 1.0) {
            p if p < 0.35 => Segment::Sweep(
                rng.uniform(0.03, 0.1),
                rng.uniform(0.05, 0.2),
                rng.uniform(1.0, 2.0),
            ),
            p if p < 0.65 => Segment::Move(rng.uniform(-0.1, 0.1), rng.uniform(5.0, 20.0)),
            p if p < 0.85 => Segment::Hover,
            _ => Segment::Idle,
        };
        plan.push((start, length, y, x, segment));
        if let Segment::Move(to, _) = segment {
            x = to;
        }
        start += length;
    }
    sampled(3600, 1000, |t| {
        let Some(&(t0, _, y, x_from, segment)) = plan.iter().rev().find(|s| s.0 <= t) else {
            return [0.0; COILS];
        };
        let tau = t - t0;
        match segment {
            Segment::Sweep(amp, freq, current) => plate_currents(
                x_mid + x_from + amp * (2.0 * PI * freq * tau).sin(),
                y,
                current,
            ),
            Segment::Move(to, time) if tau < time => {
                let s = 0.5 - 0.5 * (PI * tau / time).cos();
                plate_currents(x_mid + x_from + (to - x_from) * s, y, 1.8)
            }
            Segment::Move(to, _) => plate_currents(x_mid + to, y, 0.6),
            Segment::Hover => plate_currents(x_mid + x_from, y, 0.6),
            Segment::Idle => [0.0; COILS],
        }
    })
}

/// Every trace with its file stem and header description.
pub fn all() -> Vec<(&'static str, Vec<&'static str>, Trace)> {
    let mut out = vec![(
        "validation",
        vec![
            "validation trajectory: plate moving in x, 0.1 Hz, 10 cm amplitude, 1.5 A commutation amplitude",
            "300 s sampled at 10 Hz; coils away from the plate at 0 A",
        ],
        validation(),
    )];
    for p in Pattern::ALL {
        out.push((
            p.name(),
            vec!["calibration pattern at 0.7 A per coil: on 0..1200 s, off 1200..1800 s"],
            calibration(p),
        ));
    }
    out.push((
        "duty_cycle",
        vec![
            "one-hour duty cycle: seeded sweeps, point-to-point moves, hovering (0.6 A) and idle",
            "3600 s sampled at 1 Hz",
        ],
        duty_cycle(),
    ));
    out
}

/// The committed trace directory, `host-tests/traces`.
pub fn trace_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("traces")
}

/// Reads a committed trace by file stem.
pub fn load(name: &str) -> Trace {
    let path = trace_dir().join(format!("{name}.csv"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    Trace::from_csv(&text).unwrap_or_else(|e| panic!("{path:?}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips() {
        let trace = validation();
        let text = trace.to_csv("validation", &[]);
        assert_eq!(Trace::from_csv(&text).unwrap(), trace);
    }

    #[test]
    fn only_coils_under_the_plate_carry_current() {
        let (x, y) = grid_middle_m();
        let i = plate_currents(x, y, 1.0);
        let on = i.iter().filter(|v| **v != 0.0).count();
        assert!((20..=30).contains(&on), "{on}");
        assert_eq!(i[0], 0.0);
        assert_eq!(i[COILS - 1], 0.0);
    }
}
