//! Where the onnxruntime library is: `ORT_DYLIB_PATH` when set, otherwise the library that
//! the pip `onnxruntime` wheel ships inside the project's Python environment
//! (`.venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so.*`, made by
//! `scripts/python_env.sh`), looked for in the working folder, its ancestors and the
//! ancestors of the running executable.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The environment variable that names the library file.
pub const ORT_DYLIB_PATH: &str = "ORT_DYLIB_PATH";

/// How to get the library, for error messages.
pub const HOW_TO_GET: &str = "set ORT_DYLIB_PATH to a libonnxruntime.so of onnxruntime >= 1.31, \
     or run scripts/python_env.sh (the onnxruntime wheel it installs into .venv ships one)";

/// The onnxruntime library to load, or an error saying where it was looked for.
pub fn find_ort_library() -> Result<PathBuf> {
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        roots.extend(cwd.ancestors().map(Path::to_path_buf));
    }
    if let Ok(exe) = std::env::current_exe() {
        roots.extend(exe.ancestors().skip(1).map(Path::to_path_buf));
    }
    find_ort_library_in(std::env::var_os(ORT_DYLIB_PATH).as_deref(), &roots)
}

/// [`find_ort_library`] with the variable's value and the folders to search given:
/// `dylib_path` when set and not empty (it must be a file), else the first of `roots` with
/// a [`venv_library`].
pub fn find_ort_library_in(dylib_path: Option<&OsStr>, roots: &[PathBuf]) -> Result<PathBuf> {
    if let Some(value) = dylib_path.filter(|v| !v.is_empty()) {
        let path = PathBuf::from(value);
        if path.is_file() {
            return Ok(path);
        }
        return Err(Error::OrtLibrary(format!(
            "{ORT_DYLIB_PATH}={} is not a file; {HOW_TO_GET}",
            path.display()
        )));
    }
    for root in roots {
        if let Some(found) = venv_library(root) {
            return Ok(found);
        }
    }
    Err(Error::OrtLibrary(format!(
        "library not found ({ORT_DYLIB_PATH} is unset and no .venv with the onnxruntime wheel \
         lies above the working folder or the executable); {HOW_TO_GET}"
    )))
}

/// `ROOT/.venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so*`, the newest
/// version first.
pub fn venv_library(root: &Path) -> Option<PathBuf> {
    let lib = root.join(".venv").join("lib");
    let mut found: Vec<PathBuf> = std::fs::read_dir(&lib)
        .ok()?
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("python3"))
        .filter_map(|e| {
            let capi = e.path().join("site-packages/onnxruntime/capi");
            std::fs::read_dir(capi).ok()
        })
        .flatten()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("libonnxruntime.so"))
                && p.is_file()
        })
        .collect();
    found.sort();
    found.pop()
}
