//! The frontier's report: `frontier.json` (machine, settings, points, speed-ups),
//! `frontier.md` (the tables), `frontier.png` (PSNR against time on a log axis, the Pareto
//! front marked), `frontier_head.png` (the same with head-region PSNR and its own front) and
//! `frontier_{size}.png` for the higher resolution pass.

use std::path::{Path, PathBuf};

use nldf_core::dataset::Split;
use nldf_core::host::Machine;
use nldf_train::trainers::plot::plot_frontier;
use serde::Serialize;

use super::front::{Point, SpeedUp, dots_of, head_dots_of};
use super::shared::THREADS;
use crate::error::Result;
use crate::repeats::{Ratio, cell};
use crate::report::Written;

/// What the frontier ran with, as its JSON records it.
#[derive(Debug, Clone, Serialize)]
pub struct FrontierSettings {
    pub run: PathBuf,
    pub data: PathBuf,
    pub frames: Option<usize>,
    /// Threads of the main timing.
    pub threads: usize,
    pub one_thread_frames: usize,
    pub calibration_frames: usize,
    pub batch: usize,
    pub hires_data: Option<PathBuf>,
    pub timed_frames: usize,
    /// The upsamplers whose upsampled ray graphs are points.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub upsamplers: Vec<String>,
    /// The student's products kept in f32 in their int8 graphs.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub int8_f32: Vec<String>,
}

/// AD-NeRF's setting, timed with seeded weights.
#[derive(Debug, Clone, Serialize)]
pub struct AdNerfSetting {
    /// Median milliseconds per frame, 2 threads.
    pub ms_2_threads: f64,
    pub gmac_per_frame: f64,
    /// Frames timed.
    pub frames: usize,
    /// The points it was timed against, taking turns frame by frame.
    pub against: Vec<AdNerfPair>,
}

/// A point timed in turns with AD-NeRF's setting.
#[derive(Debug, Clone, Serialize)]
pub struct AdNerfPair {
    /// `model precision runtime`, as the speed-up table names it.
    pub point: String,
    /// Its median milliseconds per frame over the same frames.
    pub ms: f64,
    /// AD-NeRF's time over the point's, frame by frame.
    pub speed_up: Option<Ratio>,
}

/// The rows of `table` that AD-NeRF's setting is set against: each split's speed-up point,
/// then the fastest export, each once.
pub(crate) fn adnerf_listed(table: &[Point], speed_up: &[SpeedUp]) -> Vec<usize> {
    let mut listed: Vec<usize> = speed_up
        .iter()
        .filter_map(|s| {
            let name = s.point.as_deref()?;
            table
                .iter()
                .position(|p| format!("{} {} {}", p.model, p.precision, p.runtime) == name)
        })
        .collect();
    if let Some(fastest) = table
        .iter()
        .enumerate()
        .filter(|(_, p)| p.runtime != "candle")
        .min_by(|a, b| a.1.ms_2_threads.total_cmp(&b.1.ms_2_threads))
    {
        listed.push(fastest.0);
    }
    let mut seen = Vec::new();
    listed.retain(|i| {
        let new = !seen.contains(i);
        seen.push(*i);
        new
    });
    listed
}

/// Everything the frontier measured: `frontier.json`.
#[derive(Debug, Clone, Serialize)]
pub struct FrontierReport {
    pub machine: Machine,
    pub settings: FrontierSettings,
    /// The teacher first, then its variants, then every export in every runtime.
    pub points: Vec<Point>,
    pub speed_up: Vec<SpeedUp>,
    pub adnerf_setting: Option<AdNerfSetting>,
    /// The `--hires-data` pass's points, apart.
    pub hires_points: Option<Vec<Point>>,
    /// The splits scored: `val`, then `novel` and `voice` where the dataset has them.
    #[serde(skip)]
    pub splits: Vec<Split>,
}

