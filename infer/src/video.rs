//! A talking-head video from a model and a WAV file (or ready-made feature windows): a plan
//! that checks every input and the output folder before any frame is rendered, then one PNG
//! per video frame (audio windows from the WAV, a pose per frame), and an MP4 with the audio
//! muxed in when ffmpeg is on the PATH. Everything is written into a staging folder that replaces `out` only on success.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use glam::Mat4;
use nldf_core::audio::AudioWindows;

use nldf_core::audio::neighbourhood;

use crate::audio::{windows_from_npy, windows_from_wav};
use crate::backend::{BackendKind, BackendOptions, backend_for};
use crate::error::{Error, Result};
use crate::frame::FrameRenderer;
use crate::output::Staging;
use crate::poses::{default_track, pose_at, poses_from_transforms};
use crate::still::{FrameKind, SkipConfig, StillSkipper, probe_frames};

/// File name of frame `f` in the output folder.
pub fn frame_file_name(f: usize) -> String {
    format!("frame_{f:05}.png")
}

/// The video's file name in the output folder.
pub const VIDEO_FILE: &str = "video.mp4";

/// What `nldf render` was asked to do.
#[derive(Debug, Clone)]
pub struct VideoJob {
    /// The exported model (`.onnx` written by `nldf export`).
    pub model: PathBuf,
    /// The speech to animate, a WAV file: the source of the audio features (unless
    /// `features` are given) and the MP4's sound.
    pub audio: Option<PathBuf>,
    /// Ready-made feature windows (`aud.npy`, `[N, window, F]`), one per video frame, made
    /// by the front end the model was trained on; a model trained on another front end's
    /// features than nldf's renders only from these.
    pub features: Option<PathBuf>,
    /// A transforms json whose camera poses to follow; `None`: the default track.
    pub poses: Option<PathBuf>,
    /// The output folder (absent or empty).
    pub out: PathBuf,
    /// Which runtime runs the network.
    pub backend: BackendKind,
    /// Batch size and threads.
    pub options: BackendOptions,
    /// The image's longer side in pixels; `None`: the model's own size.
    pub size: Option<u32>,
    /// Mux an MP4 when ffmpeg is found.
    pub mp4: bool,
    /// The ffmpeg binary; `None`: `ffmpeg` on the PATH.
    pub ffmpeg: Option<PathBuf>,
    /// Re-render only the pixels the audio moves while the pose holds still
    /// ([`crate::still`]); `None`: every frame in full.
    pub skip: Option<SkipConfig>,
}

/// A checked job, ready to render: the model is loaded in its runtime, the audio features
/// and poses are made, and the staging folder exists.
#[derive(Debug)]
pub struct VideoPlan {
    renderer: FrameRenderer,
    windows: AudioWindows,
    poses: Vec<Mat4>,
    skipper: Option<StillSkipper>,
    staging: Staging,
    audio: Option<PathBuf>,
    ffmpeg: Option<PathBuf>,
    mp4_asked: bool,
}

/// Progress after each frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameProgress {
    /// Frames done.
    pub done: usize,
    /// Frames in all.
    pub total: usize,
    /// Pixels of the last frame that went through the network.
    pub head_pixels: usize,
}

/// What a finished render wrote and how fast it ran.
#[derive(Debug, Clone, PartialEq)]
pub struct VideoReport {
    /// The output folder.
    pub out: PathBuf,
    /// Every file written, frames first.
    pub files: Vec<PathBuf>,
    /// Frames rendered.
    pub n_frames: usize,
    /// Image size.
    pub width: u32,
    pub height: u32,
    /// The video's frame rate.
    pub fps: f32,
    /// Seconds spent rendering frames (network, rays and assembly; PNG writing excluded).
    pub render_seconds: f64,
    /// Seconds spent writing PNGs.
    pub write_seconds: f64,
    /// Mean rays through the network per output pixel: the fraction of the pixels whose
    /// rays did, or with a learned upsampler (one ray per `r x r` block) its coarse rays.
    pub head_fraction: f64,
    /// Frames rendered in full (all of them without skipping).
    pub full_frames: usize,
    /// The MP4, when ffmpeg was found and asked for.
    pub video: Option<PathBuf>,
    /// True when an MP4 was asked for but ffmpeg is not on the PATH.
    pub ffmpeg_missing: bool,
}

impl VideoJob {
    /// Checks every input and the output folder, loads the model in its runtime and makes
    /// the audio features and poses; nothing is rendered yet.
    pub fn plan(&self) -> Result<VideoPlan> {
        let model = nldf_model::read_model(&self.model)?;
        let windows = match (&self.features, &self.audio) {
            (Some(npy), _) => windows_from_npy(&model.info, npy)?,
            (None, Some(wav)) => windows_from_wav(&model.info, &self.model, wav)?,
            (None, None) => {
                return Err(Error::Argument(
                    "nothing to animate: give a WAV file (--audio) or feature windows \
                     (--features)"
                        .into(),
                ));
            }
        };
        if let Some(wav) = self.audio.as_ref().filter(|_| self.features.is_some()) {
            // The soundtrack of a render from features: it must at least be a WAV.
            nldf_core::audio::read_wav(wav)?;
        }
        let poses = match &self.poses {
            Some(path) => poses_from_transforms(path)?,
            None => default_track(&model.info, windows.n_frames),
        };
        crate::frame::intrinsics_at(&model.info, self.size)?;
        let ffmpeg = match (&self.ffmpeg, self.mp4) {
            (_, false) => None,
            (Some(path), true) if path.is_file() => Some(path.clone()),
            (Some(path), true) => {
                return Err(Error::Argument(format!(
                    "{}: no ffmpeg binary there",
                    path.display()
                )));
            }
            (None, true) => ffmpeg_on_path(),
        };
        let skipper = match self.skip {
            Some(config) => {
                let att = model.info.audio.att_frames;
                let probes = probe_frames(windows.n_frames, config.probes)
                    .into_iter()
                    .map(|f| neighbourhood(&windows, f, att))
                    .collect();
                Some(StillSkipper::new(config, probes)?)
            }
            None => None,
        };
        let staging = Staging::create(&self.out)?;
        let renderer =
            FrameRenderer::new(backend_for(&model, self.backend, self.options)?, self.size)?;
        Ok(VideoPlan {
            renderer,
            windows,
            poses,
            skipper,
            staging,
            audio: self.audio.clone(),
            ffmpeg,
            mp4_asked: self.mp4,
        })
    }
}

