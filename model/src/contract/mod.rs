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
//! - input [`INPUT_BACKGROUND`] `background`: f32 `[n_rays, 3]`, the background image's
//!   colour at each ray's pixel
//! - output [`OUTPUT_RGB`] `rgb`: f32 `[n_rays, 3]`, the pixel colours (paper Eq. 7)
//! - output [`OUTPUT_SEGMENTS`] `segments`: f32 `[n_rays, M, 3]`, the M segment colours,
//!   the head's colour alone
//! - output [`OUTPUT_OPACITY`] `opacity`: f32 `[n_rays, 1]`, how much of the ray the head
//!   covers, in (0, 1) ([`keys::OPACITY`] is always `true`)
//!
//! and `rgb` is `sum_i segments_i + (1 - opacity) * background`, composited in the graph as
//! the teacher composites.
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
//!
//! # Int8
//! An int8 graph's quantized weights lie within [`INT8_WEIGHT_MAX`] (7 bits), so that no
//! runtime's u8 x s8 kernel saturates a pair of products ([`int8_pair_sum_max`]).

mod int8;
/// `metadata_props` keys.
pub mod keys;
mod metadata;
mod model_info;
mod names;

pub use int8::{INT8_WEIGHT_MAX, int8_pair_sum_max};
pub use metadata::MetadataError;
pub use model_info::{
    AudioInput, ModelInfo, NetworkShape, UpsampleInfo, front_end, model_input_names,
    model_output_names, weights_checksum,
};
pub use names::*;