impl FrontierReport {
    /// Writes `frontier.json`, `frontier_{size}.png` (with a higher resolution pass),
    /// `frontier.md` and `frontier.png` into `out`; the plots are listed main one first.
    pub fn write(&self, out: &Path) -> Result<Written> {
        let json_path = out.join("frontier.json");
        let json = serde_json::to_value(self)?;
        nldf_core::files::write_atomic(
            &json_path,
            serde_json::to_string_pretty(&json)?.as_bytes(),
        )?;
        let md = self.markdown();
        let mut pngs = Vec::new();
        if let Some(hires) = self.hires() {
            let size = hires[0].size;
            let path = out.join(format!("frontier_{size}.png"));
            plot_frontier(
                &path,
                &format!(
                    "val PSNR at {size} x {size} against time per frame, {THREADS} threads, {}",
                    self.machine.cpu
                ),
                &dots_of(hires),
            )?;
            pngs.push(path);
        }
        let md_path = out.join("frontier.md");
        nldf_core::files::write_atomic(&md_path, md.as_bytes())?;
        let png_path = out.join("frontier.png");
        plot_frontier(
            &png_path,
            &format!(
                "val PSNR against time per frame, {} threads, {}",
                THREADS, self.machine.cpu
            ),
            &dots_of(&self.points),
        )?;
        let head = head_dots_of(&self.points);
        if !head.is_empty() {
            let path = out.join("frontier_head.png");
            plot_frontier(
                &path,
                &format!(
                    "val head-region PSNR against time per frame, {} threads, {}",
                    THREADS, self.machine.cpu
                ),
                &head,
            )?;
            pngs.insert(0, path);
        }
        Ok(Written {
            markdown: md,
            json: json_path,
            md: md_path,
            plots: std::iter::once(png_path).chain(pngs).collect(),
        })
    }

    /// The higher resolution pass's points, where it has any.
    fn hires(&self) -> Option<&[Point]> {
        self.hires_points.as_deref().filter(|h| !h.is_empty())
    }

    /// The tables: every point, the speed-ups, AD-NeRF's setting and the higher resolution
    /// pass.
    pub fn markdown(&self) -> String {
        let mut md = self.points_table();
        md.push_str(&self.speed_up_table());
        if let Some(adnerf) = &self.adnerf_setting {
            md.push_str(&self.adnerf_table(adnerf));
        }
        if let Some(hires) = self.hires() {
            md.push_str(&self.hires_table(hires));
        }
        md
    }

    /// The heading and one row per point: size, cost, times, each split's scores.
    fn points_table(&self) -> String {
        let machine = &self.machine;
        let splits = &self.splits;
        let mut md = String::new();
        md.push_str(&format!(
            "# Run time against error\n\n{}. Whole \
             frames (ray set-up, network, compositing): the median over the val scoring pass with \
             {THREADS} threads, where the ways of rendering take turns frame by frame; beside it \
             the median over {} val frames rendered back to back; and over {} frames with 1 \
             thread. Scores over every frame of each split.\n\n",
            crate::report::machine_cell(machine),
            self.settings.timed_frames,
            self.settings.one_thread_frames.saturating_sub(1),
        ));
        md.push_str("| model | precision | runtime | MB | GMAC / frame | ms / frame (2 threads) | frames/s | ms, back to back | ms (1 thread) |");
        for s in splits {
            md.push_str(&format!(
                " {0} head PSNR | {0} PSNR | {0} mouth |",
                s.name()
            ));
        }
        md.push_str(" val SSIM | front |\n|");
        md.push_str(&"---|".repeat(9 + 3 * splits.len() + 2));
        md.push('\n');
        for p in &self.points {
            let val_ssim = p
                .scores
                .iter()
                .find(|s| s.split == "val")
                .map_or(f64::NAN, |s| s.ssim);
            md.push_str(&format!(
                "| {} | {} | {} | {} | {:.1} | {:.1} | {:.2} | {:.1} | {} |",
                p.model,
                p.precision,
                p.runtime,
                p.file_bytes
                    .map_or("".into(), |b| format!("{:.2}", b as f64 / 1e6)),
                p.gmac_per_frame,
                p.ms_2_threads,
                1e3 / p.ms_2_threads,
                p.ms_back_to_back,
                p.ms_1_thread.map_or("".into(), |t| format!("{t:.1}")),
            ));
            for s in splits {
                match p.scores.iter().find(|x| x.split == s.name()) {
                    Some(x) => md.push_str(&format!(
                        " {} | {:.2} | {} |",
                        x.head_psnr.map_or("".into(), |h| format!("{h:.2}")),
                        x.psnr,
                        x.mouth_psnr.map_or("".into(), |m| format!("{m:.2}"))
                    )),
                    None => md.push_str(" | | |"),
                }
            }
            md.push_str(&format!(
                " {val_ssim:.4} | {} |\n",
                if p.on_front { "yes" } else { "" }
            ));
        }
        md
    }

