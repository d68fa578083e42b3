//! The synthetic head model: the signed-distance field that places every part of one head
//! ([`HeadParams`]) in one animated state ([`FaceState`]) in head space, with the colour and
//! face region of each surface point. The parameters and their random draws live in
//! `head_params.rs` and are re-exported here.
//!
//! The head is a smooth union of ellipsoids, spheres and capsules in head space (AD-NeRF's
//! world: head near the origin, facing +z, +y up, about 0.25 units tall). Eyes with blinking
//! lids and a mouth whose opening and width follow a [`FaceState`] are carved into and added
//! onto it. [`render_head`](super::trace::render_head) and
//! [`render_background`](super::trace::render_background) render it into images.

use glam::Vec3;

use super::head_params::sanitized;
pub use super::head_params::{FaceState, HeadParams};
use super::head_parts::{BaseFace, K_CHEEK, K_CHIN, K_JAW, lid_normals};
use super::sdf::{Ellipsoid, RoundBox, RoundCone, smax, smin, smoothstep};
use crate::region::Region;

/// Margin added to every part's bounds: covers the bulge of the smooth unions.
const BOUNDS_MARGIN: f32 = 0.01;
/// Largest jaw drop (and mouth gap) at `mouth_open = 1`, in head units.
const MAX_GAP: f32 = 0.024;

/// Smooth-union widths of the parts (the featureless face's come with it).
const K_HAIR: f32 = 0.004;
const K_NOSE: f32 = 0.008;
const K_EAR: f32 = 0.008;
const K_BROW: f32 = 0.003;
const K_LIPS: f32 = 0.005;
const K_SOCKET: f32 = 0.004;
const K_CAVITY: f32 = 0.003;
const K_LID: f32 = 0.0015;
/// Axis-aligned bounds (min, max) in head space that contain the head in every FaceState.
pub fn head_bounds(head: &HeadParams) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for mouth_open in [0.0, 1.0] {
        for mouth_width in [0.0, 1.0] {
            let model = Model::new(
                head,
                &FaceState {
                    mouth_open,
                    mouth_width,
                    blink: 0.0,
                },
            );
            lo = lo.min(model.lo);
            hi = hi.max(model.hi);
        }
    }
    (lo, hi)
}

/// Material of a surface point: which part owns it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Part {
    Skin,
    Hair,
    Brow,
    Lips,
    Cavity,
    Teeth,
    Eyeball,
    Lid,
    Socket,
}

/// A surface sample as the material-tracking evaluation builds it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Surf {
    d: f32,
    pub(super) colour: Vec3,
    pub(super) part: Part,
}

/// Accumulates the field: the distance alone (`MAT = false`, the fast path used by the
/// march) or the distance with colour and owning part (`MAT = true`, at hit points).
struct Acc<const MAT: bool> {
    s: Surf,
}

impl<const MAT: bool> Acc<MAT> {
    #[inline]
    fn union(&mut self, d: f32, k: f32, part: Part, colour: impl FnOnce() -> Vec3) {
        let (nd, h) = smin(self.s.d, d, k);
        if MAT && h > 0.0 {
            self.s.colour = self.s.colour.lerp(colour(), h);
            if h > 0.5 {
                self.s.part = part;
            }
        }
        self.s.d = nd;
    }

    #[inline]
    fn hard_union(&mut self, d: f32, part: Part, colour: impl FnOnce() -> Vec3) {
        if d < self.s.d {
            self.s.d = d;
            if MAT {
                self.s.colour = colour();
                self.s.part = part;
            }
        }
    }

    /// Removes the solid where `d < 0` (smooth subtraction).
    #[inline]
    fn carve(&mut self, d: f32, k: f32, part: Part, colour: impl FnOnce() -> Vec3) {
        let (nd, h) = smax(self.s.d, -d, k);
        if MAT && h > 0.0 {
            self.s.colour = self.s.colour.lerp(colour(), h);
            if h > 0.5 {
                self.s.part = part;
            }
        }
        self.s.d = nd;
    }
}

