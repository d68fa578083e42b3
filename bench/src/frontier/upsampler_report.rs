//! The report of `nldf bench upsampler` (`upsampler.json`) and its Markdown
//! (`upsampler.md`).

use nldf_core::dataset::Split;
use nldf_core::host::Machine;
use serde::Serialize;

use super::front::SplitScore;
use crate::repeats::{Ratio, cell};
use crate::report::machine_cell;

/// One way of rendering.
#[derive(Debug, Clone, Serialize)]
pub struct UpsamplerRow {
    /// `teacher`, `native rays`, `bilinear`, `upsampler, frame graph` or `upsampler, ray
    /// graph`.
    pub way: String,
    pub precision: String,
    pub runtime: String,
    /// Output frames' side, and the side of the grid the network evaluates.
    pub size: u32,
    pub grid: u32,
    /// Median seconds a whole frame, 2 threads, taking turns frame by frame.
    pub s_per_frame: f64,
    pub fps: f64,
    pub scores: Vec<SplitScore>,
    /// How many times as fast as the student's native rays in f32 onnxruntime: the median
    /// over the frames of that row's time over this one's (smallest-largest).
    pub speed_against_native: Option<Ratio>,
    /// Seconds of each frame, in the order the ways took turns (any two rows pair frame by
    /// frame).
    pub frame_seconds: Vec<f64>,
}

/// One precision against another of the same way and runtime.
#[derive(Debug, Clone, Serialize)]
pub struct PrecisionRatio {
    pub way: String,
    pub runtime: String,
    /// The faster-to-compute precision, and the one it is set against.
    pub precision: String,
    pub against: String,
    /// How many times as fast `precision` is as `against`, frame by frame.
    pub speed: Ratio,
}

/// The benchmark's result.
#[derive(Debug, Clone, Serialize)]
pub struct UpsamplerBenchReport {
    pub machine: Machine,
    pub run: String,
    pub upsampler: String,
    pub factor: usize,
    pub frames: Option<usize>,
    pub threads: usize,
    /// The student's products kept in f32 in the int8 ray graph.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub int8_f32: Vec<String>,
    pub rows: Vec<UpsamplerRow>,
    /// Each precision against the others of its way and runtime.
    pub precisions: Vec<PrecisionRatio>,
}

/// The report as Markdown: one row per way of rendering, head PSNR / SSIM per split.
pub(super) fn markdown(r: &UpsamplerBenchReport, splits: &[Split]) -> String {
    let mut md = format!(
        "# Learned upsampler x{} against native rays and bilinear\n\n\
         Run `{}`, upsampler `{}`; {} threads; {} frames a split; {}.\n\
         Times: median seconds a whole frame, the ways of rendering taking turns frame by \
         frame. Speed: how many times as fast as the student's native rays in fp32 \
         onnxruntime, the median over the frames (each rendered by both in turn) of the \
         per-frame ratio (smallest-largest). Scores: head-region PSNR (dB) / head SSIM, then \
         whole-frame PSNR.\n\n",
        r.factor,
        r.run,
        r.upsampler,
        r.threads,
        r.frames.map_or("all".to_string(), |n| n.to_string()),
        machine_cell(&r.machine),
    );
    md.push_str(&kept_in_f32(&r.int8_f32));
    md.push_str("| way | precision | runtime | size | grid | ms / frame | frames/s | speed |");
    for s in splits {
        md.push_str(&format!(
            " {} head PSNR / SSIM | {} whole |",
            s.name(),
            s.name()
        ));
    }
    md.push_str("\n| --- | --- | --- | --- | --- | --- | --- | --- |");
    for _ in splits {
        md.push_str(" --- | --- |");
    }
    md.push('\n');
    let f2 = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    let f3 = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
    for row in &r.rows {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.1} | {:.1} | {} |",
            row.way,
            row.precision,
            row.runtime,
            row.size,
            row.grid,
            1000.0 * row.s_per_frame,
            row.fps,
            cell(row.speed_against_native.as_ref())
        ));
        for s in splits {
            match row.scores.iter().find(|x| x.split == s.name()) {
                Some(x) => md.push_str(&format!(
                    " {} / {} | {:.2} |",
                    f2(x.head_psnr),
                    f3(x.head_ssim),
                    x.psnr
                )),
                None => md.push_str(" - | - |"),
            }
        }
        md.push('\n');
    }
    if !r.precisions.is_empty() {
        md.push_str(
            "\nPrecisions against each other, the same way and runtime, frame by frame: how \
             many times as fast (median over the frames, smallest-largest).\n\n\
             | way | runtime | precision | against | speed |\n| --- | --- | --- | --- | --- |\n",
        );
        for p in &r.precisions {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} |\n",
                p.way,
                p.runtime,
                p.precision,
                p.against,
                p.speed.cell()
            ));
        }
    }
    md
}

/// The line saying which of the student's products the int8 rows keep in f32 (none: empty).
fn kept_in_f32(products: &[String]) -> String {
    if products.is_empty() {
        return String::new();
    }
    let names: Vec<String> = products.iter().map(|p| format!("`{p}`")).collect();
    format!(
        "int8 rows: the student's products {} kept in f32.\n\n",
        names.join(", ")
    )
}
