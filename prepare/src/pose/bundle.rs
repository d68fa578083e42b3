//! The bundle step: the face's weighted points and the poses of a set of key frames refined
//! together, so that a face whose depth differs from the canonical one stops biasing every
//! rotation.
//!
//! It minimises, over key-frame poses `(R_f, t_f)` and face points `X_j`,
//!
//! `E = sum_f sum_j w_j |pi(R_f X_j + t_f) - u_fj|^2 + mu sum_j |X_j - C_j|^2`
//!
//! (`pi` the pinhole projection in pixels, `C_j` the canonical face, `mu` the prior weight in
//! px^2 per m^2) by Levenberg-Marquardt on the joint problem, the points eliminated by the
//! Schur complement so that each step solves a dense system in the poses alone (`6 n_keys`
//! unknowns). Alternating poses and points crawls when the head turns little: a deeper face
//! and smaller rotations explain the same pixels to first order in the rotation (the
//! bas-relief ambiguity), and alternation creeps along that valley where a joint step
//! crosses it. After each accepted step the face is mapped
//! back onto the canonical by the least-squares similarity (the poses compensated), so it
//! keeps the canonical's centroid, scale and orientation: the gauge the pixels leave free.

use glam::{DMat3, DVec2, DVec3};
use rayon::prelude::*;

use super::linalg::{Similarity, cholesky_solve, fit_similarity};
use super::pnp::{Pinhole, Pose, cost};

/// The data of a bundle problem; points are the weighted ones only.
pub(crate) struct Bundle<'a> {
    /// Canonical face points, `[n_points]`.
    pub canonical: &'a [DVec3],
    /// Landmark weights, `[n_points]`, positive.
    pub weights: &'a [f64],
    /// Observed pixels of each key frame, `[n_keys][n_points]`.
    pub pixels: &'a [Vec<DVec2>],
    pub cam: Pinhole,
    /// `mu`: the prior's weight, px^2 per m^2 of departure from the canonical.
    pub prior: f64,
}

/// One key frame's share of the normal equations. `w_t[(3 j + k) * 6 + b]` is entry
/// `(b, k)` of `W_fj = sum w J_pose^T J_point` (6 x 3), laid out so that products over
/// points run along contiguous memory.
struct FrameBlock {
    u: [f64; 36],
    g: [f64; 6],
    w_t: Vec<f64>,
    v: Vec<DMat3>,
    gx: Vec<DVec3>,
}

/// The linearised problem: frame blocks and the point blocks `V_j` (3 x 3) and gradients.
struct Normal {
    frames: Vec<FrameBlock>,
    v: Vec<DMat3>,
    gx: Vec<DVec3>,
}

