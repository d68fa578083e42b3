//! The teacher: compositing against the f64 reference, the audio encoder and sampler shapes,
//! a tiny training run that learns, and a resume that continues bit for bit.

use std::sync::atomic::AtomicBool;

use crate::util::{tiny_run_config, tiny_scene};
use candle_core::{Device, Tensor};
use glam::Vec3;
use nldf_core::bounds::Bounds;
use nldf_core::composite::composite_f64;
use nldf_core::rays::Rays;
use nldf_train::networks::nn::{conv1d, new_varmap};
use nldf_train::networks::render::composite;
use nldf_train::networks::sampler::{sample_importance, sample_stratified};
use nldf_train::trainers::config::{TeacherConfig, TeacherRunConfig};
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::teacher_trainer::TeacherRun;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn candle_compositing_matches_the_f64_reference() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (n_rays, n_samples) = (64, 24);
    let mut sigma = vec![0.0f32; n_rays * n_samples];
    let mut delta = vec![0.0f32; n_rays * n_samples];
    let mut rgb = vec![0.0f32; n_rays * n_samples * 3];
    let mut bg = vec![0.0f32; n_rays * 3];
    for r in 0..n_rays {
        for s in 0..n_samples {
            let k = r * n_samples + s;
            // Some rays are nearly empty, some hit an opaque wall, some have negative raw
            // densities that the ReLU removes.
            sigma[k] = match r % 4 {
                0 => rng.random_range(0.0..0.5),
                1 => rng.random_range(-5.0..50.0),
                2 => {
                    if s == 7 {
                        1e6
                    } else {
                        rng.random_range(0.0..5.0)
                    }
                }
                _ => rng.random_range(0.0..200.0),
            };
            delta[k] = rng.random_range(0.001..0.05);
            for c in 0..3 {
                rgb[3 * k + c] = rng.random();
            }
        }
        for c in 0..3 {
            bg[3 * r + c] = rng.random();
        }
    }
    let t = |v: &[f32], shape: &[usize]| Tensor::from_slice(v, shape, &Device::Cpu).unwrap();
    let out = composite(
        &t(&sigma, &[n_rays, n_samples]),
        &t(&delta, &[n_rays, n_samples]),
        &t(&rgb, &[n_rays, n_samples, 3]),
        &t(&bg, &[n_rays, 3]),
    )
    .unwrap();
    let color: Vec<Vec<f32>> = out.color.to_vec2().unwrap();
    let weights: Vec<Vec<f32>> = out.weights.to_vec2().unwrap();
    let left: Vec<f32> = out.transmittance.to_vec1().unwrap();
    let mut worst = 0.0f64;
    for r in 0..n_rays {
        let d = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
        let range = r * n_samples..(r + 1) * n_samples;
        let colors: Vec<[f64; 3]> = range
            .clone()
            .map(|k| {
                [
                    rgb[3 * k] as f64,
                    rgb[3 * k + 1] as f64,
                    rgb[3 * k + 2] as f64,
                ]
            })
            .collect();
        let reference = composite_f64(
            &d(&sigma[range.clone()]),
            &d(&delta[range.clone()]),
            &vec![0.0; n_samples],
            &colors,
        );
        let t_left = 1.0 - reference.opacity;
        for c in 0..3 {
            let want = reference.color[c] + t_left * bg[3 * r + c] as f64;
            worst = worst.max((color[r][c] as f64 - want).abs());
        }
        for (w, want) in weights[r].iter().zip(&reference.weights) {
            worst = worst.max((*w as f64 - want).abs());
        }
        worst = worst.max((left[r] as f64 - t_left).abs());
    }
    println!("compositing: worst difference from the f64 reference {worst:e}");
    // Measured worst about 2.1e-7.
    assert!(
        worst < 1e-6,
        "largest difference from the f64 reference: {worst:e}"
    );
}

