//! Camera rays as flat f32 buffers that any backend (candle, tract, onnxruntime) can take:
//! for a whole image, for a list of pixels, or as a seeded random training batch biased to
//! the face rectangle as AD-NeRF samples it.

use glam::Vec3;
use rand::Rng;

use crate::bounds::HeadRange;
use crate::camera::Camera;
use crate::image::Rect;

/// A set of rays, `origins` and `directions` each flat `[n_rays, 3]`. Directions are not
/// normalised (NeRF's convention): a point at parameter `t` is `o + t d`, and `t` is depth
/// along the camera's viewing axis.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Rays {
    pub origins: Vec<f32>,
    pub directions: Vec<f32>,
}

impl Rays {
    /// Room for `n` rays.
    pub fn with_capacity(n: usize) -> Rays {
        Rays {
            origins: Vec::with_capacity(3 * n),
            directions: Vec::with_capacity(3 * n),
        }
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.origins.len() / 3
    }

    /// True when there are no rays.
    pub fn is_empty(&self) -> bool {
        self.origins.is_empty()
    }

    /// Appends one ray.
    pub fn push(&mut self, origin: Vec3, direction: Vec3) {
        self.origins.extend_from_slice(&origin.to_array());
        self.directions.extend_from_slice(&direction.to_array());
    }

    /// Origin of ray `r`.
    pub fn origin(&self, r: usize) -> Vec3 {
        Vec3::from_slice(&self.origins[3 * r..3 * r + 3])
    }

    /// A copy of rays `range`.
    pub fn slice(&self, range: std::ops::Range<usize>) -> Rays {
        Rays {
            origins: self.origins[3 * range.start..3 * range.end].to_vec(),
            directions: self.directions[3 * range.start..3 * range.end].to_vec(),
        }
    }

    /// Direction of ray `r`.
    pub fn direction(&self, r: usize) -> Vec3 {
        Vec3::from_slice(&self.directions[3 * r..3 * r + 3])
    }
}

/// Rays through every pixel of `camera`'s image, row by row (`j` outer, `i` inner), as
/// AD-NeRF's `get_rays` orders them.
///
/// # Shapes
/// - returns `width * height` rays
pub fn rays_for_image(camera: &Camera) -> Rays {
    let k = &camera.intrinsics;
    let mut rays = Rays::with_capacity(k.n_pixels());
    for j in 0..k.height {
        for i in 0..k.width {
            let (o, d) = camera.ray(i as f32, j as f32);
            rays.push(o, d);
        }
    }
    rays
}

/// Rays of an image with the pixel each goes through.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PixelRays {
    /// The rays, in pixel order.
    pub rays: Rays,
    /// The row-major pixel index (`j * width + i`) of each ray.
    pub pixels: Vec<usize>,
}

impl PixelRays {
    /// Pixel (`i`, `j`) of ray `r`, for an image `width` pixels wide.
    pub fn pixel_ij(&self, r: usize, width: u32) -> (u32, u32) {
        let p = self.pixels[r];
        ((p % width as usize) as u32, (p / width as usize) as u32)
    }
}

/// The rays of `camera`'s image that meet the head's bounds within `[near, far]`, row by
/// row, with their pixels: the only rays the student is trained on and the only ones a
/// renderer sends through a network; every other pixel is the background. Training,
/// evaluation and inference all take a frame's rays from here.
pub fn head_rays(camera: &Camera, head: &HeadRange) -> PixelRays {
    pixel_rays(camera, |o, d| {
        head.bounds.intersect(o, d, head.near, head.far).is_some()
    })
}

/// [`head_rays`] for a box that fills little of the image (a mouth's): the same rays and
/// pixels, testing only the pixels inside the rectangle that the box's corners project to,
/// grown by a pixel on each side, or every pixel when a corner is not in front of the
/// camera. A ray that meets the box passes through the box's image, which is the hull of
/// its corners' images.
pub fn box_rays(camera: &Camera, head: &HeadRange) -> PixelRays {
    let k = &camera.intrinsics;
    let (lo, hi) = (head.bounds.lo, head.bounds.hi);
    let mut rect = (
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
    );
    for c in 0..8 {
        let corner = Vec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        );
        match camera.project(corner) {
            Some((i, j, z)) if z > 1e-6 && i.is_finite() && j.is_finite() => {
                rect = (rect.0.min(i), rect.1.max(i), rect.2.min(j), rect.3.max(j));
            }
            _ => return head_rays(camera, head),
        }
    }
    let span = |a: f32, b: f32, n: u32| -> (u32, u32) {
        let first = (a.floor() - 1.0).clamp(0.0, n as f32) as u32;
        let past = (b.ceil() + 2.0).clamp(0.0, n as f32) as u32;
        (first, past.max(first))
    };
    let columns = span(rect.0, rect.1, k.width);
    let rows = span(rect.2, rect.3, k.height);
    pixel_rays_in(camera, (columns, rows), |o, d| {
        head.bounds.intersect(o, d, head.near, head.far).is_some()
    })
}

