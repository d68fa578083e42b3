//! `nldf render --stream`: frames from audio that is still arriving. A reader thread decodes
//! a WAV stream (stdin or a named pipe) as it comes in; each video frame is rendered as soon
//! as its audio neighbourhood is complete ([`FeatureStream`] makes the same windows as the
//! file path, bit for bit), and written as `frame_NNNNN.png` straight into the output folder
//! (each file atomically), so that a consumer can show it at once.
//!
//! Latency is bounded: when more than `drop_behind` frames wait behind the next one (the
//! renderer has fallen that far behind the audio), it skips to the newest frame it can
//! render (the skipped frames are counted, not written), so a frame is never older than the
//! audio lookahead plus about `drop_behind + 2` frame times. The slack lets a renderer that
//! keeps up on average absorb a slow frame (another process, a page fault) without dropping
//! any. The frames still to render when the stream ends are all rendered (its end releases
//! the last few at once). `drop_behind = None` renders every frame, however far behind that
//! puts it.
//!
//! A frame's latency is measured from the moment the audio of its instant (sample
//! `ceil(f / fps * rate)`) arrived to the moment its PNG is in place; it includes the
//! lookahead the features need and the render. AD-NeRF's 16-frame windows reach 152.5 ms
//! ahead; a student with attention waits for its neighbours' 3 frames more (0.27 s at 25
//! fps); a short-lookahead student (`nldf train lookahead`) reads only the first rows of
//! its window, and the stream waits for those alone.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use glam::Mat4;
use nldf_core::audio::{FeatureConfig, Waveform};
use nldf_core::audio_stream::{FeatureStream, WavStreamDecoder};
use nldf_model::contract::ModelInfo;
use serde::Serialize;

use crate::backend::{BackendKind, BackendOptions, backend_for};
use crate::error::{Error, Result};
use crate::frame::FrameRenderer;
use crate::poses::{default_pose, pose_at, poses_from_transforms};
use crate::video::frame_file_name;
use nldf_core::audio::neighbourhood_of;

/// The report's file name in the output folder.
pub const STREAM_REPORT_FILE: &str = "stream.json";

/// Bytes read from the stream at a time.
const READ_CHUNK: usize = 4096;

/// What `nldf render --stream` was asked to do.
#[derive(Debug, Clone)]
pub struct StreamJob {
    /// The exported model.
    pub model: PathBuf,
    /// A transforms json whose poses to follow; `None`: the default sway.
    pub poses: Option<PathBuf>,
    /// The output folder (absent or empty); frames appear in it as they are rendered.
    pub out: PathBuf,
    /// Which runtime runs the network.
    pub backend: BackendKind,
    /// Batch size and threads.
    pub options: BackendOptions,
    /// The image's longer side in pixels; `None`: the model's own size.
    pub size: Option<u32>,
    /// Skip to the newest renderable frame once more than this many frames wait behind the
    /// next one (bounded latency); `None`: render every frame.
    pub drop_behind: Option<usize>,
}

/// Frames that may wait behind the next one before a stream skips to the newest: two
/// frames (80 ms at 25 fps) absorb a slow frame of a renderer that keeps up on average.
pub const DEFAULT_DROP_BEHIND: usize = 2;

/// A checked stream job: the model loaded, the poses read, the output folder made.
#[derive(Debug)]
pub struct StreamPlan {
    renderer: FrameRenderer,
    /// nldf's front end as the model was trained with it.
    features: FeatureConfig,
    poses: Option<Vec<Mat4>>,
    out: PathBuf,
    drop_behind: Option<usize>,
}

/// One rendered frame of a stream.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StreamFrame {
    /// Video frame index (its file is `frame_{index:05}.png`).
    pub index: usize,
    /// Seconds from the arrival of the frame's audio instant to its PNG being written.
    pub latency_s: f64,
    /// Seconds the frame took to render and write.
    pub render_s: f64,
    /// Pixels that went through the network.
    pub head_pixels: usize,
}

/// Latency figures over a stream's frames, in milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LatencyStats {
    pub mean_ms: f64,
    pub p50_ms: f64,
    pub p95_ms: f64,
    pub max_ms: f64,
}

