//! nldf's CPU kernels for the dense layers of training, below the training crate
//! (`nldf-train`), which builds its fused candle ops on them: a register-blocked matrix product with an
//! AVX-512 micro-kernel, an AVX2 one that gives the same bits, and a portable one
//! (`NLDF_KERNELS` forces one: [`KernelPath`]), the fused forward `act(x W^T + B)`, and
//! the three backward pieces (ReLU mask with the bias gradient, input gradient, weight
//! gradient), each parallel over rows with rayon.
//!
//! Every result is deterministic whatever the thread count: each output element is summed
//! by one task in a fixed order, and the reductions over rows (weight and bias gradients)
//! use fixed-size row chunks summed in chunk order.

use rayon::prelude::*;

/// Rows of a micro-tile.
const MR: usize = 6;
/// Columns of a micro-tile (three 16-lane vectors).
const NR: usize = 64;
/// Rows per parallel task of the row-parallel products.
const ROW_CHUNK: usize = MR * 8;
/// Reduction rows per pass over a row chunk, so that a `[KC, NR]` panel of B stays in L1.
const KC: usize = 128;
/// Rows per partial sum of the reductions over rows (fixed, for determinism).
const REDUCE_CHUNK: usize = 512;
/// Rows of the reduction dimension kept hot in cache at a time in the weight gradient.
const K_BLOCK: usize = 256;

/// How the additive term `B` of [`linear_forward`] is laid out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Addend {
    /// No term.
    None,
    /// `[n]`: one bias row for every row.
    Row,
    /// `[m / group, n]`: one row per group of `group` consecutive rows (a per-ray term
    /// shared by the ray's samples).
    Group(usize),
    /// `[m, n]`: one row per row.
    Full,
}

impl Addend {
    /// The row of the addend that output row `i` uses.
    fn row(self, i: usize) -> Option<usize> {
        match self {
            Addend::None => None,
            Addend::Row => Some(0),
            Addend::Group(g) => Some(i / g.max(1)),
            Addend::Full => Some(i),
        }
    }
}

/// `A(i, p) = a[i * rs + p * cs]`.
#[derive(Clone, Copy)]
struct StridedA {
    ptr: *const f32,
    rs: usize,
    cs: usize,
}

/// One micro-tile's job: `C[i0.., j0..] (+)= sum_p A(i, p) B[p, j]` for `rows` x `cols`
/// (at most MR x NR), then optionally `+ addend row` and ReLU on the way out.
#[derive(Clone, Copy)]
struct Tile {
    k: usize,
    a: StridedA,
    /// `B` at column `j0`, row stride `ldb`.
    b: *const f32,
    ldb: usize,
    /// `C` at `(i0, j0)`, row stride `ldc`.
    c: *mut f32,
    ldc: usize,
    rows: usize,
    cols: usize,
    accumulate: bool,
    relu: bool,
    /// Per tile row, the addend row at column `j0` (null: none).
    addend: [*const f32; MR],
    /// A bias row at column `j0`, added to every row (null: none).
    bias: *const f32,
    /// Per tile row, a row at column `j0` of the ReLU output whose sign gates the result:
    /// `C = 0` where it is `<= 0` (null: no gate). Applied last, after ReLU.
    gate: [*const f32; MR],
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{MR, NR, Tile};
    use std::arch::x86_64::*;

    /// The tile with `R` rows and `V` vectors of 16 columns.
    #[target_feature(enable = "avx512f")]
    unsafe fn kernel<const R: usize, const V: usize>(t: &Tile) {
        // SAFETY (whole function): the caller guarantees that every A(i, p), B row and C
        // element addressed below (rows < t.rows, columns < t.cols) lies inside its slice.
        unsafe {
            let mut masks = [0 as __mmask16; 4];
            for (v, m) in masks.iter_mut().enumerate() {
                let left = t.cols.saturating_sub(16 * v).min(16);
                *m = ((1u32 << left) - 1) as u16;
            }
            let mut acc = [[_mm512_setzero_ps(); V]; R];
            let (rs, cs) = (t.a.rs, t.a.cs);
            for p in 0..t.k {
                let brow = t.b.add(p * t.ldb);
                let mut bv = [_mm512_setzero_ps(); V];
                for (v, b) in bv.iter_mut().enumerate() {
                    *b = _mm512_maskz_loadu_ps(masks[v], brow.add(16 * v));
                }
                let arow = t.a.ptr.add(p * cs);
                for (r, acc_r) in acc.iter_mut().enumerate() {
                    let av = _mm512_set1_ps(*arow.add(r * rs));
                    for (a, b) in acc_r.iter_mut().zip(&bv) {
                        *a = _mm512_fmadd_ps(av, *b, *a);
                    }
                }
            }
            finish::<R, V>(t, &acc, &masks);
        }
    }

