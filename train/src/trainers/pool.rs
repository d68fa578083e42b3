//! The active beam pool (paper section 3.5): the beams the student finds hardest are kept
//! and trained again as an extra batch, so that rare, detailed rays (the mouth, the eyes,
//! silhouette edges) are not drowned by the many easy ones.
//!
//! Each step the top `hard_ratio` of the batch by loss enter the pool; once it is full,
//! they replace the entries with the lowest recorded loss, when theirs is higher. A pool
//! batch's new losses overwrite its entries' records, so beams that have become easy make
//! room for harder ones.

use std::path::Path;

use candle_core::{Device, Tensor};
use rand::Rng;

use crate::error::{Error, Result};
use crate::trainers::checkpoint::{load_tensors, save_tensors, step_of};

/// A beam in the pool: which training frame, which of its hit pixels, and its last loss.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoolEntry {
    pub frame: u32,
    pub pixel: u32,
    pub loss: f32,
}

/// The pool of hardest beams.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct BeamPool {
    pub capacity: usize,
    pub entries: Vec<PoolEntry>,
}

impl BeamPool {
    /// An empty pool holding at most `capacity` beams.
    pub fn new(capacity: usize) -> BeamPool {
        BeamPool {
            capacity,
            entries: Vec::with_capacity(capacity),
        }
    }

    /// Offers a batch's beams: the `ratio` fraction with the highest loss enter (appended
    /// while there is room, then replacing lower-loss entries). Returns how many entered.
    pub fn offer(&mut self, beams: &[PoolEntry], ratio: f64) -> usize {
        if self.capacity == 0 || beams.is_empty() {
            return 0;
        }
        let take = ((ratio.clamp(0.0, 1.0) * beams.len() as f64).round() as usize).min(beams.len());
        let mut order: Vec<usize> = (0..beams.len()).collect();
        order.sort_by(|&a, &b| beams[b].loss.total_cmp(&beams[a].loss).then(a.cmp(&b)));
        let hardest: Vec<PoolEntry> = order[..take].iter().map(|&i| beams[i]).collect();
        let room = self.capacity - self.entries.len().min(self.capacity);
        let (appended, rest) = hardest.split_at(room.min(hardest.len()));
        self.entries.extend_from_slice(appended);
        if rest.is_empty() {
            return appended.len();
        }
        // Replace the lowest-loss entries, hardest newcomer against easiest entry.
        let mut by_loss: Vec<usize> = (0..self.entries.len()).collect();
        let k = rest.len().min(by_loss.len());
        by_loss.select_nth_unstable_by(k.saturating_sub(1), |&a, &b| {
            self.entries[a]
                .loss
                .total_cmp(&self.entries[b].loss)
                .then(a.cmp(&b))
        });
        let mut easiest: Vec<usize> = by_loss[..k].to_vec();
        easiest.sort_by(|&a, &b| {
            self.entries[a]
                .loss
                .total_cmp(&self.entries[b].loss)
                .then(a.cmp(&b))
        });
        let mut entered = appended.len();
        for (new, &slot) in rest.iter().zip(&easiest) {
            if new.loss > self.entries[slot].loss {
                self.entries[slot] = *new;
                entered += 1;
            }
        }
        entered
    }

    /// `n` entries drawn uniformly (with replacement); returns their indices.
    pub fn draw<R: Rng + ?Sized>(&self, n: usize, rng: &mut R) -> Vec<usize> {
        if self.entries.is_empty() {
            return Vec::new();
        }
        (0..n)
            .map(|_| rng.random_range(0..self.entries.len()))
            .collect()
    }

    /// Records new losses of entries drawn by [`BeamPool::draw`].
    pub fn update(&mut self, drawn: &[usize], losses: &[f32]) {
        for (&i, &l) in drawn.iter().zip(losses) {
            if let Some(e) = self.entries.get_mut(i) {
                e.loss = l;
            }
        }
    }
}

/// Writes the pool's entries with the step of the checkpoint they belong to.
pub fn save_pool(path: &Path, pool: &BeamPool, step: usize) -> Result<()> {
    let dev = Device::Cpu;
    let n = pool.entries.len();
    let frames: Vec<u32> = pool.entries.iter().map(|e| e.frame).collect();
    let pixels: Vec<u32> = pool.entries.iter().map(|e| e.pixel).collect();
    let losses: Vec<f32> = pool.entries.iter().map(|e| e.loss).collect();
    let tensors = [
        ("frame".to_string(), Tensor::from_vec(frames, n, &dev)?),
        ("pixel".to_string(), Tensor::from_vec(pixels, n, &dev)?),
        ("loss".to_string(), Tensor::from_vec(losses, n, &dev)?),
    ]
    .into_iter()
    .collect();
    let meta = [("step".to_string(), step.to_string())]
        .into_iter()
        .collect();
    save_tensors(path, &tensors, meta)
}

/// Reads a pool written by [`save_pool`], checking that it is from `step`.
pub fn load_pool(path: &Path, capacity: usize, step: usize) -> Result<BeamPool> {
    let (tensors, meta) = load_tensors(path)?;
    let pool_step = step_of(path, &meta)?;
    if pool_step != step {
        return Err(Error::invalid(
            path,
            format!("is from step {pool_step}, the weights from step {step}"),
        ));
    }
    let get = |k: &str| {
        tensors
            .get(k)
            .ok_or_else(|| Error::invalid(path, format!("lacks `{k}`")))
    };
    let frames: Vec<u32> = get("frame")?.to_vec1()?;
    let pixels: Vec<u32> = get("pixel")?.to_vec1()?;
    let losses: Vec<f32> = get("loss")?.to_vec1()?;
    let mut pool = BeamPool::new(capacity);
    pool.entries = frames
        .into_iter()
        .zip(pixels)
        .zip(losses)
        .map(|((frame, pixel), loss)| PoolEntry { frame, pixel, loss })
        .collect();
    Ok(pool)
}
