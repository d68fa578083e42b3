//! The synthetic head model: the shape and colours of one head ([`HeadParams`]), its animated
//! state ([`FaceState`]), and the signed-distance field that places every part in head space,
//! with the colour and face region of each surface point.
//!
//! The head is a smooth union of ellipsoids, spheres and capsules in head space (AD-NeRF's
//! world: head near the origin, facing +z, +y up, about 0.25 units tall). Eyes with blinking
//! lids and a mouth whose opening and width follow a [`FaceState`] are carved into and added
//! onto it. [`render_head`](super::trace::render_head) and
//! [`render_background`](super::trace::render_background) render it into images.

use glam::{Vec2, Vec3};
use rand::Rng;
use serde::{Deserialize, Serialize};

use super::sdf::{Ellipsoid, RoundBox, RoundCone, smax, smin, smoothstep};
use crate::region::Region;

/// Margin added to every part's bounds: covers the bulge of the smooth unions.
const BOUNDS_MARGIN: f32 = 0.01;
/// Largest jaw drop (and mouth gap) at `mouth_open = 1`, in head units.
const MAX_GAP: f32 = 0.024;

/// Smooth-union widths of the parts.
const K_JAW: f32 = 0.03;
const K_CHEEK: f32 = 0.025;
const K_CHIN: f32 = 0.025;
const K_HAIR: f32 = 0.004;
const K_NOSE: f32 = 0.008;
const K_EAR: f32 = 0.008;
const K_BROW: f32 = 0.003;
const K_LIPS: f32 = 0.005;
const K_SOCKET: f32 = 0.004;
const K_CAVITY: f32 = 0.003;
const K_LID: f32 = 0.0015;

/// Shape and colour parameters of one synthetic head. Lengths are in head units (the head is
/// about 0.25 tall); colours are linear RGB in [0, 1].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeadParams {
    /// Skin colour.
    pub skin: [f32; 3],
    /// How much redder the cheeks are than the rest of the skin, 0..1.
    pub blush: f32,
    /// Hair colour (also the eyebrows, darker).
    pub hair: [f32; 3],
    /// Lip colour.
    pub lips: [f32; 3],
    /// Iris colour.
    pub iris: [f32; 3],
    /// Skull half-width (x radius).
    pub head_width: f32,
    /// Skull half-height (y radius).
    pub head_height: f32,
    /// Skull half-depth (z radius).
    pub head_depth: f32,
    /// Jaw half-width.
    pub jaw_width: f32,
    /// Jaw half-height.
    pub jaw_height: f32,
    /// Chin radius.
    pub chin_size: f32,
    /// Half the distance between the eye centres.
    pub eye_spacing: f32,
    /// Height of the eye centres.
    pub eye_height: f32,
    /// Eyeball radius.
    pub eye_radius: f32,
    /// How far the nose tip stands out of the face.
    pub nose_length: f32,
    /// Radius of the nose tip.
    pub nose_width: f32,
    /// Height of the mouth's centre line.
    pub mouth_height: f32,
    /// Half-width of the mouth at neutral width (`mouth_width = 0.5`).
    pub mouth_half_width: f32,
    /// Half-thickness of each lip.
    pub lip_thickness: f32,
    /// Height of the eyebrows above the eye centres.
    pub brow_height: f32,
    /// Rise of the outer end of each eyebrow over its inner end.
    pub brow_tilt: f32,
    /// Radius of the eyebrow strokes.
    pub brow_thickness: f32,
    /// Height of the hairline at the middle of the head (z = 0); it is higher at the front.
    pub hairline: f32,
    /// Thickness of the hair cap.
    pub hair_thickness: f32,
    /// Ear scale, about 1.
    pub ear_size: f32,
}

impl Default for HeadParams {
    fn default() -> Self {
        HeadParams {
            skin: [0.86, 0.66, 0.54],
            blush: 0.5,
            hair: [0.22, 0.14, 0.09],
            lips: [0.72, 0.33, 0.33],
            iris: [0.30, 0.45, 0.62],
            head_width: 0.078,
            head_height: 0.105,
            head_depth: 0.092,
            jaw_width: 0.058,
            jaw_height: 0.055,
            chin_size: 0.024,
            eye_spacing: 0.032,
            eye_height: 0.02,
            eye_radius: 0.0165,
            nose_length: 0.02,
            nose_width: 0.0095,
            mouth_height: -0.05,
            mouth_half_width: 0.024,
            lip_thickness: 0.0055,
            brow_height: 0.026,
            brow_tilt: 0.004,
            brow_thickness: 0.0034,
            hairline: 0.018,
            hair_thickness: 0.008,
            ear_size: 1.0,
        }
    }
}