    /// Writes a tile's accumulators: `C (+)= acc (+ addend row) (+ bias)`, then ReLU.
    #[target_feature(enable = "avx512f")]
    unsafe fn finish<const R: usize, const V: usize>(
        t: &Tile,
        acc: &[[__m512; V]; R],
        masks: &[__mmask16; 4],
    ) {
        // SAFETY: the caller guarantees that the tile's C, addend and bias cover it.
        unsafe {
            let zero = _mm512_setzero_ps();
            for (r, acc_r) in acc.iter().enumerate() {
                let crow = t.c.add(r * t.ldc);
                for (v, &mask) in masks.iter().enumerate().take(V) {
                    let mut x = acc_r[v];
                    if t.accumulate {
                        x = _mm512_add_ps(x, _mm512_maskz_loadu_ps(mask, crow.add(16 * v)));
                    }
                    if !t.addend[r].is_null() {
                        x = _mm512_add_ps(x, _mm512_maskz_loadu_ps(mask, t.addend[r].add(16 * v)));
                    }
                    if !t.bias.is_null() {
                        x = _mm512_add_ps(x, _mm512_maskz_loadu_ps(mask, t.bias.add(16 * v)));
                    }
                    if t.relu {
                        x = _mm512_max_ps(x, zero);
                    }
                    if !t.gate[r].is_null() {
                        let y = _mm512_maskz_loadu_ps(mask, t.gate[r].add(16 * v));
                        x = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_GT_OQ>(y, zero), x);
                    }
                    _mm512_mask_storeu_ps(crow.add(16 * v), mask, x);
                }
            }
        }
    }

    /// The full 6 x 64 tile with named accumulators (an array of 24 vectors is spilled
    /// to the stack by the compiler, which halves the rate).
    #[target_feature(enable = "avx512f")]
    unsafe fn kernel_full(t: &Tile) {
        // SAFETY: as for `kernel`: the caller guarantees every address is inside its slice.
        unsafe {
            let mut c00 = _mm512_setzero_ps();
            let mut c01 = _mm512_setzero_ps();
            let mut c02 = _mm512_setzero_ps();
            let mut c03 = _mm512_setzero_ps();
            let mut c10 = _mm512_setzero_ps();
            let mut c11 = _mm512_setzero_ps();
            let mut c12 = _mm512_setzero_ps();
            let mut c13 = _mm512_setzero_ps();
            let mut c20 = _mm512_setzero_ps();
            let mut c21 = _mm512_setzero_ps();
            let mut c22 = _mm512_setzero_ps();
            let mut c23 = _mm512_setzero_ps();
            let mut c30 = _mm512_setzero_ps();
            let mut c31 = _mm512_setzero_ps();
            let mut c32 = _mm512_setzero_ps();
            let mut c33 = _mm512_setzero_ps();
            let mut c40 = _mm512_setzero_ps();
            let mut c41 = _mm512_setzero_ps();
            let mut c42 = _mm512_setzero_ps();
            let mut c43 = _mm512_setzero_ps();
            let mut c50 = _mm512_setzero_ps();
            let mut c51 = _mm512_setzero_ps();
            let mut c52 = _mm512_setzero_ps();
            let mut c53 = _mm512_setzero_ps();
            let (rs, cs) = (t.a.rs, t.a.cs);
            for p in 0..t.k {
                let brow = t.b.add(p * t.ldb);
                let b0 = _mm512_loadu_ps(brow.add(0));
                let b1 = _mm512_loadu_ps(brow.add(16));
                let b2 = _mm512_loadu_ps(brow.add(32));
                let b3 = _mm512_loadu_ps(brow.add(48));
                let arow = t.a.ptr.add(p * cs);
                let a0 = _mm512_set1_ps(*arow);
                c00 = _mm512_fmadd_ps(a0, b0, c00);
                c01 = _mm512_fmadd_ps(a0, b1, c01);
                c02 = _mm512_fmadd_ps(a0, b2, c02);
                c03 = _mm512_fmadd_ps(a0, b3, c03);
                let a1 = _mm512_set1_ps(*arow.add(rs));
                c10 = _mm512_fmadd_ps(a1, b0, c10);
                c11 = _mm512_fmadd_ps(a1, b1, c11);
                c12 = _mm512_fmadd_ps(a1, b2, c12);
                c13 = _mm512_fmadd_ps(a1, b3, c13);
                let a2 = _mm512_set1_ps(*arow.add(2 * rs));
                c20 = _mm512_fmadd_ps(a2, b0, c20);
                c21 = _mm512_fmadd_ps(a2, b1, c21);
                c22 = _mm512_fmadd_ps(a2, b2, c22);
                c23 = _mm512_fmadd_ps(a2, b3, c23);
                let a3 = _mm512_set1_ps(*arow.add(3 * rs));
                c30 = _mm512_fmadd_ps(a3, b0, c30);
                c31 = _mm512_fmadd_ps(a3, b1, c31);
                c32 = _mm512_fmadd_ps(a3, b2, c32);
                c33 = _mm512_fmadd_ps(a3, b3, c33);
                let a4 = _mm512_set1_ps(*arow.add(4 * rs));
                c40 = _mm512_fmadd_ps(a4, b0, c40);
                c41 = _mm512_fmadd_ps(a4, b1, c41);
                c42 = _mm512_fmadd_ps(a4, b2, c42);
                c43 = _mm512_fmadd_ps(a4, b3, c43);
                let a5 = _mm512_set1_ps(*arow.add(5 * rs));
                c50 = _mm512_fmadd_ps(a5, b0, c50);
                c51 = _mm512_fmadd_ps(a5, b1, c51);
                c52 = _mm512_fmadd_ps(a5, b2, c52);
                c53 = _mm512_fmadd_ps(a5, b3, c53);
            }
            let acc = [
                [c00, c01, c02, c03],
                [c10, c11, c12, c13],
                [c20, c21, c22, c23],
                [c30, c31, c32, c33],
                [c40, c41, c42, c43],
                [c50, c51, c52, c53],
            ];
            finish::<6, 4>(t, &acc, &[!0, !0, !0, !0]);
        }
    }

    macro_rules! dispatch {
        ($t:expr, $v:literal, $($r:literal)*) => {
            match $t.rows {
                $($r => kernel::<$r, $v>($t),)*
                _ => unreachable!("tile rows are 1..=MR"),
            }
        };
    }

    /// Runs one tile (rows 1..=MR, columns 1..=NR).
    ///
    /// # Safety
    /// The CPU supports AVX-512F and the tile's pointers cover its rows and columns.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn tile(t: &Tile) {
        debug_assert!(t.rows >= 1 && t.rows <= MR && t.cols >= 1 && t.cols <= NR);
        unsafe {
            if t.cols == NR && t.rows == MR {
                kernel_full(t)
            } else if t.cols > 48 {
                dispatch!(t, 4, 1 2 3 4 5 6)
            } else if t.cols > 32 {
                dispatch!(t, 3, 1 2 3 4 5 6)
            } else if t.cols > 16 {
                dispatch!(t, 2, 1 2 3 4 5 6)
            } else {
                dispatch!(t, 1, 1 2 3 4 5 6)
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{MR, NR, Tile};
    use std::arch::x86_64::*;

    /// Lanes `start..start + 8` of a row of `cols` columns that exist, as a load mask.
    #[target_feature(enable = "avx2,fma")]
    fn lanes(cols: usize, start: usize) -> __m256i {
        let left = cols.saturating_sub(start).min(8) as i32;
        _mm256_cmpgt_epi32(
            _mm256_set1_epi32(left),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        )
    }

    /// Columns `j0..j0 + 16` of the tile's `R` rows: the same fused multiply-adds, in the
    /// same order over the reduction, and the same epilogue as the AVX-512 kernel.
    #[target_feature(enable = "avx2,fma")]
    unsafe fn kernel<const R: usize>(t: &Tile, j0: usize) {
        // SAFETY (whole function): the caller guarantees that every A(i, p), B row and C
        // element addressed below (rows < t.rows, columns < t.cols) lies inside its slice;
        // masked-off lanes are neither read nor written.
        unsafe {
            let masks = [lanes(t.cols, j0), lanes(t.cols, j0 + 8)];
            let mut acc = [[_mm256_setzero_ps(); 2]; R];
            let (rs, cs) = (t.a.rs, t.a.cs);
            for p in 0..t.k {
                let brow = t.b.add(p * t.ldb + j0);
                let b0 = _mm256_maskload_ps(brow, masks[0]);
                let b1 = _mm256_maskload_ps(brow.add(8), masks[1]);
                let arow = t.a.ptr.add(p * cs);
                for (r, acc_r) in acc.iter_mut().enumerate() {
                    let av = _mm256_set1_ps(*arow.add(r * rs));
                    acc_r[0] = _mm256_fmadd_ps(av, b0, acc_r[0]);
                    acc_r[1] = _mm256_fmadd_ps(av, b1, acc_r[1]);
                }
            }
            let zero = _mm256_setzero_ps();
            for (r, acc_r) in acc.iter().enumerate() {
                for (v, &mask) in masks.iter().enumerate() {
                    let at = j0 + 8 * v;
                    let mut x = acc_r[v];
                    if t.accumulate {
                        x = _mm256_add_ps(x, _mm256_maskload_ps(t.c.add(r * t.ldc + at), mask));
                    }
                    if !t.addend[r].is_null() {
                        x = _mm256_add_ps(x, _mm256_maskload_ps(t.addend[r].add(at), mask));
                    }
                    if !t.bias.is_null() {
                        x = _mm256_add_ps(x, _mm256_maskload_ps(t.bias.add(at), mask));
                    }
                    if t.relu {
                        x = _mm256_max_ps(x, zero);
                    }
                    if !t.gate[r].is_null() {
                        let y = _mm256_maskload_ps(t.gate[r].add(at), mask);
                        x = _mm256_and_ps(x, _mm256_cmp_ps::<_CMP_GT_OQ>(y, zero));
                    }
                    _mm256_maskstore_ps(t.c.add(r * t.ldc + at), mask, x);
                }
            }
        }
    }

    /// Runs one tile (rows 1..=MR, columns 1..=NR), 16 columns at a time.
    ///
    /// # Safety
    /// The CPU supports AVX2 and FMA and the tile's pointers cover its rows and columns.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn tile(t: &Tile) {
        debug_assert!(t.rows >= 1 && t.rows <= MR && t.cols >= 1 && t.cols <= NR);
        let mut j0 = 0;
        while j0 < t.cols {
            // SAFETY: as the caller guarantees; columns past t.cols are masked off.
            unsafe {
                match t.rows {
                    1 => kernel::<1>(t, j0),
                    2 => kernel::<2>(t, j0),
                    3 => kernel::<3>(t, j0),
                    4 => kernel::<4>(t, j0),
                    5 => kernel::<5>(t, j0),
                    _ => kernel::<6>(t, j0),
                }
            }
            j0 += 16;
        }
    }
}

