//! The synthetic head: framing, bounds, what the face state changes, determinism, numerics.

use glam::Vec3;
use nldf_core::camera::{Camera, Intrinsics, look_at};
use nldf_core::image::ImageRgb;
use nldf_core::region::Region;
use nldf_core::synth::head::{FaceState, HeadParams, head_bounds};
use nldf_core::synth::trace::{HeadFrame, render_background, render_head};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A camera at `eye` looking at `target`, focal 330 px at 128 x 128 scaled to `size`.
fn camera_at(eye: Vec3, target: Vec3, size: u32) -> Camera {
    let s = size as f32;
    let intrinsics = Intrinsics {
        focal: 330.0 * s / 128.0,
        cx: s / 2.0,
        cy: s / 2.0,
        width: size,
        height: size,
    };
    Camera {
        intrinsics,
        c2w: look_at(eye, target, Vec3::Y),
    }
}

fn front(size: u32) -> Camera {
    camera_at(Vec3::new(0.0, 0.0, 1.0), Vec3::ZERO, size)
}

fn state(mouth_open: f32, mouth_width: f32, blink: f32) -> FaceState {
    FaceState {
        mouth_open,
        mouth_width,
        blink,
    }
}

fn background(seed: u64, size: u32) -> ImageRgb {
    render_background(&mut ChaCha8Rng::seed_from_u64(seed), size, size)
}

fn random_head(seed: u64) -> HeadParams {
    HeadParams::random(&mut ChaCha8Rng::seed_from_u64(seed))
}

/// Mean absolute RGB difference over the pixels that `keep` selects, and their count.
fn mean_diff(a: &HeadFrame, b: &HeadFrame, keep: impl Fn(usize) -> bool) -> (f32, usize) {
    let mut sum = 0.0;
    let mut n = 0;
    for px in 0..a.regions.len() {
        if keep(px) {
            sum += (0..3)
                .map(|c| (a.rgb.data[3 * px + c] - b.rgb.data[3 * px + c]).abs())
                .sum::<f32>()
                / 3.0;
            n += 1;
        }
    }
    (if n == 0 { 0.0 } else { sum / n as f32 }, n)
}

fn count(frame: &HeadFrame, region: Region) -> usize {
    frame.regions.iter().filter(|&&r| r == region).count()
}

#[test]
fn front_view_frames_the_head_over_the_background() {
    let size = 128;
    let bg = background(7, size);
    let frame = render_head(
        &HeadParams::default(),
        &FaceState::default(),
        &front(size),
        &bg,
        3,
    );
    assert_eq!((frame.rgb.width, frame.rgb.height), (size, size));
    assert_eq!(frame.depth.len(), 128 * 128);
    assert_eq!(frame.regions.len(), 128 * 128);

    let centre = 64 * 128 + 64;
    assert!(
        frame.regions[centre].is_head(),
        "centre pixel misses the head"
    );
    let d = frame.depth[centre];
    assert!((0.8..=0.95).contains(&d), "centre depth {d}");

    for (i, j) in [(0, 0), (127, 0), (0, 127), (127, 127)] {
        let px = (j * 128 + i) as usize;
        assert_eq!(frame.regions[px], Region::Background);
        assert_eq!(frame.depth[px], 0.0);
        assert_eq!(frame.rgb.get(i, j), bg.get(i, j), "corner ({i}, {j})");
    }

    let head = frame.regions.iter().filter(|r| r.is_head()).count() as f32 / (128.0 * 128.0);
    assert!(
        (0.15..=0.70).contains(&head),
        "head covers {head} of the image"
    );
    // Every labelled part shows from the front, and depth is set exactly where the head is.
    assert!(
        count(&frame, Region::Eyes) > 30,
        "eyes: {}",
        count(&frame, Region::Eyes)
    );
    assert!(
        count(&frame, Region::Mouth) > 20,
        "mouth: {}",
        count(&frame, Region::Mouth)
    );
    for (px, r) in frame.regions.iter().enumerate() {
        assert_eq!(r.is_head(), frame.depth[px] > 0.0, "pixel {px}");
    }
}

