//! Reading a model's metadata back, each key checked against the rest.

use std::collections::HashMap;

use base64::Engine;
use nldf_core::beam::BeamSpec;
use nldf_core::frame_audio::FrameAudio;
use nldf_core::render_spec::RenderSpec;

use super::keys;
use super::model_info::{AudioInput, ModelInfo, UpsampleInfo, front_end};
use super::names::{CONTRACT_PLAIN, CONTRACT_VERSION, FORMAT, FRAME_FORMAT};
use crate::onnx::StringStringEntryProto;

impl ModelInfo {
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

    /// Reads the metadata back as a model of `format` ([`FORMAT`] or [`FRAME_FORMAT`]).
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
        check_format(&map, format)?;
        let props = Props(map);
        // The one version check: contracts before 4, and models without opacity or
        // anchored beams, were made by an older nldf.
        let contract: u32 = props.parse(keys::CONTRACT)?;
        if contract > CONTRACT_VERSION {
            return Err(MetadataError::Malformed(
                keys::CONTRACT.to_string(),
                format!(
                    "contract version {contract}, this build reads up to {CONTRACT_VERSION}: \
                     made by a newer nldf"
                ),
            ));
        }
        if contract < CONTRACT_PLAIN {
            return Err(older(&format!("contract version {contract}")));
        }
        if !props.parse::<bool>(keys::OPACITY)? {
            return Err(older("no opacity"));
        }
        let info = read_info(&props, contract, format)?;
        check_flat_keys(&props, &info)?;
        check_audio(&props, &info)?;
        Ok(info)
    }
}

/// The refusal of a model made by an older nldf: `what` it has, and what this build reads.
fn older(what: &str) -> MetadataError {
    MetadataError::Older(format!(
        "{what}; this build reads contracts {CONTRACT_PLAIN} to {CONTRACT_VERSION} with opacity \
         and anchored beams"
    ))
}

/// The metadata's values by key.
struct Props<'a>(HashMap<&'a str, &'a str>);

impl Props<'_> {
    /// The value of `key`, which must be present.
    fn get(&self, key: &str) -> Result<&str, MetadataError> {
        self.0
            .get(key)
            .copied()
            .ok_or_else(|| MetadataError::Missing(key.to_string()))
    }

    /// The JSON value of `key`, which must be present.
    fn parse<T: serde::de::DeserializeOwned>(&self, key: &str) -> Result<T, MetadataError> {
        parse(key, self.get(key)?)
    }

    /// The count under `key`, which must be present.
    fn value(&self, key: &str) -> Result<usize, MetadataError> {
        self.parse(key)
    }
}

/// `v`, the value of `key`, as JSON.
fn parse<T: serde::de::DeserializeOwned>(key: &str, v: &str) -> Result<T, MetadataError> {
    serde_json::from_str(v).map_err(|e| MetadataError::Malformed(key.to_string(), e.to_string()))
}

/// Refuses metadata whose [`keys::FORMAT`] is not `format`, saying what the model is.
fn check_format(map: &HashMap<&str, &str>, format: &str) -> Result<(), MetadataError> {
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
    Ok(())
}

/// The model the metadata of contract `contract` describes, its keys read one by one.
fn read_info(props: &Props<'_>, contract: u32, format: &str) -> Result<ModelInfo, MetadataError> {
    let spec: RenderSpec = props.parse(keys::RENDER_SPEC)?;
    spec.check()
        .map_err(|e| MetadataError::Malformed(keys::RENDER_SPEC.to_string(), e))?;
    let background_png = base64::engine::general_purpose::STANDARD
        .decode(props.get(keys::BACKGROUND_PNG)?)
        .map_err(|e| MetadataError::Malformed(keys::BACKGROUND_PNG.to_string(), e.to_string()))?;
    let checksum = props.get(keys::WEIGHTS_CHECKSUM)?;
    let weights_checksum = u64::from_str_radix(checksum, 16)
        .map_err(|e| MetadataError::Malformed(keys::WEIGHTS_CHECKSUM.to_string(), e.to_string()))?;
    Ok(ModelInfo {
        weights_checksum,
        beam: BeamSpec {
            n_points: props.value(keys::BEAM_POINTS)?,
            n_freqs: props.value(keys::BEAM_FREQS)?,
            anchor: Some(
                props
                    .parse::<Option<_>>(keys::BEAM_ANCHOR)?
                    .ok_or_else(|| older("no beam anchor"))?,
            ),
        },
        segments: props.value(keys::SEGMENTS)?,
        audio: AudioInput {
            att_frames: props.value(keys::AUDIO_ATT_FRAMES)?,
            window: props.value(keys::AUDIO_WINDOW)?,
            n_features: props.value(keys::AUDIO_FEATURES)?,
            attention: props.parse(keys::AUDIO_ATTENTION)?,
            ahead: read_ahead(props)?,
        },
        network: props.parse(keys::NETWORK)?,
        step: props.parse(keys::STEP)?,
        spec,
        background_png,
        upsample: read_upsample(props, contract, format)?,
    })
}

