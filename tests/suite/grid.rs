//! The grid teacher: the hash grid's kernels against their f64 reference, its layout, its
//! numerics on extreme coordinates, and a grid teacher that learns and resumes bit for bit.

use candle_core::{Device, Tensor, Var};
use nldf_train::networks::hash_grid::{GridConfig, HashGridOp};
use nldf_train::networks::hash_grid_reference::{encode_reference, table_grad_reference};
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::teacher_trainer::TeacherRun;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

use crate::util::{
    assert_teacher_learns, assert_teacher_resumes_bit_for_bit, tiny_grid_run_config, tiny_scene,
};

/// A grid with dense coarse levels and hashed fine ones, over an off-centre box.
fn small_grid() -> GridConfig {
    GridConfig {
        levels: 6,
        features: 2,
        log2_table: 10,
        base_resolution: 3,
        max_resolution: 64,
        lo: [-0.3, -0.2, 0.1],
        hi: [0.5, 0.4, 0.9],
        ..GridConfig::default()
    }
}

/// [`small_grid`] as a tri-plane.
fn small_planes() -> GridConfig {
    GridConfig {
        planes: true,
        ..small_grid()
    }
}

/// `n` points spread over the box and a margin around it (some outside).
fn points_around(cfg: &GridConfig, n: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
    (0..n)
        .flat_map(|_| {
            (0..3)
                .map(|d| {
                    let (lo, hi) = (cfg.lo[d], cfg.hi[d]);
                    let m = 0.1 * (hi - lo);
                    rng.random_range(lo - m..hi + m)
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// The largest difference of `a` from `b`, relative to `b`'s largest magnitude.
fn relative_error(a: &[f32], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0, "the reference is all zeros");
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y).abs())
        .fold(0.0, f64::max)
        / scale
}

#[test]
fn the_hash_grid_matches_its_f64_reference_forward_and_backward() {
    assert_matches_reference(small_grid());
}

#[test]
fn the_tri_plane_matches_its_f64_reference_forward_and_backward() {
    let cfg = small_planes();
    assert_eq!(cfg.dim(), 3 * small_grid().dim());
    assert_matches_reference(cfg);
}

/// The op's forward and backward on `cfg` within 1e-4 of the f64 reference.
fn assert_matches_reference(cfg: GridConfig) {
    let layout = cfg.layout();
    assert!(layout.levels.iter().any(|l| l.hashed));
    assert!(layout.levels.iter().any(|l| !l.hashed));
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let n = 500;
    let points = points_around(&cfg, n, &mut rng);
    let table: Vec<f32> = (0..layout.entries * cfg.features)
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let r: Vec<f32> = (0..n * cfg.dim())
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let dev = Device::Cpu;
    let table_var = Var::from_vec(table.clone(), (layout.entries, cfg.features), &dev).unwrap();
    let p = Tensor::from_vec(points.clone(), (n, 3), &dev).unwrap();
    let op = HashGridOp {
        layout: Arc::new(layout),
    };
    let out = p.apply_op2(table_var.as_tensor(), op).unwrap();
    let loss = (&out * Tensor::from_vec(r.clone(), (n, cfg.dim()), &dev).unwrap())
        .unwrap()
        .sum_all()
        .unwrap();
    let grads = loss.backward().unwrap();
    let dt: Vec<f32> = grads
        .get(table_var.as_tensor())
        .unwrap()
        .flatten_all()
        .unwrap()
        .to_vec1()
        .unwrap();
    let f64s = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
    let want = encode_reference(&cfg, &f64s(&points), &f64s(&table));
    let got: Vec<f32> = out.flatten_all().unwrap().to_vec1().unwrap();
    let fwd = relative_error(&got, &want);
    let want_dt = table_grad_reference(&cfg, &f64s(&points), &f64s(&r));
    let bwd = relative_error(&dt, &want_dt);
    println!(
        "hash grid (planes {}): forward {fwd:e}, backward {bwd:e} of the largest value",
        cfg.planes
    );
    assert!(fwd <= 1e-4, "forward differs by {fwd:e}");
    assert!(bwd <= 1e-4, "backward differs by {bwd:e}");
}

#[test]
fn the_reference_gradient_is_the_adjoint_of_the_reference_encoding() {
    // The encoding is linear in the table, so <r, enc(table + h e_k)> - <r, enc(table)>
    // is h times entry k of the gradient, up to rounding.
    for cfg in [small_grid(), small_planes()] {
        assert_reference_adjoint(&cfg);
    }
}

/// The f64 reference gradient of `cfg` against finite differences of its encoding.
fn assert_reference_adjoint(cfg: &GridConfig) {
    let entries = cfg.layout().entries * cfg.features;
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let n = 40;
    let points: Vec<f64> = points_around(cfg, n, &mut rng)
        .into_iter()
        .map(f64::from)
        .collect();
    let table: Vec<f64> = (0..entries).map(|_| rng.random_range(-1.0..1.0)).collect();
    let r: Vec<f64> = (0..n * cfg.dim())
        .map(|_| rng.random_range(-1.0..1.0))
        .collect();
    let dot = |t: &[f64]| -> f64 {
        encode_reference(cfg, &points, t)
            .iter()
            .zip(&r)
            .map(|(a, b)| a * b)
            .sum()
    };
    let grad = table_grad_reference(cfg, &points, &r);
    let base = dot(&table);
    let mut touched = 0;
    for k in (0..entries).step_by(7) {
        let mut t = table.clone();
        t[k] += 0.5;
        let fd = (dot(&t) - base) / 0.5;
        assert!(
            (fd - grad[k]).abs() <= 1e-9,
            "entry {k}: {fd} vs {}",
            grad[k]
        );
        touched += usize::from(grad[k] != 0.0);
    }
    assert!(touched > 10, "too few entries reached to check");
}

#[test]
fn levels_grow_from_the_base_to_the_finest_and_dense_levels_own_every_vertex() {
    let cfg = GridConfig::default();
    let res = cfg.resolutions();
    assert_eq!(res.len(), 16);
    assert_eq!(res[0], 16);
    assert!((510..=512).contains(&res[15]), "{res:?}");
    assert!(res.windows(2).all(|w| w[0] < w[1]), "{res:?}");
    let layout = small_grid().layout();
    for level in layout.levels.iter().filter(|l| !l.hashed) {
        let side = level.resolution + 1;
        let mut seen = vec![false; level.entries];
        for z in 0..side {
            for y in 0..side {
                for x in 0..side {
                    let e = level.entry(x, y, z);
                    assert!(!seen[e], "two vertices share entry {e}");
                    seen[e] = true;
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
    }
    for level in layout.levels.iter().filter(|l| l.hashed) {
        assert!(level.entries.is_power_of_two());
        assert!(level.entry(123, 456, 789) < level.entries);
    }
    // A tri-plane: each plane has every level, a dense plane level owns each of its
    // (N + 1)^2 vertices, and the planes' levels follow one another in the table.
    let planes = small_planes().layout();
    assert_eq!(planes.levels.len(), 3 * layout.levels.len());
    let mut offset = 0;
    for level in &planes.levels {
        assert_eq!(level.offset, offset);
        offset += level.entries;
        assert!(level.plane.is_some());
        if level.hashed {
            assert!(level.entry2(123, 456) < level.entries);
            continue;
        }
        let side = level.resolution + 1;
        assert_eq!(level.entries, (side * side) as usize);
        let mut seen = vec![false; level.entries];
        for b in 0..side {
            for a in 0..side {
                let e = level.entry2(a, b);
                assert!(!seen[e], "two plane vertices share entry {e}");
                seen[e] = true;
            }
        }
    }
    assert_eq!(offset, planes.entries);
}

#[test]
fn extreme_and_broken_coordinates_encode_to_finite_values_outside_the_box() {
    assert_extremes_finite(small_grid());
    assert_extremes_finite(small_planes());
}

/// Points at 1e30, NaN, infinity and the f32 limits encode to finite values and count as
/// outside `cfg`'s box.
fn assert_extremes_finite(cfg: GridConfig) {
    let layout = cfg.layout();
    let table: Vec<f32> = (0..layout.entries * cfg.features)
        .map(|i| (i % 13) as f32 - 6.0)
        .collect();
    let points = [
        1e30f32,
        -1e30,
        1e10, //
        f32::NAN,
        0.0,
        0.0, //
        f32::INFINITY,
        f32::NEG_INFINITY,
        0.2, //
        f32::MAX,
        f32::MIN,
        f32::MIN_POSITIVE,
    ];
    let out = layout.encode(&points, &table);
    assert!(out.iter().all(|v| v.is_finite()), "{out:?}");
    for p in points.chunks_exact(3) {
        assert!(!layout.contains(p), "{p:?} counted inside");
    }
    assert!(layout.contains(&[0.1, 0.1, 0.5]));
    let grad = vec![1.0f32; out.len()];
    assert!(
        layout
            .table_grad(&points, &grad)
            .iter()
            .all(|v| v.is_finite())
    );
}

#[test]
fn a_tiny_grid_teacher_learns_the_tiny_scene() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let run = TeacherRun::create(dir.path(), tiny_grid_run_config(1), &data).unwrap();
    let grid = run.model.cfg.model.grid.clone().unwrap();
    assert_eq!(
        grid.lo,
        data.bounds.lo.to_array(),
        "the grid spans the head's bounds"
    );
    assert_teacher_learns("grid teacher", tiny_grid_run_config(200));
}

#[test]
fn a_tiny_tri_plane_teacher_learns_the_tiny_scene() {
    let mut cfg = tiny_grid_run_config(200);
    if let Some(g) = cfg.model.grid.as_mut() {
        g.planes = true;
    }
    assert_teacher_learns("tri-plane teacher", cfg);
}

/// [`tiny_grid_run_config`] with region attention.
fn with_attention(
    mut cfg: nldf_train::trainers::config::TeacherRunConfig,
) -> nldf_train::trainers::config::TeacherRunConfig {
    if let Some(g) = cfg.model.grid.as_mut() {
        g.region_attention = true;
    }
    cfg
}

#[test]
fn a_grid_teacher_with_region_attention_learns_the_tiny_scene() {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cfg = with_attention(tiny_grid_run_config(1));
    let run = TeacherRun::create(dir.path(), cfg, &data).unwrap();
    assert!(run.model.teacher.attention.is_some());
    assert_teacher_learns(
        "grid teacher with attention",
        with_attention(tiny_grid_run_config(200)),
    );
}

#[test]
fn a_resumed_grid_teacher_continues_bit_for_bit() {
    assert_teacher_resumes_bit_for_bit(with_attention(tiny_grid_run_config(20)));
}

#[test]
fn the_teachers_curves_hold_each_teacher_measured_over_its_seconds() {
    use nldf_train::job::curves::CurveJob;
    use nldf_train::job::recipe::TeacherKind;
    let out = tempfile::tempdir().unwrap();
    let job = CurveJob {
        data: tiny_scene().to_path_buf(),
        out: out.path().to_path_buf(),
        teachers: vec![TeacherKind::Mlp, TeacherKind::Grid],
        seconds: 1.5,
        every_s: 0.5,
        frames: 1,
    };
    let stop = std::sync::atomic::AtomicBool::new(false);
    let report = job.run(&stop, &mut |_| {}).unwrap();
    assert_eq!(report.curves.len(), 2);
    for (curve, name) in report.curves.iter().zip(["mlp", "grid"]) {
        assert_eq!(curve.teacher, name);
        assert!(
            curve.points.len() >= 2,
            "{name}: {} points",
            curve.points.len()
        );
        assert!(
            curve
                .points
                .windows(2)
                .all(|w| w[0].seconds < w[1].seconds && w[0].step <= w[1].step)
        );
        let last = curve.points.last().unwrap();
        assert!(last.seconds >= 1.5 && last.step > 0 && last.psnr.is_finite());
        let model = out.path().join(name).join(nldf_core::run_files::MODEL_FILE);
        assert!(model.is_file(), "{} missing", model.display());
    }
    for file in ["curves.json", "curves.png"] {
        assert!(out.path().join(file).is_file(), "{file} missing");
    }
    // A job without seconds is refused before any work.
    let none = CurveJob {
        seconds: 0.0,
        ..job
    };
    assert!(none.run(&stop, &mut |_| {}).is_err());
}

#[test]
fn a_grid_teacher_renders_finite_colours_over_a_1e10_span_and_far_outside_its_box() {
    use nldf_core::bounds::{Bounds, HeadRange};
    use nldf_core::dataset::Split;
    use nldf_core::rays::rays_for_image;
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = TeacherRun::create(dir.path(), tiny_grid_run_config(20), &data).unwrap();
    for _ in 0..20 {
        run.train_step(&data).unwrap();
    }
    let frame = &data.dataset.frames(Split::Val)[0];
    let rays = rays_for_image(&data.dataset.camera(frame));
    let code = run.model.audio_codes(&data, &[frame.aud_id]).unwrap();
    let bg = &data.dataset.background.data;
    let reach = glam::Vec3::splat(1e6);
    for (near, far) in [(0.0, 1e10), (1e-9, 1e-6), (0.0, 1e4)] {
        let range = HeadRange {
            bounds: Bounds {
                lo: -reach,
                hi: reach,
            },
            near,
            far,
        };
        let out = run
            .model
            .teacher
            .render_eval(&rays, bg, &code, &range, 0.0)
            .unwrap();
        assert!(
            out.iter().all(|v| v.is_finite()),
            "non-finite colour over [{near}, {far}]"
        );
        // A ray that never enters the grid's box meets no density: it is its background.
        let grid = &run.model.cfg.model.grid.as_ref().unwrap();
        let grid_box = Bounds {
            lo: glam::Vec3::from(grid.lo),
            hi: glam::Vec3::from(grid.hi),
        };
        let mut misses = 0;
        for r in 0..rays.len() {
            let (o, d) = (rays.origin(r), rays.direction(r));
            if grid_box.padded(0.01).intersect(o, d, near, far).is_none() {
                misses += 1;
                assert_eq!(&out[3 * r..3 * r + 3], &bg[3 * r..3 * r + 3], "ray {r}");
            }
        }
        assert!(misses > 0, "every ray enters the grid's box");
    }
}
