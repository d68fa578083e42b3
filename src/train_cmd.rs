//! `nldf train`: the teacher and student trainers with progress, logging, checkpoints and
//! Ctrl-C handling.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;

use nldf_train::config::RunConfig;

use crate::progress::progress_bar;

#[derive(Subcommand, Debug)]
pub enum TrainCommand {
    /// Train the audio-conditioned NeRF teacher on a dataset.
    Teacher(TeacherArgs),
    /// Distil the light-field student from a trained teacher (RUN/teacher) into RUN/student.
    Student(StudentArgs),
}

/// Student depths of the paper's Table 3 (width 256), plus a tiny one for smoke runs.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum StudentDepth {
    #[value(name = "28")]
    D28,
    #[value(name = "50")]
    D50,
    #[value(name = "88")]
    D88,
    /// 6 x 32 with 4 beam points: tests and smoke runs.
    Tiny,
}

impl StudentDepth {
    /// The preset's network configuration.
    pub fn config(self) -> nldf_train::student::StudentConfig {
        use nldf_train::student::StudentConfig;
        match self {
            StudentDepth::D28 => StudentConfig::paper_d28(),
            StudentDepth::D50 => StudentConfig::paper_d50(),
            StudentDepth::D88 => StudentConfig::paper_d88(),
            StudentDepth::Tiny => StudentConfig::tiny(),
        }
    }
}

#[derive(clap::Args, Debug, Clone)]
pub struct StudentArgs {
    /// Dataset folder the teacher was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder: the teacher is read from RUN/teacher, the student goes to RUN/student.
    #[arg(long)]
    pub run: PathBuf,
    /// Layers of the residual MLP at width 256 (paper Table 3).
    #[arg(long, value_enum, default_value_t = StudentDepth::D88)]
    pub depth: StudentDepth,
    /// Hidden width (overrides the preset's 256).
    #[arg(long)]
    pub width: Option<usize>,
    /// Train on pixels alone (Eq. 8), without the teacher's segment colours.
    #[arg(long)]
    pub no_distill: bool,
    /// Train without the active beam pool.
    #[arg(long)]
    pub no_pool: bool,
    /// Pseudo views rendered by the teacher besides the training frames (poses turned
    /// about the head, audio codes of two frames mixed; default 0: none).
    #[arg(long)]
    pub pseudo_frames: Option<usize>,
    /// JSON run configuration ({"model": {...}, "train": {...}}; missing fields take the
    /// defaults; --depth, --width, --no-distill, --no-pool and --pseudo-frames are ignored
    /// with it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Total training steps (overrides the configuration; with --resume, extends the run).
    #[arg(long)]
    pub iters: Option<usize>,
    /// Training time limit in minutes (the run validates and checkpoints when it is spent).
    #[arg(long)]
    pub minutes: Option<f64>,
    /// Folder of the student inside RUN (default `student`).
    #[arg(long, default_value = "student")]
    pub name: String,
    /// Continue the student from its last checkpoint.
    #[arg(long)]
    pub resume: bool,
}

/// Teacher presets.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum TeacherPreset {
    /// 6 x 128, 32 samples inside the head's bounds: for 2-core machines.
    Small,
    /// AD-NeRF's 8 x 256 with 64 + 128 samples.
    AdNerf,
    /// 2 x 32, for tests and smoke runs.
    Tiny,
}

#[derive(clap::Args, Debug)]
pub struct TeacherArgs {
    /// Dataset folder in AD-NeRF's layout (e.g. one written by `nldf synth`).
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder; the teacher goes to RUN/teacher.
    #[arg(long)]
    pub run: PathBuf,
    /// Network preset (ignored with --config or --resume).
    #[arg(long, value_enum, default_value_t = TeacherPreset::Small)]
    pub preset: TeacherPreset,
    /// JSON run configuration ({"model": {...}, "train": {...}}; missing fields take the
    /// defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Total training steps (overrides the configuration; with --resume, extends the run).
    #[arg(long)]
    pub iters: Option<usize>,
    /// Continue the run in RUN/teacher from its last checkpoint.
    #[arg(long)]
    pub resume: bool,
    /// Which audio features to train on: `auto` (the default) takes nldf's own log-mel
    /// features, from aud.npy when aud.json says nldf made it, otherwise computed from
    /// aud.wav; `wav` always computes them from aud.wav; `npy` takes aud.npy as it is
    /// (e.g. AD-NeRF's DeepSpeech features, which then must be given to every render).
    #[arg(long, value_enum, default_value_t = AudioFeaturesArg::Auto)]
    pub audio_features: AudioFeaturesArg,
}

/// Which audio features a teacher trains on.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AudioFeaturesArg {
    /// nldf's own features: aud.npy when nldf made it, else computed from aud.wav.
    Auto,
    /// nldf's features computed from aud.wav.
    Wav,
    /// aud.npy as it is, whichever front end made it.
    Npy,
}

