//! Empty-space skipping for the grid teacher: Instant-NGP's occupancy grid (Müller et al.
//! 2022, Appendix E.2) over the grid's box, kept up to date while training, and the
//! stratified sampler that spends a ray's samples on the occupied cells it crosses.
//!
//! The box is cut into `R^3` cells. Each cell keeps a density, `ρ ← max(decay ρ, σ(x))`,
//! where `x` is a fresh point drawn inside the cell at every update and `σ` the field's
//! density there under one audio code of the current batch (so every mouth state the batch
//! visits leaves its mark). A cell is occupied when one cell's length `ℓ` of that density
//! would be at least `min_opacity` opaque, `1 - exp(-ρ ℓ) ≥ min_opacity`, or when its
//! density reaches the mean of all cells (so a young field, faint everywhere, is never
//! switched off), or when a neighbour is occupied (one cell of dilation, so a thin surface
//! between two cells' draws is not lost). Before the first update every cell is occupied.
//!
//! A ray's `n` samples are stratified over the occupied part of its span: the span is cut
//! into short pieces, the occupied pieces laid end to end into a length `L`, and sample `k`
//! sits at `s_k = (k + u_k) L / n` along them (`u_k` the jitter, or ½). Its spacing is the
//! occupied length to the next sample (the last: to the occupied end), so the spacings of a
//! ray add up to `L` and a ray whose span is all occupied gets exactly
//! [`sample_stratified`]'s samples. A ray that crosses no occupied cell keeps its place
//! among the hit rays with all spacings zero: it composites to its background.

use candle_core::{Device, Result, Tensor, Var};
use glam::Vec3;
use nldf_core::bounds::Bounds;
use nldf_core::rays::Rays;
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::networks::sampler::{RaySamples, sample_hits, sample_stratified};

/// The occupancy grid's settings (`model.occupancy` in the teacher's `config.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OccupancyConfig {
    /// Cells per axis of the box, `R`.
    pub resolution: usize,
    /// Training steps between updates.
    pub update_every: usize,
    /// Steps before the first update; until then every cell is occupied.
    pub warmup_steps: usize,
    /// How much of a cell's density survives one update, before the new draw's maximum.
    pub decay: f32,
    /// A cell is occupied when one cell's length of its density is this opaque.
    pub min_opacity: f32,
}

impl Default for OccupancyConfig {
    /// 32 cells per axis, updated every 16 steps after 256, decay 0.95, opacity 0.01
    /// (Instant-NGP's decay and threshold; a coarser grid, for two cores).
    fn default() -> Self {
        OccupancyConfig {
            resolution: 32,
            update_every: 16,
            warmup_steps: 256,
            decay: 0.95,
            min_opacity: 0.01,
        }
    }
}

/// The largest `resolution` the checks accept.
pub const MAX_RESOLUTION: usize = 256;

impl OccupancyConfig {
    /// Refuses settings out of range, naming each as `{key}.field`.
    pub fn check(&self, key: &str) -> crate::error::Result<()> {
        use nldf_core::checks::{in_range, in_range_open};
        let k = |name: &str| format!("{key}.{name}");
        in_range(&k("resolution"), self.resolution, 2, MAX_RESOLUTION)?;
        in_range(&k("update_every"), self.update_every, 1, 1 << 20)?;
        in_range(&k("warmup_steps"), self.warmup_steps, 0, 1 << 30)?;
        in_range(&k("decay"), self.decay, 0.0, 1.0)?;
        in_range_open(&k("min_opacity"), f64::from(self.min_opacity), 0.0, 1.0)?;
        Ok(())
    }
}

/// The name of the cells' densities among the teacher's variables. It sorts after every
/// other variable, so seeding the teacher's weights draws the others as without it; the
/// optimizer leaves it alone.
pub const OCCUPANCY_VAR: &str = "occupancy.density";

/// The density a cell holds before it is first measured: it counts as occupied.
pub const UNMEASURED: f32 = -1.0;

/// A ray's span is cut into this many pieces per cell of the grid's resolution when its
/// occupied part is found.
const PIECES_PER_CELL: usize = 3;

/// The occupancy grid: its settings, box and the cells' densities (`[R^3]`, x fastest).
#[derive(Debug, Clone)]
pub struct Occupancy {
    pub cfg: OccupancyConfig,
    pub bounds: Bounds,
    pub density: Var,
}

impl Occupancy {
    /// A grid over `bounds` whose cells' densities live in `density` (`[R^3]`).
    pub fn new(cfg: &OccupancyConfig, bounds: Bounds, density: Var) -> Occupancy {
        Occupancy {
            cfg: cfg.clone(),
            bounds,
            density,
        }
    }

