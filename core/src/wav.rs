//! WAV files in and out, and resampling: any WAV ([`read_wav`]: mono or stereo, 8 to 32-bit
//! integer or 32-bit float, any rate) to mono samples, 16-bit WAV out, and a windowed-sinc
//! resampler ([`resample`]).

use std::f64::consts::PI;
use std::io::Cursor;
use std::path::Path;

use crate::error::{Error, Result};
use crate::files::write_atomic;

/// Mono audio samples in [-1, 1] at `sample_rate` Hz.
#[derive(Debug, Clone, PartialEq)]
pub struct Waveform {
    pub sample_rate: u32,
    pub samples: Vec<f32>,
}

impl Waveform {
    /// Length in seconds.
    pub fn seconds(&self) -> f64 {
        self.samples.len() as f64 / self.sample_rate.max(1) as f64
    }

    /// The first `n` samples (all of them when there are fewer).
    pub fn truncated(&self, n: usize) -> Waveform {
        Waveform {
            sample_rate: self.sample_rate,
            samples: self.samples[..n.min(self.samples.len())].to_vec(),
        }
    }

    /// The waveform as 16-bit PCM would store it: every sample rounded to a multiple of
    /// 1/32768 and clamped to the 16-bit range, so that features computed from it equal
    /// those computed from the written file.
    pub fn quantized_16bit(&self) -> Waveform {
        Waveform {
            sample_rate: self.sample_rate,
            samples: self
                .samples
                .iter()
                .map(|&s| to_i16(s) as f32 / 32768.0)
                .collect(),
        }
    }
}

fn to_i16(s: f32) -> i16 {
    if s.is_nan() {
        0
    } else {
        (s * 32768.0).round().clamp(-32768.0, 32767.0) as i16
    }
}

/// Reads a WAV file: PCM integer (8, 16, 24 or 32 bit) or 32-bit float, any number of
/// channels (averaged to mono), any sample rate. Every problem is one error naming the file.
pub fn read_wav(path: &Path) -> Result<Waveform> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode_wav(&bytes).map_err(|problem| Error::invalid(path, problem))
}

/// Decodes WAV bytes (see [`read_wav`]); the error is the problem without the file name.
pub fn decode_wav(bytes: &[u8]) -> std::result::Result<Waveform, String> {
    if bytes.is_empty() {
        return Err("empty file, not a WAV file".into());
    }
    let reader = hound::WavReader::new(Cursor::new(bytes))
        .map_err(|e| format!("not a readable WAV file: {e}"))?;
    let spec = reader.spec();
    if spec.channels == 0 {
        return Err("WAV header declares 0 channels".into());
    }
    if !(1000..=768_000).contains(&spec.sample_rate) {
        return Err(format!(
            "WAV sample rate {} Hz is outside 1000..=768000",
            spec.sample_rate
        ));
    }
    let channels = spec.channels as usize;
    let interleaved: Vec<f32> = match spec.sample_format {
        hound::SampleFormat::Int => {
            if !(1..=32).contains(&spec.bits_per_sample) {
                return Err(format!(
                    "unsupported sample width {} bits",
                    spec.bits_per_sample
                ));
            }
            let scale = 1.0 / (1u64 << (spec.bits_per_sample - 1)) as f64;
            reader
                .into_samples::<i32>()
                .map(|s| s.map(|v| (v as f64 * scale) as f32))
                .collect::<std::result::Result<_, _>>()
        }
        hound::SampleFormat::Float => reader
            .into_samples::<f32>()
            .collect::<std::result::Result<_, _>>(),
    }
    .map_err(|e| format!("truncated or unreadable sample data: {e}"))?;
    if let Some(i) = interleaved.iter().position(|v| !v.is_finite()) {
        return Err(format!("sample {} is not finite", i / channels));
    }
    if !interleaved.len().is_multiple_of(channels) {
        return Err("sample data ends inside a frame (truncated)".into());
    }
    let samples: Vec<f32> = interleaved
        .chunks_exact(channels)
        .map(|c| c.iter().sum::<f32>() / channels as f32)
        .collect();
    if samples.is_empty() {
        return Err("holds no samples".into());
    }
    Ok(Waveform {
        sample_rate: spec.sample_rate,
        samples,
    })
}