impl HeadParams {
    /// A random head: skin tone, hair, lip and iris colours and every proportion drawn around
    /// [`HeadParams::default`], within ranges that always give a plausible face.
    /// Deterministic for the state of `rng`.
    pub fn random(rng: &mut impl Rng) -> HeadParams {
        let d = HeadParams::default();
        let mut jitter = |v: f32, rel: f32| v * (1.0 + rng.random_range(-rel..=rel));
        let head_width = jitter(d.head_width, 0.08);
        let head_height = jitter(d.head_height, 0.07);
        let head_depth = jitter(d.head_depth, 0.06);
        let jaw_width = jitter(d.jaw_width, 0.1);
        let jaw_height = jitter(d.jaw_height, 0.08);
        let chin_size = jitter(d.chin_size, 0.15);
        let eye_spacing = jitter(d.eye_spacing, 0.08);
        let eye_height = jitter(d.eye_height, 0.15);
        let eye_radius = jitter(d.eye_radius, 0.08);
        let nose_length = jitter(d.nose_length, 0.2);
        let nose_width = jitter(d.nose_width, 0.15);
        let mouth_height = jitter(d.mouth_height, 0.06);
        let mouth_half_width = jitter(d.mouth_half_width, 0.12);
        let lip_thickness = jitter(d.lip_thickness, 0.15);
        let brow_height = jitter(d.brow_height, 0.1);
        let brow_tilt = jitter(d.brow_tilt, 0.8);
        let brow_thickness = jitter(d.brow_thickness, 0.15);
        let hairline = jitter(d.hairline, 0.5);
        let hair_thickness = jitter(d.hair_thickness, 0.3);
        let ear_size = jitter(d.ear_size, 0.12);

        let tone = rng.random::<f32>();
        let light = Vec3::new(0.96, 0.80, 0.69);
        let dark = Vec3::new(0.42, 0.27, 0.19);
        let skin = jitter_color(rng, dark.lerp(light, tone), 0.03);
        const HAIR: [[f32; 3]; 7] = [
            [0.05, 0.04, 0.04],
            [0.16, 0.10, 0.06],
            [0.30, 0.19, 0.11],
            [0.45, 0.20, 0.09],
            [0.75, 0.62, 0.38],
            [0.55, 0.53, 0.52],
            [0.22, 0.14, 0.09],
        ];
        let hair_base = Vec3::from(HAIR[rng.random_range(0..HAIR.len())]);
        let hair = jitter_color(rng, hair_base, 0.03);
        let lip_tint = Vec3::new(
            rng.random_range(0.78..0.88),
            rng.random_range(0.40..0.55),
            rng.random_range(0.42..0.58),
        );
        let lips = jitter_color(rng, Vec3::from(skin) * lip_tint, 0.02);
        const IRIS: [[f32; 3]; 5] = [
            [0.33, 0.20, 0.10],
            [0.28, 0.45, 0.65],
            [0.30, 0.50, 0.30],
            [0.45, 0.38, 0.18],
            [0.45, 0.50, 0.52],
        ];
        let iris_base = Vec3::from(IRIS[rng.random_range(0..IRIS.len())]);
        let iris = jitter_color(rng, iris_base, 0.04);
        let blush = rng.random_range(0.2..0.8);
        HeadParams {
            skin,
            blush,
            hair,
            lips,
            iris,
            head_width,
            head_height,
            head_depth,
            jaw_width,
            jaw_height,
            chin_size,
            eye_spacing,
            eye_height,
            eye_radius,
            nose_length,
            nose_width,
            mouth_height,
            mouth_half_width,
            lip_thickness,
            brow_height,
            brow_tilt,
            brow_thickness,
            hairline,
            hair_thickness,
            ear_size,
        }
    }
}

impl HeadParams {
    /// The second head ([`super::HeadStyle::Second`]): a random head made longer and
    /// narrower, with a long jaw, a fuller cap of light hair, a darker skin tone and larger
    /// ears, so that a recipe tuned on the standard head meets other shapes and colours.
    pub fn second(rng: &mut impl Rng) -> HeadParams {
        let h = HeadParams::random(rng);
        let tone = rng.random_range(0.0..0.35f32);
        let light = Vec3::new(0.96, 0.80, 0.69);
        let dark = Vec3::new(0.42, 0.27, 0.19);
        let skin = dark.lerp(light, tone).to_array();
        let lips = (Vec3::from(skin) * Vec3::new(0.8, 0.5, 0.52)).to_array();
        HeadParams {
            skin,
            lips,
            hair: [0.80, 0.70, 0.48],
            head_width: h.head_width * 0.88,
            head_height: h.head_height * 1.1,
            jaw_width: h.jaw_width * 0.86,
            jaw_height: h.jaw_height * 1.2,
            hairline: h.hairline * 0.5,
            hair_thickness: h.hair_thickness * 1.6,
            ear_size: h.ear_size * 1.2,
            ..h
        }
    }
}

