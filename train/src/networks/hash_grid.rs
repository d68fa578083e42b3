//! The grid teacher's encoding of position: Instant-NGP's multiresolution hash encoding
//! (Müller et al. 2022, Sec. 3), as a candle custom op with CPU kernels of its own.
//!
//! The head's box is normalised to `[0, 1]^3`. Level `l` of `L` lays a grid of
//! `N_l = floor(N_min b^l)` cells per axis over it, `b = exp((ln N_max - ln N_min) / (L - 1))`
//! (Eq. 2-3). Each of the `(N_l + 1)^3` vertices owns `F` learned features: directly when they
//! fit the level's table of `T` entries, otherwise through the spatial hash of Eq. 4,
//! `h(x) = (x_1 π_1 ⊕ x_2 π_2 ⊕ x_3 π_3) mod T`. A point's encoding is, per level, the
//! trilinear interpolation of its cell's 8 vertices' features, the levels side by side:
//! `[n, 3] -> [n, L F]`.
//!
//! With `planes` the same levels lie over the box's three axis planes instead (the
//! tri-plane of RAD-NeRF and ER-NeRF): a level of plane `(a, b)` has `(N_l + 1)^2` vertices,
//! hashed as `(x_a π_1 ⊕ x_b π_2) mod T` when they do not fit, and a point takes the
//! bilinear interpolation of the 4 vertices around its projection; the three planes' levels
//! side by side: `[n, 3] -> [n, 3 L F]`.
//!
//! The backward scatters the output gradient into the tables with the same 8 weights. It
//! runs in parallel over levels (each level owns its slice of the table, so no two threads
//! ever add to one entry) and adds each level's points in order: bit for bit the same on
//! every run. No gradient flows to the positions.

use std::sync::Arc;

use candle_core::{CpuStorage, CustomOp2, Layout, Result, Shape, Tensor};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::ops::op_base::contiguous;

/// The multiresolution hash grid: its levels, tables and the box it spans.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GridConfig {
    /// Resolution levels `L` (Instant-NGP: 16).
    pub levels: usize,
    /// Features per level `F` (Instant-NGP: 2).
    pub features: usize,
    /// `log2 T`, the entries of one level's table (Instant-NGP: 14 to 24).
    pub log2_table: u32,
    /// Cells per axis at the coarsest level, `N_min` (Instant-NGP: 16).
    pub base_resolution: usize,
    /// Cells per axis at the finest level, `N_max` (Instant-NGP: 512 to 524288 for a scene).
    pub max_resolution: usize,
    /// The box the grid spans, in world units: its low corner. Set from the dataset's head
    /// bounds when a run is created; points outside the box have no density.
    pub lo: [f32; 3],
    /// The box's high corner.
    pub hi: [f32; 3],
    /// The grid's learning rate as a multiple of the network's (Instant-NGP trains both at
    /// 1e-2).
    pub lr_scale: f64,
    /// ER-NeRF's region attention: the audio code enters every sample weighted by a
    /// sigmoid attention computed from the sample's grid features, `a(x) ⊙ code`, beside
    /// the features.
    pub region_attention: bool,
    /// Tri-plane (RAD-NeRF's and ER-NeRF's encoding): three 2D multiresolution grids over
    /// the box's xy, xz and yz planes, each with these levels and tables, their features
    /// side by side (`3 L F` wide), instead of one 3D grid.
    pub planes: bool,
}

impl Default for GridConfig {
    /// 16 levels of 2 features in tables of 2^15 entries, 16 to 512 cells per axis, the grid
    /// at 10 times the network's learning rate (chosen on the tuning scene: docs/grid.md).
    fn default() -> Self {
        GridConfig {
            levels: 16,
            features: 2,
            log2_table: 15,
            base_resolution: 16,
            max_resolution: 512,
            lo: [-1.0; 3],
            hi: [1.0; 3],
            lr_scale: 10.0,
            region_attention: false,
            planes: false,
        }
    }
}

/// Instant-NGP's primes of Eq. 4 (`π_1 = 1` keeps the x axis coherent in memory); a plane
/// hashes its two axes with the first two.
const PRIMES: [u32; 3] = [1, 2_654_435_761, 805_459_861];

