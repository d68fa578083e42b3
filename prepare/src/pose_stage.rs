//! The head-pose stage of `nldf prepare`: the camera track solved from the face helper's
//! landmarks and feature tracks (`crate::pose`), at the job's size or, for a small video,
//! from its frames decoded again larger ([`crate::pose::PoseConfig::pose_size`]).

use std::path::Path;

use nldf_core::camera::Intrinsics;

use crate::error::{Error, Result};
use crate::face::{FaceEnv, FaceOutput};
use crate::job::{Event, PrepareJob, decode_to_jpegs, find_faces, frames_with_one_face, too_short};
use crate::pose::{CameraTrack, solve_track};
use crate::video::Probe;

/// The head-pose stage: the intrinsics of `job`'s frames and the track of the kept frames.
fn solve_poses(
    job: &PrepareJob,
    env: &FaceEnv,
    faces: &FaceOutput,
    kept: &[usize],
    events: &mut impl FnMut(Event),
) -> Result<(Intrinsics, CameraTrack)> {
    let size = job.size;
    events(Event::Stage {
        name: "head pose",
        total: None,
    });
    let k = Intrinsics {
        focal: job.focal(),
        cx: size as f32 / 2.0,
        cy: size as f32 / 2.0,
        width: size,
        height: size,
    };
    let canonical = env.canonical()?;
    let track = solve_track(
        &faces.landmark_frames(kept),
        &faces.tracks,
        &canonical.vertices,
        &canonical.rigid_weights,
        &k,
        &job.pose,
    )?;
    Ok((k, track))
}

/// The head-pose stage of a job, with what it needs to decode the video again at
/// [`crate::pose::PoseConfig::pose_size`], into scratch folders of `dir` that it removes.
pub(crate) struct PoseStage<'a> {
    pub(crate) ffmpeg: &'a Path,
    pub(crate) probe: &'a Probe,
    pub(crate) dir: &'a Path,
}

impl PoseStage<'_> {
    /// The intrinsics of `job`'s frames, the track of the `kept` frames and the size it was
    /// solved at: from `faces` at the job's size, or from the frames decoded again larger
    /// when the job's size is below [`crate::pose::PoseConfig::pose_size`] (then `kept` loses the frames
    /// without one whole face at that size).
    pub(crate) fn run(
        &self,
        job: &PrepareJob,
        env: &FaceEnv,
        faces: &FaceOutput,
        kept: &mut Vec<usize>,
        events: &mut impl FnMut(Event),
    ) -> Result<(Intrinsics, CameraTrack, u32)> {
        if job.pose.pose_size > job.size {
            let (k, track) = self.larger(job, env, kept, events)?;
            Ok((k, track, job.pose.pose_size))
        } else {
            let (k, track) = solve_poses(job, env, faces, kept, events)?;
            Ok((k, track, job.size))
        }
    }

    /// The intrinsics of `job`'s frames and the track of the `kept` frames, solved from the
    /// landmarks and tracks of the larger frames; `kept` loses the frames without one whole
    /// face at that size.
    fn larger(
        &self,
        job: &PrepareJob,
        env: &FaceEnv,
        kept: &mut Vec<usize>,
        events: &mut impl FnMut(Event),
    ) -> Result<(Intrinsics, CameraTrack)> {
        let at = PrepareJob {
            size: job.pose.pose_size,
            focal: Some(job.focal() * job.pose.pose_size as f32 / job.size as f32),
            ..job.clone()
        };
        let frames = self.dir.join("pose_frames");
        std::fs::create_dir_all(&frames).map_err(|e| Error::io(&frames, e))?;
        events(Event::Stage {
            name: "decoding for the pose",
            total: self.probe.duration.map(|d| (d * self.probe.fps) as usize),
        });
        let window = at.window(self.probe)?;
        let n = decode_to_jpegs(
            self.ffmpeg,
            &job.video,
            self.probe,
            &window,
            &frames,
            events,
        )?;
        let face_dir = self.dir.join("pose_face");
        let faces = find_faces(&at, env, &frames, n, &face_dir, events)?;
        let larger = frames_with_one_face(&job.video, &faces, at.size, 0, self.probe.fps)?;
        kept.retain(|i| larger.binary_search(i).is_ok());
        too_short(
            &job.video,
            kept.len(),
            job.min_frames,
            self.probe.fps,
            "after dropping the frames without one",
        )?;
        let (_, track) = solve_poses(&at, env, &faces, kept, events)?;
        for d in [&frames, &face_dir] {
            std::fs::remove_dir_all(d).map_err(|e| Error::io(d, e))?;
        }
        let size = job.size as f32;
        let k = Intrinsics {
            focal: job.focal(),
            cx: size / 2.0,
            cy: size / 2.0,
            width: job.size,
            height: job.size,
        };
        Ok((k, track))
    }
}
