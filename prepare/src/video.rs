//! A video file read through ffmpeg: what streams it holds, its frames at a fixed size, its
//! audio at 16 kHz. Every way a file can be unusable for training (no video, no audio, a
//! variable frame rate, a corrupt container) is refused here with one line.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::error::{Error, Result};

/// What ffmpeg says a file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// The first video stream's size in pixels.
    pub width: u32,
    pub height: u32,
    /// Its nominal frame rate.
    pub fps: f64,
    /// Whether the file has an audio stream.
    pub has_audio: bool,
    /// The container's duration in seconds, when it says.
    pub duration: Option<f64>,
}

/// Which part of the video to read, and how to frame it.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    /// Seconds into the clip to start at.
    pub start: f64,
    /// Seconds to read (to the end when `None`).
    pub seconds: Option<f64>,
    /// The square crop of the source frame, `[x, y, side]` in source pixels.
    pub crop: [u32; 3],
    /// Output frames are `size x size`.
    pub size: u32,
    /// Resample to this constant frame rate (ffmpeg's `fps` filter), which also takes a
    /// variable-rate video; `None` keeps the video's own rate and refuses a variable one.
    pub fps: Option<f64>,
}

/// Runs `ffmpeg -i path` and reads the streams from what it prints.
pub fn probe(ffmpeg: &Path, path: &Path) -> Result<Probe> {
    if !path.is_file() {
        return Err(Error::invalid(path, "no such file"));
    }
    let out = Command::new(ffmpeg)
        .args(["-hide_banner", "-nostdin", "-i"])
        .arg(path)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| Error::io(ffmpeg, e))?;
    parse_probe(path, &String::from_utf8_lossy(&out.stderr))
}

/// [`probe`]'s reading of ffmpeg's stream list.
pub fn parse_probe(path: &Path, text: &str) -> Result<Probe> {
    if let Some(line) = text.lines().find(|l| {
        l.contains("Invalid data found")
            || l.contains("moov atom not found")
            || l.contains("could not find codec parameters")
            || l.contains("Error opening input")
    }) {
        return Err(Error::invalid(
            path,
            format!("not a readable video (ffmpeg: {})", line.trim()),
        ));
    }
    let streams: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| l.starts_with("Stream #"))
        .collect();
    let has_audio = streams.iter().any(|l| l.contains(": Audio:"));
    let video = streams
        .iter()
        .find(|l| l.contains(": Video:") && !l.contains("attached pic"));
    let Some(video) = video else {
        return Err(Error::invalid(
            path,
            if has_audio {
                "holds audio only: nldf prepare needs a video of the person speaking"
            } else {
                "holds no video stream"
            },
        ));
    };
    let (width, height) = video_size(video)
        .ok_or_else(|| Error::invalid(path, format!("cannot read the frame size in `{video}`")))?;
    let fps = number_before(video, " fps")
        .or_else(|| number_before(video, " tbr"))
        .filter(|f| f.is_finite() && *f > 0.0)
        .ok_or_else(|| Error::invalid(path, format!("cannot read the frame rate in `{video}`")))?;
    let duration = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("Duration: "))
        .and_then(|d| d.split(',').next())
        .and_then(parse_clock);
    Ok(Probe {
        width,
        height,
        fps,
        has_audio,
        duration,
    })
}

/// `WxH` in a stream line: the first comma-separated field of two positive numbers.
fn video_size(line: &str) -> Option<(u32, u32)> {
    line.split([',', ' '])
        .filter_map(|tok| {
            let (w, h) = tok.trim().split_once('x')?;
            Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?))
        })
        .find(|&(w, h)| w > 0 && h > 0)
}

/// The number written just before `unit` ("25 fps", "29.97 fps", "30k tbr").
fn number_before(line: &str, unit: &str) -> Option<f64> {
    let at = line.find(unit)?;
    let head = &line[..at];
    let token = head.rsplit([',', ' ']).next()?.trim();
    match token.strip_suffix('k') {
        Some(k) => k.parse::<f64>().ok().map(|v| v * 1000.0),
        None => token.parse().ok(),
    }
}

/// `HH:MM:SS.ss` in seconds.
fn parse_clock(text: &str) -> Option<f64> {
    let mut parts = text.trim().split(':');
    let h: f64 = parts.next()?.parse().ok()?;
    let m: f64 = parts.next()?.parse().ok()?;
    let s: f64 = parts.next()?.parse().ok()?;
    Some(h * 3600.0 + m * 60.0 + s)
}

/// The centred square crop of a `width x height` frame.
pub fn centre_square(width: u32, height: u32) -> [u32; 3] {
    let side = width.min(height);
    [(width - side) / 2, (height - side) / 2, side]
}

