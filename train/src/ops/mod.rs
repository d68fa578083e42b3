//! The fused candle ops: one op each for the teacher's field and the student's residual MLP,
//! forward and backward on nldf-kernels' products, and the base they share (flat
//! parameters, affine layers).

pub mod field_op;
pub mod op_base;
pub mod student_op;
