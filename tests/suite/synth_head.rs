//! The synthetic head renderer.
