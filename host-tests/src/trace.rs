//! Strict CSV traces: recorded or generated time series.
//!
//! A trace is a CSV file with a header row. Time comes from a `time_s`
//! column (seconds, finite, strictly increasing) or, for files without one,
//! from a sample period (`--sample-period-s`). Columns are parsed on demand,
//! so a text column that nobody uses is no error; a column that *is* used
//! must hold a finite number in every row. Every error names the file, the
//! line, the column number (1-based) and the column name.
//!
//! Column *expressions* keep derived inputs minimal: `NAME`, `hypot(A,B,...)`
//! (root of the sum of squares, e.g. `hypot(IdFbk,IqFbk)` for a d/q current
//! magnitude), `abs(NAME)`, `scale(NAME,K)` and a number (a constant).
//!
//! A *step profile* `T:V,T:V,...` is an input given beside the data rather
//! than in it (e.g. `0:16.37,40:0`: 16.37 from 0 s, 0 from 40 s on): each
//! value holds from its time \[s\] until the next one's.
//!
//! Lines starting with `#` are comments (the committed HPPA traces describe
//! themselves that way); line numbers in errors count them.
//!
//! # Streams and bounds
//!
//! `replay`, `simulate --trace` and `plot` stream a trace ([`TraceFile`]:
//! a checking scan, then passes over the rows through one reused record,
//! column expressions evaluated row by row by an [`Evaluator`]), in memory
//! that does not grow with its length, and write results row by row
//! ([`CsvOut`]). A trace spanning more than [`MAX_SPAN_S`] is refused (a
//! time typo such as `1e300` would otherwise ask for astronomically many
//! model steps).
//!
//! `calibrate` and `faults` hold a whole [`Trace`]: read row by row, each
//! cell held as its `f64` (8 bytes; an empty, `NaN` or text cell as a marked
//! `NaN`, with the text of each column's first one kept for the error), so
//! a trace takes about 8 bytes per cell plus 8 per row, roughly its file
//! size for numbers of 6 to 8 characters. Files over [`MAX_TRACE_BYTES`] are
//! refused there before reading, with what to do instead.

use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

mod stream;
pub use stream::{CsvOut, Evaluator, GapMedian, Row, Rows, TraceFile};

/// The name of the time column \[s\].
pub const TIME_COLUMN: &str = "time_s";

/// The largest trace file held whole by [`Trace::read_with`] \[bytes\]
/// (1 GiB; held as 8 bytes per cell, about its own size in memory for
/// typical cells). Streamed traces ([`TraceFile`]) have no such bound.
pub const MAX_TRACE_BYTES: u64 = 1 << 30;

/// A cell that is empty.
const EMPTY: u64 = 0x7ff8_0000_0000_0001;
/// A cell that is text, not a number.
const TEXT: u64 = 0x7ff8_0000_0000_0002;
/// A cell that is a number but not finite (`inf`, `-nan`; `nan` itself is
/// a plain `NaN`, a missing reading where those are allowed).
const NON_FINITE: u64 = 0x7ff8_0000_0000_0003;

/// The text of a column's first cell of each kind that is no finite
/// number: the first failing cell of a column is always one of these.
#[derive(Debug, Clone, Default)]
struct FirstText {
    text: Option<String>,
    nan: Option<String>,
    non_finite: Option<String>,
}

/// The longest time a trace may span, last row minus first \[s\] (about
/// 3.2 years).
pub const MAX_SPAN_S: f64 = 1e8;

/// Where a trace's time comes from.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TimeSource {
    /// The time column \[s\] (default [`TIME_COLUMN`]).
    pub column: Option<String>,
    /// Sample period \[s\] for a trace without a time column: row `k` is at
    /// `k * period`.
    pub sample_period_s: Option<f64>,
}

/// A number for a message: plain when moderate, `1e300` style when very
/// large or small (Rust's `{}` writes 1e300 with 300 zeros).
pub fn num(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e7).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// An error located in a file: `file:line:col: message`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct Located {
    /// File path as given.
    pub file: String,
    /// 1-based line.
    pub line: u64,
    /// 1-based column (CSV field number, or character column for TOML).
    pub col: Option<usize>,
    /// What went wrong.
    pub msg: String,
}

