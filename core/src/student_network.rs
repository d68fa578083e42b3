//! The student's networks as lists of layers: the one description that the candle builders
//! (`nldf_train::student`, `nldf_train::audio_net`) and the ONNX builder (`nldf_export`)
//! follow, so that a layer's name and shape are written once.
//!
//! The audio encoder (AD-NeRF's; the teacher has the same one), [`AudioLayout`]:
//!
//! ```text
//! net.convs.i    Conv1d F -> 32 -> 32 -> 64 -> 64 (kernel 3, stride 2), LeakyReLU 0.02
//! net.fc1, fc2   Linear 64 -> 64, LeakyReLU; Linear 64 -> dim
//! att.convs.i    Conv1d dim -> 16 -> 8 -> 4 -> 2 -> 1 (kernel 3, stride 1), LeakyReLU
//! att.attention  Linear seq -> seq, softmax: one weight per neighbouring frame
//! ```
//!
//! The residual MLP of paper Eq. 6 on `[beam | code]`, [`MlpLayout`]:
//!
//! ```text
//! input    Linear(beam_dim + audio_dim -> width), ReLU
//! body.i   x = relu(x + fc2(relu(fc1(x))))        (n_blocks blocks of width x width)
//! output   Linear(width -> 3 M [+ 1 opacity logit])
//! ```
//!
//! A layer's name is relative to its network's prefix, as a candle builder given that
//! network's `VarBuilder` names it; its path is the full name among the student's weights:
//! the layer `body.0.fc1` of the MLP (prefix [`MLP_PREFIX`]) holds `mlp.body.0.fc1.weight`
//! `[fan_out, fan_in]` and `mlp.body.0.fc1.bias` `[fan_out]`.

use crate::student_config::{AudioConfig, StudentConfig};

/// The MLP's prefix among the student's weights.
pub const MLP_PREFIX: &str = "mlp";
/// AudioNet's prefix among the student's weights.
pub const AUDIO_NET_PREFIX: &str = "audio.net";
/// AudioAttNet's prefix among the student's weights.
pub const AUDIO_ATT_PREFIX: &str = "audio.att";

/// One linear layer: `x W^T + b`, `W` `[fan_out, fan_in]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinearLayer {
    /// Its network's prefix among the student's weights.
    pub prefix: &'static str,
    /// The layer's name under its network's prefix.
    pub name: String,
    pub fan_in: usize,
    pub fan_out: usize,
}

impl LinearLayer {
    fn new(prefix: &'static str, name: String, fan_in: usize, fan_out: usize) -> LinearLayer {
        LinearLayer {
            prefix,
            name,
            fan_in,
            fan_out,
        }
    }

    /// The layer's full name among the student's weights (`<prefix>.<name>`).
    pub fn path(&self) -> String {
        format!("{}.{}", self.prefix, self.name)
    }

    /// Its tensors among the student's weights: `(name, shape)` of the weight, then the bias.
    pub fn tensors(&self) -> [(String, Vec<usize>); 2] {
        [
            (
                format!("{}.weight", self.path()),
                vec![self.fan_out, self.fan_in],
            ),
            (format!("{}.bias", self.path()), vec![self.fan_out]),
        ]
    }
}

/// One residual block, `relu(x + fc2(relu(fc1(x))))`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ResidualBlock {
    /// The block's name under [`MLP_PREFIX`] (`body.<i>`).
    pub name: String,
    pub fc1: LinearLayer,
    pub fc2: LinearLayer,
}

impl ResidualBlock {
    /// The block's full name among the student's weights (`mlp.body.<i>`).
    pub fn path(&self) -> String {
        format!("{MLP_PREFIX}.{}", self.name)
    }
}

/// The student's residual MLP, layer by layer (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MlpLayout {
    pub input: LinearLayer,
    pub body: Vec<ResidualBlock>,
    pub output: LinearLayer,
}

impl MlpLayout {
    /// The layout of `cfg`'s MLP.
    pub fn of(cfg: &StudentConfig) -> MlpLayout {
        let w = cfg.width;
        let body = (0..cfg.n_blocks())
            .map(|i| ResidualBlock {
                name: format!("body.{i}"),
                fc1: LinearLayer::new(MLP_PREFIX, format!("body.{i}.fc1"), w, w),
                fc2: LinearLayer::new(MLP_PREFIX, format!("body.{i}.fc2"), w, w),
            })
            .collect();
        MlpLayout {
            input: LinearLayer::new(MLP_PREFIX, "input".into(), cfg.input_dim(), w),
            body,
            output: LinearLayer::new(MLP_PREFIX, "output".into(), w, cfg.output_dim()),
        }
    }