impl LatencyStats {
    /// The statistics of `seconds` (all zero when empty).
    pub fn of(seconds: &[f64]) -> LatencyStats {
        if seconds.is_empty() {
            return LatencyStats {
                mean_ms: 0.0,
                p50_ms: 0.0,
                p95_ms: 0.0,
                max_ms: 0.0,
            };
        }
        let mut s: Vec<f64> = seconds.iter().map(|v| 1e3 * v).collect();
        s.sort_by(f64::total_cmp);
        let at = |q: f64| s[((q * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)];
        LatencyStats {
            mean_ms: s.iter().sum::<f64>() / s.len() as f64,
            p50_ms: nldf_core::stats::median(&s),
            p95_ms: at(0.95),
            max_ms: s[s.len() - 1],
        }
    }
}

/// What a finished stream did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StreamReport {
    /// The output folder.
    pub out: PathBuf,
    /// The input's sample rate.
    pub sample_rate: u32,
    /// Seconds of audio received.
    pub audio_seconds: f64,
    /// Video frames the audio holds.
    pub n_frames: usize,
    /// Frames skipped to keep up (not written).
    pub dropped: usize,
    /// Image size.
    pub width: u32,
    pub height: u32,
    /// The runtime.
    pub backend: BackendKind,
    /// Frames that could wait behind the next one before the stream skipped to the newest
    /// (`None`: every frame rendered).
    pub drop_behind: Option<usize>,
    /// Seconds of audio a frame waits for beyond its own instant (the features' lookahead),
    /// the floor under every latency.
    pub lookahead_s: f64,
    /// Latency over the rendered frames.
    pub latency: LatencyStats,
    /// Wall-clock seconds from the first byte to the last frame.
    pub wall_seconds: f64,
    /// Every rendered frame.
    pub frames: Vec<StreamFrame>,
}

impl StreamReport {
    /// Frames rendered and written.
    pub fn rendered(&self) -> usize {
        self.frames.len()
    }
}

impl StreamJob {
    /// Checks the model, the poses, the size and the output folder, loads the model in its
    /// runtime and makes the output folder; no audio is read yet.
    pub fn plan(&self) -> Result<StreamPlan> {
        let model = nldf_model::read_model(&self.model)?;
        let features = crate::audio::wav_features(&model.info, &self.model)?.clone();
        let poses = match &self.poses {
            Some(path) => Some(poses_from_transforms(path)?),
            None => None,
        };
        crate::frame::intrinsics_at(&model.info, self.size)?;
        check_out(&self.out)?;
        // The renderer waits for audio between frames while the reader and the writer run:
        // onnxruntime's pool must not spin beside them.
        let options = BackendOptions {
            spin: false,
            ..self.options
        };
        let renderer = FrameRenderer::new(backend_for(&model, self.backend, options)?, self.size)?;
        std::fs::create_dir_all(&self.out)
            .map_err(|e| Error::output(&self.out, format!("cannot create the folder: {e}")))?;
        Ok(StreamPlan {
            renderer,
            features,
            poses,
            out: self.out.clone(),
            drop_behind: self.drop_behind,
        })
    }
}

/// Checks that `out` is absent or an empty folder under folders (not files).
fn check_out(out: &Path) -> Result<()> {
    crate::output::check_target(out)?;
    if let Some(parent) = out.ancestors().skip(1).find(|p| p.exists())
        && !parent.is_dir()
    {
        return Err(Error::output(parent, "is a file, not a folder"));
    }
    Ok(())
}

/// What the reader thread has received so far.
#[derive(Debug, Default)]
struct Received {
    sample_rate: Option<u32>,
    /// Samples not yet taken by the renderer.
    samples: Vec<f32>,
    /// Samples received so far.
    total: usize,
    /// `(samples received so far, when)` after each read, not yet taken.
    arrivals: Vec<(usize, Instant)>,
    ended: bool,
    error: Option<String>,
}

type Shared = Arc<(Mutex<Received>, Condvar)>;

