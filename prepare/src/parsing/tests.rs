//! The parsing's steps on drawn frames, each with a fault it must catch.

use super::*;

/// A jaw from (10, 20) down to a chin at (30, 40) and up to (50, 20).
fn jaw() -> Vec<[f32; 2]> {
    vec![
        [10.0, 20.0],
        [20.0, 35.0],
        [30.0, 40.0],
        [40.0, 35.0],
        [50.0, 20.0],
    ]
}

#[test]
fn the_person_splits_at_the_jaw_into_head_neck_and_torso() {
    let (w, h) = (60u32, 80u32);
    let person = vec![255u8; (w * h) as usize];
    let along_the_arms = ParsingConfig {
        ear_points: 0,
        ..ParsingConfig::default()
    };
    let parts = parse_frame(&along_the_arms, &person, &jaw(), [30.0, 10.0], w, h);
    let at = |x: u32, y: u32| parts[(y * w + x) as usize];
    // The jaw widened by JAW_MARGIN (0.15) about (30, 20): the chin at (30, 43), the
    // ends at (7, 20) and (53, 20).
    assert_eq!(at(30, 38), Part::Head);
    assert_eq!(at(30, 42), Part::Head, "past the chin, within the margin");
    assert_eq!(at(30, 44), Part::Neck);
    assert_eq!(at(30, 70), Part::Torso);
    assert_eq!(at(12, 30), Part::Torso, "below the jaw near its end");
    assert_eq!(
        at(5, 30),
        Part::Head,
        "beside the jaw above the chin: an ear"
    );
    assert_eq!(
        at(5, 45),
        Part::Torso,
        "beside the jaw below the chin: a shoulder"
    );
    let none = vec![0u8; (w * h) as usize];
    assert!(
        parse_frame(&ParsingConfig::default(), &none, &jaw(), [30.0, 10.0], w, h)
            .iter()
            .all(|p| *p == Part::Background)
    );
    assert_eq!(head_rect(&parts, w), Some([0, 0, 60, 43]));
}

#[test]
fn an_ear_beside_the_jaws_upper_arm_is_head() {
    // A 9-point jaw from (10, 20) down to a chin at (30, 44) and up to (50, 20); widened
    // by JAW_MARGIN about (30, 20), its left arm runs (7, 20), (9.3, 29.2),
    // (12.75, 36.1), (18.5, 41.85), (30, 47.6), and EAR_POINTS = 2 puts the ears' floor
    // at y = 36.1.
    let jaw = [
        [10.0, 20.0],
        [12.0, 28.0],
        [15.0, 34.0],
        [20.0, 39.0],
        [30.0, 44.0],
        [40.0, 39.0],
        [45.0, 34.0],
        [48.0, 28.0],
        [50.0, 20.0],
    ];
    let (w, h) = (60u32, 80u32);
    let person = vec![255u8; (w * h) as usize];
    let parse = |config: &ParsingConfig| parse_frame(config, &person, &jaw, [30.0, 10.0], w, h);
    let ears = parse(&ParsingConfig::default());
    let along_the_arms = parse(&ParsingConfig {
        ear_points: 0,
        ..ParsingConfig::default()
    });
    let at = |parts: &[Part], x: u32, y: u32| parts[(y * w + x) as usize];
    // (9.5, 33.5): left of the arm (x 11.45 at that height), below its crossing (29.6).
    assert_eq!(at(&ears, 9, 33), Part::Head, "an ear");
    assert_eq!(at(&ears, 50, 33), Part::Head, "the other ear");
    assert_eq!(at(&along_the_arms, 9, 33), Part::Torso, "cut along the arm");
    // (14.5, 40.5): below the ears' floor and the arm's crossing (37.85).
    assert_ne!(at(&ears, 14, 40), Part::Head, "below the ears");
    assert_eq!(at(&ears, 30, 40), Part::Head, "the face");
}