/// The axes of the tri-plane's planes: xy, xz, yz.
pub const PLANES: [[usize; 2]; 3] = [[0, 1], [0, 2], [1, 2]];

/// The largest table the checks accept (2^24 entries per level, as Instant-NGP's largest).
pub const MAX_LOG2_TABLE: u32 = 24;

/// One level of the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Level {
    /// Cells per axis, `N_l`.
    pub resolution: u32,
    /// Whether vertices go through the hash (the dense grid would not fit the table).
    pub hashed: bool,
    /// Entries this level uses: `(N_l + 1)^3` (a plane's `(N_l + 1)^2`) when dense, `T`
    /// when hashed.
    pub entries: usize,
    /// First entry of this level in the table.
    pub offset: usize,
    /// The two axes of a tri-plane's level; `None` for a 3D level.
    pub plane: Option<[usize; 2]>,
}

/// The levels of a [`GridConfig`], with where each lies in the table.
#[derive(Debug, Clone, PartialEq)]
pub struct GridLayout {
    pub levels: Vec<Level>,
    pub features: usize,
    /// Entries of all levels together: the table is `[entries, features]`.
    pub entries: usize,
    lo: [f32; 3],
    /// `1 / (hi - lo)` per axis.
    inv_extent: [f32; 3],
}

impl GridConfig {
    /// Cells per axis of each level, `floor(N_min b^l)` (Eq. 2-3).
    pub fn resolutions(&self) -> Vec<u32> {
        let (lo, hi) = (self.base_resolution as f64, self.max_resolution as f64);
        let b = if self.levels > 1 {
            ((hi.ln() - lo.ln()) / (self.levels - 1) as f64).exp()
        } else {
            1.0
        };
        (0..self.levels)
            .map(|l| (lo * b.powi(l as i32) + 1e-9).floor().max(1.0) as u32)
            .collect()
    }

    /// Width of the encoding, `L F` (a tri-plane's `3 L F`).
    pub fn dim(&self) -> usize {
        self.levels * self.features * if self.planes { PLANES.len() } else { 1 }
    }

    /// Where each level lies in the table.
    pub fn layout(&self) -> GridLayout {
        let table = 1usize << self.log2_table;
        let mut offset = 0;
        let planes: Vec<Option<[usize; 2]>> = if self.planes {
            PLANES.iter().copied().map(Some).collect()
        } else {
            vec![None]
        };
        let resolutions = self.resolutions();
        let levels = planes
            .iter()
            .flat_map(|&plane| resolutions.iter().map(move |&r| (plane, r)))
            .map(|(plane, resolution)| {
                let side = resolution as usize + 1;
                let dense = match plane {
                    Some(_) => side.saturating_mul(side),
                    None => side.saturating_mul(side).saturating_mul(side),
                };
                let (hashed, entries) = if dense <= table {
                    (false, dense)
                } else {
                    (true, table)
                };
                let level = Level {
                    resolution,
                    hashed,
                    entries,
                    offset,
                    plane,
                };
                offset += entries;
                level
            })
            .collect();
        let inv = |d: usize| 1.0 / (self.hi[d] - self.lo[d]);
        GridLayout {
            levels,
            features: self.features,
            entries: offset,
            lo: self.lo,
            inv_extent: [inv(0), inv(1), inv(2)],
        }
    }

    /// Checks every field, naming the key (under `key`) whose value is out of range.
    pub fn check(&self, key: &str) -> crate::error::Result<()> {
        use nldf_core::checks::{in_range, positive};
        let k = |name: &str| format!("{key}.{name}");
        in_range(&k("levels"), self.levels, 1, 64)?;
        in_range(&k("features"), self.features, 1, 16)?;
        in_range(&k("log2_table"), self.log2_table, 4, MAX_LOG2_TABLE)?;
        in_range(&k("base_resolution"), self.base_resolution, 1, 1 << 20)?;
        in_range(
            &k("max_resolution"),
            self.max_resolution,
            self.base_resolution,
            1 << 20,
        )?;
        positive(&k("lr_scale"), self.lr_scale, 1e4)?;
        for d in 0..3 {
            let (lo, hi) = (self.lo[d], self.hi[d]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return Err(crate::error::Error::Config(format!(
                    "`{key}.lo` and `{key}.hi` must be finite with hi above lo on every axis, got {lo} and {hi}"
                )));
            }
        }
        Ok(())
    }

