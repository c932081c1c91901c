//! Traces read as a stream: one checking pass ([`TraceFile::scan`]), then
//! as many passes over the rows ([`TraceFile::rows`]) as a run needs, each
//! through one reused record, so that memory does not grow with the trace.
//!
//! The scan checks what [`super::Trace::read_with`] checks (the CSV's
//! shape, the time column or the sample period, the span) with the same
//! errors, counts the rows and keeps what later passes ask about the time
//! (first and last time, the spacing's distinct values for its median).
//! Column expressions are evaluated row by row by an [`Evaluator`], which
//! keeps each expression's first error in the order
//! [`super::Trace::eval_with`] would have found it (its first failing
//! column, in argument order, then its first overflow), so a caller that
//! walks its expressions in order after a pass reports what the whole-trace
//! code reported.
//!
//! [`CsvOut`] writes a result row by row into a partial file beside the
//! target, renamed over it once the run succeeds: a run that fails half
//! way leaves nothing, as before.

use std::collections::HashMap;
use std::fs::File;
use std::path::{Path, PathBuf};

use anyhow::Result;

use super::{
    cell_checked, cell_value, csv_error, missing_column, non_numeric_cell, num, open_csv,
    read_headers, ColumnExpr, Located, TimeSource, MAX_SPAN_S, TEXT, TIME_COLUMN,
};

/// The most distinct row spacings the scan counts for the median spacing;
/// beyond them the median is selected by radix over further passes.
const MAX_DISTINCT_GAPS: usize = 4096;

/// A trace file checked by one streaming pass: its header, row count and
/// times, not its cells.
#[derive(Debug, Clone)]
pub struct TraceFile {
    path: PathBuf,
    headers: Vec<String>,
    /// The time column's index, or `None` with a sample period.
    time_index: Option<usize>,
    sample_period_s: Option<f64>,
    rows: usize,
    first_line: u64,
    first_time_s: f64,
    last_time_s: f64,
    non_numeric: Vec<Located>,
    /// The row spacings, counted while they are few.
    gaps: GapMedian,
}

impl TraceFile {
    /// Scans a trace: the checks and errors of
    /// [`super::Trace::read_with`], in constant memory.
    pub fn scan(path: &Path, time: &TimeSource) -> Result<Self, Located> {
        Self::scan_with(path, time, MAX_DISTINCT_GAPS)
    }

