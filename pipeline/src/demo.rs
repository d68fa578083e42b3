//! The whole pipeline on the embedded default, the synthetic talking head: generate the
//! scene, train the teacher within a time budget, train the student (on the recorded
//! pixels, or distilled from the teacher), export it as ONNX and evaluate both on the
//! held-out frames. A stage that already finished in the output folder is reused, and an
//! interrupted one resumes.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use nldf_core::dataset::{AudioChoice, Split};
use nldf_core::run_files::{ONNX_FILE, STUDENT_DIR, TEACHER_DIR, has_checkpoint};
use nldf_core::synth::{self, SynthConfig};

use nldf_train::job::eval::EvalJob;
use nldf_train::job::recipe::{
    DEMO_HOLD, DEMO_PSEUDO, DEMO_TEACHER_CAP_MINUTES, TeacherKind, student_budget, student_recipe,
};
use nldf_train::job::student::{PseudoSettings, StudentJob, StudentSource};
use nldf_train::job::teacher::{TeacherJob, TeacherSource};
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::networks::student::StudentConfig;
use nldf_train::reports::eval::Evaluation;
use nldf_train::trainers::config::TeacherConfig;
use nldf_train::trainers::timing::{TIMING_FILE, Timing};

use crate::error::{Error, Result};

/// Where the demo keeps its own parts of the breakdown (scene, export, evaluation).
const DEMO_TIMING_DIR: &str = "eval";

/// What `nldf demo` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoJob {
    /// The run folder: the dataset goes to `OUT/data`, the teacher to `OUT/teacher`, the
    /// student to `OUT/student`, the model to `OUT/model.onnx`, the evaluations to
    /// `OUT/eval/<split>`.
    pub out: PathBuf,
    /// A dataset to train on instead of the synthetic scene (`nldf train --data`): read in
    /// place, nothing written into it. `None`: the synthetic scene is made in `OUT/data`.
    pub data: Option<PathBuf>,
    /// The synthetic scene (seed, length, size), when no dataset is given.
    pub scene: SynthConfig,
    /// The teacher's network.
    pub teacher: TeacherConfig,
    /// Teacher training steps: the recipe is pinned in steps, so that its scores do not
    /// move with the machine.
    pub teacher_iters: usize,
    /// The teacher's learning rate before it decays.
    pub teacher_lr: f64,
    /// A wall-clock cap on the teacher in minutes, which only stops it (and says so).
    pub teacher_cap_minutes: f64,
    /// The student's network.
    pub student: StudentConfig,
    /// Student training steps (0 skips the student and the export).
    pub student_iters: usize,
    /// A wall-clock cap on the student in minutes (teacher targets included).
    pub student_cap_minutes: f64,
    /// Distil the student from the teacher (Eq. 9), with pseudo views at poses beyond the
    /// recorded ones, or train it on the recorded pixels alone (`--pixels-only`, the
    /// comparison).
    pub student_distill: bool,
    /// The distilled student's pseudo views, where they differ from the demo's.
    pub pseudo: PseudoSettings,
    /// Held-out splits evaluated (those the scene has).
    pub splits: Vec<Split>,
    /// Seed of the teacher's and the student's ray batches and initial weights (the
    /// recipe's: 0), so that a second run of the recipe on one dataset shows its spread.
    pub train_seed: u64,
}

/// What the demo made.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoReport {
    /// The exported student, when one was trained.
    pub model: Option<PathBuf>,
    /// The evaluation of the teacher and the student on the validation frames.
    pub evaluation: Evaluation,
    /// Where that evaluation was written.
    pub eval_dir: PathBuf,
    /// Every split's evaluation, `val` first.
    pub splits: Vec<(Split, Evaluation)>,
}

