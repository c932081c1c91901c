//! Plots of a run: temperatures (estimated solid, measured dashed, limits
//! dotted red, shutdowns as red and warnings as orange vertical markers) over
//! currents, as PNG or SVG (chosen by the file extension).

use std::path::Path;

use anyhow::{anyhow, bail, Result};
use plotters::coord::Shift;
use plotters::prelude::*;

/// Warning markers.
const ORANGE: RGBColor = RGBColor(255, 140, 0);

/// One time series.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Times \[s\].
    pub time_s: Vec<f64>,
    /// Values (degC or A).
    pub values: Vec<f64>,
    /// Palette index (a measured series takes its node's colour).
    pub color: usize,
}

/// Everything one figure shows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PlotData {
    /// Figure title.
    pub title: String,
    /// Estimated temperatures \[degC\].
    pub estimated: Vec<Series>,
    /// Measured temperatures \[degC\].
    pub measured: Vec<Series>,
    /// Currents \[A\] (second panel when present).
    pub currents: Vec<Series>,
    /// Horizontal limits: (label, degC).
    pub limits: Vec<(String, f64)>,
    /// Alarm (shutdown) markers, red: (time s, label).
    pub alarms: Vec<(f64, String)>,
    /// Warning markers, orange and thinner: (time s, label).
    pub warnings: Vec<(f64, String)>,
}

/// Most points drawn per series (longer series are decimated).
const MAX_POINTS: usize = 4000;

fn points(s: &Series) -> Vec<(f64, f64)> {
    let stride = s.time_s.len().div_ceil(MAX_POINTS).max(1);
    s.time_s
        .iter()
        .zip(&s.values)
        .step_by(stride)
        .map(|(t, v)| (*t, *v))
        .collect()
}

fn range(series: &[&Series], extra: &[f64]) -> Option<(f64, f64, f64, f64)> {
    let mut r: Option<(f64, f64, f64, f64)> = None;
    for s in series {
        for (t, v) in s.time_s.iter().zip(&s.values) {
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

fn color(i: usize) -> RGBColor {
    let c = Palette99::pick(i).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

fn draw<DB: DrawingBackend>(root: DrawingArea<DB, Shift>, data: &PlotData) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("plot: {e:?}");
    root.fill(&WHITE).map_err(e)?;
    let root = root.titled(&data.title, ("sans-serif", 22)).map_err(e)?;
    let (top, bottom) = if data.currents.is_empty() {
        (root, None)
    } else {
        let h = root.dim_in_pixel().1;
        let (a, b) = root.split_vertically((h as f64 * 0.65) as u32);
        (a, Some(b))
    };
    let temps: Vec<&Series> = data.estimated.iter().chain(&data.measured).collect();
    let Some((_, _, d0, d1)) = range(&temps, &[]) else {
        bail!("plot: nothing to draw (no temperature series)");
    };
    // A limit far above the data would squash it: such limits are named in
    // a note instead of drawn.
    let near = |v: f64| v <= d1 + 0.5 * (d1 - d0) && v >= d0 - 0.5 * (d1 - d0);
    let (shown, off): (Vec<_>, Vec<_>) = data.limits.iter().partition(|l| near(l.1));
    let limits: Vec<f64> = shown.iter().map(|l| l.1).collect();
    let (t0, t1, y0, y1) = range(&temps, &limits).expect("series are not empty");
    // Along the time axis, where a long note has room.
    let mut x_desc = "time [s]".to_string();
    if !off.is_empty() {
        let notes: Vec<String> = off
            .iter()
            .map(|(label, v)| format!("{label} at {v:.2} degC"))
            .collect();
        x_desc.push_str(&format!("    (off scale: {})", notes.join("; ")));
    }
    // Long legends hide the plot: label at most about 10 estimated series.
    let label_every = data.estimated.len().div_ceil(10).max(1);
    let mut chart = ChartBuilder::on(&top)
        .margin(12)
        .margin_right(36)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(t0..t1, y0..y1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc("temperature [degC]")
        .draw()
        .map_err(e)?;
    for (k, s) in data.estimated.iter().enumerate() {
        let c = color(s.color);
        let drawn = chart
            .draw_series(LineSeries::new(points(s), c.stroke_width(2)))
            .map_err(e)?;
        if k % label_every == 0 {
            drawn.label(&s.label).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
            });
        }
    }
    for s in &data.measured {
        let c = color(s.color);
        chart
            .draw_series(DashedLineSeries::new(points(s), 6, 4, c.stroke_width(1)))
            .map_err(e)?
            .label(&s.label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 8, y)], c.stroke_width(1)));
    }
    for (label, v) in &shown {
        chart
            .draw_series(DashedLineSeries::new(
                vec![(t0, *v), (t1, *v)],
                2,
                4,
                RED.stroke_width(1),
            ))
            .map_err(e)?
            .label(label)
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    }
    // Warnings first, so that a shutdown at the same time stays visible.
    let markers = [
        (&data.warnings, ORANGE, 1, "warning"),
        (&data.alarms, RED, 2, "shutdown"),
    ];
    for (events, colour, width, label) in markers {
        for (k, (t, _)) in events.iter().enumerate() {
            let drawn = chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![(*t, y0), (*t, y1)],
                    colour.stroke_width(width),
                )))
                .map_err(e)?;
            if k == 0 {
                drawn
                    .label(label)
                    .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 5, colour.filled()));
            }
            chart
                .draw_series(std::iter::once(TriangleMarker::new(
                    (*t, y1),
                    7,
                    colour.filled(),
                )))
                .map_err(e)?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(e)?;
    if let Some(bottom) = bottom {
        let currents: Vec<&Series> = data.currents.iter().collect();
        let (_, _, c0, c1) = range(&currents, &[0.0]).expect("currents are not empty");
        let mut chart = ChartBuilder::on(&bottom)
            .margin(12)
            .margin_right(36)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(t0..t1, c0..c1)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("time [s]")
            .y_desc("current [A]")
            .draw()
            .map_err(e)?;
        for s in &data.currents {
            let c = color(s.color);
            chart
                .draw_series(LineSeries::new(points(s), c.stroke_width(1)))
                .map_err(e)?
                .label(&s.label)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(e)?;
    }
    Ok(())
}

/// Renders `data` to `path` (`.png` or `.svg`), `width` x `height` pixels.
pub fn render(data: &PlotData, path: &Path, width: u32, height: u32) -> Result<()> {
    if width < 200 || height < 150 {
        bail!("plot size must be at least 200x150 pixels, got {width}x{height}");
    }
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