    fn scan_with(path: &Path, time: &TimeSource, max_gaps: usize) -> Result<Self, Located> {
        let file = path.display().to_string();
        let time_column = time.column.as_deref().unwrap_or(TIME_COLUMN);
        let at = |line: u64, col: Option<usize>, msg: String| Located {
            file: file.clone(),
            line,
            col,
            msg,
        };
        let mut reader =
            open_csv(path).map_err(|e| at(1, None, format!("cannot open trace: {e}")))?;
        let headers = read_headers(&mut reader, &at)?;
        let time_index = headers.iter().position(|h| h == time_column);
        let mut non_numeric: Vec<Option<Located>> = vec![None; headers.len()];
        // The time column's first bad cell, and its first step back or
        // beyond the span: the former wins, as in `read_with`.
        let mut time_cell: Option<Located> = None;
        let mut time_order: Option<Located> = None;
        let mut gaps = GapMedian::with_cap(max_gaps);
        let (mut rows, mut first_line) = (0usize, 0u64);
        let (mut first_time_s, mut prev) = (f64::NAN, f64::NAN);
        let mut record = csv::StringRecord::new();
        loop {
            if !reader
                .read_record(&mut record)
                .map_err(|e| csv_error(&at, &e))?
            {
                break;
            }
            let line = record.position().map_or(0, |p| p.line());
            for (i, cell) in record.iter().enumerate() {
                if non_numeric[i].is_none() && cell_value(cell).to_bits() == TEXT {
                    non_numeric[i] = Some(non_numeric_cell(&at, line, i, &headers[i], cell));
                }
            }
            let t = match (time_index, time.sample_period_s) {
                (Some(i), _) => {
                    let cell = &record[i];
                    cell_checked(cell_value(cell), cell, false).unwrap_or_else(|msg| {
                        time_cell.get_or_insert_with(|| {
                            at(line, Some(i + 1), format!("column `{time_column}`: {msg}"))
                        });
                        f64::NAN
                    })
                }
                (None, Some(p)) => rows as f64 * p,
                (None, None) => f64::NAN,
            };
            if rows == 0 {
                first_line = line;
                first_time_s = t;
            } else {
                if let Some(i) = time_index.filter(|_| time_order.is_none()) {
                    if t <= prev {
                        time_order = Some(at(
                            line,
                            Some(i + 1),
                            format!(
                                "column `{time_column}`: time must increase strictly ({t} after {prev})"
                            ),
                        ));
                    } else if t - first_time_s > MAX_SPAN_S {
                        time_order = Some(at(
                            line,
                            Some(i + 1),
                            format!(
                                "column `{time_column}`: {} s is {} s after the first row; a trace may span at most {MAX_SPAN_S:e} s \
                                 (is the time in seconds? a typo?)",
                                num(t),
                                num(t - first_time_s)
                            ),
                        ));
                    }
                }
                gaps.push(t - prev);
            }
            prev = t;
            rows += 1;
        }
        if rows == 0 {
            return Err(at(
                2,
                None,
                "the trace has a header but no data rows".into(),
            ));
        }
        if time.column.is_some() && time_index.is_none() {
            return Err(missing_column(path, &headers, time_column));
        }
        match (time_index, time.sample_period_s) {
            (Some(i), Some(_)) => {
                return Err(at(
                    1,
                    Some(i + 1),
                    format!("the trace has a `{time_column}` column and --sample-period-s was given; use one"),
                ))
            }
            (Some(_), None) => {
                if let Some(e) = time_cell.or(time_order) {
                    return Err(e);
                }
            }
            (None, Some(p)) => {
                if !(p.is_finite() && p > 0.0) {
                    return Err(at(1, None, format!("sample period must be > 0 s, got {p}")));
                }
                let span_s = (rows - 1) as f64 * p;
                if span_s > MAX_SPAN_S {
                    return Err(at(
                        1,
                        None,
                        format!("{rows} rows every {p} s span {span_s:e} s; a trace may span at most {MAX_SPAN_S:e} s"),
                    ));
                }
            }
            (None, None) => {
                return Err(at(
                    1,
                    None,
                    format!(
                        "no `{TIME_COLUMN}` column (columns: {}); name the time column with --time-column NAME [s], or pass --sample-period-s",
                        headers.join(", ")
                    ),
                ))
            }
        }
        let non_numeric = non_numeric
            .into_iter()
            .enumerate()
            .filter(|(i, _)| Some(*i) != time_index)
            .filter_map(|(_, l)| l)
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            headers,
            time_index,
            sample_period_s: time.sample_period_s,
            rows,
            first_line,
            first_time_s,
            last_time_s: prev,
            non_numeric,
            gaps,
        })
    }

    /// The file path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Header names.
    pub fn headers(&self) -> &[String] {
        &self.headers
    }

    /// Whether a column exists.
    pub fn has_column(&self, name: &str) -> bool {
        self.headers.iter().any(|h| h == name)
    }

    /// Number of data rows (at least 1).
    pub fn len(&self) -> usize {
        self.rows
    }

    /// `true` without data rows (never, for a scanned trace).
    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// The first row's time \[s\].
    pub fn first_time_s(&self) -> f64 {
        self.first_time_s
    }

    /// The last row's time \[s\].
    pub fn last_time_s(&self) -> f64 {
        self.last_time_s
    }

    /// 1-based file line of the first row.
    pub fn first_line(&self) -> u64 {
        self.first_line
    }

    /// The first non-numeric cell of each column that has one (the time
    /// column excluded), for a warning.
    pub fn non_numeric(&self) -> &[Located] {
        &self.non_numeric
    }

    /// The error for a missing column `name`.
    pub fn missing(&self, name: &str) -> Located {
        missing_column(&self.path, &self.headers, name)
    }

    /// A new pass over the rows, from the first.
    pub fn rows(&self) -> Result<Rows<'_>, Located> {
        let at = |line: u64, col: Option<usize>, msg: String| Located {
            file: self.path.display().to_string(),
            line,
            col,
            msg,
        };
        let mut reader =
            open_csv(&self.path).map_err(|e| at(1, None, format!("cannot open trace: {e}")))?;
        read_headers(&mut reader, &at)?;
        Ok(Rows {
            file: self,
            reader,
            record: csv::StringRecord::new(),
            index: 0,
        })
    }

    /// The median spacing of the rows \[s\] (the element `(n - 1) / 2` of
    /// the `n - 1` sorted spacings; 0 for one row): from the scan's counts
    /// while the distinct spacings are few, else selected 16 bits at a time
    /// over four more passes.
    pub fn median_gap_s(&self) -> Result<f64, Located> {
        if self.rows < 2 {
            return Ok(0.0);
        }
        if let Some(median) = self.gaps.median() {
            return Ok(median);
        }
        let rank = (self.rows as u64 - 1) / 2;
        radix_select(rank, |visit| {
            let mut rows = self.rows()?;
            let mut prev = f64::NAN;
            while let Some(row) = rows.next_row()? {
                if row.index > 0 {
                    visit(row.time_s - prev);
                }
                prev = row.time_s;
            }
            Ok(())
        })
    }
}

