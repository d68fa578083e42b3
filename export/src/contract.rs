//! The ONNX contract of an exported student, defined once: the graph's input and output
//! names, element types and shapes, the symbolic ray axis, the IR and opset versions, and
//! the `metadata_props` keys that carry everything a foreign runtime needs to render a frame.
//! The exporter writes to it; nldf-infer, the tests and `examples/onnxruntime_render.py`
//! read by it.
//!
//! # Graph
//! - input [`INPUT_ORIGINS`] `rays_o`: f32 `[n_rays, 3]` ray origins (world space)
//! - input [`INPUT_DIRECTIONS`] `rays_d`: f32 `[n_rays, 3]` un-normalised ray directions
//!   (AD-NeRF's `get_rays`: a point at `t` is `o + t d`)
//! - input [`INPUT_AUDIO`] `audio`: f32 `[att_frames, window, n_features]`, the windows of
//!   the frame's neighbourhood (frames `f - att_frames/2 ..`, clamped at the ends of the
//!   track); without attention only the centre window (index `att_frames / 2`) is used
//! - output [`OUTPUT_RGB`] `rgb`: f32 `[n_rays, 3]`, the pixel colours (paper Eq. 7)
//! - output [`OUTPUT_SEGMENTS`] `segments`: f32 `[n_rays, M, 3]`, the M segment colours whose
//!   sum is `rgb`
//!
//! A model with opacity ([`keys::OPACITY`] `true`, contract 3) also has:
//! - input [`INPUT_BACKGROUND`] `background`: f32 `[n_rays, 3]`, the background image's
//!   colour at each ray's pixel
//! - output [`OUTPUT_OPACITY`] `opacity`: f32 `[n_rays, 1]`, how much of the ray the head
//!   covers, in (0, 1)
//!
//! and its `rgb` is `sum_i segments_i + (1 - opacity) * background`, composited in the
//! graph as the teacher composites; its segments then hold the head's colour alone.
//!
//! # Numerics
//! The graph encodes each beam point as `nldf_core::encoding` does: the sine and cosine of
//! the lowest octave in double precision, the higher octaves by the double-angle identities
//! in double precision, each value rounded to f32 once. Every encoded value lies within
//! `nldf_core::encoding::MAX_ENCODING_ERROR` (1e-7) of the exact `sin(2^l x)` / `cos(2^l x)`
//! for every coordinate `|x| <= max_coord`, so the trainer's beams and any runtime's agree
//! to f32 rounding.
//!
//! # Metadata
//! Every value under [`keys`] is JSON (numbers, arrays, objects, `true`/`false`), except
//! [`keys::FORMAT`], [`keys::AUDIO_FRONT_END`], [`keys::BACKGROUND_FILE`],
//! [`keys::WEIGHTS_CHECKSUM`] and [`keys::BACKGROUND_PNG`] (base64 of an 8-bit RGB PNG the
//! size of the image), which are plain strings. Rays that miss the head's bounds (within
//! `[near, far]`) take the background pixel instead of the network's colour.

use std::collections::HashMap;

use base64::Engine;
use nldf_core::audio::FeatureSource;
use nldf_core::beam::BeamSpec;
use nldf_core::encoding::MAX_COORD;
use nldf_core::frame_audio::FrameAudio;
use nldf_core::render_spec::RenderSpec;
use serde::{Deserialize, Serialize};

use crate::onnx::{GraphProto, StringStringEntryProto};

/// ONNX IR version written (onnxruntime 1.31 reads up to 13, tract reads 9).
pub const IR_VERSION: i64 = 9;
/// Version of the default ONNX operator set the graph binds to.
pub const OPSET: i64 = 17;
/// `ModelProto.producer_name`.
pub const PRODUCER: &str = "nldf";
/// Name of the graph.
pub const GRAPH_NAME: &str = "nldf_student";
/// Symbolic name of the ray axis of the inputs and outputs.
pub const RAY_AXIS: &str = "n_rays";

