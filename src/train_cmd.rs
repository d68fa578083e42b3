//! `nldf train`: the teacher and student trainers with progress, logging, checkpoints and
//! Ctrl-C handling.

use std::path::{Path, PathBuf};

use anyhow::Result;
use clap::Subcommand;
use nldf_core::run_files::{CONFIG_FILE, TEACHER_DIR};

use nldf_train::job::JobEvent;
use nldf_train::job::student::{PseudoSettings, StudentJob, StudentSource};
use nldf_train::job::teacher::{TeacherJob, TeacherSource};

use crate::presets::{StudentPreset, TeacherPreset};
use crate::progress::{EventPrinter, stop_flag};

/// `nldf train`: one stage with a subcommand, or with `--data DIR --run RUN` the whole
/// recipe of `nldf demo` on that dataset.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true)]
pub struct TrainArgs {
    #[command(subcommand)]
    pub command: Option<TrainCommand>,
    #[command(flatten)]
    pub recipe: RecipeArgs,
}

/// The whole recipe on a dataset: teacher, distilled real-time student with pseudo views,
/// ONNX export, scores on the held-out splits the dataset has, and a video.
#[derive(clap::Args, Debug)]
pub struct RecipeArgs {
    /// Dataset folder in AD-NeRF's layout (read in place; nothing is written into it).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Run folder: RUN/teacher, RUN/student, RUN/model.onnx, RUN/eval/<split>, RUN/video.
    #[arg(long)]
    pub run: Option<PathBuf>,
    #[command(flatten)]
    pub stages: crate::demo_cmd::StageArgs,
}

#[derive(Subcommand, Debug)]
pub enum TrainCommand {
    /// Train the audio-conditioned NeRF teacher on a dataset.
    Teacher(TeacherArgs),
    /// Distil the light-field student from a trained teacher (RUN/teacher) into RUN/student.
    Student(StudentArgs),
    /// Train a learned upsampler over a trained student (RUN/<student>): the student
    /// evaluates one ray per `factor x factor` block and a small CNN makes the full-size
    /// frame from its features, learned from the recorded frames and the teacher's renders
    /// of pseudo views. Goes to RUN/<name>; `nldf eval` scores it beside the student.
    Upsampler(UpsamplerArgs),
    /// Give a trained upsampler (RUN/<name>) a mouth patch without training it again: the
    /// mouth's box, found from RUN/teacher's surface at the dataset's mouth pixels, saved as
    /// `model.mouth_patch` in its config.json, so that every frame's pixels whose rays meet
    /// it are the student's own rays (`nldf train upsampler` does this itself).
    MouthPatch(MouthPatchArgs),
    /// A short-lookahead student from a trained one (RUN/<student>, without audio
    /// attention): its audio encoder distilled again to read at most --lookahead-ms of
    /// future audio, the rest kept, into RUN/<name>, so that `nldf render --stream` shows
    /// each frame sooner.
    Lookahead(crate::lookahead_cmd::LookaheadArgs),
}

#[derive(clap::Args, Debug)]
pub struct UpsamplerArgs {
    /// Dataset folder the student was trained on (the output size is its frames').
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder holding RUN/teacher and the student.
    #[arg(long)]
    pub run: PathBuf,
    /// The student's folder inside RUN (default `student`; overrides the configuration's
    /// `student`, saying so).
    #[arg(long)]
    pub student: Option<String>,
    /// Folder of the upsampler inside RUN.
    #[arg(long, default_value = "upsampler")]
    pub name: String,
    /// Output pixels per coarse ray along each side: 2, 4 or 8.
    #[arg(long, default_value_t = 4)]
    pub factor: usize,
    /// JSON configuration ({"model": {...}, "train": {...}}; missing fields take the
    /// defaults; overrides --factor).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Training steps (overrides the configuration).
    #[arg(long)]
    pub iters: Option<usize>,
}

#[derive(clap::Args, Debug)]
pub struct MouthPatchArgs {
    /// Dataset folder the student was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder holding RUN/teacher and the upsampler.
    #[arg(long)]
    pub run: PathBuf,
    /// Folder of the upsampler inside RUN.
    #[arg(long, default_value = "upsampler")]
    pub name: String,
}