impl fmt::Display for Located {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.col {
            Some(c) => write!(f, "{}:{}:{}: {}", self.file, self.line, c, self.msg),
            None => write!(f, "{}:{}: {}", self.file, self.line, self.msg),
        }
    }
}

/// A CSV trace held whole, its cells as numbers until a column is asked
/// for (for runs that iterate over it; [`TraceFile`] streams it).
#[derive(Debug, Clone)]
pub struct Trace {
    path: PathBuf,
    headers: Vec<String>,
    /// Every cell, row-major (`EMPTY`, `TEXT`, `NON_FINITE` marked).
    cells: Vec<f64>,
    /// Per column, the text of its first odd cells, for the errors.
    first: Vec<FirstText>,
    lines: Vec<u64>,
    time_s: Vec<f64>,
    /// The first non-numeric cell of each column that has one (the time
    /// column excluded): reported, since a flag may never use the column.
    non_numeric: Vec<Located>,
}

/// A column expression (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub enum ColumnExpr {
    /// A column by name.
    Column(String),
    /// `sqrt(sum of squares)` of columns.
    Hypot(Vec<String>),
    /// Arithmetic mean of columns (e.g. two sensors of one node).
    Mean(Vec<String>),
    /// Absolute value of a column.
    Abs(String),
    /// A column times a constant.
    Scale(String, f64),
    /// A constant.
    Constant(f64),
    /// A step profile: `(from time [s], value)`, times strictly increasing.
    Steps(Vec<(f64, f64)>),
}

impl ColumnExpr {
    /// Parses `NAME`, `hypot(A,B)`, `mean(A,B)`, `abs(A)`, `scale(A,K)` or a number.
    pub fn parse(text: &str) -> Result<Self> {
        let t = text.trim();
        if t.is_empty() {
            bail!("empty column expression");
        }
        if let Ok(v) = t.parse::<f64>() {
            if !v.is_finite() {
                bail!("constant `{t}` is not finite");
            }
            return Ok(Self::Constant(v));
        }
        if t.contains(':') && !t.contains('(') {
            return Self::parse_steps(t);
        }
        if let Some(open) = t.find('(') {
            if !t.ends_with(')') {
                bail!("`{t}`: expected `func(ARGS)`");
            }
            let func = t[..open].trim();
            let args: Vec<String> = t[open + 1..t.len() - 1]
                .split(',')
                .map(|a| a.trim().to_string())
                .collect();
            if args.iter().any(String::is_empty) {
                bail!("`{t}`: empty argument");
            }
            return match (func, args.len()) {
                ("hypot", n) if n >= 1 => Ok(Self::Hypot(args)),
                ("mean", n) if n >= 1 => Ok(Self::Mean(args)),
                ("abs", 1) => Ok(Self::Abs(args[0].clone())),
                ("scale", 2) => {
                    let k: f64 = args[1]
                        .parse()
                        .map_err(|_| anyhow::anyhow!("`{t}`: `{}` is not a number", args[1]))?;
                    if !k.is_finite() {
                        bail!("`{t}`: the factor `{}` is not a finite number", args[1]);
                    }
                    Ok(Self::Scale(args[0].clone(), k))
                }
                _ => bail!("`{t}`: unknown function; use hypot(A,B,..), mean(A,B,..), abs(A) or scale(A,K)"),
            };
        }
        Ok(Self::Column(t.to_string()))
    }