/// Ray origins, f32 `[n_rays, 3]`.
pub const INPUT_ORIGINS: &str = "rays_o";
/// Ray directions, f32 `[n_rays, 3]`.
pub const INPUT_DIRECTIONS: &str = "rays_d";
/// The frame's audio neighbourhood, f32 `[att_frames, window, n_features]`.
pub const INPUT_AUDIO: &str = "audio";
/// Pixel colours, f32 `[n_rays, 3]`.
pub const OUTPUT_RGB: &str = "rgb";
/// Segment colours, f32 `[n_rays, M, 3]`.
pub const OUTPUT_SEGMENTS: &str = "segments";
/// The background colour behind each ray, f32 `[n_rays, 3]` (models with opacity).
pub const INPUT_BACKGROUND: &str = "background";
/// How much of each ray the head covers, f32 `[n_rays, 1]` (models with opacity).
pub const OUTPUT_OPACITY: &str = "opacity";

/// The coarse box of an upsampled ray graph, bool `[box_rows, box_cols]`, row-major: true
/// where a coarse ray is given (the given rays are its true cells in row-major order).
pub const INPUT_CELLS: &str = "cells";
/// An upsampled ray graph's pixels of the box, f32 `[box_rows r, box_cols r, 3]`, the
/// background composited in.
pub const OUTPUT_BOX_RGB: &str = "box_rgb";
/// How much of each of the box's pixels the head covers, f32 `[box_rows r, box_cols r, 1]`.
pub const OUTPUT_BOX_OPACITY: &str = "box_opacity";
/// Symbolic names of an upsampled ray graph's box axes: coarse rows and columns, then
/// output pixel rows and columns (`r` times as many).
pub const BOX_ROWS: &str = "box_rows";
pub const BOX_COLS: &str = "box_cols";
pub const BOX_HEIGHT: &str = "box_height";
pub const BOX_WIDTH: &str = "box_width";

/// The graph's input names in the order the exporter writes them: the background last,
/// for a model with opacity.
pub fn input_names(opacity: bool) -> Vec<&'static str> {
    let mut names = vec![INPUT_ORIGINS, INPUT_DIRECTIONS, INPUT_AUDIO];
    if opacity {
        names.push(INPUT_BACKGROUND);
    }
    names
}

/// The graph's output names in the order the exporter writes them.
pub fn output_names(opacity: bool) -> Vec<&'static str> {
    let mut names = vec![OUTPUT_RGB, OUTPUT_SEGMENTS];
    if opacity {
        names.push(OUTPUT_OPACITY);
    }
    names
}

/// The input names of the model `info` describes, in the order the exporter writes them:
/// [`input_names`], with [`INPUT_CELLS`] before the background for an upsampled ray graph.
pub fn model_input_names(info: &ModelInfo) -> Vec<&'static str> {
    if info.upsample.is_some() {
        vec![
            INPUT_ORIGINS,
            INPUT_DIRECTIONS,
            INPUT_AUDIO,
            INPUT_CELLS,
            INPUT_BACKGROUND,
        ]
    } else {
        input_names(info.opacity)
    }
}

/// The output names of the model `info` describes, in the order the exporter writes them:
/// [`output_names`], or for an upsampled ray graph [`OUTPUT_BOX_RGB`], [`OUTPUT_SEGMENTS`]
/// and [`OUTPUT_BOX_OPACITY`].
pub fn model_output_names(info: &ModelInfo) -> Vec<&'static str> {
    if info.upsample.is_some() {
        vec![OUTPUT_BOX_RGB, OUTPUT_SEGMENTS, OUTPUT_BOX_OPACITY]
    } else {
        output_names(info.opacity)
    }
}

/// Value of [`keys::FORMAT`] that marks a model as an nldf student.
pub const FORMAT: &str = "nldf-student";

