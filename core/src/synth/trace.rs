//! Rendering by sphere tracing: camera rays are marched through the head's bounding box to
//! the surface of its signed-distance field, shaded, and averaged over sub-pixel samples on
//! top of a procedural background, with each pixel's depth and face region as ground truth.
//!
//! Shading is Lambert plus ambient with a faint specular term, lit from a fixed direction in
//! head space, so that a surface point looks the same from every camera except for the
//! specular highlight.

use glam::{Vec2, Vec3};
use rand::Rng;

use super::head::{FaceState, HeadParams, Model, Part};
use super::sdf::smoothstep;
use crate::camera::Camera;
use crate::image::ImageRgb;
use crate::region::Region;

/// Largest number of sphere-tracing steps per ray.
const MAX_STEPS: usize = 64;
/// A ray hits the surface where the signed distance falls below this.
const HIT_EPS: f32 = 1e-4;
/// A ray that runs out of steps this close to the surface counts as a hit (grazing rays).
const GRAZE_EPS: f32 = 1e-3;

/// One rendered frame with its per-pixel ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct HeadFrame {
    /// The image: the head over the background.
    pub rgb: ImageRgb,
    /// Per pixel, row-major: ray parameter `t` (z-depth) of the surface hit by the pixel's
    /// centre sample, 0.0 where that ray misses.
    pub depth: Vec<f32>,
    /// Per pixel, row-major: which part of the head the centre sample hit.
    pub regions: Vec<Region>,
}

/// Renders one frame: for each pixel, `supersample` x `supersample` sub-pixel rays (pixel
/// (i, j) covers [i-0.5, i+0.5] x [j-0.5, j+0.5] around the [`Camera::ray`] grid point); a
/// sub-ray that hits the head takes its shaded colour, one that misses takes the background
/// pixel (i, j); the pixel is the average. Depth and region come from the centre ray
/// (`supersample` odd) or the sub-ray nearest the centre. `supersample` 0 counts as 1; a
/// background of another size is sampled at the clamped pixel.
pub fn render_head(
    head: &HeadParams,
    state: &FaceState,
    camera: &Camera,
    background: &ImageRgb,
    supersample: u32,
) -> HeadFrame {
    let model = Model::new(head, state);
    let k = &camera.intrinsics;
    let (width, height) = (k.width, k.height);
    let s = supersample.max(1);
    let offsets: Vec<f32> = (0..s).map(|a| (a as f32 + 0.5) / s as f32 - 0.5).collect();
    let centre = (s / 2) as usize;
    let n = k.n_pixels();
    let mut rgb = ImageRgb {
        width,
        height,
        data: Vec::with_capacity(3 * n),
    };
    let mut depth = Vec::with_capacity(n);
    let mut regions = Vec::with_capacity(n);
    for j in 0..height {
        for i in 0..width {
            let bg = background_pixel(background, i, j);
            let mut sum = Vec3::ZERO;
            let mut n_hit = 0u32;
            let mut centre_depth = 0.0;
            let mut centre_region = Region::Background;
            for (b, &oy) in offsets.iter().enumerate() {
                for (a, &ox) in offsets.iter().enumerate() {
                    let (o, d) = camera.ray(i as f32 + ox, j as f32 + oy);
                    let is_centre = a == centre && b == centre;
                    if let Some(hit) = model.trace(o, d) {
                        let (colour, region) = model.shade(hit.p, d);
                        sum += colour;
                        n_hit += 1;
                        if is_centre {
                            centre_depth = hit.t;
                            centre_region = region;
                        }
                    }
                }
            }
            let pixel = if n_hit == 0 {
                bg
            } else {
                let n_miss = (s * s - n_hit) as f32;
                ((sum + n_miss * Vec3::from(bg)) / (s * s) as f32).to_array()
            };
            rgb.data.extend_from_slice(&pixel);
            depth.push(centre_depth);
            regions.push(centre_region);
        }
    }
    HeadFrame {
        rgb,
        depth,
        regions,
    }
}

fn background_pixel(background: &ImageRgb, i: u32, j: u32) -> [f32; 3] {
    if background.width == 0
        || background.height == 0
        || background.data.len() < 3 * background.n_pixels()
    {
        return [0.0; 3];
    }
    background.get(i.min(background.width - 1), j.min(background.height - 1))
}

/// A static, smooth background image (soft gradient plus a few large blurred shapes, colours
/// from rng), deterministic for the rng state.
pub fn render_background(rng: &mut impl Rng, width: u32, height: u32) -> ImageRgb {
    let hue = rng.random::<f32>();
    let c0 = muted(
        hue,
        rng.random_range(0.25..0.45),
        rng.random_range(0.55..0.85),
    );
    let c1 = muted(
        hue + rng.random_range(-0.15..0.15),
        rng.random_range(0.2..0.4),
        rng.random_range(0.3..0.6),
    );
    let angle = rng.random_range(0.0..std::f32::consts::TAU);
    let dir = Vec2::new(angle.cos(), angle.sin());
    let n_blobs = rng.random_range(3..=5);
    let blobs: Vec<(Vec2, f32, Vec3, f32)> = (0..n_blobs)
        .map(|_| {
            let c = Vec2::new(rng.random_range(-0.1..1.1), rng.random_range(-0.1..1.1));
            let r = rng.random_range(0.2..0.45);
            let colour = muted(
                rng.random::<f32>(),
                rng.random_range(0.2..0.5),
                rng.random_range(0.35..0.9),
            );
            let alpha = rng.random_range(0.25..0.55);
            (c, r, colour, alpha)
        })
        .collect();
    let mut img = ImageRgb {
        width,
        height,
        data: Vec::with_capacity(3 * width as usize * height as usize),
    };
    let scale = width.max(height).max(1) as f32;
    for j in 0..height {
        for i in 0..width {
            let uv = Vec2::new((i as f32 + 0.5) / scale, (j as f32 + 0.5) / scale);
            let g = (uv - Vec2::splat(0.5)).dot(dir) * 0.9 + 0.5;
            let mut c = c0.lerp(c1, smoothstep(0.0, 1.0, g));
            for &(centre, r, colour, alpha) in &blobs {
                let w = alpha * (-(uv - centre).length_squared() / (r * r)).exp();
                c = c.lerp(colour, w);
            }
            img.data
                .extend_from_slice(&c.clamp(Vec3::ZERO, Vec3::ONE).to_array());
        }
    }
    img
}

