//! `nldf bench frontier`: run time against error. Every way nldf can render a run's
//! held-out frames renders the same frames one after another: the teacher in candle (with
//! its empty-space skipping and early stop, without early stop, and without either, as
//! AD-NeRF renders), and every student exported in f32, f16 and int8, each in onnxruntime
//! and tract. Each is scored against the ground truth (PSNR, SSIM, mouth PSNR) and timed
//! per whole frame (ray set-up, network and compositing): the median over the `val` scoring
//! pass with 2 threads, where the ways of rendering take turns frame by frame (so a burst of
//! load on the machine touches all alike), a second median over a few frames rendered back
//! to back, as a video renders them, and one over a few frames with 1 thread. AD-NeRF's own setting (8 x 256,
//! 64 + 128 samples) is timed on a few frames with seeded weights. Writes `frontier.json`
//! (machine, commit, load, settings, points), `frontier.md` and `frontier.png` (PSNR
//! against time on a log axis, the Pareto front marked), and states the students'
//! speed-up over the teacher at matched PSNR.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use nldf_core::audio::neighbourhood;
use nldf_core::dataset::{Frame, Split};
use nldf_core::image::ImageRgb;
use nldf_core::stats::median;
use nldf_export::WeightType;
use nldf_infer::{BackendKind, BackendOptions, FrameRenderer, backend_for};
use nldf_train::bench::Machine;
use nldf_train::data::TrainData;
use nldf_train::eval::{EvalReport, FrameModel, eval_models, student_short_name};
use nldf_train::job::JobEvent;
use nldf_train::job::eval::EvalJob;
use nldf_train::plot::{FrontierDot, plot_frontier};
use nldf_train::student_trainer::StudentRun;
use nldf_train::teacher_trainer::TeacherRun;
use serde::Serialize;

use crate::progress::EventPrinter;

#[derive(clap::Args, Debug)]
pub struct FrontierArgs {
    /// Run folder: its teacher and every student in it.
    #[arg(long)]
    pub run: PathBuf,
    /// The dataset the run was trained on (its `val` split, and `novel` and `voice` where
    /// `nldf synth` wrote them).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder [default: RUN/frontier].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// At most this many frames per split, spread evenly.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Frames timed with 1 thread per point.
    #[arg(long, default_value_t = 6)]
    pub one_thread_frames: usize,
    /// Training frames that calibrate the int8 exports.
    #[arg(long, default_value_t = 16)]
    pub calibration_frames: usize,
    /// Rays per network call.
    #[arg(long, default_value_t = BackendOptions::default().batch_size)]
    pub batch: usize,
    /// Frames timed for AD-NeRF's setting (8 x 256, 64 + 128 samples per ray, every pixel
    /// and every sample, seeded weights: its time, not its quality); 0 leaves it out.
    #[arg(long, default_value_t = 2)]
    pub adnerf_frames: usize,
    /// The same scene at a higher resolution (`nldf synth --seed S --size 256`): the
    /// teacher and every export in onnxruntime render its `val` frames at its size, with
    /// rays at that size and, where it is a multiple of the model's, with rays at the
    /// model's size upscaled bilinearly; scored, timed and tabled apart.
    #[arg(long)]
    pub hires_data: Option<PathBuf>,
    /// Frames each point also renders back to back, as a video renders them, for a second
    /// 2-thread median beside the scoring pass's: in three rounds where every point takes
    /// its turn, each turn one untimed frame and then its share of these.
    #[arg(long, default_value_t = 8)]
    pub timed_frames: usize,
}

/// Threads of the main timing.
const THREADS: usize = 2;

/// Precisions every student is exported in.
const PRECISIONS: [WeightType; 3] = [WeightType::F32, WeightType::F16, WeightType::Int8];

fn precision_name(w: WeightType) -> &'static str {
    match w {
        WeightType::F32 => "fp32",
        WeightType::F16 => "fp16",
        WeightType::Int8 => "int8",
    }
}

/// An exported student in one runtime, rendering whole frames and timing each.
struct OnnxPoint {
    student: String,
    describe: String,
    short: String,
    precision: WeightType,
    kind: BackendKind,
    step: usize,
    macs_per_ray: f64,
    path: PathBuf,
    renderer: RefCell<FrameRenderer>,
    /// Each frame is rendered this many times smaller and upscaled bilinearly (1: not).
    upscale: u32,
    seconds: RefCell<Vec<f64>>,
}

