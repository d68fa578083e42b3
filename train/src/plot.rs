//! The training curve as a PNG (plotters, with an embedded DejaVu Sans so that no system
//! font is needed): PSNR against wall-clock minutes, the training batches' as a thin line
//! and the validation frames' (whole image, head, mouth) as marked lines.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::error::{Error, Result};
use crate::log::LogRow;

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

/// Draws PSNR against minutes for `rows` into `path` (written atomically), titled `title`.
pub fn plot_training_curve(path: &Path, title: &str, rows: &[LogRow]) -> Result<()> {
    register_font();
    let (w, h) = SIZE;
    let mut buf = vec![255u8; (w * h * 3) as usize];
    let fail = |e: String| Error::invalid(path, format!("cannot draw the plot: {e}"));
    {
        let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
        let minutes = |r: &LogRow| r.elapsed_s / 60.0;
        let x_max = rows.iter().map(minutes).fold(0.1f64, f64::max);
        let values = rows.iter().flat_map(|r| {
            [Some(r.psnr), r.val_psnr, r.val_face_psnr, r.val_mouth_psnr]
                .into_iter()
                .flatten()
        });
        let (lo, hi) = values
            .filter(|v| v.is_finite())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
        let (lo, hi) = if lo.is_finite() {
            ((lo - 1.0).floor(), (hi + 1.0).ceil())
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
            .x_desc("wall-clock minutes")
            .y_desc("PSNR (dB)")
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        let train: Vec<(f64, f64)> = rows.iter().map(|r| (minutes(r), r.psnr)).collect();
        chart
            .draw_series(LineSeries::new(
                train,
                RGBColor(170, 170, 170).stroke_width(1),
            ))
            .map_err(|e| fail(e.to_string()))?
            .label("training batch")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RGBColor(170, 170, 170)));
        let series: [(&str, RGBColor, Pick); 3] = [
            ("validation, whole image", RGBColor(31, 119, 180), |r| {
                r.val_psnr
            }),
            ("validation, head", RGBColor(44, 160, 44), |r| {
                r.val_face_psnr
            }),
            ("validation, mouth", RGBColor(214, 39, 40), |r| {
                r.val_mouth_psnr
            }),
        ];
        for (label, color, pick) in series {
            let points: Vec<(f64, f64)> = rows
                .iter()
                .filter_map(|r| pick(r).map(|v| (minutes(r), v)))
                .collect();
            if points.is_empty() {
                continue;
            }
            chart
                .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
                .map_err(|e| fail(e.to_string()))?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], color.stroke_width(2))
                });
            chart
                .draw_series(
                    points
                        .into_iter()
                        .map(|p| Circle::new(p, 3, color.filled())),
                )
                .map_err(|e| fail(e.to_string()))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        root.present().map_err(|e| fail(e.to_string()))?;
    }
    Ok(nldf_core::image::save_png_bytes(
        path,
        w,
        h,
        image::ExtendedColorType::Rgb8,
        &buf,
    )?)
}
