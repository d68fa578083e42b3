//! The transforms files (`transforms_{train,val}.json`): AD-NeRF's fields plus optional ones
//! of ours, read and written.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::files::{read_json, write_json};
use crate::image::Rect;

/// One frame entry of a transforms file, AD-NeRF's fields plus optional ones of ours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameEntry {
    /// Image file stem under the image folder.
    pub img_id: i64,
    /// Row of `aud.npy` holding this frame's audio window.
    pub aud_id: i64,
    /// 4 x 4 camera-to-world matrix, rows as written in the JSON.
    pub transform_matrix: [[f32; 4]; 4],
    /// Face bounding box `[x, y, w, h]` in pixels; the whole image when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face_rect: Option<Rect>,
    /// Blink amount of this frame (ours; AD-NeRF's later work uses it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eye: Option<f32>,
}

/// A `transforms_{train,val}.json` file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformsFile {
    /// Focal length in pixels.
    pub focal_len: f32,
    /// Principal point x in pixels.
    pub cx: f32,
    /// Principal point y in pixels.
    pub cy: f32,
    /// Near bound of the rays (ours; AD-NeRF's rule applies when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near: Option<f32>,
    /// Far bound of the rays (ours).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub far: Option<f32>,
    /// Video frame rate (ours; 25 when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f32>,
    /// Image width (ours; the background's when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Image height (ours).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
    pub frames: Vec<FrameEntry>,
}

impl TransformsFile {
    /// Reads and parses a transforms file (no cross-file checks).
    pub fn load(path: &Path) -> Result<TransformsFile> {
        read_json(path)
    }

    /// Parses a transforms file's text; `path` names it in errors.
    pub fn parse(path: &Path, text: &str) -> Result<TransformsFile> {
        serde_json::from_str(text).map_err(|e| Error::invalid(path, format!("bad JSON: {e}")))
    }

    /// Writes the file atomically, pretty-printed.
    pub fn save(&self, path: &Path) -> Result<()> {
        write_json(path, self)
    }
}
