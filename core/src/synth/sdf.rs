//! Signed-distance primitives and the smooth blends that join them: ellipsoids, round cones
//! and round boxes, each with its distance, a bounding-sphere lower bound that lets a caller
//! skip it when far away and, for the shapes that bound the head, its axis-aligned extent;
//! and the polynomial smooth minimum and maximum, which also give the weight of their second
//! operand so that colours can be blended the way the shapes are.

use glam::Vec3;

/// Hermite step of `x` from 0 at `e0` to 1 at `e1`.
pub(super) fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Polynomial smooth minimum of `a` and `b` with blend width `k`, and the weight of `b`.
#[inline]
pub(super) fn smin(a: f32, b: f32, k: f32) -> (f32, f32) {
    let h = (0.5 + 0.5 * (a - b) / k).clamp(0.0, 1.0);
    (a + (b - a) * h - k * h * (1.0 - h), h)
}

/// Polynomial smooth maximum of `a` and `b`, and the weight of `b`.
#[inline]
pub(super) fn smax(a: f32, b: f32, k: f32) -> (f32, f32) {
    let (d, h) = smin(-a, -b, k);
    (-d, h)
}

/// An axis-aligned ellipsoid with the approximate distance of Quilez (`k0 (k0 - 1) / k1`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Ellipsoid {
    pub(super) c: Vec3,
    pub(super) r: Vec3,
    inv_r: Vec3,
    inv_r2: Vec3,
    r_max: f32,
}

impl Ellipsoid {
    pub(super) fn new(c: Vec3, r: Vec3) -> Ellipsoid {
        let r = r.max(Vec3::splat(1e-4));
        Ellipsoid {
            c,
            r,
            inv_r: r.recip(),
            inv_r2: (r * r).recip(),
            r_max: r.max_element(),
        }
    }

    #[inline]
    pub(super) fn dist(&self, p: Vec3) -> f32 {
        let q = p - self.c;
        let k0 = (q * self.inv_r).length();
        let k1 = (q * self.inv_r2).length();
        if k1 < 1e-20 {
            return -self.r.min_element();
        }
        k0 * (k0 - 1.0) / k1
    }

    /// A lower bound of the distance: to the bounding sphere.
    #[inline]
    pub(super) fn bound(&self, p: Vec3) -> f32 {
        (p - self.c).length() - self.r_max
    }

    pub(super) fn extend(&self, lo: &mut Vec3, hi: &mut Vec3) {
        *lo = lo.min(self.c - self.r);
        *hi = hi.max(self.c + self.r);
    }
}

/// A capsule whose radius varies linearly from `ra` at `a` to `rb` at `b` (Quilez' round
/// cone).
#[derive(Debug, Clone, Copy)]
pub(super) struct RoundCone {
    pub(super) a: Vec3,
    pub(super) b: Vec3,
    pub(super) ra: f32,
    pub(super) rb: f32,
    centre: Vec3,
    bound_r: f32,
}

impl RoundCone {
    pub(super) fn new(a: Vec3, b: Vec3, ra: f32, rb: f32) -> RoundCone {
        let centre = 0.5 * (a + b);
        let bound_r = 0.5 * (b - a).length() + ra.max(rb);
        RoundCone {
            a,
            b,
            ra,
            rb,
            centre,
            bound_r,
        }
    }

    #[inline]
    pub(super) fn dist(&self, p: Vec3) -> f32 {
        let ba = self.b - self.a;
        let l2 = ba.length_squared();
        if l2 < 1e-12 {
            return (p - self.a).length() - self.ra.max(self.rb);
        }
        let rr = self.ra - self.rb;
        let a2 = l2 - rr * rr;
        let il2 = 1.0 / l2;
        let pa = p - self.a;
        let y = pa.dot(ba);
        let z = y - l2;
        let xv = pa * l2 - ba * y;
        let x2 = xv.length_squared();
        let y2 = y * y * l2;
        let z2 = z * z * l2;
        let k = rr.signum() * rr * rr * x2;
        if z.signum() * a2 * z2 > k {
            return (x2 + z2).sqrt() * il2 - self.rb;
        }
        if y.signum() * a2 * y2 < k {
            return (x2 + y2).sqrt() * il2 - self.ra;
        }
        ((x2 * a2 * il2).sqrt() + y * rr) * il2 - self.ra
    }

    #[inline]
    pub(super) fn bound(&self, p: Vec3) -> f32 {
        (p - self.centre).length() - self.bound_r
    }

    pub(super) fn extend(&self, lo: &mut Vec3, hi: &mut Vec3) {
        *lo = lo.min(self.centre - Vec3::splat(self.bound_r));
        *hi = hi.max(self.centre + Vec3::splat(self.bound_r));
    }
}

/// A box with rounded edges: half extents `b` (before rounding), corner radius `r`.
#[derive(Debug, Clone, Copy)]
pub(super) struct RoundBox {
    c: Vec3,
    b: Vec3,
    r: f32,
    bound_r: f32,
}

impl RoundBox {
    pub(super) fn new(c: Vec3, b: Vec3, r: f32) -> RoundBox {
        RoundBox {
            c,
            b,
            r,
            bound_r: b.length() + r,
        }
    }

    #[inline]
    pub(super) fn dist(&self, p: Vec3) -> f32 {
        let q = (p - self.c).abs() - self.b;
        q.max(Vec3::ZERO).length() + q.max_element().min(0.0) - self.r
    }

    #[inline]
    pub(super) fn bound(&self, p: Vec3) -> f32 {
        (p - self.c).length() - self.bound_r
    }
}
