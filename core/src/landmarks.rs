//! AD-NeRF's facial landmarks: `ori_imgs/<img_id>.lms`, 68 points in the iBUG 300-W order,
//! one `x y` pair of pixel coordinates a line (as `numpy.savetxt` writes them; integer
//! coordinates are pixel centres, as in OpenCV). nldf takes the mouth region from them:
//! the polygon of the outer lip contour, points 48-59.

use std::path::Path;

use crate::error::{Error, Result};

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
