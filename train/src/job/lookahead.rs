//! The short-lookahead job (`nldf train lookahead`): a trained student's audio encoder
//! distilled again to read less future audio ([`crate::trainers::lookahead`]), into a new
//! student folder of the run, with the code error on the held-out frames and, on a
//! synthetic scene, the held-out voice.

use std::path::PathBuf;

use nldf_core::dataset::{AudioChoice, Split};
use nldf_core::run_files::CONFIG_FILE;

use crate::error::{Error, Result};
use crate::trainers::config::{StudentRunConfig, read_config};
use crate::trainers::data::TrainData;
use crate::trainers::lookahead::{
    HeldOutWindows, LookaheadConfig, LookaheadReport, train_lookahead,
};

/// What `nldf train lookahead` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct LookaheadJob {
    /// The dataset the student was trained on.
    pub data: PathBuf,
    /// The run folder holding the student.
    pub run: PathBuf,
    /// The student's folder inside the run.
    pub student: String,
    /// The new student's folder inside the run (absent or empty).
    pub name: String,
    pub config: LookaheadConfig,
}

impl LookaheadJob {
    /// Loads the data with the student's features, distils the encoder into
    /// `RUN/<name>` and reports; a failure leaves no folder behind.
    pub fn run(&self, on_step: &mut dyn FnMut(usize, f64)) -> Result<LookaheadReport> {
        let source = self.run.join(&self.student);
        let dir = self.run.join(&self.name);
        if dir == source {
            return Err(Error::Config(format!(
                "the short-lookahead student needs its own folder, not {}",
                source.display()
            )));
        }
        if std::fs::read_dir(&dir).is_ok_and(|mut d| d.next().is_some()) {
            return Err(Error::Config(format!(
                "{} already holds files: remove it or pick another name",
                dir.display()
            )));
        }
        let cfg: StudentRunConfig = read_config(&source.join(CONFIG_FILE))
            .map_err(|e| e.context(format!("reading the student in {}", source.display())))?;
        let audio = AudioChoice::Matching(cfg.model.audio.features.clone());
        let data = TrainData::open_with(&self.data, false, &audio)?;
        let att = cfg.model.audio.att_frames;
        let ids = |d: &TrainData, split: Split| -> Vec<usize> {
            d.dataset.frames(split).iter().map(|f| f.aud_id).collect()
        };
        let mut held_out: Vec<HeldOutWindows> = Vec::new();
        let val = ids(&data, Split::Val);
        if !val.is_empty() {
            held_out.push(("val".into(), data.neighbourhoods(&val, att)?));
        }
        if self.data.join(Split::Voice.file_name()).is_file() {
            let voice = TrainData::open_held_out(&self.data, false, &audio, Split::Voice)?;
            let v = ids(&voice, Split::Voice);
            held_out.push(("voice".into(), voice.neighbourhoods(&v, att)?));
        }
        let existed = dir.exists();
        let result = train_lookahead(&source, &dir, &self.config, &data, &held_out, on_step);
        if result.is_err() && !existed {
            let _ = std::fs::remove_dir_all(&dir);
        }
        result
    }
}
