//! The teacher's shape (`model` in the teacher's `config.json`): its network, sampling and
//! encoding, read by the networks that build it and by the trainer, which saves it beside
//! every checkpoint.

use serde::{Deserialize, Serialize};

use nldf_core::student_config::AudioConfig;

/// The audio-conditioned NeRF teacher: network shape and sampling.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TeacherConfig {
    pub audio: AudioConfig,
    /// Hidden layers of the density trunk (AD-NeRF: 8).
    pub depth: usize,
    /// Width of the density trunk (AD-NeRF: 256).
    pub width: usize,
    /// Trunk layers after which the input is fed in again (AD-NeRF: [4]).
    pub skips: Vec<usize>,
    /// Width of the colour head (AD-NeRF: 128).
    pub color_width: usize,
    /// Positional-encoding frequencies of points (AD-NeRF: 10).
    pub pos_freqs: usize,
    /// Positional-encoding frequencies of view directions (AD-NeRF: 4).
    pub dir_freqs: usize,
    /// Stratified samples per ray inside the head's bounds (AD-NeRF: 64 over [near, far]).
    pub n_samples: usize,
    /// Importance samples per ray drawn from the coarse weights and evaluated by the same
    /// network (AD-NeRF: 128 with a second, fine network; 0 = none).
    pub n_importance: usize,
    /// Transmittance below which a ray stops being sampled when rendering.
    pub min_transmittance: f32,
    /// The grid teacher: points encoded by a multiresolution hash grid instead of
    /// frequencies (`pos_freqs` is then unused). None: AD-NeRF's positional encoding.
    pub grid: Option<crate::networks::hash_grid::GridConfig>,
    /// The grid teacher's occupancy grid: samples only the cells where the field has
    /// density, kept up to date while training. None: every sample inside the bounds.
    pub occupancy: Option<crate::networks::occupancy::OccupancyConfig>,
}

impl Default for TeacherConfig {
    fn default() -> Self {
        TeacherConfig::small()
    }
}

impl TeacherConfig {
    /// AD-NeRF's head NeRF: 8 x 256 with a skip at layer 4, 10 / 4 frequencies, 64 samples
    /// plus 128 importance samples (AD-NeRF uses a separate fine network; nldf reuses one).
    pub fn ad_nerf() -> TeacherConfig {
        TeacherConfig {
            audio: AudioConfig::default(),
            depth: 8,
            width: 256,
            skips: vec![4],
            color_width: 128,
            pos_freqs: 10,
            dir_freqs: 4,
            n_samples: 64,
            n_importance: 128,
            min_transmittance: 1e-4,
            grid: None,
            occupancy: None,
        }
    }

    /// A preset for 2-core machines: 6 x 128 with a skip at 3 (a JAX probe on a comparable
    /// synthetic head used 6 x 128), 32 samples inside the head's bounds, no importance
    /// samples.
    pub fn small() -> TeacherConfig {
        TeacherConfig {
            depth: 6,
            width: 128,
            skips: vec![3],
            color_width: 64,
            n_samples: 32,
            n_importance: 0,
            ..TeacherConfig::ad_nerf()
        }
    }

    /// A tiny network for tests (3 x 32; seconds per hundred steps).
    pub fn tiny() -> TeacherConfig {
        TeacherConfig {
            audio: AudioConfig {
                dim: 8,
                ..AudioConfig::default()
            },
            depth: 3,
            width: 32,
            skips: vec![1],
            color_width: 16,
            pos_freqs: 6,
            dir_freqs: 2,
            n_samples: 16,
            n_importance: 0,
            ..TeacherConfig::ad_nerf()
        }
    }

    /// Multiply-adds of the network per sample, counted as AD-NeRF computes it (the audio
    /// code and view direction concatenated to every sample's input).
    pub fn macs_per_sample(&self) -> usize {
        let (w, input) = (self.width, self.pos_dim() + self.audio.dim);
        let mut macs = 0;
        for i in 0..self.depth {
            if i > 0 {
                macs += w * w;
            }
            if i == 0 || self.skips.contains(&(i - 1)) {
                macs += input * w;
            }
        }
        macs + w + w * w + (w + self.dir_dim()) * self.color_width + self.color_width * 3
    }

