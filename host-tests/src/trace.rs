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
//! Lines starting with `#` are comments (the committed HPPA traces describe
//! themselves that way); line numbers in errors count them.

use std::fmt;
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

/// The name of the time column \[s\].
pub const TIME_COLUMN: &str = "time_s";

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

/// A CSV trace held as text until a column is asked for.
#[derive(Debug, Clone)]
pub struct Trace {
    path: PathBuf,
    headers: Vec<String>,
    rows: Vec<csv::StringRecord>,
    lines: Vec<u64>,
    time_s: Vec<f64>,
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
                    Ok(Self::Scale(args[0].clone(), k))
                }
                _ => bail!("`{t}`: unknown function; use hypot(A,B,..), mean(A,B,..), abs(A) or scale(A,K)"),
            };
        }
        Ok(Self::Column(t.to_string()))
    }

    /// The columns the expression reads.
    pub fn columns(&self) -> Vec<&str> {
        match self {
            Self::Column(c) | Self::Abs(c) | Self::Scale(c, _) => vec![c.as_str()],
            Self::Hypot(cs) | Self::Mean(cs) => cs.iter().map(String::as_str).collect(),
            Self::Constant(_) => Vec::new(),
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
            Self::Scale(c, k) => write!(f, "scale({c},{k})"),
            Self::Constant(v) => write!(f, "{v}"),
        }
    }
}

impl Trace {
    /// Reads a trace. Time comes from `time_column` (default `time_s`) when
    /// present; otherwise `sample_period_s` must be given, and row `k` is at
    /// `k * sample_period_s`.
    pub fn read(path: &Path, sample_period_s: Option<f64>) -> Result<Self, Located> {
        let file = path.display().to_string();
        let at = |line: u64, col: Option<usize>, msg: String| Located {
            file: file.clone(),
            line,
            col,
            msg,
        };
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(true)
            .flexible(false)
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .from_path(path)
            .map_err(|e| at(1, None, format!("cannot open trace: {e}")))?;
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
        let mut rows = Vec::new();
        let mut lines = Vec::new();
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map_or(0, |p| p.line());
                let msg = match e.kind() {
                    csv::ErrorKind::UnequalLengths {
                        expected_len, len, ..
                    } => format!("row has {len} fields, the header has {expected_len}"),
                    _ => format!("malformed CSV: {e}"),
                };
                at(line, None, msg)
            })?;
            lines.push(record.position().map_or(0, |p| p.line()));
            rows.push(record);
        }
        if rows.is_empty() {
            return Err(at(
                2,
                None,
                "the trace has a header but no data rows".into(),
            ));
        }
        let mut trace = Self {
            path: path.to_path_buf(),
            headers,
            rows,
            lines,
            time_s: Vec::new(),
        };
        trace.time_s = match (trace.index_of(TIME_COLUMN), sample_period_s) {
            (Some(_), Some(_)) => {
                return Err(at(
                    1,
                    trace.index_of(TIME_COLUMN).map(|i| i + 1),
                    format!("the trace has a `{TIME_COLUMN}` column and --sample-period-s was given; use one"),
                ))
            }
            (Some(_), None) => {
                let t = trace.column(TIME_COLUMN)?;
                let col = trace.index_of(TIME_COLUMN).map(|i| i + 1);
                for k in 1..t.len() {
                    if t[k] <= t[k - 1] {
                        return Err(at(
                            trace.lines[k],
                            col,
                            format!(
                                "column `{TIME_COLUMN}`: time must increase strictly ({} after {})",
                                t[k],
                                t[k - 1]
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
                (0..trace.rows.len()).map(|k| k as f64 * p).collect()
            }
            (None, None) => {
                return Err(at(
                    1,
                    None,
                    format!(
                        "no `{TIME_COLUMN}` column (columns: {}); add one or pass --sample-period-s",
                        trace.headers.join(", ")
                    ),
                ))
            }
        };
        Ok(trace)
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
        self.rows.len()
    }

    /// `true` without data rows (never, for a trace that was read).
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
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
        // The closest header by edit distance (case-insensitive), if close.
        let lower = name.to_lowercase();
        let hint = self
            .headers
            .iter()
            .map(|h| (edit_distance(&h.to_lowercase(), &lower), h))
            .filter(|(d, _)| *d <= 2.max(name.len() / 3))
            .min_by_key(|(d, _)| *d)
            .map(|(_, h)| format!("; did you mean `{h}`?"))
            .unwrap_or_default();
        Located {
            file: self.path.display().to_string(),
            line: 1,
            col: None,
            msg: format!(
                "missing column `{name}` (columns: {}){hint}",
                self.headers.join(", ")
            ),
        }
    }

    /// A column parsed as finite numbers.
    pub fn column(&self, name: &str) -> Result<Vec<f64>, Located> {
        let i = self.index_of(name).ok_or_else(|| self.missing(name))?;
        self.rows
            .iter()
            .zip(&self.lines)
            .map(|(row, line)| {
                let cell = row.get(i).unwrap_or("");
                let err = |msg: String| Located {
                    file: self.path.display().to_string(),
                    line: *line,
                    col: Some(i + 1),
                    msg: format!("column `{name}`: {msg}"),
                };
                if cell.is_empty() {
                    return Err(err("empty cell".into()));
                }
                let v: f64 = cell
                    .parse()
                    .map_err(|_| err(format!("`{cell}` is not a number")))?;
                if !v.is_finite() {
                    return Err(err(format!("`{cell}` is not a finite number")));
                }
                Ok(v)
            })
            .collect()
    }

    /// Evaluates a column expression over every row.
    pub fn eval(&self, expr: &ColumnExpr) -> Result<Vec<f64>, Located> {
        Ok(match expr {
            ColumnExpr::Column(c) => self.column(c)?,
            ColumnExpr::Abs(c) => self.column(c)?.into_iter().map(f64::abs).collect(),
            ColumnExpr::Scale(c, k) => self.column(c)?.into_iter().map(|v| v * k).collect(),
            ColumnExpr::Constant(v) => vec![*v; self.len()],
            ColumnExpr::Hypot(cs) => {
                let mut acc = vec![0.0; self.len()];
                for c in cs {
                    for (a, v) in acc.iter_mut().zip(self.column(c)?) {
                        *a += v * v;
                    }
                }
                acc.into_iter().map(f64::sqrt).collect()
            }
            ColumnExpr::Mean(cs) => {
                let mut acc = vec![0.0; self.len()];
                for c in cs {
                    for (a, v) in acc.iter_mut().zip(self.column(c)?) {
                        *a += v;
                    }
                }
                let n = cs.len() as f64;
                acc.into_iter().map(|a| a / n).collect()
            }
        })
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
    let mut w = csv::Writer::from_path(path)
        .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", path.display()))?;
    let mut header = vec![TIME_COLUMN.to_string()];
    header.extend(names.iter().cloned());
    w.write_record(&header)?;
    for (k, t) in time_s.iter().enumerate() {
        let mut rec = vec![format!("{t}")];
        rec.extend(series.iter().map(|s| format!("{:.6}", s[k])));
        w.write_record(&rec)?;
    }
    w.flush()?;
    Ok(())
}