impl OnnxPoint {
    /// The student's description, with the upscaling if any.
    fn model_name(&self) -> String {
        if self.upscale > 1 {
            format!("{}, upscaled {}x", self.describe, self.upscale)
        } else {
            self.describe.clone()
        }
    }

    fn audio(&self, data: &TrainData, frame: &Frame) -> Vec<f32> {
        let renderer = self.renderer.borrow();
        neighbourhood(
            &data.dataset.audio,
            frame.aud_id,
            renderer.info().audio.att_frames,
        )
    }
}

impl FrameModel for OnnxPoint {
    fn label(&self) -> String {
        let up = if self.upscale > 1 {
            format!(".up{}", self.upscale)
        } else {
            String::new()
        };
        format!(
            "{}.{}.{}{up}",
            self.student,
            precision_name(self.precision),
            self.kind.name()
        )
    }
    fn describe(&self) -> String {
        format!(
            "{} {} {}",
            self.model_name(),
            precision_name(self.precision),
            self.kind.name()
        )
    }
    fn step(&self) -> usize {
        self.step
    }
    fn macs_per_ray(&self) -> f64 {
        // Per ray of the frame it is scored at: an upscaled frame runs 1 / factor² of them.
        self.macs_per_ray / (self.upscale * self.upscale) as f64
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> nldf_train::error::Result<ImageRgb> {
        let audio = self.audio(data, frame);
        let started = Instant::now();
        let out = self
            .renderer
            .borrow_mut()
            .render(frame.c2w, &audio)
            .map_err(|e| {
                nldf_train::error::Error::Config(format!("{}: {e}", self.path.display()))
            })?;
        let image = out.image.upscaled(self.upscale);
        self.seconds
            .borrow_mut()
            .push(started.elapsed().as_secs_f64());
        Ok(image)
    }
}

/// The teacher in candle with its savings on or off, its whole frames timed.
struct Timed<'a> {
    run: &'a TeacherRun,
    /// Sample only inside the head's bounds.
    skip: bool,
    /// Leave a ray once its transmittance is spent.
    early_stop: bool,
    seconds: RefCell<Vec<f64>>,
}

