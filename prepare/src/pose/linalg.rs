//! Small dense f64 algebra for the pose solver: Cholesky solves, rotation logarithms, the
//! mean of rotations, and the similarity that best maps one point set onto another.

use glam::{DQuat, DVec3};

/// Solves `a x = b` in place by Cholesky, `a` symmetric positive definite (`n x n`,
/// row-major, `n = b.len()`); `b` becomes `x` and `a` is overwritten by its factor.
/// `None` if a pivot falls below `1e-14` of its diagonal entry (not positive definite to
/// rounding) or is not finite.
pub(crate) fn cholesky_solve(a: &mut [f64], b: &mut [f64]) -> Option<()> {
    let n = b.len();
    debug_assert_eq!(a.len(), n * n);
    for j in 0..n {
        let row_j = &mut a[j * n..j * n + n];
        let pivot = row_j[j] - dot(&row_j[..j], &row_j[..j]);
        if !pivot.is_finite() || pivot <= 1e-14 * row_j[j].abs() {
            return None;
        }
        let pivot = pivot.sqrt();
        row_j[j] = pivot;
        // The factor L is stored by rows (L[i][k], k <= i, in row i); column j is filled from
        // the columns before it.
        for i in j + 1..n {
            let (head, tail) = a.split_at_mut(i * n);
            let row_j = &head[j * n..j * n + n];
            let row_i = &mut tail[..n];
            row_i[j] = (row_i[j] - dot(&row_i[..j], &row_j[..j])) / pivot;
        }
    }
    for i in 0..n {
        let row = &a[i * n..i * n + i];
        b[i] = (b[i] - dot(row, &b[..i])) / a[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s / a[i * n + i];
    }
    Some(())
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The rotation vector (axis times angle in radians, angle in `[0, pi]`) of a unit
/// quaternion, accurate for small angles.
pub(crate) fn log_rotation(q: DQuat) -> DVec3 {
    let q = if q.w < 0.0 { -q } else { q };
    let v = DVec3::new(q.x, q.y, q.z);
    let s = v.length();
    if s < 1e-12 {
        2.0 * v
    } else {
        v * (2.0 * s.atan2(q.w) / s)
    }
}

/// Angle in radians of the rotation taking `a` to `b`.
pub(crate) fn angle_between(a: DQuat, b: DQuat) -> f64 {
    log_rotation(b * a.inverse()).length()
}

/// The eigenvector of the largest eigenvalue of a symmetric 4x4 matrix (cyclic Jacobi).
pub(crate) fn top_eigenvector4(mut a: [[f64; 4]; 4]) -> [f64; 4] {
    let mut v = [[0.0; 4]; 4];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let scale: f64 = a.iter().flatten().map(|x| x * x).sum();
    for _sweep in 0..64 {
        let off: f64 = (0..4)
            .flat_map(|p| (p + 1..4).map(move |q| (p, q)))
            .map(|(p, q)| a[p][q] * a[p][q])
            .sum();
        if off <= 1e-30 * scale {
            break;
        }
        for p in 0..3 {
            for q in p + 1..4 {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut().chain(v.iter_mut()) {
                    let (kp, kq) = (row[p], row[q]);
                    row[p] = c * kp - s * kq;
                    row[q] = s * kp + c * kq;
                }
                let (old_p, old_q) = (a[p], a[q]);
                a[p] = std::array::from_fn(|k| c * old_p[k] - s * old_q[k]);
                a[q] = std::array::from_fn(|k| s * old_p[k] + c * old_q[k]);
            }
        }
    }
    let best = (0..4).fold(0, |b, i| if a[i][i] > a[b][b] { i } else { b });
    [v[0][best], v[1][best], v[2][best], v[3][best]]
}

/// The mean of unit quaternions, sign-blind (Markley et al. 2007): the principal
/// eigenvector of `sum_i q_i q_i^T`, which minimises the summed squared chordal distances.
pub(crate) fn mean_rotation(rotations: &[DQuat]) -> DQuat {
    let mut m = [[0.0; 4]; 4];
    for q in rotations {
        let e = [q.w, q.x, q.y, q.z];
        for (r, row) in m.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x += e[r] * e[c];
            }
        }
    }
    let [w, x, y, z] = top_eigenvector4(m);
    DQuat::from_xyzw(x, y, z, w).normalize()
}

/// `x -> scale * rotation * x + translation`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Similarity {
    pub scale: f64,
    pub rotation: DQuat,
    pub translation: DVec3,
}

impl Similarity {
    pub fn apply(&self, x: DVec3) -> DVec3 {
        self.scale * (self.rotation * x) + self.translation
    }
}

