//! `nldf doctor`: what nldf finds on this machine (CPU features, threads, onnxruntime,
//! ffmpeg, Python, `nldf prepare`'s face environment), one line each.

use anyhow::Result;

/// Runs `nldf doctor`.
pub fn run() -> Result<()> {
    let mut findings: Vec<(String, String)> = nldf_infer::doctor::findings()
        .into_iter()
        .map(|f| (f.what.to_string(), f.found))
        .collect();
    findings.push(("face environment".into(), face_env()));
    let width = findings.iter().map(|f| f.0.len()).max().unwrap_or(0);
    for (what, found) in findings {
        println!("{what:width$}  {found}");
    }
    Ok(())
}

/// Where `nldf prepare`'s face models are, and its ffmpeg.
fn face_env() -> String {
    use nldf_prepare::{face::FaceEnv, tools};
    let dir = match tools::face_env_dir() {
        Ok(d) => d,
        Err(e) => return format!("no place for it: {e}"),
    };
    match FaceEnv::open(&dir) {
        Some(_) => format!(
            "{} (mediapipe 0.10.21; ffmpeg {})",
            dir.display(),
            tools::ffmpeg().map_or_else(|e| e.to_string(), |p| p.display().to_string())
        ),
        None => format!(
            "not installed at {} (`nldf prepare --setup`, or the first `nldf prepare`, \
             installs it)",
            dir.display()
        ),
    }
}
