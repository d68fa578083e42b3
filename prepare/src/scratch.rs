//! The output folder of a job, written whole or not at all.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::video;

/// The output folder being written: `<out>.part` beside it, renamed to `out` by
/// [`Scratch::commit`] and removed when dropped uncommitted.
pub(crate) struct Scratch {
    pub(crate) dir: PathBuf,
    out: PathBuf,
    force: bool,
    done: bool,
}

impl Scratch {
    pub(crate) fn new(out: &Path, force: bool) -> Result<Scratch> {
        let occupied =
            out.exists() && std::fs::read_dir(out).map_or(true, |mut d| d.next().is_some());
        if occupied && !force {
            return Err(Error::invalid(
                out,
                "exists and is not empty (pass --force to replace it)",
            ));
        }
        let dir = video::part_path(out);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        }
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        Ok(Scratch {
            dir,
            out: out.to_path_buf(),
            force,
            done: false,
        })
    }

    pub(crate) fn commit(mut self) -> Result<()> {
        if self.out.exists() && self.force {
            std::fs::remove_dir_all(&self.out).map_err(|e| Error::io(&self.out, e))?;
        } else if self.out.exists() {
            std::fs::remove_dir(&self.out).map_err(|e| Error::io(&self.out, e))?;
        }
        std::fs::rename(&self.dir, &self.out).map_err(|e| Error::io(&self.out, e))?;
        self.done = true;
        Ok(())
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}