/// The element of rank `rank` (0-based) of the positive numbers that
/// `pass` visits (the same numbers on every call), with a 65536-bucket
/// histogram of 16 bits of their bit patterns per pass (a positive `f64`'s
/// bits order as its value).
fn radix_select(
    mut rank: u64,
    mut pass: impl FnMut(&mut dyn FnMut(f64)) -> Result<(), Located>,
) -> Result<f64, Located> {
    let mut prefix = 0u64;
    let mut counts = vec![0u64; 1 << 16];
    for round in 0..4 {
        let shift = 48 - 16 * round;
        counts.fill(0);
        pass(&mut |v: f64| {
            let bits = v.to_bits();
            // Only the numbers whose higher bits match the chosen prefix.
            if round == 0 || bits >> (shift + 16) == prefix >> (shift + 16) {
                counts[((bits >> shift) & 0xffff) as usize] += 1;
            }
        })?;
        let mut digit = 0;
        for (d, n) in counts.iter().enumerate() {
            if rank < *n {
                digit = d as u64;
                break;
            }
            rank -= n;
        }
        prefix |= digit << shift;
    }
    Ok(f64::from_bits(prefix))
}

/// The median of positive numbers pushed one at a time, counted by value
/// while at most `MAX_DISTINCT_GAPS` (4096) are distinct (row spacings, which
/// repeat); `None` beyond.
#[derive(Debug, Clone)]
pub struct GapMedian {
    counts: Option<HashMap<u64, u64>>,
    n: u64,
    cap: usize,
}

impl Default for GapMedian {
    fn default() -> Self {
        Self::with_cap(MAX_DISTINCT_GAPS)
    }
}

impl GapMedian {
    fn with_cap(cap: usize) -> Self {
        Self {
            counts: Some(HashMap::new()),
            n: 0,
            cap,
        }
    }

    /// Counts one number.
    pub fn push(&mut self, v: f64) {
        self.n += 1;
        if let Some(counts) = self.counts.as_mut() {
            *counts.entry(v.to_bits()).or_insert(0) += 1;
            if counts.len() > self.cap {
                self.counts = None;
            }
        }
    }

