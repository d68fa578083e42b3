//! The frontier's rows and what is read from them: each way of rendering's scores and times
//! ([`Point`]), the Pareto front of time against `val` PSNR, and the students' speed-up over
//! the teacher at matched PSNR.

use std::path::PathBuf;

use nldf_train::reports::eval::{EvalReport, FrameModel};
use nldf_train::trainers::plot::FrontierDot;
use serde::Serialize;

use super::points::{OnnxPoint, Timed};
use super::shared::precision_name;
use crate::repeats::Ratio;

/// Scores of one point on one split.
#[derive(Debug, Clone, Serialize)]
pub struct SplitScore {
    pub split: String,
    pub frames: usize,
    pub psnr: f64,
    pub ssim: f64,
    /// PSNR inside the head (the headline; the whole frame counts copied background).
    pub head_psnr: Option<f64>,
    pub head_ssim: Option<f64>,
    pub mouth_psnr: Option<f64>,
}

/// One way of rendering: its scores and times.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Point {
    pub model: String,
    /// Its name in plots: the network's shape and recipe, and the precision.
    pub short: String,
    /// Frames rendered this many times smaller, then upscaled (1: at their own size).
    pub upscale: u32,
    /// `fp32`, `fp16` or `int8`.
    pub precision: String,
    pub runtime: String,
    /// The model file (exports only).
    pub file: Option<PathBuf>,
    pub file_bytes: Option<u64>,
    pub step: usize,
    /// The frames' width and height in pixels.
    pub size: u32,
    pub gmac_per_frame: f64,
    /// Median milliseconds per whole frame over the `val` scoring pass, 2 threads: the ways
    /// of rendering take turns frame by frame, so each median spans the whole pass and a
    /// burst of load on the machine touches every point alike.
    pub ms_2_threads: f64,
    /// Median milliseconds per whole frame over `--timed-frames` `val` frames rendered back
    /// to back (warm caches, as a video renders them, but a few seconds of the machine's
    /// time), 2 threads.
    pub ms_back_to_back: f64,
    /// Median milliseconds per whole frame over the first frames, 1 thread.
    pub ms_1_thread: Option<f64>,
    /// Seconds of each whole frame of the `val` scoring pass, in the pass's order: the
    /// pairs of the speed-ups (every point rendered each frame in turn), kept so that any
    /// two points can be compared frame by frame later.
    pub frame_seconds: Vec<f64>,
    pub scores: Vec<SplitScore>,
    /// No other point is both faster (2 threads) and better on `val` PSNR.
    pub on_front: bool,
}

/// A point's times, in seconds: the scoring pass's median, the back-to-back median and
/// (exports only) the 1-thread median.
pub(crate) struct Times {
    pub(crate) taking_turns: f64,
    /// Each frame of the scoring pass, in order.
    pub(crate) frames: Vec<f64>,
    pub(crate) back_to_back: f64,
    pub(crate) one_thread: Option<f64>,
}

impl Point {
    /// What every row measures, rendering frames of `size` pixels; the rest is the row's
    /// own ([`Point::of_teacher`], [`Point::of_export`]).
    fn measured(r: &EvalReport, size: u32, times: Times, scores: Vec<SplitScore>) -> Point {
        Point {
            size,
            gmac_per_frame: r.macs_per_frame / 1e9,
            ms_2_threads: 1e3 * times.taking_turns,
            ms_back_to_back: 1e3 * times.back_to_back,
            ms_1_thread: times.one_thread.filter(|s| s.is_finite()).map(|s| 1e3 * s),
            frame_seconds: times.frames,
            scores,
            ..Point::default()
        }
    }

    /// The teacher's row, rendering frames of `size` pixels.
    pub(crate) fn of_teacher(
        t: &Timed,
        r: &EvalReport,
        size: u32,
        times: Times,
        scores: Vec<SplitScore>,
    ) -> Point {
        Point {
            model: t.describe(),
            short: format!("teacher{}", t.savings().0),
            upscale: 1,
            precision: "fp32".into(),
            runtime: "candle".into(),
            step: r.step,
            ..Point::measured(r, size, times, scores)
        }
    }

    /// An export's row, rendering frames of `size` pixels.
    pub(crate) fn of_export(
        p: &OnnxPoint,
        r: &EvalReport,
        size: u32,
        times: Times,
        scores: Vec<SplitScore>,
    ) -> Point {
        Point {
            model: p.model_name(),
            short: format!("{} {}", p.short, precision_name(p.precision)),
            upscale: p.upscale,
            precision: precision_name(p.precision).into(),
            runtime: p.kind.name().into(),
            file: Some(p.path.clone()),
            file_bytes: std::fs::metadata(&p.path).ok().map(|m| m.len()),
            step: p.step,
            ..Point::measured(r, size, times, scores)
        }
    }