#[derive(clap::Args, Debug, Clone)]
pub struct StudentArgs {
    /// Dataset folder the teacher was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder: the teacher is read from RUN/teacher, the student goes to RUN/student.
    #[arg(long)]
    pub run: PathBuf,
    /// A network preset: the paper's depths at width 256 (Table 3) or nldf's own, trained
    /// with the plain settings and the flags below. Without it, and without --width,
    /// --no-distill, --no-pool and the pseudo-view flags, the student is the recipe's (that
    /// of `nldf demo` and `nldf train --data`): the real-time 16 x 128 student distilled with
    /// 600 pseudo views at twice the recorded pose range, 36000 steps under a grid teacher
    /// in RUN/teacher, 4500 under an MLP teacher.
    #[arg(long, value_enum)]
    pub depth: Option<StudentPreset>,
    /// Hidden width (overrides the preset's 256).
    #[arg(long)]
    pub width: Option<usize>,
    /// Train on pixels alone (Eq. 8), without the teacher's segment colours.
    #[arg(long)]
    pub no_distill: bool,
    /// Train without the active beam pool.
    #[arg(long)]
    pub no_pool: bool,
    /// Pseudo views rendered by the teacher besides the training frames: training frames'
    /// cameras turned about the head to poses the recording lacks, each with its recorded
    /// audio (default 0: none).
    #[arg(long)]
    pub pseudo_frames: Option<usize>,
    /// How far the pseudo views reach: their yaw and pitch range as a factor of the
    /// recorded one (default 2: twice as wide).
    #[arg(long)]
    pub pose_range: Option<f32>,
    /// Hit pixels the teacher renders per pseudo view, its mouth first (default 1024; 0:
    /// all); fewer pixels per view buy more views for the same teacher time.
    #[arg(long)]
    pub pseudo_rays: Option<usize>,
    /// JSON run configuration ({"model": {...}, "train": {...}}; missing fields take the
    /// defaults; --depth, --width, --no-distill, --no-pool, --pseudo-frames, --pose-range and
    /// --pseudo-rays are ignored with it).
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

/// Runs `nldf train`.
pub fn run(args: TrainArgs) -> Result<()> {
    match args.command {
        Some(TrainCommand::Teacher(args)) => run_teacher(args),
        Some(TrainCommand::Student(args)) => run_student(args),
        Some(TrainCommand::Upsampler(args)) => run_upsampler(args),
        Some(TrainCommand::MouthPatch(args)) => run_mouth_patch(args),
        Some(TrainCommand::Lookahead(args)) => crate::lookahead_cmd::run(args),
        None => run_recipe(args.recipe),
    }
}

/// `nldf train --data DIR --run RUN`: `nldf demo`'s recipe on a dataset.
fn run_recipe(args: RecipeArgs) -> Result<()> {
    let (Some(data), Some(run)) = (args.data, args.run) else {
        anyhow::bail!(
            "nldf train needs a stage (teacher, student, upsampler) or --data DIR --run RUN \
             for the whole recipe"
        );
    };
    let recipe = nldf_pipeline::demo::DemoJob::with_teacher(run, args.stages.teacher.kind());
    let stages = &args.stages;
    let job = nldf_pipeline::demo::DemoJob {
        data: Some(data),
        teacher_iters: stages.teacher_iters.unwrap_or(recipe.teacher_iters),
        student_iters: stages.student_iters.unwrap_or(recipe.student_iters),
        teacher_cap_minutes: stages.minutes.unwrap_or(recipe.teacher_cap_minutes),
        student_cap_minutes: stages.student_minutes.unwrap_or(recipe.student_cap_minutes),
        train_seed: stages.train_seed,
        ..recipe
    };
    crate::demo_cmd::run_job(job, "nldf train")
}

impl StudentArgs {
    /// The network of the teacher in `RUN/teacher`, when it has been trained (the recipe's
    /// steps and learning rate depend on it).
    fn teacher_network(&self) -> Result<Option<nldf_train::trainers::config::TeacherConfig>> {
        let path = self.run.join(TEACHER_DIR).join(CONFIG_FILE);
        if !path.is_file() {
            return Ok(None);
        }
        let cfg: nldf_train::trainers::config::TeacherRunConfig =
            nldf_train::trainers::config::read_config(&path)?;
        Ok(Some(cfg.model))
    }

