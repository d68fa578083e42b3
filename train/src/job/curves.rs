//! `nldf bench teachers`: each teacher of the recipe trained on one dataset for the same
//! training seconds, one after the other (each with every core), its head PSNR on the
//! validation frames measured every so many seconds: a curve per teacher on one plot, and
//! the figures as JSON with the machine and the commit.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use serde::Serialize;

use crate::error::{Error, Result};
use crate::job::recipe::TeacherKind;
use crate::job::{JobEvent, OnEvent, load_data};
use crate::trainers::config::{TeacherRunConfig, TeacherTrainConfig};
use crate::trainers::plot::{Series, palette, plot_xy};
use crate::trainers::teacher_trainer::TeacherRun;
use nldf_core::dataset::AudioChoice;
use nldf_core::files::write_json;
use nldf_core::host::Machine;

/// What `nldf bench teachers` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct CurveJob {
    /// The dataset folder.
    pub data: PathBuf,
    /// Where each teacher's run (`OUT/<teacher>`), `curves.json` and `curves.png` go.
    pub out: PathBuf,
    /// The teachers, trained in this order.
    pub teachers: Vec<TeacherKind>,
    /// Training seconds of each teacher: its learning rate is held for 60 % of them, then
    /// decays tenfold by the clock.
    pub seconds: f64,
    /// Seconds between two measurements.
    pub every_s: f64,
    /// Validation frames each measurement renders.
    pub frames: usize,
}

/// One measurement.
#[derive(Debug, Clone, Serialize)]
pub struct CurvePoint {
    /// The run's training clock (its validation renders included).
    pub seconds: f64,
    pub step: usize,
    pub head_psnr: Option<f64>,
    pub mouth_psnr: Option<f64>,
    pub psnr: f64,
}

/// One teacher's curve.
#[derive(Debug, Clone, Serialize)]
pub struct Curve {
    pub teacher: String,
    pub points: Vec<CurvePoint>,
}

/// `curves.json`.
#[derive(Debug, Clone, Serialize)]
pub struct CurveReport {
    pub machine: Machine,
    pub data: String,
    pub seconds: f64,
    pub every_s: f64,
    pub frames: usize,
    pub curves: Vec<Curve>,
}

impl TeacherKind {
    /// Its name in files and tables.
    pub fn name(self) -> &'static str {
        match self {
            TeacherKind::Mlp => "mlp",
            TeacherKind::Grid => "grid",
        }
    }
}

impl CurveJob {
    /// Trains and measures each teacher, then writes `curves.json` and `curves.png`.
    pub fn run(&self, stop: &AtomicBool, on_event: OnEvent) -> Result<CurveReport> {
        if !(self.seconds.is_finite() && self.seconds > 0.0) {
            return Err(Error::Config(format!(
                "the training seconds must be positive, got {}",
                self.seconds
            )));
        }
        if !(self.every_s.is_finite() && self.every_s > 0.0) || self.frames == 0 {
            return Err(Error::Config(
                "the measurements need a positive interval and at least one frame".into(),
            ));
        }
        let mut machine = Machine::here();
        let data = load_data(&self.data, &AudioChoice::Auto, on_event)?;
        let mut curves = Vec::with_capacity(self.teachers.len());
        for &kind in &self.teachers {
            on_event(&JobEvent::Stage(format!(
                "{} teacher for {:.0} s, measured every {:.0} s",
                kind.name(),
                self.seconds,
                self.every_s
            )));
            curves.push(self.curve(kind, &data, stop, on_event)?);
            if stop.load(Ordering::Relaxed) {
                break;
            }
        }
        machine.record_end();
        let report = CurveReport {
            machine,
            data: self.data.display().to_string(),
            seconds: self.seconds,
            every_s: self.every_s,
            frames: self.frames,
            curves,
        };
        self.write(&report, on_event)?;
        Ok(report)
    }

    /// The run configuration of `kind` for this job: the recipe's network and learning
    /// rate, the schedule by the clock.
    fn config(&self, kind: TeacherKind) -> TeacherRunConfig {
        let (model, _, lr) = kind.recipe();
        TeacherRunConfig {
            model,
            train: TeacherTrainConfig {
                iters: usize::MAX / 2,
                lr,
                lr_hold_steps: 0,
                lr_decay_steps: usize::MAX / 2,
                time_budget_s: self.seconds,
                val_every: 0,
                checkpoint_every: 0,
                ..TeacherTrainConfig::default()
            },
        }
    }

    fn curve(
        &self,
        kind: TeacherKind,
        data: &crate::trainers::data::TrainData,
        stop: &AtomicBool,
        on_event: OnEvent,
    ) -> Result<Curve> {
        let dir = self.out.join(kind.name());
        let mut run = TeacherRun::create(&dir, self.config(kind), data)?;
        let mut points = Vec::new();
        let mut next = 0.0;
        loop {
            let done = run.elapsed() >= self.seconds || stop.load(Ordering::Relaxed);
            if run.elapsed() >= next || done {
                let s = run.model.validation_scores(data, self.frames)?;
                points.push(CurvePoint {
                    seconds: run.elapsed(),
                    step: run.model.step,
                    head_psnr: s.head_psnr,
                    mouth_psnr: s.mouth_psnr,
                    psnr: s.psnr,
                });
                on_event(&JobEvent::Progress {
                    what: format!("{} teacher, training seconds", kind.name()),
                    done: run.elapsed().min(self.seconds) as usize,
                    total: self.seconds as usize,
                });
                next += self.every_s;
            }
            if done {
                break;
            }
            run.train_step(data)?;
        }
        run.save()?;
        Ok(Curve {
            teacher: kind.name().into(),
            points,
        })
    }

    fn write(&self, report: &CurveReport, on_event: OnEvent) -> Result<()> {
        std::fs::create_dir_all(&self.out).map_err(|e| Error::io(&self.out, e))?;
        let json = self.out.join("curves.json");
        write_json(&json, report)?;
        let series: Vec<Series> = report
            .curves
            .iter()
            .enumerate()
            .map(|(i, c)| Series {
                label: format!("{} teacher", c.teacher),
                color: palette(i),
                points: c
                    .points
                    .iter()
                    .filter_map(|p| p.head_psnr.map(|h| (p.seconds, h)))
                    .collect(),
                marked: true,
            })
            .collect();
        let png = self.out.join("curves.png");
        plot_xy(
            &png,
            "head PSNR on the validation frames against training seconds",
            ("training seconds", "head PSNR (dB)"),
            &series,
        )?;
        on_event(&JobEvent::Wrote {
            dir: self.out.clone(),
            files: vec![json, png],
        });
        Ok(())
    }
}
