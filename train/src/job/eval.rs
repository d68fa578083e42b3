//! The evaluation job: the run's teacher and every student and upsampler beside it render
//! the frames of a split, scored against the ground truth (see [`crate::reports::eval`]).

use std::path::PathBuf;

use nldf_core::dataset::{AudioChoice, Dataset, Split};
use nldf_core::run_files::{RENDER_SPEC_FILE, has_checkpoint, teacher_dir};

use crate::error::{Error, Result};
use crate::job::{JobEvent, OnEvent, audio_note, mouth_note};
use crate::reports::eval::{Evaluation, FrameModel, eval_models_against};
use crate::trainers::data::TrainData;
use crate::trainers::student_trainer::StudentModel;
use crate::trainers::teacher_trainer::TeacherModel;
use crate::trainers::upsampler_trainer::{CoarseBilinear, UpsampledModel};

/// What `nldf eval` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalJob {
    /// The run folder: its teacher and every student folder in it are evaluated.
    pub run: PathBuf,
    /// The dataset the run was trained on.
    pub data: PathBuf,
    pub split: Split,
    /// At most this many frames, spread evenly over each kind of view the split holds.
    pub frames: Option<usize>,
    /// Output folder; default `RUN/eval/<split>`.
    pub out: Option<PathBuf>,
    /// Score against this dataset's frames of the same `img_id` instead of `data`'s own
    /// (see [`eval_models_against`]).
    pub against: Option<PathBuf>,
}

/// A checked evaluation: every model and the data loaded.
pub struct EvalPlan {
    /// The run's teacher.
    pub teacher: TeacherModel,
    /// Every student folder of the run, in name order.
    pub students: Vec<StudentModel>,
    /// Every upsampler folder of the run, in name order, each followed in the tables by its
    /// student on the same coarse grid upscaled bilinearly.
    pub upsamplers: Vec<(UpsampledModel, Option<CoarseBilinear>)>,
    /// The dataset with the teacher's audio features.
    pub data: TrainData,
    /// The split rendered.
    pub split: Split,
    /// At most this many frames of it.
    pub frames: Option<usize>,
    /// Where the renders, the grid and `metrics.json` go.
    pub out: PathBuf,
    /// The dataset scored against, when not `data`'s own frames.
    pub against: Option<Dataset>,
}

impl EvalJob {
    /// Opens the teacher and every student of the run (folders holding a student's render
    /// spec and weights) and loads the data with the teacher's audio features.
    pub fn plan(&self, on_event: OnEvent) -> Result<EvalPlan> {
        let name = self.split.name();
        let out = self
            .out
            .clone()
            .unwrap_or_else(|| self.run.join("eval").join(name));
        let dir = teacher_dir(&self.run);
        let teacher = TeacherModel::open(&dir)
            .map_err(|e| e.context(format!("loading the teacher from {}", dir.display())))?;
        let mut entries: Vec<PathBuf> = std::fs::read_dir(&self.run)
            .map_err(|e| Error::io(&self.run, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        let dirs: Vec<&PathBuf> = entries
            .iter()
            .filter(|p| p.join(RENDER_SPEC_FILE).is_file() && has_checkpoint(p))
            .collect();
        let up_dirs = entries.iter().filter(|p| UpsampledModel::is_upsampler(p));
        let mut upsamplers: Vec<(UpsampledModel, Option<CoarseBilinear>)> = Vec::new();
        for dir in up_dirs {
            let up = UpsampledModel::open(dir, &self.run)
                .map_err(|e| e.context(format!("loading the upsampler from {}", dir.display())))?;
            let factor = up.cfg.model.factor;
            // One bilinear baseline per student and factor.
            let seen = upsamplers
                .iter()
                .any(|(u, _)| u.cfg.student == up.cfg.student && u.cfg.model.factor == factor);
            let bilinear = if seen {
                None
            } else {
                let student = StudentModel::open(&self.run.join(&up.cfg.student))?;
                Some(CoarseBilinear { student, factor })
            };
            upsamplers.push((up, bilinear));
        }
        let students = dirs
            .iter()
            .map(|dir| {
                StudentModel::open(dir)
                    .map_err(|e| e.context(format!("loading the student from {}", dir.display())))
            })
            .collect::<Result<Vec<_>>>()?;
        let audio = AudioChoice::Matching(teacher.cfg.model.audio.features.clone());
        let data = TrainData::open_held_out(&self.data, false, &audio, self.split)?;
        on_event(&audio_note(&data));
        on_event(&mouth_note(&data));
        let against = match &self.against {
            Some(root) => {
                on_event(&JobEvent::Note(format!(
                    "scoring against the frames of {}",
                    root.display()
                )));
                Some(Dataset::load_held_out(root, &audio, self.split)?)
            }
            None => None,
        };
        Ok(EvalPlan {
            teacher,
            students,
            upsamplers,
            data,
            split: self.split,
            frames: self.frames,
            out,
            against,
        })
    }
}

impl EvalPlan {
    /// The models in the order they are evaluated: the teacher, then the students.
    pub fn models(&self) -> Vec<&dyn FrameModel> {
        let mut models: Vec<&dyn FrameModel> = vec![&self.teacher];
        models.extend(self.students.iter().map(|s| s as &dyn FrameModel));
        for (up, bilinear) in &self.upsamplers {
            models.push(up);
            if let Some(b) = bilinear {
                models.push(b);
            }
        }
        models
    }

    /// Frames the evaluation renders per model.
    pub fn n_frames(&self) -> usize {
        self.frames
            .unwrap_or(usize::MAX)
            .min(self.data.dataset.frames(self.split).len())
    }

    /// Renders and scores every model; a model that rendered a NaN or infinite pixel is an
    /// error after everything is written (its scores are void).
    pub fn run(&self, on_event: OnEvent) -> Result<Evaluation> {
        let total = self.n_frames();
        let mut done = 0;
        let evaluation = eval_models_against(
            &self.models(),
            &self.data,
            self.against.as_ref(),
            self.split,
            self.frames,
            &self.out,
            &mut || {
                done += 1;
                on_event(&JobEvent::Progress {
                    what: "rendering".into(),
                    done,
                    total,
                })
            },
        )?;
        Ok(evaluation)
    }
}
