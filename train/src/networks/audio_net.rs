//! AD-NeRF's audio encoder: [`AudioNet`] turns one window of audio features into a code, and
//! [`AudioAttNet`] fuses the codes of neighbouring frames with learned attention.

use candle_core::{D, Module, Result, Tensor};
use candle_nn::{Linear, VarBuilder, linear};

use crate::networks::nn::{Conv1d, conv1d};

use nldf_core::student_config::AudioConfig;
use nldf_core::student_network::{AudioLayout, Conv1dLayer, LinearLayer};

/// AD-NeRF's LeakyReLU slope.
const SLOPE: f64 = 0.02;

/// AudioNet: four Conv1d over the window (F -> 32 -> 32 -> 64 -> 64, kernel 3, stride 2,
/// padding 1, LeakyReLU 0.02) that halve it 16 -> 1, then Linear 64 -> 64, LeakyReLU,
/// Linear 64 -> dim.
#[derive(Debug, Clone)]
pub struct AudioNet {
    convs: Vec<Conv1d>,
    fc1: Linear,
    fc2: Linear,
}

/// Builds an [`AudioNet`] under `vb` (`convs.{i}`, `fc1`, `fc2`), as its [`AudioLayout`]
/// lists them.
pub fn audio_net(cfg: &AudioConfig, vb: VarBuilder) -> Result<AudioNet> {
    let layout = AudioLayout::of(cfg);
    let convs = convs_of(&layout.net_convs, &vb)?;
    Ok(AudioNet {
        convs,
        fc1: linear_of(&layout.net_fc1, &vb)?,
        fc2: linear_of(&layout.net_fc2, &vb)?,
    })
}

/// The described convolutions under their network's `vb`, in order.
fn convs_of(layers: &[Conv1dLayer], vb: &VarBuilder) -> Result<Vec<Conv1d>> {
    layers.iter().map(|c| conv_of(c, vb)).collect()
}

/// The described convolution under its network's `vb`.
fn conv_of(c: &Conv1dLayer, vb: &VarBuilder) -> Result<Conv1d> {
    conv1d(
        c.c_in,
        c.c_out,
        c.kernel,
        c.stride,
        c.padding(),
        vb.pp(&c.name),
    )
}

/// The described linear layer under its network's `vb`.
fn linear_of(l: &LinearLayer, vb: &VarBuilder) -> Result<Linear> {
    linear(l.fan_in, l.fan_out, vb.pp(&l.name))
}

impl AudioNet {
    /// The audio code of each window.
    ///
    /// # Shapes
    /// - `windows`: `[n, window, n_features]` (AD-NeRF's `aud.npy` rows; window 16)
    /// - returns `[n, dim]`
    pub fn forward(&self, windows: &Tensor) -> Result<Tensor> {
        let mut x = windows.transpose(1, 2)?.contiguous()?;
        for conv in &self.convs {
            x = candle_nn::ops::leaky_relu(&conv.forward(&x)?, SLOPE)?;
        }
        // Whatever length is left (1 for a 16-frame window) is averaged away.
        let x = x.mean(D::Minus1)?;
        let x = candle_nn::ops::leaky_relu(&self.fc1.forward(&x)?, SLOPE)?;
        self.fc2.forward(&x)
    }
}

/// AudioAttNet: Conv1d over the sequence of codes (dim -> 16 -> 8 -> 4 -> 2 -> 1, kernel 3,
/// padding 1, LeakyReLU 0.02), Linear(seq, seq) and a softmax give one weight per
/// neighbouring frame; the fused code is the weighted sum.
#[derive(Debug, Clone)]
pub struct AudioAttNet {
    convs: Vec<Conv1d>,
    attention: Linear,
}

/// Builds an [`AudioAttNet`] under `vb` (`convs.{i}`, `attention`), as its
/// [`AudioLayout`] lists them.
pub fn audio_att_net(cfg: &AudioConfig, vb: VarBuilder) -> Result<AudioAttNet> {
    let layout = AudioLayout::of(cfg);
    let convs = convs_of(&layout.att_convs, &vb)?;
    Ok(AudioAttNet {
        convs,
        attention: linear_of(&layout.attention, &vb)?,
    })
}

impl AudioAttNet {
    /// Fuses the codes of each sequence of neighbouring frames.
    ///
    /// # Shapes
    /// - `codes`: `[n, seq, dim]` (seq = `att_frames`)
    /// - returns `[n, dim]`
    pub fn forward(&self, codes: &Tensor) -> Result<Tensor> {
        let (n, seq, _dim) = codes.dims3()?;
        let mut y = codes.transpose(1, 2)?.contiguous()?;
        for conv in &self.convs {
            y = candle_nn::ops::leaky_relu(&conv.forward(&y)?, SLOPE)?;
        }
        let y = self.attention.forward(&y.reshape((n, seq))?)?;
        let weights = candle_nn::ops::softmax(&y, D::Minus1)?;
        codes.broadcast_mul(&weights.unsqueeze(2)?)?.sum(1)
    }
}