/// Value of [`keys::FORMAT`] that marks a frame graph (`nldf export --frame`): the same
/// student and metadata, with the rays, the head-bounds test, the audio front end and the
/// compositing inside the graph. Its inputs are [`FRAME_INPUT_AUDIO`],
/// [`FRAME_INPUT_POSE`] and [`FRAME_INPUT_KEEP`], its outputs [`FRAME_OUTPUT_IMAGE`],
/// [`FRAME_OUTPUT_WINDOWS`] and [`FRAME_OUTPUT_RAYS`]; [`keys::FRAME_AUDIO`] says which
/// samples the audio input holds.
pub const FRAME_FORMAT: &str = "nldf-frame";
/// The frame's audio, f32 `[samples]` at 16 kHz (`nldf_core::frame_audio::FrameAudio`):
/// NaN where the span lies outside the track.
pub const FRAME_INPUT_AUDIO: &str = "audio";
/// The camera-to-world matrix, f32 `[4, 4]`, row-major (OpenGL axes, as
/// [`keys::DEFAULT_POSE`]).
pub const FRAME_INPUT_POSE: &str = "pose";
/// The pixels to render, bool `[height, width]`, row-major: a ray goes through the student
/// only where it meets the head and its pixel is kept; every other pixel shows the
/// background. All true renders the whole frame; a caller that keeps a frame's other pixels
/// from an earlier one (skipping still pixels) marks only those it wants.
pub const FRAME_INPUT_KEEP: &str = "keep";
/// The frame, f32 `[height, width, 3]` in [0, 1], the background composited in.
pub const FRAME_OUTPUT_IMAGE: &str = "image";
/// The audio windows the graph's front end made, f32 `[att_frames, window, n_features]`
/// (what the ray graph's `audio` input takes), for checking a front end against nldf's.
pub const FRAME_OUTPUT_WINDOWS: &str = "audio_windows";
/// How many rays went through the student (met the head and were kept), int64 `[1]`.
pub const FRAME_OUTPUT_RAYS: &str = "n_rays";
/// Version of this contract, [`keys::CONTRACT`]: bumped when names, shapes or keys change
/// (2: the audio front end is recorded, [`keys::AUDIO_FRONT_END`]; 3: [`keys::OPACITY`],
/// with the background input and opacity output of a model that has one; 4:
/// [`keys::BEAM_ANCHOR`], the graph anchoring rays before sampling them; 5: [`keys::UPSAMPLE`],
/// the upsampled ray graph, written only for one). Contract 2 and 3 models are still read:
/// they have no anchor, and contract 2 no opacity.
pub const CONTRACT_VERSION: u32 = 5;
/// The contract a ray graph without an upsampler is written with: it reads as it did
/// before contract 5.
pub const CONTRACT_PLAIN: u32 = 4;

