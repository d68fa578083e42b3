//! Training-step benchmarks: rays per second, the step's effective FLOP rate, how many cores
//! were busy, and candle's own matmul rate at the same shapes for comparison. The CLI's
//! `nldf bench` writes the results as JSON and Markdown together with the machine, the
//! commit and the settings.

use std::time::Instant;

use candle_core::{Device, Tensor};
use nldf_core::host::cpu_seconds;
use serde::Serialize;

use crate::error::Result;
use crate::trainers::config::TeacherConfig;
use crate::trainers::data::TrainData;
use crate::trainers::teacher_trainer::TeacherRun;

/// The matrix products of one training step of a dense layer over `n` rows: forward
/// `[n, i] x [i, o]`, input gradient `[n, o] x [o, i]`, weight gradient `[o, n] x [n, i]`.
fn layer_products(n: usize, i: usize, o: usize) -> [(usize, usize, usize); 3] {
    [(n, i, o), (n, o, i), (o, n, i)]
}

/// Per-sample dense layers `(in, out)` of the teacher field, as its description lists them
/// ([`TeacherConfig::field_layers`], per-ray terms excluded).
pub fn teacher_sample_layers(cfg: &TeacherConfig) -> Vec<(usize, usize)> {
    cfg.field_layers()
        .iter()
        .filter(|l| !l.per_ray)
        .map(|l| (l.fan_in, l.fan_out))
        .collect()
}

/// Results of a training-step benchmark.
#[derive(Debug, Clone, Serialize)]
pub struct StepBench {
    pub model: String,
    pub batch_rays: usize,
    /// Rays that hit the head's bounds per step (only these reach the network), on average.
    pub hit_rays: f64,
    /// Samples per ray that the step trains on (forward and backward).
    pub samples_per_ray: usize,
    /// Samples per ray of a forward-only pass before it (the coarse pass that places
    /// importance samples; 0 without one).
    pub coarse_samples_per_ray: usize,
    pub steps: usize,
    pub seconds_per_step: f64,
    pub rays_per_s: f64,
    /// Forward FLOPs per step of the per-sample layers (2 per multiply-add).
    pub forward_gflop_per_step: f64,
    /// 3 x forward FLOPs (forward, input and weight gradients) of the trained samples, plus
    /// the forward FLOPs of the coarse pass, per second.
    pub effective_gflop_s: f64,
    /// CPU seconds per wall second during the timed steps.
    pub cores_busy: f64,
    /// candle's matmul alone on the step's own matrix shapes: their FLOPs over their time.
    pub candle_matmul_gflop_s: f64,
    /// `effective_gflop_s / candle_matmul_gflop_s`.
    pub fraction_of_candle_matmul: f64,
    /// nldf's own kernel ([`crate::kernels::matmul`]) alone on the same shapes: the
    /// ceiling of the fused step.
    pub kernel_matmul_gflop_s: f64,
    /// The machine's f32 register peak ([`register_peak_gflop_s`]), if measured.
    pub register_peak_gflop_s: Option<f64>,
    /// `effective_gflop_s / register_peak_gflop_s`.
    pub fraction_of_register_peak: Option<f64>,
}

/// Calls `f` once untimed, then repeatedly until 0.2 s have passed; returns the timed calls
/// and their seconds.
fn time_repeated(mut f: impl FnMut() -> Result<()>) -> Result<(usize, f64)> {
    f()?;
    let start = Instant::now();
    let mut reps = 0;
    while start.elapsed().as_secs_f64() < 0.2 {
        f()?;
        reps += 1;
    }
    Ok((reps, start.elapsed().as_secs_f64()))
}