/// The portable tile (any CPU).
///
/// # Safety
/// The tile's pointers cover its rows and columns.
unsafe fn tile_portable(t: &Tile) {
    let mut acc = [[0.0f32; NR]; MR];
    // SAFETY: as the caller guarantees, every address below is inside its slice.
    unsafe {
        for p in 0..t.k {
            let brow = t.b.add(p * t.ldb);
            for (r, acc_r) in acc.iter_mut().enumerate().take(t.rows) {
                let av = *t.a.ptr.add(r * t.a.rs + p * t.a.cs);
                for (j, acc_rj) in acc_r.iter_mut().enumerate().take(t.cols) {
                    *acc_rj += av * *brow.add(j);
                }
            }
        }
        for (r, acc_r) in acc.iter().enumerate().take(t.rows) {
            let crow = t.c.add(r * t.ldc);
            for (j, &v) in acc_r.iter().enumerate().take(t.cols) {
                let mut x = v;
                if t.accumulate {
                    x += *crow.add(j);
                }
                if !t.addend[r].is_null() {
                    x += *t.addend[r].add(j);
                }
                if !t.bias.is_null() {
                    x += *t.bias.add(j);
                }
                if t.relu {
                    x = x.max(0.0);
                }
                if !t.gate[r].is_null() && *t.gate[r].add(j) <= 0.0 {
                    x = 0.0;
                }
                *crow.add(j) = x;
            }
        }
    }
}

/// The micro-kernel a matrix product runs on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KernelPath {
    /// AVX-512F, 16 lanes, fused multiply-add.
    Avx512,
    /// AVX2 with FMA, 8 lanes: the same fused multiply-adds in the same order as
    /// [`KernelPath::Avx512`], so both give the same bits.
    Avx2,
    /// Plain Rust (any CPU): separate multiply and add, so it rounds differently.
    Portable,
}

impl KernelPath {
    /// The name `NLDF_KERNELS` takes and logs print.
    pub fn name(self) -> &'static str {
        match self {
            KernelPath::Avx512 => "avx512",
            KernelPath::Avx2 => "avx2",
            KernelPath::Portable => "portable",
        }
    }

    /// Whether this CPU can run the path.
    pub fn available(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            match self {
                KernelPath::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
                KernelPath::Avx2 => {
                    std::arch::is_x86_feature_detected!("avx2")
                        && std::arch::is_x86_feature_detected!("fma")
                }
                KernelPath::Portable => true,
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == KernelPath::Portable
        }
    }

    /// The fastest path this CPU has.
    pub fn best() -> KernelPath {
        [KernelPath::Avx512, KernelPath::Avx2]
            .into_iter()
            .find(|p| p.available())
            .unwrap_or(KernelPath::Portable)
    }

    /// The path named by `NLDF_KERNELS` (`avx512`, `avx2`, `portable`), or the best one
    /// when it is unset or empty; an unknown name or a path this CPU lacks is an error.
    pub fn from_env() -> Result<KernelPath, String> {
        let name = std::env::var("NLDF_KERNELS").unwrap_or_default();
        KernelPath::parse(&name)
    }

    fn parse(name: &str) -> Result<KernelPath, String> {
        let path = match name.trim() {
            "" | "auto" => return Ok(KernelPath::best()),
            "avx512" => KernelPath::Avx512,
            "avx2" => KernelPath::Avx2,
            "portable" => KernelPath::Portable,
            other => {
                return Err(format!(
                    "NLDF_KERNELS={other:?}: expected avx512, avx2, portable or auto"
                ));
            }
        };
        if path.available() {
            Ok(path)
        } else {
            Err(format!(
                "NLDF_KERNELS={}: this CPU lacks the instructions of that path",
                path.name()
            ))
        }
    }
}

static FORCED: std::sync::OnceLock<KernelPath> = std::sync::OnceLock::new();

/// The path every product of this process runs on: the one [`use_path`] set, else the
/// best this CPU has. Set it with [`use_path`] before the first product (the CLI does,
/// from `NLDF_KERNELS`).
pub fn path() -> KernelPath {
    *FORCED.get_or_init(KernelPath::best)
}

/// Makes every later product of this process run on `path`; returns the path in force,
/// which is the earlier one if a product already ran or a path was already set.
///
/// # Errors
/// If this CPU cannot run `path`.
pub fn use_path(path: KernelPath) -> Result<KernelPath, String> {
    if !path.available() {
        return Err(format!(
            "kernel path {}: this CPU lacks its instructions",
            path.name()
        ));
    }
    Ok(*FORCED.get_or_init(|| path))
}

/// Runs a tile on `path` (one that this CPU has: [`path`] checks it).
///
/// # Safety
/// The tile's pointers cover its rows and columns.
unsafe fn run_tile(t: &Tile, path: KernelPath) {
    #[cfg(target_arch = "x86_64")]
    match path {
        // SAFETY: the path's instructions were detected; the caller vouches for the pointers.
        KernelPath::Avx512 => return unsafe { avx512::tile(t) },
        // SAFETY: as above.
        KernelPath::Avx2 => return unsafe { avx2::tile(t) },
        KernelPath::Portable => {}
    }
    let _ = path;
    // SAFETY: the caller vouches for the pointers.
    unsafe { tile_portable(t) }
}

/// A raw pointer that may cross into rayon tasks (each task writes disjoint rows).
#[derive(Clone, Copy)]
struct SendPtr(*mut f32);
// SAFETY: tasks built on it write disjoint regions; reads are of immutable inputs.
unsafe impl Send for SendPtr {}
// SAFETY: as above.
unsafe impl Sync for SendPtr {}

