//! Run time against error (`nldf bench frontier`). Every way nldf can render a run's
//! held-out frames renders the same frames one after another: the teacher in candle (with
//! its empty-space skipping and early stop, without early stop, and without either, as
//! AD-NeRF renders), and every student exported in f32, f16 and int8, each in onnxruntime
//! and tract. Each is scored against the ground truth (PSNR, SSIM, mouth PSNR) and timed
//! per whole frame (ray set-up, network and compositing): the median over the `val` scoring
//! pass with 2 threads, where the ways of rendering take turns frame by frame (so a burst of
//! load on the machine touches all alike), a second median over a few frames rendered back
//! to back, as a video renders them, and one over a few frames with 1 thread. AD-NeRF's own
//! setting (8 x 256, 64 + 128 samples) is timed on a few frames with seeded weights, taking
//! turns frame by frame with the points it is set against. Every speed-up is a ratio over
//! frames rendered in turn, each frame a pair ([`crate::repeats`]).
//! [`FrontierReport::write`] writes `frontier.json` (machine, commit, load, settings,
//! points), `frontier.md` and `frontier.png` (PSNR against time on a log axis, the Pareto
//! front marked), and states the students' speed-up over the teacher at matched PSNR.
//!
//! The job is split by what it does: `exports` (every student in every precision),
//! `points` (the ways of rendering, timed), `timing` (back to back, AD-NeRF's setting),
//! [`front`] (rows, the front, speed-ups), `hires` (the higher resolution pass) and
//! [`report`] (the files).

mod exports;
pub mod front;
mod hires;
mod points;
pub mod report;
mod shared;
mod timing;
mod upsampled_point;
pub mod upsampler_bench;
mod upsampler_report;

use std::cell::RefCell;
use std::path::Path;

use nldf_core::dataset::Split;
use nldf_core::stats::median;
use nldf_infer::BackendKind;
use nldf_train::job::OnEvent;
use nldf_train::job::eval::{EvalJob, EvalPlan};
use nldf_train::reports::eval::{EvalReport, FrameModel};
use nldf_train::trainers::data::TrainData;

pub use front::{Point, SpeedUp, SplitScore, mark_front, speed_ups};
pub use report::{AdNerfSetting, FrontierReport, FrontierSettings};

use crate::error::{Error, Result};
use exports::{Export, export_all, export_upsampled, open_point};
use front::{Times, score};
use points::{OnnxPoint, Timed};
use shared::eval_split;
pub use shared::{FrontierJob, THREADS};
use timing::{time_adnerf_setting, time_back_to_back};

/// The ways of rendering the run, in the tables' order.
struct Ways<'a> {
    /// The teacher with its empty-space skipping and early stop.
    teacher: Timed<'a>,
    /// The teacher without early stop, and without either: scored and timed on `val` only.
    plain: [Timed<'a>; 2],
    /// Every export in both runtimes.
    points: Vec<OnnxPoint>,
}

impl FrontierJob {
    /// Exports, scores and times every way of rendering the run; `on_event` hears the
    /// evaluation plans' notes, what is exported and timed, and each scored frame.
    pub fn run(&self, on_event: OnEvent) -> Result<FrontierReport> {
        // Every point runs in onnxruntime too: refuse before anything is exported.
        nldf_infer::ort_library::OrtSearch::from_env()
            .find()
            .map_err(|e| {
                Error::from(e).context("bench frontier renders every export in onnxruntime")
            })?;
        let mut machine = self.load.admit()?;
        let splits = splits(&self.data);
        let val = self.eval_job(Split::Val).plan(&mut *on_event)?;
        if val.students.is_empty() {
            return Err(Error::Missing(format!(
                "{} has no trained student to put on the frontier",
                self.run.display()
            )));
        }
        let exports = export_all(
            &val.students,
            &self.data,
            self.calibration_frames,
            &self.out.join("models"),
            &mut *on_event,
        )?;
        let upsampled = export_upsampled(self, &val, &mut *on_event)?;
        let student_exports = exports.len();
        let exports: Vec<Export> = exports.into_iter().chain(upsampled).collect();
        // Every export in both runtimes; `val` scores them all, the other splits score the
        // onnxruntime points (tract runs the same graphs: the suite's parity tests).
        let mut points: Vec<OnnxPoint> = Vec::new();
        for e in &exports {
            for kind in [BackendKind::Ort, BackendKind::Tract] {
                points.push(open_point(e, kind, THREADS, self.batch, None, 1)?);
            }
        }
        let ways = Ways {
            teacher: Timed::new(&val.teacher, true, true),
            plain: [
                Timed::new(&val.teacher, true, false),
                Timed::new(&val.teacher, false, false),
            ],
            points,
        };
        let reports = self.score_splits(&splits, &val, &ways, &mut *on_event)?;
        let table = self.table(&val.data, &reports, &ways, &exports)?;
        let speed_up = speed_ups(&table);
        let adnerf = self.adnerf(&val.data, &table, &speed_up, &ways, &mut *on_event)?;
        let hires_points = match &self.hires_data {
            Some(dir) => Some(hires::hires_points(
                self,
                dir,
                &exports[..student_exports],
                on_event,
            )?),
            None => None,
        };
        machine.record_end();
        Ok(FrontierReport {
            machine,
            settings: self.settings(),
            points: table,
            speed_up,
            adnerf_setting: adnerf,
            hires_points,
            splits,
        })
    }