impl<'a> Timed<'a> {
    fn new(run: &'a TeacherRun, skip: bool, early_stop: bool) -> Timed<'a> {
        Timed {
            run,
            skip,
            early_stop,
            seconds: RefCell::new(Vec::new()),
        }
    }

    /// What the savings left off add to the teacher's description and to its label.
    fn savings(&self) -> (&'static str, &'static str) {
        match (self.skip, self.early_stop) {
            (true, true) => ("", ""),
            (true, false) => (", no early stop", ".no_early_stop"),
            (false, true) => (", no skipping", ".no_skipping"),
            (false, false) => (", no skipping, no early stop", ".no_skipping.no_early_stop"),
        }
    }
}

impl FrameModel for Timed<'_> {
    fn label(&self) -> String {
        format!("{}{}", self.run.label(), self.savings().1)
    }
    fn describe(&self) -> String {
        format!("{}{}", self.run.describe(), self.savings().0)
    }
    fn step(&self) -> usize {
        self.run.step
    }
    fn macs_per_ray(&self) -> f64 {
        self.run.macs_per_ray()
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> nldf_train::error::Result<ImageRgb> {
        let started = Instant::now();
        let image = self
            .run
            .render_frame_with(data, frame, self.skip, self.early_stop)?;
        self.seconds
            .borrow_mut()
            .push(started.elapsed().as_secs_f64());
        Ok(image)
    }
}

/// Scores of one point on one split.
#[derive(Debug, Clone, Serialize)]
struct SplitScore {
    split: String,
    frames: usize,
    psnr: f64,
    ssim: f64,
    /// PSNR inside the head (the headline; the whole frame counts copied background).
    head_psnr: Option<f64>,
    head_ssim: Option<f64>,
    mouth_psnr: Option<f64>,
}

/// One way of rendering: its scores and times.
#[derive(Debug, Clone, Default, Serialize)]
struct Point {
    model: String,
    /// Its name in plots: the network's shape and recipe, and the precision.
    short: String,
    /// Frames rendered this many times smaller, then upscaled (1: at their own size).
    upscale: u32,
    /// `fp32`, `fp16` or `int8`.
    precision: String,
    runtime: String,
    /// The model file (exports only).
    file: Option<PathBuf>,
    file_bytes: Option<u64>,
    step: usize,
    /// The frames' width and height in pixels.
    size: u32,
    gmac_per_frame: f64,
    /// Median milliseconds per whole frame over the `val` scoring pass, 2 threads: the ways
    /// of rendering take turns frame by frame, so each median spans the whole pass and a
    /// burst of load on the machine touches every point alike.
    ms_2_threads: f64,
    /// Median milliseconds per whole frame over `--timed-frames` `val` frames rendered back
    /// to back (warm caches, as a video renders them, but a few seconds of the machine's
    /// time), 2 threads.
    ms_back_to_back: f64,
    /// Median milliseconds per whole frame over the first frames, 1 thread.
    ms_1_thread: Option<f64>,
    scores: Vec<SplitScore>,
    /// No other point is both faster (2 threads) and better on `val` PSNR.
    on_front: bool,
}

/// A point's times, in seconds: the scoring pass's median, the back-to-back median and
/// (exports only) the 1-thread median.
struct Times {
    taking_turns: f64,
    back_to_back: f64,
    one_thread: Option<f64>,
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
            ms_1_thread: times.one_thread.map(|s| 1e3 * s),
            scores,
            ..Point::default()
        }
    }

    /// The teacher's row, rendering frames of `size` pixels.
    fn of_teacher(
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
    fn of_export(
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

    fn psnr(&self, split: &str) -> Option<f64> {
        self.scores
            .iter()
            .find(|s| s.split == split)
            .map(|s| s.psnr)
    }
}

/// Median seconds per frame of `model` rendering `frames` back to back after one untimed.
/// Rounds of [`time_back_to_back`].
const BACK_TO_BACK_ROUNDS: usize = 3;

/// Each model's median time per whole frame rendered back to back, interleaved: in each of
/// [`BACK_TO_BACK_ROUNDS`] rounds every model renders one untimed frame, then its share of
/// `frames` back to back. Each frame follows the model's own previous one (warm caches, as
/// a video renders them), and each model's times span the whole timing period, so a drift
/// of the machine's speed over minutes touches every model alike.
fn time_back_to_back(
    models: &[&dyn FrameModel],
    data: &TrainData,
    frames: &[Frame],
) -> Result<Vec<f64>> {
    let rounds = BACK_TO_BACK_ROUNDS.min(frames.len()).max(1);
    let mut times = vec![Vec::with_capacity(frames.len()); models.len()];
    for r in 0..rounds {
        let chunk = &frames[r * frames.len() / rounds..(r + 1) * frames.len() / rounds];
        let Some(first) = chunk.first() else {
            continue;
        };
        for (model, times) in models.iter().zip(times.iter_mut()) {
            model.render_frame(data, first)?;
            for f in chunk {
                let started = Instant::now();
                model.render_frame(data, f)?;
                times.push(started.elapsed().as_secs_f64());
            }
        }
    }
    Ok(times.iter().map(|t| median(t)).collect())
}

fn score(r: &EvalReport) -> SplitScore {
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

/// One student exported in one precision.
struct Export {
    /// The student's folder name.
    student: String,
    describe: String,
    /// The student's name in plots ([`student_short_name`]).
    short: String,
    step: usize,
    macs_per_ray: f64,
    precision: WeightType,
    path: PathBuf,
}

/// Exports every student of the run in every precision into `dir`.
fn export_all(
    students: &[StudentRun],
    data: &Path,
    calibration_frames: usize,
    dir: &Path,
) -> Result<Vec<Export>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut out = Vec::new();
    for s in students {
        let name = s.label();
        for w in PRECISIONS {
            let path = dir.join(format!("{name}.{}.onnx", precision_name(w)));
            let report = match w {
                WeightType::Int8 => {
                    nldf_infer::calibrate::export_int8(&s.dir, data, calibration_frames, &path)
                        .map_err(anyhow::Error::from)
                }
                _ => nldf_export::export_student(&s.dir, &path, w).map_err(anyhow::Error::from),
            };
            match report {
                Ok(_) => {
                    eprintln!("exported {}", path.display());
                    out.push(Export {
                        student: name.clone(),
                        describe: s.describe(),
                        short: student_short_name(&s.cfg),
                        step: s.step,
                        macs_per_ray: s.macs_per_ray(),
                        precision: w,
                        path,
                    });
                }
                // A student whose weights do not fit half precision has no f16 point.
                Err(e) if w == WeightType::F16 => {
                    eprintln!("{name}: no fp16 point: {e:#}")
                }
                Err(e) => return Err(e.context(format!("exporting {name}"))),
            }
        }
    }
    Ok(out)
}

/// `e` in `kind`, rendering frames of `size` (`None`: the model's own), each `upscale` times
/// smaller and then upscaled.
fn open_point(
    e: &Export,
    kind: BackendKind,
    threads: usize,
    batch: usize,
    size: Option<u32>,
    upscale: u32,
) -> Result<OnnxPoint> {
    let model = nldf_export::read_model(&e.path)?;
    // The points take turns frame by frame: a pool left spinning after its call would run
    // beside the next point's.
    let backend = backend_for(
        &model,
        kind,
        BackendOptions {
            batch_size: batch,
            threads,
            spin: false,
        },
    )?;
    let size = size.map(|s| s / upscale.max(1));
    Ok(OnnxPoint {
        student: e.student.clone(),
        describe: e.describe.clone(),
        short: e.short.clone(),
        precision: e.precision,
        kind,
        step: e.step,
        macs_per_ray: e.macs_per_ray,
        path: e.path.clone(),
        renderer: RefCell::new(FrameRenderer::new(backend, size)?),
        upscale: upscale.max(1),
        seconds: RefCell::new(Vec::new()),
    })
}

/// Runs `nldf bench frontier`.
pub fn run(args: FrontierArgs) -> Result<()> {
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.run.join("frontier"));
    // Every point runs in onnxruntime too: refuse before anything is exported.
    nldf_infer::ort_library::OrtSearch::from_env()
        .find()
        .context("bench frontier renders every export in onnxruntime")?;
    let machine = Machine::here();
    let mut printer = EventPrinter::default();
    let mut show = |e: &JobEvent| printer.show(e);
    let splits = splits(&args.data);
    let val = EvalJob {
        run: args.run.clone(),
        data: args.data.clone(),
        split: Split::Val,
        frames: args.frames,
        out: None,
    }
    .plan(&mut show)?;
    if val.students.is_empty() {
        bail!(
            "{} has no trained student to put on the frontier",
            args.run.display()
        );
    }
    let exports = export_all(
        &val.students,
        &args.data,
        args.calibration_frames,
        &out.join("models"),
    )?;
    // Every export in both runtimes; `val` scores them all, the other splits score the
    // onnxruntime points (tract runs the same graphs: the suite's parity tests).
    let mut points: Vec<OnnxPoint> = Vec::new();
    for e in &exports {
        for kind in [BackendKind::Ort, BackendKind::Tract] {
            points.push(open_point(e, kind, THREADS, args.batch, None, 1)?);
        }
    }
    let teacher = Timed::new(&val.teacher, true, true);
    // The teacher without its savings: scored and timed on `val` only.
    let plain = [
        Timed::new(&val.teacher, true, false),
        Timed::new(&val.teacher, false, false),
    ];
    let mut reports: Vec<Vec<EvalReport>> = Vec::new();
    for &split in &splits {
        let plan = if split == Split::Val {
            None
        } else {
            Some(
                EvalJob {
                    run: args.run.clone(),
                    data: args.data.clone(),
                    split,
                    frames: args.frames,
                    out: None,
                }
                .plan(&mut show)?,
            )
        };
        let data = plan.as_ref().map_or(&val.data, |p| &p.data);
        let mut models: Vec<&dyn FrameModel> = vec![&teacher];
        if split == Split::Val {
            models.extend(plain.iter().map(|t| t as &dyn FrameModel));
        }
        models.extend(
            points
                .iter()
                .filter(|p| split == Split::Val || p.kind == BackendKind::Ort)
                .map(|p| p as &dyn FrameModel),
        );
        let n = args
            .frames
            .unwrap_or(usize::MAX)
            .min(data.dataset.frames(split).len());
        eprintln!(
            "{}: {} frames x {} ways of rendering",
            split.name(),
            n,
            models.len()
        );
        let bar = crate::progress::progress_bar(n as u64, split.name());
        let evaluation = eval_models(
            &models,
            data,
            split,
            args.frames,
            &out.join(split.name()),
            &mut || bar.inc(1),
        )?;
        bar.finish_and_clear();
        evaluation.check_finite()?;
        reports.push(evaluation.models);
    }
    // Medians over the `val` pass: the first frames each point rendered.
    let n_val = reports[0].first().map_or(0, |r| r.frames.len());
    let val_median = |s: &RefCell<Vec<f64>>| median(&s.borrow()[..n_val.min(s.borrow().len())]);
    // Back-to-back times over `--timed-frames`, every way of rendering in turn.
    let val_frames = val.data.dataset.frames(Split::Val);
    let timed = &val_frames[..args.timed_frames.min(val_frames.len())];
    let back_to_back = {
        let models: Vec<&dyn FrameModel> = std::iter::once(&teacher)
            .chain(&plain)
            .map(|t| t as &dyn FrameModel)
            .chain(points.iter().map(|p| p as &dyn FrameModel))
            .collect();
        time_back_to_back(&models, &val.data, timed)?
    };
    // 1-thread times: each export in each runtime on the first frames of `val`.
    let frames = val.data.dataset.frames(Split::Val);
    let k = args.one_thread_frames.min(frames.len());
    let mut one_thread = Vec::new();
    for e in &exports {
        for kind in [BackendKind::Ort, BackendKind::Tract] {
            let p = open_point(e, kind, 1, args.batch, None, 1)?;
            for f in &frames[..k] {
                p.render_frame(&val.data, f)?;
            }
            // The first frame pays for plans and caches.
            one_thread.push(median(p.seconds.borrow().get(1..).unwrap_or(&[])));
        }
    }
    let mut table: Vec<Point> = Vec::new();
    let scores_of = |label: &str| -> Vec<SplitScore> {
        reports
            .iter()
            .filter_map(|rs| rs.iter().find(|r| r.label == label).map(score))
            .collect()
    };
    // The teacher first: `speed_ups` compares every point with the first row.
    for (k, t) in std::iter::once(&teacher).chain(&plain).enumerate() {
        let report = reports[0]
            .iter()
            .find(|r| r.label == t.label())
            .context("a teacher lacks its val report")?;
        let times = Times {
            taking_turns: val_median(&t.seconds),
            back_to_back: back_to_back[k],
            one_thread: None,
        };
        let size = val.data.dataset.intrinsics.width;
        table.push(Point::of_teacher(
            t,
            report,
            size,
            times,
            scores_of(&t.label()),
        ));
    }
    let adnerf = if args.adnerf_frames > 0 {
        Some(time_adnerf_setting(&val.data, args.adnerf_frames)?)
    } else {
        None
    };
    for (i, p) in points.iter().enumerate() {
        let label = p.label();
        let size = p.renderer.borrow().intrinsics().width;
        let report = reports[0]
            .iter()
            .find(|r| r.label == label)
            .context("a point lacks its val report")?;
        let times = Times {
            taking_turns: val_median(&p.seconds),
            back_to_back: back_to_back[1 + plain.len() + i],
            one_thread: one_thread.get(i).copied(),
        };
        table.push(Point::of_export(p, report, size, times, scores_of(&label)));
    }
    mark_front(&mut table);
    let summary = speed_ups(&table);
    let hires = match &args.hires_data {
        Some(dir) => Some(hires_points(&args, dir, &exports, &out, &mut show)?),
        None => None,
    };
    write_outputs(
        &out,
        &machine,
        &args,
        &splits,
        &table,
        &summary,
        adnerf,
        hires.as_deref(),
    )?;
    Ok(())
}