impl AudioFeaturesArg {
    /// The dataset reading this choice asks for.
    pub fn choice(self) -> nldf_core::dataset::AudioChoice {
        use nldf_core::audio::{FeatureConfig, FeatureSource};
        use nldf_core::dataset::AudioChoice;
        match self {
            AudioFeaturesArg::Auto => AudioChoice::Auto,
            AudioFeaturesArg::Wav => {
                AudioChoice::Matching(FeatureSource::Nldf(FeatureConfig::default()))
            }
            AudioFeaturesArg::Npy => AudioChoice::Npy,
        }
    }
}

/// Prints which audio features a stage reads, and from which file.
pub fn say_audio(data: &nldf_train::data::TrainData) {
    eprintln!(
        "audio features: {} from {}",
        data.dataset.audio_source.describe(),
        data.dataset.audio_file.display()
    );
}

impl TeacherPreset {
    /// The preset's network configuration.
    pub fn config(self) -> nldf_train::config::TeacherConfig {
        use nldf_train::config::TeacherConfig;
        match self {
            TeacherPreset::Small => TeacherConfig::small(),
            TeacherPreset::AdNerf => TeacherConfig::ad_nerf(),
            TeacherPreset::Tiny => TeacherConfig::tiny(),
        }
    }
}

/// Runs a `nldf train` subcommand.
pub fn run(cmd: TrainCommand) -> Result<()> {
    match cmd {
        TrainCommand::Teacher(args) => run_teacher_with(args, None),
        TrainCommand::Student(args) => run_student(args).map(|_| ()),
    }
}

/// Refuses to overwrite a trained stage without `--resume`, or to resume a missing one.
fn check_resume(dir: &std::path::Path, what: &str, resume: bool) -> Result<()> {
    let exists = dir.join(nldf_core::run_files::MODEL_FILE).is_file();
    if exists && !resume {
        anyhow::bail!(
            "{} already holds a {what}; pass --resume to continue it or choose another --run",
            dir.display()
        );
    }
    if resume && !exists {
        anyhow::bail!("{} holds no {what} checkpoint to resume", dir.display());
    }
    Ok(())
}

/// Prints the files a stage wrote.
fn list_outputs(dir: &std::path::Path, files: &[&str]) {
    println!("wrote to {}:", dir.display());
    for f in files {
        println!("  {}", dir.join(f).display());
    }
}

/// Sets the returned flag on Ctrl-C (one handler per process, shared by every stage).
fn stop_on_ctrl_c() -> Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{Arc, OnceLock};
    static STOP: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    if let Some(s) = STOP.get() {
        return Ok(s.clone());
    }
    let flag = Arc::new(AtomicBool::new(false));
    let handler = flag.clone();
    ctrlc::set_handler(move || handler.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    Ok(STOP.get_or_init(|| flag).clone())
}

/// Runs a training loop behind a progress bar labelled `what`; prints validations as they
/// come and the final scores as JSON.
fn train_with_progress(
    what: &str,
    run: &mut dyn nldf_train::run_loop::TrainingRun,
    data: &nldf_train::data::TrainData,
) -> Result<Option<nldf_train::scores::Scores>> {
    use nldf_train::run_loop::{Event, train_loop};
    use std::sync::atomic::Ordering;
    let stop = stop_on_ctrl_c()?;
    let bar = progress_bar(run.schedule().iters as u64, what);
    bar.set_position(run.step() as u64);
    let mut last_val = String::new();
    let scores = train_loop(run, data, &stop, &mut |e| match e {
        Event::Step {
            step,
            loss,
            psnr,
            rays_per_s,
        } => {
            bar.set_position(*step as u64);
            bar.set_message(format!(
                "{what} loss {loss:.2e} psnr {psnr:.2} dB {rays_per_s:.0} rays/s{last_val}"
            ));
        }
        Event::Validation { step, scores } => {
            last_val = format!(" | val {:.2} dB", scores.psnr);
            bar.println(format!(
                "step {step}: validation PSNR {:.2} dB, SSIM {:.4}{}",
                scores.psnr,
                scores.ssim,
                match (scores.face_psnr, scores.mouth_psnr) {
                    (Some(f), Some(m)) => format!(", face {f:.2} dB, mouth {m:.2} dB"),
                    _ => String::new(),
                }
            ));
        }
        Event::Checkpoint { .. } => {}
    })?;
    bar.finish_and_clear();
    if stop.load(Ordering::Relaxed) {
        println!(
            "interrupted at step {}; checkpoint written, continue with --resume",
            run.step()
        );
    }
    if let Some(s) = scores {
        println!(
            "{}",
            serde_json::to_string(
                &serde_json::json!({"stage": what, "step": run.step(), "val": s})
            )?
        );
    }
    Ok(scores)
}

