//! What an exported model's metadata says ([`ModelInfo`]) and how it is written.

use base64::Engine;
use nldf_core::audio::FeatureSource;
use nldf_core::beam::BeamSpec;
use nldf_core::bounds::Bounds;
use nldf_core::encoding::MAX_COORD;
use nldf_core::frame_audio::FrameAudio;
use nldf_core::render_spec::RenderSpec;
use serde::{Deserialize, Serialize};

use super::keys;
use super::names::{
    CONTRACT_PLAIN, CONTRACT_UPSAMPLED, CONTRACT_VERSION, FORMAT, FRAME_FORMAT, INPUT_AUDIO,
    INPUT_BACKGROUND, INPUT_CELLS, INPUT_DIRECTIONS, INPUT_ORIGINS, INPUT_PATCH_BACKGROUND,
    INPUT_PATCH_DIRECTIONS, INPUT_PATCH_ORIGINS, OUTPUT_BOX_OPACITY, OUTPUT_BOX_RGB,
    OUTPUT_PATCH_RGB, OUTPUT_SEGMENTS, input_names, output_names,
};
use crate::onnx::{GraphProto, StringStringEntryProto};

/// The input names of the model `info` describes, in the order the exporter writes them:
/// [`input_names`], with [`INPUT_CELLS`] before the background for an upsampled ray graph,
/// and the mouth patch's rays and background after it when it has one.
pub fn model_input_names(info: &ModelInfo) -> Vec<&'static str> {
    match info.upsample {
        Some(up) => {
            let mut names = vec![
                INPUT_ORIGINS,
                INPUT_DIRECTIONS,
                INPUT_AUDIO,
                INPUT_CELLS,
                INPUT_BACKGROUND,
            ];
            if up.mouth_patch.is_some() {
                names.extend([
                    INPUT_PATCH_ORIGINS,
                    INPUT_PATCH_DIRECTIONS,
                    INPUT_PATCH_BACKGROUND,
                ]);
            }
            names
        }
        None => input_names(),
    }
}

/// The output names of the model `info` describes, in the order the exporter writes them:
/// [`output_names`], or for an upsampled ray graph [`OUTPUT_BOX_RGB`], [`OUTPUT_SEGMENTS`]
/// and [`OUTPUT_BOX_OPACITY`], then [`OUTPUT_PATCH_RGB`] with a mouth patch.
pub fn model_output_names(info: &ModelInfo) -> Vec<&'static str> {
    match info.upsample {
        Some(up) => {
            let mut names = vec![OUTPUT_BOX_RGB, OUTPUT_SEGMENTS, OUTPUT_BOX_OPACITY];
            if up.mouth_patch.is_some() {
                names.push(OUTPUT_PATCH_RGB);
            }
            names
        }
        None => output_names(),
    }
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
    /// Feature frames past the centre window's middle that the graph reads; the later rows
    /// are zeroed inside it (`None`: all of them). Only without attention.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ahead: Option<usize>,
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

    /// Neighbouring frames after the frame itself whose windows the graph reads: the
    /// neighbourhood's with attention, none without (only the centre window counts).
    pub fn frames_ahead(&self) -> usize {
        if self.attention {
            nldf_core::audio::lookahead_frames(self.att_frames)
        } else {
            0
        }
    }

    /// Rows of a window the graph reads, from the first (the rest are zeroed).
    pub fn rows_read(&self) -> usize {
        nldf_core::student_config::rows_read(self.window, self.ahead)
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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct UpsampleInfo {
    /// Output pixels per coarse ray along each side: 2, 4 or 8. The coarse grid's rays pass
    /// through the centres of the output's `factor x factor` blocks
    /// (`nldf_core::upsampler_config::coarse_intrinsics`).
    pub factor: usize,
    /// Coarse rays added around the hits on each side of the box
    /// (`nldf_core::upsampler_config::coarse_box`).
    pub margin: usize,
    /// The mouth's box in head space (contract 6): the output pixels whose rays meet it
    /// within `[near, far]` are the student's own rays ([`INPUT_PATCH_ORIGINS`]), painted
    /// over the upsampled frame. Absent: no patch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mouth_patch: Option<Bounds>,
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
                    Some(UpsampleInfo {
                        mouth_patch: Some(_),
                        ..
                    }) => CONTRACT_VERSION,
                    Some(_) => CONTRACT_UPSAMPLED,
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
            // Every model predicts opacity and composites over its background input.
            (keys::OPACITY, json(&true)),
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
        if let Some(a) = self.audio.ahead {
            entries.push((keys::AUDIO_AHEAD, json(&a)));
        }
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