#[test]
fn compositing_stays_finite_for_extreme_densities_and_spacings() {
    let sigma = [0.0f32, 1e30, f32::MAX, 1e-30, 5.0, 1e10];
    let delta = [1e10f32, 1e10, 1.0, 1e10, 1e-30, 1e10];
    let t = |v: &[f32], shape: &[usize]| Tensor::from_slice(v, shape, &Device::Cpu).unwrap();
    let out = composite(
        &t(&sigma, &[1, 6]),
        &t(&delta, &[1, 6]),
        &t(&[0.5f32; 18], &[1, 6, 3]),
        &t(&[0.25f32; 3], &[1, 3]),
    )
    .unwrap();
    let color: Vec<f32> = out.color.flatten_all().unwrap().to_vec1().unwrap();
    let weights: Vec<f32> = out.weights.flatten_all().unwrap().to_vec1().unwrap();
    assert!(
        color.iter().chain(&weights).all(|v| v.is_finite()),
        "{color:?} {weights:?}"
    );
    // The second sample is opaque: it takes everything.
    // Measured worst 0.
    assert_eq!(weights[1], 1.0);
    assert_eq!(color, [0.5; 3]);
}

#[test]
fn im2col_convolution_matches_candles_forward() {
    let (varmap, vb) = new_varmap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for (stride, padding, len) in [(2usize, 1usize, 16usize), (2, 1, 2), (1, 1, 8), (2, 1, 1)] {
        let conv = conv1d(5, 4, 3, stride, padding, vb.pp(format!("c{stride}{len}"))).unwrap();
        let x: Vec<f32> = (0..2 * 5 * len)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let x = Tensor::from_vec(x, (2, 5, len), &Device::Cpu).unwrap();
        let ours: Vec<f32> = conv
            .forward(&x)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        let theirs = x
            .conv1d(&conv.weight, padding, stride, 1, 1)
            .unwrap()
            .broadcast_add(&conv.bias.reshape((1, 4, 1)).unwrap())
            .unwrap();
        let theirs: Vec<f32> = theirs.flatten_all().unwrap().to_vec1().unwrap();
        assert_eq!(ours.len(), theirs.len(), "stride {stride}, length {len}");
        // Measured worst 0: the same products summed in the same order.
        assert_eq!(ours, theirs, "stride {stride}, length {len}");
    }
    drop(varmap);
}

#[test]
fn samples_lie_inside_the_bounds_and_misses_are_skipped() {
    let bounds = Bounds {
        lo: Vec3::splat(-0.1),
        hi: Vec3::splat(0.1),
    };
    let mut rays = Rays::with_capacity(3);
    rays.push(Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.0)); // through the box
    rays.push(Vec3::new(0.5, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.0)); // beside it
    rays.push(Vec3::new(0.0, 0.05, 1.0), Vec3::new(0.0, 0.0, -2.0)); // un-normalised
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let s = sample_stratified(&rays, &bounds, 0.5, 2.0, 8, Some(&mut rng));
    assert_eq!(s.hit, vec![0, 2]);
    for (h, &r) in s.hit.iter().enumerate() {
        let d = rays.direction(r);
        let (t0, t1) = bounds.intersect(rays.origin(r), d, 0.5, 2.0).unwrap();
        let t = &s.t_vals[h * 8..(h + 1) * 8];
        assert!(t.windows(2).all(|w| w[0] <= w[1]) && t[0] >= t0 && t[7] <= t1);
        // The spacings run from the first sample to the exit, in world units.
        let total: f32 = s.deltas[h * 8..(h + 1) * 8].iter().sum();
        // Measured worst 0.
        assert_eq!(total, (t1 - t[0]) * d.length());
        for k in 0..8 {
            let p = Vec3::from_slice(&s.points[3 * (h * 8 + k)..]);
            assert!(p.cmpge(bounds.lo - 1e-5).all() && p.cmple(bounds.hi + 1e-5).all());
        }
    }
}

#[test]
fn a_tiny_teacher_learns_the_tiny_scene() {
    crate::util::assert_teacher_learns("teacher", tiny_run_config(200));
}

#[test]
fn resuming_from_a_checkpoint_gives_the_identical_next_step() {
    // Past att_start, so that AudioAttNet's weights and moments are in the state too.
    crate::util::assert_teacher_resumes_bit_for_bit(tiny_run_config(20));
}

