//! The tract backend: pure Rust, always built. The graph is compiled for concrete ray
//! counts (tract optimises a fixed shape much better than the symbolic `n_rays` axis): one
//! plan for full batches and, made on demand, plans for partial batches rounded up to
//! [`PLAN_GRANULE`] rays, so that a frame's last batch wastes little on padding. Matrix
//! products run on a private thread pool of `threads` threads. Inputs and outputs are bound
//! by their contract names, as onnxruntime binds them, not by their position in the graph.

use std::collections::HashMap;
use std::sync::Arc;

use nldf_model::ExportedModel;
use nldf_model::contract::{
    BOX_COLS, BOX_ROWS, ModelInfo, PATCH_AXIS, RAY_AXIS, model_input_names, model_output_names,
};
use tract_onnx::prelude::*;

use crate::error::{Error, Result};
use crate::runtime::{
    Backend, BackendKind, BackendOptions, BoxInput, BoxOutputs, RayOutputs, refuse_boxed,
};

/// Partial batches are padded up to a multiple of this many rays.
pub const PLAN_GRANULE: usize = 512;

const NAME: &str = "tract";

/// tract holding one model.
pub struct TractBackend {
    info: ModelInfo,
    /// The parsed graph, before shapes are fixed.
    model: InferenceModel,
    /// Optimised plans by ray count.
    plans: HashMap<usize, Arc<TypedRunnableModel>>,
    /// An upsampled ray graph's one plan, its ray count and box sides symbolic (boxes
    /// change size from frame to frame).
    boxed: Option<Arc<TypedRunnableModel>>,
    batch_size: usize,
    executor: tract_linalg::multithread::Executor,
}

impl std::fmt::Debug for TractBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TractBackend")
            .field("batch_size", &self.batch_size)
            .field("plans", &self.plans.keys().collect::<Vec<_>>())
            .finish()
    }
}

impl TractBackend {
    /// Parses `model` and compiles the plan for full batches.
    pub fn new(model: &ExportedModel, options: BackendOptions) -> Result<TractBackend> {
        options.validate()?;
        let mut parsed = tract_onnx::onnx()
            .model_for_read(&mut &model.bytes[..])
            .map_err(|e| Error::backend(NAME, format!("{}: {e}", model.path.display())))?;
        // tract numbers inputs and outputs by position; onnxruntime binds them by name. Bind
        // by name here too, so that a graph listing them in another order renders the same.
        parsed
            .set_input_names(model_input_names(&model.info))
            .and_then(|()| parsed.select_outputs_by_name(model_output_names(&model.info)))
            .map_err(|e| {
                Error::backend(
                    NAME,
                    format!(
                        "{}: binding the contract's inputs and outputs by name: {e}",
                        model.path.display()
                    ),
                )
            })?;
        let executor = if options.threads > 1 {
            tract_linalg::multithread::Executor::multithread_with_name(
                options.threads,
                "nldf-tract",
            )
        } else {
            tract_linalg::multithread::Executor::SingleThread
        };
        let boxed = match model.info.upsample {
            Some(up) => Some(boxed_plan(&parsed, &model.info, up.factor).map_err(|e| {
                Error::backend(NAME, format!("{}: compiling: {e}", model.path.display()))
            })?),
            None => None,
        };
        let mut backend = TractBackend {
            info: model.info.clone(),
            model: parsed,
            plans: HashMap::new(),
            boxed,
            batch_size: options.batch_size,
            executor,
        };
        if backend.boxed.is_none() {
            backend.plan(options.batch_size)?;
        }
        Ok(backend)
    }

    /// The plan for exactly `n_rays` rays, compiled on first use.
    fn plan(&mut self, n_rays: usize) -> Result<Arc<TypedRunnableModel>> {
        if let Some(plan) = self.plans.get(&n_rays) {
            return Ok(plan.clone());
        }
        let audio = self.info.audio.shape();
        let compile = || -> TractResult<Arc<TypedRunnableModel>> {
            self.model
                .clone()
                .with_input_fact(0, f32::fact([n_rays, 3]).into())?
                .with_input_fact(1, f32::fact([n_rays, 3]).into())?
                .with_input_fact(2, f32::fact(audio).into())?
                .with_input_fact(3, f32::fact([n_rays, 3]).into())?
                .into_optimized()?
                .into_runnable()
        };
        let plan = compile().map_err(|e| Error::backend(NAME, format!("compiling: {e}")))?;
        self.plans.insert(n_rays, plan.clone());
        Ok(plan)
    }

    /// The padded ray count a batch of `n_rays` runs at.
    fn padded(&self, n_rays: usize) -> usize {
        n_rays
            .div_ceil(PLAN_GRANULE)
            .saturating_mul(PLAN_GRANULE)
            .min(self.batch_size)
            .max(n_rays)
    }
}

