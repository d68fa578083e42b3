//! The streaming benchmark (`nldf bench stream`): `nldf render --stream` fed a WAV at
//! real-time speed, and the latency from each frame's audio to its PNG.

use std::path::{Path, PathBuf};
use std::time::Duration;

use nldf_core::host::Machine;
use nldf_infer::stream::{LatencyStats, StreamJob, StreamReport, paced_wav_stream};
use nldf_infer::{BackendKind, BackendOptions};
use nldf_train::job::{JobEvent, OnEvent};
use serde::Serialize;

use crate::error::{Result, temp_dir};
use crate::load::LoadGate;
use crate::report::{Written, machine_cell, write_bench_files};

/// What the streaming benchmark streams.
#[derive(Debug, Clone)]
pub struct StreamBenchJob {
    /// The exported model.
    pub model: PathBuf,
    /// Speech to stream (its first `seconds` are used).
    pub audio: PathBuf,
    /// Seconds of audio to stream (positive).
    pub seconds: f64,
    /// Runtime for the network.
    pub backend: BackendKind,
    /// The image's longer side in pixels; `None`: the model's training size.
    pub size: Option<u32>,
    /// Audio sent per write, in milliseconds (a microphone's buffer).
    pub piece_ms: u64,
    /// Frames that may wait behind the next one before the stream skips to the newest.
    pub drop_behind: usize,
    /// The load limit at the start.
    pub load: LoadGate,
}

/// The streaming benchmark's settings, as its JSON records them.
#[derive(Debug, Clone, Serialize)]
pub struct StreamSettings {
    pub audio: PathBuf,
    pub seconds: f64,
    pub piece_ms: u64,
    pub size: Option<u32>,
    pub drop_behind: usize,
}

/// The streaming benchmark's report: `stream.json`.
#[derive(Debug, Clone, Serialize)]
pub struct StreamBenchReport {
    /// `stream`.
    pub bench: &'static str,
    pub machine: Machine,
    /// The exported model.
    pub model: PathBuf,
    pub settings: StreamSettings,
    pub result: StreamReport,
}

impl StreamBenchJob {
    /// Streams the audio's first `seconds` at real-time speed into a temporary folder.
    pub fn run(&self, on_event: OnEvent) -> Result<StreamBenchReport> {
        let mut machine = self.load.admit()?;
        let wave = nldf_core::audio::read_wav(&self.audio)?;
        let wave = wave.truncated((self.seconds * wave.sample_rate as f64) as usize);
        let frames = temp_dir()?;
        let job = StreamJob {
            model: self.model.clone(),
            poses: None,
            out: frames.path().join("frames"),
            backend: self.backend,
            options: BackendOptions::default(),
            size: self.size,
            drop_behind: Some(self.drop_behind),
        };
        let plan = job.plan()?;
        on_event(&JobEvent::Note(format!(
            "streaming {:.1} s of {} at real-time speed",
            wave.seconds(),
            self.audio.display()
        )));
        let source = paced_wav_stream(&wave, 1.0, Duration::from_millis(self.piece_ms.max(1)))?;
        let result = plan.run(source, "the paced stream", |_, _| {})?;
        machine.record_end();
        Ok(StreamBenchReport {
            bench: "stream",
            machine,
            model: self.model.clone(),
            settings: StreamSettings {
                audio: self.audio.clone(),
                seconds: self.seconds,
                piece_ms: self.piece_ms,
                size: self.size,
                drop_behind: self.drop_behind,
            },
            result,
        })
    }
}

impl StreamBenchReport {
    /// Writes `stream.json` and `stream.md` into `out`.
    pub fn write(&self, out: &Path) -> Result<Written> {
        write_bench_files(out, "stream", self, self.markdown())
    }

    /// The table: input, frames, render time and latency.
    pub fn markdown(&self) -> String {
        let report = &self.result;
        let s = &self.settings;
        let l = report.latency;
        let render_ms: Vec<f64> = report.frames.iter().map(|f| 1e3 * f.render_s).collect();
        let mean_render = render_ms.iter().sum::<f64>() / render_ms.len().max(1) as f64;
        let render =
            LatencyStats::of(&report.frames.iter().map(|f| f.render_s).collect::<Vec<_>>());
        format!(
            "| stream, {} | value |\n|---|---|\n\
             | machine | {} |\n\
             | model | {} |\n\
             | input | {:.1} s of {} at real-time speed, {} ms pieces, {}x{} frames |\n\
             | frames | {} of {} rendered, {} skipped to keep up (skipping once more than {} wait) |\n\
             | render time per frame, PNG written | {:.1} ms mean, median {:.1}, p95 {:.1}, max {:.1} |\n\
             | features' lookahead | {:.0} ms |\n\
             | latency, audio to PNG | mean {:.0} ms, median {:.0}, p95 {:.0}, max {:.0} |\n",
            report.backend,
            machine_cell(&self.machine),
            self.model.display(),
            report.audio_seconds,
            s.audio.display(),
            s.piece_ms,
            report.width,
            report.height,
            report.rendered(),
            report.n_frames,
            report.dropped,
            s.drop_behind,
            mean_render,
            render.p50_ms,
            render.p95_ms,
            render.max_ms,
            1e3 * report.lookahead_s,
            l.mean_ms,
            l.p50_ms,
            l.p95_ms,
            l.max_ms,
        )
    }
}
