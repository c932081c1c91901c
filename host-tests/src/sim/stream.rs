//! A run's inputs row by row: from a trace file read as a stream
//! ([`TraceDrive`], the streaming form of [`Drive::from_trace`]) or from a
//! [`Drive`] held in memory, behind one [`RowSource`].

use anyhow::{anyhow, bail, Context, Result};

use super::{Bindings, Drive, PlantInfo};
use crate::model_file::InputHold;
use crate::trace::{ColumnExpr, Evaluator, Located, Rows, TraceFile};

/// The inputs of one row.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InputRow {
    /// 0-based row index.
    pub index: usize,
    /// The row's time \[s\].
    pub time_s: f64,
    /// Currents per input \[A\].
    pub currents: Vec<f64>,
    /// Boundary temperatures \[degC\].
    pub boundaries: Vec<f64>,
    /// Extra signals.
    pub signals: Vec<f64>,
    /// The extra expressions' values ([`TraceDrive::add`]), in the order
    /// they were added (`NaN`: a missing reading).
    pub extra: Vec<f64>,
    /// The sensor faults a conversion of an `extra` value met (its
    /// position in `extra`, the fault; the value is then `NaN`): see
    /// [`crate::raw_sensors`].
    pub faults: Vec<(usize, coil_thermal::SensorFault)>,
}

/// Rows of inputs, one at a time, in increasing time.
pub trait RowSource {
    /// The next row, or `None` after the last.
    fn next_row(&mut self) -> Result<Option<InputRow>>;
}

impl Drive {
    /// The rows, one at a time.
    pub fn rows(&self) -> DriveRows<'_> {
        DriveRows { drive: self, k: 0 }
    }
}

/// The rows of a [`Drive`] held in memory.
pub struct DriveRows<'a> {
    drive: &'a Drive,
    k: usize,
}

impl RowSource for DriveRows<'_> {
    fn next_row(&mut self) -> Result<Option<InputRow>> {
        if self.k >= self.drive.len() {
            return Ok(None);
        }
        let mut row = InputRow {
            index: self.k,
            time_s: self.drive.time_s[self.k],
            ..InputRow::default()
        };
        self.drive.row(
            self.k,
            &mut row.currents,
            &mut row.boundaries,
            &mut row.signals,
        );
        self.k += 1;
        Ok(Some(row))
    }
}

/// Where one channel's values come from.
enum Source {
    /// An expression of the evaluator.
    Expr(usize),
    /// A `--const` constant or step profile for a column the trace lacks.
    Const(ColumnExpr),
    /// The boundary's own `value_c`.
    Value(f64),
}

/// One channel: what it is (for errors) and its source, or the error
/// [`Drive::from_trace`] met resolving it.
struct Planned {
    what: String,
    source: Result<Source, anyhow::Error>,
}

/// A trace's channels for a plant, resolved once against its header and
/// evaluated row by row in constant memory: what [`Drive::from_trace`]
/// computes, with the same values and errors, without holding the rows.
pub struct TraceDrive<'a> {
    file: &'a TraceFile,
    ev: Evaluator<'a>,
    currents: Vec<Planned>,
    boundaries: Vec<Planned>,
    signals: Vec<Planned>,
    current_scale: Option<f64>,
    hold: InputHold,
    /// Extra expressions (sensors): their evaluator index, and whether a
    /// pass saw a reading.
    extra: Vec<(usize, bool)>,
}