    /// Sets the box to `lo..hi`.
    pub fn set_box(&mut self, lo: glam::Vec3, hi: glam::Vec3) {
        self.lo = lo.to_array();
        self.hi = hi.to_array();
    }
}

impl Level {
    /// Table entry (relative to the level) of the vertex `(x, y, z)`.
    #[inline]
    pub fn entry(&self, x: u32, y: u32, z: u32) -> usize {
        if self.hashed {
            let h =
                x.wrapping_mul(PRIMES[0]) ^ y.wrapping_mul(PRIMES[1]) ^ z.wrapping_mul(PRIMES[2]);
            (h as usize) & (self.entries - 1)
        } else {
            let side = self.resolution as usize + 1;
            x as usize + side * (y as usize + side * z as usize)
        }
    }

    /// Table entry (relative to the level) of a plane's vertex `(a, b)`.
    #[inline]
    pub fn entry2(&self, a: u32, b: u32) -> usize {
        if self.hashed {
            let h = a.wrapping_mul(PRIMES[0]) ^ b.wrapping_mul(PRIMES[1]);
            (h as usize) & (self.entries - 1)
        } else {
            a as usize + (self.resolution as usize + 1) * b as usize
        }
    }
}

/// One point's cell at one level: its vertices' entries (absolute) and interpolation
/// weights, the first `n` of them: 8 trilinear ones, corner `c` at offset
/// `(c & 1, c >> 1 & 1, c >> 2 & 1)`, or a plane's 4 bilinear ones, `(c & 1, c >> 1 & 1)`.
#[derive(Debug, Clone, Copy, Default)]
struct Cell {
    entries: [usize; 8],
    weights: [f32; 8],
    n: usize,
}

