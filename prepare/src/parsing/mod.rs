//! Parsing masks in AD-NeRF's colours from a person mask and the face's jaw line, and the
//! background without the person.
//!
//! A person pixel is head (with hair and ears) above the jaw line (widened by
//! [`JAW_MARGIN`]), neck below the jaw close under the chin, torso elsewhere below it.
//! Beside the jaw (left of its first point, right of its last) the head reaches down to the
//! chin's height. Below the cut, a column's run of person pixels that differ from the
//! background and end in background within [`HANG_DEPTH`] is head too ([`hang_below_jaw`]):
//! a chin or jaw corner the landmarks' jaw line does not reach.

use image::{Rgb, RgbImage};
use serde::{Deserialize, Serialize};

/// AD-NeRF's parsing labels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    Background,
    Head,
    Neck,
    Torso,
}

impl Part {
    /// AD-NeRF's colour (RGB): head blue, neck green, torso red, background white.
    pub fn colour(self) -> [u8; 3] {
        match self {
            Part::Background => [255, 255, 255],
            Part::Head => [0, 0, 255],
            Part::Neck => [0, 255, 0],
            Part::Torso => [255, 0, 0],
        }
    }
}

/// How far the head reaches past the landmarks' jaw line, as a share of the line's size
/// ([`widened`]): mediapipe's jaw points sit inside the head's outline, and a head mask cut
/// there leaves the jaw's edge out of the head, and so out of `head_imgs/` (where it becomes
/// background) and out of the head's renders. A mask too large costs less: the pixels it
/// takes in are the frame's own. Chosen on the test videos of both synthetic heads
/// (`scripts/prepare_check.sh`): pooled head IoU at 128 from the 512 videos, standard /
/// second head, 0.965 / 0.954 at 0.1, 0.959 / 0.968 at 0.15, 0.943 / 0.967 at 0.2; at 0.1
/// the second head's chin fell outside its masks and its models drew none. On a real
/// person it takes a strip of the neck under the chin into the head.
pub const JAW_MARGIN: f32 = 0.15;

/// The parts of a `width x height` frame from its person probability (0-255, row-major),
/// its jaw line (pixels, image left to right; the chin is its middle point) and a point on
/// the face (`seed`, the nose, say): the head is the part above the cut (the jaw line
/// widened by `config.jaw_margin`) that holds the seed; person pixels above the cut but apart
/// from it are torso.
pub fn parse_frame(
    config: &ParsingConfig,
    person: &[u8],
    jaw: &[[f32; 2]],
    seed: [f32; 2],
    width: u32,
    height: u32,
) -> Vec<Part> {
    let (w, h) = (width as usize, height as usize);
    let mut parts = vec![Part::Background; w * h];
    if jaw.len() < 3 || person.len() != w * h {
        return parts;
    }
    let Cut {
        jaw,
        chin,
        depth,
        x_min,
        x_max,
    } = Cut::new(jaw, config.jaw_margin);
    let jaw = &jaw;
    let neck_depth = 0.6 * depth;
    let inner_min = jaw[jaw.len() / 4][0].min(jaw[3 * jaw.len() / 4][0]);
    let inner_max = jaw[jaw.len() / 4][0].max(jaw[3 * jaw.len() / 4][0]);
    let mid = jaw.len() / 2;
    let side = config.ear_points.min(mid);
    let (left, right) = (&jaw[..=mid], &jaw[mid..]);
    // Beside the jaw's upper points (outside its arms, down to the height of point `side`
    // from each end) the head goes on: the ears and the side of the head.
    let beside = |xc: f32, yc: f32| {
        let outside_left = yc <= jaw[side][1] && arm_x(left, yc).is_some_and(|a| xc < a);
        let right_floor = jaw[jaw.len() - 1 - side][1];
        let outside_right = yc <= right_floor && arm_x(right, yc).is_some_and(|a| xc > a);
        side > 0 && (outside_left || outside_right)
    };
    for x in 0..w {
        let xc = x as f32 + 0.5;
        let cut = if xc >= x_min && xc <= x_max {
            lowest_crossing(jaw, xc).unwrap_or(chin[1])
        } else {
            chin[1]
        };
        for y in 0..h {
            let i = y * w + x;
            if person[i] < 128 {
                continue;
            }
            let yc = y as f32 + 0.5;
            parts[i] = if yc <= cut || beside(xc, yc) {
                Part::Head
            } else if xc >= inner_min && xc <= inner_max && yc <= chin[1] + neck_depth {
                Part::Neck
            } else {
                Part::Torso
            };
        }
    }
    keep_connected_head(&mut parts, seed, w, h);
    parts
}

