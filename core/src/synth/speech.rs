//! Speech-like audio (syllables with pitch and formants) and the mouth track it drives.
//!
//! [`synthesize_speech`] makes phrases of syllables separated by pauses: each syllable is an
//! optional consonant (a noise burst) and a vowel, a band-limited sawtooth at a gliding pitch
//! through three cascaded formant resonators. [`mouth_track`] reads any waveform, generated or
//! recorded, and gives per video frame the loudness that opens the mouth and the spectral
//! balance that widens it, so the synthetic face follows whatever audio drives it.

use std::f32::consts::PI;

use rand::Rng;
use realfft::RealFftPlanner;
use serde::{Deserialize, Serialize};

use crate::audio::Waveform;

/// A speaker's voice: what the seed varies between synthetic heads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Voice {
    /// Mean pitch in Hz.
    pub pitch: f32,
    /// Formant frequencies scale (vocal tract length).
    pub formant_scale: f32,
    /// Syllables per second while speaking.
    pub syllable_rate: f32,
}

impl Voice {
    /// A random voice: pitch 90 to 230 Hz, formants scaled 0.9 to 1.15, 3.5 to 5.5
    /// syllables per second.
    pub fn random(rng: &mut impl Rng) -> Voice {
        Voice {
            pitch: rng.random_range(90.0..230.0),
            formant_scale: rng.random_range(0.9..1.15),
            syllable_rate: rng.random_range(3.5..5.5),
        }
    }
}

/// Vowel formants (F1, F2, F3) in Hz of an adult voice: /a/ /e/ /i/ /o/ /u/.
const VOWELS: [[f32; 3]; 5] = [
    [730.0, 1090.0, 2440.0],
    [530.0, 1840.0, 2480.0],
    [270.0, 2290.0, 3010.0],
    [570.0, 840.0, 2410.0],
    [300.0, 870.0, 2240.0],
];
/// Formant bandwidths in Hz.
const BANDWIDTHS: [f32; 3] = [80.0, 100.0, 150.0];

/// One planned sound: a stretch of samples with a vowel and a loudness.
struct Syllable {
    start: usize,
    consonant: usize,
    len: usize,
    vowel: usize,
    gain: f32,
    pitch: f32,
}

/// Speech-like audio of `n_samples` samples at `sample_rate`: phrases of 3 to 8 syllables
/// (consonant burst, then a voiced vowel with attack and release) with pauses of 0.25 to
/// 0.7 s between phrases, pitch falling over each phrase, peak normalised to 0.8.
/// Deterministic for the rng state.
pub fn synthesize_speech(
    rng: &mut impl Rng,
    voice: &Voice,
    n_samples: usize,
    sample_rate: u32,
) -> Waveform {
    let sr = sample_rate as f32;
    let secs = |s: f32| (s * sr) as usize;
    let plan = plan_syllables(rng, voice, n_samples, sr);
    let mut out = vec![0.0f32; n_samples];
    let mut phase = 0.0f32;
    for syl in &plan {
        let formants = VOWELS[syl.vowel].map(|f| f * voice.formant_scale);
        let mut resonators = formants.map(|f| Resonator::new(f, BANDWIDTHS[0].max(f * 0.06), sr));
        let voiced = syl.len.saturating_sub(syl.consonant);
        let attack = secs(0.03).min(voiced / 2).max(1);
        let release = secs(0.06).min(voiced / 2).max(1);
        for n in 0..syl.len {
            let idx = syl.start + n;
            if idx >= n_samples {
                break;
            }
            let noise = rng.random_range(-1.0f32..1.0);
            if n < syl.consonant {
                let t = n as f32 / syl.consonant as f32;
                out[idx] += 0.18 * syl.gain * noise * (PI * t).sin();
                continue;
            }
            let v = n - syl.consonant;
            let envelope = if v < attack {
                0.5 - 0.5 * (PI * v as f32 / attack as f32).cos()
            } else if v + release > voiced {
                0.5 - 0.5 * (PI * (voiced - v) as f32 / release as f32).cos()
            } else {
                1.0
            };
            let glide = 1.0 - 0.08 * v as f32 / voiced.max(1) as f32;
            let f0 = syl.pitch * glide;
            let dt = f0 / sr;
            phase += dt;
            if phase >= 1.0 {
                phase -= 1.0;
            }
            let source = sawtooth(phase, dt) + 0.05 * noise;
            let voiced_sample = resonators.iter_mut().fold(source, |x, r| r.step(x));
            out[idx] += syl.gain * envelope * voiced_sample;
        }
    }
    let peak = out.iter().fold(0.0f32, |m, s| m.max(s.abs()));
    if peak > 0.0 {
        out.iter_mut().for_each(|s| *s *= 0.8 / peak);
    }
    Waveform {
        sample_rate,
        samples: out,
    }
}

