//! AD-NeRF's 68 landmarks (iBUG 300-W's order: jaw 0-16, brows 17-26, nose 27-35, eyes
//! 36-47, outer lips 48-59, inner lips 60-67) taken from mediapipe's 468-point face mesh,
//! one mesh vertex per landmark. The image's left comes first, as in 300-W.

use nldf_core::landmarks::{Landmarks, N_LANDMARKS};

/// The mesh vertex of each of the 68 landmarks.
pub const MESH_OF_68: [usize; N_LANDMARKS] = [
    // jaw, from the image's left ear to its right ear through the chin (152)
    127, 234, 93, 132, 58, 172, 136, 150, 152, 377, 365, 397, 288, 361, 323, 454, 356,
    // brows, image left then right
    70, 63, 105, 66, 107, 336, 296, 334, 293, 300,
    // nose bridge, then the nostrils' lower edge
    168, 197, 5, 4, 75, 97, 2, 326, 305,
    // eyes, image left then right, each from its outer corner clockwise
    33, 160, 158, 133, 153, 144, 362, 385, 387, 263, 373, 380,
    // outer lips from the image-left corner over the upper lip, then back under the lower
    61, 39, 37, 0, 267, 269, 291, 405, 314, 17, 84, 181, // inner lips, the same way round
    78, 82, 13, 312, 308, 317, 14, 87,
];

/// The 68 landmarks of a frame's 468 mesh points (pixels).
///
/// # Panics
/// Never: a mesh with fewer than 468 points gives `None`.
pub fn landmarks_68(mesh: &[[f32; 2]]) -> Option<Landmarks> {
    let points = MESH_OF_68
        .iter()
        .map(|&m| mesh.get(m).copied())
        .collect::<Option<Vec<_>>>()?;
    Some(Landmarks { points })
}

/// The mesh's lower face outline, image left to right through the chin: the jaw of
/// [`MESH_OF_68`] (points 0-16), where the head ends and the neck begins.
pub fn jaw_line(mesh: &[[f32; 2]]) -> Option<Vec<[f32; 2]>> {
    MESH_OF_68[..17]
        .iter()
        .map(|&m| mesh.get(m).copied())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_landmark_is_a_distinct_mesh_vertex() {
        let mut seen = std::collections::BTreeSet::new();
        for &m in &MESH_OF_68 {
            assert!(m < 468);
            assert!(seen.insert(m), "vertex {m} twice");
        }
    }

    #[test]
    fn the_landmarks_follow_the_mesh_points() {
        let mesh: Vec<[f32; 2]> = (0..468).map(|i| [i as f32, -(i as f32)]).collect();
        let lms = landmarks_68(&mesh).unwrap();
        assert_eq!(lms.points[8], [152.0, -152.0]);
        assert_eq!(lms.points[48], [61.0, -61.0]);
        assert!(landmarks_68(&mesh[..400]).is_none());
    }
}