    /// Network evaluations per ray: the stratified samples, plus, with importance
    /// sampling, the fine pass over all samples (AD-NeRF: 64 coarse + 192 fine).
    pub fn evaluations_per_ray(&self) -> usize {
        if self.n_importance == 0 {
            self.n_samples
        } else {
            2 * self.n_samples + self.n_importance
        }
    }

    /// Multiply-adds per rendered ray.
    pub fn macs_per_ray(&self) -> usize {
        self.macs_per_sample() * self.evaluations_per_ray()
    }

    /// Width of the encoded point: `3 (1 + 2 L)` frequencies, or the grid's `L F`.
    pub fn pos_dim(&self) -> usize {
        match &self.grid {
            Some(g) if g.region_attention => g.dim() + self.audio.dim,
            Some(g) => g.dim(),
            None => 3 * (1 + 2 * self.pos_freqs),
        }
    }

    /// The grid teacher for 2-core machines: a hash grid (16 levels of 2 features, tables
    /// of 2^15, 16 to 512 cells across the head's box) under a 2 x 64 network with a colour
    /// head of 64, the audio code entering the first layer; 32 samples inside the head's
    /// bounds.
    pub fn grid() -> TeacherConfig {
        TeacherConfig {
            depth: 2,
            width: 64,
            skips: vec![],
            color_width: 64,
            grid: Some(crate::networks::hash_grid::GridConfig::default()),
            ..TeacherConfig::small()
        }
    }

    /// What the teacher is called in tables: `teacher` (frequencies) or `grid teacher`.
    pub fn kind_name(&self) -> &'static str {
        if self.grid.is_some() {
            "grid teacher"
        } else {
            "teacher"
        }
    }

    /// Width of the encoded view direction.
    pub fn dir_dim(&self) -> usize {
        3 * (1 + 2 * self.dir_freqs)
    }

    /// The field's dense layers, each by name and shape, in the order the builder creates
    /// them: per trunk layer `i`, `trunk.{i}.hidden` (after the first), then where the input
    /// is fed in (the first layer and after each skip) `trunk.{i}.points` (biased on the
    /// first layer only) and `trunk.{i}.audio` (per ray); then `density`, `feature`,
    /// `color_feature`, `color_dir` (per ray) and `rgb`. The one description that the candle
    /// builder (`networks::field::teacher_field`) and the step benchmarks' FLOP count follow.
    pub fn field_layers(&self) -> Vec<FieldLayer> {
        let (w, p, a, c) = (self.width, self.pos_dim(), self.audio.dim, self.color_width);
        let layer = |name: String, fan_in, fan_out, bias, per_ray| FieldLayer {
            name,
            fan_in,
            fan_out,
            bias,
            per_ray,
        };
        let mut layers = Vec::new();
        for i in 0..self.depth {
            if i > 0 {
                layers.push(layer(format!("trunk.{i}.hidden"), w, w, true, false));
            }
            if i == 0 || self.skips.contains(&(i - 1)) {
                layers.push(layer(format!("trunk.{i}.points"), p, w, i == 0, false));
                layers.push(layer(format!("trunk.{i}.audio"), a, w, false, true));
            }
        }
        layers.extend([
            layer("density".into(), w, 1, true, false),
            layer("feature".into(), w, w, true, false),
            layer("color_feature".into(), w, c, true, false),
            layer("color_dir".into(), self.dir_dim(), c, false, true),
            layer("rgb".into(), c, 3, true, false),
        ]);
        layers
    }
}

/// One dense layer of the teacher's field ([`TeacherConfig::field_layers`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldLayer {
    /// Its name among the field's weights (`trunk.0.points`, `density`).
    pub name: String,
    pub fan_in: usize,
    pub fan_out: usize,
    pub bias: bool,
    /// Computed once per ray and broadcast over its samples (the audio code's and the view
    /// direction's terms), not per sample.
    pub per_ray: bool,
}
