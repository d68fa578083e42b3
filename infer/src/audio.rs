//! The audio input of each frame: made from a WAV file with the training code
//! (`nldf_core::audio`) and the feature settings the model's metadata records, or read from
//! an `aud.npy` of ready-made windows, which a model trained on another front end's features
//! (AD-NeRF's DeepSpeech) needs.

use std::path::Path;

use nldf_core::audio::{AudioWindows, FeatureConfig, FeatureSource, audio_windows, read_wav};
use nldf_core::dataset::load_audio_npy;
use nldf_model::contract::ModelInfo;

use crate::error::{Error, Result};

/// The settings of nldf's front end that `info`'s model was trained with, or, for a model
/// trained on another front end's features, an error naming `model` that says to pass the
/// features instead of a WAV.
pub fn wav_features<'a>(info: &'a ModelInfo, model: &Path) -> Result<&'a FeatureConfig> {
    match &info.spec.features {
        FeatureSource::Nldf(cfg) => {
            if cfg.n_mels != info.audio.n_features || cfg.window != info.audio.window {
                return Err(Error::Argument(format!(
                    "{}: the model's feature settings make [{}, {}] windows but its audio \
                     input takes [{}, {}]",
                    model.display(),
                    cfg.window,
                    cfg.n_mels,
                    info.audio.window,
                    info.audio.n_features
                )));
            }
            Ok(cfg)
        }
        foreign @ FeatureSource::Foreign { .. } => Err(Error::Argument(format!(
            "{}: the model was trained on {}, which nldf cannot make from a WAV; render from \
             the same kind of features with --features FILE.npy ([N, {}, {}] windows, one per \
             video frame)",
            model.display(),
            foreign.describe(),
            info.audio.window,
            info.audio.n_features
        ))),
    }
}

/// Reads the WAV at `path` and makes its feature windows for `info`'s model (read from
/// `model`): one `[window, n_features]` block per video frame at the model's fps. A WAV too
/// short for one video frame is an error naming the file.
///
/// # Shapes
/// - returns `[n_video_frames, window, n_features]`
pub fn windows_from_wav(info: &ModelInfo, model: &Path, path: &Path) -> Result<AudioWindows> {
    let features = wav_features(info, model)?;
    let wave = read_wav(path)?;
    let windows = audio_windows(&wave, info.spec.fps, features)?;
    if windows.n_frames == 0 {
        return Err(Error::Core(nldf_core::Error::invalid(
            path,
            format!(
                "{:.3} s of audio is shorter than one video frame (1/{} s)",
                wave.seconds(),
                info.spec.fps
            ),
        )));
    }
    Ok(windows)
}

/// Reads ready-made feature windows (an `aud.npy`, `[N, window, F]`) for `info`'s model,
/// checking their shape against its audio input.
pub fn windows_from_npy(info: &ModelInfo, path: &Path) -> Result<AudioWindows> {
    let windows = load_audio_npy(path)?;
    if (windows.window, windows.n_features) != (info.audio.window, info.audio.n_features) {
        return Err(Error::Core(nldf_core::Error::invalid(
            path,
            format!(
                "holds [{}, {}, {}] windows, the model takes [N, {}, {}]",
                windows.n_frames,
                windows.window,
                windows.n_features,
                info.audio.window,
                info.audio.n_features
            ),
        )));
    }
    if windows.n_frames == 0 {
        return Err(Error::Core(nldf_core::Error::invalid(
            path,
            "holds no windows",
        )));
    }
    Ok(windows)
}
