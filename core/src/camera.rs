//! Pinhole cameras in AD-NeRF's convention: intrinsics in pixels and a 4x4 camera-to-world
//! matrix with OpenGL axes (the camera looks along its -z axis, +y is up in the image).

use glam::{Mat3, Mat4, Quat, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// Pinhole intrinsics in pixels (AD-NeRF's `focal_len`, `cx`, `cy`) and the image size.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    /// Focal length in pixels, the same for x and y.
    pub focal: f32,
    /// Principal point, x, in pixels.
    pub cx: f32,
    /// Principal point, y, in pixels (down the image).
    pub cy: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Intrinsics {
    /// The same camera at another resolution: focal and principal point scale with it.
    pub fn resized(&self, width: u32, height: u32) -> Intrinsics {
        let sx = width as f32 / self.width as f32;
        let sy = height as f32 / self.height as f32;
        Intrinsics {
            focal: self.focal * sx,
            cx: self.cx * sx,
            cy: self.cy * sy,
            width,
            height,
        }
    }

    /// The un-normalised camera-space direction through pixel (`i`, `j`), as AD-NeRF's
    /// `get_rays` writes it: `[(i - cx) / f, -(j - cy) / f, -1]`.
    pub fn camera_direction(&self, i: f32, j: f32) -> Vec3 {
        Vec3::new(
            (i - self.cx) / self.focal,
            -(j - self.cy) / self.focal,
            -1.0,
        )
    }

    /// Number of pixels.
    pub fn n_pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// A posed pinhole camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub intrinsics: Intrinsics,
    /// Camera-to-world transform (rotation and translation only).
    pub c2w: Mat4,
}

impl Camera {
    /// Origin and un-normalised direction of the ray through pixel (`i`, `j`) (pixel
    /// coordinates as AD-NeRF uses them: integer values hit pixel corners' grid points,
    /// `i` along the width, `j` down the height).
    pub fn ray(&self, i: f32, j: f32) -> (Vec3, Vec3) {
        let d = self.intrinsics.camera_direction(i, j);
        let rot = Mat3::from_mat4(self.c2w);
        (self.c2w.w_axis.truncate(), rot * d)
    }

    /// Camera centre in world space.
    pub fn origin(&self) -> Vec3 {
        self.c2w.w_axis.truncate()
    }

    /// Projects a world point to pixel coordinates (`i`, `j`) and its depth along the
    /// viewing axis; `None` behind the camera.
    pub fn project(&self, p: Vec3) -> Option<(f32, f32, f32)> {
        let pc = self.c2w.inverse() * Vec4::new(p.x, p.y, p.z, 1.0);
        let z = -pc.z;
        if z <= 0.0 {
            return None;
        }
        let k = &self.intrinsics;
        Some((k.cx + k.focal * pc.x / z, k.cy - k.focal * pc.y / z, z))
    }
}

/// The rigid transform turning the world about `centre`: `yaw` radians about the vertical
/// (y) axis after `pitch` radians about the horizontal (x) axis. A camera-to-world matrix
/// `c2w` seen from the turned place is `turn_about(..) * c2w`.
pub fn turn_about(centre: Vec3, yaw: f32, pitch: f32) -> Mat4 {
    Mat4::from_translation(centre)
        * Mat4::from_quat(Quat::from_rotation_y(yaw) * Quat::from_rotation_x(pitch))
        * Mat4::from_translation(-centre)
}

/// A camera-to-world matrix at `eye` looking at `target`, OpenGL axes.
pub fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let back = (eye - target).normalize();
    let right = up.cross(back).normalize();
    let true_up = back.cross(right);
    Mat4::from_cols(
        right.extend(0.0),
        true_up.extend(0.0),
        back.extend(0.0),
        eye.extend(1.0),
    )
}

/// Why a 4x4 matrix is not a rigid camera-to-world transform, or `None` if it is one:
/// every entry finite, the last row `[0, 0, 0, 1]`, and the 3x3 block a rotation
/// (orthonormal columns, determinant +1) to within `tol`.
pub fn rigid_problem(m: &Mat4, tol: f32) -> Option<String> {
    if !m.is_finite() {
        return Some("has a non-finite entry".into());
    }
    let row3 = m.row(3);
    if (row3 - Vec4::new(0.0, 0.0, 0.0, 1.0)).abs().max_element() > tol {
        return Some(format!(
            "last row is {:?}, expected [0, 0, 0, 1]",
            row3.to_array()
        ));
    }
    let r = Mat3::from_mat4(*m);
    let rtr = r.transpose() * r;
    let off = (rtr - Mat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0f32, |a, v| a.max(v.abs()));
    if off > tol {
        return Some(format!(
            "rotation block is not orthonormal (|R^T R - I| = {off:.3e})"
        ));
    }
    let det = r.determinant();
    if (det - 1.0).abs() > tol {
        return Some(format!(
            "rotation block has determinant {det:.4}, expected 1"
        ));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_is_rigid_and_projects_target_to_centre() {
        let c2w = look_at(Vec3::new(0.3, 0.2, 1.5), Vec3::ZERO, Vec3::Y);
        assert!(rigid_problem(&c2w, 1e-5).is_none());
        let k = Intrinsics {
            focal: 100.0,
            cx: 64.0,
            cy: 64.0,
            width: 128,
            height: 128,
        };
        let cam = Camera { intrinsics: k, c2w };
        let (i, j, z) = cam.project(Vec3::ZERO).unwrap();
        assert!((i - 64.0).abs() < 1e-3 && (j - 64.0).abs() < 1e-3);
        assert!((z - Vec3::new(0.3, 0.2, 1.5).length()).abs() < 1e-4);
    }

    #[test]
    fn project_inverts_ray() {
        let c2w = look_at(
            Vec3::new(-0.4, 0.1, 1.2),
            Vec3::new(0.0, 0.05, 0.0),
            Vec3::Y,
        );
        let k = Intrinsics {
            focal: 120.0,
            cx: 60.0,
            cy: 70.0,
            width: 128,
            height: 140,
        };
        let cam = Camera { intrinsics: k, c2w };
        let (o, d) = cam.ray(17.0, 93.0);
        let (i, j, z) = cam.project(o + 2.0 * d).unwrap();
        assert!((i - 17.0).abs() < 1e-3 && (j - 93.0).abs() < 1e-3 && (z - 2.0).abs() < 1e-4);
    }
}