    /// Scores every way of rendering on each split, taking turns frame by frame: all of
    /// them on `val`, the teacher and the onnxruntime points on the others.
    fn score_splits(
        &self,
        splits: &[Split],
        val: &EvalPlan,
        ways: &Ways<'_>,
        on_event: OnEvent,
    ) -> Result<Vec<Vec<EvalReport>>> {
        let Ways {
            teacher,
            plain,
            points,
        } = ways;
        let mut reports: Vec<Vec<EvalReport>> = Vec::new();
        for &split in splits {
            let plan = if split == Split::Val {
                None
            } else {
                Some(self.eval_job(split).plan(&mut *on_event)?)
            };
            let data = plan.as_ref().map_or(&val.data, |p| &p.data);
            let mut models: Vec<&dyn FrameModel> = vec![teacher];
            if split == Split::Val {
                models.extend(plain.iter().map(|t| t as &dyn FrameModel));
            }
            models.extend(
                points
                    .iter()
                    .filter(|p| split == Split::Val || p.kind == BackendKind::Ort)
                    .map(|p| p as &dyn FrameModel),
            );
            let out = self.out.join(split.name());
            let evaluation = eval_split(&models, data, split, self.frames, &out, &mut *on_event)?;
            reports.push(evaluation.models);
        }
        Ok(reports)
    }

    /// The frontier's rows, the teacher first, each timed taking turns over the `val` pass,
    /// back to back and (the exports) with 1 thread; the Pareto front marked.
    fn table(
        &self,
        val_data: &TrainData,
        reports: &[Vec<EvalReport>],
        ways: &Ways<'_>,
        exports: &[Export],
    ) -> Result<Vec<Point>> {
        let Ways {
            teacher,
            plain,
            points,
        } = ways;
        // Each point's frame times over the `val` pass: the first frames it rendered.
        let n_val = reports[0].first().map_or(0, |r| r.frames.len());
        let pass_frames =
            |s: &RefCell<Vec<f64>>| s.borrow()[..n_val.min(s.borrow().len())].to_vec();
        // Back-to-back times over `--timed-frames`, every way of rendering in turn.
        let val_frames = val_data.dataset.frames(Split::Val);
        let timed = &val_frames[..self.timed_frames.min(val_frames.len())];
        let back_to_back = {
            let models: Vec<&dyn FrameModel> = std::iter::once(teacher)
                .chain(plain)
                .map(|t| t as &dyn FrameModel)
                .chain(points.iter().map(|p| p as &dyn FrameModel))
                .collect();
            time_back_to_back(&models, val_data, timed)?
        };
        let one_thread = self.one_thread_times(exports, val_data)?;
        let mut table: Vec<Point> = Vec::new();
        let scores_of = |label: &str| -> Vec<SplitScore> {
            reports
                .iter()
                .filter_map(|rs| rs.iter().find(|r| r.label == label).map(score))
                .collect()
        };
        // The teacher first: `speed_ups` compares every point with the first row.
        for (k, t) in std::iter::once(teacher).chain(plain).enumerate() {
            let report = reports[0]
                .iter()
                .find(|r| r.label == t.label())
                .ok_or_else(|| Error::Missing("a teacher lacks its val report".into()))?;
            let frames = pass_frames(&t.seconds);
            let times = Times {
                taking_turns: median(&frames),
                frames,
                back_to_back: back_to_back[k],
                one_thread: None,
            };
            let size = val_data.dataset.intrinsics.width;
            table.push(Point::of_teacher(
                t,
                report,
                size,
                times,
                scores_of(&t.label()),
            ));
        }
        for (i, p) in points.iter().enumerate() {
            let label = p.label();
            let size = p.renderer.borrow().intrinsics().width;
            let report = reports[0]
                .iter()
                .find(|r| r.label == label)
                .ok_or_else(|| Error::Missing("a point lacks its val report".into()))?;
            let frames = pass_frames(&p.seconds);
            let times = Times {
                taking_turns: median(&frames),
                frames,
                back_to_back: back_to_back[1 + plain.len() + i],
                one_thread: one_thread.get(i).copied(),
            };
            table.push(Point::of_export(p, report, size, times, scores_of(&label)));
        }
        mark_front(&mut table);
        Ok(table)
    }

