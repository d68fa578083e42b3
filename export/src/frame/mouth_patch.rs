//! An upsampled frame graph's mouth patch: the output pixels whose rays meet the
//! upsampler's mouth box (`UpsamplerConfig::mouth_patch`), tested only inside the rectangle
//! the box's corners project to, their rays after the coarse rays in the student's pass,
//! and their pixels painted over the upsampled frame (`nldf_train`'s `paint_mouth_patch`).

use nldf_core::camera::Intrinsics;
use nldf_model::onnx::DataType;

use super::select::{
    hit_rays, mask_indices, pixel_coords, pose_columns, ray_directions, slab_hits,
};
use crate::checkpoint::StudentCheckpoint;
use crate::graph::{GraphBuilder, attr_int};

/// The pixel rows and columns (int64 `[n]` index lists, ascending) of the rectangle that
/// the corners of `bounds` project to in the camera `k` at `pose`, grown by one pixel on
/// each side and clipped to the image; the whole image when a corner is not in front of
/// the camera (its depth below 1e-6), where the projection bounds nothing. A pixel whose
/// ray meets the box lies inside: the box's image is the hull of its corners' images. The
/// pose must be rigid (a rotation and a translation, as every camera-to-world pose is):
/// `(p - o) R` is then its inverse.
fn projected_rect(
    g: &mut GraphBuilder,
    bounds: &nldf_core::bounds::Bounds,
    k: &Intrinsics,
    pose: &str,
) -> (String, String) {
    let (h, w) = (k.height as usize, k.width as usize);
    let (lo, hi) = (bounds.lo, bounds.hi);
    let corners: Vec<f32> = (0..8)
        .flat_map(|c| {
            [
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            ]
        })
        .collect();
    let corners = g.constant_f32("patch.rect.corners", &[8, 3], &corners);
    let slice = |g: &mut GraphBuilder, name: &str, lo: [i64; 2], hi: [i64; 2]| {
        let lo = g.constant_i64(&format!("{name}.start"), &[2], &lo);
        let hi = g.constant_i64(&format!("{name}.end"), &[2], &hi);
        g.node("Slice", name, &[pose, &lo, &hi], vec![])
    };
    let rotation = slice(g, "patch.rect.rotation", [0, 0], [3, 3]);
    let origin = slice(g, "patch.rect.origin_column", [0, 3], [3, 4]);
    let row = g.constant_i64("patch.rect.row_shape", &[2], &[1, 3]);
    let origin = g.node("Reshape", "patch.rect.origin", &[&origin, &row], vec![]);
    // Camera coordinates: (p - o) R, the rotation's columns being the camera's axes.
    let rel = g.node("Sub", "patch.rect.relative", &[&corners, &origin], vec![]);
    let cam = g.node("MatMul", "patch.rect.camera", &[&rel, &rotation], vec![]);
    let axis1 = g.constant_i64("patch.rect.axis1", &[1], &[1]);
    let coord = |g: &mut GraphBuilder, name: &str, a: i64| {
        let lo = g.constant_i64(&format!("{name}.start"), &[1], &[a]);
        let hi = g.constant_i64(&format!("{name}.end"), &[1], &[a + 1]);
        g.node("Slice", name, &[&cam, &lo, &hi, &axis1], vec![])
    };
    let x = coord(g, "patch.rect.x", 0);
    let y = coord(g, "patch.rect.y", 1);
    let z = coord(g, "patch.rect.z", 2);
    let depth = g.node("Neg", "patch.rect.depth", &[&z], vec![]);
    let tiny = g.constant_f32("patch.rect.min_depth", &[], &[1e-6]);
    let front = g.node("Greater", "patch.rect.in_front", &[&depth, &tiny], vec![]);
    let front = g.node(
        "Cast",
        "patch.rect.in_front_i64",
        &[&front],
        vec![attr_int("to", DataType::Int64 as i64)],
    );
    let all_axes = || vec![attr_int("keepdims", 0)];
    let all_front = g.node(
        "ReduceMin",
        "patch.rect.all_front_i64",
        &[&front],
        all_axes(),
    );
    let zero_i = g.constant_i64("patch.rect.zero_i", &[], &[0]);
    let all_front = g.node(
        "Greater",
        "patch.rect.all_front",
        &[&all_front, &zero_i],
        vec![],
    );
    let safe = g.node("Max", "patch.rect.safe_depth", &[&depth, &tiny], vec![]);
    let focal = g.constant_f32("patch.rect.focal", &[], &[k.focal]);
    let px = g.node("Div", "patch.rect.x_over_depth", &[&x, &safe], vec![]);
    let py = g.node("Div", "patch.rect.y_over_depth", &[&y, &safe], vec![]);
    let px = g.node("Mul", "patch.rect.x_focal", &[&px, &focal], vec![]);
    let py = g.node("Mul", "patch.rect.y_focal", &[&py, &focal], vec![]);
    let cx = g.constant_f32("patch.rect.cx", &[], &[k.cx]);
    let cy = g.constant_f32("patch.rect.cy", &[], &[k.cy]);
    let u = g.node("Add", "patch.rect.u", &[&cx, &px], vec![]);
    let v = g.node("Sub", "patch.rect.v", &[&cy, &py], vec![]);
    let front = (all_front.as_str(), zero_i.as_str());
    let cols = pixel_span(g, "patch.rect.cols", &u, w, front);
    let rows = pixel_span(g, "patch.rect.rows", &v, h, front);
    (rows, cols)
}