/// The audio rows a graph reads past the window's middle ([`keys::AUDIO_AHEAD`]), absent
/// for one that reads them all; refused with attention or beyond the window's half.
fn read_ahead(props: &Props<'_>) -> Result<Option<usize>, MetadataError> {
    let Some(v) = props.0.get(keys::AUDIO_AHEAD) else {
        return Ok(None);
    };
    let a: usize = parse(keys::AUDIO_AHEAD, v)?;
    let window: usize = props.value(keys::AUDIO_WINDOW)?;
    let attention: bool = props.parse(keys::AUDIO_ATTENTION)?;
    if a == 0 || a > window / 2 || attention {
        return Err(MetadataError::Malformed(
            keys::AUDIO_AHEAD.to_string(),
            format!(
                "{a} rows ahead: it must be 1 to half the window ({}) and the graph without \
                 attention",
                window / 2
            ),
        ));
    }
    Ok(Some(a))
}

/// A ray graph's upsampler ([`keys::UPSAMPLE`], required from contract 5); `None` for a
/// frame graph.
fn read_upsample(
    props: &Props<'_>,
    contract: u32,
    format: &str,
) -> Result<Option<UpsampleInfo>, MetadataError> {
    match props.0.get(keys::UPSAMPLE) {
        Some(v) if format == FORMAT => {
            let up: UpsampleInfo = parse(keys::UPSAMPLE, v)?;
            if let Some(b) = &up.mouth_patch
                && (contract < 6 || !b.is_proper())
            {
                return Err(MetadataError::Malformed(
                    keys::UPSAMPLE.to_string(),
                    format!(
                        "a mouth patch needs contract 6 (this is {contract}) and a box with \
                         finite `lo` below `hi` on every axis (lo {:?}, hi {:?})",
                        b.lo.to_array(),
                        b.hi.to_array()
                    ),
                ));
            }
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
            Ok(Some(up))
        }
        _ if contract >= 5 && format == FORMAT => {
            Err(MetadataError::Missing(keys::UPSAMPLE.to_string()))
        }
        _ => Ok(None),
    }
}

/// Checks the flat keys against the render spec.
fn check_flat_keys(props: &Props<'_>, info: &ModelInfo) -> Result<(), MetadataError> {
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
        let got: f32 = props.parse(key)?;
        if got != expected as f32 {
            return Err(MetadataError::Malformed(
                key.to_string(),
                format!("says {got}, the render spec says {expected}"),
            ));
        }
    }
    Ok(())
}

/// Checks the audio front end and the input's windows against the render spec's features,
/// and that the beam, the segments and the audio input are not empty.
fn check_audio(props: &Props<'_>, info: &ModelInfo) -> Result<(), MetadataError> {
    let said = props.get(keys::AUDIO_FRONT_END)?;
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
    Ok(())
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
    /// The model was made by an older nldf, whose models this build no longer reads.
    #[error("made by an older nldf ({0}): train again or re-export")]
    Older(String),
    /// A required key is absent.
    #[error("metadata lacks `{0}`")]
    Missing(String),
    /// A key's value does not parse or disagrees with the rest.
    #[error("metadata `{0}`: {1}")]
    Malformed(String, String),
}
