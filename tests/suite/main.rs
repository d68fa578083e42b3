//! The workspace test suite: one binary, a module per topic.

mod audio;
mod synth_head;
