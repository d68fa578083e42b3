//! Rays, beam encoding and compositing against analytic cases and f64 references.

use glam::{Mat4, Vec3};
use nldf_core::beam::{BeamSpec, encode_beams};
use nldf_core::camera::{Camera, Intrinsics, look_at};
use nldf_core::composite::{
    composite, composite_f64, segment_colors, segment_colors_f64, segment_of,
};
use nldf_core::encoding::{MAX_COORD, encoded_len, positional_encoding};
use nldf_core::image::Rect;
use nldf_core::rays::{Rays, rays_for_image, rays_for_pixels, sample_batch};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn intrinsics() -> Intrinsics {
    Intrinsics {
        focal: 100.0,
        cx: 31.0,
        cy: 23.0,
        width: 64,
        height: 48,
    }
}

#[test]
fn ray_through_principal_point_is_the_cameras_minus_z_axis() {
    let c2w = look_at(Vec3::new(0.4, -0.3, 1.2), Vec3::new(0.0, 0.1, 0.0), Vec3::Y);
    let cam = Camera {
        intrinsics: intrinsics(),
        c2w,
    };
    let (o, d) = cam.ray(31.0, 23.0);
    let minus_z = -c2w.z_axis.truncate();
    // Measured worst 0: the origin is the pose's translation and the direction its -z, exactly.
    assert_eq!(o, Vec3::new(0.4, -0.3, 1.2));
    assert_eq!(d, minus_z);
    // Identity pose: exactly (0, 0, -1).
    let cam = Camera {
        intrinsics: intrinsics(),
        c2w: Mat4::IDENTITY,
    };
    assert_eq!(cam.ray(31.0, 23.0).1, Vec3::new(0.0, 0.0, -1.0));
    // +i goes right (+x), +j goes down (-y), as in AD-NeRF's get_rays.
    // Measured worst 0: ten pixels over a focal of 100 is 0.1 in f32 too.
    assert_eq!(cam.ray(41.0, 33.0).1, Vec3::new(0.1, -0.1, -1.0));
}

#[test]
fn image_rays_are_row_major_and_match_pixel_rays() {
    let cam = Camera {
        intrinsics: intrinsics(),
        c2w: look_at(Vec3::Z, Vec3::ZERO, Vec3::Y),
    };
    let all = rays_for_image(&cam);
    assert_eq!(all.len(), 64 * 48);
    let some = rays_for_pixels(&cam, &[(5, 7), (63, 47)]);
    assert_eq!(some.direction(0), all.direction(7 * 64 + 5));
    assert_eq!(some.direction(1), all.direction(47 * 64 + 63));
}

#[test]
fn batches_are_seeded_and_mostly_inside_the_face_rect() {
    let cam = Camera {
        intrinsics: intrinsics(),
        c2w: Mat4::IDENTITY,
    };
    let rect = Rect {
        x: 20,
        y: 10,
        w: 16,
        h: 20,
    };
    let a = sample_batch(&cam, rect, 2000, 0.95, &mut ChaCha8Rng::seed_from_u64(3));
    let b = sample_batch(&cam, rect, 2000, 0.95, &mut ChaCha8Rng::seed_from_u64(3));
    assert_eq!(a, b);
    let inside = a
        .pixels
        .iter()
        .filter(|&&(i, j)| rect.contains(i, j))
        .count();
    // 1900 drawn inside, plus the share of the other 100 that lands there by chance.
    assert!((1900..=1930).contains(&inside), "{inside}");
    assert!(a.pixels.iter().all(|&(i, j)| i < 64 && j < 48));
    // A rectangle outside the image falls back to the whole image.
    let away = Rect {
        x: 500,
        y: 500,
        w: 5,
        h: 5,
    };
    let c = sample_batch(&cam, away, 100, 0.95, &mut ChaCha8Rng::seed_from_u64(1));
    assert!(c.pixels.iter().all(|&(i, j)| i < 64 && j < 48));
}

/// NeRF's embedder, independently in f64.
fn encoding_f64(values: &[f64], n_freqs: usize) -> Vec<f64> {
    let mut out = values.to_vec();
    for l in 0..n_freqs {
        let f = 2f64.powi(l as i32);
        out.extend(values.iter().map(|v| (v * f).sin()));
        out.extend(values.iter().map(|v| (v * f).cos()));
    }
    out
}

#[test]
fn positional_encoding_matches_f64_reference() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let values: Vec<f32> = (0..48).map(|_| rng.random_range(-1.5f32..1.5)).collect();
    let got = positional_encoding(&values, 10);
    let want = encoding_f64(&values.iter().map(|&v| v as f64).collect::<Vec<_>>(), 10);
    assert_eq!(got.len(), 1008);
    assert_eq!(got.len(), encoded_len(48, 10));
    let err = got
        .iter()
        .zip(&want)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0.0, f64::max);
    // Taken in f64, only the f32 result rounds: measured worst about 3e-8.
    println!("positional encoding: worst error {err:e}");
    assert!(err < 1e-7, "max error {err}");
}