#[derive(Clone, Copy)]
struct SendConst(*const f32);
// SAFETY: points into an input slice that outlives the parallel section and is only read.
unsafe impl Send for SendConst {}
// SAFETY: as above.
unsafe impl Sync for SendConst {}

/// `C = act(A B + addend)` over rows `i_lo..i_hi` of C, all columns.
/// `A` is `[m, k]` strided, `B` `[k, n]` packed by [`pack_b`], `C` `[m, n]` with row stride
/// `ldc`.
///
/// # Safety
/// All pointers cover the given shapes.
#[allow(clippy::too_many_arguments)]
unsafe fn gemm_rows(
    i_lo: usize,
    i_hi: usize,
    n: usize,
    k: usize,
    a: StridedA,
    b: *const f32,
    c: *mut f32,
    ldc: usize,
    accumulate: bool,
    addend: (*const f32, usize, Addend),
    bias: *const f32,
    relu: bool,
    gate: *const f32,
    path: KernelPath,
) {
    let (add_ptr, add_ld, add_mode) = addend;
    // The reduction runs in blocks of KC so that a B sub-panel `[KC, NR]` stays in L1 while
    // every row tile of the chunk passes over it; the epilogue (addend, bias, ReLU) runs
    // with the last block.
    let mut k0 = 0;
    while k0 < k.max(1) {
        let kc = KC.min(k - k0);
        let last = k0 + kc >= k;
        let mut j0 = 0;
        while j0 < n {
            let cols = NR.min(n - j0);
            let mut i0 = i_lo;
            while i0 < i_hi {
                let rows = MR.min(i_hi - i0);
                let mut rows_addend = [std::ptr::null::<f32>(); MR];
                let mut rows_gate = [std::ptr::null::<f32>(); MR];
                if last && !gate.is_null() {
                    for (r, slot) in rows_gate.iter_mut().enumerate().take(rows) {
                        // SAFETY: the gate has C's shape and row stride (caller's contract).
                        *slot = unsafe { gate.add((i0 + r) * ldc + j0) };
                    }
                }
                if last {
                    for (r, slot) in rows_addend.iter_mut().enumerate().take(rows) {
                        if let Some(row) = add_mode.row(i0 + r) {
                            // SAFETY: the addend covers this row (caller's shape contract).
                            *slot = unsafe { add_ptr.add(row * add_ld + j0) };
                        }
                    }
                }
                // SAFETY: the offsets stay within the shapes the caller vouched for.
                let t = unsafe {
                    Tile {
                        k: kc,
                        a: StridedA {
                            ptr: a.ptr.add(i0 * a.rs + k0 * a.cs),
                            rs: a.rs,
                            cs: a.cs,
                        },
                        b: b.add((j0 / NR) * k * NR + k0 * NR),
                        ldb: NR,
                        c: c.add(i0 * ldc + j0),
                        ldc,
                        rows,
                        cols,
                        accumulate: accumulate || k0 > 0,
                        relu: relu && last,
                        addend: rows_addend,
                        gate: rows_gate,
                        bias: if bias.is_null() || !last {
                            std::ptr::null()
                        } else {
                            bias.add(j0)
                        },
                    }
                };
                // SAFETY: as above.
                unsafe { run_tile(&t, path) };
                i0 += rows;
            }
            j0 += cols;
        }
        k0 += kc;
    }
}

/// Copies `B` (`[k, n]`, row stride `ldb`) into column panels of NR, each `[k, NR]`
/// contiguous and zero-padded, so that the kernel streams B without cache-set conflicts.
///
/// # Safety
/// `b` covers `k` rows of `n` values at stride `ldb`.
unsafe fn pack_b(b: *const f32, ldb: usize, k: usize, n: usize, out: &mut Vec<f32>) {
    let panels = n.div_ceil(NR);
    out.clear();
    out.resize(panels * k * NR, 0.0);
    for q in 0..panels {
        let j0 = q * NR;
        let cols = NR.min(n - j0);
        let dst = &mut out[q * k * NR..(q + 1) * k * NR];
        for p in 0..k {
            // SAFETY: row p, columns j0..j0+cols of B exist (caller's contract).
            let src = unsafe { std::slice::from_raw_parts(b.add(p * ldb + j0), cols) };
            dst[p * NR..p * NR + cols].copy_from_slice(src);
        }
    }
}

fn check(name: &str, len: usize, need: usize) {
    assert!(
        len >= need,
        "kernel argument `{name}` holds {len} values, needs {need}"
    );
}

/// The fused dense forward: `y = act(x w^T + addend)`.
///
/// # Shapes
/// - `x`: `[m, k]`, `w`: `[n, k]` (candle's `Linear` layout), `y`: `[m, n]`
/// - `addend`: see [`Addend`]
///
/// # Panics
/// If a slice is shorter than its shape (a caller bug).
#[allow(clippy::too_many_arguments)]
pub fn linear_forward(
    x: &[f32],
    m: usize,
    k: usize,
    w: &[f32],
    n: usize,
    addend: &[f32],
    mode: Addend,
    relu: bool,
    y: &mut [f32],
) {
    check("x", x.len(), m * k);
    check("w", w.len(), n * k);
    check("y", y.len(), m * n);
    let add_rows = match mode {
        Addend::None => 0,
        Addend::Row => 1,
        Addend::Group(g) => m.div_ceil(g.max(1)),
        Addend::Full => m,
    };
    check("addend", addend.len(), add_rows * n);
    let packed = pack_weight(w, n, k);
    gemm_parallel(x, m, k, &packed, n, y, (addend, mode), None, relu);
}

/// The residual layer's forward: `y = act(x w^T + bias + residual)`, with a bias row and a
/// full `[m, n]` residual added on the way out of the product.
///
/// # Shapes
/// - `x`: `[m, k]`, `w`: `[n, k]`, `bias`: `[n]`, `residual`, `y`: `[m, n]`
///
/// # Panics
/// If a slice is shorter than its shape (a caller bug).
#[allow(clippy::too_many_arguments)]
pub fn linear_forward_residual(
    x: &[f32],
    m: usize,
    k: usize,
    w: &[f32],
    n: usize,
    bias: &[f32],
    residual: &[f32],
    relu: bool,
    y: &mut [f32],
) {
    check("x", x.len(), m * k);
    check("w", w.len(), n * k);
    check("bias", bias.len(), n);
    check("residual", residual.len(), m * n);
    check("y", y.len(), m * n);
    let packed = pack_weight(w, n, k);
    gemm_parallel(
        x,
        m,
        k,
        &packed,
        n,
        y,
        (residual, Addend::Full),
        Some(bias),
        relu,
    );
}

