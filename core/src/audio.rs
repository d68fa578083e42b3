//! Audio features: WAV in, AD-NeRF-shaped windows of log-mel frames out, one window of 16
//! feature frames (50 Hz) per 25 fps video frame. The same function serves training and
//! rendering.
//!
//! The pipeline is fixed and stateless past its input, so that a stream and a file give the
//! same features: any WAV ([`read_wav`]: mono or stereo, 8 to 32-bit integer or 32-bit
//! float, any rate) -> mono -> resampled to 16 kHz by windowed sinc ([`resample`]) -> a
//! 25 ms Hann window every 20 ms -> power spectrum (realfft) -> triangular mel filters ->
//! `(log10(max(energy, 1e-10)) + 5) / 5` ([`log_mel`]) -> per video frame the 16 feature
//! frames centred on it ([`audio_windows`]).

use std::f64::consts::PI;

use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
pub(crate) use crate::wav::SincResampler;
pub use crate::wav::{Waveform, decode_wav, read_wav, resample, write_wav};

/// Audio feature windows, `data` is `[n_frames, window, n_features]` row-major (the layout of
/// AD-NeRF's `aud.npy`).
#[derive(Debug, Clone, PartialEq)]
pub struct AudioWindows {
    pub n_frames: usize,
    pub window: usize,
    pub n_features: usize,
    pub data: Vec<f32>,
}

impl AudioWindows {
    /// The `[window, n_features]` block of video frame `f`.
    pub fn frame(&self, f: usize) -> &[f32] {
        let n = self.window * self.n_features;
        &self.data[f * n..(f + 1) * n]
    }
}

/// The audio neighbourhood of video frame `f`, the model's audio input for that frame: the
/// windows of frames `f - att_frames/2 .. f + att_frames/2`, clamped to the track at its
/// ends (AD-NeRF's `smo_size` windows; AD-NeRF pads with zeros instead). Training and
/// rendering both take a frame's audio from here.
///
/// # Shapes
/// - returns `[att_frames, window, n_features]` flat (empty for an empty track)
pub fn neighbourhood(audio: &AudioWindows, f: usize, att_frames: usize) -> Vec<f32> {
    neighbourhood_of(audio.n_frames, f, att_frames, |g| audio.frame(g))
}

/// [`neighbourhood`] over any store of windows (a stream's, say): `window(g)` is frame
/// `g`'s window, for `g < n_frames`.
pub fn neighbourhood_of<'a>(
    n_frames: usize,
    f: usize,
    att_frames: usize,
    window: impl Fn(usize) -> &'a [f32],
) -> Vec<f32> {
    let mut out = Vec::new();
    if n_frames == 0 {
        return out;
    }
    for s in 0..att_frames {
        let g =
            (f as isize + s as isize - (att_frames / 2) as isize).clamp(0, n_frames as isize - 1);
        out.extend_from_slice(window(g as usize));
    }
    out
}

/// Frames after `f` whose windows `f`'s neighbourhood reads: a stream renders frame `f`
/// once frame `f + lookahead_frames(att_frames)` has its window.
pub fn lookahead_frames(att_frames: usize) -> usize {
    att_frames.saturating_sub(1) - att_frames / 2
}

/// Samples past a window's centre (the frame's instant) that reading `ahead` feature frames
/// past it takes: the last one read starts `ahead - 1` hops after the centre and ends half a
/// Hann window later (at least one frame is read).
pub fn samples_past_centre(ahead: usize, hop: usize, win: usize) -> usize {
    ahead.max(1).saturating_sub(1) * hop + win - win / 2
}

/// Settings of the log-mel features. The defaults follow common speech front ends (25 ms
/// windows every 20 ms at 16 kHz, as DeepSpeech's 50 Hz features that AD-NeRF uses) with
/// AD-NeRF's 16-frame window and its feature count F = 29.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FeatureConfig {
    /// Rate every input is resampled to, in Hz.
    pub sample_rate: u32,
    /// Samples between feature frames (320 at 16 kHz = 50 Hz).
    pub hop: usize,
    /// Hann window length in samples (400 at 16 kHz = 25 ms).
    pub win: usize,
    /// FFT length (>= `win`).
    pub n_fft: usize,
    /// Number of mel bands, the F of `aud.npy` `[N, 16, F]`.
    pub n_mels: usize,
    /// Lowest mel filter edge in Hz.
    pub f_min: f32,
    /// Highest mel filter edge in Hz (at most half the sample rate).
    pub f_max: f32,
    /// Feature frames per video frame window (AD-NeRF: 16).
    pub window: usize,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        FeatureConfig {
            sample_rate: 16_000,
            hop: 320,
            win: 400,
            n_fft: 512,
            n_mels: 29,
            f_min: 60.0,
            f_max: 7600.0,
            window: 16,
        }
    }
}

