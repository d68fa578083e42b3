//! The training curve as a PNG (plotters, with an embedded DejaVu Sans so that no system
//! font is needed): PSNR against wall-clock minutes, the training batches' as a thin line
//! and the validation frames' (whole image, head, mouth) as marked lines.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::error::{Error, Result};
use crate::trainers::log::LogRow;

/// Picks one value of a log row.
type Pick = fn(&LogRow) -> Option<f64>;

/// Image size of the plot.
const SIZE: (u32, u32) = (960, 540);

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid; a failure would only drop the labels.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

/// The series' legend in the lower right corner.
fn draw_legend<'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, CT>,
) -> std::result::Result<(), String> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(|e| e.to_string())
}

/// Writes a drawn [`SIZE`] RGB buffer to `path` as a PNG, atomically.
fn save_plot(path: &Path, buf: &[u8]) -> Result<()> {
    let (w, h) = SIZE;
    Ok(nldf_core::image::save_png_bytes(
        path,
        w,
        h,
        image::ExtendedColorType::Rgb8,
        buf,
    )?)
}

/// One line of a plot: PSNR (y) against wall-clock minutes (x).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub color: (u8, u8, u8),
    pub points: Vec<(f64, f64)>,
    /// Thick with a dot per point (validation), or thin (training batches).
    pub marked: bool,
}

/// A colour per series index (matplotlib's cycle).
pub fn palette(i: usize) -> (u8, u8, u8) {
    const COLORS: [(u8, u8, u8); 8] = [
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
    ];
    COLORS[i % COLORS.len()]
}

/// Draws PSNR against minutes for `rows` into `path` (written atomically), titled `title`.
pub fn plot_training_curve(path: &Path, title: &str, rows: &[LogRow]) -> Result<()> {
    let minutes = |r: &LogRow| r.elapsed_s / 60.0;
    let mut series = vec![Series {
        label: "training batch".into(),
        color: (170, 170, 170),
        points: rows.iter().map(|r| (minutes(r), r.psnr)).collect(),
        marked: false,
    }];
    let picks: [(&str, usize, Pick); 3] = [
        ("validation, whole image", 0, |r| r.val_psnr),
        ("validation, head", 2, |r| r.val_face_psnr),
        ("validation, mouth", 3, |r| r.val_mouth_psnr),
    ];
    for (label, color, pick) in picks {
        series.push(Series {
            label: label.into(),
            color: palette(color),
            points: rows
                .iter()
                .filter_map(|r| pick(r).map(|v| (minutes(r), v)))
                .collect(),
            marked: true,
        });
    }
    plot_lines(path, title, &series)
}

/// Draws `series` (PSNR against wall-clock minutes) into `path` (written atomically);
/// empty series are left out.
pub fn plot_lines(path: &Path, title: &str, series: &[Series]) -> Result<()> {
    plot_xy(path, title, ("wall-clock minutes", "PSNR (dB)"), series)
}

/// Draws `series` into `path` (written atomically) with the axes labelled `axes` (x, y);
/// x runs from 0, y spans the values with a margin of 5 % (at least 1). Empty series are
/// left out.
pub fn plot_xy(path: &Path, title: &str, axes: (&str, &str), series: &[Series]) -> Result<()> {
    register_font();
    let (w, h) = SIZE;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let fail = |e: String| Error::invalid(path, format!("cannot draw the plot: {e}"));
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
        let all = || series.iter().flat_map(|s| s.points.iter().copied());
        let x_max = all().map(|p| p.0).fold(0.1f64, f64::max);
        let (lo, hi) = all()
            .map(|p| p.1)
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        let (lo, hi) = if lo.is_finite() {
            let margin = (0.05 * (hi - lo)).max(1.0);
            ((lo - margin).floor(), (hi + margin).ceil())
        } else {
            (0.0, 40.0)
        };
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(0.0..x_max, lo..hi)
            .map_err(|e| fail(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc(axes.0)
            .y_desc(axes.1)
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        for s in series.iter().filter(|s| !s.points.is_empty()) {
            let color = RGBColor(s.color.0, s.color.1, s.color.2);
            let width = if s.marked { 2 } else { 1 };
            chart
                .draw_series(LineSeries::new(s.points.clone(), color.stroke_width(width)))
                .map_err(|e| fail(e.to_string()))?
                .label(s.label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], color.stroke_width(width))
                });
            if s.marked {
                chart
                    .draw_series(s.points.iter().map(|&p| Circle::new(p, 3, color.filled())))
                    .map_err(|e| fail(e.to_string()))?;
            }
        }
        draw_legend(&mut chart).map_err(fail)?;
        root.present().map_err(|e| fail(e.to_string()))?;
    }
    save_plot(path, &buf)
}

