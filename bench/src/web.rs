//! The frame graph's frame rate (`nldf bench web`): each frame graph in headless Chromium
//! with onnxruntime-web (WASM, SIMD, threads; `web/bench.mjs`), and natively in onnxruntime
//! and tract, side by side in one run on one machine, so that the browser's figure is read
//! against native onnxruntime's. Full frames with the head turning, and frames skipping
//! still pixels at the default pose: the page's skipping beside nldf's own
//! (`nldf_infer::still::StillSkipper`, as `nldf render --skip-still`) on the same student's
//! ray graph in onnxruntime, over the same WAV. Everything runs in rounds (every model
//! natively, then the browser; again), so the browser's frame rate against native
//! onnxruntime's is one ratio per round, over interleaved pairs ([`crate::repeats`]); the
//! frame rates in the table are the median over the rounds.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Mat4;
use nldf_core::audio::{Waveform, neighbourhood, read_wav, resample, write_wav};
use nldf_core::camera::turn_about;
use nldf_core::host::Machine;
use nldf_core::synth::hidden_voice;
use nldf_infer::audio::windows_from_wav;
use nldf_infer::frame_graph::FrameGraph;
use nldf_infer::poses::default_pose;
use nldf_infer::still::{SkipConfig, StillTrack, bench_track, probe_frames};
use nldf_infer::{BackendKind, BackendOptions, FrameRenderer, backend_for};
use nldf_model::{FrameGraphFile, read_frame_model, read_model};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::load::LoadGate;
use crate::repeats::{Ratio, check_pairs};
use crate::report::{Written, machine_cell, write_bench_files};

/// Frames rendered before timing starts (plans compiled, caches warm).
const WARM_UP: usize = 5;

/// What to time.
#[derive(Debug, Clone)]
pub struct WebBenchJob {
    /// Frame graphs (`nldf export --frame`), e.g. fp32, fp16 and int8 of one student.
    pub models: Vec<PathBuf>,
    /// The same students' ray graphs (`nldf export`), one per frame graph in the same
    /// order, for native onnxruntime with still-pixel skipping; empty leaves it out.
    pub ray_models: Vec<PathBuf>,
    /// Timed frames per model and runtime.
    pub frames: usize,
    /// Threads of every runtime (the browser's WASM threads too).
    pub threads: usize,
    /// The page's folder (`web/`), whose `bench.mjs` times the browser; `None` times the
    /// native runtimes alone.
    pub web: Option<PathBuf>,
    /// Rounds (at least 2): every model natively, then in the browser.
    pub pairs: usize,
    /// The load limit at the start.
    pub load: LoadGate,
    /// The speech every frame's audio comes from (a WAV); `None` plays the synthetic scene's
    /// hidden voice ([`hidden_voice`] of seed 0, the shipped model's `voice` split speaker).
    pub audio: Option<PathBuf>,
}

/// One model's frame rates: the median over the rounds, each round's beside it.
#[derive(Debug, Clone, Serialize)]
pub struct WebRow {
    pub model: PathBuf,
    pub bytes: u64,
    pub width: u32,
    pub height: u32,
    /// Native onnxruntime, frames per second.
    pub ort_fps: f64,
    /// Native tract, frames per second.
    pub tract_fps: f64,
    /// Headless Chromium with onnxruntime-web, frames per second.
    pub browser_fps: Option<f64>,
    /// The page skipping still pixels, frames per second and the share of the head's rays
    /// it re-rendered.
    pub browser_skip_fps: Option<f64>,
    pub browser_skip_rays: Option<f64>,
    /// The page's skipped frames against full renders of the same frames (the first
    /// round's): PSNR over all frames, dB (`None` where identical or not measured).
    pub browser_skip_psnr: Option<f64>,
    /// What `web/bench.mjs` reported for this model (versions, threads, SIMD).
    pub browser: Option<serde_json::Value>,
    /// The ray graph timed with nldf's skipping.
    pub ray_model: Option<PathBuf>,
    /// Native onnxruntime with nldf's skipping on the ray graph, the first round (its
    /// `ray_share` is the row's; `full_ms_mean` is the ray graph's full frames).
    pub ort_skip: Option<StillTrack>,
    /// Native onnxruntime skipping still pixels, frames per second (median over the
    /// rounds).
    pub ort_skip_fps: Option<f64>,
    /// Each round's frames per second: onnxruntime, tract, the browser, the browser
    /// skipping, onnxruntime skipping.
    pub rounds_ort_fps: Vec<f64>,
    pub rounds_tract_fps: Vec<f64>,
    pub rounds_browser_fps: Vec<f64>,
    pub rounds_browser_skip_fps: Vec<f64>,
    pub rounds_ort_skip_fps: Vec<f64>,
    /// The browser's frame rate over native onnxruntime's, per round.
    pub browser_over_ort: Option<Ratio>,
    /// The same, both skipping still pixels.
    pub browser_over_ort_skipping: Option<Ratio>,
}