/// `metadata_props` keys.
pub mod keys {
    /// [`super::FORMAT`]: what the model is (plain string). Written first.
    pub const FORMAT: &str = "nldf.format";
    /// [`super::CONTRACT_VERSION`].
    pub const CONTRACT: &str = "nldf.contract";
    /// Image width and height in pixels.
    pub const IMAGE_WIDTH: &str = "nldf.image_width";
    pub const IMAGE_HEIGHT: &str = "nldf.image_height";
    /// Focal length and principal point in pixels (AD-NeRF's `focal_len`, `cx`, `cy`).
    pub const FOCAL: &str = "nldf.focal";
    pub const CX: &str = "nldf.cx";
    pub const CY: &str = "nldf.cy";
    /// Beam range along each ray.
    pub const NEAR: &str = "nldf.near";
    pub const FAR: &str = "nldf.far";
    /// Video frame rate the audio windows follow.
    pub const FPS: &str = "nldf.fps";
    /// Beam points K and positional-encoding frequencies L.
    pub const BEAM_POINTS: &str = "nldf.beam_points";
    pub const BEAM_FREQS: &str = "nldf.beam_freqs";
    /// Where the graph anchors each ray before sampling its beam (JSON `null`, or
    /// `{"centre": [x, y, z], "distance": d}`; see `nldf_core::beam::BeamAnchor`): for
    /// reading only, the graph applies it itself. Contract 4.
    pub const BEAM_ANCHOR: &str = "nldf.beam_anchor";
    /// Coordinates are clamped to ± this before the encoding.
    pub const MAX_COORD: &str = "nldf.max_coord";
    /// Segments per ray, M.
    pub const SEGMENTS: &str = "nldf.segments";
    /// The audio input's `[att_frames, window, n_features]`.
    pub const AUDIO_ATT_FRAMES: &str = "nldf.audio_att_frames";
    pub const AUDIO_WINDOW: &str = "nldf.audio_window";
    pub const AUDIO_FEATURES: &str = "nldf.audio_features";
    /// Whether the neighbourhood is fused by attention (else only the centre window counts).
    pub const AUDIO_ATTENTION: &str = "nldf.audio_attention";
    /// Which front end made the training features (plain string): `nldf` (the render spec's
    /// `features` hold its settings, and any WAV can be turned into the same features) or
    /// `foreign` (another front end's, e.g. AD-NeRF's DeepSpeech: a render must be given
    /// features made the same way).
    pub const AUDIO_FRONT_END: &str = "nldf.audio_front_end";
    /// The head's bounds, `[x, y, z]` each.
    pub const BOUNDS_LO: &str = "nldf.bounds_lo";
    pub const BOUNDS_HI: &str = "nldf.bounds_hi";
    /// Camera-to-world matrix to render from by default, 4 rows of 4 (OpenGL axes).
    pub const DEFAULT_POSE: &str = "nldf.default_pose";
    /// Training step of the exported weights.
    pub const STEP: &str = "nldf.step";
    /// Network shape: `{"depth", "width", "audio_dim"}`.
    pub const NETWORK: &str = "nldf.network";
    /// The whole render spec (`render.json`) as JSON.
    pub const RENDER_SPEC: &str = "nldf.render_spec";
    /// The background's original file name (plain string).
    pub const BACKGROUND_FILE: &str = "nldf.background_file";
    /// FNV-1a 64 of the initializers' names and bytes, 16 hex digits (plain string): see
    /// [`super::weights_checksum`].
    pub const WEIGHTS_CHECKSUM: &str = "nldf.weights_checksum";
    /// Whether the graph predicts opacity and composites over its `background` input
    /// (JSON `true` / `false`; contract 3).
    pub const OPACITY: &str = "nldf.opacity";
    /// A frame graph's audio input (`nldf_core::frame_audio::FrameAudio` as JSON):
    /// frame `f` takes the `samples` samples from `f * samples_per_frame + offset` of the
    /// 16 kHz track, NaN where they lie outside it.
    pub const FRAME_AUDIO: &str = "nldf.frame_audio";
    /// A frame graph's learned upsampler: output pixels per coarse ray along each side
    /// (plain integer; absent or 1 without one). Its `keep` input is then the coarse grid's,
    /// `[height / factor, width / factor]`.
    pub const FRAME_UPSAMPLE: &str = "nldf.frame_upsample";
    /// A ray graph's learned upsampler (`super::UpsampleInfo` as JSON, `{"factor",
    /// "margin"}`; contract 5): the graph takes the coarse rays of a box of the coarse
    /// grid and gives the box's pixels ([`super::INPUT_CELLS`], [`super::OUTPUT_BOX_RGB`]).
    pub const UPSAMPLE: &str = "nldf.upsample";
    /// The background as base64 of an 8-bit RGB PNG (plain string). Written last.
    pub const BACKGROUND_PNG: &str = "nldf.background_png";
}

