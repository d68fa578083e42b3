//! The student: presets with the paper's depths and cost, and a forward whose segments sum to
//! the pixel (Eq. 7).

use candle_core::{Device, Tensor};
use nldf_train::networks::nn::new_varmap;
use nldf_train::networks::student::{StudentConfig, residual_mlp};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn the_student_presets_have_the_papers_depths_and_cost() {
    for (cfg, blocks) in [
        (StudentConfig::paper_d28(), 13),
        (StudentConfig::paper_d50(), 24),
        (StudentConfig::paper_d88(), 43),
    ] {
        assert_eq!(cfg.n_blocks(), blocks);
        assert_eq!(1 + 2 * cfg.n_blocks() + 1, cfg.depth);
        assert_eq!(cfg.input_dim(), 1008 + 64);
    }
    // About 11.8 MFLOP per ray at 88 x 256 (2 x 5.91 M multiply-adds).
    let flops = 2.0 * StudentConfig::paper_d88().macs_per_ray() as f64;
    assert!((flops / 1e6 - 11.8).abs() < 0.1, "{flops}");
    assert!(
        StudentConfig {
            depth: 7,
            ..StudentConfig::tiny()
        }
        .check()
        .is_err()
    );

    // An anchor must be finite: a NaN centre or an infinite distance is refused.
    for (centre, distance) in [([f32::NAN, 0.0, 0.0], 1.0), ([0.0; 3], f32::INFINITY)] {
        let mut bad = StudentConfig::tiny();
        bad.beam.anchor = Some(nldf_core::beam::BeamAnchor { centre, distance });
        let e = bad.check().unwrap_err().to_string();
        assert!(e.contains("model.beam.anchor"), "{e}");
    }
    let cfg = StudentConfig::tiny();
    let (varmap, vb) = new_varmap();
    let net = residual_mlp(&cfg, vb).unwrap();
    let n_params: usize = varmap.all_vars().iter().map(|v| v.elem_count()).sum();
    let w = cfg.width;
    // The output layer: 12 segment values and the opacity's logit.
    let expected = cfg.input_dim() * w + w + cfg.n_blocks() * 2 * (w * w + w) + w * 13 + 13;
    assert_eq!(n_params, expected);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let beams: Vec<f32> = (0..5 * cfg.beam.encoded_len())
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let codes: Vec<f32> = (0..5 * cfg.audio.dim)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let beams = Tensor::from_vec(beams, (5, cfg.beam.encoded_len()), &Device::Cpu).unwrap();
    let codes = Tensor::from_vec(codes, (5, cfg.audio.dim), &Device::Cpu).unwrap();
    let out = net.forward(&beams, &codes).unwrap();
    assert_eq!(out.segments.dims(), &[5, 4, 3]);
    let seg: Vec<Vec<Vec<f32>>> = out.segments.to_vec3().unwrap();
    let colour: Vec<Vec<f32>> = out.colour.to_vec2().unwrap();
    let alpha: Vec<Vec<f32>> = out.opacity.to_vec2().unwrap();
    let bg = Tensor::from_vec(vec![0.25f32; 15], (5, 3), &Device::Cpu).unwrap();
    let pix: Vec<Vec<f32>> = out.pixels(&bg).unwrap().to_vec2().unwrap();
    // Measured worst 0: the colour is the segments' sum and the pixel Eq. 7, to the bit.
    for r in 0..5 {
        let a = alpha[r][0];
        assert!(a > 0.0 && a < 1.0, "opacity {a}");
        for c in 0..3 {
            let sum: f32 = (0..4).map(|i| seg[r][i][c]).sum();
            assert_eq!(sum, colour[r][c]);
            // Eq. 7 over the background: colour + (1 - opacity) background.
            assert_eq!(sum + (1.0 - a) * 0.25, pix[r][c]);
        }
    }
}

