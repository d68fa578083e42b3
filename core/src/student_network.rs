//! The student's light-field network as a list of layers: the one description that the
//! candle builder (`nldf_train::student`) and the ONNX builder (`nldf_export`) both follow,
//! so that a layer's name and shape are written once.
//!
//! The residual MLP of paper Eq. 6 on `[beam | code]`:
//!
//! ```text
//! input    Linear(beam_dim + audio_dim -> width), ReLU
//! body.i   x = relu(x + fc2(relu(fc1(x))))        (n_blocks blocks of width x width)
//! output   Linear(width -> 3 M [+ 1 opacity logit])
//! ```
//!
//! Names are relative to the MLP's own prefix ([`MLP_PREFIX`] in the student's weights):
//! a layer `body.0.fc1` holds `mlp.body.0.fc1.weight` `[fan_out, fan_in]` and
//! `mlp.body.0.fc1.bias` `[fan_out]`.

use crate::student_config::StudentConfig;

/// The MLP's prefix among the student's weights (beside the audio encoder's).
pub const MLP_PREFIX: &str = "mlp";

/// One linear layer: `x W^T + b`, `W` `[fan_out, fan_in]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinearLayer {
    /// The layer's name under [`MLP_PREFIX`].
    pub name: String,
    pub fan_in: usize,
    pub fan_out: usize,
}

impl LinearLayer {
    fn new(name: String, fan_in: usize, fan_out: usize) -> LinearLayer {
        LinearLayer {
            name,
            fan_in,
            fan_out,
        }
    }

    /// The layer's full name among the student's weights (`mlp.<name>`).
    pub fn path(&self) -> String {
        format!("{MLP_PREFIX}.{}", self.name)
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
                fc1: LinearLayer::new(format!("body.{i}.fc1"), w, w),
                fc2: LinearLayer::new(format!("body.{i}.fc2"), w, w),
            })
            .collect();
        MlpLayout {
            input: LinearLayer::new("input".into(), cfg.input_dim(), w),
            body,
            output: LinearLayer::new("output".into(), w, cfg.output_dim()),
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
    }
}