/// One point of a run-time against error plot.
#[derive(Debug, Clone, PartialEq)]
pub struct FrontierDot {
    /// Legend label of its group (one colour per group, e.g. a runtime and precision).
    pub group: String,
    /// Milliseconds per whole frame (x, log axis).
    pub ms: f64,
    /// PSNR in dB (y).
    pub psnr: f64,
    /// On the Pareto front: ringed, joined by the front's line and labelled with `name`.
    pub on_front: bool,
    /// Short name written beside a point on the front.
    pub name: String,
}

/// Draws PSNR against milliseconds per frame on a log axis into `path` (written
/// atomically): one colour per group, the Pareto front ringed and joined by a dashed
/// grey line. Points with a non-finite or non-positive value are left out.
pub fn plot_frontier(path: &Path, title: &str, dots: &[FrontierDot]) -> Result<()> {
    register_font();
    let (w, h) = SIZE;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let fail = |e: String| Error::invalid(path, format!("cannot draw the plot: {e}"));
    let dots: Vec<&FrontierDot> = dots
        .iter()
        .filter(|d| d.ms.is_finite() && d.ms > 0.0 && d.psnr.is_finite())
        .collect();
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
        let ((x_lo, x_hi), (lo, hi)) = frontier_ranges(&dots);
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(16)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d((x_lo..x_hi).log_scale(), lo..hi)
            .map_err(|e| fail(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc("milliseconds per whole frame (log scale)")
            .y_desc("PSNR (dB)")
            .x_labels(10)
            .x_label_formatter(&|x| format!("{x:.0}"))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        let mut front: Vec<(f64, f64)> = dots
            .iter()
            .filter(|d| d.on_front)
            .map(|d| (d.ms, d.psnr))
            .collect();
        front.sort_by(|a, b| a.0.total_cmp(&b.0));
        let grey = RGBColor(120, 120, 120);
        chart
            .draw_series(LineSeries::new(front.clone(), grey.stroke_width(1)))
            .map_err(|e| fail(e.to_string()))?
            .label("Pareto front")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], grey.stroke_width(1)));
        chart
            .draw_series(
                front
                    .iter()
                    .map(|&p| Circle::new(p, 8, grey.stroke_width(2))),
            )
            .map_err(|e| fail(e.to_string()))?;
        chart
            .draw_series(dots.iter().filter(|d| d.on_front).map(|d| {
                EmptyElement::at((d.ms, d.psnr))
                    + Text::new(d.name.clone(), (10, -16), ("sans-serif", 13).into_font())
            }))
            .map_err(|e| fail(e.to_string()))?;
        for (i, group) in groups_in_order(&dots).iter().enumerate() {
            let (r, g, b) = palette(i);
            let color = RGBColor(r, g, b);
            chart
                .draw_series(
                    dots.iter()
                        .filter(|d| d.group == *group)
                        .map(|d| Circle::new((d.ms, d.psnr), 4, color.filled())),
                )
                .map_err(|e| fail(e.to_string()))?
                .label(*group)
                .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
        }
        draw_legend(&mut chart).map_err(fail)?;
        root.present().map_err(|e| fail(e.to_string()))?;
    }
    save_plot(path, &buf)
}

/// The frontier plot's axis ranges, milliseconds then PSNR, around `dots` (fixed ranges
/// when there are none).
fn frontier_ranges(dots: &[&FrontierDot]) -> ((f64, f64), (f64, f64)) {
    let (x_lo, x_hi) = dots.iter().fold((f64::INFINITY, 0.0f64), |(a, b), d| {
        (a.min(d.ms), b.max(d.ms))
    });
    let (x_lo, x_hi) = if x_lo.is_finite() {
        (x_lo / 1.5, x_hi * 1.5)
    } else {
        (1.0, 1000.0)
    };
    let (lo, hi) = dots
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            (a.min(d.psnr), b.max(d.psnr))
        });
    let (lo, hi) = if lo.is_finite() {
        ((lo - 1.0).floor(), (hi + 1.0).ceil())
    } else {
        (0.0, 40.0)
    };
    ((x_lo, x_hi), (lo, hi))
}

/// The dots' groups, each once, in the order they first appear.
fn groups_in_order<'a>(dots: &[&'a FrontierDot]) -> Vec<&'a str> {
    let mut groups: Vec<&str> = Vec::new();
    for d in dots {
        if !groups.contains(&d.group.as_str()) {
            groups.push(&d.group);
        }
    }
    groups
}