    /// Parses a step profile `T:V,T:V,...` (times \[s\] strictly
    /// increasing, values finite).
    fn parse_steps(t: &str) -> Result<Self> {
        let mut steps: Vec<(f64, f64)> = Vec::new();
        for part in t.split(',') {
            let part = part.trim();
            let number = |x: &str| {
                x.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                    anyhow::anyhow!(
                        "step profile `{t}`: `{}` is not a finite number (expected TIME_S:VALUE,TIME_S:VALUE,...)",
                        x.trim()
                    )
                })
            };
            let Some((time, value)) = part.split_once(':') else {
                bail!("step profile `{t}`: `{part}` is not TIME_S:VALUE");
            };
            let (time, value) = (number(time)?, number(value)?);
            if let Some((last, _)) = steps.last() {
                if time <= *last {
                    bail!("step profile `{t}`: times must increase ({time} s after {last} s)");
                }
            }
            steps.push((time, value));
        }
        Ok(Self::Steps(steps))
    }

    /// A constant or a step profile at each of `time_s` \[s\]
    /// (increasing); an error for a column expression or a profile that
    /// starts after the first time.
    pub fn at_times(&self, time_s: &[f64]) -> Result<Vec<f64>, String> {
        match self {
            Self::Constant(v) => Ok(vec![*v; time_s.len()]),
            Self::Steps(steps) => {
                let (first_s, _) = steps[0];
                if let Some(t0) = time_s.first().filter(|t0| first_s > **t0) {
                    return Err(format!(
                        "step profile `{self}` starts at {first_s} s, after the first row ({t0} s): give a step at or before it"
                    ));
                }
                let mut k = 0;
                Ok(time_s
                    .iter()
                    .map(|t| {
                        while k + 1 < steps.len() && steps[k + 1].0 <= *t {
                            k += 1;
                        }
                        steps[k].1
                    })
                    .collect())
            }
            _ => Err(format!(
                "`{self}` reads trace columns; a number or a step profile T:V,T:V was expected"
            )),
        }
    }

    /// A constant's value, or a step profile's at `time_s` \[s\] (the
    /// step in force, the first one before it: what [`Self::at_times`]
    /// gives, one time at a time); `NaN` for a column expression.
    pub fn value_at(&self, time_s: f64) -> f64 {
        match self {
            Self::Constant(v) => *v,
            Self::Steps(steps) => {
                let k = steps.partition_point(|s| s.0 <= time_s).saturating_sub(1);
                steps[k].1
            }
            _ => f64::NAN,
        }
    }

    /// The columns the expression reads.
    pub fn columns(&self) -> Vec<&str> {
        match self {
            Self::Column(c) | Self::Abs(c) | Self::Scale(c, _) => vec![c.as_str()],
            Self::Hypot(cs) | Self::Mean(cs) => cs.iter().map(String::as_str).collect(),
            Self::Constant(_) | Self::Steps(_) => Vec::new(),
        }
    }
}

impl fmt::Display for ColumnExpr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Column(c) => write!(f, "{c}"),
            Self::Hypot(cs) => write!(f, "hypot({})", cs.join(",")),
            Self::Mean(cs) => write!(f, "mean({})", cs.join(",")),
            Self::Abs(c) => write!(f, "abs({c})"),
            Self::Scale(c, k) => write!(f, "scale({c},{})", num(*k)),
            Self::Constant(v) => write!(f, "{}", num(*v)),
            Self::Steps(steps) => {
                let parts: Vec<String> = steps
                    .iter()
                    .map(|(t, v)| format!("{}:{}", num(*t), num(*v)))
                    .collect();
                write!(f, "{}", parts.join(","))
            }
        }
    }
}

impl Trace {
    /// Reads a trace with its time in `time_s` or, without that column,
    /// every `sample_period_s` (see [`Self::read_with`]).
    pub fn read(path: &Path, sample_period_s: Option<f64>) -> Result<Self, Located> {
        Self::read_with(
            path,
            &TimeSource {
                column: None,
                sample_period_s,
            },
        )
    }

