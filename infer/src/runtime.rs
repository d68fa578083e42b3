//! The network as a function of rays and audio, behind one trait so that the frame renderer
//! does not care which runtime evaluates it: [`TractBackend`](crate::tract_backend) (pure
//! Rust, the default) or the onnxruntime backend (cargo feature `ort`). The runtimes build
//! on this module; [`crate::backend`] opens a model in the one a [`BackendKind`] names.

use nldf_model::contract::ModelInfo;

use crate::error::{Error, Result};

/// Which runtime evaluates the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendKind {
    /// tract: pure Rust, always built.
    Tract,
    /// onnxruntime through the `ort` crate, loaded at run time (cargo feature `ort`).
    Ort,
}

impl BackendKind {
    /// The runtime's name as the CLI spells it.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Tract => "tract",
            BackendKind::Ort => "ort",
        }
    }
}

impl std::fmt::Display for BackendKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How a backend runs the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct BackendOptions {
    /// Rays per network call: larger batches use the matrix units better, smaller ones
    /// waste less on a frame's last, partial batch.
    pub batch_size: usize,
    /// Threads for the matrix products (1 = the calling thread only).
    pub threads: usize,
    /// Whether onnxruntime's worker threads keep spinning (busy-waiting) after a call
    /// returns, ready for the next, instead of parking. They always spin within a call
    /// (without it a 2-core EPYC frame of the real-time student takes 20-30 % longer); the
    /// spinning after it helps only calls that follow at once, and takes a core (or its
    /// SMT sibling) from every other thread: a second session, a stream's reader, the PNG
    /// writer. Streams turn it off. tract ignores it.
    pub spin: bool,
}

impl Default for BackendOptions {
    fn default() -> Self {
        BackendOptions {
            batch_size: 4096,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            spin: true,
        }
    }
}

impl BackendOptions {
    /// The largest batch size and thread count accepted.
    pub const LIMITS: BackendOptions = BackendOptions {
        batch_size: 1 << 20,
        threads: 1024,
        spin: true,
    };

    /// Checks the options.
    pub fn validate(&self) -> Result<()> {
        let max = Self::LIMITS;
        if self.batch_size == 0 || self.batch_size > max.batch_size {
            return Err(Error::Argument(format!(
                "batch size must be 1 to {}, got {}",
                max.batch_size, self.batch_size
            )));
        }
        if self.threads == 0 || self.threads > max.threads {
            return Err(Error::Argument(format!(
                "threads must be 1 to {}, got {}",
                max.threads, self.threads
            )));
        }
        Ok(())
    }
}

/// The network's outputs for a set of rays.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RayOutputs {
    /// Pixel colours, `[n_rays, 3]` (paper Eq. 7).
    pub rgb: Vec<f32>,
    /// Segment colours, `[n_rays, M, 3]`, summing to `rgb` less the background's share.
    pub segments: Vec<f32>,
    /// How much of each ray the head covers, `[n_rays]`.
    pub opacity: Vec<f32>,
}

/// The box an upsampled ray graph renders: its coarse cells and its pixels' background.
#[derive(Debug, Clone, Copy)]
pub struct BoxInput<'a> {
    /// `[rows, cols]` of the coarse grid, row-major: true where a ray is given (the rays
    /// are the true cells in this order).
    pub cells: &'a [bool],
    /// The box's coarse rows and columns.
    pub rows: usize,
    pub cols: usize,
    /// `[rows r, cols r, 3]` flat: the background of the box's pixels (`r` the factor).
    pub background: &'a [f32],
    /// The mouth patch's rays, for a graph that has one (`UpsampleInfo::mouth_patch`;
    /// `None` sends none).
    pub patch: Option<PatchRays<'a>>,
}

/// The rays of the output pixels whose rays meet an upsampled ray graph's mouth box, and
/// the background behind them, `[n_patch, 3]` flat each.
#[derive(Debug, Clone, Copy)]
pub struct PatchRays<'a> {
    pub origins: &'a [f32],
    pub directions: &'a [f32],
    pub background: &'a [f32],
}

impl PatchRays<'_> {
    /// The patch that holds no ray.
    pub const NONE: PatchRays<'static> = PatchRays {
        origins: &[],
        directions: &[],
        background: &[],
    };

    /// How many rays it holds.
    pub fn len(&self) -> usize {
        self.origins.len() / 3
    }

    /// Whether it holds no ray.
    pub fn is_empty(&self) -> bool {
        self.origins.is_empty()
    }
}

