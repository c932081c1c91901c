//! Plots of a run, as PNG or SVG (chosen by the file extension), drawn to
//! be read at a glance:
//!
//! * estimates as thin solid lines; truth and measurements thick and
//!   dashed in a darker shade of their node's colour, drawn on top; fused
//!   sensor readings as open circles on their node;
//! * each node's own limit (a derated alarm limit, or a critical
//!   temperature) as a dashed line in its node's colour, labelled at its
//!   right end (nodes sharing one value share one line); `--limit-c` lines
//!   each in their own colour and dash, labelled;
//! * events as compact markers: warnings (orange triangles) and predictive
//!   alarms (violet crosses) on their node's curve, a shutdown as a red
//!   line with its triangle;
//! * the legend in the corner the curves leave emptiest;
//! * optional panels: residuals, estimate minus truth \[K\] (for
//!   `replay --truth` and `calibrate`), then the currents \[A\];
//! * an optional time window that clips every series and event.

use std::path::Path;

use anyhow::{anyhow, bail, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Warning markers.
const ORANGE: RGBColor = RGBColor(255, 140, 0);
/// Predictive alarm markers.
const VIOLET: RGBColor = RGBColor(148, 0, 211);
/// A limit line shared by several nodes.
const GREY: RGBColor = RGBColor(90, 90, 90);
/// Colours of the `--limit-c` lines, one each in turn.
const LIMIT_COLOURS: [RGBColor; 4] = [
    RGBColor(200, 0, 0),
    RGBColor(120, 60, 0),
    RGBColor(0, 90, 160),
    RGBColor(110, 0, 110),
];

/// One time series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Times \[s\].
    pub time_s: Vec<f64>,
    /// Values (degC, K or A).
    pub values: Vec<f64>,
    /// Palette index (a measured series takes its node's colour).
    pub color: usize,
}

/// One node's own limit line.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeLimit {
    /// The node's name.
    pub node: String,
    /// What the line is, e.g. `alarm limit` or `critical`.
    pub kind: String,
    /// The limit \[degC\].
    pub limit_c: f64,
    /// The node's palette index.
    pub color: usize,
}

/// Everything one figure shows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlotData {
    /// Figure title.
    pub title: String,
    /// Estimated temperatures \[degC\].
    pub estimated: Vec<Series>,
    /// Protective upper bounds \[degC\] (what the alarm and the limiter act
    /// on): a thin dotted line in their node's colour, above its estimate.
    pub upper: Vec<Series>,
    /// Truth and measured temperatures \[degC\], not fused.
    pub measured: Vec<Series>,
    /// Sensor readings the observer fused \[degC\].
    pub fused: Vec<Series>,
    /// Estimate minus truth \[K\] (a residual panel when present).
    pub residuals: Vec<Series>,
    /// Currents \[A\] (the last panel when present).
    pub currents: Vec<Series>,
    /// Each node's own limit.
    pub node_limits: Vec<NodeLimit>,
    /// Other horizontal limits: (label, degC).
    pub limits: Vec<(String, f64)>,
    /// Shutdown markers, red: (time s, node).
    pub alarms: Vec<(f64, String)>,
    /// Warning markers, orange: (time s, node).
    pub warnings: Vec<(f64, String)>,
    /// Predictive alarm markers, violet: (time s, node).
    pub predictive: Vec<(f64, String)>,
}

/// A horizontal line as drawn: its label, value \[degC\] and colour.
#[derive(Debug, Clone, PartialEq)]
pub struct LimitLine {
    /// The label written at its right end.
    pub label: String,
    /// Value \[degC\].
    pub value_c: f64,
    /// Colour.
    pub colour: RGBColor,
    /// Dash length \[px\] (the gap is 4 px).
    pub dash: u32,
}