/// Shape of the audio input and how the graph uses it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct AudioInput {
    /// Neighbouring frames given per rendered frame.
    pub att_frames: usize,
    /// Feature frames per window (AD-NeRF: 16).
    pub window: usize,
    /// Features per feature frame, F.
    pub n_features: usize,
    /// Fuse the neighbourhood with attention; without, only window `att_frames / 2` counts.
    pub attention: bool,
}

impl AudioInput {
    /// The input's shape, `[att_frames, window, n_features]`.
    pub fn shape(&self) -> [usize; 3] {
        [self.att_frames, self.window, self.n_features]
    }

    /// Values in one neighbourhood.
    pub fn len(&self) -> usize {
        self.att_frames * self.window * self.n_features
    }

    /// True when the input holds no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Sizes of the network, for reports and checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct NetworkShape {
    /// Linear layers of the residual MLP.
    pub depth: usize,
    /// Hidden width.
    pub width: usize,
    /// Width of the audio code.
    pub audio_dim: usize,
}

/// Everything an exported model's metadata says: what a runtime needs besides the graph.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelInfo {
    /// Camera, range, bounds, background name, audio features, default pose.
    pub spec: RenderSpec,
    /// Beam points K and frequencies L.
    pub beam: BeamSpec,
    /// Segments per ray, M.
    pub segments: usize,
    /// The graph predicts opacity and composites over its background input.
    pub opacity: bool,
    /// The audio input.
    pub audio: AudioInput,
    /// The network's sizes.
    pub network: NetworkShape,
    /// Training step of the weights.
    pub step: u64,
    /// [`weights_checksum`] of the graph.
    pub weights_checksum: u64,
    /// The background image, an 8-bit RGB PNG of the image's size.
    pub background_png: Vec<u8>,
    /// The learned upsampler of an upsampled ray graph (none for a plain one or a frame
    /// graph, whose upsampler is [`keys::FRAME_UPSAMPLE`]).
    pub upsample: Option<UpsampleInfo>,
}

/// What a renderer needs to know of an upsampled ray graph's upsampler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct UpsampleInfo {
    /// Output pixels per coarse ray along each side: 2, 4 or 8. The coarse grid's rays pass
    /// through the centres of the output's `factor x factor` blocks
    /// (`nldf_core::upsampler_config::coarse_intrinsics`).
    pub factor: usize,
    /// Coarse rays added around the hits on each side of the box
    /// (`nldf_core::upsampler_config::coarse_box`).
    pub margin: usize,
}

impl UpsampleInfo {
    /// Largest margin read back.
    pub const MAX_MARGIN: usize = 64;
}

fn json<T: Serialize + ?Sized>(v: &T) -> String {
    // Plain numbers, arrays and derived structs always serialise.
    serde_json::to_string(v).unwrap_or_default()
}