/// How far below the jaw cut a hanging part of the head may reach, as a share of the jaw's
/// depth (from its highest point to the chin): a run of foreground pixels longer than this
/// below the cut is a neck, not a chin. Chosen on the tuning videos (seed 0, the 512 videos
/// prepared at 128; `scripts/prepare_parsing_sweep.sh`): pooled head IoU, standard / second
/// head, 0.9664 / 0.9797 without the step, 0.9678 / 0.9866 at 0.25, 0.9680 / 0.9871 at 0.4
/// and at 0.6.
pub const HANG_DEPTH: f32 = 0.4;

/// The smallest difference from the background plate (0-255, the largest of the three
/// channels) that makes a pixel foreground in [`hang_below_jaw`]. Chosen on the tuning
/// videos with [`HANG_DEPTH`]: at 0.4, 12 / 24 / 40 give pooled IoU 0.9682 / 0.9680 / 0.9675
/// (standard) and 0.9869 / 0.9871 / 0.9867 (second head).
pub const FOREGROUND_DIFF: u8 = 24;

/// Where a frame's person splits into head, neck and torso: the settings of [`parse_frame`]
/// and [`hang_below_jaw`], saved in `prepare.json`. Each default is its constant's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ParsingConfig {
    /// How far the head's cut lies past the jaw line, as a share of the line's size
    /// (default [`JAW_MARGIN`], 0.15).
    pub jaw_margin: f32,
    /// How far below the cut a hanging chin may reach, as a share of the jaw's depth
    /// (default [`HANG_DEPTH`], 0.4); 0 turns [`hang_below_jaw`] off.
    pub hang_depth: f32,
    /// The smallest difference from the background plate that is foreground (default
    /// [`FOREGROUND_DIFF`], 24 of 255).
    pub foreground_diff: u8,
    /// Beside the jaw line's arms, the head reaches down to the height of this point from
    /// each end (default [`EAR_POINTS`]); 0 cuts the head at the arms.
    pub ear_points: usize,
}

impl Default for ParsingConfig {
    fn default() -> Self {
        Self {
            jaw_margin: JAW_MARGIN,
            hang_depth: HANG_DEPTH,
            foreground_diff: FOREGROUND_DIFF,
            ear_points: EAR_POINTS,
        }
    }
}

/// Beside the jaw line's arms the head reaches down to the height of the arm's point
/// `EAR_POINTS` from its end: a head that turns shows an ear outside the jaw line, and a cut
/// along the arm drops it from the head. Chosen on the tuning videos
/// (`scripts/prepare_parsing_sweep.sh`): pooled head IoU, standard / second head, 0.9680 /
/// 0.9871 along the arms (0), 0.9681 / 0.9875 at 2 and at 3, 0.9549 / 0.9875 at 4 (where
/// the standard head's worst frame fell to 0.79: the segmenter's shoulders joined the head).
pub const EAR_POINTS: usize = 2;

/// A frame's colours and its background plate (RGB, row-major, the parsing's size), for
/// [`hang_below_jaw`].
#[derive(Debug, Clone, Copy)]
pub struct Plate<'a> {
    pub frame: &'a [u8],
    pub background: &'a [u8],
}

/// Turns into head what hangs below the jaw cut and ends in background: in each column of
/// the (widened) jaw line, the run of pixels straight below the cut that are person and
/// differ from the background by at least `config.foreground_diff`, when the run ends
/// within `config.hang_depth` of the jaw's depth. A run that goes on is a neck and stays as
/// it is. The landmarks' jaw line misses a chin when the mouth opens wider than the face
/// tracker follows; a segmenter that draws a neck below every head cannot show where the
/// chin ends, the background plate can.
pub fn hang_below_jaw(
    config: &ParsingConfig,
    parts: &mut [Part],
    person: &[u8],
    plate: Plate,
    jaw: &[[f32; 2]],
    width: u32,
    height: u32,
) {
    let (w, h) = (width as usize, height as usize);
    let n = w * h;
    let planes = [plate.frame.len(), plate.background.len()];
    if jaw.len() < 3 || person.len() != n || planes != [3 * n, 3 * n] {
        return;
    }
    let Cut {
        jaw,
        depth,
        x_min,
        x_max,
        ..
    } = Cut::new(jaw, config.jaw_margin);
    let jaw = &jaw;
    let reach = (config.hang_depth.max(0.0) * depth).ceil() as usize;
    let foreground = |i: usize| {
        let d = (0..3)
            .map(|c| plate.frame[3 * i + c].abs_diff(plate.background[3 * i + c]))
            .max()
            .unwrap_or(0);
        person[i] >= 128 && d >= config.foreground_diff
    };
    for x in 0..w {
        let xc = x as f32 + 0.5;
        if xc < x_min || xc > x_max {
            continue;
        }
        let Some(cut) = lowest_crossing(jaw, xc) else {
            continue;
        };
        // The first row whose centre lies below the cut.
        let first = (cut - 0.5).floor().max(-1.0) as i64 + 1;
        if first <= 0 || first as usize >= h || parts[(first as usize - 1) * w + x] != Part::Head {
            continue;
        }
        let first = first as usize;
        let run = (first..h)
            .take(reach + 1)
            .take_while(|&y| foreground(y * w + x))
            .count();
        let ends = run <= reach && first + run < h;
        if ends {
            for y in first..first + run {
                parts[y * w + x] = Part::Head;
            }
        }
    }
}

