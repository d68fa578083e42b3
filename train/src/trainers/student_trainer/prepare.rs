//! Preparing a student's run: its views, their hit pixels and the teacher's segment
//! colours, read from the cache or rendered now or between steps.

use nldf_core::render_spec::RenderSpec;
use nldf_core::run_files::{BACKGROUND_FILE, RENDER_SPEC_FILE, TARGETS_FILE};

use super::StudentRun;
use crate::error::{Error, Result};
use crate::trainers::data::TrainData;
use crate::trainers::targets::{
    TargetLayout, load_targets, save_targets, teacher_targets, view_targets,
};
use crate::trainers::teacher_trainer::TeacherModel;
use crate::trainers::views::{
    frame_beams, mouth_surface_points, thin_beams, thin_pseudo_beams, training_views,
    views_fingerprint,
};

impl StudentRun {
    /// Makes the views (training frames and pseudo views), finds their hit pixels and,
    /// when distilling, the teacher's segment colours: read from `targets.safetensors` when
    /// it matches the views and the teacher's step, otherwise computed with `teacher` and
    /// cached. Writes `render.json` and the background beside the checkpoint.
    pub fn prepare(
        &mut self,
        data: &TrainData,
        teacher: Option<&TeacherModel>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<()> {
        if let Some(layout) = self.prepare_cached(data, teacher)? {
            let teacher = teacher.ok_or_else(|| self.no_teacher())?;
            self.targets =
                teacher_targets(teacher, data, &self.views, &self.beams, layout, progress)?;
            self.save_targets(teacher.step)?;
        }
        Ok(())
    }

    /// [`StudentRun::prepare`], except that without a matching cache only the recorded
    /// frames' targets are rendered now: the pseudo views' are rendered
    /// `pseudo_per_step` at a time before each training step, so the student starts at
    /// once and learns from each pseudo view as soon as it exists. The cache is written
    /// once all are done.
    pub fn prepare_deferred(
        &mut self,
        data: &TrainData,
        teacher: Option<TeacherModel>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<()> {
        let Some(layout) = self.prepare_cached(data, teacher.as_ref())? else {
            return Ok(());
        };
        let teacher = teacher.ok_or_else(|| self.no_teacher())?;
        let n_recorded = self.views.iter().filter(|v| v.recorded).count();
        self.targets = teacher_targets(
            &teacher,
            data,
            &self.views[..n_recorded],
            &self.beams[..n_recorded],
            layout,
            progress,
        )?;
        self.targets.resize(self.views.len(), Vec::new());
        if n_recorded == self.views.len() {
            self.save_targets(teacher.step)?;
        } else {
            self.pending = Some((teacher, n_recorded));
        }
        Ok(())
    }

    /// Pseudo views whose targets are still to be rendered.
    pub fn pending_pseudo_views(&self) -> usize {
        self.pending
            .as_ref()
            .map_or(0, |(_, next)| self.views.len() - next)
    }

    /// What the teacher renders per ray for this student.
    pub(super) fn target_layout(&self) -> TargetLayout {
        TargetLayout {
            segments: self.model.cfg.model.segments,
            anchor: self.model.cfg.model.beam.anchor,
        }
    }

    /// The views, their hit pixels, the render spec and background files, and the cached
    /// targets when they fit; `Some(layout)` when targets must be rendered.
    fn prepare_cached(
        &mut self,
        data: &TrainData,
        teacher: Option<&TeacherModel>,
    ) -> Result<Option<TargetLayout>> {
        let teacher_step = teacher.map(|t| t.step);
        std::fs::create_dir_all(&self.model.dir).map_err(|e| Error::io(&self.model.dir, e))?;
        self.views = training_views(data, &self.model.cfg.train);
        // Pseudo views find their mouth by projecting the recorded frames' mouth through
        // the teacher's depth.
        let mouth_points = match teacher {
            Some(t)
                if self.views.iter().any(|v| !v.recorded) && self.model.cfg.train.project_mouth =>
            {
                Some(mouth_surface_points(t, data)?)
            }
            _ => None,
        };
        self.beams = frame_beams(data, &self.views, mouth_points.as_deref());
        let t = &self.model.cfg.train;
        thin_pseudo_beams(&self.views, &mut self.beams, t.pseudo_rays, t.seed);
        thin_beams(
            &self.views,
            &mut self.beams,
            t.recorded_rays,
            true,
            t.seed ^ 0x7ec0_4de5,
        );
        self.pending = None;
        let spec = RenderSpec::of_dataset(
            &data.dataset,
            data.bounds,
            self.model.cfg.model.audio.att_frames,
        );
        spec.save(&self.model.dir.join(RENDER_SPEC_FILE))?;
        data.dataset
            .background
            .save_png(&self.model.dir.join(BACKGROUND_FILE))?;
        if !self.model.cfg.train.distill {
            return Ok(None);
        }
        let layout = self.target_layout();
        let path = self.model.dir.join(TARGETS_FILE);
        let fingerprint = views_fingerprint(&self.views, &self.beams);
        // Without a teacher at hand, a cache made by any teacher step is used.
        if path.is_file()
            && let Some(cached) =
                load_targets(&path, &self.beams, layout, teacher_step, &fingerprint)?
        {
            self.targets = cached;
            return Ok(None);
        }
        Ok(Some(layout))
    }

    fn no_teacher(&self) -> Error {
        Error::Config(format!(
            "distillation needs the teacher's segment colours: {} is missing and no teacher was given",
            self.model.dir.join(TARGETS_FILE).display()
        ))
    }

    fn save_targets(&self, teacher_step: usize) -> Result<()> {
        save_targets(
            &self.model.dir.join(TARGETS_FILE),
            &self.targets,
            self.target_layout(),
            teacher_step,
            &views_fingerprint(&self.views, &self.beams),
        )
    }

    /// Renders the next `pseudo_per_step` pending pseudo views' targets; writes the cache
    /// once the last is done.
    pub(super) fn render_pending(&mut self, data: &TrainData) -> Result<()> {
        let Some((teacher, next)) = self.pending.take() else {
            return Ok(());
        };
        let layout = self.target_layout();
        let end = (next + self.model.cfg.train.pseudo_per_step).min(self.views.len());
        let started = std::time::Instant::now();
        for v in next..end {
            self.targets[v] = view_targets(&teacher, data, &self.views[v], &self.beams[v], layout)?;
        }
        self.pseudo_time.0 += started.elapsed().as_secs_f64();
        self.pseudo_time.1 += end - next;
        if end == self.views.len() {
            self.save_targets(teacher.step)
        } else {
            self.pending = Some((teacher, end));
            Ok(())
        }
    }
}