/// The pixel indices `[floor(min t) - 1, ceil(max t) + 2)` of the projected coordinates `t`
/// (f32 `[8, 1]`), clipped to `[0, n)`, as an index list (int64 `[m]`); all of `0..n` unless
/// `all_front` (bool `[]`; `zero` is the int64 0 `[]`).
fn pixel_span(
    g: &mut GraphBuilder,
    name: &str,
    t: &str,
    n: usize,
    (all_front, zero): (&str, &str),
) -> String {
    let lo_c = g.constant_f32(&format!("{name}.clip_lo"), &[], &[-2.0]);
    let hi_c = g.constant_f32(&format!("{name}.clip_hi"), &[], &[n as f32 + 2.0]);
    let t = g.node(
        "Clip",
        &format!("{name}.clipped"),
        &[t, &lo_c, &hi_c],
        vec![],
    );
    let whole = || vec![attr_int("keepdims", 0)];
    let min = g.node("ReduceMin", &format!("{name}.min"), &[&t], whole());
    let max = g.node("ReduceMax", &format!("{name}.max"), &[&t], whole());
    let min = g.node("Floor", &format!("{name}.floor"), &[&min], vec![]);
    let max = g.node("Ceil", &format!("{name}.ceil"), &[&max], vec![]);
    let one = g.constant_f32(&format!("{name}.one"), &[], &[1.0]);
    let two = g.constant_f32(&format!("{name}.two"), &[], &[2.0]);
    let start = g.node("Sub", &format!("{name}.start_f"), &[&min, &one], vec![]);
    let end = g.node("Add", &format!("{name}.end_f"), &[&max, &two], vec![]);
    let to_i = || vec![attr_int("to", DataType::Int64 as i64)];
    let start = g.node("Cast", &format!("{name}.start_i"), &[&start], to_i());
    let end = g.node("Cast", &format!("{name}.end_i"), &[&end], to_i());
    let all_end = g.constant_i64(&format!("{name}.all_end"), &[], &[n as i64]);
    let start = g.node(
        "Where",
        &format!("{name}.start_s"),
        &[all_front, &start, zero],
        vec![],
    );
    let end = g.node(
        "Where",
        &format!("{name}.end_s"),
        &[all_front, &end, &all_end],
        vec![],
    );
    let shape = g.constant_i64(&format!("{name}.one_shape"), &[1], &[1]);
    let start = g.node(
        "Reshape",
        &format!("{name}.first"),
        &[&start, &shape],
        vec![],
    );
    let end = g.node("Reshape", &format!("{name}.past"), &[&end, &shape], vec![]);
    crate::layers::index_range(g, name, n, &start, &end, 1)
}

/// The mouth patch of an upsampled frame graph: the output pixels whose rays meet the
/// upsampler's mouth box, their rays (which go through the student after the coarse hits)
/// and their count.
pub(super) struct MouthPatch {
    /// int64 `[n_patch]`, row-major pixel indices of the output image.
    pixels: String,
    /// int64 `[n_patch]`, their places among the tested pixels (`mask_i64`'s).
    local: String,
    /// int64 `[1]`.
    pub(super) count: String,
    /// The patch's mask over the tested pixels as int64 `[n_rect]`.
    mask_i64: String,
    pub(super) o: String,
    pub(super) d: String,
}

