//! Audio features from a stream: samples arrive in pieces of any size, and each video
//! frame's window of log-mel features is made as soon as every sample it depends on has
//! arrived. The windows are bit-identical to [`audio_windows`](crate::audio::audio_windows)
//! on the whole recording: a resampled sample is computed once every input sample its sinc
//! kernel reads is in, a feature frame once every resampled sample of its Hann window is
//! in, and the track's end (where the batch path pads with zeros and clamps) is handled
//! only when the stream says it has ended.
//!
//! [`WavStreamDecoder`] turns the bytes of a WAV stream (a header, then PCM to the end of the
//! stream, as `arecord` or `ffmpeg -f wav -` write to a pipe) into mono samples the same way
//! [`read_wav`](crate::audio::read_wav) decodes a file.

use crate::audio::{
    FeatureConfig, MelFrontEnd, SincResampler, n_feature_frames, n_video_frames, push_window,
    window_span,
};
use crate::error::{Error, Result};
pub use crate::wav_stream::{WavStreamDecoder, WavStreamFormat};

/// Video-frame feature windows made incrementally from a stream of samples.
#[derive(Debug)]
pub struct FeatureStream {
    cfg: FeatureConfig,
    fps: f32,
    input_rate: u32,
    /// `None` when the input is already at the feature rate.
    resampler: Option<SincResampler>,
    /// Every input sample so far (mono, at `input_rate`).
    input: Vec<f32>,
    /// The resampled samples that are final (unused without a resampler).
    resampled: Vec<f32>,
    front: MelFrontEnd,
    /// Final feature frames, `[n_feat, n_mels]`.
    feats: Vec<f32>,
    n_feat: usize,
    /// Final video-frame windows, `[n_windows, window, n_mels]`.
    windows: Vec<f32>,
    n_windows: usize,
    /// Rows of each window, from the first, that must be final before it is made.
    rows_read: usize,
    ended: bool,
}

