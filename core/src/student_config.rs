//! The student's shape, read by every stage that builds, exports or renders it: the audio
//! encoder's sizes ([`AudioConfig`], shared with the teacher) and the light-field network's
//! ([`StudentConfig`]: beam points K and frequencies L, depth, width, segments M). The
//! trainer saves it under `model` in the student's `config.json`; the exporter reads it back
//! from there.

use serde::{Deserialize, Serialize};

use crate::audio::FeatureSource;
use crate::beam::BeamSpec;
use crate::checks::{MAX_WIDTH, in_range};
use crate::dataset::Dataset;
use crate::error::{Error, Result};

/// The audio encoder (AD-NeRF's AudioNet and AudioAttNet).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AudioConfig {
    /// Features per audio frame, the F of `aud.npy` `[N, 16, F]` (set from the data).
    pub n_features: usize,
    /// Feature frames per window (AD-NeRF: 16).
    pub window: usize,
    /// Width of the audio code (AD-NeRF: 64).
    pub dim: usize,
    /// Neighbouring frames fused by AudioAttNet (AD-NeRF: 8).
    pub att_frames: usize,
    /// Which front end made the features (set from the data): later stages read the
    /// dataset's audio the same way, and an exported model records it.
    pub features: FeatureSource,
    /// Feature frames past the window's centre that the encoder reads; the later ones are
    /// zeroed before it (`None`: all `window / 2` of them, AD-NeRF's 152.5 ms of future
    /// audio). A short-lookahead encoder (`nldf train lookahead`) reads fewer, so that a
    /// stream renders a frame sooner (at 50 Hz, 20 ms per frame fewer); it needs a student
    /// without attention, whose neighbours' windows would read further.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ahead: Option<usize>,
}

impl Default for AudioConfig {
    fn default() -> Self {
        AudioConfig {
            n_features: 29,
            window: 16,
            dim: 64,
            att_frames: 8,
            features: FeatureSource::default(),
            ahead: None,
        }
    }
}

impl AudioConfig {
    /// Takes the features' width, window and source from a loaded dataset.
    pub fn set_from(&mut self, dataset: &Dataset) {
        self.n_features = dataset.audio.n_features;
        self.window = dataset.audio.window;
        self.features = dataset.audio_source.clone();
    }

    /// Checks the audio encoder's sizes; `at` prefixes the keys (`model.audio`).
    pub fn check(&self, at: &str) -> Result<()> {
        if self.window != 16 {
            return Err(Error::Argument(format!(
                "`{at}.window` must be 16 feature frames (AudioNet halves it 4 times), got {}",
                self.window
            )));
        }
        in_range(&format!("{at}.n_features"), self.n_features, 1, 4096)?;
        if (self.features.n_features(), self.features.window()) != (self.n_features, self.window) {
            return Err(Error::Argument(format!(
                "`{at}.features` describe {} x {} windows, `{at}` says {} x {}",
                self.features.window(),
                self.features.n_features(),
                self.window,
                self.n_features
            )));
        }
        in_range(&format!("{at}.dim"), self.dim, 1, MAX_WIDTH)?;
        if let Some(a) = self.ahead {
            in_range(&format!("{at}.ahead"), a, 1, self.window / 2)?;
        }
        in_range(&format!("{at}.att_frames"), self.att_frames, 1, 64)
    }

    /// Rows of each `[window, n_features]` window the encoder reads, from the first: the
    /// rest are zeroed (`window / 2 + ahead`; all without `ahead`).
    pub fn rows_read(&self) -> usize {
        rows_read(self.window, self.ahead)
    }
}

/// Rows of a `window`-row audio window that an encoder reading `ahead` feature frames past
/// its centre reads, from the first (all of them for `None`).
pub fn rows_read(window: usize, ahead: Option<usize>) -> usize {
    ahead.map_or(window, |a| (window / 2 + a).min(window))
}

/// A retired switch (`opacity`, `anchor_beams`) read from a config written before checkpoint
/// version 2: `true`, the only behaviour left, is accepted; `false` is refused.
fn retired_on<'de, D: serde::Deserializer<'de>>(de: D) -> std::result::Result<(), D::Error> {
    if bool::deserialize(de)? {
        Ok(())
    } else {
        Err(serde::de::Error::custom(
            "switched off by a config of an older nldf: every student now predicts opacity \
             and anchors its beams (remove the key, and train again)",
        ))
    }
}