#[test]
fn training_writes_a_log_and_a_checkpoint_and_stops_cleanly() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = tiny_run_config(12);
    cfg.train.log_every = 4;
    cfg.train.val_every = 6;
    let mut run = TeacherRun::create(dir.path(), cfg, &data).unwrap();
    let mut events = 0;
    let scores = run
        .train(&data, &AtomicBool::new(false), &mut |_| events += 1)
        .unwrap()
        .unwrap();
    assert!(scores.psnr.is_finite() && events >= 12);
    let log = nldf_train::trainers::log::read_log(&dir.path().join(nldf_core::run_files::LOG_FILE))
        .unwrap();
    assert_eq!(
        log.iter().map(|r| r.step).collect::<Vec<_>>(),
        vec![4, 6, 8, 12]
    );
    assert!(log[1].val_psnr.is_some() && log[0].val_psnr.is_none());
    // A stop request leaves a checkpoint that opens at the step it stopped at.
    let mut run = TeacherRun::open(dir.path()).unwrap();
    run.model.cfg.train.iters = 30;
    assert!(
        run.train(&data, &AtomicBool::new(true), &mut |_| {})
            .unwrap()
            .is_none()
    );
    assert_eq!(TeacherRun::open(dir.path()).unwrap().model.step, 12);
    for f in [
        "model.safetensors",
        "train_state.safetensors",
        "config.json",
        "training_curve.png",
    ] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
    assert!(
        std::fs::read_dir(dir.path()).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .ends_with(".tmp"))
    );
}

#[test]
fn the_fused_field_matches_plain_candle_ops_forward_and_backward() {
    use candle_core::Var;
    use nldf_train::networks::field::teacher_field;
    use nldf_train::networks::nn::{init_seeded, sorted_vars};
    for (cfg, n_rays, n_samples) in [
        (TeacherConfig::tiny(), 7, 5),
        (TeacherConfig::small(), 13, 9),
        // Many blocks of whole rays, the last one partial, over several spans.
        (TeacherConfig::small(), 200, 9),
        // The grid teacher's network: its points (the grid's encoding) get a gradient too.
        (TeacherConfig::grid(), 200, 9),
    ] {
        let (varmap, vb) = new_varmap();
        let field = teacher_field(&cfg, vb).unwrap();
        init_seeded(&varmap, 11).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut rand =
            |n: usize| -> Vec<f32> { (0..n).map(|_| rng.random_range(-1.0..1.0)).collect() };
        let n = n_rays * n_samples;
        let dev = Device::Cpu;
        let points = Var::from_vec(rand(n * cfg.pos_dim()), (n, cfg.pos_dim()), &dev).unwrap();
        let codes =
            Var::from_vec(rand(n_rays * cfg.audio.dim), (n_rays, cfg.audio.dim), &dev).unwrap();
        let dirs =
            Var::from_vec(rand(n_rays * cfg.dir_dim()), (n_rays, cfg.dir_dim()), &dev).unwrap();
        let wd = Tensor::from_vec(rand(n), (n_rays, n_samples), &dev).unwrap();
        let wc = Tensor::from_vec(rand(n * 3), (n_rays, n_samples, 3), &dev).unwrap();
        let run = |fused: bool| {
            let (d, c) = if fused {
                field
                    .forward(&points, &codes, &dirs, n_samples, true)
                    .unwrap()
            } else {
                field
                    .forward_reference(&points, &codes, &dirs, n_samples)
                    .unwrap()
            };
            let loss = ((&d * &wd).unwrap().sum_all().unwrap()
                + (&c * &wc).unwrap().sum_all().unwrap())
            .unwrap();
            let grads = loss.backward().unwrap();
            let mut out: Vec<(String, Vec<f32>)> = vec![
                (
                    "density".into(),
                    d.flatten_all().unwrap().to_vec1().unwrap(),
                ),
                ("rgb".into(), c.flatten_all().unwrap().to_vec1().unwrap()),
            ];
            for (name, var) in sorted_vars(&varmap).unwrap() {
                let g = grads
                    .get(var.as_tensor())
                    .map(|g| g.flatten_all().unwrap().to_vec1().unwrap());
                out.push((format!("grad {name}"), g.unwrap_or_default()));
            }
            let mut inputs = vec![("codes", &codes), ("dirs", &dirs)];
            if cfg.grid.is_some() {
                inputs.push(("points", &points));
            }
            for (name, var) in inputs {
                let g = grads.get(var.as_tensor()).unwrap();
                out.push((
                    format!("grad {name}"),
                    g.flatten_all().unwrap().to_vec1().unwrap(),
                ));
            }
            out
        };
        let (fused, plain) = (run(true), run(false));
        // Without a backward to come, the op keeps nothing and computes the same values.
        let (d, c) = field
            .forward(&points, &codes, &dirs, n_samples, false)
            .unwrap();
        assert_eq!(
            d.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
            fused[0].1
        );
        assert_eq!(
            c.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
            fused[1].1
        );
        let mut worst = 0f32;
        for ((name, a), (_, b)) in fused.iter().zip(&plain) {
            assert_eq!(a.len(), b.len(), "{name}");
            assert!(!a.is_empty(), "{name} has no gradient");
            let scale = b.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
            for (x, y) in a.iter().zip(b) {
                worst = worst.max((x - y).abs() / scale.max(1.0));
                // Measured worst about 5.6e-6 of the largest gradient.
                assert!(
                    (x - y).abs() <= 3e-5 * scale.max(1.0),
                    "{name}: fused {x} vs plain {y}"
                );
            }
        }
        println!("fused field: gradients differ by {worst:e} of the largest");
    }
}

