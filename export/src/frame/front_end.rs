//! The frame graph's log-mel front end (`nldf_core::audio::log_mel`): framing by Gather, the
//! Hann window, the DFT as two products with cosine and sine tables, the mel filters as a
//! product, the log; then the windows and the neighbourhood, clamped to the track where the
//! input marks samples off it with NaN (`nldf_core::frame_audio::FrameAudio`).

use nldf_core::audio::{FeatureConfig, hann_window, mel_filters};
use nldf_core::frame_audio::FrameAudio;

use crate::graph::{GraphBuilder, attr_int, attr_ints};

/// The front end: the chunk of samples to the audio neighbourhood, as
/// `FrameAudio::windows` computes it.
///
/// # Shapes
/// - `audio`: `[samples]`; returns `[att_frames, window, n_mels]`
pub(super) fn front_end(
    g: &mut GraphBuilder,
    layout: &FrameAudio,
    cfg: &FeatureConfig,
    audio: &str,
) -> String {
    let off_track = g.node("IsNaN", "front.off_track", &[audio], vec![]);
    let on_track = g.node("Not", "front.on_track", &[&off_track], vec![]);
    let zero = g.constant_f32("front.zero", &[], &[0.0]);
    let x = g.node(
        "Where",
        "front.samples",
        &[&off_track, &zero, audio],
        vec![],
    );
    let (frames, norm) = windowed_frames(g, layout, cfg, &x);
    let power = power_spectrum(g, cfg, &frames, norm);
    let feats = log_mel(g, cfg, &power);
    neighbourhood(g, layout, &on_track, &feats)
}

/// Framing and the Hann window: `[n_k, win]` frames and the spectrum's normalisation.
fn windowed_frames(
    g: &mut GraphBuilder,
    layout: &FrameAudio,
    cfg: &FeatureConfig,
    x: &str,
) -> (String, f32) {
    let n_k = layout.n_features();
    let win = cfg.win;
    // Framing: frame q reads samples q hop .. q hop + win.
    let starts: Vec<i64> = (0..n_k).map(|q| layout.feature_start(q) as i64).collect();
    let starts = g.constant_i64("front.frame_starts", &[n_k, 1], &starts);
    let taps: Vec<i64> = (0..win as i64).collect();
    let taps_row = g.constant_i64("front.frame_taps", &[1, win], &taps);
    let index = g.node("Add", "front.frame_index", &[&starts, &taps_row], vec![]);
    let frames = g.node(
        "Gather",
        "front.frames",
        &[x, &index],
        vec![attr_int("axis", 0)],
    );
    let (hann, norm) = hann_window(cfg);
    let hann = g.constant_f32("front.hann", &[1, win], &hann);
    let frames = g.node("Mul", "front.windowed", &[&frames, &hann], vec![]);
    (frames, norm)
}

/// The power spectrum of the windowed frames, `[n_k, n_bins]`, by the DFT.
fn power_spectrum(g: &mut GraphBuilder, cfg: &FeatureConfig, frames: &str, norm: f32) -> String {
    let (win, n_fft) = (cfg.win, cfg.n_fft);
    let n_bins = n_fft / 2 + 1;
    let taps: Vec<i64> = (0..win as i64).collect();
    // The DFT's cosine and sine at (n k mod n_fft), gathered from one period of each.
    let taps_col = g.constant_i64("front.dft_taps", &[win, 1], &taps);
    let bins: Vec<i64> = (0..n_bins as i64).collect();
    let bins = g.constant_i64("front.dft_bins", &[1, n_bins], &bins);
    let period = g.constant_i64("front.dft_period", &[], &[n_fft as i64]);
    let phase = g.node("Mul", "front.dft_phase_raw", &[&taps_col, &bins], vec![]);
    let phase = g.node("Mod", "front.dft_phase", &[&phase, &period], vec![]);
    let angle = |m: usize| 2.0 * std::f64::consts::PI * m as f64 / n_fft as f64;
    let cos: Vec<f32> = (0..n_fft).map(|m| angle(m).cos() as f32).collect();
    let sin: Vec<f32> = (0..n_fft).map(|m| angle(m).sin() as f32).collect();
    let cos = g.constant_f32("front.cos_period", &[n_fft], &cos);
    let sin = g.constant_f32("front.sin_period", &[n_fft], &sin);
    let cos = g.node(
        "Gather",
        "front.dft_cos",
        &[&cos, &phase],
        vec![attr_int("axis", 0)],
    );
    let sin = g.node(
        "Gather",
        "front.dft_sin",
        &[&sin, &phase],
        vec![attr_int("axis", 0)],
    );
    let re = g.node("MatMul", "front.re", &[frames, &cos], vec![]);
    let im = g.node("MatMul", "front.im", &[frames, &sin], vec![]);
    let re2 = g.node("Mul", "front.re2", &[&re, &re], vec![]);
    let im2 = g.node("Mul", "front.im2", &[&im, &im], vec![]);
    let power = g.node("Add", "front.power_raw", &[&re2, &im2], vec![]);
    let norm = g.constant_f32("front.norm", &[], &[norm]);
    g.node("Mul", "front.power", &[&power, &norm], vec![])
}

