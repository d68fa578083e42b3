//! AD-NeRF's facial landmarks: `ori_imgs/<img_id>.lms`, 68 points in the iBUG 300-W order,
//! one `x y` pair of pixel coordinates a line (as `numpy.savetxt` writes them; integer
//! coordinates are pixel centres, as in OpenCV). nldf takes the mouth region from them:
//! the polygon of the outer lip contour, points 48-59.

use std::path::Path;

use crate::error::{Error, Result};
use crate::region::Region;

/// Points of a landmarks file.
pub const N_LANDMARKS: usize = 68;
/// The outer lip contour (points 48-59, in order around the lips).
pub const OUTER_LIPS: std::ops::Range<usize> = 48..60;
/// File extension of a landmarks file.
pub const LANDMARKS_EXT: &str = "lms";

/// One frame's 68 landmarks, `[x, y]` in pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Landmarks {
    pub points: Vec<[f32; 2]>,
}

impl Landmarks {
    /// Reads and checks a `.lms` file: 68 lines of two finite numbers.
    pub fn load(path: &Path) -> Result<Landmarks> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::parse(path, &text)
    }

    /// Parses a `.lms` file's text; `path` names it in errors.
    pub fn parse(path: &Path, text: &str) -> Result<Landmarks> {
        let mut points = Vec::with_capacity(N_LANDMARKS);
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let values: Vec<&str> = line
                .split(|c: char| c.is_whitespace() || c == ',')
                .filter(|s| !s.is_empty())
                .collect();
            let parsed: Option<Vec<f32>> = values.iter().map(|v| v.parse::<f32>().ok()).collect();
            match parsed.as_deref() {
                Some([x, y]) if x.is_finite() && y.is_finite() => points.push([*x, *y]),
                _ => {
                    return Err(Error::invalid(
                        path,
                        format!(
                            "line {}: expected two finite numbers `x y`, got {line:?}",
                            n + 1
                        ),
                    ));
                }
            }
        }
        if points.len() != N_LANDMARKS {
            return Err(Error::invalid(
                path,
                format!(
                    "holds {} points, expected AD-NeRF's {N_LANDMARKS}",
                    points.len()
                ),
            ));
        }
        Ok(Landmarks { points })
    }

    /// The file's text, one `x y` line a point.
    pub fn to_text(&self) -> String {
        self.points
            .iter()
            .map(|[x, y]| format!("{x:.6} {y:.6}\n"))
            .collect()
    }

    /// The mouth region: pixels whose centre lies inside the outer lip contour, row-major
    /// over a `width x height` image.
    pub fn mouth_mask(&self, width: u32, height: u32) -> Vec<bool> {
        polygon_mask(&self.points[OUTER_LIPS], width, height)
    }
}

/// The 68 landmarks a face tracker would place on a frame whose exact regions (row-major,
/// `width` wide) are known: the outer lips (48-59) on an ellipse around the mouth region
/// (half a pixel outside its outermost pixel centres), the inner lips (60-67) inside it,
/// the eyes (36-47) around the eye regions, the brows (17-26) above them, the nose
/// (27-35) between the eyes and the mouth and the jaw (0-16) along the head's lower
/// outline. A synthetic scene writes them for datasets in AD-NeRF's layout, which carry
/// no mouth label. `None` when the frame shows no mouth or no head.
pub fn landmarks_from_regions(regions: &[Region], width: u32) -> Option<Landmarks> {
    let w = width.max(1) as usize;
    let bbox = |keep: &dyn Fn(Region) -> bool| region_bbox(regions, w, keep);
    let mouth = bbox(&|r| r == Region::Mouth)?;
    let head = bbox(&|r| r.is_head())?;
    let eyes = bbox(&|r| r == Region::Eyes);
    use std::f32::consts::PI;
    let (hx, hy) = ((head[0] + head[1]) / 2.0, (head[2] + head[3]) / 2.0);
    let eye_line = eyes.map_or(hy - 0.1 * (head[3] - head[2]), |e| (e[2] + e[3]) / 2.0);
    let eye_half = eyes.map_or(0.25 * (head[1] - head[0]), |e| (e[1] - e[0]) / 4.0);
    let mut points = Vec::with_capacity(N_LANDMARKS);
    // Jaw: the lower half of the head's outline, ear to ear (image rows grow downwards, so
    // angles from pi to 0 already run below the centre).
    points.extend(ellipse_points(head, 0.0, 17, PI, 0.0));
    // Brows: five points above each eye.
    for side in [-1.0f32, 1.0] {
        let cx = hx + side * eye_half * 1.2;
        for k in 0..5 {
            let x = cx + (k as f32 - 2.0) * eye_half * 0.3;
            points.push([x, eye_line - eye_half * 0.8]);
        }
    }
    // Nose: bridge (27-30) and base (31-35).
    let mouth_top = mouth[2];
    for k in 0..4 {
        let t = (k + 1) as f32 / 5.0;
        points.push([hx, eye_line + (mouth_top - eye_line) * t * 0.8]);
    }
    for k in 0..5 {
        points.push([
            hx + (k as f32 - 2.0) * eye_half * 0.25,
            eye_line + (mouth_top - eye_line) * 0.8,
        ]);
    }
    // Eyes: six points around each.
    for side in [-1.0f32, 1.0] {
        let cx = hx + side * eye_half * 1.2;
        let b = [
            cx - eye_half * 0.5,
            cx + eye_half * 0.5,
            eye_line - 1.0,
            eye_line + 1.0,
        ];
        points.extend(ellipse_points(b, 0.0, 6, PI, PI + 2.0 * PI * 5.0 / 6.0));
    }
    // Outer lips, around the mouth region in image order; inner lips inside them.
    points.extend(ellipse_points(
        mouth,
        0.5,
        12,
        PI,
        PI + 2.0 * PI * 11.0 / 12.0,
    ));
    let inner = [
        mouth[0] + 1.0,
        mouth[1] - 1.0,
        mouth[2] + 1.0,
        mouth[3] - 1.0,
    ];
    points.extend(ellipse_points(inner, 0.0, 8, PI, PI + 2.0 * PI * 7.0 / 8.0));
    debug_assert_eq!(points.len(), N_LANDMARKS);
    Some(Landmarks { points })
}