impl DemoJob {
    /// The demo as `nldf demo` runs it by default, into `out`: the synthetic scene of seed
    /// 0 at 128 x 128 (supersampled 3x), the recipe's default teacher ([`TeacherKind`]'s
    /// default, the grid teacher) for its steps, then the real-time student (16 x 128,
    /// K = 8) with opacity, distilled from the teacher with pseudo views, for the steps
    /// [`student_budget`] gives under that teacher, evaluated on `val`, `novel` and
    /// `voice`. The command line changes only what its flags say; the tests shrink the
    /// sizes and steps and keep the recipe.
    pub fn defaults(out: PathBuf) -> DemoJob {
        DemoJob::with_teacher(out, TeacherKind::default())
    }

    /// [`DemoJob::defaults`] with the recipe of `kind`: its teacher's network, steps and
    /// learning rate, and the steps and cap [`student_budget`] gives its student.
    pub fn with_teacher(out: PathBuf, kind: TeacherKind) -> DemoJob {
        let (teacher, teacher_iters, teacher_lr) = kind.recipe();
        let budget = student_budget(&teacher);
        DemoJob {
            out,
            data: None,
            scene: SynthConfig {
                size: 128,
                supersample: 3,
                ..SynthConfig::default()
            },
            teacher,
            teacher_iters,
            teacher_lr,
            teacher_cap_minutes: DEMO_TEACHER_CAP_MINUTES,
            student: StudentConfig::realtime(),
            student_iters: budget.iters,
            student_cap_minutes: budget.cap_minutes,
            student_distill: true,
            pseudo: DEMO_PSEUDO,
            splits: vec![Split::Val, Split::Novel, Split::Voice],
            train_seed: 0,
        }
    }

    /// Checks the steps, caps and the scene's settings; nothing is made yet.
    pub fn check(&self) -> Result<()> {
        if self.teacher_iters == 0 {
            return Err(Error::Argument(
                "the teacher needs at least one step".into(),
            ));
        }
        if !(self.teacher_lr.is_finite() && self.teacher_lr > 0.0 && self.teacher_lr <= 1.0) {
            return Err(Error::Argument(format!(
                "the teacher's learning rate must be in (0, 1], got {}",
                self.teacher_lr
            )));
        }
        for (what, minutes) in [
            ("teacher", self.teacher_cap_minutes),
            ("student", self.student_cap_minutes),
        ] {
            if !(minutes.is_finite() && minutes > 0.0) {
                return Err(Error::Argument(format!(
                    "the {what}'s wall-clock cap must be a finite number of minutes above 0, got {minutes}"
                )));
            }
        }
        if self.splits.first() != Some(&Split::Val) {
            return Err(Error::Argument(
                "the demo evaluates `val` first; other splits follow it".into(),
            ));
        }
        match &self.data {
            Some(data) if !data.is_dir() => Err(Error::Argument(format!(
                "{}: no such dataset folder",
                data.display()
            ))),
            Some(_) => Ok(()),
            None => Ok(synth::validate(&self.scene)?),
        }
    }

    /// The dataset the stages train on: the given one, or the synthetic scene's folder.
    pub fn data_dir(&self) -> PathBuf {
        self.data.clone().unwrap_or_else(|| self.out.join("data"))
    }

    /// Writes the whole run's time breakdown, `OUT/timing.json`: the scene, each stage's
    /// parts (from its own `timing.json`), the export and the evaluation.
    fn save_timing(&self, own: &Timing, on_event: OnEvent) -> Result<()> {
        // The scene first, then the stages, then the demo's other parts.
        let own_parts = |scene: bool| Timing {
            parts: own
                .parts
                .iter()
                .filter(|p| (p.what == "synthetic scene") == scene)
                .cloned()
                .collect(),
        };
        let mut all = own_parts(true);
        for stage in [TEACHER_DIR, STUDENT_DIR] {
            all.absorb(&format!("{stage}: "), &Timing::open(&self.out.join(stage))?);
        }
        all.absorb("", &own_parts(false));
        // The demo's own parts are kept apart, so that a rerun adds to them only.
        let own_dir = self.out.join(DEMO_TIMING_DIR);
        std::fs::create_dir_all(&own_dir).map_err(|e| Error::io(&own_dir, e))?;
        own.save(&own_dir)?;
        all.save(&self.out)?;
        on_event(&JobEvent::Note(format!(
            "time of the whole demo ({}):",
            self.out.join(TIMING_FILE).display()
        )));
        for line in all.lines() {
            on_event(&JobEvent::Note(format!("  {line}")));
        }
        Ok(())
    }