    /// The element `n / 2` of the `n` sorted numbers (0 without any);
    /// `None` when they were too many distinct ones to count.
    pub fn median(&self) -> Option<f64> {
        if self.n == 0 {
            return Some(0.0);
        }
        let counts = self.counts.as_ref()?;
        let mut sorted: Vec<(f64, u64)> = counts
            .iter()
            .map(|(bits, n)| (f64::from_bits(*bits), *n))
            .collect();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        let rank = self.n / 2;
        let mut below = 0;
        sorted.into_iter().find_map(|(v, n)| {
            below += n;
            (below > rank).then_some(v)
        })
    }
}

/// One pass over a trace's rows.
pub struct Rows<'a> {
    file: &'a TraceFile,
    reader: csv::Reader<File>,
    record: csv::StringRecord,
    index: usize,
}

/// One row of a pass.
pub struct Row<'r> {
    /// 0-based row index.
    pub index: usize,
    /// 1-based file line.
    pub line: u64,
    /// The row's time \[s\].
    pub time_s: f64,
    record: &'r csv::StringRecord,
}

impl Row<'_> {
    /// The text of cell `i` (trimmed).
    pub fn cell(&self, i: usize) -> &str {
        &self.record[i]
    }
}

impl Rows<'_> {
    /// The next row, or `None` after the last.
    pub fn next_row(&mut self) -> Result<Option<Row<'_>>, Located> {
        let file = self.file;
        let at = |line: u64, col: Option<usize>, msg: String| Located {
            file: file.path.display().to_string(),
            line,
            col,
            msg,
        };
        if !self
            .reader
            .read_record(&mut self.record)
            .map_err(|e| csv_error(&at, &e))?
        {
            return Ok(None);
        }
        let index = self.index;
        self.index += 1;
        let time_s = match (file.time_index, file.sample_period_s) {
            (Some(i), _) => cell_value(&self.record[i]),
            (None, Some(p)) => index as f64 * p,
            (None, None) => f64::NAN,
        };
        Ok(Some(Row {
            index,
            line: self.record.position().map_or(0, |p| p.line()),
            time_s,
            record: &self.record,
        }))
    }
}

/// An expression bound to a trace's columns.
#[derive(Debug, Clone)]
struct Bound {
    expr: ColumnExpr,
    /// Each column the expression reads, with its index (`None`: missing).
    columns: Vec<(String, Option<usize>)>,
    allow_missing: bool,
}

/// An expression's first errors: per column argument, and otherwise (an
/// overflow, a step profile starting after the first row).
#[derive(Debug, Clone, Default)]
struct Check {
    args: Vec<Option<Located>>,
    other: Option<Located>,
}

/// Evaluates column expressions row by row, keeping each one's first
/// error.
pub struct Evaluator<'a> {
    file: &'a TraceFile,
    exprs: Vec<Bound>,
    checks: Vec<Check>,
    values: Vec<f64>,
}

impl<'a> Evaluator<'a> {
    /// An evaluator of no expression over `file`.
    pub fn new(file: &'a TraceFile) -> Self {
        Self {
            file,
            exprs: Vec::new(),
            checks: Vec::new(),
            values: Vec::new(),
        }
    }

    /// Adds an expression (with `allow_missing`, empty and `NaN` cells are
    /// missing readings, `NaN`); returns its index in [`Self::eval`]'s
    /// output.
    pub fn add(&mut self, expr: &ColumnExpr, allow_missing: bool) -> usize {
        let columns: Vec<(String, Option<usize>)> = expr
            .columns()
            .into_iter()
            .map(|c| (c.to_string(), self.file.headers.iter().position(|h| h == c)))
            .collect();
        let args = columns
            .iter()
            .map(|(c, i)| i.is_none().then(|| self.file.missing(c)))
            .collect();
        self.exprs.push(Bound {
            expr: expr.clone(),
            columns,
            allow_missing,
        });
        self.checks.push(Check { args, other: None });
        self.exprs.len() - 1
    }

