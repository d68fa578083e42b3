//! Runs a frame graph (`nldf export --frame`) in tract or onnxruntime: a frame's audio
//! chunk and a pose in, the frame out, with nothing computed outside the graph. Every pixel
//! is rendered ([`FrameGraph::render`]) unless the caller names the ones to keep
//! ([`FrameGraph::render_kept`]). nldf's own renderer runs the ray graph
//! ([`crate::FrameRenderer`]); this runner is how the tests and benchmarks hold the frame
//! graph against it, as any other runtime would load it.

use glam::Mat4;
use nldf_core::image::ImageRgb;
use nldf_model::FrameGraphFile;
use nldf_model::contract::{
    FRAME_INPUT_AUDIO, FRAME_INPUT_KEEP, FRAME_INPUT_POSE, FRAME_OUTPUT_IMAGE, FRAME_OUTPUT_RAYS,
    FRAME_OUTPUT_WINDOWS,
};
use tract_onnx::prelude::*;

use crate::error::{Error, Result};
use crate::runtime::BackendKind;

/// What a frame graph computes for one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphFrame {
    /// The frame, `[height, width, 3]`.
    pub image: ImageRgb,
    /// The audio windows its front end made, `[att_frames, window, n_features]` flat.
    pub windows: Vec<f32>,
    /// Rays that went through the student: those that meet the head, of the kept pixels.
    pub n_rays: usize,
}

enum Session {
    Tract(std::sync::Arc<TypedRunnableModel>),
    #[cfg(feature = "ort")]
    Ort(ort::session::Session),
}

/// A frame graph opened in one runtime.
pub struct FrameGraph {
    model: FrameGraphFile,
    session: Session,
    /// Every pixel kept, `[height * width]`.
    all: Vec<bool>,
}

impl std::fmt::Debug for FrameGraph {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameGraph")
            .field("path", &self.model.path)
            .finish()
    }
}

impl FrameGraph {
    /// Opens `model` in the runtime `kind` with `threads` threads.
    pub fn open(model: &FrameGraphFile, kind: BackendKind, threads: usize) -> Result<FrameGraph> {
        let session = match kind {
            BackendKind::Tract => Session::Tract(open_tract(model)?),
            BackendKind::Ort => open_ort(model, threads)?,
        };
        Ok(FrameGraph {
            model: model.clone(),
            session,
            all: vec![true; model.keep_shape()[0] * model.keep_shape()[1]],
        })
    }

    /// The model.
    pub fn model(&self) -> &FrameGraphFile {
        &self.model
    }

    /// The frame seen from camera-to-world `c2w` with the audio `chunk`
    /// (`FrameAudio::chunk`), every pixel rendered.
    ///
    /// # Shapes
    /// - `chunk`: `[samples]` of the model's `FrameAudio`
    pub fn render(&mut self, c2w: Mat4, chunk: &[f32]) -> Result<GraphFrame> {
        let all = std::mem::take(&mut self.all);
        let frame = self.render_kept(c2w, chunk, &all);
        self.all = all;
        frame
    }

    /// [`FrameGraph::render`] with only the pixels `keep` marks rendered: a pixel not kept
    /// shows the background, as one whose ray misses the head does.
    ///
    /// # Shapes
    /// - `chunk`: `[samples]` of the model's `FrameAudio`
    /// - `keep`: `[height * width]`, row-major
    pub fn render_kept(&mut self, c2w: Mat4, chunk: &[f32], keep: &[bool]) -> Result<GraphFrame> {
        if chunk.len() != self.model.audio.samples {
            return Err(Error::Argument(format!(
                "a frame's audio holds {} samples, the frame graph takes {}",
                chunk.len(),
                self.model.audio.samples
            )));
        }
        let k = self.model.info.spec.intrinsics;
        let shape = self.model.keep_shape();
        if keep.len() != shape[0] * shape[1] {
            return Err(Error::Argument(format!(
                "the pixels to keep are {}, the frame graph takes {} x {}",
                keep.len(),
                shape[1],
                shape[0]
            )));
        }
        // Row-major, as the graph reads it.
        let pose: Vec<f32> = c2w.transpose().to_cols_array().to_vec();
        let (image, windows, n_rays) = match &mut self.session {
            Session::Tract(plan) => run_tract(plan, chunk, &pose, (shape, keep))?,
            #[cfg(feature = "ort")]
            Session::Ort(session) => run_ort(session, chunk, &pose, (shape, keep))?,
        };
        let n_windows = self.model.info.audio.len();
        if image.len() != k.n_pixels() * 3 || windows.len() != n_windows {
            return Err(Error::backend(
                "frame graph",
                format!(
                    "outputs hold {} and {} values, expected {} and {n_windows}",
                    image.len(),
                    windows.len(),
                    k.n_pixels() * 3
                ),
            ));
        }
        Ok(GraphFrame {
            image: ImageRgb {
                width: k.width,
                height: k.height,
                data: image,
            },
            windows,
            n_rays,
        })
    }
}