/// The report: `web.json`.
#[derive(Debug, Clone, Serialize)]
pub struct WebReport {
    /// `web`.
    pub bench: &'static str,
    pub machine: Machine,
    pub frames: usize,
    pub threads: usize,
    /// Rounds of every model and runtime.
    pub pairs: usize,
    /// What every frame's audio comes from: a WAV's path, or the synthetic scene's hidden
    /// voice.
    pub track: String,
    /// Its seconds.
    pub track_seconds: f64,
    /// Still-pixel skipping's settings, the page's and nldf's.
    pub skip: SkipConfig,
    pub rows: Vec<WebRow>,
}

impl WebBenchJob {
    /// The speech every frame plays: `audio`, or the synthetic scene's hidden voice written
    /// into `dir` (whole frames at 25 fps, at least 4 s, so that the skipping probes spread
    /// over it). Returns the WAV, what it is, and its samples at 16 kHz.
    fn speech(&self, dir: &Path) -> Result<(PathBuf, String, Waveform)> {
        let (wav, track) = match &self.audio {
            Some(path) => (path.clone(), path.display().to_string()),
            None => {
                let wav = dir.join("voice.wav");
                let seconds = 0.04 * (self.frames + WARM_UP).max(100) as f64;
                write_wav(&wav, &hidden_voice(0, seconds))?;
                let what = "the synthetic scene's hidden voice (seed 0)".to_string();
                (wav, what)
            }
        };
        let speech = resample(&read_wav(&wav)?, 16_000);
        if speech.samples.is_empty() {
            let problem = format!("{}: the WAV holds no samples", wav.display());
            return Err(Error::Missing(problem));
        }
        Ok((wav, track, speech))
    }

    /// Times every model natively, then in the browser, in rounds.
    pub fn run(&self, note: &mut dyn FnMut(&str)) -> Result<WebReport> {
        if !(self.ray_models.is_empty() || self.ray_models.len() == self.models.len()) {
            return Err(Error::Missing(format!(
                "{} ray graphs for {} frame graphs: give one per frame graph, or none",
                self.ray_models.len(),
                self.models.len()
            )));
        }
        check_pairs(self.pairs)?;
        let mut machine = self.load.admit()?;
        let dir = crate::error::temp_dir()?;
        let (wav, track, speech) = self.speech(dir.path())?;
        let skip = SkipConfig::default();
        let models = self
            .models
            .iter()
            .map(|p| read_frame_model(p).map_err(Error::from))
            .collect::<Result<Vec<_>>>()?;
        let mut rows: Vec<WebRow> = self
            .models
            .iter()
            .zip(&models)
            .enumerate()
            .map(|(i, (path, model))| WebRow::empty(path, model, self.ray_models.get(i).cloned()))
            .collect();
        for round in 0..self.pairs {
            let of = format!("round {} of {}", round + 1, self.pairs);
            for (row, model) in rows.iter_mut().zip(&models) {
                let path = row.model.display().to_string();
                let speech = &speech.samples;
                let ort_fps =
                    native_fps(model, BackendKind::Ort, self.threads, self.frames, speech)?;
                note(&format!("{of}: {path}: onnxruntime {ort_fps:.1} frames/s"));
                let tract_fps =
                    native_fps(model, BackendKind::Tract, self.threads, self.frames, speech)?;
                note(&format!("{of}: {path}: tract {tract_fps:.1} frames/s"));
                row.rounds_ort_fps.push(ort_fps);
                row.rounds_tract_fps.push(tract_fps);
                if let Some(rays) = &row.ray_model {
                    let track =
                        native_skip(rays, &wav, self.threads, self.frames, skip).map_err(|e| {
                            e.context(format!("{}: skipping still pixels", rays.display()))
                        })?;
                    let fps = 1e3 / track.skip_ms_mean;
                    note(&format!(
                        "{of}: {}: onnxruntime skipping still pixels {fps:.1} frames/s, {:.1} % \
                         of rays",
                        rays.display(),
                        100.0 * track.ray_share
                    ));
                    row.rounds_ort_skip_fps.push(fps);
                    row.ort_skip.get_or_insert(track);
                }
            }
            if let Some(web) = &self.web {
                let lines = browser_fps(web, &self.models, &wav, self.frames, self.threads)?;
                record_browser(&mut rows, lines, &of, note);
            }
        }
        machine.record_end();
        for row in &mut rows {
            row.summarise(self.pairs)?;
        }
        Ok(WebReport {
            bench: "web",
            machine,
            frames: self.frames,
            threads: self.threads,
            pairs: self.pairs,
            track,
            track_seconds: speech.seconds(),
            skip,
            rows,
        })
    }
}