/// Reads and decodes `source` into `shared` until its end or an error.
fn read_stream(mut source: Box<dyn Read + Send>, shared: Shared) {
    let mut decoder = WavStreamDecoder::new();
    let mut buf = vec![0u8; READ_CHUNK];
    let (lock, cond) = &*shared;
    loop {
        let outcome = match source.read(&mut buf) {
            Ok(0) => decoder.finish().map(|_| None),
            Ok(n) => decoder.push(&buf[..n]).map(Some),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => Err(format!("cannot read: {e}")),
        };
        let now = Instant::now();
        let Ok(mut r) = lock.lock() else { return };
        match outcome {
            Ok(Some(samples)) => {
                if r.sample_rate.is_none() {
                    r.sample_rate = decoder.format().map(|f| f.sample_rate);
                }
                r.samples.extend_from_slice(&samples);
                r.total += samples.len();
                let n = r.total;
                r.arrivals.push((n, now));
            }
            Ok(None) => r.ended = true,
            Err(e) => r.error = Some(e),
        }
        let done = r.ended || r.error.is_some();
        drop(r);
        cond.notify_all();
        if done {
            return;
        }
    }
}

/// The next frame to render: `None` when none of `next..renderable` is; otherwise the frame
/// and how many before it are skipped: the newest when more than `drop_behind` frames wait
/// behind `next`, else `next` itself.
pub fn next_frame(
    next: usize,
    renderable: usize,
    drop_behind: Option<usize>,
) -> Option<(usize, usize)> {
    if next >= renderable {
        return None;
    }
    let waiting = renderable - next - 1;
    let f = match drop_behind {
        Some(slack) if waiting > slack => renderable - 1,
        _ => next,
    };
    Some((f, f - next))
}

impl StreamPlan {
    /// The renderer (its backend, size and metadata).
    pub fn renderer(&self) -> &FrameRenderer {
        &self.renderer
    }

    /// Reads the WAV stream `source` to its end, rendering frames as their audio arrives;
    /// `on_frame` is called after each frame. `stream_name` names the source in errors.
    /// Frames already written stay when the stream breaks (each is a whole PNG); the report
    /// `stream.json` is written only at a clean end.
    pub fn run(
        mut self,
        source: Box<dyn Read + Send>,
        stream_name: &str,
        mut on_frame: impl FnMut(&StreamFrame, usize),
    ) -> Result<StreamReport> {
        let started = Instant::now();
        let shared: Shared = Arc::new((Mutex::new(Received::default()), Condvar::new()));
        let reader = {
            let shared = Arc::clone(&shared);
            std::thread::Builder::new()
                .name("nldf-stream-reader".into())
                .spawn(move || read_stream(source, shared))
                .map_err(|e| Error::Argument(format!("cannot start the stream reader: {e}")))?
        };
        let bad = |problem: String| {
            Error::Core(nldf_core::Error::invalid(Path::new(stream_name), problem))
        };
        let info = self.renderer.info().clone();
        let fps = info.spec.fps;
        // Without attention only the frame's own window counts: no neighbour is waited for.
        let ahead = info.audio.frames_ahead();
        let rows = info.audio.rows_read();
        let mut mel: Option<FeatureStream> = None;
        let mut arrivals: Vec<(usize, Instant)> = Vec::new();
        let mut next = 0usize;
        let mut dropped = 0usize;
        let mut frames = Vec::new();
        loop {
            // Take what has arrived; wait only when no frame can be rendered.
            let can_render = mel.as_ref().is_some_and(|m| next < renderable(m, ahead));
            let (samples, ended, rate) = take_arrived(&shared, can_render, &mut arrivals, &bad)?;
            if mel.is_none()
                && let Some(rate) = rate
            {
                mel = Some(FeatureStream::new(rate, fps, &self.features)?.reading(rows));
            }
            let Some(m) = mel.as_mut() else {
                if ended {
                    return Err(bad("holds no audio".into()));
                }
                continue;
            };
            feed(m, &samples, ended, fps, &bad)?;
            // The stream's end makes its last frames (those whose windows reach past it)
            // renderable at once: waiting for the end is not falling behind, so the frames
            // still to render then are all rendered.
            let slack = self.drop_behind.filter(|_| !m.ended());
            if let Some((f, skipped)) = next_frame(next, renderable(m, ahead), slack) {
                let record = self.render_frame(m, f, &info, (started, &arrivals))?;
                dropped += skipped;
                next = f + 1;
                frames.push(record);
                on_frame(&record, dropped);
                continue;
            }
            if m.ended() && next >= m.n_ready() {
                break;
            }
        }
        let _ = reader.join();
        let m = mel.ok_or_else(|| bad("holds no audio".into()))?;
        let report = self.report(&m, frames, dropped, started, (fps, ahead));
        nldf_core::files::write_json(&self.out.join(STREAM_REPORT_FILE), &report)?;
        Ok(report)
    }

