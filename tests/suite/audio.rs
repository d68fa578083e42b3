//! Audio features: WAV decoding of every common layout, resampling, log-mel windows with the
//! frame counts AD-NeRF expects, a WAV that drives the synthetic mouth, and malformed files.

use std::f64::consts::PI;
use std::path::Path;

use nldf_core::audio::{
    FeatureConfig, Waveform, audio_windows, log_mel, n_video_frames, read_wav, resample,
};
use nldf_core::synth::{SceneFile, SynthConfig, generate};
use nldf_tests::assert_one_line_naming;

/// Writes `channels` copies of `signal(t)` (t in seconds) as a WAV of the given layout.
fn write_wav(
    path: &Path,
    rate: u32,
    channels: u16,
    format: hound::SampleFormat,
    bits: u16,
    seconds: f64,
    signal: impl Fn(f64, u16) -> f64,
) {
    let spec = hound::WavSpec {
        channels,
        sample_rate: rate,
        bits_per_sample: bits,
        sample_format: format,
    };
    let mut w = hound::WavWriter::create(path, spec).unwrap();
    let n = (seconds * rate as f64).round() as usize;
    for i in 0..n {
        for c in 0..channels {
            let v = signal(i as f64 / rate as f64, c);
            match format {
                hound::SampleFormat::Float => w.write_sample(v as f32).unwrap(),
                hound::SampleFormat::Int => {
                    let max = (1i64 << (bits - 1)) as f64;
                    let s = (v * max).round().clamp(-max, max - 1.0) as i32;
                    w.write_sample(s).unwrap()
                }
            }
        }
    }
    w.finalize().unwrap();
}

fn tone(freq: f64, amp: f64) -> impl Fn(f64, u16) -> f64 {
    move |t, _| amp * (2.0 * PI * freq * t).sin()
}

#[test]
fn frame_counts_for_known_durations_and_rates() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = FeatureConfig::default();
    // (rate, channels, format, bits, seconds, expected video frames at 25 fps)
    let cases = [
        (16_000, 1, hound::SampleFormat::Int, 16, 2.0, 50),
        (44_100, 2, hound::SampleFormat::Int, 16, 1.0, 25),
        (48_000, 1, hound::SampleFormat::Float, 32, 0.52, 13),
        (22_050, 1, hound::SampleFormat::Int, 24, 3.3, 82),
        (8_000, 2, hound::SampleFormat::Int, 8, 0.039, 0),
        (11_025, 1, hound::SampleFormat::Int, 32, 1.2, 30),
    ];
    for (n, &(rate, ch, fmt, bits, secs, expected)) in cases.iter().enumerate() {
        let path = dir.path().join(format!("{n}.wav"));
        write_wav(&path, rate, ch, fmt, bits, secs, tone(300.0, 0.5));
        let wave = read_wav(&path).unwrap();
        assert_eq!(wave.sample_rate, rate);
        assert_eq!(
            wave.samples.len(),
            (secs * rate as f64).round() as usize,
            "case {n}"
        );
        assert_eq!(
            n_video_frames(wave.samples.len(), rate, 25.0),
            expected,
            "case {n}"
        );
        let windows = audio_windows(&wave, 25.0, &cfg).unwrap();
        assert_eq!(windows.n_frames, expected, "case {n}");
        assert_eq!((windows.window, windows.n_features), (16, 29));
        assert_eq!(windows.data.len(), expected * 16 * 29);
        assert!(windows.data.iter().all(|v| v.is_finite()));
        // 50 feature frames per second: 20 ms hop, one frame per started hop.
        let feats = log_mel(&wave, &cfg).unwrap();
        let n16k = (secs * 16_000.0).round() as usize;
        let got = feats.len() / 29;
        assert!(
            got.abs_diff(n16k.div_ceil(320)) <= 1,
            "case {n}: {got} feature frames"
        );
    }
}

#[test]
fn stereo_is_averaged_and_every_sample_format_decodes_to_the_same_signal() {
    let dir = tempfile::tempdir().unwrap();
    let cancel = dir.path().join("cancel.wav");
    write_wav(
        &cancel,
        16_000,
        2,
        hound::SampleFormat::Int,
        16,
        0.5,
        |t, c| if c == 0 { 0.5 } else { -0.5 } * (2.0 * PI * 440.0 * t).sin(),
    );
    let wave = read_wav(&cancel).unwrap();
    // Measured worst 0: the channels cancel exactly, and silence sits at the feature floor, -1.
    assert!(wave.samples.iter().all(|&s| s == 0.0));
    let feats = log_mel(&wave, &FeatureConfig::default()).unwrap();
    assert!(feats.iter().all(|&v| v == -1.0), "{:?}", &feats[..5]);

    // Integers within one step of their format; 32 bits within f32 rounding. Measured worst
    // about 3.9e-3, 1.4e-5, 5.9e-8, 2.6e-8 and 2.6e-8.
    let formats = [
        (hound::SampleFormat::Int, 8, 1.0 / 128.0),
        (hound::SampleFormat::Int, 16, 1.0 / 32768.0),
        (hound::SampleFormat::Int, 24, 1.0 / 8388608.0),
        (hound::SampleFormat::Int, 32, 1e-7),
        (hound::SampleFormat::Float, 32, 1e-7),
    ];
    for (fmt, bits, tol) in formats {
        let path = dir.path().join(format!("{bits}-{fmt:?}.wav"));
        write_wav(&path, 8000, 1, fmt, bits, 0.1, tone(200.0, 0.7));
        let wave = read_wav(&path).unwrap();
        let mut worst = 0f64;
        for (i, s) in wave.samples.iter().enumerate() {
            let want = 0.7 * (2.0 * PI * 200.0 * i as f64 / 8000.0).sin();
            worst = worst.max((*s as f64 - want).abs());
            assert!(
                (*s as f64 - want).abs() <= tol,
                "{bits}-bit {fmt:?} sample {i}: {s} vs {want}"
            );
        }
        println!("{bits}-bit {fmt:?}: worst error {worst:e}");
    }
}