/// The fused student op computes what the plain candle ops compute: outputs, every weight's
/// gradient and the audio codes' gradient.
#[test]
fn the_fused_student_matches_candle_ops_forward_and_backward() {
    let cfg = StudentConfig {
        width: 40,
        depth: 8,
        ..StudentConfig::tiny()
    };
    let (varmap, vb) = new_varmap();
    let net = residual_mlp(&cfg, vb).unwrap();
    nldf_train::networks::nn::init_seeded(&varmap, 3).unwrap();
    let n = 77;
    let mut rng = ChaCha8Rng::seed_from_u64(10);
    let mut random =
        |len: usize| -> Vec<f32> { (0..len).map(|_| rng.random_range(-1.0..1.0)).collect() };
    let beams = Tensor::from_vec(
        random(n * cfg.beam.encoded_len()),
        (n, cfg.beam.encoded_len()),
        &Device::Cpu,
    )
    .unwrap();
    let codes =
        candle_core::Var::from_vec(random(n * cfg.audio.dim), (n, cfg.audio.dim), &Device::Cpu)
            .unwrap();
    let probe = Tensor::from_vec(random(n * 12), (n, 4, 3), &Device::Cpu).unwrap();
    let probe_px = Tensor::from_vec(random(n * 3), (n, 3), &Device::Cpu).unwrap();
    let probe_bg = Tensor::from_vec(random(n * 3), (n, 3), &Device::Cpu).unwrap();
    let run = |fused: bool| {
        let out = if fused {
            net.forward_fused(&beams, codes.as_tensor(), true).unwrap()
        } else {
            net.forward(&beams, codes.as_tensor()).unwrap()
        };
        // The composited pixel reaches the opacity's output too.
        let px = out.pixels(&probe_bg).unwrap();
        let loss = ((&out.segments * &probe).unwrap().sum_all().unwrap()
            + (&px * &probe_px).unwrap().sqr().unwrap().sum_all().unwrap())
        .unwrap();
        let grads = loss.backward().unwrap();
        let mut named: Vec<(String, Vec<f32>)> = varmap
            .data()
            .lock()
            .unwrap()
            .iter()
            .map(|(k, v)| {
                (
                    k.clone(),
                    grads
                        .get(v.as_tensor())
                        .unwrap()
                        .flatten_all()
                        .unwrap()
                        .to_vec1()
                        .unwrap(),
                )
            })
            .collect();
        named.sort_by(|a, b| a.0.cmp(&b.0));
        named.push((
            "codes".into(),
            grads
                .get(codes.as_tensor())
                .unwrap()
                .flatten_all()
                .unwrap()
                .to_vec1()
                .unwrap(),
        ));
        (
            out.segments
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap(),
            named,
        )
    };
    let (out_f, grads_f) = run(true);
    let (out_r, grads_r) = run(false);
    let max_diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    let out_diff = max_diff(&out_f, &out_r);
    println!("fused student: outputs differ by {out_diff:e}");
    // Measured worst about 8.9e-8.
    assert!(out_diff < 5e-7, "outputs differ by {out_diff}");
    assert_eq!(grads_f.len(), 2 + 2 * 2 * cfg.n_blocks() + 2 + 1);
    let mut worst = 0f32;
    for ((name, gf), (_, gr)) in grads_f.iter().zip(&grads_r) {
        let scale = gr.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
        let d = max_diff(gf, gr);
        worst = worst.max(d / scale);
        // Measured worst about 2.1e-7 of the largest gradient.
        assert!(
            d / scale < 1e-6,
            "{name}: gradients differ by {d} (scale {scale})"
        );
    }
    println!("fused student: gradients differ by {worst:e} of the largest");
}

use crate::util::{assert_learned, tiny_run_config, tiny_scene};
use nldf_core::dataset::Split;
use nldf_train::trainers::config::{StudentRunConfig, StudentTrainConfig};
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::pool::{BeamPool, PoolEntry};
use nldf_train::trainers::student_trainer::StudentRun;
use nldf_train::trainers::teacher_trainer::{TeacherModel, TeacherRun};

