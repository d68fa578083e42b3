//! The NLDF student (paper section 3.1, after R2L): a deep residual MLP that maps a whole
//! encoded beam plus the audio code to M segment colours in one pass; the pixel is their sum
//! (Eq. 7). Beam encoding lives in nldf-core ([`nldf_core::beam`]); this file is the
//! network and the segment sum.

use candle_core::{D, Device, Result, Tensor};
use candle_nn::{Linear, Module, VarBuilder, linear};
use nldf_core::beam::encode_beams;
use nldf_core::rays::Rays;
use nldf_core::student_network::{LinearLayer, MLP_PREFIX, MlpLayout};

use crate::networks::audio_net::{AudioEncoder, audio_encoder};
use crate::ops::student_op::{StudentOp, StudentPlan};
pub use nldf_core::student_config::StudentConfig;

/// What the light field gives for a batch of rays.
#[derive(Debug, Clone)]
pub struct LightOut {
    /// The M segment colours, `[n_rays, m, 3]`: each a weighted sum of sample colours,
    /// not bounded by a squashing function of its own, premultiplied: the network's raw
    /// segment colours times the ray's opacity, as the teacher's Eq. 5 segments carry its
    /// weights, so that a ray the head does not cover adds no colour.
    pub segments: Tensor,
    /// Their sum, `[n_rays, 3]` (Eq. 7): the head's colour, premultiplied by its opacity.
    pub colour: Tensor,
    /// How much of each ray the head covers, `sigmoid(logit)`, `[n_rays, 1]`.
    pub opacity: Tensor,
    /// The opacity's logit, the network's last output, `[n_rays, 1]`.
    pub logit: Tensor,
}

impl LightOut {
    /// The pixels over `background` (`[n_rays, 3]`): `colour + (1 - opacity) *
    /// background`, as the teacher composites.
    ///
    /// # Shapes
    /// - returns `[n_rays, 3]`
    pub fn pixels(&self, background: &Tensor) -> Result<Tensor> {
        let clear = self.opacity.affine(-1.0, 1.0)?;
        &self.colour + clear.broadcast_mul(background)?
    }

    /// Splits the network's raw output `[n_rays, 3 m + 1]`.
    fn from_raw(raw: &Tensor, m: usize) -> Result<LightOut> {
        let n_rays = raw.dim(0)?;
        let logit = raw.narrow(1, 3 * m, 1)?;
        let opacity = candle_nn::ops::sigmoid(&logit)?;
        let colours = raw.narrow(1, 0, 3 * m)?.broadcast_mul(&opacity)?;
        let segments = colours.reshape((n_rays, m, 3))?;
        let colour = segments.sum(1)?;
        Ok(LightOut {
            segments,
            colour,
            opacity,
            logit,
        })
    }
}

/// One residual block: `relu(x + fc2(relu(fc1(x))))`.
#[derive(Debug, Clone)]
struct ResidualBlock {
    fc1: Linear,
    fc2: Linear,
}

/// The residual MLP: `input`, `body.{i}.{fc1,fc2}`, `output`.
#[derive(Debug, Clone)]
pub struct ResidualMlp {
    input: Linear,
    body: Vec<ResidualBlock>,
    output: Linear,
    segments: usize,
}

