//! The whole of `nldf prepare`: a video in, an AD-NeRF dataset out, written into a scratch
//! folder beside the output and moved into place only when complete, so that a failure
//! leaves nothing behind.

use std::path::Path;
use std::time::Instant;

use nldf_core::audio::{
    FeatureConfig, FeatureSource, audio_windows_for_frames, n_video_frames, read_wav,
};
use nldf_core::camera::Intrinsics;
use nldf_core::dataset::save_audio_features;
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::face::{FaceEnv, FaceOutput};
use crate::frames::{read_gray, read_rgb, save_jpeg};
use crate::lms68::{jaw_line, landmarks_68};
use crate::parsing::{
    ParsingConfig, Part, Plate, background, hang_below_jaw, head_rect, parse_frame, parsing_image,
};
use crate::pose::{CameraTrack, PoseConfig, TrackSummary};
use crate::pose_stage::{solve_poses, square_intrinsics};
use crate::resample::shrink_dataset;
use crate::scratch::Scratch;
use crate::transforms::write_transforms;
use crate::video::{self, Probe, Window};

pub use crate::settings::{ANALYSIS_MAX, DEFAULT_FOCAL_AT_450, MAX_SIZE, MIN_SIZE, PrepareJob};

/// The head-pose stage's start.
const HEAD_POSE: Event = Event::Stage {
    name: "head pose",
    total: None,
};
/// Frames the background median samples at most.
const BACKGROUND_SAMPLES: usize = 150;
/// The face mesh's nose tip: a point on the head in every frame.
const NOSE_TIP: usize = 1;

/// Progress of a [`PrepareJob`].
#[derive(Debug, Clone)]
pub enum Event {
    /// A stage begins; `total` is its number of frames when it counts frames.
    Stage {
        name: &'static str,
        total: Option<usize>,
    },
    /// Frames done in the current stage.
    Frames(usize),
}

/// What a finished job did, saved as `prepare.json` beside the dataset.
#[derive(Debug, Clone, Serialize)]
pub struct PrepareReport {
    pub video: String,
    pub size: u32,
    /// The size the frames were analysed at before the dataset was shrunk to `size`.
    pub analysed_at: u32,
    /// The size the head's pose was solved at: `analysed_at`, or the frames decoded again
    /// larger for it ([`PoseConfig::pose_size`]); `reprojection_px` is in its pixels.
    pub posed_at: u32,
    pub focal: f32,
    pub fps: f64,
    pub frames_read: usize,
    /// Frames dropped because no single whole face was found in them, and their indices.
    pub frames_dropped: usize,
    pub dropped: Vec<usize>,
    pub train_frames: usize,
    pub val_frames: usize,
    /// Whether the bundle step refined the face's shape (the head moved enough).
    pub bundled: bool,
    /// Median reprojection error of the landmarks, pixels.
    pub reprojection_px: f32,
    /// Whether the poses come from feature tracks, how many, and how well they fit.
    pub tracks: TrackSummary,
    /// The parsing's settings.
    pub parsing: ParsingConfig,
    /// The pose solver's settings (the tracks' reach among them).
    pub pose: PoseConfig,
    /// Seconds per stage and in all.
    pub seconds: Vec<(String, f64)>,
    pub total_seconds: f64,
}

/// Runs `job` with the face environment `env` and the program `ffmpeg`.
pub fn run(
    job: &PrepareJob,
    env: &FaceEnv,
    ffmpeg: &Path,
    mut events: impl FnMut(Event),
) -> Result<PrepareReport> {
    job.check()?;
    let focal = job.focal();
    let started = Instant::now();
    let mut probe = video::probe(ffmpeg, &job.video)?;
    if let Some(f) = job.fps {
        probe.fps = f;
    }
    if !probe.has_audio {
        return Err(Error::invalid(
            &job.video,
            "has no audio track: nldf learns the face from the voice",
        ));
    }
    let side = job.window(&probe)?.crop[2];
    let analysed_at = job.analysis(side);
    let at = PrepareJob {
        size: analysed_at,
        focal: Some(focal * analysed_at as f32 / job.size as f32),
        ..job.clone()
    };
    let window = at.window(&probe)?;
    let scratch = Scratch::new(&job.out, job.force)?;
    let mut report = prepare_into(&at, env, ffmpeg, &probe, &window, &scratch.dir, &mut events)?;
    if analysed_at > job.size {
        events(Event::Stage {
            name: "shrinking",
            total: None,
        });
        let t = Instant::now();
        shrink_dataset(&scratch.dir, analysed_at, job.size)?;
        report
            .seconds
            .push(("shrink".into(), t.elapsed().as_secs_f64()));
        report.size = job.size;
        report.focal = focal;
    }
    report.total_seconds = started.elapsed().as_secs_f64();
    nldf_core::files::write_json(&scratch.dir.join("prepare.json"), &report)?;
    scratch.commit()?;
    Ok(report)
}

