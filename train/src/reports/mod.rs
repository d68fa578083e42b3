//! What trained models are reported as: evaluation on every split ([`eval`]) and the
//! training-step benchmarks ([`bench`](mod@bench)).

pub mod bench;
pub mod eval;
