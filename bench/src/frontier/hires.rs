//! The frontier's `--hires-data` pass: the teacher and every export in onnxruntime on a
//! higher resolution copy of the scene.

use std::path::Path;

use nldf_core::dataset::Split;
use nldf_core::stats::median;
use nldf_infer::BackendKind;
use nldf_train::job::eval::EvalJob;
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::reports::eval::FrameModel;

use super::exports::{Export, open_point};
use super::front::{Point, Times, mark_front, score};
use super::points::{OnnxPoint, Timed};
use super::shared::{FrontierJob, THREADS, eval_counted};
use super::timing::time_back_to_back;
use crate::error::{Error, Result};

/// The teacher and every export in onnxruntime on the `val` frames of `dir` (the same scene
/// at a higher resolution), with rays at its size and (where the size is a multiple of the
/// model's) at the model's size upscaled; the Pareto front marked among them.
pub(crate) fn hires_points(
    job: &FrontierJob,
    dir: &Path,
    exports: &[Export],
    on_event: OnEvent,
) -> Result<Vec<Point>> {
    let plan = EvalJob {
        run: job.run.clone(),
        data: dir.to_path_buf(),
        split: Split::Val,
        frames: job.frames,
        out: None,
        against: None,
    }
    .plan(&mut *on_event)?;
    let size = plan.data.dataset.intrinsics.width;
    let teacher = Timed::new(&plan.teacher, true, true);
    let points = open_at(job, exports, size)?;
    let mut models: Vec<&dyn FrameModel> = vec![&teacher];
    models.extend(points.iter().map(|p| p as &dyn FrameModel));
    let n = job
        .frames
        .unwrap_or(usize::MAX)
        .min(plan.data.dataset.frames(Split::Val).len());
    on_event(&JobEvent::Note(format!(
        "val at {size} x {size} ({}): {n} frames x {} ways of rendering",
        dir.display(),
        models.len()
    )));
    let evaluation = eval_counted(
        &models,
        &plan.data,
        Split::Val,
        job.frames,
        &job.out.join(format!("val_{size}")),
        n,
        on_event,
    )?;
    let hires_frames = plan.data.dataset.frames(Split::Val);
    let timed = &hires_frames[..job.timed_frames.min(hires_frames.len())];
    let report_of = |label: &str| {
        evaluation
            .models
            .iter()
            .find(|r| r.label == label)
            .ok_or_else(|| Error::Missing(format!("{label} lacks its report at {size} pixels")))
    };
    // Each point's turn-taking times are read before it renders again back to back.
    let teacher_turns = teacher.seconds.borrow().clone();
    let point_turns: Vec<Vec<f64>> = points.iter().map(|p| p.seconds.borrow().clone()).collect();
    let models: Vec<&dyn FrameModel> = std::iter::once(&teacher as &dyn FrameModel)
        .chain(points.iter().map(|p| p as &dyn FrameModel))
        .collect();
    let back_to_back = time_back_to_back(&models, &plan.data, timed)?;
    let mut table = Vec::new();
    let r = report_of(&teacher.label())?;
    let times = Times {
        taking_turns: median(&teacher_turns),
        frames: teacher_turns,
        back_to_back: back_to_back[0],
        one_thread: None,
    };
    table.push(Point::of_teacher(&teacher, r, size, times, vec![score(r)]));
    for (i, p) in points.iter().enumerate() {
        let r = report_of(&p.label())?;
        let times = Times {
            taking_turns: median(&point_turns[i]),
            frames: point_turns[i].clone(),
            back_to_back: back_to_back[1 + i],
            one_thread: None,
        };
        table.push(Point::of_export(p, r, size, times, vec![score(r)]));
    }
    mark_front(&mut table);
    Ok(table)
}

/// Each export opened in onnxruntime at `size` pixels: its rays at that size and, where
/// `size` is a multiple of its own, its own size upscaled.
fn open_at(job: &FrontierJob, exports: &[Export], size: u32) -> Result<Vec<OnnxPoint>> {
    let mut points = Vec::new();
    for e in exports {
        let own = nldf_model::read_model(&e.path)?.info.spec.intrinsics.width;
        points.push(open_point(
            e,
            BackendKind::Ort,
            THREADS,
            job.batch,
            Some(size),
            1,
        )?);
        if own < size && size.is_multiple_of(own) {
            let factor = size / own;
            points.push(open_point(
                e,
                BackendKind::Ort,
                THREADS,
                job.batch,
                Some(size),
                factor,
            )?);
        }
    }
    Ok(points)
}
