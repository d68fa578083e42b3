//! `nldf prepare`: a video of one person speaking as an AD-NeRF dataset, on a CPU.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use indicatif::ProgressBar;
use nldf_prepare::face::{self, FaceEnv};
use nldf_prepare::job::{self, Event, PrepareJob};
use nldf_prepare::parsing::ParsingConfig;
use nldf_prepare::pose::PoseConfig;
use nldf_prepare::tools;

use crate::progress::progress_bar;

#[derive(clap::Args, Debug)]
pub struct PrepareArgs {
    /// The video (MP4 or anything ffmpeg reads): one person facing the camera, speaking, at a
    /// constant frame rate, with its sound.
    #[arg(long, required_unless_present = "setup")]
    pub video: Option<PathBuf>,
    /// Output dataset folder (created; must be empty or absent unless --force).
    #[arg(long, required_unless_present = "setup")]
    pub out: Option<PathBuf>,
    /// Output frames are SIZE x SIZE pixels (a square crop of the video, scaled; 32 to
    /// 2048). The default, 128, is the size `nldf train --data`'s recipe is measured at; a
    /// larger video is analysed at up to 512 pixels first (--analysis-size).
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Find the face, its landmarks, tracks, poses and masks in frames of this size, then
    /// shrink the dataset to --size: landmarks hold a pixel's worth of error at any size,
    /// so a larger frame gives finer poses. Default: the crop's side, at most 512, and
    /// never below --size.
    #[arg(long)]
    pub analysis_size: Option<u32>,
    /// Focal length in output pixels; landmarks cannot tell it. Default: AD-NeRF's 1200 at
    /// 450 pixels, scaled to --size (341 at 128, 1365 at 512). Half or twice the true value
    /// moves the rotations by well under a degree.
    #[arg(long)]
    pub focal: Option<f32>,
    /// Resample the video to this constant frame rate (AD-NeRF's datasets are 25); this
    /// also takes a video with a variable frame rate. Default: the video's own rate.
    #[arg(long)]
    pub fps: Option<f64>,
    /// Seconds into the video to start at.
    #[arg(long, default_value_t = 0.0)]
    pub start: f64,
    /// Seconds of video to read (default: to its end).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// The square of the video to keep, `X,Y,SIDE` in the video's pixels (default: the
    /// centred square).
    #[arg(long, value_parser = parse_crop)]
    pub crop: Option<Crop>,
    /// Fewest frames with one face needed to train (100 is 4 s at 25 frames/s).
    #[arg(long, default_value_t = 100)]
    pub min_frames: usize,
    /// How far the head's cut lies past the face's jaw line, as a share of the line's size
    /// (the segmenter's person above the cut is the head).
    #[arg(long, default_value_t = ParsingConfig::default().jaw_margin, value_parser = share)]
    pub jaw_margin: f32,
    /// How far below the jaw cut a chin may hang, as a share of the jaw's depth: a run of
    /// pixels below the cut that differ from the background and end in background within
    /// it is head. 0 turns it off.
    #[arg(long, default_value_t = ParsingConfig::default().hang_depth, value_parser = share)]
    pub hang_depth: f32,
    /// The smallest difference from the background image (0-255, the largest channel) that
    /// counts as foreground for --hang-depth.
    #[arg(long, default_value_t = ParsingConfig::default().foreground_diff)]
    pub foreground_diff: u8,
    /// Beside the jaw line's arms (the ears, the side of the head), the head reaches down to
    /// the height of the arm's point this many from its end (of 8); 0 cuts along the arms.
    #[arg(long, default_value_t = ParsingConfig::default().ear_points)]
    pub ear_points: usize,
    /// How far above the face's outline (up to the hairline) features are tracked for the
    /// head pose, as a share of the face's height; 0 keeps them off the hair, which slides
    /// and sways over the head.
    #[arg(long, default_value_t = PoseConfig::default().track_reach, value_parser = share)]
    pub track_reach: f32,
    /// Frames analysed at fewer pixels than this (a small video) are decoded again at this
    /// size for the head's pose alone, where the tracker finds more to follow; 0 turns it
    /// off.
    #[arg(long, default_value_t = PoseConfig::default().pose_size)]
    pub pose_size: u32,
    /// Replace the output folder if it exists.
    #[arg(long)]
    pub force: bool,
    /// Only install the face environment (mediapipe's models from PyPI, the canonical face
    /// from npm, ffmpeg from the imageio-ffmpeg wheel) and exit.
    #[arg(long)]
    pub setup: bool,
}

