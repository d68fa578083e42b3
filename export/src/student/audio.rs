//! The student's audio encoder: AudioNet over the windows of the frame's neighbourhood and
//! AudioAttNet's weighted sum (AD-NeRF).

use super::ops::{conv_leaky, leaky, linear};
use crate::checkpoint::StudentCheckpoint;
use crate::error::Result;
use crate::graph::{GraphBuilder, attr_int, attr_ints};
use nldf_core::student_config::AudioConfig;
use nldf_core::student_network::{AudioLayout, LinearLayer};

/// The audio code of the frame: AudioNet over each window of the neighbourhood and
/// AudioAttNet's weighted sum, or AudioNet over the centre window without attention.
///
/// # Shapes
/// - `audio`: `[att_frames, window, n_features]`
/// - returns `audio.code` `[1, dim]`
pub(super) fn audio_code(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    audio: &str,
) -> Result<String> {
    let a = &ckpt.shape.audio;
    let seq = a.att_frames;
    let windows = if ckpt.shape.attention {
        audio.to_string()
    } else {
        let c = (seq / 2) as i64;
        let starts = g.constant_i64("audio.centre_start", &[1], &[c]);
        let ends = g.constant_i64("audio.centre_end", &[1], &[c + 1]);
        let axes = g.constant_i64("audio.centre_axis", &[1], &[0]);
        g.node(
            "Slice",
            "audio.centre",
            &[audio, &starts, &ends, &axes],
            vec![],
        )
    };
    let windows = rows_read(g, a, windows);
    // AudioNet: [n, window, F] -> [n, F, window] -> convs -> mean over what is left.
    let mut x = g.node(
        "Transpose",
        "audio.net.input",
        &[&windows],
        vec![attr_ints("perm", &[0, 2, 1])],
    );
    let layout = AudioLayout::of(a);
    for c in &layout.net_convs {
        x = conv_leaky(g, ckpt, c, &x)?;
    }
    let x = g.node(
        "ReduceMean",
        "audio.net.mean",
        &[&x],
        vec![attr_ints("axes", &[2]), attr_int("keepdims", 0)],
    );
    let dense = |g: &mut GraphBuilder, l: &LinearLayer, x: &str| {
        linear(g, ckpt, &l.path(), x, l.fan_in, l.fan_out)
    };
    let x = dense(g, &layout.net_fc1, &x)?;
    let x = leaky(g, &format!("{}.act", layout.net_fc1.path()), &x);
    let codes = dense(g, &layout.net_fc2, &x)?;
    if !ckpt.shape.attention {
        return Ok(g.node("Identity", "audio.code", &[&codes], vec![]));
    }
    // AudioAttNet: [seq, dim] -> [1, dim, seq] -> convs -> [1, seq] logits -> softmax.
    let t = g.node(
        "Transpose",
        "audio.att.input_t",
        &[&codes],
        vec![attr_ints("perm", &[1, 0])],
    );
    let axis0 = g.constant_i64("audio.att.axis0", &[1], &[0]);
    let mut y = g.node("Unsqueeze", "audio.att.input", &[&t, &axis0], vec![]);
    for c in &layout.att_convs {
        y = conv_leaky(g, ckpt, c, &y)?;
    }
    let shape = g.constant_i64("audio.att.logit_shape", &[2], &[1, seq as i64]);
    let y = g.node("Reshape", "audio.att.logits_in", &[&y, &shape], vec![]);
    let y = dense(g, &layout.attention, &y)?;
    let weights = g.node(
        "Softmax",
        "audio.att.weights",
        &[&y],
        vec![attr_int("axis", 1)],
    );
    Ok(g.node("MatMul", "audio.code", &[&weights, &codes], vec![]))
}

/// A short-lookahead encoder reads the first [`AudioConfig::rows_read`] rows of each
/// window: the rest are zeroed, as the trainer zeroes them (`windows` as they are for an
/// encoder that reads every row).
///
/// # Shapes
/// - `windows`: `[n, window, n_features]`; returns the same
fn rows_read(g: &mut GraphBuilder, a: &AudioConfig, windows: String) -> String {
    let rows = a.rows_read();
    if rows >= a.window {
        return windows;
    }
    let mask: Vec<f32> = (0..a.window)
        .map(|j| if j < rows { 1.0 } else { 0.0 })
        .collect();
    let mask = g.constant_f32("audio.rows_read", &[1, a.window, 1], &mask);
    g.node("Mul", "audio.ahead", &[&windows, &mask], vec![])
}
