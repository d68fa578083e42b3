//! `log.csv`: one row per logged step (loss, PSNR, learning rate, throughput) with the
//! validation scores on the steps that have them. A resumed run keeps the rows up to its
//! checkpoint and drops the ones after it, so the file always describes one history.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::trainers::scores::Scores;

/// The header of `log.csv`.
pub const HEADER: &str =
    "step,elapsed_s,loss,psnr,lr,rays_per_s,val_psnr,val_ssim,val_face_psnr,val_mouth_psnr";

/// An open `log.csv`.
pub struct CsvLog {
    path: PathBuf,
    file: std::fs::File,
}

impl CsvLog {
    /// Opens `path` for a run at `step`: rows after `step` are dropped, a new file gets the
    /// header.
    pub fn open(path: &Path, step: usize) -> Result<CsvLog> {
        let mut kept = vec![HEADER.to_string()];
        if let Ok(text) = std::fs::read_to_string(path) {
            for line in text.lines().skip(1) {
                let row_step = line.split(',').next().and_then(|s| s.parse::<usize>().ok());
                if matches!(row_step, Some(s) if s <= step) {
                    kept.push(line.to_string());
                }
            }
        }
        let mut body = kept.join("\n");
        body.push('\n');
        nldf_core::files::write_atomic(path, body.as_bytes())?;
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(|e| Error::io(path, e))?;
        Ok(CsvLog {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Appends one row and flushes it.
    #[allow(clippy::too_many_arguments)]
    pub fn row(
        &mut self,
        step: usize,
        elapsed: f64,
        loss: f64,
        psnr: f64,
        lr: f64,
        rays_per_s: f64,
        scores: Option<Scores>,
    ) -> Result<()> {
        let opt = |v: Option<f64>| v.map(|m| format!("{m:.4}")).unwrap_or_default();
        let (vp, vs, vf, vm) = match scores {
            Some(s) => (
                format!("{:.4}", s.psnr),
                format!("{:.5}", s.ssim),
                opt(s.head_psnr),
                opt(s.mouth_psnr),
            ),
            None => Default::default(),
        };
        writeln!(
            self.file,
            "{step},{elapsed:.3},{loss:.6e},{psnr:.4},{lr:.4e},{rays_per_s:.1},{vp},{vs},{vf},{vm}"
        )
        .and_then(|_| self.file.flush())
        .map_err(|e| Error::io(&self.path, e))
    }
}

/// One parsed row of `log.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct LogRow {
    pub step: usize,
    pub elapsed_s: f64,
    pub loss: f64,
    pub psnr: f64,
    pub val_psnr: Option<f64>,
    pub val_face_psnr: Option<f64>,
    pub val_mouth_psnr: Option<f64>,
}

/// Reads the rows of a `log.csv`.
pub fn read_log(path: &Path) -> Result<Vec<LogRow>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut rows = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize| f.get(i).and_then(|s| s.parse::<f64>().ok());
        let (Some(step), Some(elapsed_s), Some(loss), Some(psnr)) =
            (num(0), num(1), num(2), num(3))
        else {
            return Err(Error::invalid(
                path,
                format!("line {} is not a log row", n + 1),
            ));
        };
        rows.push(LogRow {
            step: step as usize,
            elapsed_s,
            loss,
            psnr,
            val_psnr: num(6),
            val_face_psnr: num(8),
            val_mouth_psnr: num(9),
        });
    }
    Ok(rows)
}