#[test]
fn a_chin_that_hangs_below_the_jaw_into_background_is_head() {
    // The segmenter draws a person everywhere (a neck below every head); the frame is
    // the background's grey but for the head above the cut, a chin under it (columns
    // 26..35, to row 48, ending in background within HANG_DEPTH = 0.4 of the widened
    // jaw's depth 23, so 10 rows), a neck that goes on to the frame's bottom (columns
    // 36..40) and a faint patch (column 24, to row 48) too close to the background's
    // colour to be foreground.
    let (w, h) = (60u32, 80u32);
    let n = (w * h) as usize;
    let person = vec![255u8; n];
    let background = vec![50u8; 3 * n];
    let mut parts = parse_frame(
        &ParsingConfig::default(),
        &person,
        &jaw(),
        [30.0, 10.0],
        w,
        h,
    );
    let before = parts.clone();
    let mut frame = background.clone();
    let mut paint = |x: u32, y: u32, v: u8| {
        let i = 3 * (y * w + x) as usize;
        frame[i..i + 3].copy_from_slice(&[v, v, v]);
    };
    for y in 0..h {
        for x in 0..w {
            let head = before[(y * w + x) as usize] == Part::Head;
            let chin = (26..35).contains(&x) && y < 49;
            if head || chin || (36..40).contains(&x) {
                paint(x, y, 200);
            }
            if x == 24 && y < 49 && !head {
                paint(x, y, 50 + FOREGROUND_DIFF - 1);
            }
        }
    }
    let plate = Plate {
        frame: &frame,
        background: &background,
    };
    hang_below_jaw(
        &ParsingConfig::default(),
        &mut parts,
        &person,
        plate,
        &jaw(),
        w,
        h,
    );
    let at = |x: u32, y: u32| parts[(y * w + x) as usize];
    assert_eq!(at(30, 44), Part::Head, "the chin under the cut");
    assert_eq!(at(30, 48), Part::Head, "the chin's last row");
    assert_eq!(at(30, 49), Part::Neck, "background below the chin");
    assert_eq!(at(37, 45), before[(45 * w + 37) as usize], "a neck stays");
    assert_ne!(at(37, 45), Part::Head);
    assert_ne!(at(24, 45), Part::Head, "too close to the background");
    for (i, (now, was)) in parts.iter().zip(&before).enumerate() {
        let (x, y) = (i as u32 % w, i as u32 / w);
        let chin = (26..35).contains(&x) && y < 49;
        assert_eq!(*now, if chin { Part::Head } else { *was }, "at ({x}, {y})");
    }
}

#[test]
fn person_pixels_apart_from_the_face_are_not_head() {
    let (w, h) = (60u32, 80u32);
    // The head fills columns 8..52 above row 42; a blob at columns 0..4, rows 25..32
    // (above the chin, beside the jaw) is apart from it.
    let mut person = vec![0u8; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let head = (8..52).contains(&x) && y < 42;
            let blob = x < 4 && (25..32).contains(&y);
            if head || blob {
                person[(y * w + x) as usize] = 255;
            }
        }
    }
    let parts = parse_frame(
        &ParsingConfig::default(),
        &person,
        &jaw(),
        [30.0, 10.0],
        w,
        h,
    );
    assert_eq!(parts[(28 * w + 2) as usize], Part::Torso);
    assert_eq!(parts[(21 * w + 9) as usize], Part::Head);
    let unseeded = parse_frame(
        &ParsingConfig::default(),
        &person,
        &jaw(),
        [2.0, 70.0],
        w,
        h,
    );
    assert!(
        unseeded.iter().all(|p| *p != Part::Head),
        "a seed off the head keeps no head"
    );
}

#[test]
fn the_background_is_the_median_where_the_person_is_away() {
    let (w, h) = (8u32, 4u32);
    let n = (w * h) as usize;
    let scene = |i: usize| [(i * 7) as u8, 100, 200];
    let mut frames = Vec::new();
    let mut people = Vec::new();
    for k in 0..5usize {
        let mut f = vec![0u8; 3 * n];
        let mut p = vec![0u8; n];
        for i in 0..n {
            f[3 * i..3 * i + 3].copy_from_slice(&scene(i));
            // The person covers column k and column 7 always; noise in frame 4.
            if i % w as usize == k || i % w as usize == 7 {
                p[i] = 255;
                f[3 * i] = 17;
            }
        }
        if k == 4 {
            f[3] = 250;
        }
        frames.push(f);
        people.push(p);
    }
    let bc = background(&frames, &people, w, h, 0);
    for i in 0..n {
        let (x, y) = ((i % 8) as u32, (i / 8) as u32);
        let want = if x == 7 { scene(i - 1) } else { scene(i) };
        assert_eq!(bc.get_pixel(x, y).0, want, "pixel {x},{y}");
    }
}
