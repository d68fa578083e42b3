//! `nldf export`: writes a run's trained student (with its audio encoder) as one ONNX model
//! whose metadata carries everything a foreign runtime needs to render a frame.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use nldf_export::{
    ExportReport, WeightType, export_frame, export_frame_int8, export_frame_upsampled_int8,
    export_student, export_student_int8, export_student_upsampled_int8,
};
use nldf_model::{read_frame_model, read_model};
use nldf_pipeline::quantize::calibrated_ranges;

#[derive(clap::Args, Debug)]
pub struct ExportArgs {
    /// Run folder (with a trained RUN/student).
    #[arg(long)]
    pub run: PathBuf,
    /// The student's folder inside RUN (another student of the run, e.g. an ablation's
    /// `posed_distilled`).
    #[arg(long, default_value = "student")]
    pub student: String,
    /// Output file (default RUN/model.onnx, or RUN/frame.onnx with --frame).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Export the frame graph: inputs the frame's audio samples and the camera pose, output
    /// the frame, with the audio front end, the rays, the head-bounds test and the
    /// compositing inside the graph, so that any ONNX runtime renders from it alone
    /// (docs/frame-graph.md). nldf's own commands render from the ray graph.
    #[arg(long)]
    pub frame: bool,
    /// A learned upsampler of the run (its folder inside RUN, e.g. `upsampler`) goes into
    /// the graph; the student runs on its coarse grid. Without --frame, the ray graph takes
    /// the coarse rays of the head's box and gives the box's pixels; `nldf render` finds
    /// the box (docs/sharp.md).
    #[arg(long)]
    pub upsampler: Option<String>,
    /// Store the weights in half precision (cast back to f32 in the graph): half the size.
    #[arg(long, conflicts_with = "int8")]
    pub fp16: bool,
    /// Do the per-ray products in int8 (weights symmetric with one scale per output
    /// channel, activations uint8 over ranges calibrated on training rays of --data):
    /// about a quarter of the size, and faster where the runtime has integer kernels
    /// (onnxruntime; `nldf bench render` measures it).
    #[arg(long, requires = "data")]
    pub int8: bool,
    /// The student's training data, whose frames calibrate --int8.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Training frames to calibrate --int8 on (their rays that meet the head's bounds).
    #[arg(long, default_value_t = 16)]
    pub calibration_frames: usize,
    /// With --int8, these per-ray products stay in f32, comma-separated by layer name
    /// (`mlp.input.beam`, `mlp.body.6.fc2`; an unknown name lists the student's): mixed
    /// precision for the layers whose int8 error costs the most (docs/sharp.md).
    #[arg(long, value_delimiter = ',', requires = "int8")]
    pub int8_f32: Vec<String>,
}

/// Runs `nldf export`.
pub fn run(args: ExportArgs) -> Result<()> {
    let student = args.run.join(&args.student);
    if !student.is_dir() {
        bail!(
            "{} has no trained student (expected {})",
            args.run.display(),
            student.display()
        );
    }
    let default_name = if args.frame {
        "frame.onnx"
    } else {
        "model.onnx"
    };
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.run.join(default_name));
    let weights = if args.fp16 {
        WeightType::F16
    } else if args.int8 {
        WeightType::Int8
    } else {
        WeightType::F32
    };
    let report = export(&args, &student, &out, weights)?;
    read_back(args.frame, &out)?;
    print_summary(&report, weights);
    Ok(())
}

