//! The mouth patch's graph parts that the upsampled frame graph and the upsampled ray graph
//! share: the student's rows of the patch's rays after the coarse ones, and their pixels
//! composited over the background (`nldf_train`'s `paint_mouth_patch`). The frame graph
//! finds the patch's rays itself (`frame::mouth_patch`); the ray graph is given them
//! (contract 6, `patch_o`, `patch_d` and `patch_background`).

use nldf_model::contract::{
    INPUT_PATCH_BACKGROUND, INPUT_PATCH_DIRECTIONS, INPUT_PATCH_ORIGINS, PATCH_AXIS,
};
use nldf_model::onnx::DataType;

use crate::graph::{Dim, GraphBuilder, attr_int};
use crate::layers::rank_rows;

/// The ray graph's mouth patch inputs: the patch's rays and their background, f32
/// `[n_patch, 3]` each.
pub(crate) struct PatchInputs {
    pub(crate) o: String,
    pub(crate) d: String,
    pub(crate) background: String,
}

impl PatchInputs {
    /// Declares the inputs (after the coarse rays', cells' and background's).
    pub(crate) fn declare(g: &mut GraphBuilder) -> PatchInputs {
        let dims = [Dim::Symbolic(PATCH_AXIS.to_string()), Dim::Fixed(3)];
        PatchInputs {
            o: g.input(INPUT_PATCH_ORIGINS, DataType::Float, &dims),
            d: g.input(INPUT_PATCH_DIRECTIONS, DataType::Float, &dims),
            background: g.input(INPUT_PATCH_BACKGROUND, DataType::Float, &dims),
        }
    }

    /// Where the student's rows of the coarse rays and of the patch's rays lie when the
    /// student ran on the coarse rays (the true cells of `cells`, bool `[bh, bw]`) followed
    /// by the patch's: int64 `[n_rays]` (`0 .. n_rays`) and int64 `[n_patch]` (`n_rays ..
    /// n_rays + n_patch`). Counted from the masks, as index lists for a Gather: no runtime
    /// needs to size a Slice of computed bounds.
    pub(crate) fn rows(&self, g: &mut GraphBuilder, cells: &str) -> (String, String) {
        let to_i64 = || vec![attr_int("to", DataType::Int64 as i64)];
        let flat = g.constant_i64("patch.flat", &[1], &[-1]);
        let cells = g.node("Reshape", "patch.cells_flat", &[cells, &flat], vec![]);
        let cells_i64 = g.node("Cast", "patch.cells_i64", &[&cells], to_i64());
        let coarse = g.node("NonZero", "patch.coarse_2d", &[&cells], vec![]);
        let coarse = g.node("Reshape", "patch.coarse_at", &[&coarse, &flat], vec![]);
        let first = rank_rows(g, "up.coarse", &cells_i64, &coarse, None);
        // A one per patch ray, from its background's first column (0 x + 1).
        let axis1 = g.constant_i64("patch.column_axis", &[1], &[1]);
        let (c0, c1) = (
            g.constant_i64("patch.column_start", &[1], &[0]),
            g.constant_i64("patch.column_end", &[1], &[1]),
        );
        let column = g.node(
            "Slice",
            "patch.background_red",
            &[&self.background, &c0, &c1, &axis1],
            vec![],
        );
        let column = g.node("Reshape", "patch.red_flat", &[&column, &flat], vec![]);
        let zero = g.constant_f32("patch.zero_f32", &[], &[0.0]);
        let one = g.constant_f32("patch.one_f32", &[], &[1.0]);
        let ones = g.node("Mul", "patch.zeros_f32", &[&column, &zero], vec![]);
        let ones = g.node("Add", "patch.ones_f32", &[&ones, &one], vec![]);
        let ones = g.node("Cast", "patch.ones", &[&ones], to_i64());
        let zero_i = g.constant_i64("patch.zero_i64", &[], &[0]);
        let none = g.node("Mul", "patch.cells_none", &[&cells_i64, &zero_i], vec![]);
        let axis0 = || vec![attr_int("axis", 0)];
        let all = g.node("Concat", "patch.all_mask", &[&cells_i64, &ones], axis0());
        let marks = g.node("Concat", "patch.marks_i64", &[&none, &ones], axis0());
        let marks = g.node(
            "Cast",
            "patch.marks",
            &[&marks],
            vec![attr_int("to", DataType::Bool as i64)],
        );
        let at = g.node("NonZero", "patch.at_2d", &[&marks], vec![]);
        let at = g.node("Reshape", "patch.at", &[&at, &flat], vec![]);
        let rows = rank_rows(g, "patch", &all, &at, None);
        (first, rows)
    }
}

/// The patch's pixels: of the student's rows `rows` (`[n_all, width + 4]`: hidden layer,
/// premultiplied colour, opacity logit) those at `at` (int64 `[n]`), `colour + (1 -
/// sigmoid(logit)) behind` with `behind` their background (`[n, 3]`); node names start with
/// `prefix`.
///
/// # Shapes
/// - returns `[n, 3]`
pub(crate) fn patch_pixels(
    g: &mut GraphBuilder,
    prefix: &str,
    (rows, at): (&str, &str),
    behind: &str,
    width: usize,
) -> String {
    let name = |n: &str| format!("{prefix}.{n}");
    let rows = g.node(
        "Gather",
        &name("rows"),
        &[rows, at],
        vec![attr_int("axis", 0)],
    );
    let cols = |g: &mut GraphBuilder, part: &str, lo: i64, hi: i64| {
        let lo = g.constant_i64(&name(&format!("{part}.start")), &[1], &[lo]);
        let hi = g.constant_i64(&name(&format!("{part}.end")), &[1], &[hi]);
        let axis = g.constant_i64(&name(&format!("{part}.axis")), &[1], &[1]);
        g.node("Slice", &name(part), &[&rows, &lo, &hi, &axis], vec![])
    };
    let f = width as i64;
    let colour = cols(g, "colour", f, f + 3);
    let logit = cols(g, "logit", f + 3, f + 4);
    let alpha = g.node("Sigmoid", &name("opacity"), &[&logit], vec![]);
    let one = g.constant_f32(&name("one"), &[1], &[1.0]);
    let clear = g.node("Sub", &name("clear"), &[&one, &alpha], vec![]);
    let behind = g.node("Mul", &name("behind"), &[&clear, behind], vec![]);
    g.node("Add", &name("pixels"), &[&colour, &behind], vec![])
}