fn jitter_color(rng: &mut impl Rng, c: Vec3, amount: f32) -> [f32; 3] {
    let j = Vec3::new(
        rng.random_range(-amount..=amount),
        rng.random_range(-amount..=amount),
        rng.random_range(-amount..=amount),
    );
    (c + j).clamp(Vec3::ZERO, Vec3::ONE).to_array()
}

/// The animated part of a face: what the audio and the blink track drive.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FaceState {
    /// Mouth opening: 0 closed .. 1 wide open.
    pub mouth_open: f32,
    /// Mouth width: 0 narrow .. 1 wide, 0.5 neutral.
    pub mouth_width: f32,
    /// Eyelids: 0 open .. 1 closed.
    pub blink: f32,
}

impl Default for FaceState {
    fn default() -> Self {
        FaceState {
            mouth_open: 0.0,
            mouth_width: 0.5,
            blink: 0.0,
        }
    }
}

impl FaceState {
    /// The state with every field clamped to [0, 1] (NaN becomes the neutral value).
    pub fn clamped(&self) -> FaceState {
        let c = |v: f32, neutral: f32| {
            if v.is_nan() {
                neutral
            } else {
                v.clamp(0.0, 1.0)
            }
        };
        FaceState {
            mouth_open: c(self.mouth_open, 0.0),
            mouth_width: c(self.mouth_width, 0.5),
            blink: c(self.blink, 0.0),
        }
    }
}

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
    pub(super) fn new(head: &HeadParams, state: &FaceState) -> Model {
        let st = state.clamped();
        let h = sanitized(head);
        let gap = MAX_GAP * st.mouth_open;
        let drop = 0.6 * gap;
        let skull = Ellipsoid::new(
            Vec3::new(0.0, 0.02, -0.005),
            Vec3::new(h.head_width, h.head_height, h.head_depth),
        );
        let jaw_at = |drop: f32| {
            Ellipsoid::new(
                Vec3::new(0.0, -0.05 - drop, 0.012),
                Vec3::new(h.jaw_width, h.jaw_height, 0.072),
            )
        };
        let chin_at = |drop: f32| {
            Ellipsoid::new(
                Vec3::new(0.0, -0.084 - drop, 0.05),
                Vec3::new(1.25 * h.chin_size, 0.9 * h.chin_size, 0.95 * h.chin_size),
            )
        };
        let cheek = Ellipsoid::new(
            Vec3::new(0.037, -0.014, 0.05),
            Vec3::new(0.028, 0.026, 0.032),
        );
        let base = |p: Vec3, drop: f32| {
            let q = Vec3::new(p.x.abs(), p.y, p.z);
            let d = smin(skull.dist(p), jaw_at(drop).dist(p), K_JAW).0;
            let d = smin(d, chin_at(drop).dist(p), K_CHIN).0;
            smin(d, cheek.dist(q), K_CHEEK).0
        };
        // Front surface of the featureless face at (x, y), found by marching along -z.
        let surface_z = |x: f32, y: f32, drop: f32| {
            let mut z = 0.3;
            for _ in 0..200 {
                let d = base(Vec3::new(x, y, z), drop);
                if d < 1e-6 {
                    break;
                }
                z -= d.max(1e-6);
                if z < -0.2 {
                    return 0.0;
                }
            }
            z
        };

        // Eyes, lids and brows, placed on the face at rest.
        let eye_r = h.eye_radius;
        let ez = surface_z(h.eye_spacing, h.eye_height, 0.0);
        let eye_c = Vec3::new(h.eye_spacing, h.eye_height, ez - 0.62 * eye_r);
        let up_open = 0.42;
        let down_open = -0.55;
        let meet = -0.15;
        let up = up_open + (meet - 0.03 - up_open) * st.blink;
        let down = down_open + (meet + 0.03 - down_open) * st.blink;
        let lid_up_n = Vec3::new(0.0, up.cos(), -up.sin());
        let lid_down_n = Vec3::new(0.0, -down.cos(), down.sin());
        let brow_in = Vec2::new(h.eye_spacing - 0.014, h.eye_height + h.brow_height);
        let brow_out = Vec2::new(h.eye_spacing + 0.017, brow_in.y + h.brow_tilt);
        let brow = RoundCone::new(
            brow_in.extend(surface_z(brow_in.x, brow_in.y, 0.0) - 0.4 * h.brow_thickness),
            brow_out.extend(surface_z(brow_out.x, brow_out.y, 0.0) - 0.6 * h.brow_thickness),
            h.brow_thickness,
            0.7 * h.brow_thickness,
        );

        // Nose: a round cone from the bridge to the tip, with two nostril wings.
        let tip_y = h.mouth_height + 0.45 * (h.eye_height - h.mouth_height);
        let bridge_y = h.eye_height - 0.004;
        let bridge = Vec3::new(0.0, bridge_y, surface_z(0.0, bridge_y, 0.0) - 0.004);
        let tip_z = surface_z(0.0, tip_y, 0.0) + h.nose_length - h.nose_width;
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

        let ear = Ellipsoid::new(
            Vec3::new(h.head_width + 0.001, h.eye_height - 0.02, -0.014),
            Vec3::new(0.009, 0.026, 0.016) * h.ear_size,
        );

        // Hair: the skull grown by the hair thickness above a plane that rises to the front.
        let hair_n = Vec3::new(0.0, -1.0, 0.6).normalize();
        let hair_off = hair_n.dot(Vec3::new(0.0, h.hairline, 0.0));

        // Mouth: the upper lip stays, the lower lip and the jaw drop as it opens.
        let lt = h.lip_thickness;
        let a = h.mouth_half_width * (0.75 + 0.5 * st.mouth_width);
        let my = h.mouth_height;
        let zm = surface_z(0.0, my, 0.0);
        let y_up = my + 0.3 * gap;
        let y_down = my - 0.7 * gap;
        let upper_lip = Ellipsoid::new(
            Vec3::new(0.0, y_up + 0.8 * lt, zm - 0.45 * lt),
            Vec3::new(a, lt, 1.15 * lt),
        );
        let zl = surface_z(0.0, y_down - 0.9 * lt, drop);
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
            skull,
            jaw: jaw_at(drop),
            chin: chin_at(drop),
            cheek,
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
            upper_lip,
            lower_lip,
            cavity,
            teeth,
            mouth_c,
            mouth_seam_y: my,
            mouth_closed: 1.0 - (4.0 * st.mouth_open).min(1.0),
            mouth_region,
            mouth_group_c: mouth_c,
            mouth_group_r,
            eye_group_r: eye_r + 0.006,
            light: Vec3::new(-0.35, 0.5, 0.8).normalize(),
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
        };
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        let grown = Ellipsoid::new(skull.c, skull.r + Vec3::splat(h.hair_thickness));
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
        m.lo = lo - Vec3::splat(BOUNDS_MARGIN);
        m.hi = hi + Vec3::splat(BOUNDS_MARGIN);
        m
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
        acc.s
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