/// Writes a mono 16-bit PCM WAV atomically.
pub fn write_wav(path: &Path, wave: &Waveform) -> Result<()> {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: wave.sample_rate,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let fail = |e: hound::Error| Error::invalid(path, format!("cannot encode WAV: {e}"));
    let mut buf = Vec::new();
    {
        let mut writer = hound::WavWriter::new(Cursor::new(&mut buf), spec).map_err(fail)?;
        for &s in &wave.samples {
            writer.write_sample(to_i16(s)).map_err(fail)?;
        }
        writer.finalize().map_err(fail)?;
    }
    write_atomic(path, &buf)
}

/// Zero crossings of the sinc kernel on each side of a resampled point.
const SINC_ZEROS: f64 = 16.0;

/// Resamples to `rate` Hz with a Hann-windowed sinc low-pass at 0.95 of the lower Nyquist
/// frequency. The output has `round(n * rate / input_rate)` samples; the input is returned
/// unchanged when the rates agree. Samples outside the input count as zero.
pub fn resample(wave: &Waveform, rate: u32) -> Waveform {
    if wave.sample_rate == rate || wave.samples.is_empty() {
        return Waveform {
            sample_rate: rate,
            samples: wave.samples.clone(),
        };
    }
    let sinc = SincResampler::new(wave.sample_rate, rate);
    let samples = (0..sinc.n_out(wave.samples.len()))
        .map(|n| sinc.sample(&wave.samples, n))
        .collect();
    Waveform {
        sample_rate: rate,
        samples,
    }
}

/// The windowed-sinc resampler of [`resample`], one output sample at a time, so that a
/// stream can compute each output sample once every input sample it reads has arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SincResampler {
    /// Output rate / input rate.
    ratio: f64,
    /// Low-pass cutoff in cycles per input sample.
    cutoff: f64,
    /// Kernel half width in input samples.
    half: f64,
}

impl SincResampler {
    pub(crate) fn new(from: u32, to: u32) -> SincResampler {
        let ratio = to as f64 / from as f64;
        let cutoff = 0.95 * 0.5 * ratio.min(1.0);
        SincResampler {
            ratio,
            cutoff,
            half: SINC_ZEROS / (2.0 * cutoff),
        }
    }

    /// Output samples made from `n_in` input samples.
    pub(crate) fn n_out(&self, n_in: usize) -> usize {
        (n_in as f64 * self.ratio).round() as usize
    }

    /// Input samples that output sample `n` reads, counted from the start: it is final once
    /// this many have arrived.
    pub(crate) fn input_needed(&self, n: usize) -> usize {
        (n as f64 / self.ratio + self.half).floor() as usize + 1
    }

    /// Output sample `n` of `input` (non-empty; samples past its end count as zero).
    pub(crate) fn sample(&self, input: &[f32], n: usize) -> f32 {
        let (cutoff, half) = (self.cutoff, self.half);
        let x = n as f64 / self.ratio;
        let lo = ((x - half).ceil().max(0.0)) as usize;
        let hi = ((x + half).floor() as usize).min(input.len() - 1);
        let mut acc = 0.0f64;
        for (k, &s) in input.iter().enumerate().take(hi + 1).skip(lo) {
            let u = x - k as f64;
            let arg = 2.0 * cutoff * u;
            let sinc = if arg.abs() < 1e-12 {
                1.0
            } else {
                (PI * arg).sin() / (PI * arg)
            };
            let window = 0.5 + 0.5 * (PI * u / half).cos();
            acc += s as f64 * 2.0 * cutoff * sinc * window;
        }
        acc as f32
    }
}