/// The lines a figure draws for its limits: one per distinct node limit (in
/// the node's colour, or grey with the count of nodes sharing it), then
/// each `--limit-c`, each in its own colour and dash.
pub fn limit_lines(data: &PlotData) -> Vec<LimitLine> {
    let mut groups: Vec<(f64, &str, Vec<&NodeLimit>)> = Vec::new();
    for l in &data.node_limits {
        match groups
            .iter_mut()
            .find(|g| (g.0 - l.limit_c).abs() < 1e-9 && g.1 == l.kind)
        {
            Some(g) => g.2.push(l),
            None => groups.push((l.limit_c, &l.kind, vec![l])),
        }
    }
    let mut lines: Vec<LimitLine> = groups
        .into_iter()
        .map(|(value_c, kind, nodes)| match nodes.as_slice() {
            [one] => LimitLine {
                label: format!("{} {kind} {value_c:.1} degC", one.node),
                value_c,
                colour: color(one.color),
                dash: 10,
            },
            many => LimitLine {
                label: format!("{} nodes: {kind} {value_c:.1} degC", many.len()),
                value_c,
                colour: GREY,
                dash: 10,
            },
        })
        .collect();
    for (k, (label, value_c)) in data.limits.iter().enumerate() {
        lines.push(LimitLine {
            label: format!("{label} {value_c:.1} degC"),
            value_c: *value_c,
            colour: LIMIT_COLOURS[k % LIMIT_COLOURS.len()],
            dash: [3, 8, 14, 20][k % 4],
        });
    }
    lines
}

impl PlotData {
    /// The same figure between `from_s` and `to_s` \[s\]: every series and
    /// event clipped to the window. Refused when the window is empty or no
    /// temperature is left in it.
    pub fn windowed(&self, from_s: Option<f64>, to_s: Option<f64>) -> Result<PlotData> {
        let from = from_s.unwrap_or(f64::NEG_INFINITY);
        let to = to_s.unwrap_or(f64::INFINITY);
        if from.is_nan() || to.is_nan() || from >= to {
            bail!("the plot window must have --from-s below --to-s, got {from} and {to}");
        }
        let inside = |t: f64| (from..=to).contains(&t);
        let clip = |all: &[Series]| -> Vec<Series> {
            all.iter()
                .map(|s| {
                    let (time_s, values) = s
                        .time_s
                        .iter()
                        .zip(&s.values)
                        .filter(|(t, _)| inside(**t))
                        .map(|(t, v)| (*t, *v))
                        .unzip();
                    Series {
                        time_s,
                        values,
                        ..s.clone()
                    }
                })
                .filter(|s| !s.time_s.is_empty())
                .collect()
        };
        let events = |all: &[(f64, String)]| -> Vec<(f64, String)> {
            all.iter().filter(|e| inside(e.0)).cloned().collect()
        };
        let out = PlotData {
            title: self.title.clone(),
            estimated: clip(&self.estimated),
            upper: clip(&self.upper),
            measured: clip(&self.measured),
            fused: clip(&self.fused),
            residuals: clip(&self.residuals),
            currents: clip(&self.currents),
            node_limits: self.node_limits.clone(),
            limits: self.limits.clone(),
            alarms: events(&self.alarms),
            warnings: events(&self.warnings),
            predictive: events(&self.predictive),
        };
        if out.estimated.is_empty() && out.measured.is_empty() {
            bail!("no temperature between {from} s and {to} s: widen the plot window");
        }
        Ok(out)
    }
}

/// Most points drawn per series (longer series are decimated).
pub const MAX_POINTS: usize = 4000;
/// Most markers drawn per fused sensor.
const MAX_MARKERS: usize = 150;

/// The largest magnitude a plotted temperature or current may have; beyond
/// it the axes cannot be laid out (and no thermal model reads that).
pub const MAX_PLOT_MAGNITUDE: f64 = 1e9;

fn points(s: &Series, most: usize) -> Vec<(f64, f64)> {
    let finite = s
        .time_s
        .iter()
        .zip(&s.values)
        .filter(|(t, v)| t.is_finite() && v.is_finite())
        .map(|(t, v)| (*t, *v));
    if s.time_s.len() <= most {
        return finite.collect();
    }
    let mut d = Decimated::with_buckets(most / 4);
    finite.for_each(|(t, v)| d.push(t, v));
    d.points().into_iter().map(|p| (p.t, p.v)).collect()
}

/// One sample of a [`Decimated`] series: its index, time \[s\] and value.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Point {
    k: usize,
    t: f64,
    v: f64,
}

/// The samples a bucket keeps: its first, lowest, highest and last.
#[derive(Debug, Clone, Copy)]
struct Bucket {
    first: Point,
    min: Point,
    max: Point,
    last: Point,
    samples: usize,
}

impl Bucket {
    fn new(p: Point) -> Self {
        Self {
            first: p,
            min: p,
            max: p,
            last: p,
            samples: 1,
        }
    }

    fn take(&mut self, p: Point) {
        if p.v < self.min.v {
            self.min = p;
        }
        if p.v > self.max.v {
            self.max = p;
        }
        self.last = p;
        self.samples += 1;
    }