/// Builds a [`ResidualMlp`] for `cfg` under `vb`, layer by layer as its
/// [`MlpLayout`] lists them (the blocks created first, as the weights' initial draws
/// have always been made).
pub fn residual_mlp(cfg: &StudentConfig, vb: VarBuilder) -> Result<ResidualMlp> {
    let layout = MlpLayout::of(cfg);
    let layer = |l: &LinearLayer| linear(l.fan_in, l.fan_out, vb.pp(&l.name));
    let body = layout
        .body
        .iter()
        .map(|b| {
            Ok(ResidualBlock {
                fc1: layer(&b.fc1)?,
                fc2: layer(&b.fc2)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(ResidualMlp {
        input: layer(&layout.input)?,
        body,
        output: layer(&layout.output)?,
        segments: cfg.segments,
    })
}

impl ResidualMlp {
    /// The same function as [`ResidualMlp::forward`] through the fused op
    /// ([`StudentOp`]): one candle op for the whole network. With `train`, it keeps what
    /// its backward needs; gradients reach the weights and `codes`, not `beams`.
    ///
    /// # Shapes
    /// - `beams`: `[n_rays, beam_dim]`; `codes`: `[n_rays, audio_dim]`
    pub fn forward_fused(&self, beams: &Tensor, codes: &Tensor, train: bool) -> Result<LightOut> {
        let beam_dim = beams.dim(1)?;
        let layer = |l: &Linear| -> Result<(Tensor, Tensor)> {
            let b = l
                .bias()
                .ok_or_else(|| candle_core::Error::Msg("student layers have biases".into()))?;
            Ok((l.weight().clone(), b.clone()))
        };
        let input = layer(&self.input)?;
        let blocks = self
            .body
            .iter()
            .map(|b| Ok([layer(&b.fc1)?, layer(&b.fc2)?]))
            .collect::<Result<Vec<_>>>()?;
        let block_refs: Vec<[(&Tensor, &Tensor); 2]> = blocks
            .iter()
            .map(|[a, b]| [(&a.0, &a.1), (&b.0, &b.1)])
            .collect();
        let output = layer(&self.output)?;
        let (plan, params) = StudentPlan::pack(
            (&input.0, &input.1),
            &block_refs,
            (&output.0, &output.1),
            beam_dim,
        )?;
        let op = StudentOp::new(plan, train);
        let (beams, codes) = (beams.contiguous()?, codes.contiguous()?);
        let raw = if train {
            beams.apply_op3(&codes, &params, op)?
        } else {
            beams.apply_op3_no_bwd(&codes, &params, &op)?
        };
        LightOut::from_raw(&raw, self.segments)
    }

    /// Segment colours, their sum (Eq. 7) and the opacity, with plain candle ops.
    ///
    /// # Shapes
    /// - `beams`: `[n_rays, beam_dim]` encoded beams; `codes`: `[n_rays, audio_dim]`
    pub fn forward(&self, beams: &Tensor, codes: &Tensor) -> Result<LightOut> {
        Ok(self.forward_hidden(beams, codes)?.1)
    }

    /// [`ResidualMlp::forward`] with the last hidden layer, the features the learned
    /// upsampler reads.
    ///
    /// # Shapes
    /// - returns the hidden layer `[n_rays, width]` and the outputs
    pub fn forward_hidden(&self, beams: &Tensor, codes: &Tensor) -> Result<(Tensor, LightOut)> {
        let x = Tensor::cat(&[beams, codes], D::Minus1)?;
        let mut h = self.input.forward(&x)?.relu()?;
        for block in &self.body {
            let y = block.fc2.forward(&block.fc1.forward(&h)?.relu()?)?;
            h = (h + y)?.relu()?;
        }
        let out = LightOut::from_raw(&self.output.forward(&h)?, self.segments)?;
        Ok((h, out))
    }
}

/// The student: its own audio encoder (`audio.net.*`, `audio.att.*`, started from the
/// teacher's) and the residual MLP (`mlp.input`, `mlp.body.{i}.{fc1,fc2}`, `mlp.output`).
/// These are the checkpoint's tensor names, which the exporter reads.
#[derive(Debug, Clone)]
pub struct Student {
    pub cfg: StudentConfig,
    pub audio: AudioEncoder,
    pub mlp: ResidualMlp,
}

/// Builds a [`Student`] for `cfg` under `vb` (`audio`, `mlp`).
pub fn student(cfg: &StudentConfig, vb: VarBuilder) -> Result<Student> {
    Ok(Student {
        cfg: cfg.clone(),
        audio: audio_encoder(&cfg.audio, vb.pp("audio"))?,
        mlp: residual_mlp(cfg, vb.pp(MLP_PREFIX))?,
    })
}

impl Student {
    /// Audio codes of frames from their neighbourhoods.
    ///
    /// # Shapes
    /// - `neighbourhoods`: `[n, att_frames, window, n_features]`; returns `[n, audio_dim]`
    pub fn audio_codes(&self, neighbourhoods: &Tensor) -> Result<Tensor> {
        self.audio.forward(neighbourhoods, self.cfg.attention)
    }

    /// Encoded beams of `rays` without jitter (rendering).
    ///
    /// # Shapes
    /// - returns `[rays.len(), beam_dim]`
    pub fn encode(&self, rays: &Rays, near: f32, far: f32) -> Result<Tensor> {
        let width = self.cfg.beam.encoded_len();
        let mut out = vec![0.0f32; rays.len() * width];
        encode_beams(rays, near, far, &self.cfg.beam, None, &mut out);
        Tensor::from_vec(out, (rays.len(), width), &Device::Cpu)
    }

    /// Segment colours, colour and opacity of `rays` seen by one frame whose audio
    /// neighbourhood is `neighbourhood`, with plain candle ops (the reference every
    /// exported runtime must match; [`LightOut::pixels`] composites them).
    ///
    /// # Shapes
    /// - `neighbourhood`: `[1, att_frames, window, n_features]`
    pub fn render_rays(
        &self,
        rays: &Rays,
        neighbourhood: &Tensor,
        near: f32,
        far: f32,
    ) -> Result<LightOut> {
        let code = self.audio_codes(neighbourhood)?;
        let beams = self.encode(rays, near, far)?;
        let codes = code
            .broadcast_as((rays.len(), code.dim(1)?))?
            .contiguous()?;
        self.mlp.forward(&beams, &codes)
    }
}
