//! The learned upsampler's shape and the geometry every stage shares (after MobileR2L): the
//! student evaluates the rays of a coarse grid, one ray per `factor x factor` block of output
//! pixels ([`coarse_intrinsics`]), and a small CNN turns the grid's features into the
//! full-size image, on the head's bounding box only ([`coarse_box`]). The trainer saves the
//! shape as `model` in the upsampler's `config.json`; the exporter and the renderers read it
//! back from there.

use serde::{Deserialize, Serialize};

use crate::bounds::Bounds;
use crate::camera::Intrinsics;
use crate::checks::in_range;
use crate::error::{Error, Result};

/// A logit that no trained opacity reaches: the opacity channel of a coarse ray that misses
/// the head's bounds (it was not evaluated; `sigmoid(-MISS_LOGIT)` is 0 in f32).
pub const MISS_LOGIT: f32 = -30.0;

/// One square convolution of the upsampler's CNN: `weight` `[c_out, c_in, kernel, kernel]`,
/// zero padding `kernel / 2`; named as in the upsampler's weights (`stages.0`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Conv2dLayer {
    pub name: String,
    pub c_in: usize,
    pub c_out: usize,
    pub kernel: usize,
}

impl Conv2dLayer {
    /// Its tensors among the upsampler's weights: `(name, shape)` of the weight, then the
    /// bias.
    pub fn tensors(&self) -> [(String, Vec<usize>); 2] {
        let k = self.kernel;
        [
            (
                format!("{}.weight", self.name),
                vec![self.c_out, self.c_in, k, k],
            ),
            (format!("{}.bias", self.name), vec![self.c_out]),
        ]
    }
}

/// The upsampler's CNN ([`UpsamplerConfig::layout`]): `reduce` (1 x 1, the student's
/// `width + 4` features to `channels[0]`), then per x2 stage `stages.s` (3 x 3 to
/// `4 channels[s + 1]`, depth-to-space 2, ReLU), then `head` (3 x 3 to 4: colour and
/// opacity logit).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UpsamplerLayout {
    pub reduce: Conv2dLayer,
    pub stages: Vec<Conv2dLayer>,
    pub head: Conv2dLayer,
}

impl UpsamplerLayout {
    /// Every layer in the order the grid passes through them.
    pub fn layers(&self) -> Vec<&Conv2dLayer> {
        std::iter::once(&self.reduce)
            .chain(&self.stages)
            .chain(std::iter::once(&self.head))
            .collect()
    }
}

/// The upsampler's shape.
///
/// Input, per coarse ray: the student's last hidden layer (`width` values, zero for a ray
/// that misses the head) and its premultiplied colour and opacity logit (`[0, 0, 0,
/// MISS_LOGIT]` for a miss). The network:
///
/// ```text
/// reduce:    1x1 conv, width -> channels[0], relu
/// stage s:   3x3 conv, channels[s] -> 4 channels[s + 1], depth-to-space x2 (DCR), relu
/// head:      3x3 conv, channels[last] -> 4
/// output:    [c, l] = bilinear(colour, logit) + [sigmoid(bilinear(logit)) head_c, head_l]
///            ->  colour c, opacity sigmoid(l)
/// pixel:     c + (1 - opacity) background
/// ```
///
/// with `log2(factor)` stages, every 3x3 convolution zero-padded by 1 at the box's edge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UpsamplerConfig {
    /// Output pixels per coarse ray along each side: 2, 4 or 8 (the coarse grid is 1/2, 1/4
    /// or 1/8 of the output's side).
    pub factor: usize,
    /// Channels after the 1x1 reduction, then after each x2 stage (`log2(factor) + 1`
    /// values).
    pub channels: Vec<usize>,
    /// Coarse rays added around the head's hits on each side of the box the CNN runs on,
    /// so that its edge (zero padding) lies on background.
    pub margin: usize,
    /// The mouth's box in head space (`lo`, `hi`; the trainer clips it to the head's
    /// bounds, the check asks only for a finite box with `lo` below `hi`): every output
    /// pixel whose ray meets it (within `[near, far]`) is the student's own ray at full
    /// resolution, drawn over the upsampled frame, so that the mouth keeps native-ray
    /// detail. `nldf train upsampler` (or `nldf train mouth-patch` on a trained upsampler)
    /// fills it from the teacher's mouth surface points; absent: no patch.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mouth_patch: Option<Bounds>,
}

impl Default for UpsamplerConfig {
    fn default() -> Self {
        UpsamplerConfig {
            factor: 4,
            channels: vec![32, 16, 16],
            margin: 2,
            mouth_patch: None,
        }
    }
}

impl UpsamplerConfig {
    /// A default shape for `factor`: 32 channels after the reduction, 16 after each stage.
    pub fn with_factor(factor: usize) -> UpsamplerConfig {
        let stages = factor.max(1).trailing_zeros() as usize;
        let mut channels = vec![32];
        channels.extend(std::iter::repeat_n(16, stages));
        UpsamplerConfig {
            factor,
            channels,
            ..UpsamplerConfig::default()
        }
    }

