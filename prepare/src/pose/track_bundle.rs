//! The track bundle: the 3D points of feature tracks and the poses of key frames refined
//! together, each point seen in only some of the frames.
//!
//! It minimises, over key-frame poses `(R_f, t_f)` and points `X_j`,
//!
//! `E = sum_(f,j observed) rho(|pi(R_f X_j + t_f) - u_fj|)`
//!
//! with Huber's loss `rho(e) = e^2` for `e <= delta`, `2 delta e - delta^2` beyond (pixels),
//! by Levenberg-Marquardt on iteratively reweighted normal equations (weight `1` inside
//! `delta`, `delta / e` beyond). The points are eliminated by the Schur complement, so each
//! step solves a dense system in the poses alone (`6 (n_keys - 1)` unknowns): the first key
//! frame's pose stays fixed (six of the seven directions the pixels leave free); the
//! world's scale, the seventh, is held by the damping and set afterwards by the caller.

use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::linalg::cholesky_solve;
use super::pnp::{Pinhole, Pose};

/// One observation: track point `point` seen at `pixel` in key frame `key`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Observation {
    pub key: usize,
    pub point: usize,
    pub pixel: DVec2,
}

/// The data of a track bundle problem.
pub(crate) struct TrackBundle<'a> {
    /// Observations, at most one per key frame and point.
    pub observations: &'a [Observation],
    pub cam: Pinhole,
    /// Huber's `delta`, pixels.
    pub huber_px: f64,
}

/// Huber's loss of a residual of length `e`, and the weight of its squared residual in the
/// reweighted normal equations.
pub(crate) fn huber(e: f64, delta: f64) -> (f64, f64) {
    if e <= delta {
        (e * e, 1.0)
    } else {
        (2.0 * delta * e - delta * delta, delta / e)
    }
}

/// One observation linearised: `J_pose^T w J_point` (6 x 3, columns), its key and point.
struct Coupling {
    key: usize,
    point: usize,
    w: [DVec3; 6],
}

/// The reweighted normal equations: pose blocks `U_f` (6 x 6, row-major) and gradients,
/// point blocks `V_j` and gradients, and the couplings.
struct Normal {
    u: Vec<[f64; 36]>,
    g: Vec<[f64; 6]>,
    v: Vec<DMat3>,
    gx: Vec<DVec3>,
    couplings: Vec<Coupling>,
}