    /// Every cell back to [`UNMEASURED`].
    pub fn reset(&self) -> Result<()> {
        let n = self.density.elem_count();
        self.density
            .set(&Tensor::from_vec(vec![UNMEASURED; n], n, &Device::Cpu)?)
    }

    /// Whether `step` is one at which the grid is updated.
    pub fn due(&self, step: usize) -> bool {
        step >= self.cfg.warmup_steps
            && (step - self.cfg.warmup_steps).is_multiple_of(self.cfg.update_every.max(1))
    }

    /// One point inside each cell (`[R^3, 3]` flat, x fastest), uniform within it.
    pub fn cell_points<R: Rng + ?Sized>(&self, rng: &mut R) -> Vec<f32> {
        let r = self.cfg.resolution;
        let size = (self.bounds.hi - self.bounds.lo) / r as f32;
        let mut points = Vec::with_capacity(3 * r * r * r);
        for z in 0..r {
            for y in 0..r {
                for x in 0..r {
                    let u = Vec3::new(rng.random(), rng.random(), rng.random());
                    let cell = Vec3::new(x as f32, y as f32, z as f32);
                    points.extend_from_slice(&(self.bounds.lo + (cell + u) * size).to_array());
                }
            }
        }
        points
    }

    /// Takes in the densities `sigma` (`[R^3]`) measured at [`Occupancy::cell_points`]:
    /// `ρ ← max(decay ρ, σ)`, or `σ` for a cell not yet measured.
    pub fn absorb(&self, sigma: &[f32]) -> Result<()> {
        let old: Vec<f32> = self.density.as_tensor().to_vec1()?;
        let new = absorbed(&old, sigma, self.cfg.decay);
        let n = new.len();
        self.density.set(&Tensor::from_vec(new, n, &Device::Cpu)?)
    }

    /// Which cells are occupied now.
    pub fn mask(&self) -> Result<OccupancyMask> {
        let density: Vec<f32> = self.density.as_tensor().to_vec1()?;
        Ok(OccupancyMask::from_density(
            &density,
            self.cfg.resolution,
            self.bounds,
            self.cfg.min_opacity,
        ))
    }
}

/// `max(decay old, new)` per cell; `new` alone where `old` is unmeasured. Densities that are
/// not finite count as huge (occupied), never as NaN.
pub fn absorbed(old: &[f32], new: &[f32], decay: f32) -> Vec<f32> {
    old.iter()
        .zip(new)
        .map(|(&o, &n)| {
            let n = if n.is_nan() {
                f32::MAX
            } else {
                n.clamp(0.0, f32::MAX)
            };
            if o < 0.0 { n } else { (decay * o).max(n) }
        })
        .collect()
}

/// The mean density of the measured cells (infinite when none is measured), in f64.
fn mean_measured(density: &[f32]) -> f32 {
    let (sum, n) = density
        .iter()
        .filter(|&&d| d >= 0.0)
        .fold((0.0f64, 0usize), |(s, n), &d| (s + f64::from(d), n + 1));
    if n == 0 {
        f32::INFINITY
    } else {
        (sum / n as f64) as f32
    }
}

/// The occupied cells of a grid, dilated by one cell.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyMask {
    pub resolution: usize,
    pub bounds: Bounds,
    /// `[R^3]`, x fastest.
    pub occupied: Vec<bool>,
}

impl OccupancyMask {
    /// The cells whose density `ρ` makes one cell's length `ℓ` (the mean of the cell's
    /// sides) at least `min_opacity` opaque or reaches the mean of the measured cells
    /// (Instant-NGP's `min(τ, mean)`: a young field, faint everywhere, still has cells to
    /// learn in), or that are unmeasured, and their 26 neighbours.
    pub fn from_density(
        density: &[f32],
        resolution: usize,
        bounds: Bounds,
        min_opacity: f32,
    ) -> OccupancyMask {
        let r = resolution;
        let side = (bounds.hi - bounds.lo) / r as f32;
        let cell = (side.x + side.y + side.z) / 3.0;
        let threshold = -(1.0 - min_opacity.clamp(0.0, 0.999_999)).ln() / cell.max(1e-30);
        let threshold = threshold.min(mean_measured(density));
        let seed: Vec<bool> = density.iter().map(|&d| d < 0.0 || d >= threshold).collect();
        let mut occupied = vec![false; seed.len()];
        let idx = |x: usize, y: usize, z: usize| (z * r + y) * r + x;
        for z in 0..r {
            for y in 0..r {
                for x in 0..r {
                    if !seed[idx(x, y, z)] {
                        continue;
                    }
                    for zz in z.saturating_sub(1)..(z + 2).min(r) {
                        for yy in y.saturating_sub(1)..(y + 2).min(r) {
                            for xx in x.saturating_sub(1)..(x + 2).min(r) {
                                occupied[idx(xx, yy, zz)] = true;
                            }
                        }
                    }
                }
            }
        }
        OccupancyMask {
            resolution,
            bounds,
            occupied,
        }
    }