    /// Every expression's value at `row` into `out` (`NaN` where a cell
    /// fails; the failure is kept for [`Self::error`]).
    pub fn eval(&mut self, row: &Row, out: &mut Vec<f64>) {
        out.clear();
        let file = self.file;
        for (b, check) in self.exprs.iter().zip(&mut self.checks) {
            self.values.clear();
            for (a, (name, index)) in b.columns.iter().enumerate() {
                let v = match index {
                    None => f64::NAN,
                    Some(i) => {
                        let cell = row.cell(*i);
                        cell_checked(cell_value(cell), cell, b.allow_missing).unwrap_or_else(
                            |msg| {
                                check.args[a].get_or_insert_with(|| Located {
                                    file: file.path.display().to_string(),
                                    line: row.line,
                                    col: Some(i + 1),
                                    msg: format!("column `{name}`: {msg}"),
                                });
                                f64::NAN
                            },
                        )
                    }
                };
                self.values.push(v);
            }
            let x = &self.values;
            let value = match &b.expr {
                ColumnExpr::Column(_) => x[0],
                ColumnExpr::Abs(_) => x[0].abs(),
                ColumnExpr::Scale(_, k) => x[0] * k,
                ColumnExpr::Constant(_) | ColumnExpr::Steps(_) => {
                    if row.index == 0 {
                        if let Err(msg) = b.expr.at_times(&[row.time_s]) {
                            check.other.get_or_insert(Located {
                                file: file.path.display().to_string(),
                                line: row.line,
                                col: None,
                                msg,
                            });
                        }
                    }
                    b.expr.value_at(row.time_s)
                }
                // Scaled by the largest magnitude, so that squares of large
                // but finite values do not overflow.
                ColumnExpr::Hypot(_) => x.iter().fold(0.0, |acc: f64, s| acc.hypot(*s)),
                ColumnExpr::Mean(cs) => x.iter().sum::<f64>() / cs.len() as f64,
            };
            if value.is_infinite() && check.other.is_none() {
                check.other = Some(Located {
                    file: file.path.display().to_string(),
                    line: row.line,
                    col: None,
                    msg: format!("`{}` overflows to {value} at this row", b.expr),
                });
            }
            out.push(value);
        }
    }

    /// Expression `i`'s error over the rows evaluated so far: its first
    /// failing column (in argument order), else its first overflow.
    pub fn error(&self, i: usize) -> Option<Located> {
        let check = &self.checks[i];
        check
            .args
            .iter()
            .flatten()
            .next()
            .or(check.other.as_ref())
            .cloned()
    }
}

/// A CSV result written row by row: `time_s`, then one column per name.
///
/// The rows go to a partial file beside the target (`.NAME.partial`),
/// renamed over it by [`Self::finish`]; dropped unfinished (a run that
/// failed), the partial file is removed and the target left as it was. A
/// target that exists and is no regular file (`/dev/null`, a pipe) is
/// written directly.
pub struct CsvOut {
    writer: Option<csv::Writer<File>>,
    path: PathBuf,
    partial: Option<PathBuf>,
    record: Vec<String>,
}

impl CsvOut {
    /// Creates the file and writes the header row.
    pub fn create(path: &Path, names: &[String]) -> Result<Self> {
        let partial = match path.file_name() {
            Some(name) if !path.exists() || path.is_file() => {
                Some(path.with_file_name(format!(".{}.partial", name.to_string_lossy())))
            }
            _ => None,
        };
        let mut w = csv::Writer::from_path(partial.as_deref().unwrap_or(path))
            .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", path.display()))?;
        let mut header = vec![TIME_COLUMN.to_string()];
        header.extend(names.iter().cloned());
        let mut out = Self {
            writer: None,
            path: path.to_path_buf(),
            partial,
            record: Vec::with_capacity(header.len()),
        };
        w.write_record(&header)?;
        out.writer = Some(w);
        Ok(out)
    }

