//! The whole pipeline on the embedded default, the synthetic talking head: generate the
//! scene, train the teacher within a time budget, train the student (on the recorded
//! pixels, or distilled from the teacher), export it as ONNX and evaluate both on the
//! held-out frames. A stage that already finished in the output folder is reused, and an
//! interrupted one resumes.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use nldf_core::dataset::{AudioChoice, Split};
use nldf_core::run_files::{ONNX_FILE, STUDENT_DIR, TEACHER_DIR, has_checkpoint};
use nldf_core::synth::{self, SynthConfig};

use crate::config::TeacherConfig;
use crate::error::{Error, Result};
use crate::eval::Evaluation;
use crate::job::eval::EvalJob;
use crate::job::student::{PseudoSettings, StudentJob, StudentSource};
use crate::job::teacher::{TeacherJob, TeacherSource};
use crate::job::{JobEvent, OnEvent};
use crate::student::StudentConfig;

/// What `nldf demo` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoJob {
    /// The run folder: the dataset goes to `OUT/data`, the teacher to `OUT/teacher`, the
    /// student to `OUT/student`, the model to `OUT/model.onnx`, the evaluation to
    /// `OUT/eval/val`.
    pub out: PathBuf,
    /// The synthetic scene (seed, length, size).
    pub scene: SynthConfig,
    /// The teacher's network.
    pub teacher: TeacherConfig,
    /// Teacher training budget in minutes.
    pub teacher_minutes: f64,
    /// The student's network.
    pub student: StudentConfig,
    /// Student training budget in minutes (teacher targets included); 0 skips the student
    /// and the export.
    pub student_minutes: f64,
    /// Distil the student from the teacher's segment colours (Eq. 9), or train it on the
    /// recorded pixels alone (which reaches more on the recorded poses within a short
    /// budget: the teacher's targets cost minutes to render).
    pub student_distill: bool,
    /// Student training steps (the learning rate decays over them; the budget may end the
    /// run first).
    pub student_iters: usize,
}

/// What the demo made.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoReport {
    /// The exported student, when one was trained.
    pub model: Option<PathBuf>,
    /// The evaluation of the teacher and the student on the held-out frames.
    pub evaluation: Evaluation,
    /// Where the evaluation was written.
    pub eval_dir: PathBuf,
}

/// The demo's teacher budget in minutes.
pub const DEMO_TEACHER_MINUTES: f64 = 5.0;

/// The demo's student budget in minutes: with the teacher's, the scene, the export, the
/// video and the evaluation, the demo ends within 15 minutes on 2 cores.
pub const DEMO_STUDENT_MINUTES: f64 = 8.5;

/// The demo's student steps: the learning rate is held for 60 % of the budget, then decays
/// tenfold (the budget ends the run first).
pub const DEMO_STUDENT_ITERS: usize = 100_000;

impl DemoJob {
    /// The demo as `nldf demo` runs it by default, into `out`: the synthetic scene of seed
    /// 0 at 128 x 128 (supersampled 3x), the small teacher (6 x 128) for
    /// [`DEMO_TEACHER_MINUTES`], then the real-time student (16 x 128, K = 8) on the
    /// recorded pixels for [`DEMO_STUDENT_MINUTES`]. The command line changes only what
    /// its flags say; the tests shrink the sizes and budgets and keep the recipe.
    pub fn defaults(out: PathBuf) -> DemoJob {
        DemoJob {
            out,
            scene: SynthConfig {
                size: 128,
                supersample: 3,
                ..SynthConfig::default()
            },
            teacher: TeacherConfig::small(),
            teacher_minutes: DEMO_TEACHER_MINUTES,
            student: StudentConfig::realtime(),
            student_minutes: DEMO_STUDENT_MINUTES,
            student_iters: DEMO_STUDENT_ITERS,
            student_distill: false,
        }
    }

