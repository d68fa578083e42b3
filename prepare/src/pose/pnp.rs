//! One frame's head pose from its landmarks: a weak-perspective (scaled orthographic)
//! closed form, then Levenberg-Marquardt on the full perspective reprojection error.
//!
//! Frames here use OpenCV's camera axes (x right, y down, z forward, so pixel rows and the
//! camera's y agree); [`super`] turns the result into AD-NeRF's OpenGL camera-to-world.

use glam::{DMat3, DQuat, DVec2, DVec3};

use super::linalg::cholesky_solve;

/// Points closer to the camera plane than this (metres) count as behind the camera.
const MIN_DEPTH: f64 = 1e-6;

/// A head pose in the camera's OpenCV frame: face point `x` sits at `rotation * x +
/// translation` in camera space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Pose {
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Pose {
    /// The pose after a left-multiplied increment: `R <- exp([step[0..3]]) R`,
    /// `t <- t + step[3..6]`.
    pub fn stepped(&self, step: &[f64]) -> Pose {
        let omega = DVec3::new(step[0], step[1], step[2]);
        Pose {
            rotation: (DQuat::from_scaled_axis(omega) * self.rotation).normalize(),
            translation: self.translation + DVec3::new(step[3], step[4], step[5]),
        }
    }
}

/// Focal length and principal point in pixels, f64.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Pinhole {
    pub focal: f64,
    pub cx: f64,
    pub cy: f64,
}

/// One landmark's residual (projected minus observed pixel) and its derivatives.
pub(crate) struct Linearised {
    pub residual: DVec2,
    /// Rows of d(pixel)/d(camera-space point), 2 x 3.
    pub d_point: [DVec3; 2],
    /// Rows of d(pixel)/d(pose step) (rotation then translation), 2 x 6.
    pub d_pose: [[f64; 6]; 2],
}

impl Pinhole {
    /// Pixel of a camera-space point, `None` behind the camera.
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        (p.z > MIN_DEPTH).then(|| {
            DVec2::new(
                self.cx + self.focal * p.x / p.z,
                self.cy + self.focal * p.y / p.z,
            )
        })
    }

    /// The residual of face point `x` against `pixel` under `pose`, linearised; `rotated` is
    /// `R x` (passed in so callers can reuse one rotation matrix).
    pub fn linearise(&self, rot: &DMat3, t: DVec3, x: DVec3, pixel: DVec2) -> Option<Linearised> {
        let rotated = *rot * x;
        let p = rotated + t;
        let uv = self.project(p)?;
        let (f, iz) = (self.focal, 1.0 / p.z);
        let rows = [
            DVec3::new(f * iz, 0.0, -f * p.x * iz * iz),
            DVec3::new(0.0, f * iz, -f * p.y * iz * iz),
        ];
        // d p / d omega = -[R x]_x, so the pixel row j gives (R x) cross j.
        let d_pose = rows.map(|j| {
            let w = rotated.cross(j);
            [w.x, w.y, w.z, j.x, j.y, j.z]
        });
        Some(Linearised {
            residual: uv - pixel,
            d_point: rows,
            d_pose,
        })
    }
}

/// `sum_i w_i |project(R x_i + t) - u_i|^2` in pixels squared; infinite when a weighted
/// point is behind the camera.
pub(crate) fn cost(
    pose: &Pose,
    face: &[DVec3],
    pixels: &[DVec2],
    weights: &[f64],
    cam: &Pinhole,
) -> f64 {
    let rot = DMat3::from_quat(pose.rotation);
    let mut sum = 0.0;
    for ((x, u), w) in face.iter().zip(pixels).zip(weights) {
        match cam.project(rot * *x + pose.translation) {
            Some(uv) => sum += w * (uv - *u).length_squared(),
            None => return f64::INFINITY,
        }
    }
    sum
}