/// The similarity minimising `sum_i w_i |s R p_i + d - q_i|^2` (Horn 1987 for `R`, with
/// `s = sum w q'.(R p') / sum w |p'|^2` on the centred points, as Umeyama 1991), or `None`
/// when the points `p` all coincide.
///
/// # Shapes
/// `from`, `to`, `weights`: `[n]`, weights non-negative with a positive sum.
pub(crate) fn fit_similarity(from: &[DVec3], to: &[DVec3], weights: &[f64]) -> Option<Similarity> {
    let total: f64 = weights.iter().sum();
    let centroid = |pts: &[DVec3]| {
        pts.iter()
            .zip(weights)
            .fold(DVec3::ZERO, |acc, (p, w)| acc + *w * *p)
            / total
    };
    let (pc, qc) = (centroid(from), centroid(to));
    let mut s = [[0.0; 3]; 3];
    let mut spread = 0.0;
    for ((p, q), w) in from.iter().zip(to).zip(weights) {
        let (p, q) = ((*p - pc).to_array(), (*q - qc).to_array());
        for (a, row) in s.iter_mut().enumerate() {
            for (b, x) in row.iter_mut().enumerate() {
                *x += w * p[a] * q[b];
            }
        }
        spread += w * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    }
    if !spread.is_finite() || spread <= 0.0 {
        return None;
    }
    let [[xx, xy, xz], [yx, yy, yz], [zx, zy, zz]] = s;
    let n = [
        [xx + yy + zz, yz - zy, zx - xz, xy - yx],
        [yz - zy, xx - yy - zz, xy + yx, zx + xz],
        [zx - xz, xy + yx, -xx + yy - zz, yz + zy],
        [xy - yx, zx + xz, yz + zy, -xx - yy + zz],
    ];
    let [w, x, y, z] = top_eigenvector4(n);
    let rotation = DQuat::from_xyzw(x, y, z, w).normalize();
    let mut projected = 0.0;
    for ((p, q), w) in from.iter().zip(to).zip(weights) {
        projected += w * (*q - qc).dot(rotation * (*p - pc));
    }
    let scale = projected / spread;
    Some(Similarity {
        scale,
        rotation,
        translation: qc - scale * (rotation * pc),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_a_known_system() {
        // a = l l^T with l = [[2,0,0],[1,3,0],[-1,0.5,1]]; x = [1,-2,0.5].
        let mut a = vec![4.0, 2.0, -2.0, 2.0, 10.0, 0.5, -2.0, 0.5, 2.25];
        let x = [1.0, -2.0, 0.5];
        let mut b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|k| a[i * 3 + k] * x[k]).sum())
            .collect();
        cholesky_solve(&mut a, &mut b).unwrap();
        for (got, want) in b.iter().zip(x) {
            assert!((got - want).abs() < 1e-12, "{b:?}");
        }
        let mut singular = vec![1.0, 1.0, 1.0, 1.0];
        assert!(cholesky_solve(&mut singular, &mut [1.0, 2.0]).is_none());
    }

    #[test]
    fn similarity_recovers_a_planted_one() {
        let truth = Similarity {
            scale: 1.3,
            rotation: DQuat::from_scaled_axis(DVec3::new(0.3, -1.1, 0.4)),
            translation: DVec3::new(0.2, -0.5, 1.0),
        };
        let from: Vec<DVec3> = (0..20)
            .map(|i| {
                let t = i as f64;
                DVec3::new((t * 0.7).sin(), (t * 1.3).cos(), (t * 0.37).sin() * 0.5)
            })
            .collect();
        let to: Vec<DVec3> = from.iter().map(|p| truth.apply(*p)).collect();
        let weights: Vec<f64> = (0..20).map(|i| 0.5 + (i % 3) as f64).collect();
        let got = fit_similarity(&from, &to, &weights).unwrap();
        assert!((got.scale - truth.scale).abs() < 1e-12);
        assert!(angle_between(got.rotation, truth.rotation) < 1e-12);
        assert!((got.translation - truth.translation).length() < 1e-12);
        let same = vec![DVec3::ONE; 20];
        assert!(fit_similarity(&same, &to, &weights).is_none());
    }

    #[test]
    fn mean_rotation_is_sign_blind_and_central() {
        let centre = DQuat::from_scaled_axis(DVec3::new(0.2, 0.5, -0.1));
        let offsets = [DVec3::X, -DVec3::X, DVec3::Y, -DVec3::Y].map(|v| 0.1 * v);
        let qs: Vec<DQuat> = offsets
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let q = DQuat::from_scaled_axis(*v) * centre;
                if i % 2 == 0 { -q } else { q }
            })
            .collect();
        assert!(angle_between(mean_rotation(&qs), centre) < 1e-9);
        assert!((log_rotation(DQuat::from_scaled_axis(DVec3::Z * 1e-9)).z - 1e-9).abs() < 1e-20);
    }
}