/// The log-mel features of the power spectrum, `[n_k, n_mels]`.
fn log_mel(g: &mut GraphBuilder, cfg: &FeatureConfig, power: &str) -> String {
    let (n_fft, n_mels) = (cfg.n_fft, cfg.n_mels);
    let n_bins = n_fft / 2 + 1;
    let filters = mel_filters(cfg);
    let mut mel_t = vec![0.0f32; n_bins * n_mels];
    for (m, filter) in filters.iter().enumerate() {
        for (b, &v) in filter.iter().enumerate() {
            mel_t[b * n_mels + m] = v;
        }
    }
    let mel_t = g.constant_f32("front.mel_filters", &[n_bins, n_mels], &mel_t);
    let energy = g.node("MatMul", "front.energy", &[power, &mel_t], vec![]);
    let floor = g.constant_f32("front.floor", &[], &[1e-10]);
    let energy = g.node("Max", "front.energy_floored", &[&energy, &floor], vec![]);
    let ln = g.node("Log", "front.ln", &[&energy], vec![]);
    let ln10 = g.constant_f32("front.ln10", &[], &[std::f32::consts::LN_10]);
    let log10 = g.node("Div", "front.log10", &[&ln, &ln10], vec![]);
    let five = g.constant_f32("front.five", &[], &[5.0]);
    let shifted = g.node("Add", "front.shifted", &[&log10, &five], vec![]);
    g.node("Div", "front.features", &[&shifted, &five], vec![])
}

/// The windows of the frame's neighbourhood, `[att_frames, window, n_mels]`, each neighbour
/// and feature frame clamped to the ones on the track.
fn neighbourhood(g: &mut GraphBuilder, layout: &FrameAudio, on_track: &str, feats: &str) -> String {
    let n_k = layout.n_features();
    // The track's ends: the first and last feature frame and neighbour on it.
    let axis0 = vec![attr_int("axis", 0)];
    let span = |g: &mut GraphBuilder, name: &str, deciding: Vec<i64>| -> (String, String) {
        let n = deciding.len();
        let deciding = g.constant_i64(&format!("{name}.deciding"), &[n], &deciding);
        let on = g.node(
            "Gather",
            &format!("{name}.on_track"),
            &[on_track, &deciding],
            axis0.clone(),
        );
        let index: Vec<i64> = (0..n as i64).collect();
        let index = g.constant_i64(&format!("{name}.index"), &[n], &index);
        let past = g.constant_i64(&format!("{name}.past"), &[], &[n as i64]);
        let before = g.constant_i64(&format!("{name}.before"), &[], &[-1]);
        let lo = g.node(
            "Where",
            &format!("{name}.lo_each"),
            &[&on, &index, &past],
            vec![],
        );
        let hi = g.node(
            "Where",
            &format!("{name}.hi_each"),
            &[&on, &index, &before],
            vec![],
        );
        let reduce = || vec![attr_ints("axes", &[0]), attr_int("keepdims", 0)];
        (
            g.node("ReduceMin", &format!("{name}.lo"), &[&lo], reduce()),
            g.node("ReduceMax", &format!("{name}.hi"), &[&hi], reduce()),
        )
    };
    let centres = (0..n_k).map(|q| layout.feature_centre(q) as i64).collect();
    let (k_lo, k_hi) = span(g, "front.feature_span", centres);
    let ends = (0..layout.att_frames)
        .map(|s| layout.frame_end(s) as i64)
        .collect();
    let (s_lo, s_hi) = span(g, "front.frame_span", ends);
    let none = g.constant_i64("front.index_zero", &[], &[0]);
    let clamp = |g: &mut GraphBuilder, name: &str, x: &str, lo: &str, hi: &str| -> String {
        let x = g.node("Max", &format!("{name}.above_lo"), &[x, lo], vec![]);
        let x = g.node("Min", &format!("{name}.below_hi"), &[&x, hi], vec![]);
        g.node("Max", name, &[&x, &none], vec![])
    };
    let neighbours: Vec<i64> = (0..layout.att_frames as i64).collect();
    let neighbours = g.constant_i64("front.neighbours", &[layout.att_frames, 1], &neighbours);
    let neighbours = clamp(g, "front.neighbours_clamped", &neighbours, &s_lo, &s_hi);
    let per_frame = g.constant_i64(
        "front.features_per_frame",
        &[],
        &[layout.features_per_frame as i64],
    );
    let first = g.node(
        "Mul",
        "front.window_first",
        &[&neighbours, &per_frame],
        vec![],
    );
    let entries: Vec<i64> = (0..layout.window as i64).collect();
    let entries = g.constant_i64("front.window_entries", &[1, layout.window], &entries);
    let which = g.node("Add", "front.window_index_raw", &[&first, &entries], vec![]);
    let which = clamp(g, "front.window_index", &which, &k_lo, &k_hi);
    g.node("Gather", "front.windows", &[feats, &which], axis0)
}
