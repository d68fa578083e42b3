//! A seeded, untrained student exported as ONNX over a dataset's camera, bounds and
//! background: a model of the real size to try `nldf render` and to time the backends
//! without training one first.
//!
//! Usage: cargo run --example seeded_model -- DATASET OUT_DIR [tiny|d28|d50|d88]
//! (writes OUT_DIR/student/ and OUT_DIR/model.onnx).

use std::collections::HashMap;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use nldf_core::bounds::dataset_bounds;
use nldf_core::dataset::Dataset;
use nldf_core::render_spec::{BACKGROUND_FILE, RENDER_SPEC_FILE, RenderSpec};
use nldf_export::{WeightType, export_student};
use nldf_train::networks::nn::{init_seeded, new_varmap};
use nldf_train::networks::student::{StudentConfig, student};
use nldf_train::trainers::checkpoint::{save_tensors, weights};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [data, out, rest @ ..] = args.as_slice() else {
        bail!("usage: seeded_model DATASET OUT_DIR [tiny|d28|d50|d88]");
    };
    let mut cfg = match rest.first().map(String::as_str).unwrap_or("d88") {
        "tiny" => StudentConfig::tiny(),
        "d28" => StudentConfig::paper_d28(),
        "d50" => StudentConfig::paper_d50(),
        "d88" => StudentConfig::paper_d88(),
        other => bail!("unknown preset {other:?} (tiny, d28, d50, d88)"),
    };
    let ds = Dataset::load(&PathBuf::from(data)).context("loading the dataset")?;
    cfg.audio.set_from(&ds);
    let spec = RenderSpec::of_dataset(&ds, dataset_bounds(&ds)?, cfg.audio.att_frames);
    let out = PathBuf::from(out);
    let student_dir = out.join("student");
    std::fs::create_dir_all(&student_dir)?;
    let (varmap, vb) = new_varmap();
    student(&cfg, vb)?;
    init_seeded(&varmap, 1)?;
    let metadata = HashMap::from([
        ("step".to_string(), "0".to_string()),
        ("kind".to_string(), "student".to_string()),
    ]);
    save_tensors(
        &student_dir.join("model.safetensors"),
        &weights(&varmap)?,
        metadata,
    )?;
    let config = serde_json::json!({ "model": cfg, "seed": 1 });
    std::fs::write(student_dir.join("config.json"), config.to_string())?;
    spec.save(&student_dir.join(RENDER_SPEC_FILE))?;
    ds.background.save_png(&student_dir.join(BACKGROUND_FILE))?;
    let report = export_student(&student_dir, &out.join("model.onnx"), WeightType::F32)?;
    println!(
        "wrote {} ({} x {})",
        report.path.display(),
        cfg.depth,
        cfg.width
    );
    Ok(())
}