impl Bundle<'_> {
    /// `E` at `face` and `poses`.
    pub fn cost(&self, face: &[DVec3], poses: &[Pose]) -> f64 {
        let data: f64 = poses
            .par_iter()
            .zip(self.pixels)
            .map(|(pose, pixels)| cost(pose, face, pixels, self.weights, &self.cam))
            .sum();
        let prior: f64 = face
            .iter()
            .zip(self.canonical)
            .map(|(x, c)| (*x - *c).length_squared())
            .sum();
        data + self.prior * prior
    }

    fn frame_block(&self, face: &[DVec3], pose: &Pose, pixels: &[DVec2]) -> Option<FrameBlock> {
        let n = face.len();
        let rot = DMat3::from_quat(pose.rotation);
        let mut block = FrameBlock {
            u: [0.0; 36],
            g: [0.0; 6],
            w_t: vec![0.0; n * 18],
            v: vec![DMat3::ZERO; n],
            gx: vec![DVec3::ZERO; n],
        };
        for (j, ((x, u), w)) in face.iter().zip(pixels).zip(self.weights).enumerate() {
            let lin = self.cam.linearise(&rot, pose.translation, *x, *u)?;
            let residual = lin.residual.to_array();
            for ((pose_row, point_row), r) in lin.d_pose.iter().zip(lin.d_point).zip(residual) {
                // d pixel / d X = d pixel / d p * R.
                let point_row = rot.transpose() * point_row;
                for a in 0..6 {
                    block.g[a] += w * pose_row[a] * r;
                    for b in 0..6 {
                        block.u[a * 6 + b] += w * pose_row[a] * pose_row[b];
                    }
                    for k in 0..3 {
                        block.w_t[(3 * j + k) * 6 + a] += w * pose_row[a] * point_row[k];
                    }
                }
                block.v[j] += DMat3::from_cols(
                    point_row * point_row.x,
                    point_row * point_row.y,
                    point_row * point_row.z,
                ) * *w;
                block.gx[j] += (w * r) * point_row;
            }
        }
        Some(block)
    }

    fn linearise(&self, face: &[DVec3], poses: &[Pose]) -> Option<Normal> {
        let frames = poses
            .par_iter()
            .zip(self.pixels)
            .map(|(pose, pixels)| self.frame_block(face, pose, pixels))
            .collect::<Option<Vec<_>>>()?;
        let mut v: Vec<DMat3> = vec![DMat3::IDENTITY * self.prior; face.len()];
        let mut gx: Vec<DVec3> = face
            .iter()
            .zip(self.canonical)
            .map(|(x, c)| self.prior * (*x - *c))
            .collect();
        for block in &frames {
            for j in 0..face.len() {
                v[j] += block.v[j];
                gx[j] += block.gx[j];
            }
        }
        Some(Normal { frames, v, gx })
    }

    /// The damped Gauss-Newton step `(d poses, d points)` (to subtract), by the Schur
    /// complement on the points.
    fn step(&self, normal: &Normal, lambda: f64) -> Option<(Vec<f64>, Vec<DVec3>)> {
        let damp = |m: &DMat3| {
            let mut d = *m;
            d.x_axis.x *= 1.0 + lambda;
            d.y_axis.y *= 1.0 + lambda;
            d.z_axis.z *= 1.0 + lambda;
            d
        };
        let v_inv: Vec<DMat3> = normal.v.iter().map(|v| damp(v).inverse()).collect();
        // y_t[(3 j + k) * 6 + a] = (W_fj V_j^-1)[a][k].
        let y_t: Vec<Vec<f64>> = normal
            .frames
            .par_iter()
            .map(|block| {
                let mut y = vec![0.0; block.w_t.len()];
                for (j, vi) in v_inv.iter().enumerate() {
                    for k in 0..3 {
                        for l in 0..3 {
                            let vlk = vi.col(k)[l];
                            for a in 0..6 {
                                y[(3 * j + k) * 6 + a] += block.w_t[(3 * j + l) * 6 + a] * vlk;
                            }
                        }
                    }
                }
                y
            })
            .collect();
        let mut dc = self.reduced_system(normal, &y_t, lambda)?;
        let n = normal.frames.len();
        let mut rhs: Vec<f64> = Vec::with_capacity(6 * n);
        for (block, y) in normal.frames.iter().zip(&y_t) {
            for a in 0..6 {
                let coupled: f64 = normal
                    .gx
                    .iter()
                    .enumerate()
                    .map(|(j, gx)| (0..3).map(|k| y[(3 * j + k) * 6 + a] * gx[k]).sum::<f64>())
                    .sum();
                rhs.push(block.g[a] - coupled);
            }
        }
        cholesky_solve(&mut dc, &mut rhs)?;
        let dx = (0..normal.v.len())
            .map(|j| {
                let mut b = normal.gx[j];
                for (f, block) in normal.frames.iter().enumerate() {
                    for k in 0..3 {
                        b[k] -= (0..6)
                            .map(|a| block.w_t[(3 * j + k) * 6 + a] * rhs[6 * f + a])
                            .sum::<f64>();
                    }
                }
                v_inv[j] * b
            })
            .collect();
        Some((rhs, dx))
    }

    /// `S = blockdiag(U_f) - W V^-1 W^T`, dense `6 n_keys` square, row-major.
    fn reduced_system(&self, normal: &Normal, y_t: &[Vec<f64>], lambda: f64) -> Option<Vec<f64>> {
        let n = normal.frames.len();
        let rows: Vec<Vec<[f64; 36]>> = (0..n)
            .into_par_iter()
            .map(|f| {
                (f..n)
                    .map(|g| cross_block(&y_t[f], &normal.frames[g].w_t))
                    .collect()
            })
            .collect();
        let dim = 6 * n;
        let mut s = vec![0.0; dim * dim];
        for (f, row) in rows.iter().enumerate() {
            for (offset, block) in row.iter().enumerate() {
                let g = f + offset;
                for a in 0..6 {
                    for b in 0..6 {
                        let mut x = -block[a * 6 + b];
                        if f == g {
                            let u = normal.frames[f].u[a * 6 + b];
                            x += if a == b { u * (1.0 + lambda) } else { u };
                        }
                        s[(6 * f + a) * dim + 6 * g + b] = x;
                        s[(6 * g + b) * dim + 6 * f + a] = x;
                    }
                }
            }
        }
        s.iter().all(|x| x.is_finite()).then_some(s)
    }

    /// The face mapped onto the canonical by the least-squares similarity, and the poses
    /// that keep every projection: `X' = s Q X + d`, `R' = R Q^T`, `t' = s t - R' d`.
    fn regauge(&self, face: Vec<DVec3>, poses: Vec<Pose>) -> (Vec<DVec3>, Vec<Pose>) {
        let ones = vec![1.0; face.len()];
        let Some(sim) = fit_similarity(&face, self.canonical, &ones) else {
            return (face, poses);
        };
        let Similarity {
            scale,
            rotation,
            translation,
        } = sim;
        let face = face.iter().map(|x| sim.apply(*x)).collect();
        let poses = poses
            .iter()
            .map(|p| {
                let r = (p.rotation * rotation.inverse()).normalize();
                Pose {
                    rotation: r,
                    translation: scale * p.translation - r * translation,
                }
            })
            .collect();
        (face, poses)
    }

    /// Levenberg-Marquardt from `face` and `poses`, at most `iterations` accepted steps;
    /// stops when a step gains less than `1e-10` of `E`. Returns the refined face and poses
    /// (the inputs when no step helps).
    pub fn run(
        &self,
        mut face: Vec<DVec3>,
        mut poses: Vec<Pose>,
        iterations: usize,
    ) -> (Vec<DVec3>, Vec<Pose>) {
        let mut current = self.cost(&face, &poses);
        let mut lambda = 1e-3;
        for _ in 0..iterations {
            let Some(normal) = self.linearise(&face, &poses) else {
                break;
            };
            let accepted = loop {
                if let Some((mut dc, dx)) = self.step(&normal, lambda) {
                    dc.iter_mut().for_each(|x| *x = -*x);
                    let p: Vec<Pose> = poses
                        .iter()
                        .zip(dc.chunks_exact(6))
                        .map(|(p, d)| p.stepped(d))
                        .collect();
                    let x: Vec<DVec3> = face.iter().zip(&dx).map(|(x, d)| *x - *d).collect();
                    let c = self.cost(&x, &p);
                    if c < current {
                        lambda = (lambda / 3.0).max(1e-12);
                        break Some(self.regauge(x, p));
                    }
                }
                lambda *= 5.0;
                if lambda > 1e10 {
                    break None;
                }
            };
            let Some((x, p)) = accepted else { break };
            let c = self.cost(&x, &p);
            let gain = current - c;
            (face, poses, current) = (x, p, c);
            if gain <= 1e-10 * current {
                break;
            }
        }
        (face, poses)
    }
}

/// `sum_jk y[jk][a] w[jk][b]` for two frames' `6 x 3 n_points` blocks stored point-major.
fn cross_block(y: &[f64], w: &[f64]) -> [f64; 36] {
    let mut acc = [0.0; 36];
    for (ya, wb) in y.chunks_exact(6).zip(w.chunks_exact(6)) {
        for a in 0..6 {
            for b in 0..6 {
                acc[a * 6 + b] += ya[a] * wb[b];
            }
        }
    }
    acc
}