impl WebRow {
    /// A row for the frame graph at `path`, before any round: no figure yet.
    fn empty(path: &Path, model: &FrameGraphFile, ray_model: Option<PathBuf>) -> WebRow {
        let k = model.info.spec.intrinsics;
        WebRow {
            model: path.to_path_buf(),
            bytes: model.bytes.len() as u64,
            width: k.width,
            height: k.height,
            ort_fps: f64::NAN,
            tract_fps: f64::NAN,
            browser_fps: None,
            browser_skip_fps: None,
            browser_skip_rays: None,
            browser_skip_psnr: None,
            browser: None,
            ray_model,
            ort_skip: None,
            ort_skip_fps: None,
            rounds_ort_fps: Vec::new(),
            rounds_tract_fps: Vec::new(),
            rounds_browser_fps: Vec::new(),
            rounds_browser_skip_fps: Vec::new(),
            rounds_ort_skip_fps: Vec::new(),
            browser_over_ort: None,
            browser_over_ort_skipping: None,
        }
    }
}

/// One round's browser figures (a line of the page's benchmark per frame graph) added to
/// the rows, each said in `note`.
fn record_browser(
    rows: &mut [WebRow],
    lines: Vec<serde_json::Value>,
    of: &str,
    note: &mut dyn FnMut(&str),
) {
    for (row, value) in rows.iter_mut().zip(lines) {
        let get = |key: &str| value.get(key).and_then(|v| v.as_f64());
        if let Some(fps) = get("fps") {
            row.rounds_browser_fps.push(fps);
        }
        if let Some(fps) = get("skip_fps") {
            row.rounds_browser_skip_fps.push(fps);
        }
        row.browser_skip_rays = row.browser_skip_rays.or(get("skip_ray_share"));
        row.browser_skip_psnr = row.browser_skip_psnr.or(get("skip_psnr"));
        note(&format!(
            "{of}: {}: browser {:.1} frames/s, skipping still pixels {:.1}",
            row.model.display(),
            get("fps").unwrap_or(f64::NAN),
            get("skip_fps").unwrap_or(f64::NAN)
        ));
        row.browser.get_or_insert(value);
    }
}
impl WebRow {
    /// The medians over the rounds and the browser's ratios, from a figure of every one of
    /// the `pairs` rounds (a figure some round lacks is left out, with its ratio).
    fn summarise(&mut self, pairs: usize) -> Result<()> {
        use nldf_core::stats::median;
        let all = |v: &[f64]| (v.len() == pairs).then(|| median(v));
        self.ort_fps = median(&self.rounds_ort_fps);
        self.tract_fps = median(&self.rounds_tract_fps);
        self.browser_fps = all(&self.rounds_browser_fps);
        self.browser_skip_fps = all(&self.rounds_browser_skip_fps);
        self.ort_skip_fps = all(&self.rounds_ort_skip_fps);
        let ratio = |a: &[f64], b: &[f64]| -> Result<Option<Ratio>> {
            if a.len() != pairs || b.len() != pairs {
                return Ok(None);
            }
            let pairs: Vec<(f64, f64)> = a.iter().copied().zip(b.iter().copied()).collect();
            Ratio::of_pairs(&pairs).map(Some)
        };
        self.browser_over_ort = ratio(&self.rounds_browser_fps, &self.rounds_ort_fps)?;
        self.browser_over_ort_skipping =
            ratio(&self.rounds_browser_skip_fps, &self.rounds_ort_skip_fps)?;
        Ok(())
    }
}