    /// Checks the budgets and the scene's settings; nothing is made yet.
    pub fn check(&self) -> Result<()> {
        if !(self.teacher_minutes.is_finite() && self.teacher_minutes > 0.0) {
            return Err(Error::Config(format!(
                "the teacher's budget must be positive, got {} minutes",
                self.teacher_minutes
            )));
        }
        if !(self.student_minutes.is_finite() && self.student_minutes >= 0.0) {
            return Err(Error::Config(format!(
                "the student's budget must be zero or positive, got {} minutes",
                self.student_minutes
            )));
        }
        synth::validate(&self.scene)?;
        Ok(())
    }

    /// Runs every stage in turn; `stop` ends the training stage under way with a checkpoint
    /// and skips the rest. The evaluation is returned even when a model rendered NaN or
    /// infinite pixels: see [`Evaluation::check_finite`].
    pub fn run(&self, stop: &AtomicBool, on_event: OnEvent) -> Result<Option<DemoReport>> {
        self.check()?;
        let data = self.out.join("data");
        if data.join(nldf_core::synth::SCENE_FILE).is_file() {
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
                    synth::generate(&self.scene, None, &data, false, &|| {
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
                    .map_err(|_| Error::Config("the synthetic scene's thread panicked".into()))
            })??;
            on_event(&JobEvent::Progress {
                what: "synthetic frames".into(),
                done: total,
                total,
            });
            on_event(&JobEvent::Wrote {
                dir: data.clone(),
                files: summary.files.iter().map(|(f, _)| data.join(f)).collect(),
            });
        }
        let teacher_dir = self.out.join(TEACHER_DIR);
        let resume = has_checkpoint(&teacher_dir);
        on_event(&JobEvent::Stage(format!(
            "teacher ({} min budget{}) -> {}",
            self.teacher_minutes,
            if resume { ", resuming" } else { "" },
            teacher_dir.display()
        )));
        TeacherJob {
            data: data.clone(),
            run: self.out.clone(),
            source: TeacherSource::Preset(self.teacher.clone()),
            iters: None,
            resume,
            audio: AudioChoice::Auto,
            budget_s: Some(self.teacher_minutes * 60.0),
        }
        .plan(on_event)?
        .run(stop, on_event)?;
        if stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
        let mut model = None;
        if self.student_minutes > 0.0 {
            let student_dir = self.out.join(STUDENT_DIR);
            let resume = has_checkpoint(&student_dir);
            on_event(&JobEvent::Stage(format!(
                "student ({} min budget{}) -> {}",
                self.student_minutes,
                if resume { ", resuming" } else { "" },
                student_dir.display()
            )));
            StudentJob {
                data: data.clone(),
                run: self.out.clone(),
                name: STUDENT_DIR.into(),
                source: StudentSource::Settings {
                    model: self.student.clone(),
                    distill: self.student_distill,
                    pool: true,
                    pseudo: PseudoSettings::default(),
                },
                iters: Some(self.student_iters),
                minutes: Some(self.student_minutes),
                resume,
            }
            .plan(on_event)?
            .run(stop, on_event)?;
            if stop.load(Ordering::Relaxed) {
                return Ok(None);
            }
            on_event(&JobEvent::Stage("ONNX export".into()));
            let onnx = self.out.join(ONNX_FILE);
            let report =
                nldf_export::export_student(&student_dir, &onnx, nldf_export::WeightType::F32)?;
            // Read it back as every loader will, so that a bad file never leaves the demo.
            nldf_export::read_model(&onnx)?;
            on_event(&JobEvent::Note(format!(
                "student at step {}: {} bytes",
                report.info.step, report.bytes
            )));
            on_event(&JobEvent::Wrote {
                dir: self.out.clone(),
                files: vec![onnx.clone()],
            });
            model = Some(onnx);
        }
        on_event(&JobEvent::Stage("evaluation on the held-out frames".into()));
        let plan = EvalJob {
            run: self.out.clone(),
            data,
            split: Split::Val,
            frames: None,
            out: None,
        }
        .plan(on_event)?;
        let evaluation = plan.run(on_event)?;
        Ok(Some(DemoReport {
            model,
            evaluation,
            eval_dir: plan.out,
        }))
    }
}
