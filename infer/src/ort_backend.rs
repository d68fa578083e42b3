//! The onnxruntime backend (cargo feature `ort`): the `ort` crate with `load-dynamic`, so
//! that nothing is downloaded at build time and the library is found at run time (see
//! [`crate::ort_library`]). onnxruntime handles the symbolic ray axis well, so batches run
//! at their own size without padding.

use std::sync::OnceLock;

use nldf_model::ExportedModel;
use nldf_model::contract::{
    INPUT_AUDIO, INPUT_BACKGROUND, INPUT_CELLS, INPUT_DIRECTIONS, INPUT_ORIGINS,
    INPUT_PATCH_BACKGROUND, INPUT_PATCH_DIRECTIONS, INPUT_PATCH_ORIGINS, ModelInfo,
    OUTPUT_BOX_OPACITY, OUTPUT_BOX_RGB, OUTPUT_OPACITY, OUTPUT_PATCH_RGB, OUTPUT_RGB,
    OUTPUT_SEGMENTS,
};
use ort::environment::Environment;
use ort::session::{Session, SessionOutputs};
use ort::value::TensorRef;

use crate::error::{Error, Result};
use crate::ort_library::find_ort_library;
use crate::runtime::{
    Backend, BackendKind, BackendOptions, BoxInput, BoxOutputs, RayOutputs, refuse_boxed,
};

const NAME: &str = "ort";

/// onnxruntime allows one environment per process: made once, kept for the process's life.
static ENVIRONMENT: OnceLock<std::result::Result<Environment, String>> = OnceLock::new();

/// The process's onnxruntime environment, loading the library on first use.
pub fn environment() -> Result<&'static Environment> {
    let made = ENVIRONMENT.get_or_init(|| {
        let path = find_ort_library().map_err(|e| e.to_string())?;
        let builder = ort::init_from(&path).map_err(|e| {
            format!(
                "onnxruntime: cannot load {}: {e}; {}",
                path.display(),
                crate::ort_library::HOW_TO_GET
            )
        })?;
        builder
            .with_name("nldf")
            .build()
            .map_err(|e| format!("onnxruntime: {e}"))
    });
    match made {
        Ok(env) => Ok(env),
        Err(message) => Err(Error::OrtLibrary(
            message
                .strip_prefix("onnxruntime: ")
                .unwrap_or(message)
                .to_string(),
        )),
    }
}

/// onnxruntime holding one model.
pub struct OrtBackend {
    info: ModelInfo,
    session: Session,
    batch_size: usize,
}

impl std::fmt::Debug for OrtBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OrtBackend")
            .field("batch_size", &self.batch_size)
            .finish()
    }
}

impl OrtBackend {
    /// Loads the library (once per process) and makes a session for `model`.
    pub fn new(model: &ExportedModel, options: BackendOptions) -> Result<OrtBackend> {
        options.validate()?;
        let env = environment()?;
        let fail = |e: String| Error::backend(NAME, format!("{}: {e}", model.path.display()));
        let session = Session::builder(env)
            .map_err(|e| fail(e.to_string()))?
            .with_intra_threads(options.threads)
            .map_err(|e| fail(e.to_string()))?
            .with_inter_threads(1)
            .map_err(|e| fail(e.to_string()))?
            // Spinning inside a call (between its operators) always; between calls only when
            // asked: `session.force_spinning_stop` parks the pool as each call ends.
            .with_config_entry(
                "session.force_spinning_stop",
                if options.spin { "0" } else { "1" },
            )
            .map_err(|e| fail(e.to_string()))?
            .commit_from_memory(&model.bytes)
            .map_err(|e| fail(e.to_string()))?;
        Ok(OrtBackend {
            info: model.info.clone(),
            session,
            batch_size: options.batch_size,
        })
    }
}

impl OrtBackend {
    /// Runs the session on one batch and hands its outputs to `take`.
    fn run_session<R>(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        background: &[f32],
        audio: &[f32],
        take: impl FnOnce(&SessionOutputs<'_>) -> Result<R>,
    ) -> Result<R> {
        let n = origins.len() / 3;
        let fail = |e: ort::Error| Error::backend(NAME, e);
        let inputs = ort::inputs![
            INPUT_ORIGINS => TensorRef::from_array_view(([n, 3], origins)).map_err(fail)?,
            INPUT_DIRECTIONS => TensorRef::from_array_view(([n, 3], directions)).map_err(fail)?,
            INPUT_AUDIO => TensorRef::from_array_view((self.info.audio.shape(), audio))
                .map_err(fail)?,
            INPUT_BACKGROUND => TensorRef::from_array_view(([n, 3], background)).map_err(fail)?,
        ];
        let outputs = self.session.run(inputs).map_err(fail)?;
        take(&outputs)
    }

    /// Runs the session on `origins`/`directions` in batches of [`Backend::batch_size`]
    /// rays, as [`Backend::run`] does, but keeps no output: the bare runtime's cost on
    /// ready-made inputs, which `bench` compares whole frames against.
    pub fn run_bare(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        background: &[f32],
        audio: &[f32],
    ) -> Result<()> {
        crate::runtime::check_inputs(&self.info, origins, directions, background, audio)?;
        let n = origins.len() / 3;
        for start in (0..n).step_by(self.batch_size) {
            let end = (start + self.batch_size).min(n);
            let rows = 3 * start..3 * end;
            let (o, d, b) = (
                &origins[rows.clone()],
                &directions[rows.clone()],
                &background[rows],
            );
            self.run_session(o, d, b, audio, |_| Ok(()))?;
        }
        Ok(())
    }
}

impl Backend for OrtBackend {
    fn kind(&self) -> BackendKind {
        BackendKind::Ort
    }