/// GFLOP/s of `product(m, k, n)` over the given `(m, k, n)` products, each timed by
/// [`time_repeated`] after `prepare(m, k, n)` builds its operands.
fn products_rate<S>(
    products: &[(usize, usize, usize)],
    prepare: impl Fn(usize, usize, usize) -> Result<S>,
    product: impl Fn(&mut S) -> Result<()>,
) -> Result<f64> {
    let (mut flops, mut secs) = (0.0, 0.0);
    for &(m, k, n) in products {
        let mut operands = prepare(m, k, n)?;
        let (reps, s) = time_repeated(|| product(&mut operands))?;
        flops += 2.0 * (m * k * n) as f64 * reps as f64;
        secs += s;
    }
    Ok(flops / secs / 1e9)
}

/// Times candle's matmul on the given `(m, k, n)` products; returns GFLOP/s over all of
/// them.
pub fn candle_matmul_rate(products: &[(usize, usize, usize)]) -> Result<f64> {
    let ones = |r: usize, c: usize| Tensor::ones((r, c), candle_core::DType::F32, &Device::Cpu);
    products_rate(
        products,
        |m, k, n| Ok((ones(m, k)?, ones(k, n)?)),
        |(a, b)| Ok(a.matmul(b).map(|_| ())?),
    )
}

/// Times nldf's matmul kernel on the given `(m, k, n)` products like
/// [`candle_matmul_rate`].
pub fn kernel_matmul_rate(products: &[(usize, usize, usize)]) -> Result<f64> {
    products_rate(
        products,
        |m, k, n| {
            Ok((
                vec![1.0f32; m * k],
                vec![1.0f32; k * n],
                vec![0.0f32; m * n],
                m,
                k,
                n,
            ))
        },
        |(a, b, c, m, k, n)| {
            crate::kernels::matmul(a, *m, *k, b, *n, c);
            Ok(())
        },
    )
}

/// Independent multiply-add chains per thread in [`register_peak_gflop_s`]: enough to
/// cover the FMA latency times the FMA ports of current x86 cores.
const FMA_CHAINS: usize = 12;

/// Iterations of the FMA loop between clock reads.
const FMA_ROUNDS: usize = 1 << 20;

#[cfg(target_arch = "x86_64")]
mod fma_loop {
    use super::{FMA_CHAINS, FMA_ROUNDS};
    use std::arch::x86_64::*;

    /// `FMA_ROUNDS` rounds of `FMA_CHAINS` 16-lane multiply-adds; returns a value that
    /// depends on all of them (so that none is optimised away).
    ///
    /// # Safety
    /// The CPU supports AVX-512F.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn avx512() -> f32 {
        let (b, c) = (_mm512_set1_ps(0.999_999), _mm512_set1_ps(1e-7));
        let mut acc = [_mm512_setzero_ps(); FMA_CHAINS];
        for _ in 0..FMA_ROUNDS {
            for a in acc.iter_mut() {
                *a = _mm512_fmadd_ps(*a, b, c);
            }
        }
        acc.iter().map(|&a| _mm512_reduce_add_ps(a)).sum()
    }

    /// The same with 8-lane AVX2 multiply-adds.
    ///
    /// # Safety
    /// The CPU supports AVX2 and FMA.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn avx2() -> f32 {
        let (b, c) = (_mm256_set1_ps(0.999_999), _mm256_set1_ps(1e-7));
        let mut acc = [_mm256_setzero_ps(); FMA_CHAINS];
        for _ in 0..FMA_ROUNDS {
            for a in acc.iter_mut() {
                *a = _mm256_fmadd_ps(*a, b, c);
            }
        }
        let mut lanes = [0.0f32; 8];
        let mut sum = 0.0;
        for a in acc {
            // SAFETY: `lanes` holds 8 values.
            unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), a) };
            sum += lanes.iter().sum::<f32>();
        }
        sum
    }
}

