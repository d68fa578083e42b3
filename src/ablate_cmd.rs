//! `nldf ablate`: the paper's Tables 1-3 on one dataset, plus a pixels-only student given
//! the same total wall time as the teacher and the distilled student together
//! ([`nldf_train::job::ablation`]).

use std::path::PathBuf;

use anyhow::Result;
use nldf_train::job::JobEvent;
use nldf_train::job::ablation::AblationJob;
use nldf_train::job::posed::PosedJob;
use nldf_train::trainers::config::StudentTrainConfig;

use crate::presets::StudentPreset;
use crate::progress::{EventPrinter, stop_flag};

#[derive(clap::Args, Debug)]
pub struct AblateArgs {
    /// Dataset folder the teacher was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder with a trained RUN/teacher; variants go to RUN/ablate_<name>.
    #[arg(long)]
    pub run: PathBuf,
    /// Training steps of every fixed-iteration variant.
    #[arg(long, default_value_t = 1000)]
    pub iters: usize,
    /// Depth of the distillation and pool comparisons (Tables 1 and 2).
    #[arg(long, value_enum, default_value_t = StudentPreset::D88)]
    pub depth: StudentPreset,
    /// Hidden width of every variant (the paper: 256).
    #[arg(long)]
    pub width: Option<usize>,
    /// Depths of Table 3.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [StudentPreset::D28, StudentPreset::D50, StudentPreset::D88])]
    pub depths: Vec<StudentPreset>,
    /// Skip the wall-time-matched pixels-only student.
    #[arg(long)]
    pub no_wall_time: bool,
    /// Run the posed ablation instead, with this many student minutes after the teacher's:
    /// the teacher, a distilled student with pseudo views, one without and a pixels-only
    /// student (given the teacher's minutes too), scored on the val, novel and voice
    /// splits, with a pose-sweep strip (RUN/posed.md, RUN/posed_sweep.png).
    #[arg(long)]
    pub posed_minutes: Option<f64>,
    /// Pseudo views of the posed ablation's student that has them.
    #[arg(long, default_value_t = 2000)]
    pub pseudo_frames: usize,
    /// Their pose range, as a factor of the recorded yaw and pitch range.
    #[arg(long, default_value_t = 2.0)]
    pub pose_range: f32,
    /// Hit pixels the teacher renders per pseudo view (0: all).
    #[arg(long, default_value_t = StudentTrainConfig::default().pseudo_rays)]
    pub pseudo_rays: usize,
    /// Frames scored per split in the posed ablation (default: all).
    #[arg(long)]
    pub frames: Option<usize>,
}

/// The name of a depth in folder names and tables.
fn depth_name(d: StudentPreset) -> String {
    match d {
        StudentPreset::D28 => "28".to_string(),
        StudentPreset::D50 => "50".to_string(),
        StudentPreset::D88 => "88".to_string(),
        StudentPreset::D28W128 => "28x128".to_string(),
        StudentPreset::Realtime => "realtime".to_string(),
        StudentPreset::Tiny => "tiny".to_string(),
    }
}

/// Runs `nldf ablate`.
pub fn run(args: AblateArgs) -> Result<()> {
    let shape = |d: StudentPreset| {
        let mut cfg = d.config();
        if let Some(w) = args.width {
            cfg.width = w;
        }
        (depth_name(d), cfg)
    };
    let stop = stop_flag();
    let mut printer = EventPrinter::default();
    let mut show = |e: &JobEvent| printer.show(e);
    if let Some(minutes) = args.posed_minutes {
        let job = PosedJob {
            data: args.data.clone(),
            run: args.run.clone(),
            model: shape(args.depth).1,
            minutes,
            pseudo_frames: args.pseudo_frames,
            pose_range: args.pose_range,
            pseudo_rays: args.pseudo_rays,
            frames: args.frames,
        };
        let report = job.run(&stop, &mut show)?;
        print_report(&report.markdown, &report.files);
        return Ok(());
    }
    let job = AblationJob {
        data: args.data.clone(),
        run: args.run.clone(),
        iters: args.iters,
        model: shape(args.depth),
        depths: args.depths.iter().map(|&d| shape(d)).collect(),
        wall_time: !args.no_wall_time,
    };
    let report = job.plan()?.run(&stop, &mut show)?;
    print_report(&report.markdown, &report.files);
    Ok(())
}

/// Prints an ablation's table and the files it wrote.
fn print_report(markdown: &str, files: &[PathBuf]) {
    print!("{markdown}");
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    println!("wrote {}", names.join(", "));
}