impl ModelInfo {
    /// The metadata entries, in the order they are written ([`keys::FORMAT`] first, the
    /// background last, so that a file cut short loses a required key).
    pub fn to_metadata(&self) -> Vec<StringStringEntryProto> {
        let s = &self.spec;
        let k = &s.intrinsics;
        let entries: Vec<(&str, String)> = vec![
            (keys::FORMAT, FORMAT.to_string()),
            (
                keys::CONTRACT,
                json(&match self.upsample {
                    Some(_) => CONTRACT_VERSION,
                    None => CONTRACT_PLAIN,
                }),
            ),
            (keys::IMAGE_WIDTH, json(&k.width)),
            (keys::IMAGE_HEIGHT, json(&k.height)),
            (keys::FOCAL, json(&k.focal)),
            (keys::CX, json(&k.cx)),
            (keys::CY, json(&k.cy)),
            (keys::NEAR, json(&s.near)),
            (keys::FAR, json(&s.far)),
            (keys::FPS, json(&s.fps)),
            (keys::BEAM_POINTS, json(&self.beam.n_points)),
            (keys::BEAM_FREQS, json(&self.beam.n_freqs)),
            (keys::BEAM_ANCHOR, json(&self.beam.anchor)),
            (keys::MAX_COORD, json(&MAX_COORD)),
            (keys::SEGMENTS, json(&self.segments)),
            (keys::OPACITY, json(&self.opacity)),
            (keys::AUDIO_ATT_FRAMES, json(&self.audio.att_frames)),
            (keys::AUDIO_WINDOW, json(&self.audio.window)),
            (keys::AUDIO_FEATURES, json(&self.audio.n_features)),
            (keys::AUDIO_ATTENTION, json(&self.audio.attention)),
            (keys::AUDIO_FRONT_END, front_end(&s.features).to_string()),
            (keys::BOUNDS_LO, json(&s.bounds.lo.to_array())),
            (keys::BOUNDS_HI, json(&s.bounds.hi.to_array())),
            (keys::DEFAULT_POSE, json(&s.default_pose)),
            (keys::STEP, json(&self.step)),
            (keys::NETWORK, json(&self.network)),
            (keys::RENDER_SPEC, json(s)),
            (keys::BACKGROUND_FILE, s.background.clone()),
        ];
        let mut entries = entries;
        if let Some(up) = &self.upsample {
            entries.push((keys::UPSAMPLE, json(up)));
        }
        entries.extend([
            (
                keys::WEIGHTS_CHECKSUM,
                format!("{:016x}", self.weights_checksum),
            ),
            (
                keys::BACKGROUND_PNG,
                base64::engine::general_purpose::STANDARD.encode(&self.background_png),
            ),
        ]);
        entries
            .into_iter()
            .map(|(key, value)| StringStringEntryProto {
                key: Some(key.to_string()),
                value: Some(value),
            })
            .collect()
    }

    /// The metadata entries of the frame graph of this model whose audio input is `audio`:
    /// [`ModelInfo::to_metadata`]'s, marked [`FRAME_FORMAT`], with [`keys::FRAME_AUDIO`]
    /// before the background.
    pub fn to_frame_metadata(&self, audio: &FrameAudio) -> Vec<StringStringEntryProto> {
        let mut entries = self.to_metadata();
        for e in &mut entries {
            if e.key.as_deref() == Some(keys::FORMAT) {
                e.value = Some(FRAME_FORMAT.to_string());
            }
        }
        let at = entries.len().saturating_sub(1);
        entries.insert(
            at,
            StringStringEntryProto {
                key: Some(keys::FRAME_AUDIO.to_string()),
                value: Some(json(audio)),
            },
        );
        entries
    }

    /// Reads a frame graph's metadata back: the model's and its audio input's.
    pub fn from_frame_metadata(
        props: &[StringStringEntryProto],
    ) -> Result<(ModelInfo, FrameAudio), MetadataError> {
        let info = Self::parse_metadata(props, FRAME_FORMAT)?;
        let text = props
            .iter()
            .find(|p| p.key.as_deref() == Some(keys::FRAME_AUDIO))
            .and_then(|p| p.value.as_deref())
            .ok_or_else(|| MetadataError::Missing(keys::FRAME_AUDIO.to_string()))?;
        let audio: FrameAudio = serde_json::from_str(text)
            .map_err(|e| MetadataError::Malformed(keys::FRAME_AUDIO.to_string(), e.to_string()))?;
        Ok((info, audio))
    }

    /// Reads the metadata back; the error says which key is missing or malformed.
    pub fn from_metadata(props: &[StringStringEntryProto]) -> Result<ModelInfo, MetadataError> {
        Self::parse_metadata(props, FORMAT)
    }