    /// Reads a trace. Time comes from the time column (default `time_s`)
    /// when present; otherwise the sample period must be given, and row `k`
    /// is at `k * period`. A named time column must exist.
    pub fn read_with(path: &Path, time: &TimeSource) -> Result<Self, Located> {
        let file = path.display().to_string();
        let time_column = time.column.as_deref().unwrap_or(TIME_COLUMN);
        let sample_period_s = time.sample_period_s;
        let at = |line: u64, col: Option<usize>, msg: String| Located {
            file: file.clone(),
            line,
            col,
            msg,
        };
        let mut reader =
            open_csv(path).map_err(|e| at(1, None, format!("cannot open trace: {e}")))?;
        if let Ok(meta) = std::fs::metadata(path) {
            if meta.len() > MAX_TRACE_BYTES {
                return Err(at(
                    1,
                    None,
                    format!(
                        "the trace is {} MiB; traces are held in memory (8 bytes a cell) up to {} MiB: \
                         keep the columns you use and decimate the rows (e.g. `awk -F, 'NR==1 || NR%10==2'` keeps every 10th), or split it",
                        meta.len() >> 20,
                        MAX_TRACE_BYTES >> 20
                    ),
                ));
            }
        }
        let headers = read_headers(&mut reader, &at)?;
        let mut cells = Vec::new();
        let mut first = vec![FirstText::default(); headers.len()];
        let mut lines = Vec::new();
        let mut non_numeric: Vec<Option<Located>> = vec![None; headers.len()];
        let mut record = csv::StringRecord::new();
        loop {
            let more = reader
                .read_record(&mut record)
                .map_err(|e| csv_error(&at, &e))?;
            if !more {
                break;
            }
            let line = record.position().map_or(0, |p| p.line());
            lines.push(line);
            for (i, cell) in record.iter().enumerate() {
                let value = cell_value(cell);
                match value.to_bits() {
                    TEXT if first[i].text.is_none() => {
                        first[i].text = Some(cell.to_string());
                        non_numeric[i] = Some(non_numeric_cell(&at, line, i, &headers[i], cell));
                    }
                    NON_FINITE => {
                        first[i].non_finite.get_or_insert_with(|| cell.to_string());
                    }
                    _ if value.is_nan() && value.to_bits() != EMPTY && value.to_bits() != TEXT => {
                        first[i].nan.get_or_insert_with(|| cell.to_string());
                    }
                    _ => {}
                }
                cells.push(value);
            }
        }
        if lines.is_empty() {
            return Err(at(
                2,
                None,
                "the trace has a header but no data rows".into(),
            ));
        }
        let mut trace = Self {
            path: path.to_path_buf(),
            headers,
            cells,
            first,
            lines,
            time_s: Vec::new(),
            non_numeric: Vec::new(),
        };
        if time.column.is_some() && trace.index_of(time_column).is_none() {
            return Err(trace.missing(time_column));
        }
        trace.time_s = match (trace.index_of(time_column), sample_period_s) {
            (Some(_), Some(_)) => {
                return Err(at(
                    1,
                    trace.index_of(time_column).map(|i| i + 1),
                    format!("the trace has a `{time_column}` column and --sample-period-s was given; use one"),
                ))
            }
            (Some(_), None) => {
                let t = trace.column(time_column)?;
                let col = trace.index_of(time_column).map(|i| i + 1);
                for k in 1..t.len() {
                    if t[k] <= t[k - 1] {
                        return Err(at(
                            trace.lines[k],
                            col,
                            format!(
                                "column `{time_column}`: time must increase strictly ({} after {})",
                                t[k],
                                t[k - 1]
                            ),
                        ));
                    }
                    if t[k] - t[0] > MAX_SPAN_S {
                        return Err(at(
                            trace.lines[k],
                            col,
                            format!(
                                "column `{time_column}`: {} s is {} s after the first row; a trace may span at most {MAX_SPAN_S:e} s \
                                 (is the time in seconds? a typo?)",
                                num(t[k]),
                                num(t[k] - t[0])
                            ),
                        ));
                    }
                }
                t
            }
            (None, Some(p)) => {
                if !(p.is_finite() && p > 0.0) {
                    return Err(at(1, None, format!("sample period must be > 0 s, got {p}")));
                }
                let span_s = (trace.len() - 1) as f64 * p;
                if span_s > MAX_SPAN_S {
                    return Err(at(
                        1,
                        None,
                        format!("{} rows every {p} s span {span_s:e} s; a trace may span at most {MAX_SPAN_S:e} s", trace.len()),
                    ));
                }
                (0..trace.len()).map(|k| k as f64 * p).collect()
            }
            (None, None) => {
                return Err(at(
                    1,
                    None,
                    format!(
                        "no `{TIME_COLUMN}` column (columns: {}); name the time column with --time-column NAME [s], or pass --sample-period-s",
                        trace.headers.join(", ")
                    ),
                ))
            }
        };
        let time_index = trace.index_of(time_column);
        trace.non_numeric = non_numeric
            .into_iter()
            .enumerate()
            .filter(|(i, _)| Some(*i) != time_index)
            .filter_map(|(_, l)| l)
            .collect();
        Ok(trace)
    }

