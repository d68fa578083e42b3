//! The frame rendering benchmark (`nldf bench render`): an exported model's whole frames in
//! onnxruntime against bare onnxruntime on the same rays, tract against onnxruntime, and
//! frame time against the share of pixels the head covers, with a plot of the last.

use std::path::{Path, PathBuf};

use nldf_export::ExportedModel;
use nldf_infer::BackendOptions;
use nldf_infer::bench::{RenderBench, RenderBenchConfig, bench_render};
use nldf_train::bench::Machine;
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::plot::{Series, palette, plot_xy};
use serde::Serialize;

use crate::error::{Result, create_dir};
use crate::report::{Written, machine_cell, write_bench_files};

/// An exported model read for the render benchmark.
pub struct RenderBenchPlan {
    machine: Machine,
    path: PathBuf,
    model: ExportedModel,
}

/// The render benchmark's report: `render.json`.
#[derive(Debug, Clone, Serialize)]
pub struct RenderReport {
    /// `render`.
    pub bench: &'static str,
    pub machine: Machine,
    /// The exported model.
    pub model: PathBuf,
    pub result: RenderBench,
}

impl RenderBenchPlan {
    /// Reads the exported model at `path`.
    pub fn open(path: &Path) -> Result<RenderBenchPlan> {
        let machine = Machine::here();
        let model = nldf_export::read_model(path)?;
        Ok(RenderBenchPlan {
            machine,
            path: path.to_path_buf(),
            model,
        })
    }

    /// Times the model's frames, `reps` per measurement, with `options`; each measurement
    /// is announced as a note.
    pub fn run(
        self,
        reps: usize,
        options: BackendOptions,
        on_event: OnEvent,
    ) -> Result<RenderReport> {
        let cfg = RenderBenchConfig {
            reps,
            options,
            ..RenderBenchConfig::default()
        };
        let result = bench_render(&self.model, &cfg, |what| {
            on_event(&JobEvent::Note(what.to_string()))
        })?;
        Ok(RenderReport {
            bench: "render",
            machine: self.machine,
            model: self.path,
            result,
        })
    }
}

fn ms(s: f64) -> f64 {
    1e3 * s
}

fn pct(f: f64) -> f64 {
    100.0 * f
}

impl RenderReport {
    /// Writes `render.png` (frame time against head coverage), then `render.json` and
    /// `render.md`, into `out`.
    pub fn write(&self, out: &Path) -> Result<Written> {
        let r = &self.result;
        let mut points: Vec<(f64, f64)> = r
            .coverage
            .iter()
            .chain(std::iter::once(&r.ort_frame))
            .map(|t| (pct(t.head_fraction), ms(t.seconds)))
            .collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let full = ms(r.full_frame.seconds);
        let series = [
            Series {
                label: "ort, rays that miss the head skipped".into(),
                color: palette(0),
                points,
                marked: true,
            },
            Series {
                label: "ort, every pixel through the network".into(),
                color: palette(1),
                points: vec![(0.0, full), (100.0, full)],
                marked: false,
            },
            Series {
                label: "proportional to head pixels".into(),
                color: palette(2),
                points: vec![(0.0, 0.0), (100.0, full)],
                marked: false,
            },
        ];
        create_dir(out)?;
        let png = out.join("render.png");
        plot_xy(
            &png,
            &format!(
                "frame time against head coverage ({} x {}, {}x{})",
                r.depth, r.width, r.image_width, r.image_height
            ),
            ("pixels the head covers (%)", "ms per frame"),
            &series,
        )?;
        let mut written = write_bench_files(out, "render", self, self.markdown())?;
        written.plots.push(png);
        Ok(written)
    }

    /// The table: the default frame in each runtime, then each head coverage.
    pub fn markdown(&self) -> String {
        let r = &self.result;
        let cfg = &r.settings;
        let mut md = format!(
            "| render, {} x {} student, {}x{} frames | value |\n|---|---|\n\
             | machine | {} |\n\
             | settings | batch {}, {} threads, median of {} frames after {} untimed |\n\
             | default frame | head covers {:.1} % of the pixels ({} rays) |\n\
             | bare onnxruntime, the same rays | {:.1} ms ({:.0} rays/s) |\n\
             | ort whole frame | {:.1} ms ({:.0} rays/s, {:.2} frames/s) |\n\
             | ort whole frame / bare | {:.1} % of the bare throughput |\n\
             | tract whole frame | {:.1} ms ({:.2} frames/s) |\n\
             | tract / ort | {:.2}x the time |\n\
             | every pixel through the network (ort) | {:.1} ms ({} rays) |\n",
            r.depth,
            r.width,
            r.image_width,
            r.image_height,
            machine_cell(&self.machine),
            cfg.options.batch_size,
            cfg.options.threads,
            cfg.reps,
            cfg.warmup,
            pct(r.ort_frame.head_fraction),
            r.ort_frame.network_rays,
            ms(r.bare_ort.seconds),
            r.bare_ort.rays_per_s,
            ms(r.ort_frame.seconds),
            r.ort_frame.rays_per_s,
            1.0 / r.ort_frame.seconds,
            pct(r.ort_frame_over_bare),
            ms(r.tract_frame.seconds),
            1.0 / r.tract_frame.seconds,
            r.tract_over_ort,
            ms(r.full_frame.seconds),
            r.full_frame.network_rays,
        );
        for t in &r.coverage {
            md += &format!(
                "| head on {:.1} % of the pixels (focal {:.0} px) | {:.1} ms, {:.1} % of every-pixel time |\n",
                pct(t.head_fraction),
                t.focal,
                ms(t.seconds),
                pct(t.seconds / r.full_frame.seconds)
            );
        }
        if let Some((share, ratio)) = r.at_30_percent {
            md += &format!(
                "| at {:.1} % coverage | {:.1} % of the every-pixel frame time |\n",
                pct(share),
                pct(ratio)
            );
        }
        md
    }
}