/// The machine's register peak for f32: every rayon thread runs independent vector
/// multiply-add chains (AVX-512 where the CPU has it, else AVX2 with FMA) for about 0.2 s;
/// returns their FLOPs over the wall time. The ceiling no matrix product can pass. `None`
/// on CPUs without FMA vectors.
pub fn register_peak_gflop_s() -> Option<f64> {
    #[cfg(target_arch = "x86_64")]
    {
        let lanes = if std::arch::is_x86_feature_detected!("avx512f") {
            16
        } else if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            8
        } else {
            return None;
        };
        let round = || {
            // SAFETY: the features each loop needs were detected above.
            unsafe {
                if lanes == 16 {
                    fma_loop::avx512()
                } else {
                    fma_loop::avx2()
                }
            }
        };
        std::hint::black_box(round());
        let start = Instant::now();
        let mut loops = 0usize;
        while start.elapsed().as_secs_f64() < 0.2 {
            let sums = rayon::broadcast(|_| std::hint::black_box(round()));
            loops += sums.len();
        }
        let flops = (loops * FMA_ROUNDS * FMA_CHAINS * lanes * 2) as f64;
        Some(flops / start.elapsed().as_secs_f64() / 1e9)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        None
    }
}

/// Runs `warmup` untimed calls of `step`, then `steps` timed ones; `step` returns how many
/// rays it processed. Returns the timed rays, wall seconds and cores busy.
fn timed_steps(
    warmup: usize,
    steps: usize,
    mut step: impl FnMut() -> Result<usize>,
) -> Result<(usize, f64, f64)> {
    for _ in 0..warmup {
        step()?;
    }
    let cpu0 = cpu_seconds();
    let start = Instant::now();
    let mut rays = 0;
    for _ in 0..steps {
        rays += step()?;
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu = cpu_seconds()
        .zip(cpu0)
        .map(|(b, a)| b - a)
        .unwrap_or(f64::NAN);
    Ok((rays, wall, cpu / wall))
}

/// What a timed run of training steps measured, before the rates are worked out.
struct Timed {
    model: String,
    batch_rays: usize,
    /// Rays per step that reached the network.
    rays_per_step: f64,
    samples_per_ray: usize,
    coarse_samples_per_ray: usize,
    steps: usize,
    wall: f64,
    cores_busy: f64,
    /// The dense layers `(in, out)` every row of the step passes through.
    layers: Vec<(usize, usize)>,
}

impl Timed {
    /// The benchmark's rates, with the matmul rates at the step's own shapes.
    fn report(self) -> Result<StepBench> {
        let rows = (self.rays_per_step * self.samples_per_ray as f64).round() as usize;
        let fwd_flops: f64 = self
            .layers
            .iter()
            .map(|&(i, o)| 2.0 * (rows * i * o) as f64)
            .sum();
        let products: Vec<_> = self
            .layers
            .iter()
            .flat_map(|&(i, o)| layer_products(rows, i, o))
            .collect();
        let matmul = candle_matmul_rate(&products)?;
        let kernel = kernel_matmul_rate(&products)?;
        let peak = register_peak_gflop_s();
        let per_step = self.wall / self.steps.max(1) as f64;
        let coarse_flops =
            fwd_flops * self.coarse_samples_per_ray as f64 / self.samples_per_ray.max(1) as f64;
        let effective = (3.0 * fwd_flops + coarse_flops) / per_step / 1e9;
        Ok(StepBench {
            model: self.model,
            batch_rays: self.batch_rays,
            hit_rays: self.rays_per_step,
            samples_per_ray: self.samples_per_ray,
            coarse_samples_per_ray: self.coarse_samples_per_ray,
            steps: self.steps,
            seconds_per_step: per_step,
            rays_per_s: self.batch_rays as f64 / per_step,
            forward_gflop_per_step: fwd_flops / 1e9,
            effective_gflop_s: effective,
            cores_busy: self.cores_busy,
            candle_matmul_gflop_s: matmul,
            fraction_of_candle_matmul: effective / matmul,
            kernel_matmul_gflop_s: kernel,
            register_peak_gflop_s: peak,
            fraction_of_register_peak: peak.map(|p| effective / p),
        })
    }
}

/// Times `steps` teacher training steps after `warmup` untimed ones.
pub fn bench_teacher_step(
    run: &mut TeacherRun,
    data: &TrainData,
    warmup: usize,
    steps: usize,
) -> Result<StepBench> {
    let (hits, wall, cores_busy) = timed_steps(warmup, steps, || {
        run.train_step(data)?;
        Ok(run.last_hit_rays)
    })?;
    let cfg = &run.model.cfg;
    Timed {
        model: if cfg.model.n_importance > 0 {
            format!(
                "{} {}x{} ({} + {} samples/ray)",
                cfg.model.kind_name(),
                cfg.model.depth,
                cfg.model.width,
                cfg.model.n_samples,
                cfg.model.n_importance
            )
        } else {
            format!(
                "{} {}x{} ({} samples/ray)",
                cfg.model.kind_name(),
                cfg.model.depth,
                cfg.model.width,
                cfg.model.n_samples
            )
        },
        batch_rays: cfg.train.batch_rays,
        rays_per_step: hits as f64 / steps.max(1) as f64,
        samples_per_ray: cfg.model.n_samples + cfg.model.n_importance,
        coarse_samples_per_ray: if cfg.model.n_importance > 0 {
            cfg.model.n_samples
        } else {
            0
        },
        steps,
        wall,
        cores_busy,
        layers: teacher_sample_layers(&cfg.model),
    }
    .report()
}

/// Times `steps` student training steps after `warmup` untimed ones. The run must be
/// prepared ([`crate::trainers::student_trainer::StudentRun::prepare`]). Pool beams count as rays
/// (in `hit_rays` and the FLOPs; `rays_per_s` counts the main batch only): they pass
/// through the network like the others.
pub fn bench_student_step(
    run: &mut crate::trainers::student_trainer::StudentRun,
    data: &TrainData,
    warmup: usize,
    steps: usize,
) -> Result<StepBench> {
    let batch = run.model.cfg.train.batch_rays;
    let (rays, wall, cores_busy) = timed_steps(warmup, steps, || {
        Ok(batch + run.train_step(data)?.pool_beams)
    })?;
    let m = &run.model.cfg.model;
    Timed {
        model: format!("student {}x{} (M = {})", m.depth, m.width, m.segments),
        batch_rays: batch,
        rays_per_step: rays as f64 / steps.max(1) as f64,
        samples_per_ray: 1,
        coarse_samples_per_ray: 0,
        steps,
        wall,
        cores_busy,
        layers: student_layers(m),
    }
    .report()
}

/// Dense layers `(in, out)` of the student, as its description lists them
/// (`nldf_core::student_network::MlpLayout`).
pub fn student_layers(cfg: &crate::networks::student::StudentConfig) -> Vec<(usize, usize)> {
    nldf_core::student_network::MlpLayout::of(cfg)
        .layers()
        .iter()
        .map(|l| (l.fan_in, l.fan_out))
        .collect()
}

/// One way to compute the positional encoding's sines and cosines, timed and checked.
#[derive(Debug, Clone, serde::Serialize)]
pub struct EncodingVariant {
    /// What it computes.
    pub name: String,
    /// Median nanoseconds per encoded input value (all `L` octaves, both functions), one
    /// thread.
    pub ns_per_value: f64,
    /// Largest difference from the exact `sin(2^l x)` / `cos(2^l x)` (f64) over coordinates
    /// in the scene's range, `|x| <= scene_range`.
    pub max_error_scene: f64,
    /// The same over `|x| <= MAX_COORD`.
    pub max_error_clamp: f64,
}

/// The positional encoding's variants side by side (`nldf bench encoding`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct EncodingBench {
    /// Frequencies L.
    pub n_freqs: usize,
    /// Values per call (a beam: 3 K).
    pub values_per_call: usize,
    /// The coordinate range of the scene the first error column covers.
    pub scene_range: f32,
    pub variants: Vec<EncodingVariant>,
}