#[test]
fn importance_samples_gather_where_the_weight_is() {
    let bounds = Bounds {
        lo: Vec3::splat(-0.1),
        hi: Vec3::splat(0.1),
    };
    let mut rays = Rays::with_capacity(2);
    rays.push(Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.0));
    rays.push(Vec3::new(0.02, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.5));
    let coarse = sample_stratified(&rays, &bounds, 0.5, 2.0, 16, None::<&mut ChaCha8Rng>);
    // All the weight on coarse sample 10 of each ray.
    let mut weights = vec![0.0f32; 2 * 16];
    weights[10] = 1.0;
    weights[16 + 10] = 1.0;
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for jitter in [false, true] {
        let rng: Option<&mut dyn rand::RngCore> = if jitter { Some(&mut rng) } else { None };
        let fine = sample_importance(&rays, &coarse, &weights, 32, rng);
        assert_eq!(fine.n_samples, 48);
        assert_eq!(fine.hit, coarse.hit);
        for (h, &r) in fine.hit.iter().enumerate() {
            let (t0, t1) = bounds
                .intersect(rays.origin(r), rays.direction(r), 0.5, 2.0)
                .unwrap();
            let t = &fine.t_vals[h * 48..(h + 1) * 48];
            assert!(t.windows(2).all(|w| w[0] <= w[1]), "not sorted: {t:?}");
            assert!(t[0] >= t0 - 1e-6 && t[47] <= t1 + 1e-6);
            // The bin of coarse sample 10 lies between the midpoints around it.
            let c = &coarse.t_vals[h * 16..(h + 1) * 16];
            let (lo, hi) = (0.5 * (c[9] + c[10]), 0.5 * (c[10] + c[11]));
            let inside = t
                .iter()
                .filter(|&&x| x >= lo - 1e-6 && x <= hi + 1e-6)
                .count();
            // 32 draws nearly all land there, plus the coarse sample itself.
            assert!(inside >= 30, "only {inside} samples in the heavy bin");
            let total: f32 = fine.deltas[h * 48..(h + 1) * 48].iter().sum();
            let d = rays.direction(r).length();
            // Measured worst 0.
            assert_eq!(total, (t1 - t[0]) * d);
        }
    }
}

#[test]
fn a_teacher_with_importance_samples_trains_and_renders() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = tiny_run_config(40);
    cfg.model.n_importance = 8;
    let mut run = TeacherRun::create(dir.path(), cfg, &data).unwrap();
    let losses: Vec<f64> = (0..40).map(|_| run.train_step(&data).unwrap().0).collect();
    assert!(losses.iter().all(|l| l.is_finite()));
    assert!(losses[35..].iter().sum::<f64>() < losses[..5].iter().sum::<f64>());
    let frame = &data.dataset.val[0];
    let img = run.model.render_frame(&data, frame).unwrap();
    assert!(
        img.data
            .iter()
            .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
    );
}

/// A tiny teacher trained `steps` steps on the tiny scene (rendering without early
/// termination, so that every path sees every sample), with the rays and audio code of the
/// first validation frame.
struct TrainedTeacher {
    _dir: tempfile::TempDir,
    data: TrainData,
    run: TeacherRun,
    rays: Rays,
    code: Tensor,
}