    /// Runs every stage in turn; `stop` ends the training stage under way with a checkpoint
    /// and skips the rest. The evaluation is returned even when a model rendered NaN or
    /// infinite pixels: see [`Evaluation::check_finite`].
    pub fn run(&self, stop: &AtomicBool, on_event: OnEvent) -> Result<Option<DemoReport>> {
        self.check()?;
        let mut own = Timing::open(&self.out.join(DEMO_TIMING_DIR))?;
        let data = self.data_dir();
        self.prepare_scene(&data, &mut own, on_event)?;
        self.train_teacher(&data, stop, on_event)?;
        if stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
        let mut model = None;
        if self.student_iters > 0 {
            self.train_student(&data, stop, on_event)?;
            if stop.load(Ordering::Relaxed) {
                return Ok(None);
            }
            model = Some(self.export_onnx(&mut own, on_event)?);
        }
        let (splits, eval_dir) = self.evaluate(&data, &mut own, on_event)?;
        self.save_timing(&own, on_event)?;
        let evaluation = splits
            .first()
            .map(|(_, e)| e.clone())
            .ok_or_else(|| Error::Argument("the demo evaluated no split".into()))?;
        Ok(Some(DemoReport {
            model,
            evaluation,
            eval_dir,
            splits,
        }))
    }

    /// Announces the dataset, and renders the synthetic scene into `data` unless it is
    /// there already (or a dataset was given), adding its seconds to `own`.
    fn prepare_scene(&self, data: &Path, own: &mut Timing, on_event: OnEvent) -> Result<()> {
        let started = Instant::now();
        if self.data.is_some() {
            on_event(&JobEvent::Stage(format!(
                "dataset: {}{}",
                data.display(),
                size_note(data)
            )));
        } else if data.join(nldf_core::dataset::SCENE_FILE).is_file() {
            on_event(&JobEvent::Stage(format!(
                "synthetic scene: reusing {}",
                data.display()
            )));
        } else {
            on_event(&JobEvent::Stage(format!(
                "synthetic scene -> {}",
                data.display()
            )));
            let total = synth::frames_rendered(&self.scene);
            let done = std::sync::atomic::AtomicUsize::new(0);
            // The scene renders on its own thread; this one reports its frames as they come.
            let summary = std::thread::scope(|scope| {
                let synth = scope.spawn(|| {
                    synth::generate(&self.scene, None, data, false, &|| {
                        done.fetch_add(1, Ordering::Relaxed);
                    })
                });
                while !synth.is_finished() {
                    on_event(&JobEvent::Progress {
                        what: "synthetic frames".into(),
                        done: done.load(Ordering::Relaxed).min(total.saturating_sub(1)),
                        total,
                    });
                    std::thread::sleep(std::time::Duration::from_millis(200));
                }
                synth
                    .join()
                    .map_err(|_| Error::Argument("the synthetic scene's thread panicked".into()))
            })??;
            on_event(&JobEvent::Progress {
                what: "synthetic frames".into(),
                done: total,
                total,
            });
            on_event(&JobEvent::Wrote {
                dir: data.to_path_buf(),
                files: summary.files.iter().map(|(f, _)| data.join(f)).collect(),
            });
            own.add("synthetic scene", started.elapsed().as_secs_f64(), 1);
        }
        Ok(())
    }