    /// Number of x2 stages, `log2(factor)`.
    pub fn stages(&self) -> usize {
        self.factor.trailing_zeros() as usize
    }

    /// The CNN layer by layer over a student `width` wide: the one description that the
    /// candle builder (`nldf_train::upsampler`) and the ONNX builder (`nldf_export`'s
    /// upsampler graph) follow.
    pub fn layout(&self, width: usize) -> UpsamplerLayout {
        let c = &self.channels;
        let layer = |name: String, c_in: usize, c_out: usize, kernel: usize| Conv2dLayer {
            name,
            c_in,
            c_out,
            kernel,
        };
        let n = self.stages();
        UpsamplerLayout {
            reduce: layer("reduce".into(), width + 4, c[0], 1),
            stages: (0..n)
                .map(|s| layer(format!("stages.{s}"), c[s], 4 * c[s + 1], 3))
                .collect(),
            head: layer("head".into(), c[n], 4, 3),
        }
    }

    /// Checks the shape; `at` prefixes the keys (`model`).
    pub fn check(&self, at: &str) -> Result<()> {
        if !matches!(self.factor, 2 | 4 | 8) {
            return Err(Error::Argument(format!(
                "`{at}.factor` must be 2, 4 or 8, got {}",
                self.factor
            )));
        }
        if self.channels.len() != self.stages() + 1 {
            return Err(Error::Argument(format!(
                "`{at}.channels` must hold {} values for factor {} (after the reduction, then \
                 after each x2 stage), got {}",
                self.stages() + 1,
                self.factor,
                self.channels.len()
            )));
        }
        for (i, &c) in self.channels.iter().enumerate() {
            in_range(&format!("{at}.channels[{i}]"), c, 1, 256)?;
        }
        in_range(&format!("{at}.margin"), self.margin, 0, 64)?;
        if let Some(b) = &self.mouth_patch
            && !b.is_proper()
        {
            return Err(Error::Argument(format!(
                "`{at}.mouth_patch` must be a box with finite `lo` below `hi` on every \
                 axis, got lo {:?}, hi {:?}",
                b.lo.to_array(),
                b.hi.to_array()
            )));
        }
        Ok(())
    }

    /// Multiply-adds of the CNN per output pixel inside the box, for an input of `width`
    /// features (the reduction and each stage run on fewer pixels than the output).
    pub fn macs_per_pixel(&self, width: usize) -> f64 {
        let r2 = (self.factor * self.factor) as f64;
        let mut macs = (width * self.channels[0]) as f64 / r2;
        let mut side = self.factor;
        for s in 0..self.stages() {
            let pixels = 1.0 / (side * side) as f64;
            macs += pixels * (9 * self.channels[s] * 4 * self.channels[s + 1]) as f64;
            side /= 2;
        }
        macs + (9 * self.channels[self.stages()] * 4) as f64
    }
}

/// The kernel of bilinear upsampling by `r` (even) of `c` channels as a transposed
/// convolution of stride `r`, kernel `2 r` and padding `r / 2`, `[c, c, 2 r, 2 r]`: on each
/// channel's diagonal the outer product of `1 - |i - (2 r - 1) / 2| / r`, zero elsewhere.
/// Output pixel `x` then interpolates the inputs at `(x + 0.5) / r - 0.5` (zero beyond the
/// edges). The trainer and the exported graph both upsample with it.
pub fn bilinear_kernel(c: usize, r: usize) -> Vec<f32> {
    let k = 2 * r;
    let centre = (k - 1) as f32 / 2.0;
    let taps: Vec<f32> = (0..k)
        .map(|i| 1.0 - (i as f32 - centre).abs() / r as f32)
        .collect();
    let mut w = vec![0.0f32; c * c * k * k];
    for ch in 0..c {
        for (i, ti) in taps.iter().enumerate() {
            for (j, tj) in taps.iter().enumerate() {
                w[((ch * c + ch) * k + i) * k + j] = ti * tj;
            }
        }
    }
    w
}

/// The coarse grid's intrinsics for an output of intrinsics `k`: one ray per `factor x
/// factor` block, through the block's centre (pixel `r I + (r - 1) / 2` of the output in
/// AD-NeRF's integer pixel convention), so `f' = f / r` and `c' = (c - (r - 1) / 2) / r`.
/// The output's sides must be multiples of `factor`.
pub fn coarse_intrinsics(k: &Intrinsics, factor: usize) -> Result<Intrinsics> {
    let r = factor as u32;
    if factor == 0 || !k.width.is_multiple_of(r) || !k.height.is_multiple_of(r) {
        return Err(Error::Argument(format!(
            "an upsampler of factor {factor} needs image sides that are multiples of it, \
             the images are {} x {}",
            k.width, k.height
        )));
    }
    let half = (factor as f32 - 1.0) / 2.0;
    Ok(Intrinsics {
        focal: k.focal / factor as f32,
        cx: (k.cx - half) / factor as f32,
        cy: (k.cy - half) / factor as f32,
        width: k.width / r,
        height: k.height / r,
    })
}