/// The `--hires-data` pass: the teacher and every export in onnxruntime on the higher
/// resolution scene's `val` frames, with rays at its size and (where the size is a multiple
/// of the model's) at the model's size upscaled; the Pareto front marked among them.
fn hires_points(
    args: &FrontierArgs,
    dir: &Path,
    exports: &[Export],
    out: &Path,
    show: &mut impl FnMut(&JobEvent),
) -> Result<Vec<Point>> {
    let plan = EvalJob {
        run: args.run.clone(),
        data: dir.to_path_buf(),
        split: Split::Val,
        frames: args.frames,
        out: None,
    }
    .plan(show)?;
    let size = plan.data.dataset.intrinsics.width;
    let teacher = Timed::new(&plan.teacher, true, true);
    let mut points = Vec::new();
    for e in exports {
        let own = nldf_export::read_model(&e.path)?.info.spec.intrinsics.width;
        points.push(open_point(
            e,
            BackendKind::Ort,
            THREADS,
            args.batch,
            Some(size),
            1,
        )?);
        if own < size && size % own == 0 {
            let factor = size / own;
            points.push(open_point(
                e,
                BackendKind::Ort,
                THREADS,
                args.batch,
                Some(size),
                factor,
            )?);
        }
    }
    let mut models: Vec<&dyn FrameModel> = vec![&teacher];
    models.extend(points.iter().map(|p| p as &dyn FrameModel));
    let n = args
        .frames
        .unwrap_or(usize::MAX)
        .min(plan.data.dataset.frames(Split::Val).len());
    eprintln!(
        "val at {size} x {size} ({}): {n} frames x {} ways of rendering",
        dir.display(),
        models.len()
    );
    let bar = crate::progress::progress_bar(n as u64, "val");
    let evaluation = eval_models(
        &models,
        &plan.data,
        Split::Val,
        args.frames,
        &out.join(format!("val_{size}")),
        &mut || bar.inc(1),
    )?;
    bar.finish_and_clear();
    evaluation.check_finite()?;
    let hires_frames = plan.data.dataset.frames(Split::Val);
    let timed = &hires_frames[..args.timed_frames.min(hires_frames.len())];
    let report_of = |label: &str| {
        evaluation
            .models
            .iter()
            .find(|r| r.label == label)
            .with_context(|| format!("{label} lacks its report at {size} pixels"))
    };
    // Each point's turn-taking times are read before it renders again back to back.
    let teacher_turns = median(&teacher.seconds.borrow());
    let point_turns: Vec<f64> = points.iter().map(|p| median(&p.seconds.borrow())).collect();
    let models: Vec<&dyn FrameModel> = std::iter::once(&teacher as &dyn FrameModel)
        .chain(points.iter().map(|p| p as &dyn FrameModel))
        .collect();
    let back_to_back = time_back_to_back(&models, &plan.data, timed)?;
    let mut table = Vec::new();
    let r = report_of(&teacher.label())?;
    let times = Times {
        taking_turns: teacher_turns,
        back_to_back: back_to_back[0],
        one_thread: None,
    };
    table.push(Point::of_teacher(&teacher, r, size, times, vec![score(r)]));
    for (i, p) in points.iter().enumerate() {
        let r = report_of(&p.label())?;
        let times = Times {
            taking_turns: point_turns[i],
            back_to_back: back_to_back[1 + i],
            one_thread: None,
        };
        table.push(Point::of_export(p, r, size, times, vec![score(r)]));
    }
    mark_front(&mut table);
    Ok(table)
}