/// `W^T` (`W` `[n, k]`, candle's `Linear` layout) packed into the column panels of
/// [`pack_b`], read straight from `W`.
fn pack_weight(w: &[f32], n: usize, k: usize) -> Vec<f32> {
    let panels = n.div_ceil(NR);
    let mut out = vec![0.0f32; panels * k * NR];
    for q in 0..panels {
        let j0 = q * NR;
        let dst = &mut out[q * k * NR..(q + 1) * k * NR];
        for j in j0..(j0 + NR).min(n) {
            for (p, &v) in w[j * k..(j + 1) * k].iter().enumerate() {
                dst[p * NR + j - j0] = v;
            }
        }
    }
    out
}

/// `c = act(a b + addend)` for row-major `a` `[m, k]` and `b` packed by [`pack_b`], in
/// parallel over chunks of rows (each task writes its own rows of `c`).
#[allow(clippy::too_many_arguments)]
fn gemm_parallel(
    a: &[f32],
    m: usize,
    k: usize,
    packed: &[f32],
    n: usize,
    c: &mut [f32],
    addend: (&[f32], Addend),
    bias: Option<&[f32]>,
    relu: bool,
) {
    let path = path();
    let cp = SendPtr(c.as_mut_ptr());
    let (ap, bp, dp) = (
        SendConst(a.as_ptr()),
        SendConst(packed.as_ptr()),
        SendConst(addend.0.as_ptr()),
    );
    let biasp = SendConst(bias.map_or(std::ptr::null(), |b| b.as_ptr()));
    let mode = addend.1;
    (0..m.div_ceil(ROW_CHUNK))
        .into_par_iter()
        .for_each(|chunk| {
            let (cp, ap, bp, dp, biasp) = (cp, ap, bp, dp, biasp);
            let i_lo = chunk * ROW_CHUNK;
            let i_hi = (i_lo + ROW_CHUNK).min(m);
            // SAFETY: the callers checked the shapes; tasks write disjoint row ranges of c.
            unsafe {
                gemm_rows(
                    i_lo,
                    i_hi,
                    n,
                    k,
                    StridedA {
                        ptr: ap.0,
                        rs: k,
                        cs: 1,
                    },
                    bp.0,
                    cp.0,
                    n,
                    false,
                    (dp.0, n, mode),
                    biasp.0,
                    relu,
                    std::ptr::null(),
                    path,
                )
            };
        });
}

/// `c = a b` for row-major `a` `[m, k]` and `b` `[k, n]` (the input gradient `g' W`).
///
/// # Panics
/// If a slice is shorter than its shape (a caller bug).
pub fn matmul(a: &[f32], m: usize, k: usize, b: &[f32], n: usize, c: &mut [f32]) {
    check("a", a.len(), m * k);
    check("b", b.len(), k * n);
    check("c", c.len(), m * n);
    let mut packed = Vec::new();
    // SAFETY: b is [k, n] row-major (checked above).
    unsafe { pack_b(b.as_ptr(), n, k, n, &mut packed) };
    gemm_parallel(a, m, k, &packed, n, c, (&[], Addend::None), None, false);
}

/// `c = a b + addend` for row-major `a` `[m, k]`, `b` `[k, n]` and a full `[m, n]` addend
/// (the input gradient of a residual block: `g' W + g`).
///
/// # Panics
/// If a slice is shorter than its shape (a caller bug).
pub fn matmul_add(a: &[f32], m: usize, k: usize, b: &[f32], n: usize, add: &[f32], c: &mut [f32]) {
    check("a", a.len(), m * k);
    check("b", b.len(), k * n);
    check("add", add.len(), m * n);
    check("c", c.len(), m * n);
    let mut packed = Vec::new();
    // SAFETY: b is [k, n] row-major (checked above).
    unsafe { pack_b(b.as_ptr(), n, k, n, &mut packed) };
    gemm_parallel(a, m, k, &packed, n, c, (add, Addend::Full), None, false);
}

/// `c = a^T b` for row-major `a` `[m, n]` and `b` `[m, k]`, summed over the `m` rows (the
/// weight gradient `g'^T x`), `c` `[n, k]`. Partial sums over fixed chunks of rows are
/// added in chunk order.
///
/// # Panics
/// If a slice is shorter than its shape (a caller bug).
pub fn matmul_tn(a: &[f32], m: usize, n: usize, b: &[f32], k: usize, c: &mut [f32]) {
    check("a", a.len(), m * n);
    check("b", b.len(), m * k);
    check("c", c.len(), n * k);
    let partials: Vec<Vec<f32>> = (0..m.div_ceil(REDUCE_CHUNK))
        .into_par_iter()
        .map(|chunk| {
            let mut part = vec![0.0f32; n * k];
            let mut packed = Vec::new();
            let p_lo = chunk * REDUCE_CHUNK;
            let rows = REDUCE_CHUNK.min(m - p_lo);
            block_weight_grad(
                &a[p_lo * n..],
                n,
                n,
                &b[p_lo * k..],
                k,
                k,
                rows,
                &mut part,
                &mut packed,
            );
            part
        })
        .collect();
    c[..n * k].iter_mut().for_each(|v| *v = 0.0);
    for part in &partials {
        for (ci, pi) in c.iter_mut().zip(part) {
            *ci += pi;
        }
    }
}

/// The ReLU backward mask and the bias gradient, in one pass: sets `g *= (y > 0)` in place
/// (nothing without ReLU) and returns the bias gradient, the `[n]` column sums of `g`
/// (partial sums over fixed chunks of rows, added in chunk order).
///
/// # Shapes
/// - `g`, `y`: `[m, n]` (`y` unused without ReLU)
pub fn relu_backward(g: &mut [f32], y: &[f32], m: usize, n: usize, relu: bool) -> Vec<f32> {
    check("g", g.len(), m * n);
    if relu {
        check("y", y.len(), m * n);
    }
    let n1 = n.max(1);
    let partials: Vec<Vec<f32>> = g[..m * n]
        .par_chunks_mut(REDUCE_CHUNK * n1)
        .enumerate()
        .map(|(c, g)| {
            if relu {
                let lo = c * REDUCE_CHUNK * n1;
                let len = g.len();
                for (g, &y) in g.iter_mut().zip(&y[lo..lo + len]) {
                    if y <= 0.0 {
                        *g = 0.0;
                    }
                }
            }
            let mut s = vec![0.0f32; n];
            for row in g.chunks(n1) {
                for (s, v) in s.iter_mut().zip(row) {
                    *s += v;
                }
            }
            s
        })
        .collect();
    let mut db = vec![0.0f32; n];
    for p in &partials {
        for (d, v) in db.iter_mut().zip(p) {
            *d += v;
        }
    }
    db
}

/// A right-hand operand `B` `[k, n]` packed once into the kernel's column panels, for
/// products over many row blocks (see [`block_product`]).
#[derive(Debug, Clone, Default)]
pub struct Packed {
    data: Vec<f32>,
    k: usize,
    n: usize,
}

impl Packed {
    /// `B = W^T` for a weight `W` `[n, k]` (candle's `Linear` layout): the forward operand.
    ///
    /// # Panics
    /// If `w` is shorter than `[n, k]` (a caller bug).
    pub fn weight_t(w: &[f32], n: usize, k: usize) -> Packed {
        check("w", w.len(), n * k);
        Packed {
            data: pack_weight(w, n, k),
            k,
            n,
        }
    }