impl FeatureConfig {
    /// Feature frames per second.
    pub fn feature_rate(&self) -> f64 {
        self.sample_rate as f64 / self.hop as f64
    }

    /// Seconds of audio past a video frame's instant that its window reads when it reads
    /// `ahead` feature frames past its centre (`window / 2` of them: all, AD-NeRF's 152.5
    /// ms at the defaults): the last one read, `ahead - 1` hops after the centre, ends half
    /// a Hann window later. A video frame's instant is taken on the feature grid (every
    /// frame at 25 fps with the defaults).
    pub fn lookahead_s(&self, ahead: usize) -> f64 {
        samples_past_centre(ahead, self.hop, self.win) as f64 / self.sample_rate as f64
    }

    /// The most feature frames past a window's centre whose lookahead
    /// ([`FeatureConfig::lookahead_s`]) is at most `seconds`; `None` when not even one is.
    pub fn ahead_within(&self, seconds: f64) -> Option<usize> {
        (1..=self.window / 2)
            .rev()
            .find(|&a| self.lookahead_s(a) <= seconds + 1e-12)
    }

    /// Checks that the settings describe a usable front end.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Argument(format!("audio features: {m}")));
        if self.sample_rate < 1000 || self.hop == 0 || self.win == 0 || self.window == 0 {
            return bad("sample_rate >= 1000 and positive hop, win and window are required".into());
        }
        if self.n_fft < self.win {
            return bad(format!(
                "n_fft {} is shorter than win {}",
                self.n_fft, self.win
            ));
        }
        if self.n_mels == 0 || self.n_mels > self.n_fft / 2 {
            return bad(format!(
                "n_mels {} must be in 1..={}",
                self.n_mels,
                self.n_fft / 2
            ));
        }
        let nyquist = self.sample_rate as f32 / 2.0;
        if !(self.f_min >= 0.0 && self.f_max > self.f_min && self.f_max <= nyquist) {
            return bad(format!(
                "need 0 <= f_min < f_max <= {nyquist} Hz, got {} and {}",
                self.f_min, self.f_max
            ));
        }
        Ok(())
    }
}

/// Which front end made a set of audio features. A model records it, so that it is only
/// ever driven by features made the way it was trained on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "front_end", rename_all = "lowercase", deny_unknown_fields)]
pub enum FeatureSource {
    /// nldf's log-mel front end ([`audio_windows`]) with these settings: nldf makes the
    /// same features from any WAV file.
    Nldf(FeatureConfig),
    /// Another front end (AD-NeRF's DeepSpeech logits, say): nldf cannot make these from a
    /// WAV, so a model trained on them renders only from windows made the same way.
    Foreign {
        /// What is known of the front end.
        description: String,
        /// Features per feature frame, the F of `[N, window, F]`.
        n_features: usize,
        /// Feature frames per window.
        window: usize,
    },
}

impl Default for FeatureSource {
    fn default() -> Self {
        FeatureSource::Nldf(FeatureConfig::default())
    }
}

impl FeatureSource {
    /// Features per feature frame, F.
    pub fn n_features(&self) -> usize {
        match self {
            FeatureSource::Nldf(cfg) => cfg.n_mels,
            FeatureSource::Foreign { n_features, .. } => *n_features,
        }
    }

    /// Feature frames per window.
    pub fn window(&self) -> usize {
        match self {
            FeatureSource::Nldf(cfg) => cfg.window,
            FeatureSource::Foreign { window, .. } => *window,
        }
    }

    /// nldf's settings, when nldf made the features.
    pub fn nldf(&self) -> Option<&FeatureConfig> {
        match self {
            FeatureSource::Nldf(cfg) => Some(cfg),
            FeatureSource::Foreign { .. } => None,
        }
    }

    /// One line saying what the features are, for messages.
    pub fn describe(&self) -> String {
        match self {
            FeatureSource::Nldf(cfg) => format!(
                "nldf log-mel features ({} mels, {}-frame windows at {} Hz)",
                cfg.n_mels,
                cfg.window,
                cfg.feature_rate()
            ),
            FeatureSource::Foreign {
                description,
                n_features,
                window,
            } => format!("{description} ({window} x {n_features} windows)"),
        }
    }
}

fn hz_to_mel(f: f64) -> f64 {
    2595.0 * (1.0 + f / 700.0).log10()
}

fn mel_to_hz(m: f64) -> f64 {
    700.0 * (10f64.powf(m / 2595.0) - 1.0)
}