    /// The first non-numeric cell of each column that has one (the time
    /// column excluded), for a warning: such a column is refused only when
    /// a flag uses it.
    pub fn non_numeric(&self) -> &[Located] {
        &self.non_numeric
    }

    /// The file path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Header names.
    pub fn headers(&self) -> &[String] {
        &self.headers
    }

    /// Number of data rows.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// `true` without data rows (never, for a trace that was read).
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// Time of every row \[s\].
    pub fn time_s(&self) -> &[f64] {
        &self.time_s
    }

    /// 1-based file line of row `k`.
    pub fn line_of_row(&self, k: usize) -> u64 {
        self.lines[k]
    }

    /// Whether a column exists.
    pub fn has_column(&self, name: &str) -> bool {
        self.index_of(name).is_some()
    }

    fn index_of(&self, name: &str) -> Option<usize> {
        self.headers.iter().position(|h| h == name)
    }

    fn missing(&self, name: &str) -> Located {
        missing_column(&self.path, &self.headers, name)
    }

    /// A column parsed as finite numbers.
    pub fn column(&self, name: &str) -> Result<Vec<f64>, Located> {
        self.column_with(name, false)
    }

    /// A column parsed as finite numbers; with `allow_missing`, an empty
    /// cell or `NaN` is a missing reading, returned as `NaN`.
    pub fn column_with(&self, name: &str, allow_missing: bool) -> Result<Vec<f64>, Located> {
        let i = self.index_of(name).ok_or_else(|| self.missing(name))?;
        let columns = self.headers.len();
        let first = &self.first[i];
        let text = |t: &Option<String>| t.clone().unwrap_or_default();
        self.lines
            .iter()
            .enumerate()
            .map(|(k, line)| {
                let v = self.cells[k * columns + i];
                let err = |msg: String| Located {
                    file: self.path.display().to_string(),
                    line: *line,
                    col: Some(i + 1),
                    msg: format!("column `{name}`: {msg}"),
                };
                if v.is_finite() {
                    return Ok(v);
                }
                // The first failing cell of a column is its first cell of
                // that kind, whose text `first` holds.
                match v.to_bits() {
                    EMPTY if allow_missing => Ok(f64::NAN),
                    EMPTY => Err(err("empty cell".into())),
                    TEXT => Err(err(format!("`{}` is not a number", text(&first.text)))),
                    NON_FINITE => Err(err(format!(
                        "`{}` is not a finite number",
                        text(&first.non_finite)
                    ))),
                    _ if allow_missing => Ok(f64::NAN),
                    _ => Err(err(format!(
                        "`{}` is not a finite number",
                        text(&first.nan)
                    ))),
                }
            })
            .collect()
    }

    /// Evaluates a column expression over every row; a result that
    /// overflows (e.g. `scale(C,1e308)`) is refused at its row.
    pub fn eval(&self, expr: &ColumnExpr) -> Result<Vec<f64>, Located> {
        self.eval_with(expr, false)
    }

