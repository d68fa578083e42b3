//! The graph's names, the contract's versions and the format markers.

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
/// The background colour behind each ray, f32 `[n_rays, 3]`.
pub const INPUT_BACKGROUND: &str = "background";
/// How much of each ray the head covers, f32 `[n_rays, 1]`.
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

/// An upsampled ray graph's mouth patch (contract 6, [`super::UpsampleInfo::mouth_patch`]):
/// the rays of the output pixels whose rays meet the mouth's box, f32 `[n_patch, 3]` each
/// (none: `[0, 3]`). They go through the student after the coarse rays.
pub const INPUT_PATCH_ORIGINS: &str = "patch_o";
pub const INPUT_PATCH_DIRECTIONS: &str = "patch_d";
/// The background colour behind each of the mouth patch's pixels, f32 `[n_patch, 3]`.
pub const INPUT_PATCH_BACKGROUND: &str = "patch_background";
/// The mouth patch's pixels, f32 `[n_patch, 3]`: the student's own colour of each ray
/// composited over its background, which replace the upsampled pixels there.
pub const OUTPUT_PATCH_RGB: &str = "patch_rgb";
/// Symbolic name of the mouth patch's ray axis.
pub const PATCH_AXIS: &str = "n_patch";

/// The graph's input names in the order the exporter writes them: the background last.
pub fn input_names() -> Vec<&'static str> {
    vec![
        INPUT_ORIGINS,
        INPUT_DIRECTIONS,
        INPUT_AUDIO,
        INPUT_BACKGROUND,
    ]
}

/// The graph's output names in the order the exporter writes them.
pub fn output_names() -> Vec<&'static str> {
    vec![OUTPUT_RGB, OUTPUT_SEGMENTS, OUTPUT_OPACITY]
}

/// Value of [`keys::FORMAT`](super::keys::FORMAT) that marks a model as an nldf student.
pub const FORMAT: &str = "nldf-student";

/// Value of [`keys::FORMAT`](super::keys::FORMAT) that marks a frame graph (`nldf export --frame`): the same
/// student and metadata, with the rays, the head-bounds test, the audio front end and the
/// compositing inside the graph. Its inputs are [`FRAME_INPUT_AUDIO`],
/// [`FRAME_INPUT_POSE`] and [`FRAME_INPUT_KEEP`], its outputs [`FRAME_OUTPUT_IMAGE`],
/// [`FRAME_OUTPUT_WINDOWS`] and [`FRAME_OUTPUT_RAYS`]; [`keys::FRAME_AUDIO`](super::keys::FRAME_AUDIO) says which
/// samples the audio input holds.
pub const FRAME_FORMAT: &str = "nldf-frame";
/// The frame's audio, f32 `[samples]` at 16 kHz (`nldf_core::frame_audio::FrameAudio`):
/// NaN where the span lies outside the track.
pub const FRAME_INPUT_AUDIO: &str = "audio";
/// The camera-to-world matrix, f32 `[4, 4]`, row-major (OpenGL axes, as
/// [`keys::DEFAULT_POSE`](super::keys::DEFAULT_POSE)).
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
/// Version of this contract, [`keys::CONTRACT`](super::keys::CONTRACT): bumped when names, shapes or keys change
/// (2: the audio front end is recorded, [`keys::AUDIO_FRONT_END`](super::keys::AUDIO_FRONT_END); 3: [`keys::OPACITY`](super::keys::OPACITY),
/// with the background input and opacity output of a model that has one; 4:
/// [`keys::BEAM_ANCHOR`](super::keys::BEAM_ANCHOR), the graph anchoring rays before sampling them; 5: [`keys::UPSAMPLE`](super::keys::UPSAMPLE),
/// the upsampled ray graph, written only for one; 6: the upsampled ray graph's mouth patch,
/// [`INPUT_PATCH_ORIGINS`] and the rest, written only for one that has it). This build reads
/// contracts 4 to 6, and only models with opacity and anchored beams: older ones were made
/// by an older nldf.
pub const CONTRACT_VERSION: u32 = 6;
/// The contract an upsampled ray graph without a mouth patch is written with.
pub const CONTRACT_UPSAMPLED: u32 = 5;
/// The contract a ray graph without an upsampler is written with: it reads as it did
/// before contract 5.
pub const CONTRACT_PLAIN: u32 = 4;