    /// The library job these flags ask for.
    pub fn job(&self) -> Result<StudentJob> {
        let plain = self.depth.is_some()
            || self.width.is_some()
            || self.no_distill
            || self.no_pool
            || self.pseudo_frames.is_some()
            || self.pose_range.is_some()
            || self.pseudo_rays.is_some();
        let source = match &self.config {
            Some(path) => StudentSource::File(path.clone()),
            None if !plain => {
                let defaults = nldf_pipeline::demo::DemoJob::defaults(self.run.clone());
                let teacher = self.teacher_network()?.unwrap_or(defaults.teacher);
                let iters = nldf_train::job::recipe::student_budget(&teacher).iters;
                let cfg = nldf_train::job::recipe::student_recipe(
                    &defaults.student,
                    &teacher,
                    true,
                    defaults.pseudo,
                    iters,
                )?;
                StudentSource::Config(Box::new(cfg))
            }
            None => {
                let mut model = self.depth.unwrap_or(StudentPreset::D88).config();
                if let Some(w) = self.width {
                    model.width = w;
                }
                StudentSource::Settings {
                    model: Box::new(model),
                    distill: !self.no_distill,
                    pool: !self.no_pool,
                    pseudo: PseudoSettings {
                        frames: self.pseudo_frames,
                        pose_range: self.pose_range,
                        rays: self.pseudo_rays,
                    },
                }
            }
        };
        Ok(StudentJob {
            data: self.data.clone(),
            run: self.run.clone(),
            name: self.name.clone(),
            source,
            iters: self.iters,
            minutes: self.minutes,
            resume: self.resume,
        })
    }
}

impl TeacherArgs {
    /// The library job these flags ask for.
    pub fn job(&self) -> TeacherJob {
        TeacherJob {
            data: self.data.clone(),
            run: self.run.clone(),
            source: match &self.config {
                Some(path) => TeacherSource::File(path.clone()),
                None => TeacherSource::Preset(Box::new(self.preset.config())),
            },
            iters: self.iters,
            resume: self.resume,
            audio: self.audio_features.choice(),
            budget_s: None,
        }
    }
}

/// Runs `nldf train student`.
fn run_student(args: StudentArgs) -> Result<()> {
    let stop = stop_flag();
    let mut printer = EventPrinter::default();
    let mut show = |e: &JobEvent| printer.show(e);
    args.job()?.plan(&mut show)?.run(&stop, &mut show)?;
    Ok(())
}

/// Runs `nldf train teacher`.
fn run_teacher(args: TeacherArgs) -> Result<()> {
    let stop = stop_flag();
    let mut printer = EventPrinter::default();
    let mut show = |e: &JobEvent| printer.show(e);
    args.job().plan(&mut show)?.run(&stop, &mut show)?;
    Ok(())
}

/// The student's folder inside a run when neither `--student` nor a configuration names one.
const DEFAULT_STUDENT: &str = "student";

/// The dataset `data`, its audio features read as the student in `student_dir` was
/// trained on them (an upsampler's data).
fn student_data(student_dir: &Path, data: &Path) -> Result<nldf_train::trainers::data::TrainData> {
    use anyhow::Context;
    use nldf_train::trainers::config::{StudentRunConfig, read_config};
    let student_cfg: StudentRunConfig =
        read_config(&student_dir.join(nldf_core::run_files::CONFIG_FILE))
            .with_context(|| format!("reading the student in {}", student_dir.display()))?;
    let audio = nldf_core::dataset::AudioChoice::Matching(student_cfg.model.audio.features);
    eprintln!("loading {}", data.display());
    Ok(nldf_train::trainers::data::TrainData::open_with(
        data, true, &audio,
    )?)
}

/// Runs `nldf train mouth-patch`.
fn run_mouth_patch(args: MouthPatchArgs) -> Result<()> {
    use anyhow::Context;
    use nldf_train::trainers::config::read_config;
    use nldf_train::trainers::upsampler_trainer::{UpsamplerRunConfig, attach_mouth_patch};
    let dir = args.run.join(&args.name);
    let cfg: UpsamplerRunConfig = read_config(&dir.join(nldf_core::run_files::CONFIG_FILE))
        .with_context(|| format!("reading the upsampler in {}", dir.display()))?;
    let student_dir = args.run.join(&cfg.student);
    let data = student_data(&student_dir, &args.data)?;
    eprintln!("finding the mouth's box from the teacher's surface at the mouth pixels");
    match attach_mouth_patch(&dir, &args.run, &data)? {
        Some(b) => println!(
            "mouth patch: the box {:?} to {:?} in head space, saved in {}",
            b.lo.to_array(),
            b.hi.to_array(),
            dir.join(nldf_core::run_files::CONFIG_FILE).display()
        ),
        None => anyhow::bail!(
            "{}: no mouth box found: its frames have no mouth region (no region labels, no \
             landmarks), or the teacher in {} holds no surface at their mouth pixels; {} is \
             unchanged",
            args.data.display(),
            args.run.join("teacher").display(),
            dir.join(nldf_core::run_files::CONFIG_FILE).display()
        ),
    }
    Ok(())
}

/// The upsampler's student: `--student` (saying so when it overrides the configuration's),
/// else the configuration's, else [`DEFAULT_STUDENT`].
fn choose_student(
    cfg: &mut nldf_train::trainers::upsampler_trainer::UpsamplerRunConfig,
    args: &UpsamplerArgs,
) {
    if let Some(flag) = &args.student {
        if let Some(file) = &args.config
            && !cfg.student.is_empty()
            && cfg.student != *flag
        {
            eprintln!(
                "--student {flag} overrides the student `{}` that {} names",
                cfg.student,
                file.display()
            );
        }
        cfg.student = flag.clone();
    } else if cfg.student.is_empty() {
        cfg.student = DEFAULT_STUDENT.to_string();
    }
}

/// Says what the upsampler's training found for its mouth patch (`None`: not asked).
fn say_mouth_patch(found: Option<bool>) {
    match found {
        Some(true) => println!("mouth patch: the mouth's box is saved with the upsampler"),
        Some(false) => eprintln!(
            "warning: train.mouth_patch is on but no mouth box was found (no mouth region in \
             the frames, or no teacher surface at their mouth pixels): the upsampler has no patch"
        ),
        None => {}
    }
}

/// Runs `nldf train upsampler`.
fn run_upsampler(args: UpsamplerArgs) -> Result<()> {
    use nldf_train::trainers::config::read_config;
    use nldf_train::trainers::upsampler_trainer::{UpsamplerRunConfig, train_upsampler};
    let mut cfg: UpsamplerRunConfig = match &args.config {
        Some(path) => read_config(path)?,
        None => UpsamplerRunConfig {
            model: nldf_core::upsampler_config::UpsamplerConfig::with_factor(args.factor),
            ..UpsamplerRunConfig::default()
        },
    };
    choose_student(&mut cfg, &args);
    if let Some(iters) = args.iters {
        cfg.train.iters = iters;
    }
    cfg.check()?;
    let student_dir = args.run.join(&cfg.student);
    let data = student_data(&student_dir, &args.data)?;
    let dir = args.run.join(&args.name);
    eprintln!(
        "upsampler x{} over {} into {}: coarse features and the teacher's crops first",
        cfg.model.factor,
        student_dir.display(),
        dir.display()
    );
    let iters = cfg.train.iters as u64;
    let mut bar: Option<indicatif::ProgressBar> = None;
    let stop = stop_flag();
    crate::progress::arm_ctrl_c();
    let report = train_upsampler(&dir, &args.run, cfg, &data, &stop, &mut |step, loss| {
        let bar = bar.get_or_insert_with(|| crate::progress::progress_bar(iters, "upsampler"));
        bar.set_position(step as u64);
        if step % 25 == 0 {
            bar.set_message(format!(
                "upsampler, PSNR {:.2}",
                nldf_core::metrics::psnr_from_mse(loss)
            ));
        }
    })?;
    if let Some(bar) = bar {
        bar.finish();
    }
    say_mouth_patch(report.mouth_patch);
    if report.steps < iters as usize {
        eprintln!(
            "stopped after {} of {iters} steps; the checkpoint holds them",
            report.steps
        );
    }
    println!(
        "upsampler: {} steps in {:.1} s after {:.1} s of preparation ({} recorded views, {} \
         teacher crops), final loss {:.3e}; weights in {}",
        report.steps,
        report.train_s,
        report.prepare_s,
        report.recorded_views,
        report.pseudo_crops,
        report.final_loss,
        dir.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests;
