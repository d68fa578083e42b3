//! The frame rendering benchmark (`nldf bench render`): an exported model's whole frames in
//! onnxruntime against bare onnxruntime on the same rays, tract against onnxruntime, and
//! frame time against the share of pixels the head covers, with a plot of the last. The
//! measurements run in rounds (bare, ort, tract, every pixel, each coverage; again), so each
//! ratio is one per round, over interleaved pairs ([`crate::repeats`]); the times in the
//! table are the median of the rounds' medians.

use std::path::{Path, PathBuf};

use nldf_core::host::Machine;
use nldf_infer::BackendOptions;
use nldf_infer::bench::{RenderBench, RenderBenchConfig, bench_render};
use nldf_model::ExportedModel;
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::trainers::plot::{Series, palette, plot_xy};
use serde::Serialize;

use crate::error::{Result, create_dir};
use crate::load::LoadGate;
use crate::repeats::{Ratio, check_pairs};
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
    /// The first round, its times replaced by the median over the rounds.
    pub result: RenderBench,
    /// Every round, in order.
    pub rounds: Vec<RenderBench>,
    /// Bare onnxruntime's time over the ort whole frame's, per round: the share of the bare
    /// throughput the whole frame keeps.
    pub ort_frame_over_bare: Ratio,
    /// tract's whole-frame time over onnxruntime's, per round.
    pub tract_over_ort: Ratio,
    /// Each coverage frame's time over the every-pixel frame's, per round, in the order of
    /// `result.coverage`.
    pub coverage_over_full: Vec<Ratio>,
}

impl RenderBenchPlan {
    /// Reads the exported model at `path`, if the machine's load admits the benchmark.
    pub fn open(path: &Path, load: LoadGate) -> Result<RenderBenchPlan> {
        let machine = load.admit()?;
        let model = nldf_model::read_model(path)?;
        Ok(RenderBenchPlan {
            machine,
            path: path.to_path_buf(),
            model,
        })
    }

    /// Times the model's frames in `pairs` rounds, `reps` frames per measurement, with
    /// `options`; each measurement is announced as a note.
    pub fn run(
        self,
        reps: usize,
        pairs: usize,
        options: BackendOptions,
        on_event: OnEvent,
    ) -> Result<RenderReport> {
        check_pairs(pairs)?;
        let cfg = RenderBenchConfig {
            reps,
            options,
            ..RenderBenchConfig::default()
        };
        let mut rounds = Vec::new();
        for round in 0..pairs {
            rounds.push(bench_render(&self.model, &cfg, |what| {
                on_event(&JobEvent::Note(format!(
                    "round {} of {pairs}: {what}",
                    round + 1
                )))
            })?);
        }
        let mut machine = self.machine;
        machine.record_end();
        let ratio = |f: &dyn Fn(&RenderBench) -> (f64, f64)| {
            Ratio::of_pairs(&rounds.iter().map(f).collect::<Vec<_>>())
        };
        let ort_frame_over_bare = ratio(&|r| (r.bare_ort.seconds, r.ort_frame.seconds))?;
        let tract_over_ort = ratio(&|r| (r.tract_frame.seconds, r.ort_frame.seconds))?;
        let coverage_over_full = (0..rounds[0].coverage.len())
            .map(|i| ratio(&|r| (r.coverage[i].seconds, r.full_frame.seconds)))
            .collect::<Result<Vec<_>>>()?;
        // The result's own ratios are the rounds' medians, as the table writes them.
        let mut result = median_round(&rounds);
        result.ort_frame_over_bare = ort_frame_over_bare.median;
        result.tract_over_ort = tract_over_ort.median;
        result.at_30_percent = result.at_30_percent.and_then(|(share, _)| {
            let i = result
                .coverage
                .iter()
                .position(|t| t.head_fraction == share)?;
            Some((share, coverage_over_full.get(i)?.median))
        });
        Ok(RenderReport {
            bench: "render",
            machine,
            model: self.path,
            result,
            rounds,
            ort_frame_over_bare,
            tract_over_ort,
            coverage_over_full,
        })
    }
}

/// The first of `rounds` (at least one) with each time the median over the rounds, and the
/// rates worked out from those medians.
fn median_round(rounds: &[RenderBench]) -> RenderBench {
    use nldf_core::stats::median;
    let mut r = rounds[0].clone();
    let med = |f: &dyn Fn(&RenderBench) -> f64| median(&rounds.iter().map(f).collect::<Vec<_>>());
    let set = |t: &mut nldf_infer::bench::FrameTiming, seconds: f64| {
        t.seconds = seconds;
        t.rays_per_s = t.network_rays as f64 / seconds.max(1e-12);
    };
    set(&mut r.bare_ort, med(&|x| x.bare_ort.seconds));
    set(&mut r.ort_frame, med(&|x| x.ort_frame.seconds));
    set(&mut r.tract_frame, med(&|x| x.tract_frame.seconds));
    set(&mut r.full_frame, med(&|x| x.full_frame.seconds));
    for i in 0..r.coverage.len() {
        let s = med(&|x| x.coverage.get(i).map_or(f64::NAN, |t| t.seconds));
        set(&mut r.coverage[i], s);
    }
    r
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
             | settings | batch {}, {} threads, {} rounds, each timing every row by the median of {} frames after {} untimed; times: the median of the rounds; ratios: the median over the rounds (smallest-largest) |\n\
             | default frame | head covers {:.1} % of the pixels ({} rays) |\n\
             | bare onnxruntime, the same rays | {:.1} ms ({:.0} rays/s) |\n\
             | ort whole frame | {:.1} ms ({:.0} rays/s, {:.2} frames/s) |\n\
             | ort whole frame / bare | {} the bare throughput |\n\
             | tract whole frame | {:.1} ms ({:.2} frames/s) |\n\
             | tract / ort | {} the time |\n\
             | every pixel through the network (ort) | {:.1} ms ({} rays) |\n",
            r.depth,
            r.width,
            r.image_width,
            r.image_height,
            machine_cell(&self.machine),
            cfg.options.batch_size,
            cfg.options.threads,
            self.rounds.len(),
            cfg.reps,
            cfg.warmup,
            pct(r.ort_frame.head_fraction),
            r.ort_frame.network_rays,
            ms(r.bare_ort.seconds),
            r.bare_ort.rays_per_s,
            ms(r.ort_frame.seconds),
            r.ort_frame.rays_per_s,
            1.0 / r.ort_frame.seconds,
            self.ort_frame_over_bare.cell(),
            ms(r.tract_frame.seconds),
            1.0 / r.tract_frame.seconds,
            self.tract_over_ort.cell(),
            ms(r.full_frame.seconds),
            r.full_frame.network_rays,
        );
        for (t, ratio) in r.coverage.iter().zip(&self.coverage_over_full) {
            md += &format!(
                "| head on {:.1} % of the pixels (focal {:.0} px) | {:.1} ms, {} the every-pixel time |\n",
                pct(t.head_fraction),
                t.focal,
                ms(t.seconds),
                ratio.cell()
            );
        }
        md
    }
}
