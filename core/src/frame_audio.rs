//! One video frame's audio as one slice of samples: what a self-contained frame graph
//! (`nldf export --frame`) takes instead of feature windows, so that a runtime other than
//! nldf needs no front end of its own.
//!
//! Frame `f`'s neighbourhood ([`crate::audio::neighbourhood`]) reads the windows of video
//! frames `f - att_frames/2 ..`, and each window reads `window` feature frames, each of
//! which reads `win` samples. [`FrameAudio`] is the span of samples all of them read:
//! `samples` of them from sample `f * samples_per_frame + offset` of the 16 kHz track. The
//! samples of that span that lie outside the track are NaN ([`FrameAudio::chunk`]): from
//! those marks the graph knows where the track ends, and it clamps the windows and the
//! neighbourhood to the track there exactly as nldf does ([`FrameAudio::windows`] is the
//! reference). A chunk padded with zeros instead is read as silence beyond the ends.

use serde::{Deserialize, Serialize};

use crate::audio::{FeatureConfig, MelFrontEnd};
use crate::error::{Error, Result};

/// Where one video frame's audio lies on the track, and how the features are cut from it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameAudio {
    /// Rate of the samples, Hz.
    pub sample_rate: u32,
    /// Samples in a chunk.
    pub samples: usize,
    /// First sample of frame `f`'s chunk, relative to sample `f * samples_per_frame`.
    pub offset: i64,
    /// Samples per video frame (`sample_rate / fps`).
    pub samples_per_frame: usize,
    /// Feature frames per video frame, P (`samples_per_frame / hop`).
    pub features_per_frame: usize,
    /// Samples between feature frames.
    pub hop: usize,
    /// Samples each feature frame reads.
    pub win: usize,
    /// Neighbouring video frames, A.
    pub att_frames: usize,
    /// Feature frames per window, W.
    pub window: usize,
}

impl FrameAudio {
    /// The layout for the features `cfg` at `fps` video frames per second and an
    /// `att_frames` neighbourhood. A video frame must span a whole number of feature frames
    /// (nldf's defaults at 25 fps: 640 samples, 2 feature frames).
    pub fn new(cfg: &FeatureConfig, fps: f32, att_frames: usize) -> Result<FrameAudio> {
        cfg.validate()?;
        let per_frame = cfg.sample_rate as f64 / fps as f64;
        let spv = per_frame.round();
        if !(fps.is_finite() && fps > 0.0) || (per_frame - spv).abs() > 1e-6 || spv < 1.0 {
            return Err(Error::Argument(format!(
                "a video frame must span a whole number of samples: {} Hz at {fps} fps gives \
                 {per_frame:.2}",
                cfg.sample_rate
            )));
        }
        let spv = spv as usize;
        if !spv.is_multiple_of(cfg.hop) || att_frames == 0 {
            return Err(Error::Argument(format!(
                "a video frame must span a whole number of feature frames and the \
                 neighbourhood at least one frame: {spv} samples per frame, hop {}, \
                 att_frames {att_frames}",
                cfg.hop
            )));
        }
        let p = spv / cfg.hop;
        let first_feature = -((p * (att_frames / 2) + cfg.window / 2) as i64);
        let n_features = p * (att_frames - 1) + cfg.window;
        Ok(FrameAudio {
            sample_rate: cfg.sample_rate,
            samples: (n_features - 1) * cfg.hop + cfg.win,
            offset: first_feature * cfg.hop as i64 - (cfg.win / 2) as i64,
            samples_per_frame: spv,
            features_per_frame: p,
            hop: cfg.hop,
            win: cfg.win,
            att_frames,
            window: cfg.window,
        })
    }

