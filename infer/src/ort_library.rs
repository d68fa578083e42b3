//! Where the onnxruntime library is, looked for in this order:
//! 1. `ORT_DYLIB_PATH`, when set (it must name the file);
//! 2. the project's Python environment: `.venv/lib/python3*/site-packages/onnxruntime/capi/
//!    libonnxruntime.so.*` (made by `scripts/python_env.sh`) in the working folder, its
//!    ancestors or the ancestors of the running executable;
//! 3. the `onnxruntime` package of the `python3` on the PATH (`pip install onnxruntime`
//!    puts the library inside it);
//! 4. the system's library path (`LD_LIBRARY_PATH`, then the usual library folders).

use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::{Error, Result};

/// The environment variable that names the library file.
pub const ORT_DYLIB_PATH: &str = "ORT_DYLIB_PATH";

/// The one command that gets the library, for error messages.
pub const HOW_TO_GET: &str = "run `pip install onnxruntime` (1.31 or newer), or set \
     ORT_DYLIB_PATH to a libonnxruntime.so";

/// Library folders searched after `LD_LIBRARY_PATH`.
const SYSTEM_DIRS: &[&str] = &[
    "/usr/local/lib",
    "/usr/lib/x86_64-linux-gnu",
    "/usr/lib64",
    "/usr/lib",
    "/lib/x86_64-linux-gnu",
    "/lib",
];

/// Where to look for the library, in order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OrtSearch {
    /// `ORT_DYLIB_PATH`'s value.
    pub dylib_path: Option<OsString>,
    /// Folders whose `.venv` may hold the onnxruntime wheel.
    pub roots: Vec<PathBuf>,
    /// The Python whose `onnxruntime` package to look in.
    pub python: Option<PathBuf>,
    /// System library folders.
    pub system_dirs: Vec<PathBuf>,
}

/// A library found, and where.
#[derive(Debug, Clone, PartialEq)]
pub struct FoundOrt {
    /// The library file.
    pub path: PathBuf,
    /// Which place of the search order held it.
    pub place: &'static str,
}

impl FoundOrt {
    /// The onnxruntime version its file name carries (`libonnxruntime.so.1.31.1`), if any.
    pub fn version(&self) -> Option<String> {
        let name = self.path.file_name()?.to_string_lossy().to_string();
        let version = name.strip_prefix("libonnxruntime.so.")?;
        (!version.is_empty()).then(|| version.to_string())
    }
}

impl OrtSearch {
    /// The search this process would make: its environment, working folder, executable,
    /// `python3` on the PATH and library path.
    pub fn from_env() -> OrtSearch {
        let mut roots: Vec<PathBuf> = Vec::new();
        if let Ok(cwd) = std::env::current_dir() {
            roots.extend(cwd.ancestors().map(Path::to_path_buf));
        }
        if let Ok(exe) = std::env::current_exe() {
            roots.extend(exe.ancestors().skip(1).map(Path::to_path_buf));
        }
        let mut system_dirs: Vec<PathBuf> = std::env::var_os("LD_LIBRARY_PATH")
            .map(|v| std::env::split_paths(&v).collect())
            .unwrap_or_default();
        system_dirs.extend(SYSTEM_DIRS.iter().map(PathBuf::from));
        OrtSearch {
            dylib_path: std::env::var_os(ORT_DYLIB_PATH),
            roots,
            python: on_path("python3"),
            system_dirs,
        }
    }

    /// The first library in the search order, or one line saying where it was looked for
    /// and the command that fixes it.
    pub fn find(&self) -> Result<FoundOrt> {
        if let Some(value) = self.dylib_path.as_deref().filter(|v| !v.is_empty()) {
            let path = PathBuf::from(value);
            if path.is_file() {
                return Ok(FoundOrt {
                    path,
                    place: ORT_DYLIB_PATH,
                });
            }
            return Err(Error::OrtLibrary(format!(
                "{ORT_DYLIB_PATH}={} is not a file; {HOW_TO_GET}",
                path.display()
            )));
        }
        if let Some(path) = self.roots.iter().find_map(|root| venv_library(root)) {
            return Ok(FoundOrt {
                path,
                place: "the project's .venv",
            });
        }
        if let Some(path) = self.python.as_deref().and_then(python_library) {
            return Ok(FoundOrt {
                path,
                place: "the onnxruntime package of python3",
            });
        }
        if let Some(path) = self.system_dirs.iter().find_map(|d| newest_library(d)) {
            return Ok(FoundOrt {
                path,
                place: "the system library path",
            });
        }
        Err(Error::OrtLibrary(format!(
            "library not found ({ORT_DYLIB_PATH} is unset, no .venv with the onnxruntime wheel \
             lies above the working folder or the executable, {} and none is on the system \
             library path); {HOW_TO_GET}",
            match &self.python {
                Some(p) => format!("{} has no onnxruntime package", p.display()),
                None => "no python3 is on the PATH".to_string(),
            }
        )))
    }
}

/// The onnxruntime library to load (see [`OrtSearch`]), or an error saying where it was
/// looked for and how to get it.
pub fn find_ort_library() -> Result<PathBuf> {
    OrtSearch::from_env().find().map(|f| f.path)
}

/// The search's first two places alone: `dylib_path` when set and not empty (it must be a
/// file), else the first of `roots` with a [`venv_library`].
pub fn find_ort_library_in(dylib_path: Option<&OsStr>, roots: &[PathBuf]) -> Result<PathBuf> {
    OrtSearch {
        dylib_path: dylib_path.map(OsStr::to_os_string),
        roots: roots.to_vec(),
        ..OrtSearch::default()
    }
    .find()
    .map(|f| f.path)
}

/// `ROOT/.venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so*`, the newest
/// version first.
pub fn venv_library(root: &Path) -> Option<PathBuf> {
    let lib = root.join(".venv").join("lib");
    let mut found: Vec<PathBuf> = std::fs::read_dir(&lib)
        .ok()?
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("python3"))
        .filter_map(|e| newest_library(&e.path().join("site-packages/onnxruntime/capi")))
        .collect();
    found.sort_by_key(|p| version_key(p));
    found.pop()
}

/// The library inside the `onnxruntime` package that `python` imports, if it has one.
pub fn python_library(python: &Path) -> Option<PathBuf> {
    let out = Command::new(python)
        .args([
            "-c",
            "import os, onnxruntime; print(os.path.dirname(onnxruntime.__file__))",
        ])
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let package = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    newest_library(&package.join("capi"))
}

/// The newest `libonnxruntime.so*` file in `dir`.
fn newest_library(dir: &Path) -> Option<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("libonnxruntime.so"))
                && p.is_file()
        })
        .collect();
    found.sort_by_key(|p| version_key(p));
    found.pop()
}

/// The file `name` in the first folder of the PATH that has it.
pub fn on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join(name))
        .find(|p| p.is_file())
}

/// The numbers in a path, in order, so that `python3.12` sorts after `python3.9` and
/// `libonnxruntime.so.1.31.1` after `libonnxruntime.so.1.9.0`.
fn version_key(path: &Path) -> Vec<u64> {
    path.to_string_lossy()
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|d| d.parse().ok())
        .collect()
}