/// The seconds between the source frames' time stamps, as ffmpeg's `showinfo` prints them.
fn parse_pts_times(lines: &[String]) -> Vec<f64> {
    lines
        .iter()
        .filter(|l| l.contains("Parsed_showinfo"))
        .filter_map(|l| {
            let at = l.find("pts_time:")? + "pts_time:".len();
            l[at..].split_whitespace().next()?.parse().ok()
        })
        .collect()
}

/// Whether time stamps `pts` come at a constant rate `fps`: every gap between neighbours
/// lies within a quarter of a frame of `1 / fps`, but for at most 1 % of them (a container's
/// rounding). Returns the share of gaps that do not.
pub fn irregular_share(pts: &[f64], fps: f64) -> f64 {
    if pts.len() < 3 {
        return 0.0;
    }
    let step = 1.0 / fps;
    let bad = pts
        .windows(2)
        .filter(|w| ((w[1] - w[0]) - step).abs() > 0.25 * step)
        .count();
    bad as f64 / (pts.len() - 1) as f64
}

/// Decodes the video's frames in `window`, at its native rate, as `size x size` RGB, and
/// hands each to `each(index, rgb)`. Refuses a variable frame rate (after reading the
/// frames: ffmpeg's time stamps say it). Returns the number of frames.
pub fn decode_frames(
    ffmpeg: &Path,
    path: &Path,
    probe: &Probe,
    window: &Window,
    mut each: impl FnMut(usize, &[u8]) -> Result<()>,
) -> Result<usize> {
    let mut cmd = decode_command(ffmpeg, path, window);
    let mut child = cmd.spawn().map_err(|e| Error::io(ffmpeg, e))?;
    let stderr = child.stderr.take();
    let log = crate::tools::collect_lines(stderr);
    let frame_bytes = (window.size as usize).pow(2) * 3;
    let mut buf = vec![0u8; frame_bytes];
    let mut n = 0usize;
    let mut failure = None;
    if let Some(mut out) = child.stdout.take() {
        loop {
            match out.read_exact(&mut buf) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => break,
                Err(e) => {
                    failure = Some(Error::io(path, e));
                    break;
                }
            }
            if let Err(e) = each(n, &buf) {
                failure = Some(e);
                break;
            }
            n += 1;
        }
    }
    if failure.is_some() {
        let _ = child.kill();
    }
    let status = child.wait().map_err(|e| Error::io(ffmpeg, e))?;
    let lines = log.join().unwrap_or_default();
    if let Some(e) = failure {
        return Err(e);
    }
    if !status.success() {
        return Err(Error::invalid(
            path,
            format!("ffmpeg could not decode the video: {}", last_error(&lines)),
        ));
    }
    if n == 0 {
        return Err(Error::invalid(
            path,
            "no video frames in the chosen time range",
        ));
    }
    let share = irregular_share(&parse_pts_times(&lines), probe.fps);
    if share > 0.01 && window.fps.is_none() {
        return Err(Error::invalid(
            path,
            format!(
                "has a variable frame rate ({:.0} % of frame gaps differ from 1/{:.3} s): \
                 pass --fps 25 (or another rate) to resample it to a constant one",
                share * 100.0,
                probe.fps
            ),
        ));
    }
    Ok(n)
}

/// The ffmpeg command that writes the video's frames in `window`, cropped and scaled, as
/// raw RGB to its stdout, with its log (`showinfo`'s time stamps) on stderr.
fn decode_command(ffmpeg: &Path, path: &Path, window: &Window) -> Command {
    let [x, y, side] = window.crop;
    let resample = window.fps.map(|f| format!("fps={f},")).unwrap_or_default();
    // swscale's default YUV-to-RGB path rounds coarsely and darkens every channel by 1-1.5
    // levels of 255; with `accurate_rnd` and full chroma interpolation the mean stays within
    // a tenth of a level (the suite's `prepare_video` test).
    let filter = format!(
        "showinfo,{resample}crop={side}:{side}:{x}:{y},\
         scale={s}:{s}:flags=area+accurate_rnd+full_chroma_int",
        s = window.size
    );
    let mut cmd = Command::new(ffmpeg);
    cmd.args(["-hide_banner", "-nostdin", "-loglevel", "info"]);
    time_args(&mut cmd, window);
    cmd.arg("-i")
        .arg(path)
        .args(["-map", "0:v:0", "-an", "-sn", "-vf", &filter])
        .args([
            "-fps_mode",
            "passthrough",
            "-f",
            "rawvideo",
            "-pix_fmt",
            "rgb24",
            "pipe:1",
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    cmd
}

/// Writes the audio in `window` as 16 kHz mono 16-bit WAV at `out`.
pub fn extract_audio(ffmpeg: &Path, path: &Path, window: &Window, out: &Path) -> Result<()> {
    let mut cmd = Command::new(ffmpeg);
    cmd.args(["-hide_banner", "-nostdin", "-loglevel", "error", "-y"]);
    time_args(&mut cmd, window);
    let output = cmd
        .arg("-i")
        .arg(path)
        .args([
            "-map",
            "0:a:0",
            "-vn",
            "-ac",
            "1",
            "-ar",
            "16000",
            "-c:a",
            "pcm_s16le",
        ])
        .args(["-f", "wav"])
        .arg(out)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| Error::io(ffmpeg, e))?;
    if !output.status.success() {
        let lines: Vec<String> = String::from_utf8_lossy(&output.stderr)
            .lines()
            .map(str::to_string)
            .collect();
        return Err(Error::invalid(
            path,
            format!("ffmpeg could not decode the audio: {}", last_error(&lines)),
        ));
    }
    Ok(())
}

fn time_args(cmd: &mut Command, window: &Window) {
    if window.start > 0.0 {
        cmd.args(["-ss", &format!("{:.3}", window.start)]);
    }
    if let Some(t) = window.seconds {
        cmd.args(["-t", &format!("{t:.3}")]);
    }
}

/// The last line of ffmpeg's log that is not a progress or showinfo line.
fn last_error(lines: &[String]) -> String {
    lines
        .iter()
        .rev()
        .map(|l| l.trim())
        .find(|l| !l.is_empty() && !l.contains("showinfo") && !l.starts_with("frame="))
        .unwrap_or("no message")
        .to_string()
}

/// A path beside `path` for a file being written (renamed into place when complete).
pub fn part_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".part");
    path.with_file_name(name)
}