    /// Its PSNR on `split`, where it was scored there.
    pub fn psnr(&self, split: &str) -> Option<f64> {
        self.scores
            .iter()
            .find(|s| s.split == split)
            .map(|s| s.psnr)
    }

    /// Its head-region PSNR on `split`, where it was scored there with a head mask.
    pub fn head_psnr(&self, split: &str) -> Option<f64> {
        self.scores
            .iter()
            .find(|s| s.split == split)
            .and_then(|s| s.head_psnr)
    }
}

/// The scores of an evaluation report.
pub(crate) fn score(r: &EvalReport) -> SplitScore {
    SplitScore {
        split: r.split.clone(),
        frames: r.frames.len(),
        psnr: r.psnr,
        ssim: r.ssim,
        head_psnr: r.head_psnr,
        head_ssim: r.head_ssim,
        mouth_psnr: r.mouth_psnr,
    }
}

/// Marks the points no other point beats on both time (2 threads) and `val` PSNR.
pub fn mark_front(table: &mut [Point]) {
    let keys: Vec<(f64, f64)> = table
        .iter()
        .map(|p| (p.ms_2_threads, p.psnr("val").unwrap_or(f64::NAN)))
        .collect();
    for (p, on) in table.iter_mut().zip(pareto(&keys)) {
        p.on_front = on;
    }
}

/// For each `(time, quality)`: whether it is finite and no other pair is at least as fast
/// and as good, and strictly better in one.
fn pareto(keys: &[(f64, f64)]) -> Vec<bool> {
    keys.iter()
        .enumerate()
        .map(|(i, &(t, q))| {
            t.is_finite()
                && q.is_finite()
                && !keys
                    .iter()
                    .enumerate()
                    .any(|(j, &(t2, q2))| j != i && t2 <= t && q2 >= q && (t2 < t || q2 > q))
        })
        .collect()
}

/// The fastest export within 1 dB of the teacher on each split, and its speed-up over the
/// teacher (whole frames, 2 threads, the same run).
#[derive(Debug, Clone, Serialize)]
pub struct SpeedUp {
    pub split: String,
    pub teacher_psnr: f64,
    pub point: Option<String>,
    pub point_psnr: Option<f64>,
    /// The teacher's time over the point's, frame by frame over the `val` scoring pass
    /// (each frame a pair: the two rendered it in turn); `None` without a point or without
    /// paired frames.
    pub speed_up: Option<Ratio>,
}

/// `a`'s frame times over `b`'s, frame by frame; `None` where they have no frames in
/// common or a time is not positive.
pub(crate) fn paired_ratio(a: &[f64], b: &[f64]) -> Option<Ratio> {
    let n = a.len().min(b.len());
    let pairs: Vec<(f64, f64)> = a[..n].iter().copied().zip(b[..n].iter().copied()).collect();
    Ratio::of_pairs(&pairs).ok()
}

/// The speed-up on each split the teacher (the first row of `table`) was scored on.
pub fn speed_ups(table: &[Point]) -> Vec<SpeedUp> {
    let Some(teacher) = table.first() else {
        return Vec::new();
    };
    teacher
        .scores
        .iter()
        .map(|ts| {
            // Among the exported students: the teacher's own variants are no speed-up.
            let best = table[1..]
                .iter()
                .filter(|p| p.file.is_some())
                .filter(|p| p.psnr(&ts.split).is_some_and(|q| q >= ts.psnr - 1.0))
                .min_by(|a, b| a.ms_2_threads.total_cmp(&b.ms_2_threads));
            SpeedUp {
                split: ts.split.clone(),
                teacher_psnr: ts.psnr,
                point: best.map(|p| format!("{} {} {}", p.model, p.precision, p.runtime)),
                point_psnr: best.and_then(|p| p.psnr(&ts.split)),
                speed_up: best.and_then(|p| paired_ratio(&teacher.frame_seconds, &p.frame_seconds)),
            }
        })
        .collect()
}

/// The plot's dots of `table`: one group per runtime and precision, the teacher apart.
pub(crate) fn dots_of(table: &[Point]) -> Vec<FrontierDot> {
    table
        .iter()
        .map(|p| FrontierDot {
            group: if p.runtime == "candle" {
                "teacher (candle)".into()
            } else if p.upscale > 1 {
                format!("{} {}, upscaled", p.runtime, p.precision)
            } else {
                format!("{} {}", p.runtime, p.precision)
            },
            name: p.short.clone(),
            ms: p.ms_2_threads,
            psnr: p.psnr("val").unwrap_or(f64::NAN),
            on_front: p.on_front,
        })
        .collect()
}