/// The box `[x0, x1, y0, y1]` of the pixel centres (row-major, `w` wide) whose region
/// `keep` accepts; `None` when it accepts none.
fn region_bbox(regions: &[Region], w: usize, keep: &dyn Fn(Region) -> bool) -> Option<[f32; 4]> {
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
    for (p, &r) in regions.iter().enumerate() {
        if keep(r) {
            let (x, y) = (p % w, p / w);
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    }
    (x0 != usize::MAX).then_some([x0 as f32, x1 as f32, y0 as f32, y1 as f32])
}

/// `n` points from angle `from` to `to` on the ellipse inscribed in the box
/// `[x0, x1, y0, y1]` grown by `pad`.
fn ellipse_points(b: [f32; 4], pad: f32, n: usize, from: f32, to: f32) -> Vec<[f32; 2]> {
    let (cx, cy) = ((b[0] + b[1]) / 2.0, (b[2] + b[3]) / 2.0);
    let (rx, ry) = ((b[1] - b[0]) / 2.0 + pad, (b[3] - b[2]) / 2.0 + pad);
    (0..n)
        .map(|k| {
            let t = if n > 1 {
                k as f32 / (n - 1) as f32
            } else {
                0.0
            };
            let a = from + (to - from) * t;
            [cx + rx * a.cos(), cy + ry * a.sin()]
        })
        .collect()
}

/// Pixels (row-major) whose centre `(i, j)` lies inside `polygon` (even-odd rule).
pub fn polygon_mask(polygon: &[[f32; 2]], width: u32, height: u32) -> Vec<bool> {
    let mut mask = vec![false; width as usize * height as usize];
    if polygon.len() < 3 {
        return mask;
    }
    let (mut y_lo, mut y_hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for p in polygon {
        y_lo = y_lo.min(p[1]);
        y_hi = y_hi.max(p[1]);
    }
    let rows =
        (y_lo.ceil().max(0.0) as u32)..((y_hi.floor() + 1.0).clamp(0.0, height as f32) as u32);
    for j in rows {
        let y = j as f32;
        for i in 0..width {
            let x = i as f32;
            let mut inside = false;
            for (a, b) in polygon.iter().zip(polygon.iter().cycle().skip(1)) {
                if (a[1] > y) != (b[1] > y) {
                    let cross = a[0] + (y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                    if x < cross {
                        inside = !inside;
                    }
                }
            }
            mask[(j * width + i) as usize] = inside;
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Landmarks placed from exact regions put their lip polygon on the mouth: it covers
    /// most of the mouth's pixels and little else.
    /// A 40 x 40 frame's regions: an elliptic head (columns 8..=32, rows 4..=36) with an
    /// elliptic mouth below its centre.
    fn head_with_mouth() -> (Vec<Region>, u32, u32) {
        let (w, h) = (40u32, 40u32);
        let mut regions = vec![Region::Background; (w * h) as usize];
        for j in 0..h {
            for i in 0..w {
                let p = (j * w + i) as usize;
                let (x, y) = (i as f32 - 20.0, j as f32 - 20.0);
                if (x / 12.0).powi(2) + (y / 16.0).powi(2) <= 1.0 {
                    regions[p] = Region::Face;
                }
                if (x / 5.0).powi(2) + ((y - 9.0) / 2.5).powi(2) <= 1.0 {
                    regions[p] = Region::Mouth;
                }
            }
        }
        (regions, w, h)
    }

    #[test]
    fn landmarks_from_regions_outline_the_mouth() {
        let (regions, w, h) = head_with_mouth();
        let lms = landmarks_from_regions(&regions, w).unwrap();
        assert_eq!(lms.points.len(), N_LANDMARKS);
        let mask = lms.mouth_mask(w, h);
        let exact: Vec<bool> = regions.iter().map(|r| *r == Region::Mouth).collect();
        let both = mask.iter().zip(&exact).filter(|(a, b)| **a && **b).count();
        let (m, e) = (
            mask.iter().filter(|&&v| v).count(),
            exact.iter().filter(|&&v| v).count(),
        );
        assert!(both as f64 >= 0.85 * e as f64, "covers {both} of {e}");
        assert!(
            both as f64 >= 0.75 * m as f64,
            "{both} of its {m} on the mouth"
        );
        // No mouth, no landmarks.
        let no_mouth: Vec<Region> = regions
            .iter()
            .map(|&r| if r == Region::Mouth { Region::Face } else { r })
            .collect();
        assert!(landmarks_from_regions(&no_mouth, w).is_none());
    }

    /// The jaw (0-16) runs along the lower half of the head's outline, ear to ear: no point
    /// above the head's centre row, the chin (8) on the head's lowest row below the mouth.
    #[test]
    fn the_jaw_runs_below_the_head_centre_to_the_chin() {
        let (regions, w, _) = head_with_mouth();
        let lms = landmarks_from_regions(&regions, w).unwrap();
        // The head's pixel rows span 4..=36 (centre 20), its columns 8..=32.
        for (k, [x, y]) in lms.points[..17].iter().enumerate() {
            assert!(
                *y >= 20.0 - 1e-3,
                "jaw point {k} at row {y}, above the centre"
            );
            assert!(
                (8.0 - 1e-3..=32.0 + 1e-3).contains(x),
                "jaw point {k} at column {x}"
            );
        }
        let chin = lms.points[8];
        assert!((chin[1] - 36.0).abs() < 1e-3, "chin at row {}", chin[1]);
        let lowest_lip = lms.points[48..60]
            .iter()
            .map(|p| p[1])
            .fold(f32::MIN, f32::max);
        assert!(
            chin[1] > lowest_lip,
            "chin {} above the lips {lowest_lip}",
            chin[1]
        );
        // Ear to ear: the ends on the head's widest columns, at its centre row.
        assert!((lms.points[0][0] - 8.0).abs() < 1e-3 && (lms.points[16][0] - 32.0).abs() < 1e-3);
    }

    #[test]
    fn a_square_covers_its_inner_pixel_centres() {
        let square = [[1.5, 1.5], [4.5, 1.5], [4.5, 3.5], [1.5, 3.5]];
        let mask = polygon_mask(&square, 6, 5);
        let inside: Vec<(u32, u32)> = (0..30u32)
            .filter(|&p| mask[p as usize])
            .map(|p| (p % 6, p / 6))
            .collect();
        assert_eq!(inside, vec![(2, 2), (3, 2), (4, 2), (2, 3), (3, 3), (4, 3)]);
    }

    #[test]
    fn a_polygon_off_the_image_covers_nothing() {
        let far = [[-10.0, -10.0], [-5.0, -10.0], [-5.0, -5.0]];
        assert!(polygon_mask(&far, 4, 4).iter().all(|&m| !m));
        let huge = [[-1e30, -1e30], [1e30, -1e30], [1e30, 1e30], [-1e30, 1e30]];
        assert!(polygon_mask(&huge, 4, 4).iter().all(|&m| m));
    }

    #[test]
    fn a_landmarks_file_needs_68_finite_pairs() {
        let p = Path::new("0.lms");
        let good: String = (0..68).map(|k| format!("{k}.5 {}.25\n", 2 * k)).collect();
        let lms = Landmarks::parse(p, &good).unwrap();
        assert_eq!(lms.points[48], [48.5, 96.25]);
        assert_eq!(Landmarks::parse(p, &lms.to_text()).unwrap(), lms);
        let short: String = (0..67).map(|k| format!("{k} {k}\n")).collect();
        let err = Landmarks::parse(p, &short).unwrap_err().to_string();
        assert!(err.contains("67 points") && err.contains("0.lms"), "{err}");
        let nan = good.replacen("0.5 0.25", "nan 1", 1);
        assert!(
            Landmarks::parse(p, &nan)
                .unwrap_err()
                .to_string()
                .contains("line 1")
        );
    }
}