/// An upsampled ray graph's outputs for one box.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BoxOutputs {
    /// The box's pixels, `[rows r, cols r, 3]`, the background composited in.
    pub rgb: Vec<f32>,
    /// How much of each pixel the head covers, `[rows r, cols r]`.
    pub opacity: Vec<f32>,
    /// The mouth patch's pixels, `[n_patch, 3]`, the background composited in (empty
    /// without a patch).
    pub patch_rgb: Vec<f32>,
}

/// The mouth patch a graph is sent: `patch` for a graph with one (none given: an empty
/// patch), none for a graph without; the rays' and background's lengths checked.
fn check_patch(has_patch: bool, patch: Option<PatchRays<'_>>) -> Result<Option<PatchRays<'_>>> {
    match (has_patch, patch) {
        (false, None) => Ok(None),
        (false, Some(_)) => Err(Error::Argument(
            "this model has no mouth patch: it takes no patch rays".into(),
        )),
        (true, None) => Ok(Some(PatchRays::NONE)),
        (true, Some(p)) => {
            check_rays(p.origins, p.directions)?;
            if p.background.len() != p.origins.len() {
                return Err(Error::Argument(format!(
                    "mouth patch: {} background values for {} rays",
                    p.background.len(),
                    p.len()
                )));
            }
            Ok(Some(p))
        }
    }
}

/// A runtime holding one exported model.
pub trait Backend {
    /// Which runtime this is.
    fn kind(&self) -> BackendKind;

    /// The model's metadata.
    fn info(&self) -> &ModelInfo;

    /// Rays per network call.
    fn batch_size(&self) -> usize;

    /// Runs the network on one batch of 1 to [`Backend::batch_size`] rays with one audio
    /// neighbourhood; [`Backend::run`] has checked the inputs' lengths.
    ///
    /// # Shapes
    /// - `origins`, `directions`: `[n_rays, 3]` flat, `1 <= n_rays <= batch_size`
    /// - `background`: `[n_rays, 3]` flat
    /// - `audio`: `[att_frames, window, n_features]` flat (see `nldf_model::contract`)
    /// - returns `rgb` `[n_rays, 3]`, `segments` `[n_rays, M, 3]` and `opacity` `[n_rays]`
    fn run_batch(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        background: &[f32],
        audio: &[f32],
    ) -> Result<RayOutputs>;

    /// Runs an upsampled ray graph (one whose [`ModelInfo::upsample`] is set) on one box
    /// with one audio neighbourhood; [`Backend::run_box`] has checked the inputs.
    ///
    /// # Shapes
    /// - `origins`, `directions`: `[n_rays, 3]` flat, `n_rays >= 1` the true cells of the
    ///   box, in row-major order
    /// - `audio`: `[att_frames, window, n_features]` flat
    fn run_box_once(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        audio: &[f32],
        boxed: BoxInput<'_>,
    ) -> Result<BoxOutputs>;

    /// [`Backend::run_box_once`] after checking the inputs against the model: an
    /// upsampled model, as many rays as true cells, a background `r` times the box.
    fn run_box(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        audio: &[f32],
        boxed: BoxInput<'_>,
    ) -> Result<BoxOutputs> {
        let info = self.info();
        let Some(up) = info.upsample else {
            return Err(Error::Argument(
                "this model has no learned upsampler: it renders rays (Backend::run), not boxes"
                    .into(),
            ));
        };
        check_rays(origins, directions)?;
        let n_cells = boxed.cells.iter().filter(|&&c| c).count();
        let (r, area) = (up.factor, boxed.rows * boxed.cols);
        if boxed.cells.len() != area || n_cells != origins.len() / 3 || n_cells == 0 {
            return Err(Error::Argument(format!(
                "box: {} cells for {} x {}, {n_cells} of them true, for {} rays (expected \
                 one ray per true cell, at least one)",
                boxed.cells.len(),
                boxed.rows,
                boxed.cols,
                origins.len() / 3
            )));
        }
        if boxed.background.len() != 3 * area * r * r {
            return Err(Error::Argument(format!(
                "box: the background holds {} values, expected {} x {} pixels of 3",
                boxed.background.len(),
                boxed.rows * r,
                boxed.cols * r
            )));
        }
        check_audio(info, audio)?;
        let boxed = BoxInput {
            patch: check_patch(up.mouth_patch.is_some(), boxed.patch)?,
            ..boxed
        };
        let n_patch = boxed.patch.map_or(0, |p| p.len());
        let out = self.run_box_once(origins, directions, audio, boxed)?;
        if out.patch_rgb.len() != 3 * n_patch {
            return Err(Error::backend(
                self.kind().name(),
                format!(
                    "the mouth patch's output holds {} values, expected {}",
                    out.patch_rgb.len(),
                    3 * n_patch
                ),
            ));
        }
        if out.rgb.len() != 3 * area * r * r || out.opacity.len() != area * r * r {
            return Err(Error::backend(
                self.kind().name(),
                format!(
                    "the box's outputs hold {} and {} values, expected {} and {}",
                    out.rgb.len(),
                    out.opacity.len(),
                    3 * area * r * r,
                    area * r * r
                ),
            ));
        }
        Ok(out)
    }

    /// Runs the network on any number of rays, batch by batch.
    ///
    /// # Shapes
    /// - `origins`, `directions`: `[n_rays, 3]` flat
    /// - `background`: `[n_rays, 3]` flat, the background behind each ray
    /// - `audio`: `[att_frames, window, n_features]` flat
    /// - returns `rgb` `[n_rays, 3]`, `segments` `[n_rays, M, 3]` and `opacity` `[n_rays]`
    fn run(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        background: &[f32],
        audio: &[f32],
    ) -> Result<RayOutputs> {
        check_inputs(self.info(), origins, directions, background, audio)?;
        let n = origins.len() / 3;
        let m = self.info().segments;
        let mut out = RayOutputs {
            rgb: Vec::with_capacity(3 * n),
            segments: Vec::with_capacity(3 * m * n),
            opacity: Vec::with_capacity(n),
        };
        let batch = self.batch_size();
        for start in (0..n).step_by(batch) {
            let end = (start + batch).min(n);
            let part = self.run_batch(
                &origins[3 * start..3 * end],
                &directions[3 * start..3 * end],
                &background[3 * start..3 * end],
                audio,
            )?;
            out.rgb.extend_from_slice(&part.rgb);
            out.segments.extend_from_slice(&part.segments);
            out.opacity.extend_from_slice(&part.opacity);
        }
        Ok(out)
    }
}

/// Checks the lengths of a call's inputs against the model.
pub fn check_inputs(
    info: &ModelInfo,
    origins: &[f32],
    directions: &[f32],
    background: &[f32],
    audio: &[f32],
) -> Result<()> {
    refuse_boxed(info)?;
    check_rays(origins, directions)?;
    if background.len() != origins.len() {
        return Err(Error::Argument(format!(
            "rays: the model composites over the background, which holds {} values for {} \
             rays (expected 3 per ray)",
            background.len(),
            origins.len() / 3
        )));
    }
    check_audio(info, audio)
}

/// Origins and directions of the same rays, 3 values each.
fn check_rays(origins: &[f32], directions: &[f32]) -> Result<()> {
    if !origins.len().is_multiple_of(3) || origins.len() != directions.len() {
        return Err(Error::Argument(format!(
            "rays: origins hold {} values and directions {}, expected equal multiples of 3",
            origins.len(),
            directions.len()
        )));
    }
    Ok(())
}

/// An audio neighbourhood of the model's shape.
fn check_audio(info: &ModelInfo, audio: &[f32]) -> Result<()> {
    if audio.len() != info.audio.len() {
        return Err(Error::Argument(format!(
            "audio: expected {:?} = {} values, got {}",
            info.audio.shape(),
            info.audio.len(),
            audio.len()
        )));
    }
    Ok(())
}

/// Refuses single rays for an upsampled ray graph, which renders boxes.
pub fn refuse_boxed(info: &ModelInfo) -> Result<()> {
    match info.upsample {
        Some(up) => Err(Error::Argument(format!(
            "this model has a learned upsampler (x{}): it renders boxes of its coarse grid \
             (nldf render, FrameRenderer::render), not single rays; export the student \
             without --upsampler for a ray graph",
            up.factor
        ))),
        None => Ok(()),
    }
}
