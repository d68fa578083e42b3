//! Configuration files read strictly: an unknown key or a value of the wrong type is an
//! error naming the file and the key, and a run configuration is checked value by value
//! before any work starts.

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::{Error, Result};

/// Reads a configuration file strictly: a key the configuration does not have, or a value
/// of the wrong type, is an error that names the file and the key's path
/// (`model.width: invalid value ...`).
pub fn read_config<T: DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_config(path, &text)
}

/// [`read_config`] on text already read; `path` names it in errors.
pub fn parse_config<T: DeserializeOwned>(path: &Path, text: &str) -> Result<T> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let key = e.path().to_string();
        let inner = e.into_inner();
        let problem = if key.is_empty() || key == "." {
            format!("bad configuration: {inner}")
        } else {
            format!("bad configuration: `{key}`: {inner}")
        };
        Error::invalid(path, problem)
    })
}

/// A run configuration: read strictly, then checked value by value.
pub trait RunConfig: DeserializeOwned {
    /// Checks every value before any work starts; the error names the key.
    fn check(&self) -> Result<()>;
}

/// [`RunConfig::check`], its error saying "invalid configuration" and naming `file` when
/// the configuration came from one.
pub fn check_config<T: RunConfig>(cfg: &T, file: Option<&Path>) -> Result<()> {
    cfg.check().map_err(|e| {
        let problem = format!("invalid configuration: {e}");
        match file {
            Some(path) => Error::invalid(path, problem),
            None => Error::Config(problem),
        }
    })
}

/// [`parse_config`], then [`RunConfig::check`]: either error names `path`.
pub fn parse_checked<T: RunConfig>(path: &Path, text: &str) -> Result<T> {
    let cfg: T = parse_config(path, text)?;
    check_config(&cfg, Some(path))?;
    Ok(cfg)
}

/// [`parse_checked`] on the file at `path`.
pub fn read_checked<T: RunConfig>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse_checked(path, &text)
}