    fn info(&self) -> &ModelInfo {
        &self.info
    }

    fn batch_size(&self) -> usize {
        self.batch_size
    }

    fn run_batch(
        &mut self,
        rays_o: &[f32],
        rays_d: &[f32],
        background: &[f32],
        audio: &[f32],
    ) -> Result<RayOutputs> {
        refuse_boxed(&self.info)?;
        let n = rays_o.len() / 3;
        let m = self.info.segments;
        self.run_session(rays_o, rays_d, background, audio, |outputs| {
            let take = |name: &str, per_ray: usize| -> Result<Vec<f32>> {
                let value = outputs
                    .get(name)
                    .ok_or_else(|| Error::backend(NAME, format!("no output `{name}`")))?;
                let (_, data) = value
                    .try_extract_tensor::<f32>()
                    .map_err(|e| Error::backend(NAME, e))?;
                if data.len() != per_ray * n {
                    return Err(Error::backend(
                        NAME,
                        format!(
                            "output `{name}` holds {} values, expected {}",
                            data.len(),
                            per_ray * n
                        ),
                    ));
                }
                Ok(data.to_vec())
            };
            Ok(RayOutputs {
                rgb: take(OUTPUT_RGB, 3)?,
                segments: take(OUTPUT_SEGMENTS, 3 * m)?,
                opacity: take(OUTPUT_OPACITY, 1)?,
            })
        })
    }

    fn run_box_once(
        &mut self,
        origins: &[f32],
        directions: &[f32],
        audio: &[f32],
        boxed: BoxInput<'_>,
    ) -> Result<BoxOutputs> {
        let r = self.info.upsample.map_or(1, |u| u.factor);
        let n = origins.len() / 3;
        let fail = |e: ort::Error| Error::backend(NAME, e);
        let pixels = [boxed.rows * r, boxed.cols * r, 3];
        let mut inputs = ort::inputs![
            INPUT_ORIGINS => TensorRef::from_array_view(([n, 3], origins)).map_err(fail)?,
            INPUT_DIRECTIONS => TensorRef::from_array_view(([n, 3], directions)).map_err(fail)?,
            INPUT_AUDIO => TensorRef::from_array_view((self.info.audio.shape(), audio))
                .map_err(fail)?,
            INPUT_CELLS => TensorRef::from_array_view(([boxed.rows, boxed.cols], boxed.cells))
                .map_err(fail)?,
            INPUT_BACKGROUND => TensorRef::from_array_view((pixels, boxed.background))
                .map_err(fail)?,
        ];
        if let Some(p) = boxed.patch {
            let rows = [p.len(), 3];
            inputs.extend(ort::inputs![
                INPUT_PATCH_ORIGINS => TensorRef::from_array_view((rows, p.origins))
                    .map_err(fail)?,
                INPUT_PATCH_DIRECTIONS => TensorRef::from_array_view((rows, p.directions))
                    .map_err(fail)?,
                INPUT_PATCH_BACKGROUND => TensorRef::from_array_view((rows, p.background))
                    .map_err(fail)?,
            ]);
        }
        let outputs = self.session.run(inputs).map_err(fail)?;
        let take = |name: &str| -> Result<Vec<f32>> {
            let value = outputs
                .get(name)
                .ok_or_else(|| Error::backend(NAME, format!("no output `{name}`")))?;
            let (_, data) = value.try_extract_tensor::<f32>().map_err(fail)?;
            Ok(data.to_vec())
        };
        Ok(BoxOutputs {
            rgb: take(OUTPUT_BOX_RGB)?,
            opacity: take(OUTPUT_BOX_OPACITY)?,
            patch_rgb: match boxed.patch {
                Some(_) => take(OUTPUT_PATCH_RGB)?,
                None => Vec::new(),
            },
        })
    }
}