    /// Renders frame `f` of `m` and writes its PNG; its latency runs from the read that
    /// brought the frame's instant (`clock`: the stream's start and its reads).
    fn render_frame(
        &mut self,
        m: &FeatureStream,
        f: usize,
        info: &ModelInfo,
        (started, arrivals): (Instant, &[(usize, Instant)]),
    ) -> Result<StreamFrame> {
        let fps = info.spec.fps;
        let att = info.audio.att_frames;
        let t0 = Instant::now();
        let audio = neighbourhood_of(m.n_ready(), f, att, |g| m.window(g));
        let pose = match &self.poses {
            Some(p) => pose_at(p, f),
            None => default_pose(info, f),
        };
        let frame = self.renderer.render(pose, &audio)?;
        frame.image.save_png(&self.out.join(frame_file_name(f)))?;
        let written = Instant::now();
        let instant_sample = (f as f64 * m.input_rate() as f64 / fps as f64).ceil() as usize;
        // The read that brought the frame's instant (the last one if it never came).
        let k = arrivals.partition_point(|(n, _)| *n <= instant_sample);
        let heard = arrivals
            .get(k)
            .or(arrivals.last())
            .map_or(started, |(_, t)| *t);
        Ok(StreamFrame {
            index: f,
            latency_s: written.duration_since(heard).as_secs_f64(),
            render_s: written.duration_since(t0).as_secs_f64(),
            head_pixels: frame.head_pixels,
        })
    }

    /// The stream's report: its audio, frames, drops and latencies.
    fn report(
        &self,
        m: &FeatureStream,
        frames: Vec<StreamFrame>,
        dropped: usize,
        started: Instant,
        (fps, ahead): (f32, usize),
    ) -> StreamReport {
        let rate = m.input_rate();
        let k = self.renderer.intrinsics();
        let latencies: Vec<f64> = frames.iter().map(|f| f.latency_s).collect();
        // The lookahead of a frame far from the start, in seconds past its instant.
        let probe = 100;
        let lookahead_s =
            m.samples_needed(probe + ahead) as f64 / rate as f64 - probe as f64 / fps as f64;
        StreamReport {
            out: self.out.clone(),
            sample_rate: rate,
            audio_seconds: m.n_samples() as f64 / rate as f64,
            n_frames: m.n_ready(),
            dropped,
            width: k.width,
            height: k.height,
            backend: self.renderer.backend().kind(),
            drop_behind: self.drop_behind,
            lookahead_s,
            latency: LatencyStats::of(&latencies),
            wall_seconds: started.elapsed().as_secs_f64(),
            frames,
        }
    }
}

/// The samples, end and sample rate that have arrived since the last take (their reads
/// appended to `arrivals`), waiting for more only when no frame can be rendered.
fn take_arrived(
    shared: &Shared,
    can_render: bool,
    arrivals: &mut Vec<(usize, Instant)>,
    bad: &impl Fn(String) -> Error,
) -> Result<(Vec<f32>, bool, Option<u32>)> {
    let (lock, cond) = &**shared;
    let mut r = lock
        .lock()
        .map_err(|_| bad("the stream reader failed".into()))?;
    while !can_render && r.samples.is_empty() && !r.ended && r.error.is_none() {
        r = cond
            .wait(r)
            .map_err(|_| bad("the stream reader failed".into()))?;
    }
    if let Some(e) = r.error.take() {
        return Err(bad(e));
    }
    arrivals.append(&mut r.arrivals);
    Ok((std::mem::take(&mut r.samples), r.ended, r.sample_rate))
}