#[test]
fn bounds_contain_every_hit() {
    let size = 64;
    let eyes = [
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.6, 0.2, 0.8),
        Vec3::new(-1.0, -0.1, 0.1),
        Vec3::new(0.0, 0.9, 0.4),
        Vec3::new(0.1, -0.8, 0.5),
        Vec3::new(0.2, 0.1, -1.0),
    ];
    let states = [
        state(0.0, 0.5, 0.0),
        state(1.0, 1.0, 0.0),
        state(1.0, 0.0, 1.0),
        state(0.4, 0.7, 0.6),
    ];
    for seed in 0..3u64 {
        let head = if seed == 0 {
            HeadParams::default()
        } else {
            random_head(seed)
        };
        let (lo, hi) = head_bounds(&head);
        assert!(lo.cmplt(hi).all() && lo.cmplt(Vec3::ZERO).all() && hi.cmpgt(Vec3::ZERO).all());
        assert!(lo.length() < 0.25 && hi.length() < 0.25, "bounds {lo} {hi}");
        let bg = ImageRgb::filled(size, size, [0.5; 3]);
        for (e, eye) in eyes.iter().enumerate() {
            let cam = camera_at(*eye, Vec3::new(0.0, 0.01, 0.0), size);
            let st = states[e % states.len()];
            let frame = render_head(&head, &st, &cam, &bg, 1);
            let mut hits = 0;
            for j in 0..size {
                for i in 0..size {
                    let t = frame.depth[(j * size + i) as usize];
                    if t > 0.0 {
                        let (o, d) = cam.ray(i as f32, j as f32);
                        let p = o + t * d;
                        let tol = Vec3::splat(1e-4);
                        assert!(
                            (p + tol).cmpge(lo).all() && (p - tol).cmple(hi).all(),
                            "seed {seed}, eye {eye}: hit {p} outside {lo} .. {hi}"
                        );
                        hits += 1;
                    }
                }
            }
            assert!(hits > 100, "seed {seed}, eye {eye}: only {hits} hits");
        }
    }
}

#[test]
fn opening_the_mouth_changes_the_mouth_only() {
    let size = 128;
    let head = HeadParams::default();
    let bg = background(3, size);
    let cam = front(size);
    let closed = render_head(&head, &state(0.0, 0.5, 0.0), &cam, &bg, 1);
    let half = render_head(&head, &state(0.5, 0.5, 0.0), &cam, &bg, 1);
    let open = render_head(&head, &state(1.0, 0.5, 0.0), &cam, &bg, 1);

    let in_mouth =
        |px: usize| closed.regions[px] == Region::Mouth || open.regions[px] == Region::Mouth;
    let (mouth, n_mouth) = mean_diff(&closed, &open, in_mouth);
    assert!(
        n_mouth > 50 && mouth > 0.08,
        "mouth pixels: {n_mouth}, mean change {mouth}"
    );

    // Above the eyes' lower edge nothing moves.
    let eye_row = (0..size as usize * size as usize)
        .filter(|&px| closed.regions[px] == Region::Eyes)
        .map(|px| px / size as usize)
        .max()
        .unwrap();
    let upper = |px: usize| px / (size as usize) < eye_row && closed.regions[px].is_head();
    let (above, n_above) = mean_diff(&closed, &open, upper);
    println!("upper head: mean change {above:e}");
    // Measured worst about 1.4e-4.
    assert!(
        n_above > 1000 && above < 1e-3,
        "upper head: {n_above} pixels, mean change {above}"
    );

    let (m0, m1, m2) = (
        count(&closed, Region::Mouth),
        count(&half, Region::Mouth),
        count(&open, Region::Mouth),
    );
    assert!(
        m0 < m1 && m1 < m2 && m2 as f32 > 1.5 * m0 as f32,
        "mouth pixels {m0} {m1} {m2}"
    );

    // A wider mouth covers more pixels too.
    let narrow = render_head(&head, &state(0.5, 0.0, 0.0), &cam, &bg, 1);
    let wide = render_head(&head, &state(0.5, 1.0, 0.0), &cam, &bg, 1);
    assert!(count(&wide, Region::Mouth) > count(&narrow, Region::Mouth));
}

#[test]
fn blinking_changes_the_eyes() {
    let size = 128;
    let head = random_head(5);
    let bg = background(5, size);
    let cam = front(size);
    let open = render_head(&head, &state(0.2, 0.5, 0.0), &cam, &bg, 2);
    let shut = render_head(&head, &state(0.2, 0.5, 1.0), &cam, &bg, 2);
    let in_eyes = |px: usize| open.regions[px] == Region::Eyes;
    let (eyes, n_eyes) = mean_diff(&open, &shut, in_eyes);
    assert!(
        n_eyes > 30 && eyes > 0.05,
        "eye pixels: {n_eyes}, mean change {eyes}"
    );
    let elsewhere =
        |px: usize| open.regions[px] != Region::Eyes && shut.regions[px] != Region::Eyes;
    let (rest, _) = mean_diff(&open, &shut, elsewhere);
    println!("blink: the rest of the image changed by {rest:e}");
    // Measured worst about 1.2e-6.
    assert!(rest < 1e-5, "blink changed the rest of the image by {rest}");
}