fn entry(frame: u32, loss: f32) -> PoolEntry {
    PoolEntry {
        frame,
        pixel: frame * 10,
        loss,
    }
}

#[test]
fn the_pool_keeps_the_highest_loss_beams() {
    let mut pool = BeamPool::new(6);
    // 10 beams, the top 40 % (4) enter: losses 9, 8, 7, 6.
    let batch: Vec<PoolEntry> = (0..10).map(|i| entry(i, i as f32)).collect();
    assert_eq!(pool.offer(&batch, 0.4), 4);
    let mut held: Vec<f32> = pool.entries.iter().map(|e| e.loss).collect();
    held.sort_by(f32::total_cmp);
    assert_eq!(held, vec![6.0, 7.0, 8.0, 9.0]);
    // Next batch's top 4 are 20, 15, 5, 0.5: two fill the room, then 5 replaces nothing
    // (the easiest entry, 6, is harder) and neither does 0.5.
    let batch = vec![
        entry(20, 20.0),
        entry(21, 0.5),
        entry(22, 15.0),
        entry(23, 5.0),
        entry(24, 0.1),
    ];
    pool.offer(&batch, 0.8);
    let mut held: Vec<f32> = pool.entries.iter().map(|e| e.loss).collect();
    held.sort_by(f32::total_cmp);
    assert_eq!(held, vec![6.0, 7.0, 8.0, 9.0, 15.0, 20.0]);
    // A full pool: harder newcomers replace the easiest entries, so that the pool holds
    // the highest losses of old and new together (6.5 loses to 7 once 30 has taken 6's
    // place).
    let batch = vec![entry(30, 30.0), entry(31, 6.5), entry(32, 1.0)];
    assert_eq!(pool.offer(&batch, 1.0), 1);
    let mut held: Vec<f32> = pool.entries.iter().map(|e| e.loss).collect();
    held.sort_by(f32::total_cmp);
    assert_eq!(held, vec![7.0, 8.0, 9.0, 15.0, 20.0, 30.0]);
    // New losses of drawn entries overwrite the records.
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let drawn = pool.draw(3, &mut rng);
    assert_eq!(drawn.len(), 3);
    pool.update(&drawn, &[0.0, 0.0, 0.0]);
    assert!(pool.entries.iter().filter(|e| e.loss == 0.0).count() >= 1);
}

fn tiny_student_config(iters: usize) -> StudentRunConfig {
    StudentRunConfig {
        model: StudentConfig::tiny(),
        train: StudentTrainConfig {
            iters,
            batch_rays: 256,
            frames_per_batch: 2,
            lr: 3e-3,
            lr_decay_steps: iters,
            pool_batches: 4,
            pseudo_frames: 6,
            val_every: 0,
            val_frames: 2,
            checkpoint_every: 0,
            ..StudentTrainConfig::default()
        },
    }
}

/// A tiny teacher trained briefly on the tiny scene (shared by the student tests).
fn tiny_teacher(data: &TrainData) -> (tempfile::TempDir, TeacherRun) {
    let dir = tempfile::tempdir().unwrap();
    let mut teacher = TeacherRun::create(dir.path(), tiny_run_config(150), data).unwrap();
    for _ in 0..150 {
        teacher.train_step(data).unwrap();
    }
    (dir, teacher)
}