/// The scaled orthographic pose: the weighted least-squares affine map `A` (2 x 3) from the
/// centred face to the centred pixels is `(f / z) [r1; r2]`; its rows made orthonormal give
/// `R = [r1; r2; r1 x r2]` and the centroid's depth `z = f / s` with `s` their mean length.
/// `None` when the face is flat or the pixels collapse.
pub(crate) fn weak_perspective(
    face: &[DVec3],
    pixels: &[DVec2],
    weights: &[f64],
    cam: &Pinhole,
) -> Option<Pose> {
    let total: f64 = weights.iter().sum();
    let mut x_mean = DVec3::ZERO;
    let mut u_mean = DVec2::ZERO;
    for ((x, u), w) in face.iter().zip(pixels).zip(weights) {
        x_mean += *w * *x;
        u_mean += *w * *u;
    }
    x_mean /= total;
    u_mean /= total;
    let mut cov = DMat3::ZERO;
    let (mut bx, mut by) = (DVec3::ZERO, DVec3::ZERO);
    for ((x, u), w) in face.iter().zip(pixels).zip(weights) {
        let (dx, du) = (*x - x_mean, *u - u_mean);
        cov += DMat3::from_cols(dx * dx.x, dx * dx.y, dx * dx.z) * *w;
        bx += (*w * du.x) * dx;
        by += (*w * du.y) * dx;
    }
    let trace = cov.x_axis.x + cov.y_axis.y + cov.z_axis.z;
    let det = cov.determinant();
    if det.is_nan() || det <= 1e-9 * (trace / 3.0).powi(3) {
        return None;
    }
    let inv = cov.inverse();
    let (a1, a2) = (inv * bx, inv * by);
    let (n1, n2) = (a1.length(), a2.length());
    let (b1, b2) = (a1 / n1, a2 / n2);
    let (sum, diff) = (b1 + b2, b1 - b2);
    if !(n1 > 0.0 && n2 > 0.0) || sum.length() < 1e-6 || diff.length() < 1e-6 {
        return None;
    }
    let (m, d) = (sum.normalize(), diff.normalize());
    let r1 = (m + d) * std::f64::consts::FRAC_1_SQRT_2;
    let r2 = (m - d) * std::f64::consts::FRAC_1_SQRT_2;
    let rot = DMat3::from_cols(r1, r2, r1.cross(r2)).transpose();
    let s = 0.5 * (n1 + n2);
    let centre = rot * x_mean;
    let translation = DVec3::new(
        (u_mean.x - cam.cx) / s - centre.x,
        (u_mean.y - cam.cy) / s - centre.y,
        cam.focal / s - centre.z,
    );
    let pose = Pose {
        rotation: DQuat::from_mat3(&rot).normalize(),
        translation,
    };
    pose.translation.is_finite().then_some(pose)
}

/// The Gauss-Newton system of one frame: `J^T W J` (6 x 6, row-major) and `J^T W r`.
fn normal_equations(
    pose: &Pose,
    face: &[DVec3],
    pixels: &[DVec2],
    weights: &[f64],
    cam: &Pinhole,
) -> Option<([f64; 36], [f64; 6])> {
    let rot = DMat3::from_quat(pose.rotation);
    let mut h = [0.0; 36];
    let mut g = [0.0; 6];
    for ((x, u), w) in face.iter().zip(pixels).zip(weights) {
        let lin = cam.linearise(&rot, pose.translation, *x, *u)?;
        for (row, r) in lin.d_pose.iter().zip(lin.residual.to_array()) {
            for a in 0..6 {
                g[a] += w * row[a] * r;
                for b in 0..6 {
                    h[a * 6 + b] += w * row[a] * row[b];
                }
            }
        }
    }
    Some((h, g))
}

/// Levenberg-Marquardt on the weighted reprojection error from `pose`, at most
/// `iterations` accepted steps; stops when a step gains less than `1e-12` of the cost.
/// `None` if the pose it starts from puts a weighted point behind the camera.
pub(crate) fn refine(
    mut pose: Pose,
    face: &[DVec3],
    pixels: &[DVec2],
    weights: &[f64],
    cam: &Pinhole,
    iterations: usize,
) -> Option<Pose> {
    let mut current = cost(&pose, face, pixels, weights, cam);
    if !current.is_finite() {
        return None;
    }
    let mut lambda = 1e-3;
    for _ in 0..iterations {
        let (h, g) = normal_equations(&pose, face, pixels, weights, cam)?;
        let next = loop {
            let mut damped = h;
            for a in 0..6 {
                damped[a * 6 + a] *= 1.0 + lambda;
            }
            let mut step = g.map(|x| -x);
            if cholesky_solve(&mut damped, &mut step).is_some() {
                let candidate = pose.stepped(&step);
                let c = cost(&candidate, face, pixels, weights, cam);
                if c < current {
                    lambda = (lambda / 3.0).max(1e-12);
                    break Some((candidate, c));
                }
            }
            lambda *= 5.0;
            if lambda > 1e10 {
                break None;
            }
        };
        let Some((candidate, c)) = next else { break };
        let gain = current - c;
        pose = candidate;
        current = c;
        if gain <= 1e-12 * current {
            break;
        }
    }
    Some(pose)
}

/// The pose of one frame from scratch: [`weak_perspective`], then [`refine`].
pub(crate) fn solve_frame(
    face: &[DVec3],
    pixels: &[DVec2],
    weights: &[f64],
    cam: &Pinhole,
    iterations: usize,
) -> Option<Pose> {
    let start = weak_perspective(face, pixels, weights, cam)?;
    refine(start, face, pixels, weights, cam, iterations)
}

/// Weighted RMS reprojection error in pixels: `sqrt(cost / sum w)`.
pub(crate) fn rms_px(
    pose: &Pose,
    face: &[DVec3],
    pixels: &[DVec2],
    weights: &[f64],
    cam: &Pinhole,
) -> f64 {
    (cost(pose, face, pixels, weights, cam) / weights.iter().sum::<f64>()).sqrt()
}