/// Sines and cosines `[L][n]` of `2^l x` by one of the variants: 0 direct f32 `sin_cos` per
/// octave, 1 the f32 double-angle climb, 2 nldf's encoding (f64 climb).
fn encode_variant(variant: usize, values: &[f32], n_freqs: usize, out: &mut [f32]) {
    use nldf_core::encoding::{MAX_COORD, encode_positions};
    let n = values.len();
    match variant {
        0 => {
            for l in 0..n_freqs {
                let scale = (1u32 << l) as f32;
                for (i, &v) in values.iter().enumerate() {
                    let (s, c) = (scale * v.clamp(-MAX_COORD, MAX_COORD)).sin_cos();
                    out[n + 2 * n * l + i] = s;
                    out[2 * n + 2 * n * l + i] = c;
                }
            }
        }
        1 => {
            for (i, &v) in values.iter().enumerate() {
                let (mut s, mut c) = v.clamp(-MAX_COORD, MAX_COORD).sin_cos();
                for l in 0..n_freqs {
                    out[n + 2 * n * l + i] = s;
                    out[2 * n + 2 * n * l + i] = c;
                    let p = s * c;
                    (s, c) = (p + p, (c - s) * (c + s));
                }
            }
        }
        _ => encode_positions(values, n_freqs, out),
    }
}