    /// Whether the point `p` lies in an occupied cell (nothing outside the box is).
    pub fn contains(&self, p: Vec3) -> bool {
        let r = self.resolution;
        let u = (p - self.bounds.lo) / (self.bounds.hi - self.bounds.lo) * r as f32;
        if !(u.x >= 0.0 && u.y >= 0.0 && u.z >= 0.0) {
            return false;
        }
        let (x, y, z) = (u.x as usize, u.y as usize, u.z as usize);
        if x > r || y > r || z > r {
            return false;
        }
        // The box's far faces belong to its last cells.
        let (x, y, z) = (x.min(r - 1), y.min(r - 1), z.min(r - 1));
        self.occupied[(z * r + y) * r + x]
    }

    /// Whether every cell is occupied.
    pub fn all(&self) -> bool {
        self.occupied.iter().all(|&o| o)
    }

    /// Share of the cells that are occupied.
    pub fn fraction(&self) -> f64 {
        self.occupied.iter().filter(|&&o| o).count() as f64 / self.occupied.len().max(1) as f64
    }
}

/// Stratified samples over the occupied part of each ray's span inside `bounds` (module
/// docs): the same rays hit, and `spans`, as [`sample_stratified`] gives; with every cell
/// occupied, exactly its samples.
///
/// # Shapes
/// - see [`RaySamples`]
pub fn sample_occupied<R: Rng + ?Sized>(
    rays: &Rays,
    bounds: &Bounds,
    near: f32,
    far: f32,
    n_samples: usize,
    mask: &OccupancyMask,
    rng: Option<&mut R>,
) -> RaySamples {
    if mask.all() {
        return sample_stratified(rays, bounds, near, far, n_samples, rng);
    }
    let mut pieces: Vec<(f32, f32)> = Vec::new();
    let mut along: Vec<(f32, f32)> = Vec::with_capacity(n_samples);
    sample_hits(
        rays,
        bounds,
        near,
        far,
        n_samples,
        rng,
        &mut |o, d, (t0, t1), u, s| {
            let norm = d.length();
            occupied_pieces(o, d, (t0, t1), mask, &mut pieces);
            let total: f32 = pieces.iter().map(|&(a, b)| b - a).sum();
            along.clear();
            let (mut piece, mut before) = (0, 0.0f32);
            for (k, &uk) in u.iter().enumerate() {
                let sk = (k as f32 + uk) * total / n_samples as f32;
                while piece + 1 < pieces.len() && before + (pieces[piece].1 - pieces[piece].0) < sk
                {
                    before += pieces[piece].1 - pieces[piece].0;
                    piece += 1;
                }
                let t = match pieces.get(piece) {
                    Some(&(a, b)) => (a + (sk - before)).min(b),
                    None => t0 + (k as f32 + uk) * (t1 - t0) / n_samples as f32,
                };
                along.push((sk, t));
            }
            for (k, &(sk, t)) in along.iter().enumerate() {
                let next = along.get(k + 1).map_or(total, |&(sn, _)| sn);
                s.t_vals.push(t);
                s.deltas.push((next - sk).max(0.0) * norm);
                s.points.extend_from_slice(&(o + t * d).to_array());
            }
        },
    )
}

/// The occupied pieces of the span `(t0, t1)` of the ray `o + t d`, in order, neighbours
/// merged: the span inside the mask's box is cut into `PIECES_PER_CELL` pieces per cell of
/// resolution, and a piece is occupied when its midpoint is.
fn occupied_pieces(
    o: Vec3,
    d: Vec3,
    (t0, t1): (f32, f32),
    mask: &OccupancyMask,
    out: &mut Vec<(f32, f32)>,
) {
    out.clear();
    let Some((a, b)) = mask.bounds.intersect(o, d, t0, t1) else {
        return;
    };
    let n = PIECES_PER_CELL * mask.resolution;
    let step = (b - a) / n as f32;
    let edge = |i: usize| if i == n { b } else { a + i as f32 * step };
    for i in 0..n {
        let (lo, hi) = (edge(i), edge(i + 1));
        if !mask.contains(o + (0.5 * (lo + hi)) * d) {
            continue;
        }
        match out.last_mut() {
            Some(last) if last.1 == lo => last.1 = hi,
            _ => out.push((lo, hi)),
        }
    }
}

#[cfg(test)]
#[path = "occupancy_tests.rs"]
mod tests;
