//! The student: presets with the paper's depths and cost, and a forward whose segments sum to
//! the pixel (Eq. 7).

use candle_core::{Device, Tensor};
use nldf_train::nn::new_varmap;
use nldf_train::student::{StudentConfig, residual_mlp};
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
    // DESIGN.md: about 11.8 MFLOP per ray at 88 x 256.
    let flops = 2.0 * StudentConfig::paper_d88().macs_per_ray() as f64;
    assert!((flops / 1e6 - 11.8).abs() < 0.1, "{flops}");
    assert!(
        StudentConfig {
            depth: 7,
            ..StudentConfig::tiny()
        }
        .validate()
        .is_err()
    );

    let cfg = StudentConfig::tiny();
    let (varmap, vb) = new_varmap();
    let net = residual_mlp(&cfg, vb).unwrap();
    let n_params: usize = varmap.all_vars().iter().map(|v| v.elem_count()).sum();
    let w = cfg.width;
    let expected = cfg.input_dim() * w + w + cfg.n_blocks() * 2 * (w * w + w) + w * 12 + 12;
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
    let (segments, pixels) = net.forward(&beams, &codes).unwrap();
    assert_eq!(segments.dims(), &[5, 4, 3]);
    let seg: Vec<Vec<Vec<f32>>> = segments.to_vec3().unwrap();
    let pix: Vec<Vec<f32>> = pixels.to_vec2().unwrap();
    for r in 0..5 {
        for c in 0..3 {
            let sum: f32 = (0..4).map(|i| seg[r][i][c]).sum();
            assert!((sum - pix[r][c]).abs() < 1e-6);
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
    nldf_train::nn::init_seeded(&varmap, 3).unwrap();
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
    let run = |fused: bool| {
        let (seg, px) = if fused {
            net.forward_fused(&beams, codes.as_tensor(), true).unwrap()
        } else {
            net.forward(&beams, codes.as_tensor()).unwrap()
        };
        let loss = ((&seg * &probe).unwrap().sum_all().unwrap()
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
        (seg.flatten_all().unwrap().to_vec1::<f32>().unwrap(), named)
    };
    let (out_f, grads_f) = run(true);
    let (out_r, grads_r) = run(false);
    let max_diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    assert!(
        max_diff(&out_f, &out_r) < 1e-5,
        "outputs differ by {}",
        max_diff(&out_f, &out_r)
    );
    assert_eq!(grads_f.len(), 2 + 2 * 2 * cfg.n_blocks() + 2 + 1);
    for ((name, gf), (_, gr)) in grads_f.iter().zip(&grads_r) {
        let scale = gr.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
        let d = max_diff(gf, gr);
        assert!(
            d / scale < 1e-4,
            "{name}: gradients differ by {d} (scale {scale})"
        );
    }
}