    /// `B = b` for a row-major `b` `[k, n]` (a weight `[out, inp]` read as the input
    /// gradient's operand: `k = out`, `n = inp`).
    ///
    /// # Panics
    /// If `b` is shorter than `[k, n]` (a caller bug).
    pub fn rows(b: &[f32], k: usize, n: usize) -> Packed {
        check("b", b.len(), k * n);
        let mut data = Vec::new();
        // SAFETY: b is [k, n] row-major (checked above).
        unsafe { pack_b(b.as_ptr(), n, k, n, &mut data) };
        Packed { data, k, n }
    }

    /// Rows of `B` (the reduction length).
    pub fn k(&self) -> usize {
        self.k
    }
}

/// What [`block_product`] does on the way out, per output element `C[i, j]`, in this
/// order: add the old `C` (`accumulate`), the addend row of `i`, the bias; clamp at zero
/// (`relu`); zero it where `gate[i, j] <= 0` (the gate has C's shape and row stride).
#[derive(Debug, Clone, Copy, Default)]
pub struct Epilogue<'a> {
    pub accumulate: bool,
    /// `(values, row stride, layout)`; rows are counted from the block's first row.
    pub addend: Option<(&'a [f32], usize, Addend)>,
    pub bias: Option<&'a [f32]>,
    pub relu: bool,
    pub gate: Option<&'a [f32]>,
}

/// Checks that `rows` rows of `cols` values at row stride `ld` fit in `len` values.
fn check_strided(name: &str, len: usize, rows: usize, cols: usize, ld: usize) {
    if rows > 0 && cols > 0 {
        check(name, len, (rows - 1) * ld + cols);
    }
}

/// One row block's product on the calling thread (the caller parallelises over blocks):
/// `C[i, j] = epilogue(sum_p a[i * lda + p] B[p, j])` for `rows` rows, `C` at row stride
/// `ldc`.
///
/// # Shapes
/// - `a`: `rows` rows of `b.k` values at stride `lda`; `c` (and the gate): `rows` rows of
///   `b.n` values at stride `ldc`
///
/// # Panics
/// If a slice is shorter than its shape (a caller bug).
pub fn block_product(
    a: &[f32],
    lda: usize,
    rows: usize,
    b: &Packed,
    c: &mut [f32],
    ldc: usize,
    epi: Epilogue<'_>,
) {
    check_strided("a", a.len(), rows, b.k, lda);
    check_strided("c", c.len(), rows, b.n, ldc);
    if let Some(g) = epi.gate {
        check_strided("gate", g.len(), rows, b.n, ldc);
    }
    if let Some(bias) = epi.bias {
        check("bias", bias.len(), b.n);
    }
    let (add_ptr, add_ld, add_mode) = match epi.addend {
        Some((v, ld, mode)) => {
            if let Some(last) = rows.checked_sub(1).and_then(|r| mode.row(r)) {
                check_strided("addend", v.len(), last + 1, b.n, ld);
            }
            (v.as_ptr(), ld, mode)
        }
        None => (std::ptr::null(), 0, Addend::None),
    };
    if rows == 0 || b.n == 0 {
        return;
    }
    // SAFETY: every operand's extent was checked above against the shapes used.
    unsafe {
        gemm_rows(
            0,
            rows,
            b.n,
            b.k,
            StridedA {
                ptr: a.as_ptr(),
                rs: lda,
                cs: 1,
            },
            b.data.as_ptr(),
            c.as_mut_ptr(),
            ldc,
            epi.accumulate,
            (add_ptr, add_ld, add_mode),
            epi.bias.map_or(std::ptr::null(), <[f32]>::as_ptr),
            epi.relu,
            epi.gate.map_or(std::ptr::null(), <[f32]>::as_ptr),
            path(),
        )
    };
}

/// One row block's weight gradient on the calling thread: `acc += g^T x`, `acc` `[n, k]`
/// row-major, summed over the block's `rows` rows in order. `scratch` holds the packed
/// `x` between calls.
///
/// # Shapes
/// - `g`: `rows` rows of `n` values at stride `ldg`; `x`: `rows` rows of `k` at stride `ldx`
///
/// # Panics
/// If a slice is shorter than its shape (a caller bug).
#[allow(clippy::too_many_arguments)]
pub fn block_weight_grad(
    g: &[f32],
    ldg: usize,
    n: usize,
    x: &[f32],
    ldx: usize,
    k: usize,
    rows: usize,
    acc: &mut [f32],
    scratch: &mut Vec<f32>,
) {
    check_strided("g", g.len(), rows, n, ldg);
    check_strided("x", x.len(), rows, k, ldx);
    check("acc", acc.len(), n * k);
    if rows == 0 || n == 0 || k == 0 {
        return;
    }
    let path = path();
    let mut p0 = 0;
    while p0 < rows {
        let kb = K_BLOCK.min(rows - p0);
        // SAFETY: rows p0..p0 + kb of g and x exist and acc is [n, k] (checked above).
        unsafe {
            pack_b(x.as_ptr().add(p0 * ldx), ldx, kb, k, scratch);
            gemm_rows(
                0,
                n,
                k,
                kb,
                StridedA {
                    ptr: g.as_ptr().add(p0 * ldg),
                    rs: 1,
                    cs: ldg,
                },
                scratch.as_ptr(),
                acc.as_mut_ptr(),
                k,
                true,
                (std::ptr::null(), 0, Addend::None),
                std::ptr::null(),
                false,
                std::ptr::null(),
                path,
            )
        };
        p0 += kb;
    }
}

/// Large scratch buffers kept between training steps: a fresh multi-megabyte allocation
/// costs a page fault per 4 KiB page, more than the arithmetic that fills it.
static POOL: std::sync::Mutex<Vec<Vec<f32>>> = std::sync::Mutex::new(Vec::new());
/// Buffers the pool keeps at most (the 88-layer student's backward holds about 90 at once).
const POOL_SIZE: usize = 256;
/// Values the pool keeps at most, over all its buffers (2 GiB of f32).
const POOL_VALUES: usize = 1 << 29;

/// A buffer of exactly `len` values from the pool. Its contents are unspecified (zeros or
/// an earlier step's values): only for outputs that are written in full.
pub fn take_buffer(len: usize) -> Vec<f32> {
    let reused = POOL.lock().ok().and_then(|mut pool| {
        let best = pool
            .iter()
            .enumerate()
            .filter(|(_, v)| v.capacity() >= len)
            .min_by_key(|(_, v)| v.capacity())
            .map(|(i, _)| i)?;
        Some(pool.swap_remove(best))
    });
    match reused {
        Some(mut v) => {
            if v.len() >= len {
                v.truncate(len);
            } else {
                v.resize(len, 0.0);
            }
            v
        }
        None => vec![0.0; len],
    }
}