#[test]
fn a_tiny_distilled_student_learns_the_tiny_scene_and_its_pool_spares_the_audio_encoder() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let (_teacher_dir, teacher) = tiny_teacher(&data);
    let dir = tempfile::tempdir().unwrap();
    let mut run = StudentRun::create(
        dir.path(),
        tiny_student_config(150),
        &data,
        Some(&teacher.model),
    )
    .unwrap();
    run.prepare(&data, Some(&teacher.model), &mut |_, _| {})
        .unwrap();
    assert!(dir.path().join("targets.safetensors").is_file());
    assert!(dir.path().join("render.json").is_file());
    // The training frames, then 6 pseudo views, each with the teacher's colours of every
    // pixel whose ray meets the head.
    let n_train = data.dataset.frames(Split::Train).len();
    assert_eq!(run.views.len(), n_train + 6);
    assert!(run.views[..n_train].iter().all(|v| v.recorded));
    assert!(run.views[n_train..].iter().all(|v| !v.recorded));
    for (fb, t) in run.beams.iter().zip(&run.targets) {
        // 3 M colours and the opacity per pixel.
        assert_eq!(
            t.len(),
            (3 * run.model.cfg.model.segments + 1) * fb.pixels.len()
        );
    }
    assert!(run.beams[n_train..].iter().all(|fb| !fb.pixels.is_empty()));

    // Deferred, the pseudo views' targets come 2 per step while the student trains, and
    // end equal to those rendered up front; the cache is written once the last is done.
    {
        teacher.save().unwrap();
        let reopened = TeacherModel::open(_teacher_dir.path()).unwrap();
        let later = tempfile::tempdir().unwrap();
        let mut cfg = tiny_student_config(150);
        cfg.train.pseudo_per_step = 2;
        let mut deferred =
            StudentRun::create(later.path(), cfg, &data, Some(&teacher.model)).unwrap();
        deferred
            .prepare_deferred(&data, Some(reopened), &mut |_, _| {})
            .unwrap();
        assert_eq!(deferred.pending_pseudo_views(), 6);
        assert!(deferred.targets[n_train..].iter().all(Vec::is_empty));
        assert_eq!(deferred.targets[..n_train], run.targets[..n_train]);
        assert!(!later.path().join("targets.safetensors").exists());
        for left in [4, 2, 0] {
            deferred.train_step(&data).unwrap();
            assert_eq!(deferred.pending_pseudo_views(), left);
        }
        assert_eq!(deferred.targets, run.targets);
        assert!(later.path().join("targets.safetensors").is_file());
    }
    // The student's audio encoder starts as the teacher's.
    let vars_of = |varmap: &candle_nn::VarMap, prefix: &str| -> Vec<(String, Vec<f32>)> {
        let mut v: Vec<(String, Vec<f32>)> = varmap
            .data()
            .lock()
            .unwrap()
            .iter()
            .filter(|(k, _)| k.starts_with(prefix))
            .map(|(k, t)| {
                (
                    k.clone(),
                    t.as_tensor().flatten_all().unwrap().to_vec1().unwrap(),
                )
            })
            .collect();
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    };
    let audio_of = |varmap: &candle_nn::VarMap| vars_of(varmap, "audio.");
    assert_eq!(audio_of(&run.model.varmap), audio_of(&teacher.model.varmap));
    let before = run.model.validation_scores(&data, 2).unwrap();
    let mut losses = Vec::new();
    for _ in 0..150 {
        let s = run.train_step(&data).unwrap();
        assert!(s.loss.is_finite());
        losses.push(s.loss);
    }
    let after = run.model.validation_scores(&data, 2).unwrap();
    assert_learned("student", &losses, 0.5, before.psnr, after.psnr);
    assert!(!run.pool.entries.is_empty() && run.pool.entries.len() <= run.pool.capacity);

    // A pool-only batch moves the light field but not the audio encoder.
    let audio_before = audio_of(&run.model.varmap);
    let mlp_before = vars_of(&run.model.varmap, "mlp.");
    let loss = run.pool_step(&data, 64).unwrap();
    assert!(loss.is_some_and(f64::is_finite));
    assert_eq!(
        audio_of(&run.model.varmap),
        audio_before,
        "a pool batch changed the audio encoder"
    );
    assert_ne!(
        vars_of(&run.model.varmap, "mlp."),
        mlp_before,
        "a pool batch left the light field unchanged"
    );
}