/// A colour from hue (turns), saturation and value.
fn muted(hue: f32, sat: f32, val: f32) -> Vec3 {
    let h = hue.rem_euclid(1.0) * 6.0;
    let f = |n: f32| {
        let k = (n + h).rem_euclid(6.0);
        val - val * sat * (k.min(4.0 - k).clamp(0.0, 1.0))
    };
    Vec3::new(f(5.0), f(3.0), f(1.0))
}

/// A ray's first surface hit.
struct Hit {
    /// Ray parameter (z-depth for camera rays).
    t: f32,
    /// Hit point in head space.
    p: Vec3,
}

impl Model {
    /// Marches the ray `o + t d` and returns its first hit inside the head's bounds.
    fn trace(&self, o: Vec3, d: Vec3) -> Option<Hit> {
        let len = d.length();
        if !(len > 1e-20 && len.is_finite() && o.is_finite()) {
            return None;
        }
        let u = d / len;
        let (s0, s1) = ray_box(o, u, self.lo, self.hi)?;
        let s0 = s0.max(0.0);
        if s1 <= s0 {
            return None;
        }
        let p0 = o + u * s0;
        let span = s1 - s0;
        let mut s = 0.0;
        let mut dist = f32::INFINITY;
        for _ in 0..MAX_STEPS {
            let p = p0 + u * s;
            dist = self.sdf(p);
            if dist < HIT_EPS {
                return Some(Hit {
                    t: (s0 + s) / len,
                    p,
                });
            }
            s += dist;
            if s > span {
                return None;
            }
        }
        (dist < GRAZE_EPS).then(|| Hit {
            t: (s0 + s) / len,
            p: p0 + u * s,
        })
    }

    /// Shaded colour and region of the surface point `p` seen along direction `d`.
    fn shade(&self, p: Vec3, d: Vec3) -> (Vec3, Region) {
        let n = self.normal(p);
        let surf = self.field::<true>(p);
        let diffuse = n.dot(self.light).max(0.0);
        let ao = (0.55 + 0.45 * self.sdf(p + 0.008 * n) / 0.008).clamp(0.4, 1.0);
        let view = -d.normalize_or(Vec3::NEG_Z);
        let half = (self.light + view).normalize_or(Vec3::Z);
        let gloss = match surf.part {
            Part::Eyeball => 0.25,
            Part::Lips => 0.08,
            Part::Hair | Part::Brow => 0.03,
            Part::Cavity => 0.0,
            _ => 0.04,
        };
        let spec = gloss * n.dot(half).max(0.0).powi(32) * (diffuse > 0.0) as u8 as f32;
        let colour = surf.colour * (0.32 + 0.05 * n.y + 0.68 * diffuse) * ao + Vec3::splat(spec);
        let colour = colour.clamp(Vec3::ZERO, Vec3::ONE);
        let colour = if colour.is_finite() {
            colour
        } else {
            surf.colour
        };
        (colour, self.region(p, surf.part))
    }

    /// Unit surface normal by the tetrahedron technique.
    fn normal(&self, p: Vec3) -> Vec3 {
        const H: f32 = 2e-4;
        let k0 = Vec3::new(1.0, -1.0, -1.0);
        let k1 = Vec3::new(-1.0, -1.0, 1.0);
        let k2 = Vec3::new(-1.0, 1.0, -1.0);
        let k3 = Vec3::new(1.0, 1.0, 1.0);
        let g = k0 * self.sdf(p + k0 * H)
            + k1 * self.sdf(p + k1 * H)
            + k2 * self.sdf(p + k2 * H)
            + k3 * self.sdf(p + k3 * H);
        g.try_normalize()
            .unwrap_or_else(|| (p - self.skull.c).normalize_or(Vec3::Z))
    }
}

/// Entry and exit distances of the unit-direction ray `o + s u` through the box, if it
/// crosses it in front of the origin.
fn ray_box(o: Vec3, u: Vec3, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
    let mut s0 = f32::NEG_INFINITY;
    let mut s1 = f32::INFINITY;
    for a in 0..3 {
        if u[a].abs() < 1e-12 {
            if o[a] < lo[a] || o[a] > hi[a] {
                return None;
            }
            continue;
        }
        let inv = 1.0 / u[a];
        let (ta, tb) = ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv);
        s0 = s0.max(ta.min(tb));
        s1 = s1.min(ta.max(tb));
    }
    (s1 >= s0.max(0.0) && s1.is_finite()).then_some((s0, s1))
}