/// The coarse box the CNN runs on, `(row0, row1, col0, col1)` (ends excluded): the rows and
/// columns holding a hit in `hits` (`[height, width]`, row-major), widened by `margin` on
/// each side within the grid. A grid without hits gives the 1 x 1 box at the origin (the
/// renderers then show the background alone).
pub fn coarse_box(hits: &[bool], width: usize, margin: usize) -> (usize, usize, usize, usize) {
    let height = hits.len() / width.max(1);
    let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
    for j in 0..height {
        for i in 0..width {
            if hits[j * width + i] {
                r0 = r0.min(j);
                r1 = r1.max(j + 1);
                c0 = c0.min(i);
                c1 = c1.max(i + 1);
            }
        }
    }
    if r1 == 0 {
        return (0, 1, 0, 1);
    }
    (
        r0.saturating_sub(margin),
        (r1 + margin).min(height),
        c0.saturating_sub(margin),
        (c1 + margin).min(width),
    )
}

/// Coarse cells on each side of an output pixel's own cell that the upsampler reads for it:
/// the head's 3x3 convolution at the output's resolution, each stage's 3x3 convolution at
/// its own (depth-to-space halves the offsets on the way down), and the bilinear base (the
/// two nearest cells). The CNN on a box cut `halo` cells beyond the pixels wanted gives
/// them exactly as the CNN on the whole box does (the zero padding at the smaller box's
/// edge does not reach them). x2: 2 cells, x4: 2, x8: 2.
pub fn receptive_halo(factor: usize) -> usize {
    let stages = factor.max(1).trailing_zeros();
    let mut halo = 1i64;
    for x in 0..factor.max(1) as i64 {
        // The head's taps at the output's resolution, then down through each stage.
        let (mut lo, mut hi) = (x - 1, x + 1);
        for _ in 0..stages {
            lo = lo.div_euclid(2) - 1;
            hi = hi.div_euclid(2) + 1;
        }
        halo = halo.max(-lo).max(hi);
    }
    halo as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_layout_follows_the_config() {
        let cfg = UpsamplerConfig::with_factor(8);
        let layout = cfg.layout(128);
        assert_eq!((layout.reduce.c_in, layout.reduce.kernel), (132, 1));
        assert_eq!(layout.stages.len(), 3);
        assert_eq!(layout.stages[2].name, "stages.2");
        assert_eq!(layout.stages[0].c_out, 4 * cfg.channels[1]);
        assert_eq!((layout.head.c_in, layout.head.c_out), (cfg.channels[3], 4));
        assert_eq!(layout.layers().len(), 5);
    }

    #[test]
    fn coarse_rays_pass_through_block_centres() {
        let k = Intrinsics {
            focal: 512.0,
            cx: 256.0,
            cy: 250.0,
            width: 512,
            height: 512,
        };
        let c = coarse_intrinsics(&k, 4).expect("multiple of 4");
        assert_eq!((c.width, c.height), (128, 128));
        for (ci, cj) in [(0.0f32, 0.0f32), (17.0, 93.0), (127.0, 127.0)] {
            let fine = k.camera_direction(4.0 * ci + 1.5, 4.0 * cj + 1.5);
            let coarse = c.camera_direction(ci, cj);
            assert!(
                (fine - coarse).abs().max_element() < 1e-6,
                "{fine} vs {coarse}"
            );
        }
        assert!(coarse_intrinsics(&k.resized(510, 512), 4).is_err());
    }

    #[test]
    fn box_holds_the_hits_and_margin() {
        let (w, h) = (10, 8);
        let mut hits = vec![false; w * h];
        assert_eq!(coarse_box(&hits, w, 2), (0, 1, 0, 1));
        hits[3 * w + 4] = true;
        hits[5 * w + 7] = true;
        assert_eq!(coarse_box(&hits, w, 0), (3, 6, 4, 8));
        assert_eq!(coarse_box(&hits, w, 2), (1, 8, 2, 10));
    }

    #[test]
    fn shapes_are_checked() {
        assert!(UpsamplerConfig::default().check("model").is_ok());
        assert!(UpsamplerConfig::with_factor(8).check("model").is_ok());
        let mut bad = UpsamplerConfig::with_factor(4);
        bad.factor = 3;
        assert!(bad.check("model").is_err());
        let mut bad = UpsamplerConfig::with_factor(4);
        bad.channels.pop();
        assert!(bad.check("model").is_err());
    }
}