/// The student's shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StudentConfig {
    pub audio: AudioConfig,
    /// How each ray becomes the network's input (paper: K = 16 points, L = 10).
    pub beam: BeamSpec,
    /// Linear layers in all: 1 input layer, `(depth - 2) / 2` residual blocks of two, 1 output
    /// layer (paper Table 3: 28, 50, 88).
    pub depth: usize,
    /// Hidden width (paper: 256).
    pub width: usize,
    /// Segments per ray, M (paper: 4).
    pub segments: usize,
    /// Fuse the codes of `audio.att_frames` neighbouring frames with AudioAttNet (AD-NeRF's
    /// smoothing); without, only the frame's own window is encoded.
    pub attention: bool,
    /// `opacity` of configs written before checkpoint version 2: every student now predicts
    /// its rays' opacity (how much of the ray the head covers, distilled from the teacher's
    /// accumulated weight) and composites `sum_i c_i + (1 - opacity) * background[pixel]`.
    /// Read when `true` (what it always means now), refused when `false`; never written.
    #[serde(
        rename = "opacity",
        default,
        skip_serializing,
        deserialize_with = "retired_on"
    )]
    pub retired_opacity: (),
    /// `anchor_beams` of configs written before checkpoint version 2: the trainer now always
    /// anchors the beams at the head ([`crate::beam::BeamAnchor`], `beam.anchor` set from
    /// the training cameras when a config leaves it out). Read when `true`, refused when
    /// `false`; never written.
    #[serde(
        rename = "anchor_beams",
        default,
        skip_serializing,
        deserialize_with = "retired_on"
    )]
    pub retired_anchor_beams: (),
}

impl Default for StudentConfig {
    fn default() -> Self {
        StudentConfig::paper_d88()
    }
}

impl StudentConfig {
    fn paper(depth: usize) -> StudentConfig {
        StudentConfig {
            audio: AudioConfig::default(),
            beam: BeamSpec::default(),
            depth,
            width: 256,
            segments: 4,
            attention: true,
            retired_opacity: (),
            retired_anchor_beams: (),
        }
    }

    /// The real-time preset: 16 layers at width 128 with K = 8 beam points (L = 10), a
    /// seventh of the 28 x 256 student's multiply-adds per ray; picked on the measured
    /// run-time against error frontier (`nldf bench frontier`).
    pub fn realtime() -> StudentConfig {
        StudentConfig {
            beam: BeamSpec {
                n_points: 8,
                ..BeamSpec::default()
            },
            width: 128,
            ..Self::paper(16)
        }
    }

    /// 28 layers at width 256 (paper Table 3).
    pub fn paper_d28() -> StudentConfig {
        Self::paper(28)
    }

    /// 50 layers at width 256 (paper Table 3).
    pub fn paper_d50() -> StudentConfig {
        Self::paper(50)
    }

    /// 88 layers at width 256, the paper's and R2L's main setting (1 + 43 x 2 + 1).
    pub fn paper_d88() -> StudentConfig {
        Self::paper(88)
    }

    /// 6 layers at width 32 with 4 beam points and 4 frequencies, for tests.
    pub fn tiny() -> StudentConfig {
        StudentConfig {
            audio: AudioConfig {
                dim: 8,
                ..AudioConfig::default()
            },
            beam: BeamSpec {
                n_points: 4,
                n_freqs: 4,
                anchor: None,
            },
            depth: 6,
            width: 32,
            segments: 4,
            attention: true,
            retired_opacity: (),
            retired_anchor_beams: (),
        }
    }

    /// Residual blocks between the input and output layers.
    pub fn n_blocks(&self) -> usize {
        self.depth.saturating_sub(2) / 2
    }

    /// Width of the network's input: the encoded beam and the audio code.
    pub fn input_dim(&self) -> usize {
        self.beam.encoded_len() + self.audio.dim
    }

    /// Width of the network's output: `3 M` segment colours, then the opacity's logit.
    pub fn output_dim(&self) -> usize {
        3 * self.segments + 1
    }

    /// Multiply-adds per ray of the network.
    pub fn macs_per_ray(&self) -> usize {
        let w = self.width;
        self.input_dim() * w + self.n_blocks() * 2 * w * w + w * self.output_dim()
    }

    /// Checks the shape (at least one block, even depth, sizes in range); the error names
    /// the key under `model`.
    pub fn check(&self) -> Result<()> {
        if self.depth < 4 || !self.depth.is_multiple_of(2) || self.depth > 512 {
            return Err(Error::Argument(format!(
                "`model.depth` must be even and in [4, 512] (1 + 2 x blocks + 1), got {}",
                self.depth
            )));
        }
        in_range("model.width", self.width, 1, MAX_WIDTH)?;
        in_range("model.segments", self.segments, 1, 64)?;
        in_range("model.beam.n_points", self.beam.n_points, 2, 256)?;
        in_range("model.beam.n_freqs", self.beam.n_freqs, 0, 16)?;
        if let Some(a) = &self.beam.anchor {
            let within = |v: &f32| v.is_finite() && v.abs() <= 1e6;
            if !(a.centre.iter().all(within) && within(&a.distance)) {
                return Err(Error::Argument(format!(
                    "`model.beam.anchor` must hold finite values within 1e6, got centre {:?}, \
                     distance {}",
                    a.centre, a.distance
                )));
            }
        }
        if self.audio.ahead.is_some() && self.attention {
            return Err(Error::Argument(
                "`model.audio.ahead` needs `model.attention` off: attention reads the \
                 neighbouring frames' windows, which lie further ahead"
                    .into(),
            ));
        }
        self.audio.check("model.audio")
    }
}
