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