/// Refuses a clip of `n` usable frames when fewer than `min` are left (`what`: after what),
/// naming the video and the seconds it holds.
pub(crate) fn too_short(video: &Path, n: usize, min: usize, fps: f64, what: &str) -> Result<()> {
    if n < min {
        return Err(Error::invalid(
            video,
            format!(
                "too short to train: {n} frames with one face {what} ({:.1} s), at least {min} needed",
                n as f64 / fps
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const MP4: &str = "Input #0, mov,mp4,m4a,3gp,3g2,mj2, from 'a.mp4':
  Duration: 00:00:04.00, start: 0.000000, bitrate: 900 kb/s
  Stream #0:0[0x1](und): Video: h264 (High) (avc1 / 0x31637661), yuv420p(progressive), 512x512 [SAR 1:1 DAR 1:1], 800 kb/s, 25 fps, 25 tbr, 12800 tbn (default)
  Stream #0:1[0x2](und): Audio: aac (LC) (mp4a / 0x6134706D), 16000 Hz, mono, fltp, 69 kb/s (default)
At least one output file must be specified";

    #[test]
    fn a_probe_reads_size_rate_audio_and_duration() {
        let p = parse_probe(Path::new("a.mp4"), MP4).unwrap();
        assert_eq!(
            (p.width, p.height, p.fps, p.has_audio),
            (512, 512, 25.0, true)
        );
        assert_eq!(p.duration, Some(4.0));
    }

    #[test]
    fn a_probe_refuses_audio_only_and_corrupt_files() {
        let audio_only = "  Duration: 00:00:02.00\n  Stream #0:0: Audio: pcm_s16le, 16000 Hz";
        let e = parse_probe(Path::new("a.wav"), audio_only).unwrap_err();
        assert!(e.to_string().contains("audio only"), "{e}");
        let cover = format!(
            "{audio_only}\n  Stream #0:1: Video: mjpeg, yuvj420p, 300x300, 90k tbr (attached pic)"
        );
        assert!(parse_probe(Path::new("a.m4a"), &cover).is_err());
        let corrupt =
            "[mov,mp4 @ 0x1] moov atom not found\nb.mp4: Invalid data found when processing input";
        let e = parse_probe(Path::new("b.mp4"), corrupt).unwrap_err();
        assert!(
            e.to_string().starts_with("b.mp4: not a readable video"),
            "{e}"
        );
    }

    #[test]
    fn a_constant_rate_has_no_irregular_gaps_and_a_variable_one_has() {
        let cfr: Vec<f64> = (0..100).map(|i| i as f64 * 0.04).collect();
        assert_eq!(irregular_share(&cfr, 25.0), 0.0);
        let vfr: Vec<f64> = (0..100)
            .map(|i| (i as f64 * 0.04) + if i % 2 == 0 { 0.0 } else { 0.02 })
            .collect();
        assert!(irregular_share(&vfr, 25.0) > 0.9);
    }

    #[test]
    fn numbers_before_units_read_fractions_and_thousands() {
        assert_eq!(number_before("a, 29.97 fps, 30 tbr", " fps"), Some(29.97));
        assert_eq!(number_before("a, 90k tbr", " tbr"), Some(90000.0));
        assert_eq!(centre_square(1280, 720), [280, 0, 720]);
    }
}