    fn merged(self, later: Bucket) -> Self {
        Self {
            first: self.first,
            min: if later.min.v < self.min.v {
                later.min
            } else {
                self.min
            },
            max: if later.max.v > self.max.v {
                later.max
            } else {
                self.max
            },
            last: later.last,
            samples: self.samples + later.samples,
        }
    }
}

/// A series reduced as it comes, in memory that does not grow with it:
/// consecutive samples share a bucket that keeps its first, lowest,
/// highest and last sample, so no peak is lost from a figure; when the
/// buckets fill, neighbours merge and each bucket takes twice the samples.
/// A series of at most the bucket count is kept whole. The first sample
/// beyond +-[`MAX_PLOT_MAGNITUDE`] is kept too, for the refusal that names
/// it. `NaN` values (missing readings) are skipped.
#[derive(Debug, Clone)]
pub struct Decimated {
    buckets: Vec<Bucket>,
    current: Option<Bucket>,
    /// Samples per bucket.
    per: usize,
    most: usize,
    seen: usize,
    beyond: Option<Point>,
}

impl Default for Decimated {
    /// At most [`MAX_POINTS`] points: drawn as they are.
    fn default() -> Self {
        // 4 points a bucket, the partial bucket and the first sample
        // beyond the plottable range included.
        Self::with_buckets((MAX_POINTS - 5) / 4 / 2 * 2)
    }
}

impl Decimated {
    /// A series of at most `buckets` buckets (4 points each).
    pub fn with_buckets(buckets: usize) -> Self {
        Self {
            buckets: Vec::new(),
            current: None,
            per: 1,
            most: buckets.max(2) / 2 * 2,
            seen: 0,
            beyond: None,
        }
    }

    /// Adds a sample at `t` \[s\] (`NaN` values are skipped).
    pub fn push(&mut self, t: f64, v: f64) {
        if v.is_nan() {
            return;
        }
        let p = Point { k: self.seen, t, v };
        self.seen += 1;
        if self.beyond.is_none() && (v.is_infinite() || v.abs() > MAX_PLOT_MAGNITUDE) {
            self.beyond = Some(p);
        }
        match self.current.as_mut() {
            Some(b) if b.samples < self.per => b.take(p),
            _ => {
                if let Some(full) = self.current.take() {
                    self.buckets.push(full);
                }
                if self.buckets.len() >= self.most {
                    let pairs: Vec<Bucket> = self
                        .buckets
                        .chunks(2)
                        .map(|c| {
                            if c.len() == 2 {
                                c[0].merged(c[1])
                            } else {
                                c[0]
                            }
                        })
                        .collect();
                    self.buckets = pairs;
                    self.per *= 2;
                }
                self.current = Some(Bucket::new(p));
            }
        }
    }

    /// The kept samples in order.
    fn points(&self) -> Vec<Point> {
        let mut out: Vec<Point> = Vec::new();
        for b in self.buckets.iter().chain(&self.current) {
            let mut four = [b.first, b.min, b.max, b.last];
            four.sort_by_key(|p| p.k);
            for p in four {
                if out.last().is_none_or(|l| l.k < p.k) {
                    out.push(p);
                }
            }
        }
        if let Some(p) = self.beyond {
            let at = out.partition_point(|q| q.k < p.k);
            if out.get(at).is_none_or(|q| q.k != p.k) {
                out.insert(at, p);
            }
        }
        out
    }

    /// The series to draw.
    pub fn series(&self, label: String, color: usize) -> Series {
        let (time_s, values) = self.points().into_iter().map(|p| (p.t, p.v)).unzip();
        Series {
            label,
            time_s,
            values,
            color,
        }
    }

    /// The largest value pushed (`f64::MIN` before any).
    pub fn max(&self) -> f64 {
        self.buckets
            .iter()
            .chain(&self.current)
            .map(|b| b.max.v)
            .fold(f64::MIN, f64::max)
    }
}

/// A thick polyline as separate two-point segments: drawn as one path,
/// its miter joins spike far out of the chart at the sharp turns of a
/// dense series (a decimated one turns at each bucket's lowest and
/// highest sample); segments have no joins.
fn segments(
    points: Vec<(f64, f64)>,
    style: ShapeStyle,
) -> impl Iterator<Item = PathElement<(f64, f64)>> {
    (1..points.len().max(1)).map(move |i| PathElement::new(vec![points[i - 1], points[i]], style))
}

