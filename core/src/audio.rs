//! Audio features: WAV in, AD-NeRF-shaped windows of log-mel frames out, one window of 16
//! feature frames (50 Hz) per 25 fps video frame. The same function serves training and
//! rendering.

/// Mono audio samples in [-1, 1] at `sample_rate` Hz.
#[derive(Debug, Clone, PartialEq)]
pub struct Waveform {
    pub sample_rate: u32,
    pub samples: Vec<f32>,
}

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