/// AD-NeRF's setting timed as the paper compares against it: 8 x 256 with 64 coarse + 128
/// fine samples, every pixel of the frame sampled over `[near, far]` and every sample
/// evaluated. The weights are seeded (training it takes hours on 2 cores), so this is its
/// time per frame, not its quality; returns milliseconds per frame (median of `n`
/// frames) and multiply-adds per frame.
fn time_adnerf_setting(data: &TrainData, n: usize) -> Result<(f64, f64)> {
    use nldf_train::config::TeacherRunConfig;
    let cfg = TeacherRunConfig {
        model: crate::train_cmd::TeacherPreset::AdNerf.config(),
        ..TeacherRunConfig::default()
    };
    let scratch = tempfile::tempdir().context("creating a temporary folder")?;
    let run = TeacherRun::create(scratch.path(), cfg, data)?;
    let timed = Timed::new(&run, false, false);
    let frames = data.dataset.frames(Split::Val);
    eprintln!("timing AD-NeRF's setting on {n} frames after an untimed one (seeded weights)");
    for f in frames.iter().cycle().take(n + 1) {
        timed.render_frame(data, f)?;
    }
    let pixels = (data.dataset.intrinsics.width * data.dataset.intrinsics.height) as f64;
    Ok((
        1e3 * median(timed.seconds.borrow().get(1..).unwrap_or(&[])),
        pixels * run.macs_per_ray(),
    ))
}