/// `--crop X,Y,SIDE`.
#[derive(Debug, Clone, Copy)]
pub struct Crop(pub [u32; 3]);

fn parse_crop(text: &str) -> std::result::Result<Crop, String> {
    let v: Vec<u32> = text
        .split(',')
        .map(|t| t.trim().parse::<u32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("`{text}` is not X,Y,SIDE in whole pixels"))?;
    match v.as_slice() {
        [x, y, s] if *s > 0 => Ok(Crop([*x, *y, *s])),
        _ => Err(format!("`{text}` is not X,Y,SIDE with SIDE > 0")),
    }
}

/// A share between 0 and 1 (`--jaw-margin`, `--hang-depth`).
fn share(text: &str) -> std::result::Result<f32, String> {
    match text.trim().parse::<f32>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("`{text}` is not a number from 0 to 1")),
    }
}

/// The face environment, installed first when missing.
fn face_env() -> Result<FaceEnv> {
    let dir = tools::face_env_dir()?;
    if let Some(env) = FaceEnv::open(&dir) {
        return Ok(env);
    }
    eprintln!(
        "installing the face environment into {} (once)",
        dir.display()
    );
    let env = face::install(&dir, |line| eprintln!("  {line}"))
        .with_context(|| format!("installing the face environment into {}", dir.display()))?;
    Ok(env)
}

pub fn run(args: PrepareArgs) -> Result<()> {
    if args.setup {
        let env = face_env()?;
        println!("face environment ready: {}", env.dir.display());
        println!("ffmpeg: {}", tools::ffmpeg()?.display());
        return Ok(());
    }
    let (Some(video), Some(out)) = (args.video, args.out) else {
        bail!("--video and --out are needed");
    };
    let job = PrepareJob {
        video,
        out: out.clone(),
        size: args.size,
        focal: args.focal,
        start: args.start,
        seconds: args.seconds,
        crop: args.crop.map(|c| c.0),
        min_frames: args.min_frames,
        force: args.force,
        pose: PoseConfig {
            track_reach: args.track_reach,
            pose_size: args.pose_size,
            ..PoseConfig::default()
        },
        analysis_size: args.analysis_size,
        fps: args.fps,
        parsing: ParsingConfig {
            jaw_margin: args.jaw_margin,
            hang_depth: args.hang_depth,
            foreground_diff: args.foreground_diff,
            ear_points: args.ear_points,
        },
    };
    // Settings first: a mistyped flag should not wait for the face environment's install.
    job.check()?;
    let env = face_env()?;
    let ffmpeg = tools::ffmpeg()?;
    let mut bar: Option<ProgressBar> = None;
    let report = job::run(&job, &env, &ffmpeg, |event| match event {
        Event::Stage { name, total } => {
            if let Some(b) = bar.take() {
                b.finish();
            }
            bar = Some(match total {
                Some(n) => progress_bar(n as u64, name),
                None => {
                    let b = ProgressBar::new_spinner();
                    b.set_message(name);
                    b
                }
            });
        }
        Event::Frames(done) => {
            if let Some(b) = &bar {
                if b.length().is_some_and(|l| done as u64 > l) {
                    b.set_length(done as u64);
                }
                b.set_position(done as u64);
            }
        }
    });
    if let Some(b) = bar.take() {
        b.finish();
    }
    print_summary(&report?, &out);
    Ok(())
}

/// Says what the preparation kept, dropped and wrote, and what to run next.
fn print_summary(report: &job::PrepareReport, out: &Path) {
    println!(
        "prepared {} frames ({} train, {} val) of {} read, {} dropped without one whole face; \
         {:.1} s ({:.1} frames/s){}",
        report.train_frames + report.val_frames,
        report.train_frames,
        report.val_frames,
        report.frames_read,
        report.frames_dropped,
        report.total_seconds,
        report.frames_read as f64 / report.total_seconds.max(1e-9),
        if report.tracks.bundled {
            format!(
                "; poses from {} feature tracks on the head",
                report.tracks.tracks_used
            )
        } else if report.bundled {
            "; poses from the landmarks, the face's shape refined from the head's motion".into()
        } else {
            "; poses from the landmarks".into()
        },
    );
    println!(
        "wrote {}/ (head_imgs, ori_imgs with .lms, parsing, bc.jpg, aud.wav, aud.npy, transforms_train.json, transforms_val.json, prepare.json)",
        out.display()
    );
    println!(
        "next: nldf train --data {} --run runs/<name>",
        out.display()
    );
}
