//! The frame graph's frame rate (`nldf bench web`): each frame graph in headless Chromium
//! with onnxruntime-web (WASM, SIMD, threads; `web/bench.mjs`), and natively in onnxruntime
//! and tract, side by side in one run on one machine, so that the browser's figure is read
//! against native onnxruntime's. Full frames with the head turning, and frames skipping
//! still pixels at the default pose: the page's skipping beside nldf's own
//! (`nldf_infer::still::StillSkipper`, as `nldf render --skip-still`) on the same student's
//! ray graph in onnxruntime, over the same WAV.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Mat4;
use nldf_core::audio::{Waveform, neighbourhood, write_wav};
use nldf_core::camera::turn_about;
use nldf_export::{FrameModel, read_frame_model, read_model};
use nldf_infer::audio::windows_from_wav;
use nldf_infer::frame_graph::FrameGraph;
use nldf_infer::poses::default_pose;
use nldf_infer::still::{SkipConfig, StillTrack, bench_track, probe_frames};
use nldf_infer::{BackendKind, BackendOptions, FrameRenderer, backend_for};
use nldf_train::bench::Machine;
use serde::Serialize;

use crate::error::{Error, Result};
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
}

/// One model's frame rates.
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
    /// What `web/bench.mjs` reported for this model (versions, threads, SIMD).
    pub browser: Option<serde_json::Value>,
    /// The ray graph timed with nldf's skipping.
    pub ray_model: Option<PathBuf>,
    /// Native onnxruntime with nldf's skipping on the ray graph (its `skip_ms_mean` is
    /// the figure; `full_ms_mean` is the ray graph's full frames).
    pub ort_skip: Option<StillTrack>,
}

/// The report: `web.json`.
#[derive(Debug, Clone, Serialize)]
pub struct WebReport {
    /// `web`.
    pub bench: &'static str,
    pub machine: Machine,
    pub frames: usize,
    pub threads: usize,
    /// Seconds of the WAV (a voiced test signal) every frame's audio comes from.
    pub track_seconds: f64,
    /// Still-pixel skipping's settings, the page's and nldf's.
    pub skip: SkipConfig,
    pub rows: Vec<WebRow>,
}

impl WebBenchJob {
    /// Times every model natively, then in the browser.
    pub fn run(&self, note: &mut dyn FnMut(&str)) -> Result<WebReport> {
        if !(self.ray_models.is_empty() || self.ray_models.len() == self.models.len()) {
            return Err(Error::Missing(format!(
                "{} ray graphs for {} frame graphs: give one per frame graph, or none",
                self.ray_models.len(),
                self.models.len()
            )));
        }
        let machine = Machine::here();
        let dir = crate::error::temp_dir()?;
        let wav = dir.path().join("voice.wav");
        // Whole frames at 25 fps, at least 4 s: the skipping probes spread over the clip.
        let track_samples = 640 * (self.frames + WARM_UP).max(100);
        write_wav(
            &wav,
            &Waveform {
                sample_rate: 16_000,
                samples: voice(track_samples),
            },
        )?;
        let skip = SkipConfig::default();
        let mut rows = Vec::new();
        for (i, path) in self.models.iter().enumerate() {
            let model = read_frame_model(path)?;
            let ort_fps = native_fps(&model, BackendKind::Ort, self.threads, self.frames)?;
            note(&format!(
                "{}: onnxruntime {ort_fps:.1} frames/s",
                path.display()
            ));
            let tract_fps = native_fps(&model, BackendKind::Tract, self.threads, self.frames)?;
            note(&format!(
                "{}: tract {tract_fps:.1} frames/s",
                path.display()
            ));
            let ray_model = self.ray_models.get(i).cloned();
            let ort_skip = match &ray_model {
                Some(rays) => {
                    let track =
                        native_skip(rays, &wav, self.threads, self.frames, skip).map_err(|e| {
                            e.context(format!("{}: skipping still pixels", rays.display()))
                        })?;
                    note(&format!(
                        "{}: onnxruntime skipping still pixels {:.1} frames/s, {:.1} % of rays",
                        rays.display(),
                        1e3 / track.skip_ms_mean,
                        100.0 * track.ray_share
                    ));
                    Some(track)
                }
                None => None,
            };
            let k = model.info.spec.intrinsics;
            rows.push(WebRow {
                model: path.clone(),
                bytes: model.bytes.len() as u64,
                width: k.width,
                height: k.height,
                ort_fps,
                tract_fps,
                browser_fps: None,
                browser_skip_fps: None,
                browser_skip_rays: None,
                browser: None,
                ray_model,
                ort_skip,
            });
        }
        if let Some(web) = &self.web {
            let lines = browser_fps(web, &self.models, &wav, self.frames, self.threads)?;
            for (row, value) in rows.iter_mut().zip(lines) {
                let get = |key: &str| value.get(key).and_then(|v| v.as_f64());
                row.browser_fps = get("fps");
                row.browser_skip_fps = get("skip_fps");
                row.browser_skip_rays = get("skip_ray_share");
                note(&format!(
                    "{}: browser {:.1} frames/s, skipping still pixels {:.1}",
                    row.model.display(),
                    row.browser_fps.unwrap_or(f64::NAN),
                    row.browser_skip_fps.unwrap_or(f64::NAN)
                ));
                row.browser = Some(value);
            }
        }
        Ok(WebReport {
            bench: "web",
            machine,
            frames: self.frames,
            threads: self.threads,
            track_seconds: track_samples as f64 / 16_000.0,
            skip,
            rows,
        })
    }
}