/// Marks the points no other point beats on both time (2 threads) and `val` PSNR.
fn mark_front(table: &mut [Point]) {
    let keys: Vec<(f64, f64)> = table
        .iter()
        .map(|p| (p.ms_2_threads, p.psnr("val").unwrap_or(f64::NAN)))
        .collect();
    for (i, p) in table.iter_mut().enumerate() {
        let (t, q) = keys[i];
        p.on_front = t.is_finite()
            && q.is_finite()
            && !keys
                .iter()
                .enumerate()
                .any(|(j, &(t2, q2))| j != i && t2 <= t && q2 >= q && (t2 < t || q2 > q));
    }
}

/// The fastest export within 1 dB of the teacher on each split, and its speed-up over the
/// teacher (whole frames, 2 threads, the same run).
#[derive(Debug, Clone, Serialize)]
struct SpeedUp {
    split: String,
    teacher_psnr: f64,
    point: Option<String>,
    point_psnr: Option<f64>,
    speed_up: Option<f64>,
}

fn speed_ups(table: &[Point]) -> Vec<SpeedUp> {
    let teacher = &table[0];
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
                speed_up: best.map(|p| teacher.ms_2_threads / p.ms_2_threads),
            }
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn write_outputs(
    out: &Path,
    machine: &Machine,
    args: &FrontierArgs,
    splits: &[Split],
    table: &[Point],
    summary: &[SpeedUp],
    adnerf: Option<(f64, f64)>,
    hires: Option<&[Point]>,
) -> Result<()> {
    let settings = serde_json::json!({
        "run": args.run, "data": args.data, "frames": args.frames,
        "threads": THREADS, "one_thread_frames": args.one_thread_frames,
        "calibration_frames": args.calibration_frames, "batch": args.batch,
        "hires_data": args.hires_data, "timed_frames": args.timed_frames,
    });
    let adnerf_json = adnerf.map(|(ms, macs)| serde_json::json!({"ms_2_threads": ms, "gmac_per_frame": macs / 1e9, "frames": args.adnerf_frames}));
    let json = serde_json::json!({
        "machine": machine, "settings": settings, "points": table, "speed_up": summary,
        "adnerf_setting": adnerf_json, "hires_points": hires,
    });
    let json_path = out.join("frontier.json");
    nldf_core::files::write_atomic(&json_path, serde_json::to_string_pretty(&json)?.as_bytes())?;
    let mut md = String::new();
    md.push_str(&format!(
        "# Run time against error\n\n{} ({} cores), commit {}, load {} at the start. Whole \
         frames (ray set-up, network, compositing): the median over the val scoring pass with \
         {THREADS} threads, where the ways of rendering take turns frame by frame; beside it \
         the median over {} val frames rendered back to back; and over {} frames with 1 \
         thread. Scores over every frame of each split.\n\n",
        machine.cpu,
        machine.cores,
        machine.commit,
        machine
            .load_average_1m
            .map_or("unknown".into(), |l| format!("{l:.2}")),
        args.timed_frames,
        args.one_thread_frames.saturating_sub(1),
    ));
    md.push_str("| model | precision | runtime | MB | GMAC / frame | ms / frame (2 threads) | frames/s | ms, back to back | ms (1 thread) |");
    for s in splits {
        md.push_str(&format!(
            " {0} head PSNR | {0} PSNR | {0} mouth |",
            s.name()
        ));
    }
    md.push_str(" val SSIM | front |\n|");
    md.push_str(&"---|".repeat(9 + 3 * splits.len() + 2));
    md.push('\n');
    for p in table {
        let val_ssim = p
            .scores
            .iter()
            .find(|s| s.split == "val")
            .map_or(f64::NAN, |s| s.ssim);
        md.push_str(&format!(
            "| {} | {} | {} | {} | {:.1} | {:.1} | {:.2} | {:.1} | {} |",
            p.model,
            p.precision,
            p.runtime,
            p.file_bytes
                .map_or("".into(), |b| format!("{:.2}", b as f64 / 1e6)),
            p.gmac_per_frame,
            p.ms_2_threads,
            1e3 / p.ms_2_threads,
            p.ms_back_to_back,
            p.ms_1_thread.map_or("".into(), |t| format!("{t:.1}")),
        ));
        for s in splits {
            match p.scores.iter().find(|x| x.split == s.name()) {
                Some(x) => md.push_str(&format!(
                    " {} | {:.2} | {} |",
                    x.head_psnr.map_or("".into(), |h| format!("{h:.2}")),
                    x.psnr,
                    x.mouth_psnr.map_or("".into(), |m| format!("{m:.2}"))
                )),
                None => md.push_str(" | | |"),
            }
        }
        md.push_str(&format!(
            " {val_ssim:.4} | {} |\n",
            if p.on_front { "yes" } else { "" }
        ));
    }
    md.push_str("\nFastest export within 1 dB of the teacher's PSNR, whole frames side by side:\n\n| split | teacher PSNR | fastest within 1 dB | its PSNR | speed-up |\n|---|---|---|---|---|\n");
    for s in summary {
        md.push_str(&format!(
            "| {} | {:.2} | {} | {} | {} |\n",
            s.split,
            s.teacher_psnr,
            s.point.as_deref().unwrap_or("none"),
            s.point_psnr.map_or("".into(), |q| format!("{q:.2}")),
            s.speed_up.map_or("".into(), |x| format!("{x:.1}x")),
        ));
    }
    if let Some((ms, macs)) = adnerf {
        md.push_str(&format!(
            "\nAD-NeRF's setting (8 x 256, 64 + 128 samples, every pixel and sample, seeded \
             weights: time only), median of {} frames: {ms:.0} ms per frame, {:.0} GMAC. \
             Against it, whole frames, {THREADS} threads:\n\n| point | ms / frame | speed-up |\n|---|---|---|\n",
            args.adnerf_frames,
            macs / 1e9
        ));
        let mut listed: Vec<&Point> = summary
            .iter()
            .filter_map(|s| {
                let name = s.point.as_deref()?;
                table
                    .iter()
                    .find(|p| format!("{} {} {}", p.model, p.precision, p.runtime) == name)
            })
            .collect();
        if let Some(fastest) = table
            .iter()
            .filter(|p| p.runtime != "candle")
            .min_by(|a, b| a.ms_2_threads.total_cmp(&b.ms_2_threads))
        {
            listed.push(fastest);
        }
        let mut seen: Vec<*const Point> = Vec::new();
        listed.retain(|p| {
            let new = !seen.contains(&(*p as *const Point));
            seen.push(*p as *const Point);
            new
        });
        for p in listed {
            md.push_str(&format!(
                "| {} {} {} (val {:.2} dB) | {:.1} | {:.0}x |\n",
                p.model,
                p.precision,
                p.runtime,
                p.psnr("val").unwrap_or(f64::NAN),
                p.ms_2_threads,
                ms / p.ms_2_threads
            ));
        }
    }
    let mut pngs = Vec::new();
    if let Some(hires) = hires.filter(|h| !h.is_empty()) {
        let size = hires[0].size;
        md.push_str(&format!(
            "\n## {size} x {size}\n\nThe same scene's `val` frames at {size} x {size} ({}): \
             rays at that size, or at the model's size and upscaled bilinearly; medians over \
             the scoring pass (and over frames back to back), {THREADS} threads.\n\n\
             | model | precision | runtime | GMAC / frame | ms / frame (2 threads) | frames/s | \
             ms, back to back | val PSNR | val mouth | val SSIM | front |\n\
             |---|---|---|---|---|---|---|---|---|---|---|\n",
            args.hires_data
                .as_deref()
                .map_or(String::new(), |d| d.display().to_string()),
        ));
        for p in hires {
            let s = p.scores.first();
            md.push_str(&format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.2} | {:.1} | {:.2} | {} | {:.4} | {} |\n",
                p.model,
                p.precision,
                p.runtime,
                p.gmac_per_frame,
                p.ms_2_threads,
                1e3 / p.ms_2_threads,
                p.ms_back_to_back,
                s.map_or(f64::NAN, |s| s.psnr),
                s.and_then(|s| s.mouth_psnr)
                    .map_or("".into(), |m| format!("{m:.2}")),
                s.map_or(f64::NAN, |s| s.ssim),
                if p.on_front { "yes" } else { "" }
            ));
        }
        let path = out.join(format!("frontier_{size}.png"));
        plot_frontier(
            &path,
            &format!(
                "val PSNR at {size} x {size} against time per frame, {THREADS} threads, {}",
                machine.cpu
            ),
            &dots_of(hires),
        )?;
        pngs.push(path);
    }
    let md_path = out.join("frontier.md");
    nldf_core::files::write_atomic(&md_path, md.as_bytes())?;
    let png_path = out.join("frontier.png");
    plot_frontier(
        &png_path,
        &format!(
            "val PSNR against time per frame, {} threads, {}",
            THREADS, machine.cpu
        ),
        &dots_of(table),
    )?;
    println!("{md}");
    println!(
        "wrote {}, {} and {}",
        json_path.display(),
        md_path.display(),
        std::iter::once(&png_path)
            .chain(&pngs)
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

/// The plot's dots of `table`: one group per runtime and precision, the teacher apart.
fn dots_of(table: &[Point]) -> Vec<FrontierDot> {
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
        assert_eq!(s.speed_up, Some(5.0));
    }
}