/// Triangular mel filters (HTK mel scale, peak 1), `[n_mels][n_fft / 2 + 1]`: the
/// weights [`log_mel`] sums each band's power with.
pub fn mel_filters(cfg: &FeatureConfig) -> Vec<Vec<f32>> {
    let n_bins = cfg.n_fft / 2 + 1;
    let (lo, hi) = (hz_to_mel(cfg.f_min as f64), hz_to_mel(cfg.f_max as f64));
    let edges: Vec<f64> = (0..cfg.n_mels + 2)
        .map(|i| mel_to_hz(lo + (hi - lo) * i as f64 / (cfg.n_mels + 1) as f64))
        .collect();
    let bin_hz = cfg.sample_rate as f64 / cfg.n_fft as f64;
    (0..cfg.n_mels)
        .map(|m| {
            let (a, b, c) = (edges[m], edges[m + 1], edges[m + 2]);
            (0..n_bins)
                .map(|k| {
                    let f = k as f64 * bin_hz;
                    let w = if f <= a || f >= c {
                        0.0
                    } else if f <= b {
                        (f - a) / (b - a)
                    } else {
                        (c - f) / (c - b)
                    };
                    w as f32
                })
                .collect()
        })
        .collect()
}

/// The periodic Hann window of `win` samples that each feature frame is weighted by, and the
/// factor `1 / (sum of the window)^2` its power spectrum is scaled by.
pub fn hann_window(cfg: &FeatureConfig) -> (Vec<f32>, f32) {
    let hann: Vec<f32> = (0..cfg.win)
        .map(|i| (0.5 - 0.5 * (2.0 * PI * i as f64 / cfg.win as f64).cos()) as f32)
        .collect();
    let s: f32 = hann.iter().sum();
    (hann, 1.0 / (s * s))
}

/// Number of feature frames of `n_samples` samples (at the feature rate): frame `k` is
/// centred on sample `k * hop`, and frames are made while that centre lies inside the audio.
pub fn n_feature_frames(n_samples: usize, cfg: &FeatureConfig) -> usize {
    n_samples.div_ceil(cfg.hop).max(1)
}

/// Number of video frames at `fps` in `n_samples` samples at `sample_rate`: every frame
/// whose whole interval `[i / fps, (i + 1) / fps)` lies inside the audio.
pub fn n_video_frames(n_samples: usize, sample_rate: u32, fps: f32) -> usize {
    let seconds = n_samples as f64 / sample_rate.max(1) as f64;
    // The small slack absorbs rounding of lengths that are whole numbers of frames.
    (seconds * fps as f64 + 1e-6).floor().max(0.0) as usize
}

/// Log-mel features of a waveform (resampled to `cfg.sample_rate` first if needed),
/// `[n_feature_frames, n_mels]` row-major; values are `(log10(max(e, 1e-10)) + 5) / 5`, so
/// silence is -1 and a full-scale tone is about +0.9. Samples outside the audio count as
/// zero.
pub fn log_mel(wave: &Waveform, cfg: &FeatureConfig) -> Result<Vec<f32>> {
    cfg.validate()?;
    let wave = resample(wave, cfg.sample_rate);
    let mut front = MelFrontEnd::new(cfg)?;
    let n_frames = n_feature_frames(wave.samples.len(), cfg);
    let mut out = Vec::with_capacity(n_frames * cfg.n_mels);
    for k in 0..n_frames {
        front.push_frame(&wave.samples, k, &mut out)?;
    }
    Ok(out)
}

/// The log-mel front end of [`log_mel`], one feature frame at a time.
pub(crate) struct MelFrontEnd {
    cfg: FeatureConfig,
    filters: Vec<Vec<f32>>,
    hann: Vec<f32>,
    norm: f32,
    fft: std::sync::Arc<dyn realfft::RealToComplex<f32>>,
    frame: Vec<f32>,
    spectrum: Vec<realfft::num_complex::Complex<f32>>,
    power: Vec<f32>,
}

impl std::fmt::Debug for MelFrontEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MelFrontEnd")
            .field("cfg", &self.cfg)
            .finish()
    }
}

impl MelFrontEnd {
    pub(crate) fn new(cfg: &FeatureConfig) -> Result<MelFrontEnd> {
        cfg.validate()?;
        let (hann, norm) = hann_window(cfg);
        let fft = RealFftPlanner::<f32>::new().plan_fft_forward(cfg.n_fft);
        Ok(MelFrontEnd {
            cfg: cfg.clone(),
            filters: mel_filters(cfg),
            hann,
            norm,
            frame: fft.make_input_vec(),
            spectrum: fft.make_output_vec(),
            power: vec![0.0f32; cfg.n_fft / 2 + 1],
            fft,
        })
    }