/// The head of one [`HeadParams`] in one [`FaceState`], with every part placed.
pub(super) struct Model {
    skin: Vec3,
    blush_colour: Vec3,
    blush: f32,
    hair: Vec3,
    brow_colour: Vec3,
    lips: Vec3,
    iris: Vec3,
    pub(super) skull: Ellipsoid,
    jaw: Ellipsoid,
    chin: Ellipsoid,
    /// Right cheek; the left one is its mirror image (x -> -x).
    cheek: Ellipsoid,
    hair_n: Vec3,
    hair_off: f32,
    hair_thickness: f32,
    nose: RoundCone,
    /// Right nostril wing.
    nostril: Ellipsoid,
    /// Right ear.
    ear: Ellipsoid,
    /// Right eyeball centre.
    eye_c: Vec3,
    eye_r: f32,
    socket_r: f32,
    lid_r: f32,
    lid_half: f32,
    /// Normal of the plane through the eye centre below which the upper lid is open.
    lid_up_n: Vec3,
    /// Normal of the plane through the eye centre above which the lower lid is open.
    lid_down_n: Vec3,
    eye_region_r: f32,
    /// Right eyebrow.
    brow: RoundCone,
    upper_lip: Ellipsoid,
    lower_lip: Ellipsoid,
    cavity: Option<Ellipsoid>,
    teeth: RoundBox,
    mouth_c: Vec3,
    mouth_seam_y: f32,
    mouth_closed: f32,
    mouth_region: Ellipsoid,
    mouth_group_c: Vec3,
    mouth_group_r: f32,
    eye_group_r: f32,
    pub(super) light: Vec3,
    pub(super) lo: Vec3,
    pub(super) hi: Vec3,
}

impl Model {
    /// The head of `head` in `state` (clamped to its range), with every part placed and the
    /// bounds that hold them.
    pub(super) fn new(head: &HeadParams, state: &FaceState) -> Model {
        let st = state.clamped();
        let h = sanitized(head);
        let gap = MAX_GAP * st.mouth_open;
        let drop = 0.6 * gap;
        let face = BaseFace::new(&h);

        // Eyes, lids and brows, placed on the face at rest.
        let eye_r = h.eye_radius;
        let ez = face.surface_z(h.eye_spacing, h.eye_height, 0.0);
        let eye_c = Vec3::new(h.eye_spacing, h.eye_height, ez - 0.62 * eye_r);
        let (lid_up_n, lid_down_n) = lid_normals(st.blink);
        let brow = face.brow();
        let (nose, nostril) = face.nose();

        let ear = Ellipsoid::new(
            Vec3::new(h.head_width + 0.001, h.eye_height - 0.02, -0.014),
            Vec3::new(0.009, 0.026, 0.016) * h.ear_size,
        );

        // Hair: the skull grown by the hair thickness above a plane that rises to the front.
        let hair_n = Vec3::new(0.0, -1.0, 0.6).normalize();
        let hair_off = hair_n.dot(Vec3::new(0.0, h.hairline, 0.0));

        let mouth = face.mouth(&st, gap, drop);

        let skin = Vec3::from(h.skin);
        let hair = Vec3::from(h.hair);
        let mut m = Model {
            skin,
            blush_colour: skin * Vec3::new(1.02, 0.78, 0.78),
            blush: h.blush,
            hair,
            brow_colour: hair * 0.75,
            lips: Vec3::from(h.lips),
            iris: Vec3::from(h.iris),
            skull: face.skull,
            jaw: face.jaw(drop),
            chin: face.chin(drop),
            cheek: face.cheek,
            hair_n,
            hair_off,
            hair_thickness: h.hair_thickness,
            nose,
            nostril,
            ear,
            eye_c,
            eye_r,
            socket_r: eye_r + 0.002,
            lid_r: eye_r + 0.0017,
            lid_half: 0.0011,
            lid_up_n,
            lid_down_n,
            eye_region_r: eye_r + 0.006,
            brow,
            upper_lip: mouth.upper_lip,
            lower_lip: mouth.lower_lip,
            cavity: mouth.cavity,
            teeth: mouth.teeth,
            mouth_c: mouth.mouth_c,
            mouth_seam_y: h.mouth_height,
            mouth_closed: 1.0 - (4.0 * st.mouth_open).min(1.0),
            mouth_region: mouth.mouth_region,
            mouth_group_c: mouth.mouth_c,
            mouth_group_r: mouth.mouth_group_r,
            eye_group_r: eye_r + 0.006,
            light: Vec3::new(-0.35, 0.5, 0.8).normalize(),
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
        };
        (m.lo, m.hi) = m.part_bounds();
        m
    }