/// The plan of an upsampled ray graph: `n_rays` rays, a `box_rows x box_cols` box and
/// its `factor` times larger background, all symbolic.
fn boxed_plan(
    parsed: &InferenceModel,
    info: &ModelInfo,
    factor: usize,
) -> TractResult<Arc<TypedRunnableModel>> {
    let n: TDim = parsed.symbols.sym(RAY_AXIS).into();
    let rows: TDim = parsed.symbols.sym(BOX_ROWS).into();
    let cols: TDim = parsed.symbols.sym(BOX_COLS).into();
    let r = TDim::from(factor as i64);
    let three = TDim::from(3i64);
    let mut model = parsed
        .clone()
        .with_input_fact(0, f32::fact([n.clone(), three.clone()]).into())?
        .with_input_fact(1, f32::fact([n, three.clone()]).into())?
        .with_input_fact(2, f32::fact(info.audio.shape()).into())?
        .with_input_fact(3, bool::fact([rows.clone(), cols.clone()]).into())?
        .with_input_fact(
            4,
            f32::fact([rows * r.clone(), cols * r, three.clone()]).into(),
        )?;
    if info.upsample.is_some_and(|u| u.mouth_patch.is_some()) {
        let p: TDim = parsed.symbols.sym(PATCH_AXIS).into();
        for input in 5..8 {
            model = model.with_input_fact(input, f32::fact([p.clone(), three.clone()]).into())?;
        }
    }
    model.into_optimized()?.into_runnable()
}

impl Backend for TractBackend {
    fn kind(&self) -> BackendKind {
        BackendKind::Tract
    }

    fn info(&self) -> &ModelInfo {
        &self.info
    }

    fn batch_size(&self) -> usize {
        self.batch_size
    }

    fn run_batch(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        background: &[f32],
        audio: &[f32],
    ) -> Result<RayOutputs> {
        refuse_boxed(&self.info)?;
        let n = origins.len() / 3;
        let padded = self.padded(n);
        let plan = self.plan(padded)?;
        let pad = |v: &[f32]| -> Vec<f32> {
            let mut out = Vec::with_capacity(3 * padded);
            out.extend_from_slice(v);
            out.resize(3 * padded, 0.0);
            out
        };
        let tensor = |shape: &[usize], data: &[f32]| {
            Tensor::from_shape(shape, data).map_err(|e| Error::backend(NAME, e))
        };
        let inputs: TVec<TValue> = tvec!(
            tensor(&[padded, 3], &pad(origins))?.into(),
            tensor(&[padded, 3], &pad(directions))?.into(),
            tensor(&self.info.audio.shape(), audio)?.into(),
            tensor(&[padded, 3], &pad(background))?.into(),
        );
        let outputs =
            tract_linalg::multithread::multithread_tract_scope(self.executor.clone(), || {
                plan.run(inputs)
            })
            .map_err(|e| Error::backend(NAME, format!("running: {e}")))?;
        let m = self.info.segments;
        let take = |value: &TValue, per_ray: usize| -> Result<Vec<f32>> {
            let view = value
                .to_plain_array_view::<f32>()
                .map_err(|e| Error::backend(NAME, e))?;
            if view.len() != per_ray * padded {
                return Err(Error::backend(
                    NAME,
                    format!(
                        "an output holds {} values, expected {}",
                        view.len(),
                        per_ray * padded
                    ),
                ));
            }
            Ok(view.iter().take(per_ray * n).copied().collect())
        };
        let expected = model_output_names(&self.info).len();
        if outputs.len() != expected {
            return Err(Error::backend(
                NAME,
                format!(
                    "the graph gave {} outputs, expected {expected}",
                    outputs.len()
                ),
            ));
        }
        Ok(RayOutputs {
            rgb: take(&outputs[0], 3)?,
            segments: take(&outputs[1], 3 * m)?,
            opacity: take(&outputs[2], 1)?,
        })
    }

    fn run_box_once(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        audio: &[f32],
        boxed: BoxInput<'_>,
    ) -> Result<BoxOutputs> {
        let Some(plan) = self.boxed.clone() else {
            return Err(Error::Argument(
                "this model has no learned upsampler: it renders rays, not boxes".into(),
            ));
        };
        let r = self.info.upsample.map_or(1, |u| u.factor);
        let fail = |e: TractError| Error::backend(NAME, e);
        let n = origins.len() / 3;
        let mut inputs: TVec<TValue> = tvec!(
            Tensor::from_shape(&[n, 3], origins).map_err(fail)?.into(),
            Tensor::from_shape(&[n, 3], directions)
                .map_err(fail)?
                .into(),
            Tensor::from_shape(&self.info.audio.shape(), audio)
                .map_err(fail)?
                .into(),
            Tensor::from_shape(&[boxed.rows, boxed.cols], boxed.cells)
                .map_err(fail)?
                .into(),
            Tensor::from_shape(&[boxed.rows * r, boxed.cols * r, 3], boxed.background)
                .map_err(fail)?
                .into(),
        );
        if let Some(p) = boxed.patch {
            for values in [p.origins, p.directions, p.background] {
                inputs.push(
                    Tensor::from_shape(&[p.len(), 3], values)
                        .map_err(fail)?
                        .into(),
                );
            }
        }
        let outputs =
            tract_linalg::multithread::multithread_tract_scope(self.executor.clone(), || {
                plan.run(inputs)
            })
            .map_err(|e| Error::backend(NAME, format!("running: {e}")))?;
        let take = |i: usize| -> Result<Vec<f32>> {
            let value = outputs
                .get(i)
                .ok_or_else(|| Error::backend(NAME, format!("the graph gave no output {i}")))?;
            let view = value.to_plain_array_view::<f32>().map_err(fail)?;
            Ok(view.iter().copied().collect())
        };
        Ok(BoxOutputs {
            rgb: take(0)?,
            opacity: take(2)?,
            patch_rgb: match boxed.patch {
                Some(_) => take(3)?,
                None => Vec::new(),
            },
        })
    }
}