    /// One past the last sample of a chunk that the graph reads: every sample with
    /// attention (the neighbours' windows reach the chunk's end); without, the end of the
    /// frame's own window read `ahead` feature frames past its centre (all `W / 2` for
    /// `None`; a short-lookahead student reads fewer). A live source may put its newest
    /// sample just before it and NaN after: the graph's frame is the same.
    pub fn read_end(&self, attention: bool, ahead: Option<usize>) -> usize {
        if attention {
            return self.samples;
        }
        let rows = ahead.unwrap_or(self.window / 2);
        let lookahead = crate::audio::samples_past_centre(rows, self.hop, self.win);
        ((-self.offset) as usize + lookahead).min(self.samples)
    }

    /// Feature frames a chunk holds: `P (A - 1) + W`.
    pub fn n_features(&self) -> usize {
        self.features_per_frame * (self.att_frames - 1) + self.window
    }

    /// First sample (in the chunk) of its feature frame `q`; it reads `win` samples.
    pub fn feature_start(&self, q: usize) -> usize {
        q * self.hop
    }

    /// The chunk sample at the centre of feature frame `q`: the frame exists on the track
    /// iff this sample does (nldf makes feature frame `k` while `k * hop` lies in the audio).
    pub fn feature_centre(&self, q: usize) -> usize {
        q * self.hop + self.win / 2
    }

    /// The chunk sample that is the last of neighbour `s`'s video frame (`f - A/2 + s`):
    /// that frame exists on the track iff this sample does (nldf makes every frame whose
    /// whole interval lies in the audio).
    pub fn frame_end(&self, s: usize) -> usize {
        let last =
            (s as i64 - (self.att_frames / 2) as i64 + 1) * self.samples_per_frame as i64 - 1;
        (last - self.offset) as usize
    }

    /// The chunk's feature frame that is entry `j` of neighbour `s`'s window, before
    /// clamping: `P s + j`.
    pub fn window_feature(&self, s: usize, j: usize) -> usize {
        self.features_per_frame * s + j
    }

    /// Frame `frame`'s chunk of the track `samples` (at [`FrameAudio::sample_rate`]): the
    /// samples `frame * samples_per_frame + offset ..`, NaN where that lies outside the
    /// track.
    ///
    /// # Shapes
    /// - returns `[samples]`
    pub fn chunk(&self, samples: &[f32], frame: usize) -> Vec<f32> {
        let start = (frame * self.samples_per_frame) as i64 + self.offset;
        (0..self.samples as i64)
            .map(|i| {
                let t = start + i;
                if t >= 0 && (t as usize) < samples.len() {
                    samples[t as usize]
                } else {
                    f32::NAN
                }
            })
            .collect()
    }

    /// The neighbourhood of feature windows that a chunk makes, as a frame graph computes
    /// it: NaN samples count as zero; feature frames and video frames whose deciding sample
    /// ([`FrameAudio::feature_centre`], [`FrameAudio::frame_end`]) is NaN lie off the track,
    /// and every index is clamped to those that lie on it. For a chunk of
    /// [`FrameAudio::chunk`] this equals nldf's `neighbourhood(audio_windows(..), frame)`.
    ///
    /// # Shapes
    /// - `chunk`: `[samples]`; returns `[att_frames, window, n_mels]` flat
    pub fn windows(&self, chunk: &[f32], cfg: &FeatureConfig) -> Result<Vec<f32>> {
        if chunk.len() != self.samples {
            return Err(Error::Argument(format!(
                "a frame's audio holds {} samples, expected {}",
                chunk.len(),
                self.samples
            )));
        }
        let x: Vec<f32> = chunk
            .iter()
            .map(|&v| if v.is_nan() { 0.0 } else { v })
            .collect();
        let on_track = |i: usize| !chunk[i].is_nan();
        let mut front = MelFrontEnd::new(cfg)?;
        let n_k = self.n_features();
        let mut feats = Vec::with_capacity(n_k * cfg.n_mels);
        for q in 0..n_k {
            front.push_frame_from(&x, self.feature_start(q) as isize, &mut feats)?;
        }
        let (k_lo, k_hi) = span((0..n_k).map(|q| on_track(self.feature_centre(q))));
        let (s_lo, s_hi) = span((0..self.att_frames).map(|s| on_track(self.frame_end(s))));
        let mut out = Vec::with_capacity(self.att_frames * self.window * cfg.n_mels);
        for s in 0..self.att_frames as i64 {
            let s = s.max(s_lo).min(s_hi).max(0) as usize;
            for j in 0..self.window {
                let q = (self.window_feature(s, j) as i64)
                    .max(k_lo)
                    .min(k_hi)
                    .max(0) as usize;
                out.extend_from_slice(&feats[q * cfg.n_mels..(q + 1) * cfg.n_mels]);
            }
        }
        Ok(out)
    }
}