/// A voiced, wobbling test signal, `n` samples at 16 kHz.
fn voice(n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| {
            let t = i as f32 / 16_000.0;
            0.4 * (2.0 * std::f32::consts::PI * (160.0 + 50.0 * (3.0 * t).sin()) * t).sin()
        })
        .collect()
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
/// [`WARM_UP`], each with its own audio chunk and a pose turning a little from frame to
/// frame, as a page playing a voice renders them.
pub fn native_fps(
    model: &FrameModel,
    kind: BackendKind,
    threads: usize,
    frames: usize,
) -> Result<f64> {
    let mut graph = FrameGraph::open(model, kind, threads)?;
    let spec = &model.info.spec;
    let pose = Mat4::from_cols_array_2d(&spec.default_pose).transpose();
    let centre = spec.bounds.centre();
    let n = frames + WARM_UP;
    let samples = voice((n + 2) * model.audio.samples_per_frame);
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
            "# Frame graph: frames per second\n\nMachine: {}. {} timed frames per model and \
             runtime after {WARM_UP} warm-up frames, {} threads; each frame from its own audio \
             chunk of a {:.1} s voiced test WAV. Full frames: the head turning a little from \
             frame to frame. Skipping still pixels: the head at its default pose, from a fresh \
             skipper (its full and probed frames counted), threshold {:.0}/255, margin {} px, \
             {} probes spread over the WAV, a full frame every {} still frames; the browser's \
             on the frame graph, onnxruntime's on the ray graph with nldf's skipper \
             (`nldf render --skip-still`); rays: the share of the head's rays re-rendered.\n\n\
             | model | size (MB) | frame | browser (onnxruntime-web) | onnxruntime | tract | \
             browser / onnxruntime | browser, skipping (rays) | onnxruntime, skipping (rays) \
             | browser / onnxruntime, skipping |\n\
             | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
            machine_cell(&self.machine),
            self.frames,
            self.threads,
            self.track_seconds,
            255.0 * k.threshold,
            k.margin,
            k.probes,
            k.refresh,
        );
        let fps = |f: Option<f64>| f.map_or_else(|| "not measured".into(), |f| format!("{f:.1}"));
        let share =
            |s: Option<f64>| s.map_or_else(String::new, |s| format!(" ({:.0} %)", 100.0 * s));
        let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => format!("{:.2}", a / b),
            _ => String::new(),
        };
        for r in &self.rows {
            let ort_skip = r.ort_skip.as_ref().map(|t| 1e3 / t.skip_ms_mean);
            md.push_str(&format!(
                "| {} | {:.2} | {} x {} | {} | {:.1} | {:.1} | {} | {}{} | {}{} | {} |\n",
                r.model.display(),
                r.bytes as f64 / 1e6,
                r.width,
                r.height,
                fps(r.browser_fps),
                r.ort_fps,
                r.tract_fps,
                ratio(r.browser_fps, Some(r.ort_fps)),
                fps(r.browser_skip_fps),
                share(r.browser_skip_rays),
                fps(ort_skip),
                share(r.ort_skip.as_ref().map(|t| t.ray_share)),
                ratio(r.browser_skip_fps, ort_skip),
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