impl VideoPlan {
    /// Frames the video will have (one per 1/fps of audio).
    pub fn n_frames(&self) -> usize {
        self.windows.n_frames
    }

    /// The renderer (its backend, size and metadata).
    pub fn renderer(&self) -> &FrameRenderer {
        &self.renderer
    }

    /// Whether an MP4 will be muxed.
    pub fn will_mux(&self) -> bool {
        self.ffmpeg.is_some()
    }

    /// Renders every frame into the staging folder, muxes the MP4 when ffmpeg was found, and
    /// moves the folder into place. `on_frame` is called after each frame.
    pub fn render(mut self, mut on_frame: impl FnMut(FrameProgress)) -> Result<VideoReport> {
        let total = self.windows.n_frames;
        let att = self.renderer.info().audio.att_frames;
        let k = self.renderer.intrinsics();
        let fps = self.renderer.info().spec.fps;
        let mut files = Vec::with_capacity(total + 1);
        let (mut render_seconds, mut write_seconds, mut head) = (0.0, 0.0, 0usize);
        let mut full_frames = 0;
        for f in 0..total {
            let started = Instant::now();
            let audio = neighbourhood(&self.windows, f, att);
            let pose = pose_at(&self.poses, f);
            let frame = match &mut self.skipper {
                Some(skipper) => {
                    let out = skipper.render(&mut self.renderer, pose, &audio)?;
                    full_frames += usize::from(out.kind == FrameKind::Full);
                    out.frame
                }
                None => {
                    full_frames += 1;
                    self.renderer.render(pose, &audio)?
                }
            };
            render_seconds += started.elapsed().as_secs_f64();
            let started = Instant::now();
            let name = frame_file_name(f);
            frame.image.save_png(&self.staging.path().join(&name))?;
            write_seconds += started.elapsed().as_secs_f64();
            files.push(PathBuf::from(name));
            head += frame.head_pixels;
            on_frame(FrameProgress {
                done: f + 1,
                total,
                head_pixels: frame.head_pixels,
            });
        }
        let mut video = None;
        if let Some(ffmpeg) = &self.ffmpeg {
            mux_mp4(ffmpeg, self.staging.path(), fps, self.audio.as_deref())?;
            files.push(PathBuf::from(VIDEO_FILE));
            video = Some(PathBuf::from(VIDEO_FILE));
        }
        let out = self.staging.finish()?;
        Ok(VideoReport {
            files: files.iter().map(|f| out.join(f)).collect(),
            video: video.map(|v| out.join(v)),
            out,
            n_frames: total,
            width: k.width,
            height: k.height,
            fps,
            render_seconds,
            write_seconds,
            head_fraction: head as f64 / (total.max(1) * k.n_pixels()) as f64,
            full_frames,
            ffmpeg_missing: self.mp4_asked && self.ffmpeg.is_none(),
        })
    }
}

/// `ffmpeg` on the PATH, if any.
pub fn ffmpeg_on_path() -> Option<PathBuf> {
    crate::ort_library::on_path("ffmpeg")
}

/// Muxes `folder/frame_%05d.png` at `fps`, with the audio of `wav` when given, into
/// `folder/video.mp4` (H.264, or MPEG-4 part 2 when the ffmpeg build lacks libx264; AAC
/// audio).
pub fn mux_mp4(ffmpeg: &Path, folder: &Path, fps: f32, wav: Option<&Path>) -> Result<()> {
    let out = folder.join(VIDEO_FILE);
    let mut last_error = String::new();
    for codec in ["libx264", "mpeg4"] {
        let mut cmd = Command::new(ffmpeg);
        cmd.args(["-nostdin", "-y", "-loglevel", "error", "-framerate"])
            .arg(format!("{fps}"))
            .arg("-i")
            .arg(folder.join("frame_%05d.png"));
        if let Some(wav) = wav {
            cmd.arg("-i")
                .arg(wav)
                .args(["-map", "0:v", "-map", "1:a", "-c:a", "aac", "-shortest"]);
        }
        let result = cmd
            .args([
                "-vf",
                "pad=ceil(iw/2)*2:ceil(ih/2)*2",
                "-c:v",
                codec,
                "-pix_fmt",
                "yuv420p",
            ])
            .arg(&out)
            .output()
            .map_err(|e| Error::io(ffmpeg, e))?;
        if result.status.success() {
            return Ok(());
        }
        last_error = String::from_utf8_lossy(&result.stderr)
            .lines()
            .next()
            .unwrap_or("no message")
            .to_string();
    }
    let _ = std::fs::remove_file(&out);
    Err(Error::output(
        &out,
        format!("ffmpeg could not write the video: {last_error}"),
    ))
}
