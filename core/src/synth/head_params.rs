//! The synthetic head's parameters: the shape and colours of one head ([`HeadParams`]) with
//! their random draws, and its animated state ([`FaceState`]).

use glam::Vec3;
use rand::Rng;
use serde::{Deserialize, Serialize};

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
        let shape = HeadParams::random_shape(rng);
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
            ..shape
        }
    }

    /// Every proportion of a random head drawn around [`HeadParams::default`]'s, with the
    /// default's colours; the first draws of [`HeadParams::random`].
    fn random_shape(rng: &mut impl Rng) -> HeadParams {
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
        HeadParams {
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
            ..d
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

/// `c` with each channel moved by a random amount within `amount`, clamped to [0, 1].
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

/// Parameters made safe to evaluate: every length finite and positive, every colour finite
/// and in [0, 1].
pub(super) fn sanitized(head: &HeadParams) -> HeadParams {
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