    /// Bounds (min, max) that contain every part, grown by [`BOUNDS_MARGIN`].
    fn part_bounds(&self) -> (Vec3, Vec3) {
        let m = self;
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        let grown = Ellipsoid::new(m.skull.c, m.skull.r + Vec3::splat(m.hair_thickness));
        let mirror = |e: Ellipsoid| Ellipsoid::new(e.c * Vec3::new(-1.0, 1.0, 1.0), e.r);
        for e in [
            grown,
            m.jaw,
            m.cheek,
            mirror(m.cheek),
            m.ear,
            mirror(m.ear),
            m.upper_lip,
            m.lower_lip,
        ] {
            e.extend(&mut lo, &mut hi);
        }
        for e in [m.nostril, mirror(m.nostril)] {
            e.extend(&mut lo, &mut hi);
        }
        m.nose.extend(&mut lo, &mut hi);
        m.brow.extend(&mut lo, &mut hi);
        let mb = m.brow;
        let flip = Vec3::new(-1.0, 1.0, 1.0);
        RoundCone::new(mb.a * flip, mb.b * flip, mb.ra, mb.rb).extend(&mut lo, &mut hi);
        for c in [m.eye_c, m.eye_c * flip] {
            lo = lo.min(c - Vec3::splat(m.lid_r + m.lid_half));
            hi = hi.max(c + Vec3::splat(m.lid_r + m.lid_half));
        }
        (
            lo - Vec3::splat(BOUNDS_MARGIN),
            hi + Vec3::splat(BOUNDS_MARGIN),
        )
    }

    /// The signed distance (a lower bound of it, Lipschitz about 1) at `p`.
    #[inline]
    pub(super) fn sdf(&self, p: Vec3) -> f32 {
        self.field::<false>(p).d
    }

    /// The field at `p`; with `MAT` also the colour and owning part of the nearest surface.
    #[inline]
    pub(super) fn field<const MAT: bool>(&self, p: Vec3) -> Surf {
        // Mirror: every paired part is stored for the right side (x > 0).
        let q = Vec3::new(p.x.abs(), p.y, p.z);
        let skull = self.skull.dist(p);
        let mut acc = Acc::<MAT> {
            s: Surf {
                d: skull,
                colour: self.skin,
                part: Part::Skin,
            },
        };
        self.add_face::<MAT>(&mut acc, p, q, skull);
        self.add_mouth::<MAT>(&mut acc, p);
        self.add_eyes::<MAT>(&mut acc, q);
        acc.s
    }

    /// Adds the jaw, chin, cheeks (with their blush), hair cap, ears, nose and brows to the
    /// field at `p` (`q` is `p` mirrored to x > 0, `skull` the skull's distance).
    #[inline]
    fn add_face<const MAT: bool>(&self, acc: &mut Acc<MAT>, p: Vec3, q: Vec3, skull: f32) {
        if self.jaw.bound(p) < acc.s.d + K_JAW {
            acc.union(self.jaw.dist(p), K_JAW, Part::Skin, || self.skin);
        }
        if self.chin.bound(p) < acc.s.d + K_CHIN {
            acc.union(self.chin.dist(p), K_CHIN, Part::Skin, || self.skin);
        }
        if self.cheek.bound(q) < acc.s.d + K_CHEEK {
            acc.union(self.cheek.dist(q), K_CHEEK, Part::Skin, || self.skin);
        }
        if MAT {
            let w = self.blush
                * (-(q - self.cheek.c - Vec3::new(0.0, 0.0, 0.02)).length_squared()
                    / (0.022 * 0.022))
                    .exp();
            acc.s.colour = acc.s.colour.lerp(self.blush_colour, w);
        }
        // Hair cap.
        let hair_d = smax(
            skull - self.hair_thickness,
            self.hair_n.dot(p) - self.hair_off,
            0.01,
        )
        .0;
        acc.union(hair_d, K_HAIR, Part::Hair, || {
            // Fine strands radiating from the crown, darker towards the hairline.
            let phi = p.x.atan2(p.z);
            let strands = 0.92 + 0.08 * (phi * 70.0 + 40.0 * p.y).sin();
            let edge = smoothstep(0.0, 0.02, self.hair_off - self.hair_n.dot(p));
            self.hair * strands * (0.85 + 0.15 * edge)
        });
        if self.ear.bound(q) < acc.s.d + K_EAR {
            acc.union(self.ear.dist(q), K_EAR, Part::Skin, || {
                self.skin * Vec3::new(1.0, 0.92, 0.92)
            });
        }
        if self.nose.bound(p) < acc.s.d + K_NOSE {
            let tip = self.nose.b;
            let nose_colour = || {
                let w = (-(p - tip).length_squared() / (0.012 * 0.012)).exp() * 0.5 * self.blush;
                self.skin.lerp(self.blush_colour, w)
            };
            acc.union(self.nose.dist(p), K_NOSE, Part::Skin, nose_colour);
            if self.nostril.bound(q) < acc.s.d + K_NOSE {
                acc.union(self.nostril.dist(q), K_NOSE, Part::Skin, nose_colour);
            }
        }
        if self.brow.bound(q) < acc.s.d + K_BROW {
            acc.union(self.brow.dist(q), K_BROW, Part::Brow, || self.brow_colour);
        }
    }