    /// Every linear layer in the order a ray passes through them.
    pub fn layers(&self) -> Vec<&LinearLayer> {
        std::iter::once(&self.input)
            .chain(self.body.iter().flat_map(|b| [&b.fc1, &b.fc2]))
            .chain(std::iter::once(&self.output))
            .collect()
    }

    /// Multiply-adds per ray: the sum of the layers' `fan_in x fan_out`.
    pub fn macs_per_ray(&self) -> usize {
        self.layers().iter().map(|l| l.fan_in * l.fan_out).sum()
    }
}

/// One Conv1d with LeakyReLU: `weight` `[c_out, c_in, kernel]`, padding `kernel / 2`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Conv1dLayer {
    /// Its network's prefix among the student's weights.
    pub prefix: &'static str,
    /// The layer's name under its network's prefix.
    pub name: String,
    pub c_in: usize,
    pub c_out: usize,
    pub kernel: usize,
    pub stride: usize,
}

impl Conv1dLayer {
    /// The layer's full name among the student's weights (`<prefix>.<name>`).
    pub fn path(&self) -> String {
        format!("{}.{}", self.prefix, self.name)
    }

    /// Zero padding on each side.
    pub fn padding(&self) -> usize {
        self.kernel / 2
    }

    /// Its tensors among the student's weights: `(name, shape)` of the weight, then the bias.
    pub fn tensors(&self) -> [(String, Vec<usize>); 2] {
        [
            (
                format!("{}.weight", self.path()),
                vec![self.c_out, self.c_in, self.kernel],
            ),
            (format!("{}.bias", self.path()), vec![self.c_out]),
        ]
    }
}

/// Kernel of every audio convolution.
const AUDIO_KERNEL: usize = 3;

/// AD-NeRF's audio encoder, layer by layer (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AudioLayout {
    /// AudioNet's convolutions, which halve the window 16 -> 1.
    pub net_convs: Vec<Conv1dLayer>,
    pub net_fc1: LinearLayer,
    pub net_fc2: LinearLayer,
    /// AudioAttNet's convolutions over the sequence of codes.
    pub att_convs: Vec<Conv1dLayer>,
    pub attention: LinearLayer,
}

impl AudioLayout {
    /// The layout of `cfg`'s encoder.
    pub fn of(cfg: &AudioConfig) -> AudioLayout {
        let convs = |prefix: &'static str, channels: &[usize], stride: usize| {
            channels
                .windows(2)
                .enumerate()
                .map(|(i, c)| Conv1dLayer {
                    prefix,
                    name: format!("convs.{i}"),
                    c_in: c[0],
                    c_out: c[1],
                    kernel: AUDIO_KERNEL,
                    stride,
                })
                .collect()
        };
        let net = AUDIO_NET_PREFIX;
        let att = AUDIO_ATT_PREFIX;
        AudioLayout {
            net_convs: convs(net, &[cfg.n_features, 32, 32, 64, 64], 2),
            net_fc1: LinearLayer::new(net, "fc1".into(), 64, 64),
            net_fc2: LinearLayer::new(net, "fc2".into(), 64, cfg.dim),
            att_convs: convs(att, &[cfg.dim, 16, 8, 4, 2, 1], 1),
            attention: LinearLayer::new(att, "attention".into(), cfg.att_frames, cfg.att_frames),
        }
    }

    /// Every tensor of the encoder: `(path, shape)`.
    pub fn tensors(&self) -> Vec<(String, Vec<usize>)> {
        let convs = self.net_convs.iter().chain(&self.att_convs);
        let linears = [&self.net_fc1, &self.net_fc2, &self.attention];
        convs
            .flat_map(|c| c.tensors())
            .chain(linears.into_iter().flat_map(|l| l.tensors()))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layout_follows_the_config() {
        let cfg = StudentConfig::paper_d28();
        let layout = MlpLayout::of(&cfg);
        assert_eq!(layout.body.len(), 13);
        assert_eq!(layout.layers().len(), 28);
        assert_eq!(layout.input.fan_in, cfg.input_dim());
        assert_eq!(layout.output.fan_out, cfg.output_dim());
        assert_eq!(layout.body[3].fc2.path(), "mlp.body.3.fc2");
        assert_eq!(
            layout.output.tensors()[0],
            ("mlp.output.weight".to_string(), vec![cfg.output_dim(), 256])
        );
        assert_eq!(layout.macs_per_ray(), cfg.macs_per_ray());
        let audio = AudioLayout::of(&cfg.audio);
        assert_eq!((audio.net_convs.len(), audio.att_convs.len()), (4, 5));
        assert_eq!(audio.net_convs[3].path(), "audio.net.convs.3");
        assert_eq!(audio.att_convs[4].c_out, 1);
        assert_eq!(audio.tensors().len(), 2 * (4 + 5 + 3));
    }
}