/// The head's cut of a frame: the jaw line widened by a margin ([`widened`]), its chin (the
/// middle point), its depth from its highest point to the chin (at least 1 pixel) and its
/// horizontal span.
struct Cut {
    jaw: Vec<[f32; 2]>,
    chin: [f32; 2],
    depth: f32,
    x_min: f32,
    x_max: f32,
}

impl Cut {
    fn new(jaw: &[[f32; 2]], margin: f32) -> Self {
        let jaw = widened(jaw, margin);
        let chin = jaw[jaw.len() / 2];
        let top = jaw.iter().map(|p| p[1]).fold(f32::INFINITY, f32::min);
        let x_min = jaw.iter().map(|p| p[0]).fold(f32::INFINITY, f32::min);
        let x_max = jaw.iter().map(|p| p[0]).fold(f32::NEG_INFINITY, f32::max);
        Self {
            chin,
            depth: (chin[1] - top).max(1.0),
            x_min,
            x_max,
            jaw,
        }
    }
}

/// The jaw line scaled by `1 + margin` about the point below the middle of its two ends, at
/// their height, on the chin's column: its sides move out and its chin down.
fn widened(jaw: &[[f32; 2]], margin: f32) -> Vec<[f32; 2]> {
    let (first, last) = (jaw[0], jaw[jaw.len() - 1]);
    let centre = [jaw[jaw.len() / 2][0], 0.5 * (first[1] + last[1])];
    jaw.iter()
        .map(|p| {
            [
                centre[0] + (1.0 + margin) * (p[0] - centre[0]),
                centre[1] + (1.0 + margin) * (p[1] - centre[1]),
            ]
        })
        .collect()
}

/// Turns head pixels that are not 4-connected to `seed` into torso.
fn keep_connected_head(parts: &mut [Part], seed: [f32; 2], w: usize, h: usize) {
    let (sx, sy) = (seed[0].floor(), seed[1].floor());
    let inside = sx >= 0.0 && sy >= 0.0 && (sx as usize) < w && (sy as usize) < h;
    let start = inside.then(|| sy as usize * w + sx as usize);
    let mut reached = vec![false; w * h];
    if let Some(s) = start.filter(|&s| parts[s] == Part::Head) {
        let mut stack = vec![s];
        reached[s] = true;
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            let mut near = [None; 4];
            near[0] = (x > 0).then(|| i - 1);
            near[1] = (x + 1 < w).then(|| i + 1);
            near[2] = (y > 0).then(|| i - w);
            near[3] = (y + 1 < h).then(|| i + w);
            for j in near.into_iter().flatten() {
                if !reached[j] && parts[j] == Part::Head {
                    reached[j] = true;
                    stack.push(j);
                }
            }
        }
    }
    for (p, r) in parts.iter_mut().zip(&reached) {
        if *p == Part::Head && !r {
            *p = Part::Torso;
        }
    }
}

/// Where one arm of the jaw line (a polyline from an end to the chin, or back) is at height
/// `y`: the x of its first segment from the top that spans `y`.
fn arm_x(arm: &[[f32; 2]], y: f32) -> Option<f32> {
    crossings(arm, 1, y).next()
}

/// The largest y at which the polyline crosses the vertical line at `x`.
fn lowest_crossing(line: &[[f32; 2]], x: f32) -> Option<f32> {
    crossings(line, 0, x).reduce(f32::max)
}