#[test]
fn a_student_resumes_bit_exactly_with_its_pool() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut cfg = tiny_student_config(20);
    cfg.train.distill = false;
    let mut run = StudentRun::create(dir.path(), cfg, &data, None).unwrap();
    run.prepare(&data, None, &mut |_, _| {}).unwrap();
    for _ in 0..5 {
        run.train_step(&data).unwrap();
    }
    run.save().unwrap();
    let saved_pool = run.pool.clone();
    let next: Vec<f64> = (0..2)
        .map(|_| run.train_step(&data).unwrap().loss)
        .collect();
    let mut resumed = StudentRun::open(dir.path()).unwrap();
    resumed.prepare(&data, None, &mut |_, _| {}).unwrap();
    assert_eq!(resumed.model.step, 5);
    assert!(!saved_pool.entries.is_empty());
    assert_eq!(resumed.pool, saved_pool);
    let again: Vec<f64> = (0..2)
        .map(|_| resumed.train_step(&data).unwrap().loss)
        .collect();
    assert_eq!(next, again);
}

/// Weight averaging: a run with `ema_decay` trains exactly as one without it, and ends on the
/// moving average of the weights from the step the learning rate starts to decay, worked
/// here from the plain run's weights step by step.
#[test]
fn a_student_with_weight_averaging_ends_on_the_average_of_its_decaying_steps() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let weights = |run: &StudentRun| -> Vec<f32> {
        nldf_train::networks::nn::sorted_vars(&run.model.varmap)
            .unwrap()
            .iter()
            .flat_map(|(_, v)| {
                v.as_tensor()
                    .flatten_all()
                    .unwrap()
                    .to_vec1::<f32>()
                    .unwrap()
            })
            .collect()
    };
    let mut cfg = tiny_student_config(8);
    cfg.train.distill = false;
    cfg.train.lr_hold_steps = 4;
    cfg.train.lr_decay_steps = 4;
    let plain_dir = tempfile::tempdir().unwrap();
    let mut plain = StudentRun::create(plain_dir.path(), cfg.clone(), &data, None).unwrap();
    plain.prepare(&data, None, &mut |_, _| {}).unwrap();
    let mut expected: Option<Vec<f32>> = None;
    let decay = 0.75f32;
    for step in 1..=8 {
        plain.train_step(&data).unwrap();
        if step > 4 {
            let w = weights(&plain);
            expected = Some(match expected {
                None => w,
                Some(a) => a
                    .iter()
                    .zip(&w)
                    .map(|(a, w)| decay * a + (1.0 - decay) * w)
                    .collect(),
            });
        }
    }
    let expected = expected.unwrap();
    cfg.train.ema_decay = decay as f64;
    let dir = tempfile::tempdir().unwrap();
    let mut averaged = StudentRun::create(dir.path(), cfg, &data, None).unwrap();
    averaged.prepare(&data, None, &mut |_, _| {}).unwrap();
    for _ in 0..7 {
        averaged.train_step(&data).unwrap();
    }
    // Until the last step the weights are the plain run's.
    let before_last = weights(&averaged);
    averaged.train_step(&data).unwrap();
    let last = weights(&averaged);
    let worst = expected
        .iter()
        .zip(&last)
        .map(|(e, w)| (e - w).abs())
        .fold(0.0f32, f32::max);
    // Measured worst 0: the run averages with the same f32 arithmetic.
    assert_eq!(worst, 0.0, "the last weights are {worst} from the average");
    let moved = weights(&plain)
        .iter()
        .zip(&last)
        .map(|(p, w)| (p - w).abs())
        .fold(0.0f32, f32::max);
    assert!(
        moved > 1e-5,
        "the average equals the last step's weights ({moved})"
    );
    assert_ne!(before_last, last);
}