impl FeatureStream {
    /// A stream of mono samples at `input_rate` Hz for video at `fps`.
    pub fn new(input_rate: u32, fps: f32, cfg: &FeatureConfig) -> Result<FeatureStream> {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(Error::Argument(format!("fps must be positive, got {fps}")));
        }
        if !(1000..=768_000).contains(&input_rate) {
            return Err(Error::Argument(format!(
                "audio sample rate {input_rate} Hz is outside 1000..=768000"
            )));
        }
        Ok(FeatureStream {
            front: MelFrontEnd::new(cfg)?,
            cfg: cfg.clone(),
            fps,
            input_rate,
            resampler: (input_rate != cfg.sample_rate)
                .then(|| SincResampler::new(input_rate, cfg.sample_rate)),
            input: Vec::new(),
            resampled: Vec::new(),
            feats: Vec::new(),
            n_feat: 0,
            windows: Vec::new(),
            n_windows: 0,
            rows_read: cfg.window,
            ended: false,
        })
    }

    /// The stream for a model that reads only the first `rows` rows of each window (a
    /// short-lookahead encoder, which zeroes the rest): a window is made once those rows
    /// are final, its later rows repeating the last feature frame so far, as at a track's
    /// end. The rows read are the file path's, bit for bit.
    pub fn reading(mut self, rows: usize) -> FeatureStream {
        self.rows_read = rows.clamp(1, self.cfg.window);
        self
    }

    /// One past the last feature frame of video frame `f`'s window that must be final
    /// before the window is made.
    fn read_end(&self, f: usize) -> isize {
        let (first, end) = window_span(f, self.fps, &self.cfg);
        (first + self.rows_read as isize).min(end)
    }

    /// Adds samples and makes every window that became final.
    pub fn push(&mut self, samples: &[f32]) -> Result<()> {
        if self.ended {
            return Err(Error::Argument(
                "audio stream: samples pushed after its end".into(),
            ));
        }
        if let Some(i) = samples.iter().position(|v| !v.is_finite()) {
            return Err(Error::Argument(format!(
                "audio stream: sample {} is not finite",
                self.input.len() + i
            )));
        }
        self.input.extend_from_slice(samples);
        self.advance()
    }

    /// Marks the end of the stream: the last windows are made as the batch path makes
    /// them (zeros past the end, indices clamped to the last feature frame).
    pub fn finish(&mut self) -> Result<()> {
        self.ended = true;
        self.advance()
    }

    /// Whether [`FeatureStream::finish`] was called.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// Input samples received.
    pub fn n_samples(&self) -> usize {
        self.input.len()
    }

    /// The input's sample rate.
    pub fn input_rate(&self) -> u32 {
        self.input_rate
    }

    /// Video frames whose windows are final.
    pub fn n_ready(&self) -> usize {
        self.n_windows
    }

    /// The window of video frame `f < n_ready()`, `[window, n_mels]` flat.
    pub fn window(&self, f: usize) -> &[f32] {
        let n = self.cfg.window * self.cfg.n_mels;
        &self.windows[f * n..(f + 1) * n]
    }

    /// The signal the features read: the input, or its final resampled prefix.
    fn signal(&self) -> &[f32] {
        if self.resampler.is_some() {
            &self.resampled
        } else {
            &self.input
        }
    }

    fn advance(&mut self) -> Result<()> {
        // 1. Resampled samples whose kernel lies inside the received input.
        if let Some(sinc) = self.resampler
            && !self.input.is_empty()
        {
            let n_in = self.input.len();
            let end = if self.ended {
                sinc.n_out(n_in)
            } else {
                // input_needed grows with n: stop at the first sample not yet final.
                let mut n = self.resampled.len();
                while sinc.input_needed(n) <= n_in {
                    n += 1;
                }
                n
            };
            for n in self.resampled.len()..end {
                let v = sinc.sample(&self.input, n);
                self.resampled.push(v);
            }
        }
        // 2. Feature frames whose Hann window lies inside the final signal.
        let n_signal = self.signal().len();
        let feat_end = if self.ended {
            n_feature_frames(n_signal, &self.cfg)
        } else {
            let mut k = self.n_feat;
            while self.front.first_sample(k) + self.cfg.win as isize <= n_signal as isize {
                k += 1;
            }
            k
        };
        for k in self.n_feat..feat_end {
            let x = if self.resampler.is_some() {
                &self.resampled
            } else {
                &self.input
            };
            self.front.push_frame(x, k, &mut self.feats)?;
        }
        self.n_feat = self.n_feat.max(feat_end);
        // 3. Video frames inside the received audio whose feature frames are all final.
        let n_video = n_video_frames(self.input.len(), self.input_rate, self.fps);
        while self.n_windows < n_video {
            let end = self.read_end(self.n_windows);
            if !self.ended && end > self.n_feat as isize {
                break;
            }
            if self.n_feat == 0 {
                break;
            }
            push_window(
                &self.feats,
                self.n_feat,
                self.n_windows,
                self.fps,
                &self.cfg,
                &mut self.windows,
            );
            self.n_windows += 1;
        }
        Ok(())
    }

    /// Input samples that must have arrived before video frame `f`'s window is final
    /// (before the stream's end): the algorithmic part of a stream's latency.
    pub fn samples_needed(&self, f: usize) -> usize {
        let last_feat = (self.read_end(f) - 1).max(0) as usize;
        let signal_end =
            (self.front.first_sample(last_feat) + self.cfg.win as isize).max(0) as usize;
        let input_end = match self.resampler {
            Some(sinc) if signal_end > 0 => sinc.input_needed(signal_end - 1),
            _ => signal_end,
        };
        // The frame's own interval must be inside the audio too.
        let frame_end =
            ((f + 1) as f64 * self.input_rate as f64 / self.fps as f64 - 1e-6).ceil() as usize;
        input_end.max(frame_end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::audio::{Waveform, audio_windows};

    fn tone(rate: u32, seconds: f64) -> Vec<f32> {
        let n = (rate as f64 * seconds) as usize;
        (0..n)
            .map(|i| {
                let t = i as f64 / rate as f64;
                (0.4 * (2.0 * std::f64::consts::PI * 220.0 * t).sin() * (3.0 * t).sin()
                    + 0.1 * (2.0 * std::f64::consts::PI * 1500.0 * t).sin()) as f32
            })
            .collect()
    }

    fn streamed(samples: &[f32], rate: u32, pieces: &[usize]) -> (FeatureStream, Vec<usize>) {
        let cfg = FeatureConfig::default();
        let mut s = FeatureStream::new(rate, 25.0, &cfg).unwrap();
        let mut ready = Vec::new();
        let mut at = 0;
        let mut i = 0;
        while at < samples.len() {
            let n = pieces[i % pieces.len()].min(samples.len() - at);
            s.push(&samples[at..at + n]).unwrap();
            ready.push(s.n_ready());
            at += n;
            i += 1;
        }
        s.finish().unwrap();
        (s, ready)
    }

    #[test]
    fn stream_windows_equal_the_batch_windows_bit_for_bit() {
        for rate in [16_000u32, 44_100, 8_000] {
            let samples = tone(rate, 1.37);
            let cfg = FeatureConfig::default();
            let batch = audio_windows(
                &Waveform {
                    sample_rate: rate,
                    samples: samples.clone(),
                },
                25.0,
                &cfg,
            )
            .unwrap();
            let (s, ready) = streamed(&samples, rate, &[1, 333, 7, 4096, 160]);
            assert_eq!(s.n_ready(), batch.n_frames, "rate {rate}");
            for f in 0..batch.n_frames {
                assert_eq!(s.window(f), batch.frame(f), "rate {rate}, frame {f}");
            }
            // Windows became ready while the audio was still arriving, in order.
            assert!(ready.windows(2).all(|w| w[0] <= w[1]));
            let before_end = *ready.last().unwrap();
            assert!(before_end > 0 && before_end < batch.n_frames, "rate {rate}");
        }
    }

    #[test]
    fn a_window_is_ready_once_its_samples_have_arrived() {
        let rate = 16_000;
        let samples = tone(rate, 1.0);
        let cfg = FeatureConfig::default();
        let mut s = FeatureStream::new(rate, 25.0, &cfg).unwrap();
        let need = s.samples_needed(5);
        // 25 fps, 50 Hz features, 16-frame windows: frame 5 reaches feature frame 17, whose
        // Hann window ends at sample 17 * 320 + 200.
        assert_eq!(need, 17 * 320 + 200);
        s.push(&samples[..need - 1]).unwrap();
        assert_eq!(s.n_ready(), 5);
        s.push(&samples[need - 1..need]).unwrap();
        assert_eq!(s.n_ready(), 6);
    }

    fn wav_bytes(
        channels: u16,
        bits: u16,
        float: bool,
        rate: u32,
        data: &[u8],
        size: u32,
    ) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(b"RIFF");
        b.extend_from_slice(&u32::MAX.to_le_bytes());
        b.extend_from_slice(b"WAVE");
        b.extend_from_slice(b"LIST");
        b.extend_from_slice(&3u32.to_le_bytes());
        b.extend_from_slice(&[1, 2, 3, 0]);
        b.extend_from_slice(b"fmt ");
        b.extend_from_slice(&16u32.to_le_bytes());
        b.extend_from_slice(&(if float { 3u16 } else { 1 }).to_le_bytes());
        b.extend_from_slice(&channels.to_le_bytes());
        b.extend_from_slice(&rate.to_le_bytes());
        let block = channels * bits / 8;
        b.extend_from_slice(&(rate * block as u32).to_le_bytes());
        b.extend_from_slice(&block.to_le_bytes());
        b.extend_from_slice(&bits.to_le_bytes());
        b.extend_from_slice(b"data");
        b.extend_from_slice(&size.to_le_bytes());
        b.extend_from_slice(data);
        b
    }

    fn decode_in_pieces(bytes: &[u8], piece: usize) -> std::result::Result<Vec<f32>, String> {
        let mut d = WavStreamDecoder::new();
        let mut out = Vec::new();
        for c in bytes.chunks(piece) {
            out.extend(d.push(c)?);
        }
        d.finish()?;
        Ok(out)
    }

    #[test]
    fn wav_stream_decodes_like_read_wav() {
        let samples: Vec<i16> = vec![0, 16384, -32768, 32767, -1, 100];
        let data: Vec<u8> = samples.iter().flat_map(|v| v.to_le_bytes()).collect();
        // Stereo 16-bit, streaming size: three frames averaged.
        let bytes = wav_bytes(2, 16, false, 16_000, &data, u32::MAX);
        let expect: Vec<f32> = samples
            .chunks(2)
            .map(|c| c.iter().map(|&v| (v as f64 / 32768.0) as f32).sum::<f32>() / 2.0)
            .collect();
        for piece in [1, 3, 5, 64] {
            assert_eq!(decode_in_pieces(&bytes, piece).unwrap(), expect);
        }
        // A declared size is honoured: a trailing chunk is not taken for samples.
        let mut sized = wav_bytes(1, 16, false, 16_000, &data[..4], 4);
        sized.extend_from_slice(b"LIST\x04\x00\x00\x00abcd");
        assert_eq!(decode_in_pieces(&sized, 7).unwrap(), vec![0.0, 0.5]);
        // 32-bit float and 24-bit integers.
        let f: Vec<u8> = [0.25f32, -0.5]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        assert_eq!(
            decode_in_pieces(&wav_bytes(1, 32, true, 8000, &f, 0), 2).unwrap(),
            vec![0.25, -0.5]
        );
        let i24 = [0x00, 0x00, 0xc0]; // -0.5 * 2^23
        assert_eq!(
            decode_in_pieces(&wav_bytes(1, 24, false, 8000, &i24, 3), 1).unwrap(),
            vec![-0.5]
        );
    }

    #[test]
    fn bad_wav_streams_are_errors() {
        assert!(decode_in_pieces(b"", 4).unwrap_err().contains("empty"));
        assert!(
            decode_in_pieces(b"OggS\0\0\0\0\0\0\0\0\0\0", 4)
                .unwrap_err()
                .contains("RIFF")
        );
        assert!(
            decode_in_pieces(&wav_bytes(1, 16, false, 16_000, &[], 0)[..20], 4)
                .unwrap_err()
                .contains("header")
        );
        let cut = wav_bytes(1, 16, false, 16_000, &[1, 2, 3], u32::MAX);
        assert!(decode_in_pieces(&cut, 4).unwrap_err().contains("truncated"));
        let nan: Vec<u8> = f32::NAN.to_le_bytes().to_vec();
        assert!(
            decode_in_pieces(&wav_bytes(1, 32, true, 16_000, &nan, 0), 4)
                .unwrap_err()
                .contains("finite")
        );
        assert!(
            decode_in_pieces(&wav_bytes(1, 12, false, 16_000, &[0, 0], 0), 4)
                .unwrap_err()
                .contains("12 bits")
        );
    }
}
