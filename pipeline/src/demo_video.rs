//! The demo's video: the exported student speaking at the held-out frames' poses, rendered
//! by nldf-infer into `OUT/video` (the last stage of `nldf demo` and `nldf train --data`).

use std::path::Path;

use nldf_core::dataset::{AUDIO_NPY, AUDIO_WAV, Split, VOICE_DIR};
use nldf_infer::backend::{BackendKind, BackendOptions};
use nldf_infer::video::{VideoJob, VideoPlan};

use crate::error::{Error, Result};

/// What the demo's video speaks: a voice the student never heard where the dataset has one
/// (the synthetic scene's `voice` split), else the dataset's own recording from its start,
/// else (AD-NeRF ships only `aud.npy`) its audio features, silent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VideoVoice {
    NewVoice,
    Recording,
    Features,
}

impl VideoVoice {
    /// What the voice is, for the log.
    pub fn describe(self) -> &'static str {
        match self {
            VideoVoice::NewVoice => "a voice the student never heard",
            VideoVoice::Recording => "the recording's audio",
            VideoVoice::Features => "the recording's audio features",
        }
    }
}

/// Plans the video of `model` at the poses of the `val` split of the dataset in `data`, into
/// `out/video` (an earlier demo's video there is removed first), with tract: an MP4 when
/// ffmpeg is found, PNG frames always. Returns the plan, ready to render with a progress
/// callback ([`VideoPlan::render`]), and the voice it speaks.
pub fn plan_video(data: &Path, out: &Path, model: &Path) -> Result<(VideoPlan, VideoVoice)> {
    let video = out.join("video");
    if video.exists() {
        std::fs::remove_dir_all(&video).map_err(|e| Error::io(&video, e))?;
    }
    let voice = data.join(VOICE_DIR).join(AUDIO_WAV);
    let recording = data.join(AUDIO_WAV);
    let (audio, features, what) = if voice.is_file() {
        (Some(voice), None, VideoVoice::NewVoice)
    } else if recording.is_file() {
        (Some(recording), None, VideoVoice::Recording)
    } else {
        (None, Some(data.join(AUDIO_NPY)), VideoVoice::Features)
    };
    let job = VideoJob {
        model: model.to_path_buf(),
        audio,
        features,
        poses: Some(data.join(Split::Val.file_name())),
        out: video,
        backend: BackendKind::Tract,
        options: BackendOptions::default(),
        size: None,
        mp4: true,
        ffmpeg: None,
        skip: None,
    };
    Ok((job.plan()?, what))
}