impl MouthPatch {
    /// The rays of the output camera `k` at `pose` through the pixels whose rays meet
    /// `mouth` within the student's `[near, far]` (`nldf_train`'s `mouth_patch_rays`).
    /// Only the pixels inside the rectangle that the box's corners project to (grown by a
    /// pixel; the whole image when a corner is not in front of the camera) are tested, so
    /// that a frame does not test every pixel of the output.
    pub(super) fn rays(
        g: &mut GraphBuilder,
        ckpt: &StudentCheckpoint,
        mouth: &nldf_core::bounds::Bounds,
        k: &Intrinsics,
        pose: &str,
    ) -> MouthPatch {
        let spec = &ckpt.spec;
        let (h, w) = (k.height as usize, k.width as usize);
        let (rows, cols) = projected_rect(g, mouth, k, pose);
        // The rectangle's rays, as `camera_rays` makes them (the same products and sums).
        let (xs, ys) = pixel_coords(k);
        let xs = g.constant_f32("patch.rays.x_all", &[w], &xs);
        let ys = g.constant_f32("patch.rays.y_all", &[h], &ys);
        let axis0 = || vec![attr_int("axis", 0)];
        let xs = g.node("Gather", "patch.rays.x_rect", &[&xs, &cols], axis0());
        let ys = g.node("Gather", "patch.rays.y_rect", &[&ys, &rows], axis0());
        let x_shape = g.constant_i64("patch.rays.x_shape", &[3], &[1, -1, 1]);
        let y_shape = g.constant_i64("patch.rays.y_shape", &[3], &[-1, 1, 1]);
        let xs = g.node("Reshape", "patch.rays.x", &[&xs, &x_shape], vec![]);
        let ys = g.node("Reshape", "patch.rays.y", &[&ys, &y_shape], vec![]);
        let (columns, origin) = pose_columns(g, "patch.rays", pose);
        let d = ray_directions(g, "patch.rays", &columns, (&xs, &ys));
        // The rectangle's pixel indices, row-major `[n_rect]`.
        let width = g.constant_i64("patch.image_width", &[1], &[w as i64]);
        let row_start = g.node("Mul", "patch.row_start", &[&rows, &width], vec![]);
        let col_axis = g.constant_i64("patch.col_axis", &[1], &[1]);
        let row_axis = g.constant_i64("patch.row_axis", &[1], &[0]);
        let row_start = g.node(
            "Unsqueeze",
            "patch.row_start_col",
            &[&row_start, &col_axis],
            vec![],
        );
        let col = g.node("Unsqueeze", "patch.col_row", &[&cols, &row_axis], vec![]);
        let rect = g.node("Add", "patch.rect_grid", &[&row_start, &col], vec![]);
        let flat1 = g.constant_i64("patch.rect_flat", &[1], &[-1]);
        let rect = g.node("Reshape", "patch.rect_pixels", &[&rect, &flat1], vec![]);

        let rays = (origin, d);
        let hit = slab_hits(g, "patch.bounds", mouth, (spec.near, spec.far), &rays);
        let (local, count) = mask_indices(g, ("patch", "patch"), &hit);
        let pixels = g.node("Gather", "patch.pixels_index", &[&rect, &local], axis0());
        let (o, d) = hit_rays(g, "patch", &rays, &local);
        MouthPatch {
            pixels,
            local,
            count,
            mask_i64: "patch.hit_count".to_string(),
            o,
            d,
        }
    }

    /// `image` (`[h, w, 3]`) with the patch's pixels painted: the student's rows from
    /// `n_first` (the coarse hits come first) to `n_all`, `colour + (1 - sigmoid(logit))
    /// background`, over `background` (float `[h w, 3]`).
    pub(super) fn paint(
        &self,
        g: &mut GraphBuilder,
        image: &str,
        n_first: &str,
        background: &str,
        width: usize,
        (h, w): (usize, usize),
    ) -> String {
        // The student's rows (hidden layer, colour, logit) that the upsampler's part of the
        // graph gathered, `[n_all, width + 4]`; the patch's are rows `n_first ..`.
        let at = crate::layers::rank_rows(g, "patch", &self.mask_i64, &self.local, Some(n_first));
        let behind = g.node(
            "Gather",
            "patch.background",
            &[background, &self.pixels],
            vec![attr_int("axis", 0)],
        );
        let pixels = crate::patch::patch_pixels(
            g,
            "patch",
            (crate::upsampler_graph::UP_ROWS, &at),
            &behind,
            width,
        );
        let flat = g.constant_i64("patch.flat_shape", &[2], &[-1, 3]);
        let flat = g.node("Reshape", "patch.image_flat", &[image, &flat], vec![]);
        let axis1 = g.constant_i64("patch.index_axis", &[1], &[1]);
        let at = g.node("Unsqueeze", "patch.index", &[&self.pixels, &axis1], vec![]);
        let painted = g.node("ScatterND", "patch.painted", &[&flat, &at, &pixels], vec![]);
        let shape = g.constant_i64("patch.image_shape", &[3], &[h as i64, w as i64, 3]);
        g.node("Reshape", "patch.image", &[&painted, &shape], vec![])
    }
}