    /// Writes one row: the time \[s\] as Rust prints it; each value that is
    /// an `f32` (what the firmware's observers compute, widened) as the
    /// shortest decimal that reads back as that `f32`, so that a replay's
    /// CSV holds the MCU's numbers to the bit; any other value, and zero,
    /// with 6 decimals.
    pub fn row(&mut self, time_s: f64, values: impl IntoIterator<Item = f64>) -> Result<()> {
        use std::fmt::Write;
        // Reuse the cells' strings: no allocation per row once warm.
        let mut n = 0;
        let mut put = |n: &mut usize, args: std::fmt::Arguments| {
            if *n == self.record.len() {
                self.record.push(String::new());
            }
            let cell = &mut self.record[*n];
            cell.clear();
            cell.write_fmt(args).expect("a String takes any text");
            *n += 1;
        };
        put(&mut n, format_args!("{time_s}"));
        for v in values {
            // A value the firmware computed (an `f32`) is written exactly:
            // its shortest decimal, which reads back as the same `f32`.
            let narrow = v as f32;
            if f64::from(narrow) == v && v != 0.0 {
                put(&mut n, format_args!("{narrow}"));
            } else {
                put(&mut n, format_args!("{v:.6}"));
            }
        }
        self.writer
            .as_mut()
            .expect("open until finished")
            .write_record(&self.record[..n])?;
        Ok(())
    }

    /// Flushes the rows and puts the file in place.
    pub fn finish(mut self) -> Result<()> {
        let mut w = self.writer.take().expect("open until finished");
        w.flush()
            .map_err(|e| anyhow::anyhow!("{}: cannot write: {e}", self.path.display()))?;
        drop(w);
        if let Some(partial) = self.partial.take() {
            std::fs::rename(&partial, &self.path).map_err(|e| {
                let _ = std::fs::remove_file(&partial);
                anyhow::anyhow!("{}: cannot write: {e}", self.path.display())
            })?;
        }
        Ok(())
    }
}