/// The stages, writing into `dir`.
fn prepare_into(
    job: &PrepareJob,
    env: &FaceEnv,
    ffmpeg: &Path,
    probe: &Probe,
    window: &Window,
    dir: &Path,
    events: &mut impl FnMut(Event),
) -> Result<PrepareReport> {
    let mut seconds = Vec::new();
    let mut clock = Instant::now();
    let mut lap = |name: &str, seconds: &mut Vec<(String, f64)>| {
        seconds.push((name.to_string(), clock.elapsed().as_secs_f64()));
        clock = Instant::now();
    };
    let size = job.size;
    let ori = dir.join("ori_imgs");
    let heads = dir.join("head_imgs");
    let parsing_dir = dir.join("parsing");
    for d in [&ori, &heads, &parsing_dir] {
        std::fs::create_dir_all(d).map_err(|e| Error::io(d, e))?;
    }

    let (n, wave) = decode(job, ffmpeg, probe, window, dir, events)?;
    lap("decode", &mut seconds);
    let face_dir = dir.join("face");
    let faces = find_faces(job, env, &ori, n, &face_dir, events)?;
    let mut kept = faces.frames_with_one_face(&job.video, size, job.min_frames, probe.fps)?;
    lap("faces", &mut seconds);
    let stage = PoseStage { ffmpeg, probe, dir };
    let (k, track, posed_at) = stage.run(job, env, &faces, &mut kept, events)?;
    lap("pose", &mut seconds);
    let bc = background_of(&kept, &ori, &faces, size)?;
    save_jpeg(&dir.join("bc.jpg"), bc.as_raw(), size)?;
    lap("background", &mut seconds);
    events(Event::Stage {
        name: "parsing",
        total: Some(kept.len()),
    });
    let rects = write_parsing(&faces, &kept, &ori, &parsing_dir, bc.as_raw(), job, events)?;
    lap("parsing", &mut seconds);

    events(Event::Stage {
        name: "heads",
        total: Some(kept.len()),
    });
    write_heads(&kept, &ori, &parsing_dir, &heads, bc.as_raw(), size, events)?;
    write_features(dir, &wave, probe.fps, n)?;
    lap("heads", &mut seconds);

    let n_train = write_transforms(dir, &kept, &track.c2w, &rects, &k, probe.fps)?;
    std::fs::remove_dir_all(&face_dir).map_err(|e| Error::io(&face_dir, e))?;
    let dropped: Vec<usize> = (0..n).filter(|i| kept.binary_search(i).is_err()).collect();
    let mut reprojection = track.reprojection_px.clone();
    reprojection.sort_by(f32::total_cmp);
    Ok(PrepareReport {
        video: job.video.display().to_string(),
        size,
        analysed_at: size,
        posed_at,
        focal: k.focal,
        fps: probe.fps,
        frames_read: n,
        frames_dropped: dropped.len(),
        dropped,
        train_frames: n_train,
        val_frames: kept.len() - n_train,
        bundled: track.bundled,
        tracks: track.tracks,
        reprojection_px: reprojection
            .get(reprojection.len() / 2)
            .copied()
            .unwrap_or(0.0),
        parsing: job.parsing,
        pose: job.pose.clone(),
        seconds,
        total_seconds: 0.0,
    })
}

/// The face stage: the face helper's landmarks, masks and feature tracks of the `n` frames
/// in `ori` (see [`FaceEnv::run_frames`]), written into `face_dir`.
fn find_faces(
    job: &PrepareJob,
    env: &FaceEnv,
    ori: &Path,
    n: usize,
    face_dir: &Path,
    events: &mut impl FnMut(Event),
) -> Result<FaceOutput> {
    events(Event::Stage {
        name: "face landmarks",
        total: Some(n),
    });
    env.run_frames(ori, n, face_dir, job.pose.track_reach, |done| {
        events(Event::Frames(done))
    })
}