/// Where the polyline's segments cross the line on which coordinate `axis` (0 for x, 1 for
/// y) is `at`: the other coordinate, segment by segment in order (a segment that lies along
/// the line gives its middle).
fn crossings(line: &[[f32; 2]], axis: usize, at: f32) -> impl Iterator<Item = f32> + '_ {
    let other = 1 - axis;
    line.windows(2).filter_map(move |s| {
        let (a0, a1) = (s[0][axis], s[1][axis]);
        let (lo, hi) = (a0.min(a1), a0.max(a1));
        if at < lo || at > hi {
            return None;
        }
        let t = if hi - lo < 1e-6 {
            0.5
        } else {
            (at - a0) / (a1 - a0)
        };
        Some(s[0][other] + t * (s[1][other] - s[0][other]))
    })
}

/// The parts drawn in AD-NeRF's colours.
pub fn parsing_image(parts: &[Part], width: u32, height: u32) -> RgbImage {
    RgbImage::from_fn(width, height, |x, y| {
        Rgb(parts[(y * width + x) as usize].colour())
    })
}

/// The head's bounding box `[x, y, w, h]` (AD-NeRF's `face_rect`), `None` without a head.
pub fn head_rect(parts: &[Part], width: u32) -> Option<[u32; 4]> {
    let w = width as usize;
    let mut b = [u32::MAX, u32::MAX, 0, 0];
    for (i, _) in parts.iter().enumerate().filter(|(_, p)| **p == Part::Head) {
        let (x, y) = ((i % w) as u32, (i / w) as u32);
        b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
    }
    (b[0] != u32::MAX).then(|| [b[0], b[1], b[2] - b[0] + 1, b[3] - b[1] + 1])
}

/// The background without the person, from frames sampled over the clip: each pixel is the
/// per-channel median of the frames where neither the person nor its `margin`-pixel
/// surroundings cover it; pixels the person always covers take the nearest known pixel's
/// colour. `frames` are RGB, `people` their person probabilities.
pub fn background(
    frames: &[Vec<u8>],
    people: &[Vec<u8>],
    width: u32,
    height: u32,
    margin: u32,
) -> RgbImage {
    let (w, h) = (width as usize, height as usize);
    let free: Vec<Vec<bool>> = people
        .iter()
        .map(|p| {
            dilate(
                &p.iter().map(|&v| v >= 64).collect::<Vec<_>>(),
                w,
                h,
                margin as usize,
            )
        })
        .map(|covered| covered.into_iter().map(|c| !c).collect())
        .collect();
    let mut out = vec![[0u8; 3]; w * h];
    let mut known = vec![false; w * h];
    let mut values: [Vec<u8>; 3] = Default::default();
    for i in 0..w * h {
        for v in values.iter_mut() {
            v.clear();
        }
        for (frame, f) in frames.iter().zip(&free) {
            if f[i] {
                for (c, v) in values.iter_mut().enumerate() {
                    v.push(frame[3 * i + c]);
                }
            }
        }
        if values[0].is_empty() {
            continue;
        }
        for (c, v) in values.iter_mut().enumerate() {
            let mid = v.len() / 2;
            out[i][c] = *v.select_nth_unstable(mid).1;
        }
        known[i] = true;
    }
    fill_nearest(&mut out, &mut known, w, h);
    RgbImage::from_fn(width, height, |x, y| Rgb(out[y as usize * w + x as usize]))
}

/// `mask` grown by `r` pixels (a square neighbourhood, two separable passes).
fn dilate(mask: &[bool], w: usize, h: usize, r: usize) -> Vec<bool> {
    if r == 0 {
        return mask.to_vec();
    }
    let mut rows = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let (a, b) = (x.saturating_sub(r), (x + r).min(w - 1));
            rows[y * w + x] = mask[y * w + a..=y * w + b].iter().any(|&m| m);
        }
    }
    let mut out = vec![false; w * h];
    for y in 0..h {
        let (a, b) = (y.saturating_sub(r), (y + r).min(h - 1));
        for x in 0..w {
            out[y * w + x] = (a..=b).any(|yy| rows[yy * w + x]);
        }
    }
    out
}

/// Gives every unknown pixel the colour of the nearest known one (breadth first, 4-connected).
fn fill_nearest(out: &mut [[u8; 3]], known: &mut [bool], w: usize, h: usize) {
    let mut queue: std::collections::VecDeque<usize> = (0..w * h).filter(|&i| known[i]).collect();
    while let Some(i) = queue.pop_front() {
        let (x, y) = (i % w, i / w);
        let mut visit = |j: usize| {
            if !known[j] {
                known[j] = true;
                out[j] = out[i];
                queue.push_back(j);
            }
        };
        if x > 0 {
            visit(i - 1);
        }
        if x + 1 < w {
            visit(i + 1);
        }
        if y > 0 {
            visit(i - w);
        }
        if y + 1 < h {
            visit(i + w);
        }
    }
}

#[cfg(test)]
mod tests;