/// The first and last index whose flag is set, as the graph finds them (`(len, -1)` when
/// none is).
fn span(flags: impl Iterator<Item = bool>) -> (i64, i64) {
    let flags: Vec<bool> = flags.collect();
    let lo = flags.iter().position(|&b| b).unwrap_or(flags.len()) as i64;
    let hi = flags.iter().rposition(|&b| b).map_or(-1, |i| i as i64);
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::audio::{Waveform, audio_windows, neighbourhood};

    fn speech_like(n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| {
                let t = i as f32 / 16_000.0;
                0.4 * (2.0 * std::f32::consts::PI * (180.0 + 40.0 * (3.0 * t).sin()) * t).sin()
                    * (0.5 + 0.5 * (7.0 * t).sin())
                    + 0.05 * ((i * 7919 % 1000) as f32 / 1000.0 - 0.5)
            })
            .collect()
    }

    #[test]
    fn default_layout_spans_the_neighbourhood() {
        let a = FrameAudio::new(&FeatureConfig::default(), 25.0, 8).unwrap();
        assert_eq!((a.samples_per_frame, a.features_per_frame), (640, 2));
        assert_eq!(a.n_features(), 30);
        assert_eq!(a.samples, 29 * 320 + 400);
        assert_eq!(a.offset, -(16 * 320 + 200));
        assert!(FrameAudio::new(&FeatureConfig::default(), 30.0, 8).is_err());
        assert!(FrameAudio::new(&FeatureConfig::default(), 25.0, 0).is_err());
    }

    /// Every frame of a track, its ends included, and a track shorter than one
    /// neighbourhood: the chunk's windows are nldf's windows, to the bit.
    #[test]
    fn chunk_windows_equal_nldf_windows_at_every_frame() {
        let cfg = FeatureConfig::default();
        for (n, att) in [
            (16_000 * 2 + 123, 8),
            (16_000 * 2, 8),
            (3000, 8),
            (16_000, 1),
        ] {
            let wave = Waveform {
                sample_rate: 16_000,
                samples: speech_like(n),
            };
            let layout = FrameAudio::new(&cfg, 25.0, att).unwrap();
            let windows = audio_windows(&wave, 25.0, &cfg).unwrap();
            assert!(windows.n_frames > 0);
            for f in 0..windows.n_frames {
                let want = neighbourhood(&windows, f, att);
                let got = layout
                    .windows(&layout.chunk(&wave.samples, f), &cfg)
                    .unwrap();
                assert!(got == want, "track of {n} samples, frame {f}");
            }
        }
    }

    /// A chunk padded with zeros is silence beyond the ends, not the clamped windows.
    #[test]
    fn zero_padding_reads_as_silence() {
        let cfg = FeatureConfig::default();
        let layout = FrameAudio::new(&cfg, 25.0, 8).unwrap();
        let wave = Waveform {
            sample_rate: 16_000,
            samples: speech_like(16_000),
        };
        let chunk = layout.chunk(&wave.samples, 0);
        let zeros: Vec<f32> = chunk
            .iter()
            .map(|v| if v.is_nan() { 0.0 } else { *v })
            .collect();
        let clamped = layout.windows(&chunk, &cfg).unwrap();
        let silent = layout.windows(&zeros, &cfg).unwrap();
        assert_ne!(clamped, silent);
        assert!(silent[..cfg.n_mels].iter().all(|&v| v == -1.0));
        assert!(layout.windows(&zeros[1..], &cfg).is_err());
    }
}