fn range(series: &[&Series], extra: &[f64]) -> Option<(f64, f64, f64, f64)> {
    let mut r: Option<(f64, f64, f64, f64)> = None;
    for s in series {
        for (t, v) in s.time_s.iter().zip(&s.values) {
            if !(t.is_finite() && v.is_finite()) {
                continue;
            }
            let e = r.get_or_insert((*t, *t, *v, *v));
            *e = (e.0.min(*t), e.1.max(*t), e.2.min(*v), e.3.max(*v));
        }
    }
    if let Some(e) = r.as_mut() {
        for v in extra {
            e.2 = e.2.min(*v);
            e.3 = e.3.max(*v);
        }
    }
    r.map(|(t0, t1, v0, v1)| {
        let pad = ((v1 - v0) * 0.05).max(0.5);
        (t0, if t1 > t0 { t1 } else { t0 + 1.0 }, v0 - pad, v1 + pad)
    })
}

/// Refuses an axis whose span overflows: plotters would loop over its
/// ticks for ever.
fn finite_span(what: &str, lo: f64, hi: f64) -> Result<()> {
    if !(hi - lo).is_finite() {
        bail!("plot: the {what}s span {lo:e} to {hi:e}, more than a plot can scale: is the run diverging?");
    }
    Ok(())
}