#[test]
fn resampling_keeps_a_tone_and_removes_what_the_new_rate_cannot_hold() {
    for rate in [8_000u32, 22_050, 44_100, 48_000] {
        let n = rate as usize / 2;
        let sine = |f: f64, r: u32, i: usize| (2.0 * PI * f * i as f64 / r as f64).sin() as f32;
        let wave = Waveform {
            sample_rate: rate,
            samples: (0..n).map(|i| 0.5 * sine(440.0, rate, i)).collect(),
        };
        let out = resample(&wave, 16_000);
        assert_eq!(out.samples.len(), 8000);
        // Away from the edges the tone is reproduced closely.
        let err = out.samples[400..7600]
            .iter()
            .enumerate()
            .map(|(k, s)| (s - 0.5 * sine(440.0, 16_000, k + 400)).abs())
            .fold(0.0f32, f32::max);
        println!("{rate} Hz: max error {err:e}");
        // Measured worst about 1.8e-5.
        assert!(err < 1e-4, "{rate} Hz: max error {err}");
        if rate > 16_000 {
            // 10 kHz cannot exist at 16 kHz: it must not alias back in.
            let high = Waveform {
                sample_rate: rate,
                samples: (0..n).map(|i| 0.5 * sine(10_000.0, rate, i)).collect(),
            };
            let out = resample(&high, 16_000);
            let rms = (out.samples[400..7600].iter().map(|s| s * s).sum::<f32>() / 7200.0).sqrt();
            println!("{rate} Hz: 10 kHz leaks at RMS {rms:e}");
            // Measured worst about 1.4e-4.
            assert!(rms < 1e-3, "{rate} Hz: 10 kHz leaks at RMS {rms}");
        }
    }
}

#[test]
fn a_tone_lights_its_mel_band_and_a_click_lands_in_the_middle_of_its_window() {
    let cfg = FeatureConfig::default();
    let rate = 16_000;
    let low = Waveform {
        sample_rate: rate,
        samples: (0..rate)
            .map(|i| 0.5 * (2.0 * PI * 300.0 * i as f64 / rate as f64).sin() as f32)
            .collect(),
    };
    let high = Waveform {
        sample_rate: rate,
        samples: (0..rate)
            .map(|i| 0.5 * (2.0 * PI * 3000.0 * i as f64 / rate as f64).sin() as f32)
            .collect(),
    };
    let argmax = |w: &Waveform| {
        let f = log_mel(w, &cfg).unwrap();
        let frame = &f[25 * 29..26 * 29];
        (0..29)
            .max_by(|&a, &b| frame[a].total_cmp(&frame[b]))
            .unwrap()
    };
    let (a, b) = (argmax(&low), argmax(&high));
    assert!(
        a < 8 && b > 16,
        "300 Hz peaks in band {a}, 3 kHz in band {b}"
    );

    // A click at 1.0 s: video frame 25's window is centred on it (its 9th feature frame,
    // index 8, is centred on t = 1.0 s).
    let mut samples = vec![0.0f32; 2 * rate as usize];
    for s in &mut samples[16_000..16_040] {
        *s = 0.9;
    }
    let click = Waveform {
        sample_rate: rate,
        samples,
    };
    let w = audio_windows(&click, 25.0, &cfg).unwrap();
    let energy: Vec<f32> = w
        .frame(25)
        .chunks(29)
        .map(|row| row.iter().sum::<f32>())
        .collect();
    let loudest = (0..16)
        .max_by(|&a, &b| energy[a].total_cmp(&energy[b]))
        .unwrap();
    assert_eq!(loudest, 8, "{energy:?}");
    // Windows clamp at the edges: frame 0 repeats the first feature frame.
    let first = w.frame(0);
    assert_eq!(&first[..29], &first[29..58]);
}