    /// [`Self::eval`]; with `allow_missing`, empty and `NaN` cells are
    /// missing readings (`NaN` in the result).
    pub fn eval_with(&self, expr: &ColumnExpr, allow_missing: bool) -> Result<Vec<f64>, Located> {
        let col = |c: &str| self.column_with(c, allow_missing);
        let values: Vec<f64> = match expr {
            ColumnExpr::Column(c) => col(c)?,
            ColumnExpr::Abs(c) => col(c)?.into_iter().map(f64::abs).collect(),
            ColumnExpr::Scale(c, k) => col(c)?.into_iter().map(|v| v * k).collect(),
            ColumnExpr::Constant(_) | ColumnExpr::Steps(_) => {
                expr.at_times(&self.time_s).map_err(|msg| Located {
                    file: self.path.display().to_string(),
                    line: self.lines[0],
                    col: None,
                    msg,
                })?
            }
            ColumnExpr::Hypot(cs) => {
                // Scaled by the largest magnitude, so that squares of large
                // but finite values do not overflow.
                let series = cs.iter().map(|c| col(c)).collect::<Result<Vec<_>, _>>()?;
                (0..self.len())
                    .map(|k| series.iter().fold(0.0, |acc: f64, s| acc.hypot(s[k])))
                    .collect()
            }
            ColumnExpr::Mean(cs) => {
                let series = cs.iter().map(|c| col(c)).collect::<Result<Vec<_>, _>>()?;
                let n = cs.len() as f64;
                (0..self.len())
                    .map(|k| series.iter().map(|s| s[k]).sum::<f64>() / n)
                    .collect()
            }
        };
        if let Some(k) = values.iter().position(|v| v.is_infinite()) {
            return Err(Located {
                file: self.path.display().to_string(),
                line: self.lines[k],
                col: None,
                msg: format!("`{expr}` overflows to {} at this row", values[k]),
            });
        }
        Ok(values)
    }
}

/// Opens a trace as the reader every pass uses: a header row, `#`
/// comments, cells trimmed, every row as long as the header.
fn open_csv(path: &Path) -> csv::Result<csv::Reader<std::fs::File>> {
    csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(false)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_path(path)
}