/// The audio encoder: AudioNet, and AudioAttNet once it is switched on.
#[derive(Debug, Clone)]
pub struct AudioEncoder {
    pub net: AudioNet,
    pub att: AudioAttNet,
    pub cfg: AudioConfig,
}

/// Builds an [`AudioEncoder`] under `vb` (`net`, `att`).
pub fn audio_encoder(cfg: &AudioConfig, vb: VarBuilder) -> Result<AudioEncoder> {
    Ok(AudioEncoder {
        net: audio_net(cfg, vb.pp("net"))?,
        att: audio_att_net(cfg, vb.pp("att"))?,
        cfg: cfg.clone(),
    })
}

impl AudioEncoder {
    /// A short-lookahead encoder's mask over each window's rows, `[1, 1, window, 1]`: 1 for
    /// the [`AudioConfig::rows_read`] first rows, 0 after; `None` when it reads them all.
    fn rows_mask(&self, window: usize, device: &candle_core::Device) -> Result<Option<Tensor>> {
        let rows = self.cfg.rows_read().min(window);
        if rows == window {
            return Ok(None);
        }
        let mask: Vec<f32> = (0..window)
            .map(|j| if j < rows { 1.0 } else { 0.0 })
            .collect();
        Ok(Some(Tensor::from_vec(mask, (1, 1, window, 1), device)?))
    }

    /// Codes of `n` frames from their neighbourhoods: with attention, the `att_frames`
    /// windows around each frame are encoded and fused; without, only the centre window
    /// (index `att_frames / 2`) is encoded.
    ///
    /// # Shapes
    /// - `neighbourhoods`: `[n, att_frames, window, n_features]`
    /// - returns `[n, dim]`
    pub fn forward(&self, neighbourhoods: &Tensor, attention: bool) -> Result<Tensor> {
        let (n, seq, window, f) = neighbourhoods.dims4()?;
        let masked;
        let neighbourhoods = match self.rows_mask(window, neighbourhoods.device())? {
            Some(mask) => {
                masked = neighbourhoods.broadcast_mul(&mask)?;
                &masked
            }
            None => neighbourhoods,
        };
        if attention {
            let codes = self
                .net
                .forward(&neighbourhoods.reshape((n * seq, window, f))?)?;
            self.att.forward(&codes.reshape((n, seq, self.cfg.dim))?)
        } else {
            let centre = neighbourhoods.narrow(1, seq / 2, 1)?.squeeze(1)?;
            self.net.forward(&centre.contiguous()?)
        }
    }
}

/// Logit of the centre frame in AudioAttNet's initial attention (softmax weight
/// `e^3 / (e^3 + 7)`, about 0.74, over 8 frames).
const CENTRE_LOGIT: f32 = 3.0;

/// A new network's first weights: every variable of `varmap` drawn from `seed`
/// ([`crate::networks::nn::init_seeded`]), then the audio attention under `audio` centred
/// ([`centre_attention`]) over its `att_frames` frames. The teacher and the student start so.
pub fn init_with_centred_attention(
    varmap: &candle_nn::VarMap,
    seed: u64,
    att_frames: usize,
) -> Result<()> {
    crate::networks::nn::init_seeded(varmap, seed)?;
    centre_attention(varmap, "audio", att_frames)
}

/// Starts AudioAttNet focused on the centre frame: its attention layer's weight at zero and
/// its bias peaked at the centre, so that switching attention on late in training (as
/// AD-NeRF does) changes the audio code little instead of jolting the field. `prefix` is the
/// encoder's path in `varmap` (e.g. `audio`).
pub fn centre_attention(varmap: &candle_nn::VarMap, prefix: &str, att_frames: usize) -> Result<()> {
    let data = varmap
        .data()
        .lock()
        .map_err(|_| candle_core::Error::Msg("variable map lock poisoned".into()))?;
    let get = |name: &str| {
        data.get(&format!("{prefix}.att.attention.{name}"))
            .ok_or_else(|| candle_core::Error::Msg(format!("no `{prefix}.att.attention.{name}`")))
    };
    let weight = get("weight")?;
    weight.set(&weight.zeros_like()?)?;
    let mut bias = vec![0.0f32; att_frames];
    if let Some(c) = bias.get_mut(att_frames / 2) {
        *c = CENTRE_LOGIT;
    }
    let b = get("bias")?;
    b.set(&Tensor::from_vec(bias, att_frames, b.device())?)
}

/// The neighbourhoods of several frames as one tensor (see [`nldf_core::audio::neighbourhood`]).
///
/// # Shapes
/// - returns `[aud_ids.len(), seq, window, n_features]`
pub fn neighbourhoods(
    audio: &nldf_core::audio::AudioWindows,
    aud_ids: &[usize],
    seq: usize,
) -> Result<Tensor> {
    let flat: Vec<f32> = aud_ids
        .iter()
        .flat_map(|&f| nldf_core::audio::neighbourhood(audio, f, seq))
        .collect();
    Tensor::from_vec(
        flat,
        (aud_ids.len(), seq, audio.window, audio.n_features),
        &candle_core::Device::Cpu,
    )
}