/// Native onnxruntime on the ray graph at `path` with nldf's still-pixel skipping
/// (`StillSkipper` with `skip`, probes spread over the WAV, as `nldf render --skip-still`):
/// `frames` frames of the WAV at the default pose after [`WARM_UP`] frames, each rendered
/// in full and with skipping in turn (`bench_track`).
fn native_skip(
    path: &Path,
    wav: &Path,
    threads: usize,
    frames: usize,
    skip: SkipConfig,
) -> Result<StillTrack> {
    let model = read_model(path)?;
    let info = &model.info;
    let windows = windows_from_wav(info, path, wav)?;
    let n = windows.n_frames.max(1);
    let audio = |f: usize| neighbourhood(&windows, f % n, info.audio.att_frames);
    let probes = probe_frames(windows.n_frames, skip.probes)
        .into_iter()
        .map(audio)
        .collect();
    // The two renderers take turns: neither pool may spin beside the other.
    let options = BackendOptions {
        batch_size: 4096,
        threads,
        spin: false,
    };
    let mut full = FrameRenderer::new(backend_for(&model, BackendKind::Ort, options)?, None)?;
    let mut skipping = FrameRenderer::new(backend_for(&model, BackendKind::Ort, options)?, None)?;
    let pose = default_pose(info, 0);
    for f in 0..WARM_UP {
        full.render(pose, &audio(f))?;
        skipping.render(pose, &audio(f))?;
    }
    Ok(bench_track(
        &mut full,
        &mut skipping,
        "still pose",
        &vec![pose; frames],
        &audio,
        skip,
        probes,
    )?)
}

/// Frames per second of `model` in the runtime `kind`: `frames` frames after
/// [`WARM_UP`], each with its own audio chunk of `speech` (16 kHz, looped) and a pose
/// turning a little from frame to frame, as a page playing a voice renders them.
pub fn native_fps(
    model: &FrameGraphFile,
    kind: BackendKind,
    threads: usize,
    frames: usize,
    speech: &[f32],
) -> Result<f64> {
    let mut graph = FrameGraph::open(model, kind, threads)?;
    let spec = &model.info.spec;
    let pose = Mat4::from_cols_array_2d(&spec.default_pose).transpose();
    let centre = spec.bounds.centre();
    let n = frames + WARM_UP;
    let needed = (n + 2) * model.audio.samples_per_frame;
    let samples: Vec<f32> = speech.iter().copied().cycle().take(needed).collect();
    let mut start = Instant::now();
    for f in 0..n {
        if f == WARM_UP {
            start = Instant::now();
        }
        let yaw = 0.3 * (f as f32 * 0.1).sin();
        let c2w = turn_about(centre, yaw, 0.0) * pose;
        graph.render(c2w, &model.audio.chunk(&samples, f))?;
    }
    Ok(frames as f64 / start.elapsed().as_secs_f64().max(1e-9))
}