/// Times and checks the encoding's variants on beam-sized inputs (48 values, `n_freqs`
/// octaves): the direct `sin(2^l x)` in f32, the double-angle climb in f32 (nldf's
/// encoding before this one) and nldf's f64 climb.
pub fn bench_encoding(n_freqs: usize, scene_range: f32, reps: usize) -> EncodingBench {
    use nldf_core::encoding::{MAX_COORD, encoded_len};
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let n = 48;
    let width = encoded_len(n, n_freqs);
    let sample = |rng: &mut rand_chacha::ChaCha8Rng, range: f32| -> Vec<f32> {
        (0..n).map(|_| rng.random_range(-range..range)).collect()
    };
    let names = [
        "direct sin(2^l x) in f32, per octave",
        "double-angle climb in f32",
        "double-angle climb in f64, rounded once (nldf)",
    ];
    let variants = (0..3)
        .map(|variant| {
            let mut out = vec![0.0f32; width];
            let mut worst = [0.0f64; 2];
            for (slot, range) in [scene_range, MAX_COORD].into_iter().enumerate() {
                for _ in 0..2000 {
                    let values = sample(&mut rng, range);
                    encode_variant(variant, &values, n_freqs, &mut out);
                    for l in 0..n_freqs {
                        for (i, &x) in values.iter().enumerate() {
                            let arg = (1u64 << l) as f64 * x as f64;
                            let ds = (out[n + 2 * n * l + i] as f64 - arg.sin()).abs();
                            let dc = (out[2 * n + 2 * n * l + i] as f64 - arg.cos()).abs();
                            worst[slot] = worst[slot].max(ds).max(dc);
                        }
                    }
                }
            }
            let inputs: Vec<Vec<f32>> = (0..1024).map(|_| sample(&mut rng, scene_range)).collect();
            let times: Vec<f64> = (0..reps.max(1))
                .map(|_| {
                    let started = Instant::now();
                    for values in &inputs {
                        encode_variant(variant, std::hint::black_box(values), n_freqs, &mut out);
                        std::hint::black_box(&out);
                    }
                    started.elapsed().as_secs_f64() * 1e9 / (inputs.len() * n) as f64
                })
                .collect();
            EncodingVariant {
                name: names[variant].to_string(),
                ns_per_value: nldf_core::stats::median(&times),
                max_error_scene: worst[0],
                max_error_clamp: worst[1],
            }
        })
        .collect();
    EncodingBench {
        n_freqs,
        values_per_call: n,
        scene_range,
        variants,
    }
}