#[test]
fn rendering_is_deterministic_and_seeds_differ() {
    let size = 64;
    let cam = front(size);
    let st = state(0.6, 0.4, 0.3);
    let a = random_head(11);
    let again = random_head(11);
    assert_eq!(a, again);
    let bg = background(11, size);
    assert_eq!(bg, background(11, size));
    let f1 = render_head(&a, &st, &cam, &bg, 2);
    let f2 = render_head(&again, &st, &cam, &bg, 2);
    let bits = |f: &HeadFrame| {
        (
            f.rgb.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            f.depth.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        )
    };
    assert_eq!(bits(&f1), bits(&f2));
    assert_eq!(f1.regions, f2.regions);

    let b = random_head(12);
    assert_ne!(a, b);
    assert_ne!(background(11, size), background(12, size));
    let g = render_head(&b, &st, &cam, &bg, 2);
    let (diff, _) = mean_diff(&f1, &g, |px| {
        f1.regions[px].is_head() || g.regions[px].is_head()
    });
    assert!(diff > 0.02, "two random heads differ by only {diff}");

    let json = serde_json::to_string(&a).unwrap();
    let back: HeadParams = serde_json::from_str(&json).unwrap();
    assert_eq!(a, back);
}

#[test]
fn random_heads_are_plausible() {
    let size = 64;
    let cam = front(size);
    let bg = ImageRgb::filled(size, size, [0.0; 3]);
    for seed in 100..112u64 {
        let head = random_head(seed);
        let (lo, hi) = head_bounds(&head);
        assert!(
            lo.length() < 0.25 && hi.length() < 0.25,
            "seed {seed}: bounds {lo} {hi}"
        );
        let frame = render_head(&head, &state(0.5, 0.5, 0.0), &cam, &bg, 1);
        let head_px =
            frame.regions.iter().filter(|r| r.is_head()).count() as f32 / (size * size) as f32;
        assert!(
            (0.15..=0.7).contains(&head_px),
            "seed {seed}: head covers {head_px}"
        );
        assert!(count(&frame, Region::Eyes) > 6, "seed {seed}: eyes hidden");
        assert!(
            count(&frame, Region::Mouth) > 6,
            "seed {seed}: mouth hidden"
        );
    }
}

#[test]
fn no_nan_from_odd_cameras_and_states() {
    let size = 32;
    let head = random_head(21);
    let bg = background(21, size);
    let cams = [
        // Inside the bounds, in front of the face, and inside the head itself.
        camera_at(Vec3::new(0.0, 0.0, 0.13), Vec3::ZERO, size),
        camera_at(Vec3::new(0.01, 0.02, 0.0), Vec3::new(0.0, 0.0, 1.0), size),
        // Far away.
        camera_at(Vec3::new(0.0, 0.0, 1e4), Vec3::ZERO, size),
        camera_at(Vec3::new(3e3, -2e3, 1e4), Vec3::ZERO, size),
        // Grazing the side of the head and the top of the hair.
        camera_at(Vec3::new(0.085, 0.0, 1.0), Vec3::new(0.085, 0.0, 0.0), size),
        camera_at(Vec3::new(0.0, 0.135, 1.0), Vec3::new(0.0, 0.135, 0.0), size),
    ];
    let states = [
        state(0.0, 0.0, 0.0),
        state(1.0, 1.0, 1.0),
        state(f32::NAN, -3.0, 7.0),
        state(1e-7, 0.5, 0.999),
    ];
    for (c, cam) in cams.iter().enumerate() {
        for st in &states {
            let frame = render_head(&head, st, cam, &bg, 2);
            assert!(
                frame
                    .rgb
                    .data
                    .iter()
                    .all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
                "camera {c}: bad colour"
            );
            assert!(
                frame.depth.iter().all(|t| t.is_finite() && *t >= 0.0),
                "camera {c}: bad depth"
            );
        }
    }
    // The far camera still sees a (tiny) head at the right depth.
    let far = render_head(&head, &FaceState::default(), &cams[2], &bg, 1);
    let t = far.depth.iter().cloned().fold(0.0f32, f32::max);
    println!("far camera: depth {t}");
    // Measured worst about 0.1 from 1e4.
    assert!(t == 0.0 || (t - 1e4).abs() < 0.5, "far depth {t}");
}