    /// Adds the mouth to the field at `p`: lips on, cavity out, teeth in.
    #[inline]
    fn add_mouth<const MAT: bool>(&self, acc: &mut Acc<MAT>, p: Vec3) {
        // Mouth: lips on, cavity out, teeth in.
        if (p - self.mouth_group_c).length() - self.mouth_group_r < acc.s.d.abs() + 0.01 {
            let lip_colour = || {
                let seam =
                    (-((p.y - self.mouth_seam_y) / 0.0018).powi(2)).exp() * self.mouth_closed;
                self.lips * (1.0 - 0.55 * seam)
            };
            if self.upper_lip.bound(p) < acc.s.d + K_LIPS {
                acc.union(self.upper_lip.dist(p), K_LIPS, Part::Lips, lip_colour);
            }
            if self.lower_lip.bound(p) < acc.s.d + K_LIPS {
                acc.union(self.lower_lip.dist(p), K_LIPS, Part::Lips, lip_colour);
            }
            if let Some(cav) = &self.cavity
                && cav.bound(p) < K_CAVITY - acc.s.d
            {
                let cavity_colour = || {
                    let depth = ((self.mouth_c.z - p.z) / 0.02).clamp(0.0, 1.0);
                    Vec3::new(0.42, 0.10, 0.11) * (1.0 - 0.6 * depth)
                };
                acc.carve(cav.dist(p), K_CAVITY, Part::Cavity, cavity_colour);
                if self.teeth.bound(p) < acc.s.d {
                    acc.hard_union(self.teeth.dist(p), Part::Teeth, || {
                        Vec3::new(0.93, 0.91, 0.85)
                    });
                }
            }
        }
    }

    /// Adds the eyes to the field at `q` (mirrored to x > 0): socket out, eyeball and lids in.
    #[inline]
    fn add_eyes<const MAT: bool>(&self, acc: &mut Acc<MAT>, q: Vec3) {
        // Eyes: socket out, eyeball and lids in.
        let qe = q - self.eye_c;
        let de = qe.length();
        if de - self.eye_group_r < acc.s.d.abs() + 0.01 {
            acc.carve(de - self.socket_r, K_SOCKET, Part::Socket, || {
                self.skin * 0.85
            });
            let iris = self.iris;
            let eye_r = self.eye_r;
            acc.hard_union(de - eye_r, Part::Eyeball, || {
                let c = qe.z / de.max(1e-9);
                let rho = (1.0 - c * c).max(0.0).sqrt();
                let sclera = Vec3::new(0.95, 0.94, 0.92);
                let iris_edge = 0.5;
                let pupil_edge = 0.22;
                let ring = 0.75 + 0.25 * (rho / iris_edge).clamp(0.0, 1.0);
                let iris_c = iris * (1.15 - 0.35 * ring);
                let mut col =
                    sclera.lerp(iris_c, 1.0 - smoothstep(iris_edge - 0.04, iris_edge, rho));
                col = col.lerp(
                    Vec3::splat(0.04),
                    1.0 - smoothstep(pupil_edge - 0.03, pupil_edge, rho),
                );
                if c < 0.0 { sclera * 0.5 } else { col }
            });
            let shell = (de - self.lid_r).abs() - self.lid_half;
            let lid = shell
                .max(-qe.dot(self.lid_up_n))
                .min(shell.max(-qe.dot(self.lid_down_n)));
            acc.union(lid, K_LID, Part::Lid, || self.skin * 0.93);
        }
    }

    pub(super) fn region(&self, p: Vec3, part: Part) -> Region {
        let q = Vec3::new(p.x.abs(), p.y, p.z);
        if matches!(part, Part::Eyeball | Part::Lid)
            || (q - self.eye_c).length() < self.eye_region_r
        {
            return Region::Eyes;
        }
        if matches!(part, Part::Lips | Part::Cavity | Part::Teeth)
            || self.mouth_region.dist(p) < 0.0
        {
            return Region::Mouth;
        }
        Region::Face
    }
}