/// [`dots_of`] with the `val` head-region PSNR as the quality and the front taken on it;
/// points scored without a head mask are left out.
pub(crate) fn head_dots_of(table: &[Point]) -> Vec<FrontierDot> {
    let keys: Vec<(f64, f64)> = table
        .iter()
        .map(|p| (p.ms_2_threads, p.head_psnr("val").unwrap_or(f64::NAN)))
        .collect();
    dots_of(table)
        .into_iter()
        .zip(keys.iter().zip(pareto(&keys)))
        .map(|(dot, (&(_, q), on))| FrontierDot {
            psnr: q,
            on_front: on,
            ..dot
        })
        .filter(|d| d.psnr.is_finite())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(model: &str, ms: f64, val: f64) -> Point {
        Point {
            model: model.into(),
            short: model.into(),
            upscale: 1,
            precision: "fp32".into(),
            runtime: "ort".into(),
            file: Some(PathBuf::from(format!("{model}.onnx"))),
            file_bytes: None,
            step: 0,
            size: 128,
            gmac_per_frame: 1.0,
            ms_2_threads: ms,
            ms_back_to_back: ms,
            ms_1_thread: None,
            // Five frames around `ms`, each a little slower than the one before.
            frame_seconds: (0..5).map(|i| ms * (1.0 + 0.01 * i as f64) / 1e3).collect(),
            scores: vec![SplitScore {
                split: "val".into(),
                frames: 1,
                psnr: val,
                ssim: 1.0,
                head_psnr: None,
                head_ssim: None,
                mouth_psnr: None,
            }],
            on_front: false,
        }
    }

    #[test]
    fn the_front_keeps_only_points_nothing_beats_on_both_axes() {
        let mut table = vec![
            point("teacher", 500.0, 37.0),
            point("a", 100.0, 35.0),
            point("b", 200.0, 34.0), // slower and worse than a
            point("c", 50.0, 30.0),
            point("d", 100.0, 35.0), // ties a: neither beats the other
            point("nan", f64::NAN, 40.0),
        ];
        mark_front(&mut table);
        let front: Vec<&str> = table
            .iter()
            .filter(|p| p.on_front)
            .map(|p| p.model.as_str())
            .collect();
        assert_eq!(front, ["teacher", "a", "c", "d"]);
    }

    /// The head-region plot takes its front on head PSNR: a point the whole frame ranks
    /// behind can lead there, and a point scored without a head mask is left out.
    #[test]
    fn the_head_plot_has_a_front_of_its_own() {
        let with_head = |model: &str, ms: f64, whole: f64, head: Option<f64>| {
            let mut p = point(model, ms, whole);
            p.scores[0].head_psnr = head;
            p
        };
        let mut table = vec![
            with_head("a", 100.0, 36.0, Some(29.0)),
            with_head("b", 100.0, 35.0, Some(30.0)),
            with_head("c", 50.0, 30.0, None),
        ];
        mark_front(&mut table);
        let whole: Vec<&str> = table
            .iter()
            .filter(|p| p.on_front)
            .map(|p| p.model.as_str())
            .collect();
        assert_eq!(whole, ["a", "c"]);
        let head = head_dots_of(&table);
        let names: Vec<(&str, f64, bool)> = head
            .iter()
            .map(|d| (d.name.as_str(), d.psnr, d.on_front))
            .collect();
        assert_eq!(names, [("a", 29.0, false), ("b", 30.0, true)]);
    }

    #[test]
    fn the_speed_up_is_the_fastest_point_within_1_db_of_the_teacher() {
        let table = vec![
            point("teacher", 500.0, 37.0),
            point("slow", 250.0, 36.5),
            point("fast", 100.0, 36.1),
            point("fastest", 20.0, 35.9), // 1.1 dB below: not matched
            Point {
                runtime: "candle".into(),
                file: None, // a variant of the teacher: no speed-up of a student
                ..point("teacher, no early stop", 90.0, 37.0)
            },
        ];
        let s = &speed_ups(&table)[0];
        assert_eq!(s.point.as_deref(), Some("fast fp32 ort"));
        let r = s.speed_up.unwrap();
        assert!((r.median - 5.0).abs() < 1e-9, "{r:?}");
        assert_eq!((r.pairs, r.verdict), (5, crate::repeats::Verdict::Above));
    }

    /// The speed-up pairs frame with frame: a point that is faster on the median frame
    /// but slower on another is no difference.
    #[test]
    fn a_speed_up_whose_frames_disagree_is_no_difference() {
        let mut table = vec![point("teacher", 100.0, 37.0), point("close", 95.0, 36.5)];
        table[0].frame_seconds = vec![0.100, 0.101, 0.099, 0.100, 0.100];
        table[1].frame_seconds = vec![0.095, 0.094, 0.104, 0.096, 0.095];
        let r = speed_ups(&table)[0].speed_up.unwrap();
        assert!(r.median > 1.0, "{r:?}");
        assert_eq!(r.verdict, crate::repeats::Verdict::NoDifference);
        assert!(r.cell().starts_with("no difference"), "{}", r.cell());
    }
}