/// Pushes the new samples into the front end, and at the stream's end finishes it; a
/// stream shorter than one video frame is an error.
fn feed(
    m: &mut FeatureStream,
    samples: &[f32],
    ended: bool,
    fps: f32,
    bad: &impl Fn(String) -> Error,
) -> Result<()> {
    if !samples.is_empty() {
        m.push(samples)?;
    }
    if ended && !m.ended() {
        m.finish()?;
        if m.n_ready() == 0 {
            return Err(bad(format!(
                "{:.3} s of audio is shorter than one video frame (1/{fps} s)",
                m.n_samples() as f64 / m.input_rate() as f64
            )));
        }
    }
    Ok(())
}

/// Frames of `m` that can be rendered: those whose whole neighbourhood is final.
fn renderable(m: &FeatureStream, ahead: usize) -> usize {
    if m.ended() {
        m.n_ready()
    } else {
        m.n_ready().saturating_sub(ahead)
    }
}

/// A pipe that plays `wave` as a 16-bit mono WAV stream at `speed` times real time (the
/// header at once, then a piece every `piece` of audio time), as a microphone would: for
/// measuring a stream's latency and in tests. The writer thread stops when the reader
/// closes.
pub fn paced_wav_stream(
    wave: &Waveform,
    speed: f64,
    piece: Duration,
) -> Result<Box<dyn Read + Send>> {
    if !(speed.is_finite() && speed > 0.0) || piece.is_zero() {
        return Err(Error::Argument(format!(
            "paced stream: speed must be positive and the piece non-zero, got {speed} and \
             {piece:?}"
        )));
    }
    let (reader, mut writer) =
        std::io::pipe().map_err(|e| Error::Argument(format!("cannot make a pipe: {e}")))?;
    let rate = wave.sample_rate;
    // Quantised as `write_wav` stores a file, so a stream and a file of the same wave
    // decode to the same samples.
    let pcm: Vec<u8> = wave
        .quantized_16bit()
        .samples
        .iter()
        .flat_map(|&s| ((s * 32768.0) as i16).to_le_bytes())
        .collect();
    let per_piece = ((piece.as_secs_f64() * rate as f64).round() as usize).max(1) * 2;
    std::thread::Builder::new()
        .name("nldf-paced-wav".into())
        .spawn(move || {
            let mut header = Vec::with_capacity(44);
            header.extend_from_slice(b"RIFF");
            header.extend_from_slice(&u32::MAX.to_le_bytes());
            header.extend_from_slice(b"WAVEfmt ");
            header.extend_from_slice(&16u32.to_le_bytes());
            header.extend_from_slice(&1u16.to_le_bytes());
            header.extend_from_slice(&1u16.to_le_bytes());
            header.extend_from_slice(&rate.to_le_bytes());
            header.extend_from_slice(&(2 * rate).to_le_bytes());
            header.extend_from_slice(&2u16.to_le_bytes());
            header.extend_from_slice(&16u16.to_le_bytes());
            header.extend_from_slice(b"data");
            header.extend_from_slice(&u32::MAX.to_le_bytes());
            if writer.write_all(&header).is_err() {
                return;
            }
            let t0 = Instant::now();
            for (i, chunk) in pcm.chunks(per_piece).enumerate() {
                // Each piece is sent when its last sample has been "spoken".
                let spoken = ((i * per_piece + chunk.len()) / 2) as f64 / rate as f64 / speed;
                let due = t0 + Duration::from_secs_f64(spoken);
                if let Some(wait) = due.checked_duration_since(Instant::now()) {
                    std::thread::sleep(wait);
                }
                if writer.write_all(chunk).is_err() {
                    return;
                }
            }
        })
        .map_err(|e| Error::Argument(format!("cannot start the paced writer: {e}")))?;
    Ok(Box::new(reader))
}