/// Exports the student in `student` to `out` as the flags ask: a ray or frame graph, with
/// or without the upsampler, in `weights` (int8 calibrated on `--data`).
fn export(
    args: &ExportArgs,
    student: &Path,
    out: &Path,
    weights: WeightType,
) -> Result<ExportReport> {
    if let Some(name) = &args.upsampler {
        note_mouth_patch(&args.run.join(name), args.frame);
    }
    Ok(match (&args.data, weights) {
        (Some(data), WeightType::Int8) => {
            let export = || -> nldf_pipeline::Result<ExportReport> {
                let ranges =
                    calibrated_ranges(student, data, args.calibration_frames, &args.int8_f32)?;
                let up = args.upsampler.as_ref().map(|name| args.run.join(name));
                Ok(match (&up, args.frame) {
                    (Some(up), true) => export_frame_upsampled_int8(student, up, out, &ranges)?,
                    (Some(up), false) => export_student_upsampled_int8(student, up, out, &ranges)?,
                    (None, true) => export_frame_int8(student, out, &ranges)?,
                    (None, false) => export_student_int8(student, out, &ranges)?,
                })
            };
            export().with_context(|| {
                format!(
                    "exporting the student in {} in int8, calibrated on {}",
                    student.display(),
                    data.display()
                )
            })?
        }
        _ if args.upsampler.is_some() => {
            let name = args.upsampler.as_deref().unwrap_or_default();
            let dir = args.run.join(name);
            let export = if args.frame {
                nldf_export::export_frame_upsampled
            } else {
                nldf_export::export_student_upsampled
            };
            export(student, &dir, out, weights).with_context(|| {
                format!(
                    "exporting the student in {} with the upsampler in {} as a {} graph",
                    student.display(),
                    dir.display(),
                    if args.frame { "frame" } else { "ray" }
                )
            })?
        }
        _ if args.frame => export_frame(student, out, weights).with_context(|| {
            format!(
                "exporting the student in {} as a frame graph",
                student.display()
            )
        })?,
        _ => export_student(student, out, weights)
            .with_context(|| format!("exporting the student in {}", student.display()))?,
    })
}

/// Says whether the upsampler in `dir` has a mouth patch and which graph draws it: the frame
/// graph does, the ray graph (nldf's renderer) leaves it out.
fn note_mouth_patch(dir: &Path, frame: bool) {
    let path = dir.join(nldf_core::run_files::CONFIG_FILE);
    let Ok(config) = nldf_core::files::read_json::<serde_json::Value>(&path) else {
        return; // the export itself names what is wrong with the file
    };
    if config
        .pointer("/model/mouth_patch")
        .is_some_and(|b| !b.is_null())
    {
        let which = if frame {
            "the graph finds them"
        } else {
            "nldf render finds them and sends their rays (contract 6)"
        };
        println!(
            "mouth patch: the pixels whose rays meet the mouth's box are the student's own \
             rays, drawn over the upsampled frame ({which})"
        );
    }
}

/// Reads the written model back as every loader will; a frame graph's inputs are printed.
fn read_back(frame: bool, out: &Path) -> Result<()> {
    // Read it back as every loader will, so that a bad file never leaves this command.
    if frame {
        let model = read_frame_model(out)?;
        let a = &model.audio;
        println!(
            "frame graph: audio [{}] at {} Hz from sample {} + frame x {} (NaN off the \
             track), pose [4, 4], image [{}, {}, 3]",
            a.samples,
            a.sample_rate,
            a.offset,
            a.samples_per_frame,
            model.info.spec.intrinsics.height,
            model.info.spec.intrinsics.width
        );
    } else {
        read_model(out)?;
    }
    Ok(())
}

/// Prints what was exported: the student's shape, its upsampler and the file written.
fn print_summary(report: &ExportReport, weights: WeightType) {
    let info = &report.info;
    let k = &info.spec.intrinsics;
    println!(
        "student at step {}: {} layers x {}, K = {}, L = {}, M = {}, audio [{}, {}, {}]{}; \
         {}x{} image",
        info.step,
        info.network.depth,
        info.network.width,
        info.beam.n_points,
        info.beam.n_freqs,
        info.segments,
        info.audio.att_frames,
        info.audio.window,
        info.audio.n_features,
        if info.audio.attention {
            " with attention"
        } else {
            ""
        },
        k.width,
        k.height,
    );
    if let Some(up) = &info.upsample {
        println!(
            "learned upsampler x{}: rays on the {}x{} coarse grid, the CNN on the box around \
             those that meet the head, widened by {} coarse rays",
            up.factor,
            k.width as usize / up.factor,
            k.height as usize / up.factor,
            up.margin
        );
    }
    println!(
        "wrote {} ({:.2} MB, {} stored values, weights in {})",
        report.path.display(),
        report.bytes as f64 / 1e6,
        report.n_values,
        match weights {
            WeightType::F32 => "f32",
            WeightType::F16 => "f16",
            WeightType::Int8 => "int8 for the per-ray products, f32 elsewhere",
        }
    );
}