impl TrackBundle<'_> {
    /// The projection residual of one observation, `None` behind the camera.
    fn residual(&self, poses: &[Pose], points: &[DVec3], o: &Observation) -> Option<DVec2> {
        let pose = &poses[o.key];
        let p = pose.rotation * points[o.point] + pose.translation;
        self.cam.project(p).map(|uv| uv - o.pixel)
    }

    /// `E` at `poses` and `points`; infinite when a point is behind a camera.
    pub fn cost(&self, poses: &[Pose], points: &[DVec3]) -> f64 {
        self.observations
            .par_iter()
            .map(|o| {
                self.residual(poses, points, o)
                    .map_or(f64::INFINITY, |r| huber(r.length(), self.huber_px).0)
            })
            .sum()
    }

    /// Per point, the RMS of its residuals (pixels); infinite behind a camera.
    pub fn point_rms(&self, poses: &[Pose], points: &[DVec3]) -> Vec<f64> {
        let mut sum = vec![0.0; points.len()];
        let mut count = vec![0usize; points.len()];
        for o in self.observations {
            sum[o.point] += self
                .residual(poses, points, o)
                .map_or(f64::INFINITY, |r| r.length_squared());
            count[o.point] += 1;
        }
        sum.iter()
            .zip(&count)
            .map(|(s, &c)| (s / c.max(1) as f64).sqrt())
            .collect()
    }

    fn linearise(&self, poses: &[Pose], points: &[DVec3]) -> Option<Normal> {
        let rotations: Vec<DMat3> = poses.iter().map(|p| DMat3::from_quat(p.rotation)).collect();
        let mut normal = Normal {
            u: vec![[0.0; 36]; poses.len()],
            g: vec![[0.0; 6]; poses.len()],
            v: vec![DMat3::ZERO; points.len()],
            gx: vec![DVec3::ZERO; points.len()],
            couplings: Vec::with_capacity(self.observations.len()),
        };
        for o in self.observations {
            let rot = &rotations[o.key];
            let lin =
                self.cam
                    .linearise(rot, poses[o.key].translation, points[o.point], o.pixel)?;
            let (_, w) = huber(lin.residual.length(), self.huber_px);
            let residual = lin.residual.to_array();
            let mut coupling = Coupling {
                key: o.key,
                point: o.point,
                w: [DVec3::ZERO; 6],
            };
            let (u, g) = (&mut normal.u[o.key], &mut normal.g[o.key]);
            for ((pose_row, point_row), r) in lin.d_pose.iter().zip(lin.d_point).zip(residual) {
                // d pixel / d X = d pixel / d p * R.
                let point_row = rot.transpose() * point_row;
                for a in 0..6 {
                    g[a] += w * pose_row[a] * r;
                    for b in 0..6 {
                        u[a * 6 + b] += w * pose_row[a] * pose_row[b];
                    }
                    coupling.w[a] += (w * pose_row[a]) * point_row;
                }
                normal.v[o.point] += outer(point_row, point_row) * w;
                normal.gx[o.point] += (w * r) * point_row;
            }
            normal.couplings.push(coupling);
        }
        Some(normal)
    }

    /// The damped Gauss-Newton step `(d poses, d points)` to add, by the Schur complement on
    /// the points; the first pose's step is zero.
    fn step(&self, normal: &Normal, lambda: f64) -> Option<(Vec<[f64; 6]>, Vec<DVec3>)> {
        let n_keys = normal.u.len();
        let v_inv: Vec<DMat3> = normal
            .v
            .iter()
            .map(|v| {
                let mut d = *v;
                d.x_axis.x *= 1.0 + lambda;
                d.y_axis.y *= 1.0 + lambda;
                d.z_axis.z *= 1.0 + lambda;
                d.inverse()
            })
            .collect();
        // Y_o = W_o V_j^-1, column k of the 6 x 3 block as `y[o][a][k]`.
        let y: Vec<[DVec3; 6]> = normal
            .couplings
            .iter()
            .map(|c| c.w.map(|row| v_inv[c.point].transpose() * row))
            .collect();
        let (mut s, mut rhs) = self.reduced_system(normal, &y, lambda)?;
        cholesky_solve(&mut s, &mut rhs)?;
        let mut d_poses = vec![[0.0; 6]; n_keys];
        for (f, d) in d_poses.iter_mut().enumerate().skip(1) {
            for a in 0..6 {
                d[a] = -rhs[6 * (f - 1) + a];
            }
        }
        // d X_j = -V_j^-1 (gx_j + sum_f W_fj^T d c_f).
        let mut b = normal.gx.clone();
        for c in &normal.couplings {
            let dc = &d_poses[c.key];
            for (a, row) in c.w.iter().enumerate() {
                b[c.point] += dc[a] * *row;
            }
        }
        let d_points = b.iter().zip(&v_inv).map(|(b, vi)| -(*vi * *b)).collect();
        Some((d_poses, d_points))
    }

    /// `S = blockdiag(U_f) - sum_j W_j V_j^-1 W_j^T` and `g_f - sum_j W_fj V_j^-1 gx_j` over
    /// the free poses (all but the first), dense and row-major.
    fn reduced_system(
        &self,
        normal: &Normal,
        y: &[[DVec3; 6]],
        lambda: f64,
    ) -> Option<(Vec<f64>, Vec<f64>)> {
        let n = normal.u.len() - 1;
        let dim = 6 * n;
        let mut by_point: Vec<Vec<usize>> = vec![Vec::new(); normal.v.len()];
        let mut by_key: Vec<Vec<usize>> = vec![Vec::new(); normal.u.len()];
        for (i, c) in normal.couplings.iter().enumerate() {
            by_point[c.point].push(i);
            by_key[c.key].push(i);
        }
        let rows: Vec<(Vec<f64>, [f64; 6])> = (1..=n)
            .into_par_iter()
            .map(|f| {
                let mut row = vec![0.0; 6 * dim];
                let mut rhs = normal.g[f];
                for a in 0..6 {
                    for b in 0..6 {
                        let u = normal.u[f][a * 6 + b];
                        row[a * dim + 6 * (f - 1) + b] =
                            if a == b { u * (1.0 + lambda) } else { u };
                    }
                }
                for &i in &by_key[f] {
                    let point = normal.couplings[i].point;
                    for a in 0..6 {
                        rhs[a] -= y[i][a].dot(normal.gx[point]);
                    }
                    for &k in &by_point[point] {
                        let other = &normal.couplings[k];
                        if other.key == 0 {
                            continue;
                        }
                        let col = 6 * (other.key - 1);
                        for a in 0..6 {
                            for b in 0..6 {
                                row[a * dim + col + b] -= y[i][a].dot(other.w[b]);
                            }
                        }
                    }
                }
                (row, rhs)
            })
            .collect();
        let mut s = Vec::with_capacity(dim * dim);
        let mut rhs = Vec::with_capacity(dim);
        for (row, r) in rows {
            s.extend(row);
            rhs.extend(r);
        }
        s.iter()
            .chain(&rhs)
            .all(|x| x.is_finite())
            .then_some((s, rhs))
    }

    /// Levenberg-Marquardt from `poses` and `points`, at most `iterations` accepted steps;
    /// stops when a step gains less than `1e-9` of `E`. Returns the refined poses and points
    /// (the inputs when no step helps).
    pub fn run(
        &self,
        mut poses: Vec<Pose>,
        mut points: Vec<DVec3>,
        iterations: usize,
    ) -> (Vec<Pose>, Vec<DVec3>) {
        let mut current = self.cost(&poses, &points);
        let mut lambda = 1e-3;
        if poses.len() < 2 || !current.is_finite() {
            return (poses, points);
        }
        for _ in 0..iterations {
            let Some(normal) = self.linearise(&poses, &points) else {
                break;
            };
            let accepted = loop {
                if let Some((dc, dx)) = self.step(&normal, lambda) {
                    let p: Vec<Pose> = poses.iter().zip(&dc).map(|(p, d)| p.stepped(d)).collect();
                    let x: Vec<DVec3> = points.iter().zip(&dx).map(|(x, d)| *x + *d).collect();
                    let c = self.cost(&p, &x);
                    if c < current {
                        lambda = (lambda / 3.0).max(1e-9);
                        break Some((p, x, c));
                    }
                }
                lambda *= 5.0;
                if lambda > 1e10 {
                    break None;
                }
            };
            let Some((p, x, c)) = accepted else { break };
            let gain = current - c;
            (poses, points, current) = (p, x, c);
            if gain <= 1e-9 * current {
                break;
            }
        }
        (poses, points)
    }
}