impl Drop for CsvOut {
    fn drop(&mut self) {
        if let Some(partial) = self.partial.take() {
            self.writer = None;
            let _ = std::fs::remove_file(partial);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trace::Trace;

    use crate::trace::tests::write;

    /// The median spacing from the counts, and by radix selection when
    /// the spacings are too many to count, equals the sorted one.
    #[test]
    fn the_median_spacing_is_exact_counted_or_selected() {
        let mut rng = crate::synth::Rng::new(7);
        let mut text = String::from("time_s,x\n");
        let mut t = 0.0;
        for _ in 0..2001 {
            t += 0.1 + 0.01 * rng.uniform();
            text.push_str(&format!("{t},1\n"));
        }
        let (_d, path) = write(&text);
        let whole = Trace::read(&path, None).unwrap();
        let mut dt: Vec<f64> = whole.time_s().windows(2).map(|w| w[1] - w[0]).collect();
        dt.sort_by(f64::total_cmp);
        let expected = dt[dt.len() / 2];
        for cap in [MAX_DISTINCT_GAPS, 10] {
            let file = TraceFile::scan_with(&path, &TimeSource::default(), cap).unwrap();
            assert_eq!(file.gaps.counts.is_some(), cap > 10);
            assert_eq!(file.median_gap_s().unwrap().to_bits(), expected.to_bits());
        }
    }

    /// The evaluator's values and first errors are those of the
    /// whole-trace code.
    #[test]
    fn row_by_row_evaluation_matches_the_whole_trace() {
        let (_d, path) = write("time_s,a,b,c\n0,3e200,4e200,1\n1,3,,x\n2,nan,4,inf\n3,1e308,1,2\n");
        let whole = Trace::read(&path, None).unwrap();
        let file = TraceFile::scan(&path, &TimeSource::default()).unwrap();
        let exprs = [
            "hypot(a,b)",
            "a",
            "b",
            "c",
            "scale(a,10)",
            "mean(b,a)",
            "abs(a)",
            "zz",
            "1:5,2:6",
            "0:5,2:6",
        ];
        for allow in [false, true] {
            let mut ev = Evaluator::new(&file);
            let parsed: Vec<ColumnExpr> = exprs
                .iter()
                .map(|e| ColumnExpr::parse(e).unwrap())
                .collect();
            for e in &parsed {
                ev.add(e, allow);
            }
            let mut rows = file.rows().unwrap();
            let mut out = Vec::new();
            let mut got: Vec<Vec<f64>> = vec![Vec::new(); exprs.len()];
            while let Some(row) = rows.next_row().unwrap() {
                ev.eval(&row, &mut out);
                for (g, v) in got.iter_mut().zip(&out) {
                    g.push(*v);
                }
            }
            for (i, e) in parsed.iter().enumerate() {
                match whole.eval_with(e, allow) {
                    Ok(v) => {
                        assert!(ev.error(i).is_none(), "{e}");
                        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(&v), bits(&got[i]), "{e}");
                    }
                    Err(err) => assert_eq!(Some(err), ev.error(i), "{e} {allow}"),
                }
            }
        }
    }

    /// The scan refuses what the whole-trace reader refuses, with the same
    /// error.
    #[test]
    fn the_scan_gives_the_readers_errors() {
        for text in [
            "time_s,a\n",
            "time_s,a\n0,1\n0,2\n",
            "time_s,a\n0,1\nx,2\n1,3,4\n",
            "time_s,a\n0,1\n1e300,2\n",
            "time_s,a\n0,1\n,2\n-1,1\n",
            "t,a\n0,1\n",
            "time_s,a,a\n0,1,1\n",
        ] {
            let (_d, path) = write(text);
            let whole = Trace::read(&path, None).map(|_| ());
            let scan = TraceFile::scan(&path, &TimeSource::default()).map(|_| ());
            assert_eq!(whole, scan, "{text}");
        }
        let (_d, path) = write("a\n1\n2\nx\n");
        let time = TimeSource {
            column: None,
            sample_period_s: Some(0.5),
        };
        let file = TraceFile::scan(&path, &time).unwrap();
        assert_eq!((file.len(), file.last_time_s()), (3, 1.0));
        assert_eq!(file.non_numeric().len(), 1);
        assert_eq!(file.median_gap_s().unwrap(), 0.5);
    }

    /// An `f32` value is written so that it reads back to the bit; an
    /// `f64` one that is not an `f32` keeps 6 decimals.
    #[test]
    fn f32_values_read_back_to_the_bit() {
        let dir = tempfile::TempDir::new().unwrap();
        let path = dir.path().join("o.csv");
        let narrow = [128.70001_f32, 1.0e-7, -40.123_46, 3.4e38, f32::MIN_POSITIVE];
        let mut out = CsvOut::create(&path, &["a".into(), "b".into()]).unwrap();
        for v in narrow {
            out.row(1.0, [f64::from(v), 1.0 / 3.0]).unwrap();
        }
        out.finish().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        for (line, v) in text.lines().skip(1).zip(narrow) {
            let cells: Vec<&str> = line.split(',').collect();
            let back: f64 = cells[1].parse().unwrap();
            assert_eq!((back as f32).to_bits(), v.to_bits(), "{line}");
            assert_eq!(cells[2], "0.333333");
        }
    }

    /// A result file appears whole on success and not at all on failure.
    #[test]
    fn a_result_appears_only_when_finished() {
        let dir = tempfile::TempDir::new().unwrap();
        let path = dir.path().join("o.csv");
        let mut out = CsvOut::create(&path, &["a".into()]).unwrap();
        out.row(0.5, [1.0]).unwrap();
        drop(out);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let mut out = CsvOut::create(&path, &["a".into()]).unwrap();
        out.row(0.5, [1.0]).unwrap();
        out.finish().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "time_s,a\n0.5,1\n");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