    /// The fastest export within 1 dB of the teacher on each split.
    fn speed_up_table(&self) -> String {
        let mut md = String::from(
            "\nFastest export within 1 dB of the teacher's PSNR, whole frames side by side; \
             speed-up: the median over the val scoring pass's frames (each rendered by both in \
             turn) of the teacher's time over the export's (smallest-largest):\n\n\
             | split | teacher PSNR | fastest within 1 dB | its PSNR | speed-up |\n|---|---|---|---|---|\n",
        );
        for s in &self.speed_up {
            md.push_str(&format!(
                "| {} | {:.2} | {} | {} | {} |\n",
                s.split,
                s.teacher_psnr,
                s.point.as_deref().unwrap_or("none"),
                s.point_psnr.map_or("".into(), |q| format!("{q:.2}")),
                cell(s.speed_up.as_ref()),
            ));
        }
        md
    }

    /// AD-NeRF's setting against the speed-ups' points and the fastest export.
    fn adnerf_table(&self, adnerf: &AdNerfSetting) -> String {
        let ms = adnerf.ms_2_threads;
        let mut md = format!(
            "\nAD-NeRF's setting (8 x 256, 64 + 128 samples, every pixel and sample, seeded \
             weights: time only), median of {} frames: {ms:.0} ms per frame, {:.0} GMAC. \
             Against it, whole frames, {THREADS} threads, each point rendering the same frames \
             in turn with it; speed-up: the median over the frames of AD-NeRF's time over the \
             point's (smallest-largest):\n\n| point | ms / frame | speed-up |\n|---|---|---|\n",
            adnerf.frames, adnerf.gmac_per_frame
        );
        for a in &adnerf.against {
            let psnr = self
                .points
                .iter()
                .find(|p| format!("{} {} {}", p.model, p.precision, p.runtime) == a.point)
                .and_then(|p| p.psnr("val"))
                .unwrap_or(f64::NAN);
            md.push_str(&format!(
                "| {} (val {psnr:.2} dB) | {:.1} | {} |\n",
                a.point,
                a.ms,
                cell(a.speed_up.as_ref())
            ));
        }
        md
    }

    /// The higher resolution pass: one row per point.
    fn hires_table(&self, hires: &[Point]) -> String {
        let size = hires[0].size;
        let mut md = format!(
            "\n## {size} x {size}\n\nThe same scene's `val` frames at {size} x {size} ({}): \
             rays at that size, or at the model's size and upscaled bilinearly; medians over \
             the scoring pass (and over frames back to back), {THREADS} threads.\n\n\
             | model | precision | runtime | GMAC / frame | ms / frame (2 threads) | frames/s | \
             ms, back to back | val PSNR | val mouth | val SSIM | front |\n\
             |---|---|---|---|---|---|---|---|---|---|---|\n",
            self.settings
                .hires_data
                .as_deref()
                .map_or(String::new(), |d| d.display().to_string()),
        );
        for p in hires {
            let s = p.scores.first();
            md.push_str(&format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.2} | {:.1} | {:.2} | {} | {:.4} | {} |\n",
                p.model,
                p.precision,
                p.runtime,
                p.gmac_per_frame,
                p.ms_2_threads,
                1e3 / p.ms_2_threads,
                p.ms_back_to_back,
                s.map_or(f64::NAN, |s| s.psnr),
                s.and_then(|s| s.mouth_psnr)
                    .map_or("".into(), |m| format!("{m:.2}")),
                s.map_or(f64::NAN, |s| s.ssim),
                if p.on_front { "yes" } else { "" }
            ));
        }
        md
    }
}