fn open_tract(model: &FrameGraphFile) -> Result<std::sync::Arc<TypedRunnableModel>> {
    let fail = |e: TractError| Error::backend("tract", format!("{}: {e}", model.path.display()));
    let mut parsed = tract_onnx::onnx()
        .model_for_read(&mut &model.bytes[..])
        .map_err(fail)?;
    parsed
        .set_input_names([FRAME_INPUT_AUDIO, FRAME_INPUT_POSE, FRAME_INPUT_KEEP])
        .and_then(|()| {
            parsed.select_outputs_by_name([
                FRAME_OUTPUT_IMAGE,
                FRAME_OUTPUT_WINDOWS,
                FRAME_OUTPUT_RAYS,
            ])
        })
        .map_err(fail)?;
    let plan = parsed
        .with_input_fact(0, f32::fact([model.audio.samples]).into())
        .and_then(|m| m.with_input_fact(1, f32::fact([4, 4]).into()))
        .and_then(|m| m.with_input_fact(2, bool::fact(model.keep_shape()).into()))
        .and_then(|m| m.into_optimized())
        .and_then(|m| m.into_runnable())
        .map_err(fail)?;
    Ok(plan)
}

/// The image, the windows and the ray count.
type Outputs = (Vec<f32>, Vec<f32>, usize);

/// The `keep` input: its `[height, width]` and values.
type Keep<'a> = ([usize; 2], &'a [bool]);

fn run_tract(
    plan: &std::sync::Arc<TypedRunnableModel>,
    chunk: &[f32],
    pose: &[f32],
    (shape, keep): Keep,
) -> Result<Outputs> {
    let fail = |e: TractError| Error::backend("tract", e.to_string());
    let audio = Tensor::from_shape(&[chunk.len()], chunk).map_err(fail)?;
    let pose = Tensor::from_shape(&[4, 4], pose).map_err(fail)?;
    let keep = Tensor::from_shape(&shape, keep).map_err(fail)?;
    let out = plan
        .run(tvec!(audio.into(), pose.into(), keep.into()))
        .map_err(fail)?;
    let take = |i: usize| -> Result<Vec<f32>> {
        let view = out[i].to_plain_array_view::<f32>().map_err(fail)?;
        Ok(view.iter().copied().collect())
    };
    // tract may hand the count back as a (concrete) dimension.
    let n_rays = out[2].cast_to::<i64>().map_err(fail)?;
    let n_rays = n_rays.to_plain_array_view::<i64>().map_err(fail)?;
    Ok((take(0)?, take(1)?, ray_count(n_rays.iter().copied())?))
}

/// The `n_rays` output's one value.
fn ray_count(mut values: impl Iterator<Item = i64>) -> Result<usize> {
    match (values.next(), values.next()) {
        (Some(n), None) if n >= 0 => Ok(n as usize),
        _ => Err(Error::backend(
            "frame graph",
            format!("`{FRAME_OUTPUT_RAYS}` is not one count"),
        )),
    }
}

#[cfg(feature = "ort")]
fn open_ort(model: &FrameGraphFile, threads: usize) -> Result<Session> {
    let env = crate::ort_backend::environment()?;
    let fail = |e: String| Error::backend("ort", format!("{}: {e}", model.path.display()));
    let session = ort::session::Session::builder(env)
        .map_err(|e| fail(e.to_string()))?
        .with_intra_threads(threads.max(1))
        .map_err(|e| fail(e.to_string()))?
        .commit_from_memory(&model.bytes)
        .map_err(|e| fail(e.to_string()))?;
    Ok(Session::Ort(session))
}

#[cfg(not(feature = "ort"))]
fn open_ort(_model: &FrameGraphFile, _threads: usize) -> Result<Session> {
    Err(Error::OrtLibrary(
        "this build has no onnxruntime backend: rebuild with the cargo feature `ort`".into(),
    ))
}

#[cfg(feature = "ort")]
fn run_ort(
    session: &mut ort::session::Session,
    chunk: &[f32],
    pose: &[f32],
    (shape, keep): Keep,
) -> Result<Outputs> {
    use ort::value::TensorRef;
    let fail = |e: ort::Error| Error::backend("ort", e);
    let inputs = ort::inputs![
        FRAME_INPUT_AUDIO => TensorRef::from_array_view(([chunk.len()], chunk)).map_err(fail)?,
        FRAME_INPUT_POSE => TensorRef::from_array_view(([4usize, 4], pose)).map_err(fail)?,
        FRAME_INPUT_KEEP => TensorRef::from_array_view((shape, keep)).map_err(fail)?,
    ];
    let outputs = session.run(inputs).map_err(fail)?;
    let output = |name: &str| {
        outputs
            .get(name)
            .ok_or_else(|| Error::backend("ort", format!("no output `{name}`")))
    };
    let take = |name: &str| -> Result<Vec<f32>> {
        let (_, data) = output(name)?.try_extract_tensor::<f32>().map_err(fail)?;
        Ok(data.to_vec())
    };
    let (_, n_rays) = output(FRAME_OUTPUT_RAYS)?
        .try_extract_tensor::<i64>()
        .map_err(fail)?;
    Ok((
        take(FRAME_OUTPUT_IMAGE)?,
        take(FRAME_OUTPUT_WINDOWS)?,
        ray_count(n_rays.iter().copied())?,
    ))
}