    /// Trains (or resumes) the teacher on `data` with the demo's pinned steps, learning
    /// rate schedule and time cap.
    fn train_teacher(&self, data: &Path, stop: &AtomicBool, on_event: OnEvent) -> Result<()> {
        let teacher_dir = self.out.join(TEACHER_DIR);
        let resume = has_checkpoint(&teacher_dir);
        on_event(&JobEvent::Stage(format!(
            "teacher ({} steps, capped at {} min{}) -> {}",
            self.teacher_iters,
            self.teacher_cap_minutes,
            if resume { ", resuming" } else { "" },
            teacher_dir.display()
        )));
        let mut plan = TeacherJob {
            data: data.to_path_buf(),
            run: self.out.clone(),
            source: TeacherSource::Preset(Box::new(self.teacher.clone())),
            iters: Some(self.teacher_iters),
            resume,
            audio: AudioChoice::Auto,
            budget_s: None,
        }
        .plan(on_event)?;
        // The learning rate is held, then decays tenfold over the last 40 % of the pinned
        // steps (as the budgeted teacher's did over its minutes); the cap only stops.
        if !resume {
            plan.run.model.cfg.train.seed = self.train_seed;
            plan.run.model.cfg.train.lr = self.teacher_lr;
            let hold = (DEMO_HOLD * self.teacher_iters as f64).round() as usize;
            plan.run.model.cfg.train.lr_hold_steps = hold;
            plan.run.model.cfg.train.lr_decay_steps = (self.teacher_iters - hold).max(1);
        }
        plan.run.model.cfg.train.time_budget_s = 0.0;
        plan.run.model.cfg.train.time_cap_s = self.teacher_cap_minutes * 60.0;
        plan.run(stop, on_event)?;
        Ok(())
    }

    /// Trains (or resumes) the student on `data` with the demo's recipe and time cap.
    fn train_student(&self, data: &Path, stop: &AtomicBool, on_event: OnEvent) -> Result<()> {
        let student_dir = self.out.join(STUDENT_DIR);
        let resume = has_checkpoint(&student_dir);
        on_event(&JobEvent::Stage(format!(
            "student, {} ({} steps, capped at {} min{}) -> {}",
            if self.student_distill {
                "distilled with pseudo views"
            } else {
                "pixels only"
            },
            self.student_iters,
            self.student_cap_minutes,
            if resume { ", resuming" } else { "" },
            student_dir.display()
        )));
        let mut cfg = student_recipe(
            &self.student,
            &self.teacher,
            self.student_distill,
            self.pseudo,
            self.student_iters,
        )?;
        cfg.train.seed = self.train_seed;
        // The recipe is complete before the run is built from it (a resumed run keeps
        // its own).
        let mut plan = StudentJob {
            data: data.to_path_buf(),
            run: self.out.clone(),
            name: STUDENT_DIR.into(),
            source: StudentSource::Config(Box::new(cfg)),
            iters: resume.then_some(self.student_iters),
            minutes: None,
            resume,
        }
        .plan(on_event)?;
        let t = &mut plan.run.model.cfg.train;
        t.time_budget_s = 0.0;
        t.time_cap_s = self.student_cap_minutes * 60.0;
        plan.run(stop, on_event)?;
        Ok(())
    }

    /// Exports the trained student to ONNX and reads the file back; returns its path.
    fn export_onnx(&self, own: &mut Timing, on_event: OnEvent) -> Result<PathBuf> {
        let student_dir = self.out.join(STUDENT_DIR);
        on_event(&JobEvent::Stage("ONNX export".into()));
        let started = Instant::now();
        let onnx = self.out.join(ONNX_FILE);
        let report =
            nldf_export::export_student(&student_dir, &onnx, nldf_export::WeightType::F32)?;
        // Read it back as every loader will, so that a bad file never leaves the demo.
        nldf_model::read_model(&onnx)?;
        on_event(&JobEvent::Note(format!(
            "student at step {}: {} bytes",
            report.info.step, report.bytes
        )));
        on_event(&JobEvent::Wrote {
            dir: self.out.clone(),
            files: vec![onnx.clone()],
        });
        own.add("ONNX export", started.elapsed().as_secs_f64(), 1);
        Ok(onnx)
    }

