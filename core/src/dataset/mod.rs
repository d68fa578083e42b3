//! Datasets in AD-NeRF's layout: `transforms_{train,val}.json` with
//! AD-NeRF's field names, frames under `head_imgs/` (or `ori_imgs/`, `gt_imgs/`), the static
//! background `bc.png|jpg`, audio windows `aud.npy` `[N, 16, F]`, optional `parsing/`
//! masks in AD-NeRF's convention, nldf's own `regions/` labels and AD-NeRF's `<id>.lms`
//! landmarks (see [`crate::region`]). Loading validates everything it can without decoding
//! every frame, and every problem is one line naming the file.

mod audio;
mod layout;
mod load;
mod regions;
mod transforms;
mod validate;

pub use crate::npy::{load_audio_npy, parse_audio_npy, save_audio_npy};
pub use audio::{
    AUDIO_NPY, AUDIO_SOURCE_FILE, AUDIO_WAV, AudioChoice, load_audio, read_audio_source,
    save_audio_features,
};
pub use layout::{
    IMAGE_DIRS, IMAGE_EXTS, LABELS_DIR, LANDMARKS_DIR, PARSING_DIR, SCENE_FILE, Split, VOICE_DIR,
};
pub use load::{Dataset, ad_nerf_bounds};
pub use regions::save_regions_png;
pub use transforms::{FrameEntry, TransformsFile};
pub use validate::{Frame, RIGID_TOL};