fn trained_teacher(mut cfg: TeacherRunConfig, steps: usize) -> TrainedTeacher {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    cfg.model.min_transmittance = 0.0;
    let mut run = TeacherRun::create(dir.path(), cfg, &data).unwrap();
    for _ in 0..steps {
        run.train_step(&data).unwrap();
    }
    let frame = &data.dataset.val[0];
    let rays = nldf_core::rays::rays_for_image(&data.dataset.camera(frame));
    let code = run.model.audio_codes(&data, &[frame.aud_id]).unwrap();
    TrainedTeacher {
        _dir: dir,
        data,
        run,
        rays,
        code,
    }
}

#[test]
fn segment_targets_sum_to_the_teachers_pixel() {
    let TrainedTeacher {
        data,
        run,
        rays,
        code,
        ..
    } = trained_teacher(tiny_run_config(30), 30);
    let ds = &data.dataset;
    let bg = &ds.background.data;
    let t = &run.model.teacher;
    let pixels = t
        .render_eval(
            &rays,
            bg,
            &code,
            &data.head_range(),
            t.cfg.min_transmittance,
        )
        .unwrap();
    for m in [1usize, 4, 5] {
        // The background stays out of the segments: the segments plus (1 - opacity) times
        // the background are the pixel, the opacity lies in [0, 1], and a ray that misses
        // the bounds is all zeros.
        let w = 3 * m + 1;
        let seg = t
            .segment_targets(&rays, &code, &data.head_range(), m)
            .unwrap();
        assert_eq!(seg.len(), rays.len() * w);
        let (mut worst, mut covered, mut missed) = (0.0f32, 0, 0);
        for r in 0..rays.len() {
            let t = &seg[r * w..(r + 1) * w];
            let alpha = t[3 * m];
            assert!((0.0..=1.0).contains(&alpha), "ray {r}: opacity {alpha}");
            covered += usize::from(alpha > 0.01);
            missed += usize::from(t.iter().all(|&v| v == 0.0));
            for c in 0..3 {
                let sum: f32 = (0..m).map(|i| t[i * 3 + c]).sum();
                let pixel = sum + (1.0 - alpha) * bg[3 * r + c];
                worst = worst.max((pixel - pixels[3 * r + c]).abs());
            }
        }
        println!("M = {m}: segments and opacity miss the pixel by {worst:e}");
        // Measured worst about 1.8e-7.
        assert!(
            worst < 1e-6,
            "M = {m}: segments and opacity miss the pixel by {worst}"
        );
        // With several segments, a head ray's colour is spread over them.
        if m > 1 {
            let spread = (0..rays.len())
                .any(|r| (0..m - 1).any(|i| (0..3).any(|c| seg[r * w + i * 3 + c] > 0.05)));
            assert!(spread, "M = {m}: every colour sits in the last segment");
        }
        assert!(covered > 0, "M = {m}: no ray is covered by the head");
        assert!(missed > 0, "M = {m}: every ray met the head's bounds");
    }
}