    fn parse_metadata(
        props: &[StringStringEntryProto],
        format: &str,
    ) -> Result<ModelInfo, MetadataError> {
        let map: HashMap<&str, &str> = props
            .iter()
            .map(|p| {
                (
                    p.key.as_deref().unwrap_or_default(),
                    p.value.as_deref().unwrap_or_default(),
                )
            })
            .collect();
        match map.get(keys::FORMAT) {
            Some(&f) if f == format => {}
            Some(&FRAME_FORMAT) => {
                return Err(MetadataError::WrongKind(
                    "it is a frame graph (`nldf export --frame`), for runtimes other than \
                     nldf's: nldf renders with the ray graph, exported without --frame"
                        .into(),
                ));
            }
            Some(&FORMAT) => {
                return Err(MetadataError::WrongKind(
                    "it is a ray graph, not a frame graph: export it with `--frame`".into(),
                ));
            }
            Some(other) => {
                return Err(MetadataError::Foreign(format!(
                    "`{}` is `{other}`",
                    keys::FORMAT
                )));
            }
            None => {
                return Err(MetadataError::Foreign(format!(
                    "no `{}` metadata",
                    keys::FORMAT
                )));
            }
        }
        let get = |key: &str| {
            map.get(key)
                .copied()
                .ok_or_else(|| MetadataError::Missing(key.to_string()))
        };
        fn parse<T: serde::de::DeserializeOwned>(key: &str, v: &str) -> Result<T, MetadataError> {
            serde_json::from_str(v)
                .map_err(|e| MetadataError::Malformed(key.to_string(), e.to_string()))
        }
        let value = |key: &str| -> Result<usize, MetadataError> { parse(key, get(key)?) };
        let contract: u32 = parse(keys::CONTRACT, get(keys::CONTRACT)?)?;
        if !(2..=CONTRACT_VERSION).contains(&contract) {
            return Err(MetadataError::Malformed(
                keys::CONTRACT.to_string(),
                format!("contract version {contract}, this build reads 2 to {CONTRACT_VERSION}"),
            ));
        }
        let spec: RenderSpec = parse(keys::RENDER_SPEC, get(keys::RENDER_SPEC)?)?;
        spec.check()
            .map_err(|e| MetadataError::Malformed(keys::RENDER_SPEC.to_string(), e))?;
        let background_png = base64::engine::general_purpose::STANDARD
            .decode(get(keys::BACKGROUND_PNG)?)
            .map_err(|e| {
                MetadataError::Malformed(keys::BACKGROUND_PNG.to_string(), e.to_string())
            })?;
        let checksum = get(keys::WEIGHTS_CHECKSUM)?;
        let weights_checksum = u64::from_str_radix(checksum, 16).map_err(|e| {
            MetadataError::Malformed(keys::WEIGHTS_CHECKSUM.to_string(), e.to_string())
        })?;
        let info = ModelInfo {
            weights_checksum,
            beam: BeamSpec {
                n_points: value(keys::BEAM_POINTS)?,
                n_freqs: value(keys::BEAM_FREQS)?,
                // Contracts 2 and 3 predate anchoring.
                anchor: if contract >= 4 {
                    parse(keys::BEAM_ANCHOR, get(keys::BEAM_ANCHOR)?)?
                } else {
                    None
                },
            },
            segments: value(keys::SEGMENTS)?,
            // Contract 2 predates opacity.
            opacity: contract >= 3 && parse(keys::OPACITY, get(keys::OPACITY)?)?,
            audio: AudioInput {
                att_frames: value(keys::AUDIO_ATT_FRAMES)?,
                window: value(keys::AUDIO_WINDOW)?,
                n_features: value(keys::AUDIO_FEATURES)?,
                attention: parse(keys::AUDIO_ATTENTION, get(keys::AUDIO_ATTENTION)?)?,
            },
            network: parse(keys::NETWORK, get(keys::NETWORK)?)?,
            step: parse(keys::STEP, get(keys::STEP)?)?,
            spec,
            background_png,
            upsample: match map.get(keys::UPSAMPLE) {
                Some(v) if format == FORMAT => {
                    let up: UpsampleInfo = parse(keys::UPSAMPLE, v)?;
                    if !matches!(up.factor, 2 | 4 | 8) || up.margin > UpsampleInfo::MAX_MARGIN {
                        return Err(MetadataError::Malformed(
                            keys::UPSAMPLE.to_string(),
                            format!(
                                "factor {} and margin {}: the factor must be 2, 4 or 8 and \
                                 the margin at most {}",
                                up.factor,
                                up.margin,
                                UpsampleInfo::MAX_MARGIN
                            ),
                        ));
                    }
                    Some(up)
                }
                _ if contract >= 5 && format == FORMAT => {
                    return Err(MetadataError::Missing(keys::UPSAMPLE.to_string()));
                }
                _ => None,
            },
        };
        // The flat keys are what foreign runtimes read: they must say what the spec says.
        let k = &info.spec.intrinsics;
        let flat: [(&str, f64); 8] = [
            (keys::IMAGE_WIDTH, k.width.into()),
            (keys::IMAGE_HEIGHT, k.height.into()),
            (keys::FOCAL, k.focal.into()),
            (keys::CX, k.cx.into()),
            (keys::CY, k.cy.into()),
            (keys::NEAR, info.spec.near.into()),
            (keys::FAR, info.spec.far.into()),
            (keys::AUDIO_ATT_FRAMES, info.spec.att_frames as f64),
        ];
        for (key, expected) in flat {
            // Compared in f32, the precision both were written with.
            let got: f32 = parse(key, get(key)?)?;
            if got != expected as f32 {
                return Err(MetadataError::Malformed(
                    key.to_string(),
                    format!("says {got}, the render spec says {expected}"),
                ));
            }
        }
        let said = get(keys::AUDIO_FRONT_END)?;
        if said != front_end(&info.spec.features) {
            return Err(MetadataError::Malformed(
                keys::AUDIO_FRONT_END.to_string(),
                format!(
                    "says `{said}`, the render spec's features are {}",
                    info.spec.features.describe()
                ),
            ));
        }
        let f = &info.spec.features;
        if (f.window(), f.n_features()) != (info.audio.window, info.audio.n_features) {
            return Err(MetadataError::Malformed(
                keys::RENDER_SPEC.to_string(),
                format!(
                    "its features make {} x {} windows, the audio input takes {} x {}",
                    f.window(),
                    f.n_features(),
                    info.audio.window,
                    info.audio.n_features
                ),
            ));
        }
        if info.beam.n_points < 2 || info.segments == 0 || info.audio.is_empty() {
            return Err(MetadataError::Malformed(
                keys::BEAM_POINTS.to_string(),
                "needs K >= 2, M >= 1 and a non-empty audio input".into(),
            ));
        }
        Ok(info)
    }
}