#[test]
fn positional_encoding_of_huge_coordinates_is_finite() {
    let values = [1e30f32, -3e38, 123456.0, f32::MAX, f32::MIN_POSITIVE];
    let got = positional_encoding(&values, 10);
    assert!(got.iter().all(|v| v.is_finite()));
    assert_eq!(got[0], MAX_COORD);
    assert_eq!(got[1], -MAX_COORD);
}

#[test]
fn beams_are_evenly_spaced_points_between_near_and_far() {
    let spec = BeamSpec::default();
    assert_eq!(spec.encoded_len(), 1008);
    let mut rays = Rays::default();
    rays.push(Vec3::new(0.1, 0.2, 1.0), Vec3::new(0.05, -0.02, -1.0));
    rays.push(Vec3::new(-0.3, 0.0, 1.1), Vec3::new(0.0, 0.01, -1.0));
    let (near, far) = (0.8f32, 1.4f32);
    let mut out = vec![0.0; 2 * 1008];
    encode_beams(&rays, near, far, &spec, None, &mut out);
    for r in 0..2 {
        let row = &out[r * 1008..(r + 1) * 1008];
        let (o, d) = (rays.origin(r), rays.direction(r));
        let mut points = Vec::new();
        for k in 0..16 {
            let t = near as f64 + (far - near) as f64 * k as f64 / 15.0;
            for c in 0..3 {
                points.push(o[c] as f64 + t * d[c] as f64);
            }
        }
        let want = encoding_f64(&points, 10);
        let err = row
            .iter()
            .zip(&want)
            .map(|(a, b)| (*a as f64 - b).abs())
            .fold(0.0, f64::max);
        // The f32 points round before the 2^9 scaling: measured worst about 2.9e-5.
        println!("beam encoding ray {r}: worst error {err:e}");
        assert!(err < 1e-4, "ray {r}: max error {err}");
    }
    // Jitter keeps points inside [near, far] and moves them.
    let mut jittered = vec![0.0; 2 * 1008];
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    encode_beams(&rays, near, far, &spec, Some(&mut rng), &mut jittered);
    assert_ne!(jittered, out);
    for k in 0..16 {
        let z = jittered[3 * k + 2];
        let (zmin, zmax) = (1.0 - far, 1.0 - near);
        assert!(z >= zmin - 1e-6 && z <= zmax + 1e-6, "point {k} z {z}");
    }
}

struct RandomRay {
    densities: Vec<f32>,
    deltas: Vec<f32>,
    t_vals: Vec<f32>,
    colors: Vec<f32>,
}

fn random_ray(rng: &mut impl Rng, n: usize, last_delta: f32) -> RandomRay {
    let mut t = 0.8f32;
    let mut t_vals = Vec::new();
    let mut deltas = Vec::new();
    for k in 0..n {
        let d = rng.random_range(0.001f32..0.02);
        t_vals.push(t);
        deltas.push(if k + 1 == n { last_delta } else { d });
        t += d;
    }
    let densities = (0..n).map(|_| rng.random_range(0.0f32..60.0)).collect();
    let colors = (0..3 * n).map(|_| rng.random::<f32>()).collect();
    RandomRay {
        densities,
        deltas,
        t_vals,
        colors,
    }
}

fn to_f64(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x as f64).collect()
}

fn rgb_f64(colors: &[f32]) -> Vec<[f64; 3]> {
    colors
        .chunks_exact(3)
        .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64])
        .collect()
}

#[test]
fn f32_compositing_matches_f64_reference() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    // Worst |f32 - f64| of the weights, colour, opacity and (finite last spacing) depth.
    let mut worst = [0f64; 4];
    for trial in 0..200 {
        let last = if trial % 2 == 0 { 1e10 } else { 0.01 };
        let ray = random_ray(&mut rng, 64, last);
        let got = composite(&ray.densities, &ray.deltas, &ray.t_vals, &ray.colors);
        let want = composite_f64(
            &to_f64(&ray.densities),
            &to_f64(&ray.deltas),
            &to_f64(&ray.t_vals),
            &rgb_f64(&ray.colors),
        );
        for k in 0..64 {
            worst[0] = worst[0].max((got.weights[k] as f64 - want.weights[k]).abs());
        }
        for c in 0..3 {
            worst[1] = worst[1].max((got.color[c] as f64 - want.color[c]).abs());
        }
        worst[2] = worst[2].max((got.opacity as f64 - want.opacity).abs());
        if last < 1.0 {
            worst[3] = worst[3].max((got.depth as f64 - want.depth).abs());
        }
        assert!(got.opacity <= 1.0 && want.opacity <= 1.0 + 1e-12);
    }
    println!("compositing: worst weight, colour, opacity, depth error {worst:?}");
    // Measured worst about 4.9e-8 (weights), 4.3e-7 (colour), 4.7e-7 (opacity), 3.9e-7 (depth).
    assert!(worst[0] < 2e-7, "weights {worst:?}");
    assert!(worst[1] < 2e-6, "colour {worst:?}");
    assert!(worst[2] < 2e-6, "opacity {worst:?}");
    assert!(worst[3] < 2e-6, "depth {worst:?}");
}