impl GridLayout {
    /// Whether the point `p` lies inside the box (false too when not finite), and `p` in
    /// the box's unit cube, clamped to it (a point that is not finite at the origin).
    #[inline]
    fn unit(&self, p: &[f32]) -> (bool, [f32; 3]) {
        let mut u = [0.0f32; 3];
        let mut inside = true;
        for d in 0..3 {
            let v = (p[d] - self.lo[d]) * self.inv_extent[d];
            if !(0.0..=1.0).contains(&v) {
                inside = false;
            }
            u[d] = if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            };
        }
        (inside, u)
    }

    /// Whether `p` lies inside the box.
    pub fn contains(&self, p: &[f32]) -> bool {
        self.unit(p).0
    }

    #[inline]
    fn cell(&self, level: &Level, u: &[f32; 3]) -> Cell {
        if let Some(axes) = level.plane {
            return self.plane_cell(level, axes, u);
        }
        let n = level.resolution;
        let mut base = [0u32; 3];
        // Per axis, the weights of the low and the high vertex.
        let mut w = [[0.0f32; 2]; 3];
        for d in 0..3 {
            (base[d], w[d]) = axis_cell(u[d], n);
        }
        let mut cell = Cell::default();
        // Per axis, the low and the high vertex's term of the index.
        let terms: [[u32; 2]; 3] = if level.hashed {
            let t = |d: usize| {
                [
                    base[d].wrapping_mul(PRIMES[d]),
                    (base[d] + 1).wrapping_mul(PRIMES[d]),
                ]
            };
            [t(0), t(1), t(2)]
        } else {
            let side = n + 1;
            let t = |d: usize, stride: u32| [base[d] * stride, (base[d] + 1) * stride];
            [t(0, 1), t(1, side), t(2, side * side)]
        };
        let mask = level.entries - 1;
        cell.n = 8;
        for c in 0..8 {
            let (bx, by, bz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            cell.weights[c] = w[0][bx] * w[1][by] * w[2][bz];
            cell.entries[c] = level.offset
                + if level.hashed {
                    ((terms[0][bx] ^ terms[1][by] ^ terms[2][bz]) as usize) & mask
                } else {
                    (terms[0][bx] + terms[1][by] + terms[2][bz]) as usize
                };
        }
        cell
    }

    /// A plane level's cell: the 4 vertices around `u` projected on `axes`, with bilinear
    /// weights.
    #[inline]
    fn plane_cell(&self, level: &Level, axes: [usize; 2], u: &[f32; 3]) -> Cell {
        let n = level.resolution;
        let mut base = [0u32; 2];
        let mut w = [[0.0f32; 2]; 2];
        for (k, &d) in axes.iter().enumerate() {
            (base[k], w[k]) = axis_cell(u[d], n);
        }
        let mut cell = Cell {
            n: 4,
            ..Cell::default()
        };
        for c in 0..4 {
            let (ba, bb) = (c & 1, (c >> 1) & 1);
            cell.weights[c] = w[0][ba] * w[1][bb];
            cell.entries[c] = level.offset + level.entry2(base[0] + ba as u32, base[1] + bb as u32);
        }
        cell
    }

    /// The encoding of `points` (`[n, 3]` flat) from `table` (`[entries, F]` flat), in
    /// parallel over blocks of points: `[n, L F]` flat.
    pub fn encode(&self, points: &[f32], table: &[f32]) -> Vec<f32> {
        let (f, width) = (self.features, self.levels.len() * self.features);
        let n = points.len() / 3;
        let mut out = vec![0.0f32; n * width];
        out.par_chunks_mut(BLOCK * width)
            .zip(points.par_chunks(BLOCK * 3))
            .for_each(|(out, pts)| {
                for (o, p) in out.chunks_exact_mut(width).zip(pts.chunks_exact(3)) {
                    let (_, u) = self.unit(p);
                    for (l, level) in self.levels.iter().enumerate() {
                        let cell = self.cell(level, &u);
                        let o = &mut o[l * f..(l + 1) * f];
                        for (e, w) in cell.entries.iter().zip(cell.weights).take(cell.n) {
                            for (v, t) in o.iter_mut().zip(&table[e * f..(e + 1) * f]) {
                                *v += w * t;
                            }
                        }
                    }
                }
            });
        out
    }

    /// The table's gradient from the encoding's (`grad`, `[n, L F]` flat): each output
    /// gradient added to its cell's 8 vertices with the interpolation weights. In parallel
    /// over levels, each level's points in order.
    pub fn table_grad(&self, points: &[f32], grad: &[f32]) -> Vec<f32> {
        let (f, width) = (self.features, self.levels.len() * self.features);
        let mut dt = vec![0.0f32; self.entries * f];
        let mut slices = Vec::with_capacity(self.levels.len());
        let mut rest = &mut dt[..];
        for level in &self.levels {
            let (head, tail) = rest.split_at_mut(level.entries * f);
            slices.push(head);
            rest = tail;
        }
        let units: Vec<[f32; 3]> = points.chunks_exact(3).map(|p| self.unit(p).1).collect();
        slices
            .into_par_iter()
            .zip(self.levels.par_iter().enumerate())
            .for_each(|(dst, (l, level))| {
                for (u, g) in units.iter().zip(grad.chunks_exact(width)) {
                    let g = &g[l * f..(l + 1) * f];
                    if g.iter().all(|&v| v == 0.0) {
                        continue;
                    }
                    let cell = self.cell(level, u);
                    for (e, w) in cell.entries.iter().zip(cell.weights).take(cell.n) {
                        let e = e - level.offset;
                        for (d, v) in dst[e * f..(e + 1) * f].iter_mut().zip(g) {
                            *d += w * v;
                        }
                    }
                }
            });
        dt
    }
}

/// Along one axis of a level of `n` cells: the low vertex of the cell holding `u` (in
/// `[0, 1]`) and the weights of its low and high vertex.
#[inline]
fn axis_cell(u: f32, n: u32) -> (u32, [f32; 2]) {
    let s = u * n as f32;
    // `u` is in [0, 1], so truncation is the floor.
    let i = (s as u32).min(n - 1);
    let f = (s - i as f32).clamp(0.0, 1.0);
    (i, [1.0 - f, f])
}

/// Points encoded together by one task of [`GridLayout::encode`].
const BLOCK: usize = 256;

