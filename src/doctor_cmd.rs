//! `nldf doctor`: what nldf finds on this machine (CPU features, threads, onnxruntime,
//! ffmpeg, Python), one line each.

use anyhow::Result;

/// Runs `nldf doctor`.
pub fn run() -> Result<()> {
    let findings = nldf_infer::doctor::findings();
    let width = findings.iter().map(|f| f.what.len()).max().unwrap_or(0);
    for f in findings {
        println!("{:width$}  {}", f.what, f.found);
    }
    Ok(())
}
