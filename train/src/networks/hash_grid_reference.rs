//! The hash grid's encoding in f64, written plainly from Eq. 2-4 of Instant-NGP (and its
//! tri-plane form), vertex by vertex: the reference the grid op's kernels
//! ([`crate::networks::hash_grid`]) are tested against, forward and backward.

use crate::networks::hash_grid::{GridConfig, Level};

/// The encoding in f64, written plainly from Eq. 2-4: the reference the op is tested
/// against. `points` `[n, 3]`, `table` `[entries, F]`; returns `[n, L F]`.
pub fn encode_reference(cfg: &GridConfig, points: &[f64], table: &[f64]) -> Vec<f64> {
    let layout = cfg.layout();
    let f = cfg.features;
    let mut out = Vec::with_capacity(points.len() / 3 * cfg.dim());
    for p in points.chunks_exact(3) {
        for level in &layout.levels {
            let mut acc = vec![0.0f64; f];
            for_corners_reference(cfg, level, p, |entry, w| {
                for (a, t) in acc.iter_mut().zip(&table[entry * f..(entry + 1) * f]) {
                    *a += w * t;
                }
            });
            out.extend(acc);
        }
    }
    out
}

/// The table's gradient in f64 (the adjoint of [`encode_reference`]).
pub fn table_grad_reference(cfg: &GridConfig, points: &[f64], grad: &[f64]) -> Vec<f64> {
    let layout = cfg.layout();
    let (f, width) = (cfg.features, cfg.dim());
    let mut dt = vec![0.0f64; layout.entries * f];
    for (p, g) in points.chunks_exact(3).zip(grad.chunks_exact(width)) {
        for (l, level) in layout.levels.iter().enumerate() {
            for_corners_reference(cfg, level, p, |entry, w| {
                for k in 0..f {
                    dt[entry * f + k] += w * g[l * f + k];
                }
            });
        }
    }
    dt
}

/// Visits the vertices of `p`'s cell at `level` with their interpolation weights, in f64:
/// 8 trilinear ones, or a plane level's 4 bilinear ones over its two axes.
fn for_corners_reference(
    cfg: &GridConfig,
    level: &Level,
    p: &[f64],
    mut visit: impl FnMut(usize, f64),
) {
    let n = level.resolution;
    let mut base = [0u32; 3];
    let mut frac = [0.0f64; 3];
    for d in 0..3 {
        let u = ((p[d] - cfg.lo[d] as f64) / (cfg.hi[d] as f64 - cfg.lo[d] as f64)).clamp(0.0, 1.0);
        let s = u * n as f64;
        let i = (s.floor() as u32).min(n - 1);
        base[d] = i;
        frac[d] = s - i as f64;
    }
    if let Some([a, b]) = level.plane {
        for db in 0..2u32 {
            for da in 0..2u32 {
                let wa = if da == 1 { frac[a] } else { 1.0 - frac[a] };
                let wb = if db == 1 { frac[b] } else { 1.0 - frac[b] };
                visit(
                    level.offset + level.entry2(base[a] + da, base[b] + db),
                    wa * wb,
                );
            }
        }
        return;
    }
    for dx in 0..2u32 {
        for dy in 0..2u32 {
            for dz in 0..2u32 {
                let w = [dx, dy, dz]
                    .iter()
                    .zip(frac)
                    .map(|(&b, f)| if b == 1 { f } else { 1.0 - f })
                    .product::<f64>();
                let entry = level.offset + level.entry(base[0] + dx, base[1] + dy, base[2] + dz);
                visit(entry, w);
            }
        }
    }
}
