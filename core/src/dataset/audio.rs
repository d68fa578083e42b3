//! A dataset's audio features: `aud.npy` as it is or computed from `aud.wav`, as an
//! [`AudioChoice`] says, with the `aud.json` that says what made them.

use std::path::{Path, PathBuf};

use crate::audio::{
    AudioWindows, FeatureConfig, FeatureSource, audio_windows_for_frames, n_video_frames, read_wav,
};
use crate::error::{Error, Result};
use crate::files::{read_json, write_json};
use crate::npy::{load_audio_npy, save_audio_npy};

/// The audio feature windows, `[N, 16, F]` (AD-NeRF's name).
pub const AUDIO_NPY: &str = "aud.npy";
/// The source audio, mono (ours; AD-NeRF's preprocessing leaves it too).
pub const AUDIO_WAV: &str = "aud.wav";
/// What made `aud.npy` (ours): a [`FeatureSource`] as JSON. Without it, `aud.npy` holds
/// another front end's features (AD-NeRF's DeepSpeech logits, say).
pub const AUDIO_SOURCE_FILE: &str = "aud.json";

/// Which audio features a dataset is read with.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum AudioChoice {
    /// nldf's own features: `aud.npy` when `aud.json` says nldf made it, otherwise
    /// computed from `aud.wav` with the default settings when there is one, otherwise
    /// `aud.npy` as it is (another front end's, which a model then needs at render time).
    #[default]
    Auto,
    /// `aud.npy` as it is, whichever front end made it.
    Npy,
    /// Features made as a trained run's were: `aud.npy` when it was made that way,
    /// otherwise, for nldf's features, computed from `aud.wav`.
    Matching(FeatureSource),
}

/// Audio windows, the front end that made them and the file they came from.
type LoadedAudio = (AudioWindows, FeatureSource, PathBuf);

/// The audio features of the dataset at `root` as `choice` says (see [`AudioChoice`]),
/// their source and the file they came from. From `aud.wav`, the windows cover the audio
/// and at least `n_frames` video frames at `fps` (a recording a frame short of its video
/// repeats its last window).
pub fn load_audio(
    root: &Path,
    choice: &AudioChoice,
    fps: f32,
    n_frames: usize,
) -> Result<LoadedAudio> {
    let npy = root.join(AUDIO_NPY);
    let wav = root.join(AUDIO_WAV);
    let sidecar = read_audio_source(root)?;
    let from_npy = || audio_from_npy(root, &npy, sidecar.as_ref());
    let from_wav = |cfg: &FeatureConfig| audio_from_wav(&wav, fps, n_frames, cfg);
    let npy_is = |want: &FeatureSource| sidecar.as_ref() == Some(want) && npy.is_file();
    match choice {
        AudioChoice::Npy => from_npy(),
        AudioChoice::Auto => {
            let ours = matches!(sidecar, Some(FeatureSource::Nldf(_)));
            if (ours && npy.is_file()) || !wav.is_file() {
                from_npy()
            } else {
                from_wav(&FeatureConfig::default())
            }
        }
        AudioChoice::Matching(want) => match want {
            _ if npy_is(want) => from_npy(),
            FeatureSource::Nldf(cfg) if wav.is_file() => from_wav(cfg),
            FeatureSource::Nldf(_) => Err(Error::invalid(
                &wav,
                format!(
                    "is missing, and {AUDIO_NPY} does not hold the run's features ({})",
                    want.describe()
                ),
            )),
            FeatureSource::Foreign { .. } => {
                let loaded = from_npy()?;
                if (loaded.0.n_features, loaded.0.window) != (want.n_features(), want.window()) {
                    return Err(Error::invalid(
                        &npy,
                        format!(
                            "holds {} x {} windows, the run was trained on {}",
                            loaded.0.window,
                            loaded.0.n_features,
                            want.describe()
                        ),
                    ));
                }
                Ok(loaded)
            }
        },
    }
}

/// The windows of `npy` (the dataset at `root`'s `aud.npy`), with the source its `aud.json`
/// (`sidecar`) says, which must match their shape, or a foreign one without it.
fn audio_from_npy(root: &Path, npy: &Path, sidecar: Option<&FeatureSource>) -> Result<LoadedAudio> {
    let windows = load_audio_npy(npy)?;
    let source = match sidecar {
        Some(source) => {
            if (source.n_features(), source.window()) != (windows.n_features, windows.window) {
                return Err(Error::invalid(
                    root.join(AUDIO_SOURCE_FILE),
                    format!(
                        "describes {} x {} windows but {AUDIO_NPY} holds {} x {}",
                        source.window(),
                        source.n_features(),
                        windows.window,
                        windows.n_features
                    ),
                ));
            }
            source.clone()
        }
        None => FeatureSource::Foreign {
            description: format!(
                "{AUDIO_NPY} without {AUDIO_SOURCE_FILE}: another front end's features \
                 (AD-NeRF's DeepSpeech logits, say)"
            ),
            n_features: windows.n_features,
            window: windows.window,
        },
    };
    Ok((windows, source, npy.to_path_buf()))
}

/// nldf's features computed with `cfg` from `wav`, covering the audio and at least
/// `n_frames` video frames at `fps`; an error when the audio is more than a frame short.
fn audio_from_wav(
    wav: &Path,
    fps: f32,
    n_frames: usize,
    cfg: &FeatureConfig,
) -> Result<LoadedAudio> {
    let wave = read_wav(wav)?;
    let have = n_video_frames(wave.samples.len(), wave.sample_rate, fps);
    if have + 1 < n_frames {
        return Err(Error::invalid(
            wav,
            format!(
                "{:.2} s of audio make {have} video frames at {fps} fps, but the \
                 transforms use aud_id up to {}",
                wave.seconds(),
                n_frames - 1
            ),
        ));
    }
    let windows = audio_windows_for_frames(&wave, fps, cfg, have.max(n_frames))
        .map_err(|e| Error::invalid(wav, e.to_string()))?;
    Ok((windows, FeatureSource::Nldf(cfg.clone()), wav.to_path_buf()))
}

/// `aud.json` of the dataset at `root`, when it has one.
pub fn read_audio_source(root: &Path) -> Result<Option<FeatureSource>> {
    let path = root.join(AUDIO_SOURCE_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let source: FeatureSource = read_json(&path)?;
    if let FeatureSource::Nldf(cfg) = &source {
        cfg.validate()
            .map_err(|e| Error::invalid(&path, e.to_string()))?;
    }
    Ok(Some(source))
}

/// Writes audio windows as `aud.npy` and their source as `aud.json` into `dir`, each
/// atomically.
pub fn save_audio_features(
    dir: &Path,
    windows: &AudioWindows,
    source: &FeatureSource,
) -> Result<()> {
    save_audio_npy(&dir.join(AUDIO_NPY), windows)?;
    write_json(&dir.join(AUDIO_SOURCE_FILE), source)
}