/// `audio_lr_scale` 0 keeps the audio encoder as it started (a distilled student's is its
/// teacher's) while the rest of the network learns; at 1 the encoder learns too.
#[test]
fn a_student_can_keep_its_audio_encoder_fixed() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let split = |run: &StudentRun| -> (Vec<f32>, Vec<f32>) {
        let (mut audio, mut rest) = (Vec::new(), Vec::new());
        for (name, v) in nldf_train::networks::nn::sorted_vars(&run.model.varmap).unwrap() {
            let values = v
                .as_tensor()
                .flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap();
            if name.starts_with("audio.") {
                audio.extend(values);
            } else {
                rest.extend(values);
            }
        }
        (audio, rest)
    };
    for (scale, audio_moves) in [(0.0, false), (1.0, true)] {
        let mut cfg = tiny_student_config(3);
        cfg.train.distill = false;
        cfg.train.audio_lr_scale = scale;
        let dir = tempfile::tempdir().unwrap();
        let mut run = StudentRun::create(dir.path(), cfg, &data, None).unwrap();
        run.prepare(&data, None, &mut |_, _| {}).unwrap();
        let (audio0, rest0) = split(&run);
        assert!(!audio0.is_empty());
        for _ in 0..3 {
            run.train_step(&data).unwrap();
        }
        let (audio1, rest1) = split(&run);
        assert_ne!(rest0, rest1, "the network did not learn");
        assert_eq!(
            audio0 != audio1,
            audio_moves,
            "audio encoder at scale {scale}"
        );
    }
}

/// Eq. 9 with opacity, on numbers worked by hand: the pixel term, lambda times the
/// segment term and lambda times the opacity's divergence, KL(0.5 | 0.9) =
/// 0.5 ln(0.5 / 0.9) + 0.5 ln(0.5 / 0.1), each per ray; and the divergence is 0 where
/// the opacity is the teacher's, even at 0 and 1.
#[test]
fn the_distillation_loss_adds_the_opacity_term_inside_lambda() {
    use nldf_train::trainers::loss::{TeacherTargets, distillation_loss};
    let t = |v: Vec<f32>, shape: &[usize]| Tensor::from_vec(v, shape, &Device::Cpu).unwrap();
    // One ray, M = 1.
    let pixels = t(vec![0.5, 0.5, 0.5], &[1, 3]);
    let truth = t(vec![0.2, 0.5, 0.5], &[1, 3]);
    let segments = t(vec![0.4, 0.4, 0.4], &[1, 1, 3]);
    let target_segments = t(vec![0.4, 0.1, 0.4], &[1, 1, 3]);
    let logit = t(vec![(0.9f32 / 0.1).ln()], &[1, 1]);
    let target_alpha = t(vec![0.5], &[1, 1]);
    let lambda = 0.2;
    let loss = |target_alpha: &Tensor| -> f32 {
        distillation_loss(
            &pixels,
            &truth,
            &segments,
            &logit,
            Some(TeacherTargets {
                segments: &target_segments,
                opacity: target_alpha,
            }),
            lambda,
        )
        .unwrap()
        .per_ray
        .to_vec1::<f32>()
        .unwrap()[0]
    };
    let pixel = 0.09 / 3.0;
    let segment = lambda as f32 * 0.09 / 3.0;
    let kl = 0.5 * (0.5f32 / 0.9).ln() + 0.5 * (0.5f32 / 0.1).ln();
    let opacity = lambda as f32 * kl;
    // Measured worst 0.
    assert_eq!(loss(&target_alpha), pixel + segment + opacity);
    // The student's own opacity as the target adds (next to) no divergence.
    let matched = loss(&t(vec![0.9], &[1, 1])) - (pixel + segment);
    assert!(matched.abs() < 1e-6, "{matched}");
    let z = t(vec![-30.0, 0.0, 30.0, 2.0], &[4, 1]);
    let a = t(vec![0.0, 0.5, 1.0, 1.0 / (1.0 + (-2.0f32).exp())], &[4, 1]);
    let d: Vec<f32> = nldf_train::trainers::loss::opacity_divergence(&z, &a)
        .unwrap()
        .to_vec1()
        .unwrap();
    println!("opacity divergence of matching pairs: {d:?}");
    // Measured worst about 6e-8 (the logit 2 against its rounded sigmoid).
    assert!(d.iter().all(|v| v.abs() < 5e-7), "{d:?}");
}