/// The [`keys::AUDIO_FRONT_END`] value of a feature source.
pub fn front_end(features: &FeatureSource) -> &'static str {
    match features {
        FeatureSource::Nldf(_) => "nldf",
        FeatureSource::Foreign { .. } => "foreign",
    }
}

/// FNV-1a (64-bit) over every initializer's name, a zero byte and its `raw_data`, in graph
/// order: a flipped weight byte, which still decodes, changes it.
pub fn weights_checksum(graph: &GraphProto) -> u64 {
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for t in &graph.initializer {
        let name = t.name.as_deref().unwrap_or_default().as_bytes();
        let raw = t.raw_data.as_deref().unwrap_or_default();
        for &b in name.iter().chain(&[0u8]).chain(raw) {
            h = (h ^ b as u64).wrapping_mul(PRIME);
        }
    }
    h
}

/// What is wrong with a model's metadata.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetadataError {
    /// The model is not an nldf student (another exporter's model).
    #[error("{0}")]
    Foreign(String),
    /// The model is nldf's, but of the other kind (frame graph or ray graph).
    #[error("{0}")]
    WrongKind(String),
    /// A required key is absent.
    #[error("metadata lacks `{0}`")]
    Missing(String),
    /// A key's value does not parse or disagrees with the rest.
    #[error("metadata `{0}`: {1}")]
    Malformed(String, String),
}