fn color(i: usize) -> RGBColor {
    let c = Palette99::pick(i).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

fn darker(c: RGBColor) -> RGBColor {
    RGBColor(c.0 / 2, c.1 / 2, c.2 / 2)
}

/// The corner of the temperature panel where the legend hides the fewest
/// points: each corner box (40 % of the width, 35 % of the height) counts
/// the points of every series inside it, and each limit's label at
/// `labels` (time s, value) counts as many; ties go to the upper left, then
/// upper right, lower right, lower left.
pub fn legend_corner(
    series: &[&Series],
    labels: &[(f64, f64)],
    x: (f64, f64),
    y: (f64, f64),
) -> SeriesLabelPosition {
    let corners = [
        (SeriesLabelPosition::UpperLeft, false, true),
        (SeriesLabelPosition::UpperRight, true, true),
        (SeriesLabelPosition::LowerRight, true, false),
        (SeriesLabelPosition::LowerLeft, false, false),
    ];
    let (w, h) = (
        (x.1 - x.0).max(f64::MIN_POSITIVE),
        (y.1 - y.0).max(f64::MIN_POSITIVE),
    );
    // A limit's label weighs as much as a short curve: the legend must not
    // hide it.
    let label_weight = MAX_POINTS / 10;
    let count = |right: bool, upper: bool| -> usize {
        series
            .iter()
            .flat_map(|s| points(s, MAX_POINTS))
            .chain(
                labels
                    .iter()
                    .flat_map(|p| std::iter::repeat_n(*p, label_weight)),
            )
            .filter(|(t, v)| {
                let (u, z) = ((t - x.0) / w, (v - y.0) / h);
                (if right { u >= 0.6 } else { u <= 0.4 })
                    && (if upper { z >= 0.65 } else { z <= 0.35 })
            })
            .count()
    };
    corners
        .into_iter()
        .min_by_key(|(_, right, upper)| count(*right, *upper))
        .map(|c| c.0)
        .expect("four corners")
}

/// The events worth a marker: per node, none within `spacing_s` of the
/// last one kept (a trajectory raises and clears a predictive alarm every
/// few rows; a marker per event would hide the curves).
pub fn thinned(events: &[(f64, String)], spacing_s: f64) -> Vec<(f64, String)> {
    let mut last: Vec<(&str, f64)> = Vec::new();
    let mut kept = Vec::new();
    for (t, node) in events {
        match last.iter_mut().find(|(n, _)| n == node) {
            Some((_, at)) if (*t - *at).abs() < spacing_s => continue,
            Some((_, at)) => *at = *t,
            None => last.push((node, *t)),
        }
        kept.push((*t, node.clone()));
    }
    kept
}

/// The value of the estimated series of `node` nearest before `time_s`, if
/// that node is drawn.
fn on_curve(data: &PlotData, node: &str, time_s: f64) -> Option<f64> {
    let s = data
        .estimated
        .iter()
        .find(|s| s.label == node || s.label.starts_with(&format!("{node} ")))?;
    let k = s.time_s.partition_point(|t| *t <= time_s);
    s.values
        .get(k.saturating_sub(1))
        .copied()
        .filter(|v| v.is_finite())
}

fn panel<'a, DB: DrawingBackend + 'a>(
    area: &'a DrawingArea<DB, Shift>,
    x: (f64, f64),
    y: (f64, f64),
    x_desc: &str,
    y_desc: &str,
) -> Result<
    ChartContext<
        'a,
        DB,
        Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
    >,
>
where
    DB::ErrorType: 'static,
{
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .margin_right(36)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(|e| anyhow!("plot: {e:?}"))?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .draw()
        .map_err(|e| anyhow!("plot: {e:?}"))?;
    Ok(chart)
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, data: &PlotData) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("plot: {e:?}");
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(&data.title, ("sans-serif", 22)).map_err(e)?;
    // Temperatures take what the lower panels leave.
    let h = root.dim_in_pixel().1 as f64;
    let (residual_h, current_h) = match (data.residuals.is_empty(), data.currents.is_empty()) {
        (true, true) => (0.0, 0.0),
        (true, false) => (0.0, 0.3 * h),
        (false, true) => (0.3 * h, 0.0),
        (false, false) => (0.22 * h, 0.22 * h),
    };
    let (top, rest) = root.split_vertically((h - residual_h - current_h) as u32);
    let (residual_area, current_area) = rest.split_vertically(residual_h as u32);
    let temps: Vec<&Series> = data
        .estimated
        .iter()
        .chain(&data.measured)
        .chain(&data.upper)
        .collect();
    let Some((_, _, d0, d1)) = range(&temps, &[]) else {
        bail!("plot: nothing to draw (no temperature series)");
    };
    // A limit far above the data would squash it: such limits are named in
    // a note instead of drawn.
    let near = |v: f64| v <= d1 + 0.5 * (d1 - d0).max(5.0) && v >= d0 - 0.5 * (d1 - d0).max(5.0);
    let (shown, off): (Vec<_>, Vec<_>) =
        limit_lines(data).into_iter().partition(|l| near(l.value_c));
    let values: Vec<f64> = shown.iter().map(|l| l.value_c).collect();
    let (t0, t1, y0, y1) = range(&temps, &values).expect("series are not empty");
    finite_span("temperature", y0, y1)?;
    // Along the time axis, where a long note has room.
    let mut x_desc = "time [s]".to_string();
    if !off.is_empty() {
        let notes: Vec<String> = off.iter().map(|l| l.label.clone()).collect();
        x_desc.push_str(&format!("    (off scale: {})", notes.join("; ")));
    }
    // Long legends hide the plot: label at most about 10 estimated series.
    let label_every = data.estimated.len().div_ceil(10).max(1);
    let mut chart = panel(&top, (t0, t1), (y0, y1), &x_desc, "temperature [degC]")?;
    for l in &shown {
        let c = l.colour;
        chart
            .draw_series(DashedLineSeries::new(
                vec![(t0, l.value_c), (t1, l.value_c)],
                l.dash,
                4,
                c.stroke_width(2),
            ))
            .map_err(e)?;
        chart
            .draw_series(std::iter::once(Text::new(
                l.label.clone(),
                // Just above its line, at the right end.
                (t1, l.value_c + 0.008 * (y1 - y0)),
                ("sans-serif", 15)
                    .into_font()
                    .color(&darker(c))
                    .pos(Pos::new(HPos::Right, VPos::Bottom)),
            )))
            .map_err(e)?;
    }
    for (k, s) in data.estimated.iter().enumerate() {
        let c = color(s.color);
        let drawn = chart
            .draw_series(segments(points(s, MAX_POINTS), c.stroke_width(2)))
            .map_err(e)?;
        if k % label_every == 0 {
            drawn.label(&s.label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
            });
        }
    }
    for s in &data.upper {
        let c = color(s.color);
        chart
            .draw_series(DashedLineSeries::new(
                points(s, MAX_POINTS),
                2,
                3,
                c.stroke_width(1),
            ))
            .map_err(e)?
            .label(&s.label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(1)));
    }
    // Truth on top of the estimates, so that a good estimate cannot hide it.
    for s in &data.measured {
        let c = darker(color(s.color));
        chart
            .draw_series(DashedLineSeries::new(
                points(s, MAX_POINTS),
                8,
                5,
                // Translucent: the estimate under it stays visible.
                c.mix(0.55).stroke_width(4),
            ))
            .map_err(e)?
            .label(&s.label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(4)));
    }
    for s in &data.fused {
        let c = darker(color(s.color));
        chart
            .draw_series(
                points(s, MAX_MARKERS)
                    .into_iter()
                    .map(|p| Circle::new(p, 4, c.stroke_width(2))),
            )
            .map_err(e)?
            .label(&s.label)
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.stroke_width(2)));
    }
    // Events: compact markers on their node's curve (at the top edge when
    // the node is not drawn); a shutdown also gets its line.
    let at = |node: &str, t: f64| on_curve(data, node, t).unwrap_or(y1 - 0.02 * (y1 - y0));
    // Events of nodes not drawn share one row along the top edge.
    let drawn_or_top = |events: &[(f64, String)]| -> Vec<(f64, String)> {
        events
            .iter()
            .map(|(t, n)| {
                (
                    *t,
                    on_curve(data, n, *t).map_or(String::new(), |_| n.clone()),
                )
            })
            .collect()
    };
    let warnings = thinned(&drawn_or_top(&data.warnings), 0.01 * (t1 - t0));
    for (k, (t, node)) in warnings.iter().enumerate() {
        let drawn = chart
            .draw_series(std::iter::once(TriangleMarker::new(
                (*t, at(node, *t)),
                6,
                ORANGE.filled(),
            )))
            .map_err(e)?;
        if k == 0 {
            drawn
                .label("warning")
                .legend(|(x, y)| TriangleMarker::new((x + 10, y), 5, ORANGE.filled()));
        }
    }
    let predictive = thinned(&drawn_or_top(&data.predictive), 0.01 * (t1 - t0));
    for (k, (t, node)) in predictive.iter().enumerate() {
        let drawn = chart
            .draw_series(std::iter::once(Cross::new(
                (*t, at(node, *t)),
                4,
                VIOLET.stroke_width(2),
            )))
            .map_err(e)?;
        if k == 0 {
            drawn
                .label("predictive alarm")
                .legend(|(x, y)| Cross::new((x + 10, y), 4, VIOLET.stroke_width(2)));
        }
    }
    for (k, (t, node)) in data.alarms.iter().enumerate() {
        chart
            .draw_series(std::iter::once(TriangleMarker::new(
                (*t, at(node, *t)),
                8,
                RED.filled(),
            )))
            .map_err(e)?;
        let drawn = chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(*t, y0), (*t, y1)],
                RED.stroke_width(2),
            )))
            .map_err(e)?;
        if k == 0 {
            drawn.label("shutdown").legend(|(x, y)| {
                PathElement::new(vec![(x + 10, y - 6), (x + 10, y + 6)], RED.stroke_width(2))
            });
        }
    }
    let drawn: Vec<&Series> = temps.iter().copied().chain(&data.fused).collect();
    let label_at: Vec<(f64, f64)> = shown.iter().map(|l| (t1, l.value_c)).collect();
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(legend_corner(&drawn, &label_at, (t0, t1), (y0, y1)))
        .draw()
        .map_err(e)?;
    if !data.residuals.is_empty() {
        let residuals: Vec<&Series> = data.residuals.iter().collect();
        let (_, _, r0, r1) = range(&residuals, &[0.0]).expect("residuals are not empty");
        finite_span("residual", r0, r1)?;
        let mut chart = panel(
            &residual_area,
            (t0, t1),
            (r0, r1),
            "time [s]",
            "residual [K]",
        )?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(t0, 0.0), (t1, 0.0)],
                BLACK,
            )))
            .map_err(e)?;
        for s in &data.residuals {
            let c = darker(color(s.color));
            chart
                .draw_series(segments(points(s, MAX_POINTS), c.stroke_width(2)))
                .map_err(e)?
                .label(&s.label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(legend_corner(&residuals, &[], (t0, t1), (r0, r1)))
            .draw()
            .map_err(e)?;
    }
    if !data.currents.is_empty() {
        let currents: Vec<&Series> = data.currents.iter().collect();
        let (_, _, c0, c1) = range(&currents, &[0.0]).expect("currents are not empty");
        finite_span("current", c0, c1)?;
        let mut chart = panel(&current_area, (t0, t1), (c0, c1), "time [s]", "current [A]")?;
        for s in &data.currents {
            let c = color(s.color);
            chart
                .draw_series(LineSeries::new(points(s, MAX_POINTS), c.stroke_width(1)))
                .map_err(e)?
                .label(&s.label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(legend_corner(&currents, &[], (t0, t1), (c0, c1)))
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

fn check_size(width: u32, height: u32) -> Result<()> {
    if width < 200 || height < 150 {
        bail!("plot size must be at least 200x150 pixels, got {width}x{height}");
    }
    Ok(())
}

/// Renders `data` to `path` (`.png` or `.svg`), `width` x `height` pixels.
pub fn render(data: &PlotData, path: &Path, width: u32, height: u32) -> Result<()> {
    check_size(width, height)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("png") => {
            let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
            draw(root.clone(), data)?;
            root.present()
                .map_err(|e| anyhow!("{}: cannot write PNG: {e:?}", path.display()))?;
        }
        Some("svg") => {
            let root = SVGBackend::new(path, (width, height)).into_drawing_area();
            draw(root.clone(), data)?;
            root.present()
                .map_err(|e| anyhow!("{}: cannot write SVG: {e:?}", path.display()))?;
        }
        _ => bail!("{}: plot file must end in .png or .svg", path.display()),
    }
    Ok(())
}

/// Renders `data` as an SVG document in memory (what the tests read).
pub fn render_svg(data: &PlotData, width: u32, height: u32) -> Result<String> {
    check_size(width, height)?;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        draw(root.clone(), data)?;
        root.present()
            .map_err(|e| anyhow!("cannot write SVG: {e:?}"))?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A decimated series keeps a short one whole, and of a long one at
    /// most MAX_POINTS points with every peak and dip, in time order.
    #[test]
    fn decimation_keeps_the_peaks_in_bounded_points() {
        let mut short = Decimated::default();
        for k in 0..500 {
            short.push(k as f64, (k % 7) as f64);
        }
        let s = short.series("s".into(), 0);
        assert_eq!(
            s.values,
            (0..500).map(|k| (k % 7) as f64).collect::<Vec<_>>()
        );
        let mut long = Decimated::default();
        let n = 2_000_003usize;
        for k in 0..n {
            let v = match k {
                1_234_567 => 99.0,
                777 => -5.0,
                1_500_000 => 2e9,
                _ if k % 3 == 0 => f64::NAN,
                _ => (k as f64 * 1e-3).sin(),
            };
            long.push(k as f64, v);
        }
        let s = long.series("l".into(), 0);
        let n_points = s.time_s.len();
        assert!(
            n_points <= MAX_POINTS && n_points > MAX_POINTS / 4,
            "{n_points}"
        );
        assert!(s.time_s.windows(2).all(|w| w[0] < w[1]));
        for (t, v) in [(1_234_567.0, 99.0), (777.0, -5.0), (1_500_000.0, 2e9)] {
            assert!(s.time_s.iter().zip(&s.values).any(|p| p == (&t, &v)), "{t}");
        }
        assert_eq!(s.time_s[0], 1.0);
        assert_eq!(*s.time_s.last().unwrap(), (n - 1) as f64);
        assert_eq!(long.max(), 2e9);
    }

    fn series(label: &str, color: usize, f: impl Fn(f64) -> f64) -> Series {
        let time_s: Vec<f64> = (0..=600).map(f64::from).collect();
        Series {
            label: label.into(),
            values: time_s.iter().map(|t| f(*t)).collect(),
            time_s,
            color,
        }
    }

    fn heating(label: &str, color: usize, rise_k: f64) -> Series {
        series(label, color, |t| 20.0 + rise_k * (1.0 - (-t / 150.0).exp()))
    }

    fn figure() -> PlotData {
        PlotData {
            title: "test".into(),
            estimated: vec![
                heating("winding (estimate)", 0, 100.0),
                heating("housing (estimate)", 1, 40.0),
                heating("heatsink (estimate)", 2, 20.0),
            ],
            measured: vec![heating("winding_tc (truth -> winding)", 0, 101.0)],
            fused: vec![heating("housing_tc (fused -> housing)", 1, 40.5)],
            residuals: vec![series("winding_tc", 0, |t| (-t / 150.0).exp() - 1.0)],
            node_limits: vec![
                NodeLimit {
                    node: "winding".into(),
                    kind: "alarm limit".into(),
                    limit_c: 118.3,
                    color: 0,
                },
                NodeLimit {
                    node: "housing".into(),
                    kind: "alarm limit".into(),
                    limit_c: 64.0,
                    color: 1,
                },
            ],
            warnings: vec![(300.0, "winding".into())],
            predictive: vec![(200.0, "winding".into())],
            ..PlotData::default()
        }
    }

    #[test]
    fn each_node_limit_is_its_own_labelled_line() {
        let data = figure();
        let lines = limit_lines(&data);
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0].label, "winding alarm limit 118.3 degC");
        assert_eq!(lines[1].label, "housing alarm limit 64.0 degC");
        assert_ne!(lines[0].colour, lines[1].colour);
        let svg = render_svg(&data, 1000, 700).unwrap();
        assert!(svg.contains("winding alarm limit 118.3 degC"));
        assert!(svg.contains("housing alarm limit 64.0 degC"));
        assert!(svg.contains("residual [K]"), "the residual panel");
        assert!(svg.contains("predictive alarm") && svg.contains("warning"));
    }

    #[test]
    fn nodes_sharing_a_limit_share_one_line_and_extra_limits_differ() {
        let mut data = figure();
        data.node_limits = (0..3)
            .map(|i| NodeLimit {
                node: format!("coil_{i}"),
                kind: "critical".into(),
                limit_c: 100.0,
                color: i,
            })
            .collect();
        data.limits = vec![("trip".into(), 90.0), ("derated".into(), 80.0)];
        let lines = limit_lines(&data);
        assert_eq!(lines.len(), 3);
        assert_eq!(lines[0].label, "3 nodes: critical 100.0 degC");
        assert_eq!(
            (lines[1].label.as_str(), lines[2].label.as_str()),
            ("trip 90.0 degC", "derated 80.0 degC")
        );
        assert!(lines[1].colour != lines[2].colour && lines[1].dash != lines[2].dash);
        let svg = render_svg(&data, 1000, 700).unwrap();
        for l in &lines {
            assert!(svg.contains(&l.label), "{} drawn", l.label);
        }
    }

    #[test]
    fn the_legend_avoids_the_peak() {
        let rising = heating("rising", 0, 100.0);
        // Rises to a plateau: the upper right is full, the lower right empty.
        let corner = legend_corner(&[&rising], &[], (0.0, 600.0), (15.0, 125.0));
        assert!(
            matches!(corner, SeriesLabelPosition::LowerRight),
            "{corner:?}"
        );
        let cooling = series("cooling", 0, |t| 20.0 + 100.0 * (-t / 150.0).exp());
        let corner = legend_corner(&[&cooling], &[], (0.0, 600.0), (15.0, 125.0));
        assert!(
            matches!(corner, SeriesLabelPosition::UpperRight),
            "{corner:?}"
        );
        // A limit labelled at the upper right end moves it from there.
        let corner = legend_corner(&[&cooling], &[(600.0, 110.0)], (0.0, 600.0), (15.0, 125.0));
        assert!(
            !matches!(corner, SeriesLabelPosition::UpperRight),
            "{corner:?}"
        );
    }

    #[test]
    fn markers_are_thinned_per_node() {
        let events: Vec<(f64, String)> = (0..100)
            .flat_map(|k| {
                [
                    (f64::from(k), "a".to_string()),
                    (f64::from(k), "b".to_string()),
                ]
            })
            .collect();
        let kept = thinned(&events, 10.0);
        assert_eq!(kept.len(), 20, "every 10 s, for each of the two nodes");
        assert_eq!(kept[2], (10.0, "a".to_string()));
    }

    #[test]
    fn the_window_clips_series_and_events() {
        let data = figure();
        let w = data.windowed(Some(100.0), Some(250.0)).unwrap();
        for s in w
            .estimated
            .iter()
            .chain(&w.measured)
            .chain(&w.fused)
            .chain(&w.residuals)
        {
            assert_eq!(s.time_s.first(), Some(&100.0));
            assert_eq!(s.time_s.last(), Some(&250.0));
            assert_eq!(s.values.len(), 151);
        }
        assert_eq!(w.predictive.len(), 1);
        assert!(w.warnings.is_empty(), "the warning at 300 s is outside");
        assert!(data.windowed(Some(250.0), Some(100.0)).is_err());
        let err = data.windowed(Some(1e4), None).unwrap_err().to_string();
        assert!(err.contains("widen the plot window"), "{err}");
    }

    #[test]
    fn non_finite_values_are_skipped_not_drawn() {
        let mut data = figure();
        data.estimated[0].values[10] = f64::NAN;
        data.estimated[0].values[11] = 1e308;
        data.estimated[0].values[12] = f64::INFINITY;
        assert!(render_svg(&data, 800, 600).is_ok());
        // +-1e308 span more than an f64: refused with a reason, no hang.
        data.estimated[1].values[10] = -1e308;
        let err = render_svg(&data, 800, 600).unwrap_err().to_string();
        assert!(err.contains("diverging"), "{err}");
    }
}