/// The header row: no empty and no duplicate name.
fn read_headers(
    reader: &mut csv::Reader<std::fs::File>,
    at: &impl Fn(u64, Option<usize>, String) -> Located,
) -> Result<Vec<String>, Located> {
    let headers: Vec<String> = reader
        .headers()
        .map_err(|e| at(1, None, format!("cannot read the header row: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    for (i, h) in headers.iter().enumerate() {
        if h.is_empty() {
            return Err(at(1, Some(i + 1), "empty column name in the header".into()));
        }
        if headers[..i].contains(h) {
            return Err(at(1, Some(i + 1), format!("duplicate column `{h}`")));
        }
    }
    Ok(headers)
}

/// A CSV reading error at its line.
fn csv_error(at: &impl Fn(u64, Option<usize>, String) -> Located, e: &csv::Error) -> Located {
    let line = e.position().map_or(0, |p| p.line());
    let msg = match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("row has {len} fields, the header has {expected_len}"),
        _ => format!("malformed CSV: {e}"),
    };
    at(line, None, msg)
}

/// The warning for a column's first text cell.
fn non_numeric_cell(
    at: &impl Fn(u64, Option<usize>, String) -> Located,
    line: u64,
    i: usize,
    header: &str,
    cell: &str,
) -> Located {
    at(
        line,
        Some(i + 1),
        format!(
            "column `{header}` holds `{cell}`, not a number (fine while no flag uses the column)"
        ),
    )
}

/// A cell as a number: finite, a plain `NaN` (`nan`), or a marked `NaN`
/// (`EMPTY`, `TEXT`, `NON_FINITE`).
fn cell_value(cell: &str) -> f64 {
    if cell.is_empty() {
        f64::from_bits(EMPTY)
    } else if cell.eq_ignore_ascii_case("nan") {
        f64::NAN
    } else {
        match cell.parse::<f64>() {
            Ok(v) if v.is_finite() => v,
            Ok(_) => f64::from_bits(NON_FINITE),
            Err(_) => f64::from_bits(TEXT),
        }
    }
}

/// A cell (`value` from [`cell_value`], `cell` its text) as a finite
/// number; with `allow_missing`, an empty cell or `NaN` is a missing
/// reading (`NaN`). The error is the one [`Trace::column_with`] gives.
fn cell_checked(value: f64, cell: &str, allow_missing: bool) -> Result<f64, String> {
    if value.is_finite() {
        return Ok(value);
    }
    match value.to_bits() {
        EMPTY if allow_missing => Ok(f64::NAN),
        EMPTY => Err("empty cell".into()),
        TEXT => Err(format!("`{cell}` is not a number")),
        NON_FINITE => Err(format!("`{cell}` is not a finite number")),
        _ if allow_missing => Ok(f64::NAN),
        _ => Err(format!("`{cell}` is not a finite number")),
    }
}

/// The error for a column the trace lacks, with the closest header as a
/// hint.
fn missing_column(path: &Path, headers: &[String], name: &str) -> Located {
    // The closest header by edit distance (case-insensitive), if close.
    let lower = name.to_lowercase();
    let hint = headers
        .iter()
        .map(|h| (edit_distance(&h.to_lowercase(), &lower), h))
        .filter(|(d, _)| *d <= 2.max(name.len() / 3))
        .min_by_key(|(d, _)| *d)
        .map(|(_, h)| format!("; did you mean `{h}`?"))
        .unwrap_or_default();
    Located {
        file: path.display().to_string(),
        line: 1,
        col: None,
        msg: format!(
            "missing column `{name}` (columns: {}){hint}",
            headers.join(", ")
        ),
    }
}

/// Levenshtein distance between two strings (by characters).
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// Writes `time_s` then one column per series (all equal length).
pub fn write_csv(path: &Path, names: &[String], time_s: &[f64], series: &[Vec<f64>]) -> Result<()> {
    let mut w = CsvOut::create(path, names)?;
    for (k, t) in time_s.iter().enumerate() {
        w.row(*t, series.iter().map(|s| s[k]))?;
    }
    w.finish()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// `text` in a file `t.csv` of a fresh temporary folder (kept while
    /// the folder lives).
    pub(crate) fn write(text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::TempDir::new().unwrap();
        let path = dir.path().join("t.csv");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    fn trace(text: &str) -> (tempfile::TempDir, Trace) {
        let (dir, path) = write(text);
        (dir, Trace::read(&path, None).unwrap())
    }

    #[test]
    fn a_step_profile_holds_each_value_from_its_time() {
        let e = ColumnExpr::parse("0:16.37,40:0,60.5:2").unwrap();
        assert_eq!(e.to_string(), "0:16.37,40:0,60.5:2");
        let t = [0.0, 39.9, 40.0, 60.0, 61.0, 1e4];
        assert_eq!(e.at_times(&t).unwrap(), [16.37, 16.37, 0.0, 0.0, 2.0, 2.0]);
        assert!(e.at_times(&[-1.0]).unwrap_err().contains("starts at 0 s"));
        for bad in ["0:1,0:2", "1:inf", "0:1,2", "a:1"] {
            assert!(ColumnExpr::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn hypot_of_large_columns_does_not_overflow_and_missing_cells_are_nan() {
        let (_d, t) = trace("time_s,a,b\n0,3e200,4e200\n1,3,\n2,nan,4\n");
        let h = t
            .eval_with(&ColumnExpr::parse("hypot(a,b)").unwrap(), true)
            .unwrap();
        assert!((h[0] / 5e200 - 1.0).abs() < 1e-15, "{}", h[0]);
        assert!(h[1].is_nan() && h[2].is_nan());
        // Strict, the empty cell is an error at its line and column.
        let e = t.eval(&ColumnExpr::parse("b").unwrap()).unwrap_err();
        assert_eq!((e.line, e.col), (3, Some(3)));
    }

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(num(1e300), "1e300");
        assert_eq!(num(1e-12), "1e-12");
        assert_eq!(num(12.5), "12.5");
        assert_eq!(num(0.0), "0");
    }
}