/// Trains (or resumes) a student; returns its final validation scores when it ran to the
/// end.
pub fn run_student(args: StudentArgs) -> Result<Option<nldf_train::scores::Scores>> {
    use nldf_core::dataset::AudioChoice;
    use nldf_train::config::StudentRunConfig;
    use nldf_train::data::TrainData;
    use nldf_train::student_trainer::StudentRun;
    use nldf_train::teacher_trainer::TeacherRun;

    let dir = args.run.join(&args.name);
    let teacher_dir = args.run.join("teacher");
    check_resume(&dir, "student", args.resume)?;
    let cfg = if args.resume {
        None
    } else {
        let mut cfg = match &args.config {
            Some(path) => nldf_train::config::read_config::<StudentRunConfig>(path)?,
            None => {
                let mut cfg = StudentRunConfig {
                    model: args.depth.config(),
                    ..StudentRunConfig::default()
                };
                if let Some(w) = args.width {
                    cfg.model.width = w;
                }
                cfg.train.distill = !args.no_distill;
                cfg.train.pool = !args.no_pool;
                if let Some(n) = args.pseudo_frames {
                    cfg.train.pseudo_frames = n;
                }
                cfg
            }
        };
        if let Some(n) = args.iters {
            cfg.train.iters = n;
            cfg.train.lr_decay_steps = n;
        }
        cfg.check().with_context(|| match &args.config {
            Some(path) => format!("{}: invalid configuration", path.display()),
            None => "invalid configuration".to_string(),
        })?;
        Some(cfg)
    };
    let teacher = if teacher_dir.join(nldf_core::run_files::MODEL_FILE).is_file() {
        Some(TeacherRun::open(&teacher_dir, false)?)
    } else {
        None
    };
    eprintln!("loading {}", args.data.display());
    // The teacher's audio features, or a resumed student's own.
    let audio = match (&teacher, &cfg) {
        (Some(t), _) => AudioChoice::Matching(t.cfg.model.audio.features.clone()),
        (None, None) => {
            let c: StudentRunConfig = nldf_train::config::read_config(&dir.join("config.json"))?;
            AudioChoice::Matching(c.model.audio.features)
        }
        (None, Some(_)) => AudioChoice::Auto,
    };
    let data = TrainData::open_with(&args.data, true, &audio)?;
    say_audio(&data);
    let mut run = match cfg {
        Some(cfg) => {
            if cfg.train.distill && teacher.is_none() {
                anyhow::bail!(
                    "{} holds no teacher to distil from; train one with `nldf train teacher --run {}` or pass --no-distill",
                    teacher_dir.display(),
                    args.run.display()
                );
            }
            StudentRun::create(&dir, cfg, &data, teacher.as_ref())?
        }
        None => {
            let mut run = StudentRun::open(&dir, true)?;
            if let Some(n) = args.iters {
                run.cfg.train.iters = n;
            }
            eprintln!("resuming at step {}", run.step);
            run
        }
    };
    if let Some(m) = args.minutes {
        run.cfg.train.time_budget_s = m * 60.0;
    }
    let bar = progress_bar(0, "teacher targets");
    run.prepare(&data, teacher.as_ref(), &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    let scores = train_with_progress("student", &mut run, &data)?;
    list_outputs(
        &dir,
        &[
            "config.json",
            "render.json",
            "model.safetensors",
            "train_state.safetensors",
            "pool.safetensors",
            "targets.safetensors",
            "log.csv",
            "training_curve.png",
        ],
    );
    Ok(scores)
}

/// Trains (or resumes) a teacher; `budget_s` caps its training time.
pub fn run_teacher_with(args: TeacherArgs, budget_s: Option<f64>) -> Result<()> {
    use nldf_train::config::TeacherRunConfig;
    use nldf_train::data::TrainData;
    use nldf_train::teacher_trainer::TeacherRun;

    let dir = args.run.join("teacher");
    check_resume(&dir, "teacher", args.resume)?;
    let cfg = if args.resume {
        None
    } else {
        let mut cfg = match &args.config {
            Some(path) => nldf_train::config::read_config::<TeacherRunConfig>(path)?,
            None => TeacherRunConfig {
                model: args.preset.config(),
                ..TeacherRunConfig::default()
            },
        };
        if let Some(n) = args.iters {
            cfg.train.iters = n;
        }
        cfg.check().with_context(|| match &args.config {
            Some(path) => format!("{}: invalid configuration", path.display()),
            None => "invalid configuration".to_string(),
        })?;
        Some(cfg)
    };

    eprintln!("loading {}", args.data.display());
    let audio = match &cfg {
        Some(_) => args.audio_features.choice(),
        None => {
            let c: TeacherRunConfig = nldf_train::config::read_config(&dir.join("config.json"))?;
            nldf_core::dataset::AudioChoice::Matching(c.model.audio.features)
        }
    };
    let data = TrainData::open_with(&args.data, true, &audio)?;
    say_audio(&data);
    let mut run = match cfg {
        Some(cfg) => TeacherRun::create(&dir, cfg, &data)?,
        None => {
            let mut run = TeacherRun::open(&dir, true)?;
            if let Some(n) = args.iters {
                run.cfg.train.iters = n;
            }
            eprintln!("resuming at step {}", run.step);
            run
        }
    };
    if let Some(b) = budget_s {
        run.cfg.train.time_budget_s = b;
    }
    train_with_progress("teacher", &mut run, &data)?;
    list_outputs(
        &dir,
        &[
            "config.json",
            "model.safetensors",
            "train_state.safetensors",
            "log.csv",
            "training_curve.png",
        ],
    );
    Ok(())
}
