//! The still-pixel benchmark (`nldf bench still`): frames that re-render only the pixels
//! the audio moves, against full renders, on a still pose, a pose held 2 s at a time and a
//! moving pose; time per frame and error against the full frames. Each track runs in
//! `pairs` rounds (every track, then every track again), a fresh skipper each time, the
//! full and the skipping frame taking turns frame by frame; the speed-up is one ratio per
//! round, over interleaved pairs ([`crate::repeats`]).

use std::path::{Path, PathBuf};

use glam::Mat4;
use nldf_core::audio::neighbourhood;
use nldf_core::host::Machine;
use nldf_infer::frame::FrameRenderer;
use nldf_infer::poses::{default_pose, default_track};
use nldf_infer::still::{SkipConfig, StillTrack, bench_track, probe_frames};
use nldf_infer::{BackendKind, BackendOptions, backend_for};
use nldf_model::contract::ModelInfo;
use nldf_train::job::{JobEvent, OnEvent};
use serde::Serialize;

use crate::error::Result;
use crate::load::LoadGate;
use crate::repeats::{Ratio, check_pairs};
use crate::report::{Written, machine_cell, write_bench_files};

/// What the still-pixel benchmark renders.
#[derive(Debug, Clone)]
pub struct StillBenchJob {
    /// The exported model.
    pub model: PathBuf,
    /// Speech to render (its first `seconds` are used).
    pub audio: PathBuf,
    /// Seconds of audio per pose track (positive).
    pub seconds: f64,
    /// Runtime for the network.
    pub backend: BackendKind,
    /// Colour spreads (in 1/255 steps) above which a pixel is re-rendered, one measurement
    /// each (at least one).
    pub thresholds: Vec<f32>,
    /// Batch size and threads (the pools never spin: the two renderers take turns).
    pub options: BackendOptions,
    /// Rounds of every track (at least 2).
    pub pairs: usize,
    /// The load limit at the start.
    pub load: LoadGate,
}

/// The still-pixel benchmark's settings, as its JSON records them.
#[derive(Debug, Clone, Serialize)]
pub struct StillSettings {
    pub audio: PathBuf,
    pub seconds: f64,
    /// Frames per track.
    pub frames: usize,
    pub backend: String,
    pub threads: usize,
    pub batch: usize,
    /// The first threshold's skipping settings.
    pub skip: SkipConfig,
    pub thresholds: Vec<f32>,
    /// Rounds of every track.
    pub pairs: usize,
}

/// One track at one threshold over every round.
#[derive(Debug, Clone, Serialize)]
pub struct StillRow {
    /// The first round (its rays, full frames and errors are the row's; its speed-up is
    /// replaced by the median over the rounds).
    pub track: StillTrack,
    /// Mean milliseconds per frame of each round, in full and with skipping.
    pub full_ms_means: Vec<f64>,
    pub skip_ms_means: Vec<f64>,
    /// The full frames' mean time over the skipping frames', per round.
    pub speed_up: Ratio,
}

/// The model's shape and frame rate, for the table's heading.
#[derive(Debug, Clone, Copy)]
pub struct StillModel {
    pub depth: usize,
    pub width: usize,
    pub fps: f64,
}

/// The still-pixel benchmark's report: `still.json`.
#[derive(Debug, Clone, Serialize)]
pub struct StillReport {
    /// `still`.
    pub bench: &'static str,
    pub machine: Machine,
    /// The exported model.
    pub model: PathBuf,
    pub settings: StillSettings,
    /// One row per track and threshold.
    pub tracks: Vec<StillRow>,
    #[serde(skip)]
    pub network: StillModel,
}

impl StillBenchJob {
    /// Renders every track in full and with skipping, frame by frame in turn.
    pub fn run(&self, on_event: OnEvent) -> Result<StillReport> {
        check_pairs(self.pairs)?;
        let mut machine = self.load.admit()?;
        let mut options = self.options;
        // The full and the skipping renderer take turns: neither pool may spin beside the
        // other.
        options.spin = false;
        let model = nldf_model::read_model(&self.model)?;
        let info = model.info.clone();
        let windows = nldf_infer::audio::windows_from_wav(&info, &self.model, &self.audio)?;
        let frames = ((self.seconds * info.spec.fps as f64).round() as usize)
            .clamp(1, windows.n_frames.max(1));
        let att = info.audio.att_frames;
        let configs = skip_configs(&self.thresholds)?;
        let config = configs[0];
        let audio = |f: usize| neighbourhood(&windows, f, att);
        let probes: Vec<Vec<f32>> = probe_frames(frames, config.probes)
            .into_iter()
            .map(audio)
            .collect();
        let kind = self.backend;
        let mut full = FrameRenderer::new(backend_for(&model, kind, options)?, None)?;
        let mut skipping = FrameRenderer::new(backend_for(&model, kind, options)?, None)?;
        let tracks = pose_tracks(&info, frames);
        // Every threshold on the still and the held tracks; the moving track never skips,
        // so it runs once a round.
        let mut rounds: Vec<Vec<StillTrack>> = Vec::new();
        for round in 0..self.pairs {
            let mut rows = Vec::new();
            for (i, (label, poses)) in tracks.iter().enumerate() {
                let moving = i == tracks.len() - 1;
                for c in if moving { &configs[..1] } else { &configs[..] } {
                    on_event(&JobEvent::Note(format!(
                        "round {} of {}: {label}, threshold {}/255: {frames} frames in full and \
                         with skipping",
                        round + 1,
                        self.pairs,
                        255.0 * c.threshold
                    )));
                    let mut row = bench_track(
                        &mut full,
                        &mut skipping,
                        label,
                        poses,
                        &audio,
                        *c,
                        probes.clone(),
                    )?;
                    row.label = format!("{label}, threshold {:.0}/255", 255.0 * c.threshold);
                    rows.push(row);
                }
            }
            rounds.push(rows);
        }
        machine.record_end();
        let rows = paired_rows(&rounds)?;
        Ok(StillReport {
            bench: "still",
            machine,
            model: self.model.clone(),
            settings: StillSettings {
                audio: self.audio.clone(),
                seconds: self.seconds,
                frames,
                backend: kind.to_string(),
                threads: options.threads,
                batch: options.batch_size,
                skip: config,
                thresholds: self.thresholds.clone(),
                pairs: self.pairs,
            },
            tracks: rows,
            network: StillModel {
                depth: info.network.depth,
                width: info.network.width,
                fps: info.spec.fps as f64,
            },
        })
    }
}