/// `aud.npy` and `aud.json`: nldf's audio features of `wave`, one window per video frame.
fn write_features(dir: &Path, wave: &nldf_core::audio::Waveform, fps: f64, n: usize) -> Result<()> {
    let features = FeatureConfig::default();
    let windows = audio_windows_for_frames(wave, fps as f32, &features, n)
        .map_err(|e| Error::invalid(dir.join("aud.wav"), e.to_string()))?;
    save_audio_features(dir, &windows, &FeatureSource::Nldf(features))
}

/// Decodes the frames into `ori_imgs/` and the audio into `aud.wav`: the number of frames
/// and the audio. Refuses audio shorter than the frames and a clip too short to train.
fn decode(
    job: &PrepareJob,
    ffmpeg: &Path,
    probe: &Probe,
    window: &Window,
    dir: &Path,
    events: &mut impl FnMut(Event),
) -> Result<(usize, nldf_core::audio::Waveform)> {
    events(Event::Stage {
        name: "decoding",
        total: probe.duration.map(|d| (d * probe.fps) as usize),
    });
    let n = decode_to_jpegs(
        ffmpeg,
        &job.video,
        probe,
        window,
        &dir.join("ori_imgs"),
        events,
    )?;
    let wav = dir.join("aud.wav");
    video::extract_audio(ffmpeg, &job.video, window, &wav)?;
    let wave = read_wav(&wav)?;
    let have = n_video_frames(wave.samples.len(), wave.sample_rate, probe.fps as f32);
    if have + 1 < n {
        return Err(Error::invalid(
            &job.video,
            format!(
                "its audio lasts {:.2} s, shorter than its {n} video frames",
                wave.seconds()
            ),
        ));
    }
    video::too_short(
        &job.video,
        n,
        job.min_frames,
        probe.fps,
        "in the chosen time range",
    )?;
    Ok((n, wave))
}

/// Decodes the frames into `ori/<i>.jpg`, encoding them in parallel batches.
fn decode_to_jpegs(
    ffmpeg: &Path,
    video: &Path,
    probe: &Probe,
    window: &Window,
    ori: &Path,
    events: &mut impl FnMut(Event),
) -> Result<usize> {
    const BATCH: usize = 16;
    let size = window.size;
    let mut batch: Vec<(usize, Vec<u8>)> = Vec::with_capacity(BATCH);
    let flush = |batch: &mut Vec<(usize, Vec<u8>)>| -> Result<()> {
        batch
            .par_iter()
            .try_for_each(|(i, rgb)| save_jpeg(&ori.join(format!("{i}.jpg")), rgb, size))?;
        batch.clear();
        Ok(())
    };
    let n = video::decode_frames(ffmpeg, video, probe, window, |i, rgb| {
        batch.push((i, rgb.to_vec()));
        if batch.len() == BATCH {
            flush(&mut batch)?;
            events(Event::Frames(i + 1));
        }
        Ok(())
    })?;
    flush(&mut batch)?;
    events(Event::Frames(n));
    Ok(n)
}

/// Writes `parsing/<i>.png` and `ori_imgs/<i>.lms` for the kept frames; returns each
/// frame's head box.
fn write_parsing(
    faces: &FaceOutput,
    kept: &[usize],
    ori: &Path,
    parsing_dir: &Path,
    bc: &[u8],
    job: &PrepareJob,
    events: &mut impl FnMut(Event),
) -> Result<Vec<Option<[u32; 4]>>> {
    let (parsing, size) = (&job.parsing, job.size);
    let mut rects = Vec::with_capacity(kept.len());
    for (chunk_no, chunk) in kept.chunks(32).enumerate() {
        let part: Vec<Option<[u32; 4]>> = chunk
            .par_iter()
            .map(|&i| -> Result<Option<[u32; 4]>> {
                let mesh = faces.landmarks[i].as_deref().unwrap_or(&[]);
                let (Some(lms), Some(jaw)) = (landmarks_68(mesh), jaw_line(mesh)) else {
                    return Err(Error::Argument(format!("frame {i} lost its landmarks")));
                };
                let lms_path = ori.join(format!("{i}.lms"));
                std::fs::write(&lms_path, lms.to_text()).map_err(|e| Error::io(&lms_path, e))?;
                let person = read_gray(&faces.mask_dir.join(format!("{i}.png")), size)?;
                let frame = read_rgb(&ori.join(format!("{i}.jpg")), size)?;
                let mut parts = parse_frame(parsing, &person, &jaw, mesh[NOSE_TIP], size, size);
                let plate = Plate {
                    frame: &frame,
                    background: bc,
                };
                hang_below_jaw(parsing, &mut parts, &person, plate, &jaw, size, size);
                let png = parsing_dir.join(format!("{i}.png"));
                parsing_image(&parts, size, size)
                    .save(&png)
                    .map_err(|e| Error::invalid(&png, format!("cannot write: {e}")))?;
                Ok(head_rect(&parts, size))
            })
            .collect::<Result<_>>()?;
        rects.extend(part);
        events(Event::Frames((chunk_no * 32 + chunk.len()).min(kept.len())));
    }
    Ok(rects)
}