/// The syllables of [`synthesize_speech`] over `n_samples` samples at `sr` Hz: phrases of 3
/// to 8 syllables with pauses between them, pitch falling over each phrase.
fn plan_syllables(rng: &mut impl Rng, voice: &Voice, n_samples: usize, sr: f32) -> Vec<Syllable> {
    let secs = |s: f32| (s * sr) as usize;
    let mut plan = Vec::new();
    let mut at = secs(rng.random_range(0.15..0.4));
    while at < n_samples {
        let n_syllables = rng.random_range(3..=8);
        for s in 0..n_syllables {
            let mean = 1.0 / voice.syllable_rate;
            let len = secs(mean * rng.random_range(0.7..1.4));
            let consonant = if rng.random_bool(0.6) {
                secs(rng.random_range(0.03..0.08))
            } else {
                0
            };
            let declination = 1.12 - 0.22 * s as f32 / n_syllables as f32;
            plan.push(Syllable {
                start: at,
                consonant,
                len,
                vowel: rng.random_range(0..VOWELS.len()),
                gain: rng.random_range(0.45..1.0),
                pitch: voice.pitch * declination * rng.random_range(0.93..1.07),
            });
            at += len + secs(rng.random_range(0.0..0.03));
        }
        at += secs(rng.random_range(0.25..0.7));
    }
    plan
}

/// A band-limited sawtooth in [-1, 1] (PolyBLEP) at phase `t` in [0, 1), step `dt`.
fn sawtooth(t: f32, dt: f32) -> f32 {
    let mut v = 2.0 * t - 1.0;
    if t < dt {
        let x = t / dt;
        v -= x + x - x * x - 1.0;
    } else if t > 1.0 - dt {
        let x = (t - 1.0) / dt;
        v -= x * x + x + x + 1.0;
    }
    v
}

/// A two-pole resonator with unit gain at DC (Klatt's formant filter).
struct Resonator {
    a: f32,
    b: f32,
    c: f32,
    y1: f32,
    y2: f32,
}

impl Resonator {
    fn new(freq: f32, bandwidth: f32, sr: f32) -> Resonator {
        let r = (-PI * bandwidth / sr).exp();
        let c = -r * r;
        let b = 2.0 * r * (2.0 * PI * freq / sr).cos();
        Resonator {
            a: 1.0 - b - c,
            b,
            c,
            y1: 0.0,
            y2: 0.0,
        }
    }

    fn step(&mut self, x: f32) -> f32 {
        let y = self.a * x + self.b * self.y1 + self.c * self.y2;
        self.y2 = self.y1;
        self.y1 = y;
        y
    }
}

/// The mouth of one video frame, read off the audio.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MouthFrame {
    /// RMS of the frame's samples.
    pub loudness: f32,
    /// Mouth opening, 0 closed .. 1 open: loudness above a noise floor, relative to the
    /// clip's loud frames.
    pub mouth_open: f32,
    /// Mouth width, 0 narrow .. 1 wide: the spectral balance (front vowels are bright and
    /// wide, rounded ones dark and narrow), neutral 0.5 when silent.
    pub mouth_width: f32,
}