#[test]
fn a_wav_file_drives_the_synthetic_mouth() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("bursts.wav");
    // 44.1 kHz stereo: a vowel-like buzz switched on and off every 0.4 s.
    write_wav(
        &wav,
        44_100,
        2,
        hound::SampleFormat::Int,
        16,
        2.0,
        |t, _| {
            let on = ((t / 0.4) as usize) % 2 == 1;
            let buzz: f64 = (1..20)
                .map(|k| (2.0 * PI * 140.0 * k as f64 * t).sin() / k as f64)
                .sum();
            if on { 0.3 * buzz } else { 0.0 }
        },
    );
    let audio = read_wav(&wav).unwrap();
    let out = dir.path().join("scene");
    let cfg = SynthConfig {
        seconds: 1.6,
        size: 24,
        supersample: 1,
        ..SynthConfig::default()
    };
    let summary = generate(&cfg, Some(audio), &out, false, &|| {}).unwrap();
    assert_eq!(summary.n_frames, 40);
    let scene = SceneFile::load(&out.join("scene.json")).unwrap();
    assert_eq!(scene.audio_source, "file");
    let stored = read_wav(&out.join("aud.wav")).unwrap();
    assert_eq!((stored.sample_rate, stored.samples.len()), (16_000, 25_600));
    for f in &scene.frames {
        let on = ((f.time + 0.02) / 0.4) as usize % 2 == 1;
        let edge = ((f.time / 0.4).fract() - 0.95).abs() < 0.06 || (f.time / 0.4).fract() < 0.05;
        if edge {
            continue;
        }
        if on {
            assert!(f.mouth_open > 0.5, "frame {} at {} s", f.img_id, f.time);
        } else {
            assert!(f.mouth_open < 0.05, "frame {} at {} s", f.img_id, f.time);
        }
    }
    // The audio must be long enough for the scene asked for.
    let short = SynthConfig {
        seconds: 3.0,
        ..cfg
    };
    let err = generate(
        &short,
        Some(read_wav(&wav).unwrap()),
        &dir.path().join("x"),
        false,
        &|| {},
    )
    .unwrap_err();
    assert!(err.to_string().contains("shorter"), "{err}");
    assert!(!dir.path().join("x").exists());
}

/// A valid 16-bit mono WAV of `n` samples, as bytes.
fn valid_wav(n: usize) -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: 16_000,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut w = hound::WavWriter::new(&mut buf, spec).unwrap();
    for i in 0..n {
        w.write_sample(((i * 37) % 2000) as i16 - 1000).unwrap();
    }
    w.finalize().unwrap();
    buf.into_inner()
}

/// A WAV header (`fmt ` chunk with the given fields) followed by `data` bytes.
fn handmade_wav(format_tag: u16, channels: u16, rate: u32, bits: u16, data: &[u8]) -> Vec<u8> {
    let block = channels.max(1) * bits.div_ceil(8);
    let mut v = Vec::new();
    v.extend_from_slice(b"RIFF");
    v.extend_from_slice(&(36 + data.len() as u32).to_le_bytes());
    v.extend_from_slice(b"WAVEfmt ");
    v.extend_from_slice(&16u32.to_le_bytes());
    v.extend_from_slice(&format_tag.to_le_bytes());
    v.extend_from_slice(&channels.to_le_bytes());
    v.extend_from_slice(&rate.to_le_bytes());
    v.extend_from_slice(&(rate * block as u32).to_le_bytes());
    v.extend_from_slice(&block.to_le_bytes());
    v.extend_from_slice(&bits.to_le_bytes());
    v.extend_from_slice(b"data");
    v.extend_from_slice(&(data.len() as u32).to_le_bytes());
    v.extend_from_slice(data);
    v
}

#[test]
fn malformed_audio_files_are_rejected_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let nan: Vec<u8> = [0.1f32, f32::NAN, 0.2]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let full = valid_wav(400);
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.wav", vec![], "empty"),
        (
            "text.wav",
            b"this is not audio at all\n".to_vec(),
            "not a readable WAV",
        ),
        ("header_only.wav", full[..20].to_vec(), "not a readable WAV"),
        (
            "truncated.wav",
            full[..full.len() - 301].to_vec(),
            "truncated",
        ),
        (
            "nan.wav",
            handmade_wav(3, 1, 16_000, 32, &nan),
            "not finite",
        ),
        (
            "zero_channels.wav",
            handmade_wav(1, 0, 16_000, 16, &[0; 8]),
            "WAV",
        ),
        (
            "zero_rate.wav",
            handmade_wav(1, 1, 0, 16, &[0; 8]),
            "sample rate",
        ),
        ("alaw.wav", handmade_wav(6, 1, 8000, 8, &[0; 8]), "WAV"),
        (
            "no_samples.wav",
            handmade_wav(1, 1, 16_000, 16, &[]),
            "no samples",
        ),
        (
            "double.wav",
            handmade_wav(3, 1, 16_000, 64, &[0; 16]),
            "WAV",
        ),
    ];
    for (name, bytes, needle) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let err = read_wav(&path).unwrap_err().to_string();
        assert_one_line_naming(&err, name);
        assert!(
            err.contains(needle),
            "{name}: {err:?} does not say {needle:?}"
        );
    }
    let err = read_wav(&dir.path().join("absent.wav"))
        .unwrap_err()
        .to_string();
    assert_one_line_naming(&err, "absent.wav");
}