#[test]
fn uniform_weights_give_the_mean_colour() {
    // Choose sigma_k delta_k so that every weight is 1/n: T_k = (n - k)/n, alpha_k = 1/(n - k).
    let n = 8;
    let deltas = vec![1.0f32; n];
    let densities: Vec<f32> = (0..n)
        .map(|k| -(1.0 - 1.0 / (n - k) as f64).ln() as f32)
        .collect();
    let mut densities = densities;
    densities[n - 1] = 1e30; // alpha = 1 for the last sample
    let colors: Vec<f32> = (0..3 * n).map(|i| (i % 7) as f32 / 7.0).collect();
    let t_vals: Vec<f32> = (0..n).map(|k| k as f32).collect();
    let c = composite(&densities, &deltas, &t_vals, &colors);
    let worst = c
        .weights
        .iter()
        .map(|w| (w - 1.0 / n as f32).abs())
        .fold(0f32, f32::max);
    println!("uniform weights: worst error {worst:e}");
    // The densities round to f32: measured worst about 7.5e-9.
    assert!(worst < 5e-8, "{:?}", c.weights);
    // Measured worst 0 for the colour and the depth.
    for ch in 0..3 {
        let mean: f32 = (0..n).map(|k| colors[3 * k + ch]).sum::<f32>() / n as f32;
        assert_eq!(c.color[ch], mean);
    }
    assert_eq!(c.depth, 3.5);
}

#[test]
fn one_opaque_first_sample_gives_its_colour_and_depth() {
    let densities = [1e6f32, 5.0, 5.0, 5.0];
    let deltas = [0.1f32, 0.1, 0.1, 1e10];
    let t_vals = [0.9f32, 1.0, 1.1, 1.2];
    let colors = [
        0.2f32, 0.4, 0.6, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0,
    ];
    let c = composite(&densities, &deltas, &t_vals, &colors);
    assert_eq!(c.color, [0.2, 0.4, 0.6]);
    assert_eq!(c.depth, 0.9);
    assert_eq!(c.opacity, 1.0);
}