/// Returns a buffer to the pool (small ones are simply dropped).
pub fn give_buffer(v: Vec<f32>) {
    if v.capacity() < 1 << 16 {
        return;
    }
    if let Ok(mut pool) = POOL.lock() {
        let held: usize = pool.iter().map(Vec::capacity).sum();
        if pool.len() < POOL_SIZE && held + v.capacity() <= POOL_VALUES {
            pool.push(v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference(a: &[f32], m: usize, k: usize, b: &[f32], n: usize) -> Vec<f64> {
        let mut c = vec![0.0f64; m * n];
        for i in 0..m {
            for j in 0..n {
                c[i * n + j] = (0..k)
                    .map(|p| a[i * k + p] as f64 * b[p * n + j] as f64)
                    .sum();
            }
        }
        c
    }

    fn values(n: usize, seed: u32) -> Vec<f32> {
        (0..n)
            .map(|i| {
                let h = (i as u32).wrapping_mul(2654435761).wrapping_add(seed * 97);
                ((h >> 8) % 2001) as f32 / 1000.0 - 1.0
            })
            .collect()
    }

    #[test]
    fn products_match_an_f64_reference_for_awkward_shapes() {
        for &(m, k, n) in &[
            (1, 1, 1),
            (13, 5, 3),
            (15, 31, 33),
            (29, 17, 64),
            (130, 40, 17),
            (5000, 9, 40),
            (50, 300, 70),
        ] {
            let a = values(m * k, 1);
            let b = values(k * n, 2);
            let want = reference(&a, m, k, &b, n);
            let mut c = vec![0.0; m * n];
            matmul(&a, m, k, &b, n, &mut c);
            for (x, y) in c.iter().zip(&want) {
                assert!(
                    (*x as f64 - y).abs() < 1e-4,
                    "matmul {m}x{k}x{n}: {x} vs {y}"
                );
            }
            // a^T b with a = [k, m] laid out as the transpose.
            let mut at = vec![0.0; k * m];
            for i in 0..m {
                for p in 0..k {
                    at[p * m + i] = a[i * k + p];
                }
            }
            let mut c2 = vec![0.0; m * n];
            matmul_tn(&at, k, m, &b, n, &mut c2);
            for (x, y) in c2.iter().zip(&want) {
                assert!(
                    (*x as f64 - y).abs() < 1e-4,
                    "matmul_tn {m}x{k}x{n}: {x} vs {y}"
                );
            }
        }
    }

    /// One gated product `c (+)= act(a b + addend + bias)` of the tests: `a` `[m, k]`, `b`
    /// `[k, n]`, addend and gate `[m, n]`, bias `[n]`.
    struct Case<'a> {
        a: &'a [f32],
        b: &'a [f32],
        m: usize,
        k: usize,
        n: usize,
        accumulate: bool,
        addend: Option<&'a [f32]>,
        bias: Option<&'a [f32]>,
        relu: bool,
        gate: Option<&'a [f32]>,
    }

    /// `t` into `c` (`[m, n]`) on `path`, through the tiles every product uses.
    fn product_on(path: KernelPath, t: &Case, c: &mut [f32]) {
        let Case { a, b, m, k, n, .. } = *t;
        let mut packed = Vec::new();
        // SAFETY: every slice has the shape given (the caller's test data).
        unsafe {
            pack_b(b.as_ptr(), n, k, n, &mut packed);
            gemm_rows(
                0,
                m,
                n,
                k,
                StridedA {
                    ptr: a.as_ptr(),
                    rs: k,
                    cs: 1,
                },
                packed.as_ptr(),
                c.as_mut_ptr(),
                n,
                t.accumulate,
                (
                    t.addend.map_or(std::ptr::null(), <[f32]>::as_ptr),
                    n,
                    if t.addend.is_some() {
                        Addend::Full
                    } else {
                        Addend::None
                    },
                ),
                t.bias.map_or(std::ptr::null(), <[f32]>::as_ptr),
                t.relu,
                t.gate.map_or(std::ptr::null(), <[f32]>::as_ptr),
                path,
            );
        }
    }

    /// The wide kernels' arithmetic for `t` into `c`, one output at a time in scalar f32:
    /// per block of KC reduction rows a chain of fused multiply-adds from zero
    /// (`f32::mul_add` rounds once, as `vfmadd` does), added to C from the second block on
    /// (or from the first when accumulating); the last block adds the addend, then the
    /// bias, then clamps at zero and gates, as `finish` does.
    fn fused_chain_model(t: &Case, c: &mut [f32]) {
        let Case { a, b, m, k, n, .. } = *t;
        for i in 0..m {
            for j in 0..n {
                let mut k0 = 0;
                while k0 < k {
                    let kc = KC.min(k - k0);
                    let last = k0 + kc >= k;
                    let mut x = 0.0f32;
                    for p in k0..k0 + kc {
                        x = a[i * k + p].mul_add(b[p * n + j], x);
                    }
                    if t.accumulate || k0 > 0 {
                        x += c[i * n + j];
                    }
                    if last {
                        if let Some(add) = t.addend {
                            x += add[i * n + j];
                        }
                        if let Some(bias) = t.bias {
                            x += bias[j];
                        }
                        // `max(x, 0)` of the vector units gives +0 for -0 too.
                        if t.relu && x <= 0.0 {
                            x = 0.0;
                        }
                        if t.gate.is_some_and(|g| g[i * n + j] <= 0.0) {
                            x = 0.0;
                        }
                    }
                    c[i * n + j] = x;
                    k0 += kc;
                }
            }
        }
    }

    /// Every wide path this CPU has (AVX-512F, AVX2 with FMA) gives the bits of the one
    /// scalar chain of fused multiply-adds above, so the two paths give each other's bits
    /// and training does not move with the machine's kernels. A CPU without AVX-512F checks
    /// the AVX2 path alone (and says so); CI demands at least that one.
    #[test]
    fn the_wide_paths_give_the_bits_of_one_fused_multiply_add_chain() {
        let wide: Vec<KernelPath> = [KernelPath::Avx512, KernelPath::Avx2]
            .into_iter()
            .filter(|p| p.available())
            .collect();
        if wide.is_empty() {
            if std::env::var_os("CI").is_some() {
                panic!("CI runs on x86-64 CPUs with AVX2 and FMA: this check needs one");
            }
            eprintln!("skipped: this CPU has neither AVX-512F nor AVX2 with FMA");
            return;
        }
        let names: Vec<&str> = wide.iter().map(|p| p.name()).collect();
        eprintln!("checking the kernel paths {names:?} against the scalar chain");
        let mut checked = 0;
        for &(m, k, n) in &[
            (1, 1, 1),
            (7, 5, 3),
            (13, 31, 33),
            (29, KC + 17, 64),
            (50, 300, 70),
            (6, 9, NR + 9),
        ] {
            let a = values(m * k, 31);
            let b = values(k * n, 32);
            let old = values(m * n, 33);
            let addend = values(m * n, 34);
            let bias = values(n, 35);
            let gate = values(m * n, 36);
            for mode in 0..8 {
                let (accumulate, relu, extras) = (mode & 1 != 0, mode & 2 != 0, mode & 4 != 0);
                let case = Case {
                    a: &a,
                    b: &b,
                    m,
                    k,
                    n,
                    accumulate,
                    addend: extras.then_some(&addend[..]),
                    bias: extras.then_some(&bias[..]),
                    relu,
                    gate: extras.then_some(&gate[..]),
                };
                let mut want = old.clone();
                fused_chain_model(&case, &mut want);
                let run = |path| {
                    let mut c = old.clone();
                    product_on(path, &case, &mut c);
                    c
                };
                for &path in &wide {
                    let got = run(path);
                    let differ = got
                        .iter()
                        .zip(&want)
                        .filter(|(x, y)| x.to_bits() != y.to_bits())
                        .count();
                    assert_eq!(
                        differ,
                        0,
                        "{} path, {m}x{k}x{n}, mode {mode}: {differ} values differ",
                        path.name()
                    );
                    checked += got.len();
                }
                // The portable path rounds each product apart: near, not the same bits.
                let portable = run(KernelPath::Portable);
                for (x, y) in portable.iter().zip(&want) {
                    assert!((x - y).abs() <= 1e-4 * (1.0 + y.abs()), "{x} vs {y}");
                }
            }
        }
        assert!(checked > 0);
    }

    #[test]
    fn kernel_paths_are_named_and_checked() {
        assert_eq!(KernelPath::parse("").unwrap(), KernelPath::best());
        assert_eq!(KernelPath::parse("auto").unwrap(), KernelPath::best());
        assert_eq!(KernelPath::parse("portable").unwrap(), KernelPath::Portable);
        let err = KernelPath::parse("avx3").unwrap_err();
        assert!(err.contains("NLDF_KERNELS=\"avx3\""), "{err}");
        for path in [KernelPath::Avx512, KernelPath::Avx2] {
            match KernelPath::parse(path.name()) {
                Ok(p) => assert!(p == path && path.available()),
                Err(e) => assert!(!path.available() && e.contains("lacks"), "{e}"),
            }
        }
    }

    #[test]
    fn a_gated_block_product_accumulates_then_zeroes_where_the_gate_is_not_positive() {
        // k spans several reduction blocks, and `a` and `c` have row strides wider than
        // their rows, as column windows of wider matrices.
        let (m, k, n, lda, ldc) = (20, KC + 9, 70, KC + 12, 75);
        let a = values(m * lda, 21);
        let b = values(k * n, 22);
        let old = values(m * ldc, 23);
        let gate = values(m * ldc, 24);
        let dense: Vec<f32> = (0..m)
            .flat_map(|i| a[i * lda..i * lda + k].to_vec())
            .collect();
        let want = reference(&dense, m, k, &b, n);
        let mut c = old.clone();
        block_product(
            &a,
            lda,
            m,
            &Packed::rows(&b, k, n),
            &mut c,
            ldc,
            Epilogue {
                accumulate: true,
                gate: Some(&gate),
                ..Epilogue::default()
            },
        );
        for i in 0..m {
            for j in 0..ldc {
                let (got, at) = (c[i * ldc + j], i * ldc + j);
                if j >= n {
                    assert_eq!(got, old[at], "column {j} is outside the product");
                } else if gate[at] <= 0.0 {
                    assert_eq!(got, 0.0, "gated ({i}, {j})");
                } else {
                    let x = want[i * n + j] + old[at] as f64;
                    assert!((got as f64 - x).abs() < 1e-4, "({i}, {j}): {got} vs {x}");
                }
            }
        }
    }

    #[test]
    fn the_block_weight_gradient_adds_g_transposed_x_from_strided_rows() {
        // More rows than one pass over K_BLOCK; g is a column window (stride 4, offset 1),
        // as the colour gradient is read from the op's [rows, 4] output gradient.
        let (rows, n, k) = (K_BLOCK + 37, 3, 19);
        let g4 = values(rows * 4, 31);
        let x = values(rows * k, 32);
        let start = values(n * k, 33);
        let mut acc = start.clone();
        block_weight_grad(&g4[1..], 4, n, &x, k, k, rows, &mut acc, &mut Vec::new());
        for j in 0..n {
            for p in 0..k {
                let want = start[j * k + p] as f64
                    + (0..rows)
                        .map(|i| g4[i * 4 + 1 + j] as f64 * x[i * k + p] as f64)
                        .sum::<f64>();
                let got = acc[j * k + p] as f64;
                assert!((got - want).abs() < 1e-3, "({j}, {p}): {got} vs {want}");
            }
        }
    }

    #[test]
    fn the_residual_forward_and_the_residual_gradient_add_their_terms() {
        // k spans several reduction blocks, so the epilogue must run once, at the end.
        let (m, k, n) = (31, 2 * KC + 7, 70);
        let x = values(m * k, 6);
        let w = values(n * k, 7);
        let bias = values(n, 8);
        let res = values(m * n, 9);
        let mut wt = vec![0.0; k * n];
        for j in 0..n {
            for p in 0..k {
                wt[p * n + j] = w[j * k + p];
            }
        }
        let base = reference(&x, m, k, &wt, n);
        let mut y = vec![0.0; m * n];
        linear_forward_residual(&x, m, k, &w, n, &bias, &res, true, &mut y);
        let mut z = vec![0.0; m * n];
        matmul_add(&x, m, k, &wt, n, &res, &mut z);
        for i in 0..m {
            for (j, &b) in bias.iter().enumerate() {
                let e = i * n + j;
                let want_y = (base[e] + b as f64 + res[e] as f64).max(0.0);
                let want_z = base[e] + res[e] as f64;
                assert!((y[e] as f64 - want_y).abs() < 1e-4, "residual ({i}, {j})");
                assert!((z[e] as f64 - want_z).abs() < 1e-4, "matmul_add ({i}, {j})");
            }
        }
    }

    #[test]
    fn the_forward_adds_its_term_and_clips() {
        let (m, k, n, group) = (45, 7, 19, 5);
        let x = values(m * k, 3);
        let w = values(n * k, 4);
        let mut wt = vec![0.0; k * n];
        for j in 0..n {
            for p in 0..k {
                wt[p * n + j] = w[j * k + p];
            }
        }
        let base = reference(&x, m, k, &wt, n);
        for mode in [
            Addend::None,
            Addend::Row,
            Addend::Group(group),
            Addend::Full,
        ] {
            let rows = match mode {
                Addend::None => 0,
                Addend::Row => 1,
                Addend::Group(g) => m.div_ceil(g),
                Addend::Full => m,
            };
            let add = values(rows * n, 5);
            for relu in [false, true] {
                let mut y = vec![0.0; m * n];
                linear_forward(&x, m, k, &w, n, &add, mode, relu, &mut y);
                for i in 0..m {
                    for j in 0..n {
                        let mut want = base[i * n + j];
                        if let Some(r) = mode.row(i) {
                            want += add[r * n + j] as f64;
                        }
                        if relu {
                            want = want.max(0.0);
                        }
                        let got = y[i * n + j] as f64;
                        assert!(
                            (got - want).abs() < 1e-4,
                            "{mode:?} relu {relu} ({i}, {j}): {got} vs {want}"
                        );
                    }
                }
            }
        }
    }
}