/// `a b^T`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

#[cfg(test)]
mod tests {
    use glam::DQuat;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::pose::linalg::angle_between;

    const CAM: Pinhole = Pinhole {
        focal: 1300.0,
        cx: 256.0,
        cy: 256.0,
    };

    /// Key poses turning the head up to 20 degrees about varied axes, 1 m in front.
    fn key_poses(n: usize) -> Vec<Pose> {
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64 * std::f64::consts::TAU;
                Pose {
                    rotation: DQuat::from_scaled_axis(DVec3::new(
                        0.15 * (1.3 * t).sin(),
                        0.35 * t.sin(),
                        0.1 * (0.7 * t).cos(),
                    )),
                    translation: DVec3::new(0.01 * t.cos(), -0.01, 1.0 + 0.02 * t.sin()),
                }
            })
            .collect()
    }

    /// Exact observations of `points` in windows of the key frames.
    fn observe(poses: &[Pose], points: &[DVec3]) -> Vec<Observation> {
        let mut out = Vec::new();
        for (j, x) in points.iter().enumerate() {
            let first = (j * 7) % (poses.len() / 2);
            for (key, pose) in poses
                .iter()
                .enumerate()
                .skip(first)
                .take(poses.len() / 2 + 3)
            {
                let pixel = CAM.project(pose.rotation * *x + pose.translation).unwrap();
                out.push(Observation {
                    key,
                    point: j,
                    pixel,
                });
            }
        }
        out
    }

    /// From poses and points knocked off by a few degrees and millimetres, exact
    /// observations are explained again to a hundredth of a pixel, and the poses' rotations
    /// relative to the fixed first one come back.
    #[test]
    fn bundle_recovers_exact_tracks() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let truth = key_poses(24);
        let points: Vec<DVec3> = (0..60)
            .map(|_| {
                let v = DVec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(0.2..1.0),
                );
                v.normalize() * DVec3::new(0.08, 0.11, 0.09)
            })
            .collect();
        let observations = observe(&truth, &points);
        let problem = TrackBundle {
            observations: &observations,
            cam: CAM,
            huber_px: 1.0,
        };
        let mut start = truth.clone();
        for p in start.iter_mut().skip(1) {
            let turn = DVec3::new(
                rng.random_range(-0.04..0.04),
                rng.random_range(-0.04..0.04),
                0.0,
            );
            *p = p.stepped(&[turn.x, turn.y, turn.z, 0.003, -0.002, 0.01]);
        }
        let moved: Vec<DVec3> = points.iter().map(|x| *x + DVec3::splat(0.004)).collect();
        let before = problem.cost(&start, &moved);
        let (poses, got) = problem.run(start, moved, 50);
        let rms = problem.point_rms(&poses, &got);
        eprintln!("cost {before} -> {}", problem.cost(&poses, &got));
        assert!(rms.iter().all(|e| *e < 0.01), "{rms:?}");
        assert_eq!(poses[0], truth[0]);
        for (p, t) in poses.iter().zip(&truth) {
            let relative = angle_between(
                p.rotation * poses[0].rotation.inverse(),
                t.rotation * truth[0].rotation.inverse(),
            );
            assert!(relative.to_degrees() < 0.01, "{}", relative.to_degrees());
        }
    }

    #[test]
    fn huber_is_quadratic_then_linear() {
        assert_eq!(huber(0.5, 1.0), (0.25, 1.0));
        assert_eq!(huber(3.0, 1.0), (5.0, 1.0 / 3.0));
        // Continuous at delta, and the weight is the loss's slope over 2 e.
        assert_eq!(huber(1.0, 1.0).0, 1.0);
        let (lo, hi) = (huber(2.999, 1.0).0, huber(3.001, 1.0).0);
        assert!(((hi - lo) / 0.002 / (2.0 * 3.0) - huber(3.0, 1.0).1).abs() < 1e-9);
    }
}
