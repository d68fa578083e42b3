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
/// Feature frames past the centre window's middle that the graph reads (a count; absent:
/// all `window / 2`): a short-lookahead student (`nldf train lookahead`) zeroes the rest, so
/// a stream need not wait for them.
pub const AUDIO_AHEAD: &str = "nldf.audio_ahead";
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
/// "margin"}`, contract 5, and `"mouth_patch": {"lo", "hi"}`, contract 6): the graph
/// takes the coarse rays of a box of the coarse grid and gives the box's pixels
/// ([`super::INPUT_CELLS`], [`super::OUTPUT_BOX_RGB`]), and with a mouth patch the colours
/// of the patch's rays ([`super::INPUT_PATCH_ORIGINS`], [`super::OUTPUT_PATCH_RGB`]).
pub const UPSAMPLE: &str = "nldf.upsample";
/// The background as base64 of an 8-bit RGB PNG (plain string). Written last.
pub const BACKGROUND_PNG: &str = "nldf.background_png";