    /// Evaluates the demo's run on each of its splits that `data` has, adding their
    /// seconds to `own`; returns the evaluations and the `val` split's folder.
    fn evaluate(
        &self,
        data: &Path,
        own: &mut Timing,
        on_event: OnEvent,
    ) -> Result<(Vec<(Split, Evaluation)>, PathBuf)> {
        let mut splits = Vec::new();
        let mut eval_dir = self.out.join("eval").join(Split::Val.name());
        for &split in &self.splits {
            if split != Split::Val && !data.join(split.file_name()).is_file() {
                continue;
            }
            on_event(&JobEvent::Stage(format!(
                "evaluation on the `{}` frames",
                split.name()
            )));
            let plan = EvalJob {
                run: self.out.clone(),
                data: data.to_path_buf(),
                split,
                frames: None,
                out: None,
                against: None,
            }
            .plan(on_event)?;
            let started = Instant::now();
            let evaluation = plan.run(on_event)?;
            own.add(
                &format!("evaluation: {}", split.name()),
                started.elapsed().as_secs_f64(),
                1,
            );
            if split == Split::Val {
                eval_dir = plan.out.clone();
            }
            splits.push((split, evaluation));
        }
        Ok((splits, eval_dir))
    }
}

/// The frame size the recipe's steps and scores were measured at.
const RECIPE_SIZE: u32 = 128;

/// A note on a dataset larger than [`RECIPE_SIZE`] (its training transforms' width, or twice
/// their principal point): the recipe runs the same steps over more pixels there, which no
/// measurement covers. Empty for the recipe's size, smaller ones, or transforms it cannot
/// read (loading the dataset then says why).
fn size_note(data: &Path) -> String {
    let path = data.join("transforms_train.json");
    let Ok(t) = nldf_core::dataset::TransformsFile::load(&path) else {
        return String::new();
    };
    let width = t.width.unwrap_or((2.0 * t.cx).round() as u32);
    if width <= RECIPE_SIZE {
        return String::new();
    }
    let pixels = (width as f64 / RECIPE_SIZE as f64).powi(2);
    format!(
        " ({width} pixels wide: the recipe is measured at {RECIPE_SIZE}, the size `nldf prepare` \
         writes by default; here it runs the same steps over {pixels:.0} times the pixels)"
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transforms(dir: &Path, fields: &str) {
        let text = format!(r#"{{"focal_len": 300.0, {fields}, "frames": []}}"#);
        std::fs::write(dir.join("transforms_train.json"), text).unwrap();
    }

    /// A 512-pixel dataset (its width, or AD-NeRF's principal point without one) gets the
    /// note with 16 times the pixels; the recipe's size, a smaller one and unreadable
    /// transforms get none.
    #[test]
    fn a_dataset_larger_than_the_recipes_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        assert_eq!(size_note(d), "");
        transforms(
            d,
            r#""cx": 256.0, "cy": 256.0, "width": 512, "height": 512"#,
        );
        let note = size_note(d);
        assert!(
            note.contains("512 pixels wide") && note.contains("16 times"),
            "{note}"
        );
        transforms(d, r#""cx": 225.0, "cy": 225.0"#);
        assert!(size_note(d).contains("450 pixels wide"), "{}", size_note(d));
        transforms(d, r#""cx": 64.0, "cy": 64.0, "width": 128, "height": 128"#);
        assert_eq!(size_note(d), "");
        transforms(d, r#""cx": 32.0, "cy": 32.0"#);
        assert_eq!(size_note(d), "");
    }
}