/// The encoding as a candle op over `(points [n, 3], table [entries, F])`.
#[derive(Debug, Clone)]
pub struct HashGridOp {
    pub layout: Arc<GridLayout>,
}

impl CustomOp2 for HashGridOp {
    fn name(&self) -> &'static str {
        "nldf-hash-grid"
    }

    fn cpu_fwd(
        &self,
        points_storage: &CpuStorage,
        points_layout: &Layout,
        table_storage: &CpuStorage,
        table_layout: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (n, three) = points_layout.shape().dims2()?;
        let g = &self.layout;
        if three != 3 || table_layout.shape().elem_count() != g.entries * g.features {
            candle_core::bail!(
                "hash grid: points {:?} and table {:?} do not fit {} entries of {} features",
                points_layout.shape(),
                table_layout.shape(),
                g.entries,
                g.features
            );
        }
        let points = contiguous(points_storage, points_layout, "points")?;
        let table = contiguous(table_storage, table_layout, "table")?;
        let out = g.encode(points, table);
        Ok((
            CpuStorage::F32(out),
            Shape::from((n, g.levels.len() * g.features)),
        ))
    }

    fn bwd(
        &self,
        points: &Tensor,
        table: &Tensor,
        _out: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let points_v = points.flatten_all()?.to_vec1::<f32>()?;
        let grad_v = grad.contiguous()?.flatten_all()?.to_vec1::<f32>()?;
        let dt = self.layout.table_grad(&points_v, &grad_v);
        Ok((
            None,
            Some(Tensor::from_vec(dt, table.shape(), table.device())?),
        ))
    }
}

/// A hash grid's table and layout, for a network to encode its points with.
#[derive(Debug, Clone)]
pub struct HashGrid {
    pub cfg: GridConfig,
    pub layout: Arc<GridLayout>,
    /// `[entries, F]`.
    pub table: Tensor,
}

/// Table entries are drawn uniform in `±INIT_RANGE` (Instant-NGP: 1e-4).
pub const INIT_RANGE: f32 = 1e-4;

/// Builds a [`HashGrid`] under `vb` (`table`).
pub fn hash_grid(cfg: &GridConfig, vb: candle_nn::VarBuilder) -> Result<HashGrid> {
    let layout = cfg.layout();
    let init = candle_nn::Init::Uniform {
        lo: -(INIT_RANGE as f64),
        up: INIT_RANGE as f64,
    };
    let table = vb.get_with_hints((layout.entries, cfg.features), "table", init)?;
    Ok(HashGrid {
        cfg: cfg.clone(),
        layout: Arc::new(layout),
        table,
    })
}

impl HashGrid {
    /// Encodes `points` (`[n, 3]` flat). With `train`, gradients flow to the table.
    ///
    /// # Shapes
    /// - returns `[n, L F]`
    pub fn encode(&self, points: &[f32], train: bool) -> Result<Tensor> {
        let n = points.len() / 3;
        let p = Tensor::from_slice(points, (n, 3), self.table.device())?;
        let op = HashGridOp {
            layout: self.layout.clone(),
        };
        if train {
            p.apply_op2(&self.table, op)
        } else {
            p.apply_op2_no_bwd(&self.table, &op)
        }
    }

    /// Whether each point lies inside the grid's box (`[n]`).
    pub fn inside(&self, points: &[f32]) -> Vec<bool> {
        points
            .chunks_exact(3)
            .map(|p| self.layout.contains(p))
            .collect()
    }
}

/// Sets the table named `name` in `varmap` to seeded values uniform in `±INIT_RANGE`
/// (after [`crate::networks::nn::init_seeded`], which draws every variable as a layer's weight).
pub fn init_table(varmap: &candle_nn::VarMap, name: &str, seed: u64) -> Result<()> {
    use rand::SeedableRng;
    let data = varmap
        .data()
        .lock()
        .map_err(|_| candle_core::Error::Msg("variable map lock poisoned".into()))?;
    let var = data
        .get(name)
        .ok_or_else(|| candle_core::Error::Msg(format!("no `{name}` to initialise")))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15);
    crate::networks::nn::set_uniform_within(var, INIT_RANGE, &mut rng)
}
