//! An output folder that appears whole or not at all: everything is written into a hidden
//! staging folder beside it, which is renamed into place when the work succeeds and removed
//! when it fails or is dropped.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Checks that `target` is absent or an empty folder: an output folder nldf may fill.
pub fn check_target(target: &Path) -> Result<()> {
    if target.exists() {
        if !target.is_dir() {
            return Err(Error::output(target, "exists and is not a folder"));
        }
        let mut entries = std::fs::read_dir(target).map_err(|e| Error::io(target, e))?;
        if entries.next().is_some() {
            return Err(Error::output(
                target,
                "exists and is not empty; choose another --out or remove it",
            ));
        }
    }
    Ok(())
}

/// A staging folder for `target`.
#[derive(Debug)]
pub struct Staging {
    staging: PathBuf,
    target: PathBuf,
    finished: bool,
}

impl Staging {
    /// Checks that `target` is absent or an empty folder and makes the staging folder beside
    /// it (creating missing parents); an unusable place is an error naming it.
    pub fn create(target: &Path) -> Result<Staging> {
        check_target(target)?;
        let name = target
            .file_name()
            .ok_or_else(|| Error::output(target, "is not a folder name"))?;
        let parent = target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        if parent.exists() && !parent.is_dir() {
            return Err(Error::output(parent, "is a file, not a folder"));
        }
        std::fs::create_dir_all(parent)
            .map_err(|e| Error::output(parent, format!("cannot create the folder: {e}")))?;
        let staging = parent.join(format!(
            ".{}.partial-{}",
            name.to_string_lossy(),
            std::process::id()
        ));
        if staging.exists() {
            std::fs::remove_dir_all(&staging).map_err(|e| Error::io(&staging, e))?;
        }
        std::fs::create_dir(&staging)
            .map_err(|e| Error::output(parent, format!("cannot write here: {e}")))?;
        Ok(Staging {
            staging,
            target: target.to_path_buf(),
            finished: false,
        })
    }

    /// The folder to write into.
    pub fn path(&self) -> &Path {
        &self.staging
    }

    /// Where the folder will be.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Moves the staging folder into place; returns the target.
    pub fn finish(mut self) -> Result<PathBuf> {
        if self.target.is_dir() {
            // Checked empty at creation; a folder filled since then makes this fail.
            std::fs::remove_dir(&self.target).map_err(|e| {
                Error::output(
                    &self.target,
                    format!("cannot replace the empty folder: {e}"),
                )
            })?;
        }
        std::fs::rename(&self.staging, &self.target)
            .map_err(|e| Error::output(&self.target, format!("cannot move the output in: {e}")))?;
        self.finished = true;
        Ok(self.target.clone())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.finished {
            let _ = std::fs::remove_dir_all(&self.staging);
        }
    }
}