/// With importance samples the merged samples crowd where the density is; Eq. 5's segments
/// still cut each ray's span into equal t-intervals. The teacher's targets must equal an
/// f64 reference built from its own samples and field outputs, segment by t-interval.
#[test]
fn importance_sampled_segment_targets_follow_t_intervals() {
    use nldf_core::composite::{composite_f64, segment_colors_f64};
    use nldf_train::networks::teacher::encode_vectors;
    let mut cfg = tiny_run_config(120);
    cfg.model.n_samples = 8;
    cfg.model.n_importance = 24;
    let TrainedTeacher {
        data,
        run,
        rays,
        code,
        ..
    } = trained_teacher(cfg, 120);
    let ds = &data.dataset;
    let t = &run.model.teacher;
    let m = 4;
    let w = 3 * m + 1;
    let seg = t
        .segment_targets(&rays, &code, &data.head_range(), m)
        .unwrap();
    // The reference: the same samples and field outputs, composited and split in f64.
    let codes_of = |hit: &[usize]| code.broadcast_as((hit.len(), code.dim(1)?))?.contiguous();
    let samples = t
        .sample(&rays, &data.bounds, ds.near, ds.far, None, &codes_of)
        .unwrap();
    let s = samples.n_samples;
    assert_eq!(s, 8 + 24);
    let n_hit = samples.hit.len();
    assert!(n_hit > 50, "{n_hit} rays hit the head");
    let points = encode_vectors(&samples.points, t.cfg.pos_freqs)
        .tensor()
        .unwrap();
    let dirs = encode_vectors(&samples.view_dirs, t.cfg.dir_freqs)
        .tensor()
        .unwrap();
    let codes = codes_of(&samples.hit).unwrap();
    let (densities, colors) = t.field.forward(&points, &codes, &dirs, s, false).unwrap();
    let densities: Vec<f32> = densities.flatten_all().unwrap().to_vec1().unwrap();
    let colors: Vec<f32> = colors.flatten_all().unwrap().to_vec1().unwrap();
    let (mut worst, mut moved) = (0.0f64, 0usize);
    for h in 0..n_hit {
        let r = samples.hit[h];
        let f = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
        let t_vals = f(&samples.t_vals[h * s..(h + 1) * s]);
        let rgb: Vec<[f64; 3]> = colors[3 * s * h..3 * s * (h + 1)]
            .chunks_exact(3)
            .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64])
            .collect();
        let c = composite_f64(
            &f(&densities[h * s..(h + 1) * s]),
            &f(&samples.deltas[h * s..(h + 1) * s]),
            &t_vals,
            &rgb,
        );
        let (t0, t1) = samples.spans[h];
        let want = segment_colors_f64(&c.weights, &rgb, &t_vals, (t0 as f64, t1 as f64), m);
        for i in 0..m {
            for ch in 0..3 {
                worst = worst.max((seg[r * w + i * 3 + ch] as f64 - want[i][ch]).abs());
            }
        }
        worst = worst.max((seg[r * w + 3 * m] as f64 - c.opacity).abs());
        // Where the samples crowd, a split by count would put other samples in segment 0.
        let by_count = (0..s / m).map(|k| c.weights[k]).sum::<f64>().to_bits();
        let by_t = (0..s)
            .filter(|&k| {
                nldf_core::composite::segment_of(t_vals[k], (t0 as f64, t1 as f64), m) == 0
            })
            .map(|k| c.weights[k])
            .sum::<f64>()
            .to_bits();
        moved += usize::from(by_count != by_t);
    }
    println!("segment targets: worst difference from the t-interval reference {worst:e}");
    // Measured worst about 6.6e-8.
    assert!(
        worst < 5e-7,
        "segment targets miss the t-interval reference by {worst}"
    );
    assert!(
        moved > n_hit / 10,
        "importance samples changed the first segment of only {moved} of {n_hit} rays"
    );
}

/// The teacher's field is described once (`TeacherConfig::field_layers`): the candle
/// builder's weights are exactly the description's layers, name for name and shape for
/// shape, for AD-NeRF's shape, the small preset and the grid teacher; and the step
/// benchmark's per-sample layers are the description's, less the per-ray terms.
#[test]
fn the_teachers_field_follows_its_described_layers() {
    use std::collections::BTreeMap;

    use nldf_train::networks::field::teacher_field;
    use nldf_train::networks::nn::sorted_vars;
    use nldf_train::reports::bench::teacher_sample_layers;

    for (name, cfg) in [
        ("AD-NeRF", TeacherConfig::ad_nerf()),
        ("small", TeacherConfig::small()),
        ("grid", TeacherConfig::grid()),
    ] {
        let (varmap, vb) = new_varmap();
        teacher_field(&cfg, vb).unwrap();
        let built: BTreeMap<String, Vec<usize>> = sorted_vars(&varmap)
            .unwrap()
            .into_iter()
            .map(|(k, v)| (k, v.dims().to_vec()))
            .collect();
        let layers = cfg.field_layers();
        let mut described = BTreeMap::new();
        for l in &layers {
            described.insert(format!("{}.weight", l.name), vec![l.fan_out, l.fan_in]);
            if l.bias {
                described.insert(format!("{}.bias", l.name), vec![l.fan_out]);
            }
        }
        assert_eq!(
            built, described,
            "{name}: candle's field is not the description"
        );
        let per_sample: Vec<(usize, usize)> = layers
            .iter()
            .filter(|l| !l.per_ray)
            .map(|l| (l.fan_in, l.fan_out))
            .collect();
        assert_eq!(teacher_sample_layers(&cfg), per_sample, "{name}");
        // AD-NeRF's skip at layer 4 feeds the input in again at layer 5.
        if name == "AD-NeRF" {
            assert!(layers.iter().any(|l| l.name == "trunk.5.points"));
        }
    }
}
