//! Writing a benchmark's report: its JSON and Markdown side by side, and the machine as a
//! table cell.

use std::path::{Path, PathBuf};

use nldf_core::host::Machine;
use serde::Serialize;

use crate::error::{Result, create_dir};

/// What a benchmark wrote: its Markdown (to print as well), the JSON and Markdown files and
/// any plots.
#[derive(Debug, Clone)]
pub struct Written {
    pub markdown: String,
    pub json: PathBuf,
    pub md: PathBuf,
    pub plots: Vec<PathBuf>,
}

/// The machine as a table cell: CPU, cores, commit, the load at the start and at the end,
/// and whether the run was forced above its load limit.
pub fn machine_cell(m: &Machine) -> String {
    format!(
        "{} ({} cores), commit {}, {}",
        m.cpu,
        m.cores,
        m.commit,
        crate::load::load_text(m)
    )
}

/// Writes `report` as `out/{stem}.json` and `markdown` as `out/{stem}.md`.
pub(crate) fn write_bench_files(
    out: &Path,
    stem: &str,
    report: &impl Serialize,
    markdown: String,
) -> Result<Written> {
    create_dir(out)?;
    let json = out.join(format!("{stem}.json"));
    let md = out.join(format!("{stem}.md"));
    // Through a JSON value, whose map orders the keys.
    nldf_core::files::write_json(&json, &serde_json::to_value(report)?)?;
    nldf_core::files::write_atomic(&md, markdown.as_bytes())?;
    Ok(Written {
        markdown,
        json,
        md,
        plots: Vec::new(),
    })
}