/// Every ray of `camera`'s image with its pixel, row by row (as [`rays_for_image`]).
pub fn all_pixel_rays(camera: &Camera) -> PixelRays {
    pixel_rays(camera, |_, _| true)
}

fn pixel_rays(camera: &Camera, keep: impl Fn(Vec3, Vec3) -> bool) -> PixelRays {
    let k = &camera.intrinsics;
    pixel_rays_in(camera, ((0, k.width), (0, k.height)), keep)
}

/// The rays `keep` accepts among the pixels of columns `i0 .. i1` and rows `j0 .. j1`, row
/// by row, with their pixels.
fn pixel_rays_in(
    camera: &Camera,
    ((i0, i1), (j0, j1)): ((u32, u32), (u32, u32)),
    keep: impl Fn(Vec3, Vec3) -> bool,
) -> PixelRays {
    let k = &camera.intrinsics;
    let mut out = PixelRays::default();
    for j in j0..j1 {
        for i in i0..i1 {
            let (o, d) = camera.ray(i as f32, j as f32);
            if keep(o, d) {
                out.rays.push(o, d);
                out.pixels.push(j as usize * k.width as usize + i as usize);
            }
        }
    }
    out
}

/// Rays through the listed pixels (`i`, `j`), in order.
pub fn rays_for_pixels(camera: &Camera, pixels: &[(u32, u32)]) -> Rays {
    let mut rays = Rays::with_capacity(pixels.len());
    for &(i, j) in pixels {
        let (o, d) = camera.ray(i as f32, j as f32);
        rays.push(o, d);
    }
    rays
}

/// A random training batch: which pixels, and their rays.
#[derive(Debug, Clone, PartialEq)]
pub struct PixelBatch {
    /// Pixel coordinates (`i`, `j`) of each ray.
    pub pixels: Vec<(u32, u32)>,
    pub rays: Rays,
}

/// Draws `n_rays` pixels of `camera`'s image, `round(face_fraction * n_rays)` of them
/// uniformly inside `face_rect` and the rest uniformly over the whole image (AD-NeRF uses
/// 0.95, the paper's student 0.9), and returns their rays. Deterministic for a seeded `rng`.
/// A `face_rect` outside the image falls back to the whole image.
pub fn sample_batch(
    camera: &Camera,
    face_rect: Rect,
    n_rays: usize,
    face_fraction: f32,
    rng: &mut impl Rng,
) -> PixelBatch {
    let k = &camera.intrinsics;
    let full = Rect {
        x: 0,
        y: 0,
        w: k.width as i64,
        h: k.height as i64,
    };
    let face = face_rect.clipped(k.width, k.height).unwrap_or(full);
    let n_face = ((face_fraction.clamp(0.0, 1.0) * n_rays as f32).round() as usize).min(n_rays);
    let mut pixels = Vec::with_capacity(n_rays);
    for r in 0..n_rays {
        let rect = if r < n_face { face } else { full };
        let i = rect.x + rng.random_range(0..rect.w);
        let j = rect.y + rng.random_range(0..rect.h);
        pixels.push((i as u32, j as u32));
    }
    let rays = rays_for_pixels(camera, &pixels);
    PixelBatch { pixels, rays }
}

#[cfg(test)]
mod tests {
    use glam::{Mat4, Vec3};

    use super::*;
    use crate::bounds::Bounds;
    use crate::camera::{Intrinsics, look_at, turn_about};

    /// `box_rays` finds exactly `head_rays`' rays and pixels for a small box seen from the
    /// front, turned, from afar, half out of the image, out of sight, behind, and from
    /// inside the box.
    #[test]
    fn box_rays_are_head_rays() {
        let intrinsics = Intrinsics {
            width: 48,
            height: 40,
            focal: 60.0,
            cx: 24.0,
            cy: 20.0,
        };
        let mouth = Bounds {
            lo: Vec3::new(-0.03, -0.08, 0.04),
            hi: Vec3::new(0.03, -0.03, 0.09),
        };
        let head = HeadRange {
            bounds: mouth,
            near: 0.3,
            far: 1.5,
        };
        let front = look_at(Vec3::new(0.0, 0.0, 0.8), Vec3::ZERO, Vec3::Y);
        let poses = [
            front,
            turn_about(Vec3::ZERO, 0.6, -0.3) * front,
            Mat4::from_translation(Vec3::new(0.0, 0.0, 0.6)) * front,
            Mat4::from_translation(Vec3::new(0.25, 0.0, 0.0)) * front,
            Mat4::from_translation(Vec3::new(2.0, 0.0, 0.0)) * front,
            look_at(Vec3::new(0.0, 0.0, 0.8), Vec3::new(0.0, 0.0, 2.0), Vec3::Y),
            Mat4::from_translation(mouth.centre() - front.w_axis.truncate()) * front,
        ];
        let mut seen = 0;
        for (c, c2w) in poses.into_iter().enumerate() {
            let camera = Camera { intrinsics, c2w };
            let want = head_rays(&camera, &head);
            let got = box_rays(&camera, &head);
            assert_eq!(got, want, "camera {c}");
            seen += usize::from(!want.pixels.is_empty());
        }
        assert!(seen >= 4, "{seen} cameras see the box");
    }
}