impl<'a> TraceDrive<'a> {
    /// Resolves every channel of `info` against `file` as
    /// [`Drive::from_trace`] does; with [`InputHold::End`] each row carries
    /// the next row's inputs (see [`Drive::held`]). Unknown inputs and
    /// boundaries in `bind` are refused here; a channel's own errors wait
    /// for [`Self::check`] after a pass.
    pub fn new(
        info: &PlantInfo,
        file: &'a TraceFile,
        bind: &Bindings,
        hold: InputHold,
    ) -> Result<Self> {
        bind.check_names(info)?;
        let path = file.path().display().to_string();
        let mut ev = Evaluator::new(file);
        let mut column = |text: &str, what: String| -> Planned {
            let source = (|| {
                let expr = ColumnExpr::parse(text).with_context(|| format!("{path}: {what}"))?;
                let cols = expr.columns();
                if let Some(missing) = cols.iter().find(|c| !file.has_column(c)) {
                    if let Some((_, v)) = bind.constants.iter().rev().find(|(c, _)| c == missing) {
                        if cols.len() == 1 {
                            v.at_times(&[file.first_time_s()])
                                .map_err(|e| anyhow!("{path}: --const {missing}: {e}"))?;
                            return Ok(Source::Const(v.clone()));
                        }
                    }
                }
                Ok(Source::Expr(ev.add(&expr, false)))
            })();
            Planned { what, source }
        };
        let currents = info
            .inputs
            .iter()
            .map(|input| {
                column(
                    &bind.current_column(input),
                    format!("current input `{}`", input.name),
                )
            })
            .collect();
        let boundaries = info
            .boundaries
            .iter()
            .map(|b| {
                let what = format!("boundary `{}`", b.name);
                match bind.boundary_column(b, file.has_column(&b.column)) {
                    Ok(text) => column(&text, what),
                    Err(value_c) => Planned {
                        what,
                        source: Ok(Source::Value(value_c)),
                    },
                }
            })
            .collect();
        let signals = info
            .signals
            .iter()
            .map(|s| column(s, format!("signal `{s}`")))
            .collect();
        Ok(Self {
            file,
            ev,
            currents,
            boundaries,
            signals,
            current_scale: bind.current_scale,
            hold,
            extra: Vec::new(),
        })
    }

    /// The trace.
    pub fn file(&self) -> &'a TraceFile {
        self.file
    }

    /// Adds an expression whose value every row carries in
    /// [`InputRow::extra`] (a sensor; with `allow_missing`, empty and
    /// `NaN` cells are missing readings); returns its position there.
    pub fn add(&mut self, expr: &ColumnExpr, allow_missing: bool) -> usize {
        let i = self.ev.add(expr, allow_missing);
        self.extra.push((i, false));
        self.extra.len() - 1
    }

    /// Extra expression `j`'s first error over the passes so far.
    pub fn extra_error(&self, j: usize) -> Option<Located> {
        self.ev.error(self.extra[j].0)
    }

    /// Whether a pass saw a reading (not `NaN`) of extra expression `j`.
    pub fn extra_seen(&self, j: usize) -> bool {
        self.extra[j].1
    }

    /// After a full pass, the first error of the channels in
    /// [`Drive::from_trace`]'s order (currents, boundaries, signals), as
    /// it reports it.
    pub fn check(&mut self) -> Result<()> {
        let ev = &self.ev;
        for p in self
            .currents
            .iter_mut()
            .chain(&mut self.boundaries)
            .chain(&mut self.signals)
        {
            match &mut p.source {
                Err(e) => return Err(std::mem::replace(e, anyhow!("reported"))),
                Ok(Source::Expr(i)) => {
                    if let Some(e) = ev.error(*i) {
                        bail!("{e} (for {})", p.what);
                    }
                }
                Ok(_) => {}
            }
        }
        Ok(())
    }

    /// A new pass over the rows.
    pub fn rows(&mut self) -> Result<TraceRows<'_, 'a>> {
        let rows = self.file.rows()?;
        Ok(TraceRows {
            drive: self,
            rows,
            pending: None,
            started: false,
            values: Vec::new(),
        })
    }

    fn row_of(&mut self, index: usize, time_s: f64, values: &[f64]) -> InputRow {
        let value = |p: &Planned| match &p.source {
            Ok(Source::Expr(i)) => values[*i],
            Ok(Source::Const(e)) => e.value_at(time_s),
            Ok(Source::Value(v)) => *v,
            Err(_) => f64::NAN,
        };
        let mut currents: Vec<f64> = self.currents.iter().map(value).collect();
        if let Some(k) = self.current_scale {
            currents.iter_mut().for_each(|i| *i *= k);
        }
        let extra = self
            .extra
            .iter_mut()
            .map(|(i, seen)| {
                let v = values[*i];
                *seen |= !v.is_nan();
                v
            })
            .collect();
        InputRow {
            index,
            time_s,
            currents,
            boundaries: self.boundaries.iter().map(value).collect(),
            signals: self.signals.iter().map(value).collect(),
            extra,
            faults: Vec::new(),
        }
    }
}