/// The background from up to [`BACKGROUND_SAMPLES`] frames spread over the clip.
fn background_of(
    kept: &[usize],
    ori: &Path,
    faces: &FaceOutput,
    size: u32,
) -> Result<image::RgbImage> {
    let step = kept.len().div_ceil(BACKGROUND_SAMPLES).max(1);
    let picked: Vec<usize> = kept.iter().step_by(step).copied().collect();
    let loaded: Vec<(Vec<u8>, Vec<u8>)> = picked
        .par_iter()
        .map(|&i| {
            Ok((
                read_rgb(&ori.join(format!("{i}.jpg")), size)?,
                read_gray(&faces.mask_dir.join(format!("{i}.png")), size)?,
            ))
        })
        .collect::<Result<_>>()?;
    let (frames, people): (Vec<_>, Vec<_>) = loaded.into_iter().unzip();
    Ok(background(&frames, &people, size, size, (size / 64).max(1)))
}

/// Writes `head_imgs/<i>.jpg`: the frame's head over the background (AD-NeRF's head images).
fn write_heads(
    kept: &[usize],
    ori: &Path,
    parsing_dir: &Path,
    heads: &Path,
    bc: &[u8],
    size: u32,
    events: &mut impl FnMut(Event),
) -> Result<()> {
    let head = Part::Head.colour();
    for (chunk_no, chunk) in kept.chunks(32).enumerate() {
        chunk.par_iter().try_for_each(|&i| -> Result<()> {
            let mut rgb = read_rgb(&ori.join(format!("{i}.jpg")), size)?;
            let labels = read_rgb(&parsing_dir.join(format!("{i}.png")), size)?;
            for (px, (lab, b)) in rgb
                .chunks_exact_mut(3)
                .zip(labels.chunks_exact(3).zip(bc.chunks_exact(3)))
            {
                if lab != head {
                    px.copy_from_slice(b);
                }
            }
            save_jpeg(&heads.join(format!("{i}.jpg")), &rgb, size)
        })?;
        events(Event::Frames((chunk_no * 32 + chunk.len()).min(kept.len())));
    }
    Ok(())
}

/// The head-pose stage of a job, with what it needs to decode the video again at
/// [`PoseConfig::pose_size`], into scratch folders of `dir` that it removes.
struct PoseStage<'a> {
    ffmpeg: &'a Path,
    probe: &'a Probe,
    dir: &'a Path,
}

impl PoseStage<'_> {
    /// The intrinsics of `job`'s frames, the track of the `kept` frames and the size it was
    /// solved at: from `faces` at the job's size, or from the frames decoded again larger
    /// when the job's size is below [`PoseConfig::pose_size`] (then `kept` loses the frames
    /// without one whole face at that size).
    fn run(
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
            events(HEAD_POSE);
            let (k, track) = solve_poses(env, faces, kept, job.size, job.focal(), &job.pose)?;
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
        let larger = faces.frames_with_one_face(&job.video, at.size, 0, self.probe.fps)?;
        kept.retain(|i| larger.binary_search(i).is_ok());
        video::too_short(
            &job.video,
            kept.len(),
            job.min_frames,
            self.probe.fps,
            "after dropping the frames without one",
        )?;
        events(HEAD_POSE);
        let (_, track) = solve_poses(env, &faces, kept, at.size, at.focal(), &at.pose)?;
        for d in [&frames, &face_dir] {
            std::fs::remove_dir_all(d).map_err(|e| Error::io(d, e))?;
        }
        Ok((square_intrinsics(job.size, job.focal()), track))
    }
}