/// Per video frame `i` (the samples of `[i / fps, (i + 1) / fps)`), the loudness and the
/// mouth it drives. The opening is `(rms - floor) / (0.85 loud - floor)` clamped to [0, 1],
/// with `loud` the clip's 95th percentile RMS and `floor = 0.06 loud`; the width maps the
/// energy ratio of 1.5-3.5 kHz to 0.1-1 kHz from [-45, -20] dB onto [0, 1], blended to
/// neutral as the mouth closes.
pub fn mouth_track(wave: &Waveform, fps: f32, n_frames: usize) -> Vec<MouthFrame> {
    let per = wave.sample_rate as f64 / fps as f64;
    let chunk = |i: usize| {
        let a = ((i as f64 * per).round() as usize).min(wave.samples.len());
        let b = (((i + 1) as f64 * per).round() as usize).min(wave.samples.len());
        &wave.samples[a..b]
    };
    let rms: Vec<f32> = (0..n_frames)
        .map(|i| {
            let c = chunk(i);
            let e = c.iter().map(|&s| s as f64 * s as f64).sum::<f64>() / c.len().max(1) as f64;
            e.sqrt() as f32
        })
        .collect();
    let mut sorted = rms.clone();
    sorted.sort_by(f32::total_cmp);
    let loud = sorted
        .get(((sorted.len() as f32 * 0.95) as usize).min(sorted.len().saturating_sub(1)))
        .copied()
        .filter(|&v| v > 1e-6)
        .unwrap_or(1.0);
    let floor = 0.06 * loud;

    let n_fft = (per.ceil() as usize).next_power_of_two().max(64);
    let fft = RealFftPlanner::<f32>::new().plan_fft_forward(n_fft);
    let mut input = fft.make_input_vec();
    let mut spectrum = fft.make_output_vec();
    let bin_hz = wave.sample_rate as f32 / n_fft as f32;
    (0..n_frames)
        .map(|i| {
            let mouth_open = ((rms[i] - floor) / (0.85 * loud - floor)).clamp(0.0, 1.0);
            let c = chunk(i);
            input.iter_mut().for_each(|v| *v = 0.0);
            for (k, &s) in c.iter().enumerate().take(n_fft) {
                let w = 0.5 - 0.5 * (2.0 * PI * k as f32 / c.len() as f32).cos();
                input[k] = s * w;
            }
            // Front vowels (/i/, /e/) carry a high second formant: a bright spectrum.
            let brightness_db = match fft.process(&mut input, &mut spectrum) {
                Ok(()) => {
                    let (mut high, mut low) = (1e-20f32, 1e-20f32);
                    for (k, z) in spectrum.iter().enumerate() {
                        let f = k as f32 * bin_hz;
                        if (100.0..1000.0).contains(&f) {
                            low += z.norm_sqr();
                        } else if (1500.0..3500.0).contains(&f) {
                            high += z.norm_sqr();
                        }
                    }
                    10.0 * (high / low).log10()
                }
                Err(_) => -32.5,
            };
            let bright = ((brightness_db + 45.0) / 25.0).clamp(0.0, 1.0);
            let voiced = (2.0 * mouth_open).min(1.0);
            MouthFrame {
                loudness: rms[i],
                mouth_open,
                mouth_width: 0.5 + (bright - 0.5) * voiced,
            }
        })
        .collect()
}

/// Eyelid closure per video frame: blinks every 2 to 5 s, each closing and opening over
/// 0.2 to 0.3 s as a half sine.
pub fn blink_track(rng: &mut impl Rng, fps: f32, n_frames: usize) -> Vec<f32> {
    let mut blink = vec![0.0f32; n_frames];
    let mut t = rng.random_range(0.5..2.5f32);
    let end = n_frames as f32 / fps;
    while t < end {
        let dur = rng.random_range(0.2..0.3f32);
        for (i, b) in blink.iter_mut().enumerate() {
            let u = (i as f32 / fps - t) / dur;
            if (0.0..1.0).contains(&u) {
                *b = b.max((PI * u).sin());
            }
        }
        t += dur + rng.random_range(2.0..5.0f32);
    }
    blink
}