/// One pass of a [`TraceDrive`] over its trace.
pub struct TraceRows<'d, 'a> {
    drive: &'d mut TraceDrive<'a>,
    rows: Rows<'a>,
    /// The row read ahead (the inputs a held row takes).
    pending: Option<InputRow>,
    started: bool,
    values: Vec<f64>,
}

impl TraceRows<'_, '_> {
    fn read(&mut self) -> Result<Option<InputRow>> {
        let Some(row) = self.rows.next_row()? else {
            return Ok(None);
        };
        self.drive.ev.eval(&row, &mut self.values);
        let (index, time_s) = (row.index, row.time_s);
        Ok(Some(self.drive.row_of(index, time_s, &self.values)))
    }
}

impl RowSource for TraceRows<'_, '_> {
    fn next_row(&mut self) -> Result<Option<InputRow>> {
        if !self.started {
            self.started = true;
            self.pending = self.read()?;
        }
        let Some(mut row) = self.pending.take() else {
            return Ok(None);
        };
        self.pending = self.read()?;
        if let (InputHold::End, Some(next)) = (self.drive.hold, &self.pending) {
            row.currents.clone_from(&next.currents);
            row.boundaries.clone_from(&next.boundaries);
            row.signals.clone_from(&next.signals);
        }
        Ok(Some(row))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model_file::{Model, ModelFile};
    use crate::trace::{TimeSource, Trace};

    /// A streamed drive's rows are the held drive's, bit for bit.
    #[test]
    fn streamed_rows_are_the_drives() {
        let dir = tempfile::TempDir::new().unwrap();
        let path = dir.path().join("t.csv");
        std::fs::write(&path, "time_s,current,T\n0,1,20\n1,2,\n3,0.5,21\n").unwrap();
        let file = ModelFile::load(&std::path::PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/models/two-node-coil.toml"
        )))
        .unwrap();
        let model = Model::build(&file).unwrap();
        let info = crate::sim::plant_info(&model);
        let bind = Bindings {
            current_scale: Some(1.5),
            constants: vec![("ambient".into(), ColumnExpr::parse("0:20,2:25").unwrap())],
            ..Bindings::default()
        };
        for hold in [InputHold::Start, InputHold::End] {
            let whole = Drive::from_trace(&info, &Trace::read(&path, None).unwrap(), &bind)
                .unwrap()
                .held(hold);
            let scanned = TraceFile::scan(&path, &TimeSource::default()).unwrap();
            let mut drive = TraceDrive::new(&info, &scanned, &bind, hold).unwrap();
            let t = drive.add(&ColumnExpr::parse("T").unwrap(), true);
            let mut rows = drive.rows().unwrap();
            let mut expected = whole.rows();
            while let Some(mut row) = rows.next_row().unwrap() {
                assert!(row.index < 2 || row.extra[t] == 21.0);
                row.extra.clear();
                assert_eq!(Some(row), expected.next_row().unwrap());
            }
            assert!(expected.next_row().unwrap().is_none());
            drive.check().unwrap();
            assert!(drive.extra_seen(t) && drive.extra_error(t).is_none());
        }
    }
}
