//! The outside programs `nldf prepare` runs, and where they live: ffmpeg, and the Python
//! environment that holds mediapipe's face models.
//!
//! The face environment is a folder made by [`crate::face`]'s installer from registry
//! packages (PyPI and npm) alone: `$NLDF_FACE_ENV`, else `$XDG_CACHE_HOME/nldf/face-env`,
//! else `~/.cache/nldf/face-env`. ffmpeg is `$NLDF_FFMPEG`, else the one the face
//! environment's `imageio-ffmpeg` wheel carries, else `ffmpeg` on the `PATH`.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::{Error, Result};

/// The variable that names the face environment's folder.
pub const FACE_ENV_VAR: &str = "NLDF_FACE_ENV";
/// The variable that names the ffmpeg program.
pub const FFMPEG_VAR: &str = "NLDF_FFMPEG";
/// Where the face environment records the ffmpeg it carries (one line: the program's path).
pub const FFMPEG_RECORD: &str = "ffmpeg-path.txt";

/// The face environment's folder (it may not exist yet).
pub fn face_env_dir() -> Result<PathBuf> {
    if let Some(dir) = std::env::var_os(FACE_ENV_VAR).filter(|v| !v.is_empty()) {
        return Ok(PathBuf::from(dir));
    }
    let cache = std::env::var_os("XDG_CACHE_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| {
            std::env::var_os("HOME")
                .filter(|v| !v.is_empty())
                .map(|h| PathBuf::from(h).join(".cache"))
        })
        .ok_or_else(|| {
            Error::Argument(format!(
                "neither {FACE_ENV_VAR}, XDG_CACHE_HOME nor HOME is set: no place for the face \
                 environment"
            ))
        })?;
    Ok(cache.join("nldf").join("face-env"))
}

/// The ffmpeg program to run: `$NLDF_FFMPEG`, the face environment's, or `ffmpeg` on the
/// `PATH`; an error when none of them runs.
pub fn ffmpeg() -> Result<PathBuf> {
    if let Some(p) = std::env::var_os(FFMPEG_VAR).filter(|v| !v.is_empty()) {
        let p = PathBuf::from(p);
        return if runs(&p) {
            Ok(p)
        } else {
            Err(Error::invalid(
                &p,
                format!("{FFMPEG_VAR} names a program that does not run"),
            ))
        };
    }
    if let Ok(dir) = face_env_dir() {
        let record = dir.join(FFMPEG_RECORD);
        if let Ok(text) = std::fs::read_to_string(&record) {
            let p = PathBuf::from(text.trim());
            if runs(&p) {
                return Ok(p);
            }
        }
    }
    let p = PathBuf::from("ffmpeg");
    if runs(&p) {
        return Ok(p);
    }
    Err(Error::Argument(
        "no ffmpeg: run `nldf prepare --setup` (it installs the imageio-ffmpeg wheel's), set \
         NLDF_FFMPEG, or put ffmpeg on the PATH"
            .into(),
    ))
}

/// Whether `program -version` runs and exits zero.
fn runs(program: &Path) -> bool {
    Command::new(program)
        .arg("-version")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// A thread that reads a child's stream to its end, line by line (so the child never blocks
/// on a full pipe), and returns the lines.
pub fn collect_lines(
    stream: Option<impl std::io::Read + Send + 'static>,
) -> std::thread::JoinHandle<Vec<String>> {
    use std::io::BufRead;
    std::thread::spawn(move || {
        stream
            .map(|s| {
                std::io::BufReader::new(s)
                    .lines()
                    .map_while(|l| l.ok())
                    .collect()
            })
            .unwrap_or_default()
    })
}