/// Parameters made safe to evaluate: every length finite and positive, every colour finite
/// and in [0, 1].
fn sanitized(head: &HeadParams) -> HeadParams {
    let d = HeadParams::default();
    let len = |v: f32, dv: f32| if v.is_finite() && v > 0.0 { v } else { dv };
    let pos = |v: f32, dv: f32| if v.is_finite() { v } else { dv };
    let col = |c: [f32; 3], dc: [f32; 3]| {
        let v = Vec3::from(c);
        if v.is_finite() {
            v.clamp(Vec3::ZERO, Vec3::ONE).to_array()
        } else {
            dc
        }
    };
    HeadParams {
        skin: col(head.skin, d.skin),
        blush: pos(head.blush, d.blush).clamp(0.0, 1.0),
        hair: col(head.hair, d.hair),
        lips: col(head.lips, d.lips),
        iris: col(head.iris, d.iris),
        head_width: len(head.head_width, d.head_width),
        head_height: len(head.head_height, d.head_height),
        head_depth: len(head.head_depth, d.head_depth),
        jaw_width: len(head.jaw_width, d.jaw_width),
        jaw_height: len(head.jaw_height, d.jaw_height),
        chin_size: len(head.chin_size, d.chin_size),
        eye_spacing: len(head.eye_spacing, d.eye_spacing),
        eye_height: pos(head.eye_height, d.eye_height),
        eye_radius: len(head.eye_radius, d.eye_radius),
        nose_length: len(head.nose_length, d.nose_length),
        nose_width: len(head.nose_width, d.nose_width),
        mouth_height: pos(head.mouth_height, d.mouth_height),
        mouth_half_width: len(head.mouth_half_width, d.mouth_half_width),
        lip_thickness: len(head.lip_thickness, d.lip_thickness),
        brow_height: pos(head.brow_height, d.brow_height),
        brow_tilt: pos(head.brow_tilt, d.brow_tilt),
        brow_thickness: len(head.brow_thickness, d.brow_thickness),
        hairline: pos(head.hairline, d.hairline),
        hair_thickness: len(head.hair_thickness, d.hair_thickness),
        ear_size: len(head.ear_size, d.ear_size),
    }
}