    /// The first sample feature frame `k` reads (it reads `win` samples from there).
    pub(crate) fn first_sample(&self, k: usize) -> isize {
        (k * self.cfg.hop) as isize - (self.cfg.win / 2) as isize
    }

    /// Appends feature frame `k` of the signal `x` (`n_mels` values) to `out`; samples
    /// outside `x` count as zero.
    pub(crate) fn push_frame(&mut self, x: &[f32], k: usize, out: &mut Vec<f32>) -> Result<()> {
        self.push_frame_from(x, self.first_sample(k), out)
    }

    /// Appends the feature frame (`n_mels` values) whose `win` samples start at sample
    /// `start` of `x`; samples outside `x` count as zero.
    pub(crate) fn push_frame_from(
        &mut self,
        x: &[f32],
        start: isize,
        out: &mut Vec<f32>,
    ) -> Result<()> {
        self.frame.iter_mut().for_each(|v| *v = 0.0);
        for (i, w) in self.hann.iter().enumerate() {
            let s = start + i as isize;
            if s >= 0 && (s as usize) < x.len() {
                self.frame[i] = x[s as usize] * w;
            }
        }
        self.fft
            .process(&mut self.frame, &mut self.spectrum)
            .map_err(|e| Error::Argument(format!("FFT failed: {e}")))?;
        for (p, c) in self.power.iter_mut().zip(&self.spectrum) {
            *p = c.norm_sqr() * self.norm;
        }
        for filter in &self.filters {
            let e: f32 = filter.iter().zip(&self.power).map(|(w, p)| w * p).sum();
            out.push((e.max(1e-10).log10() + 5.0) / 5.0);
        }
        Ok(())
    }
}

/// AD-NeRF-shaped audio windows: for each video frame `i` at `fps` (see [`n_video_frames`]),
/// the `cfg.window` feature frames centred on time `i / fps`, i.e. feature frames
/// `round(i * rate / fps) - window / 2 + j`, clamped to the first and last feature frame.
///
/// # Shapes
/// - returns `[n_video_frames, window, n_mels]`
pub fn audio_windows(wave: &Waveform, fps: f32, cfg: &FeatureConfig) -> Result<AudioWindows> {
    let n_frames = n_video_frames(wave.samples.len(), wave.sample_rate, fps);
    audio_windows_for_frames(wave, fps, cfg, n_frames)
}

/// [`audio_windows`] for exactly `n_frames` video frames: windows past the end of the audio
/// repeat its last feature frames (each index is clamped, as at the ends of every track).
///
/// # Shapes
/// - returns `[n_frames, window, n_mels]`
pub fn audio_windows_for_frames(
    wave: &Waveform,
    fps: f32,
    cfg: &FeatureConfig,
    n_frames: usize,
) -> Result<AudioWindows> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::Argument(format!("fps must be positive, got {fps}")));
    }
    let feats = log_mel(wave, cfg)?;
    let n_feat = feats.len() / cfg.n_mels;
    let mut data = Vec::with_capacity(n_frames * cfg.window * cfg.n_mels);
    for i in 0..n_frames {
        push_window(&feats, n_feat, i, fps, cfg, &mut data);
    }
    Ok(AudioWindows {
        n_frames,
        window: cfg.window,
        n_features: cfg.n_mels,
        data,
    })
}

/// The unclamped feature frames of video frame `i`'s window: `window` frames centred on
/// time `i / fps`, from the first to one past the last.
pub(crate) fn window_span(i: usize, fps: f32, cfg: &FeatureConfig) -> (isize, isize) {
    let per_video_frame = cfg.feature_rate() / fps as f64;
    let centre = (i as f64 * per_video_frame).round() as isize;
    let first = centre - (cfg.window / 2) as isize;
    (first, first + cfg.window as isize)
}

/// Appends video frame `i`'s window (`[window, n_mels]`) of the feature frames `feats`
/// (`[n_feat, n_mels]`) to `data`, each index clamped to the first and last frame.
pub(crate) fn push_window(
    feats: &[f32],
    n_feat: usize,
    i: usize,
    fps: f32,
    cfg: &FeatureConfig,
    data: &mut Vec<f32>,
) {
    let (first, end) = window_span(i, fps, cfg);
    for k in first..end {
        let k = k.clamp(0, n_feat as isize - 1) as usize;
        data.extend_from_slice(&feats[k * cfg.n_mels..(k + 1) * cfg.n_mels]);
    }
}