#[test]
fn extreme_densities_and_spacings_stay_finite() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let colors: Vec<f32> = (0..3 * 16).map(|_| rng.random::<f32>()).collect();
    let t_vals: Vec<f32> = (0..16).map(|k| 1e9 * k as f32).collect();
    for sigma in [0.0f32, 1e-30, 1.0, 1e10, 1e30, f32::MAX, -5.0, -f32::MAX] {
        for delta in [0.0f32, 1e-10, 0.01, 1e10, f32::MAX] {
            let densities = vec![sigma; 16];
            let deltas = vec![delta; 16];
            let c = composite(&densities, &deltas, &t_vals, &colors);
            assert!(
                c.weights.iter().all(|w| w.is_finite() && *w >= 0.0),
                "{sigma} {delta}"
            );
            assert!(c.color.iter().all(|v| v.is_finite()));
            assert!(c.depth.is_finite() && c.opacity.is_finite());
            assert!(c.opacity <= 1.0);
            let span = (t_vals[0], t_vals[15]);
            let seg = segment_colors(&c.weights, &colors, &t_vals, span, 4);
            assert!(seg.iter().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn accumulated_weight_never_exceeds_one() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    for _ in 0..500 {
        let ray = random_ray(&mut rng, 128, 1e10);
        let densities: Vec<f32> = ray
            .densities
            .iter()
            .map(|d| d * rng.random_range(0.0f32..100.0))
            .collect();
        let c = composite(&densities, &ray.deltas, &ray.t_vals, &ray.colors);
        let sum: f32 = c.weights.iter().sum();
        assert!(sum <= 1.0 + 1e-6, "{sum}");
        assert!(c.opacity <= 1.0);
    }
}

#[test]
fn segment_colours_sum_to_the_pixel() {
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    // Worst f32 segment sum against the f32 pixel, f64 sum against the f64 pixel, and f32
    // segment against the f64 one.
    let mut worst = [0f64; 3];
    for n in [64usize, 66, 192] {
        let ray = random_ray(&mut rng, n, 1e10);
        let span = (ray.t_vals[0], ray.t_vals[n - 1]);
        let c = composite(&ray.densities, &ray.deltas, &ray.t_vals, &ray.colors);
        let seg = segment_colors(&c.weights, &ray.colors, &ray.t_vals, span, 4);
        for ch in 0..3 {
            let sum: f32 = (0..4).map(|i| seg[3 * i + ch]).sum();
            worst[0] = worst[0].max((sum - c.color[ch]).abs() as f64);
        }
        // f64: exact to rounding, and each segment uses the ray's own transmittance.
        let t64 = to_f64(&ray.t_vals);
        let want = composite_f64(
            &to_f64(&ray.densities),
            &to_f64(&ray.deltas),
            &t64,
            &rgb_f64(&ray.colors),
        );
        let span64 = (span.0 as f64, span.1 as f64);
        let seg64 = segment_colors_f64(&want.weights, &rgb_f64(&ray.colors), &t64, span64, 4);
        for ch in 0..3 {
            let sum: f64 = seg64.iter().map(|s| s[ch]).sum();
            worst[1] = worst[1].max((sum - want.color[ch]).abs());
        }
        for i in 0..4 {
            for ch in 0..3 {
                worst[2] = worst[2].max((seg[3 * i + ch] as f64 - seg64[i][ch]).abs());
            }
        }
    }
    println!("segment colours: worst f32 sum, f64 sum, f32 segment error {worst:?}");
    // Measured worst about 1.8e-7 (f32 sum), 6.7e-16 (f64 sum), 2.0e-7 (f32 segment).
    assert!(worst[0] < 1e-6, "{worst:?}");
    assert!(worst[1] < 5e-15, "{worst:?}");
    assert!(worst[2] < 1e-6, "{worst:?}");
}

/// Eq. 5's segments are equal t-intervals of the sampled span: with one stratified sample
/// per equal bin they are the paper's groups of N/M samples in order; with samples crowded
/// towards one end (as importance samples crowd where the density is) they keep their
/// depths instead of following the crowd.
#[test]
fn segments_are_equal_t_intervals_of_the_span() {
    let (t0, t1) = (1.0f64, 3.0f64);
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    // Stratified: N = 32 bins, a jittered sample in each.
    for _ in 0..20 {
        for k in 0..32 {
            let t = t0 + (k as f64 + rng.random::<f64>()) * (t1 - t0) / 32.0;
            assert_eq!(segment_of(t, (t0, t1), 4), k / 8, "bin {k} at t {t}");
        }
    }
    // The boundaries and the ends.
    assert_eq!(segment_of(1.5, (t0, t1), 4), 1);
    assert_eq!(segment_of(t0, (t0, t1), 4), 0);
    assert_eq!(segment_of(t1, (t0, t1), 4), 3);
    assert_eq!(segment_of(0.0, (t0, t1), 4), 0);
    assert_eq!(segment_of(f64::NAN, (t0, t1), 4), 0);
    assert_eq!(segment_of(2.0, (t0, t0), 4), 0);
    // 48 samples crowded in the last quarter of the span, 16 spread over the rest: a split
    // by count would give the last quarter's samples to three segments.
    let mut t: Vec<f64> = (0..16)
        .map(|k| t0 + 1.5 * (k as f64 + 0.5) / 16.0)
        .collect();
    t.extend((0..48).map(|k| t0 + 1.5 + 0.5 * (k as f64 + 0.5) / 48.0));
    let weights = vec![1.0 / 64.0; 64];
    let colors: Vec<[f64; 3]> = t.iter().map(|&x| [x, 1.0, 0.0]).collect();
    let seg = segment_colors_f64(&weights, &colors, &t, (t0, t1), 4);
    let counts: Vec<f64> = seg.iter().map(|s| s[1] * 64.0).collect();
    for (got, want) in counts
        .iter()
        .zip([16.0 / 3.0, 16.0 / 3.0, 16.0 / 3.0, 48.0])
    {
        assert!((got - want).abs() < 0.7, "samples per segment {counts:?}");
    }
    let t32: Vec<f32> = t.iter().map(|&x| x as f32).collect();
    let w32 = vec![1.0f32 / 64.0; 64];
    let c32: Vec<f32> = colors.iter().flatten().map(|&x| x as f32).collect();
    let seg32 = segment_colors(&w32, &c32, &t32, (t0 as f32, t1 as f32), 4);
    let worst = (0..12)
        .map(|k| (seg32[k] as f64 - seg[k / 3][k % 3]).abs())
        .fold(0f64, f64::max);
    println!("equal t-intervals: worst f32 segment error {worst:e}");
    // Measured worst about 2.4e-7.
    assert!(worst < 1e-6, "{worst:e}");
}