    /// AD-NeRF's own setting, timed against the speed-ups' points and the fastest export
    /// in turns; `None` without `--adnerf-frames`.
    fn adnerf(
        &self,
        val_data: &TrainData,
        table: &[Point],
        speed_up: &[SpeedUp],
        ways: &Ways<'_>,
        on_event: OnEvent,
    ) -> Result<Option<AdNerfSetting>> {
        if self.adnerf_frames > 0 {
            // Against the speed-ups' points and the fastest export, in turns.
            let first_point = 1 + ways.plain.len();
            let listed: Vec<&dyn FrameModel> = report::adnerf_listed(table, speed_up)
                .into_iter()
                .filter_map(|i| i.checked_sub(first_point))
                .filter_map(|i| ways.points.get(i).map(|p| p as &dyn FrameModel))
                .collect();
            Ok(Some(time_adnerf_setting(
                val_data,
                self.adnerf_frames,
                &listed,
                &mut *on_event,
            )?))
        } else {
            Ok(None)
        }
    }

    /// The evaluation of the run on `split`, its renders left to the frontier's folders.
    fn eval_job(&self, split: Split) -> EvalJob {
        EvalJob {
            run: self.run.clone(),
            data: self.data.clone(),
            split,
            frames: self.frames,
            out: None,
            against: None,
        }
    }

    /// 1-thread times: each export in each runtime on the first frames of `val`, the first
    /// frame untimed (it pays for plans and caches).
    fn one_thread_times(&self, exports: &[Export], data: &TrainData) -> Result<Vec<f64>> {
        let frames = data.dataset.frames(Split::Val);
        let k = self.one_thread_frames.min(frames.len());
        let mut one_thread = Vec::new();
        for e in exports {
            for kind in [BackendKind::Ort, BackendKind::Tract] {
                let p = open_point(e, kind, 1, self.batch, None, 1)?;
                for f in &frames[..k] {
                    p.render_frame(data, f)?;
                }
                one_thread.push(median(p.seconds.borrow().get(1..).unwrap_or(&[])));
            }
        }
        Ok(one_thread)
    }

    /// The settings as the report records them.
    fn settings(&self) -> FrontierSettings {
        FrontierSettings {
            run: self.run.clone(),
            data: self.data.clone(),
            frames: self.frames,
            threads: THREADS,
            one_thread_frames: self.one_thread_frames,
            calibration_frames: self.calibration_frames,
            batch: self.batch,
            hires_data: self.hires_data.clone(),
            timed_frames: self.timed_frames,
            upsamplers: self.upsamplers.clone(),
            int8_f32: self.int8_f32.clone(),
        }
    }
}

/// The splits to score: `val`, then `novel` and `voice` where the dataset has them.
fn splits(data: &Path) -> Vec<Split> {
    let mut splits = vec![Split::Val];
    for s in [Split::Novel, Split::Voice] {
        if data.join(format!("transforms_{}.json", s.name())).is_file() {
            splits.push(s);
        }
    }
    splits
}