/// Runs `node WEB/bench.mjs` on the models with the track `wav` and reads one JSON line
/// per model.
fn browser_fps(
    web: &Path,
    models: &[PathBuf],
    wav: &Path,
    frames: usize,
    threads: usize,
) -> Result<Vec<serde_json::Value>> {
    let script = web.join("bench.mjs");
    let mut cmd = std::process::Command::new("node");
    cmd.arg(&script)
        .arg("--wav")
        .arg(wav)
        .args(["--frames", &frames.to_string()])
        .args(["--threads", &threads.to_string()])
        .args(models);
    let out = cmd
        .output()
        .map_err(|e| Error::io(format!("running node {}", script.display()), e))?;
    if !out.status.success() {
        return Err(Error::Missing(format!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("no message")
        )));
    }
    let values: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|v| v.get("fps").is_some())
        .collect();
    if values.len() != models.len() {
        return Err(Error::Missing(format!(
            "{} reported {} models, expected {}",
            script.display(),
            values.len(),
            models.len()
        )));
    }
    Ok(values)
}

impl WebReport {
    /// Writes `web.json` and `web.md` into `out`.
    pub fn write(&self, out: &Path) -> Result<Written> {
        let k = &self.skip;
        let mut md = format!(
            "# Frame graph: frames per second\n\nMachine: {}. {} rounds, each timing every model \
             natively, then in the browser; frames per second: the median over the rounds; \
             browser / onnxruntime: the median over the rounds of the per-round ratio \
             (smallest-largest). {} timed frames per model, runtime and round \
             after {WARM_UP} warm-up frames, {} threads; each frame from its own audio \
             chunk of {} ({:.1} s). Full frames: the head turning a little from \
             frame to frame. Skipping still pixels: the head at its default pose, from a fresh \
             skipper (its full and probed frames counted), threshold {:.0}/255, margin {} px, \
             {} probes spread over the WAV, a full frame every {} still frames; the browser's \
             on the frame graph, onnxruntime's on the ray graph with nldf's skipper \
             (`nldf render --skip-still`); rays: the share of the head's rays re-rendered; \
             PSNR: the skipped frames against full renders of the same frames, over all \
             frames (an untimed pass).\n\n\
             | model | size (MB) | frame | browser (onnxruntime-web) | onnxruntime | tract | \
             browser / onnxruntime | browser, skipping (rays) | onnxruntime, skipping (rays) \
             | browser / onnxruntime, skipping | skipping PSNR (dB), browser / onnxruntime |\n\
             | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
            machine_cell(&self.machine),
            self.pairs,
            self.frames,
            self.threads,
            self.track,
            self.track_seconds,
            255.0 * k.threshold,
            k.margin,
            k.probes,
            k.refresh,
        );
        let fps = |f: Option<f64>| f.map_or_else(|| "not measured".into(), |f| format!("{f:.1}"));
        let share =
            |s: Option<f64>| s.map_or_else(String::new, |s| format!(" ({:.0} %)", 100.0 * s));
        let db = |p: Option<f64>| p.map_or_else(|| "-".into(), |p| format!("{p:.1}"));
        for r in &self.rows {
            md.push_str(&format!(
                "| {} | {:.2} | {} x {} | {} | {:.1} | {:.1} | {} | {}{} | {}{} | {} | {} / {} |\n",
                r.model.display(),
                r.bytes as f64 / 1e6,
                r.width,
                r.height,
                fps(r.browser_fps),
                r.ort_fps,
                r.tract_fps,
                crate::repeats::cell(r.browser_over_ort.as_ref()),
                fps(r.browser_skip_fps),
                share(r.browser_skip_rays),
                fps(r.ort_skip_fps),
                share(r.ort_skip.as_ref().map(|t| t.ray_share)),
                crate::repeats::cell(r.browser_over_ort_skipping.as_ref()),
                db(r.browser_skip_psnr),
                db(r.ort_skip.as_ref().and_then(|t| t.psnr_vs_full)),
            ));
        }
        let rays: Vec<String> = self
            .rows
            .iter()
            .filter_map(|r| r.ray_model.as_ref().map(|p| p.display().to_string()))
            .collect();
        if !rays.is_empty() {
            md += &format!(
                "\nRay graphs skipping in onnxruntime: {}.\n",
                rays.join(", ")
            );
        }
        write_bench_files(out, "web", self, md)
    }
}
