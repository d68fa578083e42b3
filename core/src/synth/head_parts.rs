//! Where the synthetic head's parts go: the featureless face (skull, jaw, chin, cheeks) and
//! the brows, nose, mouth and eyelids placed on it, as [`Model`](super::head::Model) puts
//! them together.

use glam::{Vec2, Vec3};

use super::head_params::{FaceState, HeadParams};
use super::sdf::{Ellipsoid, RoundBox, RoundCone, smin};

/// Smooth-union widths of the featureless face's parts.
pub(super) const K_JAW: f32 = 0.03;
pub(super) const K_CHEEK: f32 = 0.025;
pub(super) const K_CHIN: f32 = 0.025;

/// The featureless face of a head that the features are placed on: skull, jaw, chin and
/// cheeks.
pub(super) struct BaseFace<'a> {
    h: &'a HeadParams,
    pub(super) skull: Ellipsoid,
    /// Right cheek; the left one is its mirror image (x -> -x).
    pub(super) cheek: Ellipsoid,
}

impl BaseFace<'_> {
    /// The featureless face of `h`.
    pub(super) fn new(h: &HeadParams) -> BaseFace<'_> {
        let skull = Ellipsoid::new(
            Vec3::new(0.0, 0.02, -0.005),
            Vec3::new(h.head_width, h.head_height, h.head_depth),
        );
        let cheek = Ellipsoid::new(
            Vec3::new(0.037, -0.014, 0.05),
            Vec3::new(0.028, 0.026, 0.032),
        );
        BaseFace { h, skull, cheek }
    }

    /// The jaw, dropped by `drop`.
    pub(super) fn jaw(&self, drop: f32) -> Ellipsoid {
        let h = self.h;
        Ellipsoid::new(
            Vec3::new(0.0, -0.05 - drop, 0.012),
            Vec3::new(h.jaw_width, h.jaw_height, 0.072),
        )
    }

    /// The chin, dropped by `drop`.
    pub(super) fn chin(&self, drop: f32) -> Ellipsoid {
        let h = self.h;
        Ellipsoid::new(
            Vec3::new(0.0, -0.084 - drop, 0.05),
            Vec3::new(1.25 * h.chin_size, 0.9 * h.chin_size, 0.95 * h.chin_size),
        )
    }

    /// The distance at `p` to the featureless face with the jaw dropped by `drop`.
    fn dist(&self, p: Vec3, drop: f32) -> f32 {
        let q = Vec3::new(p.x.abs(), p.y, p.z);
        let d = smin(self.skull.dist(p), self.jaw(drop).dist(p), K_JAW).0;
        let d = smin(d, self.chin(drop).dist(p), K_CHIN).0;
        smin(d, self.cheek.dist(q), K_CHEEK).0
    }

    /// Front surface of the featureless face at (x, y), found by marching along -z.
    pub(super) fn surface_z(&self, x: f32, y: f32, drop: f32) -> f32 {
        let mut z = 0.3;
        for _ in 0..200 {
            let d = self.dist(Vec3::new(x, y, z), drop);
            if d < 1e-6 {
                break;
            }
            z -= d.max(1e-6);
            if z < -0.2 {
                return 0.0;
            }
        }
        z
    }

    /// The right eyebrow, placed on the face at rest.
    pub(super) fn brow(&self) -> RoundCone {
        let h = self.h;
        let brow_in = Vec2::new(h.eye_spacing - 0.014, h.eye_height + h.brow_height);
        let brow_out = Vec2::new(h.eye_spacing + 0.017, brow_in.y + h.brow_tilt);
        RoundCone::new(
            brow_in.extend(self.surface_z(brow_in.x, brow_in.y, 0.0) - 0.4 * h.brow_thickness),
            brow_out.extend(self.surface_z(brow_out.x, brow_out.y, 0.0) - 0.6 * h.brow_thickness),
            h.brow_thickness,
            0.7 * h.brow_thickness,
        )
    }

    /// The nose: a round cone from the bridge to the tip, and the right nostril wing.
    pub(super) fn nose(&self) -> (RoundCone, Ellipsoid) {
        let h = self.h;
        let tip_y = h.mouth_height + 0.45 * (h.eye_height - h.mouth_height);
        let bridge_y = h.eye_height - 0.004;
        let bridge = Vec3::new(0.0, bridge_y, self.surface_z(0.0, bridge_y, 0.0) - 0.004);
        let tip_z = self.surface_z(0.0, tip_y, 0.0) + h.nose_length - h.nose_width;
        let nose = RoundCone::new(
            bridge,
            Vec3::new(0.0, tip_y, tip_z),
            0.45 * h.nose_width,
            h.nose_width,
        );
        let nostril = Ellipsoid::new(
            Vec3::new(
                0.75 * h.nose_width,
                tip_y - 0.35 * h.nose_width,
                tip_z - 0.6 * h.nose_width,
            ),
            Vec3::splat(0.55 * h.nose_width),
        );
        (nose, nostril)
    }

    /// The mouth in state `st`, open by `gap` with the jaw dropped by `drop`: the upper lip
    /// stays, the lower lip and the jaw drop as it opens.
    pub(super) fn mouth(&self, st: &FaceState, gap: f32, drop: f32) -> Mouth {
        let h = self.h;
        let lt = h.lip_thickness;
        let a = h.mouth_half_width * (0.75 + 0.5 * st.mouth_width);
        let my = h.mouth_height;
        let zm = self.surface_z(0.0, my, 0.0);
        let y_up = my + 0.3 * gap;
        let y_down = my - 0.7 * gap;
        let upper_lip = Ellipsoid::new(
            Vec3::new(0.0, y_up + 0.8 * lt, zm - 0.45 * lt),
            Vec3::new(a, lt, 1.15 * lt),
        );
        let zl = self.surface_z(0.0, y_down - 0.9 * lt, drop);
        let lower_lip = Ellipsoid::new(
            Vec3::new(0.0, y_down - 0.9 * lt, zl - 0.4 * lt),
            Vec3::new(0.95 * a, 1.15 * lt, 1.15 * lt),
        );
        let cavity = (gap > 1e-5).then(|| {
            Ellipsoid::new(
                Vec3::new(0.0, 0.5 * (y_up + y_down), zm - 0.014),
                Vec3::new(
                    0.85 * a,
                    0.5 * gap + 0.3 * lt * (10.0 * st.mouth_open).min(1.0),
                    0.024,
                ),
            )
        });
        let teeth = RoundBox::new(
            Vec3::new(0.0, y_up - 0.0025, zm - 0.0085),
            Vec3::new(0.55 * a, 0.0022, 0.003),
            0.0012,
        );
        let mouth_c = Vec3::new(0.0, 0.5 * (y_up + y_down), zm);
        let mouth_region = Ellipsoid::new(
            mouth_c,
            Vec3::new(a + 0.004, 0.5 * (y_up - y_down) + 2.0 * lt + 0.003, 0.06),
        );
        let mouth_group_r = (a + 0.01).max(0.5 * (y_up - y_down) + 3.0 * lt) + 0.02;
        Mouth {
            upper_lip,
            lower_lip,
            cavity,
            teeth,
            mouth_c,
            mouth_region,
            mouth_group_r,
        }
    }
}

/// The normals of the planes through the eye centre below which the upper lid and above
/// which the lower lid are open, with the lids at `blink`.
pub(super) fn lid_normals(blink: f32) -> (Vec3, Vec3) {
    let up_open = 0.42;
    let down_open = -0.55;
    let meet = -0.15;
    let up = up_open + (meet - 0.03 - up_open) * blink;
    let down = down_open + (meet + 0.03 - down_open) * blink;
    let lid_up_n = Vec3::new(0.0, up.cos(), -up.sin());
    let lid_down_n = Vec3::new(0.0, -down.cos(), down.sin());
    (lid_up_n, lid_down_n)
}

/// The parts of a mouth in one state, as [`BaseFace::mouth`] places them.
pub(super) struct Mouth {
    pub(super) upper_lip: Ellipsoid,
    pub(super) lower_lip: Ellipsoid,
    pub(super) cavity: Option<Ellipsoid>,
    pub(super) teeth: RoundBox,
    /// Centre of the mouth opening on the face.
    pub(super) mouth_c: Vec3,
    pub(super) mouth_region: Ellipsoid,
    pub(super) mouth_group_r: f32,
}