/// The three head tracks of `frames` frames: still, the default sway held 2 s at a time,
/// and the default sway.
fn pose_tracks(info: &ModelInfo, frames: usize) -> [(&'static str, Vec<Mat4>); 3] {
    let moving = default_track(info, frames);
    let hold = (2.0 * info.spec.fps).round().max(1.0) as usize;
    [
        ("still pose", vec![default_pose(info, 0); frames]),
        (
            "pose held 2 s at a time",
            (0..frames).map(|f| moving[f - f % hold]).collect(),
        ),
        ("moving pose (the default sway)", moving),
    ]
}
/// The skipping settings of each threshold (in 1/255 steps), each checked.
fn skip_configs(thresholds: &[f32]) -> Result<Vec<SkipConfig>> {
    thresholds
        .iter()
        .map(|&t| {
            let c = SkipConfig {
                threshold: t / 255.0,
                ..SkipConfig::default()
            };
            c.validate().map(|_| c)
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(Into::into)
}

/// Each track's rows of every round joined: its mean frame times per round and the
/// skipping's speed-up from those pairs.
fn paired_rows(rounds: &[Vec<StillTrack>]) -> Result<Vec<StillRow>> {
    (0..rounds[0].len())
        .map(|k| {
            let full_ms_means: Vec<f64> = rounds.iter().map(|r| r[k].full_ms_mean).collect();
            let skip_ms_means: Vec<f64> = rounds.iter().map(|r| r[k].skip_ms_mean).collect();
            let pairs: Vec<(f64, f64)> = full_ms_means
                .iter()
                .copied()
                .zip(skip_ms_means.iter().copied())
                .collect();
            let speed_up = Ratio::of_pairs(&pairs)?;
            let mut track = rounds[0][k].clone();
            track.speedup = speed_up.median;
            Ok(StillRow {
                track,
                full_ms_means,
                skip_ms_means,
                speed_up,
            })
        })
        .collect()
}

impl StillReport {
    /// Writes `still.json` and `still.md` into `out`.
    pub fn write(&self, out: &Path) -> Result<Written> {
        write_bench_files(out, "still", self, self.markdown())
    }

    /// The settings, then one row per track and threshold.
    pub fn markdown(&self) -> String {
        let s = &self.settings;
        let config = s.skip;
        let opt = |v: Option<f64>| v.map_or("identical".into(), |p| format!("{p:.2} dB"));
        let mut md = format!(
            "| skipping still pixels, {} x {} student, {} | value |\n|---|---|\n\
             | machine | {} |\n\
             | settings | {:.1} s of {} ({} frames), {} with {} threads, batch {}; thresholds {:?}/255, margin {} px, {} probes, a full frame every {} still frames |\n",
            self.network.depth,
            self.network.width,
            s.backend,
            machine_cell(&self.machine),
            s.frames as f64 / self.network.fps,
            s.audio.display(),
            s.frames,
            s.backend,
            s.threads,
            s.batch,
            s.thresholds,
            config.margin,
            config.probes,
            config.refresh,
        );
        md += &format!(
            "\n{} rounds of every track, a fresh skipper each; times: the median over the rounds \
             of each round's mean; speed-up: the median over the rounds of full over skipping \
             (smallest-largest); rays, frames and errors: the first round's.\n",
            s.pairs
        );
        md += "\n| track | full ms/frame | skipping ms/frame | speed-up | network rays | full frames | PSNR vs full | worst frame | max error |\n|---|---|---|---|---|---|---|---|---|\n";
        let median = nldf_core::stats::median;
        for row in &self.tracks {
            let r = &row.track;
            md += &format!(
                "| {} | {:.1} | {:.1} | {} | {:.1} % | {} of {} | {} | {} | {:.1}/255 |\n",
                r.label,
                median(&row.full_ms_means),
                median(&row.skip_ms_means),
                row.speed_up.cell(),
                100.0 * r.ray_share,
                r.full_frames,
                r.frames,
                opt(r.psnr_vs_full),
                opt(r.worst_frame_psnr),
                255.0 * r.max_abs_error,
            );
        }
        md
    }
}
