//! The frame graph's frame rate (`nldf bench web`): each frame graph in headless Chromium
//! with onnxruntime-web (WASM, SIMD, threads; `web/bench.mjs`), and natively in onnxruntime
//! and tract, side by side in one run on one machine, so that the browser's figure is read
//! against native onnxruntime's.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Mat4;
use nldf_core::camera::turn_about;
use nldf_export::{FrameModel, read_frame_model};
use nldf_infer::BackendKind;
use nldf_infer::frame_graph::FrameGraph;
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
    /// What `web/bench.mjs` reported for this model (versions, threads, SIMD).
    pub browser: Option<serde_json::Value>,
}

/// The report: `web.json`.
#[derive(Debug, Clone, Serialize)]
pub struct WebReport {
    /// `web`.
    pub bench: &'static str,
    pub machine: Machine,
    pub frames: usize,
    pub threads: usize,
    pub rows: Vec<WebRow>,
}

impl WebBenchJob {
    /// Times every model natively, then in the browser.
    pub fn run(&self, note: &mut dyn FnMut(&str)) -> Result<WebReport> {
        let machine = Machine::here();
        let mut rows = Vec::new();
        for path in &self.models {
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
            let k = model.info.spec.intrinsics;
            rows.push(WebRow {
                model: path.clone(),
                bytes: model.bytes.len() as u64,
                width: k.width,
                height: k.height,
                ort_fps,
                tract_fps,
                browser_fps: None,
                browser: None,
            });
        }
        if let Some(web) = &self.web {
            let lines = browser_fps(web, &self.models, self.frames, self.threads)?;
            for (row, value) in rows.iter_mut().zip(lines) {
                row.browser_fps = value.get("fps").and_then(|v| v.as_f64());
                note(&format!(
                    "{}: browser {:.1} frames/s",
                    row.model.display(),
                    row.browser_fps.unwrap_or(f64::NAN)
                ));
                row.browser = Some(value);
            }
        }
        Ok(WebReport {
            bench: "web",
            machine,
            frames: self.frames,
            threads: self.threads,
            rows,
        })
    }
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
    let rate = model.audio.sample_rate as f32;
    let samples: Vec<f32> = (0..(n + 2) * model.audio.samples_per_frame)
        .map(|i| {
            let t = i as f32 / rate;
            0.4 * (2.0 * std::f32::consts::PI * (160.0 + 50.0 * (3.0 * t).sin()) * t).sin()
        })
        .collect();
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

/// Runs `node WEB/bench.mjs` on the models and reads one JSON line per model.
fn browser_fps(
    web: &Path,
    models: &[PathBuf],
    frames: usize,
    threads: usize,
) -> Result<Vec<serde_json::Value>> {
    let script = web.join("bench.mjs");
    let mut cmd = std::process::Command::new("node");
    cmd.arg(&script)
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
        let mut md = format!(
            "# Frame graph: frames per second\n\nMachine: {}. {} timed frames per model and \
             runtime after {WARM_UP} warm-up frames, {} threads; each frame from its own audio \
             chunk, the head turning a little from frame to frame.\n\n\
             | model | size (MB) | frame | browser (onnxruntime-web) | onnxruntime | tract | \
             browser / onnxruntime |\n| --- | --- | --- | --- | --- | --- | --- |\n",
            machine_cell(&self.machine),
            self.frames,
            self.threads
        );
        for r in &self.rows {
            let browser = r
                .browser_fps
                .map(|f| format!("{f:.1}"))
                .unwrap_or_else(|| "not measured".into());
            let ratio = r
                .browser_fps
                .map(|f| format!("{:.2}", f / r.ort_fps))
                .unwrap_or_default();
            md.push_str(&format!(
                "| {} | {:.2} | {} x {} | {browser} | {:.1} | {:.1} | {ratio} |\n",
                r.model.display(),
                r.bytes as f64 / 1e6,
                r.width,
                r.height,
                r.ort_fps,
                r.tract_fps
            ));
        }
        write_bench_files(out, "web", self, md)
    }
}
